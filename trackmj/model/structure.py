"""Track structure "pairs": two-link sub-chains instead of 82 free links (issue 21).

Applied to the generated MJCF tree after the free links and their pin connects exist
(:func:`pair_links`), so the generator's link code stays one: every odd link k becomes a
child of link k−1, hinged about +y at their shared pin k (the child's origin), and pin k's
``connect`` is removed. 41 free planar parents (3 DOF each) carry one hinged child (1 DOF):
nv 257 -> 175 and 123 instead of 246 pin-connect rows; callgrind 2.92M -> 2.16M
instructions per bare step at 1.5 m/s (``benchmarks/README.md``, track structure candidates).

Physics kept (measured there): both links of a straight pair have the same
``body_invweight0`` (0.130 1/kg, a free link 0.190), which the contact mapping of
:mod:`trackmj.model.soft` uses (link_00's, one solref per partner geom). MuJoCo computes it at
qpos0, the layout, where a pair laid on a wrap weighs up to 3.9 % more (its contacts would be
up to ~4 % softer than stated); :func:`equalise_pair_weights` gives every link the straight
pair's value after compiling (the plant and the generator's settle call it), so the static
stiffness is the stated one within 0.1 % (ground) and 0.07 % (rails); each remaining connect
carries the compliance of the two pins of its stretch in series (K/2, B/2,
:func:`pin_series_count`), so a span stretches as before while the hinged pins are rigid.
The revolution component stays ≤ 3 % of the link-passing one at 1.0/1.5/2.0 m/s, the
half-link-passing component within 8 % of the free links', pin gaps ≤ 0.17 mm.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from trackmj.model.params import ModelParams
from trackmj.params import ParameterError


def pin_series_count(p: ModelParams) -> int:
    """Pins whose compliance one pin ``connect`` carries: 2 for pairs, 1 for free links."""
    return 2 if p.track.structure == "pairs" else 1


def hinged_pins(p: ModelParams) -> list[int]:
    """Pins that are hinges (odd pins for pairs; none for free links)."""
    return list(range(1, p.track.link_count, 2)) if p.track.structure == "pairs" else []


def _floats(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def pair_links(root: ET.Element, p: ModelParams) -> None:
    """Hinge every odd link to the even link before it (see the module docstring); refuses
    an odd link count and torsional bushings (their tendons join pitch hinges that the
    children no longer have)."""
    n = p.track.link_count
    if n % 2:
        raise ParameterError(f"[track] structure = \"pairs\" needs an even link_count, got {n}")
    joint = p.pin_joint
    if joint.torsional_stiffness_N_m_rad > 0.0 or joint.torsional_damping_N_m_s_rad > 0.0:
        raise ParameterError(f"[track] structure = \"pairs\" does not take the "
                             f"[{p.pin_joint_table}] torsional spring-damper; use "
                             "structure = \"free\" with it")
    from trackmj.model.mjcf import link_name, pin_name  # mjcf imports this module

    world = root.find("worldbody")
    bodies = {b.get("name"): b for b in world.findall("body")}
    for k in hinged_pins(p):
        child, parent = bodies[link_name(k)], bodies[link_name(k - 1)]
        qp, qc = _floats(parent.get("quat")), _floats(child.get("quat"))
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, qp)
        rel_pos = rot.reshape(3, 3).T @ (_floats(child.get("pos")) - _floats(parent.get("pos")))
        conj, rel_quat = np.empty(4), np.empty(4)
        mujoco.mju_negQuat(conj, qp)
        mujoco.mju_mulQuat(rel_quat, conj, qc)
        child.set("pos", " ".join(f"{v:.9g}" for v in rel_pos))
        child.set("quat", " ".join(f"{v:.9g}" for v in rel_quat))
        for j in child.findall("joint"):
            child.remove(j)
        child.insert(0, ET.Element("joint", name=link_name(k) + "_pin", type="hinge",
                                   axis="0 1 0", pos="0 0 0"))
        world.remove(child)
        parent.append(child)
    equality = root.find("equality")
    for k in hinged_pins(p):
        equality.remove(equality.find(f"connect[@name='{pin_name(k)}']"))


def equalise_pair_weights(model: mujoco.MjModel) -> None:
    """Give every link of a pairs model link_00's ``body_invweight0`` (the straight pair's;
    see the module docstring); a free-link model is left as it is (all its links alike)."""
    links = [b for b in range(model.nbody) if model.body(b).name.startswith("link_")]
    links.sort(key=lambda b: int(model.body(b).name.split("_")[1]))   # link_00 first
    if any(model.body_parentid[b] != 0 for b in links):
        model.body_invweight0[links] = model.body_invweight0[links[0]]
