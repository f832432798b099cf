"""Air out of solution below atmospheric (gaseous cavitation): the released-air law against
its hand formula, and a rod node pulled faster than its make-up valve and the main valve
refill it: the oil never goes into tension, the air goes back once the pull stops, and the
energy ledger closes with the air's work booked."""

from __future__ import annotations

import dataclasses
import math

import pytest

from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.hydraulics.kernels import AIR_P_ABS_MIN, released_air

P_ATM = 101325.0
"""Atmospheric pressure [Pa abs] of the shipped hydraulics files."""


def test_released_air_follows_the_isothermal_law_below_atmospheric() -> None:
    """V_g = α·V·(x − b/2)/(p_atm − x) at depth x = −p below atmospheric beyond the onset
    band b: 1 L at −0.05 MPa with α = 0.005, b = 0.01 MPa holds 5e-6·0.045/0.051325 m^3
    = 4.384 mL of air; none at or above atmospheric; and the slope is continuous at both
    ends of the band (the liquid's compliance above, the law's within 0.1 % just beyond)."""
    alpha, band = 0.005, 1e4
    v, dv = released_air(-0.05e6, 1e-3, alpha, band, P_ATM)
    assert v == pytest.approx(5e-6 * 0.045e6 / (P_ATM - 0.05e6), rel=1e-12)
    assert dv < 0.0
    assert released_air(0.0, 1e-3, alpha, band, P_ATM) == (0.0, 0.0)
    assert released_air(2e6, 1e-3, alpha, band, P_ATM) == (0.0, 0.0)
    inside = released_air(-band + 1e-3, 1e-3, alpha, band, P_ATM)
    beyond = released_air(-band - 1e-3, 1e-3, alpha, band, P_ATM)
    assert inside[1] == pytest.approx(beyond[1], rel=1e-3)
    assert released_air(-1e-3, 1e-3, alpha, band, P_ATM)[1] == pytest.approx(0.0, abs=1e-12)
    # near absolute zero the air takes any volume: 1 kPa abs holds ~0.5 L per litre
    assert released_air(-(P_ATM - 1e3), 1e-3, alpha, band, P_ATM)[0] > 0.4e-3


def test_released_air_goes_on_along_its_tangent_past_absolute_zero() -> None:
    """The law V_g ∝ 1/p_abs has no value at absolute zero; below p_abs = AIR_P_ABS_MIN it
    follows its tangent there, so Newton's trial points stay finite: value and slope
    continuous at the switch, and 1 kPa past absolute zero the volume is the tangent's."""
    alpha, band, volume = 0.005, 1e4, 1e-3
    switch = -(P_ATM - AIR_P_ABS_MIN)
    v, dv = released_air(switch, volume, alpha, band, P_ATM)
    below = released_air(switch - 1e-3, volume, alpha, band, P_ATM)
    above = released_air(switch + 1e-3, volume, alpha, band, P_ATM)
    assert below[1] == pytest.approx(dv, rel=1e-9)
    assert above[1] == pytest.approx(dv, rel=1e-4)
    assert above[0] < v < below[0]
    past = -P_ATM - 1e3
    assert released_air(past, volume, alpha, band, P_ATM) == pytest.approx(
        (v + dv * (past - switch), dv), rel=1e-12)
    assert math.isfinite(released_air(-1e9, volume, alpha, band, P_ATM)[0])


def _pull(air_fraction: float, speed_m_s: float = 0.3, start_s: float = 0.06,
          pull_s: float = 0.03, hold_s: float = 0.3) -> tuple[HydraulicTensioner, list[float],
                                                              float, float]:
    """Release mode (rod node fed from the supply through its small rod-feed restrictor,
    heads to tank), the carrier pulled in at speed_m_s [m/s] from start_s [s] (valves
    open) for pull_s [s], then the valves back to hold (rod node open to tank) for hold_s
    [s]; without make-up valves, so the rod chambers' growth 2·A_r·v outruns their feed.
    Returns the element, the rod-node pressure per step [Pa], and at the deepest pressure
    the rod node's volume [m^3] and volume deficit ∫(2·A_r·|v| − Q_in) dt − V·Δp/β [m^3]."""
    p = load_hydraulic_params()
    params = dataclasses.replace(p, cavitation=dataclasses.replace(
        p.cavitation, makeup_area_m2=0.0, air_fraction=air_fraction))
    h, beta = 1e-3, params.fluid.bulk_modulus_Pa
    ht = HydraulicTensioner(params, stroke_m=0.05, dt_s=h)
    ht.set_mode(-1)
    s, p_rod, deficit, deepest = 0.05, [], 0.0, math.inf
    p_start, volume, worst = ht.pressures[3], 0.0, 0.0
    for i in range(round((start_s + pull_s + hold_s) / h)):
        t = i * h
        if abs(t - (start_s + pull_s)) < 0.5 * h:
            ht.set_mode(0)
        v = -speed_m_s if start_s <= t < start_s + pull_s else 0.0
        ht.force_law(t, s, v)
        s_new = s + h * v
        ht.complete_step(t + h, s_new, v)
        rec = ht.record
        q = rec.flows_m3_s
        q_in = q["main_PB"] - q["main_BT"] + q["leak_L"] + q["leak_R"] + q["makeup_rod"]
        deficit += h * (-2.0 * ht.Ar * v - q_in)
        s = s_new
        p_rod.append(rec.p_rod_L_Pa)
        if rec.p_rod_L_Pa < deepest:
            deepest = rec.p_rod_L_Pa
            volume = 2.0 * rec.V_rod_L_m3 + params.lines.line_b_volume_m3
            worst = deficit - volume * (rec.p_rod_L_Pa - p_start) / beta
    return ht, p_rod, volume, worst


def test_a_rod_node_pulled_faster_than_it_refills_fills_with_air_not_tension() -> None:
    """Pulled in at 0.3 m/s for 30 ms in release mode with no make-up valve, the rod
    chambers grow faster than the rod-feed restrictor refills them. With free air
    (α = 0.005) the rod node stays above absolute zero, the air out of solution takes the
    volume deficit (V_g(p_min) equals ∫(2·A_r·|v| − Q_in) dt less the liquid's expansion,
    within 1 %), and once the valves go back to hold the node refills to tank pressure and
    the air goes back (none left). Without free air the same pull puts the oil in tension
    (below −p_atm)."""
    ht, p_rod, volume, deficit = _pull(0.005)
    deepest = min(p_rod)
    band = ht.params.cavitation.air_onset_band_Pa
    air = released_air(deepest, volume, 0.005, band, P_ATM)[0]
    print(f"rod node: deepest {deepest / 1e6:.4f} MPa gauge, air {air * 1e6:.3f} mL against a "
          f"deficit of {deficit * 1e6:.3f} mL; end {p_rod[-1] / 1e6:.3f} MPa; cavitation "
          f"{ht.ledger.cavitation_J:.4f} J")
    assert -P_ATM < deepest < -0.05e6   # well into the air, not into tension
    assert air == pytest.approx(deficit, rel=0.01)
    assert p_rod[-1] == pytest.approx(ht.params.tank_pressure_Pa, rel=0.02)
    assert released_air(p_rod[-1], volume, 0.005, band, P_ATM)[0] == 0.0
    led = ht.ledger
    assert abs(led.balance_error_J) <= 1e-9 * (led.pump_J + abs(led.piston_work_J))
    _, p_liquid, _, _ = _pull(0.0)
    assert min(p_liquid) < -P_ATM
