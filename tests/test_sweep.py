"""Parameter studies: the spec through the validator, grid and LHS points, and sweeps on a
2-worker Dask LocalCluster (rows as runs finish, resume, failed runs as rows, figures)."""

from __future__ import annotations

import csv
import json
import math
import os
import re

import numpy as np
import pytest

from trackmj.cli.main import main
from trackmj.study.campaign import flatten_metrics, write_table
from trackmj.study.executor import Executor
from trackmj.study.sweep import (
    load_sweep,
    parameter_points,
    plan,
    read_sweep,
    sweep,
)
from trackmj.validator import ParameterError

DURATION_S = 1.5
SPEED = "scenario.track.speed_m_s"
BULK = "hydraulics.fluid.bulk_modulus_Pa"


def _spec(**table) -> dict:
    return {"sweep": {"scenario": "W1", "duration_s": DURATION_S} | table}


# ----------------------------------------------------------------------------- points

def test_grid_is_every_combination_first_key_slowest() -> None:
    spec = load_sweep(_spec(parameters=[
        {"key": SPEED, "values": [0.5, 1.0]},
        {"key": BULK, "low": 1e9, "high": 4e9, "count": 3, "scale": "log"}]))
    points = parameter_points(spec)
    assert [p[SPEED] for p in points] == [0.5] * 3 + [1.0] * 3
    np.testing.assert_allclose([p[BULK] for p in points[:3]], [1e9, 2e9, 4e9], rtol=1e-12)


def test_latin_hypercube_puts_one_sample_in_each_stratum_of_each_key() -> None:
    n = 8
    table = {"method": "lhs", "samples": n, "seed": 3, "parameters": [
        {"key": SPEED, "low": 0.0, "high": 2.0},
        {"key": BULK, "low": 1e9, "high": 1e10, "scale": "log"}]}
    points = parameter_points(load_sweep(_spec(**table)))
    assert len(points) == n
    speed = np.array([p[SPEED] for p in points])
    log_bulk = np.log10([p[BULK] for p in points])
    assert sorted(np.floor(speed / 2.0 * n).astype(int)) == list(range(n))
    assert sorted(np.floor((log_bulk - 9.0) * n).astype(int)) == list(range(n))
    assert points == parameter_points(load_sweep(_spec(**table)))        # same seed
    other = parameter_points(load_sweep(_spec(**table | {"seed": 4})))
    assert [p[SPEED] for p in other] != list(speed)


def test_the_readme_spec_is_valid_and_plans_every_combination(tmp_path) -> None:
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    block = readme.split("## Parameter studies", 1)[1].split("```toml\n", 1)[1]
    spec = tmp_path / "study.toml"
    spec.write_text(block.split("```", 1)[0])
    runs = plan(load_sweep(spec))
    # 3 areas x 3 bulk moduli x 2 controllers x 2 seeds, each a distinct run
    assert len(runs) == len({r.key for r in runs}) == 36
    assert {r.row["controller"] for r in runs} == {"nmpc", "pid"}


def test_integer_keys_take_integers() -> None:
    key = "control.mpc.horizon_steps"
    points = parameter_points(load_sweep(_spec(parameters=[{"key": key, "values": [10, 20]}])))
    assert [p[key] for p in points] == [10, 20] and all(type(p[key]) is int for p in points)
    with pytest.raises(ParameterError, match=r"value 10.5 is not an integer"):
        parameter_points(load_sweep(_spec(parameters=[{"key": key, "values": [10.5]}])))


@pytest.mark.parametrize(("table", "message"), [
    ({"parameters": [{"key": "hydraulics.fluid.bulk_modulus_Paa", "values": [1e9]}]},
     r"point 0 .*did you mean 'bulk_modulus_Pa'"),
    ({"parameters": [{"key": BULK, "values": [1e9, 2e11]}]},
     r"point 1 \(hydraulics.fluid.bulk_modulus_Pa = 2e\+11\) is invalid: .* is outside the "
     r"allowed range \(0, 1e\+11\] Pa"),
    ({"parameters": [{"key": BULK, "values": [1e9], "low": 1e9}]},
     r"values = \[1000000000.0\] excludes low, high and count"),
    ({"method": "lhs", "parameters": [{"key": BULK, "low": 1e9, "high": 2e9}]},
     r"method = 'lhs' needs samples"),
    ({"parameters": [{"key": "fluid.bulk_modulus_Pa", "values": [1e9]}]},
     r"key = 'fluid.bulk_modulus_Pa': unknown file kind 'fluid' \(allowed: model, "
     r"hydraulics, control, scenario\)$"),
    ({"parameters": [{"key": "hydraulic.fluid.bulk_modulus_Pa", "values": [1e9]}]},
     r"key = 'hydraulic.fluid.bulk_modulus_Pa': unknown file kind 'hydraulic'; did you mean "
     r"'hydraulics'\?"),
    ({"set": [f"{BULK}=1e9"], "parameters": [{"key": BULK, "values": [2e9]}]},
     r"is also fixed in \[sweep\].set"),
    ({"controllers": ["nmpc", "mpcc"]}, r"controllers\[1\] = 'mpcc' is not one of"),
    ({"hydraulics": "my_hyd.toml"},
     r"^study\.toml \[sweep\]\.hydraulics = 'my_hyd\.toml': no such file \S+/my_hyd\.toml$"),
])
def test_spec_mistakes_are_named_before_any_run(tmp_path, table, message) -> None:
    path = tmp_path / "study.toml"
    lines = ["[sweep]", 'scenario = "W1"', f"duration_s = {DURATION_S}"]
    for key, value in table.items():
        if key != "parameters":
            lines.append(f"{key} = {json.dumps(value)}")
    for p in table.get("parameters", []):
        lines += ["[[sweep.parameters]]"] + [f"{k} = {json.dumps(v)}" for k, v in p.items()]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ParameterError, match=message) as info:
        plan(load_sweep(path))
    assert "study.toml" in str(info.value)


