"""Stiffness of a track's parts from their geometry and material: the pin joint, the
wheel on the link rail and the sprocket tooth on the pin (issue 30).

Pure functions (numpy/math only). Units SI: lengths [m], forces [N], moduli [Pa],
stiffnesses [N/m], compliances [m/N]. Sources:

* Johnson, K. L., *Contact Mechanics*, Cambridge University Press 1985, ch. 4 (Hertz
  theory), two-dimensional contact of cylinders, pp. 99–104: half-width
  a² = 4·P'·R/(π·E*), P' the load per unit length, 1/R = 1/R₁ + 1/R₂,
  1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂, and the approach of a cylinder's axis (radius R)
  to the contact, δ_cyl = P'·(1 − ν²)/(π·E)·(2·ln(4R/a) − 1) (the form compared with other
  cylinder-contact laws by Pereira, Ramalho & Ambrósio, Nonlinear Dynamics 63 (2011)
  681–697); ch. 2 (line loading of a half-space: the surface displacement falls as
  −2·(1 − ν²)·P'/(π·E)·ln r, so a two-dimensional approach needs a datum).
* Roark's Formulas for Stress and Strain (Young & Budynas, 7th ed., 2002), Table 8.1
  (beam deflections) and ch. 8 (shear deflection); Cowper, G. R., "The shear coefficient in
  Timoshenko's beam theory", J. Appl. Mech. 33 (1966) 335–340: κ = 6(1 + ν)/(7 + 6ν) for a
  solid circular section.

The flat body (a link rail under a wheel) has no radius: its approach is taken relative to
a datum on its surface at a distance ``depth`` from the contact centre (the rail's depth
under the tread). For the Hertz pressure p(x) = (2P'/(π·a²))·sqrt(a² − x²), the
half-space's surface displacement (Johnson ch. 2) integrates to

    δ_flat = 2·P'·(1 − ν²)/(π·E)·(ln(2·depth/a) + 1/2)          (depth ≫ a),

derived here (the mean of ln|t| over the Hertz distribution is ln(a/2) − 1/2). A
cylinder's term uses Johnson's formula above. Both terms are logarithmic in the
datum, so a factor 2 in ``depth`` moves the flat term by ln 2 (about 10 % of it here).

Linearisation: the model's contacts are linear springs from first touch, F = K·δ, so
the value for the model file is the secant K = P/δ(P) at a stated reference load (the
static deflection there is then right); :func:`line_contact` also gives the tangent
dP/dδ, which is 10–15 % higher at the loads of the shipped machines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

STEEL_E_PA = 2.1e11
"""Young's modulus of structural steel [Pa] (Roark, Table A.5: 200–207 GPa; 210 GPa EN 1993)."""
STEEL_NU = 0.3
"""Poisson's ratio of steel [-]."""


@dataclass(frozen=True)
class Body:
    """One body of a line contact: ``radius_m`` > 0 a convex cylinder, < 0 a concave bore
    of that radius, ``None`` a flat surface whose approach is taken to a datum
    ``depth_m`` away; ``modulus_Pa`` E, ``poisson`` ν."""

    radius_m: float | None
    modulus_Pa: float = STEEL_E_PA
    poisson: float = STEEL_NU
    depth_m: float = 0.0


@dataclass(frozen=True)
class LineContact:
    """A line contact at load ``load_N`` [N] over ``length_m`` [m]: half-width a [m],
    approach δ [m], secant P/δ and tangent dP/dδ stiffness [N/m]."""

    load_N: float
    length_m: float
    half_width_m: float
    approach_m: float
    secant_N_m: float
    tangent_N_m: float


def effective_modulus(first: Body, second: Body) -> float:
    """E* [Pa]: 1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂ (Johnson ch. 4)."""
    return 1.0 / ((1.0 - first.poisson ** 2) / first.modulus_Pa
                  + (1.0 - second.poisson ** 2) / second.modulus_Pa)


def relative_radius(first: Body, second: Body) -> float:
    """R [m]: 1/R = 1/R₁ + 1/R₂ (a bore's radius negative, a flat's curvature 0)."""
    curvature = sum(1.0 / b.radius_m for b in (first, second) if b.radius_m is not None)
    if curvature <= 0.0:
        raise ValueError("the contact is not convex: a bore must be larger than its pin")
    return 1.0 / curvature


def half_width(load_N: float, length_m: float, first: Body, second: Body) -> float:
    """Hertz half-width a = sqrt(4·P'·R/(π·E*)) [m], P' = load/length (Johnson ch. 4)."""
    per_length = load_N / length_m
    return math.sqrt(4.0 * per_length * relative_radius(first, second)
                     / (math.pi * effective_modulus(first, second)))


