"""Calibration of parameter-file keys against measured logs: :func:`calibrate`.

The fit replays each log's **valve command** (its ``valve_mode`` column, and ``u`` if
given) through the plant of the spec's conditions (scenario, seed, duration; the track
speed, hitch load and supply of the scenario) in open loop, and compares the simulated
channels with the logged ones. Open loop because the closed loop is not a smooth function
of the parameters: measured on W1 (4 s, tp), changing the head-branch restrictor area by
1e-4 of its value changes the controller's valve decisions at 549 of 4000 steps, so the
whole trajectory jumps; with the logged command replayed, the same change moves the
trajectory smoothly, and the nominal values reproduce the logged run bit for bit. What
remains is the MuJoCo track's own roughness (contacts): a relative change of 1e-4 moves
the 2 Hz low-pass of F_ten by ~3 N beyond the linear trend, so the finite-difference step
is relative and large (``fd_step_rel``, default 3 %), where the trend dominates (measured
on a 3 s log of the same kind, 1 ms residuals, one-sided differences: with 0.3 % the
roughness inflates JᵀJ and the standard errors shrink 4-fold against 3 %; from 1 % to 3 %
they grow by half, from 3 % to 10 % by a quarter as the trend bends).

Residuals are the channels of the log that the run records (:data:`FIT_CHANNELS`), each
divided by its sensor's noise σ (the control file's ``[sensors]``: pressure and stroke;
F_ten by the head-pressure σ times the two head areas, assumed: no load cell in the
study), as block means over ``block_s`` (10 ms: white noise stays white with σ/√m; the
contact events below are not averaged out by it, 50 ms halves them) on the samples from
``start_s`` to the end. The parameters are scaled to θ ∈ [0, 1] over their
bounds (log-uniform for positive bounds); :func:`scipy.optimize.least_squares` (trust
region reflective, forward differences) fits them, optionally from the best of a
Latin-hypercube sample of ``start_points`` points evaluated in parallel on the Dask
executor (:class:`trackmj.study.executor.Executor`).

The 95 % intervals are x ± (t(0.975, n − p) + sqrt(4a/s²))·σ_x, with σ_x² the diagonal of
s²·(JᵀJ)⁻¹, J the Jacobian of the weighted residuals at the estimate (central
differences), s² = Σr²/(n − p), and a the cost's roughness near the estimate (1.16 times
the standard deviation of the cost over the estimate and 12 points 1e-3 away,
:func:`_roughness`). The first term is the sensor noise's; the second bounds how far the
estimate, a minimum of the rough cost, can sit from the minimum θ_s of its smooth part:
½δᵀJᵀJδ <= ε(θ_s) − ε(θ̂) <= 2a, 2a the one-sided 95 % bound on the rough part's difference
between two nearby points. Measured (AMD EPYC 2-core VM; the test's 2.5 s log and four
more of its kind, two keys, 16 probe points each): the rough part takes discrete levels as
contact events flip. On four logs of 23-35 valve switches its sd over the estimate and the
16 points is 0.18-0.29 cost units; a = 0.21-0.46 (the fit's probe draw, and four more
draws on two of the logs), the second term 1.0-1.4 σ_x: intervals ±3.0-3.6 %, the truth
inside. On one log of 23 switches the fit ends in a pocket: two thirds of its
neighbourhood cost 36-38 units more, and the true values (4.4 σ_x away in the bulk
modulus) cost less than the estimate; a = 16-21 in five draws, ±9-10 %, the truth
inside: such a step must count in full, so a is not a statistic robust to it. Half the
range of 4 points instead (the rule before) grew with the number of points and spread
2-4-fold with their draw on the other logs (0.14-0.33 on the test's log, where the truth
needs a >= 0.145; 0.16-0.61 on another). Without the term the true values fell outside in
one of two noise draws.
Both terms assume the model is the plant: a model error leaves correlated residuals and
the intervals are then too narrow. Intervals are cut to the bounds. A key is **not
determined** (``determined``, and a line in ``warnings``) when the logs' channels do not
change with it, alone or along a direction shared with other keys (an eigenvalue of JᵀJ's
correlation form below :data:`UNDETERMINED_EIGENVALUE`: a valve that never moves, a
viscosity the channels do not see), or when its interval covers its bounds; ``warnings``
also names each log channel the fitted run misses by :data:`MISMATCH_NOISE_RATIO` times
its sensor σ or more (a dead sensor, an offset, a key not fitted), whatever the intervals
say.

Logs are read as a run's measured logs (:func:`trackmj.results.measured.read_trace`):
headers in any unit pint knows of the column's dimension (``p_head [psi]``,
``tension_lbf``, ``stroke [in]``), converted to SI; a fitted or command column in an unknown
or misfitting unit is refused naming the file and the column (exit 2). ``calibration.json``
records each log (``logs``: path, file name, SHA-256, ``columns_used`` {SI name: header} and
``columns_ignored``: every header the fit does not use, naming no quantity or one it does
not fit) and each estimate's unit (``units.estimates``, the unit its file declares);
``calibration.png`` shows the estimates in those units, and per channel the measured trace
behind the start and fitted runs with the residual measured − fitted below it.

The spec file (which keys, within which bounds, under which conditions) is
:mod:`trackmj.study.calibrate_spec`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import norm, qmc
from scipy.stats import t as student_t

from trackmj.errors import PhysicsError
from trackmj.ports import COLUMN_UNITS, COUPLING_STEP_S, Command, Readout
from trackmj.results.columns import display_unit, key_unit
from trackmj.results.measured import TIME, Trace, log_record, read_trace, run_grid
from trackmj.results.store import ResultWriter
from trackmj.sim.architectures import assemble
from trackmj.sim.observers import PhysicsGuard, capture_mujoco_warnings
from trackmj.sim.run import physics_limits, schedule
from trackmj.sim.setup import RunSetup, overrides_by_kind, prepare
from trackmj.study.calibrate_spec import CalibrateTable, load_spec
from trackmj.study.executor import Executor
from trackmj.validator import ParameterError

FIT_CHANNELS = ("tension_N", "p_head_Pa", "p_rod_Pa", "stroke_m")
"""Log columns the fit compares with the replayed run (any subset, at least one)."""
CALIBRATION_JSON = "calibration.json"
CALIBRATION_PNG = "calibration.png"
CONFIDENCE = 0.95


@dataclass(frozen=True)
class Log:
    """One measured log on the run's grid: the valve command replayed and the channels
    compared, shape (steps,) each; the file's name and SHA-256, the columns used (SI name
    -> header as written) and the headers the fit does not use (naming no quantity, or a
    quantity it does not fit)."""

    file: str
    mode: np.ndarray
    u: np.ndarray
    channels: dict[str, np.ndarray]
    sha256: str
    used: dict[str, str]
    ignored: tuple[str, ...]
    missing: Mapping[str, int]

    def record(self) -> dict[str, Any]:
        """JSON-ready ``{"file", "sha256", "columns_used", "columns_ignored",
        "missing_samples"}``."""
        return log_record(self.file, self.sha256, self.used, self.ignored, self.missing)


def load_log(path: str | Path, duration_s: float) -> Log:
    """Read a log for a fit of ``duration_s`` [s] (headers parsed and converted to SI by
    :func:`trackmj.results.measured.read_trace`): it needs ``valve_mode`` and at least one
    of :data:`FIT_CHANNELS`; ParameterError naming the file and column otherwise."""
    trace = read_trace(path)
    trace.require(["valve_mode"])
    channels = [c for c in FIT_CHANNELS if c in trace.columns]
    if not channels:
        others = [h for n, h in trace.headers.items() if n not in (TIME, "valve_mode", "u")]
        ignored = f"; ignored: {', '.join((*others, *trace.ignored))}" if (
            others or trace.ignored) else ""
        raise ParameterError(f"{trace.file}: no channel to fit; give one or more of "
                             f"{', '.join(FIT_CHANNELS)} (or with units, e.g. p_head [psi])"
                             f"{ignored}")
    trace.check_covers(duration_s, "the calibration")
    mode = held(trace, "valve_mode", duration_s)
    bad = ~np.isin(mode, (-1.0, 0.0, 1.0))
    if bad.any():
        raise ParameterError(f"{trace.where('valve_mode')}: value {mode[np.argmax(bad)]:g} "
                             "at t = {:g} s; a valve mode is -1, 0 or +1".format(
                                 run_grid(duration_s)[np.argmax(bad)]))
    u = held(trace, "u", duration_s) if "u" in trace.columns else mode.copy()
    t = run_grid(duration_s)
    used = {n: trace.headers[n] for n in ("valve_mode", "u", *channels) if n in trace.columns}
    unused = tuple(h for n, h in trace.headers.items() if n != TIME and n not in used)
    return Log(trace.file, mode.astype(int), u, {c: trace.resample(c, t) for c in channels},
               trace.sha256, used, trace.ignored + unused, trace.missing)


def held(trace: Trace, name: str, duration_s: float) -> np.ndarray:
    """A command column sampled and held (zero-order, across missing samples) at each
    step's end time."""
    t_s, values = trace.samples(name)
    i = np.searchsorted(t_s, run_grid(duration_s) + 1e-9, side="right") - 1
    return values[np.clip(i, 0, len(t_s) - 1)]


