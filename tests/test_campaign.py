"""The campaign layer: one identity rule for "already done" (inputs and source), the store
(lock, kind, rows readable by pandas and polars), events moved or refused, and the run
folder that never replaces a result of other inputs."""

from __future__ import annotations

import json
import math
import re

import pytest
from synthetic import energy_table, synthetic_result

import trackmj.results.seed_stats as seed_stats
import trackmj.study.campaign as campaign
import trackmj.study.identity as identity
from trackmj.cli.main import main
from trackmj.results.store import ResultDirectoryError
from trackmj.scenarios.events import check_duration, cut_events, moved_events
from trackmj.scenarios.load import load_scenario
from trackmj.study.executor import RunOutcome, RunSpec
from trackmj.validator import ParameterError


class _SyntheticExecutor:
    """Stands in for the Dask executor: each run is a synthetic result of its scenario and
    architecture (a known signal, real metrics); records which specs it was asked to run."""

    def __init__(self) -> None:
        self.ran: list[RunSpec] = []

    def as_completed(self, specs, progress=None):
        for spec in specs:
            self.ran.append(spec)
            result = synthetic_result(spec.scenario, spec.architecture, seed=spec.seed,
                                      duration_s=2.0, energy=energy_table())
            yield RunOutcome(spec, result=result, wall_time_s=0.01)


def _runs(seeds=(0, 1)):
    return [campaign.plan_run(RunSpec(scenario="W2", duration=2.0, seed=s)) for s in seeds]


def test_resume_skips_done_runs_and_reruns_after_a_source_change(tmp_path, monkeypatch):
    ex = _SyntheticExecutor()
    with campaign.Store(tmp_path, "sweep") as store:
        made = campaign.run_campaign(store, _runs(), executor=ex)
    assert (len(made.outcomes), made.resumed, len(ex.ran)) == (2, 0, 2)
    with campaign.Store(tmp_path, "sweep") as store:        # same inputs, same code: skipped
        made = campaign.run_campaign(store, _runs(), executor=ex)
    assert (len(made.outcomes), made.resumed, len(ex.ran)) == (2 - 2, 2, 2)
    before = {r.key for r in _runs()}
    monkeypatch.setattr(identity, "source_hash", lambda: "edited source")
    runs = _runs()
    assert not before & {r.key for r in runs}
    with campaign.Store(tmp_path, "sweep") as store:        # the code changed: made again
        made = campaign.run_campaign(store, runs, executor=ex)
    assert (len(made.outcomes), made.resumed, len(ex.ran)) == (2, 0, 4)
    assert len(campaign.read_rows(tmp_path / campaign.RESULTS)) == 4   # old rows kept


def test_identity_changes_with_each_input_and_not_otherwise():
    base = RunSpec(scenario="W2", duration=2.0)
    key = campaign.plan_run(base).key
    assert campaign.plan_run(RunSpec(scenario="W2", duration=2.0)).key == key
    others = [RunSpec(scenario="W2", duration=2.5), RunSpec(scenario="W2", duration=2.0, seed=1),
              RunSpec(scenario="W2", duration=2.0, estimator="ukf"),
              RunSpec(scenario="W2", duration=2.0, architecture="dp-b"),
              RunSpec(scenario="W2", duration=2.0,
                      overrides=(("hydraulics.fluid.bulk_modulus_Pa", 1.2e9),))]
    keys = {campaign.plan_run(s).key for s in others}
    assert len(keys) == len(others) and key not in keys


def test_a_second_campaign_into_the_same_directory_is_refused(tmp_path):
    with campaign.Store(tmp_path, "sweep"):
        with pytest.raises(ResultDirectoryError, match="another trackmj campaign is writing"):
            campaign.Store(tmp_path, "sweep").__enter__()
    with pytest.raises(ResultDirectoryError, match="holds a trackmj sweep"):
        campaign.Store(tmp_path, "report").__enter__()
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    with pytest.raises(ResultDirectoryError, match="holds no trackmj report"):
        campaign.Store(tmp_path / "mine", "report")


