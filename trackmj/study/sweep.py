"""Parameter studies (``trackmj sweep``): many runs of a TOML spec on the Dask executor,
one row per run in ``DIR/results.parquet``, resumable, summed up in a table (one row per
point) and a figure per swept key.

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
LHS sample is rounded). Every run is validated before the first one starts: a missing file
is an error naming the spec file, the key and the path; a bad key or value, one naming the
spec file, the parameter and the allowed range.

Output directory ``DIR``:

- ``results.parquet``: one row per run, rewritten atomically as runs finish (at most every
  2 s while they do, and at the end, also after Ctrl-C or an error).
  Columns: ``run_key`` (identity of the run's inputs), ``point`` (index of the parameter
  point), ``scenario``, ``machine`` (the name in its machine file), ``architecture``,
  ``controller``, ``estimator``, ``variant``, ``seed``, ``duration_s``, ``inputs`` (JSON:
  files and fixed overrides of the spec), one column per swept key (named by the key), every
  scalar metric (nested metric tables flattened as ``table.key``, e.g. ``energy_J.pump``),
  ``wall_time_s`` (the run's wall time in its worker) and ``error`` (null, or ``"Type:
  message"`` for a run that failed).
  Each column's unit is in its Arrow field metadata (``unit``) where the name states one,
  and all of them in the schema metadata ``units`` (JSON); see :mod:`trackmj.study.campaign`.
- ``summary.md`` and ``summary.csv`` (:func:`summarize`, :func:`summary_markdown`,
  :func:`summary_csv`): one row per point (case and parameter point) of every row in
  ``results.parquet`` (this spec's and those of earlier sweeps into ``DIR``), the varied
  case fields and swept keys first (values as given), then the engineering
  metrics (:data:`ENGINEERING_METRICS`) as mean ± std over seeds (population std, ddof = 0;
  one seed: the value) in display units (the CSV: ``KEY_mean`` / ``KEY_std`` in SI), the
  diagnostics (:data:`DIAGNOSTICS`: wall time, real-time factor, longest solve, overruns;
  machine-dependent) last and marked. Rewritten at the end of every sweep.
- ``figures/<key>.png`` per swept key (without swept keys ``figures/cases.png``, bars per
  scenario and case): the engineering metrics as panels against the key, a line per case
  and combination of the other keys, error bars (± std) only with 2+ seeds;
  ``figures/diagnostics.png`` only with ``diagnostics`` (see
  :mod:`trackmj.results.figure_sweep`).
- ``sweep.toml``: the spec as given; ``runs/<case>/``: every run's result directory with
  ``keep_runs``.

Resume: a run whose ``run_key`` already has a row is skipped (a failed one too, unless
``retry_failed``). The key is the run's identity (:func:`trackmj.study.identity.run_key`: the
validated model, hydraulic, control and scenario parameters after overrides, the variant,
architecture, controller, estimator, seed, duration, tensioner and FMU file hashes and the
hash of trackmj's source); a changed file or a changed code changes it. Rows of runs the
current spec does not ask for are kept, and the summary and the figures show them beside
the spec's (as ``--plot`` does; the sweep says how many points are not the spec's). A
``duration_s`` that would cut off a scenario's step, ramp, pulse or drop moves the events
the spec does not set itself inside the run (:func:`trackmj.scenarios.events.moved_events`).
Figures are drawn once: a resumed sweep that makes no run keeps the figures there are.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import itertools
import json
import math
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypedDict, TypeVar, overload

import numpy as np

from trackmj.io import write_text_atomic
from trackmj.machines.assembly import names, resolve
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.results.columns import column_unit, is_key_column, key_field
from trackmj.results.metrics import METRIC_DISPLAY, METRICS
from trackmj.results.seed_stats import mean_std
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
from trackmj.study.report_stats import mean_std as format_mean_std
from trackmj.validator import (
    FILE_KINDS,
    Location,
    ParameterError,
    Parameters,
    build,
    load_file,
    param,
    parse_overrides,
    split_override_key,
)

SPEC_COPY = "sweep.toml"
FIGURES = "figures"
MAX_RUNS = 100_000
"""Largest sweep accepted: a grid grows as the product of its value counts."""
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

    key: str = param(max_len=200,
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
        split_override_key(self.key, f"{at.key('key')} = {self.key!r}")
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
        if _builtin(value):
            return value
        path = Path(value).expanduser()
        return str(path if path.is_absolute() else (self.base / path).resolve())

    def scenarios(self) -> tuple[str, ...]:
        """The spec's scenarios, files as absolute paths (``scenario`` or ``scenarios``:
        the spec gives exactly one)."""
        names = self.table.scenarios or (_given(self.table.scenario, "scenario"),)
        return tuple(self.path(n) for n in names)


def _builtin(scenario: str) -> bool:
    """Whether ``scenario`` names a built-in scenario (any case), not a file."""
    return scenario.upper() in {name.upper() for name in builtin_names()}


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


def _check_files(spec: SweepSpec, files: _Files) -> None:
    """Every file the spec names exists and its machine loads; else ParameterError naming
    the spec, the key and the path, before the runs are validated (which would blame the
    first run)."""
    table = spec.table
    named = ([("scenario", table.scenario)] if table.scenarios is None else
             [(f"scenarios[{i}]", name) for i, name in enumerate(table.scenarios)])
    named += [(kind, getattr(table, kind)) for kind in ("model", "hydraulics", "control",
                                                        "tensioner")]
    for key, value in named:
        if value is not None and not _builtin(value) and not Path(spec.path(value)).is_file():
            raise ParameterError(f"{spec.where()} [sweep].{key} = {value!r}: no such file "
                                 f"{spec.path(value)}")
    try:
        resolve(files["machine"])
    except ParameterError as exc:
        raise ParameterError(f"{spec.where()} [sweep].machine = {table.machine!r}: "
                             f"{exc}") from None


def plan(spec: SweepSpec) -> list[PlannedRun]:
    """Every run of ``spec`` (:class:`trackmj.study.campaign.PlannedRun`), each validated by
    :func:`trackmj.sim.setup.prepare` (the same checks as ``trackmj run``); ParameterError
    naming the spec and the key of a missing file or a bad machine, or the run if one is
    invalid, before anything runs. A duration that
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
    _check_files(spec, files)
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


