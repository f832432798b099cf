"""Commands on the bare track and the machines: ``model info``, ``model generate``,
``machines`` and ``drive`` (the track driven with the passive tensioner).

The modules that load MuJoCo are imported inside the handlers: ``trackmj --help`` and
argument errors import this module and must stay fast.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trackmj.cli.summary import derailment_lines, tensioner_line
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.validator import ParameterError, parse_overrides

if TYPE_CHECKING:
    from trackmj.track.mechanics import ModelParams
    from trackmj.track.mjcf.geometry import Span
    from trackmj.track.plant import TrackPlant


def model_overrides(items: list[str]) -> dict:
    """The ``model`` entries of ``--set`` items (commands on the bare track take no
    others)."""
    sets = parse_overrides(items)
    other = [kind for kind, keys in sets.items() if keys and kind != "model"]
    if other:
        raise ParameterError(f"--set {other[0]}.*: this command takes only model.* keys "
                             "(the bare track has no hydraulics, control or scenario)")
    return sets["model"]


def cmd_model_info(args: argparse.Namespace) -> int:
    """``trackmj model info``: the model's bodies, DOF, links, masses, contacts and derived
    geometry, one aligned row each."""
    # start-up: --help and argument errors must not import MuJoCo
    import mujoco

    from trackmj.machines.track_plant import load_plant
    from trackmj.track.mjcf.structure import structure_text

    plant = load_plant(args.mjcf, args.model, machine=args.machine,
                       overrides=model_overrides(args.set))
    m, d = plant.model, plant.data
    p = plant.params
    link_mass = p.track.link_mass_kg * plant.link_count
    total_mass = float(m.body_subtreemass[0])
    contact_pairs = sum(1 for i in range(m.ngeom) for j in range(i + 1, m.ngeom)
                        if (m.geom_contype[i] & m.geom_conaffinity[j])
                        or (m.geom_contype[j] & m.geom_conaffinity[i]))
    tension = plant.pin_tensions_N()
    rows = [
        ("model", f"{m.names[:m.names.index(0)].decode()} "
                  f"({plant.model_path or 'generated, cached'})"),
        ("bodies", f"{m.nbody - 1} (+ world)"),
        ("degrees of freedom", f"{m.nv} (generalised coordinates {m.nq})"),
        ("links", f"{plant.link_count}, pitch {p.track.pitch_m * 1e3:.1f} mm, "
                  f"loop {plant.link_count * p.track.pitch_m:.2f} m"),
        ("road wheels", f"{p.road_wheels.count}, sprocket teeth {p.sprocket.tooth_count} "
                        f"(pitch radius {p.sprocket_pitch_radius_m * 1e3:.1f} mm)"),
        ("mass", f"{total_mass:.0f} kg: one track side with its share of the chassis "
                 "(x2 for the vehicle)"),
        ("", f"chassis share {p.chassis.mass_kg:.0f} kg, track {link_mass:.0f} kg, wheels "
             f"and carrier {total_mass - p.chassis.mass_kg - link_mass:.0f} kg"),
        ("geoms", f"{m.ngeom} ({contact_pairs} geom pairs can collide)"),
        ("equalities", f"{m.neq} pin connects ({structure_text(p)})"),
        ("actuators", f"{m.nu}: {', '.join(m.actuator(i).name for i in range(m.nu))}"),
        ("timestep", f"{m.opt.timestep * 1e3:.3f} ms, integrator "
                     f"{mujoco.mjtIntegrator(m.opt.integrator).name}"),
        ("home keyframe", f"contacts {d.ncon}, closure error "
                          f"{plant.closure_error_m * 1e3:.3f} mm, stroke "
                          f"{plant.stroke_m * 1e3:.1f} mm"),
        ("pin tension", f"{tension.min() / 1e3:.2f} .. {tension.max() / 1e3:.2f} kN (mean "
                        f"upper strand {tension[plant.upper_strand_pins()].mean() / 1e3:.2f} "
                        "kN)"),
    ]
    rows += _geometry_rows(plant)
    width = max(len(label) for label, _ in rows) + 2
    for label, text in rows:
        print(f"{label:<{width}}{text}")
    _say_idle_rollers(plant)
    return 0


def idle_rollers_line(plant: TrackPlant) -> str | None:
    """One line naming the declared return rollers that carry no track at home (the
    settled upper strand hangs clear of them: too low, or under a sprocket or idler so
    large that the strand passes high above) and the key that places them; None if every
    roller carries the strand."""
    idle = plant.idle_return_rollers()
    if not idle:
        return None
    rr, at = plant.params.return_rollers, plant.params.origin
    names = ", ".join(f"return_roller_{k + 1} ({at.key('return_rollers', 'x_m')}[{k}] = "
                      f"{rr.x_m[k]:g} m)" for k in idle)
    verb = "carries" if len(idle) == 1 else "carry"
    return (f"{names} {verb} no track at home: the settled upper strand hangs clear above "
            f"{'it' if len(idle) == 1 else 'them'} at {at.key('return_rollers', 'z_m')} = "
            f"{rr.z_m:g} m; the model runs as if {'it' if len(idle) == 1 else 'they'} were "
            "not there (raise z_m toward the line from the sprocket's top to the idler's, or "
            "remove the entry)")


def _say_idle_rollers(plant: TrackPlant) -> None:
    """:func:`idle_rollers_line` on stderr, if any."""
    line = idle_rollers_line(plant)
    if line is not None:
        print(f"trackmj: {line}", file=sys.stderr)


def _geometry_rows(plant: TrackPlant) -> list[tuple[str, str]]:
    """The derived geometry of the plant's layout and what its home keyframe measures."""
    # start-up: --help and argument errors must not import SciPy
    from trackmj.results.store import preload_text
    from trackmj.track.mjcf.geometry import (
        catenary_sag_m,
        derive_geometry,
        measured_sag_m,
        static_strand_tension_N,
    )
    from trackmj.track.mjcf.layout import compute_layout
    from trackmj.track.plant import PassiveTensioner

    p = plant.params
    layout = compute_layout(p)
    g = derive_geometry(p, layout)
    weight = float(plant.model.body_subtreemass[0]) * p.simulation.gravity_m_s2
    ground = plant.contact_forces_N()["ground"]
    end = "front" if p.sprocket.x_m > p.idler.x_m else "rear"
    rows = [
        ("layout", f"sprocket at the {end}, idler slide "
                   f"{math.degrees(p.idler.slide_angle_rad):.1f}° above horizontal, idler "
                   f"centre x {layout.idler_x_m:.4f} m (guess {p.idler.x_m:g} m)"),
        ("perimeter", f"loop {g.loop_m:.4f} m ({p.track.link_count} × "
                      f"{p.track.pitch_m * 1e3:.1f} mm), path round the pin circles "
                      f"{g.path_m:.4f} m, layout closure {g.closure_m * 1e3:.2g} mm"),
        ("wraps", ", ".join(f"{name} {math.degrees(a):.1f}°"
                            for name, a in g.wraps_rad.items() if a > 1e-6)),
    ]
    pins = plant.pins_layout_frame()
    upper_N = float(plant.pin_tensions_N()[plant.upper_strand_pins()].mean())
    supports = _upper_strand_supports(plant)
    sagged = False
    for s in g.spans:
        text = f"{s.start} -> {s.end}: {s.length_m * 1e3:.0f} mm"
        sag, chord = measured_sag_m(s, pins, p.track.pitch_m) if s.upper else (0.0, 0.0)
        if chord > 0.0:
            sagged = True
            text += (f", sag at home {sag * 1e3:.1f} mm over {chord * 1e3:.0f} mm (shallow "
                     f"catenary at the home tension "
                     f"{catenary_sag_m(p, s, upper_N, chord) * 1e3:.1f} mm)")
            text += _span_supports(s, supports)
        rows.append(("upper span" if s.upper else "lower span", text))
    if sagged:
        per_m = p.track.link_mass_kg / p.track.pitch_m * p.simulation.gravity_m_s2
        rows += [("", "sag at home: the pins' largest drop below the chord through the "
                      "first and last pins inside the span, in the settled home keyframe"),
                 ("", "catenary: the sag of that chord hanging free between its ends under "
                      f"the track's own weight only, w·L²·cos θ/(8·T) with w {per_m / 1e3:.2f} "
                      f"kN/m, T {upper_N / 1e3:.2f} kN (mean upper-strand pin tension at "
                      "home); a span resting on wheels between its ends sags less")]
    settled_N = PassiveTensioner.from_params(p).standing_force_N(plant.stroke_m)
    strand_N = static_strand_tension_N(p, g.idler_factor, settled_N)
    rows += [
        ("weight this side", f"{weight / 1e3:.2f} kN (Σ ground normal force at home "
                             f"{ground / 1e3:.2f} kN)"),
        ("tensioner", preload_text(p.tensioner.preload_N, p.idler.stroke_at_layout_m,
                                   settled_N, plant.stroke_m)
         + f" (spring {p.tensioner.stiffness_N_m / 1e6:g} MN/m)"),
        ("static strand tension", f"{strand_N / 1e3:.2f} kN at the settled idler force "
                                  f"{settled_N / 1e3:.2f} kN (idler geometry factor "
                                  f"{g.idler_factor:.4f}; frictionless idler)"),
        ("drive", _drive_text(p)),
    ]
    return rows


