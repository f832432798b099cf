"""The study's claims, one by one: each gives its rows of the report's claims table (the
study's figure, ours as mean ± std over seeds, a verdict and its reason) from the results
(:class:`~trackmj.study.report_matrix.Matrix`). The study's figures are
:mod:`trackmj.study.study_numbers`; ours are measured on the
:data:`~trackmj.sim.registry.REFERENCE_ARCHITECTURE` (the study's TP) and on the study's
reduced architectures."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from trackmj.host import machine
from trackmj.results.energy_terms import energy_terms, headline_energy
from trackmj.results.metric_windows import windows_of
from trackmj.results.metrics import lookup
from trackmj.results.seed_stats import finite
from trackmj.scenarios.load import load_scenario
from trackmj.sim.registry import REFERENCE_ARCHITECTURE as REFERENCE
from trackmj.study.report_matrix import Matrix, MatrixRun
from trackmj.study.report_stats import lower_by, mean_std, reductions
from trackmj.study.report_verdicts import verdict_magnitude, verdict_reduction
from trackmj.study.study_numbers import (
    STUDY_DISTURBANCE,
    STUDY_ENERGY_KJ,
    STUDY_ENERGY_SAVING_PCT,
    STUDY_FLUCTUATION,
    STUDY_HOST,
    STUDY_NMPC_GAIN_PCT,
    STUDY_REAL_TIME_FACTOR,
    STUDY_REAL_TIME_FACTOR_MID,
    STUDY_REDUCED,
    STUDY_REFERENCE,
    STUDY_RMSE,
    STUDY_STEP_WALL_MS,
    STUDY_W2_BODY_ACC_LOWER_PCT,
    STUDY_W3_FEWER_SWITCHES_PCT,
    STUDY_W3_PRESSURE_LOWER_PA,
)


@dataclass(frozen=True)
class Finding:
    """One row of the claims table."""

    claim: str
    study: str
    ours: str
    verdict: str
    reason: str


DP_WHY = {"dp-a": "dp-a runs the same hydraulics on the identified equivalent idler and "
                  "replays tp's own track load, so it differs from tp only by the idler "
                  "motion's feedback into the track",
          "dp-b": "dp-b keeps the track and replaces the oil column by an ideal force source "
                  "(rate-limited, one lag), so it lacks the oil column's compliance and the "
                  "valves' flow limits"}
"""Why each reduced architecture can differ from the reference, the reason a verdict ends
with."""


def _kn(values: Mapping[Any, float]) -> str:
    """mean ± std of forces [N] in kN, with the unit."""
    return mean_std(values.values(), 1e-3) + " kN"


def _ripple_reason(m: Matrix, scenario: str) -> str:
    """Why a raw tension figure differs: the ripple and the slow low-passed error of tp."""
    ripple = m.values(scenario, REFERENCE, "ripple_rms_N")
    tooth = m.values(scenario, REFERENCE, "ripple_band_rms_N.tooth_passing")
    lp = m.values(scenario, REFERENCE, "rmse_lp_N")
    fl = m.values(scenario, REFERENCE, "fluctuation_lp_N")
    return (f"tp's raw F_ten carries a ripple of {_kn(ripple)} RMS ({_kn(tooth)} of it in "
            f"the tooth-passing band) that no valve follows; on the {_cutoff(m, scenario)} "
            f"low-pass its error is {_kn(lp)} RMS, a slow wander of ±{_kn(fl)} (95 % band) "
            "around the reference")


def _cutoff(m: Matrix, scenario: str) -> str:
    """The scenario's low-pass cut-off as text ("low-pass" when it has no run)."""
    case = m.first_case(scenario)
    if case is None:
        return "low-pass"
    return f"{windows_of(m.runs[(case, REFERENCE)]).lowpass_cutoff_Hz:g} Hz"


# ----------------------------------------------------------------------------- tracking

