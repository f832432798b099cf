"""Runs many simulations in parallel on Dask distributed: ``compare``, ``report`` and
``sweep`` share this one executor.

By default a :class:`distributed.LocalCluster` with one single-threaded worker process per
core (BLAS/OpenMP/numba threads pinned to 1 in each, warmed by :mod:`trackmj.study.worker`), or
``workers`` of them; with ``scheduler`` an existing cluster (started with ``dask scheduler``
and, on each machine, ``dask worker tcp://HOST:8786 --nworkers N --nthreads 1 --preload
trackmj.study.worker``; the workers need trackmj installed and the parameter files at the same
paths). A dp-a run
replays the track load of the tp run of the same case, so its tp run is computed first
(once, shared by every dp-a run that needs it, and reported itself if it was asked for). A
failed run becomes an outcome with its error, never a lost batch.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from trackmj.results.store import Result
from trackmj.scenarios.load import load_scenario
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.sim.run import simulate
from trackmj.sim.setup import overrides_by_kind
from trackmj.validator import ParameterError


@dataclass(frozen=True)
class RunSpec:
    """One :func:`trackmj.sim.run.simulate` call, picklable and hashable.

    scenario: a built-in name or a scenario file path; overrides: ``(("KIND.TABLE.KEY",
    value), ...)`` as for ``simulate(set=...)``; the other fields as in ``simulate``.
    """

    scenario: str
    architecture: str = REFERENCE_ARCHITECTURE
    controller: str | None = None
    estimator: str | None = None
    seed: int = 0
    duration: float | None = None
    variant: str = "nominal"
    overrides: tuple[tuple[str, Any], ...] = ()
    model: str | None = None
    hydraulics: str | None = None
    control: str | None = None
    tensioner: str | None = None
    machine: str | None = None

    def as_tp(self) -> RunSpec:
        """The same case in the reference architecture (what a dp-a run replays)."""
        return replace(self, architecture=REFERENCE_ARCHITECTURE)

    def prepare_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`trackmj.sim.setup.prepare` for this run."""
        kwargs = self.simulate_kwargs()
        kwargs["overrides"] = kwargs.pop("set")
        return kwargs

    def simulate_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``simulate`` for this run."""
        return dict(scenario=self.scenario, architecture=self.architecture,
                    controller=self.controller, estimator=self.estimator, seed=self.seed,
                    duration=self.duration, variant=self.variant, set=dict(self.overrides),
                    model=self.model, hydraulics=self.hydraulics, control=self.control,
                    tensioner=self.tensioner, machine=self.machine)


@dataclass
class RunOutcome:
    """A finished run: its ``result``, or ``error`` (``"Type: message"``) if it failed;
    ``wall_time_s`` is the run's own wall time in its worker [s]."""

    spec: RunSpec
    result: Result | None = None
    error: str | None = None
    wall_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None


def execute(spec: RunSpec, tp: RunOutcome | None = None) -> RunOutcome:
    """Run ``spec`` here (in a worker); ``tp`` is the outcome of its tp run for dp-a.
    Exceptions become the outcome's error, so one run cannot lose the batch."""
    start = time.perf_counter()
    try:
        if tp is not None and not tp.ok:
            raise RuntimeError(f"its tp run failed: {tp.error}")
        result = simulate(**spec.simulate_kwargs(),
                          tp_result=None if tp is None else tp.result)
    except Exception as exc:
        return RunOutcome(spec, error=f"{type(exc).__name__}: {exc}",
                          wall_time_s=time.perf_counter() - start)
    return RunOutcome(spec, result=result, wall_time_s=time.perf_counter() - start)


