/* Cart-to-track contacts: the two driving wheels on the running surface
 * (vertical) and the two steering wheels against the guide faces (lateral),
 * each a Hunt-Crossley contact with rolling resistance mu_d * N opposing the
 * rolling direction. The track frame comes from the axle's projection; the
 * indentation rates include the motion of that frame along the track. */
#include "chain_internal.h"

void wheel_forces(Chain *c, const double *y, int i, double *p_damp, double *p_roll) {
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    ChainScratch *sc = &c->sc;
    const ChainState *st = &c->st;
    const double *yi = y + CART_NY * i;
    const double *R = sc->R + 9 * i, *ww = sc->wworld + 3 * i;
    const TrackFrame *f = &sc->frame[i];
    double t[3], n[3], b[3], dn[3], db[3], tmp[3];
    m3_col(t, f->R, 0);
    m3_col(n, f->R, 1);
    m3_col(b, f->R, 2);
    v3_set(tmp, -f->w[2], 0.0, f->w[0]);
    m3_mulv(dn, f->R, tmp);  /* dn/ds */
    v3_set(tmp, f->w[1], -f->w[0], 0.0);
    m3_mulv(db, f->R, tmp);  /* db/ds */
    double sdot = sc->sdot[i];
    double *F = sc->F + 3 * i, *T = sc->T + 3 * i;

    static const double side[N_WHEEL] = {1.0, -1.0, 1.0, -1.0};
    for (int k = 0; k < N_WHEEL; k++) {
        int drive = (k == W_DL || k == W_DR);
        double bc[3] = {g->x_axle, side[k] * (drive ? g->y_drive : g->y_steer), drive ? g->z_axle : g->z_steer};
        double rc[3], p[3], v[3], d[3];
        m3_mulv(rc, R, bc);
        v3_add(p, yi, rc);
        v3_cross(v, ww, rc);
        v3_add(v, v, yi + 7);
        v3_sub(d, p, f->c);
        double delta, ddelta, r, dir[3];
        if (drive) {
            r = g->r_drive;
            delta = r - v3_dot(d, b);
            ddelta = -v3_dot(v, b) - sdot * v3_dot(d, db);
            v3_copy(dir, b);
        } else {
            r = g->r_steer;
            double lat = v3_dot(d, n), latdot = v3_dot(v, n) + sdot * v3_dot(d, dn);
            delta = side[k] * lat + r - g->guide_half;
            ddelta = side[k] * latdot;
            v3_scale(dir, n, -side[k]);
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