# ----------------------------------------------------------------------------- summary

SUMMARY_CSV = "summary.csv"
SUMMARY_MD = "summary.md"
CASE = ("scenario", "machine", "architecture", "controller", "estimator", "variant",
        "duration_s", "inputs")
"""Columns of a results row that name its case; a case and the swept keys' values make a
point of the summary (its seeds averaged)."""
FILE_FIELDS = ("model", "hydraulics", "control", "tensioner")
"""The files a spec gives every run (``inputs``), by kind."""
CASE_FIELDS = ("scenario", "machine", "architecture", "controller", "estimator", "variant",
               "duration_s", *FILE_FIELDS, "set")
"""The fields of a point's case as the summary shows them: :data:`CASE` with ``inputs``
read: each of :data:`FILE_FIELDS` by its file name (its path where two files of a kind
share a name; absent: the machine's own) and ``set``, the spec's fixed overrides."""
ENGINEERING_METRICS = {
    "rmse_lp_N": "RMSE lp", "rmse_N": "RMSE raw", "peak_error_lp_N": "peak error lp",
    "ripple_rms_N": "ripple RMS", "overshoot_lp_N": "overshoot lp",
    "settling_time_lp_s": "settling lp", "disturbance_peak_error_lp_N": "dist. peak lp",
    "recovery_time_lp_s": "recovery lp", "fluctuation_N": "fluctuation ±",
    "constraint_violation_s": "outside F limits", "p_head_max_Pa": "p_head max",
    "energy_J.pump": "pump energy", "valve_switch_rate_Hz": "valve switching"}
"""The engineering metrics of the summary and the figures, in this order, each with its
short heading in the table (labels and display units from
:data:`trackmj.results.metrics.METRIC_DISPLAY`, listed under the table)."""
DIAGNOSTIC_MARK = "diag."
"""Marks the diagnostics' headers in summary.md."""
NOTE_WIDTH = 92
"""The notes under the summary's table are wrapped at this many characters."""
LOWPASS_COLUMN = "evaluation.lowpass_cutoff_Hz"
"""The results column of a run's low-pass cut-off [Hz] (named under the table)."""


