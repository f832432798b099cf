"""Opening an FMU: checks against the file that maps it, and one instance behind a
version-neutral call surface.

:func:`describe` runs when a tensioner or controller file is loaded, before any work: the
file exists and is a zip with a modelDescription fmpy can read, FMI 2.0 or 3.0, the
interface asked for is offered, a binary for this platform is inside, every mapped variable
exists with the causality and type its role needs and a unit of its port quantity's
dimension (:func:`unit_factor`), every parameter value fits its variable's type (an integer
its range). Each refusal is a :class:`~trackmj.validator.ParameterError` naming the file,
the key and the variable.

:class:`FmuInstance` wraps fmpy's ``FMU2Slave``/``FMU2Model``/``FMU3Slave``/``FMU3Model``:
values are set and read by port quantity in SI, each with the call of its variable's
declared type (FMI 3.0's ``setFloat32``, ``getInt8``, ...) and converted to and from its
declared unit, and any failing call raises
:class:`~trackmj.errors.FmuError` naming the FMU, the call, the time and what the FMU itself
logged ("the FMU cyl.fmu: instantiate at t = 0.000 s failed: Failed to instantiate model;
the FMU logged: [Error] Wrong GUID."). Its messages are kept (:class:`FmuLog`), not printed.

The FMU is unzipped into a ``trackmj-fmu-*`` folder of the system's temporary directory,
removed by :meth:`FmuInstance.close` on every path: a failed load or start closes the
instance before raising, ``with FmuInstance(...)`` closes it on leaving, and a finalizer
removes the folder of an instance nobody closed when it is collected (or at exit).

Platforms are named as the standard spells them (:func:`binary_platforms`): FMI 3.0's
tuples (``x86_64-linux``, ``x86_64-windows``, ``aarch64-darwin``, ...), FMI 2.0's
``linux64``, ``win64``, ``darwin64``.
"""

from __future__ import annotations

import ctypes
import functools
import itertools
import math
import os
import shutil
import tempfile
import weakref
import xml.etree.ElementTree as ET
import zipfile
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trackmj.errors import FmuError
from trackmj.validator import Location, ParameterError

KINDS: dict[str, str] = {
    "Float64": "real", "Float32": "real", "Real": "real",
    "Int8": "int", "Int16": "int", "Int32": "int", "Int64": "int", "Integer": "int",
    "UInt8": "uint", "UInt16": "uint", "UInt32": "uint", "UInt64": "uint",
    "Enumeration": "enum", "Boolean": "bool", "String": "str"}
"""Declared variable type (FMI 2.0 and 3.0) -> its kind: real, signed integer, unsigned
integer, enumeration, boolean, string. A type not here (Binary, Clock) is never mapped."""
FMI2_TYPES = ("Real", "Integer", "Enumeration", "Boolean", "String")
"""FMI 2.0's variable types (the others of :data:`KINDS` are FMI 3.0's)."""
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
"""FMI's SI base units, whose exponents a UnitDefinition's BaseUnit gives."""
PORT_UNITS: dict[str, dict[str, int]] = {
    "1": {}, "m": {"m": 1}, "m/s": {"m": 1, "s": -1}, "N": {"kg": 1, "m": 1, "s": -2},
    "Pa": {"kg": 1, "m": -1, "s": -2}, "W": {"kg": 1, "m": 2, "s": -3}}
"""A port quantity's SI unit (pint's spelling; "1": dimensionless) -> its exponents of
:data:`BASE_UNITS`."""
INPUT_CAUSALITIES = ("input",)
PARAMETER_CAUSALITIES = ("parameter", "input", "structuralParameter")
UNZIPPED_PREFIX = "trackmj-fmu-"
"""Name prefix of an FMU's unzipped copy in the system's temporary directory."""
SHARED_LIBRARIES = (".so", ".dll", ".dylib")
"""File endings of an FMU's binaries."""


