/* The vector right-hand side, written once for any width: included by
 * chain_simd_avx2.c (VW 4) and chain_simd_avx512.c (VW 8) under their
 * target pragmas, with SIMD_ENTRY the name of the entry point. See
 * chain_simd.h for the scheme; the physics is that of the scalar files named
 * in each kernel, line for line where possible. */
#ifndef VW
#error "chain_simd_kernel.h is included by chain_simd_avx2.c / chain_simd_avx512.c only"
#endif

#include <immintrin.h>
#include <stdint.h>
#include <string.h>

#define KI static inline __attribute__((always_inline))

/* The small loops over components (3, 9, 13 vectors) removed entirely: at
 * -O2 GCC kept many of them as loops over arrays of vectors on the stack,
 * so those values went through memory (in the AVX-512 k_joints, 256 of 576
 * instructions had a stack operand; 129 of 472 with this) and the
 * right-hand side ran 1.2 to 1.3 times slower. Complete peeling changes no
 * arithmetic: the same bits. This file's scope only: the including file
 * pushes and pops the options. */
#pragma GCC optimize("peel-loops")

#if VW == 8 && defined(__SANITIZE_ADDRESS__)
/* No stack protector in the AVX-512 kernels of AddressSanitizer builds (its
 * redzones guard the stack better): with both, GCC 12 misplaces the frame
 * on ASan's fake stack (detect_stack_use_after_return) by the guard's 32
 * bytes, and the 64-byte locals (V R[9] in k_chunk, declared __m512d) sat at
 * 32 mod 64: an ASan SEGV at every level, -O0 to -O2, with
 * -fstack-protector-strong (Ubuntu's default). Later GCCs count the guard
 * (asan.cc, asan_emit_stack_protection). This file's scope only: the
 * including file pushes and pops the options. */
#pragma GCC optimize("no-stack-protector")
#endif

/* --- the vector type and its few operations --------------------------------- */
/* vld and vst are unaligned (loadu, storeu) and touch only the workspace's
 * arrays (chain_simd.c: NP = NW + W slots each, so a chunk at i < NW and the
 * joints' neighbour at i + 1 <= NW stay inside; the offsets i + 1 are not
 * multiples of the width anyway); lanes on the stack are Lanes (below). */
#if VW == 4
typedef __m256d V;
typedef __m256d M;                    /* lane masks: all ones / all zeros */
KI V vset(double x) { return _mm256_set1_pd(x); }
KI V vld(const double *p) { return _mm256_loadu_pd(p); }
KI void vst(double *p, V v) { _mm256_storeu_pd(p, v); }
KI V vsqrt(V a) { return _mm256_sqrt_pd(a); }
KI V vmax(V a, V b) { return _mm256_max_pd(a, b); }  /* b where either is NaN */
KI V vmin(V a, V b) { return _mm256_min_pd(a, b); }
KI V vfma(V a, V b, V c) { return _mm256_fmadd_pd(a, b, c); }
KI V vfms(V a, V b, V c) { return _mm256_fnmadd_pd(a, b, c); }  /* c - a b */
KI M vgt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_GT_OQ); }
KI M vge(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_GE_OQ); }
KI M vlt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_LT_OQ); }
KI M mand(M a, M b) { return _mm256_and_pd(a, b); }
KI int mbits(M a) { return _mm256_movemask_pd(a); }
KI V vsel(M m, V a, V b) { return _mm256_blendv_pd(b, a, m); }  /* m ? a : b */
KI V vand(M m, V a) { return _mm256_and_pd(m, a); }              /* m ? a : 0 */
#define MALL 0xF
#elif VW == 8
typedef __m512d V;
typedef __mmask8 M;
KI V vset(double x) { return _mm512_set1_pd(x); }
KI V vld(const double *p) { return _mm512_loadu_pd(p); }
KI void vst(double *p, V v) { _mm512_storeu_pd(p, v); }
KI V vsqrt(V a) { return _mm512_sqrt_pd(a); }
KI V vmax(V a, V b) { return _mm512_max_pd(a, b); }
KI V vmin(V a, V b) { return _mm512_min_pd(a, b); }
KI V vfma(V a, V b, V c) { return _mm512_fmadd_pd(a, b, c); }
KI V vfms(V a, V b, V c) { return _mm512_fnmadd_pd(a, b, c); }
KI M vgt(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_GT_OQ); }
KI M vge(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_GE_OQ); }
KI M vlt(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_LT_OQ); }
KI M mand(M a, M b) { return (M)(a & b); }
KI int mbits(M a) { return (int)a; }
KI V vsel(M m, V a, V b) { return _mm512_mask_blend_pd(m, b, a); }
KI V vand(M m, V a) { return _mm512_maskz_mov_pd(m, a); }
#define MALL 0xFF
#else
#error "VW must be 4 or 8"
#endif

/* The lanes of a vector as doubles, for the code that works lane by lane (the
 * scalar fallbacks, sums in lane order). A union with the vector, never a
 * bare double[VW] filled by vst: its declared alignment is the vector's, so
 * every aligned access the compiler derives holds wherever the frame lives.
 * The bare arrays crashed the AVX-512 kernel at -O1 under AddressSanitizer
 * with detect_stack_use_after_return (issue 19, a "wild read" in vsum_range):
 * GCC (12.2; the same code in later cfgexpand.cc, expand_stack_vars)
 * gives an ASan-protected local the alignment its frame offset implies,
 * taking the frame's base to be aligned like the frame (64: it holds
 * __m512d), and so turned vst into the aligned vmovapd; but a fake-stack
 * frame is aligned only to the largest alignment the protected locals
 * declare (there 32: double[8] beside __m256d[4]), and the array sat at 32
 * mod 64. */
typedef union {
    V v;
    double d[VW];
} Lanes;

KI V vzero(void) { return vset(0.0); }
KI V vabs(V a) { return vmax(a, -a); }
/* a x b, one component at a time */
KI V crx(V a1, V a2, V b1, V b2) { return vfms(a2, b1, a1 * b2); }  /* a1 b2 - a2 b1 */
KI V dot3(V a0, V a1, V a2, V b0, V b1, V b2) { return vfma(a0, b0, vfma(a1, b1, a2 * b2)); }

/* contact_pow(d, n) for d >= 0 */
KI V vpow(V d, double n) {
    if (n == 1.5) return d * vsqrt(d);
    if (n == 1.0) return d;
    if (n == 2.0) return d * d;
    Lanes t = {.v = d};
    for (int l = 0; l < VW; l++) t.d[l] = pow(t.d[l], n);
    return t.v;
}

