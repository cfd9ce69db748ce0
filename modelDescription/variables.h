/*
 * The one table of FMU variables: value references, names, causality,
 * units, start values, ranges and where each value lives in the model.
 * It is included (X-macro style) by the FMU's accessors (fmu_src/model_vars.c)
 * and by the generator of modelDescription.xml (modelDescription/generate.c),
 * so the two cannot disagree.
 *
 * REAL(vr, name, kind, unit, start, min, max, field, description)
 * INT (vr, name, kind, start, min, max, field, description)
 * STR (vr, name, kind, start, field, description)
 *
 * kind: PARAM (fixed parameter: set before initialisation), CALC (calculated
 * parameter), INPUT, OUTPUT.  min/max are inclusive; NOLIM means none.
 * field is an lvalue relative to a Model *m.
 *
 * The declared range is what the FMU accepts: every value in [min, max]
 * passes the parameter checks when the other variables keep their start
 * values (tests/python/test_fmu_ranges.py walks them all).  A quantity that
 * must be positive has a small positive min rather than an exclusive 0.
 * Some parameters are also checked together (4 wheel.mass + 2
 * rover.rockerMass < rover.mass, wheel.width < rover.track, wongReece.a0
 * against a1, kc / wheel.width + kphi > 0); their ranges keep those true at
 * the start values of the others, and a combination that breaks one is
 * refused at initialisation with a message naming both.  Whether the
 * rover can stand and drive with a value (k_h = 1e-3 under 318 kg) is
 * physics, reported as such (no static equilibrium, a diverged state).
 */
#ifndef NOLIM
#define NOLIM HUGE_VAL
#endif
#include "contact_variables.h"   /* the rows the rig's table shares */
#define WHEEL_OUTPUTS(w, W, base) \
    REAL(base + 0, "wheel" W ".sinkage", OUTPUT, "m",   0, -NOLIM, NOLIM, out.wheel[w].sinkage, "Sinkage of the lowest rim point below the local soil surface") \
    REAL(base + 1, "wheel" W ".slip",    OUTPUT, "1",   0, -NOLIM, NOLIM, out.wheel[w].slip,    "Longitudinal slip (omega R - v_x) / max(|omega R|, |v_x|, eps)") \
    REAL(base + 2, "wheel" W ".Fn",      OUTPUT, "N",   0, -NOLIM, NOLIM, out.wheel[w].Fn,      "Normal force k_h V_h (Eqn 2)") \
    REAL(base + 3, "wheel" W ".Ft",      OUTPUT, "N",   0, -NOLIM, NOLIM, out.wheel[w].Ft,      "Tangential (traction) force along the heading (Eqn 5)") \
    REAL(base + 4, "wheel" W ".Fx",      OUTPUT, "N",   0, -NOLIM, NOLIM, out.wheel[w].Fx,      "Longitudinal force in the contact frame, Ft cos(alpha) - Fn sin(alpha) (Eqn 8)") \
    REAL(base + 5, "wheel" W ".Fy",      OUTPUT, "N",   0, -NOLIM, NOLIM, out.wheel[w].Fy,      "Lateral force along the axle in the contact plane") \
    REAL(base + 6, "wheel" W ".Fz",      OUTPUT, "N",   0, -NOLIM, NOLIM, out.wheel[w].Fz,      "Force along the surface normal, Fn cos(alpha) + Ft sin(alpha) (Eqn 9)")

