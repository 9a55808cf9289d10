/* FMI 2.0 Co-Simulation entry points: instance life cycle, the state machine,
 * get/set through the generated variable table, logging (FMU state copies
 * and their format: fmu_state.c).
 * No physics here: the chain is reached through chain.h only. The instance
 * holds everything; there is no global mutable state. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2_instance.h"
#include "params.h"
#include "lss_guid.h"

/* --- logging --------------------------------------------------------------- */

void lss_log(const Instance *in, fmi2Status status, const char *category, const char *fmt, ...) {
    if (!in || !in->cb.logger) return;
    if (status == fmi2OK && !in->log_all) return;
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    /* the message is a format string to the logger: double every '%' so the
     * text arrives as written whether or not the logger formats it */
    char esc[2048];
    size_t k = 0;
    for (const char *q = buf; *q && k + 2 < sizeof esc; q++) {
        if (*q == '%') esc[k++] = '%';
        esc[k++] = *q;
    }
    esc[k] = '\0';
    in->cb.logger(in->cb.componentEnvironment, in->name, status, category, esc);
}

const char *lss_state_name(ModelState s) {
    switch (s) {
    case ST_INSTANTIATED: return "Instantiated";
    case ST_INIT: return "Initialization Mode";
    case ST_STEP_COMPLETE: return "Step Mode";
    case ST_STEP_FAILED: return "Step Failed (after a discarded step)";
    case ST_TERMINATED: return "Terminated";
    case ST_ERROR: return "Error";
    }
    return "?";
}

int lss_allowed(Instance *in, const char *fn, int mask) {
    if (in->state & mask) return 1;
    LOG_ERROR(in, "%s() may not be called in state %s", fn, lss_state_name(in->state));
    return 0;
}

/* --- resources ------------------------------------------------------------- */

static int hexval(char ch) {
    if (ch >= '0' && ch <= '9') return ch - '0';
    if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
    if (ch >= 'A' && ch <= 'F') return ch - 'A' + 10;
    return -1;
}

/* file:///a%20b/ -> /a b (also file:/a, file://localhost/a; file://host/a
 * only on Windows, as a UNC path); 0 on success */
static int decode_file_uri(const char *uri, char *out, size_t outlen) {
    const char *p = uri;
    if (strncmp(p, "file://localhost/", 17) == 0) p += 16;
    else if (strncmp(p, "file:///", 8) == 0) p += 7;
    else if (strncmp(p, "file://", 7) == 0) {
#ifdef _WIN32
        p += 5;  /* //host/share: a UNC path */
#else
        return 1;  /* a remote host */
#endif
    } else if (strncmp(p, "file:/", 6) == 0) p += 5;
    else return 1;
#ifdef _WIN32
    if (p[0] == '/' && p[2] == ':') p++;
#endif
    size_t n = 0;
    while (*p) {
        char ch = *p++;
        if (ch == '%') {
            int h = hexval(p[0]), l = h < 0 ? -1 : hexval(p[1]);
            if (h < 0 || l < 0) return 1;
            ch = (char)(h * 16 + l);
            if (ch == '\0') return 1;  /* %00 would cut the path short */
            p += 2;
        }
        if (n + 1 >= outlen) return 1;
        out[n++] = ch;
    }
    while (n > 1 && (out[n - 1] == '/' || out[n - 1] == '\\')) n--;
    out[n] = '\0';
    return 0;
}

/* --- the chain ----------------------------------------------------------------- */