/* The impact velocity v_i of contact_vi: the onset velocity where one is
 * remembered, else the closing rate floored at v_min (> 0 either way). */
KI V vimpact(V vo, V ddelta, double v_min) { return vsel(vgt(vo, vzero()), vo, vmax(ddelta, vset(v_min))); }

/* Hunt-Crossley force of the lanes with delta > 0 (contact_force with
 * contact_vi), given 1 / v_i: fn, and the elastic part fe (both 0 where
 * open). The callers share one division among this and their other
 * reciprocals: divisions and square roots share one slow unit, and the arc
 * kernel had 30 divisions and 13 roots per chunk (now 14 and 13). */
KI void vcontact(const ContactLaw *law, V delta, V ddelta, V ivi, V *fn, V *fe) {
    M on = vgt(delta, vzero());
    V d = vmax(delta, vzero());
    V e = vset(law->K) * vpow(d, law->n);
    V f = e * vfma(vset(law->chi), ddelta * ivi, vset(1.0));
    *fn = vand(on, vmax(f, vzero()));
    *fe = vand(on, e);
}

/* --- 1. rotation and world angular rate (cart.c: quat_to_m3, R w) --------- */
static void k_rotation(ChainSimd *S) {
    for (int i = 0; i < S->NP; i += VW) {
        V w = vld(S->Y[3] + i), x = vld(S->Y[4] + i), y = vld(S->Y[5] + i), z = vld(S->Y[6] + i);
        V n2 = vfma(w, w, vfma(x, x, vfma(y, y, z * z)));
        V s = vset(2.0) / n2, one = vset(1.0);
        V R0 = one - s * vfma(y, y, z * z), R1 = s * vfms(w, z, x * y), R2 = s * vfma(x, z, w * y);
        V R3 = s * vfma(x, y, w * z), R4 = one - s * vfma(x, x, z * z), R5 = s * vfms(w, x, y * z);
        V R6 = s * vfms(w, y, x * z), R7 = s * vfma(y, z, w * x), R8 = one - s * vfma(x, x, y * y);
        vst(S->R[0] + i, R0); vst(S->R[1] + i, R1); vst(S->R[2] + i, R2);
        vst(S->R[3] + i, R3); vst(S->R[4] + i, R4); vst(S->R[5] + i, R5);
        vst(S->R[6] + i, R6); vst(S->R[7] + i, R7); vst(S->R[8] + i, R8);
        V w0 = vld(S->Y[10] + i), w1 = vld(S->Y[11] + i), w2 = vld(S->Y[12] + i);
        vst(S->ww[0] + i, dot3(R0, R1, R2, w0, w1, w2));
        vst(S->ww[1] + i, dot3(R3, R4, R5, w0, w1, w2));
        vst(S->ww[2] + i, dot3(R6, R7, R8, w0, w1, w2));
    }
}

/* --- 2. the carts against the track (cart.c, wheels.c, track_local.h) ------- */

/* A projection's frame in base coordinates (E, columns t n b) and the
 * query point's (a, y, z) in it; E = I on the straight code. */
typedef struct {
    V E[9];
    V d1, d2, ds;
} VFrame;

/* The arc code in three forms (ARC below): 1 any plane arc; 2 the chunk's
 * arcs turn about the base's b (uy = 0: curves in the track's plane); 3
 * about its n (uz = 0: vertical curves). Straights (k = 0, u = 0) fit all
 * three. On the last two, four entries of E are 0 and one is 1 by
 * construction, and the products with them are left out: the same bits
 * but for the sign of a zero. The arc kernel is bound by its
 * multiplications (the two FMA pipes): 514 multiplying instructions a
 * chunk in form 1, 420 in forms 2 and 3 (AVX-512, GCC 12). */
KI int e_zero(const int ARC, const int j) {
    return ARC == 2 ? (j == 2 || j == 5 || j == 6 || j == 7) : ARC == 3 ? (j == 1 || j == 3 || j == 5 || j == 7) : 0;
}
KI int e_one(const int ARC, const int j) { return ARC == 2 ? j == 8 : ARC == 3 ? j == 4 : 0; }
/* E_j x, and acc + E_j x (as vfma(E_j, x, acc)) */
KI V emul(const int ARC, const VFrame *f, const int j, V x) {
    return e_zero(ARC, j) ? vzero() : e_one(ARC, j) ? x : (V)(f->E[j] * x);
}
KI V emad(const int ARC, const VFrame *f, const int j, V x, V acc) {
    return e_zero(ARC, j) ? acc : e_one(ARC, j) ? (V)(acc + x) : vfma(f->E[j], x, acc);
}
/* column c of E dotted with (v0, v1, v2), in dot3's order */
KI V ecol(const int ARC, const VFrame *f, const int c, V v0, V v1, V v2) {
    return emad(ARC, f, c, v0, emad(ARC, f, 3 + c, v1, emul(ARC, f, 6 + c, v2)));
}

/* tl_project_planar in terms of the curvature k (k = 0: a straight, where
 * it gives E = I and d = q + ds chat, the straight's result): from the
 * guess, one round of the fixed point ds = atan(k x / (1 - k q.m)) / k, then
 * the frame at that ds. ok loses the lanes that would need atan2 (|z| >=
 * 0.1) or leave the element (the scalar code takes those). With exact
 * (the axle) ds is recomputed from the final (x, rho) by the longer series. */
