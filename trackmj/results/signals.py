"""Performance metrics on uniformly sampled signals (pure numpy/scipy).

Conventions: ``t`` [s] is a strictly increasing, uniformly spaced time vector of shape (n,);
signals ``y`` and references ``ref`` have the same shape; the error is e = y − ref.
``window = (t0, t1)`` selects the samples with t0 <= t <= t1 (``None``: all samples). A
metric over an empty window is NaN. Time integrals use the trapezoid rule; durations of
sample sets count each sample as dt. Units follow the signal: tension in N gives errors in
N, ISE in N²·s.

The run's metric set built from these is :mod:`trackmj.results.metrics`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.signal import butter, sosfiltfilt, welch

Window = tuple[float, float] | None


def window_mask(t: np.ndarray, window: Window) -> np.ndarray:
    """Boolean mask, shape (n,), of the samples of ``t`` [s] inside ``window`` (None: all)."""
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
    m = window_mask(t, window)
    if not m.any():
        return math.nan
    e = np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m]
    return float(np.sqrt(np.mean(e * e)))


def ise(t: np.ndarray, y: np.ndarray, ref: np.ndarray, window: Window = None) -> float:
    """Integral of squared error ∫(y − ref)² dt over ``window`` (trapezoid) [unit² · s]."""
    m = window_mask(t, window)
    if m.sum() < 2:
        return math.nan
    e = np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m]
    return float(np.trapezoid(e * e, np.asarray(t, dtype=float)[m]))


def peak_abs_error(t: np.ndarray, y: np.ndarray, ref: np.ndarray,
                   window: Window = None) -> float:
    """Peak absolute error max|y − ref| over ``window`` [unit of y]."""
    m = window_mask(t, window)
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
    m = window_mask(t, window)
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
    settled; :func:`~trackmj.results.metrics.compute_metrics` uses 0.5 s).
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

    :func:`~trackmj.results.metrics.compute_metrics` measures from the disturbance START
    (onset) and holds up to the next disturbance's onset (or the run end), so the response
    to the disturbance's removal is included. Same interpolation and 0/NaN rules as
    :func:`settling_time`.
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
    m = window_mask(t, window)
    if not m.any():
        return math.nan
    e = np.asarray(y, dtype=float)[m] - np.asarray(ref, dtype=float)[m]
    lo, hi = np.percentile(e, [low_pct, high_pct])
    return float(0.5 * (hi - lo))


def constraint_violation_time(t: np.ndarray, y: np.ndarray, y_min: float, y_max: float,
                              window: Window = None) -> float:
    """Time [s] spent outside [y_min, y_max]: number of samples outside × dt."""
    m = window_mask(t, window)
    yy = np.asarray(y, dtype=float)[m]
    return float(np.count_nonzero((yy < y_min) | (yy > y_max)) * sample_period(t))


def switch_count(mode: np.ndarray) -> int:
    """Number of changes between consecutive samples of a discrete mode sequence."""
    mode = np.asarray(mode)
    return int(np.count_nonzero(mode[1:] != mode[:-1]))


def switching_rate(t: np.ndarray, mode: np.ndarray, window: Window = None) -> float:
    """Mode changes per second [Hz]: changes between consecutive samples in ``window``
    divided by the window's duration (last − first sample time)."""
    m = window_mask(t, window)
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