def _drive_text(p: ModelParams) -> str:
    """The sprocket drive of ``p``: its velocity servo, torque limit and parking brake."""
    spr, brake = p.sprocket, p.parking_brake
    text = (f"velocity servo {spr.drive_gain_N_m_s / 1e3:g} kN·m·s/rad, torque limit "
            f"{spr.drive_torque_limit_N_m / 1e3:g} kN·m; ")
    if brake is None:
        return text + "no parking brake (standing, the servo yields at T/kv)"
    return text + (f"parking brake holds {brake.holding_torque_N_m / 1e3:g} kN·m at a zero "
                   f"command (drive line {brake.drive_line_stiffness_N_m_rad / 1e6:g} "
                   "MN·m/rad)")


def _upper_strand_supports(plant: TrackPlant) -> list[tuple[str, float, float]]:
    """What carries the upper strand at its current state besides its end wheels: (body,
    x [m] of the pin it carries in the layout frame, contact normal force [N]) of every
    contact between an upper-strand link and a body that is not a link."""
    # start-up: --help and argument errors must not import MuJoCo (nor NumPy)
    import mujoco
    import numpy as np

    from trackmj.track.mjcf.names import link_name

    m, d = plant.model, plant.data
    link_of_body = {m.body(link_name(k)).id: k for k in range(plant.link_count)}
    upper = set(plant.upper_strand_pins().tolist())
    x = plant.pins_layout_frame()[:, 0]
    wrench = np.zeros(6)
    found = []
    for i in range(d.ncon):
        bodies = (int(m.geom_bodyid[d.contact[i].geom1]), int(m.geom_bodyid[d.contact[i].geom2]))
        links = [link_of_body[b] for b in bodies if b in link_of_body]
        others = [b for b in bodies if b not in link_of_body]
        if len(links) == 1 and others and links[0] in upper:
            mujoco.mj_contactForce(m, d, i, wrench)
            found.append((m.body(others[0]).name, float(x[links[0]]), float(wrench[0])))
    return found


