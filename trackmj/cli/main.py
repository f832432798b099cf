"""``trackmj`` command line (also ``python -m trackmj``): parse, run the subcommand's
handler, and turn its errors into exit codes.

Display units (kN, mm, MPa) appear only in the CLI; everything inside is SI. Errors in the
input (a bad option, file, key or value) end with exit code 2 and one line naming what is
wrong; a run that leaves physics with exit code 3; Ctrl-C with 130.

The arguments are in :mod:`trackmj.cli.parser`, the handlers in the ``*_commands`` modules.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from trackmj.cli.parser import build_parser
from trackmj.errors import FmuError, PhysicsError
from trackmj.results.store import ResultDirectoryError
from trackmj.validator import ParameterError


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command ``argv`` (default: the process's arguments); its exit code."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("trackmj: interrupted; earlier results were left as they were", file=sys.stderr)
        return 130
    except BrokenPipeError:   # e.g. 'trackmj keys | head': the reader has gone
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except (PhysicsError, FmuError) as exc:
        print(f"trackmj: stopped: {exc}", file=sys.stderr)
        return 3
    except (ParameterError, ResultDirectoryError, FileNotFoundError, ValueError,
            KeyError) as exc:
        print(f"trackmj: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