def psd(t: np.ndarray, x: np.ndarray, window: Window = None, *,
        resolution_Hz: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of ``x`` over ``window``: (f [Hz], PSD [unit²/Hz]).

    Welch's method: Hann window, segments of 1/``resolution_Hz`` s (2 s at 0.5 Hz; the whole
    window if shorter), 50 % overlap, each segment's mean removed; bins f = k·Δf. Parseval:
    Σ PSD·Δf is the variance of x (for a stationary x). Empty arrays if the window holds
    fewer than 8 samples; NaN densities if x is not finite there (a quantity the
    architecture does not have).
    """
    m = window_mask(t, window)
    xx = np.asarray(x, dtype=float)[m]
    if len(xx) < 8:
        return np.zeros(0), np.zeros(0)
    fs = 1.0 / sample_period(t)
    nperseg = min(len(xx), round(fs / resolution_Hz))
    f, density = welch(np.nan_to_num(xx), fs=fs, window="hann", nperseg=nperseg,
                       detrend="constant")
    if not np.isfinite(xx).all():
        density = np.full(f.shape, math.nan)
    return f, density


def psd_band_rms(f: np.ndarray, density: np.ndarray, f_low: float, f_high: float) -> float:
    """RMS in the band f_low <= f <= f_high of a PSD from :func:`psd`: sqrt(Σ PSD·Δf)
    [unit of the signal]; NaN without bins."""
    if len(f) < 2:
        return math.nan
    sel = (f >= f_low) & (f <= f_high)
    return float(np.sqrt(np.sum(density[sel]) * (f[1] - f[0])))


def band_rms(t: np.ndarray, x: np.ndarray, f_low: float, f_high: float,
             window: Window = None, *, resolution_Hz: float) -> float:
    """RMS of ``x`` in the band [f_low, f_high] Hz [unit of x].

    The Welch PSD of :func:`psd` integrated over the bins with f_low <= f <= f_high; at
    0.5 Hz resolution (2 s Hann segments) A sine of amplitude A at 10 Hz gives A/√2 in 8-12 Hz
    (its Hann main lobe, ±2 bins = ±1 Hz, lies inside); a 2 Hz sine gives ~0.
    """
    f, density = psd(t, x, window, resolution_Hz=resolution_Hz)
    return psd_band_rms(f, density, f_low, f_high)


def ripple_band_rms(t: np.ndarray, ripple: np.ndarray, bands: Mapping[str, tuple[float, float]],
                    window: Window, *, resolution_Hz: float) -> dict[str, float]:
    """RMS of ``ripple`` in each named band and in the ``rest`` of the spectrum [unit].

    From the Welch PSD of :func:`psd` over ``window``: each band integrates its bins
    (f_low <= f <= f_high), ``rest`` the bins outside every band, so the squares of the
    rest and of disjoint bands add up to the ripple's variance (Parseval).
    """
    f, density = psd(t, ripple, window, resolution_Hz=resolution_Hz)
    out = {name: psd_band_rms(f, density, lo, hi) for name, (lo, hi) in bands.items()}
    if len(f) < 2:
        return out | {"rest": math.nan}
    inside = np.zeros(f.shape, dtype=bool)
    for lo, hi in bands.values():
        inside |= (f >= lo) & (f <= hi)
    out["rest"] = float(np.sqrt(np.sum(density[~inside]) * (f[1] - f[0])))
    return out


def lowpass(t: np.ndarray, x: np.ndarray, cutoff_Hz: float) -> np.ndarray:
    """Zero-phase low-pass of ``x``, shape (n,) [unit of x].

    A 2nd-order Butterworth with design cut-off ``cutoff_Hz`` run forward and backward
    (scipy ``sosfiltfilt``, odd extension at both ends): no phase lag, magnitude
    |H(f)|² = 1/(1 + (f/f_c)⁴), i.e. −6 dB at f_c, 94 % of the amplitude at f_c/2, 0.4 % at
    4 f_c (8 Hz for f_c = 2 Hz) and 0.01 % at 10 f_c (20 Hz). The filter is acausal: a
    perfect step passed through it at f_c = 2 Hz rises from 0.11 s before the step, over-
    and undershoots by 3.4 % of the step, and stays within ±10 % of the step from 0.11 s
    after it (what it adds to a low-passed settling time against a ±300 N band on a 3 kN
    step). All NaN if ``x`` is not finite.
    """
    x = np.asarray(x, dtype=float)
    if not np.isfinite(x).all():
        return np.full(x.shape, math.nan)
    fs = 1.0 / sample_period(t)
    if not 0.0 < cutoff_Hz < 0.5 * fs:
        raise ValueError(f"cut-off {cutoff_Hz} Hz must lie in (0, {0.5 * fs:g}) Hz, the "
                         "Nyquist band of the signal")
    return sosfiltfilt(butter(2, cutoff_Hz, fs=fs, output="sos"), x)


def trailing_mean(t: np.ndarray, y: np.ndarray, window_s: float) -> np.ndarray:
    """Mean of y over the last ``window_s`` [s] up to each sample (causal boxcar; the first
    samples average what there is), same shape as y."""
    n = max(1, round(window_s / sample_period(t)))
    c = np.concatenate(([0.0], np.cumsum(np.asarray(y, dtype=float))))
    k = np.arange(1, len(y) + 1)
    lo = np.maximum(k - n, 0)
    return (c[k] - c[lo]) / (k - lo)


def cumulative_energy(t: np.ndarray, power: np.ndarray) -> np.ndarray:
    """Cumulative energy ∫P dt [J] from power [W] (trapezoid), shape (n,), starting at 0."""
    return cumulative_trapezoid(np.asarray(power, dtype=float), np.asarray(t, dtype=float),
                                initial=0.0)


def energy(t: np.ndarray, power: np.ndarray, window: Window = None) -> float:
    """Energy ∫P dt [J] over ``window`` from power [W] (trapezoid)."""
    m = window_mask(t, window)
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
