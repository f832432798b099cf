"""ISO 8608 road profiles: PSD slope and class level, seeding, heightfield arrays."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from trackmj.cli.run_commands import _print_end_stop
from trackmj.cli.summary import end_stop_rows_line
from trackmj.results.store import read_result
from trackmj.study.campaign import flatten_metrics
from trackmj.track.terrain import (
    ISO8608_GD_N0_M3,
    band_rms_m,
    heightfield,
    iso8608_psd,
    road_profile,
    taper_start,
)


def test_class_levels_follow_the_standard() -> None:
    assert ISO8608_GD_N0_M3["A"] == pytest.approx(16e-6)
    assert ISO8608_GD_N0_M3["D"] == pytest.approx(1024e-6)
    assert ISO8608_GD_N0_M3["H"] == pytest.approx(262144e-6)
    assert iso8608_psd(0.2, "C") == pytest.approx(256e-6 / 4.0)


@pytest.mark.parametrize("road_class", ["B", "D", "F"])
def test_welch_psd_has_slope_minus_two_and_class_level(road_class: str) -> None:
    dx = 0.025
    prof = road_profile(2000.0, dx, road_class, 3, n_min=0.05, n_max=10.0)
    n, psd = welch(prof.z_m, fs=1.0 / dx, nperseg=4096)
    sel = (n >= 0.2) & (n <= 8.0)  # inside the band, away from the edges' leakage
    slope, intercept = np.polyfit(np.log10(n[sel]), np.log10(psd[sel]), 1)
    assert slope == pytest.approx(-2.0, abs=0.1)
    gd_n0 = 10.0 ** (intercept + slope * np.log10(0.1))
    assert gd_n0 == pytest.approx(ISO8608_GD_N0_M3[road_class], rel=0.15)
    # level of neighbouring classes is 4x away, so the class is identified unambiguously
    assert abs(np.log(gd_n0 / ISO8608_GD_N0_M3[road_class])) < np.log(4.0) / 4


def test_variance_matches_band_integral() -> None:
    prof = road_profile(600.0, 0.025, "D", 11, n_min=0.5, n_max=10.0)
    assert np.std(prof.z_m) == pytest.approx(band_rms_m("D", 0.5, 10.0), rel=0.02)
    assert np.mean(prof.z_m) == pytest.approx(0.0, abs=1e-12)


def test_same_seed_identical_different_seed_different() -> None:
    a = road_profile(100.0, 0.02, "C", 7).z_m
    b = road_profile(100.0, 0.02, "C", np.random.default_rng(7)).z_m
    c = road_profile(100.0, 0.02, "C", 8).z_m
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 1e-3


@pytest.mark.parametrize("bad", ["Z", "", "AB", 3])
def test_bad_class_is_a_clear_error(bad) -> None:
    with pytest.raises(ValueError, match="road class must be one of A-H"):
        road_profile(10.0, 0.02, bad, 0)


def test_band_above_nyquist_is_rejected() -> None:
    with pytest.raises(ValueError, match="n_max"):
        road_profile(10.0, 0.1, "C", 0, n_min=0.1, n_max=6.0)


def test_taper_keeps_start_flat() -> None:
    prof = taper_start(road_profile(50.0, 0.02, "E", 1, x_start_m=-5.0), 2.0, 1.0)
    x = prof.x_m
    assert np.all(prof.z_m[x <= 2.0] == 0.0)
    raw = road_profile(50.0, 0.02, "E", 1, x_start_m=-5.0)
    np.testing.assert_array_equal(prof.z_m[x >= 3.0], raw.z_m[x >= 3.0])


def test_heightfield_round_trips_heights() -> None:
    prof = road_profile(20.0, 0.05, "D", 2, n_min=0.2, n_max=5.0, x_start_m=-4.0)
    hf = heightfield(prof, width_m=1.0, nrow=3)
    assert hf.data.shape == (3, len(prof.z_m))
    assert hf.data.min() == 0.0 and hf.data.max() == pytest.approx(1.0)
    rx, ry, ez, base = hf.size
    assert rx == pytest.approx(0.05 * (len(prof.z_m) - 1) / 2) and ry == 0.5 and base > 0
    np.testing.assert_allclose(hf.pos[2] + hf.data[1] * ez, prof.z_m, atol=1e-12)
    assert hf.pos[0] - rx == pytest.approx(-4.0)


QUICK_W1 = ["--set", "scenario.evaluation.start_s=0.3", "--set",
            "scenario.reference.steps.0.time_s=0.31", "--set",
            "scenario.reference.ramps.0.start_s=0.33", "--duration", "0.35"]
"""W1 with its events moved into a 0.35 s run."""


@pytest.mark.slow
@pytest.mark.parametrize(("machine", "grade", "said"), [("m113", "0.2", True),
                                                        ("lf1352", "0.0", False)])
def test_a_carrier_settled_on_its_end_stop_is_said_in_one_line(tmp_path, capsys, machine,
                                                               grade, said) -> None:
    """M113 (front sprocket) on a 0.2 grade: the traction holding it on the slope loads
    the idler strands and the settle leaves the carrier on its retracted stop (stroke 0);
    the run says so on stderr, naming the machine, grade, stroke and stop, and still
    writes its result. A level LF1352 settles between its stops and says nothing."""
    import json

    from trackmj.cli.main import main

    out = tmp_path / "run"
    args = ["run", "W1", "--machine", machine, "--set", f"scenario.terrain.grade={grade}",
            *QUICK_W1, "--out", str(out)]
    assert main(args) in (0, 1)
    lines = [x for x in capsys.readouterr().err.replace("\r", "\n").splitlines()
             if "end stop" in x]
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    if not said:
        assert lines == [] and "settled_on_end_stop" not in metrics
        return
    assert len(lines) == 1, lines
    assert lines[0].startswith("trackmj: warning: m113 on a grade of +0.2 (tan θ) settles "
                               "with its idler carrier on its retracted end stop (stroke -")
    assert "mm, the stop at 0.0 mm)" in lines[0]
    on = metrics["settled_on_end_stop"]
    assert on["stop"] == "retracted" and on["stop_stroke_m"] == 0.0
    assert on["stroke_m"] <= 0.0 and on["grade"] == 0.2
    # a report says it once per scenario, a sweep from its rows' flattened record
    result = read_result(out)
    _print_end_stop([result, result], "m113")
    assert capsys.readouterr().err == lines[0] + "\n"
    row = {"scenario": "W1", "machine": "m113"} | flatten_metrics(metrics)
    assert end_stop_rows_line([row, {"scenario": "W1", "machine": "m113"}]) == (
        "trackmj: warning: 1 of 2 runs settled with the idler carrier on an end stop, the "
        f"first W1 on m113 on a grade of +0.2 (tan θ) (stroke {on['stroke_m'] * 1e3:.1f} "
        "mm, the stop at 0.0 mm): the stop, not the tensioner, holds the idler at the start "
        "of those runs")
