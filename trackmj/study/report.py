"""``trackmj report``: W1-W5 × architectures × seeds (W5 × its variants) -> report.md.

The report answers the study's claims one by one (Ding et al., "Simulation Method for
Hydraulic Tensioning Systems in Tracked Vehicles Using Simulink-AMESim-RecurDyn",
Actuators 2025, 14(12), 615): each claim with the study's figure, ours (mean ± std over
seeds, the same metric definition where the study gives one) and a verdict with its reason
(:mod:`trackmj.study.report_claims`). The study's figures are printed for comparison only
(:mod:`trackmj.study.study_numbers`); nothing in trackmj is tuned toward them.

Runs: every scenario's variants × seeds × architectures (``tp``, ``dp-a``, ``dp-b`` by
default, the study's three) with the scenario's controller, plus the baseline controllers
(those registered with ``baseline=True``, :func:`trackmj.sim.controllers.baselines`) on the
reference architecture in W1 for the controller claims. They run on the shared executor as
a campaign (:mod:`trackmj.study.campaign`); each run is written to
``OUT/runs/<scenario>-<arch>-<controller>-<variant>-s<seed>/`` and its row to
``OUT/results.parquet`` as it finishes, and a run already done there (the same identity:
inputs and code) is read back instead of run again, so an interrupted report resumes. A
``--duration`` shorter than a scenario's events moves them inside the run
(:func:`trackmj.study.report_cases.event_moves`); the report says where to. A dp-a run needs
its tp run's track load: when only the dp-a run is missing, the executor runs the tp case
again for it (deterministic per seed, so the same load).

This module is the command's three steps: :func:`plan` the runs, :func:`run_matrix` them,
:func:`write_report`.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from trackmj.io import write_text_atomic
from trackmj.results.store import Result
from trackmj.results.store import _json_ready as jsonable  # the one JSON form of metrics
from trackmj.scenarios.load import load_scenario
from trackmj.sim.controllers import baselines as registered_baselines
from trackmj.sim.registry import REFERENCE_ARCHITECTURE
from trackmj.sim.setup import prepare
from trackmj.study.campaign import (
    RUNS,
    PlannedRun,
    Store,
    check_campaign_dir,
    plan_run,
    run_campaign,
)
from trackmj.study.executor import RunOutcome, RunSpec, overrides_tuple
from trackmj.study.report_cases import event_moves, run_name, tensioner_for
from trackmj.study.report_claims import Finding, claims
from trackmj.study.report_markdown import report_lines
from trackmj.study.report_matrix import Matrix, MatrixRun
from trackmj.study.study_numbers import STUDY_REDUCED
from trackmj.validator import ParameterError

REPORT_ARCHS = (REFERENCE_ARCHITECTURE, *STUDY_REDUCED)
"""Architectures of a report by default: the reference and the study's two reduced ones,
the study's three (tp-weak with ``--archs``)."""
BASELINE_SCENARIOS = ("W1",)
"""Conditions the baselines run in: tracking (W1); more would push the full report past its
15 min budget on two cores (10 runs of ~12 s CPU each per condition at 5 seeds)."""
REPORT = "report.md"


# ----------------------------------------------------------------------------- plan

def plan(scenarios: Sequence[str], seeds: Sequence[int], duration: float | None,
         archs: Sequence[str] = REPORT_ARCHS,
         baselines: Sequence[str] | None = None, tensioner: str | None = None,
         machine: str | None = None, files: Mapping[str, str | None] | None = None,
         overrides: tuple[tuple[str, Any], ...] = ()) -> list[PlannedRun]:
    """Every run of a report: each scenario's variants × seeds × ``archs`` with its own
    controller, then ``baselines`` (default: the controllers registered as baselines,
    :func:`trackmj.sim.controllers.baselines`) on the reference architecture in the nominal
    :data:`BASELINE_SCENARIOS`; ``tensioner`` (a tensioner file) replaces the hydraulic
    element where an architecture has one (:func:`~trackmj.study.report_cases.tensioner_for`);
    ``machine`` (a shipped name or a machine file) is every run's, and so are ``files``
    (``model``, ``hydraulics``, ``control``: a parameter file replacing the machine's, None
    for its own) and ``overrides`` (``--set`` items in :attr:`RunSpec.overrides` form). A
    ``duration`` that would cut off a scenario's step, pulse or drop moves its events inside
    the run (:func:`~trackmj.study.report_cases.event_moves`; an override of the same key
    wins). Each run is validated here (ParameterError before anything runs) and known by its
    identity (:func:`trackmj.study.identity.run_key`)."""
    if baselines is None:
        baselines = registered_baselines()
    common = {"tensioner": tensioner, "machine": machine, **(files or {})}
    specs = []
    for name in scenarios:
        specs += _scenario_specs(name, seeds, duration, archs, baselines, common, overrides)
    return _planned(specs)


