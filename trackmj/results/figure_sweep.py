"""The figures of a sweep (:func:`sweep_figures`, PNG): how each metric depends on each swept
key. One figure per swept key, a panel per metric: the metric at each point against the
key's value, a line per case and combination of the other keys' values, error bars (± std
over seeds) only where a point has two seeds or more. Without swept keys (e.g. a controller
comparison) one figure of grouped bars, a group per scenario and a bar per case. Drawn
without pyplot (no global figure state), values in each metric's display unit.

The points and panels come from the sweep's summary (:func:`trackmj.study.sweep.summarize`),
read here through the protocols :class:`SweepPoint` and :class:`Panel`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import matplotlib

matplotlib.use("Agg")
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from trackmj.results.columns import column_label, column_unit, column_words, display_unit
from trackmj.results.figure_style import save_png

CASES_FIGURE = "cases.png"
"""The figure of a sweep without swept keys."""
DIAGNOSTICS_FIGURE = "diagnostics.png"
"""The figure of the diagnostics (drawn only when asked)."""
PALETTE = (("black", "-", "o"), ("#E69F00", "--", "s"), ("#0072B2", "-.", "^"),
           ("#009E73", ":", "D"), ("#D55E00", (0, (5, 1, 1, 1)), "v"),
           ("#56B4E9", (0, (3, 1)), "P"), ("#CC79A7", (0, (1, 1)), "X"),
           ("#999999", (0, (5, 2)), "*"))
"""Colour (Okabe-Ito), dash pattern and marker of each line, so that the figures read in
grayscale too."""
BAR_STYLES = (("#E69F00", ""), ("#56B4E9", "//"), ("#009E73", ".."), ("#0072B2", "xx"),
              ("#D55E00", "\\\\"), ("#CC79A7", "++"), ("#999999", "oo"), ("#F0E442", "--"))
"""Fill colour and hatch of each bar of a group (light enough for black error bars)."""
SCATTER_TEXT = "samples (the other swept keys vary between them)"
"""Legend text of the loose markers of scattered samples (e.g. a Latin hypercube)."""
MAX_LABELLED_LINES = 12
"""More lines than this are drawn thin, grey and without a legend entry each."""
LOG_X_RATIO = 30.0
"""A swept key whose values span more than this ratio gets a log x axis."""
PANEL_W_IN, PANEL_H_IN = 3.5, 2.5
"""Size of one panel [in]."""


class SweepPoint(Protocol):
    """A point of a sweep's summary (:class:`trackmj.study.sweep.PointRow`): ``case``
    (scenario, architecture, controller, ... -> value), ``values`` (swept key -> value, SI),
    ``seeds`` of its finished runs and each metric's (mean, std, count) over them [SI]."""

    @property
    def case(self) -> Mapping[str, Any]: ...

    @property
    def values(self) -> Mapping[str, Any]: ...

    @property
    def seeds(self) -> tuple[int, ...]: ...

    def stats(self, key: str) -> tuple[float, float, int]: ...


class Panel(Protocol):
    """A metric to draw (:class:`trackmj.study.sweep.Column`): its results column ``key``,
    ``title`` (words and display unit) and ``scale`` (display value = scale × SI value)."""

    @property
    def key(self) -> str: ...

    @property
    def title(self) -> str: ...

    @property
    def scale(self) -> float: ...


def sweep_figures(points: Sequence[SweepPoint], panels: Sequence[Panel], fig_dir: Path, *,
                  diagnostics: Sequence[Panel] = (), redraw: bool = True) -> list[Path]:
    """The figures of a sweep in ``fig_dir``: ``<key>.png`` for each swept key (without
    swept keys ``cases.png``), ``panels`` as its panels; with ``diagnostics`` also
    ``diagnostics.png`` (against the first swept key). ``points``: the points with a
    finished run. Other PNG files in ``fig_dir`` (an earlier sweep's) are removed, so it
    holds these figures only. ``redraw=False`` keeps a figure that exists. Returns the
    paths of the figures."""
    swept = list(dict.fromkeys(k for p in points for k in p.values))
    plans: dict[str, tuple[Sequence[Panel], str | None, str]] = {}
    if points and panels:
        for key in swept:
            plans[f"{key}.png"] = (panels, key, "Engineering metrics")
        if not swept:
            plans[CASES_FIGURE] = (panels, None, "Engineering metrics")
    if points and diagnostics:
        plans[DIAGNOSTICS_FIGURE] = (diagnostics, swept[0] if swept else None,
                                     "Diagnostics (machine-dependent)")
    if fig_dir.is_dir():
        for stale in fig_dir.glob("*.png"):
            if stale.name not in plans:
                stale.unlink()
    paths = []
    for name, (shown, key, heading) in plans.items():
        path = fig_dir / name
        paths.append(path)
        if path.is_file() and not redraw:
            continue
        fig = (_key_figure(points, shown, key, swept, heading) if key is not None
               else _case_figure(points, shown, heading))
        save_png(fig, path)
    return paths


# ----------------------------------------------------------------------------- layout

