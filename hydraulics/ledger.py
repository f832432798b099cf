"""Energy ledger of the hydraulic tensioner (per step and cumulative), joules.

Discrete identity closed by the backward-Euler update (see ``HydraulicTensioner``)::

    supply = to_tank + throttle_* + leakage + Δ(oil + gas) + numerical + volume_term + piston
    piston = friction + endstop + mech_work + interface_residual

``balance_error_J`` is ``supply`` minus every right-hand term, with the stored energies
evaluated from the state (p²V/(2β) per node, accumulator gas energy), not from the flows.
"""

from __future__ import annotations

from dataclasses import dataclass, fields


@dataclass(slots=True)
class EnergyLedger:
    """Energy terms [J]. Positive = energy leaving the oil circuit's budget as named.

    supply_J: work delivered by the source (pump work p_s·Q_pump in accumulator mode,
        p_s·Q_out through the main valve with a prescribed supply pressure).
    to_tank_J: p_t·Q carried to the tank by the return flow (net of make-up inflow).
    throttle_*_J: Δp·Q in the main valve edges (incl. the line-B restrictor), V_L and V_R
        (incl. head-branch restrictors), relief valve, make-up check valves.
    leakage_J: Δp·Q of the internal head->rod leakage.
    friction_J / endstop_J: friction work and end-stop work absorbed (F·v·h, ≥ 0 for friction).
    numerical_J: backward-Euler dissipation Σ V(Δp)²/(2β) + accumulator part (≥ 0).
    volume_term_J: −Σ (V_{k+1}−V_k)·p_k²/(2β): the constant-β chamber model has no exact
        energy function when V changes (p²V/(2β) grows with V at constant p); this is its
        small defect, ~p/(2β) of the piston work.
    piston_work_J: Σ p·A·v·h over the four chambers (hydraulics -> piston).
    mech_work_J: ForceLaw.at(v)·v·h received by the track.
    interface_residual_J: piston work − friction − end stop − mech work.
    oil_energy_J / gas_energy_J: stored energies now; *_start_J at the ledger start.
    """

    supply_J: float = 0.0
    to_tank_J: float = 0.0
    throttle_main_J: float = 0.0
    throttle_VL_J: float = 0.0
    throttle_VR_J: float = 0.0
    throttle_relief_J: float = 0.0
    throttle_makeup_J: float = 0.0
    leakage_J: float = 0.0
    friction_J: float = 0.0
    endstop_J: float = 0.0
    numerical_J: float = 0.0
    volume_term_J: float = 0.0
    piston_work_J: float = 0.0
    mech_work_J: float = 0.0
    interface_residual_J: float = 0.0
    oil_energy_J: float = 0.0
    gas_energy_J: float = 0.0
    oil_energy_start_J: float = 0.0
    gas_energy_start_J: float = 0.0

    @property
    def throttle_J(self) -> float:
        """Sum of all valve throttling losses [J]."""
        return (self.throttle_main_J + self.throttle_VL_J + self.throttle_VR_J
                + self.throttle_relief_J + self.throttle_makeup_J)

    @property
    def stored_change_J(self) -> float:
        """Change of oil + gas stored energy since the ledger start [J]."""
        return (self.oil_energy_J + self.gas_energy_J
                - self.oil_energy_start_J - self.gas_energy_start_J)

    @property
    def losses_J(self) -> float:
        """Every dissipated/exported term except mechanical work [J]."""
        return (self.to_tank_J + self.throttle_J + self.leakage_J + self.friction_J
                + self.endstop_J + self.numerical_J + self.volume_term_J)

    @property
    def balance_error_J(self) -> float:
        """supply − (losses + stored change + mech work + interface residual) [J]."""
        return self.supply_J - (self.losses_J + self.stored_change_J + self.mech_work_J
                                + self.interface_residual_J)

    def add(self, other: EnergyLedger) -> None:
        """Accumulate the flow terms of ``other`` and take its end stored energies."""
        self.supply_J += other.supply_J
        self.to_tank_J += other.to_tank_J
        self.throttle_main_J += other.throttle_main_J
        self.throttle_VL_J += other.throttle_VL_J
        self.throttle_VR_J += other.throttle_VR_J
        self.throttle_relief_J += other.throttle_relief_J
        self.throttle_makeup_J += other.throttle_makeup_J
        self.leakage_J += other.leakage_J
        self.friction_J += other.friction_J
        self.endstop_J += other.endstop_J
        self.numerical_J += other.numerical_J
        self.volume_term_J += other.volume_term_J
        self.piston_work_J += other.piston_work_J
        self.mech_work_J += other.mech_work_J
        self.interface_residual_J += other.interface_residual_J
        self.oil_energy_J = other.oil_energy_J
        self.gas_energy_J = other.gas_energy_J

    def as_dict(self) -> dict[str, float]:
        """All fields and derived totals as a plain dict [J]."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d.update(throttle_J=self.throttle_J, stored_change_J=self.stored_change_J,
                 losses_J=self.losses_J, balance_error_J=self.balance_error_J)
        return d