def _span_supports(span: Span, supports: list[tuple[str, float, float]]) -> str:
    """"; rests on WHEEL, ... (F kN)" for the ``supports`` inside ``span`` other than its
    end wheels; empty for a free span."""
    lo, hi = sorted((span.points[0][0], span.points[1][0]))
    inside = [(name, force) for name, x, force in supports
              if lo < x < hi and name not in (span.start, span.end)]
    if not inside:
        return ""
    names = list(dict.fromkeys(name for name, _ in inside))
    return (f"; not a free span: it rests on {', '.join(names)} "
            f"({sum(f for _, f in inside) / 1e3:.2f} kN at home)")


def cmd_model_generate(args: argparse.Namespace) -> int:
    """``trackmj model generate``: write a machine's reference MJCF from its files."""
    # start-up: --help and argument errors must not import MuJoCo
    from trackmj.machines.assembly import command_argument, resolve
    from trackmj.track.mechanics import load_model_params
    from trackmj.track.mjcf.generate import write_model

    machine = resolve(args.machine)
    out = args.out or (machine.reference_mjcf and machine.reference_mjcf.with_name(
        machine.reference_mjcf.name.removesuffix("_scene.xml") + ".xml"))
    if out is None:
        raise ValueError(f"machine {machine.name} has no reference_mjcf in "
                         f"{machine.file.name}: give --out FILE.xml")
    mechanics = Path(args.model or machine.mechanics)
    params = load_model_params(mechanics, overrides=model_overrides(args.set))
    named = command_argument(machine)
    if Path(named).parent == Path(out).resolve().parent:   # beside the files it writes
        named = Path(named).name
    scene = write_model(out, params, machine.name,
                        origin=f"From {mechanics.name}{' with --set' if args.set else ''}; "
                               f"regenerate with: trackmj model generate --machine {named}")
    print(f"wrote {out} (the machine part)")
    print(f"wrote {scene} (the scene including it: the file to load)")
    return 0