KI void proj_arc(const ChainSimd *S, int i, V q0, V q1, V q2, V ds, const int exact, const int ARC, VFrame *f,
                 M *ok) {
    V k = vld(S->k + i), uy = vld(S->uy + i), uz = vld(S->uz + i), cm = vld(S->cm + i);
    V c0 = vld(S->ch[0] + i), c1 = vld(S->ch[1] + i), c2 = vld(S->ch[2] + i);
    V one = vset(1.0);
    V qm = ARC == 2 ? (V)(q1 * uz) : ARC == 3 ? (V)(-(q2 * uy)) : vfms(q2, uy, q1 * uz);
    V x = vfma(ds, c0, q0);
    V rk = vfms(k, vfma(ds, cm, qm), one);
    M good = vgt(rk, vzero());
    V xr = x * (one / rk);
    V z = k * xr, z2 = z * z;
    good = mand(good, vlt(z2, vset(1e-2)));
    V T = vfms(z2, vfms(z2, vfms(z2, vfms(z2, vset(1.0 / 9), vset(1.0 / 7)), vset(1.0 / 5)), vset(1.0 / 3)), one);
    ds = xr * T;
    x = vfma(ds, c0, q0);
    rk = vfms(k, vfma(ds, cm, qm), one);
    V kx = k * x;
    /* rr = 1 / sq, ic = 1 / (1 + C) = sq / (sq + rk) and (exact) 1 / rk from
     * one division: 1 / (sq (sq + rk) [rk]); all near 1 where the lane is good */
    V sq = vsqrt(vfma(kx, kx, rk * rk)), sp = sq + rk, P = sq * sp;
    V inv = one / (exact ? (V)(P * rk) : P);
    V rr = exact ? (V)(sp * rk * inv) : (V)(sp * inv);
    V Sn = kx * rr, C = rk * rr, Sik = x * rr;
    V ic = exact ? (V)(sq * sq * rk * inv) : (V)(sq * sq * inv);
    V C1 = Sn * Sn * ic, C1ik = Sn * Sik * ic;
    V Suy = Sn * uy, Suz = Sn * uz, C1uy = C1 * uy, C1uz = C1 * uz, C1yz = C1uy * uz;
    f->E[0] = C;    f->E[1] = -Suz;               f->E[2] = Suy;
    f->E[3] = Suz;  f->E[4] = vfms(C1uz, uz, one); f->E[5] = C1yz;
    f->E[6] = -Suy; f->E[7] = C1yz;               f->E[8] = vfms(C1uy, uy, one);
    V r0 = x - Sik;
    V r1 = ARC == 3 ? vfma(ds, c1, q1) : vfms(C1ik, uz, vfma(ds, c1, q1));
    V r2 = ARC == 2 ? vfma(ds, c2, q2) : vfma(C1ik, uy, vfma(ds, c2, q2));
    f->d1 = ecol(ARC, f, 1, r0, r1, r2);
    f->d2 = ecol(ARC, f, 2, r0, r1, r2);
    if (exact) {
        V xr1 = x * (P * inv);
        z = k * xr1;
        z2 = z * z;
        good = mand(good, vlt(z2, vset(1e-2)));
        V Tf = vset(1.0 / 15);
        Tf = vfms(z2, Tf, vset(1.0 / 13));
        Tf = vfms(z2, Tf, vset(1.0 / 11));
        Tf = vfms(z2, Tf, vset(1.0 / 9));
        Tf = vfms(z2, Tf, vset(1.0 / 7));
        Tf = vfms(z2, Tf, vset(1.0 / 5));
        Tf = vfms(z2, Tf, vset(1.0 / 3));
        Tf = vfms(z2, Tf, one);
        ds = xr1 * Tf;
    }
    *ok = mand(*ok, mand(good, mand(vge(ds, vld(S->lo + i)), vlt(ds, vld(S->hi + i)))));
    f->ds = ds;
}

/* tl_project_straight: a = q_x - ds (1 - chat_x) = 0, E = I. */
KI void proj_straight(const ChainSimd *S, int i, V q0, V q1, V q2, VFrame *f, M *ok) {
    V ds = q0 * vld(S->ich0 + i);
    *ok = mand(*ok, mand(vge(ds, vld(S->lo + i)), vlt(ds, vld(S->hi + i))));
    f->d1 = vfma(ds, vld(S->ch[1] + i), q1);
    f->d2 = vfma(ds, vld(S->ch[2] + i), q2);
    f->ds = ds;
}

typedef struct {
    V F[3], T[3];                     /* base coordinates */
    V pd, pr;
} VSum;

/* The bump and an out-of-round wheel (wheels.c surface_effects), lane by
 * lane: they are off by default and cost a sine where on. */
static void surface_lanes(Chain *c, int i0, int k, const double *ds, const double *d1, const double *d2,
                          const double *vt, double *dh, double *slope) {  /* each [VW] */
    const Effects *fx = &c->m.fx;
    ChainSimd *S = c->simd;
    for (int l = 0; l < VW; l++) {
        int i = i0 + l;
        dh[l] = slope[l] = 0.0;
        if (i >= S->N) continue;
        if (fx->bump_on) {
            double L = c->m.track.length, s = S->bs[i] + ds[l], hs;
            if (s >= L) s -= L;
            else if (s < 0.0) s += L;
            double h = effects_bump(fx, s, L, &hs);
            if (hs != 0.0 || h != 0.0) {
                /* w = k u: (0, k uy, k uz) on the arc code's elements */
                double w1 = S->k[i] * S->uy[i], w2 = S->k[i] * S->uz[i];
                dh[l] += h;
                slope[l] += hs / (1.0 - (d1[l] * w2 - d2[l] * w1));
            }
        }
        if (fx->oor_on && i == fx->oor_cart) {
            int side = k == W_DL ? 0 : 1;
            double drdx;
            dh[l] += effects_oor(fx, side, c->sc.oor_x[side], &drdx);
            slope[l] += drdx;
            c->sc.oor_rate[side] = vt[l];
        }
    }
}

/* Wheel k of the chunk at i (wheels.c one_wheel), ARC: the arc code (else
 * the straight code), SURF: the bump or an out-of-round wheel is on. */
