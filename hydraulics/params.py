"""Hydraulic parameters: frozen, validated dataclasses read from a TOML file.

All values SI, pressures gauge [Pa] unless a name ends in ``_abs``. The checks are the one
validator of :mod:`trackmj.validator`: types, ranges and cross-field checks run on
construction, and :func:`load_hydraulic_params` refuses unknown keys, wrong types, missing
keys and missing ``source`` strings naming the file, the table and the key.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, ClassVar, Literal, get_args

from trackmj.validator import Location, Parameters, load_file, param, sources_field

DEFAULT_FILE = "lf1352_hydraulics.toml"


@dataclass(frozen=True, slots=True)
class Fluid(Parameters):
    """Hydraulic oil."""

    density_kg_m3: float = param(0.0, 2e4, open_low=True, doc="oil density")
    bulk_modulus_Pa: float = param(0.0, 1e11, open_low=True,
                                   doc="effective bulk modulus of the oil")
    kinematic_viscosity_m2_s: float = param(0.0, 1.0, open_low=True,
                                            doc="kinematic viscosity (recorded, not used by "
                                            "the turbulent orifice law)")


@dataclass(frozen=True, slots=True)
class OrificeLaw(Parameters):
    """Regularised orifice Q = Cq·A·sqrt(2/ρ)·Δp/(Δp²+p_cr²)^(1/4)."""

    discharge_coefficient: float = param(0.0, 1.0, open_low=True, unit="1",
                                         doc="discharge coefficient Cq")
    critical_pressure_Pa: float = param(0.0, 1e7, open_low=True,
                                        doc="regularisation pressure p_cr; laminar-like below")


@dataclass(frozen=True, slots=True)
class Tank(Parameters):
    """Return line to the tank."""

    pressure_Pa: float = param(0.0, 1e7, doc="tank (return-line back) pressure p_t")


@dataclass(frozen=True, slots=True)
class Cavitation(Parameters):
    """Outflow limiter floor/band, tank->chamber make-up check valves, air released below
    atmospheric (gaseous cavitation)."""

    floor_Pa: float = param(-1e5, 1e7, doc="outflow of a node stops at this pressure")
    band_Pa: float = param(0.0, 1e7, open_low=True,
                           doc="outflow fades from full at floor + band to zero at the floor")
    makeup_crack_below_tank_Pa: float = param(0.0, 1e7,
                                              doc="make-up valve starts opening this far "
                                              "below p_t")
    makeup_full_below_tank_Pa: float = param(0.0, 1e7, open_low=True,
                                             doc="make-up valve fully open this far below p_t")
    makeup_area_m2: float = param(0.0, 1.0, doc="make-up valve full opening area")
    air_fraction: float = param(0.0, 0.2, unit="-",
                                doc="free air per chamber volume out of solution below "
                                    "atmospheric: V_g ≈ α·V·(−p)/p_abs (kernels."
                                    "released_air); 0 lets a chamber go into tension")
    air_onset_band_Pa: float = param(0.0, 1e6, open_low=True,
                                     doc="depth below atmospheric over which the release "
                                         "sets in (V_g and its slope continuous)")

    def cross_check(self, at: Location) -> None:
        if self.makeup_full_below_tank_Pa <= self.makeup_crack_below_tank_Pa:
            raise at.error("makeup_full_below_tank_Pa", self.makeup_full_below_tank_Pa,
                           "must be > makeup_crack_below_tank_Pa = "
                           f"{self.makeup_crack_below_tank_Pa!r}")


SupplyModel = Literal["fixed_relief", "compensated", "unloading", "prescribed"]
"""Supply models (docs/sizing.md): ``fixed_relief`` fixed pump + gas accumulator + relief
(the study's), ``compensated`` pressure-compensated variable pump, ``unloading`` fixed pump
charging the gas accumulator through an unloading valve, ``prescribed`` an ideal pressure
source p_s(t) = p_set(t)."""
SUPPLY_MODELS: tuple[str, ...] = get_args(SupplyModel)


@dataclass(frozen=True, slots=True)
class Supply(Parameters):
    """Supply node and its pressure setting; the supply models' hardware has its own tables."""

    default_model: SupplyModel = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        doc="supply model of a run whose scenario names none (see SupplyModel)")
    setpoint_Pa: float = param(0.0, 1e8, open_low=True,
                               doc="nominal supply pressure setting p_set: the relief setting "
                               "(fixed_relief), the compensator setting (compensated), the "
                               "cut-out pressure (unloading), the pressure (prescribed)")
    line_volume_m3: float = param(0.0, 1.0, open_low=True,
                                  doc="oil volume of the supply node (hose + valve block)")


