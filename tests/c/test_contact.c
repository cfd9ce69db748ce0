/*
 * Specification tests for the volumetric wheel/soil contact (contact.c).
 *
 * Standalone: prints one line per check and a final "N passed, M failed";
 * exits nonzero if any check failed.
 *
 * Values: Table 2 of Petersen & McPhee (2013) (kh = 1.58e5, eta = 0.501,
 * gamma = 0.0813, Kvx = 0.819), wheel R = 0.2794 m, width = 0.254 m;
 * cohesion 800 Pa and phi = 0.55 rad are placeholders (not in the paper).
 * The static load is a quarter of the rover: 317.7 kg * 9.81 / 4 = 779 N.
 */
#include "contact.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"

static ContactModel table2(double eta, double gamma, int method)
{
    ContactModel m;
    memset(&m, 0, sizeof m);
    m.kh = 1.58e5;
    m.eta = eta;
    m.gamma = gamma;
    m.Kvx = 0.819;
    m.Kvy_ratio = 1.0;
    m.cohesion = 800.0;
    m.phi = 0.55;
    m.radius = R_WHEEL;
    m.width = B_WHEEL;
    m.slip_v_eps = 0.01;
    m.method = method;
    char err[256];
    if (contact_model_prepare(&m, err, sizeof err) != 0) {
        printf("FAIL  unexpected prepare error: %s\n", err);
        ++n_fail;
    }
    return m;
}

/* The tilt alpha of the normal force (Eqn 7), from its sine and cosine. */
static double alpha_of(const ContactPatch *p) { return atan2(p->sin_alpha, p->cos_alpha); }

static double rel_err(double a, double b)
{
    return fabs(a - b) / fmax(fabs(b), 1e-300);
}

/* Half-angle of a full cylinder segment of depth z, independent of contact.c. */
static double seg_angle(double z) { return acos(1.0 - z / R_WHEEL); }

/* ---- loading states used by several tests ---- */
enum { SYMMETRIC, FRONT_ONLY, ROLLED };

/* Patch at sinkage s: symmetric (wheel at rest on virgin soil), front-only
 * (rear half fully cut), or rolled (steady rolling: memory with zmax = s
 * and travel saturated, cuts from contact_cuts). */
static void patch_in_state(const ContactModel *m, int state, double s,
                           ContactPatch *p)
{
    double cf = 0.0, cr = 0.0;
    if (state == FRONT_ONLY) {
        cr = s;
    } else if (state == ROLLED) {
        ContactMemory mem = {s, 1.0};  /* 1 m >> any half length */
        contact_cuts(m, &mem, s, &cf, &cr);
    }
    contact_patch(m, s, cf, cr, p);
}

static double vertical_force(const ContactModel *m, int state, double s)
{
    ContactPatch p;
    patch_in_state(m, state, s, &p);
    return p.Fn * p.cos_alpha;
}

/* Sinkage at which the normal force carries `load` vertically (bisection;
 * the vertical force grows monotonically with sinkage). */
static double static_sinkage(const ContactModel *m, int state, double load)
{
    double lo = 0.0, hi = 0.25;
    for (int i = 0; i < 100; ++i) {
        const double mid = 0.5 * (lo + hi);
        if (vertical_force(m, state, mid) < load) lo = mid; else hi = mid;
    }
    return 0.5 * (lo + hi);
}

/* ------------------------------------------------------------------------ */

