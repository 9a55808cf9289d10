/* The vectorised right-hand side (issue 19): the same physics as the scalar
 * path (chain_rhs.c, cart.c, wheels.c, joints.c, drive.c), computed for W
 * carts per instruction (W = 4 with AVX2, 8 with AVX-512).
 *
 * Inside one evaluation the carts' quantities are stored per quantity
 * (structure of arrays, cart order): the state y (13 doubles per cart, as
 * everywhere else) is gathered into Y[13][.] at the start and the
 * derivatives are scattered back at the end, so that y, the solver and the
 * FMU state keep their layout. The carts are taken W at a time ("chunks"):
 *
 *   1. rotation and world angular rate of every cart;
 *   2. each cart against the track in the coordinates of its base (the
 *      track frame at the point of a 5 cm grid nearest its axle after the
 *      last accepted step; the scalar path's is at the axle): the axle's
 *      projection and the four wheels. A chunk whose carts all sit on
 *      straights takes the straight code (the frame is the base's); any
 *      other takes the arc code, which is exact on straights too (the plane
 *      arc's projection written with the curvature k instead of 1/k, so
 *      that k = 0 is a straight). Carts on twisted elements (helices), and
 *      lanes whose projection leaves the base's element or would need the
 *      arctangent beyond its series, are redone by the scalar code
 *      (cart_kinematics, wheel_forces): the rare cases the scalar path also
 *      treats apart;
 *   3. the speed controller (one mean over all carts);
 *   4. the joints, between cart j and cart j+1 (a ghost copy of cart 0
 *      follows cart N-1), each joint's force and its two torques stored per
 *      joint, so that no two lanes write the same cart;
 *   5. the motors (scalar per cart: a walk over the motor list);
 *   6. per cart: wheel, joint (its front joint and the rear of the one
 *      behind) and motor forces summed, Newton-Euler, scattered into dy.
 *
 * Contacts are branch-free: every lane computes the law and a mask keeps
 * the force of the closed ones. Results differ from the scalar path by
 * floating-point reassociation and fused multiply-adds only.
 *
 * The scalar scratch (ChainScratch: indentations, forces, wheel speeds, arc
 * lengths) is filled from the vector one on demand (chain_simd_sync), after
 * an accepted step and for the outputs, not in every evaluation. */
#ifndef LSS_CHAIN_SIMD_H
#define LSS_CHAIN_SIMD_H

#include "rhs_shared.h"

/* The vector paths are compiled where GCC (7 or later: its target pragmas,
 * vector extensions and <cpuid.h>) targets x86-64; elsewhere (clang, icc,
 * other compilers, other machines, or -DLSS_NO_SIMD) only the scalar path
 * exists. Sanitizer builds run them too (tests/test_c_harness.py,
 * tests/test_vector_sanitizers.py). The kernels keep lanes they treat one by
 * one in unions with the vector type (Lanes in chain_simd_kernel.h), never in
 * bare double arrays, and the AVX-512 one has no stack protector under ASan:
 * see there for the two crashes (GCC's, under ASan's fake stack) these avoid. */
#if defined(__GNUC__) && __GNUC__ >= 7 && !defined(__clang__) && !defined(__INTEL_COMPILER) && \
    defined(__x86_64__) && !defined(LSS_NO_SIMD)
#define LSS_HAVE_SIMD 1
#else
#define LSS_HAVE_SIMD 0
#endif

#define SIMD_MAXW 8
#define SIMD_BASE_MOVE 0.05  /* m: grid of the vector paths' base points */
#define SIMD_NMOT 3       /* motor candidates per cart */
#define SIMD_MWIN 0.25    /* half width of the plate window the candidates cover, m */