def _tracking_claims(m: Matrix, scenario: str) -> list[Finding]:
    """TP's tension RMSE against the study's, and TP against each reduced architecture."""
    out = []
    study = STUDY_RMSE[scenario]
    ref = study[STUDY_REFERENCE]
    tp = m.values(scenario, REFERENCE, "rmse_N")
    tp_lp = m.values(scenario, REFERENCE, "rmse_lp_N")
    verdict, text = verdict_magnitude(list(tp.values()), ref, 1e-3, "kN")
    out.append(Finding(f"{scenario}: TP tension RMSE", f"{ref / 1e3:g} kN",
                       f"raw {_kn(tp)}; low-pass {_kn(tp_lp)}", verdict,
                       f"{text} (raw, the study's definition); " + _ripple_reason(m, scenario)))
    for dp in STUDY_REDUCED:
        other = m.values(scenario, dp, "rmse_N")
        if not other:
            continue
        other_lp = m.values(scenario, dp, "rmse_lp_N")
        red, red_lp = reductions(tp, other), reductions(tp_lp, other_lp)
        implied = 100.0 * (1.0 - ref / study[dp])
        verdict, text = verdict_reduction(red, implied, implied)
        pred = m.prediction(scenario, dp, "prediction_rmse_vs_tp_lp_N")
        out.append(Finding(
            f"{scenario}: TP tracks better than {dp.upper()}",
            f"RMSE {ref / 1e3:g} vs {study[dp] / 1e3:g} kN ({implied:.0f} % lower)",
            f"{dp} raw {_kn(other)}, low-pass {_kn(other_lp)}; {lower_by(red)} raw, "
            f"{lower_by(red_lp)} low-pass",
            verdict, f"{text}. {DP_WHY[dp]}; the two low-passed traces differ by "
                     f"{_kn(pred)} RMS"))
    return out


def _prediction_claims(m: Matrix, scenario: str) -> list[Finding]:
    """The study's RMSEs bound how far its reduced models' tension is from TP's: by the
    triangle inequality of the RMS, RMS(F_dp − F_tp) >= |RMSE_dp − RMSE_tp|."""
    out = []
    study = STUDY_RMSE[scenario]
    ref = study[STUDY_REFERENCE]
    for dp in STUDY_REDUCED:
        raw = m.prediction(scenario, dp, "prediction_rmse_vs_tp_N")
        if not raw:
            continue
        lp = m.prediction(scenario, dp, "prediction_rmse_vs_tp_lp_N")
        bound = abs(study[dp] - ref)
        mean = float(np.mean(finite(raw.values()))) if finite(raw.values()) else math.nan
        if not math.isfinite(mean):
            verdict, text = "not measured", "no tp run of the same seed"
        elif mean >= bound:
            verdict, text = "supported", (f"{dp}'s F_ten departs from tp's by at least the "
                                          "study's implied amount")
        else:
            verdict, text = "not supported", (f"{dp}'s F_ten stays closer to tp's "
                                              f"({mean / 1e3:.2f} kN RMS) than the study's "
                                              f"RMSEs allow ({bound / 1e3:.2f} kN)")
        out.append(Finding(
            f"{scenario}: {dp.upper()} does not predict TP (prediction error vs tp, same seed)",
            f">= |{study[dp] / 1e3:g} − {ref / 1e3:g}| = {bound / 1e3:.2f} kN "
            "(implied by its RMSEs)",
            f"raw {_kn(raw)}, low-pass {_kn(lp)}", verdict, f"{text}. {DP_WHY[dp]}"))
    return out


# ----------------------------------------------------------------------------- energy

def _energy_reductions(m: Matrix, scenario: str, terms: set[str]) -> list[float]:
    """Per (variant, seed) reductions [%] of the reference's energy against dp-a's on the
    headline term both runs have; the terms used are added to ``terms``."""
    tp_runs = {k: r for (case, a), r in m.runs.items() if a == REFERENCE
               and case[0] == scenario and case[3] == m.controller(scenario)
               for k in [(case[1], case[2])]}
    dpa_runs = {(case[1], case[2]): r for (case, a), r in m.runs.items() if a == "dp-a"
                and case[0] == scenario}
    red = []
    for k, tp in tp_runs.items():
        if k not in dpa_runs:
            continue
        e_tp, e_dp = energy_terms(tp.metrics), energy_terms(dpa_runs[k].metrics)
        term = headline_energy(e_tp, e_dp)
        if term is None:
            continue
        terms.add(term)
        red += reductions({0: e_tp.terms[term]}, {0: e_dp.terms[term]})
    return red


