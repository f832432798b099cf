"""Performance metrics on uniformly sampled signals (pure numpy/scipy).

Conventions: ``t`` [s] is a strictly increasing, uniformly spaced time vector of shape (n,);
signals ``y`` and references ``ref`` have the same shape; the error is e = y − ref.
``window = (t0, t1)`` selects the samples with t0 <= t <= t1 (``None``: all samples). A
metric over an empty window is NaN. Time integrals use the trapezoid rule; durations of
sample sets count each sample as dt. Units follow the signal: tension in N gives errors in
N, ISE in N²·s.

Two views of the tension F_ten (see :func:`compute_metrics` for the full list):

* **raw**: the 1 kHz signal as simulated, carrying the track's chordal ripple (tooth
  passing at v/pitch, ~20 Hz at 1.5 m/s) that no valve with a 25 ms minimum hold follows;
* **low-passed** (``_lp`` in the name): F_ten through :func:`lowpass`, a zero-phase
  2nd-order Butterworth at the scenario's ``[evaluation].lowpass_cutoff_Hz`` (2 Hz in
  W1-W5), compared with the unfiltered reference: the band the controller can act on.
  The ripple is what the low-pass removes, F_ten − lowpass(F_ten).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

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


def psd(t: np.ndarray, x: np.ndarray, window: Window = None, *,
        resolution_Hz: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of ``x`` over ``window``: (f [Hz], PSD [unit²/Hz]).

    Welch's method: Hann window, segments of 1/``resolution_Hz`` s (2 s at 0.5 Hz; the whole
    window if shorter), 50 % overlap, each segment's mean removed; bins f = k·Δf. Parseval:
    Σ PSD·Δf is the variance of x (for a stationary x). Empty arrays if the window holds
    fewer than 8 samples; NaN densities if x is not finite there (a quantity the
    architecture does not have).
    """
    m = _sel(t, window)
    xx = np.asarray(x, dtype=float)[m]
    if len(xx) < 8:
        return np.zeros(0), np.zeros(0)
    from scipy.signal import welch  # imported here: scipy.signal costs ~0.3 s to import

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
    from scipy.signal import butter, sosfiltfilt

    fs = 1.0 / sample_period(t)
    if not 0.0 < cutoff_Hz < 0.5 * fs:
        raise ValueError(f"cut-off {cutoff_Hz} Hz must lie in (0, {0.5 * fs:g}) Hz, the "
                         "Nyquist band of the signal")
    return sosfiltfilt(butter(2, cutoff_Hz, fs=fs, output="sos"), x)


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

