"""FMI both ways: FMUs as the tensioner and the controller (fmpy), trackmj as an FMU
(pythonfmu), checked against the built-in elements, analytic laws and third-party importers.

The FMUs are built once per session: the gas-charged cylinder from C (tests/fmus, the
Reference FMUs framework, cc), the built-in hydraulic plugin and a P controller wrapped by
pythonfmu, and the exported plant (the native track FMU has its own tests,
test_fmi_native.py)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, filtfilt

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "fmus"))

from build import (  # noqa: E402
    build_gas_cylinder,
    build_reference,
    gas_force_N,
    gas_pressure_Pa,
)

from trackmj.cli.main import main  # noqa: E402
from trackmj.sim.setup import prepare  # noqa: E402


def _tensioner(path: Path, fmu: str, *, inputs: dict, outputs: dict,
               parameters: dict | None = None, extra: str = "") -> Path:
    lines = ["[fmu]", 'source = "tests"', f'path = "{fmu}"', "force_limit_N = 1.0e5",
             "travel_m = [-0.005, 0.105]", extra, "[fmu.inputs]"]
    lines += [f'"{k}" = "{v}"' for k, v in inputs.items()] + ["[fmu.outputs]"]
    lines += [f'"{k}" = "{v}"' for k, v in outputs.items()]
    if parameters:
        lines += ["[fmu.parameters]"] + [f'"{k}" = {v!r}' for k, v in parameters.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


GAS_IO = dict(inputs={"stroke": "stroke_m", "velocity": "velocity_m_s"},
              outputs={"force": "force_N", "power": "port_power_W"})


@pytest.fixture(scope="session")
def fmus(tmp_path_factory) -> Path:
    """The gas cylinder as FMI 2.0 (directional derivatives) and 3.0 (none), one without
    co-simulation roll-back and one without a binary for this platform."""
    d = tmp_path_factory.mktemp("fmus")
    build_gas_cylinder(d / "gas2.fmu", version=2, directional=True)
    build_gas_cylinder(d / "gas3.fmu", version=3, directional=False)
    build_gas_cylinder(d / "gas2_noroll.fmu", version=2, roll_back=False)
    build_gas_cylinder(d / "gas2_win.fmu", version=2, platform_binary=False)
    return d


@pytest.fixture(scope="session")
def hydraulic_fmu(tmp_path_factory) -> dict[str, Path]:
    """The built-in hydraulic plugin as a pythonfmu co-simulation FMU with state roll-back,
    and its tensioner files at W1's initial head pressure: "strong" takes the force over
    the step (the built-in tp's law), "weak" the force at the communication point (what the
    built-in tp-weak holds over the next step)."""
    from pythonfmu.builder import FmuBuilder

    d = tmp_path_factory.mktemp("hydraulic")
    fmu = FmuBuilder.build_FMU(HERE / "fmus" / "HydraulicTensionerFmu.py", dest=d,
                               canGetAndSetFMUstate=True)
    setup = prepare("W1")
    coupling = setup.hydraulics.coupling
    return {kind: _tensioner(
        d / f"hydraulic_{kind}.toml", fmu.name,
        inputs={"stroke_m": "stroke_m", "velocity_m_s": "velocity_m_s",
                "valve_mode": "valve_mode"},
        outputs={force: "force_N", "p_head_Pa": "p_head_Pa", "p_rod_Pa": "p_rod_Pa",
                 "p_supply_Pa": "p_supply_Pa"},
        parameters={"head_pressure_Pa": setup.head_pressure0_Pa},
        extra=f"max_correction_N = {coupling.max_correction_N!r}\n"
              f"min_correction_velocity_m_s = {coupling.min_correction_velocity_m_s!r}")
        for kind, force in (("strong", "step_force_N"), ("weak", "force_N"))}


@pytest.fixture(scope="module")
def w1_runs(hydraulic_fmu) -> dict:
    """W1 (tp, nmpc, 3 s): built-in tp and tp-weak, the FMU strong (tp) and weak (tp-weak)."""
    from trackmj import simulate

    return {"tp": simulate("W1", duration=3.0),
            "tp-weak": simulate("W1", architecture="tp-weak", duration=3.0),
            "fmu": simulate("W1", duration=3.0, tensioner=hydraulic_fmu["strong"]),
            "fmu-weak": simulate("W1", architecture="tp-weak", duration=3.0,
                                 tensioner=hydraulic_fmu["weak"])}


@pytest.mark.slow
def test_round_trip_strong_coupling_reproduces_the_built_in_plugin(w1_runs) -> None:
    """The plugin wrapped as an FMU and coupled strongly (roll-back, central difference on
    dF/dv, NEPCE) gives the built-in element's tension within 1e-6 relative at every step,
    with the same valve decisions."""
    ref, fmu = w1_runs["tp"].columns(), w1_runs["fmu"].columns()
    error = np.abs(fmu["tension_N"] - ref["tension_N"]) / np.abs(ref["tension_N"])
    print(f"round trip, strong: max relative tension error {error.max():.2e}")
    assert error.max() <= 1e-6
    assert np.array_equal(fmu["valve_mode"], ref["valve_mode"])
    described = w1_runs["fmu"].metrics["tensioner"]
    assert described["coupling"] == "strong" and described["interface"] == "co-simulation"
    assert abs(w1_runs["fmu"].metrics["interface_energy_residual_J"]) < 1e-3


def test_round_trip_weak_coupling_is_within_the_tp_weak_difference(w1_runs) -> None:
    """Forced weak (tp-weak) the FMU's error against tp is of tp-weak's size: on the study's
    headline metric (low-pass RMSE) within twice tp-weak's, and on the low-passed tension
    trace within 2.5 times tp-weak's. The FMU's weak exchange holds its whole force, seal
    friction included, where the built-in tp-weak keeps the plugin's friction implicit, so
    their valve sequences part (3 s: 20 and 12 switches against tp's 24). Measured: metric
    1.0 against 5.7 N; traces 86 against 44 N, and 85 N between the FMU and tp-weak."""
    b, a = butter(2, 2.0, fs=1000.0)
    tension = {k: filtfilt(b, a, r.columns()["tension_N"]) for k, r in w1_runs.items()}
    trace = {k: float(np.sqrt(np.mean((tension[k] - tension["tp"]) ** 2)))
             for k in ("tp-weak", "fmu-weak")}
    metric = {k: abs(w1_runs[k].metrics["rmse_lp_N"] - w1_runs["tp"].metrics["rmse_lp_N"])
              for k in ("tp-weak", "fmu-weak")}
    print(f"weak: low-pass trace rms vs tp {trace}, |Δ rmse_lp| {metric}")
    assert w1_runs["fmu-weak"].metrics["tensioner"]["coupling"] == "weak"
    assert metric["fmu-weak"] <= 2.0 * metric["tp-weak"]
    assert trace["fmu-weak"] <= 2.5 * trace["tp-weak"]


@pytest.mark.slow
@pytest.mark.parametrize(("fmu", "interface", "coupling"), [
    ("gas2.fmu", "auto", "strong"),
    ("gas2.fmu", "model-exchange", "implicit"),
    ("gas3.fmu", "model-exchange", "implicit"),
    ("gas2_noroll.fmu", "co-simulation", "weak"),
])
def test_c_fmu_gas_cylinder_as_the_drive_tensioner(fmus, tmp_path, fmu, interface,
                                                   coupling) -> None:
    """The gas cylinder compiled from C as the tensioner of trackmj drive (3 s at 1.5 m/s):
    the mean idler force matches the analytic law at the mean stroke within 1 %, in every
    coupling; the track's energy ledger closes."""
    from trackmj.sim.drive import drive

    toml = _tensioner(fmus / f"{Path(fmu).stem}_{interface}.toml", fmu, **GAS_IO,
                      extra=f'interface = "{interface}"')
    result = drive(1.5, 3.0, tensioner=toml)
    series, m = result.timeseries, result.metrics
    steady = series["t_s"] >= m["steady"]["from_s"]
    force = float(series["idler_force_N"][steady].mean())
    law = gas_force_N(float(series["stroke_m"][steady].mean()))
    print(f"{fmu} {coupling}: mean force {force:.1f} N, law at mean stroke {law:.1f} N "
          f"({100 * (force / law - 1):+.3f} %)")
    assert m["tensioner"]["coupling"] == coupling
    assert force == pytest.approx(law, rel=0.01)
    assert m["mujoco_warnings"] == 0 and m["derailment_checks_failed"] == 0
    energy = m["track_energy"]
    assert abs(energy["residual_J"]) <= 1e-3 * abs(energy["drive_work_J"])


def test_an_fmu_without_a_rod_pressure_has_its_rods_at_tank(fmus, tmp_path) -> None:
    """An FMU that outputs its head pressure but no rod pressure (the README's [fmu]
    example) closes the loop (W2, 0.3 s): the sensors read the FMU's head pressure and the
    rods at the hydraulic file's tank pressure, as a single-acting cylinder vented to tank."""
    from trackmj import simulate

    toml = _tensioner(tmp_path / "head.toml", str(fmus / "gas2.fmu"), inputs=GAS_IO["inputs"],
                      outputs={"force": "force_N", "pressure": "p_head_Pa"})
    result = simulate("W2", duration=0.3, set={"scenario.evaluation.start_s": 0.1},
                      controller="pid", tensioner=toml)
    cols = result.columns()
    head = np.array([gas_pressure_Pa(s) for s in cols["stroke_m"]])
    assert cols["t_s"][-1] == pytest.approx(0.3)
    assert cols["p_head_Pa"] == pytest.approx(head, rel=1e-9)
    assert np.all(cols["p_rod_Pa"] == prepare("W2").hydraulics.tank_pressure_Pa)


@pytest.mark.parametrize(("outputs", "cylinder"), [
    ({"pressure": "p_head_Pa"}, (1e-3, 5e-4, 2e5)),
    ({"pressure": "p_rod_Pa"}, (1e-3, 5e-4, 2e5)),
    ({}, (1e-3, 5e-4, 2e5)),
    ({"pressure": "p_head_Pa"}, None),
])
def test_chamber_pressures_the_fmu_does_not_output_are_stated(fmus, tmp_path, outputs,
                                                               cylinder) -> None:
    """A missing rod pressure is the tank pressure (0 gauge without a hydraulic file); a
    missing head pressure the equivalent of the FMU's force on the hydraulic file's
    cylinders with that rod pressure, (F + A_r·p_rod)/A_h (NaN without one)."""
    from trackmj.elements.fmu import FmuElement
    from trackmj.elements.tensioner_file import load_tensioner

    toml = _tensioner(tmp_path / "p.toml", str(fmus / "gas2.fmu"), inputs=GAS_IO["inputs"],
                      outputs={"force": "force_N"} | outputs)
    element = FmuElement(load_tensioner(toml), 0.06, "strong", equivalent=cylinder)
    log = element.log()
    area_head, area_rod, tank = cylinder or (np.nan, np.nan, 0.0)
    gas = gas_pressure_Pa(0.06)
    rod = gas if "p_rod_Pa" in outputs.values() else tank
    head = gas if "p_head_Pa" in outputs.values() else (log.force_N + area_rod * rod) / area_head
    assert log.force_N == pytest.approx(gas_force_N(0.06), rel=1e-12)
    assert log.p_rod_Pa == rod
    assert log.p_head_Pa == pytest.approx(head, rel=1e-12, nan_ok=True)
    element.inst.close()


@pytest.fixture(scope="session")
def feedthrough(tmp_path_factory) -> Path:
    """The Reference FMUs' Feedthrough (every output follows its input, a variable of every
    type) as FMI 2.0 and 3.0: ft2.fmu, ft3.fmu."""
    d = tmp_path_factory.mktemp("feedthrough")
    for version in (2, 3):
        build_reference("Feedthrough", d / f"ft{version}.fmu", version=version)
    return d


def _controller(path: Path, fmu: Path, *, inputs: dict, outputs: dict,
                parameters: dict | None = None, period_s: float = 0.01) -> Path:
    lines = ["[controller]", 'source = "tests"', f'path = "{fmu}"', f"period_s = {period_s!r}",
             "[controller.inputs]", *(f'"{k}" = "{v}"' for k, v in inputs.items()),
             "[controller.outputs]", *(f'"{k}" = "{v}"' for k, v in outputs.items())]
    if parameters:
        lines += ["[controller.parameters]", *(f'"{k}" = {v!r}' for k, v in parameters.items())]
    path.write_text("\n".join(lines) + "\n")
    return path


def _control(controller_file: Path, stroke_m: float = 0.0, reference_N: float = 0.0) -> float:
    """One period of the controller FMU of ``controller_file`` at t = 0 on a stroke and a
    reference: its output."""
    from trackmj.fmi.controller_fmu import FmuController, load_controller_file

    controller = FmuController(load_controller_file(controller_file))
    try:
        return controller(np.array([0.0, 0.0, stroke_m, 0.0]), np.array([reference_N]), 0.0).u
    finally:
        controller.close()


@pytest.mark.parametrize("real", ["Float32", "Float64"])
def test_fmi3_real_variables_are_set_and_read_by_their_declared_type(feedthrough, tmp_path,
                                                                     real) -> None:
    """A Float32 (or Float64) input and output of an FMI 3.0 controller: the stroke goes in
    and comes out as u, rounded to the type's precision, where fmi3SetFloat64 on a Float32
    variable failed at t = 0."""
    toml = _controller(tmp_path / "c.toml", feedthrough / "ft3.fmu",
                       inputs={f"{real}_continuous_input": "stroke_m"},
                       outputs={f"{real}_continuous_output": "u"})
    expected = float(np.float32(0.3)) if real == "Float32" else 0.3
    assert _control(toml, stroke_m=0.3) == expected


@pytest.mark.parametrize(("version", "integer"), [
    (3, "Int8"), (3, "Int16"), (3, "Int32"), (3, "Int64"), (2, "Int32")])
def test_integer_variables_are_set_and_read_by_their_declared_type(feedthrough, tmp_path,
                                                                   version, integer) -> None:
    """A signed integer parameter and output of every width (FMI 2.0: Integer): a valve mode
    of −1 set as the parameter comes back as the controller's valve_mode."""
    toml = _controller(tmp_path / "c.toml", feedthrough / f"ft{version}.fmu",
                       inputs={"Float64_continuous_input": "stroke_m"},
                       outputs={f"{integer}_output": "valve_mode"},
                       parameters={f"{integer}_input": -1})
    assert _control(toml) == -1


def test_an_fmi3_tensioner_takes_float32_and_int16_ports(feedthrough, tmp_path) -> None:
    """A Float32 stroke input and force output and an Int16 valve_mode input: the element
    starts and steps; the force is the stroke (in Float32), the FMU holds the valve mode."""
    from trackmj.elements.fmu import FmuElement
    from trackmj.elements.tensioner_file import load_tensioner
    from trackmj.fmi.fmu import Channel

    toml = _tensioner(tmp_path / "t.toml", str(feedthrough / "ft3.fmu"),
                      inputs={"Float32_continuous_input": "stroke_m", "Int16_input": "valve_mode",
                              "Float64_continuous_input": "velocity_m_s"},
                      outputs={"Float32_continuous_output": "force_N"})
    element = FmuElement(load_tensioner(toml), 0.05, "strong")
    assert element.force_N == float(np.float32(0.05))
    element.set_valves(-1, 0.0, 0.0)
    element.force_law(0.0, 0.05, 0.0)
    element.complete_step(0.001, 0.06, 0.0)
    assert element.force_N == float(np.float32(0.06))
    assert element.inst.read(Channel("Int16_output", 16, "int", "Int16")) == -1
    element.inst.close()


@pytest.mark.parametrize(("version", "table", "variable", "quantity", "allowed"), [
    (3, "inputs", "UInt8_input", "valve_mode", "Float64, Float32, Int8, Int16, Int32 or Int64"),
    (3, "inputs", "Enumeration_input", "valve_mode",
     "Float64, Float32, Int8, Int16, Int32 or Int64"),
    (3, "outputs", "Int8_output", "force_N", "Float64 or Float32"),
    (3, "outputs", "Binary_output", "force_N", "Float64 or Float32"),
    (2, "inputs", "Boolean_input", "valve_mode", "Real or Integer"),
])
def test_a_variable_of_a_type_the_port_cannot_take_is_refused_at_load(
        feedthrough, tmp_path, version, table, variable, quantity, allowed) -> None:
    """One line naming the file, the variable, its type and the types the port takes (an
    unsigned integer or an Option enumeration cannot carry the valve mode −1)."""
    from trackmj.elements.tensioner_file import load_tensioner
    from trackmj.validator import ParameterError

    io = {"inputs": {"Float64_continuous_input": "stroke_m"},
          "outputs": {"Float64_continuous_output": "force_N"}}
    io[table] = {k: v for k, v in io[table].items() if v != quantity} | {variable: quantity}
    toml = _tensioner(tmp_path / "t.toml", str(feedthrough / f"ft{version}.fmu"), **io)
    with pytest.raises(ParameterError) as refused:
        load_tensioner(toml)
    kind = variable.split("_")[0]
    assert str(refused.value) == (
        f"t.toml [fmu.{table}].{variable}: ft{version}.fmu's variable {variable!r} is of type "
        f"{kind}; {quantity!r} needs {allowed}")


def test_an_integer_parameter_outside_its_type_is_refused_at_load(feedthrough,
                                                                    tmp_path) -> None:
    """300 for an Int8 would wrap to 44 in the call: refused naming the type's range."""
    from trackmj.fmi.controller_fmu import load_controller_file
    from trackmj.validator import ParameterError

    toml = _controller(tmp_path / "c.toml", feedthrough / "ft3.fmu",
                       inputs={"Float64_continuous_input": "stroke_m"},
                       outputs={"Int8_output": "valve_mode"}, parameters={"Int8_input": 300})
    with pytest.raises(ParameterError, match=r"^c\.toml \[controller\.parameters\]\.Int8_input "
                       r"= 300: ft3\.fmu's variable 'Int8_input' is of type Int8, which holds "
                       r"integers in \[-128, 127\]$"):
        load_controller_file(toml)


GAS_UNITS = {"stroke": "m", "velocity": "m/s", "force": "N", "pressure": "Pa",
             "stroke_mm": "mm", "velocity_mm_s": "mm/s", "force_kN": "kN", "pressure_MPa": "MPa"}
"""The units the gas cylinder's variables declare in :func:`unit_fmus` (kN without a BaseUnit,
the others with one)."""


@pytest.fixture(scope="session")
def unit_fmus(tmp_path_factory) -> Path:
    """The gas cylinder declaring :data:`GAS_UNITS`, FMI 2.0 with directional derivatives
    and 3.0 without; one declaring its pressure in absolute bar (a unit with an offset)."""
    d = tmp_path_factory.mktemp("units")
    build_gas_cylinder(d / "gas2.fmu", version=2, directional=True, units=GAS_UNITS)
    build_gas_cylinder(d / "gas3.fmu", version=3, directional=False, units=GAS_UNITS)
    build_gas_cylinder(d / "gas2_abs.fmu", version=2, units={"pressure": "bar_abs"})
    return d


@pytest.mark.parametrize(("fmu", "interface"), [
    ("gas2.fmu", "co-simulation"), ("gas2.fmu", "model-exchange"),
    ("gas3.fmu", "model-exchange")])
def test_declared_units_are_converted_to_si(unit_fmus, tmp_path, fmu, interface) -> None:
    """The cylinder through its variables in mm, mm/s, kN and MPa gives, step by step, the
    force law and head pressure it gives through its SI variables: strong co-simulation,
    implicit model exchange with directional derivatives (taken in the FMU's units) and with
    finite differences. Its declared units ignored, the force came out in kN as N."""
    from trackmj.elements.fmu import FmuElement
    from trackmj.elements.tensioner_file import load_tensioner

    mappings = {"si": ("stroke", "velocity", "force", "pressure"),
                "scaled": ("stroke_mm", "velocity_mm_s", "force_kN", "pressure_MPa")}
    elements = {}
    for name, (stroke, velocity, force, pressure) in mappings.items():
        toml = _tensioner(tmp_path / f"{name}.toml", str(unit_fmus / fmu),
                          inputs={stroke: "stroke_m", velocity: "velocity_m_s"},
                          outputs={force: "force_N", pressure: "p_head_Pa"},
                          extra=f'interface = "{interface}"')
        elements[name] = FmuElement(load_tensioner(toml), 0.06, "strong")
    si, scaled = elements["si"], elements["scaled"]
    d = scaled.description
    assert [c.factor for c in (*d.inputs.values(), *d.outputs.values())] == \
        pytest.approx([1e-3, 1e-3, 1e3, 1e6], rel=1e-15)
    stroke, h = 0.06, 1e-3
    for k in range(20):
        velocity = 0.05 * np.sin(2 * np.pi * 5 * k * h)
        laws = [e.force_law(k * h, stroke, velocity) for e in (si, scaled)]
        assert laws[1].force_N == pytest.approx(laws[0].force_N, rel=1e-9)
        assert laws[1].damping_N_s_m == pytest.approx(laws[0].damping_N_s_m, rel=1e-6)
        stroke += h * velocity
        for e in (si, scaled):
            e.complete_step((k + 1) * h, stroke, velocity)
        assert scaled.log().p_head_Pa == pytest.approx(si.log().p_head_Pa, rel=1e-12)
    assert scaled.force_N == pytest.approx(gas_force_N(stroke, velocity), rel=1e-3)
    for e in (si, scaled):
        e.inst.close()


@pytest.mark.parametrize(("fmu", "table", "variable", "quantity", "expected"), [
    ("gas2.fmu", "outputs", "pressure_MPa", "force_N",
     "has unit 'MPa' (kg m-1 s-2); 'force_N' needs N (kg m s-2) or a multiple of it"),
    ("gas2.fmu", "inputs", "stroke_mm", "velocity_m_s",
     "has unit 'mm' (m); 'velocity_m_s' needs m/s (m s-1) or a multiple of it"),
    ("gas2.fmu", "outputs", "force_kN", "p_head_Pa",
     "has unit 'kN', defined without a BaseUnit (unit 'kN' (kilonewton, a force) is not a "
     "pressure); 'p_head_Pa' needs Pa (kg m-1 s-2) or a multiple of it"),
    ("gas2_abs.fmu", "outputs", "pressure", "p_head_Pa",
     "has unit 'bar_abs', with an offset (in SI 100000·value − 101325); 'p_head_Pa' needs Pa "
     "(kg m-1 s-2) or a multiple of it, without an offset"),
])
def test_a_unit_of_another_dimension_or_with_an_offset_is_refused_at_load(
        unit_fmus, tmp_path, fmu, table, variable, quantity, expected) -> None:
    """One line naming the file, the variable, its unit and the unit the port needs."""
    from trackmj.elements.tensioner_file import load_tensioner
    from trackmj.validator import ParameterError

    io = {"inputs": {"stroke": "stroke_m"}, "outputs": {"force": "force_N"}}
    io[table] = {k: v for k, v in io[table].items() if v != quantity} | {variable: quantity}
    toml = _tensioner(tmp_path / "t.toml", str(unit_fmus / fmu), **io)
    with pytest.raises(ParameterError) as refused:
        load_tensioner(toml)
    assert str(refused.value) == (f"t.toml [fmu.{table}].{variable}: {fmu}'s variable "
                                  f"{variable!r} {expected}")


def test_a_controller_fmu_sees_and_gives_values_in_its_declared_units(feedthrough,
                                                                       tmp_path) -> None:
    """The reference in kN and the opening in %: 50 kN reaches the FMU as 50, whose 50 %
    is u = 0.5; a kN input mapped to the stroke is refused at load."""
    from trackmj.fmi.controller_fmu import load_controller_file
    from trackmj.validator import ParameterError

    fmu = build_reference("Feedthrough", tmp_path / "ft3_units.fmu", units={
        "Float64_continuous_input": "kN", "Float64_continuous_output": "%"})
    toml = _controller(tmp_path / "c.toml", fmu,
                       inputs={"Float64_continuous_input": "F_ref_N",
                               "Float32_continuous_input": "stroke_m"},
                       outputs={"Float64_continuous_output": "u"})
    assert _control(toml, stroke_m=0.05, reference_N=50e3) == pytest.approx(0.5, rel=1e-15)
    toml = _controller(tmp_path / "bad.toml", fmu,
                       inputs={"Float64_continuous_input": "stroke_m"},
                       outputs={"Float64_continuous_output": "u"})
    with pytest.raises(ParameterError, match=r"^bad\.toml \[controller\.inputs\]\."
                       r"Float64_continuous_input: ft3_units\.fmu's variable "
                       r"'Float64_continuous_input' has unit 'kN', defined without a BaseUnit "
                       r"\(.*\); 'stroke_m' needs m \(m\) or a multiple of it$"):
        load_controller_file(toml)


@pytest.mark.parametrize("inputs", [{}, {"Float64_continuous_input": "F_ref_N",
                                        "Float64_discrete_input": "supply_pressure_Pa"}])
def test_a_controller_fmu_without_a_measurement_is_refused_at_load(feedthrough, tmp_path,
                                                                   inputs) -> None:
    """No input, or only the reference and the supply set value: it would run open loop
    and, holding, pass unnoticed; refused in one line naming the file and the quantities."""
    from trackmj.fmi.controller_fmu import load_controller_file
    from trackmj.validator import ParameterError

    toml = _controller(tmp_path / "c.toml", feedthrough / "ft2.fmu", inputs=inputs,
                       outputs={"Float64_continuous_output": "u"})
    with pytest.raises(ParameterError) as refused:
        load_controller_file(toml)
    assert str(refused.value) == (
        "c.toml [controller]: map an FMU input to a measurement (p_head_Pa, p_rod_Pa, "
        "stroke_m, stroke_velocity_m_s); without one the controller runs open loop")


@pytest.mark.parametrize("version", [2, 3])
def test_a_controller_fmu_with_a_fixed_step_runs_only_at_that_period(tmp_path,
                                                                     version) -> None:
    """An FMU that cannot handle a variable communication step, its DefaultExperiment
    stepSize 20 ms (a fixed sample time, as Simulink exports have; stepped every 10 ms such
    an FMU discards the first doStep): a 10 ms period is refused at load naming both, a
    20 ms one runs."""
    from trackmj.fmi.controller_fmu import load_controller_file
    from trackmj.validator import ParameterError

    fmu = build_reference("Feedthrough", tmp_path / f"ft{version}_fixed.fmu", version=version,
                          fixed_step_s=0.02)
    io = dict(inputs={"Float64_continuous_input": "stroke_m"},
              outputs={"Float64_continuous_output": "u"})
    toml = _controller(tmp_path / "c10.toml", fmu, **io, period_s=0.01)
    with pytest.raises(ParameterError) as refused:
        load_controller_file(toml)
    assert str(refused.value) == (
        f"c10.toml [controller].period_s = 0.01 s differs from ft{version}_fixed.fmu's "
        "DefaultExperiment stepSize 0.02 s, the only step it takes (it cannot handle a "
        "variable communication step): set period_s = 0.02")
    toml = _controller(tmp_path / "c20.toml", fmu, **io, period_s=0.02)
    assert _control(toml, stroke_m=0.25) == 0.25


def test_a_failing_step_of_a_controller_fmu_names_its_default_step(tmp_path) -> None:
    """A controller of a fixed 20 ms sample time that declares a variable step (as pythonfmu
    does) loads with a 10 ms period and discards its first doStep: the error names the
    call, its DefaultExperiment stepSize and period_s."""
    from pythonfmu.builder import FmuBuilder

    from trackmj.errors import FmuError

    fmu = FmuBuilder.build_FMU(HERE / "fmus" / "FixedStepController.py", dest=tmp_path)
    toml = _controller(tmp_path / "c.toml", fmu, inputs={"stroke": "stroke_m"},
                       outputs={"u": "u"}, period_s=0.01)
    with pytest.raises(FmuError) as failed:
        _control(toml, stroke_m=0.25)
    assert str(failed.value) == (
        "the FMU FixedStepController.fmu: fmi2DoStep at t = 0.000 s failed: fmi2DoStep failed "
        "with status 2 (discard); its DefaultExperiment stepSize is 0.02 s, period_s 0.01 s: "
        "if it runs at a fixed sample time, set period_s = 0.02")


@pytest.fixture(scope="session")
def plant_fmu(tmp_path_factory) -> Path:
    from trackmj.fmi.export import export

    return export("plant", tmp_path_factory.mktemp("exported") / "plant.fmu").path


FMI2_ERROR = 3
"""fmi2Error (FMI 2.0's fmi2Status)."""


class PlantInstance:
    """One instance of the exported plant through fmpy's FMU2Slave, its messages collected
    by trackmj's FMI 2.0 logger (logging off, as hosts run by default); ``call`` returns
    the FMI status of a call and the message it logged ("" for none)."""

    def __init__(self, fmu: Path, unzipped: Path) -> None:
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Slave

        from trackmj.fmi.fmu import FmuLog, fmi2_callbacks

        md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.log = FmuLog()
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipped),
                             modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName="plant")
        self.fmu.instantiate(callbacks=fmi2_callbacks(self.log), loggingOn=False)

    def call(self, name: str, *args) -> tuple[int, str]:
        from fmpy.fmi1 import FMICallException

        before = self.log.count
        try:
            getattr(self.fmu, name)(*args)
            status = 0
        except FMICallException as exc:
            status = exc.status
        messages = list(self.log.messages)[len(self.log.messages) - (self.log.count - before):]
        return status, " | ".join(text for _, _, text in messages)

    def initialize(self, start_s: float = 0.0) -> PlantInstance:
        self.fmu.setupExperiment(startTime=start_s)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        return self

    def real(self, *names: str) -> list[float]:
        return self.fmu.getReal([self.vr[n] for n in names])


