"""The ``trackmj`` command line (also ``python -m trackmj``): :func:`trackmj.cli.main.main`."""
