"""The default machine's name: what every command and run uses without ``--machine``.

A module of its own, importing nothing, so that the command line's help can name the
default without loading :mod:`trackmj.machines.assembly` (MuJoCo, SciPy).
"""

DEFAULT_MACHINE = "lf1352"
"""Name of the shipped machine used when none is given (``models/lf1352_machine.toml``)."""
