/* Building, checking, snapshotting and freeing the chain. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "rhs_shared.h"
#include "chain_simd.h"
#include "params.h"

#define GRAVITY 9.81

/* The ranges come from the variable table (params.c); what is left here are
 * the rules a range cannot say. */
int chain_check_params(const LSSParams *p, char *err, size_t errlen) {
    return params_check_ranges(p, err, errlen);
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
    size_t nm = (size_t)(c->m.track.n_motors > 0 ? c->m.track.n_motors : 1);
    c->m.mass0 = xcalloc(c, N, sizeof(double), &fail);
    c->m.inertia0 = xcalloc(c, (size_t)3 * N, sizeof(double), &fail);
    c->st.load = xcalloc(c, N, sizeof(double), &fail);
    c->m.motor_group = xcalloc(c, nm, sizeof(int), &fail);
    c->st.F_motor = xcalloc(c, nm, sizeof(double), &fail);
    if (!fail)  /* the motors in track order, in groups of (nearly) equal count */
        for (int k = 0; k < c->m.track.n_motors; k++)
            c->m.motor_group[k] = (int)((long)k * c->m.n_groups / c->m.track.n_motors);
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
                    c->m.mass, c->m.inertia, c->m.motor_group, c->st.F_motor, c->m.mass0, c->m.inertia0,
                    c->st.load};
    for (size_t i = 0; i < sizeof ptrs / sizeof ptrs[0]; i++)
        if (ptrs[i]) a.free(ptrs[i]);
    track_free(&c->m.track, &a);
    chain_trace_free(c);
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
    if (layout_check_chain(&spec, m->track.length, &m->n_carts, err, errlen)) goto fail_spec;
    layout_spec_free(&spec, a);
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
    m->s_start = p->chain_s_start;
    if (!(m->s_start < m->track.length)) {
        snprintf(err, errlen, "chain.s_start = %.17g is invalid: must lie in [0, %.17g), the track length",
                 m->s_start, m->track.length);
        goto fail;
    }
    const double st_s[N_STATION] = {p->station_induction_s, p->station_chute_s};
    const char *st_name[N_STATION] = {"station.induction.s", "station.chute.s"};
    for (int k = 0; k < N_STATION; k++) {
        m->station_s[k] = st_s[k];
        if (!(st_s[k] < m->track.length)) {
            snprintf(err, errlen, "%s = %.17g is invalid: must lie in [0, %.17g), the track length", st_name[k],
                     st_s[k], m->track.length);
            goto fail;
        }
    }
    m->drive_mode = p->drive_mode;
    m->n_groups = p->drive_n_groups;
    if (m->drive_mode == DRIVE_EXTERNAL && m->track.n_motors == 0) {
        snprintf(err, errlen, "drive.mode = 1 (external thrust) needs motors: layout \"%s\" has none", m->layout_name);
        goto fail;
    }
    if (m->track.n_motors > 0 && m->n_groups > m->track.n_motors) {
        snprintf(err, errlen, "drive.n_groups = %d is invalid: layout \"%s\" has %d motors", m->n_groups,
                 m->layout_name, m->track.n_motors);
        goto fail;
    }
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
        m->mass0[i] = m->g.mass * f;
        for (int k = 0; k < 3; k++) m->inertia0[3 * i + k] = m->g.inertia[k] * f;
    }
    /* the items the ports name at the start ride from the start (no momentum to share yet) */
    if (chain_check_inputs(c, p, err, errlen)) goto fail;
    const int pc[LOAD_PORTS] = {p->load1_cart, p->load2_cart};
    const double pm[LOAD_PORTS] = {p->load1_mass, p->load2_mass};
    for (int k = 0; k < LOAD_PORTS; k++) {
        if (pc[k] >= 0) c->st.load[pc[k]] = pm[k];
        c->st.port[2 * k] = pc[k];
        c->st.port[2 * k + 1] = pm[k];
    }
    chain_masses(c);
    if (chain_simd_init(c, p->solver_vector_path)) {
        snprintf(err, errlen, "out of memory for a chain of %d carts", m->n_carts);
        goto fail;
    }
    chain_set_inputs(c, p);
    double v0 = p->chain_v_init >= 0 ? p->chain_v_init : p->drive_v_ref;
    if (p->chain_relax_time > 0 && v0 != 0.0) {
        snprintf(err, errlen, "chain.relax_time = %g s needs a chain that starts at rest: chain.v_init = 0 "
                 "(it is %g m/s)", p->chain_relax_time, v0);
        goto fail;
    }
    if (chain_initial_state(c, v0, err, errlen)) goto fail;
    chain_solver_init(c);
    dopri_reset(&c->st.ode, 0.0, 1e-4);
    chain_start_memory(c);
    return c;
