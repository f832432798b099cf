"""The figure of a calibration (``trackmj calibrate``): the estimates with their units, and per
log and channel the measured trace against the start and the fitted run, with the residual.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes

from trackmj.ports import COUPLING_STEP_S
from trackmj.results.columns import display_unit
from trackmj.results.figure_compare import CHANNEL_DISPLAY
from trackmj.results.figure_style import legend_above, save_png
from trackmj.results.measured import run_grid


@dataclass(frozen=True)
class FittedLog:
    """One log of a fit: its file name and SHA-256, and the measured, start and fitted
    channels on the run's grid (SI name -> (steps,) values, the same names in each)."""

    file: str
    sha256: str
    measured: Mapping[str, np.ndarray]
    start: Mapping[str, np.ndarray]
    fitted: Mapping[str, np.ndarray]


MEASURED_COLOUR = "#E69F00"
"""The log's trace on the calibration figure: wide and behind the simulated ones."""
START_COLOUR = "#0072B2"
RESIDUAL_MEAN_COLOUR = "#D55E00"
RESIDUAL_MEAN_S = 0.05
"""The residual panels draw the 1 ms residual and its means over 50 ms: a model error
shows as a drift of the means, sensor noise averages out of them."""


def estimate_lines(doc: Mapping[str, Any]) -> list[str]:
    """One line per fitted key: estimate and 95 % interval in the key's display unit
    (:func:`trackmj.results.columns.display_unit` of the unit its file declares)."""
    lines = []
    for key, value in doc["estimates"].items():
        scale, unit = display_unit(doc["units"]["estimates"][key])
        low, high = doc["intervals"][key]
        unit = "" if unit in ("", "1") else f" {unit}"
        bound = ", at a bound" if doc["at_bound"][key] else ""
        bound += "" if doc["determined"][key] else ", not determined: the bounds"
        lines.append(f"{key} = {value * scale:.4g}{unit}   (95 %: {low * scale:.4g} .. "
                     f"{high * scale:.4g}{unit}; start {doc['start'][key] * scale:.4g}{unit}"
                     f"{bound})")
    return lines


def calibration_figure(logs: Sequence[FittedLog], doc: Mapping[str, Any], path: Path) -> Path:
    """calibration.png: per log a column, per channel the measured trace (wide, behind),
    the start and the fitted run (thin, on top) and below it the residual measured −
    fitted with its RMS over the fitted samples; the estimates with units in the title."""
    t = run_grid(float(doc["duration_s"]))
    names = [c for c in CHANNEL_DISPLAY if any(c in log.measured for log in logs)]
    width_in = max(9.0, 7.0 * len(logs))
    # the title's lines wrapped to the figure (~11 characters an inch at its size): a long
    # key with an interval and "not determined" ran off both edges of a one-log figure
    lines = [part for line in estimate_lines(doc)
             for part in textwrap.wrap(line, int(11 * width_in), subsequent_indent="    ")]
    fig, axes = plt.subplots(2 * len(names), len(logs), squeeze=False, sharex=True,
                             figsize=(width_in, 3.0 * len(names) + 0.9 + 0.2 * len(lines)),
                             height_ratios=[2.0, 1.0] * len(names), layout="constrained")
    for j, log in enumerate(logs):
        for i, channel in enumerate(names):
            ax, ax_res = axes[2 * i][j], axes[2 * i + 1][j]
            label, scale = CHANNEL_DISPLAY[channel]
            if channel in log.measured:
                _channel_panels(ax, ax_res, t, label, scale,
                                (log.measured[channel], log.start[channel],
                                 log.fitted[channel]),
                                float(doc["start_s"]))
            else:
                ax.text(0.5, 0.5, f"no {channel} in this log", ha="center", va="center",
                        transform=ax.transAxes, fontsize=9, color="0.4")
                ax.set_yticks([])
                ax_res.set_yticks([])
        axes[0][j].set_title(f"log {log.file} (sha256 {log.sha256[:12]})", fontsize=9,
                             loc="right")
        axes[-1][j].set_xlabel("time [s]")
    legend_above(next(ax for ax in axes[0] if ax.lines), ncol=3)
    fig.suptitle(f"calibration on {Path(str(doc['scenario'])).name}, {doc['duration_s']:g} "
                 f"s, seed {doc['seed']}, {doc['architecture']}\n" + "\n".join(lines),
                 fontsize=9)
    return save_png(fig, path)


def _channel_panels(ax: Axes, ax_res: Axes, t: np.ndarray, label: str, scale: float,
                    traces: tuple[np.ndarray, np.ndarray, np.ndarray], start_s: float) -> None:
    """One channel: measured, start and fitted on ``ax``; measured − fitted on ``ax_res``
    (display ``label`` "name [unit]" and ``scale`` from SI; ``traces`` SI, shape (steps,))."""
    measured, start, fitted = (x * scale for x in traces)
    ax.plot(t, measured, color=MEASURED_COLOUR, lw=2.4, alpha=0.75, zorder=1,
            label="measured")
    ax.plot(t, start, color=START_COLOUR, ls=(0, (1, 1.5)), lw=1.0, zorder=2,
            label="fit start")
    ax.plot(t, fitted, color="black", ls=(0, (5, 2)), lw=0.9, zorder=3, label="fitted")
    ax.set_ylabel(label)
    residual = measured - fitted
    fit = t >= start_s
    rms = float(np.sqrt(np.mean(residual[fit] ** 2)))
    unit = label[label.index("[") + 1: label.index("]")]
    m = max(1, round(RESIDUAL_MEAN_S / COUPLING_STEP_S))
    k = len(t) // m * m
    ax_res.plot(t, residual, color="0.55", lw=0.5)
    ax_res.plot(t[:k].reshape(-1, m).mean(axis=1), residual[:k].reshape(-1, m).mean(axis=1),
                color=RESIDUAL_MEAN_COLOUR, lw=1.4)
    ax_res.axhline(0.0, color="black", lw=0.6)
    ax_res.set_ylabel(f"meas. − fitted\n[{unit}]", fontsize=9)
    ax_res.text(0.995, 0.95, f"RMS {rms:.3g} {unit}; red: {RESIDUAL_MEAN_S * 1e3:g} ms means",
                transform=ax_res.transAxes,
                ha="right", va="top", fontsize=8,
                bbox=dict(facecolor="white", edgecolor="none", alpha=0.8, pad=1.0))
    if start_s > 0.0:
        for a in (ax, ax_res):
            a.axvspan(float(t[0]), start_s, color="0.9", zorder=0, lw=0)
        ax_res.text(0.5 * start_s, 0.95, "not fitted", ha="center", va="top", fontsize=8,
                    transform=ax_res.get_xaxis_transform())
    for a in (ax, ax_res):
        a.grid(alpha=0.3)
