"""Parameter studies (``trackmj sweep``): many runs of a TOML spec on the Dask executor,
one row per run in ``DIR/results.parquet``, resumable, with a figure per metric.

Spec file (read by the one validator, :mod:`trackmj.validator`; every key but ``scenario`` /
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
  Each column's unit is in its Arrow field metadata (``unit``) where the name states one,
  and all of them in the schema metadata ``units`` (JSON); see :mod:`trackmj.study.campaign`.
- ``sweep.toml``: the spec as given; ``figures/<metric>.png``: each metric against each
  swept parameter, mean ± std over seeds (without swept parameters: bars per scenario and
  case); ``runs/<case>/``: every run's result directory
  with ``keep_runs``.

Resume: a run whose ``run_key`` already has a row is skipped (a failed one too, unless
``retry_failed``). The key is the run's identity (:func:`trackmj.study.identity.run_key`: the
validated model, hydraulic, control and scenario parameters after overrides, the variant,
architecture, controller, estimator, seed, duration, tensioner and FMU file hashes and the
hash of trackmj's source); a changed file or a changed code changes it. Rows of runs the
current spec does not ask for are kept. A ``duration_s`` that would cut off a scenario's
step, ramp, pulse or drop moves the events the spec does not set itself inside the run
(:func:`trackmj.scenarios.events.moved_events`). Figures are drawn for the metrics that vary
across the runs, once: a resumed sweep that makes no run keeps the figures there are.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypedDict, TypeVar, overload

import numpy as np

from trackmj.io import write_text_atomic
from trackmj.machines.assembly import names
from trackmj.results.columns import key_field
from trackmj.results.store import _require
from trackmj.scenarios.events import moved_events
from trackmj.scenarios.load import builtin_names, load_scenario
from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS
from trackmj.sim.entries import by_name, choices
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.sim.setup import prepare
from trackmj.study.campaign import (
    RESULTS,
    PlannedRun,
    Store,
    plan_run,
    read_rows,
    read_units,
    run_campaign,
)
from trackmj.study.executor import RunSpec, overrides_tuple
from trackmj.validator import (
    FILE_KINDS,
    Location,
    ParameterError,
    Parameters,
    build,
    load_file,
    param,
    parse_overrides,
)

SPEC_COPY = "sweep.toml"
FIGURES = "figures"
MAX_RUNS = 100_000
"""Largest sweep accepted: a grid grows as the product of its value counts."""
KEY_PATTERN = rf"({'|'.join(FILE_KINDS)})(\.[A-Za-z0-9_]+)+"
T = TypeVar("T")


def _given(value: T | None, what: str) -> T:
    """``value`` of an optional spec key that the spec's ``cross_check`` requires here."""
    if value is None:
        raise ValueError(f"{what} is missing (the spec's cross_check requires it)")
    return value


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
                                 doc="a built-in scenario (W1-W5, NL1) or a scenario file")
    scenarios: tuple[str, ...] | None = param(max_len=4096, default=None,
                                              doc="several scenarios (instead of scenario)")
    duration_s: float | None = param(1e-3, 3600.0, default=None,
                                     doc="simulated time per run (default: the scenario's)")
    seeds: tuple[int, ...] = param(0, 2**32 - 1, unit="1", default=(0,),
                                   doc="noise and terrain seeds; every point runs each")
    architectures: tuple[str, ...] = param(choices=choices(ARCHITECTURES),
                                           default=(REFERENCE_ARCHITECTURE,),
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

    @overload
    def path(self, value: str) -> str: ...
    @overload
    def path(self, value: None) -> None: ...
    @overload
    def path(self, value: str | None) -> str | None: ...

    def path(self, value: str | None) -> str | None:
        """A file of the spec as an absolute path string (built-in scenario names stay)."""
        if value is None:
            return None
        if value.upper() in {name.upper() for name in builtin_names()}:
            return value
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else (self.base / path).resolve())

    def scenarios(self) -> tuple[str, ...]:
        """The spec's scenarios, files as absolute paths (``scenario`` or ``scenarios``:
        the spec gives exactly one)."""
        names = self.table.scenarios or (_given(self.table.scenario, "scenario"),)
        return tuple(self.path(n) for n in names)


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

def _typed(spec: SweepSpec, index: int, value: float) -> float | int:
    """``value`` as the type the swept key's file declares (int keys take integers)."""
    p = spec.table.parameters[index]
    found = key_field(p.key)
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
    lo, hi = float(_given(p.low, "low")), float(_given(p.high, "high"))
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
    lhs = table.method == "lhs"
    n_points = _given(table.samples, "samples") if lhs else math.prod(
        len(p.values) if p.values is not None else int(_given(p.count, "count"))
        for p in table.parameters)
    if n_points > MAX_RUNS:
        raise ParameterError(f"{spec.where()}: {n_points} parameter points; a sweep has at "
                             f"most {MAX_RUNS} runs (fewer values, or method = 'lhs')")
    raw = _lhs_points(table, int(n_points)) if lhs else _grid_points(table)
    return [{key: _typed(spec, i, value) for i, (key, value) in enumerate(point.items())}
            for point in raw]


def _lhs_points(table: SweepTable, n: int) -> list[dict[str, float]]:
    """``n`` Latin-hypercube points (see :func:`parameter_points`), by key."""
    rng = np.random.default_rng(table.seed)
    columns = []
    for p in table.parameters:
        fraction = (rng.permutation(n) + rng.random(n)) / n
        columns.append(_range(p, fraction.tolist()))
    return [dict(zip((p.key for p in table.parameters), row, strict=True))
            for row in zip(*columns, strict=True)]


