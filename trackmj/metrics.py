"""Performance metrics on uniformly sampled signals (pure numpy/scipy).

Conventions: ``t`` [s] is a strictly increasing, uniformly spaced time vector of shape (n,);
signals ``y`` and references ``ref`` have the same shape; the error is e = y − ref.
``window = (t0, t1)`` selects the samples with t0 <= t <= t1 (``None``: all samples). A
metric over an empty window is NaN. Time integrals use the trapezoid rule; durations of
sample sets count each sample as dt. Units follow the signal: tension in N gives errors in
N, ISE in N²·s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

Window = tuple[float, float] | None


def _sel(t: np.ndarray, window: Window) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if window is None:
        return np.ones(t.shape, dtype=bool)
    return (t >= window[0]) & (t <= window[1])


def sample_period(t: np.ndarray) -> float:
    """Sample period dt [s] of uniformly sampled ``t`` (median spacing)."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2:
        raise ValueError("need at least two samples to know the sample period")
    return float(np.median(np.diff(t)))


def rmse(t: np.ndarray, y: np.ndarray, ref: np.ndarray, window: Window = None) -> float:
    """Root-mean-square error sqrt(mean((y − ref)²)) over ``window`` [unit of y]."""
    m = _sel(t, window)
    if not m.any():
        return math.nan
    e = np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m]
    return float(np.sqrt(np.mean(e * e)))


def ise(t: np.ndarray, y: np.ndarray, ref: np.ndarray, window: Window = None) -> float:
    """Integral of squared error ∫(y − ref)² dt over ``window`` (trapezoid) [unit² · s]."""
    m = _sel(t, window)
    if m.sum() < 2:
        return math.nan
    e = np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m]
    return float(np.trapezoid(e * e, np.asarray(t, dtype=float)[m]))


def peak_abs_error(t: np.ndarray, y: np.ndarray, ref: np.ndarray,
                   window: Window = None) -> float:
    """Peak absolute error max|y − ref| over ``window`` [unit of y]."""
    m = _sel(t, window)
    if not m.any():
        return math.nan
    return float(np.max(np.abs(np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m])))


class Overshoot(NamedTuple):
    """Overshoot beyond the final value: ``value`` [unit of y] and ``percent`` of |final|."""

    value: float
    percent: float


def overshoot(t: np.ndarray, y: np.ndarray, initial: float, final: float,
              window: Window = None) -> Overshoot:
    """Overshoot of a step response from ``initial`` to ``final`` over ``window``.

    value = max(0, max(s·(y − final))) with s = sign(final − initial): how far the response
    goes beyond the final value in the step direction [unit of y]. percent = 100·value/|final|
    (the study's convention: 15.7 kN after a 12 -> 15 kN step is 4.6 %; 100·value/|final −
    initial| would be the textbook one and equals it for steps from 0).
    """
    m = _sel(t, window)
    if not m.any() or final == initial:
        return Overshoot(math.nan, math.nan)
    s = math.copysign(1.0, final - initial)
    value = max(0.0, float(np.max(s * (np.asarray(y, dtype=float)[m] - final))))
    return Overshoot(value, 100.0 * value / abs(final) if final != 0 else math.nan)


def _time_to_stay_within(t: np.ndarray, err: np.ndarray, band: float, t_from: float,
                         t_until: float, min_hold_s: float) -> float:
    """Time after ``t_from`` from which |err| <= band holds up to ``t_until`` (linear
    interpolation of the last exit); 0 if never outside; NaN if the final stay inside the
    band is shorter than ``min_hold_s`` (or empty: outside at ``t_until``)."""
    m = (t >= t_from) & (t <= t_until)
    tt, ee = t[m], np.abs(err[m])
    if len(tt) == 0:
        return math.nan
    outside = np.flatnonzero(ee > band)
    if len(outside) == 0:
        return 0.0
    k = outside[-1]
    if k == len(tt) - 1:
        return math.nan
    e0, e1 = ee[k], ee[k + 1]
    frac = (e0 - band) / (e0 - e1) if e0 != e1 else 1.0
    t_in = float(tt[k] + frac * (tt[k + 1] - tt[k]))
    if tt[-1] - t_in < min_hold_s:
        return math.nan
    return t_in - t_from


