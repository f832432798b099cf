"""Machines and the general layout generator: machine files and the registry, any plausible
single-side layout generates, closes and drives, infeasible ones are refused naming the key
and what would fit, generated models are cached by content hash."""

from __future__ import annotations

import math
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from trackmj.cli.main import main
from trackmj.io import cache_dir
from trackmj.machines.assembly import load_machine, mechanics, model_mjcf, resolve, shipped
from trackmj.machines.track_plant import load_plant
from trackmj.sim.setup import prepare
from trackmj.track.mechanics import load_model_params, models_dir
from trackmj.track.mjcf.cache import cached_mjcf
from trackmj.track.mjcf.generate import generate_mjcf
from trackmj.track.mjcf.geometry import derive_geometry
from trackmj.track.mjcf.layout import (
    chords_fitting,
    compute_layout,
    slide_axis,
    tooth_pin_distance_m,
)
from trackmj.track.plant import PassiveTensioner, TrackPlant
from trackmj.validator import ParameterError

FRONT = {"sprocket.x_m": 1.10, "idler.x_m": -1.35, "chassis.hitch_x_m": 1.30}
"""LF1352 mirrored: sprocket at the front, idler and tensioner at the rear."""


# ----------------------------------------------------------------------------- machine files

def test_shipped_machines_listed_one_line_each(capsys) -> None:
    assert main(["machines"]) == 0
    lines = capsys.readouterr().out.splitlines()
    machines = shipped()
    assert "lf1352" in machines
    for name, m in machines.items():
        assert sum(line.startswith(name + " ") for line in lines) == 1
        assert m.mechanics.is_file() and m.hydraulics.is_file() and m.control.is_file()


def _machine_file(path: Path, name: str, mechanics: Path, hydraulics: Path,
                  control: Path) -> Path:
    """A machine file at ``path`` naming machine ``name`` and its three files."""
    path.write_text(f'[machine]\nname = "{name}"\ndescription = "a test machine"\n'
                    f'mechanics = "{mechanics}"\nhydraulics = "{hydraulics}"\n'
                    f'control = "{control}"\n')
    return path


def test_machine_file_resolves_relative_paths_and_names_a_missing_file(tmp_path) -> None:
    lf = resolve("lf1352")
    path = _machine_file(tmp_path / "mine_machine.toml", "mine", lf.mechanics, lf.hydraulics,
                         lf.control)
    mine = resolve(str(path))
    assert mine.name == "mine" and mine.mechanics == lf.mechanics
    assert mine.idler is None and mine.reference_mjcf is None
    path.write_text(path.read_text().replace(str(lf.control), "nowhere.toml"))
    with pytest.raises(ParameterError, match=r"mine_machine\.toml \[machine\]\.control = "
                                             r"'nowhere\.toml': no such file"):
        load_machine(path)
    with pytest.raises(ParameterError, match=r"lf1352\.toml is a model parameter file, not a "
                                             r"machine file: give it as --model"):
        resolve(str(lf.mechanics))
    with pytest.raises(ParameterError, match=r"machine 'm1': not a shipped machine "
                                             r"\([a-z0-9, ]*lf1352"):
        resolve("m1")


def test_reference_mjcf_for_own_parameters_generated_and_cached_otherwise() -> None:
    lf = resolve("lf1352")
    own = load_model_params(lf.mechanics)
    # the committed scene joined with its machine part: the model MuJoCo compiles from the
    # scene file itself (its include resolved by MuJoCo)
    joined = mujoco.MjModel.from_xml_string(model_mjcf(own, lf))
    from_file = mujoco.MjModel.from_xml_path(str(lf.reference_mjcf))
    assert _model_bytes(joined) == _model_bytes(from_file)
    other = load_model_params(overrides={"track.link_count": 80})
    text = model_mjcf(other, lf)
    cached = list(cache_dir().glob("lf1352-*.xml"))
    assert any(path.read_text() == text for path in cached)
    cached_mjcf.cache_clear()        # a new process: read back from the directory
    assert cached_mjcf(other, "lf1352") == text
    assert text.count("<body name=\"link_") == 80


