"""Control-domain parameters: frozen, validated dataclasses.

:func:`load_config` reads the controller's own parameters from ``models/lf1352_control.toml``
(sensors, valve logic, estimator, controller limits, MPC, PID and the reduced model's
numerical choices). The reduced model's physical parameters (:class:`PlantParams`) are not
in that file: they derive from the hydraulic parameters and the identified idler
(``trackmj.sim.control_plant.reduced_plant_params``), so no value is entered twice.

All values SI (pressures gauge [Pa]). The checks are the one validator of
:mod:`trackmj.validator`: types, ranges and cross-field checks run on construction, and the
loader refuses unknown, missing or mistyped keys naming the file, the table and the key.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, ClassVar

from trackmj.validator import Location, ParameterError, Parameters, load_file, param, sources_field

DEFAULT_FILE = "lf1352_control.toml"

BAND_REL = (2.0 / 3.0, 4.0 / 3.0)
"""Admissible tension band [F_min, F_max] over the machine's nominal tension (LF1352: the
study's 10-20 kN about its 15 kN working reference)."""
REFERENCE_MARGIN_REL = 1.0 / 30.0
"""Reference-governor margin inside the band over the nominal tension (500 N at 15 kN: about
the low-passed ripple of the driven track)."""
PID_DEAD_BAND_REL = 0.01
"""PID error dead band over the nominal tension (150 N at 15 kN: half the ±2 % settling band)."""
PID_INTEGRATION_BAND_REL = 0.04
"""PID conditional-integration band over the nominal tension: twice the ±2 % settling band
(600 N at 15 kN)."""
DERIVED = {("controller", "force_min_N"): BAND_REL[0],
           ("controller", "force_max_N"): BAND_REL[1],
           ("controller", "reference_margin_N"): REFERENCE_MARGIN_REL,
           ("pid", "error_dead_band_N"): PID_DEAD_BAND_REL,
           ("pid", "integration_band_N"): PID_INTEGRATION_BAND_REL}
"""Control-file keys a machine's nominal tension fixes: value = factor x nominal tension [N]
when the file (or an override) leaves the key out."""


def resolved(params: Parameters, key: str) -> float:
    """``params.<key>`` [N], a key of :data:`DERIVED` (given in the file or derived from the
    nominal tension by :func:`load_config`); ParameterError when it is still None (parameters
    built without :func:`load_config` that leave the key out)."""
    value = getattr(params, key)
    if value is None:
        raise ParameterError(f"[{type(params).__name__}].{key}: not given and not derived "
                             "from a nominal tension (read the control file with load_config)")
    return value


