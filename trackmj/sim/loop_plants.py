"""Plants of the closed loop (``ports.Plant``): mechanics + tensioner element, or the reduced
model integrated on its own.

* :class:`CoupledPlant`: valve command -> tensioner element (``ports.Element``) -> mechanics
  (the MuJoCo track, or :class:`EquivalentIdlerMechanics`) through the tensioner port.
* :class:`EquivalentIdlerMechanics`: dp-a's mechanics, the identified equivalent idler on the
  stroke with the track load replayed from a tp run.
* :class:`ReducedLoopPlant`: the controller's own reduced model as the plant (control tests).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from trackmj.control.model import ReducedPlant
from trackmj.control.params import PlantParams
from trackmj.machines.idler import EquivalentIdler
from trackmj.ports import (
    COUPLING_STEP_S,
    Command,
    Element,
    ElementLog,
    ForceLaw,
    Mechanics,
    Readout,
    StepInputs,
    TensionerElement,
    check_order,
    positional,
)

NAN = math.nan
_readout = positional(Readout, (
    "t_s", "tension_N", "p_head_Pa", "p_rod_Pa", "p_supply_Pa", "stroke_m",
    "stroke_velocity_m_s", "q_supply_m3_s", "e_supply_J", "p_work_J", "mech_work_J",
    "chassis_acc_z_m_s2", "closure_error_m", "drive_torque_N_m"))
"""Readout from its values in field order, checked against its fields at import."""
# the order CoupledPlant.step unpacks an element's log in, checked at import
check_order(ElementLog, ("t_s", "p_head_Pa", "p_rod_Pa", "p_supply_Pa", "q_supply_m3_s",
                         "force_N", "supply_J", "piston_work_J", "mech_work_J"))


class CoupledPlant:
    """Mechanics driven by a tensioner element through the element port.

    ``step(command, inputs)``: the element takes the valve command and the supply set value
    (solenoid delays inside), the mechanics its scenario inputs, then one coupling step
    exchanges the force law; the readout combines the element's log (pressures, supply,
    energies) with the mechanics' named readouts (applied force F_ten, stroke, chassis,
    closure).
    """

    def __init__(self, mechanics: Mechanics, element: Element) -> None:
        self.mechanics = mechanics
        self.element = element

    def step(self, command: Command, inputs: StepInputs) -> Readout:
        mech, element = self.mechanics, self.element
        element.set_valves(command.mode, command.u, inputs.supply_set_Pa)
        mech.apply(inputs)
        mech.step(element)
        t, p_head, p_rod, p_supply, q_supply, _, supply, piston, work = element.log()
        return _readout(Readout, (t, mech.idler_force_N, p_head, p_rod, p_supply,
                                  mech.stroke_m, mech.stroke_velocity_m_s, q_supply, supply,
                                  piston, work, mech.chassis_acc_z_m_s2,
                                  mech.closure_error_m, mech.drive_torque_N_m))


class EquivalentIdlerMechanics:
    """dp-a mechanics: M·ÿ = F(v) − k·(y − y0) − c·ẏ − d_k on the stroke y [m].

    ``load_N`` holds the track load d_k [N] acting over each step k, shape (steps,).
    Integrated like MuJoCo (semi-implicit Euler, the affine law and c implicit), so the
    tensioner port behaves the same: v_{k+1} solves M(v_{k+1} − v_k)/h = F0 + Z·v_{k+1}
    − k(y_k − y0) − c·v_{k+1} − d_k, then y_{k+1} = y_k + h·v_{k+1}. There is no chassis,
    no loop closure and no sprocket drive (their readouts are NaN: the drive's load is in
    the replayed d_k) and no MuJoCo (no warnings).
    """

    warning_count = 0
    chassis_acc_z_m_s2 = NAN
    closure_error_m = NAN
    drive_torque_N_m = NAN

    def __init__(self, idler: EquivalentIdler, y0_m: float, stroke_m: float,
                 load_N: NDArray[np.float64]) -> None:
        self.idler, self.y0 = idler, y0_m
        self.load_N = np.asarray(load_N, dtype=float).tolist()
        self.stroke_m, self.stroke_velocity_m_s, self.time_s = stroke_m, 0.0, 0.0
        self.idler_force_N = 0.0
        self.steps = 0

    def apply(self, inputs: StepInputs) -> None:
        """No scenario input acts here: the track's response is in the replayed load."""

    def step(self, element: TensionerElement) -> ForceLaw:
        h, m = COUPLING_STEP_S, self.idler.mass_kg
        k, c = self.idler.stiffness_N_m, self.idler.damping_N_s_m
        law = element.force_law(self.time_s, self.stroke_m, self.stroke_velocity_m_s)
        rhs = (m * self.stroke_velocity_m_s / h + law.force_N
               - k * (self.stroke_m - self.y0) - self.load_N[self.steps])
        v1 = rhs / (m / h - law.damping_N_s_m + c)
        self.stroke_velocity_m_s = v1
        self.stroke_m += h * v1
        self.time_s += h
        self.steps += 1
        self.idler_force_N = law.at(v1)
        element.complete_step(self.time_s, self.stroke_m, v1)
        return law


class ReducedLoopPlant:
    """The reduced prediction model as the plant (``control.model.ReducedPlant``, RK4):
    the applied valve mode is its opening, the step's supply set value its supply.

    Readout pressures, stroke and velocity are the true model state; the tension is
    F_ten = p_h·A_h − p_r·A_r; no supply node, energies, chassis, closure or drive (NaN).
    """

    def __init__(self, params: PlantParams, x0: NDArray[np.float64]) -> None:
        self.plant = ReducedPlant(params, x0, COUPLING_STEP_S)

    @property
    def state(self) -> NDArray[np.float64]:
        """True state (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s]), shape (4,)."""
        return self.plant.x

    def step(self, command: Command, inputs: StepInputs) -> Readout:
        x = self.plant.step(float(command.mode), inputs.supply_set_Pa)
        return Readout(t_s=self.plant.t, tension_N=self.plant.force, p_head_Pa=float(x[0]),
                       p_rod_Pa=float(x[1]), p_supply_Pa=inputs.supply_set_Pa,
                       stroke_m=float(x[2]), stroke_velocity_m_s=float(x[3]),
                       q_supply_m3_s=NAN, e_supply_J=NAN, p_work_J=NAN, mech_work_J=NAN,
                       chassis_acc_z_m_s2=NAN, closure_error_m=NAN, drive_torque_N_m=NAN)
