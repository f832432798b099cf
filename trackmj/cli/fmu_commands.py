"""FMI commands: ``fmu export`` writes trackmj's track as a native FMU (FMI 2.0 or 3.0
co-simulation), or track + hydraulics as a Python-hosted FMI 2.0 one (importing FMUs is
``--tensioner`` and ``--controller fmu:FILE``)."""

from __future__ import annotations

import argparse
import sys

from trackmj.cli.summary import end_stop_line
from trackmj.fmi.export import export


def cmd_fmu_export(args: argparse.Namespace) -> int:
    """``trackmj fmu export KIND -o FILE.fmu``: the FMU written, with its notes; a name not
    ending in .fmu is refused before any work (an importer finds an FMU by it). A track
    settled with its idler carrier on an end stop is written with a warning on stderr, as
    a run's is: the stop is part of the machine, and an importer that applies less force
    lifts the carrier off it."""
    if not str(args.out).lower().endswith(".fmu"):
        raise ValueError(f"-o {args.out}: an FMU's file name must end in .fmu (FMI 2.0/3.0 "
                         "standard), e.g. -o track.fmu")
    if args.kind == "track":
        # start-up: --help and argument errors must not import MuJoCo (the exporter settles
        # the track)
        from trackmj.fmi.native.export import export_track

        try:
            native = export_track(args.out, fmi_version=args.fmi, machine=args.machine,
                                  terrain=args.terrain, seed=args.seed, force_N=args.force,
                                  platforms=tuple(args.platform or ("linux", "win64")))
        except RuntimeError as exc:   # no platform built, or a compiler error: not the input
            print(f"trackmj: the FMU was not written: {exc}", file=sys.stderr)
            return 1
        print(f"wrote {native.path}")
        for note in native.notes:
            print(f"  {note}")
        settled = ("W1's initial tension" if args.force is None else "--force")
        warning = end_stop_line({"settled_on_end_stop": native.end_stop}, native.machine,
                                native.grade, when=f"in the FMU's start state (settled under "
                                f"{settled} {native.force_N:g} N)")
        if warning is not None:
            print(warning, file=sys.stderr)
        return 0
    track_only = [f"--{name}" for name, default in (("fmi", 2), ("machine", None),
                                                    ("terrain", "flat"), ("seed", 0),
                                                    ("force", None), ("platform", None))
                  if getattr(args, name) != default]
    if track_only:
        raise ValueError(f"{', '.join(track_only)}: options of the track FMU; the plant FMU "
                         "takes its machine, terrain and seed as FMU parameters")
    exported = export(args.kind, args.out)
    print(f"wrote {exported.path}")
    for note in exported.notes:
        print(f"  {note}")
    return 0
