"""Scalar component laws of the tensioning circuit (pure Python floats, SI, gauge Pa).

Flow sign convention: a branch flow Q [m^3/s] is positive from its first node ``a`` to its
second node ``b``; Δp = p_a − p_b [Pa].
"""

from __future__ import annotations

import math
from collections import deque

from .params import Accumulator, Valve

SQRT2 = math.sqrt(2.0)
_ARRIVED = 1e-9  # a solenoid this close to its command [normalised travel] has arrived


def orifice_gain(cq: float, area_m2: float, density_kg_m3: float) -> float:
    """Turbulent gain K = Cq·A·sqrt(2/ρ) [m^3/s/sqrt(Pa)]."""
    return cq * area_m2 * SQRT2 / math.sqrt(density_kg_m3)


def series_area(a1_m2: float, a2_m2: float) -> float:
    """Equivalent area [m^2] of two turbulent orifices in series: (a1^-2 + a2^-2)^-1/2."""
    if a1_m2 <= 0.0 or a2_m2 <= 0.0:
        return 0.0
    return a1_m2 * a2_m2 / math.sqrt(a1_m2 * a1_m2 + a2_m2 * a2_m2)


def orifice_flow(dp_Pa: float, gain: float, p_cr_Pa: float) -> tuple[float, float]:
    """Regularised orifice Q = K·Δp/(Δp²+p_cr²)^(1/4) and dQ/dΔp [m^3/s, m^3/(s·Pa)].

    Tends to K·sign(Δp)·sqrt|Δp| for |Δp| >> p_cr and is linear (K/sqrt(p_cr)) near 0.
    """
    r = dp_Pa * dp_Pa + p_cr_Pa * p_cr_Pa
    r4 = math.sqrt(math.sqrt(r))
    return gain * dp_Pa / r4, gain * (0.5 * dp_Pa * dp_Pa + p_cr_Pa * p_cr_Pa) / (r * r4)


def smoothstep(x: float) -> tuple[float, float]:
    """C1 step s(x) = 3x²−2x³ clamped to [0, 1], and ds/dx."""
    if x <= 0.0:
        return 0.0, 0.0
    if x >= 1.0:
        return 1.0, 0.0
    return x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x)


def valve_area(position: float, valve: Valve) -> float:
    """Opening area [m^2] of a valve edge at normalised position (0 closed, 1 open).

    Linear from the leak area at ``overlap`` to the open area at 1 (positive overlap).
    """
    u = (position - valve.overlap) / (1.0 - valve.overlap)
    u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
    return valve.leak_area_m2 + (valve.open_area_m2 - valve.leak_area_m2) * u


def friction_force(v_m_s: float, coulomb_N: float, v_s_m_s: float,
                   viscous_N_s_m: float) -> tuple[float, float]:
    """Cylinder friction F_f = F_c·tanh(v/v_s) + b·v [N] (opposes motion) and dF_f/dv."""
    th = math.tanh(v_m_s / v_s_m_s)
    return coulomb_N * th + viscous_N_s_m * v_m_s, coulomb_N * (1.0 - th * th) / v_s_m_s \
        + viscous_N_s_m


def endstop_force(s_m: float, v_m_s: float, stroke_max_m: float, k_N_m: float,
                  c_N_s_m: float) -> tuple[float, float, float]:
    """End-stop force [N] (> 0 pushes outward), dF/ds and dF/dv; zero inside [0, stroke_max]."""
    if s_m < 0.0:
        return -k_N_m * s_m - c_N_s_m * v_m_s, -k_N_m, -c_N_s_m
    if s_m > stroke_max_m:
        return -k_N_m * (s_m - stroke_max_m) - c_N_s_m * v_m_s, -k_N_m, -c_N_s_m
    return 0.0, 0.0, 0.0