def settling_time(t: np.ndarray, y: np.ndarray, final: float, t_step: float, *,
                  band_rel: float = 0.02, band_abs: float | None = None,
                  t_end: float | None = None, min_hold_s: float = 0.0) -> float:
    """Settling time [s] after a step at ``t_step`` towards ``final``.

    The time from ``t_step`` after which y stays within ±band of ``final`` up to ``t_end``
    (default: the last sample). band = ``band_abs`` if given, else ``band_rel``·|final| (2 %
    of the final value by default: ±300 N at 15 kN). The last exit from the band is linearly
    interpolated between samples. 0 if y never leaves the band, NaN if it has not settled by
    ``t_end``, i.e. if its final stay inside the band is shorter than ``min_hold_s`` (an
    oscillation that merely passes through the band at the end of the window has not
    settled; :func:`compute_metrics` uses 0.5 s).
    """
    t = np.asarray(t, dtype=float)
    band = band_abs if band_abs is not None else band_rel * abs(final)
    t_end = float(t[-1]) if t_end is None else t_end
    return _time_to_stay_within(t, np.asarray(y, dtype=float) - final, band, t_step, t_end,
                                min_hold_s)


def recovery_time(t: np.ndarray, y: np.ndarray, ref: np.ndarray, t_from: float,
                  t_until: float, band: float, *, min_hold_s: float = 0.0) -> float:
    """Recovery time [s] after a disturbance: from ``t_from`` until |y − ref| <= ``band``
    holds up to ``t_until``.

    :func:`compute_metrics` measures from the disturbance START (onset) and holds up to the
    next disturbance's onset (or the run end), so the response to the disturbance's removal
    is included. Same interpolation and 0/NaN rules as :func:`settling_time`.
    """
    t = np.asarray(t, dtype=float)
    err = np.asarray(y, dtype=float) - np.asarray(ref, dtype=float)
    return _time_to_stay_within(t, err, band, t_from, t_until, min_hold_s)


def fluctuation_band(t: np.ndarray, y: np.ndarray, ref: np.ndarray, window: Window = None,
                     *, low_pct: float = 2.5, high_pct: float = 97.5) -> float:
    """Fluctuation band ±F [unit of y]: half of the spread between the 2.5th and 97.5th
    percentiles of the error y − ref in a steady ``window``.

    Read as "y stays within ref + centre ± F for 95 % of the time" like the study's ±1.3 kN;
    a sine of amplitude A gives ~0.997 A, Gaussian noise of std σ gives 1.96 σ.
    """
    m = _sel(t, window)
    if not m.any():
        return math.nan
    e = np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m]
    lo, hi = np.percentile(e, [low_pct, high_pct])
    return float(0.5 * (hi - lo))


def constraint_violation_time(t: np.ndarray, y: np.ndarray, y_min: float, y_max: float,
                              window: Window = None) -> float:
    """Time [s] spent outside [y_min, y_max]: number of samples outside × dt."""
    m = _sel(t, window)
    yy = np.asarray(y, dtype=float)[m]
    return float(np.count_nonzero((yy < y_min) | (yy > y_max)) * sample_period(t))


def switch_count(mode: np.ndarray) -> int:
    """Number of changes between consecutive samples of a discrete mode sequence."""
    mode = np.asarray(mode)
    return int(np.count_nonzero(mode[1:] != mode[:-1]))


def switching_rate(t: np.ndarray, mode: np.ndarray, window: Window = None) -> float:
    """Mode changes per second [Hz]: changes between consecutive samples in ``window``
    divided by the window's duration (last − first sample time)."""
    m = _sel(t, window)
    tt = np.asarray(t, dtype=float)[m]
    if len(tt) < 2:
        return math.nan
    return switch_count(np.asarray(mode)[m]) / float(tt[-1] - tt[0])


def control_increment_rms(u: np.ndarray, stride: int = 1) -> float:
    """RMS of the control increments Δu between successive control updates [unit of u].

    u is sampled every plant step; with a control period of ``stride`` steps (10 for a
    10 ms period at 1 kHz) the increments are diff(u[::stride]), so the zero increments
    between updates do not dilute the figure.
    """
    du = np.diff(np.asarray(u, dtype=float)[::stride])
    return float(np.sqrt(np.mean(du * du))) if len(du) else math.nan


def band_rms(t: np.ndarray, x: np.ndarray, f_low: float = 8.0, f_high: float = 12.0,
             window: Window = None, *, resolution_hz: float = 0.5) -> float:
    """RMS of ``x`` in the band [f_low, f_high] Hz [unit of x].

    Welch PSD (Hann window, segments of 1/``resolution_hz`` s = 2 s at 0.5 Hz, 50 % overlap,
    mean removed), integrated over the bins with f_low <= f <= f_high: sqrt(Σ PSD·Δf). A sine
    of amplitude A at 10 Hz gives A/√2 (its Hann main lobe, ±2 bins = ±1 Hz, lies inside
    8-12 Hz); a 2 Hz sine gives ~0.
    """
    m = _sel(t, window)
    xx = np.asarray(x, dtype=float)[m]
    if len(xx) < 8:
        return math.nan
    from scipy.signal import welch  # imported here: scipy.signal costs ~0.3 s to import

    fs = 1.0 / sample_period(t)
    nperseg = min(len(xx), round(fs / resolution_hz))
    f, psd = welch(xx, fs=fs, window="hann", nperseg=nperseg, detrend="constant")
    sel = (f >= f_low) & (f <= f_high)
    return float(np.sqrt(np.sum(psd[sel]) * (f[1] - f[0])))