def replay(setup: Any, mode: np.ndarray, u: np.ndarray,
           names: Sequence[str] = FIT_CHANNELS) -> dict[str, np.ndarray]:
    """Run ``setup``'s plant in open loop under the given valve command.

    Parameters
    ----------
    setup : trackmj.sim.setup.RunSetup
        The conditions and parameters.
    mode, u : ndarray, shape (steps,)
        Valve mode (−1/0/+1) and opening u [-] applied at each step.
    names : sequence of str
        Readout fields returned.

    Returns
    -------
    dict
        Field name -> values at the end of each step, shape (steps,). The physics guard
        watches every step (:class:`trackmj.errors.PhysicsError`).
    """
    with capture_mujoco_warnings() as warnings:
        asm = assemble(setup)
        sched = schedule(setup, 0, 0.01)
        guard = PhysicsGuard(physics_limits(setup, asm.element.stroke_range_m), warnings,
                             asm.element.node_pressures, asm.element.pressure_nodes)
        index = [Readout._fields.index(n) for n in names]
        out = np.empty((setup.steps, len(names)))
        plant = asm.plant
        for k, (inputs, m, v) in enumerate(zip(sched.inputs, mode.tolist(), u.tolist(),
                                               strict=True)):
            command = Command(int(m), float(v), None)
            readout = plant.step(command, inputs)
            guard.on_step(k, readout, command)
            out[k] = [readout[i] for i in index]
    return {n: out[:, j] for j, n in enumerate(names)}


