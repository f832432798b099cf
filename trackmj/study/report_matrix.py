"""The results a report is written from: what running its runs did (:class:`MatrixRun`) and
the results indexed by case and architecture (:class:`Matrix`), with each architecture's
prediction error against the reference architecture of its case."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from trackmj.results.comparison import prediction_vs_tp
from trackmj.results.metric_windows import windows_of
from trackmj.results.metrics import lookup
from trackmj.results.store import Result
from trackmj.scenarios.load import load_scenario
from trackmj.scenarios.resolved import Scenario
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.study.executor import RunSpec


@dataclass
class MatrixRun:
    """What :func:`trackmj.study.report.run_matrix` did: the results (resumed and new), the
    runs that failed (spec, error), how many were resumed, the wall time [s], the workers,
    the 1-min load average at the start and the end, each computed run's own wall time in
    its worker by architecture [s], and each resumed run's, as its row in results.parquet
    stored it when it ran [s]."""

    results: list[Result]
    failed: list[tuple[RunSpec, str]] = field(default_factory=list)
    resumed: int = 0
    wall_time_s: float = 0.0
    workers: int | None = None
    load_average: tuple[float, float] = (math.nan, math.nan)
    run_wall_s: dict[str, list[float]] = field(default_factory=dict)
    resumed_wall_s: dict[str, list[float]] = field(default_factory=dict)


def _variant(r: Result) -> str:
    """The run's scenario variant ("nominal" when its metadata names none)."""
    return r.metadata.get("variant", "nominal")


Case = tuple[str, str, int, str]
"""(scenario, variant, seed, controller): runs of one case differ only in architecture."""


class Matrix:
    """The report's results indexed by case and architecture, with each architecture's
    prediction error against the :data:`~trackmj.sim.registry.REFERENCE_ARCHITECTURE` run of
    its case."""

    def __init__(self, results: Iterable[Result]) -> None:
        self.runs: dict[tuple[Case, str], Result] = {}
        for r in results:
            self.runs[((r.scenario, _variant(r), r.seed, r.controller), r.architecture)] = r
        self.predictions: dict[tuple[Case, str], dict[str, Any]] = {}
        for (case, arch), r in self.runs.items():
            ref = self.runs.get((case, REFERENCE_ARCHITECTURE))
            if ref is not None:
                self.predictions[(case, arch)] = prediction_vs_tp(
                    r.columns(), r.metrics, ref.columns(), ref.metrics, windows_of(r))

    @property
    def scenarios(self) -> list[str]:
        """The scenarios with a run, sorted."""
        return sorted({case[0] for case, _ in self.runs})

    def architectures(self, scenario: str) -> list[str]:
        """The architectures with a run in ``scenario``, in the registry's order."""
        found = {a for (case, a) in self.runs if case[0] == scenario}
        return [a for a in ARCHITECTURES if a in found]

    def source(self, scenario: str) -> str:
        """The file the runs named ``scenario`` read (each run records it): a scenario file
        given by its path runs under the name inside it; the name itself if no run says."""
        for (case, _), result in self.runs.items():
            if case[0] == scenario:
                given = json.loads(result.metadata.get("files") or "{}").get("scenario")
                if given:
                    return str(given)
        return scenario

    def scenario(self, scenario: str) -> Scenario:
        """The scenario the runs named ``scenario`` ran (:meth:`source`)."""
        return load_scenario(self.source(scenario))

    def controller(self, scenario: str) -> str:
        """The scenario's own controller (the one its architectures ran with)."""
        return self.scenario(scenario).controller

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
        """(variant, seed) -> prediction error ``key`` of ``arch`` against the reference."""
        ctrl = self.controller(scenario)
        return {(case[1], case[2]): lookup(p, key) for (case, a), p in self.predictions.items()
                if case[0] == scenario and a == arch and case[3] == ctrl
                and (variant is None or case[1] == variant)}

    def first_case(self, scenario: str) -> Case | None:
        """The first nominal case of ``scenario`` with its own controller (lowest seed)."""
        cases = sorted(case for case, a in self.runs if case[0] == scenario and case[1] ==
                       "nominal" and case[3] == self.controller(scenario))
        return cases[0] if cases else None
