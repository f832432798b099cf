"""A run's energy terms read from its ``energy_J`` table (:func:`energy_terms`), and the
term two runs are compared on (:func:`headline_energy`). The table itself is the tensioner's
energy ledger's (:mod:`trackmj.elements.energy_table`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

ENERGY_TOTALS = ("pump", "circuit")
"""Terms of an ``energy_J`` table that are totals (energy put in), not parts of a breakdown."""
ENERGY_HEADLINE = ("pump", "circuit", "mechanical")
"""Energy compared between runs: the first of these both runs have (finite)."""


class EnergyTerms(NamedTuple):
    """A run's energy terms [J] (name -> value; a table of sub-terms, e.g. throttling by
    valve, summed), the notes the table carries (its text or flag entries, e.g. that a dp-b
    circuit is an ideal actuator's) and where they came from (``energy_J`` or
    none)."""

    terms: dict[str, float]
    notes: list[str]
    source: str


def _total(value: Any) -> float:
    if isinstance(value, Mapping):
        parts = [_total(v) for v in value.values()]
        parts = [p for p in parts if not math.isnan(p)]
        return float(sum(parts)) if parts else math.nan
    if isinstance(value, bool) or not isinstance(value, int | float):
        return math.nan
    return float(value)


def energy_terms(metrics: Mapping[str, Any]) -> EnergyTerms:
    """The energy terms of a run's metrics: the ``energy_J`` table if the run has one (keys
    such as pump, circuit, relief, throttling (by valve), leakage, friction, makeup,
    stored_change, mechanical, residual; :mod:`trackmj.elements.energy_table`), tables
    summed; empty with a note if the run has none."""
    table = metrics.get("energy_J")
    if isinstance(table, Mapping):
        terms, notes = {}, []
        for key, value in table.items():
            if isinstance(value, str):     # a "note" entry is its text, other texts named
                notes.append(value if key == "note" else f"{key}: {value}")
            elif isinstance(value, bool):
                if value:
                    notes.append(key.replace("_", " "))
            else:
                terms[key] = _total(value)
        return EnergyTerms(terms, notes, "energy_J")
    return EnergyTerms({}, ["no energy table in this run"], "none")


def headline_energy(a: EnergyTerms, b: EnergyTerms) -> str | None:
    """The first term of :data:`ENERGY_HEADLINE` finite in both ``a`` and ``b`` (None: none)."""
    for term in ENERGY_HEADLINE:
        if math.isfinite(a.terms.get(term, math.nan)) and math.isfinite(
                b.terms.get(term, math.nan)):
            return term
    return None
