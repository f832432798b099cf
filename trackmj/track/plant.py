"""Plant interface over the MuJoCo track model: named accessors and the 1 ms stepping loop.

Sign conventions (see also :mod:`trackmj.ports`):

* stroke s [m] = ``stroke_at_layout_m`` + position of ``idler_slide``; grows outward
  (tensioning). Stroke velocity v = ds/dt [m/s].
* tensioner force [N] > 0 pushes the idler carrier outward.
* pin tension [N] > 0 pulls the two links of a pin apart along the track (tension);
  pin k joins link_{k-1} and link_k; array index k, shape (link_count,). With ``[track]
  structure = "chains"`` (the default) the pins inside a chain are hinges and the pin
  starting a chain is a compliant ``connect`` carrying the chain's pins in series; with
  ``"slides"`` every hinged pin also has its own compliant slide ``link_kk_stretch`` and
  every connect carries one pin; with ``"free"`` every pin is a connect with the stated
  stiffness (``[pins]``). A pin's tension is the force it transmits, along the bisector of
  the two links.
* ground: the Kelvin–Voigt foundation under every pin (:mod:`trackmj.track.foundation`) replaces
  the MJCF ground's contact; its forces act along the ground normal (N > 0 pushes the pin
  out) and tangent (+x on flat ground).
* chassis pose (x [m] forward, z [m] up, pitch [rad] about +y, nose-down positive).
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numba
import numpy as np
from scipy.spatial import ConvexHull

from trackmj.ports import COUPLING_STEP_S, ForceLaw, StepInputs, TensionerElement
from trackmj.track.foundation import REDO_STATE, Foundation, FoundationLaw, ImplicitSprings
from trackmj.track.foundation import step as foundation_step
from trackmj.track.mechanics import ModelParams
from trackmj.track.mjcf.layout import MIN_SEATED_PINS, sprocket_outer_radius
from trackmj.track.mjcf.names import link_name, pin_name
from trackmj.track.mjcf.structure import equalise_link_weights, pin_slide_ids, torsion_hinge_ids
from trackmj.track.servo import DriveRetake


@numba.njit(cache=True)
def _largest_pin_gap_m(efc_pos: np.ndarray, pins_per_connect: np.ndarray, qpos: np.ndarray,
                       stretch_qpos: np.ndarray) -> float:
    """Largest deflection of one pin [m]: each pin connect's gap (the Euclidean norm of its
    3 rows, efc_pos[3c:3c+3], summed x² + y² + z² in that order) over the pins whose
    compliance it carries in series (``pins_per_connect``, one per connect), and each pin
    slide's stretch |qpos[i]| (``stretch_qpos``, structure "slides"; empty otherwise)."""
    largest = 0.0
    for c in range(len(pins_per_connect)):
        a, b, d = efc_pos[3 * c], efc_pos[3 * c + 1], efc_pos[3 * c + 2]
        gap = math.sqrt(a * a + b * b + d * d) / pins_per_connect[c]
        if gap > largest:
            largest = gap
    for i in range(len(stretch_qpos)):
        stretch = abs(float(qpos[stretch_qpos[i]]))
        if stretch > largest:
            largest = stretch
    return largest


@numba.njit(cache=True)
def _pin_tensions(efc_force: np.ndarray, cfrc_int: np.ndarray, xmat: np.ndarray,
                  link_body: np.ndarray, connect_of_pin: np.ndarray,
                  out: np.ndarray) -> None:
    """Tension of every pin [N] into ``out`` (see :meth:`TrackPlant.pin_tensions_N`): the
    force a pin transmits, from its connect's rows (``connect_of_pin`` >= 0) or, for a
    hinged pin (−1), the translational part of its child link's ``cfrc_int`` reversed,
    projected on the bisector of the two links' x axes (xmat columns 0, 3, 6)."""
    n = len(link_body)
    for k in range(n):
        c = connect_of_pin[k]
        if c >= 0:
            fx, fy, fz = efc_force[3 * c], efc_force[3 * c + 1], efc_force[3 * c + 2]
        else:
            body = link_body[k]
            fx, fy, fz = -cfrc_int[body, 3], -cfrc_int[body, 4], -cfrc_int[body, 5]
        a, b = link_body[k], link_body[k - 1]   # links k and k−1 (k−1 = n−1 for k = 0)
        bx = xmat[a, 0] + xmat[b, 0]
        by = xmat[a, 3] + xmat[b, 3]
        bz = xmat[a, 6] + xmat[b, 6]
        norm = math.sqrt(bx * bx + by * by + bz * bz)
        out[k] = (fx * bx + fy * by + fz * bz) / norm


STRAND_MARGIN_REL = 0.3
"""The strands' margin off the wheel centres' line, as a share of the smaller of the
sprocket's pitch radius and the idler's radius [-] (LF1352: 51 mm; M113: 75 mm): a pin a
strand carries straight between the wheels' tops lies a radius off it, one on a wheel's
side below the margin is still wrapped. Assumed; by geometric similarity it keeps the 5 cm
that LF1352's strands were classified with."""


def strand_bounds(params: ModelParams) -> np.ndarray:
    """What :func:`_strands` classifies the pins by, shape (6,): (ride height, the upper
    level at chassis x = 0, its slope dz/dx; the sprocket's lower run: x from, x to, its
    level) [m, -]. The upper strand lies above the line through the sprocket's and the
    idler's centres raised by the margin (:data:`STRAND_MARGIN_REL`), so it follows a
    sprocket set high above the idler (a high-drive layout) instead of counting only the
    pins above the higher centre; the lower run lies between the sprocket and its nearest
    road wheel, the margin below the sprocket's centre. Heights in the chassis frame
    (above the ride height)."""
    ride, spr, idler = params.chassis.ride_height_m, params.sprocket, params.idler
    margin = STRAND_MARGIN_REL * min(params.sprocket_pitch_radius_m, idler.radius_m)
    slope = (idler.z_m - spr.z_m) / (idler.x_m - spr.x_m)
    wheels = params.road_wheels.x_m
    lo, hi = (spr.x_m, min(wheels)) if spr.x_m < idler.x_m else (max(wheels), spr.x_m)
    return np.array([ride, spr.z_m - ride - slope * spr.x_m + margin, slope, lo, hi,
                     spr.z_m - ride - margin])


