"""The tables and lines the commands print about a run: the headline metrics (markdown, one
column per run) with the scenario's acceptance verdict on each run and a warning line for
each run that is not a valid result (its ``flags``, e.g. a controller output clipped), the
prediction against a measured log, and an FMU tensioner's coupling.

Display units (kN, mm, MPa) appear only here and in the commands' own lines; the metrics
they read are SI.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from trackmj.ports import unit_suffix
from trackmj.results.verdict import not_back_texts, run_verdict

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
EDGE_RECOVERY = "acceptance.recovery_max_s"
"""The acceptance's slowest return after a disturbance edge: where the 0.5 s mean did not
come back after some edge, names those edges in the verdict's words ("not back after the
E s edge before the next one at F s", "never after the E s edge")."""
VALVE_METRICS = ("valve_switches", "valve_switch_rate_Hz")
"""Rows that read "n/a" for a run whose tensioner takes no valve mode
(``valve_mode_applied`` false: a passive tensioner, an FMU without a valve_mode input)."""

MEASURED_DISPLAY = {"N": (1e-3, "kN"), "Pa": (1e-6, "MPa"), "m": (1e3, "mm"),
                    "m_s": (1e3, "mm/s"), "m3_s": (6e4, "L/min"), "": (1.0, "-")}
"""Display scale and unit of a compared channel, by its SI unit."""


def summary_table(results: list, title: str) -> str:
    """Markdown table of the headline metrics, one column per result (``title`` formatted
    with ``r=`` the result heads its column). Rows of a step or a disturbance appear only
    where the scenario has one; a settling or recovery time that never came reads "not
    within ±band" instead of a dash (the acceptance's edge recovery names the edges it
    did not come back after, as the verdict below does), a valve metric of a tensioner
    without valves "n/a".
    Below the table, each run's acceptance verdict (:func:`acceptance_line`) and one
    warning line per flag of each run (:func:`warning_lines`)."""
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
        cells = [_cell(lookup(r.metrics, key), r.metrics, w, key, scale)
                 for r, w in zip(results, windows, strict=True)]
        lines.append(f"| {name} [{unit}] | " + " | ".join(cells) + " |")
    cutoff = {w.get("lowpass_cutoff_Hz") for w in windows} - {None}
    if cutoff:
        lines.append("")
        lines.append(f"low-pass: zero-phase 2nd-order Butterworth at "
                     f"{', '.join(f'{c:g}' for c in sorted(cutoff))} Hz on F_ten; raw: the "
                     "1 kHz F_ten (see README, Metrics)")
    bands = {_bands_text(w) for w in windows} - {""}
    if bands:
        lines.append("ripple bands: " + "; ".join(sorted(bands)))
    names = [title.format(r=r) if len(results) > 1 else "" for r in results]
    verdicts = [line for r, name in zip(results, names, strict=True)
                if (line := acceptance_line(r.metrics, name))]
    if verdicts:
        lines += ["", *verdicts]
    warnings = [line for r, name in zip(results, names, strict=True)
                for line in warning_lines(r.metrics, name)]
    if warnings:
        lines += ["", *warnings]
    return "\n".join(lines)


def _bands_text(window: Mapping[str, Any]) -> str:
    """The tooth-passing and body-mode bands of a run's windows in words ("" without
    either), e.g. "tooth passing 8.77-10.7 Hz, body mode 5.16-7.75 Hz"; where they overlap
    (a track speed whose tooth passing falls on the body mode) it says that both rows count
    the overlap."""
    tooth, body = window.get("tooth_passing_band_Hz"), window.get("body_mode_band_Hz")
    parts = [f"{label} {band[0]:.3g}-{band[1]:.3g} Hz"
             for label, band in (("tooth passing", tooth), ("body mode", body)) if band]
    text = ", ".join(parts)
    if tooth and body and tooth[0] <= body[1] and body[0] <= tooth[1]:
        text += " (overlapping: both rows count the ripple they share)"
    return text


def acceptance_line(metrics: Mapping[str, Any], run: str = "") -> str:
    """The scenario's acceptance verdict on a run (:func:`trackmj.results.verdict.run_verdict`)
    in one line naming each rule broken and by how much; "" for a run without acceptance
    figures (``run``: its name, for a table of several)."""
    v = run_verdict(metrics)
    if v is None:
        return ""
    return f"acceptance ({run}): {v.text()}" if run else f"acceptance: {v.text()}"


