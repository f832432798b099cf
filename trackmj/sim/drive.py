"""The ``trackmj drive`` run: the bare track with its passive tensioner (or the tensioner of a
tensioner file: a spring-damper or an FMU) driven at a sprocket speed, with the mechanical
energy ledger (:mod:`trackmj.track.energy`) and a 1 kHz time series.

Output directory (written whole or not at all: a temporary sibling directory renamed into
place):

- ``metrics.json``: run settings, the machine (the crawler's name) and its input files,
  ``real_time_factor`` (simulated / wall time of the whole loop, ledger and recording
  included) and ``plant_real_time_factor`` (plant steps only), the ``host`` computer, the
  ``track_energy`` table [J], steady-state means, the health counts and the ``derailment``
  table (:func:`derailment_table`);
- ``timeseries.parquet``: one row per 1 ms step, SI, each column's unit in its Arrow field
  metadata under ``unit`` (:data:`TIMESERIES_UNITS`);
- ``drive.png``: idler force, strand tensions and the derailment indicators over time
  (:func:`trackmj.results.figure_drive.drive_figure`).

Derailment is checked every :data:`DERAILMENT_CHECK_S` (:meth:`TrackPlant.derailment`: three
checks, and ``derailed`` when any fails; the slack strand's reads the samples taken every
:attr:`TrackPlant.SLACK_SAMPLE_S` since the previous check, its window
:attr:`TrackPlant.SLACK_PERSISTENCE_S` being the check interval). Its timeseries columns
(:data:`DERAILMENT_UNITS`)
hold each check's value from that check's row until the next check's (sample and hold), NaN
before the first check; the flags are 1.0 when the check fails, else 0.0.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from numpy.typing import ArrayLike

from trackmj.elements.fmu import FmuElement
from trackmj.elements.tensioner_file import load_tensioner
from trackmj.errors import PhysicsError
from trackmj.host import machine as host_machine
from trackmj.machines.assembly import resolve
from trackmj.machines.track_plant import load_plant
from trackmj.ports import COUPLING_STEP_S, Command, Readout, StepInputs, TensionerElement
from trackmj.results.figure_drive import drive_figure
from trackmj.results.signals import settling_time
from trackmj.results.store import ResultWriter, finite_or_null, metrics_as_read, parquet_bytes
from trackmj.scenarios.schema import TRACK_SPEED_MAX_M_S
from trackmj.sim.mechanics import SETTLE_S
from trackmj.track.energy import TrackEnergyLedger
from trackmj.track.plant import DerailmentLimits, DerailmentStatus, PassiveTensioner, TrackPlant
from trackmj.track.terrain import check_grade_held, gravity_on_grade

STEP_UNITS: dict[str, str] = {
    "t_s": "s", "idler_force_N": "N", "stroke_m": "m", "stroke_velocity_m_s": "m/s",
    "track_speed_m_s": "m/s", "vehicle_speed_m_s": "m/s", "upper_strand_tension_N": "N",
    "lower_strand_tension_N": "N", "max_pin_gap_m": "m", "drive_torque_N_m": "N·m",
    "hitch_pull_N": "N",
}
"""Columns of ``timeseries.parquet`` recorded every step, and their units."""
DERAILMENT_UNITS: dict[str, str] = {
    "sprocket_seated_pins": "1", "envelope_excursion_max_m": "m", "envelope_worst_pin": "1",
    "upper_strand_tension_min_N": "N", "upper_strand_slackest_pin": "1",
    "upper_strand_tension_held_N": "N", "sprocket_disengaged": "1", "links_off_envelope": "1",
    "slack_strand": "1", "derailed": "1",
}
"""Columns of ``timeseries.parquet`` sampled at each derailment check and held until the
next (NaN before the first), and their units: the seated sprocket pins, the largest
envelope excursion and its pin, the least upper-strand pin tension and its pin at the check
(0 N and pin NaN when no pin is in the upper strand), the highest that least tension rose
over the slack window ending there (the slack check's reading, below the slack tension: it
fails), and each check's flag (1 failing, 0 passing)."""
TIMESERIES_UNITS: dict[str, str] = STEP_UNITS | DERAILMENT_UNITS
"""Every column of ``timeseries.parquet`` and its unit."""
DERAILMENT_CHECKS = ("slack_strand", "links_off_envelope", "sprocket_disengaged", "derailed")
"""The checks of the ``derailment`` table, ``derailed`` last (any of the others fails)."""
DRIVE_FIGURE = "drive.png"

