/* trackmj's native track FMU: the engine (see engine.h).

   One track side in MuJoCo stepped exactly as trackmj.track.plant.TrackPlant steps it, so
   that the FMU and the Python plant give the same numbers:

   * each coupling step (1 ms): the scenario inputs (TrackPlant.apply: sprocket speed
     command, rear-hitch load in the chassis frame), the tensioner's affine force law
     F = F0 + Z*v on the idler carrier (ctrl and the actuator's velocity bias, integrated
     implicitly by MuJoCo's implicitfast), then the model's MuJoCo steps with the ground
     foundation (trackmj.track.foundation.step: mj_step1, the foundation's forces and h*D
     added to M, the pin slides' springs' h^2*K too (implicit_springs_apply), mj_factorM,
     mj_step2, the active set checked against the law at the
     end-of-step velocity and mj_step2 taken again from the saved state while it is
     contradicted, at most MAX_ATTEMPTS times);
   * the readouts (stroke, velocity, the applied tension, chassis acceleration as the
     velocity change over the step, drive torque, strand tensions, the derailment
     indicators) as TrackPlant computes them.

   The foundation's kernels (foundation_apply, foundation_finish, foundation_commit and
   their helpers) are line-for-line ports of trackmj/track/foundation.py's numba kernels,
   in the same order of operations; tests/test_fmi_native.py holds the two together.

   Units SI; signs as trackmj.track.plant: stroke grows outward, a tensioner force > 0
   pushes the idler out, the ground's normal force > 0 pushes a pin out of the ground.

   The model (resources/track.mjb, MuJoCo's binary model as the exporting trackmj compiled
   and adjusted it) and the configuration (resources/track.cfg: indices, the foundation's
   arrays, the settled initial state; one "key count values..." line each) are written by
   trackmj/fmi/native/export.py. */
#include "engine.h"
#include "trackmj_variables.h"

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

/* ------------------------------------------------------------------ MuJoCo's errors */

/* MuJoCo reports errors and warnings to a log handler; its default prints them and exits
   the process on an error. Each engine call puts its own handler in place for its thread
   only, for the call's duration (MuJoCo's per-thread override, the one its own Python
   bindings use: _mjPRIVATE_setTlsLogHandler, exported by the bundled library though not in
   its public header): an error jumps back to the call, a warning's text is kept for its
   message. Nothing process-wide is changed, so a host that uses MuJoCo itself, other
   instances on other threads and an FMU unloaded while the host goes on are unaffected. */
mjfLogHandler _mjPRIVATE_setTlsLogHandler(mjfLogHandler handler);

static __thread jmp_buf *active_jump = NULL;
static __thread char mujoco_message[1024];

static void on_mujoco_log(const mjLogMessage *message) {
    if (message->level == mjLOG_ERROR || message->level == mjLOG_WARNING)
        snprintf(mujoco_message, sizeof mujoco_message, "%s", message->subject);
    if (message->level == mjLOG_ERROR && active_jump) longjmp(*active_jump, 1);
}

/* Enter and leave an engine call's MuJoCo section: the handler and the jump target. */
#define MUJOCO_ENTER(jump, outer, previous) \
    do { (outer) = active_jump; active_jump = &(jump); \
         (previous) = _mjPRIVATE_setTlsLogHandler(on_mujoco_log); } while (0)
#define MUJOCO_LEAVE(outer, previous) \
    do { _mjPRIVATE_setTlsLogHandler(previous); active_jump = (outer); } while (0)

/* ------------------------------------------------------------------ foundation */

/* columns of the per-pin state (trackmj.track.foundation's S_*) */
enum { S_DELTA, S_NX, S_NZ, S_VN, S_VT, S_N, S_FT, S_CN, S_CT, S_PX, S_PZ, S_ON, S_SLIDE,
       S_NREF, S_NA, S_FA, S_VN1, S_VT1, N_STATE };
enum { L_H, L_K, L_B, L_ONSET, L_MU, L_SHEAR, N_LAW };
enum { M_SHEAR, M_VN, M_TOUCHING, N_MEMORY };
enum { C_NORMAL, C_SLIDE, C_REFERENCE, C_TRIED_REFERENCE, C_TRIED_APPLIED, N_CHOICE };
#define LIFTED_FOR_GOOD (-2.0)
#define TOLERANCE_N 0.1
#define MAX_ATTEMPTS 5
#define REDO_STATE (mjSTATE_QPOS | mjSTATE_QVEL | mjSTATE_ACT | mjSTATE_TIME \
                    | mjSTATE_WARMSTART)
#define SAVED_STATE mjSTATE_INTEGRATION

typedef struct {
    int n;                 /* pins */
    int width;             /* D: the longest dof chain of a pin body */
    int *pins;             /* (n, 4): geom, body, root body, dof count */
    int *dofs;             /* (n, D) */
    int *mass_index;       /* (n, D, D): address in d->M, -1 none */
    double *radius;        /* (n,) [m] */
    double law[N_LAW];     /* h, K, B, onset, mu, K_j */
    int line_n;
    double *line;          /* (line_n, 2) world (x, z) of the ground line [m] */
    double *state;         /* (n, N_STATE) */
    double *jac;           /* (n, 2, D) */
    double *memory;        /* (n, N_MEMORY) */
    double *choice;        /* (n, N_CHOICE) */
    double *saved_mass;    /* (nC,) */
    double *saved_qvel;    /* (nv,): the step's start velocity */
    long redone, unresolved;
    int springs;           /* joint springs integrated implicitly (the pin slides) */
    int *spring_dofs;      /* (springs,) */
    int *spring_mass_index;  /* (springs,): the dof's diagonal address in d->M */
    double *spring_h_stiffness;  /* (springs,): h*K + B [N s/m] (B: the torsion hinges) */
} Foundation;

static int segment_of(const double *line, int n, double x) {
    int lo = 0, hi = n - 1;
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (line[2 * mid] <= x) lo = mid; else hi = mid;
    }
    return lo;
}

/* Signed distance of (cx, cz) above the ground line and the unit normal out of it
   (foundation._closest). */
static void closest(const double *line, int n, double cx, double cz, double radius,
                    double *dist_out, double *nx_out, double *nz_out) {
    int lo = segment_of(line, n, cx);
    double x0 = line[0], z0 = line[1], x1 = line[2 * (n - 1)], z1 = line[2 * (n - 1) + 1];
    double height;
    if (cx <= x0) {
        height = z0;
    } else if (cx >= x1) {
        height = z1;
    } else {
        double ax = line[2 * lo], az = line[2 * lo + 1];
        double bx = line[2 * lo + 2], bz = line[2 * lo + 3];
        height = bx > ax ? az + (cx - ax) / (bx - ax) * (bz - az) : az;
    }
    double best = INFINITY, gx = cx, gz = height;
    if (cx - radius <= x0) {
        double px = cx < x0 ? cx : x0;
        double d2 = (cx - px) * (cx - px) + (cz - z0) * (cz - z0);
        if (d2 < best) { best = d2; gx = px; gz = z0; }
    }
    if (cx + radius >= x1) {
        double px = cx > x1 ? cx : x1;
        double d2 = (cx - px) * (cx - px) + (cz - z1) * (cz - z1);
        if (d2 < best) { best = d2; gx = px; gz = z1; }
    }
    int first = lo, last = lo;
    while (first > 0 && line[2 * first] > cx - radius) first--;
    while (last < n - 2 && line[2 * (last + 1)] < cx + radius) last++;
    for (int i = first; i <= last; i++) {
        double ax = line[2 * i], az = line[2 * i + 1];
        double bx = line[2 * i + 2], bz = line[2 * i + 3];
        double ex = bx - ax, ez = bz - az;
        double length2 = ex * ex + ez * ez;
        double s = length2 == 0.0 ? 0.0 : ((cx - ax) * ex + (cz - az) * ez) / length2;
        s = fmin(1.0, fmax(0.0, s));
        double px = ax + s * ex, pz = az + s * ez;
        double d2 = (cx - px) * (cx - px) + (cz - pz) * (cz - pz);
        if (d2 < best) { best = d2; gx = px; gz = pz; }
    }
    double dist = sqrt(best);
    double sign = cz < height ? -1.0 : 1.0;
    if (dist > 1e-12) {
        *dist_out = sign * dist;
        *nx_out = sign * (cx - gx) / dist;
        *nz_out = sign * (cz - gz) / dist;
        return;
    }
    double ex = line[2 * lo + 2] - line[2 * lo], ez = line[2 * lo + 3] - line[2 * lo + 1];
    double norm = sqrt(ex * ex + ez * ez);
    *dist_out = 0.0;
    *nx_out = -ez / norm;
    *nz_out = ex / norm;
}

