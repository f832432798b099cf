"""Parameter file loading and input validation of the hydraulic plugin (no mujoco)."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import tomllib
from importlib.resources import files

import pytest

from trackmj.hydraulics import HydraulicTensioner, PressureProfile, load_hydraulic_params
from trackmj.hydraulics.params import HydraulicParams
from trackmj.ports import TensionerElement
from trackmj.validator import ParameterError, build


def _doc() -> dict:
    text = files("trackmj.models").joinpath("lf1352_hydraulics.toml").read_text("utf-8")
    return tomllib.loads(text)


def test_packaged_file_loads_with_sizing_sheet_values() -> None:
    p = load_hydraulic_params()
    assert p.cylinder.area_head_m2 == pytest.approx(math.pi * 0.02**2, rel=1e-3)
    assert p.cylinder.area_rod_m2 == pytest.approx(math.pi * (0.02**2 - 0.0125**2), rel=1e-3)
    assert p.fluid.bulk_modulus_Pa == 1.4e9 and p.tank_pressure_Pa == 0.2e6
    assert p.supply.setpoint_Pa == 12.0e6 and p.supply.default_model == "compensated"
    assert p.cut_in_Pa(12.0e6) == pytest.approx(10.2e6)


def test_every_table_states_its_source() -> None:
    """Every table's source is kept (table path -> source), and one missing is refused."""
    p = load_hydraulic_params()
    doc = _doc()
    expected = {name: table["source"] for name, table in doc.items()}
    assert dict(p.sources) == expected
    del doc["relief"]["source"]
    with pytest.raises(ParameterError, match=r"h\.toml \[relief\]: missing key 'source'"):
        build(HydraulicParams, doc, file="h.toml")


def test_importing_the_plugin_does_not_import_mujoco() -> None:
    code = "import sys, trackmj.hydraulics; print('mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize(
    ("table", "key", "value", "needle"),
    [
        ("fluid", "bulk_modulus_Pa", 0.0, r"\[fluid\]\.bulk_modulus_Pa = 0\.0 is outside the "
         r"allowed range \(0, 1e\+11\] Pa"),
        ("fluid", "bulk_modulus_Pa", -1e9,
         r"\[fluid\]\.bulk_modulus_Pa = -1000000000\.0 is outside"),
        ("fluid", "bulk_modulus_Pa", True, r"\[fluid\]\.bulk_modulus_Pa = True: expected a number, "
         r"got a boolean"),
        ("fluid", "bulk_modulus_Pa", "1.4e9", r"\[fluid\]\.bulk_modulus_Pa = '1\.4e9': expected a "
         r"number, got a string"),
        ("fluid", "density_kg_m3", float("nan"), r"\[fluid\]\.density_kg_m3 = nan: must be finite"),
        ("cylinder", "dead_volume_head_m3", 0.0, r"\[cylinder\]\.dead_volume_head_m3 = 0\.0 is"),
        ("cylinder", "dead_volume_rod_m3", -1e-4,
         r"\[cylinder\]\.dead_volume_rod_m3 = -0\.0001 is"),
        ("orifice", "discharge_coefficient", 0.0, r"\[orifice\]\.discharge_coefficient = 0\.0 is "
         r"outside the allowed range \(0, 1\]$"),
        ("orifice", "discharge_coefficient", 1.2, r"\[orifice\]\.discharge_coefficient = 1\.2 is"),
        ("cylinder", "area_head_m2", -1e-3, r"\[cylinder\]\.area_head_m2 = -0\.001 is outside"),
        ("cylinder", "area_rod_m2", 2e-3, r"\[cylinder\]\.area_rod_m2 = 0\.002 must be < "
         r"area_head_m2 = 0\.0012566"),
        ("metering", "head_branch_area_m2", -1e-7, r"\[metering\]\.head_branch_area_m2 = -1e-07"),
        ("main_valve", "leak_area_m2", -1e-9, r"\[main_valve\]\.leak_area_m2 = -1e-09 is outside"),
        ("main_valve", "leak_area_m2", 1e-3, r"\[main_valve\]\.leak_area_m2 = 0\.001 must be <= "
         r"open_area_m2 = 0\.0001"),
        ("relief", "band_Pa", 0.0, r"\[relief\]\.band_Pa = 0\.0 is outside the allowed range "
         r"\(0, 1e\+07\] Pa"),
        ("variable_pump", "standby_flow_m3_s", 1e-4, r"\[variable_pump\]\.standby_flow_m3_s = "
         r"0\.0001 must be < max_flow_m3_s = 3\.333e-05"),
        ("unloading_valve", "unloaded_pressure_Pa", 1e5, r"\[unloading_valve\]\."
         r"unloaded_pressure_Pa = 100000\.0 must be >= \[tank\]\.pressure_Pa = 200000\.0"),
        ("fixed_pump", "volumetric_efficiency", 1.1, r"\[fixed_pump\]\.volumetric_efficiency = "
         r"1\.1 is outside the allowed range \(0, 1\]$"),
        ("accumulator", "polytropic_exponent", 0.9, r"\[accumulator\]\.polytropic_exponent = 0\.9"),
        ("supply", "default_model", "pump", r"\[supply\]\.default_model = 'pump' is not one of "
         r"\['fixed_relief', 'compensated', 'unloading', 'prescribed'\]"),
        ("coupling", "newton_max_iter", 30.0, r"\[coupling\]\.newton_max_iter = 30\.0: expected an "
         r"integer, got a float"),
        ("lines", "line_a_volume_m3", [5e-5],
         r"\[lines\]\.line_a_volume_m3 = \[5e-05\]: expected a number, got an array"),
        ("fluid", "bulk_modulus_Paa", 1.4e9, r"\[fluid\]: unknown key 'bulk_modulus_Paa'; did you "
         r"mean 'bulk_modulus_Pa'\?"),
    ],
)
def test_bad_parameter_raises_naming_file_table_and_key(table: str, key: str, value: object,
                                                        needle: str) -> None:
    """The issue's cases: a misspelt key, ``true`` and a string for a number are refused."""
    doc = _doc()
    doc[table][key] = value
    with pytest.raises(ParameterError, match=r"^h\.toml " + needle):
        build(HydraulicParams, doc, file="h.toml")


