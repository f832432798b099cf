"""MJCF text of the LF1352 track side, assembled from one builder per subtree.

The model is planar (x forward, z up, all hinges about +y):

* ``chassis``: slide x, slide z, hinge y (``chassis_x``, ``chassis_z``, ``chassis_pitch``).
* ``sprocket`` (rear or front, hinge ``sprocket_hinge``, velocity servo ``sprocket_drive``;
  a positive speed turns it so the vehicle travels forward, wherever it sits) with
  ``tooth_count`` capsule teeth around a hub on which the link rails seat.
* ``idler_carrier`` on prismatic joint ``idler_slide`` carrying ``idler``, at the end
  opposite the sprocket; the slide axis points outward (away from the sprocket, +x for a
  front idler, −x for a rear one), inclined by ``[idler].slide_angle_rad`` above the
  horizontal, so a positive slide position and a positive tensioner force always tension
  the track. Actuator ``tensioner`` is affine: force = ctrl + biasprm[2]·v so that
  ``implicitfast`` integrates a cylinder's dF/dv implicitly.
* ``road_wheel_1..N`` on vertical spring-damper slides ``road_wheel_k_suspension``;
  ``return_roller_1..M`` (M may be 0) fixed to the chassis.
* ``link_00..link_{n-1}`` (:func:`link_name`): rigid links, numbered in the running
  direction for forward travel (bottom strand rearward, up round the rear wheel, top strand
  forward, down round the front wheel).
  Pin k joins link_{k-1} and link_k. The generator builds every link as a free planar body
  (world slides ``link_kk_x``, ``link_kk_z``, hinge ``link_kk_pitch`` through its centre of
  mass) and every pin as a ``connect`` equality ``pin_kk`` with the stated pin stiffness
  and damping (``[pins]``, or ``[bushings]`` when enabled), optionally with a torsional
  spring-damper (fixed tendon ``pin_kk_torsion``); with ``[track] structure = "chains"``
  (the default) :func:`trackmj.track.mjcf.structure.chain_links` then hinges the links of each
  chain to one another (hinge ``link_kk_pin``, carrying a hinged pin's torsion) and keeps
  one connect per chain, carrying the chain's pins in series. No link is the root of the
  whole loop: in a single kinematic tree the contact rows' missing J̇·q̇ term depends on
  each link's path to the root, which travels round the loop and put a
  once-per-revolution component into the idler force.

Collision filtering (contype/conaffinity bits): link rails (8) touch wheels, hub, idler and
rollers; pin spheres (16) touch the ground and sprocket teeth; links never touch links.
Wheels and idler roll without friction on the rails (condim 1), so their spin decouples
from the track and is not modelled. The ground geom's contact (condim 3, Coulomb friction)
serves MuJoCo's own viewer: trackmj's plant switches it off and applies the Kelvin–Voigt
foundation of :mod:`trackmj.track.foundation` instead (same stiffness and damping).

Stated contacts: the partner geoms (ground, hub, idler, road wheels, rollers, teeth) have
priority over the link geoms and carry the solref/solimp that give the stated Kelvin–Voigt
stiffness and damping per contact (``[ground]``, ``[contacts]``), computed from the
compiled model's row diagonals by :mod:`trackmj.track.mjcf.soft`, which documents the mapping
and what stays approximate.

Terrain: :func:`with_heightfield` replaces the flat ground by an ISO 8608 road profile
(arrays from :func:`trackmj.track.terrain.heightfield`).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

from trackmj.track.mechanics import MODEL_NAME, ModelParams, mechanics_sha256
from trackmj.track.mjcf.layout import Layout, hub_radius, outward_sign, slide_axis
from trackmj.track.mjcf.names import link_name, pin_name
from trackmj.track.mjcf.soft import SoftConstraint, body_inv_weight, row_diag, soft_constraint
from trackmj.track.mjcf.structure import chain_links, pin_series_count, stretch_armature_kg
from trackmj.track.mjcf.tree import attribute, find
from trackmj.track.terrain import RoadProfile, gravity_on_grade, heightfield
from trackmj.validator import ParameterError

_RAIL, _PIN = 8, 16  # contype bits of link rails and pin spheres
TERRAIN_WIDTH_M = 2.0
TERRAIN_BASE_M = 0.5


def _fmt(*values: float) -> str:
    """Numbers for MJCF attributes: 9 significant digits, '-0' folded to '0'."""
    out = []
    for v in values:
        s = f"{float(v):.9g}"
        out.append("0" if s == "-0" else s)
    return " ".join(out)


def _quat_y(angle: float) -> str:
    """Quaternion of a rotation that turns the body x-axis to direction (cos a, 0, sin a)."""
    return _fmt(math.cos(angle / 2.0), 0.0, -math.sin(angle / 2.0), 0.0)


def _sub(parent: ET.Element, tag: str, **attrs: str) -> ET.Element:
    return ET.SubElement(parent, tag, {k.rstrip("_"): v for k, v in attrs.items()})


def _cylinder_inertia(mass_kg: float, radius_m: float) -> str:
    return _fmt(*(0.5 * mass_kg * radius_m ** 2,) * 3)


def _wheel_geoms(body: ET.Element, name: str, radius_m: float, half_width_m: float) -> None:
    """Collision capsule across the track (class ``wheel``) and the visual cylinder."""
    _sub(body, "geom", name=f"{name}_collision", class_="wheel", size=_fmt(radius_m),
         fromto=_fmt(0, -half_width_m, 0, 0, half_width_m, 0))
    _sub(body, "geom", name=f"{name}_visual", class_="visual", type="cylinder",
         size=_fmt(radius_m, half_width_m), euler=_fmt(math.pi / 2, 0, 0))


# ----------------------------------------------------------------------------- subtrees

def _header(root: ET.Element, p: ModelParams) -> None:
    """compiler, option (integrator, solver), size and visual settings."""
    _sub(root, "compiler", angle="radian", autolimits="true")
    option = _sub(root, "option", timestep=_fmt(p.simulation.timestep_s),
                  gravity=_fmt(0, 0, -p.simulation.gravity_m_s2), integrator="implicitfast",
                  solver="Newton", jacobian=p.solver.jacobian,
                  iterations=str(p.solver.iterations), tolerance=_fmt(p.solver.tolerance),
                  cone=p.solver.cone)
    flags = {name: "disable" for name, on in (("warmstart", p.solver.warmstart),
                                                ("midphase", p.solver.midphase),
                                                ("island", p.solver.island)) if not on}
    if flags:
        _sub(option, "flag", **flags)
    _sub(root, "size", memory="16M")
    visual = _sub(root, "visual")
    _sub(visual, "global", offwidth="1280", offheight="720")


def _defaults(root: ET.Element, p: ModelParams) -> None:
    """Default classes (Menagerie habit: collision and visual geoms separate)."""
    t = p.track
    default = _sub(root, "default")
    _sub(default, "geom", contype="0", conaffinity="0", condim="1", density="0")
    vis = _sub(default, "default", class_="visual")
    _sub(vis, "geom", group="2", contype="0", conaffinity="0", rgba="0.45 0.45 0.5 1")
    col = _sub(default, "default", class_="collision")
    _sub(col, "geom", group="3", rgba="0.8 0.3 0.2 0.4")
    # link geoms (priority 0) take the partner's contact parameters, which carry the
    # solref/solimp of their stated stiffness and damping (_map_soft_constraints)
    rail = _sub(col, "default", class_="rail")
    _sub(rail, "geom", type="capsule", size=_fmt(t.rail_radius_m), contype=str(_RAIL))
    pin = _sub(col, "default", class_="pin")
    _sub(pin, "geom", type="sphere", size=_fmt(t.pin_radius_m), contype=str(_PIN))
    wheel = _sub(col, "default", class_="wheel")
    _sub(wheel, "geom", type="capsule", conaffinity=str(_RAIL), priority="1", condim="1")
    tooth = _sub(col, "default", class_="tooth")
    _sub(tooth, "geom", type="capsule", size=_fmt(p.sprocket.tooth_radius_m),
         conaffinity=str(_PIN), priority="1", condim="1")
    gnd = _sub(col, "default", class_="ground")
    _sub(gnd, "geom", conaffinity=str(_PIN), priority="2", condim="3",
         friction=_fmt(t.ground_friction, 0.005, 0.0001))
    link_j = _sub(default, "default", class_="link_pitch")
    _sub(link_j, "joint", type="hinge", axis="0 1 0")
    pin_joint = _sub(default, "default", class_="pin_joint")
    _sub(pin_joint, "equality", solref="0.02 1")  # replaced by _map_soft_constraints
    if t.structure == "slides":   # every hinged pin's own compliance (structure.py)
        stretch = _sub(default, "default", class_="pin_stretch")
        _sub(stretch, "joint", type="slide", stiffness=_fmt(p.pin_joint.radial_stiffness_N_m),
             damping=_fmt(p.pin_joint.radial_damping_N_s_m),
             armature=_fmt(stretch_armature_kg(p)))


def _world(root: ET.Element) -> ET.Element:
    """Assets, light and the flat ground (plane); returns the worldbody."""
    asset = _sub(root, "asset")
    _sub(asset, "texture", name="grid", type="2d", builtin="checker", width="256",
         height="256", rgb1="0.35 0.4 0.3", rgb2="0.3 0.35 0.25")
    _sub(asset, "material", name="ground", texture="grid", texrepeat="8 8",
         texuniform="true")
    world = _sub(root, "worldbody")
    _sub(world, "light", name="sun", pos="0 -3 6", dir="0 0.5 -1", directional="true")
    _sub(world, "geom", name="ground", class_="ground", type="plane", size="60 2 0.1",
         material="ground")
    _sub(world, "geom", name="ground_visual", class_="visual", type="plane",
         size="60 2 0.1", material="ground")
    return world


def _chassis(world: ET.Element, p: ModelParams) -> ET.Element:
    """Chassis body with its planar joints, IMU and rear-hitch sites; returns it."""
    ride = p.chassis.ride_height_m
    chassis = _sub(world, "body", name="chassis", pos=_fmt(0, 0, ride))
    _sub(chassis, "joint", name="chassis_x", type="slide", axis="1 0 0")
    _sub(chassis, "joint", name="chassis_z", type="slide", axis="0 0 1")
    _sub(chassis, "joint", name="chassis_pitch", type="hinge", axis="0 1 0")
    _sub(chassis, "inertial", pos="0 0 0.15", mass=_fmt(p.chassis.mass_kg),
         diaginertia=_fmt(p.chassis.pitch_inertia_kg_m2, p.chassis.pitch_inertia_kg_m2,
                          p.chassis.pitch_inertia_kg_m2))
    _sub(chassis, "geom", name="chassis_body", class_="visual", type="box",
         pos=_fmt(0, -0.5, 0.25),
         size=_fmt(p.chassis.length_m / 2, 0.3, p.chassis.height_m / 2), rgba="0.9 0.6 0.1 1")
    _sub(chassis, "site", name="chassis_imu", pos="0 0 0.15", size="0.02")
    _sub(chassis, "site", name="rear_hitch",
         pos=_fmt(p.chassis.hitch_x_m, 0, p.chassis.hitch_z_m - ride), size="0.03")
    return chassis


def _sprocket(chassis: ET.Element, p: ModelParams, layout: Layout) -> None:
    """Drive sprocket: hub (the rails seat on it) and teeth between the seated pins."""
    ride, half_w = p.chassis.ride_height_m, p.track.link_width_m / 2.0
    sx, sz = layout.sprocket_center
    spr = _sub(chassis, "body", name="sprocket", pos=_fmt(sx, 0, sz - ride))
    _sub(spr, "joint", name="sprocket_hinge", type="hinge", axis="0 1 0")
    _sub(spr, "inertial", pos="0 0 0", mass=_fmt(p.sprocket.mass_kg),
         diaginertia=_fmt(p.sprocket.inertia_kg_m2, p.sprocket.inertia_kg_m2,
                          p.sprocket.inertia_kg_m2))
    _sub(spr, "geom", name="sprocket_hub", class_="wheel", size=_fmt(hub_radius(p)),
         fromto=_fmt(0, -half_w, 0, 0, half_w, 0))
    _sub(spr, "geom", name="sprocket_visual", class_="visual", type="cylinder",
         size=_fmt(p.sprocket_pitch_radius_m, 0.05), euler=_fmt(math.pi / 2, 0, 0),
         rgba="0.2 0.2 0.2 1")
    rt = p.sprocket_pitch_radius_m + p.sprocket.tooth_radial_offset_m
    nt = p.sprocket.tooth_count
    for j in range(nt):
        a = layout.sprocket_seat_angle_rad + (2 * j + 1) * math.pi / nt
        x, z = rt * math.cos(a), rt * math.sin(a)
        _sub(spr, "geom", name=f"sprocket_tooth_{j:02d}", class_="tooth",
             fromto=_fmt(x, -0.06, z, x, 0.06, z))


def _idler(chassis: ET.Element, p: ModelParams, layout: Layout) -> None:
    """Idler wheel on the tensioning carrier (prismatic ``idler_slide``)."""
    ride, half_w = p.chassis.ride_height_m, p.track.link_width_m / 2.0
    ix, iz = layout.idler_center
    ux, uz = slide_axis(p)
    carrier = _sub(chassis, "body", name="idler_carrier", pos=_fmt(ix, 0, iz - ride))
    _sub(carrier, "joint", name="idler_slide", type="slide", axis=_fmt(ux, 0, uz),
         range=_fmt(*p.idler.slide_range_m))
    _sub(carrier, "inertial", pos="0 0 0", mass=_fmt(p.idler.carrier_mass_kg),
         diaginertia="0.5 0.5 0.5")
    _sub(carrier, "geom", name="idler_carrier_visual", class_="visual", type="box",
         pos=_fmt(-0.25 * outward_sign(p), -0.3, 0), size="0.25 0.04 0.04",
         rgba="0.3 0.3 0.8 1")
    _sub(carrier, "site", name="idler_force_site", pos="0 0 0", size="0.02")
    idler = _sub(carrier, "body", name="idler", pos="0 0 0")
    _sub(idler, "inertial", pos="0 0 0", mass=_fmt(p.idler.mass_kg),
         diaginertia=_cylinder_inertia(p.idler.mass_kg, p.idler.radius_m))
    _sub(idler, "geom", name="idler_wheel", class_="wheel", size=_fmt(p.idler.radius_m),
         fromto=_fmt(0, -half_w, 0, 0, half_w, 0))
    _sub(idler, "geom", name="idler_visual", class_="visual", type="cylinder",
         size=_fmt(p.idler.radius_m, half_w), euler=_fmt(math.pi / 2, 0, 0))


def _running_gear(chassis: ET.Element, p: ModelParams, layout: Layout) -> None:
    """Road wheels on preloaded spring-damper slides, and the fixed return rollers."""
    ride, half_w = p.chassis.ride_height_m, p.track.link_width_m / 2.0
    rw = p.road_wheels
    wheel_load = (p.chassis.mass_kg + p.sprocket.mass_kg + p.idler.mass_kg
                  + p.idler.carrier_mass_kg) * p.simulation.gravity_m_s2 / rw.count
    for k, (wx, wz) in enumerate(layout.road_wheel_centers, start=1):
        body = _sub(chassis, "body", name=f"road_wheel_{k}", pos=_fmt(wx, 0, wz - ride))
        # springref preloads the spring with the wheel's static share of the sprung weight
        _sub(body, "joint", name=f"road_wheel_{k}_suspension", type="slide", axis="0 0 1",
             stiffness=_fmt(rw.suspension_stiffness_N_m),
             damping=_fmt(rw.suspension_damping_N_s_m),
             springref=_fmt(-wheel_load / rw.suspension_stiffness_N_m),
             range=_fmt(*rw.suspension_range_m))
        _sub(body, "inertial", pos="0 0 0", mass=_fmt(rw.mass_kg),
             diaginertia=_cylinder_inertia(rw.mass_kg, rw.radius_m))
        _wheel_geoms(body, f"road_wheel_{k}", rw.radius_m, half_w)
    for k, (rx, rz) in enumerate(layout.roller_centers, start=1):
        body = _sub(chassis, "body", name=f"return_roller_{k}", pos=_fmt(rx, 0, rz - ride))
        _wheel_geoms(body, f"return_roller_{k}", p.return_rollers.radius_m, half_w)


def _link_inertia(p: ModelParams) -> tuple[float, float, float]:
    """Principal moments of a link about its centre of mass [kg·m²] (x along the link,
    y the pin axis); a box of pitch x width x pin diameter."""
    t = p.track
    m, L, w, h = t.link_mass_kg, t.pitch_m, t.link_width_m, 2.0 * t.pin_radius_m
    return m * (w * w + h * h) / 12, m * (L * L + h * h) / 12, m * (L * L + w * w) / 12


def _link_directions(layout: Layout) -> np.ndarray:
    """Angle of every link's axis (pin k -> pin k+1) from +x towards +z [rad], (link_count,)."""
    pins = layout.pins
    step = np.roll(pins, -1, axis=0) - pins
    return np.arctan2(step[:, 1], step[:, 0])