static void test_exact_identities(void)
{
    printf("-- 1. exact identities: eta = 1 gives Vh = V, eta = 0 gives Vh = area\n");
    double worst1 = 0.0, worst0 = 0.0, worstV = 0.0, worstNum = 0.0;
    for (double z = 0.001; z <= 0.1000001; z += 0.001) {
        const double t0 = seg_angle(z);
        const double V = B_WHEEL * R_WHEEL * R_WHEEL * (t0 - sin(t0) * cos(t0));
        const double Vlib = 2.0 * contact_half_volume(R_WHEEL, B_WHEEL, z);
        worstV = fmax(worstV, rel_err(Vlib, V));
        const double Vh1 = 2.0 * contact_half_hypervolume_quadrature(R_WHEEL, B_WHEEL, 1.0, z);
        worst1 = fmax(worst1, rel_err(Vh1, V));
        const double area = B_WHEEL * 2.0 * R_WHEEL * sin(t0);
        const double Vh0 = 2.0 * contact_half_hypervolume_quadrature(R_WHEEL, B_WHEEL, 0.0, z);
        worst0 = fmax(worst0, rel_err(Vh0, area));
    }
    /* The segment formula itself, against a plain midpoint sum of the depth. */
    for (double z = 0.01; z <= 0.1000001; z += 0.03) {
        const double L = R_WHEEL * sin(seg_angle(z));
        const int N = 200000;
        double sum = 0.0;
        for (int i = 0; i < N; ++i) {
            const double x = -L + (i + 0.5) * 2.0 * L / N;
            sum += sqrt(R_WHEEL * R_WHEEL - x * x) - (R_WHEEL - z);
        }
        sum *= B_WHEEL * 2.0 * L / N;
        worstNum = fmax(worstNum, rel_err(2.0 * contact_half_volume(R_WHEEL, B_WHEEL, z), sum));
    }
    CHECK(worstV < 1e-12, "V = b R^2 (t0 - sin t0 cos t0) for the full segment, 1..100 mm (max rel err %.2e)", worstV);
    CHECK(worstNum < 1e-6, "segment volume formula agrees with a direct midpoint sum (max rel err %.2e)", worstNum);
    CHECK(worst1 < 1e-6, "eta = 1: quadrature Vh equals the exact volume, 1..100 mm (max rel err %.2e)", worst1);
    CHECK(worst0 < 1e-6, "eta = 0: quadrature Vh equals the contact area b 2R sin t0, 1..100 mm (max rel err %.2e)", worst0);

    /* The same identities through contact_patch. */
    ContactModel m1 = table2(1.0, 0.0813, CONTACT_QUADRATURE);
    ContactModel m1c = table2(1.0, 0.0813, CONTACT_CLOSED_FORM);
    ContactModel m0 = table2(1e-9, 0.0813, CONTACT_QUADRATURE);
    ContactPatch p;
    double w1 = 0.0, w1c = 0.0, w0 = 0.0;
    for (double z = 0.005; z <= 0.08; z += 0.005) {
        contact_patch(&m1, z, 0.0, 0.0, &p);
        w1 = fmax(w1, rel_err(p.Vh, p.V));
        contact_patch(&m1c, z, 0.0, 0.0, &p);
        w1c = fmax(w1c, rel_err(p.Vh, p.V));
        contact_patch(&m0, z, 0.0, 0.0, &p);
        w0 = fmax(w0, rel_err(p.Vh, p.area));
    }
    CHECK(w1 < 1e-6, "contact_patch, quadrature, eta = 1: Vh = V (max rel err %.2e)", w1);
    CHECK(w1c < 1e-12, "contact_patch, closed form, eta = 1: Vh = V exactly (max rel err %.2e)", w1c);
    CHECK(w0 < 1e-6, "contact_patch, quadrature, eta = 1e-9: Vh = area (max rel err %.2e)", w0);

    contact_patch(&m1, 0.0, 0.0, 0.0, &p);
    CHECK(p.Vh == 0.0 && p.Fn == 0.0 && p.area == 0.0 && alpha_of(&p) == 0.0,
          "zero sinkage: no contact, all outputs zero");
    contact_patch(&m1, -0.01, 0.0, 0.0, &p);
    CHECK(p.Vh == 0.0 && p.Fn == 0.0, "negative sinkage (wheel above ground): no force");
    contact_patch(&m1, 2.0 * R_WHEEL, 0.0, 0.0, &p);
    CHECK(isfinite(p.Fn) && p.Fn > 0.0 && fabs(p.length_front - R_WHEEL) < 1e-12,
          "sinkage beyond R is clamped to R: finite force, half length = R");
}

static void test_closed_form_vs_quadrature(void)
{
    printf("-- 2. closed form (Eqn 3 with fitted A1, Vint) vs quadrature\n");
    const double etas[] = {0.3, 0.501, 0.583, 0.8, 1.2};
    for (int i = 0; i < 5; ++i) {
        ContactModel mc = table2(etas[i], 0.0813, CONTACT_CLOSED_FORM);
        ContactModel mq = table2(etas[i], 0.0813, CONTACT_QUADRATURE);
        double worst = 0.0, worst_eqn3 = 0.0;
        for (double z = 0.005; z <= 0.0800001; z += 0.0025) {
            ContactPatch pc, pq;
            contact_patch(&mc, z, 0.0, 0.0, &pc);
            contact_patch(&mq, z, 0.0, 0.0, &pq);
            worst = fmax(worst, rel_err(pc.Vh, pq.Vh));
            /* symmetric contact reduces exactly to the paper's Eqn 3 */
            const double eqn3 = pc.V * pow(pc.V / mc.Vint, mc.A1 * (mc.eta - 1.0));
            worst_eqn3 = fmax(worst_eqn3, rel_err(pc.Vh, eqn3));
        }
        CHECK(worst < 0.03, "eta = %.3f: closed-form Vh within 3%% of quadrature over 5..80 mm (max %.2f%%, A1 = %.4f)",
              etas[i], 100.0 * worst, mc.A1);
        CHECK(worst_eqn3 < 1e-12, "eta = %.3f: symmetric closed form is Eqn 3, Vh = V (V/Vint)^(A1 (eta-1)) (rel %.1e)",
              etas[i], worst_eqn3);
    }
    ContactModel m = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    CHECK(fabs(m.A1 / (2.0 / 3.0) - 1.0) < 0.05,
          "eta = 0.501: fitted A1 = %.4f within 5%% of the shallow-sinkage limit 2/3 (Vint = %.4g m^3)",
          m.A1, m.Vint);
    CHECK(m.A1 > 2.0 / 3.0, "eta = 0.501: fitted A1 is above 2/3 (finite-depth correction, notes: ~0.68)");
    CHECK(fabs(m.cz_eta - (0.501 + 1.0) / (2.0 * 0.501 + 3.0)) < 1e-15 && m.cx_eta > 0.0 && m.cx_eta < 0.5,
          "centroid factors: cz = (eta+1)/(2 eta+3) = %.4f, 0 < cx = %.4f < 1/2", m.cz_eta, m.cx_eta);
    ContactModel m1 = table2(1.0, 0.0813, CONTACT_CLOSED_FORM);
    CHECK(m1.A1 == 2.0 / 3.0 && m1.Vint > 0.0, "eta = 1 (degenerate fit): A1 = 2/3, Vint > 0");
}