@dataclass(frozen=True, slots=True)
class FixedPump(Parameters):
    """Fixed-displacement pump (fixed_relief and unloading): constant delivered flow,
    constant efficiencies; shaft power p_out·Q_d/(η_v·η_hm)."""

    flow_m3_s: float = param(0.0, 1.0, open_low=True,
                             doc="delivered flow Q_d (geometric flow × volumetric efficiency)")
    volumetric_efficiency: float = param(0.0, 1.0, open_low=True, unit="1",
                                         doc="η_v = delivered / geometric flow")
    mechanical_efficiency: float = param(0.0, 1.0, open_low=True, unit="1",
                                         doc="hydro-mechanical efficiency η_hm")


@dataclass(frozen=True, slots=True)
class VariablePump(Parameters):
    """Pressure-compensated variable pump (compensated): displacement x ∈ [0, 1] follows
    x* = clip((p_set − p_s)/droop, 0, 1) with a first-order lag; delivery
    Q = Q_g,max·x − k_L·p_s with the laminar leakage k_L = standby flow / p_set; shaft power
    p_s·Q_g,max·x/η_hm."""

    max_flow_m3_s: float = param(0.0, 1.0, open_low=True,
                                 doc="geometric flow at full displacement Q_g,max")
    droop_Pa: float = param(0.0, 1e7, open_low=True,
                            doc="compensator regulation range: full displacement at "
                            "p_set − droop, zero at p_set")
    time_constant_s: float = param(0.0, 1.0, open_low=True,
                                   doc="first-order lag of the displacement")
    standby_flow_m3_s: float = param(0.0, 1.0,
                                     doc="internal leakage at p_set the compensator strokes "
                                     "for with no demand (standby)")
    mechanical_efficiency: float = param(0.0, 1.0, open_low=True, unit="1",
                                         doc="hydro-mechanical efficiency η_hm")

    def cross_check(self, at: Location) -> None:
        if self.standby_flow_m3_s >= self.max_flow_m3_s:
            raise at.error("standby_flow_m3_s", self.standby_flow_m3_s,
                           f"must be < max_flow_m3_s = {self.max_flow_m3_s!r}")


@dataclass(frozen=True, slots=True)
class UnloadingValve(Parameters):
    """Accumulator charging (unloading) valve (unloading): the fixed pump charges the
    accumulator until p_s reaches the cut-out p_set, then circulates to tank at
    unloaded_pressure_Pa until p_s falls to the cut-in (1 − differential_rel)·p_set."""

    differential_rel: float = param(0.0, 0.5, open_low=True, unit="1",
                                    doc="cut-in below the cut-out, relative to the cut-out")
    unloaded_pressure_Pa: float = param(0.0, 1e7,
                                        doc="pump outlet pressure while unloaded (return "
                                        "line + open unloading valve)")


@dataclass(frozen=True, slots=True)
class Accumulator(Parameters):
    """Gas accumulator on the supply node (polytropic gas law)."""

    gas_volume_m3: float = param(0.0, 1.0, open_low=True, doc="gas volume at precharge")
    precharge_Pa: float = param(0.0, 1e8, open_low=True, doc="gas precharge pressure (gauge)")
    polytropic_exponent: float = param(1.0, 1.67, open_low=True, unit="1",
                                       doc="polytropic exponent n of p·V^n = const")
    atmospheric_pressure_Pa_abs: float = param(0.0, 2e5, open_low=True,
                                               doc="converts gauge to absolute for the gas law")