MAX_DURATION_S = 3600.0
MAX_HITCH_N = 1e6
"""Largest hitch load ``trackmj drive`` takes [N] (a bound on typing errors: the track's
traction gives out far below it)."""
DERAILMENT_CHECK_S = 0.1
"""Interval of the derailment check [s]."""


@dataclass(frozen=True)
class DriveResult:
    """What a drive run produced: ``metrics`` (the metrics.json content), ``timeseries``
    (column -> (steps,) array, SI), ``out_dir`` (None when nothing was written)."""

    metrics: dict
    timeseries: dict[str, np.ndarray]
    out_dir: Path | None


def _file_tensioner(path: str | Path, stroke_m: float
                    ) -> tuple[TensionerElement, dict[str, Any], PassiveTensioner | None]:
    """The tensioner of a tensioner file on the track at ``stroke_m`` [m], what metrics.json
    says about it (an FMU: strongest coupling it offers) and the passive spring-damper if it
    is one (None for an FMU)."""
    tensioner = load_tensioner(path)
    if tensioner.fmu is not None:
        element = FmuElement(tensioner, stroke_m, "strong")
        return element, element.summary() | {"file": str(path)}, None
    t = tensioner.passive
    if t is None:
        raise ValueError(f"{path}: a tensioner file holds a [passive] or an [fmu] table")
    passive = PassiveTensioner(t.preload_N, t.stiffness_N_m, t.damping_N_s_m, t.stroke_ref_m)
    return passive, {"element": "passive", "file": str(path)}, passive


