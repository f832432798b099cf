"""Hydraulic tensioner: two cylinders, 4/2 main valve, V_L/V_R, supply; implicit coupling.

Circuit and sizing: see models/lf1352_hydraulics.toml (header) and docs/sizing.md. In short:
supply S (one of four supply models: fixed pump + accumulator + relief, pressure-compensated
variable pump, fixed pump + accumulator + unloading valve, or a prescribed pressure) -> main
4/2 (rest P->A, B->T; energised P->B, A->T) -> line A -> V_L / V_R (NC 2/2, each with a
head-branch restrictor in series) -> heads; line B feeds both rod chambers,
with a 5.5e-8 m^2 restrictor in the release feed P->B only (the rods vent B->T freely). The
restrictors set how fast the tension moves: a 3 kN change against the identified track
(4.40e6 N/m, ``models/lf1352_idler.toml``) in series with the head oil and hoses takes
~0.8 s at 12 MPa supply (the sizing in ``models/lf1352_hydraulics.toml``, [metering]).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from trackmj.errors import PhysicsError
from trackmj.ports import ElementLog, ForceLaw, make_force_law, positional

from . import kernels as k
from .components import Solenoid, SolenoidBank, orifice_gain
from .ledger import EnergyLedger
from .params import SUPPLY_MODELS, HydraulicParams, SupplyModel, load_hydraulic_params

Coupling = Literal["strong", "weak", "multirate"]
MODES: dict[int, tuple[float, float, float]] = {
    1: (0.0, 1.0, 1.0),    # pressurize: main at rest (P->A, B->T), V_L and V_R open
    0: (0.0, 0.0, 0.0),    # hold: main at rest, V_L and V_R closed
    -1: (1.0, 1.0, 1.0),   # release: main energised (P->B, A->T), V_L and V_R open
}
_element_log = positional(ElementLog, k.LOG_FIELDS)
"""ElementLog from the kernel's LOG slots, checked against its fields at import."""
NODE_NAMES = ("line A", "head L", "head R", "rod node", "supply")
"""Names of the pressure nodes in ``HydraulicTensioner.pressures`` order."""
FLOW_NAMES = ("main_PA", "main_AT", "main_PB", "main_BT", "V_L", "V_R", "relief",
              "makeup_L", "makeup_R", "makeup_rod", "leak_L", "leak_R", "pump")


@dataclass(frozen=True, slots=True)
class StepRecord:
    """Everything exposed after a completed step (SI, gauge Pa, flows a->b as named).

    flows_m3_s keys: FLOW_NAMES ("main_PA" = S->A, "main_AT" = A->T, "main_PB" = S->rod node,
    "main_BT" = rod node->T, "V_L"/"V_R" = A->head, "relief" = S->T, "makeup_*" = T->chamber,
    "leak_*" = head->rod, "pump" = net pump delivery into S, 0 with a prescribed supply).
    q_pump_m3_s = flows_m3_s["pump"]. p_rod_L_Pa == p_rod_R_Pa (one rod node). dF_dp_m2 maps
    a chamber to ∂F/∂p (A_head or −A_rod); dv_dQ_1_m2 maps it to ∂v/∂Q for flow INTO that chamber
    (1/A_head, −1/A_rod), per cylinder. newton_iterations: corrections (Newton, or chord in
    a strong complete_step) of the last solve; newton_backtracks: line-search halvings in
    all solves of the step. Pressures, volumes and flows are those at the step's end;
    force_N and piston_force_N [N] are over the step, at the pressures' mean over it (what
    the track received; kernels module docstring, "Losses where they happen").
    """

    t_s: float
    stroke_m: float
    velocity_m_s: float
    p_head_L_Pa: float
    p_head_R_Pa: float
    p_rod_L_Pa: float
    p_rod_R_Pa: float
    p_line_A_Pa: float
    p_supply_Pa: float
    p_tank_Pa: float
    q_supply_m3_s: float
    q_pump_m3_s: float
    flows_m3_s: dict[str, float]
    V_head_L_m3: float
    V_head_R_m3: float
    V_rod_L_m3: float
    V_rod_R_m3: float
    V_line_A_m3: float
    force_N: float
    piston_force_N: float
    friction_N: float
    endstop_N: float
    dF_dp_m2: dict[str, float]
    dv_dQ_1_m2: dict[str, float]
    law: ForceLaw
    Z_N_s_m: float
    correction_N: float
    valve_positions: tuple[float, float, float]
    valve_commands: tuple[float, float, float]
    newton_iterations: int
    newton_backtracks: int
    interface_residual_J: float