def _approach_terms(body: Body, a: float) -> tuple[float, float]:
    """(secant, tangent) compliance per unit length of ``body``'s approach [m²/N]:
    δ_i = P'·c_s, dδ_i/dP' = c_t (a ∝ sqrt(P'), so d ln(1/a)/dP' = −1/(2P'))."""
    scale = (1.0 - body.poisson ** 2) / (math.pi * body.modulus_Pa)
    if body.radius_m is None:
        if body.depth_m <= a:
            raise ValueError(f"flat body: datum depth {body.depth_m:g} m must exceed the "
                             f"contact half-width {a:g} m")
        log = math.log(2.0 * body.depth_m / a)
        return 2.0 * scale * (log + 0.5), 2.0 * scale * log
    log = math.log(4.0 * abs(body.radius_m) / a)
    return scale * (2.0 * log - 1.0), scale * (2.0 * log - 2.0)


def line_contact(load_N: float, length_m: float, first: Body, second: Body) -> LineContact:
    """Approach and stiffness of two bodies in line contact under ``load_N`` over
    ``length_m`` (module docstring: Johnson ch. 4; the flat's datum term)."""
    if load_N <= 0.0 or length_m <= 0.0:
        raise ValueError("load and length must be positive")
    a = half_width(load_N, length_m, first, second)
    secant = tangent = 0.0
    for body in (first, second):
        s, t = _approach_terms(body, a)
        secant += s
        tangent += t
    approach = load_N / length_m * secant
    return LineContact(load_N, length_m, a, approach, load_N / approach, length_m / tangent)


def plate_tension_stiffness(area_m2: float, length_m: float,
                            modulus_Pa: float = STEEL_E_PA) -> float:
    """E·A/L [N/m] of a bar of section ``area_m2`` and length ``length_m``."""
    return modulus_Pa * area_m2 / length_m


def shear_coefficient(poisson: float = STEEL_NU) -> float:
    """Timoshenko shear coefficient of a solid circle, κ = 6(1 + ν)/(7 + 6ν) (Cowper 1966)."""
    return 6.0 * (1.0 + poisson) / (7.0 + 6.0 * poisson)


def pin_shear_bending_compliance(diameter_m: float, lever_m: float,
                                 modulus_Pa: float = STEEL_E_PA,
                                 poisson: float = STEEL_NU) -> float:
    """Compliance [m/N] of a pin of ``diameter_m`` carrying a load across a gap ``lever_m``
    between two plates that each hold its slope (clamped–guided beam, Roark Table 8.1):
    e³/(12·E·I) + e/(κ·G·A), I = π·d⁴/64, A = π·d²/4, G = E/(2(1 + ν))."""
    inertia = math.pi * diameter_m ** 4 / 64.0
    area = math.pi * diameter_m ** 2 / 4.0
    shear_modulus = modulus_Pa / (2.0 * (1.0 + poisson))
    return (lever_m ** 3 / (12.0 * modulus_Pa * inertia)
            + lever_m / (shear_coefficient(poisson) * shear_modulus * area))


@dataclass(frozen=True)
class PinJoint:
    """One pitch of a steel pin-and-bushing chain (both chain sides), dimensions [m].

    pitch_m: pin-to-pin; pin_diameter_m; bushing_bore_clearance_m: radial clearance of
    the pin in the bushing bore; plate_thickness_m: each link plate's thickness across the
    track (also the gap between the mid-planes of an outer and an inner plate, and the
    length over which the pin bears in the bushing at each side); plate_height_m: the
    plate's web depth in the pitch plane. Steel throughout.
    """

    pitch_m: float
    pin_diameter_m: float
    bushing_bore_clearance_m: float
    plate_thickness_m: float
    plate_height_m: float


@dataclass(frozen=True)
class PinJointStiffness:
    """Radial stiffness of one pitch [N/m] and its three series parts (both sides)."""

    plates_N_m: float
    pin_N_m: float
    bore_contact_N_m: float

    @property
    def total_N_m(self) -> float:
        return 1.0 / (1.0 / self.plates_N_m + 1.0 / self.pin_N_m
                      + 1.0 / self.bore_contact_N_m)


def pin_joint_stiffness(joint: PinJoint, tension_N: float) -> PinJointStiffness:
    """Stiffness of one pitch under chain tension ``tension_N`` [N], both sides in parallel,
    three parts in series:

    * plates: the link's two plates in tension, 2·E·t·h/p;
    * pin: each side's pin carries T/2 across the gap t between the outer plate (pin pressed
      in) and the inner plate (bushing pressed in), bending and shear of a clamped–guided
      beam (:func:`pin_shear_bending_compliance`);
    * bore contact: each side's pin bears on the bushing bore (radius r + clearance) over
      the length t, Johnson's line contact at T/2 (secant; the bore's log term is taken
      with its own radius, the formula's convex-cylinder form).
    """
    t, h, d = joint.plate_thickness_m, joint.plate_height_m, joint.pin_diameter_m
    plates = 2.0 * plate_tension_stiffness(t * h, joint.pitch_m)
    pin = 2.0 / pin_shear_bending_compliance(d, t)
    r = d / 2.0
    bore = line_contact(tension_N / 2.0, t, Body(r),
                        Body(-(r + joint.bushing_bore_clearance_m)))
    return PinJointStiffness(plates, pin, 2.0 * bore.secant_N_m)
