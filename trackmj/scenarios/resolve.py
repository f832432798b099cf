"""Relative -> absolute for a machine: a scenario file's forces given relative to the
machine's nominal tension (``*_rel`` keys) and drop pressures relative to its hydraulic
file's supply set-point become absolute, and the [limits] the file leaves out become the
machine's band (``BAND_REL`` x nominal). Default machine: the packaged one (lf1352)."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

from trackmj.control.params import BAND_REL
from trackmj.hydraulics.params import load_hydraulic_params
from trackmj.scenarios.schema import Limits, ScenarioFile
from trackmj.track.mechanics import load_model_params

TWINS = {"initial_N": "initial_rel", "delta_N": "delta_rel", "rate_N_s": "rate_rel_s",
         "pressure_Pa": "pressure_rel"}
"""Absolute keys and their relative twins (exactly one of a pair is given)."""


def drop_twin(data: dict[str, Any], dotted: str) -> None:
    """An override of one key of a twin pair replaces the other one of the file: remove
    the twin of the key ``dotted`` (e.g. ``"reference.steps.0.delta_N"``) from the file's
    ``data`` in place."""
    *parents, key = dotted.split(".")
    twin = TWINS.get(key) or next((a for a, r in TWINS.items() if r == key), None)
    node: Any = data
    for part in parents:
        try:
            node = node[int(part)] if isinstance(node, list) else node[part]
        except (KeyError, IndexError, ValueError, TypeError):
            return
    if twin is not None and isinstance(node, dict):
        node.pop(twin, None)


@functools.cache
def packaged_nominal() -> tuple[float, float]:
    """Nominal tension [N] and supply set-point [Pa] of the packaged machine (read once per
    process: a report loads a scenario per run, and validating the mechanics' layout takes
    ~70 ms)."""
    return (load_model_params().nominal_tension_N,
            load_hydraulic_params().supply.setpoint_Pa)


def _absolute(x: float | None, rel: float | None, scale: float) -> float | None:
    """``x`` if the file gives it absolute, else ``scale`` x ``rel`` (None if it gives
    neither: a [reference] from_file has no initial value)."""
    return x if rel is None else scale * rel


def resolve(f: ScenarioFile, nominal_N: float, setpoint_Pa: float) -> ScenarioFile:
    """``f`` with every relative value made absolute: forces x ``nominal_N``, drop pressures
    x ``setpoint_Pa``, the [limits] the file leaves out the machine's band."""
    rep = dataclasses.replace
    ref = f.reference
    reference = rep(
        ref, initial_N=_absolute(ref.initial_N, ref.initial_rel, nominal_N), initial_rel=None,
        steps=tuple(rep(s, delta_N=_absolute(s.delta_N, s.delta_rel, nominal_N), delta_rel=None)
                    for s in ref.steps),
        ramps=tuple(rep(r, rate_N_s=_absolute(r.rate_N_s, r.rate_rel_s, nominal_N),
                        rate_rel_s=None) for r in ref.ramps))
    supply = rep(f.supply, drops=tuple(
        rep(d, pressure_Pa=_absolute(d.pressure_Pa, d.pressure_rel, setpoint_Pa),
            pressure_rel=None) for d in f.supply.drops))
    pulses = tuple(rep(p, delta_N=_absolute(p.delta_N, p.delta_rel, nominal_N), delta_rel=None)
                   for p in f.load_pulses)
    lim = f.limits
    limits = Limits(nominal_N * BAND_REL[0] if lim.force_min_N is None else lim.force_min_N,
                    nominal_N * BAND_REL[1] if lim.force_max_N is None else lim.force_max_N)
    return rep(f, reference=reference, supply=supply, load_pulses=pulses, limits=limits)
