/* Test harness for the FMI 2.0 interface of LSSChain, in C, without fmpy.
 *
 * Linked directly with the model sources, fmi2_glue.c and the generated
 * lss_vars.c (files named test_*.c are left out of the FMU), and built by
 * tests/test_c_harness.py with AddressSanitizer and UndefinedBehaviorSanitizer
 * (and by tests/c/leakcheck.sh for the long run under valgrind or LSan).
 *
 *   test_harness RESOURCE_URI [--cycles N] [--stop T] [--step H]
 *                [--threads K] [--corrupt R] [--fieldwise] [--seed S] [--verbose]
 *
 * --cycles N   N cycles of instantiate / set / setup / initialise / step to T
 *              / (some cycles: FMU state round trip) / wrong calls / reset /
 *              re-initialise / step again (must equal the first run bit for
 *              bit) / terminate / free; every fifth cycle also runs one of
 *              the error paths (bad layouts, bad GUID, Discard, ...).
 * --threads K  K instances stepped at once on K threads must give the same
 *              results as one after another (bit for bit).
 * --corrupt R  R corrupted serialized FMU states: deserialize / set / step
 *              must answer with a status, never crash.
 * --fieldwise  every 8-byte word of a serialized state set to NaN, +-inf, 0,
 *              -1, 1e300 in turn: refused with a message, or stepped to the
 *              right time (fmi2OK) or discarded; never a hang.
 *
 * Cycle k (and thread k) asks for right-hand-side path k % 4
 * (solver.vector_path: auto, scalar, AVX2, AVX-512), so that the sanitizer
 * builds run every path this CPU has; the paths taken are counted and
 * printed ("vector paths used: ...").
 *
 * Memory comes from calloc/free callbacks that count live blocks; at the end
 * every block must have been returned. Every call expected to fail must
 * return the expected status and log a message. Exit code 0 when all checks
 * passed; the last line of output is a summary. */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"
#include "lss_guid.h"
#include "lss_vars.h"

#define MAX_OUT 256   /* every Real output and calculated parameter */
#define MAX_THREADS 64

typedef struct {
    long n_msg[6];        /* messages by status */
    char last[1024];      /* the last message */
    int verbose;
} Env;

typedef struct {
    const char *uri;
    double stop, h;
    char tmpdir[512];
    int verbose;
} Opts;

static atomic_long g_live, g_allocs, g_failures, g_bad_inputs, g_calls;
static atomic_long g_outcome[6];  /* statuses returned to the bad inputs */
static atomic_long g_path_used[4];  /* initialisations per solver.vector_path_used (1 scalar, 2 AVX2, 3 AVX-512) */
static fmi2ValueReference g_out_vr[MAX_OUT];
static int g_n_out;

/* --- callbacks ----------------------------------------------------------------- */

static void *h_calloc(size_t n, size_t size) {
    void *p = calloc(n, size);
    if (p) {
        atomic_fetch_add(&g_live, 1);
        atomic_fetch_add(&g_allocs, 1);
    }
    return p;
}

static void h_free(void *p) {
    if (p) atomic_fetch_sub(&g_live, 1);
    free(p);
}

static void h_logger(fmi2ComponentEnvironment e, fmi2String instance, fmi2Status status, fmi2String category,
                     fmi2String message, ...) {
    Env *env = e;
    char buf[1024];
    va_list ap;
    va_start(ap, message);
    vsnprintf(buf, sizeof buf, message ? message : "(null)", ap);
    va_end(ap);
    if (!env) return;
    if ((int)status >= 0 && (int)status < 6) env->n_msg[status]++;
    snprintf(env->last, sizeof env->last, "%s", buf);
    if (env->verbose)
        fprintf(stderr, "  [%s %s %d] %s\n", instance ? instance : "?", category ? category : "?", (int)status, buf);
}

/* --- checks -------------------------------------------------------------------- */

static void fail_at(int line, const char *fmt, ...) {
    va_list ap;
    atomic_fetch_add(&g_failures, 1);
    fprintf(stderr, "FAIL (test_harness.c:%d): ", line);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
}

#define EXPECT(cond, ...) \
    do { if (!(cond)) fail_at(__LINE__, __VA_ARGS__); } while (0)

static long n_problems(const Env *env) {
    return env->n_msg[fmi2Warning] + env->n_msg[fmi2Discard] + env->n_msg[fmi2Error] + env->n_msg[fmi2Fatal];
}

static void check_call(Env *env, const char *what, fmi2Status got, fmi2Status want, long before, int need_msg,
                       int line) {
    atomic_fetch_add(&g_calls, 1);
    if (want != fmi2OK) {
        atomic_fetch_add(&g_bad_inputs, 1);
        if ((int)got >= 0 && (int)got < 6) atomic_fetch_add(&g_outcome[got], 1);
    }
    if (got != want)
        fail_at(line, "%s returned %d, expected %d (last message: %s)", what, (int)got, (int)want, env->last);
    else if (want != fmi2OK && need_msg && n_problems(env) == before)
        fail_at(line, "%s returned %d but logged no message", what, (int)got);
}

