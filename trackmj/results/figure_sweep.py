"""The figures of a sweep's results table (:func:`sweep_figures`, PNG): a metric against each
swept parameter (mean ± std over seeds, a line per case), or, without swept parameters,
grouped bars per scenario and case. Drawn without pyplot (no global figure state), each in
the display unit of :func:`trackmj.results.columns.display_unit`."""

from __future__ import annotations

import io
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from trackmj.io import write_bytes_atomic
from trackmj.results.columns import (
    column_label,
    column_unit,
    column_words,
    display_unit,
    is_key_column,
)
from trackmj.results.seed_stats import finite, mean_std
from trackmj.scenarios.load import builtin_names

CASE = ("scenario", "architecture", "controller", "estimator", "variant", "duration_s",
        "inputs")
"""Columns of a results row that make one line of a sweep figure (with the other swept
parameters)."""
NOT_METRICS = ("run_key", "point", "scenario", "architecture", "controller", "estimator",
               "variant", "seed", "duration_s", "inputs", "error")
"""Columns of a results row that are not metrics (no figure of their own)."""
LINE_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ((0, (5, 1, 1, 1)), "v"),
               ((0, (1, 3)), "P"))
"""Line style and marker of the lines of one case (the other swept parameters' values)."""
CONSTANT_REL = 1e-9
"""A metric whose finite values differ by less than this (relative) does not vary: no
figure."""
MAX_LABELLED_LINES = 6
"""More lines per case than this are drawn thin and unlabelled."""
HATCHES = ("", "//", "..", "xx", "\\\\", "++", "oo", "--")
"""Bar hatches, so that the cases of a bar figure read in grayscale too."""


def varies(values: Sequence[Any]) -> bool:
    """Whether the finite ``values`` differ by more than :data:`CONSTANT_REL` (relative)."""
    v = finite(values)
    return len(v) > 1 and max(v) - min(v) > CONSTANT_REL * max(abs(max(v)), abs(min(v)))


def sweep_figures(rows: Sequence[Mapping[str, Any]], fig_dir: Path, *,
                  redraw: bool = True) -> list[Path]:
    """``fig_dir/<metric>.png`` for every metric (and the wall time) of the results ``rows``
    (failed runs left out by the caller) that varies across them: one panel per swept
    parameter, the metric's mean ± std over seeds at each parameter point, a line per case
    (scenario, architecture, controller, ...) and per combination of the other swept
    parameters (points that share none, e.g. Latin hypercube samples, stand alone). Without
    swept parameters (e.g. a controller comparison): bars, a group per scenario, a bar per
    case, mean ± std over seeds. Metrics with the same value in every run (a metric stored
    twice, e.g. ``friction_loss_J`` and ``energy_J.friction``) share one figure, named after
    the first and naming the others. ``redraw=False`` keeps a figure that exists. Returns
    the paths of the figures."""
    rows = [dict(r) for r in rows]
    if not rows:
        return []
    swept = sorted({k for r in rows for k in r if is_key_column(k)})
    paths = []
    for metric, *also in _varying_metrics(rows, swept):
        path = fig_dir / f"{metric}.png"
        paths.append(path)
        if path.is_file() and not redraw:
            continue
        fig = _metric_figure(rows, metric, swept) if swept else _case_figure(rows, metric)
        if also:
            fig.text(0.995, 0.005, "the same values: " + ", ".join(also), ha="right",
                     va="bottom", fontsize=9, color="0.35")
        _save_figure(fig, path)
    return paths


def _varying_metrics(rows: list[dict[str, Any]], swept: list[str]) -> list[list[str]]:
    """The metrics that vary across ``rows``, grouped by their series of values (a metric
    stored twice is one group, top-level names first), the groups sorted."""
    skip = set(NOT_METRICS) | set(swept)
    metrics = sorted({k for r in rows for k in r if k not in skip
                      and isinstance(r[k], int | float) and not isinstance(r[k], bool)})
    same: dict[tuple, list[str]] = {}      # one figure per series of values: drawn once
    for metric in sorted(metrics, key=lambda m: (m.count("."), m)):   # top-level names first
        values = [r.get(metric) for r in rows]
        if varies(values):
            same.setdefault(tuple(None if v is None or v != v else v for v in values),
                            []).append(metric)
    return sorted(same.values())


