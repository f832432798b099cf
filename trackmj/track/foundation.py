"""Kelvin–Voigt foundation under the track's pins: a force element outside MuJoCo's
constraint solver.

The study models the terrain as an equivalent Kelvin–Voigt foundation, its stiffness and
damping identified from sinkage–load tests, with Coulomb friction at the track–terrain
contact (Ding et al., *Actuators* 2025, 14(12), 615). Here every pin sphere (centre c,
radius r) meets the ground line of the model's ``ground`` geom (:func:`ground_line`: a plane
at its height, or the heightfield's profile, piecewise linear in x and held at its end
heights beyond it). With g the point of the line closest to c, n the unit normal out of the
ground (from g towards c) and t = (n_z, −n_x) the tangent (+x on flat ground), per pin:

    δ   = r − d                        penetration [m], d the signed distance of c above
                                       the line (negative below it)
    p   = c − r·n                      contact point on the pin; v = J_p·q̇ its velocity,
                                       v_n = n·v, v_t = t·v [m/s]
    N   = max(0, K·δ − B_δ·v_n)        normal force [N]: the foundation pushes, never pulls;
                                       B_δ = B·min(1, δ/δ_B) [N·s/m]
    F_t = −μ·N·(j + τ·v_t)/K_j         friction [N] while N > 0 and |F_t| < μ·N (stick),
                                       j the shear displacement of the contact along t
                                       [m], dj/dt = v_t; else F_t = ∓μ·N, j = ±K_j (slide)

(K, B, δ_B = ``[ground]`` stiffness, damping and damping onset, μ =
``[track].ground_friction``, K_j = ``[ground].shear_modulus_m``, τ = B/K), applied at p as
the force N·n + F_t·t through the pin body's row of ``xfrc_applied`` (a wrench at its centre
of mass). The stated K and B are thus the simulated ones by construction (B for a pin sunk
δ_B or more), for any terrain, and a soft-soil law would replace the lines above. The
damping grows from zero at touchdown to B at δ_B, as Hunt and Crossley (1975) argued contact
damping must: a damper at full strength from the first micrometre pushes a pin that merely
grazes the ground (measured: pins carrying ~30 N, δ = 15 µm, switched between pushing and
lifted off every few steps at mm/s of vertical velocity, which B·v_n = 40 N decides). The
friction is Janosi–Hanamoto's shear law τ = τ_max·(1 − e^(−j/K_j)) (Wong, *Theory of Ground
Vehicles*, ch. 2) by its initial tangent, capped at Coulomb's μ·N: an
elastic–perfectly-plastic tangential spring, as Cundall and Strack's (1979) for granular
contacts, with the retardation time τ = B/K of the normal Kelvin–Voigt element (assumed: the
soil's shear damping is not published; it damps a 3.5 kg link on its shear spring at ~0.8 of
critical). Below the limit a pin shears j = K_j·F_t/(μ·N) and then holds: a parked machine
does not creep; sliding, the friction is Coulomb's exactly. j starts at 0 when a pin touches
down and is forgotten when it lifts off.

Integration. MuJoCo's ``implicitfast`` step is semi-implicit Euler: the spring K·δ is
explicit, as it is for MuJoCo's own soft contacts (stable while h²·K/4 stays below the mass
at the pin; the model file's validator refuses K above 4·m/h² with m a third of a link, the
mass at one end of a link pivoting about the other). The damping and the shear spring are
implicit, with C_n = B_δ along n and C_t = (h + τ)·μ·N_ref/K_j along t while sticking (0
sliding): :meth:`Foundation.apply` runs between ``mj_step1`` and ``mj_step2`` and adds
h·(C_n·J_nᵀJ_n + C_t·J_tᵀJ_t) = h·D to MuJoCo's mass matrix, which ``mj_factorM`` then
refactors, so that the constraint solver and the integrator both use M + h·D:

    M·(v₁ − v₀) = h·(f + J_pᵀ·F(v₀)) − h·D·(v₁ − v₀),

so that the force applied over the step is the law at the end-of-step velocity, N = K·δ
− B_δ·v_n1 and F_t = −μ·N_ref·(j₀ + (h + τ)·v_t1)/K_j (as the tensioner's F0 + Z·v).
:meth:`Foundation.finish` puts the true mass matrix back after ``mj_step2`` (its factor
``qLD`` stays that of M + h·D until the next step) and adds the implicit part −C·J·Δv to
the pins' wrenches, so that ``xfrc_applied`` then holds what the foundation applied over
the step (``mj_rnePostConstraint``, hence the hinged pins' tensions, sees it). The solver
must see D: MuJoCo's own velocity-derivative route (tendon damping in ``qDeriv``) leaves
it out of the constraint solve, which then passes the explicit −B·v₀ through the stiff pin
connects to links the damper does not slow (measured on the LF1352: divergence within
60 ms even at B = 200 N·s/m).

The same step (:func:`step`) integrates the pin slides' springs by backward Euler
(:class:`ImplicitSprings`, structure "slides"): their h²·K joins h·D in the mass matrix the
solver and the integrator use, so they need no armature.

Active set. Which pins push, which stick and the normal force N_ref that bounds friction are
chosen before the step (from v_n extrapolated over it, N_ref = the predicted N) but known
only after it, so :func:`step` checks every pin against the law at v₁: a pin whose applied
normal pulls is taken as lifted off, one the law would push as touching (unless it pulled
touching in an earlier attempt of the step: then it stays off, never pulled), one whose
friction exceeds μ·N applied takes that N as N_ref, one whose stick force passed μ·N_ref
slides; the step is then taken again from its saved start with that choice (``mj_step2``
only), at most :data:`MAX_ATTEMPTS` times — a semi-smooth Newton iteration on the
complementarity of each pin, the rows MuJoCo's own solver would carry for a hard contact.
N_ref cannot follow v_n1 inside one solve: ∂F_t/∂v_n = μ·B·j/K_j would make M + h·D
unsymmetric, which MuJoCo's factorisation cannot take. On the LF1352 driven at 1.5 m/s about
1 step in 27 is taken again (pins touching down and lifting off). Applied forces therefore
keep N ≥ −:data:`TOLERANCE_N` and |F_t| ≤ μ·N + :data:`TOLERANCE_N`.

State per pin after :meth:`Foundation.apply` (columns of :attr:`Foundation.state`, SI):
penetration δ [m], normal (n_x, n_z) [-], v_n, v_t at the step's start [m/s], explicit
N, F_t [N], C_n, C_t [N·s/m], contact point (p_x, p_z) [m], pushing (1/0), sliding
direction (±1, 0 sticking), N_ref [N], and after :meth:`Foundation.finish` the applied N,
F_t [N] and v_n, v_t at the step's end [m/s]; :attr:`Foundation.jac` holds J_n·, J_t· over
each pin's dofs and :attr:`Foundation.memory` what a step leaves for the next (j [m], v_n
[m/s], touching).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np
from numba import njit

if TYPE_CHECKING:
    from trackmj.track.mechanics import ModelParams

# columns of Foundation.state
(S_DELTA, S_NX, S_NZ, S_VN, S_VT, S_N, S_FT, S_CN, S_CT, S_PX, S_PZ, S_ON, S_SLIDE, S_NREF,
 S_NA, S_FA, S_VN1, S_VT1) = range(18)
N_STATE = 18
# entries of the law array
L_H, L_K, L_B, L_ONSET, L_MU, L_SHEAR = range(6)
# columns of Foundation.memory (what a step leaves for the next) and Foundation.choice
# (the active set of an attempt: 0 predict; normal ±1 closed/open, slide ±1 its direction,
# reference the normal force friction is bound by, 0 for the predicted one; the reference
# and applied normal force of the attempt before)
M_SHEAR, M_VN, M_TOUCHING = range(3)
C_NORMAL, C_SLIDE, C_REFERENCE, C_TRIED_REFERENCE, C_TRIED_APPLIED = range(5)
LIFTED_FOR_GOOD = -2.0
"""Active-set choice of a pin that pulled after an attempt had it touch down: it stays off
for the step (the applied force 0, the law's push at v₁ missed; never a pull)."""
TOLERANCE_N = 0.1
"""Force [N] by which an attempt's applied forces may miss the law before it is redone."""
MAX_ATTEMPTS = 5
"""Attempts of a step before the last one is kept (:attr:`Foundation.unresolved` counts)."""


@dataclass(frozen=True)
class FoundationLaw:
    """Kelvin–Voigt foundation with a shear-displacement friction law (module docstring).

    stiffness_N_m K and damping_N_s_m B per pin contact, the damping reached at the
    penetration damping_onset_m δ_B [m]; friction μ [-]; shear_modulus_m K_j [m], the shear
    displacement that mobilises the full friction μ·N.
    """

    stiffness_N_m: float
    damping_N_s_m: float
    damping_onset_m: float
    friction: float
    shear_modulus_m: float

    @classmethod
    def from_params(cls, params: ModelParams) -> FoundationLaw:
        """The law of a model's ``[ground]`` table and ``[track].ground_friction``."""
        g = params.ground
        return cls(g.stiffness_N_m, g.damping_N_s_m, g.damping_onset_m,
                   params.track.ground_friction, g.shear_modulus_m)


def ground_line(model: mujoco.MjModel, geom: str = "ground") -> np.ndarray:
    """World (x, z) points [m] of the ground line under the track, shape (n, 2), x ascending:
    a plane gives the two ends of its extent at its height, the ``terrain`` heightfield its
    first row (the road is constant across y). The line is taken as held at its end heights
    beyond its first and last points. ValueError for a tilted or rotated ground."""
    g = model.geom(geom).id
    if not np.allclose(model.geom_quat[g], (1.0, 0.0, 0.0, 0.0)):
        raise ValueError(f"geom {geom!r}: a rotated ground is not supported (quat "
                         f"{model.geom_quat[g].tolist()})")
    cx, cz = float(model.geom_pos[g, 0]), float(model.geom_pos[g, 2])
    if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_HFIELD:
        h = model.geom_dataid[g]
        ncol, adr = int(model.hfield_ncol[h]), int(model.hfield_adr[h])
        size = model.hfield_size[h]
        x = cx + np.linspace(-size[0], size[0], ncol)
        return np.column_stack([x, cz + size[2] * model.hfield_data[adr:adr + ncol]])
    if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_PLANE:
        raise ValueError(f"geom {geom!r}: the ground must be a plane or a heightfield")
    half = float(model.geom_size[g, 0]) or 1e3   # size 0: an infinite plane
    return np.array([[cx - half, cz], [cx + half, cz]])


@njit(cache=True)
def _segment(line: np.ndarray, x: float) -> int:
    """Index i of the ground ``line`` segment (i, i + 1) holding x, within [0, n − 2]."""
    lo, hi = 0, line.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if line[mid, 0] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _closest(line: np.ndarray, cx: float, cz: float, radius: float) -> tuple[float, float,
                                                                          float]:
    """Signed distance [m] of (cx, cz) above the ground ``line`` (n, 2), negative below it,
    and the unit normal (n_x, n_z) out of the ground, from the closest point of the line
    (end heights held beyond its ends) within ``radius`` [m] of x = cx."""
    n = line.shape[0]
    lo = _segment(line, cx)
    x0, z0, x1, z1 = line[0, 0], line[0, 1], line[n - 1, 0], line[n - 1, 1]
    if cx <= x0:
        height = z0
    elif cx >= x1:
        height = z1
    else:
        ax, az, bx, bz = line[lo, 0], line[lo, 1], line[lo + 1, 0], line[lo + 1, 1]
        height = az + (cx - ax) / (bx - ax) * (bz - az) if bx > ax else az
    best, gx, gz = np.inf, cx, height
    if cx - radius <= x0:   # the half-line x <= x0 at the first height
        px = min(cx, x0)
        d2 = (cx - px) ** 2 + (cz - z0) ** 2
        if d2 < best:
            best, gx, gz = d2, px, z0
    if cx + radius >= x1:   # the half-line x >= x1 at the last height
        px = max(cx, x1)
        d2 = (cx - px) ** 2 + (cz - z1) ** 2
        if d2 < best:
            best, gx, gz = d2, px, z1
    first, last = lo, lo
    while first > 0 and line[first, 0] > cx - radius:
        first -= 1
    while last < n - 2 and line[last + 1, 0] < cx + radius:
        last += 1
    for i in range(first, last + 1):
        ax, az, bx, bz = line[i, 0], line[i, 1], line[i + 1, 0], line[i + 1, 1]
        ex, ez = bx - ax, bz - az
        length2 = ex * ex + ez * ez
        s = 0.0 if length2 == 0.0 else ((cx - ax) * ex + (cz - az) * ez) / length2
        s = min(1.0, max(0.0, s))
        px, pz = ax + s * ex, az + s * ez
        d2 = (cx - px) ** 2 + (cz - pz) ** 2
        if d2 < best:
            best, gx, gz = d2, px, pz
    dist = math.sqrt(best)
    sign = -1.0 if cz < height else 1.0
    if dist > 1e-12:
        return sign * dist, sign * (cx - gx) / dist, sign * (cz - gz) / dist
    ex, ez = line[lo + 1, 0] - line[lo, 0], line[lo + 1, 1] - line[lo, 1]
    norm = math.sqrt(ex * ex + ez * ez)   # on the line: the normal of its segment
    return 0.0, -ez / norm, ex / norm


@njit(cache=True)
def _add_wrench(xfrc: np.ndarray, xipos: np.ndarray, body: int, px: float, pz: float,
                fx: float, fz: float) -> None:
    """Add the in-plane force (fx, fz) [N] acting at (px, pz) [m] to ``body``'s wrench at
    its centre of mass (``xfrc_applied`` layout: force, then torque about ``xipos``)."""
    xfrc[body, 0] += fx
    xfrc[body, 2] += fz
    xfrc[body, 4] += (pz - xipos[body, 2]) * fx - (px - xipos[body, 0]) * fz


@njit(cache=True)
def foundation_apply(geom_xpos: np.ndarray, xipos: np.ndarray, cdof: np.ndarray,
                     subtree_com: np.ndarray, qvel: np.ndarray, mass: np.ndarray,
                     xfrc: np.ndarray, pins: np.ndarray, dofs: np.ndarray,
                     mass_index: np.ndarray, radius: np.ndarray, law: np.ndarray,
                     line: np.ndarray, state: np.ndarray, jac: np.ndarray,
                     saved_mass: np.ndarray, saved_qvel: np.ndarray,
                     memory: np.ndarray, choice: np.ndarray) -> int:
    """Foundation forces of every pin at the start of the step into its body's row of
    ``xfrc`` (MuJoCo's ``xfrc_applied``; the pins' rows overwritten) and h·D into ``mass``
    (MuJoCo's sparse M); M and qvel are saved first. Returns the pins in contact.

    pins: (n, 4) int: geom id, body id, root body id, dof count; dofs: (n, D) int, the
    pin body's dof chain; mass_index: (n, D, D) int, address in ``mass`` of (row dof a,
    column dof b) for b <= a, else −1; radius: (n,) [m]; law: (h, K, B, δ_B, μ, K_j), the
    L_* entries; line: ground (x, z) (m, 2); memory (n, 3): what the last step left (M_*
    columns: shear displacement, v_n, touching); choice (n, 5): the active set of this
    attempt (C_* columns; 0 = predict); state (n, N_STATE) and jac (n, 2, D) are written
    (module docstring).
    """
    h, k, b, mu, shear = law[L_H], law[L_K], law[L_B], law[L_MU], law[L_SHEAR]
    onset, retardation = law[L_ONSET], b / k
    saved_mass[:] = mass
    saved_qvel[:] = qvel
    for i in range(pins.shape[0]):
        xfrc[pins[i, 1], :] = 0.0
    active = 0
    for i in range(pins.shape[0]):
        geom, body, root, count = pins[i, 0], pins[i, 1], pins[i, 2], pins[i, 3]
        cx, cz = geom_xpos[geom, 0], geom_xpos[geom, 2]
        r = radius[i]
        dist, nx, nz = _closest(line, cx, cz, r)
        delta = r - dist
        st = state[i]
        st[:] = 0.0
        st[S_DELTA], st[S_NX], st[S_NZ] = delta, nx, nz
        if delta <= 0.0:
            continue
        px, pz = cx - r * nx, cz - r * nz
        st[S_PX], st[S_PZ] = px, pz
        ox = px - subtree_com[root, 0]
        oy = geom_xpos[geom, 1] - subtree_com[root, 1]
        oz = pz - subtree_com[root, 2]
        tx, tz = nz, -nx
        vn = 0.0
        vt = 0.0
        for c in range(count):
            j = dofs[i, c]
            # point Jacobian column: cdof_lin + cdof_ang × (p − subtree_com of the root)
            jx = cdof[j, 3] + cdof[j, 1] * oz - cdof[j, 2] * oy
            jz = cdof[j, 5] + cdof[j, 0] * oy - cdof[j, 1] * ox
            jn, jt = nx * jx + nz * jz, tx * jx + tz * jz
            jac[i, 0, c], jac[i, 1, c] = jn, jt
            vn += jn * qvel[j]
            vt += jt * qvel[j]
        st[S_VN], st[S_VT] = vn, vt
        # the normal's active set: chosen by an earlier attempt, else predicted from the
        # velocity extrapolated over the step
        predicted = vn + (vn - memory[i, M_VN]) if memory[i, M_TOUCHING] > 0.0 else vn
        damping = b * min(1.0, delta / onset)
        pushing = k * delta - damping * predicted
        if choice[i, C_NORMAL] != 0.0:
            closed = choice[i, C_NORMAL] > 0.0
        else:
            closed = pushing > 0.0
        if not closed:
            continue
        reference = choice[i, C_REFERENCE] if choice[i, C_REFERENCE] > 0.0 else max(pushing,
                                                                                      0.0)
        # shear: stick on the spring μ·N_ref/K_j unless the step would pass K_j (slide)
        stiffness = mu * reference / shear
        trial = memory[i, M_SHEAR] + (h + retardation) * vt
        slide = choice[i, C_SLIDE]
        if slide == 0.0 and abs(trial) > shear:
            slide = 1.0 if trial > 0.0 else -1.0
        if slide != 0.0:
            friction, ct = -mu * reference * slide, 0.0
        else:
            friction, ct = -stiffness * trial, (h + retardation) * stiffness
        normal, cn = k * delta - damping * vn, damping
        st[S_ON], st[S_SLIDE], st[S_NREF] = 1.0, slide, reference
        st[S_N], st[S_FT], st[S_CN], st[S_CT] = normal, friction, cn, ct
        active += 1
        _add_wrench(xfrc, xipos, body, px, pz, normal * nx + friction * tx,
                    normal * nz + friction * tz)
        for c in range(count):
            for c2 in range(count):
                adr = mass_index[i, c, c2]
                if adr >= 0:
                    mass[adr] += h * (cn * jac[i, 0, c] * jac[i, 0, c2]
                                      + ct * jac[i, 1, c] * jac[i, 1, c2])
    return active


@njit(cache=True)
def _next_reference(choice: np.ndarray, reference: float, applied: float) -> float:
    """The N_ref [N] to try next for a pin whose friction exceeded μ·N applied: the applied N
    of this attempt, or, after an earlier attempt, the fixed point N_ref = N(N_ref) of the
    secant through both (exact where the step is linear in the pin's forces)."""
    tried, tried_applied = choice[C_TRIED_REFERENCE], choice[C_TRIED_APPLIED]
    if tried <= 0.0 or abs(reference - tried) < 1e-9:
        return applied
    slope = (applied - tried_applied) / (reference - tried)
    if slope >= 0.9:
        return applied
    return (tried_applied - slope * tried) / (1.0 - slope)


@njit(cache=True)
def foundation_finish(qvel: np.ndarray, mass: np.ndarray, xipos: np.ndarray,
                      xfrc: np.ndarray, pins: np.ndarray, dofs: np.ndarray,
                      law: np.ndarray, state: np.ndarray, jac: np.ndarray,
                      saved_mass: np.ndarray, saved_qvel: np.ndarray, memory: np.ndarray,
                      choice: np.ndarray, final: bool, advance: bool) -> int:
    """After the step: the true M back into ``mass``; each pin's applied force (explicit
    part plus the implicit −C·J·(v₁ − v₀)) into ``state`` (S_NA, S_FA) and added to its
    body's row of ``xfrc``, which then holds the force the foundation applied over the
    step (what ``mj_rnePostConstraint`` and readers see). Then the active set is checked
    against the law at the end-of-step velocity: a closed contact whose applied normal
    pulls opens, an open one the law would push closes, a friction above μ·N applied
    takes that N as its reference (:func:`_next_reference`), a stick whose force passed
    μ·N_ref slides; the changes go into
    ``choice`` for the next attempt. Returns the number of pins that changed (0: the step
    is consistent); a consistent or ``final`` attempt is committed
    (:func:`foundation_commit`, with ``advance``)."""
    h, k, b, mu, shear = law[L_H], law[L_K], law[L_B], law[L_MU], law[L_SHEAR]
    onset, retardation = law[L_ONSET], b / k
    mass[:] = saved_mass
    changed = 0
    for i in range(pins.shape[0]):
        st = state[i]
        if st[S_DELTA] <= 0.0:
            continue
        jn_dv = jt_dv = 0.0
        for c in range(pins[i, 3]):
            j = dofs[i, c]
            dv = qvel[j] - saved_qvel[j]
            jn_dv += jac[i, 0, c] * dv
            jt_dv += jac[i, 1, c] * dv
        st[S_VN1], st[S_VT1] = st[S_VN] + jn_dv, st[S_VT] + jt_dv
        if st[S_ON] == 0.0:
            if (choice[i, C_NORMAL] != LIFTED_FOR_GOOD
                    and k * st[S_DELTA] - b * min(1.0, st[S_DELTA] / onset)
                    * st[S_VN1] > TOLERANCE_N):
                choice[i, C_NORMAL] = 1.0
                changed += 1
            continue
        fn, ft = -st[S_CN] * jn_dv, -st[S_CT] * jt_dv
        nx, nz = st[S_NX], st[S_NZ]
        _add_wrench(xfrc, xipos, pins[i, 1], st[S_PX], st[S_PZ], fn * nx + ft * nz,
                    fn * nz - ft * nx)
        applied_n, applied_t = st[S_N] + fn, st[S_FT] + ft
        st[S_NA], st[S_FA] = applied_n, applied_t
        if applied_n < -TOLERANCE_N:
            # lifted off; for good if an earlier attempt had it touch down (a cycle)
            choice[i, C_NORMAL] = LIFTED_FOR_GOOD if choice[i, C_NORMAL] > 0.0 else -1.0
            changed += 1
            continue
        if abs(applied_t) > mu * applied_n + TOLERANCE_N:
            choice[i, C_NORMAL] = 1.0
            choice[i, C_REFERENCE] = max(_next_reference(choice[i], st[S_NREF], applied_n),
                                         1e-9)
            choice[i, C_TRIED_REFERENCE], choice[i, C_TRIED_APPLIED] = st[S_NREF], applied_n
            changed += 1
        if st[S_SLIDE] == 0.0:
            end = memory[i, M_SHEAR] + (h + retardation) * st[S_VT1]
            if abs(end) > shear:
                choice[i, C_NORMAL] = 1.0
                choice[i, C_SLIDE] = 1.0 if end > 0.0 else -1.0
                changed += 1
    if changed == 0 or final:
        foundation_commit(law, state, memory, choice, advance)
    return changed


@njit(cache=True)
def foundation_commit(law: np.ndarray, state: np.ndarray, memory: np.ndarray,
                      choice: np.ndarray, advance: bool) -> None:
    """The step is taken: each pin's memory (shear displacement j [m] along the ground's
    tangent, v_n at the step's end [m/s], touching) from the end-of-step velocities
    :func:`foundation_finish` left in ``state``, and the active set back to 'predict'.
    Without ``advance`` (a reset) j is kept."""
    h, shear = law[L_H], law[L_SHEAR]
    for i in range(state.shape[0]):
        st = state[i]
        choice[i, :] = 0.0
        if st[S_ON] == 0.0:
            memory[i, :] = 0.0
            continue
        memory[i, M_VN], memory[i, M_TOUCHING] = st[S_VN1], 1.0
        if not advance:
            continue
        if st[S_SLIDE] != 0.0:
            memory[i, M_SHEAR] = st[S_SLIDE] * shear
        else:
            memory[i, M_SHEAR] = min(shear, max(-shear, memory[i, M_SHEAR] + h * st[S_VT1]))


@njit(cache=True)
def foundation_work(state: np.ndarray, jac: np.ndarray, pins: np.ndarray, dofs: np.ndarray,
                    qvel0: np.ndarray, qvel1: np.ndarray, h: float,
                    out: np.ndarray) -> None:
    """Work [J] the foundation did over the step as integrated, added to ``out`` =
    (normal, friction): Σ F_applied·(J·Δq) with Δq = h·v₁ (module docstring), per
    direction."""
    for i in range(pins.shape[0]):
        st = state[i]
        if st[S_ON] == 0.0:
            continue
        jn_dq = jt_dq = 0.0
        for c in range(pins[i, 3]):
            j = dofs[i, c]
            jn_dq += jac[i, 0, c] * h * qvel1[j]
            jt_dq += jac[i, 1, c] * h * qvel1[j]
        out[0] += st[S_NA] * jn_dq
        out[1] += st[S_FA] * jt_dq


@njit(cache=True)
def foundation_penetration(geom_xpos: np.ndarray, pins: np.ndarray, radius: np.ndarray,
                           line: np.ndarray, out: np.ndarray) -> None:
    """Penetration δ [m] of every pin into the ground ``line`` at the state of
    ``geom_xpos`` (after kinematics), into ``out`` (n,)."""
    for i in range(pins.shape[0]):
        g = pins[i, 0]
        out[i] = radius[i] - _closest(line, geom_xpos[g, 0], geom_xpos[g, 2], radius[i])[0]


class Foundation:
    """The foundation of every pin of a compiled track model (module docstring).

    Bound to one ``data``. Call :meth:`apply` between ``mj_step1`` and ``mj_step2``, then
    ``mj_factorM``, and :meth:`finish` after ``mj_step2`` (:func:`step` does it all);
    :attr:`state` and :attr:`jac` then hold
    the step's contact state (columns ``S_*``, SI). The ``ground`` geom of the model keeps
    its MJCF contact for MuJoCo's own viewer; the foundation switches it off.

    Parameters
    ----------
    model : mujoco.MjModel
        The compiled track model; its ``ground`` geom gives the line (:func:`ground_line`).
    data : mujoco.MjData
        The data the foundation acts on.
    pin_geoms : sequence of int
        The pin spheres, one per link, in pin order.
    law : FoundationLaw
        Stiffness, damping, friction and shear modulus.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData,
                 pin_geoms: Sequence[int] | np.ndarray, law: FoundationLaw) -> None:
        self.law = law
        self.line = ground_line(model)
        ground = model.geom("ground").id
        model.geom_contype[ground] = model.geom_conaffinity[ground] = 0
        world = model.geom_bodyid[ground]
        geoms = range(model.body_geomadr[world],
                      model.body_geomadr[world] + model.body_geomnum[world])
        model.body_contype[world] = np.bitwise_or.reduce(
            [int(model.geom_contype[g]) for g in geoms], initial=0)
        model.body_conaffinity[world] = np.bitwise_or.reduce(
            [int(model.geom_conaffinity[g]) for g in geoms], initial=0)
        n = len(pin_geoms)
        chains = []
        for g in pin_geoms:
            body = model.geom_bodyid[g]
            chain, dof = [], model.body_dofadr[body] + model.body_dofnum[body] - 1
            while dof >= 0:
                chain.append(int(dof))
                dof = model.dof_parentid[dof]
            chains.append(chain[::-1])
        width = max(len(c) for c in chains)
        self.pins = np.zeros((n, 4), dtype=np.int64)
        self.dofs = np.zeros((n, width), dtype=np.int64)
        self.mass_index = np.full((n, width, width), -1, dtype=np.int64)
        for i, (g, chain) in enumerate(zip(pin_geoms, chains, strict=True)):
            body = model.geom_bodyid[g]
            self.pins[i] = (g, body, model.body_rootid[body], len(chain))
            self.dofs[i, :len(chain)] = chain
            for c, a in enumerate(chain):
                row = model.M_colind[model.M_rowadr[a]:model.M_rowadr[a] + model.M_rownnz[a]]
                for c2, col in enumerate(chain):
                    if col > a:
                        continue
                    at = np.nonzero(row == col)[0]
                    if not len(at):
                        raise ValueError(
                            f"pin geom {model.geom(g).name!r}: MuJoCo's sparse mass matrix "
                            f"has no entry coupling dofs {a} and {col} of its body (a body "
                            "of slide joints only is 'simple', its rows diagonal); the "
                            "foundation's damping couples them: give the body a hinge")
                    self.mass_index[i, c, c2] = model.M_rowadr[a] + int(at[0])
        self.radius = model.geom_size[np.asarray(pin_geoms), 0].copy()
        self.law_array = np.array([model.opt.timestep, law.stiffness_N_m, law.damping_N_s_m,
                                   law.damping_onset_m, law.friction, law.shear_modulus_m])
        self.state = np.zeros((n, N_STATE))
        self.jac = np.zeros((n, 2, width))
        self.memory = np.zeros((n, 3))
        self.choice = np.zeros((n, 5))
        self.active = 0
        self.redone = 0
        """Steps taken more than once since construction (an attempt missed the law)."""
        self.unresolved = 0
        """Steps kept after :data:`MAX_ATTEMPTS` attempts still missed the law."""
        saved_mass, saved_qvel = np.zeros(model.nM), np.zeros(model.nv)
        self._saved_qvel = saved_qvel
        self._mass, self._saved_mass = data.M, saved_mass
        # views into data's buffers (they live as long as data): the kernels' arguments
        self._apply_args = (data.geom_xpos, data.xipos, data.cdof, data.subtree_com,
                            data.qvel, data.M, data.xfrc_applied, self.pins, self.dofs,
                            self.mass_index, self.radius, self.law_array, self.line,
                            self.state, self.jac, saved_mass, saved_qvel, self.memory,
                            self.choice)
        self._finish_args = (data.qvel, data.M, data.xipos, data.xfrc_applied, self.pins,
                             self.dofs, self.law_array, self.state, self.jac, saved_mass,
                             saved_qvel, self.memory, self.choice)

    def configuration(self) -> dict[str, np.ndarray]:
        """What a port of the kernels needs (the native FMU's engine, trackmj/fmi/native):
        pins (n, 4), dof chains (n, D), mass-matrix addresses (n, D, D), radii (n,) [m],
        the law (h, K, B, δ_B, μ, K_j) and the ground line (m, 2) [m], as the kernels take
        them."""
        return {"foundation_pins": self.pins, "foundation_width": np.array([self.dofs.shape[1]]),
                "foundation_dofs": self.dofs, "foundation_mass_index": self.mass_index,
                "foundation_radius": self.radius, "foundation_law": self.law_array,
                "ground_line": self.line}

    def scale_stiffness(self, scale: float) -> None:
        """Multiply the foundation stiffness K by ``scale`` [-] (W5's perturbation)."""
        self.law_array[L_K] *= scale

    @property
    def stiffness_N_m(self) -> float:
        """The foundation stiffness in force [N/m] (the stated one times any scale)."""
        return float(self.law_array[L_K])

    def forget(self) -> None:
        """Forget what earlier steps left (shear displacements, contact history): a reset."""
        self.memory[:] = 0.0
        self.choice[:] = 0.0

    def apply(self) -> None:
        """Forces and implicit terms of the step (after ``mj_step1``, before ``mj_step2``)."""
        self.active = foundation_apply(*self._apply_args)

    def discard(self) -> None:
        """The true mass matrix back into the data's ``M`` after an attempt taken again
        before :meth:`finish` judged it (:func:`step`'s ``retake``)."""
        self._mass[:] = self._saved_mass

    def finish(self, final: bool = True, advance: bool = True) -> int:
        """After ``mj_step2``: the true mass matrix back into the data's ``M``, the force
        applied over the step into ``xfrc_applied`` and :attr:`state`; returns the pins
        whose active set the law contradicts (0: the step is kept and committed, as a
        ``final`` attempt is; the shear displacements advance unless not ``advance``)."""
        return foundation_finish(*self._finish_args, final, advance)

    @property
    def normal_forces_N(self) -> np.ndarray:
        """Normal force N each pin received over the last step [N], shape (n,), ≥ 0."""
        return self.state[:, S_NA]

    @property
    def friction_forces_N(self) -> np.ndarray:
        """Friction force F_t each pin received over the last step [N], shape (n,), along
        the ground's tangent (+x on flat ground); |F_t| ≤ μ·N."""
        return self.state[:, S_FA]

    def applied_forces_N(self) -> np.ndarray:
        """(N, F_t) each pin received over the last step [N], shape (n, 2)."""
        return self.state[:, [S_NA, S_FA]]

    @property
    def start_velocity(self) -> np.ndarray:
        """MuJoCo's qvel at the start of the last step [SI], shape (nv,)."""
        return self._saved_qvel

    @property
    def shear_displacement_m(self) -> np.ndarray:
        """Shear displacement j of every pin's contact [m], shape (n,), along the ground's
        tangent; 0 out of contact, ±K_j while sliding."""
        return self.memory[:, M_SHEAR]


@njit(cache=True)
def implicit_springs_apply(mass: np.ndarray, qfrc_applied: np.ndarray, qvel: np.ndarray,
                           dofs: np.ndarray, mass_index: np.ndarray, h_stiffness: np.ndarray,
                           h: float) -> None:
    """Backward Euler for joint springs (and dampers) on single dofs: h·G into ``mass``
    (MuJoCo's sparse M, at each dof's diagonal address ``mass_index``) and −G·v₀ into
    ``qfrc_applied``, G = h·K + B, so that with MuJoCo's own −K·(q₀ − q_ref) the joint acts
    with −K·(q₀ + h·v₁ − q_ref) − B·v₁ = −K·(q₁ − q_ref) − B·v₁ over the step. dofs,
    mass_index: (s,) int; h_stiffness: G (s,) [N·s/m or N·m·s/rad]; h [s]."""
    for i in range(dofs.shape[0]):
        mass[mass_index[i]] += h * h_stiffness[i]
        qfrc_applied[dofs[i]] = -h_stiffness[i] * qvel[dofs[i]]


class ImplicitSprings:
    """Joint springs on single dofs integrated by backward Euler inside MuJoCo's step (the
    pins' slides, structure "slides"), the way the foundation's damping is: their h²·K sits
    in the mass matrix the constraint solver and the integrator use, so they need no
    armature and create no energy (MuJoCo integrates joint stiffness explicitly, stable
    only for h²·K/m < 4). The model's armature of those dofs is set to 0 here: the MJCF's
    armature is for MuJoCo's own stepping (its viewer). Call :meth:`apply` after
    :meth:`Foundation.apply` (which saved the true M: :meth:`Foundation.finish` puts it
    back); they own ``qfrc_applied`` of their dofs.

    joints: ids of slide or hinge joints with ``jnt_stiffness`` K [N/m or N·m/rad]; none
    for a model without such springs (structure "chains" or "free", the foundation's toys).
    dampers: ids of further joints whose joint damping B [N·s/m or N·m·s/rad] the step takes
    the same way (the pin hinges' torsional dampers): h·B into M, −B·v₀ applied, and the
    model's damping of those dofs set to 0; their springs stay MuJoCo's explicit ones.
    MuJoCo's own implicit damping (``qDeriv``) is not seen by the constraint solver (the
    module docstring): measured on M113's bushings at 1 ms, hinge dampers of 10 N·m·s/rad
    diverge that way. Construct once per compiled model (it moves the damping out of it).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData,
                 joints: Sequence[int] | np.ndarray,
                 dampers: Sequence[int] | np.ndarray = ()) -> None:
        springs = np.asarray(joints, dtype=np.int64)
        damped = np.asarray(dampers, dtype=np.int64)
        every = np.concatenate([springs, damped])
        self.dofs = model.jnt_dofadr[every].astype(np.int64)
        # M is CSR over the lower triangle: a row's diagonal is its last entry
        self.mass_index = (model.M_rowadr[self.dofs] + model.M_rownnz[self.dofs] - 1
                           ).astype(np.int64)
        if np.any(model.M_colind[self.mass_index] != self.dofs):
            raise ValueError("implicit springs: a dof's diagonal is not its row's last entry")
        model.dof_armature[self.dofs] = 0.0
        h = float(model.opt.timestep)
        self.h_stiffness = np.concatenate([h * model.jnt_stiffness[springs],
                                           np.zeros(len(damped))])
        """h·K of each spring (0 for a damper) [N·s/m or N·m·s/rad], shape (s,)."""
        damper_dofs = self.dofs[len(springs):]
        self.damping = np.concatenate([np.zeros(len(springs)), model.dof_damping[damper_dofs]])
        """B of each damper (0 for a spring) [N·s/m or N·m·s/rad], shape (s,)."""
        model.dof_damping[damper_dofs] = 0.0
        self.gain = self.h_stiffness + self.damping
        """h·K + B, the velocity gain the step takes implicitly, shape (s,)."""
        self._args = (data.M, data.qfrc_applied, data.qvel, self.dofs, self.mass_index,
                      self.gain, h)

    def apply(self) -> None:
        """h·(h·K + B) into M and −(h·K + B)·v₀ into qfrc_applied (after
        :meth:`Foundation.apply`)."""
        implicit_springs_apply(*self._args)

    def configuration(self) -> dict[str, np.ndarray]:
        """What the native FMU's engine needs: dofs, M addresses (s,) and h·K + B (s,)."""
        return {"spring_dofs": self.dofs, "spring_mass_index": self.mass_index,
                "spring_h_stiffness": self.gain}


def _integrate(model: mujoco.MjModel, data: mujoco.MjData, foundation: Foundation,
               springs: ImplicitSprings) -> None:
    """One attempt of :func:`step`: the laws into M and the forces, then ``mj_step2``."""
    foundation.apply()
    springs.apply()
    mujoco.mj_factorM(model, data)
    mujoco.mj_step2(model, data)


def step(model: mujoco.MjModel, data: mujoco.MjData, foundation: Foundation,
         springs: ImplicitSprings, saved: np.ndarray | None = None,
         retake: Callable[[], bool] | None = None) -> None:
    """One MuJoCo step with the foundation bound to ``data`` (see :class:`Foundation`) and
    the ``springs`` integrated implicitly (:class:`ImplicitSprings`), its ``mj_step2`` taken
    again while the law contradicts an attempt's active set, at most :data:`MAX_ATTEMPTS`
    times, from what the integration changed (kept in ``saved``, of ``mj_stateSize`` of
    :data:`REDO_STATE`, allocated here if not given; ``mj_step1``'s results stay valid:
    they depend on positions and velocities only). ``retake``, if given, is asked after
    every ``mj_step2``, before the foundation judges the attempt: True (having changed what
    the step should do differently, e.g. an actuator's force range:
    :class:`trackmj.track.servo.DriveRetake`) takes it again."""
    if saved is None:
        saved = np.zeros(mujoco.mj_stateSize(model, REDO_STATE))
    mujoco.mj_step1(model, data)
    mujoco.mj_getState(model, data, saved, REDO_STATE)
    for attempt in range(MAX_ATTEMPTS):
        _integrate(model, data, foundation, springs)
        while retake is not None and retake():
            foundation.discard()
            mujoco.mj_setState(model, data, saved, REDO_STATE)
            _integrate(model, data, foundation, springs)
        final = attempt == MAX_ATTEMPTS - 1
        if not foundation.finish(final):
            return
        if final:
            foundation.unresolved += 1
            return
        if attempt == 0:
            foundation.redone += 1
        mujoco.mj_setState(model, data, saved, REDO_STATE)


REDO_STATE = int(mujoco.mjtState.mjSTATE_QPOS | mujoco.mjtState.mjSTATE_QVEL
                 | mujoco.mjtState.mjSTATE_ACT | mujoco.mjtState.mjSTATE_TIME
                 | mujoco.mjtState.mjSTATE_WARMSTART)
"""What ``mj_step2``'s integration changes, restored before a step is taken again."""


__all__ = ["REDO_STATE", "Foundation", "FoundationLaw", "ImplicitSprings", "foundation_apply",
           "foundation_commit", "foundation_finish", "foundation_penetration",
           "foundation_work", "ground_line", "implicit_springs_apply", "step"]
