"""The tables and lines the commands print about a run: the headline metrics (markdown, one
column per run), the prediction against a measured log, and an FMU tensioner's coupling.

Display units (kN, mm, MPa) appear only here and in the commands' own lines; the metrics
they read are SI.
"""

from __future__ import annotations

from pathlib import Path

SUMMARY_METRICS = ("rmse_lp_N", "rmse_N", "ripple_rms_N", "ripple_band_rms_N.tooth_passing",
                   "ripple_band_rms_N.body_mode", "peak_error_lp_N", "peak_error_N",
                   "overshoot_lp_N", "settling_time_lp_s", "disturbance_peak_error_lp_N",
                   "recovery_time_lp_s", "fluctuation_N", "constraint_violation_s",
                   "acceptance.mean_min_N", "acceptance.mean_max_N",
                   "acceptance.recovery_max_s", "acceptance.steady_offset_max_rel",
                   "energy_J.pump", "energy_J.circuit", "energy_J.mechanical",
                   "valve_switch_rate_Hz", "interface_energy_residual_J",
                   "solve_time_median_s", "solve_time_max_s", "real_time_factor")
"""Rows of the summary table, metric keys (dotted for a table entry; labels and display
units in :data:`trackmj.results.metrics.METRIC_DISPLAY`)."""
STEP_METRICS = ("overshoot_lp_N", "settling_time_lp_s")
"""Rows shown only where a scenario has a setpoint step."""
DISTURBANCE_METRICS = ("disturbance_peak_error_lp_N", "recovery_time_lp_s")
"""Rows shown only where a scenario has a disturbance."""
UNSETTLED = ("settling_time_lp_s", "recovery_time_lp_s")
"""Times that read "not within ±band" when they never came."""

MEASURED_DISPLAY = {"N": (1e-3, "kN"), "Pa": (1e-6, "MPa"), "m": (1e3, "mm"), "": (1.0, "-")}
"""Display scale and unit of a compared channel, by its SI unit."""


def summary_table(results: list, title: str) -> str:
    """Markdown table of the headline metrics, one column per result (``title`` formatted
    with ``r=`` the result heads its column). Rows of a step or a disturbance appear only
    where the scenario has one; a settling or recovery time that never came reads "not
    within ±band" instead of a dash."""
    # start-up: --help and argument errors must not import SciPy
    from trackmj.results.metrics import METRIC_DISPLAY, lookup

    windows = [r.metrics.get("evaluation", {}) for r in results]
    has_step = any(w.get("step") for w in windows)
    has_disturbance = any(w.get("disturbances") for w in windows)
    head = "| metric | " + " | ".join(title.format(r=r) for r in results) + " |"
    lines = [head, "|---|" + "---|" * len(results)]
    for key in SUMMARY_METRICS:
        name, scale, unit = METRIC_DISPLAY[key]
        if (key in STEP_METRICS and not has_step) or (key in DISTURBANCE_METRICS
                                                      and not has_disturbance):
            continue
        cells = [_cell(lookup(r.metrics, key), w, key, scale)
                 for r, w in zip(results, windows, strict=True)]
        lines.append(f"| {name} [{unit}] | " + " | ".join(cells) + " |")
    cutoff = {w.get("lowpass_cutoff_Hz") for w in windows} - {None}
    if cutoff:
        lines.append("")
        lines.append(f"low-pass: zero-phase 2nd-order Butterworth at "
                     f"{', '.join(f'{c:g}' for c in sorted(cutoff))} Hz on F_ten; raw: the "
                     "1 kHz F_ten (see README, Metrics)")
    return "\n".join(lines)


def _cell(value: float, window: dict, key: str, scale: float) -> str:
    """One cell of the summary table: the ``value`` of metric ``key`` (NaN where the run has
    none) times its display ``scale``, or why there is none (``window``: the run's evaluation
    window)."""
    if value == value:
        return f"{value * scale:.3g}"
    if key in UNSETTLED and "settle_band_rel" in window:
        return f"not within ±{100 * window['settle_band_rel']:g} %"
    return "–"


def measured_table(table: dict, log: str) -> str:
    """Markdown table of ``prediction_vs_measured``: one row per channel (``log``: the
    measured log's path, named in the heading)."""
    lines = [f"prediction vs measured ({Path(log).name}; tracking window; > 0 lag: the "
             "simulation lags)", "",
             "| channel | RMSE raw | RMSE low-pass | peak (sim − meas) | lag [ms] |",
             "|---|---|---|---|---|"]
    for name, row in table.items():
        unit = name.rpartition("_")[2] if "_" in name else ""
        scale, shown = MEASURED_DISPLAY.get(unit, (1.0, unit))
        cells = [row.get(f"{k}_{unit}", float("nan")) * scale
                 for k in ("rmse", "rmse_lp", "peak_error")]
        lines.append(f"| {name} [{shown}] | " + " | ".join(f"{v:.3g}" for v in cells)
                     + f" | {row['lag_s'] * 1e3:.0f} |")
    return "\n".join(lines)


def tensioner_line(described: dict) -> str:
    """One line on an FMU tensioner's coupling (``Element.run_metrics()["tensioner"]``)."""
    cost = described.get("step_cost_us")
    per_step = f"; {cost:.0f} µs of FMU calls per 1 ms step" if cost is not None else ""
    return (f"tensioner: FMU {described['fmu']}, {described['coupling_description']} "
            f"(dF/dv: {described['dF_dv']}){per_step}")
