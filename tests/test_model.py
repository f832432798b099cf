"""The LF1352 MuJoCo model: structure, generation, initial state, static and driven physics."""

from __future__ import annotations

import math
import re

import mujoco
import numpy as np
import pytest

from trackmj.machines.track_plant import load_plant
from trackmj.ports import ForceLaw
from trackmj.track.mechanics import default_xml_path
from trackmj.track.mjcf.builders import build_mjcf, join_mjcf, read_mjcf, split_mjcf
from trackmj.track.mjcf.generate import generate_mjcf, scene_path
from trackmj.track.mjcf.layout import compute_layout
from trackmj.track.mjcf.structure import chain_starts
from trackmj.track.plant import PassiveTensioner, TrackPlant
from trackmj.track.terrain import RoadProfile


def _named(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int) -> list[str]:
    return [mujoco.mj_id2name(model, obj, i) for i in range(count)]


def test_counts_and_names(plant: TrackPlant) -> None:
    m = plant.model
    bodies = _named(m, mujoco.mjtObj.mjOBJ_BODY, m.nbody)
    links = sorted(b for b in bodies if b.startswith("link_"))
    assert links == [f"link_{k:02d}" for k in range(82)]
    assert [b for b in bodies if b.startswith("road_wheel_")] == [
        f"road_wheel_{k}" for k in range(1, 7)]
    assert bodies.count("sprocket") == 1 and bodies.count("idler") == 1
    assert "chassis" in bodies and "idler_carrier" in bodies
    for obj, n in ((mujoco.mjtObj.mjOBJ_BODY, m.nbody - 1), (mujoco.mjtObj.mjOBJ_GEOM, m.ngeom),
                   (mujoco.mjtObj.mjOBJ_JOINT, m.njnt), (mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu),
                   (mujoco.mjtObj.mjOBJ_EQUALITY, m.neq), (mujoco.mjtObj.mjOBJ_SITE, m.nsite)):
        start = 1 if obj == mujoco.mjtObj.mjOBJ_BODY else 0
        names = [mujoco.mj_id2name(m, obj, i) for i in range(start, start + n)]
        assert all(names), f"unnamed {obj.name}"
    # chains of at most 4 links (19 of 4, 2 of 3): a connect at each chain's first pin, a
    # hinge at every other pin
    p = plant.params
    starts = chain_starts(p)
    assert p.track.structure == "slides" and len(starts) == m.neq == 21
    assert all(m.equality(f"pin_{k:02d}").type == mujoco.mjtEq.mjEQ_CONNECT for k in starts)
    hinged = [k for k in range(82) if k not in starts]
    assert all(m.joint(f"link_{k:02d}_pin").type == mujoco.mjtJoint.mjJNT_HINGE for k in hinged)
    assert sorted(np.diff([*starts, 82])) == [3, 3] + [4] * 19
    assert m.actuator("tensioner").biastype == mujoco.mjtBias.mjBIAS_AFFINE
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.key("home") is not None
    # sprocket teeth: count and pitch radius matched to the link pitch
    teeth = [n for n in _named(m, mujoco.mjtObj.mjOBJ_GEOM, m.ngeom) if "tooth" in n]
    assert len(teeth) == p.sprocket.tooth_count
    assert p.sprocket_pitch_radius_m == pytest.approx(
        p.track.pitch_m / (2 * math.sin(math.pi / len(teeth))))


def test_no_link_link_contact_pairs(plant: TrackPlant) -> None:
    m = plant.model
    link_geoms = [i for i in range(m.ngeom) if m.geom(i).name.startswith("link_")]
    for i in link_geoms:
        for j in link_geoms:
            assert not (m.geom_contype[i] & m.geom_conaffinity[j]), (m.geom(i).name,
                                                                   m.geom(j).name)