def test_trackmj_sweep_is_the_function() -> None:
    import trackmj
    import trackmj.study.sweep

    assert trackmj.sweep is trackmj.study.sweep.sweep and trackmj.read_sweep is read_sweep


def test_nested_metric_tables_become_dotted_columns() -> None:
    flat = flatten_metrics({"rmse_N": 412.0, "energy_J": {"pump": 80.0, "losses": {
        "relief": 2.0, "orifices": np.float64(3.0)}}, "note": "text", "ok": True})
    assert flat == {"rmse_N": 412.0, "energy_J.pump": 80.0, "energy_J.losses.relief": 2.0,
                    "energy_J.losses.orifices": 3.0, "ok": 1.0}


# ----------------------------------------------------------------------------- summary

INPUTS = '{"files": {}, "set": []}'


def _row(key: str, point: int, seed: int = 0, **cells) -> dict:
    """A results row as a sweep writes it (W1 tp nmpc/ekf, 1.5 s), ``cells`` on top."""
    return {"run_key": key, "point": point, "scenario": "W1", "machine": "lf1352",
            "architecture": "tp",
            "controller": "nmpc", "estimator": "ekf", "variant": "nominal", "seed": seed,
            "duration_s": 1.5, "inputs": INPUTS, "evaluation.lowpass_cutoff_Hz": 2.0,
            "wall_time_s": 1.0, "error": None} | cells


def _grid_rows() -> list[dict]:
    """A 2 x 2 grid, one seed, hand-written metrics in SI (rmse_lp_N etc.)."""
    rows = []
    for i, (speed, bulk, rmse, p_head, pump, solve) in enumerate([
            (0.5, 0.8e9, 1540.0, 6.03e6, 131.9, 0.0066),
            (0.5, 1.6e9, 877.0, 6.31e6, 126.7, 0.0009),
            (1.5, 0.8e9, 1083.0, 6.15e6, 145.2, 0.0016),
            (1.5, 1.6e9, 539.0, 6.58e6, 122.0, 0.0021)]):
        rows.append(_row(f"k{i}", i, **{SPEED: speed, BULK: bulk, "rmse_lp_N": rmse,
                                        "p_head_max_Pa": p_head, "energy_J.pump": pump,
                                        "settling_time_lp_s": math.nan,
                                        "solve_time_max_s": solve, "real_time_factor": 3.0,
                                        "controller_overruns": 0.0}))
    return rows[::-1]             # as a sweep may finish them: the table sorts


def _table_lines(markdown: str) -> list[list[str]]:
    """The cells of the Markdown table's lines (header, separator, rows)."""
    return [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in markdown.splitlines() if line.startswith("|")]


def test_the_summary_has_a_row_per_point_in_display_units() -> None:
    """Varied keys first with their values as given and SI units, the metrics in display
    units (1540 N -> 1.54 kN, 6.03e6 Pa -> 6.03 MPa, 131.9 J -> 0.132 kJ, 0.0066 s ->
    6.6 ms), one seed: the plain value (no ±), diagnostics last and marked."""
    from trackmj.study.sweep import summarize, summary_markdown

    table = summarize(_grid_rows())
    assert table.varied == (SPEED, BULK) and len(table.rows) == 4
    head, _, *body = _table_lines(summary_markdown(table))
    assert head[:3] == [f"{SPEED} [m/s]", f"{BULK} [Pa]", "runs"]
    assert head[3:6] == ["RMSE lp [kN]", "p_head max [MPa]", "pump energy [kJ]"]
    assert head[-4:] == ["diag. wall time [s]", "diag. real-time [×]", "diag. solve max [ms]",
                         "diag. overruns"]
    assert [row[:3] for row in body] == [["0.5", "8e+08", "1"], ["0.5", "1.6e+09", "1"],
                                         ["1.5", "8e+08", "1"], ["1.5", "1.6e+09", "1"]]
    assert body[0][3:6] == ["1.54", "6.03", "0.132"] and body[0][-2] == "6.6"
    assert not any("±" in cell for row in body for cell in row)
    assert [c.key for c in table.metrics] == ["rmse_lp_N", "p_head_max_Pa", "energy_J.pump"]
    assert "rmse_N" in [c.key for c in table.missing]   # no value in any run
    text = summary_markdown(table)
    assert "tension RMSE, raw [kN]" in text.split("left out")[1]
    assert "seed 0" in text and "2 Hz" in text


