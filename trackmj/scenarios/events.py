"""Events of a scenario and moving them into a short run: the reference steps and ramps,
supply drops and load pulses with their keys in the scenario file, which of them a run of a
given duration cuts off (:func:`check_duration` refuses it), and the overrides that compress
the schedule into the run (:func:`moved_events`, for sweeps and reports run short on
purpose)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from trackmj.scenarios.resolved import Scenario
from trackmj.validator import ParameterError


@dataclass(frozen=True)
class Event:
    """A scheduled event of a scenario: ``what`` it is (for messages), its keys in the
    scenario file (``(key, time [s])`` of each of its times, e.g. ``("supply.drops.0.start_s",
    12.0)``), and the time it needs the run to last to be whole, ``needs_s`` [s] (a step's or
    ramp's start must lie inside the run; a pulse's or drop's end edge must be over)."""

    what: str
    times: tuple[tuple[str, float], ...]
    needs_s: float
    edge_s: float = 0.0

    def fits(self, duration_s: float) -> bool:
        """Whether a run of ``duration_s`` [s] holds the whole event."""
        start = self.times[0][1]
        return start < duration_s and self.needs_s <= duration_s


def events(sc: Scenario) -> list[Event]:
    """The reference steps and ramps, supply drops and load pulses of ``sc``."""
    out = [Event(f"[[reference.steps]][{i}] (reference step at {s.time_s:g} s)",
                 ((f"reference.steps.{i}.time_s", s.time_s),), s.time_s)
           for i, s in enumerate(sc.reference.steps)]
    for i, r in enumerate(sc.reference.ramps):
        times = ((f"reference.ramps.{i}.start_s", r.start_s),)
        if r.end_s is not None:
            times += ((f"reference.ramps.{i}.end_s", r.end_s),)
        out.append(Event(f"[[reference.ramps]][{i}] (reference ramp from {r.start_s:g} s)",
                         times, r.start_s if r.end_s is None else r.end_s))
    for i, d in enumerate(sc.supply.drops):
        out.append(Event(f"[[supply.drops]][{i}] (supply drop {d.start_s:g}-{d.end_s:g} s)",
                         ((f"supply.drops.{i}.start_s", d.start_s),
                          (f"supply.drops.{i}.end_s", d.end_s)),
                         d.end_s + d.transition_s, d.transition_s))
    for i, p in enumerate(sc.load_pulses):
        out.append(Event(f"[[load_pulses]][{i}] (load pulse {p.start_s:g}-{p.end_s:g} s)",
                         ((f"load_pulses.{i}.start_s", p.start_s),
                          (f"load_pulses.{i}.end_s", p.end_s)), p.end_s + p.rise_s, p.rise_s))
    return out


def cut_events(sc: Scenario, duration_s: float) -> list[Event]:
    """The events of ``sc`` that its own duration holds whole and a run of ``duration_s``
    [s] would cut off (start after the end, or end edge not over)."""
    return [e for e in events(sc) if e.fits(sc.duration_s) and not e.fits(duration_s)]


def check_duration(sc: Scenario, duration_s: float) -> None:
    """ParameterError (one line naming the first event cut off, and the duration that holds
    every one of them) if a run of ``duration_s`` [s] would cut off one of ``sc``'s events;
    the same rule as the scenario file's, where an event after ``duration_s`` is refused.
    A closed-loop run is judged on the response to its events; ``trackmj calibrate``
    replays logged valve commands for the logs' length and does not apply it, which the
    line says (a 4 s W1 spec calibrates, ``run W1 --duration 4`` is refused)."""
    cut = cut_events(sc, duration_s)
    if cut:
        first, last = cut[0], max(cut, key=lambda e: e.needs_s)
        more = f" (and {len(cut) - 1} more, the last {last.what})" if len(cut) > 1 else ""
        starts_inside = last.times[0][1] >= last.needs_s   # a step or open ramp: start < end
        least = f"more than {last.needs_s:g}" if starts_inside else f"{last.needs_s:g} or more"
        needs = "they need" if len(cut) > 1 else "it needs"
        current = {key: t for e in events(sc) for key, t in e.times}
        sets = " ".join(f"--set scenario.{key}={t:g}"
                        for key, t in moved_events(sc, duration_s).items()
                        if current.get(key) != t)
        raise ParameterError(
            f"--duration {duration_s:g} s cuts off {sc.source.name} {first.what}{more}: "
            f"{needs} the run to last {least} s; give --duration {least}, or move the "
            f"events into the run as report and sweep do ({sets}); a run is judged on "
            "its scenario's events (calibrate, replaying logged valve commands, needs none)")


def moved_events(sc: Scenario, duration_s: float) -> dict[str, float]:
    """Scenario overrides (``{"reference.steps.0.time_s": t, ...}``) that move every event
    of ``sc`` into a run of ``duration_s`` [s] if the run would cut one off; {} otherwise.

    The schedule after the evaluation start ``s`` is compressed linearly: a time t >= s
    becomes s + (t − s)·(duration_s − s)/(D − s), D the scenario's duration, so the events
    keep their order and their share of the run; earlier times stay, and so do times at or
    after D (a drop or pulse that lasts to the scenario's end lasts to the run's end).
    Edges (a pulse's rise, a drop's transition) keep their length where the window holds
    it, else shrink by the same factor. Moved times are rounded to the 1 ms coupling
    step."""
    if not cut_events(sc, duration_s):
        return {}
    s, end = sc.evaluation.start_s, sc.duration_s
    factor = (duration_s - s) / (end - s)

    def move(t: float) -> float:
        return t if t < s or t >= end else s + (t - s) * factor

    out: dict[str, float] = {}
    for e in events(sc):
        moved = [(key, move(t)) for key, t in e.times]
        out |= {key: round(t, 3) for key, t in moved}   # on the 1 ms coupling grid
        if e.edge_s and len(moved) == 2:
            if e.edge_s > moved[1][1] - moved[0][1]:   # the window's own check
                kind = "transition_s" if "drops" in moved[0][0] else "rise_s"
                out[moved[0][0].rsplit(".", 1)[0] + "." + kind] = round(e.edge_s * factor, 3)
    return out


def describe_moves(sc: Scenario, moves: Mapping[str, float]) -> str:
    """One line saying where ``moves`` (from :func:`moved_events`) put the events of ``sc``."""
    parts = []
    for e in events(sc):
        new = [f"{moves[k]:.3g}" for k, _ in e.times if k in moves]
        if new:
            parts.append(f"{e.what.split('(', 1)[1].rstrip(')')} -> {'-'.join(new)} s")
    return "; ".join(parts)
