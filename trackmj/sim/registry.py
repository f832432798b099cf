"""Registries of the interchangeable blocks: controllers, estimators, coupling architectures.

Each registry maps a name to a builder; the CLI, the report and scenario validation take
their choices from these keys, so a name is written once. Builders import their modules
when called, so importing this module stays cheap.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Entry:
    """One registered block: a one-line description and its builder."""

    description: str
    build: Callable[..., Any]


def _nmpc(model: Any, cfg: Any) -> Any:
    from trackmj.control.nmpc import NonlinearMpc

    return NonlinearMpc(model, cfg.controller, cfg.mpc)


def _lmpc(model: Any, cfg: Any) -> Any:
    from trackmj.control.lmpc import LinearMpc

    return LinearMpc(model, cfg.controller, cfg.mpc)


def _pid(model: Any, cfg: Any) -> Any:
    from trackmj.control.pid import PidController

    return PidController(model, cfg.controller, cfg.pid)


def _ekf(model: Any, cfg: Any, dt_s: float, x0: Any) -> Any:
    from trackmj.control.estimators import ExtendedKalmanFilter

    return ExtendedKalmanFilter(model, cfg.estimator, dt_s, x0)


def _ukf(model: Any, cfg: Any, dt_s: float, x0: Any) -> Any:
    from trackmj.control.estimators import UnscentedKalmanFilter

    return UnscentedKalmanFilter(model, cfg.estimator, dt_s, x0)


CONTROLLERS: dict[str, Entry] = {
    "nmpc": Entry("nonlinear MPC (Gauss-Newton SQP, condensed QPs by DAQP)", _nmpc),
    "lmpc": Entry("linear MPC on the model linearised at hold (OSQP)", _lmpc),
    "pid": Entry("PID with SIMC tuning and back-calculation anti-windup", _pid),
}
"""Controller builders ``build(reduced_model, control_config) -> Controller``."""

ESTIMATORS: dict[str, Entry] = {
    "ekf": Entry("extended Kalman filter", _ekf),
    "ukf": Entry("unscented Kalman filter", _ukf),
}
"""Estimator builders ``build(reduced_model, control_config, dt_s, x0) -> Estimator``."""

ARCHITECTURE_NAMES: tuple[str, ...] = ("tp", "tp-weak", "dp-a", "dp-b")
"""Coupling architectures (their builders live in :mod:`trackmj.sim.architectures`)."""


def choices(registry: dict[str, Entry]) -> tuple[str, ...]:
    """The registered names, in registration order."""
    return tuple(registry)
