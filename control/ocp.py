"""Tension-tracking optimal control problem shared by NMPC (nonlinear) and LMPC (linearised).

Discretisation: N intervals of the controller period Ts, Radau IIA collocation of degree d on
each (d = 1 is implicit Euler); L-stable, so the stiff oil column cannot destabilise the
prediction. Inputs are move-blocked: one value per ``block_steps`` intervals (block length
>= the valve's minimum holding time, so planned inputs are realisable by the valve logic).

Decision variables (scaled: pressures MPa, stroke mm, velocity 0.1 m/s; this scaling balances
the implicit-Euler Jacobian entries to O(1-10); with mm/s the QPs stalled, measured):
w = [u_0 .. u_{nb-1}, s_1 .. s_N, X_{i,j} for i < N, j = 1..d], s_i >= 0 soft-band slacks.
Parameters p = [x0 (4, SI), F_ref_0..N (N+1, N), u_prev, theta (p_s Pa, k_eq N/m, y0 m),
F_min N, F_max N, p_min Pa, p_max Pa], and for the linear OCP the affine model (c, A, B).

Cost: sum_i w_F (F_i - F_ref_i)^2 [kN^2] + sum_b L (w_u u_b^2 + w_du (u_b - u_{b-1})^2)
+ w_s s_i^2; constraints F_min - s_i <= F_i <= F_max + s_i (soft), p_min <= p <= p_max (hard)
at nodes 1..N, u_min <= u <= u_max. The cost is quadratic in w, so its Hessian is the exact
Gauss-Newton Hessian (constraint curvature dropped).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control.model import N_THETA, ReducedModel
from trackmj.control.params import ControllerParams, MpcParams, resolved

X_SCALE = np.array((1e6, 1e6, 1e-3, 0.1))  # SI per scaled unit: MPa, mm, 0.1 m/s


@dataclass(frozen=True)
class Ocp:
    """Symbolic problem and bookkeeping for a solver."""

    w: ca.SX
    p: ca.SX
    f: ca.SX
    g: ca.SX
    lbg: NDArray[np.float64]
    ubg: NDArray[np.float64]
    lbw: NDArray[np.float64]
    ubw: NDArray[np.float64]
    n_blocks: int
    n_param: int
    node_force_kN: ca.SX  # predicted tension at nodes 1..N [kN], shape (N,)


def radau_matrices(d: int) -> tuple[list[float], NDArray[np.float64]]:
    """Radau IIA points tau (with tau_0 = 0) and derivative matrix C[r, j] = l_r'(tau_j)."""
    tau = [0.0, *ca.collocation_points(d, "radau")]
    c = np.zeros((d + 1, d + 1))
    for r in range(d + 1):
        poly = np.poly1d([1.0])
        for s in range(d + 1):
            if s != r:
                poly *= np.poly1d([1.0, -tau[s]]) / (tau[r] - tau[s])
        dpoly = np.polyder(poly)
        for j in range(d + 1):
            c[r, j] = dpoly(tau[j])
    return tau, c


#: Number of linear-model parameters appended to p by ``build_ocp(linear=True)``:
#: c (4), A (4x4, column-major), B (4) of xdot = c + A x + B u (SI).
N_LINEAR = 24


def linearisation_function(model: ReducedModel) -> ca.Function:
    """CasADi Function (x_op (4,), u_op, theta (3,)) -> [c; vec(A); B] (24,) with
    xdot ~ c + A x + B u the first-order Taylor model at (x_op, u_op) (SI)."""
    xs, us, ths = ca.SX.sym("x", 4), ca.SX.sym("u"), ca.SX.sym("th", N_THETA)
    fx = model.casadi_function()(xs, us, ths)
    a, b = ca.jacobian(fx, xs), ca.jacobian(fx, us)
    c = fx - ca.mtimes(a, xs) - b * us
    return ca.Function("linearisation", [xs, us, ths], [ca.vertcat(c, ca.vec(a), b)])


