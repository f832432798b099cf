"""The native track FMU (trackmj/fmi/native): one physics with the Python plant, FMI's error
contract, state save and restore, and hosts no one in this project wrote (fmpy) or without
Python at all (a C host under ``env -i`` in an empty folder; the Windows build under Wine).

The FMU's engine steps the same MuJoCo library as the Python plant with a C port of the
foundation's kernels, in the same order of operations; compiled without FMA contraction,
the two agree to the last bit on this machine, so the comparisons below hold them to
1e-9 relative (another CPU or compiler may round differently; 1e-9 still bounds a port
that is right, a wrong line shows at 1e-3 within a second).
"""

from __future__ import annotations

import itertools
import math
import os
import shutil
import subprocess
import sys
import threading
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import fmpy
import numpy as np
import pytest
from fmpy.container_fmu.cli import create_container_fmu
from fmpy.container_fmu.config import Component, Configuration
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.model_description import CoSimulation, ModelDescription, ModelVariable
from fmpy.validation import validate_fmu
from wine import require, run_under_wine, windows_path, wine_available, wine_missing

from trackmj.elements.prescribed import ConstantForce
from trackmj.fmi.fmu import FmuLog, fmi2_callbacks
from trackmj.fmi.native import toolchain
from trackmj.fmi.native.export import configuration_text, export_track
from trackmj.ports import StepInputs
from trackmj.sim.mechanics import settled_track
from trackmj.sim.setup import prepare
from trackmj.track.plant import TrackPlant

HERE = Path(__file__).resolve().parent
CLIMB = HERE / "data" / "climb.toml"
"""A scenario on a 1 in 5 grade (flat ground, gravity tilted): the FMU carries the tilt."""
FMI_HEADERS = Path(toolchain.__file__).parent / "include"
"""The FMI headers the package ships (trackmj/fmi/native/include), for the tests' C hosts."""
FORCE_N = 13e3
DAMPING_N_S_M = 2.0e4
"""The W1-like law F = F0(t) − c·v the comparisons drive: F0 swinging ±1 kN at 1 Hz about
13 kN, c = 20 kN·s/m (the order of the hydraulic port's Z in W1)."""
VR = {"force_N": 1, "force_dv_N_s_m": 2, "track_speed_m_s": 3, "hitch_pull_N": 4,
      "drive_torque_N_m": 14,
      "stroke_m": 10, "velocity_m_s": 11, "tension_N": 12, "upper_strand_tension_N": 15,
      "closure_error_m": 18, "ground_friction": 34, "slack_strand": 22, "derailed": 23}


def force_at(t_s: float) -> float:
    """F0 of the comparison's law at time ``t_s`` [s] [N]."""
    return FORCE_N + 1e3 * math.sin(2.0 * math.pi * t_s)


@pytest.fixture(scope="session")
def native(tmp_path_factory) -> dict[str, Path]:
    """LF1352's track as native FMUs: flat ground FMI 2.0 and 3.0, W2's ISO road and a
    1 in 5 grade FMI 2.0."""
    d = tmp_path_factory.mktemp("native")
    return {
        "fmi2": export_track(d / "flat2.fmu", fmi_version=2, force_N=FORCE_N).path,
        "fmi3": export_track(d / "flat3.fmu", fmi_version=3, force_N=FORCE_N).path,
        "road": export_track(d / "road2.fmu", fmi_version=2, force_N=FORCE_N, terrain="W2",
                             platforms=("linux",)).path,
        "grade": export_track(d / "grade2.fmu", fmi_version=2, force_N=FORCE_N,
                              terrain=str(CLIMB), platforms=("linux",)).path,
    }


