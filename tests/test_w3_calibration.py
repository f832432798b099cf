"""W3's physical load pulses on each shipped machine: the hitch forces calibrated for the
machine change its hold-mode idler load by the scenario's targets (+2/15 and -1.5/15 of its
nominal tension), measured on the tp plant, every trial within the drawbar capacity and
75 % of the static tipping force (which brackets where the side rolls over); a target no
such force reaches is out of the machine's reach and takes the trial furthest towards it,
said, also on a layout no one shipped; the committed calibration belongs to the shipped
files; and in closed loop the tension recovers after each pulse edge."""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest
from layouts import Variant, overrides

from trackmj.io import cache_dir
from trackmj.machines.assembly import names
from trackmj.ports import COUPLING_STEP_S, StepInputs
from trackmj.scenarios.schema import LoadPulse
from trackmj.sim.run import simulate
from trackmj.sim.setup import RunSetup, prepare
from trackmj.sim.w3_hitch import (
    REFERENCE_MACHINE,
    TIPPING_SHARE,
    OutOfReach,
    Rig,
    calibrated_setup,
    calibration_pulse,
    committed_entries,
    drawbar_capacity_N,
    hold_mode_run,
    idler_force_history,
    input_hashes,
    load_change_N,
    search,
    side_weight_N,
    tipping_forces_N,
)


def _calibrated(machine: str = "lf1352", overrides: dict | None = None) -> RunSetup:
    """W3 prepared on ``machine`` with its hitch forces calibrated (as a run does)."""
    return calibrated_setup(prepare("W3", machine=machine, overrides=overrides))


def _change_of_calibrated_pulse(setup: RunSetup, index: int) -> float:
    """The hold-mode idler-load change [N] of pulse ``index`` with its calibrated force."""
    sc, rig = setup.scenario, Rig(setup)
    pulse = sc.load_pulses[index]
    reference = idler_force_history(
        sc, calibration_pulse(0.0, pulse.pull_angle_deg, pulse.rise_s), rig)
    return load_change_N(sc, rig, sc.pulse_hitch_N(index), pulse.pull_angle_deg,
                         rise_s=pulse.rise_s, reference=reference)


@pytest.mark.parametrize(("machine", "index"), [("lf1352", 0), ("lf1352", 1), ("m113", 0),
                                                ("m113", 1), ("compact3", 0)])
def test_calibrated_hitch_pulse_gives_target_idler_load_change(machine: str,
                                                               index: int) -> None:
    """Each committed force, applied in a fresh hold-mode run against a pulse-free one,
    changes the idler load by +2/15 (braking) or -1.5/15 (drive) of the nominal."""
    setup = _calibrated(machine)
    assert setup.scenario.hitch_calibration is not None
    assert setup.scenario.hitch_calibration.origin == "committed"
    target = setup.scenario.load_pulses[index].delta_N
    assert target == pytest.approx(setup.model.nominal_tension_N * (2.0 if index == 0
                                                                    else -1.5) / 15.0)
    # the calibration hit the target within 2 %; 10 % leaves room for model-level drift
    # while still catching a broken path (sign, hitch geometry, force application)
    assert _change_of_calibrated_pulse(setup, index) == pytest.approx(target, rel=0.10)


def test_front_sprocket_tows_for_the_rise_the_rear_sprocket_pushes_for() -> None:
    """On the front-sprocket m113 a drive (tow) tightens the top strand over the idler, so
    the braking pulse's +2/15 rise takes a tow there and a push on the rear-sprocket
    LF1352 and compact3."""
    assert _calibrated("m113").scenario.pulse_hitch_N(0) > 0.0
    assert _calibrated().scenario.pulse_hitch_N(0) < 0.0
    assert _calibrated("compact3").scenario.pulse_hitch_N(0) < 0.0


