"""The native track FMU's modelDescription.xml (trackmj.fmi.native.description) against the
FMI 2.0 / 3.0 requirements: fmpy's schema and structure validation, units whose SI
dimensions are those the variable names state, outputs without direct feedthrough listed as
initial unknowns, start values inside their ranges, and the capabilities the C layers
implement (step size of engine.h, log categories the C sources use)."""

from __future__ import annotations

import math
import re
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu

from trackmj.fmi.native.description import model_description
from trackmj.fmi.native.export import track_description
from trackmj.fmi.native.variables import INPUTS, table
from trackmj.scenarios.schema import TRACK_SPEED_MAX_M_S
from trackmj.track.mechanics import load_model_params
from trackmj.version import __version__

ROOT = Path(__file__).resolve().parents[1]
NATIVE = ROOT / "trackmj" / "fmi" / "native"
TOKEN = "{6f1c2a4e-0d7b-4c1e-9a53-2b8e5f7d3c10}"
VERSIONS = (2, 3)

KG_M_S2 = {"kg": 1, "m": 1, "s": -2}
SUFFIX_DIMENSIONS: tuple[tuple[str, dict[str, int]], ...] = (
    ("_N_s_m", {"kg": 1, "s": -1}),          # damping: force per velocity
    ("_m_s2", {"m": 1, "s": -2}),
    ("_m_s", {"m": 1, "s": -1}),
    ("_N_m", {"kg": 1, "s": -2}),            # stiffness: force per length (torque below)
    ("_N", KG_M_S2),
    ("_m", {"m": 1}),
)
"""Name suffix -> SI base-unit exponents, by hand from the quantities (longest first)."""
TORQUE = {"kg": 1, "m": 2, "s": -2}          # N·m, "_N_m" on a torque
NAMED = {"time": {"s": 1}, "ground_friction": {}}
"""Variables whose name has no unit suffix: the time [s], a friction coefficient [1]."""
DISPLAY_FACTORS = {("m", "mm"): 1e3, ("N", "kN"): 1e-3, ("N/m", "kN/mm"): 1e-6,
                   ("N.m", "kN.m"): 1e-3}
"""(unit, display unit) -> FMI factor (display value = factor × value): 1 m = 1000 mm,
1 N = 1e-3 kN, 1 N/m = 1e-3 kN / 1e3 mm, 1 N·m = 1e-3 kN·m."""


def _variables():
    return table(load_model_params(), 12000.0)


@pytest.fixture(scope="module", params=VERSIONS)
def fmi(request) -> tuple[int, ET.Element]:
    xml = model_description(_variables(), fmi_version=request.param, token=TOKEN,
                            model_name="trackmj track", description="one track side",
                            version="1.2.3")
    return request.param, ET.fromstring(xml)


def _expected_dimension(name: str) -> dict[str, int]:
    if name in NAMED:
        return NAMED[name]
    for suffix, dimension in SUFFIX_DIMENSIONS:
        if name.endswith(suffix):
            return TORQUE if suffix == "_N_m" and "torque" in name else dimension
    raise AssertionError(f"{name}: no unit suffix this test knows")


def _children(parent: ET.Element, tag: str) -> list[ET.Element]:
    """The children of ``parent``'s one ``tag`` element."""
    element = parent.find(tag)
    assert element is not None, tag
    return list(element)


def _scalars(fmi_version: int, root: ET.Element) -> list[dict[str, str]]:
    """Each variable's attributes with its type's (FMI 2: the child element) and
    ``kind``."""
    out = []
    for element in _children(root, "ModelVariables"):
        if fmi_version == 2:
            typed = element[0]
            out.append({**element.attrib, **typed.attrib, "kind": typed.tag})
        else:
            out.append({**element.attrib, "kind": element.tag})
    return out


def _units(root: ET.Element) -> dict[str, ET.Element]:
    return {u.get("name", ""): u for u in root.iter("Unit")}


