"""Opening an FMU: checks against the file that maps it, and one instance behind a
version-neutral call surface.

:func:`describe` runs when a tensioner or controller file is loaded, before any work: the
file exists and is a zip with a modelDescription fmpy can read, FMI 2.0 or 3.0, the
interface asked for is offered, a binary for this platform is inside, every mapped variable
exists with the causality and type its role needs, every parameter value fits its
variable's type. Each refusal is a :class:`~trackmj.validator.ParameterError` naming the file,
the key and the variable.

:class:`FmuInstance` wraps fmpy's ``FMU2Slave``/``FMU2Model``/``FMU3Slave``/``FMU3Model``:
values are set and read by port quantity, and any failing call raises
:class:`~trackmj.errors.FmuError` ("the FMU cyl.fmu: fmi2DoStep at t = 1.234 s failed with
status 3 (error)").
"""

from __future__ import annotations

import ctypes
import math
import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trackmj.errors import FmuError
from trackmj.validator import Location, ParameterError

REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32",
                 "UInt32", "Int64", "UInt64")
INPUT_CAUSALITIES = ("input",)
PARAMETER_CAUSALITIES = ("parameter", "input", "structuralParameter")


@dataclass(frozen=True)
class Channel:
    """One mapped FMU variable: its name, value reference and kind ("real", "int", "bool",
    "str")."""

    name: str
    vr: int
    kind: str


@dataclass(frozen=True)
class FmuDescription:
    """A checked FMU: its resolved ``path``, FMI ``version`` ("2.0"/"3.0"), fmpy's model
    description ``md``, the ``interface`` used ("co-simulation"/"model-exchange"), whether a
    co-simulation can save and restore its state (``can_roll_back``), whether model exchange
    provides directional derivatives (``directional``); ``inputs``/``outputs``: port
    quantity -> :class:`Channel`; ``parameters``: (channel, value) set before
    initialisation; ``offers``: the interfaces the FMU has."""

    path: Path
    version: str
    md: Any
    interface: str
    can_roll_back: bool
    directional: bool
    inputs: dict[str, Channel]
    outputs: dict[str, Channel]
    parameters: tuple[tuple[Channel, Any], ...]
    offers: tuple[str, ...] = field(default=())

    @property
    def name(self) -> str:
        """The FMU's file name (how messages name it)."""
        return self.path.name

    @property
    def identifier(self) -> str:
        """The model identifier of the interface used."""
        part = self.md.coSimulation if self.interface == "co-simulation" else \
            self.md.modelExchange
        return part.modelIdentifier


def _kind(type_name: str) -> str:
    if type_name in REAL_TYPES:
        return "real"
    if type_name in INTEGER_TYPES:
        return "int"
    return {"Boolean": "bool", "String": "str"}.get(type_name, "other")


def _fmi3_directional(path: Path, interface: str) -> bool:
    """FMI 3.0's ``providesDirectionalDerivatives`` of ``interface`` (fmpy reads FMI 2.0's
    singular attribute only)."""
    with zipfile.ZipFile(path) as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    tag = "CoSimulation" if interface == "co-simulation" else "ModelExchange"
    node = root.find(tag)
    return node is not None and node.get("providesDirectionalDerivatives") in ("true", "1")


def open_description(path: Path, where: str) -> Any:
    """fmpy's model description of the FMU at ``path``; ParameterError starting with
    ``where`` if the file is missing, not a zip, or has no readable modelDescription."""
    try:   # optional dependency (trackmj[fmi]): loaded only when an FMU is read
        import fmpy
    except ImportError:
        raise ParameterError(f"{where}: reading an FMU needs fmpy: pip install "
                             "'trackmj[fmi]'") from None
    if not path.is_file():
        raise ParameterError(f"{where}: no such file {path}")
    if not zipfile.is_zipfile(path):
        raise ParameterError(f"{where}: {path} is not an FMU (not a zip archive)")
    try:
        with zipfile.ZipFile(path) as zf:
            zf.getinfo("modelDescription.xml")
    except KeyError:
        raise ParameterError(f"{where}: {path} is not an FMU (no modelDescription.xml "
                             "inside)") from None
    try:
        return fmpy.read_model_description(str(path), validate=True)
    except Exception as exc:   # fmpy raises plain Exceptions for schema violations
        raise ParameterError(f"{where}: {path}: fmpy cannot read its modelDescription.xml "
                             f"({type(exc).__name__}: {exc})") from None


