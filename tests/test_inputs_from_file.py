"""Scenario inputs read from files: [reference], [supply], [track] from_file and [hitch]
(trackmj.results.measured.input_signal through the one validator)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trackmj.scenarios.load import load_scenario
from trackmj.sim.setup import prepare
from trackmj.validator import ParameterError

DATA = Path(__file__).parent / "data"
SHORT = DATA / "steps_short.toml"


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    names = list(columns)
    np.savetxt(path, np.column_stack([columns[n] for n in names]), delimiter=",",
               header=",".join(names), comments="", fmt="%.17g")
    return path


def scenario_with(tmp: Path, replace: dict[str, str]) -> Path:
    text = SHORT.read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp / "from_file.toml"
    path.write_text(text)
    return path


REFERENCE_TABLE = """[reference]
initial_N = 12.0e3

[[reference.steps]]
time_s = 0.5
delta_N = 3.0e3

[[reference.steps]]
time_s = 1.5
delta_N = -3.0e3
"""


def test_a_reference_from_file_equal_to_the_built_in_one_gives_the_same_run(tmp_path):
    from trackmj.sim.run import simulate

    built_in = load_scenario(SHORT)
    t = 1e-3 * np.arange(0, 2501)
    write_csv(tmp_path / "ref.csv", {"t_s": t, "F_ref [kN]": built_in.reference_N(t) / 1e3})
    path = scenario_with(tmp_path, {REFERENCE_TABLE: '[reference]\nfrom_file = "ref.csv"\n'})
    from_file = load_scenario(path)
    probe = np.linspace(0.0, 2.6, 5001)      # between grid points and beyond the end too
    np.testing.assert_array_equal(from_file.reference_N(probe), built_in.reference_N(probe))
    a = simulate(SHORT, duration=1.0).columns()
    b = simulate(path, duration=1.0).columns()
    for name in ("tension_N", "p_head_Pa", "stroke_m", "valve_mode", "tension_ref_N"):
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_supply_track_and_hitch_from_files_are_the_signals_in_si(tmp_path):
    t = 1e-3 * np.arange(0, 3001)
    write_csv(tmp_path / "p.csv", {"t [ms]": t * 1e3, "p_set [bar]": 120.0 - 20.0 * (t > 1.0)})
    write_csv(tmp_path / "v.csv", {"t_s": t, "speed_mm_s": 1500.0 * np.minimum(t, 1.0)})
    write_csv(tmp_path / "h.csv", {"t_s": t, "hitch_kN": 5.0 * (t > 2.0), "other_N": 0 * t})
    path = scenario_with(tmp_path, {
        "[track]\nspeed_m_s = 1.5\nramp_s = 1.0\n": '[track]\nfrom_file = "v.csv"\n',
        "[terrain]": '[supply]\nmodel = "prescribed"\nfrom_file = "p.csv"\n\n[hitch]\n'
                     'from_file = "h.csv"\ncolumn = "hitch_kN"\npull_angle_deg = 30.0\n\n'
                     '[terrain]'})
    sc = load_scenario(path)
    assert sc.supply_setpoint_Pa(0.5, 0.0) == 12e6 and sc.supply_setpoint_Pa(1.5, 0.0) == 10e6
    assert sc.supply_setpoint_profile(0.0)(1.5) == 10e6
    assert sc.track_speed_m_s(0.5) == pytest.approx(0.75) and sc.track_speed_m_s(2.0) == 1.5
    pull, down = sc.hitch_force_N(np.array([1.0, 2.5]))
    np.testing.assert_allclose(pull, [0.0, 5e3 * np.cos(np.radians(30.0))])
    np.testing.assert_allclose(down, [0.0, 5e3 * np.sin(np.radians(30.0))])
    # a ramp from standstill over 1 s, then 1.5 m/s: 0.75 m + 1.5 m/s * (2.5 - 1) s
    assert sc.distance_m(2.5) == pytest.approx(0.75 + 1.5 * 1.5, rel=1e-6)


def test_a_shuttle_speed_trace_travels_both_ways_and_a_speed_past_5_m_s_is_refused(tmp_path):
    """A dozer's shuttle from a file: 1 s forward at 1 m/s, then back at -1.5 m/s (linear
    edges of 0.2 s): it goes 0.1 + 0.8 + 0.04 = 0.94 m ahead (turning at 1.08 s), then
    0.09 + 2.7 m back, to -1.85 m; a trace reaching -6 m/s is refused naming the file,
    column, the first value outside and the range."""
    t = 1e-3 * np.arange(0, 3001)
    edge = np.clip(t / 0.2, 0.0, 1.0) - 2.5 * np.clip((t - 1.0) / 0.2, 0.0, 1.0)
    write_csv(tmp_path / "v.csv", {"t_s": t, "speed_m_s": edge})
    track = "[track]\nspeed_m_s = 1.5\nramp_s = 1.0\n"
    sc = load_scenario(scenario_with(tmp_path, {track: '[track]\nfrom_file = "v.csv"\n'}))
    assert sc.travel_range_m(3.0) == pytest.approx((-1.85, 0.94), abs=2e-3)
    # the tooth-passing band over a steady window from 0.5 s: the mean |v|, (0.5·1 + 0.13
    # + 1.8·1.5)/2.5 = 1.332 m/s, where the signed mean (−0.9 m/s) would put it at 12 Hz
    both = load_scenario(scenario_with(tmp_path, {track: '[track]\nfrom_file = "v.csv"\n'}),
                         {"evaluation.steady_start_s": 0.5})
    f_tooth = 1.332 / 0.075
    assert both.metric_windows(3.0, link_pitch_m=0.075).tooth_passing_band_Hz == (
        pytest.approx((0.9 * f_tooth, 1.1 * f_tooth), rel=2e-3))
    write_csv(tmp_path / "v.csv", {"t_s": t, "speed_m_s": 4.0 * edge})
    with pytest.raises(ParameterError) as info:
        prepare(scenario_with(tmp_path, {track: '[track]\nfrom_file = "v.csv"\n'}))
    assert ("v.csv column 'speed_m_s' (track speed): data row 1182 (t_s = 1.181) holds -5.05; "
            "it must stay in [-5, 5] m/s over the run (0 .. 2.5 s)") == str(info.value)


def test_a_bad_speed_sample_is_named_as_the_file_holds_it(tmp_path):
    """A coarse trace in km/h: the message names the file's first sample outside ±5 m/s
    (its data row, time and value as written, and the value in m/s), not a point of the
    1 ms resampling between two of its rows; a sample after the run's end refuses no run."""
    write_csv(tmp_path / "v.csv", {"t [ms]": np.array([0.0, 500.0, 1000.0, 1500.0, 3000.0]),
                                   "speed [km/h]": np.array([0.0, 3.6, 18.0, 19.5, 30.0])})
    path = scenario_with(tmp_path, {"[track]\nspeed_m_s = 1.5\nramp_s = 1.0\n":
                                    '[track]\nfrom_file = "v.csv"\n'})
    with pytest.raises(ParameterError) as info:
        prepare(path)
    assert str(info.value) == (
        "v.csv column 'speed [km/h]' (track speed): data row 4 (t [ms] = 1500) holds 19.5 "
        "(5.41667 m/s); it must stay in [-5, 5] m/s over the run (0 .. 2.5 s)")
    with pytest.raises(ParameterError, match=r"data row 4 \(t \[ms\] = 1500\) holds 19\.5"):
        prepare(path, duration=1.2)        # reads row 4: the run's speed interpolates to it
    assert prepare(path, duration=1.0).scenario.track_speed_m_s(1.0) == pytest.approx(5.0)


