"""The controller's reduced plant, derived from the hydraulic file and the identified idler.

The reduced model (:class:`~trackmj.control.params.PlantParams`) has no file of its own:
:func:`reduced_plant_params` lumps the two cylinders of the hydraulic parameters into one,
puts each valve edge in series with its restrictor, adds line B to the rod node, takes
k, M, c from the equivalent idler identified on the MuJoCo track
(:mod:`trackmj.machines.idler`) and the drive torque's idler load from the machine's layout
(:mod:`trackmj.machines.drive_load`).
"""

from __future__ import annotations

from trackmj.control.params import ControlConfig, PlantParams, load_config
from trackmj.hydraulics.components import series_area
from trackmj.hydraulics.params import HydraulicParams, load_hydraulic_params
from trackmj.machines.drive_load import DriveLoad, drive_load
from trackmj.machines.idler import EquivalentIdler, load_idler
from trackmj.track.mechanics import load_model_params

NOMINAL_FORCE_N = 15e3
"""Operating point of :func:`nominal_plant_params`: the reference tension of W2-W5 [N]..."""
NOMINAL_SUPPLY_PA = 12e6
"""... at the study's simulation supply pressure [Pa], with the force at mid stroke."""


def packaged_control(overrides: dict[str, object] | None = None) -> ControlConfig:
    """The packaged control file with the values derived from the packaged machine's nominal
    tension (``models/lf1352.toml`` [tensioner].nominal_tension_N)."""
    return load_config(overrides=overrides,
                       nominal_tension_N=load_model_params().nominal_tension_N)


def reduced_plant_params(hydraulics: HydraulicParams, idler: EquivalentIdler,
                         control_config: ControlConfig, *, supply_pressure_Pa: float,
                         free_position_m: float, drive: DriveLoad) -> PlantParams:
    """The controller's reduced model from the hydraulic circuit and the equivalent idler.

    The two identical cylinders act as one with twice the areas, volumes and seal leakage;
    line B belongs to the rod node. Each full-opening path area is its valve edge in series
    with its restrictor (turbulent orifices: A = (A1^-2 + A2^-2)^-1/2): the head path is the
    two branches (2/2 valve + head restrictor) in parallel, the rod path the main valve's
    P -> B edge with the release-feed restrictor. The rod vent and the opening smoothing are
    the control file's own (``[reduced_model]``).

    Parameters
    ----------
    hydraulics : HydraulicParams
        The plugin's circuit (per-cylinder values).
    idler : EquivalentIdler
        k [N/m], M [kg], c [N·s/m] of the idler seen by the stroke.
    control_config : ControlConfig
        Supplies ``reduced_model.vent_area_rod_m2`` and ``opening_smoothing``.
    supply_pressure_Pa : float
        Nominal supply pressure of the model [Pa gauge].
    free_position_m : float
        Stroke y0 [m] at which the idler spring is unloaded.
    drive : DriveLoad
        The idler load of the sprocket torque (gain [1/m] and the tight side's sign).

    Returns
    -------
    PlantParams
    """
    cyl, met, own = hydraulics.cylinder, hydraulics.metering, control_config.reduced_model
    return PlantParams(
        area_head_m2=2.0 * cyl.area_head_m2,
        area_rod_m2=2.0 * cyl.area_rod_m2,
        stroke_m=cyl.stroke_max_m,
        dead_volume_head_m3=2.0 * cyl.dead_volume_head_m3,
        dead_volume_rod_m3=2.0 * cyl.dead_volume_rod_m3 + hydraulics.lines.line_b_volume_m3,
        bulk_modulus_Pa=hydraulics.fluid.bulk_modulus_Pa,
        density_kg_m3=hydraulics.fluid.density_kg_m3,
        discharge_coefficient=hydraulics.orifice.discharge_coefficient,
        valve_area_head_m2=2.0 * series_area(hydraulics.switching_valves.open_area_m2,
                                             met.head_branch_area_m2),
        valve_area_rod_m2=series_area(hydraulics.main_valve.open_area_m2, met.rod_feed_area_m2),
        vent_area_rod_m2=own.vent_area_rod_m2,
        critical_pressure_Pa=hydraulics.orifice.critical_pressure_Pa,
        opening_smoothing=own.opening_smoothing,
        supply_pressure_Pa=supply_pressure_Pa,
        tank_pressure_Pa=hydraulics.tank_pressure_Pa,
        leakage_m3_s_Pa=2.0 * cyl.leakage_m3_s_Pa,
        mass_kg=idler.mass_kg,
        stiffness_N_m=idler.stiffness_N_m,
        damping_N_s_m=idler.damping_N_s_m,
        free_position_m=free_position_m,
        drive_load_gain_1_m=drive.gain_1_m,
        drive_tight_sign=drive.tight_sign,
    )


def nominal_plant_params(hydraulics: HydraulicParams | None = None,
                         idler: EquivalentIdler | None = None,
                         control_config: ControlConfig | None = None, *,
                         force_N: float = NOMINAL_FORCE_N,
                         supply_pressure_Pa: float = NOMINAL_SUPPLY_PA) -> PlantParams:
    """The reduced plant of the packaged files at an operating point: ``force_N`` [N] at mid
    stroke (y0 = stroke_max/2 − F/k) and ``supply_pressure_Pa`` [Pa]; defaults 15 kN and
    12 MPa; the drive load of the packaged machine's layout. The control unit tests run on
    it; a coupled run sets y0 from the settled track.

    Parameters
    ----------
    hydraulics, idler, control_config : optional
        Default: the packaged hydraulic file, idler file and control file.
    force_N : float
        Idler force at mid stroke [N].
    supply_pressure_Pa : float
        Supply pressure [Pa gauge].

    Returns
    -------
    PlantParams
    """
    hydraulics = load_hydraulic_params() if hydraulics is None else hydraulics
    idler = load_idler() if idler is None else idler
    control_config = packaged_control() if control_config is None else control_config
    y0 = 0.5 * hydraulics.cylinder.stroke_max_m - force_N / idler.stiffness_N_m
    return reduced_plant_params(hydraulics, idler, control_config,
                                supply_pressure_Pa=supply_pressure_Pa, free_position_m=y0,
                                drive=drive_load(load_model_params()))