fail_spec:
    layout_spec_free(&spec, a);
fail:
    chain_free(c);
    return NULL;
}

void chain_masses(Chain *c) {
    ChainModel *m = &c->m;
    for (int i = 0; i < m->n_carts; i++) {
        double M = m->mass0[i] + c->st.load[i];
        m->mass[i] = M;
        /* the item rides at the cart's CG with the cart's own distribution (1 bit for bit without one) */
        double f = c->st.load[i] == 0.0 ? 1.0 : M / m->mass0[i];
        for (int k = 0; k < 3; k++) m->inertia[3 * i + k] = m->inertia0[3 * i + k] * f;
    }
    chain_simd_masses(c);
}

int chain_check_inputs(const Chain *c, const LSSParams *p, char *err, size_t errlen) {
    const int pc[LOAD_PORTS] = {p->load1_cart, p->load2_cart};
    for (int k = 0; k < LOAD_PORTS; k++)
        if (pc[k] >= c->m.n_carts) {
            snprintf(err, errlen, "load%d.cart = %d is invalid: the chain has %d carts (0..%d; -1: the port is idle)",
                     k + 1, pc[k], c->m.n_carts, c->m.n_carts - 1);
            return 1;
        }
    return 0;
}

/* Cart i now carries an item of `mass` kg. An item put on arrives with no
 * velocity: the cart's momentum (and, the item riding at its CG with its
 * own distribution, its angular momentum) is shared with it; one taken off
 * leaves at the cart's velocity. E_items takes the change of mechanical
 * energy (the inelastic loss, the item's weight) so that the balance holds. */
static void put_item(Chain *c, int i, double mass) {
    ChainModel *m = &c->m;
    ChainState *st = &c->st;
    double old = st->load[i];
    if (mass == old) return;
    double M_old = m->mass0[i] + old, M_new = m->mass0[i] + mass, f = M_old / M_new;
    double *y = st->y + CART_NY * i, *v = y + 7, *w = y + 10, I[3];
    double E0 = 0.5 * M_old * v3_dot(v, v) + M_old * m->gravity * y[2];
    for (int k = 0; k < 3; k++) E0 += 0.5 * m->inertia[3 * i + k] * w[k] * w[k];
    if (mass > old)
        for (int k = 0; k < 3; k++) {
            v[k] *= f;
            w[k] *= f;
        }
    st->load[i] = mass;
    chain_masses(c);
    for (int k = 0; k < 3; k++) I[k] = m->inertia[3 * i + k];
    double E1 = 0.5 * M_new * v3_dot(v, v) + M_new * m->gravity * y[2];
    for (int k = 0; k < 3; k++) E1 += 0.5 * I[k] * w[k] * w[k];
    st->E_items += E1 - E0;
    st->ode.fsal_valid = 0;
    c->scratch_at_state = 0;
    chain_simd_invalidate(c);
}

