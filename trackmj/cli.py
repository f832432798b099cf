"""``trackmj`` command line.

Display units (kN, mm, MPa) appear only here; everything inside is SI.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np


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
    from trackmj.plant import PassiveTensioner, TrackPlant

    if not 0.0 <= abs(args.speed) <= 5.0:
        raise SystemExit("--speed must be within [-5, 5] m/s")
    if not 0.0 < args.duration <= 3600.0:
        raise SystemExit("--duration must be within (0, 3600] s")
    plant = TrackPlant.load(args.model, args.params)
    element = PassiveTensioner.from_params(plant.params)
    if args.preload is not None:
        element.preload_N = args.preload * 1e3
    ramp = min(1.0, args.duration / 4.0)
    samples: list[tuple[float, float, float, float, float]] = []
    derail_events = 0

    def record(pl: TrackPlant) -> None:
        nonlocal derail_events
        if round(pl.time_s * 1000) % 10:
            return
        t = pl.pin_tensions_N()
        upper = pl.upper_strand_pins()
        samples.append((pl.time_s, pl.idler_force_N, float(t[upper].mean()), float(t.max()),
                        pl.chassis_velocity[0]))
        if round(pl.time_s * 1000) % 100 == 0 and pl.derailment().any:
            derail_events += 1

    start = time.perf_counter()
    plant.run(element, args.duration, lambda t: args.speed * min(1.0, t / ramp), record)
    wall = time.perf_counter() - start
    arr = np.array(samples)
    steady = arr[arr[:, 0] >= ramp + 1.0] if args.duration > ramp + 1.0 else arr
    print(f"drove {args.duration:.1f} s at {args.speed:.2f} m/s in {wall:.1f} s wall "
          f"({args.duration / wall:.2f}x real time)")
    print(f"idler force        mean {steady[:, 1].mean() / 1e3:7.2f} kN   "
          f"min {steady[:, 1].min() / 1e3:7.2f}  max {steady[:, 1].max() / 1e3:7.2f}")
    print(f"upper-strand tension mean {steady[:, 2].mean() / 1e3:5.2f} kN   "
          f"min {steady[:, 2].min() / 1e3:7.2f}  max {steady[:, 2].max() / 1e3:7.2f}")
    print(f"peak pin tension   {arr[:, 3].max() / 1e3:7.2f} kN")
    print(f"vehicle speed      {steady[:, 4].mean():.3f} m/s "
          f"(sprocket pitch speed {args.speed:.3f} m/s)")
    print(f"closure error      {plant.closure_error_m * 1e3:.3f} mm   "
          f"MuJoCo warnings {plant.warning_count}   derailment checks failed {derail_events}")
    return 0 if plant.warning_count == 0 and derail_events == 0 else 1


SUMMARY_METRICS = (
    ("rmse_N", "tension RMSE", 1e-3, "kN"),
    ("peak_error_N", "peak error", 1e-3, "kN"),
    ("overshoot_N", "overshoot", 1e-3, "kN"),
    ("settling_time_s", "settling time", 1.0, "s"),
    ("fluctuation_N", "fluctuation (±)", 1e-3, "kN"),
    ("energy_J.pump", "pump energy", 1e-3, "kJ"),
    ("energy_J.circuit", "circuit energy", 1e-3, "kJ"),
    ("energy_J.mechanical", "work into the track", 1e-3, "kJ"),
    ("valve_switch_rate_Hz", "valve switching", 1.0, "Hz"),
    ("interface_energy_residual_J", "interface residual", 1.0, "J"),
    ("solve_time_median_s", "solve time median", 1e3, "ms"),
    ("solve_time_max_s", "solve time max", 1e3, "ms"),
    ("real_time_factor", "real-time factor", 1.0, "x"),
)


def _metric(metrics: dict, key: str) -> float:
    """The metric at dotted ``key`` (``energy_J.pump`` is a term of the energy table); NaN
    where the run has none."""
    value = metrics
    for part in key.split("."):
        value = value.get(part, float("nan")) if isinstance(value, dict) else float("nan")
    return value if isinstance(value, float) else float("nan")


def _summary_table(results: list, title: str) -> str:
    """Markdown table of the headline metrics, one column per result."""
    head = "| metric | " + " | ".join(title.format(r=r) for r in results) + " |"
    lines = [head, "|---|" + "---|" * len(results)]
    for key, name, scale, unit in SUMMARY_METRICS:
        cells = []
        for r in results:
            value = _metric(r.metrics, key)
            cells.append("–" if value != value else f"{value * scale:.3g}")
        lines.append(f"| {name} [{unit}] | " + " | ".join(cells) + " |")
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


def _cmd_compare(args: argparse.Namespace) -> int:
    from concurrent.futures import ProcessPoolExecutor

    from trackmj.figures import compare_figure
    from trackmj.io import write_text_atomic
    from trackmj.results import check_output_dir, write_result
    from trackmj.sim.setup import prepare

    controllers = args.controllers.split(",") if args.controllers else [None]
    setups = [prepare(args.scenario, controller=c, estimator=args.estimator, seed=args.seed,
                      duration=args.duration, **_files(args)) for c in controllers]
    scenario = setups[0].scenario
    out = check_output_dir(Path(args.out or f"runs/compare-{scenario.name}"))
    base = dict(scenario=scenario, estimator=args.estimator, seed=args.seed,
                duration=args.duration, model=args.model, hydraulics=args.hydraulics,
                control=args.control, set=args.set)
    cases = [dict(base, architecture=a, controller=c) for c in controllers
             for a in ("tp", "tp-weak", "dp-b")]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(_run_one, cases))
        tp = {r.controller: r for r in results if r.architecture == "tp"}
        dpa = list(pool.map(_run_one, [dict(base, architecture="dp-a", controller=c,
                                             tp_result=tp[s.controller])
                                        for c, s in zip(controllers, setups, strict=True)]))
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
