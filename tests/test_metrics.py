"""The run's metric set on synthetic runs with known answers, the acceptance figures, and
the metric registry: one registry line adds a metric, every metric written is registered."""

from __future__ import annotations

import importlib
import math
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import pytest
from metric_cases import columns, contract_columns, step_ripple_noise, time_grid, windows
from synthetic import synthetic_result

from trackmj.results import metrics as M
from trackmj.results.acceptance import acceptance
from trackmj.results.metric_windows import MetricWindows
from trackmj.results.signals import lowpass
from trackmj.results.verdict import Verdict, verdict


def test_compute_metrics_standard_set() -> None:
    t = time_grid(20.0)
    w = windows(step=(3.0, 12e3, 15e3, 10.0), steady=(10.0, 20.0),
                 disturbances=((12.0, 14.0),), recovery_band_N=250.0)
    out = M.compute_metrics(contract_columns(t), w, control_period_s=0.01,
                            solve_times_s=[1e-3, 2e-3, 4e-3],
                            solve_success=[True, False, True], wall_time_s=10.0)
    assert out["overshoot_N"] == 0.0
    assert out["settling_time_s"] == pytest.approx(-0.4 * math.log(0.1), abs=1e-3)
    assert out["fluctuation_N"] == pytest.approx(200.0, rel=0.01)
    assert out["chassis_acc_body_mode_rms_m_s2"] == pytest.approx(1 / math.sqrt(2), rel=0.01)
    assert out["valve_switches"] == 2.0
    assert out["valve_switch_rate_Hz"] == pytest.approx(2 / 19.0)
    assert "supply_energy_J" not in out    # the energy breakdown is trackmj.elements.energy_table's
    assert out["interface_energy_residual_J"] == pytest.approx(0.02)
    assert out["constraint_violation_s"] == 0.0
    assert out["disturbance_peak_error_N"] == pytest.approx(200.0, rel=1e-3)
    assert out["recovery_time_s"] == 0.0  # the 200 N sine stays inside the 250 N band
    assert out["solve_failures"] == 1.0 and out["solve_time_median_s"] == pytest.approx(2e-3)
    assert out["real_time_factor"] == pytest.approx(2.0)
    # the 10 Hz sine is ripple (0.16 % of it passes the 2 Hz low-pass): in the body-mode band
    assert out["fluctuation_lp_N"] < 5.0 and out["recovery_time_lp_s"] == 0.0
    assert out["ripple_band_rms_N"]["body_mode"] == pytest.approx(200 / math.sqrt(2) *
                                                                  math.sqrt(10 / 19), rel=0.02)
    assert out["ripple_band_rms_N"]["tooth_passing"] < 1.0
    assert MetricWindows.from_table(out["evaluation"]) == w
    narrow = M.compute_metrics(contract_columns(t), windows(
        disturbances=((12.0, 14.0),), recovery_band_N=150.0))
    assert math.isnan(narrow["recovery_time_s"])  # 200 N never stays inside 150 N for 0.5 s
    assert narrow["recovery_time_lp_s"] == 0.0    # ... but its low-pass does
    assert math.isnan(narrow["overshoot_N"]) and math.isnan(narrow["fluctuation_N"])
    assert math.isnan(narrow["control_increment_rms"])  # no control period given
    assert narrow["psd"]["f_Hz"] == [] and math.isnan(narrow["chassis_acc_body_mode_rms_m_s2"])


