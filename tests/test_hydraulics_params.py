"""Parameter file loading and input validation of the hydraulic plugin (no mujoco)."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import tomllib
from importlib.resources import files

import pytest

from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.hydraulics.params import params_from_dict
from trackmj.ports import TensionerElement


def _doc() -> dict:
    text = files("trackmj.models").joinpath("lf1352_hydraulics.toml").read_text("utf-8")
    return tomllib.loads(text)


def test_packaged_file_loads_with_sizing_sheet_values() -> None:
    p = load_hydraulic_params()
    assert p.cylinder.area_head_m2 == pytest.approx(math.pi * 0.02**2, rel=1e-3)
    assert p.cylinder.area_rod_m2 == pytest.approx(math.pi * (0.02**2 - 0.0125**2), rel=1e-3)
    assert p.fluid.bulk_modulus_Pa == 1.4e9 and p.tank_pressure_Pa == 0.2e6
    assert p.profiles["W4"](16.0) == 9.0e6 and p.profiles["W4"](5.0) == 12.0e6


def test_every_table_states_its_source() -> None:
    for name, table in _doc().items():
        if name == "profiles":
            assert all("source" in t for t in table.values())
        else:
            assert "source" in table, name


def test_importing_the_plugin_does_not_import_mujoco() -> None:
    code = "import sys, trackmj.hydraulics; print('mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize(
    ("table", "key", "value", "needle"),
    [
        ("fluid", "bulk_modulus_Pa", 0.0, "bulk_modulus_Pa"),
        ("fluid", "bulk_modulus_Pa", -1e9, "bulk_modulus_Pa"),
        ("fluid", "density_kg_m3", float("nan"), "density_kg_m3"),
        ("cylinder", "dead_volume_head_m3", 0.0, "dead_volume_head_m3"),
        ("cylinder", "dead_volume_rod_m3", -1e-4, "dead_volume_rod_m3"),
        ("orifice", "discharge_coefficient", 0.0, "discharge_coefficient"),
        ("orifice", "discharge_coefficient", 1.2, "discharge_coefficient"),
        ("cylinder", "area_head_m2", -1e-3, "area_head_m2"),
        ("cylinder", "area_rod_m2", 2e-3, "area_rod_m2"),
        ("metering", "head_branch_area_m2", -1e-7, "head_branch_area_m2"),
        ("main_valve", "leak_area_m2", -1e-9, "leak_area_m2"),
        ("accumulator", "polytropic_exponent", 0.9, "polytropic_exponent"),
        ("supply", "mode", "pump", "mode"),
    ],
)
def test_bad_parameter_raises_naming_it(table: str, key: str, value: object,
                                        needle: str) -> None:
    doc = _doc()
    doc[table][key] = value
    with pytest.raises(ValueError, match=needle):
        params_from_dict(doc)


def test_missing_key_is_named() -> None:
    doc = _doc()
    del doc["cylinder"]["stroke_max_m"]
    with pytest.raises(ValueError, match="stroke_max_m"):
        params_from_dict(doc)


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