def test_compact3_drive_pulse_is_out_of_reach_and_takes_the_trial_furthest_towards_it(
) -> None:
    """compact3's rollers are bolted to its frame (no suspension), so a tow does not shorten
    the track path as on LF1352: even at the drawbar capacity mu W along the 30° chain the
    hold-mode idler load does not fall by 1.3 kN. The drive pulse then applies the trial
    that moved it furthest towards the target (here the search's start, LF1352's tow per
    side weight on compact3's side weight), said with the reason, and its measured change
    is compact3's own: towards the target, short of it."""
    setup = _calibrated("compact3")
    cal = setup.scenario.hitch_calibration
    assert cal is not None and len(cal.out_of_reach) == 1
    assert "W3 load pulse 1 (-1.300 kN) on machine compact3 (drawbar capacity mu W = 0.8 x " \
           "14.77 kN" in cal.out_of_reach[0]
    assert "is out of reach: the pulse applies the tow +4130 N, of the forces tried the one " \
           "that moved the idler load furthest towards the target" in cal.out_of_reach[0]
    rig = Rig(setup)
    weight = side_weight_N(hold_mode_run(setup.scenario, rig)[0])
    assert weight == pytest.approx(1500.0 * 9.81, rel=0.01)   # the 3 t class, one side
    lf1352 = committed_entries()[REFERENCE_MACHINE]
    lf1352_tow = lf1352.hitch_N[lf1352.pulse_index.index(1)]
    # the start's rule: the same drawbar load per side weight (the entries round to 0.1 N)
    assert setup.scenario.pulse_hitch_N(1) == pytest.approx(
        lf1352_tow / lf1352.side_weight_N * weight, abs=0.2)
    change = _change_of_calibrated_pulse(setup, 1)
    assert -1.3e3 < change < 0.0
    tow = drawbar_capacity_N(rig.params, weight) / math.cos(math.radians(30.0))
    assert load_change_N(setup.scenario, rig, tow, 30.0) > -1.3e3


@pytest.mark.parametrize("machine", names())
def test_committed_calibration_is_for_the_shipped_files(machine: str) -> None:
    """The committed entry holds the hashes of the machine's own validated mechanics and
    hydraulics and of each W3 pulse: an edit of either makes it stale (refresh with
    experiments/calibrate_w3.py)."""
    own = prepare("W3", machine=machine)        # its own files, nothing calibrated yet
    hashes = input_hashes(own.scenario, Rig(own))
    entry = committed_entries()[machine]
    assert (entry.mechanics_sha256, entry.hydraulics_sha256) == (hashes.mechanics,
                                                                 hashes.hydraulics)
    assert all(entry.lookup(hashes, i) is not None for i in (0, 1))


def test_overridden_machine_is_calibrated_on_first_use_and_cached(capsys) -> None:
    """A --set model.* override (here a visual-only key) makes LF1352's committed entry
    not apply: the forces are calibrated again (stderr says why), land within 2 % of the
    target and are cached in the user cache directory for the next process."""
    setup = _calibrated(overrides={"model.chassis.length_m": 3.0})
    err = capsys.readouterr().err
    assert "W3 on machine lf1352: the committed one (W3_calibration.toml [machine.lf1352]) " \
           "is stale or for other inputs (mechanics differ" in err
    cal = setup.scenario.hitch_calibration
    assert cal is not None and cal.origin == "calibrated"
    cached = cache_dir() / f"lf1352-{cal.inputs_sha256[:32]}-w3-hitch.json"
    assert cached.is_file()
    # a run gets the same forces whether it calibrated them or read them from the cache
    # (the in-process ones were unrounded, the cached ones to 0.1 N: a W3 run on an unseen
    # layout differed in its third digit between the two)
    record = json.loads(cached.read_text())
    assert [cal.hitch_N[i] for i in record["pulse_index"]] == record["hitch_N"]
    # the calibration's own tolerance: the re-run repeats its deterministic hold-mode run
    assert _change_of_calibrated_pulse(setup, 0) == pytest.approx(2e3, rel=0.02)


