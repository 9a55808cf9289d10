/* A chain at rest in its static equilibrium, for measurements that start from
 * standstill (issue 17). The assembled chain is close to equilibrium but not
 * in it: released, it rings for about a second and creeps. Relaxing it by
 * kinetic damping (integrate in short intervals; when the kinetic energy
 * stops growing, the chain is passing its potential minimum along the way
 * it moves: set every velocity to zero there and go on) walks it down its
 * potential energy (gravity and contact strain), slow axial modes of the
 * whole loop included, without the slow PI drive and with a fixed contact
 * damping, so that the
 * equilibrium does not depend on the CoRs, the gains or mu_roll: one
 * equilibrium serves every such value (an FMU state can keep it). */
#include <string.h>

#include "chain_internal.h"
#include "chain_simd.h"

#define RELAX_INTERVAL 0.001    /* s between looks at the kinetic energy */
#define RELAX_COR 0.5           /* the contact damping during relaxation */
#define RELAX_TOL_MAX 1e-3      /* the solver's tolerance while relaxing: ten times the run's, at most this */

static double kinetic_energy(const Chain *c) {
    const ChainModel *m = &c->m;
    double E = 0.0;
    for (int i = 0; i < m->n_carts; i++) {
        const double *v = c->st.y + CART_NY * i + 7, *w = v + 3, *I = m->inertia + 3 * i;
        E += m->mass[i] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) + I[0] * w[0] * w[0] + I[1] * w[1] * w[1] +
             I[2] * w[2] * w[2];
    }
    return 0.5 * E;
}

static void quench(Chain *c) {
    for (int i = 0; i < c->m.n_carts; i++) memset(c->st.y + CART_NY * i + 7, 0, 6 * sizeof(double));
    c->st.ode.fsal_valid = 0;
    c->scratch_at_state = 0;
    chain_simd_invalidate(c);   /* the vector path's copy of the state */
}

int chain_relax(Chain *c, double T, char *err, size_t errlen) {
    ChainModel *m = &c->m;
    ChainState *st = &c->st;
    if (!(T > 0)) return 0;
    ContactLaw saved[CC_N];
    memcpy(saved, m->law, sizeof saved);
    double mu = m->mu_roll, v_ref = st->v_ref, Kp = st->Kp, Ki = st->Ki;
    int mode = m->drive_mode;
    for (int k = 0; k < CC_N; k++) m->law[k].chi = contact_chi(m->law_code, RELAX_COR);
    m->mu_roll = 0.0;
    m->drive_mode = DRIVE_INTERNAL;   /* drive off: no external thrust either */
    st->v_ref = st->Kp = st->Ki = 0.0;
    double tol = c->ode.tol;
    c->ode.tol = 10.0 * tol < RELAX_TOL_MAX ? 10.0 * tol : RELAX_TOL_MAX;  /* an equilibrium, not a trajectory */
    quench(c);
    int failed = 0;
    double E_prev = 0.0;
    for (double t = 0.0; t < T && !failed;) {
        double next = t + RELAX_INTERVAL < T ? t + RELAX_INTERVAL : T;
        failed = chain_step(c, next, err, errlen);
        double E = kinetic_energy(c);
        if (E < E_prev) {  /* past the peak: the potential minimum along the path */
            quench(c);
            E = 0.0;
        }
        E_prev = E;
        t = next;
    }
    quench(c);
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
