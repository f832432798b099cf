"""Parameter studies (``trackmj sweep``): many runs of a TOML spec on the Dask executor,
one row per run in ``DIR/results.parquet``, resumable, with a figure per metric.

Spec file (read by the one validator, :mod:`trackmj.params`; every key but ``scenario`` /
``scenarios`` optional)::

    [sweep]
    scenario = "W1"              # or scenarios = ["W1", "W2"]; a name or a TOML file
    duration_s = 10.0            # default: each scenario's duration_s
    seeds = [0, 1]               # default [0]
    architectures = ["tp"]       # default ["tp"]
    controllers = ["nmpc", "pid"]  # default: the scenario's controller
    estimator = "ekf"            # default: the scenario's estimator
    variant = "nominal"
    model = "my_model.toml"      # parameter files (default: the packaged ones)
    hydraulics = "my_hyd.toml"
    control = "my_control.toml"
    set = ["scenario.track.speed_m_s=2.0"]   # --set items applied to every run
    method = "grid"              # "grid": every combination; "lhs": Latin hypercube
    samples = 20                 # lhs: number of parameter points
    seed = 0                     # lhs: sampling seed

    [[sweep.parameters]]
    key = "hydraulics.metering.head_branch_area_m2"   # a --set key (KIND.TABLE.KEY)
    values = [3.0e-8, 4.0e-8, 6.0e-8]                 # grid: the values ...

    [[sweep.parameters]]
    key = "hydraulics.fluid.bulk_modulus_Pa"
    low = 0.8e9                  # ... or low, high (and count for a grid)
    high = 1.6e9
    count = 3
    scale = "linear"             # or "log" (points spaced evenly in log(value))

File paths are relative to the spec file. The runs are scenarios x parameter points x
architectures x controllers x seeds. Swept keys are numeric keys of the model, hydraulics,
control or scenario files; a key the file declares as an integer takes integral values (an
LHS sample is rounded). Every run is validated before the first one starts: a bad key or
value is an error naming the spec file, the parameter and the allowed range.

Output directory ``DIR``:

- ``results.parquet``: one row per run, rewritten atomically as runs finish (at most every
  2 s while they do, and at the end, also after Ctrl-C or an error).
  Columns: ``run_key`` (identity of the run's inputs), ``point`` (index of the parameter
  point), ``scenario``, ``architecture``, ``controller``, ``estimator``, ``variant``,
  ``seed``, ``duration_s``, ``inputs`` (JSON: files and fixed overrides of the spec), one
  column per swept key (named by the key), every scalar metric (nested metric tables
  flattened as ``table.key``, e.g. ``energy_J.pump``), ``wall_time_s`` (the run's wall time
  in its worker) and ``error`` (null, or ``"Type: message"`` for a run that failed).
  Each column's unit is in its Arrow field metadata (``unit``) where the name states one.
- ``sweep.toml``: the spec as given; ``figures/<metric>.png``: each metric against each
  swept parameter, mean ± std over seeds (without swept parameters: bars per scenario and
  case); ``runs/<case>/``: every run's result directory
  with ``keep_runs``.

Resume: a run whose ``run_key`` already has a row is skipped (a failed one too, unless
``retry_failed``). The key hashes everything that determines the run: the validated model,
hydraulic, control and scenario parameters (after overrides), the variant, architecture,
controller, estimator, seed, duration and the trackmj version; a changed file changes it.
Rows of runs the current spec does not ask for are kept.
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import itertools
import json
import math
import time
import types
import typing
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from trackmj.machines import DEFAULT_MACHINE, names
from trackmj.params import (
    FILE_KINDS,
    Location,
    ParameterError,
    Parameters,
    build,
    file_fields,
    load_file,
    param,
    parse_overrides,
    unit_from_name,
)
from trackmj.sim.registry import ARCHITECTURES, CONTROLLERS, ESTIMATORS, by_name, choices

RESULTS = "results.parquet"
SPEC_COPY = "sweep.toml"
FIGURES = "figures"
RUNS = "runs"
WRITE_PERIOD_S = 2.0
"""results.parquet is rewritten at most this often while runs finish [s]."""
MAX_RUNS = 100_000
"""Largest sweep accepted: a grid grows as the product of its value counts."""
KEY_PATTERN = rf"({'|'.join(FILE_KINDS)})(\.[A-Za-z0-9_]+)+"
IDENTITY = ("run_key", "point", "scenario", "architecture", "controller", "estimator",
            "variant", "seed", "duration_s", "inputs")
"""Columns naming a run, first in every row."""
TEXT_COLUMNS = ("run_key", "scenario", "architecture", "controller", "estimator", "variant",
                "inputs", "error")
CASE = ("scenario", "architecture", "controller", "estimator", "variant", "duration_s",
        "inputs")
"""Columns that make one line of a figure (with the other swept parameters)."""


# ----------------------------------------------------------------------------- spec

@dataclass(frozen=True)
class SweptParameter(Parameters):
    """One ``[[sweep.parameters]]`` entry: a ``--set`` key and its values or range."""

    key: str = param(pattern=KEY_PATTERN, max_len=200,
                     doc="a --set key KIND.TABLE.KEY, KIND one of " + ", ".join(FILE_KINDS))
    values: tuple[float, ...] | None = param(default=None,
                                             doc="grid values (optional: or low/high)")
    low: float | None = param(default=None, unit="the key's unit",
                              doc="lower end of the range")
    high: float | None = param(default=None, unit="the key's unit",
                               doc="upper end of the range")
    count: int | None = param(1, 10_000, default=None, unit="1",
                              doc="grid points from low to high (grid with a range)")
    scale: Literal["linear", "log"] = param(default="linear",
                                            doc="spacing of range points and samples")

    def cross_check(self, at: Location) -> None:
        ranged = self.low is not None or self.high is not None
        if self.values is not None and (ranged or self.count is not None):
            raise at.error("values", self.values, "excludes low, high and count: give either "
                           "values or a range")
        if self.values is None and not ranged:
            raise at.error("key", self.key, "needs values = [...] or low and high")
        if self.values is not None and len(set(self.values)) != len(self.values):
            raise at.error("values", self.values, "lists a value twice")
        if ranged:
            if self.low is None or self.high is None:
                raise at.error("low" if self.low is None else "high", None,
                               "is missing: a range needs both low and high")
            if not self.high > self.low:
                raise at.error("high", self.high, f"must be > low = {self.low!r}")
        if self.scale == "log":
            lowest = min(self.values) if self.values is not None else self.low
            if lowest is not None and lowest <= 0.0:
                raise at.error("scale", self.scale, f"needs positive values (lowest "
                               f"{lowest!r})")


@dataclass(frozen=True)
class SweepTable(Parameters):
    """The ``[sweep]`` table (see the module docstring)."""

    scenario: str | None = param(max_len=4096, default=None,
                                 doc="a built-in scenario (W1..W5) or a scenario file")
    scenarios: tuple[str, ...] | None = param(max_len=4096, default=None,
                                              doc="several scenarios (instead of scenario)")
    duration_s: float | None = param(1e-3, 3600.0, default=None,
                                     doc="simulated time per run (default: the scenario's)")
    seeds: tuple[int, ...] = param(0, 2**32 - 1, unit="1", default=(0,),
                                   doc="noise and terrain seeds; every point runs each")
    architectures: tuple[str, ...] = param(choices=choices(ARCHITECTURES), default=("tp",),
                                           doc="coupling architectures")
    controllers: tuple[str, ...] | None = param(choices=by_name(CONTROLLERS), default=None,
                                                doc="controllers (default: the scenario's)")
    estimator: str | None = param(choices=choices(ESTIMATORS), default=None,
                                  doc="state estimator (default: the scenario's)")
    variant: str = param(max_len=64, default="nominal", doc="scenario variant (W5)")
    machine: str | None = param(max_len=4096, default=None,
                                doc="a shipped machine's name or a machine file (default "
                                    "lf1352)")
    model: str | None = param(max_len=4096, default=None, doc="model parameter file")
    hydraulics: str | None = param(max_len=4096, default=None,
                                   doc="hydraulic parameter file")
    control: str | None = param(max_len=4096, default=None, doc="control parameter file")
    tensioner: str | None = param(max_len=4096, default=None, doc="tensioner file (an FMU "
                                  "or a spring-damper) replacing the hydraulic element")
    set: tuple[str, ...] | None = param(max_len=4096, default=None,
                                        doc="--set items KIND.TABLE.KEY=VALUE for every run")
    method: Literal["grid", "lhs"] = param(default="grid",
                                           doc="grid: every combination; lhs: Latin hypercube")
    samples: int | None = param(1, MAX_RUNS, default=None, unit="1",
                                doc="parameter points of a Latin hypercube (method lhs)")
    seed: int = param(0, 2**32 - 1, unit="1", default=0, doc="seed of the LHS sampling")
    parameters: tuple[SweptParameter, ...] = param(default=(), doc="the swept keys")

    def cross_check(self, at: Location) -> None:
        if (self.scenario is None) == (self.scenarios is None):
            raise at.error("scenario", self.scenario, "or scenarios: give exactly one")
        for name in ("seeds", "architectures", "controllers", "scenarios"):
            items = getattr(self, name)
            if items is not None and len(set(items)) != len(items):
                raise at.error(name, items, "lists an item twice")
        keys = [p.key for p in self.parameters]
        for i, key in enumerate(keys):
            if key in keys[:i]:
                raise at.error(("parameters", i, "key"), key, "is swept twice")
        if self.method == "lhs":
            if self.samples is None:
                raise at.error("method", self.method, "needs samples = N (parameter points)")
            if not self.parameters:
                raise at.error("method", self.method, "needs [[sweep.parameters]] to sample")
            for i, p in enumerate(self.parameters):
                if p.values is not None or p.count is not None:
                    raise at.error(("parameters", i, "values" if p.values else "count"),
                                   p.values or p.count, "does not apply to method = 'lhs': "
                                   "give low and high")
        else:
            if self.samples is not None:
                raise at.error("samples", self.samples, "applies to method = 'lhs' only")
            for i, p in enumerate(self.parameters):
                if p.values is None and p.count is None:
                    raise at.error(("parameters", i, "count"), None, "is missing: a grid "
                                   "over a range needs count")


@dataclass(frozen=True)
class SweepFile(Parameters):
    """A sweep spec file: one ``[sweep]`` table."""

    sweep: SweepTable


@dataclass(frozen=True)
class SweepSpec:
    """A validated spec: ``table`` as read, ``base`` the directory its paths are relative
    to, ``source`` the file (None for a spec given as a mapping), ``text`` its TOML text."""

    table: SweepTable
    base: Path
    source: Path | None = None
    text: str = ""

    def where(self) -> str:
        """The spec's name in messages."""
        return self.source.name if self.source is not None else "sweep spec"

    def path(self, value: str | None) -> str | None:
        """A file of the spec as an absolute path string (built-in scenario names stay)."""
        if value is None:
            return None
        if value.upper() in _builtin_scenarios():
            return value
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else (self.base / path).resolve())

    def scenarios(self) -> tuple[str, ...]:
        names = self.table.scenarios or (self.table.scenario,)
        return tuple(self.path(n) for n in names)


