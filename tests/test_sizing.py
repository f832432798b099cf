"""Sizing rules (trackmj/machines/sizing.py, docs/sizing.md): hand checks on LF1352, the shipped
machines' hydraulic files come from them, and the controller values follow each machine."""

from __future__ import annotations

import dataclasses
import math
import re

import pytest

from trackmj.cli.main import main
from trackmj.control.model import ReducedModel
from trackmj.control.params import BAND_REL, load_config
from trackmj.hydraulics import load_hydraulic_params
from trackmj.hydraulics.components import series_area
from trackmj.machines import assembly as machines
from trackmj.machines import sizing
from trackmj.machines.identify import IdentificationError
from trackmj.machines.idler import load_idler
from trackmj.sim import setup
from trackmj.sim.control_plant import nominal_plant_params
from trackmj.sim.setup import machine_weights, prepare

SUPPLY_PA, TANK_PA, VALVE_DROP_PA, HOLD_S = 12e6, 0.2e6, 1e6, 0.030


def test_lf1352_cylinders_by_hand() -> None:
    """F_max 20 kN on two cylinders at 12 MPa less 1 MPa, rods at 0.2 MPa over phi = 1.6:
    A_h >= 20e3 / (2 (11e6 - 0.2e6 / 1.6)) = 9.195e-4 m^2. ISO 3320: 32 mm gives 8.04e-4
    (too small), 40 mm 1.2566e-3; rod 40 sqrt(1 - 1/1.6) = 24.5 -> 25 mm."""
    cyl = sizing.size_cylinders(20e3, SUPPLY_PA, TANK_PA, VALVE_DROP_PA)
    assert (cyl.bore_m, cyl.rod_m) == (0.040, 0.025)
    assert cyl.area_head_m2 == pytest.approx(1.2566e-3, rel=1e-4)
    assert cyl.area_rod_m2 == pytest.approx(7.658e-4, rel=1e-4)
    assert 20e3 / (2 * (11e6 - 0.2e6 / 1.6)) == pytest.approx(9.195e-4, rel=1e-3)
    assert math.pi * 0.032 ** 2 / 4 < 9.195e-4 < cyl.area_head_m2


def test_head_path_area_inverts_the_reduced_models_tension_rate() -> None:
    """The area asked for a rate gives that rate in control/model.py's independent
    quasi-static gain (LF1352 plant at 15 kN, 12 MPa), and by hand: with 8e-8 m^2 the head
    flow Cq A sqrt(2 dp / rho) at dp = 12 - 6.09 MPa is 6.10e-6 m^3/s."""
    plant = nominal_plant_params()
    head = (15e3 + plant.area_rod_m2 * TANK_PA) / plant.area_head_m2
    assert head == pytest.approx(6.09e6, rel=1e-3)
    volume = plant.dead_volume_head_m3 + plant.area_head_m2 * 0.5 * plant.stroke_m
    area = sizing.head_path_area_m2(
        3000.0, force_N=15e3, area_head_m2=plant.area_head_m2, area_rod_m2=plant.area_rod_m2,
        volume_head_m3=volume, idler_stiffness_N_m=plant.stiffness_N_m, supply_Pa=SUPPLY_PA,
        tank_Pa=TANK_PA, bulk_modulus_Pa=plant.bulk_modulus_Pa,
        density_kg_m3=plant.density_kg_m3, discharge_coefficient=plant.discharge_coefficient,
        critical_pressure_Pa=plant.critical_pressure_Pa)
    rate = ReducedModel(plant.replace(valve_area_head_m2=area)).tension_rate_gain(15e3)
    assert rate == pytest.approx(3000.0, rel=1e-9)
    flow = 0.65 * 8e-8 * math.sqrt(2 * (12e6 - head) / 860.0)
    assert flow == pytest.approx(6.10e-6, rel=2e-3)
    restrictor = sizing.restrictor_for(area / 2, 2e-5)
    assert series_area(2e-5, restrictor) == pytest.approx(area / 2, rel=1e-12)


