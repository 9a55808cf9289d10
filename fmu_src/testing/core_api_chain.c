/* Flat access to a whole chain without the FMI layer: for tests of the
 * physics that need more than the FMU's outputs, and for benchmarks that
 * measure the core without fmpy in between. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "chain.h"
#include "core_api.h"

static const LSSAlloc heap = {calloc, free};

void *lss_params_new(void) {
    LSSParams *p = calloc(1, sizeof(LSSParams));
    if (p) lss_params_defaults(p);
    return p;
}

void lss_params_free(void *p) { free(p); }

static const LSSVarInfo *find(const char *name) {
    for (int i = 1; i <= LSS_N_VARS; i++)
        if (strcmp(LSS_VARS[i].name, name) == 0) return &LSS_VARS[i];
    return NULL;
}

int lss_params_set(void *params, const char *name, double value) {
    const LSSVarInfo *v = find(name);
    if (!v || !v->in_params || v->type == LSS_STRING) return 1;
    char *slot = (char *)params + v->offset;
    if (v->type == LSS_REAL) *(double *)slot = value;
    else *(int *)slot = (int)value;
    return 0;
}

int lss_params_set_string(void *params, const char *name, const char *value) {
    const LSSVarInfo *v = find(name);
    if (!v || !v->in_params || v->type != LSS_STRING || strlen(value) >= LSS_STRING_MAX) return 1;
    strcpy((char *)params + v->offset, value);
    return 0;
}

void *lss_chain_new(void *params, const char *resource_dir, char *err, int errlen) {
    return chain_create(params, resource_dir, &heap, err, (size_t)errlen);
}

void lss_chain_free(void *c) { chain_free(c); }

int lss_chain_step(void *c, double t_end, char *err, int errlen) {
    return chain_step(c, t_end, err, (size_t)errlen);
}

void lss_chain_set_inputs(void *c, void *params) { chain_set_inputs(c, params); }

int lss_chain_n_carts(void *c) { return ((Chain *)c)->m.n_carts; }
int lss_chain_ny(void *c) { return ((Chain *)c)->m.n_y; }
double lss_chain_time(void *c) { return ((Chain *)c)->st.ode.t; }

void lss_chain_state(void *c, double *y) {
    Chain *ch = c;
    memcpy(y, ch->st.y, sizeof(double) * (size_t)ch->m.n_y);
}

/* Per cart and contact slot (joint axial, joint radial, steering L/R,
 * driving L/R): indentation (m), its rate (m/s) and force (N), each 6*N. */
void lss_chain_contacts(void *c, double *delta, double *ddelta, double *force) {
    Chain *ch = c;
    LSSOutputs o;
    chain_outputs(ch, &o);  /* brings the scratch to the current state */
    size_t n = (size_t)N_SLOT * ch->m.n_carts;
    memcpy(delta, ch->sc.delta, n * sizeof(double));
    memcpy(ddelta, ch->sc.ddelta, n * sizeof(double));
    memcpy(force, ch->sc.force, n * sizeof(double));
}

/* The outputs in value-reference order (entry k is value reference k+1;
 * non-output entries are NaN). */
void lss_chain_outputs(void *c, double *out) {
    Chain *ch = c;
    LSSOutputs o;
    chain_outputs(ch, &o);
    for (int i = 1; i <= LSS_N_VARS; i++) {
        const LSSVarInfo *v = &LSS_VARS[i];
        double x = NAN;
        if (!v->in_params) {
            const char *slot = (const char *)&o + v->offset;
            x = v->type == LSS_REAL ? *(const double *)slot : (double)*(const int *)slot;
        }
        out[i - 1] = x;
    }
}

/* Solver counters: steps, rejected, rhs evaluations. */
void lss_chain_stats(void *c, long *out3) {
    Chain *ch = c;
    out3[0] = ch->st.ode.n_steps;
    out3[1] = ch->st.ode.n_rejected;
    out3[2] = ch->st.ode.n_rhs;
}

void lss_chain_rhs(void *c, double t, const double *y, double *dy) {
    Chain *ch = c;
    chain_rhs(ch, t, y, dy);
    ch->scratch_at_state = 0;
}

int lss_chain_put_state(void *c, double t, double *y, int accept) { return chain_put_state(c, t, y, accept); }

void lss_chain_error_scales(void *c, double *scale, double *rel) {
    Chain *ch = c;
    memcpy(scale, ch->m.err_scale, sizeof(double) * (size_t)ch->m.n_y);
    memcpy(rel, ch->m.err_rel, sizeof(double) * (size_t)ch->m.n_y);
}

int lss_chain_state_size(void *c) { return (int)chain_state_size(c); }
void lss_chain_state_save(void *c, double *buf) { chain_state_save(c, buf); }
void lss_chain_state_load(void *c, const double *buf) { chain_state_load(c, buf); }

int lss_chain_run(void *c, double comm, int n_comm, const int *idx, int n_idx, double *out, char *err,
                  int errlen) {
    Chain *ch = c;
    double t0 = ch->st.ode.t;
    for (int k = 1; k <= n_comm; k++) {
        if (chain_step(ch, t0 + k * comm, err, (size_t)errlen) != 0) return 1;
        LSSOutputs o;
        chain_outputs(ch, &o);
        for (int j = 0; j < n_idx; j++) {
            const LSSVarInfo *v = &LSS_VARS[idx[j] + 1];
            const char *slot = (const char *)&o + v->offset;
            out[(size_t)(k - 1) * n_idx + j] =
                v->in_params ? NAN : (v->type == LSS_REAL ? *(const double *)slot : (double)*(const int *)slot);
        }
    }
    return 0;
}