@dataclass(frozen=True)
class Channel:
    """One mapped FMU variable: its name, value reference, kind (a value of :data:`KINDS`),
    declared type (``Float32``, ``Int8``, ``Integer``, ...) and ``factor``: its value in its
    declared unit times ``factor`` is the port quantity's value in SI (1: no unit, or SI)."""

    name: str
    vr: int
    kind: str
    type: str
    factor: float = 1.0


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
    return KINDS.get(type_name, "other")


def _type_names(kinds: Sequence[str], version: str) -> str:
    """The declared types of ``kinds`` in FMI ``version``, for messages ("Float64,
    Float32, Int8, Int16, Int32 or Int64")."""
    fmi2 = version.startswith("2")
    names = [t for t, k in KINDS.items() if k in kinds and (t in FMI2_TYPES) == fmi2]
    return ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else names[0]


def integer_range(type_name: str, version: str) -> tuple[int, int]:
    """The values an integer variable of ``type_name`` holds in FMI ``version`` (FMI 2.0's
    Integer and Enumeration are 32-bit, FMI 3.0's Enumeration 64-bit)."""
    bits = {"Integer": 32, "Enumeration": 32 if version.startswith("2") else 64}.get(
        type_name) or int(type_name.removeprefix("U").removeprefix("Int"))
    if type_name.startswith("U"):
        return 0, 2 ** bits - 1
    return -(2 ** (bits - 1)), 2 ** (bits - 1) - 1


def accessor(type_name: str, version: str) -> str:
    """The name of fmpy's get/set call for a variable of ``type_name`` (``getFloat32``,
    ``setInt8``, ...: FMI 3.0 has one per type, an Enumeration's is Int64's; FMI 2.0's
    Enumeration is read and set as Integer)."""
    if type_name == "Enumeration":
        return "Integer" if version.startswith("2") else "Int64"
    return type_name


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


def binary_platforms(path: Path) -> list[str]:
    """The platforms the FMU at ``path`` has binaries for, named as its ``binaries/`` folders
    name them (the standard's names: FMI 3.0 ``x86_64-linux``, ``x86_64-windows``,
    ``aarch64-darwin``, ``x86_64-darwin``, ...; FMI 2.0 ``linux64``, ``win64``,
    ``darwin64``, ...), sorted, then ``c-code`` if it holds C sources."""
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    platforms = sorted({parts[1] for parts in (name.split("/") for name in names)
                        if len(parts) == 3 and parts[0] == "binaries"
                        and parts[2].endswith(SHARED_LIBRARIES)})
    if any(name.startswith("sources/") and name.endswith(".c") for name in names):
        platforms.append("c-code")
    return platforms


def this_platform(version: str) -> str:
    """This computer's platform as FMI ``version`` ("2.0", "3.0") names it (``linux64`` /
    ``x86_64-linux``, ``win64`` / ``x86_64-windows``, ...)."""
    import fmpy  # optional dependency (trackmj[fmi]), present once open_description ran

    return fmpy.platform if version.startswith("2") else fmpy.platform_tuple


def _check_platform(path: Path, version: str, identifier: str, where: str) -> None:
    """ParameterError unless the FMU has the binary of ``identifier`` for this platform."""
    import fmpy  # optional dependency (trackmj[fmi]), present once open_description ran

    here = this_platform(version)
    library = f"binaries/{here}/{identifier}{fmpy.sharedLibraryExtension}"
    with zipfile.ZipFile(path) as zf:
        if library in zf.namelist():
            return
    platforms = binary_platforms(path)
    sources = " (it has C sources only: compile it first, e.g. fmpy's 'compile_platform_" \
              "binary')" if platforms == ["c-code"] else ""
    raise ParameterError(f"{where}: {path.name} (FMI {version}) has no binary for this "
                         f"platform ({here}: {library}); it has: "
                         f"{', '.join(platforms) or 'none'}{sources}")


def _exponents(exponents: Mapping[str, int]) -> str:
    """SI base-unit exponents as text: "kg m-1 s-2"; "1" for none."""
    return " ".join(u if e == 1 else f"{u}{e}" for u, e in exponents.items()) or "1"


