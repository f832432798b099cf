"""``trackmj report``: W1-W5 × architectures × seeds (W5 × its variants) -> report.md.

The report answers the study's claims one by one (Ding et al., "Simulation Method for
Hydraulic Tensioning Systems in Tracked Vehicles Using Simulink-AMESim-RecurDyn",
Actuators 2025, 14(12), 615): each claim with the study's figure, ours (mean ± std over
seeds, the same metric definition where the study gives one) and a verdict with its reason
(:data:`CLAIMS`). The study's figures are printed for comparison only; nothing in trackmj is
tuned toward them.

Runs: every scenario's variants × seeds × architectures (``tp``, ``dp-a``, ``dp-b`` by
default, the study's three) with the scenario's controller, plus the baseline controllers
(``lmpc``, ``pid``) on ``tp`` in W1 for the controller claims. They run on the shared
executor as a campaign (:mod:`trackmj.study.campaign`); each run is written to
``OUT/runs/<scenario>-<arch>-<controller>-<variant>-s<seed>/`` and its row to
``OUT/results.parquet`` as it finishes, and a run already done there (the same identity:
inputs and code) is read back instead of run again, so an interrupted report resumes. A
``--duration`` shorter than a scenario's events moves them inside the run
(:func:`event_moves`); the report says where to. A dp-a run needs its tp run's track
load: when only the dp-a run is missing, the executor runs the tp case again for it
(deterministic per seed, so the same load).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from trackmj.host import machine
from trackmj.io import write_text_atomic
from trackmj.results.figures import (
    overlay_figure,
    psd_figure,
    run_figure,
    variants_figure,
    windows_of,
)
from trackmj.results.metrics import (
    METRIC_DISPLAY,
    energy_terms,
    headline_energy,
    lookup,
    prediction_vs_tp,
)
from trackmj.results.store import Result
from trackmj.results.store import _json_ready as jsonable  # the one JSON form of metrics
from trackmj.scenarios.schema import describe_moves, load_scenario
from trackmj.sim.setup import prepare
from trackmj.study.campaign import (
    RUNS,
    PlannedRun,
    Store,
    check_campaign_dir,
    finite,
    plan_run,
    run_campaign,
)
from trackmj.study.campaign import mean_std as statistics
from trackmj.study.executor import RunOutcome, RunSpec, overrides_tuple

REPORT_ARCHS = ("tp", "dp-a", "dp-b")
"""Architectures of a report by default: the study's three (tp-weak with ``--archs``)."""
BASELINES = ("lmpc", "pid")
"""Baseline controllers run on tp for the controller claims."""
BASELINE_SCENARIOS = ("W1",)
"""Conditions the baselines run in: tracking (W1); more would push the full report past its
15 min budget on two cores (10 runs of ~12 s CPU each per condition at 5 seeds)."""
REPORT = "report.md"
STUDY = ("Ding et al., \"Simulation Method for Hydraulic Tensioning Systems in Tracked "
         "Vehicles Using Simulink-AMESim-RecurDyn\", Actuators 2025, 14(12), 615")


# ----------------------------------------------------------------------------- the runs

def run_name(scenario: str, architecture: str, controller: str, variant: str, seed: int) -> str:
    """Directory name of one run of the report under ``OUT/runs``."""
    return f"{scenario}-{architecture}-{controller}-{variant}-s{seed}"


def event_moves(scenario: str, duration: float | None) -> dict[str, float]:
    """The scenario overrides that move ``scenario``'s events inside a run of ``duration``
    [s] (:func:`trackmj.scenarios.schema.moved_events`; {} for the scenario's own duration)."""
    from trackmj.scenarios.schema import moved_events

    return {} if duration is None else moved_events(load_scenario(scenario), duration)


def plan(scenarios: Sequence[str], seeds: Sequence[int], duration: float | None,
         archs: Sequence[str] = REPORT_ARCHS,
         baselines: Sequence[str] = BASELINES, tensioner: str | None = None,
         machine: str | None = None) -> list[PlannedRun]:
    """Every run of a report: each scenario's variants × seeds × ``archs`` with its own
    controller, then ``baselines`` on tp in the nominal :data:`BASELINE_SCENARIOS`;
    ``tensioner`` (a tensioner file) replaces the hydraulic element where an architecture
    has one (:func:`tensioner_for`); ``machine`` (a shipped name or a machine file) is
    every run's. A ``duration`` that would cut off a scenario's step,
    pulse or drop moves its events inside the run (:func:`event_moves`). Each run is
    validated here (ParameterError before anything runs) and known by its identity
    (:func:`trackmj.study.campaign.run_key`)."""
    specs = []
    for name in scenarios:
        sc = load_scenario(name)
        moves = overrides_tuple({f"scenario.{k}": v
                                 for k, v in event_moves(name, duration).items()})
        specs += [RunSpec(scenario=name, architecture=arch, controller=sc.controller,
                          seed=seed, duration=duration, variant=variant.name,
                          overrides=moves, tensioner=tensioner_for(arch, tensioner),
                          machine=machine)
                  for variant in sc.variants for seed in seeds for arch in archs]
        if sc.name in BASELINE_SCENARIOS:
            specs += [RunSpec(scenario=name, architecture="tp", controller=c, seed=seed,
                              duration=duration, overrides=moves, tensioner=tensioner,
                              machine=machine)
                      for c in baselines if c != sc.controller for seed in seeds]
    setups: dict[RunSpec, Any] = {}
    runs = []
    for spec in specs:
        unseeded = replace(spec, seed=0)
        if unseeded not in setups:          # validated once per case, not once per seed
            setups[unseeded] = prepare(**unseeded.prepare_kwargs())
        setup = replace(setups[unseeded], seed=spec.seed)
        runs.append(plan_run(spec, setup=setup, name=run_name(
            setup.scenario.name, setup.architecture, setup.controller, setup.variant.name,
            setup.seed)))
    return runs


