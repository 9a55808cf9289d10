/* The plain-text layout format (docs/layouts.md). lss_fmu/layout_format.py
 * implements the same grammar, the same checks in the same order and so names
 * the same line for the same file; tests/test_layout_parser.py holds them to it.
 *
 * Grammar, per line: a '#' starts a comment; tokens are separated by blanks
 * (space, tab, CR, VT, FF); a blank line is skipped; the first token is a
 * keyword. Numbers are decimal ([+-]digits[.digits][e[+-]digits]) and are
 * read independently of the C locale. */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 200809L /* open, fstat, fcntl, fdopen under -std=c11 */
#endif
#include "layout_io.h"

#include <locale.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#if defined(__unix__) || defined(__APPLE__)
#include <fcntl.h>
#include <unistd.h>
#define LSS_POSIX_OPEN 1
#endif
#ifndef S_ISREG /* MSVC has only the mode bits */
#ifdef S_IFMT
#define S_ISREG(m) (((m) & S_IFMT) == S_IFREG)
#define S_ISDIR(m) (((m) & S_IFMT) == S_IFDIR)
#else
#define S_ISREG(m) (((m) & _S_IFMT) == _S_IFREG)
#define S_ISDIR(m) (((m) & _S_IFMT) == _S_IFDIR)
#endif
#endif

#define LAYOUT_MAX_TOKENS 8
#define DEG (3.14159265358979323846 / 180.0)

typedef struct {
    const char *p;
    size_t n;
} Tok;

static int is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }
static int is_digit(char c) { return c >= '0' && c <= '9'; }

static int tok_is(const Tok *t, const char *s) {
    size_t n = strlen(s);
    return t->n == n && memcmp(t->p, s, n) == 0;
}

/* A token for a message: printable ASCII, at most 24 characters. */
static void tok_show(const Tok *t, char *buf, size_t size) {
    size_t k = 0;
    for (size_t i = 0; i < t->n && k + 1 < size; i++) {
        if (i == 24) {
            if (k + 4 < size) { memcpy(buf + k, "...", 3); k += 3; }
            break;
        }
        unsigned char c = (unsigned char)t->p[i];
        buf[k++] = (c >= 0x20 && c < 0x7f) ? (char)c : '?';
    }
    buf[k] = 0;
}

#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static int fail(char *err, size_t errlen, int line, const char *fmt, ...) {
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (err && errlen) snprintf(err, errlen, "line %d: %s", line, msg);
    return 1;
}

/* Decimal number syntax check, then a locale-independent strtod. */
static int tok_number(const Tok *t, double *v) {
    size_t i = 0, n = t->n;
    if (n == 0 || n > LAYOUT_MAX_NUMBER_CHARS) return 0;
    if (t->p[i] == '+' || t->p[i] == '-') i++;
    size_t d0 = i;
    while (i < n && is_digit(t->p[i])) i++;
    size_t nd = i - d0;
    if (i < n && t->p[i] == '.') {
        i++;
        size_t f0 = i;
        while (i < n && is_digit(t->p[i])) i++;
        nd += i - f0;
    }
    if (nd == 0) return 0;
    if (i < n && (t->p[i] == 'e' || t->p[i] == 'E')) {
        i++;
        if (i < n && (t->p[i] == '+' || t->p[i] == '-')) i++;
        size_t e0 = i;
        while (i < n && is_digit(t->p[i])) i++;
        if (i == e0) return 0;
    }
    if (i != n) return 0;
    char buf[LAYOUT_MAX_NUMBER_CHARS + 1];
    memcpy(buf, t->p, n);
    buf[n] = 0;
    const struct lconv *lc = localeconv();
    char point = (lc && lc->decimal_point && lc->decimal_point[0]) ? lc->decimal_point[0] : '.';
    if (point != '.') {
        char *dot = strchr(buf, '.');
        if (dot) *dot = point;
    }
    *v = strtod(buf, NULL);
    return 1;
}

/* A number with a range check: kind 0 any finite, 1 positive (> 0, <= max). */
static int get_number(const Tok *t, int line, const char *what, int positive, double max,
                      double *v, char *err, size_t errlen) {
    char show[32], lim[64];
    tok_show(t, show, sizeof show);
    if (!tok_number(t, v)) return fail(err, errlen, line, "%s: '%s' is not a number", what, show);
    if (!isfinite(*v)) return fail(err, errlen, line, "%s: '%s' is not finite", what, show);
    if (positive && !(*v > 0)) return fail(err, errlen, line, "%s must be positive, got %s", what, show);
    if (max > 0 && !(fabs(*v) <= max)) {
        snprintf(lim, sizeof lim, "%g", max);
        return fail(err, errlen, line, "%s is too large: %s (limit %s)", what, show, lim);
    }
    return 0;
}

