/* Cart-to-cart contacts: the spherical joint between cart j's front joint and
 * cart j+1's rear joint, as an axial and a radial Hunt-Crossley contact in the
 * frame of cart j. The forces derive from a potential that depends on cart
 * j's orientation too, so the matching torque is applied: the chain then
 * conserves energy exactly when undamped.
 *
 * Joint play (effects.joint_clearance.gap) is a dead band: both penetrations
 * are reduced by the gap before the contact law sees them. The potential is
 * then K (delta - gap)^(n+1)/(n+1) of the same coordinates, so the forces
 * and the frame torque keep their form and the joint stays conservative. */
#include "rhs_shared.h"

void joint_forces(Chain *c, const double *y, int j, double *p_damp) {
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    ChainState *st = &c->st;
    const CartGeometry *g = &m->g;
    int A = j, B = (j + 1 == m->n_carts) ? 0 : j + 1;
    const double *yA = y + CART_NY * A, *yB = y + CART_NY * B;
    CartScratch *cA = &sc->cart[A], *cB = &sc->cart[B];
    const double *RA = cA->R, *RB = cB->R;
    const double *wA = cA->ww, *wB = cB->ww;

    double bF[3] = {0.5 * g->pitch, 0.0, g->z_joint}, bR[3] = {-0.5 * g->pitch, 0.0, g->z_joint};
    double rF[3], rR[3], pF[3], pR[3], vF[3], vR[3], tmp[3];
    m3_mulv(rF, RA, bF);
    m3_mulv(rR, RB, bR);
    v3_add(pF, yA, rF);
    v3_add(pR, yB, rR);
    v3_cross(tmp, wA, rF);
    v3_add(vF, yA + 7, tmp);
    v3_cross(tmp, wB, rR);
    v3_add(vR, yB + 7, tmp);

    double D[3], Dd[3], a[3], adot[3];
    v3_sub(D, pR, pF);
    v3_sub(Dd, vR, vF);
    m3_col(a, RA, 0);
    v3_cross(adot, wA, a);
    double Da = v3_dot(D, a);
    double Dadot = v3_dot(Dd, a) + v3_dot(D, adot);
    if (A == m->transducer) sc->joint_v_axial = -Dadot;  /* closing positive: Da grows as the joint opens */
    double Dr[3];
    v3_copy(Dr, D);
    v3_axpy(Dr, -Da, a);
    double rho = v3_norm(Dr);

    int sa = N_SLOT * A + SLOT_JA, sr = N_SLOT * A + SLOT_JR;
    double sgn = Da >= 0 ? 1.0 : -1.0, gap = m->fx.gap;

    /* axial; a penetration below the play is an open contact (negative
     * delta, so the contact memory sees the closing) */
    double da = fabs(Da) - gap, dda = sgn * Dadot, fa = 0, fea = 0;
    if (da > 0) {
        fa = contact_force(&m->law[CC_JA], da, dda, contact_vi(st->v_onset[sa], dda, m->v_min), &fea);
        *p_damp += (fa - fea) * dda;
    }
    sc->delta[sa] = da; sc->ddelta[sa] = dda; sc->force[sa] = fa;

    /* radial */
    double u[3] = {0, 0, 0}, fr = 0, fer = 0, ddr = 0;
    double dr = rho - gap;
    if (rho > 1e-15) {
        v3_scale(u, Dr, 1.0 / rho);
        ddr = v3_dot(u, Dd) - Da * v3_dot(u, adot);
        if (dr > 0) {
            fr = contact_force(&m->law[CC_JR], dr, ddr, contact_vi(st->v_onset[sr], ddr, m->v_min), &fer);
            *p_damp += (fr - fer) * ddr;
        }
    }
    sc->delta[sr] = dr; sc->ddelta[sr] = ddr; sc->force[sr] = fr;

    /* force on A at pF; the opposite on B at pR */
    double f[3];
    v3_scale(f, a, sgn * fa);
    v3_axpy(f, fr, u);
    double *FA = cA->F, *FB = cB->F, *TA = cA->T, *TB = cB->T;
    v3_add(FA, FA, f);
    v3_sub(FB, FB, f);
    v3_cross(tmp, rF, f);
    v3_add(TA, TA, tmp);
    v3_cross(tmp, rR, f);
    v3_sub(TB, TB, tmp);
    /* torque from the joint frame turning with cart A: (F_r D_a - f_a rho) a x u */
    if (rho > 1e-15) {
        double axu[3];
        v3_cross(axu, a, u);
        v3_axpy(TA, fr * Da - sgn * fa * rho, axu);
    }
    if (A == m->transducer) m3_tmulv(sc->jointF, RA, f);
}