def _lf_rows() -> list[dict]:
    """Rows of a 2-point bulk-modulus grid on the packaged machine."""
    return [_row(f"a{i}", i, **{BULK: b, "rmse_lp_N": 100.0}) for i, b in enumerate((8e8, 16e8))]


def _mini_rows() -> list[dict]:
    """Rows of a 2-point bulk-modulus grid on machine "mini" (a machine file
    mini_machine.toml), given a hydraulics file and a fixed override."""
    mini = json.dumps({"files": {"machine": "/w/mini_machine.toml",
                                 "hydraulics": "/w/soft_hyd.toml"},
                       "set": [f"{SPEED}=1.0"]}, sort_keys=True)
    return [_row(f"b{i}", i, machine="mini", inputs=mini, **{BULK: b, "rmse_lp_N": 200.0})
            for i, b in enumerate((8e8, 16e8))]


def test_machines_by_name_files_and_overrides_readable(tmp_path, monkeypatch) -> None:
    """Rows of the packaged machine and of a machine file mini_machine.toml whose [machine]
    name is "mini", given a hydraulics file and a fixed override: the summary (Markdown and
    CSV) and the figure's legend name the machine "mini", the file by its name, the override
    as given, and show no JSON."""
    from trackmj.study.sweep import plot_sweep, summarize, summary_csv, summary_markdown

    rows = _lf_rows() + _mini_rows()
    table = summarize(rows)
    markdown = summary_markdown(table)
    head, _, *body = _table_lines(markdown)
    assert head[:4] == ["machine", "hydraulics", "set", f"{BULK} [Pa]"]
    assert [row[:3] for row in body] == [["lf1352", "", ""]] * 2 + [
        ["mini", "soft_hyd.toml", f"{SPEED}=1.0"]] * 2
    assert "hydraulics: the file its spec gave every run instead of the machine's own" in \
        " ".join(markdown.split())
    for text in (markdown, summary_csv(table)):
        assert "{" not in text and "mini_machine" not in text
    write_table(rows, tmp_path / "results.parquet")
    drawn = _drawn(monkeypatch)
    plot_sweep(tmp_path)
    legend = [line.get_label() for line in drawn[f"{BULK}.png"].axes[0].get_lines()]
    assert legend == ["lf1352", f"mini, soft_hyd.toml, {SPEED}=1.0"]


def test_a_row_written_before_the_machine_column_is_named_by_its_machine_file() -> None:
    """A results row of an earlier trackmj (no machine column, the machine file in inputs)
    is named by the file's [machine] name and superseded by the newer row of its point."""
    from trackmj.machines.assembly import resolve
    from trackmj.study.sweep import summarize

    inputs = json.dumps({"files": {"machine": str(resolve("compact3").file)}, "set": []})
    old = _row("old", 0, inputs=inputs, rmse_lp_N=900.0)
    del old["machine"]
    table = summarize([old, _row("new", 0, machine="compact3", inputs=inputs,
                                 rmse_lp_N=500.0)])
    assert [(r.case["machine"], r.stats("rmse_lp_N")[0]) for r in table.rows] == [
        ("compact3", 500.0)]
    assert table.superseded == 1


def test_the_markdown_table_parses() -> None:
    """Header, separator (every column, right-aligned metrics), one line per point, the same
    number of cells in each; the lines are padded to one width."""
    from trackmj.study.sweep import summarize, summary_markdown

    markdown = summary_markdown(summarize(_grid_rows()))
    lines = [line for line in markdown.splitlines() if line.startswith("|")]
    cells = _table_lines(markdown)
    assert len(lines) == 2 + 4 and len({len(row) for row in cells}) == 1
    assert all(re.fullmatch(r"-+:?", c) for c in cells[1])
    assert [c.endswith(":") for c in cells[1][:3]] == [False, False, True]  # numbers right
    assert len({len(line) for line in lines}) == 1


