"""Derailment you can act on: which check failed, when and where, in the drive's metrics,
timeseries, summary and figure; ``--model`` is the model parameter TOML in ``drive`` as in
``run``, ``--mjcf`` the MJCF file."""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

import mujoco
import numpy as np
import pyarrow.parquet as pq
import pytest

from trackmj.cli.main import main
from trackmj.elements.prescribed import ConstantForce
from trackmj.fmi.native.variables import OUTPUTS
from trackmj.machines.track_plant import load_plant
from trackmj.ports import Command, Readout, StepInputs, TensionerElement
from trackmj.sim.drive import DerailmentChecks, derailment_columns, derailment_table
from trackmj.track.plant import DerailmentLimits, DerailmentStatus, PassiveTensioner, TrackPlant

ROOT = Path(__file__).resolve().parent.parent
LF1352 = tomllib.loads((ROOT / "models" / "lf1352.toml").read_text())
LINKS = LF1352["track"]["link_count"]   # 82
CHECKS = ("slack_strand", "links_off_envelope", "sprocket_disengaged", "derailed")
COLUMNS = {"sprocket_seated_pins": "1", "envelope_excursion_max_m": "m",
           "envelope_worst_pin": "1", "upper_strand_tension_min_N": "N",
           "upper_strand_slackest_pin": "1", "upper_strand_tension_held_N": "N",
           "sprocket_disengaged": "1", "links_off_envelope": "1", "slack_strand": "1",
           "derailed": "1"}
LIMITS = DerailmentLimits(envelope_threshold_m=0.1, seat_tolerance_m=0.012)
"""Hand-written limits for hand-written statuses (LF1352's, rounded)."""
SLACK_N = TrackPlant.SLACK_TENSION_N
WINDOW_S = TrackPlant.SLACK_PERSISTENCE_S
LOOSE = """[passive]
source = "holds 1 kN on the idler whatever its stroke: the strands F/2.0 = 0.5 kN"
preload_N = 1.0e3
stiffness_N_m = 0.0
damping_N_s_m = 2.0e4
stroke_ref_m = 0.05
travel_m = [-0.005, 0.105]
"""
"""A tensioner file that leaves LF1352's strands below the slack tension."""


def _drive(tmp_path: Path, capsys: pytest.CaptureFixture[str], *args: str
           ) -> tuple[int, str, dict, dict[str, np.ndarray], dict[str, str]]:
    """``trackmj drive ARGS --out tmp/drive``: exit code, stdout, metrics, columns, units."""
    out = tmp_path / "drive"
    code = main(["drive", *args, "--out", str(out)])
    printed = capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    table = pq.read_table(out / "timeseries.parquet")
    columns = {name: table.column(name).to_numpy() for name in table.column_names}
    units = {f.name: f.metadata[b"unit"].decode() for f in table.schema}
    return code, printed, metrics, columns, units


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) [px] from the PNG's IHDR chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def test_a_drive_whose_strand_hangs_names_each_failing_check_with_its_first_time(
        tmp_path, capsys) -> None:
    """A tensioner holding 1 kN on LF1352's idler (its strands' share 0.5 kN, below the
    1 kN slack tension) at 1.5 m/s for 2 s: the upper strand hangs; the slack check fails
    and says when, where and what it read."""
    loose = tmp_path / "loose.toml"
    loose.write_text(LOOSE)
    code, printed, m, c, units = _drive(tmp_path, capsys, "--tensioner", str(loose),
                                        "--speed", "1.5", "--duration", "2")
    assert code == 1
    table = m["derailment"]
    assert m["derailment_checks"] == 20 and m["derailment_check_interval_s"] == 0.1
    slack = table["slack_strand"]
    assert slack["window_s"] == WINDOW_S and slack["threshold"] == SLACK_N
    assert slack["failing_checks"] >= 10 and m["derailment_checks_failed"] >= 10
    first, last = slack["first_s"], slack["last_s"]
    assert 0.0 < first <= last <= 2.0
    assert first == pytest.approx(round(first * 10) / 10, abs=1e-6)   # at a check
    at = slack["at_first"]
    assert at["t_s"] == first and 0 <= at["pin"] < LINKS and at["strand"] == "upper"
    # slack: the least pin tension stayed below 1 kN over the window (its peak there), and
    # at the check it is at most that peak
    assert at["tension_N"] <= at["held_tension_N"] < SLACK_N
    row = int(np.argmin(np.abs(c["t_s"] - first)))
    # the strand hangs as a whole: its mean pin tension, recorded every step, is below 1 kN
    # over the second second (measured 0.65 kN), and at least its least pin's at the check
    assert c["upper_strand_tension_N"][c["t_s"] > 1.0].mean() < SLACK_N
    assert c["upper_strand_tension_N"][row] >= at["tension_N"]
    assert c["upper_strand_tension_min_N"][row] == pytest.approx(at["tension_N"])
    assert c["upper_strand_tension_held_N"][row] == pytest.approx(at["held_tension_N"])
    assert c["slack_strand"][row] == 1.0 and c["derailed"][row] == 1.0
    # every check that never failed says so with null times, and still gives its margin
    failing = [k for k in CHECKS[:-1] if table[k]["failing_checks"]]
    for check in CHECKS[:-1]:
        if check not in failing:
            assert table[check]["first_s"] is None and table[check]["last_s"] is None
            assert table[check]["at_first"] is None and table[check]["worst"] is not None
    assert table["derailed"]["first_s"] == min(table[k]["first_s"] for k in failing)
    assert table["derailed"]["failing_checks"] == m["derailment_checks_failed"]
    worst = table["links_off_envelope"]["worst"]
    assert 0 <= worst["pin"] < LINKS and worst["strand"] in ("upper", "lower run", "other")
    assert {k: units[k] for k in COLUMNS} == COLUMNS
    # the summary names the first failure and when
    assert f"first: slack strand at {first:.2f} s" in printed
    assert re.search(rf"slack strand\s+FAILED first at {first:.2f} s: upper-strand min "
                     rf"tension peaked at \d\.\d\d kN over the window, -?\d\.\d\d kN at pin "
                     rf"{at['pin']} at the check \(fails below 1\.00 kN throughout 0\.1 s\)",
                     printed)
    assert _png_size(tmp_path / "drive" / "drive.png") == (1200, 1100)


