"""The sprocket drive's velocity servo at its torque limit, stepped as backward Euler does.

The drive is a MuJoCo velocity actuator, torque kv·(ω_cmd − ω) clamped to ±L
(``forcerange``). MuJoCo applies a clamped actuator's force explicitly (its damping leaves
the implicit step), which is right while the servo stays saturated but overshoots in the
step that reaches the command: a light sprocket at an abrupt stop reversed in one step and
the clamp flipped sign every step after (LF1352: +1.5 / −0.6 m/s for 10 ms). Unclamping
that step would not do either: MuJoCo's implicit damping is not seen by its constraint
solver, which would then answer the start-of-step torque kv·(ω_cmd − ω₀), 18 L at 1.5 m/s.

:class:`DriveRetake` asks after a step MuJoCo took clamped whether the torque at its end,
kv·(ω_cmd − ω₁), is still at the same limit. If not, backward Euler's torque lies inside
the limit: T* = kv·(ω_cmd − ω₁(T*)). The step's end speed is affine in an explicit torque
while the contacts' active set holds (one linear solve), so a second attempt at T = 0
gives a line through both and T* from it, applied explicitly by a third (the force range
pinned to [T*, T*], so the constraint solver sees the torque the step applies); where the
active set changed between them (the contacts', or the ground's when its check takes the
step again), secants through the last two attempts go on until the residual is below
:data:`CONSISTENCY` of L.
"""

from __future__ import annotations

import mujoco

CONSISTENCY = 1e-3
"""Torque residual |T − kv·(ω_cmd − ω₁)| a retaken step stops at, as a fraction of L."""
MAX_ATTEMPTS = 8
"""Attempts a step is retaken for the drive (T = 0, then secants, also after the ground's
check took the step again) before the last is kept."""


class DriveRetake:
    """:func:`trackmj.track.foundation.step`'s ``retake`` for a step of a velocity servo
    that starts at its torque limit: called after every attempt's ``mj_step2`` (the
    ground's retakes included, whose new active set moves ω₁), True to take the step again
    with the force range it set. :meth:`restore` puts the limit back (after
    whatever reads the step, e.g. an energy ledger, which sees the range it was taken
    with).

    actuator: the velocity actuator's id (gear 1, on a hinge); dof: its joint's dof;
    kv [N·m·s/rad]; limit L [N·m] (forcerange ±L).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, actuator: int, dof: int,
                 kv: float, limit: float) -> None:
        self.model, self.data = model, data
        self.actuator, self.dof, self.kv, self.limit = actuator, dof, kv, limit
        self._retaking = False
        self._attempt = 0
        self._previous = (0.0, 0.0)   # (torque [N·m], end speed [rad/s]) of the last attempt

    def start(self) -> DriveRetake:
        """Ready for a new step; returns itself."""
        self._retaking = False
        self._attempt = 0
        return self

    def __call__(self) -> bool:
        m, d, a = self.model, self.data, self.actuator
        applied, speed = float(d.actuator_force[a]), float(d.qvel[self.dof])
        command = float(d.ctrl[a])
        residual = applied - self.kv * (command - speed)
        if not self._retaking:   # an attempt MuJoCo's clamp decided
            if -self.limit < applied < self.limit:
                return False                      # not clamped: implicit, as MuJoCo does
            if (applied <= -self.limit and residual >= 0.0) or (
                    applied >= self.limit and residual <= 0.0):
                return False                      # still at the limit: the clamp was right
            self._retaking = True
            self._previous = (applied, speed)
            m.actuator_forcerange[a] = (0.0, 0.0)   # explicit zero torque
            return True
        self._attempt += 1
        if abs(residual) <= CONSISTENCY * self.limit or self._attempt >= MAX_ATTEMPTS:
            return False
        torque_b, speed_b = self._previous
        self._previous = (applied, speed)
        if applied == torque_b:
            # the same torque again: on the active set the ground's check chose since, or
            # T* clipped to the limit twice; a new second point at zero torque
            m.actuator_forcerange[a] = (0.0, 0.0)
            return True
        slope = (speed_b - speed) / (torque_b - applied)   # end speed per torque [rad/s/N·m]
        torque = self.kv * (command - speed + slope * applied) / (1.0 + self.kv * slope)
        torque = min(max(torque, -self.limit), self.limit)
        m.actuator_forcerange[a] = (torque, torque)
        return True

    def restore(self) -> None:
        """The drive's force range back to ±L."""
        self.model.actuator_forcerange[self.actuator] = (-self.limit, self.limit)


__all__ = ["DriveRetake"]
