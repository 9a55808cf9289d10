/* Cart configurations by wheel type (A, B, C) and coupling type (A, B).
 *
 * The paper's stiffness curves (its Fig. 5 and 6) are not available; these are
 * Hertz-type fits F = K d^n chosen so that a driving wheel sinks a few tenths
 * of a millimetre under its static load (polyurethane tyres on 90-100 mm
 * wheels) and a spherical plain bearing deflects about a tenth of a millimetre
 * at a kilonewton. docs/model.md lists them with the resulting deflections. */
#include <string.h>

#include "chain.h"

int cart_type_lookup(char wheel, char coupling, CartType *t) {
    memset(t, 0, sizeof(*t));
    t->wheel = wheel;
    t->coupling = coupling;
    switch (wheel) {
    case 'A':  /* standard polyurethane wheels, medium carrier */
        t->mass = 45.0;
        t->r_drive = 0.050; t->K_drive = 5.6e7; t->n_drive = 1.5;
        t->r_steer = 0.040; t->K_steer = 4.0e7; t->n_steer = 1.5;
        break;
    case 'B':  /* harder wheels, heavy carrier of long sorters */
        t->mass = 55.0;
        t->r_drive = 0.050; t->K_drive = 9.0e7; t->n_drive = 1.5;
        t->r_steer = 0.040; t->K_steer = 6.0e7; t->n_steer = 1.5;
        break;
    case 'C':  /* soft wheels, light carrier of compact sorters */
        t->mass = 38.0;
        t->r_drive = 0.045; t->K_drive = 3.5e7; t->n_drive = 1.5;
        t->r_steer = 0.035; t->K_steer = 2.5e7; t->n_steer = 1.5;
        break;
    default:
        return 0;
    }
    switch (coupling) {
    case 'A':  /* spherical plain bearing with polymer liner */
        t->K_axial = 6.0e8; t->n_axial = 1.5;
        t->K_radial = 4.0e8; t->n_radial = 1.5;
        break;
    case 'B':  /* steel-on-steel spherical plain bearing */
        t->K_axial = 1.2e9; t->n_axial = 1.5;
        t->K_radial = 8.0e8; t->n_radial = 1.5;
        break;
    default:
        return 0;
    }
    return 1;
}

void cart_geometry_init(CartGeometry *g, const CartType *t, double pitch, double guide_gap,
                        double mass_factor) {
    memset(g, 0, sizeof(*g));
    g->mass = t->mass * mass_factor;
    /* a 1.2 x 0.6 x 0.35 m box of uniform density */
    const double lx = 1.2, ly = 0.6, lz = 0.35;
    g->inertia[0] = g->mass * (ly * ly + lz * lz) / 12.0;
    g->inertia[1] = g->mass * (lx * lx + lz * lz) / 12.0;
    g->inertia[2] = g->mass * (lx * lx + ly * ly) / 12.0;
    g->pitch = pitch;
    /* wheels near the front joint: each cart rests on its own axle and, at
     * the rear, on the front joint of the cart behind it */
    g->x_axle = 0.40;
    g->z_axle = -0.10;
    g->z_joint = -0.05;
    g->r_drive = t->r_drive;
    g->y_drive = 0.22;
    g->r_steer = t->r_steer;
    g->y_steer = 0.10;
    g->z_steer = -0.18;
    g->guide_half = g->y_steer + g->r_steer + guide_gap;
    g->x_motor = 0.0;
    g->z_motor = -0.22;
    g->plate_length = pitch;  /* plates tile the chain: no thrust ripple */
}
