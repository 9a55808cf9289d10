/* A small C driver over the core's test API (fmu_src/testing/core_api.h) for
 * instruction counts with callgrind, so that nothing but the core is counted:
 *
 *   gcc -O2 -o build/profile_core benchmarks/profile_core.c -Ifmu_src/testing \
 *       -Lbuild -llsscore -Wl,-rpath,$PWD/build
 *   valgrind --tool=callgrind build/profile_core layout7 3 1e-4 3 0
 *
 * Arguments: layout, solver.vector_path (0 auto, 1 scalar, 2 AVX2, 3 AVX-512),
 * tolerance, simulated seconds at 300 Hz, solver.method (0 DOPRI5, 1 DOP853).
 * Prints carts, steps, rejected steps and right-hand sides. */
#include <stdio.h>
#include <stdlib.h>

#include "core_api.h"

int main(int argc, char **argv) {
    const char *layout = argc > 1 ? argv[1] : "layout7";
    double path = argc > 2 ? atof(argv[2]) : 0, tol = argc > 3 ? atof(argv[3]) : 1e-4;
    double t_end = argc > 4 ? atof(argv[4]) : 3.0, method = argc > 5 ? atof(argv[5]) : 0;
    char err[1024];
    void *p = lss_params_new();
    lss_params_set_string(p, "layout.name", layout);
    lss_params_set(p, "solver.tolerance", tol);
    lss_params_set(p, "solver.vector_path", path);
    lss_params_set(p, "solver.method", method);
    void *c = lss_chain_new(p, "fmu_src/resources", err, sizeof err);
    lss_params_free(p);
    if (!c) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    int n = (int)(t_end * 300 + 0.5), idx[7] = {0, 1, 2, 3, 4, 5, 6};
    double *out = malloc(sizeof(double) * 7 * (size_t)n);
    if (!out || lss_chain_run(c, 1.0 / 300, n, idx, 0, out, err, sizeof err)) {
        fprintf(stderr, "%s\n", err);
        return 1;
    }
    long st[3];
    lss_chain_stats(c, st);
    printf("%d carts, %ld steps, %ld rejected, %ld rhs\n", lss_chain_n_carts(c), st[0], st[1], st[2]);
    free(out);
    lss_chain_free(c);
    return 0;
}
