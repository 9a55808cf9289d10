/* Forward sensitivities of the force channels by internal numerical
 * differentiation: for each parameter asked for (sensitivity.pK.vr), a
 * follower chain built with that parameter moved by its step takes the
 * leading chain's accepted steps (its relaxation at rest included) instead
 * of its own; the difference quotient of the two runs' outputs is the
 * derivative of the discrete solution the leader computes, smooth in the
 * parameter whatever the step-size control does. A follower costs one
 * right-hand side per stage of every accepted step, no rejected ones: about
 * what one simulation of its own costs, half a central difference's two.
 * Apart from the chain and the FMI glue: the glue owns one Sens per
 * instance and calls these at build, step, input and output time. */
#ifndef LSS_SENSITIVITY_H
#define LSS_SENSITIVITY_H

#include <stddef.h>

#include "chain.h"

#define SENS_MAX (VR_SENSITIVITY_P1_STEP - VR_SENSITIVITY_P1_VR)   /* sensitivity.n's largest value */
#define SENS_CHANNELS 7                                          /* the force channels, FORCE_CHANNELS' order */

typedef struct {
    int n;                     /* followers built */
    Chain *f[SENS_MAX];
} Sens;

/* The rules of sensitivity.n, .k.vr and .k.step on a parameter set: 0, or 1
 * with a message naming the variable and its value. */
int sens_check(const LSSParams *p, char *err, size_t errlen);
/* The parameters of follower k: p with its parameter moved by its step. */
void sens_params(const LSSParams *p, int k, LSSParams *out);
/* Creates the followers p asks for, as assembled (no relaxation). 0, or 1
 * with a message (then s holds none). */
int sens_create(Sens *s, const LSSParams *p, const char *resource_dir, const LSSAlloc *a, char *err, size_t errlen);
/* Creates the followers of a leader just built and relaxed at rest with its
 * trace on: each relaxes on the leader's steps, or takes the leader's
 * relaxed state where its parameter is one the relaxation ignores. */
int sens_build(Sens *s, const Chain *lead, const LSSParams *p, const char *resource_dir, const LSSAlloc *a,
               char *err, size_t errlen);
void sens_free(Sens *s);
/* The followers take the leader's steps recorded since its trace was last
 * started. 0, or 1 with a message naming the follower. */
int sens_step(Sens *s, const Chain *lead, const LSSParams *p, char *err, size_t errlen);
/* The tunable parameters and inputs, each follower's own parameter moved. */
void sens_set_inputs(Sens *s, const LSSParams *p);
/* sensitivity.pK.<channel> into out from the followers' outputs and the
 * leader's (lead_out, already in out for the force channels); 0 beyond
 * sensitivity.n. */
void sens_outputs(Sens *s, const LSSParams *p, LSSOutputs *out);

#endif
