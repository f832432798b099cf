"""An FMU as the tensioner element (``ports.Element``), chosen by a tensioner file's ``[fmu]``
table (:mod:`trackmj.elements.tensioner_file`).

Coupling, from what the FMU offers (``FmuElement.coupling`` names it; metrics.json and the
run's summary state it):

* ``co-simulation, strong`` (the FMU can get and set its state): for the step from
  (t_k, s_k, v_k) the FMU is stepped over h with the predicted end-of-step velocity
  v* = 2·v_k − v_{k−1} (stroke s_k + h·v*) and rolled back, stepped with v* ± δv and
  rolled back: F(v) ≈ F(v*) + Z·(v − v*) with Z = (F(v*+δv) − F(v*−δv))/(2δv), handed to
  MuJoCo as F0 + Z·v; after the mechanics step it is stepped with the velocity the mechanics
  produced, v_{k+1} (stroke s_{k+1}), and that step is kept. The directional derivatives a
  co-simulation FMU may offer are instantaneous (∂y/∂u at fixed state), not the step's
  dF/dv through its states, so a difference is used: central, F(v* ± δv), since a forward
  secant's error (F''·δv/2, large where seal friction is smoothed over a few mm/s) made
  the round trip of the built-in plugin 100 times worse.
* ``model exchange, implicit``: trackmj integrates the FMU's states x with the mechanics by
  backward Euler over the 1 ms step, x_{k+1} = x_k + h·f(t_{k+1}, x_{k+1}, u(v)), Newton on
  x with the Jacobian from the FMU's directional derivatives where it provides them, finite
  differences otherwise; dx/dv from the same Jacobian gives Z = ∂F/∂x·dx/dv + ∂F/∂v, F0 + Z·v
  goes to MuJoCo, and the step is re-solved (chord) at v_{k+1}. Events: step events and
  time events are handled at the end of the step they fall in, state events (a sign change
  of an event indicator) likewise, without locating the crossing inside the step.
* ``co-simulation, weak`` (no state roll-back, or the tp-weak architecture): explicit, as
  tp-weak: the force of the last completed step is held over the next one (Z = 0), then the
  FMU is stepped with v_{k+1}. Its interface energy residual is not corrected.

Both strong couplings carry the interface energy residual r_k = (F_FMU(v_{k+1}) −
law(v_{k+1}))·v_{k+1}·h into the next law (NEPCE, bounded by ``max_correction_N``), as the
hydraulic plugin does. Booked: the work into the mechanics ∫law(v)·v dt, the residual, and
the FMU's own port power ∫P dt where it outputs one. Guards (a PhysicsError, the run stops
with exit 3): a non-finite output, |F| beyond ``force_limit_N``, the stroke outside
``travel_m``. A failing FMI call is an :class:`~trackmj.errors.FmuError` (exit 3).

Inputs are set before every step: stroke at the end of the step (less ``stroke_offset_m``),
the step's velocity, and the valve command (mode, u, supply set value) in force; in and
out, values are converted between SI and the units the FMU declares
(:class:`~trackmj.fmi.fmu.FmuInstance`).
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from trackmj.elements.cylinder import equivalent_cylinder, equivalent_pressures
from trackmj.errors import FmuError, PhysicsError
from trackmj.fmi.fmu import FmuDescription, FmuInstance
from trackmj.ports import COUPLING_STEP_S, Element, ElementLog, ForceLaw

if TYPE_CHECKING:
    from trackmj.elements.context import ElementContext
    from trackmj.elements.tensioner_file import FmuTable, TensionerFile

NAN = math.nan
MAX_NEWTON_ITER = 30
COUPLINGS = {
    "strong": "co-simulation, strong: predicted step, roll-back, central-difference dF/dv, "
              "re-step",
    "implicit": "model exchange, implicit: backward Euler on the FMU's states with the "
                "mechanics at 1 ms, Newton",
    "weak": "co-simulation, weak: the last step's force held (explicit exchange, as tp-weak)",
}
"""Coupling name -> what it does (stated in metrics.json)."""
PRESSURE_NODES = (("p_head_Pa", "head"), ("p_rod_Pa", "rod"), ("p_supply_Pa", "supply"))


class FmuElement:
    """The FMU of ``tensioner`` on the element port (see the module docstring).

    Parameters
    ----------
    tensioner : TensionerFile
        A loaded tensioner file with an ``[fmu]`` table (its FMU checked).
    stroke_m : float
        Initial stroke [m] (trackmj's).
    coupling : {"strong", "weak"}
        What the architecture asks for; "strong" gets the strongest the FMU offers.
    supply_Pa : float
        Supply set value before the first step [Pa gauge].
    equivalent : tuple of float, optional
        (lumped head area A_h [m²], lumped rod area A_r [m²], tank pressure p_t [Pa gauge])
        of the hydraulic file's cylinders. A chamber pressure the FMU does not output is
        logged (and measured by the sensors) as: the rod chamber at tank, p_t (a cylinder
        model without a rod-side pressure is taken as single-acting, its rod side vented
        to tank, as dp-b's rods are); the head chamber at the equivalent head pressure of
        the FMU's force, (F + A_r·p_rod)/A_h, with the rod pressure the FMU outputs or p_t.
        Without it (no hydraulic file: ``trackmj drive``) an unmapped rod pressure is
        0 gauge and an unmapped head pressure NaN (nothing measures it).
    """

    def __init__(self, tensioner: TensionerFile, stroke_m: float, coupling: str,
                 supply_Pa: float = 0.0,
                 equivalent: tuple[float, float, float] | None = None) -> None:
        table, d = tensioner.fmu, tensioner.description
        if table is None:
            raise ValueError(f"the tensioner file {tensioner.name} has no [fmu] table: it "
                             f"makes the element {tensioner.element!r}, not 'fmu'")
        self.table: FmuTable = table
        self.description: FmuDescription = d
        self.name = d.name
        if coupling == "weak":
            self.coupling = "weak"
        elif d.interface == "model-exchange":
            self.coupling = "implicit"
        else:
            self.coupling = "strong" if d.can_roll_back else "weak"
        self.h = COUPLING_STEP_S
        self.offset = table.stroke_offset_m
        lo, hi = table.travel_m
        self.stroke_range_m = (lo, hi)
        self.limit = table.force_limit_N
        self.equivalent = equivalent
        self.pressure_nodes = tuple(name for q, name in PRESSURE_NODES if q in d.outputs)
        self.inst = inst = FmuInstance(d)
        self._pressure_index = [inst.output_names.index(q) for q, _ in PRESSURE_NODES
                                if q in d.outputs]
        weakref.finalize(self, inst.close)
        self._valves: dict[str, float] = {"valve_mode": 0, "u": 0.0,
                                          "supply_pressure_Pa": supply_Pa}
        self.t_s, self.s, self.v_prev = 0.0, stroke_m, 0.0
        inst.start(0.0, self._valves | {"stroke_m": stroke_m - self.offset,
                                        "velocity_m_s": 0.0})
        names = inst.output_names
        self._i_force = names.index("force_N")
        self._i_power = names.index("port_power_W") if "port_power_W" in names else None
        self._outputs = self._checked(inst.real_outputs(), stroke_m)
        self.force_N = self._outputs[self._i_force]
        self._law = ForceLaw(self.force_N)
        self.carry_J = self.residual_J = self.mech_work_J = self.port_J = 0.0
        self.corrections = 0
        self.wall_s = 0.0
        self.steps = 0
        self.newton_iterations = 0
        self._saved: Any = None
        if self.coupling == "implicit":
            self._x = inst.states()
            self._nominal = [max(abs(n), 1e-12) for n in inst.nominals()] if inst.n_states \
                else []
            self._z = inst.event_indicators()
            self._jac: tuple[Any, ...] | None = None

    # ----------------------------------------------------------------- element port
    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """The valve command and supply set value the FMU sees on its next step."""
        self._valves = {"valve_mode": mode, "u": u, "supply_pressure_Pa": supply_set_Pa}

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        start = time.perf_counter()
        self.t_s, self.s = t_s, stroke_m
        if self.coupling == "weak":
            law = ForceLaw(self.force_N)
        else:
            v_star = 2.0 * velocity_m_s - self.v_prev
            if self.coupling == "strong":
                f_star, z = self._cs_linearise(t_s, stroke_m, v_star)
            else:
                f_star, z = self._me_linearise(t_s, stroke_m, v_star)
            law = ForceLaw(f_star - z * v_star + self._correction(velocity_m_s), z)
            if not math.isfinite(f_star + z):
                raise PhysicsError(f"t = {t_s:.3f} s: the FMU {self.name} output force_N = "
                                   f"{f_star!r}, dF/dv = {z!r} (non-finite) in the predicted "
                                   "step; the run left physics and was stopped")
        self.v_prev = velocity_m_s
        self._law = law
        self.wall_s += time.perf_counter() - start
        return law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        start = time.perf_counter()
        h = t_s - self.t_s
        if self.coupling == "implicit":
            outputs = self._me_complete(t_s, stroke_m, velocity_m_s)
        else:
            outputs = self._cs_step(self.t_s, h, stroke_m, velocity_m_s)
            if self._saved is not None:
                self.inst.free_state(self._saved)
                self._saved = None
        self._outputs = outputs = self._checked(outputs, stroke_m)
        force = outputs[self._i_force]
        applied = self._law.at(velocity_m_s)
        residual = (force - applied) * velocity_m_s * h
        self.residual_J += residual
        if self.coupling != "weak":
            self.carry_J += residual
        self.mech_work_J += applied * velocity_m_s * h
        if self._i_power is not None:
            self.port_J += outputs[self._i_power] * h
        self.force_N = force
        self.t_s, self.s = t_s, stroke_m
        self.steps += 1
        self.wall_s += time.perf_counter() - start

    def log(self) -> ElementLog:
        pressures = dict(zip(self.inst.output_names, self._outputs, strict=True))
        p_head, p_rod = pressures.get("p_head_Pa", NAN), pressures.get("p_rod_Pa", 0.0)
        if self.equivalent is not None:
            head, p_rod = equivalent_pressures(self.force_N, self.equivalent,
                                               pressures.get("p_rod_Pa"))
            p_head = pressures.get("p_head_Pa", head)
        return ElementLog(self.t_s, p_head, p_rod, pressures.get("p_supply_Pa", NAN), NAN,
                          self.force_N, NAN, NAN, self.mech_work_J)

    channels: ClassVar[Mapping[str, str]] = {}

    def channel_values(self) -> tuple[()]:
        return ()

    def node_pressures(self) -> list[float]:
        out = self._outputs
        return [out[i] for i in self._pressure_index]

    def run_metrics(self, duration_s: float) -> dict[str, Any]:
        """The coupling used and what it cost, the interface residual and the energy table
        (work into the mechanics, the residual, the FMU's port energy where it has one)."""
        d = self.description
        table: dict[str, Any] = {
            "fmu": True,
            "note": "no trackmj hydraulics: mechanical is the work into the track, "
                    "interface the coupling's residual, fmu_port the FMU's own port energy",
            "mechanical": self.mech_work_J, "interface": self.residual_J}
        if self._i_power is not None:
            table["fmu_port"] = self.port_J
        return {
            "tensioner": self.summary() | {
                "step_cost_us": 1e6 * self.wall_s / max(self.steps, 1),
                "newton_iterations_per_step": self.newton_iterations / max(self.steps, 1),
                "fmi_version": d.version, "interface": d.interface},
            "interface_energy_residual_J": self.residual_J,
            "energy_J": table,
        }

    def summary(self) -> dict[str, str]:
        """What the run's summary and metrics.json say about this element."""
        d = self.description
        jacobian = {"strong": "central difference", "weak": "none",
                    "implicit": "directional derivatives" if d.directional
                    else "finite differences"}[self.coupling]
        return {"element": "fmu", "fmu": d.name, "coupling": self.coupling,
                "coupling_description": COUPLINGS[self.coupling], "dF_dv": jacobian}

    # ----------------------------------------------------------------- internals
    def _checked(self, outputs: list[float], stroke_m: float) -> list[float]:
        """The physics guards on the FMU's outputs and the stroke."""
        names = self.inst.output_names
        for name, value in zip(names, outputs, strict=True):
            if not math.isfinite(value):
                raise PhysicsError(f"t = {self.t_s:.3f} s: the FMU {self.name} output "
                                   f"{name} = {value!r} (non-finite); the run left physics "
                                   "and was stopped")
        force = outputs[names.index("force_N")]
        if abs(force) > self.limit:
            raise PhysicsError(f"t = {self.t_s:.3f} s: the FMU {self.name} force "
                               f"{force / 1e3:.1f} kN exceeds the tensioner file's "
                               f"force_limit_N {self.limit / 1e3:.1f} kN; the run left physics "
                               "and was stopped")
        lo, hi = self.stroke_range_m
        if not lo <= stroke_m <= hi:
            raise PhysicsError(f"t = {self.t_s:.3f} s: stroke {stroke_m * 1e3:.1f} mm outside "
                               f"the FMU tensioner's travel [{lo * 1e3:.1f}, {hi * 1e3:.1f}] "
                               "mm; the run left physics and was stopped")
        return outputs

    def _correction(self, velocity_m_s: float) -> float:
        """NEPCE: the carried interface residual as a force over the coming step."""
        table = self.table
        if abs(velocity_m_s) < table.min_correction_velocity_m_s:
            return 0.0
        limit = table.max_correction_N
        self.corrections += 1
        return max(-limit, min(limit, self.carry_J / (self.h * velocity_m_s)))

    def _motion(self, stroke_end_m: float, velocity_m_s: float) -> dict[str, float]:
        return self._valves | {"stroke_m": stroke_end_m - self.offset,
                               "velocity_m_s": velocity_m_s}

    def _cs_step(self, t_s: float, h: float, stroke_end_m: float,
                 velocity_m_s: float) -> list[float]:
        inst = self.inst
        inst.set_inputs(self._motion(stroke_end_m, velocity_m_s))
        inst.do_step(t_s, h)
        return inst.real_outputs()

    def _cs_linearise(self, t_s: float, s: float, v_star: float) -> tuple[float, float]:
        inst, h, i = self.inst, self.h, self._i_force
        self._saved = state = inst.get_state()
        f_star = self._cs_step(t_s, h, s + h * v_star, v_star)[i]
        inst.set_state(state)
        dv = self.table.difference_velocity_m_s
        f_plus = self._cs_step(t_s, h, s + h * (v_star + dv), v_star + dv)[i]
        inst.set_state(state)
        f_minus = self._cs_step(t_s, h, s + h * (v_star - dv), v_star - dv)[i]
        inst.set_state(state)
        return f_star, (f_plus - f_minus) / (2.0 * dv)

    # model exchange
    def _me_eval(self, x: list[float], stroke_end_m: float,
                 velocity_m_s: float) -> tuple[np.ndarray, list[float]]:
        inst = self.inst
        inst.set_inputs(self._motion(stroke_end_m, velocity_m_s))
        if inst.n_states:
            inst.set_states(x)
            f = np.array(inst.derivatives())
        else:
            f = np.zeros(0)
        return f, inst.real_outputs()

    def _me_jacobian(self, x: list[float], s1: float, v: float, f0: np.ndarray,
                     out0: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(∂f/∂x (n, n), ∂F/∂x (n,), ∂f/∂v (n,), ∂F/∂v) at (x, v), the stroke moving h·dv
        with the velocity, F in N and v in m/s whatever units the FMU declares; directional
        derivatives (in the FMU's units, scaled) or forward differences."""
        inst, h, i = self.inst, self.h, self._i_force
        n = inst.n_states
        motion = [(q, c) for q, c in self.description.inputs.items()
                  if q in ("stroke_m", "velocity_m_s")]
        if self.description.directional:
            force = self.description.outputs["force_N"]
            unknowns = [*inst.derivative_vrs, force.vr]
            # column j of the Jacobian of (f, F) on the states, one call per state
            jac = np.array([inst.directional(unknowns, [inst.state_vrs[j]], [1.0])
                            for j in range(n)]).reshape(n, n + 1).T
            seed = [(h if q == "stroke_m" else 1.0) / c.factor for q, c in motion]
            col_v = np.array(inst.directional(unknowns, [c.vr for _, c in motion], seed))
            return jac[:n], force.factor * jac[n], col_v[:n], force.factor * float(col_v[n])
        a = np.zeros((n, n))
        dfx = np.zeros(n)
        for j in range(n):
            step = 1e-7 * max(abs(x[j]), self._nominal[j])
            xp = list(x)
            xp[j] += step
            fj, outj = self._me_eval(xp, s1, v)
            a[:, j] = (fj - f0) / step
            dfx[j] = (outj[i] - out0[i]) / step
        dv = self.table.difference_velocity_m_s
        fv, outv = self._me_eval(x, s1 + h * dv, v + dv)
        return a, dfx, (fv - f0) / dv, (outv[i] - out0[i]) / dv

    def _me_solve(self, x_guess: list[float], s1: float, v: float,
                  lu: np.ndarray | None) -> tuple[list[float], list[float], np.ndarray]:
        """Backward Euler on the states at velocity v (stroke s1 at the end of the step):
        chord Newton from ``x_guess`` with the iteration matrix ``lu`` (I − h·∂f/∂x; None:
        evaluated here). Returns (x_{k+1}, outputs there, the iteration matrix)."""
        h, x0, tol = self.h, np.array(self._x), self.table.newton_tol_rel
        x = np.array(x_guess, dtype=float)
        for _ in range(MAX_NEWTON_ITER):
            f, out = self._me_eval(x.tolist(), s1, v)
            if lu is None:
                a = self._me_jacobian(x.tolist(), s1, v, f, out)[0]
                lu = np.eye(len(x)) - h * a
            r = x - x0 - h * f
            scale = tol * np.maximum(np.abs(x), self._nominal)
            if np.all(np.abs(r) <= scale):
                return x.tolist(), out, lu
            self.newton_iterations += 1
            x = x - np.linalg.solve(lu, r)
        raise FmuError(f"the FMU {self.name}: backward Euler on its states did not converge "
                       f"in {MAX_NEWTON_ITER} Newton iterations at t = {self.t_s:.3f} s "
                       f"(v = {v:.4g} m/s)")

    def _me_linearise(self, t_s: float, s: float, v_star: float) -> tuple[float, float]:
        inst, h = self.inst, self.h
        inst.set_time(t_s + h)
        s1 = s + h * v_star
        if not inst.n_states:
            f, out = self._me_eval([], s1, v_star)
            _, _, _, dfdv = self._me_jacobian([], s1, v_star, f, out)
            self._jac = (None, v_star, [], np.zeros(0))
            return out[self._i_force], dfdv
        x1, out, lu = self._me_solve(self._x, s1, v_star, None)
        f1, out1 = self._me_eval(x1, s1, v_star)
        a, dfx, dfv, dFv = self._me_jacobian(x1, s1, v_star, f1, out1)
        lu = np.eye(len(x1)) - h * a
        dxdv = np.linalg.solve(lu, h * dfv)
        self._jac = (lu, v_star, x1, dxdv)
        return out[self._i_force], float(dfx @ dxdv + dFv)

    def _me_complete(self, t1: float, s1: float, v1: float) -> list[float]:
        inst = self.inst
        if self.coupling == "weak":
            inst.set_time(t1)
            if inst.n_states:
                x1, out, _ = self._me_solve(self._x, s1, v1, None)
            else:
                x1, out = [], self._me_eval([], s1, v1)[1]
        else:
            if self._jac is None:
                raise RuntimeError(f"the FMU element {self.name}: complete_step before the "
                                   "step's force_law")
            lu, v_star, x_star, dxdv = self._jac
            if inst.n_states:
                guess = (np.array(x_star) + dxdv * (v1 - v_star)).tolist()
                x1, out, _ = self._me_solve(guess, s1, v1, lu)
            else:
                x1, out = [], self._me_eval([], s1, v1)[1]
        if inst.n_states:
            inst.set_states(x1)
        self._x = x1
        self._handle_events(t1)
        return out

    def _handle_events(self, t1: float) -> None:
        """Step, time and state events at the end of the step (see the module docstring)."""
        inst = self.inst
        event = inst.completed_step() or inst.next_event_s <= t1 + 1e-12
        z = inst.event_indicators()
        if any((a > 0.0) != (b > 0.0) for a, b in zip(self._z, z, strict=True)):
            event = True
        if event:
            inst.handle_event()
            self._x = inst.states() if inst.n_states else []
            z = inst.event_indicators()
        self._z = z


def build(ctx: ElementContext) -> Element:
    """The FMU of the run's tensioner file on the mechanics' stroke; chamber pressures the
    FMU does not output are the rods at tank and the head at the equivalent of its force on
    the hydraulic file's cylinders (see :class:`FmuElement`)."""
    if ctx.tensioner is None:
        raise ValueError("the element 'fmu' needs a tensioner file with an [fmu] table")
    return FmuElement(ctx.tensioner, ctx.stroke_m, ctx.coupling, ctx.setup.supply0_Pa,
                      equivalent_cylinder(ctx.setup.hydraulics))
