"""The one validator over every file kind (model, hydraulics, control, scenario): the same
refusals with the same messages, overrides, units and docs of every field, shipped sources."""

from __future__ import annotations

import functools
import math
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from trackmj.cli.main import main
from trackmj.control.params import ControlConfig, PlantParams, load_config
from trackmj.control.params import default_path as control_path
from trackmj.hydraulics.params import HydraulicParams, load_hydraulic_params
from trackmj.hydraulics.params import default_path as hydraulics_path
from trackmj.machines.idler import IdlerFile
from trackmj.scenarios.load import load_scenario, scenario_path
from trackmj.scenarios.schema import ScenarioFile
from trackmj.track.mechanics import ModelParams, default_param_path, load_model_params, models_dir
from trackmj.validator import (
    FILE_KINDS,
    ParameterError,
    Parameters,
    build,
    describe_schema,
    file_fields,
    numeric_fields,
    param,
    parameter_classes,
    parse_overrides,
    unit_from_name,
)

# kind -> (loader(path, overrides), packaged file, a table, a float key in it, a value
# outside its range, the range text in the message)
KINDS: dict[str, tuple[Callable[..., Any], Path, str, str, float, str]] = {
    "model": (load_model_params, default_param_path(), "chassis", "mass_kg", 5.0,
              r"\[10, 100000\] kg"),
    "hydraulics": (load_hydraulic_params, hydraulics_path(), "fluid", "bulk_modulus_Pa", -1.0,
                   r"\(0, 1e\+11\] Pa"),
    "control": (functools.partial(load_config, nominal_tension_N=15e3), control_path(), "mpc",
                "weight_input", -1.0, r"\[0, 1e\+06\]"),
    "scenario": (load_scenario, scenario_path("W1"), "track", "speed_m_s", 6.0,
                 r"\[-5, 5\] m/s"),
}


def _dump(data: dict[str, Any], prefix: str = "") -> str:
    """Minimal TOML writer for the parsed packaged files (tables, arrays of tables)."""
    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float) and not math.isfinite(v):
            return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    lines = [f"{k} = {value(v)}" for k, v in data.items()
             if not isinstance(v, dict) and not (isinstance(v, list) and v
                                                 and isinstance(v[0], dict))]
    for k, v in data.items():
        if isinstance(v, dict):
            lines += ["", f"[{prefix}{k}]", _dump(v, f"{prefix}{k}.")]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines += ["", f"[[{prefix}{k}]]", _dump(item, f"{prefix}{k}.")]
    return "\n".join(lines)


def _mutated(tmp_path: Path, kind: str, change: Callable[[dict], None]) -> Path:
    path = KINDS[kind][1]
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    change(data)
    out = tmp_path / f"bad_{kind}.toml"
    out.write_text(_dump(data), encoding="utf-8")
    return out


def _set(table: str, key: str, value: Any) -> Callable[[dict], None]:
    return lambda d: d[table].__setitem__(key, value)


def _del(table: str, key: str) -> Callable[[dict], None]:
    return lambda d: d[table].pop(key)


def _rename_table(table: str) -> Callable[[dict], None]:
    return lambda d: d.__setitem__(table + "s", d.pop(table))


