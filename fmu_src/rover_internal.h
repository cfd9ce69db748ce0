/*
 * What the parts of the rover model share (not part of the model's API,
 * model.h):
 *   rover_setup.c          parameters, derived data, static equilibrium,
 *                          the life cycle and the hooks of the FMI layer
 *   rover_dynamics.c       kinematics, the bodies' mass matrix and forces,
 *                          the drive, the drawbar, the outputs
 *   rover_wheel_contact.c  the wheels' contacts with the soil (both contact
 *                          laws) and the model extensions acting there
 *   rover_step.c           a communication step: the fixed step, the reuse
 *                          of an evaluation, the soil memory's update, the
 *                          checks of a diverging state
 *   rover_auto_step.c      the automatic step (the default)
 *   dense_lu.c             the dense 9 x 9 solver of both steps (dense_lu.h)
 *
 * The rover: the CSA Juno rover's chassis (6 DOF), two main rockers coupled
 * by the transverse differential (left angle beta, right -beta), one spin
 * DOF per side (1:1 chain), four wheel/soil contacts, a drawbar hitch.
 *
 * Formulation: Kane's equations in the 9 generalised velocities u of
 * model.h.  Each of the 7 bodies (chassis, 2 rockers, 4 wheels) has a
 * linear and angular velocity Jacobian J(q) (3 x 9) and a bias
 * acceleration (the J'u terms), so M(q) u' = Q(q, u) with
 * M = sum J^T m J and Q = sum J^T (F - m b) + gyroscopic terms.
 */
#ifndef JUNO_ROVER_INTERNAL_H
#define JUNO_ROVER_INTERNAL_H

#include <math.h>
#include <stddef.h>

#include "model.h"
#include "vec3.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

enum { BODY_CHASSIS = 0, BODY_ROCKER_L = 1, BODY_ROCKER_R = 2, BODY_WHEEL0 = 3 };

/* "FL", "RL", "FR", "RR", for messages. */
extern const char *const rover_wheel_names[NUM_WHEELS];

/* Keeps a function out of line where inlining it makes its caller too
 * large for GCC to keep the caller's values in registers (measured with
 * callgrind and CPU time at each use). */
#if defined(__GNUC__)
#define NOINLINE __attribute__((noinline))
#else
#define NOINLINE
#endif

/* The side of wheel w (0..3): a shift, where w / 2 of a signed w would take
 * three more instructions for negative w's rounding. */
static inline int side_of(int w) { return (int)((unsigned)w >> 1); }

/* fmin(a, x) and fmax(a, x) without their library calls (GCC keeps the calls unless it may
 * ignore NaNs and signed zeros), for an a that is neither NaN nor zero: the same result, a NaN x
 * giving a as fmin and fmax do. */
static inline double fmin_of(double a, double x) { return x < a ? x : a; }
static inline double fmax_of(double a, double x) { return x > a ? x : a; }
static inline double sigma_of(int side) { return side == SIDE_LEFT ? 1.0 : -1.0; }

/* What an evaluation computes beside the kinematics and the forces (the
 * `matrices` argument below):
 *   EVAL_FORCES       nothing more (the outputs);
 *   EVAL_MATRICES     M, Q, and the damping D and stiffness K, the Jacobians
 *                     the linearly implicit step needs. */
enum { EVAL_FORCES = 0, EVAL_MATRICES = 1 };

/* K's structural non-zeros: the block of rows and columns 0..U_BETA (the
 * contacts' normal stiffness acts through the hubs, whose velocity
 * Jacobians have no spin columns: rover_wheel_contact.c's add_outer_hub)
 * and the spin diagonal (the PID integral, rover_evaluate_inputs).  The
 * integrators' products with K skip the rest, exact zeros, whose terms
 * change no sum. */
enum { K_BLOCK = U_BETA + 1 };

/* out = K x over K's structural non-zeros, each sum in the order of the
 * dense loop. */