static void test_free_rolling_gamma_one(void)
{
    printf("-- 3. gamma = 1: full rebound, symmetric contact, no compaction resistance\n");
    for (int method = 0; method <= 1; ++method) {
        ContactModel m = table2(0.501, 1.0, method);
        const double s = 0.02;
        ContactMemory mem = {s, 0.0};
        mem.travel = 2.0 * R_WHEEL * sin(seg_angle(s)); /* rolled well beyond L */
        double cf = -1.0, cr = -1.0;
        contact_cuts(&m, &mem, s, &cf, &cr);
        ContactPatch p;
        contact_patch(&m, s, cf, cr, &p);
        CHECK(cf == 0.0 && cr == 0.0, "method %d: rolled wheel, gamma = 1: both cuts are zero", method);
        CHECK(p.xc == 0.0 && alpha_of(&p) == 0.0, "method %d: centroid xc = %g, alpha = %g: straight below the hub",
              method, p.xc, alpha_of(&p));
        CHECK(-p.Fn * p.sin_alpha == 0.0 && p.Fn > 0.0,
              "method %d: horizontal normal-force component -Fn sin(alpha) = 0 at Fn = %.1f N", method, p.Fn);
    }
}

static void test_resistance_vs_gamma(void)
{
    printf("-- 4. compaction resistance at equal vertical load (779 N) falls as gamma rises\n");
    for (int method = 0; method <= 1; ++method) {
        double prev = INFINITY, first = 0.0, last = 0.0;
        int monotone = 1;
        for (int k = 0; k <= 10; ++k) {
            ContactModel m = table2(0.501, 0.1 * k, method);
            const double s = static_sinkage(&m, ROLLED, LOAD);
            ContactPatch p;
            patch_in_state(&m, ROLLED, s, &p);
            const double res = p.Fn * p.sin_alpha;
            printf("      method %d gamma %.1f: sinkage %.2f mm, resistance %.2f N\n", method, 0.1 * k, 1e3 * s, res);
            if (!(res < prev)) monotone = 0;
            prev = res;
            if (k == 0) first = res;
            last = res;
        }
        CHECK(monotone, "method %d: resistance strictly decreasing over gamma = 0, 0.1, ..., 1", method);
        CHECK(first > 10.0, "method %d: gamma = 0 has a real resistance (%.1f N > 10 N)", method, first);
        CHECK(fabs(last) < 1e-9, "method %d: gamma = 1 has none (%.2e N)", method, last);
    }
}

