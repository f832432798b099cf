"""Scenario files W1-W5: contents per the study, signals, windows, clear errors."""

from __future__ import annotations

import dataclasses
import re
import shutil

import numpy as np
import pytest

from trackmj.scenarios import load
from trackmj.scenarios.load import builtin_names, load_scenario, scenario_path
from trackmj.scenarios.schema import NOMINAL
from trackmj.sim.setup import prepare
from trackmj.sim.w3_hitch import calibrated_setup
from trackmj.track.terrain import band_rms_m
from trackmj.validator import ParameterError, parse_overrides


@pytest.mark.parametrize("name", ["W1", "W2", "W3", "W4", "W5", "w3"])
def test_builtin_scenarios_load_with_defaults(name: str) -> None:
    s = load_scenario(name)
    assert s.name == name.upper()
    assert s.duration_s == 30.0 and s.seeds == (0, 1, 2, 3, 4)
    assert (s.controller, s.estimator) == ("nmpc", "ekf")
    assert (s.limits.force_min_N, s.limits.force_max_N) == (10e3, 20e3)
    assert s.supply.model is None    # the hydraulic file's default supply model


def test_builtin_scenarios_are_the_scenario_files_of_the_experiments_folder() -> None:
    """Found by glob: the study's conditions in number order, then NL1; controllers.toml
    (a sweep spec, no [scenario] table) is not one."""
    assert builtin_names() == ("W1", "W2", "W3", "W4", "W5", "NL1")
    assert (load.BUILTIN_FOLDER / "controllers.toml").is_file()
    with pytest.raises(ParameterError, match="built-in scenarios: W1, W2, W3, W4, W5, NL1"):
        scenario_path("controllers")


def test_a_scenario_file_dropped_into_the_folder_is_found_by_name(tmp_path, monkeypatch) -> None:
    """Adding a built-in scenario is adding its file: no list to edit."""
    folder = tmp_path / "experiments"
    shutil.copytree(load.BUILTIN_FOLDER, folder, ignore=shutil.ignore_patterns("__pycache__"))
    text = (folder / "W1.toml").read_text()
    for name in ("X7", "W10", "NL2"):
        (folder / f"{name}.toml").write_text(text.replace('name = "W1"', f'name = "{name}"'))
    monkeypatch.setattr(load, "BUILTIN_FOLDER", folder)
    assert builtin_names() == ("W1", "W2", "W3", "W4", "W5", "W10", "NL1", "NL2", "X7")
    s = load_scenario("x7")
    assert (s.name, s.source) == ("X7", folder / "X7.toml")
    assert s.reference_N(5.0) == load_scenario("W1").reference_N(5.0)


def test_w1_reference_step_and_ramp() -> None:
    s = load_scenario("W1")
    t = np.array([0.0, 2.999, 3.0, 10.0, 15.0, 25.0, 30.0])
    np.testing.assert_allclose(s.reference_N(t), [12e3, 12e3, 15e3, 15e3, 15e3, 15.5e3, 15.75e3])
    assert s.reference_N(3.5).shape == ()
    prev = s.reference_preview(2.95, 11, 0.01)
    assert prev.shape == (11,)
    np.testing.assert_allclose(prev[:5], 12e3)
    np.testing.assert_allclose(prev[6:], 15e3)
    w = s.metric_windows()
    assert w.step == (3.0, 12e3, 15e3, 15.0)  # evaluated until the ramp starts
    assert w.drive_events_s == (1.0,)          # the track's 1 s start ramp ends


def test_other_references_are_constant_15kN() -> None:
    t = np.linspace(0.0, 30.0, 301)
    for name in ["W2", "W3", "W4", "W5"]:
        np.testing.assert_array_equal(load_scenario(name).reference_N(t), 15e3)


def test_w4_supply_setpoint_drop() -> None:
    """W4 lowers the set-point from the hydraulic file's nominal to 9 MPa and back; the
    profile handed to the plugin is the same piecewise-linear signal."""
    s = load_scenario("W4")
    t = np.array([0.0, 11.99, 12.05, 12.1, 16.0, 20.0, 20.05, 20.1, 29.0])
    expected = [12e6, 12e6, 10.5e6, 9e6, 9e6, 9e6, 10.5e6, 12e6, 12e6]
    np.testing.assert_allclose(s.supply_setpoint_Pa(t, 12e6), expected)
    profile = s.supply_setpoint_profile(12e6)
    np.testing.assert_allclose([profile(x) for x in t], expected, rtol=1e-12)
    assert s.metric_windows().disturbances == ((12.0, 20.0),)
    np.testing.assert_array_equal(load_scenario("W1").supply_setpoint_Pa(t, 12e6), 12e6)
    assert load_scenario("W1").supply_setpoint_profile(12e6) is None


def test_zero_transition_drop_is_a_step_for_the_plugin() -> None:
    s = load_scenario("W4", overrides={"supply.drops.0.transition_s": 0.0})
    profile = s.supply_setpoint_profile(12e6)
    assert [profile(x) for x in (11.999, 12.0, 19.999, 20.0)] == [12e6, 9e6, 9e6, 12e6]