@pytest.mark.parametrize("fmi_version", VERSIONS)
def test_fmpy_validation_finds_no_problem(fmi_version: int, tmp_path: Path) -> None:
    """fmpy's validate_fmu (the FMI XSD, names, model structure, start values, units,
    causality/variability/initial combinations) on an FMU holding the description."""
    xml = model_description(_variables(), fmi_version=fmi_version, token=TOKEN,
                            model_name="trackmj track", description="one track side",
                            version="1.2.3")
    path = tmp_path / "track.fmu"
    with zipfile.ZipFile(path, "w") as fmu:
        fmu.writestr("modelDescription.xml", xml)
    assert validate_fmu(str(path)) == []


def test_units_have_the_dimensions_the_names_state(fmi) -> None:
    """Every Float64 variable has a unit whose BaseUnit exponents are the SI dimension its
    name's suffix states (absent exponents are 0); Booleans have none."""
    fmi_version, root = fmi
    units = _units(root)
    for v in _scalars(fmi_version, root):
        if v["kind"] == "Boolean":
            assert "unit" not in v, v["name"]
            continue
        base = units[v["unit"]].find("BaseUnit")
        assert base is not None, v["unit"]
        exponents = {k: int(e) for k, e in base.attrib.items() if int(e) != 0}
        assert exponents == _expected_dimension(v["name"]), v["name"]


def test_display_units_convert_by_their_si_prefixes(fmi) -> None:
    """Each DisplayUnit's factor is the conversion its SI prefixes give (FMI: value in the
    display unit = factor × value in the unit); relative 1e-15: one rounding of 1/x."""
    _, root = fmi
    declared = {(u.get("name"), d.get("name")): float(d.get("factor", "1"))
                for u in root.iter("Unit") for d in u.iter("DisplayUnit")}
    assert declared.keys() <= DISPLAY_FACTORS.keys()
    assert declared
    for key, factor in declared.items():
        assert math.isclose(factor, DISPLAY_FACTORS[key], rel_tol=1e-15), key


def test_outputs_have_no_direct_feedthrough_and_are_initial_unknowns(fmi) -> None:
    """Outputs change only in a step: each is listed once as an output and once as an
    initial unknown, with an empty dependency list, initial="calculated" and no start."""
    fmi_version, root = fmi
    scalars = _scalars(fmi_version, root)
    structure = root.find("ModelStructure")
    assert structure is not None
    if fmi_version == 2:
        by_key = {str(i): v for i, v in enumerate(scalars, start=1)}
        lists = [[(u.get("index"), u.get("dependencies")) for u in _children(structure, tag)]
                 for tag in ("Outputs", "InitialUnknowns")]
    else:
        by_key = {v["valueReference"]: v for v in scalars}
        lists = [[(u.get("valueReference"), u.get("dependencies"))
                  for u in structure.findall(tag)] for tag in ("Output", "InitialUnknown")]
    outputs = sorted(k for k, v in by_key.items() if v["causality"] == "output")
    assert len(outputs) >= 13
    for listed in lists:
        assert sorted(k for k, _ in listed) == outputs
        assert all(dependencies == "" for _, dependencies in listed)
    for key in outputs:
        assert by_key[key]["initial"] == "calculated"
        assert "start" not in by_key[key]


def test_inputs_and_parameters_start_inside_their_ranges(fmi) -> None:
    """Inputs are continuous with a start; parameters fixed, initial exact; every start
    lies in [min, max]; the time is the one independent variable, without start."""
    fmi_version, root = fmi
    scalars = _scalars(fmi_version, root)
    assert [v["name"] for v in scalars if v["causality"] == "independent"] == ["time"]
    assert all("start" not in v for v in scalars if v["causality"] == "independent")
    inputs = [v for v in scalars if v["causality"] == "input"]
    parameters = [v for v in scalars if v["causality"] == "parameter"]
    assert inputs and parameters
    for v in inputs:
        assert v["variability"] == "continuous" and "initial" not in v
    for v in parameters:
        assert (v["variability"], v["initial"]) == ("fixed", "exact")
    for v in inputs + parameters:
        start = float(v["start"])
        assert float(v.get("min", "-inf")) <= start <= float(v.get("max", "inf")), v["name"]


