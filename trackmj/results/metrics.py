"""A run's metric set (:func:`compute_metrics`) and the registry of every metric
(:data:`METRICS`): its key in ``metrics.json``, SI unit, the step that computes it and how
tables show it.

Two views of the tension F_ten:

* **raw**: the 1 kHz signal as simulated, carrying the track's chordal ripple (tooth
  passing at v/pitch, ~20 Hz at 1.5 m/s) that no valve with a 25 ms minimum hold follows;
* **low-passed** (``_lp`` in the name): F_ten through
  :func:`~trackmj.results.signals.lowpass`, a zero-phase 2nd-order Butterworth at the
  scenario's ``[evaluation].lowpass_cutoff_Hz`` (2 Hz in W1-W5), compared with the
  unfiltered reference: the band the controller can act on. The ripple is what the
  low-pass removes, F_ten − lowpass(F_ten).

"Tracking window": [evaluation_start_s, end]; "steady window": ``windows.steady``. The
tracking metrics come twice, on the raw and on the low-passed F_ten, always against the
unfiltered reference F_ref:

- ``rmse_N`` / ``rmse_lp_N``: sqrt(mean((F − F_ref)²)) in the tracking window;
- ``peak_error_N`` / ``peak_error_lp_N``: max|F − F_ref| in the tracking window;
- ``tension_max_N``, ``tension_min_N`` (and ``_lp_``): extremes in the tracking window;
- ``fluctuation_N`` / ``fluctuation_lp_N``: ± half the 2.5-97.5 % spread of F − F_ref in
  the steady window (:func:`~trackmj.results.signals.fluctuation_band`);
- ``overshoot_N``, ``overshoot_pct`` (of the final value), ``settling_time_s`` (and
  ``_lp_``): of the reference step, in [t_step, t_end] (band ±settle_band_rel·|final|,
  held min_hold_s);
- ``disturbance_peak_error_N`` (and ``_lp_``): max|F − F_ref| from each disturbance
  onset to the next onset (or the run end), the largest over disturbances;
  ``recovery_time_s`` (and ``_lp_``): the largest recovery time over disturbances, each
  from its onset; NaN if any did not recover.

Raw only:

- ``ise_N2s``: ∫(F − F_ref)² dt in the tracking window; ``tension_mean_N``: mean F in
  the steady window; ``p_head_max_Pa``: peak head pressure in the tracking window;
- ``ripple_rms_N``: RMS of the ripple F − lowpass(F) in the tracking window (with
  ``rmse_lp_N``: rmse_N² ≈ rmse_lp_N² + ripple_rms_N², the cross term being the
  covariance of a slow and a fast signal); ``ripple_band_rms_N``: table of the ripple's
  RMS in the named bands (``tooth_passing`` v/pitch ± tooth_band_rel, ``body_mode``) and
  the ``rest``, from its Welch PSD in the tracking window;
- ``psd``: table of spectra in the steady window up to psd_max_Hz at psd_resolution_Hz:
  ``f_Hz``, ``tension_N2_Hz`` (raw F_ten), ``chassis_acc_m2_s4_Hz`` (chassis vertical
  acceleration; null without a chassis);
- ``chassis_acc_body_mode_rms_m_s2``: chassis vertical acceleration RMS in the body-mode
  band (the machine's: 8-12 Hz on LF1352, ``trackmj.sim.setup.machine_body_mode_band``),
  steady window;
- ``constraint_violation_s``: time with F outside [force_min_N, force_max_N];
  ``valve_switches`` and ``valve_switch_rate_Hz``: valve mode changes (count, per s);
  NaN (null) when ``valve_mode_applied`` is false: the tensioner takes no valve mode (a
  passive tensioner, an FMU without a ``valve_mode`` input), the modes act on nothing;
- ``control_increment_rms``: RMS of Δu per control period (u dimensionless; NaN unless
  ``control_period_s`` is given);
- ``interface_energy_residual_J``: p_work_J − mech_work_J at the end (∫Σp·A·v dt vs
  ∫F·v dt; zero for a power-conserving interface);
- ``solve_time_median_s``, ``solve_time_max_s``, ``solve_failures``: if solve times
  given; ``real_time_factor``: simulated time / ``wall_time_s`` if given (> 1: faster
  than real time);
- ``controller_output_clipped`` (if the clipped outputs are given): the controller's
  outputs outside the port's range [−1, 1] that the loop clipped: ``outputs`` (how many),
  ``steps`` (1 ms steps run with a clipped output), ``share`` (of the run's steps),
  ``first_s`` (time of the first) and ``worst`` (the output farthest outside, as given);
  ``flags``: the keys of what makes the run not a valid result (``controller_output_clipped``
  when any output was clipped; [] otherwise);
- ``acceptance``: the tensioner's acceptance figures
  (:func:`~trackmj.results.acceptance.acceptance`).

The energy breakdown of a run (``energy_J``, pump to track) comes from the tensioner's
own ledger, not from the timeseries: :mod:`trackmj.elements.energy_table`.

``evaluation``: the windows themselves (:meth:`MetricWindows.as_table`), so a result
states what its metrics were measured on. Floats are NaN where undefined (no step, an
empty window, a quantity the architecture lacks).

A new metric is a step (a function of :class:`RunSignals` returning ``{key: value}``) and
one line in :data:`METRICS`: :func:`compute_metrics` runs every registered step and the
tables read their labels from :data:`METRIC_DISPLAY`, a view of the registry.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from trackmj.results.acceptance import acceptance
from trackmj.results.energy_terms import energy_terms
from trackmj.results.metric_windows import MetricWindows
from trackmj.results.signals import (
    Overshoot,
    constraint_violation_time,
    control_increment_rms,
    fluctuation_band,
    ise,
    lowpass,
    overshoot,
    peak_abs_error,
    psd,
    psd_band_rms,
    recovery_time,
    ripple_band_rms,
    rmse,
    sample_period,
    settling_time,
    solve_time_stats,
    switch_count,
    switching_rate,
    window_mask,
)

REQUIRED_COLUMNS = ("t_s", "tension_N", "tension_ref_N", "p_head_Pa", "valve_mode", "u",
                    "e_supply_J", "p_work_J", "mech_work_J", "chassis_acc_z_m_s2")


# ------------------------------------------------------------------ what the steps read

@dataclass(frozen=True)
class RunSignals:
    """What the steps of :func:`compute_metrics` read: the run's timeseries ``columns`` and
    ``windows``, the signals and windows derived from them once, and the run's options.

    t [s], tension (F_ten) [N], reference (F_ref) [N], lowpassed (lowpass(F_ten)) [N]: shape
    (n,). tracking: the tracking window (evaluation_start_s, t_end) [s], in_tracking its
    sample mask. steady: the steady window cut at the run end [s]; None if the scenario has
    none or it is empty (unlike a :data:`~trackmj.results.signals.Window`, None here means
    no sample). control_period_s, solve_times_s, solve_success, wall_time_s,
    clipped_outputs, valve_mode_applied: as given to :func:`compute_metrics`.
    """

    columns: Mapping[str, np.ndarray]
    windows: MetricWindows
    t: np.ndarray
    tension: np.ndarray
    reference: np.ndarray
    lowpassed: np.ndarray
    tracking: tuple[float, float]
    in_tracking: np.ndarray
    steady: tuple[float, float] | None
    control_period_s: float | None = None
    solve_times_s: Sequence[float] | None = None
    solve_success: Sequence[bool] | None = None
    wall_time_s: float | None = None
    clipped_outputs: Sequence[tuple[int, float]] | None = None
    valve_mode_applied: bool = True

    @property
    def t_end(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t[-1])


def run_signals(columns: Mapping[str, np.ndarray], windows: MetricWindows,
                **options: Any) -> RunSignals:
    """The :class:`RunSignals` of a run (``options``: the keyword options of
    :func:`compute_metrics`); KeyError if a column of :data:`REQUIRED_COLUMNS` is missing."""
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise KeyError(f"timeseries lacks column(s) {missing}")
    t = np.asarray(columns["t_s"], dtype=float)
    y = np.asarray(columns["tension_N"], dtype=float)
    t_end = float(t[-1])
    tracking = (windows.evaluation_start_s, t_end)
    steady = None if windows.steady is None else (windows.steady[0],
                                                  min(windows.steady[1], t_end))
    return RunSignals(columns=columns, windows=windows, t=t, tension=y,
                      reference=np.asarray(columns["tension_ref_N"], dtype=float),
                      lowpassed=lowpass(t, y, windows.lowpass_cutoff_Hz), tracking=tracking,
                      in_tracking=window_mask(t, tracking),
                      steady=steady if steady is not None and steady[1] > steady[0] else None,
                      **options)


# ------------------------------------------------------------------ tracking steps

def _name(base: str, unit: str, lowpassed: bool) -> str:
    return f"{base}_lp_{unit}" if lowpassed else f"{base}_{unit}"


def _tracking_errors(run: RunSignals, y: np.ndarray, lowpassed: bool) -> dict[str, float]:
    """RMSE, peak error and the extremes of tension view ``y`` in the tracking window [N]."""
    t, ref, ev, ev_mask = run.t, run.reference, run.tracking, run.in_tracking
    return {_name("rmse", "N", lowpassed): rmse(t, y, ref, ev),
            _name("peak_error", "N", lowpassed): peak_abs_error(t, y, ref, ev),
            _name("tension_max", "N", lowpassed): (float(np.max(y[ev_mask])) if ev_mask.any()
                                                   else math.nan),
            _name("tension_min", "N", lowpassed): (float(np.min(y[ev_mask])) if ev_mask.any()
                                                   else math.nan)}


def _fluctuation(run: RunSignals, y: np.ndarray, lowpassed: bool) -> dict[str, float]:
    """Fluctuation band of view ``y`` in the steady window [N] (NaN without one)."""
    return {_name("fluctuation", "N", lowpassed): (
        fluctuation_band(run.t, y, run.reference, run.steady) if run.steady is not None
        else math.nan)}


def _step_response(run: RunSignals, y: np.ndarray, lowpassed: bool) -> dict[str, float]:
    """Overshoot [N, %] and settling time [s] of view ``y`` after the reference step, in
    [t_step, t_end] (NaN without a step in the run)."""
    w, t_end = run.windows, run.t_end
    over, settle = Overshoot(math.nan, math.nan), math.nan
    if w.step is not None and w.step[0] < t_end:
        t_step, initial, final, t_stop = w.step
        t_stop = min(t_stop, t_end)
        over = overshoot(run.t, y, initial, final, (t_step, t_stop))
        settle = settling_time(run.t, y, final, t_step, band_rel=w.settle_band_rel,
                               t_end=t_stop, min_hold_s=w.min_hold_s)
    return {_name("overshoot", "N", lowpassed): over.value,
            _name("overshoot", "pct", lowpassed): over.percent,
            _name("settling_time", "s", lowpassed): settle}


def _disturbance_response(run: RunSignals, y: np.ndarray,
                          lowpassed: bool) -> dict[str, float]:
    """Largest peak error [N] and recovery time [s] of view ``y`` over the disturbances
    judged, each from its onset to the next onset (or the run end)."""
    t, ref, w, t_end = run.t, run.reference, run.windows, run.t_end
    onsets = sorted(on for on, _ in w.disturbances if w.judges_edge(on, t_end))
    peaks, recoveries = [], []
    for k, on in enumerate(onsets):
        until = onsets[k + 1] if k + 1 < len(onsets) else t_end
        i_on = min(int(np.searchsorted(t, on)), len(t) - 1)
        band = (w.recovery_band_N if w.recovery_band_N is not None
                else w.settle_band_rel * abs(ref[i_on]))
        peaks.append(peak_abs_error(t, y, ref, (on, until)))
        recoveries.append(recovery_time(t, y, ref, on, until, band, min_hold_s=w.min_hold_s))
    return {_name("disturbance_peak_error", "N", lowpassed): max(peaks) if peaks else math.nan,
            _name("recovery_time", "s", lowpassed): (
                math.nan if not recoveries or any(map(math.isnan, recoveries))
                else max(recoveries))}


def _tracking(run: RunSignals, y: np.ndarray, lowpassed: bool) -> dict[str, float]:
    """The tracking metrics of one view of the tension (raw or low-passed), named for it."""
    return (_tracking_errors(run, y, lowpassed) | _fluctuation(run, y, lowpassed)
            | _step_response(run, y, lowpassed) | _disturbance_response(run, y, lowpassed))


def tracking_raw(run: RunSignals) -> dict[str, float]:
    """The tracking metrics of the raw F_ten."""
    return _tracking(run, run.tension, lowpassed=False)


def tracking_lowpassed(run: RunSignals) -> dict[str, float]:
    """The tracking metrics of the low-passed F_ten (``_lp`` in their names)."""
    return _tracking(run, run.lowpassed, lowpassed=True)


# ------------------------------------------------------------------ raw-only steps

def integral_square_error(run: RunSignals) -> dict[str, float]:
    """``ise_N2s``: ∫(F − F_ref)² dt in the tracking window [N²·s]."""
    return {"ise_N2s": ise(run.t, run.tension, run.reference, run.tracking)}


def head_pressure_peak(run: RunSignals) -> dict[str, float]:
    """``p_head_max_Pa``: peak head pressure in the tracking window [Pa]."""
    ev_mask = run.in_tracking
    return {"p_head_max_Pa": (float(np.max(np.asarray(run.columns["p_head_Pa"])[ev_mask]))
                              if ev_mask.any() else math.nan)}


def ripple(run: RunSignals) -> dict[str, Any]:
    """``ripple_rms_N`` and ``ripple_band_rms_N`` (table by band) of F − lowpass(F) in the
    tracking window [N]."""
    w, ev_mask = run.windows, run.in_tracking
    rippled = run.tension - run.lowpassed
    return {"ripple_rms_N": (float(np.sqrt(np.mean(rippled[ev_mask] ** 2))) if ev_mask.any()
                             else math.nan),
            "ripple_band_rms_N": ripple_band_rms(run.t, rippled, w.ripple_bands_Hz(),
                                                 run.tracking,
                                                 resolution_Hz=w.psd_resolution_Hz)}


def steady_tension(run: RunSignals) -> dict[str, float]:
    """``tension_mean_N``: mean F_ten in the steady window [N]."""
    sm = (window_mask(run.t, run.steady) if run.steady is not None
          else np.zeros(run.t.shape, dtype=bool))
    return {"tension_mean_N": float(np.mean(run.tension[sm])) if sm.any() else math.nan}


def spectra(run: RunSignals) -> dict[str, Any]:
    """``psd`` (table of the F_ten and chassis-acceleration spectra in the steady window up
    to psd_max_Hz) and ``chassis_acc_body_mode_rms_m_s2`` [m/s²]."""
    t, w, steady = run.t, run.windows, run.steady
    acc = np.asarray(run.columns["chassis_acc_z_m_s2"], dtype=float)
    none = (np.zeros(0), np.zeros(0))
    f, p_tension = (psd(t, run.tension, steady, resolution_Hz=w.psd_resolution_Hz)
                    if steady is not None else none)
    _, p_acc = (psd(t, acc, steady, resolution_Hz=w.psd_resolution_Hz) if steady is not None
                else none)
    shown = f <= w.psd_max_Hz * (1.0 + 1e-9)     # fs from the median dt is not exact
    return {"psd": {"f_Hz": f[shown].tolist(), "tension_N2_Hz": p_tension[shown].tolist(),
                    "chassis_acc_m2_s4_Hz": p_acc[shown].tolist()},
            "chassis_acc_body_mode_rms_m_s2": psd_band_rms(f, p_acc, *w.body_mode_band_Hz)}


def constraint_violation(run: RunSignals) -> dict[str, float]:
    """``constraint_violation_s``: time with F_ten outside [force_min_N, force_max_N] [s]."""
    w = run.windows
    return {"constraint_violation_s": constraint_violation_time(
        run.t, run.tension, w.force_min_N, w.force_max_N, run.tracking)}


def valve_switching(run: RunSignals) -> dict[str, Any]:
    """``valve_switches`` (count) and ``valve_switch_rate_Hz`` in the tracking window, NaN
    when the tensioner takes no valve mode; ``valve_mode_applied`` says which."""
    if not run.valve_mode_applied:
        return {"valve_switches": math.nan, "valve_switch_rate_Hz": math.nan,
                "valve_mode_applied": False}
    mode = np.asarray(run.columns["valve_mode"])
    return {"valve_switches": float(switch_count(mode[run.in_tracking])),
            "valve_switch_rate_Hz": switching_rate(run.t, mode, run.tracking),
            "valve_mode_applied": True}


def control_increments(run: RunSignals) -> dict[str, float]:
    """``control_increment_rms``: RMS of Δu per control period in the tracking window (NaN
    without a control period)."""
    if run.control_period_s is None:
        return {"control_increment_rms": math.nan}
    stride = max(1, round(run.control_period_s / sample_period(run.t)))
    return {"control_increment_rms": control_increment_rms(
        np.asarray(run.columns["u"])[run.in_tracking], stride)}


def interface_energy(run: RunSignals) -> dict[str, float]:
    """``interface_energy_residual_J``: p_work_J − mech_work_J at the end [J]."""
    return {"interface_energy_residual_J": float(np.asarray(run.columns["p_work_J"])[-1]
                                                 - np.asarray(run.columns["mech_work_J"])[-1])}


def solver_statistics(run: RunSignals) -> dict[str, float]:
    """Median and max solve time [s] and failed solves, if solve times were given."""
    if run.solve_times_s is None:
        return {}
    stats = solve_time_stats(np.asarray(run.solve_times_s),
                             None if run.solve_success is None
                             else np.asarray(run.solve_success))
    return {"solve_time_median_s": stats.median_s, "solve_time_max_s": stats.max_s,
            "solve_failures": float(stats.failures)}


def output_clipping(run: RunSignals) -> dict[str, Any]:
    """``controller_output_clipped`` (table: ``outputs``, ``steps``, ``share`` [-],
    ``first_s`` [s], ``worst`` [-]) and ``flags``, if the clipped outputs were given.

    Each clipped output (step k, value) was held from t_k = t_s[k] − h until the next
    controller period (``control_period_s``; without it, one step) or the run's end."""
    if run.clipped_outputs is None:
        return {}
    clipped = list(run.clipped_outputs)
    n, h = len(run.t), sample_period(run.t)
    stride = 1 if run.control_period_s is None else max(1, round(run.control_period_s / h))
    steps = sum(min(stride, n - k) for k, _ in clipped)
    finite = [u for _, u in clipped if math.isfinite(u)]
    first = clipped[0][0] if clipped else None
    table = {"outputs": float(len(clipped)), "steps": float(steps),
             "share": steps / n if n else math.nan,
             "first_s": (math.nan if first is None    # the start of step k: t_s[k - 1]
                         else round(float(run.t[first - 1] if first else run.t[0] - h), 9)
                         + 0.0),   # + 0.0: no "-0.000 s"
             "worst": max(finite, key=abs) if finite else math.nan}
    return {"controller_output_clipped": table,
            "flags": ["controller_output_clipped"] if clipped else []}


