/*
 * Volumetric wheel/soil contact (Petersen & McPhee 2013): implementation.
 * See contact.h for the geometry, frames and API.
 *
 * Layout of this file:
 *   1. small geometry helpers (segment angle, half length, half volume),
 *   2. the reference quadrature of a half patch (hypervolume and moments),
 *   3. contact_model_prepare (validation, Eqn 3 fit, centroid factors),
 *   4. contact_patch (closed form = Eqn 3, or quadrature),
 *   5. contact_shear (Eqn 5 generalised to the slip vector, with Jacobian),
 *   6. soil memory: contact_cuts and contact_memory_update.
 *
 * No global mutable state, no allocation, no printing (snprintf into the
 * caller's error buffer only).  All functions are reentrant.
 */
#include "contact.h"

#include <math.h>
#include <stdio.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ------------------------------------------------------------------------
 * 1. Geometry of a cylinder of radius R pressed a depth h into a plane.
 *    Half-angle of the segment t0 = acos(1 - h/R), half chord
 *    L = R sin t0 = sqrt(h (2R - h)).
 *    Assumption: h is clamped to [0, R].  Deeper than the hub the circular
 *    geometry no longer describes a wheel in soil (the soil would close
 *    over the rim); the contact saturates at the half-cylinder instead of
 *    producing NaN from acos/sqrt.
 * ---------------------------------------------------------------------- */

static double clamp_depth(double R, double h)
{
    if (!(h > 0.0)) return 0.0;          /* also maps NaN to 0 */
    return h < R ? h : R;
}

/* Half chord of the segment of depth h (h already in [0, R]). */
static double chord_half(double R, double h)
{
    return sqrt(h * (2.0 * R - h));
}

/* seg(t) = t - sin t cos t, the segment area over R^2, of half-angle t.
 *
 * Shallow halves, h <= R/2 (every practical sinkage): with y = sin(t/2),
 * w = y^2 = h / (2R), dseg/dy = 16 y^2 sqrt(1 - y^2), so seg = y^3 H(w) with
 * H(w) = 16 sum_n (-1)^n C(1/2, n) w^n / (2n + 3), analytic for |w| < 1 and
 * free of cancellation at small h (H(0) = 16/3, seg ~ 2t^3/3).  SEG_SHALLOW
 * holds H on w in [0, 1/4] as a polynomial of degree 13 in s = 8w - 1 =
 * 4h/R - 1 (Chebyshev interpolation in 60-digit arithmetic,
 * scripts/segment_polynomial.py): truncation ~1e-19 relative, 1.3e-16 with
 * the rounding of its evaluation in doubles.  The half volume then needs a
 * square root beside a polynomial, no atan and no division: an atan after a
 * square root and a division is the longest link of the chain that ends in
 * the normal force, and with it the closed form takes a third more time
 * (bench_contact).  The volume is also accurate to ~6e-16 at every depth,
 * where t - sin t cos t from t loses digits to cancellation (~7e-14). */
static const double SEG_SHALLOW[14] = {
    5.128637043666172,
    -0.20964079195137553,
    -0.005210251973204928,
    -0.00028473560060429757,
    -2.0566890535696796e-05,
    -1.7260233555171983e-06,
    -1.5927493935194996e-07,
    -1.5697276312455876e-08,
    -1.6237896390633733e-09,
    -1.7432952087026875e-10,
    -1.925734658774316e-11,
    -2.1806451119031694e-12,
    -2.648792360064483e-13,
    -3.1152627211769835e-14,
};

/* Half-segment volume (b R^2 / 2) seg(t) of depth h in (0, R/2]:
 * volume_factor h sqrt(h) H(s), volume_factor = (b R^2 / 2) (2R)^-3/2,
 * s_scale = 4 / R.  Estrin's scheme: the polynomial's chain is 5 products
 * and sums deep instead of 13. */
#if defined(__GNUC__)
#define ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE inline
#endif

/* Inlined everywhere: out of line, GCC's calls from the loop over the halves
 * keep it scalar and spill around each call. */
static ALWAYS_INLINE double shallow_half_volume(double volume_factor, double s_scale, double h)
{
    const double *c = SEG_SHALLOW;
    const double s = h * s_scale - 1.0, s2 = s * s, s4 = s2 * s2, s8 = s4 * s4;
    const double q0 = (c[0] + c[1] * s) + (c[2] + c[3] * s) * s2;
    const double q1 = (c[4] + c[5] * s) + (c[6] + c[7] * s) * s2;
    const double q2 = (c[8] + c[9] * s) + (c[10] + c[11] * s) * s2;
    const double q3 = c[12] + c[13] * s;
    const double H = (q0 + q1 * s4) + (q2 + q3 * s4) * s8;
    return (volume_factor * h * H) * sqrt(h);
}

/* Deeper halves (R/2 < h <= R, t >= pi/3, where t - sin t cos t does not
 * cancel): t = 2 atan(L / (2R - h)) by the half-angle formula tan(t/2) =
 * sin t / (1 + cos t), accurate up to h = R, and sin t cos t = (L / R)((R - h) / R). */