@dataclass(frozen=True, slots=True)
class Relief(Parameters):
    """Relief valve supply -> tank: cracks at the set-point with fixed_relief (the pressure
    regulator) and safety_margin_rel above the initial set-point otherwise (a safety valve);
    fully open band_Pa above its crack pressure."""

    band_Pa: float = param(0.0, 1e7, open_low=True,
                           doc="pressure rise from cracking to fully open")
    full_area_m2: float = param(0.0, 1.0, doc="opening area when fully open")
    safety_margin_rel: float = param(0.0, 1.0, open_low=True, unit="1",
                                     doc="safety relief's crack above the set-point "
                                     "(compensated, unloading), relative to it")


@dataclass(frozen=True, slots=True)
class Valve(Parameters):
    """Solenoid valve: edge areas, overlap, delay and opening lag."""

    open_area_m2: float = param(0.0, 1.0, open_low=True, doc="area of an open edge")
    leak_area_m2: float = param(0.0, 1.0, doc="leak area of a closed edge")
    overlap: float = param(0.0, 0.9, unit="1",
                           doc="fraction of the spool travel before an edge opens")
    delay_s: float = param(0.0, 1.0, doc="pure electromagnetic delay")
    time_constant_s: float = param(0.0, 1.0, open_low=True, doc="first-order opening lag")

    def cross_check(self, at: Location) -> None:
        if self.leak_area_m2 > self.open_area_m2:
            raise at.error("leak_area_m2", self.leak_area_m2,
                           f"must be <= open_area_m2 = {self.open_area_m2!r}")


@dataclass(frozen=True, slots=True)
class Metering(Parameters):
    """Fixed restrictors: one per head branch (A -> head, both directions) and one in the
    release feed P -> B; the rods vent B -> T through the main valve edge alone."""

    head_branch_area_m2: float = param(0.0, 1.0, open_low=True,
                                       doc="restrictor in each head branch, in series with "
                                       "its 2/2 valve")
    rod_feed_area_m2: float = param(0.0, 1.0, open_low=True,
                                    doc="restrictor in the release feed P -> B, in series "
                                    "with the main valve's P -> B edge")


@dataclass(frozen=True, slots=True)
class Lines(Parameters):
    """Hose volumes of line A (its own node) and line B (part of the rod node)."""

    line_a_volume_m3: float = param(0.0, 1.0, open_low=True, doc="line A oil volume")
    line_b_volume_m3: float = param(0.0, 1.0, doc="line B oil volume (in the rod node)")


@dataclass(frozen=True, slots=True)
class Cylinder(Parameters):
    """One of the two identical cylinders (per-cylinder values)."""

    area_head_m2: float = param(0.0, 1.0, open_low=True, doc="piston (head side) area")
    area_rod_m2: float = param(0.0, 1.0, open_low=True, doc="annulus (rod side) area")
    stroke_max_m: float = param(0.0, 10.0, open_low=True, doc="stroke between the end stops")
    dead_volume_head_m3: float = param(0.0, 1.0, open_low=True,
                                       doc="head node volume at zero stroke incl. hose "
                                       "compliance")
    dead_volume_rod_m3: float = param(0.0, 1.0, open_low=True,
                                      doc="rod chamber volume at full stroke")
    leakage_m3_s_Pa: float = param(0.0, 1e-6, doc="laminar piston-seal leakage head -> rod")
    coulomb_friction_N: float = param(0.0, 1e6, doc="Coulomb seal friction")
    coulomb_velocity_m_s: float = param(0.0, 1.0, open_low=True,
                                        doc="tanh smoothing velocity of the Coulomb friction")
    viscous_friction_N_s_m: float = param(0.0, 1e8, doc="viscous friction coefficient")
    endstop_stiffness_N_m: float = param(0.0, 1e12, doc="end-stop contact stiffness")
    endstop_damping_N_s_m: float = param(0.0, 1e9, doc="end-stop contact damping")

    def cross_check(self, at: Location) -> None:
        if self.area_rod_m2 >= self.area_head_m2:
            raise at.error("area_rod_m2", self.area_rod_m2,
                           f"must be < area_head_m2 = {self.area_head_m2!r}")