def test_failed_runs_are_error_rows_with_units_readable_by_pandas_and_polars(tmp_path):
    import pandas
    import polars

    class Failing(_SyntheticExecutor):
        def as_completed(self, specs, progress=None):
            for outcome in super().as_completed(specs):
                if outcome.spec.seed == 1:
                    outcome = RunOutcome(outcome.spec, error="PhysicsError: t = 1 s: ...",
                                         wall_time_s=0.5)
                yield outcome

    with campaign.Store(tmp_path, "sweep") as store:
        made = campaign.run_campaign(store, _runs(), executor=Failing())
    assert len(made.failed) == 1
    path = tmp_path / campaign.RESULTS
    df = pandas.read_parquet(path).set_index("seed")
    assert df.loc[1, "error"].startswith("PhysicsError") and math.isnan(df.loc[1, "rmse_N"])
    assert df.loc[0, "rmse_N"] > 0 and pandas.isna(df.loc[0, "error"])
    pl = polars.read_parquet(path)
    assert pl.shape == df.reset_index().shape and pl["rmse_N"].null_count() == 1
    import pyarrow.parquet as pq

    units = json.loads(pq.read_schema(path).metadata[b"units"])   # for readers without
    assert units["rmse_N"] == "N" and units["duration_s"] == "s"   # field metadata
    assert campaign.read_units(path)["energy_J.pump"] == "J"
    # a failed run is retried only when asked
    with campaign.Store(tmp_path, "sweep") as store:
        again = campaign.run_campaign(store, _runs(), executor=_SyntheticExecutor())
        assert again.resumed == 2
        retried = campaign.run_campaign(store, _runs(), executor=_SyntheticExecutor(),
                                        retry_failed=True)
    assert (retried.resumed, len(retried.outcomes)) == (1, 1)


def test_statistics_filter_non_finite_values():
    assert seed_stats.mean_std([1.0, 3.0, math.nan, None]) == (2.0, 1.0, 2)
    assert seed_stats.mean_std([math.nan]) == (pytest.approx(math.nan, nan_ok=True), 0.0, 0)


# ----------------------------------------------------------------------------- events