def real_time(run: RunSignals) -> dict[str, float]:
    """``real_time_factor``: simulated time / wall time, if the wall time was given."""
    if run.wall_time_s is None:
        return {}
    return {"real_time_factor": ((run.t_end - float(run.t[0])) / run.wall_time_s
                                 if run.wall_time_s > 0 else math.nan)}


def acceptance_figures(run: RunSignals) -> dict[str, Any]:
    """``acceptance``: the table of :func:`~trackmj.results.acceptance.acceptance` of the raw
    F_ten (with the drive torque, where the run recorded it)."""
    return {"acceptance": acceptance(run.t, run.tension, run.reference, run.windows,
                                     run.columns.get("drive_torque_N_m"))}


def evaluation_table(run: RunSignals) -> dict[str, Any]:
    """``evaluation``: the windows the metrics were measured on
    (:meth:`MetricWindows.as_table`)."""
    return {"evaluation": run.windows.as_table()}


# ------------------------------------------------------------------ the registry

class Display(NamedTuple):
    """How tables show a metric: ``label``, ``scale`` (shown value = scale × SI value) and
    the display ``unit``."""

    label: str
    scale: float
    unit: str


MetricStep = Callable[[RunSignals], dict[str, Any]]
"""A step of :func:`compute_metrics`: the metrics it computes, top-level key -> value (a
number, or a table for dotted keys)."""


