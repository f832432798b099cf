"""Figures: units on every axis, legends outside the data, styles that survive grayscale,
the energy breakdown stacking the ledger's terms, zooms on each condition's events."""

from __future__ import annotations

import itertools

import matplotlib.pyplot as plt
import matplotlib.text
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from synthetic import energy_table, synthetic_result

from trackmj.results import figure_compare, figure_energy, figure_panels, figure_run, figure_style
from trackmj.results.comparison import prediction_vs_tp
from trackmj.results.metric_windows import windows_of
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
    """Every axis with data names its unit in brackets; every legend lies outside its axes
    (above, beside them on the right, or below); every text is at least 9 pt at the saved
    size (the figure's own inches)."""
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    for ax in fig.axes:
        if not (ax.lines or ax.patches or ax.collections):
            continue
        assert "[" in ax.get_ylabel() and "]" in ax.get_ylabel(), ax.get_ylabel()
        if ax.get_xlabel():
            assert "[" in ax.get_xlabel(), ax.get_xlabel()
        legend = ax.get_legend()
        if legend is not None:
            box = legend.get_window_extent(renderer).transformed(ax.transAxes.inverted())
            assert box.y0 >= 0.99 or box.x0 >= 1.0 or box.y1 <= 0.0, (
                f"legend of '{ax.get_ylabel()}' overlaps its data")
    small = {(t.get_text()[:40], t.get_fontsize()) for t in fig.findobj(matplotlib.text.Text)
             if t.get_text().strip() and t.get_visible() and t.get_fontsize() < 9}
    assert not small, small


def test_run_figure_units_legends_and_zooms(captured) -> None:
    tp = _runs("W3", duration_s=22.0)[0]
    tp.metrics["energy_J"]["numerical"] = {"circuit": 20.0, "interface": 5.0}
    figure_run.run_figure(tp, "unused.png")
    fig = captured[0]
    _check_axes(fig)
    titles = [ax.get_title(loc="left") for ax in fig.axes if ax.get_title(loc="left")]
    assert titles[:-1] == ["zoom: load pulse +2 kN, onset at 6 s",
                           "zoom: load pulse +2 kN, end at 8 s",
                           "zoom: load pulse -1.5 kN, onset at 18 s",
                           "zoom: load pulse -1.5 kN, end at 20 s"]
    u_axis = next(ax for ax in fig.axes if ax.get_ylabel() == "u [-]")
    assert "controller's command" in u_axis.get_legend().get_texts()[0].get_text()
    energy = next(ax for ax in fig.axes if ax.get_ylabel() == "energy [kJ]")
    assert any(t.get_text().startswith("numerical (backward-Euler")
               for t in energy.get_legend().get_texts())
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


def test_styles_differ_in_more_than_colour() -> None:
    """Readable in grayscale: within the architectures and within the controllers, each line
    has its own dash pattern and marker, and its own colour too."""
    for group in (("tp", "tp-weak", "dp-a", "dp-b"), ("nmpc", "lmpc", "pid")):
        styles = [figure_style.style(name) for name in group]
        assert len({str(s["linestyle"]) for s in styles}) == len(group)
        assert len({s["marker"] for s in styles}) == len(group)
        assert len({to_rgb(s["color"]) for s in styles}) == len(group)
    hatches = [h for _, h in figure_style.ENERGY_STYLES.values()]
    assert len(set(hatches)) == len(hatches)


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
    """Each term's bar starts where the previous one ended (a negative term goes down); the
    circuit's terms end at the circuit total, all of them at the pump total, where the
    dashed and the solid tick stand."""
    table = energy_table()
    with_table = synthetic_result(energy=table)
    without = synthetic_result()
    fig, ax = plt.subplots()
    figure_energy.energy_bars(ax, ["tp", "old"], [with_table, without])
    bars = sorted((p for p in ax.patches if abs(p.get_x() + p.get_width() / 2) < 0.45),
                  key=lambda p: p.get_x())
    for a, b in itertools.pairwise(bars):
        assert b.get_y() == pytest.approx(a.get_y() + a.get_height())
    circuit_terms, supply_terms = figure_energy.energy_waterfall(with_table.metrics)
    assert [n for n, _ in supply_terms] == ["residual", "relief"]
    n_circuit = len([v for _, v in circuit_terms if v != 0.0])
    end_circuit = bars[n_circuit - 1].get_y() + bars[n_circuit - 1].get_height()
    assert end_circuit == pytest.approx(table["circuit"] / 1e3, abs=2e-3)   # residual 1 J
    end = bars[-1].get_y() + bars[-1].get_height()
    assert end == pytest.approx(table["pump"] / 1e3)
    ticks = {float(seg[0][1]): c.get_linestyle() for c in ax.collections
             for seg in c.get_segments()}
    assert sorted(ticks) == pytest.approx(sorted([table["pump"] / 1e3, table["circuit"] / 1e3]))
    assert any("numerical" not in t.get_text() for t in ax.get_legend().get_texts())
    at_old = [p for p in ax.patches if abs(p.get_x() + p.get_width() / 2 - 1) < 0.45]
    assert at_old == []      # a run without an energy table gets no bar, but a note
    assert "old: no energy table in this run" in ax.texts[0].get_text()
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
