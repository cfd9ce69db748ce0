/*
 * Classical terramechanics wheel model (Wong & Reece 1967; Ishigami et al.
 * 2007): implementation.  See wong_reece.h for the geometry, the equations,
 * the slip convention and the named assumptions.
 *
 * Layout of this file:
 *   1. parameter validation and derived constants (wong_reece_prepare),
 *   2. the integrand at one angle (normal stress, shear displacement, shear),
 *   3. the quadrature over the front and rear regions (wong_reece_forces),
 *   4. sinkage at a given load (bracket + Brent),
 *   5. published soil sets.
 *
 * No global mutable state, no allocation, no printing (snprintf into the
 * caller's error buffer only).  All functions are reentrant.
 */
#include "wong_reece.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ------------------------------------------------------------------------
 * 1. Parameter validation and derived constants.
 * ---------------------------------------------------------------------- */

static int fail(char *err, size_t errlen, const char *name,
                const char *rule, double value)
{
    if (err != NULL && errlen > 0)
        snprintf(err, errlen, "%s must be %s (got %g)", name, rule, value);
    return -1;
}

static int finite_positive(double x) { return isfinite(x) && x > 0.0; }

int wong_reece_prepare(WongReeceModel *m, char *err, size_t errlen)
{
    if (err != NULL && errlen > 0) err[0] = '\0';

    if (!finite_positive(m->n))
        return fail(err, errlen, "wongReece.n", "finite and > 0", m->n);
    /* Fitted Bekker sets can have kc < 0 (the fit is of kc/b + kphi over a
     * range of plate widths); only the combination for this wheel must be a
     * positive stiffness. */
    if (!isfinite(m->kc))
        return fail(err, errlen, "wongReece.kc", "finite", m->kc);
    if (!isfinite(m->kphi))
        return fail(err, errlen, "wongReece.kphi", "finite", m->kphi);
    if (!finite_positive(m->radius))
        return fail(err, errlen, "wheel.radius", "finite and > 0", m->radius);
    if (!finite_positive(m->width))
        return fail(err, errlen, "wheel.width", "finite and > 0", m->width);
    const double modulus = m->kc / m->width + m->kphi;
    if (!finite_positive(modulus))
        return fail(err, errlen, "wongReece.kc / wheel.width + wongReece.kphi",
                    "finite and > 0", modulus);
    if (!(isfinite(m->cohesion) && m->cohesion >= 0.0))
        return fail(err, errlen, "soil.cohesion", "finite and >= 0",
                    m->cohesion);
    if (!(m->phi >= 0.0 && m->phi < 0.5 * M_PI))   /* false for NaN */
        return fail(err, errlen, "soil.phi", "in [0, pi/2) rad", m->phi);
    if (!finite_positive(m->K))
        return fail(err, errlen, "wongReece.K", "finite and > 0 (m)", m->K);
    /* theta_m = (a0 + a1 s) theta_f must stay in [0, theta_f) for every
     * slip: at a0 + a1 s >= 1 the peak would sit at the entry, where the
     * stress is zero, and the whole distribution would vanish. */
    if (!(m->a0 >= 0.0 && m->a0 < 1.0))
        return fail(err, errlen, "wongReece.a0", "in [0, 1)", m->a0);
    if (!(fabs(m->a1) <= m->a0 && fabs(m->a1) < 1.0 - m->a0))
        return fail(err, errlen, "wongReece.a1",
                    "such that 0 <= wongReece.a0 + wongReece.a1 s < 1 for all "
                    "s in [-1, 1], i.e. |a1| <= a0 and |a1| < 1 - a0", m->a1);
    if (!(m->lambda >= 0.0 && m->lambda <= 1.0))
        return fail(err, errlen, "wongReece.lambda (the FMU's soil.gamma)", "in [0, 1]",
                    m->lambda);
    if (m->points < WONG_REECE_MIN_POINTS || m->points > WONG_REECE_MAX_POINTS)
        return fail(err, errlen, "wongReece.points", "in [6, 1000000]",
                    (double)m->points);

    m->k_sigma = pow(m->radius, m->n) * modulus;
    if (!finite_positive(m->k_sigma))
        return fail(err, errlen, "wheel.radius^wongReece.n * (kc/b + kphi)",
                    "finite and > 0 (overflow)", m->k_sigma);
    m->tan_phi = tan(m->phi);
    m->r_over_K = m->radius / m->K;
    if (!isfinite(m->r_over_K))
        return fail(err, errlen, "wheel.radius / wongReece.K",
                    "finite (K too small)", m->r_over_K);
    /* Two regions, each with an even number (>= 2) of Simpson intervals and
     * its own end points: intervals + 2 evaluations <= points. */
    m->intervals = 2 * ((m->points - 2) / 2);
    return 0;
}