@pytest.fixture
def plant(plant_fmu, tmp_path):
    """A factory of plant instances on one unzipped copy; all freed at the end."""
    from fmpy import extract

    unzipped = Path(extract(str(plant_fmu), str(tmp_path / "plant")))
    made: list[PlantInstance] = []

    def make() -> PlantInstance:
        made.append(PlantInstance(plant_fmu, unzipped))
        return made[-1]

    yield make
    for instance in made:
        instance.fmu.freeInstance()


UNIT_SUFFIXES = {"_Pa": {"kg": 1, "m": -1, "s": -2}, "_m": {"m": 1}, "_m_s": {"m": 1, "s": -1},
                 "_m_s2": {"m": 1, "s": -2}, "_N": {"kg": 1, "m": 1, "s": -2},
                 "_N_m": {"kg": 1, "m": 2, "s": -2}}
"""trackmj's name suffix -> SI base-unit exponents (the dimension the name promises)."""


def test_the_plant_fmu_declares_si_units_descriptions_and_no_direct_feedthrough(
        plant_fmu) -> None:
    """fmpy validates the plant FMU; every variable has a description; every Real a unit
    whose SI base-unit exponents are the dimension its name's suffix promises; the outputs
    depend on no input (they change only in doStep) and are the initial unknowns; the
    generation tool is trackmj and the state can be serialised."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(plant_fmu)) == []
    md = read_model_description(str(plant_fmu))
    units = {u.name: u.baseUnit for u in md.unitDefinitions}
    for v in md.modelVariables:
        assert v.description, v.name
        if v.type == "Real":
            suffix = max((s for s in UNIT_SUFFIXES if v.name.endswith(s)), key=len)
            base = units[v.unit]
            assert {k: getattr(base, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
                    if getattr(base, k)} == UNIT_SUFFIXES[suffix], v.name
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    assert [u.variable for u in md.outputs] == outputs
    assert all(u.dependencies == [] for u in md.outputs)
    assert [u.variable for u in md.initialUnknowns] == outputs
    assert md.generationTool.startswith("trackmj ") and md.license and md.author
    assert md.coSimulation.canSerializeFMUstate


def test_the_plant_fmu_reads_the_initial_state_in_initialization_mode(plant) -> None:
    """Outputs read in initialization mode are W1's initial state (the tension its
    scenario starts from, a stroke inside the travel), the same after initialization; the
    measured head pressure is the true one plus the sensor's noise."""
    fmu = plant()
    fmu.fmu.setupExperiment(startTime=0.0)
    fmu.fmu.enterInitializationMode()
    names = ("tension_N", "stroke_m", "p_head_Pa", "p_head_measured_Pa")
    during = fmu.real(*names)
    fmu.fmu.exitInitializationMode()
    assert fmu.real(*names) == during
    tension, stroke, p_head, measured = during
    assert tension == pytest.approx(prepare("W1").force0_N, rel=1e-12)
    assert -0.005 < stroke < 0.105
    assert measured != p_head and abs(measured - p_head) < 0.05 * p_head