def _builtin_scenarios() -> tuple[str, ...]:
    from trackmj.scenarios import BUILTIN

    return BUILTIN


def load_sweep(spec: str | Path | Mapping[str, Any] | SweepSpec) -> SweepSpec:
    """Read and validate a sweep spec.

    Parameters
    ----------
    spec : str, Path, mapping or SweepSpec
        A TOML file, or its content as a mapping (``{"sweep": {...}}``; paths then are
        relative to the working directory).

    Returns
    -------
    SweepSpec
        Raises ParameterError naming the file, table and key of a mistake.
    """
    if isinstance(spec, SweepSpec):
        return spec
    if isinstance(spec, Mapping):
        table = build(SweepFile, spec, file="sweep spec", require_source=False).sweep
        return SweepSpec(table, Path.cwd())
    path = Path(spec)
    table = load_file(SweepFile, path, require_source=False).sweep   # readable UTF-8 TOML
    return SweepSpec(table, path.resolve().parent, path, path.read_text(encoding="utf-8"))


# ----------------------------------------------------------------------------- points

def _key_field(key: str) -> Any:
    """The (type hint, Spec) that the file of ``key`` declares for it, or None if the key
    does not exist (the file's validator then says why)."""
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
        from trackmj.model.params import ModelParams

        return ModelParams
    if kind == "hydraulics":
        from trackmj.hydraulics.params import HydraulicParams

        return HydraulicParams
    if kind == "control":
        from trackmj.control.params import ControlConfig

        return ControlConfig
    from trackmj.scenarios import ScenarioFile

    return ScenarioFile


