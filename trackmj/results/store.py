"""Run results: the timeseries table, and result directories written whole or not at all.

Timeseries contract of a closed-loop run (SI; each column's unit in its Arrow field metadata
under ``unit``), in this order (:data:`COLUMN_UNITS`):

    t_s [s], tension_N [N] (F_ten, cylinder force on the idler carrier), tension_ref_N [N],
    p_head_Pa, p_rod_Pa, p_supply_Pa [Pa gauge], stroke_m [m], stroke_velocity_m_s [m/s],
    q_supply_m3_s [m³/s], valve_mode (int8: −1 release, 0 hold, +1 pressurize), u [-],
    e_supply_J (cumulative supply energy), p_work_J (cumulative ∫Σp·A·v dt),
    mech_work_J (cumulative ∫F·v dt) [J], chassis_acc_z_m_s2 [m/s²], closure_error_m [m];

NaN where an architecture has no such quantity. Table metadata (strings): scenario,
architecture, controller, estimator, seed, trackmj_version, machine (the crawler's
name), host (the computer), plus extras.

Result directory (:class:`ResultWriter`, :func:`write_result`; read by :func:`read_result`):

- ``timeseries.parquet``: the table, units in the column metadata;
- ``timeseries.csv`` (optional): one header row of column names, then the rows (plain CSV
  for any reader); the units are in ``units.json``;
- ``units.json``: column name -> unit of the timeseries;
- ``metrics.json``: ``{"run": {table metadata}, "metrics": {name: value}}``; values are
  numbers or tables (nested objects); non-finite numbers are written as ``null`` and read
  back as NaN;
- whatever the writer of the run adds (figures, ``run.rrd``).

A directory is replaced whole: everything is staged in a hidden sibling directory and
swapped in with one atomic exchange (Linux ``renameat2(RENAME_EXCHANGE)``; elsewhere two
renames), so the directory always holds one complete run, never a mix of two. A lock file
beside the directory (``.NAME.lock``, :class:`LockFile`) refuses a second writer for as long
as the first one runs and is removed when it finishes; an interrupted run (exception,
Ctrl-C) leaves the previous result untouched.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import importlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from trackmj.host import machine as describe_machine
from trackmj.io import current_umask
from trackmj.ports import COLUMN_UNITS
from trackmj.version import __version__

INT_COLUMNS = {"valve_mode": pa.int8()}
NUMPY_TYPES = {pa.float64(): np.float64, pa.int8(): np.int8}
RUN_KEYS = ("scenario", "architecture", "controller", "estimator", "seed", "trackmj_version",
            "machine")
TIMESERIES = "timeseries.parquet"
CSV = "timeseries.csv"
UNITS = "units.json"
METRICS = "metrics.json"


class ResultDirectoryError(OSError):
    """An output directory cannot take a result (a file, not writable, someone else's
    directory, or locked by another writer); the message says which and why."""


def _arrow_array(values: np.ndarray, dtype: pa.DataType) -> pa.Array:
    """1-D numpy array as an Arrow array of ``dtype`` (NaN stays a value, not a null).

    Built from the array's buffer rather than with ``pa.array``, which imports pandas when
    it is installed (~0.5 s on the first run of every process, e.g. each Dask worker)."""
    values = np.ascontiguousarray(values, dtype=NUMPY_TYPES[dtype])
    if values.ndim != 1:
        raise ValueError(f"columns are 1-D, got shape {values.shape}")
    return pa.Array.from_buffers(dtype, len(values), [None, pa.py_buffer(values)])


def _numpy(column: pa.ChunkedArray) -> np.ndarray:
    """A column as a read-only numpy view of its buffer (float64 and int8 without nulls;
    anything else through ``to_numpy``, which imports pandas when it is installed)."""
    array = column.combine_chunks()
    dtype = NUMPY_TYPES.get(array.type)
    if dtype is None or array.null_count:
        return array.to_numpy(zero_copy_only=False)
    view = np.frombuffer(array.buffers()[1], dtype=dtype, count=len(array),
                         offset=array.offset * np.dtype(dtype).itemsize)
    view.flags.writeable = False
    return view


def make_table(columns: Mapping[str, np.ndarray], units: Mapping[str, str],
               metadata: Mapping[str, Any]) -> pa.Table:
    """Arrow table from 1-D arrays of equal length with ``units[name]`` in each field's metadata.

    Columns named in :data:`COLUMN_UNITS` come first in its order, the others after them in
    the order given; every column needs a unit. Columns are float64 except ``valve_mode``
    (int8). Metadata values are stored as strings.
    """
    no_unit = [c for c in columns if c not in units]
    if no_unit:
        raise ValueError(f"column(s) {no_unit} need a unit")
    order = [c for c in COLUMN_UNITS if c in columns] + [c for c in columns
                                                          if c not in COLUMN_UNITS]
    arrays, fields = [], []
    for name in order:
        dtype = INT_COLUMNS.get(name, pa.float64())
        values = np.asarray(columns[name])
        if dtype == pa.int8():
            values = np.rint(values).astype(np.int8)
        arrays.append(_arrow_array(values, dtype))
        fields.append(pa.field(name, dtype, metadata={"unit": units[name]}))
    meta = {str(k): str(v) for k, v in metadata.items()}
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=meta))


def run_metadata(scenario: str, architecture: str, controller: str, estimator: str, seed: int,
                 host: str | None = None, *, machine: str, **extra: Any) -> dict[str, str]:
    """Table metadata of a run: ``machine`` is the crawler's name (``lf1352``), ``host`` the
    computer that ran it (default :func:`trackmj.host.machine`); extras that are not strings
    are stored as JSON."""
    if host is None:
        host = describe_machine()
    meta = {"scenario": scenario, "architecture": architecture, "controller": controller,
            "estimator": estimator, "seed": str(int(seed)), "trackmj_version": __version__,
            "machine": machine, "host": host}
    return meta | {k: v if isinstance(v, str) else json.dumps(v, sort_keys=True)
                   for k, v in extra.items()}


def running_text(running: Mapping[str, Any] | None) -> str:
    """How a run's track ran, in words for titles and summaries (a run's ``running``
    record, :meth:`trackmj.scenarios.resolved.Scenario.running`): "" driving forward on
    level ground; else ", reversing at 1.5 m/s", ", forward and back (speed from a file)",
    ", on a grade of +0.2 (tan θ, uphill forward)"."""
    if not running:
        return ""
    parts = []
    speed, (back, ahead) = running.get("speed_m_s"), running.get("travel_m") or (0.0, 0.0)
    if speed is not None and speed < 0.0:
        parts.append(f"reversing at {-speed:g} m/s")
    elif speed is None and back < 0.0:
        parts.append("forward and back (speed from a file)" if ahead > 0.0
                     else "reversing (speed from a file)")
    grade = running.get("grade") or 0.0
    if grade:
        parts.append(f"on a grade of {grade:+g} (tan θ, {'up' if grade > 0 else 'down'}hill "
                     "forward)")
    return "".join(f", {p}" for p in parts)


def preload_text(preload_N: float, stroke_ref_m: float, settled_N: float,
                 stroke_m: float, settled: str = "settled") -> str:
    """"preload 40 kN at the layout stroke 80.0 mm; settled 13.81 kN at 88.7 mm": the
    passive tensioner's preload [N] where it holds (``stroke_ref_m`` [m]) beside the idler
    force [N] at the home stroke [m], which the spring moves off the preload."""
    return (f"preload {preload_N / 1e3:.3g} kN at the layout stroke {stroke_ref_m * 1e3:.1f} "
            f"mm; {settled} {settled_N / 1e3:.2f} kN at {stroke_m * 1e3:.1f} mm")


def passive_text(metrics: Mapping[str, Any]) -> str:
    """A drive's passive tensioner in words (its metrics.json, which holds ``preload_N``):
    :func:`preload_text` with the home keyframe's force called "settled" when the keyframe
    was settled under this law, else "at home"; the preload alone for a drive made before
    metrics.json held the home stroke."""
    if "home_idler_force_N" not in metrics:
        return f"preload {metrics['preload_N'] / 1e3:g} kN"
    return preload_text(metrics["preload_N"], metrics["preload_stroke_m"],
                        metrics["home_idler_force_N"], metrics["home_stroke_m"],
                        "settled" if metrics["home_settled"] else "at home")


def running_of(result: Result) -> dict[str, Any] | None:
    """The ``running`` record of a run's metadata (None for runs made before it)."""
    try:
        return json.loads(result.metadata["running"])
    except (KeyError, json.JSONDecodeError):
        return None