/* Add the in-plane force (fx, fz) [N] at (px, pz) [m] to body's xfrc_applied row. */
static void add_wrench(double *xfrc, const double *xipos, int body, double px, double pz,
                       double fx, double fz) {
    xfrc[6 * body + 0] += fx;
    xfrc[6 * body + 2] += fz;
    xfrc[6 * body + 4] += (pz - xipos[3 * body + 2]) * fx - (px - xipos[3 * body + 0]) * fz;
}

/* The foundation's forces at the step's start into xfrc_applied and h*D into M
   (foundation.foundation_apply). */
static int foundation_apply(const mjModel *m, mjData *d, Foundation *f) {
    const double h = f->law[L_H], k = f->law[L_K], b = f->law[L_B], mu = f->law[L_MU];
    const double shear = f->law[L_SHEAR], onset = f->law[L_ONSET], retardation = b / k;
    const int D = f->width;
    memcpy(f->saved_mass, d->M, sizeof(double) * (size_t)m->nC);
    memcpy(f->saved_qvel, d->qvel, sizeof(double) * (size_t)m->nv);
    for (int i = 0; i < f->n; i++)
        memset(d->xfrc_applied + 6 * f->pins[4 * i + 1], 0, 6 * sizeof(double));
    int active = 0;
    for (int i = 0; i < f->n; i++) {
        int geom = f->pins[4 * i], body = f->pins[4 * i + 1], root = f->pins[4 * i + 2];
        int count = f->pins[4 * i + 3];
        double cx = d->geom_xpos[3 * geom], cz = d->geom_xpos[3 * geom + 2];
        double r = f->radius[i];
        double dist, nx, nz;
        closest(f->line, f->line_n, cx, cz, r, &dist, &nx, &nz);
        double delta = r - dist;
        double *st = f->state + N_STATE * i;
        double *mem = f->memory + N_MEMORY * i, *ch = f->choice + N_CHOICE * i;
        double *jac = f->jac + 2 * D * i;
        memset(st, 0, N_STATE * sizeof(double));
        st[S_DELTA] = delta; st[S_NX] = nx; st[S_NZ] = nz;
        if (delta <= 0.0) continue;
        double px = cx - r * nx, pz = cz - r * nz;
        st[S_PX] = px; st[S_PZ] = pz;
        const double *com = d->subtree_com + 3 * root;
        double ox = px - com[0], oy = d->geom_xpos[3 * geom + 1] - com[1], oz = pz - com[2];
        double tx = nz, tz = -nx;
        double vn = 0.0, vt = 0.0;
        for (int c = 0; c < count; c++) {
            int j = f->dofs[D * i + c];
            const double *cd = d->cdof + 6 * j;
            double jx = cd[3] + cd[1] * oz - cd[2] * oy;
            double jz = cd[5] + cd[0] * oy - cd[1] * ox;
            double jn = nx * jx + nz * jz, jt = tx * jx + tz * jz;
            jac[c] = jn; jac[D + c] = jt;
            vn += jn * d->qvel[j];
            vt += jt * d->qvel[j];
        }
        st[S_VN] = vn; st[S_VT] = vt;
        double predicted = mem[M_TOUCHING] > 0.0 ? vn + (vn - mem[M_VN]) : vn;
        double damping = b * fmin(1.0, delta / onset);
        double pushing = k * delta - damping * predicted;
        int closed = ch[C_NORMAL] != 0.0 ? ch[C_NORMAL] > 0.0 : pushing > 0.0;
        if (!closed) continue;
        double reference = ch[C_REFERENCE] > 0.0 ? ch[C_REFERENCE] : fmax(pushing, 0.0);
        double stiffness = mu * reference / shear;
        double trial = mem[M_SHEAR] + (h + retardation) * vt;
        double slide = ch[C_SLIDE];
        if (slide == 0.0 && fabs(trial) > shear) slide = trial > 0.0 ? 1.0 : -1.0;
        double friction, ct;
        if (slide != 0.0) {
            friction = -mu * reference * slide;
            ct = 0.0;
        } else {
            friction = -stiffness * trial;
            ct = (h + retardation) * stiffness;
        }
        double normal = k * delta - damping * vn, cn = damping;
        st[S_ON] = 1.0; st[S_SLIDE] = slide; st[S_NREF] = reference;
        st[S_N] = normal; st[S_FT] = friction; st[S_CN] = cn; st[S_CT] = ct;
        active++;
        add_wrench(d->xfrc_applied, d->xipos, body, px, pz, normal * nx + friction * tx,
                   normal * nz + friction * tz);
        for (int c = 0; c < count; c++)
            for (int c2 = 0; c2 < count; c2++) {
                int adr = f->mass_index[D * D * i + D * c + c2];
                if (adr >= 0)
                    d->M[adr] += h * (cn * jac[c] * jac[c2] + ct * jac[D + c] * jac[D + c2]);
            }
    }
    return active;
}

/* The N_ref to try next for a pin whose friction exceeded mu*N applied
   (foundation._next_reference). */
static double next_reference(const double *ch, double reference, double applied) {
    double tried = ch[C_TRIED_REFERENCE], tried_applied = ch[C_TRIED_APPLIED];
    if (tried <= 0.0 || fabs(reference - tried) < 1e-9) return applied;
    double slope = (applied - tried_applied) / (reference - tried);
    if (slope >= 0.9) return applied;
    return (tried_applied - slope * tried) / (1.0 - slope);
}

/* The step is taken: each pin's memory, the active set back to 'predict'
   (foundation.foundation_commit). */
static void foundation_commit(Foundation *f, int advance) {
    const double h = f->law[L_H], shear = f->law[L_SHEAR];
    for (int i = 0; i < f->n; i++) {
        const double *st = f->state + N_STATE * i;
        double *mem = f->memory + N_MEMORY * i;
        memset(f->choice + N_CHOICE * i, 0, N_CHOICE * sizeof(double));
        if (st[S_ON] == 0.0) {
            memset(mem, 0, N_MEMORY * sizeof(double));
            continue;
        }
        mem[M_VN] = st[S_VN1];
        mem[M_TOUCHING] = 1.0;
        if (!advance) continue;
        if (st[S_SLIDE] != 0.0)
            mem[M_SHEAR] = st[S_SLIDE] * shear;
        else
            mem[M_SHEAR] = fmin(shear, fmax(-shear, mem[M_SHEAR] + h * st[S_VT1]));
    }
}

/* After mj_step2: the true M back, the applied forces, the active set checked
   (foundation.foundation_finish). Returns the pins whose choice changed. */
