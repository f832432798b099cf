"""No debris, no silent clipping: finished folders hold no lock files (two writers still
serialise), an FMU's unzipped copy is removed on every path, a controller output outside
[-1, 1] is counted and marks the run, an FMU's own logged reason is in its error, FMI 3.0
platforms are named as the standard names them, and a tensioner without valves has no
valve metrics.

The FMUs are the tests' gas-charged cylinder compiled from C (tests/fmus): as a controller
its output, a force of ~1e4-1e5 N mapped to u, is the "controller output 13,000" of the
issue; with another GUID in its modelDescription it fails to instantiate and says why."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import textwrap
import threading
import zipfile
from pathlib import Path

import numpy as np
import pytest
from synthetic import energy_table, synthetic_result

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "fmus"))

from build import build_gas_cylinder  # noqa: E402

import trackmj.results.store as store  # noqa: E402
import trackmj.study.campaign as campaign  # noqa: E402
from trackmj.cli.main import main  # noqa: E402
from trackmj.cli.summary import flagged, summary_table, warning_lines  # noqa: E402
from trackmj.errors import FmuError  # noqa: E402
from trackmj.ports import (  # noqa: E402
    COUPLING_STEP_S,
    Command,
    ControlOutput,
    Readout,
    StepInputs,
)
from trackmj.results.metrics import compute_metrics  # noqa: E402
from trackmj.scenarios.load import load_scenario  # noqa: E402
from trackmj.sim.loop import Schedule, run_loop  # noqa: E402
from trackmj.sim.observers import Recorder  # noqa: E402
from trackmj.study.executor import RunOutcome, RunSpec  # noqa: E402
from trackmj.validator import ParameterError  # noqa: E402

SHORT = {"scenario.evaluation.start_s": 0.1}
"""W2 evaluated from 0.1 s, so that a 0.3 s run has metrics."""


# ============================================================================ lock files

def _locks(*roots: Path) -> list[Path]:
    return [p for root in roots for p in root.rglob("*.lock")]


def test_a_result_written_through_the_store_leaves_no_lock_file(tmp_path) -> None:
    out = store.write_result(synthetic_result("W2", duration_s=2.0), tmp_path / "run")
    store.write_result(synthetic_result("W2", duration_s=2.0, offset_N=5.0), out)  # replaced
    assert [p.name for p in tmp_path.iterdir()] == ["run"] and _locks(tmp_path) == []


class _SyntheticExecutor:
    """Stands in for the Dask executor (``with Executor(...) as ex``): each run is a
    synthetic result of its scenario and architecture."""

    def __init__(self, **kwargs: object) -> None:
        pass

    def __enter__(self) -> _SyntheticExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def as_completed(self, specs, progress=None):
        for spec in specs:
            result = synthetic_result(spec.scenario, spec.architecture, seed=spec.seed,
                                      duration_s=2.0, energy=energy_table())
            yield RunOutcome(spec, result=result, wall_time_s=0.01)


@pytest.mark.slow
def test_a_finished_compare_folder_holds_no_lock_files(tmp_path, monkeypatch) -> None:
    """`trackmj compare` (its runs made by a stand-in executor, its figures drawn): the
    campaign's lock and each run's writer lock (.campaign.lock, .tp-nmpc.lock, ...) are
    gone when it ends."""
    monkeypatch.setattr(campaign, "Executor", _SyntheticExecutor)
    out = tmp_path / "cmp"
    assert main(["compare", "W2", "--duration", "2", "--out", str(out)]) == 0
    assert (out / "tp-nmpc" / "metrics.json").is_file()
    assert _locks(tmp_path) == []


def test_a_finished_campaign_with_its_runs_holds_no_lock_files(tmp_path) -> None:
    """A campaign keeping its runs under runs/, made and then resumed: no .campaign.lock,
    no runs/.NAME.lock left."""
    runs = [campaign.plan_run(RunSpec(scenario="W2", duration=2.0, seed=s)) for s in (0, 1)]
    for _ in range(2):   # made, then resumed
        with campaign.Store(tmp_path / "sweep", "sweep") as st:
            assert (tmp_path / "sweep" / campaign.LOCK).exists()   # held while it runs
            campaign.run_campaign(st, runs, executor=_SyntheticExecutor(), keep_runs=True)
    assert len(list((tmp_path / "sweep" / "runs").iterdir())) == 2
    assert _locks(tmp_path) == []


def test_a_lock_taken_over_from_a_releasing_holder_is_the_path_s_file(tmp_path,
                                                                       monkeypatch) -> None:
    """The race of removing a lock file: B opens the path while A holds it, A releases
    (removes the file, unlocks), B's flock then succeeds on the removed file. B must see
    that and take the path's lock anew, so that a third writer C is refused while B
    holds it (without the check B and C would both hold a lock)."""
    path = tmp_path / ".run.lock"
    a, b, c = store.LockFile(path), store.LockFile(path), store.LockFile(path)
    assert a.acquire()
    real_flock = store.fcntl.flock
    calls = []

    def flock_after_a_released(fh, op):
        if not calls:   # B has opened A's file; A releases before B's flock
            calls.append(op)
            a.release()
        return real_flock(fh, op)

    monkeypatch.setattr(store.fcntl, "flock", flock_after_a_released)
    assert b.acquire()
    monkeypatch.setattr(store.fcntl, "flock", real_flock)
    assert path.exists() and not c.acquire()
    b.release()
    assert not path.exists() and c.acquire()
    c.release()
    assert list(tmp_path.iterdir()) == []


def test_writers_in_threads_never_hold_the_lock_together(tmp_path) -> None:
    """8 threads taking and releasing one lock file 300 times each: at most one holds it at
    any time, some are refused, and no file is left."""
    path = tmp_path / ".run.lock"
    holders, most, refused = [0], [0], [0]
    guard = threading.Lock()

    def work() -> None:
        for _ in range(300):
            lock = store.LockFile(path)
            if not lock.acquire():
                with guard:
                    refused[0] += 1
                continue
            with guard:
                holders[0] += 1
                most[0] = max(most[0], holders[0])
            with guard:
                holders[0] -= 1
            lock.release()

    threads = [threading.Thread(target=work) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert most[0] == 1 and list(tmp_path.iterdir()) == []


def test_a_second_process_is_refused_while_the_first_writes_then_finds_no_lock(
        tmp_path) -> None:
    out = tmp_path / "run"
    script = textwrap.dedent(f"""
        import sys
        import trackmj.results.store as R
        with R.ResultWriter({str(out)!r}):
            print("holding", flush=True)
            sys.stdin.readline()
    """)
    with subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True) as proc:
        try:
            assert proc.stdout.readline().strip() == "holding"
            assert (tmp_path / ".run.lock").exists()
            with pytest.raises(store.ResultDirectoryError, match="another trackmj process"):
                store.ResultWriter(out).__enter__()
            proc.stdin.write("done\n")
            proc.stdin.flush()
            assert proc.wait(timeout=30) == 0
        finally:
            proc.kill()
    assert list(tmp_path.iterdir()) == []
    store.write_result(synthetic_result("W2", duration_s=2.0), out)
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


# ============================================================================ FMUs

@pytest.fixture(scope="module")
def gas(tmp_path_factory) -> Path:
    """The gas cylinder as FMI 2.0 and 3.0, each also with another GUID/instantiation token
    in its modelDescription (its binary refuses to instantiate, logging why), FMI 3.0
    without a binary for this platform, and FMI 3.0 with its binary under FMI 2.0's
    folder name."""
    d = tmp_path_factory.mktemp("gas")
    for version in (2, 3):
        fmu = build_gas_cylinder(d / f"gas{version}.fmu", version=version)
        with zipfile.ZipFile(fmu) as zi, \
                zipfile.ZipFile(d / f"wrong_token{version}.fmu", "w") as zo:
            for item in zi.infolist():
                data = zi.read(item.filename)
                if item.filename == "modelDescription.xml":
                    data = data.replace(b"{6f1c2a52-", b"{00000000-")
                zo.writestr(item, data)
    build_gas_cylinder(d / "gas3_windows.fmu", version=3, platform_binary=False)
    build_gas_cylinder(d / "gas2_windows.fmu", version=2, platform_binary=False)
    with zipfile.ZipFile(d / "gas3.fmu") as zi, \
            zipfile.ZipFile(d / "gas3_fmi2_folder.fmu", "w") as zo:
        for item in zi.infolist():
            name = item.filename.replace("binaries/x86_64-linux/", "binaries/linux64/")
            zo.writestr(name, zi.read(item.filename))
    return d


def _tensioner(path: Path, fmu: Path, *, inputs: str = 'stroke = "stroke_m"\n'
               'velocity = "velocity_m_s"\n', parameters: str = "") -> Path:
    path.write_text(f'[fmu]\nsource = "tests"\npath = "{fmu}"\nforce_limit_N = 1.0e5\n'
                    f'travel_m = [-0.005, 0.105]\n[fmu.inputs]\n{inputs}[fmu.outputs]\n'
                    f'force = "force_N"\n'
                    + (f"[fmu.parameters]\n{parameters}" if parameters else ""))
    return path


def _controller(path: Path, fmu: Path, parameters: str = "") -> Path:
    """The gas cylinder as a controller FMU: its force [N] mapped to u."""
    path.write_text(f'[controller]\nsource = "tests"\npath = "{fmu}"\nperiod_s = 0.01\n'
                    '[controller.inputs]\nstroke = "stroke_m"\n'
                    'velocity = "stroke_velocity_m_s"\n[controller.outputs]\nforce = "u"\n'
                    + (f"[controller.parameters]\n{parameters}" if parameters else ""))
    return path


@pytest.fixture
def private_tmp(tmp_path, monkeypatch) -> Path:
    """The system's temporary directory as an empty folder of this test."""
    folder = tmp_path / "systmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def _unzipped(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.startswith("trackmj-fmu-")]


