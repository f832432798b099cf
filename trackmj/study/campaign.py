"""The campaign layer under ``report``, ``sweep`` and ``calibrate``: many runs into one
directory, each known by its identity, resumable, one row per run.

A run is known by its ``run_key``, the hash of its identity: everything that determines
its result, inputs and code (:mod:`trackmj.study.identity`).

One rule for "already done", for every campaign: a run is done when the campaign's
``results.parquet`` holds a row with its ``run_key`` (and no error, unless failed runs are
kept), and, for a campaign that needs the runs themselves (the report), its directory under
``runs/`` holds a result with that ``run_key``. A change of any input or of the code changes
the key, so the run is made again; rows of other keys are kept.

A campaign directory (:class:`Store`):

- ``campaign.json``: what kind of campaign it is (``sweep``, ``report``, ``calibrate``); a
  campaign of another kind into the same directory is refused, and so is a second campaign
  while one writes it (an exclusive lock, ``.campaign.lock``, removed when the campaign
  ends: a finished campaign directory holds no lock files);
- ``results.parquet``: one row per run, rewritten atomically as runs finish (at most every
  2 s while they do, and at the end, also after Ctrl-C or an error). Columns: the identity
  columns (:data:`IDENTITY`), one column per swept key, every scalar metric (nested metric
  tables flattened as ``table.key``), ``wall_time_s`` and ``error`` (null, or ``"Type:
  message"``). Each column's unit is in its Arrow field metadata (``unit``) and, for readers
  that drop field metadata (polars), in the schema metadata ``units`` (JSON object); plain
  Parquet types only (string, int64, float64), read as-is by pandas, polars and DuckDB;
- ``runs/<name>/``: the runs' result directories (always for the report; a sweep with
  ``keep_runs``).
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from trackmj.io import write_bytes_atomic, write_text_atomic
from trackmj.results.columns import column_unit, is_key_column
from trackmj.results.store import (
    LockFile,
    Result,
    ResultDirectoryError,
    read_result,
    write_result,
)
from trackmj.sim.setup import RunSetup, prepare
from trackmj.study.executor import Executor, RunOutcome, RunSpec
from trackmj.study.identity import run_key, stamped

RESULTS = "results.parquet"
CAMPAIGN = "campaign.json"
LOCK = ".campaign.lock"
RUNS = "runs"
WRITE_PERIOD_S = 2.0
"""results.parquet is rewritten at most this often while runs finish [s]."""
IDENTITY = ("run_key", "point", "scenario", "machine", "architecture", "controller",
            "estimator", "variant", "seed", "duration_s", "inputs")
"""Columns naming a run, first in every row (``machine``: the name in its machine file)."""
TEXT_COLUMNS = ("run_key", "scenario", "machine", "architecture", "controller", "estimator",
                "variant", "inputs", "error")


# ----------------------------------------------------------------------------- the store

def check_campaign_dir(out: str | Path, markers: Sequence[str], what: str) -> Path:
    """``out`` (created) if it can hold a ``what`` (a sweep, a report, a comparison): absent,
    empty, or holding one of ``markers`` (a previous one, which it resumes or replaces); else
    :class:`trackmj.results.store.ResultDirectoryError`, before anything runs. The one ``--out``
    guard of every campaign command."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ResultDirectoryError(f"--out {out}: is a file, not a directory")
    if out.is_dir() and any(out.iterdir()) and not any((out / m).exists() for m in markers):
        raise ResultDirectoryError(f"--out {out}: an existing directory that holds no trackmj "
                                   f"{what} ({' or '.join(markers)} missing); refusing to "
                                   "write into it")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ResultDirectoryError(f"--out {out}: cannot create it: {exc.strerror}") from None
    return out