def _energy_vs_dpa(m: Matrix) -> list[Finding]:
    """TP energy 12-17 % below DP, vs dp-a where the definitions match (same hydraulics)."""
    parts, pooled, terms = [], [], set()
    for scenario in m.scenarios:
        if not m.values(scenario, "dp-a", "rmse_N", variant=None):
            continue
        red = _energy_reductions(m, scenario, terms)
        if red:
            pooled += red
            parts.append(f"{scenario} {lower_by(red)}")
    if not pooled:
        return []
    low, high = STUDY_ENERGY_SAVING_PCT
    kj = STUDY_ENERGY_KJ["W1"]
    verdict, text = verdict_reduction(pooled, low, high)
    term_text = ", ".join(sorted(terms))
    why = ""
    if verdict == "no difference":
        why = (" The energy drawn is set by the supply, not by the architecture: with the "
               "accumulator supply a fixed-displacement pump works against the relief "
               "whatever the cylinders take (the relief spills the rest), and dp-a's "
               "valve flows follow tp's closely.")
    return [Finding(
        "TP uses less energy than DP-A",
        f"{low:.0f}-{high:.0f} % less (W1 {kj[0]:g} vs {kj[1]:g} kJ)",
        f"{term_text} energy, TP vs dp-a: " + "; ".join(parts), verdict,
        f"{text}.{why} Both run the same hydraulic model and ledger, so the {term_text} "
        "energies mean the same thing and their difference is a prediction; magnitudes "
        "are not compared with the study's kJ, which it does not define (neither what is "
        "counted nor over which window)")]


def _energy_vs_dpb(m: Matrix) -> list[Finding]:
    """TP vs dp-b: not comparable, dp-b has no hydraulic circuit."""
    dpb = [s for s in m.scenarios if m.values(s, "dp-b", "rmse_N")]
    if not dpb:
        return []
    s = dpb[0]
    e = [energy_terms(r.metrics) for (case, a), r in m.runs.items()
         if a == "dp-b" and case[0] == s] or [energy_terms({})]
    notes = sorted({n for t in e for n in t.notes})
    kj = STUDY_ENERGY_KJ["W1"]
    return [Finding(
        "TP uses less energy than DP-B",
        f"W1 {kj[0]:g} vs {kj[2]:g} kJ ({100.0 * (1.0 - kj[0] / kj[2]):.0f} % less)",
        f"dp-b terms: {', '.join(sorted(k for k, v in e[0].terms.items() if v == v))}"
        + (f" ({'; '.join(notes)})" if notes else ""), "not comparable",
        "dp-b has no hydraulic circuit: its energy is the ideal force source's work, "
        "without throttling, relief or leakage, so a difference to tp measures what dp-b "
        "leaves out by construction, not a prediction; the study does not say how it "
        "counted DP-B's energy either")]


# ----------------------------------------------------------------------------- controllers

def _controller_claims(m: Matrix) -> list[Finding]:
    """NMPC against each baseline controller the study names, on the reference."""
    out = []
    for baseline, (low, high) in STUDY_NMPC_GAIN_PCT.items():
        parts, pooled, pooled_lp = [], [], []
        for scenario in m.scenarios:
            nmpc = m.values(scenario, REFERENCE, "rmse_N")
            other = m.values(scenario, REFERENCE, "rmse_N", controller=baseline)
            if not other:
                continue
            red = reductions(nmpc, other)
            red_lp = reductions(m.values(scenario, REFERENCE, "rmse_lp_N"),
                                m.values(scenario, REFERENCE, "rmse_lp_N", controller=baseline))
            pooled += red
            pooled_lp += red_lp
            parts.append(f"{scenario}: {baseline} raw {_kn(other)}, "
                         f"{lower_by(red, 'NMPC')} raw, {lower_by(red_lp, 'NMPC')} low-pass")
        if not pooled:
            continue
        verdict, text = verdict_reduction(pooled, low, high)
        verdict_lp, text_lp = verdict_reduction(pooled_lp, low, high)
        out.append(Finding(f"NMPC tracks better than {baseline.upper()} (TP)",
                           f"RMSE {low:.0f}-{high:.0f} % lower", "; ".join(parts),
                           f"{verdict} (raw); {verdict_lp} (low-pass)",
                           f"raw: {text}; low-pass: {text_lp}. The raw RMSE is dominated by "
                           "the tooth-passing ripple every controller leaves alike, so the "
                           "low-passed figure is the one that tells controllers apart; the "
                           "controllers are not re-tuned for this report"))
    return out


# ----------------------------------------------------------------------------- disturbances

