"""Tensioner elements (each a ``ports.TensionerElement``) and the closed loop's elements
(``ports.Element``), each with the builder its registry entry calls
(:data:`trackmj.sim.registry.ELEMENTS`, ``build(context) -> Element``).

* :class:`HydraulicElement`: the hydraulic plugin (:mod:`trackmj.hydraulics`) on the element
  port (tp, tp-weak, dp-a);
* :class:`IdealForceSource`: dp-b's ideal force source;
* :class:`PassiveElement`: a preload spring-damper that ignores the valves (a tensioner
  file's ``[passive]`` table);
* :class:`ConstantForce`, :class:`ForceHistory`: bare tensioner elements for settling,
  identification and replay.

The FMU element lives in :mod:`trackmj.fmi.element`. Sign conventions as in
:mod:`trackmj.ports`: stroke s [m] outward positive, v = ds/dt, force F [N] > 0 pushes the
idler carrier outward.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from trackmj.hydraulics import HydraulicTensioner
from trackmj.hydraulics.tensioner import FLOW_NAMES, NODE_NAMES
from trackmj.params import ParameterError
from trackmj.plant import PassiveTensioner
from trackmj.ports import COUPLING_STEP_S, ElementLog, ForceLaw

if TYPE_CHECKING:
    from trackmj.hydraulics import HydraulicParams
    from trackmj.sim.architectures import ElementContext

END_STOP_ALLOWANCE_M = 5e-3
"""End-stop penetration a physical run may reach beyond the cylinder travel [m] (50 kN per
cylinder on the 1e7 N/m stops): beyond it the stops are not holding the stroke."""
NAN = math.nan


def cylinder_travel_m(hydraulics: HydraulicParams) -> tuple[float, float]:
    """The hydraulic file's cylinder travel with the end-stop allowance [m]."""
    return (-END_STOP_ALLOWANCE_M, hydraulics.cylinder.stroke_max_m + END_STOP_ALLOWANCE_M)


def equivalent_cylinder(hydraulics: HydraulicParams) -> tuple[float, float, float]:
    """(lumped head area [m²], lumped rod area [m²], tank pressure [Pa]) of the hydraulic
    file's two cylinders: an element without pressures shows the sensors the equivalent
    head pressure of its force, (F + A_r·p_t)/A_h, and the rods at tank (as dp-b does)."""
    cyl = hydraulics.cylinder
    return 2.0 * cyl.area_head_m2, 2.0 * cyl.area_rod_m2, hydraulics.tank_pressure_Pa


def equivalent_pressures(force_N: float,
                         cylinder: tuple[float, float, float]) -> tuple[float, float]:
    """(head, rod) pressure [Pa gauge] holding ``force_N`` on the lumped ``cylinder`` of
    :func:`equivalent_cylinder`, the rods at tank."""
    area_head, area_rod, tank = cylinder
    return (force_N + area_rod * tank) / area_head, tank


