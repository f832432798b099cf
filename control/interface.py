"""Shared controller interface: ``controller(estimate (4,), reference_preview (N+1,) [N], t [s])
-> ControlOutput`` with the continuous valve opening ``u`` in [-1, 1] and solve statistics."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class ControlOutput:
    """Controller result: opening u [-], success flag, wall time [s], iterations, fallback."""

    u: float
    success: bool = True
    solve_time_s: float = 0.0
    iterations: int = 0
    fallback: bool = False


def steps_per_period(period_s: float, dt_s: float) -> int:
    """Plant steps per controller period; ValueError unless period is an integer multiple."""
    if dt_s <= 0.0 or period_s <= 0.0:
        raise ValueError(f"period_s = {period_s} and dt_s = {dt_s} must be > 0")
    ratio = period_s / dt_s
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(1.0, ratio):
        raise ValueError(
            f"controller period {period_s} s must be an integer multiple of the step {dt_s} s"
        )
    return k