KI void v_wheel(Chain *c, int i, const V *Mx, const V *Lq, const V *Lv, const V *om, const V *x0, V ds_axle,
                const int k, const int ARC, const int SURF, VSum *acc, M *ok) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    const int drive = (k == W_DL || k == W_DR);
    const double side = (k == W_SL || k == W_DL) ? 1.0 : -1.0;
    const double yb = side * (drive ? g->y_drive : g->y_steer), r = drive ? g->r_drive : g->r_steer;
    const double h = side * g->guide_half;
    V rc[3], q[3], v[3];
    for (int j = 0; j < 3; j++) rc[j] = vfma(Mx[3 * j + 1], vset(yb), x0[j]);
    for (int j = 0; j < 3; j++) q[j] = Lq[j] + rc[j];
    v[0] = Lv[0] + crx(om[1], om[2], rc[1], rc[2]);
    v[1] = Lv[1] + crx(om[2], om[0], rc[2], rc[0]);
    v[2] = Lv[2] + crx(om[0], om[1], rc[0], rc[1]);
    VFrame f;
    V vf0, vfn;  /* velocity along t, and along the normal (b for a driving wheel, n for a guide) */
    if (ARC) {
        proj_arc(S, i, q[0], q[1], q[2], ds_axle, 0, ARC, &f, ok);
        vf0 = ecol(ARC, &f, 0, v[0], v[1], v[2]);
        vfn = ecol(ARC, &f, drive ? 2 : 1, v[0], v[1], v[2]);
    } else {
        proj_straight(S, i, q[0], q[1], q[2], &f, ok);
        vf0 = v[0];
        vfn = drive ? v[2] : v[1];
    }
    /* the normal is b or n exactly (no twist on these elements) */
    V delta, ddelta;
    if (drive) {
        delta = vset(r) - f.d2;
        ddelta = -vfn;
    } else {  /* side is +-1: signs flipped, not multiplied (the same bits) */
        delta = side > 0 ? (V)(vset(r) + (f.d1 - vset(h))) : (V)(vset(r) - (f.d1 - vset(h)));
        ddelta = side > 0 ? vfn : (V)(-vfn);
    }
    V vt = vf0;
    vst(S->ws[k] + i, vt * vset(drive ? S->ir_drive : S->ir_steer));
    V slope = vzero();
    if (drive && SURF) {
        Lanes a_ds = {.v = f.ds}, a_d1 = {.v = f.d1}, a_d2 = {.v = f.d2}, a_vt = {.v = vt}, a_dh, a_sl;
        surface_lanes(c, i, k, a_ds.d, a_d1.d, a_d2.d, a_vt.d, a_dh.d, a_sl.d);
        slope = a_sl.v;
        delta = delta + a_dh.v;
        ddelta = vfma(slope, vt, ddelta);
    }
    /* 1 / v_i and 1 / sqrt(vt^2 + 1e-4) from one division */
    V vi = vimpact(vld(S->voW[k] + i), ddelta, m->v_min), sd = vsqrt(vfma(vt, vt, vset(1e-4)));
    V inv = vset(1.0) / (vi * sd);
    V fn, fe;
    vcontact(&m->law[drive ? CC_RW : CC_SW], delta, ddelta, sd * inv, &fn, &fe);
    acc->pd = vfma(fn - fe, ddelta, acc->pd);
    V sg = vt * (vi * inv), froll = vset(m->mu_roll) * fn;
    V fsg = froll * sg;
    acc->pr = vfma(fsg, vt, acc->pr);
    /* ff = dir fn - froll sg t; dir = b (driving) or -side n (guide); fv = E ff, db = E dir */
    /* arm = rc - r db: a sign flip of db taken into the fused operation, and
     * the straight code's zero components left out (the same bits) */
    V fv[3], arm[3];
    V fx = -fsg, fd = drive ? fn : (side > 0 ? (V)(-fn) : fn);
    if (ARC) {
        const int cd = drive ? 2 : 1;
        for (int j = 0; j < 3; j++) {
            const int jd = 3 * j + cd;
            V ed = f.E[jd];
            fv[j] = emad(ARC, &f, 3 * j, fx, emul(ARC, &f, jd, fd));
            if (e_zero(ARC, jd))
                arm[j] = rc[j];
            else if (e_one(ARC, jd))
                arm[j] = (!drive && side > 0) ? (V)(rc[j] + vset(r)) : (V)(rc[j] - vset(r));
            else
                arm[j] = (!drive && side > 0) ? vfma(vset(r), ed, rc[j]) : vfms(vset(r), ed, rc[j]);
        }
    } else {
        fv[0] = fx;
        fv[1] = drive ? vzero() : fd;
        fv[2] = drive ? fd : vzero();
        arm[0] = rc[0];
        arm[1] = drive ? rc[1] : (V)(rc[1] + vset(side * r));
        arm[2] = drive ? (V)(rc[2] - vset(r)) : rc[2];
    }
    for (int j = 0; j < 3; j++) acc->F[j] = acc->F[j] + fv[j];
    acc->T[0] = acc->T[0] + crx(arm[1], arm[2], fv[1], fv[2]);
    acc->T[1] = acc->T[1] + crx(arm[2], arm[0], fv[2], fv[0]);
    acc->T[2] = acc->T[2] + crx(arm[0], arm[1], fv[0], fv[1]);
    if (drive && SURF) {
        /* the slope's tangential force through the wheel centre */
        V ft = -(fn * slope), tv[3];
        for (int j = 0; j < 3; j++) tv[j] = ARC ? emul(ARC, &f, 3 * j, ft) : (j == 0 ? ft : vzero());
        for (int j = 0; j < 3; j++) acc->F[j] = acc->F[j] + tv[j];
        acc->T[0] = acc->T[0] + crx(rc[1], rc[2], tv[1], tv[2]);
        acc->T[1] = acc->T[1] + crx(rc[2], rc[0], tv[2], tv[0]);
        acc->T[2] = acc->T[2] + crx(rc[0], rc[1], tv[0], tv[1]);
    }
    vst(S->wd[k] + i, delta);
    vst(S->wdd[k] + i, ddelta);
    vst(S->wf[k] + i, fn);
}

/* One chunk: kinematics in the base (cart_kinematics), the four wheels
 * (wheel_forces), the running resistance (effects_resistance). Returns the
 * lanes whose projections the scalar code must redo. */