def _require(module: str, what: str, install: str) -> Any:
    """Import optional ``module`` for ``what``; ImportError saying what to install."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ImportError(f"{what} needs {module}, an optional dependency: "
                          f"pip install '{install}'") from None


@dataclass(repr=False)
class Result:
    """One run: ``timeseries`` (Arrow table, contract above) and ``metrics`` (name -> value
    or table; names carry their units). Run identity is read from the table metadata."""

    timeseries: pa.Table
    metrics: dict[str, Any] = field(default_factory=dict)

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

    def __repr__(self) -> str:
        meta, rows = self.metadata, self.timeseries.num_rows
        rmse = self.metrics.get("rmse_N")
        tail = f", rmse_N={rmse:.4g}" if isinstance(rmse, float) else ""
        return (f"Result({meta.get('scenario', '?')} {meta.get('architecture', '?')} "
                f"{meta.get('controller', '?')}/{meta.get('estimator', '?')} seed "
                f"{meta.get('seed', '?')}, {rows} rows x {self.timeseries.num_columns} columns"
                f", {len(self.metrics)} metrics{tail})")

    def to_pandas(self) -> Any:
        """The timeseries as a :class:`pandas.DataFrame` (needs ``pip install
        'trackmj[pandas]'``).

        Returns
        -------
        pandas.DataFrame
            One row per 1 ms step, the contract columns in SI; ``df.attrs["units"]`` maps
            each column to its unit, ``df.attrs["run"]`` holds the run metadata (scenario,
            architecture, controller, estimator, seed, ...) and ``df.attrs["metrics"]``
            the metrics.
        """
        _require("pandas", "Result.to_pandas()", "'trackmj[pandas]'")
        frame = self.timeseries.to_pandas()
        frame.attrs["units"] = self.units
        frame.attrs["run"] = self.metadata
        frame.attrs["metrics"] = dict(self.metrics)
        return frame

    def to_polars(self) -> Any:
        """The timeseries as a :class:`polars.DataFrame` (needs ``pip install
        'trackmj[polars]'``);
        polars keeps no units on a frame: they are :attr:`units`."""
        polars = _require("polars", "Result.to_polars()", "'trackmj[polars]'")
        return polars.from_arrow(self.timeseries)

    def columns(self) -> dict[str, np.ndarray]:
        """Column name -> numpy array (e.g. for :func:`trackmj.results.metrics.compute_metrics`);
        read-only views of the table's buffers."""
        return {n: _numpy(self.timeseries.column(n)) for n in self.timeseries.column_names}