@dataclass
class Executor:
    """``with Executor(workers=2) as ex: outcomes = ex.map(specs)``.

    workers: worker processes of the local cluster (default: one per core); scheduler:
    address of an existing Dask scheduler (``tcp://HOST:8786``) instead of a local cluster.

    The local cluster's workers are forked from one forkserver that imported
    :mod:`trackmj.study.worker` first (threads pinned, run code imported, model, idler and
    hydraulic kernels loaded), so each worker starts warm and the start-up is paid once per
    process, not once per worker. Like every multiprocessing pool, a script that starts one
    must guard its entry point with ``if __name__ == "__main__":``.
    """

    workers: int | None = None
    scheduler: str | None = None
    client: Any = field(default=None, init=False)
    _cluster: Any = field(default=None, init=False)

    def __enter__(self) -> Executor:
        from distributed import Client, LocalCluster  # heavy: loaded when a cluster starts

        if self.scheduler is not None:
            self.client = Client(self.scheduler, timeout="20s")
            return self
        n = os.cpu_count() or 1 if self.workers is None else self.workers
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"workers = {self.workers!r}: need an integer >= 1")
        _configure_local_workers()
        self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                     # None: no dashboard (documented; unannotated, its
                                     # default ":8787" makes the checker infer str)
                                     dashboard_address=None,  # pyright: ignore[reportArgumentType]
                                     silence_logs=50,
                                     scheduler_kwargs={"dashboard_address": ":0"})
        self.client = Client(self._cluster)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.client is not None:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
        self.client = self._cluster = None

    def as_completed(self, specs: Iterable[RunSpec], *,
                     progress: str | None = None) -> Iterator[RunOutcome]:
        """Run every spec; yields each asked-for run's outcome as it finishes (a spec given
        twice runs once). Each result is released from the cluster once yielded, so a long
        batch holds only what the caller keeps.

        progress: description of a progress bar over the simulated seconds of the runs.
        """
        from distributed import as_completed  # heavy: loaded when a cluster runs

        if self.client is None:
            raise RuntimeError("use the Executor as a context manager")
        futures: dict[RunSpec, Any] = {}

        def submit(spec: RunSpec) -> Any:
            if spec not in futures:
                tp = submit(spec.as_tp()) if _replays_tp(spec) else None
                futures[spec] = self.client.submit(
                    execute, spec, tp, pure=False,
                    key=f"run-{spec.architecture}-{uuid.uuid4().hex}")
            return futures[spec]

        wanted = {submit(spec).key: spec for spec in specs}
        bar = _ProgressBar(list(wanted.values()), progress) if progress else None
        pending = as_completed(list(futures.values()))
        futures.clear()   # the as_completed iterator and the tasks' inputs hold the rest
        try:
            for future in pending:
                spec = wanted.pop(future.key, None)
                if spec is None:    # a tp run computed only for its dp-a dependants
                    continue
                try:
                    outcome = future.result()
                except Exception as exc:   # the worker died (e.g. KilledWorker), not the run
                    outcome = RunOutcome(spec, error=f"{type(exc).__name__}: {exc}")
                future.release()
                if bar is not None:
                    bar.done(outcome)
                yield outcome
        finally:
            if bar is not None:
                bar.close()

    def map(self, specs: Iterable[RunSpec], *,
            on_done: Callable[[RunOutcome], None] | None = None,
            progress: str | None = None) -> list[RunOutcome]:
        """Run every spec; returns the outcomes in the order of ``specs``.

        on_done(outcome) is called in this process as each asked-for run finishes (e.g. to
        write it at once); progress: description of a progress bar over the simulated
        seconds of the runs.
        """
        specs = list(specs)
        done: dict[RunSpec, RunOutcome] = {}
        for outcome in self.as_completed(specs, progress=progress):
            done[outcome.spec] = outcome
            if on_done is not None:
                on_done(outcome)
        return [done[spec] for spec in specs]


def _configure_local_workers() -> None:
    """Dask settings for the local cluster: worker processes forked from a forkserver that
    imports :mod:`trackmj.study.worker` first (it pins the BLAS/OpenMP/numba thread pools to one
    thread before numpy is imported, then warms the run code), non-daemonic workers."""
    import dask.config  # heavy (dask, distributed): loaded when a local cluster starts
    from distributed import utils

    dask.config.set({"distributed.worker.daemon": False,
                     "distributed.worker.multiprocessing-method": "forkserver"})
    # distributed sets its own preload list at its first use of the context; take that
    # turn first, then put trackmj.study.worker ahead of it (no effect once the server runs)
    utils.get_mp_context()
    multiprocessing.get_context("forkserver").set_forkserver_preload(
        ["trackmj.study.worker", "distributed"])


class _ProgressBar:
    """tqdm bar over the simulated seconds of ``specs``, with runs done and failed."""

    def __init__(self, specs: Sequence[RunSpec], description: str) -> None:
        self.seconds = {spec: simulated_seconds(spec) for spec in specs}
        self.runs, self.finished, self.failed = len(specs), 0, 0
        self.bar = tqdm(total=sum(self.seconds.values()), desc=description, mininterval=0.5,
                        unit="simulated s",
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} "
                                   "simulated s [{elapsed}<{remaining}{postfix}]")
        self._postfix()

    def _postfix(self) -> None:
        failed = f", {self.failed} failed" if self.failed else ""
        self.bar.set_postfix_str(f"runs {self.finished}/{self.runs}{failed}", refresh=False)

    def done(self, outcome: RunOutcome) -> None:
        self.finished += 1
        self.failed += not outcome.ok
        self._postfix()
        self.bar.update(self.seconds.get(outcome.spec, 0.0))

    def close(self) -> None:
        self.bar.close()


def simulated_seconds(spec: RunSpec) -> float:
    """Simulated time of ``spec`` [s]: its duration or its scenario's (0 if the scenario
    cannot be read; the run itself will report why)."""
    if spec.duration is not None:
        return float(spec.duration)
    scenario_keys = tuple((k.partition(".")[2], v) for k, v in spec.overrides
                          if k.startswith("scenario."))
    try:
        return _scenario_duration(spec.scenario, scenario_keys)
    except ParameterError:
        return 0.0


@functools.cache
def _scenario_duration(scenario: str, overrides: tuple[tuple[str, Any], ...]) -> float:
    return load_scenario(scenario, overrides=dict(overrides)).duration_s


def _replays_tp(spec: RunSpec) -> bool:
    return ARCHITECTURES[spec.architecture].replays_tp


def overrides_tuple(overrides: Mapping[str, Any] | Sequence[str] | None) -> tuple:
    """Overrides in :attr:`RunSpec.overrides` form, from a mapping or ``--set`` items."""
    if not overrides:
        return ()
    def frozen(value: Any) -> Any:   # TOML arrays -> tuples, so a RunSpec stays hashable
        return tuple(frozen(v) for v in value) if isinstance(value, list | tuple) else value

    return tuple(sorted((f"{kind}.{key}", frozen(value))
                        for kind, keys in overrides_by_kind(overrides).items()
                        for key, value in keys.items()))


def as_path(value: str | Path | None) -> str | None:
    """A file argument as a string for a RunSpec (None stays None)."""
    return None if value is None else str(value)
