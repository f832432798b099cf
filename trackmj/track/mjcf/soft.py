"""Physical stiffness and damping for MuJoCo soft constraints (contacts and pin connects).

A stated K [N/m] and B [N·s/m] must be the simulated ones. This module maps them to
MuJoCo's direct reference ``solref = (−k, −b)`` and a constant impedance
``solimp = (d, d, …)``, from MuJoCo's own per-row quantities (documentation, Computation
chapter: "Soft constraints", "Solver parameters"; source ``engine_core_constraint.c``:
``mj_makeImpedance``, ``mj_referenceConstraint``).

Per active constraint row i MuJoCo's primal solvers apply the force

    f_i = (aref_i − J_i·q̈) / R_i,   aref_i = −(b/d)·J_i·q̇ − (k/d²)·d·r_i,
    R_i = (1 − d)/d · A_i,

with r_i the violation (contact distance, connect gap), ``A_i = efc_diagA`` MuJoCo's
diagonal approximation of the row's inverse mass (from ``body_invweight0``, fixed at
compile time) and d = dmax the constant impedance. Hence, exactly,

    f_i = −k/((1−d)·A_i)·r_i − b/((1−d)·A_i)·J_i·q̇ − d/((1−d)·A_i)·J_i·q̈ .

A constraint with n rows carrying one force direction (n = 1 for a frictionless contact
and for each axis of a ``connect``; n = 4 for a pyramidal condim-3 contact, whose four edge
forces J_n ± μ·J_t sum to the normal force) is therefore a Kelvin–Voigt element

    K = n·k/((1−d)·A),   B = n·b/((1−d)·A)

plus an apparent mass m_a = n·d/((1−d)·A) acting on the constraint's relative acceleration.
The row diagonal A is the sum of the two bodies' translational ``body_invweight0``
(w₁ + w₂; the world has 0) for frictionless contacts and connects, and
A = 2·μ²·(1 + μ²)·(w₁ + w₂)/impratio for the pyramidal cone (MuJoCo gives all four edges
the regulariser that matches the elliptic cone's friction impedance). Every link is a free
planar body with its pitch hinge at the centre of mass, so w = 2/(3·m_link) for every link,
whatever its place in the loop.

Choice of d: ``aref`` uses the start-of-step state, so semi-implicit Euler integrates the
spring and damper explicitly on the mass m + m_a, which is stable for
m + m_a > (h²·K + 2·h·B)/4 (h the timestep). The generator sets
m_a = margin·(h²·K + 2·h·B)/4 (``[solver].soft_margin``, ignoring the body's own mass m),
i.e. d = x/(1 + x) with x = m_a·A/n: the smallest apparent mass with that margin.

What remains approximate:

* the apparent mass m_a. It slows each constraint's own mode (a contact rings at
  sqrt(K/(m + m_a)), not sqrt(K/m)), and because MuJoCo's J·q̈ omits the velocity product
  J̇·q̇, a constraint on a moving body carries a steady force offset m_a·(J̇·q̇). With free
  links this offset depends only on where a link is in the loop (v²/R on a wrap, ω²·pitch
  at a wrapped pin), not on the link's place in a kinematic tree, so it has no
  once-per-revolution component;
* friction below the Coulomb limit is viscous creep: the pyramidal edges give a tangential
  force μ²·B/2 per unit slip velocity (impratio 1) and no tangential stiffness;
* A comes from ``body_invweight0`` at qpos0 (exact for the free links; for wheels on the
  chassis subtree the qpos0 value), and the impedance is the constant d (no solimp ramp).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from trackmj.validator import ParameterError

MIN_IMPEDANCE = 1e-4
MAX_IMPEDANCE = 0.9999
"""MuJoCo clamps solimp d to [mjMINIMP, mjMAXIMP]; a mapping outside is refused."""

IMPEDANCE_WIDTH_M = 0.001
"""solimp width; irrelevant with dmin = dmax but must be positive."""


@dataclass(frozen=True)
class SoftConstraint:
    """A stated Kelvin–Voigt element and the MuJoCo parameters that simulate it.

    stiffness_N_m K, damping_N_s_m B: per force direction; rows: rows carrying that
    direction (1 or 4); row_diag_per_kg: MuJoCo's ``efc_diagA`` of each row [1/kg];
    impedance: d [-]; apparent_mass_kg: m_a [kg]; solref (−k, −b); solimp (5 values).
    """

    stiffness_N_m: float
    damping_N_s_m: float
    rows: int
    row_diag_per_kg: float
    impedance: float
    apparent_mass_kg: float

    @property
    def solref(self) -> tuple[float, float]:
        scale = (1.0 - self.impedance) * self.row_diag_per_kg / self.rows
        return -self.stiffness_N_m * scale, -self.damping_N_s_m * scale

    @property
    def solimp(self) -> tuple[float, float, float, float, float]:
        return self.impedance, self.impedance, IMPEDANCE_WIDTH_M, 0.5, 2.0


def row_diag(inv_weight_sum: float, condim: int, friction: float = 0.0,
             impratio: float = 1.0) -> tuple[int, float]:
    """(rows, efc_diagA per row [1/kg]) of a contact or connect axis.

    inv_weight_sum: w₁ + w₂, the translational ``body_invweight0`` of both bodies [1/kg];
    condim 1 (frictionless contact, connect axis) or 3 (pyramidal friction cone with
    coefficient ``friction``).
    """
    if condim == 1:
        return 1, inv_weight_sum
    if condim == 3:
        mu2 = friction * friction
        return 4, 2.0 * mu2 * (1.0 + mu2) * inv_weight_sum / impratio
    raise ValueError(f"condim {condim}: only 1 and 3 are mapped")


def soft_constraint(stiffness_N_m: float, damping_N_s_m: float, rows: int,
                    row_diag_per_kg: float, timestep_s: float, margin: float,
                    where: str) -> SoftConstraint:
    """Impedance and solref that give K and B exactly, with the apparent mass
    m_a = margin·(h²K + 2hB)/4; ParameterError naming ``where`` if d leaves MuJoCo's range."""
    h = timestep_s
    apparent = margin * (h * h * stiffness_N_m + 2.0 * h * damping_N_s_m) / 4.0
    x = apparent * row_diag_per_kg / rows
    impedance = x / (1.0 + x)
    if not MIN_IMPEDANCE <= impedance <= MAX_IMPEDANCE:
        raise ParameterError(
            f"{where}: stiffness {stiffness_N_m:g} N/m and damping {damping_N_s_m:g} N·s/m "
            f"need impedance {impedance:.6f}, outside MuJoCo's [{MIN_IMPEDANCE}, "
            f"{MAX_IMPEDANCE}]; change them or [solver].soft_margin")
    return SoftConstraint(stiffness_N_m, damping_N_s_m, rows, row_diag_per_kg, impedance,
                          apparent)


def body_inv_weight(model: mujoco.MjModel, body: str) -> float:
    """Translational ``body_invweight0`` of ``body`` [1/kg] (0 for the world)."""
    return float(model.body_invweight0[model.body(body).id, 0])
