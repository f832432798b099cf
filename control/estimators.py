"""State estimators (EKF, UKF) for X = [p_head Pa, p_rod Pa, y m, y_dot m/s, y0 m] from
z = [p_head Pa, p_rod Pa, y m] sampled every dt [s] (1 ms), with the measured sprocket drive
torque z[3] [N·m] (when given) as a known input.

The fifth state is a disturbance state: y0, the stroke at which the equivalent idler is
unloaded, as a random walk. The reduced model's idler is a linear spring
F = k·(y − y0) + c·ẏ + M·ÿ; the real track is not (ground and contact friction creep, a
hitch load moves the running gear), so its equilibrium stroke for a given force wanders.
Estimating y0 makes the model's equilibrium agree with the measured force and stroke, which
is what makes the MPC offset-free (it takes ŷ0 as its online parameter) and lets it see a
load disturbance on the idler as such (the input-disturbance model of offset-free MPC,
e.g. Pannocchia & Rawlings 2003, with the disturbance entering as an idler load
k·Δy0).

The drive torque is a measured disturbance, not estimated: its idler load L [N]
(:func:`~trackmj.control.model.drive_load_N`) moves the model's unloaded stroke to
y0 − L/k_eq, so a traction change is explained by the torque and y0 keeps only what the
torque does not explain. The torque is low-passed first (first order,
``drive_torque_filter_s``): a speed-servoed sprocket's torque swings by several times its
mean at tooth engagement (M113 at 1.5 m/s: 160 ± 470 N·m, peaks 2.2 kN·m), which neither
the valves nor a strand's tension over a controller period follow, and the load law's
max(σT, 0) would rectify into a bias. ``period_mean`` appends the period's mean L for the
controllers.

Process model: the reduced model (:mod:`trackmj.control.model`) with y0 constant,
discretised by one linearly-implicit trapezoidal step x+ = x + (I − h/2·J)⁻¹·h·f(x, u),
F = (I − h/2·J)⁻¹(I + h/2·J) with J the exact Jacobian (CasADi algorithmic
differentiation); A-stable, so the ~100 Hz oil-column mode neither blows up nor is damped
away at h = 1 ms.

Noise: the study's Q = diag(0.2², 0.3², 0.05², 0.1²) and R = diag(0.15², 0.15², 0.02²)
are read in (MPa, MPa, mm, mm/s) for Q and (MPa, MPa, cm -> 0.2 mm) for R as discrete
per-sample covariances (see ``models/lf1352_control.toml``), plus our own y0 random-walk
variance. SI inside. The measurement is linear (H = [I3 0 0]), so both filters share the
exact linear update.

The whole 1 kHz EKF step (predict + update) and the UKF's sigma-point step are SX
functions evaluated on the filter's own arrays, compiled to machine code
(:mod:`trackmj.control.compiled`, bit-identical to CasADi's virtual machine).
"""

from __future__ import annotations

import functools
import math

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control.compiled import Bound, bind
from trackmj.control.model import ReducedModel, _rhs_generic, drive_load_N
from trackmj.control.params import EstimatorParams, PlantParams

N_STATE = 5
"""Estimated state: p_head [Pa], p_rod [Pa], y [m], ẏ [m/s], y0 [m]."""
N_MEAS = 3
N_INPUT = 3
"""Known inputs of a step: valve opening u [-], supply pressure p_s [Pa], drive load L [N]."""


SCALE = np.array((1e6, 1e6, 1e-3, 0.1, 1e-3))
"""SI per scaled unit of the state (MPa, MPa, mm, 0.1 m/s, mm): the implicit step's linear
solves are done on the scaled system, whose entries are O(1-10); unscaled (Pa next to m)
the elimination loses the y0 row to round-off (measured: F's y0 row off by 1e-3)."""