def test_healthy_drive_reports_no_failure_with_null_times(tmp_path, capsys) -> None:
    """The default preload at 1 m/s for 1 s (a 0.25 s ramp, a quarter of the drive, which
    the summary says) keeps the track guided."""
    code, printed, m, c, _ = _drive(tmp_path, capsys, "--speed", "1", "--duration", "1")
    assert code == 0
    assert m["ramp_s"] == 0.25 and "drove 1.0 s at 1.00 m/s (from rest in 0.25 s)" in printed
    t = c["t_s"]
    speed = c["track_speed_m_s"]
    assert speed[np.argmin(np.abs(t - 0.125))] == pytest.approx(0.5, abs=0.1)   # mid-ramp
    assert speed[np.argmin(np.abs(t - 0.5))] == pytest.approx(1.0, abs=0.05)
    assert m["derailment_checks"] == 10 and m["derailment_checks_failed"] == 0
    for check in CHECKS:
        row = m["derailment"][check]
        assert row["failing_checks"] == 0
        assert row["first_s"] is None and row["last_s"] is None and row["at_first"] is None
    margin = m["derailment"]["slack_strand"]["worst"]
    assert margin["held_tension_N"] > 1000.0 and 0 <= margin["pin"] < LINKS
    assert margin["held_tension_N"] >= margin["tension_N"]   # the peak includes the check
    assert m["derailment"]["sprocket_disengaged"]["worst"]["seated_pins"] >= 2
    # sampled every 0.1 s and held: NaN before the first check (t = 0.1 s), then 0/1
    t = c["t_s"]
    before = t < 0.1 - 1e-6
    assert np.isnan(c["derailed"][before]).all()
    assert (c["derailed"][~before] == 0.0).all()
    seated = c["sprocket_seated_pins"][99:]          # row 99: the first check
    changes = np.flatnonzero(seated[1:] != seated[:-1]) + 1 + 99
    assert ((changes + 1) % 100 == 0).all()          # a new value only at a check's row
    assert "0 of 10 checks failed" in printed and "FAILED" not in printed
    assert (tmp_path / "drive" / "drive.png").is_file()


def _status(seated: int, excursion_m: float, tension_N: float, held_N: float, pin: int = 7
            ) -> DerailmentStatus:
    """A check's status: slack when the least tension's peak over the window ``held_N`` [N]
    is below 1 kN, whatever the least tension at the check ``tension_N`` [N]."""
    return DerailmentStatus(
        sprocket_disengaged=seated < 2, links_off_envelope=excursion_m > 0.1,
        slack_strand=held_N < 1000.0, max_envelope_excursion_m=excursion_m,
        min_upper_strand_tension_N=tension_N, held_upper_strand_tension_N=held_N,
        seated_pins=seated, worst_envelope_pin=pin, worst_envelope_strand="lower run",
        worst_envelope_xz_m=(-1.0, 0.05), min_upper_strand_pin=30)


