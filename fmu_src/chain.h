/* The chain of carts: the immutable model (built once from the parameters)
 * and the mutable state (everything a step changes, so that copying the state
 * is what fmi2GetFMUstate needs). The FMI glue sees only this header.
 *
 * State vector y: per cart i, at 13*i: r[3] (CG, world), q[4] (orientation
 * quaternion w,x,y,z, body->world), v[3] (world), w[3] (body angular rate);
 * then the globals at 13*N: PI integrator, motor work, damping loss,
 * rolling loss, and the distances rolled by the out-of-round wheels (left,
 * right; constant 0 when that effect is off). Body frame: x forward, y left,
 * z up, origin at the CG.
 * Cart i+1 runs ahead of cart i; cart i's front joint meets cart i+1's rear
 * joint, and cart N-1's front joint meets cart 0's rear joint. */
#ifndef LSS_CHAIN_H
#define LSS_CHAIN_H

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

/* Parameters of the wheel/coupling type; returns 0 for an unknown type. */
int cart_type_lookup(char wheel, char coupling, CartType *out);

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
} ChainState;

/* Right-hand-side code paths (solver.vector_path): the scalar one runs
 * everywhere; the vector ones (chain_simd*.c) exist in x86-64 builds with
 * GCC and run where the CPU has the instructions. */
enum { LSS_PATH_AUTO = 0, LSS_PATH_SCALAR = 1, LSS_PATH_AVX2 = 2, LSS_PATH_AVX512 = 3 };
/* Pairs (solver.method). */
enum { LSS_METHOD_DOPRI5 = 0, LSS_METHOD_DOP853 = 1 };

struct ChainSimd;

typedef struct {
    ChainModel m;
    ChainState st;
    ChainScratch sc;
    Dopri ode;                        /* solver set-up and workspace */
    double *dy_scratch;               /* [n_y] for evaluations outside the solver */
    int scratch_at_state;             /* the scratch describes st.y as it is now */
    int path;                         /* LSS_PATH_* in use, fixed at creation */
    struct ChainSimd *simd;           /* the vector paths' workspace (NULL on the scalar path) */
} Chain;

/* Builds the chain from validated parameters: layout, carts, initial state.
 * resource_dir locates built-in layouts (may be NULL). Returns NULL with a
 * message in err on failure; never aborts. */
Chain *chain_create(const LSSParams *p, const char *resource_dir, const LSSAlloc *a,
                    char *err, size_t errlen);
void chain_free(Chain *c);

/* Checks the values of the parameters (ranges, finiteness, codes); returns 0
 * or a message naming the variable and the value. */
int chain_check_params(const LSSParams *p, char *err, size_t errlen);

/* Adopts the tunable parameters and inputs (v_ref, Kp, Ki, the CoRs, mu_roll,
 * the external thrusts, the item ports: a port whose cart or mass changed
 * puts that mass on that cart). */
void chain_set_inputs(Chain *c, const LSSParams *p);
/* The inputs' rules that need the chain (an item port's cart below the
 * number of carts); 0, or 1 with a message naming the input. */
int chain_check_inputs(const Chain *c, const LSSParams *p, char *err, size_t errlen);
/* Each cart's mass and inertia from its own and its item's (after the loads changed or were restored). */
void chain_masses(Chain *c);

/* Static equilibrium of a chain at rest: relaxes it for T s (drive off,
 * viscous damping on a fixed schedule, fixed contact damping so that the result does not depend
 * on the CoRs), then starts the clock at 0 at rest. 0, or 1 with a message. */
int chain_relax(Chain *c, double T, char *err, size_t errlen);

/* The contact memory of a fresh start: closed contacts use the floor v_min
 * (evaluates the right-hand side at the current state). */
void chain_start_memory(Chain *c);

/* Sets up the solver (tolerance, error scales, callbacks, workspace). */
void chain_solver_init(Chain *c);

/* Integrates to t_end, landing on it exactly.
 * 0: ok; 1: the state turned non-finite or the step collapsed (discard). */
int chain_step(Chain *c, double t_end, char *err, size_t errlen);

/* Fills the outputs from the current state. */
void chain_outputs(Chain *c, LSSOutputs *out);

/* Right-hand side dy = f(t, y); fills the scratch. */
void chain_rhs(Chain *c, double t, const double *y, double *dy);

/* (t, y) as the chain's state; with accept, as after an accepted step of
 * chain_step (for integrators outside the core). 1 if y or f(t, y) changed. */
int chain_put_state(Chain *c, double t, double *y, int accept);

/* State snapshot for get/set/serialise FMU state. */
size_t chain_state_size(const Chain *c);
void chain_state_save(const Chain *c, double *buf);
void chain_state_load(Chain *c, const double *buf);
int chain_state_check(const double *buf, size_t n, const LSSParams *built, double t_chain, int exact,
                      const Chain *c, char *why, size_t len);

/* Helpers shared by the chain's files. */
void cart_geometry_init(CartGeometry *g, const CartType *t, double pitch, double guide_gap,
                        double mass_factor);
int chain_initial_state(Chain *c, double v0, char *err, size_t errlen);
int chain_load_layout(const char *name, const char *resource_dir, LayoutSpec *spec,
                      const LSSAlloc *a, char *err, size_t errlen);

/* Motor thrust fraction of a cart whose reaction plate is centred at arc
 * length s_plate: sum over motors of overlap / motor length. */
double drive_overlap(const ChainModel *m, double s_plate);
/* PI controller: thrust command per motor and the integrator derivative. */
double drive_command(const ChainModel *m, const ChainState *st, double v_mean, double z, double *zdot);
/* Thrust F on a cart whose axle is at arc length s_axle: the command's
 * share under the motors it covers (F_motor NULL), or with the external
 * drive each covering motor's own thrust F_motor[k] by its share; with the
 * ripple if on. *hint is the cart's motor hint. Returns 0 when no motor is
 * under its plate (then the cart gets no thrust at all). */
int drive_thrust(const ChainModel *m, const double *F_motor, double s_axle, int *hint, double F_cmd, double *F);
/* Per motor group: the thrust on the chain, the coverage-weighted tangential
 * speed of the plates over it and the thrust's power, at the current
 * scratch (outputs only). */
void drive_groups(const Chain *c, double *F, double *v, double *P);

#endif