def test_two_seeds_give_numpys_mean_and_population_std(tmp_path) -> None:
    """CSV (SI): mean and population std (ddof = 0) of the seeds' values as numpy computes
    them; the Markdown cell in kN ("1.5 ± 0.5"); a seed without a value is named; a point
    whose runs failed is counted and has no values."""
    from trackmj.study.sweep import summarize, summary_markdown, write_summary

    rmse = {(0, 0): 1000.0, (0, 1): 2000.0, (1, 0): 700.0, (1, 1): 1300.0}
    settle = {(0, 0): 0.4, (0, 1): math.nan, (1, 0): 0.2, (1, 1): 0.3}
    rows = [_row(f"k{p}{s}", p, s, **{BULK: bulk, "rmse_lp_N": rmse[p, s],
                                      "settling_time_lp_s": settle[p, s]})
            for p, bulk in enumerate((0.8e9, 1.6e9)) for s in (0, 1)]
    rows += [_row(f"f{s}", 2, s, **{BULK: 2.4e9, "error": "PhysicsError: t = 0.2 s"})
             for s in (0, 1)]
    table = summarize(rows)
    csv_path, md_path = write_summary(tmp_path, table)
    with csv_path.open() as fh:
        read = list(csv.DictReader(fh))
    assert [r[f"{BULK} [Pa]"] for r in read] == ["800000000.0", "1600000000.0",
                                                  "2400000000.0"]
    for p in (0, 1):
        values = [rmse[p, 0], rmse[p, 1]]
        assert float(read[p]["rmse_lp_N_mean [N]"]) == pytest.approx(np.mean(values))
        assert float(read[p]["rmse_lp_N_std [N]"]) == pytest.approx(np.std(values, ddof=0))
        assert (read[p]["runs"], read[p]["failed"]) == ("2", "0")
    assert float(read[1]["settling_time_lp_s_std [s]"]) == pytest.approx(0.05)
    assert read[0]["settling_time_lp_s_std [s]"] == ""        # one value: no spread
    assert (read[2]["runs"], read[2]["failed"], read[2]["rmse_lp_N_mean [N]"]) == ("0", "2", "")
    assert "wall_time_s_mean [s] (diagnostic)" in read[0]
    head, _, *body = _table_lines(md_path.read_text())
    assert md_path.read_text() == summary_markdown(table)
    col = head.index("RMSE lp [kN]")
    assert [row[col] for row in body] == ["1.5 ± 0.5", "1 ± 0.3", "–"]
    assert body[0][head.index("settling lp [s]")] == "0.4 (1 of 2 undefined)"
    assert body[2][head.index("runs")] == "0 (2 failed)"
    assert "mean ± std over the point's seeds (0, 1; population std, ddof = 0)" in \
        " ".join(md_path.read_text().split())


def test_a_rerun_of_a_point_and_seed_replaces_the_earlier_row(tmp_path) -> None:
    """Results holding runs of earlier code (other run keys, same point and seed), as a
    resumed sweep after an update leaves them: the newest row counts, once, not as a second
    seed."""
    from trackmj.study.campaign import read_rows
    from trackmj.study.sweep import plot_sweep, summarize

    path = tmp_path / "results.parquet"
    write_table([_row("old0", 0, 0, **{BULK: 1e9, "rmse_lp_N": 900.0}),
                 _row("old1", 1, 0, **{BULK: 2e9, "rmse_lp_N": 800.0})], path)
    write_table([*read_rows(path), _row("new0", 0, 0, **{BULK: 1e9, "rmse_lp_N": 500.0})],
                path)
    table = summarize(read_rows(path))
    assert [(r.seeds, r.stats("rmse_lp_N")[0]) for r in table.rows] == [((0,), 500.0),
                                                                        ((0,), 800.0)]
    assert table.superseded == 1
    assert len(plot_sweep(tmp_path)) == 1


def _drawn(monkeypatch) -> dict:
    """Record the figures sweep_figures saves: file name -> Figure."""
    import trackmj.results.figure_sweep as figure_sweep

    drawn, save = {}, figure_sweep.save_png
    monkeypatch.setattr(figure_sweep, "save_png",
                        lambda fig, path: drawn.__setitem__(path.name, fig) or save(fig, path))
    return drawn


def test_a_grade_axis_says_it_is_tan_theta(tmp_path, monkeypatch) -> None:
    """A swept [terrain] grade is the slope's tangent, dimensionless: the sweep figure's x
    axis, its lines and its title say "terrain grade tan θ", the axis with [-] like every
    other axis's unit."""
    from trackmj.study.sweep import plot_sweep

    grade = "scenario.terrain.grade"
    rows = [_row(f"k{i}", i, **{SPEED: speed, grade: g, "rmse_lp_N": rmse})
            for i, (speed, g, rmse) in enumerate([(0.5, 0.0, 500.0), (0.5, 0.2, 650.0),
                                                   (1.5, 0.0, 540.0), (1.5, 0.2, 700.0)])]
    write_table(rows, tmp_path / "results.parquet")
    drawn = _drawn(monkeypatch)
    plot_sweep(tmp_path)
    by_grade, by_speed = drawn[f"{grade}.png"], drawn[f"{SPEED}.png"]
    assert by_grade.axes[-1].get_xlabel() == "terrain grade tan θ [-]"
    assert "against terrain grade tan θ" in by_grade.get_suptitle()
    assert sorted(line.get_label() for line in by_speed.axes[0].get_lines()) == [
        "terrain grade tan θ = 0", "terrain grade tan θ = 0.2"]


def _error_bars(ax) -> list:
    from matplotlib.container import BarContainer, ErrorbarContainer

    return [c for c in ax.containers if isinstance(c, ErrorbarContainer)
            or (isinstance(c, BarContainer) and c.errorbar is not None)]