def test_table_and_columns_of_hand_written_checks() -> None:
    """Four checks at 0.1, 0.2, 0.3, 0.4 s (rows 99, 199, 299, 399 of 450 steps); at 0.3 s
    one pin reads 300 N at the check but the strand rose to 3 kN in the window: not slack,
    and not the slack check's worst either (its worst is the lowest peak, 0.4 s's)."""
    statuses = [_status(9, 0.02, 4000.0, 5000.0), _status(1, 0.15, 800.0, 900.0, pin=41),
                _status(8, 0.12, 300.0, 3000.0), _status(9, 0.03, 600.0, 700.0)]
    table = derailment_table([0.1, 0.2, 0.3, 0.4], statuses, LIMITS)
    slack = table["slack_strand"]
    assert "1000 N" in slack["fails_when"] and "0.1 s" in slack.pop("fails_when")
    assert slack == {
        "threshold": 1000.0, "window_s": 0.1, "failing_checks": 2, "first_s": 0.2,
        "last_s": 0.4,
        "at_first": {"t_s": 0.2, "held_tension_N": 900.0, "tension_N": 800.0, "pin": 30,
                     "strand": "upper"},
        "worst": {"t_s": 0.4, "held_tension_N": 700.0, "tension_N": 600.0, "pin": 30,
                  "strand": "upper"}}
    envelope = table["links_off_envelope"]
    assert (envelope["failing_checks"], envelope["first_s"], envelope["last_s"]) == (2, 0.2, 0.3)
    assert envelope["worst"] == {"t_s": 0.2, "excursion_m": 0.15, "pin": 41,
                                 "strand": "lower run", "x_m": -1.0, "z_m": 0.05}
    sprocket = table["sprocket_disengaged"]
    assert (sprocket["failing_checks"], sprocket["first_s"], sprocket["last_s"]) == (1, 0.2, 0.2)
    assert sprocket["worst"] == {"t_s": 0.2, "seated_pins": 1}
    derailed = table["derailed"]
    assert (derailed["failing_checks"], derailed["first_s"], derailed["last_s"]) == (3, 0.2, 0.4)
    assert derailed["worst"]["failing"] == ["slack_strand", "links_off_envelope",
                                            "sprocket_disengaged"]
    quiet = derailment_table([0.1], [_status(9, 0.02, 4000.0, 4500.0)], LIMITS)
    assert all(quiet[k]["first_s"] is None and quiet[k]["failing_checks"] == 0 for k in CHECKS)
    assert json.loads(json.dumps(table)) == table    # plain JSON: null, not NaN

    columns = derailment_columns([99, 199, 299, 399], statuses, 450)
    assert set(columns) == set(COLUMNS)
    seated = columns["sprocket_seated_pins"]
    assert np.isnan(seated[:99]).all()
    np.testing.assert_array_equal(seated[99:199], 9.0)
    np.testing.assert_array_equal(seated[199:299], 1.0)
    np.testing.assert_array_equal(seated[399:], 9.0)
    np.testing.assert_array_equal(columns["slack_strand"][[99, 199, 299, 449]], [0, 1, 0, 1])
    np.testing.assert_array_equal(columns["upper_strand_tension_held_N"][[299, 449]],
                                  [3000.0, 700.0])
    assert columns["envelope_worst_pin"][250] == 41.0
    assert np.isnan(derailment_columns([], [], 50)["derailed"]).all()


def _steps(plant: TrackPlant, element: TensionerElement, speed_m_s: float, ramp_s: float,
           seconds: float) -> dict[str, np.ndarray]:
    """Drive ``plant`` with ``element`` at ``speed_m_s`` [m/s] (ramped over ``ramp_s`` [s])
    for ``seconds`` [s]; after every step: the upper strand's least and mean pin tension
    [N] (``least``, ``mean``), how long the least has stayed below the slack tension at
    the window's samples (``spell`` [s]), the slack verdict (``slack``) and the reading it
    takes, the least tension's peak over the window's samples (``held`` [N]), and the
    plant's step count (``count``)."""
    rows = []
    for _ in range(round(seconds / 1e-3)):
        plant.apply(StepInputs(speed_m_s * min(1.0, plant.time_s / ramp_s), 0.0, 0.0,
                               math.nan))
        plant.step(element)
        tension = plant.pin_tensions_N()[plant.upper_strand_pins()]
        s = plant.derailment()
        rows.append((tension.min(), tension.mean(), plant.slack_duration_s, s.slack_strand,
                     s.held_upper_strand_tension_N, plant.step_count))
    return dict(zip(("least", "mean", "spell", "slack", "held", "count"), np.array(rows).T,
                    strict=True))


