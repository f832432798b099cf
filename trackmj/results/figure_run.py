"""The figure of one run (:func:`run_figure`, PNG): tension (raw as a light min-max band,
low-pass as the line, reference), chamber and supply pressures, valve mode and u, zooms on
the events, energy breakdown; a measured log overlaid where there is one. Display units:
kN, MPa, mm, kJ."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.gridspec import GridSpecFromSubplotSpec

from trackmj.results.figure_energy import energy_bars
from trackmj.results.figure_panels import shade_events, tension_panel, zoom_windows
from trackmj.results.figure_style import RAW_COLOUR, envelope, legend_above, save_png
from trackmj.results.metric_windows import MetricWindows, windows_of
from trackmj.results.signals import lowpass
from trackmj.results.store import Result

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
    zooms = zoom_windows(w, t_end)
    measured = dict(measured or {})
    stroke = "stroke_m" in measured
    fig, left, right = _run_grid(stroke, len(zooms))
    ax_f = fig.add_subplot(left[0])
    ax_p = fig.add_subplot(left[1], sharex=ax_f)
    ax_v = fig.add_subplot(left[3 if stroke else 2], sharex=ax_f)
    ax_u = fig.add_subplot(left[4 if stroke else 3], sharex=ax_f)
    tension_panel(ax_f, [(result.architecture, result)], w)
    _measured_overlay(ax_f, ax_p, t, measured, w.lowpass_cutoff_Hz)
    if stroke:
        _stroke_panel(fig.add_subplot(left[2], sharex=ax_f), t, c["stroke_m"],
                      measured["stroke_m"], w.lowpass_cutoff_Hz)
    legend_above(ax_f, ncol=4)
    _pressure_panel(ax_p, c, w, t_end, ncol=3 if measured else None)
    _valve_panels(ax_v, ax_u, c, w, t_end)
    for ax in (ax_f, ax_p, ax_v):
        ax.tick_params(labelbottom=False)
    for k, (title, t0, t1) in enumerate(zooms):
        ax = fig.add_subplot(right[k])
        tension_panel(ax, [(result.architecture, result)], w, (t0, t1), legend=False,
                      raw_as_line=True)
        ax.set_title(f"zoom: {title}", fontsize=9, loc="left")
        ax.set_xlabel("time [s]")
    energy_bars(fig.add_subplot(right[len(zooms)]), [result.architecture], [result],
                below=True)
    fig.suptitle(f"{result.scenario} {result.architecture} {result.controller}/"
                 f"{result.estimator} seed {result.seed}, variant "
                 f"{result.metadata.get('variant', 'nominal')}")
    return save_png(fig, Path(path))


def _run_grid(stroke: bool, n_zooms: int,
              ) -> tuple[Figure, GridSpecFromSubplotSpec, GridSpecFromSubplotSpec]:
    """The figure and its two columns' grids: on the left tension, pressures, (stroke,)
    valve mode and u; on the right ``n_zooms`` zooms and the energy bars."""
    fig = plt.figure(figsize=(16, 14 if stroke else 12), layout="constrained")
    outer = fig.add_gridspec(1, 2, width_ratios=(2.0, 1.0))
    left = outer[0].subgridspec(5 if stroke else 4, 1,
                                height_ratios=(3.0, 2.0, *((1.6,) if stroke else ()), 1.1, 1.1))
    right = outer[1].subgridspec(n_zooms + 1, 1,
                                 height_ratios=(*[1.0] * n_zooms, 1.2 + 0.6 * n_zooms))
    return fig, left, right


def _measured_overlay(ax_f: Axes, ax_p: Axes, t: np.ndarray, measured: Mapping[str, np.ndarray],
                      fc: float) -> None:
    """The measured tension [kN] and chamber pressures [MPa], low-passed at ``fc`` [Hz]."""
    if "tension_N" in measured:
        ax_f.plot(t, lowpass(t, measured["tension_N"], fc) / 1e3, color=MEASURED_COLOUR,
                  lw=1.2, ls="--", label=f"measured F_ten {fc:g} Hz low-pass")
    for name, ls in (("p_head_Pa", "-"), ("p_rod_Pa", "--")):
        if name in measured:
            ax_p.plot(t, lowpass(t, measured[name], fc) / 1e6, color=MEASURED_COLOUR, ls=ls,
                      lw=1.1, label=f"measured {name[:-3]} {fc:g} Hz low-pass")


def _stroke_panel(ax_y: Axes, t: np.ndarray, stroke_m: np.ndarray,
                  measured_m: np.ndarray, fc: float) -> None:
    """The run's and the measured stroke [mm], both low-passed at ``fc`` [Hz]."""
    ax_y.plot(t, lowpass(t, stroke_m, fc) * 1e3, color="black", lw=1.1,
              label=f"stroke {fc:g} Hz low-pass")
    ax_y.plot(t, lowpass(t, measured_m, fc) * 1e3, color=MEASURED_COLOUR,
              ls="--", lw=1.1, label=f"measured stroke {fc:g} Hz low-pass")
    ax_y.set_ylabel("stroke [mm]")
    ax_y.grid(alpha=0.3)
    ax_y.tick_params(labelbottom=False)
    legend_above(ax_y)


def _pressure_panel(ax_p: Axes, c: Mapping[str, np.ndarray], w: MetricWindows, t_end: float,
                    ncol: int | None) -> None:
    """Chamber pressures [MPa] (raw head pressure as a band, low-passed lines) and the
    supply pressure as it is (a smooth node); a legend entry for a pressure the
    architecture has none of."""
    t = c["t_s"]
    if np.isfinite(c["p_head_Pa"]).all():
        tb, lo, hi = envelope(t, c["p_head_Pa"])
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
    shade_events(ax_p, w, t_end, label=False)
    ax_p.set_ylabel("pressure [MPa]")
    ax_p.grid(alpha=0.3)
    legend_above(ax_p, ncol=ncol)


def _valve_panels(ax_v: Axes, ax_u: Axes, c: Mapping[str, np.ndarray], w: MetricWindows,
                  t_end: float) -> None:
    """The valve mode (−1 release, 0 hold, +1 pressurize) and the controller's command u."""
    t = c["t_s"]
    ax_v.step(t, c["valve_mode"], where="post", color="black", lw=0.8, label="valve mode")
    ax_v.set_yticks([-1, 0, 1], ["−1 release", "0 hold", "+1 pressurize"])
    ax_v.set_ylim(-1.4, 1.4)
    ax_v.set_ylabel("mode [-]")
    shade_events(ax_v, w, t_end, label=False)
    ax_v.grid(alpha=0.3)
    ax_u.plot(t, c["u"], color="#0072B2", lw=0.6,
              label="u: the controller's command in [−1, 1] (> 0 pressurize, < 0 release), "
                    "which the valve logic turns into the modes above")
    ax_u.set_ylabel("u [-]")
    legend_above(ax_u)
    ax_u.set_xlabel("time [s]")
    shade_events(ax_u, w, t_end, label=False)
    ax_u.grid(alpha=0.3)
