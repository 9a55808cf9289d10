/* Dormand-Prince 5(4) with PI step-size control (used inside fmi2DoStep).
 *
 * Why not Cash-Karp (the paper's pair): both cost six right-hand sides per
 * step, but Dormand-Prince has the smaller error constants and the last stage
 * is the next step's first (FSAL), so an accepted step costs six evaluations,
 * not seven. The error is measured in the max norm: with hundreds of carts an
 * RMS norm would let one cart's impact drown in the quiet of the others.
 * Steps are cut to land exactly on the end time; the step-size proposal
 * survives the cut, so communication points cost no accuracy and few steps. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "dopri5.h"

static const double
    c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9,
    a21 = 1.0 / 5,
    a31 = 3.0 / 40, a32 = 9.0 / 40,
    a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9,
    a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561, a54 = -212.0 / 729,
    a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176, a65 = -5103.0 / 18656,
    a71 = 35.0 / 384, a73 = 500.0 / 1113, a74 = 125.0 / 192, a75 = -2187.0 / 6784, a76 = 11.0 / 84,
    e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200, e6 = 22.0 / 525,
    e7 = -1.0 / 40;

#define H_MIN 1e-9

void dopri_reset(DopriState *s, double t0, double h0) {
    memset(s, 0, sizeof(*s));
    s->t = t0;
    s->h = h0;
    s->err_prev = 1e-4;
}

/* The stage combinations run over an even count (m = n & ~1) with
 * restrict arguments so that -O2 vectorises them (two doubles per SSE2
 * instruction); the odd last component, if any, follows in scalar code.
 * Where GCC builds for x86-64 with glibc they are also compiled for AVX2 and
 * AVX-512 (target_clones: the dynamic loader picks one per process from
 * the CPU, an ifunc, so there is no dispatch state of ours); each lane does
 * the same arithmetic in the same order, so every clone gives the same bits.
 * Not with other C libraries: ifuncs need glibc's loader (musl's has none).
 * Not under ThreadSanitizer: GCC instruments the resolver it generates
 * (__tsan_func_entry, whatever attributes the function carries), and the
 * loader runs resolvers while it relocates the executable, before the TSan
 * runtime has started: a TSan build linked with the core crashed in comb1's
 * resolver at start-up (GCC 12). AddressSanitizer builds keep the clones
 * (their resolvers run fine); the vector right-hand sides (chain_simd.h) are
 * picked per instance, no ifunc, and run under every sanitizer. */
#if defined(__GNUC__) && __GNUC__ >= 7 && !defined(__clang__) && !defined(__INTEL_COMPILER) && \
    defined(__x86_64__) && defined(__GLIBC__) && !defined(LSS_NO_SIMD) && !defined(__SANITIZE_THREAD__)
#define STAGE_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define STAGE_CLONES
#endif
STAGE_CLONES static void comb1(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + b0 * k0[i];
    for (int i = m; i < n; i++) o[i] = y[i] + b0 * k0[i];
}
STAGE_CLONES static void comb2(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i]);
}
STAGE_CLONES static void comb3(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1, double b2, const double *restrict k2) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i]);
}
STAGE_CLONES static void comb4(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1, double b2, const double *restrict k2, double b3,
                  const double *restrict k3) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i]);
}
STAGE_CLONES static void comb5(int n, double *restrict o, const double *restrict y, double b0, const double *restrict k0,
                  double b1, const double *restrict k1, double b2, const double *restrict k2, double b3,
                  const double *restrict k3, double b4, const double *restrict k4) {
    int m = n & ~1;
    for (int i = 0; i < m; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i] + b4 * k4[i]);
    for (int i = m; i < n; i++) o[i] = y[i] + (b0 * k0[i] + b1 * k1[i] + b2 * k2[i] + b3 * k3[i] + b4 * k4[i]);
}
/* |sum g_j k_j| / (tol (scale + rel max(|y|, |y_new|))) per component into
 * o, and their max (0 if n = 0) in the same pass (a max over eight lanes,
 * which the compiler vectorises); a NaN anywhere makes the caller redo the
 * max by max_norm below, whose order decides what a NaN gives. */