def test_the_plant_fmu_refuses_bad_values_with_fmi2_error_and_a_message(plant) -> None:
    """A bad parameter, a non-finite input, a valve mode outside {-1, 0, 1}, a step that is
    no positive multiple of 1 ms and a doStep at another time than the FMU's each return
    fmi2Error (not Fatal), with a message naming the variable and the allowed values; the
    instance keeps running and a fresh one in the same process runs afterwards."""
    fmu = plant()
    for name, setter, value, allowed in (
            ("machine", "setString", "nosuch", "lf1352"),
            ("scenario", "setString", "W9", "W1"),
            ("seed", "setInteger", -1, ">= 0")):
        status, message = fmu.call(setter, [fmu.vr[name]], [value])
        assert status == FMI2_ERROR and name in message and allowed in message, message
    fmu.initialize()
    for args, expected in (
            (("setReal", [fmu.vr["track_speed_m_s"]], [float("nan")]),
             "track_speed_m_s = nan m/s: allowed a finite value"),
            (("setReal", [fmu.vr["track_speed_m_s"]], [7.5]),
             "track_speed_m_s = 7.5 m/s: allowed a finite value in [-5, 5]"),
            (("setReal", [fmu.vr["hitch_pull_N"]], [float("inf")]),
             "hitch_pull_N = inf N: allowed a finite value"),
            (("setInteger", [fmu.vr["valve_mode"]], [2]), "valve_mode = 2: allowed -1"),
            (("doStep", 0.0, 1.5e-3), "allowed a positive integer multiple of 0.001 s"),
            (("doStep", 0.0, 0.0), "allowed a positive integer multiple of 0.001 s"),
            (("doStep", 0.005, 1e-3), "doStep at t = 0.005 s: the FMU is at t = 0 s")):
        status, message = fmu.call(*args)
        assert status == FMI2_ERROR and expected in message, (args, message)
    assert fmu.call("doStep", 0.0, 2e-3) == (0, "")
    fresh = plant().initialize()
    assert fresh.call("doStep", 0.0, 1e-3) == (0, "")


