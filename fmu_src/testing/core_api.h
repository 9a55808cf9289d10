/* A flat C API to the core for tests and benchmarks (read by cffi in
 * lss_fmu/ccore.py: plain declarations only, no macros or structs here).
 * The FMU does not use it. Sections are added per concern. */
#ifndef LSS_CORE_API_H
#define LSS_CORE_API_H

/* --- track geometry (core_api_track.c) --- */
/* A parsed layout and its built track behind an opaque handle. open returns
 * NULL and fills err ("[path: ]line N: ...") on any error; motor_length is the
 * active length of one linear motor (m), tol_pos (m) and tol_ang (rad) the
 * closure limits. */
void *lss_track_open(const char *path, double motor_length, double tol_pos, double tol_ang,
                     char *err, int errlen);
void *lss_track_open_text(const char *text, int len, double motor_length, double tol_pos,
                          double tol_ang, char *err, int errlen);
void lss_track_close(void *h);
/* Parse only (no geometry): 0 or non-zero with err filled; n_el gets the element count. */
int lss_layout_check_text(const char *text, int len, int *n_el, char *err, int errlen);
/* Every layout rule the FMU applies before assembling the chain: parse, the
 * track with the FMU's closure limits (1 mm, 0.1 mrad), layout_check_chain.
 * 0 with the number of carts, or 1 with the FMU's message. */
int lss_layout_rules_text(const char *text, int len, double motor_length, int *n_carts, char *err, int errlen);
double lss_track_length(void *h);
/* out15: c[3], R[9] row-major (columns t n b), w[3] turn rate in the frame (rad/m) */
void lss_track_eval(void *h, double s, double *out15);
void lss_track_eval_many(void *h, const double *s, int n, double *out15n);
/* closure before correction: dx, dy, dz (m), direction error (rad) */
void lss_track_closure(void *h, double *out4);
int lss_track_n_motors(void *h);
void lss_track_motor(void *h, int k, double *s0s1);
int lss_track_n_elements(void *h);
/* kind (1 straight, 2 curve, 3 vcurve, 4 spiral), file line; s0, length */
void lss_track_element(void *h, int i, int *kind_line, double *s0_len);
/* ints: wheel char, coupling char, n_motors, n_carts (0: default);
 * dbls: start x y z (m), heading (rad), cart mass (kg, 0: default) */
void lss_track_header(void *h, char *name, int namelen, int *ints4, double *dbls5);

/* --- whole chain (core_api_chain.c) --- */
void *lss_params_new(void);
void lss_params_free(void *p);
/* 0 on success; 1 for an unknown name or a name of another type */
int lss_params_set(void *params, const char *name, double value);
int lss_params_set_string(void *params, const char *name, const char *value);
void *lss_chain_new(void *params, const char *resource_dir, char *err, int errlen);
void lss_chain_free(void *c);
int lss_chain_step(void *c, double t_end, char *err, int errlen);
void lss_chain_set_inputs(void *c, void *params);
int lss_chain_n_carts(void *c);
int lss_chain_ny(void *c);
double lss_chain_time(void *c);
void lss_chain_state(void *c, double *y);
void lss_chain_contacts(void *c, double *delta, double *ddelta, double *force);
void lss_chain_outputs(void *c, double *out);
void lss_chain_stats(void *c, long *out3);
/* Snapshot of the chain's state (as fmi2GetFMUstate): size in doubles, save
 * into buf, load from buf (same chain and library only). */
/* The right-hand side dy = f(t, y) of the chain's ODE at any state y
 * (n_y entries; for Jacobians and stiffness studies). */
void lss_chain_rhs(void *c, double t, const double *y, double *dy);
/* For integrators outside the core (benchmarks/bench_integrators.py): puts
 * (t, y) into the chain and, with accept, does what follows an accepted step
 * (contact onset memory, projection warm starts, quaternion norm; y is
 * updated). Returns 1 if y or the right-hand side at y changed. */
int lss_chain_put_state(void *c, double t, double *y, int accept);
/* The solver's error weights: component i is judged by tol (scale[i] + rel[i] |y_i|). */
void lss_chain_error_scales(void *c, double *scale, double *rel);
int lss_chain_state_size(void *c);
void lss_chain_state_save(void *c, double *buf);
void lss_chain_state_load(void *c, const double *buf);
/* Steps to t0 + comm, t0 + 2 comm, ... (n_comm points, t0 the chain's time)
 * and after each writes the outputs of the n_idx value references idx (as in
 * lss_chain_outputs: entry vr-1) to out[k * n_idx + j]: a 300 Hz master loop
 * in C, for measuring the cost of the core without any master overhead.
 * 0 on success, else err is filled. */
int lss_chain_run(void *c, double comm, int n_comm, const int *idx, int n_idx, double *out, char *err,
                  int errlen);

/* --- local track frames (core_api_local.c) --- */
/* The trigonometry-free projections (track_local.h) against the world-frame
 * search at n pseudo-random points near the chain's track (all faces).
 * out5: worst difference in arc length (m), in (a, y, z) (m), in the frame
 * axes, the worst residual |a - a*| (m) of the local result, and the share of
 * points the local search declined (left to the world search). Returns the
 * number of points compared. */
int lss_chain_check_local(void *chain, int n, unsigned seed, double *out5);

/* --- single impact (core_api_impact.c) --- */
/* One body of mass m (kg) approaching a Hunt-Crossley contact (law 1..6,
 * restitution e, stiffness K in N/m^n, exponent n) at v_i (m/s), with the
 * onset floor v_min (m/s), integrated by the chain's DOPRI5 with the chain's
 * onset-memory rule at tolerance tol. 0 on success, else err is filled.
 * opts (nopts entries, may be NULL; NaN = default): 0 h_max (s; default the
 * natural time ds/v_i, ds the elastic peak indentation), 1 error scale of the
 * indentation (m; default ds), 2 error scale of the rate (m/s; default v_i),
 * 3 relative error weight of the rate (default 0), 4 onset rule (0 the
 * chain's linear interpolation, 1 cubic Hermite), 5 start gap (m; 0.1 ds).
 * out (nout entries, NaN if unset): 0 v_out/v_in, 1 v_in, 2 v_out, 3 peak
 * force (N), 4 contact duration (s), 5 largest indentation (m), 6 chi(e),
 * 7 accepted steps, 8 rejected steps, 9 right-hand sides, 10 onset time (s),
 * 11 trace rows written, 12 the onset velocity the contact remembered (m/s).
 * trace (4 * trace_max, may be NULL): t, delta, delta_dot, force at the start
 * and after every accepted step. */
int lss_impact_run(int law, double e, double K, double n, double m, double v_i, double v_min, double tol,
                   const double *opts, int nopts, double *out, int nout, double *trace, int trace_max,
                   char *err, int errlen);
/* contact.c as it is: chi(e) of a law, the exact chi(e), its inverse */
double lss_contact_chi(int law, double e);
double lss_contact_chi_exact(double e);
double lss_contact_restitution_of_chi(double chi);

#endif