/* ------------------------------------------------------------------------
 * 2. The integrand at one angle.
 *
 * Every point is parametrised by delta = (theta_f - theta)/2 >= 0, so that
 * the differences that vanish at the entry are products of sines, not
 * differences of nearly equal cosines (which lose all digits at small
 * sinkage):
 *   A = theta_f - delta = (theta_f + theta)/2,
 *   cos theta - cos theta_f = 2 sin A sin delta,
 *   sin theta_f - sin theta = 2 cos A sin delta,
 *   theta = A - delta (sin, cos by the addition formulas),
 * so that sin and cos of delta (and of theta_f) are all a point needs.
 * ---------------------------------------------------------------------- */

typedef struct {
    double sf, cf;      /* sin, cos theta_f */
    double k;           /* k_sigma */
    double n;
    int linear;         /* n == 1: skip pow */
    double c, tan_phi;
    /* shear: j/K = r_over_K * jnum / jden, with
     *   driving (s >= 0): jnum = (tf - t) - (1 - s) D,        jden = 1
     *   braking (s < 0):  jnum = (1 + s)(tf - t) - D,         jden = 1 + s
     * D = sin tf - sin t, so that a locked wheel (jden = 0) needs no
     * division by zero. */
    double rK_jden;     /* r/K / jden (unused when jden = 0) */
    double rho_num;     /* factor on D in jnum: 1 - s (driving) or 1 (braking) */
    double lin;         /* factor on (tf - t) in jnum: 1 or 1 + s */
    double jden;
} PointConst;

/* Normal stress k * base^n for base >= 0 (rounding can give -0 or -1e-17). */
static double stress(const PointConst *pc, double base)
{
    if (!(base > 0.0)) return 0.0;
    /* exp(n log b) rather than pow: the same accuracy here (relative error
     * ~ |n log b| eps ~ 1e-14) at half the cost of glibc's pow, which was a
     * third of a call for n != 1. */
    return pc->k * (pc->linear ? base : exp(pc->n * log(base)));
}

/* sign(j) (1 - exp(-|j|/K)) from its numerator/denominator form. */
static double shear_factor(const PointConst *pc, double two_delta, double D)
{
    const double jnum = pc->lin * two_delta - pc->rho_num * D;
    if (jnum == 0.0) return 0.0;
    /* jden == 0: locked wheel, |j| is infinite for every point behind the
     * entry, and the shear is at the Mohr-Coulomb limit. */
    const double x = pc->jden > 0.0 ? pc->rK_jden * fabs(jnum) : INFINITY;
    /* expm1 keeps the relative accuracy of small shear (it alone sets T at
     * tiny sinkage); above 0.1 plain exp is as accurate (1 - e^-x >= 0.095,
     * error ~1e-16) and, with glibc, several times cheaper: expm1 was over
     * half the cost of a call. */
    const double g = x < 0.1 ? -expm1(-x) : 1.0 - exp(-x);
    return jnum > 0.0 ? g : -g;
}

typedef struct {
    double x, z, t;     /* running sums of the three integrands */
} Sums;

/* Add weight * integrands at the point with half-gap delta (sd, cd its
 * sine and cosine, sA = sin(theta_f - delta)), whose normal stress is
 * sigma. */