static void test_centroid(void)
{
    printf("-- 5. centroid: symmetric patch on the axis, front-only patch ahead of the hub\n");
    for (int method = 0; method <= 1; ++method) {
        ContactModel m = table2(0.501, 0.0, method);
        const double s = 0.03;
        ContactPatch p;
        patch_in_state(&m, SYMMETRIC, s, &p);
        CHECK(p.xc == 0.0 && alpha_of(&p) == 0.0 && p.zc < -(R_WHEEL - s) && p.zc > -R_WHEEL,
              "method %d: symmetric patch: xc = 0 exactly, centroid between rim bottom and surface (zc = %.4f)",
              method, p.zc);
        patch_in_state(&m, ROLLED, s, &p);   /* gamma = 0: front only */
        CHECK(p.length_rear == 0.0 && p.xc > 0.0 && alpha_of(&p) > 0.0,
              "method %d: gamma = 0, rolled: front-only contact, xc = %.4f m > 0, alpha = %.4f rad > 0",
              method, p.xc, alpha_of(&p));
    }
    ContactModel mc = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    ContactModel mq = table2(0.501, 0.0813, CONTACT_QUADRATURE);
    double wx = 0.0, wz = 0.0;
    for (double s = 0.005; s <= 0.0800001; s += 0.0025) {
        /* front-only and a partial rear cut */
        const double cuts[2] = {s, 0.6 * s};
        for (int i = 0; i < 2; ++i) {
            ContactPatch pc, pq;
            contact_patch(&mc, s, 0.0, cuts[i], &pc);
            contact_patch(&mq, s, 0.0, cuts[i], &pq);
            wx = fmax(wx, fabs(pc.xc - pq.xc) / pq.length_front);
            wz = fmax(wz, fabs(pc.zc - pq.zc) / s);
        }
    }
    CHECK(wx < 0.02, "closed-form centroid xc within 2%% of the half length of quadrature, 5..80 mm (max %.2f%%)",
          100.0 * wx);
    CHECK(wz < 0.02, "closed-form centroid zc within 2%% of the sinkage of quadrature, 5..80 mm (max %.2f%%)",
          100.0 * wz);

    ContactPatch pf, pr;
    contact_patch(&mq, 0.03, 0.0, 0.01, &pr);
    contact_patch(&mq, 0.03, 0.01, 0.0, &pf);
    CHECK(fabs(pf.xc + pr.xc) < 1e-15 && fabs(pf.zc - pr.zc) < 1e-15 && pf.Fn == pr.Fn,
          "mirror symmetry: a front cut mirrors a rear cut (xc -> -xc)");
}

static void test_static_sinkage(void)
{
    printf("-- 6. static sinkage under a quarter of the rover (779 N), Table 2 soil\n");
    ContactModel mc = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    ContactModel mq = table2(0.501, 0.0813, CONTACT_QUADRATURE);
    const double sc = static_sinkage(&mc, SYMMETRIC, LOAD);
    const double sq = static_sinkage(&mq, SYMMETRIC, LOAD);
    const double fc = static_sinkage(&mc, FRONT_ONLY, LOAD);
    const double fq = static_sinkage(&mq, FRONT_ONLY, LOAD);
    CHECK(fabs(vertical_force(&mq, SYMMETRIC, sq) - LOAD) < 1e-6, "bisection converged (%.9f N)",
          vertical_force(&mq, SYMMETRIC, sq));
    CHECK(sc > 0.01 && sc < 0.03, "symmetric, closed form: %.2f mm in 10..30 mm (notes: ~17 mm)", 1e3 * sc);
    CHECK(sq > 0.01 && sq < 0.03, "symmetric, quadrature: %.2f mm in 10..30 mm", 1e3 * sq);
    CHECK(fc > 0.025 && fc < 0.05, "front-only, closed form: %.2f mm in 25..50 mm (notes: ~35 mm)", 1e3 * fc);
    CHECK(fq > 0.025 && fq < 0.05, "front-only, quadrature: %.2f mm in 25..50 mm", 1e3 * fq);
    CHECK(rel_err(sc, sq) < 0.03, "symmetric: closed form and quadrature agree within 3%% (%.2f%%)",
          100.0 * rel_err(sc, sq));
    CHECK(rel_err(fc, fq) < 0.03, "front-only: closed form and quadrature agree within 3%% (%.2f%%)",
          100.0 * rel_err(fc, fq));
}

/* Small deterministic generator for the shear tests. */
static unsigned long long rng_state = 0x9E3779B97F4A7C15ULL;
static double urand(double lo, double hi)
{
    rng_state = rng_state * 6364136223846793005ULL + 1442695040888963407ULL;
    const double u = (double)(rng_state >> 11) * (1.0 / 9007199254740992.0);
    return lo + (hi - lo) * u;
}

