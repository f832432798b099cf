"""SX functions compiled to machine code (control/compiled.py) compute what CasADi's virtual
machine computes, bit for bit: every supported operation (with NaN, infinities and signed
zeros), the NMPC's closed-loop solves and the EKF's and UKF's steps."""

from __future__ import annotations

import dataclasses
import gc
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from trackmj.control import compiled
from trackmj.control.compiled import CompiledFunction, bind
from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
from trackmj.control.fastcall import BufferedFunction
from trackmj.control.governor import feasible_band
from trackmj.control.model import ReducedModel, ReducedPlant
from trackmj.control.nmpc import NonlinearMpc
from trackmj.control.sensors import Sensors
from trackmj.control.valves import ValveLogic
from trackmj.io import cache_dir
from trackmj.sim.control_plant import nominal_plant_params, packaged_control

CFG = packaged_control()
PLANT = nominal_plant_params(control_config=CFG)
EDGES = (0.0, -0.0, 1.0, -2.5, 3e-310, 1e300, np.inf, -np.inf, np.nan)


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.int64)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit-identical, except that any two NaNs count as equal (a NaN's payload is not
    part of IEEE arithmetic's result)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    nan = np.isnan(a)
    return bool(np.array_equal(nan, np.isnan(b))
                and np.array_equal(_bits(a)[~nan], _bits(b)[~nan]))


def test_every_operation_on_edge_values_equals_the_virtual_machine() -> None:
    """Each supported operation on every pair of edge values (NaN, ±inf, ±0, subnormal)."""
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    outs = [x + y, x - y, x * y, x / y, -x, x * x, 2 * x, 1 / x, ca.sqrt(x), ca.fabs(x),
            ca.fmax(x, y), ca.fmin(x, y), 3.25 * x - y / 7.0]
    fn = ca.Function("ops", [ca.vertcat(x, y)], [ca.vertcat(*outs)])
    ops = {int(fn.instruction_id(k)) for k in range(fn.n_instructions())}
    assert ops == set(compiled.SUPPORTED)   # the function exercises every one
    arg = np.zeros(2)
    ours = CompiledFunction(fn, [arg])
    theirs = BufferedFunction(fn, [arg])
    for a in EDGES:
        for b in EDGES:
            arg[:] = a, b
            ours()
            theirs()
            assert _same(ours.res[0], theirs.res[0]), (a, b)


def test_unsupported_operation_stays_in_the_virtual_machine() -> None:
    x = ca.SX.sym("x")
    fn = ca.Function("trig", [x], [ca.sin(x) + x])
    with pytest.raises(NotImplementedError):
        compiled.instructions(fn)
    assert isinstance(bind(fn, [np.zeros(1)]), BufferedFunction)


def test_constants_are_not_part_of_the_compiled_structure() -> None:
    """Two functions that differ only in a constant share one generated module."""
    x = ca.SX.sym("x", 2)
    rows = [compiled.instructions(ca.Function("f", [x], [c * x[0] + x[1]]))
            for c in (1.5, 2.5)]
    np.testing.assert_array_equal(rows[0][0], rows[1][0])
    assert rows[0][1].tolist() == [1.5] and rows[1][1].tolist() == [2.5]


def test_disabled_by_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    x = ca.SX.sym("x")
    fn = ca.Function("f", [x], [x * x])
    monkeypatch.setenv(compiled.DISABLE_ENV, "1")
    assert isinstance(bind(fn, [np.zeros(1)]), BufferedFunction)
    monkeypatch.setenv(compiled.DISABLE_ENV, "0")
    assert isinstance(bind(fn, [np.zeros(1)]), CompiledFunction)


def _closed_loop_nmpc(steps: int) -> list[tuple[np.ndarray, np.ndarray, float, int]]:
    """The NMPC (its SQP's functions as built now) on the reduced plant, 12 -> 15 kN and
    back: per period the solution w, the multipliers, u and the SQP iterations."""
    model = ReducedModel(PLANT)
    # no wall-clock budget: an overrun on a loaded machine would apply the previous plan
    # and make the comparison depend on timing, not on the arithmetic compared here
    untimed = dataclasses.replace(CFG.mpc, time_budget_s=10.0)
    ctrl = NonlinearMpc(model, CFG.controller, untimed)
    n = CFG.mpc.horizon_steps
    plant = ReducedPlant(PLANT, model.equilibrium(12e3))
    period = round(CFG.controller.period_s / 1e-3)
    out = []
    for k in range(steps):
        ref = np.full(n + 1, 15e3 if k < steps // 2 else 13e3)
        r = ctrl(plant.x, ref, k * CFG.controller.period_s)
        out.append((ctrl._w.copy(), ctrl._lam_g.copy(), r.u, r.iterations))
        for _ in range(period):
            plant.step(r.u, PLANT.supply_pressure_Pa)
    return out


def test_nmpc_closed_loop_is_bit_identical(monkeypatch: pytest.MonkeyPatch) -> None:
    ours = _closed_loop_nmpc(40)
    monkeypatch.setenv(compiled.DISABLE_ENV, "1")
    theirs = _closed_loop_nmpc(40)
    assert any(abs(u) > 0.05 for _, _, u, _ in ours)   # the valves act
    for (w, lam, u, it), (w_ref, lam_ref, u_ref, it_ref) in zip(ours, theirs, strict=True):
        assert it == it_ref and _same(w, w_ref) and _same(lam, lam_ref) and u == u_ref


@pytest.mark.parametrize("cls", [ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_estimator_steps_are_bit_identical(cls: type,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    def run() -> list[np.ndarray]:
        model = ReducedModel(PLANT)
        x0 = model.equilibrium(12e3)
        plant = ReducedPlant(PLANT, x0)
        sensors = Sensors(CFG.sensors, np.random.default_rng(3))
        filt = cls(model, CFG.estimator, 1e-3, x0)
        valves = ValveLogic(CFG.valves, 1e-3)
        out = []
        for k in range(300):
            mode = valves.step(0.6 * np.sin(2 * np.pi * 3.0 * k * 1e-3))
            x = plant.step(float(mode), PLANT.supply_pressure_Pa)
            filt.step(sensors.measure(x), float(mode), PLANT.supply_pressure_Pa)
            out.append(np.concatenate((filt.x, filt.P.ravel(), filt.innovation)))
        return out

    ours = run()
    monkeypatch.setenv(compiled.DISABLE_ENV, "1")
    theirs = run()
    assert all(_same(a, b) for a, b in zip(ours, theirs, strict=True))


def test_generated_modules_are_written_whole_into_trackmjs_cache(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A new structure's module lands in ``$TRACKMJ_CACHE/compiled`` (else
    ``$XDG_CACHE_HOME/trackmj/compiled``), complete, with no temporary file left."""
    monkeypatch.setenv(compiled.DISABLE_ENV, "0")
    for env, root in (("TRACKMJ_CACHE", tmp_path / "own"),
                      ("XDG_CACHE_HOME", tmp_path / "xdg")):
        monkeypatch.delenv("TRACKMJ_CACHE", raising=False)
        monkeypatch.setenv(env, str(root))
        expected = root if env == "TRACKMJ_CACHE" else root / "trackmj"
        assert cache_dir() == expected
        x = ca.SX.sym("x", 2)   # a structure no other test builds, new for each root
        fn = ca.Function("probe", [x], [ca.vertcat(x[0] * x[1] * x[1] * x[0] - 7.0,
                                                    x[1] / (x[0] + 3.0) * x[1])])
        bound = bind(fn, [np.array((0.3, 2.0))], [np.zeros(2)])
        assert isinstance(bound, CompiledFunction)
        files = sorted(p.name for p in (expected / "compiled").iterdir()
                       if p.suffix in (".py", ".tmp"))
        assert len(files) == 1 and files[0].startswith("trackmj_sx_")
        assert files[0].endswith(".py")
        compiled._modules.pop(files[0][:-3])   # the next root writes its own


@pytest.mark.parametrize("compile_", [True, False])
def test_results_bound_to_inputs_see_the_inputs_before_the_step(
        compile_: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """A result bound to its own input (a state updated in place) is written only after
    every input was read: swapping a vector's entries in place works."""
    monkeypatch.setenv(compiled.DISABLE_ENV, "0" if compile_ else "1")
    x = ca.SX.sym("x", 3)
    fn = ca.Function("rotate", [x], [ca.vertcat(x[1], x[2], x[0] * x[1])])
    state = np.array((2.0, 3.0, 5.0))
    bound = bind(fn, [state], [state])
    assert isinstance(bound, CompiledFunction if compile_ else compiled.AliasedBuffer)
    bound.call()
    assert state.tolist() == [3.0, 5.0, 6.0]


def test_nmpc_problem_and_update_kernels_equal_their_numpy_expressions() -> None:
    """control/mpc_kernels.py against the numpy code it replaces: the parameter vector and
    warm start (cold, warm, pressures below p_min, preview outside the governor's band),
    the SQP's iterate update (full and shortened step) and the finite check with the plan."""
    from trackmj.control import mpc_kernels

    model = ReducedModel(PLANT)
    # no wall-clock budget: an overrun on a loaded machine would apply the previous plan
    # and make the comparison depend on timing, not on the arithmetic compared here
    untimed = dataclasses.replace(CFG.mpc, time_budget_s=10.0)
    ctrl = NonlinearMpc(model, CFG.controller, untimed)
    n = CFG.mpc.horizon_steps
    x = model.equilibrium(14e3)
    cases = [(np.append(x, 0.01), np.linspace(9e3, 25e3, n + 1)),
             (np.array((-1e5, -2e5, x[2], 0.01)), np.full(n + 1, 15e3))]
    band = feasible_band(CFG.controller, PLANT, PLANT.supply_pressure_Pa)
    for warm in (False, True):
        if warm:
            ctrl(x, np.full(n + 1, 16e3), 0.0)
        for estimate, preview in cases:
            ctrl._compiled_problem = True
            w_c, p_c = (a.copy() for a in ctrl._problem(estimate, preview, band))
            ctrl._compiled_problem = False
            w_n, p_n = ctrl._problem(estimate, preview, band)
            assert _same(w_c, w_n) and _same(p_c, p_n)
    rng = np.random.default_rng(5)
    for t in (1.0, 0.8, 0.64):
        w, lam_g, lam_x, dx, dlam_g, dlam_x = (rng.standard_normal(k) for k in
                                               (80, 150, 80, 80, 150, 80))
        ref = [w.copy(), lam_g.copy(), lam_x.copy()]
        if t == 1.0:
            ref = [ref[0] + dx, dlam_g.copy(), dlam_x.copy()]
        else:
            ref[1] *= 1.0 - t
            ref[1] += t * dlam_g
            ref[2] *= 1.0 - t
            ref[2] += t * dlam_x
            ref[0] += t * dx
        mpc_kernels.update(w, lam_g, lam_x, dx, dlam_g, dlam_x, t)
        assert all(_same(a, b) for a, b in zip((w, lam_g, lam_x), ref, strict=True))
    w, lam = rng.standard_normal(80), rng.standard_normal(150)
    plan = np.zeros(15)
    assert mpc_kernels.finish(w, lam, 5, 3, plan, True)
    assert _same(plan, np.repeat(w[:5], 3))
    lam[7] = np.nan
    assert not mpc_kernels.finish(w, lam, 5, 3, plan, True)


def test_a_filter_keeping_only_the_call_reads_live_memory() -> None:
    """The EKF keeps only ``bind(...).call`` of its compiled step. The call must keep the
    bound arrays (the function's constants among them) alive: when it did not, numpy reused
    the freed constants' memory for the next small arrays and the estimate went wild
    (found on a W1 run whose observer only allocated small arrays: 12.1 kN mean became
    2.4 kN). Dirtying numpy's freed small blocks must not change a step."""
    plant = nominal_plant_params()
    model, cfg = ReducedModel(plant), packaged_control()
    x0 = model.equilibrium(15e3)
    z = np.array((x0[0] + 1e5, x0[1], x0[2] + 1e-4))
    clean = ExtendedKalmanFilter(model, cfg.estimator, 1e-3, x0)
    clean.step(z, 0.0, 12e6)
    dirtied = ExtendedKalmanFilter(model, cfg.estimator, 1e-3, x0)
    gc.collect()
    for n in range(1, 260):
        block = np.full(n, 7.0)
        del block
    dirtied.step(z, 0.0, 12e6)
    np.testing.assert_array_equal(dirtied.x, clean.x)
