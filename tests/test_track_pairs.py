"""``[track] structure = "pairs"``: two-link sub-chains keep the stated physics.

Every odd link hinged to the even link before it (trackmj/model/structure.py): 82 fewer
DOFs and half the pin connects, the contacts still at their stated stiffness, the hinged
pins' tensions the forces they transmit, every connect two pins in series, the energy
ledger closing while driving.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from test_contacts import STATIC_TOLERANCE, _static_stiffness, span_under_tension
from test_model import assert_sparse_matches_dense

from trackmj.model import ModelParams, generate_mjcf
from trackmj.model.mjcf import link_name
from trackmj.plant import PassiveTensioner, TrackPlant
from trackmj.track_energy import TrackEnergyLedger


@pytest.fixture(scope="module")
def pairs(model_params: ModelParams) -> tuple[str, ModelParams]:
    params = dataclasses.replace(model_params,
                                 track=dataclasses.replace(model_params.track,
                                                           structure="pairs"))
    return generate_mjcf(params), params


def _plant(pairs: tuple[str, ModelParams]) -> TrackPlant:
    xml, params = pairs
    return TrackPlant(mujoco.MjModel.from_xml_string(xml), params)


def test_pairs_halve_the_pin_connects(pairs, model_params: ModelParams) -> None:
    plant = _plant(pairs)
    m, n = plant.model, model_params.track.link_count
    free = TrackPlant.load().model
    assert m.nv == free.nv - n and m.neq == n // 2
    for k in range(1, n, 2):
        assert m.body(link_name(k)).parentid == m.body(link_name(k - 1)).id
        assert m.joint(link_name(k) + "_pin").type == mujoco.mjtJoint.mjJNT_HINGE
    # MuJoCo weighs a pair laid on a wrap at qpos0 up to 3.9 % more than a straight one;
    # the plant gives every link the straight pair's weight, which the contact mapping used
    links = [m.body(link_name(k)).id for k in range(n)]
    compiled = mujoco.MjModel.from_xml_string(pairs[0]).body_invweight0[links, 0]
    assert 0.01 < compiled.max() / compiled.min() - 1.0 < 0.04
    assert np.all(m.body_invweight0[links] == m.body_invweight0[links[0]])


def test_pairs_static_contact_stiffness_is_the_stated_one(pairs) -> None:
    plant = _plant(pairs)
    p = plant.params
    stated = {"ground": p.ground.stiffness_N_m, "tooth": p.contacts.tooth_stiffness_N_m}
    stiffness = _static_stiffness(plant)
    assert len(stiffness["ground"]) >= 10 and len(stiffness["rail:road_wheel"]) == 6
    for kind, values in stiffness.items():
        np.testing.assert_allclose(values, stated.get(kind, p.contacts.rail_stiffness_N_m),
                                   rtol=STATIC_TOLERANCE, err_msg=kind)


def test_pairs_span_stretches_as_its_connects_in_series(pairs) -> None:
    """The free upper span stretches by c·ΔT·2/K when its tension rises by ΔT, c the
    connects in it (each carries two pins' compliance; the hinged pins are rigid); its
    hinged pins carry the tension of their neighbours (the cfrc_int readout)."""
    plant = _plant(pairs)
    spans = [span_under_tension(plant, f) for f in (11_000.0, 15_000.0)]
    for a, b, _, _, tension in spans:
        inner = np.arange(a + 1, b)
        hinged = inner[inner % 2 == 1]
        assert len(hinged) >= 2
        np.testing.assert_allclose(tension[hinged],
                                   0.5 * (tension[hinged - 1] + tension[hinged + 1]),
                                   rtol=0.01)
    (a, b, l0, t0, _), (a1, b1, l1, t1, _) = spans
    assert (a, b) == (a1, b1)
    connects = int(np.count_nonzero(np.arange(a + 1, b + 1) % 2 == 0))
    measured = 2.0 * connects * (t1 - t0) / (l1 - l0)
    assert t1 - t0 > 1_000.0
    assert measured == pytest.approx(plant.params.pin_joint.radial_stiffness_N_m, rel=0.05)


def test_pairs_drive_closes_the_ledger(pairs) -> None:
    plant = _plant(pairs)
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
    assert abs(e.residual_J) <= 0.01 * e.drive_work_J and e.drive_work_J > 1e3


def test_pairs_sparse_and_dense_constraint_solutions_agree(pairs) -> None:
    """The sparse path (the model's) gives the dense path's solution on driven pairs states
    (upstream issue 3767)."""
    assert_sparse_matches_dense(_plant(pairs), every_ms=200, min_rows=200)


def test_pairs_refuse_the_torsional_bushings(model_params: ModelParams) -> None:
    """The bushings' torsion tendons join pitch hinges the hinged children do not have."""
    from trackmj.params import ParameterError

    p = dataclasses.replace(model_params,
                            track=dataclasses.replace(model_params.track, structure="pairs"),
                            bushings=dataclasses.replace(model_params.bushings, enabled=True))
    with pytest.raises(ParameterError, match=r"structure = \"pairs\" does not take the "
                                              r"\[bushings\] torsional"):
        generate_mjcf(p)