static void test_shear(void)
{
    printf("-- 7. shear force: Eqn 5 on straight running, slip-vector direction, Jacobian\n");
    ContactModel m = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    m.Kvy_ratio = 0.7;  /* a distinct lateral modulus exercises the elliptic scaling */
    char err[256];
    CHECK(contact_model_prepare(&m, err, sizeof err) == 0, "prepared again after changing Kvy_ratio %s", err);
    ContactPatch p;
    contact_patch(&m, 0.02, 0.0, 0.0, &p);
    const double Fn = p.Fn, area = p.area;
    const double Fmax = area * m.cohesion + Fn * tan(m.phi);

    /* straight running at several slips: drive, brake, reverse */
    const double vw[][2] = {{1.0, 1.2}, {1.0, 3.0}, {0.5, 0.3}, {1.0, 0.0}, {0.2, 1.0},
                            {-1.0, -1.3}, {-0.8, -0.2}, {0.0, 0.5}, {0.3, -0.3}};
    double worst = 0.0;
    int signs_ok = 1;
    for (size_t i = 0; i < sizeof vw / sizeof vw[0]; ++i) {
        const double v = vw[i][0], w = vw[i][1];
        const double den = fmax(fmax(fabs(v), fabs(w)), m.slip_v_eps);
        const double s_long = (w - v) / den;
        double Fl, Ft;
        contact_shear(&m, Fn, area, v, 0.0, w, &Fl, &Ft, NULL);
        worst = fmax(worst, rel_err(Fl, Fmax * tanh(s_long / m.Kvx)));
        if (Ft != 0.0 || (s_long > 0.0) != (Fl > 0.0)) signs_ok = 0;
    }
    CHECK(worst < 1e-12, "v_lat = 0: F_long = F_taumax tanh(S_long / Kvx) (Eqn 5), max rel err %.1e", worst);
    CHECK(signs_ok, "v_lat = 0: no lateral force, F_long has the sign of the slip (braking < 0)");

    double Fl, Ft;
    contact_shear(&m, Fn, area, 1.0, 0.0, 0.5, &Fl, &Ft, NULL);
    CHECK(Fl < 0.0, "braking (omega R < v): F_long = %.1f N < 0", Fl);

    contact_shear(&m, Fn, area, 1.0, 0.3, 1.0, &Fl, &Ft, NULL);
    const double q = 0.3 / (m.Kvy_ratio * m.Kvx);
    CHECK(Fl == 0.0 && Ft < 0.0 && rel_err(Ft, -Fmax * tanh(q)) < 1e-12,
          "pure lateral sliding v_lat = +0.3: F_lat = %.1f N opposes it, F_long = 0, |F| = F_taumax tanh(|q|)", Ft);
    contact_shear(&m, Fn, area, 0.0, -0.2, 0.0, &Fl, &Ft, NULL);
    CHECK(Fl == 0.0 && Ft > 0.0, "pure lateral sliding at zero spin, v_lat = -0.2: F_lat = %.1f N > 0", Ft);

    contact_shear(&m, Fn, area, 1.3, 0.0, 1.3, &Fl, &Ft, NULL);
    CHECK(Fl == 0.0 && Ft == 0.0, "zero slip (omega R = v, v_lat = 0): zero force");
    double J[6];
    contact_shear(&m, Fn, area, 0.0, 0.0, 0.0, &Fl, &Ft, J);
    int jfin = 1;
    for (int k = 0; k < 6; ++k) jfin = jfin && isfinite(J[k]);
    CHECK(Fl == 0.0 && Ft == 0.0 && jfin, "standstill (all velocities 0): zero force, finite Jacobian");
    contact_shear(&m, Fn, area, 1e-5, -2e-5, 3e-5, &Fl, &Ft, NULL);
    CHECK(isfinite(Fl) && isfinite(Ft) && hypot(Fl, Ft) < 0.01 * Fmax,
          "creeping (|v| << slipVelocityEps): small, finite force (%.3g N)", hypot(Fl, Ft));

    double fmax_ratio = 0.0;
    for (int i = 0; i < 2000; ++i) {
        const double v = urand(-3, 3), vl = urand(-3, 3), w = urand(-3, 3);
        contact_shear(&m, Fn, area, v, vl, w, &Fl, &Ft, NULL);
        fmax_ratio = fmax(fmax_ratio, hypot(Fl, Ft) / Fmax);
    }
    /* up to rounding: tanh saturates to 1 in double precision */
    CHECK(fmax_ratio <= 1.0 + 1e-14, "|F| never exceeds F_taumax (max |F|/F_taumax - 1 = %.1e over 2000 random states)",
          fmax_ratio - 1.0);

    /* Jacobian vs central differences at points away from the kinks of
     * den = max(|omega R|, |v|, eps). Tolerance: 1e-5 of the largest entry. */
    int n_ok = 0, n_pts = 0;
    double worst_j = 0.0;
    while (n_pts < 50) {
        /* mix of scales: cruising, slow, and inside the eps region */
        const double scale = (n_pts % 5 == 0) ? 0.008 : ((n_pts % 5 == 1) ? 0.05 : 2.0);
        double x[3] = {urand(-scale, scale), urand(-scale, scale), urand(-scale, scale)};
        const double av = fabs(x[0]), aw = fabs(x[2]);
        const double dmax = fmax(av, aw);
        if (fabs(av - aw) < 0.02 * scale || fabs(dmax - m.slip_v_eps) < 0.02 * scale) continue;
        if (n_pts % 10 == 9) x[1] = 0.0;   /* straight running: the Eqn 5 branch */
        ++n_pts;
        double Jan[6];
        contact_shear(&m, Fn, area, x[0], x[1], x[2], &Fl, &Ft, Jan);
        const double hstep = 1e-6 * fmax(scale, m.slip_v_eps);
        double err_max = 0.0, jmax = 0.0;
        for (int j = 0; j < 3; ++j) {
            double xp[3] = {x[0], x[1], x[2]}, xm[3] = {x[0], x[1], x[2]};
            xp[j] += hstep;
            xm[j] -= hstep;
            double Fpl, Fpt, Fml, Fmt;
            contact_shear(&m, Fn, area, xp[0], xp[1], xp[2], &Fpl, &Fpt, NULL);
            contact_shear(&m, Fn, area, xm[0], xm[1], xm[2], &Fml, &Fmt, NULL);
            const double d0 = (Fpl - Fml) / (2.0 * hstep), d1 = (Fpt - Fmt) / (2.0 * hstep);
            err_max = fmax(err_max, fmax(fabs(d0 - Jan[j]), fabs(d1 - Jan[3 + j])));
        }
        for (int k = 0; k < 6; ++k) jmax = fmax(jmax, fabs(Jan[k]));
        const double e = err_max / jmax;
        worst_j = fmax(worst_j, e);
        if (e < 1e-5) ++n_ok;
    }
    CHECK(n_ok == 50, "Jacobian d(F_long, F_lat)/d(v_long, v_lat, omega R) matches central differences at %d/50 points (worst %.1e)",
          n_ok, worst_j);
}