def _grid_points(table: SweepTable) -> list[dict[str, float]]:
    """Every combination of the keys' grid values, the first key varying slowest."""
    axes = []
    for p in table.parameters:
        if p.values is not None:
            axes.append(list(p.values))
        else:
            count = int(_given(p.count, "count"))
            axes.append(_range(p, [k / (count - 1) for k in range(count)]
                               if count > 1 else [0.0]))
    return [dict(zip((p.key for p in table.parameters), combo, strict=True))
            for combo in itertools.product(*axes)]


# ----------------------------------------------------------------------------- runs

class _Files(TypedDict):
    """The files of every run of a spec (absolute paths; a machine may be a shipped name)."""

    model: str | None
    hydraulics: str | None
    control: str | None
    tensioner: str | None
    machine: str | None


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
    """Every run of ``spec`` (:class:`trackmj.study.campaign.PlannedRun`), each validated by
    :func:`trackmj.sim.setup.prepare` (the same checks as ``trackmj run``); ParameterError
    naming the spec and the run if one is invalid, before anything runs. A duration that
    would cut off one of a scenario's events moves the events inside the run
    (:func:`trackmj.scenarios.events.moved_events`); the moves are fixed overrides of the run."""
    table = spec.table
    points = parameter_points(spec)
    fixed = _fixed_overrides(spec)
    n_runs = (len(spec.scenarios()) * len(points) * len(table.architectures)
              * len(table.controllers or (None,)) * len(table.seeds))
    if n_runs > MAX_RUNS:
        raise ParameterError(f"{spec.where()}: {n_runs} runs; a sweep has at most "
                             f"{MAX_RUNS} (fewer values, or method = 'lhs')")
    files: _Files = {
        "model": spec.path(table.model), "hydraulics": spec.path(table.hydraulics),
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
            if table.duration_s is not None:
                given = {k.partition(".")[2]: v for k, v in overrides.items()
                         if k.startswith("scenario.")}
                moves = moved_events(load_scenario(scenario, overrides=given),
                                     table.duration_s)
                overrides = {f"scenario.{k}": v for k, v in moves.items()
                             if k not in given} | overrides
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
        for seed in table.seeds:
            seeded = dataclasses.replace(setup, seed=seed)
            runs.append(plan_run(
                dataclasses.replace(base, seed=seed), setup=seeded, point=index,
                values=point, inputs=inputs,
                name=f"{setup.scenario.name}-{arch}-{setup.controller}-p{index}-s{seed}"))
    return [dataclasses.replace(r, name=f"{r.name}-{r.key[:8]}") for r in runs]


def read_sweep(out_dir: str | Path) -> Any:
    """``DIR/results.parquet`` as a :class:`pandas.DataFrame` (needs pandas), one row per
    run; ``df.attrs["units"]`` maps each column to its unit (where known).

    Parameters
    ----------
    out_dir : str or Path
        The sweep's output directory (or the parquet file itself).
    """
    pandas = _require("pandas", "read_sweep()", "'trackmj[pandas]'")
    path = Path(out_dir)
    path = path / RESULTS if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no sweep results here")
    frame = pandas.read_parquet(path)
    frame.attrs["units"] = read_units(path)
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
        as for :class:`trackmj.study.executor.Executor`.
    executor : Executor, optional
        An executor already entered (its cluster is used and left running).
    keep_runs : bool
        Also write each run's result directory under ``out/runs/``.
    retry_failed : bool
        Run again the runs whose rows hold an error.
    plot : bool
        Draw the figures (:func:`plot_sweep`) at the end: every figure when a run was made
        now, else only the missing ones.
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
    with Store(out, "sweep", markers=(SPEC_COPY, FIGURES)) as store:
        if spec.text:
            write_text_atomic(store.out / SPEC_COPY, spec.text)
        made = run_campaign(store, runs, executor=executor, workers=workers,
                            scheduler=scheduler, progress="sweep" if progress else None,
                            keep_runs=keep_runs, retry_failed=retry_failed)
        figures = (plot_sweep(store.out, keys={r.key for r in runs},
                              redraw=bool(made.outcomes)) if plot else [])
    distinct = len({r.key for r in runs})   # LHS samples rounded onto one integer coincide
    ran = len(made.outcomes)
    return SweepSummary(store.out, store.results, distinct, ran, distinct - ran,
                        len(made.failed), figures)


# ----------------------------------------------------------------------------- figures

def plot_sweep(out_dir: str | Path, *, keys: set[str] | None = None,
               redraw: bool = True) -> list[Path]:
    """Draw ``DIR/figures/<metric>.png`` from ``DIR/results.parquet`` for every metric that
    varies across the runs (:func:`trackmj.results.figure_sweep.sweep_figures`); ``keys``: only
    the rows of these runs (default: every row); ``redraw=False`` keeps the figures that exist.
    Returns the paths of the figures of the varying metrics (drawn now or kept)."""
    # matplotlib (which the figure module switches to Agg) is heavy: loaded only to draw
    from trackmj.results.figure_sweep import sweep_figures

    out = Path(out_dir)
    rows = [r for r in read_rows(out / RESULTS)
            if not r.get("error") and (keys is None or r["run_key"] in keys)]
    return sweep_figures(rows, out / FIGURES, redraw=redraw)
