/* Track geometry: element frames in closed form, projection of a point onto
 * the centreline, motor placement. See track.h for the representation. */
#include "track.h"

#include <stdio.h>
#include <string.h>

#include "lss_math.h"
#include "track_local.h"

#ifndef M_PI /* not declared under -std=c11 */
#define M_PI 3.14159265358979323846
#endif

/* Local frame rotation Rl and displacement pl after arc length sigma in an
 * element of turn rate k about unit axis u (element-frame coordinates). */
static void element_local(const TrackElement *e, double sigma, double *Rl, double *pl) {
    if (e->k == 0.0) {
        m3_identity(Rl);
        v3_set(pl, sigma, 0.0, 0.0);
        return;
    }
    const double *u = e->u;
    double th = e->k * sigma, S = sin(th), C1 = 1.0 - cos(th);
    /* [u]x and [u]x^2 */
    double K[9] = {0, -u[2], u[1], u[2], 0, -u[0], -u[1], u[0], 0};
    double K2[9];
    m3_mul(K2, K, K);
    for (int i = 0; i < 9; i++) Rl[i] = ((i % 4 == 0) ? 1.0 : 0.0) + S * K[i] + C1 * K2[i];
    /* int_0^sigma exp(x [w]) e_x dx = sigma e_x + (1-cos)/k [u]x e_x + (sigma - sin/k) [u]x^2 e_x */
    double a = C1 / e->k, b = sigma - S / e->k;
    pl[0] = sigma + a * K[3 * 0] + b * K2[0];
    pl[1] = a * K[3 * 1] + b * K2[3];
    pl[2] = a * K[3 * 2] + b * K2[6];
}

static void element_end(const TrackElement *e, double *c, double *R) {
    double Rl[9], pl[3], d[3];
    element_local(e, e->length, Rl, pl);
    m3_mulv(d, e->R0, pl);
    v3_add(c, e->c0, d);
    m3_mul(R, e->R0, Rl);
}

static void set_rate(TrackElement *e, double wx, double wy, double wz) {
    v3_set(e->w, wx, wy, wz);
    e->k = v3_norm(e->w);
    if (e->k > 0) v3_scale(e->u, e->w, 1.0 / e->k);
    else v3_set(e->u, 0, 0, 0);
}

/* The element's precomputed matrices (needs R0 and the rate). */
static void element_precompute(TrackElement *e) {
    const double *u = e->u;
    double K[9] = {0, -u[2], u[1], u[2], 0, -u[0], -u[1], u[0], 0};
    memcpy(e->K, K, sizeof K);
    m3_mul(e->K2, K, K);
    m3_mul(e->A, e->R0, e->K);
    m3_mul(e->B, e->R0, e->K2);
    e->planar = fabs(u[0]) <= 1e-12;
    e->ik = e->k > 0 ? 1.0 / e->k : 0.0;
    e->uy = u[1];
    e->uz = u[2];
}

static double m3_angle_between(const double *A, const double *B) {
    /* angle of A^T B */
    double tr = 0;
    for (int j = 0; j < 3; j++) tr += A[j] * B[j] + A[3 + j] * B[3 + j] + A[6 + j] * B[6 + j];
    double c = 0.5 * (tr - 1.0);
    if (c > 1) c = 1;
    if (c < -1) c = -1;
    /* acos loses precision near 1: use the Frobenius distance for small angles */
    double f2 = 0;
    for (int i = 0; i < 9; i++) f2 += (A[i] - B[i]) * (A[i] - B[i]);
    double small = 2.0 * asin(fmin(1.0, sqrt(f2 / 8.0)));
    return (c > 0.99) ? small : acos(c);
}

static int place_motors(Track *t, int n_motors, double motor_length, const LSSAlloc *a,
                        char *err, size_t errlen) {
    t->n_motors = n_motors;
    if (n_motors <= 0) return 0;
    double S = 0;
    for (int i = 0; i < t->n; i++)
        if (t->el[i].kind == EL_STRAIGHT) S += t->el[i].length;
    if (S <= 0) {
        snprintf(err, errlen, "the layout asks for %d linear motors but has no straight track", n_motors);
        return 1;
    }
    t->motor_s0 = a->calloc((size_t)n_motors, sizeof(double));
    t->motor_s1 = a->calloc((size_t)n_motors, sizeof(double));
    if (!t->motor_s0 || !t->motor_s1) {
        snprintf(err, errlen, "out of memory placing %d motors", n_motors);
        return 1;
    }
    /* Equally spaced along the concatenated straights, each centred in its share. */
    int el = 0;
    double acc = 0;
    for (int m = 0; m < n_motors; m++) {
        double u = (m + 0.5) * S / n_motors;
        while (el < t->n && (t->el[el].kind != EL_STRAIGHT || acc + t->el[el].length < u)) {
            if (t->el[el].kind == EL_STRAIGHT) acc += t->el[el].length;
            el++;
        }
        if (el >= t->n) el = t->n - 1;
        const TrackElement *e = &t->el[el];
        double half = 0.5 * fmin(motor_length, e->length);
        double centre = e->s0 + (u - acc);
        if (centre - half < e->s0) centre = e->s0 + half;
        if (centre + half > e->s0 + e->length) centre = e->s0 + e->length - half;
        t->motor_s0[m] = centre - half;
        t->motor_s1[m] = centre + half;
    }
    return 0;
}

