"""Plausible track layouts no machine ships, for tests/test_unseen_layouts.py.

A layout is a shipped machine's mechanics file with three things changed, as ``--set``
overrides of it: the sprocket at the front or the rear, 4-8 road wheels and the carrier
slide inclined 0-20° above the horizontal. Everything else is the machine's, its hydraulics
and control files too (so its nominal tension and band).

Moving the sprocket to the other end mirrors every x about the chassis centre of mass
(x = 0): sprocket, idler (the generator's starting guess: it still moves the idler along
its slide until the loop closes), road wheels and return rollers; the rear hitch stays
behind the rear end, as far behind it as on the machine. The idler's slide range, its
stroke and its inclination are along the slide's outward axis, which points away from the
sprocket at either end (:func:`trackmj.track.mjcf.layout.slide_axis`): they carry over
unchanged. The road wheels are spread evenly from the machine's first to its last (the
same ground length).

:func:`close` passes the overrides through the model's own feasibility checks (the
validator's layout checks, :func:`trackmj.track.mechanics._check_layout`, and the loop
laid round the wheels, :func:`trackmj.track.mjcf.layout.compute_layout`) and returns the
closed parameters or the check's message; :func:`layouts` is the hypothesis strategy of
closed layouts, a refused one logged as a hypothesis event with its reason and rejected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from hypothesis import event, reject
from hypothesis import strategies as st

from trackmj.machines import assembly as machines
from trackmj.track.mechanics import ModelParams, load_model_params
from trackmj.track.mjcf.layout import compute_layout
from trackmj.validator import ParameterError

WHEEL_COUNTS = (4, 8)
"""Road wheels per side [-], least and most."""
SLIDE_ANGLE_DEG = (0.0, 20.0)
"""Carrier slide inclination above the horizontal, outward [°], least and most."""


@dataclass(frozen=True)
class Variant:
    """A layout: the shipped ``machine`` it starts from, the sprocket at the front or the
    rear, ``wheel_count`` road wheels, the slide inclined ``slide_angle_deg`` [°]."""

    machine: str
    sprocket_front: bool
    wheel_count: int
    slide_angle_deg: float

    def __str__(self) -> str:
        side = "front" if self.sprocket_front else "rear"
        return (f"{self.machine} with its sprocket at the {side}, {self.wheel_count} road "
                f"wheels, slide at {self.slide_angle_deg:g}°")


def base_params(machine: str) -> ModelParams:
    """The shipped machine's own mechanics."""
    return machines.mechanics(machines.resolve(machine))


def sprocket_at_front(p: ModelParams) -> bool:
    """Whether the sprocket is the front end (+x) of the track."""
    return p.sprocket.x_m > p.idler.x_m


def overrides(v: Variant) -> dict[str, Any]:
    """``--set`` overrides (``{"model.TABLE.KEY": value}``) of the machine's mechanics that
    make layout ``v`` (see the module docstring); x in the chassis frame [m]."""
    p = base_params(v.machine)
    sign = -1.0 if v.sprocket_front != sprocket_at_front(p) else 1.0

    def mirrored(xs: tuple[float, ...]) -> list[float]:
        return sorted(sign * x + 0.0 for x in xs)   # + 0.0: no -0.0

    sprocket_x, idler_x = sign * p.sprocket.x_m, sign * p.idler.x_m
    behind = min(p.sprocket.x_m, p.idler.x_m) - p.chassis.hitch_x_m
    wheels = mirrored(p.road_wheels.x_m)
    spread = np.linspace(wheels[0], wheels[-1], v.wheel_count)
    return {"model.sprocket.x_m": sprocket_x, "model.idler.x_m": idler_x,
            "model.idler.slide_angle_rad": math.radians(v.slide_angle_deg),
            "model.road_wheels.count": v.wheel_count,
            "model.road_wheels.x_m": [round(float(x), 6) for x in spread],
            "model.return_rollers.x_m": mirrored(p.return_rollers.x_m),
            "model.chassis.hitch_x_m": min(sprocket_x, idler_x) - behind}


def close(v: Variant) -> tuple[ModelParams | None, str]:
    """(the validated parameters of layout ``v``, "") if the model's feasibility checks pass
    and the loop closes round its wheels; (None, the refusal's message) if not."""
    sets = {key.removeprefix("model."): value for key, value in overrides(v).items()}
    try:
        p = load_model_params(machines.resolve(v.machine).mechanics, overrides=sets)
        compute_layout(p)
    except ParameterError as exc:
        return None, str(exc)
    return p, ""


@st.composite
def variants(draw: st.DrawFn, names: tuple[str, ...] | None = None) -> Variant:
    """Any layout of a shipped machine (of ``names``; None: every shipped one), feasible or
    not; the slide angle to 0.1°."""
    return Variant(machine=draw(st.sampled_from(names or tuple(machines.names()))),
                   sprocket_front=draw(st.booleans()),
                   wheel_count=draw(st.integers(*WHEEL_COUNTS)),
                   slide_angle_deg=round(draw(st.floats(*SLIDE_ANGLE_DEG)), 1))


def shipped(v: Variant) -> bool:
    """Whether ``v`` is its machine's own layout (same sprocket end, wheels and slide)."""
    p = base_params(v.machine)
    return (v.sprocket_front == sprocket_at_front(p) and v.wheel_count == p.road_wheels.count
            and math.radians(v.slide_angle_deg) == p.idler.slide_angle_rad)


@st.composite
def layouts(draw: st.DrawFn, names: tuple[str, ...] | None = None) -> Variant:
    """A layout no machine ships that the model's checks accept. A refused one is rejected,
    its reason logged as a hypothesis event (``--hypothesis-show-statistics``), and so is
    a machine's own layout; if every draw is rejected hypothesis fails the test as
    unsatisfiable."""
    v = draw(variants(names))
    if shipped(v):
        event(f"rejected: {v} is {v.machine}'s own layout")
        reject()
    params, refusal = close(v)
    if params is None:
        event(f"refused: {v}: {refusal}")
        reject()
    return v
