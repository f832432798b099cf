"""Measured time series: rig logs and input traces read from CSV or Parquet files, their
column headers parsed by pint and converted to SI.

A header is ``name [unit]`` or ``name (unit)`` (``p_head [psi]``, ``t (ms)``) or
``name_unit``, the unit a suffix after an underscore (``tension_kN``, ``p_head_MPa``,
``stroke_in``, ``t_ms``); a name is matched as written, then in lower case (``Time``,
``Tension``) unless it is one letter (``T``, ``U``: a temperature, a voltage). The
name says which **quantity** the column holds; a rig log may hold the run's own columns
(:data:`trackmj.ports.COLUMN_UNITS`; with ``--channels all`` the run's further ones too):

=======================  ====================================  =====  ====================
column (SI name)         quantity                              SI     also accepted, e.g.
=======================  ====================================  =====  ====================
``t_s`` (or ``time``)    time (required)                       s      ms, min
``tension_N``            F_ten, tensioner force on the idler   N      kN, lbf
``tension_ref_N``        the reference F_ref                   N      kN, lbf
``p_head_Pa``            mean head-chamber pressure, gauge     Pa     kPa, MPa, bar, psi
``p_rod_Pa``             mean rod-chamber pressure, gauge      Pa     kPa, MPa, bar, psi
``p_supply_Pa``          supply pressure, gauge                Pa     kPa, MPa, bar, psi
``stroke_m``             stroke, > 0 outward                   m      mm, in, ft
``stroke_velocity_m_s``  stroke velocity                       m/s    mm/s, in/s
``q_supply_m3_s``        flow out of the supply                m³/s   L/min, gal/min
``valve_mode``           valve mode −1/0/+1                    1      -
``u``                    valve opening                         1      -, %
``e_supply_J``           energy drawn from the supply          J      kJ
``p_work_J``             piston work ∫Σp·A·v dt                J      kJ
``mech_work_J``          work into the mechanics ∫F·v dt       J      kJ
``chassis_acc_z_m_s2``   vertical chassis acceleration         m/s²   g0, ft/s^2
``closure_error_m``      track loop closure gap                m      mm
=======================  ====================================  =====  ====================

Units are pint's (:func:`unit_registry`): any unit pint knows with the quantity's dimension
is converted to SI and the column renamed to its SI name (``p_head [psi]`` -> ``p_head_Pa``
× 6894.757). pint's spellings: ``psi`` is pound-force per square inch, ``lbf`` pound-force,
``in`` inch, ``gal`` the US gallon, ``min`` minute, ``g0`` standard gravity (``g`` is the
gram). Pressures are gauge, as the run's own columns, and converted by a factor alone (no
offsets; psig and barg read as psi and bar, psia and bara are refused). In a suffix,
underscores between unit tokens divide and a digit after a token is its power, as in the
run's column names (``m_s2`` = m/s^2, ``L_min`` = L/min, ``m3_s`` = m^3/s, ``mm_s`` =
mm/s; :func:`pint_spelling`, tried when pint does not read the suffix as written; ``-`` is
read as dimensionless, :data:`UNIT_ALIASES`). The suffix starts at the rightmost
underscore whose left part names a quantity and whose unit fits
(``stroke_velocity_mm_s``: stroke_velocity in mm/s); a header in SI of something else
(``p_head_L_Pa`` when the run does not record it) names no quantity.

A CSV file is read as UTF-8, else as Windows-1252 (a DAQ on a European Windows PC writes
``Öltemp [°C]`` so), else Latin-1; its separator is the one of ``,``, ``;`` and tab its
header line holds most of, and with ``;`` or tab a decimal comma is read when the first data
line has one (``0,5;12,3``). Headers are taken without the spaces around them (``t_s,
p_head [bar]``). In Parquet a column named without a unit takes the ``unit`` of its field's
metadata, as trackmj writes its own results.

An empty cell (or ``NaN``) of a quantity's column is a **missing sample**: the column is
interpolated across it from its neighbours (a channel logged at a lower rate than the time
column, or a dropped sample), if the gap between the samples around it is at most
:data:`MAX_GAP_S`; :attr:`Trace.missing` counts them per column. Time has none.

Refused, each with one line naming the file, the column and what is expected (a
:class:`~trackmj.validator.ParameterError`, exit 2 on the command line): a quantity's
column whose unit pint does not know, whose dimension does not fit (``tension [psi]``,
``p_head_N``, ``tension_kNm`` — pint reads kNm as kilo-number-metre), or that names no
unit (``tension``); a quantity's column holding text; no time column, time not strictly
increasing or missing, an infinite value, a gap of missing samples longer than
:data:`MAX_GAP_S` and, for a run, time not covering the run [1 ms, duration] (a log
timed from another origin is told to subtract its start). A header naming no quantity
(``temperature [degC]``, ``comment``, ``engine_rpm``) is **ignored and listed**
(:attr:`Trace.ignored`, :attr:`MeasuredLog.ignored`); it may hold text.

Signals are resampled to the run's 1 ms grid by linear interpolation (:func:`resample`; a
log sampled faster than 1 kHz is interpolated, not averaged). Input signals of a scenario
(:func:`input_signal`) name their column freely (``F_ref [kN]``, ``speed_mm_s``); their unit
must have the input's dimension.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from trackmj.ports import COLUMN_UNITS, COUPLING_STEP_S
from trackmj.validator import ParameterError

if TYPE_CHECKING:
    import pint


def suffix_of(unit: str) -> str:
    """The column-name suffix of an SI unit in pint's spelling (``m^3/s`` -> ``m3_s``,
    ``N·m`` -> ``N_m``: a run's torque column, named like the files' torque keys)."""
    return unit.replace("^", "").replace("/", "_").replace("·", "_")


TIME = "t_s"
TIME_NAMES = ("t", "time")
"""Base names of the time column (``t_s``, ``t [ms]``, ``time [s]``, ``time_ms``)."""
SYMBOLS = {"F_ten": "tension", "F_ref": "tension_ref"}
"""The study's symbols a header may use for a quantity's base name (``F_ten [kN]``)."""
DIMENSIONLESS = tuple(name for name, unit in COLUMN_UNITS.items() if unit == "1")
"""Columns without a unit suffix (the run's valve mode −1/0/+1 and opening u [-])."""
SI_SUFFIXES: dict[str, str] = {suffix_of(unit): unit for unit in COLUMN_UNITS.values()
                               if unit != "1"}
"""SI suffix of a column name -> its SI unit in pint's spelling (``m3_s`` -> ``m^3/s``)."""
UNIT_ALIASES = {"-": "dimensionless", "psig": "psi", "barg": "bar", "gpm": "gal/min"}
"""Units written in logs that pint's parser refuses or does not know, in pint's spelling:
``psig``/``barg`` are gauge pressures (the run's pressures are gauge), ``gpm`` US gallons
per minute."""
ABSOLUTE_PRESSURES = ("psia", "bara", "kPaa", "MPaa")
"""Absolute-pressure spellings: refused, since a log's pressures are compared with the run's
gauge pressures and the ambient pressure at the rig is not known to trackmj."""
UNIT_EXAMPLES: dict[str, tuple[str, str]] = {
    "s": ("time", "s, ms, min"), "N": ("force", "N, kN, lbf"),
    "Pa": ("pressure", "Pa, kPa, MPa, bar, psi"), "m": ("length", "m, mm, in, ft"),
    "m/s": ("velocity", "m/s, mm/s, in/s"), "m^3/s": ("volume flow", "m^3/s, L/min, gal/min"),
    "m/s^2": ("acceleration", "m/s^2, g0"), "J": ("energy", "J, kJ"),
    "1": ("dimensionless number", "1, -, %")}
"""SI unit -> (what it measures, units accepted for it, e.g.), for messages."""
OTHER_DIMENSIONS = {"kg": "mass", "K": "temperature", "m^2": "area", "m^3": "volume",
                    "Hz": "frequency", "W": "power", "N/m": "stiffness"}
"""Further SI units whose dimension a message names in words (a unit of the wrong kind)."""
MAX_GAP_S = 0.05
"""Longest span [s] between two samples of a column that missing samples between them may
leave (a channel logged at 20 Hz or faster is bridged; assumed: the tensioner's dynamics
of interest, the valves' 20-50 ms and the 8-12 Hz body mode, are not resolved across a
longer gap, so a longer one is refused rather than drawn as a straight line)."""
ENCODINGS = ("utf-8-sig", "cp1252", "latin-1")
"""A CSV file's encodings, tried in turn (Latin-1 reads any byte)."""
SEPARATORS = (",", ";", "\t")
"""A CSV file's separators: the one its header line holds most of (ties: the first)."""
COVER_TOLERANCE_S = 0.5 * COUPLING_STEP_S
"""A trace covers the run if it starts by the end of the first step (a run's own ``t_s``
starts there) and ends by the duration, within half a step [s]; before its first sample
it holds its first value."""

_BRACKET = re.compile(r"^\s*(?P<name>[^\[\]()]+?)\s*(?:\[(?P<unit>[^\[\]]+)\]|"
                      r"\((?P<paren>[^()]+)\))\s*$")
"""``name [unit]`` or ``name (unit)``."""
_POWER = re.compile(r"(?<=[A-Za-z])(\d+)$")


# ----------------------------------------------------------------------------- units

@functools.cache
def unit_registry() -> pint.UnitRegistry:
    """pint's unit registry, built once per process (~0.3 s)."""
    # local: pint takes ~0.4 s to import; every scenario load imports this module, few
    # read a file with units beyond SI
    import pint

    return pint.UnitRegistry()


def pint_spelling(unit: str) -> str:
    """A unit written as a column-name suffix in pint's spelling: underscores divide, a
    digit after a token is its power (``m_s2`` -> ``m/s^2``, ``m3_s`` -> ``m^3/s``,
    ``L_min`` -> ``L/min``)."""
    return "/".join(_POWER.sub(r"^\1", token) for token in unit.split("_"))


def _parse(unit: str) -> pint.Unit | None:
    """pint's unit for ``unit`` as written (:data:`UNIT_ALIASES` first), else in the
    suffix spelling (:func:`pint_spelling`); None if neither parses."""
    registry = unit_registry()
    for spelling in dict.fromkeys((UNIT_ALIASES.get(unit, unit), pint_spelling(unit))):
        try:
            return registry.parse_units(spelling)
        # pint's parser raises many kinds: UndefinedUnitError, AssertionError ("-"),
        # ValueError (a factor, "2*N"), the tokenizer's errors
        except Exception:
            continue
    return None


def _article(words: str) -> str:
    return f"{'an' if words[0] in 'aeiou' else 'a'} {words}"


@functools.cache
def _dimension_words() -> dict[Any, str]:
    """pint dimensionality -> what it measures (the units of :data:`UNIT_EXAMPLES` and
    :data:`OTHER_DIMENSIONS`)."""
    registry = unit_registry()
    named = {unit: words for unit, (words, _) in UNIT_EXAMPLES.items()} | OTHER_DIMENSIONS
    return {registry.parse_units(unit).dimensionality: words for unit, words in named.items()}


def si_factor(unit: str, si_unit: str) -> float:
    """Factor taking a value in ``unit`` (as written in a header) to ``si_unit`` (pint's
    spelling, e.g. ``m^3/s``); ValueError saying why not (a unit pint does not know, or of
    another dimension)."""
    if unit in (si_unit, suffix_of(si_unit)):
        return 1.0
    if unit in ABSOLUTE_PRESSURES:
        raise ValueError(f"unit {unit!r} is an absolute pressure; the run's pressures are "
                         "gauge: log them as gauge (psig, barg, or psi, bar, Pa meaning "
                         "gauge)")
    parsed = _parse(unit)
    if parsed is None:
        raise ValueError(f"unit {unit!r} is not a unit pint knows")
    target = unit_registry().parse_units(si_unit)
    if parsed.dimensionality != target.dimensionality:
        words = _dimension_words().get(parsed.dimensionality)
        kind = str(parsed.dimensionality) if words is None else _article(words)
        wanted = UNIT_EXAMPLES[si_unit][0] if si_unit in UNIT_EXAMPLES else si_unit
        raise ValueError(f"unit {unit!r} ({parsed}, {kind}) is not {_article(wanted)}")
    return float(unit_registry().Quantity(1.0, parsed).to(target).magnitude)


def expects(name: str, si_unit: str) -> str:
    """What a column of ``name`` (a quantity's SI name, or an input) needs: "tension_N
    needs a unit of force (N, kN, lbf, ...)"."""
    words, examples = UNIT_EXAMPLES.get(si_unit, (si_unit, si_unit))
    if si_unit == "1":
        return f"{name} is dimensionless (no unit, or {examples})"
    return f"{name} needs a unit of {words} ({examples}, ...)"


# ----------------------------------------------------------------------------- headers

@dataclass(frozen=True)
class Quantity:
    """A quantity a log may hold: its SI column ``name`` (``p_head_Pa``) and SI ``unit`` in
    pint's spelling (``Pa``; ``1``: dimensionless)."""

    name: str
    unit: str

    def convert(self, unit: str | None) -> float:
        """Factor to SI of this quantity's column in ``unit`` as written (None: no unit);
        ValueError saying why not and what it needs."""
        if unit is None and self.unit != "1":
            base = self.name.removesuffix("_" + suffix_of(self.unit))
            example = UNIT_EXAMPLES.get(self.unit, ("", self.unit))[1].split(", ")[1:2]
            raise ValueError(f"names no unit (write e.g. '{self.name}' or "
                             f"'{base} [{example[0] if example else self.unit}]'); "
                             f"{expects(self.name, self.unit)}")
        try:
            return 1.0 if unit is None else si_factor(unit, self.unit)
        except ValueError as exc:
            raise ValueError(f"{exc}; {expects(self.name, self.unit)}") from None


def split_si(name: str) -> tuple[str, Quantity] | None:
    """(base, quantity) of a column name in SI: ``p_head_Pa`` -> ("p_head", p_head_Pa in
    Pa), ``valve_mode`` -> ("valve_mode", dimensionless); None without an SI suffix of
    :data:`SI_SUFFIXES`."""
    if COLUMN_UNITS.get(name) == "1":
        return name, Quantity(name, "1")
    for suffix in sorted(SI_SUFFIXES, key=len, reverse=True):
        if name.endswith("_" + suffix) and len(name) > len(suffix) + 1:
            return name[: -len(suffix) - 1], Quantity(name, SI_SUFFIXES[suffix])
    return None


def log_quantities(names: Iterable[str] = ()) -> dict[str, Quantity]:
    """Base name -> quantity of a log: the run's columns (:data:`COLUMN_UNITS`), the
    further SI column ``names`` given (a run's ``--channels all`` columns), the study's
    symbols (:data:`SYMBOLS`) and the time's names (:data:`TIME_NAMES`)."""
    out = {}
    for name in (*COLUMN_UNITS, *names):
        split = split_si(name)
        if split is not None:
            out[split[0]] = split[1]
    out |= {alias: out[base] for alias, base in SYMBOLS.items() if base in out}
    return out | {base: Quantity(TIME, "s") for base in TIME_NAMES}


def _splits(header: str) -> list[tuple[str, str]]:
    """Every (base, unit) of a header split at one underscore, from the right
    (``p_head_MPa``: (p_head, MPa), (p, head_MPa))."""
    cuts = [i for i, c in enumerate(header) if c == "_" and 0 < i < len(header) - 1]
    return [(header[:i], header[i + 1:]) for i in reversed(cuts)]


def _lookup(quantities: Mapping[str, Quantity], base: str) -> Quantity | None:
    """The quantity a header's base name names: as written, else in lower case when it is
    longer than one letter (``Time``, ``Tension``; ``T`` and ``U`` stay themselves, often
    a temperature and a voltage, not the time and the opening)."""
    if base in quantities:
        return quantities[base]
    return quantities.get(base.lower()) if len(base) > 1 else None


def si_name(header: str, quantities: Mapping[str, Quantity] | None = None
            ) -> tuple[str, float] | None:
    """(SI column name, factor to SI) of a log's column header; None if it names no
    quantity (the column is ignored); ValueError saying why for a quantity's column whose
    unit pint does not know, has another dimension or is missing.

    ``tension_kN`` -> ("tension_N", 1e3); ``p_head [psi]`` -> ("p_head_Pa", 6894.757...);
    ``stroke_velocity_mm_s`` -> ("stroke_velocity_m_s", 1e-3); ``valve_mode`` ->
    ("valve_mode", 1.0); ``temperature [degC]``, ``engine_rpm`` -> None. A suffix is taken
    at the rightmost underscore whose left part names a quantity and whose unit fits; a
    header in SI of something else (``p_head_L_Pa`` when that is no quantity) is ignored.

    Parameters
    ----------
    header : str
        The header as written.
    quantities : mapping, optional
        Base name -> quantity (default :func:`log_quantities`).
    """
    quantities = log_quantities() if quantities is None else quantities
    match = _BRACKET.match(header)
    if match:
        quantity = _lookup(quantities, match["name"].strip().replace(" ", "_"))
        unit = match["unit"] if match["unit"] is not None else match["paren"]
        return None if quantity is None else (quantity.name, quantity.convert(unit.strip()))
    bare = _lookup(quantities, header)
    if bare is not None:
        return bare.name, bare.convert(None)
    errors = []
    for base, unit in _splits(header):
        quantity = _lookup(quantities, base)
        if quantity is not None:
            try:
                return quantity.name, quantity.convert(unit)
            except ValueError as exc:
                errors.append(exc)
    own = split_si(header)
    if not errors or (own is not None and own[0] not in quantities):
        return None
    raise errors[0]


# ----------------------------------------------------------------------------- files

@dataclass(frozen=True)
class Trace:
    """A file's time series in SI: ``t_s`` [s], shape (n,), strictly increasing;
    ``columns``: SI name -> values, shape (n,); ``headers``: SI name -> the header as
    written, for every column naming a quantity (time included); ``ignored``: the headers
    as written that name no quantity; ``file``: the file's name; ``sha256``: the hex
    SHA-256 of the file's bytes; ``missing``: SI name -> how many of the column's samples
    are missing (NaN in ``columns``; bridged by :meth:`samples`), for the columns with
    any."""

    file: str
    t_s: np.ndarray
    columns: Mapping[str, np.ndarray]
    headers: Mapping[str, str]
    ignored: tuple[str, ...]
    sha256: str
    missing: Mapping[str, int] = field(default_factory=dict)

    def where(self, name: str) -> str:
        """``file column 'header'`` for a message."""
        return f"{self.file} column {self.headers.get(name, name)!r}"

    def require(self, names: Sequence[str]) -> None:
        """ParameterError naming the file if a column is missing."""
        missing = [n for n in names if n not in self.headers]
        if missing:
            hint = ("" if missing[0] in DIMENSIONLESS else "; name it in SI (tension_N) or "
                    "with its unit (tension_kN, p_head [psi])")
            ignored = f"; ignored: {', '.join(self.ignored)}" if self.ignored else ""
            raise ParameterError(f"{self.file}: no column {missing[0]!r} (has: "
                                 f"{', '.join(self.headers.values())}{ignored}){hint}")

    def check_covers(self, duration_s: float, what: str = "the run") -> None:
        """ParameterError naming the file and time column unless t spans [0, duration_s]."""
        t0, t1 = float(self.t_s[0]), float(self.t_s[-1])
        if t0 > COUPLING_STEP_S + COVER_TOLERANCE_S:
            raise ParameterError(
                f"{self.where(TIME)}: starts at {t0:g} s; its time counts from the start of "
                f"{what} at 0 s, which it must cover from {COUPLING_STEP_S:g} s on (a log "
                f"timed from another origin: subtract its first time, {t0:g} s)")
        if t1 < duration_s - COVER_TOLERANCE_S:
            raise ParameterError(f"{self.where(TIME)}: spans {t0:g} .. {t1:g} s, too short "
                                 f"to cover {what} ({COUPLING_STEP_S:g} .. {duration_s:g} s)")

    def samples(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(t [s], values) of column ``name`` where it has samples (its missing ones left
        out), shape (m,) each."""
        values = self.columns[name]
        present = ~np.isnan(values)
        return self.t_s[present], values[present]

    def resample(self, name: str, t_s: np.ndarray) -> np.ndarray:
        """Column ``name`` at times ``t_s`` [s] by linear interpolation of its samples
        (across missing ones; held beyond the ends), shape of ``t_s``."""
        return np.interp(np.asarray(t_s, dtype=float), *self.samples(name))


def _decoded(data: bytes) -> str:
    """A CSV file's text in the first of :data:`ENCODINGS` that reads it."""
    for encoding in ENCODINGS[:-1]:
        try:
            return data.decode(encoding)
        except UnicodeDecodeError:
            continue
    return data.decode(ENCODINGS[-1])


def _csv_options(text: str) -> tuple[pacsv.ParseOptions, pacsv.ConvertOptions]:
    """pyarrow's options for a CSV text: the separator of :data:`SEPARATORS` its first
    line holds most of; with ``;`` or tab, a decimal comma if the second line has a digit,
    a comma and a digit in a row."""
    lines = text.splitlines()
    header = lines[0] if lines else ""
    separator = max(SEPARATORS, key=header.count)
    decimal = "," if separator != "," and len(lines) > 1 and re.search(
        r"\d,\d", lines[1]) else "."
    return (pacsv.ParseOptions(delimiter=separator),
            pacsv.ConvertOptions(decimal_point=decimal))


def _with_field_units(table: pa.Table) -> pa.Table:
    """A Parquet table whose columns named without a unit (``t``, ``tension``) are renamed
    ``name [unit]`` by their field's ``unit`` metadata (as trackmj writes its results)."""
    names = []
    for f in table.schema:
        unit = (f.metadata or {}).get(b"unit", b"").decode().strip()
        try:
            si_name(f.name)
            names.append(f.name)
        except ValueError:
            names.append(f"{f.name} [{unit}]" if unit else f.name)
    return table.rename_columns(names)


def _read_table(path: Path) -> tuple[pa.Table, str]:
    """The file's table (pyarrow: CSV, or Parquet for ``.parquet``/``.pq``; see the module
    docstring for encodings, separators and units in metadata), its headers stripped of
    spaces, and the hex SHA-256 of the bytes it was read from; ParameterError naming the
    file if it is none."""
    if not path.is_file():
        raise ParameterError(f"measured data file not found: {path}")
    data = path.read_bytes()
    parquet = path.suffix.lower() in (".parquet", ".pq")
    try:
        if parquet:
            table = _with_field_units(pq.read_table(pa.BufferReader(data)))
        else:
            text = _decoded(data)
            parse, convert = _csv_options(text)
            table = pacsv.read_csv(pa.BufferReader(text.encode()), parse_options=parse,
                                   convert_options=convert)
    except (OSError, pa.ArrowInvalid) as exc:
        raise ParameterError(f"{path.name}: cannot read as {'Parquet' if parquet else 'CSV'}"
                             f": {str(exc).splitlines()[0]}") from None
    return (table.rename_columns([name.strip() for name in table.column_names]),
            hashlib.sha256(data).hexdigest())


def _numbers(file: str, header: str, column: pa.ChunkedArray) -> np.ndarray:
    """A column's values as floats (nulls -> NaN); ParameterError naming the file and
    column if it holds other than numbers."""
    if pa.types.is_null(column.type):
        raise ParameterError(f"{file} column {header!r}: holds no values (every cell empty"
                             f"{'' if len(column) else '; the file has no data rows'})")
    if not (pa.types.is_floating(column.type) or pa.types.is_integer(column.type)):
        raise ParameterError(f"{file} column {header!r}: holds {column.type}, not numbers")
    return column.to_numpy(zero_copy_only=False).astype(float)


def _named(file: str, headers: Sequence[str], quantities: Mapping[str, Quantity]
           ) -> tuple[dict[str, tuple[str, float]], tuple[str, ...]]:
    """SI name -> (header, factor to SI) of the headers naming a quantity, and the headers
    naming none; ParameterError naming the file and column for a refused header
    (:func:`si_name`), two headers of one quantity or no time column."""
    named: dict[str, tuple[str, float]] = {}
    ignored = []
    for header in headers:
        try:
            found = si_name(header, quantities)
        except ValueError as exc:
            raise ParameterError(f"{file} column {header!r}: {exc}") from None
        if found is None:
            ignored.append(header)
        elif found[0] in named:
            raise ParameterError(f"{file}: columns {named[found[0]][0]!r} and {header!r} are "
                                 f"both {found[0]}")
        else:
            named[found[0]] = (header, found[1])
    if TIME not in named:
        raise ParameterError(f"{file}: no time column 't_s' (or 't [s]', 't [ms]', "
                             f"'time_s'); columns: {', '.join(headers)}")
    return named, tuple(ignored)


def _longest_gap(t_s: np.ndarray, present: np.ndarray) -> tuple[float, float]:
    """(from, to) [s] of the longest span that a column's missing samples leave without a
    sample: between the samples around them, or from the log's first time or to its last
    (``present``: which rows have a sample, shape of ``t_s``; at least one missing)."""
    rows = np.flatnonzero(present)
    if not len(rows):
        return float(t_s[0]), float(t_s[-1])
    spans = [(t_s[a], t_s[b]) for a, b in itertools.pairwise(rows) if b - a > 1]
    spans += [(t_s[0], t_s[rows[0]])] if rows[0] > 0 else []
    spans += [(t_s[rows[-1]], t_s[-1])] if rows[-1] < len(t_s) - 1 else []
    start, end = max(spans, key=lambda span: span[1] - span[0])
    return float(start), float(end)


def _checked(trace: Trace) -> Trace:
    """``trace`` after checking it has two or more rows, strictly increasing time with no
    cell missing, no infinite value and no gap of missing samples over :data:`MAX_GAP_S`
    (ParameterError naming the file and column), with its missing samples counted."""
    t = trace.t_s
    if len(t) < 2:
        raise ParameterError(f"{trace.where(TIME)}: {len(t)} row(s); a time series needs two "
                             "or more")
    missing = {}
    for name, data in ((TIME, t), *trace.columns.items()):
        bad = np.isinf(data) | (np.isnan(data) if name == TIME else False)
        if bad.any():
            i = int(np.argmax(bad))
            rule = ("a time in every row" if name == TIME
                    else "values must be finite numbers, or missing")
            raise ParameterError(f"{trace.where(name)}: data row {i + 1} is {data[i]:g} "
                                 f"({rule})")
        present = ~np.isnan(data)
        if not present.all():
            start, end = _longest_gap(t, present)
            if end - start > MAX_GAP_S or not present.any():
                raise ParameterError(
                    f"{trace.where(name)}: no sample from t = {start:g} to {end:g} s; "
                    f"missing samples are bridged over at most {MAX_GAP_S:g} s")
            missing[name] = int((~present).sum())
    steps = np.diff(t)
    if (steps <= 0.0).any():
        i = int(np.argmax(steps <= 0.0))
        raise ParameterError(f"{trace.where(TIME)}: time is not strictly increasing at row "
                             f"{i + 2} (t = {t[i + 1]:g} s after {t[i]:g} s)")
    return Trace(trace.file, t, trace.columns, trace.headers, trace.ignored, trace.sha256,
                 missing)


def read_trace(path: str | Path, columns: Sequence[str] | None = None,
               quantities: Mapping[str, Quantity] | None = None) -> Trace:
    """Read a measured time series (see the module docstring).

    Parameters
    ----------
    path : str or Path
        CSV (one header row) or Parquet (``.parquet``) file.
    columns : sequence of str, optional
        SI names of the columns wanted (each must be there); default every column whose
        header names a quantity.
    quantities : mapping, optional
        Base name -> quantity the headers may name (default :func:`log_quantities`).

    Returns
    -------
    Trace
        Time and the columns in SI, the headers as written, the ignored headers and the
        file's SHA-256. ParameterError naming the file and column for a missing file or
        column, a refused header, text in a quantity's column, time not strictly
        increasing, or a non-finite value.
    """
    path = Path(path)
    table, sha256 = _read_table(path)
    named, ignored = _named(path.name, table.column_names,
                            log_quantities() if quantities is None else quantities)
    headers = {name: header for name, (header, _) in named.items()}
    wanted = [n for n in named if n != TIME] if columns is None else list(columns)
    Trace(path.name, np.empty(0), {}, headers, ignored, sha256).require(wanted)
    raw = dict(zip(table.column_names, table.columns, strict=True))
    values = {name: _numbers(path.name, header, raw[header]) * factor
              for name, (header, factor) in named.items()}
    return _checked(Trace(path.name, values[TIME], {n: values[n] for n in wanted}, headers,
                          ignored, sha256))


def run_grid(duration_s: float) -> np.ndarray:
    """End of every 1 ms coupling step of a run of ``duration_s`` [s], shape (steps,): the
    run's ``t_s`` column."""
    return COUPLING_STEP_S * np.arange(1, round(duration_s / COUPLING_STEP_S) + 1)


def resample(trace: Trace, duration_s: float) -> dict[str, np.ndarray]:
    """The trace's columns on the run's 1 ms grid (:func:`run_grid`) after checking it
    covers the run; ``t_s`` included."""
    trace.check_covers(duration_s)
    t = run_grid(duration_s)
    return {TIME: t} | {name: trace.resample(name, t) for name in trace.columns}


def log_record(file: str, sha256: str, used: Mapping[str, str], ignored: Sequence[str],
               missing: Mapping[str, int]) -> dict[str, Any]:
    """A log's JSON-ready record: ``{"file", "sha256", "columns_used": {SI name: header as
    written}, "columns_ignored": [header, ...], "missing_samples": {header: count}}`` (the
    used columns' missing samples, bridged)."""
    return {"file": file, "sha256": sha256, "columns_used": dict(used),
            "columns_ignored": list(ignored),
            "missing_samples": {used[name]: n for name, n in missing.items() if name in used}}


@dataclass(frozen=True)
class MeasuredLog:
    """A measured log a run is compared with: ``file`` (its name), ``sha256`` (hex, of the
    file's bytes), ``columns`` (SI name -> values on the run's 1 ms grid, shape (steps,),
    ``t_s`` included), ``used`` (SI name -> the header as written, time excluded),
    ``ignored`` (the headers as written that name no quantity) and ``missing`` (SI name ->
    missing samples bridged, :attr:`Trace.missing`)."""

    file: str
    sha256: str
    columns: dict[str, np.ndarray]
    used: dict[str, str]
    ignored: tuple[str, ...]
    missing: Mapping[str, int] = field(default_factory=dict)

    def record(self) -> dict[str, Any]:
        """JSON-ready ``{"file", "sha256", "columns_used", "columns_ignored",
        "missing_samples"}`` (:func:`log_record`)."""
        return log_record(self.file, self.sha256, self.used, self.ignored, self.missing)


def load_measured(path: str | Path, duration_s: float,
                  run_columns: Sequence[str]) -> MeasuredLog:
    """A measured log to compare a run of ``duration_s`` [s] with: its columns naming a
    quantity, each one of ``run_columns`` (the run's own SI names, which are quantities
    too), on the run's 1 ms grid. ParameterError naming the file and column for a refused
    header, a column the run does not record, no column to compare, or a log that does not
    cover the run."""
    trace = read_trace(path, quantities=log_quantities(run_columns))
    for name in trace.columns:
        if name not in run_columns:
            raise ParameterError(f"{trace.where(name)}: {name} is not a column of the run "
                                 f"(compared by the run's own names: "
                                 f"{', '.join(c for c in run_columns if c != TIME)})")
    if not trace.columns:
        ignored = f" (ignored: {', '.join(trace.ignored)})" if trace.ignored else ""
        raise ParameterError(f"{trace.file}: no column to compare besides "
                             f"{trace.headers[TIME]!r}{ignored}; name columns as the run "
                             "does, with their unit (tension_N, p_head [psi])")
    return MeasuredLog(trace.file, trace.sha256, resample(trace, duration_s),
                       {name: trace.headers[name] for name in trace.columns}, trace.ignored,
                       trace.missing)


# ----------------------------------------------------------------------------- inputs

@dataclass(frozen=True)
class InputSignal:
    """A time-series input of a run read from a file: ``values`` on the 1 ms grid ``t_s``
    (k·h from 0; linear interpolation of the file), held between grid points and beyond
    the ends (zero-order, as a 1 kHz set-point is applied); ``file`` and ``column`` name
    where it came from (the header as written); ``rows``: the file's own samples, for
    messages that name one as written."""

    file: str
    column: str
    t_s: np.ndarray
    values: np.ndarray
    rows: FileSamples

    def __repr__(self) -> str:
        """Names the file, the column and the SHA-256 of the signal (a run's identity,
        :func:`trackmj.study.identity.identity`, changes with the file's content)."""
        digest = hashlib.sha256(self.t_s.tobytes() + self.values.tobytes()).hexdigest()
        return f"InputSignal({self.file!r}, {self.column!r}, sha256={digest})"

    def __call__(self, t_s: np.ndarray | float) -> np.ndarray:
        """The signal at ``t_s`` [s], shape of ``t_s``."""
        i = np.searchsorted(self.t_s, np.asarray(t_s, dtype=float), side="right") - 1
        return self.values[np.clip(i, 0, len(self.values) - 1)]

    def check_covers(self, duration_s: float, what: str) -> None:
        """ParameterError naming the file and column unless the file spans the run."""
        if self.t_s[-1] < duration_s - COVER_TOLERANCE_S:
            raise ParameterError(f"{self.file} column {self.column!r} ({what}): ends at "
                                 f"{self.t_s[-1]:g} s, too short to cover the run "
                                 f"(0 .. {duration_s:g} s)")

    def check_range(self, duration_s: float, low: float, high: float, unit: str,
                    what: str) -> None:
        """ParameterError naming the file, column and the first of the file's samples a
        run of ``duration_s`` [s] reads (those up to the first at or after its end) outside
        [``low``, ``high``] (SI, ``unit``): its data row, time and value as written."""
        rows = self.rows
        read = rows.t_s <= rows.t_s[min(int(np.searchsorted(rows.t_s, duration_s
                                                             - COVER_TOLERANCE_S)),
                                        len(rows.t_s) - 1)]
        si = rows.values * rows.factor
        bad = ((si < low) | (si > high)) & read
        if not bad.any():
            return
        k = int(np.argmax(bad))
        converted = "" if rows.factor == 1.0 else f" ({si[k]:.6g} {unit})"
        raise ParameterError(f"{self.file} column {self.column!r} ({what}): data row {k + 1} "
                             f"({rows.time_column} = {rows.t_s[k] / rows.time_factor:.15g}) "
                             f"holds {rows.values[k]:.15g}{converted}; it must stay in "
                             f"[{low:g}, {high:g}] {unit} over the run (0 .. {duration_s:g} s)")


@dataclass(frozen=True)
class FileSamples:
    """An input column's samples as the file holds them: ``t_s`` the times [s] (shape (n,),
    row order), ``values`` as written (the column's own unit; NaN: missing), ``factor`` to
    SI, and the time column's header as written and its factor to seconds."""

    t_s: np.ndarray
    values: np.ndarray
    factor: float
    time_column: str
    time_factor: float


def input_reading(header: str, si_unit: str) -> tuple[str, float]:
    """(base, factor to ``si_unit``) of an input column's header (any name): ``F_ref [kN]``
    -> ("F_ref", 1e3); ``speed_mm_s`` in m/s -> ("speed", 1e-3), the rightmost split whose
    unit has the input's dimension. ValueError saying why for none."""
    match = _BRACKET.match(header)
    splits = ([(match["name"].strip().replace(" ", "_"), match["unit"].strip())] if match
              else _splits(header))
    errors = []
    for base, unit in splits:
        try:
            return base, si_factor(unit, si_unit)
        except ValueError as exc:
            errors.append(exc)
    raise errors[0] if errors else ValueError("names no unit")


def _input_column(file: str, headers: Sequence[str], column: str | None, suffix: str,
                  what: str) -> tuple[str, float]:
    """(header, factor to SI) of the input's column among ``headers`` (time excluded):
    ``column`` as written or by its SI name (``F_ref_N`` for ``F_ref [kN]``), default the
    only one. ParameterError naming the file and column otherwise."""
    si_unit = SI_SUFFIXES[suffix]
    if column is None:
        if len(headers) != 1:
            raise ParameterError(f"{file} ({what}): has {len(headers)} columns besides time "
                                 f"({', '.join(headers) or 'none'}); name one with "
                                 "column = ...")
        header = headers[0]
    elif column in headers:
        header = column
    else:
        by_si = {}
        for h in headers:
            try:
                by_si[f"{input_reading(h, si_unit)[0]}_{suffix}"] = h
            except ValueError:
                continue
        if column not in by_si:
            raise ParameterError(f"{file} ({what}): no column {column!r} (has: "
                                 f"{', '.join(headers) or 'none'})")
        header = by_si[column]
    try:
        return header, input_reading(header, si_unit)[1]
    except ValueError as exc:
        raise ParameterError(f"{file} column {header!r} ({what}): {exc}; "
                             f"{expects(what, si_unit)}") from None


def input_signal(path: str | Path, column: str | None, suffix: str,
                 what: str) -> InputSignal:
    """Read one input column (header as written, e.g. ``F_ref [kN]``, or its SI name
    ``F_ref_N``; default the file's only column besides time) whose unit must have the
    dimension of SI ``suffix`` (``N``, ``Pa``, ``m_s``; :data:`SI_SUFFIXES`).

    ParameterError naming the file and column for a missing column, a unit pint does not
    know or of another dimension, or what :func:`read_trace` refuses; ``what`` names the
    input in messages."""
    path = Path(path)
    table, sha256 = _read_table(path)
    time_names = {base: Quantity(TIME, "s") for base in TIME_NAMES}
    named, others = _named(path.name, table.column_names, time_names)
    header, factor = _input_column(path.name, others, column, suffix, what)
    raw = dict(zip(table.column_names, table.columns, strict=True))
    time_header, time_factor = named[TIME]
    written = _numbers(path.name, header, raw[header])
    trace = _checked(Trace(path.name, _numbers(path.name, time_header, raw[time_header])
                           * time_factor, {header: written * factor},
                           {TIME: time_header, header: header}, others, sha256))
    if trace.t_s[0] > COUPLING_STEP_S + COVER_TOLERANCE_S:
        raise ParameterError(f"{trace.where(TIME)} ({what}): starts at {trace.t_s[0]:g} s; "
                             f"an input must start by {COUPLING_STEP_S:g} s")
    t = COUPLING_STEP_S * np.arange(0, int(np.floor(trace.t_s[-1] / COUPLING_STEP_S
                                                      + 1e-9)) + 1)
    return InputSignal(trace.file, header, t, trace.resample(header, t),
                       FileSamples(trace.t_s, written, factor, time_header, time_factor))
