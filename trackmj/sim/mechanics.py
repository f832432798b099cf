"""The mechanics of an architecture (:data:`trackmj.sim.registry.MECHANICS`), each built from
the run's setup: the MuJoCo track settled under the initial force, or dp-a's equivalent
idler loaded by a tp run's track load. Stroke y [m] outward positive, forces [N]."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import mujoco

from trackmj.elements.prescribed import ConstantForce
from trackmj.ports import Mechanics
from trackmj.results.store import Result
from trackmj.sim.loop_plants import EquivalentIdlerMechanics
from trackmj.track.plant import PlantSnapshot, TrackPlant

if TYPE_CHECKING:
    from trackmj.machines.idler import EquivalentIdler
    from trackmj.track.mechanics import ModelParams

SETTLE_S = 1.0
"""Standing settle under the initial reference force before t = 0 [s]."""
SETTLE_DAMPING_N_S_M = 2e4
"""Implicit damping of the settling load [N·s/m]: brings the track to rest in the settle."""


class MechanicsSetup(Protocol):
    """What a mechanics builder reads of the run (:class:`trackmj.sim.setup.RunSetup` is
    one): the mechanics file, the equivalent idler, the initial force [N], the run's length
    [s] and steps, the MJCF of its track on its terrain and the contact-stiffness scale of
    its variant [-]."""

    @property
    def model(self) -> ModelParams: ...
    @property
    def idler(self) -> EquivalentIdler: ...
    @property
    def force0_N(self) -> float: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @property
    def contact_stiffness_scale(self) -> float: ...
    def track_mjcf(self) -> str: ...


@dataclass(frozen=True)
class BuiltMechanics:
    """What a mechanics builder returns: the ``ports.Mechanics``, the MuJoCo track (None
    without one) and the free position y0 [m] of the equivalent idler spring (where the
    controller's reduced model puts zero force)."""

    mechanics: Mechanics
    track: TrackPlant | None
    free_position_m: float


SETTLED_KEPT = 4
"""Settled track states kept per process (see :func:`settled_track`)."""
_settled: dict[tuple, PlantSnapshot] = {}


def settled_track(setup: MechanicsSetup, force_N: float) -> TrackPlant:
    """The track of the run (terrain of the seed, W5 contact scale), settled standing under
    ``force_N`` [N] on the idler for SETTLE_S, with its clock and slack window reset.

    The settled state is kept per process for the same MJCF, contact scale, force and model
    parameters (runs that differ only in hydraulics, control, controller, or the seed on
    flat ground): a later run restores it (:meth:`TrackPlant.snapshot`: every MjData
    buffer, the tensioner's bias parameters, the ground's shear displacements and contact
    history, the last force law, the parking brake) instead of settling again, bit for bit
    the same."""
    text = setup.track_mjcf()
    plant = TrackPlant(mujoco.MjModel.from_xml_string(text), setup.model)
    scale = setup.contact_stiffness_scale
    if scale != 1.0:
        plant.scale_contact_stiffness(scale)
    key = (hashlib.sha256(text.encode()).digest(), scale, force_N, setup.model)
    kept = _settled.get(key)
    if kept is None:
        plant.run(ConstantForce(force_N, SETTLE_DAMPING_N_S_M), SETTLE_S)
        if len(_settled) >= SETTLED_KEPT:
            del _settled[next(iter(_settled))]
        _settled[key] = plant.snapshot()
    else:
        plant.restore(kept)
    plant.time_s = 0.0
    plant.clear_slack_window()   # as its clock: settled afresh or restored, the same run
    return plant


def settled_end_stop(track: TrackPlant) -> dict[str, Any] | None:
    """The end stop the settled track's idler carrier rests on at t = 0 (``stop``:
    "retracted" or "extended", the carrier's ``stroke_m`` and the stop's ``stop_stroke_m``
    [m]), None when it rests between them (the tensioner holds the idler)."""
    stop = track.end_stop()
    if stop is None:
        return None
    retracted, extended = track.stroke_stops_m
    return {"stop": stop, "stroke_m": track.stroke_m,
            "stop_stroke_m": retracted if stop == "retracted" else extended}


def build_track(setup: MechanicsSetup) -> BuiltMechanics:
    """The MuJoCo track of the run, settled under the initial force; its equivalent spring is
    free at the settled stroke less force0 / k."""
    track = settled_track(setup, setup.force0_N)
    return BuiltMechanics(track, track,
                          track.stroke_m - setup.force0_N / setup.idler.stiffness_N_m)


def build_equivalent_idler(setup: MechanicsSetup, tp_result: Result) -> BuiltMechanics:
    """dp-a's mechanics: the equivalent idler loaded by ``tp_result``'s track load."""
    idler = setup.idler
    cols = tp_result.columns()
    if len(cols["t_s"]) < setup.steps:
        raise ValueError(f"dp-a needs a tp run at least {setup.duration_s:g} s long, got "
                         f"{cols['t_s'][-1]:g} s")
    stroke_tp = cols["stroke_m"]
    y0 = float(stroke_tp[0] - cols["tension_N"][0] / idler.stiffness_N_m)
    # the load acting over step k is the one the tp run had at the end of step k
    load = (cols["tension_N"] - idler.stiffness_N_m * (stroke_tp - y0)
            - idler.damping_N_s_m * cols["stroke_velocity_m_s"])
    return BuiltMechanics(EquivalentIdlerMechanics(idler, y0, float(stroke_tp[0]), load),
                          None, y0)
