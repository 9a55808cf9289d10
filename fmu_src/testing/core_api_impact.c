/* Single-impact harness for the contact laws: one body of mass m meets a
 * Hunt-Crossley contact F = K d^n (1 + chi(e) d'/v_i), clipped at 0, in one
 * degree of freedom (indentation d, closing rate d').
 *
 * It uses the chain's own pieces: the Dormand-Prince solver of dopri5.c,
 * contact_force() of contact.h, contact_vi() of rhs_shared.h (the onset
 * velocity in force), and the onset-memory rule of chain_step.c (after each
 * accepted step: a contact found closed that has no onset velocity yet gets
 * the closing rate interpolated linearly at the crossing of d = 0 within the
 * step, floored by v_min; an open contact forgets). So what this harness
 * measures is what a chain contact does, not what a clean re-implementation
 * would do.
 *
 * The body starts away from the contact (d < 0) approaching at v_i and is
 * followed until it has left the contact again; v_out / v_in is the
 * restitution the law really produces. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "rhs_shared.h"
#include "contact.h"
#include "core_api.h"
#include "dopri5.h"

enum { IMP_APPROACH = 0, IMP_CONTACT = 1, IMP_LEFT = 2 };

typedef struct {
    ContactLaw L;
    double m, v_min;
    /* contact memory, as the chain keeps it per contact slot */
    double v_onset, d_prev, dd_prev, t_prev;
    /* what is observed */
    int phase;
    double t_on, t_off, v_out, d_max, F_max, v_mem;
    double hist_t[3], hist_F[3];   /* the last three accepted points, for the peak force */
    int n_hist;
    double *trace;
    int trace_max, n_trace;
    int skipped;                   /* the contact happened between two accepted points */
    int onset_rule;                /* 0: the chain's (linear); 1: cubic Hermite (an alternative) */
} Impact;

static double impact_force(const Impact *im, double d, double dd) {
    if (!(d > 0)) return 0.0;
    double fe;
    return contact_force(&im->L, d, dd, contact_vi(im->v_onset, dd, im->v_min), &fe);
}

static void impact_rhs(void *ctx, double t, const double *y, double *dy) {
    const Impact *im = ctx;
    (void)t;
    dy[0] = y[1];
    dy[1] = -impact_force(im, y[0], y[1]) / im->m;
}

static void record(Impact *im, double t, const double *y, double F) {
    if (im->n_trace < im->trace_max) {
        double *r = im->trace + 4 * im->n_trace++;
        r[0] = t; r[1] = y[0]; r[2] = y[1]; r[3] = F;
    }
}

/* Peak of the parabola through three points (t, F), if it lies between the
 * outer two; otherwise the largest of the three. */
static double peak3(const double *t, const double *F) {
    double best = fmax(F[1], fmax(F[0], F[2]));
    double h0 = t[1] - t[0], h1 = t[2] - t[1];
    if (!(h0 > 0 && h1 > 0)) return best;
    double s0 = (F[1] - F[0]) / h0, s1 = (F[2] - F[1]) / h1;
    double a = (s1 - s0) / (h0 + h1);          /* F = F1 + s (t - t1) + a (t - t1)^2 */
    if (!(a < 0)) return best;
    double s = (s0 * h1 + s1 * h0) / (h0 + h1); /* slope at t1 */
    double tau = -s / (2 * a);
    if (tau < -h0 || tau > h1) return best;
    double p = F[1] + s * tau + a * tau * tau;
    return p > best ? p : best;
}

/* Largest value of the cubic Hermite interpolant of (d0, d0'), (d1, d1')
 * over a step of length h in which the rate changes sign from + to -. */
static double hermite_peak(double d0, double v0, double d1, double v1, double h) {
    /* dp/dt = v0 (1 - 4s + 3s^2) + v1 (3s^2 - 2s) + 6 D s (1 - s), D = (d1 - d0)/h */
    double D = (d1 - d0) / h;
    double a = 3 * v0 + 3 * v1 - 6 * D, b = -4 * v0 - 2 * v1 + 6 * D, c = v0;
    double s;
    if (fabs(a) < 1e-14 * (fabs(b) + fabs(c))) s = -c / b;
    else {
        double disc = b * b - 4 * a * c;
        if (disc < 0) return fmax(d0, d1);
        double q = -0.5 * (b + copysign(sqrt(disc), b));
        if (q == 0) return fmax(d0, d1);
        double r1 = q / a, r2 = c / q;
        s = (r1 >= 0 && r1 <= 1) ? r1 : r2;
    }
    if (!(s >= 0 && s <= 1)) return fmax(d0, d1);
    double h00 = (1 + 2 * s) * (1 - s) * (1 - s), h10 = s * (1 - s) * (1 - s);
    double h01 = s * s * (3 - 2 * s), h11 = s * s * (s - 1);
    return h00 * d0 + h10 * h * v0 + h01 * d1 + h11 * h * v1;
}

