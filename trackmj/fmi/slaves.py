"""The Python side of trackmj's exported FMUs (pythonfmu ``Fmi2Slave`` classes), run inside
the importing tool through the FMU's embedded Python (see :mod:`trackmj.fmi.export`).

* :class:`TrackSlave`: the machine's MuJoCo track with the tensioner port as inputs
  (``force_N`` + ``force_dv_N_s_m``·v, the affine law over each 1 ms step) and the scenario
  inputs (track speed, hitch load); outputs stroke, velocity, the applied tension, chassis
  vertical acceleration, strand tensions and the derailment indicators.
* :class:`PlantSlave`: the track with the built-in hydraulics (tp, strong coupling): valve
  command (and the supply set value: 0, the default, is the hydraulic file's nominal) in,
  the sensor signals (noisy, the control file's sensor model and the seed) and
  the true tension and pressures out.

A communication step is any integer multiple of 1 ms (a doStep of another length fails).
Both save and restore their state (canGetAndSetFMUstate: a copy of the MuJoCo state and,
for the plant, of the hydraulics), so an importer can roll back and couple strongly.
Parameters (set before initialisation): ``machine`` (a shipped machine's name, default
"lf1352", a machine file ``*_machine.toml``, or a model parameter file), ``terrain``
("flat", or a scenario name or file whose road profile is used, drawn from ``seed``),
``seed``; the plant also ``scenario`` (its initial tension and supply model; default W1).
"""

from __future__ import annotations

import copy
import math
from typing import TYPE_CHECKING, Any, TypedDict

import mujoco
import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String

from trackmj.control.sensors import Sensors
from trackmj.elements.hydraulic import HydraulicElement
from trackmj.elements.prescribed import ConstantForce
from trackmj.machines.assembly import MACHINE_SUFFIX, names
from trackmj.ports import COUPLING_STEP_S, Command, Readout, StepInputs
from trackmj.sim.architectures import Assembly, assemble
from trackmj.sim.mechanics import settled_track
from trackmj.sim.setup import RunSetup, prepare

if TYPE_CHECKING:
    from trackmj.hydraulics.tensioner import HydraulicTensioner
    from trackmj.track.plant import TrackPlant

TRACK_INPUTS = ("force_N", "force_dv_N_s_m", "track_speed_m_s", "hitch_pull_N", "hitch_down_N")
TRACK_OUTPUTS = ("stroke_m", "velocity_m_s", "tension_N", "chassis_acc_z_m_s2",
                 "drive_torque_N_m", "upper_strand_tension_N", "lower_strand_tension_N",
                 "max_envelope_excursion_m", "closure_error_m")
DERAILMENT_OUTPUTS = ("sprocket_disengaged", "links_off_envelope", "slack_strand",
                      "derailed")
PLANT_INPUTS = ("track_speed_m_s", "hitch_pull_N", "hitch_down_N")
PLANT_OUTPUTS = ("p_head_measured_Pa", "p_rod_measured_Pa", "stroke_measured_m",
                 "drive_torque_measured_N_m", "tension_N", "p_head_Pa", "p_rod_Pa",
                 "p_supply_Pa", "stroke_m", "velocity_m_s", "chassis_acc_z_m_s2")


class MachineFiles(TypedDict):
    """The machine arguments of :func:`trackmj.sim.setup.prepare`: a machine (name or file)
    or a model parameter file on the default machine (None: not given)."""

    machine: str | None
    model: str | None


TrackState = tuple[Any, ...]
"""A saved track: MjData copy, actuator bias parameters, the ground's memory (shear
displacements, contact history), clock, last force law, speed
command, hitch flag (opaque to the importer)."""

PlantState = tuple[TrackState, "HydraulicTensioner", "Sensors", "int | None", dict[str, Any]]
"""A saved plant: the track, copies of the hydraulics and of the sensors (their noise
generator), the element's last valve mode and the outputs."""


def machine_files(machine: str) -> MachineFiles:
    """``prepare`` arguments for the FMU parameter ``machine``: a shipped machine's name
    ("" the default, lf1352) or a machine file (``*_machine.toml``) through the machine
    registry (:func:`trackmj.machines.assembly.resolve`); any other TOML is a model parameter file
    on the default machine. The one place the FMUs resolve a machine."""
    text = machine.strip()
    if not text or text.lower() in names() or text.endswith(MACHINE_SUFFIX):
        return {"machine": text or None, "model": None}
    return {"machine": None, "model": text}


def _steps(step_size: float) -> int:
    ratio = step_size / COUPLING_STEP_S
    n = round(ratio)
    if n < 1 or abs(ratio - n) > 1e-6:
        raise ValueError(f"communication step {step_size} s: must be an integer multiple of "
                         f"{COUPLING_STEP_S} s")
    return n


