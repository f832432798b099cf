"""The closed loop on the controller's own reduced model (no MuJoCo): the plant of the
control tests and benchmarks, run by the same loop as every architecture
(:func:`trackmj.sim.loop.run_loop`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from trackmj.control.model import ReducedModel
from trackmj.control.params import ControlConfig, PlantParams
from trackmj.control.sensors import Sensors
from trackmj.control.valves import ValveLogic
from trackmj.ports import (
    COUPLING_STEP_S,
    Command,
    Controller,
    Estimator,
    Readout,
    StepInputs,
    steps_per_period,
)
from trackmj.results.signals import overshoot, settling_time
from trackmj.sim.controllers import ESTIMATORS
from trackmj.sim.loop import Schedule, run_loop
from trackmj.sim.loop_plants import ReducedLoopPlant
from trackmj.sim.observers import Recorder


@dataclass
class LoopResult:
    """Time series at the plant step (n steps): t [s] (end of step), true and estimated
    tension [N], reference [N], true state (n, 4) and estimate (n, 5, with the disturbance
    state y0 [m] last), applied valve mode, opening u; the controller's solve times [s] and
    the valve switch count."""

    t: NDArray[np.float64]
    force: NDArray[np.float64]
    force_est: NDArray[np.float64]
    ref: NDArray[np.float64]
    x: NDArray[np.float64]
    x_est: NDArray[np.float64]
    mode: NDArray[np.int64]
    u: NDArray[np.float64]
    solve_times_s: NDArray[np.float64]
    switches: int


class PosteriorEstimator(Estimator, Protocol):
    """An estimator that shows its posterior mean ``x``, shape (5,): the four plant states
    and the disturbance state y0 (the Kalman filters of :mod:`trackmj.control.estimators`)."""

    @property
    def x(self) -> NDArray[np.float64]: ...


class _StateProbe:
    """Observer keeping the plant's true state (steps, 4) and the estimator's posterior
    (steps, 5: the four plant states and the disturbance state y0) of every step."""

    def __init__(self, plant: ReducedLoopPlant, estimator: PosteriorEstimator,
                 steps: int) -> None:
        self.plant, self.estimator = plant, estimator
        self.truth, self.estimate = np.empty((steps, 4)), np.empty((steps, 5))

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        self.truth[k] = self.plant.state
        self.estimate[k] = self.estimator.x


def run_closed_loop(cfg: ControlConfig, plant_params: PlantParams, controller: Controller,
                    reference: Callable[[float], float], t_end: float,
                    supply: Callable[[float], float] | None = None, estimator: str = "ekf",
                    seed: int = 0) -> LoopResult:
    """Simulate ``t_end`` [s] of ``controller`` on the reduced model ``plant_params`` with
    ``cfg``'s sensors, estimator and valve logic, starting at rest at ``reference(0)``;
    ``reference(t)`` [N], ``supply(t)`` [Pa] (default the plant's nominal supply, told to
    the controller and the estimator as a supply-pressure transducer would). Sensor noise
    from ``seed``."""
    h = COUPLING_STEP_S
    if abs(cfg.sensors.sample_period_s - h) > 1e-12:
        raise ValueError(f"sensor period {cfg.sensors.sample_period_s} s must equal the "
                         f"{h} s coupling step")
    model = ReducedModel(plant_params)
    p_nom = plant_params.supply_pressure_Pa
    supply = supply or (lambda _t: p_nom)
    x0 = model.equilibrium(reference(0.0))
    steps = round(t_end / h)
    ratio = steps_per_period(controller.period_s, h)
    t_start = h * np.arange(steps)
    previews = np.array([[reference(t + i * controller.period_s)
                          for i in range(controller.horizon_steps + 1)]
                         for t in t_start[::ratio]])
    sched = Schedule([StepInputs(0.0, 0.0, 0.0, supply(t)) for t in t_start], previews,
                     np.array([reference(t + h) for t in t_start]))
    plant = ReducedLoopPlant(plant_params, x0)
    est = ESTIMATORS[estimator].build(model, cfg, h, x0)
    valves = ValveLogic(cfg.valves, h)
    recorder, probe = Recorder(sched), _StateProbe(plant, est, steps)
    run_loop(sched, controller=controller, valves=valves, plant=plant,
             sensors=Sensors(cfg.sensors, seed), estimator=est, observers=[recorder, probe])
    c = recorder.columns()
    x_est = probe.estimate
    force_est = (x_est[:, 0] * plant_params.area_head_m2
                 - x_est[:, 1] * plant_params.area_rod_m2)
    return LoopResult(c["t_s"], c["tension_N"], force_est, c["tension_ref_N"], probe.truth,
                      x_est, c["valve_mode"].astype(np.int64), c["u"],
                      np.array(recorder.solve_times_s), valves.switches)


def step_metrics(res: LoopResult, t_step: float, f_final: float,
                 band: float = 0.02) -> dict[str, float]:
    """Step response figures after a step at ``t_step`` [s] to ``f_final`` [N]: settling
    time to ±band·f_final [s] (:func:`trackmj.results.signals.settling_time`, NaN if not settled),
    overshoot beyond f_final as a fraction of it [-] (the study's definition), RMSE over
    the last second [N], and the estimator's tension RMSE over the run [N]."""
    settle = settling_time(res.t, res.force, f_final, t_step, band_rel=band)
    over = overshoot(res.t, res.force, float(res.force[0]), f_final, (t_step, res.t[-1]))
    last = res.t > res.t[-1] - 1.0
    return {
        "settling_s": settle,
        "overshoot": over.percent / 100.0,
        "rmse_last_s_N": float(np.sqrt(np.mean((res.force[last] - f_final) ** 2))),
        "est_rmse_N": float(np.sqrt(np.mean((res.force_est - res.force) ** 2))),
    }