STAGE_CLONES static double err_ratio(int n, double *restrict o, const double *restrict y, const double *restrict yn,
                      const double *restrict sc, const double *restrict rl, double tol, const double *g,
                      const double *restrict k0, const double *restrict k2, const double *restrict k3,
                      const double *restrict k4, const double *restrict k5, const double *restrict k6,
                      int *nan) {
    const double g1 = g[0], g3 = g[1], g4 = g[2], g5 = g[3], g6 = g[4], g7 = g[5];
    double mx[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    int bad = 0, m = n & ~7;
    for (int i = 0; i < m; i += 8)
        for (int l = 0; l < 8; l++) {
            int j = i + l;
            double e = g1 * k0[j] + g3 * k2[j] + g4 * k3[j] + g5 * k4[j] + g6 * k5[j] + g7 * k6[j];
            double ay = fabs(y[j]), an = fabs(yn[j]);
            double r = fabs(e) / (tol * (sc[j] + rl[j] * (ay > an ? ay : an)));
            o[j] = r;
            mx[l] = r > mx[l] ? r : mx[l];
            bad |= r != r;
        }
    for (int i = m; i < n; i++) {
        double e = g1 * k0[i] + g3 * k2[i] + g4 * k3[i] + g5 * k4[i] + g6 * k5[i] + g7 * k6[i];
        double ay = fabs(y[i]), an = fabs(yn[i]);
        double r = fabs(e) / (tol * (sc[i] + rl[i] * (ay > an ? ay : an)));
        o[i] = r;
        mx[0] = r > mx[0] ? r : mx[0];
        bad |= r != r;
    }
    *nan = bad;
    double e = 0.0;
    for (int l = 0; l < 8; l++) e = mx[l] > e ? mx[l] : e;
    return e;
}

/* The max norm of the ratios, NaN as the solver has always read it: a
 * component that is not <= the running max replaces it. */
static double max_norm(int n, const double *o) {
    double err = 0.0;
    for (int i = 0; i < n; i++)
        if (!(o[i] <= err)) err = o[i];
    return err;
}

/* One trial step of size h from (t, y) with k[0] = f(t, y); returns the error
 * norm (max norm; NaN/inf if the trial turned non-finite). */
static double trial(Dopri *d, const double *y, double t, double h) {
    int n = d->n;
    double **k = d->k, *yt = d->ytmp, *yn = d->ynew;
    comb1(n, yt, y, h * a21, k[0]);
    d->rhs(d->ctx, t + c2 * h, yt, k[1]);
    comb2(n, yt, y, h * a31, k[0], h * a32, k[1]);
    d->rhs(d->ctx, t + c3 * h, yt, k[2]);
    comb3(n, yt, y, h * a41, k[0], h * a42, k[1], h * a43, k[2]);
    d->rhs(d->ctx, t + c4 * h, yt, k[3]);
    comb4(n, yt, y, h * a51, k[0], h * a52, k[1], h * a53, k[2], h * a54, k[3]);
    d->rhs(d->ctx, t + c5 * h, yt, k[4]);
    comb5(n, yt, y, h * a61, k[0], h * a62, k[1], h * a63, k[2], h * a64, k[3], h * a65, k[4]);
    d->rhs(d->ctx, t + h, yt, k[5]);
    comb5(n, yn, y, h * a71, k[0], h * a73, k[2], h * a74, k[3], h * a75, k[4], h * a76, k[5]);
    d->rhs(d->ctx, t + h, yn, k[6]);
    const double g[6] = {h * e1, h * e3, h * e4, h * e5, h * e6, h * e7};
    int nan;
    double err = err_ratio(n, yt, y, yn, d->scale, d->rel, d->tol, g, k[0], k[2], k[3], k[4], k[5], k[6], &nan);
    return nan ? max_norm(n, yt) : err;
}


/* --- DOP853 ----------------------------------------------------------------
 * Dormand and Prince's explicit pair of order 8 with error estimators of
 * orders 5 and 3 (P. J. Prince and J. R. Dormand, High order embedded
 * Runge-Kutta formulae, J. Comput. Appl. Math. 7 (1981) 67-75; in the form
 * of E. Hairer, S. P. Norsett and G. Wanner, Solving Ordinary Differential
 * Equations I, 2nd ed., Springer 1993, section II.10, and their code
 * DOP853). The coefficients below reproduce that published tableau (12
 * stages, the 13th evaluation at the new point is the next step's first);
 * they are printed to 17 significant digits, with the zero entries left out.
 * Hairer's combined error estimate per component,
 *     err = |e5|^2 / sqrt(e5^2 + 0.01 e3^2),
 * is judged in the core's max norm and weights, with the core's
 * controller at exponent 1/8 (no PI term), as in DOP853. */
static const double D8_C[12] = {0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726, 0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0};
/* row i: the nonzero a_ij, j < i, with their j */
static const int D8_AN[12] = {0, 1, 2, 2, 3, 3, 4, 5, 6, 7, 8, 9};
static const int D8_AJ[12][9] = {{0}, {0}, {0, 1}, {0, 2}, {0, 2, 3}, {0, 3, 4}, {0, 3, 4, 5}, {0, 3, 4, 5, 6}, {0, 3, 4, 5, 6, 7}, {0, 3, 4, 5, 6, 7, 8}, {0, 3, 4, 5, 6, 7, 8, 9}, {0, 3, 4, 5, 6, 7, 8, 9, 10}};
static const double D8_A[12][9] = {{0}, {0.05260015195876773},
    {0.0197250569845379, 0.0591751709536137},
    {0.02958758547680685, 0.08876275643042054},
    {0.2413651341592667, -0.8845494793282861, 0.924834003261792},
    {0.037037037037037035, 0.17082860872947386, 0.12546768756682242},
    {0.037109375, 0.17025221101954405, 0.06021653898045596, -0.017578125},
    {0.03709200011850479, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023},
    {0.6241109587160757, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996},
    {0.47766253643826434, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627},
    {-0.9371424300859873, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196},
    {2.273310147516538, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636}};
/* b_j, e5_j, e3_j of the stages 1, 6..12 (the others are zero) */
static const int D8_J[8] = {0, 5, 6, 7, 8, 9, 10, 11};
static const double D8_B[8] = {0.054293734116568765, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259};
static const double D8_E5[8] = {0.01312004499419488, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294};
static const double D8_E3[8] = {-0.18980075407240762, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.4226823213237919, -0.1521609496625161, 0.20136540080403034, 0.02265179219836082};

/* o = y + sum_j a_j k_j over the listed stages (na of them, 1 to 9) in one
 * pass over the components: each stage's vectors are read once, not once per
 * group of four terms. */
#define T1 (a0 * k0[i])
#define T2 (T1 + a1 * k1[i])
#define T3 (T2 + a2 * k2[i])
#define T4 (T3 + a3 * k3[i])
#define T5 (T4 + a4 * k4[i])
#define T6 (T5 + a5 * k5[i])
#define T7 (T6 + a6 * k6[i])
#define T8 (T7 + a7 * k7[i])
#define T9 (T8 + a8 * k8[i])
STAGE_CLONES static void comb853(int n, double *restrict o, const double *restrict y, int na, const double *a,
                                 const double *restrict k0, const double *restrict k1, const double *restrict k2,
                                 const double *restrict k3, const double *restrict k4, const double *restrict k5,
                                 const double *restrict k6, const double *restrict k7, const double *restrict k8) {
    double c[9] = {0};
    for (int j = 0; j < na && j < 9; j++) c[j] = a[j];
    const double a0 = c[0], a1 = c[1], a2 = c[2], a3 = c[3], a4 = c[4], a5 = c[5], a6 = c[6], a7 = c[7], a8 = c[8];
    switch (na) {
    case 1: for (int i = 0; i < n; i++) o[i] = y[i] + T1; break;
    case 2: for (int i = 0; i < n; i++) o[i] = y[i] + T2; break;
    case 3: for (int i = 0; i < n; i++) o[i] = y[i] + T3; break;
    case 4: for (int i = 0; i < n; i++) o[i] = y[i] + T4; break;
    case 5: for (int i = 0; i < n; i++) o[i] = y[i] + T5; break;
    case 6: for (int i = 0; i < n; i++) o[i] = y[i] + T6; break;
    case 7: for (int i = 0; i < n; i++) o[i] = y[i] + T7; break;
    case 8: for (int i = 0; i < n; i++) o[i] = y[i] + T8; break;
    default: for (int i = 0; i < n; i++) o[i] = y[i] + T9; break;
    }
}
#undef T1
#undef T2
#undef T3
#undef T4
#undef T5
#undef T6
#undef T7
#undef T8
#undef T9

static void combn(int n, double *o, const double *y, int na, const double *a, double *const *k) {
    const double *kk[9];
    for (int j = 0; j < 9; j++) kk[j] = k[j < na ? j : 0];  /* the unused ones: read by no term */
    comb853(n, o, y, na, a, kk[0], kk[1], kk[2], kk[3], kk[4], kk[5], kk[6], kk[7], kk[8]);
}

/* the eight stages that carry b, e5 and e3 */
STAGE_CLONES static void err853(int n, double *restrict o, const double *restrict y, const double *restrict yn,
                                const double *restrict sc, const double *restrict rl, double tol, double h,
                                double *const *k) {
    const double *restrict k0 = k[0], *restrict k5 = k[5], *restrict k6 = k[6], *restrict k7 = k[7];
    const double *restrict k8 = k[8], *restrict k9 = k[9], *restrict k10 = k[10], *restrict k11 = k[11];
    const double *E5 = D8_E5, *E3 = D8_E3;
    for (int i = 0; i < n; i++) {
        double e5 = h * (E5[0] * k0[i] + E5[1] * k5[i] + E5[2] * k6[i] + E5[3] * k7[i] + E5[4] * k8[i] +
                         E5[5] * k9[i] + E5[6] * k10[i] + E5[7] * k11[i]);
        double e3 = h * (E3[0] * k0[i] + E3[1] * k5[i] + E3[2] * k6[i] + E3[3] * k7[i] + E3[4] * k8[i] +
                         E3[5] * k9[i] + E3[6] * k10[i] + E3[7] * k11[i]);
        double ay = fabs(y[i]), an = fabs(yn[i]);
        double den = tol * (sc[i] + rl[i] * (ay > an ? ay : an));
        double d = sqrt(e5 * e5 + 0.01 * e3 * e3);
        o[i] = d > 0.0 ? fabs(e5) / den * (fabs(e5) / d) : 0.0;
    }
}

/* One DOP853 trial step from (t, y) with k[0] = f(t, y): the new point in
 * ynew, and the error norm (NaN/inf if the trial turned non-finite). The
 * 13th evaluation (at the new point) is left to the caller: a rejected
 * step does not need it. */
static double trial853(Dopri *d, const double *y, double t, double h) {
    int n = d->n;
    double **k = d->k, *yt = d->ytmp, *yn = d->ynew;
    double a[9];
    double *kk[9];
    for (int s = 1; s < 12; s++) {
        for (int j = 0; j < D8_AN[s]; j++) {
            a[j] = h * D8_A[s][j];
            kk[j] = k[D8_AJ[s][j]];
        }
        combn(n, yt, y, D8_AN[s], a, kk);
        d->rhs(d->ctx, t + D8_C[s] * h, yt, k[s]);
    }
    for (int j = 0; j < 8; j++) {
        a[j] = h * D8_B[j];
        kk[j] = k[D8_J[j]];
    }
    combn(n, yn, y, 8, a, kk);
    err853(n, yt, y, yn, d->scale, d->rel, d->tol, h, k);
    double err = 0.0;
    for (int i = 0; i < n; i++)
        if (!(yt[i] <= err)) err = yt[i];
    return err;
}

/* An accepted step of size h landing at t_new: the new point, the next
 * step's first evaluation (DOP853: the 13th) and the accepted callback. */
static void accept_step(Dopri *d, DopriState *st, double *y, double t_new, double h) {
    const int d853 = d->method == DOPRI_DOP853;
    st->t = t_new;
    memcpy(y, d->ynew, sizeof(double) * (size_t)d->n);
    int last_k = 6;
    if (d853) {
        d->rhs(d->ctx, st->t, y, d->k[12]);
        st->n_rhs++;
        last_k = 12;
    }
    double *tmp = d->k[0];
    d->k[0] = d->k[last_k];
    d->k[last_k] = tmp;
    st->n_steps++;
    st->h_last = h;
}

int dopri_replay(Dopri *d, DopriState *st, double *y, const double *h, const double *t, long n,
                 char *err, size_t errlen) {
    const int d853 = d->method == DOPRI_DOP853;
    for (long i = 0; i < n; i++) {
        if (!st->fsal_valid) {
            d->rhs(d->ctx, st->t, y, d->k[0]);
            st->n_rhs++;
            st->fsal_valid = 1;
        }
        double e = d853 ? trial853(d, y, st->t, h[i]) : trial(d, y, st->t, h[i]);
        st->n_rhs += d853 ? 11 : 6;
        int finite = isfinite(e);
        for (int j = 0; finite && j < d->n; j++) finite = isfinite(d->ynew[j]);
        if (!finite) {
            snprintf(err, errlen, "the follower's state turned non-finite in the step of %g s from t = %.9g s",
                     h[i], st->t);
            return 1;
        }
        accept_step(d, st, y, t[i], h[i]);
        st->h = h[i];
        if (d->accepted && d->accepted(d->ctx, st->t, y)) st->fsal_valid = 0;
    }
    return 0;
}

int dopri_integrate(Dopri *d, DopriState *st, double *y, double t_end, char *err, size_t errlen) {
    int n = d->n;
    double span = fabs(t_end) + 1.0;
    /* a state that cannot advance is refused, not looped on (NaN fails every comparison) */
    if (!isfinite(st->t) || !isfinite(t_end) || !isfinite(st->h) || !(st->h > 0) ||
        !(st->err_prev > 0 && st->err_prev <= 1.0)) {
        snprintf(err, errlen, "invalid solver state (t = %g s, h = %g s, error memory %g, end time %g s)",
                 st->t, st->h, st->err_prev, t_end);
        return 1;
    }
    /* accepted and rejected steps of this call: at most DOPRI_MAX_STEPS beyond
       twice the steps h_max alone forces on the span */
    double forced = (t_end - st->t) / d->h_max;
    long trials = 0, max_trials = DOPRI_MAX_STEPS + (forced > 0 ? (forced < 1e15 ? 2 * (long)ceil(forced) : (long)2e15) : 0);
    while (st->t < t_end - 1e-13 * span) {
        if (!st->fsal_valid) {
            d->rhs(d->ctx, st->t, y, d->k[0]);
            st->n_rhs++;
            st->fsal_valid = 1;
        }
        double h_prop = st->h > d->h_max ? d->h_max : st->h;
        double h = h_prop;
        int last = 0;
        if (st->t + h >= t_end - 1e-13 * span) {
            h = t_end - st->t;
            last = 1;
        }
        const int d853 = d->method == DOPRI_DOP853;
        for (;;) {
            if (++trials > max_trials) {
                snprintf(err, errlen, "more than %ld internal steps (the limit for this step) at t = %.9g s, "
                         "%.3g s short of the end time; the last step size was %g s",
                         max_trials, st->t, t_end - st->t, h);
                return 1;
            }
            if (!last && !(st->t + h > st->t)) {
                snprintf(err, errlen, "step size %g s is below the resolution of the time t = %.17g s", h, st->t);
                return 1;
            }
            double e = d853 ? trial853(d, y, st->t, h) : trial(d, y, st->t, h);
            st->n_rhs += d853 ? 11 : 6;
            if (!isfinite(e)) {
                st->n_rejected++;
                h *= 0.25;
                last = 0;
                if (h < H_MIN) {
                    snprintf(err, errlen, "the state turned non-finite at t = %.9g s and step sizes "
                             "down to %g s could not avoid it", st->t, H_MIN);
                    return 1;
                }
                continue;
            }
            /* Hairer's PI controller (beta = 0.04); DOP853: exponent 1/8, no PI term */
            double fac11 = pow(e > 1e-10 ? e : 1e-10, d853 ? 0.125 : 0.17);
            if (e <= 1.0) {
                double fac = (d853 ? fac11 : fac11 / pow(st->err_prev, 0.04)) / 0.9;
                fac = fac < 0.2 ? 0.2 : (fac > 10.0 ? 10.0 : fac);
                double h_new = h / fac;
                st->err_prev = e > 1e-4 ? e : 1e-4;
                accept_step(d, st, y, last ? t_end : st->t + h, h);
                st->h = last ? fmax(fmin(h_new, h_prop), h) : h_new;
                if (d->accepted && d->accepted(d->ctx, st->t, y)) st->fsal_valid = 0;
                break;
            }
            double fac = fac11 / 0.9;
            h /= fac > 5.0 ? 5.0 : fac;
            last = 0;
            st->n_rejected++;
            if (h < H_MIN) {
                snprintf(err, errlen, "step size collapsed below %g s at t = %.9g s", H_MIN, st->t);
                return 1;
            }
        }
    }
    if (!st->fsal_valid) {  /* leave k[0] and the last evaluation at the final state */
        d->rhs(d->ctx, st->t, y, d->k[0]);
        st->n_rhs++;
        st->fsal_valid = 1;
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(y[i])) {
            snprintf(err, errlen, "state %d turned non-finite at t = %.9g s", i, st->t);
            return 1;
        }
    return 0;
}
