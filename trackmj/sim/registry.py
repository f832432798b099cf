"""Registries of the interchangeable blocks: controllers, estimators, mechanics, tensioner
elements and the coupling architectures made of them.

Each registry maps a name to a builder; the CLI, the report and scenario validation take
their choices from these keys, so a name is written once. Builders import their modules
when called, so importing this module stays cheap. A new element is its own module with a
``build(context) -> ports.Element`` function and one line in :data:`ELEMENTS`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Entry:
    """One registered block: a one-line description, its builder, the names of the run
    products its builder needs besides the setup (mechanics: ``"tp_result"``, the tp run of
    the same case whose track load dp-a replays), and for a controller whether it is a
    baseline (``trackmj report`` runs the baselines beside each scenario's own controller
    for the controller claims)."""

    description: str
    build: Callable[..., Any]
    needs: tuple[str, ...] = ()
    baseline: bool = False


@dataclass(frozen=True)
class Architecture:
    """A coupling architecture: a key of :data:`MECHANICS` × a key of :data:`ELEMENTS`, with
    the coupling the element is asked for ("strong": the affine law with dF/dv; "weak": the
    last step's force held)."""

    description: str
    mechanics: str
    element: str
    coupling: str = "strong"

    @property
    def replays_tp(self) -> bool:
        """Whether its mechanics replays the track load of a tp run of the same case."""
        return "tp_result" in MECHANICS[self.mechanics].needs


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

    nominal = cfg.controller.nominal_tension_N
    if nominal is None:
        return PidController(model, cfg.controller, cfg.pid)
    # tuned between the W1 levels 0.8 and 1.0 x nominal (13.5 kN on LF1352)
    return PidController(model, cfg.controller, cfg.pid, operating_force_N=0.9 * nominal)


def _ekf(model: Any, cfg: Any, dt_s: float, x0: Any) -> Any:
    from trackmj.control.estimators import ExtendedKalmanFilter

    return ExtendedKalmanFilter(model, cfg.estimator, dt_s, x0)


def _ukf(model: Any, cfg: Any, dt_s: float, x0: Any) -> Any:
    from trackmj.control.estimators import UnscentedKalmanFilter

    return UnscentedKalmanFilter(model, cfg.estimator, dt_s, x0)


CONTROLLERS: dict[str, Entry] = {
    "nmpc": Entry("nonlinear MPC (Gauss-Newton SQP, condensed QPs by DAQP)", _nmpc),
    "lmpc": Entry("linear MPC on the model linearised at hold (OSQP)", _lmpc, baseline=True),
    "pid": Entry("PID with SIMC tuning and back-calculation anti-windup", _pid, baseline=True),
    "fmu": Entry("a controller FMU, --controller fmu:FILE.toml (e.g. exported from Simulink)",
                 _lazy("trackmj.fmi.controller", "build_fmu_controller"),
                 needs=("controller_file",)),
}
"""Controller builders ``build(reduced_model, control_config, **needs) -> Controller``."""

ESTIMATORS: dict[str, Entry] = {
    "ekf": Entry("extended Kalman filter", _ekf),
    "ukf": Entry("unscented Kalman filter", _ukf),
}
"""Estimator builders ``build(reduced_model, control_config, dt_s, x0) -> Estimator``."""

_ARCH = "trackmj.sim.architectures"
MECHANICS: dict[str, Entry] = {
    "track": Entry("the MuJoCo track of the machine, settled under the initial force",
                   _lazy(_ARCH, "build_track")),
    "equivalent-idler": Entry("the identified equivalent idler, the track load of the tp run "
                              "replayed", _lazy(_ARCH, "build_equivalent_idler"),
                              needs=("tp_result",)),
}
"""Mechanics builders ``build(setup, **needs) -> BuiltMechanics`` (see
:mod:`trackmj.sim.architectures`)."""

ELEMENTS: dict[str, Entry] = {
    "hydraulic": Entry("the hydraulic plugin (trackmj.hydraulics)",
                       _lazy("trackmj.elements.hydraulic", "build")),
    "ideal": Entry("an ideal force source at the hydraulic tension rate (dp-b)",
                   _lazy("trackmj.elements.ideal", "build")),
    "passive": Entry("a preload spring-damper, valves ignored (a tensioner file's [passive])",
                     _lazy("trackmj.elements.passive", "build")),
    "fmu": Entry("an FMU, FMI 2.0/3.0, co-simulation or model exchange (a tensioner file's "
                 "[fmu])", _lazy("trackmj.elements.fmu", "build")),
}
"""Tensioner element builders ``build(ElementContext) -> ports.Element``."""

REPLACEABLE_ELEMENT = "hydraulic"
"""The element a tensioner file replaces: architectures built on another element (dp-b's
ideal source) keep theirs."""

ARCHITECTURES: dict[str, Architecture] = {
    "tp": Architecture("track + hydraulic plugin, strong coupling", "track", "hydraulic"),
    "tp-weak": Architecture("track + hydraulic plugin, weak (explicit) coupling", "track",
                            "hydraulic", "weak"),
    "dp-a": Architecture("hydraulics on the identified equivalent idler, tp track load "
                         "replayed", "equivalent-idler", "hydraulic"),
    "dp-b": Architecture("track with an ideal force source instead of the hydraulics",
                         "track", "ideal"),
}
"""Coupling architectures, mechanics × element (see :mod:`trackmj.sim.architectures`)."""

REFERENCE_ARCHITECTURE = "tp"
"""The architecture the others are judged against: the full track with the hydraulic plugin,
strongly coupled. dp-a replays its track load; compare and report measure each reduced
architecture's prediction error against it."""


def choices(registry: dict[str, Any]) -> tuple[str, ...]:
    """The registered names, in registration order."""
    return tuple(registry)


def by_name(registry: dict[str, Entry]) -> tuple[str, ...]:
    """The names a file or option may give alone: entries whose builder needs nothing
    besides the run (the FMU controller needs its file: ``fmu:FILE.toml``)."""
    return tuple(name for name, entry in registry.items() if not entry.needs)


def baselines() -> tuple[str, ...]:
    """The controllers registered as baselines, in registration order."""
    return tuple(name for name, entry in CONTROLLERS.items() if entry.baseline)