def choose_interface(md: Any, asked: str, where: str, path: Path) -> tuple[str, tuple[str, ...]]:
    """The interface to use ("co-simulation"/"model-exchange") for ``asked`` ("auto",
    "co-simulation", "model-exchange"), and the interfaces offered."""
    offers = tuple(name for name, part in (("co-simulation", md.coSimulation),
                                           ("model-exchange", md.modelExchange))
                   if part is not None)
    if not offers:
        raise ParameterError(f"{where}: {path.name} offers neither co-simulation nor model "
                             "exchange")
    if asked != "auto":
        if asked not in offers:
            raise ParameterError(f"{where}.interface = {asked!r}: {path.name} offers only "
                                 f"{', '.join(offers)}")
        return asked, offers
    cs = md.coSimulation
    if cs is not None and cs.canGetAndSetFMUstate:
        return "co-simulation", offers
    return ("model-exchange" if "model-exchange" in offers else "co-simulation"), offers


def _check_platform(path: Path, version: str, where: str) -> None:
    import fmpy  # optional dependency (trackmj[fmi]), present once open_description ran

    platforms = fmpy.supported_platforms(str(path))
    if fmpy.platform not in platforms:
        here = fmpy.platform if version.startswith("2") else fmpy.platform_tuple
        sources = " (it has C sources only: compile it first, e.g. fmpy's 'compile_platform_" \
                  "binary')" if platforms == ["c-code"] else ""
        raise ParameterError(f"{where}: {path.name} has no binary for this platform ({here}); "
                             f"it has: {', '.join(platforms) or 'none'}{sources}")


def map_variables(md: Any, mapping: Mapping[str, str], role: str, at: Location, table: str,
                  kinds: Mapping[str, tuple[str, ...]], fmu_name: str) -> dict[str, Channel]:
    """Port quantity -> Channel for ``mapping`` (FMU name -> quantity) of table ``table``;
    each variable must exist with causality ``role`` and a kind of ``kinds[quantity]``."""
    variables = {v.name: v for v in md.modelVariables}
    out = {}
    for name, quantity in mapping.items():
        var = variables.get(name)
        key = at.key(table, name)
        if var is None:
            candidates = sorted(v.name for v in md.modelVariables if v.causality == role)
            raise ParameterError(f"{key}: {fmu_name} has no variable {name!r} (its {role}s: "
                                 f"{', '.join(candidates) or 'none'})")
        if var.causality != role:
            raise ParameterError(f"{key}: {fmu_name}'s variable {name!r} has causality "
                                 f"{var.causality!r}; mapping it to {quantity!r} needs "
                                 f"{role!r}")
        kind = _kind(var.type)
        if kind not in kinds[quantity]:
            raise ParameterError(f"{key}: {fmu_name}'s variable {name!r} is of type {var.type}; "
                                 f"{quantity!r} needs {' or '.join(kinds[quantity])}")
        if var.shape or var.dimensions:
            raise ParameterError(f"{key}: {fmu_name}'s variable {name!r} is an array; map a "
                                 "scalar")
        out[quantity] = Channel(name, var.valueReference, kind)
    return out


