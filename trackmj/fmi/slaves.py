"""The Python side of trackmj's plant FMU (a pythonfmu ``Fmi2Slave``), run inside the
importing tool through the FMU's embedded Python (see :mod:`trackmj.fmi.export`).

:class:`PlantSlave`: one track side (MuJoCo) with the built-in hydraulics (tp, strong
coupling): valve command, supply set value and the scenario inputs in; the sensor signals
(noisy: the control file's sensor model, drawn from ``seed``), the true tension, pressures,
stroke and chassis acceleration out. :data:`SIGNALS` is its variables' one table (name, SI
unit, description, allowed range): the slave registers and checks its variables from it,
the export declares their units and ranges from it.

A communication step is any positive integer multiple of 1 ms that starts where the last one
ended. The plant is built from the parameters when a value needs it (an output read in
initialization mode, or the end of initialization), so outputs read in initialization mode
are the initial state's. State save and restore (a copy of the MuJoCo state, the hydraulics,
the sensors' noise generator, the clock) and state serialisation (that copy pickled behind a
header naming this trackmj version) let an importer roll back and couple strongly.

The error contract: pythonfmu 0.7 turns a Python exception into fmi2Fatal and releases the
slave, so nothing here raises into pythonfmu. A refused value, a refused doStep or a physics
stop logs an error-level message (the variable and its allowed range, or the time and the
quantity) and leaves the slave usable; the FMU's binary layer (:mod:`trackmj.fmi.export`)
makes a call during which an error was logged return fmi2Error.
"""

from __future__ import annotations

import copy
import functools
import math
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from trackmj.control.sensors import Sensors
from trackmj.elements.hydraulic import HydraulicElement
from trackmj.errors import PhysicsError
from trackmj.machines.assembly import MACHINE_SUFFIX, names
from trackmj.ports import COUPLING_STEP_S, Command, Readout, StepInputs
from trackmj.scenarios.load import builtin_names
from trackmj.scenarios.schema import TRACK_SPEED_MAX_M_S
from trackmj.sim.architectures import Assembly, assemble
from trackmj.sim.observers import PhysicsGuard, PhysicsLimits, capture_mujoco_warnings
from trackmj.sim.run import physics_limits
from trackmj.sim.setup import prepare
from trackmj.track.plant import PlantSnapshot
from trackmj.version import __version__

if TYPE_CHECKING:
    from trackmj.hydraulics.tensioner import HydraulicTensioner
    from trackmj.track.plant import TrackPlant

TIME_TOLERANCE_S = 1e-6
"""How far a doStep's start may lie from the end of the last one [s]: far above a host's
accumulated rounding of t += h, far below one skipped or repeated 1 ms step."""
STATE_HEADER = f"trackmj {__version__} plant FMU state\n".encode()
"""The first bytes of a serialised state; other bytes are refused, not unpickled."""


@dataclass(frozen=True)
class Signal:
    """One variable of the plant FMU: ``kind`` its FMI type, ``unit`` an FMI unit name
    (declared by the export; None for the non-Real variables, which FMI 2.0 gives no unit),
    ``minimum``/``maximum`` the range a setter accepts (None: any finite value)."""

    name: str
    kind: type[Real] | type[Integer] | type[String]
    causality: Fmi2Causality
    unit: str | None
    description: str
    minimum: float | None = None
    maximum: float | None = None

    def allowed(self) -> str:
        """A Real input's allowed values in words, for error messages."""
        low, high = self.minimum, self.maximum
        if low is not None and high is not None:
            return f"allowed a finite value in [{low:g}, {high:g}]"
        return "allowed a finite value" + ("" if low is None else f" >= {low:g}") + (
            "" if high is None else f" <= {high:g}")


_PARAMETER, _INPUT, _OUTPUT = Fmi2Causality.parameter, Fmi2Causality.input, Fmi2Causality.output

