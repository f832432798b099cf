"""The tensioner's requirements on short closed-loop runs (tp, nmpc, default supply): a W3 hitch
edge and a W4 supply drop are rejected, a reference beyond what the tensioner may hold is
saturated and held (the 0.5 s trailing mean of F_ten stays in [F_min, F_max], is back within
±5 % of the reference 2 s after an edge, and the controller never stalls)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackmj.results.signals import trailing_mean
from trackmj.sim.run import simulate

F_MIN, F_MAX = 10e3, 20e3


def _check_band_and_recovery(result, edges: list[str]) -> dict:
    acc = result.metrics["acceptance"]
    assert F_MIN <= acc["mean_min_N"] and acc["mean_max_N"] <= F_MAX
    assert set(edges) <= set(acc["edge_recovery_s"])
    for edge in edges:
        assert acc["edge_recovery_s"][edge] <= 2.0, (edge, acc["edge_recovery_s"])
    return acc


@pytest.mark.slow
def test_w3_push_edge_is_rejected_within_two_seconds() -> None:
    """The calibrated +2 kN push moved to 2-4 s (its 0.1 s edges while the track drives at
    1.5 m/s; the tow pulse pushed past the run's end): after each edge the 0.5 s mean is back
    within ±5 % (750 N) of the reference within 2 s (0.46 s and 0.79 s measured)."""
    result = simulate("W3", duration=5.5, set={"scenario.load_pulses.0.start_s": 2.0,
                                               "scenario.load_pulses.0.end_s": 4.0,
                                               "scenario.load_pulses.1.start_s": 5.3,
                                               "scenario.load_pulses.1.end_s": 5.4})
    _check_band_and_recovery(result, ["2", "4"])
    assert result.metrics["mujoco_warnings"] == 0


@pytest.mark.slow
def test_w4_supply_drop_is_rejected_and_leaves_no_offset() -> None:
    """The W4 drop to 9 MPa moved to 2-5 s: the 0.5 s mean stays in [F_min, F_max] and within
    ±5 % of the reference through both edges, and 2 s after the restore the mean offset is
    below 2 %."""
    result = simulate("W4", duration=9.5, set={"scenario.supply.drops.0.start_s": 2.0,
                                               "scenario.supply.drops.0.end_s": 5.0})
    acc = _check_band_and_recovery(result, ["2", "5"])
    cols = result.columns()
    t, f, ref = cols["t_s"], cols["tension_N"], cols["tension_ref_N"]
    late = t >= 7.0
    assert abs(np.mean(f[late] - ref[late])) < 0.02 * 15e3
    assert math.isfinite(acc["recovery_max_s"])


@pytest.mark.slow
def test_reference_beyond_f_max_is_held_at_the_limit_without_stalling() -> None:
    """A ramp of 1.2 kN/s from 15 kN passes F_max = 20 kN at 6.2 s: the governor saturates it
    0.5 kN inside the band, the tension is held there (the valves keep acting, the mean
    neither exceeds F_max nor leaks away) and the MPC does not fall back there: at most 2
    fallbacks more than the same run held at 15 kN (whose start-up, the end of the speed
    ramp at 1.1-1.4 s, takes its own: 6 SQP solves at the iteration limit)."""
    held_at = {"scenario.reference.initial_N": 15e3,
               "scenario.reference.steps.0.time_s": 1.5,
               "scenario.reference.steps.0.delta_N": 0.0,
               "scenario.reference.ramps.0.start_s": 2.0}
    result = simulate("W1", duration=10.5,
                      set=held_at | {"scenario.reference.ramps.0.rate_N_s": 1.2e3})
    steady = simulate("W1", duration=10.5,
                      set=held_at | {"scenario.reference.ramps.0.rate_N_s": 0.0})
    cols = result.columns()
    t, f = cols["t_s"], cols["tension_N"]
    mean = trailing_mean(t, f, 0.5)
    assert cols["tension_ref_N"][-1] > 24e3          # asked far beyond the band
    assert mean[t >= 1.0].max() <= F_MAX
    held = t >= 8.5
    assert np.mean(f[held]) == pytest.approx(F_MAX - 500.0, abs=400.0)
    assert np.count_nonzero(np.diff(cols["valve_mode"][t >= 6.5])) > 0   # still acting
    assert (result.metrics["controller_fallbacks"]
            <= steady.metrics["controller_fallbacks"] + 2)


def _late_switch_rate_and_offset(controller: str, **changes: float) -> tuple[float, float]:
    """W5 (constant 15 kN, flat), 8 s: the valve switching rate [Hz] and the mean tension
    error [N] over 4-8 s, past the start-up (speed ramp, first settling)."""
    cols = simulate("W5", duration=8.0, controller=controller, set=changes or None).columns()
    late = cols["t_s"] >= 4.0
    rate = np.count_nonzero(np.diff(cols["valve_mode"][late])) / 4.0
    return rate, float(np.mean(cols["tension_N"][late] - cols["tension_ref_N"][late]))


@pytest.mark.slow
def test_lmpc_holds_a_constant_tension() -> None:
    rate, offset = _late_switch_rate_and_offset("lmpc")
    assert rate < 10.0 and abs(offset) < 0.02 * 15e3


@pytest.mark.slow
def test_pid_measurement_filter_keeps_the_ripple_from_switching_the_valves() -> None:
    """Without its 60 ms measurement filter the 20 Hz tooth-passing ripple drives the PID's
    valves at the 30 ms hold's limit (~30 Hz, measured 30); with it the PID switches at
    about half that (15 Hz measured: its integral settles at a steady release request of
    ~0.16, which the valve logic realises as pulses, and the filtered ripple still crosses
    the dead band) and holds the mean within 2 %."""
    busy, _ = _late_switch_rate_and_offset("pid", **{"control.pid.measurement_filter_s": 0.0})
    rate, offset = _late_switch_rate_and_offset("pid")
    assert busy > 25.0
    assert rate < 0.6 * busy
    assert abs(offset) < 0.02 * 15e3


@pytest.mark.slow
@pytest.mark.parametrize("machine", ["m113", "compact3"])
def test_the_sagging_supply_still_holds_the_nominal_tension(machine: str) -> None:
    """W4's drop to 9 MPa moved to 2-9 s on the machines whose nominal tension needs most of
    it: two 40 mm heads hold M113's 20 kN at 8.08 MPa, two 32 mm ones compact3's 13 kN at
    8.20 MPa (F + A_r·p_t over A_h; 22.3 and 14.3 kN at 9 MPa with no flow). The governor
    leaves 0.5 MPa across the metering (21.1 and 13.5 kN), so over the drop's last 3 s the
    tension's mean is within 2 % of the reference (1 MPa left: 19.8 and 12.7 kN, 2-3.7 % low).
    The supply sits at the drop's 9 MPa on average: the head flow's ripple moves it (M113 on
    its bushings, 1.63e-7 m² head branches: 9.06 MPa mean, 8.34-9.69 MPa, 0.26 MPa rms)."""
    result = simulate("W4", machine=machine, duration=10.0,
                      set={"scenario.supply.drops.0.start_s": 2.0,
                           "scenario.supply.drops.0.end_s": 9.0})
    cols = result.columns()
    t, f, ref = cols["t_s"], cols["tension_N"], cols["tension_ref_N"]
    sag = (t >= 6.0) & (t < 9.0)
    assert np.mean(cols["p_supply_Pa"][sag]) < 9.2e6        # the supply did sag
    nominal = float(np.mean(ref[sag]))
    assert abs(np.mean(f[sag]) - nominal) < 0.02 * nominal
    assert result.metrics["mujoco_warnings"] == 0