static int get_int(const Tok *t, int line, const char *what, int lo, int hi, int *v,
                   char *err, size_t errlen) {
    char show[32], lim[64];
    tok_show(t, show, sizeof show);
    size_t i = (t->n > 0 && t->p[0] == '+') ? 1 : 0;
    if (i == t->n || t->n - i > 9) return fail(err, errlen, line, "%s: '%s' is not a whole number", what, show);
    long x = 0;
    for (; i < t->n; i++) {
        if (!is_digit(t->p[i])) return fail(err, errlen, line, "%s: '%s' is not a whole number", what, show);
        x = 10 * x + (t->p[i] - '0');
    }
    if (x < lo || x > hi) {
        snprintf(lim, sizeof lim, "%d to %d", lo, hi);
        return fail(err, errlen, line, "%s must be %s, got %s", what, lim, show);
    }
    *v = (int)x;
    return 0;
}

static int count_lines(const char *text, size_t len) {
    int line = 1;
    for (size_t i = 0; i < len; i++)
        if (text[i] == '\n') line++;
    return line;
}

enum { H_NAME, H_WHEEL, H_COUPLING, H_MOTORS, H_CARTS, H_START, H_MASS, H_N };
static const char *const HEADER_KEYS[H_N] = {"name", "wheel", "coupling", "motors", "carts", "start", "mass"};
static const int HEADER_NVAL[H_N] = {1, 1, 1, 1, 1, 4, 1};
static const char *const HEADER_USAGE[H_N] = {
    "name NAME", "wheel A|B|C", "coupling A|B", "motors N", "carts N", "start X Y Z HEADING_DEG", "mass KG"};

static int grow(LayoutSpec *out, int *cap, const LSSAlloc *a) {
    int ncap = *cap ? 2 * *cap : 64;
    if (ncap > LAYOUT_MAX_ELEMENTS) ncap = LAYOUT_MAX_ELEMENTS;
    ElementSpec *el = a->calloc((size_t)ncap, sizeof(ElementSpec));
    if (!el) return 1;
    if (out->el) {
        memcpy(el, out->el, (size_t)out->n_el * sizeof(ElementSpec));
        a->free(out->el);
    }
    out->el = el;
    *cap = ncap;
    return 0;
}

static int parse_element(const Tok *tk, int nt, int line, ElementSpec *e, char *err, size_t errlen) {
    char show[32], kw[16];
    tok_show(&tk[0], kw, sizeof kw);
    int nval = nt - 1;
    e->line = line;
    if (tok_is(&tk[0], "straight")) {
        e->kind = EL_STRAIGHT;
        if (nval != 1) {
            snprintf(show, sizeof show, "%d", nval);
            return fail(err, errlen, line, "'straight LENGTH' takes 1 value, got %s", show);
        }
        return get_number(&tk[1], line, "straight length", 1, LAYOUT_MAX_SIZE_M, &e->length, err, errlen);
    }
    int spiral = tok_is(&tk[0], "spiral"), vertical = tok_is(&tk[0], "vcurve");
    e->kind = spiral ? EL_SPIRAL : vertical ? EL_VCURVE : EL_CURVE;
    const char *usage = spiral ? "'spiral RADIUS SWEEP_DEG left|right [RISE]'"
                        : vertical ? "'vcurve RADIUS ANGLE_DEG up|down'"
                                   : "'curve RADIUS SWEEP_DEG left|right'";
    if (!(nval == 3 || (spiral && nval == 4))) {
        snprintf(show, sizeof show, "%d", nval);
        return fail(err, errlen, line, spiral ? "%s takes 3 or 4 values, got %s" : "%s takes 3 values, got %s",
                    usage, show);
    }
    char what[48];
    snprintf(what, sizeof what, "%s radius", kw);
    if (get_number(&tk[1], line, what, 1, LAYOUT_MAX_SIZE_M, &e->radius, err, errlen)) return 1;
    double deg;
    snprintf(what, sizeof what, "%s %s", kw, vertical ? "angle" : "sweep");
    if (get_number(&tk[2], line, what, 1, LAYOUT_MAX_ANGLE_DEG, &deg, err, errlen)) return 1;
    double sign;
    if (vertical && tok_is(&tk[3], "up")) sign = 1;
    else if (vertical && tok_is(&tk[3], "down")) sign = -1;
    else if (!vertical && tok_is(&tk[3], "left")) sign = 1;
    else if (!vertical && tok_is(&tk[3], "right")) sign = -1;
    else {
        tok_show(&tk[3], show, sizeof show);
        return fail(err, errlen, line, vertical ? "vcurve direction must be 'up' or 'down', got '%s'"
                                                : "%s direction must be 'left' or 'right', got '%s'",
                    vertical ? show : kw, show);
    }
    e->angle = sign * (deg * DEG);
    if (spiral && nval == 4) {
        if (get_number(&tk[4], line, "spiral rise", 0, LAYOUT_MAX_SIZE_M, &e->rise, err, errlen)) return 1;
        e->has_rise = 1;
    }
    return 0;
}