@dataclass(frozen=True, slots=True)
class PlantParams(Parameters):
    """Reduced model: one equivalent cylinder (both cylinders lumped) + idler mass-spring-damper.

    State X = [p_head Pa, p_rod Pa, y m, y_dot m/s]; y = stroke, grows outward (tensioning).
    Areas [m^2] are effective full-opening path areas: valve_area_head_m2 supply<->heads and
    heads->tank, valve_area_rod_m2 the release feed supply->rods, vent_area_rod_m2 rods->tank.
    Built by ``trackmj.sim.control_plant.reduced_plant_params`` (no defaults: every value derives
    from the hydraulic, idler and control files).
    """

    area_head_m2: float = param(0.0, 1.0, open_low=True, doc="head area of both cylinders")
    area_rod_m2: float = param(0.0, 1.0, open_low=True, doc="rod (annulus) area of both")
    stroke_m: float = param(0.0, 2.0, open_low=True, doc="stroke between the end stops")
    dead_volume_head_m3: float = param(0.0, 1.0, open_low=True,
                                       doc="head node volume at zero stroke")
    dead_volume_rod_m3: float = param(0.0, 1.0, open_low=True,
                                      doc="rod node volume at full stroke (incl. line B)")
    bulk_modulus_Pa: float = param(1e7, 1e10, doc="oil bulk modulus")
    density_kg_m3: float = param(500.0, 2000.0, doc="oil density")
    discharge_coefficient: float = param(0.0, 1.0, open_low=True, unit="1",
                                         doc="orifice discharge coefficient Cq")
    valve_area_head_m2: float = param(0.0, 1e-2, open_low=True,
                                      doc="effective path area supply <-> heads, heads -> tank")
    valve_area_rod_m2: float = param(0.0, 1e-2, open_low=True,
                                     doc="effective path area of the release feed supply -> rods")
    vent_area_rod_m2: float = param(0.0, 1e-2, open_low=True, doc="rods -> tank vent area")
    critical_pressure_Pa: float = param(0.0, 5e6, open_low=True,
                                        doc="orifice regularisation pressure p_cr")
    opening_smoothing: float = param(0.0, 0.1, open_low=True, unit="1",
                                     doc="smoothing width of max(u, 0) in the opening map")
    supply_pressure_Pa: float = param(0.0, 5e7, open_low=True, doc="nominal supply pressure")
    tank_pressure_Pa: float = param(0.0, 5e6, doc="tank pressure")
    leakage_m3_s_Pa: float = param(0.0, 1e-9, doc="piston-seal leakage of both cylinders")
    mass_kg: float = param(0.0, 1e5, open_low=True, doc="equivalent idler mass M")
    stiffness_N_m: float = param(0.0, 1e9, open_low=True, doc="equivalent idler stiffness k")
    damping_N_s_m: float = param(0.0, 1e7, doc="equivalent idler damping c")
    free_position_m: float = param(-1.0, None, doc="stroke y0 at which the idler spring is "
                                   "unloaded (<= stroke_m)")
    drive_load_gain_1_m: float = param(0.0, 1e3, unit="1/m", doc="idler load per sprocket "
                                       "torque while the idler's strands are the drive's "
                                       "tight side, G/r (trackmj.machines.drive_load)")
    drive_tight_sign: float = param(-1.0, 1.0, unit="1", doc="sign of the sprocket torque "
                                    "that makes the idler's strands the tight side: +1 "
                                    "sprocket at the front, -1 at the rear")

    def cross_check(self, at: Location) -> None:
        if self.area_rod_m2 >= self.area_head_m2:
            raise at.error("area_rod_m2", self.area_rod_m2,
                           f"must be < area_head_m2 = {self.area_head_m2!r}")
        if self.free_position_m > self.stroke_m:
            raise at.error("free_position_m", self.free_position_m,
                           f"must be <= stroke_m = {self.stroke_m!r}")
        if self.drive_tight_sign not in (-1.0, 1.0):
            raise at.error("drive_tight_sign", self.drive_tight_sign, "must be -1 or +1")

    def replace(self, **changes: float) -> PlantParams:
        """Copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True, slots=True)
class SensorParams(Parameters):
    """Sensors for p_head, p_rod [Pa], stroke y [m] (Gaussian noise, bias, quantum) and the
    sprocket drive torque [N·m] (Gaussian noise)."""

    sample_period_s: float = param(0.0, 1.0, open_low=True, doc="sampling period")
    pressure_noise_std_Pa: float = param(0.0, 1e7, doc="pressure noise standard deviation")
    stroke_noise_std_m: float = param(0.0, 0.1, doc="stroke noise standard deviation")
    pressure_quantum_Pa: float = param(0.0, 1e6, doc="pressure quantisation step (0: off)")
    stroke_quantum_m: float = param(0.0, 0.01, doc="stroke quantisation step (0: off)")
    pressure_bias_Pa: float = param(-1e7, 1e7, doc="pressure sensor bias")
    stroke_bias_m: float = param(-0.1, 0.1, doc="stroke sensor bias")
    drive_torque_noise_std_N_m: float = param(0.0, 1e5, unit="N·m", doc="sprocket drive "
                                              "torque measurement noise standard deviation")


@dataclass(frozen=True, slots=True)
class ValveParams(Parameters):
    """Valve logic: dead zone on |u|, minimum holding time and solenoid delay."""

    dead_zone: float = param(0.0, 0.99, unit="1", doc="|u| below this -> hold")
    min_hold_s: float = param(0.0, 1.0, doc="minimum time a valve mode is held")
    solenoid_delay_s: float = param(0.0, 1.0, doc="delay applied by the valve logic")
    sigma_delta: bool = param(doc="sum-up rounding so the mode average follows u")


@dataclass(frozen=True, slots=True)
class EstimatorParams(Parameters):
    """EKF/UKF: standard deviations (SI) of the discrete per-sample noises, UKF spread."""

    process_std: tuple[float, float, float, float] = param(
        0.0, 1e8, open_low=True, unit="Pa, Pa, m, m/s",
        doc="process noise std of (p_head, p_rod, y, y_dot) per sample")
    measurement_std: tuple[float, float, float] = param(
        0.0, 1e8, open_low=True, unit="Pa, Pa, m", doc="measurement noise std of (p_head, "
        "p_rod, y)")
    initial_std: tuple[float, float, float, float] = param(
        0.0, 1e8, open_low=True, unit="Pa, Pa, m, m/s", doc="initial state std")
    free_position_process_std_m: float = param(
        0.0, 1e-2, open_low=True, doc="random-walk std per sample of the disturbance state "
        "y0 (the stroke at which the equivalent idler is unloaded)")
    free_position_initial_std_m: float = param(0.0, 0.1, open_low=True,
                                               doc="initial std of y0")
    drive_torque_filter_s: float = param(0.0, 10.0, doc="time constant of the first-order "
                                         "low-pass on the measured drive torque before its "
                                         "idler load enters the model")
    ukf_alpha: float = param(0.1, 1.0, unit="1", doc="UKF sigma-point spread alpha")
    ukf_beta: float = param(0.0, 10.0, unit="1", doc="UKF prior-distribution beta")
    ukf_kappa: float = param(-3.0, 10.0, unit="1", doc="UKF secondary scaling kappa")


@dataclass(frozen=True, slots=True)
class ControllerParams(Parameters):
    """Shared controller limits: period, tension band, pressure band, u bounds."""

    period_s: float = param(0.0, 1.0, open_low=True, doc="control period")
    pressure_min_Pa: float = param(-1e5, 5e7, doc="lower chamber pressure limit")
    pressure_max_Pa: float = param(-1e5, 5e7, doc="upper chamber pressure limit")
    u_min: float = param(-1.0, 0.0, unit="1", doc="lowest valve opening (-1: full release)")
    u_max: float = param(0.0, 1.0, unit="1", doc="highest valve opening (+1: full pressurize)")
    governor_valve_drop_Pa: float = param(0.0, 1e7, doc="smallest pressure drop across the head "
                                          "path the governor leaves below the supply")
    force_min_N: float | None = param(-1e6, 1e6, default=None, doc="lower tension limit "
                                      "F_min; optional: BAND_REL[0] x the nominal tension")
    force_max_N: float | None = param(-1e6, 1e6, default=None, doc="upper tension limit "
                                      "F_max; optional: BAND_REL[1] x the nominal tension")
    reference_margin_N: float | None = param(
        0.0, 1e5, default=None, doc="the reference governor keeps the tracked reference this "
        "far inside [F_min, F_max]; optional: REFERENCE_MARGIN_REL x the nominal tension")
    nominal_tension_N: float | None = param(
        0.0, 1e6, open_low=True, default=None, doc="the machine's nominal working tension "
        "the derived values scale with; optional: the machine's (load_config)")

    def cross_check(self, at: Location) -> None:
        if (self.force_min_N is not None and self.force_max_N is not None
                and self.force_max_N < self.force_min_N):
            raise at.error("force_max_N", self.force_max_N,
                           f"must be >= force_min_N = {self.force_min_N!r}")
        if self.pressure_max_Pa < self.pressure_min_Pa:
            raise at.error("pressure_max_Pa", self.pressure_max_Pa,
                           f"must be >= pressure_min_Pa = {self.pressure_min_Pa!r}")


@dataclass(frozen=True, slots=True)
class MpcParams(Parameters):
    """NMPC/LMPC horizon (steps of the controller period), blocking, weights, SQP settings.

    max_iter: NMPC SQP iterations per period (1 = real-time iteration; its condensed QPs
    are solved exactly); qp_max_iter: the LMPC's OSQP iteration cap per QP; qp_tolerance:
    its OSQP eps_abs = eps_rel (scaled units).
    """

    horizon_steps: int = param(1, 200, doc="prediction horizon in controller periods")
    block_steps: int = param(1, 200, doc="move-blocking length in controller periods")
    collocation_degree: int = param(1, 5, unit="1", doc="Radau IIA collocation degree")
    weight_force_per_kN2: float = param(0.0, 1e6, open_low=True, unit="1/kN^2",
                                        doc="weight on the tension error in kN")
    weight_input: float = param(0.0, 1e6, unit="1", doc="weight on u^2")
    weight_input_rate: float = param(0.0, 1e6, unit="1", doc="weight on the u increments")
    weight_force_slack_per_kN2: float = param(0.0, 1e9, open_low=True, unit="1/kN^2",
                                              doc="weight on the soft F_min/F_max slack")
    tuned_on_machine: str = param(pattern=r"[a-z0-9][a-z0-9_-]*", max_len=40,
                                  doc="the shipped machine on whose plant the weights were "
                                  "tuned; on a machine whose files give another tension-rate "
                                  "gain g the u and u-rate weights are scaled by (g/g_tuned)² "
                                  "(a run's --set changes do not retune them)")
    max_iter: int = param(1, 1000, doc="NMPC SQP iterations per period, at most")
    accept_iter: int = param(1, 1000, doc="NMPC SQP iterations after which a plan feasible "
                             "within the feasibility tolerance is used without more")
    qp_max_iter: int = param(1, 100000, doc="LMPC OSQP iteration cap per QP")
    qp_tolerance: float = param(0.0, 1.0, open_low=True, unit="1",
                                doc="LMPC OSQP eps_abs = eps_rel (scaled units)")
    time_budget_s: float = param(0.0, 10.0, open_low=True,
                                 doc="a solve longer than this counts as an overrun")
    offset_integral_time_s: float = param(0.0, 1e3, open_low=True,
                                          doc="integral time T_i of the reference trim "
                                          "(trackmj.control.trim)")
    offset_trim_max_rel: float = param(0.0, 0.5, unit="1",
                                       doc="trim limit I_max as a fraction of the band's "
                                       "middle (0: no trim)")
    offset_dead_band_rel: float = param(0.0, 0.5, unit="1",
                                        doc="the trim ignores low-passed errors within this "
                                        "fraction of the band's middle")
    offset_clip_rel: float = param(0.0, 0.5, unit="1",
                                   doc="the trim integrates its low-passed error clipped to "
                                   "this fraction of the band's middle")
    offset_filter_s: float = param(0.0, 100.0, open_low=True,
                                   doc="time constant of the trim error's low-pass")

    def cross_check(self, at: Location) -> None:
        if self.block_steps > self.horizon_steps or self.horizon_steps % self.block_steps:
            raise at.error("horizon_steps", self.horizon_steps,
                           f"must be a multiple of block_steps = {self.block_steps}")


@dataclass(frozen=True, slots=True)
class PidParams(Parameters):
    """PID tuning-rule inputs (SIMC on an integrating plant with dead time), error dead
    band and conditional-integration band, output hysteresis thresholds on |u| (see
    ``trackmj.control.pid``)."""

    dead_time_s: float = param(0.0, 10.0, doc="effective dead time theta of the SIMC rule "
                               "without the measurement filter")
    measurement_filter_s: float = param(0.0, 1.0, doc="time constant of the first-order "
                                        "filter on the tension the PID acts on (0: none); "
                                        "added to the SIMC dead time")
    closed_loop_time_s: float = param(0.0, 100.0, open_low=True,
                                      doc="SIMC closed-loop time constant tau_c")
    derivative_filter_N: float = param(1.0, 100.0, unit="1",
                                       doc="derivative filter ratio N (Tf = Td / N); "
                                       "dimensionless despite the suffix")
    back_calculation_gain: float = param(0.0, 100.0, open_low=True, unit="1",
                                         doc="anti-windup Tt = Ti / gain")
    output_on: float = param(0.0, 1.0, unit="1", doc="leave hold when |u| exceeds this")
    output_off: float = param(0.0, 1.0, unit="1", doc="return to hold below this")
    error_dead_band_N: float | None = param(0.0, 1e5, default=None, doc="errors inside are "
                                            "zero for the proportional part; optional: "
                                            "PID_DEAD_BAND_REL x the nominal tension")
    integration_band_N: float | None = param(0.0, 1e6, default=None, doc="integrate only "
                                             "while |error| <= this; optional: "
                                             "PID_INTEGRATION_BAND_REL x the nominal tension")

    def cross_check(self, at: Location) -> None:
        if self.output_off > self.output_on:
            raise at.error("output_off", self.output_off,
                           f"must be <= output_on = {self.output_on!r}")


@dataclass(frozen=True, slots=True)
class ReducedModelParams(Parameters):
    """The reduced model's own numerical choices (the rest of :class:`PlantParams` derives
    from the hydraulic and idler files)."""

    opening_smoothing: float = param(0.0, 0.1, open_low=True, unit="1",
                                     doc="smoothing width of the opening positive part")
    vent_area_rod_m2: float = param(0.0, 1e-2, open_low=True,
                                    doc="rods -> tank vent area of the reduced model")


@dataclass(frozen=True, slots=True)
class ControlConfig(Parameters):
    """All control-domain parameter groups of the control file; ``sources`` maps each
    table to its ``source``."""

    sensors: SensorParams
    valves: ValveParams
    estimator: EstimatorParams
    controller: ControllerParams
    mpc: MpcParams
    pid: PidParams
    reduced_model: ReducedModelParams
    sources: Mapping[str, str] = sources_field()

    file_kind: ClassVar[str] = "control"


def default_path() -> Path:
    """The packaged ``lf1352_control.toml``."""
    return Path(str(files("trackmj.models").joinpath(DEFAULT_FILE)))


def load_config(path: str | Path | None = None,
                overrides: Mapping[str, Any] | None = None, *,
                nominal_tension_N: float | None = None) -> ControlConfig:
    """Read and validate the control TOML; the keys of :data:`DERIVED` the file leaves out
    are the machine's nominal tension times their factor.

    Parameters
    ----------
    path : str or Path, optional
        The file; default the packaged ``lf1352_control.toml``.
    overrides : mapping, optional
        ``{dotted key: value}``, the ``control`` entry of
        :func:`trackmj.validator.parse_overrides`.
    nominal_tension_N : float, optional
        The machine's nominal working tension [N] (its mechanics file's
        ``[tensioner].nominal_tension_N``); needed when the file leaves a derived key out.

    Returns
    -------
    ControlConfig
    """
    path = default_path() if path is None else Path(path)
    cfg = load_file(ControlConfig, path, overrides=overrides)
    if cfg.controller.nominal_tension_N is None and nominal_tension_N is not None:
        cfg = dataclasses.replace(cfg, controller=dataclasses.replace(
            cfg.controller, nominal_tension_N=nominal_tension_N))
    nominal_tension_N = cfg.controller.nominal_tension_N
    missing = [(table, key) for table, key in DERIVED
               if getattr(getattr(cfg, table), key) is None]
    if not missing:
        return cfg
    if nominal_tension_N is None:
        table, key = missing[0]
        raise ParameterError(f"{path.name} [{table}].{key}: not given, and no nominal tension "
                             "to derive it from (load the control file through its machine)")
    changes: dict[str, dict[str, float]] = {}
    for table, key in missing:
        changes.setdefault(table, {})[key] = nominal_tension_N * DERIVED[table, key]
    return dataclasses.replace(cfg, **{table: dataclasses.replace(getattr(cfg, table), **kv)
                                       for table, kv in changes.items()})
