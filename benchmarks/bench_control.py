"""Control benchmark: 30 s closed loop (W1-like: 12 -> 15 kN step at 3 s, ramp +0.05 kN/s from
15 s, W3-like +2 kN reference pulse 6-8 s) on the reduced plant, one core, no JIT.
Prints median/p99/max wall time per call of NMPC, LMPC, PID, EKF and UKF, the number of
controller calls over 5 ms, the garbage-collector pauses inside the loop, and the machine.

Run: ``taskset -c 0 python benchmarks/bench_control.py``; the NMPC's SQP iterations and the
LMPC's OSQP settings can be overridden (e.g. ``--sqp-iter 3 --qp-max-iter 4000 --qp-tol
1e-5``; the NMPC solves its condensed QPs exactly), and ``--no-gc`` disables the cyclic
garbage collector during the loops.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import subprocess
import time

import numpy as np

from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
from trackmj.control.lmpc import LinearMpc
from trackmj.control.model import ReducedModel
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.pid import PidController
from trackmj.sim.control_plant import nominal_plant_params, packaged_control
from trackmj.sim.reduced import run_closed_loop, step_metrics


def reference(t: float) -> float:
    """W1 + W3-like reference [N]."""
    f = 12e3 if t < 3.0 else 15e3
    if 6.0 <= t < 8.0:
        f += 2e3
    if t >= 15.0:
        f += 50.0 * (t - 15.0)
    return f


class GcPauses:
    """Wall time [s] of every garbage-collector run while installed (gc.callbacks)."""

    def __init__(self) -> None:
        self.pauses: list[float] = []
        self._t0 = 0.0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._t0 = time.perf_counter()
        else:
            self.pauses.append(time.perf_counter() - self._t0)


@contextlib.contextmanager
def timed(cls: type, method: str, times: list[float]):
    """Record the wall time [s] of every call of ``cls.method`` while inside the block."""
    original = getattr(cls, method)

    def wrapper(self, *args, **kwargs):
        start = time.perf_counter()
        try:
            return original(self, *args, **kwargs)
        finally:
            times.append(time.perf_counter() - start)

    setattr(cls, method, wrapper)
    try:
        yield
    finally:
        setattr(cls, method, original)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sqp-iter", type=int, help="SQP iterations per period (NMPC)")
    ap.add_argument("--qp-max-iter", type=int, help="OSQP iteration cap (LMPC)")
    ap.add_argument("--qp-tol", type=float, help="OSQP eps_abs = eps_rel (LMPC)")
    ap.add_argument("--no-gc", action="store_true", help="gc.disable() during the loops")
    ap.add_argument("--duration", type=float, default=30.0, help="loop length [s]")
    args = ap.parse_args()
    cfg = packaged_control()
    over = {
        k: v
        for k, v in (
            ("max_iter", args.sqp_iter),
            ("qp_max_iter", args.qp_max_iter),
            ("qp_tolerance", args.qp_tol),
        )
        if v is not None
    }
    mpc = dataclasses.replace(cfg.mpc, **over)
    plant = nominal_plant_params(control_config=cfg)
    model = ReducedModel(plant)
    lscpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines()
    print("\n".join(lscpu[:12]))
    print(f"MPC settings: {mpc}; gc {'disabled' if args.no_gc else 'enabled'}")
    for name, ctrl, est in (
        ("NMPC", NonlinearMpc(model, cfg.controller, mpc), "ekf"),
        ("LMPC", LinearMpc(model, cfg.controller, mpc), "ekf"),
        ("PID", PidController(model, cfg.controller, cfg.pid), "ekf"),
        ("NMPC+UKF", NonlinearMpc(model, cfg.controller, mpc), "ukf"),
    ):
        gc_log = GcPauses()
        gc.collect()
        gc.callbacks.append(gc_log)
        if args.no_gc:
            gc.disable()
        ctrl_times: list[float] = []
        est_times: list[float] = []
        est_cls = ExtendedKalmanFilter if est == "ekf" else UnscentedKalmanFilter
        try:
            with timed(type(ctrl), "__call__", ctrl_times), timed(est_cls, "step", est_times):
                res = run_closed_loop(cfg, plant, ctrl, reference, args.duration, estimator=est,
                                      seed=3)
        finally:
            gc.enable()
            gc.callbacks.remove(gc_log)
        ct, et = np.array(ctrl_times) * 1e3, np.array(est_times) * 1e6
        gp = np.array(gc_log.pauses or [0.0]) * 1e3
        rmse = np.sqrt(np.mean((res.force - res.ref) ** 2))
        m = step_metrics(res, 3.0, 15e3)
        print(
            f"{name:9s} controller median {np.median(ct):.3f} p99 {np.percentile(ct, 99):.3f} "
            f"max {ct.max():.3f} ms (>5 ms: {int((ct > 5).sum())}, argmax t = "
            f"{0.01 * int(ct.argmax()):.2f} s) | {est.upper()} median {np.median(et):.1f} "
            f"max {et.max():.1f} us | gc runs {len(gc_log.pauses)} max {gp.max():.2f} ms | "
            f"tension RMSE {rmse:.0f} N, est. RMSE {m['est_rmse_N']:.0f} N, "
            f"switches {res.switches}, fallbacks {getattr(ctrl, 'fallbacks', 0)}"
        )


if __name__ == "__main__":
    main()