static int parse_header(int key, const Tok *tk, int nt, int line, LayoutSpec *out, char *err, size_t errlen) {
    char show[32];
    if (nt - 1 != HEADER_NVAL[key]) {
        char usage[64];
        snprintf(usage, sizeof usage, "'%s' takes %d value%s", HEADER_USAGE[key], HEADER_NVAL[key],
                 HEADER_NVAL[key] > 1 ? "s" : "");
        snprintf(show, sizeof show, "%d", nt - 1);
        return fail(err, errlen, line, "%s, got %s", usage, show);
    }
    const Tok *v = &tk[1];
    tok_show(v, show, sizeof show);
    switch (key) {
    case H_NAME: {
        int ok = v->n >= 1 && v->n < sizeof out->name;
        for (size_t i = 0; ok && i < v->n; i++) {
            char c = v->p[i];
            ok = is_digit(c) || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' || c == '.' ||
                 c == '-' || c == '+';
        }
        if (!ok)
            return fail(err, errlen, line, "name '%s' must be 1 to 63 of the characters A-Z a-z 0-9 _ . - +",
                        show);
        memcpy(out->name, v->p, v->n);
        out->name[v->n] = 0;
        return 0;
    }
    case H_WHEEL:
        if (v->n == 1 && (v->p[0] == 'A' || v->p[0] == 'B' || v->p[0] == 'C')) {
            out->wheel = v->p[0];
            return 0;
        }
        return fail(err, errlen, line, "wheel type must be A, B or C, got '%s'", show);
    case H_COUPLING:
        if (v->n == 1 && (v->p[0] == 'A' || v->p[0] == 'B')) {
            out->coupling = v->p[0];
            return 0;
        }
        return fail(err, errlen, line, "coupling type must be A or B, got '%s'", show);
    case H_MOTORS:
        return get_int(v, line, "motors", 0, LAYOUT_MAX_MOTORS, &out->n_motors, err, errlen);
    case H_CARTS:
        return get_int(v, line, "carts", LAYOUT_MIN_CARTS, LAYOUT_MAX_CARTS, &out->n_carts, err, errlen);
    case H_START: {
        static const char *const what[3] = {"start x", "start y", "start z"};
        for (int i = 0; i < 3; i++)
            if (get_number(&tk[1 + i], line, what[i], 0, LAYOUT_MAX_SIZE_M, &out->start[i], err, errlen)) return 1;
        double h;
        if (get_number(&tk[4], line, "start heading", 0, LAYOUT_MAX_ANGLE_DEG, &h, err, errlen)) return 1;
        out->heading = h * DEG;
        return 0;
    }
    case H_MASS:
        return get_number(v, line, "mass", 1, LAYOUT_MAX_MASS, &out->cart_mass, err, errlen);
    }
    return 1;
}

