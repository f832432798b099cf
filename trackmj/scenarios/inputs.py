"""The ``from_file`` inputs of a scenario: the [reference], [supply], [track] and [hitch]
signals read from CSV or Parquet files (:func:`trackmj.results.measured.input_signal`), once
per file version."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from pathlib import Path

from trackmj.results.measured import InputSignal, input_signal
from trackmj.scenarios.schema import Hitch, Reference, Supply, Track
from trackmj.validator import ParameterError

INPUT_NAMES = {"reference": "reference F_ref", "supply": "supply set-point p_set",
               "track": "track speed", "hitch": "hitch load"}
"""What each from_file input is called in messages."""
INPUT_SUFFIXES = {"reference": "N", "supply": "Pa", "track": "m_s", "hitch": "N"}
"""The unit suffix of each from_file input (its column's SI unit)."""


@functools.lru_cache(maxsize=16)
def _cached_signal(path: Path, mtime_ns: int, column: str | None, suffix: str,
                   what: str) -> InputSignal:
    return input_signal(path, column, suffix, what)


def _input_signal(path: Path, column: str | None, suffix: str, what: str) -> InputSignal:
    """The file's input signal, read once per file version."""
    if not path.is_file():
        raise ParameterError(f"{what}: from_file {path} not found")
    return _cached_signal(path.resolve(), path.stat().st_mtime_ns, column, suffix, what)


def read_inputs(folder: Path, tables: Mapping[str, Reference | Supply | Track | Hitch | None]
                ) -> dict[str, InputSignal]:
    """The signals of the ``tables`` (input name -> its table, None if absent) that give a
    ``from_file``, read relative to ``folder`` (the scenario file's), in the order given."""
    signals = {}
    for what, table in tables.items():
        if table is not None and table.from_file is not None:
            signals[what] = _input_signal(folder / table.from_file, table.column,
                                          INPUT_SUFFIXES[what], INPUT_NAMES[what])
    return signals