def unit_factor(md: Any, var: Any, quantity: str, si_unit: str, key: str,
                fmu_name: str) -> float:
    """Factor taking the values of ``var`` (fmpy's model variable) in its declared unit (its
    own ``unit``, else its declared type's) to ``si_unit``, the SI unit of the port
    ``quantity`` it is mapped to (a key of :data:`PORT_UNITS`): 1 without a unit (taken as
    SI); its UnitDefinition's BaseUnit factor where the base-unit exponents are the port's;
    pint's (:func:`trackmj.results.measured.si_factor`) for a unit defined without a
    BaseUnit. Refused (ParameterError naming ``key``, the variable, its unit and the unit
    needed): another dimension, an offset (an absolute pressure, °C)."""
    unit = var.unit or (var.declaredType.unit if var.declaredType is not None else None)
    if unit is None:
        return 1.0
    needs = (f"{quantity!r} is dimensionless (no unit, 1 or %)" if si_unit == "1" else
             f"{quantity!r} needs {si_unit} ({_exponents(PORT_UNITS[si_unit])}) or a "
             "multiple of it")
    where = f"{key}: {fmu_name}'s variable {var.name!r} has unit {unit!r}"
    defined = next((u for u in md.unitDefinitions if u.name == unit), None)
    base = defined.baseUnit if defined is not None else None
    if base is None:
        # function-local: pint and the log readers load only for a unit without a BaseUnit
        from trackmj.results.measured import si_factor

        try:
            return si_factor(unit, si_unit)
        except ValueError as exc:
            raise ParameterError(f"{where}, defined without a BaseUnit ({exc}); "
                                 f"{needs}") from None
    exponents = {u: getattr(base, u) for u in BASE_UNITS if getattr(base, u)}
    if exponents != PORT_UNITS[si_unit]:
        raise ParameterError(f"{where} ({_exponents(exponents)}); {needs}")
    if base.offset:
        sign = "+" if base.offset > 0 else "−"
        raise ParameterError(f"{where}, with an offset (in SI {base.factor:g}·value {sign} "
                             f"{abs(base.offset):g}); {needs}, without an offset")
    return float(base.factor)


def map_variables(md: Any, mapping: Mapping[str, str], role: str, at: Location, table: str,
                  kinds: Mapping[str, tuple[str, ...]], units: Mapping[str, str],
                  fmu_name: str) -> dict[str, Channel]:
    """Port quantity -> Channel for ``mapping`` (FMU name -> quantity) of table ``table``;
    each variable must exist with causality ``role``, a kind of ``kinds[quantity]``
    (refused naming the declared types those kinds allow) and, a real, a unit that
    converts to ``units[quantity]`` (:func:`unit_factor`)."""
    variables = {v.name: v for v in md.modelVariables}
    version = str(md.fmiVersion)
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
                                 f"{quantity!r} needs "
                                 f"{_type_names(kinds[quantity], version)}")
        if var.shape or var.dimensions:
            raise ParameterError(f"{key}: {fmu_name}'s variable {name!r} is an array; map a "
                                 "scalar")
        factor = unit_factor(md, var, quantity, units[quantity], key, fmu_name) \
            if kind == "real" else 1.0
        out[quantity] = Channel(name, var.valueReference, kind, var.type, factor)
    return out


def map_parameters(md: Any, values: Mapping[str, Any], at: Location,
                   fmu_name: str) -> tuple[tuple[Channel, Any], ...]:
    """(Channel, value) for every ``[... .parameters]`` entry, its type checked (an integer
    within its type's range)."""
    variables = {v.name: v for v in md.modelVariables}
    version = str(md.fmiVersion)
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
        integer = isinstance(value, int) and not isinstance(value, bool)
        ok = {"real": integer or isinstance(value, float), "int": integer, "uint": integer,
              "enum": integer, "bool": isinstance(value, bool),
              "str": isinstance(value, str)}.get(kind, False)
        if not ok:
            raise ParameterError(f"{key} = {value!r}: {fmu_name}'s variable {name!r} is of type "
                                 f"{var.type}")
        if kind in ("int", "uint", "enum"):
            lo, hi = integer_range(var.type, version)
            if not lo <= value <= hi:
                raise ParameterError(f"{key} = {value!r}: {fmu_name}'s variable {name!r} is of "
                                     f"type {var.type}, which holds integers in [{lo}, {hi}]")
        out.append((Channel(name, var.valueReference, kind, var.type),
                    float(value) if kind == "real" else value))
    return tuple(out)


