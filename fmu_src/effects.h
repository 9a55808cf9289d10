/* The effects catalogue (issue 7, docs/effects.md): departures of a real
 * sorter from the ideal chain, each off by default. This header holds the
 * model's copy of the effect parameters, checked and precomputed once per
 * build (flags, so that the right-hand side pays nothing for an effect that
 * is off), and the small pure functions the physics files share. No global
 * state: everything lives in the Chain of an instance. */
#ifndef LSS_EFFECTS_H
#define LSS_EFFECTS_H

#include <math.h>
#include <stddef.h>

#include "lss_vars.h"

#define FX_N_SENSOR 7   /* transducer force channels, in the order of LSSOutputs */
#define FX_TWO_PI 6.283185307179586476925  /* M_PI is not declared under -std=c11 */

typedef struct {
    /* out-of-round driving wheels of one cart (wheels.c) */
    int oor_on, oor_cart, oor_k;
    double oor_a, oor_phase[2];       /* [0] left, [1] right */
    double oor_ir0;                   /* 1 / r0: theta = rolled distance / r0 */
    /* cosine bump on the driving-wheel running surface (wheels.c) */
    int surface_on;                   /* bump_on || oor_on: the running-surface geometry changes */
    int bump_on;
    double bump_H, bump_s, bump_half, bump_k;   /* k = 2 pi / l */
    /* joint play (joints.c); 0 leaves the joint as it was, bit for bit */
    double gap;
    /* motor thrust ripple (drive.c) */
    int ripple_on;
    double ripple_A, ripple_k, ripple_phase;    /* k = 2 pi / pitch */
    /* velocity-dependent running resistance (effects.c) */
    int resist_on;
    double c1, c2;
    /* the transducer's force sensors (chain_outputs.c) */
    int sensor_on;
    double gain[FX_N_SENSOR], offset[FX_N_SENSOR];
    /* unequal masses (chain.c, chain_init.c) */
    int mass_on;
} Effects;

/* Fills fx from checked parameters; checks what needs the chain (cart
 * index, bump position against the track length). 0 or a message. */
int effects_init(Effects *fx, const LSSParams *p, int n_carts, int transducer, double r_drive,
                 double track_length, char *err, size_t errlen);

/* Mass factor of cart i: the transducer's factor, or 1 + spread z_i. */
double effects_mass_factor(const LSSParams *p, int i, int transducer);

/* Standard normal z_i of (seed, i), deterministic and stateless (splitmix64
 * then Box-Muller; docs/effects.md gives the exact recipe). */
double effects_normal(int seed, int i);

/* Sensor model: output = (1 + g) F + o on the seven force channels. */
void effects_sensor(const Effects *fx, LSSOutputs *o);

/* Bump height h at arc length s (track of length L) and its slope dh/ds. */
static inline double effects_bump(const Effects *fx, double s, double L, double *dhds) {
    double x = s - fx->bump_s;
    /* the shortest way round the loop: a bump near s = 0 works from both sides */
    if (x > 0.5 * L) x -= L;
    else if (x < -0.5 * L) x += L;
    if (!(fabs(x) < fx->bump_half)) {
        *dhds = 0.0;
        return 0.0;
    }
    double ph = fx->bump_k * x;
    *dhds = -0.5 * fx->bump_H * fx->bump_k * sin(ph);
    return 0.5 * fx->bump_H * (1.0 + cos(ph));
}

/* Radius change a cos(k theta - phi) of out-of-round wheel `side` (0 left,
 * 1 right) at rolled distance x, and its derivative per metre rolled. */
static inline double effects_oor(const Effects *fx, int side, double x, double *drdx) {
    double th = fx->oor_k * x * fx->oor_ir0 - fx->oor_phase[side];
    *drdx = -fx->oor_a * fx->oor_k * fx->oor_ir0 * sin(th);
    return fx->oor_a * cos(th);
}

#endif
