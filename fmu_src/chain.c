/* Building, checking, snapshotting and freeing the chain. */
#include <stdio.h>
#include <string.h>

#include "chain_simd.h"

#define GRAVITY 9.81

static int bad(char *err, size_t errlen, const char *name, double v, const char *rule) {
    snprintf(err, errlen, "%s = %.17g is invalid: %s", name, v, rule);
    return 1;
}

int chain_check_params(const LSSParams *p, char *err, size_t errlen) {
    const struct { const char *name; double v; } cors[] = {
        {"contact.e_JA", p->contact_e_JA}, {"contact.e_JR", p->contact_e_JR},
        {"contact.e_SW", p->contact_e_SW}, {"contact.e_RW", p->contact_e_RW}};
    for (int i = 0; i < 4; i++)
        if (!(cors[i].v > 0.0 && cors[i].v <= 1.0))
            return bad(err, errlen, cors[i].name, cors[i].v, "a coefficient of restitution must lie in (0, 1]");
    if (p->contact_model < 1 || p->contact_model > 6) {
        snprintf(err, errlen, "contact.model = %d is unknown: use 1 HC, 2 HW, 3 LW, 4 LN, 5 GZ or 6 FL",
                 p->contact_model);
        return 1;
    }
    if (!(p->contact_v_min > 0.0 && p->contact_v_min <= 10.0))
        return bad(err, errlen, "contact.v_min", p->contact_v_min, "must lie in (0, 10] m/s");
    if (!(fabs(p->chain_pretension) <= 0.5))
        return bad(err, errlen, "chain.pretension", p->chain_pretension, "must be finite, |d| <= 0.5 m");
    if (!(p->wheel_mu_roll >= 0.0 && p->wheel_mu_roll <= 0.5))
        return bad(err, errlen, "wheel.mu_roll", p->wheel_mu_roll, "must lie in [0, 0.5]");
    if (!(p->drive_Kp >= 0.0 && p->drive_Kp < 1e9))
        return bad(err, errlen, "drive.Kp", p->drive_Kp, "must be finite and >= 0");
    if (!(p->drive_Ki >= 0.0 && p->drive_Ki < 1e9))
        return bad(err, errlen, "drive.Ki", p->drive_Ki, "must be finite and >= 0");
    if (!(p->drive_F_max >= 0.0 && p->drive_F_max < 1e7))
        return bad(err, errlen, "drive.F_max", p->drive_F_max, "must be finite and >= 0");
    if (!(p->drive_motor_length > 0.0 && p->drive_motor_length <= 20.0))
        return bad(err, errlen, "drive.motor_length", p->drive_motor_length, "must lie in (0, 20] m");
    if (!(fabs(p->drive_v_ref) <= 20.0))
        return bad(err, errlen, "drive.v_ref", p->drive_v_ref, "must be finite, |v| <= 20 m/s");
    if (!(p->cart_mass_factor > 0.0 && p->cart_mass_factor <= 20.0))
        return bad(err, errlen, "cart.mass_factor", p->cart_mass_factor,
                   "must lie in (0, 20]: a cart needs a positive mass");
    if (!(p->track_guide_gap >= -0.005 && p->track_guide_gap <= 0.05))
        return bad(err, errlen, "track.guide_gap", p->track_guide_gap, "must lie in [-0.005, 0.05] m");
    if (!(fabs(p->chain_v_init) <= 20.0))
        return bad(err, errlen, "chain.v_init", p->chain_v_init, "must be finite, |v| <= 20 m/s");
    if (p->chain_transducer < 0) {
        snprintf(err, errlen, "chain.transducer = %d is invalid: must be >= 0", p->chain_transducer);
        return 1;
    }
    if (!(p->solver_tolerance >= 1e-12 && p->solver_tolerance <= 0.1))
        return bad(err, errlen, "solver.tolerance", p->solver_tolerance,
                   "must lie in [1e-12, 0.1] (below 1e-12 the solver stalls in double precision)");
    if (!(p->solver_h_max >= 1e-6 && p->solver_h_max <= 1.0))
        return bad(err, errlen, "solver.h_max", p->solver_h_max,
                   "must lie in [1e-6, 1] s (a smaller step would stall the solver)");
    if (p->solver_vector_path < 0 || p->solver_vector_path > 3) {
        snprintf(err, errlen, "solver.vector_path = %d is invalid: use 0 auto, 1 scalar, 2 AVX2 or 3 AVX-512",
                 p->solver_vector_path);
        return 1;
    }
    if (p->solver_method < 0 || p->solver_method > 1) {
        snprintf(err, errlen, "solver.method = %d is invalid: use 0 Dormand-Prince 5(4) or 1 DOP853",
                 p->solver_method);
        return 1;
    }
    return effects_check_params(p, err, errlen);
}

