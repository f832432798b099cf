"""Figures: units on every axis, legends outside the data, styles that survive grayscale,
the energy breakdown stacking the ledger's terms, zooms on each condition's events."""

from __future__ import annotations

import dataclasses
import re

import matplotlib.pyplot as plt
import matplotlib.text
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from synthetic import energy_table, synthetic_result

from trackmj.results import figure_compare, figure_energy, figure_panels, figure_run, figure_style
from trackmj.results.comparison import prediction_vs_tp
from trackmj.results.metric_windows import windows_of
from trackmj.results.store import Result
from trackmj.scenarios.load import load_scenario


@pytest.fixture
def captured(monkeypatch) -> list[plt.Figure]:
    """The figures the module would save, kept open for inspection."""
    figs: list[plt.Figure] = []
    for module in (figure_run, figure_compare):
        monkeypatch.setattr(module, "save_png", lambda fig, path: figs.append(fig) or path)
    yield figs
    for fig in figs:
        plt.close(fig)


def _runs(scenario: str = "W1", duration_s: float = 6.0) -> list:
    tp = synthetic_result(scenario, "tp", duration_s=duration_s, energy=energy_table())
    dpa = synthetic_result(scenario, "dp-a", duration_s=duration_s, offset_N=150.0,
                           energy=energy_table(1.1), chassis=False)
    dpb = synthetic_result(scenario, "dp-b", duration_s=duration_s, offset_N=-300.0,
                           ripple_N=50.0, energy=energy_table(ideal=True), supply=False)
    return [tp, dpa, dpb]


def _check_axes(fig: plt.Figure) -> None:
    """Every axis with data names its unit in brackets (the value axis; a category axis has
    no label); every legend lies outside its axes (above, beside them on the right, or
    below) and clear of every other axes and title; the figure's title clear of every axes
    with its labels and legend; every text is at least 9 pt at the saved size (the figure's
    own inches)."""
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    for ax in fig.axes:
        if not (ax.lines or ax.patches or ax.collections):
            continue
        labels = [label for label in (ax.get_ylabel(), ax.get_xlabel()) if label]
        assert labels and all("[" in label and "]" in label for label in labels), labels
        legend = ax.get_legend()
        if legend is not None:
            extent = legend.get_window_extent(renderer)
            box = extent.transformed(ax.transAxes.inverted())
            assert box.y0 >= 0.99 or box.x0 >= 1.0 or box.y1 <= 0.0, (
                f"legend of '{ax.get_ylabel()}' overlaps its data")
            others = [o.get_window_extent(renderer) for o in fig.axes if o is not ax]
            others += [t.get_window_extent(renderer) for o in fig.axes
                       for t in (o.title, o._left_title, o._right_title) if t.get_text()]
            assert not any(extent.overlaps(o) for o in others), (
                f"legend of '{ax.get_ylabel()}' runs into another panel or title")
    if fig.get_suptitle():
        title = fig._suptitle.get_window_extent(renderer)
        boxes = [ax.get_tightbbox(renderer) for ax in fig.axes]
        assert not any(title.overlaps(b) for b in boxes if b is not None), "title overlaps"
    small = {(t.get_text()[:40], t.get_fontsize()) for t in fig.findobj(matplotlib.text.Text)
             if t.get_text().strip() and t.get_visible() and t.get_fontsize() < 9}
    assert not small, small


def test_run_figure_units_legends_and_zooms(captured) -> None:
    tp = _runs("W3", duration_s=22.0)[0]
    tp.metrics["energy_J"]["numerical"] = {"volume_term": 20.0, "interface": 5.0}
    figure_run.run_figure(tp, "unused.png")
    fig = captured[0]
    _check_axes(fig)
    titles = [ax.get_title(loc="left") for ax in fig.axes if ax.get_title(loc="left")]
    assert titles == ["zoom: load pulse +2 kN, onset at 6 s",
                           "zoom: load pulse +2 kN, end at 8 s",
                           "zoom: load pulse -1.5 kN, onset at 18 s",
                           "zoom: load pulse -1.5 kN, end at 20 s"]
    u_axis = next(ax for ax in fig.axes if ax.get_ylabel() == "u [-]")
    assert "controller's command" in u_axis.get_legend().get_texts()[0].get_text()
    energy = next(ax for ax in fig.axes if ax.get_xlabel().startswith("energy ["))
    rows = [t.get_text() for t in energy.get_yticklabels()]
    assert "numerical (solver, coupling)" in rows and "throttling (valves, restrictors)" in rows
    assert not any("_" in row for row in rows), rows      # words, not the table's keys
    mode_axis = next(ax for ax in fig.axes if ax.get_ylabel() == "mode [-]")
    assert [t.get_text() for t in mode_axis.get_yticklabels()] == ["−1 release", "0 hold",
                                                                   "+1 pressurize"]