static int foundation_finish(const mjModel *m, mjData *d, Foundation *f, int final,
                             int advance) {
    const double h = f->law[L_H], k = f->law[L_K], b = f->law[L_B], mu = f->law[L_MU];
    const double shear = f->law[L_SHEAR], onset = f->law[L_ONSET], retardation = b / k;
    const int D = f->width;
    memcpy(d->M, f->saved_mass, sizeof(double) * (size_t)m->nC);
    int changed = 0;
    for (int i = 0; i < f->n; i++) {
        double *st = f->state + N_STATE * i;
        double *ch = f->choice + N_CHOICE * i;
        const double *jac = f->jac + 2 * D * i;
        if (st[S_DELTA] <= 0.0) continue;
        double jn_dv = 0.0, jt_dv = 0.0;
        for (int c = 0; c < f->pins[4 * i + 3]; c++) {
            int j = f->dofs[D * i + c];
            double dv = d->qvel[j] - f->saved_qvel[j];
            jn_dv += jac[c] * dv;
            jt_dv += jac[D + c] * dv;
        }
        st[S_VN1] = st[S_VN] + jn_dv;
        st[S_VT1] = st[S_VT] + jt_dv;
        if (st[S_ON] == 0.0) {
            if (ch[C_NORMAL] != LIFTED_FOR_GOOD
                && k * st[S_DELTA] - b * fmin(1.0, st[S_DELTA] / onset) * st[S_VN1]
                   > TOLERANCE_N) {
                ch[C_NORMAL] = 1.0;
                changed++;
            }
            continue;
        }
        double fn = -st[S_CN] * jn_dv, ft = -st[S_CT] * jt_dv;
        double nx = st[S_NX], nz = st[S_NZ];
        add_wrench(d->xfrc_applied, d->xipos, f->pins[4 * i + 1], st[S_PX], st[S_PZ],
                   fn * nx + ft * nz, fn * nz - ft * nx);
        double applied_n = st[S_N] + fn, applied_t = st[S_FT] + ft;
        st[S_NA] = applied_n; st[S_FA] = applied_t;
        if (applied_n < -TOLERANCE_N) {
            ch[C_NORMAL] = ch[C_NORMAL] > 0.0 ? LIFTED_FOR_GOOD : -1.0;
            changed++;
            continue;
        }
        if (fabs(applied_t) > mu * applied_n + TOLERANCE_N) {
            ch[C_NORMAL] = 1.0;
            ch[C_REFERENCE] = fmax(next_reference(ch, st[S_NREF], applied_n), 1e-9);
            ch[C_TRIED_REFERENCE] = st[S_NREF];
            ch[C_TRIED_APPLIED] = applied_n;
            changed++;
        }
        if (st[S_SLIDE] == 0.0) {
            double end = f->memory[N_MEMORY * i + M_SHEAR] + (h + retardation) * st[S_VT1];
            if (fabs(end) > shear) {
                ch[C_NORMAL] = 1.0;
                ch[C_SLIDE] = end > 0.0 ? 1.0 : -1.0;
                changed++;
            }
        }
    }
    if (changed == 0 || final) foundation_commit(f, advance);
    return changed;
}

/* Backward Euler for the joint springs: h^2*K into M, -h*K*v0 into qfrc_applied
   (foundation.implicit_springs_apply). */
static void implicit_springs_apply(const mjModel *m, mjData *d, const Foundation *f) {
    const double h = m->opt.timestep;
    for (int i = 0; i < f->springs; i++) {
        d->M[f->spring_mass_index[i]] += h * f->spring_h_stiffness[i];
        int dof = f->spring_dofs[i];
        d->qfrc_applied[dof] = -f->spring_h_stiffness[i] * d->qvel[dof];
    }
}

/* The sprocket drive's velocity servo for a step that starts at its torque limit
   (trackmj/track/servo.py, DriveRetake), asked after every mj_step2: if MuJoCo's clamped
   attempt leaves the servo's torque at the step's end kv·(ctrl − ω₁) no longer at that
   limit, the step is taken again at an explicit zero torque, then at the torque
   T* = kv·(ctrl − ω₁(T*)) of the line through the last two attempts (secants; a repeated
   torque, as after the ground's check took the step again, probes zero torque anew) until
   the residual is below DRIVE_CONSISTENCY of the limit, at most DRIVE_MAX_ATTEMPTS. */
#define DRIVE_CONSISTENCY 1e-3
#define DRIVE_MAX_ATTEMPTS 8

typedef struct {
    int actuator, dof, retaking, attempt;
    double gain, limit;
    double previous_torque, previous_speed;
} Drive;

static int drive_retake(mjModel *m, const mjData *d, Drive *drive) {
    const int a = drive->actuator;
    const double applied = d->actuator_force[a], speed = d->qvel[drive->dof];
    const double command = d->ctrl[a];
    const double residual = applied - drive->gain * (command - speed);
    if (!drive->retaking) {
        if (-drive->limit < applied && applied < drive->limit) return 0;
        if ((applied <= -drive->limit && residual >= 0.0)
            || (applied >= drive->limit && residual <= 0.0)) return 0;
        drive->retaking = 1;
        drive->previous_torque = applied;
        drive->previous_speed = speed;
        m->actuator_forcerange[2 * a] = m->actuator_forcerange[2 * a + 1] = 0.0;
        return 1;
    }
    drive->attempt++;
    if (fabs(residual) <= DRIVE_CONSISTENCY * drive->limit
        || drive->attempt >= DRIVE_MAX_ATTEMPTS) return 0;
    const double torque_b = drive->previous_torque, speed_b = drive->previous_speed;
    drive->previous_torque = applied;
    drive->previous_speed = speed;
    if (applied == torque_b) {   /* the same torque again: a new point at zero torque */
        m->actuator_forcerange[2 * a] = m->actuator_forcerange[2 * a + 1] = 0.0;
        return 1;
    }
    const double slope = (speed_b - speed) / (torque_b - applied);
    double torque = drive->gain * (command - speed + slope * applied)
                    / (1.0 + drive->gain * slope);
    torque = fmin(fmax(torque, -drive->limit), drive->limit);
    m->actuator_forcerange[2 * a] = m->actuator_forcerange[2 * a + 1] = torque;
    return 1;
}

/* One attempt of foundation_step: the laws into M and the forces, then mj_step2. */
static void foundation_integrate(mjModel *m, mjData *d, Foundation *f) {
    foundation_apply(m, d, f);
    implicit_springs_apply(m, d, f);
    mj_factorM(m, d);
    mj_step2(m, d);
}

/* One MuJoCo step with the foundation and the implicit springs (foundation.step); `drive`
   (or NULL) as its `retake`. */
static void foundation_step(mjModel *m, mjData *d, Foundation *f, double *redo,
                            Drive *drive) {
    mj_step1(m, d);
    mj_getState(m, d, redo, REDO_STATE);
    for (int attempt = 0; attempt < MAX_ATTEMPTS; attempt++) {
        foundation_integrate(m, d, f);
        while (drive && drive_retake(m, d, drive)) {   /* Foundation.discard, then again */
            memcpy(d->M, f->saved_mass, sizeof(double) * (size_t)m->nC);
            mj_setState(m, d, redo, REDO_STATE);
            foundation_integrate(m, d, f);
        }
        int final = attempt == MAX_ATTEMPTS - 1;
        if (!foundation_finish(m, d, f, final, 1)) return;
        if (final) {
            f->unresolved++;
            return;
        }
        if (attempt == 0) f->redone++;
        mj_setState(m, d, redo, REDO_STATE);
    }
}

/* ------------------------------------------------------------------ configuration */

typedef struct {
    char key[48];
    int count;
    double *values;
} CfgEntry;

typedef struct {
    int n;
    CfgEntry *entries;
} Cfg;

static void cfg_free(Cfg *cfg) {
    for (int i = 0; i < cfg->n; i++) free(cfg->entries[i].values);
    free(cfg->entries);
    cfg->entries = NULL;
    cfg->n = 0;
}

/* Reads "key count v1 ... vcount" lines; 0 on success, else -1 with `why` filled. */
static int cfg_read(const char *path, Cfg *cfg, char *why, size_t why_size) {
    FILE *file = fopen(path, "rb");
    if (!file) {
        snprintf(why, why_size, "cannot open %s", path);
        return -1;
    }
    memset(cfg, 0, sizeof *cfg);
    char key[48];
    int count;
    while (fscanf(file, "%47s %d", key, &count) == 2) {
        if (count < 0 || count > 100000000) break;
        CfgEntry *grown = realloc(cfg->entries, sizeof(CfgEntry) * (size_t)(cfg->n + 1));
        if (!grown) break;
        cfg->entries = grown;
        CfgEntry *e = &cfg->entries[cfg->n];
        memcpy(e->key, key, sizeof key);
        e->count = count;
        e->values = malloc(sizeof(double) * (size_t)(count > 0 ? count : 1));
        if (!e->values) break;
        cfg->n++;
        for (int i = 0; i < count; i++) {
            char token[64];
            if (fscanf(file, "%63s", token) != 1) {
                snprintf(why, why_size, "%s: key %s ends after %d of %d values", path, key,
                         i, count);
                fclose(file);
                cfg_free(cfg);
                return -1;
            }
            e->values[i] = strtod(token, NULL);
        }
    }
    int at_end = feof(file);
    fclose(file);
    if (!at_end) {
        snprintf(why, why_size, "%s: unreadable after key %s", path,
                 cfg->n ? cfg->entries[cfg->n - 1].key : "(none)");
        cfg_free(cfg);
        return -1;
    }
    return 0;
}

static const CfgEntry *cfg_find(const Cfg *cfg, const char *key) {
    for (int i = 0; i < cfg->n; i++)
        if (!strcmp(cfg->entries[i].key, key)) return &cfg->entries[i];
    return NULL;
}

