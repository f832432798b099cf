"""The campaign layer under ``report``, ``sweep`` and ``calibrate``: many runs into one
directory, each known by its identity, resumable, one row per run.

A run's **identity** (:func:`identity`) is everything that determines its result: the
scenario (validated, after overrides, events as they will run), the machine files' content
(the validated model, hydraulic and control parameters after overrides and the variant's
scaling; the packaged machine's files, :func:`machine_files_hash`; a tensioner file's
content and its FMU file's SHA-256; a controller FMU's file hash), the architecture,
controller, estimator, seed, variant, duration and the SHA-256 of the *source* of the
trackmj, trackmj.hydraulics and trackmj.control packages (:func:`source_hash`).
:func:`run_key` hashes all of it; :func:`inputs_key` the same without the source (what
``trackmj run`` compares before replacing a folder: the same inputs run by other code may
replace their old result, other inputs may not).

One rule for "already done", for every campaign: a run is done when the campaign's
``results.parquet`` holds a row with its ``run_key`` (and no error, unless failed runs are
kept), and, for a campaign that needs the runs themselves (the report), its directory under
``runs/`` holds a result with that ``run_key``. A change of any input or of the code changes
the key, so the run is made again; rows of other keys are kept.

A campaign directory (:class:`Store`):

- ``campaign.json``: what kind of campaign it is (``sweep``, ``report``, ``calibrate``); a
  campaign of another kind into the same directory is refused, and so is a second campaign
  while one writes it (an exclusive lock, ``.campaign.lock``);
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

import dataclasses
import fcntl
import functools
import hashlib
import json
import math
import time
import types
import typing
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trackmj.validator import FILE_KINDS, unit_from_name

RESULTS = "results.parquet"
CAMPAIGN = "campaign.json"
LOCK = ".campaign.lock"
RUNS = "runs"
WRITE_PERIOD_S = 2.0
"""results.parquet is rewritten at most this often while runs finish [s]."""
IDENTITY = ("run_key", "point", "scenario", "architecture", "controller", "estimator",
            "variant", "seed", "duration_s", "inputs")
"""Columns naming a run, first in every row."""
TEXT_COLUMNS = ("run_key", "scenario", "architecture", "controller", "estimator", "variant",
                "inputs", "error")
SOURCE_PACKAGES = ("trackmj", "trackmj.hydraulics", "trackmj.control")
"""Packages whose source (every ``.py`` file below them) is part of a run's identity."""


# ----------------------------------------------------------------------------- identity

@functools.cache
def source_hash() -> str:
    """SHA-256 (hex) of the source of :data:`SOURCE_PACKAGES`: every ``.py`` file under each
    package's directory, by relative path and content. Computed once per process."""
    import importlib

    digest = hashlib.sha256()
    for name in SOURCE_PACKAGES:
        root = Path(importlib.import_module(name).__file__).parent
        for path in sorted(root.rglob("*.py")):
            digest.update(f"{name}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return digest.hexdigest()


@functools.cache
def machine_files_hash() -> str:
    """SHA-256 (hex) of the packaged machine's files (``trackmj.models``: the committed MJCF,
    the parameter files and the identified idler), by name and content: the packaged runs
    read the MJCF and the idler from them, not from the validated parameters."""
    import importlib

    root = Path(importlib.import_module("trackmj.models").__file__).parent
    digest = hashlib.sha256()
    for path in sorted(p for p in root.iterdir() if p.suffix in (".xml", ".toml")):
        digest.update(f"{path.name}\0".encode() + path.read_bytes() + b"\0")
    return digest.hexdigest()


def machine_identity(machine: Any) -> str:
    """A machine's name and the content of the files its runs read besides the validated
    parameters: the identified idler and the reference MJCF (scene joined with its machine
    part), as SHA-256."""
    from trackmj.track.mjcf.builders import read_mjcf

    text = machine.name
    if machine.idler is not None:
        text += _file_hash(machine.idler)
    if machine.reference_mjcf is not None:
        text += hashlib.sha256(read_mjcf(machine.reference_mjcf).encode()).hexdigest()
    return text


def _file_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def identity(setup: Any) -> dict[str, Any]:
    """Everything that determines the run of ``setup`` (a :class:`trackmj.sim.setup.RunSetup`)
    as a JSON-ready mapping; see the module docstring. ``source`` is :func:`source_hash`."""
    scenario = {f.name: repr(getattr(setup.scenario, f.name))
                for f in dataclasses.fields(setup.scenario) if f.name != "source"}
    ident: dict[str, Any] = {
        "architecture": setup.architecture, "controller": setup.controller,
        "estimator": setup.estimator, "seed": setup.seed, "duration_s": repr(setup.duration_s),
        "variant": repr(setup.variant), "model": repr(setup.model),
        "hydraulics": repr(setup.hydraulics), "control": repr(setup.control),
        "scenario": scenario, "machine_files": machine_files_hash(), "source": source_hash()}
    if setup.tensioner is not None:
        ident["tensioner"] = setup.tensioner.identity()
    from trackmj.machines.assembly import DEFAULT_MACHINE

    machine = getattr(setup, "machine", None)
    if machine is not None and machine.name != DEFAULT_MACHINE:
        ident["machine"] = machine_identity(machine)
    if setup.controller_file is not None:
        ident["controller_file"] = repr(setup.controller_file)
        described = setup.controller_file.description
        if described is not None:
            ident["controller_fmu"] = _file_hash(described.path)
    return ident


def _hash(ident: Mapping[str, Any]) -> str:
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:20]


