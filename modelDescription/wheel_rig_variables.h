/*
 * The variable table of the WheelRig FMU (fmu_src/wheel_rig.h), in the
 * same X-macro form as the rover's (modelDescription/variables.h, which
 * explains the columns), included by the rig's accessors
 * (fmu_src/model_vars.c built for the rig) and by the generator of its
 * modelDescription.xml (modelDescription/generate.c), so the two cannot
 * disagree.  A variable the rover has too keeps the rover's name, unit,
 * range, start value and value reference.
 *
 * The declared range is what the FMU accepts: every value in [min, max]
 * passes the parameter checks when the other variables keep their start
 * values.  Whether the soil carries rig.load within the wheel's radius is
 * physics, reported as such at initialisation.
 */
#ifndef NOLIM
#define NOLIM HUGE_VAL
#endif

#define JUNO_VARIABLES \
    /* ---- soil: the four identified parameters (paper Table 2) and Mohr-Coulomb ---- */ \
    REAL(100, "soil.kh",        PARAM, "N/m^(2+eta)", 1.58e5, 1e-3, 1e8, p.soil_kh,    "Hyperelastic foundation stiffness k_h (> 0)") \
    REAL(101, "soil.eta",       PARAM, "1",      0.501,  1e-3, 2, p.soil_eta,      "Nonlinearity exponent eta (> 0)") \
    REAL(102, "soil.gamma",     PARAM, "1",      0.0813, 0, 1,     p.soil_gamma,    "Soil rebound as a fraction of the maximum sinkage") \
    REAL(103, "soil.Kvx",       PARAM, "1",      0.819,  1e-6, 100, p.soil_Kvx,      "Traction (shear velocity) modulus K_vx of Eqn 5 (> 0)") \
    REAL(104, "soil.KvyRatio",  PARAM, "1",      1.0,    1e-6, 100, p.soil_KvyRatio, "Lateral modulus as a multiple of K_vx (> 0; assumption: isotropic = 1)") \
    REAL(105, "soil.cohesion",  PARAM, "Pa",     1000.0, 0, 1e7, p.soil_cohesion, "Mohr-Coulomb cohesion C (assumed: dry sand)") \
    REAL(106, "soil.phi",       PARAM, "rad",    0.5236, 0, 1.5707, p.soil_phi,     "Internal friction angle (assumed: 30 deg, dry sand)") \
    REAL(110, "soil.A1",        CALC,  "1",      0.6667, -NOLIM, NOLIM, d.contact.A1,   "Eqn 3 exponent factor, fitted at initialisation") \
    REAL(111, "soil.Vint",      CALC,  "m3",     1e-3,   -NOLIM, NOLIM, d.contact.Vint, "Eqn 3 reference volume, fitted at initialisation") \
    /* ---- wheel ---- */ \
    REAL(120, "wheel.radius",   PARAM, "m",      0.2794, 0.01, 5, p.wheel_radius,  "Wheel radius including lugs (the Juno wheel: 22 in diameter)") \
    REAL(121, "wheel.width",    PARAM, "m",      0.254,  0.01, 1, p.wheel_width,   "Wheel width (the Juno wheel, assumed: ARGO 22x10.00-8)") \
    /* ---- the rig ---- */ \
    REAL(700, "rig.load",       PARAM, "N",      779.0,  1, 1e4, p.rig_load, "Vertical load the carriage puts on the wheel (weight of wheel and ballast); default a quarter of the Juno rover's weight") \
    REAL(701, "rig.mass",       PARAM, "kg",     0.0,    0, 1e4, p.rig_mass, "Vertically moving mass (wheel and the carriage part that follows it); 0 = rig.load / 9.81 m/s2") \
    REAL(703, "rig.movingMass", CALC,  "kg",     0.0,    -NOLIM, NOLIM, d.mass, "The vertically moving mass used: rig.mass, or rig.load / 9.81 m/s2 when rig.mass = 0") \
    INT (702, "rig.driveMode",  PARAM, 0, 0, 1, p.rig_driveMode, "0 = slip set (inputs rig.slip, rig.vx); 1 = spin set (inputs rig.omega, rig.vx)") \
    /* ---- Wong-Reece/Ishigami contact law (contact.model = 1; fmu_src/wong_reece.h), as in JunoRover ---- */ \
    REAL(160, "wongReece.n",    PARAM, "1",          1.1,     0.01, 5,    p.wr_n,    "Wong-Reece (contact.model 1): Bekker sinkage exponent n (> 0); default dry sand 1.1") \
    REAL(161, "wongReece.kc",   PARAM, "N/m^(n+1)",  990.0, -3.8e5, 1e8,  p.wr_kc,   "Wong-Reece (contact.model 1): Bekker cohesive modulus k_c (fitted sets may be < 0; kc / wheel.width + kphi must be > 0); default dry sand 0.99e3") \
    REAL(162, "wongReece.kphi", PARAM, "N/m^(n+2)",  1.528e6, 0, 1e10,    p.wr_kphi, "Wong-Reece (contact.model 1): Bekker frictional modulus k_phi (kc / wheel.width + kphi must be > 0); default dry sand 1.528e6") \
    REAL(163, "wongReece.K",    PARAM, "m",          0.010,   1e-6, 10,   p.wr_K,    "Wong-Reece (contact.model 1): Janosi-Hanamoto shear deformation modulus K (> 0); default dry sand 10 mm") \
    REAL(164, "wongReece.a0",   PARAM, "1",          0.40,    0.15, 0.84, p.wr_a0,   "Wong-Reece (contact.model 1): peak stress angle theta_m = (a0 + a1 slip) theta_f, |a1| <= a0 < 1 - |a1|; default 0.40 (Ishigami 2007)") \
    REAL(165, "wongReece.a1",   PARAM, "1",          0.15,   -0.4, 0.4,   p.wr_a1,   "Wong-Reece (contact.model 1): slip coefficient a1 of the peak angle, |a1| <= a0 and |a1| < 1 - a0; default 0.15 (Ishigami 2007)") \
    INT (166, "wongReece.points", PARAM, 100, 6, 1000000, p.wr_points, "Wong-Reece (contact.model 1): integrand evaluations per contact (Simpson, front and rear regions)") \
    /* ---- numerics ---- */ \
    INT (180, "contact.method",    PARAM, 0, 0, 1, p.contact_method, "0 = closed form Eqn 3; 1 = direct quadrature of the hypervolume (reference)") \
    REAL(181, "contact.slipVelocityEps", PARAM, "m/s", 0.05, 1e-6, NOLIM, p.contact_slipVelocityEps, "Slip denominator floor (> 0): below this speed the shear law is viscous") \
    INT (183, "contact.model",     PARAM, 0, 0, 1, p.contact_model, "Contact law: 0 = volumetric (Petersen-McPhee, the paper); 1 = Wong-Reece/Ishigami integrated rim stresses (wongReece.*, soil.cohesion, soil.phi, rebound soil.gamma)") \
    REAL(182, "solver.step",       PARAM, "s",   1e-3, 1e-6, 0.1, p.solver_step, "Largest internal integration step") \
    /* ---- contact extensions beyond the paper's model, as in JunoRover; each is off at its default ---- */ \
    REAL(197, "slipSinkage.coefficient", PARAM, "1", 0.0, 0, 50, p.slipSinkage_coefficient, "Slip-sinkage: k_h / (1 + c |slip|) (0 = off)") \
    REAL(507, "slipSinkage.exponent", PARAM, "1", 1.0, 0.25, 4, p.slipSinkage_exponent, "Slip-sinkage exponent p: k_h / (1 + c |slip|^p) (1 = the linear law)") \
    REAL(198, "grouser.thrustGain", PARAM, "1", 0.0, 0, 5, p.grouser_thrustGain, "Grouser/lug thrust beyond Mohr-Coulomb: F_taumax (1 + g) (0 = off)") \
    REAL(508, "grouser.thrustSlip", PARAM, "1", 0.0, 0, 1, p.grouser_thrustSlip, "Slip s_g over which the grouser thrust builds up: F_taumax (1 + g (1 - exp(-|slip| / s_g))) (0 = the full gain at any slip)") \
    REAL(189, "grouser.lugHeight", PARAM, "m", 0.0, 0, 0.1, p.grouser_lugHeight, "Grouser/lug height: the lugs shear the soil at R + h, h beyond the rim the normal law presses on (0 = off; volumetric law only)") \
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