@pytest.mark.parametrize("name", machines.names())
def test_shipped_hydraulics_are_the_sizing_rules(name: str) -> None:
    """Each machine's cylinders are size_cylinders(4/3 F_nom) and its head restrictors give
    PULSE_REL of F_nom per 30 ms pulse on its identified idler (2-digit rounding: 2 %;
    LF1352's hand-sized 4.0e-8 m^2 is within 1 % of the rule's 4.04e-8)."""
    machine = machines.resolve(name)
    params = machines.mechanics(machine)
    hyd = load_hydraulic_params(machine.hydraulics)
    nominal = params.nominal_tension_N
    cyl = sizing.size_cylinders(nominal * BAND_REL[1], hyd.supply.setpoint_Pa,
                                hyd.tank_pressure_Pa, VALVE_DROP_PA)
    assert hyd.cylinder.area_head_m2 == pytest.approx(cyl.area_head_m2, rel=1e-4)
    assert hyd.cylinder.area_rod_m2 == pytest.approx(cyl.area_rod_m2, rel=1e-3)
    idler = load_idler(machine.idler)
    volume = 2.0 * (hyd.cylinder.dead_volume_head_m3
                    + cyl.area_head_m2 * params.idler.stroke_at_layout_m)
    area = sizing.head_path_area_m2(
        sizing.PULSE_REL * nominal / HOLD_S, force_N=nominal,
        area_head_m2=2 * cyl.area_head_m2, area_rod_m2=2 * cyl.area_rod_m2,
        volume_head_m3=volume, idler_stiffness_N_m=idler.stiffness_N_m,
        supply_Pa=hyd.supply.setpoint_Pa, tank_Pa=hyd.tank_pressure_Pa,
        bulk_modulus_Pa=hyd.fluid.bulk_modulus_Pa, density_kg_m3=hyd.fluid.density_kg_m3,
        discharge_coefficient=hyd.orifice.discharge_coefficient,
        critical_pressure_Pa=hyd.orifice.critical_pressure_Pa)
    branch = sizing.restrictor_for(area / 2, hyd.switching_valves.open_area_m2)
    assert hyd.metering.head_branch_area_m2 == pytest.approx(branch, rel=0.02)
    assert hyd.metering.rod_feed_area_m2 / hyd.metering.head_branch_area_m2 == \
        pytest.approx(5.5 / 4.0, rel=1e-2)


@pytest.mark.parametrize("name", machines.names())
def test_controller_values_follow_the_machines_nominal_tension(name: str) -> None:
    """Band [2/3, 4/3], governor margin 1/30, PID dead band 1 % and integration band 4 % of
    the nominal tension: on LF1352 (15 kN) exactly the study's 10, 20, 0.5, 0.15, 0.6 kN."""
    machine = machines.resolve(name)
    nominal = machines.mechanics(machine).nominal_tension_N
    cfg = load_config(machine.control, nominal_tension_N=nominal)
    c, pid = cfg.controller, cfg.pid
    assert (c.force_min_N, c.force_max_N) == pytest.approx((2 * nominal / 3, 4 * nominal / 3))
    assert (c.reference_margin_N, pid.error_dead_band_N, pid.integration_band_N) == \
        pytest.approx((nominal / 30, 0.01 * nominal, 0.04 * nominal))
    if name == "lf1352":
        assert (c.force_min_N, c.force_max_N, c.reference_margin_N, pid.error_dead_band_N,
                pid.integration_band_N) == (10e3, 20e3, 500.0, 150.0, 600.0)


def test_mpc_input_weights_keep_the_cost_per_tension_rate() -> None:
    """w_u / g^2 is the tuned machine's on every machine (g: the tension-rate gain at the
    nominal tension and set-point); on LF1352 itself the weights are the file's."""
    def gain_and_weights(name: str) -> tuple[float, float, float]:
        machine = machines.resolve(name)
        params = machines.mechanics(machine)
        hyd = load_hydraulic_params(machine.hydraulics)
        cfg = load_config(machine.control, nominal_tension_N=params.nominal_tension_N)
        plant = nominal_plant_params(hyd, load_idler(machine.idler), cfg,
                                     force_N=params.nominal_tension_N,
                                     supply_pressure_Pa=hyd.supply.setpoint_Pa)
        g = ReducedModel(plant).tension_rate_gain(params.nominal_tension_N)
        mpc = machine_weights(cfg, machine).mpc
        return g, mpc.weight_input, mpc.weight_input_rate

    g0, wu0, wr0 = gain_and_weights("lf1352")
    assert (wu0, wr0) == (0.6, 2.0)
    for name in machines.names():
        g, wu, wr = gain_and_weights(name)
        assert wu / g ** 2 == pytest.approx(wu0 / g0 ** 2, rel=1e-12)
        assert wr / g ** 2 == pytest.approx(wr0 / g0 ** 2, rel=1e-12)
    cfg = load_config(nominal_tension_N=15e3)
    assert machine_weights(cfg, machines.resolve("lf1352")) is cfg


