"""``trackmj`` command line.

Display units (kN, mm, MPa) appear only here; everything inside is SI.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

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
    drive.set_defaults(func=_cmd_drive)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    from trackmj.params import ParameterError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ParameterError, FileNotFoundError) as exc:
        print(f"trackmj: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
