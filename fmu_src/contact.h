/*
 * Volumetric wheel/soil contact (Petersen & McPhee 2013), in SI units.
 *
 * The model is split MuJoCo-style: ContactModel holds constants (soil,
 * wheel geometry, the Eqn 3 fit) that change only when parameters change;
 * ContactMemory holds the per-wheel soil history that the rover integrates;
 * everything else is a pure function of its arguments.
 *
 * Geometry (2-D, in the wheel's mid-plane; hub frame: x forward, z up, hub
 * at the origin).  The soil surface is a straight line at z = -(R - z_s)
 * where z_s >= 0 is the sinkage of the lowest rim point below the surface.
 * The contact patch is split at the lowest point into a front half
 * (x >= 0) and a rear half (x <= 0).  Soil rebound removes a layer of
 * thickness c (the "cut") from a half: that half's surface sits c lower, so
 * its penetration depth is d(x) - c with d(x) = sqrt(R^2 - x^2) - (R - z_s).
 * A half with depth z_s - c <= 0 carries nothing.
 */
#ifndef JUNO_CONTACT_H
#define JUNO_CONTACT_H

#include <stddef.h>

enum { CONTACT_CLOSED_FORM = 0, CONTACT_QUADRATURE = 1 };

typedef struct {
    /* soil (identified) */
    double kh;          /* hyperelastic stiffness, N/m^(2+eta) */
    double eta;         /* nonlinearity exponent, > 0 */
    double gamma;       /* soil rebound fraction, [0, 1] */
    double Kvx;         /* traction (shear velocity) modulus, > 0 */
    double Kvy_ratio;   /* lateral modulus = Kvy_ratio * Kvx, > 0 */
    /* soil (Mohr-Coulomb) */
    double cohesion;    /* Pa, >= 0 */
    double phi;         /* internal friction angle, rad, [0, pi/2) */
    /* wheel */
    double radius;      /* m, > 0 */
    double width;       /* m, > 0 */
    /* numerics */
    double slip_v_eps;  /* m/s, > 0: slip denominator floor, see contact_shear */
    int method;         /* CONTACT_CLOSED_FORM (Eqn 3) or CONTACT_QUADRATURE */

    /* derived by contact_model_prepare(); read-only afterwards (a changed
     * parameter above needs contact_model_prepare again) */
    double A1;          /* Eqn 3 exponent factor (-> 2/3 at shallow sinkage) */
    double Vint;        /* Eqn 3 reference volume, m^3 (full symmetric segment) */
    double cx_eta;      /* half-patch hypervolume centroid: xbar = cx_eta * half_length */
    double cz_eta;      /* half-patch column centre: depth of centroid = cz_eta * half_depth */
    double tan_phi;
    double vh_exp;      /* A1 (eta - 1): Vh = V (2 V / Vint)^vh_exp (Eqn 3) */
    double log_Vint;    /* ln Vint, so that the power is exp(vh_exp (ln 2V - ln Vint)) */
    double inv_Kvx;     /* 1 / Kvx: the shear law's slip scale, longitudinal */
    double inv_Kvy;     /* 1 / (Kvy_ratio Kvx): lateral */
    double inv_R2;      /* 1 / radius^2 */
    double half_volume_factor; /* (width radius^2 / 2) (2 radius)^-3/2: a shallow half's volume over h^3/2 H (contact.c) */
    double shallow_scale;      /* 4 / radius: a shallow half's depth h to the polynomial's variable 4h/R - 1 */
} ContactModel;

typedef struct {
    double sinkage;     /* z_s, m (input echoed) */
    double V;           /* penetration volume, m^3 */
    double Vh;          /* hypervolume, m^(2+eta) */
    double area;        /* contact patch area (projected length * width), m^2 */
    double length_front, length_rear; /* m, half lengths actually in contact */
    double xc, zc;      /* hypervolume centroid in the hub frame, m */
    double Fn;          /* normal force magnitude k_h * Vh, N */
    double dFn_dz;      /* normal stiffness dFn/d(sinkage) at fixed cuts, N/m (see contact_patch) */
    /* Tilt alpha of the normal force (Eqn 7), alpha = atan2(xc, -zc), > 0
     * when the centroid is ahead; given as its sine and cosine (what the
     * force needs; atan2(sin_alpha, cos_alpha) recovers the angle). */
    double sin_alpha, cos_alpha;
} ContactPatch;

typedef struct {
    double zmax;        /* deepest sinkage the soil under the wheel has seen, m */
    double travel;      /* signed distance rolled since the soil under the wheel was virgin, m */
} ContactMemory;

/* Validates parameters, computes A1, Vint (least-squares fit of
 * ln(Vh/V) against ln(V) on quadrature over sinkage 5..80 mm, full
 * symmetric segment) and the centroid factors.  Returns 0 on success, or
 * -1 with a message naming the bad parameter written to err. */
int contact_model_prepare(ContactModel *m, char *err, size_t errlen);