@pytest.mark.slow
def test_overlay_and_psd_figures_units_and_legends(captured) -> None:
    runs = _runs()
    preds = {r.architecture: prediction_vs_tp(r.columns(), r.metrics, runs[0].columns(),
                                              runs[0].metrics, windows_of(r))
             for r in runs}
    figure_compare.overlay_figure(runs, "unused.png", predictions=preds)
    figure_compare.overlay_figure(runs, "unused.png", label_by="controller")
    figure_compare.psd_figure(runs, "unused.png")
    for fig in captured:
        _check_axes(fig)
    bars = next(ax for ax in captured[0].axes if ax.get_ylabel() == "F_ten RMSE vs tp [kN]")
    heights = [p.get_height() for p in bars.patches]
    # dp-a is tp + 150 N (same noise and ripple): 0.15 kN raw and low-passed
    assert heights[0] == pytest.approx(0.15, abs=2e-3) and heights[2] == pytest.approx(0.15,
                                                                                        abs=2e-3)


def test_overlay_of_the_reference_alone_shows_its_own_figures(captured) -> None:
    """A report of tp alone has no prediction to compare: the bars are tp's tracking RMSE,
    peak head pressure and switching rate, not three empty comparison panels."""
    tp = _runs()[0]
    preds = {"tp": prediction_vs_tp(tp.columns(), tp.metrics, tp.columns(), tp.metrics,
                                    windows_of(tp))}
    figure_compare.overlay_figure([tp], "unused.png", predictions=preds)
    fig = captured[0]
    _check_axes(fig)
    rmse = next(ax for ax in fig.axes if ax.get_ylabel() == "tracking RMSE [kN]")
    assert [p.get_height() for p in rmse.patches] == pytest.approx(
        [tp.metrics["rmse_N"] / 1e3, tp.metrics["rmse_lp_N"] / 1e3])
    assert not any(ax.get_ylabel().startswith("F_ten RMSE vs") for ax in fig.axes)


def test_styles_differ_in_more_than_colour() -> None:
    """Readable in grayscale: within the architectures and within the controllers, each line
    has its own dash pattern and marker, and its own colour too."""
    for group in (("tp", "tp-weak", "dp-a", "dp-b"), ("nmpc", "lmpc", "pid")):
        styles = [figure_style.style(name) for name in group]
        assert len({str(s["linestyle"]) for s in styles}) == len(group)
        assert len({s["marker"] for s in styles}) == len(group)
        assert len({to_rgb(s["color"]) for s in styles}) == len(group)


def test_a_name_without_a_style_gets_a_spare_one(captured, monkeypatch) -> None:
    """An architecture the style table does not name is still drawn with a colour, dash
    pattern and marker of its own (a spare one, by its line's index) and gets grey bars; one
    table entry gives it its style, with no other edit."""
    runs = _runs()
    runs[1] = synthetic_result("W1", "dp-c", duration_s=6.0, offset_N=150.0,
                               energy=energy_table(1.1))

    def line_of(fig: plt.Figure, label: str):
        return next(line for line in fig.axes[0].lines if line.get_label() == label)

    figure_compare.overlay_figure(runs, "unused.png")
    line = line_of(captured[-1], "dp-c 2 Hz low-pass")
    spare = figure_style.SPARE_STYLES[1]
    assert (line.get_color(), line.get_marker()) == (spare["color"], spare["marker"])
    figure_compare.variants_figure(["a", "b"], {"RMSE [kN]": {"tp": [1.0, 2.0],
                                                              "dp-c": [1.5, 2.5]}}, "unused.png")
    assert len(captured[-1].axes[0].patches) == 4
    monkeypatch.setitem(figure_style.STYLES, "dp-c", dict(color="#123456", linestyle=":",
                                                          marker="h"))
    figure_compare.overlay_figure(runs, "unused.png")
    line = line_of(captured[-1], "dp-c 2 Hz low-pass")
    assert (line.get_color(), line.get_marker()) == ("#123456", "h")


