"""Track-structure candidates of issue 21 on the default model: cost and physics checks.

Each candidate edits the default machine's MJCF (machine and scene joined) or its compiled
options here, never the generator:

* ``free``: the committed model (82 free planar links, 82 pin connects).
* ``pairs``: two-link sub-chains: every odd link hinged to the even link before it at their
  shared pin (41 free parents, 41 hinged children, 41 connects: 123 rows, nv 175).
* ``chainN``: sub-chains of N links (cost and revolution probe; their contacts are not
  re-mapped per link).
* ``novisual``: the links' visual shoe geoms removed (fewer geoms in the broadphase).
* solver variants (``+cg``, ``+iter10``, ``+tol1e-6``, ``+ls10``) on either structure.

The track settles 1 s standing under the passive tensioner (``[tensioner]`` of the model
file, implicit damping as :class:`trackmj.plant.PassiveTensioner`), then a 1 s ramp to the
speed, held. ``--check`` measures on flat ground, 3 revolutions after 3 s: the components
[N rms] of the track's contact force on the idler wheel at the revolution frequency (the
measured link-passing frequency / 82), at half the link-passing frequency (two-link
sub-chains repeat every second pin) and at the link-passing frequency (Hann-windowed
single-bin estimates), and the largest pin-connect gap [mm]. ``--callgrind`` counts
instructions per ``mj_step`` (valgrind's callgrind collecting only inside mj_step) over
``--steps`` steps from the snapshot at 1.5 m/s.
Run: ``python benchmarks/bench_structure.py --check pairs --speeds 1.0 1.5 2.0`` or
``python benchmarks/bench_structure.py --callgrind pairs+cg``.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from trackmj.machine import machine
from trackmj.machines import mechanics, model_mjcf, resolve
from trackmj.model.mjcf import contact_kind, soft_constraints
from trackmj.model.soft import row_diag, soft_constraint

MACHINE = resolve(None)   # the default machine (LF1352)
PARAMS = mechanics(MACHINE)
SETTLE_S, RAMP_S = 1.0, 1.0


def _pitch(xmat: np.ndarray) -> float:
    """World angle [rad] of a body's x axis in the x–z plane (rotation about +y)."""
    return math.atan2(-xmat[6], xmat[0])


def pairs_xml(text: str, group: int = 2) -> str:
    """Sub-chains of ``group`` links (the last one shorter when it does not divide 82):
    every link but a chain's first hinged to the preceding link at their shared pin (its
    origin); their pin connects removed; keyframes dropped (the state is mapped in
    :func:`home_state`)."""
    root = ET.fromstring(text)
    world = root.find("worldbody")
    n = PARAMS.track.link_count
    bodies = {b.get("name"): b for b in world.findall("body")}
    base = mujoco.MjModel.from_xml_string(text)
    d = mujoco.MjData(base)
    mujoco.mj_forward(base, d)   # layout pose (qpos0)
    for k in (k for k in range(n) if k % group):
        child, parent = bodies[f"link_{k:02d}"], bodies[f"link_{k - 1:02d}"]
        bp, bc = base.body(parent.get("name")).id, base.body(child.get("name")).id
        rp = d.xmat[bp].reshape(3, 3)
        rel_pos = rp.T @ (d.xpos[bc] - d.xpos[bp])
        q = np.zeros(4)
        conj = d.xquat[bp] * np.array([1.0, -1.0, -1.0, -1.0])
        mujoco.mju_mulQuat(q, conj, d.xquat[bc])
        child.set("pos", " ".join(f"{v:.9g}" for v in rel_pos))
        child.set("quat", " ".join(f"{v:.9g}" for v in q))
        for joint in child.findall("joint"):
            child.remove(joint)
        hinge = ET.Element("joint", name=f"link_{k:02d}_pin", type="hinge", axis="0 1 0",
                           pos="0 0 0")
        child.insert(0, hinge)
        world.remove(child)
        parent.append(child)
    eq = root.find("equality")
    for c in list(eq):
        k = int(c.get("name").split("_")[1])
        if k % group:
            eq.remove(c)
    key = root.find("keyframe")
    if key is not None:
        root.remove(key)
    _remap_soft(root, group)
    return ET.tostring(root, encoding="unicode")


