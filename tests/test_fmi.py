"""FMI both ways: FMUs as the tensioner and the controller (fmpy), trackmj as an FMU
(pythonfmu), checked against the built-in elements, analytic laws and third-party importers.

The FMUs are built once per session: the gas-charged cylinder from C (tests/fmus, the
Reference FMUs framework, cc), the built-in hydraulic plugin and a P controller wrapped by
pythonfmu, and the exported track and plant."""

from __future__ import annotations

import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, filtfilt

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "fmus"))

from build import build_gas_cylinder, gas_force_N  # noqa: E402

from trackmj.cli.main import main  # noqa: E402
from trackmj.sim.setup import prepare  # noqa: E402


def _tensioner(path: Path, fmu: str, *, inputs: dict, outputs: dict,
               parameters: dict | None = None, extra: str = "") -> Path:
    lines = ["[fmu]", 'source = "tests"', f'path = "{fmu}"', "force_limit_N = 1.0e5",
             "travel_m = [-0.005, 0.105]", extra, "[fmu.inputs]"]
    lines += [f'"{k}" = "{v}"' for k, v in inputs.items()] + ["[fmu.outputs]"]
    lines += [f'"{k}" = "{v}"' for k, v in outputs.items()]
    if parameters:
        lines += ["[fmu.parameters]"] + [f'"{k}" = {v!r}' for k, v in parameters.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


GAS_IO = dict(inputs={"stroke": "stroke_m", "velocity": "velocity_m_s"},
              outputs={"force": "force_N", "power": "port_power_W"})


@pytest.fixture(scope="session")
def fmus(tmp_path_factory) -> Path:
    """The gas cylinder as FMI 2.0 (directional derivatives) and 3.0 (none), one without
    co-simulation roll-back and one without a binary for this platform."""
    d = tmp_path_factory.mktemp("fmus")
    build_gas_cylinder(d / "gas2.fmu", version=2, directional=True)
    build_gas_cylinder(d / "gas3.fmu", version=3, directional=False)
    build_gas_cylinder(d / "gas2_noroll.fmu", version=2, roll_back=False)
    build_gas_cylinder(d / "gas2_win.fmu", version=2, platform_binary=False)
    return d


@pytest.fixture(scope="session")
def hydraulic_fmu(tmp_path_factory) -> Path:
    """The built-in hydraulic plugin as a pythonfmu co-simulation FMU with state roll-back,
    and its tensioner file at W1's initial head pressure."""
    from pythonfmu.builder import FmuBuilder

    d = tmp_path_factory.mktemp("hydraulic")
    fmu = FmuBuilder.build_FMU(HERE / "fmus" / "HydraulicTensionerFmu.py", dest=d,
                               canGetAndSetFMUstate=True)
    setup = prepare("W1")
    coupling = setup.hydraulics.coupling
    return _tensioner(
        d / "hydraulic.toml", fmu.name,
        inputs={"stroke_m": "stroke_m", "velocity_m_s": "velocity_m_s",
                "valve_mode": "valve_mode"},
        outputs={"force_N": "force_N", "p_head_Pa": "p_head_Pa", "p_rod_Pa": "p_rod_Pa",
                 "p_supply_Pa": "p_supply_Pa"},
        parameters={"head_pressure_Pa": setup.head_pressure0_Pa},
        extra=f"max_correction_N = {coupling.max_correction_N!r}\n"
              f"min_correction_velocity_m_s = {coupling.min_correction_velocity_m_s!r}")


@pytest.fixture(scope="module")
def w1_runs(hydraulic_fmu) -> dict:
    """W1 (tp, nmpc, 3 s): built-in tp and tp-weak, the FMU strong (tp) and weak (tp-weak)."""
    from trackmj import simulate

    return {"tp": simulate("W1", duration=3.0),
            "tp-weak": simulate("W1", architecture="tp-weak", duration=3.0),
            "fmu": simulate("W1", duration=3.0, tensioner=hydraulic_fmu),
            "fmu-weak": simulate("W1", architecture="tp-weak", duration=3.0,
                                 tensioner=hydraulic_fmu)}


@pytest.mark.slow
def test_round_trip_strong_coupling_reproduces_the_built_in_plugin(w1_runs) -> None:
    """The plugin wrapped as an FMU and coupled strongly (roll-back, central difference on
    dF/dv, NEPCE) gives the built-in element's tension within 1e-6 relative at every step,
    with the same valve decisions."""
    ref, fmu = w1_runs["tp"].columns(), w1_runs["fmu"].columns()
    error = np.abs(fmu["tension_N"] - ref["tension_N"]) / np.abs(ref["tension_N"])
    print(f"round trip, strong: max relative tension error {error.max():.2e}")
    assert error.max() <= 1e-6
    assert np.array_equal(fmu["valve_mode"], ref["valve_mode"])
    described = w1_runs["fmu"].metrics["tensioner"]
    assert described["coupling"] == "strong" and described["interface"] == "co-simulation"
    assert abs(w1_runs["fmu"].metrics["interface_energy_residual_J"]) < 1e-3


def test_round_trip_weak_coupling_is_within_the_tp_weak_difference(w1_runs) -> None:
    """Forced weak (tp-weak) the FMU's error against tp is of tp-weak's size: on the study's
    headline metric (low-pass RMSE) and on the low-passed tension trace within twice
    tp-weak's (the FMU's weak exchange holds its whole force, seal friction included, where
    the built-in tp-weak keeps the plugin's friction implicit). The metric's two errors are
    a few tens of newtons and swap order with the track model (free links: 35 against
    49 N; chains on the foundation: 40 against 25 N) while the traces stay put (134
    against 91 N; 129 against 94 N)."""
    b, a = butter(2, 2.0, fs=1000.0)
    tension = {k: filtfilt(b, a, r.columns()["tension_N"]) for k, r in w1_runs.items()}
    trace = {k: float(np.sqrt(np.mean((tension[k] - tension["tp"]) ** 2)))
             for k in ("tp-weak", "fmu-weak")}
    metric = {k: abs(w1_runs[k].metrics["rmse_lp_N"] - w1_runs["tp"].metrics["rmse_lp_N"])
              for k in ("tp-weak", "fmu-weak")}
    print(f"weak: low-pass trace rms vs tp {trace}, |Δ rmse_lp| {metric}")
    assert w1_runs["fmu-weak"].metrics["tensioner"]["coupling"] == "weak"
    assert metric["fmu-weak"] <= 2.0 * metric["tp-weak"]
    assert trace["fmu-weak"] <= 2.0 * trace["tp-weak"]


@pytest.mark.slow
@pytest.mark.parametrize(("fmu", "interface", "coupling"), [
    ("gas2.fmu", "auto", "strong"),
    ("gas2.fmu", "model-exchange", "implicit"),
    ("gas3.fmu", "model-exchange", "implicit"),
    ("gas2_noroll.fmu", "co-simulation", "weak"),
])
def test_c_fmu_gas_cylinder_as_the_drive_tensioner(fmus, tmp_path, fmu, interface,
                                                   coupling) -> None:
    """The gas cylinder compiled from C as the tensioner of trackmj drive (3 s at 1.5 m/s):
    the mean idler force matches the analytic law at the mean stroke within 1 %, in every
    coupling; the track's energy ledger closes."""
    from trackmj.sim.drive import drive

    toml = _tensioner(fmus / f"{Path(fmu).stem}_{interface}.toml", fmu, **GAS_IO,
                      extra=f'interface = "{interface}"')
    result = drive(1.5, 3.0, tensioner=toml)
    series, m = result.timeseries, result.metrics
    steady = series["t_s"] >= m["steady"]["from_s"]
    force = float(series["idler_force_N"][steady].mean())
    law = gas_force_N(float(series["stroke_m"][steady].mean()))
    print(f"{fmu} {coupling}: mean force {force:.1f} N, law at mean stroke {law:.1f} N "
          f"({100 * (force / law - 1):+.3f} %)")
    assert m["tensioner"]["coupling"] == coupling
    assert force == pytest.approx(law, rel=0.01)
    assert m["mujoco_warnings"] == 0 and m["derailment_checks_failed"] == 0
    energy = m["track_energy"]
    assert abs(energy["residual_J"]) <= 1e-3 * abs(energy["drive_work_J"])


@pytest.fixture(scope="session")
def exported(tmp_path_factory) -> dict[str, Path]:
    from trackmj.fmi.export import export

    d = tmp_path_factory.mktemp("exported")
    return {kind: export(kind, d / f"{kind}.fmu").path for kind in ("track", "plant")}


def test_exported_fmus_pass_fmpy_validation(exported) -> None:
    from fmpy.validation import validate_fmu

    for path in exported.values():
        assert validate_fmu(str(path)) == []


@pytest.mark.slow
def test_fmpy_simulate_fmu_settles_the_track_where_drive_puts_it(exported, tmp_path) -> None:
    """fmpy.simulate_fmu runs the track FMU standing with a constant 13 kN force (2e4 N·s/m
    of damping through force_dv): its stroke settles within 0.5 mm of where trackmj drive
    puts it with the same force as a tensioner file's spring-damper (k = 0)."""
    from fmpy import simulate_fmu

    from trackmj.sim.drive import drive

    result = simulate_fmu(str(exported["track"]), stop_time=3.0, step_size=1e-3,
                          output_interval=1e-3, output=["stroke_m", "tension_N"],
                          start_values={"force_N": 13e3, "force_dv_N_s_m": -2e4})
    passive = tmp_path / "constant.toml"
    passive.write_text('[passive]\nsource = "tests: a constant force"\npreload_N = 13000.0\n'
                       'stiffness_N_m = 0.0\ndamping_N_s_m = 2.0e4\nstroke_ref_m = 0.05\n'
                       'travel_m = [-0.005, 0.105]\n')
    driven = drive(0.0, 3.0, tensioner=passive).timeseries
    fmu_stroke, drive_stroke = float(result["stroke_m"][-1]), float(driven["stroke_m"][-1])
    print(f"settled stroke: FMU {fmu_stroke * 1e3:.3f} mm, drive {drive_stroke * 1e3:.3f} mm")
    assert abs(result["stroke_m"][-1] - result["stroke_m"][-200]) < 1e-5   # settled
    assert abs(fmu_stroke - drive_stroke) < 0.5e-3
    assert np.allclose(result["tension_N"][1:], 13e3, atol=2e4 * 0.01)


@pytest.mark.slow
def test_a_c_importer_without_python_steps_the_track_fmu(exported, tmp_path) -> None:
    """A C program (no Python in its process, an empty environment, as Simulink would load
    it) loads the track FMU's binary, steps it 2 s at 1 ms and reads a finite stroke."""
    from fmpy import read_model_description

    host = tmp_path / "c_importer"
    subprocess.run(["cc", "-O2", f"-I{HERE / 'fmus' / 'reference_fmus' / 'include'}",
                    str(HERE / "fmus" / "c_importer.c"), "-o", str(host), "-ldl"],
                   check=True)
    unzipped = tmp_path / "track"
    with zipfile.ZipFile(exported["track"]) as zf:
        zf.extractall(unzipped)
    md = read_model_description(str(exported["track"]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    binary = unzipped / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    run = subprocess.run([str(host), str(binary), md.guid, (unzipped / "resources").as_uri(),
                          str(vr["force_N"]), "13000", str(vr["stroke_m"]), "2000"],
                         capture_output=True, text=True, env={}, timeout=300)
    assert run.returncode == 0, run.stderr
    stroke = float(run.stdout)
    assert np.isfinite(stroke) and -0.005 < stroke < 0.105


def test_the_plant_fmu_raises_the_tension_when_pressurized(exported) -> None:
    """The plant FMU (track + built-in hydraulics): 1 s of valve mode +1 raises the true
    tension and the measured head pressure; the sensors are noisy around the truth."""
    from fmpy import simulate_fmu

    r = simulate_fmu(str(exported["plant"]), stop_time=1.0, step_size=1e-3,
                     output_interval=1e-3, start_values={"valve_mode": 1},
                     output=["tension_N", "p_head_Pa", "p_head_measured_Pa"])
    assert r["tension_N"][-1] > r["tension_N"][0] + 2e3
    noise = r["p_head_measured_Pa"] - r["p_head_Pa"]
    assert 0.0 < np.std(noise) < 1e6


BAD = {
    "missing": ("absent.fmu", "no such file"),
    "not_a_zip": ("text.fmu", "is not an FMU (not a zip archive)"),
    "no_binary": ("gas2_win.fmu", "has no binary for this platform"),
}


@pytest.mark.parametrize("case", [*BAD, "unknown_variable", "wrong_causality"])
def test_a_bad_fmu_is_refused_before_the_run(fmus, tmp_path, capsys, case) -> None:
    """Exit 2 with one line naming the file, key and variable; nothing is written."""
    (fmus / "text.fmu").write_text("not an FMU")
    inputs, outputs = dict(GAS_IO["inputs"]), dict(GAS_IO["outputs"])
    fmu, expected = BAD.get(case, ("gas2.fmu", ""))
    if case == "unknown_variable":
        inputs = {"strok": "stroke_m", "velocity": "velocity_m_s"}
        expected = "[fmu.inputs].strok: gas2.fmu has no variable 'strok'"
    if case == "wrong_causality":
        inputs = {"force": "stroke_m", "velocity": "velocity_m_s"}
        expected = "'force' has causality 'output'"
    toml = _tensioner(tmp_path / f"{case}.toml", str(fmus / fmu), inputs=inputs,
                      outputs=outputs)
    out = tmp_path / "run"
    assert main(["run", "W2", "--duration", "1.2", "--tensioner", str(toml),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err and toml.name in err
    assert not out.exists()


@pytest.mark.parametrize(("parameter", "expected"), [
    ("fail_time", "the FMU gas2.fmu: "),
    ("nan_time", "output force_N = nan"),
])
def test_an_fmu_that_fails_mid_run_stops_it_and_keeps_earlier_results(
        fmus, tmp_path, capsys, parameter, expected) -> None:
    """An FMU that errors (or outputs NaN) at 0.5 s: exit 3, one line naming the FMU and the
    call (or the output), the earlier result in the output directory untouched."""
    toml = _tensioner(tmp_path / "gas.toml", str(fmus / "gas2.fmu"), **GAS_IO,
                      parameters={parameter: 0.5})
    out = tmp_path / "run"
    out.mkdir()
    (out / "metrics.json").write_text("{}")   # an earlier result's file
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(["drive", "--duration", "1", "--tensioner", str(toml), "--out", str(out)]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err
    assert re.search(r"t = 0\.(499|500) s", err)
    code = main(["run", "W2", "--duration", "1.2", "--tensioner", str(toml), "--out", str(out)])
    assert code in (2, 3)   # 2: the directory guard refuses a foreign folder first
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.slow
def test_a_controller_fmu_closes_the_loop(tmp_path) -> None:
    """A proportional controller exported by pythonfmu (as a Simulink controller would be)
    as --controller fmu:FILE: it runs every 10 ms and tracks W1's 12 kN and 15 kN levels
    within 10 %, switching the valves both ways."""
    from pythonfmu.builder import FmuBuilder

    from trackmj import simulate

    fmu = FmuBuilder.build_FMU(HERE / "fmus" / "TensionController.py", dest=tmp_path)
    cyl = prepare("W1").hydraulics.cylinder
    controller = tmp_path / "controller.toml"
    controller.write_text(
        f'[controller]\nsource = "tests"\npath = "{fmu.name}"\nperiod_s = 0.01\n'
        '[controller.inputs]\np_head = "p_head_Pa"\np_rod = "p_rod_Pa"\nF_ref = "F_ref_N"\n'
        '[controller.outputs]\nu = "u"\n[controller.parameters]\n'
        f'area_head = {2 * cyl.area_head_m2!r}\narea_rod = {2 * cyl.area_rod_m2!r}\n'
        'kp = 2.0e-3\n')
    result = simulate("W1", duration=6.0, controller=f"fmu:{controller}")
    cols = result.columns()
    for start, end in ((1.0, 2.9), (4.5, 6.0)):
        window = (cols["t_s"] > start) & (cols["t_s"] <= end)
        assert cols["tension_N"][window].mean() == pytest.approx(
            cols["tension_ref_N"][window].mean(), rel=0.1)
    assert set(np.unique(cols["valve_mode"])) == {-1, 0, 1}
    assert result.controller == "fmu" and result.metrics["controller_fallbacks"] == 0.0