def test_energy_bars_are_a_waterfall_ending_at_the_totals() -> None:
    """Each term's bar starts where the previous one ended (a negative term goes left); the
    circuit's terms end at the circuit total, all of them at the pump total, both drawn as
    bars from zero; the rows are the terms in words and the values stand at the bars."""
    with_table = synthetic_result(energy=energy_table())
    without = synthetic_result()
    fig = plt.figure(figsize=(10, 5))
    ax, ax_old = figure_energy.energy_bars(fig, ["tp", "old"], [with_table, without])
    assert ax.get_xlabel() == "energy [J]"       # 9.5 kJ at most: in J
    rows = [t.get_text() for t in ax.get_yticklabels()]
    bars = {rows[round(p.get_y() + p.get_height() / 2)]: (p.get_x(), p.get_width())
            for p in ax.patches}
    # the synthetic table [J]: throttling 1500 + 500 + 500, leakage 400, friction 300,
    # mechanical 500, stored -200 (circuit 3501 with the 1 J residual); relief 6000, pump 9501
    terms = ["throttling (valves, restrictors)", "seal leakage, head to rod",
             "cylinder seal friction", "work into the track, ∫F·v dt", "Δ stored, circuit oil",
             "= circuit total, in at P port", "residual (pump − all terms)", "relief valve",
             "= pump total, shaft energy in"]
    assert rows == terms
    running = 0.0
    for term in terms:
        left, width = bars[term]
        if term.startswith("="):
            assert left == 0.0 and width == pytest.approx(running, abs=1.5)
        else:
            assert left == pytest.approx(running)
            running += width
    assert bars["Δ stored, circuit oil"][1] == pytest.approx(-200.0)
    assert bars["= circuit total, in at P port"][1] == pytest.approx(3501.0)
    assert bars["= pump total, shaft energy in"][1] == pytest.approx(9501.0)
    values = [t.get_text() for t in ax.texts]
    assert "2500" in values and "-200" in values and "9500" in values    # 3 digits
    assert len(ax_old.patches) == 0      # a run without an energy table gets no bar, but a note
    assert "no energy table in this run" in ax_old.texts[0].get_text()
    plt.close(fig)


@pytest.mark.parametrize(("scenario", "starts"), [("W1", [2.5, 14.5]), ("W2", [5.0]),
                                                   ("W3", [5.5, 7.5, 17.5, 19.5]),
                                                   ("W4", [11.5, 19.5]),
                                                   ("NL1", [2.5, 8.5])])
def test_zooms_follow_each_conditions_events(scenario: str, starts: list[float]) -> None:
    """The step and the next reference change (W1's ramp, NL1's first release), each
    disturbance edge, or steady running; NL1's supply held at 9 MPa from t = 0 is its
    condition, not an edge."""
    w = load_scenario(scenario).metric_windows(link_pitch_m=0.075)
    zooms = figure_panels.zoom_windows(w, 30.0)
    assert [z[1] for z in zooms] == starts
    assert all(t1 > t0 for _, t0, t1 in zooms)