@pytest.mark.slow
def test_pushing_raises_and_towing_lowers_the_idler_load_on_lf1352() -> None:
    """Physics of the two paths at equal magnitude on the rear-sprocket LF1352: a push (brake
    torque, tight top strand) moves the idler load more than a tow (drive torque, tight
    ground strand)."""
    setup = _calibrated()
    rig = Rig(setup)
    reference = idler_force_history(setup.scenario, calibration_pulse(0.0, 30.0, 0.1), rig)
    push = load_change_N(setup.scenario, rig, -3e3, 30.0, reference=reference)
    tow = load_change_N(setup.scenario, rig, 3e3, 30.0, reference=reference)
    assert push > 0.0 > tow
    assert abs(push) > abs(tow)


def _fewest_pins_carried(machine: str, hitch_N: float) -> int:
    """Fewest pins the ground carries at any step while a hitch force ``hitch_N`` [N] along
    W3's 30° chain rises over 1 s from 1 s and is held to 6 s, the machine standing in hold
    mode (valves closed)."""
    setup = prepare("W3", machine=machine)
    plant, element = hold_mode_run(setup.scenario, Rig(setup))
    pulse = LoadPulse(start_s=1.0, end_s=6.0, delta_N=0.0, hitch_N=hitch_N,
                      pull_angle_deg=30.0, rise_s=1.0)
    sc = dataclasses.replace(setup.scenario, load_pulses=(pulse,), hitch_calibration=None)
    t = COUPLING_STEP_S * np.arange(round(6.0 / COUPLING_STEP_S))
    pull, down = sc.hitch_force_N(t)
    fewest = plant.link_count
    for k in range(len(t)):
        plant.apply(StepInputs(0.0, float(pull[k]), float(down[k]), math.nan))
        plant.step(element)
        fewest = min(fewest, int(np.count_nonzero(plant.ground_forces_N()[:, 0] > 0.0)))
    return fewest


@pytest.mark.slow
@pytest.mark.parametrize("machine", ["lf1352", "compact3"])
def test_static_tipping_force_brackets_where_the_side_rolls_over(machine: str) -> None:
    """The static moment balance over the idler's line (tipping_forces_N) against the
    standing side pushed forward and up along 30°: at 0.8 of it the track stays on the
    ground (pins carried at every step), at 1.2 the side rolls over its front end (a step
    with no pin on the ground)."""
    setup = prepare("W3", machine=machine)
    push, tow = tipping_forces_N(hold_mode_run(setup.scenario, Rig(setup))[0], 30.0)
    assert 0.0 < push < tow      # the hitch is at the rear: a push tips it first
    assert _fewest_pins_carried(machine, -0.8 * push) >= 2
    assert _fewest_pins_carried(machine, -1.2 * push) == 0


@pytest.mark.slow
def test_w3_calibrates_on_a_front_sprocket_compact3_within_the_tipping_limit() -> None:
    """compact3 with its sprocket in front (6 road wheels, slide at 10°; not shipped): the
    search for its drive pulse reached the drawbar capacity's 13.8 kN push, 1.6 times its
    tipping force, and that run left physics, refusing W3. Every trial now stays within
    75 % of the static tipping force; the pulse is out of reach and says so."""
    variant = Variant("compact3", sprocket_front=True, wheel_count=6, slide_angle_deg=10.0)
    setup = _calibrated("compact3", overrides(variant))
    cal = setup.scenario.hitch_calibration
    assert cal is not None and cal.origin in ("calibrated", "cache")
    push, tow = tipping_forces_N(hold_mode_run(setup.scenario, Rig(setup))[0], 30.0)
    for reason in cal.out_of_reach:
        tried = [float(f) for f in re.findall(r"([+-]\d+) N -> ", reason)]
        assert tried and all(-TIPPING_SHARE * push - 1.0 <= f <= TIPPING_SHARE * tow + 1.0
                             for f in tried), reason
    assert all(f is not None and -TIPPING_SHARE * push - 1.0 <= f <= TIPPING_SHARE * tow + 1.0
               for f in cal.hitch_N)