def test_a_duration_that_cuts_an_event_is_refused_naming_it(tmp_path, capsys):
    assert main(["run", "W4", "--duration", "8", "--out", str(tmp_path / "w4")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "--duration 8 s cuts off W4.toml [[supply.drops]][0] (supply drop 12-20 s)" in err
    assert err.rstrip().endswith("a run is judged on its scenario's events (calibrate, "
                                 "replaying logged valve commands, needs none)")
    assert not (tmp_path / "w4").exists()
    with pytest.raises(ParameterError, match=r"\[\[reference.steps\]\]\[0\] \(reference step "
                                             r"at 3 s\)"):
        check_duration(load_scenario("W1"), 2.0)
    check_duration(load_scenario("W4"), 20.5)      # the drop's edge back is over at 20.1 s
    # two pulses cut off: the duration offered holds the later one too (18-20 s, 0.1 s edge)
    with pytest.raises(ParameterError, match=r"\[\[load_pulses\]\]\[0\] \(load pulse 6-8 s\) "
                                             r"\(and 1 more, the last \[\[load_pulses\]\]\[1\] "
                                             r"\(load pulse 18-20 s\)\): they need the run to "
                                             r"last 20.1 or more s; give --duration 20.1 or more"):
        check_duration(load_scenario("W3"), 2.0)


@pytest.mark.parametrize(("name", "duration_s"), [("W1", 4.0), ("W3", 10.0), ("W4", 15.0),
                                              ("NL1", 10.0)])
def test_the_moves_a_refusal_offers_fit_the_events_into_the_run(name, duration_s):
    """A newcomer who copies the --set items of the refusal gets a run that holds every
    event: the schedule compressed as report and sweep compress it. NL1's supply drop runs
    to the scenario's end (0-30 s, 0.1 s edge back): it stays a drop to the end, where
    moving its end to the run's end asked for 0.1 s more than the run."""
    with pytest.raises(ParameterError) as info:
        check_duration(load_scenario(name), duration_s)
    offered = re.findall(r"--set scenario\.(\S+)=([0-9.]+)", str(info.value))
    assert offered
    moved = load_scenario(name, {key: float(value) for key, value in offered})
    check_duration(moved, duration_s)
    check_duration(load_scenario("W3"), 20.1)


def test_moved_events_keep_their_order_inside_the_run():
    """W3's two load pulses in an 8 s run: the schedule after the evaluation start (1 s) is
    compressed by (8 − 1)/(30 − 1); the moved scenario passes the file's own checks and
    its metric windows lie inside the run."""
    sc = load_scenario("W3")
    moves = moved_events(sc, 8.0)
    k = 7.0 / 29.0
    assert moves["load_pulses.0.start_s"] == pytest.approx(1.0 + 5.0 * k, abs=5e-4)
    assert moves["load_pulses.1.end_s"] == pytest.approx(1.0 + 19.0 * k, abs=5e-4)
    moved = load_scenario("W3", overrides=moves)
    assert not cut_events(moved, 8.0)
    windows = moved.metric_windows(8.0).disturbances
    assert len(windows) == 2 and all(0.0 < on < off < 8.0 for on, off in windows)
    assert moved_events(sc, 30.0) == {} and moved_events(load_scenario("W2"), 2.0) == {}


# ----------------------------------------------------------------------------- real runs

@pytest.mark.slow
def test_report_and_sweep_give_identical_numbers_for_the_same_runs(tmp_path):
    """The same W1 tp run (1.5 s, its step and ramp moved inside) planned by the report and
    by a sweep: one identity, and the same numbers in both results.parquet files."""
    from trackmj.study import report
    from trackmj.study.executor import Executor
    from trackmj.study.sweep import sweep

    runs = report.plan(["W1"], [0], 1.5, archs=["tp"], baselines=())
    spec = {"sweep": {"scenario": "W1", "duration_s": 1.5}}
    with Executor(workers=1) as ex:
        report.run_matrix(runs, tmp_path / "report", progress=False, executor=ex)
        summary = sweep(spec, tmp_path / "sweep", executor=ex, progress=False, plot=False)
    assert summary.ran == 1
    (a,) = campaign.read_rows(tmp_path / "report" / campaign.RESULTS)
    (b,) = campaign.read_rows(tmp_path / "sweep" / campaign.RESULTS)
    assert a["run_key"] == b["run_key"] == runs[0].key
    timing = ("wall_time_s", "real_time_factor", "solve_time",   # this machine's clock
              "controller_overruns")
    numbers = [k for k, v in a.items() if isinstance(v, float) and not k.startswith(timing)
               and "time_factor" not in k]
    assert len(numbers) > 50 and a["rmse_N"] > 0
    differ = [k for k in numbers
              if not (a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])))]
    assert differ == []


@pytest.mark.slow
def test_two_runs_with_different_set_keep_both_results(tmp_path, monkeypatch, capsys):
    """trackmj run never replaces a result of other inputs: a run with --set gets its own
    default folder; the same inputs again replace theirs; --out onto another run's folder
    needs --overwrite."""
    monkeypatch.chdir(tmp_path)
    base = ["run", "W2", "--duration", "1.2"]
    soft = [*base, "--set", "hydraulics.fluid.bulk_modulus_Pa=1.2e9"]
    assert main(base) == 0 and main(soft) == 0
    folders = sorted(p for p in (tmp_path / "runs").iterdir() if not p.name.startswith("."))
    assert len(folders) == 2 and all(f.name.startswith("W2-tp-nmpc-s0-") for f in folders)
    docs = [json.loads((f / "metrics.json").read_text()) for f in folders]
    assert {d["run"]["overrides"].get("hydraulics.fluid.bulk_modulus_Pa") for d in docs} \
        == {None, 1.2e9}
    assert docs[0]["run"]["seed"] == 0 and docs[0]["run"]["duration_s"] == 1.2   # numbers
    assert docs[0]["metrics"]["rmse_N"] != docs[1]["metrics"]["rmse_N"]
    capsys.readouterr()
    target = next(f for f, d in zip(folders, docs, strict=True) if d["run"]["overrides"])
    assert main([*base, "--out", str(target)]) == 2
    assert "holds a run of other inputs" in capsys.readouterr().err
    assert main(soft) == 0                          # the same inputs: replaced in place
    assert len([p for p in (tmp_path / "runs").iterdir() if not p.name.startswith(".")]) == 2
    assert main([*base, "--out", str(target), "--overwrite"]) == 0
    assert not json.loads((target / "metrics.json").read_text())["run"]["overrides"]
