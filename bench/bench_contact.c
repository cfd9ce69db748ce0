/*
 * Benchmark: nanoseconds per contact evaluation of
 *   - the volumetric model, closed form (contact_patch with
 *     CONTACT_CLOSED_FORM, then contact_shear with its Jacobian, as one
 *     substep of the FMU calls them),
 *   - the volumetric model, quadrature (CONTACT_QUADRATURE, same calls),
 *   - the Wong-Reece/Ishigami model with 100 integration points
 *     (wong_reece_forces),
 * at the same wheel load, 779 N (317.7 kg * 9.81 / 4).  Each model's
 * sinkage for that load is found first and printed, with whether the
 * sinkages match within 5 %.  The wheel rolls steadily (the rear half cut
 * by (1 - gamma) z, i.e. Wong-Reece lambda = gamma) at zero slip.
 *
 * The Wong-Reece soil: the published sets (dry sand, Toyoura sand) at
 * lambda = gamma and 0 give other sinkages than the volumetric model at
 * 779 N (their soils are not the paper's), so the comparison "at matching
 * sinkage" uses dry sand with its Bekker moduli kc, kphi scaled by one
 * factor chosen so that its sinkage equals the closed form's; the
 * published sets are timed too.
 *
 * What one evaluation is: what one step of the FMU's implicit integrator
 * needs from the law at a wheel.  Volumetric: contact_patch (with the
 * normal stiffness dFn/dz) and contact_shear with its Jacobian.  Wong-Reece
 * (the headline comparison): one wong_reece_forces call; and,
 * for the record, "as the FMU uses it": three calls (forces, and the
 * differences in slip and sinkage that give its damping and stiffness,
 * rover_wheel_contact.c, wong_reece_contact).
 *
 * Timing: every evaluation gets a different sinkage (+-1 % around the
 * matched one) and slip (0..0.3) from a table, results go to a volatile
 * sink; a batch of calls is sized to take --min-time seconds.  The cases'
 * batches are interleaved, round after round, so that a change of load on
 * a shared machine hits them alike; the figures are medians (and minima)
 * over --repeats rounds, and the speed-up is the median of the per-round
 * ratios.
 * Figures are printed, never asserted.  Not a test.
 *
 * usage: bench_contact [--repeats N] [--min-time S] [--json FILE]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "contact.h"
#include "model.h"
#include "bench_util.h"
#include "wong_reece.h"

#define LOAD 779.0
#define TABLE 256
#define MAX_REPEATS 1000

/* Wall and CPU time of every timed batch, for the CPU share (< 1: the
 * machine was busy and the wall-clock figures are inflated). */
static double total_wall, total_cpu;

static volatile double sink;

/* ------------------------------------------------------------ the models */

/* The FMU's contact model at its default parameters (modelDescription/variables.h). */
static int volumetric_model(ContactModel *cm, int method)
{
    static Model m;   /* large; zero-initialised */
    model_set_defaults(&m);
    memset(cm, 0, sizeof *cm);
    cm->kh = m.p.soil_kh;
    cm->eta = m.p.soil_eta;
    cm->gamma = m.p.soil_gamma;
    cm->Kvx = m.p.soil_Kvx;
    cm->Kvy_ratio = m.p.soil_KvyRatio;
    cm->cohesion = m.p.soil_cohesion;
    cm->phi = m.p.soil_phi;
    cm->radius = m.p.wheel_radius;
    cm->width = m.p.wheel_width;
    cm->slip_v_eps = m.p.contact_slipVelocityEps;
    cm->method = method;
    char err[256];
    if (contact_model_prepare(cm, err, sizeof err) != 0) {
        fprintf(stderr, "bench_contact: %s\n", err);
        return -1;
    }
    return 0;
}

/* Vertical load carried by the rolling wheel at sinkage s and zero slip:
 * rear half cut by (1 - gamma) s, normal force tilted by alpha. */
static double volumetric_load(const ContactModel *cm, double s)
{
    ContactPatch p;
    contact_patch(cm, s, 0.0, (1.0 - cm->gamma) * s, &p);
    return p.Fn * p.cos_alpha;
}

/* Sinkage carrying `load` (bisection; the load rises with sinkage). */
static double volumetric_sinkage(const ContactModel *cm, double load)
{
    double lo = 0.0, hi = cm->radius;
    for (int it = 0; it < 200; ++it) {
        const double mid = 0.5 * (lo + hi);
        if (volumetric_load(cm, mid) < load) lo = mid;
        else hi = mid;
    }
    return 0.5 * (lo + hi);
}