@pytest.mark.parametrize(("running", "title"), [
    ({"speed_m_s": 1.5, "travel_m": [0.0, 40.0], "grade": 0.0},
     "steady running at 1.5 m/s, 5–6 s"),
    ({"speed_m_s": -1.5, "travel_m": [-40.0, 0.0], "grade": 0.2},
     "5–6 s, reversing at 1.5 m/s"),
    ({"speed_m_s": None, "travel_m": [-1.85, 0.94], "grade": 0.0},
     "5–6 s, forward and back (speed from a file)"),
    ({"speed_m_s": None, "travel_m": [0.0, 12.0], "grade": 0.0},
     "5–6 s, track speed from a file"),
    ({"speed_m_s": 0.0, "travel_m": [0.0, 0.0], "grade": 0.0}, "standing still, 5–6 s"),
    (None, "5–6 s, no step or disturbance"),
])
def test_a_zoom_without_events_says_how_the_track_runs_in_it(running, title) -> None:
    """W2 has no step or disturbance: its zoom is a second from the steady window's start,
    "steady running" only at a constant forward speed, else named by its time span and how
    the track runs (a shuttle read from a file never runs steadily; the grade is the
    figure title's)."""
    w = load_scenario("W2").metric_windows(link_pitch_m=0.075)
    assert figure_panels.zoom_windows(w, 30.0, running) == [(title, 5.0, 6.0)]


def test_moved_pulses_keep_each_zoom_titles_time_and_unit(captured) -> None:
    """W3 with its second pulse moved to 9.25-10.75 s and the hitch forces in its labels
    (one out of reach): every zoom title names its edge's time with its unit, wrapped to
    its panel so that none runs into the next panel's title or off the figure (the four
    zooms side by side of the comparison figure clipped the last ones' "at 10.75 s")."""
    tp = _runs("W3", duration_s=12.0)[0]
    w = dataclasses.replace(
        windows_of(tp), disturbances=((6.0, 8.0), (9.25, 10.75)),
        disturbance_labels=("load pulse +1.73 kN (hitch -5.29 kN)",
                            "load pulse -1.3 kN (hitch +4.13 kN, out of reach)"))
    titles = [z[0] for z in figure_panels.zoom_windows(w, 12.0)]
    assert [t.rsplit(", ", 1)[1] for t in titles] == ["onset at 6 s", "end at 8 s",
                                                       "onset at 9.25 s", "end at 10.75 s"]
    # a number stays with its unit, the time with its edge
    assert figure_panels.wrap_title(f"zoom: {titles[3]}", 40).split("\n") == [
        "zoom: load pulse -1.3 kN (hitch", "+4.13 kN, out of reach), end at 10.75 s"]
    moved = Result(tp.timeseries, tp.metrics | {"evaluation": w.as_table()})
    figure_compare.overlay_figure([moved], "unused.png")
    figure_run.run_figure(moved, "unused.png")
    for fig in captured:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        shown = [ax._left_title for ax in fig.axes if ax.get_title(loc="left")]
        assert [t.get_text().replace("\n", " ") for t in shown] == [
            f"zoom: {t}" for t in titles]
        boxes = [t.get_window_extent(renderer) for t in shown]
        page = fig.bbox
        assert all(page.x0 <= b.x0 and b.x1 <= page.x1 for b in boxes)
        assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])


def test_envelope_holds_each_bins_extremes() -> None:
    t = np.arange(1, 1001) * 1e-3
    x = np.sin(2 * np.pi * 20.0 * t)
    tb, lo, hi = figure_style.envelope(t, x)
    assert len(tb) == 20 and np.allclose(hi, 1.0, atol=2e-3) and np.allclose(lo, -1.0, atol=2e-3)


@pytest.mark.slow
def test_figures_write_png_files(tmp_path) -> None:
    runs = _runs()
    paths = [figure_run.run_figure(runs[2], tmp_path / "run.png"),
             figure_compare.overlay_figure(runs, tmp_path / "overlay.png"),
             figure_compare.psd_figure(runs, tmp_path / "psd.png")]
    for path in paths:
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def _on_machine(result, machine: str | None, **meta: str):
    """``result`` as made on ``machine`` (a result that records its host too; None: an
    older result without one), with other table metadata ``meta``."""
    table = result.metadata | meta
    if machine is not None:
        table |= {"machine": machine, "host": "a test computer"}
    return Result(result.timeseries.replace_schema_metadata(table), result.metrics)


