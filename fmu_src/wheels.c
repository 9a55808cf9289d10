/* Cart-to-track contacts: the two driving wheels on the running surface
 * (vertical) and the two steering wheels against the guide faces (lateral),
 * each a Hunt-Crossley contact with rolling resistance mu_d * N opposing the
 * rolling direction.
 *
 * The running surface is the ruled surface c(s) + y n(s), each guide face
 * c(s) + h n(s) + z b(s). A wheel (a sphere of its radius) touches them at
 * the closest point, found per wheel: where the frame twists (w_x != 0, in a
 * helix) that point is not in the plane normal to the track through the
 * wheel, and the surface normal is not b or n. With the exact closest point
 * the force is the gradient of a potential and the chain conserves energy.
 *
 * The arc length s of the closest point solves a(s) = a*(s), a the
 * t-component of p - c(s) and a* the twist offset: zero without twist; for
 * the running surface a* = -z y w_x / (1 - y w_z), for a guide face at
 * lateral position h, a* = z w_x (y - h) / (1 - h w_z + z w_y)
 * (track_local.h, tl_astar).
 *
 * Everything here is in the coordinates of the cart's track base (the track
 * frame at its axle after the last accepted step, track_local.h): the
 * search starts at the axle's arc length and is closed-form on straights
 * (where the frame is the base's: no rotation at all) and plane arcs. The
 * code is specialised per kind of base element (straight, plane arc,
 * twisted) and per wheel, so that each case carries only its own work.
 *
 * Two effects (effects.h) change the driving wheels' running surface
 * geometry: a cosine bump h(s) raises the surface under every cart, and the
 * out-of-round wheels of one cart have the radius r0 + dr(x), x the distance
 * rolled (a global state). Both add to the indentation; its gradient then has
 * a tangential part -F_n (dh/ds ds/dx_t + dr/dx), the slope of the bump or of
 * the wheel, applied through the wheel centre (a round wheel's normal passes
 * through it), so the contact stays conservative. */
#include "rhs_shared.h"

#if defined(__GNUC__)
#define ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE inline
#endif

typedef struct {
    double F[3], T[3];                /* force and torque about the CG, base coordinates */
    double p_damp, p_roll;
} WheelSum;

/* What the bump and an out-of-round wheel add to the indentation of a
 * driving wheel, and the slope d(indentation)/d(distance along t). */
typedef struct {
    double dh, slope;
} SurfaceFx;

/* Driving wheel k of cart i in its contact frame f. Kept out of line and
 * returned by value: it runs only with one of the two effects on, and the
 * hot path keeps its indentation in registers. */
static SurfaceFx surface_effects(Chain *c, int i, int k, const TrackBase *b, const LocalFrame *f, double vt) {
    const Effects *fx = &c->m.fx;
    double dh = 0.0, slope = 0.0;
    if (fx->bump_on) {
        double L = c->m.track.length, s = b->s + f->ds, hs;
        if (s >= L) s -= L;
        else if (s < 0.0) s += L;
        double h = effects_bump(fx, s, L, &hs);
        if (hs != 0.0 || h != 0.0) {
            /* ds/dx_t of the closest point: the surface point at lateral
             * offset y travels (1 - y w_z + z w_y) times as far as the centreline */
            const double *d = f->d, *w = f->w;
            dh += h;
            slope += hs / (1.0 - (d[1] * w[2] - d[2] * w[1]));
        }
    }
    if (fx->oor_on && i == fx->oor_cart) {
        int side = k == W_DL ? 0 : 1;
        double drdx;
        dh += effects_oor(fx, side, c->sc.oor_x[side], &drdx);
        slope += drdx;
        c->sc.oor_rate[side] = vt;  /* the wheel rolls without slip: theta' = v_t / r0 */
    }
    SurfaceFx r = {dh, slope};
    return r;
}

/* Wheel k of cart i; x0 is the wheel centre's part along the body x and z
 * axes (base coordinates), shared by the wheel pair. surf (a constant): the
 * bump or an out-of-round wheel is on; without, the code is the plain one. */
