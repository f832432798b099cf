"""Operating conditions as frozen dataclasses loaded from TOML: the study's W1-W5 and NL1
(added: large tension steps at a reduced supply, where the nonlinearity binds).

``load_scenario("W1")`` reads ``experiments/W1.toml`` from the installed package
``trackmj.experiments``; any other argument is a path to a custom file. The file is read by
the one validator (:mod:`trackmj.validator`) into :class:`ScenarioFile`, whose tables mirror
the file; invalid files raise :class:`~trackmj.validator.ParameterError` naming the file, the
table, the key, the value and the allowed range or choices, before anything is built.
The supply hardware and its nominal set-point are the hydraulic file's
(``models/lf1352_hydraulics.toml`` [supply]); a scenario chooses the supply model and
prescribes set-point changes (docs/sizing.md says what a drop means for each model).
Units are SI: s, N, Pa, m/s; forces are F_ten (the cylinder force on the idler carrier, see
README "Tension convention").

File layout; every table is required except [supply] and [limits], the arrays of tables
are optional (a condition has no steps, ramps, drops, pulses or variants unless it lists
them)::

    [scenario]    name, title, duration_s, seeds, controller, estimator,
                  machines, machines_reason (optional: the only machines it applies to)
    [track]       speed_m_s, ramp_s
    [reference]   initial_N | initial_rel; [[reference.steps]] time_s, delta_N | delta_rel;
                  [[reference.ramps]] start_s, rate_N_s | rate_rel_s, end_s (optional)
    [supply]      model (optional); [[supply.drops]] start_s, end_s,
                  pressure_Pa | pressure_rel, transition_s
    [terrain]     kind; for kind = "iso8608" also road_class, n_min_cycles_m, n_max_cycles_m,
                  dx_m, x_start_m, flat_until_m, taper_m, margin_m (for "flat" they are
                  optional and unused, so ``--set scenario.terrain.kind=flat`` works on W2)
    [[load_pulses]] start_s, end_s, delta_N | delta_rel, hitch_N, pull_angle_deg, rise_s
    [[variants]]  name, bulk_modulus_scale, friction_scale, contact_stiffness_scale,
                  pretension_scale (each scale optional, default 1: a variant names only
                  what it changes; if variants are listed one must be "nominal")
    [limits]      force_min_N, force_max_N (each optional: the machine's band)

A force is absolute (``*_N``) or relative to the machine's nominal tension (``*_rel``, the
mechanics file's ``[tensioner].nominal_tension_N``, else its preload); a drop pressure
absolute or relative to the hydraulic file's set-point; exactly one of each pair.
:func:`load_scenario` resolves them for the machine it is given (default the packaged one),
so a :class:`Scenario` holds absolute values only.
    [evaluation]  start_s, steady_start_s, settle_band_rel, min_hold_s, lowpass_cutoff_Hz,
                  tooth_band_rel, body_mode_band_Hz, psd_resolution_Hz, psd_max_Hz

Time windows must lie in the run: steps, ramp, drop and pulse starts and the evaluation
starts before ``duration_s``; each drop's and pulse's edges fit inside its window; drops do
not overlap; F_ref stays in [0, 50 kN]. The scenario ``name`` names the run directories, so
it is a short identifier (letters, digits, ``_ . -``, not starting with a dot, at most 64
characters). Tables may carry a ``source`` string; unlike parameter files they need not.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np

from trackmj.hydraulics.params import PressureProfile, SupplyModel
from trackmj.ports import COUPLING_STEP_S
from trackmj.results.measured import InputSignal, input_signal
from trackmj.results.metrics import MetricWindows
from trackmj.sim.registry import CONTROLLERS, ESTIMATORS, by_name, choices
from trackmj.track.terrain import ISO8608_GD_N0_M3, RoadProfile, road_profile, taper_start
from trackmj.validator import (
    Location,
    ParameterError,
    Parameters,
    build,
    construct,
    missing_key,
    param,
    read_toml,
)

BUILTIN = ("W1", "W2", "W3", "W4", "W5", "NL1")
TERRAIN_SEED_SALT = 8608
"""Terrain RNG = default_rng([seed, 8608]): independent of the noise stream of the same seed."""
NAME_PATTERN = r"[A-Za-z0-9_-][A-Za-z0-9_.-]*"
"""Scenario and variant names: they become parts of run directory names."""
REFERENCE_MAX_N = 50e3
"""F_ref must stay within [0, REFERENCE_MAX_N] over the run [N]."""
ZERO_TRANSITION_S = 1e-6
"""A set-point drop with transition_s = 0 reaches the HydraulicTensioner as a ramp this long
ending at the edge [s] (a profile's times are strictly increasing; steps are 1 ms)."""


def _edge(t: np.ndarray, t0: float, rise_s: float) -> np.ndarray:
    """0 before t0, 1 after t0 + rise_s, linear between (a step at t >= t0 if rise_s = 0)."""
    if rise_s <= 0.0:
        return (t >= t0).astype(float)
    return np.clip((t - t0) / rise_s, 0.0, 1.0)


@dataclass(frozen=True)
class Header(Parameters):
    """The ``[scenario]`` table: what the condition is called, how long and how often it runs,
    and its default controller and estimator."""

    name: str = param(pattern=NAME_PATTERN, max_len=64,
                      doc="letters, digits, '_', '.', '-', not starting with '.'; names the "
                      "run directories")
    title: str = param(max_len=200, doc="one line describing the condition")
    duration_s: float = param(COUPLING_STEP_S, 3600.0,
                              doc="simulated time; at least one 1 ms step")
    seeds: tuple[int, ...] = param(0, 2**32 - 1, unit="1",
                                   doc="one run per seed (sensor noise and terrain)")
    controller: str = param(choices=by_name(CONTROLLERS), doc="default controller")
    estimator: str = param(choices=choices(ESTIMATORS), doc="default state estimator")
    machines: tuple[str, ...] | None = param(default=None, pattern=r"[a-z0-9][a-z0-9_-]*",
                                      max_len=40, doc="optional: the only machines the "
                                      "condition applies to (default: any)")
    machines_reason: str = param(default="", max_len=300, doc="why it applies to those "
                                 "machines only (the refusal's message)")

    def cross_check(self, at: Location) -> None:
        if not self.title.strip() or any(c in self.title for c in "\n\r\t"):
            raise at.error("title", self.title, "must be one non-empty line")
        if len(set(self.seeds)) != len(self.seeds):
            raise at.error("seeds", self.seeds, "lists a seed twice")


FROM_FILE_DOC = ("a CSV or Parquet file (relative to the scenario file) with t_s "
                 "and the signal, in SI or with its unit in the header (README, Measured "
                 "data)")
COLUMN_DOC = "the file's column (default: its only one besides t_s)"


def _one_source(cls: type, at: Location, given: dict[str, Any], from_file: str | None) -> None:
    """With from_file none of ``given`` (key -> value, None if absent); without it all."""
    if from_file is not None:
        extra = [k for k, v in given.items() if v not in (None, ())]
        if extra:
            raise at.error(extra[0], given[extra[0]], "is given with from_file; the file is "
                           "the whole signal (give one or the other)")
    else:
        missing = [k for k, v in given.items() if v is None]
        if missing:
            raise missing_key(cls, missing[0], at, "; or give from_file")


@dataclass(frozen=True)
class Track(Parameters):
    """Sprocket-driven track speed, reached by a linear ramp from standstill, or read from
    a file (``from_file``, a column in m/s)."""

    speed_m_s: float | None = param(0.0, 5.0, default=None,
                                    doc="track speed commanded to the sprocket servo "
                                    "(required without from_file)")
    ramp_s: float | None = param(0.0, 10.0, default=None,
                                 doc="duration of the linear start from standstill "
                                 "(required without from_file)")
    from_file: str | None = param(default=None, doc=FROM_FILE_DOC)
    column: str | None = param(default=None, doc=COLUMN_DOC)

    def cross_check(self, at: Location) -> None:
        _one_source(Track, at, {"speed_m_s": self.speed_m_s, "ramp_s": self.ramp_s}, self.from_file)


@dataclass(frozen=True)
class Step(Parameters):
    """Reference step of delta_N [N] at time_s [s]."""

    time_s: float = param(0.0, None, doc="time of the step")
    delta_N: float | None = param(-50e3, 50e3, default=None, doc="change of F_ref (absolute)")
    delta_rel: float | None = param(-3.0, 3.0, default=None, unit="1",
                                    doc="change of F_ref over the nominal tension")

    def cross_check(self, at: Location) -> None:
        _one_of(self, at, "delta_N", "delta_rel")


@dataclass(frozen=True)
class Ramp(Parameters):
    """Reference ramp of rate_N_s [N/s] from start_s to end_s [s]."""

    start_s: float = param(0.0, None, doc="start of the ramp")
    rate_N_s: float | None = param(-5e3, 5e3, default=None, doc="slope of F_ref (absolute)")
    rate_rel_s: float | None = param(-1.0, 1.0, default=None, unit="1/s",
                                     doc="slope of F_ref over the nominal tension")
    end_s: float | None = param(0.0, None, default=None,
                                doc="end of the ramp; optional: without it the ramp runs to "
                                "the end of the run")

    def cross_check(self, at: Location) -> None:
        _one_of(self, at, "rate_N_s", "rate_rel_s")
        if self.end_s is not None and not self.end_s > self.start_s:
            raise at.error("end_s", self.end_s, f"must be > start_s = {self.start_s!r}")


@dataclass(frozen=True)
class Reference(Parameters):
    """F_ref(t) = initial_N + Σ steps + Σ ramps [N], or read from a file (``from_file``, a
    column in N)."""

    initial_N: float | None = param(0.0, REFERENCE_MAX_N, default=None,
                                    doc="F_ref at t = 0 (absolute; or initial_rel, or from_file)")
    initial_rel: float | None = param(0.0, 3.0, default=None, unit="1",
                                      doc="F_ref at t = 0 over the nominal tension")
    steps: tuple[Step, ...] = param(default=(), doc="optional reference steps")
    ramps: tuple[Ramp, ...] = param(default=(), doc="optional reference ramps")
    from_file: str | None = param(default=None, doc=FROM_FILE_DOC)
    column: str | None = param(default=None, doc=COLUMN_DOC)

    def cross_check(self, at: Location) -> None:
        if self.from_file is not None:
            _one_source(Reference, at, {"initial_N": self.initial_N,
                                        "initial_rel": self.initial_rel,
                                        "steps": self.steps or None,
                                        "ramps": self.ramps or None}, self.from_file)
        else:
            _one_of(self, at, "initial_N", "initial_rel")


@dataclass(frozen=True)
class SupplyDrop(Parameters):
    """Supply set-point held at pressure_Pa from start_s to end_s [s], linear transitions of
    transition_s [s] at both ends (starting at start_s and at end_s), back to the nominal
    set-point of the hydraulic file."""

    start_s: float = param(0.0, None, doc="start of the first transition")
    end_s: float = param(0.0, None, doc="start of the transition back to nominal")
    transition_s: float = param(0.0, 5.0, doc="duration of each linear transition")
    pressure_Pa: float | None = param(0.0, 30e6, default=None,
                                      doc="supply set-point during the drop (absolute)")
    pressure_rel: float | None = param(0.0, 2.0, default=None, unit="1",
                                       doc="supply set-point during the drop over the "
                                       "hydraulic file's nominal set-point")

    def cross_check(self, at: Location) -> None:
        _one_of(self, at, "pressure_Pa", "pressure_rel")
        _check_window(self, at, self.transition_s, "transition_s")


@dataclass(frozen=True)
class Supply(Parameters):
    """The run's supply: which supply model of the hydraulic file feeds the circuit, and the
    changes of its set-point p_set [Pa gauge] (a relief or compensator setting, a prescribed
    pressure; see docs/sizing.md)."""

    model: SupplyModel | None = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=None, doc="supply model; optional: the hydraulic file's [supply].default_model")
    drops: tuple[SupplyDrop, ...] = param(default=(),
                                          doc="optional set-point drops (not with 'unloading')")
    from_file: str | None = param(default=None, doc="the set-point p_set(t) from a file, a "
                                  "column in Pa (not with 'unloading' or drops): "
                                  + FROM_FILE_DOC)
    column: str | None = param(default=None, doc=COLUMN_DOC)

    def cross_check(self, at: Location) -> None:
        if self.from_file is not None:
            _one_source(Supply, at, {"drops": self.drops or None}, self.from_file)
            if self.model == "unloading":
                raise at.error("model", self.model, "takes no set-point from_file (see "
                               "[[supply.drops]])")
        if self.drops and self.model == "unloading":
            raise at.error("model", self.model,
                           "takes no [[supply.drops]]: with the pump unloaded and its check "
                           "valve closed nothing lowers the accumulator pressure when the "
                           "cut-out is lowered; use 'compensated', 'fixed_relief' or "
                           "'prescribed'")
        ordered = sorted(enumerate(self.drops), key=lambda d: d[1].start_s)
        for (_, a), (j, b) in itertools.pairwise(ordered):
            if b.start_s < a.end_s + a.transition_s:
                raise at.error(("drops", j, "start_s"), b.start_s,
                               f"overlaps the drop from {a.start_s!r} to "
                               f"{a.end_s + a.transition_s!r} s; drops must not overlap")


