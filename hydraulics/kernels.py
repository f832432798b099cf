"""Compiled numeric core of the hydraulic tensioner (numba ``njit``; SI, gauge Pa).

Everything the per-step solve computes lives here, once: the scalar component laws, the
backward-Euler residual with its analytic Jacobian, Newton with an Armijo line search, chord
corrections, dp/dv, the force law and the energy bookkeeping. ``HydraulicTensioner`` keeps
the Python side (input checks, valve solenoids, supply profile, records) and calls one
kernel per ``force_law`` and one per ``complete_step``. Under ``NUMBA_DISABLE_JIT=1`` the
same source runs as plain Python (slowly), and ``kernel.py_func`` is the uncompiled kernel.

The laws and kernels share this one file on purpose: numba's on-disk cache (``cache=True``)
is invalidated by a change of the file that defines a function, not by changes of functions
or globals it uses from other files; the array layouts below are such globals (compile-time
constants).

Kernels read a constants array ``const`` (float64[N_CONST], filled once by the tensioner)
and read and write a state array ``state`` (float64[N_STATE]); they return an int status
(OK, NOT_CONVERGED: Newton hit newton_max_iter, the last |dp|∞ [Pa] in state[LAST_DP];
LEFT_PHYSICS: a multi-rate sub-step emptied a chamber, did not converge or went below
absolute vacuum). Node order everywhere: (A, head L, head R, rod node, supply) = line-A
node, the two head chambers, line B + both rod chambers, supply node.

``const`` layout (index: value [unit]):

====================  ===========================================================
C_AH, C_AR            head / rod annulus area per cylinder [m^2]
C_VOL_A, C_VOL_S      line-A node, supply-line volume [m^3]
C_VOL_DH, C_VOL_DR    head / rod dead volume per cylinder [m^3]
C_VOL_LB, C_S_MAX     line-B hose volume [m^3], stroke of a cylinder [m]
C_BETA, C_PT          bulk modulus [Pa], tank pressure [Pa]
C_PCR, C_LEAK         orifice critical pressure [Pa], head->rod leakage [m^3/(s·Pa)]
C_FLOOR, C_BAND       cavitation limiter: 0 at floor, 1 at floor + band [Pa]
C_MU_OPEN, C_MU_WIDTH make-up check valves: crack pressure p_t − crack [Pa], opening band [Pa]
C_K_MU                make-up valve orifice gain [m^3/(s·Pa^0.5)]
C_REL_CRACK, C_REL_WIDTH, C_K_REL  relief S->T: crack pressure of the safety relief
                      (compensated, unloading; fixed_relief's relief cracks at the set-point)
                      [Pa], opening band [Pa], orifice gain when fully open
C_Q_PUMP              fixed pump: delivered flow [m^3/s] (fixed_relief; unloading when loaded)
C_ACC_V0, C_ACC_P0    accumulator gas volume at precharge [m^3], precharge [Pa]
C_P_ATM, C_ACC_N      atmospheric pressure [Pa abs], polytropic exponent [-]
C_FRIC_C, C_FRIC_VS, C_FRIC_B  per-cylinder Coulomb force [N], tanh velocity [m/s],
                      viscous coefficient [N·s/m]
C_ES_K, C_ES_C        per-cylinder end-stop stiffness [N/m], damping [N·s/m]
C_TOL, C_MAX_ITER     Newton tolerance on |dp|∞ [Pa], iteration limit [-]
C_V_CORR, C_MAX_CORR  NEPCE correction: min |v| [m/s], bound [N]
C_PRESCRIBED          1.0 with a prescribed supply pressure (model "prescribed"), else 0.0
C_MODEL               supply model: MODEL_PRESCRIBED, MODEL_FIXED_RELIEF,
                      MODEL_COMPENSATED or MODEL_UNLOADING
C_ACC                 1.0 if the gas accumulator sits on the supply node, else 0.0
C_QG_MAX, C_DROOP     variable pump: geometric flow at full stroke [m^3/s]; compensator
                      regulation range (full stroke at setting − droop, none at the setting) [Pa]
C_TAU, C_K_PUMP_LEAK  variable pump: displacement time constant [s]; internal leakage
                      Q_L = k·p_S [m^3/(s·Pa)]
C_ETA_V, C_ETA_HM     pump volumetric efficiency (fixed pump; 1 for the variable pump, whose
                      leakage is explicit) and hydro-mechanical efficiency [-]
C_P_UNLOADED          unloading model: pump outlet pressure while unloaded [Pa]
C_CUT_IN_REL          unloading model: cut-in pressure / cut-out pressure [-]
C_MV_OVERLAP, C_MV_LEAK, C_MV_OPEN  main valve edges: overlap [-], leak and open area [m^2]
C_SV_OVERLAP, C_SV_LEAK, C_SV_OPEN  switching valves V_L, V_R: the same
C_ROD_FEED, C_HEAD_BRANCH  restrictors in series: rod feed P->B, each head branch [m^2]
C_CQ, C_SQRT_RHO      discharge coefficient [-], sqrt(density) [sqrt(kg/m^3)]
C_TWO                 2.0, the loss-share exponent (read at run time, so the square is
                      libm's pow(x, 2) as in Python, not folded into x·x)
C_AIR, C_AIR_BAND     air out of solution below atmospheric (``released_air``): its
                      fraction α of the chamber volume [-], onset band [Pa]
====================  ===========================================================

``state`` layout (offset, length: content [unit]):

=====================  ==========================================================
P, 5                   node pressures p^k of the last completed step [Pa]
VOL, 5                 node volumes V^k at the last completed stroke [m^3]
VOIL, 1                accumulator oil volume V_oil,acc(p_S^k) [m^3]
GAIN, 6                orifice gains of the step [m^3/(s·Pa^0.5)]: main P->A, A->T, P->B
                       (with the rod-feed restrictor), B->T, V_L, V_R (with restrictors)
FRAC, 3                valve share of the throttling loss of the series paths P->B + rod-feed
                       restrictor, V_L + head restrictor, V_R + head restrictor [-]
SET_NEXT, 1            supply set-point p_set(t_{k+1}) [Pa]: the prescribed pressure, the
                       relief or compensator setting, the unloading valve's cut-out
PUMP_X, 1              variable pump displacement x^k of the last completed step [-]
LOADED, 1              unloading model: 1.0 while the pump charges, 0.0 while unloaded
V_PREV, 1              start velocity of the previous force_law [m/s]
CARRY, 1               cumulative interface residual E_c [J]
LAW, 2                 force law of the step: F0 [N], Z [N·s/m]
CORRECTION, 1          NEPCE correction δF in the law [N]
P_STAR, 5              strong: pressures solved at the predicted velocity v* [Pa]
DPDV, 5                strong: dp/dv at v* [Pa·s/m]
V_STAR, 1              strong: predicted end-of-step velocity v* [m/s]
JAC, 18                factorised Jacobian of the last Newton solve (see ``_factorise``)
FLOWS, 13              flows of the last completed step, FLOW_NAMES order [m^3/s]
ITERS, 1               corrections of the last solve (Newton or chord) [-]
BACKTRACKS, 1          line-search halvings since the last force_law [-]
STEP_BACKTRACKS, 1     halvings in all solves of the last completed step [-]
BACKTRACKS_TOTAL, 1    halvings of all completed steps [-]
LAST_DP, 1             |dp|∞ of the last Newton iteration of a failed solve [Pa]
REC, 6                 last completed step: t [s], stroke [m], velocity [m/s], friction
                       [N] (opposes motion), end-stop force [N] (> 0 outward), piston
                       force over the step A_h(p̄_HL + p̄_HR) − 2·A_r·p̄_B [N] (p̄: the
                       pressures' mean over the step, ``_commit``)
LOG, 9                 ElementLog of the last completed step, LOG_FIELDS order
                       (``trackmj.ports.ElementLog``)
STEP_LEDGER, 30        energy terms of the last step [J], LEDGER_FIELDS order
LEDGER, 30             cumulative energy terms [J], LEDGER_FIELDS order
AREAS, 4               edge areas the gains were computed for [m^2]: main at rest
                       (P->A, B->T), main energised (P->B, A->T), V_L, V_R
AREAS_SET, 1           1.0 once AREAS holds areas
TWINS, 1               1.0 while V_L and V_R have had the same commands (they then move
                       alike and V_R's position is V_L's)
PISTON_IMPULSE, 1      ∫ F_p dt of the current step, Σ h_j·F_p(p̄_j) over its (sub-)steps
                       [N·s] (``book_step`` divides it by h: the step's piston force)
=====================  ==========================================================

Solenoids (valve actuators: electromagnetic delay, then first-order opening; see
``components.Solenoid``) live in a bank ``sol`` float64[n, N_SOL] (rows main, V_L, V_R in
the tensioner) with a ring buffer of pending commands ``pend`` float64[n, capacity, 2]
(time the command takes effect [s], command [-]):

=====================  ==========================================================
S_POS, S_CMD, S_EFF    position, last command, command in force [-] (0 closed, 1 open)
S_MOVING               1.0 unless at rest (nothing pending, position = command in force)
S_DELAY, S_TAU         delay [s], opening time constant [s]
S_HEAD, S_COUNT        first pending slot, pending commands [-]
S_AT_VALID, S_AT_T, S_AT_H, S_AT_X, S_AT_EFF  position and command in force at t + h found
                       by ``valves_at`` (valid until committed or a new command) [s, s, -, -]
=====================  ==========================================================

Supply models (supply row of the residual, node S). ``prescribed``: p_S = p_set(t_{k+1}), an
ideal pressure source. The others integrate
(V_S/β)(p_S − p_S^k) + V_oil,acc(p_S) − V_oil,acc(p_S^k) = h·(Q_pump − Q_PA − Q_PB − Q_rel):

* fixed_relief: Q_pump = Q_d (fixed pump), gas accumulator, relief cracking at p_set;
* compensated: Q_pump = Q_g,max·x_{k+1} − k_L·p_S with x_{k+1} = (x_k + a·x*)/(1 + a),
  a = h/τ, x* = clip((p_set − p_S)/droop, 0, 1) (backward Euler of τ·dx/dt = x* − x); no
  accumulator; safety relief;
* unloading: Q_pump = Q_d while loaded, 0 while unloaded (the pump then circulates to tank
  at p_unloaded); unloads once p_S reaches p_set (cut-out), loads again once p_S falls to
  cut_in_rel·p_set; the state switches between steps; gas accumulator; safety relief.

Pump shaft energy per step (from the prime mover): fixed pump h·p_out·Q_d/(η_v·η_hm) with
p_out = p_S loaded and p_unloaded unloaded; variable pump h·p_S·Q_g/η_hm with the geometric
flow Q_g = Q_pump + k_L·p_S; an ideal source h·p_S·(Q_PA + Q_PB).

Air out of solution (circuit nodes A, HL, HR, B): below atmospheric each node holds
V_g(p, V) of free air (``released_air``); its residual carries −(V_g(p_{k+1}) − V_g(p_k))/h
and its Jacobian diagonal −dV_g/dp/h, both evaluated at the node's end-of-step volume, and
the ledger books the liquid's work on the air, −p̄·ΔV_g, as ``cavitation``.

Losses where they happen (every coupling). Each (sub-)step books a circuit node's flows at
its mean pressure over the step, p̄ = (p_k + p_{k+1})/2 (``_commit``): backward Euler
conserves the oil volume, V·(p_{k+1} − p_k)/β = h·ΣQ − ΔV, so the oil energy V·p²/(2β)
changes by exactly what the flows and the piston carry at p̄ (plus the volume term), and
the circuit needs no ``numerical`` term (``EnergyLedger``). The piston force the track
receives over the step is the one at p̄ (``strong_force_law``, ``book_step``), so the work
the track gets is the piston work the circuit books. Booked and applied at p_{k+1}, each
node lost ½·(V/β)·Δp² per step, a fifth of the circuit energy in W1–W5: the orifice loss of
transients faster than the step (line A, 50 mL behind a main-valve edge cracking open,
τ ≈ 0.05–1 ms), which the edges' terms at p̄ now carry, and a damping of the head oil
spring under the piston (the tooth-passing ripple) that the force at p_{k+1} applied to
the track and no part of the circuit has. Replayed with W1's recorded motion (16 s): piston
work −7.6 J at 0.01 ms, −6.2 J at 1 ms with p̄, −23.7 J at 1 ms with p_{k+1}; the main
valve's, rod-feed and head restrictors' throttling within 1.6 % of the 0.01 ms replay's.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# --------------------------------------------------------------------- layouts
(C_AH, C_AR, C_VOL_A, C_VOL_S, C_VOL_DH, C_VOL_DR, C_VOL_LB, C_S_MAX, C_BETA, C_PT, C_PCR,
 C_LEAK, C_FLOOR, C_BAND, C_MU_OPEN, C_MU_WIDTH, C_K_MU, C_REL_CRACK, C_REL_WIDTH, C_K_REL,
 C_Q_PUMP, C_ACC_V0, C_ACC_P0, C_P_ATM, C_ACC_N, C_FRIC_C, C_FRIC_VS, C_FRIC_B, C_ES_K,
 C_ES_C, C_TOL, C_MAX_ITER, C_V_CORR, C_MAX_CORR, C_PRESCRIBED, C_MODEL, C_ACC, C_QG_MAX,
 C_DROOP, C_TAU, C_K_PUMP_LEAK, C_ETA_V, C_ETA_HM, C_P_UNLOADED, C_CUT_IN_REL,
 C_MV_OVERLAP, C_MV_LEAK, C_MV_OPEN, C_SV_OVERLAP, C_SV_LEAK, C_SV_OPEN, C_ROD_FEED,
 C_HEAD_BRANCH, C_CQ, C_SQRT_RHO, C_TWO, C_AIR, C_AIR_BAND) = range(58)
N_CONST = 58
MODEL_PRESCRIBED, MODEL_FIXED_RELIEF, MODEL_COMPENSATED, MODEL_UNLOADING = 0.0, 1.0, 2.0, 3.0
MODEL_CODES = {"prescribed": MODEL_PRESCRIBED, "fixed_relief": MODEL_FIXED_RELIEF,
               "compensated": MODEL_COMPENSATED, "unloading": MODEL_UNLOADING}
"""C_MODEL value of each supply model."""

LEDGER_FIELDS = ("pump_J", "pump_volumetric_J", "pump_mechanical_J", "unloaded_J",
                 "delivered_J", "relief_J", "circuit_J", "to_tank_J", "throttle_main_J",
                 "throttle_rod_restrictor_J", "throttle_VL_J", "throttle_VR_J",
                 "throttle_head_restrictor_L_J", "throttle_head_restrictor_R_J",
                 "throttle_makeup_J", "leakage_J", "cavitation_J", "friction_J", "endstop_J",
                 "numerical_supply_J", "volume_term_J", "piston_work_J",
                 "mech_work_J", "interface_residual_J", "oil_supply_energy_J", "oil_energy_J",
                 "gas_energy_J", "oil_supply_energy_start_J", "oil_energy_start_J",
                 "gas_energy_start_J")
"""EnergyLedger fields in array order; the first N_FLOW_TERMS accumulate step by step."""
(L_PUMP, L_PUMP_VOLUMETRIC, L_PUMP_MECHANICAL, L_UNLOADED, L_DELIVERED, L_RELIEF, L_CIRCUIT,
 L_TO_TANK, L_THROTTLE_MAIN, L_THROTTLE_ROD_RESTRICTOR, L_THROTTLE_VL, L_THROTTLE_VR,
 L_THROTTLE_HEAD_RESTRICTOR_L, L_THROTTLE_HEAD_RESTRICTOR_R, L_THROTTLE_MAKEUP, L_LEAKAGE,
 L_CAVITATION, L_FRICTION, L_ENDSTOP, L_NUMERICAL_SUPPLY, L_VOLUME_TERM, L_PISTON_WORK,
 L_MECH_WORK, L_INTERFACE_RESIDUAL, L_OIL_SUPPLY_ENERGY, L_OIL_ENERGY, L_GAS_ENERGY,
 L_OIL_SUPPLY_ENERGY_START, L_OIL_ENERGY_START, L_GAS_ENERGY_START) = range(30)
N_LEDGER = 30
N_FLOW_TERMS = 24

P, VOL, VOIL, GAIN, FRAC, SET_NEXT, PUMP_X, LOADED = 0, 5, 10, 11, 17, 20, 21, 22
V_PREV, CARRY, LAW, CORRECTION, P_STAR, DPDV, V_STAR, JAC = 23, 24, 25, 27, 28, 33, 38, 39
FLOWS, ITERS, BACKTRACKS, STEP_BACKTRACKS, BACKTRACKS_TOTAL, LAST_DP = 57, 70, 71, 72, 73, 74
REC, LOG, STEP_LEDGER, LEDGER, AREAS, AREAS_SET, TWINS = 75, 81, 90, 120, 150, 154, 155
PISTON_IMPULSE = 156
LOG_FIELDS = ("t_s", "p_head_Pa", "p_rod_Pa", "p_supply_Pa", "q_supply_m3_s", "force_N",
              "supply_J", "piston_work_J", "mech_work_J")
"""What ``state[LOG + i]`` holds, i = 0..8 (the kernel writes them in this order)."""
N_STATE = 157
(S_POS, S_CMD, S_EFF, S_MOVING, S_DELAY, S_TAU, S_HEAD, S_COUNT, S_AT_VALID, S_AT_T, S_AT_H,
 S_AT_X, S_AT_EFF) = range(13)
N_SOL = 13
ARRIVED = 1e-9  # a solenoid this close to its command [normalised travel] has arrived
N_FLOWS = 13

OK, NOT_CONVERGED, LEFT_PHYSICS = 0, 1, 2
MAX_BACKTRACKS = 12  # line-search halvings per Newton iteration (alpha >= 2^-12)
_MIN_STEP = 2.0 ** -MAX_BACKTRACKS
MAX_CHORD = 3  # chord corrections in a strong complete_step before full Newton
AIR_P_ABS_MIN = 100.0
"""Absolute pressure [Pa] below which ``released_air`` follows its tangent (the law's
V_g ∝ 1/p_abs has no value at absolute zero; a chamber there holds ~αV·p_atm/100 of air)."""
SQRT2 = math.sqrt(2.0)


# --------------------------------------------------------------- component laws
@njit(cache=True)
def orifice_flow(dp_Pa: float, gain: float, p_cr_Pa: float) -> tuple[float, float]:
    """Regularised orifice Q = K·Δp/(Δp²+p_cr²)^(1/4) and dQ/dΔp [m^3/s, m^3/(s·Pa)].

    Tends to K·sign(Δp)·sqrt|Δp| for |Δp| >> p_cr and is linear (K/sqrt(p_cr)) near 0.
    """
    r = dp_Pa * dp_Pa + p_cr_Pa * p_cr_Pa
    r4 = math.sqrt(math.sqrt(r))
    return gain * dp_Pa / r4, gain * (0.5 * dp_Pa * dp_Pa + p_cr_Pa * p_cr_Pa) / (r * r4)


@njit(cache=True)
def smoothstep(x: float) -> tuple[float, float]:
    """C1 step s(x) = 3x²−2x³ clamped to [0, 1], and ds/dx."""
    if x <= 0.0:
        return 0.0, 0.0
    if x >= 1.0:
        return 1.0, 0.0
    return x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x)


@njit(cache=True)
def friction_force(v_m_s: float, coulomb_N: float, v_s_m_s: float,
                   viscous_N_s_m: float) -> tuple[float, float]:
    """Cylinder friction F_f = F_c·tanh(v/v_s) + b·v [N] (opposes motion) and dF_f/dv."""
    th = math.tanh(v_m_s / v_s_m_s)
    return (coulomb_N * th + viscous_N_s_m * v_m_s,
            coulomb_N * (1.0 - th * th) / v_s_m_s + viscous_N_s_m)


@njit(cache=True)
def endstop_force(s_m: float, v_m_s: float, stroke_max_m: float, k_N_m: float,
                  c_N_s_m: float) -> tuple[float, float, float]:
    """End-stop force [N] (> 0 pushes outward), dF/ds and dF/dv; zero inside [0, stroke_max]."""
    if s_m < 0.0:
        return -k_N_m * s_m - c_N_s_m * v_m_s, -k_N_m, -c_N_s_m
    if s_m > stroke_max_m:
        return -k_N_m * (s_m - stroke_max_m) - c_N_s_m * v_m_s, -k_N_m, -c_N_s_m
    return 0.0, 0.0, 0.0


@njit(cache=True)
def accumulator_oil_volume(p_Pa: float, v0_m3: float, p0_Pa: float, p_atm_Pa_abs: float,
                           n: float) -> tuple[float, float]:
    """Polytropic gas accumulator (p_abs·V_gas^n = const above the precharge p0, empty
    below): oil volume V_oil = V0 − V_gas(p) [m^3] and dV_oil/dp [m^3/Pa] at gauge p."""
    if p_Pa <= p0_Pa:
        return 0.0, 0.0
    p_abs = p_Pa + p_atm_Pa_abs
    inv_n = 1.0 / n
    vg = v0_m3 * ((p0_Pa + p_atm_Pa_abs) / p_abs) ** inv_n
    return v0_m3 - vg, vg * inv_n / p_abs


@njit(cache=True)
def accumulator_energy(p_Pa: float, v_oil_m3: float, v0_m3: float, p0_Pa: float,
                       p_atm_Pa_abs: float, n: float) -> float:
    """Accumulator energy [J] relative to the precharged, empty state (gauge basis,
    E = (p_abs·V_gas − p0_abs·V0)/(n−1) − p_atm·V_oil, so dE = p·dV_oil with p gauge);
    v_oil_m3 = accumulator_oil_volume(p_Pa, ...)[0]."""
    if p_Pa <= p0_Pa:
        return 0.0
    return (((p_Pa + p_atm_Pa_abs) * (v0_m3 - v_oil_m3) - (p0_Pa + p_atm_Pa_abs) * v0_m3)
            / (n - 1.0) - p_atm_Pa_abs * v_oil_m3)


@njit(cache=True)
def _limited_orifice(pa: float, pb: float, k: float, pcr: float, la: float, dla: float,
                     lb: float, dlb: float) -> tuple[float, float, float]:
    """Orifice a->b with the upstream cavitation limiter l (value, dl/dp) scaling Q:
    (Q [m^3/s], dQ/dp_a, dQ/dp_b [m^3/(s·Pa)])."""
    q0, g = orifice_flow(pa - pb, k, pcr)
    if pa >= pb:
        return q0 * la, g * la + q0 * dla, -g * la
    return q0 * lb, g * lb, -g * lb + q0 * dlb


@njit(cache=True)
def _limiter(const: np.ndarray, p: float) -> tuple[float, float]:
    """Cavitation limiter of a node's outflow: (l, dl/dp), 1 above floor + band."""
    if p >= const[C_FLOOR] + const[C_BAND]:
        return 1.0, 0.0
    s, ds = smoothstep((p - const[C_FLOOR]) / const[C_BAND])
    return s, ds / const[C_BAND]


