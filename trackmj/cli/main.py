"""``trackmj`` command line (also ``python -m trackmj``).

Display units (kN, mm, MPa) appear only here; everything inside is SI. Errors in the input
(a bad option, file, key or value) end with exit code 2 and one line naming what is wrong;
a run that leaves physics with exit code 3; Ctrl-C with 130.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path


def _cmd_model_info(args: argparse.Namespace) -> int:
    import mujoco

    from trackmj.track.mjcf.structure import structure_text
    from trackmj.track.plant import TrackPlant

    plant = TrackPlant.load(args.model, args.params, machine=args.machine,
                            overrides=_model_overrides(args.set))
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
    return 0


def _geometry_rows(plant: object) -> list[tuple[str, str]]:
    """The derived geometry of the plant's layout and what its home keyframe measures."""
    import math

    from trackmj.track.mjcf.geometry import catenary_sag_m, derive_geometry, measured_sag_m
    from trackmj.track.mjcf.layout import compute_layout

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
    for s in g.spans:
        text = f"{s.start} -> {s.end}: {s.length_m * 1e3:.0f} mm"
        sag, chord = measured_sag_m(s, pins, p.track.pitch_m) if s.upper else (0.0, 0.0)
        if chord > 0.0:
            text += (f", sag at home {sag * 1e3:.1f} mm over {chord * 1e3:.0f} mm (shallow "
                     f"catenary at the home tension "
                     f"{catenary_sag_m(p, s, upper_N, chord) * 1e3:.1f} mm)")
        rows.append(("upper span" if s.upper else "lower span", text))
    rows += [
        ("weight this side", f"{weight / 1e3:.2f} kN (Σ ground normal force at home "
                             f"{ground / 1e3:.2f} kN)"),
        ("static strand tension", f"{g.strand_tension_N / 1e3:.2f} kN at the preload "
                                  f"{p.tensioner.preload_N / 1e3:.1f} kN (idler geometry "
                                  f"factor {g.idler_factor:.4f}; frictionless idler)"),
    ]
    return rows


def _cmd_model_generate(args: argparse.Namespace) -> int:
    from trackmj.machines.assembly import resolve
    from trackmj.track.mechanics import load_model_params
    from trackmj.track.mjcf.generate import write_model

    machine = resolve(args.machine)
    out = args.out or (machine.reference_mjcf and machine.reference_mjcf.with_name(
        machine.reference_mjcf.name.removesuffix("_scene.xml") + ".xml"))
    if out is None:
        raise ValueError(f"machine {machine.name} has no reference_mjcf in "
                         f"{machine.file.name}: give --out FILE.xml")
    params = load_model_params(args.params or machine.mechanics,
                               overrides=_model_overrides(args.set))
    path = write_model(out, params, machine.name)
    print(f"wrote {path}")
    return 0


def _model_overrides(items: list[str]) -> dict:
    """The ``model`` entries of ``--set`` items (commands on the bare track take no
    others)."""
    from trackmj.validator import ParameterError, parse_overrides

    sets = parse_overrides(items)
    other = [kind for kind, keys in sets.items() if keys and kind != "model"]
    if other:
        raise ParameterError(f"--set {other[0]}.*: this command takes only model.* keys "
                             "(the bare track has no hydraulics, control or scenario)")
    return sets["model"]


def _cmd_machines(args: argparse.Namespace) -> int:
    from trackmj.machines.assembly import DEFAULT_MACHINE, shipped

    machines = shipped()
    width = max(len(name) for name in machines) + 2
    for name, m in machines.items():
        default = " (default)" if name == DEFAULT_MACHINE else ""
        print(f"{name:<{width}}{m.description}{default}")
    print("or any machine file (*_machine.toml naming its mechanics, hydraulics and control "
          "files; see README, Your machine)")
    return 0


