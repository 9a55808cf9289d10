/* FMU state copies (fmi2GetFMUstate / SetFMUstate / FreeFMUstate) and their
 * serialised format: a header (build, state machine, times, parameters,
 * outputs as the master saw them) and the chain's own snapshot
 * (chain_state_save). A state handed in by the master is checked before it is
 * adopted; adopting it is all or nothing. */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "fmi2_instance.h"
#include "lss_guid.h"

#define SNAP_MAGIC 0x4C5353434841494EULL /* "LSSCHAIN" */
#define SNAP_VERSION 3

typedef struct {
    unsigned long long magic;
    int version;
    char guid[40];          /* the build that wrote it: a state is only valid for the same binary */
    int state;
    int has_chain;
    int has_out;            /* out holds the outputs at this state */
    int tolerance_defined;
    int stop_time_defined;
    double tolerance, start_time, time, stop_time;
    size_t n;               /* doubles in the chain snapshot */
    LSSParams p;
    LSSParams built;        /* parameters the chain was built with (tolerance applied) */
    LSSOutputs out;         /* outputs as the master saw them: re-evaluating them after a restore
                               could differ in the last bit (projection warm starts) */
} SnapHeader;

typedef struct {
    SnapHeader h;
    double data[];
} Snapshot;

static int is_snapshot(const void *s) {
    const SnapHeader *h = s;
    return h->magic == SNAP_MAGIC && h->version == SNAP_VERSION;
}

static int same_build(const SnapHeader *h) {
    return memchr(h->guid, 0, sizeof h->guid) && strcmp(h->guid, LSS_GUID) == 0;
}

/* Do two parameter sets give chains of the same structure (all fixed
 * parameters equal, bit for bit)? Tunables and inputs are re-applied. */
static int same_structure(const LSSParams *a, const LSSParams *b) {
    for (int vr = 1; vr <= LSS_N_VARS; vr++) {
        const LSSVarInfo *v = &LSS_VARS[vr];
        if (!v->in_params || v->variability != LSS_FIXED) continue;
        const char *x = (const char *)a + v->offset, *y = (const char *)b + v->offset;
        if (v->type == LSS_STRING ? strcmp(x, y) != 0
                                  : memcmp(x, y, v->type == LSS_REAL ? sizeof(double) : sizeof(int)) != 0)
            return 0;
    }
    return 1;
}

static int params_terminated(const LSSParams *p) {
    for (int vr = 1; vr <= LSS_N_VARS; vr++) {
        const LSSVarInfo *v = &LSS_VARS[vr];
        if (v->in_params && v->type == LSS_STRING && !memchr((const char *)p + v->offset, 0, LSS_STRING_MAX))
            return 0;
    }
    return 1;
}

/* Do two parameter sets agree in every variable (the solver tolerance
 * excepted when skip_tol)? Compared through the variable table: padding bytes
 * are not part of a parameter set. */
static int same_params(const LSSParams *a, const LSSParams *b, int skip_tol) {
    for (int vr = 1; vr <= LSS_N_VARS; vr++) {
        const LSSVarInfo *v = &LSS_VARS[vr];
        if (!v->in_params || (skip_tol && v->offset == offsetof(LSSParams, solver_tolerance))) continue;
        const char *x = (const char *)a + v->offset, *y = (const char *)b + v->offset;
        if (v->type == LSS_STRING ? strcmp(x, y) != 0
                                  : memcmp(x, y, v->type == LSS_REAL ? sizeof(double) : sizeof(int)) != 0)
            return 0;
    }
    return 1;
}

/* The outputs a state carries: finite numbers, counters not negative. */
static int outputs_sane(const LSSOutputs *o, char *why, size_t len) {
    for (int vr = 1; vr <= LSS_N_VARS; vr++) {
        const LSSVarInfo *v = &LSS_VARS[vr];
        if (v->in_params) continue;
        const char *slot = (const char *)o + v->offset;
        if (v->type == LSS_REAL && !isfinite(*(const double *)slot)) {
            snprintf(why, len, "corrupt FMU state: output %s = %g", v->name, *(const double *)slot);
            return 0;
        }
        if (v->type == LSS_INTEGER && *(const int *)slot < 0) {
            snprintf(why, len, "corrupt FMU state: output %s = %d", v->name, *(const int *)slot);
            return 0;
        }
    }
    return 1;
}

static int valid_state(int s) {
    return s == ST_INSTANTIATED || s == ST_INIT || s == ST_STEP_COMPLETE || s == ST_STEP_FAILED ||
           s == ST_TERMINATED || s == ST_ERROR;
}

