"""Track structure "chains": short hinged sub-chains joined by pin connects.

Applied to the generated MJCF tree after the free links and their pin connects exist
(:func:`chain_links`), so the generator's link code stays one. The loop of n links is cut,
from link_00 on, into c = ceil(n / L) consecutive chains of at most L links
(``[track] chain_links``), their sizes as equal as possible (:func:`chain_sizes`). In each
chain every link but the first becomes a child of the link before it, hinged about +y at
their shared pin (the child's origin), and that pin's ``connect`` is removed; the first link
of a chain stays a free planar body (3 DOF) and the connect at its pin closes the loop. For
the LF1352 (82 links, L = 4: 19 chains of 4 and 2 of 3) this gives nv 257 -> 135 and 63
instead of 246 pin-connect rows (``benchmarks/README.md``, track structure candidates).
``chain_links = 2`` are the two-link pairs measured before.

Physics kept (measured there): every connect carries the compliance of its chain's pins in
series (K/m, B/m for a chain of m links, :func:`pin_series_count`), so a span stretches as
before while the hinged pins are rigid (the study's revolute pins). MuJoCo computes each
link's ``body_invweight0`` at qpos0 and it differs with the link's place in its chain;
:func:`equalise_link_weights` gives every link link_00's after compiling (the plant and the
generator's settle call it), so one solref per partner geom keeps every contact at its
stated stiffness (:mod:`trackmj.track.mjcf.soft`). The revolution component of the idler force
stays ≤ 4 % of the link-passing one at 1.0/1.5/2.0 m/s and the connect gaps ≤ 0.32 mm.
The pins' torsional spring-damper (bushings) follows the planar joint coordinates
(:func:`_chain_torsion`): a chain's root turns by −(its pitch hinge) and each hinged link by
−(its pin hinge) more, so the twist at a hinged pin is that hinge's angle from in-line (the
spring and damper sit on the hinge joint, ``springref`` the layout's in-line angle; the
step takes the damper into its mass matrix, :func:`torsion_hinge_ids`), and at a connect
starting chain c+1 it is root pitch(c+1) − root pitch(c) − Σ pin hinges(c), a fixed tendon
``pin_kk_torsion`` with coefficients ±1 (tested: a clamped strand bent by a couple M turns
every pin by M/k_t).

Track structure "slides": the chains above with every pin compliant on its own. Before each
pin hinge a slide ``link_kk_stretch`` along the parent link's pitch carries that pin's
stated stiffness K and damping B as joint stiffness and damping (class ``pin_stretch``), and
every connect carries one pin, so a loaded strand's pins stretch T/K each, as free links'
do, instead of a chain's m pins' worth at one connect (chains of 4 at standstill: pitch
75.000/75.000/75.000/75.108 mm, lines at the odd quarters of the link-passing frequency).
trackmj's step integrates the slides' springs by backward Euler
(:class:`trackmj.track.foundation.ImplicitSprings`: h²K in the solver's mass matrix) and
simulates no armature. ``implicitfast`` alone integrates joint stiffness explicitly (h²K/m
≈ 57 for a 3.5 kg link at 2e8 N/m: it diverges), so for MuJoCo's own stepping of the file
(its viewer) each slide carries an armature equal to the apparent mass a connect of the
same K, B already has (:func:`stretch_armature_kg`).
Cost: one more DOF per hinged pin (LF1352: nv 135 -> 196), 1.33x the instructions of chains
per step (``benchmarks/README.md``, "Every pin compliant on its own").
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable

import mujoco
import numpy as np

from trackmj.track.mechanics import ModelParams
from trackmj.track.mjcf.names import link_name, pin_name, stretch_name
from trackmj.track.mjcf.tree import attribute, find


def chain_sizes(link_count: int, max_links: int) -> list[int]:
    """Links per chain, in loop order from link_00: ceil(n / L) chains of at most L links,
    sizes differing by at most one, the longer ones spread evenly round the loop."""
    count = math.ceil(link_count / max_links)
    base, longer = divmod(link_count, count)
    return [base + ((i + 1) * longer // count - i * longer // count) for i in range(count)]


def chain_starts(p: ModelParams) -> list[int]:
    """Index of the first link of every chain (its pin is a connect), ascending; every
    link for ``structure = "free"``."""
    n = p.track.link_count
    if p.track.structure == "free":
        return list(range(n))
    sizes = chain_sizes(n, p.track.chain_links)
    return [sum(sizes[:i]) for i in range(len(sizes))]


def structure_text(p: ModelParams) -> str:
    """One line on the loop's structure, e.g. "chains: 19 of 4 links, 2 of 3" or "free
    links"."""
    if p.track.structure == "free":
        return "free links, every pin a connect"
    sizes = chain_sizes(p.track.link_count, p.track.chain_links)
    counts = sorted({size: sizes.count(size) for size in sizes}.items(), reverse=True)
    text = ", ".join(f"{count} of {size}" for size, count in counts) + " links"
    if p.track.structure == "slides":
        return f"slides: chains ({text}), every hinged pin on its own compliant slide"
    return "chains: " + text