PARAMETERS = (
    Signal("machine", String, _PARAMETER, None,
           "the machine: a shipped machine's name (default lf1352), a machine file "
           f"*{MACHINE_SUFFIX}, or a model parameter TOML on the default machine"),
    Signal("terrain", String, _PARAMETER, None,
           "flat (default: the run is set up by scenario), or a scenario (built-in name or "
           "file) whose setup, road profile included, is used instead of scenario's"),
    Signal("seed", Integer, _PARAMETER, None,
           "seed of the road profile and of the sensor noise; >= 0", 0),
    Signal("scenario", String, _PARAMETER, None,
           "scenario (built-in W1..W5, NL1, or a scenario file) that sets the initial "
           "tension and the supply model; default W1"),
)
INPUTS = (
    Signal("valve_mode", Integer, _INPUT, None,
           "valve command: +1 pressurize (supply to the heads), 0 hold, -1 release (heads "
           "to tank); held over each step", -1, 1),
    Signal("supply_pressure_set_Pa", Real, _INPUT, "Pa",
           "supply pressure set value (gauge); 0 (default): the hydraulic file's nominal", 0.0),
    Signal("track_speed_m_s", Real, _INPUT, "m/s",
           "sprocket pitch-line speed command of the drive's velocity servo; > 0 drives the "
           f"vehicle forward; |v| <= {TRACK_SPEED_MAX_M_S:g} m/s (a scenario's range)",
           -TRACK_SPEED_MAX_M_S, TRACK_SPEED_MAX_M_S),
    Signal("hitch_pull_N", Real, _INPUT, "N",
           "load on the rear hitch along the chassis x axis; > 0 pulls rearward (a towed "
           "implement), < 0 pushes"),
    Signal("hitch_down_N", Real, _INPUT, "N",
           "load on the rear hitch along the chassis z axis; > 0 pushes down"),
)
OUTPUTS = (
    Signal("p_head_measured_Pa", Real, _OUTPUT, "Pa",
           "head pressure as its sensor reads it (gauge; the control file's sensor noise)"),
    Signal("p_rod_measured_Pa", Real, _OUTPUT, "Pa",
           "rod pressure as its sensor reads it (gauge; the control file's sensor noise)"),
    Signal("stroke_measured_m", Real, _OUTPUT, "m",
           "tensioner stroke as its sensor reads it (the control file's sensor noise)"),
    Signal("drive_torque_measured_N_m", Real, _OUTPUT, "N.m",
           "sprocket drive torque as its sensor reads it (the control file's sensor noise)"),
    Signal("tension_N", Real, _OUTPUT, "N",
           "tensioner force on the idler carrier over the last step; > 0 pushes outward"),
    Signal("p_head_Pa", Real, _OUTPUT, "Pa", "head chamber pressure, mean of the two "
                                             "cylinders (gauge)"),
    Signal("p_rod_Pa", Real, _OUTPUT, "Pa", "rod chamber pressure (gauge)"),
    Signal("p_supply_Pa", Real, _OUTPUT, "Pa", "supply node pressure (gauge)"),
    Signal("stroke_m", Real, _OUTPUT, "m", "tensioner stroke, grows outward (tensioning)"),
    Signal("velocity_m_s", Real, _OUTPUT, "m/s", "tensioner stroke velocity"),
    Signal("chassis_acc_z_m_s2", Real, _OUTPUT, "m/s2",
           "vertical chassis acceleration over the last step"),
)
SIGNALS = PARAMETERS + INPUTS + OUTPUTS
"""Every variable of the plant FMU, in value-reference order."""


class MachineFiles(TypedDict):
    """The machine arguments of :func:`trackmj.sim.setup.prepare`: a machine (name or file)
    or a model parameter file on the default machine (None: not given)."""

    machine: str | None
    model: str | None


def machine_files(machine: str) -> MachineFiles:
    """``prepare`` arguments for the FMU parameter ``machine``: a shipped machine's name
    ("" the default, lf1352) or a machine file (``*_machine.toml``) through the machine
    registry (:func:`trackmj.machines.assembly.resolve`); any other TOML is a model parameter
    file on the default machine. The one place the FMU resolves a machine."""
    text = machine.strip()
    if not text or text.lower() in names() or text.endswith(MACHINE_SUFFIX):
        return {"machine": text or None, "model": None}
    return {"machine": None, "model": text}


def _machine_refused(value: str) -> str | None:
    """Why ``value`` is no machine (None: it is one)."""
    text = value.strip()
    if not text or text.lower() in names() or (text.endswith(".toml") and Path(text).is_file()):
        return None
    return (f"allowed a shipped machine ({', '.join(names())}), or an existing machine file "
            f"*{MACHINE_SUFFIX} or model parameter file *.toml")


