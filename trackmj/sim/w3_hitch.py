"""Calibration of W3's physical load pulses against the hold-mode idler load, per machine.

W3 asks for idler-load disturbances applied physically; its targets are relative to the
machine's nominal tension (``delta_rel``: the study's +2 kN and −1.5 kN at LF1352's 15 kN,
+2/15 and −1.5/15). trackmj applies them as a load on the rear hitch along a chain inclined
below the horizontal (a skidded log) while the speed-servoed sprocket holds the track speed.
The disturbance therefore enters through the track as a sprocket drive/brake torque pulse
plus a pitch load, not as a force on the idler. On a rear-sprocket machine (LF1352) a push
(forward and up) makes the sprocket brake, so the top strand between sprocket and idler
becomes the tight side, and it unloads the rear: the idler load rises. A tow (rearward and
down) makes the sprocket drive harder, with the tight side in the bottom strand on the
ground, and it loads the rear so the rear road wheels rise against their springs and the
track path shortens: the idler load falls. Measured on LF1352 in hold mode, a pure
horizontal tow at the traction limit (~13 kN) lowers the idler load by only ~1.0 kN; the
study's −1.5 kN needs the rear load that a chain at 30° below the horizontal adds. On a
front-sprocket machine (M113) the tight side of a drive is the top strand, so the force
that gives a change of a given sign may have the other direction: the calibration finds it.

The calibration runs the tp plant (track + hydraulic plugin) of the machine in hold mode
with the valves closed, once without a pulse and once per trial amplitude from the same
deterministic state, always with the study's supply (``fixed_relief``, with which the
pulses were calibrated): in hold the supply reaches the heads only through the closed
valves' leakage, but runs that differ by that leakage alone diverge after ~1.3 s, and the
measured change of the −1.5 kN pulse then moves by up to 40 % with the supply model
(measured on LF1352: fixed_relief −1.52, compensated −1.26, prescribed −0.90 kN). It
measures the mean difference of the idler force F_ten between the two runs over the pulse's
plateau, after a settling allowance. Subtracting the reference run removes the hold-mode
drift (leakage) and the chordal ripple, which are identical in both runs until the pulse
starts. The secant method then finds the hitch force that gives the target change.

The rule that ties the hitch force to the machine (:func:`starting_guess`,
:func:`drawbar_capacity_N`):

* the secant starts from LF1352's calibrated hitch force as a fraction of its side weight,
  times this machine's side weight W (and times the ratio of the relative targets, 1 for
  W3), and its first chord runs through the origin (no force, no change);
* the horizontal component of the hitch force must stay within the drawbar capacity of the
  side, μ·W with μ the track-ground friction coefficient (``[track].ground_friction``, the
  foundation's Coulomb limit): the drawbar pull of a tracked vehicle is at most the
  ground's shear strength, μ·W on firm ground (Wong, *Theory of Ground Vehicles*, ch. 2
  and 4: tractive effort ≤ c·A + W·tan φ; a dry-friction ground has c = 0, tan φ = μ).
  The chain's vertical component changes the normal load (a tow adds to it, a push lifts
  it); that bound leaves it out;
* and the hitch force must stay within 75 % of the static force that would tip the side
  over the centre of its idler or sprocket (:func:`tipping_forces_N`; a push tips it
  forward, a tow backward): the rated load of an earth-moving machine in normal work is at
  most 75 % of its tipping load (ISO 10567, rated lift capacity). A trial beyond it is no
  working load (on a layout no one shipped, compact3 with its sprocket in front, the
  drawbar capacity's 13.8 kN push, 1.6 times its tipping force, left physics and refused
  W3);
* a target that no force within those bounds reaches (compact3's drive pulse: its rollers
  are bolted to the frame, so a tow does not shorten its track path) is out of the
  machine's reach, not refused: the pulse applies, of the forces the search tried, the one
  that moved the idler load furthest towards the target, and the machine's own hold-mode
  change with it is recorded and printed (one line on stderr per process); the idler sees
  what this machine's layout makes of the load.
  A run that leaves physics, or a secant that does not converge, still refuses the pulse.

The calibrated forces are looked up by a hash of what determines them (the machine's
validated mechanics and hydraulics, the pulses' targets, angles and edges, the track speed
and initial force over the calibration run, the terrain and this method's constants):
first in ``experiments/W3_calibration.toml`` (committed for the shipped machines, written by
``experiments/calibrate_w3.py``), then in the user's cache directory
(:func:`trackmj.io.cache_dir`, where trackmj caches generated models and identified idlers),
else calibrated on first use and cached there. A committed entry whose hash differs (an
edited machine file, ``--set model.*``) is never used: the forces are recalibrated and
stderr says so.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trackmj.host import machine as host_machine
from trackmj.hydraulics.params import HydraulicParams
from trackmj.io import cache_dir, write_text_atomic
from trackmj.machines.assembly import Machine
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.ports import COUPLING_STEP_S, Element, StepInputs
from trackmj.scenarios.load import BUILTIN_FOLDER
from trackmj.scenarios.resolved import HitchCalibration, Scenario
from trackmj.scenarios.schema import (
    FORCE_MAX_N,
    HITCH_LIMIT_N,
    NOMINAL,
    LoadPulse,
    Supply,
    present,
)
from trackmj.sim.architectures import assemble
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.sim.setup import RunSetup
from trackmj.track.mechanics import ModelParams
from trackmj.track.plant import TrackPlant
from trackmj.validator import (
    Location,
    ParameterError,
    Parameters,
    build,
    param,
    read_toml,
    sources_field,
)

START_S = 3.0
"""Pulse onset in the calibration runs [s], after the 1 s speed ramp has settled."""
PLATEAU_S = 2.0
"""Plateau of the calibration pulses [s] (W3's pulses last 2 s)."""
SETTLE_ALLOWANCE_S = 0.5
"""Time after the pulse's rise excluded from the mean [s] (about three chassis heave periods)."""
RIG_SUPPLY_MODEL = "fixed_relief"
"""Supply model of the calibration rig (the pulses were calibrated with it; see above)."""
REL_TOL = 0.02
"""The secant stops when the change is within 2 % of the target."""
MAX_RUNS = 14
"""Trial runs per pulse before the calibration gives up."""
TIPPING_SHARE = 0.75
"""Share of the static tipping force a trial hitch force may reach (ISO 10567: the rated lift
capacity of an earth-moving machine is at most 75 % of its tipping load)."""
REFERENCE_MACHINE = DEFAULT_MACHINE
"""The machine whose calibrated hitch forces per side weight start the secant (LF1352)."""
CALIBRATION_FILE = BUILTIN_FOLDER / "W3_calibration.toml"
"""The committed calibration of the shipped machines."""
METHOD = (f"hold-mode tp, seed 0, nominal variant, {RIG_SUPPLY_MODEL} supply; pulse at "
          f"{START_S} s, plateau {PLATEAU_S} s, mean after {SETTLE_ALLOWANCE_S} s; secant "
          f"to {REL_TOL} within mu W and {TIPPING_SHARE} of the static tipping force; out of "
          "reach: the trial furthest towards the target")
"""What a calibration's numbers depend on besides the machine and the pulses (hashed)."""


# ----------------------------------------------------------------------- the hold-mode rig

@dataclass(frozen=True)
class Rig:
    """The machine a calibration is for, as a run prepared on it
    (:func:`~trackmj.sim.setup.prepare`): its machine, validated mechanics and hydraulics
    (what the calibration depends on) and the rest of the run, which the rig replaces (tp,
    nominal variant, seed 0, no pulses)."""

    setup: RunSetup

    @property
    def machine(self) -> Machine:
        """The machine."""
        return self.setup.machine

    @property
    def params(self) -> ModelParams:
        """Its validated mechanics (with the run's model overrides)."""
        return self.setup.model

    @property
    def hydraulic_params(self) -> HydraulicParams:
        """Its validated hydraulics (with the run's overrides and variant scales)."""
        return self.setup.hydraulics


def hold_mode_run(scenario: Scenario, rig: Rig) -> tuple[TrackPlant, Element]:
    """The tp track of ``scenario`` on the rig's machine (nominal variant, seed 0, no load
    pulses) settled at its initial reference, with the reference architecture's element
    (the hydraulic plugin) left in hold mode (no valve command is given) and the study's
    supply: the open-loop calibration rig."""
    bare = dataclasses.replace(scenario, supply=Supply(model=RIG_SUPPLY_MODEL),
                               load_pulses=(), hitch_calibration=None)
    asm = assemble(dataclasses.replace(
        rig.setup, scenario=bare, variant=NOMINAL, architecture=REFERENCE_ARCHITECTURE,
        element=ARCHITECTURES[REFERENCE_ARCHITECTURE].element, tensioner=None, seed=0,
        duration_s=bare.duration_s))
    if asm.track is None:
        raise ValueError("the calibration rig needs the MuJoCo track (the tp architecture)")
    return asm.track, asm.element


def idler_force_history(scenario: Scenario, pulse: LoadPulse, rig: Rig) -> np.ndarray:
    """F_ten [N] at 1 kHz of a hold-mode tp run of ``scenario`` on the rig's machine (its
    speed profile, nominal variant) with the one hitch ``pulse``, until the pulse ends;
    shape (steps,)."""
    plant, element = hold_mode_run(scenario, rig)
    pulsed = dataclasses.replace(scenario, load_pulses=(pulse,), hitch_calibration=None)
    steps = round(pulse.end_s / COUPLING_STEP_S)
    t = COUPLING_STEP_S * np.arange(steps)
    speed = pulsed.track_speed_m_s(t)
    pull, down = pulsed.hitch_force_N(t)
    force = np.empty(steps)
    for k in range(steps):
        plant.apply(StepInputs(float(speed[k]), float(pull[k]), float(down[k]), math.nan))
        plant.step(element)
        force[k] = plant.idler_force_N
    return force


def side_weight_N(plant: TrackPlant) -> float:
    """Weight of the plant's track side [N]: the mass of every body of its model (chassis
    share, track, wheels, idler and carrier) times gravity's component normal to the ground
    (m·g·cos θ on a scenario's grade)."""
    model = plant.model
    return float(model.body_subtreemass[0]) * float(-model.opt.gravity[2])


def drawbar_capacity_N(params: ModelParams, weight_N: float) -> float:
    """Largest horizontal hitch force the side's ground can react [N]: μ·W with μ the
    track-ground friction (``[track].ground_friction``) and W the side weight ``weight_N``
    (Wong, Theory of Ground Vehicles: drawbar pull ≤ μ·W on a frictional ground)."""
    return params.track.ground_friction * weight_N


def tipping_forces_N(plant: TrackPlant, pull_angle_deg: float) -> tuple[float, float]:
    """Static hitch forces along a chain ``pull_angle_deg`` [°] below the horizontal that
    tip the settled side of ``plant`` over an end of its track [N]: (push, tow), both > 0
    (the push's force is −push), inf where no force does.

    Planar moment balance on the side as one rigid body (x forward, z up, the ground under
    the track at z = 0): its weight W at the centre of mass x_c; the hitch force f along the
    chain (f > 0 a tow: f·cos a rearward and f·sin a down at the hitch (x_h, z_h); f < 0
    pushes forward and up), the ground's normal N = W + f·sin a at x_N and its traction
    (in the ground line, no moment). x_N·N = x_c·W − z_h·f·cos a + x_h·f·sin a, so the
    centre reaches a tipping line x_e at

        f = W·(x_c − x_e) / (sin a·(x_e − x_h) + z_h·cos a),

    the front one for a push, the rear one for a tow; a push is also bounded by lifting the
    side (N = 0: f = −W / sin a). The tipping lines are under the centres of the track's
    end wheels (sprocket and idler): pitching over an end, the side rolls onto the track
    round that wheel. Measured (push along 30°, 1 s rise, hold mode): compact3 stands at
    0.89 of this force and rolls over at 1.0, LF1352 stands at 0.8 and rolls over at 1.2
    (tests/test_w3_calibration.py brackets both); the settled ground patch's front end as
    the line would put compact3's limit at 0.81 of this, where it still stands."""
    model, data = plant.model, plant.data
    weight = side_weight_N(plant)
    x_c = float(data.subtree_com[0][0])
    rear, front = sorted(float(data.xpos[model.body(name).id][0])
                         for name in ("sprocket", "idler"))
    carried = plant.ground_forces_N()[:, 0] > 0.0
    if not carried.any():
        raise ValueError("tipping_forces_N: no pin carried by the ground (is the plant settled?)")
    line = plant.foundation.line
    ground_z = float(np.mean(np.interp(plant.pin_positions()[carried, 0], line[:, 0],
                                       line[:, 1])))
    hitch = plant.hitch_kinematics()[9:12]
    x_h, z_h = float(hitch[0]), float(hitch[2]) - ground_z
    s, c = math.sin(math.radians(pull_angle_deg)), math.cos(math.radians(pull_angle_deg))

    def tipping(x_end: float) -> float:      # |f| at the line x_end (its sign: x_c − x_end)
        lever = s * (x_end - x_h) + z_h * c
        return weight * abs(x_c - x_end) / lever if lever > 0.0 else math.inf

    lift = weight / s if s > 0.0 else math.inf
    return min(tipping(front), lift), tipping(rear)


def calibration_pulse(hitch_N: float, pull_angle_deg: float, rise_s: float,
                      plateau_s: float = PLATEAU_S) -> LoadPulse:
    """A pulse from START_S with the given hitch force [N], angle [deg], edges [s] and
    plateau [s] (target change left at 0)."""
    return LoadPulse(start_s=START_S, end_s=START_S + rise_s + plateau_s, delta_N=0.0,
                     hitch_N=hitch_N, pull_angle_deg=pull_angle_deg, rise_s=rise_s)


def load_change_N(scenario: Scenario, rig: Rig, hitch_N: float, pull_angle_deg: float, *,
                  rise_s: float = 0.1, reference: np.ndarray | None = None) -> float:
    """Mean change [N] of the hold-mode idler load that a hitch pulse causes on the rig's
    machine, measured against a pulse-free run (pass ``reference``, the history with
    hitch_N = 0, to reuse it) over the plateau after SETTLE_ALLOWANCE_S."""
    if reference is None:
        reference = idler_force_history(scenario, calibration_pulse(0.0, pull_angle_deg,
                                                                    rise_s), rig)
    pulsed = idler_force_history(scenario, calibration_pulse(hitch_N, pull_angle_deg, rise_s),
                                 rig)
    first = round((START_S + rise_s + SETTLE_ALLOWANCE_S) / COUPLING_STEP_S)
    return float(np.mean(pulsed[first:] - reference[first:]))


# ------------------------------------------------------------------------ the calibration

@dataclass(frozen=True)
class PulseCalibration:
    """One pulse's result: the hitch force [N], the idler-load change it gave [N], the
    hold-mode runs it took (the reference run not counted) and, for a target out of the
    machine's reach, why (one line; the force is then the trial furthest towards it)."""

    hitch_N: float
    achieved_N: float
    runs: int
    out_of_reach: str = ""


class OutOfReach(ParameterError):
    """No hitch force within the limits reaches the target: ``what`` names the pulse,
    machine and limits, ``why`` what the search found; ``tried`` holds each trial's (hitch
    force [N], idler-load change [N]), the start and its mirror first."""

    def __init__(self, what: str, why: str, tried: list[tuple[float, float]]) -> None:
        super().__init__(f"{what}: {why}")
        self.what, self.why, self.tried = what, why, tried


def starting_guess(target_rel: float, weight_N: float,
                   reference: CalibrationEntry | None) -> tuple[float, str]:
    """Secant start [N] for a target change of ``target_rel`` x nominal on a side weighing
    ``weight_N`` [N], and its rule in words: the reference machine's calibrated hitch force
    per side weight for the target of the same sign, times this weight and the ratio of the
    targets; without a reference entry for that sign, a hitch force of the target's size x
    the weight, pushing for a rise (LF1352's sign)."""
    if reference is not None:
        for hitch, rel in zip(reference.hitch_N, reference.delta_rel, strict=True):
            if rel * target_rel > 0.0:
                return (hitch / reference.side_weight_N * weight_N * target_rel / rel,
                        f"{REFERENCE_MACHINE}'s hitch force per side weight x this side's "
                        "weight")
    return -target_rel * weight_N, "the target's share of the nominal x the side weight"


def binding_limit(drawbar_N: float, tipping_N: float) -> tuple[float, str]:
    """The limit [N] along the chain that binds in one direction, and its name: the drawbar
    capacity ``drawbar_N``, the share of the tipping force ``tipping_N``, or (on no crawler
    trackmj models) the scenario schema's sanity cap on hitch_N."""
    return min((drawbar_N, "the drawbar capacity"),
               (tipping_N, f"{TIPPING_SHARE * 100:g} % of the tipping force"),
               (HITCH_LIMIT_N, f"the sanity cap on hitch_N, {HITCH_LIMIT_N / 1e3:g} kN"))


def search(change: Callable[[float], float], target_N: float, start_N: float,
           limits_N: tuple[float, float], *, what: str,
           limit_names: tuple[str, str] = ("", "")) -> PulseCalibration:
    """Hitch force [N] whose ``change`` [N] equals ``target_N`` within REL_TOL, every trial
    within ``limits_N`` = (push, tow), the largest push and tow along the chain [N] (> 0),
    ``limit_names`` what each is (named in an out-of-reach reason).

    ``start_N`` first; if it misses, its mirror (−start_N) too, and the direction whose
    change goes further towards the target is kept (on a front-sprocket machine a tow may
    raise the idler load). Along it, a secant through the origin (no force, no change)
    steps out until the change passes the target (doubling where the change does not grow
    towards it), then the Illinois variant of false position closes the bracket. The
    response need not be linear (a rigid undercarriage makes it convex) nor monotone over
    the whole range; the bracket keeps the root nearest the origin that the steps find.
    :class:`OutOfReach` (one line, naming ``what``) if the change at the limit still falls
    short; ParameterError if a run leaves physics or MAX_RUNS trials do not reach the
    target."""
    if not (math.isfinite(target_N) and target_N != 0.0):
        raise ValueError(f"target_N = {target_N!r}: must be finite and non-zero")
    tried: list[tuple[float, float]] = []

    def limit(f: float) -> float:           # the limit in f's direction [N]
        return limits_N[0] if f < 0.0 else limits_N[1]

    def within(f: float) -> float:          # f capped at that limit
        return math.copysign(min(abs(f), limit(f)), f)

    def run(f: float) -> float:
        d = change(f)
        tried.append((f, d))
        if not (math.isfinite(d) and abs(d) < 1e6):
            raise ParameterError(f"{what}: the hold-mode run with {f:+.0f} N at the hitch "
                                 f"left physics (idler-load change {d:.3g} N)")
        return d

    def towards(d: float) -> float:         # progress towards the target [N]
        return d if target_N > 0.0 else -d

    def close(d: float) -> bool:
        return abs(d - target_N) <= REL_TOL * abs(target_N)

    def trials() -> str:
        return "tried " + ", ".join(f"{a:+.0f} N -> {b / 1e3:+.3f} kN" for a, b in tried)

    def give_up(reason: str) -> ParameterError:
        return ParameterError(f"{what}: {reason}; {trials()} (a hitch_N given for the pulse, "
                              "e.g. --set scenario.load_pulses.N.hitch_N=..., is applied as "
                              "it is)")

    f = within(start_N)
    d = run(f)
    if close(d):
        return PulseCalibration(f, d, len(tried))
    mirror = within(-f)
    d_mirror = run(mirror)
    if close(d_mirror):
        return PulseCalibration(mirror, d_mirror, len(tried))
    if towards(d_mirror) > towards(d):
        f, d = mirror, d_mirror
    lo = (0.0, 0.0)
    while towards(d) < abs(target_N):        # short: step out along the direction
        if abs(f) >= limit(f):
            side = "the wrong way from" if towards(d) <= 0.0 else "short of"
            kind = "push" if f < 0.0 else "tow"
            name = limit_names[0] if f < 0.0 else limit_names[1]
            raise OutOfReach(what, f"at the limit{f' ({name})' if name else ''}, a {kind} of "
                             f"{f:+.0f} N along the chain, "
                             f"the idler load changes by {d / 1e3:+.3f} kN, {side} "
                             f"{target_N / 1e3:+.3f} kN; {trials()}", tried)
        if len(tried) >= MAX_RUNS:
            raise give_up(f"not bracketed in {MAX_RUNS} runs")
        grows = towards(d) > towards(lo[1])
        nxt = (f + (target_N - d) * (f - lo[0]) / (d - lo[1])) if grows else 2.0 * f
        nxt = within(math.copysign(max(abs(nxt), abs(f) * 1.25), f))
        lo, (f, d) = (f, d), (nxt, 0.0)
        d = run(f)
        if close(d):
            return PulseCalibration(f, d, len(tried))
    hi = (f, d)
    g_lo, g_hi, kept = lo[1] - target_N, hi[1] - target_N, 0
    while len(tried) < MAX_RUNS:
        f = (lo[0] * g_hi - hi[0] * g_lo) / (g_hi - g_lo)
        d = run(f)
        if close(d):
            return PulseCalibration(f, d, len(tried))
        if towards(d) < abs(target_N):
            lo, g_lo = (f, d), d - target_N
            kept = kept + 1 if kept > 0 else 1
            if kept > 1:
                g_hi /= 2.0
        else:
            hi, g_hi = (f, d), d - target_N
            kept = kept - 1 if kept < 0 else -1
            if kept < -1:
                g_lo /= 2.0
    raise give_up(f"not within {REL_TOL:.0%} in {MAX_RUNS} runs")


def furthest_towards(short: OutOfReach, target_N: float, rule: str) -> PulseCalibration:
    """The pulse for a target out of reach (``short``, from :func:`search`): of the forces
    tried (all within the limits; the search started from ``rule``), the one that moved the
    idler load furthest towards ``target_N`` [N], with its measured change and the
    reason."""
    f, d = max(short.tried, key=lambda trial: math.copysign(trial[1], target_N))
    kind = "tow" if f > 0.0 else "push"
    reason = (f"{short.what} is out of reach: the pulse applies the {kind} {f:+.0f} N, "
              f"of the forces tried the one that moved the idler load "
              f"furthest towards the target (the search started from {rule}), a hold-mode "
              f"idler-load change of {d / 1e3:+.3f} kN ({short.why}; --set "
              "scenario.load_pulses.N.hitch_N=... applies a force of your choice)")
    return PulseCalibration(f, d, len(short.tried), reason)


@dataclass(frozen=True)
class Measured:
    """A calibration on one machine: per pulse index its result, or why it was refused
    (one line); the side weight [N], the drawbar capacity [N] and the wall time [s]."""

    pulses: dict[int, PulseCalibration]
    refused: dict[int, str]
    side_weight_N: float
    drawbar_capacity_N: float
    wall_s: float


def calibrate(scenario: Scenario, rig: Rig, indices: tuple[int, ...],
              reference: CalibrationEntry | None) -> Measured:
    """Calibrate the load pulses ``indices`` of ``scenario`` on the rig's machine, each to
    its target delta_N (one reference run per pulse angle and edge; a pulse that cannot
    be reached is refused and the others still calibrated)."""
    t0 = time.perf_counter()
    settled, _ = hold_mode_run(scenario, rig)       # the side standing: its tipping lines
    weight = side_weight_N(settled)
    capacity = drawbar_capacity_N(rig.params, weight)
    nominal = scenario.nominal_tension_N or rig.params.nominal_tension_N
    references: dict[tuple[float, float], np.ndarray] = {}
    out, refused = {}, {}
    for i in indices:
        p = scenario.load_pulses[i]
        target = present(p.delta_N, "load_pulses.delta_N")
        shape = (p.pull_angle_deg, p.rise_s)
        if shape not in references:
            references[shape] = idler_force_history(
                scenario, calibration_pulse(0.0, p.pull_angle_deg, p.rise_s), rig)

        def change(f: float, angle: float = p.pull_angle_deg, rise: float = p.rise_s,
                   ref: np.ndarray = references[shape]) -> float:
            return load_change_N(scenario, rig, f, angle, rise_s=rise, reference=ref)

        tip_push, tip_tow = tipping_forces_N(settled, p.pull_angle_deg)
        what = (f"{scenario.name} load pulse {i} ({target / 1e3:+.3f} kN) on machine "
                f"{rig.machine.name} (drawbar capacity mu W = "
                f"{rig.params.track.ground_friction:g} x {weight / 1e3:.2f} kN = "
                f"{capacity / 1e3:.2f} kN horizontal, Wong, Theory of Ground Vehicles; "
                f"{TIPPING_SHARE * 100:g} % of the static tipping force along the chain, "
                f"ISO 10567: push {TIPPING_SHARE * tip_push / 1e3:.2f} kN, tow "
                f"{TIPPING_SHARE * tip_tow / 1e3:.2f} kN)")
        drawbar = capacity / math.cos(math.radians(p.pull_angle_deg))
        push, push_name = binding_limit(drawbar, TIPPING_SHARE * tip_push)
        tow, tow_name = binding_limit(drawbar, TIPPING_SHARE * tip_tow)
        start, rule = starting_guess(target / nominal, weight, reference)
        try:
            out[i] = search(change, target, start, (push, tow), what=what,
                            limit_names=(push_name, tow_name))
        except OutOfReach as exc:
            out[i] = furthest_towards(exc, target, rule)
        except ParameterError as exc:
            refused[i] = str(exc)
    return Measured(out, refused, weight, capacity, time.perf_counter() - t0)


# ------------------------------------------------------------- committed table and cache

SHA256 = r"[0-9a-f]{64}"


@dataclass(frozen=True)
class Applied:
    """A pulse's calibrated hitch force [N]; for a target out of the machine's reach (the
    force then the trial furthest towards it) why, in one line, else ""."""

    hitch_N: float
    out_of_reach: str = ""


@dataclass(frozen=True)
class CalibrationEntry(Parameters):
    """``[machine.NAME]`` of ``W3_calibration.toml`` (and a user cache record): the
    calibrated hitch forces on one machine per calibrated pulse (``pulse_index``, each
    with the hash of its inputs), the pulses refused there with the reason, and the hashes
    of the machine's mechanics and hydraulics."""

    scenario: str = param(max_len=64, doc="the scenario the pulses are from")
    pulse_index: tuple[int, ...] = param(0, 100, unit="1", allow_empty=True,
                                         doc="the calibrated pulses")
    pulse_sha256: tuple[str, ...] = param(pattern=SHA256, allow_empty=True,
                                          doc="hash of each one's inputs (target, angle, "
                                          "edges, speed, initial force, terrain, method)")
    delta_rel: tuple[float, ...] = param(-1.0, 1.0, unit="1", allow_empty=True,
                                         doc="target idler-load change over the nominal")
    target_N: tuple[float, ...] = param(-FORCE_MAX_N, FORCE_MAX_N, allow_empty=True,
                                        doc="target idler-load change")
    hitch_N: tuple[float, ...] = param(-HITCH_LIMIT_N, HITCH_LIMIT_N, allow_empty=True,
                                       doc="calibrated hitch force (> 0 tow, < 0 push)")
    achieved_N: tuple[float, ...] = param(-FORCE_MAX_N, FORCE_MAX_N, allow_empty=True,
                                          doc="hold-mode idler-load change measured with it")
    side_weight_N: float = param(0.0, FORCE_MAX_N, open_low=True,
                                 doc="weight of the track side")
    drawbar_capacity_N: float = param(0.0, FORCE_MAX_N, doc="mu x side weight")
    mechanics_sha256: str = param(pattern=SHA256, doc="hash of the validated mechanics")
    hydraulics_sha256: str = param(pattern=SHA256, doc="hash of the validated hydraulics")
    host: str = param(max_len=300, doc="where it was measured (trackmj.host.machine())")
    wall_s: float = param(0.0, 1e5, doc="wall time of the calibration")
    refused_index: tuple[int, ...] = param(0, 100, unit="1", default=(), allow_empty=True,
                                           doc="the pulses refused on this machine")
    refused_sha256: tuple[str, ...] = param(pattern=SHA256, default=(), allow_empty=True,
                                            doc="hash of each refused one's inputs")
    refused: tuple[str, ...] = param(max_len=2000, default=(), allow_empty=True,
                                     doc="why each could not be calibrated (one line)")
    out_of_reach_index: tuple[int, ...] = param(0, 100, unit="1", default=(),
                                                allow_empty=True,
                                                doc="the calibrated pulses whose target "
                                                "no force within the limits reaches "
                                                "(their hitch_N the trial furthest "
                                                "towards it)")
    out_of_reach: tuple[str, ...] = param(max_len=2000, default=(), allow_empty=True,
                                          doc="why, and what was applied (one line each)")

    def cross_check(self, at: Location) -> None:
        n = len(self.pulse_index)
        for key in ("pulse_sha256", "delta_rel", "target_N", "hitch_N", "achieved_N"):
            if len(getattr(self, key)) != n:
                raise at.error(key, list(getattr(self, key)),
                               f"must have one value per pulse_index ({n})")
        for key in ("refused_sha256", "refused"):
            if len(getattr(self, key)) != len(self.refused_index):
                raise at.error(key, list(getattr(self, key)), "must have one value per "
                               f"refused_index ({len(self.refused_index)})")
        if len(self.out_of_reach) != len(self.out_of_reach_index):
            raise at.error("out_of_reach", list(self.out_of_reach), "must have one value "
                           f"per out_of_reach_index ({len(self.out_of_reach_index)})")
        if not set(self.out_of_reach_index) <= set(self.pulse_index):
            raise at.error("out_of_reach_index", list(self.out_of_reach_index),
                           f"must be among pulse_index {list(self.pulse_index)}")

    def lookup(self, hashes: InputHashes, index: int) -> Applied | str | None:
        """Pulse ``index``'s calibrated hitch force, or the reason it is refused, if this
        entry holds its inputs (``hashes``); None if not."""
        if (self.mechanics_sha256, self.hydraulics_sha256) != (hashes.mechanics,
                                                                hashes.hydraulics):
            return None
        pulse = hashes.pulses[index]
        if pulse in self.pulse_sha256:
            at = self.pulse_sha256.index(pulse)
            reach = dict(zip(self.out_of_reach_index, self.out_of_reach, strict=True))
            return Applied(self.hitch_N[at], reach.get(self.pulse_index[at], ""))
        if pulse in self.refused_sha256:
            return self.refused[self.refused_sha256.index(pulse)]
        return None


@dataclass(frozen=True)
class CalibrationFile(Parameters):
    """``W3_calibration.toml``: a table per machine, ``[machine.NAME]``."""

    machine: Mapping[str, CalibrationEntry] = param(default_factory=dict,
                                                    doc="calibration per machine")
    sources: Mapping[str, str] = sources_field()


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class InputHashes:
    """SHA-256 of what determines the calibrated forces: the validated mechanics (every
    value, no ``source`` texts), the validated hydraulics, and per pulse to calibrate its
    target, angle and edges with the track speed and initial force over the calibration
    run, the terrain and :data:`METHOD`."""

    mechanics: str
    hydraulics: str
    pulses: dict[int, str]

    @property
    def key(self) -> str:
        """One hash of all (the user cache's key)."""
        return _sha("".join([self.mechanics, self.hydraulics,
                             *(f"{i}:{h}" for i, h in sorted(self.pulses.items()))]))


def calibrated_indices(scenario: Scenario) -> tuple[int, ...]:
    """The load pulses that give no hitch_N (the ones calibrated for the machine)."""
    return tuple(i for i, p in enumerate(scenario.load_pulses) if p.hitch_N is None)


def input_hashes(scenario: Scenario, rig: Rig) -> InputHashes:
    """The :class:`InputHashes` of the pulses of ``scenario`` without hitch_N on the rig's
    machine."""
    pulses = {}
    for i in calibrated_indices(scenario):
        p = scenario.load_pulses[i]
        t = COUPLING_STEP_S * np.arange(round((START_S + p.rise_s + PLATEAU_S)
                                              / COUPLING_STEP_S))
        speed = np.ascontiguousarray(scenario.track_speed_m_s(t), dtype=np.float64)
        pulses[i] = _sha(repr((METHOD, p.delta_N, p.pull_angle_deg, p.rise_s,
                               float(scenario.reference_N(0.0)), repr(scenario.terrain),
                               hashlib.sha256(speed.tobytes()).hexdigest())))
    return InputHashes(_sha(repr(rig.params)), _sha(repr(rig.hydraulic_params)), pulses)


def committed_file(path: Path = CALIBRATION_FILE) -> CalibrationFile:
    """The committed calibration file (no table without the file)."""
    if not path.is_file():
        return CalibrationFile()
    return build(CalibrationFile, read_toml(path), file=path.name, require_source=True)


def committed_entries(path: Path = CALIBRATION_FILE) -> Mapping[str, CalibrationEntry]:
    """The committed calibration per machine name (empty without the file)."""
    return committed_file(path).machine


def _cache_path(machine: str, key: str) -> Path:
    return cache_dir() / f"{machine}-{key[:32]}-w3-hitch.json"


def _read_cache(path: Path) -> CalibrationEntry | None:
    """The cached calibration at ``path`` if it is complete and valid."""
    try:
        data = json.loads(path.read_text())
        return build(CalibrationEntry, data, file=path.name, require_source=False)
    except (OSError, ValueError, KeyError, TypeError):
        return None


_known: dict[str, HitchCalibration] = {}
"""Calibrations found or made in this process, by input hash."""


def calibrated_setup(setup: RunSetup) -> RunSetup:
    """``setup`` with the hitch forces of its scenario's pulses that give no hitch_N
    calibrated for its machine (unchanged without such pulses or if they are already for
    this machine and inputs): a committed entry's if one holds the pulse's inputs (any
    machine name), else the user cache's, else calibrated now (stderr says so, and why the
    machine's committed entry did not apply) and cached. ParameterError (one line) if a
    pulse is refused on the machine. :func:`trackmj.sim.run.run` and its schedule call it
    (not :func:`~trackmj.sim.setup.prepare`: the calibration's rig is a run built from the
    setup, and setup may not import what imports it)."""
    scenario = setup.scenario
    if not calibrated_indices(scenario):
        return setup
    hashes = input_hashes(scenario, Rig(setup))
    if (scenario.hitch_calibration is not None
            and scenario.hitch_calibration.inputs_sha256 == hashes.key):
        return setup
    cal = _known.get(hashes.key)
    if cal is None:
        cal = _find(scenario, Rig(setup), hashes)
        _known[hashes.key] = cal
    return dataclasses.replace(setup, scenario=dataclasses.replace(scenario,
                                                                   hitch_calibration=cal))


def _found(entries: list[CalibrationEntry],
           hashes: InputHashes) -> dict[int, Applied | str]:
    """Per pulse of ``hashes``: its force or refusal from the first entry holding it."""
    out: dict[int, Applied | str] = {}
    for i in hashes.pulses:
        for entry in entries:
            value = entry.lookup(hashes, i)
            if value is not None:
                out[i] = value
                break
    return out


def _calibration(scenario: Scenario, name: str, found: dict[int, Applied | str],
                 origin: str, key: str) -> HitchCalibration:
    """The :class:`HitchCalibration` of the forces ``found``; ParameterError with the first
    refusal among them. A target out of reach is said on stderr (once per process: the
    calibrations are kept by input hash)."""
    forces: list[float | None] = [None] * len(scenario.load_pulses)
    out_of_reach = []
    for i, value in sorted(found.items()):
        if isinstance(value, str):
            raise ParameterError(value)
        if value.out_of_reach:
            print(f"trackmj: {value.out_of_reach}", file=sys.stderr)
            out_of_reach.append(value.out_of_reach)
        forces[i] = value.hitch_N
    return HitchCalibration(name, tuple(forces), origin, key, tuple(out_of_reach))


def _find(scenario: Scenario, rig: Rig, hashes: InputHashes) -> HitchCalibration:
    name, key = rig.machine.name, hashes.key
    entries = committed_entries()
    found = _found(list(entries.values()), hashes)
    if len(found) == len(hashes.pulses):
        return _calibration(scenario, name, found, "committed", key)
    path = _cache_path(name, key)
    cached = _read_cache(path)
    found |= _found([] if cached is None else [cached], hashes)
    if len(found) == len(hashes.pulses):
        return _calibration(scenario, name, found, "cache", key)
    todo = tuple(i for i in hashes.pulses if i not in found)
    why = "no calibration for these inputs"
    own = entries.get(name)
    if own is not None:
        moved = [what for what, new, old in (
            ("mechanics", hashes.mechanics, own.mechanics_sha256),
            ("hydraulics", hashes.hydraulics, own.hydraulics_sha256)) if new != old]
        moved += [f"pulse {i}" for i in todo if hashes.pulses[i] not in
                  (*own.pulse_sha256, *own.refused_sha256)]
        why = (f"the committed one ({CALIBRATION_FILE.name} [machine.{name}]) is stale or "
               f"for other inputs ({', '.join(moved)} differ from this run's)")
    print(f"trackmj: {scenario.name} on machine {name}: {why}; calibrating the hitch forces "
          f"of load pulses {', '.join(map(str, todo))} (hold-mode tp runs) ...",
          file=sys.stderr)
    measured = calibrate(scenario, rig, todo, entries.get(REFERENCE_MACHINE))
    record = entry_record(scenario, measured, hashes)
    try:
        write_text_atomic(path, json.dumps(record))
    except OSError:          # a read-only home: calibrate each time rather than fail
        pass
    # the forces as recorded (to 0.1 N), looked up as a cached entry's, so a run is the same
    # whether it calibrated or read
    found |= _found([build(CalibrationEntry, record, file=path.name, require_source=False)],
                    hashes)
    return _calibration(scenario, name, found, "calibrated", key)


def entry_record(scenario: Scenario, measured: Measured,
                 hashes: InputHashes) -> dict[str, Any]:
    """A calibration as a :class:`CalibrationEntry`'s keys (the cache file's record and the
    committed table's rows)."""
    idx = sorted(measured.pulses)
    bad = sorted(measured.refused)
    nominal = scenario.nominal_tension_N or math.nan
    targets = [present(scenario.load_pulses[i].delta_N, "load_pulses.delta_N") for i in idx]
    return {"scenario": scenario.name, "pulse_index": idx,
            "pulse_sha256": [hashes.pulses[i] for i in idx],
            "delta_rel": [t / nominal for t in targets], "target_N": targets,
            "hitch_N": [round(measured.pulses[i].hitch_N, 1) for i in idx],
            "achieved_N": [round(measured.pulses[i].achieved_N, 1) for i in idx],
            "side_weight_N": round(measured.side_weight_N, 1),
            "drawbar_capacity_N": round(measured.drawbar_capacity_N, 1),
            "mechanics_sha256": hashes.mechanics, "hydraulics_sha256": hashes.hydraulics,
            "host": host_machine(), "wall_s": round(measured.wall_s, 1),
            "refused_index": bad, "refused_sha256": [hashes.pulses[i] for i in bad],
            "refused": [measured.refused[i] for i in bad],
            "out_of_reach_index": [i for i in idx if measured.pulses[i].out_of_reach],
            "out_of_reach": [measured.pulses[i].out_of_reach for i in idx
                             if measured.pulses[i].out_of_reach]}
