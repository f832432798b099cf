"""Mechanical energy ledger of the MuJoCo track, booked consistently with its integrator.

MuJoCo's ``implicitfast`` step is semi-implicit Euler: from (q_k, v_k) it solves the
constraint forces with the mass matrix M_k, takes v_{k+1} = v_k + h·M̂⁻¹·f with the
damping and actuator-velocity terms implicit, and moves q_{k+1} = q_k + h·v_{k+1}. Every
force therefore does the work f·Δq with Δq = h·v_{k+1}, and the forces are those the step
applied: the dampers and the two actuators at v_{k+1} (the tensioner's ``ForceLaw`` at
v_{k+1}, the velocity servo kv·(ctrl − v_{k+1}) unless clamped), everything else (springs,
gravity, Coriolis, contacts, pins) at (q_k, v_k). With MuJoCo's energy flag
(E = KE + PE: KE = ½·vᵀ·M(q)·v, PE = gravity and joint/tendon springs) one step books

    E_{k+1} − E_k = W_drive + W_tensioner + W_suspension + W_torsion + W_hitch
                    + Σ_partners W_constraint + N_k + r_k

where the numerical term N_k is the integrator's own energy error, in two parts:

* velocity jump −½·Δvᵀ·M_k·Δv (Δv = v_{k+1} − v_k): the first-order dissipation of
  semi-implicit Euler when work is booked on the displacement; always ≤ 0;
* explicit forces PE_{k+1} − PE_k + (f_spring − f_bias)ᵀ·Δq + KE_{k+1} − ½·v_{k+1}ᵀ·M_k·v_{k+1}:
  springs, gravity and the Coriolis force (``qfrc_bias``) are taken at the step's start
  while PE and M change over it (½·Δqᵀ·K·Δq ≥ 0 for a linear spring; the M change is
  small: every link has a constant mass matrix, only the chassis pitch moves M).

The residual r_k = (M_k·Δv − h·f)ᵀ·v_{k+1} is what the booked forces miss of what MuJoCo
integrated (solver tolerance, an unbooked force); it is not a fitted quantity.

Constraint work is booked per row, f_row·(J_row·Δq) with MuJoCo's Jacobian of the step, and
summed by partner: sprocket (hub and teeth), road wheels, idler, return rollers, pins (the
pin connects) and joint limits. The ground is the foundation force element
(:mod:`trackmj.foundation`), booked as integrated: (F(v_k) − C·J·Δv)·(J·Δq) per pin, split
into normal (ground) and friction (ground_friction). A contact's work includes what its
explicit spring returns.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import mujoco
import numpy as np

from trackmj.foundation import S_DELTA, S_N, foundation_penetration, foundation_work
from trackmj.plant import TrackPlant

PARTNERS = ("ground", "ground_friction", "sprocket", "road_wheels", "idler",
            "return_rollers", "pins", "joint_limits")
"""Keys of :attr:`TrackEnergy.contact_work_J`."""

CONTACTS = ("ground", "ground_friction", "sprocket", "road_wheels", "idler", "return_rollers")
"""The partners that are contacts (no pins, no joint limits)."""

_GROUND, _FRICTION, _PINS, _LIMITS = 0, 1, 6, 7
_EQUALITY = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
_LIMIT_JOINT = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)


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
         "constraint_curvature"), 0.0))
    residual_J: float = 0.0

    @property
    def booked_J(self) -> float:
        """Sum of all work terms and the numerical term [J]."""
        return (self.drive_work_J + self.tensioner_work_J + self.suspension_loss_J
                + self.pin_torsion_loss_J + self.hitch_work_J
                + sum(self.contact_work_J.values()) + self.numerical_J)

    def to_dict(self) -> dict:
        return asdict(self)


class TrackEnergyLedger:
    """Books the track's energy terms after every :meth:`TrackPlant.step` (call
    :meth:`after_step`), then :meth:`finish` for the totals.

    Sets MuJoCo's energy flag on ``plant.model`` and runs one ``mj_forward`` to start from
    the current state. Per step it reads what the step left in ``plant.data``: the
    constraint rows, forces and mass matrix of the step's start, the new velocity.
    """

    def __init__(self, plant: TrackPlant) -> None:
        self.plant = plant
        m, d = plant.model, plant.data
        m.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_ENERGY)
        mujoco.mj_forward(m, d)
        self._h = float(m.opt.timestep) * plant.substeps
        if plant.substeps != 1:
            raise ValueError("the ledger books one MuJoCo step per coupling step")
        self._start_energy = d.energy.copy()
        self._v_prev = d.qvel.copy()
        self._drive = m.actuator("sprocket_drive").id
        self._drive_dof = int(m.jnt_dofadr[m.actuator_trnid[self._drive, 0]])
        self._tensioner_dof = int(m.jnt_dofadr[m.joint("idler_slide").id])
        self._damped_dofs = np.nonzero(m.dof_damping > 0.0)[0]   # the suspension slides
        hinges = [j for j in range(m.njnt) if m.joint(j).name.startswith("link_")
                  and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]   # pitch and pin hinges
        if np.any(m.dof_damping[m.jnt_dofadr[hinges]] > 0.0):
            raise ValueError("energy ledger: link hinges must not carry joint damping")
        # the implicit part of the step, qDeriv·Δv, in MuJoCo's sparse layout
        self._deriv_row = np.repeat(np.arange(m.nv), m.D_rownnz)
        self._deriv_col = m.D_colind.copy()
        self._actuator_dofs = np.array([m.jnt_dofadr[m.actuator_trnid[i, 0]]
                                        for i in range(m.nu)])
        self._partner_of_geom = np.full(m.ngeom, -1, dtype=int)
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
        self._mdv = np.zeros(m.nv)
        self._mv = np.zeros(m.nv)
        self._work = np.zeros(len(PARTNERS))
        self._terms = TrackEnergy()
        self._kinetic_next_sum = 0.0   # Σ KE_{k+1}, read one step late
        self._kinetic_mid_sum = 0.0    # Σ ½ v_{k+1}ᵀ M_k v_{k+1}
        self._creation = np.zeros(len(PARTNERS))   # Σ ½·K·Δr² of the constraint springs
        self._curvature = 0.0                      # Σ f·(J·Δq − Δr) of the constraints
        self._pending: dict[str, np.ndarray] | None = None
        self._pin_rows = plant.pin_rows
        self._foundation_work = np.zeros(2)   # (normal, friction) [J]
        self._foundation_pending: tuple[np.ndarray, ...] | None = None
        self._steps = 0

    def after_step(self) -> None:
        """Book the step the plant just took."""
        m, d, t = self.plant.model, self.plant.data, self._terms
        h, v1 = self._h, d.qvel
        if self._steps:
            self._kinetic_next_sum += float(d.energy[1])   # KE at this step's start
        dq = h * v1
        dv = v1 - self._v_prev
        # actuators as integrated: the affine velocity term at v_{k+1} unless clamped
        drive = float(d.actuator_force[self._drive])
        if not self._clamped(self._drive, drive):
            drive += m.actuator_biasprm[self._drive, 2] * dv[self._drive_dof]
        t.drive_work_J += drive * dq[self._drive_dof]
        t.tensioner_work_J += self.plant.idler_force_N * dq[self._tensioner_dof]
        # dampers as integrated: qfrc_damper at v_k plus their share of qDeriv·Δv (the
        # actuators' velocity terms removed). MuJoCo 4.0.0 keeps only the same-tree
        # entries of a tendon's damping in qDeriv, so the pin-torsion dampers (tendons
        # between two links, two trees) are implicit on their diagonal only.
        implicit = np.bincount(self._deriv_row, weights=d.qDeriv * dv[self._deriv_col],
                               minlength=m.nv)
        for i, dof in enumerate(self._actuator_dofs):
            if not self._clamped(i, float(d.actuator_force[i])):
                implicit[dof] -= m.actuator_biasprm[i, 2] * dv[dof]
        damper = (d.qfrc_damper + implicit) * dq
        suspension = float(damper[self._damped_dofs].sum())
        t.suspension_loss_J += suspension
        t.pin_torsion_loss_J += float(damper.sum()) - suspension
        if np.any(d.xfrc_applied[self._chassis]):
            mujoco.mj_jacBodyCom(m, d, self._jacp, self._jacr, self._chassis)
            wrench = d.xfrc_applied[self._chassis]
            t.hitch_work_J += float(wrench[:3] @ (self._jacp @ dq) + wrench[3:] @ (self._jacr @ dq))
        self._book_constraints(dq)
        self._book_foundation(dq)
        # numerical terms (mass matrix of the step's start, still in qM)
        mujoco.mj_mulM(m, d, self._mdv, dv)
        mujoco.mj_mulM(m, d, self._mv, v1)
        t.numerical_terms_J["velocity_jump"] -= 0.5 * float(dv @ self._mdv)
        t.numerical_terms_J["explicit_forces"] += float(
            (d.qfrc_spring - d.qfrc_bias) @ dq)   # + ΔPE and the KE terms at finish
        self._kinetic_mid_sum += 0.5 * float(v1 @ self._mv)
        self._v_prev = v1.copy()
        self._steps += 1

    def _clamped(self, actuator: int, force: float) -> bool:
        m = self.plant.model
        if not m.actuator_forcelimited[actuator]:
            return False
        low, high = m.actuator_forcerange[actuator]
        return force <= low or force >= high

    def _book_constraints(self, dq: np.ndarray) -> None:
        """Work of every constraint row on the step's displacement, f·(J·Δq), by partner;
        then the previous step's rows are settled against the true change of their
        residual (see :meth:`_settle`)."""
        m, d = self.plant.model, self.plant.data
        nefc, ncon = d.nefc, d.ncon
        if len(self._row_rate) < nefc:
            self._row_rate = np.zeros(2 * nefc)
        rate = self._row_rate[:nefc]
        mujoco.mj_mulJacVec(m, d, rate, dq)   # J_row·Δq with the step's Jacobian
        force = d.efc_force[:nefc]
        work = force * rate
        kinds = d.efc_type[:nefc]
        # spring coefficient of each row's force −(K/d²)·d·r / R:  K_row = KBIP0·KBIP2·D
        spring = d.efc_KBIP[:nefc, 0] * d.efc_KBIP[:nefc, 2] * d.efc_D[:nefc]
        pins = slice(0, self._pin_rows)
        if np.any(kinds[pins] != _EQUALITY):
            raise RuntimeError("energy ledger: the pin connects must be the first rows")
        limit = kinds == _LIMIT_JOINT
        self._work[_PINS] += work[pins].sum()
        self._work[_LIMITS] += work[limit].sum()
        self._creation[_LIMITS] += 0.5 * float(np.sum((spring * rate * rate)[limit]))
        pending = {"pin_pos": d.efc_pos[pins].copy(), "pin_force": force[pins].copy(),
                   "pin_rate": rate[pins].copy(), "pin_spring": spring[pins].copy()}
        contacts = None
        if ncon:
            contact = d.contact
            adr, geoms = contact.efc_address[:ncon], contact.geom[:ncon]
            dim, dist = contact.dim[:ncon], contact.dist[:ncon]
            key = geoms[:, 0].astype(np.int64) * m.ngeom + geoms[:, 1]
            contacts = (key, dist)
            partner = np.maximum(self._partner_of_geom[geoms[:, 0]],
                                 self._partner_of_geom[geoms[:, 1]])
            if np.any(partner < 0) or np.any(adr < 0):
                raise RuntimeError("energy ledger: a contact without a known partner or rows")
            rows = np.where(dim == 1, 1, 2 * (dim - 1))   # frictionless 1, pyramid 2·(dim−1)
            lane = np.arange(rows.max())
            mask = lane[None, :] < rows[:, None]
            index = np.where(mask, adr[:, None] + lane[None, :], 0)
            per_contact = np.where(mask, work[index], 0.0).sum(axis=1)
            np.add.at(self._work, partner, per_contact)
            # normal force = the rows' sum (pyramid edges J_n ± μ·J_t), normal rate = the
            # row or the mean of a ± pair; the rest of a ground contact's work is friction
            normal_force = np.where(mask, force[index], 0.0).sum(axis=1)
            normal_rate = rate[adr].copy()
            pyramid = rows > 1
            normal_rate[pyramid] = 0.5 * (normal_rate[pyramid] + rate[adr[pyramid] + 1])
            ground = partner == _GROUND
            friction = float((per_contact - normal_force * normal_rate)[ground].sum())
            self._work[_GROUND] -= friction
            self._work[_FRICTION] += friction
            pending |= {"key": key, "partner": partner, "force": normal_force,
                        "rate": normal_rate, "dist": dist.copy(),
                        "spring": np.where(mask, spring[index], 0.0).sum(axis=1)}
        self._settle(d.efc_pos[pins], contacts)
        self._pending = pending

    def _book_foundation(self, dq: np.ndarray) -> None:
        """Work of the ground foundation over the step as integrated (normal and friction),
        then the previous step's pins settled against their true change of penetration
        (:meth:`_settle_foundation`)."""
        f = self.plant.foundation
        state, jac = f.state, f.jac
        foundation_work(state, jac, f.pins, f.dofs, self._v_prev, self.plant.data.qvel,
                        self._h, self._foundation_work)
        self._settle_foundation(state[:, S_DELTA])
        pushing = state[:, S_N] > 0.0
        # J_n·Δq (a pin's unused dof slots hold J = 0)
        rate = np.einsum("ij,ij->i", jac[pushing, 0, :], dq[f.dofs[pushing]])
        self._foundation_pending = (pushing, state[pushing, S_N].copy(), rate,
                                    state[:, S_DELTA].copy())

    def _settle_foundation(self, penetration: np.ndarray) -> None:
        """The previous step's foundation pins against the penetration ``penetration`` [m]
        the step reached, as :meth:`_settle` does for contacts: the normal force's work on
        J_n·Δq beyond the true change −Δδ is "constraint_curvature", its explicit spring's
        ½·K·Δδ² "explicit_constraint_springs"."""
        old = self._foundation_pending
        if old is None:
            return
        pushing, force, rate, before = old
        change = -(penetration[pushing] - before[pushing])   # the pins' distance change
        curvature = force * (rate - change)
        self._foundation_work[0] -= float(curvature.sum())
        self._curvature += float(curvature.sum())
        self._creation[_GROUND] += 0.5 * self.plant.foundation.stiffness_N_m * float(
            change @ change)

    def _settle(self, pin_pos: np.ndarray,
                contacts: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Book the previous step's constraint terms against the residuals of the state it
        reached: ``pin_pos`` (the pin rows' efc_pos) and ``contacts`` (geom-pair keys and
        distances of the current contacts, or None).

        J·Δq is the residual's change to first order only; the rest, the curvature of the
        constraint along the step (a pin's two links turning on a wrap, a rail sliding
        round a wheel), is work the frozen row direction does in the discrete step
        ("constraint_curvature"). The row's explicit spring adds ½·K·Δr² per step
        ("explicit_constraint_springs"). Both move from the partner to the numerical term.
        Contacts that opened, or whose geom pair has several contacts, keep J·Δq.
        """
        old = self._pending
        if old is None:
            return
        change = pin_pos - old["pin_pos"]
        curvature = float(old["pin_force"] @ (old["pin_rate"] - change))
        self._work[_PINS] -= curvature
        self._curvature += curvature
        self._creation[_PINS] += 0.5 * float(old["pin_spring"] @ (change * change))
        if "key" not in old:
            return
        change = old["rate"].copy()
        if contacts is not None:
            key, dist = contacts
            order = np.argsort(key, kind="stable")
            sorted_key = key[order]
            repeated = np.zeros(len(key), dtype=bool)
            repeated[1:] = sorted_key[1:] == sorted_key[:-1]
            repeated[:-1] |= repeated[1:]
            at = np.minimum(np.searchsorted(sorted_key, old["key"]), len(key) - 1)
            matched = (sorted_key[at] == old["key"]) & ~repeated[at]
            change[matched] = dist[order[at[matched]]] - old["dist"][matched]
        curvature = old["force"] * (old["rate"] - change)
        np.add.at(self._work, old["partner"], -curvature)
        self._curvature += float(curvature.sum())
        pushing = old["force"] > 0.0
        np.add.at(self._creation, old["partner"][pushing],
                  0.5 * (old["spring"] * change * change)[pushing])

    def finish(self) -> TrackEnergy:
        """Totals from the start to the current state (runs one ``mj_forward``)."""
        m, d, t = self.plant.model, self.plant.data, self._terms
        mujoco.mj_forward(m, d)
        ncon = d.ncon
        geoms = d.contact.geom[:ncon]
        self._settle(d.efc_pos[: self._pin_rows],
                     (geoms[:, 0].astype(np.int64) * m.ngeom + geoms[:, 1],
                      d.contact.dist[:ncon]) if ncon else None)
        self._pending = None
        f = self.plant.foundation
        penetration = np.empty(len(f.pins))
        foundation_penetration(d.geom_xpos, f.pins, f.radius, f.line, penetration)
        self._settle_foundation(penetration)
        self._foundation_pending = None
        self._work[_GROUND] += self._foundation_work[0]
        self._work[_FRICTION] += self._foundation_work[1]
        self._foundation_work[:] = 0.0
        end = d.energy.copy()
        kinetic_next = self._kinetic_next_sum + float(end[1])
        t.kinetic_change_J = float(end[1] - self._start_energy[1])
        t.potential_change_J = float(end[0] - self._start_energy[0])
        t.contact_work_J = {name: float(w) for name, w in zip(
            PARTNERS, self._work - self._creation, strict=True)}
        t.numerical_terms_J["explicit_constraint_springs"] = float(self._creation.sum())
        t.numerical_terms_J["constraint_curvature"] = self._curvature
        t.numerical_terms_J["explicit_forces"] += (t.potential_change_J + kinetic_next
                                                   - self._kinetic_mid_sum)
        t.numerical_J = float(sum(t.numerical_terms_J.values()))
        t.residual_J = t.kinetic_change_J + t.potential_change_J - t.booked_J
        return t
