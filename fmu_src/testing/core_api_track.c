/* Flat track API for tests and tools (fmu_src/core_api.h, "track geometry"):
 * a layout parsed by layout_io.c and built by track.c behind a handle. */
#include <stdlib.h>
#include <string.h>

#include "core_api.h"
#include "layout_io.h"
#include "track.h"

typedef struct {
    LayoutSpec spec;
    Track track;
} TrackHandle;

static const LSSAlloc STD_ALLOC = {calloc, free};

static size_t errsize(int errlen) { return errlen > 0 ? (size_t)errlen : 0; }

static void *finish_open(TrackHandle *h, int rc, double motor_length, double tol_pos, double tol_ang,
                         char *err, int errlen) {
    if (rc) {
        free(h);
        return NULL;
    }
    char msg[512];
    if (track_build(&h->spec, motor_length, tol_pos, tol_ang, &h->track, &STD_ALLOC, msg, sizeof msg)) {
        if (err && errlen > 0) {
            /* keep a path prefix out: the caller knows which file it opened */
            strncpy(err, msg, errsize(errlen) - 1);
            err[errlen - 1] = 0;
        }
        track_free(&h->track, &STD_ALLOC);
        layout_spec_free(&h->spec, &STD_ALLOC);
        free(h);
        return NULL;
    }
    return h;
}

void *lss_track_open(const char *path, double motor_length, double tol_pos, double tol_ang, char *err,
                     int errlen) {
    TrackHandle *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    int rc = layout_read_file(path, &h->spec, &STD_ALLOC, err, errsize(errlen));
    return finish_open(h, rc, motor_length, tol_pos, tol_ang, err, errlen);
}

void *lss_track_open_text(const char *text, int len, double motor_length, double tol_pos, double tol_ang,
                          char *err, int errlen) {
    TrackHandle *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    int rc = layout_parse(text, len > 0 ? (size_t)len : 0, &h->spec, &STD_ALLOC, err, errsize(errlen));
    return finish_open(h, rc, motor_length, tol_pos, tol_ang, err, errlen);
}

int lss_layout_check_text(const char *text, int len, int *n_el, char *err, int errlen) {
    LayoutSpec spec;
    int rc = layout_parse(text, len > 0 ? (size_t)len : 0, &spec, &STD_ALLOC, err, errsize(errlen));
    if (n_el) *n_el = rc ? 0 : spec.n_el;
    layout_spec_free(&spec, &STD_ALLOC);
    return rc;
}

int lss_layout_rules_text(const char *text, int len, double motor_length, int *n_carts, char *err, int errlen) {
    LayoutSpec spec;
    Track track;
    char msg[512];
    *n_carts = 0;
    if (layout_parse(text, len > 0 ? (size_t)len : 0, &spec, &STD_ALLOC, err, errsize(errlen))) return 1;
    /* as chain_create: the FMU's closure limits, then the rules that need the length */
    int rc = track_build(&spec, motor_length, 1e-3, 1e-4, &track, &STD_ALLOC, msg, sizeof msg) ||
             layout_check_chain(&spec, track.length, n_carts, msg, sizeof msg);
    if (rc && err && errlen > 0) {
        strncpy(err, msg, errsize(errlen) - 1);
        err[errlen - 1] = 0;
    }
    track_free(&track, &STD_ALLOC);
    layout_spec_free(&spec, &STD_ALLOC);
    return rc;
}

void lss_track_close(void *h) {
    TrackHandle *t = h;
    if (!t) return;
    track_free(&t->track, &STD_ALLOC);
    layout_spec_free(&t->spec, &STD_ALLOC);
    free(t);
}

double lss_track_length(void *h) { return ((TrackHandle *)h)->track.length; }

static void eval_one(const Track *t, double s, int *hint, double *out) {
    TrackFrame f;
    track_frame(t, s, hint, &f);
    memcpy(out, f.c, 3 * sizeof(double));
    memcpy(out + 3, f.R, 9 * sizeof(double));
    memcpy(out + 12, f.w, 3 * sizeof(double));
}

void lss_track_eval(void *h, double s, double *out15) {
    eval_one(&((TrackHandle *)h)->track, s, NULL, out15);
}

void lss_track_eval_many(void *h, const double *s, int n, double *out15n) {
    int hint = 0;
    for (int i = 0; i < n; i++) eval_one(&((TrackHandle *)h)->track, s[i], &hint, out15n + 15 * (size_t)i);
}

void lss_track_closure(void *h, double *out4) {
    const Track *t = &((TrackHandle *)h)->track;
    memcpy(out4, t->closure, 3 * sizeof(double));
    out4[3] = t->closure_angle;
}

int lss_track_n_motors(void *h) { return ((TrackHandle *)h)->track.n_motors; }

void lss_track_motor(void *h, int k, double *s0s1) {
    const Track *t = &((TrackHandle *)h)->track;
    if (k < 0 || k >= t->n_motors) {
        s0s1[0] = s0s1[1] = 0;
        return;
    }
    s0s1[0] = t->motor_s0[k];
    s0s1[1] = t->motor_s1[k];
}

int lss_track_n_elements(void *h) { return ((TrackHandle *)h)->track.n; }

void lss_track_element(void *h, int i, int *kind_line, double *s0_len) {
    const Track *t = &((TrackHandle *)h)->track;
    if (i < 0 || i >= t->n) {
        kind_line[0] = kind_line[1] = 0;
        s0_len[0] = s0_len[1] = 0;
        return;
    }
    kind_line[0] = (int)t->el[i].kind;
    kind_line[1] = t->el[i].line;
    s0_len[0] = t->el[i].s0;
    s0_len[1] = t->el[i].length;
}

void lss_track_header(void *h, char *name, int namelen, int *ints4, double *dbls5) {
    const LayoutSpec *sp = &((TrackHandle *)h)->spec;
    if (name && namelen > 0) {
        strncpy(name, sp->name, (size_t)namelen - 1);
        name[namelen - 1] = 0;
    }
    ints4[0] = sp->wheel;
    ints4[1] = sp->coupling;
    ints4[2] = sp->n_motors;
    ints4[3] = sp->n_carts;
    memcpy(dbls5, sp->start, 3 * sizeof(double));
    dbls5[3] = sp->heading;
    dbls5[4] = sp->cart_mass;
}
