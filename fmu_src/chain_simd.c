/* The vector paths' common part (chain_simd.h): the choice of path, the
 * workspace, the bases and the contact memory by quantity, the carts the
 * scalar code redoes, the motors, and the scalar scratch on demand. Plain
 * C: compiled for the baseline instruction set like the rest of the core.
 *
 * The path is chosen per instance at its creation from cpuid (no cached
 * global: two instances never share anything), and can be forced
 * (solver.vector_path) for tests. */
#include <stdint.h>
#include <string.h>

#include "chain_simd.h"

#if LSS_HAVE_SIMD
#include <cpuid.h>

static uint64_t xgetbv0(void) {
    uint32_t a, d;
    __asm__ volatile("xgetbv" : "=a"(a), "=d"(d) : "c"(0));
    return ((uint64_t)d << 32) | a;
}

int lss_simd_best_path(void) {
    unsigned a, b, c, d;
    if (!__get_cpuid(1, &a, &b, &c, &d)) return LSS_PATH_SCALAR;
    int osxsave = (c >> 27) & 1, avx = (c >> 28) & 1, fma = (c >> 12) & 1;
    if (!osxsave || !avx || !fma) return LSS_PATH_SCALAR;
    uint64_t xcr0 = xgetbv0();
    if ((xcr0 & 0x6) != 0x6) return LSS_PATH_SCALAR;  /* the OS saves the YMM state */
    if (!__get_cpuid_count(7, 0, &a, &b, &c, &d)) return LSS_PATH_SCALAR;
    int avx2 = (b >> 5) & 1, f512 = (b >> 16) & 1, dq512 = (b >> 17) & 1, vl512 = (b >> 31) & 1;
    if (!avx2) return LSS_PATH_SCALAR;
    if (f512 && dq512 && vl512 && (xcr0 & 0xe6) == 0xe6) return LSS_PATH_AVX512;  /* and the ZMM/mask state */
    return LSS_PATH_AVX2;
}
#else
int lss_simd_best_path(void) { return LSS_PATH_SCALAR; }
#endif

int lss_simd_resolve_path(int requested) {
    int best = lss_simd_best_path();
    if (requested <= LSS_PATH_AUTO || requested > LSS_PATH_AVX512) return best;
    return requested < best ? requested : best;
}

static double *take(double **p, int n) {
    double *r = *p;
    *p += n;
    return r;
}