_ISO8608_KEYS = ("road_class", "n_min_cycles_m", "n_max_cycles_m", "dx_m", "x_start_m",
                 "flat_until_m", "taper_m", "margin_m")


@dataclass(frozen=True)
class Terrain(Parameters):
    """Ground: ``flat`` or an ``iso8608`` random road of road_class over the spatial band
    [n_min, n_max] cycles/m on a grid of dx_m [m] from x_start_m; flat up to flat_until_m
    and blended in over taper_m [m]; extends margin_m [m] past the distance driven. The
    iso8608 keys are required for ``iso8608`` and optional (unused) for ``flat``."""

    kind: Literal["flat", "iso8608"] = param(doc="ground model")
    road_class: str | None = param(choices=tuple(ISO8608_GD_N0_M3), default=None,
                                   doc="ISO 8608 road class (iso8608)")
    n_min_cycles_m: float | None = param(1e-3, 100.0, open_low=True, default=None,
                                         doc="lowest spatial frequency (iso8608)")
    n_max_cycles_m: float | None = param(1e-3, 100.0, open_low=True, default=None,
                                         doc="highest spatial frequency (iso8608)")
    dx_m: float | None = param(1e-3, 0.5, default=None, doc="grid spacing (iso8608)")
    x_start_m: float | None = param(-100.0, 0.0, default=None,
                                    doc="road start behind the vehicle (iso8608)")
    flat_until_m: float | None = param(-100.0, 100.0, default=None,
                                       doc="road level up to here (iso8608)")
    taper_m: float | None = param(0.0, 100.0, default=None,
                                  doc="blend length from flat to rough (iso8608)")
    margin_m: float | None = param(0.0, 100.0, default=None,
                                   doc="road beyond the distance driven (iso8608)")

    def cross_check(self, at: Location) -> None:
        if self.kind != "iso8608":
            return
        for key in _ISO8608_KEYS:
            if getattr(self, key) is None:
                raise ParameterError(f"{at.table()}: missing key {key!r} (needed for "
                                     "kind = 'iso8608')")
        if self.n_max_cycles_m <= self.n_min_cycles_m:
            raise at.error("n_max_cycles_m", self.n_max_cycles_m,
                           f"must be > n_min_cycles_m = {self.n_min_cycles_m!r}")
        if self.n_max_cycles_m > 0.5 / self.dx_m:
            raise at.error("n_max_cycles_m", self.n_max_cycles_m,
                           f"exceeds the grid's Nyquist 1/(2 dx_m) = {0.5 / self.dx_m:g}")