@dataclass(frozen=True)
class Metric:
    """A metric of ``metrics.json``, registered in :data:`METRICS` under its key (dotted for
    an entry of a table: ``ripple_band_rms_N.tooth_passing``; a key naming a whole table
    covers every entry in it).

    unit: its SI unit ("1": dimensionless; "": not a quantity, e.g. a table of settings
    whose fields carry their units, or a name). step: the step of :func:`compute_metrics`
    that computes it; None for a metric computed elsewhere, then ``source`` is the dotted
    path of the function that does. display: how tables show it (None: tables do not).
    """

    unit: str
    step: MetricStep | None = None
    display: Display | None = None
    source: str = ""

    def __post_init__(self) -> None:
        if (self.step is None) == (not self.source):
            raise ValueError("a metric names either the step of compute_metrics that "
                             "computes it or the source that does, not both")


LEDGER = "trackmj.elements.energy_table.energy_table"
"""Where the ``energy_J`` table comes from: the tensioner's energy ledger."""
VS_TP = "trackmj.results.comparison.prediction_vs_tp"
"""Where the prediction errors against tp come from."""
KN = 1e-3
"""Display scale of a force or an energy in kN or kJ."""

METRICS: dict[str, Metric] = {
    "rmse_N": Metric("N", tracking_raw, Display("tension RMSE, raw", KN, "kN")),
    "peak_error_N": Metric("N", tracking_raw, Display("peak error, raw", KN, "kN")),
    "tension_max_N": Metric("N", tracking_raw),
    "tension_min_N": Metric("N", tracking_raw),
    "fluctuation_N": Metric("N", tracking_raw, Display("fluctuation ±, raw", KN, "kN")),
    "overshoot_N": Metric("N", tracking_raw),
    "overshoot_pct": Metric("%", tracking_raw),
    "settling_time_s": Metric("s", tracking_raw),
    "disturbance_peak_error_N": Metric("N", tracking_raw),
    "recovery_time_s": Metric("s", tracking_raw),
    "rmse_lp_N": Metric("N", tracking_lowpassed, Display("tension RMSE, low-pass", KN, "kN")),
    "peak_error_lp_N": Metric("N", tracking_lowpassed,
                              Display("peak error, low-pass", KN, "kN")),
    "tension_max_lp_N": Metric("N", tracking_lowpassed),
    "tension_min_lp_N": Metric("N", tracking_lowpassed),
    "fluctuation_lp_N": Metric("N", tracking_lowpassed,
                               Display("fluctuation ±, low-pass", KN, "kN")),
    "overshoot_lp_N": Metric("N", tracking_lowpassed,
                             Display("step overshoot, low-pass", KN, "kN")),
    "overshoot_lp_pct": Metric("%", tracking_lowpassed),
    "settling_time_lp_s": Metric("s", tracking_lowpassed,
                                 Display("settling time (settling band), low-pass", 1.0, "s")),
    "disturbance_peak_error_lp_N": Metric("N", tracking_lowpassed,
                                          Display("disturbance peak error, low-pass", KN,
                                                  "kN")),
    "recovery_time_lp_s": Metric("s", tracking_lowpassed,
                                 Display("recovery time (settling band), low-pass", 1.0, "s")),
    "ise_N2s": Metric("N²·s", integral_square_error),
    "p_head_max_Pa": Metric("Pa", head_pressure_peak,
                            Display("peak head pressure", 1e-6, "MPa")),
    "ripple_rms_N": Metric("N", ripple, Display("ripple RMS (raw − low-pass)", KN, "kN")),
    "ripple_band_rms_N.tooth_passing": Metric(
        "N", ripple, Display("ripple in the tooth-passing band", KN, "kN")),
    "ripple_band_rms_N.body_mode": Metric(
        "N", ripple, Display("ripple in the body-mode band", KN, "kN")),
    "ripple_band_rms_N.rest": Metric("N", ripple),
    "tension_mean_N": Metric("N", steady_tension),
    "psd.f_Hz": Metric("Hz", spectra),
    "psd.tension_N2_Hz": Metric("N²/Hz", spectra),
    "psd.chassis_acc_m2_s4_Hz": Metric("m²/s⁴/Hz", spectra),
    "chassis_acc_body_mode_rms_m_s2": Metric(
        "m/s²", spectra, Display("chassis acc. RMS, body-mode band", 1.0, "m/s²")),
    "constraint_violation_s": Metric(
        "s", constraint_violation, Display("time outside [F_min, F_max], raw", 1.0, "s")),
    "valve_switches": Metric("1", valve_switching),
    "valve_switch_rate_Hz": Metric("Hz", valve_switching,
                                   Display("valve switching", 1.0, "Hz")),
    "valve_mode_applied": Metric("", valve_switching),
    "control_increment_rms": Metric("1", control_increments),
    "interface_energy_residual_J": Metric(
        "J", interface_energy, Display("interface energy residual", 1.0, "J")),
    "solve_time_median_s": Metric("s", solver_statistics,
                                  Display("solve time median", 1e3, "ms")),
    "solve_time_max_s": Metric("s", solver_statistics, Display("solve time max", 1e3, "ms")),
    "solve_failures": Metric("1", solver_statistics),
    "controller_output_clipped.outputs": Metric("1", output_clipping),
    "controller_output_clipped.steps": Metric("1", output_clipping),
    "controller_output_clipped.share": Metric("1", output_clipping),
    "controller_output_clipped.first_s": Metric("s", output_clipping),
    "controller_output_clipped.worst": Metric("1", output_clipping),
    "flags": Metric("", output_clipping),
    "real_time_factor": Metric("1", real_time, Display("real-time factor", 1.0, "×")),
    "acceptance.mean_window_s": Metric("s", acceptance_figures),
    "acceptance.recovery_band_rel": Metric("1", acceptance_figures),
    "acceptance.steady_window_s": Metric("s", acceptance_figures),
    "acceptance.mean_min_N": Metric("N", acceptance_figures,
                                    Display("0.5 s mean, lowest", KN, "kN")),
    "acceptance.mean_max_N": Metric("N", acceptance_figures,
                                    Display("0.5 s mean, highest", KN, "kN")),
    "acceptance.mean_max_s": Metric("s", acceptance_figures),
    "acceptance.drive_floor_at_max_N": Metric("N", acceptance_figures),
    "acceptance.edge_recovery_s": Metric("s", acceptance_figures),
    "acceptance.recovery_max_s": Metric(
        "s", acceptance_figures, Display("back in the recovery band after an edge", 1.0, "s")),
    "acceptance.steady_offset_max_rel": Metric(
        "1", acceptance_figures, Display("worst steady 5 s offset", 100.0, "%")),
    "evaluation": Metric("", evaluation_table),
    "energy_in_J": Metric("J", display=Display("energy in (pump; dp-b: ideal circuit)", KN,
                                               "kJ"), source="trackmj.results.metrics.lookup"),
    "energy_J.pump": Metric("J", display=Display("pump energy", KN, "kJ"), source=LEDGER),
    "energy_J.circuit": Metric("J", display=Display(
        "circuit energy (through the main valve's P port)", KN, "kJ"), source=LEDGER),
    "energy_J.mechanical": Metric("J", display=Display("work into the track", KN, "kJ"),
                                  source=LEDGER),
    "prediction_rmse_vs_tp_N": Metric("N", display=Display("F_ten RMSE vs tp, raw", KN, "kN"),
                                      source=VS_TP),
    "prediction_rmse_vs_tp_lp_N": Metric(
        "N", display=Display("F_ten RMSE vs tp, low-pass", KN, "kN"), source=VS_TP),
    "peak_pressure_error_vs_tp_Pa": Metric(
        "Pa", display=Display("peak head pressure − tp", 1e-6, "MPa"), source=VS_TP),
    "energy_error_vs_tp_J": Metric("J", source=VS_TP),
    "energy_error_vs_tp_pct": Metric("%", display=Display("energy error vs tp", 1.0, "%"),
                                     source=VS_TP),
    "energy_error_term": Metric("", source=VS_TP),
}
"""Every metric by key (dotted for a table entry), in the order :func:`compute_metrics`
writes them: its unit, the step or source that computes it, how tables show it."""