def test_mpc_weights_follow_the_machine_files_not_its_name() -> None:
    """compact3's files under lf1352's name get compact3's weights, not lf1352's tuned
    ones; a machine file that takes a shipped name for other files is refused."""
    compact3 = machines.resolve("compact3")
    posing = dataclasses.replace(compact3, name="lf1352")
    cfg = load_config(nominal_tension_N=machines.mechanics(compact3).nominal_tension_N)
    assert machine_weights(cfg, posing).mpc == machine_weights(cfg, compact3).mpc
    assert machine_weights(cfg, posing).mpc.weight_input != cfg.mpc.weight_input


def test_mpc_weights_are_the_machines_not_the_runs_overrides() -> None:
    """A run's --set hydraulics.* changes the plant, not the controller's tuning: a lower
    supply set-point keeps lf1352's tuned weights (a sensitivity study, W5's variants or a
    calibration's truth run, puts the tuned controller against a changed plant)."""
    own = prepare("W1", machine="lf1352").control.mpc
    low = prepare("W1", machine="lf1352",
                  overrides={"hydraulics.supply.setpoint_Pa": 10e6}).control.mpc
    assert (own.weight_input, own.weight_input_rate) == (0.6, 2.0)
    assert (low.weight_input, low.weight_input_rate) == (0.6, 2.0)


def test_the_idler_identified_for_a_run_is_the_run_model(monkeypatch) -> None:
    """--set model.* reaches the identification of the run's reduced plant, and a refused
    identification names the machine file and the mechanics file it changed."""
    def refuse(*args, **kwargs):
        raise IdentificationError("the idler's stroke response over 1-50 Hz is no "
                                  "mass-spring-damper")

    monkeypatch.setattr(setup, "identify_idler", refuse)
    run = prepare("W1", machine="compact3", overrides={"model.tensioner.preload_N": 12345.0})
    with pytest.raises(IdentificationError, match=r"^compact3_machine\.toml: the idler "
                       r"identified on compact3\.toml with this run's changes to it "
                       r"\(--set model\.\*, --model\): the idler's "):
        assert run.idler


def test_a_machine_whose_own_idler_is_refused_says_overrides_do_not_help(tmp_path,
                                                                          monkeypatch) -> None:
    """A newcomer's machine whose own mechanics cannot be identified (here: every
    identification refused) run with --set model.* is refused in one line saying that the
    MPC weights take the machine's own files, which the overrides leave as they are, and
    where to write the changes; without overrides the refusal is the identification's."""
    def refuse(*args, **kwargs):
        raise IdentificationError("the idler's settled stroke does not grow with the force")

    monkeypatch.setattr(setup, "identify_idler", refuse)
    monkeypatch.setenv("TRACKMJ_CACHE", str(tmp_path / "cache"))
    path = _m113_at(tmp_path, 7000.0)
    with pytest.raises(IdentificationError, match=r"^big_machine\.toml: the idler identified "
                       r"on big\.toml: the idler's settled stroke does not grow with the "
                       r"force; this run's model changes \(--set model\.\*, --model\) do not "
                       r"reach it: the MPC weights are scaled by the tension-rate gain of the "
                       r"machine's own files, so write the changes into big\.toml, or into a "
                       r"copy that a machine file of its own names$"):
        prepare("W1", machine=path, overrides={"model.tensioner.preload_N": 9000.0})
    with pytest.raises(IdentificationError, match=r"^big_machine\.toml: the idler identified "
                       r"on big\.toml: the idler's settled stroke does not grow with the "
                       r"force$"):
        prepare("W1", machine=path)