def key_unit(key: str) -> str:
    """Unit of a swept key as its file declares it ('' if unknown)."""
    found = _key_field(key)
    if found is not None and found[1] is not None and found[1].unit:
        return found[1].unit
    return unit_from_name(key.rsplit(".", 1)[-1]) or ""


def _typed(spec: SweepSpec, index: int, value: float) -> float | int:
    """``value`` as the type the swept key's file declares (int keys take integers)."""
    p = spec.table.parameters[index]
    found = _key_field(p.key)
    hint = found[0] if found is not None else float
    where = f"{spec.where()} [[sweep.parameters]][{index}] (key {p.key!r})"
    if hint is int:
        if p.values is not None and value != round(value):
            raise ParameterError(f"{where}: value {value!r} is not an integer; the key is "
                                 "declared as an integer")
        return round(value)
    if hint is not float and found is not None:
        raise ParameterError(f"{where}: the key holds {_kind_text(hint)}; a sweep varies "
                             "numeric keys only (sweep scenarios, architectures and "
                             "controllers with their own lists)")
    return float(value)


def _kind_text(hint: Any) -> str:
    if dataclasses.is_dataclass(hint):
        return "a table"
    return {str: "a string", bool: "a boolean"}.get(hint, f"values of type {hint!r}")


def _range(p: SweptParameter, fraction: Sequence[float]) -> list[float]:
    """Points at ``fraction`` (0..1) of p's range, linear or in log(value)."""
    lo, hi = float(p.low), float(p.high)
    if p.scale == "log":
        return [math.exp(math.log(lo) + f * (math.log(hi) - math.log(lo))) for f in fraction]
    return [lo + f * (hi - lo) for f in fraction]


def parameter_points(spec: SweepSpec) -> list[dict[str, float | int]]:
    """The parameter points of ``spec``: every combination of the grid values (first key
    varies slowest), or ``samples`` Latin-hypercube points (each key's range cut into
    ``samples`` equal strata in its scale, one sample in each, the strata of the keys
    paired by independent random permutations of the ``seed``). No parameters: one empty
    point."""
    table = spec.table
    n_points = table.samples if table.method == "lhs" else math.prod(
        len(p.values) if p.values is not None else int(p.count) for p in table.parameters)
    if n_points > MAX_RUNS:
        raise ParameterError(f"{spec.where()}: {n_points} parameter points; a sweep has at "
                             f"most {MAX_RUNS} runs (fewer values, or method = 'lhs')")
    if table.method == "lhs":
        import numpy as np

        n = int(table.samples)
        rng = np.random.default_rng(table.seed)
        columns = []
        for p in table.parameters:
            fraction = (rng.permutation(n) + rng.random(n)) / n
            columns.append(_range(p, fraction.tolist()))
        raw = [dict(zip((p.key for p in table.parameters), row, strict=True))
               for row in zip(*columns, strict=True)]
    else:
        axes = []
        for p in table.parameters:
            if p.values is not None:
                axes.append(list(p.values))
            else:
                count = int(p.count)
                axes.append(_range(p, [k / (count - 1) for k in range(count)]
                                   if count > 1 else [0.0]))
        raw = [dict(zip((p.key for p in table.parameters), combo, strict=True))
               for combo in itertools.product(*axes)]
    return [{key: _typed(spec, i, value) for i, (key, value) in enumerate(point.items())}
            for point in raw]


