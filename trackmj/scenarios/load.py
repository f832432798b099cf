"""Finding and loading scenarios: ``load_scenario("W1")`` reads ``W1.toml`` of the installed
package ``trackmj.experiments``; any other argument is a path to a custom file. The file is
read by the one validator into :class:`~trackmj.scenarios.schema.ScenarioFile`, its relative
values resolved for the machine given (:mod:`trackmj.scenarios.resolve`), so the
:class:`~trackmj.scenarios.resolved.Scenario` it returns holds absolute values only.

The built-in scenarios are the ``*.toml`` files of the experiments folder that are scenario
files: the name is a scenario name (:data:`~trackmj.scenarios.schema.NAME_PATTERN`) and a
line of the file is the ``[scenario]`` table header (``controllers.toml``, a sweep spec, is
not one). Dropping a file in is enough to add one. They are listed with the study's
conditions (``W`` and a number) first in number order, then the others in natural order
(W1, W2, W3, W4, W5, NL1).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from importlib.resources import files
from pathlib import Path
from typing import Any

from trackmj.scenarios.resolve import drop_twin, packaged_nominal, resolve
from trackmj.scenarios.resolved import Scenario
from trackmj.scenarios.schema import NAME_PATTERN, NOMINAL, ScenarioFile
from trackmj.validator import ParameterError, build, read_toml

BUILTIN_FOLDER = Path(str(files("trackmj.experiments")))
"""The folder of the built-in scenario files (the installed ``trackmj.experiments``)."""
STUDY_CONDITION = re.compile(r"W\d+")
"""Names of the study's operating conditions (Ding et al., Actuators 2025): listed first."""
_SCENARIO_HEADER = re.compile(r"^\s*\[scenario\]\s*(#.*)?$", re.M)


def _is_scenario_file(path: Path) -> bool:
    """Whether ``path`` is named like a scenario and has a ``[scenario]`` table header (a
    file that is not UTF-8 is listed, and refused with its reason when loaded)."""
    return (re.fullmatch(NAME_PATTERN, path.stem) is not None
            and _SCENARIO_HEADER.search(path.read_text(encoding="utf-8-sig", errors="replace"))
            is not None)


def _builtin_order(name: str) -> tuple[bool, tuple[str | int, ...], str]:
    """Sort key: the study's conditions first, then natural order (digit runs as numbers,
    letters case-insensitive: NL2 before NL10), then the name itself."""
    parts = re.split(r"(\d+)", name)
    natural = tuple(int(p) if i % 2 else p.lower() for i, p in enumerate(parts))
    return (STUDY_CONDITION.fullmatch(name) is None, natural, name)


def builtin_names() -> tuple[str, ...]:
    """Names of the built-in scenarios (the file names without ``.toml``) in listing order,
    found in :data:`BUILTIN_FOLDER` now."""
    found = [p.stem for p in BUILTIN_FOLDER.glob("*.toml") if _is_scenario_file(p)]
    return tuple(sorted(found, key=_builtin_order))




def scenario_path(name_or_path: str | Path) -> Path:
    """Path of a built-in scenario (``W1``..``W5``, ``NL1``, case-insensitive) or of a custom
    file."""
    if isinstance(name_or_path, str):
        stem = {n.upper(): n for n in builtin_names()}.get(name_or_path.upper())
        if stem is not None:
            return BUILTIN_FOLDER / f"{stem}.toml"
    path = Path(name_or_path)
    if not path.exists():
        raise ParameterError(f"scenario file not found: {path} (built-in scenarios: "
                             f"{', '.join(builtin_names())})")
    return path


def load_scenario(name_or_path: str | Path,
                  overrides: Mapping[str, Any] | None = None, *,
                  nominal_tension_N: float | None = None,
                  supply_setpoint_Pa: float | None = None) -> Scenario:
    """Load and validate a scenario.

    Parameters
    ----------
    name_or_path : str or Path
        A built-in name (``W1``..``W5``) or a TOML file.
    overrides : mapping, optional
        ``{dotted key: value}``, the ``scenario`` entry of
        :func:`trackmj.validator.parse_overrides` (e.g. ``{"track.speed_m_s": 2.0}``).
    nominal_tension_N, supply_setpoint_Pa : float, optional
        The machine's nominal tension [N] and its hydraulic file's supply set-point [Pa]
        that the relative values (``*_rel`` keys, the [limits] left out) are taken over;
        default the packaged machine's (lf1352).

    Returns
    -------
    Scenario
        Every value absolute.
    """
    path = scenario_path(name_or_path)
    data = read_toml(path)
    for key in overrides or {}:
        drop_twin(data, str(key))
    f = build(ScenarioFile, data, file=path.name, overrides=overrides, require_source=False)
    if nominal_tension_N is None or supply_setpoint_Pa is None:
        packaged = packaged_nominal()
        nominal_tension_N = packaged[0] if nominal_tension_N is None else nominal_tension_N
        supply_setpoint_Pa = packaged[1] if supply_setpoint_Pa is None else supply_setpoint_Pa
    f = resolve(f, nominal_tension_N, supply_setpoint_Pa)   # its refusals name the file
    return _scenario(f, path, nominal_tension_N)


def _scenario(f: ScenarioFile, path: Path, nominal_tension_N: float) -> Scenario:
    """The :class:`Scenario` of the resolved file ``f`` read from ``path``."""
    h = f.scenario
    return Scenario(name=h.name, title=h.title, source=path, duration_s=h.duration_s,
                    seeds=h.seeds, controller=h.controller, estimator=h.estimator,
                    track=f.track, reference=f.reference, supply=f.supply, terrain=f.terrain,
                    load_pulses=f.load_pulses, variants=f.variants or (NOMINAL,),
                    limits=f.limits, evaluation=f.evaluation, machines=h.machines,
                    machines_reason=h.machines_reason, nominal_tension_N=nominal_tension_N,
                    hitch=f.hitch)
