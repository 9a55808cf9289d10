/* Moving along the track near a known frame, without trigonometry.
 *
 * Within an element the frame turns at a constant rate w about a fixed axis
 * u (w = k u, frame coordinates), so from a base frame (R_b, c_b) at s_b
 *     R(s_b + ds) = R_b E(ds),            E = I + sin(k ds) K + (1 - cos(k ds)) K^2,
 *     c(s_b + ds) = c_b + R_b pl(ds) - ds closure / L,
 *     pl(ds) = ds e_x + (1 - cos)/k K e_x + (ds - sin/k) K^2 e_x,   K = [u]x,
 * exactly as track_frame evaluates it (the closure blend is linear in s).
 * Every cart keeps a base at the arc length of its axle after the last
 * accepted step (one track_frame per cart and step); all projections of a
 * right-hand side work in that base's coordinates, where |k ds| is a few
 * hundredths: sin and cos are then short series, exact to rounding.
 *
 * A projection finds the point of the track whose "face" contains the query
 * point q (base coordinates, relative to c_b):
 *   TL_NORMAL  the normal plane of the centreline (the axle's arc length),
 *   TL_RUNNING the closest point of the running surface c + y n,
 *   TL_GUIDE   the closest point of the guide face c + h n + z b.
 * Without twist (u_x = 0) the three coincide with the normal plane and, on a
 * plane circular arc, have a closed form (an arctangent); a straight is
 * linear. With twist (helices) the offsets a* of wheels.c apply and Newton
 * iterates, as the world-frame code does. A result that leaves the base's
 * element is not computed here (returns 0): the caller falls back to the
 * world-frame search (track_frame), which crosses elements. */
#ifndef LSS_TRACK_LOCAL_H
#define LSS_TRACK_LOCAL_H

#include "lss_math.h"
#include "track.h"

enum { TL_RUNNING = 0, TL_GUIDE = 1, TL_NORMAL = 2 };
enum { TL_STRAIGHT = 0, TL_PLANAR = 1, TL_TWISTED = 2 };

typedef struct {
    double R[9];               /* frame at the base, world (columns t n b) */
    double c[3];               /* centreline point at the base, world */
    double chat[3];            /* closure blend per metre of ds, base coordinates: R^T closure / L */
    double s;                  /* base arc length, wrapped */
    double lo, hi;             /* the base's element covers ds in [lo, hi) */
    double ich0;               /* 1 / (1 - chat_x) */
    const TrackElement *e;
    int el;
    int kind;                  /* TL_STRAIGHT, TL_PLANAR or TL_TWISTED: the base element's */
} TrackBase;

typedef struct {
    double E[9];               /* frame at the point found: its axes in base coordinates (columns t n b) */
    double d[3];               /* (a, y, z) of the query point in that frame, relative to the centreline */
    double ds;                 /* arc length from the base */
    const double *w;           /* turn rate in the frame, rad/m */
} LocalFrame;

/* Base at arc length s (track.c). */
void track_base(const Track *t, double s, int *hint, TrackBase *b);

/* World-frame search for the rare cases the local one declines (track.c):
 * from s_b + ds_guess across elements, with track_frame; same result
 * definition. *hint is an element hint. */
void track_project_face(const Track *t, const TrackBase *b, const double *q, double ds_guess, int face,
                        double h, int *hint, LocalFrame *lf);

/* sin(th), 1 - cos(th) for th = k ds, and (1 - cos)/k, ds - sin/k without
 * cancellation. Series for |th| < 0.1 (truncation below 1e-20 relative). */
static inline void tl_trig(double k, double ds, double *S, double *C1, double *C1k, double *Sm) {
    double th = k * ds, t2 = th * th;
    if (t2 < 1e-2) {
        double ps = 1.0 - t2 / 20.0 * (1.0 - t2 / 42.0 * (1.0 - t2 / 72.0 * (1.0 - t2 / 110.0)));
        double pc = 1.0 - t2 / 12.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0 * (1.0 - t2 / 90.0 * (1.0 - t2 / 132.0))));
        *S = th * (1.0 - t2 / 6.0 * ps);
        *C1 = 0.5 * t2 * pc;
        *C1k = 0.5 * ds * th * pc;
        *Sm = ds * t2 / 6.0 * ps;
    } else {
        double h = sin(0.5 * th);
        *S = sin(th);
        *C1 = 2.0 * h * h;
        *C1k = *C1 / k;
        *Sm = ds - *S / k;
    }
}