static void accumulate(const PointConst *pc, double delta, double sd, double cd,
                       double sA, double sigma, double weight, Sums *acc)
{
    const double cA = pc->cf * cd + pc->sf * sd;     /* cos(theta_f - delta) */
    const double st = sA * cd - cA * sd;             /* sin theta */
    const double ct = cA * cd + sA * sd;             /* cos theta */
    const double D = 2.0 * cA * sd;                  /* sin tf - sin theta */
    const double tau = (pc->c + sigma * pc->tan_phi) *
                       shear_factor(pc, 2.0 * delta, D);
    acc->x += weight * (tau * ct - sigma * st);
    acc->z += weight * (tau * st + sigma * ct);
    acc->t += weight * tau;
}

/* Simpson weight factor (1, 4, 2, ..., 4, 1) of node i of m intervals. */
static double simpson_factor(int i, int m)
{
    if (i == 0 || i == m) return 1.0;
    return (i & 1) ? 4.0 : 2.0;
}

/* ------------------------------------------------------------------------
 * 3. Quadrature.
 *
 * The nodes are equally spaced, so the sines and cosines they need are
 * generated by rotation, (s, c) <- (s C + c S, c C - s S) with the step's
 * (S, C), instead of one sincos per node (about a third of the cost of a
 * call, measured).  The rotation is not exactly orthogonal in floating
 * point, so the pair drifts by at most ~i eps relative after i steps
 * (1e-14 at 100 points, 1e-10 at the 1e6 maximum), far below the
 * quadrature error.  Relative accuracy
 * holds at small angles too (tiny sinkage): the step's error enters sin
 * multiplied by the small S.
 * ---------------------------------------------------------------------- */

typedef struct {
    double s, c;        /* current sine and cosine */
    double S, C;        /* of the step */
} Rotor;

static Rotor rotor(double start, double step)
{
    Rotor r = {sin(start), cos(start), sin(step), cos(step)};
    return r;
}

static void rotor_next(Rotor *r)
{
    const double s = r->s * r->C + r->c * r->S;
    const double c = r->c * r->C - r->s * r->S;
    r->s = s;
    r->c = c;
}

/* Front region theta in [theta_m, theta_f], i.e. delta in [0, dmax],
 * dmax = (theta_f - theta_m)/2; m even intervals.
 * sigma = k (cos theta - cos theta_f)^n = k (2 sin A sin delta)^n. */
static void integrate_front(const PointConst *pc, double dmax, int m, Sums *acc)
{
    if (m <= 0 || !(dmax > 0.0)) return;
    const double hd = dmax / m;                 /* step in delta */
    const double w0 = 2.0 * hd / 3.0;           /* Simpson h/3, h = 2 hd in theta */
    Rotor d = rotor(0.0, hd);
    for (int i = 0; i <= m; ++i) {
        const double sA = pc->sf * d.c - pc->cf * d.s;
        const double sigma = stress(pc, 2.0 * sA * d.s);
        accumulate(pc, hd * i, d.s, d.c, sA, sigma,
                   w0 * simpson_factor(i, m), acc);
        rotor_next(&d);
    }
}

/* Rear region theta in [theta_r, theta_m]; m even intervals, from theta_m
 * backwards.  sigma = k (cos t* - cos theta_f)^n with t* = theta_f - w,
 * w = (theta - theta_r)/(theta_m - theta_r) (theta_f - theta_m) in
 * [0, theta_f - theta_m]: cos t* - cos theta_f = 2 sin(theta_f - w/2) sin(w/2). */
static void integrate_rear(const PointConst *pc, double tf, double tm,
                           double tr, int m, Sums *acc)
{
    const double len = tm - tr;
    if (m <= 0 || !(len > 0.0)) return;
    const double ht = len / m;                  /* step in theta */
    const double w0 = ht / 3.0;
    const double d0 = 0.5 * (tf - tm);          /* delta at theta_m */
    /* delta = d0 + i ht/2 grows; w/2 = d0 (1 - i/m) shrinks to 0 at theta_r */
    Rotor d = rotor(d0, 0.5 * ht);
    Rotor hw = rotor(d0, -d0 / m);
    for (int i = 0; i <= m; ++i) {
        const double sh = i == m ? 0.0 : hw.s;  /* exact zero at theta_r */
        const double s_star = pc->sf * hw.c - pc->cf * sh;   /* sin(tf - w/2) */
        const double sigma = stress(pc, 2.0 * s_star * sh);
        const double sA = pc->sf * d.c - pc->cf * d.s;
        accumulate(pc, d0 + 0.5 * ht * i, d.s, d.c, sA, sigma,
                   w0 * simpson_factor(i, m), acc);
        rotor_next(&d);
        rotor_next(&hw);
    }
}

