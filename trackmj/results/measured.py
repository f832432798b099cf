"""Measured time series: rig logs and input traces read from CSV or Parquet files.

A file holds a time column ``t_s`` and signal columns. A column is named either in SI with
its unit as the name's suffix (``tension_N``, ``p_head_Pa``, ``stroke_m``), or with another
unit, as a suffix (``tension_kN``, ``stroke_mm``, ``p_head_MPa``) or in brackets
(``p_head [MPa]``, ``t [ms]``); every such column is converted to SI on reading and
renamed to its SI name (``p_head [MPa]`` -> ``p_head_Pa``). Pressures are gauge, as in the
run's own columns. :data:`UNIT_SCALES` lists the units understood.

Checks, each refused with one line naming the file and the column (a
:class:`~trackmj.validator.ParameterError`, exit 2 on the command line): a time column, time
strictly increasing, every value finite, and, for a run, the time covering the run
[1 ms, duration]. Signals are resampled to the run's 1 ms grid by linear interpolation
(:func:`resample`; a log sampled faster than 1 kHz is interpolated, not averaged).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from trackmj.ports import COUPLING_STEP_S
from trackmj.validator import ParameterError

UNIT_SCALES: dict[str, tuple[str, float]] = {
    "s": ("s", 1.0), "ms": ("s", 1e-3),
    "N": ("N", 1.0), "kN": ("N", 1e3),
    "Pa": ("Pa", 1.0), "kPa": ("Pa", 1e3), "MPa": ("Pa", 1e6), "bar": ("Pa", 1e5),
    "m": ("m", 1.0), "mm": ("m", 1e-3),
    "m_s": ("m_s", 1.0), "m/s": ("m_s", 1.0), "mm_s": ("m_s", 1e-3), "mm/s": ("m_s", 1e-3),
    "m3_s": ("m3_s", 1.0), "m^3/s": ("m3_s", 1.0), "L_min": ("m3_s", 1e-3 / 60.0),
    "L/min": ("m3_s", 1e-3 / 60.0),
    "m_s2": ("m_s2", 1.0), "m/s^2": ("m_s2", 1.0),
    "J": ("J", 1.0), "kJ": ("J", 1e3),
    "1": ("", 1.0), "-": ("", 1.0),
}
"""Unit written in a column header -> (SI suffix of the column's name, factor to SI)."""
DIMENSIONLESS = ("valve_mode", "u")
"""Columns without a unit suffix (the run's valve mode −1/0/+1 and opening u [-])."""
TIME = "t_s"
COVER_TOLERANCE_S = 0.5 * COUPLING_STEP_S
"""A trace covers the run if it starts by the end of the first step (a run's own ``t_s``
starts there) and ends by the duration, within half a step [s]; before its first sample
it holds its first value."""

_BRACKET = re.compile(r"^\s*(?P<name>[^\[\]]+?)\s*\[(?P<unit>[^\[\]]+)\]\s*$")


def si_name(header: str) -> tuple[str, float] | None:
    """(SI column name, factor to SI) of a header, or None if it states no known unit.

    ``tension_kN`` -> ("tension_N", 1e3); ``p_head [MPa]`` -> ("p_head_Pa", 1e6);
    ``stroke_m`` -> ("stroke_m", 1.0); ``valve_mode`` -> ("valve_mode", 1.0).
    """
    if header in DIMENSIONLESS:
        return header, 1.0
    match = _BRACKET.match(header)
    if match:
        base, unit = match["name"].strip().replace(" ", "_"), match["unit"].strip()
        if unit not in UNIT_SCALES:
            return None
        suffix, scale = UNIT_SCALES[unit]
        return (f"{base}_{suffix}" if suffix else base), scale
    for unit in sorted(UNIT_SCALES, key=len, reverse=True):
        if "/" in unit or "^" in unit or unit in ("1", "-"):
            continue
        if header.endswith("_" + unit) and len(header) > len(unit) + 1:
            suffix, scale = UNIT_SCALES[unit]
            return f"{header[: -len(unit) - 1]}_{suffix}", scale
    return None


@dataclass(frozen=True)
class Trace:
    """A file's time series in SI: ``t_s`` [s], shape (n,), strictly increasing;
    ``columns``: SI name -> values, shape (n,); ``headers``: SI name -> the header as
    written (for messages); ``file``: the file's name."""

    file: str
    t_s: np.ndarray
    columns: Mapping[str, np.ndarray]
    headers: Mapping[str, str]

    def where(self, name: str) -> str:
        """``file column 'header'`` for a message."""
        return f"{self.file} column {self.headers.get(name, name)!r}"

    def require(self, names: Sequence[str]) -> None:
        """ParameterError naming the file if a column is missing."""
        missing = [n for n in names if n not in self.columns]
        if missing:
            hint = ("" if missing[0] in DIMENSIONLESS else "; name it in SI (tension_N) or "
                    "with its unit (tension_kN, p_head [MPa])")
            raise ParameterError(f"{self.file}: no column {missing[0]!r} (has: "
                                 f"{', '.join(self.headers.values())}){hint}")

    def check_covers(self, duration_s: float, what: str = "the run") -> None:
        """ParameterError naming the file and time column unless t spans [0, duration_s]."""
        t0, t1 = float(self.t_s[0]), float(self.t_s[-1])
        if t0 > COUPLING_STEP_S + COVER_TOLERANCE_S or t1 < duration_s - COVER_TOLERANCE_S:
            raise ParameterError(f"{self.where(TIME)}: spans {t0:g} .. {t1:g} s, too short "
                                 f"to cover {what} ({COUPLING_STEP_S:g} .. {duration_s:g} s)")

    def resample(self, name: str, t_s: np.ndarray) -> np.ndarray:
        """Column ``name`` at times ``t_s`` [s] by linear interpolation (held beyond the
        ends), shape of ``t_s``."""
        return np.interp(np.asarray(t_s, dtype=float), self.t_s, self.columns[name])


def _read_table(path: Path) -> dict[str, np.ndarray]:
    """Column name -> float values of a CSV or Parquet file (pyarrow)."""
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            table = pq.read_table(path)
        else:
            table = pacsv.read_csv(path)
    except (OSError, pa.ArrowInvalid) as exc:
        raise ParameterError(f"{path.name}: cannot read as "
                             f"{'Parquet' if path.suffix.lower() in ('.parquet', '.pq') else 'CSV'}"
                             f": {str(exc).splitlines()[0]}") from None
    out = {}
    for name in table.column_names:
        column = table.column(name)
        if not (pa.types.is_floating(column.type) or pa.types.is_integer(column.type)):
            raise ParameterError(f"{path.name} column {name!r}: holds {column.type}, not "
                                 "numbers")
        out[name] = column.to_numpy(zero_copy_only=False).astype(float)   # nulls -> NaN
    return out


def read_trace(path: str | Path, columns: Sequence[str] | None = None) -> Trace:
    """Read a measured or input time series (see the module docstring).

    Parameters
    ----------
    path : str or Path
        CSV (one header row) or Parquet (``.parquet``) file.
    columns : sequence of str, optional
        SI names of the columns wanted (each must be there); default every column whose
        header names a unit.

    Returns
    -------
    Trace
        Time and the columns in SI. ParameterError naming the file and column for a
        missing file or column, time not strictly increasing, or a non-finite value.
    """
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"measured data file not found: {path}")
    raw = _read_table(path)
    headers: dict[str, str] = {}
    values: dict[str, np.ndarray] = {}
    for header, data in raw.items():
        named = si_name(header)
        if named is None:
            continue
        name, scale = named
        if name in values:
            raise ParameterError(f"{path.name}: columns {headers[name]!r} and {header!r} are "
                                 f"both {name}")
        headers[name], values[name] = header, data * scale
    if TIME not in values:
        raise ParameterError(f"{path.name}: no time column 't_s' (or 't [s]', 't [ms]'); "
                             f"columns: {', '.join(raw)}")
    trace = Trace(path.name, values.pop(TIME), values, headers)
    wanted = list(values) if columns is None else list(columns)
    trace.require(wanted)
    t = trace.t_s
    if len(t) < 2:
        raise ParameterError(f"{trace.where(TIME)}: {len(t)} row(s); a time series needs two "
                             "or more")
    for name, data in ((TIME, t), *((n, values[n]) for n in wanted)):
        bad = ~np.isfinite(data)
        if bad.any():
            i = int(np.argmax(bad))
            raise ParameterError(f"{trace.where(name)}: row {i + 1} is {data[i]!r} (values "
                                 "must be finite numbers)")
    steps = np.diff(t)
    if (steps <= 0.0).any():
        i = int(np.argmax(steps <= 0.0))
        raise ParameterError(f"{trace.where(TIME)}: time is not strictly increasing at row "
                             f"{i + 2} (t = {t[i + 1]:g} s after {t[i]:g} s)")
    return Trace(trace.file, t, {n: values[n] for n in wanted}, headers)


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


