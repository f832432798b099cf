"""One closed-loop run of an operating condition: :func:`simulate`.

A run is assembled from its validated :class:`~trackmj.sim.setup.RunSetup`: the architecture
builds the plant, the registries the controller and estimator, and the one loop
(:func:`trackmj.sim.loop.run_loop`) moves the data; the recorder, the physics guard, the
progress bar and the Rerun playback watch it as observers.

Runs are deterministic per seed: the sensor noise is drawn from ``default_rng([seed, 1])``,
the terrain from ``default_rng([seed, 8608])``; a controller solve that overruns its period
is still applied (in a simulation the plant waits) and counted as ``controller_overruns``;
only solver failures fall back.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from trackmj.control.sensors import Sensors
from trackmj.control.valves import ValveLogic
from trackmj.host import machine as host_machine
from trackmj.hydraulics.tensioner import FLOW_NAMES
from trackmj.machines.drive_load import drive_load
from trackmj.ports import (
    COLUMN_UNITS,
    COUPLING_STEP_S,
    Controller,
    Estimator,
    Observer,
    StepInputs,
    steps_per_period,
)
from trackmj.results.comparison import prediction_vs_measured
from trackmj.results.measured import load_measured
from trackmj.results.metrics import compute_metrics
from trackmj.results.store import Result, run_metadata
from trackmj.scenarios.resolved import Scenario
from trackmj.sim.architectures import Assembly, assemble
from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS
from trackmj.sim.drive import DerailmentChecks
from trackmj.sim.loop import Schedule, run_loop
from trackmj.sim.mechanics import settled_end_stop
from trackmj.sim.observers import (
    CHANNEL_SETS,
    ChannelRecorder,
    PhysicsGuard,
    PhysicsLimits,
    PlaybackFrames,
    Progress,
    Recorder,
    capture_mujoco_warnings,
)
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE
from trackmj.sim.setup import Overrides, RunSetup, prepare
from trackmj.sim.w3_hitch import calibrated_setup
from trackmj.validator import ParameterError

if TYPE_CHECKING:
    from trackmj.results.measured import MeasuredLog
    from trackmj.results.playback import PlaybackRecorder

FRAME_EVERY_STEPS = 20
"""Rerun scene frames every 20 ms of simulated time."""


def schedule(setup: RunSetup, horizon_steps: int, period_s: float) -> Schedule:
    """The scenario's per-step inputs and per-period reference previews for ``setup``."""
    sc, h, steps = calibrated_setup(setup).scenario, COUPLING_STEP_S, setup.steps
    scale = setup.variant.pretension_scale
    t_end = h * np.arange(1, steps + 1)        # end of each step
    t_start = t_end - h
    speed = sc.track_speed_m_s(t_end)
    pull, down = sc.hitch_force_N(t_start)
    supply = sc.supply_setpoint_Pa(t_end, setup.hydraulics.supply.setpoint_Pa)
    inputs = [StepInputs(*row) for row in zip(speed.tolist(), pull.tolist(), down.tolist(),
                                               supply.tolist(), strict=True)]
    t_control = h * np.arange(0, steps, steps_per_period(period_s, h))
    previews = sc.reference_N(t_control[:, None] + period_s * np.arange(horizon_steps + 1))
    return Schedule(inputs, previews * scale, sc.reference_N(t_end) * scale)


def physics_limits(setup: RunSetup, stroke_range_m: tuple[float, float]) -> PhysicsLimits:
    """Vacuum at the hydraulic file's atmospheric pressure; the element's travel
    ``stroke_range_m`` [m] (``ports.Element.stroke_range_m``)."""
    hyd = setup.hydraulics
    return PhysicsLimits(vacuum_Pa=-hyd.accumulator.atmospheric_pressure_Pa_abs,
                         stroke_range_m=stroke_range_m)


