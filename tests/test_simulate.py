"""End-to-end closed-loop runs: every architecture and controller on a short W1."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trackmj.cli.main import main
from trackmj.results.store import COLUMN_UNITS, read_result, write_result
from trackmj.scenarios.load import load_scenario
from trackmj.sim.run import simulate

DURATION_S = 2.0


@pytest.fixture(scope="module")
def w1():
    return load_scenario("W1")


@pytest.fixture(scope="module")
def tp_run(w1):
    return simulate(w1, architecture="tp", duration=DURATION_S)


def _finite_core(result) -> None:
    cols = result.columns()
    assert len(cols["t_s"]) == round(DURATION_S / 1e-3)
    np.testing.assert_allclose(np.diff(cols["t_s"]), 1e-3, rtol=1e-9)
    for name in ("tension_N", "tension_ref_N", "p_head_Pa", "stroke_m", "e_supply_J",
                 "mech_work_J"):
        assert np.all(np.isfinite(cols[name])), name
    assert set(np.unique(cols["valve_mode"])) <= {-1, 0, 1}


def test_tp_run_is_physical(tp_run) -> None:
    _finite_core(tp_run)
    m = tp_run.metrics
    assert m["mujoco_warnings"] == 0
    cols = tp_run.columns()
    assert cols["p_head_Pa"].min() > 0.0 and cols["p_supply_Pa"].max() < 25e6
    # the energy ledger of the plugin closes and the interface residual stays tiny
    assert abs(m["ledger_balance_error_J"]) < 1e-3 * max(m["energy_J"]["pump"], 1.0)
    assert abs(m["interface_energy_residual_J"]) < 1e-3 * np.sum(
        np.abs(np.diff(cols["mech_work_J"])))  + 1e-6
    # supply energy is drawn, never returned: cumulative supply energy does not decrease
    assert np.all(np.diff(cols["e_supply_J"]) >= -1e-9)


@pytest.mark.parametrize("architecture", ["tp-weak", "dp-b"])
def test_other_track_architectures_run(w1, architecture) -> None:
    result = simulate(w1, architecture=architecture, duration=DURATION_S)
    _finite_core(result)
    assert result.architecture == architecture
    assert result.metrics["mujoco_warnings"] == 0


def test_dp_a_replays_the_tp_track_load(w1, tp_run) -> None:
    """dp-a runs the same controller on the equivalent idler loaded by the replayed tp
    track load: finite, no chassis signal, tension bounded."""
    result = simulate(w1, architecture="dp-a", duration=DURATION_S, tp_result=tp_run)
    _finite_core(result)
    assert np.isnan(result.columns()["chassis_acc_z_m_s2"]).all()   # no chassis in dp-a
    assert result.columns()["tension_N"].max() < 50e3


@pytest.mark.parametrize("controller", ["pid", "lmpc"])
def test_baseline_controllers_run(w1, controller) -> None:
    result = simulate(w1, architecture="tp", controller=controller, duration=DURATION_S)
    _finite_core(result)
    assert result.controller == controller


def test_same_seed_gives_identical_timeseries(w1, tp_run) -> None:
    again = simulate(w1, architecture="tp", duration=DURATION_S)
    a, b = tp_run.columns(), again.columns()
    for name in COLUMN_UNITS:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_results_written_with_units(tp_run, tmp_path) -> None:
    out = write_result(tp_run, tmp_path / "run", csv=True)
    back = read_result(out)
    assert back.units["tension_N"] == "N" and back.units["p_head_Pa"] == "Pa"
    assert back.metrics["rmse_N"] == pytest.approx(tp_run.metrics["rmse_N"])
    assert (out / "timeseries.csv").read_text().startswith('"t_s","tension_N"')
    assert json.loads((out / "units.json").read_text())["tension_N"] == "N"


def test_bad_scenario_file_gives_clear_error_and_writes_nothing(tmp_path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(load_scenario("W1").source.read_text().replace(
        'controller = "nmpc"', 'controller = "mpcc"'))
    out = tmp_path / "out"
    assert main(["run", str(bad), "--duration", "0.1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "controller" in err and "mpcc" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.slow
def test_cli_run_writes_outputs(tmp_path) -> None:
    out = tmp_path / "w1"
    assert main(["run", "W2", "--duration", "1.5", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["metrics"]["rmse_N"] is not None
    assert (out / "timeseries.parquet").stat().st_size > 0
    assert (out / "timeseries.png").stat().st_size > 0


@pytest.mark.slow
def test_cli_overrides_change_the_run_and_are_recorded(tmp_path, capsys) -> None:
    standing, driven = tmp_path / "standing", tmp_path / "driven"
    assert main(["run", "W2", "--duration", "1.5", "--out", str(standing),
                 "--set", "scenario.track.speed_m_s=0.0",
                 "--set", "hydraulics.fluid.bulk_modulus_Pa=1.2e9"]) == 0
    assert main(["run", "W2", "--duration", "1.5", "--out", str(driven)]) == 0
    doc = json.loads((standing / "metrics.json").read_text())
    assert doc["run"]["overrides"] == {"scenario.track.speed_m_s": 0.0,
                                       "hydraulics.fluid.bulk_modulus_Pa": 1.2e9}
    assert doc["run"]["files"]["hydraulics"] == "packaged"
    # a standing track has no chordal (link-passing) ripple: the tension is far calmer
    ripple = {name: np.std(read_result(out).columns()["tension_N"][-500:])
              for name, out in (("standing", standing), ("driven", driven))}
    assert ripple["standing"] < 0.2 * ripple["driven"], ripple
    capsys.readouterr()
    assert main(["run", "W2", "--duration", "1.5", "--out", str(tmp_path / "bad"),
                 "--set", "hydraulics.fluid.bulk_modulus_Paa=1.2e9"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'bulk_modulus_Pa'" in err and not (tmp_path / "bad").exists()


def test_reversing_pulls_in_the_upper_strand_by_the_drive_torque() -> None:
    """LF1352 backing up at 1.5 m/s against an 8 kN push (tests/data/reverse_push.toml):
    the rear sprocket drives backwards (T < 0) with the push's traction, T/r ≈ −8 kN, and
    pulls in the upper strand: lower − upper run tension = T/r (the belt drive's
    T₁ − T₂ = T/r; measured 93 %, the rest the slack side's share the spans' stretch
    unloads), the idler on the tight side; the loop keeps its band."""
    from pathlib import Path

    from trackmj.machines import assembly as machines

    radius = machines.mechanics(machines.resolve("lf1352")).sprocket_pitch_radius_m
    result = simulate(Path(__file__).parent / "data" / "reverse_push.toml", channels="all")
    cols, m = result.columns(), result.metrics
    held = cols["t_s"] > 1.8                      # the push on since 1.2 s
    torque = cols["drive_torque_N_m"][held].mean()
    assert torque / radius == pytest.approx(-8e3, rel=0.1)
    split = (cols["lower_strand_tension_N"] - cols["upper_strand_tension_N"])[held].mean()
    assert split == pytest.approx(torque / radius, rel=0.15)
    assert m["mujoco_warnings"] == 0
    assert 10e3 <= m["acceptance"]["mean_min_N"] <= m["acceptance"]["mean_max_N"] <= 20e3
    # the run says it reversed: its record and its figure's title
    from trackmj.results.figure_run import run_title
    from trackmj.results.store import running_of

    running = running_of(result)
    assert running is not None and running["speed_m_s"] == -1.5 and running["grade"] == 0.0
    assert running["travel_m"][0] < -3.0 and running["travel_m"][1] == 0.0
    assert run_title(result).endswith("seed 0, reversing at 1.5 m/s")


def test_a_grade_loads_the_drive_by_the_weights_downhill_share() -> None:
    """LF1352 at 1 m/s up and down a 1 in 5 grade (tests/data/climb.toml): the drive
    torque's difference between the two is the weight's component along the slope twice,
    (T_up − T_down)/(2r) = m·g·sin θ, θ = atan 0.2 (the rolling resistance cancels; measured
    −2.1 %); down the slope the rear sprocket brakes (T < 0) and pulls in the upper strand."""
    import math
    from pathlib import Path

    import mujoco

    from trackmj.results.figure_run import run_title
    from trackmj.sim.setup import prepare

    climb = Path(__file__).parent / "data" / "climb.toml"
    setup = prepare(climb)
    model = mujoco.MjModel.from_xml_string(setup.track_mjcf())
    g = float(np.linalg.norm(model.opt.gravity))
    assert model.opt.gravity[0] == pytest.approx(-g * math.sin(math.atan(0.2)))
    downhill_N = float(model.body_subtreemass[0]) * g * math.sin(math.atan(0.2))
    radius = setup.model.sprocket_pitch_radius_m
    torques, splits = [], []
    for grade in (0.2, -0.2):
        result = simulate(climb, set={"scenario.terrain.grade": grade}, channels="all")
        cols = result.columns()
        moving = cols["t_s"] > 1.5
        torques.append(cols["drive_torque_N_m"][moving].mean())
        splits.append((cols["lower_strand_tension_N"]
                       - cols["upper_strand_tension_N"])[moving].mean())
        assert result.metrics["mujoco_warnings"] == 0
        assert f"on a grade of {grade:+g} (tan θ, {'up' if grade > 0 else 'down'}hill " \
               "forward)" in run_title(result)
    assert (torques[0] - torques[1]) / (2.0 * radius) == pytest.approx(downhill_N, rel=0.05)
    assert torques[1] < 0.0 and splits[1] < -0.5 * downhill_N < 0.5 * downhill_N < splits[0]
