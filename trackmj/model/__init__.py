"""Generator of a machine's track-side MuJoCo model (``models/lf1352.xml`` and its scene
``models/lf1352_scene.xml`` for the study's LF1352; any single-side layout).

Subpackages, each a stage of the model: :mod:`.params` (the validated parameter file and
its layout checks), :mod:`.layout` (pin positions that close the loop), :mod:`.geometry`
(derived geometry: wraps, spans, static strand tension), :mod:`.soft` (stated stiffness and
damping -> MuJoCo soft-constraint parameters), :mod:`.mjcf` (one builder per subtree, the
machine/scene split, the heightfield terrain), :mod:`.generate` (settled ``home``
keyframe, the committed files), :mod:`.cache` (generated models by content hash).
Nothing here imports the plant.
"""

from trackmj.model.generate import generate_mjcf, write_model
from trackmj.model.layout import Layout, compute_layout
from trackmj.model.mjcf import build_mjcf, link_name, pin_name, soft_constraints, with_heightfield
from trackmj.model.params import (
    MODEL_NAME,
    ModelParams,
    default_param_path,
    default_xml_path,
    load_model_params,
    models_dir,
)

__all__ = [
    "MODEL_NAME",
    "Layout",
    "ModelParams",
    "build_mjcf",
    "compute_layout",
    "default_param_path",
    "default_xml_path",
    "generate_mjcf",
    "link_name",
    "load_model_params",
    "models_dir",
    "pin_name",
    "soft_constraints",
    "with_heightfield",
    "write_model",
]