def run_key(setup: Any) -> str:
    """Hash (20 hex digits) of the run's :func:`identity`: inputs and code."""
    return _hash(identity(setup))


def inputs_key(setup: Any) -> str:
    """Hash (20 hex digits) of the run's inputs alone (its identity without the source)."""
    return _hash({k: v for k, v in identity(setup).items() if k != "source"})


def stamped(result: Any, **keys: str) -> Any:
    """``result`` with ``keys`` (e.g. ``run_key=...``) added to its table metadata."""
    from trackmj.results.store import Result

    meta = dict(result.timeseries.schema.metadata or {})
    meta |= {k.encode(): v.encode() for k, v in keys.items()}
    return Result(result.timeseries.replace_schema_metadata(meta), result.metrics)


# ----------------------------------------------------------------------------- statistics

def finite(values: Iterable[Any]) -> list[float]:
    """The finite numbers among ``values`` (None and NaN left out)."""
    return [float(v) for v in values if v is not None and math.isfinite(float(v))]


def mean_std(values: Iterable[Any]) -> tuple[float, float, int]:
    """(mean, population std, count) of the finite values; (NaN, 0, 0) if there is none.
    The one statistic of every campaign document (mean ± std over seeds)."""
    v = finite(values)
    if not v:
        return math.nan, 0.0, 0
    mean = math.fsum(v) / len(v)
    if len(v) == 1:
        return mean, 0.0, 1
    std = math.sqrt(math.fsum((x - mean) ** 2 for x in v) / len(v))
    if std <= 1e-9 * abs(mean):     # equal but for rounding
        std = 0.0
    return mean, std, len(v)


# ----------------------------------------------------------------------------- units

def _key_field(key: str) -> Any:
    """The (type hint, Spec) that the file of ``key`` (``KIND.TABLE.KEY``) declares for it,
    or None if the key does not exist (the file's validator then says why)."""
    kind, *parts = key.split(".")
    hint: Any = file_schema(kind)
    spec = None
    for part in parts:
        origin, args = typing.get_origin(hint), typing.get_args(hint)
        if origin is tuple and part.isdigit() and dataclasses.is_dataclass(args[0]):
            hint = args[0]
            continue
        if origin in (dict, Mapping) and dataclasses.is_dataclass(args[1]):
            hint = args[1]
            continue
        if not dataclasses.is_dataclass(hint):
            return None
        from trackmj.validator import file_fields

        found = file_fields(hint).get(part)
        if found is None:
            return None
        hint, spec = found.hint, found.spec
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        hint = next(a for a in typing.get_args(hint) if a is not type(None))
    return hint, spec


def file_schema(kind: str) -> type:
    """The root parameter class of file kind ``kind`` (one of FILE_KINDS)."""
    if kind == "model":
        from trackmj.track.mechanics import ModelParams

        return ModelParams
    if kind == "hydraulics":
        from trackmj.hydraulics.params import HydraulicParams

        return HydraulicParams
    if kind == "control":
        from trackmj.control.params import ControlConfig

        return ControlConfig
    from trackmj.scenarios.schema import ScenarioFile

    return ScenarioFile