class Slave:
    """fmpy's FMI 2.0 or 3.0 co-simulation slave of a native FMU, with its log."""

    def __init__(self, path: Path, name: str = "test") -> None:
        self.md = fmpy.read_model_description(str(path))
        self.dir = fmpy.extract(str(path))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.log = FmuLog()
        identifier = self.md.coSimulation.modelIdentifier
        if self.fmi3:
            self.fmu: Any = FMU3Slave(guid=self.md.instantiationToken, unzipDirectory=self.dir,
                                      modelIdentifier=identifier, instanceName=name)
            self.fmu.instantiate(logMessage=self.log.fmi3)
        else:
            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                                 modelIdentifier=identifier, instanceName=name)
            self._callbacks = fmi2_callbacks(self.log)
            self.fmu.instantiate(callbacks=self._callbacks)
        self.t = 0.0

    def start(self, **parameters: float) -> None:
        if not self.fmi3:
            self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in parameters.items():
            self.set(name, value)
        self.fmu.exitInitializationMode()

    def set(self, name: str, value: float) -> None:
        (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)([VR[name]], [value])

    def get(self, name: str) -> float:
        return (self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)([VR[name]])[0]

    def flag(self, name: str) -> bool:
        return bool(self.fmu.getBoolean([VR[name]])[0])

    def step(self, h_s: float = 1e-3) -> None:
        self.fmu.doStep(self.t, h_s)
        self.t += h_s

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()
        shutil.rmtree(self.dir, ignore_errors=True)

    def errors(self) -> str:
        return " | ".join(text for status, _, text in self.log.messages if status >= 3)


@contextmanager
def slave(path: Path, name: str = "test") -> Iterator[Slave]:
    s = Slave(path, name)
    try:
        yield s
    finally:
        shutil.rmtree(s.dir, ignore_errors=True)


def python_plant(terrain: str = "flat") -> Any:
    setup = prepare("W1" if terrain == "flat" else terrain)
    return settled_track(setup, FORCE_N)


def drive(step: Callable[[float, float], tuple[float, ...]], seconds: float,
          speed_m_s: float = 1.5, parked_s: float = 0.0) -> np.ndarray:
    """(stroke, velocity, tension, ...) after every 1 ms step of ``step(F0, speed)``: speed 0
    (the parking brake applied) for ``parked_s`` [s], then ``speed_m_s`` [m/s]."""
    rows = [step(force_at(k * 1e-3), 0.0 if k * 1e-3 < parked_s else speed_m_s)
            for k in range(round(seconds / 1e-3))]
    return np.array(rows)


PLANT_READOUTS: dict[str, Callable[[TrackPlant], float]] = {
    "stroke_m": lambda p: p.stroke_m, "velocity_m_s": lambda p: p.stroke_velocity_m_s,
    "tension_N": lambda p: p.idler_force_N, "closure_error_m": lambda p: p.closure_error_m,
    "drive_torque_N_m": lambda p: p.drive_torque_N_m}
"""The Python plant's readout behind each FMU output compared here."""


def plant_stepper(plant: TrackPlant, outputs: tuple[str, ...]
                  ) -> Callable[[float, float], tuple[float, ...]]:
    """``step(F0, speed)`` of the Python plant under the W1-like law's constant force with
    DAMPING_N_S_M, returning the readouts of ``outputs`` (FMU output names)."""
    def step(force: float, speed: float) -> tuple[float, ...]:
        plant.apply(StepInputs(speed, 0.0, 0.0, math.nan))
        plant.step(ConstantForce(force, DAMPING_N_S_M))
        return tuple(PLANT_READOUTS[name](plant) for name in outputs)
    return step


def fmu_stepper(fmu: Any, outputs: tuple[str, ...]
                ) -> Callable[[float, float], tuple[float, ...]]:
    """The same step of a started slave (its force slope set to −DAMPING_N_S_M)."""
    def step(force: float, speed: float) -> tuple[float, ...]:
        fmu.set("force_N", force)
        fmu.set("track_speed_m_s", speed)
        fmu.step()
        return tuple(fmu.get(name) for name in outputs)
    return step


def test_a_track_commanded_to_move_is_not_exported() -> None:
    """The engine takes the drive's command from its track-speed input, which starts at 0:
    a settled track commanded to another speed would start differently, so it is refused."""
    plant = settled_track(prepare("W1"), FORCE_N)
    plant.set_track_speed(1.0)
    with pytest.raises(ValueError, match=r"commanded to 1 m/s: the engine starts at the "
                                         r"track-speed input's start value, 0"):
        configuration_text(plant)
    plant.set_track_speed(0.0)
    assert configuration_text(plant).startswith("substeps 1 ")