def _panel_grid(n: int, legend_rows: int) -> tuple[Figure, list[Axes], list[bool]]:
    """A figure of ``n`` panels in a near-square grid (sharing x), room for a title and a
    legend of ``legend_rows`` rows below it; (figure, panels, whether each panel is the
    lowest of its column: it carries the x tick labels and label)."""
    ncols = math.ceil(math.sqrt(n))
    nrows = math.ceil(n / ncols)
    width = max(PANEL_W_IN * ncols, 6.0)
    height = PANEL_H_IN * nrows + 0.6 + 0.22 * legend_rows
    fig = Figure(figsize=(width, height), layout="constrained")
    axes = list(fig.subplots(nrows, ncols, squeeze=False, sharex=True).flat)
    for ax in axes[n:]:
        ax.remove()
    lowest = [i + ncols >= n for i in range(n)]
    for ax, low in zip(axes, lowest, strict=False):   # x tick labels where no panel is below
        if low:
            ax.xaxis.set_tick_params(labelbottom=True)
    return fig, axes[:n], lowest


def _legend(fig: Figure, handles: list[Any], labels: list[str]) -> None:
    """The figure's one legend, below the panels."""
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncol=_legend_columns(labels),
                   fontsize=9, frameon=False, handlelength=3.0, columnspacing=1.5)