def _cell(value: float, metrics: Mapping[str, Any], window: dict, key: str,
          scale: float) -> str:
    """One cell of the summary table: the ``value`` of metric ``key`` (NaN where the run has
    none) times its display ``scale``, or why there is none (``metrics``: the run's,
    ``window``: its evaluation window)."""
    if key in VALVE_METRICS and metrics.get("valve_mode_applied") is False:
        return "n/a"
    if value == value:
        return f"{value * scale:.3g}"
    if key in UNSETTLED and "settle_band_rel" in window:
        return f"not within ±{100 * window['settle_band_rel']:g} %"
    if key == EDGE_RECOVERY:
        not_back = not_back_texts(metrics.get("acceptance") or {})
        if not_back:
            return ", ".join(not_back)
    return "–"


def flagged(metrics: Mapping[str, Any]) -> bool:
    """Whether a run is marked as not a valid result (its ``flags`` are not empty): ``trackmj
    run`` then exits with 1 after writing it."""
    return bool(metrics.get("flags"))


def warning_lines(metrics: Mapping[str, Any], run: str = "") -> list[str]:
    """One line per flag of a run's ``metrics`` (``run``: its name, for a table of several)
    saying why it is not a valid result."""
    head = f"WARNING ({run})" if run else "WARNING"
    lines = []
    for flag in metrics.get("flags") or ():
        table = metrics.get(flag)
        if flag == "controller_output_clipped" and isinstance(table, Mapping):
            lines.append(f"{head}: {clipping_text(table)}")
        else:
            lines.append(f"{head}: {flag} (see metrics.json)")
    return lines


def clipping_text(clipped: Mapping[str, Any]) -> str:
    """What ``controller_output_clipped`` says, in one sentence."""
    worst, first = clipped.get("worst", float("nan")), clipped.get("first_s", float("nan"))
    worst_text = f"{worst:.4g}" if worst == worst else "not finite"
    return (f"the controller's output was outside its range [-1, 1] "
            f"{clipped['outputs']:.0f} times, from t = {first:.3f} s (worst {worst_text}), "
            f"and was clipped to it for {clipped['steps']:.0f} steps "
            f"({100 * clipped['share']:.0f} % of the run): this result is not what the "
            "controller asked for; check the output's mapping and scaling")


