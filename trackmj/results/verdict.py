"""The verdict on a run's acceptance figures (:func:`trackmj.results.acceptance.acceptance`):
which of the scenario's rules it broke, and in words (kN, for the run's summary and the
report). Plain Python, so that the command line's summary reads it without the numerical
stack."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
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
    steady offset against its limit (shares of the reference, NaN: no steady window); the
    trailing mean's window [s] and the recovery band (share of the reference) the figures
    were taken with; the edges judged, keyed by their times (a run without disturbances, or
    one that ends before an edge can be judged, has none); the time of the highest mean [s]
    and the drive's floor under the idler load there [N]
    (:func:`~trackmj.results.acceptance.drive_floor_N`; NaN: not known)."""

    mean_range_N: tuple[float, float]
    band_N: tuple[float, float]
    late_edges: dict[str, float]
    recovery_within_s: float
    steady_offset_rel: float
    steady_offset_max_rel: float
    mean_window_s: float = 0.5
    recovery_band_rel: float = 0.05
    edge_times: tuple[str, ...] = ()
    mean_max_s: float = math.nan
    drive_floor_at_max_N: float = math.nan

    @property
    def edges_judged(self) -> int:
        """How many disturbance edges were judged."""
        return len(self.edge_times)

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
    def band_forced_by_drive(self) -> bool:
        """Whether the mean left the band's top where the drive alone held the idler above
        it (its floor at the highest mean at or above F_max): no tensioner could keep it in."""
        top = self.band_N[1]
        return self.mean_range_N[1] > top and self.drive_floor_at_max_N >= top

    @property
    def holds(self) -> bool:
        """Whether the run keeps every rule."""
        return not self.broken

    def text(self) -> str:
        """The verdict in one phrase: "holds (...)" with what it measured, or "fails (...)"
        naming each rule broken and by how much (forces in kN)."""
        low, high = self.mean_range_N
        span = f"the {self.mean_window_s:g} s mean {low / 1e3:.1f}-{high / 1e3:.1f} kN"
        band = f"[{self.band_N[0] / 1e3:.1f}, {self.band_N[1] / 1e3:.1f}] kN"
        back = f"±{100 * self.recovery_band_rel:g} % in {self.recovery_within_s:g} s"
        if self.holds:
            edges = (f"back within {back} of every edge" if self.edges_judged
                     else "no disturbance edge to recover from")
            steady = (f"steady offset below {100 * self.steady_offset_max_rel:g} %"
                      if not math.isnan(self.steady_offset_rel)
                      else "no steady window to judge an offset in")
            return f"holds ({span} in {band}; {edges}; {steady})"
        why = []
        if "band" in self.broken:
            pull_kN = self.drive_floor_at_max_N / 1e3
            forced = (f"; the drive's pull through the idler was {pull_kN:.1f} kN there "
                      f"({self.mean_max_s:.2f} s; G/r × the drive torque, the slack side "
                      "unloaded, strands carrying tension only), above the band: no "
                      "tensioner could keep the mean in"
                      if self.band_forced_by_drive else "")
            why.append(f"band: {span}, outside {band}{forced}")
        if "recovery" in self.broken:
            why.append(f"recovery within {back}: " + ", ".join(
                late_edge_text(edge, s, self.edge_times)
                for edge, s in self.late_edges.items()))
        if "steady offset" in self.broken:
            why.append(f"steady offset {100 * self.steady_offset_rel:.2f} % (limit "
                       f"{100 * self.steady_offset_max_rel:g} %)")
        return f"fails ({'; '.join(why)})"


def verdict(figures: Mapping[str, Any], band_N: tuple[float, float],
            recovery_within_s: float, steady_offset_max_rel: float) -> Verdict:
    """The verdict on a run's :func:`~trackmj.results.acceptance.acceptance` ``figures`` (as
    computed or read back from
    JSON, a never-recovered edge then None): its 0.5 s mean within ``band_N`` = (F_min,
    F_max) [N], back within the recovery band ``recovery_within_s`` [s] after each edge,
    and no steady window's offset reaching ``steady_offset_max_rel`` of the reference. A
    figure that is NaN (no evaluation window, no steady window) breaks no rule."""
    recovery = figures.get("edge_recovery_s") or {}
    late = {edge: _number(s) for edge, s in recovery.items() if not _number(s) <= recovery_within_s}
    return Verdict((_number(figures.get("mean_min_N")), _number(figures.get("mean_max_N"))),
                   band_N, late, recovery_within_s,
                   _number(figures.get("steady_offset_max_rel")), steady_offset_max_rel,
                   figures.get("mean_window_s", 0.5), figures.get("recovery_band_rel", 0.05),
                   tuple(recovery), _number(figures.get("mean_max_s")),
                   _number(figures.get("drive_floor_at_max_N")))


def late_edge_text(edge: str, s: float, edges: Sequence[str]) -> str:
    """A late disturbance edge in words (``edge`` and ``edges``, every edge judged, keyed by
    their times [s]; ``s`` its recovery time [s]): NaN is "not back before the next edge"
    (the recovery is judged up to it) or, after the last, "never"."""
    if not math.isnan(s):
        return f"{s:.2f} s after the {edge} s edge"
    later = [e for e in edges if float(e) > float(edge)]
    if later:
        following = min(later, key=float)
        return f"not back after the {edge} s edge before the next one at {following} s"
    return f"never after the {edge} s edge"


def not_back_texts(figures: Mapping[str, Any]) -> list[str]:
    """The disturbance edges (keyed by their time, as in ``figures["edge_recovery_s"]``)
    after which the trailing mean did not come back (a recovery that is None, read back
    from JSON, or NaN), each in the verdict's words (:func:`late_edge_text`)."""
    recovery = figures.get("edge_recovery_s") or {}
    return [late_edge_text(edge, math.nan, tuple(recovery)) for edge, s in recovery.items()
            if math.isnan(_number(s))]


def _number(value: Any) -> float:
    """A figure as a float, None (JSON's NaN) as NaN."""
    return math.nan if value is None else float(value)


def run_verdict(metrics: Mapping[str, Any]) -> Verdict | None:
    """The verdict on a run from its ``metrics`` (its ``acceptance`` figures and its
    ``evaluation`` windows: the band and the limits; a run written before the limits were
    recorded is judged with the defaults); None for a run without acceptance figures."""
    figures, window = metrics.get("acceptance"), metrics.get("evaluation") or {}
    if not figures or "force_min_N" not in window:
        return None
    return verdict(figures, (window["force_min_N"], window["force_max_N"]),
                   window.get("recovery_within_s", RECOVERY_WITHIN_S),
                   window.get("steady_offset_max_rel", STEADY_OFFSET_MAX_REL))