KI int k_chunk(Chain *c, int i, const int ARC, const int SURF) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    V R[9], bR[9], Mx[9];
    for (int j = 0; j < 9; j++) {
        R[j] = vld(S->R[j] + i);
        bR[j] = vld(S->bR[j] + i);
    }
    /* M = bR^T R */
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            Mx[3 * a + b] = dot3(bR[a], bR[3 + a], bR[6 + a], R[b], R[3 + b], R[6 + b]);
    V r[3], vw[3], w[3], Lq[3], Lv[3], om[3];
    for (int j = 0; j < 3; j++) {
        r[j] = vld(S->Y[j] + i) - vld(S->bc[j] + i);
        vw[j] = vld(S->Y[7 + j] + i);
        w[j] = vld(S->Y[10 + j] + i);
    }
    for (int j = 0; j < 3; j++) {
        Lq[j] = dot3(bR[j], bR[3 + j], bR[6 + j], r[0], r[1], r[2]);
        Lv[j] = dot3(bR[j], bR[3 + j], bR[6 + j], vw[0], vw[1], vw[2]);
        om[j] = dot3(Mx[3 * j], Mx[3 * j + 1], Mx[3 * j + 2], w[0], w[1], w[2]);
    }
    /* the axle and the wheel centres' body x and z parts */
    V xa = vset(g->x_axle), za = vset(g->z_axle), zs = vset(g->z_steer);
    V ra[3], xs[3], qa[3], va[3];
    for (int j = 0; j < 3; j++) {
        ra[j] = vfma(Mx[3 * j], xa, Mx[3 * j + 2] * za);
        xs[j] = vfma(Mx[3 * j], xa, Mx[3 * j + 2] * zs);
        qa[j] = Lq[j] + ra[j];
    }
    va[0] = Lv[0] + crx(om[1], om[2], ra[1], ra[2]);
    va[1] = Lv[1] + crx(om[2], om[0], ra[2], ra[0]);
    va[2] = Lv[2] + crx(om[0], om[1], ra[0], ra[1]);
    M ok = vgt(vset(1.0), vzero());
    VFrame af;
    V vt;
    if (ARC) {
        proj_arc(S, i, qa[0], qa[1], qa[2], vzero(), 1, ARC, &af, &ok);
        vt = ecol(ARC, &af, 0, va[0], va[1], va[2]);  /* va . tl, tl = E's column t */
    } else {
        proj_straight(S, i, qa[0], qa[1], qa[2], &af, &ok);
        vt = va[0];
    }
    V s = vld(S->bs + i) + af.ds, L = vset(m->track.length);
    s = vsel(vge(s, L), s - L, vsel(vlt(s, vzero()), s + L, s));
    vst(S->s + i, s);
    vst(S->vt + i, vt);
    V t[3];
    for (int j = 0; j < 3; j++) {
        t[j] = ARC ? emad(ARC, &af, 0, bR[3 * j], emad(ARC, &af, 3, bR[3 * j + 1], emul(ARC, &af, 6, bR[3 * j + 2])))
                   : bR[3 * j];  /* bR's row j . tl */
        vst(S->t[j] + i, t[j]);
    }
    VSum acc;
    for (int j = 0; j < 3; j++) acc.F[j] = acc.T[j] = vzero();
    acc.pd = acc.pr = vzero();
    v_wheel(c, i, Mx, Lq, Lv, om, xs, af.ds, W_SL, ARC, SURF, &acc, &ok);
    v_wheel(c, i, Mx, Lq, Lv, om, xs, af.ds, W_SR, ARC, SURF, &acc, &ok);
    v_wheel(c, i, Mx, Lq, Lv, om, ra, af.ds, W_DL, ARC, SURF, &acc, &ok);
    v_wheel(c, i, Mx, Lq, Lv, om, ra, af.ds, W_DR, ARC, SURF, &acc, &ok);
    /* world: F = weight + bR F_base, T = bR T_base */
    V F[3], T[3];
    for (int j = 0; j < 3; j++) {
        F[j] = dot3(bR[3 * j], bR[3 * j + 1], bR[3 * j + 2], acc.F[0], acc.F[1], acc.F[2]);
        T[j] = dot3(bR[3 * j], bR[3 * j + 1], bR[3 * j + 2], acc.T[0], acc.T[1], acc.T[2]);
    }
    F[2] = F[2] - vld(S->mg + i);
    if (m->fx.resist_on) {
        /* effects_resistance: -(c1 v + c2 v |v|) along t at the axle */
        V Fr = -(vset(m->fx.c1) * vt + vset(m->fx.c2) * vt * vabs(vt)), fv[3], raw[3];
        for (int j = 0; j < 3; j++) {
            fv[j] = t[j] * Fr;
            raw[j] = vfma(R[3 * j], xa, R[3 * j + 2] * za);
            F[j] = F[j] + fv[j];
        }
        T[0] = T[0] + crx(raw[1], raw[2], fv[1], fv[2]);
        T[1] = T[1] + crx(raw[2], raw[0], fv[2], fv[0]);
        T[2] = T[2] + crx(raw[0], raw[1], fv[0], fv[1]);
        acc.pr = vfms(Fr, vt, acc.pr);
    }
    for (int j = 0; j < 3; j++) {
        vst(S->Fw[j] + i, F[j]);
        vst(S->Tw[j] + i, T[j]);
    }
    vst(S->pdw + i, acc.pd);
    vst(S->prw + i, acc.pr);
    return ~mbits(ok) & MALL;
}

static void k_wheels_straight(Chain *c, int i, int *bad) { *bad = k_chunk(c, i, 0, 0); }
static void k_wheels_arc(Chain *c, int i, int *bad) { *bad = k_chunk(c, i, 1, 0); }
static void k_wheels_arc_b(Chain *c, int i, int *bad) { *bad = k_chunk(c, i, 2, 0); }
static void k_wheels_arc_n(Chain *c, int i, int *bad) { *bad = k_chunk(c, i, 3, 0); }
static void k_wheels_straight_surf(Chain *c, int i, int *bad) { *bad = k_chunk(c, i, 0, 1); }
static void k_wheels_arc_surf(Chain *c, int i, int *bad) { *bad = k_chunk(c, i, 1, 1); }

