/* Forward sensitivities by follower chains on the leader's steps (sensitivity.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "params.h"
#include "sensitivity.h"

static double *real_slot(LSSParams *p, int vr) { return (double *)((char *)p + LSS_VARS[vr].offset); }
static double real_of(const LSSParams *p, int vr) {
    return *(const double *)((const char *)p + LSS_VARS[vr].offset);
}
static int vr_of(const LSSParams *p, int k) {
    return *(const int *)((const char *)p + LSS_VARS[VR_SENSITIVITY_P1_VR + k].offset);
}
static double step_of(const LSSParams *p, int k) { return real_of(p, VR_SENSITIVITY_P1_STEP + k); }

/* What a follower cannot differentiate by: an input (the master sets it at every step, the same for all),
 * the solver's settings and the relaxation's length (the follower takes the leader's steps, not its own),
 * the sensitivities' own set-up, and a value that is not a Real parameter. */
static const char *refused(int vr) {
    if (vr < 1 || vr > LSS_N_VARS) return "not a value reference of this FMU";
    const LSSVarInfo *v = &LSS_VARS[vr];
    if (v->type != LSS_REAL || v->causality != LSS_PARAMETER) return "not a Real parameter";
    if (strncmp(v->name, "solver.", 7) == 0 || strncmp(v->name, "sensitivity.", 12) == 0 ||
        vr == VR_CHAIN_RELAX_TIME)
        return "a setting of the run, not of the model";
    return NULL;
}

int sens_check(const LSSParams *p, char *err, size_t errlen) {
    for (int k = 0; k < p->sensitivity_n; k++) {
        int vr = vr_of(p, k);
        const char *why = refused(vr);
        if (why) {
            snprintf(err, errlen, "sensitivity.p%d.vr = %d: %s", k + 1, vr, why);
            return 1;
        }
        for (int j = 0; j < k; j++)
            if (vr_of(p, j) == vr) {
                snprintf(err, errlen, "sensitivity.p%d.vr = %d (%s) repeats sensitivity.p%d.vr", k + 1, vr,
                         LSS_VARS[vr].name, j + 1);
                return 1;
            }
        double h = step_of(p, k), x = real_of(p, vr);
        if (!(h != 0.0) || !isfinite(h)) {
            snprintf(err, errlen, "sensitivity.p%d.step = %g must be finite and not 0", k + 1, h);
            return 1;
        }
        if (!param_in_range(&LSS_VARS[vr], x + h) || x + h == x) {
            snprintf(err, errlen, "sensitivity.p%d.step = %g moves %s from %.17g to %.17g, %s", k + 1, h,
                     LSS_VARS[vr].name, x, x + h, x + h == x ? "the same value" : "outside its range");
            return 1;
        }
    }
    return 0;
}

void sens_params(const LSSParams *p, int k, LSSParams *out) {
    *out = *p;
    out->sensitivity_n = 0;   /* a follower has no followers of its own */
    int vr = vr_of(p, k);
    *real_slot(out, vr) = real_of(p, vr) + step_of(p, k);
}

void sens_free(Sens *s) {
    for (int k = 0; k < s->n; k++) chain_free(s->f[k]);
    memset(s, 0, sizeof *s);
}

int sens_create(Sens *s, const LSSParams *p, const char *resource_dir, const LSSAlloc *a, char *err, size_t errlen) {
    memset(s, 0, sizeof *s);
    for (int k = 0; k < p->sensitivity_n; k++) {
        LSSParams pk;
        char why[512];
        sens_params(p, k, &pk);
        Chain *f = chain_create(&pk, resource_dir, a, why, sizeof why);
        if (!f) {
            snprintf(err, errlen, "cannot build the follower of sensitivity.p%d (%s = %.17g): %s", k + 1,
                     LSS_VARS[vr_of(p, k)].name, real_of(&pk, vr_of(p, k)), why);
            sens_free(s);
            return 1;
        }
        s->f[s->n++] = f;
    }
    return 0;
}

int sens_build(Sens *s, const Chain *lead, const LSSParams *p, const char *resource_dir, const LSSAlloc *a,
               char *err, size_t errlen) {
    if (sens_create(s, p, resource_dir, a, err, errlen)) return 1;
    if (!(p->chain_relax_time > 0)) return 0;
    double *buf = NULL;
    size_t n = chain_state_size(lead);
    for (int k = 0; k < s->n; k++) {
        char why[512];
        if (chain_relax_ignores(vr_of(p, k))) {
            /* the same relaxation as the leader's, bit for bit: taken, not repeated */
            if (!buf) {
                if (!(buf = a->calloc(n, sizeof(double)))) {
                    snprintf(err, errlen, "out of memory for the followers' state at rest");
                    sens_free(s);
                    return 1;
                }
                chain_state_save(lead, buf);
            }
            LSSParams pk;
            sens_params(p, k, &pk);
            chain_state_load(s->f[k], buf);
            chain_set_inputs(s->f[k], &pk);
        } else if (chain_relax_replay(s->f[k], &lead->trace, why, sizeof why)) {
            snprintf(err, errlen, "the follower of sensitivity.p%d (%s) could not relax on the leader's steps: %s",
                     k + 1, LSS_VARS[vr_of(p, k)].name, why);
            if (buf) a->free(buf);
            sens_free(s);
            return 1;
        }
    }
    if (buf) a->free(buf);
    return 0;
}

int sens_step(Sens *s, const Chain *lead, const LSSParams *p, char *err, size_t errlen) {
    for (int k = 0; k < s->n; k++) {
        char why[512];
        if (chain_replay(s->f[k], &lead->trace, why, sizeof why)) {
            snprintf(err, errlen, "the follower of sensitivity.p%d (%s): %s", k + 1, LSS_VARS[vr_of(p, k)].name, why);
            return 1;
        }
    }
    return 0;
}

void sens_set_inputs(Sens *s, const LSSParams *p) {
    for (int k = 0; k < s->n; k++) {
        LSSParams pk;
        sens_params(p, k, &pk);
        chain_set_inputs(s->f[k], &pk);
    }
}

void sens_outputs(Sens *s, const LSSParams *p, LSSOutputs *out) {
    LSSOutputs fo;
    for (int k = 0; k < SENS_MAX; k++)
        for (int j = 0; j < SENS_CHANNELS; j++) {
            const LSSVarInfo *d = &LSS_VARS[VR_SENSITIVITY_P1_JOINT_F_X + SENS_CHANNELS * k + j];
            double *slot = (double *)((char *)out + d->offset);
            *slot = 0.0;
            if (k >= s->n) continue;
            if (j == 0) chain_outputs_light(s->f[k], &fo);  /* the transducer's channels */
            size_t off = LSS_VARS[VR_TRANSDUCER_JOINT_F_X + j].offset;
            double yf = *(const double *)((const char *)&fo + off), y = *(const double *)((const char *)out + off);
            *slot = (yf - y) / step_of(p, k);
        }
}
