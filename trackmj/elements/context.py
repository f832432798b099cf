"""What an element builder gets (:data:`trackmj.sim.registry.ELEMENTS`,
``build(ElementContext) -> ports.Element``), declared here, below the run assembly that
fills it, so that elements need nothing of :mod:`trackmj.sim`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from trackmj.ports import ElementCoupling

if TYPE_CHECKING:
    from trackmj.control.model import ReducedModel
    from trackmj.elements.tensioner_file import TensionerFile
    from trackmj.hydraulics.params import HydraulicParams
    from trackmj.machines.idler import EquivalentIdler
    from trackmj.scenarios.resolved import Scenario


class ElementSetup(Protocol):
    """The run's inputs an element builder reads (:class:`trackmj.sim.setup.RunSetup` is
    one): the scenario, the hydraulic file with the variant's scales, the equivalent idler,
    and the initial force [N], supply set-point [Pa gauge] and head pressure [Pa gauge]."""

    @property
    def scenario(self) -> Scenario: ...
    @property
    def hydraulics(self) -> HydraulicParams: ...
    @property
    def idler(self) -> EquivalentIdler: ...
    @property
    def force0_N(self) -> float: ...
    @property
    def supply0_Pa(self) -> float: ...
    @property
    def head_pressure0_Pa(self) -> float: ...


@dataclass(frozen=True)
class ElementContext:
    """What an element builder gets: the run's setup, the mechanics' initial stroke [m], the
    controller's reduced model, the architecture's coupling ("strong" or "weak") and the
    run's tensioner file (None: the built-in element)."""

    setup: ElementSetup
    stroke_m: float
    model: ReducedModel
    coupling: ElementCoupling
    tensioner: TensionerFile | None