@dataclass(frozen=True, kw_only=True)
class MetricWindows:
    """Windows, bands and settings of a scenario for :func:`compute_metrics` (times in s,
    forces in N, frequencies in Hz); built by ``Scenario.metric_windows`` from the scenario's
    ``[limits]`` and ``[evaluation]`` tables.

    evaluation_start_s: start of the tracking window (RMSE, peak error, ripple, violation
    time, switching; skips the start-up transient). steady: window of the fluctuation band,
    the mean tension and the spectra. step: (t_step, initial, final, t_end) of a reference
    step, its overshoot and settling evaluated in [t_step, t_end]. disturbances: (onset,
    end) windows of load pulses or supply drops, disturbance_labels what each one is (for
    figures; empty: unnamed); an onset or end before evaluation_start_s is the run's initial
    condition (e.g. NL1's supply held at 9 MPa from t = 0), not an edge the disturbance and
    acceptance metrics judge. settle_band_rel: settling and recovery band
    relative to the final value (recovery: to the reference at the onset), unless
    recovery_band_N is given. min_hold_s: how long a response must stay inside its band
    before the window ends to count as settled/recovered. lowpass_cutoff_Hz: cut-off of
    :func:`lowpass` for the ``_lp`` metrics. body_mode_band_Hz: the track-idler-body mode
    band; tooth_passing_band_Hz: the sprocket tooth (link) passing band v/pitch ± the
    scenario's tooth_band_rel (None: no track, or its pitch unknown); road_band_Hz: the
    band the road excites (speed × the ISO 8608 spatial band; None on flat ground), marked
    on figures only. psd_resolution_Hz, psd_max_Hz: resolution and upper end of the spectra.
    mean_window_s, recovery_band_rel, steady_window_s, reference_events_s: the
    :func:`acceptance` checks (trailing-mean length, recovery band relative to the
    reference, steady-window length, and the reference's steps and ramp starts, which end a
    steady window like a disturbance edge does).
    """

    force_min_N: float
    force_max_N: float
    evaluation_start_s: float
    settle_band_rel: float
    min_hold_s: float
    lowpass_cutoff_Hz: float
    body_mode_band_Hz: tuple[float, float]
    psd_resolution_Hz: float
    psd_max_Hz: float
    tooth_passing_band_Hz: tuple[float, float] | None = None
    road_band_Hz: tuple[float, float] | None = None
    step: tuple[float, float, float, float] | None = None
    disturbances: tuple[tuple[float, float], ...] = ()
    disturbance_labels: tuple[str, ...] = ()
    steady: tuple[float, float] | None = None
    recovery_band_N: float | None = None
    mean_window_s: float = 0.5
    recovery_band_rel: float = 0.05
    steady_window_s: float = 5.0
    reference_events_s: tuple[float, ...] = ()

    def judges_edge(self, t_s: float, t_end_s: float) -> bool:
        """Whether a disturbance edge at ``t_s`` [s] is judged in a run ending at ``t_end_s``:
        from the evaluation start (an earlier edge is the run's initial condition) to the
        end."""
        return self.evaluation_start_s <= t_s < t_end_s

    def ripple_bands_Hz(self) -> dict[str, tuple[float, float]]:
        """Named bands the ripple is split into: ``tooth_passing`` (if known), ``body_mode``."""
        bands = {} if self.tooth_passing_band_Hz is None else {
            "tooth_passing": self.tooth_passing_band_Hz}
        return bands | {"body_mode": self.body_mode_band_Hz}

    def as_table(self) -> dict[str, Any]:
        """The windows as a JSON-ready table (``metrics["evaluation"]``); fields that are
        None are left out. :meth:`from_table` reads it back."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> MetricWindows:
        """Windows from :meth:`as_table` (after a JSON round trip: lists back to tuples)."""
        def tupled(value: Any) -> Any:
            return tuple(tupled(v) for v in value) if isinstance(value, list | tuple) else value

        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: tupled(v) for k, v in table.items() if k in names})


REQUIRED_COLUMNS = ("t_s", "tension_N", "tension_ref_N", "p_head_Pa", "valve_mode", "u",
                    "e_supply_J", "p_work_J", "mech_work_J", "chassis_acc_z_m_s2")


def _name(base: str, unit: str, lowpassed: bool) -> str:
    return f"{base}_lp_{unit}" if lowpassed else f"{base}_{unit}"


def _tracking(t: np.ndarray, y: np.ndarray, ref: np.ndarray, w: MetricWindows,
              lowpassed: bool) -> dict[str, float]:
    """The tracking metrics of one view of the tension (raw or low-passed), named for it."""
    t_end = float(t[-1])
    ev = (w.evaluation_start_s, t_end)
    ev_mask = _sel(t, ev)
    out = {_name("rmse", "N", lowpassed): rmse(t, y, ref, ev),
           _name("peak_error", "N", lowpassed): peak_abs_error(t, y, ref, ev),
           _name("tension_max", "N", lowpassed): (float(np.max(y[ev_mask])) if ev_mask.any()
                                                  else math.nan),
           _name("tension_min", "N", lowpassed): (float(np.min(y[ev_mask])) if ev_mask.any()
                                                  else math.nan)}
    steady = None if w.steady is None else (w.steady[0], min(w.steady[1], t_end))
    out[_name("fluctuation", "N", lowpassed)] = (
        fluctuation_band(t, y, ref, steady) if steady is not None and steady[1] > steady[0]
        else math.nan)
    over, settle = Overshoot(math.nan, math.nan), math.nan
    if w.step is not None and w.step[0] < t_end:
        t_step, initial, final, t_stop = w.step
        t_stop = min(t_stop, t_end)
        over = overshoot(t, y, initial, final, (t_step, t_stop))
        settle = settling_time(t, y, final, t_step, band_rel=w.settle_band_rel, t_end=t_stop,
                               min_hold_s=w.min_hold_s)
    out[_name("overshoot", "N", lowpassed)] = over.value
    out[_name("overshoot", "pct", lowpassed)] = over.percent
    out[_name("settling_time", "s", lowpassed)] = settle
    onsets = sorted(on for on, _ in w.disturbances if w.judges_edge(on, t_end))
    peaks, recoveries = [], []
    for k, on in enumerate(onsets):
        until = onsets[k + 1] if k + 1 < len(onsets) else t_end
        i_on = min(int(np.searchsorted(t, on)), len(t) - 1)
        band = (w.recovery_band_N if w.recovery_band_N is not None
                else w.settle_band_rel * abs(ref[i_on]))
        peaks.append(peak_abs_error(t, y, ref, (on, until)))
        recoveries.append(recovery_time(t, y, ref, on, until, band, min_hold_s=w.min_hold_s))
    out[_name("disturbance_peak_error", "N", lowpassed)] = max(peaks) if peaks else math.nan
    out[_name("recovery_time", "s", lowpassed)] = (
        math.nan if not recoveries or any(map(math.isnan, recoveries)) else max(recoveries))
    return out


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


def trailing_mean(t: np.ndarray, y: np.ndarray, window_s: float) -> np.ndarray:
    """Mean of y over the last ``window_s`` [s] up to each sample (causal boxcar; the first
    samples average what there is), same shape as y."""
    n = max(1, round(window_s / sample_period(t)))
    c = np.concatenate(([0.0], np.cumsum(np.asarray(y, dtype=float))))
    k = np.arange(1, len(y) + 1)
    lo = np.maximum(k - n, 0)
    return (c[k] - c[lo]) / (k - lo)


def acceptance(t: np.ndarray, y: np.ndarray, ref: np.ndarray,
               w: MetricWindows) -> dict[str, Any]:
    """The tensioner's acceptance figures on the trailing ``mean_window_s`` mean of F_ten.

    - ``mean_min_N``, ``mean_max_N``: its extremes from the evaluation start (to be inside
      [force_min_N, force_max_N]);
    - ``edge_recovery_s``: for each disturbance edge (onset and end of a load pulse or a
      supply drop, from the evaluation start; table keyed by the edge time), the time until
      the mean stays within ±``recovery_band_rel``·F_ref up to the next edge (0 if it never
      leaves; NaN if it does not return); ``recovery_max_s`` the largest of them (NaN if
      one never returns or there is no edge);
    - ``steady_offset_max_rel``: the largest |mean(F − F_ref)| / mean(F_ref) over the
      ``steady_window_s`` windows (sliding by 1 s) that lie 2 s or more after any edge or
      reference step/ramp start and end before the next one;
    - the settings they were taken with.
    """
    t = np.asarray(t, dtype=float)
    mean = trailing_mean(t, y, w.mean_window_s)
    err = mean - np.asarray(ref, dtype=float)
    ev = t >= w.evaluation_start_s
    edges = sorted({e for pair in w.disturbances for e in pair if w.judges_edge(e, t[-1])})
    recovery = {}
    for i, edge in enumerate(edges):
        until = edges[i + 1] if i + 1 < len(edges) else t[-1]
        m = (t >= edge) & (t <= until)
        outside = np.flatnonzero(np.abs(err[m]) > w.recovery_band_rel * np.abs(ref[m]))
        if len(outside) == 0:
            recovery[f"{edge:g}"] = 0.0
        elif outside[-1] == m.sum() - 1:
            recovery[f"{edge:g}"] = math.nan
        else:
            recovery[f"{edge:g}"] = float(t[m][outside[-1] + 1] - edge)
    events = sorted({*edges, *w.reference_events_s})
    worst = math.nan
    start = w.evaluation_start_s
    while start + w.steady_window_s <= t[-1] + 1e-9:
        end = start + w.steady_window_s
        last = max([e for e in events if e <= end] or [-math.inf])
        if start >= last + 2.0:
            m = (t >= start) & (t <= end)
            offset = abs(float(np.mean(y[m] - ref[m]))) / float(np.mean(ref[m]))
            worst = offset if math.isnan(worst) else max(worst, offset)
        start += 1.0
    return {"mean_window_s": w.mean_window_s, "recovery_band_rel": w.recovery_band_rel,
            "steady_window_s": w.steady_window_s,
            "mean_min_N": float(mean[ev].min()) if ev.any() else math.nan,
            "mean_max_N": float(mean[ev].max()) if ev.any() else math.nan,
            "edge_recovery_s": recovery,
            "recovery_max_s": (max(recovery.values()) if recovery
                               and not any(map(math.isnan, recovery.values())) else math.nan),
            "steady_offset_max_rel": worst}


def compute_metrics(columns: Mapping[str, np.ndarray], windows: MetricWindows, *,
                    control_period_s: float | None = None,
                    solve_times_s: Sequence[float] | None = None,
                    solve_success: Sequence[bool] | None = None,
                    wall_time_s: float | None = None) -> dict[str, Any]:
    """Standard metric set from the timeseries contract (see ``trackmj.results.store``).

    "Tracking window": [evaluation_start_s, end]; "steady window": ``windows.steady``. The
    tracking metrics come twice, on the **raw** F_ten and on the **low-passed** F_ten
    (``_lp`` in the name; :func:`lowpass` at ``lowpass_cutoff_Hz``), always against the
    unfiltered reference F_ref:

    - ``rmse_N`` / ``rmse_lp_N``: sqrt(mean((F − F_ref)²)) in the tracking window;
    - ``peak_error_N`` / ``peak_error_lp_N``: max|F − F_ref| in the tracking window;
    - ``tension_max_N``, ``tension_min_N`` (and ``_lp_``): extremes in the tracking window;
    - ``fluctuation_N`` / ``fluctuation_lp_N``: ± half the 2.5-97.5 % spread of F − F_ref in
      the steady window (:func:`fluctuation_band`);
    - ``overshoot_N``, ``overshoot_pct`` (of the final value), ``settling_time_s`` (and
      ``_lp_``): of the reference step, in [t_step, t_end] (:func:`overshoot`,
      :func:`settling_time`, band ±settle_band_rel·|final|, held min_hold_s);
    - ``disturbance_peak_error_N`` (and ``_lp_``): max|F − F_ref| from each disturbance
      onset to the next onset (or the run end), the largest over disturbances;
      ``recovery_time_s`` (and ``_lp_``): the largest recovery time over disturbances, each
      from its onset (:func:`recovery_time`); NaN if any did not recover.

    Raw only:

    - ``ise_N2s``: ∫(F − F_ref)² dt in the tracking window; ``tension_mean_N``: mean F in
      the steady window; ``p_head_max_Pa``: peak head pressure in the tracking window;
    - ``ripple_rms_N``: RMS of the ripple F − lowpass(F) in the tracking window (with
      ``rmse_lp_N``: rmse_N² ≈ rmse_lp_N² + ripple_rms_N², the cross term being the
      covariance of a slow and a fast signal); ``ripple_band_rms_N``: table of the ripple's
      RMS in the named bands (``tooth_passing`` v/pitch ± tooth_band_rel, ``body_mode``) and
      the ``rest``, from its Welch PSD in the tracking window (:func:`ripple_band_rms`);
    - ``psd``: table of spectra in the steady window up to psd_max_Hz at psd_resolution_Hz
      (:func:`psd`): ``f_Hz``, ``tension_N2_Hz`` (raw F_ten), ``chassis_acc_m2_s4_Hz``
      (chassis vertical acceleration; null without a chassis);
    - ``chassis_acc_body_mode_rms_m_s2``: chassis vertical acceleration RMS in the body-mode
      band (8-12 Hz in W1-W5), steady window;
    - ``constraint_violation_s``: time with F outside [force_min_N, force_max_N];
      ``valve_switches`` and ``valve_switch_rate_Hz``: valve mode changes (count, per s);
    - ``control_increment_rms``: RMS of Δu per control period (u dimensionless; NaN unless
      ``control_period_s`` is given);
    - ``interface_energy_residual_J``: p_work_J − mech_work_J at the end (∫Σp·A·v dt vs
      ∫F·v dt; zero for a power-conserving interface);
    - ``solve_time_median_s``, ``solve_time_max_s``, ``solve_failures``: if solve times
      given; ``real_time_factor``: simulated time / ``wall_time_s`` if given (> 1: faster
      than real time).

    The energy breakdown of a run (``energy_J``, pump to track) comes from the tensioner's
    own ledger, not from the timeseries: :mod:`trackmj.elements.energy_table`.

    ``evaluation``: the windows themselves (:meth:`MetricWindows.as_table`), so a result
    states what its metrics were measured on. Floats are NaN where undefined (no step, an
    empty window, a quantity the architecture lacks).
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise KeyError(f"timeseries lacks column(s) {missing}")
    t = np.asarray(columns["t_s"], dtype=float)
    y = np.asarray(columns["tension_N"], dtype=float)
    ref = np.asarray(columns["tension_ref_N"], dtype=float)
    w = windows
    t_end = float(t[-1])
    ev = (w.evaluation_start_s, t_end)
    ev_mask = _sel(t, ev)
    y_lp = lowpass(t, y, w.lowpass_cutoff_Hz)
    out: dict[str, Any] = _tracking(t, y, ref, w, lowpassed=False)
    out |= _tracking(t, y_lp, ref, w, lowpassed=True)
    out["ise_N2s"] = ise(t, y, ref, ev)
    out["p_head_max_Pa"] = (float(np.max(np.asarray(columns["p_head_Pa"])[ev_mask]))
                            if ev_mask.any() else math.nan)
    ripple = y - y_lp
    out["ripple_rms_N"] = float(np.sqrt(np.mean(ripple[ev_mask] ** 2))) if ev_mask.any() \
        else math.nan
    out["ripple_band_rms_N"] = ripple_band_rms(t, ripple, w.ripple_bands_Hz(), ev,
                                               resolution_Hz=w.psd_resolution_Hz)

    steady = None if w.steady is None else (w.steady[0], min(w.steady[1], t_end))
    steady_ok = steady is not None and steady[1] > steady[0]
    sm = _sel(t, steady) if steady_ok else np.zeros(t.shape, dtype=bool)
    out["tension_mean_N"] = float(np.mean(y[sm])) if sm.any() else math.nan
    acc = np.asarray(columns["chassis_acc_z_m_s2"], dtype=float)
    f, p_tension = psd(t, y, steady, resolution_Hz=w.psd_resolution_Hz) if steady_ok \
        else (np.zeros(0), np.zeros(0))
    _, p_acc = psd(t, acc, steady, resolution_Hz=w.psd_resolution_Hz) if steady_ok \
        else (np.zeros(0), np.zeros(0))
    shown = f <= w.psd_max_Hz * (1.0 + 1e-9)     # fs from the median dt is not exact
    out["psd"] = {"f_Hz": f[shown].tolist(), "tension_N2_Hz": p_tension[shown].tolist(),
                  "chassis_acc_m2_s4_Hz": p_acc[shown].tolist()}
    out["chassis_acc_body_mode_rms_m_s2"] = psd_band_rms(f, p_acc, *w.body_mode_band_Hz)

    out["constraint_violation_s"] = constraint_violation_time(t, y, w.force_min_N,
                                                              w.force_max_N, ev)
    mode = np.asarray(columns["valve_mode"])
    out["valve_switches"] = float(switch_count(mode[ev_mask]))
    out["valve_switch_rate_Hz"] = switching_rate(t, mode, ev)
    out["control_increment_rms"] = math.nan
    if control_period_s is not None:
        stride = max(1, round(control_period_s / sample_period(t)))
        out["control_increment_rms"] = control_increment_rms(
            np.asarray(columns["u"])[ev_mask], stride)
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
    out["acceptance"] = acceptance(t, y, ref, w)
    out["evaluation"] = w.as_table()
    return out