def _save_figure(fig: Figure, path: Path) -> Path:
    """A pyplot-free :class:`matplotlib.figure.Figure` as PNG at ``path``, atomically."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    write_bytes_atomic(path, buffer.getvalue())
    return path


def scenario_order(names: Iterable[str]) -> list[str]:
    """``names`` with the built-in scenarios first in their order (W1-W5, NL1), then the
    others by name."""
    builtin = builtin_names()
    return sorted(names, key=lambda n: (builtin.index(n), "") if n in builtin
                  else (len(builtin), n))


def _metric_figure(rows: list[dict[str, Any]], metric: str, swept: list[str]) -> Figure:
    """One panel per swept key: the metric's mean ± std over seeds against the key, a
    colour per case, a line style per combination of the other keys."""
    cases = sorted({tuple(r.get(c) for c in CASE) for r in rows}, key=str)
    m_scale = display_unit(column_unit(metric))[0]
    width, height = 4.8 * len(swept) + 0.8, 4.4
    fig = Figure(figsize=(width, height))
    axes = fig.subplots(1, len(swept), squeeze=False, sharey=True)[0]
    # fixed margins [in] instead of tight_layout, which draws the figure once more
    fig.subplots_adjust(left=0.85 / width, right=1.0 - 0.2 / width, bottom=0.6 / height,
                        top=1.0 - 0.45 / height, wspace=0.12)
    for ax, key in zip(axes, swept, strict=True):
        _key_panel(ax, rows, metric, key, [k for k in swept if k != key], cases, m_scale)
    axes[0].set_ylabel(column_label(metric))
    n_seeds = len({r["seed"] for r in rows})
    case_text = _case_label(cases[0], cases) if len(cases) == 1 else f"{len(cases)} cases"
    fig.suptitle(f"{column_words(metric)}: mean ± std over {n_seeds} "
                 f"seed{'s' * (n_seeds > 1)} ({case_text})", fontsize=10)
    return fig


def _key_panel(ax: Axes, rows: list[dict[str, Any]], metric: str, key: str, others: list[str],
               cases: list[tuple], m_scale: float) -> None:
    """The metric [display unit, × ``m_scale``] against swept ``key``: per case a colour,
    per combination of the ``others`` keys' values a line (log x axis over a wide range)."""
    colors = matplotlib.colormaps["tab10"]
    k_scale = display_unit(column_unit(key))[0]
    for c, case in enumerate(cases):
        series, scatter = _case_series(rows, case, metric, key, others)
        labelled = len(series) <= MAX_LABELLED_LINES
        for j, (line, points) in enumerate(series):
            x = sorted(points)
            stats = np.array([mean_std(points[v])[:2] for v in x])
            style, marker = LINE_STYLES[j % len(LINE_STYLES)]
            joined = len(x) > 1 and not scatter
            ax.errorbar(np.array(x, dtype=float) * k_scale, stats[:, 0] * m_scale,
                        yerr=stats[:, 1] * m_scale, color=colors(c % 10), marker=marker,
                        ms=4, capsize=3, lw=1.0 if labelled else 0.6,
                        ls=style if joined else "none", alpha=1.0 if labelled else 0.5,
                        label=_series_label(case, cases, others, line)
                        if labelled or j == 0 else None)
    xs = [float(r[key]) for r in rows if r.get(key) is not None]
    if min(xs) > 0 and max(xs) / min(xs) > 30:
        ax.set_xscale("log")
    ax.set_xlabel(column_label(key), fontsize=9)
    ax.grid(alpha=0.3)
    if len(ax.get_legend_handles_labels()[1]) > 1 or len(cases) > 1:
        ax.legend(fontsize=9, loc="best")


def _case_series(rows: list[dict[str, Any]], case: tuple, metric: str, key: str,
                 others: list[str]) -> tuple[list[tuple[tuple, dict[Any, list[Any]]]], bool]:
    """(series, scattered) of one case: a series per combination of the ``others`` keys'
    values, each ``key`` value -> the metric's values (one per seed); scattered: no two
    points share the other keys' values (e.g. LHS samples), one series of loose points."""
    lines: dict[tuple, dict[Any, list[Any]]] = {}
    for r in rows:
        if tuple(r.get(n) for n in CASE) == case and key in r:
            lines.setdefault(tuple(r.get(k) for k in others), {}).setdefault(
                r[key], []).append(r.get(metric))
    series = sorted(lines.items(), key=lambda item: [_sortable(v) for v in item[0]])
    scatter = len(series) > 1 and all(len(points) == 1 for _, points in series)
    if scatter:   # e.g. LHS samples: no two points share the other keys' values
        series = [((), {x: ys for _, points in series for x, ys in points.items()})]
    return series, scatter