def key_unit(key: str) -> str:
    """Unit of a ``--set`` key as its file declares it ('' if unknown)."""
    found = _key_field(key)
    if found is not None and found[1] is not None and found[1].unit:
        return found[1].unit
    return unit_from_name(key.rsplit(".", 1)[-1]) or ""


def is_key_column(name: str) -> bool:
    """Whether results column ``name`` holds a ``--set`` key (``KIND.TABLE.KEY``)."""
    kind, dot, _ = name.partition(".")
    return bool(dot) and kind in FILE_KINDS


def column_unit(name: str) -> str:
    """Unit of a results (or timeseries) column: a key's declared unit, a timeseries
    column's unit (:data:`trackmj.ports.COLUMN_UNITS`), else its name's SI suffix (for a
    flattened table entry ``table.key`` the key's, else the table's)."""
    from trackmj.ports import COLUMN_UNITS

    if is_key_column(name):
        return key_unit(name)
    if name in COLUMN_UNITS:
        return COLUMN_UNITS[name]
    if name in ("point", "seed"):
        return "1"
    for part in reversed(name.split(".")):   # a table entry: the table's unit (energy_J.pump)
        unit = unit_from_name(part)
        if unit:
            return unit
    return ""


# ----------------------------------------------------------------------------- the store

def check_campaign_dir(out: str | Path, markers: Sequence[str], what: str) -> Path:
    """``out`` (created) if it can hold a ``what`` (a sweep, a report, a comparison): absent,
    empty, or holding one of ``markers`` (a previous one, which it resumes or replaces); else
    :class:`trackmj.results.store.ResultDirectoryError`, before anything runs. The one ``--out``
    guard of every campaign command."""
    from trackmj.results.store import ResultDirectoryError

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
    the subdirectory of the run directories ("." for the campaign directory itself)."""

    def __init__(self, out: str | Path, kind: str, markers: Sequence[str] = (),
                 what: str | None = None, runs: str = RUNS) -> None:
        self.kind = kind
        self.out = check_campaign_dir(out, (CAMPAIGN, RESULTS, *markers), what or kind)
        self.results = self.out / RESULTS
        self.runs = self.out / runs
        self._fh: Any = None
        self.rows: dict[str, dict[str, Any]] = {}

    def __enter__(self) -> Store:
        from trackmj.io import write_text_atomic
        from trackmj.results.store import ResultDirectoryError

        self._fh = open(self.out / LOCK, "a")   # held until __exit__
        try:
            fcntl.flock(self._fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._fh.close()
            self._fh = None
            raise ResultDirectoryError(f"--out {self.out}: another trackmj campaign is "
                                       "writing this directory; wait for it or choose "
                                       "another --out") from None
        try:
            marker = self.out / CAMPAIGN
            if marker.is_file():
                kind = json.loads(marker.read_text()).get("kind")
                if kind != self.kind:
                    raise ResultDirectoryError(
                        f"--out {self.out}: holds a trackmj {kind} ({CAMPAIGN}); refusing to "
                        f"write a {self.kind} into it (choose another --out)")
            else:
                write_text_atomic(marker, json.dumps({"kind": self.kind}) + "\n")
            self.rows = {row["run_key"]: row for row in read_rows(self.results)}
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        if self._fh is not None:
            fcntl.flock(self._fh, fcntl.LOCK_UN)
            self._fh.close()
            self._fh = None

    def run_dir(self, run: PlannedRun) -> Path:
        return self.runs / run.name

    def stored_result(self, run: PlannedRun) -> Any:
        """The result under ``runs/`` of ``run`` if its directory holds one with the same
        ``run_key``; else None."""
        from trackmj.results.store import read_result

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


def _column_type(name: str, values: list[Any]) -> Any:
    import pyarrow as pa

    if name in ("point", "seed"):
        return pa.int64()
    if name in TEXT_COLUMNS:
        return pa.string()
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.int64()
    return pa.float64()


def table(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Arrow table of the rows: identity, swept keys, metrics, wall time, error; a row
    lacking a column (another spec, a metric added later) holds null there. Units in each
    field's metadata and, as one JSON object, in the schema metadata ``units``."""
    import pyarrow as pa

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
    import pyarrow as pa
    import pyarrow.parquet as pq

    from trackmj.io import write_bytes_atomic

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
    import pyarrow.parquet as pq

    rows = pq.read_table(path).to_pylist()
    return [{k: v for k, v in row.items() if v is not None or k == "error"} for row in rows]