def tensioner_for(architecture: str, tensioner: str | None) -> str | None:
    """The tensioner file a run of ``architecture`` takes: ``tensioner`` where the
    architecture's element is the one a file replaces, else None (dp-b keeps its ideal
    source)."""
    from trackmj.sim.registry import ARCHITECTURES, REPLACEABLE_ELEMENT

    replaceable = ARCHITECTURES[architecture].element == REPLACEABLE_ELEMENT
    return tensioner if replaceable else None


@dataclass
class MatrixRun:
    """What :func:`run_matrix` did: the results (resumed and new), the runs that failed
    (spec, error), how many were resumed, the wall time [s], the workers, the 1-min load
    average at the start and the end, and each computed run's own wall time in its worker
    by architecture [s]."""

    results: list[Result]
    failed: list[tuple[RunSpec, str]] = field(default_factory=list)
    resumed: int = 0
    wall_time_s: float = 0.0
    workers: int | None = None
    load_average: tuple[float, float] = (math.nan, math.nan)
    run_wall_s: dict[str, list[float]] = field(default_factory=dict)


def run_matrix(runs: Sequence[PlannedRun], out_dir: str | Path, *, workers: int | None = None,
               scheduler: str | None = None, progress: bool = True,
               executor: Any = None) -> MatrixRun:
    """Make the runs of a report in ``out_dir`` (a campaign of kind ``report``,
    :mod:`trackmj.study.campaign`): each run is written to ``OUT/runs/<name>/`` and its row to
    ``OUT/results.parquet`` as it finishes; a run already done there (same identity) is
    read back instead. A failed run is reported and left out."""
    start = time.perf_counter()
    load_start = os.getloadavg()[0]
    run_wall: dict[str, list[float]] = defaultdict(list)

    def on_outcome(run: PlannedRun, outcome: RunOutcome) -> None:
        run_wall[outcome.spec.architecture].append(outcome.wall_time_s)
        if not outcome.ok:
            print(f"trackmj: {run.name}: {outcome.error}", file=sys.stderr)

    with Store(out_dir, "report", markers=(RUNS, REPORT)) as store:
        made = run_campaign(store, runs, executor=executor, workers=workers,
                            scheduler=scheduler, progress="report" if progress else None,
                            need_results=True, on_outcome=on_outcome)
    results = [made.results[r.key] for r in {r.key: r for r in runs}.values()
               if r.key in made.results]
    return MatrixRun(results, [(o.spec, o.error or "failed") for o in made.failed],
                     made.resumed, time.perf_counter() - start,
                     workers or (None if scheduler else os.cpu_count()),
                     (load_start, os.getloadavg()[0]), dict(run_wall))


# ----------------------------------------------------------------------------- indexing

def _variant(r: Result) -> str:
    return r.metadata.get("variant", "nominal")


Case = tuple[str, str, int, str]
"""(scenario, variant, seed, controller): runs of one case differ only in architecture."""


class Matrix:
    """The report's results indexed by case and architecture, with each reduced
    architecture's prediction error against the tp run of its case."""

    def __init__(self, results: Iterable[Result]) -> None:
        self.runs: dict[tuple[Case, str], Result] = {}
        for r in results:
            self.runs[((r.scenario, _variant(r), r.seed, r.controller), r.architecture)] = r
        self.predictions: dict[tuple[Case, str], dict[str, Any]] = {}
        for (case, arch), r in self.runs.items():
            tp = self.runs.get((case, "tp"))
            if tp is not None:
                self.predictions[(case, arch)] = prediction_vs_tp(
                    r.columns(), r.metrics, tp.columns(), tp.metrics, windows_of(r))

    @property
    def scenarios(self) -> list[str]:
        return sorted({case[0] for case, _ in self.runs})

    def architectures(self, scenario: str) -> list[str]:
        from trackmj.sim.registry import ARCHITECTURES

        found = {a for (case, a) in self.runs if case[0] == scenario}
        return [a for a in ARCHITECTURES if a in found]   # the registry's order

    def controller(self, scenario: str) -> str:
        """The scenario's own controller (the one its architectures ran with)."""
        return load_scenario(scenario).controller

    def values(self, scenario: str, arch: str, key: str, *, controller: str | None = None,
               variant: str | None = "nominal") -> dict[tuple[str, int], float]:
        """(variant, seed) -> metric ``key`` (dotted; see :func:`lookup`) of the runs of
        ``arch`` in ``scenario`` with ``controller`` (default: the scenario's) and
        ``variant`` (None: every variant)."""
        controller = controller or self.controller(scenario)
        return {(case[1], case[2]): lookup(r.metrics, key) for (case, a), r in self.runs.items()
                if case[0] == scenario and a == arch and case[3] == controller
                and (variant is None or case[1] == variant)}

    def prediction(self, scenario: str, arch: str, key: str,
                   variant: str | None = "nominal") -> dict[tuple[str, int], float]:
        """(variant, seed) -> prediction error ``key`` of ``arch`` against tp."""
        ctrl = self.controller(scenario)
        return {(case[1], case[2]): lookup(p, key) for (case, a), p in self.predictions.items()
                if case[0] == scenario and a == arch and case[3] == ctrl
                and (variant is None or case[1] == variant)}

    def first_case(self, scenario: str) -> Case | None:
        cases = sorted(case for case, a in self.runs if case[0] == scenario and case[1] ==
                       "nominal" and case[3] == self.controller(scenario))
        return cases[0] if cases else None