/* --- 4. the joints (joints.c), joint j at index j + 1 ----------------------- */
static void k_joints(Chain *c) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    const V hp = vset(0.5 * g->pitch), zj = vset(g->z_joint), gap = vset(m->fx.gap), zero = vzero();
    for (int j = 0; j < S->NW; j += VW) {
        int b = j + 1;
        V a[3], aB[3], c2A[3], c2B[3], wA[3], wB[3], rF[3], rR[3], pF[3], pR[3], vF[3], vR[3];
        for (int k = 0; k < 3; k++) {
            a[k] = vld(S->R[3 * k] + j);
            c2A[k] = vld(S->R[3 * k + 2] + j);
            aB[k] = vld(S->R[3 * k] + b);
            c2B[k] = vld(S->R[3 * k + 2] + b);
            wA[k] = vld(S->ww[k] + j);
            wB[k] = vld(S->ww[k] + b);
        }
        for (int k = 0; k < 3; k++) {
            rF[k] = vfma(a[k], hp, c2A[k] * zj);
            rR[k] = vfms(aB[k], hp, c2B[k] * zj);
            pF[k] = vld(S->Y[k] + j) + rF[k];
            pR[k] = vld(S->Y[k] + b) + rR[k];
        }
        vF[0] = vld(S->Y[7] + j) + crx(wA[1], wA[2], rF[1], rF[2]);
        vF[1] = vld(S->Y[8] + j) + crx(wA[2], wA[0], rF[2], rF[0]);
        vF[2] = vld(S->Y[9] + j) + crx(wA[0], wA[1], rF[0], rF[1]);
        vR[0] = vld(S->Y[7] + b) + crx(wB[1], wB[2], rR[1], rR[2]);
        vR[1] = vld(S->Y[8] + b) + crx(wB[2], wB[0], rR[2], rR[0]);
        vR[2] = vld(S->Y[9] + b) + crx(wB[0], wB[1], rR[0], rR[1]);
        V D[3], Dd[3], adot[3];
        for (int k = 0; k < 3; k++) {
            D[k] = pR[k] - pF[k];
            Dd[k] = vR[k] - vF[k];
        }
        adot[0] = crx(wA[1], wA[2], a[1], a[2]);
        adot[1] = crx(wA[2], wA[0], a[2], a[0]);
        adot[2] = crx(wA[0], wA[1], a[0], a[1]);
        V Da = dot3(D[0], D[1], D[2], a[0], a[1], a[2]);
        V Dadot = dot3(Dd[0], Dd[1], Dd[2], a[0], a[1], a[2]) + dot3(D[0], D[1], D[2], adot[0], adot[1], adot[2]);
        V Dr[3];
        for (int k = 0; k < 3; k++) Dr[k] = vfms(Da, a[k], D[k]);
        V rho = vsqrt(dot3(Dr[0], Dr[1], Dr[2], Dr[0], Dr[1], Dr[2]));
        V sgn = vsel(vge(Da, zero), vset(1.0), vset(-1.0));
        /* axial */
        V da = vabs(Da) - gap, dda = sgn * Dadot, fa, fea;
        V via = vimpact(vld(S->voJ[0] + j), dda, m->v_min);
        /* radial */
        M valid = vgt(rho, vset(1e-15));
        V rv = vsel(valid, rho, vset(1.0));
        /* 1 / rho first (the radial closing rate needs it), then both 1 / v_i
         * from one more division */
        V irho = vset(1.0) / rv, u[3];
        for (int k = 0; k < 3; k++) u[k] = vand(valid, Dr[k] * irho);
        V ddr = vfms(Da, dot3(u[0], u[1], u[2], adot[0], adot[1], adot[2]), dot3(u[0], u[1], u[2], Dd[0], Dd[1], Dd[2]));
        V vir = vimpact(vld(S->voJ[1] + j), ddr, m->v_min);
        V inv = vset(1.0) / (via * vir);
        vcontact(&m->law[CC_JA], da, dda, vir * inv, &fa, &fea);
        V pd = (fa - fea) * dda;
        V dr = rho - gap, fr, fer;
        vcontact(&m->law[CC_JR], vand(valid, dr), ddr, via * inv, &fr, &fer);
        pd = vfma(fr - fer, ddr, pd);
        /* force on A at pF, the opposite on B at pR */
        V f[3], sfa = sgn * fa;
        for (int k = 0; k < 3; k++) f[k] = vfma(a[k], sfa, fr * u[k]);
        V TA[3], TB[3], axu[3], tq = vfms(sfa, rho, fr * Da);
        axu[0] = crx(a[1], a[2], u[1], u[2]);
        axu[1] = crx(a[2], a[0], u[2], u[0]);
        axu[2] = crx(a[0], a[1], u[0], u[1]);
        TA[0] = vfma(tq, axu[0], crx(rF[1], rF[2], f[1], f[2]));
        TA[1] = vfma(tq, axu[1], crx(rF[2], rF[0], f[2], f[0]));
        TA[2] = vfma(tq, axu[2], crx(rF[0], rF[1], f[0], f[1]));
        TB[0] = -crx(rR[1], rR[2], f[1], f[2]);
        TB[1] = -crx(rR[2], rR[0], f[2], f[0]);
        TB[2] = -crx(rR[0], rR[1], f[0], f[1]);
        for (int k = 0; k < 3; k++) {
            vst(S->jf[k] + b, f[k]);
            vst(S->jTA[k] + b, TA[k]);
            vst(S->jTB[k] + b, TB[k]);
        }
        vst(S->jd[0] + b, da); vst(S->jdd[0] + b, dda); vst(S->jfn[0] + b, fa);
        vst(S->jd[1] + b, dr); vst(S->jdd[1] + b, ddr); vst(S->jfn[1] + b, fr);
        vst(S->pdj + b, pd);
        vst(S->jDadot + b, Dadot);
    }
    /* joint N-1 also at index 0: the rear joint of cart 0 */
    int N = S->N;
    for (int k = 0; k < 3; k++) {
        S->jf[k][0] = S->jf[k][N];
        S->jTA[k][0] = S->jTA[k][N];
        S->jTB[k][0] = S->jTB[k][N];
    }
}

/* 4 x 4 transposes between rows (a cart's 13 doubles) and columns (one
 * quantity of 4 carts), in 256-bit registers on both paths */
KI void tr4(__m256d a0, __m256d a1, __m256d a2, __m256d a3, __m256d *c) {
    __m256d t0 = _mm256_unpacklo_pd(a0, a1), t1 = _mm256_unpackhi_pd(a0, a1);
    __m256d t2 = _mm256_unpacklo_pd(a2, a3), t3 = _mm256_unpackhi_pd(a2, a3);
    c[0] = _mm256_permute2f128_pd(t0, t2, 0x20);
    c[1] = _mm256_permute2f128_pd(t1, t3, 0x20);
    c[2] = _mm256_permute2f128_pd(t0, t2, 0x31);
    c[3] = _mm256_permute2f128_pd(t1, t3, 0x31);
}

/* y (13 per cart) into Y by quantity; the slots after the last cart copy cart 0 */
static void k_gather(ChainSimd *S, const double *y) {
    int N = S->N, i = 0;
    for (; i + 4 <= N; i += 4) {
        const double *r0 = y + CART_NY * i, *r1 = r0 + CART_NY, *r2 = r1 + CART_NY, *r3 = r2 + CART_NY;
        for (int c0 = 0; c0 < 12; c0 += 4) {
            __m256d col[4];
            tr4(_mm256_loadu_pd(r0 + c0), _mm256_loadu_pd(r1 + c0), _mm256_loadu_pd(r2 + c0),
                _mm256_loadu_pd(r3 + c0), col);
            for (int k = 0; k < 4; k++) _mm256_storeu_pd(S->Y[c0 + k] + i, col[k]);
        }
        _mm256_storeu_pd(S->Y[12] + i, _mm256_set_pd(r3[12], r2[12], r1[12], r0[12]));
    }
    for (; i < N; i++)
        for (int k = 0; k < CART_NY; k++) S->Y[k][i] = y[CART_NY * i + k];
    /* quantity by quantity, [N, NP) by two overlapping vector stores (NP - N
     * is from W to 2W) */
    for (int k = 0; k < CART_NY; k++) {
        V v = vset(y[k]);
        vst(S->Y[k] + N, v);
        vst(S->Y[k] + S->NP - VW, v);
    }
}