def test_psd_title_states_the_resolution_the_window_gives() -> None:
    """W1's steady window starts at 5 s and the scenario asks for 0.5 Hz (2 s Welch
    segments): a 6 s run has a 1 s window, so 1 Hz, and needs 5 + 2 = 7 s for 0.5 Hz; a 9 s
    run's 4 s window gives the 0.5 Hz asked for."""
    short = synthetic_result("W1", duration_s=6.0)
    text = figure_compare.psd_resolution_text(short)
    assert "1 Hz resolution, not 0.5 Hz" in text and "run ≥ 7 s for 0.5 Hz" in text
    assert "(1 s)" in text and "0.5 Hz resolution" not in text
    long = synthetic_result("W1", duration_s=9.0)
    text = figure_compare.psd_resolution_text(long)
    assert "0.5 Hz resolution" in text and "2 s Hann segments" in text
    assert "shorter" not in text and "(4 s)" in text


def test_psd_figure_title_names_machine_and_resolution(captured) -> None:
    run = _on_machine(synthetic_result("W1", duration_s=6.0), "m113")
    figure_compare.psd_figure([run], "unused.png")
    title = captured[-1].get_suptitle()
    assert "machine m113" in title and "1 Hz resolution" in title
    _check_axes(captured[-1])


def test_run_figure_overlays_the_measured_log_everywhere_it_is_drawn(captured) -> None:
    """A measured log 800 N above the run: its low-passed tension is in the main panel and
    in every zoom, 0.8 kN above the run's and inside the zoom's limits, its head pressure in
    the pressure panel; the title names the log's file and each channel's RMSE and lag (from
    the result's prediction_vs_measured) in kN, MPa and ms; nothing overlaps."""
    run = synthetic_result("W3", duration_s=22.0, energy=energy_table())
    c = run.columns()
    measured = {"t_s": c["t_s"], "tension_N": c["tension_N"] + 800.0,
                "p_head_Pa": c["p_head_Pa"] * 1.05}
    run.metrics["measured_log"] = {"file": "logs/rig 2024-05-01.csv", "sha256": "ab" * 32,
                                   "columns_used": {"tension_N": "tension [lbf]",
                                                    "p_head_Pa": "p_head [psi]"},
                                   "columns_ignored": ["ambient [degC]"]}
    run.metrics["prediction_vs_measured"] = {
        "tension_N": {"rmse_N": 1234.0, "rmse_lp_N": 812.0, "lag_s": 0.03},
        "p_head_Pa": {"rmse_Pa": 2.5e5, "rmse_lp_Pa": 1.0e5, "lag_s": -0.012}}
    figure_run.run_figure(_on_machine(run, "m113"), "unused.png", measured)
    fig = captured[-1]
    _check_axes(fig)
    title = fig.get_suptitle()
    assert title.startswith("W3, machine m113: tp nmpc/ekf, seed 0")
    assert "rig 2024-05-01.csv" in title and "logs/" not in title
    assert "F_ten: RMSE 1.23 kN (2 Hz low-pass 0.812 kN), lag 30 ms" in title
    assert "p_head: RMSE 0.25 MPa (2 Hz low-pass 0.1 MPa), lag -12 ms" in title
    label = "measured F_ten 2 Hz low-pass"
    zooms = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("zoom:")]
    tension_axes = [ax for ax in fig.axes if ax.get_ylabel() == "F_ten [kN]"]
    assert len(zooms) == 4 and len(tension_axes) == 5
    for ax in tension_axes:
        mine = next(line for line in ax.lines if line.get_label() == label)
        run_lp = next(line for line in ax.lines if line.get_label() == "F_ten 2 Hz low-pass")
        offset = np.mean(mine.get_ydata()) - np.mean(run_lp.get_ydata())
        assert offset == pytest.approx(0.8, abs=0.02)         # kN
        assert max(mine.get_ydata()) < ax.get_ylim()[1]
    pressure = next(ax for ax in fig.axes if ax.get_ylabel() == "pressure [MPa]")
    assert "measured p_head 2 Hz low-pass" in [line.get_label() for line in pressure.lines]