def _links(root: ET.Element, world: ET.Element, p: ModelParams, layout: Layout) -> None:
    """The links as free planar bodies joined by one ``connect`` per pin.

    Link k has its origin at pin k and its x axis towards pin k+1; its joints are world
    slides ``link_kk_x``, ``link_kk_z`` and the hinge ``link_kk_pitch`` about +y through
    its centre of mass, so its mass matrix is constant and every link is equivalent.
    Equality ``pin_kk`` joins the far end of link_{k-1} to the origin of link k; the
    optional fixed tendon ``pin_kk_torsion`` (pitch_k − pitch_{k-1}) carries the pin's
    torsional spring-damper, neutral when the two links are in line.
    """
    t, joint = p.track, p.pin_joint
    pitch, n, half_w = t.pitch_m, t.link_count, t.link_width_m / 2.0
    pins = layout.pins
    direction = _link_directions(layout)
    for k in range(n):
        quat = _quat_y(direction[k])
        body = _sub(world, "body", name=link_name(k), pos=_fmt(pins[k, 0], 0, pins[k, 1]),
                    quat=quat)
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, np.array([float(v) for v in quat.split()]))
        rot = rot.reshape(3, 3)
        # slide axes are given in the body frame: world x and z seen from the link
        _sub(body, "joint", name=link_name(k) + "_x", type="slide",
             axis=_fmt(*(rot.T @ (1.0, 0.0, 0.0))))
        _sub(body, "joint", name=link_name(k) + "_z", type="slide",
             axis=_fmt(*(rot.T @ (0.0, 0.0, 1.0))))
        _sub(body, "joint", name=link_name(k) + "_pitch", class_="link_pitch",
             pos=_fmt(pitch / 2, 0, 0))
        _sub(body, "inertial", pos=_fmt(pitch / 2, 0, 0), mass=_fmt(t.link_mass_kg),
             diaginertia=_fmt(*_link_inertia(p)))
        _sub(body, "geom", name=link_name(k) + "_rail", class_="rail",
             fromto=_fmt(0, 0, 0, pitch, 0, 0))
        _sub(body, "geom", name=link_name(k) + "_pin", class_="pin", pos="0 0 0")
        _sub(body, "geom", name=link_name(k) + "_shoe", class_="visual", type="box",
             pos=_fmt(pitch / 2, 0, 0), size=_fmt(pitch * 0.48, half_w, t.rail_radius_m),
             rgba="0.25 0.25 0.28 1")
    if joint.torsional_stiffness_N_m_rad > 0.0 or joint.torsional_damping_N_m_s_rad > 0.0:
        tendon = _sub(root, "tendon")
        for k in range(n):
            # a hinge angle q about +y turns the link by −q in the x-z plane, so the pin's
            # twist from in-line is (dir_k − q_k) − (dir_{k-1} − q_{k-1}): zero when the
            # tendon length q_k − q_{k-1} equals dir_k − dir_{k-1} (wrapped to ±π)
            neutral = math.remainder(direction[k] - direction[k - 1], 2.0 * math.pi)
            fixed = _sub(tendon, "fixed", name=pin_name(k) + "_torsion",
                         stiffness=_fmt(joint.torsional_stiffness_N_m_rad),
                         damping=_fmt(joint.torsional_damping_N_m_s_rad),
                         springlength=_fmt(neutral))
            _sub(fixed, "joint", joint=link_name(k) + "_pitch", coef="1")
            _sub(fixed, "joint", joint=link_name((k - 1) % n) + "_pitch", coef="-1")
    equality = _sub(root, "equality")
    for k in range(n):
        _sub(equality, "connect", name=pin_name(k), class_="pin_joint",
             body1=link_name((k - 1) % n), body2=link_name(k),
             anchor=_fmt(pitch, 0, 0))


