"""Control-domain parameters: frozen dataclasses read from ``models/lf1352_control.toml``.

All values SI (pressures gauge [Pa]). Each dataclass validates its ranges on construction and
raises ``ValueError`` naming the parameter and the allowed range.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Any

DEFAULT_FILE = "lf1352_control.toml"


def _check(obj: object, name: str, lo: float, hi: float, *, lo_open: bool = False) -> None:
    """Raise ValueError unless lo (<|<=) getattr(obj, name) <= hi."""
    v = getattr(obj, name)
    values = v if isinstance(v, tuple) else (v,)
    for x in values:
        ok = math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi
        if not ok:
            bracket = "(" if lo_open else "["
            raise ValueError(
                f"{type(obj).__name__}.{name} = {v!r} outside allowed range {bracket}{lo}, {hi}]"
            )


@dataclass(frozen=True, slots=True)
class PlantParams:
    """Reduced model: one equivalent cylinder (both cylinders lumped) + idler mass-spring-damper.

    State X = [p_head Pa, p_rod Pa, y m, y_dot m/s]; y = stroke, grows outward (tensioning).
    Areas [m^2] are effective full-opening path areas: valve_area_head_m2 supply<->heads and
    heads->tank, valve_area_rod_m2 the release feed supply->rods, vent_area_rod_m2 rods->tank.
    Defaults equal ``models/lf1352_control.toml``.
    """

    area_head_m2: float = 2.513e-3
    area_rod_m2: float = 1.532e-3
    stroke_m: float = 0.10
    dead_volume_head_m3: float = 3.0e-4
    dead_volume_rod_m3: float = 3.0e-4
    bulk_modulus_Pa: float = 1.4e9
    density_kg_m3: float = 860.0
    discharge_coefficient: float = 0.65
    valve_area_head_m2: float = 5.5e-8
    valve_area_rod_m2: float = 5.5e-8
    vent_area_rod_m2: float = 1.0e-5
    critical_pressure_Pa: float = 1.0e5
    opening_smoothing: float = 0.01
    supply_pressure_Pa: float = 12.0e6
    tank_pressure_Pa: float = 0.2e6
    leakage_m3_s_Pa: float = 1.0e-14
    mass_kg: float = 474.0
    stiffness_N_m: float = 9.4e6
    damping_N_s_m: float = 1.3e5
    free_position_m: float = 0.0484

    def __post_init__(self) -> None:
        _check(self, "area_head_m2", 0.0, 1.0, lo_open=True)
        _check(self, "area_rod_m2", 0.0, self.area_head_m2, lo_open=True)
        _check(self, "stroke_m", 0.0, 2.0, lo_open=True)
        _check(self, "dead_volume_head_m3", 0.0, 1.0, lo_open=True)
        _check(self, "dead_volume_rod_m3", 0.0, 1.0, lo_open=True)
        _check(self, "bulk_modulus_Pa", 1e7, 1e10)
        _check(self, "density_kg_m3", 500.0, 2000.0)
        _check(self, "discharge_coefficient", 0.0, 1.0, lo_open=True)
        _check(self, "valve_area_head_m2", 0.0, 1e-2, lo_open=True)
        _check(self, "valve_area_rod_m2", 0.0, 1e-2, lo_open=True)
        _check(self, "vent_area_rod_m2", 0.0, 1e-2, lo_open=True)
        _check(self, "critical_pressure_Pa", 0.0, 5e6, lo_open=True)
        _check(self, "opening_smoothing", 0.0, 0.1, lo_open=True)
        _check(self, "supply_pressure_Pa", 0.0, 5e7, lo_open=True)
        _check(self, "tank_pressure_Pa", 0.0, 5e6)
        _check(self, "leakage_m3_s_Pa", 0.0, 1e-9)
        _check(self, "mass_kg", 0.0, 1e5, lo_open=True)
        _check(self, "stiffness_N_m", 0.0, 1e9, lo_open=True)
        _check(self, "damping_N_s_m", 0.0, 1e7)
        _check(self, "free_position_m", -1.0, self.stroke_m)

    def replace(self, **changes: float) -> PlantParams:
        """Copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True, slots=True)