/* Angle of a chord at depth d below the top of a circle of radius r:
 * acos(1 - d/r), via atan2 (accurate at small d, where acos(1 - x) loses
 * half its digits).  d in [0, r]. */
static double depth_angle(double r, double d)
{
    return atan2(sqrt(d * (2.0 * r - d)), r - d);
}

void wong_reece_forces(const WongReeceModel *m, double sinkage, double slip,
                       WRForces *out)
{
    const double r = m->radius;
    double h = sinkage > 0.0 ? sinkage : 0.0;       /* NaN -> 0 */
    if (h > r) h = r;
    double s = slip;
    if (!(s == s)) s = 0.0;                          /* NaN -> s = 0 */
    if (s > 1.0) s = 1.0;
    if (s < -1.0) s = -1.0;

    memset(out, 0, sizeof *out);
    out->sinkage = h;
    out->slip = s;
    if (!(h > 0.0)) return;

    const double tf = depth_angle(r, h);
    const double hr = m->lambda * h;
    const double tr = hr > 0.0 ? -depth_angle(r, hr) : 0.0;
    double tm = (m->a0 + m->a1 * s) * tf;
    if (tm > tf) tm = tf;
    if (tm < tr) tm = tr;
    out->theta_f = tf;
    out->theta_r = tr;
    out->theta_m = tm;

    PointConst pc;
    pc.sf = sin(tf);
    pc.cf = cos(tf);
    pc.k = m->k_sigma;
    pc.n = m->n;
    pc.linear = (m->n == 1.0);
    pc.c = m->cohesion;
    pc.tan_phi = m->tan_phi;
    if (s >= 0.0) {
        pc.lin = 1.0;
        pc.rho_num = 1.0 - s;
        pc.jden = 1.0;
    } else {
        pc.lin = 1.0 + s;
        pc.rho_num = 1.0;
        pc.jden = 1.0 + s;
    }
    pc.rK_jden = pc.jden > 0.0 ? m->r_over_K / pc.jden : 0.0;

    /* Share the Simpson intervals in proportion to the angular lengths,
     * each region even and >= 2 (a region of zero length gets none). */
    const int M = m->intervals;
    const double Lf = tf - tm, Lr = tm - tr;
    int mf, mr;
    if (!(Lr > 0.0)) {
        mf = M;
        mr = 0;
    } else if (!(Lf > 0.0)) {
        mf = 0;
        mr = M;
    } else {
        mf = 2 * (int)floor(0.5 * M * Lf / (Lf + Lr) + 0.5);
        if (mf < 2) mf = 2;
        if (mf > M - 2) mf = M - 2;
        mr = M - mf;
    }

    Sums acc = {0.0, 0.0, 0.0};
    integrate_front(&pc, 0.5 * Lf, mf, &acc);
    integrate_rear(&pc, tf, tm, tr, mr, &acc);

    const double dm = 0.5 * (tf - tm);
    out->sigma_m = stress(&pc, 2.0 * sin(tf - dm) * sin(dm));
    const double rb = r * m->width;
    out->Fx = rb * acc.x;
    out->Fz = rb * acc.z;
    out->T = rb * r * acc.t;
}

/* ------------------------------------------------------------------------
 * 4. Sinkage at a given load.
 * ---------------------------------------------------------------------- */

static double load_residual(const WongReeceModel *m, double h, double slip,
                            double load)
{
    WRForces f;
    wong_reece_forces(m, h, slip, &f);
    return f.Fz - load;
}