def simulate(scenario: Scenario | str | Path, *, architecture: str = REFERENCE_ARCHITECTURE,
             controller: str | None = None, estimator: str | None = None, seed: int = 0,
             duration: float | None = None, variant: str = "nominal",
             model: str | Path | None = None, hydraulics: str | Path | None = None,
             control: str | Path | None = None, set: Overrides | None = None,
             rrd: str | Path | None = None, progress: bool = False,
             tp_result: Result | None = None, tensioner: str | Path | None = None,
             machine: str | Path | None = None, measured: str | Path | None = None,
             channels: str = "default") -> Result:
    """Run one operating condition in closed loop.

    Parameters
    ----------
    scenario : Scenario, str or Path
        A loaded scenario, a built-in name (``"W1"`` .. ``"W5"``) or a scenario TOML file.
    architecture : str
        Coupling architecture, a key of :data:`trackmj.sim.registry.ARCHITECTURES`
        (``"tp"``, ``"tp-weak"``, ``"dp-a"``, ``"dp-b"``).
    controller, estimator : str, optional
        Keys of the controller and estimator registries; default: the scenario's. A
        controller FMU: ``"fmu:FILE.toml"`` (see :mod:`trackmj.fmi.controller_fmu`).
    seed : int
        Sensor-noise and terrain seed (>= 0).
    duration : float, optional
        Simulated time [s]; default: the scenario's ``duration_s``.
    variant : str
        Name of a scenario variant (W5 perturbations); ``"nominal"`` by default.
    model, hydraulics, control : str or Path, optional
        Parameter files replacing the machine's (``models/lf1352*.toml`` by default).
    set : mapping or sequence of str, optional
        Overrides of file keys, ``{"hydraulics.fluid.bulk_modulus_Pa": 1.2e9}`` or
        ``["hydraulics.fluid.bulk_modulus_Pa=1.2e9"]`` (the CLI's ``--set``); KIND is
        ``model``, ``hydraulics``, ``control`` or ``scenario``. Validated like the files.
    rrd : str or Path, optional
        Write a Rerun recording of the run there (track architectures).
    progress : bool
        Show a progress bar over simulated seconds.
    tp_result : Result, optional
        For ``dp-a``: the tp run whose track load is replayed (run here if None).
    tensioner : str or Path, optional
        A tensioner file (:mod:`trackmj.elements.tensioner_file`: an FMU or a passive spring-damper)
        replacing the hydraulic plugin of tp, tp-weak and dp-a.
    machine : str or Path, optional
        A shipped machine's name (``trackmj machines``) or a machine file
        (``*_machine.toml``, see :mod:`trackmj.machines.assembly`); default ``"lf1352"``.
    measured : str or Path, optional
        A measured log (:mod:`trackmj.results.measured`: CSV or Parquet, ``t_s`` and any of the
        run's columns, e.g. ``tension_N``, ``p_head [MPa]``); the metrics get
        ``prediction_vs_measured`` (:func:`trackmj.results.comparison.prediction_vs_measured`).
    channels : str
        ``"default"``: the contract columns; ``"all"``: also per-cylinder pressures, valve
        flows, strand tensions and the hitch load, with units
        (:class:`trackmj.sim.observers.ChannelRecorder`).

    Returns
    -------
    Result
        The 1 kHz timeseries (see :mod:`trackmj.results.store`) and the metrics.

    Raises
    ------
    trackmj.validator.ParameterError
        An input is invalid (raised before anything is built).
    trackmj.errors.PhysicsError
        The run left physics (MuJoCo warning, non-finite state, pressure below vacuum,
        stroke outside the travel, loop closure broken; an FMU's force beyond its limit).
    trackmj.errors.FmuError
        An FMU failed during the run (the message names the FMU and the call).
    """
    _check_channels(channels)
    setup = prepare(scenario, architecture=architecture, controller=controller,
                    estimator=estimator, seed=seed, duration=duration, variant=variant,
                    model=model, hydraulics=hydraulics, control=control, overrides=set,
                    tensioner=tensioner, machine=machine)
    log = None if measured is None else measured_log(setup, measured, channels)
    return run(setup, rrd=rrd, progress=progress, tp_result=tp_result, measured=log,
               channels=channels)


def _check_channels(channels: str) -> None:
    if channels not in CHANNEL_SETS:
        raise ParameterError(f"channels = {channels!r}: allowed {', '.join(CHANNEL_SETS)}")