/* Is the header usable (it may come from bytes handed in by the master)?
 * 0, or 1 with the reason in why. */
static int check_header(const SnapHeader *h, char *why, size_t len) {
    char err[512];
    if (!is_snapshot(h)) {
        snprintf(why, len, "not an LSSChain FMU state of this version");
        return 1;
    }
    if (!same_build(h)) {
        snprintf(why, len, "the FMU state was written by another build of LSSChain (GUID differs)");
        return 1;
    }
    if (!valid_state(h->state) || (h->has_chain != 0 && h->has_chain != 1) ||
        (h->has_out != 0 && h->has_out != h->has_chain) ||
        (h->tolerance_defined != 0 && h->tolerance_defined != 1) ||
        (h->stop_time_defined != 0 && h->stop_time_defined != 1)) {
        snprintf(why, len, "corrupt FMU state: flags out of range");
        return 1;
    }
    if ((h->has_chain != 0) != (h->n != 0) ||
        (!h->has_chain && (h->state & (ST_STEP_COMPLETE | ST_STEP_FAILED)))) {
        snprintf(why, len, "corrupt FMU state: a state in %s without the chain's state", lss_state_name(h->state));
        return 1;
    }
    if (!isfinite(h->start_time) || !isfinite(h->time) || (h->stop_time_defined && !isfinite(h->stop_time)) ||
        (h->tolerance_defined && !(h->tolerance >= TOL_FLOOR && h->tolerance <= 0.1))) {
        snprintf(why, len, "corrupt FMU state: non-finite time or tolerance out of range");
        return 1;
    }
    if (!params_terminated(&h->p) || !params_terminated(&h->built)) {
        snprintf(why, len, "corrupt FMU state: unterminated string parameter");
        return 1;
    }
    if (chain_check_params(&h->p, err, sizeof err) ||
        (h->has_chain && (chain_check_params(&h->built, err, sizeof err) || sens_check(&h->built, err, sizeof err)))) {
        snprintf(why, len, "FMU state with invalid parameters: %s", err);
        return 1;
    }
    if (h->stop_time_defined && !(h->stop_time >= h->start_time)) {
        snprintf(why, len, "corrupt FMU state: stopTime %.17g before startTime %.17g", h->stop_time, h->start_time);
        return 1;
    }
    if (h->has_chain) {
        if (!same_params(&h->p, &h->built, 1) ||
            h->built.solver_tolerance != (h->tolerance_defined ? h->tolerance : h->p.solver_tolerance)) {
            snprintf(why, len, "corrupt FMU state: the chain's parameters differ from the state's");
            return 1;
        }
        if (h->has_out && !outputs_sane(&h->out, why, len)) return 1;
    }
    return 0;
}

/* The header and the chain's snapshot (data, h->n doubles, aligned) together;
 * c: the chain the state will be loaded into, or NULL. 0, or 1 with why. */