/* Wong-Reece model of a published set scaled by `modulus` (kc, kphi), lambda, 100 points. */
static int wr_model(WongReeceModel *wm, int toyoura, double lambda, double modulus,
                    double radius, double width)
{
    *wm = toyoura ? wong_reece_toyoura_sand(radius, width) : wong_reece_dry_sand(radius, width);
    wm->lambda = lambda;
    wm->kc *= modulus;
    wm->kphi *= modulus;
    wm->points = WONG_REECE_DEFAULT_POINTS;
    char err[256];
    if (wong_reece_prepare(wm, err, sizeof err) != 0) {
        fprintf(stderr, "bench_contact: %s\n", err);
        return -1;
    }
    return 0;
}

/* Modulus factor that makes dry sand (lambda) sink `target` at LOAD, zero slip
 * (bisection in log: a stiffer soil sinks less). */
static double wr_matching_modulus(double lambda, double target, double radius, double width)
{
    double lo = log(1e-3), hi = log(1e3);
    for (int it = 0; it < 100; ++it) {
        const double mid = 0.5 * (lo + hi);
        WongReeceModel wm;
        if (wr_model(&wm, 0, lambda, exp(mid), radius, width) != 0) return NAN;
        if (wong_reece_sinkage_for_load(&wm, LOAD, 0.0) > target) lo = mid;
        else hi = mid;
    }
    return exp(0.5 * (lo + hi));
}

/* ------------------------------------------------------------ timing */

typedef struct {
    const ContactModel *cm;
    const WongReeceModel *wm;
    double sinkage[TABLE], slip[TABLE];
} Workload;

/* A batch of volumetric evaluations: contact_patch, then contact_shear with
 * its Jacobian if with_jacobian, else the forces alone.  The forces alone
 * are the like-for-like counterpart of one wong_reece_forces call, which
 * gives no derivatives either (contact_patch's dFn/dz is a by-product of
 * its volumes and stays).  Inlined with a constant flag, each runner below
 * is its own loop. */
static inline void volumetric_batch(const Workload *w, long n, int with_jacobian)
{
    const ContactModel *cm = w->cm;
    const double v = 0.15;                   /* hub speed, m/s */
    double acc = 0.0;
    for (long i = 0; i < n; ++i) {
        const int k = (int)(i & (TABLE - 1));
        const double s = w->sinkage[k];
        ContactPatch p;
        contact_patch(cm, s, 0.0, (1.0 - cm->gamma) * s, &p);
        double F_long, F_lat, jac[6] = {0};
        /* omega R such that the slip is w->slip[k]; a little lateral slip */
        contact_shear(cm, p.Fn, p.area, v, 0.002, v / (1.0 - w->slip[k]), &F_long, &F_lat,
                      with_jacobian ? jac : NULL);
        acc += p.Fn * p.cos_alpha + p.dFn_dz + F_long + F_lat + jac[0];
    }
    sink = acc;
}

static void run_volumetric(const Workload *w, long n) { volumetric_batch(w, n, 1); }
static void run_volumetric_forces(const Workload *w, long n) { volumetric_batch(w, n, 0); }

/* Wong-Reece as rover_wheel_contact.c's wong_reece_contact calls it in a matrices
 * evaluation at speed: the forces, then a slip step and a sinkage step. */
static void run_wong_reece_fmu(const Workload *w, long n)
{
    double acc = 0.0;
    for (long i = 0; i < n; ++i) {
        const int k = (int)(i & (TABLE - 1));
        WRForces f, g, h;
        wong_reece_forces(w->wm, w->sinkage[k], w->slip[k], &f);
        wong_reece_forces(w->wm, w->sinkage[k], w->slip[k] + 1e-3, &g);
        wong_reece_forces(w->wm, w->sinkage[k] * (1.0 + 1e-3), w->slip[k], &h);
        acc += f.Fz + f.Fx + f.T + g.T + h.Fz;
    }
    sink = acc;
}

static void run_wong_reece(const Workload *w, long n)
{
    double acc = 0.0;
    for (long i = 0; i < n; ++i) {
        const int k = (int)(i & (TABLE - 1));
        WRForces f;
        wong_reece_forces(w->wm, w->sinkage[k], w->slip[k], &f);
        acc += f.Fz + f.Fx + f.T;
    }
    sink = acc;
}

