"""Calibration of W3's physical load pulses against the hold-mode idler load.

W3 asks for idler-load disturbances of +2 kN and −1.5 kN applied physically. trackmj applies
them as a load on the rear hitch along a chain inclined below the horizontal (a skidded log)
while the speed-servoed sprocket holds the track speed. The disturbance therefore enters
through the track as a sprocket drive/brake torque pulse plus a pitch load, not as a force
on the idler. A push (forward and up) makes the sprocket brake, so the top strand between
sprocket and idler becomes the tight side, and it unloads the rear: the idler load rises.
A tow (rearward and down) makes the sprocket drive harder, with the tight side in the bottom
strand on the ground, and it loads the rear so the rear road wheels rise against their springs
and the track path shortens: the idler load falls. Measured on this model in hold mode, a
pure horizontal tow at the traction limit (~13 kN) lowers the idler load by only ~1.0 kN;
the study's −1.5 kN needs the rear load that a chain at 30° below the horizontal adds.

The calibration runs the tp plant (track + hydraulic plugin) in hold mode with the valves
closed, once without a pulse and once per trial amplitude from the same deterministic
state, always with the study's supply (``fixed_relief``, with which the pulses were
calibrated): in hold the supply reaches the heads only through the closed valves' leakage,
but runs that differ by that leakage alone diverge after ~1.3 s, and the measured change of
the −1.5 kN pulse then moves by up to 40 % with the supply model (measured: fixed_relief
−1.52, compensated −1.26, prescribed −0.90 kN). It measures the mean difference of the idler
force F_ten between the two runs over the pulse's plateau, after a settling allowance. The
secant method then finds the hitch force that gives the target change. Subtracting the
reference run removes the hold-mode drift (leakage) and the chordal ripple, which are
identical in both runs until the pulse starts.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from trackmj.elements.hydraulic import HydraulicElement
from trackmj.hydraulics import HydraulicTensioner
from trackmj.ports import COUPLING_STEP_S, StepInputs
from trackmj.scenarios.resolved import Scenario
from trackmj.scenarios.schema import LoadPulse, Supply
from trackmj.sim.architectures import assemble
from trackmj.sim.setup import prepare
from trackmj.track.plant import TrackPlant

START_S = 3.0
"""Pulse onset in the calibration runs [s], after the 1 s speed ramp has settled."""
SETTLE_ALLOWANCE_S = 0.5
"""Time after the pulse's rise excluded from the mean [s] (about three chassis heave periods)."""
RIG_SUPPLY_MODEL = "fixed_relief"
"""Supply model of the calibration rig (the pulses were calibrated with it; see above)."""


def hold_mode_run(scenario: Scenario) -> tuple[TrackPlant, HydraulicTensioner]:
    """The tp track of ``scenario`` (nominal variant, seed 0) settled at its initial
    reference, with the hydraulic plugin in hold mode and the study's supply: the open-loop
    calibration rig."""
    rig = dataclasses.replace(scenario, supply=Supply(model=RIG_SUPPLY_MODEL))
    asm = assemble(prepare(rig))
    if asm.track is None or not isinstance(asm.element, HydraulicElement):
        raise TypeError("the calibration rig needs the MuJoCo track and the hydraulic plugin "
                        f"(the tp architecture); got {type(asm.element).__name__} on "
                        f"{'no track' if asm.track is None else 'the track'}")
    return asm.track, asm.element.tensioner


def idler_force_history(scenario: Scenario, pulse: LoadPulse) -> np.ndarray:
    """F_ten [N] at 1 kHz of a hold-mode tp run of ``scenario`` (its speed profile, nominal
    variant) with the one hitch ``pulse``, until the pulse ends; shape (steps,)."""
    plant, tensioner = hold_mode_run(scenario)
    pulsed = dataclasses.replace(scenario, load_pulses=(pulse,))
    steps = round(pulse.end_s / COUPLING_STEP_S)
    t = COUPLING_STEP_S * np.arange(steps)
    speed = pulsed.track_speed_m_s(t)
    pull, down = pulsed.hitch_force_N(t)
    force = np.empty(steps)
    for k in range(steps):
        plant.apply(StepInputs(float(speed[k]), float(pull[k]), float(down[k]), math.nan))
        plant.step(tensioner)
        force[k] = plant.idler_force_N
    return force


def calibration_pulse(hitch_N: float, pull_angle_deg: float, rise_s: float,
                      plateau_s: float) -> LoadPulse:
    """A pulse from START_S with the given hitch force [N], angle [deg], edges [s] and
    plateau [s] (target change left at 0)."""
    return LoadPulse(start_s=START_S, end_s=START_S + rise_s + plateau_s, delta_N=0.0,
                     hitch_N=hitch_N, pull_angle_deg=pull_angle_deg, rise_s=rise_s)


def load_change_N(scenario: Scenario, hitch_N: float, pull_angle_deg: float, *,
                  plateau_s: float = 2.0, rise_s: float = 0.1,
                  reference: np.ndarray | None = None) -> float:
    """Mean change [N] of the hold-mode idler load that a hitch pulse causes, measured
    against a pulse-free run (pass ``reference``, the history with hitch_N = 0, to reuse
    it) over the plateau after SETTLE_ALLOWANCE_S."""
    if reference is None:
        reference = idler_force_history(
            scenario, calibration_pulse(0.0, pull_angle_deg, rise_s, plateau_s))
    pulsed = idler_force_history(
        scenario, calibration_pulse(hitch_N, pull_angle_deg, rise_s, plateau_s))
    first = round((START_S + rise_s + SETTLE_ALLOWANCE_S) / COUPLING_STEP_S)
    return float(np.mean(pulsed[first:] - reference[first:]))


def calibrate_hitch(scenario: Scenario, target_N: float, pull_angle_deg: float, *,
                    plateau_s: float = 2.0, rise_s: float = 0.1, rel_tol: float = 0.02,
                    max_iter: int = 8) -> tuple[float, float]:
    """Hitch force [N] along ``pull_angle_deg`` whose hold-mode idler-load change is
    ``target_N`` [N] within ``rel_tol``; returns (hitch_N, achieved change [N]). Secant
    from linear first guesses."""
    if not (math.isfinite(target_N) and target_N != 0.0):
        raise ValueError(f"target_N = {target_N!r}: must be finite and non-zero")
    reference = idler_force_history(
        scenario, calibration_pulse(0.0, pull_angle_deg, rise_s, plateau_s))

    def change(f: float) -> float:
        return load_change_N(scenario, f, pull_angle_deg, plateau_s=plateau_s,
                             rise_s=rise_s, reference=reference)

    # first guesses (measured at 30°): a push raises the idler load ~0.6 N/N, a tow
    # lowers it ~0.23 N/N
    f0 = -target_N / 0.6 if target_N > 0 else -target_N / 0.23
    f1 = 1.2 * f0
    d0, d1 = change(f0), change(f1)
    for _ in range(max_iter):
        if abs(d1 - target_N) <= rel_tol * abs(target_N) or d1 == d0:
            break
        f0, f1 = f1, f1 + (target_N - d1) * (f1 - f0) / (d1 - d0)
        d0, d1 = d1, change(f1)
    return f1, d1
