"""The text of report.md: the header and this invocation's timing, the claims table, one
section per condition (metric table, prediction errors against the reference architecture,
figures) and the controllers compared on the reference. Figures are drawn into the report's
directory as their sections are written."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from trackmj.host import machine
from trackmj.results.figure_compare import overlay_figure, psd_figure, variants_figure
from trackmj.results.figure_run import run_figure
from trackmj.results.metrics import METRIC_DISPLAY
from trackmj.results.seed_stats import finite
from trackmj.results.store import Result, running_of, running_text
from trackmj.results.verdict import run_verdict
from trackmj.scenarios.events import describe_moves
from trackmj.sim.registry import REFERENCE_ARCHITECTURE as REFERENCE
from trackmj.study.campaign import RUNS
from trackmj.study.report_cases import event_moves, run_name
from trackmj.study.report_claims import Finding
from trackmj.study.report_matrix import Case, Matrix, MatrixRun
from trackmj.study.report_stats import mean_std
from trackmj.study.report_verdicts import VERDICT_RULES
from trackmj.study.study_numbers import STUDY

TABLE_METRICS = ("rmse_N", "rmse_lp_N", "ripple_rms_N", "ripple_band_rms_N.tooth_passing",
                 "ripple_band_rms_N.body_mode", "peak_error_lp_N", "overshoot_lp_N",
                 "settling_time_lp_s", "disturbance_peak_error_lp_N", "recovery_time_lp_s",
                 "fluctuation_N", "fluctuation_lp_N", "constraint_violation_s",
                 "p_head_max_Pa", "valve_switch_rate_Hz", "chassis_acc_body_mode_rms_m_s2",
                 "energy_in_J", "interface_energy_residual_J", "real_time_factor")
"""Rows of each condition's table (labels and display units: :data:`METRIC_DISPLAY`)."""
CONTROLLER_METRICS = TABLE_METRICS[:13]
"""Rows of the controllers' table: the tracking metrics, up to the constraint violation."""
PREDICTION_METRICS = ("prediction_rmse_vs_tp_N", "prediction_rmse_vs_tp_lp_N",
                      "peak_pressure_error_vs_tp_Pa", "energy_error_vs_tp_pct")
"""Rows of the prediction-error tables, against the reference architecture."""

STUDY_GAPS = ("What the study leaves undefined: what its \"energy consumption\" counts and "
              "over which window (so only TP vs DP-A differences, from the same hydraulic "
              "ledger, are compared, never the kJ); how its RMSE, fluctuation and settling are "
              "computed (filtering, window, band); whether the W3 pulses are reference or load "
              "changes (here: load, through the rear hitch); the geometry, masses and cylinder "
              "sizes (ours are assumptions, see models/).")
"""The paragraph after the claims table: what the comparison with the study cannot rest on."""


def report_lines(m: Matrix, findings: Sequence[Finding], results: Sequence[Result],
                 timing: MatrixRun | None, out: Path) -> list[str]:
    """The lines of report.md for the results ``m`` (``results`` as given) and their
    ``findings``; the figures are drawn into ``out``."""
    lines = _header(results)
    if timing is not None:
        lines += _invocation(timing)
    lines += _claims_table(findings, sorted({r.metadata.get("machine", "?") for r in results}),
                           _conditions_changed(results))
    for scenario in m.scenarios:
        lines += _condition_section(m, scenario, out)
    lines += _controller_section(m, out)
    return lines


# ----------------------------------------------------------------------------- head

def _inputs(results: Sequence[Result]) -> str:
    """The crawler the runs simulated, the parameter and tensioner files that are not the
    package's own (a machine file's, or given) and the ``--set`` overrides every run shares,
    in one sentence."""
    crawlers = sorted({r.metadata.get("machine", "?") for r in results})
    said = f"Machine: {', '.join(crawlers)}"
    files: dict[str, set[str]] = {}
    for r in results:
        for kind, source in json.loads(r.metadata.get("files", "{}")).items():
            if kind not in ("machine", "scenario") and source != "packaged":
                files.setdefault(kind, set()).add(str(source))
    if files:
        said += "; files " + ", ".join(f"{kind} {' / '.join(sorted(paths))}"
                                       for kind, paths in sorted(files.items()))
    shared = [json.loads(r.metadata.get("overrides", "{}")) for r in results]
    common = {k: v for k, v in shared[0].items() if all(o.get(k) == v for o in shared)}
    if common:
        said += "; on every run " + ", ".join(f"`{k} = {v}`" for k, v in sorted(common.items()))
    return said + "."