# ----------------------------------------------------------------------------- writing

def parquet_bytes(table: pa.Table) -> bytes:
    """``table`` as a zstd-compressed Parquet file (its field metadata, e.g. units, kept)."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    return sink.getvalue().to_pybytes()


def _csv_bytes(table: pa.Table) -> bytes:
    sink = pa.BufferOutputStream()
    pacsv.write_csv(table, sink, pacsv.WriteOptions(quoting_style="none"))
    return sink.getvalue().to_pybytes()


def _json_ready(value: Any) -> Any:
    """Metrics as JSON: non-finite numbers -> None, tables recursively, numpy scalars -> float."""
    if isinstance(value, Mapping):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_json_ready(v) for v in value]
    if isinstance(value, str | bool) or value is None:
        return value
    number = float(value)
    return number if math.isfinite(number) else None


def finite_or_null(value: Any) -> Any:
    """``value`` for strict JSON: a float that is not finite becomes None, tables and lists
    recursively; integers (pin indices, counts) stay integers."""
    if isinstance(value, Mapping):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_null(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def metrics_as_read(value: Any) -> Any:
    """Metrics as :func:`read_result` reads them from JSON: null (a non-finite number, or
    None) -> NaN, numbers -> float, tables recursively."""
    if isinstance(value, dict):
        return {k: metrics_as_read(v) for k, v in value.items()}
    if isinstance(value, list):
        return [metrics_as_read(v) for v in value]
    if value is None:
        return math.nan
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else value


NUMERIC_METADATA = {"seed": int, "duration_s": float}
"""Run metadata written as numbers in metrics.json (the Arrow metadata holds strings)."""


def _metadata_value(key: str, text: str) -> Any:
    if text.startswith("{"):
        return json.loads(text)
    kind = NUMERIC_METADATA.get(key)
    if kind is not None:
        try:
            return kind(text)
        except ValueError:
            return text
    return text


def metrics_json(result: Result) -> str:
    """The text of ``metrics.json`` for ``result``; metadata stored as JSON objects (e.g. the
    files and overrides of the run) are written as objects, the seed and the duration
    (:data:`NUMERIC_METADATA`) as numbers."""
    run = {k: _metadata_value(k, v) for k, v in result.metadata.items()}
    return json.dumps({"run": run, "metrics": _json_ready(result.metrics)},
                      indent=2, sort_keys=True, allow_nan=False) + "\n"


def _write(path: Path, payload: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(payload)
        fh.flush()
        os.fsync(fh.fileno())


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap directories ``a`` and ``b`` (Linux renameat2); False if unsupported."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def check_output_dir(out: Path, marker: str = METRICS) -> Path:
    """``out`` resolved, or ResultDirectoryError if it cannot take a result: an existing file,
    a directory that holds something other than a trackmj result (no ``marker`` file in it),
    or a parent that cannot be created or written. Nothing is created but the parent
    directories."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ResultDirectoryError(f"--out {out}: is a file, not a directory")
    if out.is_dir() and any(out.iterdir()) and not (out / marker).is_file():
        raise ResultDirectoryError(f"--out {out}: an existing directory that holds no trackmj "
                                   f"result ({marker} missing); refusing to replace it")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ResultDirectoryError(f"--out {out}: cannot create {out.parent}: "
                                   f"{exc.strerror}") from None
    if not os.access(out.parent, os.W_OK | os.X_OK):
        raise ResultDirectoryError(f"--out {out}: {out.parent} is not writable")
    return out


