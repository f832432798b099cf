"""FMI commands: ``fmu export`` writes trackmj's track, or track + hydraulics, as an FMI 2.0
co-simulation FMU (importing FMUs is ``--tensioner`` and ``--controller fmu:FILE``)."""

from __future__ import annotations

import argparse

from trackmj.fmi.export import export


def cmd_fmu_export(args: argparse.Namespace) -> int:
    """``trackmj fmu export KIND -o FILE.fmu``: the FMU written, with its notes."""
    exported = export(args.kind, args.out)
    print(f"wrote {exported.path}")
    for note in exported.notes:
        print(f"  {note}")
    return 0