@dataclass(frozen=True)
class LoadPulse(Parameters):
    """Load disturbance from start_s to end_s [s] with linear edges of rise_s [s], applied
    physically as a force hitch_N [N] on the rear hitch along a line pull_angle_deg [deg]
    below the horizontal, rearward (> 0: a towed load, the sprocket drives harder and the
    rear is loaded; < 0: a pushing load, the sprocket brakes and the rear is unloaded; see
    :meth:`~trackmj.track.plant.TrackPlant.set_hitch_force`). delta_N [N] is the change of the
    hold-mode idler load the pulse is calibrated to (``experiments/calibrate_w3.py``)."""

    start_s: float = param(0.0, None, doc="start of the rising edge")
    end_s: float = param(0.0, None, doc="start of the falling edge")
    hitch_N: float = param(-30e3, 30e3, doc="hitch force (> 0 tow, < 0 push)")
    pull_angle_deg: float = param(0.0, 60.0, doc="line of the hitch force below horizontal")
    rise_s: float = param(0.0, 1.0, doc="duration of each linear edge")
    delta_N: float | None = param(-20e3, 20e3, default=None,
                                  doc="target change of the hold-mode idler load (absolute)")
    delta_rel: float | None = param(-1.0, 1.0, default=None, unit="1",
                                    doc="target change over the nominal tension")

    def cross_check(self, at: Location) -> None:
        _one_of(self, at, "delta_N", "delta_rel")
        _check_window(self, at, self.rise_s, "rise_s")


def _one_of(table: Parameters, at: Location, absolute: str, relative: str) -> None:
    """Exactly one of an absolute key and its relative (over the nominal) twin is given."""
    given = [k for k in (absolute, relative) if getattr(table, k) is not None]
    if len(given) != 1:
        raise ParameterError(f"{at.table()}: give exactly one of {absolute!r} (absolute) and "
                             f"{relative!r} (relative to the machine's nominal); got "
                             f"{given or 'neither'}")


@dataclass(frozen=True)
class Hitch(Parameters):
    """A rear-hitch load read from a file (a column in N along the line pull_angle_deg below
    the horizontal, > 0 a towed load, as :class:`LoadPulse` hitch_N); added to the load
    pulses."""

    from_file: str = param(doc=FROM_FILE_DOC)
    pull_angle_deg: float = param(0.0, 60.0, doc="line of the hitch force below horizontal")
    column: str | None = param(default=None, doc=COLUMN_DOC)


def _check_window(window: SupplyDrop | LoadPulse, at: Location, edge_s: float,
                  edge_key: str) -> None:
    if not window.end_s > window.start_s:
        raise at.error("end_s", window.end_s, f"must be > start_s = {window.start_s!r}")
    if edge_s > window.end_s - window.start_s:
        raise at.error(edge_key, edge_s, "is longer than the window end_s - start_s = "
                       f"{window.end_s - window.start_s:g} s")


