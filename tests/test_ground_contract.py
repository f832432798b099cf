"""The ground's contract on the LF1352 track (trackmj/track/foundation.py): what it applies
pushes and never pulls, its friction never exceeds μ·N applied, a parked machine's pins do
not creep on a 1:2 slope, and what the plant reports is what was applied."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackmj.elements.prescribed import ConstantForce
from trackmj.machines.track_plant import load_plant
from trackmj.track.foundation import S_ON
from trackmj.track.plant import PassiveTensioner, TrackPlant

G = 9.81
FORCE_SLACK_N = 1.0
"""The issue's bound on a pull and on friction above μ·N [N]; the foundation's own
tolerance is 0.1 N."""


@pytest.fixture(scope="module")
def driven() -> tuple[TrackPlant, np.ndarray, np.ndarray]:
    """The LF1352 driven from rest to 1.5 m/s in 1 s and on to 3 s under 12.5 kN: applied
    (N, F_t) per pin and step, shape (steps, pins, 2), and the pins in contact."""
    plant = load_plant()
    element = ConstantForce(12_500.0, 2e4)
    forces, touching = [], []
    for k in range(3000):
        plant.set_track_speed(min(1.5, 1.5e-3 * k))
        plant.step(element)
        forces.append(plant.ground_forces_N())
        touching.append(plant.foundation.state[:, S_ON] > 0.0)
    return plant, np.array(forces), np.array(touching)


def test_the_ground_never_pulls_and_its_friction_stays_below_mu_n(driven) -> None:
    """Every applied normal force ≥ −1 N, every friction ≤ μ·N + 1 N, over every pin and
    step of a hard start and a drive (the regularised law pulled pins in 9 % of steps, down
    to −310 N, and broke μ·N in 16 % of loaded pin-steps)."""
    plant, forces, touching = driven
    mu = plant.params.track.ground_friction
    normal, friction = forces[..., 0], forces[..., 1]
    assert touching.sum() > 20 * len(forces)   # ~22 pins on the ground
    assert normal.min() >= -FORCE_SLACK_N
    assert np.all(np.abs(friction) <= mu * np.maximum(normal, 0.0) + FORCE_SLACK_N)
    assert plant.foundation.unresolved == 0


def test_reported_ground_forces_are_the_applied_ones(driven) -> None:
    """The group total is the sum of the per-pin forces, and over the last second the
    applied normal forces carry the weight (mean ΣN within 0.5 % of m·g: the chassis rides
    level; the start-of-step values read 4.7 % high)."""
    plant, forces, _ = driven
    assert plant.contact_forces_N()["ground"] == pytest.approx(forces[-1, :, 0].sum(),
                                                               rel=1e-12)
    weight = float(plant.model.body_subtreemass[0]) * G
    assert forces[-1000:, :, 0].sum(axis=1).mean() == pytest.approx(weight, rel=5e-3)


def test_chassis_acceleration_is_what_the_step_produced() -> None:
    """chassis_acceleration = (v₁ − v₀)/h of the chassis dofs over the step."""
    plant = load_plant()
    element = ConstantForce(12_500.0, 2e4)
    plant.set_track_speed(1.0)
    for _ in range(200):
        v0 = plant.chassis_velocity
        plant.step(element)
        expected = (plant.chassis_velocity - v0) / plant.model.opt.timestep
        np.testing.assert_allclose(plant.chassis_acceleration, expected, rtol=1e-12,
                                   atol=1e-12)


def test_a_parked_machine_does_not_creep_on_a_one_in_two_slope() -> None:
    """Gravity tilted by atan(0.5) (downhill towards −x), the speed command zero (the
    parking brake applied): after 3 s the ground pins slide less than 0.5 mm/s (the
    regularised law: 8.1 mm/s) and the ground's friction carries the weight's slope
    component (tests/test_parking_brake.py: what holds the hull)."""
    plant = load_plant()
    slope = math.atan(0.5)
    plant.model.opt.gravity[:] = (-G * math.sin(slope), 0.0, -G * math.cos(slope))
    element = PassiveTensioner.from_params(plant.params)
    plant.run(element, 3.0, 0.0)
    x0 = plant.pin_positions()[:, 0]
    touching0 = plant.foundation.state[:, S_ON] > 0.0
    plant.run(element, 1.0, 0.0)
    touching = touching0 & (plant.foundation.state[:, S_ON] > 0.0)
    slip = np.abs(plant.pin_positions()[:, 0] - x0)[touching] / 1.0
    assert touching.sum() >= 15
    assert slip.max() < 0.5e-3
    weight = float(plant.model.body_subtreemass[0]) * G
    assert plant.foundation.friction_forces_N.sum() == pytest.approx(   # uphill: +x
        weight * math.sin(slope), rel=0.02)