class GasAccumulator:
    """Polytropic gas accumulator: p_abs·V_gas^n = const above precharge, empty below.

    Oil volume V_oil(p) = V0 − V_gas(p) [m^3] for p above precharge (gauge Pa), else 0.
    Energy (gauge basis) E(p) = (p_abs·V_gas − p0_abs·V0)/(n−1) − p_atm·V_oil [J], zero at
    precharge, so that dE = p·dV_oil with p gauge.
    """

    __slots__ = ("_inv_n", "n", "p0", "p0_abs", "p_atm", "v0")

    def __init__(self, acc: Accumulator) -> None:
        self.v0 = acc.gas_volume_m3
        self.p0 = acc.precharge_Pa
        self.p_atm = acc.atmospheric_pressure_Pa_abs
        self.p0_abs = acc.precharge_Pa + acc.atmospheric_pressure_Pa_abs
        self.n = acc.polytropic_exponent
        self._inv_n = 1.0 / acc.polytropic_exponent

    def oil_volume(self, p_Pa: float) -> tuple[float, float]:
        """Oil volume in the accumulator [m^3] and dV_oil/dp [m^3/Pa] at gauge pressure p."""
        if p_Pa <= self.p0:
            return 0.0, 0.0
        p_abs = p_Pa + self.p_atm
        vg = self.v0 * (self.p0_abs / p_abs) ** self._inv_n
        return self.v0 - vg, vg * self._inv_n / p_abs

    def gas_volume(self, p_Pa: float) -> float:
        """Gas volume [m^3] at gauge pressure p."""
        return self.v0 - self.oil_volume(p_Pa)[0]

    def energy(self, p_Pa: float, v_oil_m3: float | None = None) -> float:
        """Stored energy [J] relative to the precharged, empty state (gauge basis); pass
        ``v_oil_m3 = oil_volume(p_Pa)[0]`` when already known."""
        if p_Pa <= self.p0:
            return 0.0
        v_oil = self.oil_volume(p_Pa)[0] if v_oil_m3 is None else v_oil_m3
        p_abs = p_Pa + self.p_atm
        return ((p_abs * (self.v0 - v_oil) - self.p0_abs * self.v0) / (self.n - 1.0)
                - self.p_atm * v_oil)


class Solenoid:
    """Valve actuator: pure electromagnetic delay then first-order opening.

    Command c ∈ [0, 1] set at time t takes effect at t + delay; the position x ∈ [0, 1]
    then follows dx/dt = (c − x)/τ, integrated exactly over each step with the command
    in force at the step end; within 1e-9 of the command the position snaps to it.
    ``moving`` is False only at rest (no pending command, position equal to the command in
    force), when stepping cannot change the position.
    """

    __slots__ = ("_pending", "command", "delay", "effective", "moving", "position", "tau")

    def __init__(self, valve: Valve, position: float = 0.0) -> None:
        self.delay = valve.delay_s
        self.tau = valve.time_constant_s
        self.position = position
        self.command = position
        self.effective = position
        self.moving = False
        self._pending: deque[tuple[float, float]] = deque()

    def set(self, t_s: float, command: float) -> None:
        """Request command [0..1] at time t_s [s]."""
        if not 0.0 <= command <= 1.0:
            raise ValueError(f"valve command = {command!r} is outside [0, 1]")
        if command != self.command:
            self.command = command
            self._pending.append((t_s + self.delay, command))
            self.moving = True

    def position_at(self, t_s: float, h_s: float) -> tuple[float, float]:
        """(position, effective command) at t_s + h_s without committing."""
        eff = self.effective
        if not self.moving:
            return eff, eff
        t_end = t_s + h_s
        for t_on, c in self._pending:
            if t_on <= t_end + 1e-12:
                eff = c
            else:
                break
        x = eff + (self.position - eff) * math.exp(-h_s / self.tau)
        return x, eff

    def advance(self, t_s: float, h_s: float) -> float:
        """Move the solenoid to t_s + h_s and return the new position."""
        self.position, self.effective = self.position_at(t_s, h_s)
        t_end = t_s + h_s
        while self._pending and self._pending[0][0] <= t_end + 1e-12:
            self._pending.popleft()
        if abs(self.position - self.effective) < _ARRIVED:
            self.position = self.effective
        self.moving = bool(self._pending) or self.position != self.effective
        return self.position
