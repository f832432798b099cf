"""PID baseline on tension: anti-windup by back-calculation, derivative on the filtered
measurement, error dead band and output hysteresis, explicit dt = controller period [s].

The PID acts on the estimated tension through a first-order measurement filter
(``measurement_filter_s``), so that the track's tooth-passing ripple (~20 Hz) does not
switch the valves by itself.

Tuning rule (SIMC, Skogestad 2003, integrating plant with dead time): dF/dt = k' u with
k' [N/s per unit u] from ``ReducedModel.tension_rate_gain`` at the operating tension and the
effective dead time theta (solenoid delay + half the minimum hold + half the period, plus
the measurement filter's time constant: a lag counts as dead time):
Kc = 1 / (k' (tau_c + theta)) [1/N], Ti = 4 (tau_c + theta) [s]; Td = theta / 2 (assumed),
first-order measurement filter Tf = Td / N for the derivative; tracking time Tt = Ti / gain.

Noise and valve quantisation (one 30 ms dwell pulse moves the tension ~300 N on the identified
track, the tension estimate carries ~100 N rms after the period mean): the proportional
part counts errors inside +-``error_dead_band_N`` as zero, the integral takes the error as
it is (a dead-banded integral froze inside the band and left the offset there), and the
output is hysteretic: it leaves 0 only when |v| >= ``output_on`` and returns to 0 when
|v| < ``output_off``. The integral runs only while |error| <= ``integration_band_N``
(conditional integration): with integration during the whole rise the step overshot ~4 %
and settled in 1.8-2.5 s.

Feed-forward of the drive load (the estimate's sixth entry L [N], the measured sprocket
torque's idler load, :func:`~trackmj.control.model.drive_load_N`): in hold a load step ΔL
moves the tension by s·ΔL at once (s the reduced model's ``hold_load_share``). Like the MPCs,
the PID lets the tension ride the part of s·L the band cannot take when the load ends: that
allowance (:func:`~trackmj.control.governor.drive_load_allowance`) is added to its
reference, and feedback rejects the rest. L goes through the same measurement filter as the
tension (its torque is noisy). A derivative feed-forward (the opening −Δ(rejected)/(k'·dt)
per period) was tried and not kept: on M113's W1 the filtered load still moves a few hundred
newtons per period, and the pulses left a steady offset of 18 % (RMSE 2.43 kN against
0.78 kN with the allowance alone, 0.89 kN without either).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from trackmj.control.governor import drive_load_allowance, feasible_band, govern
from trackmj.control.model import ReducedModel
from trackmj.control.params import ControllerParams, PidParams, resolved
from trackmj.ports import ControllerStatistics, ControlOutput


class PidController:
    """PID on the estimated tension (see the module docstring):
    ``controller(estimate (4,)-(6,), reference_preview (1,) [N], t [s]) -> ControlOutput``.

    Parameters
    ----------
    model : ReducedModel
        Gives the tension of an estimate and the tension-rate gain the rule is tuned on.
    ctrl : ControllerParams
        Period [s] and input bounds [-].
    pid : PidParams
        Tuning-rule inputs, dead band, integration band, output hysteresis.
    operating_force_N : float
        Tension at which the tension-rate gain k' is evaluated for the tuning [N].
    """

    def __init__(
        self,
        model: ReducedModel,
        ctrl: ControllerParams,
        pid: PidParams,
        operating_force_N: float = 13.5e3,
    ) -> None:
        self.model, self.ctrl, self.pid = model, ctrl, pid
        self.dt = self.period_s = ctrl.period_s
        self.supply_pressure_Pa = model.p.supply_pressure_Pa
        self.horizon_steps = 0  # the PID acts on the current reference only
        k_rate = model.tension_rate_gain(operating_force_N)  # [N/s per unit u]
        theta = pid.dead_time_s + pid.measurement_filter_s   # a lag counts as dead time
        lam = pid.closed_loop_time_s + theta
        self.kc = 1.0 / (k_rate * lam)  # [1/N]
        self.ti = 4.0 * lam
        self.td = 0.5 * theta
        self.tf = self.td / pid.derivative_filter_N
        self.tt = self.ti / pid.back_calculation_gain
        self.integral = 0.0
        self.f_measured: float | None = None   # the tension through measurement_filter_s
        self.f_filtered: float | None = None   # ... and through the derivative filter Tf
        self.load_measured: float | None = None   # the drive load through the filter [N]
        self.u = 0.0

    def set_parameters(self, *, supply_pressure_Pa: float | None = None) -> None:
        """The controller port's parameter update: the supply pressure [Pa] the reference
        governor uses (the gains stay those of the tuning rule at the operating force)."""
        if supply_pressure_Pa is not None:
            self.supply_pressure_Pa = supply_pressure_Pa

    def statistics(self) -> ControllerStatistics:
        """The controller port's counts: a PID has no plan to fall back from (0)."""
        return ControllerStatistics()

    def _lag(self, previous: float | None, x: float, tau_s: float) -> float:
        """One period of the first-order lag with time constant ``tau_s`` [s] (backward
        Euler; 0: none) from ``previous`` (None: start at ``x``) towards ``x``."""
        if previous is None:
            return x
        return previous + self.dt / (tau_s + self.dt) * (x - previous)

    def _with_drive_load(self, estimate: NDArray, reference: NDArray, band_low_N: float
                         ) -> NDArray:
        """The reference (1,) [N] raised by the drive load's allowance (module docstring);
        L through the measurement filter; unchanged without a load."""
        if len(estimate) < 6:
            return reference
        self.load_measured = load = self._lag(self.load_measured, float(estimate[5]),
                                              self.pid.measurement_filter_s)
        held = self.model.hold_load_share(float(reference[0])) * load
        return reference + drive_load_allowance(reference, band_low_N, held)

    def __call__(self, estimate: NDArray, reference_preview: NDArray, t: float) -> ControlOutput:
        self.f_measured = f = self._lag(self.f_measured, self.model.force(estimate),
                                        self.pid.measurement_filter_s)
        band = feasible_band(self.ctrl, self.model.p, self.supply_pressure_Pa)
        reference = self._with_drive_load(
            estimate, np.asarray(reference_preview[:1], float), band[0])
        e_raw = float(govern(reference, band)[0]) - f
        e = math.copysign(max(abs(e_raw) - resolved(self.pid, "error_dead_band_N"), 0.0), e_raw)
        # conditional integration: the valve->tension plant is integrating, so the integral
        # is only needed against slow disturbances (leakage, supply), not to reach a step
        e_int = e_raw if abs(e_raw) <= resolved(self.pid, "integration_band_N") else 0.0
        # derivative on the first-order filtered measurement (Tf), backward difference
        f_prev = f if self.f_filtered is None else self.f_filtered
        self.f_filtered = self._lag(f_prev, f, self.tf)
        deriv = -self.kc * self.td * (self.f_filtered - f_prev) / self.dt
        v = self.kc * e + self.integral + deriv
        u_sat = min(self.ctrl.u_max, max(self.ctrl.u_min, v))
        self.integral += self.dt * (self.kc * e_int / self.ti + (u_sat - v) / self.tt)
        threshold = self.pid.output_off if self.u != 0.0 else self.pid.output_on
        self.u = u_sat if abs(u_sat) >= threshold else 0.0
        return ControlOutput(self.u)