@pytest.mark.parametrize("version", [2, 3])
def test_a_failed_instantiation_removes_the_copy_and_says_what_the_fmu_logged(
        gas, tmp_path, private_tmp, version) -> None:
    """Another GUID (instantiation token) in the modelDescription: the binary refuses it and
    logs why; the error names the call and quotes the FMU, and the unzipped copy is gone
    while the exception is still held (not only once it is collected)."""
    from trackmj.elements.fmu import FmuElement
    from trackmj.elements.tensioner_file import load_tensioner

    loaded = load_tensioner(_tensioner(tmp_path / "t.toml", gas / f"wrong_token{version}.fmu"))
    with pytest.raises(FmuError) as info:
        FmuElement(loaded, stroke_m=0.05, coupling="strong")
    said = "Wrong GUID." if version == 2 else "Wrong instantiationToken."
    assert "instantiate" in str(info.value) and f"the FMU logged: [Error] {said}" in str(
        info.value)
    assert _unzipped(private_tmp) == []


def test_a_controller_fmu_that_cannot_load_its_binary_leaves_no_copy(
        gas, tmp_path, private_tmp) -> None:
    """A binary that is not a shared library (the load fails before any instance) and a
    controller that fails to instantiate: no copy left either way."""
    from trackmj.fmi.controller_fmu import FmuController, load_controller_file

    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(gas / "gas2.fmu") as zi, zipfile.ZipFile(broken, "w") as zo:
        for item in zi.infolist():
            data = zi.read(item.filename)
            zo.writestr(item, b"not a library" if item.filename.endswith(".so") else data)
    loaded = load_controller_file(_controller(tmp_path / "c.toml", broken))
    with pytest.raises(FmuError, match=r"load at t = 0\.000 s failed"):
        FmuController(loaded)
    assert _unzipped(private_tmp) == []
    loaded = load_controller_file(_controller(tmp_path / "c2.toml", gas / "wrong_token2.fmu"))
    with pytest.raises(FmuError, match=r"the FMU logged: \[Error\] Wrong GUID\."):
        FmuController(loaded)
    assert _unzipped(private_tmp) == []


