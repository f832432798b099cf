"""Observers of the closed loop (``ports.Observer``): they see every completed step.

* :class:`Recorder`: the run's timeseries, column by name with its unit.
* :class:`PhysicsGuard`: stops a run that leaves physics, with the time and the value.
* :class:`Progress`: a progress bar over simulated seconds.
* :class:`PlaybackFrames`: scene frames for the Rerun recording.
"""

from __future__ import annotations

import contextlib
import math
from array import array
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import pyarrow as pa
from tqdm import tqdm

from trackmj.errors import PhysicsError
from trackmj.ports import (
    COMMAND_UNITS,
    COUPLING_STEP_S,
    READOUT_UNITS,
    REFERENCE_UNITS,
    Command,
    Element,
    Readout,
)
from trackmj.results.store import make_table
from trackmj.sim.loop import Schedule


class Recorder:
    """Records every step's readout and command into preallocated arrays.

    Columns are the :class:`~trackmj.ports.Readout` fields (units in
    :data:`~trackmj.ports.READOUT_UNITS`), ``valve_mode`` and ``u``, plus, from the
    schedule, the reference ``tension_ref_N`` and the time grid ``t_s`` = (k + 1)·h (exact,
    where the plant's clock accumulates steps); the controller's solves (wall time [s],
    success) are kept in :attr:`solve_times_s` and :attr:`solve_success`, and its outputs
    the loop clipped to [−1, 1] as (step k, output as given) in :attr:`clipped`.

    A step's values are appended to a flat float64 buffer (``array('d')``, one C call per
    readout) and copied into :attr:`data` :data:`CHUNK` steps at a time; the same float64
    values as writing each row. :meth:`columns`, :meth:`table` and :attr:`rows` include the
    steps not yet copied.
    """

    CHUNK = 1000
    """Steps kept before they are copied into :attr:`data` [-]."""

    def __init__(self, schedule: Schedule) -> None:
        self._n_readout = len(Readout._fields)
        self.names: tuple[str, ...] = (*Readout._fields, *COMMAND_UNITS)
        self.units: dict[str, str] = READOUT_UNITS | COMMAND_UNITS | REFERENCE_UNITS
        self._reference, self._time = schedule.reference_N, schedule.t_s
        self.data = np.full((schedule.steps, len(self.names)), np.nan)
        self._start = 0        # step of the first kept (not yet copied) step
        self._kept = 0         # steps kept
        self._values = array("d")   # their values, row after row
        self.solve_times_s: list[float] = []
        self.solve_success: list[bool] = []
        self.clipped: list[tuple[int, float]] = []

    @property
    def rows(self) -> int:
        """Steps recorded so far [-]."""
        return self._start + self._kept

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        if k != self._start + self._kept:   # not the next step: copy what is kept first
            self._write()
            self._start = k
        values = self._values
        values.extend(readout)
        values.append(command.mode)
        values.append(command.u)
        solved = command.solved
        if solved is not None:
            self.solve_times_s.append(solved.solve_time_s)
            self.solve_success.append(solved.success)
            if solved.u != command.u:   # the loop clipped it (NaN differs from everything)
                self.clipped.append((k, solved.u))
        self._kept += 1
        if self._kept == self.CHUNK:
            self._write()

    def _write(self) -> None:
        """Copy the kept steps into :attr:`data`."""
        n = self._kept
        if not n:
            return
        width = len(self.names)
        self.data[self._start:self._start + n] = np.frombuffer(
            self._values, dtype=np.float64).reshape(n, width)
        self._start += n
        self._kept = 0
        del self._values[:]

    def columns(self) -> dict[str, np.ndarray]:
        """Column name -> values of the steps recorded so far, shape (rows,)."""
        self._write()
        rows = self.rows
        cols = {name: self.data[:rows, i] for i, name in enumerate(self.names)}
        cols["tension_ref_N"] = self._reference[:rows]
        cols["t_s"] = self._time[:rows]
        return cols

    def table(self, metadata: Mapping[str, Any],
              extra: ChannelRecorder | None = None) -> pa.Table:
        """The recorded steps as an Arrow table with units and run ``metadata`` (and the
        ``extra`` channels' columns after the contract's)."""
        columns, units = self.columns(), dict(self.units)
        if extra is not None:
            columns |= extra.columns(self.rows)
            units |= extra.units
        return make_table(columns, units, metadata)


CHANNEL_SETS = ("default", "all")
"""``--channels``: the contract columns, or those and every channel below."""


class ChannelRecorder:
    """The extra channels of ``--channels all``: the element's own (``Element.channels``,
    e.g. the hydraulic element's per-cylinder head pressures and every valve flow), the
    MuJoCo track's ``upper_strand_tension_N`` and ``lower_strand_tension_N`` [N] (mean pin
    tension of the upper strand and of the rear lower run; none without a track), and the
    hitch load applied, ``hitch_pull_N`` (rearward) and ``hitch_down_N`` [N] in the chassis
    frame (the scenario's, whether the mechanics takes it or not)."""

    def __init__(self, schedule: Schedule, element: Element, track: Any) -> None:
        self._element, self._track = element, track
        self.units: dict[str, str] = dict(element.channels)
        self._n_element = len(self.units)
        if track is not None:
            self.units |= {"upper_strand_tension_N": "N", "lower_strand_tension_N": "N"}
        self._measured = list(self.units)
        self.data = np.full((schedule.steps, len(self._measured)), np.nan)
        self._hitch = np.array([(i.hitch_pull_N, i.hitch_down_N) for i in schedule.inputs])
        self.units |= {"hitch_pull_N": "N", "hitch_down_N": "N"}

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        row, n = self.data[k], self._n_element
        if n:
            row[:n] = self._element.channel_values()
        if self._track is not None:
            strands = self._track.strand_tensions_N()
            row[n:n + 2] = strands.upper_N, strands.lower_N

    def columns(self, rows: int) -> dict[str, np.ndarray]:
        """Column name -> values of the first ``rows`` steps, shape (rows,)."""
        cols = {name: self.data[:rows, i] for i, name in enumerate(self._measured)}
        cols["hitch_pull_N"], cols["hitch_down_N"] = self._hitch[:rows, 0], self._hitch[:rows, 1]
        return cols


