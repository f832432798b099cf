"""Mechanical parameters of one track side (``models/lf1352.toml`` for the study's machine)
as frozen dataclasses, with the checks that refuse a layout the generator cannot build.

Units are SI (m, kg, N, s, rad); each field declares its allowed range with
:func:`trackmj.validator.param`, and :func:`load_model_params` refuses unknown keys, wrong types
and out-of-range values naming the file, the table and the key; every table carries a
``source`` (kept in :attr:`ModelParams.sources`).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from itertools import pairwise
from pathlib import Path
from typing import Any, ClassVar, Literal

from trackmj.ports import COUPLING_STEP_S
from trackmj.track.mjcf.layout import (
    CLEARANCE_M,
    check_closure,
    road_wheel_z,
    sprocket_outer_radius,
    tooth_pin_distance_m,
)
from trackmj.validator import (
    Location,
    Parameters,
    load_file,
    origin_field,
    param,
    sources_field,
)

MODEL_NAME = "lf1352"


def models_dir() -> Path:
    """Directory holding the packaged model files."""
    return Path(str(resources.files("trackmj.models")))


def default_param_path() -> Path:
    return models_dir() / f"{MODEL_NAME}.toml"


def default_xml_path() -> Path:
    return models_dir() / f"{MODEL_NAME}.xml"


def mechanics_sha256(params: ModelParams) -> str:
    """SHA-256 (hex) of the validated mechanics' values (their ``repr``: every value in
    declaration order, no ``source`` text): what a generated model and an identified idler
    record of the mechanics they were made from, so that a stale one is refused."""
    return hashlib.sha256(repr(params).encode()).hexdigest()


@dataclass(frozen=True)
class SimulationParams(Parameters):
    timestep_s: float = param(1e-5, 1e-3, doc="MuJoCo timestep [s]; divides the 1 ms step")
    gravity_m_s2: float = param(0.0, 20.0, doc="gravitational acceleration [m/s²]")


@dataclass(frozen=True)
class TrackParams(Parameters):
    link_count: int = param(20, 200, doc="number of links [-]")
    pitch_m: float = param(0.02, 0.3, open_low=True, doc="pin-to-pin distance [m]")
    link_mass_kg: float = param(0.1, 100.0, doc="mass of one link with its shoe [kg]")
    rail_radius_m: float = param(0.002, 0.05, doc="rail capsule radius [m]")
    pin_radius_m: float = param(0.002, 0.05, doc="pin sphere radius [m]")
    link_width_m: float = param(0.05, 1.5, doc="shoe width [m], visual and inertia")
    ground_friction: float = param(0.0, 2.0, unit="1", doc="Coulomb coefficient pin-ground [-]")
    structure: Literal["free", "chains", "slides"] = param(
        default="chains", doc="chains: hinged sub-chains of at most chain_links links joined "
        "by pin connects (trackmj/track/mjcf/structure.py); slides: chains with every hinged "
        "pin on its own compliant slide (every pin stretches T/K; 1.33x the step cost); free: "
        "every link a free planar body, every pin a connect (1.6x the step cost, "
        "benchmarks/README.md); optional: chains (the cheaper; LF1352 and compact3 state "
        "slides: the chains' lumped stretch also bends the hitch's load path to the idler by "
        "8-23 %)")
    chain_links: int = param(2, 12, unit="1", default=4,
                             doc="longest chain of hinged links for structure = chains or slides "
                                 "[-]; optional: 4. Measured on the shipped machines up to "
                                 "12 (gaps, strands, ledger as with 4); longer chains lump "
                                 "more pins in one connect (24: a slack-strand check trips "
                                 "on LF1352 at 2 m/s; one chain of the whole loop: its "
                                 "connect does positive work) and gain little (6: 3 % "
                                 "fewer instructions than 4)")


@dataclass(frozen=True)
class ChassisParams(Parameters):
    mass_kg: float = param(10.0, 1e5)
    pitch_inertia_kg_m2: float = param(1.0, 1e6)
    length_m: float = param(0.1, 20.0)
    height_m: float = param(0.05, 5.0)
    ride_height_m: float = param(0.05, 3.0, doc="chassis origin above ground [m]")
    hitch_x_m: float = param(-10.0, 10.0, doc="rear hitch, chassis frame x [m]")
    hitch_z_m: float = param(0.0, 5.0, doc="rear hitch height above ground at layout [m]")


@dataclass(frozen=True)
class SprocketParams(Parameters):
    tooth_count: int = param(6, 40, doc="pins seated per turn: N pitch chords round "
                             "the pitch circle, pitch radius p/(2·sin(π/N)); a "
                             "sprocket whose teeth engage every other pin (an odd "
                             "21-23 tooth excavator sprocket) seats about half its "
                             "teeth: enter that (11 for 21) and check the pitch "
                             "radius model info prints")
    x_m: float = param(-10.0, 10.0)
    z_m: float = param(0.0, 5.0)
    tooth_radius_m: float = param(0.002, 0.1)
    tooth_radial_offset_m: float = param(-0.05, 0.05)
    mass_kg: float = param(0.1, 1e4)
    inertia_kg_m2: float = param(1e-4, 1e4)
    drive_gain_N_m_s: float = param(1.0, 1e8, doc="velocity servo gain [N·m·s/rad]")
    drive_torque_limit_N_m: float = param(1.0, 1e7, unit="N·m")


@dataclass(frozen=True)
class ParkingBrakeParams(Parameters):
    """The drive's spring-applied parking brake, applied while the sprocket speed command
    is zero (the travel control in neutral releases its pressure): at the sprocket, a
    torsional spring (the drive line between the brake and the sprocket) to an anchor
    angle that slips once the spring carries the holding torque."""

    holding_torque_N_m: float = param(0.0, 1e7, open_low=True, unit="N·m",
                                      doc="torque the brake holds at the sprocket before "
                                          "it slips")
    drive_line_stiffness_N_m_rad: float = param(1e3, 1e9, unit="N·m/rad",
                                                doc="torsional stiffness between the "
                                                    "brake and the sprocket")


@dataclass(frozen=True)
class IdlerParams(Parameters):
    radius_m: float = param(0.02, 1.0)
    x_m: float = param(-10.0, 10.0)
    z_m: float = param(0.0, 5.0)
    mass_kg: float = param(0.1, 1e4)
    carrier_mass_kg: float = param(0.1, 1e4)
    slide_range_m: tuple[float, float] = param(-1.0, 1.0)
    stroke_at_layout_m: float = param(0.0, 1.0, doc="cylinder stroke at slide q = 0 [m]")
    slide_angle_rad: float = param(-math.pi / 4, math.pi / 4, default=0.0,
                                   doc="inclination of the carrier slide above the "
                                       "horizontal, outward (optional: 0 = horizontal) [rad]")


@dataclass(frozen=True)
class RoadWheelParams(Parameters):
    count: int = param(2, 10, unit="1")
    radius_m: float = param(0.02, 1.0)
    x_m: tuple[float, ...] = param(-10.0, 10.0)
    mass_kg: float = param(0.1, 1e4)
    suspension_stiffness_N_m: float = param(1.0, 1e9)
    suspension_damping_N_s_m: float = param(0.0, 1e8)
    suspension_range_m: tuple[float, float] = param(-1.0, 1.0)


@dataclass(frozen=True)
class ReturnRollerParams(Parameters):
    radius_m: float = param(0.01, 1.0)
    x_m: tuple[float, ...] = param(-10.0, 10.0, allow_empty=True,
                                   doc="roller positions, 0-4 of them ([] for none) [m]")
    z_m: float = param(0.0, 5.0)


@dataclass(frozen=True)
class GroundParams(Parameters):
    """The Kelvin–Voigt foundation under every pin (:mod:`trackmj.track.foundation`)."""

    stiffness_N_m: float = param(1e3, 1e10, doc="Kelvin-Voigt stiffness per pin contact [N/m]")
    damping_N_s_m: float = param(0.0, 1e8, doc="Kelvin-Voigt damping per pin contact [N·s/m]")
    damping_onset_m: float = param(
        1e-6, 0.05, doc="penetration at which the damping reaches damping_N_s_m, growing "
                        "from 0 at touchdown (Hunt & Crossley 1975) [m]")
    shear_modulus_m: float = param(
        1e-4, 0.1, doc="shear displacement that mobilises the full friction mu·N "
                       "(Janosi-Hanamoto's K, its initial tangent capped at Coulomb) [m]")


@dataclass(frozen=True)
class ContactParams(Parameters):
    """Kelvin–Voigt normal stiffness and damping of the frictionless contacts: link rails
    on hub, idler, road wheels and rollers; pin spheres on the sprocket teeth."""

    rail_stiffness_N_m: float = param(1e3, 1e10, doc="rail contact stiffness [N/m]")
    rail_damping_N_s_m: float = param(0.0, 1e8, doc="rail contact damping [N·s/m]")
    tooth_stiffness_N_m: float = param(1e3, 1e10, doc="tooth contact stiffness [N/m]")
    tooth_damping_N_s_m: float = param(0.0, 1e8, doc="tooth contact damping [N·s/m]")


@dataclass(frozen=True)
class PinParams(Parameters):
    """Joint between two links at a pin: in-plane (radial) Kelvin–Voigt stiffness and
    damping, and the torsional spring-damper about the pin axis (zero twist when the two
    links are in line). The planar model has no motion along the pin axis."""

    radial_stiffness_N_m: float = param(1e5, 1e10, doc="in-plane pin stiffness [N/m]")
    radial_damping_N_s_m: float = param(0.0, 1e6, doc="in-plane pin damping [N·s/m]")
    torsional_stiffness_N_m_rad: float = param(0.0, 1e5, unit="N·m/rad",
                                               doc="twist stiffness [N·m/rad]")
    torsional_damping_N_m_s_rad: float = param(0.0, 1e4, unit="N·m·s/rad",
                                               doc="twist damping [N·m·s/rad]")


@dataclass(frozen=True)
class BushingParams(PinParams):
    """Rubber-bushed pins: when ``enabled`` they replace the steel pins of ``[pins]``."""

    enabled: bool = param(doc="use the bushings instead of the steel pins")



@dataclass(frozen=True)
class PassiveTensionerParams(Parameters):
    preload_N: float = param(0.0, 1e6, doc="force at the layout stroke [N]")
    stiffness_N_m: float = param(0.0, 1e9)
    damping_N_s_m: float = param(0.0, 1e8)
    nominal_tension_N: float | None = param(
        0.0, 1e6, open_low=True, default=None,
        doc="working tension the tensioning system is designed to hold [N]; optional: "
            "the preload (the controller's band and the relative scenarios scale with it)")


@dataclass(frozen=True)
class SolverParams(Parameters):
    iterations: int = param(1, 1000, unit="1")
    tolerance: float = param(0.0, 1e-2, unit="1")
    soft_margin: float = param(1.0, 100.0, unit="1",
                               doc="apparent mass of a soft constraint over its "
                                   "explicit-integration limit (h²K + 2hB)/4 [-]")
    cone: Literal["pyramidal", "elliptic"] = param()
    jacobian: Literal["dense", "sparse", "auto"] = param()
    warmstart: bool = param()
    midphase: bool = param(doc="per-body geom bounding-volume tree before the narrow phase")
    island: bool = param(default=False,
                         doc="MuJoCo's constraint islands (the whole track side is one "
                             "island: they only add their own bookkeeping); optional: false")


@dataclass(frozen=True)
class ModelParams(Parameters):
    """All mechanical parameters of one track side (SI units, e.g. lf1352.toml)."""

    simulation: SimulationParams
    track: TrackParams
    chassis: ChassisParams
    sprocket: SprocketParams
    idler: IdlerParams
    road_wheels: RoadWheelParams
    return_rollers: ReturnRollerParams
    ground: GroundParams
    contacts: ContactParams
    pins: PinParams
    bushings: BushingParams
    tensioner: PassiveTensionerParams
    solver: SolverParams
    parking_brake: ParkingBrakeParams | None = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=None, doc="the drive's parking brake; optional: none, a zero speed "
                          "command then holds the sprocket through the drive's velocity "
                          "servo only, which yields under a holding torque (creeps)")
    sources: Mapping[str, str] = sources_field()
    origin: Location = origin_field()  # noqa: RUF009 (returns a dataclasses.Field)

    file_kind: ClassVar[str] = "model"

    def cross_check(self, at: Location) -> None:
        _check_consistency(self, at)

    @property
    def pin_joint(self) -> PinParams:
        """The pin joint in force: the bushings when enabled, else the steel pins."""
        return self.bushings if self.bushings.enabled else self.pins

    @property
    def pin_joint_table(self) -> str:
        """Name of the TOML table the pin joint comes from."""
        return "bushings" if self.bushings.enabled else "pins"

    @property
    def nominal_tension_N(self) -> float:
        """The machine's nominal working tension [N]: ``[tensioner].nominal_tension_N``,
        else the passive preload."""
        t = self.tensioner
        return t.preload_N if t.nominal_tension_N is None else t.nominal_tension_N

    @property
    def sprocket_pitch_radius_m(self) -> float:
        """Pitch radius p / (2 sin(pi/N)) on which the pins seat [m]."""
        return self.track.pitch_m / (2.0 * math.sin(math.pi / self.sprocket.tooth_count))


def load_model_params(path: str | Path | None = None,
                      overrides: Mapping[str, Any] | None = None) -> ModelParams:
    """Read and validate the model parameter file (default: packaged lf1352.toml);
    ``overrides``: ``{dotted key: value}`` (the ``model`` entry of
    :func:`trackmj.validator.parse_overrides`)."""
    path = Path(path) if path is not None else default_param_path()
    return load_file(ModelParams, path, overrides=overrides)


MAX_RETURN_ROLLERS = 4


def _check_consistency(p: ModelParams, at: Location) -> None:
    if COUPLING_STEP_S / p.simulation.timestep_s % 1.0 > 1e-9:
        raise at.error(("simulation", "timestep_s"), p.simulation.timestep_s,
                       "must divide the 1 ms coupling step")
    lo, hi = p.idler.slide_range_m
    if not lo < 0.0 < hi:
        raise at.error(("idler", "slide_range_m"), p.idler.slide_range_m,
                       "must bracket 0 (low < 0 < high)")
    # the foundation's spring is explicit (trackmj/track/foundation.py): a link pivoting about one
    # pin puts m/3 at the other (a rod's end), which semi-implicit Euler holds below 4·m/h²
    limit = 4.0 * (p.track.link_mass_kg / 3.0) / p.simulation.timestep_s ** 2
    if p.ground.stiffness_N_m > limit:
        raise at.error(("ground", "stiffness_N_m"), p.ground.stiffness_N_m,
                       f"exceeds {limit:.3g} N/m, the explicit limit 4·m/h² of a pin carrying "
                       f"a third of a link ({p.track.link_mass_kg:g} kg) at timestep "
                       f"{p.simulation.timestep_s:g} s")
    _check_layout(p, at)
    brake, limit = p.parking_brake, p.sprocket.drive_torque_limit_N_m
    if brake is not None and brake.holding_torque_N_m > limit:
        raise at.error(("parking_brake", "holding_torque_N_m"), brake.holding_torque_N_m,
                       f"must be <= [sprocket] drive_torque_limit_N_m = {limit:g} N·m (the "
                       "brake acts through the drive, whose torque limit bounds it)")


def _check_spacing(at: Location, table: str, xs: Sequence[float], gap: float) -> None:
    """Refuse wheel abscissae that do not increase from rear to front by ``gap`` [m]. The
    message names the first offending pair with its values; a list that is merely unsorted
    is told to sort itself, with the sorted list to paste."""
    spacing = f"2·radius_m + {CLEARANCE_M * 1e3:g} mm = {gap:g} m"
    ordered = sorted(xs)
    pairs = [(k, xs[k - 1], xs[k]) for k in range(1, len(xs))]
    backwards = [(k, a, b) for k, a, b in pairs if b <= a]
    if backwards:
        k, a, b = backwards[0]
        spaced = all(y - x >= gap for x, y in pairwise(ordered))
        fix = (f"sort them rear to front, x_m = [{', '.join(f'{x:g}' for x in ordered)}]"
               if spaced else f"list them rear to front, neighbours at least {spacing} apart")
        raise at.error((table, "x_m"), xs, f"entries {k - 1} ({a:g} m) and {k} ({b:g} m) are "
                       f"not in increasing x (rear to front): {fix}")
    for k, a, b in pairs:
        if b - a < gap:
            raise at.error((table, "x_m"), xs, f"entries {k - 1} ({a:g} m) and {k} ({b:g} m) "
                           f"are only {b - a:g} m apart: neighbours must be at least "
                           f"{spacing} apart")


def _check_layout(p: ModelParams, at: Location) -> None:
    """Geometry a track can be laid round: wheels in the span, clear of each other, above
    the ground line; then the loop closure (:func:`trackmj.track.mjcf.layout.check_closure`)."""
    rw, rr, s, i = p.road_wheels, p.return_rollers, p.sprocket, p.idler
    if abs(s.x_m - i.x_m) < s.tooth_radius_m:
        raise at.error(("idler", "x_m"), i.x_m, f"must differ from [sprocket].x_m = "
                       f"{s.x_m:g} m (the sprocket and idler are the two ends of the track)")
    if len(rw.x_m) != rw.count:
        raise at.error(("road_wheels", "x_m"), rw.x_m,
                       f"has {len(rw.x_m)} entries, count = {rw.count}")
    if len(rr.x_m) > MAX_RETURN_ROLLERS:
        raise at.error(("return_rollers", "x_m"), rr.x_m,
                       f"has {len(rr.x_m)} rollers; at most {MAX_RETURN_ROLLERS}")
    r_pin = p.track.pin_radius_m
    rear, front = sorted((s.x_m, i.x_m))
    wz = road_wheel_z(p)
    for table, xs, radius in (("road_wheels", rw.x_m, rw.radius_m),
                              ("return_rollers", rr.x_m, rr.radius_m)):
        for k, x in enumerate(xs):
            if not rear < x < front:
                raise at.error((table, "x_m"), xs, f"entry {k} ({x:g} m) lies outside the span "
                               f"between sprocket and idler ({rear:g} .. {front:g} m)")
        _check_spacing(at, table, xs, 2.0 * radius + CLEARANCE_M)
    if max(rw.x_m) - min(rw.x_m) < 2.0 * p.track.pitch_m:
        raise at.error(("road_wheels", "x_m"), rw.x_m, f"span {max(rw.x_m) - min(rw.x_m):g} m "
                       f"from first to last: at least two links (2·pitch_m = "
                       f"{2.0 * p.track.pitch_m:g} m) must lie flat between them")
    if not min(rw.x_m) < 0.0 < max(rw.x_m):
        raise at.error(("road_wheels", "x_m"), rw.x_m, "must straddle the chassis centre "
                       "of mass at x = 0 (else the machine tips over its end wheel)")
    spr_reach = rw.radius_m + sprocket_outer_radius(p) + CLEARANCE_M
    for k, x in enumerate(rw.x_m):
        if math.hypot(x - s.x_m, wz - s.z_m) < spr_reach:
            raise at.error(("road_wheels", "x_m"), rw.x_m, f"entry {k} ({x:g} m) touches the "
                           f"sprocket teeth: keep its centre {spr_reach:.3f} m from the "
                           "sprocket's")
    # a tooth sits between two pins: seated ones, and those running on and off the sprocket
    reach = tooth_pin_distance_m(s.tooth_count, p.track.pitch_m, s.tooth_radial_offset_m)
    if s.tooth_radius_m + r_pin > reach:
        room = reach - r_pin
        allowed = (f"allowed tooth_radius_m <= {room:.4f} m" if room > 0.0
                   else "no tooth_radius_m fits")
        raise at.error(("sprocket", "tooth_radius_m"), s.tooth_radius_m,
                       f"overlaps a pin running onto or off the sprocket: with "
                       f"tooth_radial_offset_m = {s.tooth_radial_offset_m:g} m, "
                       f"{s.tooth_count} teeth and [track].pitch_m = {p.track.pitch_m:g} m "
                       f"that pin comes {reach:.4f} m from a tooth centre, less than "
                       f"tooth_radius_m + [track].pin_radius_m = "
                       f"{s.tooth_radius_m + r_pin:.4f} m: {allowed} (a smaller "
                       "tooth_radial_offset_m or pin_radius_m leaves more room)")
    floor = r_pin
    if s.z_m - p.sprocket_pitch_radius_m < floor:
        raise at.error(("sprocket", "z_m"), s.z_m, f"puts the sprocket's lowest pin below "
                       f"the ground line: at least {floor + p.sprocket_pitch_radius_m:.4f} m "
                       "(pin radius + pitch radius)")
    if rr.x_m:
        wheel_top = wz + rw.radius_m
        need = wheel_top + rr.radius_m + CLEARANCE_M
        if rr.z_m < need:
            raise at.error(("return_rollers", "z_m"), rr.z_m, f"puts the rollers onto the "
                           f"road wheels (tops at {wheel_top:.3f} m): at least {need:.3f} m")
        for k, x in enumerate(rr.x_m):
            reach = rr.radius_m + sprocket_outer_radius(p) + CLEARANCE_M
            if math.hypot(x - s.x_m, rr.z_m - s.z_m) < reach:
                raise at.error(("return_rollers", "x_m"), rr.x_m, f"entry {k} ({x:g} m) "
                               f"touches the sprocket teeth: keep its centre {reach:.3f} m "
                               "from the sprocket's")
    check_closure(p, at)
