"""A controller FMU (e.g. a controller exported from Simulink) as the run's controller
(``ports.Controller``): ``--controller fmu:FILE.toml``.

The controller file's ``[controller]`` table names the FMU (``path``, relative to the file;
FMI 2.0 or 3.0 co-simulation), its ``period_s`` (an integer multiple of the 1 ms coupling
step; an FMU that cannot handle a variable communication step has its DefaultExperiment
stepSize as period), ``[controller.inputs]`` FMU name = one of :data:`CONTROLLER_INPUTS`
(at least one of the :data:`MEASUREMENTS`), ``[controller.outputs]`` FMU name = ``"u"``
(opening in [−1, 1]) or ``"valve_mode"`` (+1/0/−1), and ``[controller.parameters]`` set
before initialisation. Values cross the port in SI (:data:`CONTROLLER_UNITS`): a mapped
variable's declared unit is converted (kN, bar, %, ...; another dimension or an offset is
refused at load), one without a unit is taken as SI.

Every period at t the FMU's inputs are set (the measurements as the run's estimator gives
them: its mean over the past period, and the reference F_ref(t)) and it is stepped from t
to t + period; its output is applied from t, as trackmj's own controllers' solves are. The
valve logic (dead zone, minimum hold) then turns u into valve modes; a ``valve_mode``
output passes through it unchanged (|mode| = 1 is outside any dead zone).

The output is handed to the loop as the FMU gave it: an output outside [−1, 1] is clipped
there, counted and reported (``controller_output_clipped`` in metrics.json, see
:func:`trackmj.sim.loop.run_loop`), never silently. The FMU's unzipped copy is removed by
:meth:`FmuController.close`, or when the controller is collected.
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from trackmj.errors import FmuError
from trackmj.fmi.fmu import FmuInstance, describe
from trackmj.ports import ControllerStatistics, ControlOutput, steps_per_period
from trackmj.validator import Location, ParameterError, Parameters, load_file, param, sources_field

CONTROLLER_INPUTS: dict[str, str] = {
    "p_head_Pa": "head pressure [Pa gauge] (the estimator's period mean)",
    "p_rod_Pa": "rod pressure [Pa gauge]",
    "stroke_m": "stroke [m]",
    "stroke_velocity_m_s": "stroke velocity [m/s]",
    "F_ref_N": "tension reference F_ref(t) [N]",
    "supply_pressure_Pa": "supply pressure set value [Pa gauge]",
}
"""Port quantities a controller FMU input can be mapped to."""
MEASUREMENTS = ("p_head_Pa", "p_rod_Pa", "stroke_m", "stroke_velocity_m_s")
"""The inputs that measure the plant: a controller FMU maps at least one (else it runs open
loop)."""
CONTROLLER_OUTPUTS = {"u": "valve opening in [−1, 1] [-]",
                      "valve_mode": "valve mode +1 pressurize, 0 hold, −1 release [-]"}
"""Port quantities a controller FMU output can be mapped to (exactly one)."""
CONTROLLER_UNITS = {"p_head_Pa": "Pa", "p_rod_Pa": "Pa", "stroke_m": "m",
                    "stroke_velocity_m_s": "m/s", "F_ref_N": "N", "supply_pressure_Pa": "Pa",
                    "u": "1", "valve_mode": "1"}
"""Port quantity -> its SI unit (a key of :data:`trackmj.fmi.fmu.PORT_UNITS`), to which a
mapped variable's declared unit is converted."""


@dataclass(frozen=True)
class ControllerTable(Parameters):
    """A controller FMU (see the module docstring)."""

    path: str = param(max_len=4096, doc="the .fmu file, relative to the controller file")
    period_s: float = param(1e-3, 10.0, doc="the controller's period, an integer multiple "
                            "of the 1 ms coupling step")
    inputs: Mapping[str, str] = param(doc="FMU input name = measurement (p_head_Pa, "
                                      "p_rod_Pa, stroke_m, stroke_velocity_m_s: at least "
                                      "one), F_ref_N or supply_pressure_Pa")
    outputs: Mapping[str, str] = param(doc="FMU output name = u or valve_mode (one)")
    parameters: Mapping[str, Any] = param(default_factory=dict, doc="FMU variable name = "
                                          "value set before initialisation (default none)")

    def cross_check(self, at: Location) -> None:
        try:
            steps_per_period(self.period_s)
        except ValueError as exc:
            raise at.error("period_s", self.period_s, str(exc)) from None
        for table, allowed in (("inputs", CONTROLLER_INPUTS), ("outputs", CONTROLLER_OUTPUTS)):
            for name, quantity in getattr(self, table).items():
                if quantity not in allowed:
                    raise at.error((table, name), quantity,
                                   f"is not a port quantity; allowed: {', '.join(allowed)}")
        if not set(MEASUREMENTS) & set(self.inputs.values()):
            raise ParameterError(f"{at.table()}: map an FMU input to a measurement "
                                 f"({', '.join(MEASUREMENTS)}); without one the controller "
                                 "runs open loop")
        if len(self.outputs) != 1:
            raise ParameterError(f"{at.table()}: map exactly one FMU output, to \"u\" or "
                                 f"\"valve_mode\" (got {len(self.outputs)})")


