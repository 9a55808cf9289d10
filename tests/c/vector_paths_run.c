/* Runs the FMU's sources, linked in, on layouts and right-hand-side paths
 * through the FMI 2.0 API, and prints the outputs at the end of each run:
 * built by tests/test_vector_sanitizers.py at -O2 (the reference) and at -O0
 * and -O1 under AddressSanitizer + UndefinedBehaviorSanitizer, whose results
 * must agree with the reference.
 *
 *   vector_paths_run RESOURCE_URI STOP STEP TOL LAYOUT:PATH [LAYOUT:PATH ...]
 *
 * PATH is solver.vector_path (0 auto, 1 scalar, 2 AVX2, 3 AVX-512). For each
 * run one line
 *
 *   run LAYOUT PATH USED N_STEPS v_1 ... v_n
 *
 * with USED = solver.vector_path_used and v the Real outputs (%.17g, in
 * value-reference order; a line "names ..." first lists them). Exit code 0
 * when every FMI call succeeded and every block allocated through the
 * callbacks was returned. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "lss_guid.h"
#include "lss_vars.h"

#define MAX_OUT 64

static long g_live, g_failures;

static void *h_calloc(size_t n, size_t size) {
    void *p = calloc(n, size);
    if (p) g_live++;
    return p;
}

static void h_free(void *p) {
    if (p) g_live--;
    free(p);
}

static void h_logger(fmi2ComponentEnvironment e, fmi2String instance, fmi2Status status, fmi2String category,
                     fmi2String message, ...) {
    (void)e;
    (void)category;
    if (status == fmi2OK) return;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s %d] ", instance ? instance : "?", (int)status);
    vfprintf(stderr, message ? message : "(null)", ap);
    fputc('\n', stderr);
    va_end(ap);
}

#define CHECK(call) \
    do { \
        fmi2Status st_ = (call); \
        if (st_ != fmi2OK) { \
            fprintf(stderr, "FAIL: %s returned %d\n", #call, (int)st_); \
            g_failures++; \
            goto done; \
        } \
    } while (0)

static void run(const char *uri, double stop, double h, double tol, const char *layout, int path,
                const fmi2ValueReference *vr_out, int n_out) {
    fmi2CallbackFunctions cb = {h_logger, h_calloc, h_free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("run", fmi2CoSimulation, LSS_GUID, uri, &cb, fmi2False, fmi2False);
    if (!c) {
        fprintf(stderr, "FAIL: fmi2Instantiate\n");
        g_failures++;
        return;
    }
    fmi2ValueReference vr_s = VR_LAYOUT_NAME, vr_p = VR_SOLVER_VECTOR_PATH, vr_t = VR_SOLVER_TOLERANCE;
    fmi2ValueReference vr_u = VR_SOLVER_VECTOR_PATH_USED;
    fmi2Integer ip = path, used = -1;
    fmi2Real out[MAX_OUT];
    int steps = (int)lround(stop / h);
    double t = 0.0;
    CHECK(fmi2SetString(c, &vr_s, 1, &layout));
    CHECK(fmi2SetInteger(c, &vr_p, 1, &ip));
    CHECK(fmi2SetReal(c, &vr_t, 1, &tol));
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop));
    CHECK(fmi2EnterInitializationMode(c));
    CHECK(fmi2ExitInitializationMode(c));
    CHECK(fmi2GetInteger(c, &vr_u, 1, &used));
    for (int i = 1; i <= steps; i++) {
        double tn = i == steps ? stop : i * h;
        CHECK(fmi2DoStep(c, t, tn - t, fmi2True));
        t = tn;
    }
    CHECK(fmi2GetReal(c, vr_out, (size_t)n_out, out));
    printf("run %s %d %d %d", layout, path, (int)used, steps);
    for (int i = 0; i < n_out; i++) printf(" %.17g", out[i]);
    printf("\n");
    CHECK(fmi2Terminate(c));
done:
    fmi2FreeInstance(c);
}

int main(int argc, char **argv) {
    if (argc < 6) {
        fprintf(stderr, "usage: %s RESOURCE_URI STOP STEP TOL LAYOUT:PATH [LAYOUT:PATH ...]\n", argv[0]);
        return 2;
    }
    double stop = atof(argv[2]), h = atof(argv[3]), tol = atof(argv[4]);
    if (!(stop > 0 && h > 0 && h <= stop && tol > 0)) {
        fprintf(stderr, "bad STOP, STEP or TOL\n");
        return 2;
    }
    fmi2ValueReference vr_out[MAX_OUT];
    int n_out = 0;
    printf("names");
    for (int vr = 1; vr <= LSS_N_VARS && n_out < MAX_OUT; vr++)
        if (!LSS_VARS[vr].in_params && LSS_VARS[vr].type == LSS_REAL) {
            vr_out[n_out++] = (fmi2ValueReference)vr;
            printf(" %s", LSS_VARS[vr].name);
        }
    printf("\n");
    for (int a = 5; a < argc; a++) {
        char layout[256];
        const char *colon = strrchr(argv[a], ':');
        if (!colon || colon == argv[a] || (size_t)(colon - argv[a]) >= sizeof layout) {
            fprintf(stderr, "bad case %s (LAYOUT:PATH)\n", argv[a]);
            return 2;
        }
        memcpy(layout, argv[a], (size_t)(colon - argv[a]));
        layout[colon - argv[a]] = '\0';
        run(argv[1], stop, h, tol, layout, atoi(colon + 1), vr_out, n_out);
    }
    if (g_live != 0) {
        fprintf(stderr, "FAIL: %ld blocks allocated through the callbacks were never freed\n", g_live);
        g_failures++;
    }
    return g_failures ? 1 : 0;
}