def _header(results: Sequence[Result]) -> list[str]:
    """Title, what was run (the crawler, its files and overrides), the study cited, and
    where the metrics are defined."""
    durations = sorted({r.metadata.get("duration_s", "?") for r in results})
    seeds = sorted({r.seed for r in results})
    return ["# trackmj report", "",
            f"{_inputs(results)} {len(results)} runs, seeds {seeds}, {', '.join(durations)} "
            f"s each, on {machine()}. Values are mean ± std over seeds (W5: over variants × "
            "seeds). "
            "The study's figures are from " + STUDY + ", shown for comparison only: trackmj "
            "is never tuned toward them.", "",
            "Metrics are defined in the README (section Metrics) and in "
            "`trackmj/results/metrics.py`: **raw** is the 1 kHz F_ten as simulated, "
            "**low-pass** the same through a zero-phase 2nd-order Butterworth at the "
            "scenario's cut-off, both against the unfiltered reference.", ""]


def _invocation(timing: MatrixRun) -> list[str]:
    """This invocation: runs computed and resumed, wall time, load, each run's wall time
    (a resumed run's as stored when it ran), failures."""
    computed = len(timing.results) - timing.resumed
    rate = computed / timing.wall_time_s * 3600.0 if timing.wall_time_s > 0 else math.nan
    lines = [f"This invocation: {computed} runs computed and {timing.resumed} resumed "
             f"from `runs/` in {timing.wall_time_s:.0f} s wall on {timing.workers} "
             f"worker(s) ({rate:.0f} runs/hour); 1-min load average "
             f"{timing.load_average[0]:.1f} at the start, {timing.load_average[1]:.1f} "
             f"at the end; {len(timing.failed)} failed.", ""]
    if timing.run_wall_s:
        lines += [f"Wall time of one run in its worker (mean, s): {_walls(timing.run_wall_s)}.",
                  ""]
    if timing.resumed_wall_s:
        lines += ["Wall time of one resumed run in its worker, as stored when it ran (mean, "
                  f"s): {_walls(timing.resumed_wall_s)}.", ""]
    for spec, error in timing.failed:
        lines.append(f"- failed: {spec.scenario} {spec.architecture} {spec.controller} "
                     f"{spec.variant} seed {spec.seed}: {error}")
    if timing.failed:
        lines.append("")
    return lines


def _walls(by_arch: dict[str, list[float]]) -> str:
    """Runs' wall times by architecture [s] as "tp 1.2 (3 runs), dp-a ..."."""
    return ", ".join(f"{a} {np.mean(w):.1f} ({len(w)} run{'s' * (len(w) != 1)})"
                     for a, w in sorted(by_arch.items()))


STUDY_MACHINE = "lf1352"
"""The crawler the study's figures are of (its only machine)."""


EVENT_TIMES = ("time_s", "start_s", "end_s", "rise_s", "transition_s")
"""Scenario keys that place an event in time (a shorter report moves them)."""


def _conditions_changed(results: Sequence[Result]) -> list[str]:
    """What the runs changed of the study's conditions (a scenario override other than an
    event's time, which the condition's intro explains; a reversed track or a grade), in
    words; [] for runs of the conditions as the study states them."""
    changed = sorted({k for r in results for k in json.loads(r.metadata.get("overrides", "{}"))
                      if k.startswith("scenario.") and k.rsplit(".", 1)[-1] not in EVENT_TIMES})
    how = sorted({text.lstrip(", ") for r in results
                  if (text := running_text(running_of(r)))})
    return [f"`{k}`" for k in changed] + how


def _claims_table(findings: Sequence[Finding], crawlers: Sequence[str],
                  changed: Sequence[str] = ()) -> list[str]:
    """The study's claims: the verdict rules (and, for another crawler than the study's or
    conditions the runs changed, what its verdicts then mean), one row per finding, what
    the study leaves undefined."""
    others = [c for c in crawlers if c != STUDY_MACHINE]
    caveat = ([f"The study's figures are of the LF1352; these runs are of {', '.join(others)}: "
               "a verdict here says how another crawler compares with them, not whether "
               "trackmj reproduces the study.", ""] if others else [])
    if changed:
        caveat += [f"These runs change the study's conditions ({', '.join(changed)}): a "
                   "verdict here compares those conditions with the study's figures, not "
                   "whether trackmj reproduces the study.", ""]
    lines = ["## Study claims", "", *caveat, VERDICT_RULES,
             "", "| claim | study | ours | verdict | reason |", "|---|---|---|---|---|"]
    for f in findings:
        lines.append(f"| {f.claim} | {f.study} | {f.ours} | **{f.verdict}** | {f.reason} |")
    return [*lines, "", STUDY_GAPS, ""]


