"""Closed loop on the reduced plant at 1 ms: plant -> sensors -> estimator -> controller
(every period) -> valve logic -> plant. Used by the tests and the benchmark (no MuJoCo)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
from trackmj.control.model import ReducedModel, ReducedPlant
from trackmj.control.params import ControlConfig, PlantParams
from trackmj.control.sensors import Sensors
from trackmj.control.valves import ValveLogic
from trackmj.ports import ControlOutput, steps_per_period

Controller = Callable[[NDArray[np.float64], NDArray[np.float64], float], ControlOutput]


@dataclass
class LoopResult:
    """Time series at the plant step: t [s], true/estimated tension [N], reference [N],
    true state (K, 4), applied valve mode, commanded opening u; controller/estimator wall
    times [s] and the valve switch count."""

    t: NDArray[np.float64]
    force: NDArray[np.float64]
    force_est: NDArray[np.float64]
    ref: NDArray[np.float64]
    x: NDArray[np.float64]
    x_est: NDArray[np.float64]
    mode: NDArray[np.int64]
    u: NDArray[np.float64]
    controller_times: NDArray[np.float64]
    estimator_times: NDArray[np.float64]
    switches: int


def run_closed_loop(
    cfg: ControlConfig,
    plant_params: PlantParams,
    controller: Controller,
    reference: Callable[[float], float],
    t_end: float,
    supply: Callable[[float], float] | None = None,
    estimator: str = "ekf",
    seed: int = 0,
    dt: float = 1e-3,
    feed_supply: bool = True,
) -> LoopResult:
    """Simulate ``t_end`` seconds of the reduced plant ``plant_params`` under ``cfg``'s
    sensors, estimator and valve logic. ``reference(t)`` [N], ``supply(t)`` [Pa] (default
    the plant's nominal supply). The controller receives the estimator's mean posterior
    over the past period (``period_mean``: decimation filter 1 kHz -> controller rate). With
    ``feed_supply`` the supply pressure is handed to the estimator and, if it has
    ``set_parameters``, to the controller (assumes a supply pressure transducer)."""
    ratio = steps_per_period(cfg.controller.period_s, dt)
    if abs(cfg.sensors.sample_period_s - dt) > 1e-12:
        raise ValueError(f"sensor period {cfg.sensors.sample_period_s} s must equal dt = {dt} s")
    model = ReducedModel(plant_params)
    p_nom = plant_params.supply_pressure_Pa
    supply = supply or (lambda _t: p_nom)
    x0 = model.equilibrium(reference(0.0))
    plant = ReducedPlant(plant_params, x0, dt)
    sensors = Sensors(cfg.sensors, seed)
    est_cls = {"ekf": ExtendedKalmanFilter, "ukf": UnscentedKalmanFilter}[estimator]
    est = est_cls(model, cfg.estimator, dt, x0)
    valves = ValveLogic(cfg.valves, dt)
    n_horizon = getattr(getattr(controller, "mpc", None), "horizon_steps", 15)
    steps = round(t_end / dt)
    out = {k: np.empty(steps) for k in ("t", "force", "force_est", "ref", "u")}
    xs, xe, modes = np.empty((steps, 4)), np.empty((steps, 4)), np.empty(steps, dtype=np.int64)
    ctrl_times, est_times = [], []
    u = 0.0
    set_params = getattr(controller, "set_parameters", None)
    period = cfg.controller.period_s
    for k in range(steps):
        t = k * dt
        p_s = supply(t)
        if k % ratio == 0:
            preview = np.array([reference(t + i * period) for i in range(n_horizon + 1)])
            if feed_supply and set_params is not None:
                set_params(supply_pressure_Pa=p_s)
            x_ctrl = est.period_mean()
            t0 = time.perf_counter()
            u = controller(x_ctrl, preview, t).u
            ctrl_times.append(time.perf_counter() - t0)
        mode = valves.step(u)
        x = plant.step(float(mode), p_s)
        z = sensors.measure(x)
        t0 = time.perf_counter()
        x_hat = est.step(z, float(mode), p_s if feed_supply else p_nom).copy()
        est_times.append(time.perf_counter() - t0)
        out["t"][k], out["force"][k], out["ref"][k], out["u"][k] = t + dt, plant.force, 0.0, u
        out["force_est"][k] = model.force(x_hat)
        out["ref"][k] = reference(t + dt)
        xs[k], xe[k], modes[k] = x, x_hat, mode
    return LoopResult(
        out["t"],
        out["force"],
        out["force_est"],
        out["ref"],
        xs,
        xe,
        modes,
        out["u"],
        np.array(ctrl_times),
        np.array(est_times),
        valves.switches,
    )


def step_metrics(
    res: LoopResult, t_step: float, f_final: float, band: float = 0.02
) -> dict[str, float]:
    """Settling time after ``t_step`` to +-band of f_final [s], overshoot (peak - final) /
    final [-] (the study's definition), steady RMSE over the last second [N]."""
    after = res.t > t_step
    err = np.abs(res.force[after] - f_final) > band * f_final
    idx = np.nonzero(err)[0]
    t_after = res.t[after]
    settle = 0.0 if idx.size == 0 else float(t_after[idx[-1]] - t_step)
    if idx.size and idx[-1] == t_after.size - 1:
        settle = np.inf
    last = res.t > res.t[-1] - 1.0
    return {
        "settling_s": settle,
        "overshoot": float((res.force[after].max() - f_final) / f_final),
        "rmse_last_s_N": float(np.sqrt(np.mean((res.force[last] - f_final) ** 2))),
        "est_rmse_N": float(np.sqrt(np.mean((res.force_est - res.force) ** 2))),
    }
