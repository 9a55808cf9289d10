/* SpeedProfile: a minimal FMI 2.0 co-simulation FMU for the system tests
 * (tests/test_cosimulation.py compiles it with gcc against fmpy's headers).
 * One output, v_ref, a speed step: v0 before t_step, v1 from t_step on
 * (value at the end of each communication step). Value references:
 * 1 v0, 2 v1, 3 t_step (parameters), 4 v_ref (output). */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define GUID "{8c4e810f-3df3-4a00-8276-176fa3c9f001}"

typedef struct {
    fmi2CallbackFunctions cb;
    double v[5];  /* indexed by value reference */
    double time;
    int initialised;
} Profile;

static void update(Profile *p) { p->v[4] = p->time >= p->v[3] - 1e-12 ? p->v[2] : p->v[1]; }

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    (void)name; (void)res; (void)visible; (void)logging;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID) || !cb || !cb->allocateMemory) return NULL;
    Profile *p = cb->allocateMemory(1, sizeof(Profile));
    if (!p) return NULL;
    memcpy((void *)&p->cb, cb, sizeof *cb);
    p->v[1] = 2.0;
    p->v[2] = 1.5;
    p->v[3] = 0.3;
    update(p);
    return p;
}

void fmi2FreeInstance(fmi2Component c) {
    Profile *p = c;
    if (p) p->cb.freeMemory(p);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real start, fmi2Boolean sd,
                               fmi2Real stop) {
    (void)td; (void)tol; (void)sd; (void)stop;
    Profile *p = c;
    p->time = start;
    update(p);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Profile *p = c;
    p->initialised = 1;
    update(p);
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) {
    Profile *p = c;
    p->time = 0;
    update(p);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Profile *p = c;
    update(p);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < 1 || vr[i] > 4) return fmi2Error;
        value[i] = p->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Profile *p = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < 1 || vr[i] > 3) return fmi2Error;
        p->v[vr[i]] = value[i];
    }
    update(p);
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    (void)no_prior;
    Profile *p = c;
    p->time = t + h;
    update(p);
    return fmi2OK;
}

#define UNSUPPORTED(decl) decl { return fmi2Error; }
#pragma GCC diagnostic ignored "-Wunused-parameter"
UNSUPPORTED(fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]))
UNSUPPORTED(fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]))
UNSUPPORTED(fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]))
UNSUPPORTED(fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]))
UNSUPPORTED(fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]))
UNSUPPORTED(fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]))
UNSUPPORTED(fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s))
UNSUPPORTED(fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s))
UNSUPPORTED(fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s))
UNSUPPORTED(fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n))
UNSUPPORTED(fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n))
UNSUPPORTED(fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s))
UNSUPPORTED(fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                                    const fmi2ValueReference k[], size_t nk, const fmi2Real dk[],
                                                    fmi2Real du[]))
UNSUPPORTED(fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                   const fmi2Integer o[], const fmi2Real v[]))
UNSUPPORTED(fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                                    const fmi2Integer o[], fmi2Real v[]))
UNSUPPORTED(fmi2Status fmi2CancelStep(fmi2Component c))
UNSUPPORTED(fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v))
UNSUPPORTED(fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v))
UNSUPPORTED(fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v))
UNSUPPORTED(fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v))
UNSUPPORTED(fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v))
