"""Hydraulic tensioner: two cylinders, 4/2 main valve, V_L/V_R, supply; implicit coupling.

Circuit and sizing: see models/lf1352_hydraulics.toml (header) and docs/sizing.md. In short:
supply S -> main 4/2 (rest P->A, B->T; energised P->B, A->T) -> line A -> V_L / V_R (NC
2/2, each with a 2.75e-8 m^2 restrictor in series) -> heads; line B feeds both rod chambers,
with a 5.5e-8 m^2 restrictor in the release feed P->B only (the rods vent B->T freely). The
restrictors make a 3 kN tension change against the identified track stiffness (~9.4e6 N/m)
take ~0.3 s at 12 MPa supply, i.e. 1.2e-6 m^3 of oil at ~4.2e-6 m^3/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, NamedTuple

from trackmj.ports import ForceLaw

from .components import (
    GasAccumulator,
    Solenoid,
    endstop_force,
    friction_force,
    orifice_flow,
    orifice_gain,
    series_area,
    smoothstep,
    valve_area,
)
from .ledger import EnergyLedger
from .params import HydraulicParams, load_hydraulic_params

Coupling = Literal["strong", "weak", "multirate"]
MODES: dict[int, tuple[float, float, float]] = {
    1: (0.0, 1.0, 1.0),    # pressurize: main at rest (P->A, B->T), V_L and V_R open
    0: (0.0, 0.0, 0.0),    # hold: main at rest, V_L and V_R closed
    -1: (1.0, 1.0, 1.0),   # release: main energised (P->B, A->T), V_L and V_R open
}
_MAX_BACKTRACKS = 12  # line-search halvings per Newton iteration (alpha >= 2^-12)
_MIN_STEP = 2.0 ** -_MAX_BACKTRACKS
_MAX_CHORD = 3  # chord corrections in complete_step before falling back to full Newton
_tuple_new = tuple.__new__  # LogRow(...) without NamedTuple's keyword-capable __new__
FLOW_NAMES = ("main_PA", "main_AT", "main_PB", "main_BT", "V_L", "V_R", "relief",
              "makeup_L", "makeup_R", "makeup_rod", "leak_L", "leak_R")


@dataclass(frozen=True, slots=True)
class StepRecord:
    """Everything exposed after a completed step (SI, gauge Pa, flows a->b as named).

    flows_m3_s keys: FLOW_NAMES ("main_PA" = S->A, "main_AT" = A->T, "main_PB" = S->rod node,
    "main_BT" = rod node->T, "V_L"/"V_R" = A->head, "relief" = S->T, "makeup_*" = T->chamber,
    "leak_*" = head->rod). p_rod_L_Pa == p_rod_R_Pa (one rod node). dF_dp_m2 maps a chamber
    to ∂F/∂p (A_head or −A_rod); dv_dQ_1_m2 maps it to ∂v/∂Q for flow INTO that chamber
    (1/A_head, −1/A_rod), per cylinder. newton_iterations: corrections (Newton, or chord in
    a strong complete_step) of the last solve; newton_backtracks: line-search halvings in
    all solves of the step.
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


class LogRow(NamedTuple):
    """The per-step logging values of a completed step (cheap; see ``HydraulicTensioner.log``).

    p_head_Pa is the mean of the two head pressures, q_supply_m3_s the flow out of the supply
    node through the main valve (S->A + S->rod node), force_N the cylinder force on the idler
    (> 0 outward; = StepRecord.force_N); the *_J values are the cumulative ledger terms.
    """

    t_s: float
    p_head_Pa: float
    p_rod_Pa: float
    p_supply_Pa: float
    q_supply_m3_s: float
    force_N: float
    supply_J: float
    piston_work_J: float
    mech_work_J: float


def _orf(pa: float, pb: float, k: float, pcr2: float, la: float, dla: float, lb: float,
         dlb: float) -> tuple[float, float, float]:
    """Limited orifice a->b: (Q, dQ/dp_a, dQ/dp_b); the upstream limiter l scales Q."""
    d = pa - pb
    r = d * d + pcr2
    r4 = math.sqrt(math.sqrt(r))
    q0 = k * d / r4
    g = k * (0.5 * d * d + pcr2) / (r * r4)
    if d >= 0.0:
        return q0 * la, g * la + q0 * dla, -g * la
    return q0 * lb, g * lb, -g * lb + q0 * dlb


def _absmax(a: float, b: float, c: float, d: float, e: float) -> float:
    """max(|a|, |b|, |c|, |d|, |e|) (a third of the builtins' cost)."""
    if a < 0.0:
        a = -a
    if b < 0.0:
        b = -b
    if b > a:
        a = b
    if c < 0.0:
        c = -c
    if c > a:
        a = c
    if d < 0.0:
        d = -d
    if d > a:
        a = d
    if e < 0.0:
        e = -e
    return e if e > a else a


