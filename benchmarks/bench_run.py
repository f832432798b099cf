"""End-to-end speed of ``trackmj run W1`` (tp, nmpc, ekf) and its split.

Runs the scenario plain (real-time factor as users see it) and with timing wrappers around
the blocks (MuJoCo step, hydraulic plugin, sensors + estimator, controller, logging) to
split the wall time, each ``--repeat`` times; the best plain run and the split of the
fastest wrapped run are printed (the machine is shared: take the best of N). The wrappers'
own cost (measured on a no-op, ~0.5-1 us per call) is reported as its own row instead of
inflating "other". Run: ``python benchmarks/bench_run.py [--duration 10] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

from trackmj.control.estimators import ExtendedKalmanFilter
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.sensors import Sensors
from trackmj.host import machine
from trackmj.hydraulics import HydraulicTensioner
from trackmj.machines.idler import load_idler
from trackmj.sim.observers import Recorder
from trackmj.sim.run import simulate
from trackmj.track.plant import TrackPlant

SPENT: dict[str, float] = defaultdict(float)
CALLS: dict[str, int] = defaultdict(int)
BLOCKS = ((TrackPlant, "step", "plant step (MuJoCo + plugin)"),
          (HydraulicTensioner, "force_law", "hydraulic plugin"),
          (HydraulicTensioner, "complete_step", "hydraulic plugin"),
          (Sensors, "measure", "sensors + estimator"),
          (ExtendedKalmanFilter, "step", "sensors + estimator"),
          (NonlinearMpc, "__call__", "controller (NMPC)"),
          (Recorder, "on_step", "logging"),
          (HydraulicTensioner, "log", "logging"))


def _wrap(original, bucket: str, key: str):
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            SPENT[bucket] += time.perf_counter() - start
            CALLS[key] += 1

    return wrapper


def _wrapper_cost_s(calls: int = 200_000) -> float:
    """Extra wall time of one wrapped call over a plain one [s] (no-op function)."""
    def noop() -> None:
        return None

    wrapped = _wrap(noop, "calibration", "calibration")
    best = []
    for fn in (noop, wrapped):
        runs = []
        for _ in range(5):
            start = time.perf_counter()
            for _ in range(calls):
                fn()
            runs.append(time.perf_counter() - start)
        best.append(min(runs) / calls)
    SPENT.pop("calibration")
    CALLS.pop("calibration")
    return best[1] - best[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time [s]")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each kind (best kept)")
    args = parser.parse_args()
    load_idler()   # identification is cached per process; keep it out of the timing
    plain = []
    for _ in range(args.repeat):
        start = time.perf_counter()
        result = simulate("W1", duration=args.duration)
        plain.append((result.metrics["real_time_factor"], time.perf_counter() - start, result))
    loop_rtf, total, result = max(plain, key=lambda r: r[0])
    originals = {(cls, name): getattr(cls, name) for cls, name, _ in BLOCKS}
    for cls, name, bucket in BLOCKS:
        setattr(cls, name, _wrap(originals[cls, name], bucket,
                                 name if bucket.startswith("plant") else bucket))
    best = None
    for _ in range(args.repeat):
        SPENT.clear()
        CALLS.clear()
        rtf = simulate("W1", duration=args.duration).metrics["real_time_factor"]
        if best is None or rtf > best[0]:
            best = (rtf, dict(SPENT), dict(CALLS))
    for (cls, name), original in originals.items():
        setattr(cls, name, original)
    split_rtf, spent, calls = best
    m = result.metrics
    print(f"machine: {machine()}")
    print(f"trackmj run W1 (tp, nmpc, ekf), {args.duration:.0f} s simulated, best of "
          f"{args.repeat}")
    print(f"  plain run: loop real-time factor {loop_rtf:.2f}x, whole call "
          f"{args.duration / total:.2f}x (incl. model load and 1 s settle)")
    print(f"  NMPC solve median {1e3 * m['solve_time_median_s']:.3f} ms, max "
          f"{1e3 * m['solve_time_max_s']:.3f} ms; tension RMSE {m['rmse_N']:.0f} N, "
          f"fluctuation {m['fluctuation_N']:.0f} N, fallbacks {m['controller_fallbacks']:.0f}")
    wall = args.duration / split_rtf
    # the plant also steps through the 1 s standing settle before the loop; scale the
    # MuJoCo share to the loop's steps (the plugin is not called while settling)
    loop_steps = round(args.duration / 1e-3)
    # wrapper cost: top-level wrapped calls, plus the plugin's two wrapped calls nested in
    # each plant step (their cost lands in the plant step's time, not the plugin's)
    cost = _wrapper_cost_s()
    nested = calls["hydraulic plugin"] * cost
    mujoco_only = ((spent["plant step (MuJoCo + plugin)"] - spent["hydraulic plugin"] - nested)
                   * loop_steps / calls["step"])
    top_level = loop_steps + sum(calls[k] for k in calls if k not in ("step", "hydraulic plugin"))
    rows = {"MuJoCo (mj_step + plant)": mujoco_only,
            **{k: v for k, v in spent.items() if k != "plant step (MuJoCo + plugin)"},
            "timing wrappers (estimated)": top_level * cost + nested}
    rows["other (loop, valve logic, signals)"] = wall - sum(rows.values())
    print(f"  split run (wrapped): loop real-time factor {split_rtf:.2f}x")
    for name, seconds in rows.items():
        print(f"  {name:38s} {seconds / args.duration * 1e3:7.1f} ms per simulated s "
              f"({seconds / wall:5.1%})")


if __name__ == "__main__":
    main()
