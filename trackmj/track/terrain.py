"""ISO 8608 random road profiles and MuJoCo heightfield arrays (numpy only, no MuJoCo).

ISO 8608:2016 describes road roughness by the one-sided displacement PSD over spatial
frequency n [cycles/m]:

    G_d(n) = G_d(n0) · (n / n0)^(−w),   n0 = 0.1 cycles/m,  w = 2,

with G_d(n0) [m³] the geometric mean of the class (A 16e-6 ... H 262144e-6, a factor 4 per
class). :func:`road_profile` synthesises a profile as a sum of harmonics on the FFT grid of
the road length L (spacing Δn = 1/L) with deterministic amplitudes sqrt(2·G_d(n_k)·Δn) and
seeded uniform random phases (ISO 8608 Annex, random-phase method), restricted to a band
[n_min, n_max]; the profile is periodic in L. At a driving speed v a spatial frequency n
becomes a temporal frequency f = v·n, and the temporal PSD is G_d(f/v)/v.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trackmj.validator import ParameterError

N0_CYCLES_M = 0.1
"""ISO 8608 reference spatial frequency n0 [cycles/m]."""

WAVINESS = 2.0
"""ISO 8608 waviness w (slope of log G_d over log n is −w)."""

ISO8608_GD_N0_M3: dict[str, float] = {
    cls: 16e-6 * 4.0**i for i, cls in enumerate("ABCDEFGH")
}
"""Geometric-mean G_d(n0) [m³] per ISO 8608 class: A 16e-6, B 64e-6, ..., H 262144e-6."""


def _gd_n0(road_class: str) -> float:
    if not isinstance(road_class, str) or road_class.upper() not in ISO8608_GD_N0_M3:
        raise ValueError(f"ISO 8608 road class must be one of A-H, got {road_class!r}")
    return ISO8608_GD_N0_M3[road_class.upper()]


def iso8608_psd(n_cycles_m: np.ndarray | float, road_class: str) -> np.ndarray:
    """One-sided displacement PSD G_d(n) [m³] of ``road_class`` at n [cycles/m]."""
    n = np.asarray(n_cycles_m, dtype=float)
    return _gd_n0(road_class) * (n / N0_CYCLES_M) ** (-WAVINESS)


def band_rms_m(road_class: str, n_min: float, n_max: float) -> float:
    """Expected RMS height [m] of a class-``road_class`` profile band-limited to [n_min, n_max]."""
    gd = _gd_n0(road_class)
    return float(np.sqrt(gd * N0_CYCLES_M**2 * (1.0 / n_min - 1.0 / n_max)))


@dataclass(frozen=True)
class RoadProfile:
    """Road heights ``z_m`` [m], shape (n,), at x = ``x_start_m`` + i·``dx_m`` [m]."""

    x_start_m: float
    dx_m: float
    z_m: np.ndarray

    @property
    def x_m(self) -> np.ndarray:
        """Grid positions [m], shape (n,)."""
        return self.x_start_m + self.dx_m * np.arange(len(self.z_m))


def road_profile(length_m: float, dx_m: float, road_class: str,
                 rng: np.random.Generator | int, *, n_min: float = 0.011, n_max: float = 2.83,
                 x_start_m: float = 0.0) -> RoadProfile:
    """Random ISO 8608 road profile of ``road_class`` (A-H) on a uniform grid.

    length_m: road length L [m] (grid of round(L/dx) points, periodic in L); dx_m: spacing [m];
    rng: numpy Generator or integer seed (same seed -> identical profile); n_min, n_max: band
    [cycles/m] of the harmonics (defaults: ISO 8608's 0.011-2.83; n_max <= 1/(2·dx)).
    Heights have zero mean.
    """
    gd = _gd_n0(road_class)
    if not (length_m > 0.0 and dx_m > 0.0):
        raise ValueError(f"length_m = {length_m} and dx_m = {dx_m} must be > 0")
    npts = round(length_m / dx_m)
    if npts < 4:
        raise ValueError(f"length_m / dx_m = {length_m / dx_m:g} gives fewer than 4 points")
    nyquist = 0.5 / dx_m
    if not (0.0 < n_min < n_max <= nyquist * (1 + 1e-12)):
        raise ValueError(f"need 0 < n_min < n_max <= 1/(2 dx) = {nyquist:g} cycles/m, "
                         f"got n_min = {n_min}, n_max = {n_max}")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    dn = 1.0 / (npts * dx_m)
    n = np.arange(npts // 2 + 1) * dn
    inband = (n >= n_min) & (n <= n_max)
    amplitude = np.zeros_like(n)
    amplitude[inband] = np.sqrt(2.0 * gd * (n[inband] / N0_CYCLES_M) ** (-WAVINESS) * dn)
    phase = rng.uniform(0.0, 2.0 * np.pi, size=n.shape)
    spectrum = 0.5 * npts * amplitude * np.exp(1j * phase)
    if npts % 2 == 0:
        spectrum[-1] = 0.0  # the Nyquist bin of a real signal cannot carry a phase
    z = np.fft.irfft(spectrum, npts)
    return RoadProfile(float(x_start_m), float(dx_m), z)


def taper_start(profile: RoadProfile, flat_until_m: float, taper_m: float, *,
                both_ways: bool = False) -> RoadProfile:
    """Profile held at 0 for x <= flat_until_m, blended in by a raised cosine over taper_m [m]
    (``both_ways``: for |x| <= flat_until_m, blended in over taper_m on either side).

    Lets a vehicle start its run on level ground under its home layout, whichever way it
    drives off.
    """
    x = np.abs(profile.x_m) if both_ways else profile.x_m
    s = np.clip((x - flat_until_m) / max(taper_m, 1e-12), 0.0, 1.0)
    return RoadProfile(profile.x_start_m, profile.dx_m,
                       profile.z_m * 0.5 * (1.0 - np.cos(np.pi * s)))


@dataclass(frozen=True)
class Heightfield:
    """MuJoCo heightfield for a planar road (constant across y).

    data: elevation, shape (nrow, ncol), in [0, 1]; rows run along y, columns along x
    (MuJoCo ``hfield`` layout). size: (radius_x, radius_y, elevation_z, base_z) [m] for the
    ``hfield`` element. pos: (x, y, z) [m] of the ``geom``: the field centre, with z the
    lowest road height so that world height = pos_z + data·elevation_z.
    """

    data: np.ndarray
    size: tuple[float, float, float, float]
    pos: tuple[float, float, float]


def heightfield(profile: RoadProfile, *, width_m: float = 2.0, nrow: int = 2,
                base_m: float = 0.5) -> Heightfield:
    """Heightfield arrays for ``profile`` (same convention as
    ``trackmj.track.mjcf.builders.with_heightfield``).

    width_m: extent across the track [m]; nrow: rows along y (>= 2); base_m: depth of the
    box below the lowest point [m]. A flat profile gets elevation_z = 1e-6 m (MuJoCo needs > 0).
    """
    if nrow < 2:
        raise ValueError(f"nrow = {nrow} must be >= 2")
    z = np.asarray(profile.z_m, dtype=float)
    low, high = float(z.min()), float(z.max())
    span = max(high - low, 1e-6)
    length = profile.dx_m * (len(z) - 1)
    data = np.tile((z - low) / span, (nrow, 1))
    return Heightfield(data=data, size=(length / 2.0, width_m / 2.0, span, base_m),
                       pos=(profile.x_start_m + length / 2.0, 0.0, low))


def gravity_on_grade(gravity: Sequence[float], grade: float) -> tuple[float, float, float]:
    """Gravity [m/s²] on a slope of ``grade`` = tan θ [-] (rise over run, > 0 uphill driving
    forward, +x): ``gravity``'s magnitude g tilted by θ in the x–z plane, g·(−sin θ, 0,
    −cos θ); the ground stays the model's x axis."""
    g, theta = math.hypot(*gravity), math.atan(grade)
    return (-g * math.sin(theta), 0.0, -g * math.cos(theta))


def check_grade_held(grade: float, ground_friction: float, given: str, where: str) -> None:
    """ParameterError (``given``, e.g. "W1.toml [terrain].grade = ", then the grade) unless
    |tan θ| < μ, ``where`` naming the key μ comes from: on a steeper slope no track holds,
    the machine slides down whatever the sprocket does (Coulomb)."""
    if abs(grade) >= ground_friction:
        raise ParameterError(
            f"{given}{grade:g}: a slope of tan θ = {abs(grade):g} is at or past the "
            f"ground's friction μ = {ground_friction:g} ({where}), so no track holds on it "
            f"and the machine would slide down; allowed |grade| < {ground_friction:g}")