static fmi2Status build_chain(Instance *in) {
    char err[1024];
    LSSParams p = in->p;
    if (in->tolerance_defined) p.solver_tolerance = in->tolerance;
    if (sens_check(&p, err, sizeof err)) {
        LOG_ERROR(in, "cannot build the chain: %s", err);
        return fmi2Error;
    }
    Chain *c = chain_create(&p, in->has_resources ? in->resource_dir : NULL, &in->alloc, err, sizeof err);
    if (!c) {
        /* a parse error names the file already; a chain that cannot be assembled on a
           well-formed layout must still say which layout */
        if (strstr(err, p.layout_name))
            LOG_ERROR(in, "cannot build the chain: %s", err);
        else
            LOG_ERROR(in, "cannot build the chain: %s (layout.name = '%s')", err, p.layout_name);
        return fmi2Error;
    }
    chain_trace(c, p.sensitivity_n > 0);   /* the followers take the leader's steps */
    if (p.chain_relax_time > 0 && chain_relax(c, p.chain_relax_time, err, sizeof err)) {
        chain_free(c);
        LOG_ERROR(in, "cannot relax the chain at rest for chain.relax_time = %g s: %s", p.chain_relax_time, err);
        return fmi2Error;
    }
    Sens sens;
    if (sens_build(&sens, c, &p, in->has_resources ? in->resource_dir : NULL, &in->alloc, err, sizeof err)) {
        chain_free(c);
        LOG_ERROR(in, "cannot set up the sensitivities: %s", err);
        return fmi2Error;
    }
    chain_trace(c, p.sensitivity_n > 0);   /* the relaxation's steps are taken: record the run's afresh */
    sens_free(&in->sens);
    in->sens = sens;
    chain_free(in->chain);
    in->chain = c;
    in->chain_stale = 0;
    in->outputs_stale = 1;
    return fmi2OK;
}

fmi2Status lss_ensure_outputs_part(Instance *in, int bulk) {
    if (!in->chain || in->chain_stale) {
        if (build_chain(in) != fmi2OK) return fmi2Error;
    }
    if (in->outputs_stale) {
        chain_outputs_light(in->chain, &in->out);
        sens_outputs(&in->sens, &in->p, &in->out);
        in->outputs_stale = 0;
        in->bulk_done = 0;
    }
    if (bulk && !in->bulk_done) {  /* at the same state: any change sets outputs_stale */
        chain_outputs_bulk(in->chain, &in->out);
        in->bulk_done = 1;
    }
    return fmi2OK;
}

fmi2Status lss_ensure_outputs(Instance *in) { return lss_ensure_outputs_part(in, 1); }

