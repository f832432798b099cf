"""One run of a report or a comparison: its directory name, its scenario's events moved
inside a shorter run, and the tensioner file its architecture takes."""

from __future__ import annotations

from trackmj.scenarios.events import moved_events
from trackmj.scenarios.load import load_scenario
from trackmj.sim.registry import ARCHITECTURES, REPLACEABLE_ELEMENT


def run_name(scenario: str, architecture: str, controller: str, variant: str, seed: int) -> str:
    """Directory name of one run of the report under ``OUT/runs``."""
    return f"{scenario}-{architecture}-{controller}-{variant}-s{seed}"


def event_moves(scenario: str, duration: float | None) -> dict[str, float]:
    """The scenario overrides that move ``scenario``'s events inside a run of ``duration``
    [s] (:func:`trackmj.scenarios.events.moved_events`; {} for the scenario's own duration)."""
    return {} if duration is None else moved_events(load_scenario(scenario), duration)


def tensioner_for(architecture: str, tensioner: str | None) -> str | None:
    """The tensioner file a run of ``architecture`` takes: ``tensioner`` where the
    architecture's element is the one a file replaces, else None (dp-b keeps its ideal
    source)."""
    replaceable = ARCHITECTURES[architecture].element == REPLACEABLE_ELEMENT
    return tensioner if replaceable else None
