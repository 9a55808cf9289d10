/* The right-hand side of the chain: kinematics of every cart with its
 * wheels against the track (and its running resistance), then the speed
 * controller (it needs the mean speed of all carts), the joints, the motors,
 * and Newton-Euler per cart. Cost is linear in the number of carts. */
#include "chain_simd.h"

static void chain_rhs_scalar(Chain *c, double t, const double *y, double *dy) {
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    int N = m->n_carts;
    (void)t;
    double sum_vt = 0.0, p_damp = 0.0, p_roll = 0.0;
    const double *gl = y + CART_NY * N;
    if (m->fx.oor_on) {  /* the out-of-round wheels' angle: distance rolled / r0 */
        sc->oor_x[0] = gl[G_ROLL_L];
        sc->oor_x[1] = gl[G_ROLL_R];
    }
    for (int i = 0; i < N; i++) {
        CartLocal L;
        sum_vt += cart_kinematics(c, y, i, &L);
        wheel_forces(c, i, &L, &p_damp, &p_roll);
        if (m->fx.resist_on) effects_resistance(c, i, &p_roll);
    }
    double v_mean = sum_vt / N, zdot;
    double F_cmd = drive_command(m, &c->st, v_mean, gl[G_INT], &zdot);
    sc->F_total = sc->P_total = 0.0;
    for (int j = 0; j < N; j++) joint_forces(c, y, j, &p_damp);
    for (int i = 0; i < N; i++) {
        drive_forces(c, y, i, F_cmd);
        cart_derivatives(c, y, i, dy);
    }
    double *dg = dy + CART_NY * N;
    dg[G_INT] = zdot;
    dg[G_WMOT] = sc->P_total;
    dg[G_WDAMP] = p_damp;
    dg[G_WROLL] = p_roll;
    dg[G_ROLL_L] = m->fx.oor_on ? sc->oor_rate[0] : 0.0;
    dg[G_ROLL_R] = m->fx.oor_on ? sc->oor_rate[1] : 0.0;
    sc->v_mean = v_mean;
    sc->F_cmd = F_cmd;
    sc->n_rhs++;
}

/* The path fixed at the instance's creation (chain_simd.h). */
void chain_rhs(Chain *c, double t, const double *y, double *dy) {
    switch (c->path) {
    case LSS_PATH_AVX512: chain_rhs_avx512(c, y, dy); break;
    case LSS_PATH_AVX2: chain_rhs_avx2(c, y, dy); break;
    default: chain_rhs_scalar(c, t, y, dy); break;
    }
}
