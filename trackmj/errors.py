"""Errors that cross the layers: raised low (an element, the physics guard), caught high (a
run, the command line). A leaf: it imports nothing.

Parameter errors are the validator's (:class:`trackmj.validator.ParameterError`); an FMU's
failing call is :class:`trackmj.fmi.FmuError`.
"""


class PhysicsError(RuntimeError):
    """A run left physics; the message names the time, the quantity and its value."""
