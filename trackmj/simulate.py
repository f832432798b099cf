"""Closed-loop runs of one operating condition: ``simulate(scenario, architecture=...)``.

Every 1 ms step: valve mode -> tensioner element -> mechanics step -> sensors (1 kHz) ->
estimator; every controller period (10 ms): controller(estimate, reference preview, t) -> u,
mapped to valve modes by the valve logic (dead zone, minimum holding time, sum-up rounding).

Architectures (same controller, weights, horizons, steps and references in all):

* ``tp``: MuJoCo track + hydraulic plugin, strong coupling (affine law, implicit dF/dv).
* ``tp-weak``: the same with the weak coupling (force of the previous step held, no dF/dv).
* ``dp-a``: hydraulics + control on an equivalent idler mass-spring-damper identified from
  the track (:mod:`trackmj.identify`); the track's load is replayed from a ``tp`` run of the
  same condition and seed as the part of the tp tension the equivalent spring does not
  explain, d(t) = F_tp − k(y_tp − y0) − c·ẏ_tp. The coupling is one-way.
* ``dp-b``: MuJoCo track + control; the hydraulics replaced by an ideal force source: the
  valve mode integrates a force command at the hydraulic tension-rate gain, applied through
  a first-order lag (the oil column's time constant) with the cylinders' viscous damping;
  no pressures (sensors see the equivalent head pressure), no supply limit.

The solenoid delay lives in the hydraulic plugin (tp, tp-weak, dp-a); the valve logic then
runs without its own delay so the delay is not counted twice.

W3's load pulses enter physically: a load on the rear hitch (a towed or pushing load along a
chain 30° below the horizontal) while the sprocket servo holds the track speed, so the track
sees sprocket drive/brake torque pulses and a pitch load. Amplitudes are calibrated to the
target hold-mode idler-load changes (:mod:`trackmj.calibration`); dp-a sees them through the
replayed tp track load.

Runs are deterministic per seed: a controller solve that overruns its period is still
applied (in a simulation the plant waits) and counted as ``controller_overruns``; only
solver failures fall back.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
from trackmj.control.model import ReducedModel
from trackmj.control.params import ControlConfig, PlantParams, load_config
from trackmj.control.sensors import Sensors
from trackmj.control.valves import ValveLogic
from trackmj.hydraulics import HydraulicParams, HydraulicTensioner, load_hydraulic_params
from trackmj.identify import EquivalentIdler, identify_idler
from trackmj.machine import machine
from trackmj.metrics import compute_metrics
from trackmj.plant import TrackPlant
from trackmj.ports import COUPLING_STEP_S, ForceLaw, steps_per_period
from trackmj.results import Result, TimeseriesRecorder, run_metadata
from trackmj.scenarios import Scenario, Variant, load_scenario
from trackmj.sim.config import reduced_plant_params

ARCHITECTURES = ("tp", "tp-weak", "dp-a", "dp-b")
CONTROLLERS = ("nmpc", "lmpc", "pid")
ESTIMATORS = ("ekf", "ukf")
SETTLE_S = 1.0
"""Standing settle under the initial reference force before t = 0 [s]."""
FRAME_EVERY_STEPS = 20
"""Rerun scene frames every 20 ms of simulated time."""


# --------------------------------------------------------------------------- elements

class _SettleForce:
    """Constant force with strong implicit damping: brings the track to rest at a load."""

    def __init__(self, force_N: float) -> None:
        self.force_N = force_N

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(self.force_N, -2e4)

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Stateless."""


