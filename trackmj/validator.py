"""One validator for every parameter and scenario file: typed, range-checked frozen dataclasses.

A parameter class is a frozen dataclass deriving from :class:`Parameters`; each field is
declared with :func:`param` (allowed range, unit, choices, doc). The field's type comes from
its annotation:

========================  =====================================================================
annotation                accepted value
========================  =====================================================================
``float``                 a float or an integer (stored as float); finite
``int``                   an integer; a float is refused even if integral (``82.0``): a count
                          written as a float is a slip worth a message, not a guess
``bool``                  ``true`` / ``false`` only (never 0 / 1)
``str``                   a string (optionally one of ``choices``, matching ``pattern``, at most
                          ``max_len`` characters)
``Literal["a", "b"]``     one of the listed values
``tuple[float, float]``   an array of exactly that many items
``tuple[float, ...]``     a non-empty array of items (empty allowed with ``allow_empty``)
``X | None``              ``None`` only as a code default: TOML has no null, so "not given"
a Parameters dataclass    a table ``[name]``
``tuple[D, ...]``         an array of tables ``[[name]]`` (may be empty)
``Mapping[str, D]``       a table of named tables ``[name.key]`` (or ``dict[str, D]``)
``D | None = None``       an optional table ``[name]`` (None when the file has none)
``Mapping[str, X]``       a table of values of type X (``Any``: a number, boolean or string),
                          e.g. a map of names chosen by the file
========================  =====================================================================

Every check runs in ``__post_init__``, so objects built in code (``dataclasses.replace``)
pass the same checks as a file. :func:`load_file` tells the check where the values come
from, so its messages read ``file [table].key = value: ...``; in code they read
``Class.key = value: ...``. Cross-field checks go in :meth:`Parameters.cross_check`, which
receives that :class:`Location` so they name file, table and key too.

Units: a numeric field's unit defaults to the one its name's SI suffix states
(:data:`UNIT_SUFFIXES`; ``_N_m`` is a stiffness N/m, a torque passes ``unit="N·m"``); a
numeric field whose name has no suffix passes ``unit=`` explicitly ("1" for dimensionless).
String, boolean and table fields carry no unit.

Parameter files (model, hydraulics, control) carry a ``source`` string in every table (the
study, a datasheet, a public source by name, or "assumed: why"); the loader keeps them in
the root object's :func:`sources_field` (table path -> source). Scenario files may carry
``source`` keys but need not.

Overrides (``--set kind.table.key=value``, :func:`parse_overrides`) are applied to the raw
TOML data before validation, so they pass the same checks; a message about an overridden
value names the option.

One module, although it is long: the coercion of values, the override paths and the key
listing (:func:`describe_schema`, ``trackmj keys``) all walk the same field specs, and
``hydraulics/`` and ``control/`` import it as a leaf; split, each part would reach into the
others' private helpers.
"""

from __future__ import annotations

import contextvars
import dataclasses
import difflib
import functools
import math
import re
import tomllib
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

T = TypeVar("T")

FILE_KINDS = ("model", "hydraulics", "control", "scenario")
"""The file kinds an override names first: ``--set hydraulics.fluid.bulk_modulus_Pa=1.2e9``."""

MAX_FILE_BYTES = 1 << 20
"""Largest parameter or scenario file read [bytes]; the packaged ones are ~10 kB."""

UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (
    ("_m3_s_Pa", "m^3/(s·Pa)"),
    ("_N2s", "N^2·s"),
    ("_Pa_abs", "Pa (absolute)"),
    ("_cycles_m", "1/m"),
    ("_N_s_m", "N·s/m"),
    ("_N_m_s", "N·m·s/rad"),
    ("_kg_m3", "kg/m^3"),
    ("_kg_m2", "kg·m^2"),
    ("_m3_s", "m^3/s"),
    ("_m2_s", "m^2/s"),
    ("_m_s2", "m/s^2"),
    ("_count", "1"),
    ("_steps", "1"),
    ("_scale", "1"),
    ("_iter", "1"),
    ("_rel", "1"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_N_m", "N/m"),
    ("_N_s", "N/s"),
    ("_m_s", "m/s"),
    ("_Hz", "Hz"),
    ("_Pa", "Pa"),
    ("_kg", "kg"),
    ("_m2", "m^2"),
    ("_m3", "m^3"),
    ("_N", "N"),
    ("_J", "J"),
    ("_W", "W"),
    ("_s", "s"),
    ("_m", "m"),
)
"""Name suffix -> unit, longest suffix first. ``_X_Y`` is X/Y except the products a
mechanical engineer writes that way: ``_N_s_m`` N·s/m (damping), ``_kg_m2`` kg·m^2
(inertia), ``_N_m_s`` N·m·s/rad (rotational damping). ``_N_m`` is a stiffness [N/m]; a
torque declares ``unit="N·m"``. ``_N_s`` is a rate [N/s]. Counts (``_count``, ``_steps``,
``_iter``), scales and relative values are dimensionless."""


class ParameterError(ValueError):
    """A parameter or scenario file, an override or a value is malformed or out of range."""


def unit_from_name(name: str) -> str | None:
    """The unit the SI suffix of field ``name`` states (see :data:`UNIT_SUFFIXES`), or None."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return None


def _number(x: float) -> str:
    """An integer as written, a float in short form (1e+11, 0.02)."""
    return str(x) if isinstance(x, int) else f"{x:g}"


@dataclass(frozen=True)
class Spec:
    """What :func:`param` declares about one field (see there)."""

    low: float | None = None
    high: float | None = None
    unit: str | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple[Any, ...] | None = None
    pattern: str | None = None
    max_len: int | None = None
    doc: str = ""
    allow_empty: bool = False

    def range_text(self) -> str:
        """The allowed range as text, e.g. ``(0, 1e+11]``; '' if unbounded."""
        if self.low is None and self.high is None:
            return ""
        lo = "-inf" if self.low is None else _number(self.low)
        hi = "inf" if self.high is None else _number(self.high)
        return f"{'(' if self.open_low else '['}{lo}, {hi}{')' if self.open_high else ']'}"


def param(low: float | None = None, high: float | None = None, *, unit: str | None = None,
          open_low: bool = False, open_high: bool = False,
          choices: Sequence[Any] | None = None, pattern: str | None = None,
          max_len: int | None = None, default: Any = dataclasses.MISSING,
          default_factory: Any = dataclasses.MISSING, doc: str = "",
          allow_empty: bool = False) -> Any:
    """Dataclass field with its allowed range, unit and meaning.

    Parameters
    ----------
    low, high : float, optional
        Allowed range (inclusive unless ``open_low`` / ``open_high``); for arrays, per item.
    unit : str, optional
        Unit of a numeric field; default: the unit of the name's SI suffix.
    choices : sequence, optional
        Allowed values of a string field (the error lists them).
    pattern, max_len : optional
        Regular expression the whole string must match, and its maximum length.
    default, default_factory : optional
        Only for keys that are genuinely optional in a file; say why in ``doc``.
    doc : str
        One line on what the value means (shown in errors for missing keys and by
        :func:`describe_schema`).
    allow_empty : bool
        A ``tuple[X, ...]`` field may be an empty array (e.g. no return rollers).

    Returns
    -------
    dataclasses.Field
    """
    spec = Spec(low, high, unit, open_low, open_high,
                None if choices is None else tuple(choices), pattern, max_len, doc,
                allow_empty)
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={"param": spec})


def sources_field() -> Any:
    """Field of a file's root class that the loader fills with ``{table path: source}``
    (overridden keys add ``{key path: "--set ..."}``); not a key of the file, not compared."""
    return dataclasses.field(default_factory=dict, compare=False, repr=False,
                             metadata={"loader": "sources"})


# ----------------------------------------------------------------------------- locations

def _path_text(path: Sequence[str | int]) -> str:
    """TOML-style text of a table path: ('a', 'b') -> '[a.b]', ('a', 0) -> '[[a]][0]'."""
    text, names = "", []
    for part in path:
        if isinstance(part, int):
            text += f"[[{'.'.join(names)}]][{part}]" if names else f"[{part}]"
            names = []
        else:
            names.append(part)
    if names:
        text += "." + ".".join(names) if text else f"[{'.'.join(names)}]"
    return text


@dataclass(frozen=True)
class Location:
    """Where a table's values come from: ``file`` (a name) or, built in code, ``label`` (the
    class name); ``path`` the table path in the file; ``overridden`` (key path -> option
    text) names the ``--set`` options that changed values."""

    file: str | None = None
    label: str | None = None
    path: tuple[str | int, ...] = ()
    overridden: Mapping[tuple[str | int, ...], str] = dataclasses.field(default_factory=dict)

    def child(self, *parts: str | int) -> Location:
        """The location of a sub-table."""
        return dataclasses.replace(self, path=self.path + parts)

    def table(self) -> str:
        """e.g. ``lf1352_hydraulics.toml [cylinder]`` or ``Cylinder``."""
        head = self.file if self.file is not None else (self.label or "")
        tail = _path_text(self.path)
        return f"{head} {tail}".strip()

    def key(self, *parts: str | int) -> str:
        """Text naming key ``parts`` below this table, e.g. ``W1.toml [track].speed_m_s``,
        ``Track.speed_m_s`` or, if overridden, ``--set scenario.track.speed_m_s``."""
        full = self.path + parts
        for n in range(len(full), 0, -1):
            option = self.overridden.get(full[:n])
            if option is not None:
                return option + "".join(f"[{p}]" if isinstance(p, int) else f".{p}"
                                        for p in full[n:])
        last, head = max((i, p) for i, p in enumerate(full) if isinstance(p, str))
        name = head + "".join(f"[{p}]" for p in full[last + 1:])
        table = _path_text(full[:last])
        if self.file is not None:
            return f"{self.file} {table}.{name}" if table else f"{self.file}: {name}"
        return f"{self.label} {table}.{name}" if table else f"{self.label}.{name}"

    def error(self, key: str | tuple[str | int, ...], value: Any, text: str) -> ParameterError:
        """``ParameterError('<where key> = <value> <text>')`` for a cross-field check; when
        ``--set`` changed other keys of the file than the one named, the message ends
        naming them (a cross-field check may fail on a key the file holds because of a
        value given on the command line)."""
        parts = (key,) if isinstance(key, str) else key
        named = self.key(*parts)
        others = [option for option in dict.fromkeys(self.overridden.values())
                  if named != option and not named.startswith((option + ".", option + "["))]
        changed = f" (with {', '.join(others)})" if others else ""
        return ParameterError(f"{named} = {_show(value)} {text}{changed}")


def origin_field() -> Any:
    """Field of a parameter class that its checks fill with the :class:`Location` they name:
    loaded, the file's (its name, the keys ``--set`` options changed); built in code, the
    class name. A check made later (the MJCF generator's) names file and key through it as
    the loader's checks do. Not a key of the file, not compared."""
    return dataclasses.field(default=None, compare=False, repr=False,
                             metadata={"loader": "origin"})


_BUILDING: contextvars.ContextVar[tuple[type, Location] | None] = contextvars.ContextVar(
    "trackmj_params_building", default=None)


# ----------------------------------------------------------------------------- checking

class Parameters:
    """Base of every parameter dataclass: validates all fields on construction.

    Subclasses are frozen dataclasses (``@dataclass(frozen=True)``, ``slots=True`` allowed)
    and may override :meth:`cross_check` for checks that involve several fields.
    """

    __slots__ = ()

    def __post_init__(self) -> None:
        check(self)

    def cross_check(self, at: Location) -> None:
        """Checks between fields; raise ``at.error(key, value, 'must be ...')``."""


@dataclass(frozen=True)
class _Field:
    hint: Any
    spec: Spec
    required: bool
    loader: str | None


@functools.cache
def _schema(cls: type) -> dict[str, _Field]:
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        spec = f.metadata.get("param") or Spec()
        if spec.unit is None:
            spec = dataclasses.replace(spec, unit=unit_from_name(f.name))
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        out[f.name] = _Field(hints[f.name], spec, required, f.metadata.get("loader"))
    return out


def file_fields(cls: type) -> dict[str, _Field]:
    """The fields of ``cls`` that are keys of its file (loader-filled fields left out)."""
    return {n: f for n, f in _schema(cls).items() if f.loader is None}


def check(obj: Any) -> None:
    """Validate and normalise every field of parameter dataclass ``obj`` (ints to float,
    lists to tuples), then run its :meth:`~Parameters.cross_check`."""
    building = _BUILDING.get()
    at = (building[1] if building is not None and building[0] is type(obj)
          else Location(label=type(obj).__name__))
    for name, fld in file_fields(type(obj)).items():
        value = getattr(obj, name)
        new = _coerce(value, fld.hint, fld.spec, at, (name,))
        if new is not value:
            object.__setattr__(obj, name, new)
    for name, fld in _schema(type(obj)).items():
        if fld.loader == "origin":
            object.__setattr__(obj, name, at)
    obj.cross_check(at)


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a float"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list | tuple):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return f"a {type(value).__name__}"


def _show(value: Any) -> str:
    if isinstance(value, dict):
        return "{...}"
    if isinstance(value, float):          # numpy scalars print as plain numbers
        value = float(value)
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 80 else text[:77] + "..."


def _expected(hint: Any) -> str:
    origin, args = get_origin(hint), get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_expected(a) for a in args if a is not type(None))
    if hint is float:
        return "a number"
    if hint is int:
        return "an integer"
    if hint is bool:
        return "true or false"
    if hint is str:
        return "a string"
    if origin is Literal:
        return f"one of {list(args)}"
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            if dataclasses.is_dataclass(args[0]):
                return "an array of tables"
            return f"a non-empty array of {_plural(args[0])}"
        return f"an array of {len(args)} {_plural(args[0])}"
    if origin in (dict, Mapping) or dataclasses.is_dataclass(hint):
        return "a table"
    return str(hint)


