"""trackmj's version, a leaf that the results and the command line record."""

__version__ = "0.1.0"
