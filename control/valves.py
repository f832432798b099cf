"""Valve logic: continuous opening u -> discrete mode (+1 pressurize, 0 hold, -1 release).

Runs once per plant step dt [s]. Guarantees: a commanded mode is held for at least
``min_hold_s`` (counted in whole steps, rounded up) before it may change; the applied mode is
the commanded one delayed by the solenoid delay (whole steps), so applied modes obey the same
holding time. Optional sum-up rounding (sigma-delta): the integral of (u - mode) is carried
over so the average of the modes follows u; inside the dead zone the valves hold and the
carried error is discarded.
"""

from __future__ import annotations

import math
from collections import deque

from trackmj.control.params import ValveParams

MODES = (-1, 0, 1)


class ValveLogic:
    """Stateful mapper u -> mode with dead zone, minimum holding time and solenoid delay."""

    def __init__(self, params: ValveParams, dt: float) -> None:
        if dt <= 0.0:
            raise ValueError(f"dt = {dt} must be > 0")
        self.p = params
        self.dt = dt
        self.hold_steps = max(1, math.ceil(params.min_hold_s / dt - 1e-9))
        self.delay_steps = round(params.solenoid_delay_s / dt)
        self.mode = 0
        self.steps_in_mode = self.hold_steps
        self.error_integral = 0.0
        self.switches = 0
        self._pipeline: deque[int] = deque([0] * self.delay_steps)
        # per-step constants as plain attributes (this runs every 1 ms step)
        self._dead_zone, self._sigma_delta = params.dead_zone, params.sigma_delta
        self._horizon = self.hold_steps * dt  # [s] integral bound and look-ahead

    def step(self, u: float) -> int:
        """Advance one step with command u in [-1, 1]; return the mode applied at the valves."""
        u = float(u)
        if not u >= -1.0:   # min(1, max(-1, u)): NaN -> -1
            u = -1.0
        elif u > 1.0:
            u = 1.0
        if abs(u) < self._dead_zone:
            u = 0.0
            self.error_integral = 0.0
        if self.steps_in_mode >= self.hold_steps:
            target = self._choose(u)
            if target != self.mode:
                self.mode = target
                self.steps_in_mode = 0
                self.switches += 1
        self.steps_in_mode += 1
        if self._sigma_delta:
            horizon = self._horizon
            integral = self.error_integral + (u - self.mode) * self.dt
            self.error_integral = min(horizon, max(-horizon, integral))
        if not self._pipeline:
            return self.mode
        self._pipeline.append(self.mode)
        return self._pipeline.popleft()

    def _choose(self, u: float) -> int:
        if not self._sigma_delta:
            return 0 if u == 0.0 else (1 if u > 0.0 else -1)
        horizon, integral = self._horizon, self.error_integral
        best = self.mode
        best_err = abs(integral + (u - best) * horizon)
        for m in MODES:   # -1, 0, +1: the first clearly better one wins ties
            err = abs(integral + (u - m) * horizon)
            if err < best_err - 1e-12:
                best, best_err = m, err
        return best
