/* Time stepping of the chain: the generic Dormand-Prince solver with the
 * chain's right-hand side, and what happens after every accepted step: the
 * contact memory (onset velocities) is updated, the projection warm starts
 * advance, and drifting quaternions are renormalised. */
#include <stdio.h>
#include <string.h>

#include "chain_simd.h"

/* The contact memory of every slot from the scalar scratch (the scalar
 * path; the vector paths work on their own arrays, chain_simd_accept).
 * Returns 1 if the right-hand side at the new point changed. */
static int update_contact_memory(Chain *c) {
    const ChainScratch *sc = &c->sc;
    int changed = 0, n = N_SLOT * c->m.n_carts;
    for (int k = 0; k < n; k++) changed |= contact_memory_slot(&c->st, c->m.v_min, k, sc->delta[k], sc->ddelta[k]);
    return changed;
}

static void rhs(void *ctx, double t, const double *y, double *dy) {
    Chain *c = ctx;
    chain_rhs(c, t, y, dy);
    double k = c->st.relax_rate;
    if (k > 0) {   /* the relaxation's viscous damping, on every velocity (chain_relax.c) */
        for (int i = 0; i < c->m.n_carts; i++)
            for (int j = 7; j < 13; j++) dy[CART_NY * i + j] -= k * y[CART_NY * i + j];
    }
}

/* Appends an accepted step to the trace, growing it by half (the host's calloc, no realloc). */
static void record(Chain *c, double h, double t) {
    ChainTrace *tr = &c->trace;
    if (tr->n == tr->cap) {
        long cap = tr->cap < 256 ? 256 : tr->cap + tr->cap / 2;
        double *nh = c->m.alloc.calloc((size_t)cap, sizeof(double));
        double *nt = c->m.alloc.calloc((size_t)cap, sizeof(double));
        if (!nh || !nt) {
            if (nh) c->m.alloc.free(nh);
            if (nt) c->m.alloc.free(nt);
            tr->lost = 1;
            return;
        }
        if (tr->n) {
            memcpy(nh, tr->h, sizeof(double) * (size_t)tr->n);
            memcpy(nt, tr->t, sizeof(double) * (size_t)tr->n);
        }
        if (tr->h) c->m.alloc.free(tr->h);
        if (tr->t) c->m.alloc.free(tr->t);
        tr->h = nh;
        tr->t = nt;
        tr->cap = cap;
    }
    tr->h[tr->n] = h;
    tr->t[tr->n] = t;
    tr->n++;
}

void chain_trace(Chain *c, int on) {
    c->trace.on = on;
    c->trace.n = 0;
    c->trace.lost = 0;
}

void chain_trace_free(Chain *c) {
    if (c->trace.h) c->m.alloc.free(c->trace.h);
    if (c->trace.t) c->m.alloc.free(c->trace.t);
    memset(&c->trace, 0, sizeof c->trace);
}

static int accepted(void *ctx, double t, double *y) {
    Chain *c = ctx;
    int changed = 0;
    if (c->trace.on) record(c, c->st.ode.h_last, t);
    for (int i = 0; i < c->m.n_carts; i++) {
        double *q = y + CART_NY * i + 3;
        double nq = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (fabs(nq - 1.0) > 1e-9) {  /* rare: the rotation is normalised anyway */
            for (int j = 0; j < 4; j++) q[j] /= nq;
            changed = 1;
        }
    }
    /* the scratch holds the last stage, evaluated at the new point */
    if (c->simd) return chain_simd_accept(c) || changed;
    for (int i = 0; i < c->m.n_carts; i++) c->st.s_hint[i] = c->sc.cart[i].s;
    return update_contact_memory(c) || changed;
}

void chain_solver_init(Chain *c) {
    Dopri *d = &c->ode;
    d->n = c->m.n_y;
    d->method = c->m.method == LSS_METHOD_DOP853 ? DOPRI_DOP853 : DOPRI_DOPRI5;
    d->rhs = rhs;
    d->accepted = accepted;
    d->ctx = c;
    d->scale = c->m.err_scale;
    d->rel = c->m.err_rel;
    d->tol = c->m.tol;
    d->h_max = c->m.h_max;
}

int chain_step(Chain *c, double t_end, char *err, size_t errlen) {
    int r = dopri_integrate(&c->ode, &c->st.ode, c->st.y, t_end, err, errlen);
    c->scratch_at_state = (r == 0);
    return r;
}

int chain_replay(Chain *c, const ChainTrace *tr, char *err, size_t errlen) {
    if (tr->lost) {
        snprintf(err, errlen, "the leading chain's steps could not be kept (out of memory)");
        return 1;
    }
    int r = dopri_replay(&c->ode, &c->st.ode, c->st.y, tr->h, tr->t, tr->n, err, errlen);
    c->scratch_at_state = (r == 0);
    return r;
}

/* For integrators outside the core (benchmarks): puts (t, y) into the chain;
 * with accept, runs what follows an accepted step (y may be renormalised).
 * Returns 1 if y or the right-hand side at y changed. */
int chain_put_state(Chain *c, double t, double *y, int accept) {
    memcpy(c->st.y, y, sizeof(double) * (size_t)c->m.n_y);
    c->st.ode.t = t;
    chain_rhs(c, t, c->st.y, c->dy_scratch);
    int r = accept ? accepted(c, t, c->st.y) : 0;
    if (r) chain_rhs(c, t, c->st.y, c->dy_scratch);
    c->scratch_at_state = 1;
    c->st.ode.fsal_valid = 0;
    memcpy(y, c->st.y, sizeof(double) * (size_t)c->m.n_y);
    return r;
}
