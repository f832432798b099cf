"""A preload spring-damper on the element port (a tensioner file's ``[passive]`` table) and
its builder. Sign conventions as in :mod:`trackmj.ports`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from trackmj.elements.cylinder import equivalent_cylinder, equivalent_pressures
from trackmj.ports import Element, ElementLog, ForceLaw
from trackmj.track.plant import PassiveTensioner

if TYPE_CHECKING:
    from trackmj.elements.context import ElementContext

NAN = math.nan


class PassiveElement(PassiveTensioner):
    """A preload spring-damper on the element port (see :class:`PassiveTensioner` for the
    law): the valves act on nothing, there are no pressure nodes (the sensors see the
    equivalent pressures of its force on ``cylinder``, :func:`equivalent_pressures`); it
    books the work it does on the mechanics, ∫F·v dt, its only energy term."""

    pressure_nodes = ()
    channels: ClassVar[Mapping[str, str]] = {}

    def __init__(self, preload_N: float, stiffness_N_m: float, damping_N_s_m: float,
                 stroke_ref_m: float, stroke_range_m: tuple[float, float],
                 cylinder: tuple[float, float, float]) -> None:
        super().__init__(preload_N, stiffness_N_m, damping_N_s_m, stroke_ref_m)
        self.stroke_range_m = stroke_range_m
        self.cylinder = cylinder
        self.t_s = self.work_J = 0.0
        self._law = ForceLaw(preload_N)
        self._force_N = preload_N

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        self._law = super().force_law(t_s, stroke_m, velocity_m_s)
        return self._law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Book F(v)·v·h of the step."""
        self.work_J += self._law.at(velocity_m_s) * velocity_m_s * (t_s - self.t_s)
        self.t_s = t_s
        self._force_N = self._law.at(velocity_m_s)

    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """Nothing to command: a passive tensioner has no valves."""

    def log(self) -> ElementLog:
        p_head, p_rod = equivalent_pressures(self._force_N, self.cylinder)
        return ElementLog(self.t_s, p_head, p_rod, NAN, NAN, self._force_N, 0.0, NAN,
                          self.work_J)

    def node_pressures(self) -> tuple[float, ...]:
        return ()

    def channel_values(self) -> tuple[()]:
        return ()

    def run_metrics(self, duration_s: float) -> dict[str, Any]:
        """The energy table of a passive element: its mechanical work [J]."""
        return {"energy_J": {"passive_element": True, "mechanical": self.work_J}}


def build(ctx: ElementContext) -> Element:
    """The passive tensioner of the run's tensioner file (its ``[passive]`` table)."""
    table = None if ctx.tensioner is None else ctx.tensioner.passive
    if table is None:
        raise ValueError("the element 'passive' needs a tensioner file with a [passive] table")
    return PassiveElement(table.preload_N, table.stiffness_N_m, table.damping_N_s_m,
                          table.stroke_ref_m, table.travel_m,
                          equivalent_cylinder(ctx.setup.hydraulics))