def _case_figure(rows: list[dict[str, Any]], metric: str) -> Figure:
    """Grouped bars: a group per scenario, a bar per other case (architecture, controller,
    ...: the fields that differ) with its mean ± std over seeds and its value above it."""
    scenarios = scenario_order({r["scenario"] for r in rows})
    cases = sorted({tuple(r.get(c) for c in CASE[1:]) for r in rows}, key=str)
    labels = [_case_label(("", *case), [("", *c) for c in cases]).strip() for case in cases]
    width, height = max(6.0, 1.1 * len(scenarios) * max(1, len(cases)) / 2 + 2.6), 4.4
    fig = Figure(figsize=(width, height))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.85 / width, right=1.0 - 1.7 / width, bottom=0.6 / height,
                        top=1.0 - 0.45 / height)
    measured = _case_bars(ax, rows, metric, scenarios, cases, labels)
    for i in np.flatnonzero(~measured).tolist():    # e.g. a settling time where nothing steps
        ax.text(i, 0.0, "no value", ha="center", va="bottom", fontsize=9, color="0.4")
    ax.set_xticks(range(len(scenarios)), scenarios)
    ax.set_xlim(-0.5, len(scenarios) - 0.5)      # groups without a value keep their place
    ax.axhline(0.0, color="black", lw=0.6)
    ax.grid(axis="y", alpha=0.3)
    ax.set_ylabel(column_label(metric))
    ax.set_xlabel("scenario")
    ax.legend(fontsize=9, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    n_seeds = len({r["seed"] for r in rows})
    fig.suptitle(f"{column_words(metric)}: mean ± std over {n_seeds} "
                 f"seed{'s' * (n_seeds > 1)}", fontsize=10)
    return fig


def _case_bars(ax: Axes, rows: list[dict[str, Any]], metric: str, scenarios: list[str],
               cases: list[tuple], labels: list[str]) -> np.ndarray:
    """A bar per case in each scenario's group at the metric's mean ± std over seeds
    [display unit], its value above the error bar; returns which groups have a value
    (bool, one per scenario)."""
    colors = matplotlib.colormaps["tab10"]
    m_scale = display_unit(column_unit(metric))[0]
    bar = 0.8 / len(cases)
    measured = np.zeros(len(scenarios), bool)
    for j, (case, label) in enumerate(zip(cases, labels, strict=True)):
        stats = np.array([mean_std([r.get(metric) for r in rows if r["scenario"] == sc
                                    and tuple(r.get(c) for c in CASE[1:]) == case])[:2]
                          for sc in scenarios]) * m_scale
        measured |= np.isfinite(stats[:, 0])
        x = np.arange(len(scenarios)) - 0.4 + bar * (j + 0.5)
        ax.bar(x, stats[:, 0], bar, yerr=stats[:, 1], capsize=2, color=colors(j % 10),
               hatch=HATCHES[j % len(HATCHES)], edgecolor="black", lw=0.5, label=label)
        for xi, (value, std) in zip(x, stats, strict=True):   # above the error bar
            if math.isfinite(value):
                ax.text(xi, value + std if value >= 0 else value - std, f"{value:.3g}",
                        ha="center", va="bottom" if value >= 0 else "top", fontsize=9)
    return measured


def _sortable(value: Any) -> tuple[int, Any]:
    return (1, 0.0) if value is None else (0, value)


def _series_label(case: tuple, cases: list[tuple], others: list[str], line: tuple) -> str:
    """Legend text: the case (if there are several) and the other keys' values."""
    parts = [_case_label(case, cases)] if len(cases) > 1 else []
    for key, value in zip(others, line, strict=False):   # () for scattered samples
        if value is not None:
            scale, unit = display_unit(column_unit(key))
            shown = f" {unit}" if unit and unit != "1" else ""
            parts.append(f"{column_words(key)} = {value * scale:.4g}{shown}")
    return ", ".join(parts) or _case_label(case, cases)


def _case_label(case: tuple, cases: list[tuple]) -> str:
    """The case fields that differ between cases (all of them if there is one case:
    scenario, architecture, controller)."""
    varying = [i for i in range(len(CASE)) if len({c[i] for c in cases}) > 1]
    shown = varying or [0, 1, 2]
    return " ".join(str(case[i]) for i in shown if CASE[i] != "inputs") or "runs"
