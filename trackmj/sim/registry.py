"""Registries of a run's wiring: mechanics, tensioner elements and the coupling
architectures made of them, and the reference architecture.

Each registry maps a name to a builder (:class:`~trackmj.sim.entries.Entry`); the CLI, the
report and the file validators take their choices from these keys, so a name is written
once. Builders are named by module (:func:`~trackmj.sim.entries.lazy`), so importing this
module stays cheap. A new element is its own module with a ``build(context) ->
ports.Element`` function and one line in :data:`ELEMENTS`; a new architecture is one line in
:data:`ARCHITECTURES`. The control blocks' registries are in :mod:`trackmj.sim.controllers`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from trackmj.sim.entries import Entry, lazy

if TYPE_CHECKING:
    from trackmj.ports import ElementCoupling


@dataclass(frozen=True)
class Architecture:
    """A coupling architecture: a key of :data:`MECHANICS` × a key of :data:`ELEMENTS`, with
    the coupling the element is asked for ("strong": the affine law with dF/dv; "weak": the
    last step's force held)."""

    description: str
    mechanics: str
    element: str
    coupling: ElementCoupling = "strong"

    @property
    def replays_tp(self) -> bool:
        """Whether its mechanics replays the track load of a tp run of the same case."""
        return "tp_result" in MECHANICS[self.mechanics].needs


_MECHANICS = "trackmj.sim.mechanics"
MECHANICS: dict[str, Entry] = {
    "track": Entry("the MuJoCo track of the machine, settled under the initial force",
                   lazy(_MECHANICS, "build_track")),
    "equivalent-idler": Entry("the identified equivalent idler, the track load of the tp run "
                              "replayed", lazy(_MECHANICS, "build_equivalent_idler"),
                              needs=("tp_result",)),
}
"""Mechanics builders ``build(setup, **needs) -> BuiltMechanics`` (see
:mod:`trackmj.sim.mechanics`)."""

ELEMENTS: dict[str, Entry] = {
    "hydraulic": Entry("the hydraulic plugin (trackmj.hydraulics)",
                       lazy("trackmj.elements.hydraulic", "build")),
    "ideal": Entry("an ideal force source at the hydraulic tension rate (dp-b)",
                   lazy("trackmj.elements.ideal", "build")),
    "passive": Entry("a preload spring-damper, valves ignored (a tensioner file's [passive])",
                     lazy("trackmj.elements.passive", "build")),
    "fmu": Entry("an FMU, FMI 2.0/3.0, co-simulation or model exchange (a tensioner file's "
                 "[fmu])", lazy("trackmj.elements.fmu", "build")),
}
"""Tensioner element builders ``build(ElementContext) -> ports.Element``."""

REPLACEABLE_ELEMENT = "hydraulic"
"""The element a tensioner file replaces: architectures built on another element (dp-b's
ideal source) keep theirs."""

ARCHITECTURES: dict[str, Architecture] = {
    "tp": Architecture("track + hydraulic plugin, strong coupling", "track", "hydraulic"),
    "tp-weak": Architecture("track + hydraulic plugin, weak (explicit) coupling", "track",
                            "hydraulic", "weak"),
    "dp-a": Architecture("hydraulics on the identified equivalent idler, tp track load "
                         "replayed", "equivalent-idler", "hydraulic"),
    "dp-b": Architecture("track with an ideal force source instead of the hydraulics",
                         "track", "ideal"),
}
"""Coupling architectures, mechanics × element (see :mod:`trackmj.sim.architectures`)."""

REFERENCE_ARCHITECTURE = "tp"
"""The architecture the others are judged against: the full track with the hydraulic plugin,
strongly coupled. dp-a replays its track load; compare and report measure each reduced
architecture's prediction error against it."""


