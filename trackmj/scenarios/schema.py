"""The scenario file's tables: frozen dataclasses read by the one validator
(:mod:`trackmj.validator`) into :class:`ScenarioFile`, whose tables mirror the file. Invalid
files raise :class:`~trackmj.validator.ParameterError` naming the file, the table, the key,
the value and the allowed range or choices, before anything is built.
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
    [terrain]     kind, grade (optional, default 0: level); for kind = "iso8608" also
                  road_class, n_min_cycles_m, n_max_cycles_m, dx_m, x_start_m, flat_until_m,
                  taper_m, margin_m (for "flat" they are optional and unused, so
                  ``--set scenario.terrain.kind=flat`` works on W2)
    [[load_pulses]] start_s, end_s, delta_N | delta_rel, pull_angle_deg, rise_s,
                  hitch_N (optional: calibrated for the machine)
    [[variants]]  name, bulk_modulus_scale, friction_scale, contact_stiffness_scale,
                  pretension_scale (each scale optional, default 1: a variant names only
                  what it changes; if variants are listed one must be "nominal")
    [limits]      force_min_N, force_max_N (each optional: the machine's band)
    [evaluation]  start_s, steady_start_s, settle_band_rel, min_hold_s, lowpass_cutoff_Hz,
                  tooth_band_rel, body_mode_band_Hz, psd_resolution_Hz, psd_max_Hz

A force is absolute (``*_N``) or relative to the machine's nominal tension (``*_rel``, the
mechanics file's ``[tensioner].nominal_tension_N``, else its preload); a drop pressure
absolute or relative to the hydraulic file's set-point; exactly one of each pair
(:mod:`trackmj.scenarios.resolve` makes them absolute for a machine).

Time windows must lie in the run: steps, ramp, drop and pulse starts and the evaluation
starts before ``duration_s``; each drop's and pulse's edges fit inside its window; drops do
not overlap; F_ref stays in [0, 5 MN] (:data:`FORCE_MAX_N`, a sanity cap above any crawler;
the machine's own limits bind). The scenario ``name`` names the run directories, so it is a
short identifier (letters, digits, ``_ . -``, not starting with a dot, at most 64
characters). Tables may carry a ``source`` string; unlike parameter files they need not.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Literal, TypeVar

import numpy as np

from trackmj.hydraulics.params import SupplyModel
from trackmj.ports import COUPLING_STEP_S
from trackmj.results.verdict import RECOVERY_WITHIN_S, STEADY_OFFSET_MAX_REL
from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS
from trackmj.sim.entries import by_name, choices
from trackmj.track.terrain import ISO8608_GD_N0_M3
from trackmj.validator import (
    Location,
    ParameterError,
    Parameters,
    missing_key,
    origin_field,
    param,
)

NAME_PATTERN = r"[A-Za-z0-9_-][A-Za-z0-9_.-]*"
"""Scenario and variant names: they become parts of run directory names."""
FORCE_MAX_N = 5e6
"""Sanity cap on every force a scenario gives or resolves to [N] (F_ref and its steps, a
hitch force, a pulse's target, the [limits]; a ramp's slope at most this per second): the
weight of one side of the heaviest crawlers built, 1000 t class mining shovels (~500 t a
side, 4.9 MN), so above the track tension and the drawbar pull (mu W) of any crawler
trackmj models (its mechanics file admits up to 1.2e5 kg a side and a nominal tension up
to 1 MN). It only catches a slip of units; the limits that bind are the machine's: its
drawbar capacity and 75 % of its tipping force for a hitch force
(:mod:`trackmj.sim.w3_hitch`), its cylinders' force for the band
(:func:`trackmj.machines.assembly.cylinder_force_shortfall`)."""
REFERENCE_MAX_N = FORCE_MAX_N
"""F_ref must stay within [0, REFERENCE_MAX_N] over the run [N] (the sanity cap)."""
TRACK_SPEED_MAX_M_S = 5.0
"""The commanded track speed stays within ±TRACK_SPEED_MAX_M_S [m/s] (negative: reverse)."""
STUDY_BODY_MODE_BAND_HZ = (8.0, 12.0)
"""The study's first track–idler–body mode band [Hz] on LF1352. A scenario that states no
``[evaluation] body_mode_band_Hz`` takes the machine's: this band moved with the ratio of
the machine's first identified mode to LF1352's (:mod:`trackmj.machines.idler`), so it
stays the study's on LF1352 and does not sit on another machine's tooth passing (M113 at
1.5 m/s: 8.8-10.7 Hz, inside 8-12 Hz)."""
HITCH_LIMIT_N = FORCE_MAX_N
"""A load pulse's hitch force stays within ±HITCH_LIMIT_N [N] (the sanity cap; the
calibration keeps within the machine's drawbar capacity and tipping limit)."""