# ----------------------------------------------------------------------------- statistics

def _finite(values: Iterable[float]) -> list[float]:
    return finite(values)


def mean_std(values: Iterable[float], scale: float = 1.0, digits: int = 3) -> str:
    """"mean ± std" of the finite values (population std over seeds,
    :func:`trackmj.study.campaign.mean_std`), scaled; "–" if none; "(k of n undefined)" appended
    when some are NaN (e.g. never settled)."""
    values = list(values)
    mean, std, n = statistics(values)
    missing = len(values) - n
    tail = f" ({missing} of {len(values)} undefined)" if missing else ""
    if not n:
        return "–" + tail
    if n == 1:
        return f"{mean * scale:.{digits}g}" + tail
    return f"{mean * scale:.{digits}g} ± {std * scale:.2g}" + tail


def percent(values: Iterable[float]) -> str:
    """Percentages as "mean ± std %" with whole points (one value: no ± part)."""
    v = _finite(values)
    if not v:
        return "– %"
    digits = 1 if all(abs(x) < 10.0 for x in v) else 0
    if len(v) == 1:
        return f"{v[0]:.{digits}f} %"
    return f"{np.mean(v):.{digits}f} ± {np.std(v):.{digits}f} %"


def lower_by(values: Sequence[float], who: str = "TP") -> str:
    """"TP lower by x %" for per-seed reductions, "TP higher by x %" when they are negative
    on average (then x = 100·(tp/other − 1))."""
    v = _finite(values)
    if v and float(np.mean(v)) < 0.0:
        return f"{who} higher by {percent([-x for x in v])}"
    return f"{who} lower by {percent(v)}"


def reductions(tp: Mapping[Any, float], other: Mapping[Any, float]) -> list[float]:
    """Paired reductions 100·(1 − tp/other) [%] over the keys (seeds) both have finite."""
    return [100.0 * (1.0 - tp[k] / other[k]) for k in tp
            if k in other and math.isfinite(tp[k]) and math.isfinite(other[k]) and other[k] != 0]


def verdict_reduction(values: Sequence[float], low: float, high: float) -> tuple[str, str]:
    """Verdict on "TP is low..high % below X" from per-seed reductions [%]: *no difference*
    if every seed is within ±1 %; *supported* if every seed has the claimed sign and the
    mean lies within the range widened by max(2 std, 5 points); *direction only* if every
    seed has the sign but not the size; *contradicted* if every seed has the opposite sign;
    *inconclusive* otherwise."""
    v = _finite(values)
    if not v:
        return "not measured", "no pair of runs to compare"
    mean, std = float(np.mean(v)), float(np.std(v))
    tol = max(2.0 * std, 5.0)
    study = f"{low:.0f} %" if low == high else f"{low:.0f}-{high:.0f} %"
    ours = percent(v)
    if all(abs(x) < 1.0 for x in v):
        return "no difference", f"equal within 1 % in every seed ({ours}; study {study})"
    if all(x > 0 for x in v):
        if low - tol <= mean <= high + tol:
            return "supported", f"every seed lower, by {ours} (study {study})"
        return "direction only", f"every seed lower, but by {ours}, not {study}"
    if all(x < 0 for x in v):
        return "contradicted", f"the opposite in every seed: higher by {percent([-x for x in v])}"
    return "inconclusive", f"the sign changes across seeds ({ours})"


def verdict_magnitude(values: Sequence[float], study: float, unit_scale: float,
                      unit: str) -> tuple[str, str]:
    """*agrees* if |mean − study| <= max(2 std, 25 % of the study's value), else *differs*
    (the ratio stated)."""
    v = _finite(values)
    if not v:
        return "not measured", "undefined in every run"
    mean, std = float(np.mean(v)), float(np.std(v))
    ratio = mean / study if study else math.nan
    text = f"ours {mean * unit_scale:.3g} {unit}, ×{ratio:.2f} the study's"
    if abs(mean - study) <= max(2.0 * std, 0.25 * abs(study)):
        return "agrees", text
    return "differs", text


# ----------------------------------------------------------------------------- claims

@dataclass(frozen=True)
class Finding:
    """One row of the claims table."""

    claim: str
    study: str
    ours: str
    verdict: str
    reason: str


def _kn(values: Mapping[Any, float]) -> str:
    return mean_std(values.values(), 1e-3) + " kN"


def _ripple_reason(m: Matrix, scenario: str) -> str:
    """Why a raw tension figure differs: the ripple and the slow low-passed error of tp."""
    ripple = m.values(scenario, "tp", "ripple_rms_N")
    tooth = m.values(scenario, "tp", "ripple_band_rms_N.tooth_passing")
    lp = m.values(scenario, "tp", "rmse_lp_N")
    fl = m.values(scenario, "tp", "fluctuation_lp_N")
    return (f"tp's raw F_ten carries a ripple of {_kn(ripple)} RMS ({_kn(tooth)} of it in "
            f"the tooth-passing band) that no valve follows; on the {_cutoff(m, scenario)} "
            f"low-pass its error is {_kn(lp)} RMS, a slow wander of ±{_kn(fl)} (95 % band) "
            "around the reference")


def _cutoff(m: Matrix, scenario: str) -> str:
    case = m.first_case(scenario)
    if case is None:
        return "low-pass"
    return f"{windows_of(m.runs[(case, 'tp')]).lowpass_cutoff_Hz:g} Hz"


STUDY_RMSE = {"W1": {"tp": 420.0, "dp-a": 1150.0, "dp-b": 920.0},
              "W2": {"tp": 860.0, "dp-a": 1640.0, "dp-b": 1270.0},
              "W5": {"tp": 790.0, "dp-a": 1750.0, "dp-b": 1280.0}}
