"""The verdict rules: how a claim of the study is judged from our per-seed values, and the
paragraph of report.md that states them."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from trackmj.results.seed_stats import finite
from trackmj.study.report_stats import percent

VERDICT_RULES = (
    "Verdicts: a size claim *agrees* when the study's value lies within max(2 std, "
    "25 %) of our mean; a claim \"TP is x % below\" is *supported* when every seed "
    "shows it and our mean is within max(2 std, 5 points) of the study's range, "
    "*direction only* when every seed shows the sign but not the size, "
    "*contradicted* when every seed shows the opposite, *no difference* when every "
    "seed is within ±1 %, *inconclusive* otherwise.")
"""The rules of :func:`verdict_magnitude` and :func:`verdict_reduction` in words."""


def verdict_reduction(values: Sequence[float], low: float, high: float) -> tuple[str, str]:
    """Verdict on "TP is low..high % below X" from per-seed reductions [%]: *no difference*
    if every seed is within ±1 %; *supported* if every seed has the claimed sign and the
    mean lies within the range widened by max(2 std, 5 points); *direction only* if every
    seed has the sign but not the size; *contradicted* if every seed has the opposite sign;
    *inconclusive* otherwise."""
    v = finite(values)
    if not v:
        return "not measured", "no pair of runs to compare"
    mean, std = float(np.mean(v)), float(np.std(v))
    tol = max(2.0 * std, 5.0)
    study = f"{low:.0f} %" if low == high else f"{low:.0f}-{high:.0f} %"
    ours = percent(v)
    if all(abs(x) < 1.0 for x in v):
        return "no difference", f"equal within 1 % in every seed ({ours}; study {study})"
    if all(x > 0 for x in v):
        if low - tol <= mean <= high + tol:
            return "supported", f"every seed lower, by {ours} (study {study})"
        return "direction only", f"every seed lower, but by {ours}, not {study}"
    if all(x < 0 for x in v):
        return "contradicted", f"the opposite in every seed: higher by {percent([-x for x in v])}"
    return "inconclusive", f"the sign changes across seeds ({ours})"


def verdict_magnitude(values: Sequence[float], study: float, unit_scale: float,
                      unit: str) -> tuple[str, str]:
    """*agrees* if |mean − study| <= max(2 std, 25 % of the study's value), else *differs*
    (the ratio stated)."""
    v = finite(values)
    if not v:
        return "not measured", "undefined in every run"
    mean, std = float(np.mean(v)), float(np.std(v))
    ratio = mean / study if study else math.nan
    text = f"ours {mean * unit_scale:.3g} {unit}, ×{ratio:.2f} the study's"
    if abs(mean - study) <= max(2.0 * std, 0.25 * abs(study)):
        return "agrees", text
    return "differs", text
