"""``[track] structure``: hinged sub-chains ("chains", the default) and free links keep the
stated physics.

Chains of at most ``chain_links`` links (trackmj/track/mjcf/structure.py): each chain's links
hinged in a row, one connect per chain carrying its pins' compliance in series; two fewer
DOFs per hinged link, the contacts still at their stated stiffness, the hinged pins'
tensions the forces they transmit, a span stretching as its connects' pins in series, the
energy ledger closing while driving. ``structure = "free"`` (every pin a connect) and
two-link chains are checked the same way.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_contacts import STATIC_TOLERANCE, _static_stiffness, span_under_tension
from test_model import assert_sparse_matches_dense

from trackmj.machines.track_plant import load_plant
from trackmj.track.energy import TrackEnergyLedger
from trackmj.track.mechanics import ModelParams, load_model_params
from trackmj.track.mjcf.generate import generate_mjcf
from trackmj.track.mjcf.names import link_name
from trackmj.track.mjcf.structure import chain_sizes, chain_starts, pin_series_count
from trackmj.track.plant import PassiveTensioner, TrackPlant
from trackmj.validator import ParameterError


def _variant(model_params: ModelParams, **track) -> tuple[str, ModelParams]:
    params = dataclasses.replace(model_params,
                                 track=dataclasses.replace(model_params.track, **track))
    return generate_mjcf(params), params


@pytest.fixture(scope="module")
def pairs(model_params: ModelParams) -> tuple[str, ModelParams]:
    return _variant(model_params, chain_links=2)


@pytest.fixture(scope="module")
def free(model_params: ModelParams) -> tuple[str, ModelParams]:
    return _variant(model_params, structure="free")


def _plant(variant: tuple[str, ModelParams]) -> TrackPlant:
    xml, params = variant
    return TrackPlant(mujoco.MjModel.from_xml_string(xml), params)


@given(st.integers(20, 200), st.integers(2, 12))
def test_chain_sizes_cover_the_loop_evenly(links: int, longest: int) -> None:
    sizes = chain_sizes(links, longest)
    assert sum(sizes) == links and len(sizes) == math.ceil(links / longest)
    assert max(sizes) <= longest and max(sizes) - min(sizes) <= 1


@pytest.mark.parametrize("structure", ["default", "pairs", "free"])
def test_structure_cuts_the_loop_into_its_chains(structure: str, pairs, free,
                                                 model_params: ModelParams) -> None:
    plant = {"default": load_plant, "pairs": lambda: _plant(pairs),
             "free": lambda: _plant(free)}[structure]()
    m, p, n = plant.model, plant.params, model_params.track.link_count
    starts = chain_starts(p)
    hinged = n - len(starts)
    # 3 DOFs per free link, 1 per hinged link, besides the machine's own 11
    assert m.neq == len(starts) and m.nv == 11 + 3 * len(starts) + hinged
    assert pin_series_count(p) == dict(zip(starts, np.diff([*starts, n]), strict=True))
    for k in range(n):
        parent = m.body(link_name(k)).parentid
        if k in starts:
            assert parent == 0 and m.equality(f"pin_{k:02d}") is not None
        else:
            assert parent == m.body(link_name(k - 1)).id
            assert m.joint(link_name(k) + "_pin").type == mujoco.mjtJoint.mjJNT_HINGE
    links = [m.body(link_name(k)).id for k in range(n)]
    if structure == "free":   # identical bodies: MuJoCo's own weights agree to round-off
        np.testing.assert_allclose(m.body_invweight0[links, 0], m.body_invweight0[links[0], 0],
                                   rtol=1e-9)
    else:
        assert np.all(m.body_invweight0[links] == m.body_invweight0[links[0]])
    if structure == "pairs":
        # MuJoCo weighs a pair laid on a wrap at qpos0 up to 3.9 % more than a straight one;
        # the plant gives every link link_00's weight, which the contact mapping used
        compiled = mujoco.MjModel.from_xml_string(pairs[0]).body_invweight0[links, 0]
        assert 0.01 < compiled.max() / compiled.min() - 1.0 < 0.04


def test_pairs_static_contact_stiffness_is_the_stated_one(pairs) -> None:
    plant = _plant(pairs)
    p = plant.params
    stiffness = _static_stiffness(plant)
    assert len(stiffness["rail:road_wheel"]) == 6
    for kind, values in stiffness.items():
        target = p.contacts.tooth_stiffness_N_m if kind == "tooth" else \
            p.contacts.rail_stiffness_N_m
        np.testing.assert_allclose(values, target, rtol=STATIC_TOLERANCE, err_msg=kind)


@pytest.mark.parametrize("structure", ["default", "pairs"])
def test_span_stretches_as_its_connects_pins_in_series(structure: str, pairs) -> None:
    """The free upper span stretches by Σ m_c·ΔT/K when its tension rises by ΔT, m_c the
    pins each connect in it carries (its chain's); its hinged pins carry the tension of
    their neighbours (the cfrc_int readout)."""
    plant = load_plant() if structure == "default" else _plant(pairs)
    series = pin_series_count(plant.params)
    spans = [span_under_tension(plant, f) for f in (11_000.0, 15_000.0)]
    for a, b, _, _, tension in spans:
        inner = np.arange(a + 1, b)
        hinged = np.array([k for k in inner if k not in series])
        assert len(hinged) >= 2
        np.testing.assert_allclose(tension[hinged],
                                   0.5 * (tension[hinged - 1] + tension[hinged + 1]),
                                   rtol=0.01)
    (a, b, l0, t0, _), (a1, b1, l1, t1, _) = spans
    assert (a, b) == (a1, b1)
    pins = sum(series[k] for k in range(a + 1, b + 1) if k in series)
    measured = pins * (t1 - t0) / (l1 - l0)
    assert t1 - t0 > 1_000.0
    assert measured == pytest.approx(plant.params.pin_joint.radial_stiffness_N_m, rel=0.05)


@pytest.mark.parametrize("structure", ["pairs", "free"])
def test_drive_closes_the_ledger(structure: str, pairs, free) -> None:
    plant = _plant(pairs if structure == "pairs" else free)
    element = PassiveTensioner.from_params(plant.params)
    ledger = TrackEnergyLedger(plant)
    gaps = []
    for _ in range(2000):
        plant.set_track_speed(1.5 * min(1.0, plant.time_s))
        plant.step(element)
        ledger.after_step()
        gaps.append(plant.closure_error_m)
    e = ledger.finish()
    assert plant.warning_count == 0 and max(gaps) < 0.5e-3
    assert not plant.derailment().any
    assert abs(e.residual_J) <= 1e-6 * e.drive_work_J and e.drive_work_J > 1e3


@pytest.mark.parametrize("structure", ["pairs", "free"])
def test_sparse_and_dense_constraint_solutions_agree(structure: str, pairs, free) -> None:
    """The sparse path (the model's) gives the dense path's solution on driven states of
    either structure (upstream issue 3767)."""
    plant = _plant(pairs if structure == "pairs" else free)
    assert_sparse_matches_dense(plant, every_ms=200, min_rows=100)


def test_chains_refuse_the_torsional_bushings(model_params: ModelParams) -> None:
    """The bushings' torsion tendons join pitch hinges the chained links do not have."""
    p = dataclasses.replace(model_params,
                            bushings=dataclasses.replace(model_params.bushings, enabled=True))
    with pytest.raises(ParameterError, match=r"structure = \"chains\" does not take the "
                                              r"\[bushings\] torsional"):
        generate_mjcf(p)


def test_chains_longer_than_measured_are_refused_naming_the_key() -> None:
    """A chain of 24 links (one connect lumping 24 pins) already trips the slack-strand check
    on LF1352 at 2 m/s: the validator refuses it before any model is generated."""
    assert load_model_params(overrides={"track.chain_links": 12}).track.chain_links == 12
    with pytest.raises(ParameterError, match=r"chain_links.*\[2, 12\]"):
        load_model_params(overrides={"track.chain_links": 24})
