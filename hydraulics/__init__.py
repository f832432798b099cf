"""Hydraulic tensioning circuit (numpy, numba-compiled kernels; never imports mujoco).

Public API: :class:`HydraulicTensioner` (a ``trackmj.ports.TensionerElement``),
:class:`StepRecord`, :class:`EnergyLedger`, :func:`load_hydraulic_params`
and the parameter dataclasses in :mod:`trackmj.hydraulics.params`.
"""

from .ledger import EnergyLedger
from .params import HydraulicParams, PressureProfile, load_hydraulic_params
from .tensioner import MODES, HydraulicTensioner, StepRecord

__all__ = ["MODES", "EnergyLedger", "HydraulicParams", "HydraulicTensioner",
           "PressureProfile", "StepRecord", "load_hydraulic_params"]
