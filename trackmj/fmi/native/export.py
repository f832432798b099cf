"""``trackmj fmu export track``: the track as a native FMU (C against MuJoCo's C API).

The FMU holds everything a host needs and nothing of the exporting machine:

* ``binaries/<platform>/TrackmjTrack.{so,dll}``: the engine (engine.c, the plant's step
  sequence in C) behind the FMI layer (fmi2.c or fmi3.c), and MuJoCo's shared library of
  the exporting trackmj's version beside it;
* ``resources/track.mjb``: the machine's MuJoCo model as trackmj compiled and adjusted it
  (machine, scene and terrain, the ground's contact handed to the foundation, equalised link
  weights, W5's contact scale), ``resources/track.xml`` its MJCF source (for reading and
  viewing), ``resources/track.cfg``: the indices, the foundation's arrays and the track
  settled under ``force_N`` (the state the Python plant starts a run from);
* ``documentation/sources/``: the C sources and headers the binaries were built from, to
  read (every equation open). Not in ``sources/``: that folder makes an FMU a source FMU,
  which an importing tool may try to build, and these need MuJoCo's headers and a
  ``libmujoco`` for the host's platform, which only the binaries' platforms carry;
* ``documentation/licenses/``: MuJoCo's licence (Apache 2.0) and its third parties'.

The machine, terrain and seed are fixed at export (the model is compiled then); the
ground law is tunable as parameters. Platforms: Linux x86-64 with the system C compiler,
Windows x86-64 cross-built with MinGW-w64 against MuJoCo's win_amd64 library; a platform
that cannot be built is left out, and the export says why.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import shutil
import tempfile
import uuid
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from trackmj.fmi.native import toolchain
from trackmj.fmi.native.description import model_description
from trackmj.fmi.native.variables import Variable, c_header, table
from trackmj.sim.mechanics import settled_end_stop, settled_track
from trackmj.sim.observers import PhysicsLimits, capture_mujoco_warnings
from trackmj.sim.setup import prepare
from trackmj.track.foundation import L_B, L_K, L_MU, L_ONSET, L_SHEAR
from trackmj.track.plant import TrackPlant
from trackmj.version import __version__

IDENTIFIER = "TrackmjTrack"
CLOSURE_MAX_M = PhysicsLimits(0.0, (0.0, 0.0)).closure_max_m
"""The pin gap beyond which a run's physics guard counts the loop as broken [m]; the
engine stops a step there as the guard stops a run."""
HERE = Path(__file__).resolve().parent
SOURCES = ("engine.c", "engine.h", "layer.h")
FMI_LAYER = {2: "fmi2.c", 3: "fmi3.c"}
GROUND_LAW = {"ground_stiffness_N_m": L_K, "ground_damping_N_s_m": L_B,
              "ground_damping_onset_m": L_ONSET, "ground_shear_modulus_m": L_SHEAR,
              "ground_friction": L_MU}
"""Ground parameter -> its entry of the foundation's law (the start value taken from it, so
that a W5 contact scale is included)."""


@dataclass(frozen=True)
class NativeExport:
    """What an export made: the FMU ``path``, the FMI version, the platforms built and, for
    each left out, why; ``notes`` the lines to tell the user; the ``machine`` and ground
    ``grade`` (tan θ) it stands on, the force ``force_N`` [N] it was settled under and, if
    its idler carrier settled on an end stop, which
    (:func:`~trackmj.sim.mechanics.settled_end_stop`, None between the stops)."""

    path: Path
    fmi_version: int
    platforms: tuple[str, ...]
    missing: Mapping[str, str]
    notes: tuple[str, ...]
    machine: str = ""
    grade: float = 0.0
    force_N: float = 0.0
    end_stop: Mapping[str, Any] | None = None


def initial_outputs(plant: TrackPlant) -> np.ndarray:
    """The FMU's outputs of the settled track, in the engine's order (stroke, velocity,
    tension, chassis acceleration, drive torque, upper and lower strand tension, envelope
    excursion, closure error; then sprocket disengaged, links off envelope, slack strand,
    derailed as 0/1), as TrackPlant reads them."""
    strands = plant.strand_tensions_N()
    status = plant.derailment()
    return np.array([plant.stroke_m, plant.stroke_velocity_m_s, plant.idler_force_N,
                     plant.chassis_acc_z_m_s2, plant.drive_torque_N_m, strands.upper_N,
                     strands.lower_N, status.max_envelope_excursion_m, plant.closure_error_m,
                     status.sprocket_disengaged, status.links_off_envelope,
                     status.slack_strand, status.any], dtype=float)


def configuration_text(plant: TrackPlant) -> str:
    """``resources/track.cfg``: one ``key count values...`` line per array (doubles as
    %.17g, exact), the plant's configuration and its settled state."""
    law = plant.last_law
    if law is None:
        raise ValueError("the track has not been settled (no step taken)")
    if plant.step_count or plant.time_s:
        raise ValueError(f"the track's clock is at step {plant.step_count}, t = "
                         f"{plant.time_s:g} s: the engine starts its clock and slack window "
                         "at 0 (settled_track clears them)")
    if plant.speed_command_m_s != 0.0:
        raise ValueError(f"the track is commanded to {plant.speed_command_m_s:g} m/s: the "
                         "engine starts at the track-speed input's start value, 0")
    state = np.zeros(mujoco.mj_stateSize(plant.model, mujoco.mjtState.mjSTATE_INTEGRATION))
    mujoco.mj_getState(plant.model, plant.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
    arrays = {**plant.configuration(), "initial_state": state,
              "initial_memory": plant.foundation.memory,
              "initial_law": np.array([law.force_N, law.damping_N_s_m]),
              "initial_outputs": initial_outputs(plant),
              "initial_kinematics": plant.hitch_kinematics(),
              "initial_brake": np.array([float(plant.parked), float(plant.park_pending),
                                         plant.parking_brake_anchor_rad]),
              "closure_max_m": np.array([CLOSURE_MAX_M])}
    lines = []
    for key, value in arrays.items():
        flat = np.asarray(value, dtype=float).ravel()
        lines.append(f"{key} {flat.size} " + " ".join(f"{v:.17g}" for v in flat))
    return "\n".join(lines) + "\n"


def export_track(out: Path | str, *, fmi_version: int = 2, machine: str | None = None,
                 model: str | None = None, terrain: str = "flat", seed: int = 0,
                 force_N: float | None = None, platforms: tuple[str, ...] = ("linux",
                                                                             "win64"),
                 ) -> NativeExport:
    """Write the track of ``machine`` (a shipped name or a machine file; ``model``: a model
    parameter file on the default machine) on ``terrain`` ("flat" or a scenario whose road
    is used, drawn from ``seed``) as a native FMU at ``out``, FMI ``fmi_version`` 2 or 3
    co-simulation, settled under ``force_N`` [N] (default: W1's initial tension of the
    machine), for the ``platforms`` that can be built here. ValueError for a bad argument,
    RuntimeError when no platform could be built."""
    if fmi_version not in FMI_LAYER:
        raise ValueError(f"--fmi {fmi_version}: must be 2 or 3")
    if force_N is not None and not (np.isfinite(force_N) and force_N > 0.0):
        raise ValueError(f"--force {force_N!r}: must be a finite force > 0 [N] (it pushes "
                         "the idler outward)")
    scenario = "W1" if terrain in ("", "flat") else terrain
    setup = prepare(scenario, seed=seed, machine=machine, model=model)
    force = setup.force0_N if force_N is None else float(force_N)
    with capture_mujoco_warnings() as warnings:
        plant = settled_track(setup, force)
    left = _left_physics(plant, warnings)
    if left is not None:
        given = "--force" if force_N is not None else "W1's initial tension"
        raise ValueError(f"{given} {force:g} N: the track of {setup.machine.name} settled "
                         f"under it left physics ({left}), so the FMU would start from no "
                         "physical state and was not written; give a force nearer the "
                         f"machine's nominal tension {setup.model.nominal_tension_N:g} N")
    variables = _with_ground_starts(table(setup.model, force), plant)
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="trackmj-fmu-") as tmp:
        work = Path(tmp)
        resources = work / "fmu" / "resources"
        resources.mkdir(parents=True)
        mujoco.mj_saveModel(plant.model, str(resources / "track.mjb"), None)
        (resources / "track.xml").write_text(setup.track_mjcf())
        (resources / "track.cfg").write_text(configuration_text(plant))
        token = _token(resources, variables)
        sources = work / "fmu" / "documentation" / "sources"
        sources.mkdir(parents=True)
        for source in (*SOURCES, FMI_LAYER[fmi_version]):
            shutil.copy(HERE / source, sources / source)
        for header in (HERE / "include").iterdir():
            shutil.copy(header, sources / header.name)
        licenses = work / "fmu" / "documentation" / "licenses"
        licenses.mkdir(parents=True)
        for name, text in mujoco_licenses().items():
            (licenses / f"MuJoCo-{name}").write_text(text)
        (sources / "trackmj_variables.h").write_text(c_header(variables, token))
        built, missing = _build(work / "fmu" / "binaries", sources, fmi_version, platforms)
        if not built:
            raise RuntimeError("no platform could be built: " + "; ".join(
                f"{p}: {why}" for p, why in missing.items()))
        (work / "fmu" / "modelDescription.xml").write_text(model_description(
            variables, fmi_version=fmi_version, token=token, model_name=f"{IDENTIFIER}",
            description=track_description(setup.machine.name, terrain, seed, force,
                                          setup.scenario.terrain.grade),
            version=__version__), encoding="utf-8")
        out.parent.mkdir(parents=True, exist_ok=True)
        partial = out.with_name(out.name + ".partial")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as fmu:
            for path in sorted((work / "fmu").rglob("*")):
                if path.is_file():
                    fmu.write(path, path.relative_to(work / "fmu").as_posix())
        partial.replace(out)
    notes = tuple([f"FMI {fmi_version}.0 co-simulation, native: needs no Python on the host",
                   f"platforms: {', '.join(built)}",
                   *(f"not built for {p}: {why}" for p, why in missing.items())])
    return NativeExport(out, fmi_version, tuple(built), dict(missing), notes,
                        machine=setup.machine.name, grade=setup.scenario.terrain.grade,
                        force_N=force, end_stop=settled_end_stop(plant))