class _Base(Fmi2Slave):
    """Parameters, variable registration and state save/restore of both slaves."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.machine, self.terrain, self.seed = "lf1352", "flat", 0
        self.register_variable(String("machine", causality=Fmi2Causality.parameter,
                                      variability=Fmi2Variability.fixed,
                                      description="machine: a shipped name (lf1352), a "
                                                  "*_machine.toml or a model TOML"))
        self.register_variable(String("terrain", causality=Fmi2Causality.parameter,
                                      variability=Fmi2Variability.fixed,
                                      description="flat, or a scenario whose road is used"))
        self.register_variable(Integer("seed", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed,
                                       description="terrain (and sensor noise) seed"))
        self.plant: TrackPlant | None = None

    def _real(self, names, causality, default=0.0):
        for name in names:
            setattr(self, name, default)
            self.register_variable(Real(name, causality=causality))

    def _track(self) -> TrackPlant:
        """The track, built when initialisation ends; RuntimeError before."""
        if self.plant is None:
            raise RuntimeError(f"{type(self).__name__}: no track before "
                               "exit_initialization_mode")
        return self.plant

    def _setup(self, scenario: str) -> RunSetup:
        name = scenario if self.terrain in ("", "flat") else self.terrain
        return prepare(name, seed=int(self.seed), **machine_files(self.machine))

    def _outputs_track(self, plant: TrackPlant, derailment: bool) -> None:
        self.stroke_m = plant.stroke_m
        self.velocity_m_s = plant.stroke_velocity_m_s
        self.tension_N = plant.idler_force_N
        self.chassis_acc_z_m_s2 = plant.chassis_acc_z_m_s2
        self.drive_torque_N_m = plant.drive_torque_N_m
        if derailment:
            strands = plant.strand_tensions_N()
            self.upper_strand_tension_N = strands.upper_N
            self.lower_strand_tension_N = strands.lower_N
            status = plant.derailment()
            self.sprocket_disengaged = status.sprocket_disengaged
            self.links_off_envelope = status.links_off_envelope
            self.slack_strand = status.slack_strand
            self.derailed = status.any
            self.max_envelope_excursion_m = status.max_envelope_excursion_m
            self.closure_error_m = plant.closure_error_m

    def _track_state(self, plant: TrackPlant) -> TrackState:
        return (copy.copy(plant.data), plant.model.actuator_biasprm.copy(),
                plant.foundation.memory.copy(), plant.time_s, plant.last_law,
                plant._speed_command, plant._hitch_loaded)

    def _restore_track(self, plant: TrackPlant, state: TrackState) -> None:
        data, biasprm, memory, plant.time_s, plant.last_law, speed, loaded = state
        mujoco.mj_copyData(plant.data, plant.model, data)
        plant.model.actuator_biasprm[:] = biasprm
        plant.foundation.memory[:] = memory
        plant._speed_command, plant._hitch_loaded = speed, loaded


class TrackSlave(_Base):
    """The track with the tensioner port as inputs (see the module docstring)."""

    description = ("trackmj: one track side (MuJoCo) with the tensioner port as inputs; "
                   "force F = force_N + force_dv_N_s_m * v over each 1 ms step, > 0 pushes "
                   "the idler outward")

    # inputs, registered by _real and set by the importer (force_N is set in __init__)
    force_dv_N_s_m: float
    track_speed_m_s: float
    hitch_pull_N: float
    hitch_down_N: float

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._real(TRACK_INPUTS, Fmi2Causality.input)
        self.force_N = 13e3
        self._real(TRACK_OUTPUTS, Fmi2Causality.output, math.nan)
        for name in DERAILMENT_OUTPUTS:
            setattr(self, name, False)
            self.register_variable(Boolean(name, causality=Fmi2Causality.output,
                                           variability=Fmi2Variability.discrete))

    def exit_initialization_mode(self):
        self.plant = settled_track(self._setup("W1"), self.force_N)
        self._element = ConstantForce
        self._outputs_track(self.plant, True)

    def do_step(self, current_time, step_size):
        plant = self._track()
        element = self._element(self.force_N, -self.force_dv_N_s_m)
        inputs = StepInputs(self.track_speed_m_s, self.hitch_pull_N, self.hitch_down_N,
                            math.nan)
        for _ in range(_steps(step_size)):
            plant.apply(inputs)
            plant.step(element)
        self._outputs_track(plant, True)
        return True

    # the state is this tuple (pythonfmu keeps it opaque), not pythonfmu's dict of variables
    def _get_fmu_state(self) -> tuple[TrackState, dict[str, Any]]:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque tuple state
        return self._track_state(self._track()), {n: getattr(self, n) for n in
                                                   (*TRACK_OUTPUTS, *DERAILMENT_OUTPUTS)}

    def _set_fmu_state(self, state: tuple[TrackState, dict[str, Any]]) -> None:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque tuple state
        track, outputs = state
        self._restore_track(self._track(), track)
        for name, value in outputs.items():
            setattr(self, name, value)


class PlantSlave(_Base):
    """The track with the built-in hydraulics (see the module docstring)."""

    description = ("trackmj: one track side (MuJoCo) with the built-in hydraulic tensioner, "
                   "strong coupling; valve command in, sensor signals out")

    # inputs, registered by _real and set by the importer
    supply_pressure_set_Pa: float
    track_speed_m_s: float
    hitch_pull_N: float
    hitch_down_N: float
    asm: Assembly
    sensors: Sensors

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.scenario = "W1"
        self.register_variable(String("scenario", causality=Fmi2Causality.parameter,
                                      variability=Fmi2Variability.fixed,
                                      description="scenario of the initial tension and "
                                                  "supply"))
        self.valve_mode = 0
        self.register_variable(Integer("valve_mode", causality=Fmi2Causality.input,
                                       variability=Fmi2Variability.discrete,
                                       description="+1 pressurize, 0 hold, -1 release"))
        self._real(("supply_pressure_set_Pa",), Fmi2Causality.input, 0.0)
        self._real(PLANT_INPUTS, Fmi2Causality.input)
        self._real(PLANT_OUTPUTS, Fmi2Causality.output, math.nan)

    def exit_initialization_mode(self):
        terrain = None if self.terrain in ("", "flat") else self.terrain
        setup = prepare(terrain or self.scenario, **machine_files(self.machine),
                        seed=int(self.seed))
        self.asm = asm = assemble(setup)
        if asm.track is None:
            raise ValueError(f"{setup.architecture}: the plant FMU needs the MuJoCo track")
        self.plant = track = asm.track
        self._nominal_supply_Pa = setup.supply0_Pa
        self.sensors = Sensors(asm.control.sensors, np.random.default_rng([int(self.seed), 1]))
        _, p_head_l, p_head_r, p_rod, p_supply = asm.element.node_pressures()
        self._read(Readout(0.0, setup.force0_N, 0.5 * (p_head_l + p_head_r), p_rod, p_supply,
                           track.stroke_m, track.stroke_velocity_m_s, 0.0, 0.0, 0.0, 0.0,
                           track.chassis_acc_z_m_s2, track.closure_error_m,
                           track.drive_torque_N_m))

    def _inputs(self) -> StepInputs:
        supply = self.supply_pressure_set_Pa
        return StepInputs(self.track_speed_m_s, self.hitch_pull_N, self.hitch_down_N,
                          supply if supply > 0.0 else self._nominal_supply_Pa)

    def _read(self, r: Readout) -> None:
        z = self.sensors.measure((r.p_head_Pa, r.p_rod_Pa, r.stroke_m), r.drive_torque_N_m)
        (self.p_head_measured_Pa, self.p_rod_measured_Pa, self.stroke_measured_m,
         self.drive_torque_measured_N_m) = z.tolist()
        self.tension_N, self.p_head_Pa, self.p_rod_Pa = r.tension_N, r.p_head_Pa, r.p_rod_Pa
        self.p_supply_Pa, self.stroke_m = r.p_supply_Pa, r.stroke_m
        self.velocity_m_s, self.chassis_acc_z_m_s2 = r.stroke_velocity_m_s, r.chassis_acc_z_m_s2

    def do_step(self, current_time, step_size):
        mode = int(self.valve_mode)
        if mode not in (-1, 0, 1):
            raise ValueError(f"valve_mode = {mode}: must be +1, 0 or -1")
        command = Command(mode, float(mode), None)
        steps = _steps(step_size)
        readout = self.asm.plant.step(command, self._inputs())
        for _ in range(steps - 1):
            readout = self.asm.plant.step(command, self._inputs())
        self._read(readout)
        return True

    def _hydraulic_element(self) -> HydraulicElement:
        """The run's element, the built-in hydraulics (tp); TypeError for another."""
        element = self.asm.element
        if not isinstance(element, HydraulicElement):
            raise TypeError(f"the plant FMU saves the built-in hydraulic element, not "
                            f"{type(element).__name__}")
        return element

    # the state is this tuple (pythonfmu keeps it opaque), not pythonfmu's dict of variables
    def _get_fmu_state(self) -> PlantState:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque tuple state
        element = self._hydraulic_element()
        return (self._track_state(self._track()), copy.deepcopy(element.tensioner),
                copy.deepcopy(self.sensors), element._mode,
                {n: getattr(self, n) for n in PLANT_OUTPUTS})

    def _set_fmu_state(self, state: PlantState) -> None:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque tuple state
        track, tensioner, sensors, mode, outputs = state
        self._restore_track(self._track(), track)
        element = HydraulicElement(copy.deepcopy(tensioner))
        element._mode = mode
        self.asm.element = self.asm.plant.element = element
        self.sensors = copy.deepcopy(sensors)
        for name, value in outputs.items():
            setattr(self, name, value)