def test_one_figure_per_swept_key_no_error_bars_with_one_seed(tmp_path, monkeypatch) -> None:
    """Figures of a 2 x 2 grid with one seed: one per swept key, a panel per engineering
    metric with a value, a line per value of the other key at the values in display units,
    no error bars; no diagnostics unless asked; an earlier sweep's per-metric file goes."""
    from trackmj.study.sweep import plot_sweep

    write_table(_grid_rows(), tmp_path / "results.parquet")
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "rmse_N.png").write_bytes(b"\x89PNG old")
    drawn = _drawn(monkeypatch)
    figures = plot_sweep(tmp_path)
    assert sorted(p.name for p in figures) == sorted([f"{BULK}.png", f"{SPEED}.png"])
    assert sorted(p.name for p in (tmp_path / "figures").iterdir()) == sorted(
        p.name for p in figures)
    fig = drawn[f"{SPEED}.png"]
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == ["tension RMSE, low-pass [kN]", "peak head pressure [MPa]",
                      "pump energy [kJ]"]
    assert not any(_error_bars(ax) for f in drawn.values() for ax in f.axes)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    assert sorted(lines) == ["fluid bulk modulus = 1600 MPa", "fluid bulk modulus = 800 MPa"]
    np.testing.assert_allclose(lines["fluid bulk modulus = 800 MPa"].get_xdata(), [0.5, 1.5])
    np.testing.assert_allclose(lines["fluid bulk modulus = 800 MPa"].get_ydata(),
                               [1.540, 1.083])
    assert fig.axes[-1].get_xlabel() == "track speed [m/s]"
    np.testing.assert_allclose(drawn[f"{BULK}.png"].axes[1].get_lines()[0].get_xdata(),
                               [800.0, 1600.0])                 # MPa
    assert "one run per point (seed 0)" in fig.get_suptitle()

    drawn.clear()
    figures = plot_sweep(tmp_path, diagnostics=True)
    assert sorted(p.name for p in figures) == sorted([f"{BULK}.png", f"{SPEED}.png",
                                                      "diagnostics.png"])
    assert [ax.get_title() for ax in drawn["diagnostics.png"].axes] == [
        "wall time of a run [s]", "real-time factor (simulated / wall) [×]",
        "longest controller solve [ms]", "controller overruns (solve > period)"]
    np.testing.assert_allclose(drawn["diagnostics.png"].axes[2].get_lines()[0].get_ydata(),
                               [6.6, 1.6])                      # ms, the 0.8 GPa line
    plot_sweep(tmp_path)
    assert not (tmp_path / "figures" / "diagnostics.png").exists()


def test_error_bars_are_the_std_over_two_seeds(tmp_path, monkeypatch) -> None:
    """Two seeds: a point's error bar spans mean ± the population std, in kN."""
    from trackmj.study.sweep import plot_sweep

    values = {(0.8e9, 0): 1000.0, (0.8e9, 1): 2000.0, (1.6e9, 0): 700.0, (1.6e9, 1): 1300.0}
    write_table([_row(f"k{b}{s}", int(b > 1e9), s, **{BULK: b, "rmse_lp_N": v})
                 for (b, s), v in values.items()], tmp_path / "results.parquet")
    drawn = _drawn(monkeypatch)
    assert [p.name for p in plot_sweep(tmp_path)] == [f"{BULK}.png"]
    (bars,) = _error_bars(drawn[f"{BULK}.png"].axes[0])
    spans = [seg[:, 1] for seg in bars.lines[2][0].get_segments()]
    np.testing.assert_allclose(spans, [[1.0, 2.0], [0.7, 1.3]])   # mean ± std [kN]
    assert "mean ± std over seeds 0, 1" in drawn[f"{BULK}.png"].get_suptitle()


def test_a_comparison_without_swept_keys_is_one_figure_of_bars(tmp_path, monkeypatch) -> None:
    """Scenarios x controllers, no swept key: the table's varied columns are scenario and
    controller (built-in scenarios in their order), one figure of grouped bars, no error
    bars with one seed."""
    from trackmj.study.sweep import plot_sweep, summarize

    rows = [_row(f"{sc}{c}", 0, 0, scenario=sc, controller=c, rmse_lp_N=100.0 * k + 10 * j)
            for j, sc in enumerate(("NL1", "W1")) for k, c in enumerate(("nmpc", "pid"))]
    table = summarize(rows)
    assert table.varied == ("scenario", "controller")
    assert [(r.case["scenario"], r.case["controller"]) for r in table.rows] == [
        ("W1", "nmpc"), ("W1", "pid"), ("NL1", "nmpc"), ("NL1", "pid")]
    write_table(rows, tmp_path / "results.parquet")
    drawn = _drawn(monkeypatch)
    assert [p.name for p in plot_sweep(tmp_path)] == ["cases.png"]
    ax = drawn["cases.png"].axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["W1", "NL1"]   # built-in order
    heights = sorted(round(p.get_height(), 9) for p in ax.patches)
    assert heights == [0.0, 0.01, 0.1, 0.11]                     # kN
    assert not _error_bars(ax)