# ----------------------------------------------------------------------------- conditions

def _condition_section(m: Matrix, scenario: str, out: Path) -> list[str]:
    """One condition: the acceptance verdict on the reference architecture's runs, its
    metrics per architecture, the prediction errors against the reference, and its figures
    (W5: over every variant)."""
    archs = m.architectures(scenario)
    variant = None if scenario == "W5" else "nominal"
    runs = [r for (case, a), r in m.runs.items() if case[0] == scenario]
    seeds = sorted({r.seed for r in runs})
    lines = _condition_intro(m, scenario, runs, seeds, variant)
    lines += acceptance_lines(m, scenario)
    lines += _metric_table(m, scenario, archs, variant)
    reduced = [a for a in archs if a != REFERENCE]
    if reduced and REFERENCE in archs:
        lines += _prediction_table(m, scenario, reduced, variant)
    case = m.first_case(scenario)
    if case is not None:
        lines += _condition_figures(m, scenario, case, archs, seeds, out)
    return lines


def _condition_intro(m: Matrix, scenario: str, runs: Sequence[Result], seeds: Sequence[int],
                     variant: str | None) -> list[str]:
    """Title, controller and seeds, and where shorter runs moved the scenario's events."""
    sc = m.scenario(scenario)
    scope = "all variants × seeds" if variant is None else "seeds"
    lines = [f"## {scenario}: {sc.title}", "",
             f"{sc.controller} controller; mean ± std over {scope} {seeds}.", ""]
    durations = {float(r.metadata.get("duration_s", sc.duration_s)) for r in runs}
    for duration in sorted(durations):
        moves = event_moves(m.source(scenario), duration)
        if moves:
            lines += [f"The {duration:g} s runs would cut off events of the {sc.duration_s:g} s "
                      f"scenario, so its schedule after the evaluation start "
                      f"({sc.evaluation.start_s:g} s) is compressed linearly into the run "
                      f"(README, Usage, Durations): {describe_moves(sc, moves)}.", ""]
    return lines


def acceptance_lines(m: Matrix, scenario: str) -> list[str]:
    """The scenario's acceptance on each :data:`REFERENCE` run
    (:func:`trackmj.results.verdict.run_verdict`): how many hold, and each one that fails
    with why."""
    judged = [(case, run_verdict(r.metrics)) for (case, a), r in sorted(m.runs.items())
              if case[0] == scenario and a == REFERENCE]
    judged = [(case, v) for case, v in judged if v is not None]
    if not judged:
        return []
    controllers = sorted({case[3] for case, _ in judged})
    counts = ", ".join(f"{sum(v.holds for c, v in judged if c[3] == k)} of "
                       f"{sum(c[3] == k for c, _ in judged)} {k} runs" for k in controllers)
    lines = [f"Acceptance on {REFERENCE} (the scenario's rules, README Metrics): holds in "
             f"{counts}.", ""]
    failed = [f"- seed {seed}" + ("" if variant == "nominal" else f", {variant}")
              + f" ({controller}): {v.text()}"
              for (_, variant, seed, controller), v in judged if not v.holds]
    return [*lines, *failed, ""] if failed else lines


def _metric_table(m: Matrix, scenario: str, archs: Sequence[str],
                  variant: str | None) -> list[str]:
    """Rows of :data:`TABLE_METRICS` with a value, one column per architecture."""
    lines = ["| metric | " + " | ".join(archs) + " |", "|---|" + "---|" * len(archs)]
    for key in TABLE_METRICS:
        label, scale, unit = METRIC_DISPLAY[key]
        cells = [mean_std(m.values(scenario, a, key, variant=variant).values(), scale)
                 for a in archs]
        if all(c.startswith("–") for c in cells):
            continue
        lines.append(f"| {label} [{unit}] | " + " | ".join(cells) + " |")
    return lines


