/* The chain's model and state types: the immutable model (built once from
 * the parameters) and the mutable state (everything a step changes, so that
 * copying the state is what fmi2GetFMUstate needs), with the scratch of the
 * latest right-hand side. Types only: the functions are in chain.h and
 * rhs_shared.h.
 *
 * State vector y: per cart i, at 13*i: r[3] (CG, world), q[4] (orientation
 * quaternion w,x,y,z, body->world), v[3] (world), w[3] (body angular rate);
 * then the globals at 13*N: PI integrator, motor work, damping loss,
 * rolling loss, and the distances rolled by the out-of-round wheels (left,
 * right; constant 0 when that effect is off). Body frame: x forward, y left,
 * z up, origin at the CG.
 * Cart i+1 runs ahead of cart i; cart i's front joint meets cart i+1's rear
 * joint, and cart N-1's front joint meets cart 0's rear joint. */
#ifndef LSS_CHAIN_MODEL_H
#define LSS_CHAIN_MODEL_H

#include <stddef.h>

#include "contact.h"
#include "dopri5.h"
#include "effects.h"
#include "lss_alloc.h"
#include "lss_vars.h"
#include "track.h"
#include "track_local.h"

#define CART_NY 13
#define G_INT 0     /* PI integrator, m */
#define G_WMOT 1    /* motor work, J */
#define G_WDAMP 2   /* hysteresis loss, J */
#define G_WROLL 3   /* rolling loss, J */
#define G_ROLL_L 4  /* distance rolled by the out-of-round left driving wheel, m */
#define G_ROLL_R 5  /* the same, right */
#define N_GLOBAL 6

#define DRIVE_GROUPS 8   /* motor groups a plant model can drive: drive.group1.F .. (lss_fmu.variables.N_GROUPS) */
enum { DRIVE_INTERNAL = 0, DRIVE_EXTERNAL = 1 };
enum { STATION_INDUCTION = 0, STATION_CHUTE, N_STATION };
#define LOAD_PORTS 2     /* item ports load1.*, load2.* (lss_fmu.variables.N_LOAD_PORTS) */

enum { CC_JA = 0, CC_JR, CC_SW, CC_RW, CC_N };          /* contact classes */
enum { W_SL = 0, W_SR, W_DL, W_DR, N_WHEEL };          /* wheels of one cart */
/* Contact slots per cart: 0 joint axial, 1 joint radial (of its front joint),
 * 2..5 the wheels in W_* order. */
#define SLOT_JA 0
#define SLOT_JR 1
#define SLOT_WHEEL 2
#define N_SLOT 6

typedef struct {
    double mass, inertia[3];          /* kg, principal moments kg m^2 (body axes) */
    double pitch;                     /* unstretched joint-to-joint length, m */
    double x_axle, z_axle;            /* wheel axle position (body), m */
    double z_joint;                   /* height of both joints (body), m */
    double y_drive, r_drive;          /* driving wheels: lateral offset, radius */
    double y_steer, z_steer, r_steer; /* steering wheels: lateral offset, height, radius */
    double guide_half;                /* lateral position of each guide face (track frame), m */
    double x_motor, z_motor;          /* motor reaction point (body), m */
    double plate_length;              /* length of the motor reaction plate, m */
} CartGeometry;

typedef struct {
    char wheel, coupling;
    double mass;                      /* kg */
    double K_drive, n_drive, K_steer, n_steer, r_drive, r_steer;
    double K_axial, n_axial, K_radial, n_radial;
} CartType;

/* Fixed once built, but for the tunable parameters (the CoRs in law[], mu_roll)
 * that chain_set_inputs adopts. */
typedef struct ChainModel {
    LSSAlloc alloc;
    Track track;
    char layout_name[64];
    int n_carts, transducer, n_y;
    CartGeometry g;
    CartType type;
    ContactLaw law[CC_N];
    int law_code;
    double v_min, mu_roll, F_max, motor_length, pretension, preload, gravity;
    double tol, h_max;
    double s_start;                   /* arc position of cart 0's axle as assembled, m */
    int method;                       /* LSS_METHOD_*: the embedded pair */
    Effects fx;                       /* the effects catalogue (effects.h) */
    double *mass;                     /* [N] mass of each cart with its item, kg (from mass0 and ChainState.load) */
    double *inertia;                  /* [3N] its principal moments, kg m^2 (inertia0 scaled with the mass) */
    double *mass0, *inertia0;         /* [N], [3N] the carts' own (g.mass unless the masses differ) */
    double *err_scale;                /* per state: absolute scale of the error norm */
    double *err_rel;                  /* per state: 1 if the error is also relative to |y| */
    int drive_mode;                   /* DRIVE_INTERNAL (the PI) or DRIVE_EXTERNAL (thrust inputs per group) */
    int n_groups;                     /* motor groups (drive.n_groups) */
    int *motor_group;                 /* [n_motors] the group of each motor, in track order */
    double station_s[N_STATION];      /* arc positions of the stations (induction, chute) */
} ChainModel;