def channel_sigma(setup: Any) -> dict[str, float]:
    """Noise σ of each fitted channel (SI): the control file's sensors; F_ten: the pressure
    σ times the two head areas (assumed: the study names no load cell)."""
    s = setup.control.sensors
    area = 2.0 * setup.hydraulics.cylinder.area_head_m2
    return {"tension_N": s.pressure_noise_std_Pa * area, "p_head_Pa": s.pressure_noise_std_Pa,
            "p_rod_Pa": s.pressure_noise_std_Pa, "stroke_m": s.stroke_noise_std_m}


def _files_value(setup: Any, key: str) -> float | None:
    """The value of ``KIND.TABLE.KEY`` in the run's files, if it is a plain attribute path."""
    kind, _, dotted = key.partition(".")
    node = {"hydraulics": setup.hydraulics, "model": setup.model,
            "control": setup.control}.get(kind)
    for part in dotted.split("."):
        if node is None or not hasattr(node, part):
            return None
        node = getattr(node, part)
    return float(node) if isinstance(node, int | float) else None


@dataclass
class Problem:
    """The fit: parameters scaled to θ ∈ [0, 1]^p over their bounds, the logs and the
    conditions; :meth:`residuals` runs the plant once per log and records every run."""

    spec: CalibrateTable
    scenario: str
    logs: list[Log]
    runs: list[dict[str, Any]]

    @property
    def keys(self) -> list[str]:
        return [p.key for p in self.spec.parameters]

    @property
    def low(self) -> np.ndarray:
        return np.array([p.bounds[0] for p in self.spec.parameters])

    @property
    def high(self) -> np.ndarray:
        return np.array([p.bounds[1] for p in self.spec.parameters])

    @property
    def logarithmic(self) -> np.ndarray:
        """Which parameters are scaled logarithmically (positive bounds), shape (p,)."""
        return self.low > 0.0

    def x(self, theta: np.ndarray) -> np.ndarray:
        """Parameter values of scaled θ ∈ [0, 1]^p: log-uniform over positive bounds (a
        rate ∝ B·A is then linear in θ), linear otherwise."""
        theta = np.clip(np.asarray(theta, dtype=float), 0.0, 1.0)
        lin = self.low + theta * (self.high - self.low)
        log = np.exp(np.log(np.where(self.logarithmic, self.low, 1.0))
                     + theta * np.log(np.where(self.logarithmic, self.high / self.low, 1.0)))
        return np.where(self.logarithmic, log, lin)

    def dx_dtheta(self, theta: np.ndarray) -> np.ndarray:
        """d x / d θ at θ, shape (p,)."""
        ratio = np.where(self.logarithmic, self.high / self.low, 1.0)
        return np.where(self.logarithmic, self.x(theta) * np.log(ratio),
                        self.high - self.low)

    def theta(self, values: Mapping[str, float]) -> np.ndarray:
        x = np.array([values[k] for k in self.keys])
        with np.errstate(divide="ignore", invalid="ignore"):
            log = np.log(x / self.low) / np.log(self.high / self.low)
        return np.where(self.logarithmic, log, (x - self.low) / (self.high - self.low))

    def values(self, theta: np.ndarray) -> dict[str, float]:
        return dict(zip(self.keys, self.x(theta).tolist(), strict=True))

    def setup(self, values: Mapping[str, float]) -> RunSetup:
        fixed = overrides_by_kind(list(self.spec.set or ()))
        merged = {f"{kind}.{k}": v for kind, keys in fixed.items() for k, v in keys.items()}
        return prepare(self.scenario, architecture=self.spec.architecture,
                       seed=self.spec.seed, duration=self.spec.duration_s,
                       overrides=merged | dict(values))

    def simulate(self, values: Mapping[str, float]) -> list[dict[str, np.ndarray]]:
        """The replayed channels of every log at ``values``."""
        setup = self.setup(values)
        return [replay(setup, log.mode, log.u, list(log.channels)) for log in self.logs]

    def weighted(self, values: Mapping[str, float], purpose: str) -> np.ndarray:
        """Stacked residuals (simulated − measured)/σ on the fitted samples, recorded as a
        run with its purpose and residual RMS per channel [SI]."""
        setup = self.setup(values)
        sigma = channel_sigma(setup)
        keep = run_grid(self.spec.duration_s) >= self.spec.start_s
        parts, rms = [], {}
        by_log: list[dict[str, float]] = []
        wall = time.perf_counter()
        for log, sim in zip(self.logs, self.simulate(values), strict=True):
            by_log.append({})
            for name, measured in log.channels.items():
                e = sim[name][keep] - measured[keep]
                m = max(1, round(self.spec.block_s / COUPLING_STEP_S))
                blocks = e[: len(e) // m * m].reshape(-1, m).mean(axis=1)
                parts.append(blocks * math.sqrt(m) / sigma[name])
                rms.setdefault(name, []).append(float(np.mean(e * e)))
                by_log[-1][name] = math.sqrt(float(np.mean(e * e)))
        r = np.concatenate(parts)
        self.runs.append({"purpose": purpose, "values": dict(values),
                          "cost": float(0.5 * r @ r),
                          "residual_rms": {n: math.sqrt(float(np.mean(v)))
                                           for n, v in rms.items()},
                          "residual_rms_by_log": by_log,
                          "wall_time_s": time.perf_counter() - wall})
        return r


def _lhs_cost(problem: Problem, values: dict[str, float]) -> tuple[float, dict[str, Any]]:
    """Cost of one start point (in a worker): (0.5 Σr², its run record); a point whose run
    leaves physics costs inf and its record says why."""
    problem = Problem(problem.spec, problem.scenario, problem.logs, [])
    try:
        r = problem.weighted(values, "start")
    except PhysicsError as exc:
        return math.inf, {"purpose": "start", "values": dict(values), "cost": None,
                          "error": str(exc)}
    return float(0.5 * r @ r), problem.runs[0]


def _starts(problem: Problem) -> list[dict[str, float]]:
    """The Latin-hypercube start points (seeded by the spec's seed)."""
    n = problem.spec.start_points
    # seed=, the legacy keyword scipy still takes (its signature names only rng=): an int
    # rng= would draw from a generator spawned off it, so other start points
    engine = qmc.LatinHypercube(d=len(problem.keys),
                                seed=problem.spec.seed)  # pyright: ignore[reportCallIssue]
    theta = engine.random(n)
    return [problem.values(th) for th in theta]


def _best_start(problem: Problem, workers: int | None) -> dict[str, float]:
    """Evaluate the start points on the Dask executor; the lowest cost wins."""
    points = _starts(problem)
    with Executor(workers=workers) as ex:
        futures = ex.client.map(_lhs_cost, [problem] * len(points), points, pure=False)
        outcomes = ex.client.gather(futures)
    problem.runs.extend(run for _, run in outcomes)
    costs = [cost for cost, _ in outcomes]
    if not np.isfinite(costs).any():
        raise ParameterError(f"every one of the {len(points)} start points left physics "
                             f"(first: {outcomes[0][1]['error']}); narrow the bounds")
    return points[int(np.argmin(costs))]


def _fd_steps(problem: Problem, theta: np.ndarray, step: float) -> np.ndarray:
    """The θ step of a relative change ``step`` of each parameter, shape (p,)."""
    x = problem.x(theta)
    dx = step * np.maximum(np.abs(x), 1e-3 * (problem.high - problem.low))
    return dx / problem.dx_dtheta(theta)


def _central_jacobian(problem: Problem, theta: np.ndarray, step: float) -> np.ndarray:
    """d r / d θ by central differences of ± step·|x| (inside the bounds): the interval's
    Jacobian, where the one-sided one of the fit would count the track's roughness twice."""
    cols = []
    for i, h in enumerate(_fd_steps(problem, theta, step)):
        lo, hi = max(theta[i] - h, 0.0), min(theta[i] + h, 1.0)
        pair = []
        for value in (lo, hi):
            th = theta.copy()
            th[i] = value
            pair.append(problem.weighted(problem.values(th), "interval"))
        cols.append((pair[1] - pair[0]) / (hi - lo))
    return np.stack(cols, axis=1)


ROUGHNESS_POINTS = 12
ROUGHNESS_REL = 1e-3
"""The cost's roughness is probed at ROUGHNESS_POINTS points a relative ROUGHNESS_REL
(normal, seeded) from the estimate: too close for the smooth part to change the cost (its
Gauss-Newton model: 0.02-0.07 units on average on the logs measured, against a >= 0.2),
far enough for the track's contact events to flip."""
ROUGHNESS_SD_FACTOR = float(norm.ppf(CONFIDENCE)) / math.sqrt(2.0)
"""a = this times the standard deviation of the cost near the estimate: 2a = z(0.95)·√2·sd,
the one-sided 95 % bound on the difference of the rough part between two nearby points
(normal), so that ½δᵀJᵀJδ <= 2a holds for 95 % of the smooth minima the fit could have
missed."""


def _roughness(problem: Problem, theta: np.ndarray, cost: float) -> float:
    """a, the roughness of the cost near the estimate [cost units]:
    :data:`ROUGHNESS_SD_FACTOR` times the standard deviation of the cost over the estimate
    and :data:`ROUGHNESS_POINTS` probe points. A standard deviation, not a range: it does
    not grow with the number of points, and a step that most of the neighbourhood takes
    (the estimate in a pocket below it) still counts in full."""
    rng = np.random.default_rng([problem.spec.seed, 1])
    x = problem.x(theta)
    costs = [cost]
    for _ in range(ROUGHNESS_POINTS):
        values = x * (1.0 + ROUGHNESS_REL * rng.standard_normal(len(x)))
        r = problem.weighted(dict(zip(problem.keys, np.clip(values, problem.low,
                                                            problem.high).tolist(),
                                      strict=True)), "roughness")
        costs.append(float(0.5 * r @ r))
    return ROUGHNESS_SD_FACTOR * float(np.std(costs, ddof=1))


def _solve(problem: Problem, start: Mapping[str, float]
           ) -> tuple[Any, Callable[[np.ndarray], np.ndarray]]:
    """The least-squares fit from ``start`` (trust region reflective; one-sided differences
    of ``fd_step_rel``, stepping back inside the upper bound): scipy's result (θ in ``x``)
    and the residual function of θ (cached per θ)."""
    cache: dict[bytes, np.ndarray] = {}
    step = problem.spec.fd_step_rel

    def fun(theta: np.ndarray) -> np.ndarray:
        key = np.asarray(theta, float).tobytes()
        if key not in cache:
            cache[key] = problem.weighted(problem.values(theta), "fit")
        return cache[key]

    jacobians: dict[bytes, np.ndarray] = {}

    def jac(theta: np.ndarray) -> np.ndarray:
        key = np.asarray(theta, float).tobytes()
        if key in jacobians:
            return jacobians[key]
        r0 = fun(theta)
        cols = []
        for i, h in enumerate(_fd_steps(problem, theta, step)):
            h = h if theta[i] + h <= 1.0 else -h        # step back inside the upper bound
            th = theta.copy()
            th[i] += h
            cols.append((problem.weighted(problem.values(th), "jacobian") - r0) / h)
        jacobians[key] = np.stack(cols, axis=1)
        return jacobians[key]

    theta0 = np.clip(problem.theta(start), 0.0, 1.0)
    # jac: a callable, as documented; scipy's signature is unannotated, and its default
    # "2-point" makes the checker infer str
    sol = least_squares(fun, theta0, jac=jac,  # pyright: ignore[reportArgumentType]
                        bounds=(0.0, 1.0), method="trf",
                        x_scale=1.0, max_nfev=problem.spec.max_evaluations,
                        ftol=1e-4, xtol=1e-3)
    return sol, fun


UNDETERMINED_EIGENVALUE = 1e-10
"""An eigenvalue of the correlation form of JᵀJ below this is a direction of the keys the
logs do not see (their channels do not change along it, to the fit's resolution)."""
MISMATCH_NOISE_RATIO = 5.0
"""A log's channel whose fitted residual RMS is this many times its sensor σ or more is
not explained by the model with the fitted keys (measured, LF1352's 2.2 s step log with
noise at the sensors' σ, the bulk modulus 29 % off: 0.8-1.0 σ per channel logged at 2 kHz,
0.7-0.9 σ at 200 Hz; the same log fitted by the oil's viscosity instead, 1.2-2.0 σ; its
stroke sensor reading zero from mid-log, 148 σ)."""


def _inverse_information(j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(JᵀJ)⁻¹ of the keys the Jacobian ``j`` (n, p) determines, shape (p, p), and which
    they are, shape (p,): a key whose column is zero, or that takes part in a direction of
    the correlation form of JᵀJ with an eigenvalue below :data:`UNDETERMINED_EIGENVALUE`,
    is undetermined (its row and column inf)."""
    info = j.T @ j
    norm = np.sqrt(np.diag(info))
    determined = norm > 0.0
    while determined.any():
        d = np.flatnonzero(determined)
        corr = info[np.ix_(d, d)] / np.outer(norm[d], norm[d])
        w, v = np.linalg.eigh(corr)
        null = w < UNDETERMINED_EIGENVALUE
        if not null.any():
            break
        determined[d[(np.abs(v[:, null]) > 1e-3).any(axis=1)]] = False
    inverse = np.full(info.shape, np.inf)
    d = np.flatnonzero(determined)
    inverse[np.ix_(d, d)] = np.linalg.inv(info[np.ix_(d, d)])
    return inverse, determined


def fit_warnings(problem: Problem, undetermined: Mapping[str, str],
                 residual_rms_by_log: Sequence[Mapping[str, float]],
                 sigma: Mapping[str, float]) -> list[str]:
    """One line per key the logs do not determine within its bounds (``undetermined``: key
    -> why), and per log channel whose residual is :data:`MISMATCH_NOISE_RATIO` times its
    sensor σ or more."""
    lines = [f"{key}: the logs do not determine it within its bounds ({why}); its interval "
             "is the bounds" for key, why in undetermined.items()]
    for log, rms in zip(problem.logs, residual_rms_by_log, strict=True):
        for name, value in rms.items():
            if value >= MISMATCH_NOISE_RATIO * sigma[name]:
                scale, unit = display_unit(COLUMN_UNITS[name])
                lines.append(
                    f"{log.file} {log.used[name]!r}: the fitted run misses it by "
                    f"{value * scale:.3g} {unit} RMS, {value / sigma[name]:.0f} times its "
                    f"sensor's sigma: the model with these keys does not explain it (a "
                    "sensor fault, an offset, a key not fitted); the intervals assume it does")
    return lines


def _finite_or_none(value: float) -> float | None:
    """``value`` as a float, or None (JSON's null) where it is not finite: an undetermined
    key's standard error and correlations."""
    return float(value) if math.isfinite(value) else None


def fit(problem: Problem, start: Mapping[str, float]) -> dict[str, Any]:
    """Least-squares fit from ``start``; estimates, 95 % intervals (within the bounds),
    which keys the logs determine, residual RMS, and :func:`fit_warnings`."""
    step = problem.spec.fd_step_rel
    sol, fun = _solve(problem, start)
    r, j = fun(sol.x), _central_jacobian(problem, sol.x, step)   # d r / d theta
    n, p = len(r), len(sol.x)
    dof = max(n - p, 1)
    s2 = float(r @ r) / dof
    scale = problem.dx_dtheta(sol.x)
    inverse, determined = _inverse_information(j)
    with np.errstate(invalid="ignore"):                           # inf * 0 off the diagonal
        cov = s2 * np.outer(scale, scale) * inverse                # of x, physical units
    rough = _roughness(problem, sol.x, float(0.5 * r @ r))
    sd = np.sqrt(np.diag(cov))
    half = (student_t.ppf(0.5 + 0.5 * CONFIDENCE, dof) + math.sqrt(4.0 * rough / s2)) * sd
    x = problem.x(sol.x)
    low, high = np.maximum(x - half, problem.low), np.minimum(x + half, problem.high)
    covers = (low <= problem.low) & (high >= problem.high)
    undetermined = {k: "its channels do not change with it, or only together with another "
                    "key's" if not determined[i] else "its 95 % interval covers them"
                    for i, k in enumerate(problem.keys) if covers[i] or not determined[i]}
    fitted = problem.values(sol.x)
    final = next(run for run in reversed(problem.runs)
                 if run["values"] == fitted and run["purpose"] == "fit")
    flags = {k: k not in undetermined for k in problem.keys}
    with np.errstate(invalid="ignore"):
        correlation = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    return {
        "estimates": fitted,
        "intervals": {k: [float(low[i]), float(high[i])] for i, k in enumerate(problem.keys)},
        "determined": flags,
        "standard_errors": {k: _finite_or_none(sd[i]) for i, k in enumerate(problem.keys)},
        "correlation": [[_finite_or_none(c) for c in row] for row in correlation],
        "at_bound": {k: bool(sol.x[i] <= 1e-6 or sol.x[i] >= 1 - 1e-6)
                     for i, k in enumerate(problem.keys)},
        "residual_rms": final["residual_rms"],
        "residual_rms_by_log": final["residual_rms_by_log"],
        "residual_variance_rel": s2,
        "cost_roughness": rough,
        "samples": n,
        "optimizer": {"status": int(sol.status), "message": str(sol.message),
                      "evaluations": int(sol.nfev)},
        "warnings": fit_warnings(problem, undetermined, final["residual_rms_by_log"],
                                 channel_sigma(problem.setup(fitted))),
    }


@dataclass(frozen=True)
class Calibration:
    """What :func:`calibrate` wrote: the output directory and the calibration document."""

    out: Path
    document: dict[str, Any]


def calibrate(spec_path: str | Path, logs: Sequence[str | Path], out: str | Path, *,
              workers: int | None = None,
              progress: Callable[[str], None] | None = None) -> Calibration:
    """Fit the spec's keys to measured logs and write ``out`` whole (atomic).

    Parameters
    ----------
    spec_path : str or Path
        Calibration spec (module docstring).
    logs : sequence of str or Path
        Measured logs (:mod:`trackmj.results.measured`): ``t_s``, ``valve_mode`` (``u``
        optional) and any of :data:`FIT_CHANNELS`.
    out : str or Path
        Output directory: ``calibration.json`` (estimates with their units, 95 %
        intervals, residual RMS per channel [SI], every run made, and per log its
        ``path``, ``file``, ``sha256``, ``columns_used`` {SI name: header} and
        ``columns_ignored``: the headers the fit does not use) and ``calibration.png``
        (measured against start and fitted, and the residual, per channel and log).
    workers : int, optional
        Dask workers for the Latin-hypercube start (default one per core).

    Returns
    -------
    Calibration
    """
    spec, scenario = load_spec(spec_path)
    if not logs:
        raise ParameterError("calibrate needs one or more --measured LOG files")
    loaded = [load_log(path, spec.duration_s) for path in logs]
    problem = Problem(spec, scenario, loaded, [])
    start = _start_values(problem, spec_path)
    # local: the figure module loads matplotlib, heavy: only when a calibration draws
    from trackmj.results.figure_calibration import FittedLog, calibration_figure

    with ResultWriter(out, marker=CALIBRATION_JSON) as writer:
        wall = time.perf_counter()
        if spec.start_points:
            start = _best_start(problem, workers)
        result = fit(problem, start)
        start_sim = problem.simulate(start)
        fitted_sim = problem.simulate(result["estimates"])
        doc = {"spec": str(spec_path), "scenario": scenario, "duration_s": spec.duration_s,
               "seed": spec.seed, "architecture": spec.architecture, "start_s": spec.start_s,
               "logs": [log.record() | {"path": str(p)} for log, p in zip(loaded, logs,
                                                                          strict=True)],
               "start": start, "confidence": CONFIDENCE, **result,
               "units": {"residual_rms": {c: _unit(c) for c in FIT_CHANNELS},
                         "estimates": {key: key_unit(key) for key in problem.keys}},
               "runs": problem.runs, "wall_time_s": time.perf_counter() - wall}
        writer.commit_files(
            {CALIBRATION_JSON: (json.dumps(doc, indent=2, sort_keys=True, allow_nan=False)
                                + "\n").encode()},
            extras={CALIBRATION_PNG: lambda path: calibration_figure(
                [FittedLog(log.file, log.sha256, log.channels, s, f)
                 for log, s, f in zip(loaded, start_sim, fitted_sim, strict=True)], doc, path)})
    return Calibration(Path(out), doc)


def _start_values(problem: Problem, spec_path: str | Path) -> dict[str, float]:
    """Each key's start value: its ``start``, else its value in the files if that lies
    within its bounds, else the middle of the bounds (geometric for positive bounds). Every
    key and bound is checked first, before any run (ParameterError naming the spec's
    entry)."""
    spec = problem.spec
    for i, p in enumerate(spec.parameters):
        for value in p.bounds:
            try:
                problem.setup({p.key: value})
            except ParameterError as exc:
                raise ParameterError(f"{Path(spec_path).name} [[calibrate.parameters]][{i}] "
                                     f"key = {p.key!r} at bound {value:g}: {exc}") from None
    nominal = problem.setup({})
    start = {}
    for p in spec.parameters:
        value = p.start if p.start is not None else _files_value(nominal, p.key)
        low, high = p.bounds
        start[p.key] = value if value is not None and low <= value <= high else math.sqrt(
            low * high) if low > 0 else 0.5 * (low + high)
    return start


def _unit(column: str) -> str:
    return COLUMN_UNITS[column]
