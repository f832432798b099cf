"""Figures that compare runs (PNG). Display units: kN, MPa, kJ.

* :func:`overlay_figure`: several runs of one case overlaid (per architecture or per
  controller), zooms, prediction error against the reference architecture, energy breakdown
  bars.
* :func:`psd_figure`: tension and chassis-acceleration spectra with the bands marked.
* :func:`variants_figure`: a metric per parameter variant and architecture (W5).
* :func:`calibration_figure`: measured logs against a calibration's fitted run and its
  start.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.gridspec import GridSpecFromSubplotSpec

from trackmj.results.figure_energy import energy_bars
from trackmj.results.figure_panels import shade_events, tension_panel, zoom_windows
from trackmj.results.figure_style import (
    BAND_COLOUR,
    STYLES,
    legend_above,
    marker_step,
    save_png,
    style,
)
from trackmj.results.metric_windows import MetricWindows, windows_of
from trackmj.results.signals import lowpass
from trackmj.results.store import Result
from trackmj.sim.registry import REFERENCE_ARCHITECTURE

CHANNEL_DISPLAY: dict[str, tuple[str, float]] = {
    "tension_N": ("F_ten [kN]", 1e-3), "p_head_Pa": ("p_head [MPa]", 1e-6),
    "p_rod_Pa": ("p_rod [MPa]", 1e-6), "stroke_m": ("stroke [mm]", 1e3)}
"""Label and display scale of the channels a log is compared on."""


def _number(value: float, values: Sequence[float]) -> str:
    """Bar label: "–" if undefined, "0" if below 0.1 % of the largest bar, else 3 digits."""
    if not math.isfinite(value):
        return "–"
    largest = max((abs(v) for v in values if math.isfinite(v)), default=0.0)
    return "0" if abs(value) < 1e-3 * largest or value == 0.0 else f"{value:.3g}"


def _bars(ax: Axes, labels: Sequence[str], series: Mapping[str, Sequence[float]], unit: str,
          ylabel: str) -> None:
    """Grouped bars: one group per label, one hatched bar per series; values annotated. A
    series named after an architecture or controller takes its colour (else a grey; the
    reference architecture's bars have light edges)."""
    hatches, shades = ("", "//", "..", "xx"), ("0.35", "0.75", "0.55", "0.9")
    n = max(len(series), 1)
    width = 0.8 / n
    for j, (name, values) in enumerate(series.items()):
        x = np.arange(len(labels)) + (j - (n - 1) / 2) * width
        colour = STYLES[name]["color"] if name in STYLES else shades[j % 4]
        edge = "0.6" if name == REFERENCE_ARCHITECTURE else "black"
        bars = ax.bar(x, values, width=width, color=colour, hatch=hatches[j % 4],
                      edgecolor=edge, lw=0.5, label=name)
        ax.bar_label(bars, labels=[_number(v, values) for v in values], fontsize=9,
                     padding=1)
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xticks(range(len(labels)), labels, rotation=20)
    ax.set_ylabel(f"{ylabel} [{unit}]")
    ax.grid(axis="y", alpha=0.3)
    finite = [v for vals in series.values() for v in vals if math.isfinite(v)] or [0.0]
    low, high = min(min(finite), 0.0), max(max(finite), 0.0)
    pad = 0.18 * (high - low or 1.0)       # room for the value labels
    ax.set_ylim(low - pad if low < 0.0 else 0.0, high + pad)
    legend_above(ax, ncol=1)      # stacked: a narrow panel's entries would overlap its neighbour


def overlay_figure(results: Sequence[Result], path: str | Path, *,
                   label_by: str = "architecture",
                   predictions: Mapping[str, Mapping[str, Any]] | None = None,
                   title: str = "") -> Path:
    """Runs of one case overlaid, labelled by ``label_by`` (``architecture`` or
    ``controller``): low-passed tension (raw of the first run as a band), head pressure
    (low-passed) and the first run's supply pressure, zooms on the events, then bars:
    with ``predictions`` (label -> :func:`trackmj.results.comparison.prediction_vs_tp`) the
    prediction RMSE against the reference architecture (raw and low-passed), the
    peak-pressure error and the energy error; without, the tracking RMSE (raw and
    low-passed); and the energy breakdown of every run."""
    labels = [getattr(r, label_by) for r in results]
    runs = list(zip(labels, results, strict=True))
    w = windows_of(results[0])
    t_end = float(results[0].columns()["t_s"][-1])
    zooms = zoom_windows(w, t_end)[:4]
    bar_axes = 4 if predictions else 2
    fig = plt.figure(figsize=(17, 15), layout="constrained")
    grid = fig.add_gridspec(4, 1, height_ratios=(3.0, 2.0, 2.0, 3.0))
    ax_f = fig.add_subplot(grid[0])
    tension_panel(ax_f, runs, w)
    ax_f.set_xlabel("time [s]")
    legend_above(ax_f, ncol=5)
    _head_pressures(fig.add_subplot(grid[1], sharex=ax_f), runs, w, t_end)
    zoom_grid = grid[2].subgridspec(1, len(zooms))
    for k, (name, t0, t1) in enumerate(zooms):
        ax = fig.add_subplot(zoom_grid[k])
        tension_panel(ax, runs, w, (t0, t1), legend=False, raw_as_line=True)
        ax.set_title(f"zoom: {name}", fontsize=9, loc="left")
        ax.set_xlabel("time [s]")
    bars = grid[3].subgridspec(1, bar_axes, width_ratios=(*[1.0] * (bar_axes - 1), 2.4))
    if predictions:
        _prediction_bars(fig, bars, labels, predictions, w)
    else:
        _bars(fig.add_subplot(bars[0]), labels, {
            "raw": [r.metrics.get("rmse_N", math.nan) / 1e3 for r in results],
            f"{w.lowpass_cutoff_Hz:g} Hz low-pass":
                [r.metrics.get("rmse_lp_N", math.nan) / 1e3 for r in results]},
            "kN", "tracking RMSE")
    energy_bars(fig.add_subplot(bars[bar_axes - 1]), labels, results)
    first = results[0]
    fig.suptitle(title or f"{first.scenario} seed {first.seed}: " + ", ".join(labels))
    return save_png(fig, Path(path))


def _head_pressures(ax_p: Axes, runs: Sequence[tuple[str, Result]], w: MetricWindows,
                    t_end: float) -> None:
    """Each run's head pressure [MPa], low-passed and styled, and the first run's supply
    pressure."""
    for k, (label, res) in enumerate(runs):
        c = res.columns()
        ax_p.plot(c["t_s"], lowpass(c["t_s"], c["p_head_Pa"], w.lowpass_cutoff_Hz) / 1e6,
                  lw=1.2, markersize=5, markevery=marker_step(len(c["t_s"])),
                  markerfacecolor="white", label=f"{label} p_head", **style(label, k))
    label0, first = runs[0]
    supply = first.columns()["p_supply_Pa"]
    if np.isfinite(supply).any():
        ax_p.plot(first.columns()["t_s"], supply / 1e6, color="0.45", lw=1.0,
                  ls=(0, (4, 1, 1, 1)), label=f"{label0} p_supply")
    shade_events(ax_p, w, t_end, label=False)
    ax_p.set_ylabel("pressure [MPa]")
    ax_p.set_xlabel("time [s]")
    ax_p.grid(alpha=0.3)
    legend_above(ax_p, ncol=len(runs) + 1,
                 title=f"head pressure, {w.lowpass_cutoff_Hz:g} Hz low-pass")


def _prediction_bars(fig: Figure, bars: GridSpecFromSubplotSpec, labels: Sequence[str],
                     predictions: Mapping[str, Mapping[str, Any]], w: MetricWindows) -> None:
    """Bars of each run's prediction error against the reference architecture: F_ten RMSE
    (raw and low-passed) [kN], peak head pressure [MPa], energy [%] (named by the term
    compared) in the first three cells of ``bars``."""
    ref = REFERENCE_ARCHITECTURE
    others = [lab for lab in labels if lab in predictions and lab != ref]
    _bars(fig.add_subplot(bars[0]), others, {
        "raw": [predictions[o]["prediction_rmse_vs_tp_N"] / 1e3 for o in others],
        f"{w.lowpass_cutoff_Hz:g} Hz low-pass":
            [predictions[o]["prediction_rmse_vs_tp_lp_N"] / 1e3 for o in others]},
        "kN", f"F_ten RMSE vs {ref}")
    _bars(fig.add_subplot(bars[1]), others, {f"peak p_head − {ref}": [
        predictions[o]["peak_pressure_error_vs_tp_Pa"] / 1e6 for o in others]},
        "MPa", "peak pressure error")
    term = [predictions[o]["energy_error_term"] for o in others]
    _bars(fig.add_subplot(bars[2]), [f"{o}\n({t or 'none'})" for o, t in
                                     zip(others, term, strict=True)],
          {f"(E − E_{ref})/E_{ref}": [predictions[o]["energy_error_vs_tp_pct"]
                                      for o in others]}, "%", f"energy error vs {ref}")


def psd_figure(results: Sequence[Result], path: str | Path, *,
               label_by: str = "architecture", title: str = "") -> Path:
    """Tension and chassis vertical acceleration spectra (the runs' ``metrics["psd"]``,
    steady window) on log axes; the road's excitation band, the body-mode band and the
    tooth-passing band marked."""
    w = windows_of(results[0])
    fig, axes = plt.subplots(2, 1, figsize=(12, 9), layout="constrained", sharex=True)
    quantities = (("tension_N2_Hz", 1e-6, "F_ten PSD [kN²/Hz]"),
                  ("chassis_acc_m2_s4_Hz", 1.0, "chassis vertical acc. PSD [(m/s²)²/Hz]"))
    for ax, (key, scale, ylabel) in zip(axes, quantities, strict=True):
        _mark_bands(ax, w)
        drawn = _spectra(ax, results, key, scale, label_by)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
        legend_above(ax, ncol=4)
        if not drawn:
            ax.text(0.5, 0.5, "no run has this quantity", transform=ax.transAxes,
                    ha="center")
    axes[1].set_xlabel("frequency [Hz]")
    axes[1].set_xlim(0.0, w.psd_max_Hz)
    steady = w.steady or (w.evaluation_start_s, math.nan)
    first = results[0]
    fig.suptitle(title or f"{first.scenario} seed {first.seed}: spectra over {steady[0]:g}-"
                 f"{steady[1]:g} s (Welch, {w.psd_resolution_Hz:g} Hz resolution)")
    return save_png(fig, Path(path))


def _mark_bands(ax: Axes, w: MetricWindows) -> None:
    """The road's excitation band (where there is one), the body-mode band and the
    tooth-passing band (where known) [Hz]."""
    if w.road_band_Hz is not None:
        ax.axvspan(*w.road_band_Hz, color=BAND_COLOUR, alpha=0.08, lw=0,
                   label=f"road excitation {w.road_band_Hz[0]:g}-{w.road_band_Hz[1]:g} Hz")
    ax.axvspan(*w.body_mode_band_Hz, facecolor="none", edgecolor="0.7", hatch="//",
               lw=0.0, label=f"body mode {w.body_mode_band_Hz[0]:g}-"
                             f"{w.body_mode_band_Hz[1]:g} Hz")
    if w.tooth_passing_band_Hz is not None:
        lo, hi = w.tooth_passing_band_Hz
        ax.axvspan(lo, hi, facecolor="none", edgecolor="#F2B48A", hatch="\\\\", lw=0.0,
                   label=f"tooth passing {lo:.3g}-{hi:.3g} Hz")


def _spectra(ax: Axes, results: Sequence[Result], key: str, scale: float,
             label_by: str) -> int:
    """Each run's spectrum ``key`` × ``scale`` on a log axis (the zero frequency left out),
    a legend entry "none" for a run without it; returns how many were drawn."""
    drawn = 0
    for k, res in enumerate(results):
        spectra = res.metrics.get("psd", {})
        f = np.asarray(spectra.get("f_Hz", []), dtype=float)
        p = np.asarray(spectra.get(key, []), dtype=float) * scale
        label = getattr(res, label_by)
        if len(f) < 2 or not np.isfinite(p[1:]).any():
            ax.plot([], [], label=f"{label}: none", **style(label, k))
            continue
        ax.semilogy(f[1:], p[1:], lw=1.1, markersize=4, markevery=marker_step(len(f)),
                    markerfacecolor="white", label=label, **style(label, k))
        drawn += 1
    return drawn


def variants_figure(variants: Sequence[str], series: Mapping[str, Mapping[str, Sequence[float]]],
                    path: str | Path, *, title: str = "") -> Path:
    """Grouped bars per parameter variant (W5), one panel per metric: ``series`` maps a
    panel's "label [unit]" to {architecture: one value per variant} (mean over seeds)."""
    fig, axes = plt.subplots(len(series), 1, figsize=(14, 3.6 * len(series)),
                             layout="constrained", squeeze=False)
    for ax, (label, values) in zip(axes[:, 0], series.items(), strict=True):
        name, unit = label.rsplit(" [", 1)
        _bars(ax, list(variants), values, unit.rstrip("]"), name)
    fig.suptitle(title)
    return save_png(fig, Path(path))


def calibration_figure(t: np.ndarray, panels: Sequence[tuple[str, Mapping[str, np.ndarray],
                                                             Mapping[str, np.ndarray],
                                                             Mapping[str, np.ndarray]]],
                       title: str, path: str | Path) -> Path:
    """Measured (grey) against fitted (black) and the fit's start (dashed), one row per
    channel, one column per log; ``panels``: (log name, measured, start, fitted), each a
    channel -> values on ``t`` [s] (SI)."""
    names = [c for c in CHANNEL_DISPLAY if any(c in p[1] for p in panels)]
    fig, axes = plt.subplots(len(names), len(panels), squeeze=False, sharex=True,
                             figsize=(8.0 * len(panels), 2.3 * len(names) + 1.4),
                             layout="constrained")
    for j, (name, measured, start, fitted) in enumerate(panels):
        for i, channel in enumerate(names):
            ax = axes[i][j]
            label, scale = CHANNEL_DISPLAY[channel]
            if channel in measured:
                ax.plot(t, measured[channel] * scale, color="0.6", lw=0.5, label="measured")
                ax.plot(t, start[channel] * scale, color="#0072B2", ls="--", lw=1.0,
                        label="start of the fit")
                ax.plot(t, fitted[channel] * scale, color="black", lw=1.1, label="fitted")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        axes[0][j].set_title(f"log {name}", fontsize=10, loc="right")
        axes[-1][j].set_xlabel("time [s]")
    legend_above(axes[0][0], ncol=3)
    fig.suptitle(title, fontsize=10)
    return save_png(fig, Path(path))
