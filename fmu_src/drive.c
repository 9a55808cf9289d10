/* Linear motors on the straights and the saturated PI speed controller.
 * A motor pushes the reaction plate under a cart in proportion to how much of
 * the motor the plate covers, so thrust is continuous in the cart position.
 * With effects.motor_ripple each motor adds a cogging force that depends on
 * the plate's position over it, A w sin(2 pi x / p + phi), whatever the
 * controller asks; its work is motor work like the thrust's. */
#include <math.h>

#include "rhs_shared.h"

static double overlap(double a0, double a1, double b0, double b1) {
    double lo = a0 > b0 ? a0 : b0, hi = a1 < b1 ? a1 : b1;
    return hi > lo ? hi - lo : 0.0;
}

#if defined(__GNUC__)
#define DRIVE_INLINE inline __attribute__((always_inline))
#define DRIVE_NOINLINE __attribute__((noinline))
#else
#define DRIVE_INLINE inline
#define DRIVE_NOINLINE
#endif

/* Sum over the motors that overlap the plate centred at s_plate of
 * overlap / motor length. lo is the first motor starting after s_plate
 * (0..n); motor k < 0 or k >= n stands for motor k mod n a lap earlier or
 * later, so the loop closes without wrapping arc lengths. The motors are
 * sorted by their start; a motor is at most motor_length long.
 * With the constant with_ripple, *ripple also receives the sum of
 * w sin(2 pi x / p + phi), x the plate centre from the motor start; with
 * Fk (each motor's own thrust, the external drive) *weighted receives the
 * sum of w Fk; without either the loop is the plain one. */
static DRIVE_INLINE double overlap_sum(const ChainModel *m, double s_plate, int lo, const int with_ripple,
                                       double *ripple, const double *Fk, double *weighted) {
    const Track *t = &m->track;
    double half = 0.5 * m->g.plate_length, L = t->length, frac = 0.0, rs = 0.0, wf = 0.0;
    int nm = t->n_motors;
    /* forwards: motors starting before the plate's end */
    for (int k = lo; k < lo + nm; k++) {
        int kk = k >= nm ? k - nm : k;
        double shift = k >= nm ? L : 0.0, s0 = t->motor_s0[kk] + shift, s1 = t->motor_s1[kk] + shift;
        if (s0 >= s_plate + half) break;
        if (s1 > s0) {
            double w = overlap(s_plate - half, s_plate + half, s0, s1) / (s1 - s0);
            frac += w;
            if (Fk) wf += w * Fk[kk];
            if (with_ripple && w > 0.0) rs += w * sin(m->fx.ripple_k * (s_plate - s0) + m->fx.ripple_phase);
        }
    }
    /* backwards: motors ending after the plate's start */
    for (int k = lo - 1; k >= lo - nm; k--) {
        int kk = k < 0 ? k + nm : k;
        double shift = k < 0 ? -L : 0.0, s0 = t->motor_s0[kk] + shift, s1 = t->motor_s1[kk] + shift;
        if (s0 + m->motor_length <= s_plate - half) break;
        if (s1 > s0) {
            double w = overlap(s_plate - half, s_plate + half, s0, s1) / (s1 - s0);
            frac += w;
            if (Fk) wf += w * Fk[kk];
            if (with_ripple && w > 0.0) rs += w * sin(m->fx.ripple_k * (s_plate - s0) + m->fx.ripple_phase);
        }
    }
    if (with_ripple) *ripple = rs;
    if (Fk) *weighted = wf;
    return frac;
}

static double overlap_from(const ChainModel *m, double s_plate, int lo) {
    return overlap_sum(m, s_plate, lo, 0, NULL, NULL, NULL);
}

/* out of line: the plain thrust path stays as lean as without the ripple or the external drive */
static DRIVE_NOINLINE double overlap_other_from(const ChainModel *m, double s_plate, int lo, double *ripple,
                                                const double *Fk, double *weighted) {
    return overlap_sum(m, s_plate, lo, m->fx.ripple_on, ripple, Fk, weighted);
}

double drive_overlap(const ChainModel *m, double s_plate) {
    const Track *t = &m->track;
    if (t->n_motors == 0) return 0.0;
    /* first motor starting after the plate centre, by bisection */
    int lo = 0, hi = t->n_motors;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (t->motor_s0[mid] <= s_plate) lo = mid + 1;
        else hi = mid;
    }
    return overlap_from(m, s_plate, lo);
}

/* The first motor starting after s_plate, found by walking from a hint (a
 * cart moves little between evaluations), which is updated. */
static int motor_from_hint(const ChainModel *m, double s_plate, int *hint) {
    const Track *t = &m->track;
    int nm = t->n_motors, lo = *hint;
    if (lo < 0 || lo > nm) lo = 0;
    while (lo > 0 && t->motor_s0[lo - 1] > s_plate) lo--;
    while (lo < nm && t->motor_s0[lo] <= s_plate) lo++;
    *hint = lo;
    return lo;
}

/* Conditional integration (no wind-up), its switch spread over a band of
 * ANTIWINDUP_BAND * F_max below the saturation: the integrator stops as the
 * command enters the band rather than at the limit at once. A switch at
 * once turns zdot off and on at every step while the controller rides its
 * limit (a start at full thrust with a low Kp, where Ki e outpaces Kp de/dt:
 * the Filippov sliding motion), and the solver fell to steps of 1e-7 s
 * (layout 1, a start-up with Kp 269: 170 CPU-s for 0.3 s, against 0.3 CPU-s
 * with Kp 445). In the band zdot is continuous and the motion the same
 * within the band's width of command. */