class LockFile:
    """An exclusive lock held on the file ``path`` (``flock``), which exists only while it
    is held: :meth:`acquire` creates it, :meth:`release` removes it, so a finished folder
    holds no lock files (a killed holder leaves one behind, which the next holder takes
    over and removes).

    The race of removing a lock file: the holder unlinks the path while it still holds the
    lock, then unlocks. A process that opened the old file before the unlink and gets its
    lock after it holds a file that ``path`` no longer names; :meth:`acquire` sees that
    (the path is gone or is another inode) and opens the path again. So two holders never
    both hold what ``path`` names.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._fh: IO[str] | None = None

    def acquire(self) -> bool:
        """Take the lock without waiting; False if another holder (another process, or
        another LockFile in this one) has it."""
        if self._fh is not None:
            raise RuntimeError(f"{self.path}: already held")
        while True:
            fh = open(self.path, "a")   # held until release
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                if self._names(fh):
                    self._fh = fh
                    return True
            except BlockingIOError:
                fh.close()
                return False
            except BaseException:
                fh.close()
                raise
            fh.close()   # its holder removed it as we waited: open what the path names now

    def _names(self, fh: IO[str]) -> bool:
        """Whether ``path`` still names the file ``fh`` has open."""
        try:
            on_disk = os.stat(self.path)
        except FileNotFoundError:
            return False
        mine = os.fstat(fh.fileno())
        return (on_disk.st_dev, on_disk.st_ino) == (mine.st_dev, mine.st_ino)

    def release(self) -> None:
        """Remove the lock file, then unlock it (nothing if not held)."""
        fh, self._fh = self._fh, None
        if fh is None:
            return
        try:
            if self._names(fh):
                self.path.unlink()
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
            fh.close()


class ResultWriter:
    """Writes one result directory whole: ``with ResultWriter(out) as w:`` takes the lock and
    a staging directory ``w.stage`` (a run may write e.g. its Rerun recording there while it
    runs); ``w.commit(result, ...)`` writes the result files into the stage and swaps it in.
    Leaving the block without a commit (an exception, Ctrl-C) removes the stage and leaves
    ``out`` as it was. A second writer of the same ``out`` is refused while the lock is held.
    ``marker``: the file that marks an existing ``out`` as a trackmj result it may replace.
    """

    def __init__(self, out: str | Path, marker: str = METRICS) -> None:
        self.out = check_output_dir(Path(out), marker)
        self.stage: Path | None = None
        self.committed = False
        self._lock: LockFile | None = None

    def __enter__(self) -> ResultWriter:
        out = self.out
        lock = LockFile(out.parent / f".{out.name}.lock")   # held until __exit__
        if not lock.acquire():
            raise ResultDirectoryError(
                f"--out {out}: another trackmj process is writing this directory; wait for it "
                "or choose another --out")
        self._lock = lock
        try:
            for stale in out.parent.glob(f".{out.name}.stage-*"):  # left by a killed writer
                shutil.rmtree(stale, ignore_errors=True)
            self.stage = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.stage-"))
        except BaseException:
            self.__exit__()
            raise
        return self

    def commit(self, result: Result, *, csv: bool = False,
               extras: Mapping[str, Callable[[Path], Any]] | None = None) -> Path:
        """Write ``result`` (parquet, units, metrics, optional CSV) and each ``extras`` entry
        (file name -> writer(path)) into the stage, then swap the stage in as ``out``."""
        table = result.timeseries
        files = {TIMESERIES: parquet_bytes(table),
                 UNITS: (json.dumps(result.units, indent=2) + "\n").encode()}
        if csv:
            files[CSV] = _csv_bytes(table)
        files[METRICS] = metrics_json(result).encode()
        return self.commit_files(files, extras=extras)

    def commit_files(self, files: Mapping[str, bytes], *,
                     extras: Mapping[str, Callable[[Path], Any]] | None = None) -> Path:
        """Write ``files`` (file name -> contents, each fsynced) and each ``extras`` entry
        (file name -> writer(path)) into the stage, then swap the stage in as ``out``."""
        stage = self.stage
        if stage is None or self.committed:
            raise RuntimeError("commit() needs an open, uncommitted ResultWriter")
        for name, payload in files.items():
            _write(stage / name, payload)
        for name, writer in (extras or {}).items():
            writer(stage / name)
        os.chmod(stage, 0o777 & ~current_umask())
        if not self.out.exists():
            os.rename(stage, self.out)
        elif _exchange(stage, self.out):
            shutil.rmtree(stage)   # now the previous result
        else:
            old = stage.with_name(stage.name + ".old")
            os.rename(self.out, old)
            os.rename(stage, self.out)
            shutil.rmtree(old)
        self.committed = True
        self.stage = None
        return self.out

    def __exit__(self, *exc: object) -> None:
        if self.stage is not None:
            shutil.rmtree(self.stage, ignore_errors=True)
            self.stage = None
        if self._lock is not None:
            self._lock.release()
            self._lock = None


def write_result(result: Result, out_dir: str | Path, *, csv: bool = False,
                 extras: Mapping[str, Callable[[Path], Any]] | None = None) -> Path:
    """Write ``result`` as the whole directory ``out_dir`` (see :class:`ResultWriter`)."""
    with ResultWriter(out_dir) as writer:
        return writer.commit(result, csv=csv, extras=extras)


def read_result(run_dir: str | Path) -> Result:
    """Read a result directory written by :func:`write_result` (``trackmj run --out``).

    Parameters
    ----------
    run_dir : str or Path
        The directory; it holds ``metrics.json`` and ``timeseries.parquet`` (see the module
        docstring for the layout).

    Returns
    -------
    Result
        The timeseries with its units and run metadata (``result.units``,
        ``result.metadata``) and the metrics; non-finite metrics (``null`` in the JSON)
        come back as NaN.

    Raises
    ------
    FileNotFoundError
        ``metrics.json`` or ``timeseries.parquet`` is missing (an incomplete directory).

    Notes
    -----
    Other tools read the same files directly: ``pandas.read_parquet(run_dir /
    "timeseries.parquet")``, or the optional plain CSV ``pandas.read_csv(run_dir /
    "timeseries.csv")`` (one header row; the units are in ``units.json``, never in the
    CSV, so any CSV reader sees numbers only).
    """
    run_dir = Path(run_dir)
    if not (run_dir / METRICS).is_file():
        raise FileNotFoundError(f"{run_dir}: no {METRICS}; not a complete result directory")
    if not (run_dir / TIMESERIES).is_file():
        raise FileNotFoundError(f"{run_dir}: no {TIMESERIES}; not a complete result "
                                "directory")
    doc = json.loads((run_dir / METRICS).read_text())
    table = pq.read_table(run_dir / TIMESERIES)
    return Result(timeseries=table, metrics=metrics_as_read(doc["metrics"]))