# ------------------------------------------------------------------ energy terms

ENERGY_TOTALS = ("pump", "circuit")
"""Terms of an ``energy_J`` table that are totals (energy put in), not parts of a breakdown."""
ENERGY_HEADLINE = ("pump", "circuit", "mechanical")
"""Energy compared between runs: the first of these both runs have (finite)."""


class EnergyTerms(NamedTuple):
    """A run's energy terms [J] (name -> value; a table of sub-terms, e.g. throttling by
    valve, summed), the notes the table carries (its text or flag entries, e.g. that a dp-b
    circuit is an ideal actuator's) and where they came from (``energy_J`` or
    none)."""

    terms: dict[str, float]
    notes: list[str]
    source: str


def _total(value: Any) -> float:
    if isinstance(value, Mapping):
        parts = [_total(v) for v in value.values()]
        parts = [p for p in parts if not math.isnan(p)]
        return float(sum(parts)) if parts else math.nan
    if isinstance(value, bool) or not isinstance(value, int | float):
        return math.nan
    return float(value)


def energy_terms(metrics: Mapping[str, Any]) -> EnergyTerms:
    """The energy terms of a run's metrics: the ``energy_J`` table if the run has one (keys
    such as pump, circuit, relief, throttling (by valve), leakage, friction, makeup,
    stored_change, mechanical, residual; :mod:`trackmj.elements.energy_table`), tables summed; empty with a
    note if the run has none."""
    table = metrics.get("energy_J")
    if isinstance(table, Mapping):
        terms, notes = {}, []
        for key, value in table.items():
            if isinstance(value, str):     # a "note" entry is its text, other texts named
                notes.append(value if key == "note" else f"{key}: {value}")
            elif isinstance(value, bool):
                if value:
                    notes.append(key.replace("_", " "))
            else:
                terms[key] = _total(value)
        return EnergyTerms(terms, notes, "energy_J")
    return EnergyTerms({}, ["no energy table in this run"], "none")


