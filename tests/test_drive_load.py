"""The drive torque as a measured disturbance: the idler load it makes (the layout's hand
formula against the track driven with hitch loads), its sensor, and the estimator that takes
it as a known input instead of discovering it in its disturbance state."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from trackmj.control.estimators import ExtendedKalmanFilter
from trackmj.control.governor import drive_load_allowance
from trackmj.control.model import ReducedModel, ReducedPlant, drive_load_N
from trackmj.control.sensors import Sensors
from trackmj.machines import assembly as machines
from trackmj.machines.drive_load import drive_load
from trackmj.machines.idler import load_idler
from trackmj.ports import COUPLING_STEP_S
from trackmj.results.signals import trailing_mean
from trackmj.results.verdict import run_verdict
from trackmj.sim.control_plant import nominal_plant_params, packaged_control
from trackmj.sim.drive import drive
from trackmj.sim.run import simulate
from trackmj.track.mjcf.layout import compute_layout, idler_strand_directions

HITCH_N = {"tight": 8e3, "slack": -4e3}
"""Hitch loads [N] that make the sprocket drive (a tow, > 0) or brake (a push, < 0); which of
them puts the idler on the tight side depends on the sprocket's end."""
DRIVE_S, MEAN_FROM_S = 7.0, 4.0
"""Drive length [s] and start of the mean [s]: the speed ramps over 1 s, the hitch over 2 s,
then two chassis-pitch periods settle."""
HELD_STIFFNESS_N_M = 1e9
"""The passive tensioner's spring while the stroke is held [N/m]: a few kN of drive load
move the idler by micrometres (k·Δy, k the identified idler stiffness, corrects the
remainder: under 1 % of the formula's load on every machine). Integrated implicitly through
its damping (below), so stable at any stiffness."""
HELD_DAMPING_RATIO = 0.7
"""The held spring's own damping on the idler and carrier [-]."""
TIGHT_RANGE = (0.55, 1.25)
"""The held-stroke gain on the tight side over the layout formula's G/r [-]. The formula takes
the strands inextensible; with the idler held, the sprocket's turn that stretches the tight
span relaxes the slack one, which unloads by the spans' compliance share. Measured 0.97 on
M113 driving, 0.90 on compact3 and 0.64 on LF1352 braking on its 2e8 N/m pins (0.80 on its
derived 6.08e8 N/m: :data:`STIFF_PINS`)."""
STIFF_PINS = {"pins.radial_stiffness_N_m": 6.08e8, "pins.radial_damping_N_s_m": 2.0e3}
"""LF1352's pins at their derived steel stiffness (models/lf1352.toml), damping ~3 % of
critical: the spans stretch a third as much, so the gain comes closer to the formula."""
SLACK_SHARE = 0.3
"""On the slack side the formula says 0; the held loop unloads it by the spans' compliance
share (above). Measured 0.004 (LF1352), 0.17 (compact3) and 0.14-0.24 (M113, held at
1e8-1e9 N/m: its 154 mm pitch's ±6 kN chordal swing on a 0.9 kN·m torque change) of the
tight side's G/r: bounded at 0.3."""


def held_stroke(name: str) -> dict[str, float]:
    """``[tensioner]`` overrides that hold machine ``name``'s idler at its stroke: the spring
    :data:`HELD_STIFFNESS_N_M` about the preload, made implicit by adding h·k to its damping
    (F = F_pre − k·(s₀ + h·v₁ − s_ref) − c·v₁, the element's F0 + Z·v with Z = −(c + h·k))."""
    params = machines.mechanics(machines.resolve(name))
    mass = params.idler.mass_kg + params.idler.carrier_mass_kg
    damping = 2.0 * HELD_DAMPING_RATIO * math.sqrt(HELD_STIFFNESS_N_M * mass)
    return {"tensioner.stiffness_N_m": HELD_STIFFNESS_N_M,
            "tensioner.damping_N_s_m": damping + COUPLING_STEP_S * HELD_STIFFNESS_N_M}


