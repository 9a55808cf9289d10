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

/* One trial step of size h from (t, y) with k[0] = f(t, y); returns the error
 * norm (max norm; NaN/inf if the trial turned non-finite). */
static double trial(Dopri *d, const double *y, double t, double h) {
    int n = d->n;
    double **k = d->k, *yt = d->ytmp, *yn = d->ynew;
    for (int i = 0; i < n; i++) yt[i] = y[i] + h * a21 * k[0][i];
    d->rhs(d->ctx, t + c2 * h, yt, k[1]);
    for (int i = 0; i < n; i++) yt[i] = y[i] + h * (a31 * k[0][i] + a32 * k[1][i]);
    d->rhs(d->ctx, t + c3 * h, yt, k[2]);
    for (int i = 0; i < n; i++) yt[i] = y[i] + h * (a41 * k[0][i] + a42 * k[1][i] + a43 * k[2][i]);
    d->rhs(d->ctx, t + c4 * h, yt, k[3]);
    for (int i = 0; i < n; i++)
        yt[i] = y[i] + h * (a51 * k[0][i] + a52 * k[1][i] + a53 * k[2][i] + a54 * k[3][i]);
    d->rhs(d->ctx, t + c5 * h, yt, k[4]);
    for (int i = 0; i < n; i++)
        yt[i] = y[i] + h * (a61 * k[0][i] + a62 * k[1][i] + a63 * k[2][i] + a64 * k[3][i] + a65 * k[4][i]);
    d->rhs(d->ctx, t + h, yt, k[5]);
    for (int i = 0; i < n; i++)
        yn[i] = y[i] + h * (a71 * k[0][i] + a73 * k[2][i] + a74 * k[3][i] + a75 * k[4][i] + a76 * k[5][i]);
    d->rhs(d->ctx, t + h, yn, k[6]);
    double err = 0.0, tol = d->tol;
    for (int i = 0; i < n; i++) {
        double e = h * (e1 * k[0][i] + e3 * k[2][i] + e4 * k[3][i] + e5 * k[4][i] + e6 * k[5][i] + e7 * k[6][i]);
        double mag = fabs(y[i]) > fabs(yn[i]) ? fabs(y[i]) : fabs(yn[i]);
        double r = fabs(e) / (tol * (d->scale[i] + d->rel[i] * mag));
        if (!(r <= err)) err = r;  /* also propagates NaN */
    }
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