/* ------------------------------------------------------------------ engine */

enum { OUT_STROKE, OUT_VELOCITY, OUT_TENSION, OUT_ACC_Z, OUT_TORQUE, OUT_UPPER, OUT_LOWER,
       OUT_EXCURSION, OUT_CLOSURE, N_OUT_REAL };
enum { OUT_DISENGAGED, OUT_OFF_ENVELOPE, OUT_SLACK, OUT_DERAILED, N_OUT_BOOL };

/* The chassis kinematics the next step's hitch load is resolved with (TrackPlant reads them
   from MjData, where they are those of the last mj_step1): chassis rotation matrix (9,
   row-major), hitch site position (3), chassis centre of mass (3), world frame [m]. */
enum { K_XMAT = 0, K_SITE = 9, K_COM = 12, N_KINEMATICS = 15 };

/* What a saved state holds besides MuJoCo's integration state and the ground's memory. */
typedef struct {
    uint64_t magic;
    uint64_t steps;                 /* coupling steps since the initial state */
    double values[TRACKMJ_VARIABLE_COUNT];   /* inputs and parameters as set */
    double out_real[N_OUT_REAL];
    int32_t out_bool[N_OUT_BOOL];
    double law_force, law_damping;  /* the last step's force law */
    double speed_command;           /* the sprocket speed command in effect [m/s] */
    double brake_anchor;            /* sprocket angle the parking brake holds to [rad] */
    int32_t parked;                 /* the parking brake is applied */
    int32_t park_pending;           /* asked for at a zero command, not yet applied */
    int32_t hitch_loaded;
    int32_t initialized;
    /* slack-window samples (one after every slack_sample_steps-th of the steps) in a row, up
       to the window, whose least upper-strand pin tension was below the slack tension
       (plant._slack_samples) */
    int32_t slack_samples;
    double kinematics[N_KINEMATICS];
} Scalars;

#define STATE_MAGIC 0x74726b6d6a310003ULL   /* "trkmj1" + layout 3 */

struct Engine {
    mjModel *m;
    mjData *d;
    EngineLog log;
    void *environment;
    Foundation f;
    double *redo;           /* mj_stateSize(REDO_STATE) */
    int substeps;
    /* indices (TrackPlant's) */
    int slide_q, slide_v, sprocket_q, sprocket_v, chassis_q[3], chassis_v[3], tensioner, drive;
    int hitch_site, chassis_body, sprocket_body;
    double drive_gain, drive_limit, drive_band, stroke_offset_m, pitch_radius_m, ride_height_m;
    /* parking brake: k_b/kv [1/s], slip angle [rad], sprocket speed it applies below [rad/s] */
    double brake_ratio, brake_slip_rad, brake_apply_rad_s;
    int n;                  /* pins (= links) */
    int *link_body, *pin_geom, *connect_of_pin;
    int *stretch_qpos;      /* structure "slides": qpos of every pin slide */
    double *pins_per_connect;
    int connects, has_hinged, stretches;
    double strand_bounds[6];
    int hull_n;
    double *hull;           /* (hull_n, 2) home envelope, chassis frame, counter-clockwise */
    double envelope_threshold_m, seat_tolerance_m, slack_tension_N;
    double closure_max_m;   /* a pin gap beyond this: the loop is broken (sim's guard) */
    int min_seated_pins;
    int slack_sample_steps; /* the slack window samples after every this many steps ... */
    int slack_window_samples;   /* ... and is slack when this many in a row were below */
    double *tension;        /* (n,) pin tensions [N] */
    unsigned char *upper, *lower;
    /* the state */
    Scalars s;
    double *initial_mj;     /* SAVED_STATE of the settled track */
    double *initial_memory; /* (n, N_MEMORY) */
    Scalars initial;
    long warnings;          /* MuJoCo warnings counted so far */
    int failed;             /* a step left physics: only reset or free */
};

static void logf_engine(const Engine *e, EngineStatus level, const char *category,
                        const char *format, ...) {
    char message[1024];
    va_list args;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    if (e && e->log) e->log(e->environment, level, category, message);
}

static const VariableInfo *variable(unsigned vr) {
    for (int i = 0; i < TRACKMJ_VARIABLE_COUNT; i++)
        if (TRACKMJ_VARIABLES[i].vr == vr) return &TRACKMJ_VARIABLES[i];
    return NULL;
}

static int variable_index(unsigned vr) {
    for (int i = 0; i < TRACKMJ_VARIABLE_COUNT; i++)
        if (TRACKMJ_VARIABLES[i].vr == vr) return i;
    return -1;
}

static double value_of(const Engine *e, unsigned vr) {
    return e->s.values[variable_index(vr)];
}

/* The entry of a configuration key with `expected` values (any number when < 0); NULL, and a
   logged reason, when the key is missing or has another length. */
static const CfgEntry *cfg_entry(const Engine *e, const Cfg *cfg, const char *key,
                                 int expected) {
    const CfgEntry *entry = cfg_find(cfg, key);
    if (!entry || (expected >= 0 && entry->count != expected)) {
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "resources/track.cfg: key %s %s (expected %d values)", key,
                    entry ? "has another length" : "missing", expected);
        return NULL;
    }
    return entry;
}

/* A configuration array in a fresh allocation of ints or doubles; NULL (and a logged reason)
   when the key is missing or has another length. */
static int *cfg_ints(const Engine *e, const Cfg *cfg, const char *key, int expected) {
    const CfgEntry *entry = cfg_entry(e, cfg, key, expected);
    if (!entry) return NULL;
    int *out = malloc(sizeof(int) * (size_t)(entry->count ? entry->count : 1));
    if (out)
        for (int i = 0; i < entry->count; i++) out[i] = (int)entry->values[i];
    return out;
}

static double *cfg_doubles(const Engine *e, const Cfg *cfg, const char *key, int expected) {
    const CfgEntry *entry = cfg_entry(e, cfg, key, expected);
    if (!entry) return NULL;
    double *out = malloc(sizeof(double) * (size_t)(entry->count ? entry->count : 1));
    if (out) memcpy(out, entry->values, sizeof(double) * (size_t)entry->count);
    return out;
}

static int cfg_count(const Cfg *cfg, const char *key) {
    const CfgEntry *entry = cfg_find(cfg, key);
    return entry ? entry->count : -1;
}

/* Copy the n values of a key into out (doubles, or ints); -1 (and a logged reason) when the
   key is missing or has another length. */
static int cfg_into(const Engine *e, const Cfg *cfg, const char *key, double *out, int n) {
    const CfgEntry *entry = cfg_entry(e, cfg, key, n);
    if (!entry) return -1;
    memcpy(out, entry->values, sizeof(double) * (size_t)n);
    return 0;
}

static int cfg_into_int(const Engine *e, const Cfg *cfg, const char *key, int *out, int n) {
    const CfgEntry *entry = cfg_entry(e, cfg, key, n);
    if (!entry) return -1;
    for (int i = 0; i < n; i++) out[i] = (int)entry->values[i];
    return 0;
}

void engine_free(Engine *e) {
    if (!e) return;
    if (e->d) mj_deleteData(e->d);
    if (e->m) mj_deleteModel(e->m);
    Foundation *f = &e->f;
    free(f->pins); free(f->dofs); free(f->mass_index); free(f->radius); free(f->line);
    free(f->spring_dofs); free(f->spring_mass_index); free(f->spring_h_stiffness);
    free(f->state); free(f->jac); free(f->memory); free(f->choice); free(f->saved_mass);
    free(f->saved_qvel);
    free(e->redo); free(e->link_body); free(e->pin_geom); free(e->connect_of_pin);
    free(e->pins_per_connect); free(e->stretch_qpos);
    free(e->hull); free(e->tension); free(e->upper);
    free(e->lower); free(e->initial_mj); free(e->initial_memory);
    free(e);
}

