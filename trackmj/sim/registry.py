"""Registries of the interchangeable blocks: controllers, estimators, coupling architectures.

Each registry maps a name to a builder; the CLI, the report and scenario validation take
their choices from these keys, so a name is written once. Builders import their modules
when called, so importing this module stays cheap.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Entry:
    """One registered block: a one-line description, its builder, and (architectures) whether
    it replays the track load of a tp run of the same case."""

    description: str
    build: Callable[..., Any]
    replays_tp: bool = False


def _lazy(module: str, name: str) -> Callable[..., Any]:
    """A builder that imports ``module`` and calls its ``name`` when first used."""

    def build(*args: Any, **kwargs: Any) -> Any:
        return getattr(importlib.import_module(module), name)(*args, **kwargs)

    build.__name__ = name
    return build


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

_ARCH = "trackmj.sim.architectures"
ARCHITECTURES: dict[str, Entry] = {
    "tp": Entry("track + hydraulic plugin, strong coupling", _lazy(_ARCH, "build_tp")),
    "tp-weak": Entry("track + hydraulic plugin, weak (explicit) coupling",
                     _lazy(_ARCH, "build_tp_weak")),
    "dp-a": Entry("hydraulics on the identified equivalent idler, tp track load replayed",
                  _lazy(_ARCH, "build_dp_a"), replays_tp=True),
    "dp-b": Entry("track with an ideal force source instead of the hydraulics",
                  _lazy(_ARCH, "build_dp_b")),
}
"""Coupling architectures ``build(setup, tp_result) -> Assembly`` (see
:mod:`trackmj.sim.architectures`)."""


def choices(registry: dict[str, Entry]) -> tuple[str, ...]:
    """The registered names, in registration order."""
    return tuple(registry)
