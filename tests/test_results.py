"""Result tables and result directories: round trip, units, and a directory that always holds
one complete run (staged whole, swapped in, locked against a second writer)."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

import trackmj.results.store as R

META = R.run_metadata("W1", "tp", "nmpc", "ekf", 3, "test box", machine="lf1352")


def _table(n: int = 500):
    t = np.arange(n) * 1e-3
    mode = np.array([(0, 1, 0, -1)[(i // 100) % 4] for i in range(n)], dtype=float)
    cols = {name: np.zeros(n) for name in R.COLUMN_UNITS}
    cols |= {"t_s": t, "tension_N": 15e3 + 100 * np.sin(60 * t), "tension_ref_N": np.full(n, 15e3),
             "valve_mode": mode, "u": 0.3 * mode, "stroke_velocity_m_s": np.full(n, 1e-3),
             "pin_tension_max_N": np.full(n, 7.5e3)}
    return R.make_table(cols, R.COLUMN_UNITS | {"pin_tension_max_N": "N"}, META)


def _result(n: int = 500, **metrics: float) -> R.Result:
    return R.Result(_table(n), dict(metrics))


def test_table_orders_contract_columns_and_carries_units() -> None:
    table = _table()
    assert table.column_names[: len(R.COLUMN_UNITS)] == list(R.COLUMN_UNITS)
    assert table.column_names[-1] == "pin_tension_max_N"
    assert str(table.schema.field("valve_mode").type) == "int8"
    assert table.schema.field("chassis_acc_z_m_s2").metadata[b"unit"] == b"m/s^2"
    with pytest.raises(ValueError, match=r"mystery.*need a unit"):
        R.make_table({"mystery": np.zeros(3)}, {}, META)


def test_round_trip_with_units_tables_and_nan_metrics(tmp_path) -> None:
    result = _result(rmse_N=412.5, settling_time_s=math.nan,
                     energy_J={"pump": 1200.0, "losses": {"relief": 3.0, "leakage": math.nan}})
    out = R.write_result(result, tmp_path / "run", csv=True)
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "timeseries.csv",
                                                     "timeseries.parquet", "units.json"]
    back = R.read_result(out)
    assert back.timeseries.equals(result.timeseries, check_metadata=True)
    assert back.units["p_head_Pa"] == "Pa" and back.units["valve_mode"] == "1"
    assert (back.scenario, back.architecture, back.controller, back.estimator, back.seed) == (
        "W1", "tp", "nmpc", "ekf", 3)
    assert back.metadata["host"] == "test box" and back.metadata["trackmj_version"]
    assert back.metrics["rmse_N"] == 412.5 and math.isnan(back.metrics["settling_time_s"])
    assert back.metrics["energy_J"]["losses"]["relief"] == 3.0
    assert math.isnan(back.metrics["energy_J"]["losses"]["leakage"])
    doc = json.loads((out / "metrics.json").read_text())  # strict JSON: NaN written as null
    assert doc["metrics"]["settling_time_s"] is None and doc["run"]["scenario"] == "W1"
    # units straight from the Parquet schema, and from units.json, without trackmj
    schema = pq.read_schema(out / "timeseries.parquet")
    assert schema.field("q_supply_m3_s").metadata[b"unit"] == b"m^3/s"
    assert json.loads((out / "units.json").read_text())["stroke_velocity_m_s"] == "m/s"


def test_csv_is_plain_with_one_header_row(tmp_path) -> None:
    result = _result(20)
    out = R.write_result(result, tmp_path / "run", csv=True)
    table = pacsv.read_csv(out / "timeseries.csv")   # any CSV reader, no options
    assert table.column_names == result.timeseries.column_names
    np.testing.assert_allclose(table.column("tension_N").to_numpy(),
                               result.columns()["tension_N"])
    assert table.num_rows == 20


def test_failure_mid_write_leaves_no_output(tmp_path, monkeypatch) -> None:
    def boom(table):
        raise OSError("disk full")

    monkeypatch.setattr(R, "_csv_bytes", boom)
    with pytest.raises(OSError, match="disk full"):
        R.write_result(_result(50), tmp_path / "run", csv=True)
    assert list(tmp_path.iterdir()) == []  # no directory, no stage, no lock file


def test_rewrite_replaces_the_whole_directory(tmp_path) -> None:
    out = R.write_result(_result(50, rmse_N=1.0), tmp_path / "run", csv=True,
                         extras={"run.rrd": lambda p: p.write_bytes(b"rrd")})
    # a rerun without a recording or CSV leaves neither stale file behind
    R.write_result(_result(80, rmse_N=2.0), out)
    back = R.read_result(out)
    assert back.metrics["rmse_N"] == 2.0 and back.timeseries.num_rows == 80
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "timeseries.parquet",
                                                     "units.json"]
    assert [p.name for p in tmp_path.iterdir()] == ["run"]   # no stage, no lock file


def test_failed_overwrite_keeps_the_previous_result(tmp_path, monkeypatch) -> None:
    out = R.write_result(_result(50, rmse_N=1.0), tmp_path / "run")
    monkeypatch.setattr(R, "metrics_json", lambda result: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        R.write_result(_result(80, rmse_N=2.0), out)
    assert R.read_result(out).metrics["rmse_N"] == 1.0
    assert [p.name for p in tmp_path.iterdir()] == ["run"]   # no stage, no lock file


def test_second_writer_is_refused_while_the_first_holds_the_lock(tmp_path) -> None:
    with R.ResultWriter(tmp_path / "run") as first:
        with pytest.raises(R.ResultDirectoryError, match="another trackmj process"):
            R.ResultWriter(tmp_path / "run").__enter__()
        first.commit(_result(10, rmse_N=1.0))
    assert R.read_result(tmp_path / "run").metrics["rmse_N"] == 1.0


def test_killed_writer_leaves_the_previous_result_and_is_cleaned_up(tmp_path) -> None:
    """A writer killed (SIGKILL) after staging its files: the old result stays whole, the
    stale stage is removed by the next writer, and the lock died with the process (its
    file, left behind, is taken over and removed by the next writer)."""
    out = R.write_result(_result(50, rmse_N=1.0), tmp_path / "run")
    script = textwrap.dedent(f"""
        import time
        import trackmj.results.store as R
        with R.ResultWriter({str(out)!r}) as w:
            (w.stage / "timeseries.parquet").write_bytes(b"half a file")
            print("staged", flush=True)
            time.sleep(60)
    """)
    with subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                          text=True) as proc:
        try:
            assert proc.stdout.readline().strip() == "staged"
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
        finally:
            proc.kill()
    assert R.read_result(out).metrics["rmse_N"] == 1.0
    assert any(p.name.startswith(".run.stage-") for p in tmp_path.iterdir())
    R.write_result(_result(20, rmse_N=3.0), out)
    assert R.read_result(out).metrics["rmse_N"] == 3.0
    assert [p.name for p in tmp_path.iterdir()] == ["run"]   # no stage, no lock file


def test_output_that_cannot_take_a_result_is_refused_before_any_work(tmp_path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(R.ResultDirectoryError, match="is a file"):
        R.check_output_dir(tmp_path / "file")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("x")
    with pytest.raises(R.ResultDirectoryError, match="holds no trackmj result"):
        R.check_output_dir(tmp_path / "mine")
    with pytest.raises(R.ResultDirectoryError, match="cannot create"):
        R.check_output_dir(tmp_path / "file" / "run")
    assert (tmp_path / "mine" / "thesis.tex").exists()


def test_incomplete_directory_is_not_a_result(tmp_path) -> None:
    (tmp_path / "run").mkdir()
    with pytest.raises(FileNotFoundError, match="not a complete result"):
        R.read_result(tmp_path / "run")


def test_writer_exits_cleanly_on_keyboard_interrupt(tmp_path) -> None:
    out = R.write_result(_result(50, rmse_N=1.0), tmp_path / "run")
    with pytest.raises(KeyboardInterrupt), R.ResultWriter(out) as writer:
        (writer.stage / "timeseries.parquet").write_bytes(b"partial")
        raise KeyboardInterrupt
    assert R.read_result(out).metrics["rmse_N"] == 1.0
    assert [p.name for p in tmp_path.iterdir()] == ["run"]   # no stage, no lock file
    with R.ResultWriter(out):   # the lock was released: a new writer gets it at once
        pass
