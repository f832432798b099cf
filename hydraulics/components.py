"""Scalar component laws of the tensioning circuit (SI, gauge Pa).

Flow sign convention: a branch flow Q [m^3/s] is positive from its first node ``a`` to its
second node ``b``; Δp = p_a − p_b [Pa].

The laws the per-step solve evaluates (orifice, smoothstep, friction, end stop, gas
accumulator) are compiled in :mod:`.kernels` and re-exported here (callable from Python
with floats); the laws below set up a step's orifice gains and valve positions in Python.
"""

from __future__ import annotations

import math
from collections import deque

from .kernels import (
    accumulator_energy,
    accumulator_oil_volume,
    endstop_force,
    friction_force,
    orifice_flow,
    smoothstep,
)
from .params import Valve

__all__ = ["Solenoid", "accumulator_energy", "accumulator_oil_volume", "endstop_force",
           "friction_force", "orifice_flow", "orifice_gain", "series_area", "smoothstep",
           "valve_area"]

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


def valve_area(position: float, valve: Valve) -> float:
    """Opening area [m^2] of a valve edge at normalised position (0 closed, 1 open).

    Linear from the leak area at ``overlap`` to the open area at 1 (positive overlap).
    """
    u = (position - valve.overlap) / (1.0 - valve.overlap)
    u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
    return valve.leak_area_m2 + (valve.open_area_m2 - valve.leak_area_m2) * u


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