/* Hypervolume of the patch, its volume, area and centroid, and Fn, for
 * sinkage z_s and cuts c_front, c_rear (each clamped to [0, z_s]).
 * Uses m->method.  No allocation; safe for z_s <= 0 (all zero, alpha 0).
 * dFn_dz is the derivative of Fn with respect to z_s with the cuts held
 * fixed (what the linearly implicit integrator needs): closed form, exact
 * derivative of Eqn 3 per half, dVh/dh = (1 + A1 (eta-1)) Vh b L / V
 * (dV/dh of a half segment is its half chord L times the width b);
 * quadrature, a forward difference over 1e-5 h of the two half
 * quadratures (the reference method pays one more quadrature for it). */
void contact_patch(const ContactModel *m, double sinkage, double cut_front,
                   double cut_rear, ContactPatch *out);

/* How many patches (and shears) contact_patches (contact_shears) computes
 * side by side: a rover's four wheels. */
enum { CONTACT_BATCH = 4 };

/* contact_patch for n patches, sinkage[i], cut_front[i], cut_rear[i] into
 * out[i], the same values bit for bit.  Faster than n calls: each patch is
 * a chain of dependent library calls (sqrt, log, exp, divisions),
 * and computed stage by stage together, CONTACT_BATCH at a time, the
 * chains overlap in the processor. */
void contact_patches(const ContactModel *m, int n, const double *sinkage, const double *cut_front,
                     const double *cut_rear, ContactPatch *out);

/* Reference: quadrature of the hypervolume of ONE half-patch of depth h
 * (m) with exponent eta; returns m^(2+eta).  Also the exact plain volume of
 * a half segment.  Exposed for tests and the Eqn 3 fit. */
double contact_half_hypervolume_quadrature(double radius, double width,
                                           double eta, double h);
double contact_half_volume(double radius, double width, double h);

/* Shear force (Eqn 5 generalised to the slip-velocity vector).
 * v_long, v_lat: hub velocity along the wheel heading and along the axle
 * in the contact plane (m/s); omega_r: absolute spin times radius (m/s).
 * den = max(|omega_r|, |v_long|, slip_v_eps);
 * s_long = (omega_r - v_long)/den, s_lat = -v_lat/den (elliptic scaling by
 * Kvy_ratio); F = F_taumax * tanh(|s_scaled|) along the slip direction,
 * F_taumax = area * cohesion + Fn * tan(phi).  Straight running (v_lat = 0)
 * gives exactly F_long = F_taumax tanh(s_long / Kvx).
 * Outputs the force (N) along heading and axle and, if jac != NULL, its
 * Jacobian d(F_long, F_lat)/d(v_long, v_lat, omega_r), row-major 2x3. */
void contact_shear(const ContactModel *m, double Fn, double area,
                   double v_long, double v_lat, double omega_r,
                   double *F_long, double *F_lat, double *jac);

/* contact_shear's arguments and results, for contact_shears. */
typedef struct {
    double Fn, area;                    /* N, m^2 */
    double v_long, v_lat, omega_r;      /* m/s */
} ShearInput;
typedef struct {
    double F_long, F_lat;               /* N */
    double jac[6];                      /* d(F_long, F_lat)/d(v_long, v_lat, omega_r), row-major 2x3 */
} ShearForce;

/* contact_shear for n wheels, in[i] into out[i] (the Jacobian only if
 * jacobians), the same values bit for bit; side by side, CONTACT_BATCH at
 * a time, as contact_patches. */
void contact_shears(const ContactModel *m, int n, const ShearInput *in, ShearForce *out, int jacobians);

/* Rear/front cuts implied by the memory at the current sinkage:
 * the half the wheel has rolled over (rear when travel > 0) is cut by
 * phi * (1 - gamma) * zmax with phi = min(1, |travel| / L), L the half
 * contact length at zmax; a wheel that has not rolled has symmetric contact. */
void contact_cuts(const ContactModel *m, const ContactMemory *mem,
                  double sinkage, double *cut_front, double *cut_rear);

/* Factor in [-1, 1] on the tilt alpha of the normal force (Eqn 7) at hub
 * speed v_long (m/s): sign(travel) * clamp(v_long / slip_v_eps, -1, 1).
 * Assumption: rebound acts only on soil the wheel has passed over, so
 * rolling resistance always opposes
 * the motion, a standing wheel is supported vertically (a rover that
 * stops does not creep), and rolling at slip_v_eps or faster in the
 * direction that shaped the patch gives the paper's model exactly.  The
 * normal force magnitude is unchanged, so the regularisation adds no
 * energy. */
double contact_rolling_factor(const ContactModel *m, const ContactMemory *mem, double v_long);

/* Explicit update of the memory over dt (s) with the current sinkage and
 * the hub's speed along the heading (m/s).  zmax follows deeper sinkage at
 * once and relaxes towards shallower sinkage over one half contact length
 * of travel; travel integrates v_long and saturates at +-L; lift-off
 * (sinkage <= 0) resets the memory (virgin soil). */
void contact_memory_update(const ContactModel *m, ContactMemory *mem,
                           double sinkage, double v_long, double dt);

#endif