def _scenario_refused(value: str, flat: bool) -> str | None:
    """Why ``value`` is no scenario (None: it is one; ``flat``: "flat" and "" are too)."""
    text = value.strip()
    builtin = builtin_names()
    if (flat and text.lower() in ("", "flat")) or text.upper() in {n.upper() for n in builtin} \
            or (text.endswith(".toml") and Path(text).is_file()):
        return None
    return ("allowed " + ("flat, " if flat else "") + f"a built-in scenario "
            f"({', '.join(builtin)}) or an existing scenario file *.toml")


@dataclass(frozen=True)
class PlantState:
    """A saved plant FMU (opaque to the importer): the parameters it was built from, the
    track, copies of the hydraulics and the sensors (their noise generator), the element's
    last valve mode, the inputs and outputs, the clock (start [s], 1 ms steps since) and why
    it stopped (None: running)."""

    parameters: dict[str, str | int]
    track: PlantSnapshot
    tensioner: HydraulicTensioner
    sensors: Sensors
    mode: int | None
    inputs: dict[str, float]
    valve_mode: int
    outputs: dict[str, float]
    start_s: float
    steps: int
    stopped: str | None


@dataclass(frozen=True)
class UnreadableState:
    """What deserialising bytes that are no plant state gives (the restore then fails)."""

    reason: str


@dataclass
class _Built:
    """The plant built from the parameters: the run's assembly, its MuJoCo track and
    hydraulic element, the sensors, the nominal supply [Pa gauge], the physics limits."""

    asm: Assembly
    track: TrackPlant
    element: HydraulicElement
    sensors: Sensors
    nominal_supply_Pa: float
    limits: PhysicsLimits


