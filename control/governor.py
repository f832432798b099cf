"""Reference governor: the reference the controllers track is kept inside what the tensioner
can hold.

A reference outside the admissible band [F_min, F_max], or above what the supply can push,
would make the MPC fight its own soft constraints (and, measured, stall its truncated SQP:
infeasible plans, fallbacks, the valves left in hold). The governor saturates every value of
the reference preview to the nearest feasible one:

    lo = F_min + margin,   hi = min(F_max − margin, A_h·(p_s − Δp_valve) − A_r·p_t)

with ``margin`` = ``reference_margin_N`` (the band the tension's ripple needs) and
Δp_valve = ``governor_valve_drop_Pa``, the smallest pressure drop across the head path that
still feeds the heads at a useful rate (with the turbulent law the flow at Δp is
sqrt(Δp/Δp_0) of the flow at Δp_0). If the supply cannot even reach lo, the governed
reference is hi: the controller holds the most the supply gives. Areas are the lumped ones of
the reduced model [m²], pressures gauge [Pa].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from trackmj.control.params import ControllerParams, PlantParams, resolved


def feasible_band(ctrl: ControllerParams, plant: PlantParams,
                  supply_pressure_Pa: float) -> tuple[float, float]:
    """(lo, hi) [N] of the governed reference at supply pressure ``supply_pressure_Pa``."""
    reach = (plant.area_head_m2 * (supply_pressure_Pa - ctrl.governor_valve_drop_Pa)
             - plant.area_rod_m2 * plant.tank_pressure_Pa)
    margin = resolved(ctrl, "reference_margin_N")
    return (resolved(ctrl, "force_min_N") + margin,
            min(resolved(ctrl, "force_max_N") - margin, reach))


def govern(preview: NDArray[np.float64], band: tuple[float, float]) -> NDArray[np.float64]:
    """``preview`` [N] saturated to ``band``; the upper bound wins if they cross."""
    lo, hi = band
    return np.minimum(np.maximum(preview, lo), hi)
