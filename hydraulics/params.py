"""Hydraulic parameters: frozen, range-checked dataclasses read from a TOML file.

All values SI, pressures gauge [Pa] unless a name ends in ``_abs``. Every constructor
validates its fields and raises ``ValueError`` naming the parameter and the allowed range.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass, fields
from importlib.resources import files
from pathlib import Path
from typing import Any

_INF = math.inf


def _check(obj: Any, limits: dict[str, tuple[float, float, bool]]) -> None:
    """Validate float fields of ``obj``: name -> (low, high, low_inclusive); high inclusive."""
    for name, (lo, hi, lo_incl) in limits.items():
        prefix = type(obj).__name__
        value = getattr(obj, name)
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{prefix}.{name} must be a number, got {value!r}") from None
        ok = math.isfinite(x) and (x >= lo if lo_incl else x > lo) and x <= hi
        if not ok:
            bracket = "[" if lo_incl else "("
            raise ValueError(f"{prefix}.{name} = {value!r} is outside {bracket}{lo}, {hi}]")


@dataclass(frozen=True, slots=True)
class Fluid:
    """Hydraulic oil: density [kg/m^3], effective bulk modulus [Pa], viscosity [m^2/s]."""

    density_kg_m3: float
    bulk_modulus_Pa: float
    kinematic_viscosity_m2_s: float

    def __post_init__(self) -> None:
        _check(self, {"density_kg_m3": (0.0, 2e4, False), "bulk_modulus_Pa": (0.0, 1e11, False),
                      "kinematic_viscosity_m2_s": (0.0, 1.0, False)})


@dataclass(frozen=True, slots=True)
class OrificeLaw:
    """Regularised orifice Q = Cq·A·sqrt(2/ρ)·Δp/(Δp²+p_cr²)^(1/4); Cq [-], p_cr [Pa]."""

    discharge_coefficient: float
    critical_pressure_Pa: float

    def __post_init__(self) -> None:
        _check(self, {"discharge_coefficient": (0.0, 1.0, False),
                      "critical_pressure_Pa": (0.0, 1e7, False)})


@dataclass(frozen=True, slots=True)
class Cavitation:
    """Outflow limiter floor/band [Pa] and tank->chamber make-up check valves."""

    floor_Pa: float
    band_Pa: float
    makeup_crack_below_tank_Pa: float
    makeup_full_below_tank_Pa: float
    makeup_area_m2: float

    def __post_init__(self) -> None:
        _check(self, {"floor_Pa": (-1e5, 1e7, True), "band_Pa": (0.0, 1e7, False),
                      "makeup_crack_below_tank_Pa": (0.0, 1e7, True),
                      "makeup_full_below_tank_Pa": (self.makeup_crack_below_tank_Pa, 1e7, False),
                      "makeup_area_m2": (0.0, 1.0, True)})


@dataclass(frozen=True, slots=True)
class Supply:
    """Supply node: mode ("accumulator" | "prescribed"), pump flow [m^3/s], line volume [m^3]."""

    mode: str
    pump_flow_m3_s: float
    line_volume_m3: float

    def __post_init__(self) -> None:
        if self.mode not in ("accumulator", "prescribed"):
            raise ValueError(f"Supply.mode = {self.mode!r} must be 'accumulator' or 'prescribed'")
        _check(self, {"pump_flow_m3_s": (0.0, 1.0, True), "line_volume_m3": (0.0, 1.0, False)})


@dataclass(frozen=True, slots=True)
class Accumulator:
    """Gas accumulator: gas volume at precharge [m^3], precharge [Pa gauge], exponent n [-]."""

    gas_volume_m3: float
    precharge_Pa: float
    polytropic_exponent: float
    atmospheric_pressure_Pa_abs: float

    def __post_init__(self) -> None:
        _check(self, {"gas_volume_m3": (0.0, 1.0, False), "precharge_Pa": (0.0, 1e8, False),
                      "polytropic_exponent": (1.0, 1.67, False),
                      "atmospheric_pressure_Pa_abs": (0.0, 2e5, False)})


@dataclass(frozen=True, slots=True)
class Relief:
    """Relief valve S->T: opens between crack and full-open pressure [Pa] to full area [m^2]."""

    crack_Pa: float
    full_open_Pa: float
    full_area_m2: float

    def __post_init__(self) -> None:
        _check(self, {"crack_Pa": (0.0, 1e8, False), "full_open_Pa": (self.crack_Pa, 1e8, False),
                      "full_area_m2": (0.0, 1.0, True)})


@dataclass(frozen=True, slots=True)
class Valve:
    """Solenoid valve: open / closed-edge leak area [m^2], overlap (fraction of travel),
    pure electromagnetic delay [s] and first-order opening time constant [s]."""

    open_area_m2: float
    leak_area_m2: float
    overlap: float
    delay_s: float
    time_constant_s: float

    def __post_init__(self) -> None:
        _check(self, {"open_area_m2": (0.0, 1.0, False),
                      "leak_area_m2": (0.0, self.open_area_m2, True),
                      "overlap": (0.0, 0.9, True), "delay_s": (0.0, 1.0, True),
                      "time_constant_s": (0.0, 1.0, False)})


@dataclass(frozen=True, slots=True)
class Metering:
    """Fixed restrictors [m^2]: one per head branch (A -> head, both directions) and one in
    the release feed P -> B; the rods vent B -> T through the main valve edge alone."""

    head_branch_area_m2: float
    rod_feed_area_m2: float

    def __post_init__(self) -> None:
        _check(self, {"head_branch_area_m2": (0.0, 1.0, False),
                      "rod_feed_area_m2": (0.0, 1.0, False)})


@dataclass(frozen=True, slots=True)
class Lines:
    """Hose volumes [m^3] of line A (its own node) and line B (part of the rod node)."""

    line_a_volume_m3: float
    line_b_volume_m3: float

    def __post_init__(self) -> None:
        _check(self, {"line_a_volume_m3": (0.0, 1.0, False), "line_b_volume_m3": (0.0, 1.0, True)})


@dataclass(frozen=True, slots=True)
class Cylinder:
    """One of the two identical cylinders (per-cylinder values, SI)."""

    area_head_m2: float
    area_rod_m2: float
    stroke_max_m: float
    dead_volume_head_m3: float
    dead_volume_rod_m3: float
    leakage_m3_s_Pa: float
    coulomb_friction_N: float
    coulomb_velocity_m_s: float
    viscous_friction_N_s_m: float
    endstop_stiffness_N_m: float
    endstop_damping_N_s_m: float

    def __post_init__(self) -> None:
        _check(self, {"area_head_m2": (0.0, 1.0, False),
                      "area_rod_m2": (0.0, self.area_head_m2, False),
                      "stroke_max_m": (0.0, 10.0, False),
                      "dead_volume_head_m3": (0.0, 1.0, False),
                      "dead_volume_rod_m3": (0.0, 1.0, False),
                      "leakage_m3_s_Pa": (0.0, 1e-6, True),
                      "coulomb_friction_N": (0.0, 1e6, True),
                      "coulomb_velocity_m_s": (0.0, 1.0, False),
                      "viscous_friction_N_s_m": (0.0, 1e8, True),
                      "endstop_stiffness_N_m": (0.0, 1e12, True),
                      "endstop_damping_N_s_m": (0.0, 1e9, True)})


@dataclass(frozen=True, slots=True)
class Coupling:
    """Strong-coupling numerics: NEPCE correction bound [N], min velocity [m/s], Newton."""

    max_correction_N: float
    min_correction_velocity_m_s: float
    newton_tol_Pa: float
    newton_max_iter: int

    def __post_init__(self) -> None:
        _check(self, {"max_correction_N": (0.0, 1e6, True),
                      "min_correction_velocity_m_s": (0.0, 1.0, False),
                      "newton_tol_Pa": (0.0, 1e5, False), "newton_max_iter": (1, 1000, True)})


@dataclass(frozen=True, slots=True)
class PressureProfile:
    """Piecewise-linear supply pressure p_s(t) [Pa gauge] over times [s]; held at the ends."""

    times_s: tuple[float, ...]
    pressures_Pa: tuple[float, ...]

    def __post_init__(self) -> None:
        t, p = self.times_s, self.pressures_Pa
        if len(t) != len(p) or len(t) == 0:
            raise ValueError("PressureProfile.times_s and pressures_Pa need equal, nonzero length")
        if any(not math.isfinite(x) for x in (*t, *p)):
            raise ValueError("PressureProfile.times_s / pressures_Pa must be finite")
        if any(b <= a for a, b in itertools.pairwise(t)):
            raise ValueError("PressureProfile.times_s must be strictly increasing")
        if any(x < 0.0 for x in p):
            raise ValueError("PressureProfile.pressures_Pa must be in [0, inf)")

    def __call__(self, t_s: float) -> float:
        """Supply pressure [Pa] at time ``t_s`` [s]."""
        t, p = self.times_s, self.pressures_Pa
        if t_s <= t[0]:
            return p[0]
        for i in range(1, len(t)):
            if t_s < t[i]:
                w = (t_s - t[i - 1]) / (t[i] - t[i - 1])
                return p[i - 1] + w * (p[i] - p[i - 1])
        return p[-1]


@dataclass(frozen=True, slots=True)
class HydraulicParams:
    """Every parameter of the tensioning circuit (see models/lf1352_hydraulics.toml)."""

    fluid: Fluid
    orifice: OrificeLaw
    tank_pressure_Pa: float
    cavitation: Cavitation
    supply: Supply
    accumulator: Accumulator
    relief: Relief
    main_valve: Valve
    switching_valves: Valve
    metering: Metering
    lines: Lines
    cylinder: Cylinder
    coupling: Coupling
    profiles: dict[str, PressureProfile]

    def __post_init__(self) -> None:
        _check(self, {"tank_pressure_Pa": (0.0, 1e7, True)})
        if self.cavitation.floor_Pa >= self.tank_pressure_Pa:
            raise ValueError("cavitation.floor_Pa must be below tank_pressure_Pa")


def _build(cls: type, table: dict[str, Any], name: str) -> Any:
    """Construct ``cls`` from a TOML table, ignoring ``source`` and naming missing keys."""
    kwargs = {}
    for f in fields(cls):
        if f.name not in table:
            raise ValueError(f"[{name}] is missing parameter {f.name!r}")
        kwargs[f.name] = table[f.name]
    return cls(**kwargs)


def params_from_dict(data: dict[str, Any]) -> HydraulicParams:
    """Build :class:`HydraulicParams` from a parsed TOML document."""
    try:
        profiles = {
            key: PressureProfile(tuple(map(float, tab["times_s"])),
                                 tuple(map(float, tab["pressures_Pa"])))
            for key, tab in data.get("profiles", {}).items()
        }
        return HydraulicParams(
            fluid=_build(Fluid, data["fluid"], "fluid"),
            orifice=_build(OrificeLaw, data["orifice"], "orifice"),
            tank_pressure_Pa=data["tank"]["pressure_Pa"],
            cavitation=_build(Cavitation, data["cavitation"], "cavitation"),
            supply=_build(Supply, data["supply"], "supply"),
            accumulator=_build(Accumulator, data["accumulator"], "accumulator"),
            relief=_build(Relief, data["relief"], "relief"),
            main_valve=_build(Valve, data["main_valve"], "main_valve"),
            switching_valves=_build(Valve, data["switching_valves"], "switching_valves"),
            metering=_build(Metering, data["metering"], "metering"),
            lines=_build(Lines, data["lines"], "lines"),
            cylinder=_build(Cylinder, data["cylinder"], "cylinder"),
            coupling=_build(Coupling, data["coupling"], "coupling"),
            profiles=profiles,
        )
    except KeyError as exc:
        raise ValueError(f"hydraulic parameter file is missing table/key {exc}") from None


def load_hydraulic_params(path: str | Path | None = None) -> HydraulicParams:
    """Read the hydraulic parameter TOML (default: packaged ``lf1352_hydraulics.toml``)."""
    if path is None:
        text = files("trackmj.models").joinpath("lf1352_hydraulics.toml").read_text("utf-8")
    else:
        text = Path(path).read_text("utf-8")
    return params_from_dict(tomllib.loads(text))
