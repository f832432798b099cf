"""A machine's track as a :class:`~trackmj.track.plant.TrackPlant`: :func:`load_plant`.

The plant is built from the machine's files (:mod:`trackmj.machines.assembly`: its
mechanics and committed MJCF), or from a mechanics file, overrides or an MJCF file given
instead. It sits with the machines, above the track layer whose plant it builds.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import mujoco

from trackmj.hydraulics.params import load_hydraulic_params
from trackmj.machines.assembly import (
    check_cylinder_stroke,
    mechanics,
    model_mjcf,
    reference_mjcf,
    resolve,
)
from trackmj.track.mechanics import load_model_params
from trackmj.track.mjcf.builders import read_mjcf, with_heightfield
from trackmj.track.plant import TrackPlant
from trackmj.track.terrain import RoadProfile


def load_plant(xml_path: str | Path | None = None, param_path: str | Path | None = None,
               terrain: RoadProfile | None = None, *, machine: str | Path | None = None,
               overrides: Mapping[str, Any] | None = None) -> TrackPlant:
    """Load a machine's track (default the packaged LF1352).

    machine: a shipped machine's name or a machine file (:mod:`trackmj.machines.assembly`),
    whose hydraulic file's cylinder stroke the mechanics' must fit
    (:func:`~trackmj.machines.assembly.check_cylinder_stroke`);
    param_path: a model parameter file replacing the machine's mechanics; overrides:
    ``{dotted key: value}`` of the model file (``--set model.KEY=VALUE``); xml_path: an
    MJCF file to load instead of the model of those parameters (the machine's committed
    reference for its own parameters, else generated and cached; a scene that includes
    its machine part is joined with it). terrain: optional
    road profile replacing the flat ground by a heightfield (see
    :func:`trackmj.track.mjcf.builders.with_heightfield`).
    """
    mach = resolve(machine)
    params = (load_model_params(param_path or mach.mechanics, overrides=overrides)
              if param_path is not None or overrides else mechanics(mach))
    check_cylinder_stroke(params, Path(param_path or mach.mechanics).name,
                          load_hydraulic_params(mach.hydraulics), mach.hydraulics.name)
    if xml_path is not None:
        path: Path | None = Path(xml_path)
        if not path.is_file():
            raise FileNotFoundError(f"model file not found: {path}")
        text = read_mjcf(path)
    else:
        path = reference_mjcf(params, mach)
        text = model_mjcf(params, mach)
    try:
        if terrain is not None:
            text = with_heightfield(text, terrain)
        model = mujoco.MjModel.from_xml_string(text)
    except ValueError as exc:
        raise ValueError(f"{path or 'generated model'}: MuJoCo could not load the model: "
                         f"{exc}") from None
    plant = TrackPlant(model, params)
    plant.model_path = path
    return plant
