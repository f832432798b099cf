"""The recorder keeps steps in a buffer and copies them in chunks: what it returns is what
it was given, whenever it is asked, and a law built without the dataclass __init__ is the
same ForceLaw."""

from __future__ import annotations

import numpy as np

from trackmj.ports import Command, ControlOutput, ForceLaw, Readout, StepInputs, make_force_law
from trackmj.sim.loop import Schedule
from trackmj.sim.observers import Recorder


def _readout(k: int) -> Readout:
    return Readout(*(k + i / 16.0 for i in range(len(Readout._fields))))


def test_recorder_returns_every_step_given_mid_chunk_and_after_a_gap() -> None:
    steps = 2 * Recorder.CHUNK + 300
    sched = Schedule([StepInputs(0.0, 0.0, 0.0, 1.0)] * steps, np.zeros((1, 2)),
                     np.arange(steps, dtype=float))
    rec = Recorder(sched)
    given = {}
    for k in [*range(Recorder.CHUNK + 10), *range(Recorder.CHUNK + 50, steps)]:
        solved = ControlOutput(0.1 * k, True, 1e-4) if k % 10 == 0 else None
        rec.on_step(k, _readout(k), Command(k % 3 - 1, 0.5 - k / steps, solved))
        given[k] = (*_readout(k), k % 3 - 1, 0.5 - k / steps)
        if k in (5, Recorder.CHUNK - 1, Recorder.CHUNK + 9):
            cols = rec.columns()
            assert rec.rows == k + 1 and len(cols["t_s"]) == k + 1
    cols = rec.columns()
    assert rec.rows == steps
    table = rec.data   # the readout columns as given (columns() takes t_s from the grid)
    np.testing.assert_array_equal(cols["tension_N"], table[:, 1])
    for k, row in given.items():
        assert table[k].tolist() == list(row)
    assert np.isnan(table[Recorder.CHUNK + 10:Recorder.CHUNK + 50]).all()
    assert len(rec.solve_times_s) == sum(1 for k in given if k % 10 == 0)


def test_make_force_law_is_a_force_law() -> None:
    law = make_force_law(1.5e4, -2e5)
    assert type(law) is ForceLaw and law == ForceLaw(1.5e4, -2e5)
    assert hash(law) == hash(ForceLaw(1.5e4, -2e5)) and law.at(0.01) == 1.5e4 - 2e3