def measured_table(table: dict, log: str) -> str:
    """Markdown table of ``prediction_vs_measured``: one row per channel (``log``: the
    measured log's path, named in the heading)."""
    lines = [f"prediction vs measured ({Path(log).name}; tracking window; > 0 lag: the "
             "simulation lags)", "",
             "| channel | RMSE raw | RMSE low-pass | peak (sim − meas) | lag [ms] |",
             "|---|---|---|---|---|"]
    for name, row in table.items():
        unit = unit_suffix(name)
        scale, shown = MEASURED_DISPLAY.get(unit, (1.0, unit))
        cells = [row.get(f"{k}_{unit}" if unit else k, float("nan")) * scale
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


CHECK_WORDS = {"slack_strand": "slack strand", "links_off_envelope": "links off envelope",
               "sprocket_disengaged": "sprocket disengaged"}
"""The derailment checks in the summaries' words (drive, run), in the order of the table."""


def _missing(value: Any) -> bool:
    """No value: None (a drive's metrics) or NaN (a run's, read back from metrics.json)."""
    return value is None or (isinstance(value, float) and math.isnan(value))


def derailment_lines(metrics: dict) -> list[str]:
    """The derailment lines of a drive's or a run's summary from its metrics (display units
    kN, mm): how many checks failed and the first failure, then one line per check, the
    failing ones first in the order they first failed: when and where it first failed, how
    often, its worst; a passing check's worst value (its margin)."""
    table = metrics["derailment"]
    failed, checks = metrics["derailment_checks_failed"], metrics["derailment_checks"]
    order = sorted(CHECK_WORDS, key=lambda c: (_missing(table[c]["first_s"]),
                                               0.0 if _missing(table[c]["first_s"])
                                               else table[c]["first_s"]))
    head = (f"derailment         {failed:.0f} of {checks:.0f} checks failed (every "
            f"{metrics['derailment_check_interval_s']:g} s)")
    if failed:
        first = order[0]
        head += f"; first: {CHECK_WORDS[first]} at {table[first]['first_s']:.2f} s"
    lines = [head]
    width = max(len(w) for w in CHECK_WORDS.values()) + 2
    for check in order:
        row, limit = table[check], _limit_text(check, table[check])
        worst = row["worst"]
        if _missing(worst):
            text = "not checked (a run shorter than the check interval)"
        elif row["failing_checks"]:
            text = (f"FAILED first at {row['first_s']:.2f} s: "
                    f"{_where_text(check, row['at_first'])} ({limit}); "
                    f"{_checks(row['failing_checks'])}, last at {row['last_s']:.2f} s; worst "
                    f"{_where_text(check, worst)} at {worst['t_s']:.2f} s")
        else:
            text = (f"passed; closest {_where_text(check, worst)} at {worst['t_s']:.2f} s "
                    f"({limit})")
        lines.append(f"  {CHECK_WORDS[check]:<{width}}{text}")
    return lines


def _checks(n: float) -> str:
    return f"{n:.0f} check" if n == 1 else f"{n:.0f} checks"


def _limit_text(check: str, row: dict) -> str:
    """When ``check`` fails (its ``row`` of the table), in display units."""
    threshold = row["threshold"]
    if check == "slack_strand":
        return f"fails below {threshold / 1e3:.2f} kN throughout {row['window_s']:g} s"
    if check == "links_off_envelope":
        return f"fails above {threshold * 1e3:.0f} mm"
    return (f"fails below {threshold:.0f} pins within {row['seat_tolerance_m'] * 1e3:.0f} mm "
            "of the pitch circle")


def _where_text(check: str, where: dict) -> str:
    """What ``check`` measured and where (an ``at_first`` or ``worst`` entry)."""
    if check == "slack_strand":
        now = ("no pin in the upper strand" if _missing(where["pin"]) else
               f"{where['tension_N'] / 1e3:.2f} kN at pin {where['pin']:.0f}")
        if _missing(where["held_tension_N"]):
            return f"upper-strand min tension {now} (no full window yet)"
        return (f"upper-strand min tension peaked at {where['held_tension_N'] / 1e3:.2f} kN "
                f"over the window, {now} at the check")
    if check == "links_off_envelope":
        return (f"pin {where['pin']:.0f}, {where['strand']}, {where['excursion_m'] * 1e3:.0f} mm "
                f"outside (chassis frame x {where['x_m']:.2f} m, z {where['z_m']:.2f} m)")
    return f"{where['seated_pins']:.0f} pins seated"


def end_stop_line(metrics: Mapping[str, Any], machine: str, grade: float | None = None,
                  when: str = "at the start of the run") -> str | None:
    """One line if the run's track settled with its idler carrier on an end stop
    (``metrics["settled_on_end_stop"]``, :func:`trackmj.sim.run.run`): the machine, the
    grade (tan θ; the record's own unless given), the stroke and the stop, and ``when`` the
    stop holds the idler; None otherwise."""
    on = metrics.get("settled_on_end_stop")
    if on is None:
        return None
    if grade is None:
        grade = float(on.get("grade", 0.0))
    return (f"trackmj: warning: {machine} on {_ground(grade)} settles with its idler carrier "
            f"on its {on['stop']} end stop (stroke {on['stroke_m'] * 1e3:.1f} mm, the stop "
            f"at {on['stop_stroke_m'] * 1e3:.1f} mm): the stop, not the tensioner, holds the "
            f"idler {when}")


def _ground(grade: float) -> str:
    """"level ground" or "a grade of +0.2 (tan θ)"."""
    return "level ground" if grade == 0.0 else f"a grade of {grade:+g} (tan θ)"


def end_stop_rows_line(rows: Sequence[Mapping[str, Any]]) -> str | None:
    """One line if any of a campaign's ``rows`` (flattened metrics, :func:`trackmj.study.
    campaign.flatten_metrics`: ``settled_on_end_stop.stroke_m`` and ``.stop_stroke_m`` [m],
    ``.grade`` [-]) settled with its idler carrier on an end stop: how many of the rows, and
    the first one's scenario, machine, grade, stroke and stop; None otherwise."""
    on = [r for r in rows if "settled_on_end_stop.stroke_m" in r]
    if not on:
        return None
    first = on[0]
    return (f"trackmj: warning: {len(on)} of {len(rows)} runs settled with the idler carrier "
            f"on an end stop, the first {first.get('scenario', '?')} on "
            f"{first.get('machine', '?')} on "
            f"{_ground(float(first.get('settled_on_end_stop.grade', 0.0)))} (stroke "
            f"{first['settled_on_end_stop.stroke_m'] * 1e3:.1f} mm, the stop at "
            f"{first['settled_on_end_stop.stop_stroke_m'] * 1e3:.1f} mm): the stop, not the "
            "tensioner, holds the idler at the start of those runs")