static ALWAYS_INLINE void one_wheel(Chain *c, int i, const CartLocal *L, const TrackBase *b, const double *x0,
                                    const int k, const int kind, const int surf, WheelSum *acc) {
    const ChainModel *m = &c->m;
    const CartGeometry *g = &m->g;
    ChainScratch *sc = &c->sc;
    CartScratch *cs = &sc->cart[i];
    const int drive = (k == W_DL || k == W_DR);
    const double side = (k == W_SL || k == W_DL) ? 1.0 : -1.0;
    const double *M = L->M;
    double yb = side * (drive ? g->y_drive : g->y_steer), r = drive ? g->r_drive : g->r_steer;
    double h = side * g->guide_half;
    double rc[3], q[3], v[3];
    for (int j = 0; j < 3; j++) rc[j] = x0[j] + M[3 * j + 1] * yb;
    v3_add(q, L->q, rc);
    v3_cross(v, L->om, rc);
    v3_add(v, v, L->v);

    /* the closest point: frame E (axes in base coordinates), d = (a, y, z) */
    LocalFrame f;
    int ident = 0, ok;
    if (kind == TL_STRAIGHT) {
        const double *ch = b->chat;
        double ds = q[0] * b->ich0;
        ok = ds >= b->lo && ds < b->hi;
        if (ok) {
            ident = 1;
            v3_set(f.d, 0.0, q[1] + ds * ch[1], q[2] + ds * ch[2]);
            f.w = b->e->w;
            if (surf) f.ds = ds;
        }
    } else {
        ok = tl_project_kind(b, q, L->axle.ds, drive ? TL_RUNNING : TL_GUIDE, h, &f, kind);
    }
    if (!ok) track_project_face(&m->track, b, q, L->axle.ds, drive ? TL_RUNNING : TL_GUIDE, h, &cs->el, &f);
    const double *d = f.d, *w = f.w;
    double vf[3];
    if (ident) v3_copy(vf, v);
    else m3_tmulv(vf, f.E, v);

    /* normal (frame coordinates), indentation, its rate, force direction */
    double N[3], delta, ddelta, dir[3];
    int flat = ident || w[0] == 0.0;
    if (drive) {
        /* normal of the running surface: (1 - y w_z) b - y w_x t */
        if (flat) {
            v3_set(N, 0.0, 0.0, 1.0);
        } else {
            v3_set(N, -d[1] * w[0], 0.0, 1.0 - d[1] * w[2]);
            v3_scale(N, N, 1.0 / v3_norm(N));
        }
        delta = r - (d[0] * N[0] + d[2] * N[2]);
        ddelta = -v3_dot(N, vf);
        v3_copy(dir, N);
    } else {
        /* normal of the face at h: (1 - h w_z + z w_y) n + z w_x t, and the
         * wheel's clearance to it measured towards the track centre */
        if (flat) {
            v3_set(N, 0.0, 1.0, 0.0);
        } else {
            v3_set(N, d[2] * w[0], 1.0 - h * w[2] + d[2] * w[1], 0.0);
            v3_scale(N, N, 1.0 / v3_norm(N));
        }
        delta = r + side * (d[0] * N[0] + (d[1] - h) * N[1]);
        ddelta = side * v3_dot(N, vf);
        v3_scale(dir, N, -side);
    }
    double vt = vf[0];
    cs->wheel_speed[k] = vt / r;
    int slot = N_SLOT * i + SLOT_WHEEL + k;
    SurfaceFx sf = {0.0, 0.0};
    if (drive && surf) {
        sf = surface_effects(c, i, k, b, &f, vt);
        delta += sf.dh;
        ddelta += sf.slope * vt;
    }
    double fn = 0.0;
    if (delta > 0) {
        const ContactLaw *law = &m->law[drive ? CC_RW : CC_SW];
        double fe;
        fn = contact_force(law, delta, ddelta, contact_vi(c->st.v_onset[slot], ddelta, m->v_min), &fe);
        acc->p_damp += (fn - fe) * ddelta;
        double sg = smooth_sign(vt), froll = m->mu_roll * fn;
        acc->p_roll += froll * sg * vt;
        /* force in the frame, then in base coordinates; applied at the
         * contact point, a wheel radius from the centre */
        double ff[3], fv[3], db[3], arm[3], tmp[3];
        v3_scale(ff, dir, fn);
        ff[0] -= froll * sg;
        if (ident) {
            v3_copy(fv, ff);
            v3_copy(db, dir);
        } else {
            m3_mulv(fv, f.E, ff);
            m3_mulv(db, f.E, dir);
        }
        v3_copy(arm, rc);
        v3_axpy(arm, -r, db);
        v3_add(acc->F, acc->F, fv);
        v3_cross(tmp, arm, fv);
        v3_add(acc->T, acc->T, tmp);
    }
    if (drive && surf && fn > 0.0) {
        /* the slope's tangential force, through the wheel centre */
        double ft[3] = {-fn * sf.slope, 0.0, 0.0}, fv[3], tmp[3];
        if (ident) v3_copy(fv, ft);
        else m3_mulv(fv, f.E, ft);
        v3_add(acc->F, acc->F, fv);
        v3_cross(tmp, rc, fv);
        v3_add(acc->T, acc->T, tmp);
    }
    sc->delta[slot] = delta;
    sc->ddelta[slot] = ddelta;
    sc->force[slot] = fn;
}