# ----------------------------------------------------------------------------- runs

@dataclass(frozen=True)
class PlannedRun:
    """One run of a sweep: its executor spec, identity row fields and parameter point."""

    key: str
    spec: Any   # trackmj.executor.RunSpec
    point: int
    values: dict[str, float | int]
    identity: dict[str, Any]


def _run_key(setup: Any) -> str:
    """Hash of everything that determines a run (see the module docstring)."""
    from trackmj import __version__

    scenario = {f.name: repr(getattr(setup.scenario, f.name))
                for f in dataclasses.fields(setup.scenario) if f.name != "source"}
    ident = {"version": __version__, "architecture": setup.architecture,
             "controller": setup.controller, "estimator": setup.estimator,
             "seed": setup.seed, "duration_s": repr(setup.duration_s),
             "variant": repr(setup.variant), "model": repr(setup.model),
             "hydraulics": repr(setup.hydraulics), "control": repr(setup.control),
             "scenario": scenario}
    if setup.tensioner is not None:
        ident["tensioner"] = tensioner_identity(setup.tensioner)
    if setup.machine.name != DEFAULT_MACHINE:
        ident["machine"] = str(setup.machine.file)
    text = json.dumps(ident, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def tensioner_identity(tensioner: Any) -> str:
    """The tensioner file's validated content and, for an FMU, the hash of the FMU file."""
    text = repr((tensioner.passive, tensioner.fmu))
    if tensioner.description is not None:
        text += hashlib.sha256(tensioner.description.path.read_bytes()).hexdigest()
    return text


def _fixed_overrides(spec: SweepSpec) -> dict[str, Any]:
    """The spec's ``set`` items as ``{"KIND.TABLE.KEY": value}``; a key that is also swept
    is an error."""
    items = spec.table.set or ()
    try:
        by_kind = parse_overrides(list(items))
    except ParameterError as exc:
        raise ParameterError(f"{spec.where()} [sweep].set: {exc}") from None
    fixed = {f"{kind}.{key}": value for kind, keys in by_kind.items()
             for key, value in keys.items()}
    for i, p in enumerate(spec.table.parameters):
        if p.key in fixed:
            raise ParameterError(f"{spec.where()} [[sweep.parameters]][{i}].key = {p.key!r} "
                                 "is also fixed in [sweep].set; give it in one place")
    return fixed


def plan(spec: SweepSpec) -> list[PlannedRun]:
    """Every run of ``spec``, each validated by :func:`trackmj.sim.setup.prepare` (the
    same checks as ``trackmj run``); ParameterError naming the spec and the run if one is
    invalid, before anything runs."""
    from trackmj.executor import RunSpec, overrides_tuple
    from trackmj.sim.setup import prepare

    table = spec.table
    points = parameter_points(spec)
    fixed = _fixed_overrides(spec)
    n_runs = (len(spec.scenarios()) * len(points) * len(table.architectures)
              * len(table.controllers or (None,)) * len(table.seeds))
    if n_runs > MAX_RUNS:
        raise ParameterError(f"{spec.where()}: {n_runs} runs; a sweep has at most "
                             f"{MAX_RUNS} (fewer values, or method = 'lhs')")
    files = {"model": spec.path(table.model), "hydraulics": spec.path(table.hydraulics),
             "control": spec.path(table.control), "tensioner": spec.path(table.tensioner),
             "machine": (table.machine if table.machine is None or table.machine in names()
                         else spec.path(table.machine))}
    inputs = json.dumps({"files": {k: v for k, v in files.items() if v},
                         "set": list(table.set or ())}, sort_keys=True)
    runs = []
    for scenario, (index, point), arch, controller in itertools.product(
            spec.scenarios(), enumerate(points), table.architectures,
            table.controllers or (None,)):
        overrides = fixed | point
        try:
            setup = prepare(scenario, architecture=arch, controller=controller,
                            estimator=table.estimator, duration=table.duration_s,
                            variant=table.variant, overrides=overrides, **files)
        except ParameterError as exc:
            shown = ", ".join(f"{k} = {v:g}" for k, v in point.items()) or "no parameters"
            raise ParameterError(f"{spec.where()}: the run of {Path(scenario).name} {arch} "
                                 f"at point {index} ({shown}) is invalid: {exc}") from None
        base = RunSpec(scenario=scenario, architecture=arch, controller=setup.controller,
                       estimator=setup.estimator, duration=setup.duration_s,
                       variant=setup.variant.name, overrides=overrides_tuple(overrides),
                       **files)
        identity = {"point": index, "scenario": setup.scenario.name, "architecture": arch,
                    "controller": setup.controller, "estimator": setup.estimator,
                    "variant": setup.variant.name, "duration_s": setup.duration_s,
                    "inputs": inputs}
        for seed in table.seeds:
            seeded = dataclasses.replace(setup, seed=seed)
            key = _run_key(seeded)
            runs.append(PlannedRun(key, dataclasses.replace(base, seed=seed), index,
                                   dict(point), {"run_key": key, **identity, "seed": seed}))
    return runs


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


def _row(run: PlannedRun, outcome: Any) -> dict[str, Any]:
    row: dict[str, Any] = dict(run.identity) | dict(run.values)
    if outcome.ok:
        row |= flatten_metrics(outcome.result.metrics)
    row["wall_time_s"] = outcome.wall_time_s
    row["error"] = outcome.error
    return row


# ----------------------------------------------------------------------------- table

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


def is_key_column(name: str) -> bool:
    """Whether results column ``name`` holds a swept key (``KIND.TABLE.KEY``)."""
    kind, dot, _ = name.partition(".")
    return bool(dot) and kind in FILE_KINDS


def column_unit(name: str) -> str:
    """Unit of a results column: a swept key's declared unit, else its name's suffix."""
    if is_key_column(name):
        return key_unit(name)
    if name in ("point", "seed"):
        return "1"
    return unit_from_name(name.rsplit(".", 1)[-1]) or ""


def _table(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Arrow table of the rows: identity, swept keys, metrics, wall time, error; a row
    lacking a column (another spec, a metric added later) holds null there."""
    import pyarrow as pa

    names: dict[str, None] = dict.fromkeys(IDENTITY)
    for row in rows:
        names |= dict.fromkeys(k for k in row if is_key_column(k))
    for row in rows:
        names |= dict.fromkeys(k for k in row if k not in ("wall_time_s", "error"))
    names |= dict.fromkeys(("wall_time_s", "error"))
    arrays, fields = [], []
    for name in names:
        values = [row.get(name) for row in rows]
        dtype = _column_type(name, values)
        if dtype == pa.float64():
            values = [None if v is None else float(v) for v in values]
        arrays.append(pa.array(values, type=dtype))
        unit = column_unit(name)
        fields.append(pa.field(name, dtype, metadata={"unit": unit} if unit else None))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def _write_table(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    """Write the rows (in run order: scenario, architecture, controller, point, seed) as
    ``path``, atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from trackmj.io import write_bytes_atomic

    ordered = sorted(rows, key=lambda r: (*(str(r.get(k)) for k in ("scenario", "architecture",
                                                                      "controller")),
                                          r.get("point", -1), r.get("seed", -1)))
    sink = pa.BufferOutputStream()
    pq.write_table(_table(ordered), sink, compression="zstd")
    write_bytes_atomic(path, sink.getvalue().to_pybytes())


def _read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows of an existing results.parquet ([] if there is none)."""
    if not path.is_file():
        return []
    import pyarrow.parquet as pq

    rows = pq.read_table(path).to_pylist()
    return [{k: v for k, v in row.items()
             if v is not None or k == "error"} for row in rows]


def read_sweep(out_dir: str | Path) -> Any:
    """``DIR/results.parquet`` as a :class:`pandas.DataFrame` (needs pandas), one row per
    run; ``df.attrs["units"]`` maps each column to its unit (where known).

    Parameters
    ----------
    out_dir : str or Path
        The sweep's output directory (or the parquet file itself).
    """
    import pyarrow.parquet as pq

    from trackmj.results import _require

    _require("pandas", "read_sweep()", "'trackmj[pandas]'")
    path = Path(out_dir)
    path = path / RESULTS if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no sweep results here")
    table = pq.read_table(path)
    frame = table.to_pandas()
    frame.attrs["units"] = {f.name: (f.metadata or {}).get(b"unit", b"").decode()
                            for f in table.schema}
    return frame


# ----------------------------------------------------------------------------- sweep

@dataclass
class SweepSummary:
    """What a :func:`sweep` did: ``ran`` runs executed now (``failed`` of them with an
    error), ``skipped`` already in the results; ``results`` the parquet file;
    ``figures`` the figures drawn."""

    out: Path
    results: Path
    runs: int
    ran: int
    skipped: int
    failed: int
    figures: list[Path]

    def __str__(self) -> str:
        failed = f" ({self.failed} failed: their rows hold the error)" if self.failed else ""
        return (f"{self.runs} runs: {self.ran} ran now{failed}, {self.skipped} already in "
                f"{self.results} -> {self.out}")


class _DirectoryLock:
    """An exclusive lock on a sweep directory for one writer at a time."""

    def __init__(self, out: Path) -> None:
        self.path = out / ".sweep.lock"
        self._fh: Any = None

    def __enter__(self) -> _DirectoryLock:
        from trackmj.results import ResultDirectoryError

        self._fh = open(self.path, "a")   # held until __exit__
        try:
            fcntl.flock(self._fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._fh.close()
            raise ResultDirectoryError(f"{self.path.parent}: another trackmj sweep is "
                                       "writing this directory; wait for it or choose "
                                       "another --out") from None
        return self

    def __exit__(self, *exc: object) -> None:
        fcntl.flock(self._fh, fcntl.LOCK_UN)
        self._fh.close()


def _output_dir(out: Path) -> Path:
    from trackmj.results import ResultDirectoryError

    if out.exists() and not out.is_dir():
        raise ResultDirectoryError(f"--out {out}: is a file, not a directory")
    if out.is_dir() and any(p.name not in (RESULTS, SPEC_COPY, FIGURES, RUNS, ".sweep.lock")
                            and not p.name.startswith(f".{RESULTS}.") for p in out.iterdir()):
        raise ResultDirectoryError(f"--out {out}: an existing directory that holds "
                                   f"something other than a trackmj sweep ({RESULTS}, "
                                   f"{SPEC_COPY}, {FIGURES}/, {RUNS}/); refusing to write "
                                   "into it")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _run_dir_name(run: PlannedRun) -> str:
    ident = run.identity
    return (f"{ident['scenario']}-{ident['architecture']}-{ident['controller']}"
            f"-p{run.point}-s{ident['seed']}-{run.key[:8]}")


def sweep(spec: str | Path | Mapping[str, Any] | SweepSpec, out: str | Path, *,
          workers: int | None = None, scheduler: str | None = None, executor: Any = None,
          keep_runs: bool = False, retry_failed: bool = False, plot: bool = True,
          progress: bool = True, tensioner: str | Path | None = None,
          machine: str | None = None) -> SweepSummary:
    """Run a parameter study (see the module docstring for the spec and the output).

    Parameters
    ----------
    spec : str, Path, mapping or SweepSpec
        The sweep spec (see :func:`load_sweep`).
    out : str or Path
        Output directory; created, or resumed if it holds this or an earlier sweep.
    workers, scheduler : optional
        Local cluster size (default one worker per core) or an existing Dask scheduler,
        as for :class:`trackmj.executor.Executor`.
    executor : Executor, optional
        An executor already entered (its cluster is used and left running).
    keep_runs : bool
        Also write each run's result directory under ``out/runs/``.
    retry_failed : bool
        Run again the runs whose rows hold an error.
    plot : bool
        Draw the figures (:func:`plot_sweep`) at the end.
    progress : bool
        Show a progress bar over the simulated seconds of the runs.
    tensioner : str or Path, optional
        A tensioner file for every run (the CLI's ``--tensioner``; replaces the spec's).
    machine : str, optional
        A shipped machine's name or a machine file for every run (the CLI's
        ``--machine``; replaces the spec's).

    Returns
    -------
    SweepSummary
        Raises ParameterError (before any run) if the spec or a run is invalid.
    """
    spec = load_sweep(spec)
    if tensioner is not None:
        spec = dataclasses.replace(spec, table=dataclasses.replace(
            spec.table, tensioner=str(Path(tensioner).resolve())))
    if machine is not None:
        spec = dataclasses.replace(spec, table=dataclasses.replace(spec.table,
                                                                   machine=machine))
    runs = plan(spec)
    out = _output_dir(Path(out))
    results = out / RESULTS
    with _DirectoryLock(out):
        from trackmj.io import write_text_atomic
        from trackmj.results import write_result

        if spec.text:
            write_text_atomic(out / SPEC_COPY, spec.text)
        rows = {row["run_key"]: row for row in _read_rows(results)}
        todo = [r for r in runs
                if r.key not in rows or (retry_failed and rows[r.key].get("error"))]
        todo = list({r.key: r for r in todo}.values())
        by_spec = {r.spec: r for r in todo}
        failed = 0
        writer = _TableWriter(results)
        outcomes = (_outcomes([r.spec for r in todo], executor, workers, scheduler, progress)
                    if todo else iter(()))   # nothing to run starts no cluster
        try:
            for outcome in outcomes:
                run = by_spec[outcome.spec]
                rows[run.key] = _row(run, outcome)
                failed += not outcome.ok
                if keep_runs and outcome.ok:
                    write_result(outcome.result, out / RUNS / _run_dir_name(run))
                writer.changed(rows)
        finally:   # also on Ctrl-C or an error: the rows that arrived are kept
            writer.flush(rows)
        figures = plot_sweep(out, keys={r.key for r in runs}) if plot else []
    distinct = len({r.key for r in runs})   # LHS samples rounded onto one integer coincide
    return SweepSummary(out, results, distinct, len(todo), distinct - len(todo), failed,
                        figures)


class _TableWriter:
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
        _write_table(list(rows.values()), self.path)
        self.last_s = time.monotonic()
        self.period_s = max(WRITE_PERIOD_S, 20.0 * (self.last_s - start))
        self.pending = False


def _outcomes(specs: list[Any], executor: Any, workers: int | None, scheduler: str | None,
              progress: bool) -> Iterator[Any]:
    from trackmj.executor import Executor

    label = "sweep" if progress else None
    if executor is not None:
        yield from executor.as_completed(specs, progress=label)
        return
    with Executor(workers=workers, scheduler=scheduler) as ex:
        yield from ex.as_completed(specs, progress=label)


# ----------------------------------------------------------------------------- figures

DISPLAY_UNITS: dict[str, tuple[float, str]] = {
    "N": (1e-3, "kN"), "Pa": (1e-6, "MPa"), "Pa (absolute)": (1e-6, "MPa abs"),
    "J": (1e-3, "kJ"), "W": (1e-3, "kW"), "m": (1e3, "mm"), "m^2": (1e6, "mm²"),
    "m^3": (1e6, "cm³"), "m^3/s": (6e4, "L/min"), "N/m": (1e-6, "kN/mm"),
}
"""SI unit -> (scale, display unit) on the figures; other units are shown as they are."""


def _display(unit: str) -> tuple[float, str]:
    return DISPLAY_UNITS.get(unit, (1.0, unit))


def _label(name: str, unit: str) -> str:
    shown = _display(unit)[1]
    return f"{name} [{shown}]" if shown and shown != "1" else name


def plot_sweep(out_dir: str | Path, *, keys: set[str] | None = None) -> list[Path]:
    """Draw ``DIR/figures/<metric>.png`` from ``DIR/results.parquet``: for every metric
    (and the wall time) one panel per swept parameter, the metric's mean ± std over seeds
    at each parameter point; a line per case (scenario, architecture, controller, ...)
    and per combination of the other swept parameters (points that share none, e.g. Latin
    hypercube samples, stand alone). A sweep without swept parameters (e.g. a controller
    comparison) gets bars instead: a group per scenario, a bar per case within it, mean ±
    std over seeds. Failed runs are left out.

    keys: only the rows of these runs (default: every row). Returns the figure paths.
    """
    import numpy as np

    out = Path(out_dir)
    rows = [r for r in _read_rows(out / RESULTS)
            if not r.get("error") and (keys is None or r["run_key"] in keys)]
    if not rows:
        return []
    swept = sorted({k for r in rows for k in r if is_key_column(k)})
    skip = set(IDENTITY) | set(swept) | {"error"}
    metrics = sorted({k for r in rows for k in r if k not in skip
                      and isinstance(r[k], int | float)})
    paths = []
    for metric in metrics:
        values = [r.get(metric) for r in rows]
        if not any(v is not None and math.isfinite(v) for v in values):
            continue
        fig = (_metric_figure(rows, metric, swept, np) if swept
               else _case_figure(rows, metric, np))
        paths.append(_save(fig, out / FIGURES / f"{metric}.png"))
    return paths


def _save(fig: Any, path: Path) -> Path:
    import io

    from trackmj.io import write_bytes_atomic

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    write_bytes_atomic(path, buffer.getvalue())
    return path


LINE_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ((0, (5, 1, 1, 1)), "v"),
               ((0, (1, 3)), "P"))
"""Line style and marker of the lines of one case (the other swept parameters' values)."""
CONSTANT_REL = 1e-6
"""A metric whose values differ by less than this (relative) is drawn as a constant."""
MAX_LABELLED_LINES = 6
"""More lines per case than this are drawn thin and unlabelled."""


def _metric_figure(rows: list[dict[str, Any]], metric: str, swept: list[str], np: Any) -> Any:
    """One panel per swept key: the metric's mean ± std over seeds against the key, a
    colour per case, a line style per combination of the other keys."""
    import matplotlib
    from matplotlib.figure import Figure  # no pyplot: no global figure state, no backend

    cases = sorted({tuple(r.get(c) for c in CASE) for r in rows}, key=str)
    colors = matplotlib.colormaps["tab10"]
    m_scale = _display(column_unit(metric))[0]
    width, height = 4.8 * len(swept) + 0.8, 4.4
    fig = Figure(figsize=(width, height))
    axes = fig.subplots(1, len(swept), squeeze=False, sharey=True)[0]
    # fixed margins [in] instead of tight_layout, which draws the figure once more
    fig.subplots_adjust(left=0.85 / width, right=1.0 - 0.2 / width, bottom=0.6 / height,
                        top=1.0 - 0.45 / height, wspace=0.12)
    for ax, key in zip(axes, swept, strict=True):
        k_scale = _display(column_unit(key))[0]
        others = [k for k in swept if k != key]
        for c, case in enumerate(cases):
            lines: dict[tuple, dict[Any, list[float]]] = {}
            for r in rows:
                if tuple(r.get(n) for n in CASE) == case and key in r:
                    lines.setdefault(tuple(r.get(k) for k in others), {}).setdefault(
                        r[key], []).append(_finite(r.get(metric)))
            series = sorted(lines.items(), key=lambda item: [_sortable(v) for v in item[0]])
            scatter = len(series) > 1 and all(len(points) == 1 for _, points in series)
            if scatter:   # e.g. LHS samples: no two points share the other keys' values
                series = [((), {x: ys for _, points in series for x, ys in points.items()})]
            labelled = len(series) <= MAX_LABELLED_LINES
            for j, (line, points) in enumerate(series):
                x = sorted(points)
                stats = np.array([_mean_std(points[v], np) for v in x])
                style, marker = LINE_STYLES[j % len(LINE_STYLES)]
                joined = len(x) > 1 and not scatter
                ax.errorbar(np.array(x, dtype=float) * k_scale, stats[:, 0] * m_scale,
                            yerr=stats[:, 1] * m_scale, color=colors(c % 10), marker=marker,
                            ms=4, capsize=3, lw=1.0 if labelled else 0.6,
                            ls=style if joined else "none", alpha=1.0 if labelled else 0.5,
                            label=_series_label(case, cases, others, line)
                            if labelled or j == 0 else None)
        xs = [float(r[key]) for r in rows if r.get(key) is not None]
        if min(xs) > 0 and max(xs) / min(xs) > 30:
            ax.set_xscale("log")
        ax.set_xlabel(_label(key, column_unit(key)), fontsize=8)
        ax.grid(alpha=0.3)
        if len(ax.get_legend_handles_labels()[1]) > 1 or len(cases) > 1:
            ax.legend(fontsize=7, loc="best")
    values = [_finite(r.get(metric)) * m_scale for r in rows]
    finite = [v for v in values if math.isfinite(v)]
    if max(finite) - min(finite) <= CONSTANT_REL * max(abs(max(finite)), abs(min(finite))):
        middle = 0.5 * (max(finite) + min(finite))   # constant: no offset-notation noise
        half = abs(middle) * 0.05 if middle else 1.0
        axes[0].set_ylim(middle - half, middle + half)
        axes[0].yaxis.get_major_formatter().set_useOffset(False)
        fig.text(0.005, 0.01, f"constant within {CONSTANT_REL:g} (relative) over the sweep",
                 ha="left", va="bottom", fontsize=7, color="0.4")
    axes[0].set_ylabel(_label(metric, column_unit(metric)))
    n_seeds = len({r["seed"] for r in rows})
    case_text = _case_label(cases[0], cases) if len(cases) == 1 else f"{len(cases)} cases"
    fig.suptitle(f"{metric}: mean ± std over {n_seeds} seed{'s' * (n_seeds > 1)} "
                 f"({case_text})", fontsize=10)
    return fig


HATCHES = ("", "//", "..", "xx", "\\\\", "++", "oo", "--")
"""Bar hatches, so that the cases of a bar figure read in grayscale too."""


def _case_figure(rows: list[dict[str, Any]], metric: str, np: Any) -> Any:
    """Grouped bars: a group per scenario, a bar per other case (architecture, controller,
    ...: the fields that differ) with its mean ± std over seeds and its value above it."""
    import matplotlib
    from matplotlib.figure import Figure

    scenarios = sorted({r["scenario"] for r in rows}, key=_scenario_order)
    cases = sorted({tuple(r.get(c) for c in CASE[1:]) for r in rows}, key=str)
    labels = [_case_label(("", *case), [("", *c) for c in cases]).strip() for case in cases]
    colors = matplotlib.colormaps["tab10"]
    m_scale = _display(column_unit(metric))[0]
    width, height = max(6.0, 1.1 * len(scenarios) * max(1, len(cases)) / 2 + 2.6), 4.4
    fig = Figure(figsize=(width, height))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.85 / width, right=1.0 - 1.7 / width, bottom=0.6 / height,
                        top=1.0 - 0.45 / height)
    bar = 0.8 / len(cases)
    measured = np.zeros(len(scenarios), bool)
    for j, (case, label) in enumerate(zip(cases, labels, strict=True)):
        stats = np.array([_mean_std([_finite(r.get(metric)) for r in rows
                                     if r["scenario"] == sc
                                     and tuple(r.get(c) for c in CASE[1:]) == case], np)
                          for sc in scenarios]) * m_scale
        measured |= np.isfinite(stats[:, 0])
        x = np.arange(len(scenarios)) - 0.4 + bar * (j + 0.5)
        ax.bar(x, stats[:, 0], bar, yerr=stats[:, 1], capsize=2, color=colors(j % 10),
               hatch=HATCHES[j % len(HATCHES)], edgecolor="black", lw=0.5, label=label)
        for xi, (value, std) in zip(x, stats, strict=True):   # above the error bar
            if math.isfinite(value):
                ax.text(xi, value + std if value >= 0 else value - std, f"{value:.3g}",
                        ha="center", va="bottom" if value >= 0 else "top", fontsize=6)
    for i in np.flatnonzero(~measured):    # e.g. a settling time where nothing steps
        ax.text(i, 0.0, "no value", ha="center", va="bottom", fontsize=7, color="0.4")
    ax.set_xticks(range(len(scenarios)), scenarios)
    ax.set_xlim(-0.5, len(scenarios) - 0.5)      # groups without a value keep their place
    ax.axhline(0.0, color="black", lw=0.6)
    ax.grid(axis="y", alpha=0.3)
    ax.set_ylabel(_label(metric, column_unit(metric)))
    ax.set_xlabel("scenario")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    n_seeds = len({r["seed"] for r in rows})
    fig.suptitle(f"{metric}: mean ± std over {n_seeds} seed{'s' * (n_seeds > 1)}",
                 fontsize=10)
    return fig


def _scenario_order(name: str) -> tuple[int, str]:
    """Built-in scenarios in their order (W1-W5, NL1), then the others by name."""
    builtin = _builtin_scenarios()
    return (builtin.index(name), "") if name in builtin else (len(builtin), name)


def _finite(value: Any) -> float:
    return math.nan if value is None else float(value)


def _sortable(value: Any) -> tuple[int, Any]:
    return (1, 0.0) if value is None else (0, value)


def _series_label(case: tuple, cases: list[tuple], others: list[str], line: tuple) -> str:
    """Legend text: the case (if there are several) and the other keys' values."""
    parts = [_case_label(case, cases)] if len(cases) > 1 else []
    for key, value in zip(others, line, strict=False):   # () for scattered samples
        if value is not None:
            scale, unit = _display(column_unit(key))
            shown = f" {unit}" if unit and unit != "1" else ""
            parts.append(f"{_short(key)} = {value * scale:.4g}{shown}")
    return ", ".join(parts) or _case_label(case, cases)


def _mean_std(values: list[float], np: Any) -> tuple[float, float]:
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return math.nan, 0.0
    return float(np.mean(finite)), float(np.std(finite)) if len(finite) > 1 else 0.0


def _short(key: str) -> str:
    return key.rsplit(".", 1)[-1]


def _case_label(case: tuple, cases: list[tuple]) -> str:
    """The case fields that differ between cases (all of them if there is one case:
    scenario, architecture, controller)."""
    varying = [i for i in range(len(CASE)) if len({c[i] for c in cases}) > 1]
    shown = varying or [0, 1, 2]
    return " ".join(str(case[i]) for i in shown if CASE[i] != "inputs") or "runs"