static void test_prepare_validation(void)
{
    printf("-- 8. contact_model_prepare rejects bad parameters, naming them\n");
    const double nan = NAN, inf = INFINITY;
    struct {
        const char *name;
        int field;
        double value;
    } cases[] = {
        {"soil.kh", 0, 0.0},          {"soil.kh", 0, -1.0},        {"soil.kh", 0, nan},
        {"soil.kh", 0, inf},          {"soil.eta", 1, 0.0},        {"soil.eta", 1, -0.5},
        {"soil.eta", 1, nan},         {"soil.eta", 1, inf},        {"soil.gamma", 2, -0.01},
        {"soil.gamma", 2, 1.01},      {"soil.gamma", 2, nan},      {"soil.Kvx", 3, 0.0},
        {"soil.Kvx", 3, nan},         {"soil.KvyRatio", 4, 0.0},   {"soil.KvyRatio", 4, -2.0},
        {"soil.cohesion", 5, -1.0},   {"soil.cohesion", 5, inf},   {"soil.phi", 6, -0.1},
        {"soil.phi", 6, M_PI / 2.0},  {"soil.phi", 6, nan},        {"wheel.radius", 7, 0.0},
        {"wheel.radius", 7, -0.3},    {"wheel.radius", 7, nan},    {"wheel.width", 8, 0.0},
        {"wheel.width", 8, inf},      {"contact.slipVelocityEps", 9, 0.0},
        {"contact.slipVelocityEps", 9, -1e-3}, {"contact.method", 10, 2.0},
        {"contact.method", 10, -1.0},
    };
    int all = 1;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        ContactModel m = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
        double *fields[10] = {&m.kh, &m.eta, &m.gamma, &m.Kvx, &m.Kvy_ratio, &m.cohesion,
                              &m.phi, &m.radius, &m.width, &m.slip_v_eps};
        if (cases[i].field == 10) m.method = (int)cases[i].value;
        else *fields[cases[i].field] = cases[i].value;
        char err[256] = "";
        const int rc = contact_model_prepare(&m, err, sizeof err);
        const int ok = rc == -1 && strstr(err, cases[i].name) != NULL;
        if (!ok) all = 0;
        CHECK(ok, "%s = %g rejected: \"%s\"", cases[i].name, cases[i].value, err);
    }
    CHECK(all, "every bad parameter rejected with its FMU name");

    ContactModel m = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    m.eta = -0.5;
    char err[256] = "";
    contact_model_prepare(&m, err, sizeof err);
    CHECK(strstr(err, "-0.5") != NULL, "the message carries the bad value: \"%s\"", err);

    /* boundary values are legal */
    const double okvals[][3] = {{0.0, 0.0, 0.0}, {1.0, 0.0, 1.5}};
    int legal = 1;
    for (int i = 0; i < 2; ++i) {
        m = table2(0.501, 0.0813, CONTACT_QUADRATURE);
        m.gamma = okvals[i][0];
        m.cohesion = okvals[i][1];
        m.phi = okvals[i][2];
        err[0] = 'x';
        err[1] = '\0';
        if (contact_model_prepare(&m, err, sizeof err) != 0 || err[0] != '\0') legal = 0;
    }
    CHECK(legal, "gamma = 0 and 1, cohesion = 0, phi = 0 are accepted (and err is cleared)");
    m = table2(0.501, 0.0813, CONTACT_QUADRATURE);
    m.kh = -1.0;
    CHECK(contact_model_prepare(&m, NULL, 0) == -1, "a NULL error buffer is allowed");
}