@dataclass(frozen=True)
class Variant(Parameters):
    """Named parameter perturbation: multiplicative scales on the bulk modulus, the cylinder
    friction coefficient, the track contact stiffness and the initial pre-tension. Each scale
    is optional (default 1): a variant names only what it changes."""

    name: str = param(pattern=NAME_PATTERN, max_len=64,
                      doc="letters, digits, '_', '.', '-', not starting with '.'")
    bulk_modulus_scale: float = param(0.5, 2.0, default=1.0, doc="oil bulk modulus factor")
    friction_scale: float = param(0.5, 2.0, default=1.0, doc="cylinder friction factor")
    contact_stiffness_scale: float = param(0.5, 2.0, default=1.0,
                                           doc="track contact stiffness factor")
    pretension_scale: float = param(0.5, 2.0, default=1.0, doc="initial pre-tension factor")


NOMINAL = Variant("nominal")


@dataclass(frozen=True)
class Limits(Parameters):
    """Admissible tension band [F_min, F_max] [N]; each optional: the machine's band
    (``trackmj.control.params.BAND_REL`` x its nominal tension)."""

    force_min_N: float | None = param(0.0, 100e3, default=None, doc="lower tension limit")
    force_max_N: float | None = param(0.0, 100e3, default=None, doc="upper tension limit")

    def cross_check(self, at: Location) -> None:
        if (self.force_min_N is not None and self.force_max_N is not None
                and self.force_max_N <= self.force_min_N):
            raise at.error("force_max_N", self.force_max_N,
                           f"must be > force_min_N = {self.force_min_N!r}")


@dataclass(frozen=True)
class Evaluation(Parameters):
    """How the metrics are measured (:class:`~trackmj.results.metrics.MetricWindows`): tracking
    metrics from start_s, steady-state metrics and spectra from steady_start_s [s]; the
    settling band relative to the final value and the minimum hold [s]; the low-pass of the
    ``_lp`` metrics; the named ripple bands; the resolution and extent of the spectra."""

    start_s: float = param(0.0, None, doc="tracking metrics from here")
    steady_start_s: float = param(0.0, None, doc="steady-state metrics from here")
    settle_band_rel: float = param(0.0, 0.5, open_low=True,
                                   doc="settling band relative to the final value")
    min_hold_s: float = param(0.0, 10.0, doc="time in the band that counts as settled")
    lowpass_cutoff_Hz: float = param(0.1, 50.0,
                                     doc="cut-off of the zero-phase 2nd-order Butterworth "
                                     "low-pass of the _lp metrics")
    tooth_band_rel: float = param(0.0, 0.5, open_low=True,
                                  doc="tooth-passing ripple band: v/pitch times 1 ± this")
    body_mode_band_Hz: tuple[float, float] = param(0.1, 100.0,
                                                   doc="track-idler-body mode band "
                                                   "[low, high] (ripple and chassis "
                                                   "acceleration)")
    psd_resolution_Hz: float = param(0.05, 10.0,
                                     doc="frequency resolution of the spectra (Welch "
                                     "segments of 1/resolution s)")
    psd_max_Hz: float = param(1.0, 500.0, doc="spectra written up to here")
    mean_window_s: float = param(0.01, 10.0, doc="trailing mean of the acceptance checks")
    recovery_band_rel: float = param(0.0, 0.5, open_low=True,
                                     doc="acceptance: band around the reference the mean "
                                     "returns to after a disturbance edge")
    steady_window_s: float = param(0.1, 100.0, doc="acceptance: length of a steady window "
                                   "whose mean error is the steady offset")

    def cross_check(self, at: Location) -> None:
        low, high = self.body_mode_band_Hz
        if not high > low:
            raise at.error("body_mode_band_Hz", list(self.body_mode_band_Hz),
                           "must be [low, high] with high > low")
        if not low > self.lowpass_cutoff_Hz:
            raise at.error("body_mode_band_Hz", list(self.body_mode_band_Hz),
                           f"must lie above lowpass_cutoff_Hz = {self.lowpass_cutoff_Hz!r} "
                           "(the band splits the ripple the low-pass removes)")
        if not self.psd_max_Hz > self.psd_resolution_Hz:
            raise at.error("psd_max_Hz", self.psd_max_Hz,
                           f"must be > psd_resolution_Hz = {self.psd_resolution_Hz!r}")


@dataclass(frozen=True)
class ScenarioFile(Parameters):
    """A scenario file as written (see the module docstring for its layout)."""

    scenario: Header
    track: Track
    reference: Reference
    terrain: Terrain
    evaluation: Evaluation
    limits: Limits = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=Limits(), doc="optional: the machine's band")
    supply: Supply = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=Supply(), doc="optional: the hydraulic file's default supply at its nominal "
        "set-point")
    load_pulses: tuple[LoadPulse, ...] = param(default=(), doc="optional load pulses")
    variants: tuple[Variant, ...] = param(default=(), doc="optional parameter variants")
    hitch: Hitch | None = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=None, doc="optional hitch load from a file")

    file_kind: ClassVar[str] = "scenario"

    def cross_check(self, at: Location) -> None:
        duration = self.scenario.duration_s
        starts = [(("reference", "steps", i, "time_s"), s.time_s)
                  for i, s in enumerate(self.reference.steps)]
        starts += [(("reference", "ramps", i, "start_s"), r.start_s)
                   for i, r in enumerate(self.reference.ramps)]
        starts += [(("supply", "drops", i, "start_s"), d.start_s)
                   for i, d in enumerate(self.supply.drops)]
        starts += [(("load_pulses", i, "start_s"), p.start_s)
                   for i, p in enumerate(self.load_pulses)]
        starts += [(("evaluation", key), getattr(self.evaluation, key))
                   for key in ("start_s", "steady_start_s")]
        for key, t in starts:
            if t >= duration:
                raise at.error(key, t, f"is at or after the end of the run "
                               f"([scenario].duration_s = {duration!r})")
        if self.reference.from_file is None:
            _check_reference_range(self.reference, duration, at.child("reference"))
        names = [v.name for v in self.variants]
        for i, name in enumerate(names):
            if name in names[:i]:
                raise at.error(("variants", i, "name"), name, "is used twice")
        if self.variants and NOMINAL not in self.variants:
            raise ParameterError(f"{at.table()} [[variants]]: one variant must be "
                                 "name = 'nominal' with every scale 1 (the default run)")


