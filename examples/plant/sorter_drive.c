/* SorterDrive: the drives of a loop sorter as a plant engineer models them,
 * an FMI 2.0 co-simulation FMU. A speed controller (PI on the chain speed it
 * reads, its set point ramped up from 0) commands the thrust of every linear
 * motor; the motors follow the command with a first-order lag (their current
 * loop), saturated at their rating. LSSChain's external drive takes the
 * thrust (drive.groupK.F).
 *
 * Value references: 1 v_set (m/s), 2 t_ramp (s), 3 Kp (N s/m), 4 Ki (N/m),
 * 5 tau (s), 6 F_max (N): parameters; 7 v (m/s): input, the chain speed;
 * 8 F (N): output, the thrust per motor; 9 v_ref (m/s): output, the ramped
 * set point. Inside a communication step the input is held; the controller
 * and the lag advance in substeps of at most tau / 10 (explicit Euler). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define GUID "{6a3f0e52-3c1b-4f7e-9a0e-51d0c2b7e801}"
#define NV 10

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    double v[NV];      /* by value reference */
    double z;          /* the PI's integral of the speed error, m */
    double time;
    int initialised;
} Drive;

static double ramp(const Drive *d, double t) {
    double tr = d->v[2];
    return tr > 0 && t < tr ? d->v[1] * t / tr : d->v[1];
}

static fmi2Status check(Drive *d) {
    const char *names[] = {"", "v_set", "t_ramp", "Kp", "Ki", "tau", "F_max", "v"};
    for (int k = 1; k <= 7; k++)
        if (!isfinite(d->v[k])) {
            plant_log(&d->cb, d->name, fmi2Error, "%s = %g is not a finite number", names[k], d->v[k]);
            return fmi2Error;
        }
    if (!(d->v[5] > 0) || !(d->v[6] > 0) || d->v[2] < 0 || d->v[3] < 0 || d->v[4] < 0) {
        plant_log(&d->cb, d->name, fmi2Error, "tau = %g s and F_max = %g N must be positive, t_ramp = %g s, "
                  "Kp = %g and Ki = %g not negative", d->v[5], d->v[6], d->v[2], d->v[3], d->v[4]);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    (void)res; (void)visible; (void)logging;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID) || !cb || !cb->allocateMemory) return NULL;
    Drive *d = cb->allocateMemory(1, sizeof(Drive));
    if (!d) return NULL;
    memcpy((void *)&d->cb, cb, sizeof *cb);
    snprintf(d->name, sizeof d->name, "%s", name ? name : "drive");
    const double start[NV] = {0, 1.5, 0.5, 2000.0, 1000.0, 0.02, 400.0, 0.0, 0.0, 0.0};
    memcpy(d->v, start, sizeof start);
    return d;
}

void fmi2FreeInstance(fmi2Component c) {
    Drive *d = c;
    if (d) d->cb.freeMemory(d);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real start, fmi2Boolean sd,
                               fmi2Real stop) {
    (void)td; (void)tol; (void)sd; (void)stop;
    Drive *d = c;
    if (!d) return fmi2Error;
    d->time = start;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Drive *d = c;
    if (!d || check(d) != fmi2OK) return fmi2Error;
    d->initialised = 1;
    d->z = 0.0;
    d->v[8] = 0.0;
    d->v[9] = ramp(d, d->time);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Drive *d = c;
    if (!d) return fmi2Error;
    const double start[NV] = {0, 1.5, 0.5, 2000.0, 1000.0, 0.02, 400.0, 0.0, 0.0, 0.0};
    memcpy(d->v, start, sizeof start);
    d->z = d->time = 0.0;
    d->initialised = 0;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Drive *d = c;
    if (!d || (n && (!vr || !value))) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < 1 || vr[i] >= NV) {
            plant_log(&d->cb, d->name, fmi2Error, "fmi2GetReal: no Real variable with value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = d->v[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Drive *d = c;
    if (!d || (n && (!vr || !value))) return fmi2Error;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] < 1 || vr[i] > 7 || (d->initialised && vr[i] != 7)) {
            plant_log(&d->cb, d->name, fmi2Error, "fmi2SetReal: value reference %u cannot be set now", vr[i]);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            plant_log(&d->cb, d->name, fmi2Error, "fmi2SetReal: value reference %u = %g is not finite", vr[i],
                      value[i]);
            return fmi2Error;
        }
        d->v[vr[i]] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    (void)vr; (void)v;
    return c && n == 0 ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    (void)vr; (void)v;
    return c && n == 0 ? fmi2OK : fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    (void)no_prior;
    Drive *d = c;
    if (!d || !d->initialised || !(h > 0) || !isfinite(t + h)) return fmi2Error;
    double Kp = d->v[3], Ki = d->v[4], tau = d->v[5], Fm = d->v[6], v = d->v[7];
    int n = (int)ceil(h / (0.1 * tau));
    if (n < 1) n = 1;
    if (n > 100000) {
        plant_log(&d->cb, d->name, fmi2Error, "a step of %g s needs more than 100000 substeps of tau / 10", h);
        return fmi2Error;
    }
    double dt = h / n, F = d->v[8];
    for (int k = 0; k < n; k++) {
        double e = ramp(d, t + k * dt) - v, u = Kp * e + Ki * d->z;
        double cmd = u > Fm ? Fm : (u < -Fm ? -Fm : u);
        if (cmd == u || (u > Fm && e < 0) || (u < -Fm && e > 0)) d->z += e * dt;  /* no wind-up */
        F += (cmd - F) * dt / tau;
    }
    d->v[8] = F;
    d->time = t + h;
    d->v[9] = ramp(d, d->time);
    return fmi2OK;
}