def load_measured(path: str | Path, duration_s: float,
                  run_columns: Sequence[str]) -> dict[str, np.ndarray]:
    """A measured log to compare a run of ``duration_s`` [s] with: its columns that name a
    unit, each one of ``run_columns`` (the run's own names), on the run's 1 ms grid
    (``t_s`` included). ParameterError naming the file and column for a column the run
    does not record, or a log that does not cover the run."""
    trace = read_trace(path)
    for name in trace.columns:
        if name not in run_columns:
            raise ParameterError(f"{trace.where(name)}: {name} is not a column of the run "
                                 f"(compared by the run's own names: "
                                 f"{', '.join(c for c in run_columns if c != TIME)})")
    if not trace.columns:
        raise ParameterError(f"{trace.file}: no column to compare besides t_s")
    return resample(trace, duration_s)


@dataclass(frozen=True)
class InputSignal:
    """A time-series input of a run read from a file: ``values`` on the 1 ms grid ``t_s``
    (k·h from 0; linear interpolation of the file), held between grid points and beyond
    the ends (zero-order, as a 1 kHz set-point is applied); ``file`` and ``column`` name
    where it came from (the header as written)."""

    file: str
    column: str
    t_s: np.ndarray
    values: np.ndarray

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


def input_signal(path: str | Path, column: str | None, suffix: str,
                 what: str) -> InputSignal:
    """Read one input column (SI name or header as written, e.g. ``F_ref [kN]``; default the
    file's only column besides time) whose unit is SI ``suffix`` (``N``, ``Pa``, ``m_s``).

    ParameterError naming the file and column for a missing column, another unit, or what
    :func:`read_trace` refuses; ``what`` names the input in messages."""
    trace = read_trace(path, [])
    named = {name: header for name, header in trace.headers.items() if name != TIME}
    if column is None:
        if len(named) != 1:
            raise ParameterError(f"{trace.file} ({what}): has {len(named)} signal columns "
                                 f"({', '.join(named.values()) or 'none'}); name one with "
                                 "column = ...")
        name = next(iter(named))
    else:
        by_header = {header: name for name, header in named.items()}
        name = by_header.get(column, column)
        if name not in named:
            raise ParameterError(f"{trace.file} ({what}): no column {column!r} (has: "
                                 f"{', '.join(named.values()) or 'none'})")
    if not name.endswith("_" + suffix):
        raise ParameterError(f"{trace.file} column {named[name]!r} ({what}): is in "
                             f"{name.rpartition('_')[2]}; {what} needs a unit of {suffix} "
                             f"(e.g. {what.split()[0]}_{suffix} or a unit in brackets)")
    trace = read_trace(path, [name])
    if trace.t_s[0] > COUPLING_STEP_S + COVER_TOLERANCE_S:
        raise ParameterError(f"{trace.where(TIME)} ({what}): starts at {trace.t_s[0]:g} s; "
                             f"an input must start by {COUPLING_STEP_S:g} s")
    t = COUPLING_STEP_S * np.arange(0, int(np.floor(trace.t_s[-1] / COUPLING_STEP_S
                                                      + 1e-9)) + 1)
    return InputSignal(trace.file, named[name], t, trace.resample(name, t))