def _trapezoid_sx(plant: PlantParams, x: ca.SX, u: ca.SX, p_s: ca.SX, load: ca.SX,
                  h: float) -> tuple[ca.SX, ca.SX]:
    """One linearly-implicit trapezoidal step of the augmented model with the drive's idler
    load ``load`` [N] held: (x+, F)."""
    k = plant.stiffness_N_m
    f = ca.vertcat(*_rhs_generic(plant, [x[i] for i in range(4)], u, p_s,
                                 k, x[4] - load / k, ca.sqrt), 0)
    scale, inv = ca.diag(ca.DM(SCALE)), ca.diag(ca.DM(1.0 / SCALE))
    jac = ca.mtimes([inv, ca.jacobian(f, x), scale])       # d(f/scale)/d(x/scale)
    m = ca.SX.eye(N_STATE) - 0.5 * h * jac
    x_next = x + ca.mtimes(scale, ca.solve(m, h * ca.mtimes(inv, f)))
    trans = ca.mtimes([scale, ca.solve(m, ca.SX.eye(N_STATE) + 0.5 * h * jac), inv])
    return x_next, trans


def _update_sx(x: ca.SX, P: ca.SX, z: ca.SX, r: ca.SX) -> tuple[ca.SX, ...]:
    """Linear update with H = [I3 0]: gain K = P[:, :3] S^-1, S = P[:3, :3] + diag(r);
    S^-1 by the explicit symmetric 3x3 adjugate. Returns (x+, P+ symmetrised, innovation,
    S^-1)."""
    innovation = z - x[:3]
    a, b, c, d, e, f = P[0, 0] + r[0], P[0, 1], P[0, 2], P[1, 1] + r[1], P[1, 2], P[2, 2] + r[2]
    c0, c1, c2 = d * f - e * e, c * e - b * f, b * e - c * d
    q = 1.0 / (a * c0 + b * c1 + c * c2)
    c4, c5 = (b * c - a * e) * q, (a * d - b * b) * q
    s_inv = ca.vertcat(ca.horzcat(c0 * q, c1 * q, c2 * q),
                       ca.horzcat(c1 * q, (a * f - c * c) * q, c4),
                       ca.horzcat(c2 * q, c4, c5))
    gain = ca.mtimes(P[:, :3], s_inv)
    P_new = P - ca.mtimes(gain, P[:3, :])
    return x + ca.mtimes(gain, innovation), 0.5 * (P_new + P_new.T), innovation, s_inv


def _symbols() -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    return (ca.SX.sym("x", N_STATE), ca.SX.sym("P", N_STATE, N_STATE), ca.SX.sym("z", N_MEAS),
            ca.SX.sym("r", N_MEAS))


@functools.cache
def _update_function() -> ca.Function:
    """(x, P, z, r) -> (x+, P+, innovation, S^-1 (3x3))."""
    x, P, z, r = _symbols()
    return ca.Function("kf_update", [x, P, z, r], [ca.densify(v) for v in _update_sx(x, P, z, r)])


@functools.cache
def _propagate_function(plant: PlantParams, dt: float) -> ca.Function:
    """(x, (u, p_s, L)) -> x+: one trapezoidal step (the UKF's sigma-point propagation)."""
    x, ups = ca.SX.sym("x", N_STATE), ca.SX.sym("u_ps_load", N_INPUT)
    return ca.Function("propagate", [x, ups],
                       [_trapezoid_sx(plant, x, ups[0], ups[1], ups[2], dt)[0]])


@functools.cache
def _ekf_function(plant: PlantParams, dt: float) -> ca.Function:
    """One EKF step (x, P, z, (u, p_s, L), Q, r, s) -> (x+, P+, innovation, S^-1, s + x+):
    the last output accumulates the posteriors for :meth:`_KalmanBase.period_mean`."""
    x, P, z, r = _symbols()
    ups, Q = ca.SX.sym("u_ps_load", N_INPUT), ca.SX.sym("Q", N_STATE, N_STATE)
    total = ca.SX.sym("sum", N_STATE)
    x_pred, F = _trapezoid_sx(plant, x, ups[0], ups[1], ups[2], dt)
    P_pred = ca.mtimes([F, P, F.T]) + Q
    outs = [ca.densify(v) for v in _update_sx(x_pred, P_pred, z, r)]
    return ca.Function("ekf_step", [x, P, z, ups, Q, r, total], [*outs, total + outs[0]])


