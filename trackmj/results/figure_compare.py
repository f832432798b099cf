"""Figures that compare runs (PNG). Display units: kN, MPa, J or kJ.

* :func:`overlay_figure`: several runs of one case overlaid (per architecture or per
  controller), zooms, prediction error against the reference architecture, each run's
  energy waterfall.
* :func:`psd_figure`: tension and chassis-acceleration spectra with the bands marked.
* :func:`variants_figure`: a metric per parameter variant and architecture (W5).

Titles name the machine (:func:`with_machine`).
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
from matplotlib.figure import Figure, SubFigure
from matplotlib.gridspec import GridSpecFromSubplotSpec

from trackmj.results.figure_energy import energy_bars
from trackmj.results.figure_panels import (
    shade_events,
    tension_panel,
    zoom_titles,
    zoom_windows,
)
from trackmj.results.figure_style import (
    BAND_COLOUR,
    STYLES,
    legend_above,
    machines_text,
    marker_step,
    number,
    save_png,
    span,
    style,
)
from trackmj.results.metric_windows import MetricWindows, windows_of
from trackmj.results.signals import lowpass
from trackmj.results.store import Result, running_of
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
    longest = max((len(line) for lab in labels for line in lab.split("\n")), default=0)
    ax.set_xticks(range(len(labels)), labels, rotation=0 if longest <= 12 else 20)
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
    with ``predictions`` (label -> :func:`trackmj.results.comparison.prediction_vs_tp`) for
    a run other than the reference architecture, the prediction RMSE against the reference
    (raw and low-passed), the peak-pressure error and the energy error; otherwise the
    tracking RMSE (raw and low-passed), the peak head pressure and the valve switching rate;
    and the energy waterfall of every run. The title names the machine."""
    labels = [getattr(r, label_by) for r in results]
    runs = list(zip(labels, results, strict=True))
    w = windows_of(results[0])
    t_end = float(results[0].columns()["t_s"][-1])
    zooms = zoom_windows(w, t_end, running_of(results[0]))[:4]
    fig = plt.figure(figsize=(17, 20), layout="constrained")
    rows = fig.add_gridspec(2, 1, height_ratios=(15.0, 5.0), hspace=0.0)
    top, bottom = fig.add_subfigure(rows[0]), fig.add_subfigure(rows[1])
    grid = top.add_gridspec(4, 1, height_ratios=(3.0, 2.0, 2.0, 3.0))
    ax_f = top.add_subplot(grid[0])
    tension_panel(ax_f, runs, w)
    ax_f.set_xlabel("time [s]")
    legend_above(ax_f, ncol=5)
    _head_pressures(top.add_subplot(grid[1], sharex=ax_f), runs, w, t_end)
    zoom_grid = grid[2].subgridspec(1, len(zooms))
    zoom_axes = []
    for k, (_, t0, t1) in enumerate(zooms):
        ax = top.add_subplot(zoom_grid[k])
        tension_panel(ax, runs, w, (t0, t1), legend=False, raw_as_line=True)
        ax.set_xlabel("time [s]")
        zoom_axes.append(ax)
    compared = [lab for lab in labels
                if lab in (predictions or {}) and lab != REFERENCE_ARCHITECTURE]
    if predictions and compared:
        _prediction_bars(top, grid[3].subgridspec(1, 3), compared, predictions, w)
    else:   # nothing to compare with the reference (a report of tp alone): its own figures
        _run_bars(top, grid[3].subgridspec(1, 3), labels, results, w)
    energy_bars(bottom, labels, results)
    first = results[0]
    fig.suptitle(with_machine(title or f"{first.scenario} seed {first.seed}: "
                              + ", ".join(labels), results))
    zoom_titles(fig, [(ax, name) for ax, (name, _, _) in zip(zoom_axes, zooms, strict=True)])
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


def _prediction_bars(fig: Figure | SubFigure, bars: GridSpecFromSubplotSpec,
                     others: Sequence[str],
                     predictions: Mapping[str, Mapping[str, Any]], w: MetricWindows) -> None:
    """Bars of the prediction error of each run labelled in ``others`` (keys of
    ``predictions``, the reference architecture's run not among them) against the reference:
    F_ten RMSE (raw and low-passed) [kN], peak head pressure [MPa], energy [%] (named by the
    term compared) in the first three cells of ``bars``."""
    ref = REFERENCE_ARCHITECTURE
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


def _run_bars(fig: Figure | SubFigure, bars: GridSpecFromSubplotSpec, labels: Sequence[str],
              results: Sequence[Result], w: MetricWindows) -> None:
    """Bars of each run's tracking RMSE (raw and low-passed) [kN], peak head pressure [MPa]
    and valve switching rate [Hz] in the three cells of ``bars``."""
    def values(key: str, scale: float) -> list[float]:
        return [float(r.metrics.get(key, math.nan)) * scale for r in results]

    _bars(fig.add_subplot(bars[0]), labels, {
        "raw": values("rmse_N", 1e-3),
        f"{w.lowpass_cutoff_Hz:g} Hz low-pass": values("rmse_lp_N", 1e-3)},
        "kN", "tracking RMSE")
    _bars(fig.add_subplot(bars[1]), labels, {"peak p_head, raw": values("p_head_max_Pa", 1e-6)},
          "MPa", "peak head pressure")
    _bars(fig.add_subplot(bars[2]), labels, {"valve mode changes per s": values(
        "valve_switch_rate_Hz", 1.0)}, "Hz", "valve switching")