_STATE = ("tension_N", "p_head_Pa", "p_rod_Pa", "stroke_m", "stroke_velocity_m_s")
"""Readout fields that must stay finite in every architecture."""


@dataclass(frozen=True)
class PhysicsLimits:
    """Bounds of a physical run (SI).

    vacuum_Pa: lowest admissible gauge pressure (absolute zero, −p_atm) [Pa];
    stroke_range_m: cylinder travel with the end stops' allowed penetration [m];
    closure_max_m: largest track loop closure gap [m] before the loop counts as broken.
    """

    vacuum_Pa: float
    stroke_range_m: tuple[float, float]
    closure_max_m: float = 5e-3


class PhysicsGuard:
    """Raises :class:`PhysicsError` at the first step that leaves physics: a MuJoCo warning
    (from ``warnings``, filled by :func:`capture_mujoco_warnings`), a non-finite readout,
    a pressure below vacuum, a stroke outside the travel the end stops must hold, or a loop
    closure gap beyond ``closure_max_m``.

    pressures: optional callable returning every node pressure of the element [Pa gauge],
    named by ``pressure_names`` (``ports.Element.node_pressures``; the readout's head
    pressure is the mean of the two heads; an element without pressures returns none);
    without it the readout's head, rod and supply pressures are checked.
    """

    def __init__(self, limits: PhysicsLimits, warnings: Sequence[str],
                 pressures: Callable[[], Sequence[float]] | None = None,
                 pressure_names: Sequence[str] = ()) -> None:
        self.limits = limits
        self.warnings = warnings
        self.pressures = pressures
        self.pressure_names = tuple(pressure_names)
        self._lo, self._hi = limits.stroke_range_m
        self._closure_max, self._vacuum = limits.closure_max_m, limits.vacuum_Pa

    def _fail(self, r: Readout, what: str) -> None:
        raise PhysicsError(f"t = {r.t_s:.3f} s: {what}; the run left physics and was stopped")

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        if self.warnings:
            self._fail(readout, f"MuJoCo warning: {self.warnings[0]}")
        _, tension, p_head, p_rod, _, stroke, velocity, _, _, _, _, _, closure, _ = readout
        if not math.isfinite(tension + p_head + p_rod + stroke + velocity):
            fields = readout._asdict()
            bad = [f"{name} = {fields[name]!r}" for name in _STATE
                   if not math.isfinite(fields[name])]
            self._fail(readout, "non-finite state (" + ", ".join(bad) + ")")
        if not self._lo <= stroke <= self._hi:
            self._fail(readout, f"stroke {stroke * 1e3:.1f} mm outside the travel "
                                 f"[{self._lo * 1e3:.1f}, {self._hi * 1e3:.1f}] mm the end stops "
                                 "must hold")
        if closure > self._closure_max:
            self._fail(readout, f"track loop closure gap {closure * 1e3:.1f} mm exceeds "
                                 f"{self.limits.closure_max_m * 1e3:.1f} mm")
        if self.pressures is not None:
            values, names = self.pressures(), self.pressure_names
        else:
            values, names = (readout.p_head_Pa, readout.p_rod_Pa,
                             readout.p_supply_Pa), ("head", "rod", "supply")
        vacuum = self._vacuum
        if values and min(values) < vacuum:   # NaN (no such node) never compares below
            name, value = min(zip(names, values, strict=True), key=lambda nv: nv[1])
            self._fail(readout, f"{name} pressure {value / 1e6:.3f} MPa gauge below vacuum "
                                 f"({vacuum / 1e6:.3f} MPa gauge)")


@contextlib.contextmanager
def capture_mujoco_warnings() -> Iterator[list[str]]:
    """Collect MuJoCo's warning messages into a list instead of its default handler (which
    prints and writes MUJOCO_LOG.TXT into the working directory); the previous handler is
    restored on exit. MuJoCo reports each kind of warning once per MjData."""
    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)


class Progress:
    """Progress bar over the run's simulated time (unit "simulated s"), updated every 0.1 s."""

    UPDATE_STEPS = 100

    def __init__(self, steps: int, description: str) -> None:
        self.bar = tqdm(total=steps, unit_scale=COUPLING_STEP_S, unit="simulated s",
                        desc=description, leave=False, mininterval=0.5,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} "
                                   "simulated s [{elapsed}<{remaining}]")

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        if (k + 1) % self.UPDATE_STEPS == 0:
            self.bar.update(self.UPDATE_STEPS)

    def close(self) -> None:
        self.bar.close()


class PlaybackFrames:
    """Logs a scene frame of ``recorder`` (a ``playback.PlaybackRecorder``) every
    ``every_steps`` steps (20 ms by default)."""

    def __init__(self, recorder: Any, every_steps: int = 20) -> None:
        self.recorder = recorder
        self.every = every_steps

    def on_step(self, k: int, readout: Readout, command: Command) -> None:
        if (k + 1) % self.every == 0:
            self.recorder.log_frame(readout.t_s)

