/*
 * The soil's force on one rigid wheel, independent of the vehicle and of
 * any frame: what the rover (rover_wheel_contact.c, four wheels on a
 * terrain) and the single-wheel test rig (wheel_rig.c) share, so both run
 * the same contact law.
 *
 * The caller describes the wheel in its own contact frame: the heading f
 * (in the contact plane, within the wheel's mid-plane), the soil normal
 * np (within the mid-plane) and the lateral direction l = n x f.  What
 * comes back is the force in that frame's terms (Eqns 6-9):
 *   force = Fn nvec + F_long t + F_lat l,
 *   nvec  = -sin(alpha) f + cos(alpha) np   (from the centroid to the hub),
 *   t     =  cos(alpha) f + sin(alpha) np,
 * with the shear acting on the rim point -shear_radius nvec from the hub,
 * so its moment about the axle is -shear_radius F_long and the normal
 * force passes through the hub.
 *
 * Three stages, because the lateral slip velocity the shear needs is that
 * of the rim point on the tilted ray, which only the caller's kinematics
 * know:
 *   1. wheel_soil_slip    the longitudinal slip and the soil factors that
 *                         depend on it (slip-sinkage, grouser thrust) or
 *                         on the wheel's angle (lug ripple);
 *   2. wheel_soil_normal  the normal force, its tilt alpha, the contact
 *                         area and the normal stiffness, from the law
 *                         chosen (volumetric or Wong-Reece/Ishigami);
 *   3. wheel_soil_shear   the traction and lateral force (the slip-vector
 *                         shear law, contact_shear) and their Jacobian.
 * Plain structs in, plain structs out; no allocation, no global state.
 */
#ifndef JUNO_WHEEL_SOIL_H
#define JUNO_WHEEL_SOIL_H

#include "contact.h"
#include "wong_reece.h"

enum { CONTACT_LAW_VOLUMETRIC = 0, CONTACT_LAW_WONG_REECE = 1 };

/* What both contact laws are prepared from: the FMU variables soil.*, wheel.radius, wheel.width,
 * contact.* and wr.*, which every model that uses this file declares under the same names in
 * its Params.  SOIL_LAWS_OF(p) gathers them from a model's Params p. */
typedef struct {
    double kh, eta, gamma, Kvx, Kvy_ratio, cohesion, phi, radius, width, slip_v_eps;
    int method, law;
    double wr_n, wr_kc, wr_kphi, wr_K, wr_a0, wr_a1;
    int wr_points;
} SoilLaws;

#define SOIL_LAWS_OF(p)                                                                        \
    ((SoilLaws){(p)->soil_kh, (p)->soil_eta, (p)->soil_gamma, (p)->soil_Kvx, (p)->soil_KvyRatio, \
                (p)->soil_cohesion, (p)->soil_phi, (p)->wheel_radius, (p)->wheel_width,          \
                (p)->contact_slipVelocityEps, (p)->contact_method, (p)->contact_model,           \
                (p)->wr_n, (p)->wr_kc, (p)->wr_kphi, (p)->wr_K, (p)->wr_a0, (p)->wr_a1,           \
                (p)->wr_points})

/* Prepares both contact laws from s: the volumetric law (checked, the Eqn 3 fit made) into cm
 * and the Wong-Reece/Ishigami law into wm, the latter checked whatever contact.model is, so a
 * bad value is reported when it is set, not when the law is switched on later (its messages
 * name the FMU variables).  Returns 0, or -1 with the first problem in err. */
int wheel_soil_prepare_laws(const SoilLaws *s, ContactModel *cm, WongReeceModel *wm, char *err, size_t errlen);

/* The law's constants for one wheel: both contact laws prepared
 * (contact_model_prepare, wong_reece_prepare) and the extensions beyond
 * the paper's model that act at the contact, off at 0. */
typedef struct {
    const ContactModel *contact;        /* volumetric law; its shear law serves both */
    const WongReeceModel *wong_reece;   /* used when law = CONTACT_LAW_WONG_REECE */
    int law;                            /* CONTACT_LAW_VOLUMETRIC or CONTACT_LAW_WONG_REECE */
    double slip_sinkage;                /* slipSinkage.coefficient: k_h / (1 + c |slip|), volumetric */
    double thrust_gain;                 /* grouser.thrustGain: F_taumax (1 + g) */
    double lug_height;                  /* grouser.lugHeight, m: shear radius R + h (volumetric) */
    double slip_sinkage_power;          /* slipSinkage.exponent p: k_h / (1 + c |slip|^p); 0 or 1: linear */
    double thrust_slip;                 /* grouser.thrustSlip s_g: F_taumax (1 + g (1 - exp(-|slip| / s_g))); 0: (1 + g) */
    double lug_count;                   /* grouser.lugCount N: lugs per wheel, 0: no ripple */
    double ripple_amplitude;            /* grouser.rippleAmplitude a: F_taumax (1 + a cos(N theta + phi)), 0: off */
} WheelSoil;

