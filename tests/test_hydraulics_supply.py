"""Supply models against hand-derived results (no mujoco): the relief's loss at the pump
flow, the compensated pump's droop, standby and energy for a known demand and its fall after
a set-point drop, the unloading valve's charge / discharge times and energies, and the
ledger chain from the pump shaft to the circuit for every model."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.hydraulics.components import (
    accumulator_oil_volume,
    orifice_flow,
    orifice_gain,
    series_area,
    smoothstep,
)
from trackmj.hydraulics.kernels import LEDGER_FIELDS

P = load_hydraulic_params()
H = 1e-3


def _replace(params, **tables):
    """Copy of params with fields of sub-tables replaced: table={field: value}."""
    new = {name: dataclasses.replace(getattr(params, name), **fields)
           for name, fields in tables.items()}
    return dataclasses.replace(params, **new)


def _drawn(main_leak_m2: float):
    """Hold mode, every leak closed except the main valve's two closed edges of
    ``main_leak_m2`` (A->T, and P->B with the rod-feed restrictor in series): a demand from
    the supply node straight to tank; no cylinder leakage."""
    return _replace(P, main_valve={"leak_area_m2": main_leak_m2},
                    switching_valves={"leak_area_m2": 0.0}, cylinder={"leakage_m3_s_Pa": 0.0})


def _demand(prm, p_s: float) -> float:
    """Flow [m^3/s] out of the supply node through ``_drawn``'s leaks at p_s [Pa] (line A at
    p_s and the rod node at p_t: both behind fully open 1e-4 m^2 edges)."""
    cq, rho = prm.orifice.discharge_coefficient, prm.fluid.density_kg_m3
    a = prm.main_valve.leak_area_m2
    k = orifice_gain(cq, a, rho) + orifice_gain(cq, series_area(a, prm.metering.rod_feed_area_m2),
                                                  rho)
    return orifice_flow(p_s - prm.tank_pressure_Pa, k, prm.orifice.critical_pressure_Pa)[0]


def _hold(ht: HydraulicTensioner, seconds: float, t0: float = 0.0) -> None:
    for i in range(round(seconds / H)):
        ht.force_law(t0 + i * H, 0.05, 0.0)
        ht.complete_step(t0 + (i + 1) * H, 0.05, 0.0)


@pytest.mark.parametrize("setpoint_Pa", [12e6, 9e6])
def test_relief_passes_the_fixed_pump_flow_with_the_hand_derived_loss(setpoint_Pa) -> None:
    """fixed_relief, no demand: at steady state the whole pump flow Q_d crosses the relief at
    p* with Q_d = s((p* − p_set)/band)·Q_orifice(p* − p_t); loss p*·Q_d, shaft
    p*·Q_d/(η_v·η_hm)."""
    prm = _drawn(0.0)
    rel, fp = prm.relief, prm.fixed_pump
    k = orifice_gain(prm.orifice.discharge_coefficient, rel.full_area_m2,
                     prm.fluid.density_kg_m3)

    def relief_flow(p: float) -> float:
        s = smoothstep((p - setpoint_Pa) / rel.band_Pa)[0]
        return s * orifice_flow(p - prm.tank_pressure_Pa, k, prm.orifice.critical_pressure_Pa)[0]

    p_star = brentq(lambda p: relief_flow(p) - fp.flow_m3_s, setpoint_Pa + 1.0,
                    setpoint_Pa + rel.band_Pa)
    ht = HydraulicTensioner(prm, supply_model="fixed_relief", setpoint_Pa=setpoint_Pa)
    _hold(ht, 3.0)                      # ~20 time constants of accumulator vs relief
    before = ht.ledger.terms.copy()
    _hold(ht, 1.0, 3.0)
    d = dict(zip(LEDGER_FIELDS, (ht.ledger.terms - before).tolist(), strict=True))
    print(f"p_set {setpoint_Pa / 1e6} MPa: p* {p_star / 1e6:.5f} MPa, simulated "
          f"{ht.pressures[4] / 1e6:.5f} MPa; relief {d['relief_J']:.3f} J/s")
    assert ht.pressures[4] == pytest.approx(p_star, rel=1e-6)
    assert d["relief_J"] == pytest.approx(p_star * fp.flow_m3_s, rel=1e-5)
    eta = fp.volumetric_efficiency * fp.mechanical_efficiency
    assert d["pump_J"] == pytest.approx(p_star * fp.flow_m3_s / eta, rel=1e-5)
    assert d["circuit_J"] == pytest.approx(0.0, abs=1e-6) and d["unloaded_J"] == 0.0


@pytest.mark.parametrize("main_leak_m2", [0.0, 2e-8])
def test_compensated_pump_droop_standby_and_energy_for_a_known_demand(main_leak_m2) -> None:
    """compensated at steady state with demand Q(p): displacement x = (p_set − p)/droop
    and Q_g,max·x = Q(p) + k_L·p give p*; shaft power p*·(Q + k_L·p*)/η_hm, the standby
    (volumetric) part k_L·p*², the circuit p*·Q. Zero demand: p* = p_set/(1 + droop·k_L/Q_g)."""
    prm = _drawn(main_leak_m2)
    vp, p_set = prm.variable_pump, prm.supply.setpoint_Pa
    k_leak = vp.standby_flow_m3_s / p_set
    p_star = brentq(lambda p: vp.max_flow_m3_s * (p_set - p) / vp.droop_Pa
                    - _demand(prm, p) - k_leak * p, p_set - vp.droop_Pa, p_set)
    q = _demand(prm, p_star)
    ht = HydraulicTensioner(prm, supply_model="compensated")
    _hold(ht, 3.0)
    before = ht.ledger.terms.copy()
    _hold(ht, 1.0, 3.0)
    d = dict(zip(LEDGER_FIELDS, (ht.ledger.terms - before).tolist(), strict=True))
    print(f"demand {q:.3e} m^3/s: p* {p_star / 1e6:.5f} MPa (simulated "
          f"{ht.pressures[4] / 1e6:.5f}), displacement {ht.pump_displacement:.4f}, pump "
          f"{d['pump_J']:.3f} J/s of which standby {d['pump_volumetric_J']:.3f} J/s")
    if main_leak_m2 == 0.0:
        assert p_star == pytest.approx(p_set / (1.0 + vp.droop_Pa * k_leak / vp.max_flow_m3_s))
    else:
        assert q > 0.1 * vp.max_flow_m3_s           # a real demand, well inside the range
    assert ht.pressures[4] == pytest.approx(p_star, rel=1e-6)
    assert ht.pump_displacement == pytest.approx((p_set - p_star) / vp.droop_Pa, rel=1e-5)
    assert d["pump_J"] == pytest.approx(p_star * (q + k_leak * p_star)
                                        / vp.mechanical_efficiency, rel=1e-5)
    assert d["pump_volumetric_J"] == pytest.approx(k_leak * p_star**2, rel=1e-5)
    assert d["circuit_J"] == pytest.approx(p_star * q, rel=1e-4, abs=1e-9)
    assert d["relief_J"] == 0.0


def test_compensator_setting_drop_lowers_the_pressure_through_the_pump_leakage() -> None:
    """Set-point 12 -> 9 MPa at t = 0, no demand: the displacement decays, τ·dx/dt = −x (the
    target is clipped at 0 while p_s > 9 MPa), and the pump leakage drains the supply node and
    line A, C·dp/dt = Q_g,max·x − k_L·p with C = (V_S + V_A)/β. From the standby steady
    state (Q_g,max·x0 = k_L·p0): p(t) = p0·(T·e^(−t/T) − τ·e^(−t/τ))/(T − τ), T = C/k_L."""
    prm = _drawn(0.0)
    vp = prm.variable_pump
    k_leak = vp.standby_flow_m3_s / prm.supply.setpoint_Pa
    ht = HydraulicTensioner(prm, supply_model="compensated",
                            setpoint_Pa=lambda t: 12e6 if t <= 0.0 else 9e6)
    p0 = ht.pressures[4]
    c = (prm.supply.line_volume_m3 + prm.lines.line_a_volume_m3) / prm.fluid.bulk_modulus_Pa
    big_t, tau = c / k_leak, vp.time_constant_s
    times, simulated = [0.25, 0.5, 0.75], []
    t = 0.0
    for t_check in times:
        _hold(ht, t_check - t, t)
        t = t_check
        simulated.append(ht.pressures[4])
    expected = [p0 * (big_t * math.exp(-x / big_t) - tau * math.exp(-x / tau)) / (big_t - tau)
                for x in times]
    print(f"T = {big_t:.3f} s: p(t) simulated {np.round(np.array(simulated) / 1e6, 4)} MPa, "
          f"hand {np.round(np.array(expected) / 1e6, 4)} MPa")
    assert simulated[-1] > 9e6     # still above the new setting: the target stayed at 0
    # backward Euler at h = τ/30 lags the exponential decay by ~h/(2τ) of x
    np.testing.assert_allclose(simulated, expected, rtol=2e-3)


def test_unloading_valve_cycles_with_the_hand_derived_period_and_energy() -> None:
    """unloading with a known draw Q(p) (``_drawn``): from the cut-out, unloaded, the
    accumulator and the lines discharge to the cut-in in t_d = ∫ C(p)/Q(p) dp, then the
    loaded pump charges back to the cut-out in t_c = ∫ C(p)/(Q_d − Q(p)) dp, with
    C(p) = dV_oil,acc/dp + (V_S + V_A)/β. Unloaded the shaft draws p_u·Q_d/(η_v·η_hm);
    charging it draws ∫ p·Q_d/(η_v·η_hm) dt = ∫ p·C/(Q_d − Q) dp·Q_d/(η_v·η_hm)."""
    prm = _drawn(5e-8)
    acc, fp, uv = prm.accumulator, prm.fixed_pump, prm.unloading_valve
    p_out = prm.supply.setpoint_Pa
    p_in = prm.cut_in_Pa(p_out)
    c_lines = (prm.supply.line_volume_m3 + prm.lines.line_a_volume_m3) / prm.fluid.bulk_modulus_Pa

    def compliance(p: float) -> float:
        return accumulator_oil_volume(p, acc.gas_volume_m3, acc.precharge_Pa,
                                      acc.atmospheric_pressure_Pa_abs,
                                      acc.polytropic_exponent)[1] + c_lines

    t_d = quad(lambda p: compliance(p) / _demand(prm, p), p_in, p_out)[0]
    t_c = quad(lambda p: compliance(p) / (fp.flow_m3_s - _demand(prm, p)), p_in, p_out)[0]
    eta = fp.volumetric_efficiency * fp.mechanical_efficiency
    e_charge = quad(lambda p: p * compliance(p) / (fp.flow_m3_s - _demand(prm, p)),
                    p_in, p_out)[0] * fp.flow_m3_s / eta

    ht = HydraulicTensioner(prm, supply_model="unloading")
    assert not ht.pump_loaded and ht.pressures[4] == p_out
    loaded, pump_J, unloaded_J = [], [], []
    for i in range(round((t_d + t_c + 0.5) / H)):
        ht.force_law(i * H, 0.05, 0.0)
        ht.complete_step((i + 1) * H, 0.05, 0.0)
        loaded.append(ht.pump_loaded)
        pump_J.append(ht.ledger.pump_J)
        unloaded_J.append(ht.ledger.unloaded_J)
    switches = np.flatnonzero(np.diff(np.array(loaded, dtype=int))) + 1   # first step in state
    cut_in, cut_out = switches[0], switches[1]
    sim_d, sim_c = cut_in * H, (cut_out - cut_in) * H
    sim_e = pump_J[cut_out - 1] - pump_J[cut_in - 1]
    print(f"discharge {sim_d:.3f} s (hand {t_d:.3f}), charge {sim_c:.3f} s (hand {t_c:.3f}), "
          f"charging energy {sim_e:.2f} J (hand {e_charge:.2f})")
    assert loaded[cut_in] and not loaded[cut_out]
    assert sim_d == pytest.approx(t_d, rel=2e-3)
    assert sim_c == pytest.approx(t_c, rel=5e-3)
    assert sim_e == pytest.approx(e_charge, rel=5e-3)
    # unloaded: the pump circulates its whole flow at p_u, every step
    assert unloaded_J[cut_in - 1] == pytest.approx(uv.unloaded_pressure_Pa * fp.flow_m3_s
                                                   * cut_in * H, rel=1e-9)
    assert pump_J[cut_in - 1] == pytest.approx(unloaded_J[cut_in - 1] / eta, rel=1e-9)


@pytest.mark.parametrize("model", ["fixed_relief", "compensated", "unloading", "prescribed"])
def test_every_supply_model_closes_its_ledger_from_pump_shaft_to_track(model: str) -> None:
    """Mass-spring idler, pressurize / hold / release / hold every 0.4 s for 4 s: the chain
    pump -> supply node -> circuit -> piston -> track closes for each model (terms from the
    flows, stored energies from the state)."""
    prm = _replace(P, accumulator={"gas_volume_m3": 5e-5})  # the unloading valve cycles
    kw = {"setpoint_Pa": lambda t: 12e6} if model == "prescribed" else {}
    ht = HydraulicTensioner(prm, supply_model=model, **kw)
    h, m, k, c = 1e-3, 80.0, 2e6, 5e3
    s, v = 0.05, 0.0
    s_free = s - ht.force_law(0.0, s, 0.0).force_N / k
    cycled = set()
    for i in range(4000):
        if i % 400 == 0:
            ht.set_mode((1, 0, -1, 0)[(i // 400) % 4])
        law = ht.force_law(i * h, s, v)
        v = (v + h * (law.force_N - k * (s - s_free)) / m) / (1 - h * (law.damping_N_s_m - c) / m)
        s += h * v
        ht.complete_step((i + 1) * h, s, v)
        cycled.add(ht.pump_loaded)
    led = ht.ledger
    print(f"{model}: " + ", ".join(f"{n}={x:.4g}" for n, x in led.as_dict().items()))
    assert led.circuit_J > 10.0 and abs(led.balance_error_J) <= 1e-9 * led.pump_J
    assert abs(led.supply_balance_error_J) <= 1e-9 * led.pump_J
    assert led.pump_J >= led.circuit_J
    if model == "unloading":
        assert cycled == {True, False}
    if model == "prescribed":
        assert led.pump_J == led.delivered_J == pytest.approx(led.circuit_J, rel=1e-12)


def test_supply_choices_are_checked() -> None:
    with pytest.raises(ValueError, match="supply_model = 'pump' must be one of"):
        HydraulicTensioner(supply_model="pump")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="the unloading model takes a constant setpoint_Pa"):
        HydraulicTensioner(supply_model="unloading", setpoint_Pa=lambda t: 12e6)
    with pytest.raises(ValueError, match="supply_profile is the prescribed model's set-point"):
        HydraulicTensioner(supply_model="compensated", supply_profile=lambda t: 12e6)
    with pytest.raises(ValueError, match=r"cut-in 6\.8e\+06 Pa must exceed the accumulator "
                       r"precharge 8e\+06 Pa"):
        HydraulicTensioner(supply_model="unloading", setpoint_Pa=8e6)
    with pytest.raises(ValueError, match="setpoint_Pa"):
        HydraulicTensioner(setpoint_Pa=math.nan)
