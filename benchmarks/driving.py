"""Shared set-up of the MuJoCo benchmarks: the track spun up to 1.5 m/s on flat ground.

Both ``bench_model.py`` and ``bench_coupled.py`` time blocks from the same snapshot and
compare them with the bare ``mj_step``, so the snapshot, its restore and the timed bare block
live here once.
"""

from __future__ import annotations

import time

import mujoco

from trackmj.machines.track_plant import load_plant
from trackmj.track.foundation import step
from trackmj.track.plant import PassiveTensioner

SPEED_M_S = 1.5
"""Track speed of the benchmarks [m/s], reached by a 1 s ramp and held for 0.5 s."""


class DrivingSnapshot:
    """The default model driven to SPEED_M_S with the passive tensioner, and its state."""

    def __init__(self) -> None:
        self.plant = load_plant()
        self.passive = PassiveTensioner.from_params(self.plant.params)
        self.plant.run(self.passive, 1.5, lambda t: SPEED_M_S * min(1.0, t))
        d = self.plant.data
        self._state = (d.qpos.copy(), d.qvel.copy(), d.act.copy(), self.plant.time_s)

    def restore(self) -> None:
        """Put the plant back to the snapshot (state, time, derived quantities)."""
        d = self.plant.data
        d.qpos[:], d.qvel[:], d.act[:] = self._state[:3]
        self.plant.time_s = self._state[3]
        mujoco.mj_forward(self.plant.model, d)

    def bare_step_s(self, steps: int) -> float:
        """Wall time per bare step [s] from the snapshot over ``steps`` steps: MuJoCo and the
        ground foundation (:func:`trackmj.track.foundation.step`), with the passive law fixed once
        (preload + implicit damping) and no element port. MuJoCo's timers hold this block's
        totals afterwards."""
        self.restore()
        plant, m, d = self.plant, self.plant.model, self.plant.data
        law = self.passive.force_law(plant.time_s, plant.stroke_m, plant.stroke_velocity_m_s)
        tensioner = m.actuator("tensioner").id
        d.ctrl[tensioner] = law.force_N
        m.actuator_biasprm[tensioner, 2] = law.damping_N_s_m
        for timer in d.timer:
            timer.duration, timer.number = 0.0, 0
        start = time.perf_counter()
        foundation, springs = plant.foundation, plant.springs
        for _ in range(steps):
            step(m, d, foundation, springs)
        return (time.perf_counter() - start) / steps
