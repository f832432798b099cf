"""trackmj: electro-hydraulic track tensioning simulator.

The Python API reads like the command line::

    import trackmj

    r = trackmj.simulate("W1", architecture="tp", controller="nmpc", seed=0, duration=10,
                         set={"hydraulics.fluid.bulk_modulus_Pa": 1.2e9})   # trackmj run
    df = r.to_pandas()                   # df.attrs["units"]: column -> unit
    trackmj.sweep("study.toml", "runs/study", workers=2)                    # trackmj sweep

Exports: :func:`simulate`, :func:`sweep`, :func:`load_sweep`, :func:`read_sweep`,
:func:`load_scenario`, :func:`read_result`, :func:`write_result`, :class:`Result`,
:class:`TrackPlant` (:func:`load_plant` loads a machine's), :class:`Executor`,
:class:`RunSpec`. They are imported on first use
(module ``__getattr__``), so ``import trackmj`` stays cheap: it imports no numpy, MuJoCo
or numba, and the pure subpackages ``trackmj.hydraulics`` and ``trackmj.control`` that live
under it stay importable without MuJoCo.
"""

from __future__ import annotations

import importlib

from trackmj.version import __version__

TYPE_CHECKING = False   # type checkers take this name as True; importing typing costs ~3 ms

_EXPORTS: dict[str, str] = {
    "simulate": "trackmj.sim.run",
    "sweep": "trackmj.study.sweep",
    "load_sweep": "trackmj.study.sweep",
    "read_sweep": "trackmj.study.sweep",
    "load_scenario": "trackmj.scenarios.load",
    "read_result": "trackmj.results.store",
    "write_result": "trackmj.results.store",
    "Result": "trackmj.results.store",
    "TrackPlant": "trackmj.track.plant",
    "load_plant": "trackmj.machines.track_plant",
    "Executor": "trackmj.study.executor",
    "RunSpec": "trackmj.study.executor",
}
"""Public name -> the module that defines it."""

__all__ = ["Executor", "Result", "RunSpec", "TrackPlant", "__version__", "load_plant",
           "load_scenario", "load_sweep", "read_result", "read_sweep", "simulate", "sweep",
           "write_result"]

if TYPE_CHECKING:
    from trackmj.machines.track_plant import load_plant
    from trackmj.results.store import Result, read_result, write_result
    from trackmj.scenarios.load import load_scenario
    from trackmj.sim.run import simulate
    from trackmj.study.executor import Executor, RunSpec
    from trackmj.study.sweep import load_sweep, read_sweep, sweep
    from trackmj.track.plant import TrackPlant


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'trackmj' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value   # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
