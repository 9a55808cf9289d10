/* Linear motors on the straights and the saturated PI speed controller.
 * A motor pushes the reaction plate under a cart in proportion to how much of
 * the motor the plate covers, so thrust is continuous in the cart position. */
#include <math.h>

#include "chain_internal.h"

static double overlap(double a0, double a1, double b0, double b1) {
    double lo = a0 > b0 ? a0 : b0, hi = a1 < b1 ? a1 : b1;
    return hi > lo ? hi - lo : 0.0;
}

double drive_overlap(const ChainModel *m, double s_plate) {
    const Track *t = &m->track;
    if (t->n_motors == 0) return 0.0;
    double half = 0.5 * m->g.plate_length;
    /* first motor starting after the plate centre, by bisection */
    int lo = 0, hi = t->n_motors;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (t->motor_s0[mid] <= s_plate) lo = mid + 1;
        else hi = mid;
    }
    double frac = 0.0;
    int few = t->n_motors <= 4;  /* then visit each motor once */
    int nm = t->n_motors;
    for (int d = few ? 0 : -2; d < (few ? nm : 2); d++) {
        int kk = few ? d : lo + d;
        if (kk < 0) kk += nm;  /* lo is in [0, nm], d in [-2, 1] */
        else if (kk >= nm) kk -= nm;
        double ml = t->motor_s1[kk] - t->motor_s0[kk];
        if (ml <= 0) continue;
        /* the motor's centre relative to the plate centre, wrapped */
        double rel = track_ds(t, s_plate, 0.5 * (t->motor_s0[kk] + t->motor_s1[kk]));
        if (fabs(rel) > half + ml) continue;
        frac += overlap(-half, half, rel - 0.5 * ml, rel + 0.5 * ml) / ml;
    }
    return frac;
}

double drive_command(const ChainModel *m, const ChainState *st, double v_mean, double z, double *zdot) {
    double e = st->v_ref - v_mean;
    double u = st->Kp * e + st->Ki * z;
    double F = u;
    *zdot = e;
    if (u > m->F_max) {
        F = m->F_max;
        if (e > 0) *zdot = 0.0;  /* conditional integration: no wind-up */
    } else if (u < -m->F_max) {
        F = -m->F_max;
        if (e < 0) *zdot = 0.0;
    }
    return F;
}

/* Thrust on cart i along the track tangent, at its motor point. */
void drive_forces(Chain *c, const double *y, int i, double F_cmd) {
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    CartScratch *cs = &sc->cart[i];
    if (m->track.n_motors == 0 || F_cmd == 0.0) return;
    double s_plate = cs->s - (m->g.x_axle - m->g.x_motor);
    double frac = drive_overlap(m, s_plate);
    if (frac <= 0) return;
    const double *yi = y + CART_NY * i;
    const double *R = cs->R, *ww = cs->ww;
    double bm[3] = {m->g.x_motor, 0.0, m->g.z_motor}, rm[3], v[3], fv[3], tmp[3];
    m3_mulv(rm, R, bm);
    v3_cross(v, ww, rm);
    v3_add(v, v, yi + 7);
    v3_scale(fv, cs->t, F_cmd * frac);
    v3_add(cs->F, cs->F, fv);
    v3_cross(tmp, rm, fv);
    v3_add(cs->T, cs->T, tmp);
    sc->F_total += F_cmd * frac;
    sc->P_total += v3_dot(fv, v);
}
