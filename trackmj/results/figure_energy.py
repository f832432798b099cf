"""A run's energy as a waterfall [J or kJ] (:func:`energy_waterfall`, drawn by
:func:`energy_bars`): the circuit's terms from zero, each from the running sum, up to the
circuit total; then the supply side's terms up to the pump total. Horizontal: the terms
named in words down the side, one panel per run."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping, Sequence
from typing import Any

from matplotlib.axes import Axes
from matplotlib.figure import Figure, SubFigure

from trackmj.results.energy_terms import ENERGY_TOTALS, energy_terms
from trackmj.results.figure_style import number
from trackmj.results.store import Result

ENERGY_ORDER = ("throttling", "leakage", "friction", "makeup", "cavitation", "return_line",
                "endstop", "mechanical", "stored_change", "numerical", "residual", "relief",
                "pump_losses")
"""Stacking order of the energy terms (terms not listed go on top)."""
SUPPLY_SIDE = ("pump_losses", "relief", "stored_change.supply_oil",
               "stored_change.accumulator", "numerical.supply")
"""Terms of the energy table between the pump and the main valve's P port (the rest of the
terms, but the residual, lie between the P port and the track: the circuit's)."""
ENERGY_WORDS = {
    "throttling": "throttling (valves, restrictors)",
    "leakage": "seal leakage, head to rod",
    "friction": "cylinder seal friction",
    "makeup": "make-up check valves",
    "cavitation": "air out of solution (cavitation)",
    "return_line": "return-line back-pressure",
    "endstop": "end-stop contact",
    "mechanical": "work into the track, ∫F·v dt",
    "stored_change": "Δ stored, circuit oil",
    "numerical": "numerical (solver, coupling)",
    "residual": "residual (pump − all terms)",
    "relief": "relief valve",
    "pump_losses": "pump losses",
    "supply.stored_change": "Δ stored, supply oil and gas",
    "supply.numerical": "numerical (supply node)",
    "total.circuit": "= circuit total, in at P port",
    "total.pump": "= pump total, shaft energy in",
}
"""The rows of the waterfall in words: a term of the energy table (``supply.<term>``: its
supply-side share, where that differs), or a total (``total.<name>``); a term without an
entry is shown by its key."""
KJ_FROM_J = 1e4
"""The waterfall is drawn in kJ when its largest value reaches this [J] (else in J)."""
BAR_COLOUR = "0.6"
"""Colour of a term's bar (the totals are outlined white bars)."""
BAR_HEIGHT = 0.7
"""Height of a bar, in rows."""
MIN_ROWS = 8
"""The panel's height in rows at least (a run with few terms gets bars of the usual
height)."""
FONT_PT = 9.0
"""Size of the row labels and of the values written beside the bars."""


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


def energy_bars(fig: Figure | SubFigure, labels: Sequence[str],
                results: Sequence[Result]) -> list[Axes]:
    """The runs' energy as horizontal waterfalls filling ``fig`` [J, or kJ from
    :data:`KJ_FROM_J`], one panel per run (titled by its label when there are several),
    sharing their rows and energy axis: one row per term in words (the circuit's terms,
    their total, the supply side's terms, the pump total). A term's bar starts where the
    previous one ended (a negative term, e.g. energy released from storage, goes left), so
    the circuit's terms end at the circuit total and all the terms at the pump total; the
    totals are outlined bars from zero. The values stand beside the bars where they fit;
    a run's energy notes (e.g. no energy table) under its panel. Returns the axes."""
    rows, bars = _waterfall_rows(results)
    largest = max((abs(x) for run in bars for (_, lo, v) in run for x in (lo, lo + v)),
                  default=0.0)
    unit, scale = ("kJ", 1e-3) if largest >= KJ_FROM_J else ("J", 1.0)
    axes = list(fig.subplots(1, len(results), sharex=True, sharey=True, squeeze=False)[0])
    values = (_row_height_pt(fig, axes[0], max(len(rows), MIN_ROWS)) * BAR_HEIGHT
              >= 1.2 * FONT_PT)
    for ax, label, r, run in zip(axes, labels, results, bars, strict=True):
        for row, start, value in run:
            total = row[0] == "total"
            ax.barh(rows.index(row), value * scale, left=start * scale, height=BAR_HEIGHT,
                    color="white" if total else BAR_COLOUR, edgecolor="black",
                    lw=1.4 if total else 0.5)
            if values:
                _value_label(ax, start * scale, value * scale, rows.index(row),
                             largest * scale)
        for k, row in enumerate(rows[:-1]):
            if row[0] == "total":
                ax.axhline(k + 0.5, color="0.5", lw=0.6)
        ax.axvline(0.0, color="black", lw=0.6)
        ax.grid(axis="x", alpha=0.3)
        ax.tick_params(axis="y", length=0)
        ax.set_xlabel(f"energy [{unit}]")
        if len(results) > 1:
            ax.set_title(label, fontsize=10, loc="left")
        _energy_notes(ax, energy_terms(r.metrics).notes)
    if rows:
        axes[0].set_yticks(range(len(rows)), [_row_label(row) for row in rows],
                           fontsize=FONT_PT)
        # first term at the top; a short table keeps the bars of a long one
        axes[0].set_ylim(max(len(rows), MIN_ROWS) - 0.5, -0.5)
        low, high = axes[0].get_xlim()
        pad = (0.2 if values else 0.03) * (high - low)       # room for the values
        axes[0].set_xlim(low - pad if low < 0.0 else low, high + pad)
    else:      # no run has an energy table: its note alone
        axes[0].set_yticks([])
        axes[0].set_xticks([])
    chars = int(fig.bbox.width / fig.dpi * 11.0)       # ~11 characters of 10 pt per inch
    fig.suptitle(textwrap.fill("energy over the run: the circuit's terms, each from where the "
                               "previous ended, then the supply side's", chars), fontsize=10)
    return axes


