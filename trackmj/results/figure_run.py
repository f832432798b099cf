"""The figure of one run (:func:`run_figure`, PNG): tension (raw as a light min-max band,
low-pass as the line, reference), chamber and supply pressures, valve mode and u, zooms on
the events, energy waterfall; a measured log overlaid where there is one, its errors in the
title (:func:`run_title`). Display units: kN, MPa, mm, J or kJ."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure, SubFigure

from trackmj.results.figure_energy import energy_bars
from trackmj.results.figure_panels import (
    shade_events,
    tension_panel,
    zoom_titles,
    zoom_windows,
)
from trackmj.results.figure_style import (
    MEASURED_COLOUR,
    RAW_COLOUR,
    envelope,
    legend_above,
    machine_of,
    measured_log_of,
    number,
    save_png,
    span,
)
from trackmj.results.metric_windows import MetricWindows, windows_of
from trackmj.results.signals import lowpass
from trackmj.results.store import Result, running_of, running_text

MEASURED_PANELS = {"tension_N": "F_ten", "p_head_Pa": "p_head", "p_rod_Pa": "p_rod",
                   "p_supply_Pa": "p_supply", "stroke_m": "stroke", "valve_mode": "valve mode",
                   "u": "u"}
"""The measured channels the run figure draws (each in the panel of the run's own), by the
name its panels give them."""
DISPLAY_UNITS = {"N": ("kN", 1e-3), "Pa": ("MPa", 1e-6), "m": ("mm", 1e3),
                 "m_s": ("mm/s", 1e3), "m3_s": ("L/min", 6e4), "m_s2": ("m/s²", 1.0),
                 "J": ("kJ", 1e-3), "s": ("s", 1.0), "": ("", 1.0)}
"""SI suffix of a column -> (display unit, factor from SI; '': dimensionless)."""


def run_figure(result: Result, path: str | Path,
               measured: Mapping[str, np.ndarray] | None = None) -> Path:
    """One run: tension (raw band, low-pass, reference, F band, events), chamber and supply
    pressures, valve mode (−1/0/+1), valve opening u, zoom panels on the step, each
    disturbance edge (or a second of steady running) and the energy waterfall; the title
    names the scenario, the machine, the run and the measured log. With a ``measured`` log
    on the run's grid (:func:`trackmj.results.measured.resample`), its channels are drawn in
    the panels of the run's own (tension in the zooms too; a stroke panel is added for a
    measured stroke), low-passed like the run's, and its RMSE and lag per channel (the
    result's ``prediction_vs_measured``) are in the title."""
    w = windows_of(result)
    c = result.columns()
    t = c["t_s"]
    t_end = float(t[-1])
    zooms = zoom_windows(w, t_end, running_of(result))
    measured = dict(measured or {})
    measured_N = measured.get("tension_N")
    stroke = "stroke_m" in measured
    fig, time_axes, zoom_axes, energy = _run_axes(stroke, len(zooms))
    ax_f, ax_p, *ax_y, ax_v, ax_u = time_axes
    tension_panel(ax_f, [(result.architecture, result)], w, measured_N=measured_N)
    if stroke:
        _stroke_panel(ax_y[0], t, c["stroke_m"],
                      measured["stroke_m"], w.lowpass_cutoff_Hz)
    legend_above(ax_f, ncol=3)
    _pressure_panel(ax_p, c, w, t_end, measured)
    _valve_panels(ax_v, ax_u, c, w, t_end, measured)
    for ax in (ax_f, ax_p, ax_v):
        ax.tick_params(labelbottom=False)
    for ax, (_, t0, t1) in zip(zoom_axes, zooms, strict=True):
        tension_panel(ax, [(result.architecture, result)], w, (t0, t1), legend=False,
                      raw_as_line=True, measured_N=measured_N)
        ax.set_xlabel("time [s]")
    energy_bars(energy, [result.architecture], [result])
    fig.suptitle(run_title(result, measured_channels=[n for n in measured if n != "t_s"]))
    zoom_titles(fig, [(ax, title) for ax, (title, _, _) in zip(zoom_axes, zooms, strict=True)])
    return save_png(fig, Path(path))


