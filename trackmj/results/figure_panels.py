"""Time panels the run and comparison figures share (display unit kN): the tension panel
(:func:`tension_panel`: raw as a light min-max band, low-pass as the line, the reference),
the admissible band [F_min, F_max] shaded green (:func:`force_band`), the disturbance
windows (load pulses, supply drops) grey (:func:`shade_events`), and the windows the zoom
panels show (:func:`zoom_windows`) with their titles (:func:`zoom_titles`). The windows
come from the run's own ``metrics["evaluation"]`` table.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

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
from trackmj.results.store import Result, running_text

ZOOM_TITLE_PT = 9.0
"""Font size of a zoom panel's title [pt]."""
CHAR_WIDTH_EM = 0.55
"""Width of a title character as a share of its font size, with a margin (DejaVu Sans
averages about 0.51 em on these lower-case titles)."""
_NBSP = "\u00a0"


def shade_events(ax: Axes, w: MetricWindows, t_end: float, label: bool = True) -> None:
    """Grey spans over the disturbance windows up to the run's end ``t_end`` [s] (a window
    after the end of a shortened run is not drawn); a dotted line at the reference step.
    A window that starts before the evaluation start is the run's initial condition, not an
    event (NL1's supply at 9 MPa from t = 0): it is shaded only from the evaluation start
    to its end, and not at all if it lasts the run, which the legend then says
    (:func:`initial_condition_text`)."""
    named = set()
    for k, (on, off) in enumerate(w.disturbances):
        if on >= t_end:
            continue
        kind = _disturbance_kind(w, k)
        if on < w.evaluation_start_s:
            if off >= t_end:           # no edge in the run: a legend line, no span
                if label:
                    ax.plot([], [], ls="none", label=initial_condition_text(w, k))
                continue
            on = w.evaluation_start_s
        off = min(off, t_end)
        if off <= on:
            continue
        ax.axvspan(on, off, color=EVENT_COLOUR, alpha=0.15, lw=0,
                   label=f"{kind} window" if label and kind not in named else None)
        named.add(kind)
    if w.step is not None and w.step[0] < t_end:
        ax.axvline(w.step[0], color=EVENT_COLOUR, ls="-.", lw=1.0,
                   label=f"reference step at {w.step[0]:g} s" if label else None)


def initial_condition_text(w: MetricWindows, k: int) -> str:
    """Disturbance ``k`` as the run's initial condition: "supply at 9 MPa from the start"
    (from its onset when that is after t = 0)."""
    states = w.disturbance_states or w.disturbance_labels
    what = states[k] if k < len(states) else "disturbance"
    on = w.disturbances[k][0]
    return f"{what} from the start" if on <= 0.0 else f"{what} from {on:g} s"


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


def zoom_windows(w: MetricWindows, t_end: float, running: Mapping[str, Any] | None = None,
                 ) -> list[tuple[str, float, float]]:
    """(title, t0, t1) of the zoom panels [s]: the reference step, each disturbance edge
    (onset and end) from the evaluation start (an earlier one is the run's initial
    condition), or, with none, the next reference change after the step (NL1's first
    release), or, with neither, one second from the steady window's start, titled by how the
    track runs in it (the run's ``running`` record, :func:`quiet_window_title`)."""
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
        zooms.append((quiet_window_title(t0, t0 + 1.0, running), t0, t0 + 1.0))
    return [(title, max(t0, 0.0), min(t1, t_end)) for title, t0, t1 in zooms]


def quiet_window_title(t0: float, t1: float, running: Mapping[str, Any] | None) -> str:
    """Title of a zoom on [t0, t1] [s] without a step or disturbance, by how the track runs
    (a run's ``running`` record): "steady running at 1.5 m/s, 5–6 s" at a constant forward
    speed, "standing still, 5–6 s", else the window and the running in the words of
    :func:`~trackmj.results.store.running_text` ("5–6 s, reversing at 1.5 m/s", "5–6 s,
    forward and back (speed from a file)"); "5–6 s, no step or disturbance" for a run
    without the record."""
    window = f"{t0:g}–{t1:g} s"
    if not running:
        return f"{window}, no step or disturbance"
    speed = running.get("speed_m_s")
    if speed is not None and speed > 0.0:
        return f"steady running at {speed:g} m/s, {window}"
    if speed == 0.0:
        return f"standing still, {window}"
    how = running_text({**running, "grade": 0.0})     # the grade is the suptitle's
    return f"{window}{how or ', track speed from a file'}"


def zoom_titles(fig: Figure, zooms: Sequence[tuple[Axes, str]]) -> None:
    """Title each zoom panel ``(axes, title)`` of ``fig`` "zoom: ``title``", left-aligned at
    ZOOM_TITLE_PT and wrapped to the panel's width (:func:`wrap_title`), so that a long
    title (a load pulse's hitch force, a moved pulse's times) runs neither into the next
    panel nor off the figure, where it lost its end, the edge's time and unit. Wrapped at
    the width before the layout, then again at the width the figure's layout gives."""
    for laid_out in (False, True):
        if laid_out and (engine := fig.get_layout_engine()) is not None:
            engine.execute(fig)
        for ax, title in zooms:
            width_pt = ax.get_window_extent().width / fig.dpi * 72.0
            chars = int(width_pt / (CHAR_WIDTH_EM * ZOOM_TITLE_PT))
            ax.set_title(wrap_title(f"zoom: {title}", chars), fontsize=ZOOM_TITLE_PT,
                         loc="left")


def wrap_title(text: str, width_chars: int) -> str:
    """``text`` in lines of at most ``width_chars`` characters, broken at spaces but not
    between a number and the word after it (its unit) nor in a time "onset at 9.25 s" (it
    stays on one line); a word longer than a line stays whole."""
    glued = re.sub(r"(?<=\d) (?=\S)", _NBSP, text)
    glued = re.sub(r"(?<=\w) at (?=[-+]?\d)", f"{_NBSP}at{_NBSP}", glued)
    lines = textwrap.wrap(glued, max(width_chars, 1), break_long_words=False,
                          break_on_hyphens=False)
    return "\n".join(lines).replace(_NBSP, " ")


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