/* columns d[13] of 4 carts (n of them real) into their rows of dy */
KI void scatter4(double *dy, const __m256d *d, int n) {
    if (n == 4) {
        double *r[4] = {dy, dy + CART_NY, dy + 2 * CART_NY, dy + 3 * CART_NY};
        for (int c0 = 0; c0 < 12; c0 += 4) {
            __m256d row[4];
            tr4(d[c0], d[c0 + 1], d[c0 + 2], d[c0 + 3], row);
            for (int l = 0; l < 4; l++) _mm256_storeu_pd(r[l] + c0, row[l]);
        }
        __m128d lo = _mm256_castpd256_pd128(d[12]), hi = _mm256_extractf128_pd(d[12], 1);
        _mm_storel_pd(r[0] + 12, lo);
        _mm_storeh_pd(r[1] + 12, lo);
        _mm_storel_pd(r[2] + 12, hi);
        _mm_storeh_pd(r[3] + 12, hi);
        return;
    }
    union {
        __m256d v;
        double d[4];
    } tmp[CART_NY];  /* as Lanes: the alignment the vector needs, declared */
    for (int k = 0; k < CART_NY; k++) tmp[k].v = d[k];
    for (int l = 0; l < n; l++)
        for (int k = 0; k < CART_NY; k++) dy[CART_NY * l + k] = tmp[k].d[l];
}

#if VW == 8
/* Half hf (carts 4 hf .. 4 hf + 3) of a full chunk of 8 into its rows of dy:
 * scatter4 on the 256-bit halves, taken straight from the registers. */
KI void scatter8_half(double *dy, const V *d, const int hf) {
    double *r0 = dy + CART_NY * 4 * hf;
    for (int c0 = 0; c0 < 12; c0 += 4) {
        __m256d row[4];
        if (hf)
            tr4(_mm512_extractf64x4_pd(d[c0], 1), _mm512_extractf64x4_pd(d[c0 + 1], 1),
                _mm512_extractf64x4_pd(d[c0 + 2], 1), _mm512_extractf64x4_pd(d[c0 + 3], 1), row);
        else
            tr4(_mm512_castpd512_pd256(d[c0]), _mm512_castpd512_pd256(d[c0 + 1]), _mm512_castpd512_pd256(d[c0 + 2]),
                _mm512_castpd512_pd256(d[c0 + 3]), row);
        _mm256_storeu_pd(r0 + c0, row[0]);
        _mm256_storeu_pd(r0 + CART_NY + c0, row[1]);
        _mm256_storeu_pd(r0 + 2 * CART_NY + c0, row[2]);
        _mm256_storeu_pd(r0 + 3 * CART_NY + c0, row[3]);
    }
    __m256d q = hf ? _mm512_extractf64x4_pd(d[12], 1) : _mm512_castpd512_pd256(d[12]);
    __m128d lo = _mm256_castpd256_pd128(q), hi = _mm256_extractf128_pd(q, 1);
    _mm_storel_pd(r0 + 12, lo);
    _mm_storeh_pd(r0 + CART_NY + 12, lo);
    _mm_storel_pd(r0 + 2 * CART_NY + 12, hi);
    _mm_storeh_pd(r0 + 3 * CART_NY + 12, hi);
}
#endif

/* --- 6. forces summed, Newton-Euler (cart.c cart_derivatives), into dy ----- */
/* The motors (drive.c drive_forces) with the candidates of chain_simd.c:
 * thrust F_cmd times the covered share of each candidate motor, along t at
 * the motor point; lanes outside their window take the scalar walk. */
KI void v_drive(Chain *c, int i, double F_cmd, const V *Rm, V *F, V *T, V *Ftot, V *Ptot) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    V sp = vld(S->s + i) - vset(m->g.x_axle - m->g.x_motor), half = vset(0.5 * m->g.plate_length);
    V a = sp - half, b = sp + half, frac = vzero();
    for (int k = 0; k < SIMD_NMOT; k++) {
        V ov = vmin(b, vld(S->ms1[k] + i)) - vmax(a, vld(S->ms0[k] + i));
        frac = vfma(vmax(ov, vzero()), vld(S->mil[k] + i), frac);
    }
    V Fm = vset(F_cmd) * frac;
    M inw = mand(vge(sp, vld(S->mlo + i)), vge(vld(S->mhi + i), sp));
    int bad = ~mbits(inw) & MALL;
    uint64_t full = 0;  /* the chunk's flags at once (mfull has NP >= i + VW bytes) */
    memcpy(&full, S->mfull + i, VW);
    for (int l = 0; full && l < VW && l < S->N - i; l++)
        if (S->mfull[i + l]) bad |= 1 << l;
    bad &= (S->N - i >= VW) ? MALL : (1 << (S->N - i)) - 1;
    if (bad) {
        Lanes t = {.v = Fm};
        for (int l = 0; l < VW; l++)
            if (bad >> l & 1) simd_drive_lane(c, i + l, F_cmd, &t.d[l]);
        Fm = t.v;
    }
    if (S->N - i < VW) {  /* the padding lanes get no thrust */
        Lanes t = {.v = Fm};
        for (int l = S->N - i; l < VW; l++) t.d[l] = 0.0;
        Fm = t.v;
    }
    V xm = vset(m->g.x_motor), zm = vset(m->g.z_motor), rm[3], w[3], fv[3], v[3];
    for (int k = 0; k < 3; k++) {
        rm[k] = vfma(Rm[3 * k], xm, Rm[3 * k + 2] * zm);
        w[k] = vld(S->ww[k] + i);
        fv[k] = vld(S->t[k] + i) * Fm;
        F[k] = F[k] + fv[k];
    }
    v[0] = vld(S->Y[7] + i) + crx(w[1], w[2], rm[1], rm[2]);
    v[1] = vld(S->Y[8] + i) + crx(w[2], w[0], rm[2], rm[0]);
    v[2] = vld(S->Y[9] + i) + crx(w[0], w[1], rm[0], rm[1]);
    T[0] = T[0] + crx(rm[1], rm[2], fv[1], fv[2]);
    T[1] = T[1] + crx(rm[2], rm[0], fv[2], fv[0]);
    T[2] = T[2] + crx(rm[0], rm[1], fv[0], fv[1]);
    *Ftot = *Ftot + Fm;
    *Ptot = *Ptot + dot3(fv[0], fv[1], fv[2], v[0], v[1], v[2]);
}