def _check_torsion(p: ModelParams) -> None:
    """Limits of the pins' torsional spring-damper at this timestep (I: a link's pitch
    inertia about its centre of mass, h: the timestep).

    The springs are explicit (tendons, and on chains the hinge joints' stiffness): the
    zig-zag mode of the links, ω² = 4·k_t/I, must keep soft_margin·(hω)²/4 <= 1. The
    dampers: on free links every pin is a fixed tendon joining two links, two trees, and
    MuJoCo 4.0.0's ``implicitfast`` keeps only the same-tree entries of a tendon's damping
    derivative, none of which the constraint solver sees; measured on LF1352 at 1 ms it
    diverges from 0.2 N·m·s/rad (0.15 holds), so the limit is I/(20·h). On chains and
    slides a hinged pin's damper is taken into the step's mass matrix
    (:class:`trackmj.track.foundation.ImplicitSprings`, no limit), and the connects' tendons
    join a chain's root pitch and pin hinges to the next root: driven at 2.0 m/s on slides
    LF1352 holds 0.5 N·m·s/rad (0.27·I/h) and diverges at 1.0 (0.53·I/h), M113's connects
    hold 40 (0.98·I/h; 80 creates 8 % of the drive work), so the limit is I/(4·h).
    """
    joint, table = p.pin_joint, p.pin_joint_table
    inertia, h = _link_inertia(p)[1], p.simulation.timestep_s
    stiffness_limit = inertia / (p.solver.soft_margin * h * h)
    share = 20.0 if p.track.structure == "free" else 4.0
    damping_limit = inertia / (share * h)
    if joint.torsional_stiffness_N_m_rad > stiffness_limit:
        raise p.origin.error((table, "torsional_stiffness_N_m_rad"),
                             joint.torsional_stiffness_N_m_rad,
                             f"exceeds the explicit limit {stiffness_limit:.0f} N·m/rad (link "
                             "pitch inertia / (soft_margin·timestep²))")
    if joint.torsional_damping_N_m_s_rad > damping_limit:
        raise p.origin.error((table, "torsional_damping_N_m_s_rad"),
                             joint.torsional_damping_N_m_s_rad,
                             f"exceeds {damping_limit:.3f} N·m·s/rad (link pitch inertia / "
                             f"({share:.0f}·timestep) for structure "
                             f"\"{p.track.structure}\"); larger values diverge at this "
                             "timestep")