def test_w3_load_pulses() -> None:
    """The pulses' targets are the study's at LF1352's 15 kN; their hitch forces, calibrated
    for the machine (LF1352's committed), enter along the 30° chain."""
    s = calibrated_setup(prepare("W3")).scenario
    t = np.array([5.9, 6.05, 7.9, 8.05, 12.0, 18.5, 20.5])
    assert [(p.start_s, p.end_s, p.delta_N) for p in s.load_pulses] == [
        (6.0, 8.0, 2e3), (18.0, 20.0, -1.5e3)]
    pull, down = s.hitch_force_N(t)
    push, tow = s.pulse_hitch_N(0), s.pulse_hitch_N(1)
    assert push < 0.0 < tow            # braking pulse pushes, drive pulse tows
    cos30, sin30 = np.cos(np.radians(30.0)), 0.5
    np.testing.assert_allclose(pull, [0, push * cos30 / 2, push * cos30, push * cos30 / 2, 0,
                                      tow * cos30, 0])
    np.testing.assert_allclose(down, pull * sin30 / cos30)
    assert s.track_speed_m_s(0.5) == pytest.approx(0.75) and s.track_speed_m_s(9.0) == 1.5
    assert s.metric_windows().disturbances == ((6.0, 8.0), (18.0, 20.0))
    with pytest.raises(RuntimeError, match="load pulse 0 has no hitch_N"):
        load_scenario("W3").hitch_force_N(t)      # not calibrated for a machine yet


def test_w3_targets_scale_with_the_machines_nominal_tension() -> None:
    """+2/15 and -1.5/15 of the nominal tension: m113's 20 kN gives +2.67 / -2.0 kN, and the
    reference is its nominal."""
    s = load_scenario("W3", nominal_tension_N=20e3)
    np.testing.assert_allclose([p.delta_N for p in s.load_pulses], [20e3 * 2 / 15, -2e3])
    assert s.reference_N(0.0) == 20e3
    assert load_scenario("W1").hitch_force_N(7.0) == (0.0, 0.0)


def test_w2_road_band_maps_to_1_20_hz_and_is_seeded() -> None:
    s = load_scenario("W2")
    v = s.track.speed_m_s
    assert v * s.terrain.n_min_cycles_m == pytest.approx(1.0)
    assert v * s.terrain.n_max_cycles_m == pytest.approx(20.0)
    assert v / 8.0 > 2 * 0.075  # the 8 Hz wavelength is resolved by the 75 mm pin spacing
    a, b, c = s.terrain_profile(0), s.terrain_profile(0), s.terrain_profile(1)
    np.testing.assert_array_equal(a.z_m, b.z_m)
    assert not np.array_equal(a.z_m, c.z_m)
    assert a.x_m[-1] >= v * 30.0  # covers the distance driven
    assert np.all(a.z_m[a.x_m <= s.terrain.flat_until_m] == 0.0)
    rough = a.z_m[a.x_m > 4.0]
    assert np.std(rough) == pytest.approx(band_rms_m("D", 0.5, 10.0), rel=0.2)
    assert load_scenario("W1").terrain_profile(0) is None
    assert len(s.terrain_profile(0, duration_s=5.0).z_m) < len(a.z_m)


def test_a_reversing_run_drives_onto_road_behind_it_and_the_forward_roads_are_unchanged(
) -> None:
    """W2 at -2 m/s backs 59 m in 30 s: its road reaches margin_m behind that, is level
    under the home layout (|x| <= flat_until_m) and as rough as class D behind it; the
    forward W2 road of each seed is the one earlier runs drove (grid from x_start_m)."""
    forward = load_scenario("W2")
    reverse = load_scenario("W2", {"track.speed_m_s": -2.0})
    road = forward.terrain
    assert reverse.travel_range_m(30.0) == pytest.approx((-2.0 * 29.5, 0.0))
    assert forward.travel_range_m(30.0) == pytest.approx((0.0, 2.0 * 29.5))
    back = reverse.terrain_profile(0)
    assert back is not None
    assert back.x_m[0] <= -2.0 * 29.5 - road.margin_m + road.dx_m
    assert back.x_m[-1] >= -road.x_start_m - road.dx_m
    assert np.all(back.z_m[np.abs(back.x_m) <= road.flat_until_m] == 0.0)
    rough = back.z_m[back.x_m < -4.0]
    assert np.std(rough) == pytest.approx(band_rms_m("D", 0.5, 10.0), rel=0.2)
    ahead = forward.terrain_profile(0)
    assert ahead is not None and ahead.x_start_m == road.x_start_m
    assert ahead.x_m[-1] == pytest.approx(2.0 * 29.5 + road.margin_m, abs=road.dx_m)
    windows = reverse.metric_windows(link_pitch_m=0.075)
    assert windows.tooth_passing_band_Hz == pytest.approx((2.0 / 0.075 * 0.9,
                                                            2.0 / 0.075 * 1.1))
    assert windows.road_band_Hz == pytest.approx((1.0, 20.0))


