"""Figures of runs and comparisons (PNG, matplotlib Agg). Display units: kN, MPa, kJ.

Every figure reads in colour and in grayscale: each architecture, controller and energy term
has its own colour (Okabe-Ito, colour-blind safe) AND line style, marker or hatch. Legends
sit above the panels, outside the data; every axis states its unit; the admissible band
[F_min, F_max] is shaded green and the disturbance windows (load pulses, supply drops)
grey. The windows come from the run's own ``metrics["evaluation"]`` table.

* :func:`run_figure`: one run: tension (raw as a light min-max band, low-pass as the line,
  reference), chamber and supply pressures, valve mode and u, zooms on the events, energy
  breakdown.
* :func:`overlay_figure`: several runs of one case overlaid (per architecture or per
  controller), zooms, prediction error against tp, energy breakdown bars.
* :func:`psd_figure`: tension and chassis-acceleration spectra with the bands marked.
* :func:`variants_figure`: a metric per parameter variant and architecture (W5).
"""

from __future__ import annotations

import io
import math
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes

from trackmj.io import write_bytes_atomic
from trackmj.results.energy_terms import ENERGY_TOTALS, energy_terms
from trackmj.results.metric_windows import MetricWindows
from trackmj.results.metrics import METRIC_DISPLAY
from trackmj.results.signals import lowpass
from trackmj.results.store import Result
from trackmj.study.campaign import column_unit, mean_std

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
ENERGY_STYLES: dict[str, tuple[str, str]] = {
    "relief": ("#E69F00", ""), "throttling": ("#56B4E9", "//"), "leakage": ("#009E73", "\\\\"),
    "friction": ("#F0E442", ".."), "makeup": ("#0072B2", "xx"),
    "stored_change": ("#D55E00", "--"), "mechanical": ("#CC79A7", "oo"),
    "residual": ("#999999", "++"), "return_line": ("#44AA99", "||"),
    "endstop": ("#332288", "o"), "numerical": ("#DDCC77", "x"),
    "pump_losses": ("#882255", "\\\\//")}
"""Colour and hatch of each energy term in the breakdown bars."""
ENERGY_ORDER = ("throttling", "leakage", "friction", "makeup", "return_line", "endstop",
                "mechanical", "stored_change", "numerical", "residual", "relief", "pump_losses")
"""Stacking order of the energy terms (terms not listed go on top)."""
RAW_COLOUR = "0.78"
BAND_COLOUR = "#009E73"
EVENT_COLOUR = "0.55"
ENVELOPE_BIN_S = 0.05
"""Raw signals are drawn as their min-max band over 50 ms bins (the 1 kHz trace would be a
solid block at full-run scale)."""
MARKERS_PER_LINE = 12


def _save(fig: plt.Figure, path: Path) -> Path:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    write_bytes_atomic(path, buffer.getvalue())
    return path


def style(label: str, index: int = 0) -> dict[str, Any]:
    """Line style of ``label`` (an architecture or controller); a spare one otherwise."""
    return STYLES.get(label, SPARE_STYLES[index % len(SPARE_STYLES)])


def windows_of(result: Result) -> MetricWindows:
    """The metric windows a result was measured on (its ``evaluation`` table)."""
    table = result.metrics.get("evaluation")
    if not isinstance(table, Mapping):
        raise KeyError(f"{result.scenario} {result.architecture}: metrics have no "
                       "'evaluation' table (a result written before the windows were stored)")
    return MetricWindows.from_table(table)