CONTACT_PARTNERS = {"ground": "ground", "sprocket_hub": "rail", "idler_wheel": "rail"}
"""Partner geoms by kind, besides road wheels, return rollers (rail) and teeth (tooth)."""


def contact_kind(geom_name: str) -> str | None:
    """Stated-parameter kind of a partner geom: 'ground', 'rail', 'tooth' or None."""
    if geom_name.startswith("sprocket_tooth_"):
        return "tooth"
    if geom_name.startswith(("road_wheel_", "return_roller_")) and geom_name.endswith(
            "_collision"):
        return "rail"
    return CONTACT_PARTNERS.get(geom_name)


def soft_constraints(p: ModelParams, model: mujoco.MjModel) -> dict[str, SoftConstraint]:
    """The MuJoCo parameters of every stated contact (by partner geom name) and of every pin
    connect (by its name, :func:`pin_name`), from the row diagonals of ``model`` (see
    :mod:`trackmj.track.mjcf.soft`)."""
    h, margin = p.simulation.timestep_s, p.solver.soft_margin
    link = body_inv_weight(model, "link_00")
    stated = {"ground": (p.ground.stiffness_N_m, p.ground.damping_N_s_m, "[ground]"),
              "rail": (p.contacts.rail_stiffness_N_m, p.contacts.rail_damping_N_s_m,
                       "[contacts].rail_*"),
              "tooth": (p.contacts.tooth_stiffness_N_m, p.contacts.tooth_damping_N_s_m,
                        "[contacts].tooth_*")}
    out = {}
    for g in range(model.ngeom):
        name = model.geom(g).name
        kind = contact_kind(name)
        if kind is None:
            continue
        partner = float(model.body_invweight0[model.geom_bodyid[g], 0])
        rows, diag = row_diag(link + partner, int(model.geom_condim[g]),
                              float(model.geom_friction[g, 0]), float(model.opt.impratio))
        stiffness, damping, key = stated[kind]
        out[name] = soft_constraint(stiffness, damping, rows, diag, h, margin,
                                    f"{p.origin.table()} {key}")
    joint = p.pin_joint
    rows, diag = row_diag(2.0 * link, condim=1)
    for k, series in pin_series_count(p).items():   # pins in series on one connect
        out[pin_name(k)] = soft_constraint(joint.radial_stiffness_N_m / series,
                                           joint.radial_damping_N_s_m / series, rows, diag,
                                           h, margin,
                                           f"{p.origin.table()} [{p.pin_joint_table}]")
    return out


