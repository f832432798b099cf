"""Identification of the equivalent idler-carrier dynamics seen by the cylinders.

The reduced models (NMPC prediction, the ``dp-a`` architecture) replace the track by
M·ÿ = F_ten − k·(y − y0) − c·ẏ on the cylinder stroke y. :func:`identify_idler` finds
k, M and c from the MuJoCo track itself: it settles the track under a constant
tensioner force, steps the force, and fits the stroke response with a second-order
step response (least squares on the first ``fit_window_s`` seconds).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from trackmj.ports import ForceLaw


@dataclass(frozen=True)
class EquivalentIdler:
    """Equivalent mass-spring-damper on the stroke (SI).

    stiffness_N_m: k, static dF/dy; mass_kg: M = k/ω_n²; damping_N_s_m: c = 2ζ·sqrt(k·M);
    natural_frequency_Hz: ω_n/2π; damping_ratio: ζ; fit_r2: coefficient of determination of
    the step-response fit (1 = perfect); stroke_m: stroke at the lower force level.
    """

    stiffness_N_m: float
    mass_kg: float
    damping_N_s_m: float
    natural_frequency_Hz: float
    damping_ratio: float
    fit_r2: float
    stroke_m: float


class ConstantForce:
    """Tensioner element giving a constant force with optional implicit damping."""

    def __init__(self, force_N: float, damping_N_s_m: float) -> None:
        self.force_N = force_N
        self.damping_N_s_m = damping_N_s_m

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(self.force_N, -self.damping_N_s_m)

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Stateless."""


def second_order_step(t: np.ndarray, gain: float, omega_n: float, zeta: float) -> np.ndarray:
    """Unit-input step response of gain/(s²/ω² + 2ζs/ω + 1) for 0 < ζ < 1, t [s]."""
    wd = omega_n * math.sqrt(1.0 - zeta * zeta)
    decay = np.exp(-zeta * omega_n * t)
    return gain * (1.0 - decay * (np.cos(wd * t) + zeta * omega_n / wd * np.sin(wd * t)))


def fit_step_response(t: np.ndarray, dy: np.ndarray,
                      force_step_N: float) -> tuple[float, float, float, float]:
    """Fit dy(t) [m] after a force step [N] with a second-order response.

    Returns (stiffness k [N/m], ω_n [rad/s], ζ [-], R²). The static gain is the mean
    of the last 20 % of the record, so the record should reach steady state. The start
    values come from the textbook peak relations (overshoot → ζ, time to peak → ω_d).
    """
    steady = float(np.mean(dy[int(0.8 * len(dy)):]))
    if steady == 0.0 or not np.all(np.isfinite(dy)):
        raise ValueError("step response has no finite non-zero steady state")
    peak = int(np.argmax(dy / steady))
    overshoot = max(float(dy[peak] / steady) - 1.0, 1e-3)
    zeta0 = min(-math.log(overshoot) / math.hypot(math.pi, math.log(overshoot)), 0.95)
    omega0 = math.pi / max(float(t[peak]), 1e-3) / math.sqrt(1.0 - zeta0 * zeta0)

    def residual(x: np.ndarray) -> np.ndarray:
        return second_order_step(t, x[0], x[1], x[2]) - dy

    fit = least_squares(residual, x0=[steady, omega0, zeta0],
                        bounds=([steady * 0.5, 1.0, 0.01], [steady * 2.0, 1e4, 0.99]))
    gain, omega_n, zeta = fit.x
    ss_res = float(np.sum(fit.fun ** 2))
    ss_tot = float(np.sum((dy - dy.mean()) ** 2))
    return force_step_N / gain, float(omega_n), float(zeta), 1.0 - ss_res / ss_tot


def identify_idler(make_plant: Callable[[], object], force_low_N: float = 12_000.0,
                   force_high_N: float = 15_000.0, settle_s: float = 1.5,
                   record_s: float = 0.6) -> EquivalentIdler:
    """Identify the equivalent idler dynamics on a standing track (sprocket held).

    make_plant: returns a fresh ``TrackPlant`` (at its home keyframe).
    """
    plant = make_plant()
    element = ConstantForce(force_low_N, damping_N_s_m=2e4)
    plant.run(element, settle_s)
    element.damping_N_s_m = 0.0
    element.force_N = force_high_N
    start = plant.stroke_m
    strokes: list[float] = []
    plant.run(element, record_s, 0.0, lambda pl: strokes.append(pl.stroke_m))
    t = np.arange(1, len(strokes) + 1) * 1e-3
    dy = np.array(strokes) - start
    k, omega_n, zeta, r2 = fit_step_response(t, dy, force_high_N - force_low_N)
    mass = k / omega_n ** 2
    return EquivalentIdler(stiffness_N_m=k, mass_kg=mass,
                           damping_N_s_m=2.0 * zeta * math.sqrt(k * mass),
                           natural_frequency_Hz=omega_n / (2.0 * math.pi),
                           damping_ratio=zeta, fit_r2=r2, stroke_m=start)
