/* One cart as a free rigid body: kinematics of its points, its place on the
 * track, and the Newton-Euler equations. */
#include "rhs_shared.h"

double cart_kinematics(Chain *c, const double *y, int i, CartLocal *L) {
    const ChainModel *m = &c->m;
    CartScratch *cs = &c->sc.cart[i];
    const double *yi = y + CART_NY * i;
    quat_to_m3(cs->R, yi + 3);
    m3_mulv(cs->ww, cs->R, yi + 10);

    /* the base: the track frame where the axle was after the last accepted step */
    double sh = c->st.s_hint[i];
    if (!cs->base.e || cs->base_key != sh) {
        track_base(&m->track, sh, &cs->el, &cs->base);
        cs->base_key = sh;
    }
    const TrackBase *b = &cs->base;
    double r[3];
    m3_tmul(L->M, b->R, cs->R);
    v3_sub(r, yi, b->c);
    m3_tmulv(L->q, b->R, r);
    m3_tmulv(L->v, b->R, yi + 7);
    m3_mulv(L->om, L->M, yi + 10);

    /* the axle's normal-plane projection */
    const double *M = L->M;
    double xa = m->g.x_axle, za = m->g.z_axle, ra[3], qa[3], va[3];
    v3_set(ra, M[0] * xa + M[2] * za, M[3] * xa + M[5] * za, M[6] * xa + M[8] * za);
    v3_add(qa, L->q, ra);
    v3_cross(va, L->om, ra);
    v3_add(va, va, L->v);
    LocalFrame *af = &L->axle;
    if (!tl_project(b, qa, 0.0, TL_NORMAL, 0.0, af))
        track_project_face(&m->track, b, qa, 0.0, TL_NORMAL, 0.0, &cs->el, af);
    const double *E = af->E, *d = af->d, *w = af->w;
    double tl[3] = {E[0], E[3], E[6]};
    double vt = v3_dot(va, tl);
    double s = b->s + af->ds, L_tr = m->track.length;
    if (s >= L_tr) s -= L_tr;
    else if (s < 0.0) s += L_tr;
    cs->s = s;
    cs->sdot = vt / (1.0 - (d[1] * w[2] - d[2] * w[1]));
    cs->v_t = vt;
    m3_mulv(cs->t, b->R, tl);

    v3_set(cs->F, 0.0, 0.0, -m->mass[i] * m->gravity);
    v3_set(cs->T, 0.0, 0.0, 0.0);
    return vt;
}

void cart_derivatives(const Chain *c, const double *y, int i, double *dy) {
    const ChainModel *m = &c->m;
    const CartScratch *cs = &c->sc.cart[i];
    const double *yi = y + CART_NY * i;
    double *d = dy + CART_NY * i;
    const double *q = yi + 3, *v = yi + 7, *w = yi + 10;
    const double *I = m->inertia + 3 * i;
    d[0] = v[0]; d[1] = v[1]; d[2] = v[2];
    /* q' = q (x) (0, w) / 2 */
    d[3] = -0.5 * (q[1] * w[0] + q[2] * w[1] + q[3] * w[2]);
    d[4] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]);
    d[5] = 0.5 * (q[0] * w[1] + q[3] * w[0] - q[1] * w[2]);
    d[6] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]);
    const double *F = cs->F;
    double im = 1.0 / m->mass[i];
    d[7] = F[0] * im; d[8] = F[1] * im; d[9] = F[2] * im;
    double tb[3], Iw[3], gyro[3];
    m3_tmulv(tb, cs->R, cs->T);
    v3_set(Iw, I[0] * w[0], I[1] * w[1], I[2] * w[2]);
    v3_cross(gyro, w, Iw);
    d[10] = (tb[0] - gyro[0]) / I[0];
    d[11] = (tb[1] - gyro[1]) / I[1];
    d[12] = (tb[2] - gyro[2]) / I[2];
}
