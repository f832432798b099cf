"""Tensioner elements other than the hydraulic plugin (each a ``ports.TensionerElement``).

Sign conventions as in :mod:`trackmj.ports`: stroke s [m] outward positive, v = ds/dt,
force F [N] > 0 pushes the idler carrier outward.
"""

from __future__ import annotations

import numpy as np

from trackmj.hydraulics import LogRow
from trackmj.ports import COUPLING_STEP_S, ForceLaw


class ConstantForce:
    """F(v) = force_N − damping_N_s_m·v: a constant load with implicit damping, e.g. to bring
    the track to rest at a load (settle, identification). Stateless."""

    def __init__(self, force_N: float, damping_N_s_m: float = 0.0) -> None:
        self.force_N = force_N
        self.damping_N_s_m = damping_N_s_m

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(self.force_N, -self.damping_N_s_m)

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Nothing to finish: the element has no state."""


class ForceHistory:
    """Tensioner element replaying ``force_N`` [N], one value per coupling step (the last
    one held after the end), with no damping."""

    def __init__(self, force_N: np.ndarray) -> None:
        self.force_N = force_N
        self.step = 0

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(float(self.force_N[min(self.step, len(self.force_N) - 1)]))

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        self.step += 1


class IdealForceSource:
    """dp-b tensioner: an ideal force source replacing the hydraulics.

    State: commanded force F_c [N] and lagged force F_l [N]. Each step
    F_c += mode·rate_N_s·h, F_l += (F_c − F_l)·h/(τ + h) (implicit lag), and the law is
    F(v) = F_l − c·v with c the cylinders' viscous damping [N·s/m]. Equivalent pressures for
    the sensors: p_head = (F_l + A_r·p_t)/A_h, p_rod = p_t (A the lumped areas). There is
    no supply node (p_supply and q_supply are NaN). ``work_J``: the net work into the track
    Σ F·v·h. ``supply_J``: the energy an ideal actuator with the same cylinders would draw:
    lossless valves, no leakage or seal friction, the head oil column (compliance C_h [m^3/Pa])
    a lossless store of the energy the track returns, so the supply delivers only what the
    head side ever needs beyond it: the running maximum of E(t) = Σ p_head·A_h·v·h +
    C_h·(p_head² − p_head,0²)/2 (a hold against the track's ripple draws nothing, as a
    closed cylinder does not).
    """

    def __init__(self, force_N: float, rate_N_s: float, lag_s: float, damping_N_s_m: float,
                 area_head_m2: float, area_rod_m2: float, tank_Pa: float,
                 head_compliance_m3_Pa: float) -> None:
        self.command_N = self.force_N = force_N
        self.rate_N_s, self.lag_s, self.damping = rate_N_s, lag_s, damping_N_s_m
        self.area_head, self.area_rod, self.tank = area_head_m2, area_rod_m2, tank_Pa
        self.head_compliance = head_compliance_m3_Pa
        self.mode = 0
        self.t_s = 0.0
        self.work_J = 0.0
        self.supply_J = 0.0
        self._head_work_J = 0.0
        self._p_head0 = self.p_head_Pa
        self._law = ForceLaw(force_N, -damping_N_s_m)

    def set_mode(self, mode: int) -> None:
        """Valve mode +1 (force rises at rate_N_s), 0 (held), −1 (falls)."""
        self.mode = mode

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        h = COUPLING_STEP_S
        self.command_N += self.mode * self.rate_N_s * h
        self.force_N += (self.command_N - self.force_N) * h / (self.lag_s + h)
        self._law = ForceLaw(self.force_N, -self.damping)
        return self._law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        h = COUPLING_STEP_S
        p_head = self.p_head_Pa
        self.work_J += self._law.at(velocity_m_s) * velocity_m_s * h
        self._head_work_J += p_head * self.area_head * velocity_m_s * h
        needed = self._head_work_J + 0.5 * self.head_compliance * (p_head * p_head
                                                                   - self._p_head0 ** 2)
        self.supply_J = max(self.supply_J, needed)
        self.t_s = t_s

    @property
    def p_head_Pa(self) -> float:
        """Equivalent head pressure [Pa gauge] of the lumped cylinder at the lagged force."""
        return (self.force_N + self.area_rod * self.tank) / self.area_head

    def log(self) -> LogRow:
        """The per-step values in the hydraulic plugin's layout (NaN where none exist)."""
        nan = float("nan")
        return LogRow(self.t_s, self.p_head_Pa, self.tank, nan, nan, self.force_N,
                      self.supply_J, self.work_J, self.work_J)
