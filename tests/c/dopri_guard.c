/* The solver's guards (issue 20), on small ODEs without the chain:
 * a step size of 0, NaN or < 0, a non-finite time or end time and an error
 * memory out of range are refused at once; a step below the resolution of
 * the time is refused; a stiff problem that would need millions of steps
 * ends at the step limit; a legal run at the smallest h_max is not hurt.
 * Prints one line per case: "name rc steps message". Built and run by
 * tests/test_hostile_input.py. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "dopri5.h"

static void decay(void *ctx, double t, const double *y, double *dy) {  /* y' = -k (y - cos t) */
    double k = *(const double *)ctx;
    dy[0] = -k * (y[0] - cos(t));
}

static void run(const char *name, double k, double h_max, double t0, double h0, double err_prev, double t_end) {
    double y[1] = {1.0}, scale[1] = {1.0}, rel[1] = {0.0}, w[DOPRI_NK + 2][1];
    Dopri d = {.n = 1, .method = DOPRI_DOPRI5, .rhs = decay, .accepted = NULL, .ctx = &k, .scale = scale,
               .rel = rel, .tol = 1e-6, .h_max = h_max, .ytmp = w[DOPRI_NK], .ynew = w[DOPRI_NK + 1]};
    for (int i = 0; i < 7; i++) d.k[i] = w[i];  /* DOPRI5 uses the first seven stages */
    DopriState s;
    dopri_reset(&s, t0, h0);
    s.err_prev = err_prev;
    char err[256] = "";
    int rc = dopri_integrate(&d, &s, y, t_end, err, sizeof err);
    printf("%s %d %ld %s\n", name, rc, s.n_steps + s.n_rejected, rc ? err : "ok");
}

int main(void) {
    run("legal", 1.0, 0.01, 0.0, 1e-4, 1e-4, 1.0);
    run("legal_hmax_1e-6", 1.0, 1e-6, 0.0, 1e-4, 1e-4, 0.01);  /* 10,000 steps */
    run("h_zero", 1.0, 0.01, 0.0, 0.0, 1e-4, 0.01);
    run("h_negative", 1.0, 0.01, 0.0, -1e-3, 1e-4, 0.01);
    run("h_nan", 1.0, 0.01, 0.0, NAN, 1e-4, 0.01);
    run("h_inf", 1.0, 0.01, 0.0, INFINITY, 1e-4, 0.01);
    run("t_nan", 1.0, 0.01, NAN, 1e-4, 1e-4, 0.01);
    run("t_end_nan", 1.0, 0.01, 0.0, 1e-4, 1e-4, NAN);
    run("t_end_inf", 1.0, 0.01, 0.0, 1e-4, 1e-4, INFINITY);
    run("err_prev_zero", 1.0, 0.01, 0.0, 1e-4, 0.0, 0.01);
    run("err_prev_negative", 1.0, 0.01, 0.0, 1e-4, -1.0, 0.01);
    run("no_progress", 1.0, 1e-9, 1e10, 1e-9, 1e-4, 1e10 + 1.0);
    run("stiff", 1e7, 1.0, 0.0, 1e-4, 1e-4, 1.0);  /* stable steps ~3e-7 s: 3 million steps */
    return 0;
}