def drive(speed_m_s: float, duration_s: float, *, model: str | Path | None = None,
          mjcf: str | Path | None = None, preload_N: float | None = None,
          out_dir: str | Path | None = None,
          tensioner: str | Path | None = None, machine: str | Path | None = None,
          overrides: dict[str, Any] | None = None, hitch_pull_N: float = 0.0,
          grade: float = 0.0, stop_s: float | None = None) -> DriveResult:
    """Drive the track at ``speed_m_s`` [m/s] (ramped over min(1 s, duration/4)) for
    ``duration_s`` [s], commanded to 0 at once from ``stop_s`` [s] if given (an abrupt stop:
    the drive stops the sprocket at its torque limit, the parking brake applies once it is
    still), with the passive tensioner (its ``preload_N`` [N] if given) or the
    ``tensioner`` file's, book the energy ledger from rest and check derailment every
    :data:`DERAILMENT_CHECK_S`; write ``out_dir`` (metrics, timeseries, figure) if given.
    ``hitch_pull_N`` [N]: a horizontal load on the rear hitch, rearward (a towed load: the
    sprocket drives harder) or, < 0, forward (a push: it brakes), ramped up over twice the
    speed ramp. ``grade`` [-]: the slope driven on, tan θ (> 0 uphill driving forward):
    gravity tilted by θ as a scenario's ``[terrain] grade`` tilts it.
    ``machine``, ``model`` (a model parameter TOML replacing the machine's mechanics),
    ``overrides`` (``{dotted key: value}`` of the model file) and ``mjcf`` (an MJCF file)
    as in :func:`trackmj.machines.track_plant.load_plant`.

    Raises ValueError for a speed outside [−5, 5] m/s, a duration outside (0, 3600] s, a
    hitch load outside ±:data:`MAX_HITCH_N`, a grade outside [−1, 1] or at or past the
    ground's friction, a stop outside (0, duration) or of a standing drive,
    ParameterError for a bad tensioner file (before any work), PhysicsError if the track
    leaves physics, PhysicsError or FmuError if an FMU tensioner leaves physics or fails.
    """
    _check_drive(speed_m_s, duration_s, tensioner, preload_N, hitch_pull_N, grade, stop_s)
    plant = load_plant(mjcf, model, machine=machine, overrides=overrides)
    check_grade_held(grade, plant.params.track.ground_friction, "grade ",
                     "[track].ground_friction")
    if grade != 0.0:
        _settle_on_grade(plant, grade)
    element, described, passive = _drive_tensioner(plant, tensioner, preload_N)
    home = passive_metrics(plant, passive)
    ramp_s = min(1.0, duration_s / 4.0)
    steps = round(duration_s / COUPLING_STEP_S)
    ledger = TrackEnergyLedger(plant)
    series, checks, wall, plant_wall = _drive_loop(plant, element, ledger, speed_m_s,
                                                   ramp_s, steps, hitch_pull_N, stop_s)
    rows = [row for row, _ in checks]
    statuses = [status for _, status in checks]
    series |= derailment_columns(rows, statuses, steps)
    # the check times to 1 µs: the sum of 1 ms steps drifts in the 16th digit
    table = derailment_table([round(float(series["t_s"][row]), 6) for row in rows],
                             statuses, plant.limits)
    energy = ledger.finish()
    metrics = {
        "speed_m_s": speed_m_s, "duration_s": duration_s, "ramp_s": ramp_s, "stop_s": stop_s,
        "hitch_pull_N": hitch_pull_N, "grade": grade,
        "machine": resolve(machine).name,
        "model_file": None if model is None else str(model),
        "mjcf_file": None if mjcf is None else str(mjcf),
        "overrides": dict(overrides or {}),
        "tensioner": described,
        **home,
        "real_time_factor": duration_s / wall, "plant_real_time_factor": duration_s / plant_wall,
        "wall_time_s": wall, "host": host_machine(),
        "track_energy": energy.to_dict(),
        "steady": _steady_means(series, _steady_from_s(ramp_s, duration_s, stop_s), stop_s),
        "stop": None if stop_s is None else stop_metrics(series, stop_s),
        "max_pin_gap_m": float(series["max_pin_gap_m"].max()),
        "mujoco_warnings": plant.warning_count,
        "parked": plant.parked,
        "parking_brake_holding_N_m": (None if plant.params.parking_brake is None
                                      else plant.params.parking_brake.holding_torque_N_m),
        "integrator_created_rel": integrator_created_rel(energy.numerical_J,
                                                         energy.drive_work_J),
        **derailment_metrics(table, len(checks)),
    }
    out = write_drive(out_dir, metrics, series) if out_dir is not None else None
    return DriveResult(metrics, series, out)


def _settle_on_grade(plant: TrackPlant, grade: float) -> None:
    """Tilt ``plant``'s gravity to the ``grade`` (tan θ) and let the machine settle there
    standing for :data:`~trackmj.sim.mechanics.SETTLE_S` under the model's own passive
    tensioner (the law its level home keyframe was settled under), its clock back at 0:
    the drive then starts from rest on the slope, as a scenario's run does, not from the
    level keyframe sliding back into the tilted gravity while the sprocket ramps up. Its
    slack window starts with the drive, as on level ground."""
    plant.model.opt.gravity[:] = gravity_on_grade(plant.model.opt.gravity, grade)
    plant.run(PassiveTensioner.from_params(plant.params), SETTLE_S)
    plant.time_s = 0.0
    plant.clear_slack_window()