class HydraulicTensioner:
    """Two-cylinder hydraulic tensioner implementing ``trackmj.ports.TensionerElement``.

    State (gauge Pa): ``p = (p_A, p_HL, p_HR, p_B, p_S)`` = line-A node, head L, head R,
    rod node (line B + both rod chambers), supply node (a state in accumulator mode,
    prescribed otherwise). Stroke s [m] grows outward, v = ds/dt; F > 0 pushes the idler
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

    Weak coupling: F0 = pressure force of the last completed step + end stop at (s_k, v_k),
    friction linearised at v_k (Z = −dF_fric/dv only), no correction. Multi-rate: the force
    is updated every ``exchange_steps`` calls to force_law; in between, each completed step
    advances the hydraulics in ``substep_s`` BE sub-steps with the velocity held from the last
    exchange (stroke integrated internally, re-synchronised at each exchange). With a light
    carrier (80 kg against the ~2e7 N/m oil spring, ω ≈ 500 rad/s) the 5 ms held exchange is
    unstable, a real property of the scheme: the carrier oscillation grows until the held
    velocity drives a chamber below absolute vacuum (p < −p_atm gauge), empties a chamber
    volume or stops Newton converging. The element then does not raise: it sets
    ``diverged = True`` and ``divergence_time_s`` (start of the failing sub-step), keeps the
    hydraulics frozen at the last physical state (its last force law is held, the ledger
    stops at the last completed sub-step) and keeps accepting steps, so an experiment can
    run the scheme to the end and report that and when it diverged.

    Valves: ``set_mode(+1/0/−1)`` or ``set_command(main, v_l, v_r)`` (each in [0, 1]) at the
    time of the last call; solenoid delay and first-order opening apply inside.

    Output: ``record`` builds the full StepRecord of the last completed step on access
    (~8 µs); ``log()`` returns the per-step logging values as a LogRow (~0.5 µs).
    """

    def __init__(self, params: HydraulicParams | None = None, *, dt_s: float = 1e-3,
                 stroke_m: float = 0.05, head_pressure_Pa: float | None = None,
                 supply_profile: Callable[[float], float] | str | None = None,
                 coupling: Coupling = "strong", exchange_steps: int = 5,
                 substep_s: float = 1e-4, t0_s: float = 0.0,
                 supply_pressure_Pa: float | None = None) -> None:
        self.params = prm = params if params is not None else load_hydraulic_params()
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s = {dt_s!r} must be finite and > 0")
        if coupling not in ("strong", "weak", "multirate"):
            raise ValueError(f"coupling = {coupling!r} must be 'strong', 'weak' or 'multirate'")
        if exchange_steps < 1 or not (0.0 < substep_s <= dt_s):
            raise ValueError("exchange_steps must be >= 1 and substep_s in (0, dt_s]")
        self._check_input("stroke_m", stroke_m)
        self.dt = dt_s
        self.coupling = coupling
        self.exchange_steps = exchange_steps
        self.n_sub = max(1, round(dt_s / substep_s))
        if isinstance(supply_profile, str):
            supply_profile = prm.profiles[supply_profile]
        self.profile = supply_profile
        self.prescribed = supply_profile is not None or prm.supply.mode == "prescribed"
        if self.prescribed and supply_profile is None:
            raise ValueError("supply.mode = 'prescribed' needs a supply_profile")
        cyl, fl = prm.cylinder, prm.fluid
        self.Ah, self.Ar = cyl.area_head_m2, cyl.area_rod_m2
        self._vol_A, self._vol_S = prm.lines.line_a_volume_m3, prm.supply.line_volume_m3
        self._vol_dh, self._vol_dr = cyl.dead_volume_head_m3, cyl.dead_volume_rod_m3
        self._vol_lb, self._s_max = prm.lines.line_b_volume_m3, cyl.stroke_max_m
        self._cyl = cyl
        self.beta = fl.bulk_modulus_Pa
        self.pT = prm.tank_pressure_Pa
        self.pcr = prm.orifice.critical_pressure_Pa
        self.pcr2 = self.pcr * self.pcr
        self.leak = cyl.leakage_m3_s_Pa
        cq, rho = prm.orifice.discharge_coefficient, fl.density_kg_m3
        self._gain = lambda a: orifice_gain(cq, a, rho)
        cav = prm.cavitation
        self.floor, self.band = cav.floor_Pa, cav.band_Pa
        self.mu_open = self.pT - cav.makeup_crack_below_tank_Pa
        self.mu_width = cav.makeup_full_below_tank_Pa - cav.makeup_crack_below_tank_Pa
        self.K_mu = self._gain(cav.makeup_area_m2)
        rel = prm.relief
        self.rel_crack, self.rel_width = rel.crack_Pa, rel.full_open_Pa - rel.crack_Pa
        self.K_rel = self._gain(rel.full_area_m2)
        self.Q_pump = 0.0 if self.prescribed else prm.supply.pump_flow_m3_s
        self.acc = GasAccumulator(prm.accumulator)
        self.main = Solenoid(prm.main_valve)
        self.vl = Solenoid(prm.switching_valves)
        self.vr = Solenoid(prm.switching_valves)
        self.t = t0_s
        self.s = stroke_m
        self.v = 0.0
        self._v_prev = 0.0
        if head_pressure_Pa is None:  # 15 kN with the rods at tank pressure
            head_pressure_Pa = (15e3 + 2.0 * self.Ar * self.pT) / (2.0 * self.Ah)
        if self.prescribed:
            ps = self._supply_pressure(t0_s)
        else:
            ps = prm.relief.crack_Pa if supply_pressure_Pa is None else supply_pressure_Pa
            self._check_input("supply_pressure_Pa", ps)
        self.p = (ps, head_pressure_Pa, head_pressure_Pa, self.pT, ps)
        self.V = self._volumes(stroke_m)
        self.ledger = EnergyLedger()
        self.step_ledger = EnergyLedger()
        self.ledger.oil_energy_J = self.ledger.oil_energy_start_J = self._oil_energy(self.p,
                                                                                     self.V)
        self.ledger.gas_energy_J = self.ledger.gas_energy_start_J = self._gas_energy(ps)
        self._voil0 = 0.0 if self.prescribed else self.acc.oil_volume(ps)[0]  # V_oil,acc(p_S^k)
        self._areas: tuple[float, ...] = ()
        self._lim_top = self.floor + self.band
        self.p_atm = prm.accumulator.atmospheric_pressure_Pa_abs
        self.diverged = False  # multi-rate only: the lagged exchange left physics
        self.divergence_time_s = math.nan
        cp = prm.coupling
        self._tol, self._max_iter = cp.newton_tol_Pa, cp.newton_max_iter
        self._v_corr, self._max_corr = cp.min_correction_velocity_m_s, cp.max_correction_N
        self.carry_J = 0.0
        self._law = ForceLaw(self._pressure_force(self.p), 0.0)
        self._correction = 0.0
        self._lin: tuple[tuple[float, ...], tuple[float, ...], float] | None = None
        self._calls = 0
        self._v_hold = 0.0
        self._s_hyd = stroke_m
        self._iters = 0
        self._backtracks = 0  # line-search halvings since the last force_law
        self._step_backtracks = 0
        self.newton_backtracks_total = 0
        self._rec: tuple | None = None

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

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        """Affine force law F(v) = F0 + Z·v for the step starting at (t_k, s_k, v_k)."""
        t_s, stroke_m, velocity_m_s = self._check_state(t_s, stroke_m, velocity_m_s)
        self.t, self.s, self.v = t_s, stroke_m, velocity_m_s
        self._backtracks = 0
        h = self.dt
        if self.coupling == "strong":
            self._set_gains(t_s, h)
            # linearise about the extrapolated end-of-step velocity 2·v_k − v_{k−1}: the
            # residual of the affine law is second order in (v_{k+1} − v*), so the
            # predictor cut the summed |residual| ninefold against v* = v_k (measured)
            v_star = 2.0 * velocity_m_s - self._v_prev
            self._v_prev = velocity_m_s
            s1 = stroke_m + h * v_star
            p1 = self._newton(h, s1, v_star, self.p)
            dpdv = self._dpdv(p1)
            # F(v*) and Z = dF/dv: pressures through dp/dv, friction, end stop (s1 = s_k + h·v)
            ah, ar2 = self.Ah, 2.0 * self.Ar
            ff, dff = self._friction(v_star)
            fes, dfes_ds, dfes_dv = self._endstop(s1, v_star)
            f_star = ah * (p1[1] + p1[2]) - ar2 * p1[3] - ff + fes
            z = ah * (dpdv[1] + dpdv[2]) - ar2 * dpdv[3] - dff + dfes_ds * h + dfes_dv
            self._lin = (p1, dpdv, v_star)
            corr = 0.0
            if abs(velocity_m_s) >= self._v_corr:
                cmax = self._max_corr
                corr = max(-cmax, min(cmax, self.carry_J / (h * velocity_m_s)))
            self._correction = corr
            self._law = ForceLaw(f_star - z * v_star + corr, z)
        elif self.coupling == "weak" or (self._calls % self.exchange_steps == 0
                                         and not self.diverged):
            if self.coupling == "multirate":
                self._s_hyd, self._v_hold = stroke_m, velocity_m_s
            ff, dff = self._friction(velocity_m_s)
            fes = self._endstop(stroke_m, velocity_m_s)[0]
            f0 = self._pressure_force(self.p) - (ff - dff * velocity_m_s) + fes
            self._law = ForceLaw(f0, -dff)
        self._calls += 1
        return self._law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Finish the step with the end-of-step state (t_{k+1}, s_{k+1}, v_{k+1})."""
        t_s, stroke_m, velocity_m_s = self._check_state(t_s, stroke_m, velocity_m_s)
        h = t_s - self.t
        if not h > 0.0:
            raise ValueError(f"t_s = {t_s!r} must exceed the step start time {self.t!r}")
        law, v1 = self._law, velocity_m_s
        sl = self.step_ledger
        if self.coupling == "multirate":
            done = 0 if self.diverged else self._multirate_substeps(h)
            self.s, self.v, self.t = stroke_m, v1, t_s
            if done == 0:  # diverged before this step: nothing to book
                return
        else:
            if self.coupling == "weak":
                self._set_gains(self.t, h)
                p1 = self._newton(h, stroke_m, v1, self.p)
            else:  # from the linear predictor, with force_law's Jacobian
                p_star, dpdv, v_star = self._lin
                dv = v1 - v_star
                p_guess = (p_star[0] + dpdv[0] * dv, p_star[1] + dpdv[1] * dv,
                           p_star[2] + dpdv[2] * dv, p_star[3] + dpdv[3] * dv,
                           p_star[4] + dpdv[4] * dv)
                p1 = self._chord(h, stroke_m, v1, p_guess, self._F)
                if p1 is None:
                    p1 = self._newton(h, stroke_m, v1, p_guess)
            self._commit(p1, stroke_m, v1, h, accumulate=False)
            self._advance_valves(self.t, h)
            self.s, self.v, self.t = stroke_m, v1, t_s
        ff = self._friction(v1)[0]
        fes = self._endstop(stroke_m, v1)[0]
        sl.friction_J = ff * v1 * h
        sl.endstop_J = -fes * v1 * h
        sl.mech_work_J = (law.force_N + law.damping_N_s_m * v1) * v1 * h  # law.at(v1)
        sl.interface_residual_J = (sl.piston_work_J - sl.friction_J - sl.endstop_J
                                   - sl.mech_work_J)
        self.carry_J += sl.interface_residual_J
        self.ledger.add(sl)
        self._rec = (t_s, stroke_m, v1, ff, fes)
        self._step_backtracks = self._backtracks
        self.newton_backtracks_total += self._backtracks

    def _multirate_substeps(self, h: float) -> int:
        """Advance the hydraulics over h in n_sub BE sub-steps with the held velocity; returns
        the number of sub-steps taken (< n_sub when the scheme diverged in this step)."""
        hs = h / self.n_sub
        for j in range(self.n_sub):
            t_j = self.t + j * hs
            self._set_gains(t_j, hs)
            s_next = self._s_hyd + hs * self._v_hold
            p1 = self._substep_or_none(hs, s_next)
            if p1 is None:
                self.diverged, self.divergence_time_s = True, t_j
                return j
            self._s_hyd = s_next
            self._commit(p1, s_next, self._v_hold, hs, accumulate=j > 0)
            self._advance_valves(t_j, hs)
        return self.n_sub

    def _substep_or_none(self, h: float, s1: float) -> tuple[float, ...] | None:
        """One multi-rate BE sub-step to stroke s1; None if the state left physics: a chamber
        volume ≤ 0, no Newton convergence, or a pressure below absolute vacuum."""
        if min(self._volumes(s1)) <= 0.0:
            return None
        try:
            p1 = self._newton(h, s1, self._v_hold, self.p)
        except RuntimeError:
            return None
        if not all(math.isfinite(x) and x >= -self.p_atm for x in p1):
            return None
        return p1

    @property
    def record(self) -> StepRecord:
        """Record of the last completed step (built on access)."""
        if self._rec is None:
            raise RuntimeError("no step completed yet")
        t, s, v, ff, fes = self._rec
        p, fl, V = self.p, self._flows, self.V
        ah, ar = self.Ah, self.Ar
        fp = self._pressure_force(p)
        law = self._law
        vrod = (V[3] - self.params.lines.line_b_volume_m3) / 2.0
        return StepRecord(
            t_s=t, stroke_m=s, velocity_m_s=v, p_head_L_Pa=p[1], p_head_R_Pa=p[2],
            p_rod_L_Pa=p[3], p_rod_R_Pa=p[3], p_line_A_Pa=p[0], p_supply_Pa=p[4],
            p_tank_Pa=self.pT, q_supply_m3_s=fl[0] + fl[2], q_pump_m3_s=self.Q_pump,
            flows_m3_s=dict(zip(FLOW_NAMES, fl, strict=True)),
            V_head_L_m3=V[1], V_head_R_m3=V[2], V_rod_L_m3=vrod, V_rod_R_m3=vrod,
            V_line_A_m3=V[0], force_N=fp - ff + fes, piston_force_N=fp, friction_N=ff,
            endstop_N=fes,
            dF_dp_m2={"head_L": ah, "head_R": ah, "rod_L": -ar, "rod_R": -ar},
            dv_dQ_1_m2={"head_L": 1.0 / ah, "head_R": 1.0 / ah, "rod_L": -1.0 / ar,
                        "rod_R": -1.0 / ar},
            law=law, Z_N_s_m=law.damping_N_s_m, correction_N=self._correction,
            valve_positions=(self.main.position, self.vl.position, self.vr.position),
            valve_commands=(self.main.command, self.vl.command, self.vr.command),
            newton_iterations=self._iters, newton_backtracks=self._step_backtracks,
            interface_residual_J=self.step_ledger.interface_residual_J,
        )

    def log(self) -> LogRow:
        """The handful of values logged every step, without building a StepRecord (~0.5 µs)."""
        if self._rec is None:
            raise RuntimeError("no step completed yet")
        t, _, _, ff, fes = self._rec
        p, fl, led = self.p, self._flows, self.ledger
        ph = p[1] + p[2]
        return _tuple_new(LogRow, (t, 0.5 * ph, p[3], p[4], fl[0] + fl[2],
                                   self.Ah * ph - 2.0 * self.Ar * p[3] - ff + fes,
                                   led.supply_J, led.piston_work_J, led.mech_work_J))

    @property
    def pressures(self) -> tuple[float, float, float, float, float]:
        """(p_A, p_head_L, p_head_R, p_rod, p_supply) [Pa gauge] now."""
        return self.p

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

    def _supply_pressure(self, t_s: float) -> float:
        ps = float(self.profile(t_s))
        if not (math.isfinite(ps) and ps >= 0.0):
            raise ValueError(f"supply profile gave p_s = {ps!r} Pa at t = {t_s} s")
        return ps

    def _volumes(self, s: float) -> tuple[float, float, float, float, float]:
        """Node volumes [m^3] (A, head L, head R, rod node, supply line) at stroke s [m]."""
        vh = self._vol_dh + self.Ah * s
        vr = self._vol_lb + 2.0 * (self._vol_dr + self.Ar * (self._s_max - s))
        return (self._vol_A, vh, vh, vr, self._vol_S)

    def _oil_energy(self, p: tuple[float, ...], V: tuple[float, ...]) -> float:
        n = 4 if self.prescribed else 5
        return sum(p[i] * p[i] * V[i] for i in range(n)) / (2.0 * self.beta)

    def _gas_energy(self, ps: float) -> float:
        return 0.0 if self.prescribed else self.acc.energy(ps)

    def _friction(self, v: float) -> tuple[float, float]:
        """Friction of both cylinders [N] (opposes motion) and its dF/dv [N·s/m]."""
        c = self._cyl
        f, d = friction_force(v, c.coulomb_friction_N, c.coulomb_velocity_m_s,
                              c.viscous_friction_N_s_m)
        return 2.0 * f, 2.0 * d

    def _endstop(self, s: float, v: float) -> tuple[float, float, float]:
        """End-stop force of both cylinders [N] (> 0 outward), dF/ds, dF/dv; 0 inside."""
        if 0.0 <= s <= self._s_max:
            return 0.0, 0.0, 0.0
        c = self._cyl
        f, ds, dv = endstop_force(s, v, c.stroke_max_m, c.endstop_stiffness_N_m,
                                  c.endstop_damping_N_s_m)
        return 2.0 * f, 2.0 * ds, 2.0 * dv

    def _pressure_force(self, p: tuple[float, ...]) -> float:
        return self.Ah * (p[1] + p[2]) - 2.0 * self.Ar * p[3]

    def _set_gains(self, t_s: float, h: float) -> None:
        """Valve positions at t_s + h (not committed) -> orifice gains of the step.

        The gains are recomputed only when one of the four edge areas changed (valves at
        rest, or moving inside their overlap, keep the cached gains).
        """
        if self.prescribed:
            self.ps_next = self._supply_pressure(t_s + h)
        if self._areas and not (self.main.moving or self.vl.moving or self.vr.moving):
            return
        prm = self.params
        mv, sv = prm.main_valve, prm.switching_valves
        xm = self.main.position_at(t_s, h)[0]
        areas = (valve_area(1.0 - xm, mv), valve_area(xm, mv),
                 valve_area(self.vl.position_at(t_s, h)[0], sv),
                 valve_area(self.vr.position_at(t_s, h)[0], sv))
        if areas != self._areas:
            self._areas = areas
            a_rest, a_ener, a_l, a_r = areas
            met, g = prm.metering, self._gain
            self.K = (g(a_rest), g(a_ener), g(series_area(a_ener, met.rod_feed_area_m2)),
                      g(a_rest),
                      g(series_area(a_l, met.head_branch_area_m2)),
                      g(series_area(a_r, met.head_branch_area_m2)))

    def _advance_valves(self, t_s: float, h: float) -> None:
        main, vl, vr = self.main, self.vl, self.vr
        if main.moving:
            main.advance(t_s, h)
        if vl.moving:
            vl.advance(t_s, h)
        if vr.moving:
            vr.advance(t_s, h)

    def _lim(self, p: float) -> tuple[float, float]:
        """Cavitation limiter below floor + band: (l, dl/dp); callers take (1, 0) above."""
        s, ds = smoothstep((p - self.floor) / self.band)
        return s, ds / self.band

    def _makeup(self, p: float) -> tuple[float, float]:
        """Make-up check valve T -> chamber at p < mu_open: (Q, dQ/dp); callers take 0 above."""
        x = (self.mu_open - p) / self.mu_width
        s, ds = smoothstep(x)
        f, df = orifice_flow(self.pT - p, self.K_mu, self.pcr)
        return s * f, -ds / self.mu_width * f - s * df

    def _eval(self, h: float, c: tuple[float, ...], v: float, p: tuple[float, ...],
              F: tuple[float, ...] | None = None) -> tuple[tuple, tuple, tuple, tuple]:
        """Linearise the step at pressures p: (R, d, F, flows).

        R: residual R/h of the five nodes [m^3/s] (see class docstring); d = J⁻¹·R [Pa], so
        the Newton step is p − d; F: the factorised Jacobian (for ``_dpdv`` and chord steps);
        flows: the twelve FLOW_NAMES flows [m^3/s]. c = V_i(s_{k+1})/(β·h) [m^3/(s·Pa)] of the
        five nodes. J is solved with the circuit's sparsity: heads eliminated by Schur
        complement, then the supply node, leaving 2x2 in (p_A, p_B); the head rows couple to
        the rod node only through the leakage (J_HB = J_BH = −leak). Given F (of a nearby
        point), J is not evaluated: d is the chord step with F, which is returned as is.
        """
        jac = F is None
        pA, pHL, pHR, pB, pS = p
        prescribed = self.prescribed
        if prescribed:
            pS = self.ps_next
        pT, pcr2, leak, fb, mo = self.pT, self.pcr2, self.leak, self._lim_top, self.mu_open
        KPA, KAT, KPB, KBT, KVL, KVR = self.K
        p0A, p0HL, p0HR, p0B, p0S = self.p
        # heads alike (V_L and V_R commanded together): the R head's terms are the L head's
        alike = pHR == pHL and p0HR == p0HL and KVR == KVL
        if pA >= fb and pHL >= fb and pHR >= fb and pB >= fb:
            # no node near the cavitation floor: plain orifices (components.orifice_flow)
            # Q = u·Δp, dQ/dΔp = u·(Δp²/2 + p_cr²)/r with r = Δp² + p_cr², u = K·r^(−1/4)
            d1 = pS - pA
            e1 = d1 * d1
            r1 = e1 + pcr2
            u1 = KPA * r1 ** -0.25
            qPA = u1 * d1
            d2 = pA - pT
            e2 = d2 * d2
            r2 = e2 + pcr2
            u2 = KAT * r2 ** -0.25
            qAT = u2 * d2
            d3 = pS - pB
            e3 = d3 * d3
            r3 = e3 + pcr2
            u3 = KPB * r3 ** -0.25
            qPB = u3 * d3
            d4 = pB - pT
            e4 = d4 * d4
            r4 = e4 + pcr2
            u4 = KBT * r4 ** -0.25
            qBT = u4 * d4
            d5 = pA - pHL
            e5 = d5 * d5
            r5 = e5 + pcr2
            u5 = KVL * r5 ** -0.25
            qVL = u5 * d5
            if alike:
                qVR = qVL
            else:
                d6 = pA - pHR
                e6 = d6 * d6
                r6 = e6 + pcr2
                u6 = KVR * r6 ** -0.25
                qVR = u6 * d6
            if jac:
                aPA_S = u1 * (0.5 * e1 + pcr2) / r1
                aAT_A = u2 * (0.5 * e2 + pcr2) / r2
                aPB_S = u3 * (0.5 * e3 + pcr2) / r3
                aBT_B = u4 * (0.5 * e4 + pcr2) / r4
                aVL_A = u5 * (0.5 * e5 + pcr2) / r5
                aVR_A = aVL_A if alike else u6 * (0.5 * e6 + pcr2) / r6
                aPA_A, aPB_B, aVL_H, aVR_H = -aPA_S, -aPB_S, -aVL_A, -aVR_A
        else:
            lA, dlA = (1.0, 0.0) if pA >= fb else self._lim(pA)
            lHL, dlHL = (1.0, 0.0) if pHL >= fb else self._lim(pHL)
            lHR, dlHR = (1.0, 0.0) if pHR >= fb else self._lim(pHR)
            lB, dlB = (1.0, 0.0) if pB >= fb else self._lim(pB)
            qPA, aPA_S, aPA_A = _orf(pS, pA, KPA, pcr2, 1.0, 0.0, lA, dlA)
            qAT, aAT_A, _ = _orf(pA, pT, KAT, pcr2, lA, dlA, 1.0, 0.0)
            qPB, aPB_S, aPB_B = _orf(pS, pB, KPB, pcr2, 1.0, 0.0, lB, dlB)
            qBT, aBT_B, _ = _orf(pB, pT, KBT, pcr2, lB, dlB, 1.0, 0.0)
            qVL, aVL_A, aVL_H = _orf(pA, pHL, KVL, pcr2, lA, dlA, lHL, dlHL)
            qVR, aVR_A, aVR_H = _orf(pA, pHR, KVR, pcr2, lA, dlA, lHR, dlHR)
        qlL = leak * (pHL - pB)
        qmL, dmL = (0.0, 0.0) if pHL >= mo else self._makeup(pHL)
        if alike:
            qlR, qmR, dmR = qlL, qmL, dmL
        else:
            qlR = leak * (pHR - pB)
            qmR, dmR = (0.0, 0.0) if pHR >= mo else self._makeup(pHR)
        qmB, dmB = (0.0, 0.0) if pB >= mo else self._makeup(pB)
        cA, cHL, cHR, cB, cS = c
        Ahv, Arv2 = self.Ah * v, 2.0 * self.Ar * v
        rA = cA * (pA - p0A) - qPA + qAT + qVL + qVR
        rHL = cHL * (pHL - p0HL) - qVL + qlL - qmL + Ahv
        rHR = rHL if alike else cHR * (pHR - p0HR) - qVR + qlR - qmR + Ahv
        rB = cB * (pB - p0B) - qPB + qBT - qlL - qlR - qmB - Arv2
        if prescribed:
            qrel, rS, JSS, JSA, JSB = 0.0, 0.0, 1.0, 0.0, 0.0
        else:
            qrel = drel = 0.0
            if pS > self.rel_crack:  # relief S -> T, opening over rel_width (smoothstep)
                w = self.rel_width
                x = (pS - self.rel_crack) / w
                s, ds = ((1.0, 0.0) if x >= 1.0
                         else (x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x) / w))
                d = pS - pT
                e = d * d
                r = e + pcr2
                u = self.K_rel * r ** -0.25
                f = u * d
                qrel, drel = s * f, ds * f + s * u * (0.5 * e + pcr2) / r
            voil1, dvoil = self.acc.oil_volume(pS)
            ih = 1.0 / h
            rS = (cS * (pS - p0S) + (voil1 - self._voil0) * ih
                  - self.Q_pump + qPA + qPB + qrel)
            if jac:
                JSS = cS + dvoil * ih + aPA_S + aPB_S + drel
                JSA, JSB = aPA_A, aPB_B
        nl = -leak  # J_HB = J_RB = J_BHL = J_BHR
        if jac:
            JAA = cA - aPA_A + aAT_A + aVL_A + aVR_A
            JAHL, JAHR, JAS = aVL_H, aVR_H, -aPA_S
            JBB, JBS = cB - aPB_B + aBT_B - dmB + 2.0 * leak, -aPB_S
            # rows H, R, S divided by their diagonal: x_H = y_H − hA·x_A − hB·x_B etc.
            iH, iS = 1.0 / (cHL - aVL_H - dmL + leak), 1.0 / JSS
            hA, hB, sA, sB = -aVL_A * iH, nl * iH, JSA * iS, JSB * iS
            if alike:
                iR, kA, kB = iH, hA, hB
            else:
                iR = 1.0 / (cHR - aVR_H - dmR + leak)
                kA, kB = -aVR_A * iR, nl * iR
            a11 = JAA - JAHL * hA - JAHR * kA - JAS * sA
            a12 = -JAHL * hB - JAHR * kB - JAS * sB
            a21 = -nl * (hA + kA) - JBS * sA
            a22 = JBB - nl * (hB + kB) - JBS * sB
            F = (iH, iR, iS, hA, hB, kA, kB, sA, sB, a11, a12, a21, a22,
                 1.0 / (a11 * a22 - a12 * a21), JAHL, JAHR, JAS, JBS)
        iH, iR, iS, hA, hB, kA, kB, sA, sB, a11, a12, a21, a22, idet, JAHL, JAHR, JAS, JBS = F
        yH, yS = rHL * iH, rS * iS
        yR = yH if alike else rHR * iR
        b1 = rA - JAHL * yH - JAHR * yR - JAS * yS
        b2 = rB - nl * (yH + yR) - JBS * yS
        xA = (b1 * a22 - a12 * b2) * idet
        xB = (a11 * b2 - a21 * b1) * idet
        xH = yH - hA * xA - hB * xB
        return ((rA, rHL, rHR, rB, rS),
                (xA, xH, xH if alike else yR - kA * xA - kB * xB, xB, yS - sA * xA - sB * xB),
                F,
                (qPA, qAT, qPB, qBT, qVL, qVR, qrel, qmL, qmR, qmB, qlL, qlR))

    def _newton(self, h: float, s1: float, v: float, p: tuple[float, ...]) -> tuple[float, ...]:
        """Backward-Euler step: damped Newton on R(p) = 0 from the guess p; returns p_{k+1}.

        Globalised by an Armijo backtracking line search on f = Σ(β·R_i/V_i)² (the residual
        of each node expressed as a pressure error [Pa]; the Newton direction is a descent
        direction of f). Converged when the Newton correction |dx|∞ is below newton_tol_Pa,
        or, after a full (undamped) step, when the estimated remaining error
        θ/(1−θ)·|dx|, θ = |dx_k|/|dx_{k−1}| < 1, is below it (Hairer & Wanner, Solving ODEs
        II, IV.8); the correction is applied in both cases.
        """
        tol = self._tol
        V = self._volumes(s1)
        bh = self.beta * h  # the residual is evaluated divided by h
        c = (V[0] / bh, V[1] / bh, V[2] / bh, V[3] / bh, V[4] / bh)
        R, d, F, flows = self._eval(h, c, v, p)
        f = -1.0  # Σ(β·R_i/V_i)² at p, computed when a line search needs it
        pA, pHL, pHR, pB, pS = p
        backtracks = 0
        it = 0
        n_prev, full = math.inf, False
        for it in range(1, self._max_iter + 1):  # noqa: B007 (count reported)
            d0, d1, d2, d3, d4 = d
            n = _absmax(d0, d1, d2, d3, d4)
            if n < tol or (full and n < n_prev and n * n < tol * (n_prev - n)):
                p = (pA - d0, pHL - d1, pHR - d2, pB - d3, pS - d4)
                break
            if f < 0.0:  # first line search: weights β·h/V_i make R_i a pressure error
                w0, w1, w2, w3, w4 = bh / V[0], bh / V[1], bh / V[2], bh / V[3], bh / V[4]
                r0, r1, r2, r3, r4 = R[0] * w0, R[1] * w1, R[2] * w2, R[3] * w3, R[4] * w4
                f = r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3 + r4 * r4
            alpha = 1.0
            while True:
                p = (pA - alpha * d0, pHL - alpha * d1, pHR - alpha * d2, pB - alpha * d3,
                     pS - alpha * d4)
                R, dt, Ft, flt = self._eval(h, c, v, p)
                r0, r1, r2, r3, r4 = R[0] * w0, R[1] * w1, R[2] * w2, R[3] * w3, R[4] * w4
                ft = r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3 + r4 * r4
                if ft <= (1.0 - 1e-4 * alpha) * f or alpha < _MIN_STEP:
                    break
                alpha *= 0.5
                backtracks += 1
            pA, pHL, pHR, pB, pS = p
            d, F, flows, f = dt, Ft, flt, ft
            n_prev, full = n, alpha == 1.0
        else:
            raise RuntimeError(f"hydraulic Newton did not converge in {self._max_iter} "
                               f"iterations (t = {self.t} s, last |dp| = {n} Pa)")
        if self.prescribed:
            p = (p[0], p[1], p[2], p[3], self.ps_next)
        self._iters, self._F, self._flows, self._V1 = it, F, flows, V
        self._backtracks += backtracks
        return p

    def _chord(self, h: float, s1: float, v: float, p: tuple[float, ...],
               F: tuple[float, ...]) -> tuple[float, ...] | None:
        """Backward-Euler step by chord (simplified Newton) corrections from a guess p close
        to the solution, with the factorised Jacobian F of a nearby solve: p_{k+1} once a
        correction |dx|∞ is below newton_tol_Pa (applied), or None if the corrections stop
        contracting or _MAX_CHORD do not converge."""
        tol = self._tol
        V = self._volumes(s1)
        bh = self.beta * h
        c = (V[0] / bh, V[1] / bh, V[2] / bh, V[3] / bh, V[4] / bh)
        n_prev = math.inf
        for it in range(1, _MAX_CHORD + 1):
            _, d, _, flows = self._eval(h, c, v, p, F)
            d0, d1, d2, d3, d4 = d
            n = _absmax(d0, d1, d2, d3, d4)
            if n >= n_prev:
                return None
            p = (p[0] - d0, p[1] - d1, p[2] - d2, p[3] - d3, p[4] - d4)
            if n < tol:
                if self.prescribed:
                    p = (p[0], p[1], p[2], p[3], self.ps_next)
                self._iters, self._flows, self._V1 = it, flows, V
                return p
            n_prev = n
        return None

    def _dpdv(self, p: tuple[float, ...]) -> tuple[float, ...]:
        """dp_{k+1}/dv [Pa·s/m] = −R_p⁻¹·R_v with the last Newton Jacobian (both of R/h);
        −R_v is nonzero on the heads and the rod node only (chamber volumes depend on v)."""
        iH, iR, _, hA, hB, kA, kB, sA, sB, a11, a12, a21, a22, idet, JAHL, JAHR, _, _ = self._F
        p0, ib = self.p, 1.0 / self.beta
        yH = -self.Ah * (ib * (p[1] - p0[1]) + 1.0) * iH
        yR = -self.Ah * (ib * (p[2] - p0[2]) + 1.0) * iR
        b1 = -JAHL * yH - JAHR * yR
        b2 = 2.0 * self.Ar * (ib * (p[3] - p0[3]) + 1.0) + self.leak * (yH + yR)
        xA = (b1 * a22 - a12 * b2) * idet
        xB = (a11 * b2 - a21 * b1) * idet
        return (xA, yH - hA * xA - hB * xB, yR - kA * xA - kB * xB, xB, -sA * xA - sB * xB)

    def _commit(self, p1: tuple[float, ...], s1: float, v: float, h: float,
                accumulate: bool) -> None:
        """Take p1 as the new state and book the step's hydraulic energy terms (added to the
        step ledger's terms when ``accumulate``, else replacing them)."""
        qPA, qAT, qPB, qBT, qVL, qVR, qrel, qmL, qmR, qmB, qlL, qlR = self._flows
        pA, pHL, pHR, pB, pS = p1
        pT, prescribed = self.pT, self.prescribed
        p0, V0, V1 = self.p, self.V, self._V1
        ib2 = 0.5 / self.beta
        # Σ over nodes; V_HL = V_HR, and V_A, V_S do not change with the stroke
        d0, d1, d2, d3 = pA - p0[0], pHL - p0[1], pHR - p0[2], pB - p0[3]
        num = V1[0] * d0 * d0 + V1[1] * (d1 * d1 + d2 * d2) + V1[3] * d3 * d3
        vol = ((V1[1] - V0[1]) * (p0[1] * p0[1] + p0[2] * p0[2])
               + (V1[3] - V0[3]) * p0[3] * p0[3])
        oil = pA * pA * V1[0] + (pHL * pHL + pHR * pHR) * V1[1] + pB * pB * V1[3]
        gas = 0.0
        if not prescribed:
            d4 = pS - p0[4]
            num += V1[4] * d4 * d4
            oil += pS * pS * V1[4]
        num *= ib2
        vol *= -ib2
        oil *= ib2
        if not prescribed:
            voil = self.acc.oil_volume(pS)[0]
            gas = self.acc.energy(pS, voil)
            num += pS * (voil - self._voil0) - (gas - self.ledger.gas_energy_J)
            self._voil0 = voil
        terms = (h * (pS * (qPA + qPB) if prescribed else pS * self.Q_pump),
                 h * pT * (qAT + qBT + qrel - qmL - qmR - qmB),
                 h * ((pS - pA) * qPA + (pA - pT) * qAT + (pS - pB) * qPB + (pB - pT) * qBT),
                 h * (pA - pHL) * qVL,
                 h * (pA - pHR) * qVR,
                 h * (pS - pT) * qrel,
                 (h * ((pT - pHL) * qmL + (pT - pHR) * qmR + (pT - pB) * qmB)
                  if qmL or qmR or qmB else 0.0),
                 h * ((pHL - pB) * qlL + (pHR - pB) * qlR),
                 num,
                 vol,
                 h * v * (self.Ah * (pHL + pHR) - 2.0 * self.Ar * pB))
        sl = self.step_ledger
        if accumulate:
            terms = tuple(a + b for a, b in zip(terms, (
                sl.supply_J, sl.to_tank_J, sl.throttle_main_J, sl.throttle_VL_J,
                sl.throttle_VR_J, sl.throttle_relief_J, sl.throttle_makeup_J, sl.leakage_J,
                sl.numerical_J, sl.volume_term_J, sl.piston_work_J), strict=True))
        (sl.supply_J, sl.to_tank_J, sl.throttle_main_J, sl.throttle_VL_J, sl.throttle_VR_J,
         sl.throttle_relief_J, sl.throttle_makeup_J, sl.leakage_J, sl.numerical_J,
         sl.volume_term_J, sl.piston_work_J) = terms
        sl.oil_energy_J, sl.gas_energy_J = oil, gas
        self.ledger.oil_energy_J, self.ledger.gas_energy_J = oil, gas
        self.p, self.V = p1, V1