def build_ocp(
    model: ReducedModel, ctrl: ControllerParams, mpc: MpcParams, linear: bool = False
) -> Ocp:
    """Build the OCP on the nonlinear reduced model, or with ``linear`` on the affine model
    xdot = c + A x + B u whose (c, A, B) are the last ``N_LINEAR`` parameters (a QP in w
    whose linearisation point can change at every solve without rebuilding)."""
    n, d, nb = mpc.horizon_steps, mpc.collocation_degree, mpc.horizon_steps // mpc.block_steps
    h = ctrl.period_s
    _, cmat = radau_matrices(d)
    f_c: Callable[[ca.SX, ca.SX, ca.SX], ca.SX] = model.casadi_function()
    extra = []
    if linear:
        lin_p = ca.SX.sym("lin", N_LINEAR)
        extra = [lin_p]
        a_mat = ca.reshape(lin_p[4:20], 4, 4)

        def f_linear(x: ca.SX, u_: ca.SX, _theta: ca.SX) -> ca.SX:
            return lin_p[:4] + ca.mtimes(a_mat, x) + lin_p[20:] * u_

        f_c = f_linear

    x0 = ca.SX.sym("x0", 4)
    ref = ca.SX.sym("ref", n + 1)
    u_prev = ca.SX.sym("u_prev")
    theta = ca.SX.sym("theta", N_THETA)
    lim = ca.SX.sym("lim", 4)  # F_min, F_max, p_min, p_max (SI)
    p = ca.vertcat(x0, ref, u_prev, theta, lim, *extra)

    u = ca.SX.sym("u", nb)
    s = ca.SX.sym("s", n)
    xc = [ca.SX.sym(f"x_{i}", 4, d) for i in range(n)]
    w = ca.vertcat(u, s, *[ca.vec(x) for x in xc])
    scale = ca.DM(X_SCALE)
    ah, ar = model.p.area_head_m2, model.p.area_rod_m2

    g, lbg, ubg = [], [], []
    cost = ca.SX(0)
    forces = []
    x_start = x0 / scale
    for i in range(n):
        ui = u[i // mpc.block_steps]
        pts = [x_start] + [xc[i][:, j] for j in range(d)]
        for j in range(1, d + 1):
            slope = sum(cmat[r, j] * pts[r] for r in range(d + 1))
            g.append(h * f_c(scale * pts[j], ui, theta) / scale - slope)
            lbg += [0.0] * 4
            ubg += [0.0] * 4
        x_end = pts[d]
        f_kn = (x_end[0] * ah - x_end[1] * ar) * 1e3  # MPa * m^2 * 1e3 = kN
        forces.append(f_kn)
        cost += mpc.weight_force_per_kN2 * (f_kn - ref[i + 1] / 1e3) ** 2
        cost += mpc.weight_force_slack_per_kN2 * s[i] ** 2
        g += [f_kn - s[i] - lim[1] / 1e3, lim[0] / 1e3 - f_kn - s[i]]
        g += [x_end[0] - lim[3] / 1e6, x_end[1] - lim[3] / 1e6]
        g += [lim[2] / 1e6 - x_end[0], lim[2] / 1e6 - x_end[1]]
        lbg += [-np.inf] * 6
        ubg += [0.0] * 6
        x_start = x_end
    for b in range(nb):
        prev = u_prev if b == 0 else u[b - 1]
        cost += mpc.block_steps * (
            mpc.weight_input * u[b] ** 2 + mpc.weight_input_rate * (u[b] - prev) ** 2
        )
    n_x = 4 * d * n
    lbw = np.concatenate((np.full(nb, ctrl.u_min), np.zeros(n), np.full(n_x, -np.inf)))
    ubw = np.concatenate((np.full(nb, ctrl.u_max), np.full(n, np.inf), np.full(n_x, np.inf)))
    return Ocp(
        w,
        p,
        cost,
        ca.vertcat(*g),
        np.array(lbg),
        np.array(ubg),
        lbw,
        ubw,
        nb,
        int(p.numel()),
        ca.vertcat(*forces),
    )


def parameter_vector(
    x0: NDArray[np.float64],
    ref: NDArray[np.float64],
    u_prev: float,
    theta: NDArray[np.float64],
    ctrl: ControllerParams,
) -> NDArray[np.float64]:
    """Assemble the OCP parameter vector p (see module docstring)."""
    lim = (resolved(ctrl, "force_min_N"), resolved(ctrl, "force_max_N"), ctrl.pressure_min_Pa,
           ctrl.pressure_max_Pa)
    return np.concatenate((x0, ref, (u_prev,), theta, lim))


def initial_guess(
    ocp_n: int, d: int, n_blocks: int, x0: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Cold start: zero inputs and slacks, every collocation state at x0 (scaled)."""
    xs = np.tile(np.asarray(x0) / X_SCALE, d * ocp_n)
    return np.concatenate((np.zeros(n_blocks + ocp_n), xs))
