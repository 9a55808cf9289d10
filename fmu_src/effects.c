/* The effects catalogue (issue 7): parameter checks, the per-build set-up,
 * the seeded mass spread, the sensor model and the running resistance. The
 * geometric effects sit where their contact is computed (wheels.c, joints.c)
 * and the thrust ripple with the motors (drive.c). */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "rhs_shared.h"
#include "effects.h"

/* The sensor parameters in the order of the force channels. */
static void sensor_params(const LSSParams *p, double *g, double *o) {
    const double gg[FX_N_SENSOR] = {
        p->effects_sensor_gain_joint_F_x, p->effects_sensor_gain_joint_F_y, p->effects_sensor_gain_joint_F_z,
        p->effects_sensor_gain_steering_F_left, p->effects_sensor_gain_steering_F_right,
        p->effects_sensor_gain_driving_F_left, p->effects_sensor_gain_driving_F_right};
    const double oo[FX_N_SENSOR] = {
        p->effects_sensor_offset_joint_F_x, p->effects_sensor_offset_joint_F_y,
        p->effects_sensor_offset_joint_F_z, p->effects_sensor_offset_steering_F_left,
        p->effects_sensor_offset_steering_F_right, p->effects_sensor_offset_driving_F_left,
        p->effects_sensor_offset_driving_F_right};
    memcpy(g, gg, sizeof gg);
    memcpy(o, oo, sizeof oo);
}

int effects_init(Effects *fx, const LSSParams *p, int n_carts, int transducer, double r_drive,
                 double track_length, char *err, size_t errlen) {
    memset(fx, 0, sizeof *fx);
    int cart = p->effects_wheel_oor_cart;
    if (cart >= n_carts) {
        snprintf(err, errlen, "effects.wheel_oor.cart = %d is invalid: the chain has %d carts "
                 "(-1 for the transducer cart, or 0..%d)", cart, n_carts, n_carts - 1);
        return 1;
    }
    if (!(p->effects_track_bump_s < track_length)) {
        snprintf(err, errlen, "effects.track_bump.s = %.17g is invalid: must lie in [0, %.17g), the track length",
                 p->effects_track_bump_s, track_length);
        return 1;
    }
    fx->oor_on = p->effects_wheel_oor_amplitude > 0.0;
    fx->oor_cart = cart < 0 ? transducer : cart;
    fx->oor_k = p->effects_wheel_oor_order;
    fx->oor_a = p->effects_wheel_oor_amplitude;
    fx->oor_phase[0] = p->effects_wheel_oor_phase_left;
    fx->oor_phase[1] = p->effects_wheel_oor_phase_right;
    fx->oor_ir0 = 1.0 / r_drive;
    fx->bump_on = p->effects_track_bump_height != 0.0;
    fx->surface_on = fx->bump_on || fx->oor_on;
    fx->bump_H = p->effects_track_bump_height;
    fx->bump_s = p->effects_track_bump_s;
    fx->bump_half = 0.5 * p->effects_track_bump_length;
    fx->bump_k = FX_TWO_PI / p->effects_track_bump_length;
    fx->gap = p->effects_joint_clearance_gap;
    fx->ripple_on = p->effects_motor_ripple_amplitude > 0.0;
    fx->ripple_A = p->effects_motor_ripple_amplitude;
    fx->ripple_k = FX_TWO_PI / p->effects_motor_ripple_pitch;
    fx->ripple_phase = p->effects_motor_ripple_phase;
    fx->c1 = p->effects_resistance_c1;
    fx->c2 = p->effects_resistance_c2;
    fx->resist_on = fx->c1 > 0.0 || fx->c2 > 0.0;
    sensor_params(p, fx->gain, fx->offset);
    for (int k = 0; k < FX_N_SENSOR; k++)
        if (fx->gain[k] != 0.0 || fx->offset[k] != 0.0) fx->sensor_on = 1;
    fx->mass_on = p->effects_mass_transducer_factor != 1.0 || p->effects_mass_spread > 0.0;
    return 0;
}

/* splitmix64 (Steele, Lea, Flood 2014): a full-period mixer, so (seed, i)
 * gives independent streams without any generator state to carry. */
static uint64_t splitmix64(uint64_t *x) {
    uint64_t z = (*x += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

double effects_normal(int seed, int i) {
    uint64_t x = ((uint64_t)(uint32_t)seed << 32) | (uint64_t)(uint32_t)i;
    double u1 = ((double)(splitmix64(&x) >> 11) + 0.5) * 0x1.0p-53;  /* (0, 1): log is finite */
    double u2 = (double)(splitmix64(&x) >> 11) * 0x1.0p-53;
    return sqrt(-2.0 * log(u1)) * cos(FX_TWO_PI * u2);
}

double effects_mass_factor(const LSSParams *p, int i, int transducer) {
    if (i == transducer) return p->effects_mass_transducer_factor;
    if (!(p->effects_mass_spread > 0.0)) return 1.0;
    double z = effects_normal(p->effects_mass_seed, i);
    z = z > 3.0 ? 3.0 : (z < -3.0 ? -3.0 : z);
    return 1.0 + p->effects_mass_spread * z;
}

void effects_sensor(const Effects *fx, LSSOutputs *o) {
    double *ch[FX_N_SENSOR] = {&o->transducer_joint_F_x, &o->transducer_joint_F_y, &o->transducer_joint_F_z,
                               &o->transducer_steering_F_left, &o->transducer_steering_F_right,
                               &o->transducer_driving_F_left, &o->transducer_driving_F_right};
    for (int k = 0; k < FX_N_SENSOR; k++) *ch[k] = (1.0 + fx->gain[k]) * *ch[k] + fx->offset[k];
}

/* Running resistance of cart i along the track tangent, applied at the axle:
 * the tangential speed v_t is that point's, so the power is exactly
 * -F v_t and the loss goes to energy.W_rolling. */
void effects_resistance(Chain *c, int i, double *p_roll) {
    const ChainModel *m = &c->m;
    CartScratch *cs = &c->sc.cart[i];
    double v = cs->v_t, F = -(m->fx.c1 * v + m->fx.c2 * v * fabs(v));
    double ba[3] = {m->g.x_axle, 0.0, m->g.z_axle}, ra[3], fv[3], tmp[3];
    m3_mulv(ra, cs->R, ba);
    v3_scale(fv, cs->t, F);
    v3_add(cs->F, cs->F, fv);
    v3_cross(tmp, ra, fv);
    v3_add(cs->T, cs->T, tmp);
    *p_roll -= F * v;
}
