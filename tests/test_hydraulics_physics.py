"""Analytical checks of the hydraulic plugin against closed-form physics (no mujoco)."""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.optimize import brentq

from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.hydraulics.components import orifice_flow, orifice_gain, series_area

P = load_hydraulic_params()


def _replace(params, **tables):
    """Copy of params with fields of sub-tables replaced: table={field: value}."""
    new = {name: dataclasses.replace(getattr(params, name), **fields)
           for name, fields in tables.items()}
    return dataclasses.replace(params, **new)


def test_orifice_matches_turbulent_formula_far_from_zero() -> None:
    cq, a, rho, pcr = 0.65, 1.1e-7, 860.0, 1e5
    k = orifice_gain(cq, a, rho)
    for dp in (2e6, 5e6, -8e6):
        q, _ = orifice_flow(dp, k, pcr)
        exact = math.copysign(cq * a * math.sqrt(2.0 * abs(dp) / rho), dp)
        # regularisation error is (1 + (p_cr/dp)^2)^(-1/4) - 1 ~ -(p_cr/dp)^2 / 4
        assert q == pytest.approx(exact, rel=0.3 * (pcr / dp) ** 2 + 1e-12)


@given(st.floats(-2e7, 2e7))
def test_orifice_is_odd_monotone_with_exact_derivative(dp: float) -> None:
    k, pcr = 1e-8, 1e5
    q, g = orifice_flow(dp, k, pcr)
    assert orifice_flow(-dp, k, pcr)[0] == pytest.approx(-q, abs=1e-20)
    assert g > 0.0
    e = 1e-3 * max(abs(dp), pcr)
    fd = (orifice_flow(dp + e, k, pcr)[0] - orifice_flow(dp - e, k, pcr)[0]) / (2 * e)
    assert g == pytest.approx(fd, rel=1e-5)


def test_steady_branch_flow_through_valve_and_restrictor_equals_orifice_law() -> None:
    """Pressurize with the piston driven at constant speed: at steady state each head branch
    passes A_h·v, and its pressure drop satisfies Q = Cq·A_eff·sqrt(2Δp/ρ)."""
    # without the hose compliance the head fills in ~0.5 s instead of ~6 s
    prm = _replace(P, cylinder={"leakage_m3_s_Pa": 0.0, "dead_volume_head_m3": 1.5e-4})
    ht = HydraulicTensioner(prm, supply_profile=lambda t: 12e6)
    ht.set_mode(1)
    h, v, s = 1e-3, 1e-3, 0.05   # A_h·v = 1.26e-6 m^3/s, within what one branch passes
    for i in range(5000):   # ~5 time constants of the head filling through the restrictor
        ht.force_law(i * h, s, v)
        s += h * v
        ht.complete_step((i + 1) * h, s, v)
    r = ht.record
    q = r.flows_m3_s["V_L"]
    assert q == pytest.approx(prm.cylinder.area_head_m2 * v, rel=1e-4)
    a_eff = series_area(prm.switching_valves.open_area_m2, prm.metering.head_branch_area_m2)
    dp = r.p_line_A_Pa - r.p_head_L_Pa
    k = orifice_gain(prm.orifice.discharge_coefficient, a_eff, prm.fluid.density_kg_m3)
    assert q == pytest.approx(k * dp / (dp * dp + prm.orifice.critical_pressure_Pa**2) ** 0.25,
                              rel=1e-6)
    turbulent = (q / (prm.orifice.discharge_coefficient * a_eff)) ** 2 * prm.fluid.density_kg_m3 / 2
    assert dp == pytest.approx(turbulent, rel=0.01)


def test_trapped_oil_spring_frequency() -> None:
    """Hold mode (V_L, V_R closed), rods vented freely to tank, no friction or leakage, mass m
    on the rod: ω = sqrt(β·(2·A_h)²/(2·V_h)·/m) = sqrt(2·β·A_h²/(V_h·m)), V_h per head."""
    prm = _replace(P, cylinder={"leakage_m3_s_Pa": 0.0, "coulomb_friction_N": 0.0,
                                "viscous_friction_N_s_m": 0.0},
                   metering={"rod_feed_area_m2": 1e-4},
                   switching_valves={"leak_area_m2": 0.0})
    s0, m, h = 0.05, 500.0, 1e-3   # ω ≈ 69 rad/s with the hose-softened heads: ωh ≈ 0.07
    ht = HydraulicTensioner(prm, supply_profile=lambda t: 12e6, stroke_m=s0)
    ah, beta = prm.cylinder.area_head_m2, prm.fluid.bulk_modulus_Pa
    vh = prm.cylinder.dead_volume_head_m3 + ah * s0
    omega = math.sqrt(2.0 * beta * ah**2 / (vh * m))
    f_ext = -ht.force_law(0.0, s0, 0.0).force_N  # balances the static force
    s, v, t = s0, 0.05, 0.0
    crossings = []
    for i in range(1500):
        law = ht.force_law(t, s, v)
        v_new = (v + h * (law.force_N + f_ext) / m) / (1.0 - h * law.damping_N_s_m / m)
        if v > 0.0 >= v_new:  # downward zero crossing, linear interpolation
            crossings.append(t + h * v / (v - v_new))
        v = v_new
        s += h * v
        t = (i + 1) * h
        ht.complete_step(t, s, v)
    periods = [b - a for a, b in itertools.pairwise(crossings)]
    measured = 2.0 * math.pi / (sum(periods) / len(periods))
    print(f"oil spring: expected {omega:.3f} rad/s, measured {measured:.3f} rad/s "
          f"({100 * (measured / omega - 1):+.3f} %), {len(periods)} periods")
    assert len(periods) >= 10
    assert measured == pytest.approx(omega, rel=0.02)