def describe(path: Path, interface: str, at: Location, inputs: Mapping[str, str],
             outputs: Mapping[str, str], parameters: Mapping[str, Any],
             input_kinds: Mapping[str, tuple[str, ...]],
             output_kinds: Mapping[str, tuple[str, ...]],
             units: Mapping[str, str]) -> FmuDescription:
    """Every check of the module docstring; the checked FMU. ``units``: port quantity ->
    its SI unit (a key of :data:`PORT_UNITS`), inputs and outputs alike."""
    where = at.key("path")
    md = open_description(path, where)
    version = str(md.fmiVersion)
    if version not in ("2.0",) and not version.startswith("3."):
        raise ParameterError(f"{where}: {path.name} is FMI {version}; FMI 2.0 and 3.0 are "
                             "supported")
    used, offers = choose_interface(md, interface, at.table(), path)
    part = md.coSimulation if used == "co-simulation" else md.modelExchange
    _check_platform(path, version, part.modelIdentifier, where)
    name = path.name
    ins = map_variables(md, inputs, "input", at, "inputs", input_kinds, units, name)
    outs = map_variables(md, outputs, "output", at, "outputs", output_kinds, units, name)
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


STATUS_NAMES = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
"""FMI status names by value (FMI 2.0 and 3.0 agree)."""
ERROR_STATUS = 3
"""Status from which an FMU's log message is shown in an error message (Error, Fatal)."""
LOG_KEPT = 50
"""Messages an :class:`FmuLog` keeps (the last ones)."""
LOG_SHOWN = 3
"""Error-level messages an error message quotes (the last ones)."""


def _text(raw: bytes | None) -> str:
    return raw.decode("utf-8", "replace").strip() if raw else ""


class FmuLog:
    """What one FMU instance logged through fmpy's logger callback: the last
    :data:`LOG_KEPT` messages as (status, category, text); ``count`` every message so far."""

    def __init__(self) -> None:
        self.messages: deque[tuple[int, str, str]] = deque(maxlen=LOG_KEPT)
        self.count = 0

    def add(self, status: int, category: bytes | None, message: bytes | None) -> None:
        self.messages.append((int(status), _text(category), _text(message)))
        self.count += 1

    def fmi3(self, environment: Any, status: int, category: bytes | None,
             message: bytes | None) -> None:
        """The FMI 3.0 logMessage callback."""
        self.add(status, category, message)

    def reason(self, since: int = 0) -> str:
        """"; the FMU logged: [Error] ..." with the last :data:`LOG_SHOWN` error-level
        messages among those after the first ``since``; "" if there are none."""
        recent = list(self.messages)[max(0, len(self.messages) - (self.count - since)):]
        errors = [f"[{STATUS_NAMES[s] if 0 <= s < len(STATUS_NAMES) else s}] {text}"
                  for s, _, text in recent if s >= ERROR_STATUS and text][-LOG_SHOWN:]
        return "; the FMU logged: " + " | ".join(errors) if errors else ""


_FMI2_LOGS: weakref.WeakValueDictionary[int, FmuLog] = weakref.WeakValueDictionary()
"""The FMI 2.0 instances' logs by the component environment their callbacks carry."""
_FMI2_KEYS = itertools.count(1)


def _fmi2_log_message(environment: int | None, instance_name: bytes | None, status: int,
                      category: bytes | None, message: bytes | None) -> None:
    log = _FMI2_LOGS.get(environment or 0)
    if log is not None:
        log.add(status, category, message)


@functools.cache
def _fmi2_logger() -> Any:
    """The one FMI 2.0 logger of the process: fmpy's native proxy (which formats the
    printf-style message) calls the logger registered last, so every instance registers
    this one and its component environment routes the message to its log."""
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE  # optional dependency (trackmj[fmi])

    return fmi2CallbackLoggerTYPE(_fmi2_log_message)


