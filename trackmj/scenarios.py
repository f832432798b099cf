"""Operating conditions W1-W5 as frozen dataclasses loaded from TOML.

``load_scenario("W1")`` reads ``experiments/W1.toml`` from the installed package
``trackmj.experiments``; any other argument is a path to a custom file. Invalid files raise
:class:`~trackmj.params.ParameterError` naming the file, the key and the allowed range or
values. Units are SI: s, N, Pa, m/s; forces are F_ten (the cylinder force on the idler
carrier, see README "Tension convention").

File layout (every table optional except ``[scenario]`` and ``[reference]``)::

    [scenario]    name, title, duration_s, seeds, controller, estimator
    [track]       speed_m_s, ramp_s
    [reference]   initial_N; [[reference.steps]] time_s, delta_N;
                  [[reference.ramps]] start_s, rate_N_s, end_s
    [supply]      mode, nominal_Pa; [[supply.drops]] start_s, end_s, pressure_Pa, transition_s
    [terrain]     kind, road_class, n_min_cycles_m, n_max_cycles_m, dx_m, x_start_m,
                  flat_until_m, taper_m, margin_m
    [[load_pulses]] start_s, end_s, delta_N, hitch_N, pull_angle_deg, rise_s
    [[variants]]  name, bulk_modulus_scale, friction_scale, contact_stiffness_scale,
                  pretension_scale
    [limits]      force_min_N, force_max_N
    [evaluation]  start_s, steady_start_s, settle_band_rel, min_hold_s
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np

from trackmj.metrics import MetricWindows
from trackmj.params import ParameterError, load_table, param, read_toml, validate
from trackmj.terrain import ISO8608_GD_N0_M3, RoadProfile, road_profile, taper_start

BUILTIN = ("W1", "W2", "W3", "W4", "W5")
CONTROLLERS = ("nmpc", "lmpc", "pid")
ESTIMATORS = ("ekf", "ukf")
SUPPLY_MODES = ("accumulator", "prescribed")
TERRAIN_KINDS = ("flat", "iso8608")
TERRAIN_SEED_SALT = 8608
"""Terrain RNG = default_rng([seed, 8608]): independent of the noise stream of the same seed."""


def _edge(t: np.ndarray, t0: float, rise_s: float) -> np.ndarray:
    """0 before t0, 1 after t0 + rise_s, linear between (a step at t >= t0 if rise_s = 0)."""
    if rise_s <= 0.0:
        return (t >= t0).astype(float)
    return np.clip((t - t0) / rise_s, 0.0, 1.0)


@dataclass(frozen=True)
class Track:
    """Sprocket-driven track speed [m/s], reached by a linear ramp from 0 over ramp_s [s]."""

    speed_m_s: float = param(0.0, 5.0)
    ramp_s: float = param(0.0, 10.0)


@dataclass(frozen=True)
class Step:
    """Reference step of delta_N [N] at time_s [s]."""

    time_s: float = param(0.0, None)
    delta_N: float = param(-50e3, 50e3)


@dataclass(frozen=True)
class Ramp:
    """Reference ramp of rate_N_s [N/s] from start_s to end_s [s] (end_s = inf: to the end)."""

    start_s: float = param(0.0, None)
    rate_N_s: float = param(-5e3, 5e3)
    end_s: float = math.inf


@dataclass(frozen=True)
class Reference:
    """F_ref(t) = initial_N + Σ steps + Σ ramps [N]."""

    initial_N: float = param(0.0, 50e3)
    steps: tuple[Step, ...] = ()
    ramps: tuple[Ramp, ...] = ()


@dataclass(frozen=True)
class SupplyDrop:
    """Supply pressure held at pressure_Pa from start_s to end_s [s], linear transitions of
    transition_s [s] at both ends (starting at start_s and at end_s)."""

    start_s: float = param(0.0, None)
    end_s: float = param(0.0, None)
    pressure_Pa: float = param(0.0, 30e6)
    transition_s: float = param(0.0, 5.0)


@dataclass(frozen=True)
class Supply:
    """Supply: ``accumulator`` (pump + accumulator + relief model; nominal_Pa is its initial
    pressure) or ``prescribed`` (p_s(t) = nominal_Pa with the drops applied) [Pa gauge]."""

    mode: str
    nominal_Pa: float = param(1e6, 30e6)
    drops: tuple[SupplyDrop, ...] = ()


@dataclass(frozen=True)
class Terrain:
    """Ground: ``flat`` or an ``iso8608`` random road of road_class over the spatial band
    [n_min, n_max] cycles/m on a grid of dx_m [m] from x_start_m; flat up to flat_until_m
    and blended in over taper_m [m]; extends margin_m [m] past the distance driven."""

    kind: str
    road_class: str
    n_min_cycles_m: float = param(1e-3, 100.0, open_low=True)
    n_max_cycles_m: float = param(1e-3, 100.0, open_low=True)
    dx_m: float = param(1e-3, 0.5)
    x_start_m: float = param(-100.0, 0.0)
    flat_until_m: float = param(-100.0, 100.0)
    taper_m: float = param(0.0, 100.0)
    margin_m: float = param(0.0, 100.0)


_TERRAIN_DEFAULTS = {"n_min_cycles_m": 0.011, "n_max_cycles_m": 2.83, "dx_m": 0.025,
                     "x_start_m": -5.0, "flat_until_m": 2.0, "taper_m": 1.0, "margin_m": 5.0}


@dataclass(frozen=True)
class LoadPulse:
    """Load disturbance from start_s to end_s [s] with linear edges of rise_s [s], applied
    physically as a force hitch_N [N] on the rear hitch along a line pull_angle_deg [deg]
    below the horizontal, rearward (> 0: a towed load, the sprocket drives harder and the
    rear is loaded; < 0: a pushing load, the sprocket brakes and the rear is unloaded; see
    :meth:`~trackmj.plant.TrackPlant.set_hitch_force`). delta_N [N] is the change of the
    hold-mode idler load the pulse is calibrated to (``experiments/calibrate_w3.py``)."""

    start_s: float = param(0.0, None)
    end_s: float = param(0.0, None)
    delta_N: float = param(-20e3, 20e3)
    hitch_N: float = param(-30e3, 30e3)
    pull_angle_deg: float = param(0.0, 60.0)
    rise_s: float = param(0.0, 1.0)


@dataclass(frozen=True)
class Variant:
    """Named parameter perturbation: multiplicative scales on the bulk modulus, the cylinder
    friction coefficient, the track contact stiffness and the initial pre-tension."""

    name: str
    bulk_modulus_scale: float = param(0.5, 2.0)
    friction_scale: float = param(0.5, 2.0)
    contact_stiffness_scale: float = param(0.5, 2.0)
    pretension_scale: float = param(0.5, 2.0)


NOMINAL = Variant("nominal", 1.0, 1.0, 1.0, 1.0)


@dataclass(frozen=True)
class Limits:
    """Admissible tension band [F_min, F_max] [N]."""

    force_min_N: float = param(0.0, 100e3)
    force_max_N: float = param(0.0, 100e3)


@dataclass(frozen=True)
class Evaluation:
    """Metric windows: tracking metrics from start_s, steady-state metrics from
    steady_start_s [s]; settling band relative to the final value; minimum hold [s]."""

    start_s: float = param(0.0, None)
    steady_start_s: float = param(0.0, None)
    settle_band_rel: float = param(0.0, 0.5, open_low=True)
    min_hold_s: float = param(0.0, 10.0)


@dataclass(frozen=True)
class Scenario:
    """One operating condition (see the module docstring for the file layout)."""

    name: str
    title: str
    source: Path
    duration_s: float = field(default=30.0,
                              metadata=param(0.0, 3600.0, open_low=True).metadata)
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    controller: str = "nmpc"
    estimator: str = "ekf"
    track: Track = field(default_factory=lambda: Track(1.5, 1.0))
    reference: Reference = field(default_factory=lambda: Reference(15e3))
    supply: Supply = field(default_factory=lambda: Supply("accumulator", 12e6))
    terrain: Terrain = field(default_factory=lambda: Terrain("flat", "D", **_TERRAIN_DEFAULTS))
    load_pulses: tuple[LoadPulse, ...] = ()
    variants: tuple[Variant, ...] = (NOMINAL,)
    limits: Limits = field(default_factory=lambda: Limits(10e3, 20e3))
    evaluation: Evaluation = field(default_factory=lambda: Evaluation(1.0, 5.0, 0.02, 0.5))

    # ------------------------------------------------------------------ signals
    def reference_N(self, t_s: np.ndarray | float) -> np.ndarray:
        """F_ref(t) [N], same shape as ``t_s`` (vectorised)."""
        t = np.asarray(t_s, dtype=float)
        f = np.full(t.shape, self.reference.initial_N)
        for s in self.reference.steps:
            f = f + np.where(t >= s.time_s, s.delta_N, 0.0)
        for r in self.reference.ramps:
            f = f + r.rate_N_s * np.clip(t - r.start_s, 0.0, r.end_s - r.start_s)
        return f

    def reference_preview(self, t0_s: float, n: int, dt_s: float) -> np.ndarray:
        """F_ref at t0 + k·dt for k = 0..n−1 [N], shape (n,) (the controller's preview)."""
        return self.reference_N(t0_s + dt_s * np.arange(n))

    def supply_pressure_Pa(self, t_s: np.ndarray | float) -> np.ndarray:
        """Prescribed supply pressure p_s(t) [Pa] (nominal with the drops), shape of t_s.

        In ``accumulator`` mode this is the set value the supply model starts from.
        """
        t = np.asarray(t_s, dtype=float)
        p = np.full(t.shape, self.supply.nominal_Pa)
        for d in self.supply.drops:
            on = _edge(t, d.start_s, d.transition_s) - _edge(t, d.end_s, d.transition_s)
            p = p + (d.pressure_Pa - self.supply.nominal_Pa) * on
        return p

    def track_speed_m_s(self, t_s: np.ndarray | float) -> np.ndarray:
        """Commanded track speed [m/s]: linear ramp from 0 over ramp_s, then constant."""
        t = np.asarray(t_s, dtype=float)
        return self.track.speed_m_s * _edge(t, 0.0, self.track.ramp_s)

    def hitch_force_N(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Rear-hitch load (pull rearward [N], push down [N]) in the chassis frame that
        applies the load pulses; each of shape of t_s."""
        pull = self._pulses(t_s, lambda p: p.hitch_N * math.cos(math.radians(p.pull_angle_deg)))
        down = self._pulses(t_s, lambda p: p.hitch_N * math.sin(math.radians(p.pull_angle_deg)))
        return pull, down

    def _pulses(self, t_s: np.ndarray | float,
                amplitude: Callable[[LoadPulse], float]) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        f = np.zeros(t.shape)
        for p in self.load_pulses:
            f = f + amplitude(p) * (_edge(t, p.start_s, p.rise_s) - _edge(t, p.end_s, p.rise_s))
        return f

    def terrain_profile(self, seed: int, duration_s: float | None = None) -> RoadProfile | None:
        """Road profile for ``seed`` (None for flat ground), long enough for the distance
        driven in ``duration_s`` (default: the scenario's) plus the margin."""
        tr = self.terrain
        if tr.kind == "flat":
            return None
        duration = self.duration_s if duration_s is None else duration_s
        distance = self.track.speed_m_s * max(duration - 0.5 * self.track.ramp_s, 0.0)
        length = distance + tr.margin_m - tr.x_start_m
        rng = np.random.default_rng([seed, TERRAIN_SEED_SALT])
        prof = road_profile(length, tr.dx_m, tr.road_class, rng, n_min=tr.n_min_cycles_m,
                            n_max=tr.n_max_cycles_m, x_start_m=tr.x_start_m)
        return taper_start(prof, tr.flat_until_m, tr.taper_m)

    def variant(self, name: str) -> Variant:
        """The variant called ``name``; KeyError listing the available ones."""
        for v in self.variants:
            if v.name == name:
                return v
        raise KeyError(f"{self.name}: no variant {name!r}; available: "
                       f"{[v.name for v in self.variants]}")

    def metric_windows(self, duration_s: float | None = None) -> MetricWindows:
        """Windows for :func:`trackmj.metrics.compute_metrics`: the first reference step
        (evaluated until the next step or ramp start), load pulses and supply drops as
        disturbances, the steady window from steady_start_s to the end."""
        duration = self.duration_s if duration_s is None else duration_s
        step = None
        if self.reference.steps:
            s0 = min(self.reference.steps, key=lambda s: s.time_s)
            later = [s.time_s for s in self.reference.steps if s.time_s > s0.time_s]
            later += [r.start_s for r in self.reference.ramps if r.start_s > s0.time_s]
            t_stop = min([*later, duration])
            before = float(self.reference_N(s0.time_s - 1e-9))
            step = (s0.time_s, before, before + s0.delta_N, t_stop)
        dist = tuple((p.start_s, p.end_s) for p in self.load_pulses)
        dist += tuple((d.start_s, d.end_s) for d in self.supply.drops)
        return MetricWindows(
            force_min_N=self.limits.force_min_N, force_max_N=self.limits.force_max_N,
            evaluation_start_s=self.evaluation.start_s, step=step, disturbances=dist,
            steady=(self.evaluation.steady_start_s, duration),
            settle_band_rel=self.evaluation.settle_band_rel,
            min_hold_s=self.evaluation.min_hold_s)


# ---------------------------------------------------------------------- loading

def scenario_path(name_or_path: str | Path) -> Path:
    """Path of a built-in scenario (``W1``..``W5``, case-insensitive) or of a custom file."""
    if isinstance(name_or_path, str) and name_or_path.upper() in BUILTIN:
        return Path(str(files("trackmj.experiments").joinpath(f"{name_or_path.upper()}.toml")))
    return Path(name_or_path)


def _choice(where: str, value: Any, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise ParameterError(f"{where} = {value!r} is not one of {list(allowed)}")
    return value


def _table(data: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise ParameterError(f"{where}: [{key}] must be a table")
    return dict(value)


def _array(data: dict[str, Any], key: str, where: str) -> list[dict[str, Any]]:
    value = data.pop(key, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ParameterError(f"{where}: [[{key}]] must be an array of tables")
    return value


def _with_defaults(cls: type, table: dict[str, Any], defaults: Any) -> dict[str, Any]:
    return {f.name: getattr(defaults, f.name) for f in fields(cls)} | table


def _windowed(where: str, start: float, end: Any) -> None:
    if isinstance(end, bool) or not isinstance(end, int | float) or math.isnan(end):
        raise ParameterError(f"{where}.end_s: expected a number, got {end!r}")
    if not end > start:
        raise ParameterError(f"{where}.end_s = {end!r} must be > start_s = {start!r}")


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a scenario by built-in name (``W1``..``W5``) or from a TOML path."""
    path = scenario_path(name_or_path)
    data = read_toml(path)
    f = path.name
    base = Scenario(name="", title="", source=path)

    unknown = set(data) - {"scenario", "track", "reference", "supply", "terrain",
                           "load_pulses", "variants", "limits", "evaluation"}
    if unknown:
        raise ParameterError(f"{f}: unknown table(s) {sorted(unknown)}")
    head = _table(data, "scenario", f)
    allowed = {"name", "title", "duration_s", "seeds", "controller", "estimator", "source"}
    if set(head) - allowed:
        raise ParameterError(f"{f} [scenario]: unknown key(s) {sorted(set(head) - allowed)}; "
                             f"allowed: {sorted(allowed - {'source'})}")
    if not isinstance(head.get("name"), str) or not head["name"]:
        raise ParameterError(f"{f} [scenario]: missing key 'name' (a non-empty string)")
    seeds = head.get("seeds", list(base.seeds))
    if (not isinstance(seeds, list) or not seeds
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds)):
        raise ParameterError(f"{f} [scenario].seeds = {seeds!r} must be a non-empty list of "
                             f"integers >= 0")
    duration = head.get("duration_s", base.duration_s)
    controller = _choice(f"{f} [scenario].controller", head.get("controller", "nmpc"),
                         CONTROLLERS)
    estimator = _choice(f"{f} [scenario].estimator", head.get("estimator", "ekf"), ESTIMATORS)

    track = load_table(Track, _with_defaults(Track, _table(data, "track", f), base.track),
                       f"{f} [track]")

    ref_t = _table(data, "reference", f)
    steps = tuple(load_table(Step, s, f"{f} [[reference.steps]][{i}]")
                  for i, s in enumerate(_array(ref_t, "steps", f"{f} [reference]")))
    ramps = []
    for i, r in enumerate(_array(ref_t, "ramps", f"{f} [reference]")):
        ramp = load_table(Ramp, r, f"{f} [[reference.ramps]][{i}]")
        _windowed(f"{f} [[reference.ramps]][{i}]", ramp.start_s, ramp.end_s)
        ramps.append(ramp)
    reference = load_table(Reference, ref_t, f"{f} [reference]")
    reference = Reference(reference.initial_N, steps, tuple(ramps))

    sup_t = _table(data, "supply", f)
    drops = []
    for i, d in enumerate(_array(sup_t, "drops", f"{f} [supply]")):
        drop = load_table(SupplyDrop, d, f"{f} [[supply.drops]][{i}]")
        _windowed(f"{f} [[supply.drops]][{i}]", drop.start_s, drop.end_s)
        drops.append(drop)
    supply = load_table(Supply, _with_defaults(Supply, sup_t, base.supply) | {"drops": ()},
                        f"{f} [supply]")
    _choice(f"{f} [supply].mode", supply.mode, SUPPLY_MODES)
    if drops and supply.mode != "prescribed":
        raise ParameterError(f"{f} [supply].mode = {supply.mode!r}: [[supply.drops]] need "
                             f"mode = 'prescribed'")
    supply = Supply(supply.mode, supply.nominal_Pa, tuple(drops))

    terrain = load_table(Terrain, _with_defaults(Terrain, _table(data, "terrain", f),
                                                 base.terrain), f"{f} [terrain]")
    _choice(f"{f} [terrain].kind", terrain.kind, TERRAIN_KINDS)
    _choice(f"{f} [terrain].road_class", terrain.road_class, tuple(ISO8608_GD_N0_M3))
    if terrain.n_max_cycles_m <= terrain.n_min_cycles_m:
        raise ParameterError(f"{f} [terrain].n_max_cycles_m = {terrain.n_max_cycles_m!r} must "
                             f"be > n_min_cycles_m = {terrain.n_min_cycles_m!r}")
    if terrain.n_max_cycles_m > 0.5 / terrain.dx_m:
        raise ParameterError(f"{f} [terrain].n_max_cycles_m = {terrain.n_max_cycles_m!r} "
                             f"exceeds the grid's Nyquist 1/(2 dx_m) = {0.5 / terrain.dx_m:g}")

    pulses = []
    for i, p in enumerate(_array(data, "load_pulses", f)):
        pulse = load_table(LoadPulse, p, f"{f} [[load_pulses]][{i}]")
        _windowed(f"{f} [[load_pulses]][{i}]", pulse.start_s, pulse.end_s)
        pulses.append(pulse)

    variants = []
    for i, v in enumerate(_array(data, "variants", f)):
        where = f"{f} [[variants]][{i}]"
        if not isinstance(v.get("name"), str) or not v["name"]:
            raise ParameterError(f"{where}: missing key 'name' (a non-empty string)")
        variants.append(load_table(Variant, _with_defaults(Variant, v, NOMINAL), where))
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ParameterError(f"{f} [[variants]]: duplicate names in {names}")

    limits = load_table(Limits, _with_defaults(Limits, _table(data, "limits", f), base.limits),
                        f"{f} [limits]")
    if limits.force_max_N <= limits.force_min_N:
        raise ParameterError(f"{f} [limits].force_max_N = {limits.force_max_N!r} must be > "
                             f"force_min_N = {limits.force_min_N!r}")
    evaluation = load_table(Evaluation, _with_defaults(Evaluation, _table(data, "evaluation", f),
                                                       base.evaluation), f"{f} [evaluation]")

    scenario = Scenario(
        name=head["name"], title=str(head.get("title", head["name"])), source=path,
        duration_s=duration, seeds=tuple(seeds), controller=controller, estimator=estimator,
        track=track, reference=reference, supply=supply, terrain=terrain,
        load_pulses=tuple(pulses), variants=tuple(variants) or (NOMINAL,), limits=limits,
        evaluation=evaluation)
    validate(scenario, f"{f} [scenario]")
    return scenario