static int load_configuration(Engine *e, const Cfg *cfg) {
    const mjModel *m = e->m;
    Foundation *f = &e->f;
    double brake[3];
    if (cfg_into_int(e, cfg, "substeps", &e->substeps, 1)
        || cfg_into_int(e, cfg, "pins", &e->n, 1)
        || cfg_into_int(e, cfg, "slide_q", &e->slide_q, 1)
        || cfg_into_int(e, cfg, "slide_v", &e->slide_v, 1)
        || cfg_into_int(e, cfg, "sprocket_q", &e->sprocket_q, 1)
        || cfg_into_int(e, cfg, "sprocket_v", &e->sprocket_v, 1)
        || cfg_into_int(e, cfg, "chassis_q", e->chassis_q, 3)
        || cfg_into_int(e, cfg, "chassis_v", e->chassis_v, 3)
        || cfg_into_int(e, cfg, "tensioner", &e->tensioner, 1)
        || cfg_into_int(e, cfg, "drive", &e->drive, 1)
        || cfg_into_int(e, cfg, "hitch_site", &e->hitch_site, 1)
        || cfg_into_int(e, cfg, "chassis_body", &e->chassis_body, 1)
        || cfg_into_int(e, cfg, "sprocket_body", &e->sprocket_body, 1)
        || cfg_into(e, cfg, "drive_gain", &e->drive_gain, 1)
        || cfg_into(e, cfg, "drive_limit", &e->drive_limit, 1)
        || cfg_into(e, cfg, "drive_band", &e->drive_band, 1)
        || cfg_into(e, cfg, "parking_brake", brake, 3)
        || cfg_into(e, cfg, "stroke_offset_m", &e->stroke_offset_m, 1)
        || cfg_into(e, cfg, "pitch_radius_m", &e->pitch_radius_m, 1)
        || cfg_into(e, cfg, "ride_height_m", &e->ride_height_m, 1)
        || cfg_into(e, cfg, "strand_bounds", e->strand_bounds, 6)
        || cfg_into(e, cfg, "envelope_threshold_m", &e->envelope_threshold_m, 1)
        || cfg_into(e, cfg, "seat_tolerance_m", &e->seat_tolerance_m, 1)
        || cfg_into(e, cfg, "slack_tension_N", &e->slack_tension_N, 1)
        || cfg_into(e, cfg, "closure_max_m", &e->closure_max_m, 1)
        || cfg_into_int(e, cfg, "min_seated_pins", &e->min_seated_pins, 1)
        || cfg_into_int(e, cfg, "slack_sample_steps", &e->slack_sample_steps, 1)
        || cfg_into_int(e, cfg, "slack_window_samples", &e->slack_window_samples, 1)
        || cfg_into_int(e, cfg, "foundation_width", &f->width, 1)
        || cfg_into(e, cfg, "foundation_law", f->law, N_LAW))
        return -1;
    e->brake_ratio = brake[0];
    e->brake_slip_rad = brake[1];
    e->brake_apply_rad_s = brake[2];
    int n = e->n, D = f->width;
    f->n = n;
    e->connects = cfg_count(cfg, "pins_per_connect");
    e->hull_n = cfg_count(cfg, "home_envelope") / 2;
    f->line_n = cfg_count(cfg, "ground_line") / 2;
    e->link_body = cfg_ints(e, cfg, "link_body", n);
    e->pin_geom = cfg_ints(e, cfg, "pin_geom", n);
    e->connect_of_pin = cfg_ints(e, cfg, "connect_of_pin", n);
    e->pins_per_connect = cfg_doubles(e, cfg, "pins_per_connect", -1);
    e->stretches = cfg_count(cfg, "stretch_qpos");
    e->stretch_qpos = cfg_ints(e, cfg, "stretch_qpos", -1);
    e->hull = cfg_doubles(e, cfg, "home_envelope", 2 * e->hull_n);
    f->pins = cfg_ints(e, cfg, "foundation_pins", 4 * n);
    f->dofs = cfg_ints(e, cfg, "foundation_dofs", n * D);
    f->mass_index = cfg_ints(e, cfg, "foundation_mass_index", n * D * D);
    f->radius = cfg_doubles(e, cfg, "foundation_radius", n);
    f->line = cfg_doubles(e, cfg, "ground_line", 2 * f->line_n);
    f->springs = cfg_count(cfg, "spring_dofs");
    f->spring_dofs = cfg_ints(e, cfg, "spring_dofs", -1);
    f->spring_mass_index = cfg_ints(e, cfg, "spring_mass_index", f->springs);
    f->spring_h_stiffness = cfg_doubles(e, cfg, "spring_h_stiffness", f->springs);
    int state_size = mj_stateSize(m, SAVED_STATE);
    e->initial_mj = cfg_doubles(e, cfg, "initial_state", state_size);
    e->initial_memory = cfg_doubles(e, cfg, "initial_memory", N_MEMORY * n);
    double initial_law[2], initial_out[N_OUT_REAL + N_OUT_BOOL], kinematics[N_KINEMATICS];
    double initial_brake[3];
    if (!e->link_body || !e->pin_geom || !e->connect_of_pin || !e->pins_per_connect
        || !e->stretch_qpos || !f->spring_dofs || !f->spring_mass_index
        || !f->spring_h_stiffness
        || !e->hull || !f->pins || !f->dofs || !f->mass_index || !f->radius || !f->line
        || !e->initial_mj || !e->initial_memory || e->hull_n < 3 || f->line_n < 2
        || cfg_into(e, cfg, "initial_law", initial_law, 2)
        || cfg_into(e, cfg, "initial_outputs", initial_out, N_OUT_REAL + N_OUT_BOOL)
        || cfg_into(e, cfg, "initial_kinematics", kinematics, N_KINEMATICS)
        || cfg_into(e, cfg, "initial_brake", initial_brake, 3))
        return -1;
    if (e->slack_sample_steps < 1 || e->slack_window_samples < 1) {
        logf_engine(e, ENGINE_ERROR, "logStatusError", "resources/track.cfg: slack window of "
                    "%d samples, one every %d steps", e->slack_window_samples,
                    e->slack_sample_steps);
        return -1;
    }
    e->has_hinged = 0;
    for (int k = 0; k < n; k++)
        if (e->connect_of_pin[k] < 0) e->has_hinged = 1;
    f->state = calloc((size_t)n * N_STATE, sizeof(double));
    f->jac = calloc((size_t)n * 2 * (size_t)D, sizeof(double));
    f->memory = calloc((size_t)n * N_MEMORY, sizeof(double));
    f->choice = calloc((size_t)n * N_CHOICE, sizeof(double));
    f->saved_mass = calloc((size_t)m->nC, sizeof(double));
    f->saved_qvel = calloc((size_t)m->nv, sizeof(double));
    e->redo = calloc((size_t)mj_stateSize(m, REDO_STATE), sizeof(double));
    e->tension = calloc((size_t)n, sizeof(double));
    e->upper = calloc((size_t)n, 1);
    e->lower = calloc((size_t)n, 1);
    if (!f->state || !f->jac || !f->memory || !f->choice || !f->saved_mass || !f->saved_qvel
        || !e->redo || !e->tension || !e->upper || !e->lower) {
        logf_engine(e, ENGINE_ERROR, "logStatusError", "out of memory");
        return -1;
    }
    /* the initial scalars: start values, the settled state's law and outputs */
    Scalars *s0 = &e->initial;
    memset(s0, 0, sizeof *s0);
    s0->magic = STATE_MAGIC;
    for (int i = 0; i < TRACKMJ_VARIABLE_COUNT; i++) s0->values[i] = TRACKMJ_VARIABLES[i].start;
    s0->law_force = initial_law[0];
    s0->law_damping = initial_law[1];
    for (int i = 0; i < N_OUT_REAL; i++) s0->out_real[i] = initial_out[i];
    for (int i = 0; i < N_OUT_BOOL; i++) s0->out_bool[i] = initial_out[N_OUT_REAL + i] != 0.0;
    memcpy(s0->kinematics, kinematics, sizeof kinematics);
    s0->parked = initial_brake[0] != 0.0;
    s0->park_pending = initial_brake[1] != 0.0;
    s0->brake_anchor = initial_brake[2];
    return 0;   /* step 0, no slack sample yet: the plant's clock and window just cleared */
}

/* The ground parameters into the foundation's law (their values as set). */
static void apply_parameters(Engine *e) {
    double *law = e->f.law;
    law[L_K] = value_of(e, VR_ground_stiffness_N_m);
    law[L_B] = value_of(e, VR_ground_damping_N_s_m);
    law[L_ONSET] = value_of(e, VR_ground_damping_onset_m);
    law[L_SHEAR] = value_of(e, VR_ground_shear_modulus_m);
    law[L_MU] = value_of(e, VR_ground_friction);
}