class Store:
    """A campaign directory of kind ``kind`` (``with Store(out, "sweep") as store:``): the
    ``--out`` guard, the lock, ``campaign.json``, the rows of ``results.parquet`` and the run
    directories. ``markers``: other names that show a directory is one of this kind (e.g. a
    report written before campaign.json existed); ``what``: its name in messages; ``runs``:
    the subdirectory of the run directories ("." for the campaign directory itself);
    ``inputs_key``: for a campaign of one set of inputs (a comparison), their hash, kept in
    ``campaign.json``: a directory holding one of other inputs (or of none, an older trackmj)
    is refused unless ``overwrite``, which empties it first."""

    def __init__(self, out: str | Path, kind: str, markers: Sequence[str] = (),
                 what: str | None = None, runs: str = RUNS, inputs_key: str | None = None,
                 overwrite: bool = False) -> None:
        self.kind = kind
        self.what = what or kind
        self.inputs_key = inputs_key
        self.overwrite = overwrite
        self.out = check_campaign_dir(out, (CAMPAIGN, RESULTS, *markers), self.what)
        self.results = self.out / RESULTS
        self.runs = self.out / runs
        self._lock = LockFile(self.out / LOCK)
        self.rows: dict[str, dict[str, Any]] = {}

    def __enter__(self) -> Store:
        if not self._lock.acquire():   # held until __exit__
            raise ResultDirectoryError(f"--out {self.out}: another trackmj campaign is "
                                       "writing this directory; wait for it or choose "
                                       "another --out")
        try:
            marker = self.out / CAMPAIGN
            held = json.loads(marker.read_text()) if marker.is_file() else None
            if held is not None and held.get("kind") != self.kind:
                raise ResultDirectoryError(
                    f"--out {self.out}: holds a trackmj {held.get('kind')} ({CAMPAIGN}); "
                    f"refusing to write a {self.kind} into it (choose another --out)")
            if self._other_inputs(held):
                self._empty()
                held = None
            if held is None:
                doc = {"kind": self.kind} | ({} if self.inputs_key is None
                                             else {"inputs_key": self.inputs_key})
                write_text_atomic(marker, json.dumps(doc) + "\n")
            self.rows = {row["run_key"]: row for row in read_rows(self.results)}
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self._lock.release()

    def _other_inputs(self, held: dict[str, Any] | None) -> bool:
        """Whether the directory holds a campaign of inputs other than :attr:`inputs_key`
        (``held``: its campaign.json, None without one); ResultDirectoryError if so, unless
        :attr:`overwrite`. Only for a campaign of one set of inputs."""
        if self.inputs_key is None or not self._entries():
            return False
        key = "" if held is None else str(held.get("inputs_key", ""))
        if key == self.inputs_key:
            return False
        if not self.overwrite:
            what = f"inputs {key[:8]}" if key else "no inputs key: an older trackmj"
            raise ResultDirectoryError(
                f"--out {self.out}: holds a {self.what} of other inputs ({what}; this one's "
                f"are {self.inputs_key[:8]}); give --overwrite to replace it, or another --out")
        return True

    def _entries(self) -> list[Path]:
        """What the directory holds besides the lock file."""
        return [p for p in self.out.iterdir() if p != self._lock.path]

    def _empty(self) -> None:
        """Remove what the directory holds (a campaign of other inputs, ``--overwrite``)."""
        for path in self._entries():
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()

    def run_dir(self, run: PlannedRun) -> Path:
        return self.runs / run.name

    def stored_result(self, run: PlannedRun) -> Result | None:
        """The result under ``runs/`` of ``run`` if its directory holds one with the same
        ``run_key``; else None."""
        try:
            result = read_result(self.run_dir(run))
        except (OSError, ValueError, KeyError):
            return None
        return result if result.metadata.get("run_key") == run.key else None

    def write(self) -> None:
        write_table(list(self.rows.values()), self.results)


# ----------------------------------------------------------------------------- rows

def flatten_metrics(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, float]:
    """Scalar metrics as ``{name: float}``; nested tables become ``table.key`` columns
    (any depth); strings, lists and other non-numbers are left out."""
    out: dict[str, float] = {}
    for name, value in metrics.items():
        if isinstance(value, Mapping):
            out |= flatten_metrics(value, f"{prefix}{name}.")
        elif isinstance(value, bool):
            out[prefix + name] = float(value)
        elif isinstance(value, int | float) or _is_numpy_scalar(value):
            out[prefix + name] = float(value)
    return out


def _is_numpy_scalar(value: Any) -> bool:
    return type(value).__module__ == "numpy" and getattr(value, "ndim", 1) == 0


def _column_type(name: str, values: list[Any]) -> pa.DataType:
    if name in ("point", "seed"):
        return pa.int64()
    if name in TEXT_COLUMNS:
        return pa.string()
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.int64()
    return pa.float64()


def table(rows: Sequence[Mapping[str, Any]]) -> pa.Table:
    """Arrow table of the rows: identity, swept keys, metrics, wall time, error; a row
    lacking a column (another spec, a metric added later) holds null there. Units in each
    field's metadata and, as one JSON object, in the schema metadata ``units``."""
    names: dict[str, None] = dict.fromkeys(IDENTITY)
    for row in rows:
        names |= dict.fromkeys(k for k in row if is_key_column(k))
    for row in rows:
        names |= dict.fromkeys(k for k in row if k not in ("wall_time_s", "error"))
    names |= dict.fromkeys(("wall_time_s", "error"))
    arrays, fields, units = [], [], {}
    for name in names:
        values = [row.get(name) for row in rows]
        dtype = _column_type(name, values)
        if dtype == pa.float64():
            values = [None if v is None else float(v) for v in values]
        arrays.append(pa.array(values, type=dtype))
        unit = column_unit(name)
        if unit:
            units[name] = unit
        fields.append(pa.field(name, dtype, metadata={"unit": unit} if unit else None))
    meta = {"units": json.dumps(units, sort_keys=True)}
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=meta))