class SensorParams:
    """1 kHz sensors for p_head, p_rod [Pa] and stroke y [m]: Gaussian noise, bias, quantum."""

    sample_period_s: float = 1.0e-3
    pressure_noise_std_Pa: float = 0.15e6
    stroke_noise_std_m: float = 0.2e-3
    pressure_quantum_Pa: float = 0.0
    stroke_quantum_m: float = 0.0
    pressure_bias_Pa: float = 0.0
    stroke_bias_m: float = 0.0

    def __post_init__(self) -> None:
        _check(self, "sample_period_s", 0.0, 1.0, lo_open=True)
        _check(self, "pressure_noise_std_Pa", 0.0, 1e7)
        _check(self, "stroke_noise_std_m", 0.0, 0.1)
        _check(self, "pressure_quantum_Pa", 0.0, 1e6)
        _check(self, "stroke_quantum_m", 0.0, 0.01)
        _check(self, "pressure_bias_Pa", -1e7, 1e7)
        _check(self, "stroke_bias_m", -0.1, 0.1)


@dataclass(frozen=True, slots=True)
class ValveParams:
    """Valve logic: dead zone on |u|, minimum holding time and solenoid delay [s]."""

    dead_zone: float = 0.05
    min_hold_s: float = 0.030
    solenoid_delay_s: float = 0.020
    sigma_delta: bool = True

    def __post_init__(self) -> None:
        _check(self, "dead_zone", 0.0, 0.99)
        _check(self, "min_hold_s", 0.0, 1.0)
        _check(self, "solenoid_delay_s", 0.0, 1.0)


@dataclass(frozen=True, slots=True)
class EstimatorParams:
    """EKF/UKF: standard deviations (SI) of the discrete per-sample noises, UKF spread."""

    process_std: tuple[float, float, float, float] = (0.2e6, 0.3e6, 0.05e-3, 0.1e-3)
    measurement_std: tuple[float, float, float] = (0.15e6, 0.15e6, 0.2e-3)
    initial_std: tuple[float, float, float, float] = (0.5e6, 0.5e6, 1.0e-3, 10.0e-3)
    ukf_alpha: float = 1.0
    ukf_beta: float = 2.0
    ukf_kappa: float = -1.0

    def __post_init__(self) -> None:
        for name, n in (("process_std", 4), ("measurement_std", 3), ("initial_std", 4)):
            if len(getattr(self, name)) != n:
                raise ValueError(f"EstimatorParams.{name} must have {n} entries")
            _check(self, name, 0.0, 1e8, lo_open=True)
        _check(self, "ukf_alpha", 0.1, 1.0)
        _check(self, "ukf_beta", 0.0, 10.0)
        _check(self, "ukf_kappa", -3.0, 10.0)


@dataclass(frozen=True, slots=True)
class ControllerParams:
    """Shared controller limits: period [s], tension band [N], pressure band [Pa], u bounds."""

    period_s: float = 0.010
    force_min_N: float = 10.0e3
    force_max_N: float = 20.0e3
    pressure_min_Pa: float = 0.0
    pressure_max_Pa: float = 21.0e6
    u_min: float = -1.0
    u_max: float = 1.0

    def __post_init__(self) -> None:
        _check(self, "period_s", 0.0, 1.0, lo_open=True)
        _check(self, "force_min_N", -1e6, 1e6)
        _check(self, "force_max_N", self.force_min_N, 1e6)
        _check(self, "pressure_min_Pa", -1e5, 5e7)
        _check(self, "pressure_max_Pa", self.pressure_min_Pa, 5e7)
        _check(self, "u_min", -1.0, 0.0)
        _check(self, "u_max", 0.0, 1.0)


@dataclass(frozen=True, slots=True)
class MpcParams:
    """NMPC/LMPC horizon (steps of the controller period), blocking, weights, SQP settings.

    max_iter: NMPC SQP iterations per period (1 = real-time iteration; its condensed QPs
    are solved exactly); qp_max_iter: the LMPC's OSQP iteration cap per QP; qp_tolerance:
    its OSQP eps_abs = eps_rel (scaled units).
    """

    horizon_steps: int = 15
    block_steps: int = 3
    collocation_degree: int = 1
    weight_force_per_kN2: float = 1.0
    weight_input: float = 3.0
    weight_input_rate: float = 2.0
    weight_force_slack_per_kN2: float = 1.0e3
    max_iter: int = 2
    qp_max_iter: int = 100
    qp_tolerance: float = 1e-4
    time_budget_s: float = 0.010

    def __post_init__(self) -> None:
        _check(self, "horizon_steps", 1, 200)
        _check(self, "block_steps", 1, self.horizon_steps)
        _check(self, "collocation_degree", 1, 5)
        _check(self, "weight_force_per_kN2", 0.0, 1e6, lo_open=True)
        _check(self, "weight_input", 0.0, 1e6)
        _check(self, "weight_input_rate", 0.0, 1e6)
        _check(self, "weight_force_slack_per_kN2", 0.0, 1e9, lo_open=True)
        _check(self, "max_iter", 1, 1000)
        _check(self, "qp_max_iter", 1, 100000)
        _check(self, "qp_tolerance", 0.0, 1.0, lo_open=True)
        _check(self, "time_budget_s", 0.0, 10.0, lo_open=True)
        if self.horizon_steps % self.block_steps:
            raise ValueError(
                f"MpcParams.horizon_steps = {self.horizon_steps} must be a multiple of "
                f"block_steps = {self.block_steps}"
            )