@dataclass(frozen=True)
class ControllerFile(Parameters):
    """A controller file: its ``[controller]`` table; ``file`` and ``description`` (the
    checked FMU) are set by :func:`load_controller_file`."""

    controller: ControllerTable = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        doc="the controller FMU")
    sources: Mapping[str, str] = sources_field()
    file: Path | None = field(default=None, compare=False, metadata={"loader": "file"})
    description: Any = field(default=None, compare=False, repr=False,
                             metadata={"loader": "fmu"})


def default_step_s(md: Any) -> float | None:
    """The DefaultExperiment stepSize [s] of ``md`` (fmpy's model description); None if it
    gives none."""
    experiment = md.defaultExperiment
    if experiment is None or experiment.stepSize is None:
        return None
    return float(experiment.stepSize)


def fixed_step_s(md: Any) -> float | None:
    """The one communication step [s] the co-simulation FMU of ``md`` takes: its
    DefaultExperiment stepSize where it cannot handle a variable step
    (canHandleVariableCommunicationStepSize false, FMI's default); None otherwise."""
    return None if md.coSimulation.canHandleVariableCommunicationStepSize else \
        default_step_s(md)


def load_controller_file(path: str | Path) -> ControllerFile:
    """Read and validate a controller file and check its FMU (co-simulation; the mapped
    variables' causality, type and unit; an FMU with a fixed step has it as ``period_s``)
    before any run."""
    path = Path(path)
    loaded = load_file(ControllerFile, path)
    table = loaded.controller
    real, number = ("real",), ("real", "int")
    at = Location(file=path.name, path=("controller",))
    description = describe((path.parent / table.path).resolve(), "co-simulation", at,
                           table.inputs, table.outputs, table.parameters,
                           dict.fromkeys(CONTROLLER_INPUTS, real),
                           {"u": real, "valve_mode": number}, CONTROLLER_UNITS)
    step = fixed_step_s(description.md)
    if step is not None and not math.isclose(step, table.period_s, rel_tol=1e-9):
        raise at.error("period_s", table.period_s,
                       f"s differs from {description.name}'s DefaultExperiment stepSize "
                       f"{step:g} s, the only step it takes (it cannot handle a variable "
                       f"communication step): set period_s = {step:g}")
    object.__setattr__(loaded, "file", path)
    object.__setattr__(loaded, "description", description)
    return loaded


class FmuController:
    """The FMU of a controller file on the controller port (see the module docstring).

    Parameters
    ----------
    loaded : ControllerFile
        A loaded controller file (its FMU checked).
    """

    horizon_steps = 0   # it takes the current reference only

    def __init__(self, loaded: ControllerFile) -> None:
        self.period_s = loaded.controller.period_s
        self.description = d = loaded.description
        self.inst = inst = FmuInstance(d, "trackmj-controller")
        self._close = weakref.finalize(self, inst.close)
        self._supply_Pa = 0.0
        inst.start(0.0, dict.fromkeys(d.inputs, 0.0))   # closes the instance if it fails
        self._output, self._channel = next(iter(d.outputs.items()))
        step = default_step_s(d.md)
        self._step_note = "" if step is None or math.isclose(step, self.period_s) else (
            f"; its DefaultExperiment stepSize is {step:g} s, period_s {self.period_s:g} s: "
            f"if it runs at a fixed sample time, set period_s = {step:g}")

    def close(self) -> None:
        """Free the FMU and remove its unzipped copy (again: nothing)."""
        self._close()

    def set_parameters(self, *, supply_pressure_Pa: float | None = None) -> None:
        """The supply set value [Pa gauge] the FMU's ``supply_pressure_Pa`` input sees."""
        if supply_pressure_Pa is not None:
            self._supply_Pa = supply_pressure_Pa

    def __call__(self, estimate: NDArray[np.float64], reference_preview: NDArray[np.float64],
                 t: float) -> ControlOutput:
        start = time.perf_counter()
        p_head, p_rod, stroke, velocity = (float(x) for x in estimate[:4])
        self.inst.set_inputs({"p_head_Pa": p_head, "p_rod_Pa": p_rod, "stroke_m": stroke,
                              "stroke_velocity_m_s": velocity,
                              "F_ref_N": float(reference_preview[0]),
                              "supply_pressure_Pa": self._supply_Pa})
        try:
            self.inst.do_step(t, self.period_s)
        except FmuError as exc:   # say what a step the FMU refuses may be about
            raise FmuError(f"{exc}{self._step_note}") from exc
        u = float(self.inst.read(self._channel))
        if not np.isfinite(u):
            raise FmuError(f"the FMU {self.description.name} output {self._output} = {u!r} "
                           f"at t = {t:.3f} s (non-finite)")
        return ControlOutput(u, True, time.perf_counter() - start)   # the loop clips it

    def statistics(self) -> ControllerStatistics:
        """No plan, no fallback."""
        return ControllerStatistics()


def build_fmu_controller(model: Any, cfg: Any, controller_file: ControllerFile) -> FmuController:
    """The registry's builder: the FMU of ``controller_file`` (the reduced model and the
    control configuration are not used: the FMU brings its own)."""
    return FmuController(controller_file)