def _cmd_drive(args: argparse.Namespace) -> int:
    from trackmj.sim.drive import drive

    result = drive(args.speed, args.duration, model=args.model, params=args.params,
                   preload_N=args.preload, out_dir=args.out, tensioner=args.tensioner,
                   machine=args.machine, overrides=_model_overrides(args.set))
    m, s, e = result.metrics, result.metrics["steady"], result.metrics["track_energy"]
    print(f"drove {args.duration:.1f} s at {args.speed:.2f} m/s: {m['real_time_factor']:.2f}x "
          f"real time ({m['plant_real_time_factor']:.2f}x for the plant steps alone)")
    if m["tensioner"]["element"] == "fmu":
        print(_tensioner_line(m["tensioner"]))
    print(f"idler force        mean {s['idler_force_mean_N'] / 1e3:7.2f} kN   "
          f"min {s['idler_force_min_N'] / 1e3:7.2f}  max {s['idler_force_max_N'] / 1e3:7.2f}")
    print(f"strand tension     upper {s['upper_strand_tension_mean_N'] / 1e3:5.2f} kN, "
          f"sprocket lower run {s['lower_strand_tension_mean_N'] / 1e3:5.2f} kN")
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
                   "acceptance.mean_min_N", "acceptance.mean_max_N",
                   "acceptance.recovery_max_s", "acceptance.steady_offset_max_rel",
                   "energy_J.pump", "energy_J.circuit", "energy_J.mechanical",
                   "valve_switch_rate_Hz", "interface_energy_residual_J",
                   "solve_time_median_s", "solve_time_max_s", "real_time_factor")
"""Rows of the summary table, metric keys (dotted for a table entry; labels and display
units in :data:`trackmj.results.metrics.METRIC_DISPLAY`)."""
STEP_METRICS = ("overshoot_lp_N", "settling_time_lp_s")
DISTURBANCE_METRICS = ("disturbance_peak_error_lp_N", "recovery_time_lp_s")
UNSETTLED = ("settling_time_lp_s", "recovery_time_lp_s")


def _metric(metrics: dict, key: str) -> float:
    """The metric at dotted ``key`` (``energy_J.pump`` is a term of the energy table); NaN
    where the run has none."""
    value = metrics
    for part in key.split("."):
        value = value.get(part, float("nan")) if isinstance(value, dict) else float("nan")
    return value if isinstance(value, float) else float("nan")


def _summary_table(results: list, title: str) -> str:
    """Markdown table of the headline metrics, one column per result. Rows of a step or a
    disturbance appear only where the scenario has one; a settling or recovery time that
    never came reads "not within ±band" instead of a dash."""
    from trackmj.results.metrics import METRIC_DISPLAY, lookup

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


def _files(args: argparse.Namespace) -> dict:
    """The parameter files, tensioner file and ``--set`` overrides given on the command
    line."""
    return dict(model=args.model, hydraulics=args.hydraulics, control=args.control,
                overrides=args.set, tensioner=args.tensioner, machine=args.machine)


def _tensioner_line(described: dict) -> str:
    """One line on an FMU tensioner's coupling (``Element.run_metrics()["tensioner"]``)."""
    cost = described.get("step_cost_us")
    per_step = f"; {cost:.0f} µs of FMU calls per 1 ms step" if cost is not None else ""
    return (f"tensioner: FMU {described['fmu']}, {described['coupling_description']} "
            f"(dF/dv: {described['dF_dv']}){per_step}")


def run_folder(setup: object, key: str, *, defaults: bool) -> Path:
    """Default folder of ``trackmj run``: ``runs/SCENARIO-ARCH-CONTROLLER-sSEED`` for the
    scenario's own inputs (``defaults``), with ``-VARIANT`` for a W5 variant and the first
    8 digits of the inputs' hash (:func:`trackmj.study.campaign.inputs_key`) for any other input
    (estimator, --duration, --set, parameter or tensioner files), so that runs of other
    inputs never share a folder."""
    name = (f"{setup.scenario.name}-{setup.architecture}-{setup.controller}-"
            f"s{setup.seed}")
    if setup.variant.name != "nominal":
        name += f"-{setup.variant.name}"
    if not defaults:
        name += f"-{key[:8]}"
    return Path("runs") / name


