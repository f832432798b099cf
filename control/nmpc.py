"""Nonlinear MPC on the reduced model: Gauss-Newton SQP (CasADi ``sqpmethod``'s iteration, a
few SQP iterations per period) on SX, built once, with each QP condensed to the inputs and
slacks and solved exactly by DAQP (``trackmj.control.sqp``). OSQP capped at 100 iterations
(the previous QP solver) stopped up to 0.1 in u short of the QP solution and took ~0.7 ms of
the ~1.1 ms per period; qrqp stalled on the uncondensed QPs (both measured).
Warm-started from the shifted previous solution; falls back to
the shifted previous plan (or hold) on failure or overrun and counts it, never raises."""

from __future__ import annotations

import time
from collections.abc import Callable

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control import mpc_kernels
from trackmj.control.governor import drive_load_allowance, feasible_band, govern
from trackmj.control.model import ReducedModel
from trackmj.control.ocp import X_SCALE, Ocp, build_ocp, initial_guess, parameter_vector
from trackmj.control.params import ControllerParams, MpcParams, resolved
from trackmj.control.sqp import CondensedSqp
from trackmj.control.trim import IntegralTrim
from trackmj.ports import ControllerStatistics, ControlOutput

#: Largest constraint violation (scaled units: MPa, mm, kN, ...) accepted from a truncated SQP.
FEASIBILITY_TOL = 0.1