def _prediction_table(m: Matrix, scenario: str, reduced: Sequence[str],
                      variant: str | None) -> list[str]:
    """Each architecture's prediction error against the reference, and the energy term
    each was compared on."""
    lines = ["", f"Prediction error against {REFERENCE} (same seed and variant):", "",
             "| metric | " + " | ".join(reduced) + " |", "|---|" + "---|" * len(reduced)]
    for key in PREDICTION_METRICS:
        label, scale, unit = METRIC_DISPLAY[key]
        cells = [mean_std(m.prediction(scenario, a, key, variant=variant).values(), scale)
                 for a in reduced]
        lines.append(f"| {label} [{unit}] | " + " | ".join(cells) + " |")
    terms = {a: sorted({p["energy_error_term"] or "none" for (case, b), p in
                        m.predictions.items() if case[0] == scenario and b == a})
             for a in reduced}
    used = "; ".join(f"{a}: {', '.join(t)}" for a, t in terms.items())
    return [*lines, "", f"Energy compared on the term: {used}.", ""]


def _condition_figures(m: Matrix, scenario: str, case: Case, archs: Sequence[str],
                       seeds: Sequence[int], out: Path) -> list[str]:
    """The architectures overlaid on ``case`` (W2: their spectra too), the metrics per
    variant where the scenario has several, and the reference run in detail."""
    first = [m.runs[(case, a)] for a in archs if (case, a) in m.runs]
    predictions = {a: m.predictions[(case, a)] for a in archs if (case, a) in m.predictions}
    fig = overlay_figure(first, out / f"{scenario}.png", predictions=predictions,
                         title=f"{scenario} seed {case[2]}, nominal: architectures")
    lines = [f"![{scenario} architectures, seed {case[2]}]({fig.name})", ""]
    if scenario == "W2":
        psd = psd_figure(first, out / f"{scenario}-psd.png")
        lines += [f"![{scenario} spectra, seed {case[2]}]({psd.name})", ""]
    names = [v.name for v in m.scenario(scenario).variants]
    if len(names) > 1:
        lines += _variants_figure(m, scenario, names, archs, seeds, out)
    ref = m.runs.get((case, REFERENCE))
    if ref is not None:
        run_dir = out / RUNS / run_name(scenario, REFERENCE, case[3], case[1], case[2])
        run_figure(ref, run_dir / "timeseries.png")
        lines += [f"{REFERENCE} run in detail: [{run_dir.name}]({RUNS}/{run_dir.name}/"
                  "timeseries.png).", ""]
    return lines


def _variants_figure(m: Matrix, scenario: str, names: Sequence[str], archs: Sequence[str],
                     seeds: Sequence[int], out: Path) -> list[str]:
    """The low-passed RMSE and the raw fluctuation per variant, mean over seeds."""

    def per_variant(key: str, scale: float) -> dict[str, list[float]]:
        return {a: [float(np.mean(finite(m.values(scenario, a, key, variant=v).values())
                                  or [math.nan])) * scale
                    for v in names] for a in archs}

    fig = variants_figure(names, {
        "tension RMSE, low-pass [kN]": per_variant("rmse_lp_N", 1e-3),
        "fluctuation ±, raw [kN]": per_variant("fluctuation_N", 1e-3)},
        out / f"{scenario}-variants.png",
        title=f"{scenario}: per variant, mean over seeds {seeds}")
    return [f"![{scenario} per variant]({fig.name})", ""]


# ----------------------------------------------------------------------------- controllers

def _controller_section(m: Matrix, out: Path) -> list[str]:
    """Per scenario with several controllers on the reference: their metrics and their
    runs overlaid (seed of the first case)."""
    lines: list[str] = []
    for scenario in m.scenarios:
        case = m.first_case(scenario)
        if case is None:
            continue
        ctrls = sorted({c[3] for c, a in m.runs if c[0] == scenario and a == REFERENCE})
        if len(ctrls) < 2:
            continue
        runs = [m.runs[((case[0], case[1], case[2], c), REFERENCE)] for c in ctrls
                if ((case[0], case[1], case[2], c), REFERENCE) in m.runs]
        if not lines:
            lines = [f"## Controllers on {REFERENCE}", ""]
        lines += [f"### {scenario}", "", "| metric | " + " | ".join(ctrls) + " |",
                  "|---|" + "---|" * len(ctrls)]
        for key in CONTROLLER_METRICS:
            label, scale, unit = METRIC_DISPLAY[key]
            cells = [mean_std(m.values(scenario, REFERENCE, key, controller=c).values(), scale)
                     for c in ctrls]
            if not all(c.startswith("–") for c in cells):
                lines.append(f"| {label} [{unit}] | " + " | ".join(cells) + " |")
        fig = overlay_figure(runs, out / f"{scenario}-controllers.png", label_by="controller",
                             title=f"{scenario} seed {case[2]}: controllers on {REFERENCE}")
        lines += ["", f"![{scenario} controllers]({fig.name})", ""]
    return lines

