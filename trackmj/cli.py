"""``trackmj`` command line.

Display units (kN, mm, MPa) appear only here; everything inside is SI.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path


def _cmd_model_info(args: argparse.Namespace) -> int:
    import mujoco

    from trackmj.model import MODEL_NAME
    from trackmj.plant import TrackPlant

    plant = TrackPlant.load(args.model, args.params)
    m, d = plant.model, plant.data
    p = plant.params
    link_mass = p.track.link_mass_kg * plant.link_count
    total_mass = float(m.body_subtreemass[0])
    contact_pairs = sum(1 for i in range(m.ngeom) for j in range(i + 1, m.ngeom)
                        if (m.geom_contype[i] & m.geom_conaffinity[j])
                        or (m.geom_contype[j] & m.geom_conaffinity[i]))
    print(f"model            {MODEL_NAME} ({plant.model_path})")
    print(f"bodies           {m.nbody - 1} (+ world)")
    print(f"degrees of freedom {m.nv}   (generalised coordinates {m.nq})")
    print(f"links            {plant.link_count}, pitch {p.track.pitch_m * 1e3:.1f} mm, "
          f"loop {plant.link_count * p.track.pitch_m:.2f} m")
    print(f"road wheels      {p.road_wheels.count}, sprocket teeth {p.sprocket.tooth_count} "
          f"(pitch radius {p.sprocket_pitch_radius_m * 1e3:.1f} mm)")
    print(f"masses           total {total_mass:.0f} kg, chassis {p.chassis.mass_kg:.0f} kg, "
          f"track {link_mass:.0f} kg")
    print(f"geoms            {m.ngeom} ({contact_pairs} geom pairs can collide)")
    print(f"equalities       {m.neq} (one connect per pin), actuators {m.nu}: "
          f"{', '.join(m.actuator(i).name for i in range(m.nu))}")
    print(f"timestep         {m.opt.timestep * 1e3:.3f} ms, integrator "
          f"{mujoco.mjtIntegrator(m.opt.integrator).name}")
    print(f"home keyframe    contacts {d.ncon}, closure error {plant.closure_error_m * 1e3:.3f} mm,"
          f" stroke {plant.stroke_m * 1e3:.1f} mm")
    tension = plant.pin_tensions_N()
    print(f"pin tension      {tension.min() / 1e3:.2f} .. {tension.max() / 1e3:.2f} kN "
          f"(mean upper strand {tension[plant.upper_strand_pins()].mean() / 1e3:.2f} kN)")
    return 0


def _cmd_model_generate(args: argparse.Namespace) -> int:
    from trackmj.model import load_model_params, write_model

    path = write_model(args.out, load_model_params(args.params))
    print(f"wrote {path}")
    return 0


def _cmd_drive(args: argparse.Namespace) -> int:
    from trackmj.drive import drive

    preload = None if args.preload is None else args.preload * 1e3
    result = drive(args.speed, args.duration, model=args.model, params=args.params,
                   preload_N=preload, out_dir=args.out)
    m, s, e = result.metrics, result.metrics["steady"], result.metrics["track_energy"]
    print(f"drove {args.duration:.1f} s at {args.speed:.2f} m/s: {m['real_time_factor']:.2f}x "
          f"real time ({m['plant_real_time_factor']:.2f}x for the plant steps alone)")
    print(f"idler force        mean {s['idler_force_mean_N'] / 1e3:7.2f} kN   "
          f"min {s['idler_force_min_N'] / 1e3:7.2f}  max {s['idler_force_max_N'] / 1e3:7.2f}")
    print(f"strand tension     upper {s['upper_strand_tension_mean_N'] / 1e3:5.2f} kN, "
          f"rear lower run {s['lower_strand_tension_mean_N'] / 1e3:5.2f} kN")
    print(f"vehicle speed      {s['vehicle_speed_mean_m_s']:.3f} m/s "
          f"(sprocket pitch speed {s['track_speed_mean_m_s']:.3f} m/s)")
    contacts = sum(e["contact_work_J"].values())
    print(f"energy [kJ]        drive {e['drive_work_J'] / 1e3:.3f}, tensioner "
          f"{e['tensioner_work_J'] / 1e3:.3f}, suspension {e['suspension_loss_J'] / 1e3:.3f}, "
          f"constraints {contacts / 1e3:.3f}, numerical {e['numerical_J'] / 1e3:.3f}"
          f"; dKE {e['kinetic_change_J'] / 1e3:.3f}, dPE {e['potential_change_J'] / 1e3:.3f}, "
          f"residual {e['residual_J']:.2e} J")
    print(f"max pin gap        {m['max_pin_gap_m'] * 1e3:.3f} mm   MuJoCo warnings "
          f"{m['mujoco_warnings']}   derailment checks failed {m['derailment_checks_failed']}")
    if result.out_dir is not None:
        print(f"wrote {result.out_dir}")
    return 0 if m["mujoco_warnings"] == 0 and m["derailment_checks_failed"] == 0 else 1


SUMMARY_METRICS = ("rmse_lp_N", "rmse_N", "ripple_rms_N", "ripple_band_rms_N.tooth_passing",
                   "ripple_band_rms_N.body_mode", "peak_error_lp_N", "peak_error_N",
                   "overshoot_lp_N", "settling_time_lp_s", "disturbance_peak_error_lp_N",
                   "recovery_time_lp_s", "fluctuation_N", "constraint_violation_s",
                   "energy_in_J", "valve_switch_rate_Hz", "interface_energy_residual_J",
                   "solve_time_median_s", "solve_time_max_s", "real_time_factor")
"""Rows of the summary table, metric keys (dotted for a table entry; labels and display
units in :data:`trackmj.metrics.METRIC_DISPLAY`)."""
STEP_METRICS = ("overshoot_lp_N", "settling_time_lp_s")
DISTURBANCE_METRICS = ("disturbance_peak_error_lp_N", "recovery_time_lp_s")
UNSETTLED = ("settling_time_lp_s", "recovery_time_lp_s")


def _summary_table(results: list, title: str) -> str:
    """Markdown table of the headline metrics, one column per result. Rows of a step or a
    disturbance appear only where the scenario has one; a settling or recovery time that
    never came reads "not within ±band" instead of a dash."""
    from trackmj.metrics import METRIC_DISPLAY, lookup

    windows = [r.metrics.get("evaluation", {}) for r in results]
    has_step = any(w.get("step") for w in windows)
    has_disturbance = any(w.get("disturbances") for w in windows)
    head = "| metric | " + " | ".join(title.format(r=r) for r in results) + " |"
    lines = [head, "|---|" + "---|" * len(results)]
    for key in SUMMARY_METRICS:
        name, scale, unit = METRIC_DISPLAY[key]
        if (key in STEP_METRICS and not has_step) or (key in DISTURBANCE_METRICS
                                                      and not has_disturbance):
            continue
        cells = []
        for r, w in zip(results, windows, strict=True):
            value = lookup(r.metrics, key)
            if value == value:
                cells.append(f"{value * scale:.3g}")
            elif key in UNSETTLED and "settle_band_rel" in w:
                cells.append(f"not within ±{100 * w['settle_band_rel']:g} %")
            else:
                cells.append("–")
        lines.append(f"| {name} [{unit}] | " + " | ".join(cells) + " |")
    cutoff = {w.get("lowpass_cutoff_Hz") for w in windows} - {None}
    if cutoff:
        lines.append("")
        lines.append(f"low-pass: zero-phase 2nd-order Butterworth at "
                     f"{', '.join(f'{c:g}' for c in sorted(cutoff))} Hz on F_ten; raw: the "
                     "1 kHz F_ten (see README, Metrics)")
    return "\n".join(lines)


def _run_one(kwargs: dict):
    from trackmj.sim.run import simulate

    return simulate(**kwargs)


def _files(args: argparse.Namespace) -> dict:
    """The parameter files and ``--set`` overrides given on the command line."""
    return dict(model=args.model, hydraulics=args.hydraulics, control=args.control,
                overrides=args.set)


def _cmd_run(args: argparse.Namespace) -> int:
    from trackmj.figures import run_figure
    from trackmj.playback import RUN_RRD
    from trackmj.results import ResultWriter
    from trackmj.sim.run import run
    from trackmj.sim.setup import prepare

    setup = prepare(args.scenario, architecture=args.arch, controller=args.controller,
                    estimator=args.estimator, seed=args.seed, duration=args.duration,
                    variant=args.variant, **_files(args))
    out = Path(args.out or f"runs/{setup.scenario.name}-{setup.architecture}-"
                           f"{setup.controller}-s{setup.seed}")
    with ResultWriter(out) as writer:
        result = run(setup, rrd=writer.stage / RUN_RRD if args.rrd else None, progress=True)
        writer.commit(result, csv=args.csv,
                      extras={"timeseries.png": lambda path: run_figure(result, path)})
    print(f"{setup.scenario.name} ({setup.scenario.title}), {result.architecture}, "
          f"{result.controller}/{result.estimator}, seed {result.seed} -> {out}")
    print(_summary_table([result], "{r.architecture}"))
    return 0


def _specs_base(args: argparse.Namespace, scenario: str) -> dict:
    """RunSpec fields shared by every run of a compare command."""
    from trackmj.executor import as_path, overrides_tuple

    return dict(scenario=scenario, estimator=getattr(args, "estimator", None),
                duration=args.duration, overrides=overrides_tuple(args.set),
                model=as_path(args.model), hydraulics=as_path(args.hydraulics),
                control=as_path(args.control))


def _cmd_compare(args: argparse.Namespace) -> int:
    from trackmj.report import compare, write_compare
    from trackmj.sim.setup import prepare

    controllers = args.controllers.split(",") if args.controllers else [None]
    setups = [prepare(args.scenario, controller=c, estimator=args.estimator, seed=args.seed,
                      duration=args.duration, **_files(args)) for c in controllers]
    scenario = setups[0].scenario
    out = Path(args.out or f"runs/compare-{scenario.name}")
    base = _specs_base(args, str(args.scenario))
    outcome = compare(base, [s.controller for s in setups], out, seed=args.seed,
                      workers=args.workers, scheduler=args.scheduler)
    for spec, error in outcome.failed:
        print(f"trackmj: {spec.architecture} {spec.controller}: {error}", file=sys.stderr)
    doc = write_compare(outcome, out, scenario, setups[0].duration_s)
    print(_summary_table(outcome.results, "{r.architecture} {r.controller}"))
    print(f"-> {doc}")
    return 1 if outcome.failed else 0


def _cmd_report(args: argparse.Namespace) -> int:
    from trackmj.report import check_report_dir, plan, run_matrix, write_report
    from trackmj.sim.registry import ARCHITECTURES, CONTROLLERS

    if args.seeds < 1 or args.seeds > 50:
        raise ValueError(f"--seeds = {args.seeds}: allowed 1..50")
    archs = [a for a in args.archs.split(",") if a]
    baselines = [c for c in args.baselines.split(",") if c]
    for name, given, known in (("--archs", archs, ARCHITECTURES),
                               ("--baselines", baselines, CONTROLLERS)):
        unknown = [x for x in given if x not in known]
        if unknown:
            raise ValueError(f"{name}: unknown {unknown}; allowed {sorted(known)}")
    if "tp" not in archs:
        raise ValueError("--archs must include tp: every claim and prediction error is "
                         "against it")
    out = check_report_dir(Path(args.out))
    specs = plan(args.scenarios.split(","), list(range(args.seeds)), args.duration, archs,
                 baselines)
    matrix = run_matrix(specs, out, workers=args.workers, scheduler=args.scheduler)
    path = write_report(matrix.results, out, matrix)
    print(f"{len(matrix.results)} runs ({matrix.resumed} resumed, {len(matrix.failed)} failed) "
          f"in {matrix.wall_time_s:.0f} s -> {path}")
    return 1 if matrix.failed else 0


def _cmd_view(args: argparse.Namespace) -> int:
    from trackmj.playback import open_viewer

    open_viewer(args.path)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from trackmj.sim.registry import ARCHITECTURES, CONTROLLERS, ESTIMATORS, choices

    parser = argparse.ArgumentParser(prog="trackmj", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    def model_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--model", help="MJCF file (default: packaged models/lf1352.xml)")
        p.add_argument("--params", help="parameter TOML (default: packaged lf1352.toml)")

    model = sub.add_parser("model", help="inspect or regenerate the track model")
    model_sub = model.add_subparsers(dest="model_command", required=True)
    info = model_sub.add_parser("info", help="summary: bodies, DOF, links, masses, contacts")
    model_args(info)
    info.set_defaults(func=_cmd_model_info)
    gen = model_sub.add_parser("generate", help="regenerate lf1352.xml from the TOML")
    gen.add_argument("--params", help="parameter TOML (default: packaged lf1352.toml)")
    gen.add_argument("--out", help="output MJCF path (default: packaged lf1352.xml)")
    gen.set_defaults(func=_cmd_model_generate)

    drive = sub.add_parser("drive", help="drive the track with the passive tensioner")
    model_args(drive)
    drive.add_argument("--speed", type=float, default=1.5, help="sprocket pitch speed [m/s]")
    drive.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    drive.add_argument("--preload", type=float, help="tensioner preload [kN]")
    drive.add_argument("--out", help="directory for metrics.json and timeseries.parquet")
    drive.set_defaults(func=_cmd_drive)

    def file_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--model", metavar="FILE",
                       help="model parameter TOML (default: packaged models/lf1352.toml)")
        p.add_argument("--hydraulics", metavar="FILE", help="hydraulic parameter TOML "
                       "(default: packaged models/lf1352_hydraulics.toml)")
        p.add_argument("--control", metavar="FILE", help="control parameter TOML "
                       "(default: packaged models/lf1352_control.toml)")
        p.add_argument("--set", metavar="KIND.TABLE.KEY=VALUE", action="append", default=[],
                       help="override one key of a file (repeatable), KIND one of model, "
                            "hydraulics, control, scenario; e.g. "
                            "--set hydraulics.fluid.bulk_modulus_Pa=1.2e9 "
                            "--set scenario.track.speed_m_s=2.0")

    def executor_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--workers", type=int, help="Dask worker processes of the local "
                       "cluster (default: one per core)")
        p.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, "
                       "e.g. tcp://HOST:8786, instead of a local cluster")

    def run_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("scenario", help="W1..W5 or a scenario TOML file")
        p.add_argument("--estimator", choices=choices(ESTIMATORS),
                       help="default: the scenario's")
        p.add_argument("--seed", type=int, default=0, help="noise and terrain seed")
        p.add_argument("--duration", type=float, help="simulated time [s] (default: scenario)")
        p.add_argument("--out", help="output directory")
        file_args(p)

    run = sub.add_parser("run", help="one closed-loop run of a scenario")
    run_args(run)
    run.add_argument("--arch", default="tp", choices=choices(ARCHITECTURES))
    run.add_argument("--controller", choices=choices(CONTROLLERS))
    run.add_argument("--variant", default="nominal", help="W5 variant name")
    run.add_argument("--csv", action="store_true", help="also write timeseries.csv")
    run.add_argument("--rrd", action="store_true", help="also write a Rerun recording")
    run.set_defaults(func=_cmd_run)

    compare = sub.add_parser("compare", help="all architectures on one scenario, with each "
                             "reduced one's prediction error against tp")
    run_args(compare)
    compare.add_argument("--controllers", help="comma list, e.g. nmpc,lmpc,pid (each on every "
                         "architecture; one more figure overlays the controllers)")
    executor_args(compare)
    compare.set_defaults(func=_cmd_compare)

    report = sub.add_parser("report", help="W1-W5 x architectures x seeds -> report.md with "
                            "the study's claims, resumable")
    report.add_argument("--scenarios", default="W1,W2,W3,W4,W5", help="comma list")
    report.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per case")
    report.add_argument("--duration", type=float, help="simulated time per run [s]")
    report.add_argument("--archs", default="tp,dp-a,dp-b",
                        help="architectures (comma list; default: the study's three)")
    report.add_argument("--baselines", default="lmpc,pid",
                        help="baseline controllers run on tp in W1 ('' for none)")
    executor_args(report)
    report.add_argument("--out", default="runs/report",
                        help="output directory; runs already complete in it are kept")
    report.set_defaults(func=_cmd_report)

    view = sub.add_parser("view", help="open a run's Rerun recording in the viewer")
    view.add_argument("path", help="run directory or .rrd file")
    view.set_defaults(func=_cmd_view)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    from trackmj.params import ParameterError
    from trackmj.results import ResultDirectoryError
    from trackmj.sim.observers import PhysicsError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("trackmj: interrupted; earlier results were left as they were", file=sys.stderr)
        return 130
    except PhysicsError as exc:
        print(f"trackmj: stopped: {exc}", file=sys.stderr)
        return 3
    except (ParameterError, ResultDirectoryError, FileNotFoundError, ValueError,
            KeyError) as exc:
        print(f"trackmj: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
