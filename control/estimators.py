"""State estimators (EKF, UKF) for X = [p_head Pa, p_rod Pa, y m, y_dot m/s] from
z = [p_head Pa, p_rod Pa, y m] sampled every dt [s] (1 ms).

Process model: the reduced model discretised by one linearly-implicit trapezoidal step,
x+ = x + (I - h/2 J)^-1 h f(x, u),  F = (I - h/2 J)^-1 (I + h/2 J),
with the hand-derived Jacobian J (no symbolic work per step). It is A-stable, so the ~100 Hz
oil-column mode neither blows up nor is damped away at h = 1 ms.

Noise: the study's Q = diag(0.2^2, 0.3^2, 0.05^2, 0.1^2) and R = diag(0.15^2, 0.15^2, 0.02^2)
are read in (MPa, MPa, mm, mm/s) for Q and (MPa, MPa, cm -> 0.2 mm) for R as discrete
per-sample covariances; see ``models/lf1352_control.toml`` for the reasoning. SI inside.
The measurement is linear (H = [I3 0]), so both filters share the exact linear update.

The arithmetic is written once for scalars (floats or CasADi SX): the EKF's whole 1 kHz step
(predict + update) is one SX function evaluated on the filter's own arrays through a
:class:`~trackmj.control.fastcall.BufferedFunction` (22 -> ~4 us per step, measured); the UKF
propagates its sigma points with the same step in floats and shares the SX update.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control.fastcall import BufferedFunction
from trackmj.control.model import ReducedModel, _rhs_jacobian_generic
from trackmj.control.params import EstimatorParams, PlantParams

Matrix = tuple[tuple[Any, ...], ...]


def _trapezoid_step(x: Any, f: Any, jac: Matrix, h: float) -> tuple[tuple[Any, ...], Matrix]:
    """One linearly-implicit trapezoidal step for any scalar algebra: (x+ (4), F (4x4)).

    M = I - c J with c = h/2; x+ = x + M^-1 h f, F = M^-1 (I + c J) = 2 M^-1 - I. M^-1 in
    closed form: row 2 of J is (0, 0, 0, 1) (dy/dt = v), so x2 = y2 + c x3 eliminates y and
    leaves a 3x3 system on (p_h, p_r, v) inverted by its adjugate.
    """
    c = 0.5 * h
    (j00, j01, j02, j03), (j10, j11, j12, j13), _, (j30, j31, j32, j33) = jac
    # reduced matrix N on (p_h, p_r, v): N[i] = (m_i0, m_i1, m_i3 + c m_i2), m = I - c J
    n00, n01, n02 = 1.0 - c * j00, -c * j01, -c * j03 - c * c * j02
    n10, n11, n12 = -c * j10, 1.0 - c * j11, -c * j13 - c * c * j12
    n20, n21, n22 = -c * j30, -c * j31, 1.0 - c * j33 - c * c * j32
    a00, a01, a02 = n11 * n22 - n12 * n21, n02 * n21 - n01 * n22, n01 * n12 - n02 * n11
    a10, a11, a12 = n12 * n20 - n10 * n22, n00 * n22 - n02 * n20, n02 * n10 - n00 * n12
    a20, a21, a22 = n10 * n21 - n11 * n20, n01 * n20 - n00 * n21, n00 * n11 - n01 * n10
    r = 1.0 / (n00 * a00 + n01 * a10 + n02 * a20)
    # column 2 of M^-1: -N^-1 (m_02, m_12, m_32) with m_i2 = -c j_i2
    v0, v1, v2 = c * j02, c * j12, c * j32
    k0 = (a00 * v0 + a01 * v1 + a02 * v2) * r
    k1 = (a10 * v0 + a11 * v1 + a12 * v2) * r
    k3 = (a20 * v0 + a21 * v1 + a22 * v2) * r
    m_inv = (
        (a00 * r, a01 * r, k0, a02 * r),
        (a10 * r, a11 * r, k1, a12 * r),
        (c * a20 * r, c * a21 * r, 1.0 + c * k3, c * a22 * r),
        (a20 * r, a21 * r, k3, a22 * r),
    )
    hf = [h * fi for fi in f]
    x_next = tuple(x[i] + sum(m_inv[i][j] * hf[j] for j in range(4)) for i in range(4))
    trans = tuple(
        tuple(2.0 * m_inv[i][j] - (1.0 if i == j else 0.0) for j in range(4)) for i in range(4)
    )
    return x_next, trans


def _sx(rows: Matrix) -> ca.SX:
    return ca.vertcat(*[ca.horzcat(*row) for row in rows])


def _update_sx(x: ca.SX, P: ca.SX, z: ca.SX, r: ca.SX) -> tuple[ca.SX, ...]:
    """Linear update with H = [I3 0]: gain K = P[:, :3] S^-1 (4, 3), S = P[:3, :3] + diag(r);
    S^-1 by the explicit symmetric 3x3 adjugate. Returns (x+, P+ symmetrised, innovation,
    S^-1)."""
    innovation = z - x[:3]
    a, b, c, d, e, f = P[0, 0] + r[0], P[0, 1], P[0, 2], P[1, 1] + r[1], P[1, 2], P[2, 2] + r[2]
    c0, c1, c2 = d * f - e * e, c * e - b * f, b * e - c * d
    q = 1.0 / (a * c0 + b * c1 + c * c2)
    c4, c5 = (b * c - a * e) * q, (a * d - b * b) * q
    s_inv = _sx(((c0 * q, c1 * q, c2 * q), (c1 * q, (a * f - c * c) * q, c4), (c2 * q, c4, c5)))
    gain = ca.mtimes(P[:, :3], s_inv)
    P_new = P - ca.mtimes(gain, P[:3, :])
    return x + ca.mtimes(gain, innovation), 0.5 * (P_new + P_new.T), innovation, s_inv


def _symbols() -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    return ca.SX.sym("x", 4), ca.SX.sym("P", 4, 4), ca.SX.sym("z", 3), ca.SX.sym("r", 3)


@functools.cache
def _update_function() -> ca.Function:
    """(x (4), P (4x4), z (3), r (3)) -> (x+, P+, innovation, S^-1 (3x3))."""
    x, P, z, r = _symbols()
    return ca.Function("kf_update", [x, P, z, r], [ca.densify(v) for v in _update_sx(x, P, z, r)])


@functools.cache
def _ekf_function(plant: PlantParams, dt: float) -> ca.Function:
    """One EKF step (x, P, z, (u, p_s), Q, r) -> (x+, P+, innovation, S^-1): predict with the
    trapezoidal step and the hand-derived Jacobian, P- = F P F^T + Q, then the update."""
    x, P, z, r = _symbols()
    ups, Q = ca.SX.sym("u_ps", 2), ca.SX.sym("Q", 4, 4)
    xs = [x[i] for i in range(4)]
    f, jac = _rhs_jacobian_generic(plant, xs, ups[0], ups[1], ca.sqrt)
    x_pred, trans = _trapezoid_step(xs, f, jac, dt)
    F = _sx(trans)
    P_pred = ca.mtimes([F, P, F.T]) + Q
    outs = _update_sx(ca.vertcat(*x_pred), P_pred, z, r)
    return ca.Function("ekf_step", [x, P, z, ups, Q, r], [ca.densify(v) for v in outs])


class _KalmanBase:
    """Shared state, covariances and the linear measurement update.

    ``x`` (4,) and ``P`` (4, 4) are updated in place (the compiled steps are bound to them);
    P and Q are symmetric, so the column-major view CasADi takes of them is the same matrix.
    """

    def __init__(
        self, model: ReducedModel, params: EstimatorParams, dt: float, x0: NDArray[np.float64]
    ) -> None:
        if dt <= 0.0:
            raise ValueError(f"dt = {dt} must be > 0")
        self.model = model
        self.dt = dt
        self.Q = np.diag(np.square(params.process_std))
        self.R = np.diag(np.square(params.measurement_std))
        self.x = np.array(x0, dtype=float).reshape(4)
        self.P = np.diag(np.square(params.initial_std))
        self._r = np.square(np.asarray(params.measurement_std, dtype=float))
        self._z = np.zeros(3)
        self._x_out, self._P_out = np.zeros(4), np.zeros((4, 4))
        self.innovation, self._s_inv = np.zeros(3), np.linalg.inv(self.P[:3, :3] + self.R)
        self._outputs = [self._x_out, self._P_out, self.innovation, self._s_inv]
        self._sum = np.zeros(4)
        self._count = 0

    def period_mean(self) -> NDArray[np.float64]:
        """Mean posterior state (4,) over the steps since the last call (decimation filter).

        The controller runs every 10 samples; the boxcar mean of the 1 kHz posteriors is the
        anti-aliasing filter before that downsampling. With the study's large Q the posterior
        tension is nearly as noisy as the sensors (~340 N rms); the mean over one period cuts
        it ~3x for ~half a period of lag. Returns the current state if no step was taken.
        """
        mean = self._sum / self._count if self._count else self.x.copy()
        self._sum[:] = 0.0
        self._count = 0
        return mean

    def _finish(self, step: BufferedFunction) -> None:
        """Evaluate ``step`` (writes x+, P+, innovation, S^-1), take x+ and P+, accumulate."""
        step()
        self.x[:] = self._x_out
        self.P[:] = self._P_out
        self._sum += self.x
        self._count += 1

    @property
    def nis(self) -> float:
        """Normalised innovation squared of the last update (chi-square, 3 dof)."""
        return float(self.innovation @ self._s_inv @ self.innovation)

    def nees(self, x_true: NDArray[np.float64]) -> float:
        """Normalised estimation error squared against the true state (chi-square, 4 dof)."""
        e = x_true - self.x
        return float(e @ np.linalg.solve(self.P, e))


class ExtendedKalmanFilter(_KalmanBase):
    """EKF; ``step(z, u, p_s)`` predicts over dt with applied opening u and supply p_s [Pa],
    then updates with z (3,). Returns the posterior state (4,) (a view; do not modify).

    Parameters
    ----------
    model : ReducedModel
        Process model (the hand-derived Jacobian of its right-hand side).
    params : EstimatorParams
        Process, measurement and initial standard deviations (SI, per 1 ms sample).
    dt : float
        Sample period [s].
    x0 : ndarray, shape (4,)
        Initial state (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s]).
    """

    def __init__(
        self, model: ReducedModel, params: EstimatorParams, dt: float, x0: NDArray[np.float64]
    ) -> None:
        super().__init__(model, params, dt, x0)
        self._u_ps = np.zeros(2)
        self._step = BufferedFunction(
            _ekf_function(model.p, dt), [self.x, self.P, self._z, self._u_ps, self.Q, self._r],
            self._outputs)

    def step(self, z: NDArray[np.float64], u: float, p_s: float) -> NDArray[np.float64]:
        self._z[:] = z
        self._u_ps[0] = u
        self._u_ps[1] = p_s
        self._finish(self._step)
        return self.x


class UnscentedKalmanFilter(_KalmanBase):
    """UKF with scaled sigma points (alpha, beta, kappa from params; 2n+1 = 9 points).

    alpha = 1, kappa = -1 gives lambda = -1, centre weights W_m0 = -1/3, W_c0 = 5/3 and a
    spread of sqrt(3) sigma: well-conditioned, unlike alpha = 1e-3 (W_m0 ~ -1e6).

    Parameters
    ----------
    model : ReducedModel
        Process model (each sigma point takes one trapezoidal step of it).
    params : EstimatorParams
        Standard deviations (SI, per 1 ms sample) and the sigma-point spread.
    dt : float
        Sample period [s].
    x0 : ndarray, shape (4,)
        Initial state (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s]).
    """

    def __init__(
        self, model: ReducedModel, params: EstimatorParams, dt: float, x0: NDArray[np.float64]
    ) -> None:
        super().__init__(model, params, dt, x0)
        n = 4
        a, b, k = params.ukf_alpha, params.ukf_beta, params.ukf_kappa
        lam = a * a * (n + k) - n
        if n + lam <= 0.0:
            raise ValueError(f"UKF: n + lambda = {n + lam} must be > 0 (alpha, kappa)")
        self.gamma = np.sqrt(n + lam)
        self.wm = np.full(2 * n + 1, 0.5 / (n + lam))
        self.wc = self.wm.copy()
        self.wm[0] = lam / (n + lam)
        self.wc[0] = self.wm[0] + 1.0 - a * a + b
        self._update = BufferedFunction(
            _update_function(), [self.x, self.P, self._z, self._r], self._outputs)

    def _propagate(self, x: NDArray[np.float64], u: float, p_s: float) -> tuple[float, ...]:
        """One trapezoidal step of a sigma point (floats)."""
        xs = tuple(x.tolist())
        f, jac = _rhs_jacobian_generic(self.model.p, xs, u, p_s, math.sqrt)
        return _trapezoid_step(xs, f, jac, self.dt)[0]

    def step(self, z: NDArray[np.float64], u: float, p_s: float) -> NDArray[np.float64]:
        L = np.linalg.cholesky(self.P) * self.gamma
        pts = np.empty((9, 4))
        pts[0] = self.x
        pts[1:5] = self.x + L.T
        pts[5:] = self.x - L.T
        prop = np.array([self._propagate(p, u, p_s) for p in pts])
        self.x[:] = self.wm @ prop
        d = prop - self.x
        self.P[:] = (d.T * self.wc) @ d + self.Q
        self._z[:] = z
        self._finish(self._update)
        return self.x