/* The wheel's state relative to the soil, in its contact frame. */
typedef struct {
    double sinkage;                     /* of the lowest rim point below the soil surface, m (> 0: in the soil) */
    double v_long;                      /* hub speed along the heading f, m/s */
    double spin;                        /* wheel spin about its axle, rad/s (positive rolls forward) */
    double kh_factor;                   /* local k_h relative to soil.kh (soil patch, rut), 1: none */
    double strength_factor;             /* local shear strength relative to the soil's, 1: none */
    double spin_angle;                  /* theta, the wheel's angle about its axle, rad (lug ripple) */
    double lug_phase;                   /* phi, the ripple's phase at theta = 0, rad (lug ripple) */
} WheelSoilInput;

/* The Wong-Reece/Ishigami law at one wheel mapped onto the volumetric
 * law's representation (wheel_soil.c says how). */
typedef struct {
    double Fn, sin_alpha, cos_alpha, F_long;   /* the Eqn 8-9 representation */
    double Fx, Fz;                             /* applied along the heading and the soil normal, N */
    double area;                               /* b r (sin theta_f - sin theta_r), m^2 */
    double dFx_ds, dFz_ds, dFt_ds;             /* derivatives in the slip, N */
    double kz;                                 /* dFz / d(sinkage), N/m */
} WongReeceContact;

/* What stages 1 and 2 find; stage 3 reads it. */
typedef struct {
    /* wheel_soil_slip */
    double omega_r;                     /* spin times the rim radius R, m/s */
    double den;                         /* slip denominator max(|omega R|, |v_long|, eps), m/s */
    double slip;                        /* (omega R - v_long) / den */
    double kh_factor;                   /* the input's, with slip-sinkage */
    double shear_factor;                /* F_taumax scaling: strength, grouser thrust, lug ripple */
    double shear_radius;                /* where the shear acts: R + lug height (volumetric), R (WR), m */
    /* wheel_soil_normal */
    int wong_reece;                     /* the law is Wong-Reece */
    WongReeceContact wr;                /* that law's result (set with Wong-Reece only) */
    double Fn;                          /* normal force, N */
    double sin_alpha, cos_alpha;        /* its tilt as applied (Eqn 7 times the rolling factor) */
    double area;                        /* contact area, m^2 */
    double support;                     /* normal load of the shear law, N */
    double kn;                          /* normal stiffness, N/m: dFn/d(sinkage) at fixed cuts
                                         * (volumetric), dFz/d(sinkage) (Wong-Reece) */
} WheelSoilContact;

/* Stage 1: the slip of a wheel in the soil and the factors that depend on
 * it (fills omega_r, den, slip, kh_factor, shear_factor, shear_radius). */
void wheel_soil_slip(const WheelSoil *ws, const WheelSoilInput *in, WheelSoilContact *c);

/* Stage 2: the normal force, its tilt, the area and the stiffness at the
 * sinkage, with the soil memory mem (volumetric).  derivatives: also the
 * Wong-Reece slip and sinkage derivatives (for an implicit integrator). */
void wheel_soil_normal(const WheelSoil *ws, const ContactMemory *mem, const WheelSoilInput *in,
                       int derivatives, WheelSoilContact *c);

/* Stage 3: the traction F_long along t and the lateral force F_lat along
 * l (N) for a lateral slip velocity v_lat (m/s, of the rim point on the
 * tilted ray, along l).  If jac != NULL, also d(F_long, F_lat) / d(v_long,
 * v_lat, shear_radius spin), row-major 2 x 3; with the Wong-Reece law its
 * first row is 0 (that law's traction derivatives are c->wr.dF*_ds). */
void wheel_soil_shear(const WheelSoil *ws, const WheelSoilContact *c, const WheelSoilInput *in, double v_lat,
                      double *F_long, double *F_lat, double *jac);

/* Stages 2 and 3 for n wheels side by side (a rover's four): mem[i],
 * in[i], c[i] (and v_lat[i], out[i]) are wheel i's, the results those of
 * wheel_soil_normal and wheel_soil_shear bit for bit (out[i].jac only if
 * jacobians).  The volumetric law's patches and the shear laws are
 * computed together (contact_patches, contact_shears), so that the
 * wheels' chains of dependent library calls overlap; the Wong-Reece law's
 * integrations one wheel after another. */
void wheel_soil_normals(const WheelSoil *ws, int n, const ContactMemory *mem, const WheelSoilInput *in,
                        int derivatives, WheelSoilContact *c);
void wheel_soil_shears(const WheelSoil *ws, int n, const WheelSoilContact *c, const WheelSoilInput *in,
                       const double *v_lat, int jacobians, ShearForce *out);

#endif