INTEGRATOR_CREATION_MAX_REL = 0.03
"""The most net energy the integrator may create, as a share of the drive work, before a
drive counts as unhealthy (assumed: the shipped machines' net numerical term stays within
−3.1..+2.9 % up to 1.75 m/s; compact3's +8.7 % at 2.0 m/s and a 1.5 t crawler's +10 % at
1.5 m/s are the 1 ms step pumping the pins' soft rows, models/README.md "The net
numerical term against speed")."""


def integrator_created_rel(numerical_J: float, drive_work_J: float) -> float:
    """The integrator's net energy over the drive work [-] (> 0: created); NaN without
    drive work (standing, or driven backwards against the track)."""
    return numerical_J / drive_work_J if drive_work_J > 0.0 else math.nan


def _check_drive(speed_m_s: float, duration_s: float, tensioner: str | Path | None,
                 preload_N: float | None, hitch_pull_N: float, grade: float,
                 stop_s: float | None) -> None:
    """ValueError for a speed outside [−5, 5] m/s, a duration outside (0, 3600] s, a hitch
    load outside ±:data:`MAX_HITCH_N`, a grade outside [−1, 1], a stop outside (0, duration)
    or of a standing drive, or both a preload and a tensioner file."""
    if not (math.isfinite(speed_m_s) and abs(speed_m_s) <= TRACK_SPEED_MAX_M_S):
        raise ValueError(f"speed {speed_m_s!r} m/s: allowed [-{TRACK_SPEED_MAX_M_S}, "
                         f"{TRACK_SPEED_MAX_M_S}]")
    if not (math.isfinite(duration_s) and 0.0 < duration_s <= MAX_DURATION_S):
        raise ValueError(f"duration {duration_s!r} s: allowed (0, {MAX_DURATION_S}]")
    if not (math.isfinite(hitch_pull_N) and abs(hitch_pull_N) <= MAX_HITCH_N):
        raise ValueError(f"hitch pull {hitch_pull_N!r} N: allowed [-{MAX_HITCH_N:g}, "
                         f"{MAX_HITCH_N:g}]")
    if not (math.isfinite(grade) and abs(grade) <= 1.0):
        raise ValueError(f"grade {grade!r}: allowed [-1, 1] (tan θ)")
    if stop_s is not None:
        if not (math.isfinite(stop_s) and 0.0 < stop_s < duration_s):
            raise ValueError(f"stop at {stop_s!r} s: allowed (0, {duration_s:g}) s, inside "
                             "the drive's duration")
        if speed_m_s == 0.0:
            raise ValueError("a stop needs a speed to stop from (the speed is 0)")
    if tensioner is not None and preload_N is not None:
        raise ValueError("give a preload or a tensioner file, not both")


def _drive_tensioner(plant: TrackPlant, tensioner: str | Path | None, preload_N: float | None
                     ) -> tuple[TensionerElement, dict[str, Any], PassiveTensioner | None]:
    """The tensioner file's element (:func:`_file_tensioner`) or the model's passive
    tensioner (at ``preload_N`` [N] if given), what metrics.json says about it and the
    passive spring-damper if it is one (None for an FMU)."""
    if tensioner is not None:
        return _file_tensioner(tensioner, plant.stroke_m)
    passive = PassiveTensioner.from_params(plant.params)
    described = {"element": "passive", "file": "model"}
    if preload_N is not None:
        if not (math.isfinite(preload_N) and preload_N >= 0.0):
            raise ValueError(f"preload {preload_N!r} N: must be finite and >= 0")
        passive.preload_N = preload_N
    return passive, described, passive


def passive_metrics(plant: TrackPlant, passive: PassiveTensioner | None) -> dict[str, Any]:
    """What metrics.json says of a passive tensioner (nothing for an FMU): its
    ``preload_N`` [N] and the stroke it holds at, ``preload_stroke_m`` [m]; the home
    keyframe's stroke ``home_stroke_m`` [m] and the force the spring-damper gives there
    standing, ``home_idler_force_N`` [N] (the spring moves it off the preload); and
    ``home_settled``: whether the keyframe was settled under this same law (the model's own
    tensioner at its preload), so the drive starts from rest at that force."""
    if passive is None:
        return {}
    own = PassiveTensioner.from_params(plant.params)
    return {"preload_N": passive.preload_N, "preload_stroke_m": passive.stroke_ref_m,
            "home_stroke_m": plant.stroke_m,
            "home_idler_force_N": passive.standing_force_N(plant.stroke_m),
            "home_settled": passive == own}