class _DisplayTable(Mapping[str, Display]):
    """Key -> :class:`Display` of the registered metrics that tables show, read from
    :data:`METRICS` at each access (a metric registered later is shown too)."""

    def __getitem__(self, key: str) -> Display:
        metric = METRICS.get(key)
        if metric is None or metric.display is None:
            raise KeyError(key)
        return metric.display

    def __iter__(self) -> Iterator[str]:
        return iter([key for key, metric in METRICS.items() if metric.display is not None])

    def __len__(self) -> int:
        return sum(1 for metric in METRICS.values() if metric.display is not None)


METRIC_DISPLAY: Mapping[str, Display] = _DisplayTable()
"""How tables show a metric (dotted key for a table entry): label, scale, display unit."""


# ------------------------------------------------------------------ the metric set

def _steps() -> list[MetricStep]:
    """The steps of the registered metrics, each once, in the order of :data:`METRICS`."""
    return list(dict.fromkeys(m.step for m in METRICS.values() if m.step is not None))


def compute_metrics(columns: Mapping[str, np.ndarray], windows: MetricWindows, *,
                    control_period_s: float | None = None,
                    solve_times_s: Sequence[float] | None = None,
                    solve_success: Sequence[bool] | None = None,
                    wall_time_s: float | None = None,
                    clipped_outputs: Sequence[tuple[int, float]] | None = None,
                    valve_mode_applied: bool = True) -> dict[str, Any]:
    """The standard metric set (the module docstring lists it) from the timeseries
    contract (see ``trackmj.results.store``) on ``windows``: the outputs of the steps of
    :data:`METRICS`, in the registry's order.

    ``control_period_s`` [s] gives ``control_increment_rms``; ``solve_times_s`` [s] and
    ``solve_success`` (per solve) the solve statistics; ``wall_time_s`` [s] the real-time
    factor; ``clipped_outputs``, (step k, output as given) of each controller output the
    loop clipped (:attr:`trackmj.sim.observers.Recorder.clipped`), gives
    ``controller_output_clipped`` and ``flags``; ``valve_mode_applied`` False (the
    tensioner takes no valve mode) makes the valve metrics NaN. KeyError if a column of
    :data:`REQUIRED_COLUMNS` is missing.
    """
    run = run_signals(columns, windows, control_period_s=control_period_s,
                      solve_times_s=solve_times_s, solve_success=solve_success,
                      wall_time_s=wall_time_s, clipped_outputs=clipped_outputs,
                      valve_mode_applied=valve_mode_applied)
    out: dict[str, Any] = {}
    for step in _steps():
        out |= step(run)
    return out


def lookup(metrics: Mapping[str, Any], key: str) -> float:
    """A metric by dotted key (``ripple_band_rms_N.tooth_passing``); NaN if absent or not a
    number. ``energy_in_J``: the run's energy input, the first finite of the energy terms
    pump, circuit (dp-b has only its ideal actuator's circuit;
    :func:`~trackmj.results.energy_terms.energy_terms`)."""
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
