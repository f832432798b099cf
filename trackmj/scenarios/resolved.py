"""The resolved operating condition :class:`Scenario` (absolute values only, built by
:func:`~trackmj.scenarios.load.load_scenario`) and its evaluation: the time signals F_ref,
supply set-point, track speed and hitch load, the road profile of a seed and the windows
the metrics are measured in. Units are SI: s, N, Pa, m/s."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trackmj.hydraulics.params import PressureProfile
from trackmj.ports import COUPLING_STEP_S
from trackmj.results.measured import InputSignal
from trackmj.results.metric_windows import MetricWindows
from trackmj.scenarios.inputs import INPUT_NAMES, read_inputs
from trackmj.scenarios.schema import (
    REFERENCE_MAX_N,
    STUDY_BODY_MODE_BAND_HZ,
    TRACK_SPEED_MAX_M_S,
    Evaluation,
    Header,
    Hitch,
    Limits,
    LoadPulse,
    Reference,
    ScenarioFile,
    Supply,
    Terrain,
    Track,
    Variant,
    present,
    reference_signal,
)
from trackmj.track.terrain import RoadProfile, check_grade_held, road_profile, taper_start
from trackmj.validator import Location, ParameterError, construct

TERRAIN_SEED_SALT = 8608
"""Terrain RNG = default_rng([seed, 8608]): independent of the noise stream of the same seed."""
ZERO_TRANSITION_S = 1e-6
"""A set-point drop with transition_s = 0 reaches the HydraulicTensioner as a ramp this long
ending at the edge [s] (a profile's times are strictly increasing; steps are 1 ms)."""


def _edge(t: np.ndarray, t0: float, rise_s: float) -> np.ndarray:
    """0 before t0, 1 after t0 + rise_s, linear between (a step at t >= t0 if rise_s = 0)."""
    if rise_s <= 0.0:
        return (t >= t0).astype(float)
    return np.clip((t - t0) / rise_s, 0.0, 1.0)



@dataclass(frozen=True)
class HitchCalibration:
    """Hitch forces calibrated for one machine (:mod:`trackmj.sim.w3_hitch`): the
    machine's name, per load pulse the hitch force [N] (None for a pulse whose file gives
    hitch_N), where the forces came from ("committed": ``experiments/W3_calibration.toml``;
    "cache": the user's cache directory; "calibrated": measured in this process), the
    hash of the inputs that determine them and, per pulse whose target is out of the
    machine's reach (its force then the trial furthest towards it), why and what it does (one
    line each)."""

    machine: str
    hitch_N: tuple[float | None, ...]
    origin: str
    inputs_sha256: str
    out_of_reach: tuple[str, ...] = ()


@dataclass(frozen=True)
class Scenario:
    """One operating condition (the file layout: :mod:`trackmj.scenarios.schema`); built by
    :func:`~trackmj.scenarios.load.load_scenario`, checked again on construction
    (``dataclasses.replace``) by the same checks as the file. ``source`` is the file it was
    read from."""

    name: str
    title: str
    source: Path
    duration_s: float
    seeds: tuple[int, ...]
    controller: str
    estimator: str
    track: Track
    reference: Reference
    supply: Supply
    terrain: Terrain
    load_pulses: tuple[LoadPulse, ...]
    variants: tuple[Variant, ...]
    limits: Limits
    evaluation: Evaluation
    machines: tuple[str, ...] | None = None
    machines_reason: str = ""
    nominal_tension_N: float | None = None
    """The nominal tension the relative values were resolved with [N] (None: all absolute)."""
    hitch: Hitch | None = None
    hitch_calibration: HitchCalibration | None = None
    """The hitch forces of the pulses that give none, calibrated for the run's machine
    (set by :func:`trackmj.sim.w3_hitch.calibrated_setup`, which a run calls; None
    before)."""
    signals: Mapping[str, InputSignal] = dataclasses.field(init=False, compare=False,
                                                           repr=False)
    """The from_file inputs ("reference", "supply", "track", "hitch"), read on construction."""

    def __post_init__(self) -> None:
        self._check_tables()
        object.__setattr__(self, "signals", read_inputs(self.source.parent, {
            "reference": self.reference, "supply": self.supply, "track": self.track,
            "hitch": self.hitch}))

    def pulse_hitch_N(self, index: int) -> float:
        """Hitch force [N] of load pulse ``index``: the file's hitch_N, else the one
        calibrated for the machine; RuntimeError if neither (the scenario did not pass
        through :func:`trackmj.sim.w3_hitch.calibrated_setup`, which calibrates them)."""
        given = self.load_pulses[index].hitch_N
        if given is not None:
            return given
        cal = self.hitch_calibration
        calibrated = cal.hitch_N[index] if cal is not None and index < len(cal.hitch_N) else None
        if calibrated is not None:
            return calibrated
        raise RuntimeError(f"{self.name}: load pulse {index} has no hitch_N and no hitch "
                           "force calibrated for a machine (trackmj.sim.w3_hitch."
                           "calibrated_setup calibrates it)")

    def _check_tables(self) -> None:
        """The file's checks on the tables as held (ParameterError naming the scenario)."""
        header = construct(Header, Location(label=f"Scenario {self.name!r}", path=("scenario",)),
                           name=self.name, title=self.title, duration_s=self.duration_s,
                           seeds=self.seeds, controller=self.controller,
                           estimator=self.estimator, machines=self.machines,
                           machines_reason=self.machines_reason)
        construct(ScenarioFile, Location(label=f"Scenario {self.name!r}"), scenario=header,
                  track=self.track, reference=self.reference, supply=self.supply,
                  terrain=self.terrain, limits=self.limits, evaluation=self.evaluation,
                  load_pulses=self.load_pulses, variants=self.variants, hitch=self.hitch)

    def check_inputs(self, duration_s: float) -> None:
        """ParameterError naming the file and column if a from_file input does not cover a
        run of ``duration_s`` [s] (the run's, :func:`trackmj.sim.setup.prepare`), or a
        sample of F_ref from a file that the run reads leaves [0, 5 MN] or one of a track
        speed leaves ±5 m/s (naming the file's sample as written)."""
        for what, signal in self.signals.items():
            signal.check_covers(duration_s, INPUT_NAMES[what])
        for what, low, high, unit in (("reference", 0.0, REFERENCE_MAX_N, "N"),
                                      ("track", -TRACK_SPEED_MAX_M_S, TRACK_SPEED_MAX_M_S,
                                       "m/s")):
            signal = self.signals.get(what)
            if signal is not None:
                signal.check_range(duration_s, low, high, unit, INPUT_NAMES[what])

    def check_grade(self, ground_friction: float, where: str) -> None:
        """ParameterError unless the grade is below the ground's friction (``where`` names
        the key μ comes from; :func:`trackmj.track.terrain.check_grade_held`)."""
        check_grade_held(self.terrain.grade, ground_friction,
                         f"{self.source.name} [terrain].grade = ", where)

    def check_machine(self, machine: str) -> None:
        """ParameterError (one line, the reason) if the condition does not apply to
        ``machine`` (a shipped machine's name)."""
        if self.machines and machine not in self.machines:
            raise ParameterError(f"{self.source.name}: scenario {self.name} applies to "
                                 f"{', '.join(self.machines)} only, not {machine}: "
                                 f"{self.machines_reason}")

    # ------------------------------------------------------------------ signals
    def reference_N(self, t_s: np.ndarray | float) -> np.ndarray:
        """F_ref(t) [N], same shape as ``t_s`` (vectorised)."""
        if "reference" in self.signals:
            return self.signals["reference"](t_s)
        return reference_signal(self.reference, np.asarray(t_s, dtype=float))

    def reference_preview(self, t0_s: float, n: int, dt_s: float) -> np.ndarray:
        """F_ref at t0 + k·dt for k = 0..n−1 [N], shape (n,) (the controller's preview)."""
        return self.reference_N(t0_s + dt_s * np.arange(n))

    def supply_setpoint_Pa(self, t_s: np.ndarray | float, nominal_Pa: float) -> np.ndarray:
        """Supply set-point p_set(t) [Pa]: ``nominal_Pa`` (the hydraulic file's
        [supply].setpoint_Pa) with the drops applied, shape of t_s (vectorised)."""
        if "supply" in self.signals:
            return self.signals["supply"](t_s)
        t = np.asarray(t_s, dtype=float)
        p = np.full(t.shape, float(nominal_Pa))
        for d in self.supply.drops:
            on = _edge(t, d.start_s, d.transition_s) - _edge(t, d.end_s, d.transition_s)
            p = p + (present(d.pressure_Pa, "supply.drops.pressure_Pa") - nominal_Pa) * on
        return p

    def supply_setpoint_profile(self, nominal_Pa: float) -> Callable[[float], float] | None:
        """:meth:`supply_setpoint_Pa` as a piecewise-linear profile with breakpoints at the
        drops' edges (a zero transition becomes a 1 µs ramp ending at the edge), the file's
        signal of a from_file supply, or None without drops (constant ``nominal_Pa``)."""
        if "supply" in self.signals:
            signal = self.signals["supply"]
            return lambda t_s: float(signal(t_s))
        if not self.supply.drops:
            return None
        times = {0.0}
        for d in self.supply.drops:
            for edge in (d.start_s, d.end_s):
                times |= {edge, edge + d.transition_s if d.transition_s > 0.0
                          else max(edge - ZERO_TRANSITION_S, 0.0)}
        t = np.array(sorted(times))
        return PressureProfile(tuple(t.tolist()),
                               tuple(self.supply_setpoint_Pa(t, nominal_Pa).tolist()))

    def track_speed_m_s(self, t_s: np.ndarray | float) -> np.ndarray:
        """Commanded track speed [m/s]: linear ramp from 0 over ramp_s, then constant."""
        if "track" in self.signals:
            return self.signals["track"](t_s)
        t = np.asarray(t_s, dtype=float)
        speed, ramp = self._constant_track()
        return speed * _edge(t, 0.0, ramp)

    def distance_m(self, duration_s: float) -> float:
        """Track distance driven in ``duration_s`` [s] [m]."""
        if "track" in self.signals:
            t = np.linspace(0.0, duration_s, max(2, round(duration_s / COUPLING_STEP_S) + 1))
            return float(np.trapezoid(self.track_speed_m_s(t), t))
        speed, ramp = self._constant_track()
        return speed * max(duration_s - 0.5 * ramp, 0.0)

    def travel_range_m(self, duration_s: float) -> tuple[float, float]:
        """How far the track carries the vehicle back and forth from its start within
        ``duration_s`` [s]: (least, greatest) displacement [m], least <= 0 <= greatest
        (negative: reversing)."""
        if "track" not in self.signals:          # one way at a constant speed
            distance = self.distance_m(duration_s)
            return min(distance, 0.0), max(distance, 0.0)
        t = np.linspace(0.0, duration_s, max(2, round(duration_s / COUPLING_STEP_S) + 1))
        speed = self.track_speed_m_s(t)
        travelled = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1])
                                                     * np.diff(t))))
        return float(min(travelled.min(), 0.0)), float(max(travelled.max(), 0.0))

    def running(self, duration_s: float) -> dict[str, Any]:
        """How the track runs over ``duration_s`` [s], for a run's record: ``speed_m_s`` the
        constant commanded speed [m/s] (< 0 reversing; None for a file's trace),
        ``travel_m`` the (least, greatest) displacement from the start [m] and ``grade``
        (tan θ, > 0 uphill driving forward)."""
        speed = None if "track" in self.signals else self._constant_track()[0]
        return {"speed_m_s": speed, "travel_m": list(self.travel_range_m(duration_s)),
                "grade": self.terrain.grade}

    def steady_pace_m_s(self, duration_s: float) -> float:
        """Mean commanded track speed, either way (|v|), over the steady window
        [steady_start_s, duration] [m/s]: what sets the tooth-passing and road bands (the
        |speed| of a file's trace averaged there, so a shuttle's two directions add; the
        constant |speed| otherwise)."""
        if "track" not in self.signals:
            return abs(self._constant_track()[0])
        t = np.arange(self.evaluation.steady_start_s, duration_s, COUPLING_STEP_S)
        return float(np.mean(np.abs(self.track_speed_m_s(t)))) if len(t) else 0.0

    def _constant_track(self) -> tuple[float, float]:
        """The [track] speed [m/s] and ramp [s] of a track speed not read from a file."""
        return (present(self.track.speed_m_s, "track.speed_m_s"),
                present(self.track.ramp_s, "track.ramp_s"))

    def hitch_force_N(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Rear-hitch load (pull rearward [N], push down [N]) in the chassis frame that
        applies the load pulses (:meth:`pulse_hitch_N`); each of shape of t_s."""
        pull = self._pulses(t_s, lambda i, p: self.pulse_hitch_N(i)
                            * math.cos(math.radians(p.pull_angle_deg)))
        down = self._pulses(t_s, lambda i, p: self.pulse_hitch_N(i)
                            * math.sin(math.radians(p.pull_angle_deg)))
        if "hitch" in self.signals:
            load = self.signals["hitch"](t_s)
            angle = math.radians(present(self.hitch, "hitch").pull_angle_deg)
            pull, down = pull + load * math.cos(angle), down + load * math.sin(angle)
        return pull, down

    def _pulses(self, t_s: np.ndarray | float,
                amplitude: Callable[[int, LoadPulse], float]) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        f = np.zeros(t.shape)
        for i, p in enumerate(self.load_pulses):
            f = f + amplitude(i, p) * (_edge(t, p.start_s, p.rise_s)
                                       - _edge(t, p.end_s, p.rise_s))
        return f

    def terrain_profile(self, seed: int, duration_s: float | None = None) -> RoadProfile | None:
        """Road profile for ``seed`` (None for flat ground), long enough for the distance
        driven in ``duration_s`` (default: the scenario's) plus the margin."""
        tr = self.terrain
        if tr.kind == "flat":
            return None
        road = tr.road()
        duration = self.duration_s if duration_s is None else duration_s
        backward, forward = self.travel_range_m(duration)
        rng = np.random.default_rng([seed, TERRAIN_SEED_SALT])
        if backward >= 0.0:                      # forward only: from x_start_m behind it
            length = forward + road.margin_m - road.x_start_m
            start = road.x_start_m
        else:                                    # reversing: the road covers both ways
            start = min(backward - road.margin_m, road.x_start_m)
            length = max(forward + road.margin_m, -road.x_start_m) - start
        prof = road_profile(length, road.dx_m, road.road_class, rng, n_min=road.n_min_cycles_m,
                            n_max=road.n_max_cycles_m, x_start_m=start)
        return taper_start(prof, road.flat_until_m, road.taper_m, both_ways=backward < 0.0)

    def variant(self, name: str) -> Variant:
        """The variant called ``name``; KeyError listing the available ones."""
        for v in self.variants:
            if v.name == name:
                return v
        raise KeyError(f"{self.name}: no variant {name!r}; available: "
                       f"{[v.name for v in self.variants]}")

    def metric_windows(self, duration_s: float | None = None, *,
                       link_pitch_m: float | None = None,
                       drive_load: tuple[float, float] | None = None,
                       body_mode_band_Hz: tuple[float, float] | None = None) -> MetricWindows:
        """Windows for :func:`trackmj.results.metrics.compute_metrics`: the first reference step
        (evaluated until the next step or ramp start), load pulses and supply drops as
        disturbances, the steady window from steady_start_s to the end, and the
        ``[evaluation]`` settings. With the track's ``link_pitch_m`` [m] the tooth-passing
        band v/pitch·(1 ± tooth_band_rel) at the scenario's track speed (a link passes the
        sprocket every pitch); without it (or standing still) there is none. On an iso8608
        road the band it excites, speed × [n_min, n_max] cycles/m, is recorded too. With the
        machine's ``drive_load`` (g [1/m], σ; :mod:`trackmj.machines.drive_load`) the
        acceptance also takes the drive's floor under the idler load. The body-mode band
        [Hz] is the scenario's ``body_mode_band_Hz``, else the machine's
        ``body_mode_band_Hz`` (:func:`trackmj.sim.setup.machine_body_mode_band`), else the
        study's on LF1352 (:data:`~trackmj.scenarios.schema.STUDY_BODY_MODE_BAND_HZ`)."""
        duration = self.duration_s if duration_s is None else duration_s
        dist, labels, states = self._disturbances()
        ev, speed = self.evaluation, self.steady_pace_m_s(duration)
        return MetricWindows(
            force_min_N=present(self.limits.force_min_N, "limits.force_min_N"),
            force_max_N=present(self.limits.force_max_N, "limits.force_max_N"),
            evaluation_start_s=ev.start_s, step=self._first_step(duration), disturbances=dist,
            disturbance_labels=labels, disturbance_states=states,
            steady=(ev.steady_start_s, duration), settle_band_rel=ev.settle_band_rel,
            min_hold_s=ev.min_hold_s, lowpass_cutoff_Hz=ev.lowpass_cutoff_Hz,
            body_mode_band_Hz=(ev.body_mode_band_Hz or body_mode_band_Hz
                               or STUDY_BODY_MODE_BAND_HZ),
            tooth_passing_band_Hz=self._tooth_band_Hz(speed, link_pitch_m),
            road_band_Hz=self._road_band_Hz(speed), psd_resolution_Hz=ev.psd_resolution_Hz,
            psd_max_Hz=ev.psd_max_Hz, mean_window_s=ev.mean_window_s,
            recovery_band_rel=ev.recovery_band_rel, steady_window_s=ev.steady_window_s,
            recovery_within_s=ev.recovery_within_s,
            steady_offset_max_rel=ev.steady_offset_max_rel,
            reference_events_s=tuple(sorted({*(s.time_s for s in self.reference.steps),
                                             *(r.start_s for r in self.reference.ramps)})),
            drive_events_s=self._drive_events_s(),
            drive_load_gain_1_m=None if drive_load is None else drive_load[0],
            drive_tight_sign=None if drive_load is None else drive_load[1])

    def _drive_events_s(self) -> tuple[float, ...]:
        """The end of the track's start ramp [s], where the drive's traction transient ends
        (a steady window starts 2 s after it, as after a disturbance edge); none for a speed
        read from a file or a track standing still."""
        if "track" in self.signals:
            return ()
        speed, ramp = self._constant_track()
        return (ramp,) if speed > 0.0 else ()

    def _first_step(self, duration_s: float) -> tuple[float, float, float, float] | None:
        """The first reference step as (time [s], F_ref before [N], F_ref after [N], end of
        its evaluation [s]: the next step or ramp start, else ``duration_s``); None without
        steps."""
        if not self.reference.steps:
            return None
        s0 = min(self.reference.steps, key=lambda s: s.time_s)
        later = [s.time_s for s in self.reference.steps if s.time_s > s0.time_s]
        later += [r.start_s for r in self.reference.ramps if r.start_s > s0.time_s]
        t_stop = min([*later, duration_s])
        before = float(self.reference_N(s0.time_s - 1e-9))
        return (s0.time_s, before, before + present(s0.delta_N, "reference.steps.delta_N"),
                t_stop)

    def _disturbances(self) -> tuple[tuple[tuple[float, float], ...], tuple[str, ...],
                                     tuple[str, ...]]:
        """The load pulses' then the supply drops' windows (start, end) [s], their labels
        and each as a state a run can start in ("supply at 9 MPa")."""
        dist = tuple((p.start_s, p.end_s) for p in self.load_pulses)
        dist += tuple((d.start_s, d.end_s) for d in self.supply.drops)
        drops_MPa = [present(d.pressure_Pa, "supply.drops.pressure_Pa") / 1e6
                     for d in self.supply.drops]
        pulses = tuple(self._pulse_label(i) for i in range(len(self.load_pulses)))
        labels = pulses + tuple(f"supply drop to {x:g} MPa" for x in drops_MPa)
        states = pulses + tuple(f"supply at {x:g} MPa" for x in drops_MPa)
        return dist, labels, states

    def _pulse_label(self, index: int) -> str:
        """"load pulse +2 kN" (its hold-mode idler-load target), with the hitch force that
        applies it once known and "out of reach" when that force misses the target
        (:class:`HitchCalibration`)."""
        pulse = self.load_pulses[index]
        label = f"load pulse {present(pulse.delta_N, 'load_pulses.delta_N') / 1e3:+.3g} kN"
        cal = self.hitch_calibration
        hitch = pulse.hitch_N if pulse.hitch_N is not None else (
            cal.hitch_N[index] if cal is not None and index < len(cal.hitch_N) else None)
        if hitch is None:
            return label
        reach = ", out of reach" if cal is not None and any(
            f"load pulse {index} " in line for line in cal.out_of_reach) else ""
        return f"{label} (hitch {hitch / 1e3:+.2f} kN{reach})"

    def _tooth_band_Hz(self, speed_m_s: float,
                       link_pitch_m: float | None) -> tuple[float, float] | None:
        """Tooth-passing band |v|/pitch·(1 ± tooth_band_rel) [Hz], either way the track
        turns; None without a pitch or standing still."""
        if link_pitch_m is not None and speed_m_s != 0.0:
            f_tooth = abs(speed_m_s) / link_pitch_m
            rel = self.evaluation.tooth_band_rel
            return (f_tooth * (1.0 - rel), f_tooth * (1.0 + rel))
        return None

    def _road_band_Hz(self, speed_m_s: float) -> tuple[float, float] | None:
        """The band an iso8608 road excites, |speed| × [n_min, n_max] cycles/m [Hz]; None
        on flat ground."""
        if self.terrain.kind != "iso8608":
            return None
        road = self.terrain.road()
        return (abs(speed_m_s) * road.n_min_cycles_m, abs(speed_m_s) * road.n_max_cycles_m)
