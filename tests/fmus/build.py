"""Builds the tests' FMUs from C with the system compiler against the vendored Reference
FMUs framework (``reference_fmus/``): the gas-charged cylinder of ``gas_cylinder/``, as
FMI 2.0 or 3.0, model exchange + co-simulation (state save and restore by copying the
instance), with or without directional derivatives; and the Reference FMUs' own models
vendored beside the framework (``reference_fmus/Feedthrough``: a variable of every type)."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping
from pathlib import Path

import trackmj.fmi.native

HERE = Path(__file__).resolve().parent
FRAMEWORK = HERE / "reference_fmus"
FMI_HEADERS = Path(trackmj.fmi.native.__file__).parent / "include"
"""The FMI 2.0 and 3.0 headers (the package ships them for its native FMU; the framework and
the tests' C hosts take them from there)."""
GAS = HERE / "gas_cylinder"
TOKEN = "{6f1c2a52-3c1d-4c55-9d4e-2f0b9a7e1c11}"

GAS_DEFAULTS = {"area": 2.0e-3, "p0": 6.6e6, "V0": 1.2e-4, "s_ref": 0.05, "n": 1.4,
                "c": 1.4e4, "p_atm": 1.0e5, "fail_time": 1e30, "nan_time": 1e30}
"""The gas cylinder's parameters (model.c's start values), name -> SI value."""
_INPUTS = (("stroke", 1, 0.05), ("velocity", 2, 0.0))
_PARAMS = tuple((name, 7 + i, value) for i, (name, value) in enumerate(GAS_DEFAULTS.items()))
_MORE = (("pressure", 16, None), ("stroke_mm", 17, 50.0), ("velocity_mm_s", 18, 0.0),
         ("force_kN", 19, None), ("pressure_MPa", 20, None))
"""After the parameters: the head-side gauge pressure [Pa], then stroke, velocity (inputs:
a start value), force and pressure (outputs) in mm, mm/s, kN and MPa."""
_OUTPUT_VRS = (5, 6, *(vr for _, vr, start in _MORE if start is None))
UNITS: dict[str, dict[str, str] | None] = {
    "m": {"m": "1"}, "mm": {"m": "1", "factor": "0.001"}, "m/s": {"m": "1", "s": "-1"},
    "mm/s": {"m": "1", "s": "-1", "factor": "0.001"}, "N": {"kg": "1", "m": "1", "s": "-2"},
    "kN": None, "Pa": {"kg": "1", "m": "-1", "s": "-2"},
    "MPa": {"kg": "1", "m": "-1", "s": "-2", "factor": "1e6"},
    "bar_abs": {"kg": "1", "m": "-1", "s": "-2", "factor": "1e5", "offset": "-101325"},
    "%": {"factor": "0.01"}}
"""Units a test FMU may declare -> the attributes of their UnitDefinition's BaseUnit (None:
defined without one, as FMI allows)."""


def gas_pressure_Pa(stroke_m: float, **overrides: float) -> float:
    """The gas cylinder's head-side gauge pressure (model.c): p0·(V0/V)^n − p_atm with
    V = V0 + A·(s − s_ref) [Pa]."""
    p = GAS_DEFAULTS | overrides
    volume = p["V0"] + p["area"] * (stroke_m - p["s_ref"])
    return p["p0"] * (p["V0"] / volume) ** p["n"] - p["p_atm"]


def gas_force_N(stroke_m: float, velocity_m_s: float = 0.0, **overrides: float) -> float:
    """The gas cylinder's force law (model.c): A·p(s) − c·v, p the head-side gauge pressure
    of :func:`gas_pressure_Pa` [N]."""
    p = GAS_DEFAULTS | overrides
    return p["area"] * gas_pressure_Pa(stroke_m, **overrides) - p["c"] * velocity_m_s


def _fmi2_xml(directional: bool, roll_back: bool) -> str:
    rows = ['<ScalarVariable name="time" valueReference="0" causality="independent" '
            'variability="continuous"><Real/></ScalarVariable>']
    rows += [f'<ScalarVariable name="{n}" valueReference="{vr}" causality="input" '
             f'variability="continuous"><Real start="{s}"/></ScalarVariable>'
             for n, vr, s in _INPUTS]
    rows += ['<ScalarVariable name="x" valueReference="3" causality="local" '
             'variability="continuous" initial="calculated"><Real/></ScalarVariable>',
             '<ScalarVariable name="der(x)" valueReference="4" causality="local" '
             'variability="continuous" initial="calculated"><Real derivative="4"/>'
             '</ScalarVariable>',
             '<ScalarVariable name="force" valueReference="5" causality="output" '
             'variability="continuous" initial="calculated"><Real/></ScalarVariable>',
             '<ScalarVariable name="power" valueReference="6" causality="output" '
             'variability="continuous" initial="calculated"><Real/></ScalarVariable>']
    rows += [f'<ScalarVariable name="{n}" valueReference="{vr}" causality="parameter" '
             f'variability="fixed" initial="exact"><Real start="{s!r}"/></ScalarVariable>'
             for n, vr, s in _PARAMS]
    rows += [f'<ScalarVariable name="{n}" valueReference="{vr}" causality="input" '
             f'variability="continuous"><Real start="{s}"/></ScalarVariable>' if s is not None
             else f'<ScalarVariable name="{n}" valueReference="{vr}" causality="output" '
             'variability="continuous" initial="calculated"><Real/></ScalarVariable>'
             for n, vr, s in _MORE]
    index = {vr: i + 1 for i, vr in enumerate((0, 1, 2, 3, 4, 5, 6,
                                                *(vr for _, vr, _ in _PARAMS + _MORE)))}
    outputs = "".join(f'<Unknown index="{index[vr]}"/>' for vr in _OUTPUT_VRS)
    initial = "".join(f'<Unknown index="{index[vr]}"/>' for vr in (3, 4, *_OUTPUT_VRS))
    dd = ' providesDirectionalDerivative="true"' if directional else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="GasCylinder" guid="{TOKEN}"
  description="passive gas-charged cylinder (trackmj tests)" numberOfEventIndicators="0">
  <ModelExchange modelIdentifier="GasCylinder" canGetAndSetFMUstate="true"{dd}/>
  <CoSimulation modelIdentifier="GasCylinder" canHandleVariableCommunicationStepSize="true"
    canGetAndSetFMUstate="{str(roll_back).lower()}"/>
  <ModelVariables>
    {chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>{outputs}</Outputs>
    <Derivatives><Unknown index="5"/></Derivatives>
    <InitialUnknowns>{initial}</InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def _fmi3_xml(directional: bool, roll_back: bool) -> str:
    rows = ['<Float64 name="time" valueReference="0" causality="independent" '
            'variability="continuous"/>']
    rows += [f'<Float64 name="{n}" valueReference="{vr}" causality="input" start="{s}"/>'
             for n, vr, s in _INPUTS]
    rows += ['<Float64 name="x" valueReference="3" initial="calculated"/>',
             '<Float64 name="der(x)" valueReference="4" derivative="3" initial="calculated"/>',
             '<Float64 name="force" valueReference="5" causality="output"/>',
             '<Float64 name="power" valueReference="6" causality="output"/>']
    rows += [f'<Float64 name="{n}" valueReference="{vr}" causality="parameter" '
             f'variability="fixed" start="{s!r}"/>' for n, vr, s in _PARAMS]
    rows += [f'<Float64 name="{n}" valueReference="{vr}" causality="input" start="{s}"/>'
             if s is not None else
             f'<Float64 name="{n}" valueReference="{vr}" causality="output"/>'
             for n, vr, s in _MORE]
    outputs = "".join(f'<Output valueReference="{vr}"/>' for vr in _OUTPUT_VRS)
    initial = "".join(f'<InitialUnknown valueReference="{vr}"/>' for vr in (3, 4, *_OUTPUT_VRS))
    dd = f' providesDirectionalDerivatives="{"true" if directional else "false"}"'
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="GasCylinder" instantiationToken="{TOKEN}"
  description="passive gas-charged cylinder (trackmj tests)">
  <ModelExchange modelIdentifier="GasCylinder" canGetAndSetFMUState="true"{dd}/>
  <CoSimulation modelIdentifier="GasCylinder" canHandleVariableCommunicationStepSize="true"
    canGetAndSetFMUState="{str(roll_back).lower()}"/>
  <ModelVariables>
    {chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    {outputs}
    <ContinuousStateDerivative valueReference="4"/>
    {initial}
  </ModelStructure>
</fmiModelDescription>
"""


def _declare_units(xml: str, units: Mapping[str, str]) -> str:
    """The modelDescription ``xml`` with ``units`` (variable name -> a unit of :data:`UNITS`)
    declared: the variables' ``unit`` attributes and their UnitDefinitions."""
    root = ET.fromstring(xml)
    fmi3 = root.get("fmiVersion", "").startswith("3")
    for variable in root.iter("ModelVariables"):
        for var in variable:
            if var.get("name") in units:
                (var if fmi3 else var[0]).set("unit", units[var.get("name", "")])
    definitions = ET.Element("UnitDefinitions")
    for name in dict.fromkeys(units.values()):
        unit, base = ET.SubElement(definitions, "Unit", name=name), UNITS[name]
        if base is not None:
            ET.SubElement(unit, "BaseUnit", base)
    last = max(i for i, child in enumerate(root)
               if child.tag in ("ModelExchange", "CoSimulation"))
    root.insert(last + 1, definitions)
    return _text(root)


def _fixed_step(xml: str, step_s: float) -> str:
    """The modelDescription ``xml`` of a co-simulation that takes only the step ``step_s``
    [s]: canHandleVariableCommunicationStepSize false, DefaultExperiment stepSize."""
    root = ET.fromstring(xml)
    for node, key, value in (("CoSimulation", "canHandleVariableCommunicationStepSize", "false"),
                             ("DefaultExperiment", "stepSize", repr(step_s))):
        found = root.find(node)
        if found is None:
            raise ValueError(f"the modelDescription has no {node}")
        found.set(key, value)
    return _text(root)


def _text(root: ET.Element) -> str:
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode")


def _compile(sources: Path, identifier: str, version: int, work: Path,
             flags: tuple[str, ...] = ()) -> Path:
    """The shared library of the model in ``sources`` (``config.h``, ``model.c``) for FMI
    ``version``, compiled in ``work``."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "all.c").write_text(f'#define FMI_VERSION {version}\n'
                                f'#include "fmi{version}Functions.c"\n'
                                '#include "model.c"\n#include "cosimulation.c"\n')
    library = work / f"{identifier}.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-O2", "-DDISABLE_PREFIX", *flags,
                    f"-I{sources}", f"-I{FRAMEWORK / 'include'}", f"-I{FMI_HEADERS}",
                    f"-I{FRAMEWORK / 'src'}", str(work / "all.c"), "-o", str(library), "-lm"],
                   check=True, capture_output=True)
    return library


def build_gas_cylinder(out: Path, *, version: int = 2, directional: bool = True,
                       roll_back: bool = True, platform_binary: bool = True,
                       units: Mapping[str, str] | None = None) -> Path:
    """Compile the gas cylinder into the FMU ``out`` (FMI ``version`` 2 or 3; ``roll_back``
    False declares its co-simulation unable to get and set its state; with
    ``platform_binary`` False the binary goes under a Windows folder instead, an FMU with
    no binary for this platform; ``units``: variable name -> the unit it declares, from
    :data:`UNITS`, else none)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    library = _compile(GAS, "GasCylinder", version, out.with_suffix(".build"),
                       ("-DGET_PARTIAL_DERIVATIVE",) if directional else ())
    folder = ("linux64" if version == 2 else "x86_64-linux") if platform_binary else \
        ("win64" if version == 2 else "x86_64-windows")
    suffix = ".so" if platform_binary else ".dll"
    xml = (_fmi2_xml if version == 2 else _fmi3_xml)(directional, roll_back)
    if units:
        xml = _declare_units(xml, units)
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.write(library, f"binaries/{folder}/GasCylinder{suffix}")
    return out


def build_reference(model: str, out: Path, *, version: int = 3,
                    units: Mapping[str, str] | None = None,
                    fixed_step_s: float | None = None) -> Path:
    """Compile the vendored Reference FMU ``model`` (``reference_fmus/<model>``: its
    ``config.h``, ``model.c`` and ``FMI<version>.xml``, unchanged) into the FMU ``out``
    (FMI ``version`` 2 or 3, binary for this platform); ``units``: variable name -> the unit
    it declares, from :data:`UNITS`; ``fixed_step_s``: the only communication step [s] its
    co-simulation declares it takes."""
    sources = FRAMEWORK / model
    out.parent.mkdir(parents=True, exist_ok=True)
    library = _compile(sources, model, version, out.with_suffix(".build"))
    folder = "linux64" if version == 2 else "x86_64-linux"
    xml = (sources / f"FMI{version}.xml").read_text()
    if units:
        xml = _declare_units(xml, units)
    if fixed_step_s is not None:
        xml = _fixed_step(xml, fixed_step_s)
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.write(library, f"binaries/{folder}/{model}.so")
    return out