static double deep_half_volume(double R, double inv_R2, double width, double h, double L)
{
    const double t = 2.0 * atan(L / (2.0 * R - h));
    return 0.5 * width * R * R * (t - L * (R - h) * inv_R2);
}

/* Half-segment volume from depth h in (0, R] and half chord L; the
 * factors as contact_model_prepare derives them. */
static double half_volume(double R, double inv_R2, double width, double volume_factor, double s_scale, double h,
                          double L)
{
    return h <= 0.5 * R ? shallow_half_volume(volume_factor, s_scale, h) : deep_half_volume(R, inv_R2, width, h, L);
}

/* (b R^2 / 2) (2R)^-3/2: the half volume over h^3/2 H(w) */
static double half_volume_factor(double R, double width)
{
    return 0.5 * width * R * R / (2.0 * R * sqrt(2.0 * R));
}

double contact_half_volume(double radius, double width, double h)
{
    const double R = radius;
    h = clamp_depth(R, h);
    if (h <= 0.0) return 0.0;
    return half_volume(R, 1.0 / (R * R), width, half_volume_factor(R, width), 4.0 / R, h, chord_half(R, h));
}

/* ------------------------------------------------------------------------
 * 2. Reference quadrature of one half patch.
 *
 * In the angle theta from the lowest point (x = R sin theta), the depth of
 * a half segment of depth h is
 *     d(theta) = R (cos theta - cos t0) = 2 R sin((t0+theta)/2) sin((t0-theta)/2),
 * which vanishes linearly at theta = t0, so d^eta has an endpoint
 * singularity (t0 - theta)^eta times an analytic factor.  Substituting
 *     t0 - theta = t0 w^3,  w = 1 - u in [0, 1],
 * turns it into w^(3 eta + 2) times a smooth function of w, which 64-point
 * Gauss-Legendre integrates with error ~ N^-(6 eta + 6) (eta -> 0 gives
 * w^2, smooth).  Measured against a 200000-point reference: relative error
 * < 2e-11 for eta in [1e-9, 2.5] and depths 1 mm .. R.  The product form of d avoids
 * the cancellation of cos theta - cos t0 near the patch end.
 * ---------------------------------------------------------------------- */

/* 64-point Gauss-Legendre rule on [-1, 1]: the 32 positive nodes and their
 * weights (the rule is symmetric).  Generated by Newton iteration on the
 * Legendre polynomial P_64 in 40-digit arithmetic (mpmath). */
static const double GL64[32][2] = {
    {2.43502926634244325090e-2, 4.86909570091397203834e-2},
    {7.29931217877990394495e-2, 4.85754674415034269348e-2},
    {1.21462819296120554470e-1, 4.83447622348029571698e-2},
    {1.69644420423992818037e-1, 4.79993885964583077281e-2},
    {2.17423643740007084150e-1, 4.75401657148303086623e-2},
    {2.64687162208767416374e-1, 4.69681828162100173253e-2},
    {3.11322871990210956158e-1, 4.62847965813144172960e-2},
    {3.57220158337668115950e-1, 4.54916279274181444798e-2},
    {4.02270157963991603696e-1, 4.45905581637565630601e-2},
    {4.46366017253464087985e-1, 4.35837245293234533768e-2},
    {4.89403145707052957479e-1, 4.24735151236535890073e-2},
    {5.31279464019894545658e-1, 4.12625632426235286102e-2},
    {5.71895646202634034284e-1, 3.99537411327203413867e-2},
    {6.11155355172393250249e-1, 3.85501531786156291290e-2},
    {6.48965471254657339858e-1, 3.70551285402400460404e-2},
    {6.85236313054233242564e-1, 3.54722132568823838107e-2},
    {7.19881850171610826849e-1, 3.38051618371416093916e-2},
    {7.52819907260531896612e-1, 3.20579283548515535855e-2},
    {7.83972358943341407610e-1, 3.02346570724024788680e-2},
    {8.13265315122797559742e-1, 2.83396726142594832275e-2},
    {8.40629296252580362752e-1, 2.63774697150546586717e-2},
    {8.65999398154092819761e-1, 2.43527025687108733382e-2},
    {8.89315445995114105853e-1, 2.22701738083832541593e-2},
    {9.10522137078502805756e-1, 2.01348231535302093723e-2},
    {9.29569172131939575821e-1, 1.79517157756973430850e-2},
    {9.46411374858402816062e-1, 1.57260304760247193220e-2},
    {9.61008799652053718919e-1, 1.34630478967186425981e-2},
    {9.73326827789910963742e-1, 1.11681394601311288186e-2},
    {9.83336253884625956931e-1, 8.84675982636394772303e-3},
    {9.91013371476744320739e-1, 6.50445796897836285612e-3},
    {9.96340116771955279347e-1, 4.14703326056246763529e-3},
    {9.99305041735772139457e-1, 1.78328072169643294730e-3},
};

