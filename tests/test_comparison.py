"""Prediction errors against tp, and the energy terms they compare, on synthetic runs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from metric_cases import columns, step_ripple_noise, time_grid, windows

from trackmj.results.comparison import prediction_vs_tp
from trackmj.results.energy_terms import energy_terms, headline_energy
from trackmj.results.metrics import compute_metrics


def test_prediction_error_is_zero_against_itself_and_bounded_below() -> None:
    t = time_grid(10.0)
    ref, _, y = step_ripple_noise(t, 800.0, 50.0)
    w = windows(step=(3.0, 12e3, 15e3, 10.0), steady=(5.0, 10.0))
    tp_cols = columns(t, y, ref)
    tp = compute_metrics(tp_cols, w) | {"energy_J": {"pump": 9e3, "relief": 1e3}}
    same = prediction_vs_tp(tp_cols, tp, tp_cols, tp, w)
    assert same["prediction_rmse_vs_tp_N"] == 0.0 and same["prediction_rmse_vs_tp_lp_N"] == 0.0
    assert same["peak_pressure_error_vs_tp_Pa"] == 0.0
    assert same["energy_error_vs_tp_J"] == {"pump": 0.0, "relief": 0.0}
    # a reduced model that predicts 150 N more tension, with its own ripple phase
    other = y + 150.0 + 300.0 * np.sin(2 * np.pi * 20.0 * t + 1.0)
    cols = columns(t, other, ref)
    mine = compute_metrics(cols, w) | {"energy_J": {"pump": 9.9e3, "relief": "absent"}}
    err = prediction_vs_tp(cols, mine, tp_cols, tp, w)
    assert err["prediction_rmse_vs_tp_N"] == pytest.approx(math.hypot(150, 300 / math.sqrt(2)),
                                                           rel=1e-3)
    assert err["prediction_rmse_vs_tp_lp_N"] == pytest.approx(150.0, rel=0.01)
    assert err["prediction_rmse_vs_tp_N"] >= abs(mine["rmse_N"] - tp["rmse_N"])
    assert err["peak_pressure_error_vs_tp_Pa"] == pytest.approx(
        mine["p_head_max_Pa"] - tp["p_head_max_Pa"])
    assert err["energy_error_vs_tp_J"] == {"pump": pytest.approx(900.0)}
    assert err["energy_error_term"] == "pump" and err["energy_error_vs_tp_pct"] == \
        pytest.approx(10.0)
    with pytest.raises(ValueError, match="time grid"):
        prediction_vs_tp(columns(t[:-1], other[:-1], ref[:-1]), mine, tp_cols, tp, w)


def test_energy_terms_of_a_table_of_a_fallback_and_of_nothing() -> None:
    table = {"pump": 10e3, "circuit": 8e3, "relief": 2e3,
             "throttling": {"main": 3e3, "V_L": 1e3, "V_R": math.nan}, "leakage": 0.5e3,
             "mechanical": 1e3, "residual": 1.0, "circuit_is_ideal_actuator": True,
             "note": "dp-b: ideal force source"}
    e = energy_terms({"energy_J": table})
    assert e.source == "energy_J" and e.terms["throttling"] == 4e3
    assert set(e.terms) == {"pump", "circuit", "relief", "throttling", "leakage",
                            "mechanical", "residual"}
    assert e.notes == ["circuit is ideal actuator", "dp-b: ideal force source"]
    none = energy_terms({})
    assert none.terms == {} and none.source == "none" and none.notes
    ideal = energy_terms({"energy_J": {"pump": math.nan, "circuit": 7e3}})
    assert headline_energy(e, ideal) == "circuit"
    assert headline_energy(e, none) is None