def test_a_grade_past_the_grounds_friction_is_refused_naming_both_keys() -> None:
    """tan θ >= μ: no track holds (a compact3 W4 at 0.9 left physics at 1.8 s, a drive at
    1.0 slid down at 3.5 m/s with its sprocket turning forward); refused before any work."""
    with pytest.raises(ParameterError, match=r"^W1\.toml \[terrain\]\.grade = 0\.85: .*μ = "
                       r"0\.8 \(lf1352\.toml \[track\]\.ground_friction\)"):
        prepare("W1", overrides={"scenario.terrain.grade": 0.85})
    assert prepare("W1", overrides={"scenario.terrain.grade": -0.7}).scenario.terrain.grade == -0.7


def test_w5_variants() -> None:
    s = load_scenario("W5")
    names = [v.name for v in s.variants]
    assert len(names) == 9 and names[0] == "nominal"
    for param in ("bulk_modulus", "friction", "contact_stiffness", "pretension"):
        for k in (0.8, 1.2):
            v = s.variant(f"{param}_{k}")
            assert getattr(v, f"{param}_scale") == k
            others = [
                f.removesuffix("_scale")
                for f in (
                    "bulk_modulus_scale",
                    "friction_scale",
                    "contact_stiffness_scale",
                    "pretension_scale",
                )
                if not f.startswith(param)
            ]
            assert all(getattr(v, f"{o}_scale") == 1.0 for o in others)
    with pytest.raises(KeyError, match="available"):
        s.variant("beta_0.5")


def test_metric_windows_follow_a_shorter_duration() -> None:
    w = load_scenario("W1").metric_windows(duration_s=5.0)
    assert w.step == (3.0, 12e3, 15e3, 5.0) and w.steady == (5.0, 5.0)


def _bad(tmp_path, old: str, new: str, base: str = "W1"):
    text = scenario_path(base).read_text()
    assert old in text, old
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    return path