def _envelope(t: np.ndarray, x: np.ndarray, bin_s: float = ENVELOPE_BIN_S,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bin centres [s], min, max) of ``x`` over consecutive bins of ``bin_s``."""
    n = max(1, round(bin_s / float(np.median(np.diff(t)))))
    m = len(t) // n * n
    tb, xb = t[:m].reshape(-1, n), x[:m].reshape(-1, n)
    return tb.mean(axis=1), xb.min(axis=1), xb.max(axis=1)


def _legend_above(ax: Axes, ncol: int | None = None, **kwargs: Any) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.0, 1.01),
                  ncol=ncol or len(handles), frameon=False, fontsize=9,
                  handlelength=3.0, borderaxespad=0.0, columnspacing=1.2, **kwargs)


def _shade_events(ax: Axes, w: MetricWindows, t_end: float, label: bool = True) -> None:
    """Grey spans over the disturbance windows up to the run's end ``t_end`` [s] (a window
    after the end of a shortened run is not drawn); a dotted line at the reference step."""
    named = set()
    for k, (on, off) in enumerate(w.disturbances):
        if on >= t_end:
            continue
        off = min(off, t_end)
        kind = _disturbance_kind(w, k)
        ax.axvspan(on, off, color=EVENT_COLOUR, alpha=0.15, lw=0,
                   label=f"{kind} window" if label and kind not in named else None)
        named.add(kind)
    if w.step is not None and w.step[0] < t_end:
        ax.axvline(w.step[0], color=EVENT_COLOUR, ls="-.", lw=1.0,
                   label=f"reference step at {w.step[0]:g} s" if label else None)


def _disturbance_kind(w: MetricWindows, k: int) -> str:
    """What disturbance ``k`` is, without its size ("load pulse", "supply drop")."""
    if k >= len(w.disturbance_labels):
        return "disturbance"
    return " ".join(w.disturbance_labels[k].split()[:2])


def _force_band(ax: Axes, w: MetricWindows, label: bool = True) -> None:
    ax.axhspan(w.force_min_N / 1e3, w.force_max_N / 1e3, facecolor=(0.0, 0.62, 0.45, 0.08),
               edgecolor=BAND_COLOUR, lw=0.9, ls="--",
               label=f"admissible [F_min, F_max] = [{w.force_min_N / 1e3:g}, "
                     f"{w.force_max_N / 1e3:g}] kN" if label else None)


def _zoom_windows(w: MetricWindows, t_end: float) -> list[tuple[str, float, float]]:
    """(title, t0, t1) of the zoom panels: the reference step, each disturbance edge (onset
    and end) from the evaluation start (an earlier one is the run's initial condition), or,
    with none, the next reference change after the step (NL1's first release), or, with
    neither, one second of steady running."""
    zooms = []
    if w.step is not None and w.step[0] < t_end:
        zooms.append((f"step at {w.step[0]:g} s", w.step[0] - 0.5, w.step[0] + 3.0))
    for k, (on, off) in enumerate(w.disturbances):
        what = w.disturbance_labels[k] if k < len(w.disturbance_labels) else "disturbance"
        for edge, name in ((on, "onset"), (off, "end")):
            if w.judges_edge(edge, t_end):
                zooms.append((f"{what}, {name} at {edge:g} s", edge - 0.5, edge + 2.5))
    later = [e for e in w.reference_events_s if w.step is not None and w.step[0] < e < t_end]
    if len(zooms) == 1 and later:
        zooms.append((f"reference change at {later[0]:g} s", later[0] - 0.5, later[0] + 3.0))
    if not zooms:
        t0 = w.steady[0] if w.steady is not None else w.evaluation_start_s
        t0 = t0 if t0 + 1.0 <= t_end else max(t_end - 1.0, 0.0)   # a short run: its last second
        zooms.append((f"steady running, {t0:g}-{t0 + 1:g} s", t0, t0 + 1.0))
    return [(title, max(t0, 0.0), min(t1, t_end)) for title, t0, t1 in zooms]


def _markevery(n: int) -> int:
    return max(n // MARKERS_PER_LINE, 1)


def _tension_panel(ax: Axes, runs: Sequence[tuple[str, Result]], w: MetricWindows,
                   t_range: tuple[float, float] | None = None, raw_of: int = 0,
                   legend: bool = True, raw_as_line: bool = False) -> None:
    """Low-passed F_ten of each run (styled), the raw F_ten of run ``raw_of`` as a light band
    (or a thin line in a zoom), the reference, the force band and the events."""
    label0, first = runs[raw_of]
    c = first.columns()
    t = c["t_s"]
    sel = np.ones(t.shape, bool) if t_range is None else (t >= t_range[0]) & (t <= t_range[1])
    raw_label = f"{label0} raw" if len(runs) > 1 else "F_ten raw"
    if raw_as_line:
        ax.plot(t[sel], c["tension_N"][sel] / 1e3, color=RAW_COLOUR, lw=0.6, label=raw_label)
    else:
        tb, lo, hi = _envelope(t[sel], c["tension_N"][sel])
        ax.fill_between(tb, lo / 1e3, hi / 1e3, color=RAW_COLOUR, lw=0,
                        label=f"{raw_label} (50 ms min-max)")
    for k, (label, res) in enumerate(runs):
        cc = res.columns()
        lp = lowpass(cc["t_s"], cc["tension_N"], w.lowpass_cutoff_Hz)
        name = (f"{label} {w.lowpass_cutoff_Hz:g} Hz low-pass" if len(runs) > 1
                else f"F_ten {w.lowpass_cutoff_Hz:g} Hz low-pass")
        ax.plot(cc["t_s"][sel], lp[sel] / 1e3, lw=1.3, markersize=5, label=name,
                markevery=_markevery(int(sel.sum())), markerfacecolor="white",
                **style(label, k))
    ax.plot(t[sel], c["tension_ref_N"][sel] / 1e3, color="black", lw=1.0, ls=(0, (1, 1.5)),
            label="reference F_ref")
    _force_band(ax, w, label=legend)
    _shade_events(ax, w, float(t[-1]), label=legend)
    ax.set_ylabel("F_ten [kN]")
    if t_range is not None:
        ax.set_xlim(*t_range)
        lo_y = min(np.nanmin(c["tension_N"][sel]), np.nanmin(c["tension_ref_N"][sel]))
        hi_y = max(np.nanmax(c["tension_N"][sel]), np.nanmax(c["tension_ref_N"][sel]))
        pad = 0.08 * (hi_y - lo_y) + 50.0
        ax.set_ylim((lo_y - pad) / 1e3, (hi_y + pad) / 1e3)
    ax.grid(alpha=0.3)


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


def _energy_bars(ax: Axes, labels: Sequence[str], results: Sequence[Result], *,
                 below: bool = False) -> None:
    """Each run's energy as a waterfall [kJ]: the circuit's terms from zero, each bar from the
    running sum (a negative term, e.g. energy released from storage, goes down), so the
    circuit total (dashed tick) stands where its terms end; then the supply-side terms
    (relief, pump losses, supply storage) up to the pump total (solid tick). A note where a
    run has no energy_J table. ``below``: the legend under the panel (else beside it)."""
    spare = iter(["#777777", "#444444", "#AAAAAA"])
    drawn: set[str] = set()
    for x, r in enumerate(results):
        circuit_terms, supply_terms = energy_waterfall(r.metrics)
        circuit_terms = [t for t in circuit_terms if t[1] != 0.0]
        steps = circuit_terms + [t for t in supply_terms if t[1] != 0.0]
        if not steps:
            continue
        width = 0.8 / len(steps)
        left = x - 0.4
        end_circuit = left + width * len(circuit_terms)
        running = 0.0
        totals = energy_terms(r.metrics).terms
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
                          label=None if total in drawn else f"{total} total (energy in)")
                drawn.add(total)
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
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xticks(range(len(labels)), labels, rotation=20)
    ax.set_xlim(-0.6, len(labels) - 0.4)
    ax.set_ylabel("energy [kJ]")
    ax.set_title("energy, waterfall: circuit terms, then supply side", fontsize=10, loc="left")
    ax.grid(axis="y", alpha=0.3)
    handles, names = ax.get_legend_handles_labels()
    if below:      # a narrow panel: the dozen terms under it, in two columns
        ax.legend(handles, [textwrap.fill(n, 38) for n in names], loc="upper center",
                  bbox_to_anchor=(0.5, -0.12), ncol=2, frameon=False, fontsize=9,
                  borderaxespad=0.0)
    else:
        ax.legend(handles, [textwrap.fill(n, 42) for n in names], loc="upper left",
                  bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=9, borderaxespad=0.0)


MEASURED_COLOUR = "#D55E00"
"""Colour of a measured log's channels overlaid on a run."""


def run_figure(result: Result, path: str | Path,
               measured: Mapping[str, np.ndarray] | None = None) -> Path:
    """One run: tension (raw band, low-pass, reference, F band, events), chamber and supply
    pressures, valve mode (−1/0/+1), valve opening u, zoom panels on the step, each
    disturbance edge (or a second of steady running) and the energy breakdown. With a
    ``measured`` log on the run's grid (:func:`trackmj.results.measured.resample`), its tension,
    pressures and stroke are overlaid, low-passed like the run's (a stroke panel is added
    for a measured stroke)."""
    w = windows_of(result)
    c = result.columns()
    t = c["t_s"]
    t_end = float(t[-1])
    zooms = _zoom_windows(w, t_end)
    measured = dict(measured or {})
    stroke = "stroke_m" in measured
    fig = plt.figure(figsize=(16, 14 if stroke else 12), layout="constrained")
    outer = fig.add_gridspec(1, 2, width_ratios=(2.0, 1.0))
    left = outer[0].subgridspec(5 if stroke else 4, 1,
                                height_ratios=(3.0, 2.0, *((1.6,) if stroke else ()), 1.1, 1.1))
    right = outer[1].subgridspec(len(zooms) + 1, 1,
                                 height_ratios=(*[1.0] * len(zooms), 1.2 + 0.6 * len(zooms)))
    ax_f = fig.add_subplot(left[0])
    ax_p = fig.add_subplot(left[1], sharex=ax_f)
    ax_v = fig.add_subplot(left[3 if stroke else 2], sharex=ax_f)
    ax_u = fig.add_subplot(left[4 if stroke else 3], sharex=ax_f)
    _tension_panel(ax_f, [(result.architecture, result)], w)
    fc = w.lowpass_cutoff_Hz
    if "tension_N" in measured:
        ax_f.plot(t, lowpass(t, measured["tension_N"], fc) / 1e3, color=MEASURED_COLOUR,
                  lw=1.2, ls="--", label=f"measured F_ten {fc:g} Hz low-pass")
    for name, ls in (("p_head_Pa", "-"), ("p_rod_Pa", "--")):
        if name in measured:
            ax_p.plot(t, lowpass(t, measured[name], fc) / 1e6, color=MEASURED_COLOUR, ls=ls,
                      lw=1.1, label=f"measured {name[:-3]} {fc:g} Hz low-pass")
    if stroke:
        ax_y = fig.add_subplot(left[2], sharex=ax_f)
        ax_y.plot(t, lowpass(t, c["stroke_m"], fc) * 1e3, color="black", lw=1.1,
                  label=f"stroke {fc:g} Hz low-pass")
        ax_y.plot(t, lowpass(t, measured["stroke_m"], fc) * 1e3, color=MEASURED_COLOUR,
                  ls="--", lw=1.1, label=f"measured stroke {fc:g} Hz low-pass")
        ax_y.set_ylabel("stroke [mm]")
        ax_y.grid(alpha=0.3)
        ax_y.tick_params(labelbottom=False)
        _legend_above(ax_y)
    _legend_above(ax_f, ncol=4)
    if np.isfinite(c["p_head_Pa"]).all():
        tb, lo, hi = _envelope(t, c["p_head_Pa"])
        ax_p.fill_between(tb, lo / 1e6, hi / 1e6, color=RAW_COLOUR, lw=0,
                          label="p_head raw (50 ms min-max)")
    for name, ls, label in (("p_head_Pa", "-", "p_head"), ("p_rod_Pa", "--", "p_rod"),
                            ("p_supply_Pa", ":", "p_supply")):
        if np.isfinite(c[name]).all() and name == "p_supply_Pa":     # a smooth node: as is
            ax_p.plot(t, c[name] / 1e6, color="black", ls=ls, lw=1.1, label=label)
        elif np.isfinite(c[name]).all():
            ax_p.plot(t, lowpass(t, c[name], w.lowpass_cutoff_Hz) / 1e6, color="black", ls=ls,
                      lw=1.1, label=f"{label} {w.lowpass_cutoff_Hz:g} Hz low-pass")
        else:
            ax_p.plot([], [], color="black", ls=ls, label=f"{label}: none in this architecture")
    _shade_events(ax_p, w, t_end, label=False)
    ax_p.set_ylabel("pressure [MPa]")
    ax_p.grid(alpha=0.3)
    _legend_above(ax_p, ncol=3 if measured else None)
    ax_v.step(t, c["valve_mode"], where="post", color="black", lw=0.8, label="valve mode")
    ax_v.set_yticks([-1, 0, 1], ["−1 release", "0 hold", "+1 pressurize"])
    ax_v.set_ylim(-1.4, 1.4)
    ax_v.set_ylabel("mode [-]")
    _shade_events(ax_v, w, t_end, label=False)
    ax_v.grid(alpha=0.3)
    ax_u.plot(t, c["u"], color="#0072B2", lw=0.6,
              label="u: the controller's command in [−1, 1] (> 0 pressurize, < 0 release), "
                    "which the valve logic turns into the modes above")
    ax_u.set_ylabel("u [-]")
    _legend_above(ax_u)
    ax_u.set_xlabel("time [s]")
    _shade_events(ax_u, w, t_end, label=False)
    ax_u.grid(alpha=0.3)
    for ax in (ax_f, ax_p, ax_v):
        ax.tick_params(labelbottom=False)
    for k, (title, t0, t1) in enumerate(zooms):
        ax = fig.add_subplot(right[k])
        _tension_panel(ax, [(result.architecture, result)], w, (t0, t1), legend=False,
                       raw_as_line=True)
        ax.set_title(f"zoom: {title}", fontsize=9, loc="left")
        ax.set_xlabel("time [s]")
    _energy_bars(fig.add_subplot(right[len(zooms)]), [result.architecture], [result],
                 below=True)
    fig.suptitle(f"{result.scenario} {result.architecture} {result.controller}/"
                 f"{result.estimator} seed {result.seed}, variant "
                 f"{result.metadata.get('variant', 'nominal')}")
    return _save(fig, Path(path))


def _number(value: float, values: Sequence[float]) -> str:
    """Bar label: "–" if undefined, "0" if below 0.1 % of the largest bar, else 3 digits."""
    if not math.isfinite(value):
        return "–"
    largest = max((abs(v) for v in values if math.isfinite(v)), default=0.0)
    return "0" if abs(value) < 1e-3 * largest or value == 0.0 else f"{value:.3g}"


def _bars(ax: Axes, labels: Sequence[str], series: Mapping[str, Sequence[float]], unit: str,
          ylabel: str) -> None:
    """Grouped bars: one group per label, one hatched bar per series; values annotated."""
    hatches, shades = ("", "//", "..", "xx"), ("0.35", "0.75", "0.55", "0.9")
    n = max(len(series), 1)
    width = 0.8 / n
    for j, (name, values) in enumerate(series.items()):
        x = np.arange(len(labels)) + (j - (n - 1) / 2) * width
        colour = STYLES[name]["color"] if name in STYLES else shades[j % 4]
        bars = ax.bar(x, values, width=width, color=colour, hatch=hatches[j % 4],
                      edgecolor="0.6" if name == "tp" else "black", lw=0.5, label=name)
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
    _legend_above(ax, ncol=1)      # stacked: a narrow panel's entries would overlap its neighbour


def overlay_figure(results: Sequence[Result], path: str | Path, *,
                   label_by: str = "architecture",
                   predictions: Mapping[str, Mapping[str, Any]] | None = None,
                   title: str = "") -> Path:
    """Runs of one case overlaid, labelled by ``label_by`` (``architecture`` or
    ``controller``): low-passed tension (raw of the first run as a band), head pressure
    (low-passed) and the first run's supply pressure, zooms on the events, then bars:
    with ``predictions`` (label -> :func:`trackmj.results.metrics.prediction_vs_tp`) the prediction
    RMSE against tp (raw and low-passed), the peak-pressure error and the energy error; without,
    the tracking RMSE (raw and low-passed); and the energy breakdown of every run."""
    labels = [getattr(r, label_by) for r in results]
    runs = list(zip(labels, results, strict=True))
    w = windows_of(results[0])
    t_end = float(results[0].columns()["t_s"][-1])
    zooms = _zoom_windows(w, t_end)[:4]
    bar_axes = 4 if predictions else 2
    fig = plt.figure(figsize=(17, 15), layout="constrained")
    grid = fig.add_gridspec(4, 1, height_ratios=(3.0, 2.0, 2.0, 3.0))
    ax_f = fig.add_subplot(grid[0])
    _tension_panel(ax_f, runs, w)
    ax_f.set_xlabel("time [s]")
    _legend_above(ax_f, ncol=5)
    ax_p = fig.add_subplot(grid[1], sharex=ax_f)
    for k, (label, res) in enumerate(runs):
        c = res.columns()
        ax_p.plot(c["t_s"], lowpass(c["t_s"], c["p_head_Pa"], w.lowpass_cutoff_Hz) / 1e6,
                  lw=1.2, markersize=5, markevery=_markevery(len(c["t_s"])),
                  markerfacecolor="white", label=f"{label} p_head", **style(label, k))
    supply = results[0].columns()["p_supply_Pa"]
    if np.isfinite(supply).any():
        ax_p.plot(results[0].columns()["t_s"], supply / 1e6, color="0.45", lw=1.0,
                  ls=(0, (4, 1, 1, 1)), label=f"{labels[0]} p_supply")
    _shade_events(ax_p, w, t_end, label=False)
    ax_p.set_ylabel("pressure [MPa]")
    ax_p.set_xlabel("time [s]")
    ax_p.grid(alpha=0.3)
    _legend_above(ax_p, ncol=len(runs) + 1,
                  title=f"head pressure, {w.lowpass_cutoff_Hz:g} Hz low-pass")
    zoom_grid = grid[2].subgridspec(1, len(zooms))
    for k, (name, t0, t1) in enumerate(zooms):
        ax = fig.add_subplot(zoom_grid[k])
        _tension_panel(ax, runs, w, (t0, t1), legend=False, raw_as_line=True)
        ax.set_title(f"zoom: {name}", fontsize=9, loc="left")
        ax.set_xlabel("time [s]")
    bars = grid[3].subgridspec(1, bar_axes, width_ratios=(*[1.0] * (bar_axes - 1), 2.4))
    if predictions:
        others = [lab for lab in labels if lab in predictions and lab != "tp"]
        _bars(fig.add_subplot(bars[0]), others, {
            "raw": [predictions[o]["prediction_rmse_vs_tp_N"] / 1e3 for o in others],
            f"{w.lowpass_cutoff_Hz:g} Hz low-pass":
                [predictions[o]["prediction_rmse_vs_tp_lp_N"] / 1e3 for o in others]},
            "kN", "F_ten RMSE vs tp")
        _bars(fig.add_subplot(bars[1]), others, {"peak p_head − tp": [
            predictions[o]["peak_pressure_error_vs_tp_Pa"] / 1e6 for o in others]},
            "MPa", "peak pressure error")
        term = [predictions[o]["energy_error_term"] for o in others]
        _bars(fig.add_subplot(bars[2]), [f"{o}\n({t or 'none'})" for o, t in
                                         zip(others, term, strict=True)],
              {"(E − E_tp)/E_tp": [predictions[o]["energy_error_vs_tp_pct"]
                                   for o in others]}, "%", "energy error vs tp")
    else:
        _bars(fig.add_subplot(bars[0]), labels, {
            "raw": [r.metrics.get("rmse_N", math.nan) / 1e3 for r in results],
            f"{w.lowpass_cutoff_Hz:g} Hz low-pass":
                [r.metrics.get("rmse_lp_N", math.nan) / 1e3 for r in results]},
            "kN", "tracking RMSE")
    _energy_bars(fig.add_subplot(bars[bar_axes - 1]), labels, results)
    first = results[0]
    fig.suptitle(title or f"{first.scenario} seed {first.seed}: " + ", ".join(labels))
    return _save(fig, Path(path))


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
        drawn = 0
        for k, res in enumerate(results):
            spectra = res.metrics.get("psd", {})
            f = np.asarray(spectra.get("f_Hz", []), dtype=float)
            p = np.asarray(spectra.get(key, []), dtype=float) * scale
            label = getattr(res, label_by)
            if len(f) < 2 or not np.isfinite(p[1:]).any():
                ax.plot([], [], label=f"{label}: none", **style(label, k))
                continue
            ax.semilogy(f[1:], p[1:], lw=1.1, markersize=4, markevery=_markevery(len(f)),
                        markerfacecolor="white", label=label, **style(label, k))
            drawn += 1
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
        _legend_above(ax, ncol=4)
        if not drawn:
            ax.text(0.5, 0.5, "no run has this quantity", transform=ax.transAxes,
                    ha="center")
    axes[1].set_xlabel("frequency [Hz]")
    axes[1].set_xlim(0.0, w.psd_max_Hz)
    steady = w.steady or (w.evaluation_start_s, math.nan)
    first = results[0]
    fig.suptitle(title or f"{first.scenario} seed {first.seed}: spectra over {steady[0]:g}-"
                 f"{steady[1]:g} s (Welch, {w.psd_resolution_Hz:g} Hz resolution)")
    return _save(fig, Path(path))



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
    return _save(fig, Path(path))


# ----------------------------------------------------------------------------- sweeps

DISPLAY_UNITS: dict[str, tuple[float, str]] = {
    "N": (1e-3, "kN"), "Pa": (1e-6, "MPa"), "Pa (absolute)": (1e-6, "MPa abs"),
    "J": (1e-3, "kJ"), "W": (1e-3, "kW"), "m": (1e3, "mm"), "m^2": (1e6, "mm²"),
    "m^3": (1e6, "cm³"), "m^3/s": (6e4, "L/min"), "N/m": (1e-6, "kN/mm"),
    "m/s^2": (1.0, "m/s²"), "N^2·s": (1e-6, "kN²·s"), "1": (1.0, ""),
}
"""SI unit -> (scale, display unit) on the figures; other units are shown as they are."""
CASE = ("scenario", "architecture", "controller", "estimator", "variant", "duration_s",
        "inputs")
"""Columns of a results row that make one line of a sweep figure (with the other swept
parameters)."""
NOT_METRICS = ("run_key", "point", "scenario", "architecture", "controller", "estimator",
               "variant", "seed", "duration_s", "inputs", "error")


WORDS = {"lp": "low-pass", "rms": "RMS", "ise": "integral of squared error"}
"""Abbreviations of metric names in plain words (on the sweep figures' axes)."""


def display_unit(unit: str) -> tuple[float, str]:
    """(scale, display unit) of SI ``unit`` (:data:`DISPLAY_UNITS`)."""
    return DISPLAY_UNITS.get(unit, (1.0, unit))


def column_words(name: str) -> str:
    """A results column in plain words: the label of :data:`trackmj.results.metrics.METRIC_DISPLAY`,
    else the name without its unit suffix, ``_`` and ``.`` as spaces (a swept key: its
    last two parts, e.g. "fluid bulk modulus")."""
    from trackmj.study.campaign import is_key_column
    from trackmj.validator import UNIT_SUFFIXES

    if name in METRIC_DISPLAY:
        return METRIC_DISPLAY[name][0]
    if name == "wall_time_s":
        return "wall time of a run"
    parts = name.split(".")
    if is_key_column(name):
        parts = [p for p in parts[1:] if not p.isdigit()][-2:]
    def bare(part: str) -> str:
        for suffix, _ in UNIT_SUFFIXES:
            if part.endswith(suffix) and len(part) > len(suffix):
                return part[: -len(suffix)]
        return part

    words = " ".join(bare(p) for p in parts).replace("_", " ").split()
    return " ".join(WORDS.get(w, w) for w in words)


def column_label(name: str) -> str:
    """Axis label of a results column: plain words and display unit ("tension RMSE,
    low-pass [kN]")."""
    from trackmj.study.campaign import column_unit

    unit = METRIC_DISPLAY[name][2] if name in METRIC_DISPLAY else \
        display_unit(column_unit(name))[1]
    return f"{column_words(name)} [{unit}]" if unit and unit != "1" else column_words(name)


def varies(values: Sequence[Any]) -> bool:
    """Whether the finite ``values`` differ by more than :data:`CONSTANT_REL` (relative)."""
    from trackmj.study.campaign import finite

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
    from trackmj.study.campaign import is_key_column

    rows = [dict(r) for r in rows]
    if not rows:
        return []
    swept = sorted({k for r in rows for k in r if is_key_column(k)})
    skip = set(NOT_METRICS) | set(swept)
    metrics = sorted({k for r in rows for k in r if k not in skip
                      and isinstance(r[k], int | float) and not isinstance(r[k], bool)})
    same: dict[tuple, list[str]] = {}      # one figure per series of values: drawn once
    for metric in sorted(metrics, key=lambda m: (m.count("."), m)):   # top-level names first
        values = [r.get(metric) for r in rows]
        if varies(values):
            same.setdefault(tuple(None if v is None or v != v else v for v in values),
                            []).append(metric)
    paths = []
    for metric, *also in sorted(same.values()):
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


def _save_figure(fig: Any, path: Path) -> Path:
    """A pyplot-free :class:`matplotlib.figure.Figure` as PNG at ``path``, atomically."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    write_bytes_atomic(path, buffer.getvalue())
    return path


def scenario_order(name: str) -> tuple[int, str]:
    """Built-in scenarios in their order (W1-W5, NL1), then the others by name."""
    from trackmj.scenarios.load import BUILTIN

    return (BUILTIN.index(name), "") if name in BUILTIN else (len(BUILTIN), name)


LINE_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ((0, (5, 1, 1, 1)), "v"),
               ((0, (1, 3)), "P"))
"""Line style and marker of the lines of one case (the other swept parameters' values)."""
CONSTANT_REL = 1e-9
"""A metric whose finite values differ by less than this (relative) does not vary: no
figure."""
MAX_LABELLED_LINES = 6
"""More lines per case than this are drawn thin and unlabelled."""


def _metric_figure(rows: list[dict[str, Any]], metric: str, swept: list[str]) -> Any:
    """One panel per swept key: the metric's mean ± std over seeds against the key, a
    colour per case, a line style per combination of the other keys."""
    from matplotlib.figure import Figure  # no pyplot: no global figure state

    cases = sorted({tuple(r.get(c) for c in CASE) for r in rows}, key=str)
    colors = matplotlib.colormaps["tab10"]
    m_scale = display_unit(column_unit(metric))[0]
    width, height = 4.8 * len(swept) + 0.8, 4.4
    fig = Figure(figsize=(width, height))
    axes = fig.subplots(1, len(swept), squeeze=False, sharey=True)[0]
    # fixed margins [in] instead of tight_layout, which draws the figure once more
    fig.subplots_adjust(left=0.85 / width, right=1.0 - 0.2 / width, bottom=0.6 / height,
                        top=1.0 - 0.45 / height, wspace=0.12)
    for ax, key in zip(axes, swept, strict=True):
        k_scale = display_unit(column_unit(key))[0]
        others = [k for k in swept if k != key]
        for c, case in enumerate(cases):
            lines: dict[tuple, dict[Any, list[float]]] = {}
            for r in rows:
                if tuple(r.get(n) for n in CASE) == case and key in r:
                    lines.setdefault(tuple(r.get(k) for k in others), {}).setdefault(
                        r[key], []).append(r.get(metric))
            series = sorted(lines.items(), key=lambda item: [_sortable(v) for v in item[0]])
            scatter = len(series) > 1 and all(len(points) == 1 for _, points in series)
            if scatter:   # e.g. LHS samples: no two points share the other keys' values
                series = [((), {x: ys for _, points in series for x, ys in points.items()})]
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
    axes[0].set_ylabel(column_label(metric))
    n_seeds = len({r["seed"] for r in rows})
    case_text = _case_label(cases[0], cases) if len(cases) == 1 else f"{len(cases)} cases"
    fig.suptitle(f"{column_words(metric)}: mean ± std over {n_seeds} "
                 f"seed{'s' * (n_seeds > 1)} ({case_text})", fontsize=10)
    return fig


HATCHES = ("", "//", "..", "xx", "\\\\", "++", "oo", "--")
"""Bar hatches, so that the cases of a bar figure read in grayscale too."""


def _case_figure(rows: list[dict[str, Any]], metric: str) -> Any:
    """Grouped bars: a group per scenario, a bar per other case (architecture, controller,
    ...: the fields that differ) with its mean ± std over seeds and its value above it."""
    from matplotlib.figure import Figure

    scenarios = sorted({r["scenario"] for r in rows}, key=scenario_order)
    cases = sorted({tuple(r.get(c) for c in CASE[1:]) for r in rows}, key=str)
    labels = [_case_label(("", *case), [("", *c) for c in cases]).strip() for case in cases]
    colors = matplotlib.colormaps["tab10"]
    m_scale = display_unit(column_unit(metric))[0]
    width, height = max(6.0, 1.1 * len(scenarios) * max(1, len(cases)) / 2 + 2.6), 4.4
    fig = Figure(figsize=(width, height))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.85 / width, right=1.0 - 1.7 / width, bottom=0.6 / height,
                        top=1.0 - 0.45 / height)
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
    for i in np.flatnonzero(~measured):    # e.g. a settling time where nothing steps
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


CHANNEL_DISPLAY: dict[str, tuple[str, float]] = {
    "tension_N": ("F_ten [kN]", 1e-3), "p_head_Pa": ("p_head [MPa]", 1e-6),
    "p_rod_Pa": ("p_rod [MPa]", 1e-6), "stroke_m": ("stroke [mm]", 1e3)}
"""Label and display scale of the channels a log is compared on."""


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
    _legend_above(axes[0][0], ncol=3)
    fig.suptitle(title, fontsize=10)
    return _save(fig, Path(path))