/* --- instance life cycle ------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    CHECK(c, "fmi2SetDebugLogging", ST_ANY);
    if (nCategories > 0 && !categories) {
        LOG_ERROR(in, "fmi2SetDebugLogging: categories is NULL but nCategories = %zu", nCategories);
        return fmi2Error;
    }
    for (size_t i = 0; i < nCategories; i++) {
        const char *k = categories[i];
        if (!k || (strcmp(k, "logStatusError") && strcmp(k, "logStatusWarning") &&
                   strcmp(k, "logStatusDiscard") && strcmp(k, "logAll"))) {
            LOG_ERROR(in, "fmi2SetDebugLogging: unknown log category \"%s\"", k ? k : "(null)");
            return fmi2Error;
        }
    }
    in->log_all = loggingOn ? 1 : 0;  /* only once the call is known to be valid */
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    if (!functions) return NULL;  /* nobody to tell */
    Instance tmp;  /* for logging before the instance exists */
    memset(&tmp, 0, sizeof tmp);
    tmp.cb = *functions;
    snprintf(tmp.name, sizeof tmp.name, "%s", instanceName ? instanceName : "");
    if (!functions->allocateMemory || !functions->freeMemory) {
        LOG_ERROR(&tmp, "fmi2Instantiate: the callback functions allocateMemory and freeMemory are required");
        return NULL;
    }
    if (!instanceName || !instanceName[0]) {
        LOG_ERROR(&tmp, "fmi2Instantiate: instanceName must be a non-empty string");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        LOG_ERROR(&tmp, "fmi2Instantiate: LSSChain is a co-simulation FMU; model exchange is not supported");
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, LSS_GUID) != 0) {
        LOG_ERROR(&tmp, "fmi2Instantiate: GUID \"%s\" does not match this binary's \"%s\"",
                  fmuGUID ? fmuGUID : "(null)", LSS_GUID);
        return NULL;
    }
    Instance *in = functions->allocateMemory(1, sizeof(Instance));
    if (!in) {
        LOG_ERROR(&tmp, "fmi2Instantiate: out of memory");
        return NULL;
    }
    *in = tmp;
    in->alloc.calloc = functions->allocateMemory;
    in->alloc.free = functions->freeMemory;
    in->log_all = loggingOn ? 1 : 0;
    in->state = ST_INSTANTIATED;
    lss_params_defaults(&in->p);
    if (fmuResourceLocation && fmuResourceLocation[0]) {
        if (decode_file_uri(fmuResourceLocation, in->resource_dir, sizeof in->resource_dir) == 0)
            in->has_resources = 1;
        else
            lss_log(in, fmi2Warning, "logStatusWarning",
                   "cannot use resource location \"%s\": built-in layouts unavailable", fmuResourceLocation);
    }
    return in;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *in = (Instance *)c;
    if (!in) return;
    sens_free(&in->sens);
    chain_free(in->chain);
    in->cb.freeMemory(in);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    CHECK(c, "fmi2SetupExperiment", ST_INSTANTIATED);
    if (!isfinite(startTime)) {
        LOG_ERROR(in, "fmi2SetupExperiment: startTime = %g is not finite", startTime);
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        LOG_ERROR(in, "fmi2SetupExperiment: stopTime = %g is before startTime = %g", stopTime, startTime);
        return fmi2Error;
    }
    if (toleranceDefined && !(tolerance > 0 && tolerance <= 0.1)) {
        LOG_ERROR(in, "fmi2SetupExperiment: tolerance = %g must lie in (0, 0.1]", tolerance);
        return fmi2Error;
    }
    fmi2Status status = fmi2OK;
    if (toleranceDefined && tolerance < TOL_FLOOR) {
        lss_log(in, fmi2Warning, "logStatusWarning",
               "fmi2SetupExperiment: tolerance = %g is below %g, the smallest the solver can honour in "
               "double precision; using %g", tolerance, TOL_FLOOR, TOL_FLOOR);
        tolerance = TOL_FLOOR;
        status = fmi2Warning;
    }
    in->tolerance_defined = toleranceDefined ? 1 : 0;
    in->tolerance = tolerance;
    in->stop_time_defined = stopTimeDefined ? 1 : 0;
    in->stop_time = stopTimeDefined ? stopTime : 0.0;
    in->start_time = in->time = startTime;
    in->chain_stale = 1;
    in->setup_done = 1;
    return status;
}

/* FMI 2.0 has fmi2SetupExperiment called before fmi2EnterInitializationMode.
 * Without it the call is accepted with the defaults a master would most
 * likely mean (startTime 0, no stop time, solver.tolerance) and fmi2Warning
 * with a message (docs/robustness.md): refusing would break masters that
 * skip it, guessing silently would hide their mistake. */
fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    CHECK(c, "fmi2EnterInitializationMode", ST_INSTANTIATED);
    fmi2Status status = fmi2OK;
    if (!in->setup_done) {
        in->tolerance_defined = in->stop_time_defined = 0;
        in->stop_time = 0.0;
        in->start_time = in->time = 0.0;
        in->chain_stale = 1;
        in->setup_done = 1;
        lss_log(in, fmi2Warning, "logStatusWarning",
                "fmi2EnterInitializationMode without fmi2SetupExperiment: using startTime = 0, no stopTime and "
                "the tolerance solver.tolerance = %g", in->p.solver_tolerance);
        status = fmi2Warning;
    }
    in->state = ST_INIT;
    return status;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    CHECK(c, "fmi2ExitInitializationMode", ST_INIT);
    if ((!in->chain || in->chain_stale) && build_chain(in) != fmi2OK) return fmi2Error;
    in->time = in->start_time;
    in->state = ST_STEP_COMPLETE;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CHECK(c, "fmi2Terminate", ST_STEP_COMPLETE | ST_STEP_FAILED | ST_ERROR | ST_INIT);
    in->state = ST_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    CHECK(c, "fmi2Reset", ST_ANY);
    sens_free(&in->sens);
    chain_free(in->chain);
    in->chain = NULL;
    lss_params_defaults(&in->p);
    in->state = ST_INSTANTIATED;
    in->tolerance_defined = 0;
    in->stop_time_defined = 0;
    in->stop_time = 0.0;
    in->start_time = in->time = 0.0;
    in->chain_stale = 1;
    in->setup_done = 0;
    in->thrust_set = in->thrust_warned = 0;
    return fmi2OK;
}

