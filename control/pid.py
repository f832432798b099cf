"""PID baseline on tension: anti-windup by back-calculation, filtered derivative on the
measurement, explicit dt [s]. Tuning: SIMC rule for an integrating plant with dead time,
dF/dt = k' u (k' from ``ReducedModel.tension_rate_gain``): Kc = 1/(k' (tau_c + theta)),
Ti = 4 (tau_c + theta); Td = theta/2 (assumed, filter Td/N)."""

from __future__ import annotations

from numpy.typing import NDArray

from trackmj.control.interface import ControlOutput
from trackmj.control.model import ReducedModel
from trackmj.control.params import ControllerParams, PidParams


class PidController:
    """``controller(estimate (4,), reference_preview (N+1,) [N], t) -> ControlOutput``."""

    def __init__(
        self,
        model: ReducedModel,
        ctrl: ControllerParams,
        pid: PidParams,
        operating_force_N: float = 13.5e3,
    ) -> None:
        self.model, self.ctrl = model, ctrl
        self.dt = ctrl.period_s
        k_rate = model.tension_rate_gain(operating_force_N)  # [N/s per unit u]
        lam = pid.closed_loop_time_s + pid.dead_time_s
        self.kc = 1.0 / (k_rate * lam)  # [1/N]
        self.ti = 4.0 * lam
        self.td = 0.5 * pid.dead_time_s
        self.tf = self.td / pid.derivative_filter_N
        self.tt = self.ti / pid.back_calculation_gain
        self.integral = 0.0
        self.deriv = 0.0
        self._f_prev: float | None = None

    def __call__(self, estimate: NDArray, reference_preview: NDArray, t: float) -> ControlOutput:
        f = self.model.force(estimate)
        e = float(reference_preview[0]) - f
        if self._f_prev is not None:
            self.deriv = (self.tf * self.deriv - self.kc * self.td * (f - self._f_prev)) / (
                self.tf + self.dt
            )
        self._f_prev = f
        v = self.kc * e + self.integral + self.deriv
        u = min(self.ctrl.u_max, max(self.ctrl.u_min, v))
        self.integral += self.dt * (self.kc * e / self.ti + (u - v) / self.tt)
        return ControlOutput(u)