# (base file, text replaced, replacement, expected message fragment (regex)); each file is
# refused by load_scenario, i.e. before any model or run is built
MALFORMED = [
    ("W1", "duration_s = 30.0", "duration_s = -1.0",
     r"^bad\.toml \[scenario\]\.duration_s = -1\.0 is outside the allowed range "
     r"\[0\.001, 3600\] s$"),
    ("W1", "duration_s = 30.0", "duration_s = 0.0005",      # shorter than one 1 ms step
     r"\[scenario\]\.duration_s = 0\.0005 is outside the allowed range \[0\.001, 3600\]"),
    ("W1", "duration_s = 30.0", 'duration_s = "30"',
     r"\[scenario\]\.duration_s = '30': expected a number, got a string"),
    ("W1", 'name = "W1"', 'name = "../../etc/W1"',           # would write outside runs/
     r"\[scenario\]\.name = '\.\./\.\./etc/W1' must match .*not starting with '\.'"),
    ("W1", 'name = "W1"', 'name = "a/b"', r"\[scenario\]\.name = 'a/b' must match"),
    ("W1", 'name = "W1"', 'name = ".hidden"', r"\[scenario\]\.name = '\.hidden' must match"),
    ("W1", 'name = "W1"', 'name = ""', r"\[scenario\]\.name = '' must match"),
    ("W1", 'name = "W1"', f'name = "{"x" * 300}"',
     r"\[scenario\]\.name = 'x+\.\.\. is 300 characters long; at most 64 allowed"),
    ("W1", 'name = "W1"', "name = 1", r"\[scenario\]\.name = 1: expected a string, got an integer"),
    ("W1", 'title = "constant-tension tracking"', 'title = " "',
     r"\[scenario\]\.title = ' ' must be one non-empty line"),
    ("W1", 'controller = "nmpc"', 'controller = "mpcc"',
     r"\[scenario\]\.controller = 'mpcc' is not one of \['nmpc', 'lmpc', 'pid'\]"),
    ("W1", 'estimator = "ekf"', 'estimator = "kf"',
     r"\[scenario\]\.estimator = 'kf' is not one of \['ekf', 'ukf'\]"),
    ("W1", "seeds = [0, 1, 2, 3, 4]", "seeds = [0, 1.5]",
     r"\[scenario\]\.seeds\[1\] = 1\.5: expected an integer, got a float"),
    ("W1", "seeds = [0, 1, 2, 3, 4]", "seeds = []",
     r"\[scenario\]\.seeds = \[\]: expected a non-empty array of integers, got an empty array"),
    ("W1", "seeds = [0, 1, 2, 3, 4]", "seeds = [-1]",
     r"\[scenario\]\.seeds\[0\] = -1 is outside the allowed range \[0, 4294967295\]$"),
    ("W1", "seeds = [0, 1, 2, 3, 4]", "seeds = [3, 3]",
     r"\[scenario\]\.seeds = \[3, 3\] lists a seed twice"),
    ("W1", "seeds = [0, 1, 2, 3, 4]", "seeds = 3",
     r"\[scenario\]\.seeds = 3: expected a non-empty array of integers, got an integer"),
    ("W1", 'name = "W1"\n', "",
     r"^bad\.toml \[scenario\]: missing key 'name' \(a string\)"),
    ("W1", "speed_m_s = 1.5", "speed_m_s = [1.5, 2.0]",   # failed after the model was built
     r"\[track\]\.speed_m_s = \[1\.5, 2\.0\]: expected a number, got an array"),
    ("W1", "speed_m_s = 1.5", "speed_m_s = true",
     r"\[track\]\.speed_m_s = True: expected a number, got a boolean"),
    ("W1", "speed_m_s = 1.5", "speed_m_s = 7.5",
     r"\[track\]\.speed_m_s = 7\.5 is outside the allowed range \[-5, 5\] m/s"),
    ("W1", "speed_m_s = 1.5", "speed_m_s = inf", r"\[track\]\.speed_m_s = inf: must be finite"),
    ("W1", "[track]", "[trak]",
     r"^bad\.toml: unknown table \[trak\]; did you mean 'track'\?"),
    ("W1", "initial_rel = 0.8", "initial_n = 12.0e3",
     r"^bad\.toml \[reference\]: unknown key 'initial_n'; did you mean 'initial_N'\?"),
    ("W1", "initial_rel = 0.8", "initial_rel = 0.8\ninitial_N = 12.0e3",
     r"^bad\.toml \[reference\]: give exactly one of 'initial_N' \(absolute\) and "
     r"'initial_rel'"),
    ("W1", "rate_rel_s = 0.0033333333333333335", "rate_N_s = 5.0e7",
     r"\[\[reference\.ramps\]\]\[0\]\.rate_N_s = 50000000\.0 is outside the allowed "
     r"range \[-5e\+06, 5e\+06\] N/s"),
    ("W1", "rate_rel_s = 0.0033333333333333335", "rate_N_s = 4.0e5",
     # 15 kN after the step + 400 kN/s for 15 s
     r"^bad\.toml \[reference\]: F_ref reaches 6\.015e\+06 N at t = 30 s; it must stay in "
     r"\[0, 5e\+06\] N over the run \(a sanity cap above any crawler's tension\), with its "
     r"relative values taken at the machine's nominal tension 15000 N$"),
    ("W1", "rate_rel_s = 0.0033333333333333335", "rate_N_s = 50.0\nend_s = 10.0",
     r"\[\[reference\.ramps\]\]\[0\]\.end_s = 10\.0 must be > start_s = 15\.0"),
    ("W1", "time_s = 3.0", 'time_s = "3"',
     r"\[\[reference\.steps\]\]\[0\]\.time_s = '3': expected a number, got a string"),
    ("W1", "time_s = 3.0", "time_s = 30.0",
     r"\[\[reference\.steps\]\]\[0\]\.time_s = 30\.0 is at or after the end of the run "
     r"\(\[scenario\]\.duration_s = 30\.0\)"),
    ("W1", "[terrain]", '[supply]\nmodel = "pump"\n[terrain]',
     r"\[supply\]\.model = 'pump' is not one of \['fixed_relief', 'compensated', 'unloading', "
     r"'prescribed'\]"),
    ("W1", "[terrain]", "[supply]\nnominal_Pa = 12e6\n[terrain]",
     r"^bad\.toml \[supply\]: unknown key 'nominal_Pa'"),
    ("W4", "[[supply.drops]]", '[supply]\nmodel = "unloading"\n[[supply.drops]]',
     r"\[supply\]\.model = 'unloading' takes no \[\[supply\.drops\]\]"),
    ("W1", 'kind = "flat"', 'kind = "bumpy"',
     r"\[terrain\]\.kind = 'bumpy' is not one of \['flat', 'iso8608'\]"),
    ("W1", "[evaluation]", "[limits]\nforce_min_N = 10.0e3\nforce_max_N = 5.0e3\n[evaluation]",
     r"\[limits\]\.force_max_N = 5000\.0 must be > force_min_N = 10000\.0"),
    ("W1", "[evaluation]", "[evaluaton]", r"^bad\.toml: unknown table \[evaluaton\]"),
    ("W1", "[evaluation]", "force_min_N = 10.0e3\n[evaluation]",   # keys land in [terrain]
     r"^bad\.toml \[terrain\]: unknown key 'force_min_N'"),
    ("W1", "start_s = 1.0                # tracking", "start_s = 30.0  # tracking",
     r"\[evaluation\]\.start_s = 30\.0 is at or after the end of the run"),  # all metrics null
    ("W1", "steady_start_s = 5.0", "steady_start_s = 45.0",
     r"\[evaluation\]\.steady_start_s = 45\.0 is at or after the end of the run"),
    ("W1", "settle_band_rel = 0.02", "settle_band_rel = 0.0",
     r"\[evaluation\]\.settle_band_rel = 0\.0 is outside the allowed range \(0, 0\.5\]$"),
    ("W2", 'road_class = "D"', 'road_class = "K"',
     r"\[terrain\]\.road_class = 'K' is not one of \['A', 'B', "),
    ("W2", 'road_class = "D"\n', "",
     r"^bad\.toml \[terrain\]: missing key 'road_class' \(needed for kind = 'iso8608'\)"),
    ("W2", "n_max_cycles_m = 10.0", "n_max_cycles_m = 30.0",
     r"\[terrain\]\.n_max_cycles_m = 30\.0 exceeds the grid's Nyquist 1/\(2 dx_m\) = 20"),
    ("W2", "n_max_cycles_m = 10.0", "n_max_cycles_m = 0.4",
     r"\[terrain\]\.n_max_cycles_m = 0\.4 must be > n_min_cycles_m = 0\.5"),
    ("W3", "end_s = 8.0", "end_s = 5.0",
     r"\[\[load_pulses\]\]\[0\]\.end_s = 5\.0 must be > start_s = 6\.0"),
    ("W3", "end_s = 8.0", "end_s = 6.05",
     r"\[\[load_pulses\]\]\[0\]\.rise_s = 0\.1 is longer than the window end_s - start_s = "
     r"0\.05 s"),
    ("W3", "start_s = 18.0\nend_s = 20.0", "start_s = 38.0\nend_s = 40.0",
     r"\[\[load_pulses\]\]\[1\]\.start_s = 38\.0 is at or after the end of the run"),
    ("W3", "pull_angle_deg = 30.0", "hitch_N = -3.5e7\npull_angle_deg = 30.0",
     r"^bad\.toml \[\[load_pulses\]\]\[0\]\.hitch_N = -35000000\.0 is outside the allowed "
     r"range \[-5e\+06, 5e\+06\] N$"),
    ("W1", "[scenario]", "load_pulses = 5\n[scenario]",
     r"^bad\.toml: load_pulses = 5: expected an array of tables \[\[load_pulses\]\]"),
    ("W1", "[scenario]", "track = 1.5\n[scenario]\n", r"^bad\.toml: malformed TOML"),
    ("W1", "[track]\n", "[track]\n[track.fast]\n",
     r"^bad\.toml \[track\]: unknown key 'fast'"),
    ("W4", "transition_s = 0.1", "transition_s = 0.1\n\n[[supply.drops]]\nstart_s = 15.0\n"
     "end_s = 25.0\npressure_Pa = 10e6\ntransition_s = 0.1",
     r"\[\[supply\.drops\]\]\[1\]\.start_s = 15\.0 overlaps the drop from 12\.0 to 20\.1 s"),
    ("W4", "transition_s = 0.1", "transition_s = 9.0",
     r"\[\[supply\.drops\]\]\[0\]\.transition_s = 9\.0 is outside the allowed range \[0, 5\] s"),
    ("W4", "end_s = 20.0", "end_s = 12.05",
     r"\[\[supply\.drops\]\]\[0\]\.transition_s = 0\.1 is longer than the window"),
    ("W5", 'name = "nominal"', 'name = "base"',
     r"^bad\.toml \[\[variants\]\]: one variant must be name = 'nominal' with every scale 1"),
    ("W5", 'name = "friction_0.8"', 'name = "friction_1.2"',
     r"\[\[variants\]\]\[4\]\.name = 'friction_1\.2' is used twice"),
    ("W5", 'name = "friction_0.8"', 'name = "../friction"',
     r"\[\[variants\]\]\[3\]\.name = '\.\./friction' must match"),
    ("W5", "friction_scale = 0.8", "friction_scale = 0.3",
     r"\[\[variants\]\]\[3\]\.friction_scale = 0\.3 is outside the allowed range \[0\.5, 2\]"),
    ("W5", "friction_scale = 0.8", "friction_scal = 0.8",
     r"\[\[variants\]\]\[3\]: unknown key 'friction_scal'; did you mean 'friction_scale'\?"),
]


