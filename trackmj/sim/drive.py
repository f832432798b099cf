"""The ``trackmj drive`` run: the bare track with its passive tensioner (or the tensioner of a
tensioner file: a spring-damper or an FMU) driven at a sprocket speed, with the mechanical
energy ledger (:mod:`trackmj.track.energy`) and a 1 kHz time series.

Output directory (written whole or not at all: a temporary sibling directory renamed into
place):

- ``metrics.json``: run settings, ``real_time_factor`` (simulated / wall time of the whole
  loop, ledger and recording included) and ``plant_real_time_factor`` (plant steps only),
  the machine, the ``track_energy`` table [J], steady-state means and the health counts;
- ``timeseries.parquet``: one row per 1 ms step, SI, each column's unit in its Arrow field
  metadata under ``unit`` (:data:`TIMESERIES_UNITS`).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from trackmj.elements.fmu import FmuElement
from trackmj.elements.tensioner_file import load_tensioner
from trackmj.host import machine as host_machine
from trackmj.machines.track_plant import load_plant
from trackmj.ports import COUPLING_STEP_S, TensionerElement
from trackmj.results.store import ResultWriter, parquet_bytes
from trackmj.track.energy import TrackEnergyLedger
from trackmj.track.plant import PassiveTensioner, TrackPlant

TIMESERIES_UNITS: dict[str, str] = {
    "t_s": "s", "idler_force_N": "N", "stroke_m": "m", "stroke_velocity_m_s": "m/s",
    "track_speed_m_s": "m/s", "vehicle_speed_m_s": "m/s", "upper_strand_tension_N": "N",
    "lower_strand_tension_N": "N", "max_pin_gap_m": "m",
}
"""Columns of ``timeseries.parquet`` and their units."""

MAX_SPEED_M_S = 5.0
MAX_DURATION_S = 3600.0
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
                    ) -> tuple[TensionerElement, dict[str, Any], float | None]:
    """The tensioner of a tensioner file on the track at ``stroke_m`` [m], what metrics.json
    says about it (an FMU: strongest coupling it offers) and its preload [N] if it is the
    passive spring-damper (None for an FMU)."""
    tensioner = load_tensioner(path)
    if tensioner.fmu is not None:
        element = FmuElement(tensioner, stroke_m, "strong")
        return element, element.summary() | {"file": str(path)}, None
    t = tensioner.passive
    if t is None:
        raise ValueError(f"{path}: a tensioner file holds a [passive] or an [fmu] table")
    return (PassiveTensioner(t.preload_N, t.stiffness_N_m, t.damping_N_s_m, t.stroke_ref_m),
            {"element": "passive", "file": str(path)}, t.preload_N)


def drive(speed_m_s: float, duration_s: float, *, model: str | Path | None = None,
          params: str | Path | None = None, preload_N: float | None = None,
          out_dir: str | Path | None = None,
          tensioner: str | Path | None = None, machine: str | Path | None = None,
          overrides: dict[str, Any] | None = None) -> DriveResult:
    """Drive the track at ``speed_m_s`` [m/s] (ramped over min(1 s, duration/4)) for
    ``duration_s`` [s] with the passive tensioner (its ``preload_N`` [N] if given) or the
    ``tensioner`` file's, and book the energy ledger from rest; write ``out_dir`` if given.
    ``machine``, ``params`` (a model file replacing the machine's mechanics), ``overrides``
    (``{dotted key: value}`` of the model file) and ``model`` (an MJCF file) as in
    :func:`trackmj.machines.track_plant.load_plant`.

    Raises ValueError for a speed outside [−5, 5] m/s or a duration outside (0, 3600] s,
    ParameterError for a bad tensioner file (before any work), PhysicsError or FmuError if
    an FMU tensioner leaves physics or fails.
    """
    _check_drive(speed_m_s, duration_s, tensioner, preload_N)
    plant = load_plant(model, params, machine=machine, overrides=overrides)
    element, described, passive_preload_N = _drive_tensioner(plant, tensioner, preload_N)
    ramp_s = min(1.0, duration_s / 4.0)
    steps = round(duration_s / COUPLING_STEP_S)
    ledger = TrackEnergyLedger(plant)
    series, derailed, wall, plant_wall = _drive_loop(plant, element, ledger, speed_m_s,
                                                     ramp_s, steps)
    energy = ledger.finish()
    metrics = {
        "speed_m_s": speed_m_s, "duration_s": duration_s, "ramp_s": ramp_s,
        "tensioner": described,
        **({"preload_N": passive_preload_N} if passive_preload_N is not None else {}),
        "real_time_factor": duration_s / wall, "plant_real_time_factor": duration_s / plant_wall,
        "wall_time_s": wall, "machine": host_machine(),
        "track_energy": energy.to_dict(),
        "steady": _steady_means(series, ramp_s + 1.0 if duration_s > ramp_s + 1.0 else 0.0),
        "max_pin_gap_m": float(series["max_pin_gap_m"].max()),
        "mujoco_warnings": plant.warning_count, "derailment_checks_failed": derailed,
    }
    out = write_drive(out_dir, metrics, series) if out_dir is not None else None
    return DriveResult(metrics, series, out)


def _check_drive(speed_m_s: float, duration_s: float, tensioner: str | Path | None,
                 preload_N: float | None) -> None:
    """ValueError for a speed outside [−5, 5] m/s, a duration outside (0, 3600] s or both
    a preload and a tensioner file."""
    if not (math.isfinite(speed_m_s) and abs(speed_m_s) <= MAX_SPEED_M_S):
        raise ValueError(f"speed {speed_m_s!r} m/s: allowed [-{MAX_SPEED_M_S}, "
                         f"{MAX_SPEED_M_S}]")
    if not (math.isfinite(duration_s) and 0.0 < duration_s <= MAX_DURATION_S):
        raise ValueError(f"duration {duration_s!r} s: allowed (0, {MAX_DURATION_S}]")
    if tensioner is not None and preload_N is not None:
        raise ValueError("give a preload or a tensioner file, not both")


def _drive_tensioner(plant: TrackPlant, tensioner: str | Path | None, preload_N: float | None
                     ) -> tuple[TensionerElement, dict[str, Any], float | None]:
    """The tensioner file's element (:func:`_file_tensioner`) or the model's passive
    tensioner (at ``preload_N`` [N] if given), what metrics.json says about it and its
    preload [N] (None for an FMU)."""
    if tensioner is not None:
        return _file_tensioner(tensioner, plant.stroke_m)
    passive = PassiveTensioner.from_params(plant.params)
    described = {"element": "passive", "file": "model"}
    if preload_N is not None:
        if not (math.isfinite(preload_N) and preload_N >= 0.0):
            raise ValueError(f"preload {preload_N!r} N: must be finite and >= 0")
        passive.preload_N = preload_N
    return passive, described, passive.preload_N


def _drive_loop(plant: TrackPlant, element: TensionerElement, ledger: TrackEnergyLedger,
                speed_m_s: float, ramp_s: float, steps: int
                ) -> tuple[dict[str, np.ndarray], int, float, float]:
    """``steps`` coupling steps at the ramped sprocket speed, booking ``ledger``; returns
    the time series (column -> (steps,), :data:`TIMESERIES_UNITS`), the failed derailment
    checks, the loop's and the plant steps' wall times [s]. RuntimeError if the track
    leaves physics (non-finite velocities)."""
    series = {name: np.empty(steps) for name in TIMESERIES_UNITS}
    check_every = round(DERAILMENT_CHECK_S / COUPLING_STEP_S)
    derailed = 0
    plant_wall = 0.0
    start = time.perf_counter()
    for k in range(steps):
        plant.set_track_speed(speed_m_s * min(1.0, plant.time_s / ramp_s))
        before = time.perf_counter()
        plant.step(element)
        plant_wall += time.perf_counter() - before
        ledger.after_step()
        strands = plant.strand_tensions_N()
        row = (plant.time_s, plant.idler_force_N, plant.stroke_m, plant.stroke_velocity_m_s,
               plant.track_speed_m_s, float(plant.chassis_velocity[0]), strands.upper_N,
               strands.lower_N, plant.closure_error_m)
        for column, value in zip(series.values(), row, strict=True):
            column[k] = value
        if (k + 1) % check_every == 0 and plant.derailment().any:
            derailed += 1
        if not np.isfinite(plant.data.qvel).all():
            raise RuntimeError(f"drive: the track left physics at t = {plant.time_s:.3f} s "
                               f"(non-finite velocities; MuJoCo warnings "
                               f"{plant.warning_count})")
    return series, derailed, time.perf_counter() - start, plant_wall


def _steady_means(series: dict[str, np.ndarray], from_s: float) -> dict[str, float]:
    """Mean, min and max of the force and tension columns from ``from_s`` [s] on."""
    keep = series["t_s"] >= from_s
    out: dict[str, float] = {"from_s": from_s}
    for name in ("idler_force_N", "upper_strand_tension_N", "lower_strand_tension_N"):
        values = series[name][keep]
        out |= {f"{name[:-2]}_mean_N": float(values.mean()),
                f"{name[:-2]}_min_N": float(values.min()),
                f"{name[:-2]}_max_N": float(values.max())}
    out["vehicle_speed_mean_m_s"] = float(series["vehicle_speed_m_s"][keep].mean())
    out["track_speed_mean_m_s"] = float(series["track_speed_m_s"][keep].mean())
    return out


def write_drive(out_dir: str | Path, metrics: dict, series: dict[str, np.ndarray]) -> Path:
    """Write metrics.json and timeseries.parquet into ``out_dir`` as a whole, the same way a
    run's result directory is written (:class:`trackmj.results.store.ResultWriter`: staged, locked
    and swapped in)."""
    fields = [pa.field(name, pa.float64(), metadata={"unit": TIMESERIES_UNITS[name]})
              for name in series]
    table = pa.Table.from_arrays([pa.array(v) for v in series.values()],
                                 schema=pa.schema(fields))
    with ResultWriter(out_dir) as writer:
        return writer.commit_files({
            "timeseries.parquet": parquet_bytes(table),
            "metrics.json": (json.dumps(metrics, indent=2) + "\n").encode()})
