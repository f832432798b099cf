"""An abrupt stop of a driving machine (``trackmj drive --stop-at``, :func:`trackmj.sim.drive
.drive`'s ``stop_s``): the speed command drops to 0 at once, the drive stops the sprocket at
its torque limit (trackmj/track/servo.py), the parking brake applies once it is still, and
the hull's momentum goes into the track. On a rear-sprocket machine braking makes the
strands over the idler the tight side (the layout law, trackmj/machines/drive_load.py), so
the idler takes the stop's load."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from trackmj.cli.main import main
from trackmj.machines.assembly import mechanics, resolve
from trackmj.machines.drive_load import drive_load
from trackmj.sim.drive import drive

SPEED_M_S, DURATION_S, STOP_S = 1.5, 4.0, 2.5


@pytest.mark.slow
def test_an_abrupt_stop_brings_the_sprocket_and_the_hull_to_rest_on_the_brake() -> None:
    """LF1352 from 1.5 m/s: the sprocket is still within 20 ms of the stop (measured 10 ms:
    one step takes it to 0.06 m/s, the links' surge then rings it below 0.05), the hull
    after its surge on the track within 1.5 s, the brake holds at the end, and braking
    loads the idler (sprocket at the rear) well past its steady maximum."""
    m = drive(SPEED_M_S, DURATION_S, stop_s=STOP_S).metrics
    stop, steady = m["stop"], m["steady"]
    print(stop, steady["idler_force_max_N"])
    assert stop["sprocket_still_after_s"] <= 0.02
    assert stop["hull_still_after_s"] < DURATION_S - STOP_S
    assert stop["hull_rebound_m_s"] <= 0.0
    assert m["parked"] and m["mujoco_warnings"] == 0 and m["derailment_checks_failed"] == 0
    braking = stop["drive_torque_extreme_N_m"]
    assert braking * SPEED_M_S < 0.0   # the drive brakes
    # the layout law: with the sprocket at the rear, a braking torque tightens the strands
    # over the idler
    assert drive_load(mechanics(resolve("lf1352"))).tight_sign * braking > 0.0
    assert stop["idler_force_max_N"] > 2.0 * steady["idler_force_max_N"]


@pytest.mark.slow
def test_the_stops_peak_is_the_one_a_finer_step_gives() -> None:
    """The stop is an impact: the contacts' explicit springs create energy at the 1 ms step
    (the ledger's explicit_constraint_springs; the CLI flags the drive), yet the idler's
    peak and the hull's rebound move by under 3 % and 0.03 m/s at 0.5 ms (measured 1.4 %,
    0.00 m/s; 39.2 kN at 0.25 ms)."""
    coarse = drive(SPEED_M_S, DURATION_S, stop_s=STOP_S).metrics["stop"]
    fine = drive(SPEED_M_S, DURATION_S, stop_s=STOP_S,
                 overrides={"simulation.timestep_s": 0.0005}).metrics["stop"]
    print(coarse, fine)
    assert coarse["idler_force_max_N"] == pytest.approx(fine["idler_force_max_N"], rel=0.03)
    assert abs(coarse["hull_rebound_m_s"] - fine["hull_rebound_m_s"]) < 0.03


@pytest.mark.parametrize(("args", "says"), [
    (["--duration", "2", "--stop-at", "2"], "stop at 2.0 s: allowed (0, 2) s"),
    (["--duration", "2", "--stop-at", "-1"], "stop at -1.0 s: allowed (0, 2) s"),
    (["--speed", "0", "--stop-at", "1"], "a stop needs a speed to stop from"),
])
def test_a_stop_outside_the_drive_is_refused_in_one_line(
        args: list[str], says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before any work: exit 2, one line saying what is allowed, no result folder."""
    out = tmp_path / "drive"
    assert main(["drive", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err
    assert not out.exists()


def test_a_stop_is_reported_only_when_asked() -> None:
    """The stop's metrics are None for a drive without one (the key is always written)."""
    m = drive(SPEED_M_S, 0.2).metrics
    assert m["stop_s"] is None and m["stop"] is None
    assert not math.isnan(m["steady"]["idler_force_mean_N"])