def test_strands_of_a_shipped_idler_are_unit_tangents() -> None:
    """Both strand directions are unit vectors leaving the idler: the upper one towards the
    sprocket's end of the machine, the lower one down towards the road wheels."""
    p = machines.mechanics(machines.resolve("lf1352"))
    layout = compute_layout(p)
    directions = idler_strand_directions(p, layout.idler_x_m)
    towards_sprocket = math.copysign(1.0, p.sprocket.x_m - layout.idler_x_m)
    for ex, ez in directions:
        assert math.hypot(ex, ez) == pytest.approx(1.0, abs=1e-12)
        assert ex * towards_sprocket > 0.9        # both strands run along the machine
    assert min(ez for _, ez in directions) < 0.0 < max(ez for _, ez in directions) + 0.1


def test_drive_load_is_the_tight_sides_share_only() -> None:
    """L = g·max(σT, 0): a front sprocket loads the idler when it drives, a rear one when it
    brakes; no load on the slack side, none from an unmeasured (NaN) torque."""
    plant = nominal_plant_params()            # LF1352: rear sprocket
    front = plant.replace(drive_tight_sign=1.0)
    g = plant.drive_load_gain_1_m
    assert drive_load_N(plant, -500.0) == pytest.approx(500.0 * g)
    assert drive_load_N(plant, 500.0) == 0.0
    assert drive_load_N(front, 500.0) == pytest.approx(500.0 * g)
    assert drive_load_N(front, -500.0) == 0.0
    assert drive_load_N(plant, math.nan) == 0.0


def held_gains(name: str, overrides: dict[str, float] | None = None) -> tuple[float, float]:
    """Machine ``name`` driven at 1.5 m/s with its idler held (:func:`held_stroke`), without
    and with each hitch load: the held-stroke gain (ΔF − k·Δy)/ΔT [1/m] on the side the
    layout formula calls tight and on the other, as multiples of its σ·G/r [-]. k is the
    identified idler stiffness, for the micrometres the stroke still moves. Once per
    machine and overrides in a session (two tests ask for LF1352's shipped gains)."""
    return _held_gains(name, tuple(sorted((overrides or {}).items())))


@functools.cache
def _held_gains(name: str, overrides: tuple[tuple[str, float], ...]) -> tuple[float, float]:
    """:func:`held_gains` with the overrides as sorted (key, value) pairs."""
    mach = machines.resolve(name)
    law = drive_load(machines.mechanics(mach))
    k = load_idler(mach.idler).stiffness_N_m
    means = {}
    for case, pull in {"none": 0.0, **HITCH_N}.items():
        series = drive(1.5, DRIVE_S, machine=name, hitch_pull_N=pull,
                       overrides={**held_stroke(name), **dict(overrides)}).timeseries
        keep = series["t_s"] >= MEAN_FROM_S
        means[case] = {c: float(series[c][keep].mean())
                       for c in ("idler_force_N", "stroke_m", "drive_torque_N_m")}
    base = means["none"]

    def held_gain(case: str) -> tuple[float, float]:
        m = means[case]
        torque = m["drive_torque_N_m"] - base["drive_torque_N_m"]
        shift = m["stroke_m"] - base["stroke_m"]
        force = m["idler_force_N"] - base["idler_force_N"] - k * shift
        # held: what the stroke still moves is under 1 % of the formula's load for the torque
        assert abs(k * shift) < 0.01 * law.gain_1_m * abs(torque)
        return force / torque / (law.tight_sign * law.gain_1_m), torque

    # a tow drives harder, a push brakes: which of them tightens the idler's strands
    tow, push = held_gain("tight"), held_gain("slack")
    assert tow[1] > 0.0 > push[1]
    tight, slack = (tow, push) if law.tight_sign > 0 else (push, tow)
    return tight[0], slack[0]


M113_BUSHED_SLACK = (
    "M113 on Chrono's rubber bushings (3.5e7 N/m, bending 1000 N·m/rad, 10 N·m·s/rad): the "
    "held loop unloads its slack side by 0.41 of G/r (the soft spans' compliance share; "
    "0.32 with the bending spring-damper off, 0.14-0.24 on 1e8-1e9 N/m steel pins), past "
    "SLACK_SHARE; the layout law's max(σT, 0) no longer describes its braking side "
    "(issue 30 item 1, left to the lead: the law or the bound)")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["lf1352", pytest.param("m113", marks=pytest.mark.xfail(
    reason=M113_BUSHED_SLACK, strict=True)), "compact3"])
