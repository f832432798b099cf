"""dp-b's ideal force source on the element port, its builder and its energy table. Sign
conventions as in :mod:`trackmj.ports`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from trackmj.elements.cylinder import cylinder_travel_m
from trackmj.ports import COUPLING_STEP_S, Element, ElementLog, ForceLaw

if TYPE_CHECKING:
    from trackmj.elements.context import ElementContext

NAN = math.nan


class IdealForceSource:
    """dp-b tensioner: an ideal force source replacing the hydraulics.

    State: commanded force F_c [N] and lagged force F_l [N]. Each step
    F_c += mode·rate_N_s·h, F_l += (F_c − F_l)·h/(τ + h) (implicit lag), and the law is
    F(v) = F_l − c·v with c the cylinders' viscous damping [N·s/m]. Equivalent pressures for
    the sensors: p_head = (F_l + A_r·p_t)/A_h, p_rod = p_t (A the lumped areas). There is
    no supply node (p_supply and q_supply are NaN). ``work_J``: the net work into the track
    Σ F·v·h. ``supply_J``: the energy an ideal actuator with the same cylinders would draw:
    lossless valves, no leakage or seal friction, the head oil column (compliance C_h [m^3/Pa])
    a lossless store of the energy the track returns, so the supply delivers only what the
    head side ever needs beyond it: the running maximum of E(t) = Σ p_head·A_h·v·h +
    C_h·(p_head² − p_head,0²)/2 (a hold against the track's ripple draws nothing, as a
    closed cylinder does not).
    """

    pressure_nodes = ("head", "rod")
    channels: ClassVar[Mapping[str, str]] = {}

    def __init__(self, force_N: float, rate_N_s: float, lag_s: float, damping_N_s_m: float,
                 area_head_m2: float, area_rod_m2: float, tank_Pa: float,
                 head_compliance_m3_Pa: float,
                 stroke_range_m: tuple[float, float] = (-math.inf, math.inf)) -> None:
        self.stroke_range_m = stroke_range_m
        self.command_N = self.force_N = force_N
        self.rate_N_s, self.lag_s, self.damping = rate_N_s, lag_s, damping_N_s_m
        self.area_head, self.area_rod, self.tank = area_head_m2, area_rod_m2, tank_Pa
        self.head_compliance = head_compliance_m3_Pa
        self.mode = 0
        self.t_s = 0.0
        self.work_J = 0.0
        self.supply_J = 0.0
        self._head_work_J = 0.0
        self._p_head0 = self.p_head_Pa
        self._law = ForceLaw(force_N, -damping_N_s_m)

    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """Valve mode +1 (force rises at rate_N_s), 0 (held), −1 (falls); no supply limit."""
        self.mode = mode

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        h = COUPLING_STEP_S
        self.command_N += self.mode * self.rate_N_s * h
        self.force_N += (self.command_N - self.force_N) * h / (self.lag_s + h)
        self._law = ForceLaw(self.force_N, -self.damping)
        return self._law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        h = COUPLING_STEP_S
        p_head = self.p_head_Pa
        self.work_J += self._law.at(velocity_m_s) * velocity_m_s * h
        self._head_work_J += p_head * self.area_head * velocity_m_s * h
        needed = self._head_work_J + 0.5 * self.head_compliance * (p_head * p_head
                                                                   - self._p_head0 ** 2)
        self.supply_J = max(self.supply_J, needed)
        self.t_s = t_s

    @property
    def p_head_Pa(self) -> float:
        """Equivalent head pressure [Pa gauge] of the lumped cylinder at the lagged force."""
        return (self.force_N + self.area_rod * self.tank) / self.area_head

    def log(self) -> ElementLog:
        """The per-step values (no supply node: NaN)."""
        return ElementLog(self.t_s, self.p_head_Pa, self.tank, NAN, NAN, self.force_N,
                          self.supply_J, self.work_J, self.work_J)

    def channel_values(self) -> tuple[()]:
        return ()

    def node_pressures(self) -> tuple[float, float]:
        """(equivalent head, rod = tank) [Pa gauge]."""
        return (self.p_head_Pa, self.tank)

    def run_metrics(self, duration_s: float) -> dict[str, Any]:
        """The ideal actuator's energy table (:func:`ideal_actuator_table`)."""
        return {"energy_J": ideal_actuator_table(self, duration_s)}


def build(ctx: ElementContext) -> Element:
    """dp-b's source: the valve mode integrates a force command at the reduced model's
    tension-rate gain at the initial force, through a lag of a quarter period of the oil
    column on the idler mass, with the two cylinders' viscous damping."""
    setup = ctx.setup
    hyd, idler = setup.hydraulics, setup.idler
    two_ah, two_ar = 2.0 * hyd.cylinder.area_head_m2, 2.0 * hyd.cylinder.area_rod_m2
    volume = 2.0 * hyd.cylinder.dead_volume_head_m3 + two_ah * ctx.stroke_m
    oil_k = hyd.fluid.bulk_modulus_Pa * two_ah ** 2 / volume
    lag = 2.0 * math.pi / math.sqrt(oil_k / idler.mass_kg) / 4.0
    return IdealForceSource(setup.force0_N, ctx.model.tension_rate_gain(setup.force0_N), lag,
                            2.0 * hyd.cylinder.viscous_friction_N_s_m, two_ah, two_ar,
                            hyd.tank_pressure_Pa, volume / hyd.fluid.bulk_modulus_Pa,
                            cylinder_travel_m(hyd))


def ideal_actuator_table(source: IdealForceSource, t_end_s: float) -> dict[str, Any]:
    """dp-b's energy table: the work into the track and, as ``circuit``, what an ideal
    actuator with the same cylinders would draw: lossless valves, no leakage or seal
    friction, the head oil column storing what the track returns (the running maximum of the
    head-side work plus the oil column's energy change; see :class:`IdealForceSource`)."""
    return {
        "ideal_actuator": True,
        "note": "no hydraulics: circuit is what an ideal actuator with the same cylinders "
                "would draw (trackmj.elements.ideal.ideal_actuator_table)",
        "circuit": float(source.supply_J),
        "mechanical": float(source.work_J),
    }