@njit(cache=True)
def _makeup(const: np.ndarray, p: float) -> tuple[float, float]:
    """Make-up check valve T -> chamber: (Q [m^3/s], dQ/dp); 0 above its crack pressure."""
    if p >= const[C_MU_OPEN]:
        return 0.0, 0.0
    w = const[C_MU_WIDTH]
    s, ds = smoothstep((const[C_MU_OPEN] - p) / w)
    f, df = orifice_flow(const[C_PT] - p, const[C_K_MU], const[C_PCR])
    return s * f, -ds / w * f - s * df


@njit(cache=True)
def released_air(p_Pa: float, volume_m3: float, alpha: float, band_Pa: float,
                 p_atm_Pa_abs: float) -> tuple[float, float]:
    """Free air in a chamber of volume_m3 [m^3] at gauge pressure p_Pa below atmospheric:
    (V_g [m^3], dV_g/dp [m^3/Pa] ≤ 0); 0 at and above atmospheric.

    Gaseous cavitation as MapleSim's and Simscape's hydraulic chambers approximate it (a
    liquid with a small gas content that expands isothermally as the pressure falls), with
    the gas out of solution only below atmospheric, where the oil in a vented tank is
    saturated: V_g = α·V·r(x)/p_abs, x = −p the depth below atmospheric, p_abs = p_atm − x,
    r(x) = x − b/2 beyond the onset band b and x²/(2b) inside it (so V_g and dV_g/dp are
    continuous at p = 0). V_g grows without bound as p_abs → 0: the liquid never goes into
    tension, the chamber fills with air instead. Below p_abs = AIR_P_ABS_MIN the law goes
    on along its tangent there (V_g and its slope continuous; the slope then takes ~1/20 of
    the chamber per pascal), so Newton's trial points past absolute zero stay finite."""
    x = -p_Pa
    if x <= 0.0 or alpha == 0.0:
        return 0.0, 0.0
    past = 0.0   # depth beyond p_abs = AIR_P_ABS_MIN [Pa], taken along the tangent
    q = p_atm_Pa_abs - x
    if q < AIR_P_ABS_MIN:
        past, x, q = AIR_P_ABS_MIN - q, p_atm_Pa_abs - AIR_P_ABS_MIN, AIR_P_ABS_MIN
    if x < band_Pa:
        r, dr = 0.5 * x * x / band_Pa, x / band_Pa
    else:
        r, dr = x - 0.5 * band_Pa, 1.0
    g = alpha * volume_m3 / q
    slope = g * (dr + r / q)   # dV_g/dx
    return g * r + slope * past, -slope


