"""``[track] structure``: hinged sub-chains ("chains", the default) and free links keep the
stated physics.

Chains of at most ``chain_links`` links (trackmj/track/mjcf/structure.py): each chain's links
hinged in a row, one connect per chain carrying its pins' compliance in series; two fewer
DOFs per hinged link, the contacts still at their stated stiffness, the hinged pins'
tensions the forces they transmit, a span stretching as its connects' pins in series, the
energy ledger closing while driving. ``structure = "free"`` (every pin a connect),
``"slides"`` (chains with every hinged pin on its own compliant slide) and two-link chains
are checked the same way; free links and slides stretch every pin of a loaded strand by
T/K.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_contacts import STATIC_TOLERANCE, _static_stiffness, span_under_tension
from test_model import assert_sparse_matches_dense

from trackmj.machines.track_plant import load_plant
from trackmj.sim.setup import prepare
from trackmj.sim.w3_hitch import Rig, load_change_N
from trackmj.track.energy import TrackEnergyLedger
from trackmj.track.foundation import ImplicitSprings
from trackmj.track.mechanics import ModelParams, load_model_params
from trackmj.track.mjcf.generate import generate_mjcf
from trackmj.track.mjcf.names import link_name, stretch_name
from trackmj.track.mjcf.structure import (
    chain_sizes,
    chain_starts,
    hinged_pins,
    pin_series_count,
    pin_slide_ids,
    stretch_armature_kg,
)
from trackmj.track.plant import PassiveTensioner, TrackPlant
from trackmj.validator import ParameterError


def _variant(model_params: ModelParams, **track) -> tuple[str, ModelParams]:
    params = dataclasses.replace(model_params,
                                 track=dataclasses.replace(model_params.track, **track))
    return generate_mjcf(params), params


@pytest.fixture(scope="module")
def pairs(model_params: ModelParams) -> tuple[str, ModelParams]:
    return _variant(model_params, structure="chains", chain_links=2)


@pytest.fixture(scope="module")
def chains(model_params: ModelParams) -> tuple[str, ModelParams]:
    return _variant(model_params, structure="chains")


@pytest.fixture(scope="module")
def free(model_params: ModelParams) -> tuple[str, ModelParams]:
    return _variant(model_params, structure="free")


@pytest.fixture(scope="module")
def slides(model_params: ModelParams) -> tuple[str, ModelParams]:
    return _variant(model_params, structure="slides")


def _plant(variant: tuple[str, ModelParams]) -> TrackPlant:
    xml, params = variant
    return TrackPlant(mujoco.MjModel.from_xml_string(xml), params)


@given(st.integers(20, 200), st.integers(2, 12))
def test_chain_sizes_cover_the_loop_evenly(links: int, longest: int) -> None:
    sizes = chain_sizes(links, longest)
    assert sum(sizes) == links and len(sizes) == math.ceil(links / longest)
    assert max(sizes) <= longest and max(sizes) - min(sizes) <= 1


@pytest.mark.parametrize("structure", ["default", "chains", "pairs", "free", "slides"])
def test_structure_cuts_the_loop_into_its_chains(structure: str, chains, pairs, free, slides,
                                                 model_params: ModelParams) -> None:
    plant = {"default": load_plant, "chains": lambda: _plant(chains),
             "pairs": lambda: _plant(pairs), "free": lambda: _plant(free),
             "slides": lambda: _plant(slides)}[structure]()
    m, p, n = plant.model, plant.params, model_params.track.link_count
    assert structure != "default" or p.track.structure == "slides"   # LF1352's
    slid = p.track.structure == "slides"
    starts = chain_starts(p)
    hinged = n - len(starts)
    per_hinged = 2 if slid else 1   # a slide before the pin's hinge
    # 3 DOFs per free link, 1 (2) per hinged link, besides the machine's own 11
    assert m.neq == len(starts) and m.nv == 11 + 3 * len(starts) + per_hinged * hinged
    carried = np.ones(len(starts)) if slid else np.diff([*starts, n])
    assert pin_series_count(p) == dict(zip(starts, carried, strict=True))
    for k in range(n):
        parent = m.body(link_name(k)).parentid
        if k in starts:
            assert parent == 0 and m.equality(f"pin_{k:02d}") is not None
        else:
            assert parent == m.body(link_name(k - 1)).id
            assert m.joint(link_name(k) + "_pin").type == mujoco.mjtJoint.mjJNT_HINGE
            if slid:
                # along the parent's pitch: the pin's gap, K and B as stated
                stretch = m.joint(stretch_name(k))
                axis = plant.data.xmat[parent].reshape(3, 3) @ np.array([1.0, 0.0, 0.0])
                np.testing.assert_allclose(plant.data.xaxis[stretch.id], axis, atol=1e-6)
                assert stretch.stiffness[0] == p.pin_joint.radial_stiffness_N_m
                assert m.dof_damping[stretch.dofadr[0]] == p.pin_joint.radial_damping_N_s_m
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


@pytest.mark.parametrize("structure", ["default", "chains", "pairs", "slides"])
def test_span_stretches_as_its_connects_pins_in_series(structure: str, chains, pairs,
                                                       slides) -> None:
    """The free upper span stretches by Σ m_c·ΔT/K when its tension rises by ΔT, m_c the
    pins each compliance in it carries (a connect its chain's, a slide its own pin); its
    hinged pins carry the tension of their neighbours (the cfrc_int readout)."""
    plant = {"default": load_plant, "chains": lambda: _plant(chains),
             "pairs": lambda: _plant(pairs), "slides": lambda: _plant(slides)}[structure]()
    series = pin_series_count(plant.params)
    # the slides' pins in series with the connects' (none for chains)
    compliant = {**dict.fromkeys(hinged_pins(plant.params),
                                 1 if plant.params.track.structure == "slides" else 0),
                 **series}
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
    pins = sum(compliant[k] for k in range(a + 1, b + 1))
    measured = pins * (t1 - t0) / (l1 - l0)
    assert t1 - t0 > 1_000.0
    assert measured == pytest.approx(plant.params.pin_joint.radial_stiffness_N_m, rel=0.05)


@pytest.mark.parametrize("structure", ["pairs", "free", "slides"])
def test_drive_closes_the_ledger(structure: str, pairs, free, slides) -> None:
    plant = _plant({"pairs": pairs, "free": free, "slides": slides}[structure])
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


@pytest.mark.parametrize("structure", ["pairs", "free", "slides"])
def test_sparse_and_dense_constraint_solutions_agree(structure: str, pairs, free,
                                                     slides) -> None:
    """The sparse path (the model's) gives the dense path's solution on driven states of
    each structure (upstream issue 3767)."""
    plant = _plant({"pairs": pairs, "free": free, "slides": slides}[structure])
    # slides keep the chains of 4's 63 connect rows; the others have 123 or 246
    assert_sparse_matches_dense(plant, every_ms=200, min_rows=60 if structure == "slides"
                                else 100)


@pytest.mark.parametrize("structure", ["free", "slides"])
def test_every_pin_of_a_loaded_strand_stretches_T_over_K(structure: str, free,
                                                          slides) -> None:
    """Standing 1.5 s at the preload, every upper-strand pin stretches by its own tension
    over the stated K (pin-centre distance − pitch): on average within 5 % of T/K, every
    pin within 0.3·T/K of the mean (issue 30's floors: 20 %, 0.3). Chains of 4 lump four
    pins' stretch on one connect (75.000/75.000/75.000/75.108 mm) and are not asked."""
    plant = _plant(free if structure == "free" else slides)
    p = plant.params
    plant.run(PassiveTensioner.from_params(p), 1.5, 0.0)
    upper = plant.upper_strand_pins()
    pins = plant.pin_positions()
    stretch = (np.linalg.norm(pins - np.roll(pins, 1, axis=0), axis=1)
               - p.track.pitch_m)[upper]
    t_over_k = plant.pin_tensions_N()[upper].mean() / p.pin_joint.radial_stiffness_N_m
    assert len(upper) >= 8 and t_over_k > 10e-6   # a loaded strand: T/K of ~27 µm
    assert stretch.mean() == pytest.approx(t_over_k, rel=0.05)
    assert np.abs(stretch - stretch.mean()).max() <= 0.3 * t_over_k
    assert plant.warning_count == 0


def test_pin_slides_armature_is_only_for_mujocos_own_stepping(slides) -> None:
    """The MJCF gives every pin slide the armature soft_margin·(h²K + 2hB)/4 (LF1352:
    76 kg), at which MuJoCo's explicit joint spring and implicit damper sit at 1/margin of
    their stability limit h²K/m + 2hB/m = 4 (its viewer steps the file alone); the plant
    integrates the slides' springs implicitly and simulates them without it."""
    xml, p = slides
    m = mujoco.MjModel.from_xml_string(xml)
    h, k, b = m.opt.timestep, p.pin_joint.radial_stiffness_N_m, p.pin_joint.radial_damping_N_s_m
    dofs = [m.joint(stretch_name(j)).dofadr[0] for j in hinged_pins(p)]
    armature = m.dof_armature[dofs]
    np.testing.assert_allclose(armature, stretch_armature_kg(p), rtol=1e-12)
    assert (h * h * k + 2.0 * h * b) / armature[0] == pytest.approx(4.0 / p.solver.soft_margin)
    plant = TrackPlant(m, p)
    np.testing.assert_array_equal(plant.model.dof_armature[dofs], 0.0)
    np.testing.assert_array_equal(np.sort(plant.springs.dofs), np.sort(dofs))


def test_implicit_spring_is_backward_euler_on_a_stiff_slide() -> None:
    """A 1 kg body on a slide of 1e8 N/m at 1 ms (h²K/m = 100: MuJoCo's explicit spring
    diverges) with the spring by :class:`ImplicitSprings`: every step is backward Euler,
    (m + h²K)·Δv = −h·K·(q₀ + h·v₀), q₁ = q₀ + h·v₁ (the recursion by hand, to 1e-12 of
    the start stretch), and the energy ½mv² + ½Kq² falls every step."""
    m_kg, k, h = 1.0, 1e8, 1e-3
    model = mujoco.MjModel.from_xml_string(
        f'<mujoco><option timestep="{h}" gravity="0 0 0"/><worldbody><body>'
        f'<joint name="s" type="slide" axis="1 0 0" stiffness="{k}"/>'
        f'<geom type="sphere" size="0.01" mass="{m_kg}" contype="0" conaffinity="0"/>'
        '</body></worldbody></mujoco>')
    data = mujoco.MjData(model)
    springs = ImplicitSprings(model, data, [model.joint("s").id])
    q, v = 1e-3, 0.0
    data.qpos[0] = q
    energy = 0.5 * k * q * q
    for _ in range(10):   # backward Euler takes ~0.1 of the stretch per step here
        mujoco.mj_step1(model, data)
        springs.apply()
        mujoco.mj_factorM(model, data)
        mujoco.mj_step2(model, data)
        v += -h * k * (q + h * v) / (m_kg + h * h * k)
        q += h * v
        assert data.qpos[0] == pytest.approx(q, abs=1e-15)
        assert data.qvel[0] == pytest.approx(v, abs=1e-12)
        now = 0.5 * m_kg * v * v + 0.5 * k * q * q
        assert now < energy
        energy = now


def _clamped_strand(params: ModelParams) -> tuple[mujoco.MjModel, int]:
    """The first three chains of ``params``' loop as a strand in zero gravity without
    contacts: link_00 welded to the world at its layout pose, pin 0 and the links from the
    fourth chain on removed (a connect or tendon reaching them too), every link joint but
    the pin slides damped (5 N·m·s/rad or N·s/m, only to settle: statics do not depend on
    it). Returns the model and the strand's link count."""
    root = ET.fromstring(generate_mjcf(params).split("-->", 1)[1])
    count = chain_starts(params)[3]
    world = root.find("worldbody")
    for body in world.findall("body"):
        if body.get("name", "").startswith("link_") and int(body.get("name")[5:]) >= count:
            world.remove(body)
    for group in (root.find("equality"), root.find("tendon")):
        for item in list(group):
            pin = int(item.get("name")[4:6])
            if pin == 0 or pin >= count:
                group.remove(item)
            for term in item.findall("joint[@joint='link_00_pitch']"):
                item.remove(term)   # the clamped root turns no more
    clamped = world.find("body[@name='link_00']")
    for joint in clamped.findall("joint"):
        clamped.remove(joint)
    for joint in root.iter("joint"):
        if joint.get("name", "").startswith("link_") and joint.get("class") != "pin_stretch":
            joint.set("damping", "5")
    root.remove(root.find("keyframe"))
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    model.opt.gravity[:] = 0.0
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return model, count


@pytest.mark.parametrize("structure", ["slides", "chains"])
def test_a_strand_bent_by_a_moment_turns_every_pin_by_moment_over_stiffness(
        model_params: ModelParams, structure: str) -> None:
    """The bushings' torsional spring on chained links: a strand of three chains clamped at
    link_00 and loaded by a couple M about +y on its free end carries M through every pin
    and no force, so each pin, hinged or connect, turns by −M/k_t (LF1352's scaled Chrono
    RSDA, 240 N·m/rad; M = 5 N·m: 20.8 mrad; a turn about +y takes a link's x axis
    towards −z, so its angle in the x-z plane falls), the pin slides unstretched. Stepped
    as the plant steps (the pin slides' springs and every damper implicit)."""
    p = dataclasses.replace(model_params,
                            track=dataclasses.replace(model_params.track, structure=structure),
                            bushings=dataclasses.replace(model_params.bushings, enabled=True))
    model, count = _clamped_strand(p)
    data = mujoco.MjData(model)
    slides = [j for j in pin_slide_ids(model, range(count)).values() if j >= 0]
    damped = [j for j in range(model.njnt) if model.joint(j).name.startswith("link_")
              and j not in slides]
    springs = ImplicitSprings(model, data, slides, damped)
    links = [model.body(link_name(k)).id for k in range(count)]
    moment = 5.0
    data.xfrc_applied[links[-1], 4] = moment
    for _ in range(10000):
        mujoco.mj_step1(model, data)
        springs.apply()
        mujoco.mj_factorM(model, data)
        mujoco.mj_step2(model, data)
    angle = [math.atan2(data.xmat[b][6], data.xmat[b][0]) for b in links]   # x axis' z, x
    twist = np.array([math.remainder(b - a, 2.0 * math.pi)
                      for a, b in itertools.pairwise(angle)])
    k_t = p.bushings.torsional_stiffness_N_m_rad
    assert set(chain_starts(p)[1:3]) < set(range(1, count))   # two connects among the pins
    np.testing.assert_allclose(twist, -moment / k_t, rtol=1e-3)
    if slides:
        stretch = data.qpos[model.jnt_qposadr[slides]]
        assert np.abs(stretch).max() < 1e-9   # no force through the pins


def test_chains_longer_than_measured_are_refused_naming_the_key() -> None:
    """A chain of 24 links (one connect lumping 24 pins) already trips the slack-strand check
    on LF1352 at 2 m/s: the validator refuses it before any model is generated."""
    assert load_model_params(overrides={"track.chain_links": 12}).track.chain_links == 12
    with pytest.raises(ParameterError, match=r"chain_links.*\[2, 12\]"):
        load_model_params(overrides={"track.chain_links": 24})


@pytest.mark.slow
def test_a_hitch_load_reaches_the_idler_as_on_free_links_when_every_pin_is_compliant(
        tmp_path) -> None:
    """W3's calibration rig (hold mode, seed 0), LF1352: at its calibrated tow and push
    (+4873 / −3380 N) slides change the idler load as free links do to 6 %, twice the rig's
    own spread on one start: settled 1.000-1.020 s, the slides' push reads +1900 to
    +2006 N (models/README.md, "Parking brake"). Measured parked through the settle:
    −1488 / −1462 N and +1908 / +2019 N (on the servo alone −1488 / −1473 N and
    +1963 / +2001 N; chains of 4 as close). At a 6126 N tow the upper
    strand nears slack, where its sag turns on fractions of a millimetre of length: there
    the pins' stretch decides, and slides stay nearer the free links than chains of 4, whose
    4-link rigid spans lump it (parked: −1821 and −1531 against −1944 N; on the servo alone
    −1838 and −1551 against −1955 N; on the armature and soft margin 2, −1923 and −1481
    against −1930 N; models/README.md, "Loop structure")."""
    models = Path(__file__).resolve().parents[1] / "models"
    text = (models / "lf1352.toml").read_text()
    line = next(x for x in text.splitlines() if x.startswith("structure = "))
    change = {}
    for structure in ("slides", "free", "chains"):
        (tmp_path / f"{structure}.toml").write_text(
            text.replace(line, f'structure = "{structure}"'))
        machine = tmp_path / f"{structure}_machine.toml"
        machine.write_text(
            f'[machine]\nname = "lf1352{structure}"\ndescription = "LF1352, {structure}"\n'
            f'mechanics = "{structure}.toml"\n'
            f'hydraulics = "{models / "lf1352_hydraulics.toml"}"\n'
            f'control = "{models / "lf1352_control.toml"}"\n')
        rig = Rig(prepare("W3", machine=machine))
        loads = (4873.3, -3379.9, 6126.4) if structure != "chains" else (6126.4,)
        change[structure] = {load: load_change_N(rig.setup.scenario, rig, load, 30.0)
                             for load in loads}
    slides, free = change["slides"], change["free"]
    for load in (4873.3, -3379.9):
        assert slides[load] == pytest.approx(free[load], rel=0.06), load
    assert free[6126.4] < -1700.0                   # the near-slack regime
    assert (abs(slides[6126.4] - free[6126.4])
            < 0.5 * abs(change["chains"][6126.4] - free[6126.4]))


def test_a_bushed_track_steps_in_mujocos_own_integrator_as_its_viewer_does() -> None:
    """M113's MJCF (rubber bushings on slides, the hinges' torsional dampers 10 N·m·s/rad)
    stepped by ``mj_step`` alone, as MuJoCo's viewer steps it, its sprocket ramped to 2 m/s
    over 1 s: 1.5 s without a bad-acceleration warning (without the hinges' armature h·B it
    diverged at 1.2 s: MuJoCo's implicit damper is not seen by its constraint solver). The
    plant's own step takes that term into its mass matrix itself and zeroes the armature."""
    from trackmj.machines.assembly import resolve
    from trackmj.machines.track_plant import load_plant, mechanics, model_mjcf

    machine = resolve("m113")
    params = mechanics(machine)
    model = mujoco.MjModel.from_xml_string(model_mjcf(params, machine))
    hinge = model.jnt_dofadr[model.joint("link_01_pin").id]
    h, damping = model.opt.timestep, params.pin_joint.torsional_damping_N_m_s_rad
    assert model.dof_damping[hinge] == damping > 0.0
    assert model.dof_armature[hinge] == pytest.approx(h * damping)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    drive = model.actuator("sprocket_drive").id
    radius = params.sprocket_pitch_radius_m
    for k in range(1500):
        data.ctrl[drive] = min(1.0, k * h) * 2.0 / radius
        mujoco.mj_step(model, data)
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    assert np.isfinite(data.qvel).all()
    plant = load_plant(machine="m113")
    assert plant.model.dof_armature[hinge] == 0.0
