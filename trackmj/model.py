"""Generator of the LF1352 track-side MuJoCo model (``models/lf1352.xml``).

The model is planar (x forward, z up, all hinges about +y) and built from
``models/lf1352.toml``:

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
physical stiffness K = m·k·d/(1−d) and damping B = m·b·d/(1−d); the generator inverts this
with ``ground.reference_mass_kg`` so the TOML holds K [N/m] and B [N·s/m] per pin contact.
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.optimize import brentq
from scipy.spatial import ConvexHull

from trackmj.params import ParameterError, load_table, param, read_toml

MODEL_NAME = "lf1352"
LOOP_CLOSURE_PIN = 41


def models_dir() -> Path:
    """Directory holding the packaged model files."""
    return Path(str(resources.files("trackmj.models")))


def default_param_path() -> Path:
    return models_dir() / f"{MODEL_NAME}.toml"


def default_xml_path() -> Path:
    return models_dir() / f"{MODEL_NAME}.xml"


@dataclass(frozen=True)
class SimulationParams:
    timestep_s: float = param(1e-5, 1e-3, doc="MuJoCo timestep [s]; divides the 1 ms step")
    gravity_m_s2: float = param(0.0, 20.0, doc="gravitational acceleration [m/s²]")


@dataclass(frozen=True)
class TrackParams:
    link_count: int = param(20, 200, doc="number of links [-]")
    pitch_m: float = param(0.02, 0.3, open_low=True, doc="pin-to-pin distance [m]")
    link_mass_kg: float = param(0.1, 100.0, doc="mass of one link with its shoe [kg]")
    rail_radius_m: float = param(0.002, 0.05, doc="rail capsule radius [m]")
    pin_radius_m: float = param(0.002, 0.05, doc="pin sphere radius [m]")
    link_width_m: float = param(0.05, 1.5, doc="shoe width [m], visual and inertia")
    ground_friction: float = param(0.0, 2.0, doc="Coulomb coefficient pin-ground [-]")


@dataclass(frozen=True)
class ChassisParams:
    mass_kg: float = param(10.0, 1e5)
    pitch_inertia_kg_m2: float = param(1.0, 1e6)
    length_m: float = param(0.1, 20.0)
    height_m: float = param(0.05, 5.0)
    ride_height_m: float = param(0.05, 3.0, doc="chassis origin above ground [m]")
    hitch_x_m: float = param(-10.0, 10.0, doc="rear hitch, chassis frame x [m]")
    hitch_z_m: float = param(0.0, 5.0, doc="rear hitch height above ground at layout [m]")


@dataclass(frozen=True)
class SprocketParams:
    tooth_count: int = param(6, 40)
    x_m: float = param(-10.0, 10.0)
    z_m: float = param(0.0, 5.0)
    tooth_radius_m: float = param(0.002, 0.1)
    tooth_radial_offset_m: float = param(-0.05, 0.05)
    mass_kg: float = param(0.1, 1e4)
    inertia_kg_m2: float = param(1e-4, 1e4)
    drive_gain_N_m_s: float = param(1.0, 1e8, doc="velocity servo gain [N·m·s/rad]")
    drive_torque_limit_N_m: float = param(1.0, 1e7)


@dataclass(frozen=True)
class IdlerParams:
    radius_m: float = param(0.02, 1.0)
    x_m: float = param(-10.0, 10.0)
    z_m: float = param(0.0, 5.0)
    mass_kg: float = param(0.1, 1e4)
    carrier_mass_kg: float = param(0.1, 1e4)
    slide_range_m: tuple[float, float] = param(-1.0, 1.0)
    stroke_at_layout_m: float = param(0.0, 1.0, doc="cylinder stroke at slide q = 0 [m]")


@dataclass(frozen=True)
class RoadWheelParams:
    count: int = param(1, 12)
    radius_m: float = param(0.02, 1.0)
    x_m: tuple[float, ...] = param(-10.0, 10.0)
    mass_kg: float = param(0.1, 1e4)
    suspension_stiffness_N_m: float = param(1.0, 1e9)
    suspension_damping_N_s_m: float = param(0.0, 1e8)
    suspension_range_m: tuple[float, float] = param(-1.0, 1.0)


@dataclass(frozen=True)
class ReturnRollerParams:
    radius_m: float = param(0.01, 1.0)
    x_m: tuple[float, ...] = param(-10.0, 10.0)
    z_m: float = param(0.0, 5.0)


@dataclass(frozen=True)
class GroundParams:
    stiffness_N_m: float = param(1e3, 1e10, doc="Kelvin-Voigt stiffness per pin contact [N/m]")
    damping_N_s_m: float = param(0.0, 1e8, doc="Kelvin-Voigt damping per pin contact [N·s/m]")
    reference_mass_kg: float = param(0.01, 1e4, doc="effective mass for solref conversion [kg]")
    impedance: float = param(0.5, 0.999, doc="constant MuJoCo impedance d [-]")


@dataclass(frozen=True)
class ContactParams:
    rail_solref: tuple[float, float] = param(0.0, 10.0)
    tooth_solref: tuple[float, float] = param(0.0, 10.0)
    closure_solref: tuple[float, float] = param(0.0, 10.0)


@dataclass(frozen=True)
class PassiveTensionerParams:
    preload_N: float = param(0.0, 1e6, doc="force at the layout stroke [N]")
    stiffness_N_m: float = param(0.0, 1e9)
    damping_N_s_m: float = param(0.0, 1e8)


@dataclass(frozen=True)
class SolverParams:
    iterations: int = param(1, 1000)
    tolerance: float = param(0.0, 1e-2)
    cone: str = "pyramidal"
    jacobian: str = "dense"
    warmstart: bool = False
    midphase: bool = True   # per-body geom bounding-volume tree before the narrow phase


@dataclass(frozen=True)
class ModelParams:
    """All mechanical parameters of one track side (SI units, see lf1352.toml)."""

    simulation: SimulationParams
    track: TrackParams
    chassis: ChassisParams
    sprocket: SprocketParams
    idler: IdlerParams
    road_wheels: RoadWheelParams
    return_rollers: ReturnRollerParams
    ground: GroundParams
    contacts: ContactParams
    tensioner: PassiveTensionerParams
    solver: SolverParams

    @property
    def sprocket_pitch_radius_m(self) -> float:
        """Pitch radius p / (2 sin(pi/N)) on which the pins seat [m]."""
        return self.track.pitch_m / (2.0 * math.sin(math.pi / self.sprocket.tooth_count))


def load_model_params(path: str | Path | None = None) -> ModelParams:
    """Read and validate the model parameter file (default: packaged lf1352.toml)."""
    path = Path(path) if path is not None else default_param_path()
    data = read_toml(path)
    tables = {}
    classes = {f.name: globals()[f.type] if isinstance(f.type, str) else f.type
               for f in dataclasses.fields(ModelParams)}
    for name, cls in classes.items():
        if name not in data:
            raise ParameterError(f"{path.name}: missing table [{name}]")
        tables[name] = load_table(cls, data[name], f"{path.name} [{name}]")
    params = ModelParams(**tables)
    _check_consistency(params, path.name)
    return params


def _check_consistency(p: ModelParams, where: str) -> None:
    if p.track.link_count != 82:
        raise ParameterError(f"{where} [track].link_count = {p.track.link_count}: the LF1352 "
                             "model (names link_00..link_81) needs exactly 82")
    if len(p.road_wheels.x_m) != p.road_wheels.count:
        raise ParameterError(f"{where} [road_wheels].x_m has {len(p.road_wheels.x_m)} entries, "
                             f"count = {p.road_wheels.count}")
    if p.solver.jacobian not in ("dense", "sparse", "auto"):
        raise ParameterError(f"{where} [solver].jacobian = {p.solver.jacobian!r}: allowed "
                             "'dense', 'sparse' or 'auto'")
    if p.solver.cone not in ("pyramidal", "elliptic"):
        raise ParameterError(f"{where} [solver].cone = {p.solver.cone!r}: allowed "
                             "'pyramidal' or 'elliptic'")
    lo, hi = p.idler.slide_range_m
    if not lo < 0.0 < hi:
        raise ParameterError(f"{where} [idler].slide_range_m = {p.idler.slide_range_m}: "
                             "must bracket 0 (low < 0 < high)")
    if 1e-3 / p.simulation.timestep_s % 1.0 > 1e-9:
        raise ParameterError(f"{where} [simulation].timestep_s = {p.simulation.timestep_s}: "
                             "must divide the 1 ms coupling step")


# ----------------------------------------------------------------------------- layout


@dataclass(frozen=True)
class Layout:
    """Initial pin positions (world x, z) [m], shape (82, 2), and wheel centres."""

    pins: np.ndarray
    idler_x_m: float
    sprocket_center: tuple[float, float]
    idler_center: tuple[float, float]
    road_wheel_centers: tuple[tuple[float, float], ...]
    roller_centers: tuple[tuple[float, float], ...]
    sprocket_seat_angle_rad: float


def _vertex_radius(p: ModelParams, wheel_radius: float) -> float:
    """Radius of the circle through the pins of a link wrap whose rail chords touch the
    wheel of ``wheel_radius`` at their midpoints: sqrt((R + r_rail)² + (pitch/2)²)."""
    return math.hypot(wheel_radius + p.track.rail_radius_m, p.track.pitch_m / 2.0)


def _hub_radius(p: ModelParams) -> float:
    """Sprocket hub radius so the pins sit exactly on the pitch circle."""
    rp = p.sprocket_pitch_radius_m
    return rp * math.cos(math.pi / p.sprocket.tooth_count) - p.track.rail_radius_m


def _circles(p: ModelParams, idler_x: float) -> list[tuple[float, float, float]]:
    """Pin-vertex circles (x, z, radius) around which the loop is laid."""
    r_pin = p.track.pin_radius_m
    rw_v = _vertex_radius(p, p.road_wheels.radius_m)
    circles = [(p.sprocket.x_m, p.sprocket.z_m, p.sprocket_pitch_radius_m),
               (idler_x, p.idler.z_m, _vertex_radius(p, p.idler.radius_m))]
    circles += [(x, r_pin + rw_v, rw_v) for x in p.road_wheels.x_m]
    rr_v = _vertex_radius(p, p.return_rollers.radius_m)
    circles += [(x, p.return_rollers.z_m, rr_v) for x in p.return_rollers.x_m]
    return circles


def _hull_path(circles: list[tuple[float, float, float]], samples: int = 2880) -> np.ndarray:
    """Closed convex path around the circles, clockwise in the (x, z) view, starting at the
    bottom. Returns (n, 2) points; the path is sampled finely enough (< 1e-7 m chord error
    at these radii) to walk chords on it."""
    ang = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    pts = np.concatenate([np.column_stack([cx + r * np.cos(ang), cz + r * np.sin(ang)])
                          for cx, cz, r in circles])
    hull = pts[ConvexHull(pts).vertices]  # counter-clockwise
    hull = hull[::-1]  # clockwise: bottom strand runs rearward (-x)
    return hull


def _walk_chords(path: np.ndarray, pitch: float, count: int) -> np.ndarray:
    """Place ``count`` points on the closed polyline ``path`` (n, 2), the first at path[0],
    each at chord distance ``pitch`` from the previous one further along the path."""
    n = len(path)
    current = path[0]
    seg_start, seg = current, 0
    points = [current]
    while len(points) < count:
        seg_end = path[(seg + 1) % n]
        if np.linalg.norm(seg_end - current) < pitch:
            seg_start, seg = seg_end, seg + 1
            if seg > 2 * n:
                raise RuntimeError("chord walk ran round the loop twice: pitch too large")
            continue
        # the far intersection of segment seg_start -> seg_end with the circle |x - current| = pitch
        d = seg_end - seg_start
        f = seg_start - current
        qa, qb, qc = d @ d, 2.0 * (f @ d), f @ f - pitch * pitch
        t = (-qb + math.sqrt(max(qb * qb - 4.0 * qa * qc, 0.0))) / (2.0 * qa)
        current = seg_start + t * d
        seg_start = current
        points.append(current)
    return np.array(points)


def compute_layout(p: ModelParams) -> Layout:
    """Lay the 82 pins on a closed loop around sprocket, rollers, idler and road wheels,
    moving the idler along x so that the last chord closes the loop exactly."""
    count, pitch = p.track.link_count, p.track.pitch_m
    r_pin = p.track.pin_radius_m

    def pins_for(idler_x: float, n_points: int = count) -> np.ndarray:
        path = _hull_path(_circles(p, idler_x))
        # start on the bottom strand at x = pitch/2 (between the middle road wheels)
        start_x = 0.5 * pitch
        bottom = np.argmin(np.abs(path[:, 0] - start_x) + 10.0 * np.abs(path[:, 1] - r_pin))
        path = np.roll(path, -bottom, axis=0)
        if path[1, 0] > path[0, 0]:
            raise RuntimeError("hull orientation unexpected")
        path = np.concatenate([[[start_x, r_pin]], path[1:]])
        return _walk_chords(path, pitch, n_points)

    def closure_gap(idler_x: float) -> float:
        # pin 82 (one chord past the last) must land on pin 0; both lie on the bottom strand,
        # which runs in -x, so the gap along it is x_82 - x_0 (> 0: loop too long)
        pins = pins_for(idler_x, count + 1)
        return float(pins[-1, 0] - pins[0, 0])

    lo, hi = p.idler.x_m - 0.5, p.idler.x_m + 0.5
    try:
        idler_x = brentq(closure_gap, lo, hi, xtol=1e-12)
    except ValueError:
        raise ParameterError("lf1352.toml: no idler position within ±0.5 m of [idler].x_m "
                             "closes the track loop; adjust pitch, link count or geometry") \
            from None
    pins = pins_for(idler_x)
    sx, sz = p.sprocket.x_m, p.sprocket.z_m
    rp = p.sprocket_pitch_radius_m
    on_arc = [k for k in range(count)
              if abs(math.hypot(pins[k, 0] - sx, pins[k, 1] - sz) - rp) < 1e-7]
    if not on_arc:
        raise ParameterError("lf1352.toml: the track does not wrap the sprocket")
    k0 = on_arc[len(on_arc) // 2]
    seat = math.atan2(pins[k0, 1] - sz, pins[k0, 0] - sx)
    circles = _circles(p, idler_x)
    return Layout(
        pins=pins,
        idler_x_m=idler_x,
        sprocket_center=(sx, sz),
        idler_center=(idler_x, p.idler.z_m),
        road_wheel_centers=tuple((c[0], c[1]) for c in circles[2:2 + p.road_wheels.count]),
        roller_centers=tuple((c[0], c[1]) for c in circles[2 + p.road_wheels.count:]),
        sprocket_seat_angle_rad=seat,
    )


# ----------------------------------------------------------------------------- MJCF

_RAIL, _PIN = 8, 16  # contype bits of link rails and pin spheres


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


def _link_inertial(body: ET.Element, p: ModelParams) -> None:
    t = p.track
    m, L, w, h = t.link_mass_kg, t.pitch_m, t.link_width_m, 2.0 * t.pin_radius_m
    _sub(body, "inertial", pos=_fmt(L / 2, 0, 0), mass=_fmt(m),
         diaginertia=_fmt(m * (w * w + h * h) / 12, m * (L * L + h * h) / 12,
                          m * (L * L + w * w) / 12))


def build_mjcf(p: ModelParams, layout: Layout, home_qpos: np.ndarray | None = None) -> str:
    """MJCF text of the track side for ``layout``; ``home_qpos`` adds the ``home`` keyframe."""
    t = p.track
    pitch, n = t.pitch_m, t.link_count
    width = t.link_width_m
    ride = p.chassis.ride_height_m
    root = ET.Element("mujoco", model=MODEL_NAME)
    _sub(root, "compiler", angle="radian", autolimits="true")
    _sub(root, "option", timestep=_fmt(p.simulation.timestep_s),
         gravity=_fmt(0, 0, -p.simulation.gravity_m_s2), integrator="implicitfast",
         solver="Newton", jacobian=p.solver.jacobian, iterations=str(p.solver.iterations),
         tolerance=_fmt(p.solver.tolerance), cone=p.solver.cone)
    flags = {name: "disable" for name, on in (("warmstart", p.solver.warmstart),
                                                ("midphase", p.solver.midphase)) if not on}
    if flags:
        _sub(root.find("option"), "flag", **flags)
    _sub(root, "size", memory="16M")
    visual = _sub(root, "visual")
    _sub(visual, "global", offwidth="1280", offheight="720")

    # default classes (Menagerie habit: collision and visual geoms separate)
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

    # chassis and everything it carries (positions in the chassis frame)
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

    half_w = width / 2.0
    sx, sz = layout.sprocket_center
    spr = _sub(chassis, "body", name="sprocket", pos=_fmt(sx, 0, sz - ride))
    _sub(spr, "joint", name="sprocket_hinge", type="hinge", axis="0 1 0")
    _sub(spr, "inertial", pos="0 0 0", mass=_fmt(p.sprocket.mass_kg),
         diaginertia=_fmt(p.sprocket.inertia_kg_m2, p.sprocket.inertia_kg_m2,
                          p.sprocket.inertia_kg_m2))
    _sub(spr, "geom", name="sprocket_hub", class_="wheel", size=_fmt(_hub_radius(p)),
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
         diaginertia=_fmt(0.5 * p.idler.mass_kg * p.idler.radius_m ** 2,
                          0.5 * p.idler.mass_kg * p.idler.radius_m ** 2,
                          0.5 * p.idler.mass_kg * p.idler.radius_m ** 2))
    _sub(idler, "geom", name="idler_wheel", class_="wheel", size=_fmt(p.idler.radius_m),
         fromto=_fmt(0, -half_w, 0, 0, half_w, 0))
    _sub(idler, "geom", name="idler_visual", class_="visual", type="cylinder",
         size=_fmt(p.idler.radius_m, half_w), euler=_fmt(math.pi / 2, 0, 0))

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
             diaginertia=_fmt(*(0.5 * rw.mass_kg * rw.radius_m ** 2,) * 3))
        _sub(body, "geom", name=f"road_wheel_{k}_collision", class_="wheel",
             size=_fmt(rw.radius_m), fromto=_fmt(0, -half_w, 0, 0, half_w, 0))
        _sub(body, "geom", name=f"road_wheel_{k}_visual", class_="visual", type="cylinder",
             size=_fmt(rw.radius_m, half_w), euler=_fmt(math.pi / 2, 0, 0))
    rr = p.return_rollers
    for k, (rx, rz) in enumerate(layout.roller_centers, start=1):
        body = _sub(chassis, "body", name=f"return_roller_{k}", pos=_fmt(rx, 0, rz - ride))
        _sub(body, "geom", name=f"return_roller_{k}_collision", class_="wheel",
             size=_fmt(rr.radius_m), fromto=_fmt(0, -half_w, 0, 0, half_w, 0))
        _sub(body, "geom", name=f"return_roller_{k}_visual", class_="visual",
             type="cylinder", size=_fmt(rr.radius_m, half_w), euler=_fmt(math.pi / 2, 0, 0))

    # track links: a tree rooted at link_00 with two branches closed at pin 41
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
    closure_a = parent
    _sub(closure_a, "site", name="closure_a", pos=_fmt(pitch, 0, 0), size="0.01")

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

    actuator = _sub(root, "actuator")
    _sub(actuator, "velocity", name="sprocket_drive", joint="sprocket_hinge",
         kv=_fmt(p.sprocket.drive_gain_N_m_s),
         forcerange=_fmt(-p.sprocket.drive_torque_limit_N_m, p.sprocket.drive_torque_limit_N_m))
    _sub(actuator, "general", name="tensioner", joint="idler_slide", gaintype="fixed",
         gainprm="1", biastype="affine", biasprm="0 0 0")

    if home_qpos is not None:
        keyframe = _sub(root, "keyframe")
        _sub(keyframe, "key", name="home", qpos=" ".join(f"{v:.6f}" for v in home_qpos),
             ctrl=_fmt(0.0, p.tensioner.preload_N))

    ET.indent(root, space="  ")
    header = ("<!-- Generated by trackmj.model from lf1352.toml; do not edit by hand.\n"
              "     Regenerate with: trackmj model generate -->\n")
    return header + ET.tostring(root, encoding="unicode") + "\n"


# ----------------------------------------------------------------------------- generation

SETTLE_DURATION_S = 3.0
MAX_INITIAL_PENETRATION_M = 1e-3


def generate_mjcf(params: ModelParams | None = None) -> str:
    """Full MJCF of the model: layout, a check of the initial state, and the ``home``
    keyframe found by settling under gravity with the passive tensioner preload.

    Keyframe values are rounded to 1e-6 so the committed file does not depend on the
    last bits of floating-point arithmetic.
    """
    import mujoco

    from trackmj.plant import PassiveTensioner, TrackPlant

    params = params or load_model_params()
    layout = compute_layout(params)
    bare = build_mjcf(params, layout)
    model = mujoco.MjModel.from_xml_string(bare)
    plant = TrackPlant(model, params)
    worst = min((c.dist for c in plant.data.contact[: plant.data.ncon]), default=0.0)
    if worst < -MAX_INITIAL_PENETRATION_M:
        raise ParameterError(f"initial layout penetrates by {-worst * 1e3:.2f} mm "
                             f"(limit {MAX_INITIAL_PENETRATION_M * 1e3:.1f} mm): check radii "
                             "and positions in lf1352.toml")
    plant.run(PassiveTensioner.from_params(params), SETTLE_DURATION_S)
    if plant.warning_count:
        raise RuntimeError("MuJoCo warnings while settling the home keyframe")
    return build_mjcf(params, layout, home_qpos=np.round(plant.data.qpos, 6))


def write_model(path: str | Path | None = None, params: ModelParams | None = None) -> Path:
    """Generate the model and write it atomically (default: packaged lf1352.xml)."""
    from trackmj.io import write_text_atomic

    path = Path(path) if path is not None else default_xml_path()
    write_text_atomic(path, generate_mjcf(params))
    return path


# ----------------------------------------------------------------------------- terrain

TERRAIN_WIDTH_M = 2.0
TERRAIN_BASE_M = 0.5


def with_heightfield(mjcf: str, x_start_m: float, dx_m: float, heights_m: np.ndarray) -> str:
    """Replace the flat ground of ``mjcf`` by a heightfield road profile.

    heights_m: road elevation [m], shape (n,), at x = x_start_m + i·dx_m (world frame),
    constant across the track (the model is planar). The ground contact keeps the flat
    ground's foundation (default class ``ground``). Elevation 0 is the flat ground level.
    """
    heights = np.asarray(heights_m, dtype=float)
    if heights.ndim != 1 or len(heights) < 4 or not np.all(np.isfinite(heights)):
        raise ParameterError("terrain heights_m must be a finite 1-D array of >= 4 values")
    if not (math.isfinite(dx_m) and dx_m > 0.0):
        raise ParameterError(f"terrain dx_m = {dx_m!r} must be > 0")
    root = ET.fromstring(mjcf.split("-->", 1)[1] if mjcf.lstrip().startswith("<!--") else mjcf)
    low, high = float(heights.min()), float(heights.max())
    span = max(high - low, 1e-6)
    normalised = (heights - low) / span
    length = dx_m * (len(heights) - 1)
    asset = root.find("asset")
    _sub(asset, "hfield", name="terrain", nrow="2", ncol=str(len(heights)),
         size=_fmt(length / 2.0, TERRAIN_WIDTH_M / 2.0, span, TERRAIN_BASE_M),
         elevation=" ".join(f"{v:.6f}" for v in np.tile(normalised, 2)))
    world = root.find("worldbody")
    ground = world.find("geom[@name='ground']")
    for key in ("type", "size"):
        ground.attrib.pop(key, None)
    ground.set("type", "hfield")
    ground.set("hfield", "terrain")
    ground.set("pos", _fmt(x_start_m + length / 2.0, 0.0, low))
    visual = world.find("geom[@name='ground_visual']")
    visual.set("pos", _fmt(0.0, 0.0, low - 0.01))
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"