def headline_energy(a: EnergyTerms, b: EnergyTerms) -> str | None:
    """The first term of :data:`ENERGY_HEADLINE` finite in both ``a`` and ``b`` (None: none)."""
    for term in ENERGY_HEADLINE:
        if math.isfinite(a.terms.get(term, math.nan)) and math.isfinite(
                b.terms.get(term, math.nan)):
            return term
    return None


# ------------------------------------------------------------------ prediction error vs tp

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
    m = _sel(t, window)
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
    m = _sel(t, window)
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
        unit = _unit_suffix(name)
        values = np.asarray(values, dtype=float)
        fc = windows.lowpass_cutoff_Hz
        errors = trace_errors(t, y, values, ev, fc)
        out[name] = {f"{k}_{unit}" if unit else k: v for k, v in errors.items()}
        out[name]["lag_s"] = lag_s(t, lowpass(t, y, fc), lowpass(t, values, fc), ev)
    return out


def _unit_suffix(column: str) -> str:
    """The SI suffix of a column name (``p_head_Pa`` -> ``Pa``, ``u`` -> '')."""
    for suffix in ("m3_s", "m_s2", "m_s", "Pa", "N", "m", "J", "s"):
        if column.endswith("_" + suffix):
            return suffix
    return ""


# ------------------------------------------------------------------ display

