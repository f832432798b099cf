"""Hydraulic plugin strongly coupled to the MuJoCo track (the coupled checks)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackmj.hydraulics import HydraulicTensioner
from trackmj.machines.track_plant import load_plant
from trackmj.track.plant import TrackPlant


def _coupled(mode_schedule, duration_s: float, speed_m_s: float = 1.5):
    """Plant at home, hydraulics initialised to carry the home idler force in the heads."""
    plant = load_plant()
    probe = plant.last_law  # None at reset: the home force is the preload law's force
    assert probe is None
    home_force = plant.params.tensioner.preload_N - plant.params.tensioner.stiffness_N_m * (
        plant.stroke_m - plant.params.idler.stroke_at_layout_m
    )
    tensioner = HydraulicTensioner(stroke_m=plant.stroke_m)
    ah, ar, pt = tensioner.Ah, tensioner.Ar, tensioner.pT
    tensioner = HydraulicTensioner(
        stroke_m=plant.stroke_m, head_pressure_Pa=(home_force + 2 * ar * pt) / (2 * ah)
    )
    rows = []

    def on_step(pl: TrackPlant) -> None:
        mode = mode_schedule(pl.time_s)
        if mode is not None:
            tensioner.set_mode(mode)
        rec = tensioner.record
        rows.append(
            (
                pl.time_s,
                rec.p_head_L_Pa,
                rec.p_head_R_Pa,
                rec.p_rod_L_Pa,
                rec.p_supply_Pa,
                pl.idler_force_N,
                rec.force_N,
                pl.stroke_velocity_m_s,
            )
        )

    tensioner.set_mode(0)
    plant.run(tensioner, duration_s, lambda t: speed_m_s * min(1.0, t), on_step)
    return plant, tensioner, np.array(rows)


def test_hold_mode_with_track_driven() -> None:
    plant, tensioner, rows = _coupled(lambda t: None, 5.0)
    assert plant.warning_count == 0
    assert np.all(np.isfinite(rows))
    pressures = rows[:, 1:5]
    # heads trapped above tank; the rods vent to tank, so the oscillating idler can pull them
    # below it only by the vent's pressure drop, never into the make-up valves' band
    assert pressures[:, :2].min() >= tensioner.pT
    assert pressures.min() >= tensioner.mu_open
    # the trapped oil carries the track load: head pressure tracks the idler force
    force_from_pressure = 2 * tensioner.Ah * rows[:, 1] - 2 * tensioner.Ar * rows[:, 3]
    assert np.abs(force_from_pressure - rows[:, 6]).max() < 0.05 * np.abs(rows[:, 6]).max()
    ledger = tensioner.ledger
    scale = abs(ledger.pump_J) + abs(ledger.mech_work_J) + abs(ledger.oil_energy_J) + 1.0
    assert abs(ledger.balance_error_J) < 5e-3 * scale
    assert not plant.derailment().any


def test_cycle_interface_work_balances() -> None:
    """Pressurize / hold / release while driving: the piston work the hydraulics delivered
    and the work the track received agree within 0.1 % of the work exchanged."""

    def schedule(t: float) -> int | None:
        phase = math.floor(t / 0.5) % 4
        return (1, 0, -1, 0)[phase]

    plant, tensioner, rows = _coupled(schedule, 4.0)
    assert plant.warning_count == 0
    ledger = tensioner.ledger
    exchanged = np.sum(np.abs(rows[:, 5] * rows[:, 7])) * 1e-3
    assert exchanged > 1.0  # the cycle really moved the idler
    hydraulic_side = ledger.piston_work_J - ledger.friction_J - ledger.endstop_J
    assert hydraulic_side == pytest.approx(ledger.mech_work_J, abs=1e-3 * exchanged)
    # the track's own account of the work matches the hydraulic ledger's mechanical work
    track_work = float(np.sum(rows[:, 5] * rows[:, 7]) * 1e-3)
    assert track_work == pytest.approx(ledger.mech_work_J, abs=1e-3 * exchanged)


def test_full_opening_changes_tension_at_the_sized_rate() -> None:
    """Sizing target on the real plugin and track (standing): pressurize or release at full
    opening for 0.5 s changes the idler force by 1.5-5 kN, i.e. 3 kN takes ~0.3-1 s."""

    def schedule(t: float) -> int:
        return 1 if 0.5 <= t < 1.0 else (-1 if 1.5 <= t < 2.0 else 0)

    _, _, rows = _coupled(schedule, 2.6, speed_m_s=0.0)
    force, t = rows[:, 5], rows[:, 0]
    before = force[(t > 0.4) & (t < 0.5)].mean()
    pressurized = force[(t > 1.3) & (t < 1.5)].mean()
    released = force[(t > 2.4) & (t < 2.6)].mean()
    print(f"0.5 s pressurize: {pressurized - before:+.0f} N, "
          f"0.5 s release: {released - pressurized:+.0f} N")
    assert 1.5e3 < pressurized - before < 5e3
    assert 1.5e3 < pressurized - released < 5e3
