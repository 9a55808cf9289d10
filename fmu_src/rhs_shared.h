/* Shared by the files that make up the right-hand side; not part of the
 * model's interface. */
#ifndef LSS_CHAIN_INTERNAL_H
#define LSS_CHAIN_INTERNAL_H

#include "chain.h"
#include "lss_math.h"
#include "track_local.h"

/* Onset velocity in force: remembered since the contact closed, or, for a
 * contact that closes within the current step, its present closing rate;
 * never below the floor v_min. */
static inline double contact_vi(double remembered, double ddelta, double v_min) {
    if (remembered > 0) return remembered;
    return ddelta > v_min ? ddelta : v_min;
}

/* The contact memory of slot k after an accepted step whose last stage
 * (at the new point) gave indentation d1 and rate dd1: a contact that closed
 * within the step gets its onset velocity, interpolated at the crossing; an
 * open one forgets. Returns 1 if the right-hand side at the new point
 * changed: only when a contact closed and the remembered onset velocity
 * differs from the closing rate the evaluation used (an open contact has no
 * force whatever it remembers). Shared by both paths (chain_step.c,
 * chain_simd.c). */
static inline int contact_memory_slot(ChainState *st, double v_min, int k, double d1, double dd1) {
    int changed = 0;
    if (d1 > 0) {
        if (!(st->v_onset[k] > 0)) {
            double d0 = st->delta_prev[k], dd0 = st->ddelta_prev[k];
            double th = (d0 < 0 && d1 > d0) ? d0 / (d0 - d1) : 1.0;
            double v = (1 - th) * dd0 + th * dd1;
            v = v > v_min ? v : v_min;
            st->v_onset[k] = v;
            if (v != contact_vi(0.0, dd1, v_min)) changed = 1;
        }
    } else if (st->v_onset[k] > 0) {
        st->v_onset[k] = 0.0;
    }
    st->delta_prev[k] = d1;
    st->ddelta_prev[k] = dd1;
    return changed;
}

/* Can a motor push at all (a motor exists, and a command, an external thrust or the ripple is on)? */
static inline int drive_acts(const ChainModel *m, double F_cmd) {
    return m->track.n_motors > 0 && (F_cmd != 0.0 || m->fx.ripple_on || m->drive_mode == DRIVE_EXTERNAL);
}
/* Each motor's own thrust under the external drive; NULL under the internal one. */
static inline const double *drive_motors(const Chain *c) {
    return c->m.drive_mode == DRIVE_EXTERNAL ? c->st.F_motor : NULL;
}

/* Smooth sign for rolling resistance: full value above 1 cm/s. */
static inline double smooth_sign(double v) { return v / sqrt(v * v + 1e-4); }

/* One cart in the coordinates of its track base (the track frame at its
 * axle after the last accepted step, CartScratch.base): what the wheels
 * need, computed once per cart and evaluation. */
typedef struct {
    double M[9];                      /* body axes in base coordinates: R_b^T R */
    double q[3], v[3], om[3];         /* CG position (from the base point), velocity, angular velocity */
    LocalFrame axle;                  /* the track frame at the axle */
} CartLocal;

/* Kinematics of cart i: rotation, world angular rate, its place on the
 * track (fills L); returns the tangential speed of the axle. Resets the
 * cart's force to its weight and its torque to zero. */
double cart_kinematics(Chain *c, const double *y, int i, CartLocal *L);
/* The four wheels of cart i against the track, from its CartLocal. */
void wheel_forces(Chain *c, int i, const CartLocal *L, double *p_damp, double *p_roll);
/* The joint between cart j's front and cart j+1's rear. */
void joint_forces(Chain *c, const double *y, int j, double *p_damp);
void drive_forces(Chain *c, const double *y, int i, double F_cmd);
/* Velocity-dependent running resistance of cart i (effects.c). */
void effects_resistance(Chain *c, int i, double *p_roll);
/* Newton-Euler: writes the derivatives of cart i. */
void cart_derivatives(const Chain *c, const double *y, int i, double *dy);

#endif
