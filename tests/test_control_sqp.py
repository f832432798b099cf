"""The condensed Gauss-Newton SQP (control/sqp.py) against CasADi ``sqpmethod`` with an exact
QP solver (qpOASES) on the NMPC's OCP: same iteration, so the same iterates.

``sqpmethod`` gets the Gauss-Newton Hessian (Hessian of the cost, constraint curvature
dropped) through ``hess_lag`` and the line-search constants CondensedSqp documents
(3 trials, beta 0.8, c1 1e-4, min step 1e-10, Armijo test on the current merit only).
"""

import casadi as ca
import numpy as np
import pytest

from trackmj.control.model import ReducedModel
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.ocp import X_SCALE, initial_guess
from trackmj.control.sqp import BETA, C1, MAX_ITER_LS, MIN_STEP, CondensedSqp
from trackmj.sim.control_plant import nominal_plant_params, packaged_control

CFG = packaged_control()
PLANT = nominal_plant_params(control_config=CFG)
RTOL = 1e-6  # relative to max(1, |u|_inf), u scaled (valve opening)


def _sqpmethod(ctrl: NonlinearMpc) -> ca.Function:
    ocp, sqp = ctrl.ocp, ctrl.sqp
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", ocp.g.numel())
    hess = ca.Function("gn_hess", [ocp.w, ocp.p, lam_f, lam_g],
                       [lam_f * ca.hessian(ocp.f, ocp.w)[0]])
    opts = {
        "qpsol": "qpoases",
        "qpsol_options": {"printLevel": "none", "error_on_fail": False},
        "hess_lag": hess,
        "max_iter": sqp.max_iter,
        "tol_pr": sqp.tol_pr,
        "tol_du": sqp.tol_du,
        "max_iter_ls": MAX_ITER_LS,
        "beta": BETA,
        "c1": C1,
        "min_step_size": MIN_STEP,
        "merit_memory": 1,
        "print_header": False,
        "print_iteration": False,
        "print_status": False,
        "print_time": False,
        "error_on_fail": False,
    }
    return ca.nlpsol("ref_sqp", "sqpmethod",
                     {"x": ocp.w, "p": ocp.p, "f": ocp.f, "g": ocp.g}, opts)


def _problems(ctrl: NonlinearMpc) -> dict[str, tuple[np.ndarray, np.ndarray, object]]:
    """(w0, p, lam_g0) as NonlinearMpc hands them to its SQP."""
    n, d, nb = CFG.mpc.horizon_steps, CFG.mpc.collocation_degree, ctrl.ocp.n_blocks
    model = ReducedModel(PLANT)
    x15 = model.equilibrium(15e3)
    ref15, ref18 = np.full(n + 1, 15e3), np.full(n + 1, 18e3)
    probs = {
        "at_reference_cold": (initial_guess(n, d, nb, x15), ctrl._parameters(x15, ref15), 0.0),
        "step_+3kN_cold": (initial_guess(n, d, nb, x15), ctrl._parameters(x15, ref18), 0.0),
    }
    # warm-started problem mid-step: run the NMPC a few periods on the reduced plant
    seen: list[tuple[np.ndarray, np.ndarray, object]] = []
    solve = ctrl.sqp.solve

    def spy(w0, p, lam0):
        seen.append((np.array(w0), np.array(p), np.array(lam0, dtype=float)))
        return solve(w0, p, lam0)

    ctrl.sqp.solve = spy
    # the plant follows the NMPC's own one-period prediction (end of its first interval)
    x = x15.copy()
    for k in range(4):
        ctrl(x, ref18, k * CFG.controller.period_s)
        x = ctrl._w[nb + n : nb + n + 4 * d].reshape(d, 4)[-1] * X_SCALE
    ctrl.sqp.solve = solve
    probs["step_+3kN_warm"] = seen[-1]
    return probs


CTRL = NonlinearMpc(ReducedModel(PLANT), CFG.controller, CFG.mpc)
PROBLEMS = _problems(CTRL)
# sqpmethod has no early acceptance of a feasible truncated plan: compare the iterations
# with it switched off (the rule only ends the loop sooner, it changes no iterate)
CTRL.sqp.accept_iter = CTRL.sqp.max_iter
REF = _sqpmethod(CTRL)


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_condensed_sqp_matches_sqpmethod_qpoases(name: str) -> None:
    w0, p, lam0 = PROBLEMS[name]
    ocp, nb = CTRL.ocp, CTRL.ocp.n_blocks
    ours = CTRL.sqp.solve(w0, p, lam0)
    r = REF(x0=w0, p=p, lbx=ocp.lbw, ubx=ocp.ubw, lbg=ocp.lbg, ubg=ocp.ubg, lam_g0=lam0)
    st = REF.stats()
    w_ref = np.array(r["x"]).ravel()
    u_ours, u_ref = ours.w[:nb], w_ref[:nb]
    scale = max(1.0, np.abs(u_ref).max())
    err = np.abs(u_ours - u_ref).max() / scale
    print(f"{name}: iters {ours.iterations}/{st['iter_count']}, u0 {u_ours[0]:.6f} vs "
          f"{u_ref[0]:.6f}, max |du| rel {err:.2e}, status {st['return_status']}")
    assert ours.iterations == st["iter_count"]
    assert abs(u_ours[0] - u_ref[0]) <= RTOL * scale
    assert err <= RTOL
    # whole iterate (slacks and scaled states) too, and the problem must be non-trivial
    assert np.abs(ours.w - w_ref).max() <= RTOL * max(1.0, np.abs(w_ref).max())
    assert np.abs(u_ref).max() > 1e-3 or name == "at_reference_cold"


def test_early_acceptance_stops_at_a_feasible_truncated_plan() -> None:
    """With accept_iter = 2 a plan within the feasibility tolerance after two iterations is
    returned there, identical to a 2-iteration SQP's; one that is not gets the full
    iterations, identical to the SQP without the rule."""
    args = (CTRL.ocp, CFG.mpc.horizon_steps, CFG.mpc.collocation_degree)
    early = CondensedSqp(*args, 6, tol_pr=1e-6, tol_du=1e-4, accept_iter=2,
                         accept_violation=0.1)
    two = CondensedSqp(*args, 2, tol_pr=1e-6, tol_du=1e-4)
    full = CondensedSqp(*args, 6, tol_pr=1e-6, tol_du=1e-4)
    took_early = 0
    for w0, p, lam0 in PROBLEMS.values():
        r_two, r_early, r_full = (s.solve(w0, p, lam0) for s in (two, early, full))
        if r_two.iterations == 2 and r_two.max_violation <= 0.1:
            took_early += 1
            assert r_early.iterations == 2 and r_early.ok
            np.testing.assert_array_equal(r_early.w, r_two.w)
        else:
            assert r_early.iterations == r_full.iterations
            np.testing.assert_array_equal(r_early.w, r_full.w)
    assert took_early >= 1