def test_drive_torque_loads_the_idler_as_the_layout_says(name: str) -> None:
    """dL/dT = σ·G/r on the tight side (L = G/r·max(σT, 0)) within :data:`TIGHT_RANGE` of
    the held-stroke gain, and on the other side below :data:`SLACK_SHARE` of it."""
    tight, slack = held_gains(name)
    assert TIGHT_RANGE[0] <= tight <= TIGHT_RANGE[1]
    assert abs(slack) <= SLACK_SHARE


@pytest.mark.slow
def test_stiffer_pins_bring_the_held_gain_to_the_inextensible_formula() -> None:
    """LF1352 braking: with its pins at the derived 6.08e8 N/m instead of 2e8 the spans
    share less of the torque with the slack side, and the tight side's held-stroke gain
    comes within 25 % of the inextensible formula (measured 0.64 -> 0.80)."""
    shipped, _ = held_gains("lf1352")
    steel, _ = held_gains("lf1352", STIFF_PINS)
    assert abs(steel - 1.0) < abs(shipped - 1.0)
    assert steel == pytest.approx(1.0, abs=0.25)


def test_torque_sensor_noise_is_its_own_stream() -> None:
    """The torque channel adds its stated noise and leaves the other channels' numbers as
    they were without it (the same seed draws the same pressure and stroke noise)."""
    cfg = packaged_control().sensors
    with_torque, without = Sensors(cfg, 7), Sensors(cfg, 7)
    samples = np.array([with_torque.measure((1e6, 0.0, 0.05), 800.0) for _ in range(20000)])
    plain = np.array([without.measure((1e6, 0.0, 0.05)) for _ in range(20000)])
    np.testing.assert_array_equal(samples[:, :3], plain)
    # sample std of 20000 normals: relative standard error 1/sqrt(2·20000) = 0.5 %
    assert samples[:, 3].std() == pytest.approx(cfg.drive_torque_noise_std_N_m, rel=0.025)
    assert samples[:, 3].mean() == pytest.approx(800.0, abs=5 * 50.0 / math.sqrt(20000))
    assert math.isnan(Sensors(cfg, 7).measure((1e6, 0.0, 0.05), math.nan)[3])
    # a plant state's fourth entry (its velocity) is no torque
    assert len(Sensors(cfg, 7).measure((1e6, 0.0, 0.05, 0.1))) == 3


def test_estimator_explains_a_torque_step_by_the_torque() -> None:
    """A braking torque step on LF1352's reduced plant (rear sprocket: the idler's strands
    tighten) in hold: the EKF given the torque keeps y0 where it was, the EKF without it
    moves y0 by the load's L/k to explain the tension."""
    plant = nominal_plant_params()
    model, cfg = ReducedModel(plant), packaged_control()
    torque = -300.0
    load = drive_load_N(plant, torque)
    shift = load / plant.stiffness_N_m          # ~0.8 mm
    x0 = model.equilibrium(15e3)
    truth = ReducedPlant(plant, x0)
    sensors = Sensors(cfg.sensors, 3)
    told = ExtendedKalmanFilter(model, cfg.estimator, 1e-3, x0)
    blind = ExtendedKalmanFilter(model, cfg.estimator, 1e-3, x0)
    y0 = plant.free_position_m
    for k in range(1500):
        applied = torque if k >= 300 else 0.0
        x = truth.step(0.0, plant.supply_pressure_Pa, y0=y0 - drive_load_N(plant, applied)
                       / plant.stiffness_N_m)
        z = sensors.measure(x, applied)
        if k == 1490:
            told.period_mean()                  # the last period's mean starts here
        told.step(z, 0.0, plant.supply_pressure_Pa)
        blind.step(z[:3], 0.0, plant.supply_pressure_Pa)
    assert abs(told.x[4] - y0) < 0.1 * shift
    assert y0 - blind.x[4] == pytest.approx(shift, rel=0.3)
    # the period's mean load from 10 noisy torques: σ_T·g/sqrt(10) ~ 190 N of 3.6 kN
    assert told.period_mean()[5] == pytest.approx(load, rel=0.2)


