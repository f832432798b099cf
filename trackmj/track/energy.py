"""Mechanical energy ledger of the MuJoCo track, booked consistently with its integrator.

MuJoCo's ``implicitfast`` step is semi-implicit Euler: from (q_k, v_k) it solves the
constraint forces with the mass matrix M_k, takes v_{k+1} = v_k + h·M̂⁻¹·f with the
damping and actuator-velocity terms implicit, and moves q_{k+1} = q_k + h·v_{k+1}. Every
force therefore does the work f·Δq with Δq = h·v_{k+1}, and the forces are those the step
applied: the dampers and the two actuators at v_{k+1} (the tensioner's ``ForceLaw`` at
v_{k+1}, the velocity servo kv·(ctrl − v_{k+1}) unless clamped), the pin slides' springs
at q_{k+1} (trackmj's step integrates them by backward Euler), everything else (the other
springs, gravity, Coriolis, contacts, pins) at (q_k, v_k). With MuJoCo's energy flag
(E = KE + PE: KE = ½·vᵀ·M(q)·v, PE = gravity and joint/tendon springs) one step books

    E_{k+1} − E_k = W_drive + W_tensioner + W_suspension + W_torsion + W_hitch
                    + Σ_partners W_constraint + N_k + r_k

where the numerical term N_k is the integrator's own energy error, in three parts:

* velocity jump −½·Δvᵀ·M_k·Δv (Δv = v_{k+1} − v_k): the first-order dissipation of
  semi-implicit Euler when work is booked on the displacement; always ≤ 0;
* explicit forces PE_{k+1} − PE_k + (f_spring − f_bias)ᵀ·Δq + KE_{k+1} − ½·v_{k+1}ᵀ·M_k·v_{k+1}:
  springs, gravity and the Coriolis force (``qfrc_bias``) are taken at the step's start
  while PE and M change over it (½·Δqᵀ·K·Δq ≥ 0 for a linear spring; the M change is
  small: every link has a constant mass matrix, only the chassis pitch moves M);
* implicit springs: the pin slides' springs act at the step's end
  (:class:`trackmj.track.foundation.ImplicitSprings`), their implicit part −h·K·v_{k+1} on
  Δq adds −K·Δq² per slide, so with the explicit part's +½·K·Δq² backward Euler's −½·K·Δq²
  (dissipates). The pin hinges' torsional dampers the same step takes, −B·v_{k+1} on Δq,
  are booked as pin torsion.

The residual r_k = (M_k·Δv − h·f)ᵀ·v_{k+1} is what the booked forces miss of what MuJoCo
integrated (solver tolerance, an unbooked force); it is not a fitted quantity.

Constraint work is booked per row, f_row·(J_row·Δq) with MuJoCo's Jacobian of the step, and
summed by partner: sprocket (hub and teeth), road wheels, idler, return rollers, pins (the
pin connects, and with structure "slides" the pin slides' dampers; their springs are joint
springs, in PE) and joint limits. The ground is the foundation force element
(:mod:`trackmj.track.foundation`), booked as integrated: (F(v_k) − C·J·Δv)·(J·Δq) per pin, split
into normal (ground) and friction (ground_friction). A contact's work includes what its
explicit spring returns.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import mujoco
import numpy as np
from numba import njit

from trackmj.track.foundation import S_DELTA, S_NA, S_ON, foundation_penetration, foundation_work
from trackmj.track.plant import TrackPlant

PARTNERS = ("ground", "ground_friction", "sprocket", "road_wheels", "idler",
            "return_rollers", "pins", "joint_limits")
"""Keys of :attr:`TrackEnergy.contact_work_J`."""

CONTACTS = ("ground", "ground_friction", "sprocket", "road_wheels", "idler", "return_rollers")
"""The partners that are contacts (no pins, no joint limits)."""

_GROUND, _FRICTION, _PINS, _LIMITS = 0, 1, 6, 7
_EQUALITY = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
_LIMIT_JOINT = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
# accumulator slots of the kernels: work and ½·K·Δr² creation by partner, then scalars
_N = len(PARTNERS)
A_WORK, A_CREATION = 0, _N
(A_CURVATURE, A_SUSPENSION, A_TORSION, A_JUMP, A_EXPLICIT, A_KINETIC_MID,
 A_IMPLICIT_SPRINGS) = range(2 * _N, 2 * _N + 7)
A_SIZE = 2 * _N + 7


@dataclass
class TrackEnergy:
    """Energy terms of a run [J] (see the module docstring); ``to_dict`` for JSON.

    Work terms are positive into the track. ``contact_work_J`` by partner (:data:`PARTNERS`),
    with the integrator's parts moved to ``numerical_terms_J``; ``numerical_J`` is their
    sum, of either sign (the velocity jump dissipates, the explicit constraint springs and
    the constraint curvature create).
    """

    drive_work_J: float = 0.0
    tensioner_work_J: float = 0.0
    suspension_loss_J: float = 0.0
    pin_torsion_loss_J: float = 0.0
    hitch_work_J: float = 0.0
    contact_work_J: dict[str, float] = field(default_factory=lambda: dict.fromkeys(PARTNERS,
                                                                                    0.0))
    kinetic_change_J: float = 0.0
    potential_change_J: float = 0.0
    numerical_J: float = 0.0
    numerical_terms_J: dict[str, float] = field(default_factory=lambda: dict.fromkeys(
        ("velocity_jump", "explicit_forces", "explicit_constraint_springs",
         "constraint_curvature", "implicit_springs"), 0.0))
    residual_J: float = 0.0

    @property
    def booked_J(self) -> float:
        """Sum of all work terms and the numerical term [J]."""
        return (self.drive_work_J + self.tensioner_work_J + self.suspension_loss_J
                + self.pin_torsion_loss_J + self.hitch_work_J
                + sum(self.contact_work_J.values()) + self.numerical_J)

    def to_dict(self) -> dict:
        return asdict(self)


@njit(cache=True)
def _book_dampers(q_deriv: np.ndarray, deriv_row: np.ndarray, deriv_col: np.ndarray,
                  dv: np.ndarray, dq: np.ndarray, qfrc_damper: np.ndarray,
                  actuator_dofs: np.ndarray, actuator_bias: np.ndarray,
                  actuator_free: np.ndarray, slot: np.ndarray, implicit: np.ndarray,
                  acc: np.ndarray) -> None:
    """Dampers as integrated: qfrc_damper at v_k plus their share of qDeriv·Δv (the
    unclamped actuators' affine velocity terms removed), on Δq, into the accumulator slot
    of each dof (``slot``, shape (nv,)): A_SUSPENSION for the suspension slides, the pins'
    work for the pin slides of structure "slides", A_TORSION for the rest (pin torsion)."""
    implicit[:] = 0.0
    for k in range(len(q_deriv)):
        implicit[deriv_row[k]] += q_deriv[k] * dv[deriv_col[k]]
    for i in range(len(actuator_dofs)):
        if actuator_free[i]:
            implicit[actuator_dofs[i]] -= actuator_bias[i] * dv[actuator_dofs[i]]
    for j in range(len(dq)):
        work = (qfrc_damper[j] + implicit[j]) * dq[j]
        acc[slot[j]] += work


@njit(cache=True)
def _book_rows(rate: np.ndarray, force: np.ndarray, kind: np.ndarray, kbip: np.ndarray,
               efc_d: np.ndarray, efc_pos: np.ndarray, pin_rows: int,
               contact_adr: np.ndarray, contact_geom: np.ndarray, contact_dim: np.ndarray,
               contact_dist: np.ndarray, partner_of_geom: np.ndarray, ngeom: int,
               pin_pending: np.ndarray, pending: np.ndarray, pending_key: np.ndarray,
               pending_partner: np.ndarray, counts: np.ndarray, acc: np.ndarray,
               book: bool) -> int:
    """Work of every constraint row on the step's Δq (``rate`` = J·Δq), by partner; then
    the previous step's rows (in ``pending``) settled against this step's residuals (see
    :meth:`TrackEnergyLedger._book_constraints`), and this step's rows stored there (with
    ``book`` False only the settling: the end of the run). Returns 0, or 1
    if the pin rows are not the first equality rows, 2 for a contact without a known
    partner or rows.

    pin_pending: (4, pin_rows) the pin rows' residual, force, rate, spring; pending: (4, C)
    the contacts' normal force, normal rate, distance, spring; pending_key and
    pending_partner: (C,) their geom-pair key and partner (C >= ncon); counts: (pins
    pending 0/1, contacts pending).
    """
    nefc, ncon = len(rate), len(contact_adr)
    for r in range(pin_rows):
        if kind[r] != _EQUALITY:
            return 1
    # settle the previous step's pin rows on this step's residuals
    if counts[0]:
        curvature = 0.0
        for r in range(pin_rows):
            change = efc_pos[r] - pin_pending[0, r]
            curvature += pin_pending[1, r] * (pin_pending[2, r] - change)
            acc[A_CREATION + _PINS] += 0.5 * pin_pending[3, r] * change * change
        acc[A_WORK + _PINS] -= curvature
        acc[A_CURVATURE] += curvature
    if not book:
        counts[0] = 0
    # this step's rows
    for r in range(nefc if book else 0):
        work = force[r] * rate[r]
        if r < pin_rows:
            acc[A_WORK + _PINS] += work
        elif kind[r] == _LIMIT_JOINT:
            spring = kbip[r, 0] * kbip[r, 2] * efc_d[r]
            acc[A_WORK + _LIMITS] += work
            acc[A_CREATION + _LIMITS] += 0.5 * spring * rate[r] * rate[r]
    for r in range(pin_rows if book else 0):
        pin_pending[0, r], pin_pending[1, r], pin_pending[2, r] = efc_pos[r], force[r], rate[r]
        pin_pending[3, r] = kbip[r, 0] * kbip[r, 2] * efc_d[r]
        counts[0] = 1
    # contacts: this step's keys, sorted, to match the previous step's
    keys = np.empty(ncon, dtype=np.int64)
    for c in range(ncon):
        keys[c] = contact_geom[c, 0] * ngeom + contact_geom[c, 1]
    order = np.argsort(keys, kind="mergesort")
    for p in range(counts[1]):   # settle the previous step's contacts
        old_force, old_rate = pending[0, p], pending[1, p]
        change = old_rate
        lo, hi = 0, ncon
        while lo < hi:   # first sorted key >= the old key
            mid = (lo + hi) // 2
            if keys[order[mid]] < pending_key[p]:
                lo = mid + 1
            else:
                hi = mid
        if lo < ncon and keys[order[lo]] == pending_key[p] and not (
                (lo + 1 < ncon and keys[order[lo + 1]] == pending_key[p])
                or (lo > 0 and keys[order[lo - 1]] == pending_key[p])):
            change = contact_dist[order[lo]] - pending[2, p]
        curvature = old_force * (old_rate - change)
        acc[A_WORK + pending_partner[p]] -= curvature
        acc[A_CURVATURE] += curvature
        if old_force > 0.0:
            acc[A_CREATION + pending_partner[p]] += 0.5 * pending[3, p] * change * change
    counts[1] = 0
    if not book:
        return 0
    for c in range(ncon):
        adr, dim = contact_adr[c], contact_dim[c]
        partner = max(partner_of_geom[contact_geom[c, 0]], partner_of_geom[contact_geom[c, 1]])
        if partner < 0 or adr < 0:
            return 2
        rows = 1 if dim == 1 else 2 * (dim - 1)   # frictionless 1, pyramid 2·(dim − 1)
        normal_force = spring = 0.0
        for r in range(adr, adr + rows):
            acc[A_WORK + partner] += force[r] * rate[r]
            normal_force += force[r]
            spring += kbip[r, 0] * kbip[r, 2] * efc_d[r]
        # normal rate: the row, or the mean of a pyramid's ± pair
        normal_rate = rate[adr] if rows == 1 else 0.5 * (rate[adr] + rate[adr + 1])
        pending[0, c], pending[1, c] = normal_force, normal_rate
        pending[2, c], pending[3, c] = contact_dist[c], spring
        pending_key[c], pending_partner[c] = keys[c], partner
    counts[1] = ncon
    return 0


@njit(cache=True)
def _book_foundation(state: np.ndarray, jac: np.ndarray, pins: np.ndarray, dofs: np.ndarray,
                     dq: np.ndarray, stiffness: float, pending: np.ndarray,
                     acc: np.ndarray) -> None:
    """The previous step's pushing foundation pins settled against this step's penetration
    (as contacts in :func:`_book_rows`: J_n·Δq beyond the true change −Δδ is curvature, the
    explicit spring's ½·K·Δδ² creation), then this step's stored in ``pending`` (n, 3):
    force (0 if not pushing), J_n·Δq, penetration."""
    for i in range(pins.shape[0]):
        if pending[i, 0] > 0.0:
            change = -(state[i, S_DELTA] - pending[i, 2])
            curvature = pending[i, 0] * (pending[i, 1] - change)
            acc[A_WORK + _GROUND] -= curvature
            acc[A_CURVATURE] += curvature
            acc[A_CREATION + _GROUND] += 0.5 * stiffness * change * change
        rate = 0.0
        for c in range(pins[i, 3]):
            rate += jac[i, 0, c] * dq[dofs[i, c]]
        pending[i, 0] = state[i, S_NA] if state[i, S_ON] > 0.0 else 0.0
        pending[i, 1], pending[i, 2] = rate, state[i, S_DELTA]


class TrackEnergyLedger:
    """Books the track's energy terms after every MuJoCo step (call :meth:`after_step`: after
    each :meth:`TrackPlant.step` of one MuJoCo step, or as its ``on_substep`` when a
    coupling step takes several), then :meth:`finish` for the totals.

    Sets MuJoCo's energy flag on ``plant.model`` and runs one ``mj_forward`` to start from
    the current state. Per step it reads what the step left in ``plant.data``: the
    constraint rows, forces and mass matrix of the step's start, the new velocity.
    """

    def __init__(self, plant: TrackPlant) -> None:
        self.plant = plant
        m, d = plant.model, plant.data
        m.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_ENERGY)
        mujoco.mj_forward(m, d)
        self._h = float(m.opt.timestep)
        self._start_energy = d.energy.copy()
        self._v_prev = d.qvel.copy()
        self._drive = m.actuator("sprocket_drive").id
        self._drive_dof = int(m.jnt_dofadr[m.actuator_trnid[self._drive, 0]])
        self._tensioner_dof = int(m.jnt_dofadr[m.joint("idler_slide").id])
        # where each dof's damper work goes: the pin slides' (structure "slides") to the
        # pins, whose connects' work is booked there too; other damped dofs are the
        # suspension slides; the rest to A_TORSION: the link hinges (a hinged pin's
        # torsional damper on its hinge, the connects' torsion tendons on the pitch and
        # pin hinges they join)
        self._damper_slot = np.where(m.dof_damping > 0.0, A_SUSPENSION, A_TORSION)
        self._damper_slot[m.jnt_dofadr[plant.pin_slide_joints]] = A_WORK + _PINS
        hinges = [j for j in range(m.njnt) if m.joint(j).name.startswith("link_")
                  and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]   # pitch and pin hinges
        self._damper_slot[m.jnt_dofadr[hinges]] = A_TORSION
        # the implicit part of the step, qDeriv·Δv, in MuJoCo's sparse layout
        self._deriv_row = np.repeat(np.arange(m.nv), m.D_rownnz)
        self._deriv_col = m.D_colind.copy()
        self._actuator_dofs = np.array([m.jnt_dofadr[m.actuator_trnid[i, 0]]
                                        for i in range(m.nu)])
        self._actuator_free = np.ones(m.nu, dtype=bool)   # not at a force limit this step
        self._partner_of_geom = np.full(m.ngeom, -1, dtype=np.int64)
        for g in range(m.ngeom):
            name = m.geom(g).name
            if name == "ground":
                self._partner_of_geom[g] = _GROUND
            elif name.startswith("sprocket_"):
                self._partner_of_geom[g] = PARTNERS.index("sprocket")
            elif name.startswith("road_wheel_"):
                self._partner_of_geom[g] = PARTNERS.index("road_wheels")
            elif name == "idler_wheel":
                self._partner_of_geom[g] = PARTNERS.index("idler")
            elif name.startswith("return_roller_"):
                self._partner_of_geom[g] = PARTNERS.index("return_rollers")
        self._chassis = m.body("chassis").id
        self._jacp = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))
        self._row_rate = np.zeros(0)
        self._implicit = np.zeros(m.nv)
        self._mdv = np.zeros(m.nv)
        self._mv = np.zeros(m.nv)
        self._terms = TrackEnergy()
        self._kinetic_next_sum = 0.0   # Σ KE_{k+1}, read one step late
        self._pin_rows = plant.pin_rows
        # the kernels' accumulators (work and creation by partner, curvature, dampers,
        # numerical terms) and the previous step's rows, settled one step late
        self._acc = np.zeros(A_SIZE)
        self._pin_pending = np.zeros((4, self._pin_rows))
        self._pending = np.zeros((4, 0))
        self._pending_key = np.zeros(0, dtype=np.int64)
        self._pending_partner = np.zeros(0, dtype=np.int64)
        self._counts = np.zeros(2, dtype=np.int64)
        self._foundation_work = np.zeros(2)   # (normal, friction) [J]
        self._foundation_pending = np.zeros((len(plant.foundation.pins), 3))
        self._steps = 0

    def after_step(self) -> None:
        """Book the MuJoCo step the plant just took."""
        m, d, t = self.plant.model, self.plant.data, self._terms
        h, v1 = self._h, d.qvel
        if self._steps:
            self._kinetic_next_sum += float(d.energy[1])   # KE at this step's start
        dq = h * v1
        dv = v1 - self._v_prev
        # actuators as integrated: the affine velocity term at v_{k+1} unless clamped
        forces = d.actuator_force
        for i in range(m.nu):
            self._actuator_free[i] = not self._clamped(i, float(forces[i]))
        drive = float(forces[self._drive])
        if self._actuator_free[self._drive]:
            drive += m.actuator_biasprm[self._drive, 2] * dv[self._drive_dof]
        t.drive_work_J += drive * dq[self._drive_dof]
        t.tensioner_work_J += self.plant.idler_force_N * dq[self._tensioner_dof]
        # dampers as integrated (MuJoCo 4.0.0 keeps only the same-tree entries of a
        # tendon's damping in qDeriv, so a pin-torsion tendon between two trees is
        # implicit on those entries only)
        _book_dampers(d.qDeriv, self._deriv_row, self._deriv_col, dv, dq, d.qfrc_damper,
                      self._actuator_dofs, m.actuator_biasprm[:, 2], self._actuator_free,
                      self._damper_slot, self._implicit, self._acc)
        if np.any(d.xfrc_applied[self._chassis]):
            mujoco.mj_jacBodyCom(m, d, self._jacp, self._jacr, self._chassis)
            wrench = d.xfrc_applied[self._chassis]
            t.hitch_work_J += float(wrench[:3] @ (self._jacp @ dq) + wrench[3:] @ (self._jacr @ dq))
        self._book_constraints(dq)
        f = self.plant.foundation
        foundation_work(f.state, f.jac, f.pins, f.dofs, self._v_prev, v1, h,
                        self._foundation_work)
        _book_foundation(f.state, f.jac, f.pins, f.dofs, dq, f.stiffness_N_m,
                         self._foundation_pending, self._acc)
        # numerical terms (mass matrix of the step's start, still in qM)
        mujoco.mj_mulM(m, d, self._mdv, dv)
        mujoco.mj_mulM(m, d, self._mv, v1)
        self._acc[A_JUMP] -= 0.5 * float(dv @ self._mdv)
        self._acc[A_EXPLICIT] += float((d.qfrc_spring - d.qfrc_bias) @ dq)
        springs = self.plant.springs   # their implicit part −h·K·v₁ on Δq: −K·Δq² per dof
        s = springs.dofs
        self._acc[A_IMPLICIT_SPRINGS] -= float(springs.h_stiffness @ (v1[s] * dq[s]))
        # the dampers the step takes with them (the pin hinges' torsion): −B·v₁ on Δq
        self._acc[A_TORSION] -= float(springs.damping @ (v1[s] * dq[s]))
        self._acc[A_KINETIC_MID] += 0.5 * float(v1 @ self._mv)
        self._v_prev = v1.copy()
        self._steps += 1

    def _clamped(self, actuator: int, force: float) -> bool:
        m = self.plant.model
        if not m.actuator_forcelimited[actuator]:
            return False
        low, high = m.actuator_forcerange[actuator]
        return force <= low or force >= high

    def _book_constraints(self, dq: np.ndarray | None) -> None:
        """Work of every constraint row on the step's displacement, f·(J·Δq), by partner;
        the previous step's rows are settled against the true change of their residual.

        J·Δq is the residual's change to first order only; the rest, the curvature of the
        constraint along the step (a pin's two links turning on a wrap, a rail sliding
        round a wheel), is work the frozen row direction does in the discrete step
        ("constraint_curvature"). The row's explicit spring adds ½·K·Δr² per step
        ("explicit_constraint_springs"). Both move from the partner to the numerical term.
        Contacts that opened, or whose geom pair has several contacts, keep J·Δq. With
        ``dq`` None (the end of the run) the previous rows are settled and nothing new is
        booked.
        """
        m, d = self.plant.model, self.plant.data
        nefc, ncon = d.nefc, d.ncon
        if len(self._row_rate) < nefc:
            self._row_rate = np.zeros(2 * nefc)
        rate = self._row_rate[:nefc]
        if dq is not None:
            mujoco.mj_mulJacVec(m, d, rate, dq)   # J_row·Δq with the step's Jacobian
        if len(self._pending_key) < ncon:
            self._pending = np.zeros((4, 2 * ncon))
            self._pending_key = np.zeros(2 * ncon, dtype=np.int64)
            self._pending_partner = np.zeros(2 * ncon, dtype=np.int64)
            if self._counts[1]:
                raise RuntimeError("energy ledger: contact buffers grown while pending")
        contact = d.contact
        status = _book_rows(rate, d.efc_force[:nefc], d.efc_type[:nefc], d.efc_KBIP[:nefc],
                            d.efc_D[:nefc], d.efc_pos[:nefc], self._pin_rows,
                            contact.efc_address[:ncon], contact.geom[:ncon],
                            contact.dim[:ncon], contact.dist[:ncon], self._partner_of_geom,
                            m.ngeom, self._pin_pending, self._pending, self._pending_key,
                            self._pending_partner, self._counts, self._acc, dq is not None)
        if status == 1:
            raise RuntimeError("energy ledger: the pin connects must be the first rows")
        if status == 2:
            raise RuntimeError("energy ledger: a contact without a known partner or rows")

    def finish(self) -> TrackEnergy:
        """Totals from the start to the current state (runs one ``mj_forward``)."""
        m, d, t = self.plant.model, self.plant.data, self._terms
        mujoco.mj_forward(m, d)
        self._book_constraints(None)   # the last step's rows on the final residuals
        f = self.plant.foundation
        final = np.zeros_like(f.state)
        foundation_penetration(d.geom_xpos, f.pins, f.radius, f.line, final[:, S_DELTA])
        _book_foundation(final, f.jac, f.pins, f.dofs, np.zeros(m.nv), f.stiffness_N_m,
                         self._foundation_pending, self._acc)
        acc = self._acc
        work = acc[A_WORK:A_WORK + _N].copy()
        work[_GROUND] += self._foundation_work[0]
        work[_FRICTION] += self._foundation_work[1]
        creation = acc[A_CREATION:A_CREATION + _N]
        end = d.energy.copy()
        kinetic_next = self._kinetic_next_sum + float(end[1])
        t.kinetic_change_J = float(end[1] - self._start_energy[1])
        t.potential_change_J = float(end[0] - self._start_energy[0])
        t.suspension_loss_J = float(acc[A_SUSPENSION])
        t.pin_torsion_loss_J = float(acc[A_TORSION])
        t.contact_work_J = {name: float(w) for name, w in zip(PARTNERS, work - creation,
                                                               strict=True)}
        t.numerical_terms_J = {
            "velocity_jump": float(acc[A_JUMP]),
            "explicit_forces": float(acc[A_EXPLICIT] + t.potential_change_J + kinetic_next
                                     - acc[A_KINETIC_MID]),
            "explicit_constraint_springs": float(creation.sum()),
            "constraint_curvature": float(acc[A_CURVATURE]),
            "implicit_springs": float(acc[A_IMPLICIT_SPRINGS])}
        t.numerical_J = float(sum(t.numerical_terms_J.values()))
        t.residual_J = t.kinetic_change_J + t.potential_change_J - t.booked_J
        return t