def test_a_physics_stop_is_an_error_and_a_restored_state_replays_bit_identically(
        plant) -> None:
    """A 10 MN load pushing the hitch down leaves physics within a few steps (the track's
    loop closure tears in the fourth, measured): fmi2Error naming the time and the
    quantity, and every doStep after it too. A state saved before,
    serialised to bytes and deserialised, restores the instance: with the load removed it
    replays the same 50 ms as before bit for bit (sensor noise included); bytes that are no
    state are refused with fmi2Error."""
    fmu = plant().initialize()
    for k in range(10):
        fmu.fmu.doStep(k * 1e-3, 1e-3)
    saved = fmu.fmu.serializeFMUstate(fmu.fmu.getFMUstate())
    fmu.fmu.doStep(0.010, 0.050)
    names = ("stroke_m", "tension_N", "p_head_measured_Pa", "stroke_measured_m")
    reference = fmu.real(*names)
    fmu.fmu.setReal([fmu.vr["hitch_down_N"]], [1e7])
    t, status, message = 0.060, 0, ""
    while status == 0 and t < 0.160:
        status, message = fmu.call("doStep", t, 1e-3)
        t += 1e-3
    print(f"10 MN on the hitch: {message}")
    assert status == FMI2_ERROR
    assert re.search(r"t = 0\.\d+ s: .*(pressure|stroke|MuJoCo|closure)", message), message
    assert fmu.call("doStep", t, 1e-3)[0] == FMI2_ERROR
    status, message = fmu.call("setFMUstate", fmu.fmu.deSerializeFMUstate(b"not a state"))
    assert status == FMI2_ERROR and "no state this FMU serialised" in message
    fmu.fmu.setFMUstate(fmu.fmu.deSerializeFMUstate(saved))
    fmu.fmu.setReal([fmu.vr["hitch_down_N"]], [0.0])
    assert fmu.call("doStep", 0.010, 0.050) == (0, "")
    assert fmu.real(*names) == reference


