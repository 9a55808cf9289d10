/* A chain at rest in its static equilibrium, for measurements that start from
 * standstill (issue 17). The assembled chain is close to equilibrium but not
 * in it: released, it rings for about a second and creeps. Relaxing it walks
 * it down its potential energy (gravity and contact strain), slow axial modes
 * of the whole loop included, without the slow PI drive and with a fixed
 * contact damping, so that the equilibrium does not depend on the CoRs, the
 * gains or mu_roll: one equilibrium serves every such value (an FMU state can
 * keep it).
 *
 * The walk is viscous: every velocity decays at RELAX_RATE, a damping term in
 * the equations of motion while relaxing, for a time fixed in advance. That
 * makes the chain at rest a smooth function of where it stands and of its
 * pretension, and leaves the solver its own steps: applied between fixed
 * intervals instead, the damping bounded every step to the interval (1 ms,
 * about half the joints' stability limit) and restarted the solver's first
 * stage at each application. Kinetic
 * damping (zero every velocity when the kinetic energy passes a peak) settles
 * as fast, but which look sees the peak is decided by the state: half a
 * millimetre further along the track quenches at another look, the start
 * jumps by up to a newton or more, and an identification's objective
 * inherits the jumps as local minima in the trigger point and the
 * pretension (docs/benchmarks.md). */
#include <stdio.h>
#include <string.h>

#include "rhs_shared.h"
#include "chain_simd.h"

#define RELAX_RATE 10.0         /* 1/s: about critical for the slowest modes of a loop at rest; after 1 s of
                                   it the forces of a chain left at rest drift by under 3 N (layouts 1-7) */
#define RELAX_COR 0.5           /* the contact damping during relaxation */
#define RELAX_TOL_MAX 1e-5      /* the solver's tolerance while relaxing: the run's, at most this, so that the
                                   chain at rest lands within 0.1 N of a finer run's whatever the run's tolerance */

/* Every velocity times k (the velocities are state: the solver's last stage and the vector path's
 * copy no longer hold). */
static void damp(Chain *c, double k) {
    for (int i = 0; i < c->m.n_carts; i++)
        for (int j = 7; j < 13; j++) c->st.y[CART_NY * i + j] *= k;
    c->st.ode.fsal_valid = 0;
    c->scratch_at_state = 0;
    chain_simd_invalidate(c);   /* the vector path's copy of the state */
}

/* Relaxes for T s on the solver's own steps, or (tr) on a leader's recorded ones. */
static int relax(Chain *c, double T, const ChainTrace *tr, char *err, size_t errlen) {
    ChainModel *m = &c->m;
    ChainState *st = &c->st;
    if (!(T > 0)) return 0;
    ContactLaw saved[CC_N];
    memcpy(saved, m->law, sizeof saved);
    double mu = m->mu_roll, v_ref = st->v_ref, Kp = st->Kp, Ki = st->Ki;
    int mode = m->drive_mode;
    /* what is overridden here is what chain_relax_ignores names */
    for (int k = 0; k < CC_N; k++) m->law[k].chi = contact_chi(m->law_code, RELAX_COR);
    m->mu_roll = 0.0;
    m->drive_mode = DRIVE_INTERNAL;   /* drive off: no external thrust either */
    st->v_ref = st->Kp = st->Ki = 0.0;
    double tol = c->ode.tol;
    /* not looser: the steps would then sit at the joints' stability limit, and the error control's noise
       there leaves the chain up to 0.8 N from where a finer run relaxes it (1e-4: 0.3-0.8 N, layouts 1-7) */
    c->ode.tol = tol < RELAX_TOL_MAX ? tol : RELAX_TOL_MAX;
    damp(c, 0.0);
    st->relax_rate = RELAX_RATE;
    int failed = tr ? chain_replay(c, tr, err, errlen) : chain_step(c, T, err, errlen);
    if (!failed && tr && !(st->ode.t == T)) {
        snprintf(err, errlen, "the leader's relaxation ended at %.17g s, not at %.17g s", st->ode.t, T);
        failed = 1;
    }
    st->relax_rate = 0.0;
    damp(c, 0.0);
    c->ode.tol = tol;
    memcpy(m->law, saved, sizeof saved);
    m->mu_roll = mu;
    m->drive_mode = mode;
    st->v_ref = v_ref;
    st->Kp = Kp;
    st->Ki = Ki;
    if (failed) return 1;
    /* the clock starts now, at rest: no drive history, no energy spent yet */
    memset(st->y + CART_NY * m->n_carts, 0, N_GLOBAL * sizeof(double));
    dopri_reset(&st->ode, 0.0, 1e-4);   /* the solver statistics count from t = 0 too */
    chain_start_memory(c);
    return 0;
}

int chain_relax(Chain *c, double T, char *err, size_t errlen) { return relax(c, T, NULL, err, errlen); }

int chain_relax_replay(Chain *c, const ChainTrace *tr, char *err, size_t errlen) {
    double T = tr->n ? tr->t[tr->n - 1] : 0.0;
    return relax(c, T, tr, err, errlen);
}

int chain_relax_ignores(int vr) {
    return vr == VR_CONTACT_E_JA || vr == VR_CONTACT_E_JR || vr == VR_CONTACT_E_SW || vr == VR_CONTACT_E_RW ||
           vr == VR_WHEEL_MU_ROLL || vr == VR_DRIVE_KP || vr == VR_DRIVE_KI || vr == VR_DRIVE_V_REF;
}