int layout_parse(const char *text, size_t len, LayoutSpec *out, const LSSAlloc *a, char *err, size_t errlen) {
    memset(out, 0, sizeof(*out));
    if (err && errlen) err[0] = 0;
    if (!text) {
        text = "";
        len = 0;
    }
    if (len > LAYOUT_MAX_BYTES)
        return fail(err, errlen, count_lines(text, LAYOUT_MAX_BYTES),
                    "the layout is larger than 1 MiB (1048576 bytes); is this a layout file?");
    int seen[H_N] = {0};
    int cap = 0, line = 0;
    size_t pos = 0;
    while (pos <= len) {
        line++;
        size_t end = pos;
        while (end < len && text[end] != '\n') end++;
        if (memchr(text + pos, 0, end - pos)) {
            layout_spec_free(out, a);
            return fail(err, errlen, line, "NUL byte in the layout (a binary file?)");
        }
        const char *hash = memchr(text + pos, '#', end - pos);
        size_t stop = hash ? (size_t)(hash - text) : end;
        Tok tk[LAYOUT_MAX_TOKENS + 1];
        int nt = 0;
        for (size_t i = pos; i < stop;) {
            while (i < stop && is_blank(text[i])) i++;
            if (i >= stop) break;
            size_t j = i;
            while (j < stop && !is_blank(text[j])) j++;
            if (nt <= LAYOUT_MAX_TOKENS) {
                tk[nt].p = text + i;
                tk[nt].n = j - i;
            }
            nt++;
            i = j;
        }
        pos = end + 1;
        if (nt == 0) continue;
        char show[32];
        /* nt may exceed the stored tokens: the value-count checks come first */
        int key = -1;
        for (int k = 0; k < H_N; k++)
            if (tok_is(&tk[0], HEADER_KEYS[k])) key = k;
        if (key >= 0) {
            if (seen[key]) {
                char first[16];
                snprintf(first, sizeof first, "%d", seen[key]);
                layout_spec_free(out, a);
                return fail(err, errlen, line, "duplicate '%s' (first given on line %s)", HEADER_KEYS[key], first);
            }
            seen[key] = line;
            if (parse_header(key, tk, nt, line, out, err, errlen)) {
                layout_spec_free(out, a);
                return 1;
            }
            continue;
        }
        if (tok_is(&tk[0], "straight") || tok_is(&tk[0], "curve") || tok_is(&tk[0], "vcurve") ||
            tok_is(&tk[0], "spiral")) {
            if (out->n_el >= LAYOUT_MAX_ELEMENTS) {
                layout_spec_free(out, a);
                return fail(err, errlen, line, "too many track elements (limit 10000)");
            }
            if (out->n_el >= cap && grow(out, &cap, a)) {
                layout_spec_free(out, a);
                return fail(err, errlen, line, "out of memory");
            }
            ElementSpec *e = &out->el[out->n_el];
            memset(e, 0, sizeof(*e));
            if (parse_element(tk, nt, line, e, err, errlen)) {
                layout_spec_free(out, a);
                return 1;
            }
            out->n_el++;
            continue;
        }
        tok_show(&tk[0], show, sizeof show);
        layout_spec_free(out, a);
        return fail(err, errlen, line,
                    "unknown keyword '%s' (expected straight, curve, vcurve, spiral, name, wheel, coupling, "
                    "motors, carts, start or mass)", show);
    }
    if (out->n_el == 0) {
        layout_spec_free(out, a);
        return fail(err, errlen, line, "end of file: the layout has no track elements");
    }
    static const int required[3] = {H_WHEEL, H_COUPLING, H_MOTORS};
    for (int r = 0; r < 3; r++)
        if (!seen[required[r]]) {
            layout_spec_free(out, a);
            return fail(err, errlen, line, "end of file: the header lacks '%s'", HEADER_USAGE[required[r]]);
        }
    return 0;
}

/* Opens path for reading only if it is a regular file: a FIFO, a device or a
 * directory is refused without blocking (POSIX: opened with O_NONBLOCK, then
 * fstat on the open file, so the check and the read see the same file). NULL
 * with a message otherwise; *size is the size the file claims. */
static FILE *open_regular(const char *path, size_t *size, char *err, size_t errlen) {
    const char *why = NULL;
#ifdef LSS_POSIX_OPEN
    int fd = open(path, O_RDONLY | O_NONBLOCK);
    if (fd < 0) {
        if (err && errlen) snprintf(err, errlen, "%s: cannot open the layout file", path);
        return NULL;
    }
    struct stat st;
    if (fstat(fd, &st) != 0) why = "cannot read its file status";
    else if (S_ISDIR(st.st_mode)) why = "is a directory, not a layout file";
    else if (!S_ISREG(st.st_mode)) why = "is not a regular file (a FIFO, device or socket is not read)";
    else {
        int fl = fcntl(fd, F_GETFL);  /* a regular file: blocking reads as usual */
        if (fl != -1) fcntl(fd, F_SETFL, fl & ~O_NONBLOCK);
    }
    FILE *f = why ? NULL : fdopen(fd, "rb");
    if (!f) {
        close(fd);
        if (!why) why = "cannot open the layout file";
        if (err && errlen) snprintf(err, errlen, "%s: %s", path, why);
        return NULL;
    }
#else  /* elsewhere: the file's type and size by name, then fopen */
    struct stat st;
    FILE *f = NULL;
    if (stat(path, &st) != 0) why = "cannot open the layout file";
    else if (S_ISDIR(st.st_mode)) why = "is a directory, not a layout file";
    else if (!S_ISREG(st.st_mode)) why = "is not a regular file";
    else if (!(f = fopen(path, "rb"))) why = "cannot open the layout file";
    if (why) {
        if (err && errlen) snprintf(err, errlen, "%s: %s", path, why);
        return NULL;
    }
#endif
    *size = st.st_size > 0 ? (size_t)st.st_size : 0;
    return f;
}

