"""Coupling architectures: an architecture is mechanics × element
(:data:`trackmj.sim.registry.ARCHITECTURES`); :func:`assemble` builds the plant of one run
from its setup, the mechanics from :data:`~trackmj.sim.registry.MECHANICS` and the element
from :data:`~trackmj.sim.registry.ELEMENTS`.

Same controller, weights, horizons, steps and references in all:

* ``tp``: MuJoCo track + hydraulic plugin, strong coupling (affine law, implicit dF/dv).
* ``tp-weak``: the same with the weak coupling (force of the previous step held, no dF/dv).
* ``dp-a``: hydraulics + control on the equivalent idler mass-spring-damper identified from
  the track (:mod:`trackmj.machines.identify`); the track's load is replayed from a ``tp``
  run of the same condition and seed as the part of the tp tension the equivalent spring
  does not explain, d(t) = F_tp − k(y_tp − y0) − c·ẏ_tp. The coupling is one-way.
* ``dp-b``: MuJoCo track + control; the hydraulics replaced by an ideal force source: the
  valve mode integrates a force command at the hydraulic tension-rate gain, applied through
  a first-order lag (a quarter period of the oil column) with the cylinders' viscous
  damping; no pressures (sensors see the equivalent head pressure), no supply limit.

The solenoid delay lives in the hydraulic plugin (tp, tp-weak, dp-a); the valve logic then
runs without its own delay so the delay is not counted twice (dp-b has no solenoid).

W3's load pulses enter physically: a load on the rear hitch (a towed or pushing load along a
chain below the horizontal) while the sprocket servo holds the track speed, so the track
sees sprocket drive/brake torque pulses and a pitch load (:mod:`trackmj.sim.w3_hitch`);
dp-a sees them through the replayed tp track load.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from trackmj.control.model import ReducedModel
from trackmj.control.params import ControlConfig
from trackmj.elements.context import ElementContext
from trackmj.machines.drive_load import drive_load
from trackmj.ports import Element, Mechanics
from trackmj.results.store import Result
from trackmj.sim.control_plant import reduced_plant_params
from trackmj.sim.loop_plants import CoupledPlant
from trackmj.sim.registry import ARCHITECTURES, ELEMENTS, MECHANICS
from trackmj.sim.setup import RunSetup
from trackmj.track.plant import TrackPlant

if TYPE_CHECKING:
    from trackmj.sim.mechanics import MechanicsSetup

    # A run's setup is what mechanics builders read (their registry entries are untyped
    # callables, so the type checker checks the protocol here).
    _SETUP_BUILDS_MECHANICS: type[MechanicsSetup] = RunSetup


@dataclass
class Assembly:
    """One run's plant and the controller's view of it.

    plant: the ``ports.Plant`` of the loop; mechanics, element: its parts; track: the MuJoCo
    plant (None for dp-a); control: the control configuration of the run (plant derived from
    the hydraulics and the idler); model: the reduced prediction model; initial_estimate:
    (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s]) the estimator starts from.
    """

    plant: CoupledPlant
    mechanics: Mechanics
    element: Element
    track: TrackPlant | None
    control: ControlConfig
    model: ReducedModel
    initial_estimate: NDArray[np.float64]


def assemble(setup: RunSetup, tp_result: Result | None = None) -> Assembly:
    """The run's plant: its architecture's mechanics (given what the mechanics declares it
    needs, e.g. dp-a's ``tp_result``), the control configuration on the mechanics' free
    position, and the run's element (``setup.element``) on the mechanics' stroke."""
    arch = ARCHITECTURES[setup.architecture]
    entry = MECHANICS[arch.mechanics]
    available = {"tp_result": tp_result}
    built = entry.build(setup, **{name: available[name] for name in entry.needs})
    cfg, model = control_and_model(setup, built.free_position_m)
    stroke = built.mechanics.stroke_m
    element = ELEMENTS[setup.element].build(
        ElementContext(setup, stroke, model, arch.coupling, setup.tensioner))
    return Assembly(CoupledPlant(built.mechanics, element), built.mechanics, element,
                    built.track, cfg, model, _estimate0(setup, stroke))


def control_and_model(setup: RunSetup, free_position_m: float
                      ) -> tuple[ControlConfig, ReducedModel]:
    """Control configuration with the reduced plant derived from the hydraulics, the
    identified idler and the layout's drive load, valve logic without its own solenoid
    delay (the plugin applies it), and no wall-clock budget (every finished solve is
    applied; overruns are counted)."""
    cfg = setup.control
    plant = reduced_plant_params(setup.hydraulics, setup.idler, cfg,
                                 supply_pressure_Pa=setup.supply0_Pa,
                                 free_position_m=free_position_m,
                                 drive=drive_load(setup.model))
    cfg = dataclasses.replace(
        cfg, valves=dataclasses.replace(cfg.valves, solenoid_delay_s=0.0),
        mpc=dataclasses.replace(cfg.mpc, time_budget_s=10.0))
    return cfg, ReducedModel(plant)


def _estimate0(setup: RunSetup, stroke_m: float) -> NDArray[np.float64]:
    """Initial estimate: at rest, heads at the pressure of the initial force, rods at tank
    (the state both the plugin and the ideal force source start from)."""
    return np.array((setup.head_pressure0_Pa, setup.hydraulics.tank_pressure_Pa, stroke_m, 0.0))
