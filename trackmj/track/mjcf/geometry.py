"""Derived geometry of a layout: the loop round the pin-vertex circles (free spans on the
outer tangents, wraps on the circles), the closure of the pin polygon, and the static strand
tension the preload sets.

The pins of a wrapped link sit on the wheel's *vertex circle* (:func:`vertex_radius`); the
loop of pins is laid on the convex path round those circles: outer tangent segments (free
spans) and arcs (wraps). Angles are in the (x, z) plane, the path runs clockwise (bottom
strand rearward), which is the running direction for forward travel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from trackmj.track.mechanics import ModelParams
from trackmj.track.mjcf.layout import Layout, _circles, slide_axis

HULL_SAMPLES = 720
"""Points per circle used only to find the circles' order round the hull."""


@dataclass(frozen=True)
class Span:
    """A free span between two wheels: names, length [m], direction (x, z) of travel,
    tangent points ((x, z) at start, at end) [m] on the vertex circles; ``upper``: on the
    upper strand (the track runs forward there)."""

    start: str
    end: str
    length_m: float
    direction: tuple[float, float]
    points: tuple[tuple[float, float], tuple[float, float]]

    @property
    def upper(self) -> bool:
        return self.direction[0] > 1e-9


@dataclass(frozen=True)
class Geometry:
    """Derived geometry of a layout (SI; angles [rad]).

    wraps_rad: wrap angle of the track on each wheel it touches, in loop order;
    spans: the free spans between them; path_m: length of the path round the vertex circles
    (spans + arcs); loop_m: link_count·pitch; closure_m: | |pin_{n-1} − pin_0| − pitch |,
    the layout's closure error; strand_tension_N: the static tension in both strands at the
    idler that the preload holds (frictionless idler, the carrier's weight along an
    inclined slide included); idler_factor: (d_in − d_out)·u, the strands' pull on the idler
    along the slide per newton of strand tension [-].
    """

    wraps_rad: dict[str, float]
    spans: tuple[Span, ...]
    path_m: float
    loop_m: float
    closure_m: float
    strand_tension_N: float
    idler_factor: float


def _names(p: ModelParams) -> list[str]:
    """Names of the circles of :func:`trackmj.track.mjcf.layout._circles`, in their order."""
    return (["sprocket", "idler"] + [f"road_wheel_{k + 1}" for k in range(p.road_wheels.count)]
            + [f"return_roller_{k + 1}" for k in range(len(p.return_rollers.x_m))])