typedef struct ChainSimd {
    int W;                            /* lanes */
    int N, NW, NP;                    /* carts; rounded up to W; allocated length (NW + W) */
    void *block;                      /* the one allocation behind every array */
    /* state by quantity; [N..NP) copies of cart 0 (the ghost after the last cart, and padding) */
    double *Y[CART_NY];
    double *R[9], *ww[3];             /* rotation body -> world, world angular rate */
    /* the carts' bases (CartScratch.base, by quantity), refreshed when s_hint moves */
    double *bR[9], *bc[3], *ch[3], *bs, *lo, *hi, *ich0, *k, *uy, *uz, *cm;
    double *key;                      /* the grid point each base was built at */
    /* wheels and axle */
    double *Fw[3], *Tw[3];            /* wheel (+ weight, running resistance, motor) force and torque, world */
    double *s, *vt, *t[3];            /* axle arc length, tangential speed, tangent (world) */
    double *ws[N_WHEEL];              /* wheel speeds */
    double *wd[N_WHEEL], *wdd[N_WHEEL], *wf[N_WHEEL];  /* indentation, rate, force */
    double *pdw, *prw;                /* damping and rolling power per cart */
    double p_damp, p_roll;            /* their sums over the carts (with the joints' damping) */
    /* joints: joint j (cart j's front, cart j+1's rear) at index j + 1; index 0 is joint N-1 */
    double *jf[3], *jTA[3], *jTB[3];  /* force on cart j, torque on cart j, torque on cart j+1 */
    double *jd[2], *jdd[2], *jfn[2];  /* axial, radial: indentation, rate, force */
    double *pdj, *jDadot;
    /* the contact memory (ChainState.v_onset) by quantity */
    double *voW[N_WHEEL], *voJ[2];
    double *im, *iI[3], *In[3], *mg;  /* 1 / mass, 1 / principal moments, the moments, the weight */
    /* the motors that can reach each cart's plate while its plate centre
     * stays in [mlo, mhi] (refreshed as it moves): start, end, 1 / length */
    double *mlo, *mhi, *ms0[SIMD_NMOT], *ms1[SIMD_NMOT], *mil[SIMD_NMOT];
    unsigned char *mfull;             /* [NP] more motors than SIMD_NMOT: the scalar walk */
    unsigned char *kind;              /* [NP] TL_* of each base */
    unsigned char *chunk;             /* [NW / W] 0: straight code; 1, 2, 3: arc code (any, about b, about n) */
    int *fix;                         /* [N] carts for the scalar code */
    int n_fix_twisted;                /* fix[0 .. n_fix_twisted) sit on twisted elements */
    int vo_dirty;                     /* v_onset changed since the mirror was taken */
    int base_dirty;                   /* s_hint may have changed since the bases were checked */
    double ir_drive, ir_steer;        /* 1 / wheel radius (no division per chunk) */
    int synced;                       /* the scalar scratch holds the last evaluation */
} ChainSimd;

/* The widest path this build and this CPU can run (cpuid, computed per call). */
int lss_simd_best_path(void);
/* The path for a request (LSS_PATH_*): the requested one, or the next
 * narrower the CPU and build have; AUTO: the best. */
int lss_simd_resolve_path(int requested);

/* Sets c->path and, for a vector path, allocates c->simd. 0, or 1 when out
 * of memory. */
int chain_simd_init(Chain *c, int requested);
void chain_simd_free(Chain *c);
/* ChainState changed outside an evaluation (accepted step, state loaded). */
void chain_simd_invalidate(Chain *c);
/* The per-cart masses and moments of the vector path from the model's (they change with the items). */
void chain_simd_masses(Chain *c);
/* After an accepted step, from the last evaluation (at the new point): the
 * track hints and the contact memory (ChainState) straight from the vector
 * arrays, the mirror of the memory kept with it; the scalar scratch is
 * filled only when asked (chain_simd_sync). Returns 1 if the right-hand
 * side at the new point changed (update_contact_memory's rule). */
int chain_simd_accept(Chain *c);
/* Fills the scalar scratch from the last vector evaluation (no-op on the
 * scalar path or when done). */
void chain_simd_sync(Chain *c);
/* The same for cart i alone (the transducer's outputs). */
void chain_simd_sync_cart(Chain *c, int i);

/* Per-path entry points (chain_simd_avx2.c, chain_simd_avx512.c). */
void chain_rhs_avx2(Chain *c, const double *y, double *dy);
void chain_rhs_avx512(Chain *c, const double *y, double *dy);

/* Shared by both vector paths (chain_simd.c). */
void simd_refresh(Chain *c, const double *y);
void simd_fix_cart(Chain *c, const double *y, int i);
void simd_drive(Chain *c, double F_cmd);
void simd_drive_lane(Chain *c, int i, double F_cmd, double *F);
void simd_finish(Chain *c, const double *y, double *dy, double F_cmd, double zdot, double sum_vt);

#endif
