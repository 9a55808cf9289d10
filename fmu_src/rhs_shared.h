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