def pin_series_count(p: ModelParams) -> dict[int, int]:
    """Pins whose compliance each pin ``connect`` carries, by its pin index: the size of the
    chain it begins for "chains", 1 for free links and for "slides" (whose hinged pins
    carry their own on their slides)."""
    starts = chain_starts(p)
    if p.track.structure == "slides":
        return dict.fromkeys(starts, 1)
    ends = [*starts[1:], p.track.link_count]
    return {s: e - s for s, e in zip(starts, ends, strict=True)}


def stretch_armature_kg(p: ModelParams) -> float:
    """Armature of every pin slide in the MJCF, for MuJoCo's own stepping (trackmj's step
    sets it to 0 and integrates the spring implicitly) [kg]: soft_margin·(h²K + 2hB)/4, the
    apparent mass a soft ``connect`` of the pin's K, B carries at the step h
    (:mod:`trackmj.track.mjcf.soft`: the margin over the stability limit h²K/m + 2hB/m ≤ 4
    of the explicit spring and the implicit damper, which the slide's joint stiffness under
    ``implicitfast`` has as well). LF1352 (K 2e8 N/m, B 1e3 N·s/m, h 1 ms, margin 1.5):
    76 kg."""
    h, joint = p.simulation.timestep_s, p.pin_joint
    return p.solver.soft_margin * (h * h * joint.radial_stiffness_N_m
                                   + 2.0 * h * joint.radial_damping_N_s_m) / 4.0


def pin_slide_ids(model: mujoco.MjModel, links: Iterable[int]) -> dict[int, int]:
    """Joint id of link k's pin slide (``stretch_name(k)``, structure "slides") for each k
    of ``links``; −1 where the link has none (chains, free links, a chain's first link)."""
    return {k: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, stretch_name(k))
            for k in links}


def torsion_hinge_ids(model: mujoco.MjModel, links: Iterable[int]) -> list[int]:
    """Joint ids of the pin hinges ``link_kk_pin`` among ``links`` that carry a torsional
    damper (bushings on chains or slides), for the step's implicit dampers
    (:class:`trackmj.track.foundation.ImplicitSprings`); none without torsional damping."""
    ids = (mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, link_name(k) + "_pin")
           for k in links)
    return [j for j in ids if j >= 0 and model.dof_damping[model.jnt_dofadr[j]] > 0.0]


def hinged_pins(p: ModelParams) -> list[int]:
    """Pins that are hinges (every pin inside a chain; none for free links)."""
    starts = set(chain_starts(p))
    return [k for k in range(p.track.link_count) if k not in starts]


def _floats(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split()])


