"""Reduced prediction model of the tensioner: one equivalent cylinder + idler mass-spring-damper.

State X = [p_head Pa, p_rod Pa, y m, y_dot m/s] (pressures gauge; y = stroke, grows outward).
Input u in [-1, 1]: continuous equivalent valve opening (time average of the discrete modes):

- u > 0 (pressurize): supply -> head open by fraction u; rod -> tank fully open (main valve at
  rest, line B vents to tank through the main valve's edge, no restrictor).
- u = 0 (hold): heads trapped (V_L, V_R closed), rod -> tank fully open.
- u < 0 (release): head -> tank open by |u|; supply -> rod open by |u| (through the line-B
  feed restrictor), rod -> tank (vent) by 1 - |u|.

At u in {-1, 0, +1} this is exactly the circuit of docs/sizing.md; in between it is the time
average of the modes (what the sum-up-rounding valve logic realises). Orifices follow the
regularised turbulent law Q = Cq A sqrt(2/rho) dp / (dp^2 + p_cr^2)^(1/4).

    dp_h/dt = beta / (V_h0 + A_h y)       (Q_h - A_h y_dot - C_l (p_h - p_r))
    dp_r/dt = beta / (V_r0 + A_r (L - y)) (Q_r + A_r y_dot + C_l (p_h - p_r))
    M y''   = F_ten - k_eq (y - y0) - c_eq y_dot,   F_ten = p_h A_h - p_r A_r  [N]

The same expression is built for CasADi SX (NMPC/LMPC, EKF/UKF) and for Python floats
(the reduced plant).

Drive load (the measured disturbance): a sprocket torque T [N·m] loads the idler by
L = g·max(σ·T, 0) [N] at held stroke (:func:`drive_load_N`; g and σ derived from the
machine's layout, ``trackmj.machines.drive_load``), so the idler holds
F_ten = k_eq (y − y0) + L. It enters the model as the unloaded stroke moved in by L/k_eq:
y0_eff = y0 − L/k_eq, the online parameter the controllers and estimators already carry.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control.params import PlantParams

#: Online parameters theta of the CasADi model: [p_supply Pa, k_eq N/m, y0 m].
N_THETA = 3


def _rhs_generic(
    p: PlantParams, x: Any, u: Any, p_s: Any, k_eq: Any, y0: Any, sqrt: Callable[[Any], Any]
) -> tuple[Any, Any, Any, Any]:
    """State derivative for any scalar algebra (floats with math.sqrt, SX with ca.sqrt)."""
    ph, pr, y, v = x[0], x[1], x[2], x[3]
    eps = p.opening_smoothing
    norm = 1.0 + math.sqrt(1.0 + eps * eps) - eps
    a_pos = (u + sqrt(u * u + eps * eps) - eps) / norm
    a_neg = (-u + sqrt(u * u + eps * eps) - eps) / norm
    kq = p.discharge_coefficient * math.sqrt(2.0 / p.density_kg_m3)
    pc2 = p.critical_pressure_Pa**2

    def orifice(dp: Any) -> Any:
        return kq * dp / sqrt(sqrt(dp * dp + pc2))

    pt = p.tank_pressure_Pa
    q_h = p.valve_area_head_m2 * (a_pos * orifice(p_s - ph) - a_neg * orifice(ph - pt))
    q_r = p.valve_area_rod_m2 * a_neg * orifice(p_s - pr) - p.vent_area_rod_m2 * (
        1.0 - a_neg
    ) * orifice(pr - pt)
    q_l = p.leakage_m3_s_Pa * (ph - pr)
    v_h = p.dead_volume_head_m3 + p.area_head_m2 * y
    v_r = p.dead_volume_rod_m3 + p.area_rod_m2 * (p.stroke_m - y)
    dph = p.bulk_modulus_Pa / v_h * (q_h - p.area_head_m2 * v - q_l)
    dpr = p.bulk_modulus_Pa / v_r * (q_r + p.area_rod_m2 * v + q_l)
    force = ph * p.area_head_m2 - pr * p.area_rod_m2
    acc = (force - k_eq * (y - y0) - p.damping_N_s_m * v) / p.mass_kg
    return dph, dpr, v, acc


def drive_load_N(p: PlantParams, torque_N_m: float) -> float:
    """Idler load L [N] (> 0 pulls the idler in) of the sprocket torque ``torque_N_m`` [N·m]
    at held stroke: g·max(σ·T, 0), the tight side's extra tension on the idler's strands
    (``drive_load_gain_1_m`` g, ``drive_tight_sign`` σ); a NaN torque (no drive measured)
    gives 0."""
    tight = p.drive_tight_sign * torque_N_m
    return p.drive_load_gain_1_m * tight if tight > 0.0 else 0.0


class ReducedModel:
    """Reduced model with numpy/float evaluation and a CasADi twin."""

    def __init__(self, params: PlantParams) -> None:
        self.p = params

    def force(self, x: NDArray[np.float64]) -> float:
        """Tension F_ten = p_h A_h - p_r A_r [N] of state x (shape (4,))."""
        return float(x[0] * self.p.area_head_m2 - x[1] * self.p.area_rod_m2)

    def rhs(
        self, x: NDArray[np.float64], u: float, p_s: float, k_eq: float | None = None
    ) -> NDArray[np.float64]:
        """dX/dt (shape (4,)) for opening u, supply p_s [Pa], stiffness k_eq [N/m]."""
        k = self.p.stiffness_N_m if k_eq is None else k_eq
        return np.array(
            _rhs_generic(self.p, x, u, p_s, k, self.p.free_position_m, math.sqrt), dtype=float
        )

    def casadi_function(self) -> ca.Function:
        """CasADi SX Function f(x[4], u, theta[3]) -> dX/dt[4]; theta = [p_s, k_eq, y0]."""
        x = ca.SX.sym("x", 4)
        u = ca.SX.sym("u")
        th = ca.SX.sym("theta", N_THETA)
        out = _rhs_generic(self.p, x, u, th[0], th[1], th[2], ca.sqrt)
        return ca.Function(
            "reduced_rhs", [x, u, th], [ca.vertcat(*out)], ["x", "u", "theta"], ["xdot"]
        )

    def equilibrium(self, force_N: float) -> NDArray[np.float64]:
        """Hold-mode rest state (4,) at tension force_N [N]: rod at tank, y from the spring."""
        p = self.p
        pr = p.tank_pressure_Pa
        ph = (force_N + pr * p.area_rod_m2) / p.area_head_m2
        y = p.free_position_m + force_N / p.stiffness_N_m
        return np.array((ph, pr, y, 0.0))

    def hold_load_share(self, force_N: float) -> float:
        """Share [-] of an idler load step the tension takes in hold (heads trapped, rod at
        tank) at tension ``force_N`` [N]: the oil spring k_h = β·A_h²/V_h in series with the
        idler's k_eq, ΔF_ten/ΔL = k_h/(k_h + k_eq)."""
        p = self.p
        v_h = p.dead_volume_head_m3 + p.area_head_m2 * self.equilibrium(force_N)[2]
        k_oil = p.bulk_modulus_Pa * p.area_head_m2 ** 2 / v_h
        return k_oil / (k_oil + p.stiffness_N_m)

    def tension_rate_gain(self, force_N: float, p_s: float | None = None) -> float:
        """Quasi-static dF/dt per unit opening [N/s] at tension force_N (u = +1, rod at tank).

        Oil entering the head goes into stroke (spring k_eq) and compression (beta):
        dF/dt = k Q / (A_h + V_h k / (beta A_h)), with Q the full-opening supply flow.
        """
        p = self.p
        ps = p.supply_pressure_Pa if p_s is None else p_s
        x = self.equilibrium(force_N)
        dp = ps - x[0]
        kq = p.discharge_coefficient * math.sqrt(2.0 / p.density_kg_m3)
        q = p.valve_area_head_m2 * kq * dp / (dp * dp + p.critical_pressure_Pa**2) ** 0.25
        v_h = p.dead_volume_head_m3 + p.area_head_m2 * x[2]
        k = p.stiffness_N_m
        return k * q / (p.area_head_m2 + v_h * k / (p.bulk_modulus_Pa * p.area_head_m2))


