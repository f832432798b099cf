"""Synthetic signals and windows with known answers, for the metric tests (1 kHz grids)."""

from __future__ import annotations

import math

import numpy as np

from trackmj.results.metric_windows import MetricWindows
from trackmj.results.signals import cumulative_energy

DT = 1e-3
"""Sample period of the grids [s]."""


def time_grid(duration: float) -> np.ndarray:
    """t = 0, DT, ..., duration [s]."""
    return np.arange(round(duration / DT) + 1) * DT


def second_order_step(t: np.ndarray, zeta: float, wn: float) -> np.ndarray:
    """Unit step response of a 2nd-order system (damping ``zeta`` < 1, ``wn`` [rad/s])."""
    wd = wn * math.sqrt(1 - zeta**2)
    phi = math.acos(zeta)
    return 1 - np.exp(-zeta * wn * t) / math.sqrt(1 - zeta**2) * np.sin(wd * t + phi)


def contract_columns(t: np.ndarray) -> dict[str, np.ndarray]:
    """W1-like run: 12 -> 15 kN at 3 s, first-order response, no ramp."""
    ref = np.where(t >= 3.0, 15e3, 12e3)
    y = np.where(t >= 3.0, 15e3 - 3e3 * np.exp(-(t - 3.0) / 0.4), 12e3)
    y = y + np.where(t >= 10.0, 200.0 * np.sin(2 * np.pi * 10.0 * t), 0.0)
    mode = np.where((t >= 3.0) & (t < 4.0), 1, 0).astype(np.int8)
    power = np.where(mode == 1, 300.0, 0.0)
    return {"t_s": t, "tension_N": y, "tension_ref_N": ref, "p_head_Pa": y / 2.5e-3,
            "valve_mode": mode, "u": mode.astype(float),
            "e_supply_J": cumulative_energy(t, power), "p_work_J": 0.01 * t,
            "mech_work_J": 0.01 * t - 1e-3 * t, "chassis_acc_z_m_s2": np.sin(2 * np.pi * 10 * t)}


def windows(**changes: object) -> MetricWindows:
    """W1-like windows (tracking from 1 s, 2 Hz low-pass, 8-12 and 18-22 Hz bands) with
    ``changes``."""
    base = dict(force_min_N=10e3, force_max_N=20e3, evaluation_start_s=1.0,
                settle_band_rel=0.02, min_hold_s=0.5, lowpass_cutoff_Hz=2.0,
                body_mode_band_Hz=(8.0, 12.0), tooth_passing_band_Hz=(18.0, 22.0),
                psd_resolution_Hz=0.5, psd_max_Hz=50.0)
    return MetricWindows(**(base | changes))


def step_ripple_noise(t: np.ndarray, ripple_N: float, noise_N: float,
                      seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """12 -> 15 kN at 3 s with a first-order response (tau 0.4 s), plus a 20 Hz sine of
    amplitude ripple_N and white noise of std noise_N: (reference, slow error, tension)."""
    ref = np.where(t >= 3.0, 15e3, 12e3)
    slow = np.where(t >= 3.0, -3e3 * np.exp(-(t - 3.0) / 0.4), 0.0)
    rng = np.random.default_rng(seed)
    y = (ref + slow + ripple_N * np.sin(2 * np.pi * 20.0 * t)
         + rng.normal(0.0, noise_N, t.shape))
    return ref, slow, y


def columns(t: np.ndarray, y: np.ndarray, ref: np.ndarray) -> dict[str, np.ndarray]:
    """The contract columns of tension ``y`` and reference ``ref``, every other one zero."""
    zeros = np.zeros_like(t)
    return {"t_s": t, "tension_N": y, "tension_ref_N": ref, "p_head_Pa": y / 2.5e-3,
            "valve_mode": zeros, "u": zeros, "e_supply_J": zeros, "p_work_J": zeros,
            "mech_work_J": zeros, "chassis_acc_z_m_s2": zeros}
