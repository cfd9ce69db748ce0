/*
 * The variable table of the WheelRig FMU (fmu_src/wheel_rig.h), in the
 * same X-macro form as the rover's (modelDescription/variables.h, which
 * explains the columns), included by the rig's accessors
 * (fmu_src/model_vars.c built for the rig) and by the generator of its
 * modelDescription.xml (modelDescription/generate.c), so the two cannot
 * disagree.  The contact law's variables, which the rover has too, come
 * from contact_variables.h, the one declaration both tables include.
 *
 * The declared range is what the FMU accepts: every value in [min, max]
 * passes the parameter checks when the other variables keep their start
 * values.  Whether the soil carries rig.load within the wheel's radius is
 * physics, reported as such at initialisation.
 */
#ifndef NOLIM
#define NOLIM HUGE_VAL
#endif
#include "contact_variables.h"   /* the rows the rover's table shares */

#define JUNO_VARIABLES \
    /* ---- soil, as in JunoRover (contact_variables.h) ---- */ \
    JUNO_SOIL_VARIABLES \
    /* ---- wheel ---- */ \
    REAL(120, "wheel.radius",   PARAM, "m",      0.2794, 0.01, 5, p.wheel_radius,  "Wheel radius including lugs (the Juno wheel: 22 in diameter)") \
    REAL(121, "wheel.width",    PARAM, "m",      0.254,  0.01, 1, p.wheel_width,   "Wheel width (the Juno wheel, assumed: ARGO 22x10.00-8)") \
    /* ---- the rig ---- */ \
    REAL(700, "rig.load",       PARAM, "N",      779.0,  1, 1e4, p.rig_load, "Vertical load the carriage puts on the wheel (weight of wheel and ballast); default a quarter of the Juno rover's weight") \
    REAL(701, "rig.mass",       PARAM, "kg",     0.0,    0, 1e4, p.rig_mass, "Vertically moving mass (wheel and the carriage part that follows it); 0 = rig.load / 9.81 m/s2") \
    REAL(703, "rig.movingMass", CALC,  "kg",     0.0,    -NOLIM, NOLIM, d.mass, "The vertically moving mass used: rig.mass, or rig.load / 9.81 m/s2 when rig.mass = 0") \
    INT (702, "rig.driveMode",  PARAM, 0, 0, 1, p.rig_driveMode, "0 = slip set (inputs rig.slip, rig.vx); 1 = spin set (inputs rig.omega, rig.vx)") \
    /* ---- Wong-Reece/Ishigami contact law, as in JunoRover (contact_variables.h) ---- */ \
    JUNO_WONG_REECE_VARIABLES \
    /* ---- numerics: the contact law's, as in JunoRover (contact_variables.h), and the integrator's ---- */ \
    JUNO_CONTACT_NUMERICS_VARIABLES \
    REAL(182, "solver.step",       PARAM, "s",   1e-3, 1e-6, 0.1, p.solver_step, "Largest internal integration step") \
    /* ---- contact extensions beyond the paper's model, as in JunoRover (contact_variables.h) ---- */ \
    JUNO_CONTACT_EXTENSION_VARIABLES \
    /* ---- inputs ---- */ \
    REAL(710, "rig.slip",      INPUT, "1",     0.2,  -1, 0.99, in.slip,      "Longitudinal slip set (rig.driveMode 0): spin omega = v / ((1 - slip) R) when driving, v (1 + slip) / R when braking, v = rig.vx cos(rig.slipAngle)") \
    REAL(711, "rig.vx",        INPUT, "m/s",   0.05, 0, 10,    in.vx,        "Carriage speed, forward") \
    REAL(712, "rig.omega",     INPUT, "rad/s", 0.2,  -1000, 1000, in.omega,  "Wheel spin set (rig.driveMode 1), positive rolling forward") \
    REAL(713, "rig.slipAngle", INPUT, "rad",   0.0,  -1.5, 1.5, in.slipAngle, "Slip angle: the wheel's heading turned from the carriage's direction about the vertical, positive to the left") \
    /* ---- outputs: the soil's force on the wheel ---- */ \
    REAL(800, "rig.drawbarPull",   OUTPUT, "N",     0, -NOLIM, NOLIM, out.drawbarPull,   "Soil force on the wheel along the carriage's direction, positive pulling forward") \
    REAL(801, "rig.verticalForce", OUTPUT, "N",     0, -NOLIM, NOLIM, out.verticalForce, "Soil force on the wheel, vertical, positive up (rig.load in equilibrium)") \
    REAL(802, "rig.torque",        OUTPUT, "N.m",   0, -NOLIM, NOLIM, out.torque,        "Driving torque the wheel needs: the soil's moment about the axle, reversed; positive when driving") \
    REAL(803, "rig.lateralForce",  OUTPUT, "N",     0, -NOLIM, NOLIM, out.lateralForce,  "Soil force on the wheel along its axle, positive to the wheel's left") \
    REAL(804, "rig.sinkage",       OUTPUT, "m",     0, -NOLIM, NOLIM, out.sinkage,       "Sinkage of the lowest rim point below the undisturbed soil surface") \
    REAL(805, "rig.slipActual",    OUTPUT, "1",     0, -NOLIM, NOLIM, out.slipActual,    "Longitudinal slip the contact law sees, (omega R - v) / max(|omega R|, |v|, contact.slipVelocityEps)") \
    REAL(806, "rig.omegaActual",   OUTPUT, "rad/s", 0, -NOLIM, NOLIM, out.omegaActual,   "Wheel spin, positive rolling forward") \
    REAL(807, "rig.normalForce",   OUTPUT, "N",     0, -NOLIM, NOLIM, out.normalForce,   "Normal force Fn of the contact law (Eqn 2), before its tilt") \
    REAL(808, "rig.tractionForce", OUTPUT, "N",     0, -NOLIM, NOLIM, out.tractionForce, "Shear (traction) force along the tilted tangent (Eqn 5); rig.torque is it times the shear radius") \
    REAL(809, "rig.travel",        OUTPUT, "m",     0, -NOLIM, NOLIM, out.travel,        "Distance the carriage has moved") \
    REAL(810, "rig.hubHeight",     OUTPUT, "m",     0, -NOLIM, NOLIM, out.hubHeight,     "Hub height above the undisturbed soil surface")
