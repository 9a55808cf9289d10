/* Dormand-Prince 5(4) with PI step-size control (used inside fmi2DoStep).
 *
 * Why not Cash-Karp (the paper's pair): both cost six right-hand sides per
 * step, but Dormand-Prince has the smaller error constants and the last stage
 * is the next step's first (FSAL), so an accepted step costs six evaluations,
 * not seven. The error is measured in the max norm: with hundreds of carts an
 * RMS norm would let one cart's impact drown in the quiet of the others.
 * Steps are cut to land exactly on the end time; the step-size proposal
 * survives the cut, so communication points cost no accuracy and few steps. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "dopri5.h"

static const double
    c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9,
    a21 = 1.0 / 5,
    a31 = 3.0 / 40, a32 = 9.0 / 40,
    a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9,
    a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561, a54 = -212.0 / 729,
    a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176, a65 = -5103.0 / 18656,
    a71 = 35.0 / 384, a73 = 500.0 / 1113, a74 = 125.0 / 192, a75 = -2187.0 / 6784, a76 = 11.0 / 84,
    e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200, e6 = 22.0 / 525,
    e7 = -1.0 / 40;

#define H_MIN 1e-9

void dopri_reset(DopriState *s, double t0, double h0) {
    memset(s, 0, sizeof(*s));
    s->t = t0;
    s->h = h0;
    s->err_prev = 1e-4;
}

/* The stage combinations run over an even count (m = n & ~1) with
 * restrict arguments so that -O2 vectorises them (two doubles per SSE2
 * instruction); the odd last component, if any, follows in scalar code.
 * Where GCC builds for x86-64 Linux they are also compiled for AVX2 and
 * AVX-512 (target_clones: the dynamic loader picks one per process from
 * the CPU, an ifunc, so there is no dispatch state of ours); each lane does
 * the same arithmetic in the same order, so every clone gives the same bits. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && !defined(LSS_NO_SIMD)
#define STAGE_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define STAGE_CLONES
#endif
STAGE_CLONES static void comb1(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + b0 * k0[i];
    for (int i = m; i < n; i++) o[i] = y[i] + b0 * k0[i];
}
STAGE_CLONES static void comb2(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i]);
}
STAGE_CLONES static void comb3(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1, double b2, const double *restrict k2) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i]);
}
STAGE_CLONES static void comb4(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1, double b2, const double *restrict k2, double b3,
                  const double *restrict k3) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i]);
}
STAGE_CLONES static void comb5(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1, double b2, const double *restrict k2, double b3,
                  const double *restrict k3, double b4, const double *restrict k4) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i] + b4 * k4[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i] + b4 * k4[i]);
}
/* |sum g_j k_j| / (tol (scale + rel max(|y|, |y_new|))) per component */
STAGE_CLONES static void err_ratio(int n, double *restrict o, const double *restrict y, const double *restrict yn,
                      const double *restrict sc, const double *restrict rl, double tol, const double *g,
                      const double *restrict k0, const double *restrict k2, const double *restrict k3,
                      const double *restrict k4, const double *restrict k5, const double *restrict k6) {
    const double g1 = g[0], g3 = g[1], g4 = g[2], g5 = g[3], g6 = g[4], g7 = g[5];
    int m = n & ~1;
    for (int i = 0; i < m; i++) {
        double e = g1 * k0[i] + g3 * k2[i] + g4 * k3[i] + g5 * k4[i] + g6 * k5[i] + g7 * k6[i];
        double ay = fabs(y[i]), an = fabs(yn[i]);
        o[i] = fabs(e) / (tol * (sc[i] + rl[i] * (ay > an ? ay : an)));
    }
    for (int i = m; i < n; i++) {
        double e = g1 * k0[i] + g3 * k2[i] + g4 * k3[i] + g5 * k4[i] + g6 * k5[i] + g7 * k6[i];
        double ay = fabs(y[i]), an = fabs(yn[i]);
        o[i] = fabs(e) / (tol * (sc[i] + rl[i] * (ay > an ? ay : an)));
    }
}

/* One trial step of size h from (t, y) with k[0] = f(t, y); returns the error
 * norm (max norm; NaN/inf if the trial turned non-finite). */
