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

A measured drive load L [N] on the idler (the tight side's extra tension,
:func:`~trackmj.control.model.drive_load_N`) is rejected only as far as the band can take
its end: rejecting L means letting the carrier in, and when the load goes the tension drops
by the share s·L the trapped oil takes (``ReducedModel.hold_load_share``). So the tension is
let ride :func:`drive_load_allowance` above the reference, the part of s·L that would take it
below lo when the load ends. W3's pulses (s·L ≈ 2 kN against 4.5 kN to lo on LF1352) are
rejected whole; a heavy machine's start-up traction (M113: s·L ≈ 13 kN against 2.1 kN)
mostly rides on the tight side, as it must: a tensioner cannot take a tight side's tension
away, only slacken the other side.
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


def drive_load_allowance(reference_N: NDArray[np.float64], band_low_N: float,
                         held_load_N: float) -> NDArray[np.float64]:
    """Tension [N] let ride above each reference value under a drive load whose held share
    is ``held_load_N`` (s·L): max(0, s·L − (F_ref − lo)), lo = ``band_low_N`` (see the module
    docstring); 0 for no load."""
    return np.maximum(0.0, held_load_N - (reference_N - band_low_N))
