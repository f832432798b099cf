"""`trackmj compare`: every architecture (and controller) on one case, the run contract for
each run, and the prediction error of each architecture against tp."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from synthetic import energy_table, synthetic_result

from trackmj.cli.main import main
from trackmj.results.store import read_result
from trackmj.scenarios.load import load_scenario
from trackmj.sim.registry import ARCHITECTURES
from trackmj.study.compare import CompareRun, check_compare_dir, write_compare


@pytest.mark.slow
def test_quick_compare_writes_runs_prediction_errors_and_figures(tmp_path, capsys) -> None:
    out = tmp_path / "cmp"
    args = ["compare", "W2", "--duration", "1.5", "--workers", "2", "--out", str(out)]
    assert main(args) == 0
    assert f"-> {out / 'compare.json'}" in capsys.readouterr().out
    doc = json.loads((out / "compare.json").read_text())
    names = {f"{a}-nmpc" for a in ARCHITECTURES}
    assert set(doc["runs"]) == names and doc["failed"] == []
    for name in names:
        run = read_result(out / name)                    # the normal run contract
        assert run.metrics.get("mujoco_warnings", 0.0) == 0.0
        assert (out / name / "timeseries.png").stat().st_size > 20_000
        metrics = doc["runs"][name]["metrics"]
        assert metrics["rmse_lp_N"] == pytest.approx(run.metrics["rmse_lp_N"])
        assert "psd" not in metrics and "evaluation" not in metrics
    preds = doc["prediction_vs_tp"]["nmpc"]
    assert preds["tp"]["prediction_rmse_vs_tp_N"] == 0.0
    assert preds["tp"]["prediction_rmse_vs_tp_lp_N"] == 0.0
    tp_rmse = doc["runs"]["tp-nmpc"]["metrics"]["rmse_N"]
    for arch in ARCHITECTURES:
        rmse = doc["runs"][f"{arch}-nmpc"]["metrics"]["rmse_N"]
        # the RMS triangle inequality: two runs only track alike by erring alike
        assert preds[arch]["prediction_rmse_vs_tp_N"] >= abs(rmse - tp_rmse) - 1e-9
    assert set(doc["figures"]) == {"compare-nmpc.png", "psd-nmpc.png"}
    assert "Prediction error against tp (nmpc" in (out / "compare.md").read_text()
    assert check_compare_dir(out) == out                # a previous comparison may be replaced
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert main([*args[:-1], str(other)]) == 2          # refused before anything runs
    assert "holds no trackmj comparison" in capsys.readouterr().err


@pytest.mark.slow
def test_several_controllers_get_their_own_figures(tmp_path) -> None:
    runs = [synthetic_result("W1", a, controller=c, offset_N=k * 100.0, energy=energy_table())
            for c in ("nmpc", "pid") for k, a in enumerate(("tp", "dp-b"))]
    write_compare(CompareRun(runs, [], {}), tmp_path, load_scenario("W1"), 6.0)
    doc = json.loads((tmp_path / "compare.json").read_text())
    assert doc["figures"] == ["compare-nmpc.png", "psd-nmpc.png", "compare-pid.png",
                              "psd-pid.png", "controllers-tp.png", "controllers-dp-b.png"]
    assert doc["runs"]["dp-b-pid"]["metrics"]["energy_J"]["pump"] == pytest.approx(9501.0)


QUICK = ["--set", "scenario.evaluation.start_s=0.02", "--set",
         "scenario.evaluation.steady_start_s=0.03", "--set",
         "scenario.reference.steps.0.time_s=0.03", "--set",
         "scenario.reference.steps.1.time_s=0.04", "--workers", "1"]
"""steps_short.toml's events moved into a 0.05 s comparison."""


@pytest.mark.slow
def test_a_comparison_of_other_inputs_is_refused_unless_overwrite(tmp_path, capsys) -> None:
    """As ``trackmj run`` does: the same inputs resume, other inputs are refused with one
    line naming the folder and --overwrite (the comparison there left as it was), and
    --overwrite replaces it."""
    out = tmp_path / "cmp"
    scenario = Path(__file__).parent / "data" / "steps_short.toml"
    args = ["compare", str(scenario), *QUICK, "--out", str(out)]
    assert main([*args, "--duration", "0.05"]) == 0
    capsys.readouterr()
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main([*args, "--duration", "0.06"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"trackmj: error: --out {out}: holds a comparison of other inputs")
    assert "give --overwrite to replace it" in err and len(err.splitlines()) == 1
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*")
            if p.is_file()} == before
    assert main([*args, "--duration", "0.05"]) == 0          # the same inputs: resumed
    assert json.loads((out / "compare.json").read_text())["duration_s"] == 0.05
    assert main([*args, "--duration", "0.06", "--overwrite"]) == 0
    doc = json.loads((out / "compare.json").read_text())
    assert doc["duration_s"] == 0.06 and set(doc["runs"]) == {f"{a}-nmpc" for a in ARCHITECTURES}
    assert all(read_result(out / name).columns()["t_s"][-1] == pytest.approx(0.06)
               for name in doc["runs"])