METRIC_DISPLAY: dict[str, tuple[str, float, str]] = {
    "rmse_lp_N": ("tension RMSE, low-pass", 1e-3, "kN"),
    "rmse_N": ("tension RMSE, raw", 1e-3, "kN"),
    "ripple_rms_N": ("ripple RMS (raw − low-pass)", 1e-3, "kN"),
    "ripple_band_rms_N.tooth_passing": ("ripple in the tooth-passing band", 1e-3, "kN"),
    "ripple_band_rms_N.body_mode": ("ripple in the body-mode band", 1e-3, "kN"),
    "peak_error_lp_N": ("peak error, low-pass", 1e-3, "kN"),
    "peak_error_N": ("peak error, raw", 1e-3, "kN"),
    "overshoot_lp_N": ("step overshoot, low-pass", 1e-3, "kN"),
    "settling_time_lp_s": ("settling time, low-pass", 1.0, "s"),
    "disturbance_peak_error_lp_N": ("disturbance peak error, low-pass", 1e-3, "kN"),
    "recovery_time_lp_s": ("recovery time, low-pass", 1.0, "s"),
    "fluctuation_N": ("fluctuation ±, raw", 1e-3, "kN"),
    "fluctuation_lp_N": ("fluctuation ±, low-pass", 1e-3, "kN"),
    "constraint_violation_s": ("time outside [F_min, F_max], raw", 1.0, "s"),
    "p_head_max_Pa": ("peak head pressure", 1e-6, "MPa"),
    "valve_switch_rate_Hz": ("valve switching", 1.0, "Hz"),
    "chassis_acc_body_mode_rms_m_s2": ("chassis acc. RMS, body-mode band", 1.0, "m/s²"),
    "energy_in_J": ("energy in (pump; dp-b: ideal circuit)", 1e-3, "kJ"),
    "acceptance.mean_min_N": ("0.5 s mean, lowest", 1e-3, "kN"),
    "acceptance.mean_max_N": ("0.5 s mean, highest", 1e-3, "kN"),
    "acceptance.recovery_max_s": ("back within 5 % after an edge", 1.0, "s"),
    "acceptance.steady_offset_max_rel": ("worst steady 5 s offset", 100.0, "%"),
    "energy_J.pump": ("pump energy", 1e-3, "kJ"),
    "energy_J.circuit": ("circuit energy (through the main valve's P port)", 1e-3, "kJ"),
    "energy_J.mechanical": ("work into the track", 1e-3, "kJ"),
    "interface_energy_residual_J": ("interface energy residual", 1.0, "J"),
    "solve_time_median_s": ("solve time median", 1e3, "ms"),
    "solve_time_max_s": ("solve time max", 1e3, "ms"),
    "real_time_factor": ("real-time factor", 1.0, "×"),
    "prediction_rmse_vs_tp_N": ("F_ten RMSE vs tp, raw", 1e-3, "kN"),
    "prediction_rmse_vs_tp_lp_N": ("F_ten RMSE vs tp, low-pass", 1e-3, "kN"),
    "peak_pressure_error_vs_tp_Pa": ("peak head pressure − tp", 1e-6, "MPa"),
    "energy_error_vs_tp_pct": ("energy error vs tp", 1.0, "%"),
}
"""How tables show a metric (dotted key for a table entry): label, scale, display unit."""


def lookup(metrics: Mapping[str, Any], key: str) -> float:
    """A metric by dotted key (``ripple_band_rms_N.tooth_passing``); NaN if absent or not a
    number. ``energy_in_J``: the run's energy input, the first finite of the energy terms
    pump, circuit (dp-b has only its ideal actuator's circuit; :func:`energy_terms`)."""
    if key == "energy_in_J":
        terms = energy_terms(metrics).terms
        for name in ("pump", "circuit"):
            if math.isfinite(terms.get(name, math.nan)):
                return terms[name]
        return math.nan
    value: Any = metrics
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return math.nan
        value = value[part]
    if isinstance(value, bool) or not isinstance(value, int | float):
        return math.nan
    return float(value)