typedef void (*Runner)(const Workload *, long);

typedef struct {
    Runner run;
    const Workload *w;
    long n;                       /* calls per batch */
    double ns[MAX_REPEATS];       /* wall ns per call, per round */
    double median_ns, min_ns;
} Case;

/* Calls per batch so that a batch takes >= min_time. */
static long calibrate(Runner run, const Workload *w, double min_time)
{
    long n = 16;
    for (;;) {
        const double t0 = now();
        run(w, n);
        const double dt = now() - t0;
        if (dt >= min_time || n > (1L << 40)) break;
        n = dt > 0 ? (long)(n * fmin(100.0, 1.2 * min_time / dt)) + 1 : n * 100;
    }
    return n;
}

/* Times every case once per round, interleaved, for `repeats` rounds. */
static void time_cases(Case *c, int nc, int repeats, double min_time)
{
    for (int i = 0; i < nc; ++i) c[i].n = calibrate(c[i].run, c[i].w, min_time);
    for (int r = 0; r < repeats; ++r)
        for (int i = 0; i < nc; ++i) {
            const double t0 = now(), c0 = cpu_now();
            c[i].run(c[i].w, c[i].n);
            const double wall = now() - t0;
            total_wall += wall;
            total_cpu += cpu_now() - c0;
            c[i].ns[r] = wall / (double)c[i].n * 1e9;
        }
    for (int i = 0; i < nc; ++i) {
        double v[MAX_REPEATS];
        memcpy(v, c[i].ns, sizeof(double) * (size_t)repeats);
        c[i].min_ns = v[0];
        for (int r = 1; r < repeats; ++r) c[i].min_ns = fmin(c[i].min_ns, v[r]);
        c[i].median_ns = median_in_place(v, repeats);
    }
}

/* Median over rounds of a[r] / b[r]. */
static double median_ratio(const Case *a, const Case *b, int repeats)
{
    double v[MAX_REPEATS];
    for (int r = 0; r < repeats; ++r) v[r] = a->ns[r] / b->ns[r];
    return median_in_place(v, repeats);
}

static void fill_table(Workload *w, double sinkage)
{
    for (int k = 0; k < TABLE; ++k) {
        /* deterministic scatter: +-1 % sinkage, slip 0..0.3 */
        const double a = (double)((k * 37) % TABLE) / (TABLE - 1), b = (double)((k * 101) % TABLE) / (TABLE - 1);
        w->sinkage[k] = sinkage * (0.99 + 0.02 * a);
        w->slip[k] = 0.3 * b;
    }
}

/* ------------------------------------------------------------ main */

