/* The plain-text layout format (docs/layouts.md): one keyword per line, header
 * keys first, then one track element per line. Parsed without allocation
 * beyond the element list, with "line N: ..." messages on any error. */
#ifndef LSS_LAYOUT_IO_H
#define LSS_LAYOUT_IO_H

#include <stddef.h>
#include "lss_alloc.h"

/* The layout rules, one place on the C side (lss_fmu/layout_format.py has the
 * same numbers; docs/layouts.md states them). */
#define LAYOUT_MAX_BYTES 1048576        /* file size */
#define LAYOUT_MAX_ELEMENTS 10000
#define LAYOUT_MAX_NUMBER_CHARS 64
#define LAYOUT_MAX_SIZE_M 10000.0       /* lengths, radii, rise, |start x, y, z| */
#define LAYOUT_MAX_ANGLE_DEG 3600.0     /* sweeps, angles, |start heading| */
#define LAYOUT_MAX_MOTORS 10000
#define LAYOUT_MIN_CARTS 3
#define LAYOUT_MAX_CARTS 100000
#define LAYOUT_MAX_MASS 10000.0
#define LAYOUT_NOMINAL_PITCH 1.25       /* carts = round(length / 1.25 m) unless given */
#define LAYOUT_MIN_PITCH 0.5            /* track length per cart, m */
#define LAYOUT_MAX_PITCH 5.0

typedef enum { EL_STRAIGHT = 1, EL_CURVE = 2, EL_VCURVE = 3, EL_SPIRAL = 4 } ElementKind;

typedef struct {
    ElementKind kind;
    double length;   /* straight: m */
    double radius;   /* curve, vcurve, spiral: m (> 0); horizontal radius for curve/spiral */
    double angle;    /* rad, signed: curve/spiral + = left turn; vcurve + = up */
    double rise;     /* spiral: expected rise in m, checked when has_rise */
    int has_rise;
    int line;        /* line in the layout file, 0 if built in code */
} ElementSpec;

typedef struct {
    char name[64];
    char wheel;        /* 'A', 'B' or 'C' */
    char coupling;     /* 'A' or 'B' */
    int n_motors;
    int n_carts;       /* 0: round(track length / 1.25 m) */
    double start[3];   /* m */
    double heading;    /* rad, about +z from +x */
    double cart_mass;  /* kg, 0: from the wheel/coupling type */
    int n_el;
    ElementSpec *el;
} LayoutSpec;

/* 0 on success; otherwise non-zero with a message "line N: ..." in err. */
int layout_parse(const char *text, size_t len, LayoutSpec *out, const LSSAlloc *a,
                 char *err, size_t errlen);
int layout_read_file(const char *path, LayoutSpec *out, const LSSAlloc *a,
                     char *err, size_t errlen);
/* The rules that need the built track's length: the number of carts (given,
 * or round(length / 1.25 m)) in [3, 100000], the pitch length / carts in
 * [0.5, 5] m, no curve radius below the pitch. 0 with *n_carts (may be NULL),
 * or 1 with a message. */
int layout_check_chain(const LayoutSpec *spec, double length, int *n_carts, char *err, size_t errlen);
void layout_spec_free(LayoutSpec *spec, const LSSAlloc *a);

#endif
