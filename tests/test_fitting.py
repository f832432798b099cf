"""Calibration against measured logs (trackmj.study.calibrate) and the log reader
(trackmj.results.measured).

The log is made with trackmj itself: a closed-loop run of a short step-up/step-down
condition with the head-branch restrictor area and the oil bulk modulus off nominal, plus
sensor noise at the study's σ (0.15 MPa, 0.2 mm; models/lf1352_control.toml [sensors]).
The fit must recover both values within its stated 95 % intervals.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from trackmj.validator import ParameterError

DATA = Path(__file__).parent / "data"
SCENARIO = DATA / "steps_short.toml"
DURATION_S = 2.5
AREA = "hydraulics.metering.head_branch_area_m2"
BULK = "hydraulics.fluid.bulk_modulus_Pa"
TRUTH = {AREA: 3.0e-8, BULK: 1.1e9}
"""Off nominal (the hydraulic file has 4.0e-8 m² and 1.4e9 Pa)."""
NOMINAL = {AREA: 4.0e-8, BULK: 1.4e9}


def lf1352_sensors():
    """The default machine's sensor noise (its control file read through the machine)."""
    from trackmj.control.params import load_config
    from trackmj.machines import assembly as machines

    nominal_N = machines.mechanics(machines.resolve("lf1352")).nominal_tension_N
    return load_config(nominal_tension_N=nominal_N).sensors


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    """A plain CSV, header as given (units in it), full float precision."""
    names = list(columns)
    rows = np.column_stack([columns[n] for n in names])
    np.savetxt(path, rows, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return path


@pytest.fixture(scope="module")
def truth_run():
    from trackmj.sim.run import simulate

    return simulate(SCENARIO, set=TRUTH, seed=0).columns()


@pytest.fixture(scope="module")
def noisy_log(truth_run, tmp_path_factory):
    sensors = lf1352_sensors()
    rng = np.random.default_rng(1)
    c = truth_run
    n = len(c["t_s"])
    path = tmp_path_factory.mktemp("log") / "rig.csv"
    return write_csv(path, {
        "t_s": c["t_s"],
        "p_head [MPa]": (c["p_head_Pa"] + rng.normal(0.0, sensors.pressure_noise_std_Pa, n))
        / 1e6,
        "stroke_mm": (c["stroke_m"] + rng.normal(0.0, sensors.stroke_noise_std_m, n)) * 1e3,
        "valve_mode": c["valve_mode"]})


def spec_file(tmp: Path, **extra: object) -> Path:
    lines = ["[calibrate]", f'scenario = "{SCENARIO}"', f"duration_s = {DURATION_S}",
             "seed = 0", *(f"{k} = {v!r}" for k, v in extra.items()),
             "[[calibrate.parameters]]", f'key = "{AREA}"', "bounds = [1.6e-8, 8.0e-8]",
             "[[calibrate.parameters]]", f'key = "{BULK}"', "bounds = [0.6e9, 2.0e9]"]
    path = tmp / "spec.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.slow
def test_replayed_valve_command_reproduces_the_run(truth_run):
    """The fit's open-loop plant under the run's own valve command is the run, bit for bit
    (what makes a fit at the true values leave the sensor noise alone)."""
    from trackmj.sim.setup import prepare
    from trackmj.study.calibrate import replay

    setup = prepare(SCENARIO, seed=0, overrides=TRUTH)
    mode = truth_run["valve_mode"].astype(float)
    out = replay(setup, mode, truth_run["u"], ["tension_N", "p_head_Pa", "stroke_m"])
    for name, values in out.items():
        np.testing.assert_array_equal(values, truth_run[name], err_msg=name)


@pytest.mark.slow
def test_calibration_recovers_off_nominal_values(noisy_log, tmp_path, capsys):
    """Through the command line, as a user runs it: the estimates printed in display units
    with their intervals, and the log named by its hash."""
    from trackmj.cli.main import main
    from trackmj.study.calibrate import CALIBRATION_JSON, CALIBRATION_PNG

    out = tmp_path / "cal"
    assert main(["calibrate", str(spec_file(tmp_path)), "--measured", str(noisy_log),
                 "--out", str(out)]) == 0
    doc = json.loads((out / CALIBRATION_JSON).read_text())
    printed = capsys.readouterr().out
    bulk = doc["estimates"]["hydraulics.fluid.bulk_modulus_Pa"]
    assert f"hydraulics.fluid.bulk_modulus_Pa = {bulk * 1e-6:.5g} MPa" in printed
    assert "mm²" in printed and f"log {Path(noisy_log).name} (sha256 " in printed
    for key, truth in TRUTH.items():
        low, high = doc["intervals"][key]
        assert low <= truth <= high, (key, doc["estimates"][key], low, high)
        assert not low <= NOMINAL[key] <= high, (key, low, high)   # the fit moved
        assert high - low < 0.2 * truth                             # and says how well
    sensors = lf1352_sensors()
    # at the estimate what is left is the sensor noise
    assert doc["residual_rms"]["p_head_Pa"] == pytest.approx(sensors.pressure_noise_std_Pa,
                                                             rel=0.05)
    assert doc["residual_rms"]["stroke_m"] == pytest.approx(sensors.stroke_noise_std_m,
                                                            rel=0.05)
    assert {run["purpose"] for run in doc["runs"]} >= {"fit", "jacobian", "interval"}
    assert (out / CALIBRATION_PNG).stat().st_size > 10_000


@pytest.mark.parametrize(("header", "name", "scale"), [
    ("tension_kN", "tension_N", 1e3), ("p_head [MPa]", "p_head_Pa", 1e6),
    ("p_rod_bar", "p_rod_Pa", 1e5), ("stroke_mm", "stroke_m", 1e-3),
    ("t [ms]", "t_s", 1e-3), ("tension_N", "tension_N", 1.0), ("valve_mode", "valve_mode", 1.0),
    ("q_supply [L/min]", "q_supply_m3_s", 1e-3 / 60.0)])
def test_headers_name_their_unit(header, name, scale):
    from trackmj.results.measured import si_name

    assert si_name(header) == (name, pytest.approx(scale))


@pytest.mark.parametrize(("mutate", "words"), [
    (lambda c: c["t_s"].__setitem__(5, c["t_s"][3]), ["rig.csv column 't_s'", "not strictly "
                                                       "increasing at row 6"]),
    (lambda c: c["p_head [MPa]"].__setitem__(slice(9, 70), np.nan),
     ["rig.csv column 'p_head [MPa]'", "no sample from t = 0.009 to 0.071 s", "0.05 s"]),
    (lambda c: c["p_head [MPa]"].__setitem__(9, np.inf), ["rig.csv column 'p_head [MPa]'",
                                                            "data row 10 is inf"]),
    (lambda c: c.update(t_s=c["t_s"] + 1234.5), ["rig.csv column 't_s'", "starts at 1234.5 s",
                                                 "subtract its first time, 1234.5 s"]),
    (lambda c: c.update(t_s=c["t_s"] * 0.5), ["rig.csv column 't_s'", "too short"]),
])
def test_bad_logs_are_refused_naming_file_and_column(tmp_path, mutate, words):
    from trackmj.study.calibrate import load_log

    t = 1e-3 * np.arange(1, 2501)
    cols = {"t_s": t, "p_head [MPa]": np.full(t.shape, 5.0), "valve_mode": np.zeros(t.shape)}
    mutate(cols)
    path = write_csv(tmp_path / "rig.csv", cols)
    with pytest.raises(ParameterError) as info:
        load_log(path, DURATION_S)
    for word in words:
        assert word in str(info.value)


def test_a_log_without_a_fit_channel_or_command_is_refused(tmp_path):
    from trackmj.study.calibrate import load_log

    t = 1e-3 * np.arange(1, 2501)
    path = write_csv(tmp_path / "rig.csv", {"t_s": t, "valve_mode": np.zeros(t.shape)})
    with pytest.raises(ParameterError, match=r"rig\.csv: no channel to fit"):
        load_log(path, DURATION_S)
    path = write_csv(tmp_path / "rig.csv", {"t_s": t, "p_head_Pa": np.zeros(t.shape)})
    with pytest.raises(ParameterError, match=r"rig\.csv: no column 'valve_mode'"):
        load_log(path, DURATION_S)


def test_cli_refuses_a_bad_spec_before_any_run(tmp_path, capsys):
    from trackmj.cli.main import main

    spec = spec_file(tmp_path).read_text().replace("bounds = [0.6e9, 2.0e9]",
                                                   "bounds = [2.0e9, 0.6e9]")
    (tmp_path / "spec.toml").write_text(spec)
    t = 1e-3 * np.arange(1, 2501)
    log = write_csv(tmp_path / "rig.csv", {"t_s": t, "p_head_Pa": np.zeros(t.shape),
                                           "valve_mode": np.zeros(t.shape)})
    code = main(["calibrate", str(tmp_path / "spec.toml"), "--measured", str(log), "--out",
                 str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "spec.toml [[calibrate.parameters]][1].bounds" in err and "high > low" in err
    assert not (tmp_path / "out").exists()


def test_a_mistyped_spec_key_is_answered_with_the_nearest_kind(tmp_path):
    """A spec key of a mistyped kind names the nearest one, not the pattern it failed."""
    from trackmj.study.calibrate_spec import load_spec

    spec = spec_file(tmp_path).read_text().replace(f'key = "{BULK}"',
                                                   f'key = "hydraulic{BULK[10:]}"')
    (tmp_path / "spec.toml").write_text(spec)
    with pytest.raises(ParameterError, match=r"^spec\.toml \[\[calibrate\.parameters\]\]\[1\]"
                       r"\.key = 'hydraulic\.fluid\.bulk_modulus_Pa': unknown file kind "
                       r"'hydraulic'; did you mean 'hydraulics'\?"):
        load_spec(tmp_path / "spec.toml")


# ---------------------------------------------------------------------- run --measured

def test_lag_by_cross_correlation_finds_a_known_delay():
    from trackmj.results.comparison import lag_s

    t = 1e-3 * np.arange(1, 4001)
    ref = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 1.9 * t)
    late = np.sin(2 * np.pi * 0.7 * (t - 0.037)) + 0.3 * np.sin(2 * np.pi * 1.9 * (t - 0.037))
    assert lag_s(t, late, ref, (0.5, 4.0)) == pytest.approx(0.037, abs=1e-9)
    assert lag_s(t, ref, late, (0.5, 4.0)) == pytest.approx(-0.037, abs=1e-9)


def test_trace_errors_of_a_constant_offset():
    from trackmj.results.comparison import trace_errors

    t = 1e-3 * np.arange(1, 3001)
    y_ref = 12e3 + 3e3 * (t >= 1.0)
    e = trace_errors(t, y_ref + 250.0, y_ref, (0.5, 3.0), 2.0)
    assert e["rmse"] == pytest.approx(250.0) and e["peak_error"] == pytest.approx(250.0)
    # the low-pass is linear: the offset passes whole (DC gain 1)
    assert e["rmse_lp"] == pytest.approx(250.0, rel=1e-6)
    assert e["peak_abs_error_lp"] == pytest.approx(250.0, rel=1e-6)


def test_a_run_compared_with_its_own_log_has_no_error(truth_run, tmp_path):
    from trackmj.sim.run import simulate

    c = truth_run
    log = write_csv(tmp_path / "own.csv", {"t [ms]": c["t_s"] * 1e3,
                                           "tension_kN": c["tension_N"] / 1e3,
                                           "p_head_Pa": c["p_head_Pa"]})
    result = simulate(SCENARIO, set=TRUTH, seed=0, measured=log)
    table = result.metrics["prediction_vs_measured"]
    assert set(table) == {"tension_N", "p_head_Pa"}
    # a micronewton: the log's round trip and the filter's arithmetic, not a model error
    assert table["tension_N"]["rmse_N"] == pytest.approx(0.0, abs=1e-6)
    assert table["tension_N"]["rmse_lp_N"] == pytest.approx(0.0, abs=1e-6)
    assert table["p_head_Pa"]["peak_error_Pa"] == pytest.approx(0.0, abs=1e-6)
    assert table["p_head_Pa"]["lag_s"] == 0.0


@pytest.mark.parametrize(("columns", "words"), [
    ({"t_s": 1e-3 * np.arange(1, 2501), "hitch_kN": np.zeros(2500)},
     ["bad.csv: no column to compare", "ignored: hitch_kN"]),
    ({"t_s": 1e-3 * np.arange(1, 2501), "tension [psi]": np.zeros(2500)},
     ["bad.csv column 'tension [psi]'", "is not a force"]),
    ({"t_s": 1e-3 * np.arange(1, 1001), "tension_N": np.zeros(1000)},
     ["bad.csv column 't_s'", "too short"]),
])
def test_run_refuses_a_bad_measured_log_before_running(tmp_path, capsys, columns, words):
    from trackmj.cli.main import main

    log = write_csv(tmp_path / "bad.csv", columns)
    code = main(["run", str(SCENARIO), "--measured", str(log), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and all(w in err for w in words), err
    assert not (tmp_path / "r").exists()


def test_missing_samples_are_bridged_and_counted(tmp_path):
    """A channel logged at 1/10 of the time column's rate (blank cells between) and a
    dropped command sample: the channel is the line between its samples, the command is
    held across the gap, and the log record counts what was bridged."""
    from trackmj.study.calibrate import load_log

    t = 1e-3 * np.arange(1, 2501)
    p_head = np.where(np.arange(t.size) % 10 == 0, 5.0 + t, np.nan)   # MPa, 100 Hz
    mode = np.where(t < 1.0, 1.0, -1.0)
    mode[1200] = np.nan
    path = write_csv(tmp_path / "rig.csv", {"t_s": t, "p_head [MPa]": p_head, "valve_mode": mode})
    log = load_log(path, DURATION_S)
    np.testing.assert_allclose(log.channels["p_head_Pa"][:-9], 1e6 * (5.0 + t[:-9]), rtol=1e-12)
    np.testing.assert_array_equal(log.mode[1195:1205], -1)
    assert log.record()["missing_samples"] == {"p_head [MPa]": 2250, "valve_mode": 1}


def test_the_information_matrix_names_the_keys_the_logs_do_not_determine():
    """A Jacobian column of zeros (a key the channels do not see) and two proportional
    columns (keys seen only together) are undetermined; the rest is inverted as it is."""
    from trackmj.study.calibrate import _inverse_information

    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((2, 200))
    j = np.stack([a, np.zeros(200), b, -2.0 * b], axis=1)
    inverse, determined = _inverse_information(j)
    np.testing.assert_array_equal(determined, [True, False, False, False])
    assert inverse[0, 0] == pytest.approx(1.0 / (a @ a), rel=1e-12)
    assert np.isinf(inverse[1:, 1:]).all()
    well = np.stack([a, b], axis=1)
    inverse, determined = _inverse_information(well)
    assert determined.all()
    np.testing.assert_allclose(inverse, np.linalg.inv(well.T @ well), rtol=1e-12)


def test_a_channel_the_fit_misses_by_far_more_than_its_noise_is_named():
    """The warning names the log, the header as written and the ratio to the sensor's σ; a
    channel at its noise is not named; an undetermined key is named with why."""
    from types import SimpleNamespace

    from trackmj.study.calibrate import fit_warnings

    log = SimpleNamespace(file="rig.csv", used={"stroke_m": "stroke [mm]",
                                                "p_head_Pa": "p_head [bar]"})
    lines = fit_warnings(SimpleNamespace(logs=[log]), {"k": "its 95 % interval covers them"},
                         [{"stroke_m": 0.0296, "p_head_Pa": 1.5e5}],
                         {"stroke_m": 2e-4, "p_head_Pa": 1.5e5})
    assert lines[0].startswith("k: the logs do not determine it within its bounds (its 95 %")
    assert len(lines) == 2 and "rig.csv 'stroke [mm]'" in lines[1]
    assert "29.6 mm RMS, 148 times its sensor's sigma" in lines[1]


class _RoughCost:
    """A stand-in for the fit's problem near an estimate of two keys: the cost is 100 plus
    a rough part drawn afresh at each point (seeded by the point's values), as the track's
    contact events make it; ``seed`` picks the roughness probe points' stream."""

    keys = ("a", "b")
    low, high = np.array([1.0, 1.0]), np.array([4.0, 4.0])

    def __init__(self, seed: int, rough: Callable[[np.random.Generator], float]) -> None:
        from types import SimpleNamespace

        self.spec = SimpleNamespace(seed=seed)
        self.rough = rough

    def x(self, theta: np.ndarray) -> np.ndarray:
        return 1.0 + 3.0 * np.asarray(theta)

    def weighted(self, values: dict[str, float], purpose: str) -> np.ndarray:
        point = np.array([values[k] for k in self.keys]).view(np.uint64).tolist()
        return np.array([np.sqrt(2.0 * (100.0 + self.rough(np.random.default_rng(point))))])


def test_the_cost_roughness_does_not_hang_on_the_probe_points_draw():
    """a is a standard deviation of the cost near the estimate, scaled so that 2a bounds the
    rough part's difference between two points at 95 % (1.16 sd for a normal one): over 100
    draws of the probe points the middle 80 % of a lie within a factor 2 (half the range of
    4 points, the rule before, spread 2.6-fold), and a step of the cost that two thirds of
    the neighbourhood take counts in full in every draw (the estimate in a pocket below it:
    measured on a 2.5 s log, 37 cost units, the true bulk modulus 4.4 σ_x away)."""
    from trackmj.study.calibrate import _roughness

    sd = 0.2
    theta = np.array([0.5, 0.5])
    a = np.array([_roughness(_RoughCost(s, lambda g: sd * g.standard_normal()), theta, 100.0)
                  for s in range(100)])
    p10, p50, p90 = np.percentile(a, [10, 50, 90])
    assert p50 == pytest.approx(1.16 * sd, rel=0.15)
    assert p90 / p10 < 2.0, (p10, p90)
    step = [_roughness(_RoughCost(s, lambda g: 37.0 * (g.random() < 2 / 3)), theta, 100.0)
            for s in range(100)]
    assert min(step) > 0.25 * 37.0, min(step)
