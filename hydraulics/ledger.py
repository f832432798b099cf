"""Energy ledger of the hydraulic tensioner (per step and cumulative), joules.

Discrete identities closed by the backward-Euler update (see ``HydraulicTensioner``), from
the prime mover to the track::

    pump      = pump_volumetric + pump_mechanical + unloaded + delivered
    delivered = relief + Δ(oil_supply + gas) + numerical_supply + circuit
    circuit   = to_tank + throttle_* + leakage + cavitation + Δoil + volume_term + piston
    piston    = friction + endstop + mech_work + interface_residual

The circuit's terms are booked at each node's mean pressure over the step,
p̄ = (p_k + p_{k+1})/2 (per sub-step in the multi-rate coupling): a backward-Euler
step conserves the oil volume, V·(p_{k+1} − p_k)/β = h·ΣQ − ΔV, so the oil energy
V·p²/(2β) changes by exactly h·p̄·ΣQ − p̄·ΔV + volume_term, and the circuit needs no
numerical term. Booked at p_{k+1} instead, each node would show ½·(V/β)·Δp² per step as
``numerical``: the orifice loss of a transient faster than the step (which ``p̄`` books on
the edges that carry its flow) and a damping of the oil spring under the piston (which the
piston force at ``p̄`` does not apply; kernels module docstring).

``balance_error_J`` is ``pump`` minus every right-hand term, with the stored energies
evaluated from the state (p²V/(2β) per node, accumulator gas energy), not from the flows.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import kernels as k
from .kernels import LEDGER_FIELDS, N_FLOW_TERMS, N_LEDGER


def _term(index: int) -> property:
    """The ledger term at ``index`` of the backing array, as a Python float [J]."""

    def get(self: EnergyLedger) -> float:
        return self.terms.item(index)

    def set_(self: EnergyLedger, value: float) -> None:
        self.terms[index] = value

    return property(get, set_, doc=f"{LEDGER_FIELDS[index]} [J]")


class EnergyLedger:
    """Energy terms [J] (gauge pressures: energies relative to the atmospheric reservoir).

    pump_J: shaft energy from the prime mover into the pump (an ideal source with a
        prescribed supply pressure: its delivered energy).
    pump_volumetric_J / pump_mechanical_J: the pump's leakage loss (the variable pump's
        standby flow k_L·p_S) and hydro-mechanical loss.
    unloaded_J: p_unloaded·Q of the fixed pump circulating to tank through the unloading valve.
    delivered_J: hydraulic energy the pump (or the ideal source) delivers into the supply node.
    relief_J: p_s·Q of the relief flow (its throttling down to p_t plus the return line).
    circuit_J: p_s·Q through the main valve's P port into the tensioning circuit.
    to_tank_J: p_t·Q carried to the tank by the circuit's return flow (net of make-up inflow).
    throttle_*_J: Δp·Q in the main valve edges, the rod-feed restrictor, V_L, V_R, the two
        head restrictors and the make-up check valves; a valve and its series restrictor
        share a loss in proportion to 1/A² (exact for the turbulent orifice law).
    leakage_J: Δp·Q of the internal head->rod leakage.
    cavitation_J: −Σ p̄·ΔV_g, the work the liquid does on the air out of solution below
        atmospheric (``kernels.released_air``): > 0 while air comes out, < 0 while it goes
        back. The law is reversible, so over a release and re-absorption the sum is the
        steps' quadrature of it, not a loss (a 30 ms pull of the rod node into the air,
        tests/test_cavitation.py: +0.96 J out, −1.02 J back).
    friction_J / endstop_J: friction work and end-stop work absorbed (F·v·h, ≥ 0 for friction).
    numerical_supply_J: backward-Euler dissipation V(Δp)²/(2β) of the supply node (booked
        at its end-of-step pressure, as the pump's and the relief's energies are) and the
        accumulator's part (gas energy against ∫p·dV_oil of the step) (≥ 0).
    volume_term_J: −Σ (V_{k+1}−V_k)·p_k²/(2β): the constant-β chamber model has no exact
        energy function when V changes (p²V/(2β) grows with V at constant p); this is its
        small defect, ~p/(2β) of the piston work.
    piston_work_J: Σ p̄·A·v·h over the four chambers (hydraulics -> piston).
    mech_work_J: ForceLaw.at(v)·v·h received by the track.
    interface_residual_J: piston work − friction − end stop − mech work.
    oil_supply_energy_J / oil_energy_J / gas_energy_J: stored energies now (supply node;
        circuit nodes: line A, heads with their hoses, rod node; accumulator gas);
        *_start_J at the ledger start.

    The terms live in ``terms``, a float64 array of length 30 in ``kernels.LEDGER_FIELDS``
    order (the first 24 are the flow terms that ``add`` accumulates). ``EnergyLedger.view``
    wraps an existing array: the tensioner's ledgers are views of its state array, so they
    show the current values at any time.
    """

    __slots__ = ("terms",)

    def __init__(self, **terms: float) -> None:
        self.terms = np.zeros(N_LEDGER)
        for name, value in terms.items():
            if name not in LEDGER_FIELDS:
                raise TypeError(f"EnergyLedger has no term {name!r}")
            self.terms[LEDGER_FIELDS.index(name)] = value

    @classmethod
    def view(cls, terms: np.ndarray) -> EnergyLedger:
        """A ledger reading and writing ``terms`` (float64, shape (30,)) in place."""
        if terms.shape != (N_LEDGER,) or terms.dtype != np.float64:
            raise ValueError(f"terms must be float64 of shape ({N_LEDGER},), got "
                             f"{terms.dtype} {terms.shape}")
        ledger = cls.__new__(cls)
        ledger.terms = terms
        return ledger

    pump_J = _term(k.L_PUMP)
    pump_volumetric_J = _term(k.L_PUMP_VOLUMETRIC)
    pump_mechanical_J = _term(k.L_PUMP_MECHANICAL)
    unloaded_J = _term(k.L_UNLOADED)
    delivered_J = _term(k.L_DELIVERED)
    relief_J = _term(k.L_RELIEF)
    circuit_J = _term(k.L_CIRCUIT)
    to_tank_J = _term(k.L_TO_TANK)
    throttle_main_J = _term(k.L_THROTTLE_MAIN)
    throttle_rod_restrictor_J = _term(k.L_THROTTLE_ROD_RESTRICTOR)
    throttle_VL_J = _term(k.L_THROTTLE_VL)
    throttle_VR_J = _term(k.L_THROTTLE_VR)
    throttle_head_restrictor_L_J = _term(k.L_THROTTLE_HEAD_RESTRICTOR_L)
    throttle_head_restrictor_R_J = _term(k.L_THROTTLE_HEAD_RESTRICTOR_R)
    throttle_makeup_J = _term(k.L_THROTTLE_MAKEUP)
    leakage_J = _term(k.L_LEAKAGE)
    cavitation_J = _term(k.L_CAVITATION)
    friction_J = _term(k.L_FRICTION)
    endstop_J = _term(k.L_ENDSTOP)
    numerical_supply_J = _term(k.L_NUMERICAL_SUPPLY)
    volume_term_J = _term(k.L_VOLUME_TERM)
    piston_work_J = _term(k.L_PISTON_WORK)
    mech_work_J = _term(k.L_MECH_WORK)
    interface_residual_J = _term(k.L_INTERFACE_RESIDUAL)
    oil_supply_energy_J = _term(k.L_OIL_SUPPLY_ENERGY)
    oil_energy_J = _term(k.L_OIL_ENERGY)
    gas_energy_J = _term(k.L_GAS_ENERGY)
    oil_supply_energy_start_J = _term(k.L_OIL_SUPPLY_ENERGY_START)
    oil_energy_start_J = _term(k.L_OIL_ENERGY_START)
    gas_energy_start_J = _term(k.L_GAS_ENERGY_START)

    @property
    def pump_losses_J(self) -> float:
        """Losses between the prime mover and the supply node: pump leakage, pump
        hydro-mechanical loss, unloaded circulation [J]."""
        return self.pump_volumetric_J + self.pump_mechanical_J + self.unloaded_J

    @property
    def throttle_J(self) -> float:
        """Sum of the circuit's valve and restrictor throttling losses incl. make-up [J]."""
        return (self.throttle_main_J + self.throttle_rod_restrictor_J + self.throttle_VL_J
                + self.throttle_VR_J + self.throttle_head_restrictor_L_J
                + self.throttle_head_restrictor_R_J + self.throttle_makeup_J)

    @property
    def supply_stored_change_J(self) -> float:
        """Change of the supply node's oil and the accumulator gas energy since the start [J]."""
        return (self.oil_supply_energy_J + self.gas_energy_J
                - self.oil_supply_energy_start_J - self.gas_energy_start_J)

    @property
    def circuit_stored_change_J(self) -> float:
        """Change of the circuit nodes' oil energy since the start [J]."""
        return self.oil_energy_J - self.oil_energy_start_J

    @property
    def stored_change_J(self) -> float:
        """Change of all oil + gas stored energy since the ledger start [J]."""
        return self.supply_stored_change_J + self.circuit_stored_change_J

    @property
    def losses_J(self) -> float:
        """Every dissipated/exported term except mechanical work and the interface residual,
        from the pump shaft to the piston [J]."""
        return (self.pump_losses_J + self.relief_J + self.to_tank_J + self.throttle_J
                + self.leakage_J + self.cavitation_J + self.friction_J + self.endstop_J
                + self.numerical_supply_J + self.volume_term_J)

    @property
    def supply_balance_error_J(self) -> float:
        """pump − (pump losses + relief + supply stored change + supply numerical + circuit)
        [J]: the source side of the chain."""
        return self.pump_J - (self.pump_losses_J + self.relief_J + self.supply_stored_change_J
                              + self.numerical_supply_J + self.circuit_J)

    @property
    def balance_error_J(self) -> float:
        """pump − (losses + stored change + mech work + interface residual) [J]."""
        return self.pump_J - (self.losses_J + self.stored_change_J + self.mech_work_J
                              + self.interface_residual_J)

    def add(self, other: EnergyLedger) -> None:
        """Accumulate the flow terms of ``other`` and take its end stored energies."""
        self.terms[:N_FLOW_TERMS] += other.terms[:N_FLOW_TERMS]
        self.oil_supply_energy_J = other.oil_supply_energy_J
        self.oil_energy_J = other.oil_energy_J
        self.gas_energy_J = other.gas_energy_J

    def as_dict(self) -> dict[str, float]:
        """All fields and derived totals as a plain dict [J]."""
        d: dict[str, float] = dict(zip(LEDGER_FIELDS, self.terms.tolist(), strict=True))
        d.update(pump_losses_J=self.pump_losses_J, throttle_J=self.throttle_J,
                 stored_change_J=self.stored_change_J, losses_J=self.losses_J,
                 balance_error_J=self.balance_error_J)
        return d

    def __eq__(self, other: Any) -> bool:
        if not isinstance(other, EnergyLedger):
            return NotImplemented
        return bool(np.array_equal(self.terms, other.terms))

    # __eq__ without __hash__: Python sets __hash__ = None (unhashable: mutable, as the
    # dataclass it replaces)

    def __repr__(self) -> str:
        terms = ", ".join(f"{k}={v!r}" for k, v in zip(LEDGER_FIELDS, self.terms.tolist(),
                                                        strict=True))
        return f"EnergyLedger({terms})"