class ReducedPlant:
    """Fast reduced plant: classical RK4 with ``substeps`` sub-steps per step ``dt`` [s].

    RK4 at 0.5 ms resolves the ~100 Hz oil-column mode (omega*h ~ 0.3, well inside RK4's
    stability region) without the numerical damping an implicit Euler step would add.
    """

    def __init__(
        self, params: PlantParams, x0: NDArray[np.float64], dt: float = 1e-3, substeps: int = 2
    ) -> None:
        if dt <= 0.0 or substeps < 1:
            raise ValueError("dt must be > 0 and substeps >= 1")
        self.p = params
        self.dt = dt
        self.substeps = substeps
        self.x = np.array(x0, dtype=float).reshape(4)
        self.t = 0.0

    @property
    def force(self) -> float:
        """Current tension [N]."""
        return float(self.x[0] * self.p.area_head_m2 - self.x[1] * self.p.area_rod_m2)

    def step(self, u: float, p_s: float, k_eq: float | None = None,
             y0: float | None = None) -> NDArray[np.float64]:
        """Advance one dt with opening u held and supply pressure p_s [Pa]; return X (4,).
        k_eq [N/m] and y0 [m] default to the parameters' stiffness and free position."""
        p = self.p
        k = p.stiffness_N_m if k_eq is None else k_eq
        y0 = p.free_position_m if y0 is None else y0
        h = self.dt / self.substeps
        x = tuple(float(v) for v in self.x)
        for _ in range(self.substeps):
            k1 = _rhs_generic(p, x, u, p_s, k, y0, math.sqrt)
            x2 = tuple(a + 0.5 * h * b for a, b in zip(x, k1, strict=True))
            k2 = _rhs_generic(p, x2, u, p_s, k, y0, math.sqrt)
            x3 = tuple(a + 0.5 * h * b for a, b in zip(x, k2, strict=True))
            k3 = _rhs_generic(p, x3, u, p_s, k, y0, math.sqrt)
            x4 = tuple(a + h * b for a, b in zip(x, k3, strict=True))
            k4 = _rhs_generic(p, x4, u, p_s, k, y0, math.sqrt)
            x = tuple(
                a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4, strict=True)
            )
        self.x = np.array(x)
        self.t += self.dt
        return self.x.copy()