/* Per-unit-width moments of one half patch of depth h (0 < h <= R):
 *   m0 = integral d^eta dx,  m1 = integral x d^eta dx,
 *   m2 = integral d^(eta+1) dx,   x from 0 to the half chord. */
typedef struct {
    double m0, m1, m2;
} HalfMoments;

static HalfMoments half_moments_quadrature(double R, double eta, double h)
{
    HalfMoments mo = {0.0, 0.0, 0.0};
    h = clamp_depth(R, h);
    if (h <= 0.0) return mo;
    const double t0 = atan2(chord_half(R, h), R - h);
    for (int i = 0; i < 32; ++i) {
        for (int side = -1; side <= 1; side += 2) {
            /* node on [0, 1] in u; w = 1 - u computed directly so that the
             * nodes crowding towards w = 0 keep their relative accuracy */
            const double w = 0.5 * (1.0 - (double)side * GL64[i][0]);
            const double wt = 0.5 * GL64[i][1];
            const double w2 = w * w;
            const double gap = t0 * w2 * w;          /* t0 - theta >= 0 */
            const double theta = t0 - gap;
            const double d = 2.0 * R * sin(t0 - 0.5 * gap) * sin(0.5 * gap);
            const double x = R * sin(theta);
            /* dx = R cos(theta) dtheta, dtheta = 3 t0 w^2 du */
            const double jw = wt * 3.0 * t0 * w2 * R * cos(theta);
            const double de = pow(d, eta);
            mo.m0 += jw * de;
            mo.m1 += jw * x * de;
            mo.m2 += jw * d * de;
        }
    }
    return mo;
}

double contact_half_hypervolume_quadrature(double radius, double width,
                                           double eta, double h)
{
    return width * half_moments_quadrature(radius, eta, h).m0;
}

/* ------------------------------------------------------------------------
 * 3. Parameter validation and derived constants.
 * ---------------------------------------------------------------------- */

static int fail(char *err, size_t errlen, const char *name,
                const char *rule, double value)
{
    if (err != NULL && errlen > 0)
        snprintf(err, errlen, "%s must be %s (got %g)", name, rule, value);
    return -1;
}

/* I(a) = integral_0^1 (1 - u^2)^a du = (sqrt(pi)/2) Gamma(a+1)/Gamma(a+3/2).
 * Not via lgamma: it writes the global signgam, a data race when instances
 * initialise in parallel threads.  tgamma is exact enough and finite for
 * a < 160; beyond, the ratio's asymptotic series (error < 1e-9). */
static double parabola_integral(double a)
{
    if (a < 160.0) return 0.5 * sqrt(M_PI) * tgamma(a + 1.0) / tgamma(a + 1.5);
    const double x = a + 1.0;   /* Gamma(x)/Gamma(x+1/2) ~ x^-1/2 (1 + 1/(8x) + 1/(128x^2)) */
    return 0.5 * sqrt(M_PI) / sqrt(x) * (1.0 + 1.0 / (8.0 * x) + 1.0 / (128.0 * x * x));
}

/* Number of sinkages in the Eqn 3 fit. */
enum { FIT_POINTS = 32 };

