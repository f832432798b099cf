"""Statistics over seeds as the report prints them: mean ± std, percentages, and the paired
reductions of one architecture's (or controller's) metric against another's."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from trackmj.results.seed_stats import finite
from trackmj.results.seed_stats import mean_std as statistics


def mean_std(values: Iterable[float], scale: float = 1.0, digits: int = 3) -> str:
    """"mean ± std" of the finite values (population std over seeds,
    :func:`trackmj.results.seed_stats.mean_std`), scaled; "–" if none; "(k of n undefined)" appended
    when some are NaN (e.g. never settled)."""
    values = list(values)
    mean, std, n = statistics(values)
    missing = len(values) - n
    tail = f" ({missing} of {len(values)} undefined)" if missing else ""
    if not n:
        return "–" + tail
    if n == 1:
        return f"{mean * scale:.{digits}g}" + tail
    return f"{mean * scale:.{digits}g} ± {std * scale:.2g}" + tail


def percent(values: Iterable[float]) -> str:
    """Percentages as "mean ± std %" with whole points (one value: no ± part)."""
    v = finite(values)
    if not v:
        return "– %"
    digits = 1 if all(abs(x) < 10.0 for x in v) else 0
    if len(v) == 1:
        return f"{v[0]:.{digits}f} %"
    return f"{np.mean(v):.{digits}f} ± {np.std(v):.{digits}f} %"


def lower_by(values: Sequence[float], who: str = "TP") -> str:
    """"TP lower by x %" for per-seed reductions, "TP higher by x %" when they are negative
    on average (then x = 100·(tp/other − 1))."""
    v = finite(values)
    if v and float(np.mean(v)) < 0.0:
        return f"{who} higher by {percent([-x for x in v])}"
    return f"{who} lower by {percent(v)}"


def reductions(tp: Mapping[Any, float], other: Mapping[Any, float]) -> list[float]:
    """Paired reductions 100·(1 − tp/other) [%] over the keys (seeds) both have finite."""
    return [100.0 * (1.0 - tp[k] / other[k]) for k in tp
            if k in other and math.isfinite(tp[k]) and math.isfinite(other[k]) and other[k] != 0]
