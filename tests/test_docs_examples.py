"""The README's worked examples, run as a reader would: the tensioner FMU written in Python
(docs/tensioner-fmu), built with pythonfmu's command line and driven on the track."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "tensioner-fmu"
COMMAND = re.compile(r"trackmj (?:run|compare) (W\d)\b[^`#\n]*?--duration (\d+(?:\.\d*)?)")
"""A documented run or compare of a shipped scenario with a duration: (scenario, seconds)."""


def _gas_force_N(stroke_m: float, velocity_m_s: float) -> float:
    """The example's law with its default parameters, written out here by hand:
    F = A p0 (V0/V)^n − A p_atm − c v, V = V0 + A (s − s_ref)."""
    area, p0, v0, s_ref, n, c, p_atm = 3.2e-3, 4.2e6, 6.0e-4, 0.05, 1.3, 2.0e4, 1.013e5
    volume = v0 + area * (stroke_m - s_ref)
    return area * p0 * (v0 / volume) ** n - area * p_atm - c * velocity_m_s


@pytest.mark.slow
def test_python_tensioner_fmu_example_holds_its_law_on_the_track(tmp_path: Path) -> None:
    """Built with ``pythonfmu build`` from the docs and driven 3 s at 1.5 m/s, the track's
    mean idler force over the last second equals the gas law at the mean stroke and
    velocity (0.5 %: the weak coupling holds the last step's force)."""
    for name in ("GasSpring.py", "gas_spring.toml"):
        shutil.copy(DOCS / name, tmp_path / name)
    pythonfmu = Path(sys.executable).with_name("pythonfmu")
    subprocess.run([str(pythonfmu), "build", "-f", "GasSpring.py"], cwd=tmp_path, check=True,
                   capture_output=True)
    out = tmp_path / "drive"
    # in a process of its own: a pythonfmu FMU puts its own copy of pythonfmu (without the
    # builder's binaries) on the importing process's sys.path
    done = subprocess.run([sys.executable, "-m", "trackmj", "drive", "--tensioner",
                           str(tmp_path / "gas_spring.toml"), "--duration", "3", "--out",
                           str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    table = pq.read_table(out / "timeseries.parquet")
    t = table.column("t_s").to_numpy()
    last = t > t[-1] - 1.0
    force = table.column("idler_force_N").to_numpy()[last].mean()
    stroke = table.column("stroke_m").to_numpy()[last].mean()
    velocity = table.column("stroke_velocity_m_s").to_numpy()[last].mean()
    assert 5e3 < force < 2e4
    assert force == pytest.approx(_gas_force_N(stroke, velocity), rel=5e-3)
    assert np.isfinite(table.column("stroke_m").to_numpy()).all()


def test_documented_runs_last_long_enough_for_their_scenario() -> None:
    """Every ``trackmj run`` or ``compare`` of a shipped scenario with a ``--duration`` in
    the README and the docs keeps the scenario's events (``run`` refuses a duration that
    cuts one off, exit 2)."""
    from trackmj.scenarios.events import check_duration
    from trackmj.scenarios.load import load_scenario
    from trackmj.validator import ParameterError

    files = [ROOT / "README.md", *sorted(ROOT.glob("*/**/*.md"))]
    found = [(path.name, *match.groups()) for path in files if ".venv" not in path.parts
             for match in COMMAND.finditer(path.read_text())]
    assert len(found) >= 4, found
    for name, scenario, duration in found:
        try:
            check_duration(load_scenario(scenario), float(duration))
        except ParameterError as exc:
            pytest.fail(f"{name}: trackmj run {scenario} --duration {duration}: {exc}")