int chain_simd_init(Chain *c, int requested) {
    c->path = lss_simd_resolve_path(requested);
    c->simd = NULL;
    if (c->path == LSS_PATH_SCALAR) return 0;
    int N = c->m.n_carts, W = c->path == LSS_PATH_AVX512 ? 8 : 4;
    int NW = (N + W - 1) / W * W, NP = NW + W;
    const int n_arrays = CART_NY + 12 + 25 + 29 + 17 + 6 + 7 + 2 + 3 * SIMD_NMOT;
    size_t bytes = sizeof(ChainSimd) + 64 + sizeof(double) * (size_t)n_arrays * NP + (size_t)3 * NP +
                   sizeof(int) * (size_t)N + 64;
    void *block = c->m.alloc.calloc(1, bytes);
    if (!block) return 1;
    ChainSimd *S = block;
    S->block = block;
    S->W = W;
    S->N = N;
    S->NW = NW;
    S->NP = NP;
    S->ir_drive = 1.0 / c->m.g.r_drive;
    S->ir_steer = 1.0 / c->m.g.r_steer;
    uintptr_t a = ((uintptr_t)(S + 1) + 63) & ~(uintptr_t)63;
    double *p = (double *)a;
    for (int k = 0; k < CART_NY; k++) S->Y[k] = take(&p, NP);
    for (int k = 0; k < 9; k++) S->R[k] = take(&p, NP);
    for (int k = 0; k < 3; k++) S->ww[k] = take(&p, NP);
    for (int k = 0; k < 9; k++) S->bR[k] = take(&p, NP);
    for (int k = 0; k < 3; k++) S->bc[k] = take(&p, NP);
    for (int k = 0; k < 3; k++) S->ch[k] = take(&p, NP);
    S->bs = take(&p, NP); S->lo = take(&p, NP); S->hi = take(&p, NP); S->ich0 = take(&p, NP);
    S->k = take(&p, NP); S->uy = take(&p, NP); S->uz = take(&p, NP); S->cm = take(&p, NP);
    S->key = take(&p, NP);
    for (int k = 0; k < 3; k++) S->Fw[k] = take(&p, NP);
    for (int k = 0; k < 3; k++) S->Tw[k] = take(&p, NP);
    S->s = take(&p, NP); S->vt = take(&p, NP);
    for (int k = 0; k < 3; k++) S->t[k] = take(&p, NP);
    for (int k = 0; k < N_WHEEL; k++) {
        S->ws[k] = take(&p, NP); S->wd[k] = take(&p, NP); S->wdd[k] = take(&p, NP); S->wf[k] = take(&p, NP);
    }
    S->pdw = take(&p, NP); S->prw = take(&p, NP);
    for (int k = 0; k < 3; k++) {
        S->jf[k] = take(&p, NP); S->jTA[k] = take(&p, NP); S->jTB[k] = take(&p, NP);
    }
    for (int k = 0; k < 2; k++) {
        S->jd[k] = take(&p, NP); S->jdd[k] = take(&p, NP); S->jfn[k] = take(&p, NP);
    }
    S->pdj = take(&p, NP); S->jDadot = take(&p, NP);
    for (int k = 0; k < N_WHEEL; k++) S->voW[k] = take(&p, NP);
    for (int k = 0; k < 2; k++) S->voJ[k] = take(&p, NP);
    S->im = take(&p, NP);
    for (int k = 0; k < 3; k++) S->iI[k] = take(&p, NP);
    for (int k = 0; k < 3; k++) S->In[k] = take(&p, NP);
    S->mg = take(&p, NP);
    S->mlo = take(&p, NP); S->mhi = take(&p, NP);
    for (int k = 0; k < SIMD_NMOT; k++) {
        S->ms0[k] = take(&p, NP); S->ms1[k] = take(&p, NP); S->mil[k] = take(&p, NP);
    }
    unsigned char *u = (unsigned char *)p;
    S->kind = u;
    S->chunk = u + NP;
    S->mfull = u + 2 * NP;
    S->fix = (int *)(((uintptr_t)(u + 3 * NP) + 7) & ~(uintptr_t)7);
    c->simd = S;
    chain_simd_masses(c);
    for (int i = 0; i < NP; i++) {
        S->key[i] = NAN;  /* no base yet */
        S->mlo[i] = S->mhi[i] = NAN;
        for (int k = 0; k < SIMD_NMOT; k++) {  /* an empty slot overlaps nothing */
            S->ms0[k][i] = S->ms1[k][i] = -1e30;
            S->mil[k][i] = 0.0;
        }
    }
    S->vo_dirty = 1;
    S->base_dirty = 1;
    S->synced = 0;
    return 0;
}

void chain_simd_free(Chain *c) {
    if (c->simd) c->m.alloc.free(c->simd->block);
    c->simd = NULL;
}

void chain_simd_masses(Chain *c) {
    ChainSimd *S = c->simd;
    if (!S) return;
    for (int i = 0; i < S->NP; i++) {
        int j = i < S->N ? i : 0;   /* the padding and the ghost: copies of cart 0 */
        S->im[i] = 1.0 / c->m.mass[j];
        for (int k = 0; k < 3; k++) {
            S->In[k][i] = c->m.inertia[3 * j + k];
            S->iI[k][i] = 1.0 / c->m.inertia[3 * j + k];
        }
        S->mg[i] = c->m.mass[j] * c->m.gravity;
    }
}

void chain_simd_invalidate(Chain *c) {
    if (c->simd) {
        c->simd->vo_dirty = 1;
        c->simd->base_dirty = 1;
        c->simd->synced = 0;
    }
}

/* Cart j's base into slot i of the arrays (i = j, or a padding slot). */
static void put_base(ChainSimd *S, const TrackBase *b, int i) {
    const TrackElement *e = b->e;
    for (int k = 0; k < 9; k++) S->bR[k][i] = b->R[k];
    for (int k = 0; k < 3; k++) {
        S->bc[k][i] = b->c[k];
        S->ch[k][i] = b->chat[k];
    }
    S->bs[i] = b->s;
    S->lo[i] = b->lo;
    S->hi[i] = b->hi;
    S->ich0[i] = b->ich0;
    /* the arc code's element: a straight is k = 0, u = 0 */
    S->k[i] = b->kind == TL_STRAIGHT ? 0.0 : e->k;
    S->uy[i] = b->kind == TL_STRAIGHT ? 0.0 : e->uy;
    S->uz[i] = b->kind == TL_STRAIGHT ? 0.0 : e->uz;
    S->cm[i] = b->chat[1] * S->uz[i] - b->chat[2] * S->uy[i];
    S->kind[i] = (unsigned char)b->kind;
}