def measured_log(setup: RunSetup, path: str | Path,
                 channels: str = "default") -> MeasuredLog:
    """The measured log at ``path`` on the run's grid, checked against the columns the run
    records with ``channels`` and its duration before the run (ParameterError naming the
    file and column)."""
    names = list(COLUMN_UNITS)
    if channels == "all":
        names += [*EXTRA_CHANNELS, *(f"q_{n}_m3_s" for n in FLOW_NAMES)]
    return load_measured(path, setup.duration_s, names)


EXTRA_CHANNELS = ("p_head_L_Pa", "p_head_R_Pa", "p_line_A_Pa", "upper_strand_tension_N",
                  "lower_strand_tension_N", "hitch_pull_N", "hitch_down_N")
"""Columns of ``channels="all"`` besides the flows (:class:`ChannelRecorder`) that a
measured log may hold too."""


def run(setup: RunSetup, *, rrd: str | Path | None = None, progress: bool = False,
        tp_result: Result | None = None,
        measured: MeasuredLog | None = None, channels: str = "default") -> Result:
    """Run a prepared setup (see :func:`simulate` for the arguments and the result;
    ``measured``: a log from :func:`measured_log`)."""
    _check_channels(channels)
    setup = calibrated_setup(setup)
    if ARCHITECTURES[setup.architecture].replays_tp and tp_result is None:
        tp_result = run(dataclasses.replace(setup, architecture=REFERENCE_ARCHITECTURE))
    with capture_mujoco_warnings() as warnings:
        asm = assemble(setup, tp_result)
        on_stop = None if asm.track is None else settled_end_stop(asm.track)
        controller, estimator, sensors = _blocks(setup, asm)
        sched = schedule(setup, controller.horizon_steps, controller.period_s)
        watch = _watch(setup, asm, sched, warnings, channels=channels, progress=progress,
                       rrd=rrd)
        wall = _run_watched(sched, asm, controller, estimator, sensors, watch)
    meta = run_metadata(setup.scenario.name, setup.architecture, setup.controller,
                        setup.estimator, setup.seed, host_machine(),
                        machine=setup.machine.name, variant=setup.variant.name,
                        duration_s=setup.duration_s, files=setup.files,
                        overrides=setup.overrides,
                        running=setup.scenario.running(setup.duration_s))
    result = Result(watch.recorder.table(meta, watch.extra), {})
    result.metrics = _run_metrics(setup, asm, result, watch.recorder, controller, wall,
                                  measured)
    if watch.derailment is not None:
        result.metrics |= watch.derailment.metrics()
    if on_stop is not None:
        result.metrics["settled_on_end_stop"] = on_stop | {
            "grade": setup.scenario.terrain.grade}
    if watch.playback is not None:
        watch.playback.log_timeseries(result)
        watch.playback.close()
    return result


def _blocks(setup: RunSetup, asm: Assembly) -> tuple[Controller, Estimator, Sensors]:
    """The run's controller and estimator from their registries, and its sensors."""
    cfg = asm.control
    entry = CONTROLLERS[setup.controller]
    available = {"controller_file": setup.controller_file}
    controller = entry.build(asm.model, cfg, **{n: available[n] for n in entry.needs})
    estimator = ESTIMATORS[setup.estimator].build(asm.model, cfg, COUPLING_STEP_S,
                                                  asm.initial_estimate)
    # the run owns this generator: its noise can be drawn a second ahead (same numbers)
    sensors = Sensors(cfg.sensors, np.random.default_rng([setup.seed, 1]), block=1000)
    return controller, estimator, sensors


@dataclass(frozen=True)
class _Watch:
    """The loop's observers in calling order (``all``), and those the run reads afterwards:
    the recorder, the extra channels (``channels="all"``), the progress bar, the Rerun
    recording (None when not asked for) and the derailment checks (None without a MuJoCo
    track)."""

    all: list[Observer]
    recorder: Recorder
    extra: ChannelRecorder | None
    bar: Progress | None
    playback: PlaybackRecorder | None
    derailment: DerailmentChecks | None