@pytest.mark.slow
@pytest.mark.parametrize("which", ["fmi2", "road", "grade"])
def test_the_fmu_steps_as_the_python_plant(native, which) -> None:
    """5 s at 1.5 m/s under the W1-like law, flat ground, W2's ISO road and a 1 in 5 grade
    (there parked for its first second, the parking brake holding): stroke, velocity and
    tension equal the Python plant's to 1e-9 relative."""
    plant = python_plant({"fmi2": "flat", "road": "W2", "grade": str(CLIMB)}[which])
    parked_s = 1.0 if which == "grade" else 0.0

    outputs = ("stroke_m", "velocity_m_s", "tension_N")
    with slave(native[which]) as fmu:
        fmu.start()
        fmu.set("force_dv_N_s_m", -DAMPING_N_S_M)
        ours = drive(fmu_stepper(fmu, outputs), 5.0, parked_s=parked_s)
        fmu.close()
    theirs = drive(plant_stepper(plant, outputs), 5.0, parked_s=parked_s)
    scale = np.abs(theirs).max(axis=0)
    assert np.abs(ours - theirs).max(axis=0) / scale == pytest.approx(0.0, abs=1e-9)
    assert theirs[:, 1].std() > 1e-3   # the comparison saw a moving idler


@pytest.mark.slow
def test_a_slipping_parking_brake_steps_as_the_python_plant(tmp_path) -> None:
    """LF1352 with a 300 N·m parking brake parked on the 1 in 5 grade, which asks ~0.6
    kN·m of it: 1 s parked (the brake slipping, the track rolling back), 1 s at 1.5 m/s,
    then 0.6 s commanded to stop (the brake applying once the sprocket is slow); stroke,
    velocity, tension and the drive torque equal the Python plant's to 1e-9 relative, the
    parked second rolled back and the brake is applied again at the end."""
    text = (Path(__file__).resolve().parents[1] / "models" / "lf1352.toml").read_text()
    line = next(x for x in text.splitlines() if x.startswith("holding_torque_N_m = "))
    model = tmp_path / "lf1352_weak_brake.toml"
    model.write_text(text.replace(line, "holding_torque_N_m = 300.0"))
    fmu_path = export_track(tmp_path / "weak.fmu", force_N=FORCE_N, model=str(model),
                            terrain=str(CLIMB), platforms=("linux",)).path
    plant = settled_track(prepare(str(CLIMB), model=model), FORCE_N)

    def speed_at(k: int) -> float:
        """Parked 1 s, 1.5 m/s for 1 s, then commanded to stop [m/s] at step ``k``."""
        return 1.5 if 1000 <= k < 2000 else 0.0

    outputs = ("stroke_m", "velocity_m_s", "tension_N", "drive_torque_N_m")
    with slave(fmu_path) as fmu:
        fmu.start()
        fmu.set("force_dv_N_s_m", -DAMPING_N_S_M)
        fmu_step = fmu_stepper(fmu, outputs)
        ours = np.array([fmu_step(force_at(k * 1e-3), speed_at(k)) for k in range(2600)])
        fmu.close()
    python_step = plant_stepper(plant, outputs)
    theirs, sprocket = [], []
    for k in range(2600):
        theirs.append(python_step(force_at(k * 1e-3), speed_at(k)))
        sprocket.append(plant.sprocket_speed_rad_s)
    scale = np.abs(np.array(theirs)).max(axis=0)
    assert np.abs(ours - theirs).max(axis=0) / scale == pytest.approx(0.0, abs=1e-9)
    assert np.mean(sprocket[500:1000]) < -1e-3   # parked, the sprocket turned back: slipping
    assert not plant.park_pending and plant.parked   # stopped again: the brake re-applied