def _drive_loop(plant: TrackPlant, element: TensionerElement, ledger: TrackEnergyLedger,
                speed_m_s: float, ramp_s: float, steps: int, hitch_pull_N: float,
                stop_s: float | None
                ) -> tuple[dict[str, np.ndarray], list[tuple[int, DerailmentStatus]], float,
                           float]:
    """``steps`` coupling steps at the ramped sprocket speed (0 from ``stop_s`` [s] on, if
    given) and hitch load, booking
    ``ledger``; returns
    the time series (column -> (steps,), :data:`STEP_UNITS`), the derailment checks (row,
    status) every :data:`DERAILMENT_CHECK_S`, the loop's and the plant steps' wall times
    [s]. PhysicsError if the track leaves physics (non-finite velocities)."""
    series = {name: np.empty(steps) for name in STEP_UNITS}
    check_every = round(DERAILMENT_CHECK_S / COUPLING_STEP_S)
    checks: list[tuple[int, DerailmentStatus]] = []
    plant_wall = ledger_wall = 0.0
    # the ledger books every MuJoCo step: inside the coupling step when it takes several
    # (its time then taken out of the plant's), after it otherwise

    def book() -> None:
        nonlocal ledger_wall
        before = time.perf_counter()
        ledger.after_step()
        ledger_wall += time.perf_counter() - before

    per_substep = book if plant.substeps > 1 else None
    start = time.perf_counter()
    for k in range(steps):
        pull = hitch_pull_N * min(1.0, plant.time_s / (2.0 * ramp_s))
        stopped = stop_s is not None and bool(_from_stop(plant.time_s, stop_s))
        command = 0.0 if stopped else speed_m_s * min(1.0, plant.time_s / ramp_s)
        plant.apply(StepInputs(command, pull, 0.0,
                               math.nan))   # no supply: the tensioner is passive or a file's
        before = time.perf_counter()
        plant.step(element, on_substep=per_substep)
        plant_wall += time.perf_counter() - before
        if per_substep is None:
            ledger.after_step()
        strands = plant.strand_tensions_N()
        row = (plant.time_s, plant.idler_force_N, plant.stroke_m, plant.stroke_velocity_m_s,
               plant.track_speed_m_s, float(plant.chassis_velocity[0]), strands.upper_N,
               strands.lower_N, plant.closure_error_m, plant.drive_torque_N_m, pull)
        for column, value in zip(series.values(), row, strict=True):
            column[k] = value
        if (k + 1) % check_every == 0:
            checks.append((k, plant.derailment()))
        if not np.isfinite(plant.data.qvel).all():
            raise PhysicsError(f"drive: the track left physics at t = {plant.time_s:.3f} s "
                               f"(non-finite velocities; MuJoCo warnings "
                               f"{plant.warning_count})")
    return series, checks, time.perf_counter() - start, plant_wall - ledger_wall