static void copy_base(ChainSimd *S, int from, int to) {
    for (int k = 0; k < 9; k++) S->bR[k][to] = S->bR[k][from];
    for (int k = 0; k < 3; k++) {
        S->bc[k][to] = S->bc[k][from];
        S->ch[k][to] = S->ch[k][from];
    }
    S->bs[to] = S->bs[from]; S->lo[to] = S->lo[from]; S->hi[to] = S->hi[from]; S->ich0[to] = S->ich0[from];
    S->k[to] = S->k[from]; S->uy[to] = S->uy[from]; S->uz[to] = S->uz[from]; S->cm[to] = S->cm[from];
    S->kind[to] = S->kind[from];
}

/* The motors whose span can overlap cart i's plate while its centre stays
 * within SIMD_MWIN of sp0 (arc lengths unwrapped around sp0: a motor a lap
 * away is listed shifted by the track length). */
static void motor_window(Chain *c, int i, double sp0) {
    ChainSimd *S = c->simd;
    const Track *t = &c->m.track;
    double half = 0.5 * c->m.g.plate_length, L = t->length;
    double a = sp0 - SIMD_MWIN - half, b = sp0 + SIMD_MWIN + half;
    int n = 0, full = 0;
    for (int k = 0; k < SIMD_NMOT; k++) {
        S->ms0[k][i] = S->ms1[k][i] = -1e30;
        S->mil[k][i] = 0.0;
    }
    for (int lap = -1; lap <= 1; lap++)
        for (int j = 0; j < t->n_motors; j++) {
            double s0 = t->motor_s0[j] + lap * L, s1 = t->motor_s1[j] + lap * L;
            if (!(s1 > s0) || !(s1 > a) || !(s0 < b)) continue;
            if (n == SIMD_NMOT) {
                full = 1;
                continue;
            }
            S->ms0[n][i] = s0;
            S->ms1[n][i] = s1;
            S->mil[n][i] = 1.0 / (s1 - s0);
            n++;
        }
    S->mlo[i] = sp0 - SIMD_MWIN;
    S->mhi[i] = sp0 + SIMD_MWIN;
    S->mfull[i] = (unsigned char)full;
}

/* Before every evaluation: the bases of the carts whose axle reached another
 * point of the SIMD_BASE_MOVE grid (one track_frame each; the scalar path
 * builds one per cart and accepted step, at the axle), the chunk kinds and
 * the twisted carts, the contact memory by quantity. The bases depend on
 * s_hint alone, which changes only outside evaluations (then
 * chain_simd_invalidate is called): they are checked once per change, not
 * in each of a step's six or twelve evaluations. */