def psd_figure(results: Sequence[Result], path: str | Path, *,
               label_by: str = "architecture", title: str = "") -> Path:
    """Tension and chassis vertical acceleration spectra (the runs' ``metrics["psd"]``,
    steady window) on log axes; the road's excitation band, the body-mode band and the
    tooth-passing band marked. The title names the window and the resolution the spectra
    have (:func:`psd_resolution`) and says when the window is too short for the scenario's
    resolution."""
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
    first = results[0]
    fig.suptitle(with_machine(title or f"{first.scenario} seed {first.seed}: spectra", results)
                 + "\n" + psd_resolution_text(first))
    return save_png(fig, Path(path))


def psd_resolution(result: Result) -> tuple[float, float, float]:
    """(start [s], length [s], frequency resolution [Hz]) of a run's spectra: the steady
    window up to the run's end and the bin spacing of its ``metrics["psd"]`` (Welch
    segments of 1/resolution_Hz s, or the whole window where it is shorter:
    :func:`trackmj.results.signals.psd`); the spacing from the window if the run has no
    spectra."""
    w = windows_of(result)
    t_end = float(result.columns()["t_s"][-1])
    start = w.steady[0] if w.steady is not None else w.evaluation_start_s
    length = max(min(w.steady[1] if w.steady is not None else t_end, t_end) - start, 0.0)
    f = np.asarray(result.metrics.get("psd", {}).get("f_Hz", []), dtype=float)
    if len(f) >= 2:
        return start, length, float(f[1] - f[0])
    return start, length, max(w.psd_resolution_Hz, 1.0 / length if length > 0 else math.inf)


def psd_resolution_text(result: Result) -> str:
    """The spectra's window and resolution for a title: "Welch over 5–30 s (25 s), 2 s Hann
    segments: 0.5 Hz resolution"; where the window is shorter than one segment of the
    scenario's resolution, what it gives and how long a run needs to be for that:
    "window 5–6 s is 1 s, shorter than the 2 s Welch segment: 1 Hz resolution, not
    0.5 Hz; run ≥ 7 s for 0.5 Hz"."""
    w = windows_of(result)
    start, length, resolution = psd_resolution(result)
    wanted = w.psd_resolution_Hz
    window = f"{span(start, start + length, 's')} ({number(length, 2)} s)"
    if resolution <= wanted * (1.0 + 1e-2):
        return (f"Welch over {window}, {number(1.0 / wanted)} s Hann segments: "
                f"{number(resolution, 2)} Hz resolution")
    return (f"window {window} is shorter than the {number(1.0 / wanted)} s Welch segment: "
            f"{number(resolution, 2)} Hz resolution, not {number(wanted)} Hz; run ≥ "
            f"{number(start + 1.0 / wanted)} s for {number(wanted)} Hz")


def _mark_bands(ax: Axes, w: MetricWindows) -> None:
    """The road's excitation band (where there is one), the body-mode band and the
    tooth-passing band (where known) [Hz]."""
    if w.road_band_Hz is not None:
        ax.axvspan(*w.road_band_Hz, color=BAND_COLOUR, alpha=0.08, lw=0,
                   label=f"road excitation {span(*w.road_band_Hz, 'Hz')}")
    ax.axvspan(*w.body_mode_band_Hz, facecolor="none", edgecolor="0.7", hatch="//",
               lw=0.0, label=f"body mode {span(*w.body_mode_band_Hz, 'Hz')}")
    if w.tooth_passing_band_Hz is not None:
        lo, hi = w.tooth_passing_band_Hz
        ax.axvspan(lo, hi, facecolor="none", edgecolor="#F2B48A", hatch="\\\\", lw=0.0,
                   label=f"tooth passing {span(lo, hi, 'Hz')}")


def _spectra(ax: Axes, results: Sequence[Result], key: str, scale: float,
             label_by: str) -> int:
    """Each run's spectrum ``key`` × ``scale`` on a log axis (the zero frequency left out),
    a legend entry "not recorded" for a run without it; returns how many were drawn."""
    drawn = 0
    for k, res in enumerate(results):
        spectra = res.metrics.get("psd", {})
        f = np.asarray(spectra.get("f_Hz", []), dtype=float)
        p = np.asarray(spectra.get(key, []), dtype=float) * scale
        label = getattr(res, label_by)
        if len(f) < 2 or not np.isfinite(p[1:]).any():
            ax.plot([], [], label=f"{label}: not recorded", **style(label, k))
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


def with_machine(title: str, results: Sequence[Result]) -> str:
    """``title`` naming the machine(s) of ``results`` (", machine m113") unless it does
    already or no result names one."""
    machine = machines_text(results)
    return title if machine is None or machine in title else f"{title}, machine {machine}"