def test_titles_name_the_machine(captured) -> None:
    """The run figure and the comparison figure name the machine, also under a title given
    by the caller; an older result (its ``machine`` was the computer) names the machine of
    its files, and one that records none is titled without."""
    runs = [_on_machine(r, "m113") for r in _runs()[:2]]
    assert figure_run.run_title(runs[0]) == "W1, machine m113: tp nmpc/ekf, seed 0"
    figure_compare.overlay_figure(runs, "unused.png", title="W1 seed 0, nmpc: architectures")
    assert captured[-1].get_suptitle() == "W1 seed 0, nmpc: architectures, machine m113"
    old = synthetic_result()
    table = {k: v for k, v in old.metadata.items() if k != "host"}
    old = Result(old.timeseries.replace_schema_metadata(
        table | {"machine": "AMD EPYC, 2 cores", "files": '{"machine": "lf1352"}'}), old.metrics)
    assert figure_run.run_title(old).startswith("W1, machine lf1352:")
    older = Result(old.timeseries.replace_schema_metadata(
        {k: v for k, v in table.items() if k != "files"} | {"machine": "AMD EPYC"}), old.metrics)
    assert figure_run.run_title(older) == "W1: tp nmpc/ekf, seed 0"


def test_band_labels_carry_three_significant_digits(captured) -> None:
    """m113's band, 2/3 and 4/3 of its 20 kN nominal tension, reads 13.3–26.7 kN; a
    tooth-passing band at 1.5 m/s over a 152 mm pitch ± 10 % (8.8816-10.855 Hz) reads
    8.88–10.9 Hz; no text of the figures carries four decimals or more."""
    run = synthetic_result("W1", duration_s=6.0)
    run.metrics["evaluation"] = run.metrics["evaluation"] | {
        "force_min_N": 2e4 * 2 / 3, "force_max_N": 2e4 * 4 / 3,
        "tooth_passing_band_Hz": (1.5 / 0.152 * 0.9, 1.5 / 0.152 * 1.1)}
    figure_run.run_figure(run, "unused.png")
    figure_compare.psd_figure([run], "unused.png")
    tension = next(ax for ax in captured[0].axes if ax.get_ylabel() == "F_ten [kN]")
    assert "admissible band F_min–F_max, 13.3–26.7 kN" in [
        t.get_text() for t in tension.get_legend().get_texts()]
    assert "tooth passing 8.88–10.9 Hz" in [
        t.get_text() for t in captured[1].axes[0].get_legend().get_texts()]
    for fig in captured:
        texts = [t.get_text() for t in fig.findobj(matplotlib.text.Text)]
        assert not [t for t in texts if re.search(r"\d\.\d{4,}", t)]


@pytest.mark.parametrize(("value", "text"), [(13.3333, "13.3"), (26.6667, "26.7"),
                                             (20.0, "20"), (1049.7, "1050"),
                                             (0.000123456, "0.000123"), (-0.33, "-0.33")])
def test_numbers_in_labels(value: float, text: str) -> None:
    assert figure_style.number(value) == text


def _spans(ax) -> list[tuple[float, float]]:
    """The (start, end) [s] of each grey span on ``ax``."""
    return [(round(p.get_x(), 6), round(p.get_x() + p.get_width(), 6)) for p in ax.patches]


@pytest.mark.parametrize(("drop", "spans", "note"), [
    ((0.0, 30.0), [], "supply at 9 MPa from the start"),          # NL1: the whole run
    ((0.0, 5.0), [(1.0, 5.0)], None),       # ends during the run: from the evaluation start
    ((11.0, 13.0), [(11.0, 13.0)], None),   # W4's drop: an event
])
def test_a_supply_held_from_the_start_is_the_runs_condition_not_a_shaded_event(
        drop, spans, note) -> None:
    """NL1's supply is at 9 MPa from t = 0: shading its whole run as "supply drop window"
    hid the admissible band; the legend says what the supply is instead."""
    w = dataclasses.replace(load_scenario("NL1").metric_windows(link_pitch_m=0.075),
                            disturbances=(drop,))
    fig, ax = plt.subplots()
    figure_panels.shade_events(ax, w, 30.0)
    labels = ax.get_legend_handles_labels()[1]
    assert _spans(ax) == spans
    assert ("supply drop window" in labels) == bool(spans)
    assert (note in labels) if note else not any("from the start" in s for s in labels)
    plt.close(fig)
