/* The outputs: the transducer cart's signals (its force sensors with their
 * gain and offset errors, effects.c), the chain and drive
 * quantities, the energy bookkeeping and the solver statistics. */
#include <stddef.h>

#include "chain_simd.h"

static double mechanical_energy(const Chain *c) {
    const ChainModel *m = &c->m;
    const ChainScratch *sc = &c->sc;
    double E = 0.0;
    for (int i = 0; i < m->n_carts; i++) {
        const double *yi = c->st.y + CART_NY * i, *v = yi + 7, *w = yi + 10, *I = m->inertia + 3 * i;
        E += 0.5 * m->mass[i] * v3_dot(v, v);
        E += 0.5 * (I[0] * w[0] * w[0] + I[1] * w[1] * w[1] + I[2] * w[2] * w[2]);
        E += m->mass[i] * m->gravity * yi[2];
        const double *d = sc->delta + N_SLOT * i;
        E += contact_energy(&m->law[CC_JA], d[SLOT_JA]) + contact_energy(&m->law[CC_JR], d[SLOT_JR]);
        for (int k = 0; k < N_WHEEL; k++)
            E += contact_energy(&m->law[(k == W_DL || k == W_DR) ? CC_RW : CC_SW], d[SLOT_WHEEL + k]);
    }
    return E;
}

/* The cart whose axle passed arc position s last: the smallest distance
 * behind it along the direction of travel. */
static int cart_past(const Chain *c, double s) {
    double L = c->m.track.length, best = INFINITY;
    int who = 0;
    for (int i = 0; i < c->m.n_carts; i++) {
        double d = fmod(s - c->sc.cart[i].s, L);
        if (d < 0) d += L;
        if (d < best) { best = d; who = i; }
    }
    return who;
}

static void at_state(Chain *c) {
    if (!c->scratch_at_state) {
        chain_rhs(c, c->st.ode.t, c->st.y, c->dy_scratch);
        c->scratch_at_state = 1;
    }
}

/* The outputs of constant cost: the transducer's signals (only its cart's
 * part of the scratch is brought over from the vector path), the chain's
 * and the drive's scalars, the energy integrals, the solver's counts. */
void chain_outputs_light(Chain *c, LSSOutputs *o) {
    const ChainModel *m = &c->m;
    const ChainScratch *sc = &c->sc;
    at_state(c);
    int tr = m->transducer;
    chain_simd_sync_cart(c, tr);
    const double *f = sc->force + N_SLOT * tr + SLOT_WHEEL, *ws = sc->cart[tr].wheel_speed;
    o->transducer_joint_F_x = sc->jointF[0];
    o->transducer_joint_F_y = sc->jointF[1];
    o->transducer_joint_F_z = sc->jointF[2];
    o->transducer_steering_F_left = f[W_SL];
    o->transducer_steering_F_right = f[W_SR];
    o->transducer_driving_F_left = f[W_DL];
    o->transducer_driving_F_right = f[W_DR];
    o->transducer_wheel_w_sl = ws[W_SL];
    o->transducer_wheel_w_sr = ws[W_SR];
    o->transducer_wheel_w_dl = ws[W_DL];
    o->transducer_wheel_w_dr = ws[W_DR];
    o->transducer_s = sc->cart[tr].s;
    if (m->fx.sensor_on) effects_sensor(&m->fx, o);
    o->transducer_v = sc->cart[tr].v_t;
    o->transducer_joint_v_axial = sc->joint_v_axial;
    o->chain_v_mean = sc->v_mean;
    o->drive_F_total = sc->F_total;
    o->drive_P_total = sc->P_total;
    o->drive_F_cmd = sc->F_cmd;
    o->energy_E_items = c->st.E_items;
    const double *gl = c->st.y + CART_NY * m->n_carts;
    o->energy_W_motor = gl[G_WMOT];
    o->energy_W_damping = gl[G_WDAMP];
    o->energy_W_rolling = gl[G_WROLL];
    o->solver_n_steps = (int)c->st.ode.n_steps;
    o->solver_n_rejected = (int)c->st.ode.n_rejected;
    o->solver_h_last = c->st.ode.h_last;
    o->solver_n_rhs = (int)(c->st.ode.n_rhs > 2147483647L ? 2147483647L : c->st.ode.n_rhs);
    o->chain_n_carts = m->n_carts;
    o->track_length = m->track.length;
    o->cart_mass = m->g.mass;
    o->chain_pitch = m->g.pitch;
    o->chain_preload = m->preload;
    o->drive_n_motors = m->track.n_motors;
    o->cart_r_drive = m->g.r_drive;
    o->solver_vector_path_used = c->path;
}

/* The outputs that walk every cart (or motor): the motor groups, the largest
 * joint force, the stations, the items' mass, the mechanical energy. */
void chain_outputs_bulk(Chain *c, LSSOutputs *o) {
    const ChainModel *m = &c->m;
    const ChainScratch *sc = &c->sc;
    at_state(c);
    chain_simd_sync(c);
    double gF[DRIVE_GROUPS], gv[DRIVE_GROUPS], gP[DRIVE_GROUPS];
    drive_groups(c, gF, gv, gP);
    double *oF[DRIVE_GROUPS] = {&o->drive_group1_F_total, &o->drive_group2_F_total, &o->drive_group3_F_total,
                                &o->drive_group4_F_total, &o->drive_group5_F_total, &o->drive_group6_F_total,
                                &o->drive_group7_F_total, &o->drive_group8_F_total};
    double *ov[DRIVE_GROUPS] = {&o->drive_group1_v, &o->drive_group2_v, &o->drive_group3_v, &o->drive_group4_v,
                                &o->drive_group5_v, &o->drive_group6_v, &o->drive_group7_v, &o->drive_group8_v};
    double *oP[DRIVE_GROUPS] = {&o->drive_group1_P, &o->drive_group2_P, &o->drive_group3_P, &o->drive_group4_P,
                                &o->drive_group5_P, &o->drive_group6_P, &o->drive_group7_P, &o->drive_group8_P};
    for (int g = 0; g < DRIVE_GROUPS; g++) {
        *oF[g] = gF[g];
        *ov[g] = gv[g];
        *oP[g] = gP[g];
    }
    double jmax = -1.0;
    int jwho = 0;
    for (int i = 0; i < m->n_carts; i++) {
        double fa = sc->force[N_SLOT * i + SLOT_JA], fr = sc->force[N_SLOT * i + SLOT_JR], f = sqrt(fa * fa + fr * fr);
        if (f > jmax) { jmax = f; jwho = i; }
    }
    o->chain_joint_F_max = jmax;
    o->chain_joint_F_max_cart = jwho;
    o->station_induction_cart = cart_past(c, m->station_s[STATION_INDUCTION]);
    o->station_chute_cart = cart_past(c, m->station_s[STATION_CHUTE]);
    double items = 0.0;
    for (int i = 0; i < m->n_carts; i++) items += c->st.load[i];
    o->chain_items_mass = items;
    o->energy_E_mech = mechanical_energy(c);
}

void chain_outputs(Chain *c, LSSOutputs *o) {
    chain_outputs_light(c, o);
    chain_outputs_bulk(c, o);
}