/* Per-cart quantities of the latest right-hand-side evaluation, kept
 * together in memory (a cart's kinematics, geometry and forces are used
 * together). */
typedef struct {
    double R[9];                      /* rotation, body -> world */
    double ww[3];                     /* angular velocity, world */
    double F[3], T[3];                /* force and torque (world, about the CG) */
    double t[3];                      /* track tangent at the axle, world */
    double s;                         /* projected axle arc length */
    double sdot;                      /* its rate, m/s */
    double v_t;                       /* tangential speed of the axle */
    double wheel_speed[N_WHEEL];      /* rad/s */
    double base_key;                  /* the s_hint the base was built at */
    TrackBase base;                   /* track frame at s_hint (NULL element: none yet) */
    int el;                           /* element hint */
    int motor;                        /* motor index hint (drive.c) */
} CartScratch;

/* Quantities of the latest right-hand-side evaluation. */
typedef struct {
    CartScratch *cart;                /* [N] */
    double *delta, *ddelta;           /* [N_SLOT*N] indentation and its rate */
    double *force;                    /* [N_SLOT*N] contact force magnitude */
    double jointF[3];                 /* front-joint force on the transducer cart, its body frame */
    double joint_v_axial;             /* closing rate of the transducer's front joint, m/s */
    double oor_x[2];                  /* distance rolled by the out-of-round wheels (from y), m */
    double oor_rate[2];               /* its rate: their tangential speed, m/s */
    double v_mean, F_cmd, F_total, P_total;
    long n_rhs;
} ChainScratch;

typedef struct ChainState {
    DopriState ode;                   /* time, step size, counters, FSAL validity */
    double *y;                        /* [n_y] */
    double *s_hint;                   /* [N] projection warm start (accepted steps only) */
    double *v_onset;                  /* [N_SLOT*N] onset velocity, 0 when the contact is open */
    double *delta_prev, *ddelta_prev; /* [N_SLOT*N] at the last accepted point */
    double v_ref, Kp, Ki;             /* inputs and tunables in force */
    double F_group[DRIVE_GROUPS];     /* external drive: each group's thrust per motor, saturated */
    double *F_motor;                  /* [n_motors] external drive: each motor's thrust (from its group) */
    double *load;                     /* [N] the item mass each cart carries, kg */
    double port[2 * LOAD_PORTS];      /* each item port's (cart, mass) as last applied */
    double E_items;                   /* mechanical energy the item ports changed, J */
    double relax_rate;                /* 1/s: every velocity decays at this rate (only while relaxing at rest) */
} ChainState;

/* Right-hand-side code paths (solver.vector_path): the scalar one runs
 * everywhere; the vector ones (chain_simd*.c) exist in x86-64 builds with
 * GCC and run where the CPU has the instructions. */
enum { LSS_PATH_AUTO = 0, LSS_PATH_SCALAR = 1, LSS_PATH_AVX2 = 2, LSS_PATH_AVX512 = 3 };
/* Pairs (solver.method). */
enum { LSS_METHOD_DOPRI5 = 0, LSS_METHOD_DOP853 = 1 };

struct ChainSimd;

/* The accepted steps of a run, kept while a follower chain (sensitivity.c)
 * is to take them after it: not part of the state. */
typedef struct {
    double *h, *t;                    /* step sizes and the times they landed at */
    long n, cap;
    int on;                           /* recording */
    int lost;                         /* a step could not be recorded (out of memory) */
} ChainTrace;

typedef struct {
    ChainModel m;
    ChainState st;
    ChainScratch sc;
    Dopri ode;                        /* solver set-up and workspace */
    double *dy_scratch;               /* [n_y] for evaluations outside the solver */
    int scratch_at_state;             /* the scratch describes st.y as it is now */
    int path;                         /* LSS_PATH_* in use, fixed at creation */
    struct ChainSimd *simd;           /* the vector paths' workspace (NULL on the scalar path) */
    ChainTrace trace;                 /* the accepted steps, while recording */
} Chain;

#endif