def test_the_plant_fmu_raises_the_tension_when_pressurized(plant_fmu) -> None:
    """The plant FMU (track + built-in hydraulics): 1 s of valve mode +1 raises the true
    tension and the measured head pressure; the sensors are noisy around the truth."""
    from fmpy import simulate_fmu

    r = simulate_fmu(str(plant_fmu), stop_time=1.0, step_size=1e-3,
                     output_interval=1e-3, start_values={"valve_mode": 1},
                     output=["tension_N", "p_head_Pa", "p_head_measured_Pa"])
    assert r["tension_N"][-1] > r["tension_N"][0] + 2e3
    noise = r["p_head_measured_Pa"] - r["p_head_Pa"]
    assert 0.0 < np.std(noise) < 1e6


def test_the_track_is_not_exported_through_pythonfmu(tmp_path) -> None:
    """``export("track")`` points to the native exporter and writes nothing."""
    from trackmj.fmi.export import export

    with pytest.raises(ValueError, match="native"):
        export("track", tmp_path / "track.fmu")
    assert not (tmp_path / "track.fmu").exists()


BAD = {
    "missing": ("absent.fmu", "no such file"),
    "not_a_zip": ("text.fmu", "is not an FMU (not a zip archive)"),
    "no_binary": ("gas2_win.fmu", "has no binary for this platform"),
}