def test_lowpassed_metrics_recover_the_step_error_and_ripple_the_sine() -> None:
    """A step plus a 20 Hz sine plus noise: rmse_lp_N is the step's own tracking error,
    ripple_rms_N the sine's RMS (with the noise, all but the 0.4 % of its power below the
    cut-off), rmse_N both; the raw settling time never comes (the ±1 kN sine exceeds the
    ±300 N band), the low-passed one is the first-order -tau ln(300/3000)."""
    t = time_grid(15.0)
    ripple, noise = 1000.0, 100.0
    ref, slow, y = step_ripple_noise(t, ripple, noise)
    w = windows(step=(3.0, 12e3, 15e3, 15.0), steady=(5.0, 15.0))
    out = M.compute_metrics(columns(t, y, ref), w)
    ev = t >= 1.0
    step_error = float(np.sqrt(np.mean(slow[ev] ** 2)))
    assert out["rmse_lp_N"] == pytest.approx(step_error, rel=0.01)
    assert out["ripple_rms_N"] == pytest.approx(math.hypot(ripple / math.sqrt(2), noise),
                                                rel=0.01)
    assert out["rmse_N"] == pytest.approx(math.hypot(out["rmse_lp_N"], out["ripple_rms_N"]),
                                          rel=0.01)
    assert math.isnan(out["settling_time_s"])
    assert out["settling_time_lp_s"] == pytest.approx(-0.4 * math.log(0.1), abs=0.02)
    assert out["overshoot_lp_N"] < 0.04 * 3e3      # the filter's own 3.4 % at most
    assert out["overshoot_N"] > ripple              # raw: the sine's crest and the noise
    bands = out["ripple_band_rms_N"]
    assert bands["tooth_passing"] == pytest.approx(ripple / math.sqrt(2), rel=0.02)
    assert bands["body_mode"] == pytest.approx(noise * math.sqrt(4.5 / 500), rel=0.15)
    parts = math.sqrt(sum(v ** 2 for v in bands.values()))
    assert parts == pytest.approx(out["ripple_rms_N"], rel=0.01)  # bands + rest = ripple
    f = np.array(out["psd"]["f_Hz"])
    assert f[-1] == pytest.approx(50.0)
    assert f[np.argmax(out["psd"]["tension_N2_Hz"])] == pytest.approx(20.0)


def test_recovery_time_of_a_decaying_disturbance_on_the_lowpass() -> None:
    """W4-like: a 900 N dip at 12 s decaying with tau = 0.5 s under a ±600 N 20 Hz ripple:
    the raw error never stays in the ±300 N band, the low-passed one does after tau ln 3.
    The low-pass rounds the instantaneous onset: its peak error is the filtered dip's
    (~0.72 of 900 N), whatever the ripple."""
    t = time_grid(30.0)
    ref = np.full_like(t, 15e3)
    dip = np.where(t >= 12.0, 900.0 * np.exp(-(t - 12.0) / 0.5), 0.0)
    y = ref - dip + 600.0 * np.sin(2 * np.pi * 20.0 * t)
    out = M.compute_metrics(columns(t, y, ref), windows(disturbances=((12.0, 20.0),),
                                                           steady=(5.0, 30.0)))
    assert math.isnan(out["recovery_time_s"])
    # the first trough of the sine after the onset, at 12 + 3/80 s
    assert out["disturbance_peak_error_N"] == pytest.approx(900.0 * math.exp(-0.0375 / 0.5)
                                                            + 600.0, rel=1e-3)
    assert out["recovery_time_lp_s"] == pytest.approx(0.5 * math.log(3.0), abs=0.03)
    rounded = float(np.max(lowpass(t, dip, 2.0)))
    assert 0.7 * 900.0 < rounded < 0.75 * 900.0
    assert out["disturbance_peak_error_lp_N"] == pytest.approx(rounded, rel=0.01)


