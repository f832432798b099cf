"""Calibrate W3's rear-hitch pulses on the shipped machines and commit them.

For each ``[[load_pulses]]`` entry of W3 (targets relative to the machine's nominal tension),
this finds the rear-hitch force whose hold-mode idler-load change equals the target on the
machine (:mod:`trackmj.sim.w3_hitch`: secant on hold-mode tp runs from LF1352's force per
side weight, within the drawbar capacity mu·W) and writes it, with the hashes of the inputs,
to ``experiments/W3_calibration.toml`` (the table of that machine; the others are kept).
LF1352 is calibrated first when all machines are: its entry starts the others' secants.
It prints what it measured and on which host.
Run: ``python experiments/calibrate_w3.py [--machine NAME]`` (default: every shipped machine).
"""

from __future__ import annotations

import argparse
import fcntl
import json
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from trackmj.host import machine as host_machine
from trackmj.io import write_text_atomic
from trackmj.machines.assembly import names
from trackmj.sim.setup import prepare
from trackmj.sim.w3_hitch import (
    CALIBRATION_FILE,
    REFERENCE_MACHINE,
    CalibrationEntry,
    Rig,
    calibrate,
    calibrated_indices,
    committed_entries,
    committed_file,
    entry_record,
    input_hashes,
)

SCENARIO = "W3"
HEADER = """\
# W3's rear-hitch forces per shipped machine: the hitch force along the chain whose hold-mode
# idler-load change is W3's target (delta_rel x the machine's nominal tension), found by
# trackmj/sim/w3_hitch.py (secant on hold-mode tp runs; start: LF1352's force per side
# weight x this side weight; bounds: the drawbar capacity mu x side weight, Wong, Theory of
# Ground Vehicles, and 75 % of the static tipping force, ISO 10567; a target no force within
# them reaches is out of reach: the trial furthest towards it is applied, listed in
# out_of_reach with its measured change). Written by
# `python experiments/calibrate_w3.py [--machine NAME]`; not edited by hand. A run uses a
# table only while its hashes equal those of the run's inputs (the validated mechanics and
# hydraulics, the pulses, speed, initial force, terrain and method); otherwise it
# recalibrates (stderr says so) and caches the result for the user.
"""


def _toml_value(value: Any) -> str:
    """A TOML literal of a string, number or list of numbers."""
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def write_table(entries: dict[str, dict[str, Any]], path: Path = CALIBRATION_FILE) -> None:
    """Write the calibration file: ``[machine.NAME]`` per entry, keys in schema order."""
    keys = [k for k in CalibrationEntry.__dataclass_fields__ if k != "source"]
    lines = [HEADER]
    for name in sorted(entries, key=lambda n: (n != REFERENCE_MACHINE, n)):
        row = entries[name]
        lines.append(f"[machine.{name}]")
        lines.append(f"source = {_toml_value(row['source'])}")
        lines += [f"{k} = {_toml_value(row[k])}" for k in keys]
        lines.append("")
    write_text_atomic(path, "\n".join(lines))
    committed_entries(path)      # the file written must load


def committed_rows() -> dict[str, dict[str, Any]]:
    """The committed entries as the writer's rows, with their source texts."""
    file = committed_file()
    rows = {}
    for name, entry in file.machine.items():
        row = {k: getattr(entry, k) for k in CalibrationEntry.__dataclass_fields__}
        rows[name] = {k: list(v) if isinstance(v, tuple) else v for k, v in row.items()}
        rows[name]["source"] = file.sources.get(f"machine.{name}", "measured")
    return rows


def calibrate_machine(name: str, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Calibrate W3 on the shipped machine ``name`` (its own files) and print the result;
    the reference entry starting the secant is ``rows``' (the file's, or fresh)."""
    rig = Rig(prepare(SCENARIO, machine=name))
    scenario, params = rig.setup.scenario, rig.params
    ref = rows.get(REFERENCE_MACHINE)
    reference = (CalibrationEntry(**{k: tuple(v) if isinstance(v, list) else v
                                     for k, v in ref.items() if k != "source"})
                 if ref else None)
    measured = calibrate(scenario, rig, calibrated_indices(scenario), reference)
    record = entry_record(scenario, measured, input_hashes(scenario, rig))
    runs = sum(p.runs for p in measured.pulses.values())
    record["source"] = (f"measured: experiments/calibrate_w3.py (trackmj.sim.w3_hitch), "
                        f"{runs} trial runs for the calibrated pulses")
    print(f"{name}: nominal {params.nominal_tension_N / 1e3:g} kN, side weight "
          f"{measured.side_weight_N / 1e3:.2f} kN, drawbar capacity mu W = "
          f"{params.track.ground_friction:g} x {measured.side_weight_N / 1e3:.2f} = "
          f"{measured.drawbar_capacity_N / 1e3:.2f} kN; {measured.wall_s:.0f} s wall")
    for i, p in sorted(measured.pulses.items()):
        pulse = scenario.load_pulses[i]
        target = float(pulse.delta_N or math.nan)
        rel = target / params.nominal_tension_N
        horizontal = abs(p.hitch_N * math.cos(math.radians(pulse.pull_angle_deg)))
        print(f"  pulse {i}: target {target / 1e3:+.3f} kN ({rel:+.4f} x nominal) at "
              f"{pulse.pull_angle_deg:g} deg -> hitch_N = {p.hitch_N:+.0f} "
              f"({'tow' if p.hitch_N > 0 else 'push'}: {horizontal / 1e3:.2f} kN horizontal, "
              f"{p.hitch_N / measured.side_weight_N:+.4f} x side weight), "
              f"achieved {p.achieved_N / 1e3:+.3f} kN in {p.runs} runs")
        if p.out_of_reach:
            print(f"    {p.out_of_reach}")
    for i, reason in sorted(measured.refused.items()):
        print(f"  pulse {i}: refused: {reason}")
    return record


@contextmanager
def _exclusive(path: Path) -> Iterator[None]:
    """An exclusive ``flock`` on the directory of ``path`` (the file itself is replaced by
    each write, so a lock on it would not be shared by the next writer)."""
    fd = os.open(path.parent, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machine", choices=names(), help="one shipped machine (default: all)")
    args = parser.parse_args()
    print(f"host: {host_machine()}")
    rows = committed_rows()
    todo = [args.machine] if args.machine else sorted(
        names(), key=lambda n: (n != REFERENCE_MACHINE, n))
    for name in todo:
        record = calibrate_machine(name, rows)
        # read, merge and write as one step: another run's entries written meanwhile are kept
        # (two runs for different machines each wrote back the table they had read)
        with _exclusive(CALIBRATION_FILE):
            rows = committed_rows() | {name: record}
            write_table(rows)
    print(f"written: {CALIBRATION_FILE}")


if __name__ == "__main__":
    main()
