/*
 * The JunoRover model: constant model vs. changing data (MuJoCo style).
 *   Params  - what the user sets (FMU parameters), read-only after initialisation
 *   Derived - computed from Params at initialisation (masses, contact fits)
 *   Inputs  - FMU inputs, set between steps
 *   State   - everything the integrator changes
 *   Outputs - computed from State and Inputs after every step
 * All five are plain old data (no pointers), so an FMU state is a byte copy.
 * The terrain grid, the terrain file name and the path it is loaded from
 * live beside them in Model.
 */
#ifndef JUNO_MODEL_H
#define JUNO_MODEL_H

#include <stddef.h>
#include <stdint.h>
#include "contact.h"
#include "terrain.h"
#include "wheel_soil.h"
#include "wong_reece.h"

enum { WHEEL_FL = 0, WHEEL_RL = 1, WHEEL_FR = 2, WHEEL_RR = 3, NUM_WHEELS = 4 };
enum { SIDE_LEFT = 0, SIDE_RIGHT = 1 };
enum { DRIVE_TORQUE = 0, DRIVE_PID = 1, DRIVE_MOTOR = 2 };

/* Generalised velocities u (9): chassis linear velocity (world, 3),
 * chassis angular velocity (world, 3), rocker rate, left and right wheel
 * spin relative to their rockers. */
enum { U_VX = 0, U_WX = 3, U_BETA = 6, U_SPIN_L = 7, U_SPIN_R = 8, NU = 9 };

typedef struct {
    double soil_kh, soil_eta, soil_gamma, soil_Kvx, soil_KvyRatio, soil_cohesion, soil_phi;
    double wheel_radius, wheel_width, wheel_mass, wheel_inertia;
    double rover_mass, rover_payload, rover_wheelbase, rover_track, rover_pivotHeight, rover_rockerMass;
    double rover_cgHeight, rover_hitchX, rover_hitchZ, rover_rockerDamping, env_gravity;
    int drive_mode;
    double drive_Kp, drive_Ki, drive_Kd, drive_torqueMax;
    double motor_voltage, motor_kt, motor_resistance, motor_gearRatio, motor_efficiency;
    double init_x, init_y, init_yaw, init_vx;
    int contact_method;
    double contact_slipVelocityEps, solver_step, solver_tolerance;
    /* contact law (contact.model) and the Wong-Reece/Ishigami soil (wong_reece.h) */
    int contact_model;
    double wr_n, wr_kc, wr_kphi, wr_K, wr_a0, wr_a1;
    int wr_points;
    /* extensions beyond the paper's model (soil patch, multi-pass, slip-sinkage, grousers,
     * drive loss, terrain registration), off at their defaults */
    double patch_x, patch_y, patch_radius, patch_khFactor, patch_strengthFactor;
    double multipass_rutFraction, multipass_khFactor;
    double slipSinkage_coefficient, grouser_thrustGain, grouser_lugHeight, drive_lossFraction;
    double terrain_offsetX, terrain_offsetY, terrain_offsetZ, terrain_offsetYaw;
    double terrain_slopeX, terrain_slopeY;      /* registration tilt, off at 0 */
    double drive_frictionLeft, drive_frictionRight, drive_viscousFriction;   /* drivetrain friction, off at 0 */
    double strip_x, strip_halfWidth, strip_khFactor, strip_strengthFactor;   /* soil strip, off at factors 1 */
    double slipSinkage_exponent, grouser_thrustSlip, multipass_compactionDepth;
    int grouser_lugCount;                        /* lugs per wheel (lug ripple), 0: none */
    double grouser_rippleAmplitude;              /* lug ripple of the traction limit, off at 0 */
    double grouser_lugPhaseLeft, grouser_lugPhaseRight;   /* the front lugs' ripple phase at each side's angle 0 */
} Params;

/* Multi-pass: each side remembers the residual rut its front wheel leaves,
 * sampled every RUT_SPACING m of the front wheel's forward travel, so the
 * rear wheel (one wheelbase behind on the same track) rolls in it. */
#define RUT_SAMPLES 256
#define RUT_SPACING 0.01
#define RUT_WINDOW_HALF 5  /* samples: a rear wheel follows the rut's mean over 11 cm, about its contact length */

typedef struct {
    ContactModel contact;
    WongReeceModel wong_reece;     /* prepared always (its parameters are checked), used when contact.model = 1 */
    double chassis_mass;
    double chassis_inertia[3];     /* body-frame principal inertia, kg m^2 */
    double rocker_inertia[3];
    double wheel_inertia_transverse;
    double chassis_cg[3];          /* chassis CG in the chassis frame, m */
    double pivot[2][3];            /* rocker pivots in the chassis frame (left, right) */
    double rocker_cg[3];           /* rocker CG in the rocker frame (from the pivot) */
    double hub[2][3];              /* front, rear hub in the rocker frame */
    double side_mass, side_cg[3], side_I[9];   /* a side's rocker and wheels as one body (rover_side_body) */
    uint64_t terrain_fingerprint;  /* of the ground initialisation loaded (terrain_fingerprint): a state
                                    * steps on only where it was taken */
} Derived;

typedef struct {
    double drawbarForce, torqueLeft, torqueRight, omegaRefLeft, omegaRefRight;
    double throttleLeft, throttleRight;
} Inputs;