@njit(cache=True)
def _air(const: np.ndarray, p: float, volume_m3: float) -> tuple[float, float]:
    """``released_air`` with the circuit's constants: (V_g [m^3], dV_g/dp [m^3/Pa])."""
    return released_air(p, volume_m3, const[C_AIR], const[C_AIR_BAND], const[C_P_ATM])


@njit(cache=True)
def _friction(const: np.ndarray, v: float) -> tuple[float, float]:
    """Friction of both cylinders [N] (opposes motion) and its dF/dv [N·s/m]."""
    f, d = friction_force(v, const[C_FRIC_C], const[C_FRIC_VS], const[C_FRIC_B])
    return 2.0 * f, 2.0 * d


@njit(cache=True)
def _endstop(const: np.ndarray, s: float, v: float) -> tuple[float, float, float]:
    """End-stop force of both cylinders [N] (> 0 outward), dF/ds, dF/dv; 0 inside."""
    f, ds, dv = endstop_force(s, v, const[C_S_MAX], const[C_ES_K], const[C_ES_C])
    return 2.0 * f, 2.0 * ds, 2.0 * dv


@njit(cache=True)
def _volumes(const: np.ndarray, s: float) -> tuple[float, float, float, float, float]:
    """Node volumes [m^3] at stroke s [m]: V_HL = V_HR = V_dh + A_h·s,
    V_B = V_lineB + 2(V_dr + A_r(s_max − s))."""
    vh = const[C_VOL_DH] + const[C_AH] * s
    vr = const[C_VOL_LB] + 2.0 * (const[C_VOL_DR] + const[C_AR] * (const[C_S_MAX] - s))
    return const[C_VOL_A], vh, vh, vr, const[C_VOL_S]