def _value_label(ax: Axes, start: float, value: float, y: float, largest: float) -> None:
    """``value`` beside its bar from ``start`` at row position ``y``: right of its end
    (left of it for a negative value); "≈0" below 0.1 % of the ``largest`` value shown."""
    end = start + value
    text = "≈0" if abs(value) < 1e-3 * largest else number(value)
    ax.annotate(text, (max(start, end) if value >= 0.0 else min(start, end), y),
                xytext=(3 if value >= 0.0 else -3, 0), textcoords="offset points",
                ha="left" if value >= 0.0 else "right", va="center", fontsize=FONT_PT)


Row = tuple[str, str]
"""A waterfall row: (side, term) with side ``circuit`` or ``supply``, or (``total``, name
of the total)."""


def _waterfall_rows(results: Sequence[Result],
                    ) -> tuple[list[Row], list[list[tuple[Row, float, float]]]]:
    """The rows every run's waterfall needs, in order, and per run its bars (row, start,
    value) [J]: the non-zero terms from the running sum, the totals from zero."""
    bars: list[list[tuple[Row, float, float]]] = []
    used: set[Row] = set()
    for r in results:
        circuit_terms, supply_terms = energy_waterfall(r.metrics)
        totals = energy_terms(r.metrics).terms
        run: list[tuple[Row, float, float]] = []
        running = 0.0
        for side, terms, total in (("circuit", circuit_terms, "circuit"),
                                   ("supply", supply_terms, "pump")):
            for name, value in terms:
                if value != 0.0:
                    run.append(((side, name), running, value))
                    running += value
            value = totals.get(total, math.nan)
            if math.isfinite(value):
                run.append((("total", total), 0.0, value))
        used.update(row for row, _, _ in run)
        bars.append(run)
    rows: list[Row] = []
    for side, total in (("circuit", "circuit"), ("supply", "pump")):
        terms = {n for s, n in used if s == side}
        rows += [(side, n) for n in [*ENERGY_ORDER, *sorted(terms - set(ENERGY_ORDER))]
                 if n in terms]
        rows += [("total", total)] if ("total", total) in used else []
    return rows, bars


def _row_label(row: Row) -> str:
    """A row's label in words (:data:`ENERGY_WORDS`)."""
    side, term = row
    return (ENERGY_WORDS.get(f"{side}.{term}") or ENERGY_WORDS.get(term)
            or term.replace("_", " "))


def _row_height_pt(fig: Figure | SubFigure, ax: Axes, n_rows: int) -> float:
    """Height of a row [pt] when ``ax`` (in ``fig``) holds ``n_rows`` rows, estimated from
    its place in the figure's grid (the layout takes ~25 % for titles and labels)."""
    box = ax.get_position()        # in the root figure's coordinates
    panel_pt = box.height * fig.figure.get_figheight() * 72.0
    return panel_pt * 0.75 / max(n_rows, 1)


def _words(note: str) -> str:
    """A note with its key in words ("supply_model: compensated" -> "supply model:
    compensated"); the text after the key as it is (it may name code)."""
    key, sep, rest = note.partition(": ")
    return key.replace("_", " ") + sep + rest


def _energy_notes(ax: Axes, notes: Sequence[str]) -> None:
    """A run's energy ``notes`` (e.g. no energy table) under its panel's axis label; in the
    panel if it has no bars."""
    text = "\n".join(textwrap.fill(_words(n), 44, break_long_words=False) for n in notes)
    if text and not ax.patches:
        ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center",
                fontsize=FONT_PT)
    elif text:
        ax.annotate(text, (0.5, 0.0), xycoords="axes fraction", xytext=(0, -36),
                    textcoords="offset points", ha="center", va="top", fontsize=FONT_PT)