static int check_snapshot(const SnapHeader *h, const double *data, const Chain *c, char *why, size_t len) {
    if (check_header(h, why, len)) return 1;
    if (!h->has_chain) return 0;
    /* Step Mode and Initialization Mode: the chain is at the FMU's time; after a
       discarded step (and a Terminate that may follow) it may be past it */
    int exact = !(h->state & (ST_STEP_FAILED | ST_TERMINATED | ST_ERROR));
    char what[400];
    /* the leader's snapshot, then each follower's (sensitivity.h), all of one size */
    size_t parts = 1 + (size_t)h->built.sensitivity_n, n1 = h->n / parts;
    if (h->n % parts != 0) {
        snprintf(why, len, "corrupt FMU state: %zu values do not split into %zu chains", h->n, parts);
        return 1;
    }
    for (size_t k = 0; k < parts; k++) {
        LSSParams pk = h->built;
        if (k > 0) sens_params(&h->built, (int)k - 1, &pk);
        if (chain_state_check(data + k * n1, n1, &pk, h->time - h->start_time, exact, k ? NULL : c, what,
                              sizeof what)) {
            snprintf(why, len, "corrupt FMU state: %s%s", k ? "a follower's snapshot: " : "", what);
            return 1;
        }
    }
    return 0;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    CHECK(c, "fmi2GetFMUstate", ST_ANY);
    if (!FMUstate) {
        LOG_ERROR(in, "fmi2GetFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    Snapshot *s = *FMUstate;
    if (s && !is_snapshot(s)) {
        LOG_ERROR(in, "fmi2GetFMUstate: *FMUstate is neither NULL nor an LSSChain FMU state");
        return fmi2Error;
    }
    int has = in->chain && !in->chain_stale;
    size_t n1 = has ? chain_state_size(in->chain) : 0, n = n1 * (1 + (size_t)in->sens.n);
    if (has && lss_ensure_outputs(in) != fmi2OK) return fmi2Error;  /* cannot fail: the chain exists */
    if (s && s->h.n != n) {  /* an old snapshot of another size: replace it */
        in->cb.freeMemory(s);
        s = NULL;
        *FMUstate = NULL;
    }
    if (!s) s = in->cb.allocateMemory(1, sizeof(SnapHeader) + n * sizeof(double));
    if (!s) {
        LOG_ERROR(in, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    s->h.magic = SNAP_MAGIC;
    s->h.version = SNAP_VERSION;
    memset(s->h.guid, 0, sizeof s->h.guid);
    snprintf(s->h.guid, sizeof s->h.guid, "%s", LSS_GUID);
    s->h.state = in->state;
    s->h.has_chain = has;
    s->h.has_out = has;
    if (has) s->h.out = in->out;
    s->h.tolerance_defined = in->tolerance_defined;
    s->h.tolerance = in->tolerance;
    s->h.stop_time_defined = in->stop_time_defined;
    s->h.stop_time = in->stop_time;
    s->h.start_time = in->start_time;
    s->h.time = in->time;
    s->h.n = n;
    s->h.p = in->p;
    s->h.built = in->p;
    if (in->tolerance_defined) s->h.built.solver_tolerance = in->tolerance;
    if (has) {
        chain_state_save(in->chain, s->data);
        for (int k = 0; k < in->sens.n; k++) chain_state_save(in->sens.f[k], s->data + n1 * (size_t)(k + 1));
    }
    *FMUstate = s;
    return fmi2OK;
}

/* All or nothing: on an error the instance is left as it was. */
static fmi2Status restore(Instance *in, const Snapshot *s, const char *fn) {
    char why[600];
    if (check_snapshot(&s->h, s->data, NULL, why, sizeof why)) {
        LOG_ERROR(in, "%s: %s", fn, why);
        return fmi2Error;
    }
    Chain *fresh = NULL;
    Sens fresh_sens;
    memset(&fresh_sens, 0, sizeof fresh_sens);
    size_t parts = 1 + (size_t)s->h.built.sensitivity_n, n1 = s->h.n / parts;
    if (s->h.has_chain) {
        LSSParams now = in->p;
        if (in->tolerance_defined) now.solver_tolerance = in->tolerance;
        int same = in->chain && !in->chain_stale && chain_state_size(in->chain) == n1 &&
                   (size_t)in->sens.n + 1 == parts && same_structure(&now, &s->h.built);
        if (!same) {  /* build the chains of the snapshot's structure, then load their states */
            char err[1024];
            const char *res = in->has_resources ? in->resource_dir : NULL;
            fresh = chain_create(&s->h.built, res, &in->alloc, err, sizeof err);
            if (!fresh) {
                LOG_ERROR(in, "%s: cannot rebuild the chain of the FMU state: %s", fn, err);
                return fmi2Error;
            }
            if (chain_state_size(fresh) != n1) {
                chain_free(fresh);
                LOG_ERROR(in, "%s: the FMU state does not fit the chain it describes", fn);
                return fmi2Error;
            }
            if (sens_create(&fresh_sens, &s->h.built, res, &in->alloc, err, sizeof err)) {
                chain_free(fresh);
                LOG_ERROR(in, "%s: cannot rebuild the sensitivities of the FMU state: %s", fn, err);
                return fmi2Error;
            }
            chain_trace(fresh, fresh_sens.n > 0);
        }
        /* the checks that need the chain (its track) */
        if (check_snapshot(&s->h, s->data, fresh ? fresh : in->chain, why, sizeof why)) {
            sens_free(&fresh_sens);
            chain_free(fresh);
            LOG_ERROR(in, "%s: %s", fn, why);
            return fmi2Error;
        }
    }
    /* from here on nothing fails */
    if (fresh) {
        sens_free(&in->sens);
        in->sens = fresh_sens;
        chain_free(in->chain);
        in->chain = fresh;
    }
    in->p = s->h.p;
    in->tolerance_defined = s->h.tolerance_defined;
    in->tolerance = s->h.tolerance;
    in->stop_time_defined = s->h.stop_time_defined;
    in->stop_time = s->h.stop_time;
    in->start_time = s->h.start_time;
    in->time = s->h.time;
    in->setup_done = 1;  /* the state carries the experiment's times */
    in->outputs_stale = 1;
    if (s->h.has_chain) {
        chain_state_load(in->chain, s->data);
        chain_set_inputs(in->chain, &in->p);
        for (int k = 0; k < in->sens.n; k++) chain_state_load(in->sens.f[k], s->data + n1 * (size_t)(k + 1));
        sens_set_inputs(&in->sens, &in->p);
        in->chain_stale = 0;
        if (s->h.has_out) {
            in->out = s->h.out;
            in->outputs_stale = 0;
            in->bulk_done = 1;  /* the snapshot's outputs are whole (lss_ensure_outputs) */
        }
    } else {
        in->chain_stale = 1;
    }
    in->state = (ModelState)s->h.state;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    CHECK(c, "fmi2SetFMUstate", ST_ANY);
    if (!FMUstate) {
        LOG_ERROR(in, "fmi2SetFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    return restore(in, (const Snapshot *)FMUstate, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    CHECK(c, "fmi2FreeFMUstate", ST_ANY);
    if (!FMUstate) {
        LOG_ERROR(in, "fmi2FreeFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    if (*FMUstate && !is_snapshot(*FMUstate)) {
        LOG_ERROR(in, "fmi2FreeFMUstate: *FMUstate is not an LSSChain FMU state; not freed");
        return fmi2Error;
    }
    if (*FMUstate) {
        ((Snapshot *)*FMUstate)->h.magic = 0;  /* poisoned: a stale copy of the pointer is not a state */
        in->cb.freeMemory(*FMUstate);
    }
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    CHECK(c, "fmi2SerializedFMUstateSize", ST_ANY);
    if (!FMUstate || !size) {
        LOG_ERROR(in, "fmi2SerializedFMUstateSize: NULL argument");
        return fmi2Error;
    }
    if (!is_snapshot(FMUstate)) {
        LOG_ERROR(in, "fmi2SerializedFMUstateSize: not an LSSChain FMU state");
        return fmi2Error;
    }
    const Snapshot *s = FMUstate;
    *size = sizeof(SnapHeader) + s->h.n * sizeof(double);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    CHECK(c, "fmi2SerializeFMUstate", ST_ANY);
    if (!FMUstate || !serializedState) {
        LOG_ERROR(in, "fmi2SerializeFMUstate: NULL argument");
        return fmi2Error;
    }
    if (!is_snapshot(FMUstate)) {
        LOG_ERROR(in, "fmi2SerializeFMUstate: not an LSSChain FMU state");
        return fmi2Error;
    }
    const Snapshot *s = FMUstate;
    size_t need = sizeof(SnapHeader) + s->h.n * sizeof(double);
    if (size < need) {
        LOG_ERROR(in, "fmi2SerializeFMUstate: buffer of %zu bytes, %zu needed", size, need);
        return fmi2Error;
    }
    memcpy(serializedState, s, need);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    CHECK(c, "fmi2DeSerializeFMUstate", ST_ANY);
    if (!serializedState || !FMUstate) {
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: NULL argument");
        return fmi2Error;
    }
    if (*FMUstate && !is_snapshot(*FMUstate)) {
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: *FMUstate is neither NULL nor an LSSChain FMU state");
        return fmi2Error;
    }
    SnapHeader h;
    if (size < sizeof h) {
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: %zu bytes is too short for an LSSChain FMU state", size);
        return fmi2Error;
    }
    memcpy(&h, serializedState, sizeof h);
    if (!is_snapshot(&h) || h.n > (size - sizeof h) / sizeof(double) || size != sizeof h + h.n * sizeof(double)) {
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: the %zu bytes are not an LSSChain FMU state of this version", size);
        return fmi2Error;
    }
    char why[600];
    if (check_header(&h, why, sizeof why)) {
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: %s", why);
        return fmi2Error;
    }
    Snapshot *s = in->cb.allocateMemory(1, size);
    if (!s) {
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    memcpy(s, serializedState, size);  /* aligned copy: the chain part is read as doubles */
    if (check_snapshot(&s->h, s->data, NULL, why, sizeof why)) {
        in->cb.freeMemory(s);
        LOG_ERROR(in, "fmi2DeSerializeFMUstate: %s", why);
        return fmi2Error;
    }
    if (*FMUstate) {
        ((Snapshot *)*FMUstate)->h.magic = 0;
        in->cb.freeMemory(*FMUstate);
    }
    *FMUstate = s;
    return fmi2OK;
}
