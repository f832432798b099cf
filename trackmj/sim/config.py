"""The controller's reduced plant derived from the hydraulic parameters and the identified
equivalent idler (temporary: replaced by the validator branch's version at merge)."""

from __future__ import annotations

import functools

from trackmj.control.params import ControlConfig, PlantParams
from trackmj.hydraulics import HydraulicParams
from trackmj.hydraulics.components import series_area
from trackmj.identify import EquivalentIdler, identify_idler


@functools.cache
def load_idler() -> EquivalentIdler:
    """Equivalent idler dynamics of the packaged track (identified once per process)."""
    from trackmj.plant import TrackPlant

    return identify_idler(TrackPlant.load)


def reduced_plant_params(hydraulics: HydraulicParams, idler: EquivalentIdler,
                         control: ControlConfig, *, supply_pressure_Pa: float,
                         free_position_m: float) -> PlantParams:
    """The reduced model's plant: the plugin's cylinders lumped, the valve and restrictor
    paths in series, the line-B hose in the rod node, and the identified idler."""
    hyd = hydraulics
    cyl, met = hyd.cylinder, hyd.metering
    head_path = 2.0 * series_area(hyd.switching_valves.open_area_m2, met.head_branch_area_m2)
    rod_path = series_area(hyd.main_valve.open_area_m2, met.rod_feed_area_m2)
    return control.plant.replace(
        area_head_m2=2.0 * cyl.area_head_m2, area_rod_m2=2.0 * cyl.area_rod_m2,
        dead_volume_head_m3=2.0 * cyl.dead_volume_head_m3,
        dead_volume_rod_m3=2.0 * cyl.dead_volume_rod_m3 + hyd.lines.line_b_volume_m3,
        valve_area_head_m2=head_path, valve_area_rod_m2=rod_path,
        bulk_modulus_Pa=hyd.fluid.bulk_modulus_Pa, supply_pressure_Pa=supply_pressure_Pa,
        tank_pressure_Pa=hyd.tank_pressure_Pa, stiffness_N_m=idler.stiffness_N_m,
        mass_kg=idler.mass_kg, damping_N_s_m=idler.damping_N_s_m,
        free_position_m=free_position_m)