@dataclass(frozen=True)
class Column:
    """A metric column of the summary: results column ``key`` in SI ``si_unit``, shown as
    ``label`` (headed ``short`` in the table) in display ``unit`` (shown value = ``scale`` ×
    SI value); ``diagnostic``: a figure of the computer that ran the sweep (wall clock,
    load), not of the design."""

    key: str
    label: str
    scale: float
    unit: str
    si_unit: str
    short: str
    diagnostic: bool = False

    @property
    def title(self) -> str:
        """Label and display unit: "tension RMSE, low-pass [kN]"."""
        return f"{self.label} [{self.unit}]" if self.unit else self.label

    @property
    def header(self) -> str:
        """The column's heading in summary.md: short words and display unit ("RMSE lp
        [kN]"), diagnostics marked."""
        shown = f"{self.short} [{self.unit}]" if self.unit else self.short
        return f"{DIAGNOSTIC_MARK} {shown}" if self.diagnostic else shown

    @property
    def csv_headers(self) -> tuple[str, str]:
        """The headings of its mean and std columns in summary.csv (SI unit; diagnostics
        marked)."""
        mark = " (diagnostic)" if self.diagnostic else ""
        return (f"{self.key}_mean [{self.si_unit}]{mark}",
                f"{self.key}_std [{self.si_unit}]{mark}")


def _engineering(key: str) -> Column:
    label, scale, unit = METRIC_DISPLAY[key]
    return Column(key, label, scale, unit, METRICS[key].unit, ENGINEERING_METRICS[key])


DIAGNOSTICS = (
    Column("wall_time_s", "wall time of a run", 1.0, "s", "s", "wall time", diagnostic=True),
    Column("real_time_factor", "real-time factor (simulated / wall)", 1.0, "×", "1",
           "real-time", diagnostic=True),
    Column("solve_time_max_s", "longest controller solve", 1e3, "ms", "s", "solve max",
           diagnostic=True),
    Column("controller_overruns", "controller overruns (solve > period)", 1.0, "", "1",
           "overruns", diagnostic=True))
"""The diagnostics of the summary (last columns): machine-dependent, drawn only when asked."""


@dataclass(frozen=True)
class PointRow:
    """One row of the summary: a sweep point of one case, its seeds averaged. ``case``: the
    case fields (:data:`CASE_FIELDS`) -> value; ``values``: swept key -> value as given (SI, the
    key's unit); ``seeds``: the seeds of its finished runs; ``failed``: how many of its runs
    ended with an error; ``samples``: metric -> its value in each finished run (SI, NaN where
    a run has none)."""

    case: Mapping[str, Any]
    values: Mapping[str, Any]
    seeds: tuple[int, ...]
    failed: int
    samples: Mapping[str, tuple[float, ...]]

    def stats(self, key: str) -> tuple[float, float, int]:
        """(mean, std, count) of metric ``key`` over the point's seeds [SI]: the population
        std (ddof = 0) of the finite values (:func:`trackmj.results.seed_stats.mean_std`)."""
        return mean_std(self.samples.get(key, ()))


@dataclass(frozen=True)
class PointTable:
    """The summary of a sweep (:func:`summarize`): ``rows``, one per point, ordered by the
    ``varied`` columns (the case fields that differ between rows, then the swept keys);
    ``metrics``: the engineering metrics with a value in some run; ``missing``: those with
    none (a step metric where nothing steps); ``lowpass_Hz``: the low-pass cut-offs of the
    runs' ``_lp`` metrics [Hz]; ``superseded``: rows left out for a newer one of the same
    point and seed; ``diagnostics``: :data:`DIAGNOSTICS`; ``machine``: the one machine whose
    rows it holds when asked for one (``--machine``), ``left_out`` the other machines' rows."""

    varied: tuple[str, ...]
    rows: tuple[PointRow, ...]
    metrics: tuple[Column, ...]
    missing: tuple[Column, ...]
    lowpass_Hz: tuple[float, ...] = ()
    superseded: int = 0
    diagnostics: tuple[Column, ...] = DIAGNOSTICS
    machine: str | None = None
    left_out: int = 0

    @property
    def columns(self) -> tuple[Column, ...]:
        """The metric columns in table order: engineering metrics, then diagnostics."""
        return self.metrics + self.diagnostics

    @property
    def seeds(self) -> tuple[int, ...]:
        """Every seed of a finished run, sorted."""
        return tuple(sorted({s for row in self.rows for s in row.seeds}))


