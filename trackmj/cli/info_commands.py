"""Commands that show what there is: ``scenarios`` (the built-in operating conditions and
the registered blocks), ``keys`` (the ``--set`` keys) and ``view`` (a run's Rerun recording
in the viewer).

The scenario loader (Numba, SciPy), the files' key tables (SciPy) and the playback module
(Rerun, MuJoCo) are imported inside the handlers: ``trackmj --help`` and argument errors
import this module and must stay fast.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import textwrap

from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS
from trackmj.sim.registry import ARCHITECTURES, ELEMENTS
from trackmj.validator import FILE_KINDS, describe_schema, did_you_mean

VIEWER_START_S = 5.0
"""How long ``view`` waits for the viewer to fail before it reports it open [s]."""


def cmd_view(args: argparse.Namespace) -> int:
    """``trackmj view``: open a run's recording in the Rerun viewer; exit code 1 if there is
    no display or the viewer exits with an error within :data:`VIEWER_START_S`."""
    # start-up: --help and argument errors must not import Rerun or MuJoCo
    from trackmj.results.playback import open_viewer, resolve_rrd

    rrd = resolve_rrd(args.path)
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        print(f"trackmj: error: no display (DISPLAY and WAYLAND_DISPLAY are unset), so the "
              f"Rerun viewer cannot open here; copy {rrd} to a machine with a display and "
              f"run 'rerun {rrd.name}' there, or serve it to a browser with "
              f"'python -m rerun --web-viewer {rrd}'", file=sys.stderr)
        return 1
    viewer = open_viewer(rrd)
    try:   # a viewer that cannot start (no GPU, broken install) exits within seconds
        code = viewer.wait(timeout=VIEWER_START_S)
    except subprocess.TimeoutExpired:
        print(f"viewer open on {rrd}")
        return 0
    if code != 0:
        print(f"trackmj: error: the Rerun viewer exited with code {code} without opening "
              f"{rrd} (its messages are above)", file=sys.stderr)
        return 1
    return 0


def cmd_scenarios(args: argparse.Namespace) -> int:
    """``trackmj scenarios``: the built-in scenarios (W5's variants for ``--variant``), then
    each registry's names with their descriptions."""
    # start-up: --help and argument errors must not import Numba
    from trackmj.scenarios.load import builtin_names, load_scenario

    loaded = [load_scenario(name) for name in builtin_names()]
    width = max(len(sc.name) for sc in loaded) + 2
    for sc in loaded:
        print(f"{sc.name:<{width}}{sc.title} ({sc.duration_s:g} s, {sc.controller}/"
              f"{sc.estimator})")
        if len(sc.variants) > 1:
            print(textwrap.fill("--variant " + ", ".join(v.name for v in sc.variants), 90,
                                initial_indent=" " * width, subsequent_indent=" " * (width + 10)))
    print("or any scenario TOML file in the same format (experiments/*.toml)")
    for title, registry in (("architectures (--arch)", ARCHITECTURES),
                            ("controllers (--controller)", CONTROLLERS),
                            ("estimators (--estimator)", ESTIMATORS),
                            ("tensioner elements (of the architectures; --tensioner FILE)",
                             ELEMENTS)):
        print(f"\n{title}")
        for name, entry in registry.items():
            print(f"{name:<{width + 5}}{entry.description}")
    return 0


def cmd_keys(args: argparse.Namespace) -> int:
    """``trackmj keys``: the ``--set`` keys of each file kind with type, unit, range and
    meaning."""
    # start-up: --help and argument errors must not import SciPy
    from trackmj.results.columns import file_schema

    unknown = [k for k in args.kinds if k not in FILE_KINDS]
    if unknown:
        raise ValueError(f"keys {unknown[0]!r}{did_you_mean(unknown[0], FILE_KINDS)} "
                         f"(allowed: {', '.join(FILE_KINDS)})")
    print("# --set KIND.TABLE.KEY=VALUE and sweep keys: type, unit, range - meaning; '[]' is "
          "an array of tables, give the index (scenario.load_pulses.0.hitch_N), '<name>' a "
          "named table")
    for kind in args.kinds or FILE_KINDS:
        print(f"# {kind}")
        for row in describe_schema(file_schema(kind)):
            print(f"{kind}.{row}")
    return 0