static int is_path(const char *name) {
    return strchr(name, '/') || strchr(name, '\\') || strstr(name, ".layout");
}

int chain_load_layout(const char *name, const char *resource_dir, LayoutSpec *spec,
                      const LSSAlloc *a, char *err, size_t errlen) {
    char path[LSS_STRING_MAX + 64], msg[512];
    if (name[0] == '\0') {
        snprintf(err, errlen, "layout.name is empty: give a built-in layout or a file path");
        return 1;
    }
    if (is_path(name)) {
        snprintf(path, sizeof path, "%s", name);
    } else {
        for (const char *q = name; *q; q++)
            if (!((*q >= 'a' && *q <= 'z') || (*q >= 'A' && *q <= 'Z') || (*q >= '0' && *q <= '9') ||
                  *q == '_' || *q == '-')) {
                snprintf(err, errlen, "layout.name = \"%.200s\" is neither a built-in layout name nor a path", name);
                return 1;
            }
        if (!resource_dir) {
            snprintf(err, errlen, "layout.name = \"%.200s\": no resource folder to find built-in layouts in", name);
            return 1;
        }
        snprintf(path, sizeof path, "%s/layouts/%s.layout", resource_dir, name);
    }
    if (layout_read_file(path, spec, a, msg, sizeof msg) != 0) {
        snprintf(err, errlen, "layout.name = \"%.200s\": %s", name, msg);  /* msg starts with the path */
        return 1;
    }
    return 0;
}

static void *xcalloc(Chain *c, size_t n, size_t size, int *fail) {
    void *p = c->m.alloc.calloc(n ? n : 1, size);
    if (!p) *fail = 1;
    return p;
}

static int allocate(Chain *c) {
    int N = c->m.n_carts, ny = c->m.n_y, fail = 0;
    size_t ns = (size_t)N_SLOT * N;
    c->st.y = xcalloc(c, ny, sizeof(double), &fail);
    c->st.s_hint = xcalloc(c, N, sizeof(double), &fail);
    c->st.v_onset = xcalloc(c, ns, sizeof(double), &fail);
    c->st.delta_prev = xcalloc(c, ns, sizeof(double), &fail);
    c->st.ddelta_prev = xcalloc(c, ns, sizeof(double), &fail);
    c->sc.delta = xcalloc(c, ns, sizeof(double), &fail);
    c->sc.ddelta = xcalloc(c, ns, sizeof(double), &fail);
    c->sc.force = xcalloc(c, ns, sizeof(double), &fail);
    c->sc.cart = xcalloc(c, N, sizeof(CartScratch), &fail);
    int nk = c->m.method == LSS_METHOD_DOP853 ? DOPRI_NK : 7;
    for (int k = 0; k < nk; k++) c->ode.k[k] = xcalloc(c, ny, sizeof(double), &fail);
    c->ode.ytmp = xcalloc(c, ny, sizeof(double), &fail);
    c->ode.ynew = xcalloc(c, ny, sizeof(double), &fail);
    c->dy_scratch = xcalloc(c, ny, sizeof(double), &fail);
    c->m.err_scale = xcalloc(c, ny, sizeof(double), &fail);
    c->m.err_rel = xcalloc(c, ny, sizeof(double), &fail);
    c->m.mass = xcalloc(c, N, sizeof(double), &fail);
    c->m.inertia = xcalloc(c, (size_t)3 * N, sizeof(double), &fail);
    return fail;
}