@pytest.mark.parametrize(("base", "old", "new", "message"), MALFORMED,
                         ids=[f"{b}:{n[:30]}" for b, _, n, _ in MALFORMED])
def test_malformed_scenarios_are_refused_naming_file_table_and_key(
        tmp_path, base: str, old: str, new: str, message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        load_scenario(_bad(tmp_path, old, new, base))


def test_unreadable_files_are_refused_naming_the_file(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"scenario file not found: .*nope\.toml \(built-in "
                       r"scenarios: W1, W2, W3, W4, W5, NL1\)"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ParameterError, match=r"bad\.toml: malformed TOML"):
        load_scenario(_bad(tmp_path, "[track]", "[track"))
    with pytest.raises(ParameterError, match=r": is a directory, not a TOML file"):
        load_scenario(tmp_path)
    binary = tmp_path / "run.parquet"
    binary.write_bytes(b"PAR1\x00\x15\x04" + bytes(range(256)))
    with pytest.raises(ParameterError, match=r"run\.parquet: not a text file \(NUL byte at "
                       r"offset 4\)"):
        load_scenario(binary)
    latin1 = tmp_path / "latin1.toml"
    latin1.write_bytes('[scenario]\ntitle = "Spannung f\u00fcr W1"\n'.encode("latin-1"))
    with pytest.raises(ParameterError, match=r"latin1\.toml: not UTF-8 text \(byte 0xfc at "
                       r"offset 30\); save the file as UTF-8"):
        load_scenario(latin1)
    bom = tmp_path / "bom.toml"            # a UTF-8 byte-order mark (Windows editors) is fine
    bom.write_bytes(b"\xef\xbb\xbf" + scenario_path("W1").read_bytes())
    assert load_scenario(bom).name == "W1"


def test_missing_required_table_is_named(tmp_path) -> None:
    text = scenario_path("W1").read_text()
    cut = text.index("[terrain]")
    path = tmp_path / "mine.toml"
    path.write_text(text[:cut] + text[text.index("[evaluation]"):])
    with pytest.raises(ParameterError, match=r"^mine\.toml: missing table \[terrain\]$"):
        load_scenario(path)


def test_relative_values_scale_with_the_machine_and_limits_default_to_its_band() -> None:
    """W1 and NL1 state forces over the nominal tension and drop pressures over the supply
    set-point: on a 20 kN / 16 MPa machine W1 starts at 16 kN, steps +4 kN, ramps 66.7 N/s,
    is judged in [13.33, 26.67] kN; NL1 drops to 12 MPa. LF1352 (15 kN, 12 MPa) keeps the
    study's absolute values."""
    s = load_scenario("W1", nominal_tension_N=20e3, supply_setpoint_Pa=16e6)
    assert float(s.reference_N(0.0)) == pytest.approx(16e3)
    assert float(s.reference_N(4.0)) == pytest.approx(20e3)
    assert float(s.reference_N(16.0)) == pytest.approx(20e3 + 20e3 / 300.0)
    assert (s.limits.force_min_N, s.limits.force_max_N) == pytest.approx((40e3 / 3, 80e3 / 3))
    nl1 = load_scenario("NL1", nominal_tension_N=20e3, supply_setpoint_Pa=16e6)
    assert nl1.supply.drops[0].pressure_Pa == pytest.approx(12e6)
    lf = load_scenario("W1")
    assert (float(lf.reference_N(0.0)), float(lf.reference_N(4.0))) == (12e3, 15e3)
    assert (lf.limits.force_min_N, lf.limits.force_max_N) == (10e3, 20e3)


def test_w3_applies_to_every_machine_and_a_restriction_names_its_reason(tmp_path) -> None:
    """W3's targets are relative and its hitch forces calibrated per machine, so it has no
    [scenario].machines; a file that restricts itself is refused on another machine with its
    reason."""
    for machine in ("lf1352", "m113", "compact3"):
        load_scenario("W3").check_machine(machine)
    only = load_scenario(_bad(tmp_path, 'estimator = "ekf"', 'estimator = "ekf"\nmachines = '
                              '["lf1352"]\nmachines_reason = "measured there"', "W3"))
    only.check_machine("lf1352")
    with pytest.raises(ParameterError, match=r"^bad\.toml: scenario W3 applies to lf1352 only, "
                       r"not m113: measured there$"):
        only.check_machine("m113")


def test_custom_file_with_every_table_loads(tmp_path) -> None:
    """A custom condition: arrays of tables are optional, flat terrain needs only its kind,
    variants default to the nominal one, and an open ramp runs to the end."""
    path = tmp_path / "mine.toml"
    path.write_text('[scenario]\nname = "mine"\ntitle = "my ramp"\nduration_s = 8\n'
                    'seeds = [7]\ncontroller = "pid"\nestimator = "ukf"\n'
                    "[track]\nspeed_m_s = 1\nramp_s = 0.5\n"
                    "[reference]\ninitial_N = 14e3\n"
                    "[[reference.ramps]]\nstart_s = 2.0\nrate_N_s = 100.0\n"
                    '[supply]\nmodel = "fixed_relief"\n'
                    '[terrain]\nkind = "flat"\n'
                    "[limits]\nforce_min_N = 10e3\nforce_max_N = 20e3\n"
                    "[evaluation]\nstart_s = 1.0\nsteady_start_s = 4.0\nsettle_band_rel = 0.02\n"
                    "min_hold_s = 0.5\nlowpass_cutoff_Hz = 2.0\ntooth_band_rel = 0.1\n"
                    "body_mode_band_Hz = [8.0, 12.0]\npsd_resolution_Hz = 0.5\n"
                    "psd_max_Hz = 50.0\nmean_window_s = 0.5\nrecovery_band_rel = 0.05\n"
                    "steady_window_s = 5.0\n")
    s = load_scenario(path)
    assert (s.duration_s, s.seeds, s.controller, s.estimator) == (8.0, (7,), "pid", "ukf")
    assert type(s.duration_s) is float and type(s.track.speed_m_s) is float
    assert s.variants == (NOMINAL,) and s.load_pulses == () and s.terrain_profile(0) is None
    np.testing.assert_allclose(s.reference_N([0.0, 2.0, 8.0]), [14e3, 14e3, 14.6e3])


def test_overrides_change_the_loaded_scenario_and_are_checked() -> None:
    sets = parse_overrides(["scenario.track.speed_m_s=2", "scenario.load_pulses.0.hitch_N=-15000",
                            "scenario.scenario.controller=pid", "scenario.scenario.seeds=[9]"])
    s = load_scenario("W3", overrides=sets["scenario"])
    assert s.track.speed_m_s == 2.0 and s.load_pulses[0].hitch_N == -15000.0
    assert (s.controller, s.seeds) == ("pid", (9,))
    assert s.load_pulses[1] == load_scenario("W3").load_pulses[1]
    w2 = load_scenario("W2", overrides={"terrain.kind": "flat"})
    assert w2.terrain_profile(0) is None
    with pytest.raises(ParameterError, match=r"^--set scenario\.load_pulses\.2\.hitch_N: index "
                       r"'2' is out of range; \[load_pulses\] has 2 entries$"):
        load_scenario("W3", overrides={"load_pulses.2.hitch_N": 1.0})
    with pytest.raises(ParameterError, match=r"^--set scenario\.track\.speed_m_s = 9\.0 is outside "
                       r"the allowed range \[-5, 5\] m/s$"):
        load_scenario("W1", overrides={"track.speed_m_s": 9.0})
    with pytest.raises(ParameterError, match=r"^--set scenario\.trak\.speed_m_s: the file has no "
                       r"key 'trak'; did you mean 'track'\?"):
        load_scenario("W1", overrides={"trak.speed_m_s": 2.0})


def test_replace_runs_the_same_checks() -> None:
    s = load_scenario("W3")
    late = dataclasses.replace(s.load_pulses[0], start_s=31.0, end_s=32.0)
    with pytest.raises(ParameterError, match=r"^Scenario 'W3' \[\[load_pulses\]\]\[0\]\.start_s = "
                       r"31\.0 is at or after the end of the run"):
        dataclasses.replace(s, load_pulses=(late,))
    assert dataclasses.replace(s, load_pulses=()).load_pulses == ()


def test_w4_windows_give_dip_and_recovery_from_compute_metrics() -> None:
    """A synthetic W4 run: a 900 N dip at the drop onset decaying with tau = 0.5 s."""
    from trackmj.results.metrics import compute_metrics

    s = load_scenario("W4")
    t = np.arange(30001) * 1e-3
    ref = s.reference_N(t)
    y = ref - np.where(t >= 12.0, 900.0 * np.exp(-(t - 12.0) / 0.5), 0.0)
    zeros = np.zeros_like(t)
    cols = {"t_s": t, "tension_N": y, "tension_ref_N": ref, "p_head_Pa": zeros,
            "valve_mode": zeros, "u": zeros, "e_supply_J": zeros, "p_work_J": zeros,
            "mech_work_J": zeros, "chassis_acc_z_m_s2": zeros}
    out = compute_metrics(cols, s.metric_windows())
    assert out["disturbance_peak_error_N"] == pytest.approx(900.0)
    assert out["recovery_time_s"] == pytest.approx(0.5 * np.log(3.0), abs=1e-3)  # ±300 N band
    assert np.isnan(out["overshoot_N"]) and out["constraint_violation_s"] == 0.0


def test_a_pulse_label_names_the_hitch_force_that_applies_it_and_a_missed_target():
    """The label names the hold-mode target, and once calibrated the hitch force and
    whether it reaches the target (a figure of compact3's W3 said "load pulse -1.3 kN"
    for a tow that moved the idler load by -0.10 kN)."""
    from trackmj.scenarios.resolved import HitchCalibration

    sc = load_scenario("W3")
    assert sc.metric_windows().disturbance_labels == ("load pulse +2 kN", "load pulse -1.5 kN")
    cal = HitchCalibration("compact3", (-5290.0, 4130.0), "committed", "0" * 64,
                           ("W3 load pulse 1 (-1.733 kN) on machine compact3: out of reach",))
    sc = dataclasses.replace(sc, hitch_calibration=cal)
    assert sc.metric_windows().disturbance_labels == (
        "load pulse +2 kN (hitch -5.29 kN)", "load pulse -1.5 kN (hitch +4.13 kN, out of reach)")


def test_a_scenario_gives_only_the_evaluation_keys_that_differ(tmp_path) -> None:
    """[evaluation] with its two windows alone reads as W1's whole table (the same run
    inputs); another key given overrides its default; an unknown key is refused with a
    suggestion; the windows stay required."""
    from trackmj.sim.setup import prepare
    from trackmj.study.identity import inputs_key

    text = scenario_path("W1").read_text()
    cut = text.index("[evaluation]")
    path = tmp_path / "mine.toml"
    path.write_text(text[:cut] + "[evaluation]\nstart_s = 1.0\nsteady_start_s = 5.0\n")
    assert load_scenario(path).evaluation == load_scenario("W1").evaluation
    assert inputs_key(prepare(path)) == inputs_key(prepare("W1"))
    path.write_text(text[:cut] + "[evaluation]\nstart_s = 1.0\nsteady_start_s = 5.0\n"
                    "lowpass_cutoff_Hz = 3.0\n")
    assert load_scenario(path).evaluation.lowpass_cutoff_Hz == 3.0
    assert load_scenario(path).evaluation.psd_max_Hz == 50.0
    path.write_text(text[:cut] + "[evaluation]\nstart_s = 1.0\nsteady_start_s = 5.0\n"
                    "lowpass_cutof_Hz = 3.0\n")
    with pytest.raises(ParameterError, match=r"^mine\.toml \[evaluation\]: unknown key "
                                             r"'lowpass_cutof_Hz'; did you mean "
                                             r"'lowpass_cutoff_Hz'\?"):
        load_scenario(path)
    path.write_text(text[:cut] + "[evaluation]\nstart_s = 1.0\n")
    with pytest.raises(ParameterError, match=r"^mine\.toml \[evaluation\]: missing key "
                                             r"'steady_start_s'"):
        load_scenario(path)


@pytest.mark.parametrize("name", ["W1", "NL1"])
def test_a_heavy_machine_s_nominal_tension_passes_the_relative_scenarios(name: str) -> None:
    """A 20-40 t excavator side runs at 40-60 kN: W1 and NL1 (F_ref up to 1.2 x nominal)
    at a nominal tension of 60 kN validate, F_ref and the band scaled with it; the
    cylinders' force check (a warning) is what binds, not a fixed cap of the file."""
    setup = prepare(name, overrides={"model.tensioner.nominal_tension_N": 60e3})
    sc = setup.scenario
    t = np.linspace(0.0, sc.duration_s, 3001)
    on_lf1352 = load_scenario(name).reference_N(t)      # at its nominal 15 kN
    assert sc.reference_N(t) == pytest.approx(4.0 * on_lf1352)
    assert float(np.max(sc.reference_N(t))) >= 60e3      # beyond the former 50 kN cap
    assert (sc.limits.force_min_N, sc.limits.force_max_N) == pytest.approx((40e3, 80e3))


def test_a_hitch_force_within_a_heavy_side_s_drawbar_capacity_is_applied_as_given() -> None:
    """--set scenario.load_pulses.1.hitch_N=40000 on a side of 9 t (mu W about 73 kN at
    mu = 0.8) is accepted and applied as it is, not capped at a fixed 30 kN."""
    sets = parse_overrides(["model.chassis.mass_kg=9000",
                            "scenario.load_pulses.1.hitch_N=40000"])
    setup = prepare("W3", overrides={f"{kind}.{key}": value for kind, table in sets.items()
                                     for key, value in table.items()})
    assert setup.model.track.ground_friction * 9000.0 * 9.81 > 40e3   # within mu W
    assert setup.scenario.pulse_hitch_N(1) == 40e3


@pytest.mark.parametrize(("args", "message"), [
    (["W3", "--set", "scenario.load_pulses.1.hitch_N=4e7"],
     r"--set scenario\.load_pulses\.1\.hitch_N = 40000000\.0 is outside the allowed range "
     r"\[-5e\+06, 5e\+06\] N"),
    (["W1", "--set", "model.tensioner.nominal_tension_N=1e6", "--set",
      "scenario.reference.initial_rel=3", "--set", "scenario.reference.steps.0.delta_rel=3"],
     r"W1\.toml \[reference\]: F_ref reaches 6e\+06 N at t = 3 s; it must stay in "
     r"\[0, 5e\+06\] N over the run \(a sanity cap above any crawler's tension\), with its "
     r"relative values taken at the machine's nominal tension 1e\+06 N"),
    (["W4", "--set", "scenario.supply.drops.0.pressure_rel=1.9", "--set",
      "hydraulics.supply.setpoint_Pa=20e6"],
     r"--set scenario\.supply\.drops\.0\.pressure_rel = 1\.9 gives pressure_Pa = 3\.8e\+07 "
     r"at the hydraulic file's supply set-point 2e\+07 Pa, which is outside the allowed "
     r"range \[0, 3e\+07\] Pa"),
])
def test_an_absurd_force_is_refused_in_one_line_naming_the_key(tmp_path, capsys, args,
                                                                message) -> None:
    """The sanity caps still refuse a slip of units, before any work, in one line naming
    the option or the file's table, never a class of the code."""
    from trackmj.cli.main import main

    assert main(["run", *args, "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "ScenarioFile" not in err, err
    assert re.search(message, err), err
    assert not (tmp_path / "r").exists()
