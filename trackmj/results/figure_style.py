"""The look every figure shares (PNG, matplotlib Agg).

Every figure reads in colour and in grayscale: each architecture and controller has its own
colour (Okabe-Ito, colour-blind safe) AND line style and marker (:data:`STYLES`); a name
without an entry gets a spare style (:func:`style`). Legends sit above the panels, outside
the data (:func:`legend_above`); raw signals are drawn as a light min-max band
(:func:`envelope`); figures are written whole or not at all (:func:`save_png`). Numbers in
labels carry three significant digits (:func:`number`, :func:`span`); titles name the
machine a run was made on (:func:`machine_of`, :func:`machines_text`) and the measured log
it was compared with (:func:`measured_log_of`).
"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from trackmj.io import write_bytes_atomic
from trackmj.results.store import Result

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
RAW_COLOUR = "0.78"
BAND_COLOUR = "#009E73"
EVENT_COLOUR = "0.55"
MEASURED_COLOUR = "#D55E00"
"""Colour of a measured log's channels overlaid on a run (low-passed: dashed)."""
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


def number(value: float, digits: int = 3) -> str:
    """``value`` to ``digits`` significant digits, positional, without trailing zeros
    (13.3333 -> "13.3", 20.0 -> "20", 1049.7 -> "1050", 0.000123 -> "0.000123")."""
    return str(np.format_float_positional(value, precision=digits, unique=False,
                                          fractional=False, trim="-"))


def span(low: float, high: float, unit: str) -> str:
    """A band or window as text: "13.3–26.7 kN" (values in the display unit ``unit``)."""
    return f"{number(low)}–{number(high)} {unit}"


def machine_of(result: Result) -> str | None:
    """The machine (crawler) a run was made on: ``metadata["machine"]`` (results that also
    record the ``host``), else the ``machine`` of its ``files`` (older results, whose
    ``machine`` was the computer); None if neither says."""
    meta = result.metadata
    if "host" in meta:
        return meta.get("machine") or None
    try:
        files = json.loads(meta.get("files", "{}"))
    except json.JSONDecodeError:
        return None
    return files.get("machine") if isinstance(files, dict) else None


def machines_text(results: Sequence[Result]) -> str | None:
    """The machine(s) of ``results`` for a title ("m113"; "lf1352, m113" if they differ);
    None if no result names one."""
    names = list(dict.fromkeys(m for m in map(machine_of, results) if m))
    return ", ".join(names) or None


def measured_log_of(result: Result) -> str | None:
    """File name of the measured log a run was compared with (``metrics["measured_log"]``
    or the table metadata's ``measured_log``, a JSON table with ``file``); None without."""
    table = result.metrics.get("measured_log")
    if not isinstance(table, dict):
        try:
            table = json.loads(result.metadata.get("measured_log", "{}"))
        except json.JSONDecodeError:
            return None
    name = table.get("file") if isinstance(table, dict) else None
    return Path(str(name)).name if name else None
