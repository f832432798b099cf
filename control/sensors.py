"""Sensors: 1 kHz samples of z = [p_head Pa, p_rod Pa, y m] with noise, bias and quantisation,
and of the sprocket drive torque [N·m] with noise."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from trackmj.control.params import SensorParams


class Sensors:
    """Measurement model z = quantise(H X + bias + noise), H = [I3 0] on X = [p_h, p_r, y, v],
    and, when given, the drive torque T + noise (NaN stays NaN).

    Noise is Gaussian with the standard deviations of ``params`` drawn from a seeded
    ``numpy.random.Generator``; quantisation (step > 0) rounds to the nearest multiple.
    ``block`` samples' noise is drawn at a time: the same numbers in the same order as one
    draw per sample, so use block > 1 only when nothing else draws from ``rng``. The torque's
    noise comes from a stream spawned from ``rng`` (so the first three channels draw the
    same numbers with or without a torque).
    """

    def __init__(
        self, params: SensorParams, rng: np.random.Generator | int | None = 0, block: int = 1
    ) -> None:
        if block < 1:
            raise ValueError(f"block = {block} must be >= 1")
        self.p = params
        self.block = block
        self._noise: list[list[float]] = []
        self._next = 0
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
        self._bias = tuple(self.bias.tolist())
        self._std = tuple(self.std.tolist())
        self._quanta = tuple((i, q) for i, q in enumerate(self.quantum.tolist()) if q > 0.0)
        self._torque_std = params.drive_torque_noise_std_N_m
        self._torque_rng = self.rng.spawn(1)[0]
        self._torque_noise: list[float] = []
        self._torque_next = 0

    @property
    def dt(self) -> float:
        """Sample period [s]."""
        return self.p.sample_period_s

    def measure(self, x: Sequence[float] | NDArray[np.float64],
                drive_torque_N_m: float | None = None) -> NDArray[np.float64]:
        """Noisy sample z of the true values: (3,) from x's first three entries (p_head,
        p_rod, y), (4,) with the drive torque [N·m] when it is given. Python scalars per
        channel (cheaper than small-array numpy at 1 kHz)."""
        i = self._next
        if i == len(self._noise):
            self._noise = self.rng.standard_normal((self.block, 3)).tolist()
            i = 0
        self._next = i + 1
        n0, n1, n2 = self._noise[i]
        (b0, b1, b2), (s0, s1, s2) = self._bias, self._std
        z = [x[0] + b0 + s0 * n0, x[1] + b1 + s1 * n1, x[2] + b2 + s2 * n2]
        if self._quanta:
            for i, q in self._quanta:
                z[i] = round(z[i] / q) * q  # half to even, like np.round
        if drive_torque_N_m is not None:
            z.append(drive_torque_N_m + self._torque_std * self._next_torque_noise())
        return np.array(z)

    def _next_torque_noise(self) -> float:
        """The next standard normal of the torque's own stream (drawn 1000 at a time)."""
        i = self._torque_next
        if i == len(self._torque_noise):
            self._torque_noise = self._torque_rng.standard_normal(1000).tolist()
            i = 0
        self._torque_next = i + 1
        return self._torque_noise[i]