static long warning_total(const mjData *d) {
    long total = 0;
    for (int i = 0; i < mjNWARNING; i++) total += d->warning[i].number;
    return total;
}

EngineStatus engine_reset(Engine *e) {
    if (!e) return ENGINE_ERROR;
    jmp_buf jump, *outer;
    mjfLogHandler previous;
    MUJOCO_ENTER(jump, outer, previous);
    if (setjmp(jump)) {
        MUJOCO_LEAVE(outer, previous);
        logf_engine(e, ENGINE_ERROR, "logStatusError", "reset: MuJoCo error: %s",
                    mujoco_message);
        e->failed = 1;
        return ENGINE_ERROR;
    }
    mj_resetData(e->m, e->d);
    mj_setState(e->m, e->d, e->initial_mj, SAVED_STATE);
    MUJOCO_LEAVE(outer, previous);
    memcpy(e->f.memory, e->initial_memory, sizeof(double) * (size_t)e->n * N_MEMORY);
    memset(e->f.choice, 0, sizeof(double) * (size_t)e->n * N_CHOICE);
    e->s = e->initial;
    apply_parameters(e);
    e->m->actuator_biasprm[mjNBIAS * e->tensioner + 2] = e->s.law_damping;
    e->warnings = warning_total(e->d);
    e->failed = 0;
    return ENGINE_OK;
}

static void join_path(char *out, size_t size, const char *dir, const char *file) {
    size_t len = strlen(dir);
    int separator = len > 0 && (dir[len - 1] == '/' || dir[len - 1] == '\\');
    snprintf(out, size, "%s%s%s", dir, separator ? "" : "/", file);
}

#ifdef _WIN32
/* The build's loader of the bundled mujoco.dll (trackmj/fmi/native/toolchain.py): NULL once
   it is loaded, else why it cannot be (e.g. no Visual C++ runtime on the host). */
const char *trackmj_mujoco_load_error(void);
#endif

Engine *engine_new(const char *resource_dir, EngineLog log, void *environment) {
#ifdef _WIN32
    const char *unloadable = trackmj_mujoco_load_error();
    if (unloadable) {
        if (log) log(environment, ENGINE_ERROR, "logStatusError", unloadable);
        return NULL;
    }
#endif
    Engine *volatile e = calloc(1, sizeof(Engine));
    if (!e) {
        if (log) log(environment, ENGINE_ERROR, "logStatusError", "out of memory");
        return NULL;
    }
    e->log = log;
    e->environment = environment;
    char path[4096], why[4608];
    jmp_buf jump, *outer;
    mjfLogHandler previous;
    MUJOCO_ENTER(jump, outer, previous);
    if (setjmp(jump)) {
        MUJOCO_LEAVE(outer, previous);
        logf_engine(e, ENGINE_ERROR, "logStatusError", "loading the model: MuJoCo error: %s",
                    mujoco_message);
        engine_free(e);
        return NULL;
    }
    join_path(path, sizeof path, resource_dir, "track.mjb");
    mujoco_message[0] = '\0';
    e->m = mj_loadModel(path, NULL);
    if (!e->m) {
        MUJOCO_LEAVE(outer, previous);
        logf_engine(e, ENGINE_ERROR, "logStatusError", "cannot load the model %s: %s", path,
                    mujoco_message[0] ? mujoco_message : "no such file or not a model of "
                    "this MuJoCo version");
        engine_free(e);
        return NULL;
    }
    e->d = mj_makeData(e->m);
    MUJOCO_LEAVE(outer, previous);
    if (!e->d) {
        logf_engine(e, ENGINE_ERROR, "logStatusError", "MuJoCo could not allocate its data");
        engine_free(e);
        return NULL;
    }
    Cfg cfg;
    join_path(path, sizeof path, resource_dir, "track.cfg");
    if (cfg_read(path, &cfg, why, sizeof why)) {
        logf_engine(e, ENGINE_ERROR, "logStatusError", "%s", why);
        engine_free(e);
        return NULL;
    }
    int loaded = load_configuration(e, &cfg);
    cfg_free(&cfg);
    if (loaded || engine_reset(e) != ENGINE_OK) {
        engine_free(e);
        return NULL;
    }
    return e;
}

/* ------------------------------------------------------------------ values */

EngineStatus engine_set_real(Engine *e, unsigned vr, double value) {
    if (!e) return ENGINE_ERROR;
    const VariableInfo *v = variable(vr);
    if (!v || v->kind != VAR_FLOAT64) {
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "no Float64 variable has value reference %u", vr);
        return ENGINE_ERROR;
    }
    if (v->causality != CAUSALITY_INPUT && v->causality != CAUSALITY_PARAMETER) {
        logf_engine(e, ENGINE_ERROR, "logStatusError", "%s is an %s: it cannot be set",
                    v->name, v->causality == CAUSALITY_OUTPUT ? "output" : "independent");
        return ENGINE_ERROR;
    }
    if (v->causality == CAUSALITY_PARAMETER && e->s.initialized) {
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "%s is a fixed parameter: set it before initialisation ends", v->name);
        return ENGINE_ERROR;
    }
    if (!isfinite(value) || value < v->minimum || value > v->maximum) {
        const char *unit = strcmp(v->unit, "1") ? v->unit : "";
        char range[128] = "finite";
        if (isfinite(v->minimum) || isfinite(v->maximum))
            snprintf(range, sizeof range, "within [%g, %g]%s%s", v->minimum, v->maximum,
                     *unit ? " " : "", unit);
        logf_engine(e, ENGINE_ERROR, "logStatusError", "%s = %.17g%s%s: must be %s",
                    v->name, value, *unit ? " " : "", unit, range);
        return ENGINE_ERROR;
    }
    e->s.values[variable_index(vr)] = value;
    return ENGINE_OK;
}

EngineStatus engine_get_real(Engine *e, unsigned vr, double *value) {
    if (!e || !value) return ENGINE_ERROR;
    const VariableInfo *v = variable(vr);
    if (!v || v->kind != VAR_FLOAT64) {
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "no Float64 variable has value reference %u", vr);
        return ENGINE_ERROR;
    }
    switch (vr) {
    case VR_time: *value = engine_time(e); break;
    case VR_stroke_m: *value = e->s.out_real[OUT_STROKE]; break;
    case VR_velocity_m_s: *value = e->s.out_real[OUT_VELOCITY]; break;
    case VR_tension_N: *value = e->s.out_real[OUT_TENSION]; break;
    case VR_chassis_acc_z_m_s2: *value = e->s.out_real[OUT_ACC_Z]; break;
    case VR_drive_torque_N_m: *value = e->s.out_real[OUT_TORQUE]; break;
    case VR_upper_strand_tension_N: *value = e->s.out_real[OUT_UPPER]; break;
    case VR_lower_strand_tension_N: *value = e->s.out_real[OUT_LOWER]; break;
    case VR_max_envelope_excursion_m: *value = e->s.out_real[OUT_EXCURSION]; break;
    case VR_closure_error_m: *value = e->s.out_real[OUT_CLOSURE]; break;
    default: *value = e->s.values[variable_index(vr)]; break;
    }
    return ENGINE_OK;
}

EngineStatus engine_get_boolean(Engine *e, unsigned vr, int *value) {
    if (!e || !value) return ENGINE_ERROR;
    switch (vr) {
    case VR_sprocket_disengaged: *value = e->s.out_bool[OUT_DISENGAGED]; return ENGINE_OK;
    case VR_links_off_envelope: *value = e->s.out_bool[OUT_OFF_ENVELOPE]; return ENGINE_OK;
    case VR_slack_strand: *value = e->s.out_bool[OUT_SLACK]; return ENGINE_OK;
    case VR_derailed: *value = e->s.out_bool[OUT_DERAILED]; return ENGINE_OK;
    default:
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "no Boolean variable has value reference %u", vr);
        return ENGINE_ERROR;
    }
}

EngineStatus engine_initialize(Engine *e) {
    if (!e) return ENGINE_ERROR;
    apply_parameters(e);
    e->s.initialized = 1;
    return ENGINE_OK;
}

double engine_time(const Engine *e) {
    return e ? (double)e->s.steps * ENGINE_STEP_S : 0.0;
}

/* ------------------------------------------------------------------ readouts */