int contact_model_prepare(ContactModel *m, char *err, size_t errlen)
{
    if (err != NULL && errlen > 0) err[0] = '\0';

    if (!(isfinite(m->kh) && m->kh > 0.0))
        return fail(err, errlen, "soil.kh", "finite and > 0", m->kh);
    if (!(isfinite(m->eta) && m->eta > 0.0))
        return fail(err, errlen, "soil.eta", "finite and > 0", m->eta);
    if (!(m->gamma >= 0.0 && m->gamma <= 1.0))   /* false for NaN */
        return fail(err, errlen, "soil.gamma", "in [0, 1]", m->gamma);
    if (!(isfinite(m->Kvx) && m->Kvx > 0.0))
        return fail(err, errlen, "soil.Kvx", "finite and > 0", m->Kvx);
    if (!(isfinite(m->Kvy_ratio) && m->Kvy_ratio > 0.0))
        return fail(err, errlen, "soil.KvyRatio", "finite and > 0",
                    m->Kvy_ratio);
    if (!(isfinite(m->cohesion) && m->cohesion >= 0.0))
        return fail(err, errlen, "soil.cohesion", "finite and >= 0",
                    m->cohesion);
    if (!(m->phi >= 0.0 && m->phi < 0.5 * M_PI))
        return fail(err, errlen, "soil.phi", "in [0, pi/2) rad", m->phi);
    if (!(isfinite(m->radius) && m->radius > 0.0))
        return fail(err, errlen, "wheel.radius", "finite and > 0",
                    m->radius);
    if (!(isfinite(m->width) && m->width > 0.0))
        return fail(err, errlen, "wheel.width", "finite and > 0", m->width);
    if (!(isfinite(m->slip_v_eps) && m->slip_v_eps > 0.0))
        return fail(err, errlen, "contact.slipVelocityEps", "finite and > 0",
                    m->slip_v_eps);
    if (m->method != CONTACT_CLOSED_FORM && m->method != CONTACT_QUADRATURE)
        return fail(err, errlen, "contact.method",
                    "0 (closed form) or 1 (quadrature)", (double)m->method);

    const double R = m->radius, b = m->width, eta = m->eta;

    m->tan_phi = tan(m->phi);
    m->inv_Kvx = 1.0 / m->Kvx;
    m->inv_R2 = 1.0 / (m->radius * m->radius);
    m->half_volume_factor = half_volume_factor(R, b);
    m->shallow_scale = 4.0 / R;
    m->inv_Kvy = 1.0 / (m->Kvy_ratio * m->Kvx);

    /* Centroid factors of a half patch from the shallow-sinkage (parabolic)
     * profile d = h (1 - u^2), u = x / half_length:
     *   xbar / half_length = int u (1-u^2)^eta / int (1-u^2)^eta
     *                      = [1 / (2 (eta+1))] / I(eta),
     *   column centre below the surface, weighted by d^eta:
     *   int (d/2) d^eta / int d^eta = h I(eta+1) / (2 I(eta))
     *                               = h (eta+1) / (2 eta + 3). */
    m->cx_eta = (0.5 / (eta + 1.0)) / parabola_integral(eta);
    m->cz_eta = (eta + 1.0) / (2.0 * eta + 3.0);

    /* Sinkage range of the fit: 5..80 mm as in the model notes.
     * Assumption: for a wheel smaller than 80 mm the range is scaled to
     * [R/16, R] (same ratio), since depths beyond R are clamped. */
    const double s_hi = fmin(0.080, R);
    const double s_lo = fmin(0.005, s_hi / 16.0);

    if (fabs(eta - 1.0) < 1e-12) {
        /* Degenerate: the exponent A1 (eta - 1) is 0, so any A1, Vint give
         * V_h = V.  Keep the shallow-sinkage limit A1 = 2/3 and a volume in
         * the middle of the fit range. */
        m->A1 = 2.0 / 3.0;
        m->Vint = 2.0 * contact_half_volume(R, b, fmin(0.030, s_hi));
        m->vh_exp = m->A1 * (eta - 1.0);
        m->log_Vint = log(m->Vint);
        return 0;
    }

    /* Least squares of y = ln(Vh/V) on x = ln V, for the full symmetric
     * segment (both halves, i.e. twice the half values), sinkages
     * log-spaced so that shallow and deep contacts weigh alike:
     *     y = a x + c,  a = A1 (eta - 1),  c = -a ln Vint. */
    double sx = 0.0, sy = 0.0, sxx = 0.0, sxy = 0.0;
    const double ratio = log(s_hi / s_lo);
    for (int k = 0; k < FIT_POINTS; ++k) {
        const double s = s_lo * exp(ratio * (double)k / (FIT_POINTS - 1));
        const double V = 2.0 * contact_half_volume(R, b, s);
        const double Vh = 2.0 * contact_half_hypervolume_quadrature(R, b, eta, s);
        const double x = log(V), y = log(Vh / V);
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    const double n = (double)FIT_POINTS;
    const double xm = sx / n, ym = sy / n;
    const double a = (sxy - n * xm * ym) / (sxx - n * xm * xm);
    const double c = ym - a * xm;
    m->A1 = a / (eta - 1.0);
    m->Vint = exp(-c / a);
    m->vh_exp = m->A1 * (eta - 1.0);
    m->log_Vint = -c / a;
    return 0;
}

/* ------------------------------------------------------------------------
 * 4. The contact patch.
 * ---------------------------------------------------------------------- */

/* One half patch: half chord, plain volume, hypervolume and its
 * derivative with respect to the depth, and the hypervolume centroid as
 * |x| from the lowest point and depth below that half's own (possibly cut)
 * surface. */
typedef struct {
    double L, V, Vh, dVh, xbar, dbar;
} Half;

/* n halves by Eqn 3 (n <= 2 CONTACT_BATCH), for depths h[k] (each already
 * <= R; <= 0: no contact).  The halves are computed stage by stage together
 * (every volume, then every log, then every exp) rather than one after the
 * other: each half is a chain of dependent libm calls, and side by side the
 * processor overlaps the chains (the two halves of a patch, and the patches
 * of the wheels that contact_patches gets together). */
static void halves_closed_form(const ContactModel *m, int n, const double *h, Half *hf)
{
    const double R = m->radius, b = m->width, p = m->vh_exp, half_R = 0.5 * R;
    /* Every half's shallow volume first, at its depth clamped to [0, R/2]
     * (no square root of a negative, which would raise FE_INVALID): a loop
     * without calls, which GCC vectorises and the processor overlaps. */
    double shallow[2 * CONTACT_BATCH];
    for (int k = 0; k < n; ++k) {
        double hk = h[k] > 0.0 ? h[k] : 0.0;
        hk = hk < half_R ? hk : half_R;
        shallow[k] = shallow_half_volume(m->half_volume_factor, m->shallow_scale, hk);
    }
    for (int k = 0; k < n; ++k) {
        hf[k].L = hf[k].V = hf[k].Vh = hf[k].dVh = hf[k].xbar = hf[k].dbar = 0.0;
        if (!(h[k] > 0.0)) continue;
        hf[k].L = chord_half(R, h[k]);
        hf[k].V = h[k] <= half_R ? shallow[k] : deep_half_volume(R, m->inv_R2, b, h[k], hf[k].L);
    }
    /* Eqn 3 applied to each half as if it were half of a symmetric segment
     * of the same depth (V = 2 V_half): for symmetric contact the sum of
     * the halves is exactly the paper's Eqn 3.  The power as
     * exp(p (ln 2V - ln Vint)) with ln Vint prepared: the same value as
     * pow(2V / Vint, p) to rounding (|p ln(2V/Vint)| is small), at about
     * half the cost of glibc's pow, which took a quarter of the time. */
    double lg[2 * CONTACT_BATCH], ratio[2 * CONTACT_BATCH];
    for (int k = 0; k < n; ++k)
        lg[k] = hf[k].V > 0.0 ? log(2.0 * hf[k].V) : 0.0;     /* V may underflow at tiny h */
    for (int k = 0; k < n; ++k)
        ratio[k] = hf[k].V > 0.0 ? exp(p * (lg[k] - m->log_Vint)) : 0.0;   /* Vh / V */
    for (int k = 0; k < n; ++k) {
        if (!(hf[k].V > 0.0)) continue;
        hf[k].Vh = hf[k].V * ratio[k];
        /* d/dh [V (2V/Vint)^p] = (1 + p) (Vh / V) dV/dh, dV/dh = b L */
        hf[k].dVh = (1.0 + p) * ratio[k] * (b * hf[k].L);
        hf[k].xbar = m->cx_eta * hf[k].L;
        hf[k].dbar = m->cz_eta * h[k];
    }
}

static Half half_quadrature(const ContactModel *m, double h)
{
    Half hf = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    if (h <= 0.0) return hf;
    const double R = m->radius;
    const HalfMoments mo = half_moments_quadrature(R, m->eta, h);
    hf.L = chord_half(R, h);
    hf.V = contact_half_volume(R, m->width, h);
    hf.Vh = m->width * mo.m0;
    /* Stiffness by a forward difference (the reference method: the
     * derivative's integrand d^(eta-1) is singular at the patch end, which
     * the rule does not resolve).  At h = R the half is saturated. */
    const double dz = 1e-5 * h;     /* truncation error ~1e-5 relative */
    if (h < R)
        hf.dVh = (m->width * half_moments_quadrature(R, m->eta, h + dz).m0 - hf.Vh) / dz;
    if (mo.m0 > 0.0) {
        hf.xbar = mo.m1 / mo.m0;
        hf.dbar = 0.5 * mo.m2 / mo.m0;
    }
    return hf;
}

/* The patch from its two halves (sinkage s clamped, cuts cf, cr clamped to
 * [0, s]); out has the no-contact values. */
static void patch_from_halves(const ContactModel *m, double sinkage, double s, double cf, double cr,
                              const Half *front, const Half *rear, ContactPatch *out)
{
    const double R = m->radius;
    out->V = front->V + rear->V;
    out->Vh = front->Vh + rear->Vh;
    out->length_front = front->L;
    out->length_rear = rear->L;
    out->area = m->width * (front->L + rear->L);
    out->Fn = m->kh * out->Vh;
    /* Sinkage beyond R is clamped: no stiffness there.  A half cut to
     * nothing (cut >= sinkage) has h = 0 and dVh = 0. */
    if (sinkage < R) out->dFn_dz = m->kh * (front->dVh + rear->dVh);
    if (!(out->Vh > 0.0)) return;

    /* A cut lowers that half's surface: z = -(R - s) - cut. */
    const double zf = -(R - s) - cf - front->dbar;
    const double zr = -(R - s) - cr - rear->dbar;
    /* Moments of the hypervolume; the centroid is (mx, mz) / Vh. */
    const double mx = front->Vh * front->xbar - rear->Vh * rear->xbar;
    const double mz = front->Vh * zf + rear->Vh * zr;
    const double inv_vh = 1.0 / out->Vh;
    out->xc = mx * inv_vh;
    out->zc = mz * inv_vh;
    /* Sine and cosine of atan2(xc, -zc) directly: no atan2 here and no
     * sin/cos in the caller.  From the moments, so that this chain does
     * not wait for 1/Vh (measured: the divide-sqrt-divide chain was a
     * fifth of the closed form); from the centroid (|zc| ~ R) where the
     * moments' squares could underflow. */
    const double m2 = mx * mx + mz * mz;
    const double inv_rho = m2 > 1e-280 ? 1.0 / sqrt(m2) : 1.0 / sqrt(out->xc * out->xc + out->zc * out->zc);
    const double scale = m2 > 1e-280 ? 1.0 : inv_vh;
    out->sin_alpha = mx * scale * inv_rho;
    out->cos_alpha = -mz * scale * inv_rho;
}

/* contact_patches for n patches (a constant 1 from contact_patch, which
 * GCC then compiles without the loops' overhead). */
static inline void patches(const ContactModel *m, int n, const double *sinkage, const double *cut_front,
                           const double *cut_rear, ContactPatch *out)
{
    const double R = m->radius;
    double s[CONTACT_BATCH], cf[CONTACT_BATCH], cr[CONTACT_BATCH], h[2 * CONTACT_BATCH];
    int live[CONTACT_BATCH], n_live = 0;        /* the patches in the soil */
    for (int i = 0; i < n; ++i) {
        ContactPatch *o = &out[i];
        o->sinkage = sinkage[i];
        o->V = o->Vh = o->area = 0.0;
        o->length_front = o->length_rear = 0.0;
        o->xc = 0.0;
        o->zc = -R;            /* no contact: lowest rim point, alpha = 0 */
        o->Fn = o->dFn_dz = 0.0;
        o->sin_alpha = 0.0;
        o->cos_alpha = 1.0;
        if (!(sinkage[i] > 0.0)) continue;
        /* Assumption: sinkage beyond R is clamped to R (see clamp_depth). */
        const int k = n_live++;
        live[k] = i;
        s[k] = sinkage[i] < R ? sinkage[i] : R;
        cf[k] = cut_front[i] > 0.0 ? (cut_front[i] < s[k] ? cut_front[i] : s[k]) : 0.0;
        cr[k] = cut_rear[i] > 0.0 ? (cut_rear[i] < s[k] ? cut_rear[i] : s[k]) : 0.0;
        h[2 * k] = s[k] - cf[k];
        h[2 * k + 1] = s[k] - cr[k];
    }
    Half halves[2 * CONTACT_BATCH];
    if (m->method == CONTACT_QUADRATURE)
        for (int k = 0; k < 2 * n_live; ++k) halves[k] = half_quadrature(m, h[k]);
    else
        halves_closed_form(m, 2 * n_live, h, halves);
    for (int k = 0; k < n_live; ++k)
        patch_from_halves(m, sinkage[live[k]], s[k], cf[k], cr[k], &halves[2 * k], &halves[2 * k + 1],
                          &out[live[k]]);
}

void contact_patch(const ContactModel *m, double sinkage, double cut_front,
                   double cut_rear, ContactPatch *out)
{
    patches(m, 1, &sinkage, &cut_front, &cut_rear, out);
}

void contact_patches(const ContactModel *m, int n, const double *sinkage, const double *cut_front,
                     const double *cut_rear, ContactPatch *out)
{
    for (int i = 0; i < n; i += CONTACT_BATCH)
        patches(m, n - i < CONTACT_BATCH ? n - i : CONTACT_BATCH, sinkage + i, cut_front + i, cut_rear + i, out + i);
}

/* ------------------------------------------------------------------------
 * 5. Shear force.
 *
 * F = F_taumax g(|q|) q with g(r) = tanh(r)/r and the scaled slip
 * q = (s_long / Kvx, s_lat / (Kvy_ratio Kvx)): the force has the magnitude
 * F_taumax tanh(|q|) and points along the scaled slip, i.e. against the
 * sliding of the soil under the wheel.  With s_lat = 0 this is Eqn 5.
 *
 * Standstill: den = max(|omega_r|, |v_long|, slip_v_eps) never falls below
 * slip_v_eps, so below that speed the slip becomes (slip velocity) /
 * slip_v_eps, a viscous-like law that is finite, smooth and zero at rest.
 * ---------------------------------------------------------------------- */

/* tanh(r) for r >= 0, g(r) = tanh(r)/r and, if with_h (only the Jacobian
 * needs it), h(r) = g'(r)/r, both even and smooth; Taylor series near 0
 * (truncation < 1e-14 relative at r = 0.05) avoid the 0/0 and the
 * cancellation in h.  Above 0.05, tanh r =
 * (1 - e)/(1 + e) with e = exp(-2r): 1 - e >= 0.095 has no cancellation,
 * so this is tanh to a few ulp, for one exp instead of glibc's tanh
 * (expm1 inside), which with the hypot below took 15 % of the time. */
static inline void tanh_ratio(double r, int with_h, double *th, double *g, double *h)
{
    if (r < 0.05) {
        const double r2 = r * r;
        *g = 1.0 - r2 * (1.0 / 3.0 - r2 * (2.0 / 15.0 - r2 * (17.0 / 315.0 -
             r2 * (62.0 / 2835.0 - r2 * (1382.0 / 155925.0)))));
        if (with_h)
            *h = -2.0 / 3.0 + r2 * (8.0 / 15.0 - r2 * (34.0 / 105.0 -
                 r2 * (496.0 / 2835.0 - r2 * (13820.0 / 155925.0))));
        *th = tanh(r);
        return;
    }
    const double e = exp(-2.0 * r);
    const double t = (1.0 - e) / (1.0 + e);
    const double inv_r = 1.0 / r;
    *th = t;
    *g = t * inv_r;
    if (with_h) *h = (r * (1.0 - t * t) - t) * (inv_r * inv_r * inv_r);
}

/* contact_shears for n wheels (a constant 1 from contact_shear), stage by
 * stage: the slips (a division, a square root) for all, then tanh (an exp,
 * a division) for all, then the forces and Jacobians. */
static inline void shears(const ContactModel *m, int n, const ShearInput *in, ShearForce *out, int jacobians)
{
    const double kx = m->inv_Kvx, ky = m->inv_Kvy, eps = m->slip_v_eps;
    double Fmax[CONTACT_BATCH], inv_den[CONTACT_BATCH], dden_dv[CONTACT_BATCH], dden_dw[CONTACT_BATCH];
    double s_long[CONTACT_BATCH], s_lat[CONTACT_BATCH], ql[CONTACT_BATCH], qt[CONTACT_BATCH], r[CONTACT_BATCH];
    for (int k = 0; k < n; ++k) {
        /* Assumption: a negative limit (only from negative inputs) is treated
         * as 0, so the shear force can never push along the slip. */
        Fmax[k] = in[k].area * m->cohesion + in[k].Fn * m->tan_phi;
        if (!(Fmax[k] > 0.0)) Fmax[k] = 0.0;

        /* den = max(|omega_r|, |v_long|, eps) with its derivative along the
         * active branch (ties go to omega_r, then v_long). */
        const double omega_r = in[k].omega_r, v_long = in[k].v_long;
        const double aw = fabs(omega_r), av = fabs(v_long);
        double den = eps, dv = 0.0, dw = 0.0;      /* scalars: a loop clearing the arrays became a memset */
        if (aw >= av && aw >= eps) {
            den = aw;
            dw = omega_r > 0.0 ? 1.0 : -1.0;
        } else if (av >= eps) {
            den = av;
            dv = v_long > 0.0 ? 1.0 : -1.0;
        }
        dden_dv[k] = dv;
        dden_dw[k] = dw;
        inv_den[k] = 1.0 / den;
        s_long[k] = (omega_r - v_long) * inv_den[k];
        s_lat[k] = -in[k].v_lat * inv_den[k];
        ql[k] = s_long[k] * kx;
        qt[k] = s_lat[k] * ky;
        /* |q| by sqrt of the squares (glibc's hypot is several times dearer);
         * hypot only where the squares could overflow (absurd Kvx). */
        const double aql = fabs(ql[k]), aqt = fabs(qt[k]);
        r[k] = (aql < 1e150 && aqt < 1e150) ? sqrt(ql[k] * ql[k] + qt[k] * qt[k]) : hypot(ql[k], qt[k]);
    }
    double th[CONTACT_BATCH], g[CONTACT_BATCH], h[CONTACT_BATCH];
    for (int k = 0; k < n; ++k) tanh_ratio(r[k], jacobians, &th[k], &g[k], &h[k]);

    for (int k = 0; k < n; ++k) {
        if (qt[k] == 0.0) {
            /* straight running: Eqn 5 verbatim (r = |ql|, tanh is odd) */
            out[k].F_long = Fmax[k] * copysign(th[k], ql[k]);
            out[k].F_lat = 0.0;
        } else {
            out[k].F_long = Fmax[k] * g[k] * ql[k];
            out[k].F_lat = Fmax[k] * g[k] * qt[k];
        }
        if (!jacobians) continue;

        /* dF/dq = Fmax (g I + h q q^T) */
        const double M00 = Fmax[k] * (g[k] + h[k] * ql[k] * ql[k]);
        const double M01 = Fmax[k] * h[k] * ql[k] * qt[k];
        const double M11 = Fmax[k] * (g[k] + h[k] * qt[k] * qt[k]);

        /* dq/d(v_long, v_lat, omega_r); dql/dv_lat = 0.  Plain scalars: built
         * as arrays, GCC vectorised the products below through a 16-byte load
         * of two 8-byte stores, a store-forwarding stall that perf showed as
         * 40 % of this function. */
        const double dql_v = kx * (-1.0 - s_long[k] * dden_dv[k]) * inv_den[k];
        const double dql_w = kx * (1.0 - s_long[k] * dden_dw[k]) * inv_den[k];
        const double dqt_v = ky * (-s_lat[k] * dden_dv[k]) * inv_den[k];
        const double dqt_t = -ky * inv_den[k];
        const double dqt_w = ky * (-s_lat[k] * dden_dw[k]) * inv_den[k];
        double *jac = out[k].jac;
        jac[0] = M00 * dql_v + M01 * dqt_v;
        jac[1] = M01 * dqt_t;
        jac[2] = M00 * dql_w + M01 * dqt_w;
        jac[3] = M01 * dql_v + M11 * dqt_v;
        jac[4] = M11 * dqt_t;
        jac[5] = M01 * dql_w + M11 * dqt_w;
    }
}

void contact_shear(const ContactModel *m, double Fn, double area,
                   double v_long, double v_lat, double omega_r,
                   double *F_long, double *F_lat, double *jac)
{
    const ShearInput in = {Fn, area, v_long, v_lat, omega_r};
    ShearForce out;
    shears(m, 1, &in, &out, jac != NULL);
    *F_long = out.F_long;
    *F_lat = out.F_lat;
    if (jac)
        for (int i = 0; i < 6; ++i) jac[i] = out.jac[i];
}

void contact_shears(const ContactModel *m, int n, const ShearInput *in, ShearForce *out, int jacobians)
{
    for (int i = 0; i < n; i += CONTACT_BATCH)
        shears(m, n - i < CONTACT_BATCH ? n - i : CONTACT_BATCH, in + i, out + i, jacobians);
}

/* ------------------------------------------------------------------------
 * 6. Soil memory (rebound, gamma).
 *
 * Reading of the paper's lost Figure 1 (model notes, section 2): soil the
 * wheel has already passed over springs back by gamma z_max, so that half
 * of the patch is cut by (1 - gamma) z_max.  The cut grows with the
 * distance rolled, phi = min(1, |travel| / L), so a wheel pressed down at
 * rest has symmetric contact (no creep at rest) and one that has rolled
 * one half contact length has the full cut.
 * ---------------------------------------------------------------------- */

/* Half contact length at depth z (0 for z <= 0). */
static double half_length_at(double R, double z)
{
    z = clamp_depth(R, z);
    return z > 0.0 ? chord_half(R, z) : 0.0;
}

void contact_cuts(const ContactModel *m, const ContactMemory *mem,
                  double sinkage, double *cut_front, double *cut_rear)
{
    *cut_front = 0.0;
    *cut_rear = 0.0;
    const double L = half_length_at(m->radius, mem->zmax);
    if (!(L > 0.0) || !(sinkage > 0.0)) return;

    const double a = fabs(mem->travel) / L;
    const double phi = a < 1.0 ? a : 1.0;
    double cut = phi * (1.0 - m->gamma) * mem->zmax;
    if (cut > sinkage) cut = sinkage;
    if (!(cut > 0.0)) cut = 0.0;

    if (mem->travel > 0.0)
        *cut_rear = cut;        /* rolled forward: soil behind is passed */
    else if (mem->travel < 0.0)
        *cut_front = cut;       /* rolled backward */
}

double contact_rolling_factor(const ContactModel *m, const ContactMemory *mem, double v_long)
{
    /* Rolling resistance is the horizontal part of a normal force tilted by
     * the rebound; it is dissipative, so like Coulomb friction it opposes
     * the motion and has no definite direction at standstill.  Regularised
     * like the slip law: the paper's tilt when moving at slip_v_eps or
     * faster in the direction that shaped the patch, none at rest, and
     * reversed (still resisting) when moving the other way.  Moving back
     * over its own rut the real wheel meets compacted soil; the per-wheel
     * memory cannot represent that rut, so the magnitude is kept. */
    if (mem->travel == 0.0) return 0.0;
    double b = v_long / m->slip_v_eps;
    b = b > 1.0 ? 1.0 : (b < -1.0 ? -1.0 : b);
    return mem->travel > 0.0 ? b : -b;
}

void contact_memory_update(const ContactModel *m, ContactMemory *mem,
                           double sinkage, double v_long, double dt)
{
    const double R = m->radius;
    if (!(sinkage > 0.0)) {
        /* lift-off: the wheel lands on virgin soil next time */
        mem->zmax = 0.0;
        mem->travel = 0.0;
        return;
    }
    const double step = v_long * dt;
    if (sinkage >= mem->zmax) {
        mem->zmax = sinkage;
    } else {
        /* Shallower than the deepest rut: the soil under the wheel is
         * replaced by less compacted soil as it rolls on.  First-order
         * relaxation with length scale L (the gap shrinks by the fraction
         * |v| dt / L per step, ~exp(-distance / L)); at rest zmax is kept,
         * since the soil under a standing wheel does not change. */
        const double L = half_length_at(R, mem->zmax);
        const double a = L > 0.0 ? fabs(step) / L : 1.0;
        mem->zmax -= (mem->zmax - sinkage) * (a < 1.0 ? a : 1.0);
    }
    const double Lnew = half_length_at(R, mem->zmax);
    double travel = mem->travel + step;
    if (travel > Lnew) travel = Lnew;
    if (travel < -Lnew) travel = -Lnew;
    mem->travel = travel;
}