static ALWAYS_INLINE void four_wheels(Chain *c, int i, const CartLocal *L, const TrackBase *b, const double *xs,
                                      const double *xd, const int kind, const int surf, WheelSum *acc) {
    one_wheel(c, i, L, b, xs, W_SL, kind, surf, acc);
    one_wheel(c, i, L, b, xs, W_SR, kind, surf, acc);
    one_wheel(c, i, L, b, xd, W_DL, kind, surf, acc);
    one_wheel(c, i, L, b, xd, W_DR, kind, surf, acc);
}

void wheel_forces(Chain *c, int i, const CartLocal *L, double *p_damp, double *p_roll) {
    const CartGeometry *g = &c->m.g;
    CartScratch *cs = &c->sc.cart[i];
    const TrackBase *b = &cs->base;
    const double *M = L->M;
    /* the body's x and z axis parts of the wheel centres, shared by each pair */
    double xs[3], xd[3];
    for (int j = 0; j < 3; j++) {
        xd[j] = M[3 * j] * g->x_axle + M[3 * j + 2] * g->z_axle;
        xs[j] = M[3 * j] * g->x_axle + M[3 * j + 2] * g->z_steer;
    }
    WheelSum acc = {{0, 0, 0}, {0, 0, 0}, *p_damp, *p_roll};
    if (!c->m.fx.surface_on) {
        switch (b->kind) {
        case TL_STRAIGHT: four_wheels(c, i, L, b, xs, xd, TL_STRAIGHT, 0, &acc); break;
        case TL_PLANAR: four_wheels(c, i, L, b, xs, xd, TL_PLANAR, 0, &acc); break;
        default: four_wheels(c, i, L, b, xs, xd, TL_TWISTED, 0, &acc); break;
        }
    } else {
        switch (b->kind) {
        case TL_STRAIGHT: four_wheels(c, i, L, b, xs, xd, TL_STRAIGHT, 1, &acc); break;
        case TL_PLANAR: four_wheels(c, i, L, b, xs, xd, TL_PLANAR, 1, &acc); break;
        default: four_wheels(c, i, L, b, xs, xd, TL_TWISTED, 1, &acc); break;
        }
    }
    *p_damp = acc.p_damp;
    *p_roll = acc.p_roll;
    double tmp[3];
    m3_mulv(tmp, b->R, acc.F);
    v3_add(cs->F, cs->F, tmp);
    m3_mulv(tmp, b->R, acc.T);
    v3_add(cs->T, cs->T, tmp);
}
