"""Initial layout of the track loop: 82 pitch-length chords around sprocket, idler, road
wheels and return rollers, with the idler moved until the loop closes exactly.

Coordinates are world (x forward, z up) [m] at the initial, undeformed state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.spatial import ConvexHull

from trackmj.model.params import ModelParams
from trackmj.params import ParameterError


@dataclass(frozen=True)
class Layout:
    """Initial pin positions (world x, z) [m], shape (82, 2), and wheel centres."""

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


def _circles(p: ModelParams, idler_x: float) -> list[tuple[float, float, float]]:
    """Pin-vertex circles (x, z, radius) around which the loop is laid."""
    r_pin = p.track.pin_radius_m
    rw_v = vertex_radius(p, p.road_wheels.radius_m)
    circles = [(p.sprocket.x_m, p.sprocket.z_m, p.sprocket_pitch_radius_m),
               (idler_x, p.idler.z_m, vertex_radius(p, p.idler.radius_m))]
    circles += [(x, r_pin + rw_v, rw_v) for x in p.road_wheels.x_m]
    rr_v = vertex_radius(p, p.return_rollers.radius_m)
    circles += [(x, p.return_rollers.z_m, rr_v) for x in p.return_rollers.x_m]
    return circles


def _hull_path(circles: list[tuple[float, float, float]], samples: int = 2880) -> np.ndarray:
    """Closed convex path around the circles, clockwise in the (x, z) view, starting at the
    bottom. Returns (n, 2) points; the path is sampled finely enough (< 1e-7 m chord error
    at these radii) to walk chords on it."""
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


def compute_layout(p: ModelParams) -> Layout:
    """Lay the 82 pins on a closed loop around sprocket, rollers, idler and road wheels,
    moving the idler along x so that the last chord closes the loop exactly."""
    count, pitch = p.track.link_count, p.track.pitch_m
    r_pin = p.track.pin_radius_m

    def pins_for(idler_x: float, n_points: int = count) -> np.ndarray:
        path = _hull_path(_circles(p, idler_x))
        # start on the bottom strand at x = pitch/2 (between the middle road wheels)
        start_x = 0.5 * pitch
        bottom = np.argmin(np.abs(path[:, 0] - start_x) + 10.0 * np.abs(path[:, 1] - r_pin))
        path = np.roll(path, -bottom, axis=0)
        if path[1, 0] > path[0, 0]:
            raise RuntimeError("hull orientation unexpected")
        path = np.concatenate([[[start_x, r_pin]], path[1:]])
        return _walk_chords(path, pitch, n_points)

    def closure_gap(idler_x: float) -> float:
        # pin 82 (one chord past the last) must land on pin 0; both lie on the bottom strand,
        # which runs in -x, so the gap along it is x_82 - x_0 (> 0: loop too long)
        pins = pins_for(idler_x, count + 1)
        return float(pins[-1, 0] - pins[0, 0])

    lo, hi = p.idler.x_m - 0.5, p.idler.x_m + 0.5
    try:
        idler_x = brentq(closure_gap, lo, hi, xtol=1e-12)
    except ValueError:
        raise ParameterError("lf1352.toml: no idler position within ±0.5 m of [idler].x_m "
                             "closes the track loop; adjust pitch, link count or geometry") \
            from None
    pins = pins_for(idler_x)
    sx, sz = p.sprocket.x_m, p.sprocket.z_m
    rp = p.sprocket_pitch_radius_m
    on_arc = [k for k in range(count)
              if abs(math.hypot(pins[k, 0] - sx, pins[k, 1] - sz) - rp) < 1e-7]
    if not on_arc:
        raise ParameterError("lf1352.toml: the track does not wrap the sprocket")
    k0 = on_arc[len(on_arc) // 2]
    seat = math.atan2(pins[k0, 1] - sz, pins[k0, 0] - sx)
    circles = _circles(p, idler_x)
    return Layout(
        pins=pins,
        idler_x_m=idler_x,
        sprocket_center=(sx, sz),
        idler_center=(idler_x, p.idler.z_m),
        road_wheel_centers=tuple((c[0], c[1]) for c in circles[2:2 + p.road_wheels.count]),
        roller_centers=tuple((c[0], c[1]) for c in circles[2 + p.road_wheels.count:]),
        sprocket_seat_angle_rad=seat,
    )

