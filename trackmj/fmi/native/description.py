"""The native track FMU's ``modelDescription.xml`` (FMI 2.0 or 3.0 co-simulation), written
from the variable table of :mod:`trackmj.fmi.native.variables`.

What it declares is what the C layers (``fmi2.c``, ``fmi3.c``) do: outputs change only in a
step, so none depends on an input within a communication point (empty ``dependencies``),
and they are valid in initialisation mode (``initial="calculated"``, listed as initial
unknowns); the communication step is any positive whole multiple of the 1 ms coupling step;
the FMU state can be saved, restored and serialised; several instances may live in one
process. Units carry their SI base-unit exponents; display units are declared with FMI's
factor (value in the display unit = factor × value in the unit).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable

from trackmj.fmi.native.variables import DISPLAY_UNITS, UNITS, Variable
from trackmj.ports import COUPLING_STEP_S, steps_per_period
from trackmj.version import __version__

MODEL_IDENTIFIER = "TrackmjTrack"
"""The binary's name in ``binaries/<platform>/`` (its functions carry no prefix)."""
AUTHOR = "trackmj contributors"
LICENSE = "Apache-2.0"
"""The repository's licence (its LICENSE file), the FMU's sources and binary included."""
COPYRIGHT = "Copyright trackmj contributors"
LOG_CATEGORIES = (
    ("logStatusError", "a call failed (fmi2Error/fmi3Error): always logged"),
    ("logStatusWarning", "a call succeeded with a warning"),
    ("logEvents", "information on the instance's life: instantiation, initialisation, "
                  "reset, state restore"),
)
"""(name, description) of the log categories the C layers use."""
_FMI2_KINDS = {"Float64": "Real", "Boolean": "Boolean"}


def _number(value: float) -> str:
    """An xs:double of a finite value (Python's shortest round-trip form)."""
    if not math.isfinite(value):
        raise ValueError(f"{value} cannot be written to a modelDescription")
    return repr(float(value))


def _start(variable: Variable) -> str:
    """The start attribute of an input or parameter."""
    if variable.start is None:
        raise ValueError(f"{variable.name}: a {variable.causality} needs a start value")
    if variable.kind == "Boolean":
        return "true" if variable.start else "false"
    return _number(float(variable.start))


def _check(variables: tuple[Variable, ...]) -> None:
    """ValueError for a table no modelDescription may declare."""
    for attr in ("name", "vr"):
        seen = [getattr(v, attr) for v in variables]
        if len(set(seen)) != len(seen):
            raise ValueError(f"variables' {attr}s are not unique: {seen}")
    if [v.causality for v in variables].count("independent") != 1:
        raise ValueError("exactly one variable must be the independent one (the time)")
    for v in variables:
        if v.kind == "Float64" and v.unit not in UNITS:
            raise ValueError(f"{v.name}: unit {v.unit!r} is not one of {sorted(UNITS)}")
        if v.kind == "Boolean" and v.unit is not None:
            raise ValueError(f"{v.name}: a Boolean has no unit")


def _unit_definitions(parent: ET.Element, units: Iterable[str]) -> None:
    """``<UnitDefinitions>`` of ``units`` (in :data:`UNITS` order), with BaseUnit exponents
    and display units."""
    used = set(units)
    defs = ET.SubElement(parent, "UnitDefinitions")
    for name, exponents in UNITS.items():
        if name not in used:
            continue
        unit = ET.SubElement(defs, "Unit", name=name)
        ET.SubElement(unit, "BaseUnit", {k: str(e) for k, e in exponents.items()})
        for display, factor in DISPLAY_UNITS.get(name, ()):
            # DISPLAY_UNITS: value in the unit = factor × value in display; FMI: the inverse
            ET.SubElement(unit, "DisplayUnit", name=display, factor=_number(1.0 / factor))


