"""Every result traceable to what made it: the machine and the measured log are part of a
run's identity and of its default folder's name, and metrics.json records them."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from trackmj.cli.main import main
from trackmj.cli.run_folder import refuse_other_inputs, run_folder
from trackmj.results.measured import load_measured
from trackmj.sim.run import measured_log
from trackmj.sim.setup import prepare
from trackmj.study.identity import inputs_key

DURATION_S = 2.0
"""A short W2 run (W2 has no event that a short run would cut off)."""


def _log(path: Path, tension_kN: float) -> Path:
    """A rig log written by hand: tension in kN, a column of no quantity of the run."""
    rows = ["t [s],tension [kN],oil_temperature [degC]"]
    rows += [f"{t:.3f},{tension_kN:.3f},41.5" for t in np.arange(0.0, DURATION_S + 0.01, 0.01)]
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("machine, suffix", [(None, ""), ("lf1352", ""),
                                             ("m113", "-m113"), ("compact3", "-compact3")])
def test_default_folder_names_the_machine_unless_it_is_the_default(machine, suffix) -> None:
    setup = prepare("W1", machine=machine)
    folder = run_folder(setup, inputs_key(setup), defaults=True)
    assert folder == Path("runs") / f"W1-tp-nmpc-s0{suffix}"


def test_runs_on_two_machines_never_share_a_folder_or_a_key(tmp_path: Path) -> None:
    """After an LF1352 W1 in its default folder, W1 on m113 with default options goes to
    another folder, and would be refused in LF1352's (another machine is another input)."""
    lf, m113 = prepare("W1"), prepare("W1", machine="m113")
    key_lf, key_m113 = inputs_key(lf), inputs_key(m113)
    assert key_lf != key_m113
    assert run_folder(lf, key_lf, defaults=True) != run_folder(m113, key_m113, defaults=True)
    held = tmp_path / "W1-tp-nmpc-s0"
    held.mkdir()
    (held / "metrics.json").write_text(json.dumps({"run": {"inputs_key": key_lf}}))
    with pytest.raises(Exception, match="other inputs"):
        refuse_other_inputs(held, key_m113, overwrite=False)


def test_the_log_is_part_of_the_identity(tmp_path: Path) -> None:
    """Two logs that differ in one value give two keys; the same log read twice, one."""
    setup = prepare("W2", duration=DURATION_S)
    a = measured_log(setup, _log(tmp_path / "a.csv", 13.0))
    b = measured_log(setup, _log(tmp_path / "b.csv", 13.1))
    again = load_measured(tmp_path / "a.csv", DURATION_S, ["t_s", "tension_N"])
    assert inputs_key(setup, a) != inputs_key(setup, b) != inputs_key(setup)
    assert inputs_key(setup, a) == inputs_key(setup, again)


@pytest.mark.slow
def test_two_logs_keep_two_results_each_naming_its_log(tmp_path: Path, monkeypatch,
                                                       capsys) -> None:
    """``trackmj run W2 --measured`` with two logs writes two folders (no --out), each
    metrics.json naming its log by file and SHA-256 with the columns compared and ignored;
    the summary lists the ignored column."""
    monkeypatch.chdir(tmp_path)
    logs = [_log(tmp_path / "rig_a.csv", 13.0), _log(tmp_path / "rig_b.csv", 12.0)]
    for log in logs:
        assert main(["run", "W2", "--duration", str(DURATION_S), "--measured", str(log)]) == 0
    printed = capsys.readouterr().out
    assert "oil_temperature [degC]" in printed
    folders = sorted((tmp_path / "runs").iterdir())
    assert len(folders) == 2
    named = {}
    for folder in folders:
        doc = json.loads((folder / "metrics.json").read_text())
        record = doc["metrics"]["measured_log"]
        named[record["file"]] = record
        assert doc["run"]["machine"] == "lf1352"
        assert record["columns_used"] == {"tension_N": "tension [kN]"}
        assert record["columns_ignored"] == ["oil_temperature [degC]"]
        assert (folder / "timeseries.png").is_file()
        assert pq.read_table(folder / "timeseries.parquet").num_rows == round(DURATION_S / 1e-3)
    assert set(named) == {"rig_a.csv", "rig_b.csv"}
    for log in logs:
        assert named[log.name]["sha256"] == hashlib.sha256(log.read_bytes()).hexdigest()