class HydraulicElement:
    """The hydraulic plugin on the element port: valve modes to its solenoids (when the mode
    changes), its log, its five node pressures for the guard, its ledger as run metrics and
    energy table. ``force_law``, ``complete_step`` and ``log`` are the plugin's own bound
    methods (no call in between at 1 kHz)."""

    pressure_nodes = NODE_NAMES
    channels: ClassVar[Mapping[str, str]] = {"p_head_L_Pa": "Pa", "p_head_R_Pa": "Pa",
                                   "p_line_A_Pa": "Pa",
                                   **{f"q_{name}_m3_s": "m^3/s" for name in FLOW_NAMES}}
    """Each cylinder's head (both rods share one node, the readout's p_rod_Pa), line A, and
    every flow of the circuit a -> b as :data:`~trackmj.hydraulics.tensioner.FLOW_NAMES`
    names them (main_PA supply -> line A, main_AT line A -> tank, main_PB supply -> rod
    node, main_BT rod node -> tank, V_L / V_R line A -> head, relief, make-up, leakage,
    pump)."""

    def __init__(self, tensioner: HydraulicTensioner) -> None:
        self.tensioner = tensioner
        self.force_law = tensioner.force_law
        self.complete_step = tensioner.complete_step
        self.log = tensioner.log
        self.stroke_range_m = cylinder_travel_m(tensioner.params)
        self._mode: int | None = None
        self._pressures = tensioner.pressure_view()

    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """Valve mode +1/0/−1 to the solenoids when it changes (u: the mode is the command;
        the supply set-point is the plugin's own profile)."""
        if mode != self._mode:
            self.tensioner.set_mode(mode)
            self._mode = mode

    def node_pressures(self) -> list[float]:
        """(line A, head L, head R, rod node, supply) [Pa gauge] now."""
        return self._pressures.tolist()

    def channel_values(self) -> list[float]:
        rec = self.tensioner.record
        return [rec.p_head_L_Pa, rec.p_head_R_Pa, rec.p_line_A_Pa,
                *(rec.flows_m3_s[name] for name in FLOW_NAMES)]

    def run_metrics(self, duration_s: float) -> dict[str, Any]:
        """Interface residual, friction loss and ledger balance error [J], and the energy
        table (:func:`trackmj.energy.energy_table`)."""
        from trackmj.energy import energy_table

        ledger = self.tensioner.ledger
        return {"interface_energy_residual_J": ledger.interface_residual_J,
                "friction_loss_J": ledger.friction_J,
                "ledger_balance_error_J": ledger.balance_error_J,
                "energy_J": energy_table(ledger, self.tensioner.supply_model, duration_s)}


def build_hydraulic(ctx: ElementContext) -> HydraulicElement:
    """The plugin with the scenario's supply model (default: the hydraulic file's) at the
    hydraulic file's set-point with the scenario's changes, each model starting in its
    steady state without demand; all valves closed (hold); ``ctx.coupling`` strong or weak."""
    setup = ctx.setup
    hyd, sc = setup.hydraulics, setup.scenario
    nominal = hyd.supply.setpoint_Pa
    profile = sc.supply_setpoint_profile(nominal)
    if profile is not None and (sc.supply.model or hyd.supply.default_model) == "unloading":
        raise ParameterError(f"{sc.source.name} [[supply.drops]]: the supply model "
                             "'unloading' (the hydraulic file's [supply].default_model) takes "
                             "no set-point drops; name another [supply].model")
    tensioner = HydraulicTensioner(
        hyd, stroke_m=ctx.stroke_m, head_pressure_Pa=setup.head_pressure0_Pa,
        supply_model=sc.supply.model, setpoint_Pa=nominal if profile is None else profile,
        coupling=ctx.coupling)
    tensioner.set_mode(0)
    return HydraulicElement(tensioner)


class ConstantForce:
    """F(v) = force_N − damping_N_s_m·v: a constant load with implicit damping, e.g. to bring
    the track to rest at a load (settle, identification). Stateless."""

    def __init__(self, force_N: float, damping_N_s_m: float = 0.0) -> None:
        self.force_N = force_N
        self.damping_N_s_m = damping_N_s_m

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(self.force_N, -self.damping_N_s_m)

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Nothing to finish: the element has no state."""


class ForceHistory:
    """Tensioner element replaying ``force_N`` [N], one value per coupling step (the last
    one held after the end), with no damping."""

    def __init__(self, force_N: np.ndarray) -> None:
        self.force_N = force_N
        self.step = 0

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(float(self.force_N[min(self.step, len(self.force_N) - 1)]))

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        self.step += 1


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
        """The ideal actuator's energy table (:func:`trackmj.energy.ideal_actuator_table`)."""
        from trackmj.energy import ideal_actuator_table

        return {"energy_J": ideal_actuator_table(self, duration_s)}


def build_ideal(ctx: ElementContext) -> IdealForceSource:
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


def build_passive(ctx: ElementContext) -> PassiveElement:
    """The passive tensioner of the run's tensioner file (its ``[passive]`` table)."""
    table = ctx.tensioner.passive
    return PassiveElement(table.preload_N, table.stiffness_N_m, table.damping_N_s_m,
                          table.stroke_ref_m, table.travel_m,
                          equivalent_cylinder(ctx.setup.hydraulics))