/* The crossing of zero of the cubic Hermite interpolant of (d0, d0'),
 * (d1, d1') over a step of length h (d0 < 0 < d1): the fraction *th of the
 * step (on entry: the linear guess) and the rate *v there. */
static void hermite_crossing(double d0, double v0, double d1, double v1, double h, double *th, double *v) {
    double lo = 0, hi = 1, s = *th;
    for (int it = 0; it < 60; it++) {
        double h00 = (1 + 2 * s) * (1 - s) * (1 - s), h10 = s * (1 - s) * (1 - s);
        double h01 = s * s * (3 - 2 * s), h11 = s * s * (s - 1);
        double p = h00 * d0 + h10 * h * v0 + h01 * d1 + h11 * h * v1;
        double dp = h * (v0 * (1 - 4 * s + 3 * s * s) + v1 * (3 * s * s - 2 * s)) + 6 * (d1 - d0) * s * (1 - s);
        if (p < 0) lo = s;
        else hi = s;
        double sn = dp > 0 ? s - p / dp : -1;
        if (!(sn > lo && sn < hi)) sn = 0.5 * (lo + hi);   /* safeguarded Newton */
        if (fabs(sn - s) < 1e-15) { s = sn; break; }
        s = sn;
    }
    *th = s;
    *v = v0 * (1 - 4 * s + 3 * s * s) + v1 * (3 * s * s - 2 * s) + 6 * (d1 - d0) / h * s * (1 - s);
}

static int impact_accepted(void *ctx, double t, double *y) {
    Impact *im = ctx;
    double d1 = y[0], dd1 = y[1], d0 = im->d_prev, dd0 = im->dd_prev;
    int changed = 0;
    /* --- the chain's rule (chain_step.c, update_contact_memory) --- */
    if (d1 > 0) {
        if (!(im->v_onset > 0)) {
            double th = (d0 < 0 && d1 > d0) ? d0 / (d0 - d1) : 1.0;
            double v = (1 - th) * dd0 + th * dd1;
            if (im->onset_rule == 1 && d0 < 0 && d1 > d0) hermite_crossing(d0, dd0, d1, dd1, t - im->t_prev, &th, &v);
            im->v_onset = v > im->v_min ? v : im->v_min;
            changed = 1;
            if (im->phase == IMP_APPROACH) {
                im->phase = IMP_CONTACT;
                im->t_on = im->t_prev + th * (t - im->t_prev);
                im->v_mem = im->v_onset;
            }
        }
    } else if (im->v_onset > 0) {
        im->v_onset = 0.0;
        changed = 1;
    }
    /* --- observation --- */
    if (im->phase == IMP_CONTACT && !(d1 > 0)) {
        double th = (d0 > 0 && d0 > d1) ? d0 / (d0 - d1) : 1.0;
        im->t_off = im->t_prev + th * (t - im->t_prev);
        im->v_out = -dd1;   /* free flight after the crossing: the rate is constant */
        im->phase = IMP_LEFT;
    } else if (im->phase == IMP_APPROACH && !(d1 > 0) && dd1 < 0) {
        im->skipped = 1;    /* turned back without a single accepted point in contact */
        im->phase = IMP_LEFT;
    }
    if (d1 > im->d_max) im->d_max = d1;
    if (dd0 > 0 && dd1 <= 0 && t > im->t_prev) {
        double p = hermite_peak(d0, dd0, d1, dd1, t - im->t_prev);
        if (p > im->d_max) im->d_max = p;
    }
    /* force at the new point, with the memory as it now stands */
    double F = impact_force(im, d1, dd1);
    if (im->n_hist == 3) {
        memmove(im->hist_t, im->hist_t + 1, 2 * sizeof(double));
        memmove(im->hist_F, im->hist_F + 1, 2 * sizeof(double));
        im->n_hist = 2;
    }
    im->hist_t[im->n_hist] = t;
    im->hist_F[im->n_hist++] = F;
    if (F > im->F_max) im->F_max = F;
    if (im->n_hist == 3 && im->hist_F[1] >= im->hist_F[0] && im->hist_F[1] >= im->hist_F[2] && im->hist_F[1] > 0) {
        double p = peak3(im->hist_t, im->hist_F);
        if (p > im->F_max) im->F_max = p;
    }
    record(im, t, y, F);
    im->d_prev = d1;
    im->dd_prev = dd1;
    im->t_prev = t;
    return changed;
}

static double opt(const double *opts, int nopts, int i) {
    return (opts && i < nopts) ? opts[i] : NAN;
}

