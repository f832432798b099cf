"""Initial layout of the track loop: ``link_count`` pitch-length chords around sprocket,
idler, road wheels and return rollers, with the idler moved along its slide until the loop
closes exactly; the feasibility checks that refuse a layout that cannot close.

The sprocket may be at the rear or at the front: the idler is at the other end, and its
slide's outward (tensioning) direction points away from the sprocket, inclined by
``[idler].slide_angle_rad`` above the horizontal.

Coordinates are world (x forward, z up) [m] at the initial, undeformed state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import brentq
from scipy.spatial import ConvexHull

from trackmj.validator import Location

if TYPE_CHECKING:   # annotations only: mechanics validates a layout through this module
    from trackmj.track.mechanics import ModelParams

MIN_SEATED_PINS = 2
"""Pins seated on the sprocket at the layout, at least (the plant's derailment check)."""


@dataclass(frozen=True)
class Layout:
    """Initial pin positions (world x, z) [m], shape (link_count, 2), and wheel centres."""

    pins: np.ndarray
    idler_x_m: float
    sprocket_center: tuple[float, float]
    idler_center: tuple[float, float]
    road_wheel_centers: tuple[tuple[float, float], ...]
    roller_centers: tuple[tuple[float, float], ...]
    sprocket_seat_angle_rad: float


def vertex_radius(p: ModelParams, wheel_radius: float) -> float:
    """Radius of the circle through the pins of a link wrap whose rail chords touch the
    wheel of ``wheel_radius`` at their midpoints: sqrt((R + r_rail)² + (pitch/2)²)."""
    return math.hypot(wheel_radius + p.track.rail_radius_m, p.track.pitch_m / 2.0)


def hub_radius(p: ModelParams) -> float:
    """Sprocket hub radius so the pins sit exactly on the pitch circle."""
    rp = p.sprocket_pitch_radius_m
    return rp * math.cos(math.pi / p.sprocket.tooth_count) - p.track.rail_radius_m


CLOSURE_WINDOW_M = 0.5
"""How far along x [m] from ``[idler].x_m`` the generator may move the idler to close the
loop."""
CLEARANCE_M = 0.01
"""Least gap between two wheels (sprocket teeth, idler, road wheels, rollers) [m]."""


def outward_sign(p: ModelParams) -> float:
    """+1 when the idler is at the front (sprocket at the rear), −1 when it is at the rear:
    the x direction in which the tensioner pushes the idler outward."""
    return 1.0 if p.idler.x_m > p.sprocket.x_m else -1.0


def slide_axis(p: ModelParams) -> tuple[float, float]:
    """Unit vector (x, z) of the carrier slide, outward (tensioning) positive."""
    a = p.idler.slide_angle_rad
    return outward_sign(p) * math.cos(a), math.sin(a)


def idler_center(p: ModelParams, idler_x: float) -> tuple[float, float]:
    """Idler centre (x, z) [m] on the slide line through (x_m, z_m) at abscissa ``idler_x``."""
    dz = (idler_x - p.idler.x_m) * outward_sign(p) * math.tan(p.idler.slide_angle_rad)
    return idler_x, p.idler.z_m + dz


def road_wheel_z(p: ModelParams) -> float:
    """Height of the road-wheel centres at the layout [m]: the rails seat on the flat
    bottom strand whose pins rest on the ground (z = pin radius)."""
    return p.track.pin_radius_m + vertex_radius(p, p.road_wheels.radius_m)


def sprocket_outer_radius(p: ModelParams) -> float:
    """Radius of the sprocket teeth's outer edge [m]."""
    s = p.sprocket
    return p.sprocket_pitch_radius_m + s.tooth_radial_offset_m + s.tooth_radius_m


ENGAGEMENT_PHASES = 1025
"""Phases of the strand's tangent point over one tooth pitch that
:func:`tooth_pin_distance_m` samples (an error below 1e-6 m on the shipped sprockets)."""


def tooth_pin_distance_m(tooth_count: int, pitch_m: float, offset_m: float) -> float:
    """Least distance [m] from a tooth centre to a pin centre of a track wrapping the
    sprocket, over every phase of the wrap: a tooth (``tooth_radius_m``) fits a pin
    (``pin_radius_m``) iff their radii sum to no more than it.

    Pins seat on the pitch circle r_p = p/(2 sin(π/N)) at 2πk/N, the teeth on r_t = r_p + e
    (e = ``offset_m``) half a seat between them; seated pins alone leave the pocket
    c = sqrt(r_p² + r_t² − 2·r_p·r_t·cos(π/N)). The strands leave the circle along a
    tangent, and the pins on it are nearer: with the tangent point at α ∈ [0, 2π/N] past
    the last seated pin, the strand's pins lie s_k = s_1 + (k − 1)·p along the tangent,
    s_1 = r_p·(sqrt(sin²α + 2·(cos α − cos(2π/N))) − sin α) (one chord p from the seated
    pin), and a pin at s from the tangent point is d² = r_p² + s² + r_t² −
    2·r_t·(r_p·cos δ + s·sin δ) from a tooth δ ahead of that point; the least d over α
    (:data:`ENGAGEMENT_PHASES` samples), the pins and the teeth. The first strand pin
    swings about the seated one at radius p: where its swing faces the tooth
    (r_p·cos(π/N) <= r_t <= r_p/cos(π/N)) the least d is p − c; further out, the link
    tangent at the seated pin already gives d² = c² − p²·e/r_p and the next pin, shortly
    before it seats, slightly less (LF1352: 36.37 against 36.39 mm); further in, c."""
    seat = 2.0 * math.pi / tooth_count
    rp = pitch_m / (2.0 * math.sin(math.pi / tooth_count))
    rt = rp + offset_m
    alpha = np.linspace(0.0, seat, ENGAGEMENT_PHASES)[:, None, None]
    sin_a = np.sin(alpha)
    s1 = rp * (np.sqrt(sin_a ** 2 + 2.0 * (np.cos(alpha) - math.cos(seat))) - sin_a)
    # pins on the tangent up to |r_t| + p out: any further one is more than p from a tooth
    s = s1 + pitch_m * np.arange(2 + math.ceil(abs(rt) / pitch_m))[None, :, None]
    delta = (0.5 * seat + seat * np.arange(tooth_count))[None, None, :] - alpha
    d2 = rp * rp + s * s + rt * rt - 2.0 * rt * (rp * np.cos(delta) + s * np.sin(delta))
    return math.sqrt(max(float(d2.min()), 0.0))


def _circles(p: ModelParams, idler_x: float) -> list[tuple[float, float, float]]:
    """Pin-vertex circles (x, z, radius) around which the loop is laid."""
    rw_v = vertex_radius(p, p.road_wheels.radius_m)
    wz = road_wheel_z(p)
    circles = [(p.sprocket.x_m, p.sprocket.z_m, p.sprocket_pitch_radius_m),
               (*idler_center(p, idler_x), vertex_radius(p, p.idler.radius_m))]
    circles += [(x, wz, rw_v) for x in p.road_wheels.x_m]
    rr_v = vertex_radius(p, p.return_rollers.radius_m)
    circles += [(x, p.return_rollers.z_m, rr_v) for x in p.return_rollers.x_m]
    return circles


HULL_SAMPLES = 2880
"""Points per circle of the sampled convex path the pins are walked on."""


def _hull_path(circles: list[tuple[float, float, float]],
               samples: int = HULL_SAMPLES) -> np.ndarray:
    """Closed convex path around the circles, clockwise in the (x, z) view, starting at the
    bottom. Returns (n, 2) points; sampled finely enough to walk chords on it (sagitta
    r·(1 − cos(π/samples)): 1.0e-7 m on a 0.17 m circle, 3e-7 m on 0.5 m)."""
    ang = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    pts = np.concatenate([np.column_stack([cx + r * np.cos(ang), cz + r * np.sin(ang)])
                          for cx, cz, r in circles])
    hull = pts[ConvexHull(pts).vertices]  # counter-clockwise
    hull = hull[::-1]  # clockwise: bottom strand runs rearward (-x)
    return hull


def _walk_chords(path: np.ndarray, pitch: float, count: int) -> np.ndarray:
    """Place ``count`` points on the closed polyline ``path`` (n, 2), the first at path[0],
    each at chord distance ``pitch`` from the previous one further along the path."""
    n = len(path)
    current = path[0]
    seg_start, seg = current, 0
    points = [current]
    while len(points) < count:
        seg_end = path[(seg + 1) % n]
        if np.linalg.norm(seg_end - current) < pitch:
            seg_start, seg = seg_end, seg + 1
            if seg > 2 * n:
                raise RuntimeError("chord walk ran round the loop twice: pitch too large")
            continue
        # the far intersection of segment seg_start -> seg_end with the circle |x - current| = pitch
        d = seg_end - seg_start
        f = seg_start - current
        qa, qb, qc = d @ d, 2.0 * (f @ d), f @ f - pitch * pitch
        t = (-qb + math.sqrt(max(qb * qb - 4.0 * qa * qc, 0.0))) / (2.0 * qa)
        current = seg_start + t * d
        seg_start = current
        points.append(current)
    return np.array(points)


def _start_x(p: ModelParams) -> float:
    """Where pin 0 lies: on the bottom strand, half a pitch ahead of the middle of the
    road-wheel span."""
    x = p.road_wheels.x_m
    return 0.5 * (min(x) + max(x)) + 0.5 * p.track.pitch_m


def _pins_for(p: ModelParams, idler_x: float, n_points: int) -> np.ndarray:
    """``n_points`` pins at chord distance pitch round the loop with the idler at
    ``idler_x``, pin 0 on the bottom strand (:func:`_start_x`), (n_points, 2)."""
    path = _hull_path(_circles(p, idler_x))
    start_x, r_pin = _start_x(p), p.track.pin_radius_m
    bottom = np.argmin(np.abs(path[:, 0] - start_x) + 10.0 * np.abs(path[:, 1] - r_pin))
    path = np.roll(path, -bottom, axis=0)
    if path[1, 0] > path[0, 0]:
        raise RuntimeError("hull orientation unexpected")
    path = np.concatenate([[[start_x, r_pin]], path[1:]])
    return _walk_chords(path, p.track.pitch_m, n_points)


def closure_gap(p: ModelParams, idler_x: float) -> float:
    """x_N − x_0 [m] of pin N (one chord past the last) and pin 0, both on the bottom
    strand, which runs in −x: > 0 the loop round the wheels is longer than N chords."""
    pins = _pins_for(p, idler_x, p.track.link_count + 1)
    return float(pins[-1, 0] - pins[0, 0])


def chords_fitting(p: ModelParams, idler_x: float) -> float:
    """How many pitch chords fit once round the loop with the idler at ``idler_x``: the
    (fractional) link count that would close it [-]."""
    path = _hull_path(_circles(p, idler_x))
    perimeter = float(np.linalg.norm(np.roll(path, -1, axis=0) - path, axis=1).sum())
    pins = _pins_for(p, idler_x, math.ceil(perimeter / p.track.pitch_m) + 3)
    start_x, r_pin = _start_x(p), p.track.pin_radius_m
    flat = np.abs(pins[:, 1] - r_pin) < 0.25 * p.track.pitch_m   # on or near the bottom
    for k in range(len(pins) // 2, len(pins)):
        if flat[k - 1] and flat[k] and pins[k - 1, 0] > start_x >= pins[k, 0]:
            return k - 1 + (pins[k - 1, 0] - start_x) / (pins[k - 1, 0] - pins[k, 0])
    raise RuntimeError("chord walk did not come back to the bottom strand")


def _idler_obstacles(p: ModelParams) -> list[tuple[str, float, float, float]]:
    """(key, x, z, least centre distance) of everything the idler must stay clear of."""
    ri = p.idler.radius_m + CLEARANCE_M
    wz = road_wheel_z(p)
    out = [("[sprocket].x_m", p.sprocket.x_m, p.sprocket.z_m, ri + sprocket_outer_radius(p))]
    out += [(f"[road_wheels].x_m[{k}]", x, wz, ri + p.road_wheels.radius_m)
            for k, x in enumerate(p.road_wheels.x_m)]
    out += [(f"[return_rollers].x_m[{k}]", x, p.return_rollers.z_m,
             ri + p.return_rollers.radius_m) for k, x in enumerate(p.return_rollers.x_m)]
    return out


def _idler_blocks(p: ModelParams, xs: np.ndarray, cz: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(clear, blocked_by) of idler centres (xs, cz): clear where the idler stays above the
    ground line and CLEARANCE_M from the other wheels; blocked_by names what it hits."""
    floor = p.track.pin_radius_m + vertex_radius(p, p.idler.radius_m)
    clear = cz >= floor
    blocked_by = np.full(len(xs), "", dtype=object)
    blocked_by[~clear] = "the ground line (the idler's lowest pin below the road wheels')"
    for key, ox, oz, distance in _idler_obstacles(p):
        hit = np.hypot(xs - ox, cz - oz) < distance
        blocked_by[hit & clear] = key
        clear &= ~hit
    return clear, blocked_by


def _idler_x_move(p: ModelParams, obstacle_x: float) -> str:
    """Which way and how far [mm] to move ``[idler].x_m`` (z_m as it is) to clear every
    wheel, away from the one at ``obstacle_x`` first: the advice of a refusal."""
    x0 = p.idler.x_m
    away = math.copysign(1.0, x0 - obstacle_x) if x0 != obstacle_x else outward_sign(p)
    steps = np.arange(1, int(CLOSURE_WINDOW_M * 1e3) + 1) * 1e-3
    for d in (away, -away):
        xs = x0 + d * steps
        clear, _ = _idler_blocks(p, xs, np.full(len(xs), p.idler.z_m))
        if clear.any():
            j = int(np.argmax(clear))
            return (f"{'increase' if d > 0 else 'decrease'} x_m by at least "
                    f"{round(steps[j] * 1e3)} mm (x_m {'>=' if d > 0 else '<='} "
                    f"{xs[j]:.3f} m)")
    return (f"no x_m within ±{CLOSURE_WINDOW_M:g} m clears it at z_m = {p.idler.z_m:g} m: "
            "move the idler or that wheel")


def idler_window(p: ModelParams, at: Location) -> tuple[float, float]:
    """The idler abscissae [m] within ±CLOSURE_WINDOW_M of ``x_m`` where the idler clears
    the other wheels (CLEARANCE_M) and stays above the ground line: the contiguous range
    round ``x_m``. ParameterError if the idler at ``x_m`` itself collides."""
    x0 = p.idler.x_m
    xs = np.linspace(x0 - CLOSURE_WINDOW_M, x0 + CLOSURE_WINDOW_M, 1001)
    cz = np.array([idler_center(p, x)[1] for x in xs])
    floor = p.track.pin_radius_m + vertex_radius(p, p.idler.radius_m)
    clear, blocked_by = _idler_blocks(p, xs, cz)
    i0 = len(xs) // 2
    if cz[i0] < floor:       # the centre at x_m is (x_m, z_m): its height is what fixes it
        raise at.error(("idler", "z_m"), p.idler.z_m, f"puts the idler (radius "
                       f"{p.idler.radius_m:g} m) into the ground line (its lowest pin below "
                       f"the road wheels'): raise it by at least "
                       f"{math.ceil((floor - cz[i0]) * 1e3)} mm (z_m >= "
                       f"{math.ceil(floor * 1e3) / 1e3:g} m)")
    if not clear[i0]:
        obstacle_x = next(ox for key, ox, _, _ in _idler_obstacles(p)
                          if key == blocked_by[i0])
        raise at.error(("idler", "x_m"), x0, f"puts the idler (radius {p.idler.radius_m:g} m) "
                       f"into {blocked_by[i0]} (it must keep {CLEARANCE_M * 1e3:g} mm clear "
                       f"of it): {_idler_x_move(p, obstacle_x)}")
    lo = i0
    while lo > 0 and clear[lo - 1]:
        lo -= 1
    hi = i0
    while hi < len(xs) - 1 and clear[hi + 1]:
        hi += 1
    return float(xs[lo]), float(xs[hi])


def check_closure(p: ModelParams, at: Location) -> tuple[float, float]:
    """Refuse a link count that cannot close the loop with the idler in its window
    (:func:`idler_window`): it must lie between the chords that fit round the loop with the
    idler at the window's two ends. Returns the window; the message names what would fit."""
    lo, hi = idler_window(p, at)
    n, pitch = p.track.link_count, p.track.pitch_m
    f_lo, f_hi = sorted((chords_fitting(p, lo), chords_fitting(p, hi)))
    if f_lo <= n <= f_hi:
        return lo, hi
    n_lo, n_hi = math.ceil(f_lo), math.floor(f_hi)
    fits = (f"use {n_lo}–{n_hi} links" if n_lo < n_hi else f"use {n_lo} links"
            if n_lo == n_hi else "no whole link count fits: change pitch_m")
    raise at.error(("track", "link_count"), n,
                   f"links × {pitch:g} m = {n * pitch:.3f} m; this layout needs "
                   f"{f_lo * pitch:.3f}–{f_hi * pitch:.3f} m with the idler x within "
                   f"{lo:.3f}–{hi:.3f} m (±{CLOSURE_WINDOW_M:g} m of [idler].x_m, clear "
                   f"of the other wheels): {fits} or move the idler")


def _closing_idler_x(p: ModelParams, lo: float, hi: float) -> float:
    """The idler x [m] in [lo, hi] where the loop closes (brentq on :func:`closure_gap`);
    ValueError without a sign change in the interval."""
    root = brentq(lambda x: closure_gap(p, x), lo, hi, xtol=1e-12)
    assert isinstance(root, float)  # without full_output brentq returns the root alone
    return root


def idler_strand_directions(p: ModelParams, idler_x: float
                            ) -> tuple[tuple[float, float], tuple[float, float]]:
    """Unit vectors (x, z) along the two straight strands that leave the idler's wrap,
    pointing away from the idler, with the idler at ``idler_x`` [m]: the loop's common
    tangents from the idler to its neighbours (the top strand's sprocket or roller, the
    bottom strand's end road wheel), first the one the loop (clockwise in the x–z view)
    arrives on."""
    circles = _circles(p, idler_x)
    cx, cz, radius = circles[1]
    path = _hull_path(circles)
    sagitta = radius * (1.0 - math.cos(math.pi / HULL_SAMPLES))
    on_idler = np.abs(np.hypot(path[:, 0] - cx, path[:, 1] - cz) - radius) <= sagitta + 1e-9
    following = np.roll(on_idler, -1)
    arrive = np.flatnonzero(~on_idler & following)     # the last point before the wrap
    leave = np.flatnonzero(on_idler & ~following)      # the wrap's last point
    if len(arrive) != 1 or len(leave) != 1:
        raise ValueError("the idler does not wrap the loop once (it is inside the hull)")
    i, j = int(arrive[0]), int(leave[0])
    n = len(path)
    first = path[i] - path[(i + 1) % n]
    second = path[(j + 1) % n] - path[j]
    e1, e2 = first / np.linalg.norm(first), second / np.linalg.norm(second)
    return (float(e1[0]), float(e1[1])), (float(e2[0]), float(e2[1]))


def compute_layout(p: ModelParams) -> Layout:
    """Lay the pins on a closed loop around sprocket, rollers, idler and road wheels,
    moving the idler along its slide until the last chord closes the loop exactly."""
    count = p.track.link_count
    at = p.origin
    lo, hi = p.idler.x_m - CLOSURE_WINDOW_M, p.idler.x_m + CLOSURE_WINDOW_M
    idler_x: float | None
    try:
        idler_x = _closing_idler_x(p, lo, hi)
    except (ValueError, RuntimeError):    # no sign change, or a walk round the loop twice
        idler_x = None
    free = check_closure(p, at)
    if idler_x is None or not free[0] <= idler_x <= free[1]:
        idler_x = _closing_idler_x(p, *free)
    pins = _pins_for(p, idler_x, count)
    sx, sz = p.sprocket.x_m, p.sprocket.z_m
    rp = p.sprocket_pitch_radius_m
    # a pin on the sprocket arc lies on the sampled hull: within its sagitta of the circle
    tolerance = rp * (1.0 - math.cos(math.pi / HULL_SAMPLES)) + 1e-7
    on_arc = [k for k in range(count)
              if abs(math.hypot(pins[k, 0] - sx, pins[k, 1] - sz) - rp) < tolerance]
    if len(on_arc) < MIN_SEATED_PINS:
        raise at.error(("sprocket", "z_m"), sz, f"lets the track wrap the sprocket over "
                       f"{len(on_arc)} seated pins (at least {MIN_SEATED_PINS}): raise the "
                       "sprocket or lower the idler")
    k0 = on_arc[len(on_arc) // 2]
    seat = math.atan2(pins[k0, 1] - sz, pins[k0, 0] - sx)
    circles = _circles(p, idler_x)
    return Layout(
        pins=pins,
        idler_x_m=idler_x,
        sprocket_center=(sx, sz),
        idler_center=idler_center(p, idler_x),
        road_wheel_centers=tuple((c[0], c[1]) for c in circles[2:2 + p.road_wheels.count]),
        roller_centers=tuple((c[0], c[1]) for c in circles[2 + p.road_wheels.count:]),
        sprocket_seat_angle_rad=seat,
    )