def run_title(result: Result, measured_channels: Sequence[str] = ()) -> str:
    """Title of a run's figure: "W1, machine m113: tp nmpc/ekf, seed 0" (the variant
    unless nominal, and how the track ran unless forward on level ground: ", reversing at
    1.5 m/s, on a grade of +0.2 ..."); with a measured log (its channels
    ``measured_channels``, or the result's ``prediction_vs_measured``) a line naming the
    log and the tracking window, then each channel's RMSE (raw and low-passed) and lag."""
    machine = machine_of(result)
    variant = result.metadata.get("variant", "nominal")
    title = (f"{result.scenario}{f', machine {machine}' if machine else ''}: "
             f"{result.architecture} {result.controller}/{result.estimator}, seed {result.seed}"
             f"{'' if variant == 'nominal' else f', variant {variant}'}"
             f"{running_text(running_of(result))}")
    errors = result.metrics.get("prediction_vs_measured")
    log = measured_log_of(result)
    if not (log or measured_channels or isinstance(errors, Mapping)):
        return title
    w = windows_of(result)
    t_end = float(result.columns()["t_s"][-1])
    lines = [title, f"against measured log {log or '(file not recorded)'}: RMSE and lag over "
                    f"the tracking window {span(w.evaluation_start_s, t_end, 's')} "
                    "(lag > 0: the run lags the log)"]
    parts = [_channel_errors(name, e, w.lowpass_cutoff_Hz)
             for name, e in (errors.items() if isinstance(errors, Mapping) else ())]
    lines += ["; ".join(parts[k:k + 2]) for k in range(0, len(parts), 2)]
    if not parts:
        lines.append("no prediction_vs_measured in this result")
    return "\n".join(lines)


def _channel_errors(channel: str, errors: Mapping[str, float], cutoff_Hz: float) -> str:
    """One channel's errors against the log in display units: "F_ten: RMSE 0.63 kN
    (2 Hz low-pass 0.41 kN), lag 30 ms"."""
    suffix = next((s for s in sorted(DISPLAY_UNITS, key=len, reverse=True)
                   if s and channel.endswith("_" + s)), "")
    unit, scale = DISPLAY_UNITS[suffix]
    name = MEASURED_PANELS.get(channel, channel[: -len(suffix) - 1] if suffix else channel)
    key = f"_{suffix}" if suffix else ""

    def shown(value: object, factor: float, unit: str) -> str:
        v = float(value) if isinstance(value, int | float) else math.nan
        return f"{number(v * factor)} {unit}".strip() if math.isfinite(v) else "–"

    return (f"{name}: RMSE {shown(errors.get(f'rmse{key}'), scale, unit)} "
            f"({cutoff_Hz:g} Hz low-pass {shown(errors.get(f'rmse_lp{key}'), scale, unit)}), "
            f"lag {shown(errors.get('lag_s'), 1e3, 'ms')}")