def test_acceptance_of_a_decaying_load_disturbance() -> None:
    """A 2 kN disturbance at 6 s decaying with tau = 0.4 s on 15 kN: the trailing 0.5 s mean
    is back within 5 % (750 N) when the mean of the decay over the last 0.5 s is 750 N,
    i.e. 2000·tau·(1 − exp(−0.5/tau))·exp(−(t − 6 − 0.5)/tau)/0.5 = 750, solved by hand; a
    second edge at 8 s with no disturbance recovers at once; a 200 N offset from 9 s on is a
    1.33 % steady offset, the worst of the steady windows."""
    tau, ref = 0.4, 15e3
    t = time_grid(20.0)
    y = np.full_like(t, ref)
    on = t >= 6.0
    y[on] += 2000.0 * np.exp(-(t[on] - 6.0) / tau)
    y[t >= 9.0] += 200.0
    w = windows(disturbances=((6.0, 8.0),), evaluation_start_s=1.0)
    a = acceptance(t, y, np.full_like(t, ref), w)
    # mean over [t - 0.5, t] for t > 6.5: 2000 tau (1 - e^{-0.5/tau}) e^{-(t-6.5)/tau} / 0.5
    amp = 2000.0 * tau * (1.0 - math.exp(-0.5 / tau)) / 0.5
    expected = 0.5 + tau * math.log(amp / 750.0)
    assert a["edge_recovery_s"]["6"] == pytest.approx(expected, abs=2e-3)
    assert a["edge_recovery_s"]["8"] == 0.0
    assert a["steady_offset_max_rel"] == pytest.approx(200.0 / ref, rel=0.02)
    # the mean rises while the window fills with the decay (6 - 6.5 s), then falls: its
    # maximum is ref + amp at 6.5 s
    assert a["mean_max_N"] == pytest.approx(ref + amp, rel=1e-4)
    assert a["mean_min_N"] == pytest.approx(ref)


def test_verdict_names_the_rules_a_decaying_disturbance_breaks() -> None:
    """The disturbance above (its end edge at 12 s) judged by the scenario's rules (band
    2/3-4/3 of 15 kN, back within 2 s, steady offset below 2 %): with tau = 0.4 s it holds;
    with tau = 2 s the mean is back only 0.5 + tau·ln(amp/750) = 2.22 s after the edge
    (amp = 2000·tau·(1 − exp(−0.5/tau))/0.5, the hand formula above); a 400 N offset
    (2.7 %) breaks the steady rule; a band whose top is below the mean's peak breaks the
    band rule."""
    ref = 15e3
    t = time_grid(20.0)
    w = windows(disturbances=((6.0, 12.0),), evaluation_start_s=1.0)

    def judged(tau: float, offset_N: float, band: tuple[float, float]) -> list[str]:
        y = np.full_like(t, ref)
        on = t >= 6.0
        y[on] += 2000.0 * np.exp(-(t[on] - 6.0) / tau)
        y[t >= 9.0] += offset_N
        v = verdict(acceptance(t, y, np.full_like(t, ref), w), band, 2.0, 0.02)
        if tau == 2.0:
            amp = 2000.0 * tau * (1.0 - math.exp(-0.5 / tau)) / 0.5
            assert v.late_edges["6"] == pytest.approx(0.5 + tau * math.log(amp / 750.0),
                                                      abs=2e-3)
        return v.broken

    band = (2.0 * ref / 3.0, 4.0 * ref / 3.0)
    assert judged(0.4, 200.0, band) == []
    assert judged(2.0, 200.0, band) == ["recovery"]
    assert judged(0.4, 400.0, band) == ["steady offset"]
    assert judged(0.4, 200.0, (band[0], ref + 1000.0)) == ["band"]


def test_the_start_ramps_traction_transient_is_not_a_steady_offset() -> None:
    """The tension 600 N (4 %) above 15 kN until 2.5 s, where a front sprocket's start-up
    traction leaves it, then on the reference: with the track's start ramp ending at 1 s
    the first steady window starts at 3 s (offset 0); without that event the 1-6 s window
    holds 600 N x 1.5 s / 5 s = 180 N (1.2 %)."""
    ref = 15e3
    t = time_grid(20.0)
    y = np.where(t < 2.5, ref + 600.0, ref)
    plain = acceptance(t, y, np.full_like(t, ref), windows(evaluation_start_s=1.0))
    assert plain["steady_offset_max_rel"] == pytest.approx(180.0 / ref, rel=0.01)
    ramped = acceptance(t, y, np.full_like(t, ref),
                        windows(evaluation_start_s=1.0, drive_events_s=(1.0,)))
    assert ramped["steady_offset_max_rel"] == pytest.approx(0.0, abs=1e-12)


