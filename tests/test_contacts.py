"""Stated contact and pin parameters are the simulated ones (trackmj/track/mjcf/soft.py and the
ground foundation, trackmj/track/foundation.py).

Static: force / penetration of every loaded contact of the standing track equals the
stated stiffness of its kind, and the foundation carries the weight at its stated
stiffness. Dynamic: the free vibration of a mass on a contact mapped by
:func:`trackmj.track.mjcf.soft.soft_constraint` decays with the stated damping and rings with the
stated stiffness on the documented mass m + m_a, as semi-implicit Euler integrates them.
Pins: a free span of free links stretches as n pins in series, steel or rubber-bushed
(the chained structure's spans: tests/test_track_chains.py).
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from trackmj.elements.prescribed import ConstantForce
from trackmj.track.foundation import S_DELTA
from trackmj.track.mechanics import ModelParams
from trackmj.track.mjcf.generate import generate_mjcf
from trackmj.track.mjcf.soft import row_diag, soft_constraint
from trackmj.track.plant import TrackPlant

STATIC_TOLERANCE = 0.10   # the bound; measured within 3 %


def _kind(model: mujoco.MjModel, g1: int, g2: int) -> str | None:
    names = (model.geom(g1).name, model.geom(g2).name)
    partner = names[0] if not names[0].startswith("link_") else names[1]
    if partner == "ground":
        return "ground"
    if partner.startswith("sprocket_tooth_"):
        return "tooth"
    for prefix in ("sprocket_hub", "idler_wheel", "road_wheel_", "return_roller_"):
        if partner.startswith(prefix):
            return "rail:" + prefix.rstrip("_")
    return None


def _static_stiffness(plant: TrackPlant, force_N: float = 13_000.0) -> dict[str, list[float]]:
    """Time-averaged normal force / penetration of each contact loaded throughout 0.3 s of
    a standing track settled under ``force_N`` [N], grouped by kind [N/m]."""
    plant.run(ConstantForce(force_N, 2e4), 1.5)
    m, d = plant.model, plant.data
    sums: dict[tuple[int, int], list[float]] = {}
    wrench = np.zeros(6)
    steps = 300
    for _ in range(steps):
        plant.step(ConstantForce(force_N, 2e4))
        for i in range(d.ncon):
            c = d.contact[i]
            mujoco.mj_contactForce(m, d, i, wrench)
            entry = sums.setdefault((int(c.geom1), int(c.geom2)), [0.0, 0.0, 0])
            entry[0] += wrench[0]
            entry[1] += -c.dist
            entry[2] += 1
    out: dict[str, list[float]] = {}
    for (g1, g2), (force, pen, count) in sums.items():
        kind = _kind(m, g1, g2)
        if kind is None or count < steps or pen / count < 5e-6:
            continue   # contacts that opened during the window or carry (almost) nothing
        out.setdefault(kind, []).append(force / pen)
    return out


def _standing_foundation(plant: TrackPlant) -> tuple[float, float, float]:
    """(Σ ground normal force [N], Σ penetration of the loaded pins [m], Σ K·δ over them
    [N]) of the track standing settled (after :func:`_static_stiffness`)."""
    f = plant.foundation
    loaded = f.normal_forces_N > 0.0
    delta = f.state[loaded, S_DELTA]
    return (float(f.normal_forces_N.sum()), float(delta.sum()),
            float(f.stiffness_N_m * delta.sum()))


def test_static_contact_stiffness_is_the_stated_one(plant: TrackPlant) -> None:
    """Every MuJoCo contact at its stated stiffness; the foundation carries the machine's
    weight with each loaded pin at N = K·δ (at rest its damping term vanishes)."""
    p = plant.params
    stiffness = _static_stiffness(plant)
    assert {"rail:sprocket_hub", "rail:idler_wheel", "rail:road_wheel",
            "rail:return_roller"} <= set(stiffness) and "ground" not in stiffness
    assert len(stiffness["rail:road_wheel"]) == 6
    for kind, values in stiffness.items():
        target = p.contacts.tooth_stiffness_N_m if kind == "tooth" else \
            p.contacts.rail_stiffness_N_m
        np.testing.assert_allclose(values, target, rtol=STATIC_TOLERANCE, err_msg=kind)
    total, _, elastic = _standing_foundation(plant)
    weight = float(plant.model.body_subtreemass[0]) * p.simulation.gravity_m_s2
    assert total == pytest.approx(weight, rel=0.005)
    assert elastic == pytest.approx(total, rel=0.005)
    assert np.count_nonzero(plant.foundation.normal_forces_N) >= 10


def test_contact_stiffness_scale_multiplies_the_physical_stiffness(plant: TrackPlant) -> None:
    """W5's perturbation keeps its meaning: x1.2 gives 1.2 x the stated ground stiffness
    (the weight on 1/1.2 of the sinkage) and 1.2 x every contact's."""
    _static_stiffness(plant)
    _, sinkage, _ = _standing_foundation(plant)
    plant.reset()
    plant.scale_contact_stiffness(1.2)
    wheels = _static_stiffness(plant)["rail:road_wheel"]
    total, scaled_sinkage, elastic = _standing_foundation(plant)
    assert plant.foundation.stiffness_N_m == pytest.approx(1.2 * plant.params.ground
                                                           .stiffness_N_m, rel=1e-12)
    assert elastic == pytest.approx(total, rel=0.005)
    assert scaled_sinkage == pytest.approx(sinkage / 1.2, rel=0.05)
    np.testing.assert_allclose(wheels, 1.2 * plant.params.contacts.rail_stiffness_N_m,
                               rtol=STATIC_TOLERANCE)


