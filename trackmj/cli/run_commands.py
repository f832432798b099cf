"""Commands that run closed-loop simulations: ``run`` (one run), ``compare`` (every
architecture on one scenario), ``report`` (the study), ``sweep`` (a parameter study) and
``calibrate`` (fit keys to measured logs).

The modules that load MuJoCo, CasADi or Matplotlib are imported inside the handlers:
``trackmj --help`` and argument errors import this module and must stay fast.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trackmj.cli.run_folder import refuse_other_inputs, run_folder
from trackmj.cli.summary import (
    derailment_lines,
    end_stop_line,
    end_stop_rows_line,
    flagged,
    measured_table,
    summary_table,
    tensioner_line,
)
from trackmj.elements.tensioner_file import load_tensioner
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.results.store import ResultWriter, running_of, running_text
from trackmj.sim.controllers import CONTROLLERS
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from trackmj.results.measured import MeasuredLog
    from trackmj.results.store import Result


def _files(args: argparse.Namespace) -> dict:
    """The parameter files, tensioner file and ``--set`` overrides given on the command
    line."""
    return dict(model=args.model, hydraulics=args.hydraulics, control=args.control,
                overrides=args.set, tensioner=args.tensioner, machine=args.machine)


def _specs_base(args: argparse.Namespace, scenario: str) -> dict:
    """RunSpec fields shared by every run of a compare command."""
    # start-up: --help and argument errors must not import MuJoCo, CasADi or SciPy
    from trackmj.study.executor import as_path, overrides_tuple

    return dict(scenario=scenario, estimator=getattr(args, "estimator", None),
                duration=args.duration, overrides=overrides_tuple(args.set),
                **_parameter_files(args), tensioner=as_path(args.tensioner),
                machine=_machine_spec(args.machine))


def _parameter_files(args: argparse.Namespace) -> dict[str, str | None]:
    """The ``--model``, ``--hydraulics`` and ``--control`` files as RunSpec fields (None:
    the machine's own)."""
    # start-up: --help and argument errors must not import MuJoCo, CasADi or SciPy
    from trackmj.study.executor import as_path

    return {kind: as_path(getattr(args, kind)) for kind in ("model", "hydraulics", "control")}


def _machine_spec(machine: str | None) -> str | None:
    """A machine for a RunSpec: a shipped name as given, a machine file as an absolute
    path (workers may run elsewhere)."""
    # start-up: --help and argument errors must not import MuJoCo
    from trackmj.machines.assembly import names

    if machine is None or machine.strip().lower() in names():
        return machine
    return str(Path(machine).resolve())


def cmd_run(args: argparse.Namespace) -> int:
    """``trackmj run``: one closed-loop run written to its folder, with its summary."""
    # start-up: --help and argument errors must not import MuJoCo, CasADi, Rerun or Matplotlib
    from trackmj.results.figure_run import run_figure
    from trackmj.results.playback import RUN_RRD
    from trackmj.sim.run import measured_log, run
    from trackmj.sim.setup import prepare
    from trackmj.study.identity import inputs_key, run_key, stamped

    setup = prepare(args.scenario, architecture=args.arch, controller=args.controller,
                    estimator=args.estimator, seed=args.seed, duration=args.duration,
                    variant=args.variant, whole_events=True, **_files(args))
    log: str | None = args.measured
    measured = None if log is None else measured_log(setup, log, args.channels)
    key = inputs_key(setup, measured)
    defaults = not (args.estimator or args.duration is not None or args.set or args.model
                    or args.hydraulics or args.control or args.tensioner or measured)
    out = Path(args.out) if args.out else run_folder(setup, key, defaults=defaults)
    refuse_other_inputs(out, key, overwrite=args.overwrite)
    with ResultWriter(out) as writer:
        result = run(setup, rrd=_staged(writer, RUN_RRD) if args.rrd else None,
                     progress=True, measured=measured, channels=args.channels)
        result = stamped(result, inputs_key=key, run_key=run_key(setup, measured))
        writer.commit(result, csv=args.csv,
                      extras={"timeseries.png": lambda path: run_figure(
                          result, path, None if measured is None else measured.columns)})
    print(f"{setup.scenario.name} ({setup.scenario.title}) on {setup.machine.name}, "
          f"{result.architecture}, {result.controller}/{result.estimator}, seed "
          f"{result.seed}{running_text(running_of(result))} -> {out}")
    _print_end_stop([result], setup.machine.name)
    if result.metrics.get("tensioner", {}).get("element") == "fmu":
        print(tensioner_line(result.metrics["tensioner"]))
    if result.metrics.get("valve_mode_applied") is False and setup.tensioner is not None:
        print(f"tensioner {setup.tensioner.name}: takes no valve mode, so the controller's "
              "output acts on nothing; the valve metrics read n/a")
    print(summary_table([result], "{r.architecture}"))
    if "derailment" in result.metrics:
        print("\n".join(derailment_lines(result.metrics)))
    if measured is not None:
        print(measured_table(result.metrics["prediction_vs_measured"], measured.file))
        print(_log_line(measured))
    return 1 if flagged(result.metrics) else 0


def _print_end_stop(results: Sequence[Result], machine: str) -> None:
    """On stderr, one line per scenario whose track settled with its idler carrier on an
    end stop in any of ``results`` (:func:`trackmj.cli.summary.end_stop_line`; the runs of
    one scenario settle alike)."""
    said: dict[str, str] = {}
    for r in results:
        line = end_stop_line(r.metrics, machine)
        if line is not None:
            said.setdefault(r.scenario, line)
    for line in said.values():
        print(line, file=sys.stderr)


def _machine_suffix(name: str) -> str:
    """``-NAME`` for default folder names when machine ``name`` is not the default one."""
    return "" if name == DEFAULT_MACHINE else f"-{name}"


def _log_line(log: MeasuredLog) -> str:
    """The measured log's name, hash and columns: the ones compared and the ones ignored."""
    ignored = ", ".join(log.ignored) if log.ignored else "none"
    return (f"log {log.file} (sha256 {log.sha256[:12]}): compared "
            f"{', '.join(log.used.values())}; ignored (no quantity of the run): {ignored}")


def _staged(writer: ResultWriter, name: str) -> Path:
    """Path of file ``name`` in the stage of ``writer``, which is open (inside its ``with``
    block); RuntimeError otherwise."""
    if writer.stage is None:
        raise RuntimeError("a ResultWriter has a stage only inside its with block")
    return writer.stage / name


def cmd_compare(args: argparse.Namespace) -> int:
    """``trackmj compare``: every architecture (× ``--controllers``) on one scenario;
    exit code 1 if a run failed."""
    # start-up: --help and argument errors must not import MuJoCo, CasADi or Matplotlib
    from trackmj.sim.setup import prepare
    from trackmj.study.compare import compare, comparison_key, write_compare

    controllers = args.controllers.split(",") if args.controllers else [None]
    setups = [prepare(args.scenario, controller=c, estimator=args.estimator, seed=args.seed,
                      duration=args.duration, whole_events=True, **_files(args))
              for c in controllers]
    controllers = [str(c) if c else s.controller for c, s in zip(controllers, setups,
                                                                 strict=True)]
    scenario = setups[0].scenario
    scenario_machine = setups[0].machine.name
    out = Path(args.out or f"runs/compare-{scenario.name}{_machine_suffix(scenario_machine)}")
    base = _specs_base(args, str(args.scenario))
    outcome = compare(base, controllers, out, seed=args.seed, workers=args.workers,
                      scheduler=args.scheduler, key=comparison_key(setups),
                      overwrite=args.overwrite)
    for spec, error in outcome.failed:
        print(f"trackmj: {spec.architecture} {spec.controller}: {error}", file=sys.stderr)
    _print_end_stop(outcome.results, scenario_machine)
    doc = write_compare(outcome, out, scenario, setups[0].duration_s)
    print(summary_table(outcome.results, "{r.architecture} {r.controller}"))
    print(f"-> {doc}")
    return 1 if outcome.failed or any(flagged(r.metrics) for r in outcome.results) else 0


def _report_choices(args: argparse.Namespace, study_archs: tuple[str, ...]
                    ) -> tuple[list[str], list[str]]:
    """The architectures (``study_archs`` unless ``--archs``) and baseline controllers of a
    report, each checked against its registry, after ``--seeds``; ValueError naming the
    option otherwise."""
    if args.seeds < 1 or args.seeds > 50:
        raise ValueError(f"--seeds = {args.seeds}: allowed 1..50")
    archs = (list(study_archs) if args.archs is None
             else [a for a in args.archs.split(",") if a])
    baselines = [c for c in args.baselines.split(",") if c]
    for name, given, known in (("--archs", archs, ARCHITECTURES),
                               ("--baselines", baselines, CONTROLLERS)):
        unknown = [x for x in given if x not in known]
        if unknown:
            raise ValueError(f"{name}: unknown {unknown}; allowed {sorted(known)}")
    if REFERENCE_ARCHITECTURE not in archs:
        raise ValueError(f"--archs must include {REFERENCE_ARCHITECTURE}: every claim and "
                         "prediction error is against it")
    return archs, baselines


def cmd_report(args: argparse.Namespace) -> int:
    """``trackmj report``: the study's matrix of runs, resumed, and report.md; exit code 1
    if a run failed."""
    # start-up: --help and argument errors must not import MuJoCo, CasADi or Matplotlib
    from trackmj.machines.assembly import resolve
    from trackmj.study.executor import overrides_tuple
    from trackmj.study.report import REPORT_ARCHS, check_report_dir, plan, run_matrix, write_report

    archs, baselines = _report_choices(args, REPORT_ARCHS)
    # the machine is refused here, before any run, if it is bad
    machine = DEFAULT_MACHINE if args.machine is None else resolve(args.machine).name
    if args.tensioner is not None:
        load_tensioner(args.tensioner)   # refused here, before any run, if it is bad
    specs = plan(args.scenarios.split(","), list(range(args.seeds)), args.duration, archs,
                 baselines, tensioner=args.tensioner, machine=_machine_spec(args.machine),
                 files=_parameter_files(args), overrides=overrides_tuple(args.set))
    # after the plan: a refused scenario or key leaves no empty --out behind
    out = check_report_dir(Path(args.out or f"runs/report{_machine_suffix(machine)}"))
    matrix = run_matrix(specs, out, workers=args.workers, scheduler=args.scheduler)
    path = write_report(matrix.results, out, matrix)
    _print_end_stop(matrix.results, machine)
    print(f"{len(matrix.results)} runs ({matrix.resumed} resumed, {len(matrix.failed)} failed) "
          f"in {matrix.wall_time_s:.0f} s -> {path}")
    return 1 if matrix.failed else 0


def _count(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless one ("1 figure", "2 figures")."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def cmd_sweep(args: argparse.Namespace) -> int:
    """``trackmj sweep``: every point of a sweep spec, resumed, or ``--plot`` to redraw its
    figures; exit code 1 if a run failed."""
    # start-up: --help and argument errors must not import MuJoCo
    from trackmj.study.campaign import RESULTS, read_rows
    from trackmj.study.sweep import plot_sweep, summarize_sweep, summary_markdown, sweep

    if args.plot is not None:
        if args.spec is not None:
            raise ValueError("give a sweep spec to run, or --plot DIR to redraw, not both")
        running = [option for option, given in (
            ("--out", args.out), ("--tensioner", args.tensioner), ("--keep-runs", args.keep_runs),
            ("--retry-failed", args.retry_failed), ("--workers", args.workers),
            ("--scheduler", args.scheduler)) if given]
        if running:
            raise ValueError(f"--plot DIR redraws from DIR/results.parquet and runs nothing: "
                             f"{', '.join(running)} apply to a sweep that runs a spec")
        print(summary_markdown(summarize_sweep(args.plot, machine=args.machine)))
        figures = plot_sweep(args.plot, machine=args.machine, diagnostics=args.diagnostics)
        print(f"summary.md, summary.csv, {_count(len(figures), 'figure')} -> {Path(args.plot)}")
        _print_rows_end_stop(read_rows(Path(args.plot) / RESULTS))
        return 0
    if args.spec is None:
        raise ValueError("sweep needs a spec file (or --plot DIR); see 'trackmj sweep -h'")
    out = Path(args.out or f"runs/sweep-{Path(args.spec).stem}")
    summary = sweep(args.spec, out, workers=args.workers, scheduler=args.scheduler,
                    keep_runs=args.keep_runs, retry_failed=args.retry_failed,
                    tensioner=args.tensioner, machine=_machine_spec(args.machine),
                    diagnostics=args.diagnostics)
    print(summary_markdown(summary.table))
    print(summary)
    _print_rows_end_stop(read_rows(summary.results))
    print(f"summary.md, summary.csv, {_count(len(summary.figures), 'figure')} -> {out}")
    return 1 if summary.failed else 0


def _print_rows_end_stop(rows: Sequence[Mapping[str, Any]]) -> None:
    """On stderr, one line if runs of a campaign's ``rows`` (results.parquet's) settled
    with the idler carrier on an end stop (:func:`trackmj.cli.summary.end_stop_rows_line`)."""
    line = end_stop_rows_line(rows)
    if line is not None:
        print(line, file=sys.stderr)


def cmd_calibrate(args: argparse.Namespace) -> int:
    """``trackmj calibrate``: fit a spec's keys to measured logs, with 95 % intervals."""
    # start-up: --help and argument errors must not import MuJoCo, CasADi or SciPy
    from trackmj.results.columns import display_unit
    from trackmj.study.calibrate import CALIBRATION_JSON, CALIBRATION_PNG, calibrate

    out = Path(args.out)
    done = calibrate(args.spec, args.measured, out, workers=args.workers)
    doc = done.document
    runs = len(doc["runs"])
    print(f"calibrated {len(doc['estimates'])} keys on {len(args.measured)} log(s), {runs} "
          f"runs in {doc['wall_time_s']:.0f} s ({doc['optimizer']['message']})")
    for key, value in doc["estimates"].items():
        scale, unit = display_unit(doc["units"]["estimates"][key])
        unit = "" if unit in ("", "1") else f" {unit}"
        low, high = doc["intervals"][key]
        bound = "  (at a bound)" if doc["at_bound"][key] else ""
        bound += "" if doc["determined"][key] else "  (not determined: the bounds)"
        print(f"  {key} = {value * scale:.5g}{unit}   95 % [{low * scale:.5g}, "
              f"{high * scale:.5g}]{unit}{bound}")
    rms = ", ".join(f"{name} {value:.4g}" for name, value in doc["residual_rms"].items())
    print(f"  residual RMS (SI): {rms}")
    for log in doc["logs"]:
        ignored = ", ".join(log["columns_ignored"]) or "none"
        missing = "".join(f"; {header}: {n} missing samples bridged"
                          for header, n in log["missing_samples"].items())
        print(f"  log {log['file']} (sha256 {log['sha256'][:12]}): fitted "
              f"{', '.join(log['columns_used'].values())}; ignored: {ignored}{missing}")
    for line in doc["warnings"]:
        print(f"warning: {line}", file=sys.stderr)
    print(f"-> {out / CALIBRATION_JSON}, {out / CALIBRATION_PNG}")
    return 0