def _number(value: Any) -> float:
    """A results cell as a float (NaN if absent or not a number)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return math.nan
    return float(value)


def _order(field: str, value: Any, builtin: Sequence[str]) -> tuple[int, float, str]:
    """Sort key of a varied column's value: ``builtin`` scenarios in their order, numbers by
    value, other text by name, absent values last."""
    if value is None:
        return (3, 0.0, "")
    if field == "scenario" and value in builtin:
        return (0, float(builtin.index(value)), "")
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (1, float(value), "")
    return (2, 0.0, str(value))


def _machine(row: Mapping[str, Any]) -> str:
    """The name of a results row's machine: the one the row holds; a row written before
    that column: the machine ``inputs`` names (:func:`_machine_name`), else the default."""
    if row.get("machine"):
        return str(row["machine"])
    given = json.loads(row.get("inputs") or "{}").get("files", {}).get("machine")
    return _machine_name(given) if given else DEFAULT_MACHINE


@functools.cache
def _machine_name(given: str) -> str:
    """The name of a shipped machine or machine file ``given``; a file that no longer
    loads: its file name."""
    try:
        return resolve(given).name
    except ParameterError:
        return Path(given).name


def _case(case: tuple) -> dict[str, Any]:
    """The case fields (:data:`CASE_FIELDS`) of a results row's :data:`CASE` values (its
    machine by name, :func:`_machine`), files as full paths."""
    fields: dict[str, Any] = dict(zip(CASE, case, strict=True))
    inputs = json.loads(fields.get("inputs") or "{}")
    files, items = inputs.get("files", {}), inputs.get("set", [])
    fields |= {kind: files.get(kind) for kind in FILE_FIELDS}
    fields["set"] = ", ".join(items) or None
    return {f: fields.get(f) for f in CASE_FIELDS}


def _file_names(cases: Sequence[dict[str, Any]]) -> None:
    """Each file of ``cases`` (see :data:`FILE_FIELDS`) shown by its file name, in place;
    by its full path where two files of one kind share a name."""
    for kind in FILE_FIELDS:
        paths = {c[kind] for c in cases if c[kind]}
        names = [Path(p).name for p in paths]
        for c in cases:
            if c[kind] and names.count(Path(c[kind]).name) == 1:
                c[kind] = Path(c[kind]).name


def summarize(rows: Sequence[Mapping[str, Any]]) -> PointTable:
    """The sweep's summary from results rows (:func:`trackmj.study.campaign.read_rows`,
    failed runs included: they are counted, not averaged): a row per case and parameter
    point with every metric's values over its seeds. Of several rows of one point and seed
    (runs of earlier code or file contents kept in the results) the last is used: the
    newest, as the campaign appends new rows after the old ones of the same point and seed
    (:func:`trackmj.study.campaign.write_table` sorts stably); they are counted in
    ``superseded``."""
    swept = list(dict.fromkeys(k for r in rows for k in r if is_key_column(k)))
    groups: dict[tuple[tuple, tuple], dict[Any, Mapping[str, Any]]] = {}
    for r in rows:
        case = tuple(_machine(r) if c == "machine" else r.get(c) for c in CASE)
        point = (case, tuple(r.get(k) for k in swept))
        groups.setdefault(point, {})[r.get("seed")] = r     # the newest row of each seed
    superseded = len(rows) - sum(len(by_seed) for by_seed in groups.values())
    cases = {case: _case(case) for case, _ in groups}
    _file_names(list(cases.values()))
    varied = tuple([f for f in CASE_FIELDS if len({str(c[f]) for c in cases.values()}) > 1]
                   + swept)
    keys = [*ENGINEERING_METRICS, *(c.key for c in DIAGNOSTICS)]
    points = []
    for (case, values), by_seed in groups.items():
        runs = list(by_seed.values())
        done = [r for r in runs if not r.get("error")]
        points.append(PointRow(
            cases[case], {k: v for k, v in zip(swept, values, strict=True) if v is not None},
            tuple(sorted(int(r["seed"]) for r in done)), len(runs) - len(done),
            {m: tuple(_number(r.get(m)) for r in done) for m in keys}))
    builtin = builtin_names()
    points.sort(key=lambda p: [_order(k, p.case[k] if k in p.case else p.values.get(k),
                                      builtin) for k in varied])
    engineering = [_engineering(k) for k in ENGINEERING_METRICS]
    measured = [c for c in engineering if any(p.stats(c.key)[2] for p in points)]
    cutoffs = {_number(r.get(LOWPASS_COLUMN)) for r in rows if not r.get("error")}
    return PointTable(varied, tuple(points), tuple(measured),
                      tuple(c for c in engineering if c not in measured),
                      tuple(sorted(c for c in cutoffs if math.isfinite(c))), superseded)


def _key_header(key: str) -> str:
    """Heading of a varied column: its name, and its SI unit where it has one."""
    unit = column_unit(key)
    return f"{key} [{unit}]" if unit and unit != "1" else key


def _key_cell(row: PointRow, key: str, digits: int | None = 6) -> str:
    """A varied column's value as given (SI); ``digits`` significant (None: every digit)."""
    value = row.case[key] if key in row.case else row.values.get(key)
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value) if digits is None else f"{value:.{digits}g}"
    return str(value)