def test_scattered_samples_are_loose_markers(tmp_path, monkeypatch) -> None:
    """Latin hypercube samples (no two share the other key's value) are one set of
    unjoined markers per figure, not a line per sample."""
    from trackmj.study.sweep import plot_sweep

    write_table([_row(f"k{i}", i, **{SPEED: 0.5 + 0.25 * i, BULK: 1e9 * (1 + i),
                                     "rmse_lp_N": 100.0 * i}) for i in range(5)],
                tmp_path / "results.parquet")
    drawn = _drawn(monkeypatch)
    plot_sweep(tmp_path)
    (line,) = drawn[f"{SPEED}.png"].axes[0].get_lines()
    assert line.get_linestyle() == "None" and len(line.get_xdata()) == 5


def test_cli_plot_prints_and_writes_the_summary(tmp_path, capsys) -> None:
    write_table(_grid_rows(), tmp_path / "results.parquet")
    assert main(["sweep", "--plot", str(tmp_path), "--diagnostics"]) == 0
    out = capsys.readouterr().out
    assert "RMSE lp [kN]" in out and (tmp_path / "summary.md").read_text() in out
    assert (tmp_path / "summary.csv").is_file()
    assert (tmp_path / "figures" / "diagnostics.png").is_file()
    assert main(["sweep", "--plot", str(tmp_path / "none")]) == 2
    assert "no sweep results here" in capsys.readouterr().err


class _SyntheticExecutor:
    """Stands in for the Dask executor: synthetic runs of the asked-for specs."""

    def as_completed(self, specs, progress=None):
        from synthetic import synthetic_result

        from trackmj.study.executor import RunOutcome

        for spec in specs:
            yield RunOutcome(spec, result=synthetic_result(
                spec.scenario, spec.architecture, seed=spec.seed, duration_s=spec.duration),
                wall_time_s=0.5)


def test_a_sweep_into_a_folder_of_another_machine_shows_every_row(tmp_path) -> None:
    """A sweep resumed into a folder holding another machine's rows prints and writes the
    summary --plot makes of the folder (every row, each machine by its name) and says how
    many of its points are not the spec's."""
    from trackmj.study.sweep import summarize_sweep, summary_markdown

    out = tmp_path / "out"
    out.mkdir()
    write_table(_mini_rows(), out / "results.parquet")
    summary = sweep(_spec(parameters=[{"key": BULK, "values": [8e8, 16e8]}]), out,
                    executor=_SyntheticExecutor(), progress=False, plot=False)
    assert [r.case["machine"] for r in summary.table.rows] == ["lf1352"] * 2 + ["mini"] * 2
    assert (summary.ran, summary.other_points) == (2, 2)
    assert summary_markdown(summary.table) == (out / "summary.md").read_text() == \
        summary_markdown(summarize_sweep(out))
    assert f"2 of its 4 points are of earlier sweeps into {out}" in str(summary)