class IdealForceSource:
    """dp-b tensioner: ideal force source replacing the hydraulics.

    State: commanded force F_c [N] and lagged force F_l [N]. Each step
    F_c += mode·rate_N_s·h, F_l += (F_c − F_l)·h/(τ + h) (implicit lag), and the law is
    F(v) = F_l − c·v with c the cylinders' viscous damping [N·s/m]. Equivalent pressures for
    the sensors: p_head = (F_l + A_r·p_t)/A_h, p_rod = p_t (A the lumped areas).
    """

    def __init__(self, force_N: float, rate_N_s: float, lag_s: float, damping_N_s_m: float,
                 area_head_m2: float, area_rod_m2: float, tank_Pa: float) -> None:
        self.command_N = self.force_N = force_N
        self.rate_N_s, self.lag_s, self.damping = rate_N_s, lag_s, damping_N_s_m
        self.area_head, self.area_rod, self.tank = area_head_m2, area_rod_m2, tank_Pa
        self.mode = 0
        self.work_J = 0.0
        self.supply_J = 0.0
        self._law = ForceLaw(force_N, -damping_N_s_m)

    def set_mode(self, mode: int) -> None:
        self.mode = mode

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        h = COUPLING_STEP_S
        self.command_N += self.mode * self.rate_N_s * h
        self.force_N += (self.command_N - self.force_N) * h / (self.lag_s + h)
        self._law = ForceLaw(self.force_N, -self.damping)
        return self._law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        power = self._law.at(velocity_m_s) * velocity_m_s
        self.work_J += power * COUPLING_STEP_S
        self.supply_J += max(power, 0.0) * COUPLING_STEP_S

    @property
    def p_head_Pa(self) -> float:
        return (self.force_N + self.area_rod * self.tank) / self.area_head


class EquivalentIdlerMechanics:
    """dp-a mechanics: M·ÿ = F(v) − k·(y − y0) − c·ẏ − d(t) on the stroke y [m].

    Integrated like MuJoCo (semi-implicit Euler, the affine law and c implicit), so the
    tensioner port behaves the same: v_{k+1} solves M(v_{k+1} − v_k)/h = F0 + Z·v_{k+1}
    − k(y_k − y0) − c·v_{k+1} − d(t_k), then y_{k+1} = y_k + h·v_{k+1}.
    """

    def __init__(self, idler: EquivalentIdler, y0_m: float, stroke_m: float,
                 disturbance_N: Callable[[float], float]) -> None:
        self.idler, self.y0, self.disturbance = idler, y0_m, disturbance_N
        self.stroke_m, self.stroke_velocity_m_s, self.time_s = stroke_m, 0.0, 0.0
        self.idler_force_N = 0.0
        self.acceleration = 0.0

    def step(self, element) -> ForceLaw:
        h, m = COUPLING_STEP_S, self.idler.mass_kg
        k, c = self.idler.stiffness_N_m, self.idler.damping_N_s_m
        law = element.force_law(self.time_s, self.stroke_m, self.stroke_velocity_m_s)
        rhs = (m * self.stroke_velocity_m_s / h + law.force_N
               - k * (self.stroke_m - self.y0) - self.disturbance(self.time_s))
        v1 = rhs / (m / h - law.damping_N_s_m + c)
        self.acceleration = (v1 - self.stroke_velocity_m_s) / h
        self.stroke_velocity_m_s = v1
        self.stroke_m += h * v1
        self.time_s += h
        self.idler_force_N = law.at(v1)
        element.complete_step(self.time_s, self.stroke_m, v1)
        return law


# --------------------------------------------------------------------------- set-up

@functools.cache
def equivalent_idler() -> EquivalentIdler:
    """Equivalent idler dynamics of the packaged track (identified once per process)."""
    return identify_idler(TrackPlant.load)


def hydraulic_params_for(variant: Variant) -> HydraulicParams:
    """Hydraulic parameters with the variant's bulk-modulus and friction scales applied."""
    base = load_hydraulic_params()
    fluid = dataclasses.replace(base.fluid, bulk_modulus_Pa=base.fluid.bulk_modulus_Pa
                                * variant.bulk_modulus_scale)
    cyl = base.cylinder
    cylinder = dataclasses.replace(
        cyl, coulomb_friction_N=cyl.coulomb_friction_N * variant.friction_scale,
        viscous_friction_N_s_m=cyl.viscous_friction_N_s_m * variant.friction_scale)
    return dataclasses.replace(base, fluid=fluid, cylinder=cylinder)


def control_config(hyd: HydraulicParams, idler: EquivalentIdler, y0_m: float,
                   supply_Pa: float) -> tuple[ControlConfig, PlantParams]:
    """The control file with the valve logic's own solenoid delay off (the plugin applies
    it), and the controller's reduced plant derived from the plugin's sizes and the
    identified idler (:func:`trackmj.sim.config.reduced_plant_params`)."""
    cfg = load_config()
    plant = reduced_plant_params(hyd, idler, cfg, supply_pressure_Pa=supply_Pa,
                                 free_position_m=y0_m)
    valves = dataclasses.replace(cfg.valves, solenoid_delay_s=0.0)
    # a simulation must not depend on the wall clock: every finished solve is applied and
    # overruns of the controller period are counted from the solve times instead
    mpc = dataclasses.replace(cfg.mpc, time_budget_s=10.0)
    return dataclasses.replace(cfg, valves=valves, mpc=mpc), plant


