"""How the sprocket's drive torque loads the idler: the static gain the controllers feed
forward (``PlantParams.drive_load_gain_1_m`` and ``drive_tight_sign``).

A torque T [N·m] on a sprocket of pitch radius r makes the strand it pulls in tighter than
the one it pays out by T/r (the belt drive's T₁ − T₂ = T/r). Driving forward (T > 0) the
sprocket pulls in the top strand when it is at the front and the ground strand when it is at
the rear; braking (T < 0) swaps them. The tensioner holds the slack side's tension, so the
tight side carries the whole T/r. While the idler's two strands are the tight side, both
pull the carrier in by T/r more, and at held stroke the tensioner takes

    ΔF = G·|T|/r,   G = −(e₁ + e₂)·ŝ,

e₁, e₂ the unit vectors along the idler's two strands away from it
(:func:`~trackmj.track.mjcf.layout.idler_strand_directions`) and ŝ the slide's outward unit
vector (G = 2 for straight strands along a horizontal slide). On the slack side ΔF ≈ 0.
So L(T) = g·max(σ·T, 0) with g = G/r and σ = +1 for a front sprocket, −1 for a rear one.

The formula takes the strands inextensible. Measured with the idler truly held
(tests/test_drive_load.py: ``trackmj drive`` at 1.5 m/s with hitch loads of −4, 0 and
+8 kN, the tensioner a 1e9 N/m spring made implicit through its damping; Intel Xeon 2-core
VM, 2026-12-06), the tight side's gain over G/r is 0.97 on M113 (driving), 0.90 on compact3
and 0.64 on LF1352 (braking): with the stroke held, the sprocket's turn that stretches the
tight span relaxes the slack one, which unloads by the spans' compliance share, the more
the softer the pins (LF1352 at its derived 6.08e8 N/m steel pins: 0.80). The slack side
takes 0.004 (LF1352), 0.17 (compact3) and up to 0.24 (M113) of G/r. The controllers use the
formula; the test holds the tight side to [0.55, 1.25] of it and the slack side to 0.3.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from trackmj.track.mechanics import ModelParams
from trackmj.track.mjcf.layout import compute_layout, idler_strand_directions, slide_axis


@dataclass(frozen=True)
class DriveLoad:
    """Idler load of the drive torque: ``gain_1_m`` g = G/r [N per N·m = 1/m] while the
    idler's strands are the tight side, ``tight_sign`` σ (+1 sprocket at the front, −1 at
    the rear). The law itself is the controllers' :func:`trackmj.control.model.drive_load_N`
    (these two values become the reduced model's parameters)."""

    gain_1_m: float
    tight_sign: float


@functools.cache
def drive_load(p: ModelParams) -> DriveLoad:
    """The drive load of the machine ``p`` at its layout (see the module docstring); cached
    per parameters: laying the loop out again takes ~0.1 s, and every run asks."""
    layout = compute_layout(p)
    (e1x, e1z), (e2x, e2z) = idler_strand_directions(p, layout.idler_x_m)
    sx, sz = slide_axis(p)
    factor = -((e1x + e2x) * sx + (e1z + e2z) * sz)
    return DriveLoad(gain_1_m=factor / p.sprocket_pitch_radius_m,
                     tight_sign=1.0 if p.sprocket.x_m > p.idler.x_m else -1.0)