/* Tension of every pin into e->tension (plant._pin_tensions). */
static void pin_tensions(Engine *e) {
    const mjModel *m = e->m;
    mjData *d = e->d;
    if (e->has_hinged) mj_rnePostConstraint(m, d);
    int n = e->n;
    for (int k = 0; k < n; k++) {
        int c = e->connect_of_pin[k];
        double fx, fy, fz;
        if (c >= 0) {
            fx = d->efc_force[3 * c]; fy = d->efc_force[3 * c + 1]; fz = d->efc_force[3 * c + 2];
        } else {
            const double *cf = d->cfrc_int + 6 * e->link_body[k];
            fx = -cf[3]; fy = -cf[4]; fz = -cf[5];
        }
        int a = e->link_body[k], b = e->link_body[k == 0 ? n - 1 : k - 1];
        double bx = d->xmat[9 * a + 0] + d->xmat[9 * b + 0];
        double by = d->xmat[9 * a + 3] + d->xmat[9 * b + 3];
        double bz = d->xmat[9 * a + 6] + d->xmat[9 * b + 6];
        double norm = sqrt(bx * bx + by * by + bz * bz);
        e->tension[k] = (fx * bx + fy * by + fz * bz) / norm;
    }
}

/* Pin k's position in the chassis frame (plant._chassis_frame_pins). */
static void chassis_frame_pin(const Engine *e, int k, double *x, double *z) {
    const mjData *d = e->d;
    double x0 = d->qpos[e->chassis_q[0]], z0 = e->ride_height_m + d->qpos[e->chassis_q[1]];
    double pitch = d->qpos[e->chassis_q[2]];
    double c = cos(pitch), s = sin(pitch);
    int g = e->pin_geom[k];
    double rx = d->geom_xpos[3 * g] - x0, rz = d->geom_xpos[3 * g + 2] - z0;
    *x = c * rx - s * rz;
    *z = s * rx + c * rz;
}

/* Strand masks and mean tensions (plant._strands); NaN for an empty strand. */
static void strands(Engine *e, double *upper_N, double *lower_N) {
    const double *bounds = e->strand_bounds;
    double sum_u = 0.0, sum_l = 0.0;
    int n_u = 0, n_l = 0;
    for (int k = 0; k < e->n; k++) {
        double px, pz;
        chassis_frame_pin(e, k, &px, &pz);
        e->upper[k] = pz > bounds[1] + bounds[2] * px;
        e->lower[k] = bounds[3] < px && px < bounds[4] && pz < bounds[5];
        if (e->upper[k]) { sum_u += e->tension[k]; n_u++; }
        if (e->lower[k]) { sum_l += e->tension[k]; n_l++; }
    }
    *upper_N = n_u ? sum_u / n_u : NAN;
    *lower_N = n_l ? sum_l / n_l : NAN;
}

/* Largest distance of a pin outside the home envelope [m] (plant.envelope_excursion_m). */
static double envelope_excursion(const Engine *e) {
    double worst = 0.0;
    for (int k = 0; k < e->n; k++) {
        double px, pz;
        chassis_frame_pin(e, k, &px, &pz);
        double outside = -INFINITY;
        for (int i = 0; i < e->hull_n; i++) {
            int j = (i + 1) % e->hull_n;
            double hx = e->hull[2 * i], hz = e->hull[2 * i + 1];
            double ex = e->hull[2 * j] - hx, ez = e->hull[2 * j + 1] - hz;
            double norm = sqrt(ez * ez + ex * ex);
            double nx = ez / norm, nz = -ex / norm;
            double distance = (px * nx + pz * nz) - (nx * hx + nz * hz);
            if (distance > outside) outside = distance;
        }
        if (outside > worst) worst = outside;
    }
    return worst;
}

/* Pins within the seat tolerance of the sprocket pitch circle (plant.seated_sprocket_pins). */
static int seated_pins(const Engine *e) {
    const mjData *d = e->d;
    double cx = d->xpos[3 * e->sprocket_body], cz = d->xpos[3 * e->sprocket_body + 2];
    int seated = 0;
    for (int k = 0; k < e->n; k++) {
        int g = e->pin_geom[k];
        double dx = d->geom_xpos[3 * g] - cx, dz = d->geom_xpos[3 * g + 2] - cz;
        if (fabs(sqrt(dx * dx + dz * dz) - e->pitch_radius_m) < e->seat_tolerance_m) seated++;
    }
    return seated;
}

/* Largest pin deflection of the loop [m] (plant._largest_pin_gap_m). */
static double closure_error(const Engine *e) {
    const double *efc = e->d->efc_pos;
    double largest = 0.0;
    for (int c = 0; c < e->connects; c++) {
        double a = efc[3 * c], b = efc[3 * c + 1], z = efc[3 * c + 2];
        double gap = sqrt(a * a + b * b + z * z) / e->pins_per_connect[c];
        if (gap > largest) largest = gap;
    }
    for (int i = 0; i < e->stretches; i++) {
        double gap = fabs(e->d->qpos[e->stretch_qpos[i]]);
        if (gap > largest) largest = gap;
    }
    return largest;
}

/* The pin tensions and strand masks now (into e->tension, e->upper, e->lower) and the mean
   strand tensions (into the outputs). */
static void read_strands(Engine *e) {
    pin_tensions(e);
    strands(e, &e->s.out_real[OUT_UPPER], &e->s.out_real[OUT_LOWER]);
}

/* A slack-window sample from read_strands' tensions: the least upper-strand pin tension
   (0 N with no pin there) against the slack tension; the run of slack samples goes on, up
   to the window, or ends (plant._book_slack; NaN ends it as there). */
static void book_slack(Engine *e) {
    double least = INFINITY;
    for (int k = 0; k < e->n; k++)
        if (e->upper[k] && e->tension[k] < least) least = e->tension[k];
    if (isinf(least)) least = 0.0;
    if (!(least < e->slack_tension_N)) e->s.slack_samples = 0;
    else if (e->s.slack_samples < e->slack_window_samples) e->s.slack_samples++;
}

/* The outputs after the last step of a doStep; the strands' come from its read_strands. */
static void read_outputs(Engine *e, double stroke0) {
    const mjData *d = e->d;
    double *out = e->s.out_real;
    out[OUT_STROKE] = e->stroke_offset_m + d->qpos[e->slide_q];
    out[OUT_VELOCITY] = e->substeps == 1 ? d->qvel[e->slide_v]
                                         : (out[OUT_STROKE] - stroke0) / ENGINE_STEP_S;
    out[OUT_TENSION] = e->s.law_force + e->s.law_damping * d->qvel[e->slide_v];
    out[OUT_ACC_Z] = (d->qvel[e->chassis_v[1]] - e->f.saved_qvel[e->chassis_v[1]])
                     / e->m->opt.timestep;
    double torque = e->drive_gain * (d->ctrl[e->drive] - d->qvel[e->sprocket_v]);
    out[OUT_TORQUE] = fmin(fmax(torque, -e->drive_limit), e->drive_limit);
    out[OUT_EXCURSION] = envelope_excursion(e);
    int *flags = e->s.out_bool;
    flags[OUT_DISENGAGED] = seated_pins(e) < e->min_seated_pins;
    flags[OUT_OFF_ENVELOPE] = out[OUT_EXCURSION] > e->envelope_threshold_m;
    flags[OUT_SLACK] = e->s.slack_samples >= e->slack_window_samples;
    flags[OUT_DERAILED] = flags[OUT_DISENGAGED] || flags[OUT_OFF_ENVELOPE] || flags[OUT_SLACK];
    out[OUT_CLOSURE] = closure_error(e);
}

/* ------------------------------------------------------------------ stepping */

/* The hitch load in the chassis frame as a wrench at the chassis' centre of mass
   (plant.set_hitch_force): pull rearward along chassis x, down along chassis -z. */
static void set_hitch_force(Engine *e, double pull_N, double down_N) {
    const double *kin = e->s.kinematics, *r = kin + K_XMAT;
    double local[3] = {-pull_N, 0.0, -down_N}, force[3], arm[3];
    for (int i = 0; i < 3; i++)
        force[i] = r[3 * i] * local[0] + r[3 * i + 1] * local[1] + r[3 * i + 2] * local[2];
    for (int i = 0; i < 3; i++) arm[i] = kin[K_SITE + i] - kin[K_COM + i];
    double *w = e->d->xfrc_applied + 6 * e->chassis_body;
    w[0] = force[0]; w[1] = force[1]; w[2] = force[2];
    w[3] = arm[1] * force[2] - arm[2] * force[1];
    w[4] = arm[2] * force[0] - arm[0] * force[2];
    w[5] = arm[0] * force[1] - arm[1] * force[0];
}

