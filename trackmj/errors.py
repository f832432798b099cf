"""Errors that cross the layers: raised low (an element, the physics guard, an FMU call),
caught high (a run, the command line). A leaf: it imports nothing.

Parameter errors are the validator's (:class:`trackmj.validator.ParameterError`).
"""


class PhysicsError(RuntimeError):
    """A run left physics; the message names the time, the quantity and its value."""


class FmuError(RuntimeError):
    """An FMU failed during a run: the message names the FMU, the FMI call and the time."""
