"""The figure of a ``trackmj drive`` run (:func:`drive_figure`, PNG): the idler force, the
strand tensions and the derailment indicators over time against their thresholds, with the
intervals where a check failed shaded. Display units: kN, mm."""

from __future__ import annotations

from collections.abc import Mapping
from itertools import pairwise
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.ticker import MaxNLocator

from trackmj.results.figure_style import legend_above, save_png
from trackmj.results.store import passive_text, running_text

FAIL_COLOURS = {"slack_strand": "#E69F00", "links_off_envelope": "#CC79A7",
                "sprocket_disengaged": "#0072B2", "derailed": "#D55E00"}
"""Shade of the intervals where each derailment check failed."""
THRESHOLD_COLOUR = "#D55E00"
CHECK_COLOUR = "#009E73"
LEAST_COLOUR = "#56B4E9"
"""The upper strand's least pin tension at the checks (a readout; the slack check reads its
peak over the window, in :data:`CHECK_COLOUR`)."""
RAW_ROWS = 2000
BINS = 200
"""Up to :data:`RAW_ROWS` rows a signal is drawn as it is, beyond as min-max bands and
means over :data:`BINS` bins (50 ms at 10 s)."""


def failing_spans(t: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) [s] of the runs of rows where ``flag`` is 1 (NaN counts as 0); a run
    ends at the time of the first row after it, or at the last row."""
    on = np.nan_to_num(flag, nan=0.0) > 0.5
    edges = np.flatnonzero(np.diff(on.astype(np.int8))) + 1
    bounds = np.concatenate([[0], edges, [len(on)]])
    return [(float(t[a]), float(t[min(b, len(t) - 1)]))
            for a, b in pairwise(bounds) if on[a]]


def _shade(ax: Axes, t: np.ndarray, flag: np.ndarray, check: str, label: str | None) -> None:
    """Shade where ``check`` failed (its held flag column ``flag``), one legend entry."""
    for k, (a, b) in enumerate(failing_spans(t, flag)):
        ax.axvspan(a, b, color=FAIL_COLOURS[check], alpha=0.25, lw=0,
                   label=label if k == 0 else None)


def _checked(t: np.ndarray, interval_s: float) -> np.ndarray:
    """Rows of the derailment checks: t a whole multiple of ``interval_s`` [s]."""
    n = t / interval_s
    return np.flatnonzero((np.abs(n - np.round(n)) < 1e-4) & (n > 0.5))


def drive_figure(metrics: Mapping[str, Any], series: Mapping[str, np.ndarray],
                 path: str | Path) -> Path:
    """One drive run (``metrics`` and ``series`` as :mod:`trackmj.sim.drive` writes them,
    SI): idler force [kN]; upper-strand and lower-run mean tensions, the upper strand's
    least pin tension at each check and the highest it rose over the slack window ending
    there (the slack check's reading) against the slack threshold [kN]; the largest envelope
    excursion against its threshold [mm]; the seated sprocket pins against their minimum.
    The derailment values are those of each check, held to the next; shaded: where a
    check failed (the whole run's ``derailed`` in the top panel). Written to ``path``."""
    t = series["t_s"]
    table = metrics["derailment"]
    interval = float(metrics["derailment_check_interval_s"])
    rows = _checked(t, interval)
    fig, axes = plt.subplots(4, 1, figsize=(12, 11), sharex=True, layout="constrained",
                             height_ratios=(1.0, 1.3, 1.0, 0.8))
    ax_f, ax_t, ax_e, ax_s = axes

    _band(ax_f, t, series["idler_force_N"] / 1e3, "black",
          "idler force (tensioner on the idler carrier)")
    _shade(ax_f, t, series["derailed"], "derailed", "derailed: a check failing (to the next)")
    ax_f.set_ylabel("idler force [kN]")

    slack = table["slack_strand"]["threshold"]
    _band(ax_t, t, series["upper_strand_tension_N"] / 1e3, "black",
          "upper strand, mean pin tension")
    _band(ax_t, t, series["lower_strand_tension_N"] / 1e3, "#0072B2",
          "sprocket lower run, mean pin tension", ls="--")
    _indicator(ax_t, t, series["upper_strand_tension_min_N"] / 1e3, rows,
               "upper strand, least pin tension at each check", LEAST_COLOUR)
    _indicator(ax_t, t, series["upper_strand_tension_held_N"] / 1e3, rows,
               f"its peak over the {table['slack_strand']['window_s']:g} s before each check "
               "(slack below the threshold)")
    ax_t.axhline(slack / 1e3, color=THRESHOLD_COLOUR, ls=":", lw=1.4,
                 label=f"slack below {slack / 1e3:g} kN")
    _shade(ax_t, t, series["slack_strand"], "slack_strand", "slack strand (to the next check)")
    ax_t.set_ylabel("pin tension [kN]")

    limit = table["links_off_envelope"]["threshold"]
    _indicator(ax_e, t, series["envelope_excursion_max_m"] * 1e3, rows,
               "largest pin excursion outside the home envelope at each check")
    ax_e.axhline(limit * 1e3, color=THRESHOLD_COLOUR, ls=":", lw=1.4,
                 label=f"off envelope above {limit * 1e3:.0f} mm")
    _shade(ax_e, t, series["links_off_envelope"], "links_off_envelope",
           "links off envelope (to the next check)")
    ax_e.set_ylim(bottom=0.0)
    ax_e.set_ylabel("excursion [mm]")

    least = table["sprocket_disengaged"]["threshold"]
    seat_mm = table["sprocket_disengaged"]["seat_tolerance_m"] * 1e3
    _indicator(ax_s, t, series["sprocket_seated_pins"], rows,
               f"pins seated on the sprocket (within {seat_mm:.0f} mm of its pitch circle) "
               "at each check")
    ax_s.axhline(least, color=THRESHOLD_COLOUR, ls=":", lw=1.4,
                 label=f"disengaged below {least:g} pins")
    _shade(ax_s, t, series["sprocket_disengaged"], "sprocket_disengaged",
           "sprocket disengaged (to the next check)")
    ax_s.set_ylim(bottom=0.0)
    ax_s.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax_s.set_ylabel("seated pins [-]")
    ax_s.set_xlabel("time [s]")
    ax_s.set_xlim(0.0, float(t[-1]))

    stop_s = metrics.get("stop_s")
    for ax in axes:
        if stop_s is not None:
            ax.axvline(stop_s, color="0.4", ls="--", lw=1.0,
                       label="commanded to 0 (abrupt stop)" if ax is ax_f else None)
        ax.grid(alpha=0.3)
        legend_above(ax, ncol=2)
    fig.suptitle(_title(metrics), fontsize=11)
    return save_png(fig, Path(path))


def _band(ax: Axes, t: np.ndarray, x: np.ndarray, colour: str, label: str, ls: str = "-"
          ) -> None:
    """A 1 kHz signal as it is up to :data:`RAW_ROWS` rows; longer, as its min-max band
    (light) and mean (line) over :data:`BINS` bins."""
    n = len(t) // BINS
    if len(t) <= RAW_ROWS:
        ax.plot(t, x, color=colour, lw=0.7, ls=ls, label=label)
        return
    m = len(t) // n * n
    tb, xb = t[:m].reshape(-1, n).mean(axis=1), x[:m].reshape(-1, n)
    ax.fill_between(tb, xb.min(axis=1), xb.max(axis=1), color=colour, alpha=0.15, lw=0)
    bin_ms = n * float(t[1] - t[0]) * 1e3
    ax.plot(tb, xb.mean(axis=1), color=colour, lw=0.9, ls=ls,
            label=f"{label} ({bin_ms:.0f} ms mean, band min-max)")


def _indicator(ax: Axes, t: np.ndarray, held: np.ndarray, rows: np.ndarray, label: str,
               colour: str = CHECK_COLOUR) -> None:
    """A derailment value held between checks (line) with a marker at each check."""
    ax.plot(t, held, color=colour, lw=1.6, label=label, zorder=5)
    ax.plot(t[rows], held[rows], ls="none", marker="o", ms=3.5, color=colour, zorder=5)


def _title(metrics: Mapping[str, Any]) -> str:
    """Machine, speed (and grade), duration (and a stop) and tensioner (a passive one's
    preload beside its settled force, :func:`~trackmj.results.store.passive_text`); below,
    the derailment count with how the checks are made."""
    tensioner = (passive_text(metrics) if "preload_N" in metrics
                 else f"tensioner {metrics['tensioner'].get('file', '')}")
    failed = metrics["derailment_checks_failed"]
    slope = running_text({"grade": metrics.get("grade")})
    stop = "" if metrics.get("stop_s") is None else f", stopped at {metrics['stop_s']:g} s"
    return (f"drive: {metrics['machine']}, {metrics['speed_m_s']:g} m/s{slope}, "
            f"{metrics['duration_s']:g} s{stop}; {tensioner}\nderailment checks failed "
            f"{failed} of {metrics['derailment_checks']} (every "
            f"{metrics['derailment_check_interval_s']:g} s, values held between checks)")