def _stored_inputs_key(out: Path) -> str | None:
    """The inputs key of the run in folder ``out`` ('' for a run without one, None if
    ``out`` holds no run)."""
    import json

    from trackmj.results.store import METRICS

    try:
        doc = json.loads((out / METRICS).read_text())
    except (OSError, ValueError):
        return None
    return str(doc.get("run", {}).get("inputs_key", ""))


def _cmd_run(args: argparse.Namespace) -> int:
    from trackmj.results.figures import run_figure
    from trackmj.results.playback import RUN_RRD
    from trackmj.results.store import ResultDirectoryError, ResultWriter
    from trackmj.scenarios.schema import check_duration
    from trackmj.sim.run import measured_log, run
    from trackmj.sim.setup import prepare
    from trackmj.study.campaign import inputs_key, run_key, stamped

    setup = prepare(args.scenario, architecture=args.arch, controller=args.controller,
                    estimator=args.estimator, seed=args.seed, duration=args.duration,
                    variant=args.variant, **_files(args))
    check_duration(setup.scenario, setup.duration_s)
    measured = (None if args.measured is None
                else measured_log(setup, args.measured, args.channels))
    key = inputs_key(setup)
    defaults = not (args.estimator or args.duration is not None or args.set or args.model
                    or args.hydraulics or args.control or args.tensioner)
    out = Path(args.out) if args.out else run_folder(setup, key, defaults=defaults)
    held = _stored_inputs_key(out)
    if held is not None and held != key and not args.overwrite:
        what = f"inputs {held[:8]}" if held else "no inputs key: an older trackmj"
        raise ResultDirectoryError(
            f"--out {out}: holds a run of other inputs ({what}; this run's are {key[:8]}); "
            "give --overwrite to replace it, or another --out")
    with ResultWriter(out) as writer:
        result = run(setup, rrd=writer.stage / RUN_RRD if args.rrd else None, progress=True,
                     measured=measured, channels=args.channels)
        result = stamped(result, inputs_key=key, run_key=run_key(setup))
        writer.commit(result, csv=args.csv,
                      extras={"timeseries.png": lambda path: run_figure(result, path,
                                                                        measured)})
    print(f"{setup.scenario.name} ({setup.scenario.title}), {result.architecture}, "
          f"{result.controller}/{result.estimator}, seed {result.seed} -> {out}")
    if result.metrics.get("tensioner", {}).get("element") == "fmu":
        print(_tensioner_line(result.metrics["tensioner"]))
    print(_summary_table([result], "{r.architecture}"))
    if measured is not None:
        print(_measured_table(result.metrics["prediction_vs_measured"], args.measured))
    return 0


MEASURED_DISPLAY = {"N": (1e-3, "kN"), "Pa": (1e-6, "MPa"), "m": (1e3, "mm"), "": (1.0, "-")}
"""Display scale and unit of a compared channel, by its SI unit."""


def _measured_table(table: dict, log: str) -> str:
    """Markdown table of ``prediction_vs_measured``: one row per channel."""
    lines = [f"prediction vs measured ({Path(log).name}; tracking window; > 0 lag: the "
             "simulation lags)", "",
             "| channel | RMSE raw | RMSE low-pass | peak (sim − meas) | lag [ms] |",
             "|---|---|---|---|---|"]
    for name, row in table.items():
        unit = name.rpartition("_")[2] if "_" in name else ""
        scale, shown = MEASURED_DISPLAY.get(unit, (1.0, unit))
        cells = [row.get(f"{k}_{unit}", float("nan")) * scale
                 for k in ("rmse", "rmse_lp", "peak_error")]
        lines.append(f"| {name} [{shown}] | " + " | ".join(f"{v:.3g}" for v in cells)
                     + f" | {row['lag_s'] * 1e3:.0f} |")
    return "\n".join(lines)


def _specs_base(args: argparse.Namespace, scenario: str) -> dict:
    """RunSpec fields shared by every run of a compare command."""
    from trackmj.study.executor import as_path, overrides_tuple

    return dict(scenario=scenario, estimator=getattr(args, "estimator", None),
                duration=args.duration, overrides=overrides_tuple(args.set),
                model=as_path(args.model), hydraulics=as_path(args.hydraulics),
                control=as_path(args.control), tensioner=as_path(args.tensioner),
                machine=_machine_spec(args.machine))