void chain_free(Chain *c) {
    if (!c) return;
    LSSAlloc a = c->m.alloc;
    chain_simd_free(c);
    void *ptrs[] = {c->st.y, c->st.s_hint, c->st.v_onset, c->st.delta_prev, c->st.ddelta_prev,
                    c->sc.delta, c->sc.ddelta, c->sc.force, c->sc.cart,
                    c->ode.k[0], c->ode.k[1], c->ode.k[2], c->ode.k[3], c->ode.k[4], c->ode.k[5], c->ode.k[6],
                    c->ode.k[7], c->ode.k[8], c->ode.k[9], c->ode.k[10], c->ode.k[11], c->ode.k[12],
                    c->ode.ytmp, c->ode.ynew, c->dy_scratch, c->m.err_scale, c->m.err_rel,
                    c->m.mass, c->m.inertia};
    for (size_t i = 0; i < sizeof ptrs / sizeof ptrs[0]; i++)
        if (ptrs[i]) a.free(ptrs[i]);
    track_free(&c->m.track, &a);
    a.free(c);
}

/* Error scales: positions and orientations are judged in absolute terms (a
 * contact sees millimetres, not a fraction of the track's size), rates also
 * relative to their size. */
static void error_scales(ChainModel *m) {
    for (int i = 0; i < m->n_carts; i++) {
        double *s = m->err_scale + CART_NY * i, *r = m->err_rel + CART_NY * i;
        for (int k = 0; k < 3; k++) { s[k] = 1e-2; r[k] = 0; }
        for (int k = 3; k < 7; k++) { s[k] = 1e-2; r[k] = 0; }
        for (int k = 7; k < 10; k++) { s[k] = 1e-2; r[k] = 1; }
        for (int k = 10; k < 13; k++) { s[k] = 1e-1; r[k] = 1; }
    }
    double *s = m->err_scale + CART_NY * m->n_carts, *r = m->err_rel + CART_NY * m->n_carts;
    s[G_INT] = 1e-2; r[G_INT] = 1;
    for (int k = 1; k < N_GLOBAL; k++) { s[k] = 1e6; r[k] = 1; }  /* bookkeeping only */
    /* the rolled distances set the phase of an out-of-round wheel: positions */
    s[G_ROLL_L] = s[G_ROLL_R] = 1e-2;
    r[G_ROLL_L] = r[G_ROLL_R] = 0;
}

