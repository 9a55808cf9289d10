/* Test access to the trigonometry-free track projections (track_local.h):
 * they are held against the world-frame search (track_frame and Newton,
 * track_project_face) at pseudo-random points near the track, for every
 * kind of element (straight, plane arc, helix) and every face. */
#include <math.h>

#include "chain.h"
#include "core_api.h"
#include "track_local.h"

static double urand(unsigned long long *x) {  /* xorshift64*, uniform in [0, 1) */
    *x ^= *x >> 12;
    *x ^= *x << 25;
    *x ^= *x >> 27;
    return (double)((*x * 2685821657736338717ULL) >> 11) * (1.0 / 9007199254740992.0);
}

int lss_chain_check_local(void *chain, int n, unsigned seed, double *out5) {
    const Track *t = &((Chain *)chain)->m.track;
    unsigned long long x = 0x9E3779B97F4A7C15ULL ^ seed;
    double worst_ds = 0, worst_d = 0, worst_E = 0, worst_a = 0;
    int declined = 0, hint = 0, checked = 0;
    for (int k = 0; k < n; k++) {
        /* a base anywhere, a point up to 5 cm along, 0.3 m across, 0.25 m up or down */
        double sb = urand(&x) * t->length;
        TrackBase b;
        track_base(t, sb, &hint, &b);
        double q[3] = {(urand(&x) - 0.5) * 0.1, (urand(&x) - 0.5) * 0.6, (urand(&x) - 0.5) * 0.5};
        int face = (int)(urand(&x) * 3.0);
        double h = (urand(&x) < 0.5 ? -1.0 : 1.0) * 0.15;
        double guess = (urand(&x) - 0.5) * 0.1;
        LocalFrame lf, wf;
        if (!tl_project(&b, q, guess, face, h, &lf)) {
            declined++;
            continue;
        }
        int hint2 = b.el;
        track_project_face(t, &b, q, guess, face, h, &hint2, &wf);
        double dds = fabs(lf.ds - wf.ds);
        if (dds > t->length / 2) dds = fabs(dds - t->length);
        if (dds > worst_ds) worst_ds = dds;
        for (int j = 0; j < 3; j++)
            if (fabs(lf.d[j] - wf.d[j]) > worst_d) worst_d = fabs(lf.d[j] - wf.d[j]);
        for (int j = 0; j < 9; j++)
            if (fabs(lf.E[j] - wf.E[j]) > worst_E) worst_E = fabs(lf.E[j] - wf.E[j]);
        /* the defining equation: a = a* at the point found */
        double ra = fabs(lf.d[0] - tl_astar(face, h, lf.d, lf.w));
        if (ra > worst_a) worst_a = ra;
        checked++;
    }
    out5[0] = worst_ds;
    out5[1] = worst_d;
    out5[2] = worst_E;
    out5[3] = worst_a;
    out5[4] = n > 0 ? (double)declined / n : 0.0;
    return checked;
}