def _map_soft_constraints(root: ET.Element, p: ModelParams) -> None:
    """Set solref/solimp of the partner geoms and of the pin connects from the stated
    stiffness and damping (compiles the model once for its row diagonals). The ground's go
    on the ``ground`` class, so the scene's ground geom (and a heightfield) carries none."""
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    mapping = soft_constraints(p, model)
    classes = {"ground": find(root, "default/default[@class='collision']"
                                    "/default[@class='ground']/geom")}
    for geom in root.iter("geom"):
        name = geom.get("name", "")
        soft = mapping.get(name)
        if soft is not None:
            target = classes.get(name, geom)
            target.set("solref", _fmt(*soft.solref))
            target.set("solimp", _fmt(*soft.solimp))
    # the pin class takes pin_00's mapping; a connect carrying another number of pins in
    # series (a chain of another length) carries its own
    pin_class = find(root, "default/default[@class='pin_joint']/equality")
    first = mapping[pin_name(0)]
    pin_class.set("solref", _fmt(*first.solref))
    pin_class.set("solimp", _fmt(*first.solimp))
    for connect in root.iter("connect"):
        soft = mapping[attribute(connect, "name")]
        if soft != first:
            connect.set("solref", _fmt(*soft.solref))
            connect.set("solimp", _fmt(*soft.solimp))


