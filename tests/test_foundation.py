"""The ground foundation force element (trackmj/track/foundation.py) on small hand-checkable models.

Static sinkage is the load over the stated stiffness; a free vibration rings as the
semi-implicit Euler step with the spring explicit and the damper implicit, from which the
stated K and B are recovered; below the Coulomb limit a pulled block shears K_j·F/(μ·N)
and holds, on a 1:2 slope too, and above it slides at μ·N exactly; a bouncing block is
never pulled and its friction never exceeds μ·N applied; the constraint solver sees the
damping added to M (a constrained toy, exact implicit Euler); the work booked per step
closes the energy balance; the ground line's closest point, normal and sign are the
hand-derived ones on a slope and round a corner.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from trackmj.track.foundation import (
    S_DELTA,
    S_NA,
    S_ON,
    TOLERANCE_N,
    Foundation,
    FoundationLaw,
    ImplicitSprings,
    _closest,
    foundation_work,
    ground_line,
    step,
)

H, G = 1e-3, 9.81
LAW = FoundationLaw(stiffness_N_m=2.0e6, damping_N_s_m=2.0e4, damping_onset_m=1e-6,
                    friction=0.8, shear_modulus_m=0.01)
"""Full damping from 1 µm of penetration: the hand formulas below take B constant."""
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
                                                         Foundation, ImplicitSprings]:
    """The toy's model and data, its foundation on the ``pin_*`` spheres and no implicit
    springs."""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    pins = [g for g in range(model.ngeom) if model.geom(g).name.startswith("pin_")]
    return model, data, Foundation(model, data, pins, law), ImplicitSprings(model, data, ())


def test_static_sinkage_is_the_load_over_the_stated_stiffness() -> None:
    """Blocks of 300 and 400 kg on two pins settle at δ = m·g/(2·K) per pin (the
    foundation's only stiffness), level, and the ground force equals the weight; the
    MJCF ground contact is off (no MuJoCo contacts)."""
    for mass in (300.0, 400.0):
        model, data, foundation, springs = _setup(_block(mass))
        for _ in range(2000):
            step(model, data, foundation, springs)
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
        law = dataclasses.replace(LAW, damping_N_s_m=damping, friction=0.0)
        model, data, foundation, springs = _setup(_block(mass), law)
        rest = -mass * G / (2.0 * law.stiffness_N_m)
        data.qpos[1] = rest + 1e-4
        x = []
        for _ in range(60):
            step(model, data, foundation, springs)
            x.append(data.qpos[1] - rest)
        x = np.array(x)
        assert foundation.state[:, S_ON].min() > 0.0   # in contact throughout
        a1, a0 = np.linalg.lstsq(np.column_stack([x[1:-1], x[:-2]]), x[2:], rcond=None)[0]
        total = -mass / a0
        assert (total - mass) / (2.0 * H) == pytest.approx(damping, rel=1e-6)
        assert (mass - (a1 - 1.0) * total) / (2.0 * H ** 2) == pytest.approx(
            law.stiffness_N_m, rel=1e-6)


def test_friction_holds_below_the_coulomb_limit_and_slides_above() -> None:
    """A 100 kg block on two pins pulled sideways with F (ramped up over 1 s: a sudden pull
    overshoots on the shear spring): below μ·m·g it shears j = K_j·F/(μ·m·g) and stands
    still (its shear spring rings down at ~0.14 of critical;
    then no creep: it moves less than 1 µm over a second, its displacement is that j);
    above it, it accelerates at (F − μ·m·g)/m, Coulomb's exactly."""
    mass = 100.0
    limit = LAW.friction * mass * G
    for fraction in (0.5, 0.9):
        model, data, foundation, springs = _setup(_block(mass))
        for _ in range(500):   # set down
            step(model, data, foundation, springs)
        start = data.qpos[0]
        for k in range(2500):   # the pull ramped up over 1 s, then held
            data.ctrl[0] = fraction * limit * min(1.0, k / 1000)
            step(model, data, foundation, springs)
        x = data.qpos[0]
        for _ in range(1000):
            step(model, data, foundation, springs)
        assert abs(data.qpos[0] - x) < 1e-6   # creep below 1 µm/s
        assert data.qpos[0] - start == pytest.approx(fraction * LAW.shear_modulus_m,
                                                     rel=1e-3)
        np.testing.assert_allclose(foundation.friction_forces_N.sum(), -fraction * limit,
                                   rtol=1e-6)
    model, data, foundation, springs = _setup(_block(mass))
    data.ctrl[0] = 1.5 * limit
    for _ in range(200):
        step(model, data, foundation, springs)
    v0 = data.qvel[0]
    for _ in range(100):
        step(model, data, foundation, springs)
    assert (data.qvel[0] - v0) / 0.1 == pytest.approx(0.5 * limit / mass, rel=1e-6)


def test_a_block_parked_on_a_one_in_two_slope_holds() -> None:
    """Gravity tilted by atan(0.5) is a 1:2 slope (tan θ = 0.5 < μ = 0.8): set down on it,
    the block slides while its pins load, then sticks; after 3 s its pins slide less than
    10 µm/s (the issue's floor is 0.5 mm/s; the law gives 0) and the ground's friction
    carries the weight's slope component m·g·sin θ."""
    slope = math.atan(0.5)
    mass = 100.0
    xml = _block(mass).replace(f'gravity="0 0 -{G}"',
                               f'gravity="{G * math.sin(slope)} 0 {-G * math.cos(slope)}"')
    model, data, foundation, springs = _setup(xml)
    for _ in range(3000):
        step(model, data, foundation, springs)
    x = data.qpos[0]
    for _ in range(1000):
        step(model, data, foundation, springs)
    assert abs(data.qpos[0] - x) / 1.0 < 1e-5
    assert foundation.friction_forces_N.sum() == pytest.approx(-mass * G * math.sin(slope),
                                                               rel=1e-4)


def test_a_bouncing_block_is_never_pulled_and_never_over_the_friction_limit() -> None:
    """A block dropped 20 mm while pitching and pulled at 0.7 μ·m·g strikes, bounces and
    lifts its pins off again and again (B = 2 kN·s/m: at lift-off B·v_n exceeds K·δ, where
    the Kelvin–Voigt law linearised at v₀ pulled): every applied normal force is
    ≥ −TOLERANCE_N and every applied friction ≤ μ·N + TOLERANCE_N, every step; the
    lift-offs happen (11) and every step's active set is resolved."""
    law = dataclasses.replace(LAW, damping_N_s_m=2.0e3)
    mass = 50.0
    model, data, foundation, springs = _setup(_block(mass), law)
    data.qpos[1] = 0.02
    data.qvel[2] = 3.0
    data.ctrl[0] = 0.7 * law.friction * mass * G
    lift_offs, touching = 0, np.zeros(2, dtype=bool)
    for _ in range(1500):
        step(model, data, foundation, springs)
        on = foundation.state[:, S_ON] > 0.0
        lift_offs += int(np.count_nonzero(touching & ~on))
        touching = on
        applied = foundation.state[:, S_NA]
        assert applied.min() >= -TOLERANCE_N
        assert np.all(np.abs(foundation.friction_forces_N)
                      <= law.friction * np.maximum(applied, 0.0) + TOLERANCE_N)
    assert lift_offs >= 5
    assert foundation.unresolved == 0


def test_the_constraint_solver_sees_the_damping_added_to_the_mass_matrix() -> None:
    """MuJoCo contract the foundation rests on: two 1 kg slides joined by a joint equality,
    a damper c = 2000 N·s/m on one, its force −c·v₀ applied and h·c added to M before
    ``mj_factorM``; from v = 1 m/s
    exact implicit Euler gives (m₁ + m₂ + h·c)·v₁ = (m₁ + m₂)·v₀, v₁ = 0.5 m/s for both
    (an equality as hard as MuJoCo's impedance allows, 0.9999: measured 0.49998, 0.50007).
    (MuJoCo's own ``dof_damping`` under implicitfast gives (0.667, 0.0001): the solver does
    not see it.)"""
    model = mujoco.MjModel.from_xml_string(f"""<mujoco><option timestep="{H}" gravity="0 0 0"
      integrator="implicitfast"/><worldbody>
      <body><joint name="a" type="slide" axis="1 0 0"/><geom size="0.1" mass="1"/></body>
      <body pos="1 0 0"><joint name="b" type="slide" axis="1 0 0"/>
      <geom size="0.1" mass="1"/></body></worldbody>
      <equality><joint joint1="a" joint2="b" solref="0.002 1" solimp="0.9999 0.9999 0.001"/>
      </equality></mujoco>""")
    data = mujoco.MjData(model)
    data.qvel[:] = 1.0
    mujoco.mj_step1(model, data)
    data.qfrc_applied[0] = -2000.0 * data.qvel[0]   # the damper's force at v₀ ...
    data.M[model.M_rowadr[0] + model.M_rownnz[0] - 1] += H * 2000.0   # ... and h·c in M
    mujoco.mj_factorM(model, data)
    mujoco.mj_step2(model, data)
    np.testing.assert_allclose(data.qvel, 0.5, atol=1e-4)


def test_the_booked_work_closes_the_energy_balance() -> None:
    """A block on two pins dropped 5 mm onto the foundation, pitching and pulled sideways:
    per step semi-implicit Euler gives ½v₁ᵀM₀v₁ − ½v₀ᵀM₀v₀ = W − ½ΔvᵀM₀Δv, M₀ the mass
    matrix of the step's start and W the work of every force on Δq = h·v₁; with the
    foundation's work booked as integrated, Σ(F(v₀) − C·J·Δv)·(J·Δq), the pull's and the
    bias forces' (gravity, Coriolis), the balance closes to round-off."""
    model, data, foundation, springs = _setup(_block(50.0))
    data.qpos[1] = 0.005
    data.qvel[2] = 0.5   # a pitch rate: the pins strike one after the other
    data.ctrl[0] = 200.0
    mass_matrix = np.zeros((model.nv, model.nv))
    work, other, kinetic, jump = np.zeros(2), 0.0, 0.0, 0.0
    for _ in range(400):
        v0 = data.qvel.copy()
        step(model, data, foundation, springs)
        v1 = data.qvel
        foundation_work(foundation.state, foundation.jac, foundation.pins, foundation.dofs,
                        v0, v1, H, work)
        dq = H * v1
        other += data.ctrl[0] * dq[0] - data.qfrc_bias @ dq
        mujoco.mj_fullM(model, data, mass_matrix)   # M of the step's start (restored)
        kinetic += 0.5 * (v1 @ mass_matrix @ v1 - v0 @ mass_matrix @ v0)
        jump += 0.5 * (v1 - v0) @ mass_matrix @ (v1 - v0)
    assert foundation.state[:, S_ON].min() > 0.0 and work[1] < 0.0 < other
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
    model, data, foundation, springs = _setup(xml)
    np.testing.assert_allclose(ground_line(model), [[-2.5, 0], [-1.5, 0], [-0.5, 0.02],
                                                    [0.5, 0.02], [1.5, 0], [2.5, 0]],
                               atol=1e-12)
    data.qpos[1] = 0.02
    for _ in range(1500):
        step(model, data, foundation, springs)
    np.testing.assert_allclose(foundation.normal_forces_N, 100.0 * G / 2.0, rtol=1e-6)
    assert data.qpos[1] == pytest.approx(0.02 - 100.0 * G / (2.0 * LAW.stiffness_N_m),
                                         abs=1e-9)
