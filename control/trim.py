"""Integral trim of the MPC's reference: removes the mean offset the offset-free estimate
cannot see.

The estimators' disturbance state (the idler's free position y0) makes the MPCs offset-free
for a load that moves the idler's equilibrium (Pannocchia & Rawlings 2003). It does not see
an offset that comes from the loop's own nonlinearity: on a rough road the tension swings by
~1 kN RMS at the 8-12 Hz body mode, faster than the valves can act (20 ms delay, 30 ms
minimum hold), and the MPC's answers to that swing do not average to zero (measured on
LF1352's W2 road, seed 0: the estimate's cylinder force p_h·A_h − p_r·A_r 0.3-2 % below the
reference over 5 s windows while the mean command released, u = −0.2). The trim closes a slow
integral loop around the MPC on the same force, the one the MPC tracks:

    I_{j+1} = I_j + T·clip(dz(ē_j), −c, c)/T_i,   |I| <= I_max,   dz(e) = sign(e)·max(|e| − b, 0),

with ē the error r − F̂ low-passed over T_f (first order), r the reference the MPC is asked
to track now, F̂ = p̂_h·A_h − p̂_r·A_r of the period's mean estimate [N], T the controller
period and T_i the integral time [s]; the MPC tracks r + I over its horizon (governed
again, so the trim never leaves the band). The dead band b is the valves' resolution (the
tension one minimum-hold pulse moves): an offset below it is the valves' quantum, and a
trim chasing it set up a valve limit cycle (LF1352's W5 with 0.8 x pretension: 4-12
switches/s against 2, measured). Transients are the MPC's to remove: the clip c
bounds what a load pulse or a step's settling winds up to c·t/T_i (without it, T_i = 1 s,
LF1352's W1 step and W3's pulses wound the trim up by ~0.5 kN and the low-pass RMSE rose
15 %, measured). A gate that integrated only while |ē| < 2 % instead selected the low side
of a skewed error (M113's W1: ē +200 N on average, the trim driven to −190 N). The trim
integrates only while the reference preview is flat (a reference step or ramp is the MPC's
to follow) and while the trimmed reference is not saturated by the governor in the direction
it would grow (a supply that cannot reach the reference, W4's drop, does not wind it up).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

#: A preview whose values span less than this [N] counts as flat.
FLAT_PREVIEW_N = 1.0


class IntegralTrim:
    """Slow integral loop on the MPC's tracked force (see the module docstring).

    ``integral_time_s`` T_i [s] (> 0), ``limit_N`` I_max [N] (>= 0), ``dead_band_N`` b [N],
    ``clip_N`` c [N], ``filter_s`` T_f [s] (> 0), ``period_s`` T [s]. :meth:`trimmed` gives
    the preview to track, :meth:`update` integrates one period.
    """

    def __init__(self, integral_time_s: float, limit_N: float, dead_band_N: float,
                 clip_N: float, filter_s: float, period_s: float) -> None:
        self.gain = period_s / integral_time_s
        self.limit_N, self.dead_band_N, self.clip_N = limit_N, dead_band_N, clip_N
        self.filter_gain = period_s / (filter_s + period_s)
        self.trim_N = 0.0
        self.filtered_error_N = 0.0

    def trimmed(self, preview_N: NDArray[np.float64]) -> NDArray[np.float64]:
        """The preview (N+1,) [N] raised by the trim."""
        return preview_N + self.trim_N

    def update(self, preview_N: NDArray[np.float64], band_N: tuple[float, float],
               force_N: float) -> None:
        """Integrate one period: ``preview_N`` the untrimmed preview (N+1,) [N] the MPC is
        asked to track, ``band_N`` the governor's (lo, hi) [N], ``force_N`` the estimated
        cylinder force F̂ [N]."""
        reference = float(preview_N[0])
        error = reference - force_N
        self.filtered_error_N += self.filter_gain * (error - self.filtered_error_N)
        lo, hi = band_N
        # the governor already moves the reference: the supply, not an offset
        if float(np.ptp(preview_N)) > FLAT_PREVIEW_N or not lo <= reference <= hi:
            return
        excess = abs(self.filtered_error_N) - self.dead_band_N
        if excess <= 0.0:
            return
        step = self.gain * math.copysign(min(excess, self.clip_N), self.filtered_error_N)
        trimmed = reference + self.trim_N
        if (step > 0.0 and trimmed >= hi) or (step < 0.0 and trimmed <= lo):
            return
        self.trim_N = min(max(self.trim_N + step, -self.limit_N), self.limit_N)
