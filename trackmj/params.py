"""Typed, range-checked parameter loading from TOML into frozen dataclasses.

A parameter field declares its allowed range with :func:`param`; :func:`load_table`
reads one TOML table into the dataclass and raises :class:`ParameterError` (a
``ValueError``) naming the file, the key and the allowed range for anything missing,
mistyped, NaN or out of range.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


class ParameterError(ValueError):
    """A parameter file or value is malformed or out of its allowed range."""


def param(low: float | None = None, high: float | None = None, *, open_low: bool = False,
          doc: str = "") -> Any:
    """Dataclass field with an allowed range [low, high] (``open_low``: low excluded)."""
    return dataclasses.field(metadata={"low": low, "high": high, "open_low": open_low,
                                       "doc": doc})


def _describe_range(meta: dataclasses.Field) -> str:
    low, high = meta.metadata.get("low"), meta.metadata.get("high")
    left = "(" if meta.metadata.get("open_low") else "["
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    return f"{left}{lo}, {hi}]"


def _check_number(where: str, value: Any, fld: dataclasses.Field) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(f"{where}: expected a number, got {value!r}")
    if math.isnan(value) or math.isinf(value):
        raise ParameterError(f"{where}: must be finite, got {value!r}")
    low, high = fld.metadata.get("low"), fld.metadata.get("high")
    open_low = fld.metadata.get("open_low", False)
    too_low = low is not None and (value <= low if open_low else value < low)
    too_high = high is not None and value > high
    if too_low or too_high:
        raise ParameterError(f"{where} = {value!r} is outside the allowed range "
                             f"{_describe_range(fld)}")
    return value


def validate(obj: Any, where: str) -> None:
    """Check every ranged field of dataclass instance ``obj``; ``where`` names its origin."""
    for fld in dataclasses.fields(obj):
        if "low" not in fld.metadata:
            continue
        value = getattr(obj, fld.name)
        items = value if isinstance(value, tuple) else (value,)
        for item in items:
            _check_number(f"{where}.{fld.name}", item, fld)


def load_table(cls: type[T], table: dict[str, Any], where: str) -> T:
    """Build dataclass ``cls`` from TOML ``table``; ``where`` is e.g. ``'lf1352.toml [track]'``.

    Keys not declared by ``cls`` (such as ``source``) are ignored only if they are
    documentation keys; unknown parameter keys are an error so typos do not pass silently.
    """
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = set(table) - names - {"source"}
    if unknown:
        raise ParameterError(f"{where}: unknown key(s) {sorted(unknown)}; "
                             f"allowed: {sorted(names)}")
    kwargs: dict[str, Any] = {}
    for fld in dataclasses.fields(cls):
        if fld.name not in table:
            if fld.default is not dataclasses.MISSING:
                continue
            raise ParameterError(f"{where}: missing key '{fld.name}'")
        value = table[fld.name]
        if isinstance(value, list):
            value = tuple(value)
        kwargs[fld.name] = value
    obj = cls(**kwargs)
    validate(obj, where)
    return obj


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file, turning syntax errors into a ParameterError naming the file."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ParameterError(f"parameter file not found: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{path}: malformed TOML: {exc}") from None