def read_units(path: Path) -> dict[str, str]:
    """Column -> unit of a results.parquet (from its field metadata)."""
    import pyarrow.parquet as pq

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
    """One run of a campaign: ``key`` its :func:`run_key`, ``spec`` the executor's
    :class:`trackmj.study.executor.RunSpec`, ``row`` the identity columns (and swept values) that
    start its row, ``name`` its directory under ``runs/``."""

    key: str
    spec: Any
    row: dict[str, Any]
    name: str

    @property
    def seed(self) -> int:
        return int(self.spec.seed)


def plan_run(spec: Any, *, setup: Any = None, point: int | None = None,
             values: Mapping[str, Any] | None = None, inputs: str = "",
             name: str | None = None) -> PlannedRun:
    """A :class:`PlannedRun` of ``spec`` (a RunSpec); ``setup``: its prepared
    :class:`~trackmj.sim.setup.RunSetup` (prepared here from ``spec`` if None, which
    validates it: ParameterError before anything runs); ``point``/``values``: the parameter
    point of a sweep; ``inputs``: JSON of the files and fixed overrides; ``name``: the run
    directory (default ``SCENARIO-ARCH-CONTROLLER-VARIANT-sSEED-KEY8``)."""
    if setup is None:
        from trackmj.sim.setup import prepare

        setup = prepare(**spec.prepare_kwargs())
    key = run_key(setup)
    row = {"run_key": key, "point": point, "scenario": setup.scenario.name,
           "architecture": setup.architecture, "controller": setup.controller,
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

    outcomes: list[Any] = field(default_factory=list)
    resumed: int = 0
    results: dict[str, Any] = field(default_factory=dict)
    wall_time_s: float = 0.0

    @property
    def failed(self) -> list[Any]:
        return [o for o in self.outcomes if not o.ok]


def run_campaign(store: Store, runs: Sequence[PlannedRun], *, executor: Any = None,
                 workers: int | None = None, scheduler: str | None = None,
                 progress: str | None = None, keep_runs: bool = False,
                 retry_failed: bool = False, need_results: bool = False,
                 extras: Callable[[Any], Mapping[str, Callable[[Path], Any]]] | None = None,
                 on_outcome: Callable[[PlannedRun, Any], None] | None = None) -> CampaignRun:
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
        row = store.rows.get(run.key)
        ready = row is not None and not (retry_failed and row.get("error"))
        if ready and need_results and not row.get("error"):
            result = store.stored_result(run)
            ready = result is not None
            if ready:
                done.results[run.key] = result
        if ready:
            done.resumed += 1
        else:
            todo.setdefault(run.key, run)
    by_spec = {run.spec: run for run in todo.values()}
    writer = TableWriter(store.results)
    try:
        for outcome in _outcomes(list(by_spec), executor, workers, scheduler, progress):
            run = by_spec[outcome.spec]
            row = dict(run.row)
            if outcome.ok:
                result = stamped(outcome.result, run_key=run.key)
                outcome.result = result
                row |= flatten_metrics(result.metrics)
                if keep_runs or need_results:
                    from trackmj.results.store import write_result

                    write_result(result, store.run_dir(run),
                                 extras=extras(result) if extras else None)
                if need_results:
                    done.results[run.key] = result
            row["wall_time_s"] = outcome.wall_time_s
            row["error"] = outcome.error
            store.rows[run.key] = row
            done.outcomes.append(outcome)
            if on_outcome is not None:
                on_outcome(run, outcome)
            writer.changed(store.rows)
    finally:   # also on Ctrl-C or an error: the rows that arrived are kept
        writer.flush(store.rows)
    done.wall_time_s = time.perf_counter() - start
    return done


def _outcomes(specs: list[Any], executor: Any, workers: int | None, scheduler: str | None,
              progress: str | None) -> Iterator[Any]:
    """The executor's outcomes of ``specs``; nothing to run starts no cluster."""
    if not specs:
        return
    from trackmj.study.executor import Executor

    if executor is not None:
        yield from executor.as_completed(specs, progress=progress)
        return
    with Executor(workers=workers, scheduler=scheduler) as ex:
        yield from ex.as_completed(specs, progress=progress)
