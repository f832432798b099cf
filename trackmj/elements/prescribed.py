"""Bare tensioner elements (``ports.TensionerElement``) with a prescribed force, for settling,
identification and replay. Force F [N] > 0 pushes the idler carrier outward."""

from __future__ import annotations

import numpy as np

from trackmj.ports import ForceLaw


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
