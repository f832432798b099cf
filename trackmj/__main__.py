"""``python -m trackmj``: the command line (:mod:`trackmj.cli`)."""

import sys

from trackmj.cli import main

if __name__ == "__main__":   # multiprocessing workers import this module too
    sys.exit(main())
