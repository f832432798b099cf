"""Runs many simulations in parallel on Dask distributed: ``compare``, ``report`` and
``sweep`` share this one executor.

By default a :class:`distributed.LocalCluster` with one single-threaded worker process per
core (BLAS/OpenMP threads pinned to 1 in each), or ``workers`` of them; with ``scheduler``
an existing cluster (started with ``dask scheduler`` and ``dask worker tcp://HOST:8786
--nthreads 1`` on each machine; the workers need trackmj installed). A dp-a run replays the
track load of the tp run of the same case, so its tp run is computed first (once, shared
by every dp-a run that needs it, and reported itself if it was asked for). A failed run
becomes an outcome with its error, never a lost batch.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from trackmj.results import Result

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")
"""Thread-pool sizes pinned to 1 in every worker: one run per core, no oversubscription."""


@dataclass(frozen=True)
class RunSpec:
    """One :func:`trackmj.sim.run.simulate` call, picklable and hashable.

    scenario: a built-in name or a scenario file path; overrides: ``(("KIND.TABLE.KEY",
    value), ...)`` as for ``simulate(set=...)``; the other fields as in ``simulate``.
    """

    scenario: str
    architecture: str = "tp"
    controller: str | None = None
    estimator: str | None = None
    seed: int = 0
    duration: float | None = None
    variant: str = "nominal"
    overrides: tuple[tuple[str, Any], ...] = ()
    model: str | None = None
    hydraulics: str | None = None
    control: str | None = None

    def as_tp(self) -> RunSpec:
        """The same case in the tp architecture (what a dp-a run replays)."""
        return replace(self, architecture="tp")

    def simulate_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``simulate`` for this run."""
        return dict(scenario=self.scenario, architecture=self.architecture,
                    controller=self.controller, estimator=self.estimator, seed=self.seed,
                    duration=self.duration, variant=self.variant, set=dict(self.overrides),
                    model=self.model, hydraulics=self.hydraulics, control=self.control)


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
    from trackmj.sim.run import simulate

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
    """

    workers: int | None = None
    scheduler: str | None = None
    client: Any = field(default=None, init=False)
    _cluster: Any = field(default=None, init=False)

    def __enter__(self) -> Executor:
        import dask
        from distributed import Client, LocalCluster

        dask.config.set({"distributed.worker.daemon": False,
                         "distributed.nanny.pre-spawn-environ":
                         dict.fromkeys(THREAD_VARIABLES, "1")})
        if self.scheduler is not None:
            self.client = Client(self.scheduler, timeout="20s")
        else:
            n = self.workers or os.cpu_count() or 1
            if n < 1:
                raise ValueError(f"workers = {n}: need at least one")
            self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                         dashboard_address=None, silence_logs=50)
            self.client = Client(self._cluster)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.client is not None:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
        self.client = self._cluster = None

    def map(self, specs: Iterable[RunSpec], *,
            on_done: Callable[[RunOutcome], None] | None = None,
            progress: str | None = None) -> list[RunOutcome]:
        """Run every spec; returns the outcomes in the order of ``specs``.

        on_done(outcome) is called in this process as each asked-for run finishes (e.g. to
        write it at once); progress: description of a progress bar over the runs.
        """
        from distributed import as_completed

        specs = list(specs)
        if self.client is None:
            raise RuntimeError("use the Executor as a context manager")
        futures: dict[RunSpec, Any] = {}

        def submit(spec: RunSpec) -> Any:
            if spec not in futures:
                tp = submit(spec.as_tp()) if _replays_tp(spec) else None
                futures[spec] = self.client.submit(execute, spec, tp, pure=False,
                                                   key=f"run-{len(futures)}-{spec.architecture}")
            return futures[spec]

        wanted = {submit(spec).key: spec for spec in specs}
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(wanted), unit="run", desc=progress, mininterval=0.5)
        done: dict[RunSpec, RunOutcome] = {}
        try:
            for future in as_completed(list(futures.values())):
                if future.key not in wanted:
                    continue
                outcome = future.result()
                done[wanted[future.key]] = outcome
                if on_done is not None:
                    on_done(outcome)
                if bar is not None:
                    bar.update(1)
        finally:
            if bar is not None:
                bar.close()
        return [done[spec] for spec in specs]


def _replays_tp(spec: RunSpec) -> bool:
    from trackmj.sim.registry import ARCHITECTURES

    return ARCHITECTURES[spec.architecture].replays_tp


def overrides_tuple(overrides: Mapping[str, Any] | Sequence[str] | None) -> tuple:
    """Overrides in :attr:`RunSpec.overrides` form, from a mapping or ``--set`` items."""
    if not overrides:
        return ()
    from trackmj.sim.setup import overrides_by_kind

    def frozen(value: Any) -> Any:   # TOML arrays -> tuples, so a RunSpec stays hashable
        return tuple(frozen(v) for v in value) if isinstance(value, list | tuple) else value

    return tuple(sorted((f"{kind}.{key}", frozen(value))
                        for kind, keys in overrides_by_kind(overrides).items()
                        for key, value in keys.items()))


def as_path(value: str | Path | None) -> str | None:
    """A file argument as a string for a RunSpec (None stays None)."""
    return None if value is None else str(value)