int track_build(const LayoutSpec *spec, double motor_length, double tol_pos, double tol_ang,
                Track *t, const LSSAlloc *a, char *err, size_t errlen) {
    memset(t, 0, sizeof(*t));
    if (spec->n_el <= 0) {
        snprintf(err, errlen, "the layout has no track elements");
        return 1;
    }
    t->el = a->calloc((size_t)spec->n_el, sizeof(TrackElement));
    if (!t->el) {
        snprintf(err, errlen, "out of memory for %d track elements", spec->n_el);
        return 1;
    }
    t->n = spec->n_el;
    double c[3], R[9];
    v3_copy(c, spec->start);
    double ch = cos(spec->heading), sh = sin(spec->heading);
    double R0[9] = {ch, -sh, 0, sh, ch, 0, 0, 0, 1};
    memcpy(R, R0, sizeof R);
    double s = 0;
    for (int i = 0; i < t->n; i++) {
        const ElementSpec *es = &spec->el[i];
        TrackElement *e = &t->el[i];
        e->kind = es->kind;
        e->line = es->line;
        e->s0 = s;
        v3_copy(e->c0, c);
        memcpy(e->R0, R, sizeof R);
        double tz = R[6];  /* sine of the incline */
        double incline = asin(fmax(-1.0, fmin(1.0, tz)));
        switch (es->kind) {
        case EL_STRAIGHT:
            if (!(es->length > 0)) {
                snprintf(err, errlen, "line %d: straight length must be positive, got %g", es->line, es->length);
                return 1;
            }
            e->length = es->length;
            set_rate(e, 0, 0, 0);
            break;
        case EL_VCURVE:
            if (!(es->radius > 0) || !(es->angle != 0)) {
                snprintf(err, errlen, "line %d: vcurve needs a positive radius and a non-zero angle (got %g, %g)",
                         es->line, es->radius, es->angle);
                return 1;
            }
            e->length = es->radius * fabs(es->angle);
            set_rate(e, 0, -es->angle / e->length, 0);
            break;
        case EL_CURVE:
        case EL_SPIRAL: {
            if (!(es->radius > 0) || !(es->angle != 0)) {
                snprintf(err, errlen, "line %d: %s needs a positive radius and a non-zero sweep (got %g, %g)",
                         es->line, es->kind == EL_CURVE ? "curve" : "spiral", es->radius, es->angle);
                return 1;
            }
            double cg = cos(incline);
            if (cg < 1e-3) {
                snprintf(err, errlen, "line %d: a horizontal curve cannot start on vertical track", es->line);
                return 1;
            }
            e->length = es->radius * fabs(es->angle) / cg;
            double om = es->angle / e->length;  /* about world z */
            set_rate(e, om * R[6], om * R[7], om * R[8]);
            if (es->kind == EL_SPIRAL && es->has_rise) {
                double rise = es->radius * fabs(es->angle) * tan(incline);
                if (fabs(rise - es->rise) > 1e-3) {
                    double need = atan2(es->rise, es->radius * fabs(es->angle));
                    snprintf(err, errlen,
                             "line %d: spiral rise %.4g m needs an entry incline of %.6g deg, "
                             "the track arrives at %.6g deg (rise would be %.4g m)",
                             es->line, es->rise, need * 180 / M_PI, incline * 180 / M_PI, rise);
                    return 1;
                }
            }
            break;
        }
        default:
            snprintf(err, errlen, "line %d: unknown element kind %d", es->line, (int)es->kind);
            return 1;
        }
        element_precompute(e);
        element_end(e, c, R);
        s += e->length;
    }
    t->length = s;
    v3_sub(t->closure, c, spec->start);
    t->closure_angle = m3_angle_between(R, R0);
    double cp = v3_norm(t->closure);
    if (!(cp <= tol_pos) || !(t->closure_angle <= tol_ang)) {
        snprintf(err, errlen,
                 "the loop does not close: end point misses the start by %.6g m "
                 "(dx %.4g, dy %.4g, dz %.4g) and the direction by %.6g mrad "
                 "(limits %.3g m, %.3g mrad)",
                 cp, t->closure[0], t->closure[1], t->closure[2], t->closure_angle * 1e3,
                 tol_pos, tol_ang * 1e3);
        return 1;
    }
    return place_motors(t, spec->n_motors, motor_length, a, err, errlen);
}

void track_free(Track *t, const LSSAlloc *a) {
    if (t->el) a->free(t->el);
    if (t->motor_s0) a->free(t->motor_s0);
    if (t->motor_s1) a->free(t->motor_s1);
    memset(t, 0, sizeof(*t));
}

static double wrap(const Track *t, double s) {
    if (s >= 0 && s < t->length) return s;
    s = fmod(s, t->length);
    if (s < 0) s += t->length;
    if (s >= t->length) s = 0;
    return s;
}