def test_the_fmu_s_message_is_formatted_and_reaches_its_own_instance(gas, tmp_path) -> None:
    """Two FMI 2.0 instances at once (a controller and a tensioner): the one that fails
    quotes its own printf-formatted message ("injected failure at t = 0.02 s"), the other
    logged nothing."""
    from trackmj.fmi.controller_fmu import FmuController, load_controller_file

    fine = FmuController(load_controller_file(_controller(tmp_path / "a.toml",
                                                          gas / "gas2.fmu")))
    failing = FmuController(load_controller_file(_controller(
        tmp_path / "b.toml", gas / "gas2.fmu", "fail_time = 0.02\n")))
    estimate, preview = np.array([1e6, 0.0, 0.05, 0.0]), np.array([12e3])
    fine(estimate, preview, 0.0)
    failing(estimate, preview, 0.0)
    with pytest.raises(FmuError) as info:   # its step from 0.01 s to 0.02 s fails
        failing(estimate, preview, 0.01)
    fine(estimate, preview, 0.01)
    assert "the FMU logged: [Error] injected failure at t = 0.02 s" in str(info.value)
    assert list(fine.inst.log.messages) == []
    fine.close()
    failing.close()


def test_a_controller_fmu_run_and_a_failed_one_leave_no_copy(gas, tmp_path,
                                                             private_tmp) -> None:
    from trackmj import simulate

    simulate("W2", duration=0.3, architecture="dp-b", set=SHORT,
             controller=f"fmu:{_controller(tmp_path / 'c.toml', gas / 'gas3.fmu')}")
    assert _unzipped(private_tmp) == []
    failing = _controller(tmp_path / "f.toml", gas / "gas2.fmu", "fail_time = 0.15\n")
    with pytest.raises(FmuError, match=r"injected failure at t = 0\.15 s") as info:
        simulate("W2", duration=0.3, architecture="dp-b", set=SHORT,
                 controller=f"fmu:{failing}")
    del info   # the exception handled: its frames, and the controller with them, are gone
    assert _unzipped(private_tmp) == []