@pytest.mark.slow
def test_a_track_with_pin_slides_steps_as_the_python_plant(tmp_path) -> None:
    """``[track] structure = "slides"`` (every hinged pin on its own compliant slide): 2 s
    of the W1-like law at 1.5 m/s, stroke, velocity, tension and the largest pin gap (now
    a slide's stretch or a connect's) equal the Python plant's to 1e-9 relative."""
    text = (Path(__file__).resolve().parents[1] / "models" / "lf1352.toml").read_text()
    line = next(x for x in text.splitlines() if x.startswith("structure = "))
    model = tmp_path / "lf1352_slides.toml"
    model.write_text(text.replace(line, 'structure = "slides"   # per-pin compliance'))
    fmu_path = export_track(tmp_path / "slides.fmu", force_N=FORCE_N, model=str(model),
                            platforms=("linux",)).path
    plant = settled_track(prepare("W1", model=model), FORCE_N)
    assert plant.model.nv == 196

    outputs = ("stroke_m", "velocity_m_s", "tension_N", "closure_error_m")
    with slave(fmu_path) as fmu:
        fmu.start()
        fmu.set("force_dv_N_s_m", -DAMPING_N_S_M)
        ours = drive(fmu_stepper(fmu, outputs), 2.0)
        fmu.close()
    theirs = drive(plant_stepper(plant, outputs), 2.0)
    scale = np.abs(theirs).max(axis=0)
    assert np.abs(ours - theirs).max(axis=0) / scale == pytest.approx(0.0, abs=1e-9)
    # the largest gap is one pin's stretch: a few T/K (~30 µm) on the start's traction peak
    assert 10e-6 < np.median(theirs[:, 3]) < 0.1e-3 and theirs[:, 3].max() < 0.5e-3


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_the_slack_strand_output_is_the_python_plants_verdict_at_every_step(native,
                                                                           which) -> None:
    """LF1352 driven to 1.5 m/s in 0.5 s under 13 kN, its idler dropped to 300 N from 0.6 to
    1.2 s, 1.6 s: the upper strand's least pin tension falls below 1 kN in spells shorter
    than the 0.1 s window (measured: 1-50 ms, 1-5 of the window's samples every 10 ms)
    and in one of 0.38 s (38 samples), slack from 0.1 s into it. After every 1 ms step the
    FMU's slack_strand is the Python plant's verdict (both sample at the same steps of
    their counts, from 0 at the settled state), and the run saw both kinds of spell."""
    window = round(TrackPlant.SLACK_PERSISTENCE_S / TrackPlant.SLACK_SAMPLE_S)   # samples

    def force(t_s: float) -> float:
        return 300.0 if 0.6 <= t_s < 1.2 else FORCE_N

    plant = python_plant()
    spells, theirs = [], []
    for k in range(1600):
        t, speed = k * 1e-3, 1.5 * min(1.0, k * 1e-3 / 0.5)
        plant.apply(StepInputs(speed, 0.0, 0.0, math.nan))
        plant.step(ConstantForce(force(t), DAMPING_N_S_M))
        spells.append(round(plant.slack_duration_s / TrackPlant.SLACK_SAMPLE_S))
        theirs.append(plant.derailment().slack_strand)
    ours = []
    with slave(native[which]) as fmu:
        fmu.start()
        fmu.set("force_dv_N_s_m", -DAMPING_N_S_M)
        for k in range(1600):
            fmu.set("force_N", force(k * 1e-3))
            fmu.set("track_speed_m_s", 1.5 * min(1.0, k * 1e-3 / 0.5))
            fmu.step()
            ours.append(fmu.flag("slack_strand"))
        fmu.close()
    np.testing.assert_array_equal(ours, theirs)
    ended = [n for n, after in itertools.pairwise(spells) if n > 0 and after == 0]
    assert sum(0 < n < window for n in ended) >= 3      # brief spells: not slack
    assert max(spells) > 3 * window and sum(theirs) > 0.2 / 1e-3   # a lasting one: slack


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_fmpy_simulate_fmu_settles_where_the_python_plant_does(native, which) -> None:
    """fmpy's own simulation loop (its defaults: output every step) on the FMU, 0.5 s at
    13 kN standing: the stroke the Python plant reaches."""
    result = fmpy.simulate_fmu(str(native[which]), stop_time=0.5, step_size=1e-3,
                               start_values={"force_N": FORCE_N}, output=["stroke_m"])
    plant = python_plant()
    for _ in range(500):
        plant.step(ConstantForce(FORCE_N))
    assert result["stroke_m"][-1] == pytest.approx(plant.stroke_m, abs=1e-9)


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_outputs_read_the_settled_track_in_initialization_mode(native, which) -> None:
    """InitialUnknowns: in initialization mode the outputs are the settled track's, as the
    Python plant has it after settling (stroke, and the tension it was settled under)."""
    plant = python_plant()
    with slave(native[which]) as fmu:
        if not fmu.fmi3:
            fmu.fmu.setupExperiment(startTime=0.0)
        fmu.fmu.enterInitializationMode()
        assert fmu.get("stroke_m") == plant.stroke_m
        assert fmu.get("tension_N") == pytest.approx(plant.idler_force_N, abs=1e-9)
        fmu.fmu.exitInitializationMode()
        fmu.close()


def test_both_exports_pass_fmpy_validation(native) -> None:
    for which in ("fmi2", "fmi3"):
        assert validate_fmu(str(native[which])) == [], which


