"""The controller's reduced plant derives from the hydraulic file and the identified idler."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from trackmj.control.model import ReducedModel, ReducedPlant
from trackmj.hydraulics import HydraulicTensioner, load_hydraulic_params
from trackmj.io import file_sha256
from trackmj.machines.drive_load import drive_load
from trackmj.machines.identify import identify_packaged_idler
from trackmj.machines.idler import (
    EquivalentIdler,
    default_idler_path,
    load_identification,
    load_idler,
    write_idler_file,
)
from trackmj.sim.control_plant import nominal_plant_params, packaged_control, reduced_plant_params
from trackmj.track.mechanics import default_xml_path, load_model_params
from trackmj.validator import ParameterError

REGENERATE = ("models/lf1352_idler.toml differs from a fresh identification by more than CPU "
              "rounding: if you changed models/lf1352.xml or the identification, regenerate it "
              "with `python -m trackmj.machines.identify` and commit it; if you changed "
              "neither, the difference is real on your machine: report it with your CPU")
IDENTIFICATION_RTOL = 1e-6
"""The identification is deterministic on one machine; across CPUs MuJoCo's last bits differ
(AVX-512 paths) and 8 s of contact dynamics and a nonlinear fit carry them to ~1e-9 relative
(seen between an AMD EPYC and an Intel Xeon). A change of the track moves k, M, c by far more
than 1e-6 (a pin stiffness 1 % off moves k by ~0.5 %)."""
MODES_RTOL = 1e-4
"""The modal fit's terms are less well conditioned than k, M and c: between an AMD EPYC and
an Intel Xeon (2026-12-07) a residue moved 5.4e-6 and the damping ratio of the fit's
overdamped 0 Hz term (3383) 5.9e-6 relative, while k, M and c stayed within 1e-6, which
still catch a change of the track."""


@pytest.mark.slow
def test_committed_idler_file_equals_a_fresh_identification() -> None:
    """The committed file is what the committed track gives, within CPU rounding (after a
    change of models/lf1352.xml this fails until the file is regenerated)."""
    assert load_identification().model_sha256 == file_sha256(default_xml_path()), REGENERATE
    stored, fresh = load_idler(), identify_packaged_idler()
    for f in dataclasses.fields(EquivalentIdler):
        if f.name in ("modes", "response"):
            continue
        expected = pytest.approx(getattr(fresh, f.name), rel=IDENTIFICATION_RTOL, abs=1e-12)
        assert getattr(stored, f.name) == expected, (f.name, REGENERATE)
    for a, b in zip(stored.modes, fresh.modes, strict=True):
        assert dataclasses.astuple(a) == pytest.approx(dataclasses.astuple(b),
                                                       rel=MODES_RTOL), REGENERATE


def test_reduced_plant_lumps_both_cylinders_and_puts_paths_in_series() -> None:
    """Hand-derived from models/lf1352_hydraulics.toml: two cylinders of bore 40 / rod 25 mm,
    each head branch a 2e-5 m^2 valve in series with a 4e-8 m^2 restrictor (two in
    parallel), the release feed a 1e-4 m^2 edge with a 5.5e-8 m^2 restrictor, line B
    (5e-5 m^3) in the rod node, seal leakage 5e-15 per cylinder."""
    p = nominal_plant_params()
    assert p.area_head_m2 == pytest.approx(2 * math.pi * 0.02**2, rel=1e-4)
    assert p.area_rod_m2 == pytest.approx(2 * math.pi * (0.02**2 - 0.0125**2), rel=1e-4)
    assert p.valve_area_head_m2 == pytest.approx(2 * 4e-8 / math.sqrt(1 + (4e-8 / 2e-5)**2))
    assert p.valve_area_rod_m2 == pytest.approx(5.5e-8 / math.sqrt(1 + (5.5e-8 / 1e-4)**2))
    assert p.dead_volume_head_m3 == pytest.approx(2 * 1.82e-3)
    assert p.dead_volume_rod_m3 == pytest.approx(2 * 1.5e-4 + 5e-5)
    assert p.leakage_m3_s_Pa == pytest.approx(1e-14)
    idler, own = load_idler(), packaged_control().reduced_model
    assert (p.stiffness_N_m, p.mass_kg, p.damping_N_s_m) == (
        idler.stiffness_N_m, idler.mass_kg, idler.damping_N_s_m)
    assert (p.vent_area_rod_m2, p.opening_smoothing) == (own.vent_area_rod_m2,
                                                         own.opening_smoothing)


def test_nominal_operating_point_is_15_kN_at_mid_stroke_and_12_MPa() -> None:
    p = nominal_plant_params()
    x = ReducedModel(p).equilibrium(15e3)
    assert x[2] == pytest.approx(0.5 * p.stroke_m, abs=1e-9)
    assert p.supply_pressure_Pa == 12e6
    assert ReducedModel(p).force(x) == pytest.approx(15e3)


def _tension_rate(forces: np.ndarray, start: int, low_N: float, high_N: float) -> float:
    """|dF/dt| [N/s] while the change from forces[start] goes from low_N to high_N."""
    change = np.abs(forces - forces[start])
    i1, i2 = int(np.argmax(change >= low_N)), int(np.argmax(change >= high_N))
    return (change[i2] - change[i1]) / ((i2 - i1) * 1e-3)


def _plugin_forces(mode: int, force_N: float, y0: float, idler: EquivalentIdler,
                   steps: int = 1500) -> np.ndarray:
    """The hydraulic plugin on the equivalent idler M·ÿ = F(v) − k(y − y0) − c·ẏ, integrated
    semi-implicitly with the affine force law (as MuJoCo does); mode switched at 0.1 s."""
    hyd = load_hydraulic_params()
    k, m, c = idler.stiffness_N_m, idler.mass_kg, idler.damping_N_s_m
    cyl = hyd.cylinder
    stroke, v, h = y0 + force_N / k, 0.0, 1e-3
    head = (force_N + 2 * cyl.area_rod_m2 * hyd.tank_pressure_Pa) / (2 * cyl.area_head_m2)
    element = HydraulicTensioner(hyd, stroke_m=stroke, head_pressure_Pa=head,
                                 supply_pressure_Pa=12e6)
    element.set_mode(0)
    forces = np.empty(steps)
    for i in range(steps):
        if i == 100:
            element.set_mode(mode)
        law = element.force_law(i * h, stroke, v)
        v = (m * v / h + law.force_N - k * (stroke - y0)) / (m / h - law.damping_N_s_m + c)
        stroke += h * v
        element.complete_step((i + 1) * h, stroke, v)
        forces[i] = law.at(v)
    return forces


@pytest.mark.parametrize(("mode", "force_N"), [(1, 12e3), (-1, 15e3)])
def test_reduced_plant_moves_the_tension_at_the_plugins_rate(mode: int, force_N: float) -> None:
    """On the same idler, the derived reduced plant and the hydraulic plugin change the
    tension at the same rate at full opening, measured from 0.5 to 2.5 kN of change (the
    plugin's solenoid delay and valve lag shift the start, not the rate; measured: 0.7 %
    pressurize, 0.03 % release)."""
    p, idler = nominal_plant_params(), load_idler()
    plugin = _plugin_forces(mode, force_N, p.free_position_m, idler)
    plant = ReducedPlant(p, ReducedModel(p).equilibrium(force_N))
    reduced = np.empty(1500)
    for i in range(1500):
        plant.step(0.0 if i < 100 else float(mode), 12e6)
        reduced[i] = plant.force
    rate_plugin = _tension_rate(plugin, 99, 0.5e3, 2.5e3)
    rate_reduced = _tension_rate(reduced, 99, 0.5e3, 2.5e3)
    print(f"mode {mode:+d}: dF/dt plugin {rate_plugin:.0f} N/s, reduced {rate_reduced:.0f} N/s")
    assert rate_reduced == pytest.approx(rate_plugin, rel=0.02)


def test_idler_file_round_trips_and_is_validated(tmp_path) -> None:
    idler = load_idler()
    path = write_idler_file(idler, tmp_path / "idler.toml", params=load_model_params())
    assert load_idler(path) == idler
    text = path.read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(f"stiffness_N_m = {idler.stiffness_N_m!r}", "stiffness_N_m = -1.0"))
    with pytest.raises(ParameterError, match=r"^bad\.toml \[idler\]\.stiffness_N_m = -1\.0 is "
                       r"outside the allowed range \(0, 1e\+10\] N/m$"):
        load_idler(bad)
    bad.write_text(text.replace('source = "identified', 'sorce = "identified'))
    with pytest.raises(ParameterError, match=r"^bad\.toml \[idler\]: unknown key 'sorce'; did "
                       r"you mean 'source'\?"):
        load_idler(bad)
    assert default_idler_path().name == "lf1352_idler.toml"


def test_derived_plant_follows_the_hydraulic_file() -> None:
    """A changed hydraulic value reaches the reduced model: no copy of it in the control file."""
    hyd = load_hydraulic_params(overrides={"fluid.bulk_modulus_Pa": 1.2e9,
                                           "metering.head_branch_area_m2": 3e-8})
    p = reduced_plant_params(hyd, load_idler(), packaged_control(), supply_pressure_Pa=9e6,
                             free_position_m=0.04, drive=drive_load(load_model_params()))
    assert p.bulk_modulus_Pa == 1.2e9 and p.supply_pressure_Pa == 9e6
    assert p.valve_area_head_m2 == pytest.approx(6e-8, rel=1e-5)