@dataclass(frozen=True, slots=True)
class PidParams:
    """PID tuning-rule inputs (SIMC on an integrating plant with dead time) [s], error dead
    band and conditional-integration band [N], output hysteresis thresholds on |u| [-]
    (see ``trackmj.control.pid``)."""

    dead_time_s: float = 0.040
    closed_loop_time_s: float = 0.25
    derivative_filter_N: float = 1.0
    back_calculation_gain: float = 1.0
    error_dead_band_N: float = 150.0
    integration_band_N: float = 600.0
    output_on: float = 0.1
    output_off: float = 0.05

    def __post_init__(self) -> None:
        _check(self, "dead_time_s", 0.0, 10.0)
        _check(self, "closed_loop_time_s", 0.0, 100.0, lo_open=True)
        _check(self, "derivative_filter_N", 1.0, 100.0)
        _check(self, "back_calculation_gain", 0.0, 100.0, lo_open=True)
        _check(self, "error_dead_band_N", 0.0, 1e5)
        _check(self, "integration_band_N", 0.0, 1e6)
        _check(self, "output_on", 0.0, 1.0)
        _check(self, "output_off", 0.0, self.output_on)


@dataclass(frozen=True, slots=True)
class ControlConfig:
    """All control-domain parameter groups."""

    plant: PlantParams = field(default_factory=PlantParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    valves: ValveParams = field(default_factory=ValveParams)
    estimator: EstimatorParams = field(default_factory=EstimatorParams)
    controller: ControllerParams = field(default_factory=ControllerParams)
    mpc: MpcParams = field(default_factory=MpcParams)
    pid: PidParams = field(default_factory=PidParams)


_SECTIONS: dict[str, type] = {
    "plant": PlantParams,
    "sensors": SensorParams,
    "valves": ValveParams,
    "estimator": EstimatorParams,
    "controller": ControllerParams,
    "mpc": MpcParams,
    "pid": PidParams,
}


def _build(cls: type, section: str, raw: dict[str, Any]) -> Any:
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = set(raw) - set(known)
    if unknown:
        raise ValueError(f"[{section}]: unknown parameter(s) {sorted(unknown)}")
    kwargs = {k: tuple(float(x) for x in v) if isinstance(v, list) else v for k, v in raw.items()}
    return cls(**kwargs)


def load_config(path: str | Path | None = None) -> ControlConfig:
    """Read the control TOML (default: ``trackmj.models/lf1352_control.toml``)."""
    if path is None:
        text = files("trackmj.models").joinpath(DEFAULT_FILE).read_text(encoding="utf-8")
    else:
        text = Path(path).read_text(encoding="utf-8")
    raw = tomllib.loads(text)
    unknown = set(raw) - set(_SECTIONS)
    if unknown:
        raise ValueError(f"unknown section(s) {sorted(unknown)}")
    return ControlConfig(**{k: _build(c, k, raw.get(k, {})) for k, c in _SECTIONS.items()})


def control_config_with(
    plant_overrides: dict[str, float], base: ControlConfig | None = None
) -> ControlConfig:
    """``base`` (default: the TOML file) with some ``PlantParams`` fields replaced, e.g. k_eq,
    M, c, y0 from ``trackmj.identify`` and the supply pressure and areas from the hydraulic
    plugin: ``control_config_with({"stiffness_N_m": idler.stiffness_N_m, ...})``.

    Values SI (field names carry the unit). Raises ``ValueError`` naming unknown fields, and
    the ``PlantParams`` range checks apply to the new values.
    """
    cfg = load_config() if base is None else base
    known = {f.name for f in dataclasses.fields(PlantParams)}
    unknown = set(plant_overrides) - known
    if unknown:
        raise ValueError(f"control_config_with: unknown plant parameter(s) {sorted(unknown)}")
    plant = dataclasses.replace(cfg.plant, **{k: float(v) for k, v in plant_overrides.items()})
    return dataclasses.replace(cfg, plant=plant)