class _KalmanBase:
    """Shared state, covariances and the linear measurement update.

    ``x`` (5,) and ``P`` (5, 5) are updated in place (the compiled steps are bound to them);
    P and Q are symmetric, so the column-major view CasADi takes of them is the same matrix.
    The filter starts at ``x0`` (4,), the plant state, with y0 = the model's
    ``free_position_m``.
    """

    def __init__(
        self, model: ReducedModel, params: EstimatorParams, dt: float, x0: NDArray[np.float64]
    ) -> None:
        if dt <= 0.0:
            raise ValueError(f"dt = {dt} must be > 0")
        self.model = model
        self.dt = dt
        self.Q = np.diag(np.square((*params.process_std, params.free_position_process_std_m)))
        self.R = np.diag(np.square(params.measurement_std))
        self.x = np.array((*np.asarray(x0, dtype=float).reshape(4),
                           model.p.free_position_m))
        self.P = np.diag(np.square((*params.initial_std, params.free_position_initial_std_m)))
        self._r = np.square(np.asarray(params.measurement_std, dtype=float))
        self._z = np.zeros(N_MEAS)
        self._x_out, self._P_out = np.zeros(N_STATE), np.zeros((N_STATE, N_STATE))
        self.innovation, self._s_inv = np.zeros(N_MEAS), np.linalg.inv(self.P[:3, :3] + self.R)
        self._outputs = [self._x_out, self._P_out, self.innovation, self._s_inv]
        self._sum = np.zeros(N_STATE)
        self._count = 0
        self._inputs = np.zeros(N_INPUT)   # (u, p_s, L) of the step
        self._load_sum = 0.0
        self._torque_lag = dt / (params.drive_torque_filter_s + dt)
        self._torque_N_m: float | None = None   # the filtered drive torque [N·m]

    def _set_inputs(self, z: NDArray[np.float64], u: float, p_s: float) -> None:
        """The step's measurement z[:3] and known inputs (u, p_s and the drive load of the
        filtered torque z[3], 0 without one); the load joins the period's sum."""
        self._z[:] = z[:3]
        load = 0.0
        if len(z) > 3 and math.isfinite(z[3]):
            torque = self._torque_N_m
            torque = float(z[3]) if torque is None else (
                torque + self._torque_lag * (float(z[3]) - torque))
            self._torque_N_m = torque
            load = drive_load_N(self.model.p, torque)
        inputs = self._inputs
        inputs[0] = u
        inputs[1] = p_s
        inputs[2] = load
        self._load_sum += load

    def period_mean(self) -> NDArray[np.float64]:
        """Mean posterior state (5,) and mean drive load L [N] over the steps since the last
        call, (6,) (decimation filter).

        The controller runs every 10 samples; the boxcar mean of the 1 kHz posteriors is the
        anti-aliasing filter before that downsampling. With the study's large Q the posterior
        tension is nearly as noisy as the sensors (~340 N rms); the mean over one period cuts
        it ~3x for ~half a period of lag. Returns the current state (and no load) if no step
        was taken.
        """
        if self._count:
            mean = np.append(self._sum / self._count, self._load_sum / self._count)
        else:
            mean = np.append(self.x, 0.0)
        self._sum[:] = 0.0
        self._load_sum = 0.0
        self._count = 0
        return mean

    def _finish(self, step: Bound) -> None:
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
        """Normalised estimation error squared against the true state (5,) (chi-square,
        5 dof)."""
        e = x_true - self.x
        return float(e @ np.linalg.solve(self.P, e))


