"""Tensioner kinds are a registry (:data:`trackmj.elements.tensioner_file.TENSIONER_KINDS`):
every table a tensioner file may hold is registered, makes a registered element, and takes
part in a run's identity with the files it reads, so a campaign never reuses a result made
with another tensioner."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

from trackmj.elements.tensioner_file import TENSIONER_KINDS, TensionerFile, load_tensioner
from trackmj.sim.registry import ELEMENTS
from trackmj.validator import ParameterError

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE / "fmus"))
from build import build_gas_cylinder  # noqa: E402

PASSIVE = ('[passive]\nsource = "tests: a spring-damper"\npreload_N = 13000.0\n'
           'stiffness_N_m = {k}\ndamping_N_s_m = 2.0e4\nstroke_ref_m = 0.05\n'
           'travel_m = [-0.005, 0.105]\n')
FMU = ('[fmu]\nsource = "tests"\npath = "{name}"\nforce_limit_N = 1.0e5\n'
       'travel_m = [-0.005, 0.105]\n[fmu.inputs]\n"stroke" = "stroke_m"\n'
       '"velocity" = "velocity_m_s"\n[fmu.outputs]\n"force" = "force_N"\n'
       '"power" = "port_power_W"\n')


def test_every_table_of_a_tensioner_file_is_a_registered_kind_with_an_element() -> None:
    tables = {f.name for f in dataclasses.fields(TensionerFile)
              if f.compare and f.name != "sources"}
    assert tables == set(TENSIONER_KINDS)
    assert all(kind.element in ELEMENTS for kind in TENSIONER_KINDS.values())


def test_a_file_holds_exactly_one_kind(tmp_path: Path) -> None:
    both = tmp_path / "both.toml"
    both.write_text(PASSIVE.format(k=0.0) + FMU.format(name="x.fmu"))
    with pytest.raises(ParameterError, match=r"exactly one of the tables \[passive\] and "
                                             r"\[fmu\]"):
        load_tensioner(both)


def test_identity_follows_each_kinds_table_and_the_files_it_reads(tmp_path: Path) -> None:
    soft, stiff = tmp_path / "soft.toml", tmp_path / "stiff.toml"
    soft.write_text(PASSIVE.format(k=0.0))
    stiff.write_text(PASSIVE.format(k=1.0e5))
    assert load_tensioner(soft).identity() != load_tensioner(stiff).identity()
    assert load_tensioner(soft).kind == "passive"

    build_gas_cylinder(tmp_path / "gas.fmu", version=2)
    gas = tmp_path / "gas.toml"
    gas.write_text(FMU.format(name="gas.fmu"))
    loaded = load_tensioner(gas)
    assert loaded.kind == "fmu" and loaded.element == "fmu"
    before = loaded.identity()
    assert load_tensioner(gas).identity() == before   # stable
    build_gas_cylinder(tmp_path / "gas.fmu", version=3)   # same file name, other content
    assert load_tensioner(gas).identity() != before
