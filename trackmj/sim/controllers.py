"""Registries of the control blocks a run is built with: controllers and estimators (the
control layer, :mod:`trackmj.control`, and a controller FMU). Scenario, sweep and command
line validate names against these keys. A new controller is its module and one line in
:data:`CONTROLLERS`; ``baseline=True`` makes ``trackmj report`` run it for the controller
claims."""

from __future__ import annotations

from typing import Any

from trackmj.sim.entries import Entry, lazy


def _nmpc(model: Any, cfg: Any) -> Any:
    from trackmj.control.nmpc import NonlinearMpc  # when built: names alone import no CasADi

    return NonlinearMpc(model, cfg.controller, cfg.mpc)


def _lmpc(model: Any, cfg: Any) -> Any:
    from trackmj.control.lmpc import LinearMpc  # when built: names alone import no CasADi

    return LinearMpc(model, cfg.controller, cfg.mpc)


def _pid(model: Any, cfg: Any) -> Any:
    from trackmj.control.pid import PidController  # when built: names alone import no CasADi

    nominal = cfg.controller.nominal_tension_N
    if nominal is None:
        return PidController(model, cfg.controller, cfg.pid)
    # tuned between the W1 levels 0.8 and 1.0 x nominal (13.5 kN on LF1352)
    return PidController(model, cfg.controller, cfg.pid, operating_force_N=0.9 * nominal)


def _ekf(model: Any, cfg: Any, dt_s: float, x0: Any) -> Any:
    from trackmj.control.estimators import (
        ExtendedKalmanFilter,  # when built: names alone import no CasADi
    )

    return ExtendedKalmanFilter(model, cfg.estimator, dt_s, x0)


def _ukf(model: Any, cfg: Any, dt_s: float, x0: Any) -> Any:
    from trackmj.control.estimators import (
        UnscentedKalmanFilter,  # when built: names alone import no CasADi
    )

    return UnscentedKalmanFilter(model, cfg.estimator, dt_s, x0)


CONTROLLERS: dict[str, Entry] = {
    "nmpc": Entry("nonlinear MPC (Gauss-Newton SQP, condensed QPs by DAQP)", _nmpc),
    "lmpc": Entry("linear MPC on the model linearised at hold (OSQP)", _lmpc, baseline=True),
    "pid": Entry("PID with SIMC tuning and back-calculation anti-windup", _pid, baseline=True),
    "fmu": Entry("a controller FMU, --controller fmu:FILE.toml (e.g. exported from Simulink)",
                 lazy("trackmj.fmi.controller_fmu", "build_fmu_controller"),
                 needs=("controller_file",)),
}
"""Controller builders ``build(reduced_model, control_config, **needs) -> Controller``."""

ESTIMATORS: dict[str, Entry] = {
    "ekf": Entry("extended Kalman filter", _ekf),
    "ukf": Entry("unscented Kalman filter", _ukf),
}
"""Estimator builders ``build(reduced_model, control_config, dt_s, x0) -> Estimator``."""


def baselines() -> tuple[str, ...]:
    """The controllers registered as baselines, in registration order."""
    return tuple(name for name, entry in CONTROLLERS.items() if entry.baseline)