@numba.njit(cache=True)
def _strands(geom_xpos: np.ndarray, pin_geom: np.ndarray, qpos: np.ndarray,
             chassis_q: np.ndarray, bounds: np.ndarray, tension: np.ndarray,
             upper: np.ndarray, lower: np.ndarray) -> tuple[float, float]:
    """Upper-strand and lower-run masks of the pins (written into ``upper``, ``lower``) and
    the mean ``tension`` over each [N] (NaN for an empty strand). Pins are taken in the
    chassis frame: world (x, z) less the chassis origin (x, ride + z), turned back by its
    pitch; ``bounds``: :func:`strand_bounds`."""
    x0, z0 = qpos[chassis_q[0]], bounds[0] + qpos[chassis_q[1]]
    c, s = math.cos(qpos[chassis_q[2]]), math.sin(qpos[chassis_q[2]])
    sum_u = sum_l = 0.0
    n_u = n_l = 0
    for k in range(len(pin_geom)):
        rx, rz = geom_xpos[pin_geom[k], 0] - x0, geom_xpos[pin_geom[k], 2] - z0
        px, pz = c * rx - s * rz, s * rx + c * rz   # undo the rotation about +y by pitch
        upper[k] = pz > bounds[1] + bounds[2] * px
        lower[k] = bounds[3] < px < bounds[4] and pz < bounds[5]
        if upper[k]:
            sum_u += tension[k]
            n_u += 1
        if lower[k]:
            sum_l += tension[k]
            n_l += 1
    return (sum_u / n_u if n_u else math.nan), (sum_l / n_l if n_l else math.nan)


@numba.njit(cache=True)
def _least_upper_tension(efc_force: np.ndarray, cfrc_int: np.ndarray, xmat: np.ndarray,
                         link_body: np.ndarray, connect_of_pin: np.ndarray,
                         geom_xpos: np.ndarray, pin_geom: np.ndarray, qpos: np.ndarray,
                         chassis_q: np.ndarray, bounds: np.ndarray, tension: np.ndarray,
                         upper: np.ndarray, lower: np.ndarray) -> float:
    """The least pin tension of the upper strand [N] (0 with no pin there), the pin
    tensions and strand masks left in ``tension``, ``upper``, ``lower``
    (:func:`_pin_tensions`, :func:`_strands`): one call per slack-window sample."""
    _pin_tensions(efc_force, cfrc_int, xmat, link_body, connect_of_pin, tension)
    _strands(geom_xpos, pin_geom, qpos, chassis_q, bounds, tension, upper, lower)
    least = math.inf
    for k in range(len(tension)):
        if upper[k] and tension[k] < least:
            least = tension[k]
    return 0.0 if least == math.inf else least


@dataclass
class PassiveTensioner:
    """Preload spring-damper acting on the idler carrier (like Chrono's M113 idler).

    F = preload_N - stiffness_N_m·(s - stroke_ref_m) - damping_N_s_m·v_{k+1}
    The spring term is evaluated at the start of the step, the damping implicitly.
    """

    preload_N: float
    stiffness_N_m: float
    damping_N_s_m: float
    stroke_ref_m: float

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(self.preload_N - self.stiffness_N_m * (stroke_m - self.stroke_ref_m),
                        -self.damping_N_s_m)

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Nothing to finish: the element has no state."""

    def standing_force_N(self, stroke_m: float) -> float:
        """Force [N] on the idler standing still at ``stroke_m`` [m]: the preload less the
        spring's loss from ``stroke_ref_m`` (at the home keyframe's stroke, the settled
        idler force; the preload holds only at ``stroke_ref_m``)."""
        return self.preload_N - self.stiffness_N_m * (stroke_m - self.stroke_ref_m)

    @classmethod
    def from_params(cls, params: ModelParams) -> PassiveTensioner:
        t = params.tensioner
        return cls(t.preload_N, t.stiffness_N_m, t.damping_N_s_m,
                   params.idler.stroke_at_layout_m)


END_STOP_TOLERANCE_M = 0.5e-3
"""The idler carrier rests on an end stop within this of it, or past it (into the stop's
soft limit) [m]."""

STRANDS = ("upper", "lower run", "other")
"""Where a pin is (:meth:`TrackPlant.pin_strand`): the upper strand, the sprocket's lower
run (between the sprocket and its nearest road wheel), or elsewhere (the wraps round the
sprocket and idler, the run under the road wheels)."""


@dataclass(frozen=True)
class DerailmentLimits:
    """The thresholds of :meth:`TrackPlant.derailment` for one machine, sized by its track
    and sprocket (:meth:`for_params`), so a track twice the size is judged alike.

    ``envelope_threshold_m`` [m]: a pin further than this outside its home envelope is off
    it. ``seat_tolerance_m`` [m]: a pin within this of the sprocket pitch circle is seated;
    fewer than ``min_seated_pins`` seated pins is a disengaged sprocket."""

    envelope_threshold_m: float
    seat_tolerance_m: float
    min_seated_pins: int = MIN_SEATED_PINS

    ENVELOPE_PITCHES = 4.0 / 3.0
    """The envelope threshold in link pitches: assumed, set on LF1352 (100 mm at its 75 mm
    pitch, 10x the 9-10 mm its passive drives reach at 1.5 and 3 m/s) and scaled with the
    pitch, as every displacement of a geometrically similar track scales. A fixed 100 mm
    judged M113's 154 mm-pitch rubber-bushed strand derailed when its slack lower run
    sagged 102 mm on a 2 m/s start: 50 mm at LF1352's pitch."""
    SEAT_LIFT_FRACTION = 0.3
    """The seat tolerance as a fraction of the tooth lift (:meth:`tooth_lift_m`: how far out
    a pin riding on a tooth's tip sits): assumed, set on LF1352 (12 mm of its 39 mm lift),
    scaled with the tooth; a pin that has climbed under a third of the way up its tooth
    is still in its pocket."""

    @staticmethod
    def tooth_lift_m(params: ModelParams) -> float:
        """How far outside the pitch circle [m] a pin riding on a tooth's tip sits: the
        tooth's offset plus its radius plus the pin's, o + r_tooth + r_pin (LF1352 0.039 m,
        M113 0.0813 m, compact3 0.047 m)."""
        return (sprocket_outer_radius(params) + params.track.pin_radius_m
                - params.sprocket_pitch_radius_m)

    @classmethod
    def for_params(cls, params: ModelParams) -> DerailmentLimits:
        """The limits of the machine ``params`` describes (LF1352: 0.100 m, 0.0117 m)."""
        return cls(envelope_threshold_m=cls.ENVELOPE_PITCHES * params.track.pitch_m,
                   seat_tolerance_m=cls.SEAT_LIFT_FRACTION * cls.tooth_lift_m(params))


@dataclass(frozen=True)
class DerailmentStatus:
    """Indicators that the track is losing its guidance (all False when healthy), with where
    each is worst. Pin indices k as in :meth:`TrackPlant.pin_tensions_N`; strands as in
    :data:`STRANDS`; positions in the chassis frame at its layout pose
    (:meth:`TrackPlant.pins_layout_frame`: x forward, z up from the ground line) [m]."""

    sprocket_disengaged: bool   # fewer than 2 pins seated on the sprocket pitch circle
    links_off_envelope: bool    # a pin is further than the threshold outside its home envelope
    slack_strand: bool          # held_upper_strand_tension_N below the slack tension
    max_envelope_excursion_m: float
    min_upper_strand_tension_N: float   # now; 0 when no pin is in the upper strand
    # the highest the upper strand's least pin tension rose over the last slack window's
    # samples (TrackPlant.SLACK_PERSISTENCE_S, one every SLACK_SAMPLE_S); inf before a full
    # window of them
    held_upper_strand_tension_N: float
    seated_pins: int            # pins seated on the sprocket pitch circle
    worst_envelope_pin: int     # the pin furthest outside the home envelope
    worst_envelope_strand: str  # its strand (:data:`STRANDS`)
    worst_envelope_xz_m: tuple[float, float]   # its position (x, z) [m], layout frame
    min_upper_strand_pin: int   # the upper-strand pin of least tension (−1: none there)

    @property
    def any(self) -> bool:
        return self.sprocket_disengaged or self.links_off_envelope or self.slack_strand


