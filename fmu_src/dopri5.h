/* Dormand-Prince 5(4) with PI step-size control, landing exactly on a given
 * end time; or (method DOPRI_DOP853) Dormand and Prince's 8th-order pair
 * DOP853 with the same landing and step control. Generic over the
 * right-hand side so that the chain and the single-impact harness of the
 * contact-law checks use the very same solver. */
#ifndef LSS_DOPRI5_H
#define LSS_DOPRI5_H

#include <stddef.h>

enum { DOPRI_DOPRI5 = 0, DOPRI_DOP853 = 1 };
#define DOPRI_NK 13              /* stage vectors: 7 for DOPRI5, 13 for DOP853 */

typedef struct {
    int n;
    int method;              /* DOPRI_DOPRI5 or DOPRI_DOP853 */
    void (*rhs)(void *ctx, double t, const double *y, double *dy);
    /* after each accepted step, with y the new state; returns 1 if it changed
     * y or the right-hand side (the FSAL derivative is then recomputed) */
    int (*accepted)(void *ctx, double t, double *y);
    void *ctx;
    const double *scale;   /* error scale per component: tol * (scale + rel * |y|) */
    const double *rel;
    double tol, h_max;
    double *k[DOPRI_NK], *ytmp, *ynew;  /* workspace, n each (k[7..12] for DOP853 only, else NULL) */
} Dopri;

typedef struct {
    double t, h, err_prev, h_last;
    int fsal_valid;          /* k[0] holds f(t, y) */
    long n_steps, n_rejected, n_rhs;
} DopriState;

void dopri_reset(DopriState *s, double t0, double h0);

/* Steps (accepted and rejected) one call of dopri_integrate may take beyond
 * twice the number h_max alone forces on the span, (t_end - t) / h_max:
 * legal runs need far fewer (docs/robustness.md, "Step limit"). */
#define DOPRI_MAX_STEPS 100000

/* Integrates y from s->t to t_end. 0: ok; 1: non-finite state or collapsed
 * step, a solver state that cannot advance (t or h not finite, h <= 0) or
 * more than DOPRI_MAX_STEPS steps (err filled). k[0] and the last
 * right-hand side evaluation are at (t_end, y) on return. */
int dopri_integrate(Dopri *d, DopriState *s, double *y, double t_end, char *err, size_t errlen);

/* Replays n accepted steps of another run of the same system: from s->t,
 * step i has size h[i] and lands at t[i] (the leader's times, so that both
 * runs stand at the same times bit for bit); no error control, the accepted
 * callback after each step as in dopri_integrate. A follower run on its
 * leader's steps differs from it only by what its parameters change: the
 * difference quotient of the two is the derivative of the discrete solution,
 * free of the step-size control's noise (internal numerical
 * differentiation). 0: ok; 1: a step turned non-finite (err filled). */
int dopri_replay(Dopri *d, DopriState *s, double *y, const double *h, const double *t, long n,
                 char *err, size_t errlen);

#endif