def _recovery_band(m: Matrix, scenario: str, rec: Mapping[Any, float]) -> str:
    """The recovery band and, where it says more, why no run recovers and what the
    acceptance view (trailing mean) sees; "" when the scenario has no nominal case."""
    case = m.first_case(scenario)
    if case is None:
        return ""
    w = windows_of(m.runs[(case, REFERENCE)])
    band = (f" (band ±{w.settle_band_rel * 100:g} % of F_ref held {w.min_hold_s:g} s, "
            "from each onset)")
    if not finite(rec.values()):
        band += ("; no run recovers: even the low-passed error does not stay inside the "
                 "band before the next onset or the end (tp's low-passed RMSE over the "
                 f"run: {_kn(m.values(scenario, REFERENCE, 'rmse_lp_N'))})")
    accepted = m.values(scenario, REFERENCE, "acceptance.recovery_max_s")
    if finite(accepted.values()):
        after = ("never leaves it" if max(finite(accepted.values())) == 0.0
                 else f"is back after {mean_std(accepted.values())} s (worst edge)")
        band += (f"; on the {w.mean_window_s:g} s trailing mean with a "
                 f"±{w.recovery_band_rel * 100:g} % band (the acceptance view, README "
                 f"Metrics) tp {after}")
    return band


def _event_claims(m: Matrix, scenario: str, what: tuple[str, str]) -> list[Finding]:
    """W3 overshoot/settling and W4 dip/recovery: the disturbance peak error and the
    recovery time on the low-pass (raw beside), TP magnitudes and TP vs DP."""
    out = []
    if not m.values(scenario, REFERENCE, "rmse_N"):
        return out
    study = STUDY_DISTURBANCE[scenario]
    ref = study[STUDY_REFERENCE]
    peak = m.values(scenario, REFERENCE, "disturbance_peak_error_lp_N")
    peak_raw = m.values(scenario, REFERENCE, "disturbance_peak_error_N")
    rec = m.values(scenario, REFERENCE, "recovery_time_lp_s")
    rec_raw = m.values(scenario, REFERENCE, "recovery_time_s")
    v_peak, t_peak = verdict_magnitude(list(peak.values()), ref[0], 1e-3, "kN")
    v_rec, t_rec = verdict_magnitude(list(rec.values()), ref[1], 1.0, "s")
    band = _recovery_band(m, scenario, rec)
    out.append(Finding(
        f"{scenario}: TP {what[0]} / {what[1]}",
        f"{ref[0] / 1e3:g} kN / {ref[1]:g} s",
        f"low-pass {_kn(peak)} / {mean_std(rec.values())} s; raw {_kn(peak_raw)} / "
        f"{mean_std(rec_raw.values())} s", f"{v_peak} / {v_rec}",
        f"{what[0]}: {t_peak}; {what[1]}: {t_rec}{band}. The raw peak adds the ripple's crest "
        "and the raw error rarely stays inside the band"))
    for dp in STUDY_REDUCED:
        other = m.values(scenario, dp, "disturbance_peak_error_lp_N")
        if not other:
            continue
        implied = 100.0 * (1.0 - ref[0] / study[dp][0])
        red = reductions(peak, other)
        verdict, text = verdict_reduction(red, implied, implied)
        rec_dp = m.values(scenario, dp, "recovery_time_lp_s")
        out.append(Finding(
            f"{scenario}: TP {what[0]} smaller than {dp.upper()}",
            f"{ref[0] / 1e3:g} vs {study[dp][0] / 1e3:g} kN ({implied:.0f} % less); "
            f"{what[1]} {ref[1]:g} vs {study[dp][1]:g} s",
            f"{dp} low-pass {_kn(other)} / {mean_std(rec_dp.values())} s; {lower_by(red)}",
            verdict, f"{text}. {DP_WHY[dp]}"))
    return out


def _w3_pressure(m: Matrix) -> list[Finding]:
    """W3: TP's peak head pressure below dp-a's (dp-b has no chamber pressure)."""
    tp_p = m.values("W3", REFERENCE, "p_head_max_Pa")
    dpa_p = m.values("W3", "dp-a", "p_head_max_Pa")
    if not (tp_p and dpa_p):
        return []
    low, high = STUDY_W3_PRESSURE_LOWER_PA
    diff = [dpa_p[k] - tp_p[k] for k in tp_p if k in dpa_p]
    mean = float(np.mean(diff))
    verdict = ("agrees" if low - max(2 * np.std(diff), 0.25e6) <= mean
               <= high + max(2 * np.std(diff), 0.25e6) else "differs")
    return [Finding(
        "W3: TP peak pressure lower than DP", f"{low / 1e6:g}-{high / 1e6:g} MPa lower",
        f"tp {mean_std(tp_p.values(), 1e-6)} MPa, dp-a {mean_std(dpa_p.values(), 1e-6)} "
        f"MPa: dp-a − tp = {mean_std(diff, 1e-6, 2)} MPa", verdict,
        "vs dp-a only (same hydraulics): dp-b's head pressure is the equivalent pressure of "
        "its ideal force source, not a chamber pressure; " + DP_WHY["dp-a"])]