def test_missing_key_and_table_are_named() -> None:
    doc = _doc()
    del doc["cylinder"]["stroke_max_m"]
    with pytest.raises(ParameterError, match=r"h\.toml \[cylinder\]: missing key 'stroke_max_m' "
                       r"\(a number, m, range \(0, 10\]\)"):
        build(HydraulicParams, doc, file="h.toml")
    doc = _doc()
    del doc["tank"]
    with pytest.raises(ParameterError, match=r"h\.toml: missing table \[tank\]"):
        build(HydraulicParams, doc, file="h.toml")



def test_setpoint_profile_order_is_checked() -> None:
    with pytest.raises(ParameterError, match=r"^PressureProfile\.times_s\[2\] = 12\.0 must be > "
                       r"times_s\[1\] = 12\.0 \(strictly increasing\)"):
        PressureProfile((0.0, 12.0, 12.0), (12e6, 12e6, 9e6))
    assert PressureProfile((0.0, 12.0, 12.1), (12e6, 12e6, 9e6))(12.05) == pytest.approx(10.5e6)


def test_code_construction_is_checked_too() -> None:
    """``dataclasses.replace`` runs the same checks (named after the class), and integers
    given for floats are stored as floats."""
    p = load_hydraulic_params()
    with pytest.raises(ParameterError, match=r"^Fluid\.bulk_modulus_Pa = True: expected a number"):
        dataclasses.replace(p.fluid, bulk_modulus_Pa=True)
    with pytest.raises(ParameterError, match=r"^Cylinder\.area_rod_m2 = 0\.002 must be < "):
        dataclasses.replace(p.cylinder, area_rod_m2=2e-3)
    fluid = dataclasses.replace(p.fluid, density_kg_m3=860)
    assert type(fluid.density_kg_m3) is float


def test_dataclasses_are_frozen() -> None:
    p = load_hydraulic_params()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.fluid.bulk_modulus_Pa = 1.0  # type: ignore[misc]


@pytest.mark.parametrize("name", ["t_s", "stroke_m", "velocity_m_s"])
@pytest.mark.parametrize("method", ["force_law", "complete_step"])
def test_nan_inputs_raise_naming_the_input(name: str, method: str) -> None:
    ht = HydraulicTensioner()
    assert isinstance(ht, TensionerElement)
    args = {"t_s": 0.0, "stroke_m": 0.05, "velocity_m_s": 0.0}
    if method == "complete_step":
        ht.force_law(**args)
        args["t_s"] = 1e-3
    args[name] = float("nan")
    with pytest.raises(ValueError, match=name):
        getattr(ht, method)(**args)


def test_bad_mode_and_command_rejected() -> None:
    ht = HydraulicTensioner()
    with pytest.raises(ValueError, match="mode"):
        ht.set_mode(2)
    with pytest.raises(ValueError, match="command"):
        ht.set_command(0.0, 1.5, 0.0)
    with pytest.raises(ValueError, match="coupling"):
        HydraulicTensioner(coupling="loose")  # type: ignore[arg-type]