/* E = I + S K + C1 K^2 */
static inline void tl_E(const TrackElement *e, double S, double C1, double *E) {
    for (int j = 0; j < 9; j++) E[j] = S * e->K[j] + C1 * e->K2[j];
    E[0] += 1.0; E[4] += 1.0; E[8] += 1.0;
}

/* Fills lf at ds: E, and d = E^T (q - pl(ds) + ds chat). */
static inline void tl_eval(const TrackBase *b, const double *q, double ds, LocalFrame *lf) {
    const TrackElement *e = b->e;
    double S, C1, C1k, Sm, r[3];
    tl_trig(e->k, ds, &S, &C1, &C1k, &Sm);
    tl_E(e, S, C1, lf->E);
    /* pl = ds e_x + C1k K e_x + Sm K^2 e_x; K e_x, K^2 e_x are column 0 */
    for (int j = 0; j < 3; j++) r[j] = q[j] + ds * b->chat[j] - C1k * e->K[3 * j] - Sm * e->K2[3 * j];
    r[0] -= ds;
    m3_tmulv(lf->d, lf->E, r);
    lf->ds = ds;
    lf->w = e->w;
}

static inline double tl_atan_ratio(double x, double rho) {
    double z = x / rho;
    if (fabs(z) < 0.1) {
        double z2 = z * z;
        return z * (1.0 - z2 * (1.0 / 3 - z2 * (1.0 / 5 - z2 * (1.0 / 7 - z2 * (1.0 / 9 - z2 * (1.0 / 11 -
               z2 * (1.0 / 13 - z2 * (1.0 / 15))))))));
    }
    return atan2(x, rho);
}

/* The offset a* of the face's closest point from the normal plane (zero
 * without twist); wheels.c derives it. */
static inline double tl_astar(int face, double h, const double *d, const double *w) {
    if (face == TL_NORMAL || w[0] == 0.0) return 0.0;
    if (face == TL_GUIDE) return d[2] * w[0] * (d[1] - h) / (1.0 - h * w[2] + d[2] * w[1]);
    return -d[2] * d[1] * w[0] / (1.0 - d[1] * w[2]);
}

#if defined(__GNUC__)
#define TL_INLINE inline __attribute__((always_inline))
#else
#define TL_INLINE inline
#endif

/* Straight: a = q_x - ds (1 - chat_x) = 0; the frame is the base's (E = I). */
static TL_INLINE int tl_project_straight(const TrackBase *b, const double *q, LocalFrame *lf) {
    const double *ch = b->chat;
    double ds = q[0] * b->ich0;
    if (!(ds >= b->lo && ds < b->hi)) return 0;
    lf->E[0] = 1.0; lf->E[1] = 0.0; lf->E[2] = 0.0;
    lf->E[3] = 0.0; lf->E[4] = 1.0; lf->E[5] = 0.0;
    lf->E[6] = 0.0; lf->E[7] = 0.0; lf->E[8] = 1.0;
    lf->d[0] = 0.0;
    lf->d[1] = q[1] + ds * ch[1];
    lf->d[2] = q[2] + ds * ch[2];
    lf->ds = ds;
    lf->w = b->e->w;
    return 1;
}

/* Plane arc: a circle of radius 1/k about m/k, m = K e_x = (0, uz, -uy):
 * the normal plane at angle phi = k ds contains the axis, tan(phi) = x / rho
 * with x = q'.e_x, rho = 1/k - q'.m, where q' = q + ds chat carries the
 * closure blend at ds. That makes ds a fixed point of slope about |chat|
 * (~1e-6): one round from the guess gives ds to |chat| times the guess's
 * error (the wheels start from the axle's ds, a few cm off), and (x, rho)
 * at that ds give the frame; its error is |chat| smaller again (< 1e-13 m).
 * A short series suffices for that ds (truncation < 1e-12 rad); with
 * exact_ds (the axle, whose ds is its arc length) the full series gives ds
 * from the final (x, rho). E = rotation by phi about u, written out. */