def _w3_switching(m: Matrix) -> list[Finding]:
    """W3: TP switches its valves less than each reduced architecture."""
    out = []
    fewer = STUDY_W3_FEWER_SWITCHES_PCT
    for dp in STUDY_REDUCED:
        tp_s = m.values("W3", REFERENCE, "valve_switches")
        other = m.values("W3", dp, "valve_switches")
        if not other:
            continue
        red = reductions(tp_s, other)
        verdict, text = verdict_reduction(red, fewer, fewer)
        out.append(Finding(f"W3: TP switches its valves less than {dp.upper()}",
                           f"~{fewer:.0f} % fewer",
                           f"tp {mean_std(tp_s.values())}, {dp} {mean_std(other.values())} "
                           f"switches: {lower_by(red)}", verdict, text))
    return out


# ----------------------------------------------------------------------------- W5, W2, speed

def _w5_claims(m: Matrix) -> list[Finding]:
    """W5: TP's fluctuation under the perturbations, and TP more robust than each DP."""
    out = []
    if not m.values("W5", REFERENCE, "rmse_N", variant=None):
        return out
    study_r, study_f = STUDY_RMSE["W5"], STUDY_FLUCTUATION["W5"]
    ref_r, ref_f = study_r[STUDY_REFERENCE], study_f[STUDY_REFERENCE]
    tp = m.values("W5", REFERENCE, "rmse_N", variant=None)
    tp_f = m.values("W5", REFERENCE, "fluctuation_N", variant=None)
    v_f, t_f = verdict_magnitude(list(tp_f.values()), ref_f, 1e-3, "kN")
    tp_f_lp = m.values("W5", REFERENCE, "fluctuation_lp_N", variant=None)
    out.append(Finding("W5: TP fluctuation under ±20 % perturbations",
                       f"±{ref_f / 1e3:g} kN",
                       f"raw ±{_kn(tp_f)} over {len(tp_f)} runs (variants × seeds); "
                       f"low-pass ±{_kn(tp_f_lp)}",
                       v_f, f"{t_f} (raw, half the 95 % band); " + _ripple_reason(m, "W5")))
    for dp in STUDY_REDUCED:
        other = m.values("W5", dp, "rmse_N", variant=None)
        if not other:
            continue
        implied = 100.0 * (1.0 - ref_r / study_r[dp])
        red = reductions(tp, other)
        red_lp = reductions(m.values("W5", REFERENCE, "rmse_lp_N", variant=None),
                            m.values("W5", dp, "rmse_lp_N", variant=None))
        verdict, text = verdict_reduction(red, implied, implied)
        ranges = _variant_ranges_kn(m, (REFERENCE, dp))
        out.append(Finding(
            f"W5: TP more robust than {dp.upper()}",
            f"RMSE {ref_r / 1e3:g} vs {study_r[dp] / 1e3:g} kN ({implied:.0f} % lower)",
            f"{lower_by(red)} raw, {lower_by(red_lp)} low-pass; spread of the "
            f"low-passed RMSE over the variants: tp {ranges[REFERENCE]:.2g} kN, {dp} "
            f"{ranges[dp]:.2g} kN", verdict,
            f"{text}. Robustness read as the tracking error under every perturbation, pooled; "
            f"{DP_WHY[dp]}"))
    return out


def _variant_ranges_kn(m: Matrix, archs: tuple[str, ...]) -> dict[str, float]:
    """Per architecture, the range (max − min) over W5's variants of the mean low-passed
    RMSE over seeds [kN]."""
    spread = {a: [float(np.mean(finite(m.values("W5", a, "rmse_lp_N", variant=v.name)
                                       .values()) or [math.nan]))
                  for v in load_scenario("W5").variants] for a in archs}
    return {a: (np.nanmax(s) - np.nanmin(s)) / 1e3 for a, s in spread.items()}


