"""The ``trackmj`` argument parser: every subcommand's options, help texts and defaults, one
function per subcommand, each binding its handler (``func``).

Help states each option's default. The choices of ``--arch``, ``--estimator`` and the
controllers named in help and defaults come from :mod:`trackmj.sim.registry`, so a new
block registered there is offered here with no edit.
"""

from __future__ import annotations

import argparse
from typing import Any

from trackmj.cli.fmu_commands import cmd_fmu_export
from trackmj.cli.info_commands import cmd_keys, cmd_scenarios, cmd_view
from trackmj.cli.run_commands import cmd_calibrate, cmd_compare, cmd_report, cmd_run, cmd_sweep
from trackmj.cli.track_commands import (
    cmd_drive,
    cmd_machines,
    cmd_model_generate,
    cmd_model_info,
)
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS, baselines
from trackmj.sim.entries import by_name, choices
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.version import __version__

Subcommands = argparse._SubParsersAction
"""What ``add_subparsers`` returns: each ``_add_*`` function adds its subcommand to it."""


def _nonnegative_int(text: str) -> int:
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; must be an integer >= 0")
    return value


def _positive_int(text: str) -> int:
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: must be an integer >= 1")
    return value


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def _duration(text: str) -> float:
    """A ``--duration`` [s] in (0, 3600]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not 0.0 < value <= 3600.0:
        raise argparse.ArgumentTypeError(f"{text} s: allowed (0, 3600] s")
    return value


class _HelpFormatter(argparse.HelpFormatter):
    """Help that states each option's default (unless it has none or says it itself)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if ("default" in text or default is None or default is False or default == []
                or default is argparse.SUPPRESS or not action.option_strings):
            return text
        return f"{text} (default: %(default)s)"


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose help shows defaults (subcommands inherit it)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)


def _tensioner_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--tensioner", metavar="FILE.toml", help="tensioner file: an FMU "
                   "([fmu]) or a spring-damper ([passive]) replacing the hydraulic "
                   "element (see README, FMI)")


def _machine_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--machine", metavar="NAME|FILE", help="a shipped machine ('trackmj "
                   f"machines') or a machine file *_machine.toml (default: {DEFAULT_MACHINE})")


def _renamed_params(text: str) -> str:
    """``--params`` is gone: one line naming what replaced it."""
    raise argparse.ArgumentTypeError("renamed: the model parameter TOML is --model FILE "
                                     "(as in run); drive and model info take an MJCF file "
                                     "as --mjcf FILE")


def _model_args(p: argparse.ArgumentParser) -> None:
    """Options of the commands on the bare track: machine, model file, MJCF, ``--set``."""
    _machine_arg(p)
    p.add_argument("--model", metavar="FILE",
                   help="model parameter TOML (default: the machine's mechanics)")
    p.add_argument("--mjcf", metavar="FILE", help="MJCF file (default: the model's, "
                   "generated and cached unless it is the machine's committed reference)")
    p.add_argument("--params", type=_renamed_params, help=argparse.SUPPRESS)
    p.add_argument("--set", metavar="model.TABLE.KEY=VALUE", action="append", default=[],
                   help="override one key of the model file (repeatable), e.g. "
                        "--set model.track.link_count=80")


def _file_args(p: argparse.ArgumentParser) -> None:
    """Options naming a run's input files and ``--set`` overrides."""
    _tensioner_arg(p)
    _machine_arg(p)
    p.add_argument("--model", metavar="FILE",
                   help="model parameter TOML (default: the machine's mechanics)")
    p.add_argument("--hydraulics", metavar="FILE", help="hydraulic parameter TOML "
                   "(default: the machine's)")
    p.add_argument("--control", metavar="FILE", help="control parameter TOML "
                   "(default: the machine's)")
    p.add_argument("--set", metavar="KIND.TABLE.KEY=VALUE", action="append", default=[],
                   help="override one key of a file (repeatable), KIND one of model, "
                        "hydraulics, control, scenario; e.g. "
                        "--set hydraulics.fluid.bulk_modulus_Pa=1.2e9 "
                        "--set scenario.track.speed_m_s=2.0")


def _executor_args(p: argparse.ArgumentParser) -> None:
    """Options of the Dask executor."""
    p.add_argument("--workers", type=_positive_int, help="Dask worker processes of the "
                   "local cluster (default: one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, "
                   "e.g. tcp://HOST:8786, instead of a local cluster")