def test_a_condition_held_from_the_start_is_not_an_edge() -> None:
    """A supply drop in place from t = 0 to the run's end (NL1's 9 MPa) is the run's
    condition: no edge is judged, so a reference step inside it is not read as a slow
    recovery; an onset after the evaluation start is judged as before."""
    t = time_grid(20.0)
    ref = np.where(t >= 5.0, 18e3, 12e3)
    y = ref + np.where((t >= 5.0) & (t < 8.0), -3e3, 0.0)      # a 3 s rise lag on the step
    held = windows(disturbances=((0.0, 20.0),))
    a = acceptance(t, y, ref, held)
    assert a["edge_recovery_s"] == {} and math.isnan(a["recovery_max_s"])
    out = M.compute_metrics(contract_columns(t), held, control_period_s=0.01)
    assert math.isnan(out["recovery_time_s"]) and math.isnan(out["disturbance_peak_error_N"])
    later = acceptance(t, y, ref, windows(disturbances=((4.0, 20.0),)))
    # the 0.5 s mean of the -3 kN lag ending at 8 s is within 5 % of 18 kN (900 N) once
    # 3000 (8.5 - t) / 0.5 <= 900, i.e. from t = 8.35 s: 4.35 s after the edge at 4 s
    assert later["edge_recovery_s"]["4"] == pytest.approx(4.35, abs=2e-3)


# ---------------------------------------------------------------------- the registry

FULL_OPTIONS = dict(control_period_s=0.01, solve_times_s=[1e-3, 2e-3, 4e-3],
                    solve_success=[True, False, True], wall_time_s=10.0, clipped_outputs=[])
"""Every option of compute_metrics, so that every step writes its metrics."""


def _full_run() -> dict[str, Any]:
    """Metrics of a run with a step, a disturbance, a steady window and every option."""
    t = time_grid(20.0)
    w = windows(step=(3.0, 12e3, 15e3, 10.0), steady=(10.0, 20.0),
                disturbances=((12.0, 14.0),), recovery_band_N=250.0)
    return M.compute_metrics(contract_columns(t), w, **FULL_OPTIONS)


def _leaves(table: Mapping[str, Any], prefix: str = "") -> Iterator[str]:
    """Dotted keys of the entries of ``table`` that are not tables themselves."""
    for key, value in table.items():
        if isinstance(value, Mapping) and value:
            yield from _leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}"


def _registered(key: str) -> bool:
    """Whether ``key`` or a table holding it (a prefix of its dotted parts) is registered."""
    parts = key.split(".")
    return any(".".join(parts[:n]) in M.METRICS for n in range(1, len(parts) + 1))


def test_one_registry_line_adds_a_metric(monkeypatch) -> None:
    """A new metric is its step and one entry in METRICS: compute_metrics writes it (last,
    after the metrics registered before it), tables show its label and unit, lookup reads
    it; no other edit."""
    from trackmj.results.columns import column_label, column_words

    def tension_median(run: M.RunSignals) -> dict[str, float]:
        return {"tension_median_N": float(np.median(run.tension[run.in_tracking]))}

    monkeypatch.setitem(M.METRICS, "tension_median_N", M.Metric(
        "N", tension_median, M.Display("tension median", 1e-3, "kN")))
    t = time_grid(10.0)
    cols = contract_columns(t)
    out = M.compute_metrics(cols, windows(), **FULL_OPTIONS)
    assert list(out)[-1] == "tension_median_N"
    assert out["tension_median_N"] == float(np.median(cols["tension_N"][t >= 1.0]))
    assert M.lookup(out, "tension_median_N") == out["tension_median_N"]
    label, scale, unit = M.METRIC_DISPLAY["tension_median_N"]
    assert (label, scale, unit) == ("tension median", 1e-3, "kN")
    assert "tension_median_N" in M.METRIC_DISPLAY
    assert column_words("tension_median_N") == "tension median"
    assert column_label("tension_median_N") == "tension median [kN]"