@njit(cache=True)
def _nodes(state: np.ndarray, at: int) -> tuple[float, float, float, float, float]:
    """The five node values state[at:at + 5] (pressures, volumes) as a tuple."""
    return state[at], state[at + 1], state[at + 2], state[at + 3], state[at + 4]


@njit(cache=True)
def _oil_energy(const: np.ndarray, p: tuple, V: tuple) -> tuple[float, float]:
    """Stored oil energy p²V/(2β) [J] of the circuit nodes (line A, heads, rod node) and of
    the supply node (0 with a prescribed supply pressure, which is no state)."""
    ib2 = 0.5 / const[C_BETA]
    e = p[0] * p[0] * V[0] + (p[1] * p[1] + p[2] * p[2]) * V[1] + p[3] * p[3] * V[3]
    es = 0.0 if const[C_PRESCRIBED] != 0.0 else p[4] * p[4] * V[4] * ib2
    return e * ib2, es


@njit(cache=True)
def _variable_pump(const: np.ndarray, state: np.ndarray, h: float,
                   pS: float) -> tuple[float, float, float]:
    """Pressure-compensated pump over a step of h [s] ending at supply pressure pS [Pa]:
    (net delivery Q_g,max·x_{k+1} − k_L·pS [m^3/s], its d/dpS [m^3/(s·Pa)], x_{k+1} [-])."""
    a = h / const[C_TAU]
    droop = const[C_DROOP]
    target = (state[SET_NEXT] - pS) / droop
    dtarget = -1.0 / droop
    if target <= 0.0:
        target, dtarget = 0.0, 0.0
    elif target >= 1.0:
        target, dtarget = 1.0, 0.0
    x1 = (state[PUMP_X] + a * target) / (1.0 + a)
    qg, k_leak = const[C_QG_MAX], const[C_K_PUMP_LEAK]
    return qg * x1 - k_leak * pS, qg * a / (1.0 + a) * dtarget - k_leak, x1


# ----------------------------------------------------------- residual and solve
@njit(cache=True)
def _evaluate(const: np.ndarray, state: np.ndarray, h: float, c: tuple, v: float,
              p: tuple) -> tuple[tuple, tuple, tuple]:
    """Backward-Euler residual at pressures p: (R, J, flows).

    R: R/h of the five nodes [m^3/s]; c = V_i(s_{k+1})/(β·h) [m^3/(s·Pa)]. J: the nonzero
    Jacobian entries ∂R/∂p (JAA, JAHL, JAHR, JAS, JHA, JHH, JRA, JRR, JBB, JBS, JSS, JSA,
    JSB) besides J_HB = J_RB = J_BH = J_BR = −leak (H, R = heads L, R). flows: the thirteen
    FLOW_NAMES flows [m^3/s]. With a prescribed supply the supply row is p_S = p_set(t_{k+1});
    the other supply models: see the module docstring.
    """
    pA, pHL, pHR, pB, pS = p
    prescribed = const[C_PRESCRIBED] != 0.0
    if prescribed:
        pS = state[SET_NEXT]
    pT, pcr, leak = const[C_PT], const[C_PCR], const[C_LEAK]
    KPA, KAT, KPB, KBT = state[GAIN], state[GAIN + 1], state[GAIN + 2], state[GAIN + 3]
    KVL, KVR = state[GAIN + 4], state[GAIN + 5]
    lA, dlA = _limiter(const, pA)
    lHL, dlHL = _limiter(const, pHL)
    lHR, dlHR = _limiter(const, pHR)
    lB, dlB = _limiter(const, pB)
    qPA, aPA_S, aPA_A = _limited_orifice(pS, pA, KPA, pcr, 1.0, 0.0, lA, dlA)
    qAT, aAT_A, _ = _limited_orifice(pA, pT, KAT, pcr, lA, dlA, 1.0, 0.0)
    qPB, aPB_S, aPB_B = _limited_orifice(pS, pB, KPB, pcr, 1.0, 0.0, lB, dlB)
    qBT, aBT_B, _ = _limited_orifice(pB, pT, KBT, pcr, lB, dlB, 1.0, 0.0)
    qVL, aVL_A, aVL_H = _limited_orifice(pA, pHL, KVL, pcr, lA, dlA, lHL, dlHL)
    qVR, aVR_A, aVR_H = _limited_orifice(pA, pHR, KVR, pcr, lA, dlA, lHR, dlHR)
    qlL = leak * (pHL - pB)
    qlR = leak * (pHR - pB)
    qmL, dmL = _makeup(const, pHL)
    qmR, dmR = _makeup(const, pHR)
    qmB, dmB = _makeup(const, pB)
    cA, cHL, cHR, cB, cS = c
    Ahv, Arv2 = const[C_AH] * v, 2.0 * const[C_AR] * v
    rA = cA * (pA - state[P]) - qPA + qAT + qVL + qVR
    rHL = cHL * (pHL - state[P + 1]) - qVL + qlL - qmL + Ahv
    rHR = cHR * (pHR - state[P + 2]) - qVR + qlR - qmR + Ahv
    rB = cB * (pB - state[P + 3]) - qPB + qBT - qlL - qlR - qmB - Arv2
    # air out of solution below atmospheric: −ΔV_g/h per node, V = c·β·h
    gA = gHL = gHR = gB = 0.0
    if min(pA, pHL, pHR, pB, state[P], state[P + 1], state[P + 2], state[P + 3]) < 0.0:
        bh, ih = const[C_BETA] * h, 1.0 / h
        for i, pi in enumerate((pA, pHL, pHR, pB)):
            Vi = c[i] * bh
            vg1, dvg = _air(const, pi, Vi)
            r_air, g_air = (_air(const, state[P + i], Vi)[0] - vg1) * ih, -dvg * ih
            if i == 0:
                rA, gA = rA + r_air, g_air
            elif i == 1:
                rHL, gHL = rHL + r_air, g_air
            elif i == 2:
                rHR, gHR = rHR + r_air, g_air
            else:
                rB, gB = rB + r_air, g_air
    qrel = qpump = 0.0
    if prescribed:
        rS, JSS, JSA, JSB = 0.0, 1.0, 0.0, 0.0
    else:
        model = const[C_MODEL]
        dpump = 0.0
        if model == MODEL_COMPENSATED:
            qpump, dpump, _ = _variable_pump(const, state, h, pS)
        elif model == MODEL_FIXED_RELIEF or state[LOADED] != 0.0:
            qpump = const[C_Q_PUMP]
        crack = state[SET_NEXT] if model == MODEL_FIXED_RELIEF else const[C_REL_CRACK]
        drel = 0.0
        if pS > crack:  # relief S -> T, opening over its band (smoothstep)
            w = const[C_REL_WIDTH]
            s, ds = smoothstep((pS - crack) / w)
            f, df = orifice_flow(pS - pT, const[C_K_REL], pcr)
            qrel, drel = s * f, ds / w * f + s * df
        voil1 = dvoil = 0.0
        if const[C_ACC] != 0.0:
            voil1, dvoil = accumulator_oil_volume(pS, const[C_ACC_V0], const[C_ACC_P0],
                                                  const[C_P_ATM], const[C_ACC_N])
        ih = 1.0 / h
        rS = (cS * (pS - state[P + 4]) + (voil1 - state[VOIL]) * ih
              - qpump + qPA + qPB + qrel)
        JSS = cS + dvoil * ih + aPA_S + aPB_S + drel - dpump
        JSA, JSB = aPA_A, aPB_B
    J = (cA + gA - aPA_A + aAT_A + aVL_A + aVR_A, aVL_H, aVR_H, -aPA_S,
         -aVL_A, cHL + gHL - aVL_H - dmL + leak, -aVR_A, cHR + gHR - aVR_H - dmR + leak,
         cB + gB - aPB_B + aBT_B - dmB + 2.0 * leak, -aPB_S, JSS, JSA, JSB)
    return ((rA, rHL, rHR, rB, rS), J,
            (qPA, qAT, qPB, qBT, qVL, qVR, qrel, qmL, qmR, qmB, qlL, qlR, qpump))