def _run_args(p: argparse.ArgumentParser, out_help: str) -> None:
    """Options of a closed-loop run of one scenario (``run`` and ``compare``)."""
    p.add_argument("scenario", help="a built-in scenario (W1-W5, NL1; trackmj "
                   "scenarios) or a scenario TOML file")
    p.add_argument("--estimator", choices=choices(ESTIMATORS),
                   help="default: the scenario's")
    p.add_argument("--seed", type=_nonnegative_int, default=0,
                   help="noise and terrain seed")
    p.add_argument("--duration", type=_duration,
                   help="simulated time [s] (default: the scenario's)")
    p.add_argument("--out", metavar="DIR", help=out_help)
    _file_args(p)


def _add_model(sub: Subcommands) -> None:
    """``model info`` and ``model generate``."""
    model = sub.add_parser("model", help="inspect or regenerate the track model")
    model_sub = model.add_subparsers(dest="model_command", required=True)
    info = model_sub.add_parser("info", help="summary: bodies, DOF, links, masses, contacts")
    _model_args(info)
    info.set_defaults(func=cmd_model_info)
    gen = model_sub.add_parser("generate", help="regenerate a machine's reference MJCF "
                               "(models/lf1352.xml) from its files")
    _machine_arg(gen)
    gen.add_argument("--model", metavar="FILE",
                     help="model parameter TOML (default: the machine's mechanics)")
    gen.add_argument("--params", type=_renamed_params, help=argparse.SUPPRESS)
    gen.add_argument("--set", metavar="model.TABLE.KEY=VALUE", action="append", default=[],
                     help="override one key of the model file (repeatable)")
    gen.add_argument("--out", help="output MJCF path NAME.xml, the machine part; the scene "
                     "NAME_scene.xml beside it includes it (default: the machine's "
                     "reference_mjcf)")
    gen.set_defaults(func=cmd_model_generate)


def _add_drive(sub: Subcommands) -> None:
    drive = sub.add_parser(
        "drive", help="drive the track with the passive tensioner",
        description="Drive the bare track (no hydraulics) with its passive tensioner or a "
                    "--tensioner file; derailment is checked every 0.1 s (slack upper "
                    "strand: its least pin tension below 1 kN at every 10 ms sample of "
                    "the 0.1 s up to the check, not one pin's momentary compression at a "
                    "tooth; links off their home envelope; sprocket disengaged) and the "
                    "summary names each failing check, when it first failed and where.",
        epilog="exit codes: 0 healthy; 1 a derailment check failed or MuJoCo warned; 2 bad "
               "input (an option, file, key or value, or an --out it may not write; one "
               "line names it); 3 the run left physics or an FMU tensioner failed; 130 "
               "interrupted")
    _model_args(drive)
    drive.add_argument("--speed", type=float, default=1.5,
                       help="sprocket pitch speed [m/s], negative in reverse, reached from "
                       "rest by a linear ramp over min(1 s, duration/4): a drive shorter than "
                       "4 s starts harder")
    drive.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    drive.add_argument("--preload", type=float, metavar="N",
                       help="tensioner preload [N], e.g. 12e3")
    drive.add_argument("--hitch-pull", type=float, default=0.0, metavar="N",
                       help="horizontal rear-hitch load [N]: > 0 pulls the machine "
                       "rearward (a towed load driving forward), < 0 pushes it forward; "
                       "e.g. 8e3")
    drive.add_argument("--grade", type=float, default=0.0, metavar="TAN",
                       help="slope driven on, tan θ (rise over run, > 0 uphill driving "
                       "forward, in [-1, 1]); e.g. 0.2")
    drive.add_argument("--stop-at", type=float, metavar="T", dest="stop_at",
                       help="command the sprocket to 0 at once at T [s] (an abrupt stop: "
                       "the drive stops it at its torque limit, the parking brake applies "
                       "once it is still); the summary says what the stop did to the idler "
                       "and the hull; e.g. 3")
    drive.add_argument("--out", metavar="DIR", help="directory for metrics.json, "
                       "timeseries.parquet and the figure drive.png (default: "
                       "runs/drive-MACHINE-SPEEDmps-HASH, HASH of the other inputs)")
    _tensioner_arg(drive)
    drive.set_defaults(func=cmd_drive)