@pytest.mark.parametrize("case", [*BAD, "unknown_variable", "wrong_causality"])
def test_a_bad_fmu_is_refused_before_the_run(fmus, tmp_path, capsys, case) -> None:
    """Exit 2 with one line naming the file, key and variable; nothing is written."""
    (fmus / "text.fmu").write_text("not an FMU")
    inputs, outputs = dict(GAS_IO["inputs"]), dict(GAS_IO["outputs"])
    fmu, expected = BAD.get(case, ("gas2.fmu", ""))
    if case == "unknown_variable":
        inputs = {"strok": "stroke_m", "velocity": "velocity_m_s"}
        expected = "[fmu.inputs].strok: gas2.fmu has no variable 'strok'"
    if case == "wrong_causality":
        inputs = {"force": "stroke_m", "velocity": "velocity_m_s"}
        expected = "'force' has causality 'output'"
    toml = _tensioner(tmp_path / f"{case}.toml", str(fmus / fmu), inputs=inputs,
                      outputs=outputs)
    out = tmp_path / "run"
    assert main(["run", "W2", "--duration", "1.2", "--tensioner", str(toml),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err and toml.name in err
    assert not out.exists()


@pytest.mark.parametrize(("parameter", "expected"), [
    ("fail_time", "the FMU gas2.fmu: "),
    ("nan_time", "output force_N = nan"),
])
def test_an_fmu_that_fails_mid_run_stops_it_and_keeps_earlier_results(
        fmus, tmp_path, capsys, parameter, expected) -> None:
    """An FMU that errors (or outputs NaN) at 0.5 s: exit 3, one line naming the FMU and the
    call (or the output), the earlier result in the output directory untouched."""
    toml = _tensioner(tmp_path / "gas.toml", str(fmus / "gas2.fmu"), **GAS_IO,
                      parameters={parameter: 0.5})
    out = tmp_path / "run"
    out.mkdir()
    (out / "metrics.json").write_text("{}")   # an earlier result's file
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(["drive", "--duration", "1", "--tensioner", str(toml), "--out", str(out)]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err and ".;" not in err
    assert re.search(r"t = 0\.(499|500) s", err)
    code = main(["run", "W2", "--duration", "1.2", "--tensioner", str(toml), "--out", str(out)])
    assert code in (2, 3)   # 2: the directory guard refuses a foreign folder first
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.slow
def test_a_controller_fmu_closes_the_loop(tmp_path) -> None:
    """A proportional controller exported by pythonfmu (as a Simulink controller would be)
    as --controller fmu:FILE: it runs every 10 ms and tracks W1's 12 kN and 15 kN levels
    within 10 %, switching the valves both ways."""
    from pythonfmu.builder import FmuBuilder

    from trackmj import simulate

    fmu = FmuBuilder.build_FMU(HERE / "fmus" / "TensionController.py", dest=tmp_path)
    cyl = prepare("W1").hydraulics.cylinder
    controller = tmp_path / "controller.toml"
    controller.write_text(
        f'[controller]\nsource = "tests"\npath = "{fmu.name}"\nperiod_s = 0.01\n'
        '[controller.inputs]\np_head = "p_head_Pa"\np_rod = "p_rod_Pa"\nF_ref = "F_ref_N"\n'
        '[controller.outputs]\nu = "u"\n[controller.parameters]\n'
        f'area_head = {2 * cyl.area_head_m2!r}\narea_rod = {2 * cyl.area_rod_m2!r}\n'
        'kp = 2.0e-3\n')
    result = simulate("W1", duration=6.0, controller=f"fmu:{controller}")
    cols = result.columns()
    for start, end in ((1.0, 2.9), (4.5, 6.0)):
        window = (cols["t_s"] > start) & (cols["t_s"] <= end)
        assert cols["tension_N"][window].mean() == pytest.approx(
            cols["tension_ref_N"][window].mean(), rel=0.1)
    assert set(np.unique(cols["valve_mode"])) == {-1, 0, 1}
    assert result.controller == "fmu" and result.metrics["controller_fallbacks"] == 0.0
