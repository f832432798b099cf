"""FMI both ways, through fmpy (import) and pythonfmu (export).

* :mod:`trackmj.fmi.fmu`: opening and checking an FMU against a tensioner or controller
  file, and one FMU instance behind a version-neutral call surface (FMI 2.0 and 3.0,
  co-simulation and model exchange); every failing call becomes a
  :class:`~trackmj.errors.FmuError` naming the FMU, the call and the time.
* :mod:`trackmj.elements.fmu`: an FMU as the tensioner element (``ports.Element``), coupled
  strongly (co-simulation with state roll-back, or model exchange integrated implicitly
  with the mechanics) or weakly (co-simulation without roll-back).
* :mod:`trackmj.fmi.controller_fmu`: an FMU as the controller (``ports.Controller``).
* :mod:`trackmj.fmi.export`: trackmj's plant (track + built-in hydraulics and sensors) as
  a pythonfmu FMU that runs trackmj in the importing tool's embedded Python (Linux).
* :mod:`trackmj.fmi.slaves`: the slave class that FMU runs in the importing tool.
"""