def test_a_trace_is_checked_against_the_runs_duration(tmp_path, capsys):
    """A trace covering 1.2 s of a 2.5 s scenario: a run of --duration 1 takes it, the
    scenario's own duration and a --duration past the trace are refused in one line."""
    from trackmj.cli.main import main

    t = 1e-3 * np.arange(0, 1201)
    write_csv(tmp_path / "v.csv", {"t_s": t, "speed_m_s": np.minimum(t, 1.0)})
    path = scenario_with(tmp_path, {"[track]\nspeed_m_s = 1.5\nramp_s = 1.0\n":
                                    '[track]\nfrom_file = "v.csv"\n'})
    assert load_scenario(path).duration_s == 2.5
    assert prepare(path, duration=1.0).duration_s == 1.0
    for given, shown in ((None, "2.5"), (1.5, "1.5")):
        with pytest.raises(ParameterError) as info:
            prepare(path, duration=given)
        assert str(info.value) == ("v.csv column 'speed_m_s' (track speed): ends at 1.2 s, "
                                   f"too short to cover the run (0 .. {shown} s)")
    code = main(["run", str(path), "--duration", "1.5", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith("too short to cover the run (0 .. 1.5 s)"), err
    assert len(err.splitlines()) == 1 and not (tmp_path / "r").exists()


@pytest.mark.parametrize(("columns", "words"), [
    ({"t_s": [0.0, 0.002, 0.001, 3.0], "F_ref_N": [12e3] * 4},
     ["ref.csv column 't_s'", "not strictly increasing"]),
    ({"t_s": [0.0, 1.0, 2.0, 3.0], "F_ref_N": [12e3, np.nan, 12e3, 12e3]},
     ["ref.csv column 'F_ref_N'", "no sample from t = 0 to 2 s", "at most 0.05 s"]),
    ({"t_s": [0.0, 1.0, 2.0], "F_ref_N": [12e3] * 3},
     ["ref.csv column 'F_ref_N'", "too short to cover the run"]),
    ({"t_s": [0.0, 3.0], "F_ref [MPa]": [1.0, 1.0]},
     ["ref.csv column 'F_ref [MPa]'", "is not a force", "needs a unit of force"]),
    ({"t_s": [0.0, 3.0], "F_ref_N": [12e3, 6e6]},
     ["ref.csv column 'F_ref_N'", "must stay in [0, 5e+06] N"]),
])
def test_bad_input_files_are_refused_naming_file_and_column(tmp_path, columns, words):
    write_csv(tmp_path / "ref.csv", {k: np.asarray(v, float) for k, v in columns.items()})
    path = scenario_with(tmp_path, {REFERENCE_TABLE: '[reference]\nfrom_file = "ref.csv"\n'})
    with pytest.raises(ParameterError) as info:
        prepare(path)
    assert all(w in str(info.value) for w in words), str(info.value)


def test_from_file_excludes_the_built_in_keys_and_a_longer_run_is_refused(tmp_path, capsys):
    from trackmj.cli.main import main

    write_csv(tmp_path / "ref.csv", {"t_s": np.array([0.0, 2.5]), "F_ref_N": np.full(2, 12e3)})
    both = scenario_with(tmp_path, {REFERENCE_TABLE: '[reference]\nfrom_file = "ref.csv"\n'
                                    'initial_N = 12e3\n'})
    with pytest.raises(ParameterError, match=r"\[reference\]\.initial_N = 12000.0 is given "
                                             "with from_file"):
        load_scenario(both)
    ok = scenario_with(tmp_path, {REFERENCE_TABLE: '[reference]\nfrom_file = "ref.csv"\n'})
    code = main(["run", str(ok), "--duration", "3.0", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and "ref.csv column 'F_ref_N'" in err and "too short" in err, err


def test_all_channels_carry_units_and_agree_with_the_contract_columns(tmp_path):
    """--channels all: the two heads average to p_head_Pa, the main valve's two supply edges
    add up to q_supply_m3_s, the hitch load is the file's along its line."""
    from trackmj.sim.run import simulate

    t = 1e-3 * np.arange(0, 2501)
    write_csv(tmp_path / "h.csv", {"t_s": t, "hitch_kN": 4.0 * (t > 0.3)})
    path = scenario_with(tmp_path, {"[terrain]": '[hitch]\nfrom_file = "h.csv"\n'
                                                 'pull_angle_deg = 20.0\n\n[terrain]'})
    result = simulate(path, duration=0.6, channels="all")
    c, units = result.columns(), result.units
    assert units["p_head_L_Pa"] == "Pa" and units["q_V_L_m3_s"] == "m^3/s"
    assert units["upper_strand_tension_N"] == "N" and units["hitch_pull_N"] == "N"
    np.testing.assert_allclose(0.5 * (c["p_head_L_Pa"] + c["p_head_R_Pa"]), c["p_head_Pa"],
                               rtol=1e-12)
    np.testing.assert_allclose(c["q_main_PA_m3_s"] + c["q_main_PB_m3_s"], c["q_supply_m3_s"],
                               rtol=1e-12, atol=1e-15)
    on = c["t_s"] - 1e-3 > 0.3          # the load acting over a step is the one at its start
    np.testing.assert_allclose(c["hitch_pull_N"][on], 4e3 * np.cos(np.radians(20.0)))
    np.testing.assert_allclose(c["hitch_down_N"][~on], 0.0)
    assert (c["upper_strand_tension_N"] > 0.0).all() and np.isfinite(
        c["lower_strand_tension_N"]).all()
    with pytest.raises(ParameterError, match="channels = 'some'"):
        simulate(SHORT, duration=0.1, channels="some")


def test_parquet_inputs_and_the_identity_follows_the_file_content(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from trackmj.study.identity import run_key

    t = 1e-3 * np.arange(0, 2501)
    path = scenario_with(tmp_path, {REFERENCE_TABLE: '[reference]\nfrom_file = "ref.parquet"\n'})
    keys = []
    for level_kN in (12.0, 13.0):
        pq.write_table(pa.table({"t_s": t, "F_ref_kN": np.full(t.shape, level_kN)}),
                       tmp_path / "ref.parquet")
        setup = prepare(path)
        assert setup.scenario.reference_N(1.0) == level_kN * 1e3
        keys.append(run_key(setup))
    assert keys[0] != keys[1]