def map_parameters(md: Any, values: Mapping[str, Any], at: Location,
                   fmu_name: str) -> tuple[tuple[Channel, Any], ...]:
    """(Channel, value) for every ``[... .parameters]`` entry, its type checked."""
    variables = {v.name: v for v in md.modelVariables}
    out = []
    for name, value in values.items():
        var = variables.get(name)
        key = at.key("parameters", name)
        if var is None:
            candidates = sorted(v.name for v in md.modelVariables
                                if v.causality in ("parameter", "structuralParameter"))
            raise ParameterError(f"{key}: {fmu_name} has no variable {name!r} (its "
                                 f"parameters: {', '.join(candidates) or 'none'})")
        if var.causality not in PARAMETER_CAUSALITIES or var.variability == "constant":
            raise ParameterError(f"{key}: {fmu_name}'s variable {name!r} (causality "
                                 f"{var.causality!r}, variability {var.variability!r}) cannot "
                                 "be set before initialisation")
        kind = _kind(var.type)
        ok = {"real": isinstance(value, int | float) and not isinstance(value, bool),
              "int": isinstance(value, int) and not isinstance(value, bool),
              "bool": isinstance(value, bool), "str": isinstance(value, str)}.get(kind, False)
        if not ok:
            raise ParameterError(f"{key} = {value!r}: {fmu_name}'s variable {name!r} is of type "
                                 f"{var.type}")
        out.append((Channel(name, var.valueReference, kind),
                    float(value) if kind == "real" else value))
    return tuple(out)


def describe(path: Path, interface: str, at: Location, inputs: Mapping[str, str],
             outputs: Mapping[str, str], parameters: Mapping[str, Any],
             input_kinds: Mapping[str, tuple[str, ...]],
             output_kinds: Mapping[str, tuple[str, ...]]) -> FmuDescription:
    """Every check of the module docstring; the checked FMU."""
    where = at.key("path")
    md = open_description(path, where)
    version = str(md.fmiVersion)
    if version not in ("2.0",) and not version.startswith("3."):
        raise ParameterError(f"{where}: {path.name} is FMI {version}; FMI 2.0 and 3.0 are "
                             "supported")
    used, offers = choose_interface(md, interface, at.table(), path)
    _check_platform(path, version, where)
    name = path.name
    ins = map_variables(md, inputs, "input", at, "inputs", input_kinds, name)
    outs = map_variables(md, outputs, "output", at, "outputs", output_kinds, name)
    params = map_parameters(md, parameters, at, name)
    cs = md.coSimulation
    can_roll_back = used == "co-simulation" and bool(cs.canGetAndSetFMUstate)
    if used == "model-exchange":
        directional = (bool(md.modelExchange.providesDirectionalDerivative)
                       if version == "2.0" else _fmi3_directional(path, used))
    else:
        directional = False
    return FmuDescription(path, version, md, used, can_roll_back, directional, ins, outs,
                          params, offers)


