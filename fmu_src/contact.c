/* chi(e) for the damping laws of the brief's table, and the exact
 * restitution relation that both defines GZ and verifies the others. */
#include "contact.h"

/* g(x)/x^2 with g(x) = ln(1+x) - ln(1-e x) - (1+e) x. Near 0 the series
 * sum_{k>=2} ((-1)^(k+1) + e^k) x^(k-2) / k avoids the cancellation. */
static double g_over_x2(double x, double e) {
    if (x < 0.05) {
        double s = 0, xp = 1, ek = e * e;
        int sign = -1;
        for (int k = 2; k < 60; k++) {
            s += (sign + ek) * xp / k;
            sign = -sign;
            ek *= e;
            xp *= x;
            if (fabs(xp) < 1e-18) break;
        }
        return s;
    }
    return (log1p(x) - log1p(-e * x) - (1.0 + e) * x) / (x * x);
}

double contact_chi_exact(double e) {
    if (!(e > 0.0) || !(e <= 1.0)) return NAN;
    if (e == 1.0) return 0.0;
    /* g/x^2 < 0 near 0 (it tends to (e^2-1)/2) and -> +inf as x -> 1/e */
    double lo = 0.0, hi = 1.0 / e;
    for (int i = 0; i < 200 && hi - lo > 1e-15 * hi; i++) {
        double mid = 0.5 * (lo + hi);
        if (g_over_x2(mid, e) < 0) lo = mid;
        else hi = mid;
    }
    return 0.5 * (lo + hi);
}

double contact_restitution_of_chi(double chi) {
    if (!(chi >= 0.0) || !isfinite(chi)) return NAN;
    if (chi == 0.0) return 1.0;
    /* solve for e in (0, min(1, 1/chi)): g/x^2 increases with e at fixed x */
    double lo = 0.0, hi = fmin(1.0, 1.0 / chi);
    if (g_over_x2(chi, hi * (1 - 1e-15)) < 0) return hi;
    for (int i = 0; i < 200 && hi - lo > 1e-16; i++) {
        double mid = 0.5 * (lo + hi);
        if (g_over_x2(chi, mid) < 0) lo = mid;
        else hi = mid;
    }
    return 0.5 * (lo + hi);
}

double contact_chi(int code, double e) {
    if (!(e > 0.0) || !(e <= 1.0)) return NAN;
    switch (code) {
    case LAW_HC: return 1.5 * (1.0 - e);
    case LAW_HW: return 6.0 * (1.0 - e) / ((2.0 * e - 1.0) * (2.0 * e - 1.0) + 3.0);
    case LAW_LW: return 0.75 * (1.0 - e);
    case LAW_LN: return 0.75 * (1.0 - e * e);
    case LAW_GZ: return contact_chi_exact(e);
    case LAW_FL: return 8.0 * (1.0 - e) / (5.0 * e);
    default: return NAN;
    }
}
