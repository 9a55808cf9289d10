/* Shared by the files that make up the right-hand side; not part of the
 * model's interface. */
#ifndef LSS_CHAIN_INTERNAL_H
#define LSS_CHAIN_INTERNAL_H

#include "chain.h"
#include "lss_math.h"

/* Onset velocity in force: remembered since the contact closed, or, for a
 * contact that closes within the current step, its present closing rate;
 * never below the floor v_min. */
static inline double contact_vi(double remembered, double ddelta, double v_min) {
    if (remembered > 0) return remembered;
    return ddelta > v_min ? ddelta : v_min;
}

/* Smooth sign for rolling resistance: full value above 1 cm/s. */
static inline double smooth_sign(double v) { return v / sqrt(v * v + 1e-4); }

void joint_forces(Chain *c, const double *y, int j, double *p_damp);
void wheel_forces(Chain *c, const double *y, int i, double *p_damp, double *p_roll);
void drive_forces(Chain *c, const double *y, int i, double F_cmd);

/* Kinematics of cart i: rotation, world angular rate, projection onto the
 * track; returns the tangential speed of the axle. */
double cart_kinematics(Chain *c, const double *y, int i);
/* Newton-Euler: writes the derivatives of cart i. */
void cart_derivatives(const Chain *c, const double *y, int i, double *dy);

#endif
