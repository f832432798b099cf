"""Calibrate W3's rear-hitch pulses to the hold-mode idler-load changes the scenario targets.

For each ``[[load_pulses]]`` entry of the scenario, this finds the rear-hitch force whose
hold-mode idler-load change equals ``delta_N`` (see :mod:`trackmj.study.w3_hitch`). It prints
the values to copy into the file's ``hitch_N`` and the change each one achieves.
Run: ``python experiments/calibrate_w3.py [scenario, default W3]``.
"""

from __future__ import annotations

import sys

from trackmj.host import machine
from trackmj.scenarios.load import load_scenario
from trackmj.study.w3_hitch import calibrate_hitch


def main() -> None:
    scenario = load_scenario(sys.argv[1] if len(sys.argv) > 1 else "W3")
    print(f"machine: {machine()}")
    for i, pulse in enumerate(scenario.load_pulses):
        hitch, achieved = calibrate_hitch(scenario, pulse.delta_N, pulse.pull_angle_deg,
                                          rise_s=pulse.rise_s)
        print(f"pulse {i}: target {pulse.delta_N / 1e3:+.2f} kN at {pulse.pull_angle_deg:g} deg"
              f" -> hitch_N = {hitch:.0f} (achieved {achieved / 1e3:+.3f} kN; "
              f"stored {pulse.hitch_N:.0f})")


if __name__ == "__main__":
    main()
