"""Sensors: 1 kHz samples of z = [p_head Pa, p_rod Pa, y m] with noise, bias and quantisation."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from trackmj.control.params import SensorParams


class Sensors:
    """Measurement model z = quantise(H X + bias + noise), H = [I3 0] on X = [p_h, p_r, y, v].

    Noise is Gaussian with the standard deviations of ``params`` drawn from a seeded
    ``numpy.random.Generator``; quantisation (step > 0) rounds to the nearest multiple.
    """

    def __init__(self, params: SensorParams, rng: np.random.Generator | int | None = 0) -> None:
        self.p = params
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.std = np.array(
            (params.pressure_noise_std_Pa, params.pressure_noise_std_Pa, params.stroke_noise_std_m)
        )
        self.bias = np.array(
            (params.pressure_bias_Pa, params.pressure_bias_Pa, params.stroke_bias_m)
        )
        self.quantum = np.array(
            (params.pressure_quantum_Pa, params.pressure_quantum_Pa, params.stroke_quantum_m)
        )

    @property
    def dt(self) -> float:
        """Sample period [s]."""
        return self.p.sample_period_s

    def measure(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Noisy sample z (3,) of the true state x (4,)."""
        z = x[:3] + self.bias + self.std * self.rng.standard_normal(3)
        q = self.quantum
        if q.any():
            z = np.where(q > 0.0, np.round(z / np.where(q > 0.0, q, 1.0)) * q, z)
        return z