def _header(parent: ET.Element, default_step_s: float, stop_time_s: float) -> None:
    """``<LogCategories>`` and ``<DefaultExperiment>``."""
    categories = ET.SubElement(parent, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(categories, "Category", name=name, description=text)
    ET.SubElement(parent, "DefaultExperiment", startTime="0.0", stopTime=_number(stop_time_s),
                  stepSize=_number(default_step_s))


def _value_attributes(v: Variable) -> dict[str, str]:
    """unit, start, min, max of an FMI 2 type element or an FMI 3 variable element."""
    attrs: dict[str, str] = {}
    if v.kind == "Float64":
        attrs["unit"] = str(v.unit)
    if v.causality in ("input", "parameter"):
        attrs["start"] = _start(v)
    if v.minimum is not None:
        attrs["min"] = _number(v.minimum)
    if v.maximum is not None:
        attrs["max"] = _number(v.maximum)
    return attrs


def _common_attributes(v: Variable) -> dict[str, str]:
    """causality, variability and initial (FMI 2 and 3 alike)."""
    attrs = {"causality": v.causality, "variability": v.variability}
    if v.causality == "output":
        attrs["initial"] = "calculated"
    elif v.causality == "parameter":
        attrs["initial"] = "exact"
    return attrs


def _fmi2(root: ET.Element, variables: tuple[Variable, ...]) -> None:
    """FMI 2.0 ``ModelVariables`` and ``ModelStructure`` (indices are 1-based positions)."""
    model_variables = ET.SubElement(root, "ModelVariables")
    for v in variables:
        scalar = ET.SubElement(model_variables, "ScalarVariable", {
            "name": v.name, "valueReference": str(v.vr), "description": v.description,
            **_common_attributes(v)})
        ET.SubElement(scalar, _FMI2_KINDS[v.kind], _value_attributes(v))
    structure = ET.SubElement(root, "ModelStructure")
    outputs = [str(i) for i, v in enumerate(variables, start=1) if v.causality == "output"]
    for tag in ("Outputs", "InitialUnknowns"):
        element = ET.SubElement(structure, tag)
        for index in outputs:
            ET.SubElement(element, "Unknown", index=index, dependencies="")


def _fmi3(root: ET.Element, variables: tuple[Variable, ...]) -> None:
    """FMI 3.0 ``ModelVariables`` and ``ModelStructure`` (by value reference)."""
    model_variables = ET.SubElement(root, "ModelVariables")
    for v in variables:
        ET.SubElement(model_variables, v.kind, {
            "name": v.name, "valueReference": str(v.vr), "description": v.description,
            **_common_attributes(v), **_value_attributes(v)})
    structure = ET.SubElement(root, "ModelStructure")
    outputs = [str(v.vr) for v in variables if v.causality == "output"]
    for tag in ("Output", "InitialUnknown"):
        for vr in outputs:
            ET.SubElement(structure, tag, valueReference=vr, dependencies="")


def model_description(variables: tuple[Variable, ...], *, fmi_version: int, token: str,
                      model_name: str, description: str, version: str,
                      default_step_s: float = COUPLING_STEP_S,
                      stop_time_s: float = 10.0) -> str:
    """The modelDescription.xml text of the track FMU for FMI ``fmi_version`` (2 or 3):
    ``token`` is the FMI 2 guid / FMI 3 instantiationToken (the one the binary checks),
    ``version`` the model's version; the default experiment runs 0 .. ``stop_time_s`` [s] in
    steps of ``default_step_s`` [s] (a positive whole multiple of the 1 ms coupling step)."""
    if fmi_version not in (2, 3):
        raise ValueError(f"fmi_version {fmi_version}: 2 or 3")
    steps_per_period(default_step_s)
    if not stop_time_s > 0.0:
        raise ValueError(f"stop_time_s {stop_time_s}: must be > 0")
    _check(variables)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": f"{fmi_version}.0", "modelName": model_name,
        ("guid" if fmi_version == 2 else "instantiationToken"): token,
        "description": description, "author": AUTHOR, "version": version,
        "copyright": COPYRIGHT, "license": LICENSE,
        "generationTool": f"trackmj {__version__}", "variableNamingConvention": "flat"})
    common = {"modelIdentifier": MODEL_IDENTIFIER, "needsExecutionTool": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false"}
    if fmi_version == 2:
        root.set("numberOfEventIndicators", "0")
        ET.SubElement(root, "CoSimulation", {
            **common, "canHandleVariableCommunicationStepSize": "true",
            "canInterpolateInputs": "false", "maxOutputDerivativeOrder": "0",
            "canRunAsynchronuously": "false", "canNotUseMemoryManagementFunctions": "true",
            "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
            "providesDirectionalDerivative": "false"})
    else:
        ET.SubElement(root, "CoSimulation", {
            **common, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
            "providesDirectionalDerivatives": "false", "providesAdjointDerivatives": "false",
            "providesPerElementDependencies": "false",
            "canHandleVariableCommunicationStepSize": "true",
            "fixedInternalStepSize": _number(COUPLING_STEP_S),
            "maxOutputDerivativeOrder": "0", "providesIntermediateUpdate": "false",
            "mightReturnEarlyFromDoStep": "false",
            "canReturnEarlyAfterIntermediateUpdate": "false", "hasEventMode": "false",
            "providesEvaluateDiscreteStates": "false"})
    _unit_definitions(root, (str(v.unit) for v in variables if v.kind == "Float64"))
    _header(root, default_step_s, stop_time_s)
    (_fmi2 if fmi_version == 2 else _fmi3)(root, variables)
    ET.indent(root, space="  ")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            + ET.tostring(root, encoding="unicode") + "\n")


__all__ = ["AUTHOR", "LICENSE", "LOG_CATEGORIES", "MODEL_IDENTIFIER", "model_description"]
