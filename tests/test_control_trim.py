"""The MPC's integral trim (trackmj.control.trim): it removes an offset the offset-free
estimate cannot explain, and a transient or an unreachable reference does not wind it up."""

import dataclasses

import numpy as np
import pytest

from trackmj.control.lmpc import LinearMpc
from trackmj.control.model import ReducedModel
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.trim import IntegralTrim
from trackmj.sim.control_plant import nominal_plant_params, packaged_control
from trackmj.sim.reduced import run_closed_loop

CFG = packaged_control()
PLANT = nominal_plant_params(control_config=CFG)
F_REF = 15e3


def _offset_after_step(trim_rel: float, leak_factor: float, t_end: float = 10.0,
                       mpc_class: type = NonlinearMpc
                       ) -> tuple[list[float], NonlinearMpc | LinearMpc]:
    """Mean F − F_ref [N] over 2 s windows from 2 s to ``t_end`` after a 12 -> 15 kN step
    at 0.2 s, on a reduced plant whose piston seals leak ``leak_factor`` times what the
    MPC's model (the file's) assumes."""
    cfg = dataclasses.replace(CFG, mpc=dataclasses.replace(CFG.mpc,
                                                           offset_trim_max_rel=trim_rel))
    plant = dataclasses.replace(PLANT, leakage_m3_s_Pa=PLANT.leakage_m3_s_Pa * leak_factor)
    ctrl = mpc_class(ReducedModel(PLANT), cfg.controller, cfg.mpc)
    res = run_closed_loop(cfg, plant, ctrl, lambda t: 12e3 if t < 0.2 else F_REF, t_end,
                          seed=1)
    return [float(np.mean(res.force[(res.t >= a) & (res.t < a + 2.0)]) - F_REF)
            for a in np.arange(2.0, t_end - 1.0, 2.0)], ctrl


@pytest.mark.parametrize("mpc_class", [NonlinearMpc, LinearMpc])
def test_trim_removes_the_offset_of_an_unmodelled_leak(mpc_class: type) -> None:
    """A head-to-rod leak 20x the model's drains the heads at ~(p_h − p_r)·C_l: the
    estimators' disturbance state (the idler's free position) explains forces, not flows,
    so the MPC alone (NMPC and LMPC share the trim) holds the tension short of the
    reference; the trim brings it to the dead band b (0.75 % of 15 kN, 112 N: what one
    minimum-hold pulse moves), rising at most at c/T_i = 75 N/s, so from 6 s on."""
    untrimmed, _ = _offset_after_step(0.0, 20.0, mpc_class=mpc_class)
    trimmed, ctrl = _offset_after_step(CFG.mpc.offset_trim_max_rel, 20.0, mpc_class=mpc_class)
    print(f"offsets [N], no trim {np.round(untrimmed)}, trim {np.round(trimmed)}, "
          f"trim {ctrl.trim.trim_N:.0f} N")
    assert all(o < -0.01 * F_REF for o in untrimmed)      # the defect the trim is for
    dead_band = CFG.mpc.offset_dead_band_rel * F_REF
    assert all(abs(o) < 1.2 * dead_band for o in trimmed[2:])
    assert 0.0 < ctrl.trim.trim_N < ctrl.trim.limit_N


def test_trim_stops_at_its_limit() -> None:
    """A leak 100x the model's needs more than I_max: the trim saturates there (750 N at
    75 N/s: 10 s) and the offset that remains is smaller than without it."""
    untrimmed, _ = _offset_after_step(0.0, 100.0, 14.0)
    trimmed, ctrl = _offset_after_step(CFG.mpc.offset_trim_max_rel, 100.0, 14.0)
    assert ctrl.trim.trim_N == ctrl.trim.limit_N
    assert untrimmed[-1] < trimmed[-1] < 0.0


def _trim(period_s: float = 0.01) -> IntegralTrim:
    return IntegralTrim(integral_time_s=2.0, limit_N=750.0, dead_band_N=110.0, clip_N=150.0,
                        filter_s=0.25, period_s=period_s)


def test_a_transient_winds_the_trim_up_by_at_most_its_clip_rate() -> None:
    """A 3 kN error held for 1 s (a load pulse the MPC has not yet removed) raises the trim
    by at most c·t/T_i = 150 N × 1 s / 2 s = 75 N."""
    trim, flat = _trim(), np.full(16, F_REF)
    for _ in range(100):
        trim.update(flat, (10.5e3, 19.5e3), F_REF - 3e3)
    assert 0.0 < trim.trim_N <= 75.0 + 1e-9


def test_trim_holds_while_the_reference_moves_or_the_governor_saturates() -> None:
    """No integration while the preview ramps (the MPC follows it) or while the reference
    is outside the governed band (W4: the supply cannot reach it)."""
    trim = _trim()
    ramp = F_REF + 50.0 * 0.01 * np.arange(16)
    for _ in range(100):
        trim.update(ramp, (10.5e3, 19.5e3), F_REF - 3e3)
    assert trim.trim_N == 0.0
    for _ in range(100):
        trim.update(np.full(16, F_REF), (10.5e3, 14.0e3), F_REF - 3e3)
    assert trim.trim_N == 0.0