def _stat_cell(row: PointRow, column: Column) -> str:
    """"mean ± std" of a metric in display units ("–" without a value; one seed: the value;
    "(k of n undefined)" where seeds have none)."""
    if not row.seeds:
        return "–"
    return format_mean_std(row.samples[column.key], column.scale)


def _common_case(table: PointTable) -> str:
    """The case fields every row shares, in words ("W1, lf1352, tp, nmpc, ekf, nominal, 2 s
    runs")."""
    if not table.rows:
        return ""
    case = table.rows[0].case
    same = [c for c in CASE_FIELDS if c not in table.varied]
    parts = [f"{case[c]:g} s runs" if c == "duration_s" and isinstance(case[c], float)
             else str(case[c]) for c in same if case.get(c) is not None]
    return ", ".join(parts)


def _aligned(head: list[str], body: list[list[str]], right_from: int) -> list[str]:
    """A Markdown table with padded columns (numbers right-aligned from ``right_from``)."""
    widths = [max(len(c) for c in column) for column in zip(head, *body, strict=True)]

    def line(cells: list[str]) -> str:
        return "| " + " | ".join(c.rjust(w) if i >= right_from else c.ljust(w)
                                 for i, (c, w) in enumerate(zip(cells, widths, strict=True))
                                 ) + " |"

    rule = "|" + "|".join("-" * (w + 1) + ":" if i >= right_from else "-" * (w + 2)
                          for i, w in enumerate(widths)) + "|"
    return [line(head), rule, *(line(cells) for cells in body)]


def summary_markdown(table: PointTable) -> str:
    """The summary as Markdown: a line naming what every row shares, the table (one row per
    point: the varied columns as given, the runs averaged, every metric's mean ± std over
    seeds in display units, the diagnostics last) and notes on reading it."""
    if not table.rows:
        return "Sweep summary: no runs.\n"
    shared = _common_case(table)
    n = len(table.rows)
    lines = [f"Sweep summary{f' ({shared})' if shared else ''}: {n} point{'s' * (n > 1)}",
             ""]
    head = [_key_header(k) for k in table.varied] + ["runs"] + [c.header for c in
                                                                 table.columns]
    body = [[_key_cell(row, k) for k in table.varied]
            + [f"{len(row.seeds)}" + (f" ({row.failed} failed)" if row.failed else "")]
            + [_stat_cell(row, c) for c in table.columns] for row in table.rows]
    lines += _aligned(head, body, right_from=len(table.varied))
    lines.append("")
    lines += [textwrap.fill(f"- {note}", width=NOTE_WIDTH, subsequent_indent="  ",
                            break_on_hyphens=False) for note in _notes(table)]
    return "\n".join(lines) + "\n"


def _notes(table: PointTable) -> list[str]:
    """How to read the summary's table: the statistic, the columns' meaning, the units,
    the diagnostics, the metrics left out."""
    seeds = table.seeds
    if len(seeds) > 1:
        cell = (f"Each cell: mean ± std over the point's seeds ({_seed_list(seeds)}; "
                "population std, ddof = 0); \"(k of n undefined)\": k seeds without a value.")
    else:
        cell = f"Each cell: the value of the point's one run (seed {_seed_list(seeds) or '–'})."
    named = "; ".join(f"{c.short}: {c.label}" for c in table.columns if c.short != c.label)
    notes = [cell, f"Columns: {named}."]
    if table.machine is not None:
        notes.insert(0, f"Only machine {table.machine}'s runs (--machine): {table.left_out} "
                        f"other row(s) of {RESULTS} left out.")
    files = [f for f in FILE_FIELDS if f in table.varied]
    if files:
        notes.append(f"{', '.join(files)}: the file its spec gave every run instead of the "
                     "machine's own (empty: the machine's own).")
    if "set" in table.varied:
        notes.append("set: the fixed overrides of its spec ([sweep].set; empty: none).")
    if table.lowpass_Hz:
        cutoff = ", ".join(f"{c:g}" for c in table.lowpass_Hz)
        notes.append(f"lp, low-pass: F_ten through a zero-phase 2nd-order Butterworth at "
                     f"{cutoff} Hz; raw: the 1 kHz F_ten (see README, Metrics).")
    notes.append(f"Swept keys as given in the spec (SI); metrics in display units "
                 f"({SUMMARY_CSV}: SI); –: no value (no step or disturbance in the run, or a "
                 "window it does not reach).")
    notes.append(f"{DIAGNOSTIC_MARK}: diagnostics of the computer that ran the sweep (wall "
                 "clock, load), not results of the design; drawn only when asked "
                 "(--diagnostics).")
    if table.superseded:
        notes.append(f"{table.superseded} earlier row(s) of the same point and seed (made by "
                     "other code or file contents) left out: the newest of each is used.")
    if table.missing:
        notes.append("No value in any run (left out): "
                     + ", ".join(c.title for c in table.missing) + ".")
    return notes