void simd_refresh(Chain *c, const double *y) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    int N = S->N, moved0 = 0, recode = 0;
    for (int i = 0; S->base_dirty && i < N; i++) {
        double sh = c->st.s_hint[i];
        /* the base sits at the grid point of SIMD_BASE_MOVE nearest the axle
         * (a function of the state alone, so that a restored state replays
         * bit for bit); the projections are exact to rounding from any base
         * on the cart's element, and one that leaves it is taken by the
         * scalar code */
        double g = floor(sh * (1.0 / SIMD_BASE_MOVE) + 0.5) * SIMD_BASE_MOVE;
        if (S->key[i] != g) {
            TrackBase b;
            int el = c->sc.cart[i].el, kind = S->kind[i];
            double uy = S->uy[i], uz = S->uz[i];
            track_base(&m->track, g, &el, &b);
            put_base(S, &b, i);
            S->key[i] = g;
            moved0 |= i == 0;
            /* what the chunks' codes and the twisted list depend on */
            recode |= kind != S->kind[i] || uy != S->uy[i] || uz != S->uz[i];
            double sp0 = sh - (m->g.x_axle - m->g.x_motor);
            if (m->track.n_motors > 0 && !(sp0 >= S->mlo[i] + 0.5 * SIMD_MWIN && sp0 <= S->mhi[i] - 0.5 * SIMD_MWIN))
                motor_window(c, i, sp0);
        }
    }
    S->base_dirty = 0;
    if (moved0)
        for (int i = N; i < S->NP; i++) copy_base(S, 0, i);
    if (recode) {
        int nt = 0;
        for (int i = 0; i < N; i++)
            if (S->kind[i] == TL_TWISTED) S->fix[nt++] = i;
        S->n_fix_twisted = nt;
        /* the code each chunk takes (chain_simd_kernel.h, ARC): 0 straight; 1 any
         * plane arc; 2 arcs about b alone (uy = 0); 3 about n alone (uz = 0).
         * Carts on twisted elements count for none: the scalar code redoes them. */
        for (int a = 0; a < S->NW; a += S->W) {
            int arc = 0, off_b = 0, off_n = 0;
            for (int l = a; l < a + S->W && l < N; l++) {
                if (S->kind[l] != TL_PLANAR) continue;
                arc = 1;
                off_b |= S->uy[l] != 0.0;
                off_n |= S->uz[l] != 0.0;
            }
            S->chunk[a / S->W] = (unsigned char)(!arc ? 0 : !off_b ? 2 : !off_n ? 3 : 1);
        }
    }
    if (S->vo_dirty) {
        const double *vo = c->st.v_onset;
        for (int i = 0; i < N; i++) {
            S->voJ[0][i] = vo[N_SLOT * i + SLOT_JA];
            S->voJ[1][i] = vo[N_SLOT * i + SLOT_JR];
            for (int k = 0; k < N_WHEEL; k++) S->voW[k][i] = vo[N_SLOT * i + SLOT_WHEEL + k];
        }
        S->vo_dirty = 0;
    }
    if (m->fx.oor_on) {
        const double *gl = y + CART_NY * N;
        c->sc.oor_x[0] = gl[G_ROLL_L];
        c->sc.oor_x[1] = gl[G_ROLL_R];
    }
}

/* Cart i by the scalar code (a twisted base, or a projection the vector
 * code declined); its results replace the lanes'. */
void simd_fix_cart(Chain *c, const double *y, int i) {
    ChainSimd *S = c->simd;
    CartScratch *cs = &c->sc.cart[i];
    CartLocal L;
    double pd = 0.0, pr = 0.0;
    cart_kinematics(c, y, i, &L);
    wheel_forces(c, i, &L, &pd, &pr);
    if (c->m.fx.resist_on) effects_resistance(c, i, &pr);
    for (int k = 0; k < 3; k++) {
        S->Fw[k][i] = cs->F[k];
        S->Tw[k][i] = cs->T[k];
        S->t[k][i] = cs->t[k];
    }
    S->s[i] = cs->s;
    S->vt[i] = cs->v_t;
    for (int k = 0; k < N_WHEEL; k++) {
        int slot = N_SLOT * i + SLOT_WHEEL + k;
        S->ws[k][i] = cs->wheel_speed[k];
        S->wd[k][i] = c->sc.delta[slot];
        S->wdd[k][i] = c->sc.ddelta[slot];
        S->wf[k][i] = c->sc.force[slot];
    }
    S->pdw[i] = pd;
    S->prw[i] = pr;
}

/* The motors: thrust along the tangent at each cart's motor point (as
 * drive_forces), added to the cart's force and torque. */
void simd_drive(Chain *c, double F_cmd) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    sc->F_total = sc->P_total = 0.0;
    if (!drive_acts(m, F_cmd)) return;
    const double *Fk = drive_motors(c);
    const double xm = m->g.x_motor, zm = m->g.z_motor;
    for (int i = 0; i < S->N; i++) {
        double F;
        if (!drive_thrust(m, Fk, S->s[i], &sc->cart[i].motor, F_cmd, &F)) continue;
        double rm[3], w[3], v[3], fv[3], tmp[3];
        for (int k = 0; k < 3; k++) {
            rm[k] = S->R[3 * k][i] * xm + S->R[3 * k + 2][i] * zm;
            w[k] = S->ww[k][i];
            fv[k] = S->t[k][i] * F;
        }
        v3_cross(v, w, rm);
        v[0] += S->Y[7][i]; v[1] += S->Y[8][i]; v[2] += S->Y[9][i];
        v3_cross(tmp, rm, fv);
        for (int k = 0; k < 3; k++) {
            S->Fw[k][i] += fv[k];
            S->Tw[k][i] += tmp[k];
        }
        sc->F_total += F;
        sc->P_total += v3_dot(fv, v);
    }
}

