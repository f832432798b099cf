"""The lumped cylinder of a hydraulic file as the elements without pressures see it: the
travel the physics guard allows and the equivalent pressures their force shows the sensors.
Pressures in Pa gauge, areas in m², lengths in m."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from trackmj.hydraulics.params import HydraulicParams

END_STOP_ALLOWANCE_M = 5e-3
"""End-stop penetration a physical run may reach beyond the cylinder travel [m] (50 kN per
cylinder on the 1e7 N/m stops): beyond it the stops are not holding the stroke."""


def cylinder_travel_m(hydraulics: HydraulicParams) -> tuple[float, float]:
    """The hydraulic file's cylinder travel with the end-stop allowance [m]."""
    return (-END_STOP_ALLOWANCE_M, hydraulics.cylinder.stroke_max_m + END_STOP_ALLOWANCE_M)


def equivalent_cylinder(hydraulics: HydraulicParams) -> tuple[float, float, float]:
    """(lumped head area [m²], lumped rod area [m²], tank pressure [Pa]) of the hydraulic
    file's two cylinders: an element without pressures shows the sensors the equivalent
    head pressure of its force, (F + A_r·p_t)/A_h, and the rods at tank (as dp-b does)."""
    cyl = hydraulics.cylinder
    return 2.0 * cyl.area_head_m2, 2.0 * cyl.area_rod_m2, hydraulics.tank_pressure_Pa


def equivalent_pressures(force_N: float, cylinder: tuple[float, float, float],
                         rod_Pa: float | None = None) -> tuple[float, float]:
    """(head, rod) pressure [Pa gauge] holding ``force_N`` on the lumped ``cylinder`` of
    :func:`equivalent_cylinder`, the rods at ``rod_Pa`` (None: at tank)."""
    area_head, area_rod, tank = cylinder
    rod = tank if rod_Pa is None else rod_Pa
    return (force_N + area_rod * rod) / area_head, rod

