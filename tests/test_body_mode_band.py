"""The track–idler–body mode band the ripple and chassis metrics split out: the study's
8-12 Hz on LF1352, and on another machine that band moved with its own first identified
mode, so it marks the machine's body mode and not its tooth passing."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from trackmj.cli.summary import summary_table
from trackmj.machines import assembly as machines
from trackmj.machines.idler import (
    EquivalentIdler,
    ModalTerm,
    body_mode_band_Hz,
    first_mode_Hz,
    load_idler,
)
from trackmj.scenarios.load import load_scenario
from trackmj.scenarios.schema import STUDY_BODY_MODE_BAND_HZ
from trackmj.sim.setup import prepare
from trackmj.validator import ParameterError

SPEED_M_S = 1.5
"""W1's track speed [m/s], where the tooth-passing band is v/pitch·(1 ± 0.1)."""


def _idler(name: str) -> EquivalentIdler:
    """The shipped machine ``name``'s identified idler (its idler file)."""
    return load_idler(machines.resolve(name).idler)


def test_first_mode_is_the_lowest_the_response_shows() -> None:
    """A relaxation (frequency 0) is no mode, nor is a term whose residue is 0 (the fit's
    bound: the response does not show it); the lowest of the rest is the first mode."""
    terms = (ModalTerm(4e-3, 1e-6, 30.0, 0.1), ModalTerm(0.0, 0.0, 3.0, 0.1),
             ModalTerm(5e-5, 0.0, 7.0, 0.05), ModalTerm(2e-5, 0.0, 0.0, 300.0))
    assert first_mode_Hz(terms) == 7.0
    assert first_mode_Hz(terms[1:2] + terms[3:]) is None


def test_lf1352_keeps_the_studys_band_and_others_move_with_their_mode() -> None:
    """On LF1352 the band is the study's 8-12 Hz exactly; on M113 and compact3 both edges
    are the study's times the ratio of their first identified mode to LF1352's (M113 4.68
    against 7.24 Hz: 5.2-7.7 Hz; compact3 8.35 Hz: 9.2-13.8 Hz)."""
    reference = _idler("lf1352")
    assert body_mode_band_Hz(reference, reference, STUDY_BODY_MODE_BAND_HZ) == (8.0, 12.0)
    for name in ("m113", "compact3"):
        own = _idler(name)
        ratio = first_mode_Hz(own.modes) / first_mode_Hz(reference.modes)
        low, high = body_mode_band_Hz(own, reference, STUDY_BODY_MODE_BAND_HZ)
        assert low == pytest.approx(8.0 * ratio, rel=1e-12)
        assert high == pytest.approx(12.0 * ratio, rel=1e-12)


@pytest.mark.parametrize("name", machines.names())
def test_body_band_sits_clear_of_the_tooth_passing_band(name: str) -> None:
    """Each shipped machine's body-mode band and its tooth-passing band at W1's 1.5 m/s
    (v/pitch ± 10 %) are disjoint, so the ripple's split counts no line twice (the study's
    8-12 Hz held M113's 8.8-10.7 Hz tooth passing whole)."""
    reference = _idler("lf1352")
    own = _idler(name)
    low, high = body_mode_band_Hz(own, reference, STUDY_BODY_MODE_BAND_HZ)
    pitch = machines.mechanics(machines.resolve(name)).track.pitch_m
    tooth = SPEED_M_S / pitch
    assert high < 0.9 * tooth or low > 1.1 * tooth


def test_a_run_takes_the_machines_band_unless_the_scenario_states_one() -> None:
    """prepare() hands M113's band to the metrics for W1 (which states none); a stated band
    wins; LF1352 gets the study's band."""
    m113 = prepare("W1", machine="m113")
    reference, own = _idler("lf1352"), _idler("m113")
    assert m113.body_mode_band_Hz == body_mode_band_Hz(own, reference,
                                                        STUDY_BODY_MODE_BAND_HZ)
    windows = m113.scenario.metric_windows(body_mode_band_Hz=m113.body_mode_band_Hz)
    assert windows.body_mode_band_Hz == m113.body_mode_band_Hz
    assert prepare("W1").body_mode_band_Hz == (8.0, 12.0)
    stated = prepare("W1", machine="m113",
                     overrides={"scenario.evaluation.body_mode_band_Hz": [6.0, 9.0]})
    assert stated.body_mode_band_Hz is None
    assert stated.scenario.metric_windows(
        body_mode_band_Hz=(1.0, 2.0)).body_mode_band_Hz == (6.0, 9.0)


def test_a_machine_band_below_the_lowpass_is_refused_before_the_run() -> None:
    """With the low-pass cut at 6 Hz, M113's derived band (from 5.2 Hz) would split ripple
    the low-pass keeps: refused with the scenario key, the band and the cut-off."""
    with pytest.raises(ParameterError, match=r"W1.toml \[evaluation\] body_mode_band_Hz: "
                       r"m113's band 5.16-7.75 Hz .* lowpass_cutoff_Hz = 6"):
        prepare("W1", machine="m113", overrides={"scenario.evaluation.lowpass_cutoff_Hz": 6.0})


def test_scenario_files_leave_the_band_to_the_machine() -> None:
    """W1-W5 and NL1 state no band (so every machine gets its own); the fallback for windows
    built without a machine is the study's."""
    for name in ("W1", "W2", "W3", "W4", "W5", "NL1"):
        scenario = load_scenario(name)
        assert scenario.evaluation.body_mode_band_Hz is None
        assert scenario.metric_windows().body_mode_band_Hz == STUDY_BODY_MODE_BAND_HZ
    assert math.isclose(STUDY_BODY_MODE_BAND_HZ[1] / STUDY_BODY_MODE_BAND_HZ[0], 1.5)


def test_the_summary_names_the_bands_it_split_the_ripple_into() -> None:
    """A newcomer reading "ripple in the body-mode band" learns which band: the summary's
    footnote gives both bands of the run's windows."""
    windows = {"lowpass_cutoff_Hz": 2.0, "tooth_passing_band_Hz": [8.766, 10.714],
               "body_mode_band_Hz": [5.164, 7.746]}
    run = SimpleNamespace(metrics={"evaluation": windows})
    table = summary_table([run], "m113")
    assert "ripple bands: tooth passing 8.77-10.7 Hz, body mode 5.16-7.75 Hz" in table


def test_the_summary_says_when_the_bands_overlap() -> None:
    """M113 at 1.0 m/s passes teeth at 6.5 Hz, inside its 5.2-7.7 Hz body-mode band: the
    footnote says both rows count what they share (their squares no longer add up to the
    ripple's)."""
    windows = {"tooth_passing_band_Hz": [5.84, 7.14], "body_mode_band_Hz": [5.164, 7.746]}
    table = summary_table([SimpleNamespace(metrics={"evaluation": windows})], "m113")
    assert "(overlapping: both rows count the ripple they share)" in table
    apart = {"tooth_passing_band_Hz": [8.766, 10.714], "body_mode_band_Hz": [5.164, 7.746]}
    assert "overlapping" not in summary_table([SimpleNamespace(metrics={"evaluation": apart})],
                                              "m113")
