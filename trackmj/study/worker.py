"""Warm-up of a process that will run simulations: importing this module warms it.

It pins the BLAS/OpenMP/numba thread pools to one thread (before numpy is imported, if it
is not yet), imports the run code and every registered block, loads the packaged model,
its identified idler, the compiled hydraulic kernels and the packaged scenario's controller
and estimator with their compiled SX kernels (numba's on-disk cache; compiled once if the
cache is cold). :class:`trackmj.study.executor.Executor` has its local cluster's
forkserver import it first, so every worker forked from it starts warm and the start-up is
paid once, not once per worker; workers of an existing cluster warm themselves with
``dask worker tcp://HOST:8786 --nthreads 1 --preload trackmj.study.worker``.

A failure here is reported as a warning and never raised: the worker then pays the same
costs at its first run, which reports the error properly.
"""

from __future__ import annotations

import importlib
import os
import time
import warnings

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")
"""Thread-pool sizes pinned to 1 in every worker: one run per core, no oversubscription."""

WARM_MODULES = ("trackmj.sim.run", "trackmj.sim.architectures", "trackmj.control.nmpc",
                "trackmj.control.lmpc", "trackmj.control.pid", "trackmj.control.estimators")
"""Modules of the run path that the registries would otherwise import at the first run."""
WARM_SCENARIO = "W1"
"""The scenario whose (packaged) files are loaded to warm the caches."""

warm_time_s: float = 0.0
"""Wall time the warm-up took in this process [s] (0 until it ran)."""


def pin_threads() -> None:
    """Set every :data:`THREAD_VARIABLES` to 1 (effective for libraries imported later)."""
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))


def warm() -> float:
    """Import and load what every run needs; returns the wall time taken [s]."""
    start = time.perf_counter()
    # imported here, after pin_threads(): numpy and numba size their thread pools on import
    from trackmj.hydraulics import HydraulicTensioner
    from trackmj.ports import COUPLING_STEP_S
    from trackmj.sim.setup import prepare

    for name in WARM_MODULES:
        importlib.import_module(name)
    setup = prepare(WARM_SCENARIO)
    setup.mjcf(None)                       # the packaged MJCF text, cached per process
    stroke = setup.idler.stroke_m          # the identified idler, cached per process
    for coupling in ("strong", "weak"):    # every kernel the run architectures call
        for profile in (None, lambda t: setup.supply0_Pa):
            element = HydraulicTensioner(
                setup.hydraulics, stroke_m=stroke, head_pressure_Pa=setup.head_pressure0_Pa,
                supply_profile=profile,
                supply_pressure_Pa=None if profile else setup.supply0_Pa, coupling=coupling)
            element.set_mode(1)
            element.force_law(0.0, stroke, 0.0)
            element.complete_step(COUPLING_STEP_S, stroke, 0.0)
            element.log()
    # the scenario's controller and estimator: their compiled SX kernels (generated modules
    # and numba's cache, control/compiled.py) are loaded, or compiled once; imported here,
    # after pin_threads(), like the run code above
    from trackmj.sim.architectures import control_and_model
    from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS

    cfg, model = control_and_model(setup, stroke)
    CONTROLLERS[setup.controller].build(model, cfg)
    ESTIMATORS[setup.estimator].build(model, cfg, COUPLING_STEP_S,
                                      model.equilibrium(setup.force0_N))
    return time.perf_counter() - start


def _warm_on_import() -> None:
    global warm_time_s
    pin_threads()
    try:
        warm_time_s = warm()
    except Exception as exc:   # never break the process that imports this module
        warnings.warn(f"trackmj.study.worker: warm-up failed ({type(exc).__name__}: {exc}); "
                      "runs will load what they need themselves", stacklevel=2)


_warm_on_import()