def _plural(hint: Any) -> str:
    return {float: "numbers", int: "integers", bool: "booleans", str: "strings"}.get(
        hint, "items")


def _coerce(value: Any, hint: Any, spec: Spec, at: Location,
            parts: tuple[str | int, ...]) -> Any:
    """``value`` checked against type ``hint`` and ``spec``; returns it normalised."""
    origin, args = get_origin(hint), get_args(hint)

    def fail(text: str) -> ParameterError:
        sep = " " if text.startswith(("is ", "must match")) else ": "
        return ParameterError(f"{at.key(*parts)} = {_show(value)}{sep}{text}")

    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = (a for a in args if a is not type(None))
        return _coerce(value, inner, spec, at, parts)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        if not isinstance(value, hint):
            raise fail(f"expected {_expected(hint)}, got {_kind(value)}")
        return value
    if origin in (dict, Mapping):
        item = args[1]
        if isinstance(item, type) and dataclasses.is_dataclass(item):
            if not isinstance(value, dict) or not all(
                    isinstance(k, str) and isinstance(v, item) for k, v in value.items()):
                raise fail(f"expected {_expected(hint)} of {item.__name__} tables")
            return value
        if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
            raise fail(f"expected {_expected(hint)}, got {_kind(value)}")
        return {k: _coerce_item(v, item, spec, at, (*parts, k)) for k, v in value.items()}
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise fail(f"expected {_expected(hint)}, got {_kind(value)}")
        variable = len(args) == 2 and args[1] is Ellipsis
        if variable and not value and not (dataclasses.is_dataclass(args[0])
                                           or spec.allow_empty):
            raise fail(f"expected {_expected(hint)}, got an empty array")
        if not variable and len(value) != len(args):
            raise fail(f"expected {_expected(hint)}, got {len(value)}")
        items = args[:1] * len(value) if variable else args
        out = tuple(_coerce(v, h, spec, at, (*parts, i))
                    for i, (v, h) in enumerate(zip(value, items, strict=True)))
        return value if isinstance(value, tuple) and all(
            a is b for a, b in zip(out, value, strict=True)) else out
    if origin is Literal:
        if not any(type(value) is type(c) and value == c for c in args):
            raise fail(f"is not one of {list(args)}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise fail(f"expected true or false, got {_kind(value)}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise fail(f"expected a string, got {_kind(value)}")
        _check_string(value, spec, fail)
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail(f"expected an integer, got {_kind(value)}")
        _check_range(value, spec, fail)
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise fail(f"expected a number, got {_kind(value)}")
        if not math.isfinite(value):
            raise fail("must be finite")
        _check_range(value, spec, fail)
        return value if type(value) is float else float(value)
    raise TypeError(f"{at.key(*parts)}: unsupported parameter type {hint!r}")


def _coerce_item(value: Any, hint: Any, spec: Spec, at: Location,
                 parts: tuple[str | int, ...]) -> Any:
    """One value of a ``Mapping[str, X]`` table: ``X`` checked as a field is, ``Any`` a
    number, boolean or string (no arrays or tables)."""
    if hint is not Any:
        return _coerce(value, hint, spec, at, parts)
    if isinstance(value, bool | int | float | str) and not (
            isinstance(value, float) and not math.isfinite(value)):
        return value
    raise ParameterError(f"{at.key(*parts)} = {_show(value)}: expected a finite number, a "
                         f"boolean or a string, got {_kind(value)}")


def _optional_table(hint: Any) -> Any:
    """The table class of an optional table field ``D | None``; other hints unchanged."""
    if get_origin(hint) in (typing.Union, types.UnionType):
        inner = [a for a in get_args(hint) if a is not type(None)]
        if len(inner) == 1 and dataclasses.is_dataclass(inner[0]):
            return inner[0]
    return hint


def _check_range(value: float, spec: Spec, fail: Any) -> None:
    low, high = spec.low, spec.high
    too_low = low is not None and (value <= low if spec.open_low else value < low)
    too_high = high is not None and (value >= high if spec.open_high else value > high)
    if too_low or too_high:
        raise fail(f"is outside the allowed range {spec.range_text()}"
                   + (f" {spec.unit}" if spec.unit and spec.unit != "1" else ""))


def range_error(cls: type, name: str, value: float) -> str | None:
    """``'is outside the allowed range [low, high] unit'`` if ``value`` is outside the range
    of field ``name`` of parameter class ``cls``, else None (for a value a check derives
    from the file's, e.g. a relative value made absolute, whose message names the key the
    file gives)."""
    try:
        _check_range(value, _schema(cls)[name].spec, ParameterError)
    except ParameterError as exc:
        return str(exc)
    return None


def _check_string(value: str, spec: Spec, fail: Any) -> None:
    if spec.choices is not None and value not in spec.choices:
        raise fail(f"is not one of {list(spec.choices)}")
    if spec.max_len is not None and len(value) > spec.max_len:
        raise fail(f"is {len(value)} characters long; at most {spec.max_len} allowed")
    if spec.pattern is not None and not re.fullmatch(spec.pattern, value):
        raise fail(f"must match {spec.pattern}" + (f" ({spec.doc})" if spec.doc else ""))


# ----------------------------------------------------------------------------- files

def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; every failure (missing, a directory, not a regular file, too
    large, binary, not UTF-8, malformed) is a ParameterError naming the file."""
    path = Path(path)
    try:
        if path.is_dir():
            raise ParameterError(f"{path}: is a directory, not a TOML file")
        if path.exists() and not path.is_file():
            raise ParameterError(f"{path}: not a regular file")
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ParameterError(f"{path}: {size} bytes; a parameter or scenario file has "
                                 f"at most {MAX_FILE_BYTES} bytes")
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ParameterError(f"parameter file not found: {path}") from None
    except OSError as exc:
        raise ParameterError(f"{path}: cannot read: {exc.strerror}") from None
    if b"\x00" in raw:
        raise ParameterError(f"{path}: not a text file (NUL byte at offset {raw.index(0)}); "
                             "expected TOML text")
    try:
        text = raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        raise ParameterError(f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at "
                             f"offset {exc.start}); save the file as UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"{path.name}: malformed TOML: {exc}") from None


def load_file(cls: type[T], path: str | Path, *, overrides: Mapping[str, Any] | None = None,
              require_source: bool = True) -> T:
    """Read TOML file ``path`` into parameter class ``cls`` (a :class:`Parameters` dataclass
    whose fields are the file's tables).

    Parameters
    ----------
    cls : type
        Root class; its optional class attribute ``file_kind`` (one of :data:`FILE_KINDS`)
        names the kind in override messages.
    path : str or Path
        The TOML file.
    overrides : mapping, optional
        ``{dotted key: value}`` for this file (one entry of :func:`parse_overrides`),
        applied to the raw data before validation.
    require_source : bool
        Every table must carry a ``source`` string (parameter files).

    Returns
    -------
    cls
        The validated object. Raises ParameterError naming file, table and key.
    """
    path = Path(path)
    return build(cls, read_toml(path), file=path.name, overrides=overrides,
                 require_source=require_source)


def build(cls: type[T], data: Mapping[str, Any], *, file: str = "<data>",
          overrides: Mapping[str, Any] | None = None, require_source: bool = True) -> T:
    """Validate parsed TOML ``data`` into ``cls`` as :func:`load_file` does; ``file`` names
    the data's origin in messages."""
    raw: dict[str, Any] = _copy(data)
    kind = getattr(cls, "file_kind", None)
    applied = apply_overrides(cls, raw, overrides or {}, kind)
    sources: dict[str, str] = {}
    at = Location(file=file, overridden={p: opt for p, opt, _ in applied})
    obj = _build(cls, raw, at, require_source, sources)
    for path, option, value in applied:
        sources[".".join(map(str, path))] = f"{option}={_show(value)}"
    for name, fld in _schema(cls).items():
        if fld.loader == "sources":
            object.__setattr__(obj, name, sources)
    return obj


def _copy(data: Any) -> Any:
    if isinstance(data, dict):
        return {k: _copy(v) for k, v in data.items()}
    if isinstance(data, list):
        return [_copy(v) for v in data]
    return data


def _table_kind(hint: Any) -> str | None:
    """'table' (optional or not), 'array' (of tables), 'named' (dict of tables) or None (a
    value)."""
    hint = _optional_table(hint)
    if dataclasses.is_dataclass(hint):
        return "table"
    origin, args = get_origin(hint), get_args(hint)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis \
            and dataclasses.is_dataclass(args[0]):
        return "array"
    if origin in (dict, Mapping) and dataclasses.is_dataclass(args[1]):
        return "named"
    return None


def _describe_missing(name: str, fld: _Field, at: Location) -> str:
    kind = _table_kind(fld.hint)
    if kind == "table":
        return f"{at.file}: missing table {_path_text((*at.path, name))}"
    if kind is not None:
        return f"{at.table()}: missing {_expected(fld.hint)} {name!r}"
    bits = [_expected(fld.hint)]
    if fld.spec.unit and fld.spec.unit != "1":
        bits.append(fld.spec.unit)
    if fld.spec.range_text():
        bits.append(f"range {fld.spec.range_text()}")
    doc = f": {fld.spec.doc}" if fld.spec.doc else ""
    return f"{at.table()}: missing key {name!r} ({', '.join(bits)}){doc}"


def missing_key(cls: type, name: str, at: Location, hint: str = "") -> ParameterError:
    """The loader's "missing key" error for field ``name`` of ``cls`` at ``at`` (type, unit,
    range, doc), with ``hint`` appended, for a key that a cross-check finds missing."""
    return ParameterError(_describe_missing(name, _schema(cls)[name], at) + hint)


def did_you_mean(word: str, names: Sequence[str]) -> str:
    """``"; did you mean 'name'?"`` with the name of ``names`` nearest ``word`` (difflib's
    closest), or '' if none is near."""
    close = difflib.get_close_matches(word, names, n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _unknown(key: str, value: Any, names: Sequence[str], at: Location) -> ParameterError:
    what = (f"table {_path_text((*at.path, key))}" if isinstance(value, dict) and not at.path
            else f"key {key!r}")
    return ParameterError(f"{at.table()}: unknown {what}{did_you_mean(key, names)} "
                          f"(allowed: {', '.join(names)})")


def _build(cls: type, raw: Any, at: Location, require_source: bool,
           sources: dict[str, str]) -> Any:
    if not issubclass(cls, Parameters):     # its construction would check nothing
        raise TypeError(f"{cls.__qualname__} (table {at.table()}) must derive from "
                        "trackmj.validator.Parameters")
    fields = file_fields(cls)
    unknown = [k for k in raw if k not in fields and not (k == "source" and at.path)]
    if unknown:
        names = [*fields, "source"] if at.path else list(fields)
        raise _unknown(unknown[0], raw[unknown[0]], names, at)
    if at.path:
        source = raw.get("source")
        if source is None and require_source:
            raise ParameterError(f"{at.table()}: missing key 'source' (where the values come "
                                 "from: the study, a datasheet, a public source by name, or "
                                 "'assumed: why')")
        if source is not None:
            if not isinstance(source, str) or not source.strip():
                raise ParameterError(f"{at.key('source')} = {_show(source)}: expected a "
                                     "non-empty string naming where the values come from")
            sources[".".join(map(str, at.path))] = source
    kwargs: dict[str, Any] = {}
    for name, fld in fields.items():
        if name not in raw:
            if fld.required:
                raise ParameterError(_describe_missing(name, fld, at))
            continue
        value, kind = raw[name], _table_kind(fld.hint)
        if kind == "table":
            if not isinstance(value, dict):
                raise ParameterError(f"{at.key(name)} = {_show(value)}: expected a table "
                                     f"{_path_text((*at.path, name))}, got {_kind(value)}")
            value = _build(_optional_table(fld.hint), value, at.child(name), require_source,
                           sources)
        elif kind == "array":
            if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
                raise ParameterError(f"{at.key(name)} = {_show(value)}: expected an array of "
                                     f"tables [[{'.'.join(map(str, (*at.path, name)))}]]")
            item = get_args(fld.hint)[0]
            value = tuple(_build(item, v, at.child(name, i), require_source, sources)
                          for i, v in enumerate(value))
        elif kind == "named":
            item = get_args(fld.hint)[1]
            if not isinstance(value, dict) or not all(isinstance(v, dict)
                                                      for v in value.values()):
                raise ParameterError(f"{at.key(name)} = {_show(value)}: expected tables "
                                     f"[{'.'.join(map(str, (*at.path, name)))}.NAME]")
            value = {k: _build(item, v, at.child(name, k), require_source, sources)
                     for k, v in value.items()}
        kwargs[name] = value
    return construct(cls, at, **kwargs)


def construct(cls: type[T], at: Location, /, **kwargs: Any) -> T:
    """``cls(**kwargs)`` whose checks name ``at`` (e.g. a Location labelled after the object
    being checked) instead of the class name."""
    token = _BUILDING.set((cls, at))
    try:
        return cls(**kwargs)
    finally:
        _BUILDING.reset(token)


# ----------------------------------------------------------------------------- overrides

_BARE_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_.+-]*")


def parse_overrides(items: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Parse ``--set`` items ``KIND.TABLE.KEY=VALUE`` into ``{kind: {"TABLE.KEY": value}}``.

    Parameters
    ----------
    items : sequence of str
        e.g. ``"hydraulics.fluid.bulk_modulus_Pa=1.2e9"``,
        ``"scenario.load_pulses.0.hitch_N=-15000"``; KIND is one of :data:`FILE_KINDS`, an
        integer segment indexes an array of tables,
        VALUE is a TOML value (``1.2e9``, ``2``, ``true``, ``"text"``, ``[1, 2]``; a bare
        word is a string).

    Returns
    -------
    dict
        Every kind of :data:`FILE_KINDS` mapped to its ``{dotted key: value}`` (possibly
        empty). Whether a key exists is checked when the file is loaded. A malformed item,
        an unknown kind or a key given twice is a ParameterError naming the item.
    """
    out: dict[str, dict[str, Any]] = {kind: {} for kind in FILE_KINDS}
    for item in items:
        key, sep, text = item.partition("=")
        key, text = key.strip(), text.strip()
        if not sep or not text or "\n" in item:
            raise ParameterError(f"--set {item!r}: expected KIND.TABLE.KEY=VALUE, e.g. "
                                 "hydraulics.fluid.bulk_modulus_Pa=1.2e9")
        kind, dotted = split_override_key(key, f"--set {item!r}")
        if dotted in out[kind]:
            raise ParameterError(f"--set {item!r}: {kind}.{dotted} is given twice")
        out[kind][dotted] = _parse_value(text, item)
    return out


def split_override_key(key: str, where: str) -> tuple[str, str]:
    """(kind, dotted key) of an override key ``KIND.TABLE.KEY``; an unknown kind, no key or
    an empty one between dots is a ParameterError starting with ``where`` and naming the
    nearest valid form. Whether the key exists is checked when its file is loaded."""
    kind, _, dotted = key.partition(".")
    if kind not in FILE_KINDS:
        raise ParameterError(f"{where}: unknown file kind {kind!r}{_kind_hint(kind, dotted)} "
                             f"(allowed: {', '.join(FILE_KINDS)})")
    if not dotted.strip():
        raise ParameterError(f"{where}: names no key; expected {kind}.TABLE.KEY (`trackmj "
                             f"keys {kind}` lists them)")
    if "" in dotted.split("."):
        joined = ".".join(p for p in dotted.split(".") if p)
        raise ParameterError(f"{where}: an empty key between two dots; did you mean "
                             f"{kind}.{joined}?")
    return kind, dotted


def _kind_hint(kind: str, dotted: str) -> str:
    """'; did you mean ...?' for an unknown file kind: the dot after a kind left out
    ('hydraulicsfluid.x' -> hydraulics.fluid.x), else the nearest kind."""
    glued = next((k for k in FILE_KINDS if kind.startswith(k)), None)
    rest = "" if glued is None else kind[len(glued):].lstrip("_")
    if glued is not None and len(rest) >= 3:     # not a plural: 'models' is 'model'
        return f"; did you mean {glued}.{rest}{'.' + dotted if dotted else ''}?"
    return did_you_mean(kind, FILE_KINDS)


def _parse_value(text: str, item: str) -> Any:
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        if _BARE_WORD.fullmatch(text):
            return text
        raise ParameterError(f"--set {item!r}: cannot read the value {text!r}; write a TOML "
                             'value (1.2e9, 2, true, "text", [1, 2])') from None


def apply_overrides(cls: type, data: dict[str, Any], overrides: Mapping[str, Any],
                    kind: str | None) -> list[tuple[tuple[str | int, ...], str, Any]]:
    """Set each ``{dotted key: value}`` of ``overrides`` in raw ``data`` (in place) after
    checking the key path against the schema of ``cls`` and the indices against ``data``.

    Returns ``(key path, option text, value)`` per override; a path that does not exist is
    a ParameterError naming the option.
    """
    applied: list[tuple[tuple[str | int, ...], str, Any]] = []
    for dotted, value in overrides.items():
        prefix = f"{kind}." if kind else ""
        option = f"--set {prefix}{dotted}"
        parts = dotted.split(".")
        node: Any = data
        hint: Any = cls
        path: list[str | int] = []
        for i, part in enumerate(parts):
            if _table_kind(hint) == "table":
                _check_key(option, prefix, cls, _optional_table(hint), path, parts[i:])
            step, hint = _override_step(option, node, hint, path, part)
            path.append(step)
            if i == len(parts) - 1:
                node[step] = value
            else:
                if isinstance(node, dict) and step not in node:
                    node[step] = {} if _table_kind(hint) in ("table", "named") else []
                node = node[step]
        applied.append((tuple(path), option, value))
    return applied


def _check_key(option: str, prefix: str, root: type, table: type, path: list[str | int],
               rest: Sequence[str]) -> None:
    """ParameterError unless ``rest[0]`` is a key of ``table`` (at ``path`` in the file of
    ``root``; ``prefix`` the kind's, e.g. 'hydraulics.'), naming the nearest key: a table
    name with its key glued on (a dot left out: 'fluidbulk_modulus_Pa'), the same key in
    another table ('supply.bulk_modulus_Pa' -> fluid.bulk_modulus_Pa), else the closest
    name."""
    fields = file_fields(table)
    part = rest[0]
    if part in fields:
        return
    glued = [f"{name}.{part[len(name):].lstrip('_')}" for name, fld in fields.items()
             if part.startswith(name) and _table_kind(fld.hint) == "table"
             and part[len(name):].lstrip("_") in file_fields(_optional_table(fld.hint))]
    tail = ".".join(rest)
    elsewhere = [key.replace("[]", ".N") for key in (k.key for k in describe_schema(root))
                 if key == tail or key.endswith("." + tail)]
    here = _path_text(path) or "the file"
    if glued or elsewhere:
        rows = [".".join([*map(str, path), g, *rest[1:]]) for g in glued] or elsewhere[:2]
        hint = f"; did you mean {' or '.join(prefix + row for row in rows)}?"
    else:
        hint = did_you_mean(part, list(fields))
    raise ParameterError(f"{option}: {here} has no key {part!r}{hint} "
                         f"(allowed: {', '.join(fields)})")


def _override_step(option: str, node: Any, hint: Any, path: list[str | int],
                   part: str) -> tuple[str | int, Any]:
    """One segment of an override path: (key or index, the type found there)."""
    kind = _table_kind(hint) if path else "table"
    origin, args = get_origin(hint), get_args(hint)
    here = _path_text(path) or "the file"
    if kind in ("table", "named") and not isinstance(node, dict):
        raise ParameterError(f"{option}: the file's {here} is {_kind(node)}, not a table")
    if kind == "table":
        return part, file_fields(_optional_table(hint))[part].hint   # _check_key: it exists
    if kind == "named":
        if part not in node:
            raise ParameterError(f"{option}: the file has no table {_path_text((*path, part))}"
                                 f"{did_you_mean(part, list(node))} (has: "
                                 f"{', '.join(node) or 'none'})")
        return part, args[1]
    if kind == "array" or origin is tuple:
        if not isinstance(node, list):
            raise ParameterError(f"{option}: the file's {here} is {_kind(node)}, not an array")
        variable = kind == "array" or args[-1] is Ellipsis
        size = len(node) if variable else min(len(node), len(args))
        if not part.isdigit():
            indices = ("no entries" if size == 0 else "index 0" if size == 1
                       else f"indices 0-{size - 1}")
            raise ParameterError(f"{option}: {part!r} is not an index; {here} is an array "
                                 f"({indices})")
        if int(part) >= size:
            raise ParameterError(f"{option}: index {part!r} is out of range; {here} has "
                                 f"{size} entries")
        return int(part), args[0] if variable else args[int(part)]
    raise ParameterError(f"{option}: {'.'.join(map(str, path))} is a value, not a table")


# ----------------------------------------------------------------------------- schema

@dataclass(frozen=True)
class KeySpec:
    """One key of a file schema: dotted ``key`` (``[]`` marks an array of tables, ``<name>``
    a table of named tables), expected type, unit, range, default (None if required), doc."""

    key: str
    type: str
    unit: str
    range: str
    default: str | None
    doc: str

    def __str__(self) -> str:
        bits = [self.type] + [b for b in (self.unit, self.range) if b and b != "1"]
        opt = "" if self.default is None else f", optional (default {self.default})"
        return f"{self.key}: {', '.join(bits)}{opt}" + (f" - {self.doc}" if self.doc else "")


def _default(f: dataclasses.Field) -> Any:
    """The default value of dataclass field ``f`` (its ``default`` or a new value of its
    ``default_factory``); TypeError if it has neither (a required field)."""
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    raise TypeError(f"the field {f.name} has no default")


def describe_schema(cls: type, prefix: str = "") -> list[KeySpec]:
    """Every key of the file read into ``cls``, with type, unit, range, default and doc
    (``source`` keys not listed: every table of a parameter file has one)."""
    rows: list[KeySpec] = []
    defaults = {f.name: f for f in dataclasses.fields(cls)}
    for name, fld in file_fields(cls).items():
        key, kind = prefix + name, _table_kind(fld.hint)
        if kind == "table":
            rows += describe_schema(_optional_table(fld.hint), key + ".")
        elif kind == "array":
            rows += describe_schema(get_args(fld.hint)[0], key + "[].")
        elif kind == "named":
            rows += describe_schema(get_args(fld.hint)[1], key + ".<name>.")
        else:
            default = None if fld.required else repr(_default(defaults[name]))
            choices = f"one of {list(fld.spec.choices)}" if fld.spec.choices else ""
            expected = _expected(fld.hint)
            if fld.spec.allow_empty:
                expected = expected.replace("a non-empty array", "an array (may be empty)")
            rows.append(KeySpec(key, expected, fld.spec.unit or "",
                                fld.spec.range_text() or choices, default, fld.spec.doc))
    return rows


def parameter_classes(root: type) -> list[type]:
    """``root`` and every parameter class reachable through its fields (for tests)."""
    seen: list[type] = []

    def walk(cls: type) -> None:
        if cls in seen:
            return
        seen.append(cls)
        for fld in file_fields(cls).values():
            kind = _table_kind(fld.hint)
            if kind == "table":
                walk(_optional_table(fld.hint))
            elif kind == "array":
                walk(get_args(fld.hint)[0])
            elif kind == "named":
                walk(get_args(fld.hint)[1])

    walk(root)
    return seen


def numeric_fields(cls: type) -> list[str]:
    """Names of the fields of ``cls`` holding numbers (which must carry a unit)."""
    def numeric(hint: Any) -> bool:
        origin, args = get_origin(hint), get_args(hint)
        if origin in (typing.Union, types.UnionType):
            return any(numeric(a) for a in args if a is not type(None))
        if origin is tuple:
            return any(numeric(a) for a in args if a is not Ellipsis)
        return hint in (int, float)

    return [n for n, f in file_fields(cls).items() if numeric(f.hint)]
