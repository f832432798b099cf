"""Sizing rules of a machine's tensioner and controller (pure functions, SI, gauge Pa).

The formulas and the reasons for each constant are in ``docs/sizing.md`` ("Sizing a
machine's tensioner" and "Machines"). Every shipped machine's hydraulic file takes its bore,
rod and metering areas from here (their ``source`` says so), and a run derives the
machine-dependent controller values from the machine's nominal tension (tension band,
governor margin, PID bands: ``trackmj.control.params.DERIVED``) and its plant (MPC input
weights: :func:`input_weight_scale`).

Nothing here reads a file: the callers pass the values (:mod:`trackmj.sim.setup`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

ISO_3320_BORES_M = tuple(d * 1e-3 for d in (
    8, 10, 12, 16, 20, 25, 32, 40, 50, 63, 80, 100, 125, 140, 160, 180, 200, 220, 250, 280,
    320, 360, 400))
"""Cylinder bores of ISO 3320 (fluid power cylinders, bores and rod diameters) [m]."""
ISO_3320_RODS_M = tuple(d * 1e-3 for d in (
    4, 5, 6, 8, 10, 12, 14, 16, 18, 20, 22, 25, 28, 32, 36, 40, 45, 50, 56, 63, 70, 80, 90,
    100, 110, 125, 140, 160, 180, 200, 220, 250, 280, 320, 360))
"""Piston-rod diameters of ISO 3320 [m]."""
AREA_RATIO = 1.6
"""Head over annulus area phi of the ISO 7181 series (1.25, 1.4, 1.6, 2, 2.5) chosen."""
VALVE_DROP_PA = 1.0e6
"""Pressure drop Δp_v [Pa] the sizing leaves across the metering at the band's top: a
design margin for the tension rate there (docs/sizing.md; the governor's ceiling leaves
0.5 MPa)."""
CYLINDER_COUNT = 2
"""Identical tensioner cylinders acting in parallel (a hydraulic file's [cylinder] is one)."""
PULSE_REL = 0.0075
"""Tension change of one minimum-hold pulse at full pressurizing opening over the nominal
tension, the metering the shipped machines are sized for (LF1352's restrictors give
0.74 %: 3.71 kN/s × 30 ms at 15 kN and 12 MPa)."""


@dataclass(frozen=True)
class CylinderSize:
    """Standard bore and rod of one cylinder [m] and their areas [m²]."""

    bore_m: float
    rod_m: float

    @property
    def area_head_m2(self) -> float:
        return math.pi * self.bore_m ** 2 / 4.0

    @property
    def area_rod_m2(self) -> float:
        """Annulus area on the rod side."""
        return math.pi * (self.bore_m ** 2 - self.rod_m ** 2) / 4.0


def holding_force_N(area_head_m2: float, area_rod_m2: float, supply_Pa: float,
                    tank_Pa: float, valve_drop_Pa: float = VALVE_DROP_PA,
                    count: int = CYLINDER_COUNT) -> float:
    """Force [N] of ``count`` cylinders in parallel (per-cylinder head area ``area_head_m2``
    and annulus ``area_rod_m2`` [m²]) with the heads at the supply less the valve drop and
    the rods at tank: count·(A_h·(p_s − Δp_v) − A_r·p_t), pressures gauge [Pa]."""
    return count * (area_head_m2 * (supply_Pa - valve_drop_Pa) - area_rod_m2 * tank_Pa)


def size_cylinders(force_N: float, supply_Pa: float, tank_Pa: float, valve_drop_Pa: float,
                   count: int = CYLINDER_COUNT) -> CylinderSize:
    """Smallest ISO 3320 bore of which ``count`` cylinders in parallel hold ``force_N`` [N]
    with the supply ``supply_Pa`` less ``valve_drop_Pa`` in the heads and the rods at tank:
    count·(A_h·(p_s − Δp_v) − A_r·p_t) >= F, A_r = A_h/φ; the rod is the ISO 3320 rod
    nearest to d·sqrt(1 − 1/φ) (φ = :data:`AREA_RATIO`)."""
    head_pressure = supply_Pa - valve_drop_Pa - tank_Pa / AREA_RATIO
    if head_pressure <= 0.0:
        raise ValueError(f"supply {supply_Pa:g} Pa leaves no head pressure after the valve "
                         f"drop {valve_drop_Pa:g} Pa")
    needed = force_N / (count * head_pressure)
    for bore in ISO_3320_BORES_M:
        if math.pi * bore ** 2 / 4.0 >= needed:
            ideal_rod = bore * math.sqrt(1.0 - 1.0 / AREA_RATIO)
            rod = min(ISO_3320_RODS_M, key=lambda d: abs(d - ideal_rod))
            return CylinderSize(bore, rod)
    raise ValueError(f"{force_N:g} N needs a bore above {ISO_3320_BORES_M[-1]:g} m")


def oil_stiffness_N_m(area_head_m2: float, volume_head_m3: float, bulk_modulus_Pa: float) -> float:
    """Stiffness of the trapped head oil seen by the stroke, β·A_h²/V_h [N/m]."""
    return bulk_modulus_Pa * area_head_m2 ** 2 / volume_head_m3


def orifice_velocity_m_s(dp_Pa: float, density_kg_m3: float, critical_pressure_Pa: float) -> float:
    """sqrt(2/ρ)·Δp/(Δp² + p_cr²)^¼ [m/s]: the regularised turbulent law per unit Cq·A."""
    return math.sqrt(2.0 / density_kg_m3) * dp_Pa / (dp_Pa ** 2 + critical_pressure_Pa ** 2) ** 0.25


def head_path_area_m2(rate_N_s: float, *, force_N: float, area_head_m2: float,
                      area_rod_m2: float, volume_head_m3: float, idler_stiffness_N_m: float,
                      supply_Pa: float, tank_Pa: float, bulk_modulus_Pa: float,
                      density_kg_m3: float, discharge_coefficient: float,
                      critical_pressure_Pa: float) -> float:
    """Full-opening head path area [m²] (all cylinders together) that pressurizes at
    ``rate_N_s`` [N/s] at tension ``force_N`` [N], quasi-statically: the head flow
    Q = Cq·A·v(p_s − p_h), p_h = (F + A_r·p_t)/A_h, goes into stroke against the idler and
    into compression, dF/dt = k·Q/(A_h + V_h·k/(β·A_h)). Areas and volumes are the lumped
    cylinders' (head node volume at the operating stroke)."""
    head = (force_N + area_rod_m2 * tank_Pa) / area_head_m2
    flow = rate_N_s * (area_head_m2 + volume_head_m3 * idler_stiffness_N_m
                       / (bulk_modulus_Pa * area_head_m2)) / idler_stiffness_N_m
    return flow / (discharge_coefficient
                   * orifice_velocity_m_s(supply_Pa - head, density_kg_m3, critical_pressure_Pa))


def restrictor_for(path_area_m2: float, valve_area_m2: float) -> float:
    """Restrictor area [m²] that in series with a valve edge of ``valve_area_m2`` gives
    ``path_area_m2`` (inverse of A = (A_v^-2 + A_r^-2)^-1/2)."""
    if not 0.0 < path_area_m2 < valve_area_m2:
        raise ValueError("the path area must be positive and below the valve's")
    return 1.0 / math.sqrt(path_area_m2 ** -2 - valve_area_m2 ** -2)


def input_weight_scale(rate_N_s: float, reference_rate_N_s: float) -> float:
    """Factor (g/g_ref)² on the MPC's u and u-rate weights: the MPC trades (e/kN)² against
    w_u·u², and a unit of u moves the tension at the tension-rate gain g [N/s], so the same
    trade-off on another plant needs w_u scaled by g² (docs/sizing.md)."""
    return (rate_N_s / reference_rate_N_s) ** 2
