/* Closed 3D track: elements of constant body-frame turn rate.
 *
 * Every element carries its start point c0, its start frame R0 = [t n b]
 * (tangent, lateral-left, up as columns) and a constant turn rate w (rad/m) in
 * that frame, so that along the element
 *     R(s) = R0 exp(sigma [w]x),  c(s) = c0 + R0 int_0^sigma exp(u [w]x) e_x du,
 * sigma = s - s0, both in closed form (Rodrigues). Straights have w = 0,
 * vertical curves turn about the lateral axis, horizontal curves and spirals
 * turn about the world vertical at the incline they are entered with. The
 * lateral axis n therefore stays horizontal: there is no banking. The
 * residual closure error (< 1 mm in an accepted layout) is removed from the
 * position by a linear blend over arc length so the loop is seamless. */
#ifndef LSS_TRACK_H
#define LSS_TRACK_H

#include "layout_io.h"

typedef struct {
    ElementKind kind;
    int line;
    double s0, length;
    double c0[3], R0[9];
    double w[3];     /* turn rate in the element frame, rad/m */
    double k, u[3];  /* |w| and its unit axis (u = 0 when k = 0) */
    /* Precomputed at build, so that evaluating a frame costs one sin/cos and
     * a few multiply-adds: with K = [u]x (element frame),
     *   R(sigma) = R0 + sin(k sigma) A + (1 - cos(k sigma)) B,  A = R0 K, B = R0 K^2,
     *   c(sigma) = c0 + sigma t0 + (1 - cos)/k A e_x + (sigma - sin/k) B e_x. */
    double A[9], B[9];
    double K[9], K2[9];  /* [u]x and [u]x^2: the frame moves by exp(ds [w]x) = I + sin K + (1-cos) K^2 */
    int planar;          /* no twist (u_x = 0 to 1e-12): a straight line or a plane circular arc */
    double ik;           /* 1 / k (0 on a straight) */
    double uy, uz;       /* planar: the axis u = (0, uy, uz); m = K e_x = (0, uz, -uy) points to the centre */
} TrackElement;

typedef struct {
    int n;
    TrackElement *el;
    double length;
    double closure[3];       /* c(L) - c(0) before correction, m */
    double closure_angle;    /* rad */
    int n_motors;
    double *motor_s0, *motor_s1;  /* sorted motor intervals on the arc length */
} Track;

typedef struct {
    double s;        /* wrapped to [0, length) */
    double c[3];     /* centreline point at running-surface height */
    double R[9];     /* frame, columns t n b */
    double w[3];     /* turn rate in the frame, rad/m */
    int el;
} TrackFrame;

/* Builds the track from a layout. Returns 0 or fills err ("line N: ...").
 * Position closure must be within tol_pos (m), direction within tol_ang (rad). */
int track_build(const LayoutSpec *spec, double motor_length, double tol_pos, double tol_ang,
                Track *track, const LSSAlloc *a, char *err, size_t errlen);
void track_free(Track *track, const LSSAlloc *a);

/* Frame at arc length s (wrapped). *hint is the element index to start the
 * search from and is updated; pass NULL to search from the start. */
void track_frame(const Track *track, double s, int *hint, TrackFrame *f);

/* Arc length of the centreline point whose normal plane contains p, found by
 * Newton from s_guess (a few iterations from a warm start). Fills f. */
double track_project(const Track *track, const double *p, double s_guess, int *hint, TrackFrame *f);

/* Signed arc-length difference b - a wrapped to (-L/2, L/2]. */
double track_ds(const Track *track, double a, double b);

#endif
