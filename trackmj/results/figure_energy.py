"""A run's energy as a waterfall [kJ] (:func:`energy_waterfall`, drawn by
:func:`energy_bars`): the circuit's terms from zero, each from the running sum, up to the
circuit total; then the supply side's terms up to the pump total."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

from matplotlib.axes import Axes

from trackmj.results.energy_terms import ENERGY_TOTALS, energy_terms
from trackmj.results.figure_style import ENERGY_STYLES
from trackmj.results.store import Result

ENERGY_ORDER = ("throttling", "leakage", "friction", "makeup", "return_line", "endstop",
                "mechanical", "stored_change", "numerical", "residual", "relief", "pump_losses")
"""Stacking order of the energy terms (terms not listed go on top)."""
SUPPLY_SIDE = ("pump_losses", "relief", "stored_change.supply_oil",
               "stored_change.accumulator", "numerical.supply")
"""Terms of the energy table between the pump and the main valve's P port (the rest of the
terms, but the residual, lie between the P port and the track: the circuit's)."""
ENERGY_LABELS = {
    "numerical": "numerical (backward-Euler dissipation of the pressure nodes, the chamber "
                 "volume term and the 1 ms coupling's interface residual)",
    "stored_change": "stored_change (oil and gas energy, end − start)",
    "residual": "residual (pump − every term: the bookkeeping check)",
    "mechanical": "mechanical (work into the track, ∫F·v dt)",
}
"""Legend text of the energy terms that need a word of explanation."""


def energy_waterfall(metrics: Mapping[str, Any]) -> tuple[list[tuple[str, float]],
                                                           list[tuple[str, float]]]:
    """A run's energy terms [J] in the order of the waterfall: (circuit terms, then the
    supply-side terms and the residual), each a list of (term, value); sub-terms summed per
    term and side (``stored_change`` and ``numerical`` have a share on each side). Running
    sums: after the circuit terms the circuit total, after all the pump total."""
    table = metrics.get("energy_J")
    if not isinstance(table, Mapping):
        return [], []
    sides: tuple[dict[str, float], dict[str, float]] = ({}, {})
    for key, value in table.items():
        if key in ENERGY_TOTALS or isinstance(value, str | bool):
            continue
        items = value.items() if isinstance(value, Mapping) else [(None, value)]
        for sub, v in items:
            if isinstance(v, str | bool) or not math.isfinite(float(v)):
                continue
            full = key if sub is None else f"{key}.{sub}"
            supply = key in SUPPLY_SIDE or full in SUPPLY_SIDE or key == "residual"
            side = sides[1 if supply else 0]
            side[key] = side.get(key, 0.0) + float(v)

    def order(item: tuple[str, float]) -> int:
        return ENERGY_ORDER.index(item[0]) if item[0] in ENERGY_ORDER else len(ENERGY_ORDER)

    return (sorted(sides[0].items(), key=order), sorted(sides[1].items(), key=order))


def energy_bars(ax: Axes, labels: Sequence[str], results: Sequence[Result], *,
                below: bool = False) -> None:
    """Each run's energy as a waterfall [kJ]: the circuit's terms from zero, each bar from the
    running sum (a negative term, e.g. energy released from storage, goes down), so the
    circuit total (dashed tick) stands where its terms end; then the supply-side terms
    (relief, pump losses, supply storage) up to the pump total (solid tick). A note where a
    run has no energy_J table. ``below``: the legend under the panel (else beside it)."""
    spare = iter(["#777777", "#444444", "#AAAAAA"])
    drawn: set[str] = set()
    for x, r in enumerate(results):
        _run_waterfall(ax, x, r, spare, drawn)
    _energy_notes(ax, labels, results)
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xticks(range(len(labels)), labels, rotation=20)
    ax.set_xlim(-0.6, len(labels) - 0.4)
    ax.set_ylabel("energy [kJ]")
    ax.set_title("energy, waterfall: circuit terms, then supply side", fontsize=10, loc="left")
    ax.grid(axis="y", alpha=0.3)
    _energy_legend(ax, below)


def _run_waterfall(ax: Axes, x: int, result: Result, spare: Iterator[str],
                   drawn: set[str]) -> None:
    """The waterfall of one run at ``x`` (bars across x ± 0.4) and its total ticks; a term
    without a style takes the next ``spare`` colour; ``drawn``: the legend entries there
    are (updated)."""
    circuit_terms, supply_terms = energy_waterfall(result.metrics)
    circuit_terms = [t for t in circuit_terms if t[1] != 0.0]
    steps = circuit_terms + [t for t in supply_terms if t[1] != 0.0]
    if not steps:
        return
    width = 0.8 / len(steps)
    left = x - 0.4
    end_circuit = left + width * len(circuit_terms)
    running = 0.0
    totals = energy_terms(result.metrics).terms
    for k, (name, value) in enumerate(steps):
        colour, hatch = ENERGY_STYLES.get(name) or ENERGY_STYLES.setdefault(
            name, (next(spare, "#777777"), "||"))
        ax.bar(left + width * (k + 0.5), value / 1e3, bottom=running / 1e3, width=width,
               color=colour, hatch=hatch, edgecolor="black", lw=0.5,
               label=None if name in drawn else ENERGY_LABELS.get(name, name))
        drawn.add(name)
        running += value
    for total, ls, x0, x1 in (("circuit", "--", left, end_circuit),
                              ("pump", "-", left, x + 0.4)):
        value = totals.get(total, math.nan) / 1e3
        if math.isfinite(value) and x1 > x0:
            ax.hlines(value, x0, x1, color="black", lw=2.0, ls=ls,
                      label="" if total in drawn else f"{total} total (energy in)")
            drawn.add(total)


def _energy_notes(ax: Axes, labels: Sequence[str], results: Sequence[Result]) -> None:
    """The runs' energy notes (e.g. no energy table), each naming its runs, in head room
    made above the bars."""
    by_note: dict[str, list[str]] = {}
    for lab, r in zip(labels, results, strict=True):
        for n in energy_terms(r.metrics).notes:
            by_note.setdefault(n, []).append(lab)
    lines = [textwrap.fill(f"{', '.join(labs)}: {n}", 60) for n, labs in by_note.items()]
    if lines:     # in head room above the bars, not over them
        low, high = ax.get_ylim()
        rows = sum(line.count("\n") + 1 for line in lines)
        ax.set_ylim(low, high + (0.12 * rows + 0.1) * (high - low))
        ax.text(0.02, 0.98, "\n".join(lines), transform=ax.transAxes, va="top", fontsize=9)


def _energy_legend(ax: Axes, below: bool) -> None:
    """The terms' legend under a narrow panel (``below``, two columns) or beside it."""
    handles, names = ax.get_legend_handles_labels()
    if below:      # a narrow panel: the dozen terms under it, in two columns
        ax.legend(handles, [textwrap.fill(n, 38) for n in names], loc="upper center",
                  bbox_to_anchor=(0.5, -0.12), ncol=2, frameon=False, fontsize=9,
                  borderaxespad=0.0)
    else:
        ax.legend(handles, [textwrap.fill(n, 42) for n in names], loc="upper left",
                  bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=9, borderaxespad=0.0)