def make_controller(name: str, model: ReducedModel, cfg: ControlConfig):
    """Controller object with the shared interface (estimate, preview, t) -> ControlOutput."""
    if name == "nmpc":
        from trackmj.control.nmpc import NonlinearMpc

        return NonlinearMpc(model, cfg.controller, cfg.mpc)
    if name == "lmpc":
        from trackmj.control.lmpc import LinearMpc

        return LinearMpc(model, cfg.controller, cfg.mpc)
    if name == "pid":
        from trackmj.control.pid import PidController

        return PidController(model, cfg.controller, cfg.pid)
    raise ValueError(f"controller = {name!r}: allowed {CONTROLLERS}")


@dataclass
class _Run:
    """Everything one closed-loop run needs (built by :func:`_build`)."""

    scenario: Scenario
    architecture: str
    mechanics: TrackPlant | EquivalentIdlerMechanics
    tensioner: HydraulicTensioner | IdealForceSource
    model: ReducedModel
    cfg: ControlConfig


def _initial_track(scenario: Scenario, seed: int, variant: Variant,
                   force_N: float) -> TrackPlant:
    profile = scenario.terrain_profile(seed)
    plant = TrackPlant.load(terrain=profile)
    if variant.contact_stiffness_scale != 1.0:
        plant.scale_contact_stiffness(variant.contact_stiffness_scale)
    plant.run(_SettleForce(force_N), SETTLE_S)
    plant.time_s = 0.0
    return plant


def build_hold_mode_run(scenario: Scenario, seed: int = 0) -> tuple[TrackPlant,
                                                                     HydraulicTensioner]:
    """The tp plant of ``scenario`` (nominal variant) settled at its initial reference, with
    the hydraulic plugin in hold mode: the open-loop rig of the W3 pulse calibration."""
    run = _build(scenario, "tp", scenario.variant("nominal"), seed, None)
    return run.mechanics, run.tensioner


# --------------------------------------------------------------------------- simulate