def _actuators(root: ET.Element, p: ModelParams) -> None:
    """Sprocket velocity servo and the affine tensioner actuator on the idler slide."""
    actuator = _sub(root, "actuator")
    _sub(actuator, "velocity", name="sprocket_drive", joint="sprocket_hinge",
         kv=_fmt(p.sprocket.drive_gain_N_m_s),
         forcerange=_fmt(-p.sprocket.drive_torque_limit_N_m, p.sprocket.drive_torque_limit_N_m))
    _sub(actuator, "general", name="tensioner", joint="idler_slide", gaintype="fixed",
         gainprm="1", biastype="affine", biasprm="0 0 0")


def build_mjcf(p: ModelParams, layout: Layout, home_qpos: np.ndarray | None = None,
               name: str = MODEL_NAME) -> str:
    """MJCF text of the track side for ``layout``; ``home_qpos`` adds the ``home`` keyframe;
    ``name``: the machine's (the model's name and the parameter file ``NAME.toml`` named in
    the header)."""
    root = ET.Element("mujoco", model=name)
    _header(root, p)
    _defaults(root, p)
    world = _world(root)
    chassis = _chassis(world, p)
    _sprocket(chassis, p, layout)
    _idler(chassis, p, layout)
    _running_gear(chassis, p, layout)
    _check_torsion(p)
    _links(root, world, p, layout)
    if p.track.structure in ("chains", "slides"):
        chain_links(root, p)
    _actuators(root, p)
    _map_soft_constraints(root, p)
    if home_qpos is not None:
        keyframe = _sub(root, "keyframe")
        _sub(keyframe, "key", name="home", qpos=" ".join(f"{v:.6f}" for v in home_qpos),
             ctrl=_fmt(0.0, p.tensioner.preload_N))
    ET.indent(root, space="  ")
    return (_header_comment(name, mechanics_sha256(p)) + ET.tostring(root, encoding="unicode")
            + "\n")