def test_no_file_in_the_fmu_names_a_path_of_this_machine(native) -> None:
    """The FMU is self-contained: no byte string of the exporting environment's paths (the
    interpreter's environment and installation, this checkout, the export's build folder;
    not the home folder alone: MuJoCo's own library names its build machine's /root)."""
    marks = {os.fsencode(p) for p in (sys.prefix, sys.base_prefix, str(HERE.parent),
                                      "trackmj-fmu-")}
    with zipfile.ZipFile(native["fmi2"]) as z:
        for info in z.infolist():
            data = z.read(info)
            leaked = [m.decode() for m in marks if m in data]
            assert not leaked, f"{info.filename} names {leaked}"
        names = z.namelist()
    assert "resources/track.mjb" in names and "resources/track.cfg" in names


def test_the_sources_are_documentation_not_a_source_fmu(native) -> None:
    """The C sources the binaries were built from travel in documentation/sources/ (to
    read); nothing is in sources/, so an importer lists only the built platforms and never
    tries to compile code that needs MuJoCo's library (fmpy took sources/ for c-code)."""
    for which in ("fmi2", "fmi3"):
        with zipfile.ZipFile(native[which]) as z:
            names = z.namelist()
        assert "documentation/sources/engine.c" in names, which
        assert not [n for n in names if n.startswith("sources/")], which
        assert "c-code" not in fmpy.supported_platforms(str(native[which])), which
        assert "linux64" in fmpy.supported_platforms(str(native[which])), which


def test_no_binary_needs_libpython(native) -> None:
    with zipfile.ZipFile(native["fmi2"]) as z:
        binaries = [n for n in z.namelist() if n.startswith("binaries/")]
        folder = Path(native["fmi2"]).with_suffix(".unzipped")
        z.extractall(folder)
    assert any(n.endswith(".so") for n in binaries)
    for name in binaries:
        if name.endswith((".so", ".dll")) or ".so." in name:
            imports = toolchain.imported_libraries(folder / name)
            assert not [lib for lib in imports if "python" in lib.lower()], (name, imports)
    shutil.rmtree(folder)


