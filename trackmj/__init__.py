"""trackmj: electro-hydraulic track tensioning simulator.

The Python API reads like the command line::

    import trackmj

    r = trackmj.simulate("W1", architecture="tp", controller="nmpc", seed=0, duration=10,
                         set={"hydraulics.fluid.bulk_modulus_Pa": 1.2e9})   # trackmj run
    df = r.to_pandas()                   # df.attrs["units"]: column -> unit
    trackmj.sweep("study.toml", "runs/study", workers=2)                    # trackmj sweep

Exports: :func:`simulate`, :func:`sweep`, :func:`load_sweep`, :func:`read_sweep`,
:func:`load_scenario`, :func:`read_result`, :func:`write_result`, :class:`Result`,
:class:`TrackPlant`, :class:`Executor`, :class:`RunSpec`. They are imported on first use
(module ``__getattr__``), so ``import trackmj`` stays cheap: it imports no numpy, MuJoCo
or numba, and the pure subpackages ``trackmj.hydraulics`` and ``trackmj.control`` that live
under it stay importable without MuJoCo.
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False   # type checkers take this name as True; importing typing costs ~3 ms
__version__ = "0.1.0"

_EXPORTS: dict[str, str] = {
    "simulate": "trackmj.sim.run",
    "sweep": "trackmj.sweeps",
    "load_sweep": "trackmj.sweeps",
    "read_sweep": "trackmj.sweeps",
    "load_scenario": "trackmj.scenarios",
    "read_result": "trackmj.results",
    "write_result": "trackmj.results",
    "Result": "trackmj.results",
    "TrackPlant": "trackmj.plant",
    "Executor": "trackmj.executor",
    "RunSpec": "trackmj.executor",
}
"""Public name -> the module that defines it."""

__all__ = ["Executor", "Result", "RunSpec", "TrackPlant", "__version__", "load_scenario",
           "load_sweep", "read_result", "read_sweep", "simulate", "sweep", "write_result"]

if TYPE_CHECKING:
    from trackmj.executor import Executor, RunSpec
    from trackmj.plant import TrackPlant
    from trackmj.results import Result, read_result, write_result
    from trackmj.scenarios import load_scenario
    from trackmj.sim.run import simulate
    from trackmj.sweeps import load_sweep, read_sweep, sweep


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'trackmj' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value   # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
