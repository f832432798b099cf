"""W3's physical load pulses: the calibrated rear-hitch loads change the hold-mode idler
load by the scenario's targets (+2 kN braking, -1.5 kN drive), measured on the tp plant."""

from __future__ import annotations

import pytest

from trackmj.scenarios.load import load_scenario
from trackmj.study.w3_hitch import calibration_pulse, idler_force_history, load_change_N


@pytest.fixture(scope="module")
def w3():
    scenario = load_scenario("W3")
    angle, rise = scenario.load_pulses[0].pull_angle_deg, scenario.load_pulses[0].rise_s
    reference = idler_force_history(scenario, calibration_pulse(0.0, angle, rise, 2.0))
    return scenario, reference


@pytest.mark.parametrize("index", [0, 1])
def test_calibrated_hitch_pulse_gives_target_idler_load_change(w3, index: int) -> None:
    scenario, reference = w3
    pulse = scenario.load_pulses[index]
    change = load_change_N(scenario, pulse.hitch_N, pulse.pull_angle_deg, plateau_s=2.0,
                           rise_s=pulse.rise_s, reference=reference)
    # the calibration hit the target within 2 %; 10 % leaves room for model-level drift
    # while still catching a broken path (sign, hitch geometry, force application)
    assert change == pytest.approx(pulse.delta_N, rel=0.10)


@pytest.mark.slow
def test_pushing_raises_and_towing_lowers_the_idler_load(w3) -> None:
    """Physics of the two paths at equal magnitude: a push (brake torque, tight top strand)
    moves the idler load more than a tow (drive torque, tight ground strand)."""
    scenario, reference = w3
    push = load_change_N(scenario, -3e3, 30.0, reference=reference)
    tow = load_change_N(scenario, 3e3, 30.0, reference=reference)
    assert push > 0.0 > tow
    assert abs(push) > abs(tow)