def simulate(scenario: Scenario | str | Path, *, architecture: str = "tp",
             controller: str | None = None, estimator: str | None = None, seed: int = 0,
             duration: float | None = None, variant: str = "nominal",
             rrd: str | Path | None = None, progress: bool = False,
             tp_result: Result | None = None) -> Result:
    """Run one condition in closed loop and return its :class:`~trackmj.results.Result`.

    scenario: a Scenario, a name (W1..W5) or a TOML path; architecture: one of
    ARCHITECTURES; controller/estimator default to the scenario's; duration [s] defaults to
    the scenario's; variant: a W5 variant name; rrd: write a Rerun recording there;
    tp_result: for dp-a, the tp run whose track load is replayed (run here if None).
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if architecture not in ARCHITECTURES:
        raise ValueError(f"architecture = {architecture!r}: allowed {ARCHITECTURES}")
    controller = controller or sc.controller
    estimator = estimator or sc.estimator
    if controller not in CONTROLLERS:
        raise ValueError(f"controller = {controller!r}: allowed {CONTROLLERS}")
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator = {estimator!r}: allowed {ESTIMATORS}")
    duration = sc.duration_s if duration is None else float(duration)
    if not 0.0 < duration <= 3600.0:
        raise ValueError(f"duration = {duration!r} s: allowed (0, 3600]")
    var = sc.variant(variant)
    if architecture == "dp-a" and tp_result is None:
        tp_result = simulate(sc, architecture="tp", controller=controller,
                             estimator=estimator, seed=seed, duration=duration,
                             variant=variant)
    run = _build(sc, architecture, var, seed, tp_result)
    return _loop(run, controller, estimator, seed, duration, var, rrd, progress)


def _build(sc: Scenario, architecture: str, var: Variant, seed: int,
           tp_result: Result | None) -> _Run:
    hyd = hydraulic_params_for(var)
    idler = equivalent_idler()
    force0 = float(sc.reference_N(0.0)) * var.pretension_scale
    supply0 = float(sc.supply_pressure_Pa(0.0))
    prescribed = sc.supply.mode == "prescribed"
    two_ah, two_ar = 2.0 * hyd.cylinder.area_head_m2, 2.0 * hyd.cylinder.area_rod_m2
    head0 = (force0 + two_ar * hyd.tank_pressure_Pa) / two_ah
    if architecture == "dp-a":
        cols = tp_result.columns()
        t_tp, stroke_tp = cols["t_s"], cols["stroke_m"]
        y0 = float(stroke_tp[0] - cols["tension_N"][0] / idler.stiffness_N_m)
        load = (cols["tension_N"] - idler.stiffness_N_m * (stroke_tp - y0)
                - idler.damping_N_s_m * cols["stroke_velocity_m_s"])
        # the load acting over step k is the one the tp run had at the end of step k
        mechanics = EquivalentIdlerMechanics(
            idler, y0, float(stroke_tp[0]),
            lambda t: float(np.interp(t + COUPLING_STEP_S, t_tp, load)))
    else:
        mechanics = _initial_track(sc, seed, var, force0)
        y0 = mechanics.stroke_m - force0 / idler.stiffness_N_m
    cfg, plant = control_config(hyd, idler, y0, supply0)
    model = ReducedModel(plant)
    if architecture == "dp-b":
        rate = model.tension_rate_gain(force0)
        volume = 2.0 * hyd.cylinder.dead_volume_head_m3 + two_ah * mechanics.stroke_m
        oil_k = hyd.fluid.bulk_modulus_Pa * two_ah ** 2 / volume
        lag = 2.0 * math.pi / math.sqrt(oil_k / idler.mass_kg) / 4.0
        tensioner = IdealForceSource(force0, rate, lag,
                                     2.0 * hyd.cylinder.viscous_friction_N_s_m,
                                     two_ah, two_ar, hyd.tank_pressure_Pa)
    else:
        tensioner = HydraulicTensioner(
            hyd, stroke_m=mechanics.stroke_m, head_pressure_Pa=head0,
            supply_profile=(lambda t: float(sc.supply_pressure_Pa(t))) if prescribed else None,
            supply_pressure_Pa=None if prescribed else supply0,
            coupling="weak" if architecture == "tp-weak" else "strong")
        tensioner.set_mode(0)
    return _Run(sc, architecture, mechanics, tensioner, model, cfg)


def _loop(run: _Run, controller_name: str, estimator_name: str, seed: int, duration: float,
          var: Variant, rrd: str | Path | None, progress: bool) -> Result:
    sc, cfg, model = run.scenario, run.cfg, run.model
    mech, tens = run.mechanics, run.tensioner
    dt = COUPLING_STEP_S
    ratio = steps_per_period(cfg.controller.period_s, dt)
    steps = round(duration / dt)
    controller = make_controller(controller_name, model, cfg)
    set_params = getattr(controller, "set_parameters", None)
    # the run owns this generator: its noise can be drawn a second ahead (same numbers)
    sensors = Sensors(cfg.sensors, np.random.default_rng([seed, 1]), block=1000)
    x_hat = np.array((0.0, 0.0, mech.stroke_m, 0.0))
    x_hat[:2] = _pressures(tens)
    est_cls = ExtendedKalmanFilter if estimator_name == "ekf" else UnscentedKalmanFilter
    est = est_cls(model, cfg.estimator, dt, x_hat.copy())
    valves = ValveLogic(cfg.valves, dt)
    horizon = getattr(getattr(controller, "mpc", None), "horizon_steps", 15)
    period = cfg.controller.period_s
    track = mech if isinstance(mech, TrackPlant) else None
    extra = {"closure_error_m": "m"}
    rec = TimeseriesRecorder(steps, extra_units=extra)
    t_grid = dt * np.arange(1, steps + 1)
    ref = sc.reference_N(t_grid) * var.pretension_scale
    supply_set = sc.supply_pressure_Pa(t_grid)
    speed = sc.track_speed_m_s(t_grid)
    hitch = sc.hitch_force_N(t_grid - dt) if sc.load_pulses and track is not None else None
    acc_index = track.model.jnt_dofadr[track.model.joint("chassis_z").id] if track else None
    playback = None
    if rrd is not None and track is not None:
        from trackmj.playback import PlaybackRecorder

        playback = PlaybackRecorder(track, rrd)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=steps, unit="ms", desc=f"{sc.name} {run.architecture}",
                   leave=False, mininterval=0.5)
    solve_times: list[float] = []
    solve_ok: list[bool] = []
    u = 0.0
    mode = 0
    # per-step inputs as Python floats and every period's reference preview, computed once
    # (reference_N is elementwise: the same values as one reference_preview per period)
    supply_list, speed_list = supply_set.tolist(), speed.tolist()
    t_ctrl = dt * np.arange(0, steps, ratio)
    previews = (sc.reference_N(t_ctrl[:, None] + period * np.arange(horizon + 1))
                * var.pretension_scale)
    speed_set = math.nan
    wall_start = time.perf_counter()
    try:
        for k in range(steps):
            t = k * dt
            if k % ratio == 0:
                if set_params is not None:
                    set_params(supply_pressure_Pa=supply_list[k])
                out = controller(est.period_mean(), previews[k // ratio], t)
                u = out.u
                solve_times.append(out.solve_time_s)
                solve_ok.append(out.success)
            mode = valves.step(u)
            tens.set_mode(mode)
            if track is not None:
                if speed_list[k] != speed_set:   # the servo keeps its command
                    speed_set = speed_list[k]
                    track.set_track_speed(speed_set)
                if hitch is not None:
                    track.set_hitch_force(float(hitch[0][k]), float(hitch[1][k]))
            mech.step(tens)
            p_head, p_rod, p_supply, q_supply, e_supply, p_work, mech_work = _hydraulic_row(tens)
            stroke, velocity = mech.stroke_m, mech.stroke_velocity_m_s
            est.step(sensors.measure((p_head, p_rod, stroke)), float(mode), supply_list[k])
            acc_z = float(track.data.qacc[acc_index]) if track is not None else math.nan
            closure = track.closure_error_m if track is not None else math.nan
            rec.append(k, t + dt, mech.idler_force_N, ref[k], p_head, p_rod, p_supply, stroke,
                       velocity, q_supply, mode, u, e_supply, p_work, mech_work, acc_z, closure)
            if playback is not None and (k + 1) % FRAME_EVERY_STEPS == 0:
                playback.log_frame(t + dt)
            if bar is not None and k % 100 == 99:
                bar.update(100)
    except BaseException:
        if playback is not None:
            playback.discard()   # no half-written recording
        raise
    wall = time.perf_counter() - wall_start
    if bar is not None:
        bar.close()
    meta = run_metadata(sc.name, run.architecture, controller_name, estimator_name, seed,
                        machine(), variant=var.name, duration_s=duration)
    table = rec.table(meta)
    result = Result(table, {})
    result.metrics = compute_metrics(result.columns(), sc.metric_windows(duration),
                                     solve_times_s=np.array(solve_times),
                                     solve_success=np.array(solve_ok), wall_time_s=wall)
    if isinstance(tens, HydraulicTensioner):
        result.metrics["interface_energy_residual_J"] = tens.ledger.interface_residual_J
        result.metrics["friction_loss_J"] = tens.ledger.friction_J
        result.metrics["ledger_balance_error_J"] = tens.ledger.balance_error_J
    result.metrics["controller_fallbacks"] = float(getattr(controller, "fallbacks", 0))
    result.metrics["controller_overruns"] = float(np.sum(np.array(solve_times) > period))
    if track is not None:
        result.metrics["mujoco_warnings"] = float(track.warning_count)
    if playback is not None:
        playback.log_timeseries(result)
        playback.close()
    return result


def _pressures(tens: HydraulicTensioner | IdealForceSource) -> tuple[float, float]:
    if isinstance(tens, IdealForceSource):
        return tens.p_head_Pa, tens.tank
    p = tens.pressures
    return 0.5 * (p[1] + p[2]), p[3]


def _hydraulic_row(tens: HydraulicTensioner | IdealForceSource) -> tuple[float, ...]:
    """(p_head, p_rod, p_supply, q_supply, e_supply, p_work, mech_work) after a step."""
    if isinstance(tens, IdealForceSource):
        return (tens.p_head_Pa, tens.tank, math.nan, math.nan, tens.supply_J, tens.work_J,
                tens.work_J)
    row = tens.log()
    return (row.p_head_Pa, row.p_rod_Pa, row.p_supply_Pa, row.q_supply_m3_s, row.supply_J,
            row.piston_work_J, row.mech_work_J)