def _fill_supply(prm, p_start: float, duration: float, h: float = 1e-3) -> HydraulicTensioner:
    """Fixed pump + accumulator, hold, every valve leak-free, the relief (cracking at the
    set-point) out of reach: the pump fills the supply node + line A."""
    ht = HydraulicTensioner(prm, supply_model="fixed_relief", setpoint_Pa=6e7,
                            supply_pressure_Pa=p_start)
    for i in range(round(duration / h)):
        ht.force_law(i * h, 0.05, 0.0)
        ht.complete_step((i + 1) * h, 0.05, 0.0)
    return ht


def _sealed(**acc):
    return _replace(P, main_valve={"leak_area_m2": 0.0}, switching_valves={"leak_area_m2": 0.0},
                    accumulator=acc)


def test_pressure_rise_under_constant_inflow_is_beta_over_v_times_q() -> None:
    prm = _sealed(precharge_Pa=9e7)  # gas never compressed: a fixed oil volume
    ht = _fill_supply(prm, 1e6, 0.02)
    vol = prm.supply.line_volume_m3 + prm.lines.line_a_volume_m3
    rate = (ht.record.p_supply_Pa - 1e6) / 0.02
    expected = prm.fluid.bulk_modulus_Pa / vol * prm.fixed_pump.flow_m3_s
    assert rate == pytest.approx(expected, rel=5e-3)


def test_accumulator_follows_polytropic_law() -> None:
    prm = _sealed()
    acc = prm.accumulator
    p_start, duration = 8.5e6, 2.0
    ht = _fill_supply(prm, p_start, duration)
    p_atm, n = acc.atmospheric_pressure_Pa_abs, acc.polytropic_exponent
    c_oil = (prm.supply.line_volume_m3 + prm.lines.line_a_volume_m3) / prm.fluid.bulk_modulus_Pa

    def gas_volume(p: float) -> float:
        return acc.gas_volume_m3 * ((acc.precharge_Pa + p_atm) / (p + p_atm)) ** (1.0 / n)

    pumped = prm.fixed_pump.flow_m3_s * duration  # = oil compression + gas displaced
    expected = brentq(lambda p: c_oil * (p - p_start) + gas_volume(p_start) - gas_volume(p)
                      - pumped, p_start, 5e7)
    p_end = ht.record.p_supply_Pa
    assert p_end == pytest.approx(expected, rel=1e-3)
    assert p_end > 1.1 * p_start  # the gas was really compressed


@pytest.mark.parametrize("supply_Pa", [1e6, 12e6])
def test_pressures_stay_above_floor_under_aggressive_release(supply_Pa: float) -> None:
    """Release against a 30 kN track load: the heads dump to tank, the idler is pushed in
    and the rod side expands; with a 1 MPa supply the rod feed cannot keep up (demand
    ~3.7e-6, feed ~1.5e-6 m^3/s), so only the make-up valves keep the rods above the floor."""
    ht = HydraulicTensioner(supply_profile=lambda t: supply_Pa,
                            head_pressure_Pa=(30e3 + 2 * P.cylinder.area_rod_m2 * 2e5)
                            / (2 * P.cylinder.area_head_m2))
    h, m, k, c = 1e-3, 80.0, 1e6, 5e3
    s, v = 0.05, 0.0
    s_free = s - 30e3 / k
    ht.set_mode(-1)
    lowest = math.inf
    for i in range(4000):   # the metered heads empty at a few mm/s
        law = ht.force_law(i * h, s, v)
        v = (v + h * (law.force_N - k * (s - s_free)) / m) / (1 - h * (law.damping_N_s_m - c) / m)
        s += h * v
        ht.complete_step((i + 1) * h, s, v)
        p = ht.pressures
        assert all(math.isfinite(x) for x in (*p, s, v))
        lowest = min(lowest, *p[:4])
    assert s < 0.05 - 5e-3  # the idler really retracted
    assert lowest >= P.cavitation.floor_Pa
    if supply_Pa < 2e6:
        assert lowest < P.tank_pressure_Pa - P.cavitation.makeup_crack_below_tank_Pa