def _copy_lf1352(folder, *, reference: bool = True) -> Path:
    """README's "Your machine" step 1: lf1352's files copied to ``folder`` as mine_*
    (the scene's include renamed with them); the machine file's path."""
    lf = resolve("lf1352")
    for source, target in ((lf.mechanics, "mine.toml"), (lf.hydraulics, "mine_hydraulics.toml"),
                           (lf.control, "mine_control.toml"), (lf.idler, "mine_idler.toml"),
                           (lf.reference_mjcf.with_name("lf1352.xml"), "mine.xml")):
        (folder / target).write_text(source.read_text())
    (folder / "mine_scene.xml").write_text(
        lf.reference_mjcf.read_text().replace('"lf1352.xml"', '"mine.xml"'))
    path = folder / "mine_machine.toml"
    path.write_text('[machine]\nname = "mine"\ndescription = "a copy"\nmechanics = "mine.toml"\n'
                    'hydraulics = "mine_hydraulics.toml"\ncontrol = "mine_control.toml"\n'
                    'idler = "mine_idler.toml"\n'
                    + ('reference_mjcf = "mine_scene.xml"\n' if reference else ""))
    return path


FIVE_WHEELS = (("count = 6", "count = 5"), ("x_m = [-0.75, -0.45, -0.15, 0.15, 0.45, 0.75]",
                                            "x_m = [-0.72, -0.36, 0, 0.36, 0.72]"))


def _edit(path: Path, changes: tuple[tuple[str, str], ...]) -> None:
    text = path.read_text()
    for old, new in changes:
        assert old in text
        text = text.replace(old, new)
    path.write_text(text)


def test_a_copied_machine_uses_its_copied_files_until_its_mechanics_change(tmp_path) -> None:
    """An unchanged copy runs on its copied reference and idler; after an edit of the
    mechanics both are stale: refused before any work, naming the file and the command
    that regenerates it, and `model generate` writes a model of the edited mechanics,
    named after the machine, whose header names its files."""
    path = _copy_lf1352(tmp_path)
    assert load_plant(machine=str(path)).model_path == tmp_path / "mine_scene.xml"
    prepare("W1", machine=str(path))
    _edit(tmp_path / "mine.toml", FIVE_WHEELS)
    mechanics.cache_clear()          # a new process: the edited file read again
    stale = (r"^mine_machine\.toml \[machine\]\.reference_mjcf: mine_scene\.xml is stale, not "
             r"generated from mine\.toml as it is now: regenerate it with `trackmj model "
             rf"generate --machine {re.escape(str(path))}`")
    with pytest.raises(ParameterError, match=stale):
        load_plant(machine=str(path))
    with pytest.raises(ParameterError, match=stale):
        prepare("W1", machine=str(path))
    assert main(["model", "generate", "--machine", str(path)]) == 0
    scene = (tmp_path / "mine_scene.xml").read_text()
    assert "From mine.toml; regenerate with: trackmj model generate --machine " \
           "mine_machine.toml -->" in scene
    plant = load_plant(machine=str(path))
    assert plant.model.names.startswith(b"mine\0")
    assert [plant.model.body(i).name for i in range(plant.model.nbody)].count(
        "road_wheel_6") == 0
    with pytest.raises(ParameterError, match=r"^mine_machine\.toml \[machine\]\.idler: "
                       r"mine_idler\.toml is stale, not identified on mine\.toml as it is now: "
                       r"regenerate it with `python -m trackmj\.machines\.identify "):
        prepare("W1", machine=str(path))


def test_a_machine_file_taking_a_shipped_name_for_other_files_is_refused(tmp_path) -> None:
    c3 = resolve("compact3")
    path = _machine_file(tmp_path / "m_machine.toml", "lf1352", c3.mechanics, c3.hydraulics,
                         resolve("lf1352").control)
    with pytest.raises(ParameterError, match=r"^m_machine\.toml \[machine\]\.name = 'lf1352' "
                                             r"is the shipped machine lf1352_machine\.toml's, "
                                             r"but its files are not that machine's"):
        resolve(str(path))
    assert resolve(str(resolve("lf1352").file)) == resolve("lf1352")


def test_a_layout_stroke_beyond_the_cylinder_is_refused_naming_both_files() -> None:
    """The mechanics' stroke at the layout must fit the hydraulic file's cylinder: refused
    at load by model info, drive (load_plant) and a run (prepare), before any generation,
    naming the --set option that gave it."""
    message = (r"^--set model\.idler\.stroke_at_layout_m = 0\.5 m is beyond the "
               r"cylinder's stroke, compact3_hydraulics\.toml \[cylinder\]\.stroke_max_m = "
               r"0\.08 m: allowed \[0, 0\.08\] m")
    with pytest.raises(ParameterError, match=message):
        load_plant(machine="compact3", overrides={"idler.stroke_at_layout_m": 0.5})
    with pytest.raises(ParameterError, match=message):
        prepare("W1", machine="compact3", overrides={"model.idler.stroke_at_layout_m": 0.5})


