"""Bare-model speed: wall time per 1 ms step driving at 1.5 m/s on flat ground.

Reports, in one run: the bare step, MuJoCo with the ground foundation (tensioner as a fixed
affine law set once), the plant's coupled step with the passive tensioner element (Python
port exchange every step), their ratio, the real-time factor, and MuJoCo's timer split
(collision vs constraint).
Run: ``python benchmarks/bench_model.py [--seconds 5]``.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
from driving import DrivingSnapshot

from trackmj.host import machine


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="simulated time per case")
    args = parser.parse_args()
    steps = round(args.seconds / 1e-3)

    snapshot = DrivingSnapshot()
    plant, element = snapshot.plant, snapshot.passive
    m, d = plant.model, plant.data

    def coupled_run() -> float:
        snapshot.restore()
        start = time.perf_counter()
        for _ in range(steps):
            plant.step(element)
        return (time.perf_counter() - start) / steps

    # alternate the two cases and keep each one's best of three (load noise only adds)
    bare_times, coupled_times = [], []
    for _ in range(3):
        bare_times.append(snapshot.bare_step_s(steps))
        timers = {name: d.timer[int(getattr(mujoco.mjtTimer, name))].duration / steps
                  for name in ("mjTIMER_STEP", "mjTIMER_POS_COLLISION", "mjTIMER_CONSTRAINT",
                               "mjTIMER_POS_KINEMATICS", "mjTIMER_POS_INERTIA")}
        ncon, nefc = d.ncon, d.nefc
        coupled_times.append(coupled_run())
    bare, coupled = min(bare_times), min(coupled_times)

    print(f"machine: {machine()}")
    print(f"model: nv {m.nv}, contacts {ncon}, constraint rows {nefc}, "
          f"{args.seconds:.1f} s simulated per case, best of 3")
    print(f"bare step              {bare * 1e6:8.1f} us/step   "
          f"real-time factor {1e-3 / bare:5.2f}x")
    print(f"  collision            {timers['mjTIMER_POS_COLLISION'] * 1e6:8.1f} us "
          f"({timers['mjTIMER_POS_COLLISION'] / timers['mjTIMER_STEP']:.0%})")
    print(f"  constraint solve     {timers['mjTIMER_CONSTRAINT'] * 1e6:8.1f} us "
          f"({timers['mjTIMER_CONSTRAINT'] / timers['mjTIMER_STEP']:.0%})")
    print(f"  kinematics+inertia   "
          f"{(timers['mjTIMER_POS_KINEMATICS'] + timers['mjTIMER_POS_INERTIA']) * 1e6:8.1f} us")
    print(f"plant.step (passive)   {coupled * 1e6:8.1f} us/step   real-time factor "
          f"{1e-3 / coupled:5.2f}x   ratio to bare {coupled / bare:.3f}")
    print(f"final speed {plant.chassis_velocity[0]:.3f} m/s, max pin gap "
          f"{plant.closure_error_m * 1e3:.3f} mm, warnings {plant.warning_count}, "
          f"finite {bool(np.isfinite(d.qpos).all())}")


if __name__ == "__main__":
    main()
