"""The one closed loop: every architecture, and the reduced plant of the control tests.

Per 1 ms coupling step k (t = k·h), data flows one way through the ports of
:mod:`trackmj.ports`:

    controller (every period) -> valve logic -> plant (tensioner element -> mechanics)
    -> sensors -> estimator -> observers

The controller sees the estimator's mean posterior over the past period and the reference
preview F_ref(t + i·period), i = 0..N; it is told the supply pressure of the step
(a supply-pressure transducer). Its output u is held until its next period; an output
outside the port's range [−1, 1] is clipped here, the one place (NaN counts as −1, release,
as the valve logic takes it): the :class:`~trackmj.ports.Command` carries the clipped u and
``solved`` the output as given, so an observer counts the clipping. The loop never asks
which plant, controller or estimator it has.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackmj.ports import (
    COUPLING_STEP_S,
    Command,
    Controller,
    Estimator,
    Observer,
    Plant,
    Sensors,
    StepInputs,
    ValveLogic,
    positional,
    steps_per_period,
)

_command = positional(Command, ("mode", "u", "solved"))
"""Command from (mode, u, solved), checked against its fields at import."""


@dataclass(frozen=True)
class Schedule:
    """The scenario as the loop consumes it.

    inputs: one :class:`~trackmj.ports.StepInputs` per step, shape (steps,);
    previews: reference preview per controller period [N], shape (periods, N + 1), row j
    for t = j·period; reference_N: F_ref at the end of every step [N], shape (steps,).
    t_s: end of every step, (k + 1)·h [s], shape (steps,).
    """

    inputs: Sequence[StepInputs]
    previews: NDArray[np.float64]
    reference_N: NDArray[np.float64]

    @property
    def t_s(self) -> NDArray[np.float64]:
        return COUPLING_STEP_S * np.arange(1, len(self.inputs) + 1, dtype=np.float64)

    @property
    def steps(self) -> int:
        return len(self.inputs)


def run_loop(schedule: Schedule, *, controller: Controller, valves: ValveLogic, plant: Plant,
             sensors: Sensors, estimator: Estimator, observers: Sequence[Observer]) -> None:
    """Run ``schedule.steps`` coupling steps of the closed loop (see the module docstring).

    An observer that raises (a physics guard, Ctrl-C) ends the run; nothing is caught here.
    """
    h = COUPLING_STEP_S
    ratio = steps_per_period(controller.period_s, h)
    u = 0.0
    # bound once: this runs every 1 ms step
    valve_step, plant_step, measure = valves.step, plant.step, sensors.measure
    estimate, watchers = estimator.step, [observer.on_step for observer in observers]
    for k, inputs in enumerate(schedule.inputs):
        solved = None
        if k % ratio == 0:
            controller.set_parameters(supply_pressure_Pa=inputs.supply_set_Pa)
            solved = controller(estimator.period_mean(), schedule.previews[k // ratio], k * h)
            u = solved.u
            if not -1.0 <= u <= 1.0:   # outside the port's range (NaN: release): clipped,
                u = 1.0 if u > 1.0 else -1.0   # the Command's u then differs from solved.u
        mode = valve_step(u)
        command = _command(Command, (mode, u, solved))
        readout = plant_step(command, inputs)
        z = measure((readout.p_head_Pa, readout.p_rod_Pa, readout.stroke_m),
                    readout.drive_torque_N_m)
        estimate(z, float(mode), inputs.supply_set_Pa)
        for on_step in watchers:
            on_step(k, readout, command)
