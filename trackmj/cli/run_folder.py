"""Where ``trackmj run`` writes a run, and when it refuses a folder.

A folder is named after the run (scenario, architecture, controller, seed, variant, and the
machine when it is not the default one) and, for inputs that are not the scenario's own
(a measured log among them), a short hash of them, so runs of other inputs never share a
folder. A folder that holds a run of other inputs (another inputs key, read
from its metrics.json) is refused unless ``--overwrite``; a run of the same inputs is
replaced.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.results.store import METRICS, ResultDirectoryError

if TYPE_CHECKING:
    from trackmj.sim.setup import RunSetup


def run_folder(setup: RunSetup, key: str, *, defaults: bool) -> Path:
    """Default folder of ``trackmj run``: ``runs/SCENARIO-ARCH-CONTROLLER-sSEED`` for the
    scenario's own inputs (``defaults``), with ``-VARIANT`` for a W5 variant, ``-MACHINE``
    for a machine other than the default one and the first 8 digits of the inputs' hash
    (:func:`trackmj.study.identity.inputs_key`) for any other input (estimator,
    --duration, --set, parameter or tensioner files, a measured log), so that runs of
    other inputs never share a folder."""
    name = (f"{setup.scenario.name}-{setup.architecture}-{setup.controller}-"
            f"s{setup.seed}")
    if setup.variant.name != "nominal":
        name += f"-{setup.variant.name}"
    if setup.machine.name != DEFAULT_MACHINE:
        name += f"-{setup.machine.name}"
    if not defaults:
        name += f"-{key[:8]}"
    return Path("runs") / name


def stored_inputs_key(out: Path) -> str | None:
    """The inputs key of the run in folder ``out`` ('' for a run without one, None if
    ``out`` holds no run)."""
    try:
        doc = json.loads((out / METRICS).read_text())
    except (OSError, ValueError):
        return None
    return str(doc.get("run", {}).get("inputs_key", ""))


def refuse_other_inputs(out: Path, key: str, *, overwrite: bool) -> None:
    """ResultDirectoryError if folder ``out`` holds a run of inputs other than ``key``'s,
    unless ``overwrite``."""
    held = stored_inputs_key(out)
    if held is not None and held != key and not overwrite:
        what = f"inputs {held[:8]}" if held else "no inputs key: an older trackmj"
        raise ResultDirectoryError(
            f"--out {out}: holds a run of other inputs ({what}; this run's are {key[:8]}); "
            "give --overwrite to replace it, or another --out")
