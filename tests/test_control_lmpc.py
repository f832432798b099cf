"""Linear MPC in closed loop on the reduced plant, reported beside NMPC and PID."""


import numpy as np

from trackmj.control.lmpc import LinearMpc
from trackmj.control.model import ReducedModel
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.ocp import X_SCALE
from trackmj.control.pid import PidController
from trackmj.sim.control_plant import nominal_plant_params, packaged_control
from trackmj.sim.reduced import run_closed_loop, step_metrics

CFG = packaged_control()
PLANT = nominal_plant_params(control_config=CFG)


def _step(t: float) -> float:
    return 12e3 if t < 0.2 else 15e3


def _lmpc() -> LinearMpc:
    return LinearMpc(ReducedModel(PLANT), CFG.controller, CFG.mpc)


def test_step_12_to_15_kN_beside_nmpc_and_pid() -> None:
    """Same step, seed and loop for the three controllers; LMPC must meet the NMPC's bounds."""
    model = ReducedModel(PLANT)
    ctrls = {
        "LMPC": _lmpc(),
        "NMPC": NonlinearMpc(model, CFG.controller, CFG.mpc),
        "PID": PidController(model, CFG.controller, CFG.pid),
    }
    metrics = {}
    for name, ctrl in ctrls.items():
        res = run_closed_loop(CFG, PLANT, ctrl, _step, 3.0, seed=1)
        m = step_metrics(res, 0.2, 15e3)
        rmse = float(np.sqrt(np.mean((res.force - res.ref) ** 2)))
        metrics[name] = (m, res)
        print(
            f"{name}: settling {m['settling_s']:.2f} s, overshoot {100 * m['overshoot']:.1f} %, "
            f"tracking RMSE {rmse:.0f} N, last-second RMSE {m['rmse_last_s_N']:.0f} N, "
            f"switches {res.switches}, fallbacks {getattr(ctrl, 'fallbacks', 0)}"
        )
    m, res = metrics["LMPC"]
    assert m["settling_s"] <= 2.0
    assert m["overshoot"] < 0.05
    c = CFG.controller
    assert c.force_min_N <= res.force.min() and res.force.max() <= c.force_max_N
    assert c.pressure_min_Pa <= res.x[:, :2].min() and res.x[:, :2].max() <= c.pressure_max_Pa
    assert ctrls["LMPC"].fallbacks <= 5


def test_lmpc_respects_pressure_bound_in_its_plan() -> None:
    """From 12 kN towards 15 kN, a p_max 0.05 MPa above the head pressure (~+0.13 kN) must
    cap the pressurize move of the unconstrained plan, and the planned pressures obey it."""
    ctrl = _lmpc()
    x = ReducedModel(PLANT).equilibrium(12e3)
    ref = np.full(CFG.mpc.horizon_steps + 1, 15e3)
    free = ctrl(x, ref, 0.0)
    capped = _lmpc()
    p_max = x[0] + 0.05e6
    capped.set_parameters(pressure_max_Pa=p_max)
    out = capped(x, ref, 0.0)
    n, nb = CFG.mpc.horizon_steps, capped.ocp.n_blocks
    planned = capped._w[nb + n :].reshape(n, 4) * X_SCALE  # node states, SI
    print(f"u unconstrained {free.u:.3f}, with p_max = p_head + 0.05 MPa {out.u:.3f}")
    assert free.success and out.success
    assert free.u > 0.5
    assert 0.0 <= out.u < 0.5 * free.u
    assert planned[:, 0].max() <= p_max + 5e3  # OSQP eps 1e-4 (relative, MPa units)