static TL_INLINE int tl_project_planar(const TrackBase *b, const double *q, double ds_guess, int exact_ds,
                                       LocalFrame *lf) {
    const TrackElement *e = b->e;
    const double *ch = b->chat;
    double uy = e->uy, uz = e->uz, ik = e->ik;
    double qm = q[1] * uz - q[2] * uy, cm = ch[1] * uz - ch[2] * uy;
    double ds = ds_guess;
    double x = q[0] + ds * ch[0], rho = ik - qm - ds * cm;
    if (!(rho > 0.0)) return 0;
    double z = x / rho, z2 = z * z;
    ds = (z2 < 1e-2 ? z * (1.0 - z2 * (1.0 / 3 - z2 * (1.0 / 5 - z2 * (1.0 / 7 - z2 * (1.0 / 9)))))
                    : atan2(x, rho)) * ik;
    x = q[0] + ds * ch[0];
    rho = ik - qm - ds * cm;
    double rr = 1.0 / sqrt(x * x + rho * rho), S = x * rr, C = rho * rr, C1 = S * S / (1.0 + C);
    double Suy = S * uy, Suz = S * uz, C1uy = C1 * uy, C1uz = C1 * uz, C1yz = C1uy * uz;
    double *E = lf->E;
    E[0] = C;    E[1] = -Suz;            E[2] = Suy;
    E[3] = Suz;  E[4] = 1.0 - C1uz * uz; E[5] = C1yz;
    E[6] = -Suy; E[7] = C1yz;            E[8] = 1.0 - C1uy * uy;
    /* q' - pl, pl = (S e_x + C1 m) / k */
    double r0 = x - S * ik, r1 = q[1] + ds * ch[1] - C1uz * ik, r2 = q[2] + ds * ch[2] + C1uy * ik;
    lf->d[0] = E[0] * r0 + E[3] * r1 + E[6] * r2;
    lf->d[1] = E[1] * r0 + E[4] * r1 + E[7] * r2;
    lf->d[2] = E[2] * r0 + E[5] * r1 + E[8] * r2;
    if (exact_ds) ds = tl_atan_ratio(x, rho) * ik;
    if (!(ds >= b->lo && ds < b->hi)) return 0;
    lf->ds = ds;
    lf->w = e->w;
    return 1;
}

/* Twisted element: Newton as in the world-frame search. */
static inline int tl_project_twisted(const TrackBase *b, const double *q, double ds_guess, int face, double h,
                                     LocalFrame *lf) {
    double ds = ds_guess;
    for (int it = 0; it < 12; it++) {
        if (!(ds >= b->lo - 0.5 && ds < b->hi + 0.5)) return 0;
        tl_eval(b, q, ds, lf);
        const double *d = lf->d, *w = b->e->w;
        double gp = 1.0 - (d[1] * w[2] - d[2] * w[1]);
        double step = (d[0] - tl_astar(face, h, d, w)) / (gp > 0.1 ? gp : 0.1);
        if (fabs(step) < 1e-12) return ds >= b->lo && ds < b->hi;
        ds += step;
    }
    return 0;
}

/* Projection of q (base coordinates) within the base's element, starting
 * from ds_guess; kind is b->kind (a constant where the caller specialises).
 * Returns 1 and fills lf, or 0 if the point found lies outside the element
 * (or the search did not settle there): the caller then uses
 * track_project_face. */
static TL_INLINE int tl_project_kind(const TrackBase *b, const double *q, double ds_guess, int face, double h,
                                     LocalFrame *lf, const int kind) {
    if (kind == TL_STRAIGHT) return tl_project_straight(b, q, lf);
    if (kind == TL_PLANAR) return tl_project_planar(b, q, ds_guess, face == TL_NORMAL, lf);
    return tl_project_twisted(b, q, ds_guess, face, h, lf);
}

static inline int tl_project(const TrackBase *b, const double *q, double ds_guess, int face, double h,
                             LocalFrame *lf) {
    switch (b->kind) {
    case TL_STRAIGHT: return tl_project_kind(b, q, ds_guess, face, h, lf, TL_STRAIGHT);
    case TL_PLANAR: return tl_project_kind(b, q, ds_guess, face, h, lf, TL_PLANAR);
    default: return tl_project_kind(b, q, ds_guess, face, h, lf, TL_TWISTED);
    }
}

#endif
