/*
 * The WheelRig model: one rigid wheel on flat, level soil under the
 * carriage of a single-wheel test rig, as terramechanics laboratories run
 * them.  The carriage moves the hub forward at rig.vx; the hub is free
 * vertically under the constant load rig.load (mass rig.mass); the wheel's
 * spin is imposed (kinematic), from a slip (rig.driveMode 0) or a spin
 * rate (rig.driveMode 1); rig.slipAngle turns the wheel's heading against
 * the carriage's direction.  The soil's force on the wheel is the rover's
 * law (wheel_soil.h), both contact laws and the contact extensions.
 *
 * Same split as the rover (model.h): Params, Derived, Inputs, State,
 * Outputs, all plain data, so an FMU state is a byte copy.
 *
 * Frame: world x along the carriage's travel, z up, the undisturbed soil
 * surface at z = 0.  The wheel's heading f = (cos psi, sin psi, 0) for the
 * slip angle psi, its axle (and the lateral direction l) e = (-sin psi,
 * cos psi, 0).
 */
#ifndef JUNO_WHEEL_RIG_H
#define JUNO_WHEEL_RIG_H

#include <stddef.h>

#include "contact.h"
#include "wheel_soil.h"
#include "wong_reece.h"

enum { RIG_SLIP_SET = 0, RIG_SPIN_SET = 1 };

typedef struct {
    double soil_kh, soil_eta, soil_gamma, soil_Kvx, soil_KvyRatio, soil_cohesion, soil_phi;
    double wheel_radius, wheel_width;
    int contact_model, contact_method;
    double contact_slipVelocityEps;
    double wr_n, wr_kc, wr_kphi, wr_K, wr_a0, wr_a1;
    int wr_points;
    double grouser_lugHeight, grouser_thrustGain, grouser_thrustSlip, slipSinkage_coefficient, slipSinkage_exponent;
    double rig_load, rig_mass;
    int rig_driveMode;
    double solver_step;
} Params;

typedef struct {
    ContactModel contact;
    WongReeceModel wong_reece;     /* prepared always (its parameters are checked), used when contact.model = 1 */
    double mass;                   /* the vertically moving mass, kg: rig.mass, or rig.load / g when 0 */
} Derived;

typedef struct {
    double slip, vx, omega, slipAngle;
} Inputs;

typedef struct {
    double time;
    double x;                      /* carriage travel, m */
    double z;                      /* hub height above the undisturbed soil surface, m */
    double vz;                     /* hub vertical velocity, m/s */
    ContactMemory memory;          /* the soil under the wheel (contact.h) */
} State;

typedef struct {
    double drawbarPull, verticalForce, torque, lateralForce, sinkage, slipActual, omegaActual;
    double normalForce, tractionForce, travel, hubHeight;
} Outputs;

typedef struct {
    Params p;
    Derived d;
    Inputs in;
    State s;
    Outputs out;
} Model;

/* The model's name in messages (the FMU's model identifier). */
#define MODEL_IDENTIFIER "WheelRig"

/* Everything an FMU state must restore (the whole model: it owns nothing). */
typedef struct {
    Params p;
    Derived d;
    Inputs in;
    State s;
    Outputs out;
} ModelState;

/* The life cycle, the variables and the FMU state, as the FMI layer
 * (fmi2_cs.c) calls them: model_initialize checks the parameters,
 * prepares the contact laws and finds the sinkage at which the soil
 * carries rig.load (static equilibrium, the wheel at rest). */
#include "model_hooks.h"

/* The soil's force on the wheel in one configuration (wheel_rig.c), for
 * the integrator, the equilibrium and the tests. */
typedef struct {
    double sinkage, slip, spin;    /* m, -, rad/s */
    double Fn, F_long, F_lat;      /* N: normal force, traction along t, lateral along the axle */
    double Fx, Fy, Fz;             /* N: world force, x along the carriage, z up */
    double torque;                 /* N m: the driving torque the soil resists, shear_radius F_long */
    double kz;                     /* N/m: dFz / d(sinkage) at fixed memory (the linearised normal force) */
    double v_long;                 /* m/s: hub speed along the wheel's heading */
} RigForce;

/* The force at hub height z (m) and the current inputs; at_rest: carriage
 * and wheel standing (the equilibrium at initialisation). */
void wheel_rig_force(const Model *m, double z, int at_rest, RigForce *f);

#endif