/* --- get and set --------------------------------------------------------------- */

static const LSSVarInfo *lookup(Instance *in, const char *fn, fmi2ValueReference vr, LSSType type) {
    static const char *tn[] = {"Real", "Integer", "Boolean", "String"};
    if (vr < 1 || vr > LSS_N_VARS) {
        LOG_ERROR(in, "%s: unknown value reference %u", fn, vr);
        return NULL;
    }
    const LSSVarInfo *v = &LSS_VARS[vr];
    if (v->type != type) {
        LOG_ERROR(in, "%s: %s (value reference %u) is of type %s, not %s", fn, v->name, vr, tn[v->type], tn[type]);
        return NULL;
    }
    return v;
}

static void *slot_of(Instance *in, const LSSVarInfo *v) {
    return v->in_params ? (char *)&in->p + v->offset : (char *)&in->out + v->offset;
}

static fmi2Status begin_get(Instance *in, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                            const void *value, LSSType type) {
    if (nvr == 0) return fmi2OK;
    if (!vr || !value) {
        LOG_ERROR(in, "%s: NULL array with nvr = %zu", fn, nvr);
        return fmi2Error;
    }
    int needs_outputs = 0, needs_bulk = 0;
    for (size_t i = 0; i < nvr; i++) {
        const LSSVarInfo *v = lookup(in, fn, vr[i], type);
        if (!v) return fmi2Error;
        if (!v->in_params) {
            needs_outputs = 1;
            needs_bulk |= v->bulk;
        }
    }
    if (needs_outputs) {
        if (!(in->state & ST_READ)) {
            LOG_ERROR(in, "%s: outputs and calculated parameters can be read from Initialization Mode on, "
                      "not in state %s", fn, lss_state_name(in->state));
            return fmi2Error;
        }
        return lss_ensure_outputs_part(in, needs_bulk);
    }
    return fmi2OK;
}