"""The study's tension RMSE [N] per condition and architecture (its results tables)."""
STUDY_FLUCTUATION = {"W2": {"tp": 1300.0, "dp-a": 2600.0, "dp-b": 2100.0},
                     "W5": {"tp": 1100.0, "dp-a": 2800.0, "dp-b": 2000.0}}
"""The study's tension fluctuation ±[N]."""
STUDY_ENERGY_KJ = {"W1": (82.4, 95.8, 91.7), "W2": (83.1, 97.2, 93.0), "W3": (83.1, 97.2, 93.0),
                   "W4": (80.3, 96.1, 92.4), "W5": (81.5, 98.2, 93.6)}
"""The study's "energy consumption" [kJ] (TP, DP-A, DP-B); undefined in the study."""
DP_WHY = {"dp-a": "dp-a runs the same hydraulics on the identified equivalent idler and "
                  "replays tp's own track load, so it differs from tp only by the idler "
                  "motion's feedback into the track",
          "dp-b": "dp-b keeps the track and replaces the oil column by an ideal force source "
                  "(rate-limited, one lag), so it lacks the oil column's compliance and the "
                  "valves' flow limits"}


def _tracking_claims(m: Matrix, scenario: str) -> list[Finding]:
    out = []
    study = STUDY_RMSE[scenario]
    tp = m.values(scenario, "tp", "rmse_N")
    tp_lp = m.values(scenario, "tp", "rmse_lp_N")
    verdict, text = verdict_magnitude(list(tp.values()), study["tp"], 1e-3, "kN")
    out.append(Finding(f"{scenario}: TP tension RMSE", f"{study['tp'] / 1e3:g} kN",
                       f"raw {_kn(tp)}; low-pass {_kn(tp_lp)}", verdict,
                       f"{text} (raw, the study's definition); " + _ripple_reason(m, scenario)))
    for dp in ("dp-a", "dp-b"):
        other = m.values(scenario, dp, "rmse_N")
        if not other:
            continue
        other_lp = m.values(scenario, dp, "rmse_lp_N")
        red, red_lp = reductions(tp, other), reductions(tp_lp, other_lp)
        implied = 100.0 * (1.0 - study["tp"] / study[dp])
        verdict, text = verdict_reduction(red, implied, implied)
        pred = m.prediction(scenario, dp, "prediction_rmse_vs_tp_lp_N")
        out.append(Finding(
            f"{scenario}: TP tracks better than {dp.upper()}",
            f"RMSE {study['tp'] / 1e3:g} vs {study[dp] / 1e3:g} kN ({implied:.0f} % lower)",
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
    for dp in ("dp-a", "dp-b"):
        raw = m.prediction(scenario, dp, "prediction_rmse_vs_tp_N")
        if not raw:
            continue
        lp = m.prediction(scenario, dp, "prediction_rmse_vs_tp_lp_N")
        bound = abs(study[dp] - study["tp"])
        mean = float(np.mean(_finite(raw.values()))) if _finite(raw.values()) else math.nan
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
            f">= |{study[dp] / 1e3:g} − {study['tp'] / 1e3:g}| = {bound / 1e3:.2f} kN "
            "(implied by its RMSEs)",
            f"raw {_kn(raw)}, low-pass {_kn(lp)}", verdict, f"{text}. {DP_WHY[dp]}"))
    return out