@dataclass(frozen=True)
class PlantSnapshot:
    """Everything :meth:`TrackPlant.step` carries from one step to the next besides the
    model (:meth:`TrackPlant.snapshot`): a copy of the MjData, the actuators' bias
    parameters (the tensioner's force-law slope), the ground's memory (shear displacements,
    contact history), the clock [s], the last force law, the speed command in effect
    [m/s], whether a hitch load is applied, the parking brake (applied; asked for at a
    zero command but not yet applied; anchor [rad]), and the slack-strand window (the step
    count, its samples [N], where the next goes, the slack samples in a row)."""

    data: mujoco.MjData
    actuator_biasprm: np.ndarray
    ground_memory: np.ndarray
    time_s: float
    last_law: ForceLaw | None
    speed_command_m_s: float
    hitch_loaded: bool
    parked: bool
    park_pending: bool
    brake_anchor_rad: float
    step_count: int
    slack_window_N: np.ndarray
    slack_at: int
    slack_samples: int


@dataclass(frozen=True)
class StrandTension:
    """Mean pin tension [N] of the upper strand and of the sprocket's lower run (between
    the sprocket and its nearest road wheel). Driving forward with the sprocket at the rear
    the lower run is the tight side (it carries the traction) and the upper strand the
    slack side set by the tensioner; with the sprocket at the front the upper strand is
    the tight side."""

    upper_N: float
    lower_N: float