class PlantSlave(Fmi2Slave):
    """The track with the built-in hydraulics (see the module docstring)."""

    description = ("trackmj: one track side (MuJoCo) with the built-in hydraulic tensioner, "
                   "strong coupling; valve command in, sensor signals out")

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._parameters: dict[str, str | int] = {"machine": "lf1352", "terrain": "flat",
                                                  "seed": 0, "scenario": "W1"}
        self._inputs: dict[str, float] = {s.name: 0.0 for s in INPUTS if s.kind is Real}
        self._valve_mode = 0
        self._outputs: dict[str, float] = {s.name: math.nan for s in OUTPUTS}
        self._built: _Built | None = None
        self._initialized = False
        self._start_s, self._steps = 0.0, 0
        self._stopped: str | None = None
        for signal in SIGNALS:
            self.register_variable(signal.kind(
                signal.name, causality=signal.causality, description=signal.description,
                variability=(Fmi2Variability.fixed if signal.causality == _PARAMETER else
                             Fmi2Variability.discrete if signal.kind is Integer else
                             Fmi2Variability.continuous),
                getter=functools.partial(self._get, signal),
                setter=functools.partial(self._set, signal)))

    # ---- values -------------------------------------------------------------------------

    def _error(self, message: str) -> None:
        """Report a refused call (the binary layer returns fmi2Error for it)."""
        self.log(message, Fmi2Status.error)

    def _get(self, signal: Signal) -> str | int | float:
        if signal.causality == _PARAMETER:
            return self._parameters[signal.name]
        if signal.name == "valve_mode":
            return self._valve_mode
        if signal.causality == _INPUT:
            return self._inputs[signal.name]
        return self._outputs[signal.name] if self._plant() is not None else math.nan

    def _set(self, signal: Signal, value: str | int | float) -> None:
        if signal.causality == _OUTPUT:
            self._error(f"{signal.name} is an output: it cannot be set")
        elif signal.causality == _PARAMETER:
            self._set_parameter(signal, value)
        elif signal.name == "valve_mode":
            if value not in (-1, 0, 1):
                self._error(f"valve_mode = {value}: allowed -1 (release), 0 (hold), "
                            "+1 (pressurize)")
                return
            self._valve_mode = int(value)
        else:
            number = float(value)
            if not math.isfinite(number) or (
                    signal.minimum is not None and number < signal.minimum) or (
                    signal.maximum is not None and number > signal.maximum):
                self._error(f"{signal.name} = {number!r} {signal.unit}: {signal.allowed()}")
                return
            self._inputs[signal.name] = number

    def _set_parameter(self, signal: Signal, value: str | int | float) -> None:
        name = signal.name
        if self._initialized:
            self._error(f"{name} is a fixed parameter: set it before initialization ends")
            return
        if name == "seed":
            refused = None if int(value) >= 0 else "allowed an integer >= 0"
        elif name == "machine":
            refused = _machine_refused(str(value))
        else:
            refused = _scenario_refused(str(value), flat=name == "terrain")
        if refused is not None:
            self._error(f"{name} = {value!r}: {refused}")
            return
        value = int(value) if name == "seed" else str(value)
        if value != self._parameters[name]:
            self._parameters[name] = value
            self._built = None   # built lazily again from the new value

    # ---- the plant ----------------------------------------------------------------------

    def _plant(self) -> _Built | None:
        """The plant, built from the parameters on first need; None (an error logged) if
        it cannot be built."""
        if self._built is None:
            try:
                self._built = self._build()
            except Exception as exc:   # the boundary to the host: an error, never Fatal
                values = ", ".join(f"{k} = {v!r}" for k, v in self._parameters.items())
                self._error(f"building the plant ({values}): {exc}")
        return self._built

    def _build(self) -> _Built:
        p = self._parameters
        terrain = str(p["terrain"])
        name = str(p["scenario"]) if terrain.lower() in ("", "flat") else terrain
        with capture_mujoco_warnings() as warnings:
            setup = prepare(name, seed=int(p["seed"]), **machine_files(str(p["machine"])))
            asm = assemble(setup)
        if warnings:
            raise PhysicsError(f"MuJoCo warning while settling the track: {warnings[0]}")
        track, element = asm.track, asm.element
        if track is None or not isinstance(element, HydraulicElement):
            raise ValueError(f"architecture {setup.architecture}: the plant FMU needs the "
                             "MuJoCo track and the built-in hydraulics (tp)")
        built = _Built(asm, track, element, Sensors(asm.control.sensors,
                                           np.random.default_rng([int(p["seed"]), 1])),
                       setup.supply0_Pa,
                       physics_limits(setup, element.stroke_range_m))
        _, p_head_l, p_head_r, p_rod, p_supply = element.node_pressures()
        self._read(built, Readout(0.0, setup.force0_N, 0.5 * (p_head_l + p_head_r), p_rod,
                                  p_supply, track.stroke_m, track.stroke_velocity_m_s, 0.0,
                                  0.0, 0.0, 0.0, track.chassis_acc_z_m_s2,
                                  track.closure_error_m, track.drive_torque_N_m))
        return built

    def _read(self, built: _Built, r: Readout) -> None:
        """The outputs from a readout (the sensors draw their noise)."""
        z = built.sensors.measure((r.p_head_Pa, r.p_rod_Pa, r.stroke_m), r.drive_torque_N_m)
        self._outputs.update(zip(("p_head_measured_Pa", "p_rod_measured_Pa",
                                  "stroke_measured_m", "drive_torque_measured_N_m"),
                                 z.tolist(), strict=True))
        self._outputs.update(tension_N=r.tension_N, p_head_Pa=r.p_head_Pa,
                             p_rod_Pa=r.p_rod_Pa, p_supply_Pa=r.p_supply_Pa,
                             stroke_m=r.stroke_m, velocity_m_s=r.stroke_velocity_m_s,
                             chassis_acc_z_m_s2=r.chassis_acc_z_m_s2)

    def _time_s(self) -> float:
        """The FMU's clock [s]: the start time plus the 1 ms steps taken."""
        return self._start_s + self._steps * COUPLING_STEP_S

    # ---- FMI calls ----------------------------------------------------------------------

    def setup_experiment(self, start_time: float, stop_time: float | None = None,
                         tolerance: float | None = None) -> None:
        self._start_s, self._steps = float(start_time), 0

    def exit_initialization_mode(self) -> None:
        self._initialized = self._plant() is not None

    def do_step(self, current_time: float, step_size: float) -> bool:
        built = self._built
        if not self._initialized or built is None:
            self._error("doStep before initialization ended")
            return False
        if self._stopped is not None:
            self._error(f"doStep after a physics stop ({self._stopped}); restore a saved "
                        "state (fmi2SetFMUstate) or reset")
            return False
        now = self._time_s()
        if abs(current_time - now) > TIME_TOLERANCE_S:
            self._error(f"doStep at t = {current_time:.9g} s: the FMU is at t = {now:.9g} s "
                        "(a step starts where the last one ended)")
            return False
        ratio = step_size / COUPLING_STEP_S
        n = round(ratio)
        if n < 1 or abs(ratio - n) > 1e-6:   # 1e-6 of a step: a host's rounding of k·1 ms
            self._error(f"communication step size = {step_size!r} s: allowed a positive "
                        f"integer multiple of {COUPLING_STEP_S:g} s")
            return False
        mode = self._valve_mode
        command = Command(mode, float(mode), None)
        supply = self._inputs["supply_pressure_set_Pa"] or built.nominal_supply_Pa
        inputs = StepInputs(self._inputs["track_speed_m_s"], self._inputs["hitch_pull_N"],
                            self._inputs["hitch_down_N"], supply)
        element = built.element

        def step(guard: PhysicsGuard) -> Readout:
            readout = built.asm.plant.step(command, inputs)
            guard.on_step(self._steps, readout, command)
            self._steps += 1
            return readout

        try:
            with capture_mujoco_warnings() as warnings:
                guard = PhysicsGuard(built.limits, warnings, element.node_pressures,
                                     element.pressure_nodes)
                readout = step(guard)
                for _ in range(n - 1):
                    readout = step(guard)
        except PhysicsError as exc:   # the guard's message names the time and the quantity
            self._stopped = str(exc)
        except Exception as exc:   # the plant refusing: an error, not Fatal
            end = self._time_s() + COUPLING_STEP_S
            self._stopped = f"t = {end:.3f} s: {type(exc).__name__}: {exc}"
        else:
            self._read(built, readout)
            return True
        self._error(f"doStep from t = {now:.3f} s stopped: {self._stopped}")
        return False

    # ---- state --------------------------------------------------------------------------

    # the state is a PlantState (opaque to pythonfmu), not pythonfmu's dict of variables
    def _get_fmu_state(self) -> PlantState | None:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque state
        built = self._built
        if not self._initialized or built is None:
            self._error("fmi2GetFMUstate before initialization ended: no state to save")
            return None
        plant, element = built.track, built.element
        return PlantState(dict(self._parameters), plant.snapshot(),
                          copy.deepcopy(element.tensioner),
                          copy.deepcopy(built.sensors), element._mode, dict(self._inputs),
                          self._valve_mode, dict(self._outputs), self._start_s, self._steps,
                          self._stopped)

    def _set_fmu_state(self, state: PlantState | UnreadableState | None) -> None:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque state
        built = self._built
        if not isinstance(state, PlantState):
            why = state.reason if isinstance(state, UnreadableState) else "no saved state"
            self._error(f"fmi2SetFMUstate: {why}")
            return
        if not self._initialized or built is None:
            self._error("fmi2SetFMUstate before initialization ended")
            return
        if state.parameters != self._parameters:
            self._error(f"fmi2SetFMUstate: the state was saved by a plant built from "
                        f"{state.parameters}, this one is built from {self._parameters}")
            return
        built.track.restore(state.track)
        element = HydraulicElement(copy.deepcopy(state.tensioner))
        element._mode = state.mode
        built.element = built.asm.element = built.asm.plant.element = element
        built.sensors = copy.deepcopy(state.sensors)
        self._inputs, self._valve_mode = dict(state.inputs), state.valve_mode
        self._outputs = dict(state.outputs)
        self._start_s, self._steps, self._stopped = state.start_s, state.steps, state.stopped

    @staticmethod
    def _fmu_state_to_bytes(state: PlantState | None) -> bytes:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque state
        return STATE_HEADER + pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def _fmu_state_from_bytes(data: bytes) -> PlantState | UnreadableState:  # pyright: ignore[reportIncompatibleMethodOverride]  # opaque state
        if not data.startswith(STATE_HEADER):
            return UnreadableState("the bytes are no state this FMU serialised (trackmj "
                                   f"{__version__}'s plant FMU)")
        try:   # the header is ours: the pickle was written by this FMU's _fmu_state_to_bytes
            state = pickle.loads(data[len(STATE_HEADER):])
        except Exception as exc:   # truncated or corrupted bytes: an error, not Fatal
            return UnreadableState(f"the serialised state does not load ({exc})")
        return state if isinstance(state, PlantState) else UnreadableState("no saved state")
