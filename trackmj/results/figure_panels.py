"""Time panels the run and comparison figures share (display unit kN): the tension panel
(:func:`tension_panel`: raw as a light min-max band, low-pass as the line, the reference),
the admissible band [F_min, F_max] shaded green (:func:`force_band`), the disturbance
windows (load pulses, supply drops) grey (:func:`shade_events`), and the windows the zoom
panels show (:func:`zoom_windows`). The windows come from the run's own
``metrics["evaluation"]`` table.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes

from trackmj.results.figure_style import (
    BAND_COLOUR,
    EVENT_COLOUR,
    MEASURED_COLOUR,
    RAW_COLOUR,
    envelope,
    marker_step,
    span,
    style,
)
from trackmj.results.metric_windows import MetricWindows
from trackmj.results.signals import lowpass
from trackmj.results.store import Result


def shade_events(ax: Axes, w: MetricWindows, t_end: float, label: bool = True) -> None:
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


def force_band(ax: Axes, w: MetricWindows, label: bool = True) -> None:
    """The admissible band [F_min, F_max] [kN], shaded green between dashed edges."""
    ax.axhspan(w.force_min_N / 1e3, w.force_max_N / 1e3, facecolor=(0.0, 0.62, 0.45, 0.08),
               edgecolor=BAND_COLOUR, lw=0.9, ls="--",
               label=f"admissible band F_min–F_max, "
                     f"{span(w.force_min_N / 1e3, w.force_max_N / 1e3, 'kN')}" if label else None)


def zoom_windows(w: MetricWindows, t_end: float) -> list[tuple[str, float, float]]:
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


def tension_panel(ax: Axes, runs: Sequence[tuple[str, Result]], w: MetricWindows,
                  t_range: tuple[float, float] | None = None, raw_of: int = 0,
                  legend: bool = True, raw_as_line: bool = False,
                  measured_N: np.ndarray | None = None) -> None:
    """Low-passed F_ten of each run (styled), the raw F_ten of run ``raw_of`` as a light band
    (or a thin line in a zoom), the reference, the force band and the events; a measured
    tension ``measured_N`` [N] on the run's grid low-passed like the run's (dashed)."""
    label0, first = runs[raw_of]
    c = first.columns()
    t = c["t_s"]
    sel = np.ones(t.shape, bool) if t_range is None else (t >= t_range[0]) & (t <= t_range[1])
    raw_label = f"{label0} raw" if len(runs) > 1 else "F_ten raw"
    if raw_as_line:
        ax.plot(t[sel], c["tension_N"][sel] / 1e3, color=RAW_COLOUR, lw=0.6, label=raw_label)
    else:
        tb, lo, hi = envelope(t[sel], c["tension_N"][sel])
        ax.fill_between(tb, lo / 1e3, hi / 1e3, color=RAW_COLOUR, lw=0,
                        label=f"{raw_label} (50 ms min-max)")
    for k, (label, res) in enumerate(runs):
        cc = res.columns()
        lp = lowpass(cc["t_s"], cc["tension_N"], w.lowpass_cutoff_Hz)
        name = (f"{label} {w.lowpass_cutoff_Hz:g} Hz low-pass" if len(runs) > 1
                else f"F_ten {w.lowpass_cutoff_Hz:g} Hz low-pass")
        ax.plot(cc["t_s"][sel], lp[sel] / 1e3, lw=1.3, markersize=5, label=name,
                markevery=marker_step(int(sel.sum())), markerfacecolor="white",
                **style(label, k))
    if measured_N is not None:
        ax.plot(t[sel], lowpass(t, measured_N, w.lowpass_cutoff_Hz)[sel] / 1e3,
                color=MEASURED_COLOUR, lw=1.3, ls="--",
                label=f"measured F_ten {w.lowpass_cutoff_Hz:g} Hz low-pass")
    ax.plot(t[sel], c["tension_ref_N"][sel] / 1e3, color="black", lw=1.0, ls=(0, (1, 1.5)),
            label="reference F_ref")
    force_band(ax, w, label=legend)
    shade_events(ax, w, float(t[-1]), label=legend)
    ax.set_ylabel("F_ten [kN]")
    if t_range is not None:
        ax.set_xlim(*t_range)
        shown = [c["tension_N"][sel], c["tension_ref_N"][sel]]
        if measured_N is not None:
            shown.append(measured_N[sel])
        lo_y = min(float(np.nanmin(x)) for x in shown)
        hi_y = max(float(np.nanmax(x)) for x in shown)
        pad = 0.08 * (hi_y - lo_y) + 50.0
        ax.set_ylim((lo_y - pad) / 1e3, (hi_y + pad) / 1e3)
    ax.grid(alpha=0.3)
