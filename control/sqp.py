"""Gauss-Newton SQP for the tension OCP with the collocation states condensed out of each QP.

The iteration is CasADi ``sqpmethod``'s (exact Hessian of the quadratic cost, l1-merit
Armijo line search with penalty sigma = max(sigma, 1.01 ||lambda_QP||_inf), up to 3 trials
with step factor 0.8 and c1 = 1e-4, multipliers blended by the step length, the same
convergence and step-size tests), and every QP step is solved exactly. Only how the QP is
solved differs: the collocation equations of step i are linear in the step dX_i once
linearised, so dX_i = c_i + S_i du follows from the block recursion
dX_i = -E_i^-1 (G_i + A_i dX_{i-1} + B_i du) (E_i = dG_i/dX_i, 4d x 4d), and the QP shrinks
from [u, s, X] (80 variables, 60 equalities at N = 15, d = 1) to a dense QP in [du, ds]
(20 variables) solved by an active-set method. The dynamics multipliers are recovered by the
transposed (backward) recursion, so the merit penalty is sqpmethod's too.

All symbolic work (Jacobian blocks, E_i^-1, the recursion, the condensed matrices) happens in
SX functions built once, compiled to machine code (:mod:`trackmj.control.compiled`,
bit-identical to CasADi's virtual machine); they and the QP solver (through
:class:`~trackmj.control.fastcall.BufferedFunction`) run on preallocated numpy arrays. Measured
on 3000 recorded closed-loop problems: iterates equal ``sqpmethod`` with an exact QP solver
(qpOASES) to 1e-14.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control import mpc_kernels
from trackmj.control.compiled import bind
from trackmj.control.fastcall import BufferedFunction
from trackmj.control.ocp import Ocp

#: sqpmethod defaults: line-search trials, backtracking factor, Armijo constant, smallest step.
MAX_ITER_LS = 3
BETA = 0.8
C1 = 1e-4
MIN_STEP = 1e-10
#: Largest constraint violation of an accepted QP solution (scaled units; DAQP's own primal
#: tolerance is 1e-6, its optimal solutions on recorded closed-loop QPs violate < 1e-17).
QP_FEASIBILITY_TOL = 1e-5


@dataclass(frozen=True)
class SqpResult:
    """Final iterate w, NLP constraint multipliers lam_g, largest bound/constraint violation
    of w (scaled units), iterations, and whether sqpmethod would report success or its
    iteration limit (False on a tiny step, an infeasible QP or a QP solver failure)."""

    w: NDArray[np.float64]
    lam_g: NDArray[np.float64]
    max_violation: float
    iterations: int
    ok: bool


def _violations(w: ca.SX, lbw: NDArray[np.float64], ubw: NDArray[np.float64], g: ca.SX,
                lbg: NDArray[np.float64], ubg: NDArray[np.float64]) -> ca.SX:
    """Bound violations of w and g (only where a bound is finite; |g| for equalities)."""
    terms = []
    for z, lb, ub in ((w, lbw, ubw), (g, lbg, ubg)):
        for i in range(z.numel()):
            if lb[i] == ub[i]:
                terms.append(ca.fabs(z[i] - lb[i]))
                continue
            if np.isfinite(lb[i]):
                terms.append(ca.fmax(lb[i] - z[i], 0.0))
            if np.isfinite(ub[i]):
                terms.append(ca.fmax(z[i] - ub[i], 0.0))
    return ca.vertcat(*terms)


@dataclass(frozen=True)
class _Layout:
    """Where the blocks sit in the OCP's w and g (see :class:`CondensedSqp`).

    nb input blocks, n steps of nxb = 4d collocation states; nw, ng sizes of w and g;
    nz = nb + n QP variables [u, s]; nx = n·nxb states; ``rows`` constraints per step;
    npar parameters.
    ``eq``/``ineq``: indices into g of the collocation equations and of the linear rows;
    ``xcols[i]``: indices into w of X_i.
    """

    nb: int
    n: int
    nxb: int
    nw: int
    ng: int
    nz: int
    nx: int
    rows: int
    npar: int
    eq: NDArray[np.int64]
    ineq: NDArray[np.int64]
    xcols: list[list[int]]


def _layout(ocp: Ocp, n_steps: int, degree: int) -> _Layout:
    """The index sets of ``ocp``; ValueError if it is not laid out as CondensedSqp needs."""
    nb, n, nxb = ocp.n_blocks, n_steps, 4 * degree
    nw, ng, nz = ocp.w.numel(), ocp.g.numel(), ocp.n_blocks + n_steps
    nx = n * nxb
    rows = ng // n
    if rows * n != ng or nz + nx != nw:
        raise ValueError("CondensedSqp: OCP layout does not match n_steps/degree")
    if np.isfinite(ocp.lbw[nz:]).any() or np.isfinite(ocp.ubw[nz:]).any():
        raise ValueError("CondensedSqp: collocation states must be unbounded")
    eq = np.concatenate([i * rows + np.arange(nxb) for i in range(n)])
    ineq = np.setdiff1d(np.arange(ng), eq)
    xcols = [list(range(nz + i * nxb, nz + (i + 1) * nxb)) for i in range(n)]
    return _Layout(nb, n, nxb, nw, ng, nz, nx, rows, ocp.p.numel(), eq, ineq, xcols)


@dataclass(frozen=True)
class _Linearisation:
    """The OCP linearised and condensed: constraint Jacobian ``jac`` (ng x nw), cost
    gradient ``grad`` (nw), the constant cost Hessian ``hess`` (nw x nw) and linear-row
    Jacobian ``jin``; per step E_i^-1 (``e_inv``, nxb x nxb) and the constant coupling
    A_i = dG_i/dX_{i-1} (``a_blk``); dX = ``c_all`` + ``s_all`` du stacked over the steps
    (nx, nx x nb)."""

    jac: ca.SX
    grad: ca.SX
    hess: ca.DM
    jin: ca.DM
    e_inv: list[ca.SX]
    a_blk: list[ca.DM]
    c_all: ca.SX
    s_all: ca.SX


def _derivatives(ocp: Ocp, lay: _Layout, wp: ca.SX) -> tuple[ca.SX, ca.SX, ca.DM, ca.DM]:
    """(jac, grad, hess, jin) of the OCP; ValueError unless the cost is quadratic and the
    non-collocation rows linear in w (their Hessian and Jacobian are then constants)."""
    w, f, g = ocp.w, ocp.f, ocp.g
    jac = ca.jacobian(g, w)
    grad = ca.gradient(f, w)
    hess = ca.hessian(f, w)[0]
    jin = jac[lay.ineq.tolist(), :]
    if ca.depends_on(hess, wp) or ca.depends_on(jin, wp):
        raise ValueError("CondensedSqp: cost must be quadratic and non-collocation "
                         "constraints linear in w")
    hess, jin = ca.evalf(hess), ca.evalf(jin)
    return jac, grad, hess, jin


def _linearise(ocp: Ocp, lay: _Layout, wp: ca.SX) -> _Linearisation:
    """The derivatives and the forward recursion dX_i = c_i + S_i du over the collocation
    blocks; ValueError where a block couples other variables or non-constantly."""
    jac, grad, hess, jin = _derivatives(ocp, lay, wp)
    g, nb, nxb, rows, xcols = ocp.g, lay.nb, lay.nxb, lay.rows, lay.xcols
    e_inv, a_blk, c_blk, s_blk = [], [], [], []
    c_prev, s_prev = ca.SX(nxb, 1), ca.SX(nxb, nb)
    for i in range(lay.n):
        r = list(range(i * rows, i * rows + nxb))
        jr = jac[r, :]
        others = set(jr.sparsity().get_col()) - set(xcols[i]) - set(range(nb))
        if i > 0:
            others -= set(xcols[i - 1])
        if others:
            raise ValueError(f"CondensedSqp: collocation block {i} couples other variables")
        ei = ca.inv(jac[r, xcols[i]])
        ai = ca.evalf(jac[r, xcols[i - 1]]) if i > 0 else ca.DM(nxb, nxb)
        if i > 0 and ca.depends_on(jac[r, xcols[i - 1]], wp):
            raise ValueError("CondensedSqp: block coupling must be constant")
        c_prev = -ca.mtimes(ei, g[r] + ca.mtimes(ai, c_prev))
        s_prev = -ca.mtimes(ei, jac[r, :nb] + ca.mtimes(ai, s_prev))
        e_inv.append(ei)
        a_blk.append(ai)
        c_blk.append(c_prev)
        s_blk.append(s_prev)
    return _Linearisation(jac, grad, hess, jin, e_inv, a_blk, ca.vertcat(*c_blk),
                          ca.vertcat(*s_blk))


def _qp_data_functions(ocp: Ocp, lay: _Layout, lin: _Linearisation,
                       fopts: dict) -> tuple[ca.Function, ca.Function, ca.SX]:
    """``sqp_qp_data`` (w, p, lam_g, lam_x) -> the condensed QP [H, g, A, lba, uba, lbz,
    ubz], the recursion's c, S and E^-1, the gradient and (f, l1 and max violation);
    ``sqp_du_inf`` -> the dual infeasibility; and the violations of w and g (for the
    merit)."""
    w, p, g, nz, nx, n, ineq = ocp.w, ocp.p, ocp.g, lay.nz, lay.nx, lay.n, lay.ineq
    hess, jin, grad = lin.hess, lin.jin, lin.grad
    t_map = ca.vertcat(ca.SX.eye(nz), ca.horzcat(lin.s_all, ca.SX(nx, n)))
    t0 = ca.vertcat(ca.SX(nz, 1), lin.c_all)
    g_in = g[ineq.tolist()]
    r_in = g_in + ca.mtimes(jin, t0)
    lam_g, lam_x = ca.SX.sym("lam_g", lay.ng), ca.SX.sym("lam_x", lay.nw)
    viol = _violations(w, ocp.lbw, ocp.ubw, g, ocp.lbg, ocp.ubg)
    du_inf = ca.norm_inf(grad + ca.mtimes(lin.jac.T, lam_g) + lam_x)
    d = ca.densify
    qp_data = ca.Function(
        "sqp_qp_data", [w, p, lam_g, lam_x],
        [d(ca.mtimes([t_map.T, ca.DM(hess), t_map])),
         d(ca.mtimes(t_map.T, ca.mtimes(ca.DM(hess), t0) + grad)),
         d(ca.mtimes(ca.DM(jin), t_map)),
         d(ocp.lbg[ineq] - r_in), d(ocp.ubg[ineq] - r_in),
         d(ocp.lbw[:nz] - w[:nz]), d(ocp.ubw[:nz] - w[:nz]),
         d(lin.c_all), d(lin.s_all), d(ca.vertcat(*[ca.vec(e) for e in lin.e_inv])), d(grad),
         ca.vertcat(ocp.f, ca.sum1(viol), ca.mmax(viol))], fopts)
    # dual infeasibility, only needed once the iterate is primal feasible (~8 % of the
    # QP-data instructions, so a separate function)
    du_fn = ca.Function("sqp_du_inf", [w, p, lam_g, lam_x], [du_inf], fopts)
    return qp_data, du_fn, viol


def _step_function(lay: _Layout, lin: _Linearisation, fopts: dict) -> ca.Function:
    """``sqp_step`` (QP solution z, lam_a, lam_z; c, S, E^-1, gradient; the QP's bounds)
    -> (dx, dlam_g, dlam_x, [|dlam|_inf, gradient·dx, |dx|_inf, QP violation]): the QP
    solution expanded and the collocation multipliers recovered backwards."""
    nb, n, nxb, nz, nx, ineq, xcols = lay.nb, lay.n, lay.nxb, lay.nz, lay.nx, lay.ineq, \
        lay.xcols
    hess, jin, d = lin.hess, lin.jin, ca.densify
    zs, la, lz = ca.SX.sym("z", nz), ca.SX.sym("lam_a", ineq.size), ca.SX.sym("lam_z", nz)
    cs, ss = ca.SX.sym("c", nx), ca.SX.sym("S", nx, nb)
    es, gs = ca.SX.sym("e_inv", nxb * nxb * n), ca.SX.sym("grad", lay.nw)
    bnd = [ca.SX.sym(name, k) for name, k in
           (("lba", ineq.size), ("uba", ineq.size), ("lbz", nz), ("ubz", nz))]
    s_du = ca.mtimes(ss, zs[:nb])
    dx = ca.vertcat(zs, cs + s_du)
    # primal feasibility of the QP solution: DAQP is a dual active-set method, so a
    # feasible return is optimal and an infeasible QP or an aborted solve is not feasible
    a_z = ca.mtimes(ca.DM(jin), ca.vertcat(zs, s_du))
    qp_viol = ca.mmax(ca.vertcat(ca.fmax(a_z - bnd[1], 0), ca.fmax(bnd[0] - a_z, 0),
                                 ca.fmax(zs - bnd[3], 0), ca.fmax(bnd[2] - zs, 0)))
    resid = ca.mtimes(ca.DM(hess), dx) + gs + ca.mtimes(ca.DM(jin).T, la)
    lam_eq_back: list[ca.SX] = []  # node n - 1 first
    for i in reversed(range(n)):
        ri = resid[xcols[i]]
        if lam_eq_back:  # i < n - 1
            ri = ri + ca.mtimes(lin.a_blk[i + 1].T, lam_eq_back[-1])
        einv_i = ca.reshape(es[i * nxb * nxb:(i + 1) * nxb * nxb], nxb, nxb)
        lam_eq_back.append(-ca.mtimes(einv_i.T, ri))
    dlam_g = ca.SX(lay.ng, 1)
    dlam_g[lay.eq.tolist()] = ca.vertcat(*reversed(lam_eq_back))
    dlam_g[ineq.tolist()] = la
    dlam_x = ca.vertcat(lz, ca.SX(nx, 1))
    return ca.Function(
        "sqp_step", [zs, la, lz, cs, ss, es, gs, *bnd],
        [d(dx), d(dlam_g), d(dlam_x),
         ca.vertcat(ca.fmax(ca.norm_inf(dlam_g), ca.norm_inf(lz)), ca.dot(gs, dx),
                    ca.norm_inf(dx), qp_viol)], fopts)


def _merit_function(ocp: Ocp, viol: ca.SX, fopts: dict) -> ca.Function:
    """``sqp_merit`` (w, dx, t, p) -> (f, l1 and max violation) at the trial point
    w + t·dx."""
    w, p, nw = ocp.w, ocp.p, ocp.w.numel()
    ws, dxs, ts = ca.SX.sym("w", nw), ca.SX.sym("dx", nw), ca.SX.sym("t")
    trial = ca.Function("sqp_fg", [w, p], [ocp.f, viol])(ws + ts * dxs, p)
    return ca.Function("sqp_merit", [ws, dxs, ts, p],
                       [ca.vertcat(trial[0], ca.sum1(trial[1]), ca.mmax(trial[1]))], fopts)


def _qp_solver(lay: _Layout) -> ca.Function:
    """DAQP on the dense condensed QP in [du, ds] (nz variables, the linear rows)."""
    return ca.conic("sqp_qp", "daqp",
                    {"h": ca.Sparsity.dense(lay.nz, lay.nz),
                     "a": ca.Sparsity.dense(lay.ineq.size, lay.nz)},
                    {"error_on_fail": False})


class CondensedSqp:
    """``sqpmethod``-equivalent Gauss-Newton SQP on ``ocp`` with condensed exact QPs.

    Layout required (as built by :func:`trackmj.control.ocp.build_ocp`):
    w = [u (n_blocks), s (n), X_0..X_{n-1} (4d each)], g = per step [4d collocation
    equations, then rows linear in w]; the cost is quadratic in w; the states have no
    bounds. The condensed QPs go to DAQP (dual active set for small dense QPs, through
    CasADi's conic; qpOASES gave the same iterates, ~30 % slower, and prints a banner per
    instance); ``function_options`` go to the SX functions (e.g. JIT).
    """

    def __init__(self, ocp: Ocp, n_steps: int, degree: int, max_iter: int, tol_pr: float,
                 tol_du: float, function_options: dict | None = None,
                 accept_iter: int | None = None, accept_violation: float = 0.0) -> None:
        self.max_iter, self.tol_pr, self.tol_du = max_iter, tol_pr, tol_du
        self.accept_iter = max_iter if accept_iter is None else accept_iter
        self.accept_violation = accept_violation
        lay = _layout(ocp, n_steps, degree)
        lin = _linearise(ocp, lay, ca.vertcat(ocp.w, ocp.p))
        fopts = function_options or {}
        qp_data, du_fn, viol = _qp_data_functions(ocp, lay, lin, fopts)
        step = _step_function(lay, lin, fopts)
        merit = _merit_function(ocp, viol, fopts)
        self._bind(lay, qp_data, du_fn, step, merit, _qp_solver(lay))

    def _bind(self, lay: _Layout, qp_data: ca.Function, du_fn: ca.Function,
              step: ca.Function, merit: ca.Function, qp: ca.Function) -> None:
        """Preallocate the iterate and bind the functions to it and to each other's
        results: every buffer stays bound to these arrays."""
        self.w, self.p = np.zeros(lay.nw), np.zeros(lay.npar)
        self.lam_g, self.lam_x = np.zeros(lay.ng), np.zeros(lay.nw)
        self._t = np.zeros(1)
        self._qp_data = bind(qp_data, [self.w, self.p, self.lam_g, self.lam_x])
        h, gq, aq, lba, uba, lbz, ubz, c_v, s_v, e_v, g_v, self._scal = self._qp_data.res
        zero_z, zero_a = np.zeros(lay.nz), np.zeros(lay.ineq.size)
        self._qp = BufferedFunction(qp, [h, gq, aq, lba, uba, lbz, ubz, zero_z.copy(), zero_z,
                                         zero_a, np.zeros(0), np.zeros(0)][: qp.n_in()])
        z_qp, _, lam_a, lam_z = self._qp.res
        self._du_inf = bind(du_fn, [self.w, self.p, self.lam_g, self.lam_x])
        self._step = bind(step, [z_qp, lam_a, lam_z, c_v, s_v, e_v, g_v, lba, uba, lbz, ubz])
        self.dx, self.dlam_g, self.dlam_x, self._step_scal = self._step.res
        self._merit = bind(merit, [self.w, self.dx, self._t, self.p])

    def solve(self, w0: NDArray[np.float64], p: NDArray[np.float64],
              lam_g0: NDArray[np.float64] | float) -> SqpResult:
        """Run the SQP from w0 with parameters p and initial constraint multipliers."""
        w, lam_g, lam_x = self.w, self.lam_g, self.lam_x
        w[:] = w0
        self.p[:] = p
        lam_g[:] = lam_g0
        lam_x[:] = 0.0
        sigma = 0.0
        it = 0
        step_inf = 0.0
        qp_data, qp, step, merit = (self._qp_data.call, self._qp.call, self._step.call,
                                    self._merit.call)
        while True:
            if qp_data():
                return self._result(np.inf, it, False)
            f_k, l1_infeas, max_viol = self._scal.tolist()
            if max_viol < self.tol_pr:
                self._du_inf.call()
                if self._du_inf.res[0][0] < self.tol_du:
                    return self._result(max_viol, it, True)
            if it >= 1 and step_inf <= MIN_STEP:
                return self._result(max_viol, it, False)
            it += 1
            if qp() or step():
                return self._result(max_viol, it, False)
            dlam_inf, slope, dx_inf, qp_viol = self._step_scal.tolist()
            if not (qp_viol <= QP_FEASIBILITY_TOL and math.isfinite(slope)):
                # infeasible QP (sqpmethod would switch to elastic mode) or solver failure
                return self._result(max_viol, it, False)
            sigma = max(sigma, 1.01 * dlam_inf)
            l1 = f_k + sigma * l1_infeas
            tl1 = slope - sigma * l1_infeas
            t = 1.0
            merit_out = self._merit.res[0]
            for ls in range(1, MAX_ITER_LS + 1):
                self._t[0] = t
                merit()
                f_c, viol_c, max_viol = merit_out.tolist()
                if f_c + sigma * viol_c <= l1 + t * C1 * tl1 or ls == MAX_ITER_LS:
                    break
                t *= BETA
            # w += t·dx, multipliers blended by t (the QP's at a full step)
            mpc_kernels.update(w, lam_g, lam_x, self.dx, self.dlam_g, self.dlam_x, t)
            step_inf = t * dx_inf
            if it >= self.accept_iter and max_viol <= self.accept_violation:
                # a truncated SQP whose plan is feasible enough is used as it is (real-time
                # iterations); the remaining iterations are spent only on infeasible plans
                return self._result(max_viol, it, True)
            if it >= self.max_iter:
                # sqpmethod would re-linearise here only to test convergence; success and
                # the iteration limit are both accepted, so the merit call's violation suffices
                return self._result(max_viol, it, True)

    def _result(self, max_violation: float, iterations: int, ok: bool) -> SqpResult:
        return SqpResult(self.w.copy(), self.lam_g.copy(), max_violation, iterations, ok)
