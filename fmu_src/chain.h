/* The chain of carts: its functions (the types are in chain_model.h). The
 * FMI glue sees only this header. */
#ifndef LSS_CHAIN_H
#define LSS_CHAIN_H

#include <stddef.h>

#include "chain_model.h"

/* Parameters of the wheel/coupling type; returns 0 for an unknown type. */
int cart_type_lookup(char wheel, char coupling, CartType *out);

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
/* chain_outputs in two parts: the light one of constant cost (the
 * transducer's signals, the chain's scalars, the solver's counts), the bulk
 * one the outputs that walk every cart or motor (LSSVarInfo.bulk, set in the
 * variable table lss_fmu/variables.py). */
void chain_outputs_light(Chain *c, LSSOutputs *out);
void chain_outputs_bulk(Chain *c, LSSOutputs *out);

/* Recording of the accepted steps (on: from now, an empty trace; off: stop)
 * and its memory. */
void chain_trace(Chain *c, int on);
void chain_trace_free(Chain *c);
/* Takes the steps of a trace from the current time (they must start there):
 * a follower on its leader's steps (dopri_replay). 0, or 1 with a message. */
int chain_replay(Chain *c, const ChainTrace *tr, char *err, size_t errlen);
/* chain_relax on a leader's recorded relaxation steps instead of its own. */
int chain_relax_replay(Chain *c, const ChainTrace *tr, char *err, size_t errlen);
/* Does the relaxation at rest ignore this parameter (value reference)? Those
 * it overrides while relaxing: a chain that differs from another only in
 * them relaxes to the same state. */
int chain_relax_ignores(int vr);

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
