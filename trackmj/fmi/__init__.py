"""FMI both ways, through fmpy (import) and pythonfmu (export).

* :mod:`trackmj.fmi.model`: opening and checking an FMU against a tensioner or controller
  file, and one FMU instance behind a version-neutral call surface (FMI 2.0 and 3.0,
  co-simulation and model exchange); every failing call becomes an :class:`FmuError` naming
  the FMU, the call and the time.
* :mod:`trackmj.fmi.element`: an FMU as the tensioner element (``ports.Element``), coupled
  strongly (co-simulation with state roll-back, or model exchange integrated implicitly
  with the mechanics) or weakly (co-simulation without roll-back).
* :mod:`trackmj.fmi.controller`: an FMU as the controller (``ports.Controller``).
* :mod:`trackmj.fmi.export`: trackmj's track, or track + hydraulics, as an FMU.
"""


class FmuError(RuntimeError):
    """An FMU failed during a run: the message names the FMU, the FMI call and the time."""