def _machine_spec(machine: str | None) -> str | None:
    """A machine for a RunSpec: a shipped name as given, a machine file as an absolute
    path (workers may run elsewhere)."""
    from trackmj.machines.assembly import names

    if machine is None or machine.strip().lower() in names():
        return machine
    return str(Path(machine).resolve())


def _cmd_compare(args: argparse.Namespace) -> int:
    from trackmj.scenarios.schema import check_duration
    from trackmj.sim.setup import prepare
    from trackmj.study.compare import compare, write_compare

    controllers = args.controllers.split(",") if args.controllers else [None]
    setups = [prepare(args.scenario, controller=c, estimator=args.estimator, seed=args.seed,
                      duration=args.duration, **_files(args)) for c in controllers]
    controllers = [str(c) if c else s.controller for c, s in zip(controllers, setups,
                                                                 strict=True)]
    scenario = setups[0].scenario
    check_duration(scenario, setups[0].duration_s)
    out = Path(args.out or f"runs/compare-{scenario.name}")
    base = _specs_base(args, str(args.scenario))
    outcome = compare(base, controllers, out, seed=args.seed,
                      workers=args.workers, scheduler=args.scheduler)
    for spec, error in outcome.failed:
        print(f"trackmj: {spec.architecture} {spec.controller}: {error}", file=sys.stderr)
    doc = write_compare(outcome, out, scenario, setups[0].duration_s)
    print(_summary_table(outcome.results, "{r.architecture} {r.controller}"))
    print(f"-> {doc}")
    return 1 if outcome.failed else 0


def _cmd_report(args: argparse.Namespace) -> int:
    from trackmj.sim.registry import ARCHITECTURES, CONTROLLERS
    from trackmj.study.report import check_report_dir, plan, run_matrix, write_report

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
    if args.tensioner is not None:
        from trackmj.elements.tensioner_file import load_tensioner

        load_tensioner(args.tensioner)   # refused here, before any run, if it is bad
    if args.machine is not None:
        from trackmj.machines.assembly import resolve

        resolve(args.machine)   # refused here, before any run, if it is bad
    specs = plan(args.scenarios.split(","), list(range(args.seeds)), args.duration, archs,
                 baselines, tensioner=args.tensioner, machine=_machine_spec(args.machine))
    matrix = run_matrix(specs, out, workers=args.workers, scheduler=args.scheduler)
    path = write_report(matrix.results, out, matrix)
    print(f"{len(matrix.results)} runs ({matrix.resumed} resumed, {len(matrix.failed)} failed) "
          f"in {matrix.wall_time_s:.0f} s -> {path}")
    return 1 if matrix.failed else 0


def _cmd_view(args: argparse.Namespace) -> int:
    import os
    import subprocess

    from trackmj.results.playback import open_viewer, resolve_rrd

    rrd = resolve_rrd(args.path)
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        print(f"trackmj: error: no display (DISPLAY and WAYLAND_DISPLAY are unset), so the "
              f"Rerun viewer cannot open here; copy {rrd} to a machine with a display and "
              f"run 'rerun {rrd.name}' there, or serve it to a browser with "
              f"'python -m rerun --web-viewer {rrd}'", file=sys.stderr)
        return 1
    viewer = open_viewer(rrd)
    try:   # a viewer that cannot start (no GPU, broken install) exits within seconds
        code = viewer.wait(timeout=VIEWER_START_S)
    except subprocess.TimeoutExpired:
        print(f"viewer open on {rrd}")
        return 0
    if code != 0:
        print(f"trackmj: error: the Rerun viewer exited with code {code} without opening "
              f"{rrd} (its messages are above)", file=sys.stderr)
        return 1
    return 0


