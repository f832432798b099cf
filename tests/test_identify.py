"""Identification of the equivalent idler dynamics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackmj.identify import ConstantForce, fit_step_response, identify_idler
from trackmj.plant import TrackPlant


def test_fit_recovers_a_known_second_order_system() -> None:
    k, m, c = 2.0e6, 150.0, 6.0e3
    wn = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = wn * math.sqrt(1 - zeta ** 2)
    t = np.arange(1, 601) * 1e-3
    step = 3_000.0
    dy = step / k * (1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd
                                                    * np.sin(wd * t)))
    k_fit, wn_fit, zeta_fit, r2 = fit_step_response(t, dy, step)
    assert k_fit == pytest.approx(k, rel=1e-3)
    assert wn_fit == pytest.approx(wn, rel=1e-3)
    assert zeta_fit == pytest.approx(zeta, rel=1e-3)
    assert r2 > 0.999


def _settled_stroke(force_N: float) -> float:
    plant = TrackPlant.load()
    element = ConstantForce(force_N, damping_N_s_m=2e4)
    plant.run(element, 2.0)
    samples: list[float] = []
    plant.run(element, 0.3, 0.0, lambda pl: samples.append(pl.stroke_m))
    return float(np.mean(samples))


def test_identified_stiffness_matches_static_force_balance() -> None:
    """k from the step fit equals ΔF/Δs between two independently settled force levels."""
    idler = identify_idler(TrackPlant.load)
    strokes = [_settled_stroke(force) for force in (12_000.0, 15_000.0)]
    static_k = 3_000.0 / (strokes[1] - strokes[0])
    assert idler.stiffness_N_m == pytest.approx(static_k, rel=0.10)
    assert idler.mass_kg > 80.0   # at least the idler and its carrier move
    assert idler.damping_N_s_m > 0.0
