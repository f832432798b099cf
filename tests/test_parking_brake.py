"""The drive's parking brake (``[parking_brake]``, trackmj/track/plant.py) on LF1352: a
parked machine's hull holds on a 1:2 slope, the drive line holds as its stated spring, a
weak brake slips at its holding torque, and a zero command applies it only once the
machine has stopped."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackmj.machines.track_plant import load_plant
from trackmj.track.plant import PassiveTensioner, TrackPlant

G = 9.81


def _parked_on_slope(grade: float, overrides: dict[str, float] | None = None,
                     settle_s: float = 3.0) -> tuple[TrackPlant, PassiveTensioner]:
    """LF1352 under the passive preload, gravity tilted by atan(grade) (downhill towards −x),
    speed command zero for ``settle_s`` [s]."""
    plant = load_plant(overrides=overrides)
    slope = math.atan(grade)
    plant.model.opt.gravity[:] = (-G * math.sin(slope), 0.0, -G * math.cos(slope))
    element = PassiveTensioner.from_params(plant.params)
    plant.run(element, settle_s, 0.0)
    return plant, element


def test_a_parked_machines_hull_holds_on_a_one_in_two_slope() -> None:
    """On tan θ = 0.5 with the parking brake applied, 1 s after 3 s: the hull moves less
    than 0.5 mm/s (6.7 mm/s without the brake, the drive's servo yielding; its ground pins'
    slip and friction: tests/test_ground_contract.py, the same set-up), and the drive line
    holds the sprocket as the stated spring: drive torque = k_b·windup (the servo's damping
    adds kv·ω, ~0 at rest)."""
    plant, element = _parked_on_slope(0.5)
    assert plant.parked
    hull0 = float(plant.chassis_pose[0])
    plant.run(element, 1.0, 0.0)
    assert abs(float(plant.chassis_pose[0]) - hull0) / 1.0 < 0.5e-3
    brake = plant.params.parking_brake
    assert brake is not None
    assert plant.drive_torque_N_m == pytest.approx(
        brake.drive_line_stiffness_N_m_rad * plant.parking_brake_windup_rad, rel=0.01)


def test_a_drive_without_its_brake_creeps_at_the_servos_droop_and_a_weak_brake_slips() -> None:
    """Parked on tan θ = 0.5 for 3 s, then 1 s measured (T: the drive torque's mean over
    it). Holding torque 1 N·m (a brake that holds nothing; the range forbids 0): the
    sprocket turns back at ω = T/kv, the velocity servo's droop under the torque it carries.
    Holding torque 600 N·m, under the ~1.4 kN·m the slope asks: the brake slips with its
    spring at 600 N·m and the servo's damping carries the rest, ω = (T − 600 N·m)/kv.
    Released (speed 0.5 m/s), the drive follows its command again."""
    for holding in (1.0, 600.0):
        plant, element = _parked_on_slope(0.5, {"parking_brake.holding_torque_N_m": holding})
        angle0 = plant.sprocket_angle_rad
        torques: list[float] = []
        plant.run(element, 1.0, 0.0,
                  on_step=lambda p, out=torques: out.append(p.drive_torque_N_m))
        speed = (plant.sprocket_angle_rad - angle0) / 1.0          # [rad/s], < 0: rolling back
        kv = float(plant.model.actuator_gainprm[plant.model.actuator("sprocket_drive").id, 0])
        torque = float(np.mean(torques))
        assert torque > 1000.0, torque
        assert -speed * kv == pytest.approx(torque - holding, rel=0.03), (holding, speed)
    plant.run(element, 1.0, 0.5)
    assert not plant.parked
    assert plant.track_speed_m_s == pytest.approx(0.5, rel=0.05)


def test_a_zero_command_applies_the_brake_only_once_the_machine_has_stopped() -> None:
    """LF1352 on level ground driven to 1.0 m/s (1 s ramp, 1 s at speed), then commanded to
    zero: while the sprocket's pitch speed is above BRAKE_APPLY_SPEED_M_S the brake stays
    off and the servo decelerates it alone; the brake applies within 0.5 s; 2 s later the
    sprocket holds (pitch speed below 1 mm/s) and the hull moves less than 2 mm/s on
    average over 0.5 s."""
    plant = load_plant()
    element = PassiveTensioner.from_params(plant.params)
    plant.run(element, 2.0, lambda t: min(1.0, t))
    assert not plant.parked
    radius = plant.params.sprocket_pitch_radius_m
    rows: list[tuple[bool, float]] = []
    plant.run(element, 0.5, 0.0, on_step=lambda p, out=rows: out.append(
        (p.parked, abs(p.sprocket_speed_rad_s) * radius)))
    parked = np.array([r[0] for r in rows])
    speed = np.array([r[1] for r in rows])
    assert parked[-1]
    first = int(np.argmax(parked))
    # the step that applied it started below the speed; every step before started above
    # (the servo at its limit stops the sprocket within a step or two: test_drive_servo.py)
    assert first >= 1
    assert speed[first - 1] < plant.BRAKE_APPLY_SPEED_M_S
    assert np.all(speed[:first - 1] >= plant.BRAKE_APPLY_SPEED_M_S)
    # the abrupt stop rings the hull's surge (~1.7 Hz, ±16 mm decaying to ±3 mm)
    plant.run(element, 2.0, 0.0)
    assert abs(plant.track_speed_m_s) < 1e-3
    x0 = float(plant.chassis_pose[0])
    plant.run(element, 0.5, 0.0)
    assert abs(float(plant.chassis_pose[0]) - x0) / 0.5 < 2e-3