def cumulative_energy(t: np.ndarray, power: np.ndarray) -> np.ndarray:
    """Cumulative energy ∫P dt [J] from power [W] (trapezoid), shape (n,), starting at 0."""
    from scipy.integrate import cumulative_trapezoid

    return cumulative_trapezoid(np.asarray(power, dtype=float), np.asarray(t, dtype=float),
                                initial=0.0)


def energy(t: np.ndarray, power: np.ndarray, window: Window = None) -> float:
    """Energy ∫P dt [J] over ``window`` from power [W] (trapezoid)."""
    m = _sel(t, window)
    if m.sum() < 2:
        return 0.0
    return float(np.trapezoid(np.asarray(power, dtype=float)[m], np.asarray(t, dtype=float)[m]))


class SolveStats(NamedTuple):
    """Controller solve statistics: median and max wall time [s], failure count."""

    median_s: float
    max_s: float
    failures: int


def solve_time_stats(solve_times_s: np.ndarray, success: np.ndarray | None = None) -> SolveStats:
    """Median/max of per-solve wall times [s] and the number of failed solves."""
    st = np.asarray(solve_times_s, dtype=float)
    if len(st) == 0:
        return SolveStats(math.nan, math.nan, 0)
    fails = 0 if success is None else int(np.count_nonzero(~np.asarray(success, dtype=bool)))
    return SolveStats(float(np.median(st)), float(np.max(st)), fails)


# ------------------------------------------------------------------ standard metric set

@dataclass(frozen=True)
class MetricWindows:
    """Windows and bands of a scenario for :func:`compute_metrics` (times in s, forces in N).

    evaluation_start_s: start of the tracking window for RMSE/ISE/peak error/violation
    time/switch rate/energy (skips the start-up transient). step: (t_step, initial, final,
    t_end) of a reference step (overshoot and settling evaluated in [t_step, t_end]).
    disturbances: (onset, end) windows of load pulses or supply drops. steady: window for
    the fluctuation band, mean tension and 8-12 Hz chassis acceleration. settle_band_rel:
    settling band relative to the final value; recovery_band_N: recovery band (None:
    settle_band_rel·|ref| at the onset). min_hold_s: how long a response must stay inside
    its band before the window ends to count as settled/recovered. control_period_s: for
    the control-increment RMS. acc_band_hz: band of the chassis acceleration RMS.
    """

    force_min_N: float
    force_max_N: float
    evaluation_start_s: float = 0.0
    step: tuple[float, float, float, float] | None = None
    disturbances: tuple[tuple[float, float], ...] = ()
    steady: tuple[float, float] | None = None
    settle_band_rel: float = 0.02
    recovery_band_N: float | None = None
    min_hold_s: float = 0.5
    control_period_s: float = 0.01
    acc_band_hz: tuple[float, float] = (8.0, 12.0)


REQUIRED_COLUMNS = ("t_s", "tension_N", "tension_ref_N", "p_head_Pa", "valve_mode", "u",
                    "e_supply_J", "p_work_J", "mech_work_J", "chassis_acc_z_m_s2")