def _remap_soft(root: ET.Element, group: int) -> None:
    """Contacts and pin connects re-mapped to their stated K, B on the sub-chains' row
    diagonals with link_00's weight (what the generator's ``_map_soft_constraints`` does):
    both links of a straight pair have the same ``body_invweight0`` (0.130 1/kg against
    0.190 for a free link); longer chains' links differ (their contacts are then off the
    stated K: a cost probe only). Each remaining connect carries the compliance of the
    ``group`` pins of its chain in series (K/group, B/group), so a span stretches as
    before; the hinged pins are rigid."""
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    mapping = soft_constraints(PARAMS, model)
    for geom in root.iter("geom"):
        soft = mapping.get(geom.get("name", ""))
        if soft is not None and contact_kind(geom.get("name")) is not None:
            geom.set("solref", " ".join(f"{v:.9g}" for v in soft.solref))
            geom.set("solimp", " ".join(f"{v:.9g}" for v in soft.solimp))
    pin = PARAMS.pin_joint
    link = float(model.body_invweight0[model.body("link_00").id, 0])
    rows, diag = row_diag(2.0 * link, condim=1)
    soft = soft_constraint(pin.radial_stiffness_N_m / group, pin.radial_damping_N_s_m / group,
                           rows,
                           diag, PARAMS.simulation.timestep_s, PARAMS.solver.soft_margin,
                           "pairs pin")
    cls = root.find("default/default[@class='pin_joint']/equality")
    cls.set("solref", " ".join(f"{v:.9g}" for v in soft.solref))
    cls.set("solimp", " ".join(f"{v:.9g}" for v in soft.solimp))


def novisual_xml(text: str) -> str:
    """The links' visual shoe geoms removed."""
    return re.sub(r'\n\s*<geom name="link_\d\d_shoe"[^>]*/>', "", text)


def home_state(m: mujoco.MjModel, base_text: str) -> np.ndarray:
    """qpos of ``m`` from the committed model's ``home`` keyframe: the joints ``m`` shares by
    name, and each pin hinge at its child's pitch relative to its parent there."""
    base = mujoco.MjModel.from_xml_string(base_text)
    bd = mujoco.MjData(base)
    mujoco.mj_resetDataKeyframe(base, bd, base.key("home").id)
    mujoco.mj_forward(base, bd)
    b0 = mujoco.MjData(base)
    mujoco.mj_forward(base, b0)
    qpos = m.qpos0.copy()
    for j in range(m.njnt):
        name = m.joint(j).name
        adr = m.jnt_qposadr[j]
        if name.endswith("_pin"):
            k = int(name.split("_")[1])
            c, p = base.body(f"link_{k:02d}").id, base.body(f"link_{k - 1:02d}").id
            now = _pitch(bd.xmat[c]) - _pitch(bd.xmat[p])
            layout = _pitch(b0.xmat[c]) - _pitch(b0.xmat[p])
            qpos[adr] = now - layout
        else:
            qpos[adr] = bd.qpos[base.joint(name).qposadr[0]]
    return qpos


def build(candidate: str) -> tuple[mujoco.MjModel, np.ndarray]:
    """The compiled candidate ("free" or "pairs", "+novisual", solver suffixes) and its
    starting qpos."""
    text = model_mjcf(PARAMS, MACHINE)
    parts = candidate.split("+")
    structure = parts[0]
    if structure.startswith("chain"):   # chainN: sub-chains of N links
        xml = pairs_xml(text, int(structure[5:]))
    else:
        xml = {"free": lambda t: t, "pairs": pairs_xml}[structure](text)
    if "novisual" in parts:
        xml = novisual_xml(xml)
    m = mujoco.MjModel.from_xml_string(xml)
    for opt in parts[1:]:
        if opt == "cg":
            m.opt.solver = mujoco.mjtSolver.mjSOL_CG
        elif opt.startswith("iter"):
            m.opt.iterations = int(opt[4:])
        elif opt.startswith("tol"):
            m.opt.tolerance = float(opt[3:])
        elif opt.startswith("ls"):
            m.opt.ls_iterations = int(opt[2:])
        elif opt == "dense":
            m.opt.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
        elif opt != "novisual":
            raise SystemExit(f"unknown candidate option {opt!r}")
    return m, home_state(m, text)


