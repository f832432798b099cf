"""Control benchmark: 30 s closed loop (W1-like: 12 -> 15 kN step at 3 s, ramp +0.05 kN/s from
15 s, W3-like +2 kN reference pulse 6-8 s) on the reduced plant, one core, no JIT.
Prints median/max wall time per call of NMPC, PID, EKF and UKF, and the machine (lscpu).

Run: ``taskset -c 0 python benchmarks/bench_control.py``
"""

from __future__ import annotations

import subprocess

import numpy as np

from trackmj.control.loop import run_closed_loop, step_metrics
from trackmj.control.model import ReducedModel
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.params import load_config
from trackmj.control.pid import PidController


def reference(t: float) -> float:
    """W1 + W3-like reference [N]."""
    f = 12e3 if t < 3.0 else 15e3
    if 6.0 <= t < 8.0:
        f += 2e3
    if t >= 15.0:
        f += 50.0 * (t - 15.0)
    return f


def main() -> None:
    cfg = load_config()
    model = ReducedModel(cfg.plant)
    lscpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines()
    print("\n".join(lscpu[:12]))
    for name, ctrl, est in (
        ("NMPC", NonlinearMpc(model, cfg.controller, cfg.mpc), "ekf"),
        ("PID", PidController(model, cfg.controller, cfg.pid), "ekf"),
        ("NMPC+UKF", NonlinearMpc(model, cfg.controller, cfg.mpc), "ukf"),
    ):
        res = run_closed_loop(cfg, ctrl, reference, 30.0, estimator=est, seed=3)
        ct, et = res.controller_times * 1e3, res.estimator_times * 1e6
        rmse = np.sqrt(np.mean((res.force - res.ref) ** 2))
        m = step_metrics(res, 3.0, 15e3)
        print(
            f"{name:9s} controller median {np.median(ct):.3f} ms max {ct.max():.3f} ms | "
            f"{est.upper()} median {np.median(et):.1f} us max {et.max():.1f} us | "
            f"tension RMSE {rmse:.0f} N, est. RMSE {m['est_rmse_N']:.0f} N, "
            f"switches {res.switches}, fallbacks {getattr(ctrl, 'fallbacks', 0)}"
        )


if __name__ == "__main__":
    main()