@njit(cache=True)
def _factorise(J: tuple, leak: float) -> tuple:
    """Factorise J with the circuit's sparsity: the head rows and the supply row divided by
    their diagonal (x_H = y_H − hA·x_A − hB·x_B, x_R likewise with kA, kB, x_S with sA, sB)
    and eliminated, leaving the 2x2 Schur complement [[a11, a12], [a21, a22]] in (p_A, p_B).
    Returns (iH, iR, iS, hA, hB, kA, kB, sA, sB, a11, a12, a21, a22, 1/det, JAHL, JAHR, JAS,
    JBS); the head rows couple to the rod node only through the leakage."""
    JAA, JAHL, JAHR, JAS, JHA, JHH, JRA, JRR, JBB, JBS, JSS, JSA, JSB = J
    nl = -leak
    iH, iR, iS = 1.0 / JHH, 1.0 / JRR, 1.0 / JSS
    hA, hB, kA, kB, sA, sB = JHA * iH, nl * iH, JRA * iR, nl * iR, JSA * iS, JSB * iS
    a11 = JAA - JAHL * hA - JAHR * kA - JAS * sA
    a12 = -JAHL * hB - JAHR * kB - JAS * sB
    a21 = -nl * (hA + kA) - JBS * sA
    a22 = JBB - nl * (hB + kB) - JBS * sB
    return (iH, iR, iS, hA, hB, kA, kB, sA, sB, a11, a12, a21, a22,
            1.0 / (a11 * a22 - a12 * a21), JAHL, JAHR, JAS, JBS)


@njit(cache=True)
def _solve(F, R: tuple, leak: float) -> tuple[float, float, float, float, float]:
    """d = J⁻¹·R [Pa] with the factorised Jacobian F (a tuple or the state's JAC slice)."""
    nl = -leak
    yH, yR, yS = R[1] * F[0], R[2] * F[1], R[4] * F[2]
    b1 = R[0] - F[14] * yH - F[15] * yR - F[16] * yS
    b2 = R[3] - nl * (yH + yR) - F[17] * yS
    xA = (b1 * F[12] - F[10] * b2) * F[13]
    xB = (F[9] * b2 - F[11] * b1) * F[13]
    return (xA, yH - F[3] * xA - F[4] * xB, yR - F[5] * xA - F[6] * xB, xB,
            yS - F[7] * xA - F[8] * xB)


@njit(cache=True)
def _absmax(d: tuple) -> float:
    """max |d_i| (NaN propagates from d[0] only; a NaN elsewhere is not a maximum)."""
    n = abs(d[0])
    for i in range(1, 5):
        a = abs(d[i])
        if a > n:
            n = a
    return n


@njit(cache=True)
def _weighted_norm2(R: tuple, w: tuple) -> float:
    """Σ(w_i·R_i)² (left to right)."""
    f = 0.0
    for i in range(5):
        r = R[i] * w[i]
        f += r * r
    return f


@njit(cache=True)
def _newton(const: np.ndarray, state: np.ndarray, h: float, s1: float, v: float, p: tuple):
    """Backward-Euler step to stroke s1 at velocity v: damped Newton on R(p) = 0 from p.

    Globalised by an Armijo backtracking line search on f = Σ(β·h·R_i/V_i)² (the residual
    of each node as a pressure error [Pa]; the Newton direction is a descent direction of
    f). Converged when the Newton correction |dx|∞ is below newton_tol_Pa, or, after a full
    (undamped) step, when the estimated remaining error θ/(1−θ)·|dx|, θ = |dx_k|/|dx_{k−1}|
    < 1, is below it (Hairer & Wanner, Solving ODEs II, IV.8); the correction is applied in
    both cases. Returns (converged, p_{k+1}, iterations, backtracks, F, flows, V(s1),
    last |dx|∞).
    """
    tol, leak = const[C_TOL], const[C_LEAK]
    V = _volumes(const, s1)
    bh = const[C_BETA] * h  # the residual is evaluated divided by h
    c = (V[0] / bh, V[1] / bh, V[2] / bh, V[3] / bh, V[4] / bh)
    w = (bh / V[0], bh / V[1], bh / V[2], bh / V[3], bh / V[4])
    R, J, flows = _evaluate(const, state, h, c, v, p)
    F = _factorise(J, leak)
    d = _solve(F, R, leak)
    f = -1.0  # Σ(w_i·R_i)² at p, computed when a line search needs it
    backtracks = 0
    it = 0
    n = math.inf
    n_prev, full, converged = math.inf, False, False
    for it in range(1, int(const[C_MAX_ITER]) + 1):  # noqa: B007 (count reported)
        n = _absmax(d)
        if n < tol or (full and n < n_prev and n * n < tol * (n_prev - n)):
            p = (p[0] - d[0], p[1] - d[1], p[2] - d[2], p[3] - d[3], p[4] - d[4])
            converged = True
            break
        if f < 0.0:
            f = _weighted_norm2(R, w)
        alpha = 1.0
        while True:
            pt = (p[0] - alpha * d[0], p[1] - alpha * d[1], p[2] - alpha * d[2],
                  p[3] - alpha * d[3], p[4] - alpha * d[4])
            R, J, flows = _evaluate(const, state, h, c, v, pt)
            ft = _weighted_norm2(R, w)
            if ft <= (1.0 - 1e-4 * alpha) * f or alpha < _MIN_STEP:
                break
            alpha *= 0.5
            backtracks += 1
        p, f = pt, ft
        F = _factorise(J, leak)
        d = _solve(F, R, leak)
        n_prev, full = n, alpha == 1.0
    if const[C_PRESCRIBED] != 0.0:
        p = (p[0], p[1], p[2], p[3], state[SET_NEXT])
    return converged, p, it, backtracks, F, flows, V, n


@njit(cache=True)
def _chord(const: np.ndarray, state: np.ndarray, h: float, s1: float, v: float, p: tuple):
    """Backward-Euler step by chord (simplified Newton) corrections from a guess p close to
    the solution, with the factorised Jacobian in state[JAC] (of force_law's solve).
    Returns (converged, p_{k+1}, corrections, flows, V(s1)); converged once a correction
    |dx|∞ is below newton_tol_Pa (applied), not if the corrections stop contracting or
    MAX_CHORD do not converge."""
    tol, leak = const[C_TOL], const[C_LEAK]
    F = state[JAC:JAC + 18]
    V = _volumes(const, s1)
    bh = const[C_BETA] * h
    c = (V[0] / bh, V[1] / bh, V[2] / bh, V[3] / bh, V[4] / bh)
    n_prev = math.inf
    for it in range(1, MAX_CHORD + 1):
        R, _, flows = _evaluate(const, state, h, c, v, p)
        d = _solve(F, R, leak)
        n = _absmax(d)
        if n >= n_prev:
            return False, p, it, flows, V
        p = (p[0] - d[0], p[1] - d[1], p[2] - d[2], p[3] - d[3], p[4] - d[4])
        if n < tol:
            if const[C_PRESCRIBED] != 0.0:
                p = (p[0], p[1], p[2], p[3], state[SET_NEXT])
            return True, p, it, flows, V
        n_prev = n
    return False, p, MAX_CHORD, flows, V  # pyright: ignore[reportPossiblyUnboundVariable]  # MAX_CHORD >= 1 loops


@njit(cache=True)
def _dpdv(const: np.ndarray, state: np.ndarray, F: tuple, p: tuple) -> tuple:
    """dp_{k+1}/dv [Pa·s/m] = −R_p⁻¹·R_v with the factorised Jacobian F (both of R/h);
    −R_v is nonzero on the heads and the rod node only (chamber volumes depend on v)."""
    iH, iR, _, hA, hB, kA, kB, sA, sB, a11, a12, a21, a22, idet, JAHL, JAHR, _, _ = F
    ib = 1.0 / const[C_BETA]
    yH = -const[C_AH] * (ib * (p[1] - state[P + 1]) + 1.0) * iH
    yR = -const[C_AH] * (ib * (p[2] - state[P + 2]) + 1.0) * iR
    b1 = -JAHL * yH - JAHR * yR
    b2 = 2.0 * const[C_AR] * (ib * (p[3] - state[P + 3]) + 1.0) + const[C_LEAK] * (yH + yR)
    xA = (b1 * a22 - a12 * b2) * idet
    xB = (a11 * b2 - a21 * b1) * idet
    return (xA, yH - hA * xA - hB * xB, yR - kA * xA - kB * xB, xB, -sA * xA - sB * xB)