def chain_links(root: ET.Element, p: ModelParams) -> None:
    """Hinge every link inside a chain to the link before it, for "slides" on a compliant
    slide along the parent's pitch, and move the pins' torsional spring-damper onto the
    chained coordinates (:func:`_chain_torsion`; see the module docstring)."""
    world = find(root, "worldbody")
    bodies = {b.get("name"): b for b in world.findall("body")}
    # world pose of every link at the layout, before any is re-parented
    pose = {link_name(k): (_floats(attribute(bodies[link_name(k)], "pos")),
                           _floats(attribute(bodies[link_name(k)], "quat")))
            for k in range(p.track.link_count)}
    rot, conj, rel_quat = np.empty(9), np.empty(4), np.empty(4)
    for k in hinged_pins(p):
        child, parent = bodies[link_name(k)], bodies[link_name(k - 1)]
        (pp, qp), (pc, qc) = pose[link_name(k - 1)], pose[link_name(k)]
        mujoco.mju_quat2Mat(rot, qp)
        rel_pos = rot.reshape(3, 3).T @ (pc - pp)
        mujoco.mju_negQuat(conj, qp)
        mujoco.mju_mulQuat(rel_quat, conj, qc)
        child.set("pos", " ".join(f"{v:.9g}" for v in rel_pos))
        child.set("quat", " ".join(f"{v:.9g}" for v in rel_quat))
        for j in child.findall("joint"):
            child.remove(j)
        child.insert(0, ET.Element("joint", name=link_name(k) + "_pin", type="hinge",
                                   axis="0 1 0", pos="0 0 0"))
        if p.track.structure == "slides":   # the parent's x axis in the child's frame
            mujoco.mju_quat2Mat(rot, rel_quat)
            axis = rot.reshape(3, 3).T @ (1.0, 0.0, 0.0)
            child.insert(0, ET.Element("joint", {
                "name": stretch_name(k), "class": "pin_stretch", "pos": "0 0 0",
                "axis": " ".join(f"{v:.9g}" for v in axis)}))
        world.remove(child)
        parent.append(child)
    equality = find(root, "equality")
    for k in hinged_pins(p):
        equality.remove(find(equality, f"connect[@name='{pin_name(k)}']"))
    _chain_torsion(root, p)


def _chain_torsion(root: ET.Element, p: ModelParams) -> None:
    """Rewrite the free links' torsion tendons ``pin_kk_torsion`` (pitch_k − pitch_{k−1},
    ``springlength`` the in-line value) for the chains. A hinged pin's twist is its hinge
    angle alone: the tendon becomes the hinge's own stiffness and damping about
    ``springref`` = that in-line value (the plant's step takes a joint's damper into its
    mass matrix, :func:`torsion_hinge_ids`; a tendon's it cannot; for MuJoCo's own stepping,
    its viewer, the hinge carries that term h·B as an armature, which the plant's step
    zeroes: without it MuJoCo's implicit damper diverges, M113 driven at 2 m/s at 1.2 s).
    A connect's tendon keeps +1 on its own chain's root pitch and replaces −1 on the
    previous chain's last link by −1 on that chain's root pitch and on every pin hinge of
    the chain (each hinge turns its child and all after it by −q about +y). No tendons (no
    torsion): nothing to do."""
    tendons = root.find("tendon")
    if tendons is None:
        return
    links = find(root, "worldbody")
    hinges = {attribute(j, "name"): j for j in links.iter("joint")}
    starts = chain_starts(p)
    n = p.track.link_count
    for k in hinged_pins(p):
        fixed = find(tendons, f"fixed[@name='{pin_name(k)}_torsion']")
        hinge = hinges[link_name(k) + "_pin"]
        hinge.set("stiffness", attribute(fixed, "stiffness"))
        hinge.set("damping", attribute(fixed, "damping"))
        hinge.set("springref", attribute(fixed, "springlength"))
        damping = float(attribute(fixed, "damping"))
        if damping > 0.0:
            hinge.set("armature", repr(p.simulation.timestep_s * damping))
        tendons.remove(fixed)
    for c, start in enumerate(starts):
        first = starts[c - 1]   # the previous chain's root (the last chain for c = 0)
        last = (start - 1) % n
        fixed = find(tendons, f"fixed[@name='{pin_name(start)}_torsion']")
        fixed.remove(find(fixed, f"joint[@joint='{link_name(last)}_pitch']"))
        ET.SubElement(fixed, "joint", joint=link_name(first) + "_pitch", coef="-1")
        for k in range(first + 1, last + 1):
            ET.SubElement(fixed, "joint", joint=link_name(k) + "_pin", coef="-1")
    if not len(tendons):
        root.remove(tendons)


def equalise_link_weights(model: mujoco.MjModel) -> None:
    """Give every link of a chained model link_00's ``body_invweight0`` (see the module
    docstring); a free-link model is left as it is (all its links alike)."""
    links = [b for b in range(model.nbody) if model.body(b).name.startswith("link_")]
    links.sort(key=lambda b: int(model.body(b).name.split("_")[1]))   # link_00 first
    if any(model.body_parentid[b] != 0 for b in links):
        model.body_invweight0[links] = model.body_invweight0[links[0]]
