"""Builds the tests' FMUs from C with the system compiler against the vendored Reference
FMUs framework (``reference_fmus/``): the gas-charged cylinder of ``gas_cylinder/``, as
FMI 2.0 or 3.0, model exchange + co-simulation (state save and restore by copying the
instance), with or without directional derivatives; and the Reference FMUs' own models
vendored beside the framework (``reference_fmus/Feedthrough``: a variable of every type)."""

from __future__ import annotations

import subprocess
import zipfile
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
    rows += ['<ScalarVariable name="pressure" valueReference="16" causality="output" '
             'variability="continuous" initial="calculated"><Real/></ScalarVariable>']
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
    <Outputs><Unknown index="6"/><Unknown index="7"/><Unknown index="17"/></Outputs>
    <Derivatives><Unknown index="5"/></Derivatives>
    <InitialUnknowns><Unknown index="4"/><Unknown index="5"/><Unknown index="6"/>
      <Unknown index="7"/><Unknown index="17"/></InitialUnknowns>
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
    rows += ['<Float64 name="pressure" valueReference="16" causality="output"/>']
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
    <Output valueReference="5"/><Output valueReference="6"/><Output valueReference="16"/>
    <ContinuousStateDerivative valueReference="4"/>
    <InitialUnknown valueReference="3"/><InitialUnknown valueReference="4"/>
    <InitialUnknown valueReference="5"/><InitialUnknown valueReference="6"/>
    <InitialUnknown valueReference="16"/>
  </ModelStructure>
</fmiModelDescription>
"""


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
                       roll_back: bool = True, platform_binary: bool = True) -> Path:
    """Compile the gas cylinder into the FMU ``out`` (FMI ``version`` 2 or 3; ``roll_back``
    False declares its co-simulation unable to get and set its state; with
    ``platform_binary`` False the binary goes under a Windows folder instead, an FMU with
    no binary for this platform)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    library = _compile(GAS, "GasCylinder", version, out.with_suffix(".build"),
                       ("-DGET_PARTIAL_DERIVATIVE",) if directional else ())
    folder = ("linux64" if version == 2 else "x86_64-linux") if platform_binary else \
        ("win64" if version == 2 else "x86_64-windows")
    suffix = ".so" if platform_binary else ".dll"
    xml = (_fmi2_xml if version == 2 else _fmi3_xml)(directional, roll_back)
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.write(library, f"binaries/{folder}/GasCylinder{suffix}")
    return out


def build_reference(model: str, out: Path, *, version: int = 3) -> Path:
    """Compile the vendored Reference FMU ``model`` (``reference_fmus/<model>``: its
    ``config.h``, ``model.c`` and ``FMI<version>.xml``, unchanged) into the FMU ``out``
    (FMI ``version`` 2 or 3, binary for this platform)."""
    sources = FRAMEWORK / model
    out.parent.mkdir(parents=True, exist_ok=True)
    library = _compile(sources, model, version, out.with_suffix(".build"))
    folder = "linux64" if version == 2 else "x86_64-linux"
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("modelDescription.xml", (sources / f"FMI{version}.xml").read_text())
        zf.write(library, f"binaries/{folder}/{model}.so")
    return out