static double trial(Dopri *d, const double *y, double t, double h) {
    int n = d->n;
    double **k = d->k, *yt = d->ytmp, *yn = d->ynew;
    comb1(n, yt, y, h * a21, k[0]);
    d->rhs(d->ctx, t + c2 * h, yt, k[1]);
    comb2(n, yt, y, h * a31, k[0], h * a32, k[1]);
    d->rhs(d->ctx, t + c3 * h, yt, k[2]);
    comb3(n, yt, y, h * a41, k[0], h * a42, k[1], h * a43, k[2]);
    d->rhs(d->ctx, t + c4 * h, yt, k[3]);
    comb4(n, yt, y, h * a51, k[0], h * a52, k[1], h * a53, k[2], h * a54, k[3]);
    d->rhs(d->ctx, t + c5 * h, yt, k[4]);
    comb5(n, yt, y, h * a61, k[0], h * a62, k[1], h * a63, k[2], h * a64, k[3], h * a65, k[4]);
    d->rhs(d->ctx, t + h, yt, k[5]);
    comb5(n, yn, y, h * a71, k[0], h * a73, k[2], h * a74, k[3], h * a75, k[4], h * a76, k[5]);
    d->rhs(d->ctx, t + h, yn, k[6]);
    const double g[6] = {h * e1, h * e3, h * e4, h * e5, h * e6, h * e7};
    err_ratio(n, yt, y, yn, d->scale, d->rel, d->tol, g, k[0], k[2], k[3], k[4], k[5], k[6]);
    double err = 0.0;
    for (int i = 0; i < n; i++)
        if (!(yt[i] <= err)) err = yt[i];  /* also propagates NaN */
    return err;
}

int dopri_integrate(Dopri *d, DopriState *st, double *y, double t_end, char *err, size_t errlen) {
    int n = d->n;
    double span = fabs(t_end) + 1.0;
    while (st->t < t_end - 1e-13 * span) {
        if (!st->fsal_valid) {
            d->rhs(d->ctx, st->t, y, d->k[0]);
            st->n_rhs++;
            st->fsal_valid = 1;
        }
        double h_prop = st->h > d->h_max ? d->h_max : st->h;
        double h = h_prop;
        int last = 0;
        if (st->t + h >= t_end - 1e-13 * span) {
            h = t_end - st->t;
            last = 1;
        }
        for (;;) {
            double e = trial(d, y, st->t, h);
            st->n_rhs += 6;
            if (!isfinite(e)) {
                st->n_rejected++;
                h *= 0.25;
                last = 0;
                if (h < H_MIN) {
                    snprintf(err, errlen, "the state turned non-finite at t = %.9g s and step sizes "
                             "down to %g s could not avoid it", st->t, H_MIN);
                    return 1;
                }
                continue;
            }
            /* Hairer's PI controller (beta = 0.04) */
            double fac11 = pow(e > 1e-10 ? e : 1e-10, 0.17);
            if (e <= 1.0) {
                double fac = fac11 / pow(st->err_prev, 0.04) / 0.9;
                fac = fac < 0.2 ? 0.2 : (fac > 10.0 ? 10.0 : fac);
                double h_new = h / fac;
                st->err_prev = e > 1e-4 ? e : 1e-4;
                st->t = last ? t_end : st->t + h;
                memcpy(y, d->ynew, sizeof(double) * (size_t)n);
                double *tmp = d->k[0];
                d->k[0] = d->k[6];
                d->k[6] = tmp;
                st->n_steps++;
                st->h_last = h;
                st->h = last ? fmax(fmin(h_new, h_prop), h) : h_new;
                if (d->accepted && d->accepted(d->ctx, st->t, y)) st->fsal_valid = 0;
                break;
            }
            double fac = fac11 / 0.9;
            h /= fac > 5.0 ? 5.0 : fac;
            last = 0;
            st->n_rejected++;
            if (h < H_MIN) {
                snprintf(err, errlen, "step size collapsed below %g s at t = %.9g s", H_MIN, st->t);
                return 1;
            }
        }
    }
    if (!st->fsal_valid) {  /* leave k[0] and the last evaluation at the final state */
        d->rhs(d->ctx, st->t, y, d->k[0]);
        st->n_rhs++;
        st->fsal_valid = 1;
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(y[i])) {
            snprintf(err, errlen, "state %d turned non-finite at t = %.9g s", i, st->t);
            return 1;
        }
    return 0;
}