def test_every_metric_written_is_registered() -> None:
    """No metric of compute_metrics escapes the registry: on the synthetic runs of every
    built-in scenario (with and without a chassis) and on a run with every option."""
    runs = [synthetic_result(s, chassis=c).metrics for s in ("W1", "W2", "W3", "W4", "W5", "NL1")
            for c in (True, False)]
    for metrics in [*runs, _full_run()]:
        unregistered = [k for k in _leaves(metrics) if not _registered(k)]
        assert unregistered == []


def test_every_registered_step_metric_is_written_in_the_registry_order() -> None:
    """The registry holds no metric its step no longer writes, and lists them in the order
    compute_metrics writes them."""
    out = _full_run()
    stale = [k for k, m in M.METRICS.items() if m.step is not None and not _present(out, k)]
    assert stale == []
    order = list(dict.fromkeys(k.split(".")[0] for k, m in M.METRICS.items()
                               if m.step is not None))
    assert list(out) == order


def _present(metrics: Mapping[str, Any], key: str) -> bool:
    value: Any = metrics
    for part in key.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return False
        value = value[part]
    return True


def test_every_metric_computed_elsewhere_names_an_existing_function() -> None:
    for key, metric in M.METRICS.items():
        if metric.step is None:
            module, _, name = metric.source.rpartition(".")
            assert callable(getattr(importlib.import_module(module), name)), key


def test_a_metric_names_its_step_or_its_source() -> None:
    with pytest.raises(ValueError, match="either"):
        M.Metric("N")
    with pytest.raises(ValueError, match="either"):
        M.Metric("N", M.tracking_raw, source=M.VS_TP)


def test_metric_display_is_the_registry_s_displays() -> None:
    shown = {k: m.display for k, m in M.METRICS.items() if m.display is not None}
    assert dict(M.METRIC_DISPLAY) == shown and len(M.METRIC_DISPLAY) == len(shown)
    assert "tension_max_N" not in M.METRIC_DISPLAY        # registered, not in tables
    assert M.METRIC_DISPLAY["ripple_band_rms_N.tooth_passing"] == (
        "ripple in the tooth-passing band", 1e-3, "kN")
    with pytest.raises(KeyError):
        M.METRIC_DISPLAY["no_such_metric_N"]


def test_a_verdict_claims_only_what_was_judged() -> None:
    """A 4 s run without disturbances (no edge) and shorter than a steady window plus the
    evaluation start: it holds, and says there was no edge to recover from and no steady
    window, where it used to claim both rules kept; with a disturbance edge and 20 s it
    says both were judged."""
    ref = 15e3
    band = (2.0 * ref / 3.0, 4.0 * ref / 3.0)
    t = time_grid(4.0)
    v = verdict(acceptance(t, np.full_like(t, ref), np.full_like(t, ref), windows()),
                band, 2.0, 0.02)
    assert v.holds and v.edges_judged == 0
    assert "no disturbance edge to recover from" in v.text()
    assert "no steady window to judge an offset in" in v.text()
    t = time_grid(20.0)
    v = verdict(acceptance(t, np.full_like(t, ref), np.full_like(t, ref),
                           windows(disturbances=((6.0, 8.0),))), band, 2.0, 0.02)
    assert v.edges_judged == 2
    assert "back within ±5 % in 2 s of every edge; steady offset below 2 %" in v.text()


