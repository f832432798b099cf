"""The Python API: trackmj.simulate and friends, Result.to_pandas, read_result round trip."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import trackmj
from trackmj.results.store import COLUMN_UNITS

DURATION_S = 1.2
BULK_MODULUS_PA = 1.2e9


@pytest.fixture(scope="module")
def result():
    return trackmj.simulate("W1", architecture="tp", controller="nmpc", seed=0,
                            duration=DURATION_S,
                            set={"hydraulics.fluid.bulk_modulus_Pa": BULK_MODULUS_PA})


def test_import_trackmj_loads_no_numerics_and_exports_the_api() -> None:
    """``import trackmj`` imports none of the heavy libraries; the exports load on use."""
    code = ("import sys, trackmj; heavy = [m for m in ('numpy', 'mujoco', 'numba', 'pyarrow',"
            " 'scipy', 'casadi') if m in sys.modules]; print(heavy, sorted(dir(trackmj)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    heavy, names = out.split("] ", 1)
    assert heavy == "["
    for name in ("simulate", "sweep", "load_scenario", "read_result", "TrackPlant", "Result"):
        assert repr(name) in names


def test_exports_are_the_functions_not_modules() -> None:
    import trackmj.sim.run

    assert trackmj.simulate is trackmj.sim.run.simulate and callable(trackmj.simulate)
    assert trackmj.Result is trackmj.results.store.Result
    with pytest.raises(AttributeError, match="no attribute 'simulat'"):
        trackmj.simulat   # noqa: B018


def test_simulate_runs_the_case_it_was_given(result) -> None:
    meta = result.metadata
    assert (result.scenario, result.architecture, result.controller, result.seed) == (
        "W1", "tp", "nmpc", 0)
    assert json.loads(meta["overrides"]) == {"hydraulics.fluid.bulk_modulus_Pa":
                                             BULK_MODULUS_PA}
    t = result.columns()["t_s"]
    assert len(t) == round(DURATION_S / 1e-3) and t[-1] == pytest.approx(DURATION_S)
    assert result.metrics["mujoco_warnings"] == 0


def test_repr_is_one_line_naming_the_run(result) -> None:
    text = repr(result)
    assert "\n" not in text and len(text) < 200
    assert text.startswith("Result(W1 tp nmpc/ekf seed 0, 1200 rows")


def test_columns_are_read_only_views_equal_to_the_table(result) -> None:
    cols = result.columns()
    for name in COLUMN_UNITS:
        assert not cols[name].flags.writeable
        np.testing.assert_array_equal(cols[name],
                                      result.timeseries.column(name).to_numpy(), err_msg=name)
    assert cols["valve_mode"].dtype == np.int8


def test_to_pandas_carries_units_run_and_metrics(result) -> None:
    df = result.to_pandas()
    assert list(df.columns) == list(COLUMN_UNITS)
    assert df.attrs["units"] == COLUMN_UNITS
    assert df.attrs["run"]["scenario"] == "W1" and df.attrs["run"]["seed"] == "0"
    assert df.attrs["metrics"]["rmse_N"] == result.metrics["rmse_N"]
    np.testing.assert_array_equal(df["tension_N"].to_numpy(), result.columns()["tension_N"])
    assert df["valve_mode"].dtype == np.int8


def test_optional_frame_libraries_say_what_to_install(result, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "polars", None)    # as if not installed
    with pytest.raises(ImportError, match=r"to_polars\(\) needs polars.*trackmj\[polars\]"):
        result.to_polars()
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match=r"to_pandas\(\) needs pandas.*trackmj\[pandas\]"):
        result.to_pandas()


def _same(a, b) -> bool:
    """Equal metrics, tables compared entry by entry, NaN equal to NaN."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (np.isnan(a) and np.isnan(b))
    return a == b


def test_read_result_round_trip_and_plain_csv(result, tmp_path) -> None:
    out = trackmj.write_result(result, tmp_path / "run", csv=True)
    back = trackmj.read_result(out)
    assert back.units == result.units and back.metadata == result.metadata
    for name, values in result.columns().items():
        np.testing.assert_array_equal(back.columns()[name], values, err_msg=name)
    assert _same(back.metrics, result.metrics)
    # the CSV is numbers under one header row: any reader takes it; units in units.json
    frame = pd.read_csv(out / "timeseries.csv")
    assert list(frame.columns) == list(COLUMN_UNITS)
    assert all(dtype.kind in "fi" for dtype in frame.dtypes)
    np.testing.assert_allclose(frame["p_head_Pa"], result.columns()["p_head_Pa"], rtol=1e-15)
    assert json.loads((out / "units.json").read_text()) == COLUMN_UNITS


def test_read_result_names_what_is_missing(result, tmp_path) -> None:
    out = trackmj.write_result(result, tmp_path / "run")
    (out / "timeseries.parquet").unlink()
    with pytest.raises(FileNotFoundError, match=r"no timeseries\.parquet"):
        trackmj.read_result(out)


@pytest.mark.slow
def test_a_repeated_track_restores_its_settled_state_bit_for_bit(monkeypatch) -> None:
    """Runs on the same track (here: another bulk modulus) reuse the settled state of the
    first instead of settling again; the result is the one a fresh settle gives."""
    from trackmj.sim import mechanics

    monkeypatch.setattr(mechanics, "_settled", {})
    settles = []
    original = mechanics.TrackPlant.run

    def counted(plant, *args, **kwargs):
        settles.append(args)
        return original(plant, *args, **kwargs)

    monkeypatch.setattr(mechanics.TrackPlant, "run", counted)
    first = trackmj.simulate("W1", duration=DURATION_S, seed=1)
    stiffer = trackmj.simulate("W1", duration=DURATION_S, seed=1,
                               set={"hydraulics.fluid.bulk_modulus_Pa": 2.0e9})
    again = trackmj.simulate("W1", duration=DURATION_S, seed=1)
    assert len(settles) == 1
    for name, values in first.columns().items():
        np.testing.assert_array_equal(again.columns()[name], values, err_msg=name)
    assert not np.array_equal(stiffer.columns()["p_head_Pa"], first.columns()["p_head_Pa"])