void chain_set_inputs(Chain *c, const LSSParams *p) {
    ChainModel *m = &c->m;
    const double es[CC_N] = {p->contact_e_JA, p->contact_e_JR, p->contact_e_SW, p->contact_e_RW};
    int changed = c->st.v_ref != p->drive_v_ref || c->st.Kp != p->drive_Kp || c->st.Ki != p->drive_Ki ||
                  m->mu_roll != p->wheel_mu_roll;
    for (int k = 0; k < CC_N; k++)
        if (m->law[k].e != es[k]) {  /* solved once per change (GZ: a root), never per step */
            double chi = contact_chi(m->law_code, es[k]);
            if (!isfinite(chi)) continue;  /* cannot happen within the checked range; keep the old law */
            m->law[k].e = es[k];
            m->law[k].chi = chi;
            changed = 1;
        }
    if (m->drive_mode == DRIVE_EXTERNAL) {
        /* each group's thrust per motor, saturated at the motor's rating (the FMI layer logs it) */
        const double Fg[DRIVE_GROUPS] = {p->drive_group1_F, p->drive_group2_F, p->drive_group3_F, p->drive_group4_F,
                                         p->drive_group5_F, p->drive_group6_F, p->drive_group7_F, p->drive_group8_F};
        int moved = 0;
        for (int g = 0; g < DRIVE_GROUPS; g++) {
            double F = Fg[g] > m->F_max ? m->F_max : (Fg[g] < -m->F_max ? -m->F_max : Fg[g]);
            moved |= F != c->st.F_group[g];
            c->st.F_group[g] = F;
        }
        if (moved) {
            for (int k = 0; k < m->track.n_motors; k++) c->st.F_motor[k] = c->st.F_group[m->motor_group[k]];
            changed = 1;
        }
    }
    /* an item port acts when its cart or its mass changed (chain_check_inputs has checked the cart) */
    const int pc[LOAD_PORTS] = {p->load1_cart, p->load2_cart};
    const double pm[LOAD_PORTS] = {p->load1_mass, p->load2_mass};
    for (int k = 0; k < LOAD_PORTS; k++) {
        if (pc[k] == c->st.port[2 * k] && pm[k] == c->st.port[2 * k + 1]) continue;
        c->st.port[2 * k] = pc[k];
        c->st.port[2 * k + 1] = pm[k];
        if (pc[k] >= 0 && pc[k] < m->n_carts) put_item(c, pc[k], pm[k]);
    }
    if (changed) c->st.ode.fsal_valid = c->scratch_at_state = 0;
    m->mu_roll = p->wheel_mu_roll;
    c->st.v_ref = p->drive_v_ref;
    c->st.Kp = p->drive_Kp;
    c->st.Ki = p->drive_Ki;
}

void chain_start_memory(Chain *c) {
    const ChainModel *m = &c->m;
    chain_rhs(c, c->st.ode.t, c->st.y, c->ode.k[0]);
    chain_simd_sync(c);   /* the vector path fills the scalar scratch on demand */
    c->st.ode.n_rhs = 1;
    for (int k = 0; k < N_SLOT * m->n_carts; k++) {
        c->st.v_onset[k] = c->sc.delta[k] > 0 ? m->v_min : 0.0;
        c->st.delta_prev[k] = c->sc.delta[k];
        c->st.ddelta_prev[k] = c->sc.ddelta[k];
    }
    chain_simd_invalidate(c);
    c->st.ode.fsal_valid = 1;
    c->scratch_at_state = 1;
}

/* Snapshot layout: header (solver, inputs in force: the PI's, the groups'
 * thrusts, the item ports as applied, E_items), then y, s_hint, v_onset,
 * delta_prev, ddelta_prev, the FSAL derivative and the item loads
 * and the FSAL derivative, so that a restored run replays bit for bit. */
#define SNAP_HEADER 25

size_t chain_state_size(const Chain *c) {
    return (size_t)SNAP_HEADER + 2 * (size_t)c->m.n_y + (size_t)c->m.n_carts * (2 + 3 * N_SLOT);
}

void chain_state_save(const Chain *c, double *buf) {
    const ChainState *st = &c->st;
    int N = c->m.n_carts, ns = N_SLOT * N;
    const DopriState *o = &st->ode;
    double hdr[SNAP_HEADER] = {(double)c->m.n_y, o->t, o->h, o->err_prev, st->v_ref, st->Kp, st->Ki,
                               (double)o->n_steps, (double)o->n_rejected, (double)o->n_rhs, o->h_last,
                               (double)o->fsal_valid};
    for (int g = 0; g < DRIVE_GROUPS; g++) hdr[12 + g] = st->F_group[g];
    for (int k = 0; k < 2 * LOAD_PORTS; k++) hdr[20 + k] = st->port[k];
    hdr[24] = st->E_items;
    memcpy(buf, hdr, sizeof hdr);
    double *p = buf + SNAP_HEADER;
    memcpy(p, st->y, sizeof(double) * (size_t)c->m.n_y); p += c->m.n_y;
    memcpy(p, st->s_hint, sizeof(double) * (size_t)N); p += N;
    memcpy(p, st->v_onset, sizeof(double) * (size_t)ns); p += ns;
    memcpy(p, st->delta_prev, sizeof(double) * (size_t)ns); p += ns;
    memcpy(p, st->ddelta_prev, sizeof(double) * (size_t)ns); p += ns;
    memcpy(p, c->ode.k[0], sizeof(double) * (size_t)c->m.n_y); p += c->m.n_y;
    memcpy(p, st->load, sizeof(double) * (size_t)N);
}