static inline void k_times(const double (*K)[NU], const double x[NU], double out[NU])
{
    for (int i = 0; i < K_BLOCK; ++i) {
        double s = 0;
        for (int j = 0; j < K_BLOCK; ++j) s += K[i][j] * x[j];
        out[i] = s;
    }
    for (int k = U_SPIN_L; k <= U_SPIN_R; ++k) out[k] = K[k][k] * x[k];
}

/* The linearly implicit step's matrix A = M + c D + c^2 K, with c the step (the fixed step's h,
 * the automatic step's stage gamma h); K's structural zeros (k_times) are left out: adding
 * c c 0 changes nothing. */
static inline void step_matrix(const Eval *ev, double c, double A[NU][NU])
{
    const double (*K)[NU] = (const double (*)[NU])ev->K;
    const double cc = c * c;
    for (int i = 0; i < K_BLOCK; ++i) {
        for (int j = 0; j < K_BLOCK; ++j) A[i][j] = ev->M[i][j] + c * ev->D[i][j] + cc * K[i][j];
        for (int j = K_BLOCK; j < NU; ++j) A[i][j] = ev->M[i][j] + c * ev->D[i][j];
    }
    for (int i = K_BLOCK; i < NU; ++i)
        for (int j = 0; j < NU; ++j) A[i][j] = ev->M[i][j] + c * ev->D[i][j] + (j == i ? cc * K[i][j] : 0.0);
}

/* rover_wheel_contact.c */

/* Terrain elevation (m) at world (x, y) and, if n, the unit normal there,
 * with the registration offsets (terrain.offset*) applied. */
double rover_terrain_at(const Model *m, double x, double y, double n[3]);

/* rover_terrain_at at four points (world x, y of each, as the hubs of
 * Eval): the elevations into zt, the normals into n. */
void rover_terrain_under_wheels(const Model *m, const double (*xy)[3], double zt[NUM_WHEELS], double n[NUM_WHEELS][3]);

/* The four wheels' contacts: the terrain under the hubs into
 * ev->ground_z and ev->ground_normal, then rover_wheel_contacts_on_ground.
 * Needs the kinematics of ev (rover_evaluate_passive). */
void rover_wheel_contacts(const Model *m, Eval *ev, int matrices);

/* The four wheels' contacts on the terrain already in ev->ground_z and
 * ev->ground_normal: fills ev->wheel; with matrices (EVAL_MATRICES), adds
 * their generalised forces to ev->Q, their damping to ev->D and their
 * stiffness to ev->K, wheel by wheel in order. */
void rover_wheel_contacts_on_ground(const Model *m, Eval *ev, int matrices);

/* rover_dynamics.c */

/* Each side's rocker with its two wheels as one body (the same for both
 * sides): its mass (kg), CG (rocker frame, from the pivot, m) and inertia
 * about the CG (rocker frame, kg m^2), from the parameters p and the rest
 * of the derived data d. */
void rover_side_body(const Params *p, const Derived *d, double *mass, double cg[3], double I[9]);

/* The drive and its torque limit in the step.  Each side's drive is a
 * law linear in its wheel spin omega (and, for the PID, in its integral
 * I): the torque it demands (N m, on the motor side) and the slope
 * d torque / d omega, from the drive mode and the inputs; the torque
 * applied is the demand limited to +-drive.torqueMax (drive.mode 1 and 2).
 * The step is linearly implicit in the drive: taken with the linear law,
 * it gives the wheels the law's torque along the step (the fixed step's
 * at the step's end, at the end's spin and integral; the automatic step's
 * at its stages, as they weigh them).  That step is consistent if that
 * torque lies within the limit; where it does not, the step is taken
 * again with that side at the limit of the torque's sign, a constant
 * torque (slope 0), which is then consistent too: with less torque than
 * the law demanded the spin's error only grows, and the demand with it.
 * (Taking
 * the limit whenever the step's start is saturated, explicitly, would
 * make a stiff tracker overshoot by far within the step and swing between
 * the limits step after step; the linear law where the end lies outside
 * the limit would give the wheels more than it.)  The steps keep each
 * side's choice in ev->drive_limit. */

