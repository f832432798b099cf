"""The ``trackmj`` command line (also ``python -m trackmj``).

* :mod:`trackmj.cli.main`: :func:`~trackmj.cli.main.main`, dispatch and exit codes.
* :mod:`trackmj.cli.parser`: every subcommand's arguments, help texts and defaults.
* :mod:`trackmj.cli.track_commands`: ``model``, ``machines``, ``drive``.
* :mod:`trackmj.cli.run_commands`: ``run``, ``compare``, ``report``, ``sweep``, ``calibrate``.
* :mod:`trackmj.cli.info_commands`: ``scenarios``, ``keys``, ``view``.
* :mod:`trackmj.cli.fmu_commands`: ``fmu export``.
* :mod:`trackmj.cli.run_folder`: where ``run`` writes a run and when a folder is refused.
* :mod:`trackmj.cli.summary`: the printed tables.
"""
