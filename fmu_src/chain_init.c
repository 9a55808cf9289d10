/* The initial configuration: the chain assembled into the track.
 *
 * Carts are placed one after the other so that each cart's rear joint meets
 * the front joint of the cart behind and its axle sits on the centreline at
 * the static wheel deflection. The assembled joint-to-joint length p' that
 * closes the loop is found by a secant iteration; the carts are then made
 * shorter by d/N each (d the pretension), which stretches every joint by d/N
 * and preloads it. Every cart starts at the chain speed with the track's turn
 * rate, and the integrator of the speed controller starts at the thrust that
 * balances the rolling (and running, effects.c) resistance, so that the start
 * transient is short. Carts of other masses (effects.mass.*) are assembled at
 * the nominal wheel deflection and settle in the first tenths of a second. */
#include <stdio.h>
#include <string.h>

#include "rhs_shared.h"

typedef struct {
    const Track *track;
    double h_axle;       /* axle height above the running surface */
} Assembly;

static void axle_target(const Assembly *as, double s, int *hint, double *A, TrackFrame *f) {
    track_frame(as->track, s, hint, f);
    double b[3];
    m3_col(b, f->R, 2);
    v3_copy(A, f->c);
    v3_axpy(A, as->h_axle, b);
}

/* Orientation without roll (the track has no banking): yaw and pitch such
 * that the body vector e (unit, in the x-z plane) points along the world
 * vector u. The body y axis stays horizontal. */
static void orient(double *R, const double *e, const double *u) {
    double yaw = atan2(u[1], u[0]);
    double elev = asin(fmax(-1.0, fmin(1.0, u[2]))) - atan2(e[2], e[0]);
    double cy = cos(yaw), sy = sin(yaw), cg = cos(elev), sg = sin(elev);
    /* Rz(yaw) * [x -> (cos g, 0, sin g)] */
    double Rz[9] = {cy, -sy, 0, sy, cy, 0, 0, 0, 1}, Ry[9] = {cg, 0, -sg, 0, 1, 0, sg, 0, cg};
    m3_mul(R, Rz, Ry);
}

/* March N carts with assembled pitch p from the rear joint J0 of cart 0,
 * whose axle sits at s = 0. Returns the closure miss along the start tangent
 * and the front joint of the last cart in JN (cart 0's axle at s_start). Fills s, R (9N) and J (3(N+1))
 * when given. An error in J0 shrinks by a factor |1 - p/ell| ~ 0.2 per cart,
 * so JN hardly depends on it: J0 is found by a fixed point. */
static double march(const Assembly *as, const CartGeometry *g, int N, double p, double s_start,
                    const double *J0, double *JN, double *s_out, double *R_out, double *J_out) {
    double dx = g->x_axle + 0.5 * p, dz = g->z_axle - g->z_joint;
    double ell = sqrt(dx * dx + dz * dz);
    double e[3] = {dx / ell, 0.0, dz / ell};
    int hint = 0;
    TrackFrame f;
    double A[3], J[3], t0[3], R[9];
    axle_target(as, s_start, &hint, A, &f);
    m3_col(t0, f.R, 0);
    v3_copy(J, J0);
    double s = s_start, L = as->track->length;
    for (int i = 0; i < N; i++) {
        if (i > 0) {
            /* the axle point at distance ell from J, ahead of the previous one */
            s += p;
            for (int it = 0; it < 50; it++) {
                double d[3], t[3];
                axle_target(as, s, &hint, A, &f);
                v3_sub(d, A, J);
                m3_col(t, f.R, 0);
                double r = v3_norm(d), dr = v3_dot(d, t) / (r > 1e-12 ? r : 1e-12);
                double step = (r - ell) / (dr > 0.2 ? dr : 0.2);
                s -= step;
                if (fabs(step) < 1e-13 * (1.0 + L)) break;
            }
            axle_target(as, s, &hint, A, &f);
        }
        double u[3];
        v3_sub(u, A, J);
        v3_scale(u, u, 1.0 / v3_norm(u));
        orient(R, e, u);
        if (s_out) s_out[i] = f.s;
        if (R_out) memcpy(R_out + 9 * i, R, sizeof R);
        if (J_out) v3_copy(J_out + 3 * i, J);
        double px[3] = {p, 0, 0}, wp[3];
        m3_mulv(wp, R, px);
        v3_add(J, J, wp);
    }
    if (J_out) v3_copy(J_out + 3 * N, J);
    v3_copy(JN, J);
    double miss[3];
    v3_sub(miss, J, J0);
    return v3_dot(miss, t0);
}

/* The rear joint of cart 0 consistent with a closing joint JN: on the sphere
 * of radius ell around cart 0's axle, towards JN. */
static void start_joint(const Assembly *as, const CartGeometry *g, double p, double s_start, const double *JN,
                        double *J0) {
    double dx = g->x_axle + 0.5 * p, dz = g->z_axle - g->z_joint, ell = sqrt(dx * dx + dz * dz);
    TrackFrame f;
    double A[3], d[3];
    axle_target(as, s_start, NULL, A, &f);
    v3_sub(d, JN, A);
    v3_scale(d, d, ell / v3_norm(d));
    v3_add(J0, A, d);
}