def test_with_closes_an_instance_and_a_second_close_does_nothing(gas, tmp_path,
                                                                 private_tmp) -> None:
    from trackmj.elements.tensioner_file import load_tensioner
    from trackmj.fmi.fmu import FmuInstance

    loaded = load_tensioner(_tensioner(tmp_path / "t.toml", gas / "gas3.fmu"))
    with FmuInstance(loaded.description) as inst:
        inst.start(0.0, {"stroke_m": 0.05, "velocity_m_s": 0.0})
        assert len(_unzipped(private_tmp)) == 1
    assert _unzipped(private_tmp) == []
    inst.close()


# ============================================================================ platforms

def test_fmi3_platforms_are_named_as_the_standard_names_them(gas, tmp_path) -> None:
    """An FMI 3.0 FMU built for Windows only is refused naming ``x86_64-windows`` (the
    standard's platform tuple), not FMI 2.0's ``win64``; FMI 2.0 keeps ``win64``; an FMI 3.0
    FMU whose Linux binary sits in FMI 2.0's ``linux64`` folder has none where FMI 3.0
    looks (``x86_64-linux``)."""
    from trackmj.elements.tensioner_file import load_tensioner
    from trackmj.fmi.fmu import binary_platforms

    with pytest.raises(ParameterError) as info:
        load_tensioner(_tensioner(tmp_path / "w3.toml", gas / "gas3_windows.fmu"))
    message = str(info.value)
    assert "it has: x86_64-windows" in message and "win64" not in message
    assert "this platform (x86_64-linux" in message and "FMI 3.0" in message
    with pytest.raises(ParameterError, match=r"this platform \(linux64.*it has: win64$"):
        load_tensioner(_tensioner(tmp_path / "w2.toml", gas / "gas2_windows.fmu"))
    with pytest.raises(ParameterError, match=r"x86_64-linux.*it has: linux64$"):
        load_tensioner(_tensioner(tmp_path / "l3.toml", gas / "gas3_fmi2_folder.fmu"))
    made = tmp_path / "many.fmu"
    with zipfile.ZipFile(made, "w") as zf:
        for name in ("binaries/aarch64-darwin/M.dylib", "binaries/x86_64-darwin/M.dylib",
                     "binaries/x86_64-windows/M.dll", "binaries/x86_64-linux/M.so",
                     "binaries/x86_64-linux/README.txt", "sources/model.c",
                     "modelDescription.xml"):
            zf.writestr(name, "")
    assert binary_platforms(made) == ["aarch64-darwin", "x86_64-darwin", "x86_64-linux",
                                      "x86_64-windows", "c-code"]


# ============================================================================ clipping

