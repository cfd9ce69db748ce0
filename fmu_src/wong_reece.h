/*
 * Classical terramechanics wheel model (Wong & Reece 1967, in the form used
 * by Ishigami et al. 2007), in SI units.  Kept beside the volumetric model
 * (contact.h) as a speed and accuracy baseline: it integrates normal and
 * shear stress around the rim instead of using a hypervolume.
 *
 * Same split as contact.h: WongReeceModel holds constants that change only
 * when parameters change (validated, with derived values, by
 * wong_reece_prepare); everything else is a pure, allocation-free function.
 *
 * Geometry (2-D, the wheel's mid-plane).  Angles theta are measured at the
 * hub from the downward vertical, positive towards the direction of travel
 * (the front).  A rigid wheel of radius r, width b sinks h below the
 * original (flat) soil surface:
 *   entry  theta_f =  acos(1 - h/r)            (virgin surface, front)
 *   exit   theta_r = -acos(1 - lambda h/r)     (rebounded surface, rear)
 *   peak   theta_m = (a0 + a1 s) theta_f       (largest normal stress)
 * lambda is the rebound of the soil behind the wheel as a fraction of h: the
 * rear surface sits (1 - lambda) h below the original one, which is exactly
 * the volumetric model's gamma (contact.h).  lambda = 0 is
 * front-only contact (theta_r = 0), Wong and Reece's driven-wheel case.
 *
 * Stresses (Wong and Reece 1967, with the peak angle of Ishigami et al.
 * 2007), with k = r^n (kc/b + kphi):
 *   front (theta_m..theta_f): sigma = k (cos t - cos t_f)^n
 *   rear  (theta_r..theta_m): sigma = k (cos t* - cos t_f)^n,
 *         t* = t_f - (t - t_r)/(t_m - t_r) (t_f - t_m)  (the front profile
 *         mapped linearly onto the rear, so sigma is continuous at t_m and 0
 *         at t_r)
 *   shear displacement j = r [(t_f - t) - rho (sin t_f - sin t)],
 *         rho = v / (r omega) (see slip below)
 *   tau = sign(j) (c + sigma tan phi) (1 - exp(-|j|/K))   (Janosi-Hanamoto)
 * Forces on the wheel from the soil:
 *   Fx = r b int (tau cos t - sigma sin t) dt   drawbar pull, + forward
 *   Fz = r b int (tau sin t + sigma cos t) dt   vertical load carried, + up
 *   T  = r^2 b int tau dt                       resisting torque: the drive
 *                                              torque needed in steady state
 *
 * Slip, s in [-1, 1], the same definition as contact.c's S_long
 * (Ishigami 2007): s = (r omega - v) / max(|r omega|, |v|) for a wheel
 * moving forwards (v >= 0, omega >= 0).  Driving (s >= 0): rho = 1 - s,
 * exactly the notes' j.  Braking (s < 0): s = (r omega - v)/v, so
 * rho = 1/(1 + s); s = -1 is a locked wheel (every j -> -infinity, tau at the
 * Mohr-Coulomb limit against the motion).  Both branches agree to first
 * order at s = 0.  A wheel moving backwards is the mirror image: the caller
 * flips the signs of v, omega and Fx, T.
 *
 * Assumptions, named:
 *  - tau is odd in j.  The notes' (1 - exp(-j/K)) grows without bound for
 *    j < 0, which braking produces (j >= 0 whenever s >= 0); soil sheared
 *    the other way resists the other way with the same law.
 *  - h is clamped to [0, r] (theta_f <= 90 deg): deeper than the hub the
 *    soil would close over the rim, which the model does not describe.  NaN
 *    sinkage is treated as 0 (no contact), as in contact.c.
 *  - s is clamped to [-1, 1]; NaN slip is treated as 0.
 *  - theta_m is clamped to [theta_r, theta_f]; wong_reece_prepare already
 *    requires 0 <= a0 + a1 s < 1 for every s in [-1, 1].
 *  - Shear acts only along the rim (no lateral force, no bulldozing, no
 *    grousers, no slip-sinkage); the soil surface is flat and level.
 *
 * Properties of the equations themselves (measured by the tests, Juno
 * wheel, 779 N), worth knowing before comparing with the volumetric model:
 *  - j is not zero at s = 0 (the rim follows a circle, the soil does not),
 *    so s = 0 is not free rolling.  A towed wheel (T = 0) runs at
 *    s ~ -0.08 and resists with ~0.26-0.29 of the load, close to Bekker's
 *    compaction resistance b k h^(n+1)/(n+1).  With a small K (dry sand,
 *    10 mm) the pull at s = 0 is already ~0, not negative.
 *  - Cohesion acts at zero normal stress, so at micrometre sinkage a
 *    braked wheel (and, for n > 1, any wheel at femtometre sinkage) gets
 *    Fz < 0: the rim shear pulls it down.  Above 0.1 mm Fz > 0.  A locked
 *    wheel's Fz also stops growing just short of hub depth.
 *  - At constant load, pull rises with driving slip on Toyoura sand; on dry
 *    sand (shear saturated by s ~ 0.3) it peaks near s = 0.6 and falls a
 *    few percent as the sinkage grows.
 */