def cmd_machines(args: argparse.Namespace) -> int:
    """``trackmj machines``: the shipped machines, one a line."""
    # start-up: --help and argument errors must not import MuJoCo
    from trackmj.machines.assembly import shipped

    machines = shipped()
    width = max(len(name) for name in machines) + 2
    for name, m in machines.items():
        default = " (default)" if name == DEFAULT_MACHINE else ""
        print(f"{name:<{width}}{m.description}{default}")
    print("or any machine file (*_machine.toml naming its mechanics, hydraulics and control "
          "files; see README, Your machine)")
    return 0


def cmd_drive(args: argparse.Namespace) -> int:
    """``trackmj drive``: the track driven with the passive tensioner; exit code 0 when
    healthy, 1 if MuJoCo warned, a derailment check failed or the integrator created more
    than :data:`~trackmj.sim.drive.INTEGRATOR_CREATION_MAX_REL` of the drive work (2 for
    bad input and 3 for a run that leaves physics, from :func:`trackmj.cli.main.main`)."""
    # start-up: --help and argument errors must not import MuJoCo
    from trackmj.results.store import passive_text
    from trackmj.sim.drive import INTEGRATOR_CREATION_MAX_REL, drive

    overrides = model_overrides(args.set)
    out = args.out or _drive_folder(args)
    result = drive(args.speed, args.duration, model=args.model, mjcf=args.mjcf,
                   preload_N=args.preload, out_dir=out, tensioner=args.tensioner,
                   machine=args.machine, overrides=overrides, hitch_pull_N=args.hitch_pull,
                   grade=args.grade, stop_s=args.stop_at)
    m, s, e = result.metrics, result.metrics["steady"], result.metrics["track_energy"]
    stop = "" if args.stop_at is None else f", stopped at {args.stop_at:g} s"
    print(f"drove {args.duration:.1f} s at {args.speed:.2f} m/s (from rest in "
          f"{m['ramp_s']:.2f} s){stop}: "
          f"{m['real_time_factor']:.2f}x real time ({m['plant_real_time_factor']:.2f}x for "
          "the plant steps alone)")
    if m["tensioner"]["element"] == "fmu":
        print(tensioner_line(m["tensioner"]))
    if "preload_N" in m:
        print(f"tensioner          {passive_text(m)}")
    print(f"idler force        mean {s['idler_force_mean_N'] / 1e3:7.2f} kN   "
          f"min {s['idler_force_min_N'] / 1e3:7.2f}  max {s['idler_force_max_N'] / 1e3:7.2f}")
    print(f"strand tension     upper {s['upper_strand_tension_mean_N'] / 1e3:5.2f} kN, "
          f"sprocket lower run {s['lower_strand_tension_mean_N'] / 1e3:5.2f} kN")
    print(f"vehicle speed      {s['vehicle_speed_mean_m_s']:.3f} m/s "
          f"(sprocket pitch speed {s['track_speed_mean_m_s']:.3f} m/s)")
    print(f"drive torque       mean {s['drive_torque_mean_N_m'] / 1e3:.3f} kN·m"
          + (f" (hitch load {args.hitch_pull / 1e3:g} kN)" if args.hitch_pull else "")
          + (f" (grade {args.grade:g})" if args.grade else "")
          + _parked_text(m))
    if m["stop"] is not None:
        print(stop_line(m["stop"], s))
    contacts = sum(e["contact_work_J"].values())
    print(f"energy [kJ]        drive {e['drive_work_J'] / 1e3:.3f}, tensioner "
          f"{e['tensioner_work_J'] / 1e3:.3f}, suspension {e['suspension_loss_J'] / 1e3:.3f}, "
          f"constraints {contacts / 1e3:.3f}, numerical {e['numerical_J'] / 1e3:.3f}"
          f"; dKE {e['kinetic_change_J'] / 1e3:.3f}, dPE {e['potential_change_J'] / 1e3:.3f}, "
          f"residual {e['residual_J']:.2e} J")
    print(f"max pin gap        {m['max_pin_gap_m'] * 1e3:.3f} mm   MuJoCo warnings "
          f"{m['mujoco_warnings']}")
    created = m["integrator_created_rel"] > INTEGRATOR_CREATION_MAX_REL
    if created:
        term, joules = max(e["numerical_terms_J"].items(), key=lambda item: item[1])
        print(f"integrator         created {100 * m['integrator_created_rel']:.1f} % of the "
              f"drive work (more than {100 * INTEGRATOR_CREATION_MAX_REL:g} %; most in "
              f"{term}, {joules / 1e3:+.3f} kJ): the 1 ms step pumps the pins' soft rows at "
              "speed, and an abrupt stop's impact the contacts' explicit springs; the forces "
              "are not to be trusted (models/README.md, 'The net numerical term against "
              "speed')")
    for line in derailment_lines(m):
        print(line)
    print(f"wrote {result.out_dir} (metrics.json, timeseries.parquet, drive.png)")
    healthy = m["mujoco_warnings"] == 0 and m["derailment_checks_failed"] == 0
    return 0 if healthy and not created else 1