class _Plant:
    """Returns a still readout; records the u each step was commanded with."""

    def __init__(self) -> None:
        self.u: list[float] = []
        self.t = 0.0

    def step(self, command: Command, inputs: object) -> Readout:
        self.u.append(command.u)
        self.t += COUPLING_STEP_S
        return Readout(self.t, 12e3, 5e6, 0.0, 16e6, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0,
                       math.nan, 0.0, math.nan)


class _Scripted:
    """A controller with a 5 ms period giving the outputs of ``script`` in turn."""

    period_s = 0.005
    horizon_steps = 0

    def __init__(self, script: list[float]) -> None:
        self.script = iter(script)

    def __call__(self, estimate, preview, t) -> ControlOutput:
        return ControlOutput(next(self.script))

    def set_parameters(self, *, supply_pressure_Pa=None) -> None:
        pass


class _Still:
    def step(self, z, mode, p_s):
        return np.zeros(4)

    def period_mean(self):
        return np.zeros(4)

    def measure(self, x, drive_torque_N_m=None):
        return np.asarray(x, dtype=float)


class _Valves:
    def step(self, u: float) -> int:
        return int(np.sign(u))


def test_outputs_outside_the_range_are_clipped_counted_and_flag_the_run() -> None:
    """Outputs 0.5, 2.5, −1.0, −4.0, 1.0, NaN, 0.2 every 5 ms over 35 ms (hand-counted): the
    plant sees 0.5, 1, −1, −1, 1, −1, 0.2; three outputs (2.5, −4, NaN) were clipped, held
    5 steps each (15 of 35 steps), the first at t = 5 ms, the worst −4."""
    script = [0.5, 2.5, -1.0, -4.0, 1.0, math.nan, 0.2]
    steps = 35
    sched = Schedule(inputs=[StepInputs(0.0, 0.0, 0.0, 16e6)] * steps,
                     previews=np.full((7, 1), 12e3),
                     reference_N=np.full(steps, 12e3))
    plant, recorder, still = _Plant(), Recorder(sched), _Still()
    run_loop(sched, controller=_Scripted(script), valves=_Valves(), plant=plant,
             sensors=still, estimator=still, observers=[recorder])
    assert plant.u == [u for u in (0.5, 1.0, -1.0, -1.0, 1.0, -1.0, 0.2) for _ in range(5)]
    assert [k for k, _ in recorder.clipped] == [5, 15, 25]
    assert recorder.clipped[:2] == [(5, 2.5), (15, -4.0)] and math.isnan(recorder.clipped[2][1])
    w = load_scenario("W2").metric_windows(0.035)
    cols = recorder.columns() | {"e_supply_J": np.zeros(steps), "p_work_J": np.zeros(steps),
                                 "mech_work_J": np.zeros(steps)}
    m = compute_metrics(cols, w, control_period_s=0.005, clipped_outputs=recorder.clipped)
    assert m["controller_output_clipped"] == {"outputs": 3.0, "steps": 15.0,
                                              "share": pytest.approx(15 / 35),
                                              "first_s": pytest.approx(0.005), "worst": -4.0}
    assert m["flags"] == ["controller_output_clipped"] and flagged(m)
    clean = compute_metrics(cols, w, control_period_s=0.005, clipped_outputs=[])
    assert clean["flags"] == [] and not flagged(clean)
    assert clean["controller_output_clipped"]["steps"] == 0.0
    assert math.isnan(clean["controller_output_clipped"]["first_s"])


def test_a_controller_fmu_out_of_range_all_run_is_reported_and_marked(gas, tmp_path) -> None:
    """The gas cylinder's force (~1e4-1e5 N) as u: every output clipped to +1 for the whole
    run, in metrics.json (null where undefined, read back) and as a warning under the
    summary table; a built-in controller's run carries the same table with nothing in it."""
    from trackmj import simulate

    controller = _controller(tmp_path / "c.toml", gas / "gas2.fmu")
    result = simulate("W2", duration=0.3, set=SHORT, architecture="dp-b",
                      controller=f"fmu:{controller}")
    clipped = result.metrics["controller_output_clipped"]
    assert clipped["outputs"] == 30 and clipped["steps"] == 300 and clipped["share"] == 1.0
    assert clipped["first_s"] == 0.0 and clipped["worst"] > 1e3
    assert np.all(result.columns()["u"] == 1.0)          # what the valves saw: clipped
    out = store.write_result(result, tmp_path / "run")
    doc = json.loads((out / "metrics.json").read_text())["metrics"]
    assert doc["flags"] == ["controller_output_clipped"]
    assert doc["controller_output_clipped"]["outputs"] == 30
    table = summary_table([store.read_result(out)], "{r.architecture}")
    warning = table.splitlines()[-1]
    assert warning.startswith("WARNING: the controller's output was outside its range")
    assert "30 times" in warning and "300 steps (100 % of the run)" in warning
    assert warning_lines(doc) == [warning]
    builtin = simulate("W2", duration=0.3, set=SHORT, architecture="dp-b", controller="pid")
    assert builtin.metrics["flags"] == [] and "WARNING" not in summary_table(
        [builtin], "{r.architecture}")