def _scenario_specs(name: str, seeds: Sequence[int], duration: float | None,
                    archs: Sequence[str], baselines: Sequence[str], common: Mapping[str, Any],
                    overrides: tuple[tuple[str, Any], ...]) -> list[RunSpec]:
    """The runs of one scenario: variants × seeds × ``archs`` with its controller, then
    the ``baselines`` on the reference if it is one of :data:`BASELINE_SCENARIOS`;
    ``common`` the RunSpec fields every run shares (its tensioner file given for the
    architectures that have a hydraulic element)."""
    sc = load_scenario(name)
    moves = {f"scenario.{k}": v for k, v in event_moves(name, duration).items()}
    given = overrides_tuple(moves | dict(overrides))
    tensioner = common["tensioner"]
    specs = [RunSpec(scenario=name, architecture=arch, controller=sc.controller,
                     seed=seed, duration=duration, variant=variant.name, overrides=given,
                     **{**common, "tensioner": tensioner_for(arch, tensioner)})
             for variant in sc.variants for seed in seeds for arch in archs]
    if sc.name in BASELINE_SCENARIOS:
        specs += [RunSpec(scenario=name, architecture=REFERENCE_ARCHITECTURE, controller=c,
                          seed=seed, duration=duration, overrides=given, **common)
                  for c in baselines if c != sc.controller for seed in seeds]
    return specs


def _planned(specs: Sequence[RunSpec]) -> list[PlannedRun]:
    """The specs validated (once per case, not once per seed) and named under ``OUT/runs``."""
    setups: dict[RunSpec, Any] = {}
    runs = []
    for spec in specs:
        unseeded = replace(spec, seed=0)
        if unseeded not in setups:
            try:
                setups[unseeded] = prepare(**unseeded.prepare_kwargs())
            except ParameterError as exc:   # a report's overrides meet several scenarios
                raise ParameterError(f"{spec.scenario}: {exc}") from None
        setup = replace(setups[unseeded], seed=spec.seed)
        runs.append(plan_run(spec, setup=setup, name=run_name(
            setup.scenario.name, setup.architecture, setup.controller, setup.variant.name,
            setup.seed)))
    return runs


# ----------------------------------------------------------------------------- run

def run_matrix(runs: Sequence[PlannedRun], out_dir: str | Path, *, workers: int | None = None,
               scheduler: str | None = None, progress: bool = True,
               executor: Any = None) -> MatrixRun:
    """Make the runs of a report in ``out_dir`` (a campaign of kind ``report``,
    :mod:`trackmj.study.campaign`): each run is written to ``OUT/runs/<name>/`` and its row to
    ``OUT/results.parquet`` as it finishes; a run already done there (same identity) is
    read back instead, its wall time from its row. A failed run is reported and left out."""
    start = time.perf_counter()
    load_start = os.getloadavg()[0]
    run_wall: dict[str, list[float]] = defaultdict(list)
    computed: set[str] = set()

    def on_outcome(run: PlannedRun, outcome: RunOutcome) -> None:
        computed.add(run.key)
        run_wall[outcome.spec.architecture].append(outcome.wall_time_s)
        if not outcome.ok:
            print(f"trackmj: {run.name}: {outcome.error}", file=sys.stderr)

    unique = list({r.key: r for r in runs}.values())
    stored_wall: dict[str, list[float]] = defaultdict(list)
    with Store(out_dir, "report", markers=(RUNS, REPORT)) as store:
        made = run_campaign(store, runs, executor=executor, workers=workers,
                            scheduler=scheduler, progress="report" if progress else None,
                            need_results=True, on_outcome=on_outcome)
        for r in unique:   # a resumed run's own wall time, from its row
            wall = store.rows.get(r.key, {}).get("wall_time_s")
            if r.key in made.results and r.key not in computed and wall is not None:
                stored_wall[r.spec.architecture].append(float(wall))
    results = [made.results[r.key] for r in unique if r.key in made.results]
    return MatrixRun(results, [(o.spec, o.error or "failed") for o in made.failed],
                     made.resumed, time.perf_counter() - start,
                     workers or (None if scheduler else os.cpu_count()),
                     (load_start, os.getloadavg()[0]), dict(run_wall), dict(stored_wall))


def check_report_dir(out: str | Path) -> Path:
    """``out`` if it can hold a report: absent, empty, or a previous report's directory
    (``campaign.json``, ``runs/`` or ``report.md`` in it, so an interrupted report
    resumes)."""
    return check_campaign_dir(out, ("campaign.json", RUNS, REPORT), "report")


# ----------------------------------------------------------------------------- write

def write_report(results: Sequence[Result], out_dir: str | Path,
                 timing: MatrixRun | None = None) -> Path:
    """report.md (claims, condition tables, prediction errors, figures) and report.json (the
    claims and the prediction errors) in ``out_dir``; the runs are under ``out_dir/runs``."""
    out = Path(out_dir)
    if not results:
        raise ValueError("no finished run to report on")
    m = Matrix(results)
    findings = claims(m, timing)
    lines = report_lines(m, findings, results, timing, out)
    path = out / REPORT
    write_text_atomic(out / "report.json", json.dumps(jsonable(_report_json(m, findings)),
                                                      indent=2, allow_nan=False) + "\n")
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


def _report_json(m: Matrix, findings: Sequence[Finding]) -> dict[str, Any]:
    """report.json: the claims, and each case's prediction errors of every architecture
    besides the reference, sorted by case."""
    return {"claims": [f.__dict__ for f in findings],
            "prediction_vs_tp": [{"scenario": case[0], "variant": case[1], "seed": case[2],
                                  "controller": case[3], "architecture": arch, **pred}
                                 for (case, arch), pred in sorted(m.predictions.items())
                                 if arch != REFERENCE_ARCHITECTURE]}