def test_cli_plot_with_a_machine_shows_that_machines_rows(tmp_path, capsys) -> None:
    """``sweep --plot DIR --machine NAME`` prints, writes and draws only that machine's rows
    and says so; a machine without rows there, or an option of a sweep that runs, is refused
    in one line."""
    write_table(_lf_rows() + _mini_rows(), tmp_path / "results.parquet")
    assert main(["sweep", "--plot", str(tmp_path), "--machine", "mini"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Sweep summary (W1, mini, tp, nmpc, ekf, nominal, 1.5 s runs, "
                          f"soft_hyd.toml, {SPEED}=1.0): 2 points\n")
    assert "- Only machine mini's runs (--machine): 2 other row(s) of results.parquet left " \
           "out." in out
    assert (tmp_path / "summary.md").read_text() in out
    assert len((tmp_path / "summary.csv").read_text().splitlines()) == 1 + 2
    assert main(["sweep", "--plot", str(tmp_path), "--machine", "compact3"]) == 2
    assert capsys.readouterr().err == (f"trackmj: error: --machine compact3: no run of it in "
                                       f"{tmp_path / 'results.parquet'} (machines there: "
                                       "lf1352, mini)\n")
    assert main(["sweep", "--plot", str(tmp_path), "--workers", "1"]) == 2
    assert "--workers apply to a sweep that runs a spec" in capsys.readouterr().err


def test_results_are_rewritten_at_most_every_period_and_flushed(tmp_path, monkeypatch) -> None:
    """Rewriting grows with the rows, so it is throttled; what arrived is always flushed."""
    import trackmj.study.campaign as campaign

    writes = []
    monkeypatch.setattr(campaign, "write_table", lambda rows, path: writes.append(len(rows)))
    writer = campaign.TableWriter(tmp_path / "results.parquet")
    rows = {}
    for i in range(5):
        rows[f"k{i}"] = {"run_key": f"k{i}"}
        writer.changed(rows)
    assert writes == [1]              # the first row at once, the next within the period
    writer.flush(rows)
    writer.flush(rows)
    assert writes == [1, 5]           # pending rows once, nothing when nothing is new


# ----------------------------------------------------------------------------- on Dask

@pytest.fixture(scope="module")
def executor():
    with Executor(workers=2) as ex:
        yield ex


@pytest.fixture(scope="module")
def grid(executor, tmp_path_factory):
    """2 x 2 grid of 1.5 s W1 runs: standing / driven track x soft / stiff oil; the step
    and ramp, moved inside the short runs, are of zero size (a constant reference)."""
    out = tmp_path_factory.mktemp("grid")
    spec = _spec(parameters=[{"key": SPEED, "values": [0.0, 1.5]},
                             {"key": BULK, "values": [0.8e9, 1.6e9]}],
                 set=["scenario.reference.steps.0.delta_N=0",
                      "scenario.reference.ramps.0.rate_N_s=0"])
    summary = sweep(spec, out, executor=executor, progress=False)
    return out, spec, summary


def test_workers_start_warm_with_one_thread(executor) -> None:
    """Both workers were forked from one warmed forkserver (same warm-up record) and run
    with single-threaded pools."""
    def probe():
        import numba

        import trackmj.study.worker
        return (trackmj.study.worker.warm_time_s, os.environ.get("OMP_NUM_THREADS"),
                numba.config.NUMBA_NUM_THREADS)

    reports = list(executor.client.run(probe).values())
    assert len(reports) == 2 and reports[0] == reports[1]
    assert reports[0][0] > 0.0 and reports[0][1:] == ("1", 1)


@pytest.mark.slow
def test_grid_writes_one_row_per_run_with_its_parameters_and_metrics(grid) -> None:
    out, _, summary = grid
    assert (summary.runs, summary.ran, summary.skipped, summary.failed) == (4, 4, 0, 0)
    df = read_sweep(out)
    assert len(df) == 4 and df["error"].isna().all()
    assert sorted(zip(df[SPEED], df[BULK], strict=True)) == [
        (0.0, 0.8e9), (0.0, 1.6e9), (1.5, 0.8e9), (1.5, 1.6e9)]
    assert df["rmse_N"].nunique() == 4 and (df["wall_time_s"] > 0).all()
    assert (df["duration_s"] == DURATION_S).all() and (df["mujoco_warnings"] == 0).all()
    assert df.attrs["units"][BULK] == "Pa" and df.attrs["units"]["rmse_N"] == "N"
    # physics: a standing track has no chordal ripple, so it tracks far better
    for bulk in (0.8e9, 1.6e9):
        rmse = {v: df.loc[(df[SPEED] == v) & (df[BULK] == bulk), "rmse_N"].item()
                for v in (0.0, 1.5)}
        assert rmse[0.0] < 0.5 * rmse[1.5], rmse


def test_resume_skips_the_rows_already_written(grid, executor) -> None:
    out, spec, _ = grid
    before = (out / "results.parquet").read_bytes()
    summary = sweep(spec, out, executor=executor, progress=False, plot=False)
    assert (summary.ran, summary.skipped) == (0, 4)
    assert (out / "results.parquet").read_bytes() == before


@pytest.mark.slow
def test_a_sweep_writes_its_summary_and_a_figure_per_key(grid, executor) -> None:
    """The grid's summary (one row per point, also in summary.md and summary.csv) and one
    figure per swept key, no diagnostics; a resumed sweep keeps them, --plot redraws."""
    out, spec, summary = grid
    assert len(summary.table.rows) == 4 and summary.table.varied == (SPEED, BULK)
    assert sorted(p.name for p in summary.figures) == sorted([f"{SPEED}.png", f"{BULK}.png"])
    assert sorted(p.name for p in (out / "figures").iterdir()) == sorted(
        p.name for p in summary.figures)
    for path in summary.figures:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = _table_lines((out / "summary.md").read_text())
    assert len(rows) == 2 + 4 and rows[0][:2] == [f"{SPEED} [m/s]", f"{BULK} [Pa]"]
    assert len((out / "summary.csv").read_text().splitlines()) == 1 + 4
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "figures").glob("*.png")}
    again = sweep(spec, out, executor=executor, progress=False)   # resumes: nothing to run
    assert again.ran == 0 and len(again.table.rows) == 4
    assert {p.name: p.stat().st_mtime_ns for p in (out / "figures").glob("*.png")} == stamps
    (out / "figures" / f"{SPEED}.png").unlink()
    assert main(["sweep", "--plot", str(out)]) == 0
    assert (out / "figures" / f"{SPEED}.png").is_file()


