"""Valve logic: minimum holding time never violated, delay bookkeeping, sum-up rounding."""

import dataclasses
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackmj.control.params import ValveParams
from trackmj.control.valves import ValveLogic
from trackmj.sim.control_plant import packaged_control


def _run_lengths(modes: list[int]) -> list[int]:
    """Lengths of the runs of equal modes, without the first and the last (open) run."""
    switches = [i for i in range(1, len(modes)) if modes[i] != modes[i - 1]]
    return [b - a for a, b in itertools.pairwise(switches)]


@settings(max_examples=200, deadline=None)
@given(
    commands=st.lists(st.floats(-1.5, 1.5, allow_nan=False), min_size=1, max_size=60),
    repeat=st.integers(1, 12),
    min_hold_ms=st.integers(25, 30),
    delay_ms=st.integers(0, 25),
    sigma_delta=st.booleans(),
    dead_zone=st.floats(0.0, 0.3),
)
def test_min_holding_time_never_violated(
    commands: list[float],
    repeat: int,
    min_hold_ms: int,
    delay_ms: int,
    sigma_delta: bool,
    dead_zone: float,
) -> None:
    dt = 1e-3
    vl = ValveLogic(
        ValveParams(
            dead_zone=dead_zone,
            min_hold_s=min_hold_ms * 1e-3,
            solenoid_delay_s=delay_ms * 1e-3,
            sigma_delta=sigma_delta,
        ),
        dt,
    )
    applied, commanded = [], []
    for u in commands:
        for _ in range(repeat):  # controller command held for `repeat` plant steps
            applied.append(vl.step(u))
            commanded.append(vl.mode)
    for modes in (applied, commanded):
        runs = _run_lengths(modes)
        assert all(r >= min_hold_ms for r in runs), (runs, min_hold_ms)
        assert set(modes) <= {-1, 0, 1}
    # delay bookkeeping: applied = commanded shifted by the delay, starting in hold
    assert applied[delay_ms:] == commanded[: max(0, len(commanded) - delay_ms)]
    assert all(m == 0 for m in applied[:delay_ms])


@pytest.mark.parametrize("u", [0.07, 0.2, 0.37, -0.55, 0.9])
def test_sum_up_rounding_average_follows_u(u: float) -> None:
    vl = ValveLogic(ValveParams(dead_zone=0.05, min_hold_s=0.03, solenoid_delay_s=0.02,
                                sigma_delta=True), 1e-3)
    modes = np.array([vl.step(u) for _ in range(3000)])
    assert abs(modes[20:].mean() - u) < 0.02
    assert vl.switches < 3000 / 30 + 1


def test_threshold_mode_and_dead_zone() -> None:
    vl = ValveLogic(ValveParams(dead_zone=0.1, min_hold_s=0.03, solenoid_delay_s=0.0,
                                sigma_delta=False), 1e-3)
    assert [vl.step(0.05) for _ in range(40)] == [0] * 40
    assert vl.step(0.5) == 1
    assert vl.step(-0.5) == 1  # still inside the minimum holding time
    seq = [vl.step(-0.5) for _ in range(40)]
    assert seq[27] == 1 and seq[28] == -1  # 30 steps after the switch


def test_invalid_parameters_named() -> None:
    valves = packaged_control().valves
    with pytest.raises(ValueError, match=r"ValveParams\.min_hold_s = -0\.01 is outside the "
                       r"allowed range \[0, 1\] s"):
        dataclasses.replace(valves, min_hold_s=-0.01)
    with pytest.raises(ValueError, match="dt"):
        ValveLogic(valves, 0.0)
