"""The command line explains itself: version, scenarios, keys, named option errors, help
with defaults and choices, view's exit code, model info; a controller registered in
:mod:`trackmj.sim.controllers` is offered with no other edit; help and argument errors start
without the heavy modules."""

from __future__ import annotations

import math
import re
import subprocess
import sys

import pytest
from synthetic import synthetic_result

import trackmj
from trackmj.cli.main import main
from trackmj.cli.parser import build_parser
from trackmj.cli.summary import summary_table
from trackmj.scenarios.load import builtin_names, load_scenario
from trackmj.sim import controllers
from trackmj.sim.entries import Entry


def test_version_and_python_dash_m() -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    out = subprocess.run([sys.executable, "-m", "trackmj", "--version"], capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == f"trackmj {trackmj.__version__}"


def test_scenarios_lists_each_builtin_on_one_line(capsys) -> None:
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name in builtin_names():
        (line,) = [ln for ln in lines if ln.startswith(name + " ")]
        assert load_scenario(name).title in line
    listed = " ".join(lines).replace(",", " ").split()      # W5's variants, for --variant
    assert all(v.name in listed for v in load_scenario("W5").variants)


def test_unknown_scenario_answers_with_the_names_that_exist(capsys) -> None:
    assert main(["run", "W9", "--duration", "1.2"]) == 2
    err = capsys.readouterr().err
    assert "W9" in err and "W1, W2, W3, W4, W5" in err and "Traceback" not in err


@pytest.mark.parametrize(("argv", "option"), [
    (["run", "W1", "--seed", "-1"], "--seed"),
    (["run", "W1", "--duration", "0"], "--duration"),
    (["compare", "W1", "--workers", "0"], "--workers"),
    (["run", "W1", "--arch", "tq"], "--arch"),
])
def test_bad_option_values_name_the_option(capsys, argv, option) -> None:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert f"argument {option}" in capsys.readouterr().err


def test_help_shows_defaults_and_choices(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["run", "-h"])
    text = " ".join(capsys.readouterr().out.split())
    assert "{tp,tp-weak,dp-a,dp-b}" in text
    assert "nmpc, lmpc, pid, or fmu:FILE.toml for a controller FMU" in text
    assert "noise and terrain seed (default: 0)" in text
    assert "coupling architecture (default: tp)" in text


def test_keys_lists_the_set_keys_with_units_and_ranges(capsys) -> None:
    assert main(["keys", "hydraulics"]) == 0
    out = capsys.readouterr().out
    assert "hydraulics.fluid.bulk_modulus_Pa: a number, Pa, (0, 1e+11]" in out
    assert main(["keys", "pneumatics"]) == 2
    assert main(["keys", "hydralics"]) == 2
    assert "keys 'hydralics'; did you mean 'hydraulics'? (allowed: model, hydraulics, " in (
        capsys.readouterr().err)


def test_view_without_a_display_fails_with_a_reason(tmp_path, monkeypatch, capsys) -> None:
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"")
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(rrd)]) == 1
    assert "no display" in capsys.readouterr().err


@pytest.mark.parametrize(("viewer", "code"), [("import sys; sys.exit(4)", 1),
                                              ("import time; time.sleep(30)", 0)])
def test_view_exit_code_follows_the_viewer(tmp_path, monkeypatch, viewer, code) -> None:
    """A viewer that dies at start makes ``view`` fail; one that stays up is success."""
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"")
    monkeypatch.setenv("DISPLAY", ":99")
    started = []

    def fake_viewer(path):
        started.append(subprocess.Popen([sys.executable, "-c", viewer]))
        return started[-1]

    monkeypatch.setattr("trackmj.results.playback.open_viewer", fake_viewer)
    monkeypatch.setattr("trackmj.cli.info_commands.VIEWER_START_S", 1.0)
    try:
        assert main(["view", str(rrd)]) == code
    finally:
        started[0].kill()
        started[0].wait()