def _vibration_claim(m: Matrix) -> list[Finding]:
    """W2: TP's body acceleration in the 8-12 Hz mode against dp-b's (dp-a has no chassis)."""
    tp = m.values("W2", REFERENCE, "chassis_acc_body_mode_rms_m_s2")
    dpb = m.values("W2", "dp-b", "chassis_acc_body_mode_rms_m_s2")
    if not tp:
        return []
    low, high = STUDY_W2_BODY_ACC_LOWER_PCT
    red = reductions(tp, dpb)
    verdict, text = verdict_reduction(red, low, high)
    return [Finding("W2: TP body acceleration in the 8-12 Hz mode lower than DP",
                    f"{low:.0f}-{high:.0f} % lower RMS",
                    f"tp {mean_std(tp.values())} m/s², dp-b {mean_std(dpb.values())} m/s²: "
                    f"{lower_by(red)}; dp-a: no chassis", verdict,
                    f"{text}. vs dp-b only: dp-a has no chassis (an equivalent idler), so its "
                    "body acceleration does not exist; band and window in the README metrics")]


def _speed_claim(m: Matrix, timing: MatrixRun | None) -> list[Finding]:
    """TP's real-time factor against the study's, each run's loop alone."""
    rtf = [lookup(r.metrics, "real_time_factor") for (case, a), r in m.runs.items()
           if a == REFERENCE and case[3] == m.controller(case[0])]
    if not finite(rtf):
        return []
    mean = float(np.mean(finite(rtf)))
    load = ""
    if timing is not None and len(timing.results) > timing.resumed:
        load = (f"; 1-min load average {timing.load_average[0]:.1f} at the start and "
                f"{timing.load_average[1]:.1f} at the end of this report on "
                f"{os.cpu_count()} cores (other jobs share the machine)")
    (low, high), (ms_low, ms_high) = STUDY_REAL_TIME_FACTOR, STUDY_STEP_WALL_MS
    return [Finding("Tri-platform speed", f"{low:g}-{high:g}× real time ({ms_low:g}-{ms_high:g} "
                                          f"ms per 1 ms step, {STUDY_HOST})",
                    f"tp {mean_std(rtf)}× real time ({machine()}), each run's loop alone",
                    f"ours ×{mean / STUDY_REAL_TIME_FACTOR_MID:.1f} the study's",
                    "one process (MuJoCo + numba hydraulics + CasADi NMPC) instead of three "
                    f"tools coupled through FMI; different machines{load}")]


# ----------------------------------------------------------------------------- all claims

Claim = Callable[[Matrix, MatrixRun | None], list[Finding]]
"""A claim: its rows of the claims table from the results and how they were made."""


def _tracking(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """W1, W2: TP's tension RMSE and TP against each DP."""
    return [f for s in ("W1", "W2") if s in m.scenarios for f in _tracking_claims(m, s)]


def _prediction(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """W1, W2, W5: each DP's prediction error against TP, bounded by the study's RMSEs."""
    return [f for s in ("W1", "W2", "W5") if s in m.scenarios for f in _prediction_claims(m, s)]


def _energy(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """TP's energy against DP-A (a prediction) and DP-B (not comparable)."""
    return _energy_vs_dpa(m) + _energy_vs_dpb(m)


def _controllers(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """NMPC against the baseline controllers on TP."""
    return _controller_claims(m)


def _w3(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """W3: overshoot and settling, peak pressure, valve switching."""
    if "W3" not in m.scenarios:
        return []
    return _event_claims(m, "W3", ("overshoot", "settling")) + _w3_pressure(m) + _w3_switching(m)


def _w4(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """W4: dip and recovery."""
    return _event_claims(m, "W4", ("dip", "recovery")) if "W4" in m.scenarios else []


def _w5(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """W5: fluctuation and robustness under the perturbations."""
    return _w5_claims(m)


def _vibration(m: Matrix, _: MatrixRun | None) -> list[Finding]:
    """W2: body acceleration in the body mode."""
    return _vibration_claim(m) if "W2" in m.scenarios else []


CLAIMS: tuple[Claim, ...] = (_tracking, _prediction, _energy, _controllers, _w3, _w4, _w5,
                             _vibration, _speed_claim)
"""The study's claims in the order of the report; each gives its rows of the table."""


def claims(m: Matrix, timing: MatrixRun | None = None) -> list[Finding]:
    """Every claim the results can speak to."""
    return [f for claim in CLAIMS for f in claim(m, timing)]
