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
from test_contacts import STATIC_TOLERANCE, _static_stiffness

from trackmj.elements import ConstantForce
from trackmj.model import ModelParams, generate_mjcf
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
        assert m.body(f"link_{k:02d}").parentid == m.body(f"link_{k - 1:02d}").id
        assert m.joint(f"link_{k:02d}_pin").type == mujoco.mjtJoint.mjJNT_HINGE
    # both links of a pair weigh alike in MuJoCo's row diagonals (one solref per partner
    # stays exact) on straight runs; pairs laid on a wrap at qpos0 weigh up to 3.9 % more
    weights = m.body_invweight0[[m.body(f"link_{k:02d}").id for k in range(n)], 0]
    np.testing.assert_allclose(weights[0::2], weights[1::2], rtol=1e-12)
    assert np.count_nonzero(np.isclose(weights, weights[0], rtol=1e-6)) >= n // 2
    np.testing.assert_allclose(weights, weights[0], rtol=0.04)


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
    connects in it (each carries two pins' compliance; the hinged pins are rigid); the
    hinged pins there carry the tension of their neighbours (cfrc_int readout)."""
    plant = _plant(pairs)
    p = plant.params
    ride = p.chassis.ride_height_m
    x_lo, x_hi = max(p.return_rollers.x_m) + 0.12, p.idler.x_m - 0.3
    lengths, tensions = [], []
    for force in (11_000.0, 15_000.0):
        plant.reset()
        plant.run(ConstantForce(force, 2e4), 1.5)
        pins = plant._chassis_frame_pins()
        span = np.nonzero((pins[:, 0] > x_lo) & (pins[:, 0] < x_hi) & (pins[:, 1] > 0.3 - ride))[0]
        assert len(span) >= 5 and np.all(np.diff(span) == 1)
        a, b = span[0], span[-1]
        samples = []
        for _ in range(200):
            plant.step(ConstantForce(force, 2e4))
            pos = plant.pin_positions()[a:b + 1]
            tension = plant.pin_tensions_N()
            samples.append((np.linalg.norm(np.diff(pos, axis=0), axis=1).sum(),
                            tension[a + 1:b + 1].mean()))
        inner = np.arange(a + 1, b)
        hinged = inner[inner % 2 == 1]
        np.testing.assert_allclose(tension[hinged],
                                   0.5 * (tension[hinged - 1] + tension[hinged + 1]),
                                   rtol=0.01)
        length, mean_tension = np.mean(samples, axis=0)
        lengths.append(length)
        tensions.append(mean_tension)
    connects = int(np.count_nonzero(np.arange(a + 1, b + 1) % 2 == 0))
    measured = 2.0 * connects * (tensions[1] - tensions[0]) / (lengths[1] - lengths[0])
    assert tensions[1] - tensions[0] > 1_000.0
    assert measured == pytest.approx(p.pin_joint.radial_stiffness_N_m, rel=0.05)


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
    """The sparse path (the model's) gives the dense path's accelerations, constraint forces
    and Newton iteration count on driven pairs states (upstream issue 3767)."""
    plant = _plant(pairs)
    m, d = plant.model, plant.data
    states: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def keep(pl: TrackPlant) -> None:
        if round(pl.time_s * 1000) % 200 == 0:
            states.append((d.qpos.copy(), d.qvel.copy(), d.ctrl.copy()))

    plant.run(PassiveTensioner.from_params(plant.params), 1.0,
              lambda t: 1.5 * min(1.0, t / 0.5), keep)
    for qpos, qvel, ctrl in states:
        results = []
        for jacobian in (mujoco.mjtJacobian.mjJAC_DENSE, mujoco.mjtJacobian.mjJAC_SPARSE):
            m.opt.jacobian = jacobian
            probe = mujoco.MjData(m)
            probe.qpos[:], probe.qvel[:], probe.ctrl[:] = qpos, qvel, ctrl
            mujoco.mj_forward(m, probe)
            results.append((probe.qacc.copy(), probe.efc_force[: probe.nefc].copy(),
                            int(probe.solver_niter[0])))
        (acc_d, force_d, iter_d), (acc_s, force_s, iter_s) = results
        assert len(force_d) == len(force_s) > 200
        np.testing.assert_allclose(acc_s, acc_d, rtol=0, atol=1e-9 * np.abs(acc_d).max())
        np.testing.assert_allclose(force_s, force_d, rtol=0, atol=1e-9 * np.abs(force_d).max())
        assert iter_s == iter_d
    assert len(states) == 5


def test_pairs_refuse_the_torsional_bushings(model_params: ModelParams) -> None:
    """The bushings' torsion tendons join pitch hinges the hinged children do not have."""
    from trackmj.params import ParameterError

    p = dataclasses.replace(model_params,
                            track=dataclasses.replace(model_params.track, structure="pairs"),
                            bushings=dataclasses.replace(model_params.bushings, enabled=True))
    with pytest.raises(ParameterError, match=r"structure = \"pairs\" does not take the "
                                              r"\[bushings\] torsional"):
        generate_mjcf(p)