def _check_scheme(dt_s: float, coupling: str, exchange_steps: int, substep_s: float) -> None:
    """ValueError unless the exchange step dt_s [s] is finite and > 0, ``coupling`` is a
    scheme and the multi-rate settings are consistent (substep_s [s] in (0, dt_s])."""
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        raise ValueError(f"dt_s = {dt_s!r} must be finite and > 0")
    if coupling not in ("strong", "weak", "multirate"):
        raise ValueError(f"coupling = {coupling!r} must be 'strong', 'weak' or 'multirate'")
    if exchange_steps < 1 or not (0.0 < substep_s <= dt_s):
        raise ValueError("exchange_steps must be >= 1 and substep_s in (0, dt_s]")


def _pump_leak_gain(prm: HydraulicParams) -> float:
    """The variable pump's leakage per pressure [m^3/(s·Pa)]: its standby flow at the
    file's set-point."""
    return prm.variable_pump.standby_flow_m3_s / prm.supply.setpoint_Pa


class HydraulicTensioner:
    """Two-cylinder hydraulic tensioner implementing ``trackmj.ports.TensionerElement``.

    State (gauge Pa): ``pressures = (p_A, p_HL, p_HR, p_B, p_S)`` = line-A node, head L, head R,
    rod node (line B + both rod chambers), supply node (a state with a pump, prescribed with
    the ``prescribed`` supply model). Stroke s [m] grows outward, v = ds/dt; F > 0 pushes the idler
    outward; F = A_h(p_HL + p_HR) − 2·A_r·p_B − F_fric(v) + F_endstop(s, v). Flows positive
    in the named direction (see StepRecord). Node volumes V_HL = V_dh + A_h·s,
    V_B = V_lineB + 2(V_dr + A_r(s_max − s)).

    Integration (one exchange step h): backward Euler on every node,
    R_i = (V_i(s_{k+1})/β)(p_i − p_i^k) − h(ΣQ_in,i(p) − σ_i·A_i·v) = 0 (+ V_oil,acc(p_S)
    − V_oil,acc(p_S^k) on the supply node), solved by Newton with the analytic Jacobian
    (heads eliminated by Schur complement, then a 3x3 / 2x2 solve), globalised by an Armijo
    backtracking line search on ½·Σ(β·R_i/V_i)² (node residuals as pressure errors). Cavitation:
    every orifice outflow is scaled by a smoothstep of its upstream pressure (0 at floor, 1 at
    floor+band), and make-up check valves feed a chamber from the tank below p_t − crack.
    The make-up flow s((p_t − crack − p)/w)·Q_orifice(p_t − p) is S-shaped in p (ds/dx = 0 at
    both ends of the band) and its gain h·dQ/dp exceeds the rod node's V/β ~10x, so when the
    rod chambers expand faster than line B can feed them (hold mode, idler at ±0.04 m/s) the
    undamped Newton step jumps between the closed and the fully open side of the band and
    cycles (|dp| ~ 2e5 Pa); the line search makes it converge (newton_backtracks counts it).

    Strong coupling (default). ``force_law(t_k, s_k, v_k)``: Newton-solve R(p, v) = 0 at
    the predicted end-of-step velocity v* = 2·v_k − v_{k−1} with s_{k+1} = s_k + h·v, then
    dp/dv = −R_p⁻¹·R_v (same Jacobian) and
    F(v) ≈ F(v*) + Z·(v − v*), Z = dF/dv = Σ ∂F/∂p·dp/dv − dF_fric/dv + dF_es/dv (< 0:
    the oil spring over one step, ≈ −h·ΣβA²/V, plus friction). Returned law:
    ForceLaw(F(v*) − Z·v* + δF, Z). ``complete_step(t_{k+1}, s_{k+1}, v_{k+1})``: from the
    linear predictor p* + dp/dv·(v_{k+1} − v*) (off by O((v_{k+1} − v*)²), typically
    0.01–20 Pa), chord corrections with force_law's factorised Jacobian until one is below
    newton_tol_Pa (usually two; none of a full Newton's Jacobian evaluations), full Newton
    if they stop contracting; then the step residual
    r_k = F_hyd(v_{k+1})·v_{k+1}·h − law.at(v_{k+1})·v_{k+1}·h, F_hyd = piston force at the
    converged pressures − friction + end stop. NEPCE-style carry: E_c = Σ r (the cumulative
    interface error, which already contains the work the correction delivered); the next law
    adds δF = clip(E_c/(h·v_k), ±max_correction_N) when |v_k| ≥ min_correction_velocity,
    else 0. Deadbeat when v changes little per step, so Σ r stays ≈ one step's residual.

    Weak coupling: F0 = pressure force at the last completed step's end pressures (its
    latest state; the circuit books that step at its mean pressures, so the interface
    residual carries A·(p̄ − p_k)·v·h) + end stop at (s_k, v_k),
    friction linearised at v_k (Z = −dF_fric/dv only), no correction. Multi-rate: the force
    is updated every ``exchange_steps`` calls to force_law; in between, each completed step
    advances the hydraulics in ``substep_s`` BE sub-steps with the velocity held from the last
    exchange (stroke integrated internally, re-synchronised at each exchange). With a light
    carrier (80 kg against the ~2e7 N/m oil spring, ω ≈ 500 rad/s) the 5 ms held exchange is
    unstable, a real property of the scheme: the carrier oscillation grows until the held
    velocity drives a chamber below absolute vacuum (p < −p_atm gauge: only without free
    air, ``[cavitation] air_fraction`` = 0), empties a chamber volume or stops Newton
    converging. The element then does not raise: it sets
    ``diverged = True`` and ``divergence_time_s`` (start of the failing sub-step), keeps the
    hydraulics frozen at the last physical state (its last force law is held, the ledger
    stops at the last completed sub-step) and keeps accepting steps, so an experiment can
    run the scheme to the end and report that and when it diverged.

    Valves: ``set_mode(+1/0/−1)`` or ``set_command(main, v_l, v_r)`` (each in [0, 1]) at the
    time of the last call; solenoid delay and first-order opening apply inside.

    Supply (``supply_model``, the kernels module docstring has the equations): ``fixed_relief``
    (fixed pump + gas accumulator + relief cracking at the set-point, the study's),
    ``compensated`` (pressure-compensated variable pump, its displacement following the
    set-point error with droop and lag, no accumulator, a safety relief), ``unloading``
    (fixed pump charging the accumulator up to the set-point, the cut-out, unloaded until
    the cut-in; safety relief) or ``prescribed`` (p_s(t) = set-point, an ideal source). The
    set-point p_set(t) [Pa] is the relief or compensator setting, the cut-out pressure or
    the prescribed pressure; a varying set-point (``setpoint_Pa`` a callable) is evaluated
    at the end of every step (sub-step in multi-rate).

    Output: ``record`` builds the full StepRecord of the last completed step on access
    (~7 µs); ``log()`` returns the per-step logging values as a ``trackmj.ports.ElementLog``
    (~0.4 µs: p_head the mean of the two heads, q_supply the flow S->A + S->rod node,
    force the cylinder force over the step = StepRecord.force_N,
    supply_J = ``EnergyLedger.pump_J``);
    ``ledger`` (cumulative) and ``step_ledger`` (last step) are EnergyLedger views of the
    state array, so a held reference always shows the current values.

    Implementation: the numerics above, the solenoids' motion and the orifice gains run in
    compiled kernels (:mod:`.kernels`, numba), one call per ``force_law`` and one per
    ``complete_step`` with the strong coupling. ``_const`` (float64[kernels.N_CONST]: areas,
    volumes, fluid, valve, friction, end-stop and Newton constants), ``_state``
    (float64[kernels.N_STATE]: pressures, volumes, orifice gains, strong coupling's
    linearisation, flows, record and log values, both ledgers, the valve areas) and the
    solenoids' bank (``main.bank``, shared by ``main``, ``vl``, ``vr``) are laid out, with
    units, in the kernels module docstring. Python keeps the solenoids' commands, the
    set-point profile and the input checks, and turns a kernel's failure status into a
    RuntimeError (Newton did not converge; strong and weak coupling).

    Parameters
    ----------
    params : HydraulicParams, optional
        Circuit parameters; default: the packaged ``models/lf1352_hydraulics.toml``.
    dt_s : float
        Exchange step h [s] (the 1 ms coupling step).
    stroke_m : float
        Initial stroke s_0 [m] (0 fully retracted, ``cylinder.stroke_max_m`` extended).
    head_pressure_Pa : float, optional
        Initial pressure of both heads [Pa gauge]; default: 15 kN with the rods at tank.
    supply_model : {"fixed_relief", "compensated", "unloading", "prescribed"}, optional
        Supply model; default: the file's ``[supply].default_model`` (``"prescribed"`` when
        ``supply_profile`` is given).
    setpoint_Pa : float or callable, optional
        Supply set-point p_set [Pa gauge], constant or a callable of t [s]; default: the
        file's ``[supply].setpoint_Pa``. The unloading model takes a constant only.
    supply_profile : callable, optional
        Prescribed supply pressure p_s(t) [Pa gauge]: shorthand for
        ``supply_model="prescribed", setpoint_Pa=supply_profile``.
    coupling : {"strong", "weak", "multirate"}
        Coupling scheme (see above).
    exchange_steps : int
        Multi-rate: steps between force exchanges [-].
    substep_s : float
        Multi-rate: hydraulic sub-step [s], at most ``dt_s``.
    t0_s : float
        Initial time [s].
    supply_pressure_Pa : float, optional
        Initial supply pressure with a pump [Pa gauge]; default: the model's steady state at
        the initial set-point without demand (fixed_relief: the relief's crack pressure;
        compensated: p_set/(1 + droop·k_L/Q_g,max); unloading: the cut-out, pump unloaded;
        below the cut-out the unloading pump starts loaded).
    """

    def __init__(self, params: HydraulicParams | None = None, *, dt_s: float = 1e-3,
                 stroke_m: float = 0.05, head_pressure_Pa: float | None = None,
                 supply_model: SupplyModel | None = None,
                 setpoint_Pa: float | Callable[[float], float] | None = None,
                 supply_profile: Callable[[float], float] | None = None,
                 coupling: Coupling = "strong", exchange_steps: int = 5,
                 substep_s: float = 1e-4, t0_s: float = 0.0,
                 supply_pressure_Pa: float | None = None) -> None:
        self.params = params if params is not None else load_hydraulic_params()
        _check_scheme(dt_s, coupling, exchange_steps, substep_s)
        self._check_input("stroke_m", stroke_m)
        self.dt = float(dt_s)
        self.coupling = coupling
        self.exchange_steps = exchange_steps
        self.n_sub = max(1, round(dt_s / substep_s))
        model, p_set0 = self._choose_supply(supply_model, setpoint_Pa, supply_profile, t0_s)
        self._const = c = self._circuit_constants()
        self._supply_constants(c, model, p_set0)
        self._state = st = np.zeros(k.N_STATE)  # layout: kernels module docstring
        self._make_valves()
        self._strong = coupling == "strong"
        self.t = float(t0_s)
        self.s = float(stroke_m)
        self.v = 0.0
        self._initial_pressures(model, p_set0, head_pressure_Pa, supply_pressure_Pa)
        k.initialise(c, st, self.s)
        self.step_ledger = EnergyLedger.view(st[k.STEP_LEDGER:k.STEP_LEDGER + k.N_LEDGER])
        self.ledger = EnergyLedger.view(st[k.LEDGER:k.LEDGER + k.N_LEDGER])
        self.diverged = False  # multi-rate only: the lagged exchange left physics
        self.divergence_time_s = math.nan
        self._law = ForceLaw(st.item(k.LAW), 0.0)
        self._calls = 0
        self._v_hold = 0.0
        self._s_hyd = self.s
        self._completed = False  # a step was completed (record / log exist)

    def _choose_supply(self, supply_model: SupplyModel | None,
                       setpoint_Pa: float | Callable[[float], float] | None,
                       supply_profile: Callable[[float], float] | None,
                       t0_s: float) -> tuple[SupplyModel, float]:
        """Resolve the supply model and its set-point (constructor's arguments, else the
        file's defaults), set ``setpoint``, ``supply_model`` and ``prescribed``; returns the
        model and the initial set-point p_set(t0) [Pa gauge]. ValueError on a combination
        the models do not take."""
        prm = self.params
        if supply_profile is not None:
            if supply_model not in (None, "prescribed") or setpoint_Pa is not None:
                raise ValueError("supply_profile is the prescribed model's set-point: give "
                                 "it alone, or supply_model and setpoint_Pa")
            supply_model, setpoint_Pa = "prescribed", supply_profile
        model = prm.supply.default_model if supply_model is None else supply_model
        if model not in SUPPLY_MODELS:
            raise ValueError(f"supply_model = {model!r} must be one of {list(SUPPLY_MODELS)}")
        if setpoint_Pa is None:
            setpoint_Pa = prm.supply.setpoint_Pa
        if callable(setpoint_Pa):
            if model == "unloading":
                raise ValueError("the unloading model takes a constant setpoint_Pa: with the "
                                 "pump unloaded and the check valve closed nothing lowers the "
                                 "accumulator pressure when the cut-out is lowered")
            self.setpoint: Callable[[float], float] | None = setpoint_Pa
        else:
            self.setpoint = None
            self._check_input("setpoint_Pa", setpoint_Pa)
        self.supply_model: SupplyModel = model
        self.prescribed = model == "prescribed"
        p_set0 = self._setpoint_at(t0_s) if callable(setpoint_Pa) else float(setpoint_Pa)
        if model == "unloading" and prm.accumulator.precharge_Pa >= prm.cut_in_Pa(p_set0):
            raise ValueError(f"unloading supply: the cut-in {prm.cut_in_Pa(p_set0):g} Pa "
                             "must exceed the accumulator precharge "
                             f"{prm.accumulator.precharge_Pa:g} Pa, or the accumulator is "
                             "empty before the pump loads")
        return model, p_set0

    def _circuit_constants(self) -> np.ndarray:
        """The kernels' constants (float64[kernels.N_CONST]) of the cylinders, lines, fluid,
        cavitation, valves, metering, friction, end stops and Newton; sets ``Ah``, ``Ar``
        [m^2], ``pT``, ``floor``, ``mu_open``, ``mu_width``, ``p_atm`` [Pa]. The supply's
        entries are left 0 (:meth:`_supply_constants`)."""
        prm = self.params
        cyl, cav, acc, cp = prm.cylinder, prm.cavitation, prm.accumulator, prm.coupling
        self.Ah, self.Ar = cyl.area_head_m2, cyl.area_rod_m2
        self.pT = prm.tank_pressure_Pa
        self.floor = cav.floor_Pa
        self.mu_open = self.pT - cav.makeup_crack_below_tank_Pa
        self.mu_width = cav.makeup_full_below_tank_Pa - cav.makeup_crack_below_tank_Pa
        self.p_atm = acc.atmospheric_pressure_Pa_abs
        cq, rho = prm.orifice.discharge_coefficient, prm.fluid.density_kg_m3
        c = np.zeros(k.N_CONST)  # layout: kernels module docstring
        c[k.C_AH], c[k.C_AR] = self.Ah, self.Ar
        c[k.C_VOL_A], c[k.C_VOL_S] = prm.lines.line_a_volume_m3, prm.supply.line_volume_m3
        c[k.C_VOL_DH], c[k.C_VOL_DR] = cyl.dead_volume_head_m3, cyl.dead_volume_rod_m3
        c[k.C_VOL_LB], c[k.C_S_MAX] = prm.lines.line_b_volume_m3, cyl.stroke_max_m
        c[k.C_BETA], c[k.C_PT] = prm.fluid.bulk_modulus_Pa, self.pT
        c[k.C_PCR], c[k.C_LEAK] = prm.orifice.critical_pressure_Pa, cyl.leakage_m3_s_Pa
        c[k.C_FLOOR], c[k.C_BAND] = self.floor, cav.band_Pa
        c[k.C_MU_OPEN], c[k.C_MU_WIDTH] = self.mu_open, self.mu_width
        c[k.C_K_MU] = orifice_gain(cq, cav.makeup_area_m2, rho)
        c[k.C_AIR], c[k.C_AIR_BAND] = cav.air_fraction, cav.air_onset_band_Pa
        c[k.C_FRIC_C], c[k.C_FRIC_VS] = cyl.coulomb_friction_N, cyl.coulomb_velocity_m_s
        c[k.C_FRIC_B] = cyl.viscous_friction_N_s_m
        c[k.C_ES_K], c[k.C_ES_C] = cyl.endstop_stiffness_N_m, cyl.endstop_damping_N_s_m
        c[k.C_TOL], c[k.C_MAX_ITER] = cp.newton_tol_Pa, cp.newton_max_iter
        c[k.C_V_CORR], c[k.C_MAX_CORR] = cp.min_correction_velocity_m_s, cp.max_correction_N
        mv, sv = prm.main_valve, prm.switching_valves
        c[k.C_MV_OVERLAP], c[k.C_MV_LEAK], c[k.C_MV_OPEN] = (mv.overlap, mv.leak_area_m2,
                                                              mv.open_area_m2)
        c[k.C_SV_OVERLAP], c[k.C_SV_LEAK], c[k.C_SV_OPEN] = (sv.overlap, sv.leak_area_m2,
                                                              sv.open_area_m2)
        c[k.C_ROD_FEED] = prm.metering.rod_feed_area_m2
        c[k.C_HEAD_BRANCH] = prm.metering.head_branch_area_m2
        c[k.C_CQ], c[k.C_SQRT_RHO], c[k.C_TWO] = cq, math.sqrt(rho), 2.0
        return c

    def _supply_constants(self, c: np.ndarray, model: SupplyModel, p_set0: float) -> None:
        """Fill the supply's entries of the kernels' constants ``c`` in place: relief,
        pumps, accumulator, unloading valve and the model's flags, for ``model`` at the
        initial set-point ``p_set0`` [Pa gauge]."""
        prm = self.params
        rel, acc = prm.relief, prm.accumulator
        fp, vp, uv = prm.fixed_pump, prm.variable_pump, prm.unloading_valve
        cq, rho = prm.orifice.discharge_coefficient, prm.fluid.density_kg_m3
        c[k.C_REL_CRACK] = (1.0 + rel.safety_margin_rel) * p_set0
        c[k.C_REL_WIDTH], c[k.C_K_REL] = rel.band_Pa, orifice_gain(cq, rel.full_area_m2, rho)
        c[k.C_Q_PUMP] = fp.flow_m3_s
        c[k.C_ACC_V0], c[k.C_ACC_P0] = acc.gas_volume_m3, acc.precharge_Pa
        c[k.C_P_ATM], c[k.C_ACC_N] = self.p_atm, acc.polytropic_exponent
        c[k.C_PRESCRIBED] = 1.0 if self.prescribed else 0.0
        c[k.C_MODEL] = k.MODEL_CODES[model]
        c[k.C_ACC] = 1.0 if model in ("fixed_relief", "unloading") else 0.0
        c[k.C_QG_MAX], c[k.C_DROOP], c[k.C_TAU] = (vp.max_flow_m3_s, vp.droop_Pa,
                                                   vp.time_constant_s)
        c[k.C_K_PUMP_LEAK] = _pump_leak_gain(prm)
        variable = model == "compensated"
        c[k.C_ETA_V] = 1.0 if variable else fp.volumetric_efficiency
        c[k.C_ETA_HM] = vp.mechanical_efficiency if variable else fp.mechanical_efficiency
        c[k.C_P_UNLOADED] = uv.unloaded_pressure_Pa
        c[k.C_CUT_IN_REL] = 1.0 - uv.differential_rel

    def _make_valves(self) -> None:
        """The solenoids ``main``, ``vl``, ``vr`` on one bank (rows in the kernels' order),
        alike and at rest."""
        mv, sv = self.params.main_valve, self.params.switching_valves
        bank = SolenoidBank((mv, sv, sv))   # rows main, V_L, V_R (the kernels' order)
        self.main = Solenoid(mv, bank=bank, index=0)
        self.vl = Solenoid(sv, bank=bank, index=1)
        self.vr = Solenoid(sv, bank=bank, index=2)
        self._state[k.TWINS] = 1.0   # alike and at rest: V_R moves as V_L while commanded alike

    def _initial_pressures(self, model: SupplyModel, p_set0: float,
                           head_pressure_Pa: float | None,
                           supply_pressure_Pa: float | None) -> None:
        """Initial set-point, pump state and node pressures in the state array (see the
        constructor's parameters for the defaults)."""
        st, vp, k_leak = self._state, self.params.variable_pump, _pump_leak_gain(self.params)
        if head_pressure_Pa is None:  # 15 kN with the rods at tank pressure
            head_pressure_Pa = (15e3 + 2.0 * self.Ar * self.pT) / (2.0 * self.Ah)
        st[k.SET_NEXT] = p_set0
        if self.prescribed or supply_pressure_Pa is None:
            ps = p_set0 / (1.0 + vp.droop_Pa * k_leak / vp.max_flow_m3_s) \
                if model == "compensated" else p_set0
        else:
            ps = float(supply_pressure_Pa)
            self._check_input("supply_pressure_Pa", ps)
        st[k.PUMP_X] = min(1.0, k_leak * ps / vp.max_flow_m3_s)
        st[k.LOADED] = 1.0 if model == "unloading" and ps < p_set0 else 0.0
        st[k.P:k.P + 5] = (ps, head_pressure_Pa, head_pressure_Pa, self.pT, ps)

    # ----------------------------------------------------------------- public API
    def set_mode(self, mode: int) -> None:
        """Circuit mode +1 pressurize / 0 hold / −1 release as a valve-command set."""
        if mode not in MODES:
            raise ValueError(f"mode = {mode!r} must be +1, 0 or -1")
        self.set_command(*MODES[mode])

    def set_command(self, main: float, v_l: float, v_r: float) -> None:
        """Per-valve commands in [0, 1] (main 1 = energised P->B, A->T; V 1 = open)."""
        self.main.set(self.t, main)
        self.vl.set(self.t, v_l)
        self.vr.set(self.t, v_r)
        if v_l != v_r:
            self._state[k.TWINS] = 0.0

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        """Affine force law F(v) = F0 + Z·v for the step starting at (t_k, s_k, v_k)."""
        t, s, v = self._check_state(t_s, stroke_m, velocity_m_s)
        self.t, self.s, self.v = t, s, v
        st = self._state
        if self._strong:
            h = self.dt
            if self.setpoint is not None:
                st[k.SET_NEXT] = self._setpoint_at(t + h)
            bank = self.main.bank
            # valve positions and gains at t + h, then the law linearised about the
            # extrapolated end-of-step velocity 2·v_k − v_{k−1}: the residual of the affine
            # law is second order in (v_{k+1} − v*), so the predictor cut the summed
            # |residual| ninefold against v* = v_k (measured)
            if k.strong_step_law(self._const, st, bank.sol, bank.pend, t, h, s, v) != k.OK:
                self._not_converged()
            self._law = make_force_law(st.item(k.LAW), st.item(k.LAW + 1))
        else:
            st[k.BACKTRACKS] = 0.0
            if self.coupling == "weak" or (self._calls % self.exchange_steps == 0
                                           and not self.diverged):
                if self.coupling == "multirate":
                    self._s_hyd, self._v_hold = s, v
                k.held_force_law(self._const, st, s, v)
                self._law = make_force_law(st.item(k.LAW), st.item(k.LAW + 1))
        self._calls += 1
        return self._law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Finish the step with the end-of-step state (t_{k+1}, s_{k+1}, v_{k+1})."""
        t_s, stroke_m, velocity_m_s = self._check_state(t_s, stroke_m, velocity_m_s)
        h = t_s - self.t
        if not h > 0.0:
            raise ValueError(f"t_s = {t_s!r} must exceed the step start time {self.t!r}")
        c, st = self._const, self._state
        if self._strong:   # from the linear predictor, with force_law's Jacobian
            bank = self.main.bank
            if k.strong_step_complete(c, st, bank.sol, bank.pend, self.t, t_s, stroke_m,
                                      velocity_m_s) != k.OK:
                self._not_converged()
            self.s, self.v, self.t = stroke_m, velocity_m_s, t_s
        elif self.coupling == "multirate":
            done = 0 if self.diverged else self._multirate_substeps(h)
            self.s, self.v, self.t = stroke_m, velocity_m_s, t_s
            if done == 0:  # diverged before this step: nothing to book
                return
            k.book_step(c, st, t_s, h, stroke_m, velocity_m_s)
        else:   # weak
            self._set_gains(self.t, h)
            status = k.weak_complete(c, st, t_s, h, stroke_m, velocity_m_s)
            if status != k.OK:
                self._not_converged()
            self._advance_valves(self.t, h)
            self.s, self.v, self.t = stroke_m, velocity_m_s, t_s
        self._completed = True

    def _multirate_substeps(self, h: float) -> int:
        """Advance the hydraulics over h in n_sub BE sub-steps with the held velocity; returns
        the number of sub-steps taken (< n_sub when the scheme diverged in this step)."""
        hs = h / self.n_sub
        for j in range(self.n_sub):
            t_j = self.t + j * hs
            self._set_gains(t_j, hs)
            s_next = self._s_hyd + hs * self._v_hold
            if k.multirate_substep(self._const, self._state, hs, s_next, self._v_hold,
                                   j > 0) != k.OK:
                self.diverged, self.divergence_time_s = True, t_j
                return j
            self._s_hyd = s_next
            self._advance_valves(t_j, hs)
        return self.n_sub

    @property
    def record(self) -> StepRecord:
        """Record of the last completed step (built on access)."""
        if not self._completed:
            raise RuntimeError("no step completed yet")
        st = self._state
        t, s, v, ff, fes, fp = st[k.REC:k.REC + 6].tolist()
        pA, pHL, pHR, pB, pS = st[k.P:k.P + 5].tolist()
        fl = st[k.FLOWS:k.FLOWS + k.N_FLOWS].tolist()
        V = st[k.VOL:k.VOL + 5].tolist()
        ah, ar = self.Ah, self.Ar
        law = self._law
        vrod = (V[3] - self.params.lines.line_b_volume_m3) / 2.0
        return StepRecord(
            t_s=t, stroke_m=s, velocity_m_s=v, p_head_L_Pa=pHL, p_head_R_Pa=pHR,
            p_rod_L_Pa=pB, p_rod_R_Pa=pB, p_line_A_Pa=pA, p_supply_Pa=pS,
            p_tank_Pa=self.pT, q_supply_m3_s=fl[0] + fl[2], q_pump_m3_s=fl[12],
            flows_m3_s=dict(zip(FLOW_NAMES, fl, strict=True)),
            V_head_L_m3=V[1], V_head_R_m3=V[2], V_rod_L_m3=vrod, V_rod_R_m3=vrod,
            V_line_A_m3=V[0], force_N=fp - ff + fes, piston_force_N=fp, friction_N=ff,
            endstop_N=fes,
            dF_dp_m2={"head_L": ah, "head_R": ah, "rod_L": -ar, "rod_R": -ar},
            dv_dQ_1_m2={"head_L": 1.0 / ah, "head_R": 1.0 / ah, "rod_L": -1.0 / ar,
                        "rod_R": -1.0 / ar},
            law=law, Z_N_s_m=law.damping_N_s_m, correction_N=st.item(k.CORRECTION),
            valve_positions=(self.main.position, self.vl.position, self.vr.position),
            valve_commands=(self.main.command, self.vl.command, self.vr.command),
            newton_iterations=int(st[k.ITERS]), newton_backtracks=int(st[k.STEP_BACKTRACKS]),
            interface_residual_J=self.step_ledger.interface_residual_J,
        )

    def log(self) -> ElementLog:
        """The handful of values logged every step, without building a StepRecord."""
        if not self._completed:
            raise RuntimeError("no step completed yet")
        return _element_log(ElementLog, self._state[k.LOG:k.LOG + len(k.LOG_FIELDS)].tolist())

    @property
    def pressures(self) -> tuple[float, float, float, float, float]:
        """(p_A, p_head_L, p_head_R, p_rod, p_supply) [Pa gauge] now."""
        return tuple(self._state[k.P:k.P + 5].tolist())

    def pressure_view(self) -> np.ndarray:
        """A read-only view (5,) of the pressures (p_A, p_head_L, p_head_R, p_rod, p_supply)
        [Pa gauge] that always shows the current values."""
        view = self._state[k.P:k.P + 5]
        view.flags.writeable = False
        return view

    @property
    def pump_displacement(self) -> float:
        """Variable pump's displacement x [-] (0..1) after the last completed step."""
        return self._state.item(k.PUMP_X)

    @property
    def pump_loaded(self) -> bool:
        """Unloading model: the pump charges the accumulator (False: unloaded)."""
        return self._state.item(k.LOADED) != 0.0

    @property
    def carry_J(self) -> float:
        """Cumulative interface residual E_c that the NEPCE correction works off [J]."""
        return self._state.item(k.CARRY)

    @property
    def newton_backtracks_total(self) -> int:
        """Line-search halvings in all completed steps."""
        return int(self._state[k.BACKTRACKS_TOTAL])

    # ----------------------------------------------------------------- internals
    @staticmethod
    def _check_input(name: str, x: float) -> None:
        if not math.isfinite(x):
            raise ValueError(f"{name} = {x!r} must be finite")

    @classmethod
    def _check_state(cls, t_s: float, stroke_m: float,
                     velocity_m_s: float) -> tuple[float, float, float]:
        """(t, s, v) as Python floats; ValueError naming the first non-finite one."""
        t, s, v = float(t_s), float(stroke_m), float(velocity_m_s)
        if not math.isfinite(t + s + v):
            cls._check_input("t_s", t)
            cls._check_input("stroke_m", s)
            cls._check_input("velocity_m_s", v)
        return t, s, v

    def _not_converged(self) -> None:
        """PhysicsError: the step's Newton solve failed (a run stops on it with its reason)."""
        raise PhysicsError(f"t = {self.t:.3f} s: hydraulic Newton did not converge in "
                           f"{self.params.coupling.newton_max_iter} iterations (last |dp| = "
                           f"{self._state.item(k.LAST_DP):.3g} Pa); the run left physics and "
                           "was stopped")

    def _setpoint_at(self, t_s: float) -> float:
        """The set-point profile at ``t_s`` [s] -> p_set [Pa gauge], checked finite and >= 0."""
        if self.setpoint is None:
            raise RuntimeError("the supply has a constant set-point, no profile to evaluate")
        ps = float(self.setpoint(t_s))
        if not (math.isfinite(ps) and ps >= 0.0):
            raise ValueError(f"supply set-point gave p_set = {ps!r} Pa at t = {t_s} s")
        return ps

    def _advance_valves(self, t_s: float, h: float) -> None:
        """Commit the solenoids' motion over [t_s, t_s + h] (:func:`.kernels.valves_advance`)."""
        bank = self.main.bank
        k.valves_advance(self._state, bank.sol, bank.pend, t_s, h)

    def _set_gains(self, t_s: float, h: float) -> None:
        """Valve positions at t_s + h (not committed) -> orifice gains of the step and the
        valve shares of the series paths' losses (:func:`.kernels.valves_at`: recomputed
        only for the edges whose area changed); with a varying set-point also
        p_set(t_s + h)."""
        if self.setpoint is not None:
            self._state[k.SET_NEXT] = self._setpoint_at(t_s + h)
        bank = self.main.bank
        k.valves_at(self._const, self._state, bank.sol, bank.pend, t_s, h)
