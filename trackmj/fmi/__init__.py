"""FMI both ways, through fmpy (import) and pythonfmu (export).

* :mod:`trackmj.fmi.fmu`: opening and checking an FMU against a tensioner or controller
  file, and one FMU instance behind a version-neutral call surface (FMI 2.0 and 3.0,
  co-simulation and model exchange); every failing call becomes an :class:`FmuError` naming
  the FMU, the call and the time.
* :mod:`trackmj.elements.fmu`: an FMU as the tensioner element (``ports.Element``), coupled
  strongly (co-simulation with state roll-back, or model exchange integrated implicitly
  with the mechanics) or weakly (co-simulation without roll-back).
* :mod:`trackmj.fmi.controller`: an FMU as the controller (``ports.Controller``).
* :mod:`trackmj.fmi.export`: trackmj's track, or track + hydraulics, as an FMU.
"""


class FmuError(RuntimeError):
    """An FMU failed during a run: the message names the FMU, the FMI call and the time."""


_HELD: list[dict] = []


def hold_module_dict(namespace: dict) -> None:
    """Keep one more reference to a pythonfmu slave module's globals, each time the module's
    code runs. pythonfmu 0.7's binary (``findClass``, PySlaveInstance.cpp) executes the
    module's file in the module's dict and then DECREFs that dict, which
    ``PyModule_GetDict`` lent it (a borrowed reference): one reference too few per
    instantiation, and the dict is freed while in use (measured: segmentation faults in the
    garbage collector, at random, in fmpy and in a C host). Call it at the top level of
    every pythonfmu slave script: ``hold_module_dict(globals())``."""
    _HELD.append(namespace)