class TrackPlant:
    """One track side in MuJoCo with named accessors (any machine's generated model).

    State layout: ``data.qpos`` holds chassis (x, z, pitch), sprocket angle, idler slide,
    the suspension slides, then (x, z, pitch) of each free link link_00.. (chains: of
    each chain's first link, followed by the pin hinges of the links it carries); use the
    accessors rather than raw indices. The coupling step is 1 ms; the MuJoCo timestep
    must divide it (``substeps`` MuJoCo steps per coupling step). Sign conventions: see the
    module docstring (stroke outward positive, tensioner force > 0 pushes the idler out).

    Ports: ``apply(StepInputs)`` (track speed command, rear-hitch load) and
    ``step(element)`` (one coupling step through the tensioner port); readouts as
    properties (``stroke_m``, ``stroke_velocity_m_s``, ``idler_force_N``,
    ``chassis_acc_z_m_s2``, ``closure_error_m``, ``warning_count``).

    ``parked``: the machine's parking brake ([parking_brake] of its mechanics file) is
    applied: a zero speed command applies it once the sprocket's pitch speed is below
    ``BRAKE_APPLY_SPEED_M_S``; any other command releases it.

    Parameters
    ----------
    model : mujoco.MjModel
        The compiled track model (``models/lf1352.xml`` or a generated variant).
    params : ModelParams
        The parameters the model was generated from (geometry, contacts, pins).
    """

    BRAKE_APPLY_SPEED_M_S = 0.05
    """Pitch speed [m/s] below which a zero speed command applies the parking brake: the
    machine has stopped (a brake applied at speed would lock a moving machine). Above the
    velocity servo's creep under a parked machine's holding torque (LF1352 on tan θ = 0.5:
    6.7 mm/s), so a machine the servo holds still gets its brake."""
    SLACK_TENSION_N = 1000.0
    """Below this the upper strand hangs on its own weight (rigid links never reach zero:
    one metre of track weighs ~460 N and a hanging span keeps a few hundred newtons)."""
    SLACK_PERSISTENCE_S = 0.1
    """The slack window [s]: the strand is slack when its least pin tension was below
    ``SLACK_TENSION_N`` at every sample (``SLACK_SAMPLE_S``) over this long. A strand
    hanging on its weight lasts; a tooth's chordal action or engagement compresses one pin
    for a few milliseconds (measured on M113 at its preload, 154 mm pitch, driven at 1.5-3
    m/s, ±0.2 grade, in reverse: at most 27 ms below 1 kN, the strand's mean above 1.9 kN;
    models/README.md, "The slack-strand window"). 0.1 s is 3.7 x that, one tooth-passing
    period of M113 (the coarsest pitch shipped) at 1.54 m/s, the time a released pin needs
    to fall 49 mm (g t^2 / 2, the order of a strand's home sag), and the drive's check
    interval, so the checks' windows tile the run."""
    SLACK_SAMPLE_S = 0.01
    """How often the slack window samples the upper strand's least pin tension [s]: after
    every 10th coupling step of the plant's step count (:attr:`step_count`), so the window
    holds 10 samples. Read after every step it cost ~4.5 % of the plant step
    (``mj_rnePostConstraint`` and a pass over the pins) for a check made every 0.1 s. A
    strand that hangs is below ``SLACK_TENSION_N`` at every sample, so no 0.1 s spell
    escapes; the samples must not call a tensioned strand slack by seeing only its spikes.
    The measured compression spikes last <= 27 ms and recur at tooth passing, v / pitch:
    < 20 Hz on M113 up to 3 m/s (>= 51 ms apart, >= 24 ms above 1 kN between them); on
    LF1352 and compact3 at 3 m/s 40 and 33 Hz, their spikes <= 4 ms (>= 21 ms between).
    Each gap is longer than a sample interval and holds a sample, so 10 ms samples neither
    alias the tooth passing into a slack strand nor let a 0.1 s spell escape (LF1352 at a
    1 kN preload, 3 m/s, leaves ~8 ms gaps: its window's lowest peak fell from 2.24 to
    1.75 kN, not slack; models/README.md, "The slack-strand window")."""

    def __init__(self, model: mujoco.MjModel, params: ModelParams) -> None:
        self.model = model
        self.params = params
        self.model_path: Path | None = None
        self.data = mujoco.MjData(model)
        ratio = COUPLING_STEP_S / model.opt.timestep
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"MuJoCo timestep {model.opt.timestep} s must divide the "
                             f"{COUPLING_STEP_S} s coupling step")
        self.substeps = round(ratio)
        m = model
        # views into the MjData/MjModel buffers, kept to spare the bindings' attribute
        # look-ups in the 1 kHz loop (the buffers live as long as data and model)
        self._qpos, self._qvel, self._ctrl = self.data.qpos, self.data.qvel, self.data.ctrl
        self._biasprm = m.actuator_biasprm
        self._stroke_offset_m = params.idler.stroke_at_layout_m
        self._slide_q = int(m.jnt_qposadr[m.joint("idler_slide").id])
        self._slide_v = int(m.jnt_dofadr[m.joint("idler_slide").id])
        self._sprocket_v = int(m.jnt_dofadr[m.joint("sprocket_hinge").id])
        self._chassis_q = np.array([m.jnt_qposadr[m.joint(n).id]
                                    for n in ("chassis_x", "chassis_z", "chassis_pitch")])
        self._chassis_v = np.array([m.jnt_dofadr[m.joint(n).id]
                                    for n in ("chassis_x", "chassis_z", "chassis_pitch")])
        self._tensioner = m.actuator("tensioner").id
        self._drive = m.actuator("sprocket_drive").id
        self._drive_gain = float(m.actuator_gainprm[self._drive, 0])   # kv [N·m·s/rad], gear 1
        self._drive_limit = (float(m.actuator_forcerange[self._drive, 1])
                             if m.actuator_forcelimited[self._drive] else math.inf)
        # the servo's command [rad/s] this far from the sprocket's speed (a billionth
        # inside) starts a step at the torque limit (step(), DriveRetake)
        self._drive_band = self._drive_limit / self._drive_gain * (1.0 - 1e-9)
        self._drive_retake = DriveRetake(m, self.data, self._drive, self._sprocket_v,
                                         self._drive_gain, self._drive_limit)
        # the parking brake at a zero speed command: the servo's command becomes
        # (k_b/kv)·(anchor − θ), so it applies k_b·(anchor − θ) − kv·ω; the anchor slips
        # to keep k_b·|anchor − θ| within the holding torque (none: ratio 0)
        self._sprocket_q = int(m.jnt_qposadr[m.joint("sprocket_hinge").id])
        brake = params.parking_brake
        self._brake_ratio = (0.0 if brake is None
                             else brake.drive_line_stiffness_N_m_rad / self._drive_gain)
        self._brake_slip_rad = (0.0 if brake is None else
                                brake.holding_torque_N_m / brake.drive_line_stiffness_N_m_rad)
        self._brake_apply_rad_s = self.BRAKE_APPLY_SPEED_M_S / params.sprocket_pitch_radius_m
        n = params.track.link_count
        self.link_count = n
        self._link_body = np.array([m.body(link_name(k)).id for k in range(n)])
        self._pin_geom = np.array([m.geom(link_name(k) + "_pin").id for k in range(n)])
        # the pin connects are the model's only equalities, in pin order: 3 rows each; the
        # other pins are hinges (structure "chains": link k hinged to link k-1 at pin k)
        hinged = [k for k in range(n) if m.body(link_name(k)).parentid != 0]
        connected = [k for k in range(n) if k not in hinged]
        pin_eq = [m.equality(pin_name(k)).id for k in connected]
        if m.neq != len(connected) or pin_eq != list(range(m.neq)) or any(
                m.body(link_name(k)).parentid != self._link_body[k - 1] for k in hinged):
            raise ValueError(f"{m.neq} equalities: expected one pin connect per pin that "
                             "is not a hinge, in pin order, only (regenerate the model)")
        self._pin_rows = 3 * m.neq
        self._connect_of_pin = np.full(n, -1, dtype=np.int64)
        self._connect_of_pin[connected] = np.arange(len(connected))
        self._tension = np.zeros(n)
        self._has_hinged_pins = bool(hinged)
        # structure "slides": the hinged pins with their own compliant slide
        slide = pin_slide_ids(m, hinged)
        # their joint ids (empty for chains and free links; the energy ledger books them)
        self.pin_slide_joints = np.array([j for j in slide.values() if j >= 0], dtype=np.int64)
        self._stretch_qpos = m.jnt_qposadr[self.pin_slide_joints].astype(np.int64)
        # pins each connect carries in series: its own and the hinged pins without a slide
        # up to the next connect
        bounds = [*connected, n]
        self._pins_per_connect = np.array(
            [1 + sum(slide[k] < 0 for k in range(a + 1, b))
             for a, b in itertools.pairwise(bounds)], dtype=float)
        equalise_link_weights(m)   # chains: every link link_00's row weight
        self.foundation = Foundation(m, self.data, self._pin_geom,
                                     FoundationLaw.from_params(params))
        # the pin slides' springs and the pin hinges' torsional dampers by backward Euler
        # (no armature); none without slides or torsional damping
        self.springs = ImplicitSprings(m, self.data, self.pin_slide_joints,
                                       torsion_hinge_ids(m, hinged))
        self._saved_state = np.zeros(mujoco.mj_stateSize(m, REDO_STATE))
        # the step's start velocity (the foundation keeps it) and the chassis' z dof, for
        # the per-step acceleration readout
        self._start_qvel, self._timestep = self.foundation.start_velocity, m.opt.timestep
        self._chassis_vz = int(self._chassis_v[1])
        self._chassis_body = m.body("chassis").id
        # strands in the chassis frame (:func:`strand_bounds`)
        self._strand_bounds = strand_bounds(params)
        self._upper, self._lower = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        # the least upper-strand pin tension sampled every _slack_sample_steps coupling
        # steps over the last SLACK_PERSISTENCE_S (a ring, oldest at _slack_at) and how
        # many samples in a row it was slack
        self._slack_sample_steps = round(self.SLACK_SAMPLE_S / COUPLING_STEP_S)
        self._slack_window = np.full(round(self.SLACK_PERSISTENCE_S / self.SLACK_SAMPLE_S),
                                     math.inf)
        self._slack_at = 0
        self._slack_samples = 0
        # coupling steps since the clock started (reset, clear_slack_window): the slack
        # window samples at its multiples of _slack_sample_steps
        self.step_count = 0
        self._hitch_site = m.site("rear_hitch").id
        self._sprocket_body = m.body("sprocket").id
        self._carrier_body = m.body("idler_carrier").id
        self._group_of_body = self._contact_groups()
        self.time_s = 0.0
        self.last_law: ForceLaw | None = None
        self.reset("home" if model.nkey else None)
        self._envelope = self._home_envelope()
        self.limits = DerailmentLimits.for_params(params)
        _ = self.closure_error_m   # load (or compile) the kernel here, not in the first step

    # ------------------------------------------------------------------ construction
    def reset(self, keyframe: str | None = "home") -> None:
        """Reset to a keyframe (default the pretensioned ``home``) or to the layout."""
        mujoco.mj_resetData(self.model, self.data)
        if keyframe is not None:
            mujoco.mj_resetDataKeyframe(self.model, self.data, self.model.key(keyframe).id)
        self.data.ctrl[self._drive] = 0.0
        self.time_s = 0.0
        self.last_law = None
        self.clear_slack_window()
        self._speed_command = 0.0
        self._hitch_loaded = False
        self.parked = self._brake_ratio > 0.0   # standing at the keyframe, braked
        self._park_pending = False
        self._brake_anchor = float(self.data.qpos[self._sprocket_q])
        mujoco.mj_forward(self.model, self.data)
        # the ground acting at this state as in a step (the foundation's wrenches), then
        # everything derived again with it
        self.foundation.forget()
        self.foundation.apply()
        self.foundation.finish(final=True, advance=False)
        mujoco.mj_forward(self.model, self.data)

    def snapshot(self) -> PlantSnapshot:
        """The plant's state now, for :meth:`restore` (a copy: later steps leave it)."""
        return PlantSnapshot(copy.copy(self.data), self.model.actuator_biasprm.copy(),
                             self.foundation.memory.copy(), self.time_s, self.last_law,
                             self._speed_command, self._hitch_loaded, self.parked,
                             self._park_pending, self._brake_anchor, self.step_count,
                             self._slack_window.copy(), self._slack_at, self._slack_samples)

    def restore(self, snapshot: PlantSnapshot) -> None:
        """Put the plant back into ``snapshot``'s state (taken of this plant or of one built
        from the same model), bit for bit."""
        mujoco.mj_copyData(self.data, self.model, snapshot.data)
        self.model.actuator_biasprm[:] = snapshot.actuator_biasprm
        self.foundation.memory[:] = snapshot.ground_memory
        self.time_s, self.last_law = snapshot.time_s, snapshot.last_law
        self._speed_command, self._hitch_loaded = (snapshot.speed_command_m_s,
                                                   snapshot.hitch_loaded)
        self.parked, self._park_pending = snapshot.parked, snapshot.park_pending
        self._brake_anchor = snapshot.brake_anchor_rad
        self.step_count = snapshot.step_count
        self._slack_window[:] = snapshot.slack_window_N
        self._slack_at, self._slack_samples = snapshot.slack_at, snapshot.slack_samples

    def clear_slack_window(self) -> None:
        """Forget the upper strand's tension history and start the step count again at 0:
        the slack window starts again (no ``slack_strand`` before ``SLACK_PERSISTENCE_S``
        of samples) and samples at the same steps whether the track was settled afresh or
        restored; a run whose clock starts at 0 starts it with it."""
        self._slack_window[:] = math.inf
        self._slack_at = 0
        self._slack_samples = 0
        self.step_count = 0

    def _contact_groups(self) -> dict[int, str]:
        groups = {self._sprocket_body: "sprocket", 0: "ground"}
        for i in range(self.model.nbody):
            name = self.model.body(i).name
            if name.startswith("road_wheel_"):
                groups[i] = "road_wheels"
            elif name in ("idler", "idler_carrier"):
                groups[i] = "idler"
            elif name.startswith("return_roller_"):
                groups[i] = "return_rollers"
        return groups

    # ------------------------------------------------------------------ accessors
    @property
    def stroke_m(self) -> float:
        """Cylinder stroke [m] (outward positive)."""
        return self._stroke_offset_m + float(self._qpos[self._slide_q])

    @property
    def stroke_stops_m(self) -> tuple[float, float]:
        """Strokes of the carrier's end stops, the range of ``idler_slide`` [m]: (retracted,
        extended); (-inf, inf) for a slide without limits."""
        joint = self.model.joint("idler_slide")
        if not joint.limited[0]:
            return -math.inf, math.inf
        low, high = joint.range
        return self._stroke_offset_m + float(low), self._stroke_offset_m + float(high)

    def end_stop(self) -> str | None:
        """The end stop the carrier rests on, "retracted" or "extended" (within
        :data:`END_STOP_TOLERANCE_M` of it or past it), or None between them."""
        retracted, extended = self.stroke_stops_m
        if self.stroke_m <= retracted + END_STOP_TOLERANCE_M:
            return "retracted"
        if self.stroke_m >= extended - END_STOP_TOLERANCE_M:
            return "extended"
        return None

    @property
    def stroke_velocity_m_s(self) -> float:
        """Cylinder stroke velocity [m/s]."""
        return float(self._qvel[self._slide_v])

    @property
    def idler_force_N(self) -> float:
        """Tensioner force applied to the idler carrier over the last step [N]: the force
        law at the end-of-step velocity (what ``implicitfast`` integrates), not MuJoCo's
        ``actuator_force``, which is evaluated at the start-of-step velocity."""
        if self.last_law is None:
            return float(self.data.actuator_force[self._tensioner])
        return self.last_law.at(self.stroke_velocity_m_s)

    @property
    def sprocket_speed_rad_s(self) -> float:
        return float(self.data.qvel[self._sprocket_v])

    @property
    def sprocket_angle_rad(self) -> float:
        """Sprocket angle [rad], the sense that drives the vehicle forward positive."""
        return float(self._qpos[self._sprocket_q])

    @property
    def drive_torque_N_m(self) -> float:
        """Torque of the sprocket drive on the sprocket over the last step [N·m], > 0 driving
        the vehicle forward: the velocity servo's kv·(ω_cmd − ω) at the end-of-step speed
        (what ``implicitfast`` integrates), within the drive's torque limit (a step that
        starts at the limit and would end inside it applies backward Euler's torque:
        :class:`~trackmj.track.servo.DriveRetake`). What a drive measures (motor pressure ×
        displacement × gear ratio, or a torque shaft)."""
        torque = self._drive_gain * (self._ctrl[self._drive] - self._qvel[self._sprocket_v])
        limit = self._drive_limit
        return float(min(max(torque, -limit), limit))

    @property
    def track_speed_m_s(self) -> float:
        """Sprocket pitch-line speed [m/s] (positive drives the vehicle forward)."""
        return self.sprocket_speed_rad_s * self.params.sprocket_pitch_radius_m

    @property
    def speed_command_m_s(self) -> float:
        """The sprocket pitch-line speed commanded [m/s] (:meth:`set_track_speed`)."""
        return self._speed_command

    def set_track_speed(self, speed_m_s: float, *, park: bool = True) -> None:
        """Command the sprocket velocity servo to a pitch-line speed [m/s]. Zero asks for the
        machine's parking brake where it has one: the servo brings the sprocket to rest and
        the brake applies (:attr:`parked`), anchored at the sprocket's angle then, at the
        first step that starts below ``BRAKE_APPLY_SPEED_M_S``; with ``park`` False the
        servo holds zero speed as it holds any speed when driving. Any other speed releases
        the brake."""
        if not math.isfinite(speed_m_s):
            raise ValueError(f"track speed must be finite, got {speed_m_s!r}")
        self._speed_command = speed_m_s
        if speed_m_s == 0.0 and park and self._brake_ratio > 0.0:
            if not self.parked:
                self._park_pending = True
                self._ctrl[self._drive] = 0.0
            return
        self.parked = self._park_pending = False
        self._ctrl[self._drive] = speed_m_s / self.params.sprocket_pitch_radius_m

    @property
    def park_pending(self) -> bool:
        """A zero speed command asked for the parking brake, which applies once the sprocket
        is below ``BRAKE_APPLY_SPEED_M_S``."""
        return self._park_pending

    @property
    def parking_brake_anchor_rad(self) -> float:
        """Sprocket angle [rad] the applied parking brake holds to (where it was applied,
        moved by its slips); meaningless while :attr:`parked` is False."""
        return self._brake_anchor

    @property
    def parking_brake_windup_rad(self) -> float:
        """Twist of the drive line against the applied parking brake [rad] (anchor − θ,
        > 0 while it holds the sprocket against turning backward); 0 when released."""
        return self._brake_anchor - float(self._qpos[self._sprocket_q]) if self.parked else 0.0

    def set_hitch_force(self, pull_N: float, down_N: float) -> None:
        """Load on the rear hitch (site ``rear_hitch``) in the chassis frame: ``pull_N`` [N]
        rearward along the chassis x axis, ``down_N`` [N] downward along its z axis.

        A towed load (pull_N > 0) makes the speed-servoed sprocket drive harder; a pushing
        load (pull_N < 0) makes it brake. Applied as a force and a moment about the chassis
        centre of mass (``xfrc_applied``).
        """
        if not (math.isfinite(pull_N) and math.isfinite(down_N)):
            raise ValueError(f"hitch force ({pull_N!r}, {down_N!r}) N must be finite")
        d, body = self.data, self._chassis_body
        force = d.xmat[body].reshape(3, 3) @ np.array((-pull_N, 0.0, -down_N))
        arm = d.site_xpos[self._hitch_site] - d.xipos[body]
        d.xfrc_applied[body, :3] = force
        d.xfrc_applied[body, 3:] = np.cross(arm, force)

    def apply(self, inputs: StepInputs) -> None:
        """Set one step's scenario inputs: the sprocket speed command (only when it changes:
        the servo keeps it) and the rear-hitch load (re-evaluated every step while it is not
        zero, because it acts in the rotating chassis frame)."""
        if inputs.track_speed_m_s != self._speed_command:
            self.set_track_speed(inputs.track_speed_m_s)
        hitch = (inputs.hitch_pull_N, inputs.hitch_down_N)
        if hitch != (0.0, 0.0) or self._hitch_loaded:
            self.set_hitch_force(*hitch)
            self._hitch_loaded = hitch != (0.0, 0.0)

    def scale_contact_stiffness(self, scale: float) -> None:
        """Multiply the physical stiffness of every track contact by ``scale`` [-] (W5
        perturbation): the foundation's K, and the partner geoms' (hub, idler, wheels,
        rollers, teeth), which decide every contact (priority) and carry a direct solref
        (−k, −b) with K = n·k/((1−d)·A) (:mod:`trackmj.track.mjcf.soft`), so k scales
        linearly; damping and impedance stay."""
        if not (math.isfinite(scale) and scale > 0.0):
            raise ValueError(f"contact stiffness scale must be > 0, got {scale!r}")
        m = self.model
        direct = m.geom_solref[:, 0] < 0.0
        if not np.any(direct):
            raise ValueError("no contact with a direct (physical) solref in this model")
        m.geom_solref[direct, 0] *= scale
        self.foundation.scale_stiffness(scale)

    @property
    def chassis_acc_z_m_s2(self) -> float:
        """Vertical chassis acceleration the last step produced [m/s²]: Δv_z/h (``qacc`` is
        the constraint solve's, before the foundation's implicit terms and MuJoCo's implicit
        update; it read 2–8 % high in RMS)."""
        dof = self._chassis_vz
        return float(self._qvel[dof] - self._start_qvel[dof]) / self._timestep

    @property
    def chassis_pose(self) -> np.ndarray:
        """(x [m], z [m], pitch [rad]) of the chassis frame relative to its layout pose."""
        return self.data.qpos[self._chassis_q].copy()

    @property
    def chassis_velocity(self) -> np.ndarray:
        """(vx [m/s], vz [m/s], pitch rate [rad/s])."""
        return self.data.qvel[self._chassis_v].copy()

    @property
    def chassis_acceleration(self) -> np.ndarray:
        """(ax [m/s²], az [m/s²], pitch acc [rad/s²]) the last step produced: (v₁ − v₀)/h
        over the MuJoCo step (its start velocity as the foundation kept it)."""
        v0 = self.foundation.start_velocity[self._chassis_v]
        return (self._qvel[self._chassis_v] - v0) / self.model.opt.timestep

    def ground_forces_N(self) -> np.ndarray:
        """Force the ground applied to every pin over the last step [N], shape
        (link_count, 2): normal N ≥ 0 and tangential F_t (along the ground's tangent, +x on
        flat ground; |F_t| ≤ μ·N). The group total in :meth:`contact_forces_N` and the
        energy ledger use the same numbers."""
        return self.foundation.applied_forces_N()

    @property
    def contact_count(self) -> int:
        return int(self.data.ncon)

    @property
    def closure_error_m(self) -> float:
        """Largest pin gap of the loop [m]: the deflection of the most loaded pin compliance
        (tension / stated pin stiffness, plus its damping share), at the start of the
        last step; a connect carrying m pins in series (structure "chains") stretches m
        times that; a pin slide (structure "slides") its own. Evaluated every step (the
        physics guard reads it), so in a compiled kernel (~1 µs)."""
        return _largest_pin_gap_m(self.data.efc_pos, self._pins_per_connect, self.data.qpos,
                                  self._stretch_qpos)

    @property
    def pin_rows(self) -> int:
        """Constraint rows of the pin connects, the first rows of every step (3 per connect)."""
        return self._pin_rows

    @property
    def warning_count(self) -> int:
        """Total MuJoCo warnings raised since the last reset."""
        return int(sum(w.number for w in self.data.warning))

    def pin_positions(self) -> np.ndarray:
        """World (x, z) of every pin [m], shape (link_count, 2)."""
        return self.data.geom_xpos[self._pin_geom][:, [0, 2]].copy()

    def pin_tensions_N(self) -> np.ndarray:
        """Tension in every pin [N], shape (link_count,), positive pulling the links apart.

        The force the pin's ``connect`` transmits (MuJoCo's ``efc_force``, the force the
        last step applied; its residual is anchor(link_{k-1}) − anchor(link_k), the force
        acting on link_{k-1}, forwards under tension), or for a hinged pin the force of
        link_{k-1} on its child link_k (the translational part of ``cfrc_int`` after
        ``mj_rnePostConstraint``, reversed), projected on the bisector of the two links'
        axes. It is the pin compliance's elastic and viscous force K·gap + B·gap rate plus
        the constraint's apparent-mass term (:mod:`trackmj.track.mjcf.soft`), which carries the
        pins' own stretch mode; no filtering.
        """
        d = self.data
        if self._has_hinged_pins:
            mujoco.mj_rnePostConstraint(self.model, d)
        _pin_tensions(d.efc_force, d.cfrc_int, d.xmat, self._link_body, self._connect_of_pin,
                      self._tension)
        return self._tension.copy()

    def strand_tensions_N(self) -> StrandTension:
        """Mean pin tension of the upper strand and of the rear lower run [N] (see
        :meth:`upper_strand_pins`, :meth:`lower_strand_pins`)."""
        return StrandTension(*self._strands(self.pin_tensions_N()))

    def _strands(self, tension: np.ndarray) -> tuple[float, float]:
        """Mean ``tension`` [N] over the upper strand and the lower run (the masks left in
        ``_upper``, ``_lower``)."""
        return _strands(self.data.geom_xpos, self._pin_geom, self._qpos, self._chassis_q,
                        self._strand_bounds, tension, self._upper, self._lower)

    def contact_forces_N(self) -> dict[str, float]:
        """Sum of contact normal forces on the track by partner [N]:
        sprocket, road_wheels, idler, return_rollers, ground (the foundation's)."""
        m, d = self.model, self.data
        totals: dict[str, float] = dict.fromkeys(
            ("sprocket", "road_wheels", "idler", "return_rollers"), 0.0)
        totals["ground"] = float(self.foundation.normal_forces_N.sum())
        wrench = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
            group = self._group_of_body.get(b1) or self._group_of_body.get(b2)
            if group is None:
                continue
            mujoco.mj_contactForce(m, d, i, wrench)
            totals[group] += float(wrench[0])
        return totals

    def idle_return_rollers(self) -> list[int]:
        """Indices k (0-based, as ``[return_rollers].x_m``) of the return rollers no link
        touches in the current state (at home: rollers the settled upper strand hangs clear
        of, which carry nothing)."""
        m, d = self.model, self.data
        rollers = {m.body(f"return_roller_{k + 1}").id: k
                   for k in range(len(self.params.return_rollers.x_m))}
        touched = {rollers.get(int(m.geom_bodyid[c.geom1]),
                               rollers.get(int(m.geom_bodyid[c.geom2])))
                   for c in (d.contact[i] for i in range(d.ncon))}
        return [k for k in rollers.values() if k not in touched]

    def seated_sprocket_pins(self) -> int:
        """Pins within the seat tolerance (:attr:`limits`) of the sprocket pitch circle; a
        pin riding on a tooth tip sits the tooth lift further out
        (:meth:`DerailmentLimits.tooth_lift_m`)."""
        centre = self.data.xpos[self._sprocket_body][[0, 2]]
        radius = np.linalg.norm(self.pin_positions() - centre, axis=1)
        off = np.abs(radius - self.params.sprocket_pitch_radius_m)
        return int(np.count_nonzero(off < self.limits.seat_tolerance_m))

    # ------------------------------------------------------------------ derailment
    def _chassis_frame_pins(self) -> np.ndarray:
        x, z, pitch = self.chassis_pose
        ride = self.params.chassis.ride_height_m
        rel = self.pin_positions() - np.array([x, ride + z])
        c, s = math.cos(pitch), math.sin(pitch)
        # undo the rotation about +y by `pitch`: x' = c x - s z, z' = s x + c z
        return np.column_stack([c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1]])

    def pins_layout_frame(self) -> np.ndarray:
        """(x, z) of every pin [m] in the chassis frame, placed as the chassis was at the
        layout (origin at ride height): comparable with the layout's coordinates,
        (link_count, 2)."""
        return self._chassis_frame_pins() + np.array([0.0, self.params.chassis.ride_height_m])

    def _home_envelope(self) -> np.ndarray:
        pts = self._chassis_frame_pins()
        return pts[ConvexHull(pts).vertices]  # counter-clockwise

    def envelope_excursion_m(self) -> np.ndarray:
        """Distance of each pin outside its home envelope (chassis frame) [m], (link_count,)."""
        pts = self._chassis_frame_pins()
        hull = self._envelope
        edges = np.roll(hull, -1, axis=0) - hull
        normals = np.column_stack([edges[:, 1], -edges[:, 0]])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        offsets = np.einsum("ij,ij->i", normals, hull)
        return np.maximum((pts @ normals.T - offsets).max(axis=1), 0.0)

    def upper_strand_pins(self) -> np.ndarray:
        """Indices of pins in the upper strand (above the line through the sprocket's and
        the idler's centres, raised by the margin; :func:`strand_bounds`)."""
        self._strands(self._tension)
        return np.nonzero(self._upper)[0]

    def lower_strand_pins(self) -> np.ndarray:
        """Indices of pins in the sprocket's lower run: between the sprocket and its
        nearest road wheel, the margin below the sprocket centre (:func:`strand_bounds`).
        With the sprocket at the rear
        it is the tight side driving forward; at the front the upper strand is."""
        self._strands(self._tension)
        return np.nonzero(self._lower)[0]

    def pin_strand(self, k: int) -> str:
        """The strand pin ``k`` is in now (:data:`STRANDS`)."""
        self._strands(self._tension)
        return STRANDS[0] if self._upper[k] else STRANDS[1] if self._lower[k] else STRANDS[2]

    @property
    def slack_duration_s(self) -> float:
        """How long the upper strand's least pin tension has stayed below
        ``SLACK_TENSION_N`` [s], in whole samples (``SLACK_SAMPLE_S``) up to the last one:
        0 when the last sample's was at or above it (an empty upper strand counts as 0 N)."""
        return self._slack_samples * self.SLACK_SAMPLE_S

    @property
    def slack_sample_steps(self) -> int:
        """Coupling steps per sample of the slack window (``SLACK_SAMPLE_S``)."""
        return self._slack_sample_steps

    @property
    def slack_window_samples(self) -> int:
        """Samples in ``SLACK_PERSISTENCE_S``, the slack window."""
        return len(self._slack_window)

    def _book_slack(self) -> None:
        """The least upper-strand pin tension now (0 N with no pin there) into the slack
        window and the run of slack samples: a sample, taken after every
        ``slack_sample_steps``-th step (:meth:`step`)."""
        d = self.data
        if self._has_hinged_pins:
            mujoco.mj_rnePostConstraint(self.model, d)
        least = _least_upper_tension(d.efc_force, d.cfrc_int, d.xmat, self._link_body,
                                     self._connect_of_pin, d.geom_xpos, self._pin_geom,
                                     self._qpos, self._chassis_q, self._strand_bounds,
                                     self._tension, self._upper, self._lower)
        self._slack_window[self._slack_at] = least
        self._slack_at = (self._slack_at + 1) % len(self._slack_window)
        self._slack_samples = self._slack_samples + 1 if least < self.SLACK_TENSION_N else 0

    def derailment(self) -> DerailmentStatus:
        """The derailment indicators now (thresholds :attr:`limits`; ``SLACK_TENSION_N``
        held for ``SLACK_PERSISTENCE_S``)
        and where each is worst: the pin furthest outside the home envelope and the
        upper-strand pin of least tension now. The strand is slack when its least pin
        tension was below ``SLACK_TENSION_N`` at each sample (every ``SLACK_SAMPLE_S``) of
        the last ``SLACK_PERSISTENCE_S`` (:attr:`slack_duration_s`)."""
        excursion = self.envelope_excursion_m()
        worst = int(excursion.argmax())
        upper = self.upper_strand_pins()
        tension = self.pin_tensions_N()
        slackest = int(upper[tension[upper].argmin()]) if len(upper) else -1
        min_upper = float(tension[slackest]) if slackest >= 0 else 0.0
        seated = self.seated_sprocket_pins()
        x, z = self.pins_layout_frame()[worst]
        return DerailmentStatus(
            sprocket_disengaged=seated < self.limits.min_seated_pins,
            links_off_envelope=float(excursion[worst]) > self.limits.envelope_threshold_m,
            slack_strand=self._slack_samples >= len(self._slack_window),
            max_envelope_excursion_m=float(excursion[worst]),
            min_upper_strand_tension_N=min_upper,
            held_upper_strand_tension_N=float(self._slack_window.max()),
            seated_pins=seated,
            worst_envelope_pin=worst,
            worst_envelope_strand=self.pin_strand(worst),
            worst_envelope_xz_m=(float(x), float(z)),
            min_upper_strand_pin=slackest,
        )

    def configuration(self) -> dict[str, np.ndarray]:
        """Indices, geometry and thresholds a port of :meth:`step` and the readouts needs
        (the native FMU's engine, trackmj/fmi/native/engine.c), by name; the foundation's
        arrays included (:meth:`Foundation.configuration`). Sign conventions and units as
        this class's."""
        m = self.model
        return {
            "substeps": np.array([self.substeps]), "pins": np.array([self.link_count]),
            "slide_q": np.array([self._slide_q]), "slide_v": np.array([self._slide_v]),
            "sprocket_v": np.array([self._sprocket_v]), "chassis_q": self._chassis_q,
            "chassis_v": self._chassis_v, "tensioner": np.array([self._tensioner]),
            "drive": np.array([self._drive]), "hitch_site": np.array([self._hitch_site]),
            "chassis_body": np.array([self._chassis_body]),
            "sprocket_body": np.array([self._sprocket_body]),
            "drive_gain": np.array([self._drive_gain]),
            "drive_limit": np.array([self._drive_limit]),
            "drive_band": np.array([self._drive_band]),
            "sprocket_q": np.array([self._sprocket_q]),
            "parking_brake": np.array([self._brake_ratio, self._brake_slip_rad,
                                       self._brake_apply_rad_s]),
            "stroke_offset_m": np.array([self._stroke_offset_m]),
            "pitch_radius_m": np.array([self.params.sprocket_pitch_radius_m]),
            "ride_height_m": np.array([self.params.chassis.ride_height_m]),
            "strand_bounds": self._strand_bounds,
            "envelope_threshold_m": np.array([self.limits.envelope_threshold_m]),
            "seat_tolerance_m": np.array([self.limits.seat_tolerance_m]),
            "slack_tension_N": np.array([self.SLACK_TENSION_N]),
            "slack_sample_steps": np.array([self.slack_sample_steps]),
            "slack_window_samples": np.array([self.slack_window_samples]),
            "min_seated_pins": np.array([self.limits.min_seated_pins]),
            "link_body": self._link_body, "pin_geom": self._pin_geom,
            "connect_of_pin": self._connect_of_pin, "pins_per_connect": self._pins_per_connect,
            "stretch_qpos": self._stretch_qpos,
            "home_envelope": self._envelope, "timestep_s": np.array([m.opt.timestep]),
            **self.foundation.configuration(),
            **self.springs.configuration(),
        }

    def hitch_kinematics(self) -> np.ndarray:
        """What the next step resolves the hitch load with (:meth:`set_hitch_force`): the
        chassis rotation matrix (9, row-major), the hitch site and the chassis centre of
        mass (3 each, world) [m], as MjData holds them now, shape (15,)."""
        d, body = self.data, self._chassis_body
        return np.concatenate([d.xmat[body], d.site_xpos[self._hitch_site], d.xipos[body]])

    # ------------------------------------------------------------------ stepping
    def step(self, element: TensionerElement,
             on_substep: Callable[[], None] | None = None) -> ForceLaw:
        """Advance one 1 ms coupling step with ``element`` acting on the idler carrier;
        ``on_substep`` is called after each MuJoCo step of it (an energy ledger's
        :meth:`~trackmj.track.energy.TrackEnergyLedger.after_step`).

        With several MuJoCo substeps the law is held and the element is completed with
        the mean velocity over the step (displacement / step), which keeps the work
        exchanged consistent with the stroke change. Every ``slack_sample_steps``-th
        step (of :attr:`step_count`) samples the upper strand's least pin tension into the
        slack window (:meth:`derailment`).
        """
        m, d = self.model, self.data
        stroke0 = self.stroke_m
        law = element.force_law(self.time_s, stroke0, self.stroke_velocity_m_s)
        force, damping = law.force_N, law.damping_N_s_m
        if not (math.isfinite(force) and math.isfinite(damping)):
            raise ValueError(f"tensioner returned a non-finite force law {law}")
        self._ctrl[self._tensioner] = force
        self._biasprm[self._tensioner, 2] = damping
        self.last_law = law   # what idler_force_N reads, in on_substep too
        if self._park_pending and (abs(self._qvel[self._sprocket_v])
                                   < self._brake_apply_rad_s):
            self.parked, self._park_pending = True, False
            self._brake_anchor = float(self._qpos[self._sprocket_q])
        parked = self.parked
        if parked:
            command = self._brake_ratio * (self._brake_anchor - self._qpos[self._sprocket_q])
            self._ctrl[self._drive] = command
        else:
            command = self._ctrl.item(self._drive)   # set_track_speed's
        for _ in range(self.substeps):
            # a step that starts at the drive's torque limit may end inside it
            saturated = abs(command - self._qvel.item(self._sprocket_v)) >= self._drive_band
            foundation_step(m, d, self.foundation, self.springs, self._saved_state,
                            self._drive_retake.start() if saturated else None)
            if on_substep is not None:
                on_substep()
            if saturated:
                self._drive_retake.restore()
        if parked:   # the brake slips: its anchor follows, the spring at the holding torque
            angle = float(self._qpos[self._sprocket_q])
            if abs(self._brake_anchor - angle) > self._brake_slip_rad:
                self._brake_anchor = angle + math.copysign(self._brake_slip_rad,
                                                           self._brake_anchor - angle)
        stroke = self.stroke_m
        if self.substeps == 1:
            velocity = self.stroke_velocity_m_s
        else:
            velocity = (stroke - stroke0) / COUPLING_STEP_S
        self.time_s += COUPLING_STEP_S
        self.step_count += 1
        if not self.step_count % self._slack_sample_steps:
            self._book_slack()
        element.complete_step(self.time_s, stroke, velocity)
        return law

    def run(self, element: TensionerElement, duration_s: float,
            track_speed: Callable[[float], float] | float = 0.0,
            on_step: Callable[[TrackPlant], None] | None = None, *,
            park: bool = True) -> None:
        """Step for ``duration_s`` with a track-speed command [m/s] (constant or f(t));
        ``park`` as :meth:`set_track_speed`'s."""
        steps = round(duration_s / COUPLING_STEP_S)
        speed = track_speed if callable(track_speed) else (lambda _t: track_speed)
        for _ in range(steps):
            self.set_track_speed(speed(self.time_s), park=park)
            self.step(element)
            if on_step is not None:
                on_step(self)