#ifndef JUNO_WONG_REECE_H
#define JUNO_WONG_REECE_H

#include <stddef.h>

/* Default number of integration points (integrand evaluations per call). */
enum { WONG_REECE_DEFAULT_POINTS = 100 };
/* Accepted range of WongReeceModel.points. */
enum { WONG_REECE_MIN_POINTS = 6, WONG_REECE_MAX_POINTS = 1000000 };

typedef struct {
    /* soil: Bekker pressure-sinkage */
    double n;           /* sinkage exponent, > 0 */
    double kc;          /* cohesive modulus, N/m^(n+1), finite (fitted sets can be < 0) */
    double kphi;        /* frictional modulus, N/m^(n+2), finite; kc/b + kphi > 0 */
    /* soil: Mohr-Coulomb and Janosi-Hanamoto */
    double cohesion;    /* c, Pa, >= 0 */
    double phi;         /* internal friction angle, rad, [0, pi/2) */
    double K;           /* shear deformation modulus, m, > 0 */
    /* wheel-soil interaction */
    double a0, a1;      /* peak angle theta_m = (a0 + a1 s) theta_f */
    double lambda;      /* rear rebound ratio (= gamma), [0, 1] */
    /* wheel */
    double radius;      /* m, > 0 */
    double width;       /* m, > 0 */
    /* numerics */
    int points;         /* integrand evaluations, [6, 1e6]; 100 is the default */

    /* derived by wong_reece_prepare(); read-only afterwards */
    double k_sigma;     /* r^n (kc/b + kphi), Pa: stress at unit (cos t - cos t_f)^n */
    double tan_phi;
    double r_over_K;    /* radius / K: j/K per unit of j/r */
    int intervals;      /* even number of Simpson intervals shared by the two regions */
} WongReeceModel;

typedef struct {
    double sinkage;     /* h actually used (clamped to [0, r]), m */
    double slip;        /* s actually used (clamped to [-1, 1]) */
    double theta_f, theta_r, theta_m; /* rad */
    double sigma_m;     /* normal stress at theta_m (the peak), Pa */
    double Fx;          /* drawbar pull, N (+ forward; < 0 is resistance) */
    double Fz;          /* vertical load carried, N (+ up) */
    double T;           /* resisting torque, N m (drive torque needed) */
} WRForces;

/* Validates every parameter and computes the derived values.  Returns 0 on
 * success, or -1 with a message naming the bad parameter written to err
 * (e.g. "wongReece.K must be finite and > 0 (got 0)"). */
int wong_reece_prepare(WongReeceModel *m, char *err, size_t errlen);

/* Forces at sinkage h (m) and slip s, by composite Simpson quadrature with
 * at most m->points integrand evaluations: the front (theta_m..theta_f) and
 * rear (theta_r..theta_m) regions are integrated separately, since sigma has
 * a kink at theta_m, with intervals shared in proportion to their angular
 * lengths.  No allocation; never NaN for a prepared model (h <= 0 gives all
 * forces 0). */
void wong_reece_forces(const WongReeceModel *m, double sinkage, double slip,
                       WRForces *out);

/* Sinkage (m) at which the wheel carries the vertical load Fz (N) at slip s:
 * doubling search from 1e-6 r for the first bracket with Fz(h) >= load, then
 * Brent's method to 1e-10 m.  Returns 0 for load <= 0 or NaN, and r (the
 * model's limit, see the assumptions above) when even h = r carries less
 * than the load: callers comparing at matching load should check
 * wong_reece_forces(h).Fz against the load in that case. */
double wong_reece_sinkage_for_load(const WongReeceModel *m, double Fz,
                                   double slip);

/* Published soil sets, returned as complete unprepared models for a wheel
 * of the given radius and width, with lambda = 0 (front-only contact; set
 * it, e.g. to the volumetric model's gamma, before wong_reece_prepare) and
 * points = WONG_REECE_DEFAULT_POINTS.
 *
 * Toyoura sand (Ishigami et al. 2007): n = 1.0, kc = 1.37e3, kphi = 8.14e5,
 *   c = 0.8 kPa, phi = 37.2 deg, a0 = 0.40, a1 = 0.15, K = 0.036 m (their
 *   Kx = 0.043 beta + 0.036 at zero slip angle beta).
 * Dry sand (Wong, Land Locomotion Lab data): n = 1.1, kc = 0.99e3,
 *   kphi = 1.528e6, c = 1.04 kPa, phi = 28 deg, K = 0.010 m (model notes).
 *   Assumption: a0 = 0.40, a1 = 0.15 (Ishigami's; no published pair for
 *   this soil in the notes). */
WongReeceModel wong_reece_toyoura_sand(double radius, double width);
WongReeceModel wong_reece_dry_sand(double radius, double width);

#endif