def _left_physics(plant: TrackPlant, warnings: list[str]) -> str | None:
    """Why the settled ``plant`` is no physical state, as a run's physics guard judges one
    (a MuJoCo warning during the settle, a non-finite state, the loop torn beyond
    :data:`CLOSURE_MAX_M`), or None."""
    if warnings:
        return f"MuJoCo warning: {warnings[0].strip().rstrip('.')}"
    if not (np.isfinite(plant.data.qpos).all() and np.isfinite(plant.data.qvel).all()):
        return "a non-finite state"
    if not plant.closure_error_m <= CLOSURE_MAX_M:
        return (f"track loop closure gap {plant.closure_error_m * 1e3:.1f} mm, beyond "
                f"{CLOSURE_MAX_M * 1e3:g} mm")
    return None


def track_description(machine: str, terrain: str, seed: int, force_N: float,
                      grade: float) -> str:
    """The modelDescription's description of a track FMU: the ``machine``, the ``terrain``
    ("flat" or the scenario whose road and grade it stands on) with its road's ``seed``,
    the ground's ``grade`` (tan θ, > 0 uphill driving forward; fixed in the model's gravity)
    and the force ``force_N`` [N] it was settled under."""
    slope = (f"grade tan θ = {grade:+g}, {'up' if grade > 0 else 'down'}hill driving forward"
             if grade else "level, grade tan θ = 0")
    return (f"trackmj {__version__}: one track side ({machine}, terrain {terrain}, seed "
            f"{seed}, {slope}) in MuJoCo, settled under {force_N:.6g} N; the tensioner port "
            "F = force_N + force_dv_N_s_m * v as inputs")