int lss_impact_run(int law, double e, double K, double n, double m, double v_i, double v_min, double tol,
                   const double *opts, int nopts, double *out, int nout, double *trace, int trace_max,
                   char *err, int errlen) {
    size_t el = errlen > 0 ? (size_t)errlen : 0;
    for (int i = 0; i < nout; i++) out[i] = NAN;
    double chi = contact_chi(law, e);
    if (!isfinite(chi)) {
        snprintf(err, el, "no damping factor for law %d at e = %.17g (laws 1..6, e in (0, 1])", law, e);
        return 1;
    }
    const struct { const char *name; double v, lo, hi; } chk[] = {
        {"K", K, 0, 1e30}, {"n", n, 0.5, 4}, {"m", m, 0, 1e30}, {"v_i", v_i, 0, 1e6},
        {"v_min", v_min, 0, 1e6}, {"tol", tol, 0, 0.1}};
    for (size_t i = 0; i < sizeof chk / sizeof chk[0]; i++)
        if (!(chk[i].v > chk[i].lo && chk[i].v <= chk[i].hi)) {
            snprintf(err, el, "%s = %.17g must lie in (%g, %g]", chk[i].name, chk[i].v, chk[i].lo, chk[i].hi);
            return 1;
        }
    /* options: NaN (or not given) for the default */
    const char *oname[] = {"h_max", "scale_delta", "scale_rate", "rel_rate", "onset_rule", "gap"};
    double o[6];
    for (int i = 0; i < 6; i++) {
        o[i] = opt(opts, nopts, i);
        if (!isnan(o[i]) && !(isfinite(o[i]) && o[i] >= 0 && (i == 3 || i == 4 || o[i] > 0))) {
            snprintf(err, el, "option %s = %g must be finite and %s", oname[i], o[i], i == 3 || i == 4 ? ">= 0" : "> 0");
            return 1;
        }
    }
    if (!isnan(o[4]) && o[4] != 0 && o[4] != 1) {
        snprintf(err, el, "option onset_rule = %g must be 0 (the chain's) or 1 (cubic Hermite)", o[4]);
        return 1;
    }

    Impact im;
    memset(&im, 0, sizeof im);
    im.L.K = K;
    im.L.n = n;
    im.L.e = e;
    im.L.chi = chi;
    im.m = m;
    im.v_min = v_min;
    im.trace = trace;
    im.trace_max = trace ? trace_max : 0;
    im.onset_rule = isnan(o[4]) ? 0 : (int)o[4];

    /* natural scales: the elastic peak indentation and the time to cross it */
    double d_star = pow((n + 1) * m * v_i * v_i / (2 * K), 1 / (n + 1));
    double T = d_star / v_i;
    double scale[2] = {isnan(o[1]) ? d_star : o[1], isnan(o[2]) ? v_i : o[2]};
    double rel[2] = {0, isnan(o[3]) ? 0 : o[3]};
    double y[2] = {-(isnan(o[5]) ? 0.1 * d_star : o[5]), v_i};
    double k[7][2], ytmp[2], ynew[2];
    Dopri d;
    memset(&d, 0, sizeof d);
    d.n = 2;
    d.rhs = impact_rhs;
    d.accepted = impact_accepted;
    d.ctx = &im;
    d.scale = scale;
    d.rel = rel;
    d.tol = tol;
    d.h_max = isnan(o[0]) ? T : o[0];
    for (int i = 0; i < 7; i++) d.k[i] = k[i];
    d.ytmp = ytmp;
    d.ynew = ynew;
    DopriState s;
    dopri_reset(&s, 0.0, 1e-3 * T);
    im.d_prev = y[0];
    im.dd_prev = y[1];
    im.t_prev = 0.0;
    record(&im, 0.0, y, 0.0);

    char msg[256];
    double t_end = 0.0, t_limit = -y[0] / v_i + 1e4 * T;
    while (im.phase != IMP_LEFT) {
        if (t_end > t_limit) {
            snprintf(err, el, "the body had not left the contact after %g natural times (law %d, e = %g)",
                     1e4, law, e);
            return 1;
        }
        t_end += T;
        if (dopri_integrate(&d, &s, y, t_end, msg, sizeof msg)) {
            snprintf(err, el, "solver failed: %s", msg);
            return 1;
        }
    }
    if (im.skipped) {
        snprintf(err, el, "the contact fell between two accepted steps: lower h_max or tol");
        return 1;
    }
    double res[] = {
        im.v_out / v_i,          /* 0 effective restitution */
        v_i,                     /* 1 v_in */
        im.v_out,                /* 2 v_out */
        im.F_max,                /* 3 peak force */
        im.t_off - im.t_on,      /* 4 contact duration */
        im.d_max,                /* 5 largest indentation at an accepted point */
        chi,                     /* 6 chi(e) of the law */
        (double)s.n_steps,       /* 7 */
        (double)s.n_rejected,    /* 8 */
        (double)s.n_rhs,         /* 9 */
        im.t_on,                 /* 10 onset time (interpolated) */
        (double)im.n_trace,      /* 11 trace rows written */
        im.v_mem,                /* 12 onset velocity the contact remembered */
    };
    for (int i = 0; i < nout && i < (int)(sizeof res / sizeof res[0]); i++) out[i] = res[i];
    return 0;
}

double lss_contact_chi(int law, double e) { return contact_chi(law, e); }
double lss_contact_chi_exact(double e) { return contact_chi_exact(e); }
double lss_contact_restitution_of_chi(double chi) { return contact_restitution_of_chi(chi); }
