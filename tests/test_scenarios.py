"""Scenario files W1-W5: contents per the study, signals, windows, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from trackmj.params import ParameterError
from trackmj.scenarios import load_scenario, scenario_path
from trackmj.terrain import band_rms_m


@pytest.mark.parametrize("name", ["W1", "W2", "W3", "W4", "W5", "w3"])
def test_builtin_scenarios_load_with_defaults(name: str) -> None:
    s = load_scenario(name)
    assert s.name == name.upper()
    assert s.duration_s == 30.0 and s.seeds == (0, 1, 2, 3, 4)
    assert (s.controller, s.estimator) == ("nmpc", "ekf")
    assert (s.limits.force_min_N, s.limits.force_max_N) == (10e3, 20e3)
    assert s.supply.nominal_Pa == 12e6


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


def test_other_references_are_constant_15kN() -> None:
    t = np.linspace(0.0, 30.0, 301)
    for name in ["W2", "W3", "W4", "W5"]:
        np.testing.assert_array_equal(load_scenario(name).reference_N(t), 15e3)


def test_w4_supply_drop_profile() -> None:
    s = load_scenario("W4")
    assert s.supply.mode == "prescribed"
    t = np.array([0.0, 11.99, 12.05, 12.1, 16.0, 20.0, 20.05, 20.1, 29.0])
    np.testing.assert_allclose(
        s.supply_pressure_Pa(t), [12e6, 12e6, 10.5e6, 9e6, 9e6, 9e6, 10.5e6, 12e6, 12e6]
    )
    assert s.metric_windows().disturbances == ((12.0, 20.0),)
    np.testing.assert_array_equal(load_scenario("W1").supply_pressure_Pa(t), 12e6)


def test_w3_load_pulses() -> None:
    s = load_scenario("W3")
    t = np.array([5.9, 6.05, 7.9, 8.05, 12.0, 18.5, 20.5])
    assert [(p.start_s, p.end_s, p.delta_N) for p in s.load_pulses] == [
        (6.0, 8.0, 2e3), (18.0, 20.0, -1.5e3)]
    pull, down = s.hitch_force_N(t)
    push, tow = s.load_pulses[0].hitch_N, s.load_pulses[1].hitch_N
    assert push < 0.0 < tow            # braking pulse pushes, drive pulse tows
    cos30, sin30 = np.cos(np.radians(30.0)), 0.5
    np.testing.assert_allclose(pull, [0, push * cos30 / 2, push * cos30, push * cos30 / 2, 0,
                                      tow * cos30, 0])
    np.testing.assert_allclose(down, pull * sin30 / cos30)
    assert s.track_speed_m_s(0.5) == pytest.approx(0.75) and s.track_speed_m_s(9.0) == 1.5
    assert s.metric_windows().disturbances == ((6.0, 8.0), (18.0, 20.0))
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
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "duration_s = 30.0",
            "duration_s = -1.0",
            r"bad\.toml \[scenario\]\.duration_s = -1\.0 is outside the allowed range \(0, 3600\]",
        ),
        (
            'controller = "nmpc"',
            'controller = "mpcc"',
            r"\[scenario\]\.controller = 'mpcc' is not one of \['nmpc', 'lmpc', 'pid'\]",
        ),
        ("seeds = [0, 1, 2, 3, 4]", "seeds = [0, 1.5]", r"\[scenario\]\.seeds"),
        (
            "initial_N = 12.0e3",
            "initial_n = 12.0e3",
            r"bad\.toml \[reference\]: unknown key.*'initial_n'",
        ),
        (
            "rate_N_s = 50.0",
            "rate_N_s = 5.0e4",
            r"\[\[reference\.ramps\]\]\[0\]\.rate_N_s = 50000\.0 is outside",
        ),
        ("nominal_Pa = 12.0e6", "nominal_Pa = nan", r"\[supply\]\.nominal_Pa: must be finite"),
        ('kind = "flat"', 'kind = "bumpy"', r"\[terrain\]\.kind = 'bumpy' is not one of"),
        (
            "force_max_N = 20.0e3",
            "force_max_N = 5.0e3",
            r"\[limits\]\.force_max_N = 5000\.0 must be > force_min_N",
        ),
        ("[evaluation]", "[evaluaton]", r"unknown table\(s\) \['evaluaton'\]"),
        (
            "time_s = 3.0",
            'time_s = "3"',
            r"\[\[reference\.steps\]\]\[0\]\.time_s: expected a number",
        ),
    ],
)
def test_bad_files_name_file_and_key(tmp_path, old: str, new: str, message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        load_scenario(_bad(tmp_path, old, new))


def test_bad_w2_class_and_band(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"road_class = 'K' is not one of"):
        load_scenario(_bad(tmp_path, 'road_class = "D"', 'road_class = "K"', "W2"))
    with pytest.raises(ParameterError, match=r"n_max_cycles_m = 30\.0 exceeds the grid"):
        load_scenario(_bad(tmp_path, "n_max_cycles_m = 10.0", "n_max_cycles_m = 30.0", "W2"))


def test_bad_w3_w4_windows(tmp_path) -> None:
    with pytest.raises(
        ParameterError,
        match=r"\[\[load_pulses\]\]\[0\]\.end_s = 5\.0 must be > "
        r"start_s = 6\.0",
    ):
        load_scenario(_bad(tmp_path, "end_s = 8.0", "end_s = 5.0", "W3"))
    with pytest.raises(ParameterError, match=r"\[supply\]\.mode = 'accumulator': \[\[supply"):
        load_scenario(_bad(tmp_path, 'mode = "prescribed"', 'mode = "accumulator"', "W4"))


def test_missing_file_and_malformed_toml(tmp_path) -> None:
    with pytest.raises(ParameterError, match="not found"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ParameterError, match=r"bad\.toml: malformed TOML"):
        load_scenario(_bad(tmp_path, "[track]", "[track"))


def test_custom_minimal_file_gets_defaults(tmp_path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text('[scenario]\nname = "mine"\n[reference]\ninitial_N = 14e3\n')
    s = load_scenario(path)
    assert s.duration_s == 30.0 and s.track.speed_m_s == 1.5 and s.terrain.kind == "flat"
    assert s.variants[0].name == "nominal" and s.reference_N(10.0) == 14e3


def test_w4_windows_give_dip_and_recovery_from_compute_metrics() -> None:
    """A synthetic W4 run: a 900 N dip at the drop onset decaying with tau = 0.5 s."""
    from trackmj.metrics import compute_metrics

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
