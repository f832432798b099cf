"""Named interfaces ("ports") between the blocks of trackmj. No mujoco import here.

Tensioner port (mechanics <-> tensioner force element), one exchange per 1 ms step:

1. Before the mechanical step the plant calls ``element.force_law(t, stroke, velocity)``
   with the state at the start of the step (t_k, s_k, v_k).
2. The element returns a :class:`ForceLaw` ``F(v) = force_N + damping_N_s_m * v``.
   The plant hands it to MuJoCo as an affine actuator (``ctrl = force_N``,
   ``biasprm[2] = damping_N_s_m``); MuJoCo's ``implicitfast`` integrator then applies
   exactly ``F(v_{k+1})`` over the step, with ``v_{k+1}`` the end-of-step velocity.
3. After the step the plant calls ``element.complete_step(t_{k+1}, s_{k+1}, v_{k+1})``
   so the element can finish its own (implicit) update with the velocity the mechanics
   actually produced.

Sign convention: stroke s [m] grows when the idler carrier moves outward (tensioning the
track); velocity v = ds/dt [m/s]; force F [N] > 0 pushes the idler outward. The
mechanical work received by the track over one step is ``F(v_{k+1}) * v_{k+1} * h``
(MuJoCo's semi-implicit Euler moves the position by ``h * v_{k+1}``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable


@dataclass(frozen=True, slots=True)
class ForceLaw:
    """Affine force law for one step: F(v) = force_N + damping_N_s_m * v.

    force_N: force at zero end-of-step velocity [N], > 0 pushes the idler outward.
    damping_N_s_m: dF/dv [N·s/m]; normally <= 0 (a cylinder resists motion).
    """

    force_N: float
    damping_N_s_m: float = 0.0

    def at(self, velocity_m_s: float) -> float:
        """Force [N] the law gives at end-of-step velocity ``velocity_m_s`` [m/s]."""
        return self.force_N + self.damping_N_s_m * velocity_m_s


@runtime_checkable
class TensionerElement(Protocol):
    """A tensioner force element acting on the idler carrier (see module docstring)."""

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        """Force law for the coming step, given the state at its start."""
        ...

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Finish the step with the end-of-step state the mechanics produced."""
        ...
