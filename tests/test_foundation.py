"""The ground foundation force element (trackmj/track/foundation.py) on small hand-checkable models.

Static sinkage is the load over the stated stiffness; a free vibration rings as the
semi-implicit Euler step with the spring explicit and the damper implicit, from which the
stated K and B are recovered; friction creeps at the regularised law's speed below the
Coulomb limit and slides at μ·N above it; the work booked per step closes the energy
balance; the ground line's closest point, normal and sign are the hand-derived ones on a
slope and round a corner.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from trackmj.track.foundation import (
    S_DELTA,
    S_N,
    Foundation,
    FoundationLaw,
    _closest,
    foundation_work,
    ground_line,
    step,
)

H, G = 1e-3, 9.81
LAW = FoundationLaw(stiffness_N_m=2.0e6, damping_N_s_m=2.0e4, friction=0.8, slip_m_s=0.01)
RADIUS = 0.014


def _block(mass_kg: float) -> str:
    """A block on world slides x, z and a pitch hinge, its centre of mass at the body origin
    between two pin spheres at x = ±0.1 m; a drive motor on x. The hinge sits 5 cm off the
    centre of mass (the same planar motion), which makes MuJoCo store the body's mass
    matrix rows in full, as for the track's links (a body with its joints at its centre of
    mass is 'simple': diagonal rows, which the foundation refuses)."""
    return f"""<mujoco><option timestep="{H}" gravity="0 0 -{G}" integrator="implicitfast"/>
      <worldbody><geom name="ground" type="plane" size="10 1 0.1"/>
      <body name="block" pos="0 0 {RADIUS}"><joint name="x" type="slide" axis="1 0 0"/>
      <joint name="z" type="slide" axis="0 0 1"/><joint name="pitch" type="hinge"
      axis="0 1 0" pos="0.05 0 0"/><inertial pos="0 0 0" mass="{mass_kg}"
      diaginertia="0.5 0.5 0.5"/>
      <geom name="pin_a" type="sphere" size="{RADIUS}" pos="-0.1 0 0"/>
      <geom name="pin_b" type="sphere" size="{RADIUS}" pos="0.1 0 0"/></body></worldbody>
      <actuator><motor name="pull" joint="x"/></actuator></mujoco>"""


def _setup(xml: str, law: FoundationLaw = LAW) -> tuple[mujoco.MjModel, mujoco.MjData,
                                                         Foundation]:
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    pins = [g for g in range(model.ngeom) if model.geom(g).name.startswith("pin_")]
    return model, data, Foundation(model, data, pins, law)


def test_static_sinkage_is_the_load_over_the_stated_stiffness() -> None:
    """Blocks of 300 and 400 kg on two pins settle at δ = m·g/(2·K) per pin (the
    foundation's only stiffness), level, and the ground force equals the weight; the
    MJCF ground contact is off (no MuJoCo contacts)."""
    for mass in (300.0, 400.0):
        model, data, foundation = _setup(_block(mass))
        for _ in range(2000):
            step(model, data, foundation)
        assert data.ncon == 0
        np.testing.assert_allclose(foundation.state[:, S_DELTA],
                                   mass * G / 2.0 / LAW.stiffness_N_m, rtol=1e-9)
        assert foundation.normal_forces_N.sum() == pytest.approx(mass * G, rel=1e-9)
        assert abs(data.qpos[2]) < 1e-9   # level: the pins alike


def test_free_vibration_rings_with_the_stated_stiffness_and_damping() -> None:
    """Released 0.1 mm above its rest sinkage, a block on two pins (2·K and 2·B in
    parallel) follows (m + 2hB)·(v₁ − v₀) = −h·(2K·x₀ + 2B·v₀), x₁ = x₀ + h·v₁ (the spring
    explicit, the damper implicit): x_{n+2} = a₁·x_{n+1} + a₀·x_n with
    a₀ = −m/(m + 2hB) and a₁ = 1 + (m − 2h²K)/(m + 2hB). K and B recovered from the fitted
    a₀, a₁ are the stated ones, for a lightly and a heavily damped foundation."""
    mass = 200.0
    for damping in (500.0, LAW.damping_N_s_m):
        law = FoundationLaw(LAW.stiffness_N_m, damping, 0.0, LAW.slip_m_s)
        model, data, foundation = _setup(_block(mass), law)
        rest = -mass * G / (2.0 * law.stiffness_N_m)
        data.qpos[1] = rest + 1e-4
        x = []
        for _ in range(60):
            step(model, data, foundation)
            x.append(data.qpos[1] - rest)
        x = np.array(x)
        assert foundation.state[:, S_N].min() > 0.0   # in contact throughout
        a1, a0 = np.linalg.lstsq(np.column_stack([x[1:-1], x[:-2]]), x[2:], rcond=None)[0]
        total = -mass / a0
        assert (total - mass) / (2.0 * H) == pytest.approx(damping, rel=1e-6)
        assert (mass - (a1 - 1.0) * total) / (2.0 * H ** 2) == pytest.approx(
            law.stiffness_N_m, rel=1e-6)


def test_friction_creeps_below_the_coulomb_limit_and_slides_above() -> None:
    """A 100 kg block on two pins pulled sideways with F: below μ·m·g it creeps at the regularised
    law's speed v = s·F / sqrt((μ·m·g)² − F²) (both pins slip alike, whatever the
    tilt the friction's moment gives); above it, it accelerates at
    (F − μ·m·g)/m once its speed is far above s."""
    mass = 100.0
    limit = LAW.friction * mass * G
    for fraction in (0.5, 0.9):
        model, data, foundation = _setup(_block(mass))
        data.ctrl[0] = fraction * limit
        for _ in range(1500):
            step(model, data, foundation)
        expected = LAW.slip_m_s * fraction / math.sqrt(1.0 - fraction ** 2)
        assert data.qvel[0] == pytest.approx(expected, rel=1e-3)
    model, data, foundation = _setup(_block(mass))
    data.ctrl[0] = 1.5 * limit
    for _ in range(1000):
        step(model, data, foundation)
    v0 = data.qvel[0]
    for _ in range(100):
        step(model, data, foundation)
    assert v0 > 100 * LAW.slip_m_s
    assert (data.qvel[0] - v0) / 0.1 == pytest.approx(0.5 * limit / mass, rel=2e-3)


def test_the_booked_work_closes_the_energy_balance() -> None:
    """A block on two pins dropped 5 mm onto the foundation, pitching and pulled sideways:
    per step semi-implicit Euler gives ½v₁ᵀM₀v₁ − ½v₀ᵀM₀v₀ = W − ½ΔvᵀM₀Δv, M₀ the mass
    matrix of the step's start and W the work of every force on Δq = h·v₁; with the
    foundation's work booked as integrated, Σ(F(v₀) − C·J·Δv)·(J·Δq), the pull's and the
    bias forces' (gravity, Coriolis), the balance closes to round-off."""
    model, data, foundation = _setup(_block(50.0))
    data.qpos[1] = 0.005
    data.qvel[2] = 0.5   # a pitch rate: the pins strike one after the other
    data.ctrl[0] = 200.0
    mass_matrix = np.zeros((model.nv, model.nv))
    work, other, kinetic, jump = np.zeros(2), 0.0, 0.0, 0.0
    for _ in range(400):
        v0 = data.qvel.copy()
        step(model, data, foundation)
        v1 = data.qvel
        foundation_work(foundation.state, foundation.jac, foundation.pins, foundation.dofs,
                        v0, v1, H, work)
        dq = H * v1
        other += data.ctrl[0] * dq[0] - data.qfrc_bias @ dq
        mujoco.mj_fullM(model, data, mass_matrix)   # M of the step's start (restored)
        kinetic += 0.5 * (v1 @ mass_matrix @ v1 - v0 @ mass_matrix @ v0)
        jump += 0.5 * (v1 - v0) @ mass_matrix @ (v1 - v0)
    assert foundation.state[:, S_N].min() > 0.0 and work[1] < 0.0 < other
    assert kinetic == pytest.approx(work.sum() + other - jump, abs=1e-9 * other)


def test_closest_point_on_a_slope_and_round_corners() -> None:
    """Signed distance and normal of the ground line: above a 10 % slope the normal is
    (−0.1, 1)/√1.01 and the distance the vertical gap times cos; below the line both
    turn; beside a ridge (a convex corner) the closest point is the corner; past the
    line's end its last height is held."""
    line = np.array([[0.0, 0.0], [1.0, 0.1], [2.0, 0.0]])
    c = 1.0 / math.sqrt(1.01)
    d, nx, nz = _closest(line, 0.5, 0.05 + 0.01, 0.05)
    assert d == pytest.approx(0.01 * c, rel=1e-12)
    assert (nx, nz) == pytest.approx((-0.1 * c, c), rel=1e-12)
    d, nx, nz = _closest(line, 0.5, 0.05 - 0.002, 0.05)
    assert d == pytest.approx(-0.002 * c, rel=1e-12)
    assert (nx, nz) == pytest.approx((-0.1 * c, c), rel=1e-12)
    d, nx, nz = _closest(line, 1.0, 0.12, 0.05)   # above the ridge: its corner
    assert d == pytest.approx(0.02, rel=1e-12) and (nx, nz) == pytest.approx((0.0, 1.0))
    d, nx, nz = _closest(line, 3.0, 0.01, 0.05)   # beyond the end: z = 0 held
    assert d == pytest.approx(0.01, rel=1e-12) and (nx, nz) == pytest.approx((0.0, 1.0))


def test_ground_line_of_a_heightfield_and_a_block_resting_on_it() -> None:
    """The heightfield's first row is the line (piecewise linear in x, as MuJoCo's
    triangles); a block standing on its 20 mm plateau rests 20 mm higher, each pin at the
    same sinkage."""
    hfield = ('<asset><hfield name="terrain" nrow="2" ncol="6" size="2.5 0.5 0.02 0.1" '
              'elevation="0 0 1 1 0 0 0 0 1 1 0 0"/></asset>')
    ground = '<geom name="ground" type="hfield" hfield="terrain" pos="0 0 0"/>'
    xml = _block(100.0).replace("<worldbody>", hfield + "<worldbody>").replace(
        '<geom name="ground" type="plane" size="10 1 0.1"/>', ground)
    model, data, foundation = _setup(xml)
    np.testing.assert_allclose(ground_line(model), [[-2.5, 0], [-1.5, 0], [-0.5, 0.02],
                                                    [0.5, 0.02], [1.5, 0], [2.5, 0]],
                               atol=1e-12)
    data.qpos[1] = 0.02
    for _ in range(1500):
        step(model, data, foundation)
    np.testing.assert_allclose(foundation.normal_forces_N, 100.0 * G / 2.0, rtol=1e-6)
    assert data.qpos[1] == pytest.approx(0.02 - 100.0 * G / (2.0 * LAW.stiffness_N_m),
                                         abs=1e-9)