def derailment_columns(rows: Sequence[int], statuses: Sequence[DerailmentStatus],
                       steps: int) -> dict[str, np.ndarray]:
    """The :data:`DERAILMENT_UNITS` columns, shape (steps,): each check's value (``statuses``
    at the step indices ``rows``, ascending) held from its row to the next check's, NaN
    before the first."""
    values = {name: np.empty(len(statuses)) for name in DERAILMENT_UNITS}
    for i, s in enumerate(statuses):
        slackest = s.min_upper_strand_pin if s.min_upper_strand_pin >= 0 else math.nan
        row = (s.seated_pins, s.max_envelope_excursion_m, s.worst_envelope_pin,
               s.min_upper_strand_tension_N, slackest, s.held_upper_strand_tension_N,
               s.sprocket_disengaged, s.links_off_envelope, s.slack_strand, s.any)
        for column, value in zip(values.values(), row, strict=True):
            column[i] = float(value)
    latest = np.searchsorted(np.asarray(rows, dtype=np.int64), np.arange(steps),
                             side="right") - 1   # the last check at or before each row
    checked = latest >= 0
    out = {}
    for name, v in values.items():
        column = np.full(steps, math.nan)
        column[checked] = v[latest[checked]]
        out[name] = column
    return out


def _fails(check: str, s: DerailmentStatus) -> bool:
    return s.any if check == "derailed" else bool(getattr(s, check))


def _severity(check: str, s: DerailmentStatus) -> float:
    """How bad ``check`` is in ``s``: the lower, the worse."""
    if check == "sprocket_disengaged":
        return s.seated_pins
    if check == "links_off_envelope":
        return -s.max_envelope_excursion_m
    if check == "slack_strand":
        return s.held_upper_strand_tension_N
    return -sum(_fails(c, s) for c in DERAILMENT_CHECKS[:-1])


def _where(check: str, s: DerailmentStatus, t_s: float) -> dict[str, Any]:
    """What ``check`` measured in ``s`` at ``t_s`` [s] and where (pins, strand, SI); the
    slack strand's: the highest its least pin tension rose over the window ending at
    ``t_s`` (``held_tension_N``, None before a full window) and, at ``t_s``, that least
    tension and its pin."""
    if check == "sprocket_disengaged":
        return {"t_s": t_s, "seated_pins": s.seated_pins}
    if check == "links_off_envelope":
        x, z = s.worst_envelope_xz_m
        return {"t_s": t_s, "excursion_m": s.max_envelope_excursion_m,
                "pin": s.worst_envelope_pin, "strand": s.worst_envelope_strand,
                "x_m": x, "z_m": z}
    if check == "slack_strand":
        return {"t_s": t_s, "held_tension_N": finite_or_null(s.held_upper_strand_tension_N),
                "tension_N": s.min_upper_strand_tension_N,
                "pin": s.min_upper_strand_pin if s.min_upper_strand_pin >= 0 else None,
                "strand": "upper"}
    return {"t_s": t_s, "failing": [c for c in DERAILMENT_CHECKS[:-1] if _fails(c, s)]}


def _thresholds(limits: DerailmentLimits) -> dict[str, tuple[str, float | None]]:
    """Each check's failing condition (words) and threshold (SI; None for ``derailed``) at
    the machine's ``limits``."""
    p = TrackPlant
    return {
        "slack_strand": (f"upper-strand min pin tension < {p.SLACK_TENSION_N:g} N at every "
                         f"{p.SLACK_SAMPLE_S * 1e3:g} ms sample for "
                         f"{p.SLACK_PERSISTENCE_S:g} s", p.SLACK_TENSION_N),
        "links_off_envelope": (f"a pin > {limits.envelope_threshold_m:.3g} m outside its "
                               f"home envelope (chassis frame; "
                               f"{DerailmentLimits.ENVELOPE_PITCHES:.3g} link pitches)",
                               limits.envelope_threshold_m),
        "sprocket_disengaged": (f"seated sprocket pins (within "
                                f"{limits.seat_tolerance_m * 1e3:.3g} mm of the pitch "
                                f"circle) < {limits.min_seated_pins}",
                                float(limits.min_seated_pins)),
        "derailed": ("any of the other checks fails", None)}


def derailment_metrics(table: dict[str, dict[str, Any]], checks: int) -> dict[str, Any]:
    """The derailment entries of metrics.json: the check interval [s], how many checks were
    made and how many had any failure, and the ``table`` (:func:`derailment_table`)."""
    return {"derailment_check_interval_s": DERAILMENT_CHECK_S, "derailment_checks": checks,
            "derailment_checks_failed": table["derailed"]["failing_checks"],
            "derailment": table}