def compute_metrics(columns: Mapping[str, np.ndarray], windows: MetricWindows, *,
                    solve_times_s: Sequence[float] | None = None,
                    solve_success: Sequence[bool] | None = None,
                    wall_time_s: float | None = None) -> dict[str, float]:
    """Standard metric set from the timeseries contract (see ``trackmj.results``).

    Returns (all floats; NaN where undefined, e.g. no step or an empty window):

    - ``rmse_N``, ``ise_N2s``, ``peak_error_N``: tension error in [evaluation_start, end].
    - ``tension_mean_N``, ``fluctuation_N`` (half the 2.5-97.5 % error spread),
      ``chassis_acc_rms_8_12Hz_m_s2``: in the steady window.
    - ``tension_max_N``, ``tension_min_N``, ``p_head_max_Pa``: extremes after evaluation start.
    - ``overshoot_N``, ``overshoot_pct`` (of the final value), ``settling_time_s``: step.
    - ``disturbance_peak_error_N``: max |e| from each disturbance onset to the next onset
      (or run end); ``recovery_time_s``: the largest recovery time over disturbances, each
      measured from its onset (see :func:`recovery_time`); NaN if any did not recover.
    - ``constraint_violation_s``: time with tension outside [force_min_N, force_max_N].
    - ``valve_switch_rate_Hz``: valve mode changes per second; ``valve_switches``: count.
    - ``control_increment_rms``: RMS of Δu per control period (u dimensionless).
    - ``interface_energy_residual_J``: p_work_J − mech_work_J at the end (∫Σp·A·v dt vs
      ∫F·v dt; zero for a power-conserving interface).

    The energy breakdown of a run (``energy_J``, pump to track) comes from the tensioner's
    own ledger, not from the timeseries: :mod:`trackmj.energy`.
    - ``solve_time_median_s``, ``solve_time_max_s``, ``solve_failures``: if solve times given.
    - ``real_time_factor``: simulated time / ``wall_time_s`` if given (> 1: faster than real).
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise KeyError(f"timeseries lacks column(s) {missing}")
    t = np.asarray(columns["t_s"], dtype=float)
    y = np.asarray(columns["tension_N"], dtype=float)
    ref = np.asarray(columns["tension_ref_N"], dtype=float)
    t_end = float(t[-1])
    w = windows
    ev = (w.evaluation_start_s, t_end)
    ev_mask = _sel(t, ev)
    out: dict[str, float] = {
        "rmse_N": rmse(t, y, ref, ev),
        "ise_N2s": ise(t, y, ref, ev),
        "peak_error_N": peak_abs_error(t, y, ref, ev),
        "tension_max_N": float(np.max(y[ev_mask])) if ev_mask.any() else math.nan,
        "tension_min_N": float(np.min(y[ev_mask])) if ev_mask.any() else math.nan,
        "p_head_max_Pa": (float(np.max(np.asarray(columns["p_head_Pa"])[ev_mask]))
                          if ev_mask.any() else math.nan),
    }
    steady = None if w.steady is None else (w.steady[0], min(w.steady[1], t_end))
    steady_ok = steady is not None and steady[1] > steady[0]
    sm = _sel(t, steady) if steady_ok else np.zeros(t.shape, dtype=bool)
    out["tension_mean_N"] = float(np.mean(y[sm])) if sm.any() else math.nan
    out["fluctuation_N"] = fluctuation_band(t, y, ref, steady) if steady_ok else math.nan
    acc = columns["chassis_acc_z_m_s2"]
    out["chassis_acc_rms_8_12Hz_m_s2"] = (band_rms(t, acc, *w.acc_band_hz, steady)
                                          if steady_ok else math.nan)

    over, settle = Overshoot(math.nan, math.nan), math.nan
    if w.step is not None and w.step[0] < t_end:
        t_step, initial, final, t_stop = w.step
        t_stop = min(t_stop, t_end)
        over = overshoot(t, y, initial, final, (t_step, t_stop))
        settle = settling_time(t, y, final, t_step, band_rel=w.settle_band_rel, t_end=t_stop,
                               min_hold_s=w.min_hold_s)
    out["overshoot_N"], out["overshoot_pct"] = over.value, over.percent
    out["settling_time_s"] = settle

    onsets = sorted(on for on, _ in w.disturbances if on < t_end)
    peaks, recoveries = [], []
    for k, on in enumerate(onsets):
        until = onsets[k + 1] if k + 1 < len(onsets) else t_end
        i_on = min(int(np.searchsorted(t, on)), len(t) - 1)
        band = (w.recovery_band_N if w.recovery_band_N is not None
                else w.settle_band_rel * abs(ref[i_on]))
        peaks.append(peak_abs_error(t, y, ref, (on, until)))
        recoveries.append(recovery_time(t, y, ref, on, until, band, min_hold_s=w.min_hold_s))
    out["disturbance_peak_error_N"] = max(peaks) if peaks else math.nan
    out["recovery_time_s"] = (math.nan if not recoveries or any(map(math.isnan, recoveries))
                              else max(recoveries))

    out["constraint_violation_s"] = constraint_violation_time(t, y, w.force_min_N,
                                                              w.force_max_N, ev)
    mode = np.asarray(columns["valve_mode"])
    out["valve_switches"] = float(switch_count(mode[ev_mask]))
    out["valve_switch_rate_Hz"] = switching_rate(t, mode, ev)
    stride = max(1, round(w.control_period_s / sample_period(t)))
    out["control_increment_rms"] = control_increment_rms(np.asarray(columns["u"])[ev_mask],
                                                         stride)
    out["interface_energy_residual_J"] = float(np.asarray(columns["p_work_J"])[-1]
                                               - np.asarray(columns["mech_work_J"])[-1])
    if solve_times_s is not None:
        stats = solve_time_stats(np.asarray(solve_times_s),
                                 None if solve_success is None else np.asarray(solve_success))
        out["solve_time_median_s"] = stats.median_s
        out["solve_time_max_s"] = stats.max_s
        out["solve_failures"] = float(stats.failures)
    if wall_time_s is not None:
        out["real_time_factor"] = ((t_end - float(t[0])) / wall_time_s if wall_time_s > 0
                                   else math.nan)
    return out