def test_model_info_columns_are_aligned_and_the_mass_is_explained(capsys) -> None:
    from trackmj.machines.track_plant import load_plant

    assert main(["model", "info"]) == 0
    lines = capsys.readouterr().out.splitlines()
    starts = {len(line) - len(line.lstrip()) if line.startswith(" ") else
              re.match(r"\S+( \S+)*\s{2,}", line).end() for line in lines}
    assert len(starts) == 1, lines
    (mass,) = [ln for ln in lines if ln.startswith("mass ")]
    plant = load_plant()
    assert f"{plant.model.body_mass.sum():.0f} kg: one track side" in mass
    (drive,) = [ln for ln in lines if ln.startswith("drive ")]
    brake = plant.params.parking_brake
    assert brake is not None
    assert f"parking brake holds {brake.holding_torque_N_m / 1e3:g} kN·m" in drive


def test_a_registered_controller_is_offered_with_no_other_edit(monkeypatch, capsys) -> None:
    """One more entry in CONTROLLERS: ``run --controller`` accepts it (the run goes on to
    the next check, the duration), help and ``compare --controllers`` name it, and as a
    baseline it joins ``report --baselines``' default."""
    assert main(["run", "W1", "--controller", "bang", "--duration", "0.1"]) == 2
    assert "controller = 'bang'" in capsys.readouterr().err
    monkeypatch.setitem(controllers.CONTROLLERS, "bang", Entry(
        "bang-bang on the tension error", lambda model, cfg: None, baseline=True))
    assert main(["run", "W1", "--controller", "bang", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "controller" not in err and "ends before the evaluation starts" in err
    for command in (["run", "-h"], ["compare", "-h"]):
        with pytest.raises(SystemExit):
            main(command)
        assert "bang" in capsys.readouterr().out
    assert build_parser().parse_args(["report"]).baselines.split(",")[-1] == "bang"


HEAVY = ("mujoco", "numba", "scipy", "casadi", "matplotlib", "rerun", "dask")
"""Modules whose import takes seconds: ``--help`` and argument errors must not need them."""


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["run", "W1", "--seed", "-1"]])
def test_help_and_argument_errors_import_no_heavy_module(argv) -> None:
    probe = (f"import sys\nfrom trackmj.cli.main import main\ntry:\n    main({argv!r})\n"
             f"except SystemExit:\n    pass\nprint(sorted(set({HEAVY!r}) & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout
    assert out.splitlines()[-1] == "[]"


def test_the_summary_names_the_edges_the_tension_never_came_back_after() -> None:
    """The acceptance's edge recovery (the 0.5 s mean back within ±5 % after each
    disturbance edge) names the edges it did not come back after, in the words of the verdict
    under the table, not a dash."""
    result = synthetic_result("W1", duration_s=2.0)
    assert summary_table([result], "{r.architecture}").splitlines()[-1].startswith(
        "acceptance: holds (the 0.5 s mean ")
    result.metrics["acceptance"] = {**result.metrics["acceptance"], "recovery_max_s": math.nan,
                                    "edge_recovery_s": {"6": math.nan, "8": 1.28,
                                                        "18": 0.0, "20": None}}
    rows = summary_table([result], "{r.architecture}").splitlines()
    # the 6 s edge is judged up to the next one (8 s), the 20 s edge to the run's end: the
    # table's row reads the edges as the verdict under it does
    edges = "not back after the 6 s edge before the next one at 8 s, never after the 20 s edge"
    assert f"| back in the recovery band after an edge [s] | {edges} |" in rows
    assert rows[-1] == f"acceptance: fails (recovery within ±5 % in 2 s: {edges})"
    result.metrics["acceptance"]["edge_recovery_s"] = {}
    rows = summary_table([result], "{r.architecture}").splitlines()
    assert "| back in the recovery band after an edge [s] | – |" in rows


def test_the_summary_says_which_band_each_recovery_row_judges() -> None:
    """NL1's summary showed "recovery time ... not within ±2 %" beside "acceptance: holds"
    (the acceptance asks ±5 % of the 0.5 s mean): each row's label names which band it
    judges (not its width, which a scenario may change; the cell gives it)."""
    result = synthetic_result("NL1", duration_s=20.0)
    result.metrics["recovery_time_lp_s"] = math.nan
    rows = summary_table([result], "{r.architecture}").splitlines()
    assert "| recovery time (settling band), low-pass [s] | not within ±2 % |" in rows
    assert any(row.startswith("| back in the recovery band after an edge [s] |") for row in rows)