/* Counters are stored as doubles: whole numbers in [0, 2^53]. */
static int is_count(double x) { return x >= 0 && x <= 9007199254740992.0 && x == floor(x); }

#define BAD(...) do { snprintf(why, len, __VA_ARGS__); return 1; } while (0)

/* Every field of a snapshot of n doubles that may come from bytes handed in
 * by the master (docs/robustness.md, "FMU states"). built: the parameters the
 * chain is built with; t_chain: the chain time the FMU header implies
 * (time - startTime); exact: the chain must be at t_chain (within rounding),
 * otherwise at or after it (a state taken after a discarded step); c: the
 * chain the snapshot is for, or NULL before it exists (the checks that need
 * the track are then left to the second call). 0, or 1 with the reason. */
int chain_state_check(const double *buf, size_t n, const LSSParams *built, double t_chain, int exact,
                      const Chain *c, char *why, size_t len) {
    if (n < SNAP_HEADER + 24 || (n - SNAP_HEADER - 12) % 46 != 0) BAD("chain snapshot of %zu values", n);
    size_t N = (n - SNAP_HEADER - 12) / 46, ny = CART_NY * N + N_GLOBAL, ns = N_SLOT * N;
    if (N < 3 || buf[0] != (double)ny || (c && (size_t)c->m.n_y != ny))
        BAD("chain snapshot: state size %.17g does not match its %zu values", buf[0], n);
    double t = buf[1], h = buf[2], err_prev = buf[3], h_last = buf[10];
    double tol_t = 1e-9 * (fabs(t_chain) + 1.0);
    if (!isfinite(t) || !(t >= 0) || !isfinite(t_chain))
        BAD("solver time t = %.17g s is not a finite time >= 0", t);
    if (exact ? !(fabs(t - t_chain) <= tol_t) : !(t >= t_chain - tol_t))
        BAD("solver time t = %.17g s does not match the FMU's time (%.17g s after the start)", t, t_chain);
    double h_top = 5.0 * fmax(built->solver_h_max, 1e-4) * (1.0 + 1e-9);
    if (!isfinite(h) || !(h > 0) || !(h <= h_top))
        BAD("solver step size h = %.17g s is not in (0, %g] s", h, h_top);
    if (!(h_last >= 0 && h_last <= h_top)) BAD("last step size %.17g s is not in [0, %g] s", h_last, h_top);
    if (!(err_prev >= 1e-4 && err_prev <= 1.0)) BAD("solver error memory %.17g is not in [1e-4, 1]", err_prev);
    if (buf[4] != built->drive_v_ref || buf[5] != built->drive_Kp || buf[6] != built->drive_Ki)
        BAD("inputs in the chain snapshot (v_ref %.17g, Kp %.17g, Ki %.17g) differ from the state's parameters",
            buf[4], buf[5], buf[6]);
    const double Fg[DRIVE_GROUPS] = {built->drive_group1_F, built->drive_group2_F, built->drive_group3_F,
                                     built->drive_group4_F, built->drive_group5_F, built->drive_group6_F,
                                     built->drive_group7_F, built->drive_group8_F};
    for (int g = 0; g < DRIVE_GROUPS; g++) {
        double Fm = built->drive_F_max, F = Fg[g] > Fm ? Fm : (Fg[g] < -Fm ? -Fm : Fg[g]);
        if (buf[12 + g] != (built->drive_mode == DRIVE_EXTERNAL ? F : 0.0))
            BAD("external thrust of group %d in the chain snapshot (%.17g N) differs from the state's parameters",
                g + 1, buf[12 + g]);
    }
    if (!is_count(buf[7]) || !is_count(buf[8]) || !is_count(buf[9]))
        BAD("solver counters %.17g, %.17g, %.17g are not whole numbers in [0, 2^53]", buf[7], buf[8], buf[9]);
    if (buf[11] != 0 && buf[11] != 1) BAD("solver flag %.17g is neither 0 nor 1", buf[11]);
    const double *y = buf + SNAP_HEADER, *s_hint = y + ny, *v_onset = s_hint + N, *rest = v_onset + ns;
    for (size_t i = 0; i < ny; i++)
        if (!isfinite(y[i])) BAD("state value %zu (cart %zu) is %g", i, i / CART_NY, y[i]);
    for (size_t i = 0; i < N; i++) {
        const double *q = y + CART_NY * i + 3;
        double nq = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (!(fabs(nq - 1.0) <= 1e-6)) BAD("cart %zu: orientation quaternion of norm %.17g (not 1)", i, nq);
        double L = c ? c->m.track.length : INFINITY;
        if (!(s_hint[i] >= 0 && s_hint[i] <= L)) BAD("cart %zu: track position %.17g m is not on the track", i, s_hint[i]);
        if (c) {  /* the cart where its track position says: its CG within 1 m of that centreline point */
            TrackFrame f;
            track_frame(&c->m.track, s_hint[i], NULL, &f);
            const double *r = y + CART_NY * i;
            double d = sqrt((r[0] - f.c[0]) * (r[0] - f.c[0]) + (r[1] - f.c[1]) * (r[1] - f.c[1]) +
                            (r[2] - f.c[2]) * (r[2] - f.c[2]));
            if (!(d <= 1.0)) BAD("cart %zu is %.3g m away from the track at its track position %.6g m", i, d, s_hint[i]);
        }
    }
    for (size_t k = 0; k < ns; k++)
        if (!isfinite(v_onset[k]) || !(v_onset[k] == 0 || v_onset[k] >= built->contact_v_min))
            BAD("contact %zu: onset velocity %.17g m/s is neither 0 nor >= contact.v_min", k, v_onset[k]);
    for (size_t k = 0; k < 2 * ns + ny; k++)  /* delta_prev, ddelta_prev and the FSAL derivative */
        if (!isfinite(rest[k])) BAD("contact memory or derivative value %zu is %g", k, rest[k]);
    const double *load = rest + 2 * ns + ny;
    for (size_t i = 0; i < N; i++)
        if (!(load[i] >= 0.0 && load[i] <= 1000.0)) BAD("cart %zu: item mass %.17g kg is not in [0, 1000]", i, load[i]);
    const int pc[LOAD_PORTS] = {built->load1_cart, built->load2_cart};
    const double pm[LOAD_PORTS] = {built->load1_mass, built->load2_mass};
    for (int k = 0; k < LOAD_PORTS; k++)
        if (buf[20 + 2 * k] != pc[k] || buf[21 + 2 * k] != pm[k])
            BAD("item port %d in the chain snapshot (cart %.17g, %.17g kg) differs from the state's parameters", k + 1,
                buf[20 + 2 * k], buf[21 + 2 * k]);
    if (!isfinite(buf[24])) BAD("item energy %g J is not finite", buf[24]);
    return 0;
}
#undef BAD

