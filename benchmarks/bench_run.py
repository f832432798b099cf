"""End-to-end speed of ``trackmj run W1`` (tp, nmpc, ekf) and its split.

Runs the scenario twice in one process: once plain (real-time factor as users see it),
once with timing wrappers around the blocks (MuJoCo step, hydraulic plugin, sensors +
estimator, controller, logging) to split the wall time. The wrappers add ~1 µs per call.
Run: ``python benchmarks/bench_run.py [--duration 10]``.
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

from trackmj.control.estimators import ExtendedKalmanFilter
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.sensors import Sensors
from trackmj.hydraulics import HydraulicTensioner
from trackmj.machine import machine
from trackmj.plant import TrackPlant
from trackmj.results import TimeseriesRecorder
from trackmj.simulate import equivalent_idler, simulate

SPENT: dict[str, float] = defaultdict(float)
CALLS: dict[str, int] = defaultdict(int)


def _timed(cls: type, name: str, bucket: str) -> None:
    original = getattr(cls, name)

    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            SPENT[bucket] += time.perf_counter() - start
            CALLS[name if bucket.startswith("plant") else bucket] += 1

    setattr(cls, name, wrapper)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    args = parser.parse_args()
    equivalent_idler()   # identification is cached per process; keep it out of the timing
    start = time.perf_counter()
    plain = simulate("W1", duration=args.duration)
    total = time.perf_counter() - start
    for cls, name, bucket in ((TrackPlant, "step", "plant step (MuJoCo + plugin)"),
                              (HydraulicTensioner, "force_law", "hydraulic plugin"),
                              (HydraulicTensioner, "complete_step", "hydraulic plugin"),
                              (Sensors, "measure", "sensors + estimator"),
                              (ExtendedKalmanFilter, "step", "sensors + estimator"),
                              (NonlinearMpc, "__call__", "controller (NMPC)"),
                              (TimeseriesRecorder, "append", "logging"),
                              (HydraulicTensioner, "log", "logging")):
        _timed(cls, name, bucket)
    SPENT.clear()
    CALLS.clear()
    split = simulate("W1", duration=args.duration)
    loop = split.metrics["real_time_factor"]
    print(f"machine: {machine()}")
    print(f"trackmj run W1 (tp, nmpc, ekf), {args.duration:.0f} s simulated")
    print(f"  plain run: loop real-time factor {plain.metrics['real_time_factor']:.2f}x, "
          f"whole call {args.duration / total:.2f}x (incl. model load and 1 s settle)")
    wall = args.duration / loop
    # the plant also steps through the 1 s standing settle before the loop; scale the
    # MuJoCo share to the loop's steps (the plugin is not called while settling)
    loop_steps = round(args.duration / 1e-3)
    mujoco_only = ((SPENT["plant step (MuJoCo + plugin)"] - SPENT["hydraulic plugin"])
                   * loop_steps / CALLS["step"])
    rows = {"MuJoCo (mj_step + plant)": mujoco_only,
            **{k: v for k, v in SPENT.items() if k != "plant step (MuJoCo + plugin)"}}
    rows["other (loop, valve logic, signals)"] = wall - sum(rows.values())
    for name, seconds in rows.items():
        print(f"  {name:38s} {seconds / args.duration * 1e3:7.1f} ms per simulated s "
              f"({seconds / wall:5.1%})")


if __name__ == "__main__":
    main()