def test_an_edge_not_back_before_the_next_is_said_so() -> None:
    """Two pulses 1 s apart (edges 2, 3, 4, 5 s) and a mean back 1.05 s after the 3 s edge:
    the 3 s edge is judged up to the 4 s edge, and the verdict says it was not back before
    it, where it said "never" (a newcomer's short W3)."""
    ref = 15e3
    t = time_grid(8.0)
    y = np.full_like(t, ref)
    y[(t >= 3.0) & (t < 4.3)] += 2000.0
    w = windows(disturbances=((2.0, 3.0), (4.0, 5.0)))
    v = verdict(acceptance(t, y, np.full_like(t, ref), w), (10e3, 20e3), 2.0, 0.02)
    assert v.edge_times == ("2", "3", "4", "5")
    assert "not back after the 3 s edge before the next one at 4 s" in v.text()



def test_a_band_breach_is_named_the_drives_only_where_its_floor_is_above_the_band() -> None:
    """A front-sprocket machine (σ = +1, g = G/r = 8 1/m) whose drive torque rises 0 → 3.5
    kN·m over 0-1 s and falls back by 2 s (a triangle), its idler load 2 kN above the drive's
    floor g·max(σT, 0). The trailing 0.5 s mean peaks at 1.25 s, over the window [0.75,
    1.25] centred on the apex: the torque's mean there is 3500·(1 − 0.125) = 3062.5 N·m (by
    hand: the mean distance from the apex is 0.125 s), so the floor's mean is 24.5 kN and the
    load's 26.5 kN. Against a 26 kN band top the breach is the tensioner's 2 kN; against a
    24 kN top the drive alone breaches it, and the verdict says so. With the sprocket at the
    rear (σ = −1) driving forward loads the other strands: floor 0, a plain breach."""
    t = time_grid(6.0)
    torque = 3500.0 * np.clip(np.minimum(t, 2.0 - t), 0.0, None)
    y = 2e3 + 8.0 * torque
    ref = np.full_like(t, 15e3)

    def judged(top_N: float, sign: float) -> Verdict:
        w = windows(force_min_N=10e3, force_max_N=top_N, evaluation_start_s=0.5,
                    drive_load_gain_1_m=8.0, drive_tight_sign=sign)
        return verdict(acceptance(t, y, ref, w, torque), (10e3, top_N), 2.0, 0.02)

    tensioners = judged(26e3, +1.0)
    assert tensioners.mean_max_s == pytest.approx(1.25, abs=2e-3)
    assert tensioners.drive_floor_at_max_N == pytest.approx(24.5e3, rel=1e-3)
    assert tensioners.mean_range_N[1] == pytest.approx(26.5e3, rel=1e-3)
    assert "band" in tensioners.broken and not tensioners.band_forced_by_drive
    assert "no tensioner" not in tensioners.text()
    drives = judged(24e3, +1.0)
    assert "band" in drives.broken and drives.band_forced_by_drive
    assert "the drive's pull through the idler was 24.5 kN there (1.25 s" in drives.text()
    rear = judged(24e3, -1.0)
    assert rear.drive_floor_at_max_N == 0.0 and not rear.band_forced_by_drive
    assert "no tensioner" not in rear.text()
    unknown = acceptance(t, y, ref, windows(evaluation_start_s=0.5), torque)
    assert math.isnan(unknown["drive_floor_at_max_N"])


@pytest.mark.parametrize(("column", "label"), [
    ("scenario.load_pulses.1.delta_rel", "load pulses delta relative [-]"),
    ("control.mpc.max_iter", "mpc max iterations [-]"),
    ("hydraulics.fluid.bulk_modulus_Pa", "fluid bulk modulus [MPa]"),
])
def test_a_swept_keys_label_keeps_what_its_dimensionless_suffix_says(column: str,
                                                                      label: str) -> None:
    """A unit suffix goes to the brackets, but a dimensionless one (_rel, _iter, ...) says
    what the number is: "delta" alone would not tell a relative change from an absolute."""
    from trackmj.results.columns import column_label

    assert column_label(column) == label