def _run_axes(stroke: bool, n_zooms: int,
              ) -> tuple[Figure, list[Axes], list[Axes], SubFigure]:
    """The figure, its time panels sharing their time axis (on the left: tension,
    pressures, (stroke,) valve mode, u), its ``n_zooms`` zooms (on the right) and the
    subfigure of the energy panel (under them). The three groups are subfigures, each laid
    out on its own: the energy panel's long row labels do not narrow the zooms."""
    fig = plt.figure(figsize=(16, 14 if stroke else 12), layout="constrained")
    columns = fig.add_gridspec(1, 2, width_ratios=(2.0, 1.0), wspace=0.0)
    left, right = fig.add_subfigure(columns[0]), fig.add_subfigure(columns[1])
    rows = right.add_gridspec(2, 1, height_ratios=(1.0 * n_zooms, 1.6 + 0.5 * n_zooms),
                              hspace=0.0)
    zooms, energy = right.add_subfigure(rows[0]), right.add_subfigure(rows[1])
    grid = left.add_gridspec(5 if stroke else 4, 1,
                             height_ratios=(3.0, 2.0, *((1.6,) if stroke else ()), 1.1, 1.1))
    first = left.add_subplot(grid[0])
    time_axes = [first, *(left.add_subplot(grid[k], sharex=first)
                          for k in range(1, grid.nrows))]
    zoom_axes = list(zooms.subplots(n_zooms, 1, squeeze=False)[:, 0])
    return fig, time_axes, zoom_axes, energy


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
                    measured: Mapping[str, np.ndarray]) -> None:
    """Chamber pressures [MPa] (raw head pressure as a band, low-passed lines) and the
    supply pressure as it is (a smooth node); a legend entry for a pressure the
    architecture has none of; the ``measured`` pressures, low-passed (dashed, in the
    measured colour)."""
    t = c["t_s"]
    fc = w.lowpass_cutoff_Hz
    if np.isfinite(c["p_head_Pa"]).all():
        tb, lo, hi = envelope(t, c["p_head_Pa"])
        ax_p.fill_between(tb, lo / 1e6, hi / 1e6, color=RAW_COLOUR, lw=0,
                          label="p_head raw (50 ms min-max)")
    for name, ls, label in (("p_head_Pa", "-", "p_head"), ("p_rod_Pa", "--", "p_rod"),
                            ("p_supply_Pa", ":", "p_supply")):
        if np.isfinite(c[name]).all() and name == "p_supply_Pa":     # a smooth node: as is
            ax_p.plot(t, c[name] / 1e6, color="black", ls=ls, lw=1.1, label=label)
        elif np.isfinite(c[name]).all():
            ax_p.plot(t, lowpass(t, c[name], fc) / 1e6, color="black", ls=ls,
                      lw=1.1, label=f"{label} {fc:g} Hz low-pass")
        else:
            ax_p.plot([], [], color="black", ls=ls, label=f"{label}: none in this architecture")
    for name, ls in (("p_head_Pa", "--"), ("p_rod_Pa", "-."), ("p_supply_Pa", ":")):
        if name in measured:
            ax_p.plot(t, lowpass(t, measured[name], fc) / 1e6, color=MEASURED_COLOUR, ls=ls,
                      lw=1.2, label=f"measured {MEASURED_PANELS[name]} {fc:g} Hz low-pass")
    shade_events(ax_p, w, t_end, label=False)
    ax_p.set_ylabel("pressure [MPa]")
    ax_p.grid(alpha=0.3)
    legend_above(ax_p, ncol=3 if measured else None)


def _valve_panels(ax_v: Axes, ax_u: Axes, c: Mapping[str, np.ndarray], w: MetricWindows,
                  t_end: float, measured: Mapping[str, np.ndarray]) -> None:
    """The valve mode (−1 release, 0 hold, +1 pressurize) and the controller's command u;
    a ``measured`` valve mode or u over them (in the measured colour)."""
    t = c["t_s"]
    ax_v.step(t, c["valve_mode"], where="post", color="black", lw=0.8, label="valve mode")
    if "valve_mode" in measured:
        ax_v.step(t, measured["valve_mode"], where="post", color=MEASURED_COLOUR, lw=0.8,
                  ls="--", label="measured valve mode")
        legend_above(ax_v)
    ax_v.set_yticks([-1, 0, 1], ["−1 release", "0 hold", "+1 pressurize"])
    ax_v.set_ylim(-1.4, 1.4)
    ax_v.set_ylabel("mode [-]")
    shade_events(ax_v, w, t_end, label=False)
    ax_v.grid(alpha=0.3)
    ax_u.plot(t, c["u"], color="#0072B2", lw=0.6,
              label="u: the controller's command in [−1, 1] (> 0 pressurize, < 0 release), "
                    "which the valve logic turns into the modes above")
    if "u" in measured:
        ax_u.plot(t, measured["u"], color=MEASURED_COLOUR, lw=0.6, ls="--", label="measured u")
    ax_u.set_ylabel("u [-]")
    legend_above(ax_u, ncol=1 if "u" in measured else None)
    ax_u.set_xlabel("time [s]")
    shade_events(ax_u, w, t_end, label=False)
    ax_u.grid(alpha=0.3)