static void test_memory(void)
{
    printf("-- 9. soil memory: rest, rolling, relaxation, lift-off\n");
    ContactModel m = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    const double s = 0.02, dt = 0.001;
    const double L = R_WHEEL * sin(seg_angle(s));
    ContactMemory mem = {0.0, 0.0};
    double cf, cr;

    /* pressed straight down at rest */
    for (int i = 1; i <= 100; ++i) contact_memory_update(&m, &mem, s * i / 100.0, 0.0, dt);
    contact_cuts(&m, &mem, s, &cf, &cr);
    CHECK(mem.zmax == s && mem.travel == 0.0, "pressed down at rest: zmax = sinkage, no travel");
    CHECK(cf == 0.0 && cr == 0.0, "wheel at rest pressed down: zero cuts (symmetric contact, no creep)");

    /* roll forward half a contact length: half the cut */
    const double v = 0.1;
    const int half_steps = (int)lround(0.5 * L / (v * dt));
    for (int i = 0; i < half_steps; ++i) contact_memory_update(&m, &mem, s, v, dt);
    contact_cuts(&m, &mem, s, &cf, &cr);
    const double frac = mem.travel / L;
    CHECK(cf == 0.0 && rel_err(cr, frac * (1.0 - m.gamma) * s) < 1e-12 && frac > 0.45 && frac < 0.55,
          "after rolling L/2 forward: rear cut = (travel/L)(1-gamma) zmax = %.3f mm", 1e3 * cr);

    /* roll on beyond L: full cut, travel saturates at L */
    for (int i = 0; i < 4 * half_steps; ++i) contact_memory_update(&m, &mem, s, v, dt);
    contact_cuts(&m, &mem, s, &cf, &cr);
    CHECK(fabs(mem.travel - L) < 1e-15, "travel saturates at the half contact length L = %.2f mm", 1e3 * L);
    CHECK(cf == 0.0 && rel_err(cr, (1.0 - m.gamma) * s) < 1e-12,
          "after rolling L forward: rear cut = (1-gamma) zmax = %.3f mm, front cut 0", 1e3 * cr);

    /* the same rolled wheel standing still, or creeping slower than the
     * regularisation speed: it keeps its rut (the force magnitude is
     * continuous) but its support turns vertical, so a stopped rover does
     * not push itself backwards (rebound acts only on soil the wheel has
     * passed over) */
    contact_cuts(&m, &mem, s, &cf, &cr);
    CHECK(cf == 0.0 && rel_err(cr, (1.0 - m.gamma) * s) < 1e-12, "standing still keeps the rear cut (the rut)");
    CHECK(contact_rolling_factor(&m, &mem, 0.0) == 0.0, "rolled wheel at standstill: normal force not tilted");
    CHECK(fabs(contact_rolling_factor(&m, &mem, 0.5 * m.slip_v_eps) - 0.5) < 1e-12,
          "rolled wheel at half the regularisation speed: half the tilt");
    CHECK(contact_rolling_factor(&m, &mem, v) == 1.0 && v >= m.slip_v_eps,
          "rolling at %.2f m/s: the paper's tilt, unchanged", v);
    CHECK(contact_rolling_factor(&m, &mem, -v) == -1.0,
          "rolled forward but now moving backwards: the tilt reverses and still resists the motion");

    /* a shallower sinkage while rolling: zmax relaxes towards it */
    ContactMemory relax = mem;
    contact_memory_update(&m, &relax, 0.5 * s, 0.0, dt);
    CHECK(relax.zmax == s, "unloading at rest keeps zmax (the soil under the wheel is unchanged)");
    contact_memory_update(&m, &relax, 0.5 * s, v, dt);
    CHECK(rel_err(relax.zmax, s - 0.5 * s * (v * dt / L)) < 1e-12,
          "unloading while rolling: zmax relaxes towards the sinkage by the fraction v dt / L per step (%.4f mm)",
          1e3 * relax.zmax);
    /* first-order relaxation with length scale L: the gap decays ~exp(-x/L) */
    for (int i = 0; i < 40 * half_steps; ++i) contact_memory_update(&m, &relax, 0.5 * s, v, dt);
    CHECK(fabs(relax.zmax - 0.5 * s) < 1e-9, "after rolling 20 L, zmax = the new sinkage (gap %.1e m)",
          relax.zmax - 0.5 * s);
    CHECK(fabs(relax.travel) <= R_WHEEL * sin(seg_angle(relax.zmax)) + 1e-15,
          "travel stays within +-L of the relaxed zmax");
    contact_memory_update(&m, &relax, 0.8 * s, v, dt);
    CHECK(relax.zmax == 0.8 * s, "deeper sinkage is followed at once");

    /* reversing: the cut moves to the front half */
    for (int i = 0; i < 8 * half_steps; ++i) contact_memory_update(&m, &mem, s, -v, dt);
    contact_cuts(&m, &mem, s, &cf, &cr);
    CHECK(fabs(mem.travel + L) < 1e-15 && cr == 0.0 && rel_err(cf, (1.0 - m.gamma) * s) < 1e-12,
          "after reversing beyond L: front cut = (1-gamma) zmax, rear cut 0");

    /* cuts never exceed the current sinkage */
    contact_cuts(&m, &mem, 0.3 * s, &cf, &cr);
    CHECK(cf == 0.3 * s, "cut clamped to the current sinkage");

    /* lift-off resets */
    contact_memory_update(&m, &mem, 0.0, v, dt);
    contact_cuts(&m, &mem, s, &cf, &cr);
    CHECK(mem.zmax == 0.0 && mem.travel == 0.0 && cf == 0.0 && cr == 0.0,
          "lift-off (sinkage 0): memory reset, virgin soil, zero cuts");
}

