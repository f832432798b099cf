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
    print(f"equalities       {m.neq} (loop closure), actuators {m.nu}: "
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


SUMMARY_METRICS = (
    ("rmse_N", "tension RMSE", 1e-3, "kN"),
    ("peak_error_N", "peak error", 1e-3, "kN"),
    ("overshoot_N", "overshoot", 1e-3, "kN"),
    ("settling_time_s", "settling time", 1.0, "s"),
    ("fluctuation_N", "fluctuation (±)", 1e-3, "kN"),
    ("supply_energy_J", "supply energy", 1e-3, "kJ"),
    ("valve_switch_rate_Hz", "valve switching", 1.0, "Hz"),
    ("interface_energy_residual_J", "interface residual", 1.0, "J"),
    ("solve_time_median_s", "solve time median", 1e3, "ms"),
    ("solve_time_max_s", "solve time max", 1e3, "ms"),
    ("real_time_factor", "real-time factor", 1.0, "x"),
)


def _summary_table(results: list, title: str) -> str:
    """Markdown table of the headline metrics, one column per result."""
    head = "| metric | " + " | ".join(title.format(r=r) for r in results) + " |"
    lines = [head, "|---|" + "---|" * len(results)]
    for key, name, scale, unit in SUMMARY_METRICS:
        cells = []
        for r in results:
            value = r.metrics.get(key, float("nan"))
            cells.append("–" if value != value else f"{value * scale:.3g}")
        lines.append(f"| {name} [{unit}] | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _run_one(kwargs: dict):
    from trackmj.simulate import simulate

    return simulate(**kwargs)


def _cmd_run(args: argparse.Namespace) -> int:
    from trackmj.figures import run_figure
    from trackmj.results import write_result
    from trackmj.scenarios import load_scenario

    scenario = load_scenario(args.scenario)
    controller = args.controller or scenario.controller
    out = Path(args.out or f"runs/{scenario.name}-{args.arch}-{controller}-s{args.seed}")
    result = _run_one(dict(scenario=scenario, architecture=args.arch,
                           controller=args.controller, estimator=args.estimator,
                           seed=args.seed, duration=args.duration, variant=args.variant,
                           rrd=out / "run.rrd" if args.rrd else None, progress=True))
    write_result(result, out, csv=args.csv)
    run_figure(result, out / "timeseries.png")
    print(f"{scenario.name} ({scenario.title}), {result.architecture}, {result.controller}/"
          f"{result.estimator}, seed {result.seed} -> {out}")
    print(_summary_table([result], "{r.architecture}"))
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from concurrent.futures import ProcessPoolExecutor

    from trackmj.figures import compare_figure
    from trackmj.io import write_text_atomic
    from trackmj.results import write_result
    from trackmj.scenarios import load_scenario

    scenario = load_scenario(args.scenario)
    out = Path(args.out or f"runs/compare-{scenario.name}")
    controllers = args.controllers.split(",") if args.controllers else [None]
    base = dict(scenario=scenario, estimator=args.estimator, seed=args.seed,
                duration=args.duration)
    cases = [dict(base, architecture=a, controller=c) for c in controllers
             for a in ("tp", "tp-weak", "dp-b")]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_run_one, cases))
        tp = {r.controller: r for r in results if r.architecture == "tp"}
        dpa = list(pool.map(_run_one, [dict(base, architecture="dp-a", controller=c,
                                             tp_result=tp[c or scenario.controller])
                                        for c in controllers]))
    results += dpa
    order = {"tp": 0, "tp-weak": 1, "dp-a": 2, "dp-b": 3}
    results.sort(key=lambda r: (r.controller, order[r.architecture]))
    for r in results:
        write_result(r, out / f"{r.architecture}-{r.controller}")
    label = "architecture" if len(controllers) == 1 else "controller"
    for c in {r.controller for r in results}:
        compare_figure([r for r in results if r.controller == c], out / f"compare-{c}.png")
    table = _summary_table(results, "{r.architecture} {r.controller}")
    write_text_atomic(out / "compare.md", f"# {scenario.name}: {scenario.title}\n\n"
                      f"seed {args.seed}, duration {results[0].metadata['duration_s']} s\n\n"
                      f"{table}\n")
    print(table)
    print(f"-> {out} ({label} comparison)")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from trackmj.report import run_matrix, write_report

    if args.seeds < 1 or args.seeds > 50:
        raise ValueError(f"--seeds = {args.seeds}: allowed 1..50")
    scenarios = args.scenarios.split(",")
    results = run_matrix(scenarios, list(range(args.seeds)), args.duration, args.workers)
    path = write_report(results, Path(args.out))
    print(f"{len(results)} runs -> {path}")
    return 0


def _cmd_view(args: argparse.Namespace) -> int:
    from trackmj.playback import open_viewer

    open_viewer(args.path)
    return 0


def build_parser() -> argparse.ArgumentParser:
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

    def run_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("scenario", help="W1..W5 or a scenario TOML file")
        p.add_argument("--estimator", choices=("ekf", "ukf"), help="default: the scenario's")
        p.add_argument("--seed", type=int, default=0, help="noise and terrain seed")
        p.add_argument("--duration", type=float, help="simulated time [s] (default: scenario)")
        p.add_argument("--out", help="output directory")

    run = sub.add_parser("run", help="one closed-loop run of a scenario")
    run_args(run)
    run.add_argument("--arch", default="tp", choices=("tp", "tp-weak", "dp-a", "dp-b"))
    run.add_argument("--controller", choices=("nmpc", "lmpc", "pid"))
    run.add_argument("--variant", default="nominal", help="W5 variant name")
    run.add_argument("--csv", action="store_true", help="also write timeseries.csv")
    run.add_argument("--rrd", action="store_true", help="also write a Rerun recording")
    run.set_defaults(func=_cmd_run)

    compare = sub.add_parser("compare", help="all architectures on one scenario")
    run_args(compare)
    compare.add_argument("--controllers", help="comma list, e.g. nmpc,lmpc,pid")
    compare.add_argument("--workers", type=int, default=2, help="parallel processes")
    compare.set_defaults(func=_cmd_compare)

    report = sub.add_parser("report", help="W1-W5 x architectures x seeds -> report.md")
    report.add_argument("--scenarios", default="W1,W2,W3,W4,W5", help="comma list")
    report.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per case")
    report.add_argument("--duration", type=float, help="simulated time per run [s]")
    report.add_argument("--workers", type=int, default=2, help="parallel processes")
    report.add_argument("--out", default="runs/report", help="output directory")
    report.set_defaults(func=_cmd_report)

    view = sub.add_parser("view", help="open a run's Rerun recording in the viewer")
    view.add_argument("path", help="run directory or .rrd file")
    view.set_defaults(func=_cmd_view)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    from trackmj.params import ParameterError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ParameterError, FileNotFoundError, ValueError, KeyError) as exc:
        print(f"trackmj: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