#define JUNO_VARIABLES \
    /* ---- soil (contact_variables.h) ---- */ \
    JUNO_SOIL_VARIABLES \
    /* ---- wheel ---- */ \
    REAL(120, "wheel.radius",   PARAM, "m",      0.2794, 0.01, 5, p.wheel_radius,  "Wheel radius including lugs (22 in diameter)") \
    REAL(121, "wheel.width",    PARAM, "m",      0.254,  0.01, 1, p.wheel_width,   "Wheel width (assumed: ARGO 22x10.00-8); less than rover.track") \
    REAL(122, "wheel.mass",     PARAM, "kg",     9.6,    0.01, 50, p.wheel_mass,    "Mass of one wheel; 4 wheel.mass + 2 rover.rockerMass < rover.mass") \
    REAL(123, "wheel.inertia",  PARAM, "kg.m2",  0.35,   1e-6, 1e4, p.wheel_inertia, "Spin inertia of one wheel (assumed)") \
    /* ---- rover ---- */ \
    REAL(130, "rover.mass",        PARAM, "kg", 317.7, 60, 2000, p.rover_mass,        "Total mass including wheels and rockers (more than 4 wheel.mass + 2 rover.rockerMass)") \
    REAL(129, "rover.payload",     PARAM, "kg", 0.0,   -200, 1000, p.rover_payload,   "Mass on the chassis beyond rover.mass (instruments, ballast, what a weighing missed; negative: the rover is lighter than rover.mass states); it joins the chassis's mass and inertia box at the chassis's centre of gravity") \
    REAL(131, "rover.wheelbase",   PARAM, "m",  0.82,  0.01, 20, p.rover_wheelbase,   "Distance between front and rear axles (assumed)") \
    REAL(132, "rover.track",       PARAM, "m",  1.35,  0.3, 20, p.rover_track,       "Distance between left and right wheel centres (assumed); more than wheel.width") \
    REAL(133, "rover.pivotHeight", PARAM, "m",  0.15,  0, 10, p.rover_pivotHeight, "Rocker pivot height above the axle line (assumed)") \
    REAL(134, "rover.rockerMass",  PARAM, "kg", 10.0,  0.01, 100, p.rover_rockerMass,  "Mass of one main rocker (assumed)") \
    REAL(135, "rover.cgHeight",    PARAM, "m",  0.25,  -10, 10, p.rover_cgHeight, "Chassis centre of gravity above the axle line (assumed)") \
    REAL(136, "rover.hitchX",      PARAM, "m",  -0.69, -10, 10, p.rover_hitchX,  "Drawbar hitch, longitudinal position in the chassis frame (rear)") \
    REAL(137, "rover.hitchZ",      PARAM, "m",  0.0,   -1, 1, p.rover_hitchZ,  "Drawbar hitch height above the rocker pivots") \
    REAL(138, "rover.rockerDamping", PARAM, "N.m.s/rad", 20.0, 0, NOLIM, p.rover_rockerDamping, "Viscous friction of the rocker differential (assumed)") \
    REAL(139, "env.gravity",       PARAM, "m/s2", 9.81, 0.01, 100, p.env_gravity,     "Gravitational acceleration") \
    /* ---- terrain ---- */ \
    STR(140, "terrain.file",       PARAM, "", terrain_file, "ESRI ASCII elevation grid (.asc); empty = flat ground at z = 0") \
    /* ---- drive ---- */ \
    INT (150, "drive.mode",        PARAM, 2, 0, 2, p.drive_mode, "0 = torque inputs; 1 = PID on torque tracking omegaRef; 2 = DC motors driven by throttle") \
    REAL(151, "drive.Kp",          PARAM, "N.m.s/rad", 200.0, 0, NOLIM, p.drive_Kp, "PID proportional gain (drive.mode 1)") \
    REAL(152, "drive.Ki",          PARAM, "N.m/rad",   400.0, 0, NOLIM, p.drive_Ki, "PID integral gain (drive.mode 1)") \
    REAL(153, "drive.Kd",          PARAM, "N.m.s2/rad", 0.0,  0, NOLIM, p.drive_Kd, "PID derivative gain on the measured spin (drive.mode 1)") \
    REAL(154, "drive.torqueMax",   PARAM, "N.m",       400.0, 0, NOLIM, p.drive_torqueMax, "Limit of the drive torque per side (drive.mode 1 and 2)") \
    REAL(155, "motor.voltage",     PARAM, "V",   24.0,   0, NOLIM, p.motor_voltage,    "Supply voltage at full throttle (assumed)") \
    REAL(156, "motor.kt",          PARAM, "N.m/A", 0.0465, 0, NOLIM, p.motor_kt,       "Torque and back-EMF constant (assumed)") \
    REAL(157, "motor.resistance",  PARAM, "Ohm", 0.2,    1e-6, NOLIM, p.motor_resistance, "Armature resistance (assumed)") \
    REAL(158, "motor.gearRatio",   PARAM, "1",   129.0,  1e-3, NOLIM, p.motor_gearRatio,  "Gear ratio motor:wheel (low gear 1:129)") \
    REAL(159, "motor.efficiency",  PARAM, "1",   0.85,   0, 1,     p.motor_efficiency, "Gear and chain efficiency (assumed)") \
    /* ---- Wong-Reece/Ishigami contact law (contact_variables.h) ---- */ \
    JUNO_WONG_REECE_VARIABLES \
    /* ---- initial state ---- */ \
    REAL(170, "init.x",   PARAM, "m",   0.0, -NOLIM, NOLIM, p.init_x,   "Initial x of the chassis reference point") \
    REAL(171, "init.y",   PARAM, "m",   0.0, -NOLIM, NOLIM, p.init_y,   "Initial y of the chassis reference point") \
    REAL(172, "init.yaw", PARAM, "rad", 0.0, -NOLIM, NOLIM, p.init_yaw, "Initial heading") \
    REAL(173, "init.vx",  PARAM, "m/s", 0.0, -NOLIM, NOLIM, p.init_vx,  "Initial forward speed (wheels rolling without slip)") \
    /* ---- numerics: the contact law's (contact_variables.h) and the integrator's ---- */ \
    JUNO_CONTACT_NUMERICS_VARIABLES \
    REAL(182, "solver.step",       PARAM, "s",   0.02, 1e-6, 0.1, p.solver_step, "Largest internal integration step of the automatic step (solver.tolerance > 0), or the fixed step when solver.tolerance = 0") \
    REAL(184, "solver.tolerance",  PARAM, "m/s", 4e-4, 0, 1, p.solver_tolerance, "0 = fixed internal steps of solver.step; > 0: automatic steps of at most solver.step, each a two-stage linearly implicit step with an embedded first-order solution, its length chosen so that the two solutions' velocities (angular rates as speeds at wheel.radius or half rover.wheelbase) differ by at most this") \
    /* ---- model extensions: effects real data shows and the paper's model leaves out; each is off at its default ---- */ \
    REAL(190, "soilPatch.x",        PARAM, "m",   0.0, -NOLIM, NOLIM, p.patch_x,      "Soil patch centre, world x") \
    REAL(191, "soilPatch.y",        PARAM, "m",   0.0, -NOLIM, NOLIM, p.patch_y,      "Soil patch centre, world y") \
    REAL(192, "soilPatch.radius",   PARAM, "m",   1.0, 0.01, NOLIM, p.patch_radius,   "Soil patch radius (Gaussian sigma)") \
    REAL(193, "soilPatch.khFactor", PARAM, "1",   1.0, 0.05, 20,    p.patch_khFactor, "k_h at the patch centre relative to soil.kh (1 = homogeneous soil)") \
    REAL(194, "soilPatch.strengthFactor", PARAM, "1", 1.0, 0.05, 20, p.patch_strengthFactor, "Shear strength (C, tan phi) at the patch centre relative to elsewhere (1 = homogeneous)") \
    REAL(195, "multipass.rutFraction", PARAM, "1", 0.0, 0, 1, p.multipass_rutFraction, "Fraction of the front wheel's residual rut (1-gamma) z_max that the rear wheel on the same side rolls in (0 = off)") \
    REAL(196, "multipass.khFactor", PARAM, "1",  1.0, 0.05, 20, p.multipass_khFactor, "k_h of soil compacted by the front wheel, relative to virgin soil (1 = off)") \
    JUNO_CONTACT_EXTENSION_VARIABLES /* slip-sinkage, grouser thrust and lugs (contact_variables.h) */ \
    REAL(199, "drive.lossFraction", PARAM, "1", 0.0, 0, 0.9, p.drive_lossFraction, "Fraction of the drive torque (motor side, as measured from the current) lost in gears and chain") \
    REAL(185, "terrain.offsetX",   PARAM, "m",   0.0, -1e7, 1e7, p.terrain_offsetX,   "Registration: the terrain grid is shifted by this in x (after the turn about the world origin: a turn of a scan far from the origin shifts it far)") \
    REAL(186, "terrain.offsetY",   PARAM, "m",   0.0, -1e7, 1e7, p.terrain_offsetY,   "Registration: the terrain grid is shifted by this in y (after the turn about the world origin)") \
    REAL(187, "terrain.offsetZ",   PARAM, "m",   0.0, -1e7, 1e7, p.terrain_offsetZ,   "Registration: the terrain grid is raised by this (with the tilt about the world origin: a tilt of a scan far from the origin raises it far)") \
    REAL(188, "terrain.offsetYaw", PARAM, "rad", 0.0, -3.15, 3.15,   p.terrain_offsetYaw, "Registration: the terrain grid is rotated by this about z (about the world origin)") \
    REAL(178, "terrain.slopeX",    PARAM, "1",   0.0, -0.3, 0.3, p.terrain_slopeX,    "Registration: the terrain is tilted, raised by slopeX times world x (with slopeY: a plane through the world origin). Within 0.3 (17 deg): on steeper slopes, from about the soil's friction angle (0.58 at soil.phi = 30 deg), the rover at its start pose slides and flips over backwards, which a model whose only contacts with the ground are its wheels does not describe") \
    REAL(179, "terrain.slopeY",    PARAM, "1",   0.0, -0.3, 0.3, p.terrain_slopeY,    "Registration: the terrain is tilted, raised by slopeY times world y (within 0.3, as slopeX)") \
    REAL(500, "drive.frictionLeft",  PARAM, "N.m", 0.0, 0, 400, p.drive_frictionLeft,  "Coulomb friction torque of the left drivetrain on the wheel side, opposing the wheel spin; not in the measured (motor) torque (0 = off)") \
    REAL(501, "drive.frictionRight", PARAM, "N.m", 0.0, 0, 400, p.drive_frictionRight, "Coulomb friction torque of the right drivetrain on the wheel side, opposing the wheel spin; not in the measured (motor) torque (0 = off)") \
    REAL(502, "drive.viscousFriction", PARAM, "N.m.s/rad", 0.0, 0, 1000, p.drive_viscousFriction, "Viscous friction of each side's drivetrain on the wheel side, per rad/s of wheel spin; not in the measured (motor) torque (0 = off)") \
    REAL(503, "soilStrip.x",        PARAM, "m", 0.0, -NOLIM, NOLIM, p.strip_x,      "Soil strip (a band across x) centre, world x") \
    REAL(504, "soilStrip.halfWidth", PARAM, "m", 0.5, 0.01, NOLIM, p.strip_halfWidth, "Soil strip half width along x (edges smoothed over about 5 cm)") \
    REAL(505, "soilStrip.khFactor", PARAM, "1", 1.0, 0.05, 20, p.strip_khFactor, "k_h inside the soil strip relative to outside (1 = off)") \
    REAL(506, "soilStrip.strengthFactor", PARAM, "1", 1.0, 0.05, 20, p.strip_strengthFactor, "Shear strength (C, tan phi) inside the soil strip relative to outside (1 = off)") \
    REAL(509, "multipass.compactionDepth", PARAM, "m", 0.002, 1e-4, 0.5, p.multipass_compactionDepth, "Rut depth d at which the compaction reaches half its effect: k_h (1 + (multipass.khFactor - 1) rut / (rut + d))") \
    INT (510, "grouser.lugCount", PARAM, 0, 0, 100, p.grouser_lugCount, "Lugs per wheel N of the lug ripple: the traction limit pulses N times per revolution (0 = no ripple)") \
    REAL(511, "grouser.rippleAmplitude", PARAM, "1", 0.0, 0, 1, p.grouser_rippleAmplitude, "Lug ripple: F_taumax (1 + a cos(N theta + phi)), theta the side's spinAngle, phi the side's grouser.lugPhase on the front wheels and pi more on the rear (assumed half a lug pitch behind) (0 = off)") \
    REAL(512, "grouser.lugPhaseLeft", PARAM, "rad", 0.0, -NOLIM, NOLIM, p.grouser_lugPhaseLeft, "Lug ripple phase phi of the left front wheel at spinAngleLeft 0: where its lugs are when the run starts") \
    REAL(513, "grouser.lugPhaseRight", PARAM, "rad", 0.0, -NOLIM, NOLIM, p.grouser_lugPhaseRight, "Lug ripple phase phi of the right front wheel at spinAngleRight 0: where its lugs are when the run starts") \
    /* ---- inputs ---- */ \
    REAL(200, "drawbarForce",  INPUT, "N",   400.0, -NOLIM, NOLIM, in.drawbarForce,  "Resisting force at the rear hitch, horizontal, backwards along the heading") \
    REAL(201, "torqueLeft",    INPUT, "N.m", 0.0,   -NOLIM, NOLIM, in.torqueLeft,    "Total drive torque of the left wheels (drive.mode 0)") \
    REAL(202, "torqueRight",   INPUT, "N.m", 0.0,   -NOLIM, NOLIM, in.torqueRight,   "Total drive torque of the right wheels (drive.mode 0)") \
    REAL(203, "omegaRefLeft",  INPUT, "rad/s", 0.0, -NOLIM, NOLIM, in.omegaRefLeft,  "Wheel spin reference, left (drive.mode 1)") \
    REAL(204, "omegaRefRight", INPUT, "rad/s", 0.0, -NOLIM, NOLIM, in.omegaRefRight, "Wheel spin reference, right (drive.mode 1)") \
    REAL(205, "throttleLeft",  INPUT, "1",   0.45,  -1, 1, in.throttleLeft,  "Motor throttle, left (drive.mode 2)") \
    REAL(206, "throttleRight", INPUT, "1",   0.45,  -1, 1, in.throttleRight, "Motor throttle, right (drive.mode 2)") \
    /* ---- outputs ---- */ \
    REAL(300, "x",     OUTPUT, "m",   0, -NOLIM, NOLIM, out.x,     "Chassis reference point (between the rocker pivots), world x") \
    REAL(301, "y",     OUTPUT, "m",   0, -NOLIM, NOLIM, out.y,     "Chassis reference point, world y") \
    REAL(302, "z",     OUTPUT, "m",   0, -NOLIM, NOLIM, out.z,     "Chassis reference point, world z") \
    REAL(303, "roll",  OUTPUT, "rad", 0, -NOLIM, NOLIM, out.roll,  "Chassis roll (Z-Y-X Euler angles)") \
    REAL(304, "pitch", OUTPUT, "rad", 0, -NOLIM, NOLIM, out.pitch, "Chassis pitch, positive nose down") \
    REAL(305, "yaw",   OUTPUT, "rad", 0, -NOLIM, NOLIM, out.yaw,   "Chassis heading") \
    REAL(306, "vx",    OUTPUT, "m/s", 0, -NOLIM, NOLIM, out.vx,    "Forward speed along the heading (horizontal)") \
    REAL(307, "omegaLeft",  OUTPUT, "rad/s", 0, -NOLIM, NOLIM, out.omegaLeft,  "Wheel spin of the left side relative to its rocker (encoder)") \
    REAL(308, "omegaRight", OUTPUT, "rad/s", 0, -NOLIM, NOLIM, out.omegaRight, "Wheel spin of the right side relative to its rocker (encoder)") \
    REAL(309, "torqueLeftApplied",  OUTPUT, "N.m", 0, -NOLIM, NOLIM, out.torqueLeftApplied,  "Drive torque applied to the left wheels") \
    REAL(310, "torqueRightApplied", OUTPUT, "N.m", 0, -NOLIM, NOLIM, out.torqueRightApplied, "Drive torque applied to the right wheels") \
    REAL(311, "rocker", OUTPUT, "rad", 0, -NOLIM, NOLIM, out.rocker, "Left rocker angle relative to the chassis (right is its negative)") \
    REAL(312, "spinAngleLeft",  OUTPUT, "rad", 0, -NOLIM, NOLIM, out.spinAngleLeft,  "Wheel angle of the left side relative to its rocker, the integral of omegaLeft from 0 at initialisation (encoder angle)") \
    REAL(313, "spinAngleRight", OUTPUT, "rad", 0, -NOLIM, NOLIM, out.spinAngleRight, "Wheel angle of the right side relative to its rocker, the integral of omegaRight from 0 at initialisation (encoder angle)") \
    WHEEL_OUTPUTS(0, "FL", 400) \
    WHEEL_OUTPUTS(1, "RL", 410) \
    WHEEL_OUTPUTS(2, "FR", 420) \
    WHEEL_OUTPUTS(3, "RR", 430)