class Drive:
    """The passive tensioner and the sprocket servo on a compiled candidate."""

    def __init__(self, m: mujoco.MjModel, home: np.ndarray) -> None:
        self.m, self.d = m, mujoco.MjData(m)
        self.d.qpos[:] = home
        mujoco.mj_forward(m, self.d)
        self.slide_q = m.joint("idler_slide").qposadr[0]
        self.slide_v = m.joint("idler_slide").dofadr[0]
        self.sprocket_v = m.joint("sprocket_hinge").dofadr[0]
        self.ten, self.drive = m.actuator("tensioner").id, m.actuator("sprocket_drive").id
        t = PARAMS.tensioner
        self.preload, self.k, self.c = t.preload_N, t.stiffness_N_m, t.damping_N_s_m
        self.ref = PARAMS.idler.stroke_at_layout_m
        self.radius = PARAMS.sprocket_pitch_radius_m
        self.t = 0.0
        self.idler_geom = m.geom("idler_wheel").id
        self._wrench = np.zeros(6)

    def idler_contact_N(self) -> float:
        """Magnitude of the summed contact force of the track on the idler wheel [N]."""
        d, total = self.d, np.zeros(3)
        for i in range(d.ncon):
            c = d.contact[i]
            if self.idler_geom in (c.geom1, c.geom2):
                mujoco.mj_contactForce(self.m, d, i, self._wrench)
                total += c.frame.reshape(3, 3).T @ self._wrench[:3]
        return float(np.linalg.norm(total))

    def step(self, speed: float) -> float:
        """One 1 ms step at track speed [m/s]; returns the idler force at the end-of-step
        velocity [N] (the implicitly integrated affine law)."""
        m, d = self.m, self.d
        stroke = self.ref + d.qpos[self.slide_q]
        f0 = self.preload - self.k * (stroke - self.ref)
        d.ctrl[self.ten] = f0
        m.actuator_biasprm[self.ten, 2] = -self.c
        d.ctrl[self.drive] = speed / self.radius
        mujoco.mj_step(m, d)
        self.t += m.opt.timestep
        return f0 - self.c * d.qvel[self.slide_v]

    def spin_up(self, speed: float) -> None:
        for _ in range(round(SETTLE_S / 1e-3)):
            self.step(0.0)
        for i in range(round((RAMP_S + 0.5) / 1e-3)):
            self.step(speed * min(1.0, (i + 1) * 1e-3 / RAMP_S))

    def pin_gap_m(self) -> float:
        rows = 3 * self.m.neq
        gaps = self.d.efc_pos[:rows].reshape(-1, 3)
        return float(np.sqrt((gaps * gaps).sum(axis=1)).max())


def _component(x: np.ndarray, f_hz: float, dt: float) -> float:
    """Hann-windowed single-bin rms amplitude of ``x`` at ``f_hz`` [same unit as x]."""
    t = dt * np.arange(len(x))
    w = np.hanning(len(x))
    y = (x - x.mean()) * w
    z = np.sum(y * np.exp(-2j * math.pi * f_hz * t))
    return float(abs(z) * 2.0 / w.sum() / math.sqrt(2.0))


