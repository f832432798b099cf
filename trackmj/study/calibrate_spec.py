"""The calibration spec file of :func:`trackmj.study.calibrate.calibrate`: which keys are
fitted within which bounds, under which conditions, and how.

Spec file (read by the one validator, :mod:`trackmj.validator`)::

    [calibrate]
    scenario = "W1"            # the conditions the log was taken in (name or file)
    duration_s = 10.0
    seed = 0
    [[calibrate.parameters]]
    key = "hydraulics.metering.head_branch_area_m2"
    bounds = [1.6e-8, 8.0e-8]

optional: ``[calibrate]`` architecture, start_s, start_points, fd_step_rel,
max_evaluations, set; per parameter ``start`` (default: its value in the files).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from trackmj.validator import (
    Location,
    ParameterError,
    Parameters,
    load_file,
    param,
    split_override_key,
)


@dataclass(frozen=True)
class FitParameter(Parameters):
    """One key fitted within its bounds."""

    key: str = param(max_len=200,
                     doc="a --set key KIND.TABLE.KEY (trackmj keys lists them)")
    bounds: tuple[float, float] = param(unit="unit of the key",
                                        doc="[low, high] the fit stays within")
    start: float | None = param(unit="unit of the key", default=None,
                                doc="optional start value; default: the files' value")

    def cross_check(self, at: Location) -> None:
        split_override_key(self.key, f"{at.key('key')} = {self.key!r}")
        low, high = self.bounds
        if not high > low:
            raise at.error("bounds", list(self.bounds), "must be [low, high] with high > low")
        if self.start is not None and not low <= self.start <= high:
            raise at.error("start", self.start, f"lies outside bounds [{low:g}, {high:g}]")


@dataclass(frozen=True)
class CalibrateTable(Parameters):
    """The ``[calibrate]`` table: the conditions of the logs and how to fit."""

    scenario: str = param(doc="the conditions the logs were taken in: a built-in name or a "
                          "scenario file (relative to the spec)")
    duration_s: float = param(0.01, 3600.0, doc="replayed time from t = 0")
    seed: int = param(0, 2**32 - 1, unit="1", doc="terrain seed of the conditions")
    parameters: tuple[FitParameter, ...] = param(doc="the keys fitted")
    architecture: str = param(choices=("tp", "tp-weak"), default="tp",
                              doc="plant replayed (mechanics and element)")
    start_s: float = param(0.0, 3600.0, default=0.0,
                           doc="residuals from here to the end (skip a start-up)")
    start_points: int = param(0, 1000, unit="1", default=0,
                              doc="Latin-hypercube start points evaluated before the local "
                              "fit (0: start at the start values)")
    fd_step_rel: float = param(1e-3, 0.1, default=3e-2,
                               unit="1", doc="relative finite-difference step")
    block_s: float = param(0.001, 1.0, default=0.01,
                           doc="residuals are block means over this long (white sensor "
                           "noise stays white, σ/√m; fewer, equally informative residuals)")
    max_evaluations: int = param(1, 1000, unit="1", default=40,
                                 doc="most residual evaluations of the local fit")
    set: tuple[str, ...] | None = param(default=None,
                                        doc="optional fixed --set overrides of every run")

    def cross_check(self, at: Location) -> None:
        if not self.parameters:
            raise at.error("parameters", [], "lists no parameter to fit")
        keys = [p.key for p in self.parameters]
        for i, key in enumerate(keys):
            if key in keys[:i]:
                raise at.error(("parameters", i, "key"), key, "is fitted twice")
        if self.start_s >= self.duration_s:
            raise at.error("start_s", self.start_s,
                           f"must be < duration_s = {self.duration_s!r}")


@dataclass(frozen=True)
class CalibrationSpec(Parameters):
    """A calibration spec file."""

    calibrate: CalibrateTable
    file_kind: ClassVar[str] = "calibration spec"


def load_spec(path: str | Path) -> tuple[CalibrateTable, str]:
    """The validated ``[calibrate]`` table and its scenario (a file path resolved against
    the spec's directory, or a built-in name)."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"calibration spec not found: {path}")
    spec = load_file(CalibrationSpec, path, require_source=False).calibrate
    scenario = spec.scenario
    local = path.parent / scenario
    if scenario.endswith(".toml") and local.is_file():
        scenario = str(local)
    return spec, scenario