CASES = {
    "unknown key": (lambda t, k: _set(t, k + "x", 1.0),
                    lambda f, t, k: rf"^{f} \[{t}\]: unknown key '{k}x'; did you mean '{k}'\?"),
    "misspelt table": (lambda t, k: _rename_table(t),
                       lambda f, t, k: rf"^{f}: unknown table \[{t}s\]; did you mean '{t}'\?"),
    "string for number": (lambda t, k: _set(t, k, "1.0"),
                          lambda f, t, k: rf"^{f} \[{t}\]\.{k} = '1\.0': expected a number, "
                          "got a string$"),
    "bool for number": (lambda t, k: _set(t, k, True),
                        lambda f, t, k: rf"^{f} \[{t}\]\.{k} = True: expected a number, got a "
                        "boolean$"),
    "list for scalar": (lambda t, k: _set(t, k, [1.0, 2.0]),
                        lambda f, t, k: rf"^{f} \[{t}\]\.{k} = \[1\.0, 2\.0\]: expected a "
                        "number, got an array$"),
    "table for scalar": (lambda t, k: _set(t, k, {"a": 1.0}),
                         lambda f, t, k: rf"^{f} \[{t}\]\.{k} = \{{\.\.\.\}}: expected a number, "
                         "got a table$"),
    "NaN": (lambda t, k: _set(t, k, math.nan),
            lambda f, t, k: rf"^{f} \[{t}\]\.{k} = nan: must be finite$"),
    "missing key": (lambda t, k: _del(t, k),
                    lambda f, t, k: rf"^{f} \[{t}\]: missing key '{k}' \(a number"),
    "missing table": (lambda t, k: (lambda d: d.pop(t)),
                      lambda f, t, k: rf"^{f}: missing table \[{t}\]$"),
    "scalar for table": (lambda t, k: (lambda d: d.__setitem__(t, 3)),
                         lambda f, t, k: rf"^{f}: {t} = 3: expected a table \[{t}\], got an "
                         "integer$"),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("kind", list(KINDS))
def test_every_file_kind_refuses_the_same_mistakes_naming_file_table_key(
        tmp_path, kind: str, case: str) -> None:
    loader, _, table, key, _, _ = KINDS[kind]
    change, message = CASES[case]
    path = _mutated(tmp_path, kind, change(table, key))
    with pytest.raises(ParameterError, match=message(re.escape(path.name), table, key)):
        loader(path)


@pytest.mark.parametrize("kind", list(KINDS))
def test_out_of_range_names_value_and_range(tmp_path, kind: str) -> None:
    loader, _, table, key, bad, allowed = KINDS[kind]
    path = _mutated(tmp_path, kind, _set(table, key, bad))
    with pytest.raises(ParameterError, match=rf"^{re.escape(path.name)} \[{table}\]\.{key} = "
                       rf"{re.escape(repr(bad))} is outside the allowed range {allowed}$"):
        loader(path)


@pytest.mark.parametrize("kind", ["model", "hydraulics", "control"])
def test_parameter_files_need_a_source_in_every_table(tmp_path, kind: str) -> None:
    loader, _, table, _, _, _ = KINDS[kind]
    assert loader().sources[table]           # kept: table -> source
    path = _mutated(tmp_path, kind, _del(table, "source"))
    with pytest.raises(ParameterError, match=rf"^{re.escape(path.name)} \[{table}\]: missing key "
                       r"'source' \(where the values come from"):
        loader(path)
    path = _mutated(tmp_path, kind, _set(table, "source", ""))
    with pytest.raises(ParameterError, match=r"\.source = '': expected a non-empty string"):
        loader(path)


def test_scenario_files_need_no_source(tmp_path) -> None:
    assert load_scenario(_mutated(tmp_path, "scenario", lambda d: None)).name == "W1"
    path = _mutated(tmp_path, "scenario", _set("track", "source", "assumed: 1.5 m/s"))
    assert load_scenario(path).track.speed_m_s == 1.5


@pytest.mark.parametrize(("kind", "item", "read"), [
    ("model", "model.chassis.mass_kg=1300", lambda p: p.chassis.mass_kg),
    ("hydraulics", "hydraulics.fluid.bulk_modulus_Pa=1.2e9", lambda p: p.fluid.bulk_modulus_Pa),
    ("control", "control.mpc.weight_input=1.5", lambda p: p.mpc.weight_input),
    ("scenario", "scenario.track.speed_m_s=2.0", lambda p: p.track.speed_m_s),
])
def test_valid_override_changes_the_loaded_value(kind: str, item: str, read) -> None:
    loader = KINDS[kind][0]
    sets = parse_overrides([item])
    value = float(item.split("=")[1])
    loaded = loader(None if kind != "scenario" else "W1", overrides=sets[kind])
    assert read(loaded) == value and read(loader(*(["W1"] if kind == "scenario" else []))) \
        != value
    if kind != "scenario":                    # a report can cite the override
        (key, raw), = sets[kind].items()
        assert loaded.sources[key] == f"--set {kind}.{key}={raw!r}"


@pytest.mark.parametrize(("kind", "key", "value", "message"), [
    ("model", "chassis.mass_kgg", 1.0, r"^--set model\.chassis\.mass_kgg: \[chassis\] has no key "
     r"'mass_kgg'; did you mean 'mass_kg'\?"),
    ("hydraulics", "fluids.bulk_modulus_Pa", 1.0, r"^--set hydraulics\.fluids\.bulk_modulus_Pa: "
     r"the file has no key 'fluids'; did you mean 'fluid'\?"),
    ("hydraulics", "fluid.bulk_modulus_Pa", -1.0, r"^--set hydraulics\.fluid\.bulk_modulus_Pa = "
     r"-1\.0 is outside the allowed range \(0, 1e\+11\] Pa$"),
    ("hydraulics", "fluid.bulk_modulus_Pa", True, r"^--set hydraulics\.fluid\.bulk_modulus_Pa = "
     r"True: expected a number, got a boolean$"),
    ("hydraulics", "supply.default_model", "pump", r"^--set hydraulics\.supply\.default_model = "
     r"'pump' is not one of \['fixed_relief', 'compensated', 'unloading', 'prescribed'\]$"),
    ("hydraulics", "fluid.bulk_modulus_Pa.x", 1.0, r"^--set hydraulics\.fluid\.bulk_modulus_Pa\.x"
     r": fluid\.bulk_modulus_Pa is a value, not a table$"),
    ("control", "mpc.horizon_steps", 16, r"^--set control\.mpc\.horizon_steps = 16 must be a "
     r"multiple of block_steps = 3$"),
    ("model", "road_wheels.x_m.6", 1.0, r"^--set model\.road_wheels\.x_m\.6: index '6' is out of "
     r"range; \[road_wheels\.x_m\] has 6 entries$"),
    ("model", "road_wheels.x_m.-1", 1.0, r"^--set model\.road_wheels\.x_m\.-1: '-1' is not an "
     r"index; \[road_wheels\.x_m\] is an array \(indices 0-5\)$"),
    ("hydraulics", "fluid.bulk-modulus_Pa", 1.0, r"^--set hydraulics\.fluid\.bulk-modulus_Pa: "
     r"\[fluid\] has no key 'bulk-modulus_Pa'; did you mean 'bulk_modulus_Pa'\?"),
    ("hydraulics", "fluidbulk_modulus_Pa", 1.0, r"^--set hydraulics\.fluidbulk_modulus_Pa: the "
     r"file has no key 'fluidbulk_modulus_Pa'; did you mean hydraulics\.fluid\.bulk_modulus_Pa\?"),
    ("hydraulics", "supply.bulk_modulus_Pa", 1.0, r"^--set hydraulics\.supply\.bulk_modulus_Pa: "
     r"\[supply\] has no key 'bulk_modulus_Pa'; did you mean hydraulics\.fluid\.bulk_modulus_Pa"
     r"\? \(allowed: default_model, setpoint_Pa, line_volume_m3\)$"),
    ("model", "preload_N", 1.0, r"^--set model\.preload_N: the file has no key 'preload_N'; did "
     r"you mean model\.tensioner\.preload_N\?"),
    ("control", "max_iter", 1, r"^--set control\.max_iter: the file has no key 'max_iter'; did "
     r"you mean control\.mpc\.max_iter\?"),
    ("scenario", "reference.steps.x.time_s", 5.0, r"^--set scenario\.reference\.steps\.x\.time_s: "
     r"'x' is not an index; \[reference\.steps\] is an array \(index 0\)$"),
    ("scenario", "load_pulses.x.hitch_N", 1.0, r"^--set scenario\.load_pulses\.x\.hitch_N: 'x' "
     r"is not an index; \[load_pulses\] is an array \(no entries\)$"),
    ("model", "road_wheels.x_m.1", 20.0, r"^--set model\.road_wheels\.x_m\.1 = 20\.0 is outside "
     r"the allowed range \[-10, 10\] m$"),
])
def test_invalid_override_is_named_by_its_option(kind: str, key: str, value: Any,
                                                 message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        KINDS[kind][0](*(["W1"] if kind == "scenario" else []), overrides={key: value})


def test_parse_overrides_reads_toml_values_and_refuses_malformed_items() -> None:
    sets = parse_overrides(["hydraulics.fluid.bulk_modulus_Pa=1.2e9", "scenario.track.ramp_s=2",
                            "model.solver.warmstart=true", 'scenario.scenario.title="a b"',
                            "scenario.scenario.controller=pid",
                            "model.idler.slide_range_m=[-0.04, 0.04]",
                            "scenario.load_pulses.0.hitch_N = -15000"])
    assert set(sets) == set(FILE_KINDS) and sets["control"] == {}
    assert sets["hydraulics"] == {"fluid.bulk_modulus_Pa": 1.2e9}
    assert sets["scenario"] == {"track.ramp_s": 2, "scenario.title": "a b",
                                "scenario.controller": "pid", "load_pulses.0.hitch_N": -15000}
    assert sets["model"] == {"solver.warmstart": True, "idler.slide_range_m": [-0.04, 0.04]}
    for item, message in [
        ("hydraulics.fluid.bulk_modulus_Pa", r"--set 'hydraulics\.fluid\.bulk_modulus_Pa': "
         r"expected KIND\.TABLE\.KEY=VALUE"),
        ("hydraulic.fluid.bulk_modulus_Pa=1", r"unknown file kind 'hydraulic'; did you mean "
         r"'hydraulics'\? \(allowed: model, hydraulics, control, scenario\)$"),
        ("hydraulicsfluid.bulk_modulus_Pa=1", r"unknown file kind 'hydraulicsfluid'; did you "
         r"mean hydraulics\.fluid\.bulk_modulus_Pa\? \(allowed: "),
        ("models.track.pitch_m=1", r"unknown file kind 'models'; did you mean 'model'\?"),
        ("hydraulics=1", r"names no key; expected hydraulics\.TABLE\.KEY \(`trackmj keys "
         r"hydraulics` lists them\)$"),
        ("hydraulics.fluid..bulk_modulus_Pa=1", r"an empty key between two dots; did you mean "
         r"hydraulics\.fluid\.bulk_modulus_Pa\?$"),
        ("scenario.track.speed_m_s=1.5 m/s", r"cannot read the value '1\.5 m/s'; write a TOML "
         r"value"),
        ("scenario.track.speed_m_s=", r"expected KIND\.TABLE\.KEY=VALUE"),
    ]:
        with pytest.raises(ParameterError, match=message):
            parse_overrides([item])
    with pytest.raises(ParameterError, match=r"scenario\.track\.ramp_s is given twice"):
        parse_overrides(["scenario.track.ramp_s=1", "scenario.track.ramp_s=2"])


ROOTS = (ModelParams, HydraulicParams, ControlConfig, ScenarioFile, IdlerFile, PlantParams)


def test_every_numeric_field_has_a_unit_and_every_field_a_doc() -> None:
    """Units from the SI suffix or declared; docs on every field (the model file's classes,
    owned by the track-model branch, are checked for units only)."""
    missing_unit, missing_doc = [], []
    for root in ROOTS:
        for cls in parameter_classes(root):
            fields = file_fields(cls)
            missing_unit += [f"{cls.__name__}.{n}" for n in numeric_fields(cls)
                             if not fields[n].spec.unit]
            if cls.__module__ != "trackmj.track.mechanics":
                missing_doc += [f"{cls.__name__}.{n}" for n, f in fields.items()
                                if not f.spec.doc and not _is_table(f.hint)]
    assert missing_unit == []
    assert missing_doc == []


def _is_table(hint: Any) -> bool:
    return isinstance(hint, type) and hasattr(hint, "__dataclass_fields__")


@pytest.mark.parametrize(("name", "unit"), [
    ("stiffness_N_m", "N/m"), ("damping_N_s_m", "N·s/m"), ("drive_gain_N_m_s", "N·m·s/rad"),
    ("rate_N_s", "N/s"), ("leakage_m3_s_Pa", "m^3/(s·Pa)"), ("pump_flow_m3_s", "m^3/s"),
    ("atmospheric_pressure_Pa_abs", "Pa (absolute)"), ("pitch_inertia_kg_m2", "kg·m^2"),
    ("density_kg_m3", "kg/m^3"), ("gravity_m_s2", "m/s^2"), ("speed_m_s", "m/s"),
    ("kinematic_viscosity_m2_s", "m^2/s"), ("n_min_cycles_m", "1/m"), ("hitch_N", "N"),
    ("pull_angle_deg", "deg"), ("link_count", "1"), ("ukf_alpha", None), ("count", None),
])
def test_unit_suffixes(name: str, unit: str | None) -> None:
    assert unit_from_name(name) == unit


def test_schema_description_lists_every_key_of_the_hydraulic_file() -> None:
    rows = {r.key: r for r in describe_schema(HydraulicParams)}
    data = tomllib.loads(hydraulics_path().read_text(encoding="utf-8"))
    keys = {f"{t}.{k}" for t, table in data.items() for k in table if k != "source"}
    assert set(rows) == keys
    assert str(rows["fluid.bulk_modulus_Pa"]) == (
        "fluid.bulk_modulus_Pa: a number, Pa, (0, 1e+11] - effective bulk modulus of the oil")
    assert rows["supply.default_model"].range == "" and rows["supply.default_model"].type == (
        "one of ['fixed_relief', 'compensated', 'unloading', 'prescribed']")


@dataclass(frozen=True)
class _Profile(Parameters):
    times_s: tuple[float, ...] = param(0.0, None, doc="breakpoints")


@dataclass(frozen=True)
class _NamedTables(Parameters):
    profiles: Mapping[str, _Profile] = param(default_factory=dict, doc="named tables")


def test_named_tables_load_and_overrides_name_a_missing_table() -> None:
    """A table of named tables ([profiles.NAME]); no packaged file has one."""
    data = {"profiles": {"W4": {"source": "assumed: test", "times_s": [0.0, 1.0]}}}
    assert build(_NamedTables, data, file="n.toml").profiles["W4"].times_s == (0.0, 1.0)
    with pytest.raises(ParameterError, match=r"^--set profiles\.W5\.times_s: the file has no "
                       r"table \[profiles\.W5\] \(has: W4\)$"):
        build(_NamedTables, data, file="n.toml", overrides={"profiles.W5.times_s": [0.0]})
    with pytest.raises(ParameterError, match=r"^n\.toml \[profiles\.W4\]\.times_s\[1\] = -1\.0 "
                       r"is outside the allowed range \[0, inf\] s$"):
        build(_NamedTables, {"profiles": {"W4": {"source": "x", "times_s": [0.0, -1.0]}}},
              file="n.toml")


def test_optional_keys_are_documented_as_optional() -> None:
    rows = {r.key: r for r in describe_schema(ScenarioFile)}
    assert rows["reference.ramps[].end_s"].default == "None"
    assert rows["variants[].friction_scale"].default == "1.0"
    assert rows["scenario.duration_s"].default is None      # required
    assert "without from_file" in rows["track.speed_m_s"].doc   # required unless a file


def test_shipped_files_cite_sources_a_user_has() -> None:
    """No development-machine path or reference-note file in the packaged TOML files."""
    files = sorted(models_dir().glob("*.toml")) + sorted(
        scenario_path("W1").parent.glob("*.toml"))
    assert len(files) >= 9
    pattern = re.compile(r"/work/|\.\./shared|shared/reference|paper-notes|field-notes")
    offenders = [f"{f.name}: {line.strip()}" for f in files
                 for line in f.read_text(encoding="utf-8").splitlines() if pattern.search(line)]
    assert offenders == []
    for text in (f.read_text(encoding="utf-8") for f in files if f.parent == models_dir()):
        if "study" in text:
            assert "Ding et al" in text


@pytest.mark.parametrize(("item", "nearest"), [
    ("hydraulics.fluid.bulk-modulus_Pa=1e9", "[fluid] has no key 'bulk-modulus_Pa'; did you "
     "mean 'bulk_modulus_Pa'?"),
    ("hydraulicsfluid.bulk_modulus_Pa=1e9", "did you mean hydraulics.fluid.bulk_modulus_Pa?"),
    ("model.sprockettooth_count=12", "did you mean model.sprocket.tooth_count?"),
    ("control.mpc..max_iter=3", "did you mean control.mpc.max_iter?"),
    ("scenario.load_pulses.x.hitch_N=1", "'x' is not an index; [load_pulses] is an array "
     "(no entries)"),
])
def test_a_mistyped_set_key_is_answered_in_one_line_with_the_nearest_key(item, nearest,
                                                                         capsys) -> None:
    """What a newcomer types wrong in `trackmj run W1 --set ...` (a character, a dot left
    out or doubled, an index) is refused before any work, exit 2, naming the valid key."""
    assert main(["run", "W1", "--duration", "2", "--set", item]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and nearest in err and "Traceback" not in err
