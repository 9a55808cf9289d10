/* Range checks of parameters and inputs against the variable table. */
#ifndef LSS_PARAMS_H
#define LSS_PARAMS_H

#include <stddef.h>

#include "lss_vars.h"

/* Is x within v's declared range (and finite, for a Real)? */
int param_in_range(const LSSVarInfo *v, double x);
/* 0, or 1 with a message naming the first variable out of its range. */
int params_check_ranges(const LSSParams *p, char *err, size_t errlen);

#endif
