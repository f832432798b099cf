"""A run either stays physical or stops with a clear message and a non-zero exit, and
interrupting or refusing a run never costs an earlier result."""

from __future__ import annotations

import json
import math
import re

import mujoco
import numpy as np
import pytest

from trackmj.cli.main import main
from trackmj.errors import PhysicsError
from trackmj.ports import Command, ControlOutput, Readout
from trackmj.scenarios.load import load_scenario
from trackmj.sim.observers import (
    PhysicsGuard,
    PhysicsLimits,
    capture_mujoco_warnings,
)

LIMITS = PhysicsLimits(vacuum_Pa=-101325.0, stroke_range_m=(-5e-3, 0.105), closure_max_m=5e-3)
HOLD = Command(0, 0.0, ControlOutput(0.0))


def _readout(**changes: float) -> Readout:
    base = Readout(1.234, 15e3, 6e6, 0.2e6, 12e6, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-4,
                   150.0)
    return base._replace(**changes)


@pytest.mark.parametrize(("changes", "message"), [
    ({"tension_N": math.nan}, r"t = 1\.234 s: non-finite state \(tension_N = nan\)"),
    ({"stroke_m": 0.142}, r"stroke 142\.0 mm outside the travel \[-5\.0, 105\.0\] mm"),
    ({"closure_error_m": 0.8}, r"closure gap 800\.0 mm exceeds 5\.0 mm"),
    ({"p_rod_Pa": -0.61e6}, r"rod pressure -0\.610 MPa gauge below vacuum"),
    ({"p_supply_Pa": -3794e6}, r"supply pressure -3794\.000 MPa gauge below vacuum"),
])
def test_guard_names_time_quantity_and_value(changes: dict, message: str) -> None:
    guard = PhysicsGuard(LIMITS, [])
    guard.on_step(0, _readout(), HOLD)   # a physical step passes
    with pytest.raises(PhysicsError, match=message):
        guard.on_step(1, _readout(**changes), HOLD)


def test_guard_checks_every_node_it_is_given() -> None:
    guard = PhysicsGuard(LIMITS, [], lambda: (1e6, 6e6, -0.2e6, 0.2e6, 12e6),
                         ("line A", "head L", "head R", "rod node", "supply"))
    with pytest.raises(PhysicsError, match=r"head R pressure -0\.200 MPa"):
        guard.on_step(0, _readout(), HOLD)   # the readout's mean head pressure hides it


def test_mujoco_warnings_are_captured_not_written_to_the_working_directory(
        tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint type="slide"/><geom size="0.1"/></body>'
        "</worldbody></mujoco>")
    data = mujoco.MjData(model)
    data.qvel[0] = np.nan
    with capture_mujoco_warnings() as warnings:
        mujoco.mj_step(model, data)
        with pytest.raises(PhysicsError, match="MuJoCo warning: Nan, Inf or huge value"):
            PhysicsGuard(LIMITS, warnings).on_step(0, _readout(), HOLD)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def _scenario_file(tmp_path, name: str, edit) -> str:
    text = edit(load_scenario(name).source.read_text())
    path = tmp_path / f"{name}_edited.toml"
    path.write_text(text)
    return str(path)


def test_w3_push_beyond_what_the_tensioner_holds_stops_with_the_reason(tmp_path, monkeypatch,
                                                                      capsys) -> None:
    """A -30 kN push pulse at 2-4 s (beyond LF1352's drawbar capacity) drives the idler in faster
    than the rod chambers can be fed; they fill with air, and the push tears the track loop
    open (closure gap 23 mm at 3.03 s): the run stops with exit 3 naming the time and the
    reason, writes no result and leaves no MuJoCo log in the working directory."""
    monkeypatch.chdir(tmp_path)
    path = _scenario_file(tmp_path, "W3", lambda s: s.replace(
        "start_s = 6.0\nend_s = 8.0", "start_s = 2.0\nend_s = 4.0\nhitch_N = -30000.0"))
    out = tmp_path / "out"
    assert main(["run", path, "--duration", "20.5", "--out", str(out)]) == 3
    err = capsys.readouterr().err
    assert re.search(r"stopped: t = [23]\.\d+ s: track loop closure gap [\d.]+ mm exceeds "
                     r"[\d.]+ mm; the run left physics", err), err
    assert "Traceback" not in err
    assert not out.exists() and not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_a_road_rougher_than_the_track_takes_stops_with_the_reason(tmp_path, capsys) -> None:
    """ISO class H at 5 m/s: the rod chambers fill with air out of solution on the bumps (it
    took them below vacuum before the air was modelled) and the track's loop closure tears
    past 5 mm: exit 3 with the time and the reason. The road is generated for the distance
    the run drives, so its duration picks the road: the 10 s road tears the loop at 1.71 s
    (a 3 s road's bumps, with the integral trim, took 3 s without tearing it)."""
    path = _scenario_file(tmp_path, "W2", lambda s: re.sub(
        r'road_class = "\w"', 'road_class = "H"', re.sub(r"speed_m_s = [0-9.]+",
                                                          "speed_m_s = 5.0", s)))
    assert main(["run", path, "--duration", "10", "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert re.search(r"stopped: t = \d\.\d+ s: track loop closure gap [\d.]+ mm exceeds "
                     r"[\d.]+ mm; the run left physics", err), err


@pytest.mark.slow
def test_ctrl_c_ends_with_one_line_and_keeps_the_previous_result(tmp_path, monkeypatch,
                                                                capsys) -> None:
    out = tmp_path / "w1"
    assert main(["run", "W2", "--duration", "1.2", "--out", str(out)]) == 0
    before = json.loads((out / "metrics.json").read_text())
    capsys.readouterr()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("trackmj.sim.run.run", interrupted)
    assert main(["run", "W2", "--duration", "1.2", "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "interrupted" in err and "Traceback" not in err
    assert json.loads((out / "metrics.json").read_text()) == before
    assert [p.name for p in tmp_path.iterdir()] == ["w1"]


def test_out_that_is_a_file_is_refused_before_the_run(tmp_path, capsys, monkeypatch) -> None:
    target = tmp_path / "results.txt"
    target.write_text("keep me")

    def must_not_run(*args, **kwargs):
        raise AssertionError("the simulation started")

    monkeypatch.setattr("trackmj.sim.run.run", must_not_run)
    assert main(["run", "W2", "--duration", "1.5", "--out", str(target)]) == 2
    assert "is a file" in capsys.readouterr().err
    assert target.read_text() == "keep me"


def test_a_judged_band_the_controller_does_not_enforce_is_refused() -> None:
    """The scenario's [limits] (what the metrics judge) and the control file's [controller]
    band (what the controllers enforce) are one F_min/F_max: a mismatch is refused before
    anything is built, naming both; changed together they run."""
    from trackmj.sim.setup import prepare
    from trackmj.validator import ParameterError

    with pytest.raises(ParameterError, match=r"W1\.toml \[limits\] force_min_N, force_max_N = "
                       r"10000, 18000 N but the control file \(packaged\) \[controller\] has "
                       r"10000, 20000 N"):
        prepare("W1", overrides={"scenario.limits.force_max_N": 18e3})
    setup = prepare("W1", overrides={"scenario.limits.force_max_N": 18e3,
                                     "control.controller.force_max_N": 18e3})
    assert setup.control.controller.force_max_N == 18e3