# -------------------------------------------------------------- bookkeeping
@njit(cache=True)
def _enter(state: np.ndarray, i: int, x: float, accumulate: bool) -> None:
    """state[i] = state[i] + x if accumulate, else x."""
    state[i] = state[i] + x if accumulate else x


@njit(cache=True)
def _book_supply(const: np.ndarray, state: np.ndarray, pS: float, q_out: float, h: float,
                 accumulate: bool) -> None:
    """Book the source side of a step ending at supply pressure pS [Pa] with the supply
    node's outflow q_out = Q_PA + Q_PB [m^3/s]: pump shaft energy, pump losses, unloaded
    circulation, delivered energy (into the supply node); commit the variable pump's
    displacement and switch the unloading valve for the next step."""
    model, sl, a = const[C_MODEL], STEP_LEDGER, accumulate
    delivered = vol = mech = unloaded = 0.0
    if model == MODEL_PRESCRIBED:   # ideal pressure source
        delivered = h * pS * q_out
        pump = delivered
    elif model == MODEL_COMPENSATED:
        q, _, x1 = _variable_pump(const, state, h, pS)
        geometric = h * pS * (q + const[C_K_PUMP_LEAK] * pS)   # p_S·Q_g·h
        delivered = h * pS * q
        vol = geometric - delivered                              # leakage k_L·p_S²·h
        pump = geometric / const[C_ETA_HM]
        mech = pump - geometric
        state[PUMP_X] = x1
    else:
        loaded = model == MODEL_FIXED_RELIEF or state[LOADED] != 0.0
        p_out = pS if loaded else const[C_P_UNLOADED]
        hydraulic = h * p_out * const[C_Q_PUMP]
        if loaded:
            delivered = hydraulic
        else:
            unloaded = hydraulic
        geometric = hydraulic / const[C_ETA_V]
        vol = geometric - hydraulic
        pump = geometric / const[C_ETA_HM]
        mech = pump - geometric
        if model == MODEL_UNLOADING:
            if loaded and pS >= state[SET_NEXT]:
                state[LOADED] = 0.0
            elif not loaded and pS <= const[C_CUT_IN_REL] * state[SET_NEXT]:
                state[LOADED] = 1.0
    _enter(state, sl + L_PUMP, pump, a)
    _enter(state, sl + L_PUMP_VOLUMETRIC, vol, a)
    _enter(state, sl + L_PUMP_MECHANICAL, mech, a)
    _enter(state, sl + L_UNLOADED, unloaded, a)
    _enter(state, sl + L_DELIVERED, delivered, a)


@njit(cache=True)
def _mean(a: tuple, b: tuple) -> tuple[float, float, float, float, float]:
    """(a + b)/2 of two node tuples [Pa]: a backward-Euler step's pressure taken linear in
    time, its mean over the step."""
    return (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]),
            0.5 * (a[3] + b[3]), 0.5 * (a[4] + b[4]))


@njit(cache=True)
def _commit(const: np.ndarray, state: np.ndarray, p1: tuple, V1: tuple, flows: tuple,
            v: float, h: float, accumulate: bool) -> None:
    """Take p1, V1 as the new state and book the step's hydraulic energy terms into the step
    ledger (added to its terms when ``accumulate``, else replacing them)."""
    qPA, qAT, qPB, qBT, qVL, qVR, qrel, qmL, qmR, qmB, qlL, qlR, _ = flows
    pT, prescribed = const[C_PT], const[C_PRESCRIBED] != 0.0
    p0 = _nodes(state, P)
    pS = p1[4]
    pA, pHL, pHR, pB = _mean(p0, p1)[:4]   # circuit nodes booked at their step mean
    V0 = _nodes(state, VOL)
    ib2 = 0.5 / const[C_BETA]
    # V_HL = V_HR, and V_A, V_S do not change with the stroke
    vol = -ib2 * ((V1[1] - V0[1]) * (p0[1] * p0[1] + p0[2] * p0[2])
                  + (V1[3] - V0[3]) * p0[3] * p0[3])
    oil, oil_supply = _oil_energy(const, p1, V1)
    gas = num_supply = 0.0
    if not prescribed:
        d4 = pS - p0[4]
        num_supply = V1[4] * d4 * d4 * ib2
        if const[C_ACC] != 0.0:
            v0, pc, pa, n = const[C_ACC_V0], const[C_ACC_P0], const[C_P_ATM], const[C_ACC_N]
            voil = accumulator_oil_volume(pS, v0, pc, pa, n)[0]
            gas = accumulator_energy(pS, voil, v0, pc, pa, n)
            num_supply += pS * (voil - state[VOIL]) - (gas - state[LEDGER + L_GAS_ENERGY])
            state[VOIL] = voil
    makeup = 0.0
    if qmL != 0.0 or qmR != 0.0 or qmB != 0.0:
        makeup = h * ((pT - pHL) * qmL + (pT - pHR) * qmR + (pT - pB) * qmB)
    f_pb, f_vl, f_vr = state[FRAC], state[FRAC + 1], state[FRAC + 2]
    loss_pb, loss_vl, loss_vr = h * (pS - pB) * qPB, h * (pA - pHL) * qVL, h * (pA - pHR) * qVR
    sl, a = STEP_LEDGER, accumulate
    _book_supply(const, state, pS, qPA + qPB, h, a)
    _enter(state, sl + L_RELIEF, h * pS * qrel, a)
    _enter(state, sl + L_CIRCUIT, h * pS * (qPA + qPB), a)
    _enter(state, sl + L_TO_TANK, h * pT * (qAT + qBT - qmL - qmR - qmB), a)
    _enter(state, sl + L_THROTTLE_MAIN,
           h * ((pS - pA) * qPA + (pA - pT) * qAT + (pB - pT) * qBT) + f_pb * loss_pb, a)
    _enter(state, sl + L_THROTTLE_ROD_RESTRICTOR, (1.0 - f_pb) * loss_pb, a)
    _enter(state, sl + L_THROTTLE_VL, f_vl * loss_vl, a)
    _enter(state, sl + L_THROTTLE_VR, f_vr * loss_vr, a)
    _enter(state, sl + L_THROTTLE_HEAD_RESTRICTOR_L, (1.0 - f_vl) * loss_vl, a)
    _enter(state, sl + L_THROTTLE_HEAD_RESTRICTOR_R, (1.0 - f_vr) * loss_vr, a)
    _enter(state, sl + L_THROTTLE_MAKEUP, makeup, a)
    _enter(state, sl + L_LEAKAGE, h * ((pHL - pB) * qlL + (pHR - pB) * qlR), a)
    cav = 0.0   # −Σ p̄·ΔV_g: the liquid's work on the air out of solution (EnergyLedger)
    if min(p0[0], p0[1], p0[2], p0[3], p1[0], p1[1], p1[2], p1[3]) < 0.0:
        for i, pm in enumerate((pA, pHL, pHR, pB)):
            Vi = V1[i]
            cav -= pm * (_air(const, p1[i], Vi)[0] - _air(const, p0[i], Vi)[0])
    _enter(state, sl + L_CAVITATION, cav, a)
    _enter(state, sl + L_NUMERICAL_SUPPLY, num_supply, a)
    _enter(state, sl + L_VOLUME_TERM, vol, a)
    fp = const[C_AH] * (pHL + pHR) - 2.0 * const[C_AR] * pB
    _enter(state, sl + L_PISTON_WORK, h * v * fp, a)
    _enter(state, PISTON_IMPULSE, h * fp, a)
    state[sl + L_OIL_SUPPLY_ENERGY] = state[LEDGER + L_OIL_SUPPLY_ENERGY] = oil_supply
    state[sl + L_OIL_ENERGY] = state[LEDGER + L_OIL_ENERGY] = oil
    state[sl + L_GAS_ENERGY] = state[LEDGER + L_GAS_ENERGY] = gas
    for i in range(5):
        state[P + i] = p1[i]
        state[VOL + i] = V1[i]
    for i in range(N_FLOWS):
        state[FLOWS + i] = flows[i]


