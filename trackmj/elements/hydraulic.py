"""The hydraulic plugin (:mod:`trackmj.hydraulics`) on the element port (tp, tp-weak, dp-a)
and its builder. Sign conventions as in :mod:`trackmj.ports`."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from trackmj.elements.cylinder import cylinder_travel_m
from trackmj.elements.energy_table import energy_table
from trackmj.hydraulics.tensioner import FLOW_NAMES, NODE_NAMES, HydraulicTensioner
from trackmj.ports import Element
from trackmj.validator import ParameterError

if TYPE_CHECKING:
    from trackmj.elements.context import ElementContext


class HydraulicElement:
    """The hydraulic plugin on the element port: valve modes to its solenoids (when the mode
    changes), its log, its five node pressures for the guard, its ledger as run metrics and
    energy table. ``force_law``, ``complete_step`` and ``log`` are the plugin's own bound
    methods (no call in between at 1 kHz)."""

    pressure_nodes = NODE_NAMES
    channels: ClassVar[Mapping[str, str]] = {"p_head_L_Pa": "Pa", "p_head_R_Pa": "Pa",
                                   "p_line_A_Pa": "Pa",
                                   **{f"q_{name}_m3_s": "m^3/s" for name in FLOW_NAMES}}
    """Each cylinder's head (both rods share one node, the readout's p_rod_Pa), line A, and
    every flow of the circuit a -> b as :data:`~trackmj.hydraulics.tensioner.FLOW_NAMES`
    names them (main_PA supply -> line A, main_AT line A -> tank, main_PB supply -> rod
    node, main_BT rod node -> tank, V_L / V_R line A -> head, relief, make-up, leakage,
    pump)."""

    def __init__(self, tensioner: HydraulicTensioner) -> None:
        self.tensioner = tensioner
        self.force_law = tensioner.force_law
        self.complete_step = tensioner.complete_step
        self.log = tensioner.log
        self.stroke_range_m = cylinder_travel_m(tensioner.params)
        self._mode: int | None = None
        self._pressures = tensioner.pressure_view()

    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """Valve mode +1/0/−1 to the solenoids when it changes (u: the mode is the command;
        the supply set-point is the plugin's own profile)."""
        if mode != self._mode:
            self.tensioner.set_mode(mode)
            self._mode = mode

    def node_pressures(self) -> list[float]:
        """(line A, head L, head R, rod node, supply) [Pa gauge] now."""
        return self._pressures.tolist()

    def channel_values(self) -> list[float]:
        rec = self.tensioner.record
        return [rec.p_head_L_Pa, rec.p_head_R_Pa, rec.p_line_A_Pa,
                *(rec.flows_m3_s[name] for name in FLOW_NAMES)]

    def run_metrics(self, duration_s: float) -> dict[str, Any]:
        """Interface residual, friction loss and ledger balance error [J], and the energy
        table (:func:`trackmj.elements.energy_table.energy_table`)."""
        ledger = self.tensioner.ledger
        return {"interface_energy_residual_J": ledger.interface_residual_J,
                "friction_loss_J": ledger.friction_J,
                "ledger_balance_error_J": ledger.balance_error_J,
                "energy_J": energy_table(ledger, self.tensioner.supply_model, duration_s)}


def build(ctx: ElementContext) -> Element:
    """The plugin with the scenario's supply model (default: the hydraulic file's) at the
    hydraulic file's set-point with the scenario's changes, each model starting in its
    steady state without demand; all valves closed (hold); ``ctx.coupling`` strong or weak."""
    setup = ctx.setup
    hyd, sc = setup.hydraulics, setup.scenario
    nominal = hyd.supply.setpoint_Pa
    profile = sc.supply_setpoint_profile(nominal)
    if profile is not None and (sc.supply.model or hyd.supply.default_model) == "unloading":
        raise ParameterError(f"{sc.source.name} [[supply.drops]]: the supply model "
                             "'unloading' (the hydraulic file's [supply].default_model) takes "
                             "no set-point drops; name another [supply].model")
    tensioner = HydraulicTensioner(
        hyd, stroke_m=ctx.stroke_m, head_pressure_Pa=setup.head_pressure0_Pa,
        supply_model=sc.supply.model, setpoint_Pa=nominal if profile is None else profile,
        coupling=ctx.coupling)
    tensioner.set_mode(0)
    return HydraulicElement(tensioner)