RECOVERY_NOT_MET = {
    "m113": ("issue 32's floor, not met (seed 0, edges 6/8/18/20 s: never/1.26/0.86/2.16 s, "
             "measured 2026-12-08; "
             "the 0.5 s mean stays in 18.6-25.2 kN, inside the 13.3-26.7 kN band, over the "
             "5 seeds): on Chrono's rubber bushings the pulses are a 5.6 kN tow and a "
             "3.8 kN push (a 15.0 kN push that pitched the chassis by 38 mrad on the steel "
             "pins); the tow's +13 % (with the sprocket at the front a tow tightens the top "
             "strand over the idler) is not back within 5 % before it ends 2 s later, and "
             "the push's release takes 2.2 s; neither the estimator's drive-torque filter nor its "
             "y0 random walk brings them within 1 s (models/README.md, W3 on M113)"),
    "compact3": ("issue 32's floor, not met: its oil column takes only 16 % of an idler "
                 "load step in hold, so the +13 % braking pulse needs a 5.3 kN push, 36 % of "
                 "the side's weight; while it lasts the 0.5 s mean does not come back within "
                 "5 % (edge 6 s): the push rocks the rigid undercarriage forward, the pins "
                 "on the ground falling from 12.5 to 4.5-8 as the contact patch opens and "
                 "closes at ~1.1 Hz with the chassis' pitch and surge (the same with the "
                 "valves held or the idler on a 3e5 or 1e8 N/m spring), and in the "
                 "hold-mode rig the idler load peaks at 3.4 kN for the 1.7 kN plateau and "
                 "swings +-0.5-0.9 kN, 4-7 % of 13 kN, through the pulse; after it in "
                 "1.23 s, the release it asks for pulling the carrier in faster than the rod "
                 "feed fills (the rod chambers at 0.08-0.17 MPa absolute, below the 0.2 MPa "
                 "tank, in the 5 seeds)"),
}
"""Machines on which W3's recovery floor is not met yet (strict xfails: they report when
met)."""


@pytest.mark.slow
@pytest.mark.parametrize("machine", [
    pytest.param(name, marks=pytest.mark.xfail(reason=RECOVERY_NOT_MET[name], strict=True))
    for name in ("m113", "compact3")])
def test_w3_recovers_within_one_second_after_each_edge(machine: str) -> None:
    """W3 in closed loop (tp, nmpc, seed 0, 30 s): after each pulse edge the 0.5 s mean of
    F_ten is back within ±5 % of the reference within 1.0 s (acceptance metrics)."""
    result = simulate("W3", machine=machine, seed=0)
    recovery = result.metrics["acceptance"]["edge_recovery_s"]
    assert set(recovery) == {"6", "8", "18", "20"}
    assert all(r <= 1.0 for r in recovery.values()), recovery


def test_a_pulse_out_of_reach_says_which_way_its_limit_moves_the_load() -> None:
    """A target of -1.3 kN on a layout where every force raises the idler load (compact3's
    tow): the refusal names the tow at the limit with its sign and says the change goes the
    wrong way; one whose change grows towards the target but not far enough is 'short of'
    it."""
    def raises(f: float) -> float:          # [N]: the load rises with either sign of force
        return 0.1 * abs(f)

    with pytest.raises(OutOfReach, match=r"at the limit, a (tow of \+|push of -)\d+ N along "
                       r"the chain, the idler load changes by \+\d\.\d{3} kN, the wrong way "
                       r"from -1\.300 kN"):
        search(raises, -1300.0, 4000.0, (6000.0, 12000.0), what="W3 load pulse 1")
    with pytest.raises(OutOfReach, match=r"at the limit, a push of -6000 N along the chain, "
                       r"the idler load changes by -0\.600 kN, short of -1\.300 kN"):
        search(lambda f: 0.1 * f, -1300.0, -4000.0, (6000.0, 12000.0), what="W3 load pulse 1")