int main(int argc, char **argv)
{
    int repeats = 7;
    double min_time = 0.05;
    const char *json = NULL;
    for (int i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--repeats") && i + 1 < argc) repeats = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--min-time") && i + 1 < argc) min_time = atof(argv[++i]);
        else if (!strcmp(argv[i], "--json") && i + 1 < argc) json = argv[++i];
        else {
            fprintf(stderr, "usage: %s [--repeats N (>= 1, default 7)] [--min-time S (default 0.05)] [--json FILE]\n",
                    argv[0]);
            return 2;
        }
    }
    if (repeats < 1 || repeats > MAX_REPEATS || !(min_time > 0)) {
        fprintf(stderr, "bench_contact: --repeats must be 1..%d and --min-time > 0\n", MAX_REPEATS);
        return 2;
    }

    ContactModel closed, quad;
    if (volumetric_model(&closed, CONTACT_CLOSED_FORM) != 0 || volumetric_model(&quad, CONTACT_QUADRATURE) != 0)
        return 1;
    const double R = closed.radius, b = closed.width, gamma = closed.gamma;

    /* 1. Sinkage of every model at 779 N. */
    const double s_closed = volumetric_sinkage(&closed, LOAD);
    const double s_quad = volumetric_sinkage(&quad, LOAD);
    typedef struct {
        const char *name;
        int toyoura;
        double lambda, modulus, sinkage;
        WongReeceModel wm;
    } WrCase;
    static const char *const wr_names[5] = {
        "Wong-Reece, dry sand, Bekker moduli scaled to match", "Wong-Reece, dry sand (published)",
        "Wong-Reece, dry sand (published), lambda 0", "Wong-Reece, Toyoura sand (published)",
        "Wong-Reece, Toyoura sand (published), lambda 0"};
    WrCase wr[5];
    memset(wr, 0, sizeof wr);
    for (int i = 0; i < 5; ++i) {
        wr[i].name = wr_names[i];
        wr[i].toyoura = i >= 3;
        wr[i].modulus = 1.0;
    }
    wr[0].lambda = wr[1].lambda = wr[3].lambda = gamma;
    wr[0].modulus = wr_matching_modulus(gamma, s_closed, R, b);
    for (int i = 0; i < 5; ++i) {
        if (wr_model(&wr[i].wm, wr[i].toyoura, wr[i].lambda, wr[i].modulus, R, b) != 0) return 1;
        wr[i].sinkage = wong_reece_sinkage_for_load(&wr[i].wm, LOAD, 0.0);
    }

    printf("contact evaluations at %.0f N (wheel R = %.4f m, b = %.3f m; rolling: rear half rebounded, "
           "gamma = lambda = %.4f; zero slip)\n", LOAD, R, b, gamma);
    printf("  sinkage for the load:\n");
    printf("    %-56s %7.2f mm\n", "volumetric, closed form (Eqn 3)", s_closed * 1e3);
    printf("    %-56s %7.2f mm  (%+.1f %% vs closed form)\n", "volumetric, quadrature", s_quad * 1e3,
           100 * (s_quad / s_closed - 1));
    for (int i = 0; i < 5; ++i) {
        char label[128];
        if (i == 0) snprintf(label, sizeof label, "%s (x %.3f)", wr[i].name, wr[i].modulus);
        else snprintf(label, sizeof label, "%s", wr[i].name);
        const double rel = wr[i].sinkage / s_closed - 1;
        printf("    %-56s %7.2f mm  (%+.1f %% vs closed form: %s)\n", label, wr[i].sinkage * 1e3, 100 * rel,
               fabs(rel) <= 0.05 ? "match within 5 %" : "NO match within 5 %");
    }

    /* 2. Timing. */
    static Workload w_closed, w_quad, w_wr[5];
    w_closed.cm = &closed;
    w_quad.cm = &quad;
    fill_table(&w_closed, s_closed);
    fill_table(&w_quad, s_quad);
    for (int i = 0; i < 5; ++i) {
        w_wr[i].wm = &wr[i].wm;
        fill_table(&w_wr[i], wr[i].sinkage);
    }
    /* cases: 0 closed form, 1 quadrature, 2..6 Wong-Reece sets, 7 matched WR as the FMU uses it,
     * 8 the closed form's forces alone */
    static Case cases[9];
    memset(cases, 0, sizeof cases);
    cases[0].run = run_volumetric;
    cases[0].w = &w_closed;
    cases[1].run = run_volumetric;
    cases[1].w = &w_quad;
    for (int i = 0; i < 5; ++i) {
        cases[2 + i].run = run_wong_reece;
        cases[2 + i].w = &w_wr[i];
    }
    cases[7].run = run_wong_reece_fmu;
    cases[7].w = &w_wr[0];
    cases[8].run = run_volumetric_forces;
    cases[8].w = &w_closed;
    time_cases(cases, 9, repeats, min_time);
    const Case *t_closed = &cases[0], *t_quad = &cases[1], *t_wr = &cases[2], *t_fmu = &cases[7];
    const Case *t_forces = &cases[8];

    printf("  ns per evaluation (wall clock, median of %d interleaved rounds of >= %.2f s batches; minimum; "
           "CPU share %.0f %%):\n", repeats, min_time, 100 * total_cpu / total_wall);
    printf("    %-56s %9.1f ns  (min %.1f)\n", "volumetric, closed form: contact_patch + contact_shear",
           t_closed->median_ns, t_closed->min_ns);
    printf("    %-56s %9.1f ns  (min %.1f)\n", "volumetric, closed form, forces only (no shear Jacobian)",
           t_forces->median_ns, t_forces->min_ns);
    printf("    %-56s %9.1f ns  (min %.1f)  %.1fx the closed form\n", "volumetric, quadrature (64-point Gauss)",
           t_quad->median_ns, t_quad->min_ns, median_ratio(t_quad, t_closed, repeats));
    for (int i = 0; i < 5; ++i)
        printf("    %-56s %9.1f ns  (min %.1f)  %.1fx the closed form\n", wr[i].name, t_wr[i].median_ns,
               t_wr[i].min_ns, median_ratio(&t_wr[i], t_closed, repeats));
    printf("    %-56s %9.1f ns  (min %.1f)  %.1fx the closed form\n",
           "matched Wong-Reece as the FMU uses it (3 calls)", t_fmu->median_ns, t_fmu->min_ns,
           median_ratio(t_fmu, t_closed, repeats));
    const double speedup = median_ratio(&t_wr[0], t_closed, repeats);
    const double mismatch = wr[0].sinkage / s_closed - 1;
    printf("  closed form vs Wong-Reece (100 points) at matching sinkage (%+.2f %%): %.1fx faster "
           "(target >= 30x: %s)\n", 100 * mismatch, speedup, speedup >= 30 && fabs(mismatch) <= 0.05 ? "met" : "MISSED");
    /* Like for like: forces without derivatives on both sides, and the derivatives an implicit
     * step needs on both sides (the closed form's analytic Jacobian, Wong-Reece's differences). */
    const double speedup_forces = median_ratio(&t_wr[0], t_forces, repeats);
    const double speedup_fmu = median_ratio(t_fmu, t_closed, repeats);
    printf("  like for like at matching sinkage: forces only %.1fx faster (target >= 30x: %s); forces and the "
           "derivatives the FMU's step uses %.1fx faster\n", speedup_forces,
           speedup_forces >= 30 && fabs(mismatch) <= 0.05 ? "met" : "MISSED", speedup_fmu);

    if (json) {
        FILE *f = fopen(json, "w");
        if (!f) {
            perror(json);
            return 1;
        }
        fprintf(f, "{\n  \"load_N\": %.17g, \"repeats\": %d, \"min_time_s\": %.17g,\n", LOAD, repeats, min_time);
        fprintf(f, "  \"gamma\": %.17g, \"cpu_share\": %.17g, \"peak_rss_kb\": %ld,\n", gamma,
                total_cpu / total_wall, peak_rss_kb());
        fprintf(f, "  \"models\": [\n");
        fprintf(f, "    {\"name\": \"volumetric, closed form\", \"key\": \"closed_form\", \"sinkage_m\": %.17g, "
                   "\"ns_median\": %.17g, \"ns_min\": %.17g},\n", s_closed, t_closed->median_ns, t_closed->min_ns);
        fprintf(f, "    {\"name\": \"volumetric, closed form, forces only\", \"key\": \"closed_form_forces\", "
                   "\"sinkage_m\": %.17g, \"ns_median\": %.17g, \"ns_min\": %.17g},\n", s_closed, t_forces->median_ns,
                t_forces->min_ns);
        fprintf(f, "    {\"name\": \"volumetric, quadrature\", \"key\": \"quadrature\", \"sinkage_m\": %.17g, "
                   "\"ns_median\": %.17g, \"ns_min\": %.17g}", s_quad, t_quad->median_ns, t_quad->min_ns);
        static const char *const keys[5] = {"wr_matched", "wr_dry", "wr_dry_lambda0", "wr_toyoura",
                                            "wr_toyoura_lambda0"};
        for (int i = 0; i < 5; ++i)
            fprintf(f, ",\n    {\"name\": \"%s\", \"key\": \"%s\", \"lambda\": %.17g, \"modulus_factor\": %.17g, "
                       "\"sinkage_m\": %.17g, \"ns_median\": %.17g, \"ns_min\": %.17g}",
                    wr[i].name, keys[i], wr[i].lambda, wr[i].modulus, wr[i].sinkage, t_wr[i].median_ns,
                    t_wr[i].min_ns);
        fprintf(f, ",\n    {\"name\": \"matched Wong-Reece as the FMU uses it (3 calls)\", \"key\": \"wr_matched_fmu\", "
                   "\"sinkage_m\": %.17g, \"ns_median\": %.17g, \"ns_min\": %.17g}",
                wr[0].sinkage, t_fmu->median_ns, t_fmu->min_ns);
        fprintf(f, "\n  ],\n  \"speedup_matched\": %.17g, \"speedup_matched_forces_only\": %.17g, "
                   "\"speedup_matched_as_fmu_uses\": %.17g, \"sinkage_mismatch_matched\": %.17g\n}\n", speedup,
                speedup_forces, speedup_fmu, mismatch);
        fclose(f);
    }
    return 0;
}
