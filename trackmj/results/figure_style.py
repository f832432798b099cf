"""The look every figure shares (PNG, matplotlib Agg).

Every figure reads in colour and in grayscale: each architecture, controller and energy term
has its own colour (Okabe-Ito, colour-blind safe) AND line style, marker or hatch
(:data:`STYLES`, :data:`ENERGY_STYLES`); a name without an entry gets a spare style
(:func:`style`). Legends sit above the panels, outside the data (:func:`legend_above`); raw
signals are drawn as a light min-max band (:func:`envelope`); figures are written whole or
not at all (:func:`save_png`).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from trackmj.io import write_bytes_atomic

STYLES: dict[str, dict[str, Any]] = {
    "tp": dict(color="black", linestyle="-", marker="o"),
    "tp-weak": dict(color="#56B4E9", linestyle=(0, (1, 1)), marker="v"),
    "dp-a": dict(color="#E69F00", linestyle="--", marker="^"),
    "dp-b": dict(color="#0072B2", linestyle="-.", marker="s"),
    "nmpc": dict(color="black", linestyle="-", marker="o"),
    "lmpc": dict(color="#D55E00", linestyle="--", marker="D"),
    "pid": dict(color="#009E73", linestyle="-.", marker="P"),
}
"""Line style of each architecture and controller (colour, dash pattern, marker)."""
SPARE_STYLES = (dict(color="#CC79A7", linestyle=(0, (5, 1, 1, 1, 1, 1)), marker="X"),
                dict(color="#999999", linestyle=(0, (3, 2)), marker="*"))
"""Line styles of the names :data:`STYLES` has no entry for, by the line's index."""
ENERGY_STYLES: dict[str, tuple[str, str]] = {
    "relief": ("#E69F00", ""), "throttling": ("#56B4E9", "//"), "leakage": ("#009E73", "\\\\"),
    "friction": ("#F0E442", ".."), "makeup": ("#0072B2", "xx"),
    "stored_change": ("#D55E00", "--"), "mechanical": ("#CC79A7", "oo"),
    "residual": ("#999999", "++"), "return_line": ("#44AA99", "||"),
    "endstop": ("#332288", "o"), "numerical": ("#DDCC77", "x"),
    "pump_losses": ("#882255", "\\\\//")}
"""Colour and hatch of each energy term in the breakdown bars."""
RAW_COLOUR = "0.78"
BAND_COLOUR = "#009E73"
EVENT_COLOUR = "0.55"
ENVELOPE_BIN_S = 0.05
"""Raw signals are drawn as their min-max band over 50 ms bins (the 1 kHz trace would be a
solid block at full-run scale)."""
MARKERS_PER_LINE = 12


def save_png(fig: Figure, path: Path) -> Path:
    """``fig`` as PNG (100 dpi) at ``path``, atomically; the figure is closed."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    write_bytes_atomic(path, buffer.getvalue())
    return path


def style(label: str, index: int = 0) -> dict[str, Any]:
    """Line style of ``label`` (an architecture or controller); a spare one otherwise."""
    return STYLES.get(label, SPARE_STYLES[index % len(SPARE_STYLES)])


def envelope(t: np.ndarray, x: np.ndarray, bin_s: float = ENVELOPE_BIN_S,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bin centres [s], min, max) of ``x`` over consecutive bins of ``bin_s``."""
    n = max(1, round(bin_s / float(np.median(np.diff(t)))))
    m = len(t) // n * n
    tb, xb = t[:m].reshape(-1, n), x[:m].reshape(-1, n)
    return tb.mean(axis=1), xb.min(axis=1), xb.max(axis=1)


def legend_above(ax: Axes, ncol: int | None = None, **kwargs: Any) -> None:
    """The legend of ``ax`` just above it, ``ncol`` columns (default: one row)."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.0, 1.01),
                  ncol=ncol or len(handles), frameon=False, fontsize=9,
                  handlelength=3.0, borderaxespad=0.0, columnspacing=1.2, **kwargs)


def marker_step(n: int) -> int:
    """Every how many of ``n`` points a line carries a marker (:data:`MARKERS_PER_LINE`)."""
    return max(n // MARKERS_PER_LINE, 1)