def _seed_list(seeds: Sequence[int]) -> str:
    return ", ".join(str(s) for s in seeds)


def summary_csv(table: PointTable) -> str:
    """The summary as CSV in SI units (the unit in each heading): the varied columns as
    given, ``runs`` (finished) and ``failed``, then per metric ``KEY_mean [UNIT]`` and
    ``KEY_std [UNIT]`` (population std over seeds, ddof = 0; empty with fewer than two
    values), the diagnostics last and marked; empty cells where there is no value."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([_key_header(k) for k in table.varied] + ["runs", "failed"]
                    + [h for c in table.columns for h in c.csv_headers])
    for row in table.rows:
        cells = [_key_cell(row, k, digits=None) for k in table.varied]
        cells += [str(len(row.seeds)), str(row.failed)]
        for column in table.columns:
            mean, std, count = row.stats(column.key)
            cells += [repr(mean) if count else "", repr(std) if count > 1 else ""]
        writer.writerow(cells)
    return buffer.getvalue()


def write_summary(out_dir: str | Path, table: PointTable) -> tuple[Path, Path]:
    """``DIR/summary.csv`` and ``DIR/summary.md`` of ``table``, each written atomically;
    returns their paths."""
    out = Path(out_dir)
    write_text_atomic(out / SUMMARY_CSV, summary_csv(table))
    write_text_atomic(out / SUMMARY_MD, summary_markdown(table))
    return out / SUMMARY_CSV, out / SUMMARY_MD


def _folder_table(out_dir: Path, machine: str | None) -> PointTable:
    """:func:`summarize` of every row of ``DIR/results.parquet``, or with ``machine`` (a
    machine's name, or a shipped machine or machine file) of that machine's rows only;
    ParameterError naming the machines there if it has none."""
    path = out_dir / RESULTS
    rows = read_rows(path)
    if machine is None:
        return summarize(rows)
    present = {_machine(r) for r in rows}
    name = machine if machine in present else _machine_name(machine)
    if name not in present:
        raise ParameterError(f"--machine {machine}: no run of it in {path} (machines there: "
                             f"{', '.join(sorted(present)) or 'none'})")
    kept = [r for r in rows if _machine(r) == name]
    return dataclasses.replace(summarize(kept), machine=name, left_out=len(rows) - len(kept))


def summarize_sweep(out_dir: str | Path, *, machine: str | None = None) -> PointTable:
    """The summary of the sweep in ``DIR`` (:func:`summarize` of ``DIR/results.parquet``;
    ``machine``: only that machine's rows, see :func:`_folder_table`), written as
    ``DIR/summary.csv`` and ``DIR/summary.md``."""
    out = Path(out_dir)
    if not (out / RESULTS).is_file():
        raise FileNotFoundError(f"{out}: no sweep results here ({RESULTS} missing)")
    table = _folder_table(out, machine)
    write_summary(out, table)
    return table


# ----------------------------------------------------------------------------- sweep

@dataclass
class SweepSummary:
    """What a :func:`sweep` did: ``ran`` runs executed now (``failed`` of them with an
    error), ``skipped`` already in the results; ``results`` the parquet file; ``table`` its
    summary, of every row in it (also in ``summary.csv`` and ``summary.md``, and what
    ``--plot`` shows): ``other_points`` of its points hold no run of this spec (earlier
    sweeps into ``out``: another spec or machine); ``figures`` the figures drawn."""

    out: Path
    results: Path
    runs: int
    ran: int
    skipped: int
    failed: int
    table: PointTable
    figures: list[Path]
    other_points: int = 0

    def __str__(self) -> str:
        failed = f" ({self.failed} failed: their rows hold the error)" if self.failed else ""
        said = (f"{self.runs} runs: {self.ran} ran now{failed}, {self.skipped} already in "
                f"{self.results} -> {self.out}")
        if self.other_points:
            n = len(self.table.rows)
            said += (f"\nthe summary and figures show every row of {self.results}: "
                     f"{self.other_points} of its {n} points are of earlier sweeps into "
                     f"{self.out} (another spec or machine); another --out keeps a study "
                     "apart")
        return said


def sweep(spec: str | Path | Mapping[str, Any] | SweepSpec, out: str | Path, *,
          workers: int | None = None, scheduler: str | None = None, executor: Any = None,
          keep_runs: bool = False, retry_failed: bool = False, plot: bool = True,
          diagnostics: bool = False, progress: bool = True,
          tensioner: str | Path | None = None, machine: str | None = None) -> SweepSummary:
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
    diagnostics : bool
        Also draw the diagnostics (wall time, real-time factor, solve time, overruns) in
        ``figures/diagnostics.png``.
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
        if not Path(tensioner).is_file():
            raise ParameterError(f"--tensioner: no such file {Path(tensioner).resolve()}")
        spec = dataclasses.replace(spec, table=dataclasses.replace(
            spec.table, tensioner=str(Path(tensioner).resolve())))
    if machine is not None:
        try:
            resolve(machine)
        except ParameterError as exc:
            raise ParameterError(f"--machine: {exc}") from None
        spec = dataclasses.replace(spec, table=dataclasses.replace(spec.table,
                                                                   machine=machine))
    runs = plan(spec)
    keys = {r.key for r in runs}
    with Store(out, "sweep", markers=(SPEC_COPY, FIGURES)) as store:
        if spec.text:
            write_text_atomic(store.out / SPEC_COPY, spec.text)
        made = run_campaign(store, runs, executor=executor, workers=workers,
                            scheduler=scheduler, progress="sweep" if progress else None,
                            keep_runs=keep_runs, retry_failed=retry_failed)
        rows = read_rows(store.results)
        table = summarize(rows)   # the folder's every row, as --plot shows it
        own = summarize([r for r in rows if r["run_key"] in keys])
        write_summary(store.out, table)
        figures = (_draw(table, store.out / FIGURES, redraw=bool(made.outcomes),
                         diagnostics=diagnostics) if plot else [])
    distinct = len(keys)   # LHS samples rounded onto one integer coincide
    ran = len(made.outcomes)
    return SweepSummary(store.out, store.results, distinct, ran, distinct - ran,
                        len(made.failed), table, figures, len(table.rows) - len(own.rows))


# ----------------------------------------------------------------------------- figures

def plot_sweep(out_dir: str | Path, *, machine: str | None = None, redraw: bool = True,
               diagnostics: bool = False) -> list[Path]:
    """Draw the figures of the sweep in ``DIR`` from ``DIR/results.parquet``
    (:func:`trackmj.results.figure_sweep.sweep_figures`): ``figures/<key>.png`` per swept
    key (without swept keys ``figures/cases.png``), the engineering metrics of
    :func:`summarize` as panels; with ``diagnostics`` also ``figures/diagnostics.png``.
    ``machine``: only that machine's rows (default: every row; see :func:`_folder_table`);
    ``redraw=False`` keeps the figures that exist. Returns the paths of the figures (drawn
    now or kept)."""
    out = Path(out_dir)
    return _draw(_folder_table(out, machine), out / FIGURES, redraw=redraw,
                 diagnostics=diagnostics)


def _draw(table: PointTable, fig_dir: Path, *, redraw: bool, diagnostics: bool) -> list[Path]:
    """The figures of ``table`` in ``fig_dir`` (see :func:`plot_sweep`)."""
    # local: matplotlib (which the figure module switches to Agg) is heavy, loaded to draw
    from trackmj.results.figure_sweep import sweep_figures

    finished = [row for row in table.rows if row.seeds]
    return sweep_figures(finished, table.metrics, fig_dir, redraw=redraw,
                         diagnostics=table.diagnostics if diagnostics else ())