def _contact_oscillator(mass_kg: float, stiffness: float, damping: float, condim: int,
                        friction: float) -> tuple[mujoco.MjModel, float]:
    """A body on a vertical slide resting with a sphere on a plane whose contact is mapped
    from (stiffness, damping); returns the model and the mapping's apparent mass [kg]."""
    xml = f"""<mujoco><option timestep="0.001" gravity="0 0 -9.81" integrator="implicitfast"
      cone="pyramidal"/><worldbody>
      <geom name="floor" type="plane" size="1 1 0.1" condim="{condim}" priority="1"
       friction="{friction} 0.005 0.0001"/>
      <body name="mass" pos="0 0 0.02"><joint name="z" type="slide" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="{mass_kg}" diaginertia="1 1 1"/>
      <geom name="ball" type="sphere" size="0.02" condim="1"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    rows, diag = row_diag(float(model.body_invweight0[1, 0]), condim, friction)
    soft = soft_constraint(stiffness, damping, rows, diag, 1e-3, 2.0, "test")
    floor = model.geom("floor").id
    model.geom_solref[floor] = soft.solref
    model.geom_solimp[floor] = soft.solimp
    return model, soft.apparent_mass_kg


@pytest.mark.parametrize(("stiffness", "damping", "condim", "mass_kg"),
                         [(2.0e6, 2.0e4, 3, 100.0),    # the MJCF ground (viewer), pyramidal
                          (1.0e7, 1.2e4, 1, 200.0)])   # rail contact, frictionless
def test_contact_free_vibration_has_the_stated_damping(stiffness: float, damping: float,
                                                       condim: int, mass_kg: float) -> None:
    """Released 0.1 mm above its rest penetration, the mass rings as the explicit
    semi-implicit Euler step of M·r̈ = −K·r − B·ṙ with M = m + m_a: a discrete pole z with
    |z|² = 1 − hB/M and 2·Re z = 2 − hB/M − h²K/M. K and B recovered from the fitted pole
    must be the stated ones."""
    model, apparent = _contact_oscillator(mass_kg, stiffness, damping, condim, 0.8)
    data = mujoco.MjData(model)
    h, g = 1e-3, 9.81
    rest = 0.02 - mass_kg * g / stiffness
    data.qpos[0] = rest - 0.02 + 1e-4   # slide coordinate: body at rest height + 0.1 mm
    z = []
    for _ in range(200):
        mujoco.mj_step(model, data)
        z.append(data.qpos[0] - (rest - 0.02))
    z = np.array(z)
    # x_{n+2} = a1·x_{n+1} + a0·x_n for the homogeneous discrete oscillator: least squares
    a1, a0 = np.linalg.lstsq(np.column_stack([z[1:-1], z[:-2]]), z[2:], rcond=None)[0]
    total = mass_kg + apparent
    damping_fit = (1.0 + a0) * total / h          # |z|² = −a0 = 1 − hB/M
    stiffness_fit = (2.0 - a1 - h * damping_fit / total) * total / h ** 2
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    assert damping_fit == pytest.approx(damping, rel=0.10)
    assert stiffness_fit == pytest.approx(stiffness, rel=0.10)
    assert math.isfinite(apparent) and apparent > 0.0


def _free_plant(params: ModelParams, bushings: bool) -> TrackPlant:
    """Free links (every pin a connect), steel pins or the rubber bushings."""
    free = dataclasses.replace(params, track=dataclasses.replace(params.track,
                                                                structure="free"),
                               bushings=dataclasses.replace(params.bushings, enabled=bushings))
    return TrackPlant(mujoco.MjModel.from_xml_string(generate_mjcf(free)), free)


def span_under_tension(plant: TrackPlant, force_N: float) -> tuple[int, int, float, float,
                                                                   np.ndarray]:
    """Settle standing under ``force_N`` on the idler, then over 200 steps the upper span
    between return roller 2 and the idler (pins a..b): its mean length along the links (sum
    of pin-to-pin distances, blind to sag and kinks) [m], the mean tension of its pins
    a+1..b [N], and the last step's pin tensions [N]."""
    p = plant.params
    ride = p.chassis.ride_height_m
    x_lo, x_hi = max(p.return_rollers.x_m) + 0.12, p.idler.x_m - 0.3
    plant.reset()
    plant.run(ConstantForce(force_N, 2e4), 1.5)
    pins = plant._chassis_frame_pins()
    span = np.nonzero((pins[:, 0] > x_lo) & (pins[:, 0] < x_hi) & (pins[:, 1] > 0.3 - ride))[0]
    assert len(span) >= 5 and np.all(np.diff(span) == 1)
    a, b = int(span[0]), int(span[-1])
    samples = []
    for _ in range(200):
        plant.step(ConstantForce(force_N, 2e4))
        pos = plant.pin_positions()[a:b + 1]
        tension = plant.pin_tensions_N()
        samples.append((np.linalg.norm(np.diff(pos, axis=0), axis=1).sum(),
                        tension[a + 1:b + 1].mean()))
    length, mean_tension = np.mean(samples, axis=0)
    return a, b, float(length), float(mean_tension), tension


@pytest.mark.slow
@pytest.mark.parametrize("pins", ["steel", "bushings"])
def test_free_span_stretches_as_pins_in_series(model_params: ModelParams, pins: str) -> None:
    """On free links the upper span between return roller 2 and the idler holds n pins in
    series: its length along the links grows by n·ΔT/K when the tension rises by ΔT (the
    links are rigid), for the steel pins and for the rubber bushings."""
    plant = _free_plant(model_params, bushings=pins == "bushings")
    p = plant.params
    assert p.pin_joint_table == ("pins" if pins == "steel" else "bushings")
    (_, _, l0, t0, _), (a, b, l1, t1, _) = (span_under_tension(plant, f)
                                            for f in (11_000.0, 15_000.0))
    measured = (b - a) * (t1 - t0) / (l1 - l0)
    assert t1 - t0 > 1_000.0
    assert measured == pytest.approx(p.pin_joint.radial_stiffness_N_m, rel=0.05)