def _longest_run_s(below: np.ndarray) -> float:
    """The longest run of True in ``below``, one entry per 1 ms step [s]."""
    longest = run = 0
    for b in below:
        run = run + 1 if b else 0
        longest = max(longest, run)
    return longest * 1e-3


def test_a_tooths_compression_of_one_pin_on_m113_is_not_a_slack_strand() -> None:
    """M113 (10 teeth, 154 mm pitch, bushed pins) driven to 3 m/s in 1 s, 1.4 s: as teeth
    engage, an upper-strand pin is pushed into compression (measured: least pin tension
    -2.0 kN at 1.24 s, 42 steps below 1 kN in spells of at most 17 ms; 4 of the 140
    samples, one every 10 ms, fall in one, at most 2 in a row) while the strand holds
    4.9 kN or more on mean. One instant's least tension would call it slack; the strand is
    not, and no step's verdict says it is."""
    plant = load_plant(machine="m113")
    r = _steps(plant, PassiveTensioner.from_params(plant.params), 3.0, 1.0, 1.4)
    assert r["least"].min() < 0.0                  # a pin in compression ...
    assert r["mean"].min() > 3.0 * SLACK_N         # ... in a tensioned strand
    assert 0.0 < _longest_run_s(r["least"] < SLACK_N) < WINDOW_S / 2   # briefly, in spells
    assert 0.0 < r["spell"].max() < WINDOW_S / 2   # some samples see one, none the window
    assert not r["slack"].any()
    held = r["held"][round(WINDOW_S / 1e-3):]      # from the first full window on
    assert held.min() > 3.0 * SLACK_N


def test_a_strand_left_at_half_a_kilonewton_hangs_and_is_slack(plant) -> None:
    """LF1352's idler pushed at a constant 1 kN (its strands' share F/2.0 = 0.5 kN, below
    the 1 kN slack tension), driven to 1.5 m/s in 0.5 s, 1 s: the strand hangs on its
    weight as a whole (measured: mean pin tension 0.62 kN over the last 0.1 s, its least
    pin below 1 kN at every step of the last 0.54 s, at every sample of the last 0.6 s);
    every check from 0.6 s on calls it slack, and the verdict is the window's reading at
    every step."""
    r = _steps(plant, ConstantForce(1e3, 2e4), 1.5, 0.5, 1.0)
    window = round(WINDOW_S / 1e-3)
    assert r["mean"][-window:].mean() < SLACK_N and r["least"][-window:].max() < SLACK_N
    assert r["spell"][-1] > 3 * WINDOW_S and _longest_run_s(r["least"] < SLACK_N) > 0.5
    checks = r["slack"][window - 1::window]        # at 0.1, 0.2, .. 1.0 s
    assert checks[5:].all()
    np.testing.assert_array_equal(r["slack"], r["held"] < SLACK_N)
    np.testing.assert_array_equal(r["slack"], r["spell"] >= WINDOW_S - 1e-9)


def test_the_window_samples_every_10th_step_of_the_plants_count(plant) -> None:
    """The slack window reads the strand after every 10th step of the plant's step count
    (``SLACK_SAMPLE_S`` = 10 ms, 10 samples in the 0.1 s window): its spell, peak and
    verdict change at those steps only. Clearing the window restarts the count, so a
    run that clears it samples at the same steps whatever came before (LF1352 at 1 kN, as
    above, then again from the state 0.23 s in, where the first run was first slack)."""
    sample = round(TrackPlant.SLACK_SAMPLE_S / 1e-3)
    assert (sample, plant.slack_sample_steps, plant.slack_window_samples) == (10, 10, 10)
    assert plant.step_count == 0
    r = _steps(plant, ConstantForce(1e3, 2e4), 1.5, 0.5, 0.5)
    np.testing.assert_array_equal(r["count"], np.arange(1, 501))
    for key in ("spell", "held", "slack"):
        changed = np.nonzero(r[key][1:] != r[key][:-1])[0] + 2   # steps where it changed
        assert len(changed) and not (changed % sample).any(), key
    assert r["slack"].any() and r["spell"].max() >= WINDOW_S
    # cleared mid-run (not on a sample step): the count restarts at 0 with an empty window
    plant.run(ConstantForce(1e3, 2e4), 0.005, 1.5)
    assert plant.step_count == 505
    plant.clear_slack_window()
    assert plant.step_count == 0 and plant.slack_duration_s == 0.0
    s = plant.derailment()
    assert not s.slack_strand and s.held_upper_strand_tension_N == math.inf
    plant.run(ConstantForce(1e3, 2e4), 0.009, 1.5)
    assert plant.slack_duration_s == 0.0                   # no sample in 9 steps
    plant.run(ConstantForce(1e3, 2e4), 0.001, 1.5)
    assert plant.slack_duration_s == TrackPlant.SLACK_SAMPLE_S   # the 10th: one, slack
    plant.run(ConstantForce(1e3, 2e4), 0.09, 1.5)
    assert plant.slack_duration_s == pytest.approx(WINDOW_S) and plant.derailment().slack_strand