_T = TypeVar("_T")


def present(value: _T | None, key: str) -> _T:
    """``value`` of the optional scenario ``key`` (dotted, e.g. ``"terrain.dx_m"``) where the
    file's checks or the resolution to absolute values guarantee one; RuntimeError naming the
    key if it is None (a bug in the caller, not an error in the file)."""
    if value is None:
        raise RuntimeError(f"scenario key {key} is None where the file's checks or its "
                           "resolution to absolute values guarantee a value")
    return value


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

    speed_m_s: float | None = param(-TRACK_SPEED_MAX_M_S, TRACK_SPEED_MAX_M_S, default=None,
                                    doc="track speed commanded to the sprocket servo, "
                                    "negative in reverse (required without from_file)")
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
    delta_N: float | None = param(-FORCE_MAX_N, FORCE_MAX_N, default=None,
                                  doc="change of F_ref (absolute)")
    delta_rel: float | None = param(-3.0, 3.0, default=None, unit="1",
                                    doc="change of F_ref over the nominal tension")

    def cross_check(self, at: Location) -> None:
        _one_of(self, at, "delta_N", "delta_rel")


@dataclass(frozen=True)
class Ramp(Parameters):
    """Reference ramp of rate_N_s [N/s] from start_s to end_s [s]."""

    start_s: float = param(0.0, None, doc="start of the ramp")
    rate_N_s: float | None = param(-FORCE_MAX_N, FORCE_MAX_N, default=None,
                                    doc="slope of F_ref (absolute)")
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


@dataclass(frozen=True)
class Road:
    """The keys of an ``iso8608`` [terrain], each given (their meaning: :class:`Terrain`)."""

    road_class: str
    n_min_cycles_m: float
    n_max_cycles_m: float
    dx_m: float
    x_start_m: float
    flat_until_m: float
    taper_m: float
    margin_m: float


_ISO8608_KEYS = tuple(f.name for f in fields(Road))


@dataclass(frozen=True)
class Terrain(Parameters):
    """Ground: ``flat`` or an ``iso8608`` random road of road_class over the spatial band
    [n_min, n_max] cycles/m on a grid of dx_m [m] from x_start_m; flat up to flat_until_m
    and blended in over taper_m [m]; extends margin_m [m] past the distance driven. A run
    that reverses behind its start gets the road both ways: from margin_m behind the
    furthest it backs (or x_start_m) to margin_m past the furthest it goes forward (or
    −x_start_m), level for |x| <= flat_until_m. The iso8608 keys are required for
    ``iso8608`` and optional (unused) for ``flat``. Either ground lies on a slope of
    ``grade`` (default 0, level)."""

    kind: Literal["flat", "iso8608"] = param(doc="ground model")
    grade: float = param(-1.0, 1.0, default=0.0, unit="1",
                         doc="slope driven on, tan θ (rise over run; > 0 uphill driving "
                         "forward): gravity tilted by θ, the ground the model's x axis")
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
        road = self.road()
        if road.n_max_cycles_m <= road.n_min_cycles_m:
            raise at.error("n_max_cycles_m", road.n_max_cycles_m,
                           f"must be > n_min_cycles_m = {road.n_min_cycles_m!r}")
        if road.n_max_cycles_m > 0.5 / road.dx_m:
            raise at.error("n_max_cycles_m", road.n_max_cycles_m,
                           f"exceeds the grid's Nyquist 1/(2 dx_m) = {0.5 / road.dx_m:g}")

    def road(self) -> Road:
        """The iso8608 keys, each given (the checks require them for kind = 'iso8608');
        RuntimeError naming the first one left out (a flat terrain may leave them out)."""
        return Road(road_class=present(self.road_class, "terrain.road_class"),
                    n_min_cycles_m=present(self.n_min_cycles_m, "terrain.n_min_cycles_m"),
                    n_max_cycles_m=present(self.n_max_cycles_m, "terrain.n_max_cycles_m"),
                    dx_m=present(self.dx_m, "terrain.dx_m"),
                    x_start_m=present(self.x_start_m, "terrain.x_start_m"),
                    flat_until_m=present(self.flat_until_m, "terrain.flat_until_m"),
                    taper_m=present(self.taper_m, "terrain.taper_m"),
                    margin_m=present(self.margin_m, "terrain.margin_m"))