typedef struct {
    double time;
    double pos[3];                 /* chassis reference point, world */
    double quat[4];                /* world-from-chassis rotation (w, x, y, z) */
    double beta;                   /* left rocker angle; right = -beta */
    double u[NU];                  /* generalised velocities, see U_* */
    double spin_angle[2];          /* rad, each side's wheel angle relative to its rocker: the
                                    * integral of u[U_SPIN_L + side] from 0 at initialisation */
    ContactMemory memory[NUM_WHEELS];
    double pid_integral[2];        /* rad (integral of the spin error) */
    double path[2];                /* forward travel of each side's front wheel, m */
    double rut[2][RUT_SAMPLES];    /* residual rut depth along that travel (ring buffer), m */
    double torque_applied[2];      /* N m, last applied drive torque per side */
    double step_next;              /* s, the automatic step's next internal step (0: none yet) */
    /* The automatic step's last accepted internal step, for the next one's correction
     * (rover_auto_step.c): its length (0: none, or not with the current inputs), the generalised
     * forces at its start, its increments, its own correction's velocities over its length
     * squared (m/s^3, rad/s^3; valid where last_correction_valid), the inputs it was taken
     * with and its drive terms (Eval.drive_limit). */
    double last_step;              /* s */
    double last_Q[NU];
    double last_dq[NU], last_du[NU], last_dI[2];
    double last_correction[NU];
    int last_correction_valid;
    Inputs last_inputs;
    double last_drive_limit[2];
} State;

typedef struct {
    double sinkage, slip, Fn, Ft, Fx, Fy, Fz;
} WheelOutputs;

typedef struct {
    double x, y, z, roll, pitch, yaw, vx, omegaLeft, omegaRight;
    double torqueLeftApplied, torqueRightApplied, rocker, spinAngleLeft, spinAngleRight;
    WheelOutputs wheel[NUM_WHEELS];
} Outputs;

/* ---- the working data of an evaluation (rover_*.c; not part of the FMU state) ---- */

#define NUM_BODIES 7

/* Per-wheel contact result of one evaluation. */
typedef struct {
    int in_contact;
    double sinkage, slip, Fn, F_long, F_lat, v_long;
    double rut;                    /* the rut depth the sinkage is reduced by (m; 0 but for a rear wheel in a rut) */
    double sin_alpha, cos_alpha;   /* tilt of the normal force (Eqn 7) as applied */
    double force[3];               /* world force on the wheel, N */
} WheelContact;

/* Everything one evaluation of the dynamics computes. */
typedef struct {
    double R[9];                   /* world from chassis */
    double e[3];                   /* chassis lateral axis = rocker and wheel axles */
    double heading[3];             /* horizontal unit heading */
    double pivot[2][3], hub[NUM_WHEELS][3];
    double pivot_r[2][3];          /* pivot - chassis reference point */
    double rocker_R[2][9];         /* world from rocker frame, left and right */
    double u_beta;                 /* rocker rate, rad/s */
    double Jv[NUM_BODIES][3][NU], Jw[NUM_BODIES][3][NU];   /* filled for the wheels only (the hubs) */
    double M[NU][NU], Q[NU], D[NU][NU], K[NU][NU];
    WheelContact wheel[NUM_WHEELS];
    double torque[2];              /* N m, the drive torque applied: the demand, limited */
    double torque_demand[2];       /* N m, the drive law's torque, unlimited (rover_drive_law) */
    double torque_slope[2];        /* d torque / d omega of the drive law */
    double drive_limit[2];         /* the step's drive terms: 0 the linear law, +-1 the limit of that sign */
    double ground_z[NUM_WHEELS];           /* terrain elevation under each hub (world, m) */
    double ground_normal[NUM_WHEELS][3];   /* unit terrain normal under each hub (world) */
} Eval;

typedef struct {
    Params p;
    Derived d;
    Inputs in;
    State s;
    Outputs out;
    /* not part of the byte-copied FMU state (ModelState): */
    char *terrain_file;            /* owned (malloc), NULL = flat ground; reads back as set */
    /* The String variables that name files, as initialisation opens them (model_resolve_resources):
     * owned, the path in the FMU's resources folder of a relative name found there; NULL, the name
     * as set.  Apart from the variables, so that a host reads back and saves what it set, not a
     * path that exists only on this machine. */
    struct {
        char *terrain_file;
    } resolved;
    Terrain terrain;
    uint64_t terrain_fingerprint;  /* of terrain, as loaded by the last initialisation */
    /* The input-independent evaluation of the state at the end of the
     * last model_do_step (or model_initialize), valid while eval_valid:
     * set there, cleared by every other write of what it is computed from
     * (model_changed: a parameter, String variable or state set through
     * the accessors; model_initialize, model_reset, model_free) and by a
     * failed step. */
    Eval eval;
    int eval_valid;
    /* Counts of internal steps since initialisation, for benchmarks: taken
     * (accepted) and rejected by the automatic step's error estimate. */
    unsigned long steps_taken, steps_rejected;
} Model;

/* The model's name in messages (the FMU's model identifier). */
#define MODEL_IDENTIFIER "JunoRover"

/* Everything an FMU state must restore: plain data, so a snapshot is a
 * byte copy.  The terrain grid and string values are not in it: they
 * cannot change after initialisation. */
typedef struct {
    Params p;
    Derived d;
    Inputs in;
    State s;
    Outputs out;
} ModelState;

/* The life cycle, the variables and the FMU state, as the FMI layer
 * (fmi2_cs.c) calls them: model_initialize checks the parameters,
 * prepares the contact laws, loads the terrain and places the rover in
 * static equilibrium; model_free frees the terrain grid and the string
 * values. */
#include "model_hooks.h"

#endif
