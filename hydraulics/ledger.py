"""Energy ledger of the hydraulic tensioner (per step and cumulative), joules.

Discrete identity closed by the backward-Euler update (see ``HydraulicTensioner``)::

    supply = to_tank + throttle_* + leakage + Δ(oil + gas) + numerical + volume_term + piston
    piston = friction + endstop + mech_work + interface_residual

``balance_error_J`` is ``supply`` minus every right-hand term, with the stored energies
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

    The terms live in ``terms``, a float64 array of length 19 in ``kernels.LEDGER_FIELDS``
    order (the first 15 are the flow terms that ``add`` accumulates). ``EnergyLedger.view``
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
        """A ledger reading and writing ``terms`` (float64, shape (19,)) in place."""
        if terms.shape != (N_LEDGER,) or terms.dtype != np.float64:
            raise ValueError(f"terms must be float64 of shape ({N_LEDGER},), got "
                             f"{terms.dtype} {terms.shape}")
        ledger = cls.__new__(cls)
        ledger.terms = terms
        return ledger

    supply_J = _term(k.L_SUPPLY)
    to_tank_J = _term(k.L_TO_TANK)
    throttle_main_J = _term(k.L_THROTTLE_MAIN)
    throttle_VL_J = _term(k.L_THROTTLE_VL)
    throttle_VR_J = _term(k.L_THROTTLE_VR)
    throttle_relief_J = _term(k.L_THROTTLE_RELIEF)
    throttle_makeup_J = _term(k.L_THROTTLE_MAKEUP)
    leakage_J = _term(k.L_LEAKAGE)
    friction_J = _term(k.L_FRICTION)
    endstop_J = _term(k.L_ENDSTOP)
    numerical_J = _term(k.L_NUMERICAL)
    volume_term_J = _term(k.L_VOLUME_TERM)
    piston_work_J = _term(k.L_PISTON_WORK)
    mech_work_J = _term(k.L_MECH_WORK)
    interface_residual_J = _term(k.L_INTERFACE_RESIDUAL)
    oil_energy_J = _term(k.L_OIL_ENERGY)
    gas_energy_J = _term(k.L_GAS_ENERGY)
    oil_energy_start_J = _term(k.L_OIL_ENERGY_START)
    gas_energy_start_J = _term(k.L_GAS_ENERGY_START)

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
        self.terms[:N_FLOW_TERMS] += other.terms[:N_FLOW_TERMS]
        self.oil_energy_J = other.oil_energy_J
        self.gas_energy_J = other.gas_energy_J

    def as_dict(self) -> dict[str, float]:
        """All fields and derived totals as a plain dict [J]."""
        d = dict(zip(LEDGER_FIELDS, self.terms.tolist(), strict=True))
        d.update(throttle_J=self.throttle_J, stored_change_J=self.stored_change_J,
                 losses_J=self.losses_J, balance_error_J=self.balance_error_J)
        return d

    def __eq__(self, other: Any) -> bool:
        if not isinstance(other, EnergyLedger):
            return NotImplemented
        return bool(np.array_equal(self.terms, other.terms))

    __hash__ = None  # type: ignore[assignment]  (mutable, as the dataclass it replaces)

    def __repr__(self) -> str:
        terms = ", ".join(f"{k}={v!r}" for k, v in zip(LEDGER_FIELDS, self.terms.tolist(),
                                                        strict=True))
        return f"EnergyLedger({terms})"