double wong_reece_sinkage_for_load(const WongReeceModel *m, double Fz,
                                   double slip)
{
    const double r = m->radius;
    const double load = Fz;
    if (!(load > 0.0)) return 0.0;

    /* Bracket: Fz(0) = 0 < load.  Doubling from 1e-6 r finds the first
     * crossing at that resolution (a root, and the shallowest one if Fz is
     * monotonic) in at most ~21 evaluations, and a bracket of width 2:1. */
    double a = 0.0, fa = -load;
    double b = 1e-6 * r, fb = load_residual(m, b, slip, load);
    while (fb < 0.0) {
        if (b >= r) return r;         /* even hub-deep carries less: limit */
        a = b;
        fa = fb;
        b = 2.0 * b < r ? 2.0 * b : r;
        fb = load_residual(m, b, slip, load);
    }
    if (fb == 0.0) return b;
    if (!(fb > 0.0)) return b;        /* NaN guard: cannot happen when prepared */

    /* Brent's method (inverse quadratic / secant steps, safeguarded by
     * bisection) on [a, b] with fa < 0 < fb.  Tolerance 1e-10 m absolute:
     * far below any sinkage that matters, above rounding of h ~ r. */
    const double xtol = 1e-10;
    double c = a, fc = fa;
    double d = b - a, e = d;
    for (int iter = 0; iter < 200; ++iter) {
        if ((fb > 0.0 && fc > 0.0) || (fb < 0.0 && fc < 0.0)) {
            c = a;
            fc = fa;
            d = e = b - a;
        }
        if (fabs(fc) < fabs(fb)) {
            a = b; b = c; c = a;
            fa = fb; fb = fc; fc = fa;
        }
        const double tol = 2.0 * DBL_EPSILON * fabs(b) + 0.5 * xtol;
        const double xm = 0.5 * (c - b);
        if (fabs(xm) <= tol || fb == 0.0) return b;
        if (fabs(e) >= tol && fabs(fa) > fabs(fb)) {
            const double sr = fb / fa;
            double p, q;
            if (a == c) {
                p = 2.0 * xm * sr;                 /* secant */
                q = 1.0 - sr;
            } else {
                const double qa = fa / fc, rb = fb / fc;   /* inverse quadratic */
                p = sr * (2.0 * xm * qa * (qa - rb) - (b - a) * (rb - 1.0));
                q = (qa - 1.0) * (rb - 1.0) * (sr - 1.0);
            }
            if (p > 0.0) q = -q;
            p = fabs(p);
            const double lim1 = 3.0 * xm * q - fabs(tol * q);
            const double lim2 = fabs(e * q);
            if (2.0 * p < (lim1 < lim2 ? lim1 : lim2)) {
                e = d;                             /* accept interpolation */
                d = p / q;
            } else {
                d = xm;                            /* bisect */
                e = d;
            }
        } else {
            d = xm;
            e = d;
        }
        a = b;
        fa = fb;
        b += fabs(d) > tol ? d : (xm > 0.0 ? tol : -tol);
        fb = load_residual(m, b, slip, load);
    }
    return b;
}

/* ------------------------------------------------------------------------
 * 5. Published soil sets (see wong_reece.h for sources and assumptions).
 * ---------------------------------------------------------------------- */

static WongReeceModel base_model(double radius, double width)
{
    WongReeceModel m;
    memset(&m, 0, sizeof m);
    m.radius = radius;
    m.width = width;
    m.lambda = 0.0;
    m.points = WONG_REECE_DEFAULT_POINTS;
    return m;
}

WongReeceModel wong_reece_toyoura_sand(double radius, double width)
{
    WongReeceModel m = base_model(radius, width);
    m.n = 1.0;
    m.kc = 1.37e3;
    m.kphi = 8.14e5;
    m.cohesion = 800.0;
    m.phi = 37.2 * M_PI / 180.0;
    m.K = 0.036;
    m.a0 = 0.40;
    m.a1 = 0.15;
    return m;
}

WongReeceModel wong_reece_dry_sand(double radius, double width)
{
    WongReeceModel m = base_model(radius, width);
    m.n = 1.1;
    m.kc = 0.99e3;
    m.kphi = 1.528e6;
    m.cohesion = 1040.0;
    m.phi = 28.0 * M_PI / 180.0;
    m.K = 0.010;
    m.a0 = 0.40;
    m.a1 = 0.15;
    return m;
}