#define ANTIWINDUP_BAND 1e-3

double drive_command(const ChainModel *m, const ChainState *st, double v_mean, double z, double *zdot) {
    if (m->drive_mode == DRIVE_EXTERNAL) {  /* the motors take their thrust from the inputs; the PI rests */
        *zdot = 0.0;
        return 0.0;
    }
    double e = st->v_ref - v_mean;
    double u = st->Kp * e + st->Ki * z;
    double Fm = m->F_max, band = ANTIWINDUP_BAND * m->F_max, gate = 1.0;
    double F = u > Fm ? Fm : (u < -Fm ? -Fm : u);
    if (e > 0 && u > Fm - band) gate = u >= Fm ? 0.0 : (Fm - u) / band;
    else if (e < 0 && u < band - Fm) gate = u <= -Fm ? 0.0 : (u + Fm) / band;
    *zdot = gate * e;
    return F;
}

int drive_thrust(const ChainModel *m, const double *F_motor, double s_axle, int *hint, double F_cmd, double *F) {
    double s_plate = s_axle - (m->g.x_axle - m->g.x_motor), frac;
    int lo = motor_from_hint(m, s_plate, hint);
    if (!m->fx.ripple_on && !F_motor) {
        frac = overlap_from(m, s_plate, lo);
        *F = F_cmd * frac;
    } else {
        double rsum = 0.0, wsum = 0.0;
        frac = overlap_other_from(m, s_plate, lo, &rsum, F_motor, &wsum);
        *F = (F_motor ? wsum : F_cmd * frac) + (m->fx.ripple_on ? m->fx.ripple_A * rsum : 0.0);
    }
    return !(frac <= 0);
}

/* Thrust on cart i along the track tangent, at its motor point. */
void drive_forces(Chain *c, const double *y, int i, double F_cmd) {
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    CartScratch *cs = &sc->cart[i];
    if (!drive_acts(m, F_cmd)) return;
    double F;
    if (!drive_thrust(m, drive_motors(c), cs->s, &cs->motor, F_cmd, &F)) return;
    const double *yi = y + CART_NY * i;
    const double *R = cs->R, *ww = cs->ww;
    double bm[3] = {m->g.x_motor, 0.0, m->g.z_motor}, rm[3], v[3], fv[3], tmp[3];
    m3_mulv(rm, R, bm);
    v3_cross(v, ww, rm);
    v3_add(v, v, yi + 7);
    v3_scale(fv, cs->t, F);
    v3_add(cs->F, cs->F, fv);
    v3_cross(tmp, rm, fv);
    v3_add(cs->T, cs->T, tmp);
    sc->F_total += F;
    sc->P_total += v3_dot(fv, v);
}

/* Adds to the groups what one plate gets from each motor it covers (the
 * walk of overlap_sum, one motor at a time). */
static void plate_groups(const Chain *c, double s_plate, int lo, double v_t, double F_cmd, double *F, double *wv,
                         double *w_sum, double *P) {
    const ChainModel *m = &c->m;
    const Track *t = &m->track;
    const double *Fk = drive_motors(c);
    double half = 0.5 * m->g.plate_length, L = t->length;
    int nm = t->n_motors;
    for (int dir = 0; dir < 2; dir++)
        for (int j = 0; j < nm; j++) {
            int k = dir == 0 ? lo + j : lo - 1 - j;
            int kk = k >= nm ? k - nm : (k < 0 ? k + nm : k);
            double shift = k >= nm ? L : (k < 0 ? -L : 0.0), s0 = t->motor_s0[kk] + shift, s1 = t->motor_s1[kk] + shift;
            if (dir == 0 && s0 >= s_plate + half) break;
            if (dir == 1 && s0 + m->motor_length <= s_plate - half) break;
            if (!(s1 > s0)) continue;
            double w = overlap(s_plate - half, s_plate + half, s0, s1) / (s1 - s0);
            if (!(w > 0.0)) continue;
            double f = w * (Fk ? Fk[kk] : F_cmd);
            if (m->fx.ripple_on) f += m->fx.ripple_A * w * sin(m->fx.ripple_k * (s_plate - s0) + m->fx.ripple_phase);
            int g = m->motor_group[kk];
            F[g] += f;
            P[g] += f * v_t;
            wv[g] += w * v_t;
            w_sum[g] += w;
        }
}

void drive_groups(const Chain *c, double *F, double *v, double *P) {
    const ChainModel *m = &c->m;
    double w_sum[DRIVE_GROUPS] = {0};
    for (int g = 0; g < DRIVE_GROUPS; g++) F[g] = v[g] = P[g] = 0.0;
    if (m->track.n_motors == 0) return;
    for (int i = 0; i < m->n_carts; i++) {
        const CartScratch *cs = &c->sc.cart[i];
        double s_plate = cs->s - (m->g.x_axle - m->g.x_motor);
        int hint = cs->motor;
        int lo = motor_from_hint(m, s_plate, &hint);
        plate_groups(c, s_plate, lo, cs->v_t, c->sc.F_cmd, F, v, w_sum, P);
    }
    for (int g = 0; g < DRIVE_GROUPS; g++) v[g] = w_sum[g] > 0 ? v[g] / w_sum[g] : 0.0;
}