VIEWER_START_S = 5.0
"""How long ``view`` waits for the viewer to fail before it reports it open [s]."""


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from trackmj.scenarios.schema import BUILTIN, load_scenario
    from trackmj.sim.registry import ARCHITECTURES, CONTROLLERS, ELEMENTS, ESTIMATORS

    loaded = [load_scenario(name) for name in BUILTIN]
    width = max(len(sc.name) for sc in loaded) + 2
    for sc in loaded:
        print(f"{sc.name:<{width}}{sc.title} ({sc.duration_s:g} s, {sc.controller}/"
              f"{sc.estimator})")
        if len(sc.variants) > 1:
            import textwrap

            print(textwrap.fill("--variant " + ", ".join(v.name for v in sc.variants), 90,
                                initial_indent=" " * width, subsequent_indent=" " * (width + 10)))
    print("or any scenario TOML file in the same format (experiments/*.toml)")
    for title, registry in (("architectures (--arch)", ARCHITECTURES),
                            ("controllers (--controller)", CONTROLLERS),
                            ("estimators (--estimator)", ESTIMATORS),
                            ("tensioner elements (of the architectures; --tensioner FILE)",
                             ELEMENTS)):
        print(f"\n{title}")
        for name, entry in registry.items():
            print(f"{name:<{width + 5}}{entry.description}")
    return 0


def _cmd_keys(args: argparse.Namespace) -> int:
    from trackmj.study.campaign import file_schema
    from trackmj.validator import FILE_KINDS, describe_schema

    unknown = [k for k in args.kinds if k not in FILE_KINDS]
    if unknown:
        raise ValueError(f"keys {unknown[0]!r}: allowed {', '.join(FILE_KINDS)}")
    print("# --set KIND.TABLE.KEY=VALUE and sweep keys: type, unit, range - meaning; '[]' is "
          "an array of tables, give the index (scenario.load_pulses.0.hitch_N), '<name>' a "
          "named table")
    for kind in args.kinds or FILE_KINDS:
        print(f"# {kind}")
        for row in describe_schema(file_schema(kind)):
            print(f"{kind}.{row}")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from trackmj.study.sweep import plot_sweep, sweep

    if args.plot is not None:
        if args.spec is not None:
            raise ValueError("give a sweep spec to run, or --plot DIR to redraw, not both")
        figures = plot_sweep(args.plot)
        print(f"{len(figures)} figures -> {Path(args.plot) / 'figures'}")
        return 0
    if args.spec is None:
        raise ValueError("sweep needs a spec file (or --plot DIR); see 'trackmj sweep -h'")
    out = Path(args.out or f"runs/sweep-{Path(args.spec).stem}")
    summary = sweep(args.spec, out, workers=args.workers, scheduler=args.scheduler,
                    keep_runs=args.keep_runs, retry_failed=args.retry_failed,
                    tensioner=args.tensioner, machine=_machine_spec(args.machine))
    print(summary)
    print(f"{len(summary.figures)} figures -> {out / 'figures'}")
    return 1 if summary.failed else 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from trackmj.study.calibrate import CALIBRATION_JSON, CALIBRATION_PNG, calibrate

    out = Path(args.out)
    done = calibrate(args.spec, args.measured, out, workers=args.workers)
    doc = done.document
    runs = len(doc["runs"])
    print(f"calibrated {len(doc['estimates'])} keys on {len(args.measured)} log(s), {runs} "
          f"runs in {doc['wall_time_s']:.0f} s ({doc['optimizer']['message']})")
    for key, value in doc["estimates"].items():
        low, high = doc["intervals"][key]
        bound = "  (at a bound)" if doc["at_bound"][key] else ""
        print(f"  {key} = {value:.5g}   95 % [{low:.5g}, {high:.5g}]{bound}")
    rms = ", ".join(f"{name} {value:.4g}" for name, value in doc["residual_rms"].items())
    print(f"  residual RMS (SI): {rms}")
    print(f"-> {out / CALIBRATION_JSON}, {out / CALIBRATION_PNG}")
    return 0


def _cmd_fmu_export(args: argparse.Namespace) -> int:
    from trackmj.fmi.export import export

    exported = export(args.kind, args.out)
    print(f"wrote {exported.path}")
    for note in exported.notes:
        print(f"  {note}")
    return 0


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

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)