@dataclass(frozen=True, slots=True)
class Coupling(Parameters):
    """Strong-coupling numerics: NEPCE correction bound, min velocity, Newton settings."""

    max_correction_N: float = param(0.0, 1e6, doc="bound on the NEPCE correction force")
    min_correction_velocity_m_s: float = param(0.0, 1.0, open_low=True,
                                               doc="no correction below this |v|")
    newton_tol_Pa: float = param(0.0, 1e5, open_low=True, doc="Newton pressure tolerance")
    newton_max_iter: int = param(1, 1000, doc="Newton iteration limit")


@dataclass(frozen=True, slots=True)
class PressureProfile(Parameters):
    """Piecewise-linear supply set-point p_set(t) [Pa gauge] over times [s]; held at the ends
    (built from a scenario's set-point changes, see ``trackmj.scenarios.resolved``)."""

    times_s: tuple[float, ...] = param(0.0, None, doc="breakpoints, strictly increasing")
    pressures_Pa: tuple[float, ...] = param(0.0, None, doc="pressure at each breakpoint")

    def cross_check(self, at: Location) -> None:
        t, p = self.times_s, self.pressures_Pa
        if len(t) != len(p):
            raise at.error("pressures_Pa", p, f"has {len(p)} entries, times_s has {len(t)}")
        for i, (a, b) in enumerate(itertools.pairwise(t)):
            if b <= a:
                raise at.error(("times_s", i + 1), b, f"must be > times_s[{i}] = {a!r} "
                               "(strictly increasing)")

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
class HydraulicParams(Parameters):
    """Every parameter of the tensioning circuit (see models/lf1352_hydraulics.toml);
    ``sources`` maps each table to its ``source``."""

    fluid: Fluid
    orifice: OrificeLaw
    tank: Tank
    cavitation: Cavitation
    supply: Supply
    fixed_pump: FixedPump
    variable_pump: VariablePump
    unloading_valve: UnloadingValve
    accumulator: Accumulator
    relief: Relief
    main_valve: Valve
    switching_valves: Valve
    metering: Metering
    lines: Lines
    cylinder: Cylinder
    coupling: Coupling
    sources: Mapping[str, str] = sources_field()

    file_kind: ClassVar[str] = "hydraulics"

    @property
    def tank_pressure_Pa(self) -> float:
        """Tank pressure p_t [Pa gauge]."""
        return self.tank.pressure_Pa

    def cut_in_Pa(self, setpoint_Pa: float) -> float:
        """Unloading valve's cut-in pressure [Pa] at cut-out ``setpoint_Pa`` [Pa]."""
        return (1.0 - self.unloading_valve.differential_rel) * setpoint_Pa

    def cross_check(self, at: Location) -> None:
        if self.cavitation.floor_Pa >= self.tank.pressure_Pa:
            raise at.error(("cavitation", "floor_Pa"), self.cavitation.floor_Pa,
                           f"must be below [tank].pressure_Pa = {self.tank.pressure_Pa!r}")
        if self.unloading_valve.unloaded_pressure_Pa < self.tank.pressure_Pa:
            raise at.error(("unloading_valve", "unloaded_pressure_Pa"),
                           self.unloading_valve.unloaded_pressure_Pa,
                           f"must be >= [tank].pressure_Pa = {self.tank.pressure_Pa!r} (the "
                           "unloaded pump flow returns through the tank line)")


def default_path() -> Path:
    """The packaged ``lf1352_hydraulics.toml``."""
    return Path(str(files("trackmj.models").joinpath(DEFAULT_FILE)))


def load_hydraulic_params(path: str | Path | None = None,
                          overrides: Mapping[str, Any] | None = None) -> HydraulicParams:
    """Read and validate the hydraulic parameter TOML.

    Parameters
    ----------
    path : str or Path, optional
        The file; default the packaged ``lf1352_hydraulics.toml``.
    overrides : mapping, optional
        ``{dotted key: value}``, the ``hydraulics`` entry of
        :func:`trackmj.validator.parse_overrides`.

    Returns
    -------
    HydraulicParams
    """
    return load_file(HydraulicParams, default_path() if path is None else path,
                     overrides=overrides)