/* The normal stiffness dFn/dz that contact_patch returns (the integrator's
 * K matrix), against a central difference of Fn with the cuts fixed:
 * closed form (analytic) to 1e-6, quadrature (its own forward difference)
 * to 1e-4; and alpha from its sine and cosine is the centroid angle. */
static void test_normal_stiffness(void)
{
    printf("-- 10. normal stiffness dFn/dz and the tilt's sine and cosine\n");
    const double etas[] = {0.3, 0.501, 1.0, 1.6};
    const double depths[] = {0.0005, 0.005, 0.0319, 0.08, 0.2};
    for (int method = 0; method <= 1; ++method) {
        double worst = 0.0, worst_angle = 0.0;
        int n = 0;
        for (int i = 0; i < 4; ++i) {
            const ContactModel m = table2(etas[i], 0.0813, method);
            for (int j = 0; j < 5; ++j) {
                const double s = depths[j];
                /* symmetric, rolled (rear cut (1 - gamma) s), front cut, rear cut beyond s */
                const double cuts[4][2] = {{0.0, 0.0}, {0.0, (1.0 - m.gamma) * s}, {0.3 * s, 0.0}, {0.0, 2.0 * s}};
                for (int c = 0; c < 4; ++c) {
                    ContactPatch p, lo, hi;
                    const double dz = 1e-6 * s;
                    contact_patch(&m, s, cuts[c][0], cuts[c][1], &p);
                    contact_patch(&m, s - dz, cuts[c][0], cuts[c][1], &lo);
                    contact_patch(&m, s + dz, cuts[c][0], cuts[c][1], &hi);
                    const double fd = (hi.Fn - lo.Fn) / (2.0 * dz);
                    worst = fmax(worst, rel_err(p.dFn_dz, fd));
                    worst_angle = fmax(worst_angle, fabs(alpha_of(&p) - atan2(p.xc, -p.zc)));
                    worst_angle = fmax(worst_angle, fabs(p.sin_alpha * p.sin_alpha + p.cos_alpha * p.cos_alpha - 1.0));
                    ++n;
                }
            }
        }
        CHECK(worst < (method == CONTACT_CLOSED_FORM ? 1e-6 : 1e-4),
              "method %d: dFn/dz matches a central difference of Fn at fixed cuts, %d cases, eta 0.3..1.6, "
              "sinkage 0.5..200 mm (max rel err %.2e)", method, n, worst);
        CHECK(worst_angle < 1e-14, "method %d: sin_alpha, cos_alpha are those of atan2(xc, -zc) (max err %.1e)",
              method, worst_angle);
    }
    const ContactModel m = table2(0.501, 0.0813, CONTACT_CLOSED_FORM);
    ContactPatch p;
    contact_patch(&m, 2.0 * R_WHEEL, 0.0, 0.0, &p);
    CHECK(p.dFn_dz == 0.0 && p.Fn > 0.0, "sinkage beyond R (clamped): Fn = %.0f N, no stiffness", p.Fn);
    contact_patch(&m, 0.0, 0.0, 0.0, &p);
    CHECK(p.dFn_dz == 0.0 && p.sin_alpha == 0.0 && p.cos_alpha == 1.0, "no contact: no stiffness, alpha = 0");
}

int main(void)
{
    test_exact_identities();
    test_closed_form_vs_quadrature();
    test_free_rolling_gamma_one();
    test_resistance_vs_gamma();
    test_centroid();
    test_static_sinkage();
    test_shear();
    test_prepare_validation();
    test_memory();
    test_normal_stiffness();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
