/* The Hunt-Crossley family: F = K d^n (1 + chi(e) ddot/v_i), clipped at 0.
 * chi(e) depends on the damping law; it is computed once per parameter change
 * (for GZ by solving the exact relation), never in the right-hand side. */
#ifndef LSS_CONTACT_H
#define LSS_CONTACT_H

#include <math.h>

typedef enum { LAW_HC = 1, LAW_HW = 2, LAW_LW = 3, LAW_LN = 4, LAW_GZ = 5, LAW_FL = 6 } ContactLawCode;

typedef struct {
    double K;      /* stiffness coefficient, N/m^n */
    double n;      /* exponent */
    double chi;    /* dimensionless hysteresis factor chi(e); lambda = chi K / v_i */
    double e;      /* nominal coefficient of restitution */
} ContactLaw;

/* chi(e) of a law; returns NaN for an unknown code or e outside (0, 1]. */
double contact_chi(int code, double e);

/* The nonzero root of ln((1+x)/(1-e x)) = (1+e) x, x in (0, 1/e): the
 * restitution relation of one Hunt-Crossley impact (0 for e = 1). */
double contact_chi_exact(double e);

/* Restitution an impact really has with hysteresis factor chi (the inverse
 * of contact_chi_exact): the e in (0, 1] solving the same relation. */
double contact_restitution_of_chi(double chi);

static inline double contact_pow(double d, double n) {
    if (n == 1.5) return d * sqrt(d);
    if (n == 1.0) return d;
    if (n == 2.0) return d * d;
    return pow(d, n);
}

/* Force (>= 0) of an indentation d > 0 closing at rate ddot, with the onset
 * velocity v_i; *f_el receives the elastic part K d^n. */
static inline double contact_force(const ContactLaw *L, double d, double ddot, double v_i, double *f_el) {
    double fe = L->K * contact_pow(d, L->n);
    double f = fe * (1.0 + L->chi * ddot / v_i);
    *f_el = fe;
    return f > 0.0 ? f : 0.0;
}

/* Elastic energy stored at indentation d: K d^(n+1) / (n+1). */
static inline double contact_energy(const ContactLaw *L, double d) {
    return d > 0 ? L->K * contact_pow(d, L->n) * d / (L->n + 1.0) : 0.0;
}

#endif