def write_table(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    """Write the rows (in run order: scenario, architecture, controller, point, seed) as
    ``path``, atomically."""
    ordered = sorted(rows, key=lambda r: (*(str(r.get(k)) for k in ("scenario", "architecture",
                                                                      "controller", "variant")),
                                          _int(r.get("point")), _int(r.get("seed"))))
    sink = pa.BufferOutputStream()
    pq.write_table(table(ordered), sink, compression="zstd")
    write_bytes_atomic(path, sink.getvalue().to_pybytes())


def _int(value: Any) -> int:
    return -1 if value is None else int(value)


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of an existing results.parquet ([] if there is none); nulls left out."""
    if not Path(path).is_file():
        return []
    rows = pq.read_table(path).to_pylist()
    return [{k: v for k, v in row.items() if v is not None or k == "error"} for row in rows]


def read_units(path: Path) -> dict[str, str]:
    """Column -> unit of a results.parquet (from its field metadata)."""
    schema = pq.read_schema(path)
    return {f.name: (f.metadata or {}).get(b"unit", b"").decode() for f in schema}


class TableWriter:
    """Rewrites results.parquet as rows arrive, at most as often as keeps the rewriting
    (it grows with the rows) under ~5 % of the time: every WRITE_PERIOD_S, or 20 times the
    last write's duration if that is longer; :meth:`flush` writes what is pending."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.pending = False
        self.last_s = -math.inf
        self.period_s = WRITE_PERIOD_S

    def changed(self, rows: Mapping[str, Mapping[str, Any]]) -> None:
        self.pending = True
        if time.monotonic() - self.last_s >= self.period_s:
            self.flush(rows)

    def flush(self, rows: Mapping[str, Mapping[str, Any]]) -> None:
        if not self.pending:
            return
        start = time.monotonic()
        write_table(list(rows.values()), self.path)
        self.last_s = time.monotonic()
        self.period_s = max(WRITE_PERIOD_S, 20.0 * (self.last_s - start))
        self.pending = False


# ----------------------------------------------------------------------------- planning

@dataclass(frozen=True)
class PlannedRun:
    """One run of a campaign: ``key`` its :func:`~trackmj.study.identity.run_key`, ``spec``
    the executor's :class:`trackmj.study.executor.RunSpec`, ``row`` the identity columns (and
    swept values) that start its row, ``name`` its directory under ``runs/``."""

    key: str
    spec: RunSpec
    row: dict[str, Any]
    name: str

    @property
    def seed(self) -> int:
        return int(self.spec.seed)


def plan_run(spec: RunSpec, *, setup: RunSetup | None = None, point: int | None = None,
             values: Mapping[str, Any] | None = None, inputs: str = "",
             name: str | None = None) -> PlannedRun:
    """A :class:`PlannedRun` of ``spec`` (a RunSpec); ``setup``: its prepared
    :class:`~trackmj.sim.setup.RunSetup` (prepared here from ``spec`` if None, which
    validates it: ParameterError before anything runs); ``point``/``values``: the parameter
    point of a sweep; ``inputs``: JSON of the files and fixed overrides; ``name``: the run
    directory (default ``SCENARIO-ARCH-CONTROLLER-VARIANT-sSEED-KEY8``)."""
    if setup is None:
        setup = prepare(**spec.prepare_kwargs())
    key = run_key(setup)
    row = {"run_key": key, "point": point, "scenario": setup.scenario.name,
           "machine": setup.machine.name, "architecture": setup.architecture,
           "controller": setup.controller,
           "estimator": setup.estimator, "variant": setup.variant.name, "seed": setup.seed,
           "duration_s": setup.duration_s, "inputs": inputs, **dict(values or {})}
    if point is None:
        del row["point"]
    name = name or (f"{setup.scenario.name}-{setup.architecture}-{setup.controller}-"
                    f"{setup.variant.name}-s{setup.seed}-{key[:8]}")
    return PlannedRun(key, spec, row, name)


# ----------------------------------------------------------------------------- running

@dataclass
class CampaignRun:
    """What :func:`run_campaign` did: ``outcomes`` of the runs made now (in finishing
    order), ``resumed`` how many were already done, ``results`` run key -> Result of the
    runs the caller asked to keep in memory (resumed and new), the wall time [s]."""

    outcomes: list[RunOutcome] = field(default_factory=list)
    resumed: int = 0
    results: dict[str, Result] = field(default_factory=dict)
    wall_time_s: float = 0.0

    @property
    def failed(self) -> list[RunOutcome]:
        return [o for o in self.outcomes if not o.ok]


Extras = Callable[[Result], Mapping[str, Callable[[Path], Any]]]
"""A finished run's result -> extra files of its directory (file name -> writer)."""


def run_campaign(store: Store, runs: Sequence[PlannedRun], *, executor: Any = None,
                 workers: int | None = None, scheduler: str | None = None,
                 progress: str | None = None, keep_runs: bool = False,
                 retry_failed: bool = False, need_results: bool = False,
                 extras: Extras | None = None,
                 on_outcome: Callable[[PlannedRun, RunOutcome], None] | None = None
                 ) -> CampaignRun:
    """Make the runs of ``runs`` not yet done in ``store`` (an entered :class:`Store`),
    writing each one's row as it finishes (a failed run: its error row) and, with
    ``keep_runs``, its result directory ``runs/<name>/`` (plus ``extras(result)``:
    file name -> writer, e.g. a figure).

    Done (the module's one rule): a row with the run's key, without an error unless not
    ``retry_failed``; with ``need_results`` (the caller needs every Result, e.g. the report)
    also its directory holding that key, read back into :attr:`CampaignRun.results`.

    executor: an entered :class:`trackmj.study.executor.Executor` (else a local one is started
    only if something is to run, with ``workers``/``scheduler``); progress: label of the
    progress bar (None: no bar); on_outcome(run, outcome): called as each run finishes.
    """
    start = time.perf_counter()
    done = CampaignRun()
    todo: dict[str, PlannedRun] = {}
    for run in runs:
        if _is_done(store, run, done, retry_failed=retry_failed, need_results=need_results):
            done.resumed += 1
        else:
            todo.setdefault(run.key, run)
    by_spec = {run.spec: run for run in todo.values()}
    writer = TableWriter(store.results)
    try:
        for outcome in _outcomes(list(by_spec), executor, workers, scheduler, progress):
            run = by_spec[outcome.spec]
            store.rows[run.key] = _finished_row(store, run, outcome, done, keep_runs=keep_runs,
                                                need_results=need_results, extras=extras)
            done.outcomes.append(outcome)
            if on_outcome is not None:
                on_outcome(run, outcome)
            writer.changed(store.rows)
    finally:   # also on Ctrl-C or an error: the rows that arrived are kept
        writer.flush(store.rows)
    done.wall_time_s = time.perf_counter() - start
    return done


def _is_done(store: Store, run: PlannedRun, done: CampaignRun, *, retry_failed: bool,
             need_results: bool) -> bool:
    """Whether ``run`` is done in ``store`` (see :func:`run_campaign`); with
    ``need_results`` its stored result is read back into ``done.results``."""
    row = store.rows.get(run.key)
    if row is None or (retry_failed and row.get("error")):
        return False
    if need_results and not row.get("error"):
        result = store.stored_result(run)
        if result is None:
            return False
        done.results[run.key] = result
    return True


def _finished_row(store: Store, run: PlannedRun, outcome: RunOutcome, done: CampaignRun, *,
                  keep_runs: bool, need_results: bool,
                  extras: Extras | None) -> dict[str, Any]:
    """The row of a run that finished now: its identity columns, its flattened metrics (its
    result, stamped with its key, written under ``runs/`` with ``keep_runs`` or
    ``need_results`` and kept in ``done.results`` with ``need_results``), wall time, error."""
    row = dict(run.row)
    if outcome.ok and outcome.result is not None:
        result = stamped(outcome.result, run_key=run.key)
        outcome.result = result
        row |= flatten_metrics(result.metrics)
        if keep_runs or need_results:
            write_result(result, store.run_dir(run), extras=extras(result) if extras else None)
        if need_results:
            done.results[run.key] = result
    row["wall_time_s"] = outcome.wall_time_s
    row["error"] = outcome.error
    return row


def _outcomes(specs: list[RunSpec], executor: Any, workers: int | None, scheduler: str | None,
              progress: str | None) -> Iterator[RunOutcome]:
    """The executor's outcomes of ``specs``; nothing to run starts no cluster."""
    if not specs:
        return
    if executor is not None:
        yield from executor.as_completed(specs, progress=progress)
        return
    with Executor(workers=workers, scheduler=scheduler) as ex:
        yield from ex.as_completed(specs, progress=progress)
