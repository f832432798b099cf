"""The one statistic of every campaign document and figure: mean ± std over seeds of the
finite values (:func:`mean_std`)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any


def finite(values: Iterable[Any]) -> list[float]:
    """The finite numbers among ``values`` (None and NaN left out)."""
    return [float(v) for v in values if v is not None and math.isfinite(float(v))]


def mean_std(values: Iterable[Any]) -> tuple[float, float, int]:
    """(mean, population std, count) of the finite values; (NaN, 0, 0) if there is none.
    The one statistic of every campaign document (mean ± std over seeds)."""
    v = finite(values)
    if not v:
        return math.nan, 0.0, 0
    mean = math.fsum(v) / len(v)
    if len(v) == 1:
        return mean, 0.0, 1
    std = math.sqrt(math.fsum((x - mean) ** 2 for x in v) / len(v))
    if std <= 1e-9 * abs(mean):     # equal but for rounding
        std = 0.0
    return mean, std, len(v)
