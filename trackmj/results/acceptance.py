"""The tensioner's acceptance figures (:func:`acceptance`): on the trailing mean of F_ten,
its extremes, the recovery after each disturbance edge and the worst steady offset (the
verdict on them: :mod:`trackmj.results.verdict`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from trackmj.results.metric_windows import MetricWindows
from trackmj.results.signals import trailing_mean


def _edge_recovery(t: np.ndarray, err: np.ndarray, ref: np.ndarray, edges: Sequence[float],
                   band_rel: float) -> dict[str, float]:
    """Per edge (keyed ``f"{edge:g}"``): the time [s] until |err| stays within
    band_rel·|ref| up to the next edge (or the run end); 0 if it never leaves, NaN if it
    does not return."""
    recovery = {}
    for i, edge in enumerate(edges):
        until = edges[i + 1] if i + 1 < len(edges) else t[-1]
        m = (t >= edge) & (t <= until)
        outside = np.flatnonzero(np.abs(err[m]) > band_rel * np.abs(ref[m]))
        if len(outside) == 0:
            recovery[f"{edge:g}"] = 0.0
        elif outside[-1] == m.sum() - 1:
            recovery[f"{edge:g}"] = math.nan
        else:
            recovery[f"{edge:g}"] = float(t[m][outside[-1] + 1] - edge)
    return recovery


def _worst_steady_offset(t: np.ndarray, y: np.ndarray, ref: np.ndarray,
                         events: Sequence[float], w: MetricWindows) -> float:
    """Largest |mean(y − ref)| / mean(ref) over the steady_window_s windows (sliding by 1 s
    from the evaluation start) that start ``recovery_within_s`` or more after the last of
    ``events`` [s] before their end; NaN if there is no such window."""
    worst = math.nan
    start = w.evaluation_start_s
    while start + w.steady_window_s <= t[-1] + 1e-9:
        end = start + w.steady_window_s
        last = max([e for e in events if e <= end] or [-math.inf])
        if start >= last + w.recovery_within_s:
            m = (t >= start) & (t <= end)
            offset = abs(float(np.mean(y[m] - ref[m]))) / float(np.mean(ref[m]))
            worst = offset if math.isnan(worst) else max(worst, offset)
        start += 1.0
    return worst


def drive_floor_N(drive_torque_N_m: np.ndarray, w: MetricWindows) -> np.ndarray | None:
    """The drive's floor under the idler load [N], shape of ``drive_torque_N_m`` [N·m]: while
    the idler's two strands are the drive's tight side (σ·T > 0), the sprocket's moment
    balance T₁ − T₂ = T/r with the slack side at T₂ ≥ 0 leaves the tight side at least
    T/r, and a frictionless idler passes it to both its strands, so no tensioner can hold
    the idler below G·T/r = g·max(σ·T, 0) (statics: the strands' weight and inertia, which
    add to it, neglected; :mod:`trackmj.machines.drive_load`). It takes strands that carry
    tension only: a track with bending stiffness passes part of T through its bending
    moments (M113 on its rubber bushings: the 0.5 s mean fell to 0.92 of it on W2's start
    ramp, tests/test_drive_load.py). None if the windows carry no drive load (g, σ)."""
    if w.drive_load_gain_1_m is None or w.drive_tight_sign is None:
        return None
    torque = np.asarray(drive_torque_N_m, dtype=float)
    return w.drive_load_gain_1_m * np.maximum(w.drive_tight_sign * torque, 0.0)


def acceptance(t: np.ndarray, y: np.ndarray, ref: np.ndarray, w: MetricWindows,
               drive_torque_N_m: np.ndarray | None = None) -> dict[str, Any]:
    """The tensioner's acceptance figures on the trailing ``mean_window_s`` mean of F_ten.

    - ``mean_min_N``, ``mean_max_N``: its extremes from the evaluation start (to be inside
      [force_min_N, force_max_N]); ``mean_max_s`` the time of the highest [s];
    - ``drive_floor_at_max_N``: with the drive torque [N·m, shape (n,)] and the machine's
      drive load in ``w``, the trailing mean of :func:`drive_floor_N` at that time (NaN
      without them): how much of the highest mean the drive alone forced;
    - ``edge_recovery_s``: for each disturbance edge (onset and end of a load pulse or a
      supply drop, from the evaluation start; table keyed by the edge time), the time until
      the mean stays within ±``recovery_band_rel``·F_ref up to the next edge (0 if it never
      leaves; NaN if it does not return); ``recovery_max_s`` the largest of them (NaN if
      one never returns or there is no edge);
    - ``steady_offset_max_rel``: the largest |mean(F − F_ref)| / mean(F_ref) over the
      ``steady_window_s`` windows (sliding by 1 s) that lie 2 s or more after any edge,
      reference step/ramp start or the end of the track's start ramp and end before the
      next one;
    - the settings they were taken with.
    """
    t = np.asarray(t, dtype=float)
    mean = trailing_mean(t, y, w.mean_window_s)
    err = mean - np.asarray(ref, dtype=float)
    ev = t >= w.evaluation_start_s
    edges = sorted({e for pair in w.disturbances for e in pair if w.judges_edge(e, t[-1])})
    recovery = _edge_recovery(t, err, ref, edges, w.recovery_band_rel)
    worst = _worst_steady_offset(t, y, ref,
                                 sorted({*edges, *w.reference_events_s, *w.drive_events_s}), w)
    highest = int(np.argmax(np.where(ev, mean, -np.inf))) if ev.any() else None
    floor = None if drive_torque_N_m is None else drive_floor_N(drive_torque_N_m, w)
    floor_at_max = (math.nan if floor is None or highest is None
                    else float(trailing_mean(t, floor, w.mean_window_s)[highest]))
    return {"mean_window_s": w.mean_window_s, "recovery_band_rel": w.recovery_band_rel,
            "steady_window_s": w.steady_window_s,
            "mean_min_N": float(mean[ev].min()) if ev.any() else math.nan,
            "mean_max_N": float(mean[ev].max()) if ev.any() else math.nan,
            "mean_max_s": math.nan if highest is None else float(t[highest]),
            "drive_floor_at_max_N": floor_at_max,
            "edge_recovery_s": recovery,
            "recovery_max_s": (max(recovery.values()) if recovery
                               and not any(map(math.isnan, recovery.values())) else math.nan),
            "steady_offset_max_rel": worst}
