"""Named interfaces ("ports") between the blocks of trackmj: the leaf every block imports.

No import of anything else of trackmj, nor of mujoco, casadi or numba, happens here.

Data flows one way per 1 ms coupling step (:data:`COUPLING_STEP_S`):

    controller (every period) -> valve logic -> plant [tensioner element -> mechanics]
    -> sensors -> estimator -> observers

Tensioner port (mechanics <-> tensioner force element), one exchange per step:

1. Before the mechanical step the mechanics calls ``element.force_law(t, stroke, velocity)``
   with the state at the start of the step (t_k, s_k, v_k).
2. The element returns a :class:`ForceLaw` ``F(v) = force_N + damping_N_s_m * v``.
   The track hands it to MuJoCo as an affine actuator (``ctrl = force_N``,
   ``biasprm[2] = damping_N_s_m``); MuJoCo's ``implicitfast`` integrator then applies
   exactly ``F(v_{k+1})`` over the step, with ``v_{k+1}`` the end-of-step velocity.
3. After the step the mechanics calls ``element.complete_step(t_{k+1}, s_{k+1}, v_{k+1})``
   so the element can finish its own (implicit) update with the velocity the mechanics
   actually produced.

Sign convention: stroke s [m] grows when the idler carrier moves outward (tensioning the
track); velocity v = ds/dt [m/s]; force F [N] > 0 pushes the idler outward. The
mechanical work received by the track over one step is ``F(v_{k+1}) * v_{k+1} * h``
(MuJoCo's semi-implicit Euler moves the position by ``h * v_{k+1}``).

Valve modes: +1 pressurize, 0 hold, -1 release (see ``docs/sizing.md``).

Element port (the tensioner element of the closed loop, :class:`Element`): the tensioner port
above plus what the loop and the run need of any element, so that the loop never asks which
element it has: ``set_valves(mode, u, supply_set_Pa)`` every step before the mechanics step,
``log()`` (an :class:`ElementLog`) after it, ``pressure_nodes`` / ``node_pressures()`` for the
physics guard, ``stroke_range_m`` (the travel the guard allows) and, at the end,
``run_metrics(duration_s)`` (its own metrics and its energy table ``energy_J``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, NamedTuple, Protocol, TypeVar, runtime_checkable

import numpy as np
from numpy.typing import NDArray

COUPLING_STEP_S = 1e-3
"""Fixed exchange step between controller, valves, hydraulics, mechanics and sensors [s]."""


def steps_per_period(period_s: float, dt_s: float = COUPLING_STEP_S) -> int:
    """Whole steps of ``dt_s`` [s] in one ``period_s`` [s] (e.g. 10 for a 10 ms controller at
    1 ms); ValueError unless the period is a positive integer multiple of the step."""
    if not (dt_s > 0.0 and period_s > 0.0):
        raise ValueError(f"period_s = {period_s} and dt_s = {dt_s} must be > 0")
    ratio = period_s / dt_s
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(1.0, ratio):
        raise ValueError(f"period {period_s} s must be an integer multiple of the step {dt_s} s")
    return k


ElementCoupling = Literal["strong", "weak"]
"""How an architecture couples its element to the mechanics: "strong" (the affine law with
dF/dv) or "weak" (the last step's force held)."""

TupleT = TypeVar("TupleT", bound=NamedTuple)


def check_order(cls: type[NamedTuple], order: Sequence[str]) -> None:
    """TypeError unless ``order`` (field names, as a per-step call site writes or unpacks
    the values of the NamedTuple ``cls``) is ``cls``'s declared order: a reordered or
    renamed field fails loudly when the call site's module loads, never as silently swapped
    values."""
    declared: tuple[str, ...] = cls._fields
    if tuple(order) != declared:
        raise TypeError(f"{cls.__name__} declares the fields {declared} but a call site "
                        f"uses {tuple(order)}")


def positional(cls: type[TupleT], order: Sequence[str]
               ) -> Callable[[type[TupleT], Iterable[Any]], TupleT]:
    """``tuple.__new__``, called as ``build(cls, values)``: the same object as
    ``cls(*values)`` without NamedTuple's keyword handling, for the few per-step call sites
    that build records at 1 kHz, returned once :func:`check_order` has checked the order
    the call site writes ``values`` in. Cold code builds by keyword."""
    check_order(cls, order)
    return tuple.__new__


@dataclass(frozen=True, slots=True)
class ForceLaw:
    """Affine force law for one step: F(v) = force_N + damping_N_s_m * v.

    force_N: force at zero end-of-step velocity [N], > 0 pushes the idler outward.
    damping_N_s_m: dF/dv [N·s/m]; normally <= 0 (a cylinder resists motion).
    """

    force_N: float
    damping_N_s_m: float = 0.0

    def at(self, velocity_m_s: float) -> float:
        """Force [N] the law gives at end-of-step velocity ``velocity_m_s`` [m/s]."""
        return self.force_N + self.damping_N_s_m * velocity_m_s


_new = object.__new__
_set_force = ForceLaw.__dict__["force_N"].__set__
_set_damping = ForceLaw.__dict__["damping_N_s_m"].__set__


def make_force_law(force_N: float, damping_N_s_m: float) -> ForceLaw:
    """``ForceLaw(force_N, damping_N_s_m)`` [N, N·s/m] without the frozen dataclass's
    ``__init__`` (each field through ``object.__setattr__``): the same object, ~2.5x
    cheaper, for elements that build a law every step."""
    law = _new(ForceLaw)
    _set_force(law, force_N)
    _set_damping(law, damping_N_s_m)
    return law


@dataclass(frozen=True, slots=True)
class ControlOutput:
    """Controller result: valve opening u in [-1, 1] [-], success flag, solve wall time [s],
    iterations [-], and whether a fallback plan was applied."""

    u: float
    success: bool = True
    solve_time_s: float = 0.0
    iterations: int = 0
    fallback: bool = False


@dataclass(frozen=True, slots=True)
class ControllerStatistics:
    """What a controller counts over a run: ``fallbacks``, solves whose plan was replaced by
    the fallback (the shifted previous plan, or hold) [-]."""

    fallbacks: int = 0


class Command(NamedTuple):
    """What drives the valves at a step: applied ``mode`` (+1/0/−1), the opening ``u`` [-]
    in force, and ``solved``, the controller's output when it ran at this step (else None)."""

    mode: int
    u: float
    solved: ControlOutput | None


class StepInputs(NamedTuple):
    """Scenario inputs of one step (what the operator and the environment impose).

    track_speed_m_s: sprocket pitch-line speed command [m/s]; hitch_pull_N, hitch_down_N:
    rear-hitch load in the chassis frame [N] (rearward, downward); supply_set_Pa: supply
    pressure set value (the prescribed profile, or the nominal pressure) [Pa gauge].
    """

    track_speed_m_s: float
    hitch_pull_N: float
    hitch_down_N: float
    supply_set_Pa: float


class Readout(NamedTuple):
    """What the plant shows after a completed step, SI; NaN where a plant has no such
    quantity (no supply node in dp-b, no chassis in dp-a or the reduced plant).

    t_s: end of the step [s]; tension_N: F_ten, the tensioner force on the idler carrier
    [N]; p_head_Pa / p_rod_Pa: mean head / rod chamber pressure [Pa gauge]; p_supply_Pa:
    supply node [Pa gauge]; stroke_m [m], stroke_velocity_m_s [m/s]; q_supply_m3_s: flow
    out of the supply through the main valve [m³/s]; e_supply_J, p_work_J (∫Σp·A·v dt),
    mech_work_J (∫F·v dt): cumulative energies [J]; chassis_acc_z_m_s2 [m/s²];
    closure_error_m: track loop closure gap [m]; drive_torque_N_m: the sprocket drive's torque
    over the step [N·m], > 0 driving the vehicle forward.
    """

    t_s: float
    tension_N: float
    p_head_Pa: float
    p_rod_Pa: float
    p_supply_Pa: float
    stroke_m: float
    stroke_velocity_m_s: float
    q_supply_m3_s: float
    e_supply_J: float
    p_work_J: float
    mech_work_J: float
    chassis_acc_z_m_s2: float
    closure_error_m: float
    drive_torque_N_m: float


COLUMN_UNITS: dict[str, str] = {
    "t_s": "s",
    "tension_N": "N",
    "tension_ref_N": "N",
    "p_head_Pa": "Pa",
    "p_rod_Pa": "Pa",
    "p_supply_Pa": "Pa",
    "stroke_m": "m",
    "stroke_velocity_m_s": "m/s",
    "q_supply_m3_s": "m^3/s",
    "valve_mode": "1",
    "u": "1",
    "e_supply_J": "J",
    "p_work_J": "J",
    "mech_work_J": "J",
    "chassis_acc_z_m_s2": "m/s^2",
    "closure_error_m": "m",
    "drive_torque_N_m": "N·m",
}
"""The one column -> unit table of a closed-loop run's timeseries, in the contract's order
("1": dimensionless): the :class:`Readout` fields, the command's ``valve_mode`` and ``u``
(:data:`COMMAND_UNITS`) and the reference ``tension_ref_N`` (:data:`REFERENCE_UNITS`)."""
COMMAND_UNITS = {"valve_mode": "1", "u": "1"}
"""Columns the recorder takes from the command (valve mode −1/0/+1, opening u [-])."""
REFERENCE_UNITS = {"tension_ref_N": "N"}
"""Column the recorder takes from the schedule (F_ref at the end of each step)."""
READOUT_UNITS: dict[str, str] = {name: COLUMN_UNITS[name] for name in Readout._fields}
"""Unit of every :class:`Readout` field."""


def unit_suffix(column: str) -> str:
    """The SI suffix of a column name (``p_head_Pa`` -> ``Pa``, ``stroke_velocity_m_s`` ->
    ``m_s``, ``drive_torque_N_m`` -> ``N_m``, ``u`` -> '')."""
    for suffix in ("m3_s", "m_s2", "m_s", "N_m", "Pa", "N", "m", "J", "s"):
        if column.endswith("_" + suffix):
            return suffix
    return ""


class ElementLog(NamedTuple):
    """An element's per-step values after a completed step (SI, gauge Pa; NaN where the element
    has no such quantity).

    p_head_Pa is the mean of the head pressures, q_supply_m3_s the flow out of the supply
    node into the circuit, force_N the element's own force on the idler (> 0 outward); the
    *_J values are cumulative from t = 0: supply_J the energy drawn from the prime mover,
    piston_work_J the work of the pressures on the pistons (∫Σp·A·v dt), mech_work_J the
    work into the mechanics (∫F·v dt).
    """

    t_s: float
    p_head_Pa: float
    p_rod_Pa: float
    p_supply_Pa: float
    q_supply_m3_s: float
    force_N: float
    supply_J: float
    piston_work_J: float
    mech_work_J: float


@runtime_checkable
class TensionerElement(Protocol):
    """A tensioner force element acting on the idler carrier (see module docstring)."""

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        """Force law for the coming step, given the state at its start."""
        ...

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        """Finish the step with the end-of-step state the mechanics produced."""
        ...


class Element(TensionerElement, Protocol):
    """A tensioner element of the closed loop (see the module docstring, element port).

    pressure_nodes: names of the values ``node_pressures()`` returns [Pa gauge] (empty for an
    element without pressures); stroke_range_m: (lowest, highest) stroke [m] the element's
    travel (with its end stops' allowance) admits, checked by the physics guard;
    channels: the extra columns ``channel_values()`` returns, name -> unit, recorded with
    ``--channels all`` (empty for an element with none), a table of the element's class.
    The loop only reads ``pressure_nodes`` and ``stroke_range_m`` (an element may hold them as
    class or instance attributes).
    """

    channels: ClassVar[Mapping[str, str]]

    @property
    def pressure_nodes(self) -> tuple[str, ...]: ...

    @property
    def stroke_range_m(self) -> tuple[float, float]: ...

    def channel_values(self) -> Sequence[float]:
        """The ``channels`` after the last completed step, in their order (SI)."""
        ...

    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """The step's valve command: applied mode +1/0/−1, the controller's opening u [-],
        and the supply set value [Pa gauge]; called before every mechanics step."""
        ...

    def log(self) -> ElementLog:
        """The element's values after the last completed step."""
        ...

    def node_pressures(self) -> Sequence[float]:
        """Every node pressure now [Pa gauge], in ``pressure_nodes`` order."""
        ...

    def run_metrics(self, duration_s: float) -> dict[str, Any]:
        """The element's own metrics at the end of a run of ``duration_s`` [s], with its
        energy table under ``energy_J`` (see :mod:`trackmj.elements.energy_table`)."""
        ...


class Mechanics(Protocol):
    """The mechanics the tensioner acts on (the MuJoCo track, or an equivalent idler).

    ``apply(inputs)`` sets the step's scenario inputs, ``step(element)`` advances one
    coupling step through the tensioner port and returns the law applied; the named
    readouts are attributes (stroke [m], stroke velocity [m/s], idler force [N] of the
    last step, chassis vertical acceleration [m/s²], closure error [m], the sprocket drive's
    torque [N·m] (NaN without a sprocket), time [s]).
    """

    time_s: float

    @property
    def stroke_m(self) -> float: ...

    @property
    def stroke_velocity_m_s(self) -> float: ...

    @property
    def idler_force_N(self) -> float: ...

    @property
    def chassis_acc_z_m_s2(self) -> float: ...

    @property
    def closure_error_m(self) -> float: ...

    @property
    def drive_torque_N_m(self) -> float: ...

    def apply(self, inputs: StepInputs) -> None: ...

    def step(self, element: TensionerElement) -> ForceLaw: ...


class Plant(Protocol):
    """Everything between the valve command and the sensors: ``step(command, inputs)``
    applies the :class:`Command` (valve mode +1/0/-1, opening u) and the step's inputs,
    advances one coupling step and returns its :class:`Readout`."""

    def step(self, command: Command, inputs: StepInputs) -> Readout: ...


class Sensors(Protocol):
    """Measurement z = (p_head [Pa], p_rod [Pa], stroke [m]) of the true values x and, when
    given, the drive torque [N·m], noisy (NaN stays NaN: a plant without a sprocket drive)."""

    def measure(self, x: Sequence[float],
                drive_torque_N_m: float | None = None) -> NDArray[np.float64]: ...


class Estimator(Protocol):
    """State estimate from 1 kHz samples z (4,) (:class:`Sensors`): ``period_mean()`` gives
    X = (p_head [Pa], p_rod [Pa], y [m], ẏ [m/s], y0 [m], L [N]) averaged over the controller
    period, y0 the estimated unloaded stroke, L the idler load the measured drive torque
    makes (the measured disturbance the controllers feed forward)."""

    def step(self, z: NDArray[np.float64], mode: float, p_s: float) -> NDArray[np.float64]: ...

    def period_mean(self) -> NDArray[np.float64]: ...


class Controller(Protocol):
    """``controller(estimate (4,) to (6,) (:class:`Estimator`), reference preview
    F_ref(t + i·period), i = 0..N [N], t [s]) -> ControlOutput``, told the supply pressure
    [Pa] each period by ``set_parameters``; ``statistics()`` gives its counts at the end of a
    run."""

    period_s: float
    horizon_steps: int

    def __call__(self, estimate: NDArray[np.float64], reference_preview: NDArray[np.float64],
                 t: float) -> ControlOutput: ...

    def set_parameters(self, *, supply_pressure_Pa: float | None = None) -> None: ...

    def statistics(self) -> ControllerStatistics: ...


class ValveLogic(Protocol):
    """Continuous opening u in [-1, 1] -> applied valve mode (+1, 0, -1) every step."""

    def step(self, u: float) -> int: ...


class Observer(Protocol):
    """Sees every completed step: its index k, the plant's readout and the :class:`Command`
    in force; raising stops the run (e.g. a physics guard)."""

    def on_step(self, k: int, readout: Readout, command: Command) -> None: ...