def test_a_failing_run_becomes_an_error_row(executor, tmp_path) -> None:
    """A -30 kN push on the rear hitch (far beyond LF1352's drawbar capacity) from 0.5 to 1.0 s,
    the oil's free air swept: without it the push pulls the rods below vacuum within 0.2 s,
    and that run is a row with its error; with the shipped air (0.005) the rod chambers fill
    with air and the run beside it goes through (loop closure within 0.2 mm; held to 1.4 s
    the push tears the loop about 1 s after its onset)."""
    spec = {"sweep": {"scenario": "W3", "duration_s": DURATION_S, "set": [
        "scenario.load_pulses.0.start_s=0.5", "scenario.load_pulses.0.end_s=1.0",
        "scenario.load_pulses.0.hitch_N=-30000.0", "scenario.load_pulses.1.hitch_N=0.0"],
        "parameters": [{"key": "hydraulics.cavitation.air_fraction",
                        "values": [0.005, 0.0]}]}}
    summary = sweep(spec, tmp_path, executor=executor, progress=False, plot=False,
                    keep_runs=True)
    assert (summary.ran, summary.failed) == (2, 1)
    df = read_sweep(tmp_path).set_index("hydraulics.cavitation.air_fraction")
    assert math.isnan(df.loc[0.0, "rmse_N"]) and df.loc[0.0, "wall_time_s"] > 0
    assert df.loc[0.0, "error"].startswith("PhysicsError: t = ")
    assert "below vacuum" in df.loc[0.0, "error"]
    assert df["error"].isna().sum() == 1 and df.loc[0.005, "rmse_N"] > 0
    (kept,) = [p for p in (tmp_path / "runs").iterdir() if p.is_dir()]   # the run that ran
    assert json.loads((kept / "metrics.json").read_text())["run"]["scenario"] == "W3"
    rows = {r.values["hydraulics.cavitation.air_fraction"]: r for r in summary.table.rows}
    assert (rows[0.0].seeds, rows[0.0].failed) == ((), 1)   # counted, not averaged
    assert (rows[0.005].seeds, rows[0.005].failed) == ((0,), 0)
    assert "0 (1 failed)" in (tmp_path / "summary.md").read_text()
    again = sweep(spec, tmp_path, executor=executor, progress=False, plot=False)
    assert (again.ran, again.skipped) == (0, 2)


def test_a_missing_machine_file_is_refused_naming_the_spec_key_and_path(tmp_path,
                                                                        capsys) -> None:
    """A machine file that is not there (in the spec or as --machine) is refused up front in
    one line naming where it was given and the path looked for, not blamed on a run."""
    spec = tmp_path / "study.toml"
    spec.write_text('[sweep]\nscenario = "W1"\nmachine = "mini_machine.toml"\n')
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out)]) == 2
    missing = tmp_path / "mini_machine.toml"
    assert capsys.readouterr().err == (f"trackmj: error: study.toml [sweep].machine = "
                                       f"'mini_machine.toml': machine file not found: "
                                       f"{missing}\n")
    spec.write_text('[sweep]\nscenario = "W1"\n')
    assert main(["sweep", str(spec), "--out", str(out), "--machine", str(missing)]) == 2
    assert capsys.readouterr().err == f"trackmj: error: --machine: machine file not found: " \
                                      f"{missing}\n"
    assert not out.exists()


def test_cli_sweep_refuses_a_bad_spec_naming_it(tmp_path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[sweep]\nscenario = "W1"\nmethod = "sobol"\n')
    assert main(["sweep", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml [sweep].method = 'sobol' is not one of ['grid', 'lhs']" in err
    assert not (tmp_path / "out").exists()
    assert main(["sweep"]) == 2
    assert "sweep needs a spec file" in capsys.readouterr().err


@pytest.mark.slow
def test_a_run_that_kills_its_worker_is_an_outcome_with_the_error(executor, monkeypatch):
    """A run that takes its worker process down (here: os._exit, as a segfault would) is
    retried on restarted workers by Dask and then reported as failed; the batch goes on."""
    from trackmj.study.executor import RunSpec

    submit = executor.client.submit

    def dying_for_seed_99(fn, spec, *args, **kwargs):
        if spec.seed == 99:
            def die(*_):
                os._exit(3)
            return submit(die, spec, *args, **kwargs)
        return submit(fn, spec, *args, **kwargs)

    monkeypatch.setattr(executor.client, "submit", dying_for_seed_99)
    fine, dying = RunSpec("W1", duration=DURATION_S, seed=0), RunSpec("W1", seed=99)
    outcomes = executor.map([fine, dying])
    assert outcomes[0].ok and outcomes[0].result.seed == 0
    assert outcomes[1].error.startswith("KilledWorker")


def test_plot_says_when_runs_settled_on_an_end_stop(tmp_path, capsys) -> None:
    """Rows holding a run's end-stop record (flattened, as a sweep writes it) get one line
    on stderr with how many runs and the first one's case; rows without it get none."""
    on = {"settled_on_end_stop.stroke_m": -0.0028, "settled_on_end_stop.stop_stroke_m": 0.0,
          "settled_on_end_stop.grade": 0.2}
    write_table([_row("k0", 0, machine="m113", **on), _row("k1", 1, machine="m113")],
                tmp_path / "results.parquet")
    assert main(["sweep", "--plot", str(tmp_path)]) == 0
    assert capsys.readouterr().err == (
        "trackmj: warning: 1 of 2 runs settled with the idler carrier on an end stop, the "
        "first W1 on m113 on a grade of +0.2 (tan θ) (stroke -2.8 mm, the stop at 0.0 mm): "
        "the stop, not the tensioner, holds the idler at the start of those runs\n")
    write_table([_row("k1", 1, machine="m113")], tmp_path / "results.parquet")
    assert main(["sweep", "--plot", str(tmp_path)]) == 0
    assert capsys.readouterr().err == ""