@pytest.mark.parametrize("machine", sorted(shipped()))
def test_each_shipped_carrier_travels_within_its_cylinder(machine: str, capsys) -> None:
    """The shipped carriers travel exactly the cylinder's stroke about the layout
    (slide_range_m = ±stroke_max_m / 2 about mid-stroke): model info accepts them."""
    assert main(["model", "info", "--machine", machine]) == 0
    assert "error" not in capsys.readouterr().err


def test_a_carrier_travel_beyond_the_cylinder_is_refused_naming_both_files(tmp_path,
                                                                          capsys) -> None:
    """A slide range that carries the idler past the cylinder's end stop (compact3: 0.04 m
    at the layout + 0.06 m = 0.10 m of a 0.08 m stroke) is refused by model info and a run,
    in one line naming the option, both files' keys and the range that fits."""
    message = (r"^trackmj: error: --set model\.idler\.slide_range_m = \[-0\.04, 0\.06\] m "
               r"moves the carrier over the cylinder stroke 0 \.\. 0\.1 m \(about "
               r"compact3\.toml \[idler\]\.stroke_at_layout_m = 0\.04 m\), beyond the "
               r"cylinder's stroke, compact3_hydraulics\.toml \[cylinder\]\.stroke_max_m = "
               r"0\.08 m: allowed slide_range_m within \[-0\.04, 0\.04\] m")
    bad = ["--machine", "compact3", "--set", "model.idler.slide_range_m=[-0.04, 0.06]"]
    for argv in (["model", "info", *bad],
                 ["run", "W1", *bad, "--duration", "2", "--out", str(tmp_path / "r")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert not (tmp_path / "r").exists()


def test_a_missing_include_names_the_file_that_includes_it(tmp_path) -> None:
    path = _copy_lf1352(tmp_path)
    (tmp_path / "mine.xml").unlink()
    with pytest.raises(ParameterError, match=r"mine_scene\.xml: <include file=\"mine\.xml\"/>: "
                                             r"no such file .*mine\.xml$"):
        load_plant(machine=str(path))


def _model_bytes(model: mujoco.MjModel) -> bytes:
    buffer = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


# ----------------------------------------------------------------------------- refusals

def test_infeasible_link_count_names_the_counts_that_close(tmp_path) -> None:
    with pytest.raises(ParameterError) as info:
        load_model_params(overrides={"track.link_count": 60})
    text = str(info.value)
    assert text.startswith("--set model.track.link_count = 60 links × 0.075 m = 4.500 m;")
    lo, hi = (int(v) for v in re.search(r"use (\d+)–(\d+) links", text).groups())
    for n in (lo, hi):     # the counts it proposes close the loop; one more each way does not
        load_model_params(overrides={"track.link_count": n})
    for n in (lo - 1, hi + 1):
        with pytest.raises(ParameterError, match="links or move the idler"):
            load_model_params(overrides={"track.link_count": n})


@pytest.mark.parametrize(("overrides", "message"), [
    ({"road_wheels.x_m": [-0.75, -0.45, -0.15, 0.15, 0.45, 1.6]},
     r"road_wheels\]?\.x_m = .* entry 5 \(1\.6 m\) lies outside the span"),
    ({"road_wheels.x_m": [-0.75, -0.45, -0.15, 0.15, 0.2, 0.75]},
     r"road_wheels\]?\.x_m = .* entries 3 \(0\.15 m\) and 4 \(0\.2 m\) are only 0\.05 m apart: "
     r"neighbours must be at least 2·radius_m \+ 10 mm = 0\.23 m apart$"),
    ({"road_wheels.x_m": [-0.75, -0.45, 0.15, -0.15, 0.45, 0.75]},
     r"road_wheels\]?\.x_m = .* entries 2 \(0\.15 m\) and 3 \(-0\.15 m\) are not in increasing x "
     r"\(rear to front\): sort them rear to front, "
     r"x_m = \[-0\.75, -0\.45, -0\.15, 0\.15, 0\.45, 0\.75\]$"),
    ({"road_wheels.x_m": [-0.75, -0.45, 0.15, 0.05, 0.45, 0.75]},
     r"entries 2 \(0\.15 m\) and 3 \(0\.05 m\) are not in increasing x \(rear to front\): "
     r"list them rear to front, neighbours at least 2·radius_m \+ 10 mm = 0\.23 m apart$"),
    ({"road_wheels.count": 3, "road_wheels.x_m": [-0.75, -0.5, -0.25]},
     r"must straddle the chassis centre of mass"),
    ({"road_wheels.x_m": [-0.95, -0.45, -0.15, 0.15, 0.45, 0.75]},
     r"entry 0 \(-0\.95 m\) touches the sprocket teeth"),
    ({"return_rollers.z_m": 0.30}, r"return_rollers\]?\.z_m = 0\.3 puts the rollers onto"),
    ({"return_rollers.x_m": [-0.6, -0.3, 0.0, 0.3, 0.6]}, r"at most 4"),
    ({"idler.x_m": 0.95}, r"^--set model\.idler\.x_m = 0\.95 puts the idler \(radius 0\.2 m\) into "
                          r"\[road_wheels\]\.x_m\[5\] \(it must keep 10 mm clear of it\): "
                          r"increase x_m by at least 102 mm \(x_m >= 1\.052 m\)$"),
    ({"idler.x_m": -0.95, "sprocket.x_m": 1.35, "return_rollers.x_m": [-0.3, 0.6]},
     r"idler\.x_m = -0\.95 puts the idler .* into \[road_wheels\]\.x_m\[0\] .*: "
     r"decrease x_m by at least 102 mm \(x_m <= -1\.052 m\)"),
    ({"sprocket.z_m": 0.15}, r"sprocket\]?\.z_m = 0\.15 puts the sprocket's lowest pin "
                             r"below the ground line"),
    ({"idler.z_m": 0.05}, r"^--set model\.idler\.z_m = 0\.05 puts the idler \(radius 0\.2 m\) "
                          r"into the ground line .*: raise it by at least 180 mm "
                          r"\(z_m >= 0\.23 m\)$"),
    ({"road_wheels.count": 1, "road_wheels.x_m": [0.0]}, r"count = 1 .*\[2, 10\]"),
    ({"sprocket.tooth_radius_m": 0.03}, r"tooth_radius_m = 0\.03 overlaps a pin running onto "
                                        r"or off the sprocket: .*allowed tooth_radius_m <= "
                                        r"0\.0224 m"),
])
def test_implausible_layouts_are_refused_naming_the_key(overrides, message) -> None:
    with pytest.raises(ParameterError, match=message):
        load_model_params(overrides=overrides)


def test_the_idler_x_m_a_refusal_proposes_clears_the_road_wheel() -> None:
    """The advice "increase x_m by at least 102 mm (x_m >= 1.052 m)" above is enough."""
    assert load_model_params(overrides={"idler.x_m": 1.052}).idler.x_m == 1.052


def test_a_layout_refusal_on_a_file_key_names_the_set_option_that_caused_it() -> None:
    """Only --set moved the sprocket, yet the check that fails names the road wheel the
    file holds: the message says which --set changed the layout."""
    with pytest.raises(ParameterError, match=r"^lf1352\.toml \[road_wheels\]\.x_m = .* "
                       r"touches the sprocket teeth: .* \(with --set model\.sprocket\.x_m\)$"):
        load_model_params(overrides={"sprocket.x_m": -0.8})


def test_a_tooth_that_fits_the_seated_pins_but_not_a_pin_running_on_is_refused(
        tmp_path, capsys) -> None:
    """LF1352's seated pins are 38.62 mm from a tooth centre, a pin on the strand running
    onto or off the sprocket comes to 36.37 mm: a 24 mm tooth on its 14 mm pins fits the
    first (the check before) and not the second (laid, 1.5 mm deep: a penetration at
    generation naming no key). A machine file with it is refused at load, in one line
    naming the file, the keys and the largest tooth radius that fits."""
    path = _copy_lf1352(tmp_path, reference=False)
    _edit(tmp_path / "mine.toml", (("tooth_radius_m = 0.020", "tooth_radius_m = 0.024"),))
    assert main(["model", "info", "--machine", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert ("mine.toml [sprocket].tooth_radius_m = 0.024 overlaps a pin running onto or off "
            "the sprocket: with tooth_radial_offset_m = 0.005 m, 14 teeth and "
            "[track].pitch_m = 0.075 m that pin comes 0.0364 m from a tooth centre, less "
            "than tooth_radius_m + [track].pin_radius_m = 0.0380 m: allowed tooth_radius_m "
            "<= 0.0224 m") in err


@pytest.mark.parametrize(("name", "sprocket_z_m"), [
    ("lf1352", None), ("lf1352", 0.30), ("m113", None), ("compact3", None)])
def test_tooth_pin_distance_is_the_nearest_a_laid_pin_comes(name, sprocket_z_m) -> None:
    """The pins the generator lays come no nearer a tooth centre (compiled model) than
    tooth_pin_distance_m, within 1 mm of it (the layout is one phase of the wrap), and all
    nearer than the pocket between two seated pins, sqrt(r_p² + r_t² − 2 r_p r_t cos(π/N))."""
    base = mechanics(resolve(name))
    p = (base if sprocket_z_m is None
         else load_model_params(resolve(name).mechanics, overrides={"sprocket.z_m": sprocket_z_m}))
    from trackmj.track.mjcf.builders import build_mjcf

    model = mujoco.MjModel.from_xml_string(build_mjcf(p, compute_layout(p)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    s = p.sprocket
    teeth = data.geom_xpos[[model.geom(f"sprocket_tooth_{j:02d}").id
                            for j in range(s.tooth_count)]][:, [0, 2]]
    pins = data.geom_xpos[[model.geom(f"link_{k:02d}_pin").id
                           for k in range(p.track.link_count)]][:, [0, 2]]
    nearest = np.linalg.norm(pins[:, None, :] - teeth[None, :, :], axis=2).min()
    reach = tooth_pin_distance_m(s.tooth_count, p.track.pitch_m, s.tooth_radial_offset_m)
    rp, rt = p.sprocket_pitch_radius_m, p.sprocket_pitch_radius_m + s.tooth_radial_offset_m
    pocket = math.sqrt(rp * rp + rt * rt - 2.0 * rp * rt * math.cos(math.pi / s.tooth_count))
    assert reach - 1e-6 <= nearest < min(pocket, reach + 1e-3)


def test_tooth_pin_distance_closed_forms() -> None:
    """By hand (tooth_pin_distance_m's docstring): M113, 10 teeth of 154 mm, r_p =
    0.154/(2 sin 18°) = 0.249177 m, r_t = 0.259477 m lies within [r_p cos 18°, r_p/cos 18°]
    = [0.23698, 0.26200] m, so the pin swinging in about its seated neighbour comes to
    p − c, c the pocket; LF1352 (r_t = 0.173523 m > r_p/cos(π/14) = 0.172857 m): below the
    link tangent at the seated pin, sqrt(c² − p²·e/r_p), by less than 0.1 mm; a tooth
    inside the chord (e = −0.02 m on LF1352's sprocket): the pocket."""
    rp = 0.154 / (2.0 * math.sin(math.pi / 10))
    c = math.sqrt(rp ** 2 + (rp + 0.0103) ** 2 - 2 * rp * (rp + 0.0103) * math.cos(math.pi / 10))
    assert tooth_pin_distance_m(10, 0.154, 0.0103) == pytest.approx(0.154 - c, abs=1e-7)
    rp = 0.075 / (2.0 * math.sin(math.pi / 14))
    c = math.sqrt(rp ** 2 + (rp + 0.005) ** 2 - 2 * rp * (rp + 0.005) * math.cos(math.pi / 14))
    tangent = math.sqrt(c * c - 0.075 ** 2 * 0.005 / rp)
    assert tangent - 1e-4 < tooth_pin_distance_m(14, 0.075, 0.005) < tangent
    c = math.sqrt(rp ** 2 + (rp - 0.02) ** 2 - 2 * rp * (rp - 0.02) * math.cos(math.pi / 14))
    assert tooth_pin_distance_m(14, 0.075, -0.02) == pytest.approx(c, abs=1e-7)


@pytest.mark.parametrize(("geom", "grow_m", "message"), [
    ("sprocket_tooth_03", 0.004, r"penetrates by 1\.51 mm \(limit 1\.0 mm\): link_09_pin into "
     r"sprocket_tooth_03: check \[track\]\.pin_radius_m, \[sprocket\]\.tooth_radius_m, "
     r"\[sprocket\]\.tooth_radial_offset_m$"),
    ("idler_wheel", 0.003, r"penetrates by 3\.00 mm \(limit 1\.0 mm\): idler_wheel into "
     r"link_\d+_rail: check \[idler\]\.radius_m, \[idler\]\.x_m, \[idler\]\.z_m, "
     r"\[track\]\.rail_radius_m$"),
])
def test_an_initial_penetration_names_both_geoms_and_their_keys(geom, grow_m, message) -> None:
    """A geom grown past what the load checks admit (compact3's model, one tooth by 4 mm:
    1.51 mm into the nearest pin; the idler by 3 mm) is refused before settling, naming the
    mechanics file, the two geoms and the keys that size and place them."""
    import xml.etree.ElementTree as ET

    from trackmj.track.mjcf.builders import build_mjcf
    from trackmj.track.mjcf.generate import settle

    p = mechanics(resolve("compact3"))
    root = ET.fromstring(build_mjcf(p, compute_layout(p)))
    element = root.find(f".//geom[@name='{geom}']")
    assert element is not None
    size = float(element.get("size") or p.sprocket.tooth_radius_m)   # a tooth: its class's
    element.set("size", repr(size + grow_m))
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    with pytest.raises(ParameterError, match=r"^compact3\.toml: initial layout " + message):
        settle(model, p, 0.0)


def test_the_generator_names_the_mechanics_file_it_refuses(tmp_path) -> None:
    """The generator's own checks name the file (and a --set option) as the loader's do: a
    pin torsion spring past the explicit limit in a newcomer's copy, and a rail contact too
    stiff for the 1 ms step, which diverges while settling (MuJoCo's BADQACC)."""
    text = (models_dir() / "compact3.toml").read_text()
    mine = tmp_path / "mine.toml"
    mine.write_text(re.sub(r"(?m)^torsional_stiffness_N_m_rad = 0\.0",
                           "torsional_stiffness_N_m_rad = 1e5", text, count=1))
    with pytest.raises(ParameterError, match=r"^mine\.toml \[pins\]\.torsional_stiffness_N_m_rad "
                       r"= 100000\.0 exceeds the explicit limit \d+ N·m/rad"):
        generate_mjcf(load_model_params(mine))
    stiff = load_model_params(models_dir() / "compact3.toml",
                              overrides={"contacts.rail_stiffness_N_m": 1e9})
    with pytest.raises(ParameterError, match=r"^compact3\.toml with --set model\.contacts\."
                       r"rail_stiffness_N_m: the model goes unstable while settling its home "
                       r"keyframe \(MuJoCo: BADQACC at link_\d+\): .*\[contacts\]"):
        generate_mjcf(stiff)


def test_cli_refuses_a_layout_with_one_line_and_exit_2(capsys) -> None:
    assert main(["drive", "--duration", "0.1", "--set", "model.track.link_count=40"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "use 74–94 links or move the idler" in err


# ----------------------------------------------------------------------------- layouts

def test_76_links_with_five_road_wheels_generate_and_close() -> None:
    p = load_model_params(overrides={"track.link_count": 76, "road_wheels.count": 5,
                                     "road_wheels.x_m": [-0.72, -0.36, 0.0, 0.36, 0.72]})
    layout = compute_layout(p)
    g = derive_geometry(p, layout)
    assert layout.pins.shape == (76, 2)
    assert g.closure_m < 1e-7
    assert sum(g.wraps_rad.values()) == pytest.approx(2.0 * math.pi, abs=1e-9)
    # the pin polygon is inscribed in the path round the vertex circles: 76 chords of
    # 75 mm, each shorter than its arc where it wraps
    assert 76 * 0.075 < g.path_m < 76 * 0.075 + 0.02
    assert layout.idler_x_m < p.idler.x_m          # a shorter loop pulls the idler in


@pytest.fixture(scope="module")
def front_drive():
    from trackmj.sim.drive import drive

    return drive(1.5, 3.0, overrides=FRONT)


def test_front_sprocket_slide_points_rearward() -> None:
    p = load_model_params(overrides=FRONT)
    assert slide_axis(p) == (-1.0, 0.0)
    plant = load_plant(overrides=FRONT)
    m = plant.model
    np.testing.assert_array_equal(m.jnt_axis[m.joint("idler_slide").id], (-1.0, 0.0, 0.0))
    # standing at home (settled under the passive spring) the tensioner pushes the idler
    # out, and both strands at the frictionless idler carry F / (d_in − d_out)·u (5 %: the
    # mean over the sagging 2.5 m span, the layout's strand directions, 3 s of settling)
    force = PassiveTensioner.from_params(p).force_law(0.0, plant.stroke_m, 0.0).force_N
    g = derive_geometry(p, compute_layout(p))
    upper = plant.pin_tensions_N()[plant.upper_strand_pins()].mean()
    assert force > 0.5 * p.tensioner.preload_N
    assert upper == pytest.approx(force / g.idler_factor, rel=0.05)


def test_front_sprocket_layout_drives_with_the_idler_pushed_out(front_drive) -> None:
    m, s = front_drive.metrics, front_drive.metrics["steady"]
    preload = 13e3
    assert 0.6 * preload < s["idler_force_mean_N"] < 1.2 * preload
    assert s["idler_force_min_N"] > 0.0
    assert np.isfinite(s["upper_strand_tension_mean_N"])
    assert np.isfinite(s["lower_strand_tension_mean_N"])
    # a front sprocket turning forward pulls the upper strand: it is the tight side
    assert s["upper_strand_tension_mean_N"] > s["lower_strand_tension_mean_N"]
    assert m["derailment_checks_failed"] == 0 and m["mujoco_warnings"] == 0
    assert m["max_pin_gap_m"] < 0.5e-3
    energy = m["track_energy"]
    assert abs(energy["residual_J"]) < 1e-6 * energy["drive_work_J"]


# ----------------------------------------------------------------------------- property

@st.composite
def layouts(draw) -> dict:
    """Overrides of lf1352.toml making a plausible single-side layout; the link count is
    the one that closes the loop with the idler at its x_m (rounded)."""
    pitch = draw(st.floats(0.05, 0.16))
    teeth = draw(st.integers(9, 16))
    count = draw(st.integers(2, 7))
    wheel_r = draw(st.floats(0.08, 0.15))
    spacing = 2.0 * wheel_r + draw(st.floats(0.03, 0.25))
    xs = [round((k - (count - 1) / 2) * spacing, 4) for k in range(count)]
    r_pitch = pitch / (2.0 * math.sin(math.pi / teeth))
    idler_r = draw(st.floats(0.12, 0.30))
    end = xs[-1] + wheel_r
    s_x = -(end + r_pitch + 0.06 + draw(st.floats(0.0, 0.2)))
    i_x = end + idler_r + 0.08 + draw(st.floats(0.0, 0.2))
    top = max(0.014 + r_pitch, idler_r + 0.05) + draw(st.floats(0.05, 0.2))
    s_z, i_z = top, top - draw(st.floats(0.0, 0.05))
    rollers = sorted(draw(st.lists(st.floats(-0.4, 0.4), max_size=2, unique=True)))
    rollers = [round(x * (xs[-1] - xs[0]) / 0.8, 3) for x in rollers]
    if len(rollers) == 2 and rollers[1] - rollers[0] < 0.2:
        rollers = rollers[:1]
    front = draw(st.booleans())
    if front:
        s_x, i_x = -s_x, -i_x
    scale = pitch / 0.075             # link, pin and tooth sizes follow the pitch
    o = {"track.pitch_m": pitch, "track.link_mass_kg": 3.5 * scale,
         "track.pin_radius_m": 0.014 * scale, "sprocket.tooth_radius_m": 0.02 * scale,
         "sprocket.tooth_radial_offset_m": 0.005 * scale,
         "sprocket.tooth_count": teeth, "sprocket.x_m": s_x, "sprocket.z_m": s_z,
         "idler.x_m": i_x, "idler.z_m": i_z, "idler.radius_m": idler_r,
         "idler.slide_angle_rad": draw(st.floats(-0.3, 0.3)),
         "road_wheels.count": count, "road_wheels.x_m": xs, "road_wheels.radius_m": wheel_r,
         "return_rollers.x_m": rollers, "return_rollers.z_m": top + 0.05,
         "return_rollers.radius_m": 0.05, "chassis.hitch_x_m": s_x}
    return o


def _with_closing_count(o: dict) -> dict:
    """``o`` with a link count that closes the loop: the middle of the range the refusal
    of 100 links names (or 100 if that closes)."""
    try:
        p = load_model_params(overrides=o | {"track.link_count": 100})
    except ParameterError as exc:
        found = re.search(r"use (\d+)(?:–(\d+))? links", str(exc))
        assume(found is not None)
        lo, hi = int(found.group(1)), int(found.group(2) or found.group(1))
        assume(20 <= lo and hi <= 200)
        return o | {"track.link_count": (lo + hi) // 2}
    assert chords_fitting(p, p.idler.x_m) > 0.0
    return o | {"track.link_count": 100}


@pytest.mark.slow
@settings(max_examples=4, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(layouts())
def test_random_plausible_layouts_generate_close_and_drive(o) -> None:
    o = _with_closing_count(o)
    assert 20 <= o["track.link_count"] <= 200
    p = load_model_params(overrides=o)
    layout = compute_layout(p)
    assert derive_geometry(p, layout).closure_m < 1e-4
    plant = TrackPlant(mujoco.MjModel.from_xml_string(generate_mjcf(p)), p)
    assert plant.closure_error_m < 1e-4
    plant.run(PassiveTensioner.from_params(p), 2.0, track_speed=lambda t: min(t, 1.0))
    assert plant.warning_count == 0
    assert np.isfinite(plant.data.qpos).all()
    assert plant.closure_error_m < 0.5e-3
    assert plant.idler_force_N > 0.0
    assert not plant.derailment().any


@pytest.mark.slow
@settings(max_examples=25, deadline=None, derandomize=True)
@given(layouts(), st.sampled_from(["short", "long", "outside", "overlap", "low"]))
def test_random_infeasible_layouts_are_refused_with_a_message(o, how) -> None:
    o = _with_closing_count(o)
    n, xs = o["track.link_count"], list(o["road_wheels.x_m"])
    bad = {"short": {"track.link_count": max(20, int(n * 0.7))},
           "long": {"track.link_count": min(200, int(n * 1.4) + 2)},
           "outside": {"road_wheels.x_m": [*xs[:-1], 3.0 * abs(o["idler.x_m"])]},
           "overlap": {"road_wheels.x_m": [*xs[:-1], xs[-2] + 0.01]},
           "low": {"sprocket.z_m": 0.01}}[how]
    key = {"short": "link_count", "long": "link_count", "outside": "road_wheels.x_m",
           "overlap": "road_wheels.x_m", "low": "sprocket.z_m"}[how]
    with pytest.raises(ParameterError, match=re.escape(key)):
        load_model_params(overrides=o | bad)


@pytest.mark.slow
def test_run_on_a_machine_file_of_another_layout(tmp_path) -> None:
    """A user's machine (the mirrored, front-sprocket LF1352 as mechanics, the LF1352's
    hydraulics and control files as stand-ins) runs W2 closed loop from its machine file:
    the model generated and cached (and given the road's heightfield), the idler
    identified on it."""
    import json

    lf = resolve("lf1352")
    text = lf.mechanics.read_text()
    for old, new in (("x_m = -1.10 ", "x_m = 1.10 "), ("x_m = 1.35 ", "x_m = -1.35 "),
                     ("hitch_x_m = -1.30", "hitch_x_m = 1.30")):
        assert old in text
        text = text.replace(old, new, 1)
    (tmp_path / "front.toml").write_text(text)
    (tmp_path / "front_machine.toml").write_text(
        f'[machine]\nname = "front"\ndescription = "LF1352 mirrored"\nmechanics = '
        f'"front.toml"\nhydraulics = "{lf.hydraulics}"\ncontrol = "{lf.control}"\n')
    out = tmp_path / "run"
    assert main(["run", "W2", "--duration", "2", "--machine",
                 str(tmp_path / "front_machine.toml"), "--out", str(out)]) == 0
    doc = json.loads((out / "metrics.json").read_text())
    m = doc["metrics"]
    assert doc["run"]["files"]["machine"] == "front"
    assert m["mujoco_warnings"] == 0
    # W2 holds 15 kN on a random road: the tensioner pushes the rear idler out as commanded
    means = m["acceptance"]      # lowest and highest 0.5 s mean after the start-up
    assert 0.9 * 15e3 < means["mean_min_N"] <= means["mean_max_N"] < 1.1 * 15e3
    assert list(cache_dir().glob("front-*-idler.json"))


def test_link_and_pin_names_past_100_links() -> None:
    """123 links of 50 mm (pins and teeth scaled with the pitch): the plant finds every
    link, pin and connect by name on the generated layout (no settling needed)."""
    from trackmj.track.mjcf.builders import build_mjcf

    p = load_model_params(overrides={"track.pitch_m": 0.05, "track.link_count": 123,
                                     "track.link_mass_kg": 2.3, "track.pin_radius_m": 0.009,
                                     "sprocket.tooth_radius_m": 0.013,
                                     "sprocket.tooth_count": 21})
    plant = TrackPlant(mujoco.MjModel.from_xml_string(build_mjcf(p, compute_layout(p))), p)
    assert plant.link_count == 123 and plant.model.neq == 31   # chains: 30 of 4, 1 of 3
    assert plant.model.body("link_122").id > plant.model.body("link_99").id
    assert plant.closure_error_m < 1e-6


@pytest.mark.parametrize("command", [["run", "W1"], ["compare", "W1"], ["report"],
                                     ["sweep", "spec.toml"], ["drive"], ["model", "info"],
                                     ["model", "generate"]])
def test_every_command_takes_a_machine(command) -> None:
    from trackmj.cli.parser import build_parser

    args = build_parser().parse_args([*command, "--machine", "my_machine.toml"])
    assert args.machine == "my_machine.toml"