def _add_run(sub: Subcommands) -> None:
    run = sub.add_parser("run", help="one closed-loop run of a scenario")
    _run_args(run, "output directory (default: runs/SCENARIO-ARCH-CONTROLLER-sSEED, with "
                   "-VARIANT, -MACHINE when it is not the default one, and a short hash of "
                   "the inputs when they are not the scenario's own or a log is compared; a "
                   "folder holding a run of other inputs is refused unless --overwrite)")
    run.add_argument("--arch", default=REFERENCE_ARCHITECTURE, choices=choices(ARCHITECTURES),
                     help="coupling architecture")
    run.add_argument("--controller", metavar="NAME",
                     help=f"{', '.join(by_name(CONTROLLERS))}, or "
                          "fmu:FILE.toml for a controller FMU (default: the scenario's)")
    run.add_argument("--variant", default="nominal", help="W5 variant name")
    run.add_argument("--csv", action="store_true", help="also write timeseries.csv")
    run.add_argument("--rrd", action="store_true", help="also write a Rerun recording")
    run.add_argument("--measured", metavar="LOG", help="a measured log (CSV or Parquet: t_s "
                     "and any of the run's columns, e.g. tension_N, p_head [MPa], stroke_mm) "
                     "overlaid in the figure and compared in metrics.json "
                     "(prediction_vs_measured)")
    run.add_argument("--channels", choices=("default", "all"), default="default",
                     help="all: also record per-cylinder pressures, valve flows, strand "
                          "tensions and the hitch load (units in units.json)")
    run.add_argument("--overwrite", action="store_true", help="replace a result of other "
                     "inputs in the output folder (the same inputs replace it anyway)")
    run.set_defaults(func=cmd_run)


def _add_compare(sub: Subcommands) -> None:
    compare = sub.add_parser("compare", help="all architectures on one scenario, with each "
                             "reduced one's prediction error against "
                             f"{REFERENCE_ARCHITECTURE}")
    _run_args(compare, "output directory (default: runs/compare-SCENARIO, with -MACHINE when "
                       "it is not the default one); a comparison of the same inputs in it "
                       "is resumed (its runs already done are kept), a folder holding one "
                       "of other inputs is refused unless --overwrite")
    compare.add_argument("--controllers", help="comma list, e.g. "
                         f"{','.join(by_name(CONTROLLERS))} (each on every architecture; "
                         "one more figure overlays the controllers)")
    compare.add_argument("--overwrite", action="store_true", help="replace a comparison "
                         "of other inputs in the output folder (its files are removed "
                         "before this one runs)")
    _executor_args(compare)
    compare.set_defaults(func=cmd_compare)


def _add_report(sub: Subcommands) -> None:
    """``report``: ``--archs`` left out means the study's architectures
    (:data:`trackmj.study.report.REPORT_ARCHS`), ``--baselines`` defaults to the controllers
    registered as baselines."""
    report = sub.add_parser("report", help="W1-W5 x architectures x seeds -> report.md with "
                            "the study's claims, resumable")
    report.add_argument("--scenarios", default="W1,W2,W3,W4,W5", help="comma list")
    report.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per case")
    report.add_argument("--duration", type=float, help="simulated time per run [s]")
    report.add_argument("--archs", help="architectures (comma list; default: the study's three)")
    report.add_argument("--baselines", default=",".join(baselines()),
                        help=f"baseline controllers run on {REFERENCE_ARCHITECTURE} in W1 "
                             "('' for none)")
    _file_args(report)
    _executor_args(report)
    report.add_argument("--out", help="output directory (default: runs/report, with -MACHINE "
                        "when it is not the default one); runs already complete in it are "
                        "kept")
    report.set_defaults(func=cmd_report)


def _add_sweep(sub: Subcommands) -> None:
    sweep = sub.add_parser(
        "sweep", help="parameter study from a TOML spec -> DIR/results.parquet, summary "
                      "table, figures",
        description="Run every point of a sweep spec (grid or Latin hypercube over --set "
                    "keys, x scenarios x architectures x controllers x seeds) on Dask; one "
                    "row per run in DIR/results.parquet, written as runs finish; runs "
                    "already there are skipped (resume); a failed run is a row with its "
                    "error. At the end a table, one row per point (mean ± std over "
                    "seeds), is printed and written to DIR/summary.md and DIR/summary.csv; "
                    "DIR/figures holds one figure per swept key, the metrics as panels. "
                    "The spec format is in the README ('Parameter studies').")
    sweep.add_argument("spec", nargs="?", help="sweep spec TOML file")
    sweep.add_argument("--out", metavar="DIR",
                       help="output directory, resumed if it holds a sweep "
                            "(default: runs/sweep-SPEC_NAME)")
    sweep.add_argument("--plot", metavar="DIR",
                       help="only redraw DIR/figures and DIR/summary.{csv,md} from "
                            "DIR/results.parquet, every row, or with --machine only that "
                            "machine's (a resumed sweep that makes no run keeps the figures "
                            "that exist)")
    sweep.add_argument("--diagnostics", action="store_true",
                       help="also draw DIR/figures/diagnostics.png: wall time, real-time "
                            "factor, max solve time, controller overruns (machine-dependent; "
                            "always in the summary table)")
    sweep.add_argument("--keep-runs", action="store_true",
                       help="also write each run's result directory under DIR/runs/")
    sweep.add_argument("--retry-failed", action="store_true",
                       help="run again the runs whose rows hold an error")
    _tensioner_arg(sweep)
    _machine_arg(sweep)
    _executor_args(sweep)
    sweep.set_defaults(func=cmd_sweep)