static void k_newton_euler(Chain *c, double *dy, double F_cmd, int vdrive) {
    ChainSimd *S = c->simd;
    V Ftot = vzero(), Ptot = vzero(), Pd = vzero(), Pr = vzero();
    for (int i = 0; i < S->NW; i += VW) {
        {  /* the damping and rolling powers summed here, lane by lane (the padding left out) */
            V pd = vld(S->pdw + i) + vld(S->pdj + i + 1), pr = vld(S->prw + i);
            if (S->N - i < VW) {
                Lanes a = {.v = pd}, b = {.v = pr};
                for (int l = S->N - i; l < VW; l++) a.d[l] = b.d[l] = 0.0;
                pd = a.v;
                pr = b.v;
            }
            Pd = Pd + pd;
            Pr = Pr + pr;
        }
        V F[3], T[3], Rm[9];
        for (int k = 0; k < 3; k++) {
            F[k] = vld(S->Fw[k] + i) + vld(S->jf[k] + i + 1) - vld(S->jf[k] + i);
            T[k] = vld(S->Tw[k] + i) + vld(S->jTA[k] + i + 1) + vld(S->jTB[k] + i);
        }
        for (int k = 0; k < 9; k++) Rm[k] = vld(S->R[k] + i);
        if (vdrive) v_drive(c, i, F_cmd, Rm, F, T, &Ftot, &Ptot);
        V q0 = vld(S->Y[3] + i), q1 = vld(S->Y[4] + i), q2 = vld(S->Y[5] + i), q3 = vld(S->Y[6] + i);
        V w0 = vld(S->Y[10] + i), w1 = vld(S->Y[11] + i), w2 = vld(S->Y[12] + i);
        V hf = vset(0.5), im = vld(S->im + i);
        V d[CART_NY];
        d[0] = vld(S->Y[7] + i); d[1] = vld(S->Y[8] + i); d[2] = vld(S->Y[9] + i);
        d[3] = -hf * dot3(q1, q2, q3, w0, w1, w2);
        d[4] = hf * vfms(q3, w1, vfma(q0, w0, q2 * w2));
        d[5] = hf * vfms(q1, w2, vfma(q0, w1, q3 * w0));
        d[6] = hf * vfms(q2, w0, vfma(q0, w2, q1 * w1));
        d[7] = F[0] * im; d[8] = F[1] * im; d[9] = F[2] * im;
        V tb[3];
        for (int k = 0; k < 3; k++) tb[k] = dot3(Rm[k], Rm[3 + k], Rm[6 + k], T[0], T[1], T[2]);
        V i0 = vld(S->iI[0] + i), i1 = vld(S->iI[1] + i), i2 = vld(S->iI[2] + i);
        /* Iw = I w (I = 1 / iI); gyro = w x Iw */
        V Iw0 = w0 * vld(S->In[0] + i), Iw1 = w1 * vld(S->In[1] + i), Iw2 = w2 * vld(S->In[2] + i);
        d[10] = (tb[0] - crx(w1, w2, Iw1, Iw2)) * i0;
        d[11] = (tb[1] - crx(w2, w0, Iw2, Iw0)) * i1;
        d[12] = (tb[2] - crx(w0, w1, Iw0, Iw1)) * i2;
        int n = S->N - i < VW ? S->N - i : VW;
#if VW == 4
        scatter4(dy + CART_NY * i, d, n);
#else
        if (n == VW) {
            scatter8_half(dy + CART_NY * i, d, 0);
            scatter8_half(dy + CART_NY * i, d, 1);
            continue;
        }
        __m256d h[CART_NY];
        for (int k = 0; k < CART_NY; k++) h[k] = _mm512_castpd512_pd256(d[k]);
        scatter4(dy + CART_NY * i, h, n < 4 ? n : 4);
        if (n > 4) {
            for (int k = 0; k < CART_NY; k++) h[k] = _mm512_extractf64x4_pd(d[k], 1);
            scatter4(dy + CART_NY * (i + 4), h, n - 4);
        }
#endif
    }
    if (vdrive) {
        Lanes a = {.v = Ftot}, b = {.v = Ptot};
        double ft = 0.0, pt = 0.0;
        for (int l = 0; l < VW; l++) {
            ft += a.d[l];
            pt += b.d[l];
        }
        c->sc.F_total = ft;
        c->sc.P_total = pt;
    }
    Lanes a = {.v = Pd}, b = {.v = Pr};
    double pd = 0.0, pr = 0.0;
    for (int l = 0; l < VW; l++) {
        pd += a.d[l];
        pr += b.d[l];
    }
    S->p_damp = pd;
    S->p_roll = pr;
}

static double vsum_range(const double *a, int n) {
    V acc = vzero();
    int i = 0;
    for (; i + VW <= n; i += VW) acc = acc + vld(a + i);
    Lanes t = {.v = acc};
    double s = 0.0;
    for (int l = 0; l < VW; l++) s += t.d[l];
    for (; i < n; i++) s += a[i];
    return s;
}

void SIMD_ENTRY(Chain *c, const double *y, double *dy) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    simd_refresh(c, y);
    k_gather(S, y);
    k_rotation(S);
    int nfix = S->n_fix_twisted, surf = m->fx.surface_on;
    for (int i = 0; i < S->NW; i += VW) {
        int bad;
        int kind = S->chunk[i / VW];
        if (kind) {
            if (surf) k_wheels_arc_surf(c, i, &bad);
            else if (kind == 2) k_wheels_arc_b(c, i, &bad);
            else if (kind == 3) k_wheels_arc_n(c, i, &bad);
            else k_wheels_arc(c, i, &bad);
        } else {
            if (surf) k_wheels_straight_surf(c, i, &bad);
            else k_wheels_straight(c, i, &bad);
        }
        while (bad) {
            int l = __builtin_ctz((unsigned)bad);
            bad &= bad - 1;
            int ic = i + l;
            if (ic < S->N && S->kind[ic] != TL_TWISTED) S->fix[nfix++] = ic;
        }
    }
    for (int f = 0; f < nfix; f++) simd_fix_cart(c, y, S->fix[f]);
    double sum_vt = vsum_range(S->vt, S->N), zdot;
    double F_cmd = drive_command(m, &c->st, sum_vt / S->N, y[CART_NY * S->N + G_INT], &zdot);
    k_joints(c);
    /* the motors: in the last kernel, or by the scalar walk where the ripple or the external drive is on */
    int vdrive = m->track.n_motors > 0 && F_cmd != 0.0 && !m->fx.ripple_on && m->drive_mode == DRIVE_INTERNAL;
    if (!vdrive) simd_drive(c, F_cmd);
    k_newton_euler(c, dy, F_cmd, vdrive);
    simd_finish(c, y, dy, F_cmd, zdot, sum_vt);
}
