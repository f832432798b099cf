"""Run results: the 1 kHz timeseries table, its recorder, and the on-disk format.

Timeseries contract (SI; each column's unit in its Arrow field metadata under ``unit``):

    t_s [s], tension_N [N] (F_ten, cylinder force on the idler carrier), tension_ref_N [N],
    p_head_Pa, p_rod_Pa, p_supply_Pa [Pa gauge], stroke_m [m], stroke_velocity_m_s [m/s],
    q_supply_m3_s [m³/s], valve_mode (int8: −1 release, 0 hold, +1 pressurize), u [-],
    e_supply_J (cumulative supply energy), p_work_J (cumulative ∫Σp·A·v dt),
    mech_work_J (cumulative ∫F·v dt) [J], chassis_acc_z_m_s2 [m/s²];

plus optional extra columns with their units. Table metadata (strings): scenario,
architecture, controller, estimator, seed, trackmj_version, machine, plus any extras.

Result directory (written by :func:`write_result`, read by :func:`read_result`):

- ``timeseries.parquet``: the table, units in the column metadata;
- ``timeseries.csv`` (optional): first line ``# units: s,N,...`` (one unit per column, same
  order), then a header of column names, then the rows; read it with a CSV reader that
  skips ``#`` comment lines;
- ``metrics.json``: ``{"run": {table metadata}, "metrics": {name: value}}``; non-finite
  metric values are written as ``null`` and read back as NaN.

Writing is all-or-nothing: the files are staged in a temporary sibling directory and moved
into place, ``metrics.json`` last; a failure leaves no partial output.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from trackmj import __version__
from trackmj.io import write_bytes_atomic, write_text_atomic

COLUMN_UNITS: dict[str, str] = {
    "t_s": "s",
    "tension_N": "N",
    "tension_ref_N": "N",
    "p_head_Pa": "Pa",
    "p_rod_Pa": "Pa",
    "p_supply_Pa": "Pa",
    "stroke_m": "m",
    "stroke_velocity_m_s": "m/s",
    "q_supply_m3_s": "m^3/s",
    "valve_mode": "1",
    "u": "1",
    "e_supply_J": "J",
    "p_work_J": "J",
    "mech_work_J": "J",
    "chassis_acc_z_m_s2": "m/s^2",
}
"""Contract columns in order, with their units ("1": dimensionless)."""

INT_COLUMNS = {"valve_mode": pa.int8()}
RUN_KEYS = ("scenario", "architecture", "controller", "estimator", "seed", "trackmj_version",
            "machine")
TIMESERIES = "timeseries.parquet"
CSV = "timeseries.csv"
METRICS = "metrics.json"


def make_table(columns: Mapping[str, np.ndarray], units: Mapping[str, str],
               metadata: Mapping[str, Any]) -> pa.Table:
    """Arrow table from 1-D arrays of equal length with ``units[name]`` in each field's metadata.

    All contract columns (:data:`COLUMN_UNITS`) are required; extras need a unit. Columns
    are float64 except ``valve_mode`` (int8). ``metadata`` needs :data:`RUN_KEYS`; values
    are stored as strings.
    """
    missing = [c for c in COLUMN_UNITS if c not in columns]
    if missing:
        raise ValueError(f"timeseries lacks contract column(s) {missing}")
    no_unit = [c for c in columns if c not in units and c not in COLUMN_UNITS]
    if no_unit:
        raise ValueError(f"extra column(s) {no_unit} need a unit")
    absent = [k for k in RUN_KEYS if k not in metadata]
    if absent:
        raise ValueError(f"run metadata lacks {absent}")
    order = list(COLUMN_UNITS) + [c for c in columns if c not in COLUMN_UNITS]
    arrays, fields = [], []
    for name in order:
        dtype = INT_COLUMNS.get(name, pa.float64())
        values = np.asarray(columns[name])
        if dtype == pa.int8():
            values = np.rint(values).astype(np.int8)
        arrays.append(pa.array(values, type=dtype))
        unit = units.get(name, COLUMN_UNITS.get(name))
        fields.append(pa.field(name, dtype, metadata={"unit": unit}))
    meta = {str(k): str(v) for k, v in metadata.items()}
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=meta))


def run_metadata(scenario: str, architecture: str, controller: str, estimator: str, seed: int,
                 machine: str | None = None, **extra: Any) -> dict[str, str]:
    """Table metadata of a run; ``machine`` defaults to :func:`trackmj.machine.machine`."""
    if machine is None:
        from trackmj.machine import machine as describe

        machine = describe()
    meta = {"scenario": scenario, "architecture": architecture, "controller": controller,
            "estimator": estimator, "seed": str(int(seed)), "trackmj_version": __version__,
            "machine": machine}
    return meta | {k: str(v) for k, v in extra.items()}


class TimeseriesRecorder:
    """Preallocated per-step recorder for the timeseries contract (plus extras).

    ``rec.append(i, t_s, tension_N, ..., chassis_acc_z_m_s2, *extras)`` writes row ``i``
    (0-based, rows written in order) with the values in :attr:`columns` order, one tuple
    assignment into a preallocated (n_steps, n_columns) float64 array. :meth:`table` builds
    the Arrow table of the rows written so far.
    """

    def __init__(self, n_steps: int, extra_units: Mapping[str, str] | None = None) -> None:
        extra = dict(extra_units or {})
        clash = set(extra) & set(COLUMN_UNITS)
        if clash:
            raise ValueError(f"extra columns {sorted(clash)} clash with the contract")
        self.units: dict[str, str] = COLUMN_UNITS | extra
        self.columns: tuple[str, ...] = tuple(self.units)
        self.index: dict[str, int] = {c: k for k, c in enumerate(self.columns)}
        self.data = np.full((n_steps, len(self.columns)), np.nan)
        self.rows = 0

    def append(self, i: int, *values: float) -> None:
        """Write row ``i``: one value per column in :attr:`columns` order."""
        self.data[i] = values
        self.rows = i + 1

    def arrays(self) -> dict[str, np.ndarray]:
        """Column name -> view of the rows written, shape (rows,)."""
        return {c: self.data[: self.rows, k] for k, c in enumerate(self.columns)}

    def table(self, metadata: Mapping[str, Any]) -> pa.Table:
        """Arrow table of the rows written, with units and ``metadata`` (see run_metadata)."""
        return make_table(self.arrays(), self.units, metadata)


@dataclass
class Result:
    """One run: ``timeseries`` (Arrow table, contract above) and ``metrics`` (name -> value,
    names carry their units). Run identity is read from the table metadata."""

    timeseries: pa.Table
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def metadata(self) -> dict[str, str]:
        """Table metadata (scenario, architecture, ..., machine, extras) as strings."""
        raw = self.timeseries.schema.metadata or {}
        return {k.decode(): v.decode() for k, v in raw.items() if not k.startswith(b"ARROW:")}

    @property
    def scenario(self) -> str:
        return self.metadata["scenario"]

    @property
    def architecture(self) -> str:
        return self.metadata["architecture"]

    @property
    def controller(self) -> str:
        return self.metadata["controller"]

    @property
    def estimator(self) -> str:
        return self.metadata["estimator"]

    @property
    def seed(self) -> int:
        return int(self.metadata["seed"])

    @property
    def units(self) -> dict[str, str]:
        """Column name -> unit."""
        return {f.name: (f.metadata or {}).get(b"unit", b"").decode()
                for f in self.timeseries.schema}

    def columns(self) -> dict[str, np.ndarray]:
        """Column name -> numpy array (e.g. for :func:`trackmj.metrics.compute_metrics`)."""
        return {n: self.timeseries.column(n).to_numpy() for n in self.timeseries.column_names}


def _parquet_bytes(table: pa.Table) -> bytes:
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    return sink.getvalue().to_pybytes()


def _csv_bytes(table: pa.Table) -> bytes:
    units = [(f.metadata or {}).get(b"unit", b"").decode() for f in table.schema]
    sink = pa.BufferOutputStream()
    pacsv.write_csv(table, sink, pacsv.WriteOptions(include_header=False, quoting_style="none"))
    head = "# units: " + ",".join(units) + "\n" + ",".join(table.column_names) + "\n"
    return head.encode() + sink.getvalue().to_pybytes()


def _metrics_json(result: Result) -> str:
    clean = {k: (float(v) if math.isfinite(float(v)) else None)
             for k, v in result.metrics.items()}
    return json.dumps({"run": result.metadata, "metrics": clean}, indent=2,
                      sort_keys=True, allow_nan=False) + "\n"


def write_result(result: Result, out_dir: str | Path, *, csv: bool = False) -> Path:
    """Write ``result`` to ``out_dir`` (see the module docstring); returns the directory.

    All files are staged in a temporary sibling directory. A new ``out_dir`` appears by one
    rename; in an existing one (e.g. holding figures) the old ``metrics.json`` is removed
    first, the data files are replaced and the new ``metrics.json`` moved in last, so a
    directory with a ``metrics.json`` always holds one complete result.
    """
    out = Path(out_dir)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    try:
        names = [TIMESERIES]
        write_bytes_atomic(stage / TIMESERIES, _parquet_bytes(result.timeseries))
        if csv:
            write_bytes_atomic(stage / CSV, _csv_bytes(result.timeseries))
            names.append(CSV)
        write_text_atomic(stage / METRICS, _metrics_json(result))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(stage, 0o777 & ~umask)
        if not out.exists():
            os.rename(stage, out)
            return out
        (out / METRICS).unlink(missing_ok=True)
        if not csv:
            (out / CSV).unlink(missing_ok=True)
        for name in [*names, METRICS]:
            os.replace(stage / name, out / name)
        stage.rmdir()
        return out
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


def read_result(run_dir: str | Path) -> Result:
    """Read a result directory written by :func:`write_result`.

    FileNotFoundError if ``metrics.json`` (written last) or the Parquet file is absent.
    """
    run_dir = Path(run_dir)
    if not (run_dir / METRICS).is_file():
        raise FileNotFoundError(f"{run_dir}: no {METRICS}; not a complete result directory")
    doc = json.loads((run_dir / METRICS).read_text())
    table = pq.read_table(run_dir / TIMESERIES)
    metrics = {k: (math.nan if v is None else float(v)) for k, v in doc["metrics"].items()}
    return Result(timeseries=table, metrics=metrics)
