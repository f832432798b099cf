"""What a column of a results table (``results.parquet``) or of a timeseries is: its SI unit
(:func:`column_unit`), whether it holds a swept ``--set`` key (:func:`is_key_column`), and
how figures show it: display unit (:func:`display_unit`), plain words (:func:`column_words`)
and axis label (:func:`column_label`).

A swept key (``KIND.TABLE.KEY``) takes the unit its file declares, so this module knows the
root schema of each file kind (:func:`file_schema`).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from typing import Any

from trackmj.control.params import ControlConfig
from trackmj.hydraulics.params import HydraulicParams
from trackmj.ports import COLUMN_UNITS
from trackmj.results.metrics import METRIC_DISPLAY
from trackmj.scenarios.schema import ScenarioFile
from trackmj.track.mechanics import ModelParams
from trackmj.validator import FILE_KINDS, UNIT_SUFFIXES, file_fields, unit_from_name

DISPLAY_UNITS: dict[str, tuple[float, str]] = {
    "N": (1e-3, "kN"), "Pa": (1e-6, "MPa"), "Pa (absolute)": (1e-6, "MPa abs"),
    "J": (1e-3, "kJ"), "W": (1e-3, "kW"), "m": (1e3, "mm"), "m^2": (1e6, "mm²"),
    "m^3": (1e6, "cm³"), "m^3/s": (6e4, "L/min"), "N/m": (1e-6, "kN/mm"),
    "m/s^2": (1.0, "m/s²"), "N^2·s": (1e-6, "kN²·s"), "1": (1.0, ""),
}
"""SI unit -> (scale, display unit) on the figures; other units are shown as they are."""
WORDS = {"lp": "low-pass", "rms": "RMS", "ise": "integral of squared error"}
"""Abbreviations of metric names in plain words (on the sweep figures' axes)."""
KEY_SYMBOLS = {"scenario.terrain.grade": "tan θ"}
"""Swept key -> the quantity its words are followed by where they alone do not say it (a
grade is the slope's tangent, rise over run, not its angle)."""


# ----------------------------------------------------------------------------- units

def file_schema(kind: str) -> type:
    """The root parameter class of file kind ``kind`` (one of FILE_KINDS)."""
    if kind == "model":
        return ModelParams
    if kind == "hydraulics":
        return HydraulicParams
    if kind == "control":
        return ControlConfig
    return ScenarioFile


def key_field(key: str) -> Any:
    """The (type hint, Spec) that the file of ``key`` (``KIND.TABLE.KEY``) declares for it,
    or None if the key does not exist (the file's validator then says why)."""
    kind, *parts = key.split(".")
    hint: Any = file_schema(kind)
    spec = None
    for part in parts:
        origin, args = typing.get_origin(hint), typing.get_args(hint)
        if origin is tuple and part.isdigit() and dataclasses.is_dataclass(args[0]):
            hint = args[0]
            continue
        if origin in (dict, Mapping) and dataclasses.is_dataclass(args[1]):
            hint = args[1]
            continue
        if not (isinstance(hint, type) and dataclasses.is_dataclass(hint)):
            return None
        found = file_fields(hint).get(part)
        if found is None:
            return None
        hint, spec = found.hint, found.spec
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        hint = next(a for a in typing.get_args(hint) if a is not type(None))
    return hint, spec


def key_unit(key: str) -> str:
    """Unit of a ``--set`` key as its file declares it ('' if unknown)."""
    found = key_field(key)
    if found is not None and found[1] is not None and found[1].unit:
        return found[1].unit
    return unit_from_name(key.rsplit(".", 1)[-1]) or ""


def is_key_column(name: str) -> bool:
    """Whether results column ``name`` holds a ``--set`` key (``KIND.TABLE.KEY``)."""
    kind, dot, _ = name.partition(".")
    return bool(dot) and kind in FILE_KINDS


def column_unit(name: str) -> str:
    """Unit of a results (or timeseries) column: a key's declared unit, a timeseries
    column's unit (:data:`trackmj.ports.COLUMN_UNITS`), else its name's SI suffix (for a
    flattened table entry ``table.key`` the key's, else the table's)."""
    if is_key_column(name):
        return key_unit(name)
    if name in COLUMN_UNITS:
        return COLUMN_UNITS[name]
    if name in ("point", "seed"):
        return "1"
    for part in reversed(name.split(".")):   # a table entry: the table's unit (energy_J.pump)
        unit = unit_from_name(part)
        if unit:
            return unit
    return ""


# ----------------------------------------------------------------------------- display

def display_unit(unit: str) -> tuple[float, str]:
    """(scale, display unit) of SI ``unit`` (:data:`DISPLAY_UNITS`)."""
    return DISPLAY_UNITS.get(unit, (1.0, unit))


DIMENSIONLESS_WORDS = {"_rel": "relative", "_scale": "scale", "_count": "count",
                       "_steps": "steps", "_iter": "iterations"}
"""Suffixes of dimensionless names that say what the number is, so they stay as words
(``delta_rel`` -> "delta relative", where the unit alone would leave "delta")."""


def _bare(part: str) -> str:
    """``part`` of a column name without its unit suffix (``bulk_modulus_Pa`` ->
    ``bulk_modulus``), a dimensionless one's suffix in words (``delta_rel`` ->
    ``delta_relative``)."""
    for suffix, _ in UNIT_SUFFIXES:
        if part.endswith(suffix) and len(part) > len(suffix):
            word = DIMENSIONLESS_WORDS.get(suffix)
            return part[: -len(suffix)] + ("" if word is None else f"_{word}")
    return part


def column_words(name: str) -> str:
    """A results column in plain words: the label of :data:`trackmj.results.metrics.METRIC_DISPLAY`,
    else the name without its unit suffix, ``_`` and ``.`` as spaces (a swept key: its
    last two parts, e.g. "fluid bulk modulus")."""
    if name in METRIC_DISPLAY:
        return METRIC_DISPLAY[name][0]
    if name == "wall_time_s":
        return "wall time of a run"
    parts = name.split(".")
    if is_key_column(name):
        parts = [p for p in parts[1:] if not p.isdigit()][-2:]
    words = " ".join(_bare(p) for p in parts).replace("_", " ").split()
    return " ".join([*(WORDS.get(w, w) for w in words), *KEY_SYMBOLS.get(name, "").split()])


def column_label(name: str) -> str:
    """Axis label of a results column: plain words and display unit ("tension RMSE,
    low-pass [kN]"); a dimensionless swept key [-] ("terrain grade tan θ [-]")."""
    unit = METRIC_DISPLAY[name][2] if name in METRIC_DISPLAY else \
        display_unit(column_unit(name))[1]
    if not unit and is_key_column(name) and column_unit(name) == "1":
        unit = "-"
    return f"{column_words(name)} [{unit}]" if unit and unit != "1" else column_words(name)
