"""The energy table of a run with the hydraulic plugin, ``Result.metrics["energy_J"]``
(written to ``metrics.json``).

All terms in J over the whole run, t = 0 to its end, gauge basis
(energies relative to the atmospheric reservoir). For a run with the hydraulic plugin the
chain from the prime mover to the track (:class:`~trackmj.hydraulics.EnergyLedger`)::

    pump    = Σ pump_losses + relief + stored_change.supply_oil + stored_change.accumulator
              + numerical.supply + circuit
    circuit = Σ throttling + makeup + leakage + cavitation + return_line
              + stored_change.circuit_oil
              + numerical.volume_term + friction + endstop
              + numerical.interface + mechanical

``residual`` = pump − every term but ``circuit`` (both lines together): a check of the
bookkeeping, ~1e-10 of ``pump`` (the terms come from the flows, the stored energies from the
state). Keys:

- ``supply_model``: the run's supply model (a string);
- ``pump``: shaft energy from the prime mover into the pump (the prescribed model's ideal
  source: the energy it delivers);
- ``pump_losses``: ``volumetric`` (pump leakage; the compensated pump's standby flow),
  ``mechanical`` (hydro-mechanical loss), ``unloaded`` (circulation through the unloading
  valve at its unloaded pressure);
- ``relief``: p_s·Q over the relief valve (its throttling and its return flow);
- ``circuit``: p_s·Q through the main valve's P port into the tensioning circuit;
- ``throttling``: by valve, ``main_valve`` (its four edges), ``rod_feed_restrictor``,
  ``V_L``, ``V_R``, ``head_restrictor_L``, ``head_restrictor_R``;
- ``makeup``: the make-up check valves; ``leakage``: cylinder seals head -> rod;
  ``cavitation``: the liquid's work on the air out of solution below atmospheric, −Σ p̄·ΔV_g
  (a reversible law: what stays is the steps' quadrature of it, hundredths of a joule);
  ``return_line``: p_t·Q of the circuit's return flow (back-pressure of the tank line);
- ``friction``: cylinder seal friction; ``endstop``: end-stop contact work;
- ``stored_change``: ``supply_oil``, ``accumulator`` (gas), ``circuit_oil`` (line A, heads
  with their hoses' compliance, rod node), end minus start;
- ``numerical``: backward-Euler dissipation of the ``supply`` node, the chamber model's
  ``volume_term`` and the coupling's ``interface`` residual (the circuit nodes' flows are
  booked at their mean pressure over each step, which closes their energy without a
  numerical term: :class:`~trackmj.hydraulics.EnergyLedger`);
- ``mechanical``: work into the track, ∫F·v dt;
- ``residual``: pump − every term above.

dp-b has no hydraulics: its table (:func:`trackmj.elements.ideal.ideal_actuator_table`) has
``ideal_actuator`` true, a ``note``, ``mechanical`` and, as ``circuit``, the energy an ideal
actuator with the same cylinders would draw.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from trackmj.hydraulics.ledger import EnergyLedger


def energy_table(ledger: EnergyLedger, supply_model: str, t_end_s: float) -> dict[str, Any]:
    """The energy table of a run with the hydraulic plugin (see the module docstring).

    Parameters
    ----------
    ledger : EnergyLedger
        The plugin's cumulative ledger at the end of the run (it starts at t = 0).
    supply_model : str
        The run's supply model.
    t_end_s : float
        End of the run [s].

    Returns
    -------
    dict
        Nested table of floats [J] plus ``supply_model``.
    """
    led = ledger
    table: dict[str, Any] = {
        "supply_model": supply_model,
        "pump": led.pump_J,
        "pump_losses": {"volumetric": led.pump_volumetric_J,
                        "mechanical": led.pump_mechanical_J, "unloaded": led.unloaded_J},
        "relief": led.relief_J,
        "circuit": led.circuit_J,
        "throttling": {"main_valve": led.throttle_main_J,
                       "rod_feed_restrictor": led.throttle_rod_restrictor_J,
                       "V_L": led.throttle_VL_J, "V_R": led.throttle_VR_J,
                       "head_restrictor_L": led.throttle_head_restrictor_L_J,
                       "head_restrictor_R": led.throttle_head_restrictor_R_J},
        "makeup": led.throttle_makeup_J,
        "leakage": led.leakage_J,
        "cavitation": led.cavitation_J,
        "return_line": led.to_tank_J,
        "friction": led.friction_J,
        "endstop": led.endstop_J,
        "stored_change": {
            "supply_oil": led.oil_supply_energy_J - led.oil_supply_energy_start_J,
            "accumulator": led.gas_energy_J - led.gas_energy_start_J,
            "circuit_oil": led.oil_energy_J - led.oil_energy_start_J},
        "numerical": {"supply": led.numerical_supply_J, "volume_term": led.volume_term_J,
                      "interface": led.interface_residual_J},
        "mechanical": led.mech_work_J,
    }
    table["residual"] = led.pump_J - accounted_J(table)
    return table


def accounted_J(table: dict[str, Any]) -> float:
    """Sum of every term of an :func:`energy_table` except ``pump``, ``circuit`` (an
    intermediate, not a sink) and ``residual`` [J]."""
    total = 0.0
    for key, value in table.items():
        if key in ("pump", "circuit", "residual", "supply_model"):
            continue
        total += sum(value.values()) if isinstance(value, dict) else value
    return total