def _header_comment(name: str, digest: str | None, part: str = "", origin: str = "") -> str:
    """The comment opening a generated model: machine ``name``, the part, the SHA-256 of
    the mechanics' values it was generated from (:func:`recorded_mechanics_sha256` reads
    it back; None: a joined part recorded none) and, for a written file, ``origin``: its
    mechanics file and the command that regenerates it."""
    return (f"<!-- Generated by trackmj.track.mjcf for machine {name}{part}; do not edit by "
            "hand." + (f"\n     mechanics sha256 {digest}" if digest else "")
            + (f"\n     {origin}" if origin else "") + " -->\n")


_RECORDED_SHA256 = re.compile(r"\A\s*<!--[^>]*?mechanics sha256 ([0-9a-f]{64})")


def recorded_mechanics_sha256(mjcf: str) -> str | None:
    """The mechanics SHA-256 a generated model's opening comment records (None: none, e.g.
    a file written before trackmj recorded it, or by hand)."""
    match = _RECORDED_SHA256.match(mjcf)
    return match.group(1) if match else None


SCENE_ITEMS = ("light[@name='sun']", "geom[@name='ground']", "geom[@name='ground_visual']")
"""What the scene holds besides the ground assets (MuJoCo Menagerie's scene.xml habit)."""


def _strip_comment(mjcf: str) -> str:
    return mjcf.split("-->", 1)[1] if mjcf.lstrip().startswith("<!--") else mjcf


def split_mjcf(mjcf: str, machine_file: str, origin: str) -> tuple[str, str]:
    """The machine and scene parts of a full model (Menagerie habit): the scene holds the
    ground's texture and material, the light and the ground, and includes ``machine_file``
    (the machine part's file name), which holds everything else; both headers keep the
    model's mechanics SHA-256 and add ``origin`` (the mechanics file, the command that
    regenerates them). :func:`join_mjcf` undoes it."""
    digest = recorded_mechanics_sha256(mjcf)
    root = ET.fromstring(_strip_comment(mjcf))
    name = attribute(root, "model")
    asset = find(root, "asset")
    root.remove(asset)
    world = find(root, "worldbody")
    items = [find(world, path) for path in SCENE_ITEMS]
    for item in items:
        world.remove(item)
    scene = ET.Element("mujoco", model=name)
    _sub(scene, "include", file=machine_file)
    scene.append(asset)
    scene_world = _sub(scene, "worldbody")
    scene_world.extend(items)
    for part in (root, scene):
        ET.indent(part, space="  ")
    return (_header_comment(name, digest, ", the machine part (its scene includes it)", origin)
            + ET.tostring(root, encoding="unicode") + "\n",
            _header_comment(name, digest, ", the scene: ground and light", origin)
            + ET.tostring(scene, encoding="unicode") + "\n")


