/* Induction: the item flow of a loop sorter, an FMI 2.0 co-simulation FMU.
 * An induction station puts an item of `mass` kg on the empty cart passing
 * it, at most `rate` items per second and not before t_first; the chute
 * takes each item off as its cart passes. It reads which cart is at each
 * station (LSSChain's station.induction.cart, station.chute.cart) and drives
 * LSSChain's item ports: port 1 puts items on (load1.cart, load1.mass),
 * port 2 takes them off (load2.cart, load2.mass = 0).
 *
 * Value references: Real 1 rate (1/s), 2 mass (kg), 3 t_first (s):
 * parameters; 4 put_mass, 5 take_mass (kg): outputs. Integer 7 cart_in,
 * 8 cart_out: inputs; 9 put_cart, 10 take_cart, 11 n_items (on board),
 * 12 n_put, 13 n_taken: outputs. A cart passes a station when the index
 * there changes between communication points. A port names its cart for
 * the one communication step after the action and is idle (-1) otherwise,
 * so that every action is a change LSSChain's port acts on. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define GUID "{0d9c3e7a-8b21-4c55-b1f4-7e2a6c9d4b02}"
#define MAX_CARTS 4096
#define NR 6
#define NI 14

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    double r[NR];
    int i[NI];
    int last_in, last_out;
    double t_last_put, time;
    int initialised;
    unsigned char loaded[MAX_CARTS];
} Induction;

static void defaults(Induction *d) {
    memset(d->r, 0, sizeof d->r);
    memset(d->i, 0, sizeof d->i);
    d->r[1] = 2.0;
    d->r[2] = 10.0;
    d->r[3] = 0.5;
    d->i[9] = d->i[10] = -1;
    d->last_in = d->last_out = -1;
    d->t_last_put = -INFINITY;
    d->time = 0.0;
    d->initialised = 0;
    memset(d->loaded, 0, sizeof d->loaded);
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    (void)res; (void)visible; (void)logging;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, GUID) || !cb || !cb->allocateMemory) return NULL;
    Induction *d = cb->allocateMemory(1, sizeof(Induction));
    if (!d) return NULL;
    memcpy((void *)&d->cb, cb, sizeof *cb);
    snprintf(d->name, sizeof d->name, "%s", name ? name : "induction");
    defaults(d);
    return d;
}

void fmi2FreeInstance(fmi2Component c) {
    Induction *d = c;
    if (d) d->cb.freeMemory(d);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real start, fmi2Boolean sd,
                               fmi2Real stop) {
    (void)td; (void)tol; (void)sd; (void)stop;
    Induction *d = c;
    if (!d) return fmi2Error;
    d->time = start;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Induction *d = c;
    if (!d) return fmi2Error;
    if (!(d->r[1] > 0) || !isfinite(d->r[1]) || !(d->r[2] >= 0 && d->r[2] <= 1000) || !isfinite(d->r[3])) {
        plant_log(&d->cb, d->name, fmi2Error, "rate = %g 1/s must be positive, mass = %g kg in [0, 1000], "
                  "t_first = %g s finite", d->r[1], d->r[2], d->r[3]);
        return fmi2Error;
    }
    d->initialised = 1;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Induction *d = c;
    if (!d) return fmi2Error;
    defaults(d);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Induction *d = c;
    if (!d || (n && (!vr || !value))) return fmi2Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] < 1 || vr[k] >= NR) return fmi2Error;
        value[k] = d->r[vr[k]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Induction *d = c;
    if (!d || (n && (!vr || !value))) return fmi2Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] < 1 || vr[k] > 3 || d->initialised || !isfinite(value[k])) {
            plant_log(&d->cb, d->name, fmi2Error, "fmi2SetReal: value reference %u = %g cannot be set now", vr[k],
                      value[k]);
            return fmi2Error;
        }
        d->r[vr[k]] = value[k];
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    Induction *d = c;
    if (!d || (n && (!vr || !value))) return fmi2Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] < 7 || vr[k] >= NI) return fmi2Error;
        value[k] = d->i[vr[k]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    Induction *d = c;
    if (!d || (n && (!vr || !value))) return fmi2Error;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != 7 && vr[k] != 8) return fmi2Error;
        if (value[k] < -1 || value[k] >= MAX_CARTS) {
            plant_log(&d->cb, d->name, fmi2Error, "fmi2SetInteger: cart index %d is not in [-1, %d)", value[k],
                      MAX_CARTS);
            return fmi2Error;
        }
        d->i[vr[k]] = value[k];
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    (void)no_prior;
    Induction *d = c;
    if (!d || !d->initialised || !(h > 0) || !isfinite(t + h)) return fmi2Error;
    int in = d->i[7], out = d->i[8];
    d->i[9] = d->i[10] = -1;   /* a port names a cart for one communication step: each action is a change */
    if (in != d->last_in && in >= 0) {   /* a cart arrives at the induction */
        if (t >= d->r[3] - 1e-12 && t - d->t_last_put >= 1.0 / d->r[1] - 1e-12 && !d->loaded[in]) {
            d->loaded[in] = 1;
            d->i[9] = in;
            d->r[4] = d->r[2];
            d->t_last_put = t;
            d->i[12]++;
        }
    }
    d->last_in = in;
    if (out != d->last_out && out >= 0 && d->loaded[out]) {   /* a loaded cart reaches the chute */
        d->loaded[out] = 0;
        d->i[10] = out;
        d->r[5] = 0.0;
        d->i[13]++;
    }
    d->last_out = out;
    d->i[11] = d->i[12] - d->i[13];
    d->time = t + h;
    return fmi2OK;
}