/* The thrust of cart i by the scalar walk (drive_thrust): for a plate
 * outside its window of candidates, or with more motors than it holds. */
void simd_drive_lane(Chain *c, int i, double F_cmd, double *F) {
    if (!drive_thrust(&c->m, drive_motors(c), c->simd->s[i], &c->sc.cart[i].motor, F_cmd, F)) *F = 0.0;
}

/* The globals' derivatives and the transducer's joint quantities. */
void simd_finish(Chain *c, const double *y, double *dy, double F_cmd, double zdot, double sum_vt) {
    ChainSimd *S = c->simd;
    const ChainModel *m = &c->m;
    ChainScratch *sc = &c->sc;
    int N = S->N, tr = m->transducer;
    (void)y;
    double pd = S->p_damp, pr = S->p_roll;  /* summed by the last kernel */
    double f[3] = {S->jf[0][tr + 1], S->jf[1][tr + 1], S->jf[2][tr + 1]}, RA[9];
    for (int k = 0; k < 9; k++) RA[k] = S->R[k][tr];
    m3_tmulv(sc->jointF, RA, f);
    sc->joint_v_axial = -S->jDadot[tr + 1];
    double *dg = dy + CART_NY * N;
    dg[G_INT] = zdot;
    dg[G_WMOT] = sc->P_total;
    dg[G_WDAMP] = pd;
    dg[G_WROLL] = pr;
    dg[G_ROLL_L] = m->fx.oor_on ? sc->oor_rate[0] : 0.0;
    dg[G_ROLL_R] = m->fx.oor_on ? sc->oor_rate[1] : 0.0;
    sc->v_mean = sum_vt / N;
    sc->F_cmd = F_cmd;
    sc->n_rhs++;
    S->synced = 0;
}

int chain_simd_accept(Chain *c) {
    ChainSimd *S = c->simd;
    ChainState *st = &c->st;
    const double v_min = c->m.v_min;
    int changed = 0;
    for (int i = 0; i < S->N; i++) {
        int k0 = N_SLOT * i;
        st->s_hint[i] = S->s[i];
        for (int k = 0; k < 2; k++) {
            changed |= contact_memory_slot(st, v_min, k0 + k, S->jd[k][i + 1], S->jdd[k][i + 1]);
            S->voJ[k][i] = st->v_onset[k0 + k];
        }
        for (int k = 0; k < N_WHEEL; k++) {
            int slot = k0 + SLOT_WHEEL + k;
            changed |= contact_memory_slot(st, v_min, slot, S->wd[k][i], S->wdd[k][i]);
            S->voW[k][i] = st->v_onset[slot];
        }
    }
    S->base_dirty = 1;  /* s_hint moved; the mirror of v_onset is current */
    return changed;
}

static void sync_cart(ChainSimd *S, ChainScratch *sc, int i) {
    CartScratch *cs = &sc->cart[i];
    cs->s = S->s[i];
    cs->v_t = S->vt[i];
    double *d = sc->delta + N_SLOT * i, *dd = sc->ddelta + N_SLOT * i, *f = sc->force + N_SLOT * i;
    for (int k = 0; k < 2; k++) {
        d[k] = S->jd[k][i + 1];
        dd[k] = S->jdd[k][i + 1];
        f[k] = S->jfn[k][i + 1];
    }
    for (int k = 0; k < N_WHEEL; k++) {
        cs->wheel_speed[k] = S->ws[k][i];
        d[SLOT_WHEEL + k] = S->wd[k][i];
        dd[SLOT_WHEEL + k] = S->wdd[k][i];
        f[SLOT_WHEEL + k] = S->wf[k][i];
    }
}

void chain_simd_sync(Chain *c) {
    ChainSimd *S = c->simd;
    if (!S || S->synced) return;
    for (int i = 0; i < S->N; i++) sync_cart(S, &c->sc, i);
    S->synced = 1;
}

void chain_simd_sync_cart(Chain *c, int i) {
    ChainSimd *S = c->simd;
    if (S && !S->synced) sync_cart(S, &c->sc, i);
}