Chain *chain_create(const LSSParams *p, const char *resource_dir, const LSSAlloc *a,
                    char *err, size_t errlen) {
    if (chain_check_params(p, err, errlen)) return NULL;
    Chain *c = a->calloc(1, sizeof(Chain));
    if (!c) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    ChainModel *m = &c->m;
    m->alloc = *a;
    LayoutSpec spec;
    memset(&spec, 0, sizeof spec);
    if (chain_load_layout(p->layout_name, resource_dir, &spec, a, err, errlen)) goto fail;
    snprintf(m->layout_name, sizeof m->layout_name, "%s", spec.name);
    if (track_build(&spec, p->drive_motor_length, 1e-3, 1e-4, &m->track, a, err, errlen)) {
        char why[512];
        snprintf(why, sizeof why, "%s", err);
        snprintf(err, errlen, "layout.name = \"%.200s\": %s", p->layout_name, why);
        goto fail_spec;
    }
    if (!cart_type_lookup(spec.wheel, spec.coupling, &m->type)) {
        snprintf(err, errlen, "layout \"%s\": unknown wheel/coupling type %c/%c", spec.name, spec.wheel,
                 spec.coupling);
        goto fail_spec;
    }
    if (spec.cart_mass > 0) m->type.mass = spec.cart_mass;
    m->n_carts = spec.n_carts > 0 ? spec.n_carts : (int)floor(m->track.length / 1.25 + 0.5);
    layout_spec_free(&spec, a);
    if (m->n_carts < 3 || m->n_carts > 100000) {
        snprintf(err, errlen, "a chain of %d carts is not supported (3 to 100000)", m->n_carts);
        goto fail;
    }
    if (p->chain_transducer >= m->n_carts) {
        snprintf(err, errlen, "chain.transducer = %d is invalid: the chain has %d carts (0..%d)",
                 p->chain_transducer, m->n_carts, m->n_carts - 1);
        goto fail;
    }
    m->transducer = p->chain_transducer;
    m->n_y = CART_NY * m->n_carts + N_GLOBAL;
    m->gravity = GRAVITY;
    m->law_code = p->contact_model;
    const double es[CC_N] = {p->contact_e_JA, p->contact_e_JR, p->contact_e_SW, p->contact_e_RW};
    const double Ks[CC_N] = {m->type.K_axial, m->type.K_radial, m->type.K_steer, m->type.K_drive};
    const double ns[CC_N] = {m->type.n_axial, m->type.n_radial, m->type.n_steer, m->type.n_drive};
    for (int k = 0; k < CC_N; k++) {
        m->law[k].K = Ks[k];
        m->law[k].n = ns[k];
        m->law[k].e = es[k];
        m->law[k].chi = contact_chi(p->contact_model, es[k]);
        if (!isfinite(m->law[k].chi)) {
            snprintf(err, errlen, "cannot compute the damping factor of law %d at e = %g", p->contact_model, es[k]);
            goto fail;
        }
    }
    m->v_min = p->contact_v_min;
    m->mu_roll = p->wheel_mu_roll;
    m->F_max = p->drive_F_max;
    m->motor_length = p->drive_motor_length;
    m->pretension = p->chain_pretension;
    m->tol = p->solver_tolerance;
    m->h_max = p->solver_h_max;
    m->method = p->solver_method;
    cart_geometry_init(&m->g, &m->type, m->track.length / m->n_carts, p->track_guide_gap, p->cart_mass_factor);
    if (allocate(c)) {
        snprintf(err, errlen, "out of memory for a chain of %d carts", m->n_carts);
        goto fail;
    }
    error_scales(m);
    if (effects_init(&m->fx, p, m->n_carts, m->transducer, m->g.r_drive, m->track.length, err, errlen)) goto fail;
    for (int i = 0; i < m->n_carts; i++) {
        /* factor 1 (every effect off) keeps the cart's mass and inertia bit for bit */
        double f = effects_mass_factor(p, i, m->transducer);
        m->mass[i] = m->g.mass * f;
        for (int k = 0; k < 3; k++) m->inertia[3 * i + k] = m->g.inertia[k] * f;
    }
    if (chain_simd_init(c, p->solver_vector_path)) {
        snprintf(err, errlen, "out of memory for a chain of %d carts", m->n_carts);
        goto fail;
    }
    chain_set_inputs(c, p);
    double v0 = p->chain_v_init >= 0 ? p->chain_v_init : p->drive_v_ref;
    if (chain_initial_state(c, v0, err, errlen)) goto fail;
    chain_solver_init(c);
    dopri_reset(&c->st.ode, 0.0, 1e-4);
    /* contact memory at the start: closed contacts use the floor */
    chain_rhs(c, 0.0, c->st.y, c->ode.k[0]);
    chain_simd_sync(c);
    c->st.ode.n_rhs = 1;
    for (int k = 0; k < N_SLOT * m->n_carts; k++) {
        c->st.v_onset[k] = c->sc.delta[k] > 0 ? m->v_min : 0.0;
        c->st.delta_prev[k] = c->sc.delta[k];
        c->st.ddelta_prev[k] = c->sc.ddelta[k];
    }
    chain_simd_invalidate(c);
    c->st.ode.fsal_valid = 1;
    c->scratch_at_state = 1;
    return c;
fail_spec:
    layout_spec_free(&spec, a);
fail:
    chain_free(c);
    return NULL;
}

