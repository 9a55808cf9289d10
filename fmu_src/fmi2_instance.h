/* The FMI 2.0 instance of LSSChain, shared by the FMI glue (fmi2_glue.c) and
 * the FMU-state format (fmu_state.c): the instance struct, the state machine's
 * states, logging and the call-order check. No physics. */
#ifndef LSS_FMI2_INSTANCE_H
#define LSS_FMI2_INSTANCE_H

#include "fmi2Functions.h"
#include "chain.h"
#include "sensitivity.h"
#include "lss_vars.h"

typedef enum {
    ST_INSTANTIATED = 1, ST_INIT = 2, ST_STEP_COMPLETE = 4, ST_STEP_FAILED = 8,
    ST_TERMINATED = 16, ST_ERROR = 32
} ModelState;

#define ST_ANY (ST_INSTANTIATED | ST_INIT | ST_STEP_COMPLETE | ST_STEP_FAILED | ST_TERMINATED | ST_ERROR)
#define ST_READ (ST_INIT | ST_STEP_COMPLETE | ST_STEP_FAILED | ST_TERMINATED | ST_ERROR)

typedef struct {
    char name[256];
    char resource_dir[LSS_STRING_MAX];
    int has_resources;
    fmi2CallbackFunctions cb;
    LSSAlloc alloc;
    int log_all;
    ModelState state;
    LSSParams p;
    LSSOutputs out;
    Chain *chain;
    Sens sens;              /* the followers of the forward sensitivities (sensitivity.n of them) */
    int chain_stale;        /* parameters changed since the chain was built */
    int outputs_stale;      /* the outputs are not those of the current state */
    int bulk_done;          /* chain_outputs_bulk's part is (the outputs were brought up to date since) */
    double start_time, time;
    int setup_done;         /* fmi2SetupExperiment called since fmi2Instantiate or fmi2Reset */
    int tolerance_defined;
    double tolerance;
    int stop_time_defined;
    double stop_time;
    char string_out[LSS_STRING_MAX];
    int thrust_set;         /* a drive.groupK.F input was set since fmi2Instantiate or fmi2Reset */
    int thrust_warned;      /* the external drive's unset thrust was logged */
} Instance;

/* Below this relative tolerance the Runge-Kutta pair cannot make progress in
 * double precision (1e-16 already needs ~1e5 steps per 10 ms); a smaller
 * tolerance from fmi2SetupExperiment is raised to it with a warning. */
#define TOL_FLOOR 1e-12

/* Logs through the master's callback ('%' in the text arrives as written);
 * fmi2OK messages only with debug logging on. */
void lss_log(const Instance *in, fmi2Status status, const char *category, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
const char *lss_state_name(ModelState s);
/* 1 if the instance's state is in mask; else logs the call-order error, 0. */
int lss_allowed(Instance *in, const char *fn, int mask);
/* The outputs at the current state (builds the chain if needed). */
fmi2Status lss_ensure_outputs(Instance *in);
/* The same, the bulk part (chain_outputs_bulk) only if bulk is set: a master
 * reading the transducer's channels at every point does not pay for a walk
 * over every cart. */
fmi2Status lss_ensure_outputs_part(Instance *in, int bulk);

#define LOG_ERROR(in, ...) lss_log(in, fmi2Error, "logStatusError", __VA_ARGS__)

#define CHECK(c, fn, mask)                          \
    Instance *in = (Instance *)(c);                 \
    if (!in) return fmi2Error;                      \
    if (!lss_allowed(in, fn, mask)) return fmi2Error;

#endif