def fmi2_callbacks(log: FmuLog) -> Any:
    """fmi2CallbackFunctions whose logger adds the FMU's messages, formatted, to ``log``."""
    # optional dependency (trackmj[fmi]), present once the description was read
    from fmpy import calloc, free
    from fmpy.fmi2 import (
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
    )

    key = next(_FMI2_KEYS)
    _FMI2_LOGS[key] = log
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _fmi2_logger()
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = key
    try:
        from fmpy.logging import addLoggerProxy  # optional dependency (trackmj[fmi])

        addLoggerProxy(ctypes.byref(callbacks))
    except (ImportError, OSError, AttributeError):   # no proxy here: messages unformatted
        pass
    return callbacks


class FmuInstance:
    """One instance of a checked FMU (see the module docstring).

    ``start(t0, inputs)`` instantiates, sets the parameters and the initial inputs,
    initialises (model exchange: into continuous-time mode); ``set_inputs`` / ``outputs``
    by port quantity; co-simulation: ``do_step``, ``get_state``/``set_state``/``free_state``;
    model exchange: ``set_time``, ``set_states``, ``states``, ``derivatives``,
    ``directional``, ``nominals``, ``completed_step``. ``close`` (or leaving ``with``)
    frees it and removes the FMU's unzipped copy; a failed load or start closes it before
    raising; an instance nobody closed has its copy removed when collected. ``log``: what
    the FMU logged (:class:`FmuLog`), quoted in error messages.
    """

    def __init__(self, description: FmuDescription, instance_name: str = "trackmj") -> None:
        # optional dependency (trackmj[fmi]), present once the description was read
        import fmpy
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        self.d = d = description
        self.t = 0.0
        self.fmi3 = not d.version.startswith("2")
        self.log = FmuLog()
        self.fmu: Any = None
        self._instantiated = False
        self._dir = tempfile.mkdtemp(prefix=UNZIPPED_PREFIX)
        self._remove_dir = weakref.finalize(self, shutil.rmtree, self._dir, ignore_errors=True)
        try:
            fmpy.extract(str(d.path), self._dir)
            cs = d.interface == "co-simulation"
            cls = ((FMU3Slave if cs else FMU3Model) if self.fmi3
                   else (FMU2Slave if cs else FMU2Model))
            token = d.md.instantiationToken if self.fmi3 else d.md.guid
            cwd = os.getcwd()
            try:
                self.fmu = self._call("load", lambda: cls(
                    guid=token, unzipDirectory=self._dir, modelIdentifier=d.identifier,
                    instanceName=instance_name))
            finally:   # fmpy enters the binary's folder to load it and stays if that fails
                os.chdir(cwd)
            self.n_states = d.md.numberOfContinuousStates
            self.n_events = d.md.numberOfEventIndicators
            derivatives = d.md.derivatives
            self.state_vrs = [u.variable.derivative.valueReference for u in derivatives]
            self.derivative_vrs = [u.variable.valueReference for u in derivatives]
            self._in = {q: (c, self._accessor("set", c)) for q, c in d.inputs.items()}
            real = [(q, c) for q, c in d.outputs.items() if c.kind == "real"]
            self._out_names = [q for q, _ in real]
            self._out_factors = [c.factor for _, c in real]
            groups: dict[str, tuple[list[int], list[int]]] = {}
            for i, (_, c) in enumerate(real):
                vrs, where = groups.setdefault(accessor(c.type, d.version), ([], []))
                vrs.append(c.vr)
                where.append(i)
            self._real_groups = [(getattr(self.fmu, "get" + name), vrs, where)
                                 for name, (vrs, where) in groups.items()]
            self.next_event_s = math.inf
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> FmuInstance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----------------------------------------------------------------- calls
    def _call(self, what: str, fn: Callable[[], Any]) -> Any:
        """``fn()``, any failure raised as FmuError naming the FMU, the call, the time and
        the error-level messages the FMU logged during the call."""
        since = self.log.count
        try:
            return fn()
        except FmuError:
            raise
        except Exception as exc:   # fmpy's message ends in a full stop: ours goes on
            detail = (str(exc) or type(exc).__name__).rstrip(".")
            raise FmuError(f"the FMU {self.d.name}: {what} at t = {self.t:.3f} s failed: "
                           f"{detail}{self.log.reason(since)}") from exc

    def _accessor(self, verb: str, channel: Channel) -> Callable[..., Any]:
        """fmpy's ``verb`` ("get"/"set") call for ``channel``'s declared type."""
        return getattr(self.fmu, verb + accessor(channel.type, self.d.version))

    # ----------------------------------------------------------------- life cycle
    def start(self, t0_s: float, inputs: Mapping[str, float]) -> None:
        """Instantiate, set parameters and ``inputs`` (quantity -> value), initialise; a
        failure closes the instance before it is raised."""
        try:
            self._start(t0_s, inputs)
        except BaseException:
            self.close()
            raise

    def _start(self, t0_s: float, inputs: Mapping[str, float]) -> None:
        f, d = self.fmu, self.d
        self.t = t0_s
        if self.fmi3:
            self._call("instantiate", lambda: f.instantiate(logMessage=self.log.fmi3))
        else:
            self._call("instantiate",
                       lambda: f.instantiate(callbacks=fmi2_callbacks(self.log)))
        self._instantiated = True
        if not self.fmi3:
            self._call("fmi2SetupExperiment", lambda: f.setupExperiment(startTime=t0_s))
        for channel, value in d.parameters:
            setter = self._accessor("set", channel)
            self._call(f"setting parameter {channel.name}",
                       lambda c=channel, v=value, f=setter: f([c.vr], [v]))
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
                               f"t = {self.t:.3f} s{self.log.reason()}")
            if not need:
                self.next_event_s = t_next if defined else math.inf
                return
        raise FmuError(f"the FMU {self.d.name}: its event iteration at t = {self.t:.3f} s did "
                       "not settle in 100 rounds")

    def close(self) -> None:
        """Terminate and free the instance, unload its library, remove the unzipped copy;
        again: nothing."""
        f, self.fmu = self.fmu, None
        instantiated, self._instantiated = self._instantiated, False
        try:
            if instantiated:
                try:
                    f.terminate()
                finally:
                    f.freeInstance()   # fmpy's freeInstance unloads the library too
            elif f is not None:
                f.freeLibrary()
        except Exception:   # closing after a failed call: nothing more to learn from it
            pass
        self._remove_dir()

    # ----------------------------------------------------------------- values
    def set_inputs(self, values: Mapping[str, float]) -> None:
        """Set the mapped inputs among ``values`` (quantity -> value in SI)."""
        for quantity, value in values.items():
            entry = self._in.get(quantity)
            if entry is not None:
                c, setter = entry
                fmu_value = round(value) if c.kind == "int" else value / c.factor
                self._call(f"setting input {quantity}",
                           lambda c=c, setter=setter, v=fmu_value: setter([c.vr], [v]))

    def read(self, channel: Channel) -> Any:
        """The value of one mapped variable (a real in SI)."""
        getter = self._accessor("get", channel)
        value = self._call(f"reading {channel.name}", lambda: getter([channel.vr]))[0]
        return value * channel.factor if channel.kind == "real" else value

    def real_outputs(self) -> list[float]:
        """The real outputs in :attr:`output_names` order, in SI (one call per declared
        type)."""
        values, factors = [0.0] * len(self._out_names), self._out_factors
        for getter, vrs, where in self._real_groups:
            read = self._call("reading the outputs", lambda g=getter, v=vrs: g(v))
            for i, value in zip(where, read, strict=True):
                values[i] = value * factors[i]
        return values

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
                           f"t = {t_s:.3f} s{self.log.reason()}")

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
                           f"t = {self.t:.3f} s{self.log.reason()}")
        return bool(result[0])

    def handle_event(self) -> None:
        """Enter event mode, iterate the discrete states, back to continuous time."""
        self._call("enterEventMode", self.fmu.enterEventMode)
        self.event_iteration()
        self._call("enterContinuousTimeMode", self.fmu.enterContinuousTimeMode)
