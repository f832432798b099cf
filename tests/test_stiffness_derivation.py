"""Stiffness of a track's parts (trackmj/machines/stiffness.py, issue 30): the formulas
against hand-computed numbers, an independent quadrature of the half-space, units and
monotonicity. Steel: E 210 GPa, ν 0.3, so E* = E/(2(1 − ν²)) = 1.15385e11 Pa."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from trackmj.machines.stiffness import (
    STEEL_E_PA,
    STEEL_NU,
    Body,
    PinJoint,
    effective_modulus,
    half_width,
    line_contact,
    pin_joint_stiffness,
    pin_shear_bending_compliance,
    plate_tension_stiffness,
    shear_coefficient,
)

LF1352_JOINT = PinJoint(pitch_m=0.075, pin_diameter_m=0.0168, bushing_bore_clearance_m=0.15e-3,
                        plate_thickness_m=0.012, plate_height_m=0.024)


def test_plate_tension_by_hand() -> None:
    """A 12 x 24 mm steel plate over a 75 mm pitch: 210e9 * 2.88e-4 / 0.075 = 8.064e8 N/m."""
    assert plate_tension_stiffness(0.012 * 0.024, 0.075) == pytest.approx(8.064e8, rel=1e-12)


def test_steel_on_steel_modulus_and_half_width_by_hand() -> None:
    """Johnson ch. 4: E* = 1/(2 * 0.91 / 210e9) = 1.15385e11 Pa; a steel roller of R 10 mm on
    a flat at 100 kN/m: a = sqrt(4 * 1e5 * 0.01 / (pi * 1.15385e11)) = 0.105046 mm."""
    steel = Body(0.01)
    assert effective_modulus(steel, steel) == pytest.approx(1.153846e11, rel=1e-6)
    a = half_width(1e5, 1.0, steel, Body(None, depth_m=1.0))
    assert a == pytest.approx(1.050464e-4, rel=1e-6)


def test_two_cylinders_approach_by_hand() -> None:
    """Two steel rollers of R 10 mm, 100 kN/m (Johnson's two-cylinder formula): R = 5 mm,
    a = sqrt(4 * 1e5 * 0.005 / (pi * 1.15385e11)) = 74.279 um, each axis approaches by
    1e5 * 0.91/(pi * 210e9) * (2 ln(0.04/a) - 1) = 1.59695 um: 3.19390 um, 3.1310e10 N/m per
    metre of length (secant)."""
    c = line_contact(1e5, 1.0, Body(0.01), Body(0.01))
    assert c.half_width_m == pytest.approx(7.427901e-5, rel=1e-6)
    assert c.approach_m == pytest.approx(3.193899e-6, rel=1e-6)
    assert c.secant_N_m == pytest.approx(3.130969e10, rel=1e-6)


def test_flat_datum_term_against_quadrature_of_the_half_space() -> None:
    """The flat body's approach 2P'(1-ν²)/(πE) (ln(2d/a) + 1/2) against Johnson ch. 2's
    surface displacement of a half-space, u(x) = -2(1-ν²)/(πE) ∫ p(t) ln|x - t| dt,
    integrated numerically for the Hertz pressure: u(0) - u(d). With d = 50 a the neglected
    terms are O((a/d)²) = 4e-4 of the log; the quadrature (Chebyshev nodes of the second kind,
    exact for the √(a² - t²) weight) is converged to 1e-6; bound 1e-3."""
    load, a, depth = 1e5, 1e-4, 5e-3
    n = 4000
    theta = np.pi * (np.arange(1, n + 1)) / (n + 1)
    t = a * np.cos(theta)
    weights = np.pi / (n + 1) * np.sin(theta) ** 2 * 2.0 / np.pi   # Σ = 1: p(t) dt / P'

    def log_potential(x: float) -> float:
        return float(np.sum(weights * np.log(np.abs(x - t))))

    scale = 2.0 * (1.0 - STEEL_NU ** 2) / (math.pi * STEEL_E_PA)
    numeric = -scale * load * (log_potential(0.0) - log_potential(depth))
    closed = scale * load * (math.log(2.0 * depth / a) + 0.5)
    assert numeric == pytest.approx(closed, rel=1e-3)


def test_tangent_is_the_derivative_of_the_approach() -> None:
    """dP/dδ by central differences of δ(P) (step 1e-4 P: truncation ~1e-8) on the LF1352
    wheel-on-rail contact; the closed-form tangent agrees to 1e-6."""
    wheel, rail = Body(0.11), Body(None, depth_m=0.024)
    p, dp = 2905.0, 0.2905
    slope = 2.0 * dp / (line_contact(p + dp, 0.045, wheel, rail).approach_m
                        - line_contact(p - dp, 0.045, wheel, rail).approach_m)
    assert line_contact(p, 0.045, wheel, rail).tangent_N_m == pytest.approx(slope, rel=1e-6)


def test_same_number_in_millimetres_newtons_and_megapascals() -> None:
    """No SI constant hides in the formulas: in mm, N and MPa (N/mm²) the stiffness comes out
    in N/mm, 1e-3 of the SI value."""
    si = line_contact(2905.0, 0.045, Body(0.11), Body(None, depth_m=0.024)).secant_N_m
    mm = line_contact(2905.0, 45.0, Body(110.0, modulus_Pa=STEEL_E_PA * 1e-6),
                      Body(None, modulus_Pa=STEEL_E_PA * 1e-6, depth_m=24.0)).secant_N_m
    assert mm == pytest.approx(si * 1e-3, rel=1e-12)
    k_si = 1.0 / pin_shear_bending_compliance(0.0168, 0.012)
    k_mm = 1.0 / pin_shear_bending_compliance(16.8, 12.0, modulus_Pa=STEEL_E_PA * 1e-6)
    assert k_mm == pytest.approx(k_si * 1e-3, rel=1e-12)


def test_line_contact_stiffens_with_load_length_and_modulus() -> None:
    """Hertz line contact: the half-width grows as sqrt(P), so the log terms shrink and the
    secant stiffness rises with load; longer contacts and stiffer materials are stiffer;
    the tangent exceeds the secant (the curve is concave in δ)."""
    wheel, rail = Body(0.11), Body(None, depth_m=0.024)
    loads = [500.0, 1000.0, 3000.0, 10000.0]
    secants = [line_contact(p, 0.045, wheel, rail).secant_N_m for p in loads]
    assert all(b > a for a, b in itertools.pairwise(secants))
    assert line_contact(3000.0, 0.09, wheel, rail).secant_N_m > secants[2]
    soft = line_contact(3000.0, 0.045, Body(0.11, modulus_Pa=7e10),
                        Body(None, modulus_Pa=7e10, depth_m=0.024))
    assert soft.secant_N_m < secants[2]
    c = line_contact(3000.0, 0.045, wheel, rail)
    assert c.tangent_N_m > c.secant_N_m


def test_pin_shear_and_bending_by_hand() -> None:
    """Pin d 16.8 mm across a 12 mm gap: I = π d⁴/64 = 3.9103e-9 m⁴, A = 2.2167e-4 m²,
    G = 210e9/2.6, κ = 6 * 1.3 / 8.8 = 0.88636 (Cowper); e³/(12EI) = 1.7536e-10 m/N,
    e/(κGA) = 7.5616e-10 m/N; sum 9.3152e-10 m/N."""
    assert shear_coefficient(0.3) == pytest.approx(0.886364, rel=1e-6)
    assert pin_shear_bending_compliance(0.0168, 0.012) == pytest.approx(9.31524e-10, rel=1e-5)


def test_pin_joint_is_its_parts_in_series() -> None:
    """One LF1352 pitch at 15 kN: two plates 2 * 8.064e8, two pins 2/9.3152e-10, two bore
    contacts; the total is below its softest part, stiffens with load (the bore contact's
    half-width grows) and with a tighter bore."""
    k = pin_joint_stiffness(LF1352_JOINT, 15e3)
    assert k.plates_N_m == pytest.approx(1.6128e9, rel=1e-9)
    assert k.pin_N_m == pytest.approx(2.0 / 9.31524e-10, rel=1e-5)
    by_hand = 1.0 / (1.0 / k.plates_N_m + 1.0 / k.pin_N_m + 1.0 / k.bore_contact_N_m)
    assert k.total_N_m == pytest.approx(by_hand, rel=1e-12)
    assert k.total_N_m < min(k.plates_N_m, k.pin_N_m, k.bore_contact_N_m)
    assert pin_joint_stiffness(LF1352_JOINT, 30e3).total_N_m > k.total_N_m
    tight = PinJoint(0.075, 0.0168, 0.05e-3, 0.012, 0.024)
    assert pin_joint_stiffness(tight, 15e3).bore_contact_N_m > k.bore_contact_N_m


def test_refuses_what_the_formulas_do_not_cover() -> None:
    """A bore smaller than its pin is not a contact; a flat's datum inside the contact
    half-width gives no log term; loads must be positive."""
    with pytest.raises(ValueError, match="convex"):
        line_contact(1e3, 0.01, Body(0.01), Body(-0.009))
    with pytest.raises(ValueError, match="datum"):
        line_contact(1e4, 0.01, Body(0.3, modulus_Pa=1e7), Body(None, depth_m=0.01))
    with pytest.raises(ValueError, match="positive"):
        line_contact(0.0, 0.01, Body(0.01), Body(0.01))