def test_allowance_rejects_what_the_band_takes_at_the_loads_end() -> None:
    """Hand cases of max(0, s·L − (F_ref − lo)): with lo = 10.5 kN and F_ref = 15 kN a held
    share up to 4.5 kN is rejected whole (the tension would drop to lo when the load ends),
    a 9 kN share rides 4.5 kN above the reference, and no load none."""
    ref = np.array([15e3, 15e3, 15e3, 12e3])
    held = np.array([2e3, 4.5e3, 9e3, 2e3])
    allowance = [float(drive_load_allowance(ref[i:i + 1], 10.5e3, held[i])[0])
                 for i in range(4)]
    assert allowance == pytest.approx([0.0, 0.0, 4.5e3, 0.5e3])
    assert drive_load_allowance(ref, 10.5e3, 0.0).tolist() == [0.0] * 4


def test_hold_share_is_the_oil_spring_in_series_with_the_idler() -> None:
    """s = k_h/(k_h + k), k_h = β·A_h²/V_h at the hold volume of the tension: on the
    reduced plant, a load step in hold moves the tension by s·L (RK4, 2 s to settle)."""
    plant = nominal_plant_params()
    model = ReducedModel(plant)
    x0 = model.equilibrium(15e3)
    share = model.hold_load_share(15e3)
    loaded, unloaded = ReducedPlant(plant, x0), ReducedPlant(plant, x0)
    load = 2e3
    for _ in range(2000):
        loaded.step(0.0, plant.supply_pressure_Pa,
                    y0=plant.free_position_m - load / plant.stiffness_N_m)
        unloaded.step(0.0, plant.supply_pressure_Pa)
    # the seal leakage bleeds both alike; the difference is the load's (head volume and
    # bulk modulus change by < 1 % over the 0.3 mm the load moves the carrier)
    assert loaded.force - unloaded.force == pytest.approx(share * load, rel=0.01)
    assert 0.0 < share < 1.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "M113 on Chrono's rubber bushings: the chain's bending spring-damper takes part of the "
    "sprocket's torque, T = r·(T₁ − T₂) + bending moments, so the 0.5 s mean falls to 0.918 "
    "of G·T/r at 0.88 s (seed 0; 0.941 with the bending damper off, 0.962 with the bending "
    "spring off too, 0.95 asked); the floor needs the bending term (issue 30 item 1, left "
    "to the lead)"))
def test_m113s_w2_start_sits_on_the_drives_floor_above_the_band() -> None:
    """M113 (front sprocket) on W2's 1 s start ramp to 2 m/s, closed loop (tp, nmpc, seed 0,
    2 s): the sprocket's moment balance T₁ − T₂ = T/r with the slack side at T₂ ≥ 0 leaves
    the idler's strands at least T/r each, so its load cannot fall below G·T/r whatever the
    tensioner does (statics). The trailing 0.5 s mean of F_ten stays at or above 0.95 of the
    same mean of G·max(T, 0)/r (the strands' weight and inertia, which add to it, and the
    spans' share of the pull are what the 5 % leaves), and at its highest, 1.0 s, that floor
    is above the band's top (4/3 × 20 kN): the verdict names the breach as the drive's."""
    result = simulate("W2", machine="m113", seed=0, duration=2.0)
    cols = result.columns()
    t, force = cols["t_s"], cols["tension_N"]
    load = drive_load(machines.mechanics(machines.resolve("m113")))
    assert load.tight_sign == 1.0
    floor = load.gain_1_m * np.maximum(cols["drive_torque_N_m"], 0.0)
    mean_force, mean_floor = trailing_mean(t, force, 0.5), trailing_mean(t, floor, 0.5)
    after = t >= 0.5
    assert np.all(mean_force[after] >= 0.95 * mean_floor[after])
    assert mean_floor.max() > 20e3                   # the floor is not trivially met
    v = run_verdict(result.metrics)
    assert v is not None and v.band_forced_by_drive
    assert v.drive_floor_at_max_N >= v.band_N[1] == pytest.approx(4.0 / 3.0 * 20e3)
    assert "no tensioner could keep the mean in" in v.text()