def mujoco_licenses() -> dict[str, str]:
    """The licence texts of the MuJoCo library the FMU bundles (Apache 2.0 and its third
    parties), from the installed ``mujoco-core`` distribution: file name -> text."""
    files = importlib.metadata.distribution("mujoco-core").files or []
    found = {Path(str(f)).name: f.read_text() for f in files
             if "licenses" in Path(str(f)).parts}
    if not found:
        raise RuntimeError("the installed mujoco-core carries no licence files to bundle")
    return found


def _with_ground_starts(variables: tuple[Variable, ...],
                        plant: TrackPlant) -> tuple[Variable, ...]:
    """The ground parameters started at the law the plant runs (a W5 scale included)."""
    law = plant.foundation.law_array
    out = []
    for v in variables:
        if v.name in GROUND_LAW:
            v = Variable(v.name, v.vr, v.kind, v.causality, v.variability, v.unit,
                         v.description, float(law[GROUND_LAW[v.name]]), v.minimum, v.maximum)
        out.append(v)
    return tuple(out)


def _token(resources: Path, variables: tuple[Variable, ...]) -> str:
    """The instantiation token: a UUID from the model, configuration and variables, so that
    the same export gives the same token and any change another."""
    digest = hashlib.sha256()
    for name in ("track.mjb", "track.cfg"):
        digest.update((resources / name).read_bytes())
    digest.update(repr(variables).encode())
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


def _build(binaries: Path, sources: Path, fmi_version: int,
           platforms: tuple[str, ...]) -> tuple[list[str], dict[str, str]]:
    """Build the model binary for each platform that can be; (built, missing: why)."""
    built: list[str] = []
    missing: dict[str, str] = {}
    finders = {"linux": toolchain.linux_toolchain, "win64": toolchain.win64_toolchain}
    for platform in platforms:
        found = finders[platform]()
        if isinstance(found, toolchain.Missing):
            missing[platform] = found.reason
            continue
        folder = found.platform.fmi2 if fmi_version == 2 else found.platform.fmi3
        toolchain.build(found, [sources / "engine.c", sources / FMI_LAYER[fmi_version]],
                        [sources], binaries / folder, IDENTIFIER)
        built.append(folder)
    return built, missing


__all__ = ["IDENTIFIER", "NativeExport", "configuration_text", "export_track",
           "initial_outputs"]