#define DEFINE_GET(NAME, CTYPE, LTYPE, FIELDTYPE)                                               \
    fmi2Status NAME(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, CTYPE value[]) { \
        CHECK(c, #NAME, ST_ANY);                                                                \
        fmi2Status s = begin_get(in, #NAME, vr, nvr, value, LTYPE);                              \
        if (s != fmi2OK) return s;                                                              \
        for (size_t i = 0; i < nvr; i++)                                                        \
            value[i] = (CTYPE) * (FIELDTYPE *)slot_of(in, &LSS_VARS[vr[i]]);                    \
        return fmi2OK;                                                                          \
    }

DEFINE_GET(fmi2GetReal, fmi2Real, LSS_REAL, double)
DEFINE_GET(fmi2GetInteger, fmi2Integer, LSS_INTEGER, int)
DEFINE_GET(fmi2GetBoolean, fmi2Boolean, LSS_BOOLEAN, int)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    CHECK(c, "fmi2GetString", ST_ANY);
    fmi2Status s = begin_get(in, "fmi2GetString", vr, nvr, value, LSS_STRING);
    if (s != fmi2OK) return s;
    for (size_t i = 0; i < nvr; i++) value[i] = (const char *)slot_of(in, &LSS_VARS[vr[i]]);
    return fmi2OK;
}

/* May variable v be set now? Parameters before and during initialisation,
 * tunable parameters and inputs also in Step Mode. */
static int settable(Instance *in, const char *fn, const LSSVarInfo *v) {
    if (!v->in_params) {
        LOG_ERROR(in, "%s: %s is computed by the model and cannot be set", fn, v->name);
        return 0;
    }
    int mask = ST_INSTANTIATED | ST_INIT;
    if (v->causality == LSS_INPUT || v->variability == LSS_TUNABLE) mask |= ST_STEP_COMPLETE;
    if (!(in->state & mask)) {
        LOG_ERROR(in, "%s: %s cannot be set in state %s%s", fn, v->name, lss_state_name(in->state),
                  v->variability == LSS_FIXED ? " (a fixed parameter: set it before fmi2ExitInitializationMode)" : "");
        return 0;
    }
    return 1;
}

/* After a value was stored: check the parameter set as a whole, adopt it. */
static fmi2Status commit(Instance *in, const char *fn, const LSSParams *backup, const LSSVarInfo *v) {
    char err[512];
    /* the sensitivities' rules bind once the chain is built: before, their values may come in any order */
    if (chain_check_params(&in->p, err, sizeof err) ||
        (in->state == ST_STEP_COMPLETE && sens_check(&in->p, err, sizeof err))) {
        in->p = *backup;
        LOG_ERROR(in, "%s: %s", fn, err);
        return fmi2Error;
    }
    if (in->state == ST_STEP_COMPLETE) {
        if (in->chain && chain_check_inputs(in->chain, &in->p, err, sizeof err)) {
            in->p = *backup;
            LOG_ERROR(in, "%s: %s", fn, err);
            return fmi2Error;
        }
        chain_set_inputs(in->chain, &in->p);
        sens_set_inputs(&in->sens, &in->p);
        in->outputs_stale = 1;
    } else if (v->variability == LSS_FIXED || in->state == ST_INIT || v->causality == LSS_INPUT) {
        in->chain_stale = 1;
    }
    return fmi2OK;
}

/* A motor group's thrust input (drive.groupK.F)? */
static int is_group_thrust(const LSSVarInfo *v) {
    size_t n = strlen(v->name);
    return strncmp(v->name, "drive.group", 11) == 0 && n > 2 && strcmp(v->name + n - 2, ".F") == 0;
}

static fmi2Status set_number(Instance *in, const char *fn, fmi2ValueReference vr, LSSType type, double x) {
    const LSSVarInfo *v = lookup(in, fn, vr, type);
    if (!v || !settable(in, fn, v)) return fmi2Error;
    if (is_group_thrust(v)) {
        in->thrust_set = 1;
        if (isfinite(x) && fabs(x) > in->p.drive_F_max && fabs(x) <= 1e6)
            lss_log(in, fmi2Warning, "logStatusWarning", "%s: %s = %g N is beyond the motors' rating "
                    "drive.F_max = %g N: saturated to %g N", fn, v->name, x, in->p.drive_F_max,
                    x > 0 ? in->p.drive_F_max : -in->p.drive_F_max);
    }
    LSSParams backup = in->p;
    void *slot = slot_of(in, v);
    if (type == LSS_REAL) *(double *)slot = x;
    else *(int *)slot = (int)x;
    return commit(in, fn, &backup, v);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    CHECK(c, "fmi2SetReal", ST_ANY);
    if (nvr > 0 && (!vr || !value)) {
        LOG_ERROR(in, "fmi2SetReal: NULL array with nvr = %zu", nvr);
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++)
        if (set_number(in, "fmi2SetReal", vr[i], LSS_REAL, value[i]) != fmi2OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    CHECK(c, "fmi2SetInteger", ST_ANY);
    if (nvr > 0 && (!vr || !value)) {
        LOG_ERROR(in, "fmi2SetInteger: NULL array with nvr = %zu", nvr);
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++)
        if (set_number(in, "fmi2SetInteger", vr[i], LSS_INTEGER, value[i]) != fmi2OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    CHECK(c, "fmi2SetBoolean", ST_ANY);
    if (nvr > 0 && (!vr || !value)) {
        LOG_ERROR(in, "fmi2SetBoolean: NULL array with nvr = %zu", nvr);
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++)
        if (set_number(in, "fmi2SetBoolean", vr[i], LSS_BOOLEAN, value[i] ? 1 : 0) != fmi2OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    CHECK(c, "fmi2SetString", ST_ANY);
    if (nvr > 0 && (!vr || !value)) {
        LOG_ERROR(in, "fmi2SetString: NULL array with nvr = %zu", nvr);
        return fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        const LSSVarInfo *v = lookup(in, "fmi2SetString", vr[i], LSS_STRING);
        if (!v || !settable(in, "fmi2SetString", v)) return fmi2Error;
        if (!value[i]) {
            LOG_ERROR(in, "fmi2SetString: %s = NULL", v->name);
            return fmi2Error;
        }
        if (strlen(value[i]) >= LSS_STRING_MAX) {
            LOG_ERROR(in, "fmi2SetString: %s is %zu characters long (at most %d)", v->name, strlen(value[i]),
                      LSS_STRING_MAX - 1);
            return fmi2Error;
        }
        LSSParams backup = in->p;
        char *slot = slot_of(in, v);
        memmove(slot, value[i], strlen(value[i]) + 1);
        if (commit(in, "fmi2SetString", &backup, v) != fmi2OK) return fmi2Error;
    }
    return fmi2OK;
}

/* --- stepping -------------------------------------------------------------- */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK(c, "fmi2DoStep", ST_STEP_COMPLETE);
    if (!isfinite(t) || !isfinite(h) || h < 0) {
        LOG_ERROR(in, "fmi2DoStep: currentCommunicationPoint = %g, communicationStepSize = %g: "
                  "both must be finite and the step non-negative", t, h);
        return fmi2Error;
    }
    double tol = 1e-9 * (fabs(in->time) + 1.0);
    if (fabs(t - in->time) > tol) {
        LOG_ERROR(in, "fmi2DoStep: currentCommunicationPoint = %.17g but the FMU is at t = %.17g", t, in->time);
        return fmi2Error;
    }
    if (in->stop_time_defined && t + h > in->stop_time + 1e-9 * (fabs(in->stop_time) + 1.0)) {
        LOG_ERROR(in, "fmi2DoStep: a step from t = %.17g by %.17g s goes past stopTime = %.17g "
                  "given to fmi2SetupExperiment", t, h, in->stop_time);
        return fmi2Error;
    }
    if (!in->chain || in->chain_stale) {  /* cannot happen through a valid call sequence */
        LOG_ERROR(in, "fmi2DoStep: the chain was not built (internal state inconsistent); call fmi2Reset");
        return fmi2Error;
    }
    char err[512];
    double t_end = t + h - in->start_time, t_tol = 1e-9 * (fabs(t_end) + 1.0);
    if (!(fabs(in->chain->st.ode.t - (in->time - in->start_time)) <= t_tol + 1e-9 * fabs(h))) {
        LOG_ERROR(in, "fmi2DoStep: the chain is at %.17g s but the FMU at %.17g s after the start (internal state "
                  "inconsistent); call fmi2Reset or set a valid FMU state", in->chain->st.ode.t,
                  in->time - in->start_time);
        return fmi2Error;
    }
    if (in->p.drive_mode == DRIVE_EXTERNAL && !in->thrust_set && !in->thrust_warned) {
        in->thrust_warned = 1;
        lss_log(in, fmi2Warning, "logStatusWarning", "fmi2DoStep: drive.mode = 1 (external thrust) but no "
                "drive.groupK.F input has been set: the motors push with 0 N until the master sets them");
    }
    if (in->sens.n) chain_trace(in->chain, 1);
    if (chain_step(in->chain, t_end, err, sizeof err) != 0 ||
        sens_step(&in->sens, in->chain, &in->p, err, sizeof err) != 0) {
        in->state = ST_STEP_FAILED;
        in->outputs_stale = 1;
        lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2DoStep from t = %g: %s", t, err);
        return fmi2Discard;
    }
    if (!(fabs(in->chain->st.ode.t - t_end) <= t_tol)) {  /* cannot happen: the solver lands on t_end */
        in->state = ST_STEP_FAILED;
        in->outputs_stale = 1;
        lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2DoStep from t = %g: the solver stopped at %.17g s, "
                "not at %.17g s", t, in->chain->st.ode.t + in->start_time, t + h);
        return fmi2Discard;
    }
    in->time = t + h;
    in->outputs_stale = 1;
    lss_log(in, fmi2OK, "logAll", "fmi2DoStep to t = %g: %ld steps, %ld rejected, last step %g s",
           in->time, in->chain->st.ode.n_steps, in->chain->st.ode.n_rejected, in->chain->st.ode.h_last);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    CHECK(c, "fmi2CancelStep", ST_ANY);
    LOG_ERROR(in, "fmi2CancelStep: fmi2DoStep never runs asynchronously in LSSChain");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    CHECK(c, "fmi2GetStatus", ST_ANY);
    (void)s; (void)value;
    lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2GetStatus: no asynchronous step is pending");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    CHECK(c, "fmi2GetRealStatus", ST_ANY);
    if (!value) {
        LOG_ERROR(in, "fmi2GetRealStatus: value is NULL");
        return fmi2Error;
    }
    if (s == fmi2LastSuccessfulTime) {
        *value = in->time;
        return fmi2OK;
    }
    lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2GetRealStatus: only fmi2LastSuccessfulTime is available");
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    CHECK(c, "fmi2GetIntegerStatus", ST_ANY);
    (void)s; (void)value;
    lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2GetIntegerStatus: no integer status is available");
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    CHECK(c, "fmi2GetBooleanStatus", ST_ANY);
    if (!value) {
        LOG_ERROR(in, "fmi2GetBooleanStatus: value is NULL");
        return fmi2Error;
    }
    if (s == fmi2Terminated) {
        *value = fmi2False;  /* the model never asks to stop */
        return fmi2OK;
    }
    lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2GetBooleanStatus: only fmi2Terminated is available");
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    CHECK(c, "fmi2GetStringStatus", ST_ANY);
    (void)s; (void)value;
    lss_log(in, fmi2Discard, "logStatusDiscard", "fmi2GetStringStatus: no string status is available");
    return fmi2Discard;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    CHECK(c, "fmi2SetRealInputDerivatives", ST_ANY);
    (void)vr; (void)nvr; (void)order; (void)value;
    LOG_ERROR(in, "fmi2SetRealInputDerivatives: LSSChain does not interpolate inputs");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    CHECK(c, "fmi2GetRealOutputDerivatives", ST_ANY);
    (void)vr; (void)nvr; (void)order; (void)value;
    LOG_ERROR(in, "fmi2GetRealOutputDerivatives: LSSChain provides no output derivatives");
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    CHECK(c, "fmi2GetDirectionalDerivative", ST_ANY);
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    LOG_ERROR(in, "fmi2GetDirectionalDerivative: LSSChain provides no directional derivatives");
    return fmi2Error;
}

/* --- model exchange: not provided, but exported so every entry point exists --- */

#define NOT_ME(fn)                                                                     \
    Instance *in = (Instance *)c;                                                      \
    if (in) LOG_ERROR(in, fn ": LSSChain is a co-simulation FMU, not model exchange"); \
    return fmi2Error;

fmi2Status fmi2EnterEventMode(fmi2Component c) { NOT_ME("fmi2EnterEventMode") }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { (void)e; NOT_ME("fmi2NewDiscreteStates") }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { NOT_ME("fmi2EnterContinuousTimeMode") }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean a, fmi2Boolean *b, fmi2Boolean *d) {
    (void)a; (void)b; (void)d;
    NOT_ME("fmi2CompletedIntegratorStep")
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { (void)t; NOT_ME("fmi2SetTime") }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    (void)x; (void)n;
    NOT_ME("fmi2SetContinuousStates")
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { (void)d; (void)n; NOT_ME("fmi2GetDerivatives") }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real e[], size_t n) {
    (void)e; (void)n;
    NOT_ME("fmi2GetEventIndicators")
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)x; (void)n;
    NOT_ME("fmi2GetContinuousStates")
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)x; (void)n;
    NOT_ME("fmi2GetNominalsOfContinuousStates")
}