/* The law of side's drive at spin omega (rad/s) and PID integral (rad):
 * the torque demanded, unlimited, and its slope into *slope. */
double rover_drive_law(const Model *m, int side, double omega, double integral, double *slope);

/* A demand limited to the drive's torque limit (drive.mode 1 and 2). */
double rover_drive_limited(const Model *m, double demand);

/* The torque applied per side at the current state: the law's demand,
 * limited. */
void rover_drive_torques(const Model *m, double torque[2]);

/* Changes side's drive terms in ev (with matrices and input terms) from
 * the linear law to the constant torque sign * drive.torqueMax: its
 * share of Q, its slope in D and the PID integral's stiffness in K. */
void rover_drive_at_limit(const Model *m, Eval *ev, int side, double sign);

/* The part of an evaluation that does not depend on the inputs (what
 * m->eval keeps between steps, rover_step.c): kinematics, the bodies' M
 * and Q (with matrices) and the contacts.  rover_evaluate_inputs adds the
 * drive and drawbar terms; rover_evaluate does both. */
void rover_evaluate_passive(const Model *m, Eval *ev, int matrices);

/* rover_evaluate_passive in two parts: the geometry (kinematics, and the
 * terrain under the hubs into ev->ground_z and ev->ground_normal), from
 * the state's position, attitude, rocker angle and velocities, the
 * parameters and the terrain only, which leaves ev's forces and contacts
 * (ev->wheel, Q, D, K) as they were; then the forces on that geometry,
 * from the rest (the soil memory, the rut).  Between the two the
 * automatic step advances the soil memory with the end's own sinkage. */
void rover_evaluate_geometry(const Model *m, Eval *ev);
void rover_evaluate_forces(const Model *m, Eval *ev, int matrices);
void rover_evaluate_inputs(const Model *m, Eval *ev, int matrices);
void rover_evaluate(const Model *m, Eval *ev, int matrices);

/* Outputs from an evaluation of the current state (with its torques). */
void rover_outputs_from(Model *m, const Eval *ev);

/* rover_step.c */

/* The end-of-step evaluation: the outputs, and m->eval kept for reuse. */
void rover_evaluate_end_of_step(Model *m);

/* The contact memory and the multi-pass rut over a step of length h, from
 * the evaluation ev of the step's start and each wheel's sinkage over the
 * step (m). */
void rover_advance_soil_memory(Model *m, const Eval *ev, const double sinkage[NUM_WHEELS], double h);

/* 1 if the state after a step is sane; else 0, with the likely cause of the
 * divergence (from ev, the step's start's evaluation) in err.  The same for
 * a state to come: its time (s), position, velocities and rocker angle. */
int rover_state_is_sane(const Model *m, const Eval *ev, char *err, size_t n);
int rover_motion_is_sane(const Model *m, const Eval *ev, double time, const double pos[3], const double u[NU],
                         double beta, char *err, size_t n);
/* 1 if the chassis, at attitude quat (world from chassis, w x y z), is
 * upright over the ground under the wheels of ev (rover_step.c: not
 * overturned); else 0, with the overturn named in err at time (s). */
int rover_attitude_is_upright(const Model *m, const double quat[4], const Eval *ev, double time, char *err,
                              size_t n);

/* rover_auto_step.c */

/* One communication step of h_comm (s) in automatic steps
 * (solver.tolerance > 0); 0, or -1 with the reason in err. */
int rover_do_step_automatic(Model *m, double h_comm, char *err, size_t errlen);

/* If the steepest terrain slope under the NUM_WHEELS points xy (world x,
 * y) exceeds the soil's friction angle, writes why the rover cannot stand
 * there into buf and returns 1; else returns 0. */
int rover_slope_beyond_friction(const Model *m, const double (*xy)[3], char *buf, size_t n);

#endif