def test_track_speed_input_allows_what_a_scenario_allows(fmi) -> None:
    """The FMU takes the track speed a scenario may command, ±TRACK_SPEED_MAX_M_S, and says
    so: an importer cannot drive the FMU where no trackmj run was ever checked."""
    fmi_version, root = fmi
    speed = next(v for v in _scalars(fmi_version, root) if v["name"] == "track_speed_m_s")
    assert (float(speed["min"]), float(speed["max"])) == (-TRACK_SPEED_MAX_M_S,
                                                          TRACK_SPEED_MAX_M_S)
    assert f"|v| <= {TRACK_SPEED_MAX_M_S:g} m/s" in speed["description"]


@pytest.mark.parametrize(("grade", "says"), [
    (0.2, "grade tan θ = +0.2, uphill driving forward"),
    (-0.2, "grade tan θ = -0.2, downhill driving forward"),
    (0.0, "level, grade tan θ = 0")])
def test_description_names_the_grade_the_track_stands_on(grade, says) -> None:
    """The grade is compiled into the FMU's gravity: its description says it, as tan θ, with
    the machine, terrain, seed and settling force."""
    text = track_description("lf1352", "climb.toml", 3, 13e3, grade)
    assert f"(lf1352, terrain climb.toml, seed 3, {says})" in text
    assert "settled under 13000 N" in text


def test_booleans_are_discrete_outputs(fmi) -> None:
    fmi_version, root = fmi
    booleans = [v for v in _scalars(fmi_version, root) if v["kind"] == "Boolean"]
    assert len(booleans) == 4
    assert all((v["causality"], v["variability"]) == ("output", "discrete") for v in booleans)


def test_header_matches_the_project_and_the_c_layers(fmi) -> None:
    """Token, licence and version as pyproject.toml declares them; the step size and log
    categories as engine.h and the C layers use them; the capabilities they implement."""
    fmi_version, root = fmi
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert root.get("fmiVersion") == f"{fmi_version}.0"
    assert root.get("guid" if fmi_version == 2 else "instantiationToken") == TOKEN
    assert root.get("license") == project["license"]["text"]
    assert root.get("generationTool") == f"trackmj {project['version']}" == \
        f"trackmj {__version__}"
    assert root.get("author") and root.get("copyright") and root.get("version") == "1.2.3"

    step = re.search(r"#define ENGINE_STEP_S (\S+)", (NATIVE / "engine.h").read_text())
    assert step is not None
    step_s = float(step.group(1))
    experiment = root.find("DefaultExperiment")
    assert experiment is not None
    assert float(experiment.get("startTime", "nan")) == 0.0
    assert float(experiment.get("stepSize", "nan")) == step_s

    cosim = root.find("CoSimulation")
    assert cosim is not None and root.find("ModelExchange") is None
    state = "FMUstate" if fmi_version == 2 else "FMUState"
    expected = {"modelIdentifier": "TrackmjTrack", "needsExecutionTool": "false",
                "canHandleVariableCommunicationStepSize": "true",
                "canBeInstantiatedOnlyOncePerProcess": "false",
                f"canGetAndSet{state}": "true", f"canSerialize{state}": "true"}
    assert {k: cosim.get(k) for k in expected} == expected
    if fmi_version == 3:
        assert float(cosim.get("fixedInternalStepSize", "nan")) == step_s
        assert cosim.get("hasEventMode") == "false"

    source = (NATIVE / f"fmi{fmi_version}.c").read_text()
    used = set(re.findall(r'"(log[A-Z]\w*)"', source))
    declared = {c.get("name") for c in root.iter("Category")}
    assert used == declared == {"logStatusError", "logStatusWarning", "logEvents"}


def test_refuses_what_the_fmu_cannot_declare() -> None:
    """A step size off the 1 ms grid, an input without start, an unknown FMI version."""
    variables = _variables()
    kwargs = {"token": TOKEN, "model_name": "m", "description": "d", "version": "1"}
    with pytest.raises(ValueError):
        model_description(variables, fmi_version=2, default_step_s=1.5e-3, **kwargs)
    with pytest.raises(ValueError, match="force_N"):
        model_description((variables[0], INPUTS[0], *variables[2:]), fmi_version=3,
                          **kwargs)
    with pytest.raises(ValueError):
        model_description(variables, fmi_version=1, **kwargs)
