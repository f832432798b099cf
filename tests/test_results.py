"""Result tables, recorder and result directories: round trip, units, atomicity."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest

import trackmj.results as R

META = R.run_metadata("W1", "tp", "nmpc", "ekf", 3, machine="test box")


def _recorded(n: int = 500) -> R.TimeseriesRecorder:
    rec = R.TimeseriesRecorder(n + 10, extra_units={"pin_tension_max_N": "N"})
    for i in range(n):
        t = i * 1e-3
        mode = (0, 1, 0, -1)[(i // 100) % 4]
        rec.append(i, t, 15e3 + 100 * math.sin(60 * t), 15e3, 6e6, 1e6, 12e6, 0.05, 1e-3,
                   1e-6 * mode, mode, 0.3 * mode, 12e6 * 1e-6 * t, 2.0 * t, 1.9 * t, 0.1,
                   7.5e3)
    return rec


def test_recorder_fills_columns_in_contract_order() -> None:
    rec = _recorded()
    assert rec.columns[: len(R.COLUMN_UNITS)] == tuple(R.COLUMN_UNITS)
    assert rec.columns[-1] == "pin_tension_max_N" and rec.rows == 500
    cols = rec.arrays()
    np.testing.assert_allclose(cols["t_s"], np.arange(500) * 1e-3)
    assert cols["valve_mode"][150] == 1.0 and cols["valve_mode"][350] == -1.0
    table = rec.table(META)
    assert table.num_rows == 500  # only the rows written, not the preallocation
    assert str(table.schema.field("valve_mode").type) == "int8"
    assert table.schema.field("tension_N").metadata[b"unit"] == b"N"
    assert table.schema.field("chassis_acc_z_m_s2").metadata[b"unit"] == b"m/s^2"
    assert table.schema.field("pin_tension_max_N").metadata[b"unit"] == b"N"


def test_contract_is_enforced() -> None:
    cols = _recorded().arrays()
    with pytest.raises(ValueError, match=r"lacks contract column.*p_rod_Pa"):
        R.make_table({k: v for k, v in cols.items() if k != "p_rod_Pa"}, {}, META)
    with pytest.raises(ValueError, match="need a unit"):
        R.make_table(cols | {"mystery": cols["u"]}, {}, META)
    with pytest.raises(ValueError, match=r"run metadata lacks.*seed"):
        R.make_table(cols, {"pin_tension_max_N": "N"}, {k: v for k, v in META.items()
                                                        if k != "seed"})
    with pytest.raises(ValueError, match="clash"):
        R.TimeseriesRecorder(5, extra_units={"u": "1"})


def test_round_trip_with_units_metadata_and_nan_metrics(tmp_path) -> None:
    result = R.Result(_recorded().table(META), {"rmse_N": 412.5, "settling_time_s": math.nan})
    out = R.write_result(result, tmp_path / "run", csv=True)
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "timeseries.csv",
                                                     "timeseries.parquet"]
    back = R.read_result(out)
    assert back.timeseries.equals(result.timeseries, check_metadata=True)
    assert back.units["p_head_Pa"] == "Pa" and back.units["valve_mode"] == "1"
    assert (back.scenario, back.architecture, back.controller, back.estimator, back.seed) == (
        "W1", "tp", "nmpc", "ekf", 3)
    assert back.metadata["machine"] == "test box" and back.metadata["trackmj_version"]
    assert back.metrics["rmse_N"] == 412.5 and math.isnan(back.metrics["settling_time_s"])
    doc = json.loads((out / "metrics.json").read_text())  # strict JSON: NaN written as null
    assert doc["metrics"]["settling_time_s"] is None and doc["run"]["scenario"] == "W1"
    # units also straight from the Parquet schema, without trackmj
    schema = pq.read_schema(out / "timeseries.parquet")
    assert schema.field("q_supply_m3_s").metadata[b"unit"] == b"m^3/s"


def test_csv_has_units_line_then_header(tmp_path) -> None:
    result = R.Result(_recorded(20).table(META), {})
    out = R.write_result(result, tmp_path / "run", csv=True)
    lines = (out / "timeseries.csv").read_text().splitlines()
    names, units = lines[1].split(","), lines[0].removeprefix("# units: ").split(",")
    assert names[:2] == ["t_s", "tension_N"] and units[:2] == ["s", "N"]
    assert dict(zip(names, units, strict=True))["stroke_velocity_m_s"] == "m/s"
    data = np.loadtxt(out / "timeseries.csv", delimiter=",", skiprows=2)
    np.testing.assert_allclose(data[:, 1], result.columns()["tension_N"])
    assert len(data) == 20


def test_failure_mid_write_leaves_no_output(tmp_path, monkeypatch) -> None:
    result = R.Result(_recorded(50).table(META), {"rmse_N": 1.0})

    def boom(table):
        raise OSError("disk full")

    monkeypatch.setattr(R, "_csv_bytes", boom)
    with pytest.raises(OSError, match="disk full"):
        R.write_result(result, tmp_path / "run", csv=True)
    assert list(tmp_path.iterdir()) == []  # neither the directory nor a staging leftover


def test_failed_overwrite_keeps_the_previous_result(tmp_path, monkeypatch) -> None:
    old = R.Result(_recorded(50).table(META), {"rmse_N": 1.0})
    out = R.write_result(old, tmp_path / "run")
    (out / "figure.png").write_bytes(b"png")  # other files of the run directory survive
    monkeypatch.setattr(R, "_metrics_json", lambda result: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        R.write_result(R.Result(_recorded(80).table(META), {"rmse_N": 2.0}), out)
    assert R.read_result(out).metrics["rmse_N"] == 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    monkeypatch.undo()
    R.write_result(R.Result(_recorded(80).table(META), {"rmse_N": 2.0}), out)
    back = R.read_result(out)
    assert back.metrics["rmse_N"] == 2.0 and back.timeseries.num_rows == 80
    assert (out / "figure.png").exists() and not (out / "timeseries.csv").exists()


def test_incomplete_directory_is_not_a_result(tmp_path) -> None:
    (tmp_path / "run").mkdir()
    with pytest.raises(FileNotFoundError, match="not a complete result"):
        R.read_result(tmp_path / "run")