# ============================================================================ valves

PASSIVE = ('[passive]\nsource = "tests"\npreload_N = 13000.0\nstiffness_N_m = 2.0e5\n'
           'damping_N_s_m = 2.0e4\nstroke_ref_m = 0.05\ntravel_m = [-0.005, 0.105]\n')


def test_valve_metrics_are_null_and_n_a_when_the_tensioner_takes_no_valve_mode(
        gas, tmp_path) -> None:
    """Which tensioners take the valve mode (the built-in plugin, an FMU with a valve_mode
    input; not a passive one, not an FMU without it), and what a run without valves shows:
    null valve metrics, "n/a" in the summary, though the valve logic switched modes."""
    from trackmj.sim.run import _takes_valve_mode
    from trackmj.sim.setup import prepare

    passive = tmp_path / "passive.toml"
    passive.write_text(PASSIVE)
    valved = _tensioner(tmp_path / "valved.toml", gas / "gas2.fmu",
                        inputs='stroke = "stroke_m"\nvelocity = "valve_mode"\n')
    plain = _tensioner(tmp_path / "plain.toml", gas / "gas2.fmu")
    assert [_takes_valve_mode(prepare("W2", tensioner=t)) for t in (None, valved, passive,
                                                                     plain)] == [
        True, True, False, False]
    run = synthetic_result("W2", duration_s=2.0)
    cols = dict(run.columns())
    cols["valve_mode"] = np.where(cols["t_s"] % 0.2 < 0.1, 1, 0)   # switching at 10 Hz
    w = load_scenario("W2").metric_windows(2.0)
    valves = compute_metrics(cols, w)
    assert valves["valve_mode_applied"] is True
    assert valves["valve_switch_rate_Hz"] == pytest.approx(10.0, rel=0.1)
    none = compute_metrics(cols, w, valve_mode_applied=False)
    assert none["valve_mode_applied"] is False
    assert math.isnan(none["valve_switches"]) and math.isnan(none["valve_switch_rate_Hz"])
    run.metrics = none
    out = store.write_result(run, tmp_path / "run")
    doc = json.loads((out / "metrics.json").read_text())["metrics"]
    assert doc["valve_switches"] is None and doc["valve_switch_rate_Hz"] is None
    rows = summary_table([store.read_result(out), synthetic_result("W2", duration_s=2.0)],
                         "{r.architecture}").splitlines()
    row = next(line for line in rows if line.startswith("| valve switching"))
    assert row.startswith("| valve switching [Hz] | n/a | ") and row.count("n/a") == 1


@pytest.mark.slow
def test_runs_with_a_tensioner_without_valves_have_no_valve_metrics(gas, tmp_path) -> None:
    """A passive tensioner and an FMU without a valve_mode input on the track (tp): null
    valve metrics, "n/a" in the summary."""
    from trackmj import simulate

    passive = tmp_path / "passive.toml"
    passive.write_text(PASSIVE)
    for tensioner in (passive, _tensioner(tmp_path / "gas.toml", gas / "gas2.fmu")):
        result = simulate("W2", duration=0.3, set=SHORT, tensioner=tensioner)
        m = result.metrics
        assert m["valve_mode_applied"] is False
        assert math.isnan(m["valve_switches"]) and math.isnan(m["valve_switch_rate_Hz"])
        rows = summary_table([result], "{r.architecture}").splitlines()
        assert "| valve switching [Hz] | n/a |" in rows