int chain_initial_state(Chain *c, double v0, char *err, size_t errlen) {
    ChainModel *m = &c->m;
    ChainState *st = &c->st;
    CartGeometry *g = &m->g;
    int N = m->n_carts;
    const LSSAlloc *a = &m->alloc;
    double delta_static = pow(0.5 * g->mass * m->gravity / m->law[CC_RW].K, 1.0 / m->law[CC_RW].n);
    Assembly as = {&m->track, g->r_drive - delta_static};
    double s0 = m->s_start;   /* cart 0's axle, arc length */

    /* secant on the assembled pitch, fixed point on the start joint */
    double p0 = m->track.length / N, p1 = p0 * (1 + 1e-3), J0[3], JN[3];
    {
        TrackFrame f;
        double A[3], t[3];
        axle_target(&as, s0, NULL, A, &f);
        m3_col(t, f.R, 0);
        double dx = g->x_axle + 0.5 * p0;
        v3_copy(J0, A);
        v3_axpy(J0, -dx, t);  /* first guess: behind the axle along the tangent */
    }
    double f0 = march(&as, g, N, p0, s0, J0, JN, NULL, NULL, NULL);
    start_joint(&as, g, p0, s0, JN, J0);
    double f1 = march(&as, g, N, p1, s0, J0, JN, NULL, NULL, NULL);
    for (int it = 0; it < 60; it++) {
        start_joint(&as, g, p1, s0, JN, J0);
        if (fabs(f1) <= 1e-11 * m->track.length && it > 1) break;
        if (f1 == f0) break;
        double p2 = p1 - f1 * (p1 - p0) / (f1 - f0);
        p0 = p1; f0 = f1;
        p1 = p2;
        f1 = march(&as, g, N, p1, s0, J0, JN, NULL, NULL, NULL);
    }
    if (!isfinite(p1) || fabs(f1) > 1e-6 || p1 <= 0) {
        snprintf(err, errlen, "cannot assemble %d carts into the %.6g m track (closure miss %.3g m)",
                 N, m->track.length, f1);
        return 1;
    }
    /* poses at the start and shifted by +-eps along the track: the central
     * difference gives velocities that agree at every joint */
    const double eps = 1e-4;
    double *s = a->calloc((size_t)N * 3, sizeof(double));
    double *R = a->calloc((size_t)N * 27, sizeof(double));
    double *J = a->calloc((size_t)(N + 1) * 9, sizeof(double));
    if (!s || !R || !J) {
        if (s) a->free(s);
        if (R) a->free(R);
        if (J) a->free(J);
        snprintf(err, errlen, "out of memory assembling %d carts", N);
        return 1;
    }
    for (int k = 0; k < 3; k++) {
        double sh = s0 + (k == 0 ? 0.0 : (k == 1 ? eps : -eps)), J0k[3], JNk[3];
        v3_copy(J0k, J0);
        if (k > 0) {
            march(&as, g, N, p1, sh, J0, JNk, NULL, NULL, NULL);
            start_joint(&as, g, p1, sh, JNk, J0k);
        }
        march(&as, g, N, p1, sh, J0k, JNk, s + (size_t)N * k, R + (size_t)9 * N * k, J + (size_t)3 * (N + 1) * k);
    }
    double p = p1 - m->pretension / N;
    if (!(p > 0.5 * p1)) {
        snprintf(err, errlen, "chain.pretension = %g m is too large for %d carts", m->pretension, N);
        a->free(s); a->free(R); a->free(J);
        return 1;
    }
    g->pitch = p;
    g->plate_length = p1;
    for (int i = 0; i < N; i++) {
        double *yi = st->y + CART_NY * i, r[3][3];
        for (int k = 0; k < 3; k++) {
            /* CG: midway between the assembled joints, below the joint line */
            const double *Jk = J + (size_t)3 * (N + 1) * k, *Rk = R + (size_t)9 * N * k + 9 * i;
            double mid[3], off[3], bo[3] = {0, 0, -g->z_joint};
            v3_add(mid, Jk + 3 * i, Jk + 3 * (i + 1));
            v3_scale(mid, mid, 0.5);
            m3_mulv(off, Rk, bo);
            v3_add(r[k], mid, off);
        }
        const double *R0 = R + 9 * i, *Rp = R + (size_t)9 * N + 9 * i, *Rm = R + (size_t)18 * N + 9 * i;
        v3_copy(yi, r[0]);
        m3_to_quat(yi + 3, R0);
        for (int c3 = 0; c3 < 3; c3++) yi[7 + c3] = v0 * (r[1][c3] - r[2][c3]) / (2 * eps);
        /* angular velocity from Rp Rm^T = I + [2 eps w/v0]x + O(eps^2) */
        double D[9], Rmt[9], ww[3];
        for (int u = 0; u < 3; u++)
            for (int w = 0; w < 3; w++) Rmt[3 * u + w] = Rm[3 * w + u];
        m3_mul(D, Rp, Rmt);
        v3_set(ww, 0.5 * (D[7] - D[5]), 0.5 * (D[2] - D[6]), 0.5 * (D[3] - D[1]));
        v3_scale(ww, ww, v0 / (2 * eps));
        m3_tmulv(yi + 10, R0, ww);
        st->s_hint[i] = s[i];
    }
    a->free(s); a->free(R); a->free(J);
    double *gl = st->y + CART_NY * N;
    memset(gl, 0, sizeof(double) * N_GLOBAL);
    if (st->Ki > 0 && m->track.n_motors > 0) {
        double F = m->mu_roll * g->mass * m->gravity * N;
        if (m->fx.mass_on) {
            double M = 0.0;
            for (int i = 0; i < N; i++) M += m->mass[i];
            F = m->mu_roll * M * m->gravity;
        }
        if (m->fx.resist_on) F += N * (m->fx.c1 * v0 + m->fx.c2 * v0 * fabs(v0));  /* running resistance too */
        gl[G_INT] = F / (m->track.n_motors * st->Ki);
    }
    m->preload = m->law[CC_JA].K * contact_pow(fabs(m->pretension) / N, m->law[CC_JA].n);
    return 0;
}