@dataclass
class DerailmentChecks:
    """An observer of the closed loop (``trackmj.sim.loop.run_loop``): the track's
    derailment indicators every :data:`DERAILMENT_CHECK_S`, as ``trackmj drive`` checks
    them, at the end of the step they fall on; :meth:`metrics` gives metrics.json's
    derailment entries (:func:`derailment_metrics`) as a run's metrics.json reads them back
    (:func:`trackmj.results.store.metrics_as_read`: NaN where the drive's have None), so the
    run's result round-trips."""

    track: TrackPlant
    times_s: list[float] = field(default_factory=list)
    statuses: list[DerailmentStatus] = field(default_factory=list)

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        if (k + 1) % round(DERAILMENT_CHECK_S / COUPLING_STEP_S) == 0:
            self.times_s.append(round(readout.t_s, 6))
            self.statuses.append(self.track.derailment())

    def metrics(self) -> dict[str, Any]:
        return metrics_as_read(derailment_metrics(
            derailment_table(self.times_s, self.statuses, self.track.limits),
            len(self.statuses)))


def derailment_table(times_s: Sequence[float], statuses: Sequence[DerailmentStatus],
                     limits: DerailmentLimits) -> dict[str, dict[str, Any]]:
    """The ``derailment`` table of metrics.json, one entry per check
    (:data:`DERAILMENT_CHECKS`) of the ``statuses`` taken at ``times_s`` [s]: its failing
    condition (``fails_when``, ``threshold`` SI; the slack strand's window ``window_s``
    [s], the sprocket's ``seat_tolerance_m`` [m]), ``failing_checks`` (how many checks
    failed), ``first_s`` and ``last_s`` (None when it never failed), what it measured and
    where at its first failure (``at_first``, None when it never failed) and at its worst
    over every check, passing or failing (``worst``: the margin of a healthy run; None
    with no check), against the machine's ``limits``."""
    table = {}
    conditions = _thresholds(limits)
    extras = {"slack_strand": {"window_s": TrackPlant.SLACK_PERSISTENCE_S},
              "sprocket_disengaged": {"seat_tolerance_m": limits.seat_tolerance_m}}
    for check in DERAILMENT_CHECKS:
        words, threshold = conditions[check]
        failing = [i for i, s in enumerate(statuses) if _fails(check, s)]
        worst = (min(range(len(statuses)), key=lambda i: _severity(check, statuses[i]))
                 if statuses else None)
        table[check] = {
            "fails_when": words, "threshold": threshold, **extras.get(check, {}),
            "failing_checks": len(failing),
            "first_s": times_s[failing[0]] if failing else None,
            "last_s": times_s[failing[-1]] if failing else None,
            "at_first": (_where(check, statuses[failing[0]], times_s[failing[0]])
                         if failing else None),
            "worst": None if worst is None else _where(check, statuses[worst],
                                                       times_s[worst])}
    return table


def _steady_from_s(ramp_s: float, duration_s: float, stop_s: float | None) -> float:
    """Start [s] of the steady window: 1 s after the ramp if the drive (to its stop, if
    any) lasts longer than that, else 0."""
    end = duration_s if stop_s is None else stop_s
    return ramp_s + 1.0 if end > ramp_s + 1.0 else 0.0


