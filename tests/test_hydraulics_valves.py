"""The compiled valve kernels (solenoids, edge areas, orifice gains, loss shares) compute
what the Python code they replaced computed, bit for bit.

The reference below is that Python code: a solenoid with a deque of pending commands, the
areas from ``components.valve_area`` / ``series_area``, the gains from ``orifice_gain``
and the loss share ``(A_eff/A_valve) ** 2``. Random commands (V_L and V_R alike, then
apart; bursts that outgrow the ring buffer) drive both, with the step length jittering as
a plant's accumulated clock makes it.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.hydraulics import kernels as k
from trackmj.hydraulics.components import Solenoid, orifice_gain, series_area, valve_area


class _RefSolenoid:
    def __init__(self, valve) -> None:
        self.delay, self.tau = valve.delay_s, valve.time_constant_s
        self.position = self.command = self.effective = 0.0
        self.moving = False
        self.pending: deque[tuple[float, float]] = deque()

    def set(self, t: float, c: float) -> None:
        if c != self.command:
            self.command = c
            self.pending.append((t + self.delay, c))
            self.moving = True

    def at(self, t: float, h: float) -> tuple[float, float]:
        eff = self.effective
        if not self.moving:
            return eff, eff
        for t_on, c in self.pending:
            if t_on <= t + h + 1e-12:
                eff = c
            else:
                break
        return eff + (self.position - eff) * math.exp(-h / self.tau), eff

    def advance(self, t: float, h: float) -> None:
        self.position, self.effective = self.at(t, h)
        while self.pending and self.pending[0][0] <= t + h + 1e-12:
            self.pending.popleft()
        if abs(self.position - self.effective) < 1e-9:
            self.position = self.effective
        self.moving = bool(self.pending) or self.position != self.effective


def _share(valve: float, series: float) -> float:
    return 1.0 if valve <= 0.0 or series <= 0.0 else (series / valve) ** 2


def _ref_gains(prm, sols: list[_RefSolenoid], t: float, h: float) -> list[float]:
    mv, sv, met = prm.main_valve, prm.switching_valves, prm.metering
    xm = sols[0].at(t, h)[0]
    a_rest, a_ener = valve_area(1.0 - xm, mv), valve_area(xm, mv)
    a_l, a_r = valve_area(sols[1].at(t, h)[0], sv), valve_area(sols[2].at(t, h)[0], sv)
    a_pb = series_area(a_ener, met.rod_feed_area_m2)
    a_vl = series_area(a_l, met.head_branch_area_m2)
    a_vr = series_area(a_r, met.head_branch_area_m2)
    cq, rho = prm.orifice.discharge_coefficient, prm.fluid.density_kg_m3
    g = [orifice_gain(cq, a, rho) for a in (a_rest, a_ener, a_pb, a_rest, a_vl, a_vr)]
    return [*g, _share(a_ener, a_pb), _share(a_l, a_vl), _share(a_r, a_vr)]


def test_valve_kernels_equal_the_python_reference() -> None:
    prm = load_hydraulic_params()
    ht = HydraulicTensioner(prm)
    ref = [_RefSolenoid(prm.main_valve), _RefSolenoid(prm.switching_valves),
           _RefSolenoid(prm.switching_valves)]
    rng = np.random.default_rng(7)
    t, moved, apart = 0.0, 0, False
    for step in range(6000):
        if step == 3000:
            apart = True          # from here V_L and V_R get their own commands
        burst = 500 <= step % 997 < 540   # a new command every step for 40 steps
        if burst or rng.random() < 0.04:
            main, v_l = float(rng.integers(0, 2)), float(rng.uniform(0.0, 1.0))
            v_r = float(rng.uniform(0.0, 1.0)) if apart else v_l
            ht.t = t
            ht.set_command(main, v_l, v_r)
            for sol, c in zip(ref, (main, v_l, v_r), strict=True):
                sol.set(t, c)
        h = 1e-3
        t1 = t + h                # the plant's accumulated clock: t1 - t is not exactly h
        ht._set_gains(t, h)
        expected = _ref_gains(prm, ref, t, h)
        assert ht._state[k.GAIN:k.FRAC + 3].tolist() == expected, step
        ht._advance_valves(t, t1 - t)
        for sol in ref:
            sol.advance(t, t1 - t)
        got = [(s.position, s.effective, s.moving) for s in (ht.main, ht.vl, ht.vr)]
        assert got == [(s.position, s.effective, s.moving) for s in ref], step
        moved += any(s.moving for s in ref)
        t = t1
    assert moved > 3000 and ht.main.bank.pend.shape[1] > 8   # moving; the ring grew


def test_a_solenoid_on_its_own() -> None:
    prm = load_hydraulic_params()
    sol, ref = Solenoid(prm.switching_valves), _RefSolenoid(prm.switching_valves)
    for i in range(200):
        if i in (0, 3, 90):
            sol.set(i * 1e-3, 1.0 - sol.command)
            ref.set(i * 1e-3, 1.0 - ref.command)
        assert sol.position_at(i * 1e-3, 1e-3) == ref.at(i * 1e-3, 1e-3)
        sol.advance(i * 1e-3, 1e-3)
        ref.advance(i * 1e-3, 1e-3)
        assert (sol.position, sol.effective, sol.moving) == (ref.position, ref.effective,
                                                             ref.moving)