NUMBER = re.compile(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")
ATTRIBUTE = re.compile(r'"([^"]*)"')
VECTOR_ATTRIBUTE = re.compile(r"\b(?:pos|quat|axis|fromto|euler|xyaxes|zaxis)=$")
"""Attributes whose numbers are one vector's components (positions, orientations), so that
rounding of one is relative to the vector's size; every other number stands alone (solref's
time constant beside its damping ratio)."""
GENERATED_RTOL = 1e-7
"""The generator writes 9 significant digits; derived values (soft-constraint time constants,
inverse weights, layout coordinates) come from libm and numpy, whose last bits differ between
CPUs (AVX-512 on AMD EPYC vs Intel Xeon paths: 1.38479024e-10 vs 1.38479023e-10 seen), so
the committed file is compared to a fresh one within two units of the 8th digit of the
largest number of the same attribute value: a coordinate that is zero up to rounding
(link_69's z, 1.44366073e-12 against 1.44366054e-12 m next to its 0.075 m x, seen on an AMD
EPYC) is rounding of its vector, not of itself."""
KEYFRAME_ATOL_M = 2.01e-6
"""The settled ``home`` keyframe is rounded to 1 µm: one rounding step of platform noise."""


def _comment_apart(xml: str) -> tuple[str, str]:
    """(the opening comment, the rest) of generated ``xml`` ("" when it opens with none)."""
    if not xml.lstrip().startswith("<!--"):
        return "", xml
    head, rest = xml.split("-->", 1)
    return head, rest


def _numbers_apart(xml: str) -> tuple[str, np.ndarray, np.ndarray]:
    """``xml`` with every number replaced by ``#``, the numbers in order, and for each its
    scale: the largest magnitude among its vector's components (:data:`VECTOR_ATTRIBUTE`),
    else its own."""
    values, scales = [], []
    parts = ATTRIBUTE.split(xml)
    for i, text in enumerate(parts):   # odd i: an attribute's value
        found = [float(v) for v in NUMBER.findall(text)]
        values += found
        vector = i % 2 and found and VECTOR_ATTRIBUTE.search(parts[i - 1])
        scales += [max(map(abs, found))] * len(found) if vector else map(abs, found)
    return NUMBER.sub("#", xml), np.array(values), np.array(scales)


def _strip_keyframe(xml: str) -> tuple[str, np.ndarray]:
    match = re.search(r'<key name="home" qpos="([^"]+)"', xml)
    assert match, "no home keyframe"
    values = np.array([float(v) for v in match.group(1).split()])
    return xml.replace(match.group(1), "QPOS"), values


REGENERATE = ("the generator's output differs from the committed models/lf1352.xml or "
              "lf1352_scene.xml by more than CPU rounding: if you changed the generator or "
              "models/lf1352.toml, run `trackmj model generate` and commit both files; if you "
              "changed neither, the difference is real on your machine: report it with "
              "`trackmj model info` and your CPU, do not commit a regenerated file")


def _assert_same_generated(generated: str, committed: str) -> None:
    """The same opening comment (its mechanics SHA-256 included) and the same text after it
    with every number replaced, numbers within :data:`GENERATED_RTOL` of their attribute
    value's largest."""
    (head_g, body_g), (head_c, body_c) = _comment_apart(generated), _comment_apart(committed)
    assert head_g == head_c, REGENERATE
    (template_g, values_g, _), (template_c, values_c, scales_c) = (_numbers_apart(body_g),
                                                                   _numbers_apart(body_c))
    assert template_g == template_c, REGENERATE
    off = np.abs(values_g - values_c) > GENERATED_RTOL * scales_c
    assert not off.any(), (f"{REGENERATE}; {int(off.sum())} of {len(off)} numbers, first "
                           f"{values_g[off][0]!r} against {values_c[off][0]!r}")


def test_generated_xml_equals_committed(model_params) -> None:
    """The generator makes the committed machine and scene parts (lf1352.xml and
    lf1352_scene.xml, which includes it), up to CPU rounding of the written digits and the
    keyframe's last rounding step; the scene loaded by MuJoCo (its include resolved) compiles
    to the model of the joined text the runs use."""
    generated = generate_mjcf(model_params)
    machine, scene = split_mjcf(generated, "lf1352.xml", "From lf1352.toml; regenerate with: "
                                "trackmj model generate --machine lf1352")
    _assert_same_generated(scene, scene_path(default_xml_path()).read_text())
    structure_c, home_c = _strip_keyframe(default_xml_path().read_text())
    structure_g, home_g = _strip_keyframe(machine)
    _assert_same_generated(structure_g, structure_c)
    np.testing.assert_allclose(home_g, home_c, rtol=0, atol=KEYFRAME_ATOL_M, err_msg=REGENERATE)
    assert join_mjcf(scene, machine) == generated
    from_file = mujoco.MjModel.from_xml_path(str(scene_path(default_xml_path())))
    joined = mujoco.MjModel.from_xml_string(read_mjcf(scene_path(default_xml_path())))
    assert (from_file.nbody, from_file.ngeom, from_file.nq) == (joined.nbody, joined.ngeom,
                                                                joined.nq)
    np.testing.assert_array_equal(from_file.geom_solref, joined.geom_solref)
    np.testing.assert_array_equal(from_file.key_qpos, joined.key_qpos)


def test_generated_file_check_passes_cpu_rounding_and_sees_a_change() -> None:
    """The tolerance is CPU rounding, not a change: the last written digit may differ, and
    a coordinate that is zero up to rounding may differ in any digit below its vector's
    rounding; a value moved in its 5th digit, a zero coordinate moved by a micrometre or a
    renamed attribute fails."""
    base = ('<geom name="pin_00" solref="1.38479024e-10 1" pos="0.1 0 -0.25"/>'
            '<body name="link_69" pos="0.0750000019 0 1.44366054e-12"/>')
    _assert_same_generated(base.replace("1.38479024e-10", "1.38479023e-10"), base)
    _assert_same_generated(base.replace("1.44366054e-12", "1.44366073e-12"), base)
    for changed in (base.replace("1.38479024e-10", "1.38489024e-10"),
                    base.replace("0.0750000019", "0.0750100019"),
                    base.replace("1.44366054e-12", "1.0e-6"),
                    base.replace("pos=", "quat="), base.replace("pin_00", "pin_01")):
        with pytest.raises(AssertionError):
            _assert_same_generated(changed, base)


def test_initial_layout_closes_without_penetration(model_params) -> None:
    layout = compute_layout(model_params)
    gaps = np.linalg.norm(np.roll(layout.pins, -1, axis=0) - layout.pins, axis=1)
    np.testing.assert_allclose(gaps, model_params.track.pitch_m, rtol=0, atol=1e-9)
    model = mujoco.MjModel.from_xml_string(build_mjcf(model_params, layout))
    plant = TrackPlant(model, model_params)
    d = plant.data
    assert d.ncon > 10
    assert min(c.dist for c in d.contact[: d.ncon]) > -1e-3
    assert plant.closure_error_m < 0.5e-3
    assert plant.warning_count == 0


def test_home_keyframe_is_settled(plant: TrackPlant) -> None:
    d = plant.data
    assert min(c.dist for c in d.contact[: d.ncon]) > -1e-3
    assert plant.closure_error_m < 0.5e-3
    element = PassiveTensioner.from_params(plant.params)
    start = plant.data.qpos.copy()
    plant.run(element, 0.2)
    # a settled state barely moves (chassis and links within 1 mm, no warnings)
    assert np.abs(plant.data.qpos[:3] - start[:3]).max() < 1e-3
    assert plant.warning_count == 0


def _strand_unit(pins: np.ndarray, a: int, b: int) -> np.ndarray:
    v = pins[b] - pins[a]
    return v / np.linalg.norm(v)


def test_static_tension_matches_idler_force_balance(plant: TrackPlant) -> None:
    """Frictionless idler: both strands carry T and F_idler = -T (e_u + e_l) · x_slide."""
    p = plant.params
    element = PassiveTensioner(15_000.0, 0.0, 1.4e4, p.idler.stroke_at_layout_m)
    plant.run(element, 1.5)
    force = plant.idler_force_N
    assert force == pytest.approx(15_000.0, rel=0.01)  # settled: damping term small
    pins = plant.pin_positions()
    centre = plant.data.xpos[plant.model.body("idler").id][[0, 2]]
    vertex_r = math.hypot(p.idler.radius_m + p.track.rail_radius_m, p.track.pitch_m / 2)
    on_idler = np.nonzero(np.linalg.norm(pins - centre, axis=1) < vertex_r + 1.5e-3)[0]
    assert len(on_idler) >= 3
    first, last = on_idler.min(), on_idler.max()   # running order: top strand -> idler -> bottom
    assert last - first + 1 == len(on_idler), "idler wrap must be contiguous"
    e_upper = _strand_unit(pins, first, first - 1)   # from the idler back along the top strand
    e_lower = _strand_unit(pins, last, last + 1)     # from the idler down the front strand
    pitch = plant.chassis_pose[2]
    slide_axis = np.array([math.cos(pitch), -math.sin(pitch)])
    carrier_mass = p.idler.mass_kg + p.idler.carrier_mass_kg
    gravity_along = carrier_mass * p.simulation.gravity_m_s2 * math.sin(pitch)
    t_hand = (force + gravity_along) / -(e_upper @ slide_axis + e_lower @ slide_axis)
    tension = plant.pin_tensions_N()
    upper_near_idler = np.arange(first - 6, first)   # the span between roller 2 and the idler
    measured = tension[upper_near_idler].mean()
    assert measured == pytest.approx(t_hand, rel=0.10), (measured, t_hand)


@pytest.mark.slow
def test_driving_keeps_track_engaged(plant: TrackPlant) -> None:
    element = PassiveTensioner.from_params(plant.params)
    speed, ramp = 1.5, 1.0
    vx, closure, statuses = [], [], []

    def check(pl: TrackPlant) -> None:
        ms = round(pl.time_s * 1000)
        closure.append(pl.closure_error_m)
        if pl.time_s > ramp + 1.0:
            vx.append(pl.chassis_velocity[0])
        if ms % 100 == 0:
            statuses.append(pl.derailment())

    plant.run(element, 10.0, lambda t: speed * min(1.0, t / ramp), check)
    assert plant.warning_count == 0
    assert np.all(np.isfinite(plant.data.qpos)) and np.all(np.isfinite(plant.data.qvel))
    assert not any(s.any for s in statuses), [s for s in statuses if s.any][:3]
    assert max(closure) < 1e-3
    assert np.mean(vx) == pytest.approx(speed, rel=0.05)
    assert plant.track_speed_m_s == pytest.approx(speed, rel=0.05)


def test_derailment_indicators_fire_when_track_is_loosened(plant: TrackPlant) -> None:
    class PullIn:
        """Retracts the idler with 3 kN: the track must go slack."""

        def force_law(self, t_s, stroke_m, velocity_m_s):
            return ForceLaw(-3_000.0, -1e4)

        def complete_step(self, t_s, stroke_m, velocity_m_s):
            pass

    plant.run(PullIn(), 1.0)
    status = plant.derailment()
    assert status.slack_strand and status.any
    assert status.min_upper_strand_tension_N < TrackPlant.SLACK_TENSION_N


def test_sparse_and_dense_constraint_solutions_agree(plant: TrackPlant) -> None:
    """Guards against MuJoCo 4.0.0's sparse-factorisation bug (upstream issue 3767): on
    driven states the sparse path (the model's) gives the dense path's accelerations,
    constraint forces and Newton iteration count."""
    assert_sparse_matches_dense(plant, every_ms=100, min_rows=80)


def assert_sparse_matches_dense(plant: TrackPlant, every_ms: int, min_rows: int) -> None:
    """Drive ``plant`` 1 s (ramp to 1.5 m/s in 0.5 s); at every ``every_ms`` ms the sparse
    and dense paths give the same qacc, constraint forces (> ``min_rows`` rows) and Newton
    iteration count."""
    m, d = plant.model, plant.data
    assert m.opt.jacobian == mujoco.mjtJacobian.mjJAC_SPARSE
    states: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def keep(pl: TrackPlant) -> None:
        if round(pl.time_s * 1000) % every_ms == 0:
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
        assert len(force_d) == len(force_s) > min_rows
        np.testing.assert_allclose(acc_s, acc_d, rtol=0, atol=1e-9 * np.abs(acc_d).max())
        np.testing.assert_allclose(force_s, force_d, rtol=0, atol=1e-9 * np.abs(force_d).max())
        assert iter_s == iter_d
    assert len(states) == 1000 // every_ms


def _trajectory() -> np.ndarray:
    plant = load_plant()
    element = PassiveTensioner.from_params(plant.params)
    states: list[np.ndarray] = []
    plant.run(element, 0.5, 1.0, lambda pl: states.append(pl.data.qpos.copy()))
    return np.array(states)


def test_runs_are_bit_identical() -> None:
    assert np.array_equal(_trajectory(), _trajectory())


def _chassis_heights(terrain: RoadProfile) -> np.ndarray:
    plant = load_plant(terrain=terrain)
    element = PassiveTensioner.from_params(plant.params)
    heights: list[float] = []
    plant.run(element, 4.0, lambda t: 1.5 * min(1.0, t),
              lambda pl: heights.append(pl.chassis_pose[1]))
    assert plant.warning_count == 0 and not plant.derailment().any
    return np.array(heights)


@pytest.mark.slow
def test_heightfield_terrain() -> None:
    """A flat heightfield behaves like the plane; a 50 mm step lifts the chassis by it."""
    x = np.arange(0.0, 60.0, 0.05) - 10.0
    flat = _chassis_heights(RoadProfile(-10.0, 0.05, np.zeros_like(x)))
    plane_plant = load_plant()
    plane: list[float] = []
    plane_plant.run(PassiveTensioner.from_params(plane_plant.params), 4.0,
                    lambda t: 1.5 * min(1.0, t), lambda pl: plane.append(pl.chassis_pose[1]))
    np.testing.assert_allclose(flat, plane, atol=1e-3)
    # a 0.5 m long, 50 mm high plateau under the path: the chassis rises about that much
    bump = _chassis_heights(RoadProfile(-10.0, 0.05, np.where((x > 3.0) & (x < 3.5), 0.05, 0.0)))
    rise = bump.max() - flat.max()
    assert 0.02 < rise < 0.06, rise
