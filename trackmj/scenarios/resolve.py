"""Relative -> absolute for a machine: a scenario file's forces given relative to the
machine's nominal tension (``*_rel`` keys) and drop pressures relative to its hydraulic
file's supply set-point become absolute, and the [limits] the file leaves out become the
machine's band (``BAND_REL`` x nominal). Default machine: the packaged one (lf1352)."""

from __future__ import annotations

import functools
from typing import Any, TypeVar

from trackmj.control.params import BAND_REL
from trackmj.hydraulics.params import load_hydraulic_params
from trackmj.scenarios.schema import Limits, ScenarioFile
from trackmj.track.mechanics import load_model_params
from trackmj.validator import (
    Location,
    ParameterError,
    Parameters,
    construct,
    file_fields,
    range_error,
)

TWINS = {"initial_N": "initial_rel", "delta_N": "delta_rel", "rate_N_s": "rate_rel_s",
         "pressure_Pa": "pressure_rel"}
"""Absolute keys and their relative twins (exactly one of a pair is given)."""

_P = TypeVar("_P", bound=Parameters)


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


Scale = tuple[float, str]
"""What a relative value is relative to: its size and, in words, what it is."""


def _absolute(table: Parameters, at: Location, key: str, scale: Scale) -> float | None:
    """The absolute value of ``key`` of ``table`` (at ``at``): as given, else its relative
    twin x ``scale``; ParameterError naming the twin as the file gives it if the product is
    outside ``key``'s range (None if the file gives neither: a [reference] from_file has no
    initial value)."""
    rel_key = TWINS[key]
    given, rel = getattr(table, key), getattr(table, rel_key)
    if rel is None:
        return given
    value = scale[0] * rel
    bad = range_error(type(table), key, value)
    if bad is not None:
        raise at.error(rel_key, rel, f"gives {key} = {value:g} at {scale[1]}, which {bad}")
    return value


def _replace(table: _P, at: Location, **changes: Any) -> _P:
    """``table`` with ``changes``, its checks naming ``at`` (the file's table) rather than
    the class."""
    kept = {name: getattr(table, name) for name in file_fields(type(table))}
    return construct(type(table), at, **{**kept, **changes})


def resolve(f: ScenarioFile, nominal_N: float, setpoint_Pa: float) -> ScenarioFile:
    """``f`` with every relative value made absolute: forces x ``nominal_N``, drop pressures
    x ``setpoint_Pa``, the [limits] the file leaves out the machine's band. A value out of
    range once absolute is refused in one line naming the file (or the --set option) and
    key the file gives, and what it was taken relative to."""
    at = f.origin
    force: Scale = (nominal_N, f"the machine's nominal tension {nominal_N:g} N")
    pressure: Scale = (setpoint_Pa, f"the hydraulic file's supply set-point {setpoint_Pa:g} Pa")
    ref, ref_at = f.reference, at.child("reference")
    steps = tuple(
        _replace(s, ref_at.child("steps", i),
                 delta_N=_absolute(s, ref_at.child("steps", i), "delta_N", force), delta_rel=None)
        for i, s in enumerate(ref.steps))
    ramps = tuple(
        _replace(r, ref_at.child("ramps", i),
                 rate_N_s=_absolute(r, ref_at.child("ramps", i), "rate_N_s", force),
                 rate_rel_s=None)
        for i, r in enumerate(ref.ramps))
    reference = _replace(ref, ref_at, initial_N=_absolute(ref, ref_at, "initial_N", force),
                         initial_rel=None, steps=steps, ramps=ramps)
    drops_at = at.child("supply", "drops")
    supply = _replace(f.supply, at.child("supply"), drops=tuple(
        _replace(d, drops_at.child(i), pressure_Pa=_absolute(d, drops_at.child(i),
                                                             "pressure_Pa", pressure),
                 pressure_rel=None) for i, d in enumerate(f.supply.drops)))
    pulses = tuple(
        _replace(p, at.child("load_pulses", i),
                 delta_N=_absolute(p, at.child("load_pulses", i), "delta_N", force),
                 delta_rel=None)
        for i, p in enumerate(f.load_pulses))
    lim = f.limits
    limits = construct(
        Limits, at.child("limits"),
        force_min_N=nominal_N * BAND_REL[0] if lim.force_min_N is None else lim.force_min_N,
        force_max_N=nominal_N * BAND_REL[1] if lim.force_max_N is None else lim.force_max_N)
    try:
        return _replace(f, at, reference=reference, supply=supply, load_pulses=pulses,
                        limits=limits)
    except ParameterError as exc:       # F_ref over the run, its relative values resolved
        raise ParameterError(f"{exc}, with its relative values taken at {force[1]}") from None
