/* Cart-to-track contacts: the two driving wheels on the running surface
 * (vertical) and the two steering wheels against the guide faces (lateral),
 * each a Hunt-Crossley contact with rolling resistance mu_d * N opposing the
 * rolling direction.
 *
 * The running surface is the ruled surface c(s) + y n(s), each guide face
 * c(s) + h n(s) + z b(s). A wheel (a sphere of its radius) touches them at
 * the closest point, found per wheel: where the frame twists (w_x != 0, in a
 * helix) that point is not in the plane normal to the track through the
 * wheel, and the surface normal is not b or n. With the exact closest point
 * the force is the gradient of a potential and the chain conserves energy. */
#include "chain_internal.h"

/* Arc length of the closest point of a surface to p: the t-component a of
 * p - c(s) must equal the twist offset a*(s) (zero without twist). For the
 * running surface (h_face unused) a* = -z y w_x / (1 - y w_z); for a guide
 * face at lateral position h, a* = z w_x (y - h) / (1 - h w_z + z w_y). */
static void closest(const Track *tr, const double *p, double s_guess, int *hint, int face, double h,
                    TrackFrame *f, double *a, double *y, double *z) {
    double s = s_guess;
    for (int it = 0; it < 10; it++) {
        track_frame(tr, s, hint, f);
        double d[3], t[3], n[3], b[3], dt[3], wt[3];
        v3_sub(d, p, f->c);
        m3_col(t, f->R, 0);
        m3_col(n, f->R, 1);
        m3_col(b, f->R, 2);
        *a = v3_dot(d, t);
        *y = v3_dot(d, n);
        *z = v3_dot(d, b);
        const double *w = f->w;
        double astar = face ? *z * w[0] * (*y - h) / (1.0 - h * w[2] + *z * w[1])
                            : -*z * *y * w[0] / (1.0 - *y * w[2]);
        v3_set(wt, 0, w[2], -w[1]);
        m3_mulv(dt, f->R, wt);
        double gp = 1.0 - v3_dot(d, dt);
        double step = (*a - astar) / (gp > 0.1 ? gp : 0.1);
        if (fabs(step) < 1e-12) return;
        s += step;
    }
}

void wheel_forces(Chain *c, const double *y, int i, double *p_damp, double *p_roll) {
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    ChainScratch *sc = &c->sc;
    const ChainState *st = &c->st;
    const double *yi = y + CART_NY * i;
    const double *R = sc->R + 9 * i, *ww = sc->wworld + 3 * i;
    double *F = sc->F + 3 * i, *T = sc->T + 3 * i;
    int hint = sc->el[i];

    static const double side[N_WHEEL] = {1.0, -1.0, 1.0, -1.0};
    for (int k = 0; k < N_WHEEL; k++) {
        int drive = (k == W_DL || k == W_DR);
        double bc[3] = {g->x_axle, side[k] * (drive ? g->y_drive : g->y_steer), drive ? g->z_axle : g->z_steer};
        double rc[3], p[3], v[3], tmp[3];
        m3_mulv(rc, R, bc);
        v3_add(p, yi, rc);
        v3_cross(v, ww, rc);
        v3_add(v, v, yi + 7);
        TrackFrame f;
        double a, yl, zl, r, N[3], t[3], n[3], b[3];
        double h = side[k] * g->guide_half;
        closest(&m->track, p, sc->s[i], &hint, !drive, h, &f, &a, &yl, &zl);
        m3_col(t, f.R, 0);
        m3_col(n, f.R, 1);
        m3_col(b, f.R, 2);
        const double *w = f.w;
        double delta, ddelta, dir[3];
        if (drive) {
            /* normal of the running surface: (1 - y w_z) b - y w_x t */
            r = g->r_drive;
            v3_scale(N, b, 1.0 - yl * w[2]);
            v3_axpy(N, -yl * w[0], t);
            v3_scale(N, N, 1.0 / v3_norm(N));
            double D = a * v3_dot(t, N) + zl * v3_dot(b, N);
            delta = r - D;
            ddelta = -v3_dot(N, v);
            v3_copy(dir, N);
        } else {
            /* normal of the face at h: (1 - h w_z + z w_y) n + z w_x t, and
             * the wheel's clearance to it measured towards the track centre */
            r = g->r_steer;
            v3_scale(N, n, 1.0 - h * w[2] + zl * w[1]);
            v3_axpy(N, zl * w[0], t);
            v3_scale(N, N, 1.0 / v3_norm(N));
            double D = -side[k] * (a * v3_dot(t, N) + (yl - h) * v3_dot(n, N));
            delta = r - D;
            ddelta = side[k] * v3_dot(N, v);
            v3_scale(dir, N, -side[k]);
        }
        double vt = v3_dot(v, t);
        sc->wheel_speed[N_WHEEL * i + k] = vt / r;
        int slot = N_SLOT * i + SLOT_WHEEL + k;
        double fn = 0.0;
        if (delta > 0) {
            const ContactLaw *law = &m->law[drive ? CC_RW : CC_SW];
            double fe;
            fn = contact_force(law, delta, ddelta, contact_vi(st->v_onset[slot], ddelta, m->v_min), &fe);
            *p_damp += (fn - fe) * ddelta;
            double sg = smooth_sign(vt), froll = m->mu_roll * fn;
            *p_roll += froll * sg * vt;
            double fv[3], arm[3];
            v3_scale(fv, dir, fn);
            v3_axpy(fv, -froll * sg, t);
            /* applied at the contact point, a wheel radius from the centre */
            v3_copy(arm, rc);
            v3_axpy(arm, -r, dir);
            v3_add(F, F, fv);
            v3_cross(tmp, arm, fv);
            v3_add(T, T, tmp);
        }
        sc->delta[slot] = delta;
        sc->ddelta[slot] = ddelta;
        sc->force[slot] = fn;
    }
}