def _check_reference_range(ref: Reference, duration_s: float, at: Location) -> None:
    """F_ref is piecewise linear: its extremes over [0, duration] lie at the breakpoints.
    A reference relative to the nominal tension is checked once resolved (:class:`Scenario`)."""
    if not _is_absolute(ref):
        return
    times = {0.0, duration_s, *(s.time_s for s in ref.steps)}
    times |= {r.start_s for r in ref.ramps} | {r.end_s for r in ref.ramps if r.end_s is not None}
    t = np.array(sorted(x for x in times if x <= duration_s))
    t = np.concatenate([t, t[t > 0.0] - 1e-9])     # just before each step too
    f = _reference(ref, t)
    for bad in (f < 0.0, f > REFERENCE_MAX_N):
        if bad.any():
            k = int(np.argmax(bad))
            raise ParameterError(f"{at.table()}: F_ref reaches {f[k]:.6g} N at t = "
                                 f"{t[k]:.6g} s; it must stay in [0, {REFERENCE_MAX_N:g}] N "
                                 "over the run")


def _is_absolute(ref: Reference) -> bool:
    return (ref.initial_N is not None and all(s.delta_N is not None for s in ref.steps)
            and all(r.rate_N_s is not None for r in ref.ramps))


def _reference(ref: Reference, t: np.ndarray) -> np.ndarray:
    f = np.full(t.shape, ref.initial_N)
    for s in ref.steps:
        f = f + np.where(t >= s.time_s, s.delta_N, 0.0)
    for r in ref.ramps:
        end = math.inf if r.end_s is None else r.end_s
        f = f + r.rate_N_s * np.clip(t - r.start_s, 0.0, end - r.start_s)
    return f