double track_ds(const Track *t, double a, double b) {
    double L = t->length, d = b - a;
    if (!(fabs(d) < L)) d = fmod(d, L);  /* fmod(d, L) = d exactly when |d| < L */
    if (d > 0.5 * L) d -= L;
    if (d <= -0.5 * L) d += L;
    return d;
}

static int find_element(const Track *t, double s, int hint) {
    int i = (hint >= 0 && hint < t->n) ? hint : 0;
    /* walk a few elements from the hint (the usual case), else bisect */
    for (int k = 0; k < 3; k++) {
        if (s < t->el[i].s0) {
            if (i == 0) break;
            i--;
        } else if (s >= t->el[i].s0 + t->el[i].length && i < t->n - 1) {
            i++;
        } else {
            return i;
        }
    }
    int lo = 0, hi = t->n - 1;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (t->el[mid].s0 <= s) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

void track_frame(const Track *t, double s, int *hint, TrackFrame *f) {
    s = wrap(t, s);
    int i = find_element(t, s, hint ? *hint : 0);
    if (hint) *hint = i;
    const TrackElement *e = &t->el[i];
    double sigma = s - e->s0;
    if (e->k == 0.0) {
        memcpy(f->R, e->R0, sizeof f->R);
        for (int j = 0; j < 3; j++) f->c[j] = e->c0[j] + sigma * e->R0[3 * j];
    } else {
        double th = e->k * sigma, S = sin(th), C1 = 1.0 - cos(th);
        for (int j = 0; j < 9; j++) f->R[j] = e->R0[j] + S * e->A[j] + C1 * e->B[j];
        double a = C1 / e->k, b = sigma - S / e->k;
        for (int j = 0; j < 3; j++)
            f->c[j] = e->c0[j] + sigma * e->R0[3 * j] + a * e->A[3 * j] + b * e->B[3 * j];
    }
    v3_axpy(f->c, -s / t->length, t->closure);
    v3_copy(f->w, e->w);
    f->s = s;
    f->el = i;
}

double track_project(const Track *t, const double *p, double s_guess, int *hint, TrackFrame *f) {
    double s = wrap(t, s_guess);
    for (int it = 0; it < 8; it++) {
        track_frame(t, s, hint, f);
        double d[3], tt[3], dt[3], wt[3];
        v3_sub(d, p, f->c);
        m3_col(tt, f->R, 0);
        /* dt/ds = R (w x e_x) = R (0, w_z, -w_y) */
        v3_set(wt, 0, f->w[2], -f->w[1]);
        m3_mulv(dt, f->R, wt);
        double g = v3_dot(d, tt);
        double gp = 1.0 - v3_dot(d, dt);
        double step = g / (gp > 0.1 ? gp : 0.1);
        s = wrap(t, s + step);
        if (fabs(step) < 1e-11) {
            if (fabs(step) > 0) track_frame(t, s, hint, f);
            return f->s;
        }
    }
    track_frame(t, s, hint, f);
    return f->s;
}

/* --- local frames (track_local.h) ------------------------------------------- */

void track_base(const Track *t, double s, int *hint, TrackBase *b) {
    TrackFrame f;
    track_frame(t, s, hint, &f);
    memcpy(b->R, f.R, sizeof b->R);
    v3_copy(b->c, f.c);
    double cl[3];
    v3_scale(cl, t->closure, 1.0 / t->length);
    m3_tmulv(b->chat, f.R, cl);
    b->s = f.s;
    b->el = f.el;
    b->e = &t->el[f.el];
    b->lo = b->e->s0 - f.s;
    b->hi = b->e->s0 + b->e->length - f.s;
    b->ich0 = 1.0 / (1.0 - b->chat[0]);
    b->kind = b->e->k == 0.0 ? TL_STRAIGHT : (b->e->planar ? TL_PLANAR : TL_TWISTED);
}

void track_project_face(const Track *t, const TrackBase *b, const double *q, double ds_guess, int face,
                        double h, int *hint, LocalFrame *lf) {
    double p[3], s = b->s + ds_guess, dsum = 0.0;
    m3_mulv(p, b->R, q);
    v3_add(p, p, b->c);
    TrackFrame f;
    double d[3] = {0, 0, 0};
    for (int it = 0; it < 12; it++) {
        track_frame(t, s, hint, &f);
        double r[3];
        v3_sub(r, p, f.c);
        m3_tmulv(d, f.R, r);
        const double *w = f.w;
        double gp = 1.0 - (d[1] * w[2] - d[2] * w[1]);
        double step = (d[0] - tl_astar(face, h, d, w)) / (gp > 0.1 ? gp : 0.1);
        if (fabs(step) < 1e-12) break;
        s += step;
        dsum += step;
    }
    /* frame axes in base coordinates */
    double E[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            E[3 * i + j] = b->R[i] * f.R[j] + b->R[3 + i] * f.R[3 + j] + b->R[6 + i] * f.R[6 + j];
    memcpy(lf->E, E, sizeof E);
    v3_copy(lf->d, d);
    lf->ds = ds_guess + dsum;
    lf->w = t->el[f.el].w;
}