def test_the_help_and_the_fmus_description_state_the_plants_slack_rule(capsys) -> None:
    """``trackmj drive --help`` and the native FMU's slack_strand say the threshold and
    window the plant uses."""
    with pytest.raises(SystemExit):
        main(["drive", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    sample_ms = f"{TrackPlant.SLACK_SAMPLE_S * 1e3:g} ms"
    assert (f"below {SLACK_N / 1e3:g} kN at every {sample_ms} sample of the {WINDOW_S:g} s "
            "up to the check") in help_text
    (slack,) = [v for v in OUTPUTS if v.name == "slack_strand"]
    assert (f"below {SLACK_N:g} N at every {sample_ms} sample of the last {WINDOW_S:g} s"
            in slack.description)


def test_a_pin_pushed_200_mm_below_the_ground_run_is_200_mm_off_its_envelope(plant) -> None:
    """Move the first chain (links 0..) 0.2 m down at home: the worst pin is one of its pins,
    0.2 m outside the envelope (the ground run is straight and horizontal), not in a
    strand, seen where it was put."""
    home_z = plant.pins_layout_frame()[:4, 1]
    m = plant.model
    plant.data.qpos[m.jnt_qposadr[m.joint("link_00_z").id]] -= 0.2
    mujoco.mj_forward(m, plant.data)
    s = plant.derailment()
    assert s.links_off_envelope and not s.slack_strand and not s.sprocket_disengaged
    assert s.worst_envelope_pin in range(4)
    assert s.max_envelope_excursion_m == pytest.approx(0.2, abs=0.003)
    assert s.worst_envelope_strand == "other"
    assert s.worst_envelope_xz_m[1] == pytest.approx(home_z[s.worst_envelope_pin] - 0.2,
                                                     abs=1e-3)
    assert s.seated_pins >= 2 and plant.pin_strand(s.min_upper_strand_pin) == "upper"


def test_drive_model_is_the_parameter_toml_and_mjcf_the_model_file(tmp_path, capsys) -> None:
    """A model TOML with a 6 kN preload (lf1352's is 13 kN): the idler force follows the
    passive law of that file, F = 6000 N − 1e6 N/m · (stroke − 0.05 m) − 1.4e4 N·s/m · v,
    the spring at the stroke the step starts from (the row before), the damper at the
    velocity it ends with."""
    text = (ROOT / "models" / "lf1352.toml").read_text()
    assert "preload_N = 13000.0" in text
    soft = tmp_path / "soft.toml"
    soft.write_text(text.replace("preload_N = 13000.0", "preload_N = 6000.0"))
    code, _, m, c, _ = _drive(tmp_path, capsys, "--model", str(soft), "--speed", "0",
                              "--duration", "0.3")
    assert code == 0 and m["model_file"] == str(soft) and m["preload_N"] == 6000.0
    law = 6000.0 - 1.0e6 * (c["stroke_m"][:-1] - 0.05) - 1.4e4 * c["stroke_velocity_m_s"][1:]
    np.testing.assert_allclose(c["idler_force_N"][1:], law, atol=0.5)
    assert 5.0e3 < c["idler_force_N"].mean() < 6.5e3

    out = tmp_path / "mjcf"
    assert main(["drive", "--mjcf", str(ROOT / "models" / "lf1352_scene.xml"), "--speed", "0",
                 "--duration", "0.2", "--out", str(out)]) == 0
    committed = json.loads((out / "metrics.json").read_text())
    assert committed["mjcf_file"].endswith("lf1352_scene.xml")
    assert committed["steady"]["idler_force_mean_N"] > 9.0e3    # the 13 kN machine


def test_params_is_refused_with_what_replaced_it(capsys) -> None:
    for command in (["drive"], ["model", "info"], ["model", "generate"]):
        with pytest.raises(SystemExit) as exc:
            main([*command, "--params", "x.toml"])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert "--model FILE" in err and "--mjcf FILE" in err


def test_model_generate_prints_every_file_it_wrote(tmp_path, capsys) -> None:
    out = tmp_path / "mine.xml"
    assert main(["model", "generate", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    wrote = [Path(line.split()[1]) for line in printed.splitlines()
             if line.startswith("wrote ")]
    assert sorted(p.name for p in wrote) == ["mine.xml", "mine_scene.xml"]
    assert all(p.is_file() for p in wrote)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.xml", "mine_scene.xml"]


def test_model_info_explains_the_sag_against_the_catenary(capsys) -> None:
    """M113 has no return rollers: its upper strand rests on the road wheels' tops, so it
    sags less than a free catenary; the line says what holds it."""
    assert main(["model", "info", "--machine", "m113"]) == 0
    printed = capsys.readouterr().out
    span = next(line for line in printed.splitlines() if line.startswith("upper span"))
    sag, catenary = (float(v) for v in re.findall(
        r"sag at home ([\d.]+) mm .*catenary at the home tension ([\d.]+) mm", span)[0])
    assert sag < catenary
    assert "rests on road_wheel_" in span
    w = 18.02 / 0.154 * 9.81 / 1e3      # m113.toml: link 18.02 kg, pitch 0.154 m
    assert f"w {w:.2f} kN/m" in printed


def test_drive_writes_its_figure_by_default_one_folder_per_input(tmp_path, monkeypatch,
                                                                 capsys) -> None:
    """Without --out a drive still leaves its result and figure, under runs/ named by the
    machine and speed; another preload goes to another folder, the same inputs replace."""
    monkeypatch.chdir(tmp_path)
    for preload in ("9e3", "1.1e4", "9e3"):
        assert main(["drive", "--speed", "1", "--duration", "0.3", "--preload", preload]) == 0
    folders = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len(folders) == 2 and all(f.startswith("drive-lf1352-1mps-") for f in folders)
    for folder in folders:
        assert (tmp_path / "runs" / folder / "drive.png").is_file()
    assert "wrote runs/drive-lf1352-1mps-" in capsys.readouterr().out


def test_a_closed_loop_run_checks_derailment_as_drive_does(tmp_path, capsys) -> None:
    """``trackmj run`` (W1, LF1352, 16 s) checks the track every 0.1 s as ``drive`` does:
    160 checks in metrics.json, none failing in a healthy run, each check's worst sample
    inside its limit (the upper strand above 1 kN, no pin 100 mm off its envelope, at least
    two pins seated), and the summary says so."""
    out = tmp_path / "run"
    code = main(["run", "W1", "--duration", "16", "--out", str(out)])
    printed = capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())["metrics"]
    assert code == 0
    assert metrics["derailment_checks"] == 160
    assert metrics["derailment_checks_failed"] == 0
    table = metrics["derailment"]
    assert set(table) == set(CHECKS)
    assert table["slack_strand"]["worst"]["tension_N"] > table["slack_strand"]["threshold"]
    assert (table["links_off_envelope"]["worst"]["excursion_m"]
            < table["links_off_envelope"]["threshold"])
    assert (table["sprocket_disengaged"]["worst"]["seated_pins"]
            >= table["sprocket_disengaged"]["threshold"])
    assert "derailment         0 of 160 checks failed (every 0.1 s)" in printed


def _readout(t_s: float) -> Readout:
    """A readout at ``t_s`` [s] (the observer reads only the time)."""
    return Readout(t_s, *([math.nan] * (len(Readout._fields) - 1)))


def test_the_closed_loop_observer_sees_a_track_go_slack(plant) -> None:
    """The run's observer on a standing track whose tensioner pushes 300 N: the upper strand
    hangs on its own weight, below the 1 kN slack limit, and its checks say so from the
    first on."""
    checks = DerailmentChecks(plant)
    element = ConstantForce(300.0, 2e4)
    for k in range(1000):
        plant.step(element)
        checks.on_step(k, _readout(plant.time_s), Command(0, 0.0, None))
    metrics = checks.metrics()
    assert metrics["derailment_checks"] == 10
    slack = metrics["derailment"]["slack_strand"]
    assert slack["failing_checks"] >= 5 and slack["worst"]["tension_N"] < 1000.0


def test_model_info_and_drive_give_the_settled_idler_force_beside_the_preload(
        tmp_path, capsys) -> None:
    """The preload holds at the layout stroke; compact3's track settles 3.1 mm further out,
    where its 1 MN/m spring has lost ~3 kN. model info and drive print that settled force
    and stroke beside the preload, and they are what the plant does standing; the static
    strand tension is the settled force's, and the settled strand carries it."""
    from trackmj.machines.track_plant import load_plant
    from trackmj.ports import StepInputs
    from trackmj.track.plant import PassiveTensioner

    assert main(["model", "info", "--machine", "compact3"]) == 0
    printed = capsys.readouterr().out
    (line,) = [ln for ln in printed.splitlines() if ln.startswith("tensioner ")]
    preload, ref, settled, stroke = (float(v) for v in re.search(
        r"preload ([\d.]+) kN at the layout stroke ([\d.]+) mm; settled ([\d.]+) kN at "
        r"([\d.]+) mm", line).groups())
    assert (preload, ref) == (13.0, 40.0)
    plant = load_plant(machine="compact3")
    passive = PassiveTensioner.from_params(plant.params)
    for _ in range(200):                       # standing 0.2 s at home
        plant.apply(StepInputs(0.0, 0.0, 0.0, math.nan))
        plant.step(passive)
    assert plant.idler_force_N / 1e3 == pytest.approx(settled, rel=0.01)
    assert plant.stroke_m * 1e3 == pytest.approx(stroke, abs=0.1)
    assert settled < 0.85 * preload            # the gap is real, not rounding
    (strand,) = [ln for ln in printed.splitlines() if ln.startswith("static strand tension")]
    static = float(re.search(r"([\d.]+) kN at the settled idler force ([\d.]+) kN",
                             strand).group(1))
    upper = plant.pin_tensions_N()[plant.upper_strand_pins()].mean() / 1e3
    assert static == pytest.approx(upper, rel=0.1)

    code, out, m, c, _ = _drive(tmp_path, capsys, "--machine", "compact3", "--speed", "0",
                                "--duration", "0.2")
    assert code == 0
    assert line.split(maxsplit=1)[1].startswith(
        out.split("tensioner", 1)[1].splitlines()[0].strip())
    assert m["home_idler_force_N"] == pytest.approx(c["idler_force_N"][0], abs=20.0)
    assert m["home_settled"] is True


def test_model_info_warns_of_return_rollers_the_settled_strand_hangs_clear_of(capsys) -> None:
    """LF1352's rollers lowered to 0.325 m (above the road wheels, which the loader checks):
    the settled upper strand sags 52 mm and still hangs clear of both. model info says so
    in one stderr line naming each roller, its x_m entry and the z_m that placed it (here
    the --set option); the shipped layout, both rollers carrying, says nothing."""
    assert main(["model", "info", "--set", "model.return_rollers.z_m=0.325"]) == 0
    captured = capsys.readouterr()
    assert "return_roller" not in captured.out.split("wraps", 1)[1].splitlines()[0]
    assert captured.err.count("\n") == 1
    assert captured.err.startswith(
        "trackmj: return_roller_1 (lf1352.toml [return_rollers].x_m[0] = -0.4 m), "
        "return_roller_2 (lf1352.toml [return_rollers].x_m[1] = 0.45 m) carry no track at "
        "home: the settled upper strand hangs clear above them at --set "
        "model.return_rollers.z_m = 0.325 m")
    assert main(["model", "info"]) == 0
    assert capsys.readouterr().err == ""


def test_keys_say_the_tooth_count_is_the_pins_seated_per_turn(capsys) -> None:
    """A 21-tooth excavator sprocket engages every other pin: entered as 21 it builds a
    637 mm pitch radius at 190 mm pitch; the key's doc says to enter the pins it seats."""
    assert main(["keys", "model"]) == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines()
               if ln.startswith("model.sprocket.tooth_count:")]
    assert "pins seated per turn" in line and "every other pin" in line and "(11 for 21)" in line


def test_a_nominal_tension_typed_in_kN_is_refused_naming_the_key_and_a_plausible_value(
        capsys) -> None:
    """nominal_tension_N = 15 (meant as 15 kN) on LF1352: the idler, identified at 12-15 N,
    would hold its strands at 6 N, slack on their own weight. The run refuses before the
    identification, in one line naming the --set option, the strand tension, and the values
    that would hold the strand (the least, and 15000 as the kN reading). A machine without
    nominal_tension_N (identified at its preload) gets the same line naming preload_N."""
    assert main(["run", "W1", "--set", "model.tensioner.nominal_tension_N=15"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert re.search(r"--set model\.tensioner\.nominal_tension_N = 15 N: the idler, "
                     r"identified at 0\.8-1\.0 x it, holds the strands at 6\.0\d* N, below the "
                     r"1000 N under which the upper strand hangs slack on its own weight "
                     r".*; use nominal_tension_N >= \d+ N \(15000 if 15 was meant in kN\)$",
                     err.strip()), err


@pytest.mark.parametrize("machine, envelope_m, seat_m", [
    ("lf1352", 0.100, 0.0117), ("compact3", 0.120, 0.0141), ("m113", 0.2053, 0.0244)])
def test_each_machines_limits_are_its_own_tracks(machine: str, envelope_m: float,
                                                 seat_m: float) -> None:
    """The limits scale with the track: 4/3 of the pitch (75 / 90 / 154 mm) and 0.3 of the
    tooth lift. The lift, measured on the compiled sprocket (a tooth capsule's centre
    radius + its radius + the pin geom's radius − the pitch radius), is the one the limits
    take (39 / 47 / 81.3 mm). At home the wrap seats at least two pins."""
    plant = load_plant(machine=machine)
    m, p = plant.model, plant.params
    limits = plant.limits
    assert limits.envelope_threshold_m == pytest.approx(envelope_m, abs=5e-4)
    assert limits.seat_tolerance_m == pytest.approx(seat_m, abs=5e-4)
    tooth = m.geom("sprocket_tooth_00").id
    pin_radius = float(m.geom_size[plant.configuration()["pin_geom"][0], 0])
    lift = (math.hypot(m.geom_pos[tooth, 0], m.geom_pos[tooth, 2]) + m.geom_size[tooth, 0]
            + pin_radius - p.sprocket_pitch_radius_m)
    assert lift == pytest.approx(DerailmentLimits.tooth_lift_m(p), abs=1e-6)
    assert plant.seated_sprocket_pins() >= limits.min_seated_pins


@pytest.mark.slow
def test_m113s_slack_lower_run_on_a_2_m_s_start_is_inside_its_own_bound(tmp_path,
                                                                          capsys) -> None:
    """M113 from rest to 2 m/s in 1 s (passive tensioner): the start's traction stretches
    the tight upper strand into the slack lower run behind the front sprocket, which sags
    ~100 mm off its home envelope at 0.6 s (models/README.md; the ramp is 1 s from a 4 s
    drive on, a quarter of a shorter one). That is more than LF1352's 100 mm
    bound but under M113's own, 4/3 of its 154 mm pitch; the drive is healthy."""
    code, printed, m, _, _ = _drive(tmp_path, capsys, "--machine", "m113", "--speed", "2",
                                    "--duration", "4")
    envelope = m["derailment"]["links_off_envelope"]
    assert code == 0 and m["derailment_checks_failed"] == 0, printed
    assert envelope["threshold"] == pytest.approx(4.0 / 3.0 * 0.154)
    assert 0.08 < envelope["worst"]["excursion_m"] < envelope["threshold"]
    assert envelope["worst"]["strand"] == "lower run"


HIGH_DRIVE = {"sprocket.z_m": 0.6, "track.link_count": 49}
"""compact3 with its sprocket raised 0.3 m above its home height, 0.38 m above the idler
(a high-drive layout, as on elevated-sprocket dozers), two links longer for the loop."""


@pytest.mark.parametrize("machine, overrides", [
    ("lf1352", None), ("compact3", None), ("m113", None), ("compact3", HIGH_DRIVE)])
def test_the_upper_strand_runs_from_the_idler_to_the_sprocket(machine, overrides) -> None:
    """At home the pins the slack check watches span the free strand between the idler's
    top and the sprocket's, to within a wheel radius at each end, on every shipped machine
    and on a high-drive layout. Counting only the pins above the higher wheel centre, the
    high-drive compact3's strand was its 9 pins nearest the sprocket (x −0.94 to −0.28 m of
    a strand reaching the idler at 0.80 m): its slack check watched a wrap, not the span."""
    plant = load_plant(machine=machine, overrides=overrides)
    p = plant.params
    x = plant.pin_positions()[plant.upper_strand_pins(), 0]
    ends = sorted((p.sprocket.x_m, p.idler.x_m))
    reach = max(p.sprocket_pitch_radius_m, p.idler.radius_m)
    assert x.min() <= ends[0] + reach and x.max() >= ends[1] - reach
    # and every upper pin is on top: above the lower of the two wheel centres
    z = plant.pin_positions()[plant.upper_strand_pins(), 1]
    assert z.min() > min(p.sprocket.z_m, p.idler.z_m)