class ExtendedKalmanFilter(_KalmanBase):
    """EKF; ``step(z, u, p_s)`` predicts over dt with applied opening u, supply p_s [Pa] and
    the drive load of the torque z[3] (if z has it), then updates with z[:3]. Returns the
    posterior state (5,) (a view; do not modify).

    Parameters
    ----------
    model : ReducedModel
        Process model (differentiated exactly by CasADi).
    params : EstimatorParams
        Process, measurement and initial standard deviations (SI, per 1 ms sample).
    dt : float
        Sample period [s].
    x0 : ndarray, shape (4,)
        Initial plant state (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s]).
    """

    def __init__(
        self, model: ReducedModel, params: EstimatorParams, dt: float, x0: NDArray[np.float64]
    ) -> None:
        super().__init__(model, params, dt, x0)
        # x, P and the period sum are updated in place by the one evaluation
        self._step = bind(
            _ekf_function(model.p, dt),
            [self.x, self.P, self._z, self._inputs, self.Q, self._r, self._sum],
            [self.x, self.P, self.innovation, self._s_inv, self._sum]).call

    def step(self, z: NDArray[np.float64], u: float, p_s: float) -> NDArray[np.float64]:
        self._set_inputs(z, u, p_s)
        self._step()
        self._count += 1
        return self.x


class UnscentedKalmanFilter(_KalmanBase):
    """UKF with scaled sigma points (alpha, beta, kappa from params; 2n+1 = 11 points).

    alpha = 1, kappa = -1 gives lambda = -1, centre weights W_m0 = -1/4, W_c0 = 7/4 and a
    spread of 2 sigma: well-conditioned, unlike alpha = 1e-3 (W_m0 ~ -1e6).

    Parameters
    ----------
    model : ReducedModel
        Process model (each sigma point takes one trapezoidal step of it).
    params : EstimatorParams
        Standard deviations (SI, per 1 ms sample) and the sigma-point spread.
    dt : float
        Sample period [s].
    x0 : ndarray, shape (4,)
        Initial plant state (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s]).
    """

    def __init__(
        self, model: ReducedModel, params: EstimatorParams, dt: float, x0: NDArray[np.float64]
    ) -> None:
        super().__init__(model, params, dt, x0)
        n = N_STATE
        a, b, k = params.ukf_alpha, params.ukf_beta, params.ukf_kappa
        lam = a * a * (n + k) - n
        if n + lam <= 0.0:
            raise ValueError(f"UKF: n + lambda = {n + lam} must be > 0 (alpha, kappa)")
        self.gamma = np.sqrt(n + lam)
        self.wm = np.full(2 * n + 1, 0.5 / (n + lam))
        self.wc = self.wm.copy()
        self.wm[0] = lam / (n + lam)
        self.wc[0] = self.wm[0] + 1.0 - a * a + b
        self._point, self._point_next = np.zeros(n), np.zeros(n)
        self._propagate = bind(_propagate_function(model.p, dt),
                               [self._point, self._inputs], [self._point_next])
        self._update = bind(
            _update_function(), [self.x, self.P, self._z, self._r], self._outputs)

    def step(self, z: NDArray[np.float64], u: float, p_s: float) -> NDArray[np.float64]:
        n = N_STATE
        L = np.linalg.cholesky(self.P) * self.gamma
        pts = np.empty((2 * n + 1, n))
        pts[0] = self.x
        pts[1:n + 1] = self.x + L.T
        pts[n + 1:] = self.x - L.T
        self._set_inputs(z, u, p_s)
        prop = np.empty_like(pts)
        for i, point in enumerate(pts):
            self._point[:] = point
            self._propagate()
            prop[i] = self._point_next
        self.x[:] = self.wm @ prop
        d = prop - self.x
        self.P[:] = (d.T * self.wc) @ d + self.Q
        self._finish(self._update)
        return self.x