def _steady_means(series: dict[str, np.ndarray], from_s: float, to_s: float | None
                  ) -> dict[str, float]:
    """Mean, min and max of the force and tension columns, and the means of speeds, stroke
    and drive torque, from ``from_s`` [s] to ``to_s`` [s] (the end if None)."""
    t = series["t_s"]
    keep = (t >= from_s) & (t < to_s) if to_s is not None else t >= from_s
    out: dict[str, float] = {"from_s": from_s}
    for name in ("idler_force_N", "upper_strand_tension_N", "lower_strand_tension_N"):
        values = series[name][keep]
        out |= {f"{name[:-2]}_mean_N": float(values.mean()),
                f"{name[:-2]}_min_N": float(values.min()),
                f"{name[:-2]}_max_N": float(values.max())}
    out["vehicle_speed_mean_m_s"] = float(series["vehicle_speed_m_s"][keep].mean())
    out["stroke_mean_m"] = float(series["stroke_m"][keep].mean())
    out["drive_torque_mean_N_m"] = float(series["drive_torque_N_m"][keep].mean())
    out["track_speed_mean_m_s"] = float(series["track_speed_m_s"][keep].mean())
    return out


STILL_M_S = TrackPlant.BRAKE_APPLY_SPEED_M_S
"""What counts as still after a stop [m/s]: the parking brake's own threshold on the
sprocket's pitch speed, applied to the hull too."""


def _from_stop(t_s: ArrayLike, stop_s: float) -> np.ndarray:
    """Whether each time ``t_s`` [s] on the 1 ms step grid is at or after ``stop_s`` [s],
    robust to the grid's rounding (half a step of slack)."""
    return np.asarray(t_s) >= stop_s - 0.5 * COUPLING_STEP_S


def stop_metrics(series: Mapping[str, np.ndarray], stop_s: float) -> dict[str, float]:
    """What an abrupt stop at ``stop_s`` [s] did: the idler force's peak [N] and the drive
    torque's largest magnitude, signed [N·m], after it; how long after it the sprocket's
    pitch speed and the hull's speed fell below :data:`STILL_M_S` for good [s]
    (:func:`~trackmj.results.signals.settling_time`: the last exit interpolated, NaN if they
    were still moving at the end); the hull's rebound, its speed the most against the
    travel before the stop [m/s] (≤ 0; 0 if it never reversed)."""
    t = series["t_s"]
    after = _from_stop(t, stop_s)   # from the row at the stop instant (the last step's end)
    hull, sprocket = series["vehicle_speed_m_s"], series["track_speed_m_s"]
    travel = np.sign(hull[~after][-1]) if (~after).any() else 0.0
    torque = series["drive_torque_N_m"][after]
    return {"idler_force_max_N": float(series["idler_force_N"][after].max()),
            "drive_torque_extreme_N_m": float(torque[np.argmax(np.abs(torque))]),
            "sprocket_still_after_s": settling_time(t, sprocket, 0.0, stop_s,
                                                    band_abs=STILL_M_S),
            "hull_still_after_s": settling_time(t, hull, 0.0, stop_s, band_abs=STILL_M_S),
            "hull_rebound_m_s": float(min(0.0, np.min(travel * hull[after])))}


def write_drive(out_dir: str | Path, metrics: Mapping[str, Any],
                series: Mapping[str, np.ndarray]) -> Path:
    """Write metrics.json, timeseries.parquet and the figure (:data:`DRIVE_FIGURE`) into
    ``out_dir`` as a whole, the same way a run's result directory is written
    (:class:`trackmj.results.store.ResultWriter`: staged, locked and swapped in); strict
    JSON, a number that is not finite written as null (standing, or braking down a grade,
    there is no drive work to relate the integrator's energy to)."""
    fields = [pa.field(name, pa.float64(), metadata={"unit": TIMESERIES_UNITS[name]})
              for name in series]
    table = pa.Table.from_arrays([pa.array(v) for v in series.values()],
                                 schema=pa.schema(fields))
    with ResultWriter(out_dir) as writer:
        return writer.commit_files(
            {"timeseries.parquet": parquet_bytes(table),
             "metrics.json": (json.dumps(finite_or_null(metrics), indent=2, allow_nan=False)
                              + "\n").encode()},
            extras={DRIVE_FIGURE: lambda path: drive_figure(metrics, series, path)})
