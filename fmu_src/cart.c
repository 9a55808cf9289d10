/* One cart as a free rigid body: kinematics of its points, its place on the
 * track, and the Newton-Euler equations. */
#include "chain_internal.h"

double cart_kinematics(Chain *c, const double *y, int i) {
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    const double *yi = y + CART_NY * i;
    double *R = sc->R + 9 * i, *ww = sc->wworld + 3 * i;
    quat_to_m3(R, yi + 3);
    m3_mulv(ww, R, yi + 10);

    double ba[3] = {m->g.x_axle, 0.0, m->g.z_axle}, ra[3], pa[3], va[3];
    m3_mulv(ra, R, ba);
    v3_add(pa, yi, ra);
    v3_cross(va, ww, ra);
    v3_add(va, va, yi + 7);

    TrackFrame *f = &sc->frame[i];
    track_project(&m->track, pa, c->st.s_hint[i], &sc->el[i], f);
    double t[3], d[3], dt[3], wt[3];
    m3_col(t, f->R, 0);
    v3_sub(d, pa, f->c);
    v3_set(wt, 0, f->w[2], -f->w[1]);
    m3_mulv(dt, f->R, wt);
    double vt = v3_dot(va, t);
    sc->s[i] = f->s;
    sc->sdot[i] = vt / (1.0 - v3_dot(d, dt));
    sc->v_t[i] = vt;

    double *F = sc->F + 3 * i, *T = sc->T + 3 * i;
    v3_set(F, 0.0, 0.0, -m->g.mass * m->gravity);
    v3_set(T, 0.0, 0.0, 0.0);
    return vt;
}

void cart_derivatives(const Chain *c, const double *y, int i, double *dy) {
    const ChainModel *m = &c->m;
    const ChainScratch *sc = &c->sc;
    const double *yi = y + CART_NY * i;
    double *d = dy + CART_NY * i;
    const double *q = yi + 3, *v = yi + 7, *w = yi + 10;
    const double *I = m->g.inertia;
    d[0] = v[0]; d[1] = v[1]; d[2] = v[2];
    /* q' = q (x) (0, w) / 2 */
    d[3] = -0.5 * (q[1] * w[0] + q[2] * w[1] + q[3] * w[2]);
    d[4] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]);
    d[5] = 0.5 * (q[0] * w[1] + q[3] * w[0] - q[1] * w[2]);
    d[6] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]);
    const double *F = sc->F + 3 * i;
    double im = 1.0 / m->g.mass;
    d[7] = F[0] * im; d[8] = F[1] * im; d[9] = F[2] * im;
    double tb[3], Iw[3], gyro[3];
    m3_tmulv(tb, sc->R + 9 * i, sc->T + 3 * i);
    v3_set(Iw, I[0] * w[0], I[1] * w[1], I[2] * w[2]);
    v3_cross(gyro, w, Iw);
    d[10] = (tb[0] - gyro[0]) / I[0];
    d[11] = (tb[1] - gyro[1]) / I[1];
    d[12] = (tb[2] - gyro[2]) / I[2];
}