def stop_line(stop: dict[str, float], steady: dict[str, float]) -> str:
    """The summary line of an abrupt stop (:func:`trackmj.sim.drive.stop_metrics`): the
    idler force's peak against its steady maximum before the stop, the drive torque's
    extreme, when the sprocket and the hull came to rest, and the hull's rebound."""
    def rest(seconds: float) -> str:
        return "still moving at the end" if math.isnan(seconds) else f"{seconds:.2f} s"

    return (f"stop               idler force peak {stop['idler_force_max_N'] / 1e3:.2f} kN "
            f"(steady max {steady['idler_force_max_N'] / 1e3:.2f}), drive torque "
            f"{stop['drive_torque_extreme_N_m'] / 1e3:.2f} kN·m; at rest after: sprocket "
            f"{rest(stop['sprocket_still_after_s'])}, hull {rest(stop['hull_still_after_s'])}"
            f" (rebound {stop['hull_rebound_m_s']:.2f} m/s)")


def _parked_text(metrics: dict[str, Any]) -> str:
    """What held a standing drive: its parking brake with its holding torque, or the velocity
    servo alone ('' for a drive that moved)."""
    holding = metrics["parking_brake_holding_N_m"]
    if metrics["parked"]:
        return f"; parked: the parking brake holds up to {holding / 1e3:g} kN·m"
    if metrics["speed_m_s"] == 0.0 and holding is None:
        return "; no parking brake: the velocity servo holds, creeping under the torque"
    return ""


def _drive_folder(args: argparse.Namespace) -> str:
    """Default folder of ``drive``: ``runs/drive-MACHINE-SPEED`` and the first 8 digits of
    the SHA-256 of its other inputs (duration, preload, a hitch load, a grade, a stop,
    ``--set``, and the content of the model, MJCF and tensioner files), so drives of other
    inputs never share a folder and a drive of the same inputs replaces its old result."""
    inputs: dict[str, object] = {"duration_s": args.duration, "preload_N": args.preload,
                                 "set": sorted(args.set)}
    if args.hitch_pull:
        inputs["hitch_pull_N"] = args.hitch_pull
    if args.grade:
        inputs["grade"] = args.grade
    if args.stop_at is not None:
        inputs["stop_s"] = args.stop_at
    for option in ("model", "mjcf", "tensioner", "machine"):
        given = getattr(args, option)
        if given is not None and Path(given).is_file():
            inputs[option] = hashlib.sha256(Path(given).read_bytes()).hexdigest()
        else:
            inputs[option] = given
    machine = args.machine or DEFAULT_MACHINE
    digest = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:8]
    return f"runs/drive-{Path(machine).stem}-{args.speed:g}mps-{digest}"
