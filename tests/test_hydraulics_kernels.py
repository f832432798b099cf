"""The compiled hydraulic kernels compute what their Python source says.

One scenario drives the plugin through strong, weak and multi-rate steps that enter the
cavitation limiter, the make-up band with line-search halvings, the relief valve, both end
stops and every supply model: the variable pump's displacement at both limits and in
between, and the unloading valve's cut-out and cut-in. It runs here with the numba-compiled
kernels and in a subprocess with NUMBA_DISABLE_JIT=1, where the same source executes as plain
Python; both must give the same force laws, pressures, flows and ledgers.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from trackmj.hydraulics import HydraulicTensioner, PressureProfile, load_hydraulic_params
from trackmj.hydraulics import kernels as k

_P = load_hydraulic_params()
STIFF = dataclasses.replace(_P, cylinder=dataclasses.replace(_P.cylinder,
                                                             dead_volume_head_m3=1.5e-4))
SMALL_ACCUMULATOR = dataclasses.replace(_P, accumulator=dataclasses.replace(
    _P.accumulator, gas_volume_m3=2e-5))  # charges and drains within the scenario
DROP = PressureProfile((0.0, 0.05, 0.06, 0.15, 0.16), (12e6, 12e6, 9e6, 9e6, 12e6))
ROWS = np.load(Path(__file__).parent / "data" / "hold_failure_trajectory.npy")


def _sample(ht: HydraulicTensioner, law) -> list[float]:
    rec = ht.record
    return [law.force_N, law.damping_N_s_m, *ht.pressures, *rec.flows_m3_s.values(),
            *ht.ledger.terms.tolist(), float(rec.newton_iterations),
            float(ht.newton_backtracks_total), ht.pump_displacement, float(ht.pump_loaded)]


def _ride(coupling: str, steps: int) -> list[list[float]]:
    """Kinematic stroke 0.05 + 0.056·sin(πt) m, 12 MPa supply, pressurize and release in
    turns every 0.5 s: the end stops from 0.35 s, make-up flow, a line search at 0.53 s,
    the cavitation limiter from 0.82 s."""
    ht = HydraulicTensioner(coupling=coupling, supply_profile=lambda t: 12e6)
    h, out = 1e-3, []
    for i in range(steps):
        if i % 500 == 0:
            ht.set_mode(1 if i % 1000 == 0 else -1)
        t0, t1 = i * h, (i + 1) * h
        law = ht.force_law(t0, 0.05 + 0.056 * math.sin(math.pi * t0),
                           0.056 * math.pi * math.cos(math.pi * t0))
        ht.complete_step(t1, 0.05 + 0.056 * math.sin(math.pi * t1),
                         0.056 * math.pi * math.cos(math.pi * t1))
        out.append(_sample(ht, law))
    return out


def scenario() -> list[list[float]]:
    """Per step: force law, pressures, flows, cumulative ledger, iteration counts."""
    # release against a 1 MPa supply on the recorded trajectory: make-up band and line
    # search (see test_hydraulics_robustness); the accumulator supply above the relief
    # crack pressure
    ht = HydraulicTensioner(STIFF, stroke_m=ROWS[250, 1], head_pressure_Pa=4757806.780200539,
                            supply_profile=lambda t: 1e6)
    ht.set_mode(-1)
    out = []
    for i in range(250, 420):
        law = ht.force_law(*ROWS[i])
        ht.complete_step(*ROWS[i + 1])
        out.append(_sample(ht, law))
    ht = HydraulicTensioner(supply_model="fixed_relief", supply_pressure_Pa=12.5e6)
    ht.set_command(0.0, 1.0, 0.6)
    for i in range(100):
        law = ht.force_law(i * 1e-3, 0.05, 0.0)
        ht.complete_step((i + 1) * 1e-3, 0.05, 0.0)
        out.append(_sample(ht, law))
    # variable pump: set-point 12 -> 9 -> 12 MPa (displacement 0, then 1) while pressurizing
    out += _extend(HydraulicTensioner(supply_model="compensated", setpoint_Pa=DROP), 250)
    # unloading valve: charges to the cut-out, drains to the cut-in while pressurizing
    out += _extend(HydraulicTensioner(SMALL_ACCUMULATOR, supply_model="unloading",
                                      supply_pressure_Pa=10.3e6, coupling="weak"), 600)
    return out + _ride("strong", 900) + _ride("weak", 900) + _ride("multirate", 400)


def _extend(ht: HydraulicTensioner, steps: int) -> list[list[float]]:
    """Pressurize while the stroke extends at 2 mm/s (a draw of ~5e-6 m^3/s)."""
    ht.set_mode(1)
    out = []
    for i in range(steps):
        law = ht.force_law(i * 1e-3, 0.05 + 2e-6 * i, 2e-3)
        ht.complete_step((i + 1) * 1e-3, 0.05 + 2e-6 * (i + 1), 2e-3)
        out.append(_sample(ht, law))
    return out


@pytest.mark.slow
def test_compiled_kernels_match_their_python_source() -> None:
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    proc = subprocess.run([sys.executable, __file__], env=env, capture_output=True, text=True,
                          check=True, timeout=300)
    python = np.array(json.loads(proc.stdout))
    compiled = np.array(scenario())
    assert python.shape == compiled.shape
    scale = np.maximum(np.abs(python).max(axis=0), 1e-30)
    worst = (np.abs(compiled - python) / scale).max()
    print(f"compiled vs Python source: worst difference {worst:.2e} of each column's scale")
    assert worst <= 1e-12
    # the scenario did reach the branches it is meant to cover
    end = 20 + k.N_LEDGER   # _sample's columns: law 2, pressures 5, flows 13, ledger, 4 more
    ledgers = compiled[:, 20:end]
    assert compiled[:, end + 1].max() > 0  # line-search halvings
    assert np.abs(compiled[:, 14:17]).max() > 0.0  # make-up flows
    assert np.abs(ledgers[:, k.L_ENDSTOP]).max() > 0.0 and ledgers[:, k.L_RELIEF].max() > 0.0
    assert compiled[:, 2:6].min() < _P.cavitation.floor_Pa + _P.cavitation.band_Pa  # limiter
    displacement, loaded = compiled[:, end + 2], compiled[:, end + 3]
    # destroking after the drop (target clipped at 0), stroking up after the restore (target
    # clipped at 1, 3 MPa below the setting); the standby displacement is 0.05
    assert displacement.min() < 0.01 and displacement.max() > 0.5
    assert np.any(np.diff(loaded) < 0) and np.any(np.diff(loaded) > 0)  # cut-out and cut-in


if __name__ == "__main__":
    if os.environ.get("NUMBA_DISABLE_JIT") != "1":
        pytest.fail("run with NUMBA_DISABLE_JIT=1")
    json.dump(scenario(), sys.stdout)