/* CALL: the status must be `want`, and a failure must come with a message.
 * CALLQ: the same without a message (a NULL instance has no logger). */
#define CALL(want, call) do { long b_ = n_problems(env); \
        check_call(env, #call, (call), (want), b_, 1, __LINE__); } while (0)
#define CALLQ(want, call) do { long b_ = n_problems(env); \
        check_call(env, #call, (call), (want), b_, 0, __LINE__); } while (0)

/* --- one simulation ------------------------------------------------------------ */

static fmi2Component instantiate(Env *env, const fmi2CallbackFunctions *cb, const char *uri) {
    fmi2Component c = fmi2Instantiate("harness", fmi2CoSimulation, LSS_GUID, uri, cb, fmi2False, fmi2False);
    EXPECT(c != NULL, "fmi2Instantiate returned NULL: %s", env->last);
    return c;
}

/* Parameters of cycle k: every contact law, a range of speeds, each
 * right-hand-side path in turn. Set before fmi2SetupExperiment, as some
 * masters do. */
static void set_params(Env *env, fmi2Component c, int k) {
    fmi2ValueReference vr_i[2] = {VR_CONTACT_MODEL, VR_SOLVER_VECTOR_PATH}, vr_s = VR_LAYOUT_NAME;
    fmi2ValueReference vr_r[3] = {VR_DRIVE_V_REF, VR_CONTACT_E_JA, VR_DRIVE_KP};
    fmi2Integer ints[2] = {1 + k % 6, k % 4};
    fmi2Real r[3] = {1.5 + 0.1 * (k % 10), 0.3 + 0.05 * (k % 7), 400.0 + k % 5};
    fmi2String layout = "demo";
    CALL(fmi2OK, fmi2SetString(c, &vr_s, 1, &layout));
    CALL(fmi2OK, fmi2SetInteger(c, vr_i, 2, ints));
    CALL(fmi2OK, fmi2SetReal(c, vr_r, 3, r));
    if (k % 5 == 3) {  /* every fifth cycle: two forward sensitivities; every tenth from rest, relaxed first */
        fmi2ValueReference vr_n[3] = {VR_SENSITIVITY_N, VR_SENSITIVITY_P1_VR, VR_SENSITIVITY_P2_VR};
        fmi2ValueReference vr_h[2] = {VR_SENSITIVITY_P1_STEP, VR_SENSITIVITY_P2_STEP};
        fmi2Integer n[3] = {2, VR_CONTACT_E_JA, VR_CHAIN_PRETENSION};
        fmi2Real h[2] = {1e-6, 1e-9};
        CALL(fmi2OK, fmi2SetInteger(c, vr_n, 3, n));
        CALL(fmi2OK, fmi2SetReal(c, vr_h, 2, h));
        if (k % 10 == 3) {
            fmi2ValueReference vr_rest[2] = {VR_CHAIN_V_INIT, VR_CHAIN_RELAX_TIME};
            /* 0.02 s: the relaxation and its replay run all their code in a few steps; its physics is
             * tested elsewhere, and here it would be most of the harness's time */
            fmi2Real rest[2] = {0.0, 0.02};
            CALL(fmi2OK, fmi2SetReal(c, vr_rest, 2, rest));
        }
    }
    if (k % 3 == 1) {  /* every third cycle: the external drive in groups, an item on a cart from the start */
        fmi2ValueReference vr_e[3] = {VR_DRIVE_MODE, VR_DRIVE_N_GROUPS, VR_LOAD1_CART};
        fmi2ValueReference vr_f[3] = {VR_DRIVE_GROUP1_F, VR_DRIVE_GROUP1_F + 1, VR_LOAD1_MASS};
        fmi2Integer e[3] = {1, 1 + k % 5, k % 40};
        fmi2Real f[3] = {150.0 + k % 50, 100.0 - k % 30, 10.0 + k % 7};
        CALL(fmi2OK, fmi2SetInteger(c, vr_e, 3, e));
        CALL(fmi2OK, fmi2SetReal(c, vr_f, 3, f));
    }
}

static void get_outputs(Env *env, fmi2Component c, double *out) {
    CALL(fmi2OK, fmi2GetReal(c, g_out_vr, (size_t)g_n_out, out));
    for (int i = 0; i < g_n_out; i++)
        EXPECT(isfinite(out[i]), "output %s = %g is not finite", LSS_VARS[g_out_vr[i]].name, out[i]);
}

/* setup, initialise (reading initial unknowns in Initialization Mode), step to
 * stop; the outputs at stop in out. Returns the time reached. */
static double init_and_run(Env *env, fmi2Component c, const Opts *o, int k, double *out) {
    CALL(fmi2OK, fmi2SetupExperiment(c, fmi2True, 1e-4, 0.0, fmi2True, o->stop));
    CALL(fmi2OK, fmi2EnterInitializationMode(c));
    fmi2ValueReference vr_n = VR_CHAIN_N_CARTS, vr_l[2] = {VR_TRACK_LENGTH, VR_CHAIN_V_MEAN};
    fmi2Integer n = 0;
    fmi2Real l[2] = {0, 0};
    CALL(fmi2OK, fmi2GetInteger(c, &vr_n, 1, &n));
    CALL(fmi2OK, fmi2GetReal(c, vr_l, 2, l));
    EXPECT(n >= 3 && l[0] > 0 && isfinite(l[1]), "initial unknowns: n_carts %d, length %g, v_mean %g", n, l[0], l[1]);
    CALL(fmi2OK, fmi2ExitInitializationMode(c));
    fmi2ValueReference vr_p = VR_SOLVER_VECTOR_PATH_USED;
    fmi2Integer path = 0;
    CALL(fmi2OK, fmi2GetInteger(c, &vr_p, 1, &path));
    EXPECT(path >= 1 && path <= 3 && (k % 4 == 0 || path <= k % 4), "cycle %d: vector path %d used for %d asked",
           k, path, k % 4);
    if (path >= 1 && path <= 3) atomic_fetch_add(&g_path_used[path], 1);
    int steps = (int)lround(o->stop / o->h);
    double t = 0.0;
    for (int i = 1; i <= steps; i++) {
        double tn = i == steps ? o->stop : i * o->h;
        if (k % 3 == 1 && i == steps / 2) {  /* an item put on a moving cart, another's taken off */
            fmi2ValueReference vr_c[2] = {VR_LOAD2_CART, VR_LOAD1_CART}, vr_m[2] = {VR_LOAD2_MASS, VR_LOAD1_MASS};
            fmi2Integer carts[2] = {(k + 5) % 40, k % 40};
            fmi2Real masses[2] = {25.0, 0.0};
            CALL(fmi2OK, fmi2SetInteger(c, vr_c, 2, carts));
            CALL(fmi2OK, fmi2SetReal(c, vr_m, 2, masses));
        }
        CALL(fmi2OK, fmi2DoStep(c, t, tn - t, fmi2True));
        t = tn;
    }
    get_outputs(env, c, out);
    return t;
}

/* Wrong calls in Step Mode at time t: each must give fmi2Error and a message
 * and change nothing. */
static void wrong_calls(Env *env, fmi2Component c, const Opts *o, double t) {
    fmi2ValueReference vr_out = VR_CHAIN_V_MEAN, vr_fixed = VR_CHAIN_PRETENSION, vr_in = VR_DRIVE_V_REF;
    fmi2ValueReference vr_bad[3] = {0, LSS_N_VARS + 1, 0xFFFFFFFFu}, vr_str = VR_LAYOUT_NAME;
    fmi2Real x = 0.5, big = 1e300, nan_ = NAN, r[4];
    fmi2Integer ix;
    fmi2String sv = NULL;
    CALL(fmi2Error, fmi2DoStep(c, t + 1.0, o->h, fmi2True));
    CALL(fmi2Error, fmi2DoStep(c, t, -o->h, fmi2True));
    CALL(fmi2Error, fmi2DoStep(c, t, NAN, fmi2True));
    CALL(fmi2Error, fmi2DoStep(c, t, INFINITY, fmi2True));
    CALL(fmi2Error, fmi2DoStep(c, t, o->stop + 1.0, fmi2True));  /* past stopTime */
    CALL(fmi2Error, fmi2SetReal(c, &vr_out, 1, &x));
    CALL(fmi2Error, fmi2SetReal(c, &vr_fixed, 1, &x));             /* fixed parameter in Step Mode */
    CALL(fmi2Error, fmi2SetReal(c, &vr_in, 1, &nan_));
    CALL(fmi2Error, fmi2SetReal(c, &vr_in, 1, &big));
    for (int i = 0; i < 3; i++) CALL(fmi2Error, fmi2GetReal(c, &vr_bad[i], 1, r));
    CALL(fmi2Error, fmi2GetReal(c, NULL, 1, r));
    CALL(fmi2Error, fmi2GetReal(c, &vr_out, 1, NULL));
    CALL(fmi2Error, fmi2GetInteger(c, &vr_out, 1, &ix));        /* a Real read as Integer */
    CALL(fmi2Error, fmi2SetString(c, &vr_str, 1, &sv));
    CALL(fmi2Error, fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CALL(fmi2Error, fmi2EnterInitializationMode(c));
    CALL(fmi2Error, fmi2ExitInitializationMode(c));
    CALLQ(fmi2Error, fmi2DoStep(NULL, t, o->h, fmi2True));
    CALLQ(fmi2Error, fmi2GetReal(NULL, &vr_out, 1, r));
    CALLQ(fmi2Error, fmi2SetReal(NULL, &vr_in, 1, &x));
    CALLQ(fmi2Error, fmi2Reset(NULL));
    CALLQ(fmi2Error, fmi2Terminate(NULL));
    fmi2FreeInstance(NULL);
    CALL(fmi2OK, fmi2GetReal(c, &vr_out, 1, r));  /* still usable */
}

static int same_bits(const double *a, const double *b, int n) { return memcmp(a, b, sizeof(double) * (size_t)n) == 0; }

/* At time t: get the state, serialize it, step twice; deserialize and set
 * the state (the outputs must be those read before), step twice again: the
 * two ends must agree bit for bit. */
static void state_round_trip(Env *env, fmi2Component c, const Opts *o, double t) {
    fmi2FMUstate s1 = NULL, s2 = NULL;
    double a[MAX_OUT], b[MAX_OUT], mid[MAX_OUT];
    get_outputs(env, c, mid);
    CALL(fmi2OK, fmi2GetFMUstate(c, &s1));
    CALL(fmi2OK, fmi2GetFMUstate(c, &s1));  /* reuse of the same state */
    size_t size = 0;
    CALL(fmi2OK, fmi2SerializedFMUstateSize(c, s1, &size));
    fmi2Byte *buf = malloc(size);
    EXPECT(buf != NULL, "malloc");
    if (!buf) return;
    CALL(fmi2OK, fmi2SerializeFMUstate(c, s1, buf, size));
    CALL(fmi2Error, fmi2SerializeFMUstate(c, s1, buf, size - 1));
    CALL(fmi2Error, fmi2DeSerializeFMUstate(c, buf, size - 1, &s2));
    double t1 = t;
    for (int i = 0; i < 2; i++, t1 += o->h) CALL(fmi2OK, fmi2DoStep(c, t1, o->h, fmi2False));
    get_outputs(env, c, a);
    CALL(fmi2OK, fmi2DeSerializeFMUstate(c, buf, size, &s2));
    CALL(fmi2OK, fmi2SetFMUstate(c, s2));
    get_outputs(env, c, b);  /* at the restored point: what was read there before */
    EXPECT(same_bits(mid, b, g_n_out), "outputs after fmi2SetFMUstate differ from those at fmi2GetFMUstate");
    double t2 = t;
    for (int i = 0; i < 2; i++, t2 += o->h) CALL(fmi2OK, fmi2DoStep(c, t2, o->h, fmi2False));
    get_outputs(env, c, b);
    EXPECT(t1 == t2 && same_bits(a, b, g_n_out), "FMU state round trip does not replay bit for bit");
    CALL(fmi2OK, fmi2SetFMUstate(c, s1));  /* back to the saved state */
    CALL(fmi2OK, fmi2FreeFMUstate(c, &s1));
    CALL(fmi2OK, fmi2FreeFMUstate(c, &s2));
    CALL(fmi2OK, fmi2FreeFMUstate(c, &s2));  /* NULL now: a no-op */
    free(buf);
}

/* One full cycle; the outputs at stop in out. */
static void cycle(Env *env, const Opts *o, int k, int extras, double *out) {
    fmi2CallbackFunctions cb = {h_logger, h_calloc, h_free, NULL, env};
    fmi2Component c = instantiate(env, &cb, o->uri);
    if (!c) return;
    set_params(env, c, k);
    double ref[MAX_OUT], again[MAX_OUT];
    if (extras && (k % 10 == 0 || k % 10 == 3)) {   /* 3: with followers, relaxed at rest */
        /* one step, a round trip of the FMU state, then the cycle proper */
        CALL(fmi2OK, fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CALL(fmi2OK, fmi2EnterInitializationMode(c));
        CALL(fmi2OK, fmi2ExitInitializationMode(c));
        CALL(fmi2OK, fmi2DoStep(c, 0.0, o->h, fmi2True));
        state_round_trip(env, c, o, o->h);
        CALL(fmi2OK, fmi2Reset(c));
        set_params(env, c, k);
    }
    double t = init_and_run(env, c, o, k, ref);
    if (extras) wrong_calls(env, c, o, t);
    /* reset, the same again: the same result as the first run */
    CALL(fmi2OK, fmi2Reset(c));
    set_params(env, c, k);
    init_and_run(env, c, o, k, again);
    EXPECT(same_bits(ref, again, g_n_out), "cycle %d: reset and re-run differ from the first run", k);
    CALL(fmi2OK, fmi2Terminate(c));
    if (extras) {
        fmi2ValueReference vr = VR_CHAIN_V_MEAN;
        fmi2Real v;
        CALL(fmi2OK, fmi2GetReal(c, &vr, 1, &v));              /* readable after terminate */
        CALL(fmi2Error, fmi2DoStep(c, t, o->h, fmi2True));     /* but no longer steppable */
        CALL(fmi2Error, fmi2Terminate(c));
    }
    fmi2FreeInstance(c);
    if (out) memcpy(out, ref, sizeof(double) * (size_t)g_n_out);
}

/* --- error paths (they must clean up after themselves as well) -------------------- */

static void write_file(const char *path, const char *text) {
    FILE *f = fopen(path, "w");
    EXPECT(f != NULL, "cannot write %s", path);
    if (!f) return;
    fputs(text, f);
    fclose(f);
}

#define HEAD "wheel A\ncoupling A\nmotors 2\n"

static void error_path(Env *env, const Opts *o, int kind) {
    fmi2CallbackFunctions cb = {h_logger, h_calloc, h_free, NULL, env};
    fmi2ValueReference vr_s = VR_LAYOUT_NAME, vr_t = VR_CHAIN_TRANSDUCER, vr_dm[2] = {VR_CHAIN_PRETENSION, VR_CART_MASS_FACTOR};
    fmi2ValueReference vr_out = VR_CHAIN_V_MEAN;
    char path[700];
    fmi2String name = path;
    fmi2Real r;
    fmi2Component c;
    switch (kind) {
    case 0:  /* unknown built-in layout: initialisation fails, then terminate (some masters do) and free */
    case 1:  /* a layout file with a syntax error */
    case 2:  /* a layout file whose track does not close */
    case 3:  /* a file that does not exist */
        c = instantiate(env, &cb, o->uri);
        if (!c) return;
        if (kind == 0) snprintf(path, sizeof path, "no_such_layout");
        else if (kind == 1) snprintf(path, sizeof path, "%s/bad_syntax.layout", o->tmpdir);
        else if (kind == 2) snprintf(path, sizeof path, "%s/open.layout", o->tmpdir);
        else snprintf(path, sizeof path, "%s/missing.layout", o->tmpdir);
        CALL(fmi2OK, fmi2SetString(c, &vr_s, 1, &name));
        CALL(fmi2OK, fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CALL(fmi2OK, fmi2EnterInitializationMode(c));
        CALL(fmi2Error, fmi2GetReal(c, &vr_out, 1, &r));  /* initial unknowns need the chain */
        CALL(fmi2Error, fmi2ExitInitializationMode(c));
        EXPECT(strstr(env->last, kind == 0 ? "no_such_layout" : path) != NULL,
               "the message does not name the layout: %s", env->last);
        if (kind % 2 == 0) CALL(fmi2OK, fmi2Terminate(c));
        fmi2FreeInstance(c);
        break;
    case 4: {  /* transducer index beyond the chain: fails after the track was built */
        c = instantiate(env, &cb, o->uri);
        if (!c) return;
        fmi2Integer big = 99999;
        CALL(fmi2OK, fmi2SetInteger(c, &vr_t, 1, &big));
        CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* without fmi2SetupExperiment: defaults */
        CALL(fmi2Error, fmi2ExitInitializationMode(c));
        CALL(fmi2OK, fmi2Reset(c));                    /* and recover */
        CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* no fmi2SetupExperiment: defaults, a warning */
        CALL(fmi2OK, fmi2ExitInitializationMode(c));
        CALL(fmi2OK, fmi2DoStep(c, 0.0, o->h, fmi2True));
        fmi2FreeInstance(c);                           /* without terminate */
        break;
    }
    case 5: {  /* instantiate refusals */
        fmi2CallbackFunctions nocb = {h_logger, NULL, NULL, NULL, env};
        long b = n_problems(env);
        EXPECT(fmi2Instantiate("h", fmi2CoSimulation, "{wrong-guid}", o->uri, &cb, 0, 0) == NULL, "wrong GUID");
        EXPECT(fmi2Instantiate("", fmi2CoSimulation, LSS_GUID, o->uri, &cb, 0, 0) == NULL, "empty name");
        EXPECT(fmi2Instantiate(NULL, fmi2CoSimulation, LSS_GUID, o->uri, &cb, 0, 0) == NULL, "NULL name");
        EXPECT(fmi2Instantiate("h", fmi2ModelExchange, LSS_GUID, o->uri, &cb, 0, 0) == NULL, "model exchange");
        EXPECT(fmi2Instantiate("h", fmi2CoSimulation, NULL, o->uri, &cb, 0, 0) == NULL, "NULL GUID");
        EXPECT(fmi2Instantiate("h", fmi2CoSimulation, LSS_GUID, o->uri, NULL, 0, 0) == NULL, "NULL callbacks");
        EXPECT(fmi2Instantiate("h", fmi2CoSimulation, LSS_GUID, o->uri, &nocb, 0, 0) == NULL, "no allocator");
        EXPECT(n_problems(env) >= b + 5, "instantiate refusals logged %ld messages", n_problems(env) - b);
        atomic_fetch_add(&g_bad_inputs, 7);
        atomic_fetch_add(&g_outcome[fmi2Error], 7);  /* NULL instance, counted as an error */
        break;
    }
    case 6:  /* a resource location that is not a file URI: built-in layouts unavailable */
        c = fmi2Instantiate("h", fmi2CoSimulation, LSS_GUID, "http://example.com/x", &cb, 0, 0);
        EXPECT(c != NULL && env->n_msg[fmi2Warning] > 0, "instantiate with an http URI");
        if (!c) return;
        CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* no fmi2SetupExperiment: defaults, a warning */
        CALL(fmi2Error, fmi2ExitInitializationMode(c));
        fmi2FreeInstance(c);
        break;
    case 7: {  /* a step that cannot be made (layout 7 with carts of 1/1000 of their
                  mass in a chain half a metre too long: legal, absurd; the step
                  collapses at once): fmi2Discard, then only reads, terminate */
        c = instantiate(env, &cb, o->uri);
        if (!c) return;
        fmi2Real crushed[2] = {-0.5, 1e-3};
        fmi2String lay7 = "layout7";
        CALL(fmi2OK, fmi2SetString(c, &vr_s, 1, &lay7));
        CALL(fmi2OK, fmi2SetReal(c, vr_dm, 2, crushed));
        CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* no fmi2SetupExperiment: defaults, a warning */
        CALL(fmi2OK, fmi2ExitInitializationMode(c));
        CALL(fmi2Discard, fmi2DoStep(c, 0.0, o->h, fmi2True));
        fmi2Real last = -1;
        CALL(fmi2OK, fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &last));
        EXPECT(last == 0.0, "last successful time %g after a discarded first step", last);
        CALL(fmi2Error, fmi2DoStep(c, 0.0, o->h, fmi2True));  /* no step after a discard */
        CALL(fmi2OK, fmi2GetReal(c, &vr_out, 1, &r));
        CALL(fmi2OK, fmi2Terminate(c));
        fmi2FreeInstance(c);
        break;
    }
    case 8: {  /* FMU states before the chain exists, and freed by fmi2FreeInstance's owner */
        c = instantiate(env, &cb, o->uri);
        if (!c) return;
        fmi2FMUstate s = NULL;
        CALL(fmi2OK, fmi2GetFMUstate(c, &s));
        CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* no fmi2SetupExperiment: defaults, a warning */
        CALL(fmi2OK, fmi2GetReal(c, &vr_out, 1, &r));
        CALL(fmi2OK, fmi2GetFMUstate(c, &s));  /* now with the chain: replaced by a larger one */
        CALL(fmi2OK, fmi2SetFMUstate(c, s));
        CALL(fmi2OK, fmi2ExitInitializationMode(c));
        CALL(fmi2OK, fmi2SetFMUstate(c, s));    /* back to Initialization Mode */
        CALL(fmi2OK, fmi2ExitInitializationMode(c));
        CALL(fmi2OK, fmi2FreeFMUstate(c, &s));
        fmi2FreeInstance(c);
        break;
    }
    }
}

/* --- corrupted serialized states ------------------------------------------------- */

static unsigned long long rng_state = 88172645463325252ULL;
static unsigned long long rnd(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return rng_state;
}

static void corrupt_states(Env *env, const Opts *o, int rounds) {
    fmi2CallbackFunctions cb = {h_logger, h_calloc, h_free, NULL, env};
    fmi2Component c = instantiate(env, &cb, o->uri);
    if (!c) return;
    CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* no fmi2SetupExperiment: defaults, a warning */
    CALL(fmi2OK, fmi2ExitInitializationMode(c));
    CALL(fmi2OK, fmi2DoStep(c, 0.0, 0.01, fmi2True));
    fmi2FMUstate good = NULL, s = NULL;
    CALL(fmi2OK, fmi2GetFMUstate(c, &good));
    size_t size = 0;
    CALL(fmi2OK, fmi2SerializedFMUstateSize(c, good, &size));
    fmi2Byte *ref = malloc(size + 64), *buf = malloc(size + 64);
    EXPECT(ref && buf, "malloc");
    if (!ref || !buf) return;
    CALL(fmi2OK, fmi2SerializeFMUstate(c, good, ref, size));
    long outcome[3][6] = {{0}};
    for (int r = 0; r < rounds; r++) {
        memcpy(buf, ref, size);
        size_t n = size;
        int how = (int)(rnd() % 8);
        if (how == 0) n = rnd() % size;                      /* truncated */
        else if (how == 1) n = size + 1 + rnd() % 63;        /* too long */
        else {
            int flips = 1 + (int)(rnd() % 8);
            for (int i = 0; i < flips; i++) {
                size_t at = how == 2 ? rnd() % 256 : rnd() % size;  /* header, or anywhere */
                buf[at] ^= (fmi2Byte)(1u << (rnd() % 8));
            }
        }
        long b = n_problems(env);
        fmi2Status st = fmi2DeSerializeFMUstate(c, buf, n, &s);
        outcome[0][st]++;
        if (st != fmi2OK) {
            EXPECT(n_problems(env) > b, "a refused state logged no message");
            atomic_fetch_add(&g_outcome[st], 1);
            continue;
        }
        st = fmi2SetFMUstate(c, s);
        outcome[1][st]++;
        if (st != fmi2OK) atomic_fetch_add(&g_outcome[st], 1);
        if (st == fmi2OK) {
            fmi2Real t = 0;
            fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t);
            st = fmi2DoStep(c, t, 1e-3, fmi2True);
            outcome[2][st]++;
            atomic_fetch_add(&g_outcome[st], 1);
            fmi2Real v;
            fmi2ValueReference vr = VR_CHAIN_V_MEAN;
            fmi2GetReal(c, &vr, 1, &v);
        }
        CALL(fmi2OK, fmi2SetFMUstate(c, good));
    }
    printf("corrupt states: %d; deserialize ok %ld / error %ld; set ok %ld / error %ld; "
           "step ok %ld / discard %ld / error %ld\n", rounds, outcome[0][0], outcome[0][3], outcome[1][0],
           outcome[1][3], outcome[2][0], outcome[2][2], outcome[2][3]);
    atomic_fetch_add(&g_bad_inputs, rounds);
    CALL(fmi2OK, fmi2FreeFMUstate(c, &good));
    CALL(fmi2OK, fmi2FreeFMUstate(c, &s));
    fmi2FreeInstance(c);
    free(ref);
    free(buf);
}

/* Every 8-byte word of a serialized state set in turn to NaN, +inf, -inf, 0,
 * -1 and 1e300: deserialize / set / step 1e-4 s. A state accepted must step
 * to the right time (fmi2OK) or end in fmi2Discard, never hang; a refusal
 * must log a message. */
static void fieldwise_states(Env *env, const Opts *o) {
    fmi2CallbackFunctions cb = {h_logger, h_calloc, h_free, NULL, env};
    fmi2Component c = instantiate(env, &cb, o->uri);
    if (!c) return;
    CALL(fmi2Warning, fmi2EnterInitializationMode(c));  /* no fmi2SetupExperiment: defaults, a warning */
    CALL(fmi2OK, fmi2ExitInitializationMode(c));
    CALL(fmi2OK, fmi2DoStep(c, 0.0, 0.01, fmi2True));
    fmi2FMUstate good = NULL, s = NULL;
    CALL(fmi2OK, fmi2GetFMUstate(c, &good));
    size_t size = 0;
    CALL(fmi2OK, fmi2SerializedFMUstateSize(c, good, &size));
    fmi2Byte *ref = malloc(size), *buf = malloc(size);
    EXPECT(ref && buf, "malloc");
    if (!ref || !buf) return;
    CALL(fmi2OK, fmi2SerializeFMUstate(c, good, ref, size));
    const double values[6] = {NAN, INFINITY, -INFINITY, 0.0, -1.0, 1e300};
    long outcome[4] = {0};  /* refused at deserialize, refused at set, stepped, discarded */
    for (size_t w = 0; w + 8 <= size; w += 8) {
        for (int v = 0; v < 6; v++) {
            memcpy(buf, ref, size);
            memcpy(buf + w, &values[v], 8);
            if (!memcmp(buf, ref, size)) continue;  /* the word had that value already */
            long b = n_problems(env);
            fmi2Status st = fmi2DeSerializeFMUstate(c, buf, size, &s);
            atomic_fetch_add(&g_bad_inputs, 1);
            if (st != fmi2OK) {
                EXPECT(st == fmi2Error && n_problems(env) > b, "word %zu = %g: status %d without a message", w / 8,
                       values[v], st);
                atomic_fetch_add(&g_outcome[st], 1);
                outcome[0]++;
                continue;
            }
            st = fmi2SetFMUstate(c, s);
            if (st != fmi2OK) {
                EXPECT(st == fmi2Error && n_problems(env) > b, "word %zu = %g: set status %d without a message",
                       w / 8, values[v], st);
                atomic_fetch_add(&g_outcome[st], 1);
                outcome[1]++;
            } else {
                fmi2Real t = -1, t2 = -1;
                fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t);
                EXPECT(fabs(t - 0.01) < 1e-12, "word %zu = %g: the state set is at t = %.17g", w / 8, values[v], t);
                st = fmi2DoStep(c, t, 1e-4, fmi2True);
                atomic_fetch_add(&g_outcome[st], 1);
                EXPECT(st == fmi2OK || st == fmi2Discard, "word %zu = %g: step status %d", w / 8, values[v], st);
                if (st == fmi2OK) {
                    fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t2);
                    EXPECT(t2 == t + 1e-4, "word %zu = %g: stepped to %.17g, not %.17g", w / 8, values[v], t2, t + 1e-4);
                }
                outcome[st == fmi2OK ? 2 : 3]++;
            }
            CALL(fmi2OK, fmi2SetFMUstate(c, good));
        }
    }
    printf("fieldwise states: %zu words x 6 values; refused at deserialize %ld, at set %ld; "
           "stepped %ld, discarded %ld\n", size / 8, outcome[0], outcome[1], outcome[2], outcome[3]);
    CALL(fmi2OK, fmi2FreeFMUstate(c, &good));
    CALL(fmi2OK, fmi2FreeFMUstate(c, &s));
    fmi2FreeInstance(c);
    free(ref);
    free(buf);
}

/* --- threads ---------------------------------------------------------------------- */

typedef struct {
    const Opts *o;
    int k;
    Env env;
    double out[MAX_OUT];
} Job;

static void *thread_main(void *arg) {
    Job *j = arg;
    cycle(&j->env, j->o, j->k, 0, j->out);
    return NULL;
}

static void threads(const Opts *o, int n) {
    static Job seq[MAX_THREADS], par[MAX_THREADS];
    pthread_t th[MAX_THREADS];
    for (int i = 0; i < n; i++) {
        seq[i].o = par[i].o = o;
        seq[i].k = par[i].k = i;
        seq[i].env.verbose = par[i].env.verbose = o->verbose;
        thread_main(&seq[i]);
    }
    for (int i = 0; i < n; i++) EXPECT(pthread_create(&th[i], NULL, thread_main, &par[i]) == 0, "pthread_create");
    for (int i = 0; i < n; i++) pthread_join(th[i], NULL);
    for (int i = 0; i < n; i++)
        EXPECT(same_bits(seq[i].out, par[i].out, g_n_out), "thread %d differs from the sequential run", i);
    printf("threads: %d instances stepped at once agree with one after another\n", n);
}

/* --- main -------------------------------------------------------------------------- */

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: %s RESOURCE_URI [--cycles N] [--stop T] [--step H] [--threads K] "
                        "[--corrupt R] [--fieldwise] [--seed S] [--verbose]\n", argv[0]);
        return 2;
    }
    Opts o = {argv[1], 0.05, 0.01, "", 0};
    int cycles = 0, n_threads = 0, corrupt = 0, fieldwise = 0;
    for (int i = 2; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : "0";
        if (!strcmp(a, "--cycles")) cycles = atoi(v), i++;
        else if (!strcmp(a, "--stop")) o.stop = atof(v), i++;
        else if (!strcmp(a, "--step")) o.h = atof(v), i++;
        else if (!strcmp(a, "--threads")) n_threads = atoi(v), i++;
        else if (!strcmp(a, "--corrupt")) corrupt = atoi(v), i++;
        else if (!strcmp(a, "--seed")) rng_state ^= strtoull(v, NULL, 10) * 0x9E3779B97F4A7C15ULL, i++;
        else if (!strcmp(a, "--verbose")) o.verbose = 1;
        else if (!strcmp(a, "--fieldwise")) fieldwise = 1;
        else {
            fprintf(stderr, "unknown argument %s\n", a);
            return 2;
        }
    }
    if (!(o.stop > 0 && o.h > 0 && o.h <= o.stop) || n_threads > MAX_THREADS || cycles < 0) {
        fprintf(stderr, "bad arguments\n");
        return 2;
    }
    for (int vr = 1; vr <= LSS_N_VARS && g_n_out < MAX_OUT; vr++)
        if (!LSS_VARS[vr].in_params && LSS_VARS[vr].type == LSS_REAL) g_out_vr[g_n_out++] = (fmi2ValueReference)vr;

    const char *tmp = getenv("TMPDIR");
    snprintf(o.tmpdir, sizeof o.tmpdir, "%s/lss_harness_XXXXXX", tmp && tmp[0] ? tmp : "/tmp");
    if (!mkdtemp(o.tmpdir)) {
        perror("mkdtemp");
        return 2;
    }
    char p1[700], p2[700];
    snprintf(p1, sizeof p1, "%s/bad_syntax.layout", o.tmpdir);
    snprintf(p2, sizeof p2, "%s/open.layout", o.tmpdir);
    write_file(p1, HEAD "straight 5\ncurve 3 90\n");
    write_file(p2, HEAD "straight 10\ncurve 3 90 left\nstraight 10\n");

    Env env;
    memset(&env, 0, sizeof env);
    env.verbose = o.verbose;
    for (int k = 0; k < cycles; k++) {
        cycle(&env, &o, k, 1, NULL);
        if (k % 5 == 4) error_path(&env, &o, (k / 5) % 9);
    }
    if (cycles >= 45) printf("error paths: all 9 kinds run %d times or more\n", cycles / 45);
    if (n_threads > 0) threads(&o, n_threads);
    if (corrupt > 0) corrupt_states(&env, &o, corrupt);
    if (fieldwise) fieldwise_states(&env, &o);

    unlink(p1);
    unlink(p2);
    rmdir(o.tmpdir);
    printf("vector paths used: scalar %ld, avx2 %ld, avx512 %ld\n", atomic_load(&g_path_used[1]),
           atomic_load(&g_path_used[2]), atomic_load(&g_path_used[3]));
    long live = atomic_load(&g_live);
    EXPECT(live == 0, "%ld blocks allocated through the callbacks were never freed", live);
    printf("summary: cycles %d, FMI calls checked %ld, bad inputs %ld (error %ld, discard %ld, warning %ld, ok %ld), "
           "messages error %ld / discard %ld / warning %ld, allocations %ld, live at exit %ld, failures %ld\n",
           cycles, atomic_load(&g_calls), atomic_load(&g_bad_inputs), atomic_load(&g_outcome[fmi2Error]),
           atomic_load(&g_outcome[fmi2Discard]), atomic_load(&g_outcome[fmi2Warning]),
           atomic_load(&g_outcome[fmi2OK]), env.n_msg[fmi2Error], env.n_msg[fmi2Discard],
           env.n_msg[fmi2Warning], atomic_load(&g_allocs), live, atomic_load(&g_failures));
    return atomic_load(&g_failures) ? 1 : 0;
}