def _hull_order(circles: list[tuple[float, float, float]]) -> list[int]:
    """Indices of the circles on the convex path, clockwise."""
    ang = np.linspace(0.0, 2.0 * np.pi, HULL_SAMPLES, endpoint=False)
    pts = np.concatenate([np.column_stack([cx + r * np.cos(ang), cz + r * np.sin(ang)])
                          for cx, cz, r in circles])
    labels = (ConvexHull(pts).vertices // HULL_SAMPLES)[::-1]   # clockwise
    order = [int(c) for k, c in enumerate(labels) if c != labels[k - 1]]
    return order or [int(labels[0])]


def _outer_normal(c1: tuple[float, float, float], c2: tuple[float, float, float]
                  ) -> tuple[np.ndarray, float]:
    """Outward normal of the outer tangent from circle c1 to c2 on a clockwise path, and
    the tangent's length [m]."""
    delta = np.array([c2[0] - c1[0], c2[1] - c1[1]])
    dist = float(np.hypot(*delta))
    e = delta / dist
    left = np.array([-e[1], e[0]])
    alpha = (c1[2] - c2[2]) / dist
    normal = alpha * e + math.sqrt(max(1.0 - alpha * alpha, 0.0)) * left
    return normal, math.sqrt(max(dist * dist - (c1[2] - c2[2]) ** 2, 0.0))


def derive_geometry(p: ModelParams, layout: Layout) -> Geometry:
    """The derived geometry of ``layout`` (see :class:`Geometry`)."""
    circles = _circles(p, layout.idler_x_m)
    names = _names(p)
    order = _hull_order(circles)
    n = len(order)
    normals, spans = [], []
    for k in range(n):
        a, b = circles[order[k]], circles[order[(k + 1) % n]]
        normal, length = _outer_normal(a, b)
        normals.append(normal)
        direction = (normal[1], -normal[0])        # clockwise: travel = normal turned -90°
        ends = ((a[0] + a[2] * normal[0], a[1] + a[2] * normal[1]),
                (b[0] + b[2] * normal[0], b[1] + b[2] * normal[1]))
        spans.append(Span(names[order[k]], names[order[(k + 1) % n]], length, direction,
                          ends))
    wraps = {}
    for k in range(n):
        n_in, n_out = normals[k - 1], normals[k]
        turn = math.atan2(n_in[1], n_in[0]) - math.atan2(n_out[1], n_out[0])
        wraps[names[order[k]]] = turn % (2.0 * math.pi)
    path = sum(s.length_m for s in spans) + sum(circles[order[k]][2] * wraps[names[order[k]]]
                                                for k in range(n))
    pins = layout.pins
    closure = abs(float(np.hypot(*(pins[-1] - pins[0]))) - p.track.pitch_m)
    # strands at the idler: the span arriving (d_in) and the span leaving (d_out)
    i = order.index(1)
    d_in = np.array(spans[i - 1].direction)
    d_out = np.array(spans[i].direction)
    u = np.array(slide_axis(p))
    factor = float((d_in - d_out) @ u)
    tension = static_strand_tension_N(p, factor, p.tensioner.preload_N)
    return Geometry(wraps, tuple(spans), path, p.track.link_count * p.track.pitch_m,
                    closure, tension, factor)


def static_strand_tension_N(p: ModelParams, idler_factor: float, idler_force_N: float
                            ) -> float:
    """The static tension [N] in both strands at a frictionless idler that the tensioner's
    ``idler_force_N`` [N] holds: (F − the carrier's weight along the slide) / ``idler_factor``
    (:attr:`Geometry.idler_factor`)."""
    carrier_weight = (p.idler.mass_kg + p.idler.carrier_mass_kg) * p.simulation.gravity_m_s2
    return (idler_force_N - carrier_weight * slide_axis(p)[1]) / idler_factor


def catenary_sag_m(p: ModelParams, span: Span, tension_N: float,
                   length_m: float | None = None) -> float:
    """Mid-span sag [m] of a free span (or a chord of ``length_m`` [m] along it) under its
    own weight at ``tension_N`` [N]: the shallow catenary w·L²·cos(θ)/(8·T), w the track's
    weight per metre, θ the span's slope."""
    weight = p.track.link_mass_kg / p.track.pitch_m * p.simulation.gravity_m_s2
    length = span.length_m if length_m is None else length_m
    return weight * length ** 2 * abs(span.direction[0]) / (8.0 * tension_N)


def measured_sag_m(span: Span, pins: np.ndarray, pitch_m: float) -> tuple[float, float]:
    """Largest drop [m] of the pins ``pins`` (n, 2; chassis frame, settled) below the chord
    through the first and last of them that lie within the span's x range (one pitch in
    from each tangent point), and that chord's length [m]; (0, 0) for a span holding fewer
    than three pins."""
    (x1, z1), (x2, z2) = span.points
    lo, hi = min(x1, x2) + pitch_m, max(x1, x2) - pitch_m
    level = 0.5 * min(z1, z2)          # half-way down to the ground: leaves the lower strand
    inside = pins[(pins[:, 0] > lo) & (pins[:, 0] < hi) & (pins[:, 1] > level)]
    if len(inside) < 3:
        return 0.0, 0.0
    inside = inside[np.argsort(inside[:, 0])]
    a, b = inside[0], inside[-1]
    chord = a[1] + (inside[:, 0] - a[0]) * (b[1] - a[1]) / (b[0] - a[0])
    return (float(max((chord - inside[:, 1]).max(), 0.0)),
            float(np.hypot(*(inside[-1] - inside[0]))))
