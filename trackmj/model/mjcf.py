"""MJCF text of the LF1352 track side, assembled from one builder per subtree.

The model is planar (x forward, z up, all hinges about +y):

* ``chassis``: slide x, slide z, hinge y (``chassis_x``, ``chassis_z``, ``chassis_pitch``).
* ``sprocket`` (rear, hinge ``sprocket_hinge``, velocity servo ``sprocket_drive``) with
  ``tooth_count`` capsule teeth around a hub on which the link rails seat.
* ``idler_carrier`` on prismatic joint ``idler_slide`` (+x = outward = tensioning) carrying
  ``idler``; actuator ``tensioner`` is affine: force = ctrl + biasprm[2]·v so that
  ``implicitfast`` integrates a cylinder's dF/dv implicitly.
* ``road_wheel_1..6`` on vertical spring-damper slides ``road_wheel_k_suspension``;
  ``return_roller_1..2`` fixed to the chassis.
* ``link_00..link_81``: rigid links, numbered in the running direction for forward travel
  (bottom strand rearward, over the sprocket, top strand forward, round the idler).
  Pin k joins link_{k-1} and link_k. The links form a tree rooted at ``link_00`` (bottom
  strand, planar joints) with two branches (link_01..link_40 and link_81..link_41) closed by
  ONE ``connect`` equality ``loop_closure`` at pin 41; this halves the chain depth compared
  with a single chain and keeps constraint Jacobians short.

Collision filtering (contype/conaffinity bits): link rails (8) touch wheels, hub, idler and
rollers; pin spheres (16) touch the ground and sprocket teeth; links never touch links.
Wheels and idler roll without friction on the rails (condim 1), so their spin decouples
from the track and is not modelled; the ground contact carries Coulomb friction (condim 3).

Ground foundation: MuJoCo's direct ``solref = (-k, -b)`` is mass-normalised. With a
constant impedance d (``solimp = d d ...``) a contact of effective mass m responds with the
physical stiffness K = m·k·d/(1−d) and damping B = m·b·d/(1−d); :func:`ground_solref`
inverts this with ``ground.reference_mass_kg`` so the TOML holds K [N/m] and B [N·s/m] per
pin contact.

Terrain: :func:`with_heightfield` replaces the flat ground by an ISO 8608 road profile
(arrays from :func:`trackmj.terrain.heightfield`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from trackmj.model.layout import Layout, hub_radius
from trackmj.model.params import LOOP_CLOSURE_PIN, MODEL_NAME, ModelParams
from trackmj.params import ParameterError
from trackmj.terrain import RoadProfile, heightfield

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


def ground_solref(p: ModelParams) -> tuple[float, float]:
    """MuJoCo direct solref (-k, -b) giving the physical ground stiffness and damping."""
    g = p.ground
    scale = (1.0 - g.impedance) / (g.impedance * g.reference_mass_kg)
    return -g.stiffness_N_m * scale, -g.damping_N_s_m * scale


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
                                                ("midphase", p.solver.midphase)) if not on}
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
    rail = _sub(col, "default", class_="rail")
    _sub(rail, "geom", type="capsule", size=_fmt(t.rail_radius_m), contype=str(_RAIL),
         solref=_fmt(*p.contacts.rail_solref))
    pin = _sub(col, "default", class_="pin")
    _sub(pin, "geom", type="sphere", size=_fmt(t.pin_radius_m), contype=str(_PIN))
    wheel = _sub(col, "default", class_="wheel")
    _sub(wheel, "geom", type="capsule", conaffinity=str(_RAIL),
         solref=_fmt(*p.contacts.rail_solref))
    tooth = _sub(col, "default", class_="tooth")
    _sub(tooth, "geom", type="capsule", size=_fmt(p.sprocket.tooth_radius_m),
         conaffinity=str(_PIN), priority="1", condim="1",
         solref=_fmt(*p.contacts.tooth_solref))
    gnd = _sub(col, "default", class_="ground")
    _sub(gnd, "geom", conaffinity=str(_PIN), priority="2", condim="3",
         friction=_fmt(t.ground_friction, 0.005, 0.0001), solref=_fmt(*ground_solref(p)),
         solimp=_fmt(p.ground.impedance, p.ground.impedance, 0.001, 0.5, 2))
    link_j = _sub(default, "default", class_="pin_hinge")
    _sub(link_j, "joint", type="hinge", axis="0 1 0")


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
    carrier = _sub(chassis, "body", name="idler_carrier", pos=_fmt(ix, 0, iz - ride))
    _sub(carrier, "joint", name="idler_slide", type="slide", axis="1 0 0",
         range=_fmt(*p.idler.slide_range_m))
    _sub(carrier, "inertial", pos="0 0 0", mass=_fmt(p.idler.carrier_mass_kg),
         diaginertia="0.5 0.5 0.5")
    _sub(carrier, "geom", name="idler_carrier_visual", class_="visual", type="box",
         pos=_fmt(-0.25, -0.3, 0), size="0.25 0.04 0.04", rgba="0.3 0.3 0.8 1")
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


def _link_inertial(body: ET.Element, p: ModelParams) -> None:
    t = p.track
    m, L, w, h = t.link_mass_kg, t.pitch_m, t.link_width_m, 2.0 * t.pin_radius_m
    _sub(body, "inertial", pos=_fmt(L / 2, 0, 0), mass=_fmt(m),
         diaginertia=_fmt(m * (w * w + h * h) / 12, m * (L * L + h * h) / 12,
                          m * (L * L + w * w) / 12))


def _links(root: ET.Element, world: ET.Element, p: ModelParams, layout: Layout) -> None:
    """The 82 links as a tree rooted at link_00 with two branches, closed at pin 41."""
    t = p.track
    pitch, n, half_w = t.pitch_m, t.link_count, t.link_width_m / 2.0
    pins = layout.pins
    direction = np.array([math.atan2(*(pins[(k + 1) % n] - pins[k])[::-1]) for k in range(n)])
    half = LOOP_CLOSURE_PIN  # branch A: links 1..40, branch B: links 81..41

    def add_link_geoms(body: ET.Element, k: int, pin_at_origin: bool) -> None:
        _link_inertial(body, p)
        _sub(body, "geom", name=f"link_{k:02d}_rail", class_="rail",
             fromto=_fmt(0, 0, 0, pitch, 0, 0))
        _sub(body, "geom", name=f"link_{k:02d}_pin", class_="pin",
             pos=_fmt(0 if pin_at_origin else pitch, 0, 0))
        _sub(body, "geom", name=f"link_{k:02d}_shoe", class_="visual", type="box",
             pos=_fmt(pitch / 2, 0, 0), size=_fmt(pitch * 0.48, half_w, t.rail_radius_m),
             rgba="0.25 0.25 0.28 1")

    root_link = _sub(world, "body", name="link_00", pos=_fmt(pins[0, 0], 0, pins[0, 1]),
                     quat=_quat_y(direction[0]))
    _sub(root_link, "joint", name="link_00_x", type="slide", axis="1 0 0")
    _sub(root_link, "joint", name="link_00_z", type="slide", axis="0 0 1")
    _sub(root_link, "joint", name="link_00_pitch", class_="pin_hinge")
    add_link_geoms(root_link, 0, pin_at_origin=True)

    parent, parent_angle = root_link, direction[0]
    for k in range(1, half):
        body = _sub(parent, "body", name=f"link_{k:02d}", pos=_fmt(pitch, 0, 0),
                    quat=_quat_y(direction[k] - parent_angle))
        _sub(body, "joint", name=f"pin_{k:02d}", class_="pin_hinge")
        add_link_geoms(body, k, pin_at_origin=True)
        parent, parent_angle = body, direction[k]
    _sub(parent, "site", name="closure_a", pos=_fmt(pitch, 0, 0), size="0.01")

    parent, parent_angle, offset = root_link, direction[0], 0.0
    for k in range(n - 1, half - 1, -1):
        angle = direction[k] + math.pi
        body = _sub(parent, "body", name=f"link_{k:02d}", pos=_fmt(offset, 0, 0),
                    quat=_quat_y(angle - parent_angle))
        _sub(body, "joint", name=f"pin_{(k + 1) % n:02d}", class_="pin_hinge")
        add_link_geoms(body, k, pin_at_origin=False)
        parent, parent_angle, offset = body, angle, pitch
    _sub(parent, "site", name="closure_b", pos=_fmt(pitch, 0, 0), size="0.01")

    equality = _sub(root, "equality")
    _sub(equality, "connect", name="loop_closure", body1=f"link_{half - 1:02d}",
         body2=f"link_{half:02d}", anchor=_fmt(pitch, 0, 0),
         solref=_fmt(*p.contacts.closure_solref), solimp="0.99 0.999 0.001 0.5 2")


def _actuators(root: ET.Element, p: ModelParams) -> None:
    """Sprocket velocity servo and the affine tensioner actuator on the idler slide."""
    actuator = _sub(root, "actuator")
    _sub(actuator, "velocity", name="sprocket_drive", joint="sprocket_hinge",
         kv=_fmt(p.sprocket.drive_gain_N_m_s),
         forcerange=_fmt(-p.sprocket.drive_torque_limit_N_m, p.sprocket.drive_torque_limit_N_m))
    _sub(actuator, "general", name="tensioner", joint="idler_slide", gaintype="fixed",
         gainprm="1", biastype="affine", biasprm="0 0 0")


def build_mjcf(p: ModelParams, layout: Layout, home_qpos: np.ndarray | None = None) -> str:
    """MJCF text of the track side for ``layout``; ``home_qpos`` adds the ``home`` keyframe."""
    root = ET.Element("mujoco", model=MODEL_NAME)
    _header(root, p)
    _defaults(root, p)
    world = _world(root)
    chassis = _chassis(world, p)
    _sprocket(chassis, p, layout)
    _idler(chassis, p, layout)
    _running_gear(chassis, p, layout)
    _links(root, world, p, layout)
    _actuators(root, p)
    if home_qpos is not None:
        keyframe = _sub(root, "keyframe")
        _sub(keyframe, "key", name="home", qpos=" ".join(f"{v:.6f}" for v in home_qpos),
             ctrl=_fmt(0.0, p.tensioner.preload_N))
    ET.indent(root, space="  ")
    header = ("<!-- Generated by trackmj.model from lf1352.toml; do not edit by hand.\n"
              "     Regenerate with: trackmj model generate -->\n")
    return header + ET.tostring(root, encoding="unicode") + "\n"


def with_heightfield(mjcf: str, profile: RoadProfile) -> str:
    """Replace the flat ground of ``mjcf`` by the heightfield of road ``profile``.

    The road is constant across the track (the model is planar); elevation 0 is the flat
    ground level. The ground contact keeps the flat ground's foundation (class ``ground``).
    """
    heights = np.asarray(profile.z_m, dtype=float)
    if heights.ndim != 1 or len(heights) < 4 or not np.all(np.isfinite(heights)):
        raise ParameterError("terrain heights_m must be a finite 1-D array of >= 4 values")
    if not (math.isfinite(profile.dx_m) and profile.dx_m > 0.0):
        raise ParameterError(f"terrain dx_m = {profile.dx_m!r} must be > 0")
    field = heightfield(profile, width_m=TERRAIN_WIDTH_M, base_m=TERRAIN_BASE_M)
    root = ET.fromstring(mjcf.split("-->", 1)[1] if mjcf.lstrip().startswith("<!--") else mjcf)
    nrow, ncol = field.data.shape
    _sub(root.find("asset"), "hfield", name="terrain", nrow=str(nrow), ncol=str(ncol),
         size=_fmt(*field.size), elevation=" ".join(f"{v:.6f}" for v in field.data.ravel()))
    world = root.find("worldbody")
    ground = world.find("geom[@name='ground']")
    for key in ("type", "size"):
        ground.attrib.pop(key, None)
    ground.set("type", "hfield")
    ground.set("hfield", "terrain")
    ground.set("pos", _fmt(*field.pos))
    world.find("geom[@name='ground_visual']").set("pos", _fmt(0.0, 0.0, field.pos[2] - 0.01))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"