def test_a_duration_cutting_an_event_is_refused_before_the_machine_is_identified(
        tmp_path, monkeypatch, capsys) -> None:
    """`run W1 --duration 2` on a newcomer's machine (no idler file) is refused in one line
    before its idler is identified for the MPC weights (7 s of it on an LF1352 copy)."""
    def never(*args, **kwargs):
        raise AssertionError("identified before the duration was checked")

    monkeypatch.setattr(setup, "identify_idler", never)
    monkeypatch.setenv("TRACKMJ_CACHE", str(tmp_path / "cache"))
    path = _m113_at(tmp_path, 20000.0)
    assert main(["run", "W1", "--machine", str(path), "--duration", "2",
                 "--out", str(tmp_path / "run")]) == 2
    assert capsys.readouterr().err.startswith("trackmj: error: --duration 2 s cuts off W1.toml")


# ----------------------------------------------------------------------------- holding force

def _m113_at(folder, nominal_N: float):
    """M113's files copied to ``folder`` with [tensioner].nominal_tension_N = ``nominal_N``
    (its preload stays 20 kN); the machine file's path (no idler or reference: nothing is
    generated before the checks)."""
    m113 = machines.resolve("m113")
    mechanics = m113.mechanics.read_text()
    assert "\npreload_N = 20000.0" in mechanics
    (folder / "big.toml").write_text(mechanics.replace(
        "\npreload_N = 20000.0", f"\nnominal_tension_N = {nominal_N!r}\npreload_N = 20000.0"))
    (folder / "big_hydraulics.toml").write_text(m113.hydraulics.read_text())
    path = folder / "big_machine.toml"
    path.write_text(f'[machine]\nname = "big"\ndescription = "M113 at another tension"\n'
                    f'mechanics = "big.toml"\nhydraulics = "big_hydraulics.toml"\n'
                    f'control = "{m113.control}"\n')
    return path


def test_cylinders_that_cannot_hold_the_band_top_are_named_at_load(tmp_path) -> None:
    """M113's two 40/25 mm cylinders on a 40 kN machine (the probe's long_machine): by hand,
    2·(1.2566e-3 m²·(12 − 1) MPa − 7.658e-4 m²·0.2 MPa) = 27.34 kN against the band's top
    4/3·40 = 53.33 kN; the head area that would hold it with this annulus is
    (53.33/2 kN + 7.658e-4·0.2e6 N)/11 MPa = 2.438e-3 m², the set-point 1 MPa +
    26.82 kN/1.2566e-3 m² = 22.34 MPa (at M113's own 20 kN, a 26.67 kN top, the shipped
    machine loads: below)."""
    held = 2 * (0.0012566 * (12e6 - 1e6) - 0.0007658 * 0.2e6)
    assert held == pytest.approx(27338.88, abs=0.01)
    assert sizing.holding_force_N(0.0012566, 0.0007658, 12e6, 0.2e6) == pytest.approx(held)
    area = (4 / 3 * 40e3 / 2 + 0.0007658 * 0.2e6) / 11e6
    setpoint = 1e6 + (4 / 3 * 40e3 / 2 + 0.0007658 * 0.2e6) / 0.0012566
    assert (round(area, 6), round(setpoint / 1e6, 2)) == (0.002438, 22.34)
    message = (r"^big_hydraulics\.toml \[cylinder\]\.area_head_m2 = 0\.0012566 m², "
               r"area_rod_m2 = 0\.0007658 m²: the 2 cylinders hold 27\.34 kN at "
               r"\[supply\]\.setpoint_Pa = 12 MPa less 1 MPa across the metering \(rods at "
               r"tank, 0\.2 MPa\), below the band's top 53\.33 kN \(4/3 of big\.toml "
               r"\[tensioner\]\.nominal_tension_N = 40 kN\); the run goes on, the band's top out "
               r"of the cylinders' reach: to hold it, area_head_m2 >= 0\.002438 m² \(this "
               r"annulus\) or setpoint_Pa >= 22\.34 MPa")
    big = machines.resolve(str(_m113_at(tmp_path, 40e3)))
    params = machines.mechanics(big)
    line = machines.cylinder_force_shortfall(params, "big.toml",
                                             load_hydraulic_params(big.hydraulics),
                                             "big_hydraulics.toml", BAND_REL[1] * 40e3)
    assert line is not None and re.match(message, line), line