def _add_calibrate(sub: Subcommands) -> None:
    calib = sub.add_parser(
        "calibrate", help="fit --set keys to measured logs -> DIR/calibration.json",
        description="Fit the keys of a calibration spec within their bounds to measured logs "
                    "(least squares; the logs' valve command replayed in the spec's "
                    "conditions), with 95 % intervals; see the README ('Calibrate').")
    calib.add_argument("spec", help="calibration spec TOML ([calibrate], "
                       "[[calibrate.parameters]])")
    calib.add_argument("--measured", nargs="+", required=True, metavar="LOG",
                       help="CSV or Parquet logs: t_s, valve_mode and any of tension_N, "
                            "p_head_Pa, p_rod_Pa, stroke_m (or with units: p_head [MPa])")
    calib.add_argument("--out", required=True, metavar="DIR", help="output directory")
    calib.add_argument("--workers", type=_positive_int, help="Dask workers for a "
                       "Latin-hypercube start (start_points in the spec; default one per "
                       "core)")
    calib.set_defaults(func=cmd_calibrate)


def _add_listings(sub: Subcommands) -> None:
    """``machines``, ``scenarios`` and ``keys``."""
    machines = sub.add_parser("machines", help="list the shipped machines")
    machines.set_defaults(func=cmd_machines)

    scenarios = sub.add_parser("scenarios", help="list the built-in operating conditions")
    scenarios.set_defaults(func=cmd_scenarios)

    keys = sub.add_parser("keys", help="list the --set keys (and sweep keys) with units, "
                                       "ranges and meaning")
    keys.add_argument("kinds", nargs="*", metavar="KIND",
                      help="model, hydraulics, control or scenario (default: all)")
    keys.set_defaults(func=cmd_keys)


def _add_fmu(sub: Subcommands) -> None:
    fmu = sub.add_parser("fmu", help="FMI: export trackmj as an FMU (import: --tensioner, "
                         "--controller fmu:FILE)")
    fmu_sub = fmu.add_subparsers(dest="fmu_command", required=True)
    export = fmu_sub.add_parser("export", help="write a co-simulation FMU")
    export.add_argument("kind", choices=("track", "plant"), help="track: a native FMU (C and "
                        "MuJoCo inside, no Python on the host), the tensioner port as inputs; "
                        "plant: track + built-in hydraulics through trackmj's Python, valve "
                        "command in, sensor signals out")
    export.add_argument("-o", "--out", required=True, metavar="FILE.fmu", help="FMU to write")
    native = export.add_argument_group("track only (fixed in the FMU)")
    native.add_argument("--fmi", type=int, choices=(2, 3), default=2,
                        help="FMI version of the track FMU (default 2)")
    native.add_argument("--machine", metavar="NAME|FILE", help="a shipped machine or a "
                        f"machine file *_machine.toml (default: {DEFAULT_MACHINE})")
    native.add_argument("--terrain", default="flat", metavar="flat|SCENARIO",
                        help="flat, or a scenario whose road (and grade) the track stands "
                        "on (default flat)")
    native.add_argument("--seed", type=int, default=0, help="seed of the terrain's road")
    native.add_argument("--force", type=float, metavar="N", help="tensioner force the track "
                        "is settled under [N] (default: the machine's W1 initial tension)")
    native.add_argument("--platform", action="append", choices=("linux", "win64"),
                        help="build only these platforms (repeatable; default: both, each "
                        "where it can be built)")
    export.set_defaults(func=cmd_fmu_export)


def _add_view(sub: Subcommands) -> None:
    view = sub.add_parser("view", help="open a run's Rerun recording in the viewer")
    view.add_argument("path", help="run directory or .rrd file")
    view.set_defaults(func=cmd_view)


def build_parser() -> argparse.ArgumentParser:
    """The ``trackmj`` parser; each subcommand's handler is its namespace's ``func``."""
    parser = _Parser(prog="trackmj", description="trackmj: electro-hydraulic track tensioning "
                     "simulator (MuJoCo track, hydraulic plugin, NMPC control)",
                     epilog="'trackmj COMMAND -h' explains a command; 'trackmj scenarios' lists "
                            "the operating conditions, 'trackmj keys' the --set keys")
    parser.add_argument("--version", action="version", version=f"trackmj {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_model, _add_drive, _add_run, _add_compare, _add_report, _add_sweep,
                _add_calibrate, _add_listings, _add_fmu, _add_view):
        add(sub)
    return parser