def _watch(setup: RunSetup, asm: Assembly, sched: Schedule, warnings: list[str], *,
           channels: str, progress: bool, rrd: str | Path | None) -> _Watch:
    """The recorder, the physics guard and, on a MuJoCo track, the derailment checks; then
    as asked the extra channels, the progress bar and the Rerun recording (track
    architectures)."""
    recorder = Recorder(sched)
    element = asm.element
    guard = PhysicsGuard(physics_limits(setup, element.stroke_range_m), warnings,
                         element.node_pressures, element.pressure_nodes)
    observers: list[Observer] = [recorder, guard]
    derailment = DerailmentChecks(asm.track) if asm.track is not None else None
    if derailment is not None:
        observers.append(derailment)
    extra = (ChannelRecorder(sched, asm.element, asm.track) if channels == "all"
             else None)
    if extra is not None:
        observers.append(extra)
    bar = Progress(setup.steps, f"{setup.scenario.name} {setup.architecture}") \
        if progress else None
    if bar is not None:
        observers.append(bar)
    playback = None
    if rrd is not None and asm.track is not None:
        # rerun (heavy, optional at run time) loads only when a recording is asked for
        from trackmj.results.playback import PlaybackRecorder

        playback = PlaybackRecorder(asm.track, rrd)
        observers.append(PlaybackFrames(playback, FRAME_EVERY_STEPS))
    return _Watch(observers, recorder, extra, bar, playback, derailment)


def _run_watched(sched: Schedule, asm: Assembly, controller: Controller, estimator: Estimator,
                 sensors: Sensors, watch: _Watch) -> float:
    """The loop under the observers; returns its wall time [s]. A failed run discards its
    Rerun recording; the progress bar is closed either way."""
    wall_start = time.perf_counter()
    try:
        run_loop(sched, controller=controller, valves=ValveLogic(asm.control.valves,
                                                                 COUPLING_STEP_S),
                 plant=asm.plant, sensors=sensors, estimator=estimator,
                 observers=watch.all)
    except BaseException:
        if watch.playback is not None:
            watch.playback.discard()   # no half-written recording
        raise
    finally:
        if watch.bar is not None:
            watch.bar.close()
    return time.perf_counter() - wall_start


def _takes_valve_mode(setup: RunSetup) -> bool:
    """Whether the run's tensioner takes the valve mode: the built-in elements do, a
    passive tensioner does not, an FMU does if an input is mapped to ``valve_mode``."""
    tensioner = setup.tensioner
    if tensioner is None:
        return True
    return tensioner.fmu is not None and "valve_mode" in tensioner.fmu.inputs.values()


def _run_metrics(setup: RunSetup, asm: Assembly, result: Result, recorder: Recorder,
                 controller: Controller, wall_s: float,
                 measured: MeasuredLog | None) -> dict:
    """metrics.json of the run: the scenario's metrics over its windows, the element's,
    the controller's counts, MuJoCo's warnings and, with a measured log, the comparison and
    the log's record (file, SHA-256, columns used and ignored)."""
    drive = drive_load(setup.model)
    windows = setup.scenario.metric_windows(setup.duration_s,
                                            link_pitch_m=setup.model.track.pitch_m,
                                            drive_load=(drive.gain_1_m, drive.tight_sign),
                                            body_mode_band_Hz=setup.body_mode_band_Hz)
    m = compute_metrics(result.columns(), windows, control_period_s=controller.period_s,
                        solve_times_s=recorder.solve_times_s,
                        solve_success=recorder.solve_success, wall_time_s=wall_s,
                        clipped_outputs=recorder.clipped,
                        valve_mode_applied=_takes_valve_mode(setup))
    m |= asm.element.run_metrics(setup.duration_s)
    m["controller_fallbacks"] = float(controller.statistics().fallbacks)
    m["controller_overruns"] = float(np.sum(np.array(recorder.solve_times_s)
                                            > controller.period_s))
    if asm.track is not None:
        m["mujoco_warnings"] = float(asm.track.warning_count)
    if measured is not None:
        m["prediction_vs_measured"] = prediction_vs_measured(result.columns(),
                                                             measured.columns, windows)
        m["measured_log"] = measured.record()
    return m
