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
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from trackmj.control.model import ReducedModel
from trackmj.control.params import EstimatorParams


class _KalmanBase:
    """Shared state, covariances and the linear measurement update."""

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
        self.innovation = np.zeros(3)
        self.S = self.R.copy()
        self._eye = np.eye(4)
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

    def _accumulate(self) -> None:
        self._sum += self.x
        self._count += 1

    def _discrete(
        self, x: NDArray[np.float64], u: float, p_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One linearly-implicit trapezoidal step: (x+ (4,), transition matrix F (4, 4))."""
        h = self.dt
        f, jac = self.model.rhs_and_jacobian(x, u, p_s)
        hj = (0.5 * h) * jac
        m_inv = np.linalg.inv(self._eye - hj)
        return x + m_inv @ (h * f), m_inv @ (self._eye + hj)

    def _update(self, z: NDArray[np.float64]) -> None:
        P = self.P
        self.innovation = z - self.x[:3]
        S = P[:3, :3] + self.R
        self.S = S
        # explicit symmetric 3x3 inverse (adjugate): ~4x cheaper than a LAPACK call here
        (a, b, c), (_, d, e), (_, _, f) = S.tolist()
        c0, c1, c2 = d * f - e * e, c * e - b * f, b * e - c * d
        r = 1.0 / (a * c0 + b * c1 + c * c2)
        s_inv = np.array(
            (
                (c0 * r, c1 * r, c2 * r),
                (c1 * r, (a * f - c * c) * r, (b * c - a * e) * r),
                (c2 * r, (b * c - a * e) * r, (a * d - b * b) * r),
            )
        )
        gain = P[:, :3] @ s_inv  # (4, 3)
        self.x = self.x + gain @ self.innovation
        P = P - gain @ P[:3, :]
        self.P = 0.5 * (P + P.T)

    @property
    def nis(self) -> float:
        """Normalised innovation squared of the last update (chi-square, 3 dof)."""
        return float(self.innovation @ np.linalg.solve(self.S, self.innovation))

    def nees(self, x_true: NDArray[np.float64]) -> float:
        """Normalised estimation error squared against the true state (chi-square, 4 dof)."""
        e = x_true - self.x
        return float(e @ np.linalg.solve(self.P, e))


class ExtendedKalmanFilter(_KalmanBase):
    """EKF; ``step(z, u, p_s)`` predicts over dt with applied opening u and supply p_s [Pa],
    then updates with z (3,). Returns the posterior state (4,) (a view; do not modify)."""

    def step(self, z: NDArray[np.float64], u: float, p_s: float) -> NDArray[np.float64]:
        self.x, F = self._discrete(self.x, u, p_s)
        self.P = F @ self.P @ F.T + self.Q
        self._update(z)
        self._accumulate()
        return self.x


class UnscentedKalmanFilter(_KalmanBase):
    """UKF with scaled sigma points (alpha, beta, kappa from params; 2n+1 = 9 points).

    alpha = 1, kappa = -1 gives lambda = -1, centre weights W_m0 = -1/3, W_c0 = 5/3 and a
    spread of sqrt(3) sigma: well-conditioned, unlike alpha = 1e-3 (W_m0 ~ -1e6).
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

    def step(self, z: NDArray[np.float64], u: float, p_s: float) -> NDArray[np.float64]:
        L = np.linalg.cholesky(self.P) * self.gamma
        pts = np.empty((9, 4))
        pts[0] = self.x
        pts[1:5] = self.x + L.T
        pts[5:] = self.x - L.T
        prop = np.array([self._discrete(p, u, p_s)[0] for p in pts])
        self.x = self.wm @ prop
        d = prop - self.x
        self.P = (d.T * self.wc) @ d + self.Q
        self._update(z)
        self._accumulate()
        return self.x
