"""Parameter studies: the spec through the validator, grid and LHS points, and sweeps on a
2-worker Dask LocalCluster (rows as runs finish, resume, failed runs as rows, figures)."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from trackmj.cli.main import main
from trackmj.study.campaign import flatten_metrics, write_table
from trackmj.study.executor import Executor
from trackmj.study.sweep import (
    load_sweep,
    parameter_points,
    plan,
    read_sweep,
    sweep,
)
from trackmj.validator import ParameterError

DURATION_S = 1.5
SPEED = "scenario.track.speed_m_s"
BULK = "hydraulics.fluid.bulk_modulus_Pa"


def _spec(**table) -> dict:
    return {"sweep": {"scenario": "W1", "duration_s": DURATION_S} | table}


# ----------------------------------------------------------------------------- points

def test_grid_is_every_combination_first_key_slowest() -> None:
    spec = load_sweep(_spec(parameters=[
        {"key": SPEED, "values": [0.5, 1.0]},
        {"key": BULK, "low": 1e9, "high": 4e9, "count": 3, "scale": "log"}]))
    points = parameter_points(spec)
    assert [p[SPEED] for p in points] == [0.5] * 3 + [1.0] * 3
    np.testing.assert_allclose([p[BULK] for p in points[:3]], [1e9, 2e9, 4e9], rtol=1e-12)


def test_latin_hypercube_puts_one_sample_in_each_stratum_of_each_key() -> None:
    n = 8
    table = {"method": "lhs", "samples": n, "seed": 3, "parameters": [
        {"key": SPEED, "low": 0.0, "high": 2.0},
        {"key": BULK, "low": 1e9, "high": 1e10, "scale": "log"}]}
    points = parameter_points(load_sweep(_spec(**table)))
    assert len(points) == n
    speed = np.array([p[SPEED] for p in points])
    log_bulk = np.log10([p[BULK] for p in points])
    assert sorted(np.floor(speed / 2.0 * n).astype(int)) == list(range(n))
    assert sorted(np.floor((log_bulk - 9.0) * n).astype(int)) == list(range(n))
    assert points == parameter_points(load_sweep(_spec(**table)))        # same seed
    other = parameter_points(load_sweep(_spec(**table | {"seed": 4})))
    assert [p[SPEED] for p in other] != list(speed)


def test_the_readme_spec_is_valid_and_plans_every_combination(tmp_path) -> None:
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    block = readme.split("## Parameter studies", 1)[1].split("```toml\n", 1)[1]
    spec = tmp_path / "study.toml"
    spec.write_text(block.split("```", 1)[0])
    runs = plan(load_sweep(spec))
    # 3 areas x 3 bulk moduli x 2 controllers x 2 seeds, each a distinct run
    assert len(runs) == len({r.key for r in runs}) == 36
    assert {r.row["controller"] for r in runs} == {"nmpc", "pid"}


def test_integer_keys_take_integers() -> None:
    key = "control.mpc.horizon_steps"
    points = parameter_points(load_sweep(_spec(parameters=[{"key": key, "values": [10, 20]}])))
    assert [p[key] for p in points] == [10, 20] and all(type(p[key]) is int for p in points)
    with pytest.raises(ParameterError, match=r"value 10.5 is not an integer"):
        parameter_points(load_sweep(_spec(parameters=[{"key": key, "values": [10.5]}])))


@pytest.mark.parametrize(("table", "message"), [
    ({"parameters": [{"key": "hydraulics.fluid.bulk_modulus_Paa", "values": [1e9]}]},
     r"point 0 .*did you mean 'bulk_modulus_Pa'"),
    ({"parameters": [{"key": BULK, "values": [1e9, 2e11]}]},
     r"point 1 \(hydraulics.fluid.bulk_modulus_Pa = 2e\+11\) is invalid: .* is outside the "
     r"allowed range \(0, 1e\+11\] Pa"),
    ({"parameters": [{"key": BULK, "values": [1e9], "low": 1e9}]},
     r"values = \[1000000000.0\] excludes low, high and count"),
    ({"method": "lhs", "parameters": [{"key": BULK, "low": 1e9, "high": 2e9}]},
     r"method = 'lhs' needs samples"),
    ({"parameters": [{"key": "fluid.bulk_modulus_Pa", "values": [1e9]}]},
     r"key = 'fluid.bulk_modulus_Pa' must match"),
    ({"set": [f"{BULK}=1e9"], "parameters": [{"key": BULK, "values": [2e9]}]},
     r"is also fixed in \[sweep\].set"),
    ({"controllers": ["nmpc", "mpcc"]}, r"controllers\[1\] = 'mpcc' is not one of"),
])
def test_spec_mistakes_are_named_before_any_run(tmp_path, table, message) -> None:
    path = tmp_path / "study.toml"
    lines = ["[sweep]", 'scenario = "W1"', f"duration_s = {DURATION_S}"]
    for key, value in table.items():
        if key != "parameters":
            lines.append(f"{key} = {json.dumps(value)}")
    for p in table.get("parameters", []):
        lines += ["[[sweep.parameters]]"] + [f"{k} = {json.dumps(v)}" for k, v in p.items()]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ParameterError, match=message) as info:
        plan(load_sweep(path))
    assert "study.toml" in str(info.value)


def test_trackmj_sweep_is_the_function() -> None:
    import trackmj
    import trackmj.study.sweep

    assert trackmj.sweep is trackmj.study.sweep.sweep and trackmj.read_sweep is read_sweep


def test_nested_metric_tables_become_dotted_columns() -> None:
    flat = flatten_metrics({"rmse_N": 412.0, "energy_J": {"pump": 80.0, "losses": {
        "relief": 2.0, "orifices": np.float64(3.0)}}, "note": "text", "ok": True})
    assert flat == {"rmse_N": 412.0, "energy_J.pump": 80.0, "energy_J.losses.relief": 2.0,
                    "energy_J.losses.orifices": 3.0, "ok": 1.0}


def test_scattered_samples_are_plotted_per_metric(tmp_path, monkeypatch) -> None:
    """Rows of an LHS sweep (no two points share the other key's value), one failed: a
    figure per metric that varies across the runs that ran (not the constant wall time, not
    the metric that is NaN everywhere), the failed row left out; labels in plain words."""
    from trackmj.study.sweep import plot_sweep

    rows = [{"run_key": f"k{i}", "point": i, "scenario": "W1", "architecture": "tp",
             "controller": "nmpc", "estimator": "ekf", "variant": "nominal", "seed": 0,
             "duration_s": 1.5, "inputs": "{}", SPEED: 0.5 + 0.25 * i, BULK: 1e9 * (1 + i),
             "rmse_N": 100.0 * i, "only_nan_N": math.nan, "wall_time_s": 1.0, "error": None,
             "energy_J.friction": 3.0 * i, "friction_loss_J": 3.0 * i}
            for i in range(5)]
    rows[4] |= {"rmse_N": None, "error": "PhysicsError: ..."}
    write_table(rows, tmp_path / "results.parquet")
    import trackmj.results.figure_sweep as figures_module

    drawn = []
    original = figures_module._metric_figure
    monkeypatch.setattr(figures_module, "_metric_figure",
                        lambda *args: drawn.append(original(*args)) or drawn[-1])
    figures = plot_sweep(tmp_path)      # a metric stored twice is drawn once
    assert sorted(p.name for p in figures) == ["friction_loss_J.png", "rmse_N.png"]
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in figures)
    assert "the same values: energy_J.friction" in drawn[0].texts[-1].get_text()
    ax = drawn[1].axes[0]
    assert ax.get_ylabel() == "tension RMSE, raw [kN]"
    assert ax.get_xlabel() == "fluid bulk modulus [MPa]"
    plot_sweep(tmp_path, redraw=False)      # what exists is not drawn again
    assert len(drawn) == 2


def test_a_sweep_without_swept_keys_gets_bars_per_scenario_and_case(tmp_path,
                                                                    monkeypatch) -> None:
    """A controller comparison (no swept key): a figure per metric with a group of bars per
    scenario and a bar per controller at the mean over seeds."""
    from trackmj.study.sweep import plot_sweep

    rows = [{"run_key": f"{sc}{c}{seed}", "point": 0, "scenario": sc, "architecture": "tp",
             "controller": c, "estimator": "ekf", "variant": "nominal", "seed": seed,
             "duration_s": 1.5, "inputs": "{}", "rmse_N": 100.0 * k + seed,
             "wall_time_s": 1.0 + seed, "error": None}
            for sc in ("NL1", "W1") for k, c in enumerate(("nmpc", "pid")) for seed in (0, 2)]
    write_table(rows, tmp_path / "results.parquet")
    import trackmj.results.figure_sweep as figures

    captured, original = [], figures._case_figure
    monkeypatch.setattr(figures, "_case_figure",
                        lambda *args: captured.append(original(*args)) or captured[-1])
    figures = plot_sweep(tmp_path)
    assert sorted(p.name for p in figures) == ["rmse_N.png", "wall_time_s.png"]
    ax = captured[0].axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["W1", "NL1"]   # built-in order
    assert ax.get_legend_handles_labels()[1] == ["nmpc", "pid"]
    heights = sorted(round(p.get_height(), 9) for p in ax.patches)
    assert heights == [1e-3, 1e-3, 0.101, 0.101]          # kN: means over seeds 0 and 2


def test_results_are_rewritten_at_most_every_period_and_flushed(tmp_path, monkeypatch) -> None:
    """Rewriting grows with the rows, so it is throttled; what arrived is always flushed."""
    import trackmj.study.campaign as campaign

    writes = []
    monkeypatch.setattr(campaign, "write_table", lambda rows, path: writes.append(len(rows)))
    writer = campaign.TableWriter(tmp_path / "results.parquet")
    rows = {}
    for i in range(5):
        rows[f"k{i}"] = {"run_key": f"k{i}"}
        writer.changed(rows)
    assert writes == [1]              # the first row at once, the next within the period
    writer.flush(rows)
    writer.flush(rows)
    assert writes == [1, 5]           # pending rows once, nothing when nothing is new


# ----------------------------------------------------------------------------- on Dask

@pytest.fixture(scope="module")
def executor():
    with Executor(workers=2) as ex:
        yield ex


@pytest.fixture(scope="module")
def grid(executor, tmp_path_factory):
    """2 x 2 grid of 1.5 s W1 runs: standing / driven track x soft / stiff oil; the step
    and ramp, moved inside the short runs, are of zero size (a constant reference)."""
    out = tmp_path_factory.mktemp("grid")
    spec = _spec(parameters=[{"key": SPEED, "values": [0.0, 1.5]},
                             {"key": BULK, "values": [0.8e9, 1.6e9]}],
                 set=["scenario.reference.steps.0.delta_N=0",
                      "scenario.reference.ramps.0.rate_N_s=0"])
    summary = sweep(spec, out, executor=executor, progress=False)
    return out, spec, summary


def test_workers_start_warm_with_one_thread(executor) -> None:
    """Both workers were forked from one warmed forkserver (same warm-up record) and run
    with single-threaded pools."""
    def probe():
        import numba

        import trackmj.study.worker
        return (trackmj.study.worker.warm_time_s, os.environ.get("OMP_NUM_THREADS"),
                numba.config.NUMBA_NUM_THREADS)

    reports = list(executor.client.run(probe).values())
    assert len(reports) == 2 and reports[0] == reports[1]
    assert reports[0][0] > 0.0 and reports[0][1:] == ("1", 1)


@pytest.mark.slow
def test_grid_writes_one_row_per_run_with_its_parameters_and_metrics(grid) -> None:
    out, _, summary = grid
    assert (summary.runs, summary.ran, summary.skipped, summary.failed) == (4, 4, 0, 0)
    df = read_sweep(out)
    assert len(df) == 4 and df["error"].isna().all()
    assert sorted(zip(df[SPEED], df[BULK], strict=True)) == [
        (0.0, 0.8e9), (0.0, 1.6e9), (1.5, 0.8e9), (1.5, 1.6e9)]
    assert df["rmse_N"].nunique() == 4 and (df["wall_time_s"] > 0).all()
    assert (df["duration_s"] == DURATION_S).all() and (df["mujoco_warnings"] == 0).all()
    assert df.attrs["units"][BULK] == "Pa" and df.attrs["units"]["rmse_N"] == "N"
    # physics: a standing track has no chordal ripple, so it tracks far better
    for bulk in (0.8e9, 1.6e9):
        rmse = {v: df.loc[(df[SPEED] == v) & (df[BULK] == bulk), "rmse_N"].item()
                for v in (0.0, 1.5)}
        assert rmse[0.0] < 0.5 * rmse[1.5], rmse


def test_resume_skips_the_rows_already_written(grid, executor) -> None:
    out, spec, _ = grid
    before = (out / "results.parquet").read_bytes()
    summary = sweep(spec, out, executor=executor, progress=False, plot=False)
    assert (summary.ran, summary.skipped) == (0, 4)
    assert (out / "results.parquet").read_bytes() == before


@pytest.mark.slow
def test_figures_per_metric_and_redraw(grid, executor) -> None:
    out, spec, summary = grid
    names = {p.name for p in summary.figures}
    assert {"rmse_N.png", "energy_J.pump.png", "wall_time_s.png"} <= names
    assert "fluctuation_N.png" not in names   # NaN in a 1.5 s run (steady window from 5 s)
    assert not names & {"mujoco_warnings.png", "evaluation.psd_max_Hz.png"}   # constants
    for path in summary.figures:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (out / "figures" / "rmse_N.png").unlink()
    assert main(["sweep", "--plot", str(out)]) == 0
    assert (out / "figures" / "rmse_N.png").is_file()
    assert len(list((out / "figures").glob("*.png"))) == len(summary.figures)
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "figures").glob("*.png")}
    again = sweep(spec, out, executor=executor, progress=False)   # resumes: nothing to run
    assert again.ran == 0 and len(again.figures) == len(summary.figures)
    assert {p.name: p.stat().st_mtime_ns for p in (out / "figures").glob("*.png")} == stamps


def test_a_failing_run_becomes_an_error_row(executor, tmp_path) -> None:
    """A -30 kN push on the rear hitch (the file's limit) pulls the rods below vacuum within
    0.2 s: that run is a row with its error; the calibrated push beside it runs through."""
    spec = {"sweep": {"scenario": "W3", "duration_s": DURATION_S, "set": [
        "scenario.load_pulses.0.start_s=0.5", "scenario.load_pulses.0.end_s=1.4"],
        "parameters": [{"key": "scenario.load_pulses.0.hitch_N",
                        "values": [-3755.0, -30000.0]}]}}
    summary = sweep(spec, tmp_path, executor=executor, progress=False, plot=False,
                    keep_runs=True)
    assert (summary.ran, summary.failed) == (2, 1)
    df = read_sweep(tmp_path).set_index("scenario.load_pulses.0.hitch_N")
    assert math.isnan(df.loc[-30000.0, "rmse_N"]) and df.loc[-30000.0, "wall_time_s"] > 0
    assert df.loc[-30000.0, "error"].startswith("PhysicsError: t = ")
    assert "below vacuum" in df.loc[-30000.0, "error"]
    assert df["error"].isna().sum() == 1 and df.loc[-3755.0, "rmse_N"] > 0
    (kept,) = [p for p in (tmp_path / "runs").iterdir() if p.is_dir()]   # the run that ran
    assert json.loads((kept / "metrics.json").read_text())["run"]["scenario"] == "W3"
    again = sweep(spec, tmp_path, executor=executor, progress=False, plot=False)
    assert (again.ran, again.skipped) == (0, 2)


def test_cli_sweep_refuses_a_bad_spec_naming_it(tmp_path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[sweep]\nscenario = "W1"\nmethod = "sobol"\n')
    assert main(["sweep", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml [sweep].method = 'sobol' is not one of ['grid', 'lhs']" in err
    assert not (tmp_path / "out").exists()
    assert main(["sweep"]) == 2
    assert "sweep needs a spec file" in capsys.readouterr().err


@pytest.mark.slow
def test_a_run_that_kills_its_worker_is_an_outcome_with_the_error(executor, monkeypatch):
    """A run that takes its worker process down (here: os._exit, as a segfault would) is
    retried on restarted workers by Dask and then reported as failed; the batch goes on."""
    from trackmj.study.executor import RunSpec

    submit = executor.client.submit

    def dying_for_seed_99(fn, spec, *args, **kwargs):
        if spec.seed == 99:
            def die(*_):
                os._exit(3)
            return submit(die, spec, *args, **kwargs)
        return submit(fn, spec, *args, **kwargs)

    monkeypatch.setattr(executor.client, "submit", dying_for_seed_99)
    fine, dying = RunSpec("W1", duration=DURATION_S, seed=0), RunSpec("W1", seed=99)
    outcomes = executor.map([fine, dying])
    assert outcomes[0].ok and outcomes[0].result.seed == 0
    assert outcomes[1].error.startswith("KilledWorker")