int layout_read_file(const char *path, LayoutSpec *out, const LSSAlloc *a, char *err, size_t errlen) {
    memset(out, 0, sizeof(*out));
    if (err && errlen) err[0] = 0;
    if (!path) {
        if (err && errlen) snprintf(err, errlen, "(null): cannot open the layout file");
        return 1;
    }
    size_t claimed = 0;
    FILE *f = open_regular(path, &claimed, err, errlen);
    if (!f) return 1;
    /* one byte more than the file claims: a file that grew (or a /proc file of
       size 0) is noticed; never more than one byte past the 1 MiB limit, which
       layout_parse then reports with the line it reached */
    size_t cap = (claimed > LAYOUT_MAX_BYTES ? LAYOUT_MAX_BYTES : claimed) + 1;
    char *buf = a->calloc(cap + 1, 1);
    if (!buf) {
        fclose(f);
        if (err && errlen) snprintf(err, errlen, "%s: out of memory reading the layout", path);
        return 1;
    }
    size_t n = fread(buf, 1, cap, f);
    int bad = ferror(f);
    fclose(f);
    if (bad || (claimed <= LAYOUT_MAX_BYTES && n > claimed)) {
        a->free(buf);
        if (err && errlen)
            snprintf(err, errlen, bad ? "%s: read error" : "%s: the file is longer than its size says "
                     "(it changed while being read, or is not an ordinary file)", path);
        return 1;
    }
    char msg[512];
    int rc = layout_parse(buf, n, out, a, msg, sizeof msg);
    a->free(buf);
    if (rc) {
        if (err && errlen) snprintf(err, errlen, "%s: %s", path, msg);
        return rc;
    }
    if (!out->name[0]) {
        /* default name: the file name without directory and extension */
        const char *base = path;
        for (const char *p = path; *p; p++)
            if (*p == '/' || *p == '\\') base = p + 1;
        size_t k = strlen(base);
        const char *dot = strrchr(base, '.');
        if (dot && dot != base) k = (size_t)(dot - base);
        if (k >= sizeof out->name) k = sizeof out->name - 1;
        memcpy(out->name, base, k);
        out->name[k] = 0;
    }
    return 0;
}

int layout_check_chain(const LayoutSpec *spec, double length, int *n_carts, char *err, size_t errlen) {
    double n = spec->n_carts > 0 ? (double)spec->n_carts : floor(length / LAYOUT_NOMINAL_PITCH + 0.5);
    char derived[96] = "";
    if (spec->n_carts <= 0)
        snprintf(derived, sizeof derived, " (the %.6g m track at one cart per %g m)", length, LAYOUT_NOMINAL_PITCH);
    if (!(n >= LAYOUT_MIN_CARTS && n <= LAYOUT_MAX_CARTS)) {
        if (err && errlen)
            snprintf(err, errlen, "a chain of %.0f carts is not supported (%d to %d)%s", isfinite(n) ? n : -1.0,
                     LAYOUT_MIN_CARTS, LAYOUT_MAX_CARTS, derived);
        return 1;
    }
    double pitch = length / n;
    if (!(pitch >= LAYOUT_MIN_PITCH && pitch <= LAYOUT_MAX_PITCH)) {
        if (err && errlen)
            snprintf(err, errlen, "%.0f carts on the %.6g m track make a pitch of %.6g m; it must lie in "
                     "[%g, %g] m", n, length, pitch, LAYOUT_MIN_PITCH, LAYOUT_MAX_PITCH);
        return 1;
    }
    for (int i = 0; i < spec->n_el; i++) {
        const ElementSpec *e = &spec->el[i];
        if (e->kind != EL_STRAIGHT && !(e->radius >= pitch)) {
            if (err && errlen)
                snprintf(err, errlen, "line %d: %s radius %.6g m is smaller than the cart pitch %.6g m "
                         "(%.0f carts on %.6g m): the chain cannot follow it", e->line,
                         e->kind == EL_VCURVE ? "vcurve" : e->kind == EL_SPIRAL ? "spiral" : "curve", e->radius,
                         pitch, n, length);
            return 1;
        }
    }
    if (n_carts) *n_carts = (int)n;
    return 0;
}

void layout_spec_free(LayoutSpec *spec, const LSSAlloc *a) {
    if (spec->el) a->free(spec->el);
    spec->el = NULL;
    spec->n_el = 0;
}