def build_parser() -> argparse.ArgumentParser:
    from trackmj.sim.registry import ARCHITECTURES, CONTROLLERS, ESTIMATORS, by_name, choices
    from trackmj.version import __version__

    parser = _Parser(prog="trackmj", description="trackmj: electro-hydraulic track tensioning "
                     "simulator (MuJoCo track, hydraulic plugin, NMPC control)",
                     epilog="'trackmj COMMAND -h' explains a command; 'trackmj scenarios' lists "
                            "the operating conditions, 'trackmj keys' the --set keys")
    parser.add_argument("--version", action="version", version=f"trackmj {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def tensioner_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument("--tensioner", metavar="FILE.toml", help="tensioner file: an FMU "
                       "([fmu]) or a spring-damper ([passive]) replacing the hydraulic "
                       "element (see README, FMI)")

    def machine_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument("--machine", metavar="NAME|FILE", help="a shipped machine ('trackmj "
                       "machines') or a machine file *_machine.toml (default: lf1352)")

    def model_args(p: argparse.ArgumentParser) -> None:
        machine_arg(p)
        p.add_argument("--model", help="MJCF file (default: the machine's model, generated "
                       "and cached unless it is the committed reference)")
        p.add_argument("--params", help="model parameter TOML (default: the machine's)")
        p.add_argument("--set", metavar="model.TABLE.KEY=VALUE", action="append", default=[],
                       help="override one key of the model file (repeatable), e.g. "
                            "--set model.track.link_count=80")

    model = sub.add_parser("model", help="inspect or regenerate the track model")
    model_sub = model.add_subparsers(dest="model_command", required=True)
    info = model_sub.add_parser("info", help="summary: bodies, DOF, links, masses, contacts")
    model_args(info)
    info.set_defaults(func=_cmd_model_info)
    gen = model_sub.add_parser("generate", help="regenerate a machine's reference MJCF "
                               "(models/lf1352.xml) from its files")
    machine_arg(gen)
    gen.add_argument("--params", help="model parameter TOML (default: the machine's)")
    gen.add_argument("--set", metavar="model.TABLE.KEY=VALUE", action="append", default=[],
                     help="override one key of the model file (repeatable)")
    gen.add_argument("--out", help="output MJCF path NAME.xml, the machine part; the scene "
                     "NAME_scene.xml beside it includes it (default: the machine's "
                     "reference_mjcf)")
    gen.set_defaults(func=_cmd_model_generate)

    drive = sub.add_parser("drive", help="drive the track with the passive tensioner")
    model_args(drive)
    drive.add_argument("--speed", type=float, default=1.5, help="sprocket pitch speed [m/s]")
    drive.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    drive.add_argument("--preload", type=float, metavar="N",
                       help="tensioner preload [N], e.g. 12e3")
    drive.add_argument("--out", help="directory for metrics.json and timeseries.parquet")
    tensioner_arg(drive)
    drive.set_defaults(func=_cmd_drive)

    def file_args(p: argparse.ArgumentParser) -> None:
        tensioner_arg(p)
        machine_arg(p)
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

    def executor_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--workers", type=_positive_int, help="Dask worker processes of the "
                       "local cluster (default: one per core)")
        p.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, "
                       "e.g. tcp://HOST:8786, instead of a local cluster")

    def run_args(p: argparse.ArgumentParser, out_help: str) -> None:
        p.add_argument("scenario", help="a built-in scenario (W1-W5, NL1; trackmj "
                       "scenarios) or a scenario TOML file")
        p.add_argument("--estimator", choices=choices(ESTIMATORS),
                       help="default: the scenario's")
        p.add_argument("--seed", type=_nonnegative_int, default=0,
                       help="noise and terrain seed")
        p.add_argument("--duration", type=_duration,
                       help="simulated time [s] (default: the scenario's)")
        p.add_argument("--out", metavar="DIR", help=out_help)
        file_args(p)

    run = sub.add_parser("run", help="one closed-loop run of a scenario")
    run_args(run, "output directory (default: runs/SCENARIO-ARCH-CONTROLLER-sSEED, with "
                  "-VARIANT and a short hash of the inputs when they are not the scenario's "
                  "own; a folder holding a run of other inputs is refused unless --overwrite)")
    run.add_argument("--arch", default="tp", choices=choices(ARCHITECTURES),
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
    run.set_defaults(func=_cmd_run)

    compare = sub.add_parser("compare", help="all architectures on one scenario, with each "
                             "reduced one's prediction error against tp")
    run_args(compare, "output directory (default: runs/compare-SCENARIO); runs already done "
                      "in it are kept")
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
    tensioner_arg(report)
    machine_arg(report)
    executor_args(report)
    report.add_argument("--out", default="runs/report",
                        help="output directory; runs already complete in it are kept")
    report.set_defaults(func=_cmd_report)

    sweep = sub.add_parser(
        "sweep", help="parameter study from a TOML spec -> DIR/results.parquet, figures",
        description="Run every point of a sweep spec (grid or Latin hypercube over --set "
                    "keys, x scenarios x architectures x controllers x seeds) on Dask; one "
                    "row per run in DIR/results.parquet, written as runs finish; runs "
                    "already there are skipped (resume); a failed run is a row with its "
                    "error. The spec format is in the README ('Parameter studies').")
    sweep.add_argument("spec", nargs="?", help="sweep spec TOML file")
    sweep.add_argument("--out", metavar="DIR",
                       help="output directory, resumed if it holds a sweep "
                            "(default: runs/sweep-SPEC_NAME)")
    sweep.add_argument("--plot", metavar="DIR",
                       help="only redraw DIR/figures from DIR/results.parquet (a resumed "
                            "sweep that makes no run keeps the figures that exist)")
    sweep.add_argument("--keep-runs", action="store_true",
                       help="also write each run's result directory under DIR/runs/")
    sweep.add_argument("--retry-failed", action="store_true",
                       help="run again the runs whose rows hold an error")
    tensioner_arg(sweep)
    machine_arg(sweep)
    executor_args(sweep)
    sweep.set_defaults(func=_cmd_sweep)

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
    calib.set_defaults(func=_cmd_calibrate)
    machines = sub.add_parser("machines", help="list the shipped machines")
    machines.set_defaults(func=_cmd_machines)

    scenarios = sub.add_parser("scenarios", help="list the built-in operating conditions")
    scenarios.set_defaults(func=_cmd_scenarios)

    keys = sub.add_parser("keys", help="list the --set keys (and sweep keys) with units, "
                                       "ranges and meaning")
    keys.add_argument("kinds", nargs="*", metavar="KIND",
                      help="model, hydraulics, control or scenario (default: all)")
    keys.set_defaults(func=_cmd_keys)

    fmu = sub.add_parser("fmu", help="FMI: export trackmj as an FMU (import: --tensioner, "
                         "--controller fmu:FILE)")
    fmu_sub = fmu.add_subparsers(dest="fmu_command", required=True)
    export = fmu_sub.add_parser("export", help="write an FMI 2.0 co-simulation FMU")
    export.add_argument("kind", choices=("track", "plant"), help="track: the tensioner port "
                        "as inputs; plant: track + built-in hydraulics, valve command in, "
                        "sensor signals out")
    export.add_argument("-o", "--out", required=True, metavar="FILE.fmu", help="FMU to write")
    export.set_defaults(func=_cmd_fmu_export)

    view = sub.add_parser("view", help="open a run's Rerun recording in the viewer")
    view.add_argument("path", help="run directory or .rrd file")
    view.set_defaults(func=_cmd_view)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    from trackmj.errors import PhysicsError
    from trackmj.fmi import FmuError
    from trackmj.results.store import ResultDirectoryError
    from trackmj.validator import ParameterError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("trackmj: interrupted; earlier results were left as they were", file=sys.stderr)
        return 130
    except BrokenPipeError:   # e.g. 'trackmj keys | head': the reader has gone
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (PhysicsError, FmuError) as exc:
        print(f"trackmj: stopped: {exc}", file=sys.stderr)
        return 3
    except (ParameterError, ResultDirectoryError, FileNotFoundError, ValueError,
            KeyError) as exc:
        print(f"trackmj: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