void chain_set_inputs(Chain *c, const LSSParams *p) {
    if (c->st.v_ref != p->drive_v_ref || c->st.Kp != p->drive_Kp || c->st.Ki != p->drive_Ki)
        c->st.ode.fsal_valid = c->scratch_at_state = 0;
    c->st.v_ref = p->drive_v_ref;
    c->st.Kp = p->drive_Kp;
    c->st.Ki = p->drive_Ki;
}

/* Snapshot layout: header, then y, s_hint, v_onset, delta_prev, ddelta_prev
 * and the FSAL derivative, so that a restored run replays bit for bit. */
#define SNAP_HEADER 12

size_t chain_state_size(const Chain *c) {
    return (size_t)SNAP_HEADER + 2 * (size_t)c->m.n_y + (size_t)c->m.n_carts * (1 + 3 * N_SLOT);
}

void chain_state_save(const Chain *c, double *buf) {
    const ChainState *st = &c->st;
    int N = c->m.n_carts, ns = N_SLOT * N;
    const DopriState *o = &st->ode;
    double hdr[SNAP_HEADER] = {(double)c->m.n_y, o->t, o->h, o->err_prev, st->v_ref, st->Kp, st->Ki,
                               (double)o->n_steps, (double)o->n_rejected, (double)o->n_rhs, o->h_last,
                               (double)o->fsal_valid};
    memcpy(buf, hdr, sizeof hdr);
    double *p = buf + SNAP_HEADER;
    memcpy(p, st->y, sizeof(double) * (size_t)c->m.n_y); p += c->m.n_y;
    memcpy(p, st->s_hint, sizeof(double) * (size_t)N); p += N;
    memcpy(p, st->v_onset, sizeof(double) * (size_t)ns); p += ns;
    memcpy(p, st->delta_prev, sizeof(double) * (size_t)ns); p += ns;
    memcpy(p, st->ddelta_prev, sizeof(double) * (size_t)ns); p += ns;
    memcpy(p, c->ode.k[0], sizeof(double) * (size_t)c->m.n_y);
}

void chain_state_load(Chain *c, const double *buf) {
    ChainState *st = &c->st;
    int N = c->m.n_carts, ns = N_SLOT * N;
    DopriState *o = &st->ode;
    o->t = buf[1]; o->h = buf[2]; o->err_prev = buf[3];
    st->v_ref = buf[4]; st->Kp = buf[5]; st->Ki = buf[6];
    o->n_steps = (long)buf[7]; o->n_rejected = (long)buf[8]; o->n_rhs = (long)buf[9]; o->h_last = buf[10];
    const double *p = buf + SNAP_HEADER;
    memcpy(st->y, p, sizeof(double) * (size_t)c->m.n_y); p += c->m.n_y;
    memcpy(st->s_hint, p, sizeof(double) * (size_t)N); p += N;
    memcpy(st->v_onset, p, sizeof(double) * (size_t)ns); p += ns;
    memcpy(st->delta_prev, p, sizeof(double) * (size_t)ns); p += ns;
    memcpy(st->ddelta_prev, p, sizeof(double) * (size_t)ns); p += ns;
    memcpy(c->ode.k[0], p, sizeof(double) * (size_t)c->m.n_y);
    o->fsal_valid = buf[11] != 0;
    c->scratch_at_state = 0;
    chain_simd_invalidate(c);
}