def join_mjcf(scene: str, machine: str) -> str:
    """One self-contained MJCF of a scene and the machine part it includes: the scene's
    assets after the machine's defaults, its light and ground first in the worldbody (the
    compiled model is the one of the full model :func:`split_mjcf` split)."""
    scene_root = ET.fromstring(_strip_comment(scene))
    root = ET.fromstring(_strip_comment(machine))
    position = list(root).index(find(root, "default")) + 1
    root.insert(position, find(scene_root, "asset"))
    world = find(root, "worldbody")
    for k, item in enumerate(find(scene_root, "worldbody")):
        world.insert(k, item)
    ET.indent(root, space="  ")
    return (_header_comment(attribute(root, "model"), recorded_mechanics_sha256(machine))
            + ET.tostring(root, encoding="unicode") + "\n")


def read_mjcf(path: str | Path) -> str:
    """The MJCF text of ``path`` as one self-contained model: a scene that includes its
    machine part (relative to the scene's directory) is joined (:func:`join_mjcf`)."""
    parts = mjcf_parts(path)
    return parts[0][1] if len(parts) == 1 else join_mjcf(parts[0][1], parts[1][1])


def mjcf_parts(path: str | Path) -> list[tuple[Path, str]]:
    """(file, text) of the MJCF ``path`` and, if it includes one, of its machine part
    (relative to its directory); ParameterError naming the including file if that part is
    missing."""
    path = Path(path)
    text = path.read_text()
    include = ET.fromstring(_strip_comment(text)).find("include")
    if include is None:
        return [(path, text)]
    name = attribute(include, "file")
    part = path.parent / name
    if not part.is_file():
        raise ParameterError(f"{path}: <include file=\"{name}\"/>: no such file {part}")
    return [(path, text), (part, part.read_text())]


def on_grade(mjcf: str, grade: float) -> str:
    """``mjcf`` on a slope of ``grade`` = tan θ [-] (rise over run, > 0 uphill driving
    forward, +x): its gravity tilted (:func:`trackmj.track.terrain.gravity_on_grade`)."""
    root = ET.fromstring(_strip_comment(mjcf))
    option = find(root, "option")
    level = [float(v) for v in attribute(option, "gravity").split()]
    option.set("gravity", _fmt(*gravity_on_grade(level, grade)))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def with_heightfield(mjcf: str, profile: RoadProfile) -> str:
    """Replace the flat ground of ``mjcf`` by the heightfield of road ``profile``.

    The road is constant across the track (the model is planar); elevation 0 is the flat
    ground level. The ground contact keeps the flat ground's foundation (class ``ground``);
    the plant's foundation takes the heightfield's profile as its ground line.
    """
    heights = np.asarray(profile.z_m, dtype=float)
    if heights.ndim != 1 or len(heights) < 4 or not np.all(np.isfinite(heights)):
        raise ParameterError("terrain heights_m must be a finite 1-D array of >= 4 values")
    if not (math.isfinite(profile.dx_m) and profile.dx_m > 0.0):
        raise ParameterError(f"terrain dx_m = {profile.dx_m!r} must be > 0")
    field = heightfield(profile, width_m=TERRAIN_WIDTH_M, base_m=TERRAIN_BASE_M)
    root = ET.fromstring(_strip_comment(mjcf))
    nrow, ncol = field.data.shape
    _sub(find(root, "asset"), "hfield", name="terrain", nrow=str(nrow), ncol=str(ncol),
         size=_fmt(*field.size), elevation=" ".join(f"{v:.6f}" for v in field.data.ravel()))
    world = find(root, "worldbody")
    ground = find(world, "geom[@name='ground']")
    for key in ("type", "size"):
        ground.attrib.pop(key, None)
    ground.set("type", "hfield")
    ground.set("hfield", "terrain")
    ground.set("pos", _fmt(*field.pos))
    find(world, "geom[@name='ground_visual']").set("pos", _fmt(0.0, 0.0, field.pos[2] - 0.01))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"