/* Where the state left physics, as one phrase (NULL: it did not). */
static const char *left_physics(Engine *e, char *why, size_t size) {
    const mjData *d = e->d;
    const mjModel *m = e->m;
    for (int i = 0; i < m->nq; i++)
        if (!isfinite(d->qpos[i])) {
            snprintf(why, size, "position qpos[%d] is not finite", i);
            return why;
        }
    for (int i = 0; i < m->nv; i++)
        if (!isfinite(d->qvel[i])) {
            snprintf(why, size, "velocity qvel[%d] is not finite", i);
            return why;
        }
    double gap = closure_error(e);
    if (gap > e->closure_max_m) {
        snprintf(why, size, "a pin gap of %.3g mm exceeds %.3g mm: the track loop broke",
                 gap * 1e3, e->closure_max_m * 1e3);
        return why;
    }
    long warnings = warning_total(d);
    if (warnings > e->warnings) {
        for (int i = 0; i < mjNWARNING; i++)
            if (d->warning[i].number) {
                snprintf(why, size, "MuJoCo warning: %s",
                         mju_warningText(i, (size_t)d->warning[i].lastinfo));
                break;
            }
        e->warnings = warnings;
        return why;
    }
    return NULL;
}

EngineStatus engine_step(Engine *e, long steps) {
    if (!e) return ENGINE_ERROR;
    if (e->failed) {
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "the track left physics at t = %.6f s: reset or free the instance",
                    engine_time(e));
        return ENGINE_ERROR;
    }
    mjModel *m = e->m;
    mjData *d = e->d;
    jmp_buf jump, *outer;
    mjfLogHandler previous;
    volatile long done = 0;
    MUJOCO_ENTER(jump, outer, previous);
    if (setjmp(jump)) {
        MUJOCO_LEAVE(outer, previous);
        e->failed = 1;
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "MuJoCo error in the step from t = %.6f s: %s", engine_time(e),
                    mujoco_message);
        return ENGINE_ERROR;
    }
    const double speed = value_of(e, VR_track_speed_m_s);
    const double pull = value_of(e, VR_hitch_pull_N), down = value_of(e, VR_hitch_down_N);
    const double force = value_of(e, VR_force_N), slope = value_of(e, VR_force_dv_N_s_m);
    char why[256];
    for (; done < steps; done++) {
        /* the scenario inputs (TrackPlant.apply) */
        if (speed != e->s.speed_command) {   /* TrackPlant.set_track_speed */
            if (speed == 0.0 && e->brake_ratio > 0.0) {
                if (!e->s.parked) e->s.park_pending = 1;
            } else {
                e->s.parked = e->s.park_pending = 0;
            }
            e->s.speed_command = speed;
        }
        if (pull != 0.0 || down != 0.0 || e->s.hitch_loaded) {
            set_hitch_force(e, pull, down);
            e->s.hitch_loaded = pull != 0.0 || down != 0.0;
        }
        /* the coupling step (TrackPlant.step with a ConstantForce element) */
        double stroke0 = e->stroke_offset_m + d->qpos[e->slide_q];
        d->ctrl[e->tensioner] = force;
        m->actuator_biasprm[mjNBIAS * e->tensioner + 2] = slope;
        if (e->s.park_pending && fabs(d->qvel[e->sprocket_v]) < e->brake_apply_rad_s) {
            e->s.parked = 1;
            e->s.park_pending = 0;
            e->s.brake_anchor = d->qpos[e->sprocket_q];
        }
        const int parked = e->s.parked;
        const double command = parked
            ? e->brake_ratio * (e->s.brake_anchor - d->qpos[e->sprocket_q])
            : e->s.speed_command / e->pitch_radius_m;
        d->ctrl[e->drive] = command;
        Drive drive = {e->drive, e->sprocket_v, 0, 0, e->drive_gain, e->drive_limit, 0.0, 0.0};
        for (int sub = 0; sub < e->substeps; sub++) {
            const int saturated = fabs(command - d->qvel[e->sprocket_v]) >= e->drive_band;
            drive.retaking = drive.attempt = 0;   /* DriveRetake.start */
            foundation_step(m, d, &e->f, e->redo, saturated ? &drive : NULL);
            if (saturated) {   /* DriveRetake.restore */
                m->actuator_forcerange[2 * e->drive] = -e->drive_limit;
                m->actuator_forcerange[2 * e->drive + 1] = e->drive_limit;
            }
        }
        if (parked) {   /* the brake slips: its anchor follows, the spring at the limit */
            double angle = d->qpos[e->sprocket_q];
            if (fabs(e->s.brake_anchor - angle) > e->brake_slip_rad)
                e->s.brake_anchor = angle + copysign(e->brake_slip_rad,
                                                     e->s.brake_anchor - angle);
        }
        e->s.law_force = force;
        e->s.law_damping = slope;
        e->s.steps++;
        memcpy(e->s.kinematics + K_XMAT, d->xmat + 9 * e->chassis_body, 9 * sizeof(double));
        memcpy(e->s.kinematics + K_SITE, d->site_xpos + 3 * e->hitch_site, 3 * sizeof(double));
        memcpy(e->s.kinematics + K_COM, d->xipos + 3 * e->chassis_body, 3 * sizeof(double));
        if (left_physics(e, why, sizeof why)) {
            MUJOCO_LEAVE(outer, previous);
            e->failed = 1;
            logf_engine(e, ENGINE_ERROR, "logStatusError",
                        "the track left physics in the step ending at t = %.6f s: %s "
                        "(tensioner force %.6g N, track speed %.6g m/s, hitch %.6g N)",
                        engine_time(e), why, force, speed, pull);
            return ENGINE_ERROR;
        }
        /* the slack window samples after every slack_sample_steps-th step (plant.step_count,
           both from 0 at the settled state); the strands are read for it and for the
           outputs after the doStep's last step, once when both fall on a step */
        const int sample = e->s.steps % (uint64_t)e->slack_sample_steps == 0;
        const int last = done == steps - 1;
        if (sample || last) read_strands(e);
        if (sample) book_slack(e);
        if (last) read_outputs(e, stroke0);
    }
    MUJOCO_LEAVE(outer, previous);
    return ENGINE_OK;
}

/* ------------------------------------------------------------------ state */

size_t engine_state_size(const Engine *e) {
    if (!e) return 0;
    return sizeof(Scalars) + sizeof(double) * ((size_t)mj_stateSize(e->m, SAVED_STATE)
                                              + (size_t)e->n * N_MEMORY);
}

EngineStatus engine_save(const Engine *e, void *bytes) {
    if (!e || !bytes) return ENGINE_ERROR;
    unsigned char *at = bytes;
    memcpy(at, &e->s, sizeof(Scalars));
    double *mj = (double *)(at + sizeof(Scalars));
    mj_getState(e->m, e->d, mj, SAVED_STATE);
    memcpy(mj + mj_stateSize(e->m, SAVED_STATE), e->f.memory,
           sizeof(double) * (size_t)e->n * N_MEMORY);
    return ENGINE_OK;
}

EngineStatus engine_restore(Engine *e, const void *bytes, size_t size) {
    if (!e || !bytes) return ENGINE_ERROR;
    Scalars s;
    memcpy(&s, bytes, sizeof s);
    if (size != engine_state_size(e) || s.magic != STATE_MAGIC) {
        logf_engine(e, ENGINE_ERROR, "logStatusError",
                    "a state of %zu bytes that is not this model's (%zu bytes expected)",
                    size, engine_state_size(e));
        return ENGINE_ERROR;
    }
    const double *mj = (const double *)((const unsigned char *)bytes + sizeof(Scalars));
    mj_setState(e->m, e->d, mj, SAVED_STATE);
    memcpy(e->f.memory, mj + mj_stateSize(e->m, SAVED_STATE),
           sizeof(double) * (size_t)e->n * N_MEMORY);
    memset(e->f.choice, 0, sizeof(double) * (size_t)e->n * N_CHOICE);
    e->s = s;
    apply_parameters(e);
    e->m->actuator_biasprm[mjNBIAS * e->tensioner + 2] = s.law_damping;
    e->warnings = warning_total(e->d);
    e->failed = 0;
    return ENGINE_OK;
}