class FmuInstance:
    """One instance of a checked FMU (see the module docstring).

    ``start(t0, inputs)`` instantiates, sets the parameters and the initial inputs,
    initialises (model exchange: into continuous-time mode); ``set_inputs`` / ``outputs``
    by port quantity; co-simulation: ``do_step``, ``get_state``/``set_state``/``free_state``;
    model exchange: ``set_time``, ``set_states``, ``states``, ``derivatives``,
    ``directional``, ``nominals``, ``completed_step``. The FMU's unzipped copy is removed by
    ``close``.
    """

    def __init__(self, description: FmuDescription, instance_name: str = "trackmj") -> None:
        # optional dependency (trackmj[fmi]), present once the description was read
        import fmpy
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        self.d = d = description
        self.t = 0.0
        self.fmi3 = not d.version.startswith("2")
        self._dir = tempfile.mkdtemp(prefix="trackmj-fmu-")
        fmpy.extract(str(d.path), self._dir)
        cs = d.interface == "co-simulation"
        cls = ((FMU3Slave if cs else FMU3Model) if self.fmi3
               else (FMU2Slave if cs else FMU2Model))
        token = d.md.instantiationToken if self.fmi3 else d.md.guid
        self.fmu = self._call("load", lambda: cls(
            guid=token, unzipDirectory=self._dir, modelIdentifier=d.identifier,
            instanceName=instance_name))
        self._instantiated = False
        self.n_states = d.md.numberOfContinuousStates
        self.n_events = d.md.numberOfEventIndicators
        derivatives = d.md.derivatives
        self.state_vrs = [u.variable.derivative.valueReference for u in derivatives]
        self.derivative_vrs = [u.variable.valueReference for u in derivatives]
        self._setters = self._accessors("set")
        self._getters = self._accessors("get")
        self._in = {q: (c.vr, self._setters[c.kind]) for q, c in d.inputs.items()}
        self._out = [(q, c.vr, self._getters[c.kind]) for q, c in d.outputs.items()]
        self._real_out = [c.vr for c in d.outputs.values() if c.kind == "real"]
        self._out_names = [q for q, c in d.outputs.items() if c.kind == "real"]
        self.next_event_s = math.inf

    # ----------------------------------------------------------------- calls
    def _call(self, what: str, fn: Callable[[], Any]) -> Any:
        """``fn()``, any failure raised as FmuError naming the FMU, the call and the time."""
        try:
            return fn()
        except FmuError:
            raise
        except Exception as exc:
            detail = str(exc) or type(exc).__name__
            raise FmuError(f"the FMU {self.d.name}: {what} at t = {self.t:.3f} s failed: "
                           f"{detail}") from exc

    def _accessors(self, verb: str) -> dict[str, Callable[..., Any]]:
        f = self.fmu
        if self.fmi3:
            names = {"real": "Float64", "int": "Int32", "bool": "Boolean", "str": "String"}
        else:
            names = {"real": "Real", "int": "Integer", "bool": "Boolean", "str": "String"}
        return {kind: getattr(f, verb + name) for kind, name in names.items()}

    # ----------------------------------------------------------------- life cycle
    def start(self, t0_s: float, inputs: Mapping[str, float]) -> None:
        """Instantiate, set parameters and ``inputs`` (quantity -> value), initialise."""
        f, d = self.fmu, self.d
        self.t = t0_s
        self._call("instantiate", f.instantiate)
        self._instantiated = True
        if not self.fmi3:
            self._call("fmi2SetupExperiment", lambda: f.setupExperiment(startTime=t0_s))
        for channel, value in d.parameters:
            self._call(f"setting parameter {channel.name}",
                       lambda c=channel, v=value: self._setters[c.kind]([c.vr], [v]))
        self.set_inputs(inputs)
        if self.fmi3:
            self._call("fmi3EnterInitializationMode",
                       lambda: f.enterInitializationMode(startTime=t0_s))
        else:
            self._call("fmi2EnterInitializationMode", f.enterInitializationMode)
        self.set_inputs(inputs)
        self._call("exitInitializationMode", f.exitInitializationMode)
        if d.interface == "model-exchange":
            self.event_iteration()
            self._call("enterContinuousTimeMode", f.enterContinuousTimeMode)

    def event_iteration(self) -> None:
        """Event mode until the FMU's discrete states settle (model exchange, after
        initialisation or an event); keeps the next time event."""
        f = self.fmu
        for _ in range(100):
            if self.fmi3:
                need, terminate, _, _, defined, t_next = self._call(
                    "fmi3UpdateDiscreteStates", f.updateDiscreteStates)
            else:
                info = self._call("fmi2NewDiscreteStates", f.newDiscreteStates)
                need, terminate = info[0], info[1]
                defined, t_next = info[4], info[5]
            if terminate:
                raise FmuError(f"the FMU {self.d.name} asked to terminate the simulation at "
                               f"t = {self.t:.3f} s")
            if not need:
                self.next_event_s = t_next if defined else math.inf
                return
        raise FmuError(f"the FMU {self.d.name}: its event iteration at t = {self.t:.3f} s did "
                       "not settle in 100 rounds")

    def close(self) -> None:
        """Terminate and free the instance, remove the unzipped copy."""
        f = self.fmu
        try:
            if self._instantiated:
                f.terminate()
                f.freeInstance()
                self._instantiated = False
            f.freeLibrary()
        except Exception:   # closing after a failed call: nothing more to learn from it
            pass
        shutil.rmtree(self._dir, ignore_errors=True)

    # ----------------------------------------------------------------- values
    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Set the mapped inputs among ``values`` (quantity -> value)."""
        for quantity, value in values.items():
            entry = self._in.get(quantity)
            if entry is not None:
                vr, setter = entry
                self._call(f"setting input {quantity}",
                           lambda vr=vr, setter=setter, value=value: setter([vr], [value]))

    def read(self, channel: Channel) -> Any:
        """The value of one mapped variable."""
        getter = self._getters[channel.kind]
        return self._call(f"reading {channel.name}", lambda: getter([channel.vr]))[0]

    def real_outputs(self) -> list[float]:
        """The real outputs in :attr:`output_names` order."""
        return self._call("reading the outputs", lambda: self._getters["real"](self._real_out))

    @property
    def output_names(self) -> list[str]:
        """Port quantities of :meth:`real_outputs`."""
        return self._out_names

    # ----------------------------------------------------------------- co-simulation
    def do_step(self, t_s: float, h_s: float) -> None:
        """One communication step from ``t_s`` [s] over ``h_s`` [s]."""
        self.t = t_s
        name = "fmi3DoStep" if self.fmi3 else "fmi2DoStep"
        result = self._call(name, lambda: self.fmu.doStep(t_s, h_s))
        if self.fmi3 and result[1]:   # terminateSimulation
            raise FmuError(f"the FMU {self.d.name} asked to terminate the simulation at "
                           f"t = {t_s:.3f} s")

    def get_state(self) -> Any:
        return self._call("getFMUState", self.fmu.getFMUState)

    def set_state(self, state: Any) -> None:
        self._call("setFMUState", lambda: self.fmu.setFMUState(state))

    def free_state(self, state: Any) -> None:
        self._call("freeFMUState", lambda: self.fmu.freeFMUState(state))

    # ----------------------------------------------------------------- model exchange
    def set_time(self, t_s: float) -> None:
        self.t = t_s
        self._call("setTime", lambda: self.fmu.setTime(t_s))

    def _array_call(self, what: str, fn: Callable[[Any, int], Any], n: int,
                    fill: float = 0.0) -> list[float]:
        buf = (ctypes.c_double * n)(*([fill] * n))
        self._call(what, lambda: fn(buf, n))
        return list(buf)

    def states(self) -> list[float]:
        return self._array_call("getContinuousStates", self.fmu.getContinuousStates,
                                self.n_states)

    def nominals(self) -> list[float]:
        return self._array_call("getNominalsOfContinuousStates",
                                self.fmu.getNominalsOfContinuousStates, self.n_states, 1.0)

    def set_states(self, x: Sequence[float]) -> None:
        buf = (ctypes.c_double * len(x))(*x)
        self._call("setContinuousStates", lambda: self.fmu.setContinuousStates(buf, len(x)))

    def derivatives(self) -> list[float]:
        if self.fmi3:
            return self._array_call("fmi3GetContinuousStateDerivatives",
                                    self.fmu.getContinuousStateDerivatives, self.n_states)
        return self._array_call("fmi2GetDerivatives", self.fmu.getDerivatives, self.n_states)

    def directional(self, unknowns: Sequence[int], knowns: Sequence[int],
                    seed: Sequence[float]) -> list[float]:
        """Directional derivative of ``unknowns`` along ``seed`` on ``knowns`` (value
        references)."""
        return list(self._call("getDirectionalDerivative",
                               lambda: self.fmu.getDirectionalDerivative(
                                   list(unknowns), list(knowns), list(seed))))

    def event_indicators(self) -> list[float]:
        if not self.n_events:
            return []
        return self._array_call("getEventIndicators", self.fmu.getEventIndicators,
                                self.n_events)

    def completed_step(self) -> bool:
        """completedIntegratorStep; True if the FMU asks for event mode."""
        result = self._call("completedIntegratorStep", self.fmu.completedIntegratorStep)
        if result[1]:
            raise FmuError(f"the FMU {self.d.name} asked to terminate the simulation at "
                           f"t = {self.t:.3f} s")
        return bool(result[0])

    def handle_event(self) -> None:
        """Enter event mode, iterate the discrete states, back to continuous time."""
        self._call("enterEventMode", self.fmu.enterEventMode)
        self.event_iteration()
        self._call("enterContinuousTimeMode", self.fmu.enterContinuousTimeMode)