def check(candidate: str, speed: float) -> dict[str, float]:
    m, home = build(candidate)
    drv = Drive(m, home)
    drv.spin_up(speed)
    for _ in range(round((3.0 - SETTLE_S - RAMP_S - 0.5) / 1e-3)):
        drv.step(speed)
    n, pitch = PARAMS.track.link_count, PARAMS.track.pitch_m
    steps = round(3 * n * pitch / speed / 1e-3)
    force, omega, gap, warn = np.empty(steps), np.empty(steps), 0.0, 0
    for i in range(steps):
        drv.step(speed)
        force[i] = drv.idler_contact_N()
        omega[i] = drv.d.qvel[drv.sprocket_v]
        gap = max(gap, drv.pin_gap_m())
    warn = int(sum(w.number for w in drv.d.warning))
    # the links pass slower than the sprocket's pitch-line speed suggests (~0.7 % at
    # 1.5 m/s: the chain wraps outside the pitch circle): take the peak near it
    guess = omega.mean() * drv.radius / pitch
    grid = guess * np.linspace(0.97, 1.01, 401)
    f_link = float(grid[np.argmax([_component(force, f, 1e-3) for f in grid])])
    return {"rev_N": _component(force, f_link / n, 1e-3),
            "half_N": _component(force, f_link / 2, 1e-3),
            "link_N": _component(force, f_link, 1e-3),
            "f_link_Hz": f_link, "gap_mm": gap * 1e3, "warnings": warn,
            "finite": float(np.isfinite(drv.d.qpos).all())}


def snapshot_path(candidate: str) -> str:
    return os.path.join(tempfile.gettempdir(), f"bench_structure_{candidate}.npz")


def callgrind(candidate: str, steps: int) -> None:
    m, home = build(candidate)
    drv = Drive(m, home)
    drv.spin_up(1.5)
    d = drv.d
    np.savez(snapshot_path(candidate), qpos=d.qpos, qvel=d.qvel, act=d.act, ctrl=d.ctrl,
             biasprm=m.actuator_biasprm)
    out = os.path.join(tempfile.gettempdir(), f"callgrind.{candidate}.out")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONHASHSEED="0")
    run = subprocess.run(["valgrind", "--tool=callgrind", "--collect-atstart=no",
                    "--toggle-collect=mj_step", f"--callgrind-out-file={out}",
                    sys.executable, __file__, "--replay", candidate, "--steps", str(steps)],
                         check=True, env=env, capture_output=True, text=True)
    solver = next(line for line in run.stderr.splitlines() if line.startswith("solver"))
    total = 0
    with open(out) as f:
        for line in f:
            if line.startswith("summary:") or line.startswith("totals:"):
                total = int(line.split()[1])
    print(f"{candidate}: nv {m.nv}, neq {m.neq}, ngeom {m.ngeom}, nefc {d.nefc}, "
          f"ncon {d.ncon}: {total / steps / 1e6:.3f}M instructions per mj_step "
          f"({steps} steps; {solver})")


def replay(candidate: str, steps: int) -> None:
    m, home = build(candidate)
    drv = Drive(m, home)
    s = np.load(snapshot_path(candidate))
    d = drv.d
    d.qpos[:], d.qvel[:], d.act[:], d.ctrl[:] = s["qpos"], s["qvel"], s["act"], s["ctrl"]
    m.actuator_biasprm[:] = s["biasprm"]
    mujoco.mj_forward(m, d)
    iters = 0
    for _ in range(steps):
        mujoco.mj_step(m, d)
        iters += int(d.solver_niter[0])
    print(f"solver iterations per step {iters / steps:.2f}, nefc {d.nefc}", file=sys.stderr)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", nargs="*", default=[], metavar="CANDIDATE")
    parser.add_argument("--callgrind", nargs="*", default=[], metavar="CANDIDATE")
    parser.add_argument("--replay", help=argparse.SUPPRESS)
    parser.add_argument("--speeds", type=float, nargs="+", default=[1.5])
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    if args.replay:
        replay(args.replay, args.steps)
        return
    print(f"machine: {machine()}")
    for cand in args.callgrind:
        callgrind(cand, args.steps)
    for cand in args.check:
        for v in args.speeds:
            r = check(cand, v)
            print(f"{cand} @ {v:.1f} m/s: revolution {r['rev_N']:.2f} N, half link-passing "
                  f"{r['half_N']:.2f} N, link-passing {r['link_N']:.1f} N at "
                  f"{r['f_link_Hz']:.2f} Hz; max pin gap {r['gap_mm']:.3f} mm, warnings "
                  f"{r['warnings']}, finite {bool(r['finite'])}", flush=True)


if __name__ == "__main__":
    main()
