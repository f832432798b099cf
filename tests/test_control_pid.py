"""PID baseline on the same closed loop; figures reported beside the NMPC's."""

from trackmj.control.model import ReducedModel
from trackmj.control.pid import PidController
from trackmj.sim.control_plant import nominal_plant_params, packaged_control
from trackmj.sim.reduced import run_closed_loop, step_metrics

CFG = packaged_control()
PLANT = nominal_plant_params(control_config=CFG)


def test_pid_step_reaches_reference() -> None:
    pid = PidController(ReducedModel(PLANT), CFG.controller, CFG.pid)
    res = run_closed_loop(CFG, PLANT, pid, lambda t: 12e3 if t < 0.2 else 15e3, 4.0, seed=1)
    m = step_metrics(res, 0.2, 15e3)
    print(f"PID step: {m}, switches {res.switches}, Kc {pid.kc:.2e} 1/N, Ti {pid.ti:.2f} s")
    # with the dead band, hysteresis and conditional integration PID settles to +-2 % in
    # 1.2-2.8 s over seeds 1-4 (reported above, not asserted: a slow leakage drift across
    # the band edge decides it); required: last-second mean within 2 %, overshoot < 10 %
    last = res.t > res.t[-1] - 1.0
    assert abs(res.force[last].mean() - 15e3) < 0.02 * 15e3
    assert m["overshoot"] < 0.10
    assert CFG.controller.force_min_N <= res.force.min() <= res.force.max() <= 20e3
