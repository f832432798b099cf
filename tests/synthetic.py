"""Synthetic runs with known signals, for the figure, report and compare tests.

A run follows the scenario's reference with a first-order lag (tau 0.4 s), plus a 20 Hz
ripple and an offset; every contract column is filled (NaN where an architecture has no such
quantity), the metrics are the standard set on the scenario's windows, and the run may
carry an ``energy_J`` table in the layout of the energy ledger.
"""

from __future__ import annotations

import math

import numpy as np

from trackmj.results.metrics import compute_metrics
from trackmj.results.signals import cumulative_energy
from trackmj.results.store import COLUMN_UNITS, Result, make_table, run_metadata
from trackmj.scenarios.load import load_scenario

PITCH_M = 0.075
AREA_HEAD_M2 = 2.5e-3


def energy_table(scale: float = 1.0, *, ideal: bool = False) -> dict:
    """An energy_J table [J] that closes: pump = circuit + relief, circuit = the sum of the
    other terms (stored_change negative: energy released from the accumulator)."""
    if ideal:
        return {"pump": math.nan, "circuit": 4e3 * scale, "mechanical": 4e3 * scale,
                "residual": 0.0, "circuit_is_ideal_actuator": True}
    sinks = {"throttling": {"main": 1.5e3 * scale, "V_L": 0.5e3 * scale, "V_R": 0.5e3 * scale},
             "leakage": 0.4e3 * scale, "friction": 0.3e3 * scale, "makeup": 0.0,
             "stored_change": -0.2e3 * scale, "mechanical": 0.5e3 * scale, "residual": 1.0}
    circuit = 3.5e3 * scale + 1.0
    return {"pump": circuit + 6e3 * scale, "circuit": circuit, "relief": 6e3 * scale} | sinks


def synthetic_result(scenario: str = "W1", architecture: str = "tp", *,
                     controller: str = "nmpc", seed: int = 0, variant: str = "nominal",
                     duration_s: float = 6.0, offset_N: float = 0.0, ripple_N: float = 600.0,
                     energy: dict | None = None, chassis: bool = True,
                     supply: bool = True) -> Result:
    """One synthetic run (see the module docstring); ``energy`` None: no energy_J table."""
    sc = load_scenario(scenario)
    t = np.arange(1, round(duration_s / 1e-3) + 1) * 1e-3
    ref = sc.reference_N(t)
    alpha = 1e-3 / 0.4
    lagged = np.empty_like(ref)
    state = ref[0]
    for k, r in enumerate(ref):          # first-order lag, tau 0.4 s
        state += alpha * (r - state)
        lagged[k] = state
    rng = np.random.default_rng(seed)
    tension = (lagged + offset_N + ripple_N * np.sin(2 * np.pi * 20.0 * t + seed)
               + rng.normal(0.0, 20.0, t.shape))
    mode = np.sign(np.round(np.diff(lagged, prepend=lagged[0]) * 1e3, 1)).astype(np.int8)
    power = np.where(mode > 0, 400.0, 50.0)
    nan = np.full_like(t, math.nan)
    cols = {"t_s": t, "tension_N": tension, "tension_ref_N": ref,
            "p_head_Pa": tension / AREA_HEAD_M2, "p_rod_Pa": np.full_like(t, 2e5),
            "p_supply_Pa": np.full_like(t, 12e6) if supply else nan,
            "stroke_m": 0.05 + tension / 9.4e6, "stroke_velocity_m_s": np.gradient(tension) / 9.4,
            "q_supply_m3_s": np.where(mode > 0, 1e-5, 0.0) if supply else nan,
            "valve_mode": mode, "u": mode * 0.3, "e_supply_J": cumulative_energy(t, power),
            "p_work_J": np.zeros_like(t), "mech_work_J": np.zeros_like(t),
            "chassis_acc_z_m_s2": 0.5 * np.sin(2 * np.pi * 10.0 * t) if chassis else nan,
            "closure_error_m": np.zeros_like(t)}
    meta = run_metadata(sc.name, architecture, controller, "ekf", seed, "synthetic host",
                        machine="lf1352", variant=variant, duration_s=duration_s)
    table = make_table(cols, COLUMN_UNITS, meta)
    metrics = compute_metrics(cols, sc.metric_windows(duration_s, link_pitch_m=PITCH_M),
                              control_period_s=0.01, wall_time_s=duration_s / 2.0)
    if energy is not None:
        metrics["energy_J"] = energy
    return Result(table, metrics)