@njit(cache=True)
def book_step(const: np.ndarray, state: np.ndarray, t1: float, h: float, s1: float,
              v1: float) -> None:
    """Close the step ending at (t1, s1, v1): mechanical terms of the step ledger, interface
    residual and its carry, cumulative ledger, line-search count, record and log values.
    The strong and weak completions end with it; multi-rate calls it after its sub-steps."""
    ff = _friction(const, v1)[0]
    fes = _endstop(const, s1, v1)[0]
    sl, led = STEP_LEDGER, LEDGER
    state[sl + L_FRICTION] = ff * v1 * h
    state[sl + L_ENDSTOP] = -fes * v1 * h
    state[sl + L_MECH_WORK] = (state[LAW] + state[LAW + 1] * v1) * v1 * h  # law.at(v1)
    state[sl + L_INTERFACE_RESIDUAL] = (state[sl + L_PISTON_WORK] - state[sl + L_FRICTION]
                                        - state[sl + L_ENDSTOP] - state[sl + L_MECH_WORK])
    state[CARRY] += state[sl + L_INTERFACE_RESIDUAL]
    for i in range(N_FLOW_TERMS):
        state[led + i] += state[sl + i]
    state[STEP_BACKTRACKS] = state[BACKTRACKS]
    state[BACKTRACKS_TOTAL] += state[BACKTRACKS]
    ph = state[P + 1] + state[P + 2]
    fp = state[PISTON_IMPULSE] / h   # over the step: at its mean pressures (``_commit``)
    state[REC], state[REC + 1], state[REC + 2] = t1, s1, v1
    state[REC + 3], state[REC + 4], state[REC + 5] = ff, fes, fp
    state[LOG], state[LOG + 1], state[LOG + 2], state[LOG + 3] = (t1, 0.5 * ph, state[P + 3],
                                                                  state[P + 4])
    state[LOG + 4] = state[FLOWS] + state[FLOWS + 2]
    state[LOG + 5] = fp - ff + fes
    state[LOG + 6] = state[led + L_PUMP]
    state[LOG + 7] = state[led + L_PISTON_WORK]
    state[LOG + 8] = state[led + L_MECH_WORK]


# ------------------------------------------------------------------ kernels
@njit(cache=True)
def initialise(const: np.ndarray, state: np.ndarray, stroke_m: float) -> None:
    """Fill the volumes, accumulator oil volume, stored energies (both ledgers' start and
    current values) and the static force law from the pressures in state[P]."""
    p = _nodes(state, P)
    V = _volumes(const, stroke_m)
    gas = 0.0
    if const[C_PRESCRIBED] == 0.0 and const[C_ACC] != 0.0:
        v0, pc, pa, n = const[C_ACC_V0], const[C_ACC_P0], const[C_P_ATM], const[C_ACC_N]
        state[VOIL] = accumulator_oil_volume(p[4], v0, pc, pa, n)[0]
        gas = accumulator_energy(p[4], state[VOIL], v0, pc, pa, n)
    oil, oil_supply = _oil_energy(const, p, V)
    for i in range(5):
        state[VOL + i] = V[i]
    state[LEDGER + L_OIL_SUPPLY_ENERGY] = state[LEDGER + L_OIL_SUPPLY_ENERGY_START] = oil_supply
    state[LEDGER + L_OIL_ENERGY] = state[LEDGER + L_OIL_ENERGY_START] = oil
    state[LEDGER + L_GAS_ENERGY] = state[LEDGER + L_GAS_ENERGY_START] = gas
    state[LAW] = const[C_AH] * (p[1] + p[2]) - 2.0 * const[C_AR] * p[3]
    state[LAW + 1] = 0.0


@njit(cache=True)
def _keep_solve(state: np.ndarray, iterations: int, backtracks: int, F: tuple) -> None:
    """Book a converged Newton solve: its iterations and halvings, its factorised Jacobian
    in state[JAC] (for dp/dv and the chord corrections)."""
    state[BACKTRACKS] += backtracks
    state[ITERS] = iterations
    for i in range(18):
        state[JAC + i] = F[i]


@njit(cache=True)
def strong_force_law(const: np.ndarray, state: np.ndarray, h: float, s: float,
                     v: float) -> int:
    """Strong coupling's law for the step from (s, v) (see ``HydraulicTensioner``): solve at
    v* = 2v − v_prev, dp/dv, F(v*) and Z = dF/dv with the piston force at the pressures'
    mean over the step (p^k + p*)/2 (what the completion books), NEPCE correction; writes
    state[LAW]."""
    state[BACKTRACKS] = 0.0
    v_star = 2.0 * v - state[V_PREV]
    state[V_PREV] = v
    s1 = s + h * v_star
    ok, p1, it, bt, F, _, _, n = _newton(const, state, h, s1, v_star, _nodes(state, P))
    if not ok:
        state[LAST_DP] = n
        return NOT_CONVERGED
    _keep_solve(state, it, bt, F)
    dpdv = _dpdv(const, state, F, p1)
    for i in range(5):
        state[P_STAR + i] = p1[i]
        state[DPDV + i] = dpdv[i]
    state[V_STAR] = v_star
    # F(v*) and Z = dF/dv: mean pressures through dp/dv (d(p̄)/dv = ½·dp/dv), friction, end
    # stop (s1 = s_k + h·v)
    ah, ar2 = const[C_AH], 2.0 * const[C_AR]
    pm = _mean(_nodes(state, P), p1)
    ff, dff = _friction(const, v_star)
    fes, dfes_ds, dfes_dv = _endstop(const, s1, v_star)
    f_star = ah * (pm[1] + pm[2]) - ar2 * pm[3] - ff + fes
    z = 0.5 * (ah * (dpdv[1] + dpdv[2]) - ar2 * dpdv[3]) - dff + dfes_ds * h + dfes_dv
    corr = 0.0
    if abs(v) >= const[C_V_CORR]:
        cmax = const[C_MAX_CORR]
        corr = max(-cmax, min(cmax, state[CARRY] / (h * v)))
    state[CORRECTION] = corr
    state[LAW] = f_star - z * v_star + corr
    state[LAW + 1] = z
    return OK


@njit(cache=True)
def strong_complete(const: np.ndarray, state: np.ndarray, t1: float, h: float, s1: float,
                    v1: float) -> int:
    """Strong coupling's completion: from the linear predictor p* + dp/dv·(v1 − v*), chord
    corrections with force_law's Jacobian, full Newton if they stop contracting; commit,
    book the step."""
    dv = v1 - state[V_STAR]
    guess = (state[P_STAR] + state[DPDV] * dv, state[P_STAR + 1] + state[DPDV + 1] * dv,
             state[P_STAR + 2] + state[DPDV + 2] * dv, state[P_STAR + 3] + state[DPDV + 3] * dv,
             state[P_STAR + 4] + state[DPDV + 4] * dv)
    ok, p1, it, flows, V1 = _chord(const, state, h, s1, v1, guess)
    if not ok:
        ok, p1, it, bt, F, flows, V1, n = _newton(const, state, h, s1, v1, guess)
        if not ok:
            state[LAST_DP] = n
            return NOT_CONVERGED
        _keep_solve(state, it, bt, F)
    else:
        state[ITERS] = it
    _commit(const, state, p1, V1, flows, v1, h, False)
    book_step(const, state, t1, h, s1, v1)
    return OK


@njit(cache=True)
def held_force_law(const: np.ndarray, state: np.ndarray, s: float, v: float) -> None:
    """Weak / multi-rate law from the last completed pressures: pressure force + end stop at
    (s, v), friction linearised at v (Z = −dF_fric/dv); writes state[LAW]."""
    ff, dff = _friction(const, v)
    fes = _endstop(const, s, v)[0]
    state[LAW] = (const[C_AH] * (state[P + 1] + state[P + 2]) - 2.0 * const[C_AR] * state[P + 3]
                  - (ff - dff * v) + fes)
    state[LAW + 1] = -dff


@njit(cache=True)
def weak_complete(const: np.ndarray, state: np.ndarray, t1: float, h: float, s1: float,
                  v1: float) -> int:
    """Weak coupling's completion: Newton from the last pressures at (s1, v1), commit, book."""
    ok, p1, it, bt, F, flows, V1, n = _newton(const, state, h, s1, v1, _nodes(state, P))
    if not ok:
        state[LAST_DP] = n
        return NOT_CONVERGED
    _keep_solve(state, it, bt, F)
    _commit(const, state, p1, V1, flows, v1, h, False)
    book_step(const, state, t1, h, s1, v1)
    return OK


@njit(cache=True)
def multirate_substep(const: np.ndarray, state: np.ndarray, h: float, s1: float, v: float,
                      accumulate: bool) -> int:
    """One multi-rate BE sub-step of length h to stroke s1 at the held velocity v, committed
    (its energy terms added to the step ledger's when ``accumulate``); LEFT_PHYSICS, state
    untouched, if a chamber volume is ≤ 0, Newton does not converge or a pressure falls
    below absolute vacuum."""
    V = _volumes(const, s1)
    if min(V[0], V[1], V[2], V[3], V[4]) <= 0.0:
        return LEFT_PHYSICS
    ok, p1, it, bt, F, flows, V1, _ = _newton(const, state, h, s1, v, _nodes(state, P))
    if not ok:
        return LEFT_PHYSICS
    for x in p1:
        if not (math.isfinite(x) and x >= -const[C_P_ATM]):
            return LEFT_PHYSICS
    _keep_solve(state, it, bt, F)
    _commit(const, state, p1, V1, flows, v, h, accumulate)
    return OK


