"""Linear MPC: the NMPC's cost, weights, horizon, move blocking and implicit-Euler
discretisation on the reduced model linearised at an operating point, solved as one QP per
period with ``casadi.qpsol`` (OSQP, warm-started primal and dual from the shifted plan).

The affine model xdot = c + A x + B u enters the QP as parameters, so it is re-linearised at
every solve (one CasADi call, ~20 us) without rebuilding the solver: the operating point is
the hold-mode equilibrium (u = 0) at the first reference of the preview, with the current
supply pressure, k_eq and y0 (``set_parameters``). Same ``ControlOutput`` interface,
fallback (shifted plan or hold) and counters as the NMPC.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from trackmj.control.model import ReducedModel
from trackmj.control.nmpc import _MpcBase
from trackmj.control.ocp import build_ocp, linearisation_function
from trackmj.control.params import ControllerParams, MpcParams

#: QP solver plugin (measured on the 12 -> 15 kN closed-loop step, one core; see the
#: benchmark): osqp converges on every QP; qrqp, the other solver shipped without
#: compilation, is kept selectable for comparison.
QP_SOLVER = "osqp"


def osqp_options(mpc: MpcParams) -> dict:
    """CasADi qpsol options for OSQP, warm-started, capped at ``mpc.qp_max_iter`` iterations
    with tolerance ``mpc.qp_tolerance``."""
    return {
        "osqp": {
            "verbose": False,
            "eps_abs": mpc.qp_tolerance,
            "eps_rel": mpc.qp_tolerance,
            "max_iter": mpc.qp_max_iter,
            "polish": False,
        },
        "warm_start_primal": True,
        "warm_start_dual": True,
    }


class LinearMpc(_MpcBase):
    """Linear MPC (see the module docstring):
    ``controller(estimate (4,), reference_preview (N+1,) [N], t [s]) -> ControlOutput``.

    Parameters
    ----------
    model : ReducedModel
        The model linearised at every solve.
    ctrl : ControllerParams
        Period [s], tension band [N], pressure band [Pa], input bounds [-].
    mpc : MpcParams
        Horizon, move blocking, weights and the OSQP settings.
    qp_solver : str
        CasADi QP plugin: ``"osqp"`` (default) or ``"qrqp"``.
    """

    def __init__(
        self,
        model: ReducedModel,
        ctrl: ControllerParams,
        mpc: MpcParams,
        qp_solver: str = QP_SOLVER,
    ) -> None:
        super().__init__(model, ctrl, mpc, build_ocp(model, ctrl, mpc, linear=True))
        self._lin = linearisation_function(model)
        qp = {"x": self.ocp.w, "p": self.ocp.p, "f": self.ocp.f, "g": self.ocp.g}
        if qp_solver == "osqp":
            opts: dict = osqp_options(mpc)
        else:
            opts = {"print_iter": False, "print_header": False, "max_iter": mpc.qp_max_iter}
        opts["error_on_fail"] = False
        self.solver = ca.qpsol("lmpc", qp_solver, qp, opts)

    def _parameters(self, x0: NDArray[np.float64], ref: NDArray[np.float64]) -> NDArray[np.float64]:
        """NMPC parameters plus the affine model at hold equilibrium at ref[0] [N]."""
        x_op = self.model.equilibrium(float(ref[0]))
        x_op[2] = self.theta[2] + float(ref[0]) / self.theta[1]  # y from the online k_eq, y0
        lin = np.array(self._lin(x_op, 0.0, self.theta)).ravel()
        return np.concatenate((super()._parameters(x0, ref), lin))

    def _solve(
        self, w0: NDArray[np.float64], p: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], bool, int]:
        return self._call_solver(self.solver, w0, p,
                                 lambda st: bool(st.get("success", False)))
