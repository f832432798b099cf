"""The per-step records are built positionally at 1 kHz for speed: the order each hot call
site writes is checked against the declared fields at import, and the values land in the
fields their names say (checked here against where each value comes from)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pytest

from trackmj.elements.hydraulic import HydraulicElement
from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.machines.idler import load_idler
from trackmj.ports import (
    Command,
    ControlOutput,
    ElementLog,
    StepInputs,
    check_order,
    positional,
)
from trackmj.sim.loop import _command
from trackmj.sim.loop_plants import CoupledPlant, EquivalentIdlerMechanics


class Pair(NamedTuple):
    first: float
    second: float


def test_positional_refuses_an_order_that_is_not_the_declared_one() -> None:
    build = positional(Pair, ("first", "second"))
    assert build(Pair, (1.0, 2.0)) == Pair(first=1.0, second=2.0)
    assert type(build(Pair, (1.0, 2.0))) is Pair
    with pytest.raises(TypeError, match="declares the fields"):
        positional(Pair, ("second", "first"))
    with pytest.raises(TypeError, match="declares the fields"):
        check_order(Pair, ("first",))


def test_the_loop_command_is_mode_u_solved() -> None:
    solved = ControlOutput(0.25)
    assert _command(Command, (1, 0.25, solved)) == Command(mode=1, u=0.25, solved=solved)


def test_readout_and_element_log_fields_hold_what_their_names_say() -> None:
    """A pressurising step of the hydraulic plugin on the equivalent idler: the readout's
    tension is the mechanics' applied force, its pressures and energies the element log's,
    its stroke and velocity the mechanics'; the log's force is the law at the end-of-step
    velocity the mechanics produced, its mean head pressure the two heads' mean."""
    hydraulics = load_hydraulic_params()
    idler = load_idler()
    stroke = 0.5 * hydraulics.cylinder.stroke_max_m
    force0 = 13e3
    y0 = stroke - force0 / idler.stiffness_N_m
    tensioner = HydraulicTensioner(hydraulics, stroke_m=stroke, head_pressure_Pa=(
        force0 + 2 * hydraulics.cylinder.area_rod_m2 * hydraulics.tank_pressure_Pa)
        / (2 * hydraulics.cylinder.area_head_m2))
    element = HydraulicElement(tensioner)
    mechanics = EquivalentIdlerMechanics(idler, y0, stroke, np.zeros(50))
    plant = CoupledPlant(mechanics, element)
    inputs = StepInputs(track_speed_m_s=0.0, hitch_pull_N=0.0, hitch_down_N=0.0,
                        supply_set_Pa=hydraulics.supply.setpoint_Pa)
    for _ in range(20):
        readout = plant.step(Command(mode=1, u=1.0, solved=None), inputs)
    log = element.log()
    assert isinstance(log, ElementLog)
    record = tensioner.record
    assert readout.t_s == log.t_s == pytest.approx(20e-3)
    assert readout.tension_N == mechanics.idler_force_N
    assert readout.stroke_m == mechanics.stroke_m
    assert readout.stroke_velocity_m_s == mechanics.stroke_velocity_m_s
    assert (readout.p_head_Pa, readout.p_rod_Pa, readout.p_supply_Pa) == (
        log.p_head_Pa, log.p_rod_Pa, log.p_supply_Pa)
    assert log.p_head_Pa == pytest.approx(0.5 * (record.p_head_L_Pa + record.p_head_R_Pa))
    assert (readout.e_supply_J, readout.p_work_J, readout.mech_work_J) == (
        log.supply_J, log.piston_work_J, log.mech_work_J)
    assert log.force_N == pytest.approx(mechanics.idler_force_N, rel=1e-9)
    assert log.q_supply_m3_s > 0.0 and log.supply_J > 0.0   # pressurising draws oil
    assert math.isnan(readout.chassis_acc_z_m_s2) and math.isnan(readout.closure_error_m)
