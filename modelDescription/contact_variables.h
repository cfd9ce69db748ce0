/*
 * The variables of the wheel/soil contact law that both FMUs declare: the
 * rover's table (variables.h, which explains the columns) and the rig's
 * (wheel_rig_variables.h) each include these groups, so a parameter the
 * two share is declared once and means the same in both: name, value
 * reference, unit, start value, range and description.
 */
/* The soil: the four identified parameters (paper Table 2), the lateral modulus, Mohr-Coulomb's
 * cohesion and friction angle, and the two constants of Eqn 3 fitted at initialisation. */
#define JUNO_SOIL_VARIABLES \
    REAL(100, "soil.kh",        PARAM, "N/m^(2+eta)", 1.58e5, 1e-3, 1e8, p.soil_kh,    "Hyperelastic foundation stiffness k_h (> 0)") \
    REAL(101, "soil.eta",       PARAM, "1",      0.501,  1e-3, 2, p.soil_eta,      "Nonlinearity exponent eta (> 0)") \
    REAL(102, "soil.gamma",     PARAM, "1",      0.0813, 0, 1,     p.soil_gamma,    "Soil rebound as a fraction of the maximum sinkage") \
    REAL(103, "soil.Kvx",       PARAM, "1",      0.819,  1e-6, 100, p.soil_Kvx,      "Traction (shear velocity) modulus K_vx of Eqn 5 (> 0)") \
    REAL(104, "soil.KvyRatio",  PARAM, "1",      1.0,    1e-6, 100, p.soil_KvyRatio, "Lateral modulus as a multiple of K_vx (> 0; assumption: isotropic = 1)") \
    REAL(105, "soil.cohesion",  PARAM, "Pa",     1000.0, 0, 1e7, p.soil_cohesion, "Mohr-Coulomb cohesion C (assumed: dry sand)") \
    REAL(106, "soil.phi",       PARAM, "rad",    0.5236, 0, 1.5707, p.soil_phi,     "Internal friction angle (assumed: 30 deg, dry sand)") \
    REAL(110, "soil.A1",        CALC,  "1",      0.6667, -NOLIM, NOLIM, d.contact.A1,   "Eqn 3 exponent factor, fitted at initialisation") \
    REAL(111, "soil.Vint",      CALC,  "m3",     1e-3,   -NOLIM, NOLIM, d.contact.Vint, "Eqn 3 reference volume, fitted at initialisation")

/* The Wong-Reece/Ishigami contact law (contact.model = 1; fmu_src/wong_reece.h).  Defaults: the dry
 * sand set (Wong, Land Locomotion Lab); cohesion and phi are soil.cohesion and soil.phi (defaults
 * 1 kPa, 30 deg; the set has 1.04 kPa, 28 deg), the rear rebound lambda is soil.gamma. */
#define JUNO_WONG_REECE_VARIABLES \
    REAL(160, "wongReece.n",    PARAM, "1",          1.1,     0.01, 5,    p.wr_n,    "Wong-Reece (contact.model 1): Bekker sinkage exponent n (> 0); default dry sand 1.1") \
    REAL(161, "wongReece.kc",   PARAM, "N/m^(n+1)",  990.0, -3.8e5, 1e8,  p.wr_kc,   "Wong-Reece (contact.model 1): Bekker cohesive modulus k_c (fitted sets may be < 0; kc / wheel.width + kphi must be > 0); default dry sand 0.99e3") \
    REAL(162, "wongReece.kphi", PARAM, "N/m^(n+2)",  1.528e6, 0, 1e10,    p.wr_kphi, "Wong-Reece (contact.model 1): Bekker frictional modulus k_phi (kc / wheel.width + kphi must be > 0); default dry sand 1.528e6") \
    REAL(163, "wongReece.K",    PARAM, "m",          0.010,   1e-6, 10,   p.wr_K,    "Wong-Reece (contact.model 1): Janosi-Hanamoto shear deformation modulus K (> 0); default dry sand 10 mm") \
    REAL(164, "wongReece.a0",   PARAM, "1",          0.40,    0.15, 0.84, p.wr_a0,   "Wong-Reece (contact.model 1): peak stress angle theta_m = (a0 + a1 slip) theta_f, |a1| <= a0 < 1 - |a1|; default 0.40 (Ishigami 2007)") \
    REAL(165, "wongReece.a1",   PARAM, "1",          0.15,   -0.4, 0.4,   p.wr_a1,   "Wong-Reece (contact.model 1): slip coefficient a1 of the peak angle, |a1| <= a0 and |a1| < 1 - a0; default 0.15 (Ishigami 2007)") \
    INT (166, "wongReece.points", PARAM, 100, 6, 1000000, p.wr_points, "Wong-Reece (contact.model 1): integrand evaluations per contact (Simpson, front and rear regions)")

/* The contact law's numerics and choice of law. */
#define JUNO_CONTACT_NUMERICS_VARIABLES \
    INT (180, "contact.method",    PARAM, 0, 0, 1, p.contact_method, "0 = closed form Eqn 3; 1 = direct quadrature of the hypervolume (reference)") \
    REAL(181, "contact.slipVelocityEps", PARAM, "m/s", 0.05, 1e-6, NOLIM, p.contact_slipVelocityEps, "Slip denominator floor (> 0): below this speed the shear law is viscous") \
    INT (183, "contact.model",     PARAM, 0, 0, 1, p.contact_model, "Contact law: 0 = volumetric (Petersen-McPhee, the paper); 1 = Wong-Reece/Ishigami integrated rim stresses (wongReece.*, soil.cohesion, soil.phi, rebound soil.gamma)")

/* Contact extensions beyond the paper's model that act on one wheel's law (slip-sinkage, grouser
 * thrust and lugs); each is off at its default. */
#define JUNO_CONTACT_EXTENSION_VARIABLES \
    REAL(197, "slipSinkage.coefficient", PARAM, "1", 0.0, 0, 50, p.slipSinkage_coefficient, "Slip-sinkage: k_h / (1 + c |slip|) (0 = off)") \
    REAL(507, "slipSinkage.exponent", PARAM, "1", 1.0, 0.25, 4, p.slipSinkage_exponent, "Slip-sinkage exponent p: k_h / (1 + c |slip|^p) (1 = the linear law)") \
    REAL(198, "grouser.thrustGain", PARAM, "1", 0.0, 0, 5, p.grouser_thrustGain, "Grouser/lug thrust beyond Mohr-Coulomb: F_taumax (1 + g) (0 = off)") \
    REAL(508, "grouser.thrustSlip", PARAM, "1", 0.0, 0, 1, p.grouser_thrustSlip, "Slip s_g over which the grouser thrust builds up: F_taumax (1 + g (1 - exp(-|slip| / s_g))) (0 = the full gain at any slip)") \
    REAL(189, "grouser.lugHeight", PARAM, "m", 0.0, 0, 0.1, p.grouser_lugHeight, "Grouser/lug height: the lugs shear the soil at R + h, h beyond the rim the normal law presses on (0 = off; volumetric law only)")
