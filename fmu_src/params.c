/* The ranges of the parameters and inputs, as declared in the one table of
 * variables (lss_fmu/variables.py -> lss_vars.c and modelDescription.xml):
 * what the XML says is what the FMU enforces. */
#include <math.h>
#include <stdio.h>

#include "params.h"

int param_in_range(const LSSVarInfo *v, double x) {
    if (v->type == LSS_REAL && !isfinite(x)) return 0;
    return !((v->has_min && x < v->min) || (v->has_max && x > v->max));
}

static double value_of(const LSSParams *p, const LSSVarInfo *v) {
    const char *slot = (const char *)p + v->offset;
    return v->type == LSS_REAL ? *(const double *)slot : (double)*(const int *)slot;
}

int params_check_ranges(const LSSParams *p, char *err, size_t errlen) {
    for (int vr = 1; vr <= LSS_N_VARS; vr++) {
        const LSSVarInfo *v = &LSS_VARS[vr];
        if (!v->in_params || (v->type != LSS_REAL && v->type != LSS_INTEGER)) continue;
        double x = value_of(p, v);
        if (param_in_range(v, x)) continue;
        if (!isfinite(x))
            snprintf(err, errlen, "%s = %g is not a finite number", v->name, x);
        else
            snprintf(err, errlen, "%s = %.17g is outside its range [%g, %g]", v->name, x,
                     v->has_min ? v->min : -INFINITY, v->has_max ? v->max : INFINITY);
        return 1;
    }
    return 0;
}