# --------------------------------------------------------------- valves
@njit(cache=True)
def solenoid_at(sol: np.ndarray, pend: np.ndarray, i: int, t: float,
                h: float) -> tuple[float, float]:
    """(position, command in force) of solenoid i at t + h without committing: the last
    pending command due by then (1e-12 s slack) is in force, the position follows it
    exactly over h, x = c + (x0 − c)·exp(−h/τ)."""
    eff = sol[i, S_EFF]
    if sol[i, S_MOVING] == 0.0:
        return eff, eff
    t_end = t + h
    head, count, cap = int(sol[i, S_HEAD]), int(sol[i, S_COUNT]), pend.shape[1]
    for j in range(count):
        slot = (head + j) % cap
        if pend[i, slot, 0] <= t_end + 1e-12:
            eff = pend[i, slot, 1]
        else:
            break
    return eff + (sol[i, S_POS] - eff) * math.exp(-h / sol[i, S_TAU]), eff


@njit(cache=True)
def solenoid_commit(sol: np.ndarray, pend: np.ndarray, i: int, t: float, h: float,
                    x: float, eff: float) -> None:
    """Move solenoid i to t + h at position x with command eff in force (what
    ``solenoid_at(t, h)`` gave): drop the commands due, snap within ARRIVED."""
    t_end = t + h
    head, count, cap = int(sol[i, S_HEAD]), int(sol[i, S_COUNT]), pend.shape[1]
    while count > 0 and pend[i, head, 0] <= t_end + 1e-12:
        head = (head + 1) % cap
        count -= 1
    sol[i, S_HEAD], sol[i, S_COUNT] = head, count
    if abs(x - eff) < ARRIVED:
        x = eff
    sol[i, S_POS], sol[i, S_EFF] = x, eff
    sol[i, S_MOVING] = 1.0 if count > 0 or x != eff else 0.0
    sol[i, S_AT_VALID] = 0.0


@njit(cache=True)
def valve_area(position: float, overlap: float, leak_m2: float, open_m2: float) -> float:
    """Opening area [m^2] of a valve edge at normalised position (0 closed, 1 open):
    linear from the leak area at ``overlap`` to the open area at 1."""
    u = (position - overlap) / (1.0 - overlap)
    u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
    return leak_m2 + (open_m2 - leak_m2) * u


@njit(cache=True)
def series_area(a1_m2: float, a2_m2: float) -> float:
    """Equivalent area [m^2] of two turbulent orifices in series: (a1^-2 + a2^-2)^-1/2."""
    if a1_m2 <= 0.0 or a2_m2 <= 0.0:
        return 0.0
    return a1_m2 * a2_m2 / math.sqrt(a1_m2 * a1_m2 + a2_m2 * a2_m2)


@njit(cache=True)
def _gain(const: np.ndarray, area_m2: float) -> float:
    """Turbulent orifice gain K = Cq·A·sqrt(2)/sqrt(ρ) [m^3/s/sqrt(Pa)]."""
    return const[C_CQ] * area_m2 * SQRT2 / const[C_SQRT_RHO]


@njit(cache=True)
def _share(const: np.ndarray, valve_m2: float, series_m2: float) -> float:
    """Valve share of a valve + restrictor series path's loss, (A_eff/A_valve)²; 1 closed."""
    if valve_m2 <= 0.0 or series_m2 <= 0.0:
        return 1.0
    return math.pow(series_m2 / valve_m2, const[C_TWO])


@njit(cache=True)
def valves_at(const: np.ndarray, state: np.ndarray, sol: np.ndarray, pend: np.ndarray,
              t: float, h: float) -> None:
    """Valve positions at t + h (kept in the bank for ``valves_advance``) -> the edge areas
    and, for the edges whose area changed, the orifice gains state[GAIN] and the loss
    shares state[FRAC]; nothing while every valve rests and the areas are known."""
    if state[AREAS_SET] != 0.0 and (sol[0, S_MOVING] == 0.0 and sol[1, S_MOVING] == 0.0
                                    and sol[2, S_MOVING] == 0.0):
        return
    twins = state[TWINS] != 0.0
    xm, em = solenoid_at(sol, pend, 0, t, h)
    xl, el = solenoid_at(sol, pend, 1, t, h)
    xr, er = (xl, el) if twins else solenoid_at(sol, pend, 2, t, h)
    for i, x, e in ((0, xm, em), (1, xl, el), (2, xr, er)):
        sol[i, S_AT_VALID], sol[i, S_AT_T], sol[i, S_AT_H] = 1.0, t, h
        sol[i, S_AT_X], sol[i, S_AT_EFF] = x, e
    a_rest = valve_area(1.0 - xm, const[C_MV_OVERLAP], const[C_MV_LEAK], const[C_MV_OPEN])
    a_ener = valve_area(xm, const[C_MV_OVERLAP], const[C_MV_LEAK], const[C_MV_OPEN])
    a_l = valve_area(xl, const[C_SV_OVERLAP], const[C_SV_LEAK], const[C_SV_OPEN])
    a_r = a_l if twins else valve_area(xr, const[C_SV_OVERLAP], const[C_SV_LEAK],
                                       const[C_SV_OPEN])
    known = state[AREAS_SET] != 0.0
    if (known and a_rest == state[AREAS] and a_ener == state[AREAS + 1]
            and a_l == state[AREAS + 2] and a_r == state[AREAS + 3]):
        return
    if not known or a_rest != state[AREAS] or a_ener != state[AREAS + 1]:
        a_pb = series_area(a_ener, const[C_ROD_FEED])
        g_rest = _gain(const, a_rest)
        state[GAIN], state[GAIN + 1], state[GAIN + 2], state[GAIN + 3] = (
            g_rest, _gain(const, a_ener), _gain(const, a_pb), g_rest)
        state[FRAC] = _share(const, a_ener, a_pb)
    if not known or a_l != state[AREAS + 2]:
        a_vl = series_area(a_l, const[C_HEAD_BRANCH])
        state[GAIN + 4], state[FRAC + 1] = _gain(const, a_vl), _share(const, a_l, a_vl)
    if not known or a_r != state[AREAS + 3]:
        if a_r == a_l:   # alike valves at the same opening: the same values
            state[GAIN + 5], state[FRAC + 2] = state[GAIN + 4], state[FRAC + 1]
        else:
            a_vr = series_area(a_r, const[C_HEAD_BRANCH])
            state[GAIN + 5], state[FRAC + 2] = _gain(const, a_vr), _share(const, a_r, a_vr)
    state[AREAS], state[AREAS + 1], state[AREAS + 2], state[AREAS + 3] = (a_rest, a_ener,
                                                                          a_l, a_r)
    state[AREAS_SET] = 1.0


@njit(cache=True)
def valves_advance(state: np.ndarray, sol: np.ndarray, pend: np.ndarray, t: float,
                   h: float) -> None:
    """Commit the solenoids' motion over [t, t + h] (those at rest stay put), with the
    positions ``valves_at`` found for the same (t, h) if it did; twins: V_R as V_L."""
    for i in range(3):
        if i == 2 and state[TWINS] != 0.0:
            for j in range(N_SOL):
                sol[2, j] = sol[1, j]
            break
        if sol[i, S_MOVING] == 0.0:
            sol[i, S_AT_VALID] = 0.0
            continue
        if sol[i, S_AT_VALID] != 0.0 and sol[i, S_AT_T] == t and sol[i, S_AT_H] == h:
            x, eff = sol[i, S_AT_X], sol[i, S_AT_EFF]
        else:
            x, eff = solenoid_at(sol, pend, i, t, h)
        solenoid_commit(sol, pend, i, t, h, x, eff)


@njit(cache=True)
def strong_step_law(const: np.ndarray, state: np.ndarray, sol: np.ndarray, pend: np.ndarray,
                    t: float, h: float, s: float, v: float) -> int:
    """``valves_at(t, h)``, then ``strong_force_law``: a strong force_law in one call."""
    valves_at(const, state, sol, pend, t, h)
    return strong_force_law(const, state, h, s, v)


@njit(cache=True)
def strong_step_complete(const: np.ndarray, state: np.ndarray, sol: np.ndarray,
                         pend: np.ndarray, t0: float, t1: float, s1: float, v1: float) -> int:
    """``strong_complete`` over [t0, t1], then (if it converged) ``valves_advance``."""
    h = t1 - t0
    status = strong_complete(const, state, t1, h, s1, v1)
    if status == OK:
        valves_advance(state, sol, pend, t0, h)
    return status