@dataclass(frozen=True)
class LoadPulse(Parameters):
    """Load disturbance from start_s to end_s [s] with linear edges of rise_s [s], applied
    physically as a force hitch_N [N] on the rear hitch along a line pull_angle_deg [deg]
    below the horizontal, rearward (> 0: a towed load, the sprocket drives harder and the
    rear is loaded; < 0: a pushing load, the sprocket brakes and the rear is unloaded; see
    :meth:`~trackmj.track.plant.TrackPlant.set_hitch_force`). delta_N [N] (or delta_rel x
    the nominal tension) is the change of the hold-mode idler load the pulse is calibrated
    to. Without hitch_N the hitch force is calibrated for the run's machine
    (:mod:`trackmj.sim.w3_hitch`: committed for the shipped machines, cached for others);
    a hitch_N given is applied as it is, on any machine."""

    start_s: float = param(0.0, None, doc="start of the rising edge")
    end_s: float = param(0.0, None, doc="start of the falling edge")
    pull_angle_deg: float = param(0.0, 60.0, doc="line of the hitch force below horizontal")
    rise_s: float = param(0.0, 1.0, doc="duration of each linear edge")
    hitch_N: float | None = param(-HITCH_LIMIT_N, HITCH_LIMIT_N, default=None,
                                  doc="hitch force (> 0 tow, < 0 push); optional: "
                                  "calibrated for the machine to the target delta")
    delta_N: float | None = param(-FORCE_MAX_N, FORCE_MAX_N, default=None,
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

    force_min_N: float | None = param(0.0, FORCE_MAX_N, default=None,
                                      doc="lower tension limit")
    force_max_N: float | None = param(0.0, FORCE_MAX_N, default=None,
                                      doc="upper tension limit")

    def cross_check(self, at: Location) -> None:
        if (self.force_min_N is not None and self.force_max_N is not None
                and self.force_max_N <= self.force_min_N):
            raise at.error("force_max_N", self.force_max_N,
                           f"must be > force_min_N = {self.force_min_N!r}")


@dataclass(frozen=True)
class Evaluation(Parameters):
    """How the metrics are measured (:class:`~trackmj.results.metric_windows.MetricWindows`):
    tracking metrics from start_s, steady-state metrics and spectra from steady_start_s [s]; the
    settling band relative to the final value and the minimum hold [s]; the low-pass of the
    ``_lp`` metrics; the named ripple bands; the resolution and extent of the spectra.

    start_s and steady_start_s are the scenario's own (when its start-up is over and when its
    steady part begins) and must be given; every other key defaults to the value the
    built-in scenarios (W1) use, so a scenario file gives only what differs."""

    start_s: float = param(0.0, None, doc="tracking metrics from here")
    steady_start_s: float = param(0.0, None, doc="steady-state metrics from here")
    settle_band_rel: float = param(0.0, 0.5, open_low=True, default=0.02,
                                   doc="settling band relative to the final value "
                                   "(default W1's ±2 %)")
    min_hold_s: float = param(0.0, 10.0, default=0.5,
                              doc="time in the band that counts as settled (default W1's)")
    lowpass_cutoff_Hz: float = param(0.1, 50.0, default=2.0,
                                     doc="cut-off of the zero-phase 2nd-order Butterworth "
                                     "low-pass of the _lp metrics (default W1's)")
    tooth_band_rel: float = param(0.0, 0.5, open_low=True, default=0.1,
                                  doc="tooth-passing ripple band: v/pitch times 1 ± this "
                                  "(default W1's)")
    body_mode_band_Hz: tuple[float, float] | None = param(
        0.1, 100.0, default=None, doc="track-idler-body mode band [low, high] (ripple and "
        "chassis acceleration); optional: the machine's, the study's 8-12 Hz on LF1352 "
        "moved with the machine's identified first mode (STUDY_BODY_MODE_BAND_HZ)")
    psd_resolution_Hz: float = param(0.05, 10.0, default=0.5,
                                     doc="frequency resolution of the spectra (Welch "
                                     "segments of 1/resolution s; default W1's)")
    psd_max_Hz: float = param(1.0, 500.0, default=50.0,
                              doc="spectra written up to here (default W1's)")
    mean_window_s: float = param(0.01, 10.0, default=0.5,
                                 doc="trailing mean of the acceptance checks (default W1's)")
    recovery_band_rel: float = param(0.0, 0.5, open_low=True, default=0.05,
                                     doc="acceptance: band around the reference the mean "
                                     "returns to after a disturbance edge (default W1's)")
    steady_window_s: float = param(0.1, 100.0, default=5.0,
                                   doc="acceptance: length of a steady window whose mean "
                                   "error is the steady offset (default W1's)")
    recovery_within_s: float = param(0.0, 30.0, open_low=True, default=RECOVERY_WITHIN_S,
                                     doc="acceptance: the mean is back within the recovery "
                                     "band this long after each disturbance edge (and a "
                                     "steady window starts no earlier; default W1's)")
    steady_offset_max_rel: float = param(0.0, 0.5, open_low=True,
                                         default=STEADY_OFFSET_MAX_REL,
                                         doc="acceptance: a steady window's mean error "
                                         "stays below this share of the reference "
                                         "(default W1's)")

    def cross_check(self, at: Location) -> None:
        if self.body_mode_band_Hz is not None:
            low, high = self.body_mode_band_Hz
            if not high > low:
                raise at.error("body_mode_band_Hz", [low, high],
                               "must be [low, high] with high > low")
            if not low > self.lowpass_cutoff_Hz:
                raise at.error("body_mode_band_Hz", [low, high],
                               f"must lie above lowpass_cutoff_Hz = "
                               f"{self.lowpass_cutoff_Hz!r} (the band splits the ripple the "
                               "low-pass removes)")
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
    origin: Location = origin_field()  # noqa: RUF009 (returns a dataclasses.Field)
    """Where the values come from (the file, the --set options): the resolution to
    absolute values names them (:func:`trackmj.scenarios.resolve.resolve`)."""

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
    A reference relative to the nominal tension is checked once resolved
    (:class:`~trackmj.scenarios.resolved.Scenario`)."""
    if not _is_absolute(ref):
        return
    times = {0.0, duration_s, *(s.time_s for s in ref.steps)}
    times |= {r.start_s for r in ref.ramps} | {r.end_s for r in ref.ramps if r.end_s is not None}
    t = np.array(sorted(x for x in times if x <= duration_s))
    t = np.concatenate([t, t[t > 0.0] - 1e-9])     # just before each step too
    f = reference_signal(ref, t)
    for bad in (f < 0.0, f > REFERENCE_MAX_N):
        if bad.any():
            k = int(np.argmax(bad))
            raise ParameterError(f"{at.table()}: F_ref reaches {f[k]:.6g} N at t = "
                                 f"{t[k]:.6g} s; it must stay in [0, {REFERENCE_MAX_N:g}] N "
                                 "over the run (a sanity cap above any crawler's tension)")


def _is_absolute(ref: Reference) -> bool:
    return (ref.initial_N is not None and all(s.delta_N is not None for s in ref.steps)
            and all(r.rate_N_s is not None for r in ref.ramps))


def reference_signal(ref: Reference, t: np.ndarray) -> np.ndarray:
    """F_ref(t) [N] of an absolute [reference] table (initial_N + steps + ramps), shape of
    ``t`` [s]."""
    f = np.full(t.shape, present(ref.initial_N, "reference.initial_N"))
    for s in ref.steps:
        f = f + np.where(t >= s.time_s, present(s.delta_N, "reference.steps.delta_N"), 0.0)
    for r in ref.ramps:
        end = math.inf if r.end_s is None else r.end_s
        rate = present(r.rate_N_s, "reference.ramps.rate_N_s")
        f = f + rate * np.clip(t - r.start_s, 0.0, end - r.start_s)
    return f

