"""trackmj's track as a native FMU: C against MuJoCo's C API, no Python on the host.

* :mod:`trackmj.fmi.native.export`: ``trackmj fmu export track`` (build and package);
* :mod:`trackmj.fmi.native.variables`: the FMU's variables (modelDescription and C header);
* :mod:`trackmj.fmi.native.description`: the modelDescription, FMI 2.0 and 3.0;
* :mod:`trackmj.fmi.native.toolchain`: the compilers and MuJoCo libraries per platform;
* ``engine.c`` (the plant's step sequence in C), ``fmi2.c``, ``fmi3.c`` (the FMI layers) and
  ``layer.h`` (what the two layers share: modes, doStep checks, saved and serialised state).
"""