void chain_state_load(Chain *c, const double *buf) {
    ChainState *st = &c->st;
    int N = c->m.n_carts, ns = N_SLOT * N;
    DopriState *o = &st->ode;
    o->t = buf[1]; o->h = buf[2]; o->err_prev = buf[3];
    st->v_ref = buf[4]; st->Kp = buf[5]; st->Ki = buf[6];
    for (int g = 0; g < DRIVE_GROUPS; g++) st->F_group[g] = buf[12 + g];
    for (int k = 0; k < c->m.track.n_motors; k++) st->F_motor[k] = st->F_group[c->m.motor_group[k]];
    o->n_steps = (long)buf[7]; o->n_rejected = (long)buf[8]; o->n_rhs = (long)buf[9]; o->h_last = buf[10];
    const double *p = buf + SNAP_HEADER;
    memcpy(st->y, p, sizeof(double) * (size_t)c->m.n_y); p += c->m.n_y;
    memcpy(st->s_hint, p, sizeof(double) * (size_t)N); p += N;
    memcpy(st->v_onset, p, sizeof(double) * (size_t)ns); p += ns;
    memcpy(st->delta_prev, p, sizeof(double) * (size_t)ns); p += ns;
    memcpy(st->ddelta_prev, p, sizeof(double) * (size_t)ns); p += ns;
    memcpy(c->ode.k[0], p, sizeof(double) * (size_t)c->m.n_y); p += c->m.n_y;
    memcpy(st->load, p, sizeof(double) * (size_t)N);
    for (int k = 0; k < 2 * LOAD_PORTS; k++) st->port[k] = buf[20 + k];
    st->E_items = buf[24];
    chain_masses(c);
    o->fsal_valid = buf[11] != 0;
    c->scratch_at_state = 0;
    chain_simd_invalidate(c);
}
