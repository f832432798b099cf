"""``trackmj compare``: every architecture (and controller) on one case, a campaign of kind
``compare`` (:mod:`trackmj.study.campaign`): each run in ``OUT/<arch>-<controller>/``, the
prediction error of each reduced architecture against tp, ``compare.json``, ``compare.md``
and the figures."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from trackmj.host import machine
from trackmj.io import write_text_atomic
from trackmj.results.comparison import prediction_vs_tp
from trackmj.results.figure_compare import overlay_figure, psd_figure
from trackmj.results.figure_run import run_figure
from trackmj.results.metric_windows import windows_of
from trackmj.results.metrics import METRIC_DISPLAY, lookup
from trackmj.results.store import Result, running_of, running_text
from trackmj.results.store import _json_ready as jsonable  # the one JSON form of metrics
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.study.campaign import Store, check_campaign_dir, plan_run, run_campaign
from trackmj.study.executor import RunSpec
from trackmj.study.identity import inputs_key
from trackmj.study.report_cases import tensioner_for
from trackmj.study.report_markdown import PREDICTION_METRICS
from trackmj.study.report_stats import mean_std

COMPARE = "compare.json"
SCALAR_SKIP = ("psd", "evaluation")
"""Tables of metrics.json left out of compare.json (each run's own metrics.json has them)."""


@dataclass
class CompareRun:
    """What :func:`compare` did: the results, the failed runs (spec, error) and each
    reduced architecture's prediction error against tp, by controller then architecture."""

    results: list[Result]
    failed: list[tuple[RunSpec, str]]
    predictions: dict[str, dict[str, dict[str, Any]]]


def check_compare_dir(out: str | Path) -> Path:
    """``out`` if it can hold a comparison: absent, empty or a previous comparison."""
    return check_campaign_dir(out, ("campaign.json", COMPARE), "comparison")


def comparison_key(setups: Sequence[Any]) -> str:
    """Hash (20 hex digits) of a comparison's inputs: the inputs of each controller's run
    (:func:`trackmj.study.identity.inputs_key` of its prepared setup), in order (every
    architecture runs them)."""
    keys = [inputs_key(s) for s in setups]
    return hashlib.sha256(json.dumps(keys).encode()).hexdigest()[:20]


def compare(base: Mapping[str, Any], controllers: Sequence[str], out_dir: str | Path, *,
            seed: int, workers: int | None = None, scheduler: str | None = None,
            key: str | None = None, overwrite: bool = False) -> CompareRun:
    """Every architecture with each controller on one case (``base``: the RunSpec fields but
    architecture, controller and seed), a campaign of kind ``compare``
    (:mod:`trackmj.study.campaign`): each run is written to ``OUT/<arch>-<controller>/`` (the run
    contract plus its figure) as it finishes; a run already done there is read back.
    ``key``: the comparison's :func:`comparison_key`; a directory holding a comparison of
    other inputs is refused (ResultDirectoryError) unless ``overwrite``, which replaces it."""
    fields = {k: v for k, v in base.items() if k != "tensioner"}
    specs = [RunSpec(**fields, architecture=a, controller=c, seed=seed,
                     tensioner=tensioner_for(a, base.get("tensioner")))
             for c in controllers for a in ARCHITECTURES]
    runs = [plan_run(s, name=f"{s.architecture}-{s.controller}") for s in specs]
    with Store(out_dir, "compare", markers=(COMPARE,), what="comparison", runs=".",
               inputs_key=key, overwrite=overwrite) as store:
        made = run_campaign(store, runs, workers=workers, scheduler=scheduler,
                            progress=f"compare {base['scenario']}", need_results=True,
                            extras=lambda r: {"timeseries.png": lambda path: run_figure(r, path)})
    results = [made.results[r.key] for r in runs if r.key in made.results]
    failed = [(o.spec, o.error or "failed") for o in made.failed]
    predictions: dict[str, dict[str, dict[str, Any]]] = {}
    for c in controllers:
        tp = next((r for r in results if r.controller == c
                   and r.architecture == REFERENCE_ARCHITECTURE), None)
        if tp is None:
            continue
        predictions[c] = {r.architecture: prediction_vs_tp(r.columns(), r.metrics, tp.columns(),
                                                           tp.metrics, windows_of(r))
                          for r in results if r.controller == c}
    return CompareRun(results, failed, predictions)


def write_compare(run: CompareRun, out_dir: str | Path, scenario: Any,
                  duration_s: float) -> Path:
    """compare.json (every run's scalar metrics, energy and ripple tables; the prediction
    errors against tp; the windows), compare.md, and the figures: per controller the
    architectures overlaid (``compare-<controller>.png``) and their spectra
    (``psd-<controller>.png``); with several controllers, per architecture the controllers
    overlaid (``controllers-<arch>.png``)."""
    out = Path(out_dir)
    if not run.results:
        raise ValueError("no run of the comparison finished")
    controllers = list(dict.fromkeys(r.controller for r in run.results))
    archs = list(dict.fromkeys(r.architecture for r in run.results))
    figures = []
    for c in controllers:
        mine = [r for r in run.results if r.controller == c]
        figures.append(overlay_figure(mine, out / f"compare-{c}.png",
                                      predictions=run.predictions.get(c),
                                      title=f"{scenario.name} seed {mine[0].seed}, {c}: "
                                            "architectures"))
        figures.append(psd_figure(mine, out / f"psd-{c}.png"))
    if len(controllers) > 1:
        for a in archs:
            mine = [r for r in run.results if r.architecture == a]
            figures.append(overlay_figure(mine, out / f"controllers-{a}.png",
                                          label_by="controller",
                                          title=f"{scenario.name} seed {mine[0].seed}, {a}: "
                                                "controllers"))
    running = running_of(run.results[0])
    doc = {"scenario": scenario.name, "title": scenario.title, "seed": run.results[0].seed,
           "duration_s": duration_s, "running": running, "host": machine(),
           "evaluation": run.results[0].metrics.get("evaluation"),
           "runs": {f"{r.architecture}-{r.controller}": {
               "architecture": r.architecture, "controller": r.controller,
               "estimator": r.estimator, "directory": f"{r.architecture}-{r.controller}",
               "metrics": {k: v for k, v in r.metrics.items() if k not in SCALAR_SKIP}}
               for r in run.results},
           "prediction_vs_tp": run.predictions,
           "failed": [{"architecture": s.architecture, "controller": s.controller,
                       "error": e} for s, e in run.failed],
           "figures": [f.name for f in figures]}
    write_text_atomic(out / COMPARE, json.dumps(jsonable(doc), indent=2, allow_nan=False)
                      + "\n")
    lines = [f"# {scenario.name}: {scenario.title}", "",
             f"seed {doc['seed']}, duration {duration_s:g} s{running_text(running)}, "
             f"{machine()}", ""]
    for c, preds in run.predictions.items():
        reduced = [a for a in preds if a != REFERENCE_ARCHITECTURE]
        lines += [f"Prediction error against {REFERENCE_ARCHITECTURE} ({c}, same seed):", "",
                  "| metric | " + " | ".join(reduced) + " |", "|---|" + "---|" * len(reduced)]
        for key in PREDICTION_METRICS:
            label, scale, unit = METRIC_DISPLAY[key]
            lines.append(f"| {label} [{unit}] | " + " | ".join(
                mean_std([lookup(preds[a], key)], scale) for a in reduced) + " |")
        lines += ["| energy term compared | " + " | ".join(
            str(preds[a]["energy_error_term"] or "none") for a in reduced) + " |", ""]
    lines += [f"![{f.stem}]({f.name})" for f in figures]
    write_text_atomic(out / "compare.md", "\n".join(lines) + "\n")
    return out / COMPARE