@dataclass(frozen=True)
class Scenario:
    """One operating condition (see the module docstring for the file layout); built by
    :func:`load_scenario`, checked again on construction (``dataclasses.replace``) by the
    same checks as the file. ``source`` is the file it was read from."""

    name: str
    title: str
    source: Path
    duration_s: float
    seeds: tuple[int, ...]
    controller: str
    estimator: str
    track: Track
    reference: Reference
    supply: Supply
    terrain: Terrain
    load_pulses: tuple[LoadPulse, ...]
    variants: tuple[Variant, ...]
    limits: Limits
    evaluation: Evaluation
    machines: tuple[str, ...] | None = None
    machines_reason: str = ""
    nominal_tension_N: float | None = None
    """The nominal tension the relative values were resolved with [N] (None: all absolute)."""
    hitch: Hitch | None = None
    signals: Mapping[str, InputSignal] = dataclasses.field(init=False, compare=False,
                                                           repr=False)
    """The from_file inputs ("reference", "supply", "track", "hitch"), read on construction."""

    def __post_init__(self) -> None:
        header = construct(Header, Location(label=f"Scenario {self.name!r}", path=("scenario",)),
                           name=self.name, title=self.title, duration_s=self.duration_s,
                           seeds=self.seeds, controller=self.controller,
                           estimator=self.estimator, machines=self.machines,
                           machines_reason=self.machines_reason)
        construct(ScenarioFile, Location(label=f"Scenario {self.name!r}"), scenario=header,
                  track=self.track, reference=self.reference, supply=self.supply,
                  terrain=self.terrain, limits=self.limits, evaluation=self.evaluation,
                  load_pulses=self.load_pulses, variants=self.variants, hitch=self.hitch)
        signals = {}
        for what, table, suffix in (("reference", self.reference, "N"),
                                    ("supply", self.supply, "Pa"),
                                    ("track", self.track, "m_s"), ("hitch", self.hitch, "N")):
            if table is not None and table.from_file is not None:
                signals[what] = _input_signal(self.source.parent / table.from_file,
                                              table.column, suffix, INPUT_NAMES[what])
        object.__setattr__(self, "signals", signals)
        self.check_inputs(self.duration_s)

    def check_inputs(self, duration_s: float) -> None:
        """ParameterError naming the file and column if a from_file input does not cover a
        run of ``duration_s`` [s] or F_ref from a file leaves [0, 50 kN]."""
        for what, signal in self.signals.items():
            signal.check_covers(duration_s, INPUT_NAMES[what])
        ref = self.signals.get("reference")
        if ref is not None:
            keep = ref.t_s <= duration_s + COUPLING_STEP_S
            bad = (ref.values < 0.0) | (ref.values > REFERENCE_MAX_N)
            if (bad & keep).any():
                k = int(np.argmax(bad & keep))
                raise ParameterError(f"{ref.file} column {ref.column!r} (reference F_ref): "
                                     f"{ref.values[k]:.6g} N at t = {ref.t_s[k]:.6g} s; it "
                                     f"must stay in [0, {REFERENCE_MAX_N:g}] N over the run")

    def check_machine(self, machine: str) -> None:
        """ParameterError (one line, the reason) if the condition does not apply to
        ``machine`` (a shipped machine's name)."""
        if self.machines and machine not in self.machines:
            raise ParameterError(f"{self.source.name}: scenario {self.name} applies to "
                                 f"{', '.join(self.machines)} only, not {machine}: "
                                 f"{self.machines_reason}")

    # ------------------------------------------------------------------ signals
    def reference_N(self, t_s: np.ndarray | float) -> np.ndarray:
        """F_ref(t) [N], same shape as ``t_s`` (vectorised)."""
        if "reference" in self.signals:
            return self.signals["reference"](t_s)
        return _reference(self.reference, np.asarray(t_s, dtype=float))

    def reference_preview(self, t0_s: float, n: int, dt_s: float) -> np.ndarray:
        """F_ref at t0 + k·dt for k = 0..n−1 [N], shape (n,) (the controller's preview)."""
        return self.reference_N(t0_s + dt_s * np.arange(n))

    def supply_setpoint_Pa(self, t_s: np.ndarray | float, nominal_Pa: float) -> np.ndarray:
        """Supply set-point p_set(t) [Pa]: ``nominal_Pa`` (the hydraulic file's
        [supply].setpoint_Pa) with the drops applied, shape of t_s (vectorised)."""
        if "supply" in self.signals:
            return self.signals["supply"](t_s)
        t = np.asarray(t_s, dtype=float)
        p = np.full(t.shape, float(nominal_Pa))
        for d in self.supply.drops:
            on = _edge(t, d.start_s, d.transition_s) - _edge(t, d.end_s, d.transition_s)
            p = p + (d.pressure_Pa - nominal_Pa) * on
        return p

    def supply_setpoint_profile(self, nominal_Pa: float) -> Callable[[float], float] | None:
        """:meth:`supply_setpoint_Pa` as a piecewise-linear profile with breakpoints at the
        drops' edges (a zero transition becomes a 1 µs ramp ending at the edge), the file's
        signal of a from_file supply, or None without drops (constant ``nominal_Pa``)."""
        if "supply" in self.signals:
            signal = self.signals["supply"]
            return lambda t_s: float(signal(t_s))
        if not self.supply.drops:
            return None
        times = {0.0}
        for d in self.supply.drops:
            for edge in (d.start_s, d.end_s):
                times |= {edge, edge + d.transition_s if d.transition_s > 0.0
                          else max(edge - ZERO_TRANSITION_S, 0.0)}
        t = np.array(sorted(times))
        return PressureProfile(tuple(t.tolist()),
                               tuple(self.supply_setpoint_Pa(t, nominal_Pa).tolist()))

    def track_speed_m_s(self, t_s: np.ndarray | float) -> np.ndarray:
        """Commanded track speed [m/s]: linear ramp from 0 over ramp_s, then constant."""
        if "track" in self.signals:
            return self.signals["track"](t_s)
        t = np.asarray(t_s, dtype=float)
        return self.track.speed_m_s * _edge(t, 0.0, self.track.ramp_s)

    def distance_m(self, duration_s: float) -> float:
        """Track distance driven in ``duration_s`` [s] [m]."""
        if "track" in self.signals:
            t = np.linspace(0.0, duration_s, max(2, round(duration_s / COUPLING_STEP_S) + 1))
            return float(np.trapezoid(self.track_speed_m_s(t), t))
        return self.track.speed_m_s * max(duration_s - 0.5 * self.track.ramp_s, 0.0)

    def steady_speed_m_s(self, duration_s: float) -> float:
        """Mean commanded track speed over the steady window [steady_start_s, duration] [m/s]
        (the speed of a file's trace there; the constant speed otherwise)."""
        if "track" not in self.signals:
            return self.track.speed_m_s
        t = np.arange(self.evaluation.steady_start_s, duration_s, COUPLING_STEP_S)
        return float(np.mean(self.track_speed_m_s(t))) if len(t) else 0.0

    def hitch_force_N(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Rear-hitch load (pull rearward [N], push down [N]) in the chassis frame that
        applies the load pulses; each of shape of t_s."""
        pull = self._pulses(t_s, lambda p: p.hitch_N * math.cos(math.radians(p.pull_angle_deg)))
        down = self._pulses(t_s, lambda p: p.hitch_N * math.sin(math.radians(p.pull_angle_deg)))
        if "hitch" in self.signals:
            load, angle = self.signals["hitch"](t_s), math.radians(self.hitch.pull_angle_deg)
            pull, down = pull + load * math.cos(angle), down + load * math.sin(angle)
        return pull, down

    def _pulses(self, t_s: np.ndarray | float,
                amplitude: Callable[[LoadPulse], float]) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        f = np.zeros(t.shape)
        for p in self.load_pulses:
            f = f + amplitude(p) * (_edge(t, p.start_s, p.rise_s) - _edge(t, p.end_s, p.rise_s))
        return f

    def terrain_profile(self, seed: int, duration_s: float | None = None) -> RoadProfile | None:
        """Road profile for ``seed`` (None for flat ground), long enough for the distance
        driven in ``duration_s`` (default: the scenario's) plus the margin."""
        tr = self.terrain
        if tr.kind == "flat":
            return None
        duration = self.duration_s if duration_s is None else duration_s
        distance = self.distance_m(duration)
        length = distance + tr.margin_m - tr.x_start_m
        rng = np.random.default_rng([seed, TERRAIN_SEED_SALT])
        prof = road_profile(length, tr.dx_m, tr.road_class, rng, n_min=tr.n_min_cycles_m,
                            n_max=tr.n_max_cycles_m, x_start_m=tr.x_start_m)
        return taper_start(prof, tr.flat_until_m, tr.taper_m)

    def variant(self, name: str) -> Variant:
        """The variant called ``name``; KeyError listing the available ones."""
        for v in self.variants:
            if v.name == name:
                return v
        raise KeyError(f"{self.name}: no variant {name!r}; available: "
                       f"{[v.name for v in self.variants]}")

    def metric_windows(self, duration_s: float | None = None, *,
                       link_pitch_m: float | None = None) -> MetricWindows:
        """Windows for :func:`trackmj.results.metrics.compute_metrics`: the first reference step
        (evaluated until the next step or ramp start), load pulses and supply drops as
        disturbances, the steady window from steady_start_s to the end, and the
        ``[evaluation]`` settings. With the track's ``link_pitch_m`` [m] the tooth-passing
        band v/pitch·(1 ± tooth_band_rel) at the scenario's track speed (a link passes the
        sprocket every pitch); without it (or standing still) there is none. On an iso8608
        road the band it excites, speed × [n_min, n_max] cycles/m, is recorded too."""
        duration = self.duration_s if duration_s is None else duration_s
        step = None
        if self.reference.steps:
            s0 = min(self.reference.steps, key=lambda s: s.time_s)
            later = [s.time_s for s in self.reference.steps if s.time_s > s0.time_s]
            later += [r.start_s for r in self.reference.ramps if r.start_s > s0.time_s]
            t_stop = min([*later, duration])
            before = float(self.reference_N(s0.time_s - 1e-9))
            step = (s0.time_s, before, before + s0.delta_N, t_stop)
        dist = tuple((p.start_s, p.end_s) for p in self.load_pulses)
        dist += tuple((d.start_s, d.end_s) for d in self.supply.drops)
        labels = tuple(f"load pulse {p.delta_N / 1e3:+g} kN" for p in self.load_pulses)
        labels += tuple(f"supply drop to {d.pressure_Pa / 1e6:g} MPa" for d in self.supply.drops)
        ev, speed = self.evaluation, self.steady_speed_m_s(duration)
        tooth = None
        if link_pitch_m is not None and speed > 0.0:
            f_tooth = speed / link_pitch_m
            tooth = (f_tooth * (1.0 - ev.tooth_band_rel), f_tooth * (1.0 + ev.tooth_band_rel))
        road = None
        if self.terrain.kind == "iso8608":
            road = (speed * self.terrain.n_min_cycles_m, speed * self.terrain.n_max_cycles_m)
        return MetricWindows(
            force_min_N=self.limits.force_min_N, force_max_N=self.limits.force_max_N,
            evaluation_start_s=ev.start_s, step=step, disturbances=dist,
            disturbance_labels=labels,
            steady=(ev.steady_start_s, duration), settle_band_rel=ev.settle_band_rel,
            min_hold_s=ev.min_hold_s, lowpass_cutoff_Hz=ev.lowpass_cutoff_Hz,
            body_mode_band_Hz=ev.body_mode_band_Hz, tooth_passing_band_Hz=tooth,
            road_band_Hz=road, psd_resolution_Hz=ev.psd_resolution_Hz,
            psd_max_Hz=ev.psd_max_Hz, mean_window_s=ev.mean_window_s,
            recovery_band_rel=ev.recovery_band_rel, steady_window_s=ev.steady_window_s,
            reference_events_s=tuple(sorted({*(s.time_s for s in self.reference.steps),
                                             *(r.start_s for r in self.reference.ramps)})))


# ---------------------------------------------------------------------- loading

INPUT_NAMES = {"reference": "reference F_ref", "supply": "supply set-point p_set",
               "track": "track speed", "hitch": "hitch load"}
"""What each from_file input is called in messages."""


@functools.lru_cache(maxsize=16)
def _cached_signal(path: Path, mtime_ns: int, column: str | None, suffix: str,
                   what: str) -> InputSignal:
    return input_signal(path, column, suffix, what)


def _input_signal(path: Path, column: str | None, suffix: str, what: str) -> InputSignal:
    """The file's input signal, read once per file version."""
    if not path.is_file():
        raise ParameterError(f"{what}: from_file {path} not found")
    return _cached_signal(path.resolve(), path.stat().st_mtime_ns, column, suffix, what)


def scenario_path(name_or_path: str | Path) -> Path:
    """Path of a built-in scenario (``W1``..``W5``, case-insensitive) or of a custom file."""
    if isinstance(name_or_path, str) and name_or_path.upper() in BUILTIN:
        return Path(str(files("trackmj.experiments").joinpath(f"{name_or_path.upper()}.toml")))
    path = Path(name_or_path)
    if not path.exists():
        raise ParameterError(f"scenario file not found: {path} (built-in scenarios: "
                             f"{', '.join(BUILTIN)})")
    return path


TWINS = {"initial_N": "initial_rel", "delta_N": "delta_rel", "rate_N_s": "rate_rel_s",
         "pressure_Pa": "pressure_rel"}
"""Absolute keys and their relative twins (exactly one of a pair is given)."""


def _drop_twin(data: dict[str, Any], dotted: str) -> None:
    """An override of one key of a twin pair replaces the other one of the file."""
    *parents, key = dotted.split(".")
    twin = TWINS.get(key) or next((a for a, r in TWINS.items() if r == key), None)
    node: Any = data
    for part in parents:
        try:
            node = node[int(part)] if isinstance(node, list) else node[part]
        except (KeyError, IndexError, ValueError, TypeError):
            return
    if twin is not None and isinstance(node, dict):
        node.pop(twin, None)


def _packaged_nominal() -> tuple[float, float]:
    """Nominal tension [N] and supply set-point [Pa] of the packaged machine."""
    from trackmj.hydraulics import load_hydraulic_params
    from trackmj.track.mechanics import load_model_params

    return (load_model_params().nominal_tension_N,
            load_hydraulic_params().supply.setpoint_Pa)


def _resolve(f: ScenarioFile, nominal_N: float, setpoint_Pa: float) -> ScenarioFile:
    """``f`` with every relative value made absolute: forces x ``nominal_N``, drop pressures
    x ``setpoint_Pa``, the [limits] the file leaves out the machine's band."""
    from trackmj.control.params import BAND_REL

    rep = dataclasses.replace

    def absolute(x: float | None, rel: float | None, scale: float) -> float:
        return x if rel is None else scale * rel

    ref = f.reference
    reference = rep(
        ref, initial_N=absolute(ref.initial_N, ref.initial_rel, nominal_N), initial_rel=None,
        steps=tuple(rep(s, delta_N=absolute(s.delta_N, s.delta_rel, nominal_N), delta_rel=None)
                    for s in ref.steps),
        ramps=tuple(rep(r, rate_N_s=absolute(r.rate_N_s, r.rate_rel_s, nominal_N),
                        rate_rel_s=None) for r in ref.ramps))
    supply = rep(f.supply, drops=tuple(
        rep(d, pressure_Pa=absolute(d.pressure_Pa, d.pressure_rel, setpoint_Pa),
            pressure_rel=None) for d in f.supply.drops))
    pulses = tuple(rep(p, delta_N=absolute(p.delta_N, p.delta_rel, nominal_N), delta_rel=None)
                   for p in f.load_pulses)
    lim = f.limits
    limits = Limits(nominal_N * BAND_REL[0] if lim.force_min_N is None else lim.force_min_N,
                    nominal_N * BAND_REL[1] if lim.force_max_N is None else lim.force_max_N)
    return rep(f, reference=reference, supply=supply, load_pulses=pulses, limits=limits)


def load_scenario(name_or_path: str | Path,
                  overrides: Mapping[str, Any] | None = None, *,
                  nominal_tension_N: float | None = None,
                  supply_setpoint_Pa: float | None = None) -> Scenario:
    """Load and validate a scenario.

    Parameters
    ----------
    name_or_path : str or Path
        A built-in name (``W1``..``W5``) or a TOML file.
    overrides : mapping, optional
        ``{dotted key: value}``, the ``scenario`` entry of
        :func:`trackmj.validator.parse_overrides` (e.g. ``{"track.speed_m_s": 2.0}``).
    nominal_tension_N, supply_setpoint_Pa : float, optional
        The machine's nominal tension [N] and its hydraulic file's supply set-point [Pa]
        that the relative values (``*_rel`` keys, the [limits] left out) are taken over;
        default the packaged machine's (lf1352).

    Returns
    -------
    Scenario
        Every value absolute.
    """
    path = scenario_path(name_or_path)
    data = read_toml(path)
    for key in overrides or {}:
        _drop_twin(data, str(key))
    f = build(ScenarioFile, data, file=path.name, overrides=overrides, require_source=False)
    if nominal_tension_N is None or supply_setpoint_Pa is None:
        packaged = _packaged_nominal()
        nominal_tension_N = packaged[0] if nominal_tension_N is None else nominal_tension_N
        supply_setpoint_Pa = packaged[1] if supply_setpoint_Pa is None else supply_setpoint_Pa
    try:
        f = _resolve(f, nominal_tension_N, supply_setpoint_Pa)
    except ParameterError as exc:   # a resolved value's check names the file
        raise ParameterError(f"{path.name} (relative values at a nominal tension of "
                             f"{nominal_tension_N:g} N): {exc}") from None
    h = f.scenario
    return Scenario(name=h.name, title=h.title, source=path, duration_s=h.duration_s,
                    seeds=h.seeds, controller=h.controller, estimator=h.estimator,
                    track=f.track, reference=f.reference, supply=f.supply, terrain=f.terrain,
                    load_pulses=f.load_pulses, variants=f.variants or (NOMINAL,),
                    limits=f.limits, evaluation=f.evaluation, machines=h.machines,
                    machines_reason=h.machines_reason, nominal_tension_N=nominal_tension_N,
                    hitch=f.hitch)



# ----------------------------------------------------------------------------- events

@dataclass(frozen=True)
class Event:
    """A scheduled event of a scenario: ``what`` it is (for messages), its keys in the
    scenario file (``(key, time [s])`` of each of its times, e.g. ``("supply.drops.0.start_s",
    12.0)``), and the time it needs the run to last to be whole, ``needs_s`` [s] (a step's or
    ramp's start must lie inside the run; a pulse's or drop's end edge must be over)."""

    what: str
    times: tuple[tuple[str, float], ...]
    needs_s: float
    edge_s: float = 0.0

    def fits(self, duration_s: float) -> bool:
        """Whether a run of ``duration_s`` [s] holds the whole event."""
        start = self.times[0][1]
        return start < duration_s and self.needs_s <= duration_s


def events(sc: Scenario) -> list[Event]:
    """The reference steps and ramps, supply drops and load pulses of ``sc``."""
    out = [Event(f"[[reference.steps]][{i}] (reference step at {s.time_s:g} s)",
                 ((f"reference.steps.{i}.time_s", s.time_s),), s.time_s)
           for i, s in enumerate(sc.reference.steps)]
    for i, r in enumerate(sc.reference.ramps):
        times = ((f"reference.ramps.{i}.start_s", r.start_s),)
        if r.end_s is not None:
            times += ((f"reference.ramps.{i}.end_s", r.end_s),)
        out.append(Event(f"[[reference.ramps]][{i}] (reference ramp from {r.start_s:g} s)",
                         times, r.start_s if r.end_s is None else r.end_s))
    for i, d in enumerate(sc.supply.drops):
        out.append(Event(f"[[supply.drops]][{i}] (supply drop {d.start_s:g}-{d.end_s:g} s)",
                         ((f"supply.drops.{i}.start_s", d.start_s),
                          (f"supply.drops.{i}.end_s", d.end_s)),
                         d.end_s + d.transition_s, d.transition_s))
    for i, p in enumerate(sc.load_pulses):
        out.append(Event(f"[[load_pulses]][{i}] (load pulse {p.start_s:g}-{p.end_s:g} s)",
                         ((f"load_pulses.{i}.start_s", p.start_s),
                          (f"load_pulses.{i}.end_s", p.end_s)), p.end_s + p.rise_s, p.rise_s))
    return out


def cut_events(sc: Scenario, duration_s: float) -> list[Event]:
    """The events of ``sc`` that its own duration holds whole and a run of ``duration_s``
    [s] would cut off (start after the end, or end edge not over)."""
    return [e for e in events(sc) if e.fits(sc.duration_s) and not e.fits(duration_s)]


def check_duration(sc: Scenario, duration_s: float) -> None:
    """ParameterError (one line naming the first event cut off) if a run of ``duration_s``
    [s] would cut off one of ``sc``'s events; the same rule as the scenario file's, where an
    event after ``duration_s`` is refused."""
    cut = cut_events(sc, duration_s)
    if cut:
        e = cut[0]
        more = f" (and {len(cut) - 1} more)" if len(cut) > 1 else ""
        starts_inside = e.times[0][1] >= e.needs_s     # a step or open ramp: start < duration
        least = f"more than {e.needs_s:g}" if starts_inside else f"{e.needs_s:g} or more"
        raise ParameterError(
            f"--duration {duration_s:g} s cuts off {sc.source.name} {e.what}{more}: it needs "
            f"the run to last {least} s; give --duration {least}, or move "
            f"the event with --set scenario.{e.times[0][0]}=...")


def moved_events(sc: Scenario, duration_s: float) -> dict[str, float]:
    """Scenario overrides (``{"reference.steps.0.time_s": t, ...}``) that move every event
    of ``sc`` into a run of ``duration_s`` [s] if the run would cut one off; {} otherwise.

    The schedule after the evaluation start ``s`` is compressed linearly: a time t >= s
    becomes s + (t − s)·(duration_s − s)/(D − s), D the scenario's duration, so the events
    keep their order and their share of the run; earlier times stay. Edges (a pulse's rise,
    a drop's transition) keep their length where the window holds it, else shrink by the
    same factor. Moved times are rounded to the 1 ms coupling step."""
    if not cut_events(sc, duration_s):
        return {}
    s = sc.evaluation.start_s
    factor = (duration_s - s) / (sc.duration_s - s)

    def move(t: float) -> float:
        return t if t < s else s + (t - s) * factor

    out: dict[str, float] = {}
    for e in events(sc):
        moved = [(key, move(t)) for key, t in e.times]
        out |= {key: round(t, 3) for key, t in moved}   # on the 1 ms coupling grid
        if e.edge_s and len(moved) == 2:
            if e.edge_s > moved[1][1] - moved[0][1]:   # the window's own check
                kind = "transition_s" if "drops" in moved[0][0] else "rise_s"
                out[moved[0][0].rsplit(".", 1)[0] + "." + kind] = round(e.edge_s * factor, 3)
    return out


def describe_moves(sc: Scenario, moves: Mapping[str, float]) -> str:
    """One line saying where ``moves`` (from :func:`moved_events`) put the events of ``sc``."""
    parts = []
    for e in events(sc):
        new = [f"{moves[k]:.3g}" for k, _ in e.times if k in moves]
        if new:
            parts.append(f"{e.what.split('(', 1)[1].rstrip(')')} -> {'-'.join(new)} s")
    return "; ".join(parts)