def _energy_claims(m: Matrix) -> list[Finding]:
    """TP energy 12-17 % below DP, vs dp-a where the definitions match (same hydraulics)."""
    parts, pooled, terms = [], [], set()
    for scenario in m.scenarios:
        if not m.values(scenario, "dp-a", "rmse_N", variant=None):
            continue
        tp_runs = {k: r for (case, a), r in m.runs.items() if a == "tp"
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
        if red:
            pooled += red
            parts.append(f"{scenario} {lower_by(red)}")
    findings = []
    if pooled:
        verdict, text = verdict_reduction(pooled, 12.0, 17.0)
        term_text = ", ".join(sorted(terms))
        why = ""
        if verdict == "no difference":
            why = (" The energy drawn is set by the supply, not by the architecture: with the "
                   "accumulator supply a fixed-displacement pump works against the relief "
                   "whatever the cylinders take (the relief spills the rest), and dp-a's "
                   "valve flows follow tp's closely.")
        findings.append(Finding(
            "TP uses less energy than DP-A", "12-17 % less (W1 82.4 vs 95.8 kJ)",
            f"{term_text} energy, TP vs dp-a: " + "; ".join(parts), verdict,
            f"{text}.{why} Both run the same hydraulic model and ledger, so the {term_text} "
            "energies mean the same thing and their difference is a prediction; magnitudes "
            "are not compared with the study's kJ, which it does not define (neither what is "
            "counted nor over which window)"))
    dpb = [s for s in m.scenarios if m.values(s, "dp-b", "rmse_N")]
    if dpb:
        s = dpb[0]
        e = [energy_terms(r.metrics) for (case, a), r in m.runs.items()
             if a == "dp-b" and case[0] == s] or [energy_terms({})]
        notes = sorted({n for t in e for n in t.notes})
        findings.append(Finding(
            "TP uses less energy than DP-B", "W1 82.4 vs 91.7 kJ (10 % less)",
            f"dp-b terms: {', '.join(sorted(k for k, v in e[0].terms.items() if v == v))}"
            + (f" ({'; '.join(notes)})" if notes else ""), "not comparable",
            "dp-b has no hydraulic circuit: its energy is the ideal force source's work, "
            "without throttling, relief or leakage, so a difference to tp measures what dp-b "
            "leaves out by construction, not a prediction; the study does not say how it "
            "counted DP-B's energy either"))
    return findings


def _controller_claims(m: Matrix) -> list[Finding]:
    out = []
    for baseline, (low, high) in (("lmpc", (30.0, 45.0)), ("pid", (40.0, 55.0))):
        parts, pooled, pooled_lp = [], [], []
        for scenario in m.scenarios:
            nmpc = m.values(scenario, "tp", "rmse_N")
            other = m.values(scenario, "tp", "rmse_N", controller=baseline)
            if not other:
                continue
            red = reductions(nmpc, other)
            red_lp = reductions(m.values(scenario, "tp", "rmse_lp_N"),
                                m.values(scenario, "tp", "rmse_lp_N", controller=baseline))
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


def _event_claims(m: Matrix, scenario: str, what: str, study: Mapping[str, tuple[float, float]],
                  ) -> list[Finding]:
    """W3 overshoot/settling and W4 dip/recovery: the disturbance peak error and the
    recovery time on the low-pass (raw beside), TP magnitudes and TP vs DP."""
    out = []
    if not m.values(scenario, "tp", "rmse_N"):
        return out
    peak = m.values(scenario, "tp", "disturbance_peak_error_lp_N")
    peak_raw = m.values(scenario, "tp", "disturbance_peak_error_N")
    rec = m.values(scenario, "tp", "recovery_time_lp_s")
    rec_raw = m.values(scenario, "tp", "recovery_time_s")
    v_peak, t_peak = verdict_magnitude(list(peak.values()), study["tp"][0], 1e-3, "kN")
    v_rec, t_rec = verdict_magnitude(list(rec.values()), study["tp"][1], 1.0, "s")
    case = m.first_case(scenario)
    band = ""
    if case is not None:
        w = windows_of(m.runs[(case, "tp")])
        band = (f" (band ±{w.settle_band_rel * 100:g} % of F_ref held {w.min_hold_s:g} s, "
                "from each onset)")
        if not _finite(rec.values()):
            band += ("; no run recovers: even the low-passed error does not stay inside the "
                     "band before the next onset or the end (tp's low-passed RMSE over the "
                     f"run: {_kn(m.values(scenario, 'tp', 'rmse_lp_N'))})")
        accepted = m.values(scenario, "tp", "acceptance.recovery_max_s")
        if _finite(accepted.values()):
            after = ("never leaves it" if max(_finite(accepted.values())) == 0.0
                     else f"is back after {mean_std(accepted.values())} s (worst edge)")
            band += (f"; on the {w.mean_window_s:g} s trailing mean with a "
                     f"±{w.recovery_band_rel * 100:g} % band (the acceptance view, README "
                     f"Metrics) tp {after}")
    out.append(Finding(
        f"{scenario}: TP {what[0]} / {what[1]}",
        f"{study['tp'][0] / 1e3:g} kN / {study['tp'][1]:g} s",
        f"low-pass {_kn(peak)} / {mean_std(rec.values())} s; raw {_kn(peak_raw)} / "
        f"{mean_std(rec_raw.values())} s", f"{v_peak} / {v_rec}",
        f"{what[0]}: {t_peak}; {what[1]}: {t_rec}{band}. The raw peak adds the ripple's crest "
        "and the raw error rarely stays inside the band"))
    for dp in ("dp-a", "dp-b"):
        other = m.values(scenario, dp, "disturbance_peak_error_lp_N")
        if not other:
            continue
        implied = 100.0 * (1.0 - study["tp"][0] / study[dp][0])
        red = reductions(peak, other)
        verdict, text = verdict_reduction(red, implied, implied)
        rec_dp = m.values(scenario, dp, "recovery_time_lp_s")
        out.append(Finding(
            f"{scenario}: TP {what[0]} smaller than {dp.upper()}",
            f"{study['tp'][0] / 1e3:g} vs {study[dp][0] / 1e3:g} kN ({implied:.0f} % less); "
            f"{what[1]} {study['tp'][1]:g} vs {study[dp][1]:g} s",
            f"{dp} low-pass {_kn(other)} / {mean_std(rec_dp.values())} s; {lower_by(red)}",
            verdict, f"{text}. {DP_WHY[dp]}"))
    return out


def _w3_pressure_switching(m: Matrix) -> list[Finding]:
    out = []
    tp_p = m.values("W3", "tp", "p_head_max_Pa")
    dpa_p = m.values("W3", "dp-a", "p_head_max_Pa")
    if tp_p and dpa_p:
        diff = [dpa_p[k] - tp_p[k] for k in tp_p if k in dpa_p]
        mean = float(np.mean(diff))
        verdict = ("agrees" if 0.9e6 - max(2 * np.std(diff), 0.25e6) <= mean
                   <= 1.2e6 + max(2 * np.std(diff), 0.25e6) else "differs")
        out.append(Finding(
            "W3: TP peak pressure lower than DP", "0.9-1.2 MPa lower",
            f"tp {mean_std(tp_p.values(), 1e-6)} MPa, dp-a {mean_std(dpa_p.values(), 1e-6)} "
            f"MPa: dp-a − tp = {mean_std(diff, 1e-6, 2)} MPa", verdict,
            "vs dp-a only (same hydraulics): dp-b's head pressure is the equivalent pressure of "
            "its ideal force source, not a chamber pressure; " + DP_WHY["dp-a"]))
    for dp in ("dp-a", "dp-b"):
        tp_s = m.values("W3", "tp", "valve_switches")
        other = m.values("W3", dp, "valve_switches")
        if not other:
            continue
        red = reductions(tp_s, other)
        verdict, text = verdict_reduction(red, 21.0, 21.0)
        out.append(Finding(f"W3: TP switches its valves less than {dp.upper()}", "~21 % fewer",
                           f"tp {mean_std(tp_s.values())}, {dp} {mean_std(other.values())} "
                           f"switches: {lower_by(red)}", verdict, text))
    return out


def _w5_claims(m: Matrix) -> list[Finding]:
    out = []
    if not m.values("W5", "tp", "rmse_N", variant=None):
        return out
    study_r, study_f = STUDY_RMSE["W5"], STUDY_FLUCTUATION["W5"]
    tp = m.values("W5", "tp", "rmse_N", variant=None)
    tp_f = m.values("W5", "tp", "fluctuation_N", variant=None)
    v_f, t_f = verdict_magnitude(list(tp_f.values()), study_f["tp"], 1e-3, "kN")
    out.append(Finding("W5: TP fluctuation under ±20 % perturbations",
                       f"±{study_f['tp'] / 1e3:g} kN",
                       f"raw ±{_kn(tp_f)} over {len(tp_f)} runs (variants × seeds); "
                       f"low-pass ±{_kn(m.values('W5', 'tp', 'fluctuation_lp_N', variant=None))}",
                       v_f, f"{t_f} (raw, half the 95 % band); " + _ripple_reason(m, "W5")))
    for dp in ("dp-a", "dp-b"):
        other = m.values("W5", dp, "rmse_N", variant=None)
        if not other:
            continue
        implied = 100.0 * (1.0 - study_r["tp"] / study_r[dp])
        red = reductions(tp, other)
        red_lp = reductions(m.values("W5", "tp", "rmse_lp_N", variant=None),
                            m.values("W5", dp, "rmse_lp_N", variant=None))
        verdict, text = verdict_reduction(red, implied, implied)
        spread = {a: [float(np.mean(_finite(m.values("W5", a, "rmse_lp_N", variant=v.name)
                                            .values()) or [math.nan]))
                      for v in load_scenario("W5").variants] for a in ("tp", dp)}
        ranges = {a: (np.nanmax(s) - np.nanmin(s)) / 1e3 for a, s in spread.items()}
        out.append(Finding(
            f"W5: TP more robust than {dp.upper()}",
            f"RMSE {study_r['tp'] / 1e3:g} vs {study_r[dp] / 1e3:g} kN ({implied:.0f} % lower)",
            f"{lower_by(red)} raw, {lower_by(red_lp)} low-pass; spread of the "
            f"low-passed RMSE over the variants: tp {ranges['tp']:.2g} kN, {dp} "
            f"{ranges[dp]:.2g} kN", verdict,
            f"{text}. Robustness read as the tracking error under every perturbation, pooled; "
            f"{DP_WHY[dp]}"))
    return out


def _vibration_claim(m: Matrix) -> list[Finding]:
    tp = m.values("W2", "tp", "chassis_acc_body_mode_rms_m_s2")
    dpb = m.values("W2", "dp-b", "chassis_acc_body_mode_rms_m_s2")
    if not tp:
        return []
    red = reductions(tp, dpb)
    verdict, text = verdict_reduction(red, 19.0, 27.0)
    return [Finding("W2: TP body acceleration in the 8-12 Hz mode lower than DP",
                    "19-27 % lower RMS",
                    f"tp {mean_std(tp.values())} m/s², dp-b {mean_std(dpb.values())} m/s²: "
                    f"{lower_by(red)}; dp-a: no chassis", verdict,
                    f"{text}. vs dp-b only: dp-a has no chassis (an equivalent idler), so its "
                    "body acceleration does not exist; band and window in the README metrics")]


def _speed_claim(m: Matrix, timing: MatrixRun | None) -> list[Finding]:
    rtf = [lookup(r.metrics, "real_time_factor") for (case, a), r in m.runs.items()
           if a == "tp" and case[3] == m.controller(case[0])]
    if not _finite(rtf):
        return []
    mean = float(np.mean(_finite(rtf)))
    load = ""
    if timing is not None and len(timing.results) > timing.resumed:
        load = (f"; 1-min load average {timing.load_average[0]:.1f} at the start and "
                f"{timing.load_average[1]:.1f} at the end of this report on "
                f"{os.cpu_count()} cores (other jobs share the machine)")
    return [Finding("Tri-platform speed", "0.4-0.55× real time (1.8-2.5 ms per 1 ms step, "
                                          "Intel i7 workstation)",
                    f"tp {mean_std(rtf)}× real time ({machine()}), each run's loop alone",
                    f"ours ×{mean / 0.475:.1f} the study's",
                    "one process (MuJoCo + numba hydraulics + CasADi NMPC) instead of three "
                    f"tools coupled through FMI; different machines{load}")]


CLAIMS: tuple[Callable[[Matrix, MatrixRun | None], list[Finding]], ...] = (
    lambda m, _: [f for s in ("W1", "W2") if s in m.scenarios for f in _tracking_claims(m, s)],
    lambda m, _: [f for s in ("W1", "W2", "W5") if s in m.scenarios
                  for f in _prediction_claims(m, s)],
    lambda m, _: _energy_claims(m),
    lambda m, _: _controller_claims(m),
    lambda m, _: (_event_claims(m, "W3", ("overshoot", "settling"),
                                {"tp": (1600.0, 2.4), "dp-a": (3800.0, 4.1),
                                 "dp-b": (2700.0, 3.3)}) + _w3_pressure_switching(m)
                  if "W3" in m.scenarios else []),
    lambda m, _: (_event_claims(m, "W4", ("dip", "recovery"),
                                {"tp": (900.0, 1.8), "dp-a": (2600.0, 3.5),
                                 "dp-b": (1900.0, 2.7)}) if "W4" in m.scenarios else []),
    lambda m, _: _w5_claims(m),
    lambda m, _: _vibration_claim(m) if "W2" in m.scenarios else [],
    _speed_claim,
)
"""The study's claims in the order of the report; each gives its rows of the table."""


def claims(m: Matrix, timing: MatrixRun | None = None) -> list[Finding]:
    """Every claim the results can speak to."""
    return [f for claim in CLAIMS for f in claim(m, timing)]


# ----------------------------------------------------------------------------- report.md

TABLE_METRICS = ("rmse_N", "rmse_lp_N", "ripple_rms_N", "ripple_band_rms_N.tooth_passing",
                 "ripple_band_rms_N.body_mode", "peak_error_lp_N", "overshoot_lp_N",
                 "settling_time_lp_s", "disturbance_peak_error_lp_N", "recovery_time_lp_s",
                 "fluctuation_N", "fluctuation_lp_N", "constraint_violation_s",
                 "p_head_max_Pa", "valve_switch_rate_Hz", "chassis_acc_body_mode_rms_m_s2",
                 "energy_in_J", "interface_energy_residual_J", "real_time_factor")
"""Rows of each condition's table (labels and display units: :data:`METRIC_DISPLAY`)."""
PREDICTION_METRICS = ("prediction_rmse_vs_tp_N", "prediction_rmse_vs_tp_lp_N",
                      "peak_pressure_error_vs_tp_Pa", "energy_error_vs_tp_pct")


def _condition_section(m: Matrix, scenario: str, out: Path) -> list[str]:
    sc = load_scenario(scenario)
    archs = m.architectures(scenario)
    variant = None if scenario == "W5" else "nominal"
    runs = [r for (case, a), r in m.runs.items() if case[0] == scenario]
    seeds = sorted({r.seed for r in runs})
    scope = "all variants × seeds" if variant is None else "seeds"
    lines = [f"## {scenario}: {sc.title}", "",
             f"{sc.controller} controller; mean ± std over {scope} {seeds}.", ""]
    durations = {float(r.metadata.get("duration_s", sc.duration_s)) for r in runs}
    for duration in sorted(durations):
        moves = event_moves(scenario, duration)
        if moves:
            lines += [f"The {duration:g} s runs would cut off events of the {sc.duration_s:g} s "
                      f"scenario, so its schedule after the evaluation start "
                      f"({sc.evaluation.start_s:g} s) is compressed linearly into the run "
                      f"(README, Usage, Durations): {describe_moves(sc, moves)}.", ""]
    lines += ["| metric | " + " | ".join(archs) + " |", "|---|" + "---|" * len(archs)]
    for key in TABLE_METRICS:
        label, scale, unit = METRIC_DISPLAY[key]
        cells = [mean_std(m.values(scenario, a, key, variant=variant).values(), scale)
                 for a in archs]
        if all(c.startswith("–") for c in cells):
            continue
        lines.append(f"| {label} [{unit}] | " + " | ".join(cells) + " |")
    reduced = [a for a in archs if a != "tp"]
    if reduced and "tp" in archs:
        lines += ["", "Prediction error against tp (same seed and variant):", "",
                  "| metric | " + " | ".join(reduced) + " |", "|---|" + "---|" * len(reduced)]
        for key in PREDICTION_METRICS:
            label, scale, unit = METRIC_DISPLAY[key]
            cells = [mean_std(m.prediction(scenario, a, key, variant=variant).values(), scale)
                     for a in reduced]
            lines.append(f"| {label} [{unit}] | " + " | ".join(cells) + " |")
        terms = {a: sorted({p["energy_error_term"] or "none" for (case, b), p in
                            m.predictions.items() if case[0] == scenario and b == a})
                 for a in reduced}
        lines += ["", "Energy compared on the term: " + "; ".join(
            f"{a}: {', '.join(t)}" for a, t in terms.items()) + ".", ""]
    case = m.first_case(scenario)
    if case is not None:
        first = [m.runs[(case, a)] for a in archs if (case, a) in m.runs]
        predictions = {a: m.predictions[(case, a)] for a in archs if (case, a) in m.predictions}
        fig = overlay_figure(first, out / f"{scenario}.png", predictions=predictions,
                             title=f"{scenario} seed {case[2]}, nominal: architectures")
        lines += [f"![{scenario} architectures, seed {case[2]}]({fig.name})", ""]
        if scenario == "W2":
            psd = psd_figure(first, out / f"{scenario}-psd.png")
            lines += [f"![{scenario} spectra, seed {case[2]}]({psd.name})", ""]
        names = [v.name for v in sc.variants]
        if len(names) > 1:
            def per_variant(key: str, scale: float) -> dict[str, list[float]]:
                return {a: [float(np.mean(_finite(m.values(scenario, a, key, variant=v)
                                                  .values()) or [math.nan])) * scale
                            for v in names] for a in archs}

            fig = variants_figure(names, {
                "tension RMSE, low-pass [kN]": per_variant("rmse_lp_N", 1e-3),
                "fluctuation ±, raw [kN]": per_variant("fluctuation_N", 1e-3)},
                out / f"{scenario}-variants.png",
                title=f"{scenario}: per variant, mean over seeds {seeds}")
            lines += [f"![{scenario} per variant]({fig.name})", ""]
        tp = m.runs.get((case, "tp"))
        if tp is not None:
            run_dir = out / RUNS / run_name(scenario, "tp", case[3], case[1], case[2])
            run_figure(tp, run_dir / "timeseries.png")
            lines += [f"tp run in detail: [{run_dir.name}]({RUNS}/{run_dir.name}/"
                      "timeseries.png).", ""]
    return lines


def _controller_section(m: Matrix, out: Path) -> list[str]:
    lines = []
    for scenario in m.scenarios:
        case = m.first_case(scenario)
        if case is None:
            continue
        ctrls = sorted({c[3] for c, a in m.runs if c[0] == scenario and a == "tp"})
        if len(ctrls) < 2:
            continue
        runs = [m.runs[((case[0], case[1], case[2], c), "tp")] for c in ctrls
                if ((case[0], case[1], case[2], c), "tp") in m.runs]
        if not lines:
            lines = ["## Controllers on tp", ""]
        lines += [f"### {scenario}", "", "| metric | " + " | ".join(ctrls) + " |",
                  "|---|" + "---|" * len(ctrls)]
        for key in TABLE_METRICS[:13]:
            label, scale, unit = METRIC_DISPLAY[key]
            cells = [mean_std(m.values(scenario, "tp", key, controller=c).values(), scale)
                     for c in ctrls]
            if not all(c.startswith("–") for c in cells):
                lines.append(f"| {label} [{unit}] | " + " | ".join(cells) + " |")
        fig = overlay_figure(runs, out / f"{scenario}-controllers.png", label_by="controller",
                             title=f"{scenario} seed {case[2]}: controllers on tp")
        lines += ["", f"![{scenario} controllers]({fig.name})", ""]
    return lines


def write_report(results: Sequence[Result], out_dir: str | Path,
                 timing: MatrixRun | None = None) -> Path:
    """report.md (claims, condition tables, prediction errors, figures) and report.json (the
    claims and the prediction errors) in ``out_dir``; the runs are under ``out_dir/runs``."""
    out = Path(out_dir)
    if not results:
        raise ValueError("no finished run to report on")
    m = Matrix(results)
    findings = claims(m, timing)
    durations = sorted({r.metadata.get("duration_s", "?") for r in results})
    seeds = sorted({r.seed for r in results})
    lines = ["# trackmj report", "",
             f"{len(results)} runs, seeds {seeds}, {', '.join(durations)} s each, on "
             f"{machine()}. Values are mean ± std over seeds (W5: over variants × seeds). "
             "The study's figures are from " + STUDY + ", shown for comparison only: trackmj "
             "is never tuned toward them.", "",
             "Metrics are defined in the README (section Metrics) and in "
             "`trackmj/results/metrics.py`: **raw** is the 1 kHz F_ten as simulated, **low-pass** the "
             "same through a zero-phase 2nd-order Butterworth at the scenario's cut-off, both "
             "against the unfiltered reference.", ""]
    if timing is not None:
        computed = len(timing.results) - timing.resumed
        rate = computed / timing.wall_time_s * 3600.0 if timing.wall_time_s > 0 else math.nan
        lines += [f"This invocation: {computed} runs computed and {timing.resumed} resumed "
                  f"from `runs/` in {timing.wall_time_s:.0f} s wall on {timing.workers} "
                  f"worker(s) ({rate:.0f} runs/hour); 1-min load average "
                  f"{timing.load_average[0]:.1f} at the start, {timing.load_average[1]:.1f} "
                  f"at the end; {len(timing.failed)} failed.", ""]
        if timing.run_wall_s:
            lines += ["Wall time of one run in its worker (mean, s): " + ", ".join(
                f"{a} {np.mean(w):.1f} ({len(w)} runs)" for a, w in
                sorted(timing.run_wall_s.items())) + ".", ""]
        for spec, error in timing.failed:
            lines.append(f"- failed: {spec.scenario} {spec.architecture} {spec.controller} "
                         f"{spec.variant} seed {spec.seed}: {error}")
        if timing.failed:
            lines.append("")
    lines += ["## Study claims", "",
              "Verdicts: a size claim *agrees* when the study's value lies within max(2 std, "
              "25 %) of our mean; a claim \"TP is x % below\" is *supported* when every seed "
              "shows it and our mean is within max(2 std, 5 points) of the study's range, "
              "*direction only* when every seed shows the sign but not the size, "
              "*contradicted* when every seed shows the opposite, *no difference* when every "
              "seed is within ±1 %, *inconclusive* otherwise.",
              "", "| claim | study | ours | verdict | reason |", "|---|---|---|---|---|"]
    for f in findings:
        lines.append(f"| {f.claim} | {f.study} | {f.ours} | **{f.verdict}** | {f.reason} |")
    lines += ["", "What the study leaves undefined: what its \"energy consumption\" counts and "
              "over which window (so only TP vs DP-A differences, from the same hydraulic "
              "ledger, are compared, never the kJ); how its RMSE, fluctuation and settling are "
              "computed (filtering, window, band); whether the W3 pulses are reference or load "
              "changes (here: load, through the rear hitch); the geometry, masses and cylinder "
              "sizes (ours are assumptions, see models/).", ""]
    for scenario in m.scenarios:
        lines += _condition_section(m, scenario, out)
    lines += _controller_section(m, out)
    path = out / REPORT
    write_text_atomic(out / "report.json", json.dumps(jsonable(
        {"claims": [f.__dict__ for f in findings],
         "prediction_vs_tp": [{"scenario": case[0], "variant": case[1], "seed": case[2],
                               "controller": case[3], "architecture": arch, **pred}
                              for (case, arch), pred in sorted(m.predictions.items())
                              if arch != "tp"]}), indent=2, allow_nan=False) + "\n")
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


def check_report_dir(out: str | Path) -> Path:
    """``out`` if it can hold a report: absent, empty, or a previous report's directory
    (``campaign.json``, ``runs/`` or ``report.md`` in it, so an interrupted report
    resumes)."""
    return check_campaign_dir(out, ("campaign.json", RUNS, REPORT), "report")
