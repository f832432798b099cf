"""How far a run is from another trace of the same case: the fully coupled tp run
(:func:`prediction_vs_tp`) or a measured log (:func:`prediction_vs_measured`), both built on
:func:`trace_errors` and :func:`lag_s`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from trackmj.ports import unit_suffix
from trackmj.results.energy_terms import energy_terms, headline_energy
from trackmj.results.metric_windows import MetricWindows
from trackmj.results.signals import (
    Window,
    lowpass,
    peak_abs_error,
    rmse,
    sample_period,
    window_mask,
)


def prediction_vs_tp(columns: Mapping[str, np.ndarray], metrics: Mapping[str, Any],
                     tp_columns: Mapping[str, np.ndarray], tp_metrics: Mapping[str, Any],
                     windows: MetricWindows) -> dict[str, Any]:
    """How far a run's prediction is from the fully coupled tp run of the same case and seed.

    - ``prediction_rmse_vs_tp_N``: sqrt(mean((F − F_tp)²)) of the raw F_ten traces in the
      tracking window; ``prediction_rmse_vs_tp_lp_N``: the same on their low-passes. Zero
      for tp against itself. By the triangle inequality of the RMS, it is at least
      |rmse_N − rmse_N(tp)|: two runs can only track equally well by erring alike.
    - ``peak_pressure_error_vs_tp_Pa``: p_head_max_Pa − p_head_max_Pa(tp) (signed; dp-b's
      head pressure is the equivalent pressure of its ideal force source).
    - ``energy_error_vs_tp_J``: table, per energy term both runs have finite
      (:func:`energy_terms`): E − E_tp [J]; ``energy_error_vs_tp_pct``: 100·(E − E_tp)/E_tp
      on the term ``energy_error_term`` (:func:`headline_energy`; NaN, term None: none).

    ValueError if the two runs are not on the same time grid.
    """
    t = _same_grid(columns, tp_columns, "runs differ in their time grid; a prediction "
                   "error needs the same case, duration and step")
    y = np.asarray(columns["tension_N"], dtype=float)
    y_tp = np.asarray(tp_columns["tension_N"], dtype=float)
    ev = (windows.evaluation_start_s, float(t[-1]))
    errors = trace_errors(t, y, y_tp, ev, windows.lowpass_cutoff_Hz)
    mine, theirs = energy_terms(metrics), energy_terms(tp_metrics)
    diff = {k: mine.terms[k] - theirs.terms[k] for k in mine.terms
            if k in theirs.terms and math.isfinite(mine.terms[k] - theirs.terms[k])}
    term = headline_energy(mine, theirs)
    pct = (100.0 * diff[term] / theirs.terms[term] if term is not None
           and theirs.terms[term] != 0.0 else math.nan)
    return {"prediction_rmse_vs_tp_N": errors["rmse"],
            "prediction_rmse_vs_tp_lp_N": errors["rmse_lp"],
            "peak_pressure_error_vs_tp_Pa": (float(metrics.get("p_head_max_Pa", math.nan))
                                             - float(tp_metrics.get("p_head_max_Pa",
                                                                    math.nan))),
            "energy_error_vs_tp_J": diff, "energy_error_vs_tp_pct": pct,
            "energy_error_term": term}


def _same_grid(columns: Mapping[str, np.ndarray], other: Mapping[str, np.ndarray],
               message: str) -> np.ndarray:
    """The common ``t_s`` of two tables; ValueError(message, sample counts) otherwise."""
    t = np.asarray(columns["t_s"], dtype=float)
    t_other = np.asarray(other["t_s"], dtype=float)
    if t.shape != t_other.shape or not np.allclose(t, t_other, rtol=0.0, atol=1e-9):
        raise ValueError(f"{message} ({len(t)} and {len(t_other)} samples)")
    return t


def trace_errors(t: np.ndarray, y: np.ndarray, y_ref: np.ndarray, window: Window,
                 cutoff_Hz: float) -> dict[str, float]:
    """How far trace ``y`` is from ``y_ref`` (same grid ``t`` [s]) over ``window``, in the
    unit of y: ``rmse`` of the raw traces, ``rmse_lp`` of their low-passes
    (:func:`lowpass` at ``cutoff_Hz``), ``peak_error`` max(y) − max(y_ref) and
    ``peak_abs_error_lp`` max|lowpass(y) − lowpass(y_ref)|."""
    lp, lp_ref = lowpass(t, y, cutoff_Hz), lowpass(t, y_ref, cutoff_Hz)
    m = window_mask(t, window)
    peak = (float(np.max(y[m]) - np.max(y_ref[m])) if m.any() else math.nan)
    return {"rmse": rmse(t, y, y_ref, window), "rmse_lp": rmse(t, lp, lp_ref, window),
            "peak_error": peak, "peak_abs_error_lp": peak_abs_error(t, lp, lp_ref, window)}


LAG_MAX_S = 0.5
"""Largest lag searched by :func:`lag_s` [s]."""


def lag_s(t: np.ndarray, y: np.ndarray, y_ref: np.ndarray, window: Window,
          max_lag_s: float = LAG_MAX_S) -> float:
    """Delay of ``y`` behind ``y_ref`` [s] (> 0: y lags) over ``window``: the shift d, to
    the sample period and within ±max_lag_s, that maximises the correlation coefficient of
    y(t + d) with y_ref(t) on their overlap (each overlap normalised by its own means and
    norms, so the shrinking overlap does not pull the peak towards 0). NaN if either is
    constant there."""
    m = window_mask(t, window)
    a, b = np.asarray(y, float)[m], np.asarray(y_ref, float)[m]
    if len(a) < 3 or np.ptp(a) == 0.0 or np.ptp(b) == 0.0:
        return math.nan
    dt = sample_period(t)
    n_max = min(round(max_lag_s / dt), len(a) - 2)
    best, best_k = -math.inf, 0
    for k in range(-n_max, n_max + 1):
        x, z = (a[k:], b[: len(b) - k]) if k >= 0 else (a[: len(a) + k], b[-k:])
        x, z = x - x.mean(), z - z.mean()
        den = math.sqrt(float(x @ x) * float(z @ z))
        r = float(x @ z) / den if den > 0.0 else -math.inf
        if r > best:
            best, best_k = r, k
    return best_k * dt


MEASURED_CHANNELS_SKIPPED = ("t_s",)


def prediction_vs_measured(columns: Mapping[str, np.ndarray],
                           measured: Mapping[str, np.ndarray],
                           windows: MetricWindows) -> dict[str, dict[str, float]]:
    """How far a run is from a measured log on the run's grid (``measured``: ``t_s`` and
    any of the run's own columns, SI), per channel over the tracking window: the
    :func:`trace_errors` (names carrying the channel's unit, e.g. ``rmse_lp_Pa``) and
    ``lag_s`` (:func:`lag_s` of the low-passed traces, > 0: the simulation lags the
    measurement; on the low-passes the lag is the slow response's, not the ripple's).

    ValueError if the log is not on the run's grid or names a column the run lacks."""
    t = _same_grid(columns, measured, "the measured log is not on the run's time grid; "
                   "resample it (trackmj.results.measured.resample)")
    ev = (windows.evaluation_start_s, float(t[-1]))
    out = {}
    for name, values in measured.items():
        if name in MEASURED_CHANNELS_SKIPPED:
            continue
        if name not in columns:
            raise ValueError(f"the measured log's column {name!r} is not a column of the run")
        y = np.asarray(columns[name], dtype=float)
        unit = unit_suffix(name)
        values = np.asarray(values, dtype=float)
        fc = windows.lowpass_cutoff_Hz
        errors = trace_errors(t, y, values, ev, fc)
        out[name] = {f"{k}_{unit}" if unit else k: v for k, v in errors.items()}
        out[name]["lag_s"] = lag_s(t, lowpass(t, y, fc), lowpass(t, values, fc), ev)
    return out