@pytest.mark.slow
@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_a_c_host_without_python_in_an_empty_folder_matches_the_python_plant(
        native, which, tmp_path) -> None:
    """The floor: a C host (tests/fmus), ``env -i``, the FMU alone in an empty folder, 2 s
    at 13 kN: the stroke equals the Python plant's within 0.01 mm."""
    fmi3 = which == "fmi3"
    host = _host("cc", "c_importer3.c" if fmi3 else "c_importer.c", tmp_path / "host")
    empty = tmp_path / "empty"
    empty.mkdir()
    shutil.copy(native[which], empty / "track.fmu")
    with zipfile.ZipFile(empty / "track.fmu") as z:
        z.extractall(empty / "track")
    md = fmpy.read_model_description(str(empty / "track.fmu"))
    token = md.instantiationToken if fmi3 else md.guid
    binary = (empty / "track" / "binaries" / ("x86_64-linux" if fmi3 else "linux64")
              / "TrackmjTrack.so")
    resources = empty / "track" / "resources"
    done = subprocess.run(
        ["env", "-i", str(host), str(binary), token,
         str(resources) + "/" if fmi3 else resources.as_uri(),
         str(VR["force_N"]), str(FORCE_N), str(VR["stroke_m"]), "2000"],
        cwd=empty, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    stroke = float(done.stdout.split()[-1])
    plant = python_plant()
    for _ in range(2000):
        plant.step(ConstantForce(FORCE_N))
    assert stroke == pytest.approx(plant.stroke_m, abs=1e-5)


def _host(compiler: str, source: str, out: Path) -> Path:
    """The tests' C FMI host ``source`` (tests/fmus) built with ``compiler`` into ``out``."""
    libraries = [] if out.suffix == ".exe" else ["-ldl"]
    out.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([compiler, "-O1", "-I", str(FMI_HEADERS),
                    str(HERE / "fmus" / source), "-o", str(out), *libraries], check=True)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_the_windows_binary_under_wine_steps_as_the_linux_one(native, which,
                                                              tmp_path) -> None:
    """The win64 DLL, loaded by a plain C host in another folder under Wine, imports only
    Windows' own DLLs (MuJoCo's is delay-loaded from beside it) and gives the Linux
    binary's stroke after 0.5 s at 13 kN within 0.01 mm (Windows' C runtime may round its
    maths functions differently)."""
    require(wine_available(), wine_missing("Wine cannot run Windows programs here"))
    found = toolchain.win64_toolchain()
    require(not isinstance(found, toolchain.Missing), getattr(found, "reason", ""))
    assert isinstance(found, toolchain.Toolchain)
    fmi3 = which == "fmi3"
    with zipfile.ZipFile(native[which]) as z:
        z.extractall(tmp_path / "fmu")
    md = fmpy.read_model_description(str(native[which]))
    token = md.instantiationToken if fmi3 else md.guid
    folder = "x86_64-windows" if fmi3 else "win64"
    dll = tmp_path / "fmu" / "binaries" / folder / "TrackmjTrack.dll"
    imports = toolchain.imported_libraries(dll)
    assert {name.lower() for name in imports} <= {"kernel32.dll", "msvcrt.dll"}, imports
    source = "c_importer3.c" if fmi3 else "c_importer.c"
    host = _host(found.compiler, source, tmp_path / "host" / "host.exe")
    resources = tmp_path / "fmu" / "resources"
    where = (windows_path(resources) + "\\" if fmi3
             else "file:///" + windows_path(resources).replace("\\", "/"))
    args = [str(VR["force_N"]), str(FORCE_N), str(VR["stroke_m"]), "500"]
    run = run_under_wine(host, [windows_path(dll), token, where, *args], timeout=300)
    assert run.returncode == 0, run.stderr
    linux_host = _host("cc", source, tmp_path / "linux_host")
    linux_where = str(resources) + "/" if fmi3 else resources.as_uri()
    folder = "x86_64-linux" if fmi3 else "linux64"
    done = subprocess.run([str(linux_host), str(tmp_path / "fmu" / "binaries" / folder
                                                / "TrackmjTrack.so"), token, linux_where,
                           *args], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert float(run.stdout.split()[-1]) == pytest.approx(float(done.stdout.split()[-1]),
                                                          abs=1e-5)


def _container(component: Path, folder: Path) -> Path:
    """fmpy's container FMU (FMI 3.0; its C binary, written by fmpy's authors, imports the
    components natively) around ``component``, exposing ``force_N`` and ``stroke_m``."""
    md = ModelDescription()
    md.fmiVersion, md.modelName = "3.0", "container"
    md.instantiationToken = "{7d3c6a9e-1f0b-4c1e-9d8a-2b5e4f6a7c81}"
    md.coSimulation = CoSimulation()
    md.coSimulation.modelIdentifier = "container_fmu"
    md.coSimulation.fixedInternalStepSize = 1e-3
    inner = fmpy.read_model_description(str(component))
    track = Component(name="track", filename=component, modelDescription=inner)
    by_name = {v.name: v for v in inner.modelVariables}
    mappings = {}
    # the container keeps value reference 0 for the time and numbers the mapped variables
    # from 1 in this order: force_N 1, stroke_m 2
    for name, causality in (("time", "independent"), ("force_N", "input"),
                            ("stroke_m", "output")):
        variable = ModelVariable(name=name, causality=causality)
        variable.type, variable.variability, variable.valueReference = "Float64", \
            "continuous", 0
        if causality == "input":
            variable.start = str(FORCE_N)
        md.modelVariables.append(variable)
        if name != "time":
            mappings[variable] = [(track, by_name[name])]
    unzipped = folder / "container"
    unzipped.mkdir(parents=True)
    create_container_fmu(Configuration(parallelDoStep=False, modelDescription=md,
                                       components=[track], connections=[],
                                       variableMappings=mappings),
                         unzipped, folder / "container.fmu")
    return folder / "container.fmu"


@pytest.mark.slow
@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_fmpys_c_container_imports_the_fmu_in_a_c_host_without_python(native, which,
                                                                      tmp_path) -> None:
    """An importer no one in this project wrote, in C: fmpy's container FMU holding the
    track FMU (FMI 2.0 or 3.0), run by the tests' C host under ``env -i``; 0.5 s at
    13 kN: the Python plant's stroke."""
    container = _container(native[which], tmp_path)
    with zipfile.ZipFile(container) as z:
        z.extractall(tmp_path / "run")
    token = fmpy.read_model_description(str(container)).instantiationToken
    host = _host("cc", "c_importer3.c", tmp_path / "host")
    done = subprocess.run(
        ["env", "-i", str(host),
         str(tmp_path / "run" / "binaries" / "x86_64-linux" / "container_fmu.so"), token,
         str(tmp_path / "run" / "resources") + "/", "1", str(FORCE_N), "2", "500"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    plant = python_plant()
    for _ in range(500):
        plant.step(ConstantForce(FORCE_N))
    assert float(done.stdout.split()[-1]) == pytest.approx(plant.stroke_m, abs=1e-9)


def test_a_bad_parameter_is_an_error_naming_it_and_its_range(native) -> None:
    with slave(native["fmi2"]) as fmu:
        fmu.fmu.setupExperiment(startTime=0.0)
        fmu.fmu.enterInitializationMode()
        with pytest.raises(FMICallException, match="status 3"):
            fmu.set("ground_friction", 5.0)
        assert "ground_friction" in fmu.errors() and "[0, 2]" in fmu.errors()
        fmu.fmu.freeInstance()


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_a_nan_input_is_an_error_naming_it(native, which) -> None:
    with slave(native[which]) as fmu:
        fmu.start()
        with pytest.raises(FMICallException, match="status 3"):
            fmu.set("force_N", math.nan)
        assert "force_N = nan" in fmu.errors() and "finite" in fmu.errors()
        fmu.fmu.freeInstance()


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_a_blow_up_is_an_error_with_its_time_and_a_fresh_instance_runs_after(
        native, which) -> None:
    """1e7 N on the idler tears the track apart: doStep returns Error (never OK) with the
    time and the quantity; a new instance in the same process then steps normally."""
    with slave(native[which], "blown") as fmu:
        fmu.start()
        fmu.set("force_N", 1e7)
        with pytest.raises(FMICallException, match="status 3"):
            for _ in range(2000):
                fmu.step()
        assert "left physics" in fmu.errors() and "t = " in fmu.errors()
        fmu.fmu.freeInstance()
    with slave(native[which], "fresh") as fresh:
        fresh.start()
        for _ in range(100):
            fresh.step()
        assert math.isfinite(fresh.get("stroke_m"))
        fresh.close()


def test_a_step_that_is_not_a_multiple_of_1_ms_or_at_another_time_is_an_error(
        native) -> None:
    with slave(native["fmi2"]) as fmu:
        fmu.start()
        with pytest.raises(FMICallException, match="status 3"):
            fmu.fmu.doStep(0.0, 1.5e-3)
        assert "1.5e-03" in fmu.errors() or "0.0015" in fmu.errors()
        fmu.fmu.freeInstance()
    with slave(native["fmi2"]) as fmu:
        fmu.start()
        fmu.step(4e-3)   # a multiple: four internal steps
        with pytest.raises(FMICallException, match="status 3"):
            fmu.fmu.doStep(0.5, 1e-3)
        assert "0.5" in fmu.errors()
        fmu.fmu.freeInstance()


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_state_restored_or_deserialized_replays_bit_for_bit(native, which) -> None:
    with slave(native[which]) as fmu:
        fmu.start()
        fmu.set("track_speed_m_s", 1.5)
        fmu.set("hitch_pull_N", 3e3)
        for _ in range(300):
            fmu.step()
        state = fmu.fmu.getFMUState()
        t_saved = fmu.t
        serialize = fmu.fmu.serializeFMUState if fmu.fmi3 else fmu.fmu.serializeFMUstate
        blob = serialize(state)
        first = []
        for _ in range(200):
            fmu.step()
            first.append(fmu.get("stroke_m"))
        fmu.fmu.setFMUState(state)
        fmu.t = t_saved
        again = []
        for _ in range(200):
            fmu.step()
            again.append(fmu.get("stroke_m"))
        assert again == first
        with slave(native[which], "other") as other:
            other.start()
            other.set("track_speed_m_s", 1.5)
            other.set("hitch_pull_N", 3e3)
            deserialize = (other.fmu.deserializeFMUState if other.fmi3
                           else other.fmu.deSerializeFMUstate)
            other.fmu.setFMUState(deserialize(blob))
            other.t = t_saved
            third = []
            for _ in range(200):
                other.step()
                third.append(other.get("stroke_m"))
            other.close()
        assert third == first
        fmu.close()


@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_a_foreign_or_cut_serialized_state_is_refused_naming_why(native, which) -> None:
    """Bytes that are not this FMU's serialised state (the other FMI version's header, or
    one byte short) are refused with an error naming why, and the instance steps on."""
    with slave(native[which]) as fmu:
        fmu.start()
        serialize = fmu.fmu.serializeFMUState if fmu.fmi3 else fmu.fmu.serializeFMUstate
        deserialize = fmu.fmu.deserializeFMUState if fmu.fmi3 else fmu.fmu.deSerializeFMUstate
        blob = bytes(serialize(fmu.fmu.getFMUState()))
        foreign = (b"TMJFMI2" if fmu.fmi3 else b"TMJFMI3") + blob[7:]
        for bad, why in ((foreign, "without the header of a serialised FMI"),
                         (blob[:-1], "state bytes in mode")):
            with pytest.raises(FMICallException, match="status 3"):
                deserialize(bad)
            assert why in fmu.errors()
        fmu.step()
        assert math.isfinite(fmu.get("stroke_m"))
        fmu.close()


@pytest.mark.slow
def test_two_instances_on_two_threads_agree_with_one(native) -> None:
    def run(out: list[float], name: str) -> None:
        with slave(native["fmi2"], name) as fmu:
            fmu.start()
            fmu.set("track_speed_m_s", 1.5)
            for _ in range(500):
                fmu.step()
            out.append(fmu.get("stroke_m"))
            fmu.close()

    alone: list[float] = []
    run(alone, "alone")
    results: list[list[float]] = [[], []]
    threads = [threading.Thread(target=run, args=(results[i], f"t{i}")) for i in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert results[0] == alone and results[1] == alone


@pytest.mark.parametrize("kind", ["track", "plant"])
def test_an_fmu_name_not_ending_in_fmu_is_refused_before_any_work(tmp_path, capsys,
                                                                   kind: str) -> None:
    """-o x.zip would write an FMU an importer does not take for one: refused in one line,
    nothing written."""
    from trackmj.cli.main import main

    out = tmp_path / "x.zip"
    assert main(["fmu", "export", kind, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"trackmj: error: -o {out}: an FMU's file name must end in .fmu (FMI "
                   "2.0/3.0 standard), e.g. -o track.fmu")
    assert list(tmp_path.iterdir()) == []


def test_a_force_that_tears_the_settled_track_writes_no_fmu(tmp_path, capsys) -> None:
    """--force 5e5 N (33 x LF1352's nominal) makes the settle unstable: an FMU starting
    from that state would be meaningless, so none is written and one line says why and
    what fits."""
    from trackmj.cli.main import main

    out = tmp_path / "x.fmu"
    assert main(["fmu", "export", "track", "--force", "5e5", "--platform", "linux",
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("trackmj: error: --force 500000 N: the track of lf1352 settled "
                              "under it left physics (MuJoCo warning: "), err
    assert err[-1].endswith("so the FMU would start from no physical state and was not "
                            "written; give a force nearer the machine's nominal tension "
                            "15000 N"), err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_track_settled_on_its_end_stop_is_exported_with_the_runs_warning(tmp_path,
                                                                          capsys) -> None:
    """compact3 with its carrier's travel cut to 5 mm outward of the layout, settled under
    60 kN (4.6 x its nominal), rests on its extended stop: the FMU is written (an importer
    applying less force lifts the carrier off the stop) with the warning a run gives."""
    from trackmj.cli.main import main
    from trackmj.machines.assembly import resolve

    shipped = resolve("compact3")
    mechanics = tmp_path / "short.toml"
    mechanics.write_text(shipped.mechanics.read_text().replace(
        "slide_range_m = [-0.04, 0.04]", "slide_range_m = [-0.04, 0.005]"))
    machine = tmp_path / "short_machine.toml"
    machine.write_text(f'[machine]\nname = "compact3-short"\ndescription = "compact3, short '
                       f'carrier travel"\nmechanics = "short.toml"\nhydraulics = '
                       f'"{shipped.hydraulics}"\ncontrol = "{shipped.control}"\n')
    out = tmp_path / "short.fmu"
    assert main(["fmu", "export", "track", "--machine", str(machine), "--force", "6e4",
                 "--platform", "linux", "-o", str(out)]) == 0
    assert out.is_file()
    err = [line for line in capsys.readouterr().err.splitlines() if "trackmj" in line]
    assert len(err) == 1 and err[0].startswith(
        "trackmj: warning: compact3-short on level ground settles with its idler carrier on "
        "its extended end stop (stroke "), err
    assert err[0].endswith("the stop at 45.0 mm): the stop, not the tensioner, holds the "
                           "idler in the FMU's start state (settled under --force 60000 N)")
