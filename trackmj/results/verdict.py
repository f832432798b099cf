"""The verdict on a run's acceptance figures (:func:`trackmj.results.acceptance.acceptance`):
which of the scenario's rules it broke. Plain Python, so that the command line's summary
reads it without the numerical stack."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

RECOVERY_WITHIN_S = 2.0
"""Default of a scenario's ``[evaluation] recovery_within_s`` [s] (assumed engineering
requirement, not the study's), also for runs written before the key."""
STEADY_OFFSET_MAX_REL = 0.02
"""Default of a scenario's ``[evaluation] steady_offset_max_rel`` [-], likewise."""


@dataclass(frozen=True)
class Verdict:
    """Which acceptance rules a run broke (:func:`verdict`), with what it measured: the
    trailing mean's lowest and highest [N] against the band [N]; per disturbance edge (keyed
    by its time, as :func:`~trackmj.results.acceptance.acceptance` keys it) whose mean came
    back later than ``recovery_within_s`` [s], its recovery time [s] (NaN: never); the worst
    steady offset against its limit (shares of the reference, NaN: no steady window)."""

    mean_range_N: tuple[float, float]
    band_N: tuple[float, float]
    late_edges: dict[str, float]
    recovery_within_s: float
    steady_offset_rel: float
    steady_offset_max_rel: float

    @property
    def broken(self) -> list[str]:
        """The rules broken, in order: "band", "recovery", "steady offset"."""
        low, high = self.mean_range_N
        return [rule for rule, broken in (
            ("band", low < self.band_N[0] or high > self.band_N[1]),
            ("recovery", bool(self.late_edges)),
            ("steady offset", self.steady_offset_rel >= self.steady_offset_max_rel))
            if broken]

    @property
    def holds(self) -> bool:
        """Whether the run keeps every rule."""
        return not self.broken


def verdict(figures: Mapping[str, Any], band_N: tuple[float, float],
            recovery_within_s: float, steady_offset_max_rel: float) -> Verdict:
    """The verdict on a run's :func:`~trackmj.results.acceptance.acceptance` ``figures`` (as
    computed or read back from
    JSON, a never-recovered edge then None): its 0.5 s mean within ``band_N`` = (F_min,
    F_max) [N], back within the recovery band ``recovery_within_s`` [s] after each edge,
    and no steady window's offset reaching ``steady_offset_max_rel`` of the reference. A
    figure that is NaN (no evaluation window, no steady window) breaks no rule."""
    def number(value: Any) -> float:
        return math.nan if value is None else float(value)

    late = {edge: number(s) for edge, s in (figures.get("edge_recovery_s") or {}).items()
            if not number(s) <= recovery_within_s}
    return Verdict((number(figures.get("mean_min_N")), number(figures.get("mean_max_N"))),
                   band_N, late, recovery_within_s,
                   number(figures.get("steady_offset_max_rel")), steady_offset_max_rel)
