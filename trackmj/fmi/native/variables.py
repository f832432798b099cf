"""The native track FMU's variables: one table from which the export writes both the
modelDescription (FMI 2.0 and 3.0) and the C header the engine checks values against
(``trackmj_variables.h``). SI units; value references are fixed so that a model built
against one export reads another's.

Outputs change only in a step (no direct feedthrough: each depends on no input within a
communication point); they are valid from instantiation on (the settled initial state).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

from trackmj.scenarios.schema import TRACK_SPEED_MAX_M_S
from trackmj.track.mechanics import GroundParams, ModelParams, TrackParams

Causality = Literal["independent", "input", "output", "parameter"]
Variability = Literal["continuous", "discrete", "fixed"]
Kind = Literal["Float64", "Boolean"]

UNITS: dict[str, dict[str, int]] = {
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "1": {},
}
"""Unit name -> SI base-unit exponents (FMI's BaseUnit attributes)."""

DISPLAY_UNITS: dict[str, tuple[tuple[str, float], ...]] = {
    "m": (("mm", 1e-3),),
    "N": (("kN", 1e3),),
    "N/m": (("kN/mm", 1e6),),
    "N.m": (("kN.m", 1e3),),
}
"""Unit name -> (display unit, factor: value in the unit = factor × value in display)."""


@dataclass(frozen=True)
class Variable:
    """One FMU variable. ``minimum``/``maximum`` bound what may be set (None: any finite
    value); ``start`` of a parameter or input is its value before the importer sets one
    (filled in per machine at export where None)."""

    name: str
    vr: int
    kind: Kind
    causality: Causality
    variability: Variability
    unit: str | None
    description: str
    start: float | bool | None = None
    minimum: float | None = None
    maximum: float | None = None

    @property
    def c_name(self) -> str:
        """The C enumerator of its value reference (``VR_<name>``)."""
        return f"VR_{self.name}"


TIME = Variable("time", 0, "Float64", "independent", "continuous", "s",
                "simulated time since the settled initial state")

INPUTS = (
    Variable("force_N", 1, "Float64", "input", "continuous", "N",
             "tensioner force on the idler carrier at zero stroke velocity, F0 of the law "
             "F = F0 + Z*v held over each 1 ms step (v the stroke velocity at the step's "
             "end, integrated implicitly); > 0 pushes the idler outward"),
    Variable("force_dv_N_s_m", 2, "Float64", "input", "continuous", "N.s/m",
             "slope Z = dF/dv of the tensioner's force law over each 1 ms step; <= 0 (a law "
             "that damps)", 0.0, None, 0.0),
    Variable("track_speed_m_s", 3, "Float64", "input", "continuous", "m/s",
             "sprocket pitch-line speed command of the drive's velocity servo; > 0 drives "
             f"the vehicle forward; |v| <= {TRACK_SPEED_MAX_M_S:g} m/s (a scenario's range)",
             0.0, -TRACK_SPEED_MAX_M_S, TRACK_SPEED_MAX_M_S),
    Variable("hitch_pull_N", 4, "Float64", "input", "continuous", "N",
             "load on the rear hitch along the chassis x axis; > 0 pulls rearward (a towed "
             "implement), < 0 pushes", 0.0),
    Variable("hitch_down_N", 5, "Float64", "input", "continuous", "N",
             "load on the rear hitch along the chassis z axis; > 0 pushes down", 0.0),
)

OUTPUTS = (
    Variable("stroke_m", 10, "Float64", "output", "continuous", "m",
             "tensioner stroke, grows outward (tensioning)"),
    Variable("velocity_m_s", 11, "Float64", "output", "continuous", "m/s",
             "tensioner stroke velocity at the end of the last step"),
    Variable("tension_N", 12, "Float64", "output", "continuous", "N",
             "tensioner force applied to the idler carrier over the last step, the law at "
             "the end-of-step velocity; > 0 pushes outward"),
    Variable("chassis_acc_z_m_s2", 13, "Float64", "output", "continuous", "m/s2",
             "vertical chassis acceleration the last step produced (velocity change / step)"),
    Variable("drive_torque_N_m", 14, "Float64", "output", "continuous", "N.m",
             "sprocket drive torque over the last step; > 0 drives the vehicle forward"),
    Variable("upper_strand_tension_N", 15, "Float64", "output", "continuous", "N",
             "mean pin tension of the upper strand"),
    Variable("lower_strand_tension_N", 16, "Float64", "output", "continuous", "N",
             "mean pin tension of the sprocket's lower run (sprocket to nearest road wheel)"),
    Variable("max_envelope_excursion_m", 17, "Float64", "output", "continuous", "m",
             "largest distance of a pin outside the track's home envelope (chassis frame)"),
    Variable("closure_error_m", 18, "Float64", "output", "continuous", "m",
             "largest deflection of one pin compliance, at the start of the last step"),
    Variable("sprocket_disengaged", 20, "Boolean", "output", "discrete", None,
             "fewer than 2 pins seated on the sprocket pitch circle (within 0.3 of "
             "the tooth lift: o + r_tooth + r_pin)"),
    Variable("links_off_envelope", 21, "Boolean", "output", "discrete", None,
             "a pin more than 4/3 link pitch outside the home envelope"),
    Variable("slack_strand", 22, "Boolean", "output", "discrete", None,
             "the upper strand's least pin tension below 1000 N at every 10 ms sample of "
             "the last 0.1 s (it hangs on its weight; a tooth's brief compression of one "
             "pin is not slack)"),
    Variable("derailed", 23, "Boolean", "output", "discrete", None,
             "any of the three derailment indicators"),
)

GROUND_PARAMETERS = (
    ("ground_stiffness_N_m", 30, "N/m", "stiffness_N_m",
     "Kelvin-Voigt foundation stiffness per pin contact"),
    ("ground_damping_N_s_m", 31, "N.s/m", "damping_N_s_m",
     "Kelvin-Voigt foundation damping per pin contact, reached at the damping onset"),
    ("ground_damping_onset_m", 32, "m", "damping_onset_m",
     "penetration at which the foundation damping is reached, growing from 0 at touchdown"),
    ("ground_shear_modulus_m", 33, "m", "shear_modulus_m",
     "shear displacement that mobilises the full friction mu*N (Janosi-Hanamoto)"),
)
"""(name, value reference, unit, [ground] key, description) of the tunable ground law."""
FRICTION = ("ground_friction", 34, "1", "Coulomb coefficient pin-ground")


def _bounds(cls: type, key: str) -> tuple[float | None, float | None]:
    """The validator's allowed range of ``cls``'s field ``key``."""
    spec = {f.name: f.metadata["param"] for f in dataclasses.fields(cls)}[key]
    return spec.low, spec.high


def parameters(params: ModelParams) -> tuple[Variable, ...]:
    """The ground law as parameters, started at the machine's values, bounded by the
    validator's ranges (the stiffness also by the explicit spring's stability limit
    4·m/h² with m a third of a link, as the validator's consistency check)."""
    stiffness_max_N_m = (4.0 * params.track.link_mass_kg / 3.0
                         / params.simulation.timestep_s ** 2)
    out = []
    for name, vr, unit, key, text in GROUND_PARAMETERS:
        low, high = _bounds(GroundParams, key)
        if key == "stiffness_N_m":
            high = min(high if high is not None else math.inf, stiffness_max_N_m)
        out.append(Variable(name, vr, "Float64", "parameter", "fixed", unit,
                            f"{text} (machine file [ground].{key})",
                            float(getattr(params.ground, key)), low, high))
    name, vr, unit, text = FRICTION
    low, high = _bounds(TrackParams, "ground_friction")
    out.append(Variable(name, vr, "Float64", "parameter", "fixed", unit,
                        f"{text} (machine file [track].ground_friction)",
                        float(params.track.ground_friction), low, high))
    return tuple(out)


def table(params: ModelParams, force0_N: float) -> tuple[Variable, ...]:
    """Every variable of a machine's FMU, in value-reference order: time, inputs (the force
    started at ``force0_N`` [N], the settled state's), outputs, parameters."""
    inputs = (dataclasses.replace(INPUTS[0], start=force0_N), *INPUTS[1:])
    return (TIME, *inputs, *OUTPUTS, *parameters(params))


def _c_double(value: float | bool | None, missing: str) -> str:
    if value is None:
        return missing
    return repr(float(value))


def c_header(variables: tuple[Variable, ...], token: str) -> str:
    """``trackmj_variables.h``: the value references (``VR_<name>``), and for each variable
    its name, kind, causality, unit, start and allowed range (±INFINITY when unbounded,
    start NAN for outputs), which the engine checks every set value against."""
    kinds = {"Float64": "VAR_FLOAT64", "Boolean": "VAR_BOOLEAN"}
    enum = ",\n".join(f"    {v.c_name} = {v.vr}" for v in variables)
    rows = ",\n".join(
        f'    {{{v.vr}, "{v.name}", {kinds[v.kind]}, CAUSALITY_{v.causality.upper()}, '
        f'"{v.unit or ""}", {_c_double(v.start, "NAN")}, '
        f'{_c_double(v.minimum, "-INFINITY")}, {_c_double(v.maximum, "INFINITY")}}}'
        for v in variables)
    return f"""/* Generated by trackmj's FMU export from trackmj/fmi/native/variables.py: the FMU's
   variables, as its modelDescription declares them. Do not edit. */
#ifndef TRACKMJ_VARIABLES_H
#define TRACKMJ_VARIABLES_H

#include <math.h>

#define TRACKMJ_INSTANTIATION_TOKEN "{token}"

enum {{
{enum}
}};

typedef enum {{ VAR_FLOAT64, VAR_BOOLEAN }} VariableKind;
typedef enum {{
    CAUSALITY_INDEPENDENT, CAUSALITY_INPUT, CAUSALITY_OUTPUT, CAUSALITY_PARAMETER
}} VariableCausality;

typedef struct {{
    unsigned vr;
    const char *name;
    VariableKind kind;
    VariableCausality causality;
    const char *unit;
    double start;     /* NAN for outputs and the time */
    double minimum;   /* -INFINITY when unbounded */
    double maximum;   /* INFINITY when unbounded */
}} VariableInfo;

#define TRACKMJ_VARIABLE_COUNT {len(variables)}
static const VariableInfo TRACKMJ_VARIABLES[TRACKMJ_VARIABLE_COUNT] = {{
{rows}
}};

#endif /* TRACKMJ_VARIABLES_H */
"""


__all__ = ["DISPLAY_UNITS", "INPUTS", "OUTPUTS", "TIME", "UNITS", "Variable", "c_header",
           "parameters", "table"]
