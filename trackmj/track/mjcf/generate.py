"""Generation of a machine's MJCF (``models/lf1352.xml`` for the study's): layout, a check
of the initial state, and the ``home`` keyframe found by settling under gravity with the
passive tensioner preload.

Settling uses MuJoCo and the ground foundation (:mod:`trackmj.track.foundation`, as the plant
steps them), no plant: the passive spring-damper F = preload − k·(s − s_layout) − c·v is
the tensioner actuator's affine bias (``ctrl = preload``, ``biasprm = (0, −k, −c)``; the
slide position is s − s_layout), which ``implicitfast`` integrates with the damping
implicit.
"""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np

from trackmj.io import write_text_atomic
from trackmj.track.foundation import Foundation, FoundationLaw, ImplicitSprings, step
from trackmj.track.mechanics import MODEL_NAME, ModelParams, default_xml_path, load_model_params
from trackmj.track.mjcf.builders import build_mjcf, split_mjcf
from trackmj.track.mjcf.layout import compute_layout
from trackmj.track.mjcf.names import link_name
from trackmj.track.mjcf.structure import equalise_link_weights, pin_slide_ids, torsion_hinge_ids
from trackmj.validator import ParameterError

SETTLE_DURATION_S = 3.0
MAX_INITIAL_PENETRATION_M = 1e-3
GEOM_KEYS = ((r"link_\d+_pin", ("[track].pin_radius_m",)),
             (r"link_\d+_rail", ("[track].rail_radius_m",)),
             (r"sprocket_tooth_\d+", ("[sprocket].tooth_radius_m",
                                      "[sprocket].tooth_radial_offset_m")),
             (r"sprocket_hub", ("[track].pitch_m", "[sprocket].tooth_count")),
             (r"idler_wheel", ("[idler].radius_m", "[idler].x_m", "[idler].z_m")),
             (r"road_wheel_\d+_collision", ("[road_wheels].radius_m", "[road_wheels].x_m")),
             (r"return_roller_\d+_collision", ("[return_rollers].radius_m",
                                               "[return_rollers].x_m", "[return_rollers].z_m")))
"""Mechanics keys that size or place a collision geom (by name pattern); the ground has none."""


def geom_keys(name: str) -> tuple[str, ...]:
    """The mechanics keys of :data:`GEOM_KEYS` that set geom ``name`` (none for the ground)."""
    return next((keys for pattern, keys in GEOM_KEYS if re.fullmatch(pattern, name)), ())


def settle(model: mujoco.MjModel, params: ModelParams, duration_s: float) -> mujoco.MjData:
    """State after ``duration_s`` [s] from the layout, standing (sprocket servo at 0 rad/s),
    under the passive tensioner of ``params``, the pin slides' springs and the pin hinges'
    torsional dampers implicit as in the plant's step; ParameterError naming the mechanics
    file on an initial penetration or on MuJoCo warnings while settling."""
    equalise_link_weights(model)
    data = mujoco.MjData(model)
    pins = [model.geom(link_name(k) + "_pin").id for k in range(params.track.link_count)]
    foundation = Foundation(model, data, pins, FoundationLaw.from_params(params))
    slides = [j for j in pin_slide_ids(model, range(params.track.link_count)).values()
              if j >= 0]
    springs = ImplicitSprings(model, data, slides,
                              torsion_hinge_ids(model, range(params.track.link_count)))
    tensioner = model.actuator("tensioner").id
    t = params.tensioner
    model.actuator_biasprm[tensioner, :3] = (0.0, -t.stiffness_N_m, -t.damping_N_s_m)
    data.ctrl[tensioner] = t.preload_N
    mujoco.mj_forward(model, data)
    worst = min(data.contact[: data.ncon], key=lambda c: c.dist, default=None)
    if worst is not None and worst.dist < -MAX_INITIAL_PENETRATION_M:
        names = [model.geom(g).name for g in (worst.geom1, worst.geom2)]
        keys = dict.fromkeys(k for name in names for k in geom_keys(name))
        raise ParameterError(f"{_origin(params)}: initial layout penetrates by "
                             f"{-worst.dist * 1e3:.2f} mm (limit "
                             f"{MAX_INITIAL_PENETRATION_M * 1e3:.1f} mm): {names[0]} into "
                             f"{names[1]}: check {', '.join(keys) or 'radii and positions'}")
    steps = round(duration_s / model.opt.timestep)
    for _ in range(steps):
        step(model, data, foundation, springs)
    warned = _warnings(model, data)
    if warned:
        h = params.simulation.timestep_s
        raise ParameterError(f"{_origin(params)}: the model goes unstable while "
                             f"settling its home keyframe (MuJoCo: {warned}): a stiffness or "
                             f"damping too high for [simulation].timestep_s = {h:g} s; check "
                             "[contacts], [ground], [pins] (or [bushings]) and "
                             "[solver].soft_margin (models/README.md, Stiffness of the parts)")
    return data


def _origin(params: ModelParams) -> str:
    """The mechanics file of ``params`` with the run's --set changes to it, e.g.
    'mine.toml with --set model.contacts.rail_stiffness_N_m' ('ModelParams' built in code)."""
    changed = ", ".join(params.origin.overridden.values())
    return params.origin.table() + (f" with {changed}" if changed else "")


def _warnings(model: mujoco.MjModel, data: mujoco.MjData) -> str:
    """MuJoCo's warnings raised in ``data``, by name ('BADQACC at link_20'), '' if none."""
    out = []
    for i, w in enumerate(data.warning):
        if w.number:
            name = mujoco.mjtWarning(i).name.removeprefix("mjWARN_")
            if i == mujoco.mjtWarning.mjWARN_BADQACC and 0 <= w.lastinfo < model.nv:
                name += f" at {model.body(model.dof_bodyid[w.lastinfo]).name}"
            out.append(name)
    return ", ".join(out)


def generate_mjcf(params: ModelParams | None = None, name: str = MODEL_NAME) -> str:
    """Full MJCF of the model with the settled ``home`` keyframe (``name``: the machine's).

    Keyframe values are rounded to 1e-6 so the committed file does not depend on the
    last bits of floating-point arithmetic.
    """
    params = params or load_model_params()
    layout = compute_layout(params)
    model = mujoco.MjModel.from_xml_string(build_mjcf(params, layout))
    data = settle(model, params, SETTLE_DURATION_S)
    return build_mjcf(params, layout, home_qpos=np.round(data.qpos, 6), name=name)


def scene_path(path: str | Path) -> Path:
    """The scene file beside a machine's MJCF ``NAME.xml``: ``NAME_scene.xml``."""
    path = Path(path)
    return path.with_name(f"{path.stem}_scene.xml")


def write_model(path: str | Path | None = None, params: ModelParams | None = None,
                name: str = MODEL_NAME, *, origin: str) -> Path:
    """Generate the model and write its two parts atomically (Menagerie habit): the machine
    to ``path`` (default: packaged lf1352.xml) and the scene that includes it (ground,
    light) to :func:`scene_path`, both headed by ``origin`` (the mechanics file, the
    command that regenerates them). Returns the scene's path, the file to load."""
    path = Path(path) if path is not None else default_xml_path()
    machine, scene = split_mjcf(generate_mjcf(params, name), path.name, origin)
    write_text_atomic(path, machine)
    write_text_atomic(scene_path(path), scene)
    return scene_path(path)