def _legend_columns(labels: Sequence[str]) -> int:
    longest = max((len(label) for label in labels), default=1)
    return max(1, min(len(labels), 4, 110 // (longest + 6)))


def _legend_rows(labels: Sequence[str]) -> int:
    return math.ceil(len(labels) / _legend_columns(labels)) if labels else 0


def _seed_text(points: Sequence[SweepPoint]) -> str:
    """How the points' values were made: one run each, or mean ± std over seeds."""
    seeds = sorted({s for p in points for s in p.seeds})
    if max(len(p.seeds) for p in points) < 2:
        return f"one run per point (seed {', '.join(map(str, seeds))})"
    return f"mean ± std over seeds {', '.join(map(str, seeds))} (population std)"


def _shared_case(points: Sequence[SweepPoint]) -> tuple[str, list[str]]:
    """(the case fields every point shares in words, the case fields that differ)."""
    fields = list(points[0].case)
    varied = [f for f in fields if len({str(p.case.get(f)) for p in points}) > 1]
    case = points[0].case
    words = []
    for f in fields:
        if f in varied or case.get(f) is None:
            continue
        value = case[f]
        words.append(f"{value:g} s runs" if f == "duration_s" and isinstance(value, float)
                     else str(value))
    return ", ".join(words), varied


def _case_text(case: Mapping[str, Any], fields: Sequence[str]) -> str:
    """The values of a point's case ``fields`` as a legend names its line or bar, those it
    has not (e.g. no file given instead of the machine's) left out."""
    return ", ".join(str(case[f]) for f in fields if case.get(f) is not None)


def _style(j: int, labelled: bool) -> dict[str, Any]:
    """Line ``j``'s colour, dashes and marker (thin grey when lines are too many to label)."""
    if not labelled:
        return dict(color="0.5", ls="-", marker="o", lw=0.6, ms=3, alpha=0.6)
    color, dashes, marker = PALETTE[j % len(PALETTE)]
    return dict(color=color, ls=dashes, marker=marker, lw=1.2, ms=5)


# ----------------------------------------------------------------------------- per key

def _key_value_text(key: str, value: Any) -> str:
    """``key = value`` in words and display unit ("track speed = 1.5 m/s")."""
    scale, unit = display_unit(column_unit(key))
    shown = f" {unit}" if unit and unit != "1" else ""
    return f"{column_words(key)} = {value * scale:.4g}{shown}"


def _key_lines(points: Sequence[SweepPoint], key: str, others: list[str], varied: list[str],
               ) -> list[tuple[str, list[SweepPoint]]]:
    """The lines of a figure against ``key``: per case and combination of the ``others``
    keys' values, (legend text, its points by value of ``key``). Points that share no other
    key's values (e.g. Latin hypercube samples) are one line of loose markers per case."""
    lines: dict[tuple, list[SweepPoint]] = {}
    for p in points:
        if key in p.values:
            ident = (_case_text(p.case, varied), tuple(p.values.get(k) for k in others))
            lines.setdefault(ident, []).append(p)
    scattered = len(lines) > 1 and all(len(ps) == 1 for ps in lines.values())
    if scattered:   # e.g. Latin hypercube samples
        merged: dict[tuple, list[SweepPoint]] = {}
        for (case, _), ps in lines.items():
            merged.setdefault((case, ()), []).extend(ps)
        lines = merged
    out = []
    for (case, other), ps in sorted(lines.items(), key=lambda item: (
            item[0][0], [(v is None, v if v is not None else 0.0) for v in item[0][1]])):
        words = ([case] if case else []) + [
            _key_value_text(k, v) for k, v in zip(others, other, strict=False)
            if v is not None] + ([SCATTER_TEXT] if scattered else [])
        out.append((", ".join(words) or "runs", sorted(ps, key=lambda p: p.values[key])))
    return out


def _key_figure(points: Sequence[SweepPoint], panels: Sequence[Panel], key: str,
                swept: list[str], heading: str) -> Figure:
    """``panels`` against swept ``key``: a line per case and combination of the other keys
    (see :func:`_key_lines`), ± std error bars only where a point has 2+ seeds."""
    shared, varied = _shared_case(points)
    lines = _key_lines(points, key, [k for k in swept if k != key], varied)
    labelled = len(lines) <= MAX_LABELLED_LINES
    labels = ([text for text, _ in lines] if labelled and (len(lines) > 1 or SCATTER_TEXT
                                                           in lines[0][0]) else [])
    fig, axes, lowest = _panel_grid(len(panels), _legend_rows(labels) if labels else
                                    (0 if labelled else 1))
    k_scale = display_unit(column_unit(key))[0]
    handles = []
    for ax, panel, low in zip(axes, panels, lowest, strict=True):
        for j, (text, ps) in enumerate(lines):
            x = np.array([float(p.values[key]) for p in ps]) * k_scale
            stats = np.array([p.stats(panel.key) for p in ps], dtype=float).reshape(-1, 3)
            y, std = stats[:, 0] * panel.scale, stats[:, 1] * panel.scale
            ls = "none" if len(ps) > 1 and _is_scatter(ps, swept, key) else None
            style: dict[str, Any] = _style(j, labelled) | ({"ls": ls} if ls else {})
            if (stats[:, 2] >= 2).any():
                drawn = ax.errorbar(x, y, yerr=np.where(stats[:, 2] >= 2, std, 0.0),
                                    capsize=3, label=text, **style)
            else:
                (drawn,) = ax.plot(x, y, label=text, **style)
            if ax is axes[0]:
                handles.append(drawn)
        ax.set_title(panel.title, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
        xs = [float(p.values[key]) for p in points if key in p.values]
        if min(xs) > 0 and max(xs) / min(xs) > LOG_X_RATIO:
            ax.set_xscale("log")
        if low:
            ax.set_xlabel(column_label(key), fontsize=9)
    if labels:
        _legend(fig, handles, labels)
    elif not labelled:
        fig.legend(handles[:1], [f"{len(lines)} lines: one per combination of the other "
                                 "swept keys"], loc="outside lower center", fontsize=9,
                   frameon=False)
    fig.suptitle(f"{heading} against {column_words(key)}\n"
                 f"{shared + '; ' if shared else ''}{_seed_text(points)}", fontsize=10)
    return fig


def _is_scatter(points: Sequence[SweepPoint], swept: list[str], key: str) -> bool:
    """Whether a line's points differ in other keys too (loose samples, not a curve)."""
    others = [k for k in swept if k != key]
    return len({tuple(p.values.get(k) for k in others) for p in points}) > 1


# ----------------------------------------------------------------------------- per case

def _case_figure(points: Sequence[SweepPoint], panels: Sequence[Panel], heading: str) -> Figure:
    """Grouped bars: a group per scenario, a bar per other case (the case fields that
    differ: architecture, controller, ...), ± std error bars only with 2+ seeds."""
    shared, varied = _shared_case(points)
    scenarios = list(dict.fromkeys(str(p.case.get("scenario")) for p in points))
    fields = [f for f in varied if f != "scenario"]
    bars = list(dict.fromkeys(_case_text(p.case, fields) for p in points))
    labels = bars if fields else []
    fig, axes, _ = _panel_grid(len(panels), _legend_rows(labels))
    width = 0.8 / len(bars)
    handles = []
    for ax, panel in zip(axes, panels, strict=True):
        for j, bar in enumerate(bars):
            stats = np.full((len(scenarios), 3), np.nan)
            for p in points:
                if _case_text(p.case, fields) == bar:
                    stats[scenarios.index(str(p.case.get("scenario")))] = p.stats(panel.key)
            color, hatch = BAR_STYLES[j % len(BAR_STYLES)]
            spread = stats[:, 2] >= 2
            drawn = ax.bar(np.arange(len(scenarios)) - 0.4 + width * (j + 0.5),
                           stats[:, 0] * panel.scale, width, color=color, hatch=hatch,
                           edgecolor="black", lw=0.5, label=bar,
                           yerr=np.where(spread, stats[:, 1], 0.0) * panel.scale
                           if spread.any() else None, capsize=3)
            if ax is axes[0]:
                handles.append(drawn)
        ax.set_xticks(range(len(scenarios)), scenarios, fontsize=8)
        ax.set_xlim(-0.5, len(scenarios) - 0.5)
        ax.axhline(0.0, color="black", lw=0.6)
        ax.set_title(panel.title, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(axis="y", alpha=0.3)
    if labels:
        _legend(fig, handles, labels)
    fig.suptitle(f"{heading} per scenario\n{shared + '; ' if shared else ''}"
                 f"{_seed_text(points)}", fontsize=10)
    return fig
