/* What the two plant FMUs of examples/plant share: the FMI 2.0 functions
 * neither supports, answered with fmi2Error, the ones with nothing to do,
 * and the logging helper. Each
 * FMU defines its own instance type and the functions it supports. */
#ifndef PLANT_FMU_COMMON_H
#define PLANT_FMU_COMMON_H

#include <stdarg.h>
#include <stdio.h>

#include "fmi2Functions.h"

/* Logs through the master's callback (if it gave one). */
static void plant_log(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status, const char *fmt, ...) {
    if (!cb || !cb->logger) return;
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    cb->logger(cb->componentEnvironment, name, status, status == fmi2OK ? "logAll" : "logStatusError", "%s", msg);
}

#define UNSUPPORTED(decl) decl { return fmi2Error; }
#pragma GCC diagnostic ignored "-Wunused-parameter"
UNSUPPORTED(fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]))
UNSUPPORTED(fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]))
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
#pragma GCC diagnostic warning "-Wunused-parameter"

/* Nothing to do in either FMU: logging categories are not filtered, initialisation and termination keep no resources. */
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)on; (void)n; (void)cat;
    return c ? fmi2OK : fmi2Error;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return c ? fmi2OK : fmi2Error; }
fmi2Status fmi2Terminate(fmi2Component c) { return c ? fmi2OK : fmi2Error; }

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

#endif
