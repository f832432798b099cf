"""``python -m trackmj``: the command line (:mod:`trackmj.cli.main`)."""

import sys

from trackmj.cli.main import main

if __name__ == "__main__":   # multiprocessing workers import this module too
    sys.exit(main())