class _MpcBase:
    """Warm start, fallback and statistics common to NMPC and LMPC."""

    def __init__(
        self, model: ReducedModel, ctrl: ControllerParams, mpc: MpcParams, ocp: Ocp
    ) -> None:
        self.model, self.ctrl, self.mpc, self.ocp = model, ctrl, mpc, ocp
        self.period_s = ctrl.period_s
        self.horizon_steps = mpc.horizon_steps
        self.theta = np.array(
            (model.p.supply_pressure_Pa, model.p.stiffness_N_m, model.p.free_position_m)
        )
        self.u_prev = 0.0
        middle = 0.5 * (resolved(ctrl, "force_min_N") + resolved(ctrl, "force_max_N"))
        self.trim = IntegralTrim(mpc.offset_integral_time_s, mpc.offset_trim_max_rel * middle,
                                 mpc.offset_dead_band_rel * middle, mpc.offset_clip_rel * middle,
                                 mpc.offset_filter_s, ctrl.period_s)
        self.failures = 0
        self.overruns = 0
        self.fallbacks = 0
        self.solve_times: list[float] = []
        self._w: NDArray[np.float64] | None = None
        self._lam_g: NDArray[np.float64] | None = None
        self._plan: NDArray[np.float64] = np.zeros(mpc.horizon_steps)
        self._plan_age = mpc.horizon_steps
        self._plan_buffer = np.zeros(ocp.n_blocks * mpc.block_steps)
        # the NMPC's problem is built by the compiled ``_problem`` into these (the LMPC
        # appends its linearisation to p, so it keeps the numpy path)
        self._compiled_problem = False
        self._w0_buffer = np.zeros(ocp.w.numel())
        self._p_buffer = np.zeros(ocp.n_param)

    def set_parameters(
        self,
        supply_pressure_Pa: float | None = None,
        stiffness_N_m: float | None = None,
        free_position_m: float | None = None,
        pressure_max_Pa: float | None = None,
    ) -> None:
        """Online update of NLP parameters (supply, identified stiffness/preload, p_max)."""
        if supply_pressure_Pa is not None:
            self.theta[0] = supply_pressure_Pa
        if stiffness_N_m is not None:
            self.theta[1] = stiffness_N_m
        if free_position_m is not None:
            self.theta[2] = free_position_m
        if pressure_max_Pa is not None:
            self.ctrl = ControllerParams(
                **{
                    **{f: getattr(self.ctrl, f) for f in self.ctrl.__slots__},
                    "pressure_max_Pa": pressure_max_Pa,
                }
            )

    def statistics(self) -> ControllerStatistics:
        """The controller port's counts: solves whose plan the fallback replaced."""
        return ControllerStatistics(fallbacks=self.fallbacks)

    def _parameters(self, x0: NDArray[np.float64], ref: NDArray[np.float64]) -> NDArray[np.float64]:
        """OCP parameter vector for initial state x0 (4,) and preview ref (N+1,) [N]."""
        return parameter_vector(x0, ref, self.u_prev, self.theta, self.ctrl)

    def _call_solver(
        self, solver: ca.Function, w0: NDArray[np.float64], p: NDArray[np.float64],
        converged: Callable[[dict], bool]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool, int]:
        """Run ``solver`` (a CasADi NLP/QP solver on ``self.ocp``) warm-started; (w, lam_g,
        ok, iterations) where ok needs the solver's own verdict (``converged(stats)``) and a
        plan within FEASIBILITY_TOL."""
        lam0 = self._lam_g if self._lam_g is not None else 0.0
        r = solver(x0=w0, p=p, lbx=self.ocp.lbw, ubx=self.ocp.ubw, lbg=self.ocp.lbg,
                   ubg=self.ocp.ubg, lam_g0=lam0)
        st = solver.stats()
        w, g = np.array(r["x"]).ravel(), np.array(r["g"]).ravel()
        viol = max(
            np.max(self.ocp.lbg - g, initial=0.0),
            np.max(g - self.ocp.ubg, initial=0.0),
            np.max(self.ocp.lbw - w, initial=0.0),
            np.max(w - self.ocp.ubw, initial=0.0),
        )
        ok = converged(st) and bool(viol <= FEASIBILITY_TOL)
        return w, np.array(r["lam_g"]).ravel(), ok, int(st.get("iter_count", 0))

    def _solve(
        self, w0: NDArray[np.float64], p: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool, int]:
        raise NotImplementedError

    def __call__(
        self, estimate: NDArray[np.float64], reference_preview: NDArray[np.float64], t: float
    ) -> ControlOutput:
        """Opening u for the coming period from the state estimate (4,) to (6,) and the
        reference preview F_ref(t + i Ts), i = 0..N (N+1,) [N].

        A fifth estimate entry is the estimated free position y0 [m] (the estimators'
        disturbance state); it becomes the model's online y0. A sixth is the measured drive
        torque's idler load L [N] (:func:`~trackmj.control.model.drive_load_N`), fed
        forward as the unloaded stroke moved in by L/k_eq (held over the horizon), and
        rejected only as far as the band takes its end
        (:func:`~trackmj.control.governor.drive_load_allowance`). The preview is raised by
        the integral trim (:mod:`trackmj.control.trim`, updated first from this estimate's
        cylinder force) and saturated by the reference governor
        (:mod:`trackmj.control.governor`) at the current supply.
        A solve that fails is still used if its plan is finite (counted as a fallback), so
        the controller keeps acting; otherwise the previous plan is shifted on.
        """
        n, lb = self.mpc.horizon_steps, self.mpc.block_steps
        plant = self.model.p
        band = feasible_band(self.ctrl, plant, float(self.theta[0]))
        if len(estimate) > 4:
            self.theta[2] = float(estimate[4])
            if len(estimate) > 5 and estimate[5] > 0.0:
                load = float(estimate[5])
                self.theta[2] -= load / self.theta[1]
                reference_preview = self._with_drive_load(reference_preview, load, band)
        self.trim.update(np.asarray(reference_preview, dtype=float), band,
                         float(estimate[0]) * plant.area_head_m2
                         - float(estimate[1]) * plant.area_rod_m2)
        w0, p = self._problem(estimate, self.trim.trimmed(reference_preview), band)
        t0 = time.perf_counter()
        try:
            w, lam_g, ok, iters = self._solve(w0, p)
        except RuntimeError:
            w, lam_g, ok, iters = w0.copy(), np.zeros(self.ocp.g.numel()), False, 0
        dt = time.perf_counter() - t0
        self.solve_times.append(dt)
        overrun = dt > self.mpc.time_budget_s
        plan = self._plan_buffer
        finite = mpc_kernels.finish(w, lam_g, self.ocp.n_blocks, lb, plan, not overrun)
        ok = ok and finite
        if ok:
            self._w, self._lam_g = w, lam_g   # the next solve continues from this iterate
        else:   # a failed iterate is no start: from it the truncated SQP kept failing
            self._w = self._lam_g = None
        if finite and not overrun:
            self._plan = plan    # w[:n_blocks], each value repeated block_steps times
            self._plan_age = 0
            u = min(max(float(w[0]), self.ctrl.u_min), self.ctrl.u_max)
        else:   # the previous plan shifted on (an LMPC plan may sit just past the bounds)
            self._plan_age += 1
            u = float(self._plan[self._plan_age]) if self._plan_age < n else 0.0
            u = min(max(u, self.ctrl.u_min), self.ctrl.u_max)
        if not (ok and not overrun):
            self.failures += not ok
            self.overruns += overrun
            self.fallbacks += 1
        self.u_prev = u
        return ControlOutput(u, ok and not overrun, dt, iters, not (ok and not overrun))

    def _with_drive_load(self, reference_preview: NDArray[np.float64], load_N: float,
                         band: tuple[float, float]) -> NDArray[np.float64]:
        """The preview [N] raised by the drive load's allowance for load ``load_N`` [N] in
        the governed ``band`` (lo, hi) [N]."""
        preview = np.asarray(reference_preview, dtype=float)
        held = self.model.hold_load_share(float(preview[0])) * load_N
        return preview + drive_load_allowance(preview, band[0], held)

    def _problem(self, estimate: NDArray[np.float64], reference_preview: NDArray[np.float64],
                 band: tuple[float, float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(initial guess w0, parameter vector p) of the solve from the estimate and the
        preview, governed to ``band`` (lo, hi) [N]: the numpy expressions below, or their
        compiled equal into the controller's own buffers (the NMPC's OCP with every limit set
        and a preview of N + 1 values)."""
        ctrl, n = self.ctrl, self.mpc.horizon_steps
        lim = (ctrl.force_min_N, ctrl.force_max_N, ctrl.pressure_min_Pa, ctrl.pressure_max_Pa)
        if (self._compiled_problem and len(reference_preview) == n + 1
                and None not in lim):
            w0, p = self._w0_buffer, self._p_buffer
            mpc_kernels.prepare(
                np.asarray(estimate, dtype=float), np.asarray(reference_preview, float),
                band[0], band[1], self.u_prev, self.theta, lim, ctrl.pressure_min_Pa,
                X_SCALE, self._w if self._w is not None else w0, self._w is not None, n,
                self.mpc.collocation_degree, self.ocp.n_blocks, p, w0)
            return w0, p
        x0 = np.array(estimate[:4], dtype=float)
        # gauge pressures below p_min are estimator noise; a hard bound at node 1 would make
        # the problem locally infeasible, so the initial state is projected onto p >= p_min
        p_min = ctrl.pressure_min_Pa
        if x0[0] < p_min:
            x0[0] = p_min
        if x0[1] < p_min:
            x0[1] = p_min
        p = self._parameters(x0, govern(np.asarray(reference_preview, float), band))
        return self._shifted_guess(x0), p

    def _shifted_guess(self, x0: NDArray[np.float64]) -> NDArray[np.float64]:
        n, d, nb = self.mpc.horizon_steps, self.mpc.collocation_degree, self.ocp.n_blocks
        if self._w is None:
            return initial_guess(n, d, nb, x0)
        prev, k = self._w, 4 * d
        w = prev.copy()
        # slacks and collocation blocks move one interval forward, the last ones are kept
        w[nb : nb + n - 1] = prev[nb + 1 : nb + n]
        w[nb + n + k : nb + n + (n - 1) * k] = prev[nb + n + 2 * k :]
        # the first collocation block is re-anchored at the new measurement
        w[nb + n : nb + n + k].reshape(d, 4)[:] = x0 / X_SCALE
        return w


class NonlinearMpc(_MpcBase):
    """Nonlinear MPC on the reduced model (see the module docstring).

    ``controller(estimate (4,)-(6,), reference_preview (N+1,) [N], t [s]) -> ControlOutput``;
    the supply pressure, stiffness, unloaded stroke and pressure limit can be updated
    online with ``set_parameters``.

    Parameters
    ----------
    model : ReducedModel
        The prediction model (its plant parameters, SI).
    ctrl : ControllerParams
        Period [s], tension band [N], pressure band [Pa], input bounds [-].
    mpc : MpcParams
        Horizon, move blocking, weights and SQP settings.
    jit : bool
        Compile the SQP's functions with the system C compiler (slow build, optional).
    """

    def __init__(
        self, model: ReducedModel, ctrl: ControllerParams, mpc: MpcParams, jit: bool = False
    ) -> None:
        ocp = build_ocp(model, ctrl, mpc)
        super().__init__(model, ctrl, mpc, ocp)
        self._compiled_problem = True
        opts = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O2"]}} if jit else {}
        self.sqp = CondensedSqp(ocp, mpc.horizon_steps, mpc.collocation_degree, mpc.max_iter,
                                tol_pr=1e-6, tol_du=1e-4, function_options=opts,
                                accept_iter=mpc.accept_iter,
                                accept_violation=FEASIBILITY_TOL)

    def _solve(
        self, w0: NDArray[np.float64], p: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool, int]:
        # a truncated SQP (few iterations per period) is accepted only if its plan is feasible
        lam0 = self._lam_g if self._lam_g is not None else 0.0
        r = self.sqp.solve(w0, p, lam0)
        return r.w, r.lam_g, r.ok and r.max_violation <= FEASIBILITY_TOL, r.iterations
