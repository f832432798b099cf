"""The windows, bands and settings a run's metrics are measured on (:class:`MetricWindows`),
built from a scenario's ``[limits]`` and ``[evaluation]`` tables and written beside the
metrics (``metrics["evaluation"]``), where :func:`windows_of` reads them back."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from trackmj.results.store import Result
from trackmj.results.verdict import RECOVERY_WITHIN_S, STEADY_OFFSET_MAX_REL


@dataclass(frozen=True, kw_only=True)
class MetricWindows:
    """Windows, bands and settings of a scenario for
    :func:`~trackmj.results.metrics.compute_metrics` (times in s, forces in N, frequencies in
    Hz); built by ``Scenario.metric_windows`` from the scenario's ``[limits]`` and
    ``[evaluation]`` tables.

    evaluation_start_s: start of the tracking window (RMSE, peak error, ripple, violation time,
    switching; skips the start-up transient). steady: window of the fluctuation band, the mean
    tension and the spectra. step: (t_step, initial, final, t_end) of a reference step, its
    overshoot and settling evaluated in [t_step, t_end]. disturbances: (onset, end) windows of
    load pulses or supply drops, disturbance_labels what each one is and disturbance_states
    each as the state a run can start in ("supply at 9 MPa"; for figures; empty: unnamed,
    the label); an onset or end before evaluation_start_s is the run's initial condition (e.g.
    NL1's supply held at 9 MPa from t = 0), not an edge the disturbance and acceptance metrics
    judge. settle_band_rel: settling and recovery band relative to the final value (recovery: to
    the reference at the onset), unless recovery_band_N is given. min_hold_s: how long a
    response must stay inside its band before the window ends to count as settled/recovered.
    lowpass_cutoff_Hz: cut-off of :func:`~trackmj.results.signals.lowpass` for the ``_lp``
    metrics. body_mode_band_Hz: the track-idler-body mode band; tooth_passing_band_Hz: the
    sprocket tooth (link) passing band v/pitch ± the scenario's tooth_band_rel (None: no track,
    or its pitch unknown); road_band_Hz: the band the road excites (speed × the ISO 8608 spatial
    band; None on flat ground), marked on figures only. psd_resolution_Hz, psd_max_Hz:
    resolution and upper end of the spectra. mean_window_s, recovery_band_rel, steady_window_s,
    reference_events_s: the :func:`~trackmj.results.acceptance.acceptance` checks (trailing-mean
    length, recovery band relative to the reference, steady-window length, and the reference's
    steps and ramp starts, which end a steady window like a disturbance edge does);
    recovery_within_s, steady_offset_max_rel: the acceptance's limits
    (:func:`~trackmj.results.verdict.verdict`: the mean back within the recovery band
    this long after an edge [s], where a steady window also starts; a steady offset below
    this share of the reference);
    drive_events_s: the end of the track's start ramp, which ends a steady window likewise
    (the drive's traction transient: on a front-sprocket machine the tight side loads the
    idler while the track accelerates).
    drive_load_gain_1_m, drive_tight_sign: the machine's drive load g = G/r [1/m] and σ (+1
    sprocket at the front, −1 at the rear; :mod:`trackmj.machines.drive_load`), from which
    the acceptance takes the drive's floor under the idler load, g·max(σ·T, 0) for a drive
    torque T; None: not known (a run without the track).
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
    disturbance_states: tuple[str, ...] = ()
    steady: tuple[float, float] | None = None
    recovery_band_N: float | None = None
    mean_window_s: float = 0.5
    recovery_band_rel: float = 0.05
    steady_window_s: float = 5.0
    recovery_within_s: float = RECOVERY_WITHIN_S
    steady_offset_max_rel: float = STEADY_OFFSET_MAX_REL
    reference_events_s: tuple[float, ...] = ()
    drive_events_s: tuple[float, ...] = ()
    drive_load_gain_1_m: float | None = None
    drive_tight_sign: float | None = None

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


def windows_of(result: Result) -> MetricWindows:
    """The metric windows a result was measured on (its ``evaluation`` table)."""
    table = result.metrics.get("evaluation")
    if not isinstance(table, Mapping):
        raise KeyError(f"{result.scenario} {result.architecture}: metrics have no "
                       "'evaluation' table (a result written before the windows were stored)")
    return MetricWindows.from_table(table)
