"""Scalar component laws of the tensioning circuit (SI, gauge Pa).

Flow sign convention: a branch flow Q [m^3/s] is positive from its first node ``a`` to its
second node ``b``; Δp = p_a − p_b [Pa].

The laws the per-step solve evaluates (orifice, smoothstep, friction, end stop, gas
accumulator) are compiled in :mod:`.kernels` and re-exported here (callable from Python
with floats); the laws below set up a step's orifice gains and valve positions in Python.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import kernels as k
from .kernels import (
    accumulator_energy,
    accumulator_oil_volume,
    endstop_force,
    friction_force,
    orifice_flow,
    series_area,
    smoothstep,
)
from .params import Valve

__all__ = ["Solenoid", "SolenoidBank", "accumulator_energy", "accumulator_oil_volume",
           "endstop_force", "friction_force", "orifice_flow", "orifice_gain", "series_area",
           "smoothstep", "valve_area"]

SQRT2 = math.sqrt(2.0)


def orifice_gain(cq: float, area_m2: float, density_kg_m3: float) -> float:
    """Turbulent gain K = Cq·A·sqrt(2/ρ) [m^3/s/sqrt(Pa)]."""
    return cq * area_m2 * SQRT2 / math.sqrt(density_kg_m3)


def valve_area(position: float, valve: Valve) -> float:
    """Opening area [m^2] of a valve edge at normalised position (0 closed, 1 open).

    Linear from the leak area at ``overlap`` to the open area at 1 (positive overlap); the
    kernels' law (:func:`.kernels.valve_area`) with ``valve``'s edge.
    """
    return k.valve_area(position, valve.overlap, valve.leak_area_m2, valve.open_area_m2)


class SolenoidBank:
    """The state of ``n`` solenoids in the arrays the compiled kernels read (layout: the
    kernels module docstring): ``sol`` float64[n, N_SOL] and the pending commands ``pend``
    float64[n, capacity, 2], a ring buffer per solenoid that doubles when one is full."""

    def __init__(self, valves: Sequence[Valve], capacity: int = 8) -> None:
        self.sol = np.zeros((len(valves), k.N_SOL))
        self.pend = np.zeros((len(valves), capacity, 2))
        for i, valve in enumerate(valves):
            self.sol[i, k.S_DELAY] = valve.delay_s
            self.sol[i, k.S_TAU] = valve.time_constant_s

    def push(self, i: int, t_on_s: float, command: float) -> None:
        """Queue ``command`` for solenoid ``i``, in force from ``t_on_s`` [s]."""
        sol = self.sol
        count = int(sol[i, k.S_COUNT])
        if count == self.pend.shape[1]:
            self._grow()
        cap = self.pend.shape[1]
        self.pend[i, (int(sol[i, k.S_HEAD]) + count) % cap] = (t_on_s, command)
        sol[i, k.S_COUNT] = count + 1

    def _grow(self) -> None:
        """Double the ring buffers, each solenoid's pending commands first, in order."""
        cap = self.pend.shape[1]
        grown = np.zeros((self.pend.shape[0], 2 * cap, 2))
        for i in range(self.pend.shape[0]):
            head, count = int(self.sol[i, k.S_HEAD]), int(self.sol[i, k.S_COUNT])
            grown[i, :count] = self.pend[i, (head + np.arange(count)) % cap]
            self.sol[i, k.S_HEAD] = 0.0
        self.pend = grown


class Solenoid:
    """Valve actuator: pure electromagnetic delay then first-order opening.

    Command c ∈ [0, 1] set at time t takes effect at t + delay; the position x ∈ [0, 1]
    then follows dx/dt = (c − x)/τ, integrated exactly over each step with the command
    in force at the step end; within 1e-9 of the command the position snaps to it.
    ``moving`` is False only at rest (no pending command, position equal to the command in
    force), when stepping cannot change the position.

    The state is row ``index`` of a :class:`SolenoidBank` (its own one-row bank if none is
    given), so the compiled kernels can step it (:func:`.kernels.valves_at`,
    :func:`.kernels.valves_advance`).
    """

    __slots__ = ("bank", "index")

    def __init__(self, valve: Valve, position: float = 0.0, bank: SolenoidBank | None = None,
                 index: int = 0) -> None:
        if bank is None:
            bank, index = SolenoidBank([valve]), 0
        self.bank, self.index = bank, index
        row = bank.sol[index]
        row[k.S_DELAY], row[k.S_TAU] = valve.delay_s, valve.time_constant_s
        row[k.S_POS] = row[k.S_CMD] = row[k.S_EFF] = position
        row[k.S_MOVING] = 0.0

    def _get(self, field: int) -> float:
        return self.bank.sol.item(self.index, field)

    delay = property(lambda self: self._get(k.S_DELAY), doc="delay [s]")
    tau = property(lambda self: self._get(k.S_TAU), doc="opening time constant [s]")
    position = property(lambda self: self._get(k.S_POS), doc="position [-] (0 closed)")
    command = property(lambda self: self._get(k.S_CMD), doc="last command [-]")
    effective = property(lambda self: self._get(k.S_EFF), doc="command in force [-]")
    moving = property(lambda self: self._get(k.S_MOVING) != 0.0, doc="not at rest")

    def set(self, t_s: float, command: float) -> None:
        """Request command [0..1] at time t_s [s]."""
        if not 0.0 <= command <= 1.0:
            raise ValueError(f"valve command = {command!r} is outside [0, 1]")
        sol, i = self.bank.sol, self.index
        if command != sol[i, k.S_CMD]:
            sol[i, k.S_CMD] = command
            self.bank.push(i, t_s + sol.item(i, k.S_DELAY), command)
            sol[i, k.S_MOVING] = 1.0
            sol[i, k.S_AT_VALID] = 0.0

    def position_at(self, t_s: float, h_s: float) -> tuple[float, float]:
        """(position, effective command) at t_s + h_s without committing."""
        return k.solenoid_at(self.bank.sol, self.bank.pend, self.index, t_s, h_s)

    def advance(self, t_s: float, h_s: float) -> float:
        """Move the solenoid to t_s + h_s and return the new position."""
        x, eff = self.position_at(t_s, h_s)
        k.solenoid_commit(self.bank.sol, self.bank.pend, self.index, t_s, h_s, x, eff)
        return self.position
