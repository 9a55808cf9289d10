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
 * the force is the gradient of a potential and the chain conserves energy.
 *
 * The arc length s of the closest point solves a(s) = a*(s), a the
 * t-component of p - c(s) and a* the twist offset: zero without twist; for
 * the running surface a* = -z y w_x / (1 - y w_z), for a guide face at
 * lateral position h, a* = z w_x (y - h) / (1 - h w_z + z w_y)
 * (track_local.h, tl_astar). Everything here is in the coordinates of the
 * cart's track base (track_local.h); the search starts at the axle's arc
 * length and is closed-form on straights and plane arcs. */
#include "chain_internal.h"

void wheel_forces(Chain *c, int i, const CartLocal *L, double *p_damp, double *p_roll) {
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    ChainScratch *sc = &c->sc;
    CartScratch *cs = &sc->cart[i];
    const ChainState *st = &c->st;
    const TrackBase *b = &cs->base;
    const double *M = L->M;
    double Fl[3] = {0, 0, 0}, Tl[3] = {0, 0, 0};
    /* the body's x and z axis parts of the wheel centres, shared by each pair */
    double xs[3], xd[3];
    for (int j = 0; j < 3; j++) {
        xd[j] = M[3 * j] * g->x_axle + M[3 * j + 2] * g->z_axle;
        xs[j] = M[3 * j] * g->x_axle + M[3 * j + 2] * g->z_steer;
    }

    for (int k = 0; k < N_WHEEL; k++) {
        int drive = (k == W_DL || k == W_DR);
        double side = (k == W_SL || k == W_DL) ? 1.0 : -1.0;
        double yb = side * (drive ? g->y_drive : g->y_steer), r = drive ? g->r_drive : g->r_steer;
        const double *x0 = drive ? xd : xs;
        double rc[3], q[3], v[3];
        for (int j = 0; j < 3; j++) rc[j] = x0[j] + M[3 * j + 1] * yb;
        v3_add(q, L->q, rc);
        v3_cross(v, L->om, rc);
        v3_add(v, v, L->v);
        double h = side * g->guide_half;
        int face = drive ? TL_RUNNING : TL_GUIDE;
        LocalFrame f;
        if (!tl_project(b, q, L->axle.ds, face, h, &f))
            track_project_face(&m->track, b, q, L->axle.ds, face, h, &cs->el, &f);
        const double *E = f.E, *d = f.d, *w = f.w;
        double vf[3], Nf[3], delta, ddelta, dir[3];
        m3_tmulv(vf, E, v);
        if (drive) {
            /* normal of the running surface: (1 - y w_z) b - y w_x t */
            if (w[0] == 0.0) {
                v3_set(Nf, 0.0, 0.0, 1.0);
            } else {
                v3_set(Nf, -d[1] * w[0], 0.0, 1.0 - d[1] * w[2]);
                v3_scale(Nf, Nf, 1.0 / v3_norm(Nf));
            }
            delta = r - (d[0] * Nf[0] + d[2] * Nf[2]);
            ddelta = -v3_dot(Nf, vf);
            v3_copy(dir, Nf);
        } else {
            /* normal of the face at h: (1 - h w_z + z w_y) n + z w_x t, and
             * the wheel's clearance to it measured towards the track centre */
            if (w[0] == 0.0) {
                v3_set(Nf, 0.0, 1.0, 0.0);
            } else {
                v3_set(Nf, d[2] * w[0], 1.0 - h * w[2] + d[2] * w[1], 0.0);
                v3_scale(Nf, Nf, 1.0 / v3_norm(Nf));
            }
            delta = r + side * (d[0] * Nf[0] + (d[1] - h) * Nf[1]);
            ddelta = side * v3_dot(Nf, vf);
            v3_scale(dir, Nf, -side);
        }
        double vt = vf[0];
        cs->wheel_speed[k] = vt / r;
        int slot = N_SLOT * i + SLOT_WHEEL + k;
        double fn = 0.0;
        if (delta > 0) {
            const ContactLaw *law = &m->law[drive ? CC_RW : CC_SW];
            double fe;
            fn = contact_force(law, delta, ddelta, contact_vi(st->v_onset[slot], ddelta, m->v_min), &fe);
            *p_damp += (fn - fe) * ddelta;
            double sg = smooth_sign(vt), froll = m->mu_roll * fn;
            *p_roll += froll * sg * vt;
            /* force in the frame, then in base coordinates */
            double ff[3], fv[3], db[3], arm[3], tmp[3];
            v3_scale(ff, dir, fn);
            ff[0] -= froll * sg;
            m3_mulv(fv, E, ff);
            m3_mulv(db, E, dir);
            /* applied at the contact point, a wheel radius from the centre */
            v3_copy(arm, rc);
            v3_axpy(arm, -r, db);
            v3_add(Fl, Fl, fv);
            v3_cross(tmp, arm, fv);
            v3_add(Tl, Tl, tmp);
        }
        sc->delta[slot] = delta;
        sc->ddelta[slot] = ddelta;
        sc->force[slot] = fn;
    }
    double tmp[3];
    m3_mulv(tmp, b->R, Fl);
    v3_add(cs->F, cs->F, tmp);
    m3_mulv(tmp, b->R, Tl);
    v3_add(cs->T, cs->T, tmp);
}