@pytest.mark.parametrize(("overrides", "message"), [
    ({"hydraulics.supply.setpoint_Pa": 9e6},     # 2·(1.2566e-3·8e6 − 7.658e-4·0.2e6)
     r"hold 19\.80 kN at \[supply\]\.setpoint_Pa = 9 MPa .* below the band's top 20\.00 kN "
     r"\(4/3 of lf1352\.toml \[tensioner\]\.nominal_tension_N = 15 kN\)"),
    ({"scenario.limits.force_max_N": 28e3, "control.controller.force_max_N": 28e3},
     r"hold 27\.34 kN at .* below the band's top 28\.00 kN \(the control file's "
     r"\[controller\]\.force_max_N; lf1352\.toml \[tensioner\]\.nominal_tension_N = 15 kN\)"),
])
def test_the_holding_force_is_checked_at_the_runs_set_point_and_band(overrides, message,
                                                                      capsys, tmp_path) -> None:
    """The run's hydraulic set-point (--set included) and the band the control file sets:
    said once on stderr, and the run is prepared (a sizing study runs such cylinders to
    see them fail); not said with a tensioner file, which replaces the cylinders."""
    setup._say_once.cache_clear()
    prepare("W1", machine="lf1352", overrides=overrides)
    prepare("W1", machine="lf1352", overrides=overrides)
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert "the run goes on, the band's top out of the cylinders' reach" in err
    setup._say_once.cache_clear()
    spring = tmp_path / "spring.toml"
    spring.write_text('[passive]\nsource = "tests: a spring-damper"\npreload_N = 13000.0\n'
                      'stiffness_N_m = 2.0e5\ndamping_N_s_m = 2.0e4\nstroke_ref_m = 0.05\n'
                      'travel_m = [-0.005, 0.105]\n')
    prepare("W1", machine="lf1352", overrides=overrides, tensioner=spring)
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("name", machines.names())
def test_shipped_machines_hold_their_band_top_and_run_their_supply_drops(name: str) -> None:
    """Every shipped hydraulic file holds 4/3 of its nominal tension at its set-point less
    1 MPa; W4 and NL1, which drop the set-point to 0.75 x (M113: 9 MPa, 22.3 kN against
    26.7 kN), still load: a scenario's drop is not the machine's supply."""
    machine = machines.resolve(name)
    hyd = load_hydraulic_params(machine.hydraulics)
    top = BAND_REL[1] * machines.mechanics(machine).nominal_tension_N
    assert sizing.holding_force_N(hyd.cylinder.area_head_m2, hyd.cylinder.area_rod_m2,
                                  hyd.supply.setpoint_Pa, hyd.tank_pressure_Pa) >= top
    for scenario in ("W1", "W4", "NL1"):
        prepare(scenario, machine=name)


@pytest.mark.parametrize("name", machines.names())
def test_shipped_metering_follows_the_rule_and_draws_no_warning(name: str, capsys) -> None:
    """The rule's restrictor on each machine's own files is the shipped one to 2 %, and a
    run of it says nothing about the metering."""
    machine = machines.resolve(name)
    params = machines.mechanics(machine)
    hyd = load_hydraulic_params(machine.hydraulics)
    stiffness = load_idler(machine.idler).stiffness_N_m
    rule = machines.metering_rule_m2(params, hyd, stiffness, HOLD_S)
    assert hyd.metering.head_branch_area_m2 == pytest.approx(rule, rel=0.02)
    prepare("W1", machine=name)
    assert "metering" not in capsys.readouterr().err


@pytest.mark.parametrize(("factor", "effect"), [(1.6, "valve chatter"), (0.6, "slower")])
def test_metering_far_from_the_rule_is_warned_in_one_line(factor: float, effect: str,
                                                          capsys) -> None:
    """A head restrictor 1.6 x the rule's (a 20 t newcomer's, whose valves then switched at
    14-19 Hz) or 0.6 x it: the run goes on and says so in one stderr line naming the --set
    option, the value and the rule's value (LF1352: 4.03e-8 m²); 1.4 x stays quiet."""
    area = factor * 4.03e-8
    prepare("W1", overrides={"hydraulics.metering.head_branch_area_m2": area})
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(f"trackmj: --set hydraulics.metering.head_branch_area_m2 = "
                          f"{area:.3g} m² is {factor:.2g} x the metering rule's 4.03e-08 m² "
                          "(docs/sizing.md, Metering: one 30 ms pulse moves 0.75 % of the "
                          "nominal 15 kN;"), err
    assert effect in err
    prepare("W1", overrides={"hydraulics.metering.head_branch_area_m2": 1.4 * 4.03e-8})
    assert capsys.readouterr().err == ""
