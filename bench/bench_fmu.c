/*
 * Benchmark: real-time factor (simulated time / wall time) of the
 * JunoRover model called from C, two ways:
 *   direct - model_set_defaults, model_initialize, model_do_step (the
 *            juno_model library, no FMI layer);
 *   fmi    - the staged FMU's shared library (build/fmu/binaries/...) opened
 *            with dlopen as an importer does: fmi2Instantiate, parameters,
 *            initialisation, then fmi2DoStep and fmi2GetReal of every Real
 *            output after each step (what fmpy's loop does), fmi2Terminate,
 *            fmi2FreeInstance;
 * on two runs at the default parameters (drive.mode 2, solver.step 1 ms,
 * communication step 10 ms, the default experiment's):
 *   drawbar - 30 s on flat ground, default inputs (400 N drawbar, 45 % throttle);
 *   terrain - 60 s on a synthetic mound grid (--terrain FILE, else one this
 *            program writes: a 0.5 m Gaussian mound at (4, 0.35) m with 4 mm
 *            undulations, 2 cm cells over x -1..9 m, y -2.3..2.3 m, like
 *            juno.synthesize.truth_grid), from (0.8, 0), 45 % throttle, no
 *            drawbar; the rover may leave the grid (heights are clamped).
 * Each run is timed whole (instantiation, terrain reading, static
 * equilibrium, every step) and its stepping alone; the figure is the median
 * over --repeats runs, next to the fastest run's (the least disturbed by
 * other jobs on a shared machine).  --solver-step, --solver-tolerance and
 * --contact-model set those parameters, otherwise the FMU's defaults (solver.tolerance > 0: the
 * automatic step, whose internal steps per run are counted by the model in an extra direct run;
 * 0: fixed steps of solver.step).
 * Printed, never asserted.  Not a test.
 *
 * --trace PREFIX writes, for the first direct run of each scenario, the
 * time and every Real output after each communication step to
 * PREFIX_drawbar.txt and PREFIX_terrain.txt (one line per step, %.17g):
 * for comparing trajectories between builds or solver steps.  With
 * --compare REF it then compares each trace with REF_<scenario>.txt (an
 * earlier --trace) and prints, per output, the largest difference relative
 * to that output's scale (the larger of its largest magnitude in REF and a
 * floor: 1 m, 0.1 rad, 0.1 m/s, 0.1 rad/s, 10 N m, 1 mm, 0.01 slip, 10 N,
 * so that outputs that are zero up to rounding, such as y on flat ground,
 * are not compared with their own noise); it fails above --tolerance
 * (default 1e-9).
 *
 * usage: bench_fmu [--fmu-dir DIR] [--terrain FILE] [--repeats N]
 *                  [--solver-step S] [--solver-tolerance T] [--contact-model 0|1]
 *                  [--only direct|fmi] [--json FILE]
 *                  [--trace PREFIX [--compare REF [--tolerance T]]]
 *                  [--comm-step S] [--profile]
 *
 * --profile prints instead where one internal step's CPU time goes (the
 * parts of an evaluation, the solve and update; profile_scenario below).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "fmu_loader.h"
#include "model.h"
#include "rover_internal.h"
#include "bench_util.h"

#define MAX_REPEATS 100
#define MAX_OUT 128

/* Value references from modelDescription/variables.h (the fmi path looks them up by name). */
enum { VR_DRAWBAR = 200, VR_THROTTLE_L = 205, VR_THROTTLE_R = 206 };

/* Smallest of v[0..n): on a shared machine, the run least disturbed. */
static double fastest(const double *v, int n)
{
    double m = v[0];
    for (int i = 1; i < n; ++i)
        if (v[i] < m) m = v[i];
    return m;
}

static double median(const double *v, int n)
{
    double s[MAX_REPEATS];
    memcpy(s, v, (size_t)n * sizeof *v);
    return median_in_place(s, n);
}

typedef struct {
    const char *name;
    double duration;        /* s */
    const char *terrain;    /* NULL: flat */
    double init_x, drawbar, throttle;
} Scenario;

typedef struct {
    double total, stepping;           /* wall s */
    double cpu;                       /* CPU s of the whole run */
    double stepping_cpu;              /* CPU s of the stepping */
    double x, y, z;                   /* final position */
    double steps, rejected;           /* internal steps taken and rejected (direct runs) */
    int ok;
    char error[1024];
} RunResult;

static double solver_step = 0.0;      /* 0: the FMU's default */
static double solver_tolerance = -1.0; /* < 0: the FMU's default; 0: fixed steps */
static int contact_model = -1;        /* < 0: the FMU's default */
static double comm_step = 0.01;       /* s, the default experiment's */
static const char *trace_prefix = NULL;
static const char *compare_prefix = NULL;
static double tolerance = 1e-9;

/* Trace columns: time, then Outputs in order (model.h), with their scale floors. */
#define TRACE_COLS (1 + (int)(sizeof(Outputs) / sizeof(double)))
static const char *const trace_names[] = {
    "time", "x", "y", "z", "roll", "pitch", "yaw", "vx", "omegaLeft", "omegaRight", "torqueLeftApplied",
    "torqueRightApplied", "rocker", "spinAngleLeft", "spinAngleRight",
    "FL.sinkage", "FL.slip", "FL.Fn", "FL.Ft", "FL.Fx", "FL.Fy", "FL.Fz",
    "RL.sinkage", "RL.slip", "RL.Fn", "RL.Ft", "RL.Fx", "RL.Fy", "RL.Fz",
    "FR.sinkage", "FR.slip", "FR.Fn", "FR.Ft", "FR.Fx", "FR.Fy", "FR.Fz",
    "RR.sinkage", "RR.slip", "RR.Fn", "RR.Ft", "RR.Fx", "RR.Fy", "RR.Fz"};
#define HEAD_COLS 15             /* time and the outputs before the wheels' */
static const double head_floor[HEAD_COLS] = {1, 1, 1, 1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 10, 10, 0.1, 1, 1};
static const double wheel_floor[7] = {1e-3, 0.01, 10, 10, 10, 10, 10};

static double trace_floor(int col)
{
    return col < HEAD_COLS ? head_floor[col] : wheel_floor[(col - HEAD_COLS) % 7];
}

/* Compares trace files a (reference) and b; prints the worst outputs.
 * Returns 1 if within the tolerance, 0 if not, -1 if unreadable. */
static int compare_traces(const char *ref, const char *got, const char *label)
{
    _Static_assert(sizeof trace_names / sizeof *trace_names == TRACE_COLS, "trace columns");
    FILE *fa = fopen(ref, "r"), *fb = fopen(got, "r");
    if (!fa || !fb) {
        if (fa) fclose(fa);
        if (fb) fclose(fb);
        fprintf(stderr, "bench_fmu: cannot read %s or %s\n", ref, got);
        return -1;
    }
    double scale[TRACE_COLS], diff[TRACE_COLS];
    for (int c = 0; c < TRACE_COLS; ++c) scale[c] = trace_floor(c), diff[c] = 0;
    long rows = 0;
    int ok = 1;
    for (;;) {
        double a, b;
        int ra = 0, rb = 0;
        for (int c = 0; c < TRACE_COLS; ++c) {
            ra = fscanf(fa, "%lf", &a);
            rb = fscanf(fb, "%lf", &b);
            if (ra != 1 || rb != 1) break;
            if (fabs(a) > scale[c]) scale[c] = fabs(a);
            const double d = fabs(a - b);
            if (!(d <= diff[c])) diff[c] = d;                 /* NaN counts as a difference */
        }
        if (ra != 1 || rb != 1) {
            if (ra != rb) ok = -1;                             /* one file ended early */
            break;
        }
        rows++;
    }
    fclose(fa);
    fclose(fb);
    if (ok < 0 || rows == 0) {
        printf("  %-8s compare FAILED: the traces differ in length (%ld rows read)\n", label, rows);
        return 0;
    }
    int worst = 0;
    for (int c = 0; c < TRACE_COLS; ++c)
        if (!(diff[c] / scale[c] <= diff[worst] / scale[worst])) worst = c;
    const double rel = diff[worst] / scale[worst];
    ok = rel <= tolerance;
    printf("  %-8s compare %s: %ld rows, largest difference %.3g of scale (%s: %.3g against %.3g), "
           "tolerance %.3g\n", label, ok ? "ok" : "FAILED", rows, rel, trace_names[worst], diff[worst], scale[worst],
           tolerance);
    return ok;
}

/* One trace line: the time and every field of Outputs (all doubles). */
static void trace_line(FILE *f, const Model *m)
{
    const double *o = (const double *)&m->out;
    const size_t n = sizeof m->out / sizeof(double);
    fprintf(f, "%.17g", m->s.time);
    for (size_t i = 0; i < n; ++i) fprintf(f, " %.17g", o[i]);
    fputc('\n', f);
}

/* ------------------------------------------------------------ direct */

/* A model set up for scenario sc, not yet initialised (NULL: out of memory): the defaults, the
 * scenario's start, load and throttle, and the solver settings step (s, > 0 to set it) and
 * tolerance (>= 0 to set it). */
static Model *scenario_model(const Scenario *sc, double step, double tolerance)
{
    Model *m = (Model *)calloc(1, sizeof *m);
    if (!m) return NULL;
    model_set_defaults(m);
    terrain_init_flat(&m->terrain);
    if (step > 0) m->p.solver_step = step;
    if (tolerance >= 0) m->p.solver_tolerance = tolerance;
    if (contact_model >= 0) m->p.contact_model = contact_model;
    m->p.init_x = sc->init_x;
    m->in.drawbarForce = sc->drawbar;
    m->in.throttleLeft = m->in.throttleRight = sc->throttle;
    if (sc->terrain) {
        m->terrain_file = (char *)malloc(strlen(sc->terrain) + 1);
        if (m->terrain_file) strcpy(m->terrain_file, sc->terrain);
    }
    return m;
}

static RunResult run_direct(const Scenario *sc, FILE *trace)
{
    RunResult r;
    memset(&r, 0, sizeof r);
    const double t0 = now(), c0 = cpu_now();
    Model *m = scenario_model(sc, solver_step, solver_tolerance);
    if (!m) return snprintf(r.error, sizeof r.error, "out of memory"), r;
    char err[512];
    if (model_initialize(m, err, sizeof err) != 0) {
        snprintf(r.error, sizeof r.error, "model_initialize: %s", err);
    } else {
        const int n = (int)lround(sc->duration / comm_step);
        const double t1 = now(), c1 = cpu_now();
        int k = 0;
        if (trace) {                    /* untimed: writing the trace costs more than the steps */
            trace_line(trace, m);
            for (; k < n; ++k) {
                if (model_do_step(m, comm_step, err, sizeof err) != 0) break;
                trace_line(trace, m);
            }
        } else {
            for (; k < n; ++k)
                if (model_do_step(m, comm_step, err, sizeof err) != 0) break;
        }
        r.stepping = now() - t1;
        r.stepping_cpu = cpu_now() - c1;
        if (k < n) snprintf(r.error, sizeof r.error, "model_do_step at t = %.2f s: %s", k * comm_step, err);
        else r.ok = 1;
        r.x = m->out.x;
        r.y = m->out.y;
        r.z = m->out.z;
        r.steps = (double)m->steps_taken;
        r.rejected = (double)m->steps_rejected;
    }
    model_free(m);
    free(m);
    r.total = now() - t0;
    r.cpu = cpu_now() - c0;
    return r;
}

/* ------------------------------------------------------------ fmi */

static Fmu F;
static int fmu_loaded = 0;
static unsigned out_vrs[MAX_OUT];
static size_t n_out;
static unsigned vr_x, vr_y, vr_z, vr_terrain, vr_init_x, vr_solver_step, vr_solver_tolerance, vr_contact_model;

typedef struct {
    char last[512];
} Env;

static void fmi_logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                       fmi2String message, ...)
{
    (void)instance;
    (void)category;
    Env *e = (Env *)env;
    if (!e || status < fmi2Error) return;
    va_list ap;
    va_start(ap, message);
    vsnprintf(e->last, sizeof e->last, message, ap);
    va_end(ap);
}

static RunResult run_fmi(const Scenario *sc)
{
    RunResult r;
    memset(&r, 0, sizeof r);
    const Fmi *fmi = &F.fmi;
    Env env;
    memset(&env, 0, sizeof env);
    const fmi2CallbackFunctions cb = {fmi_logger, calloc, free, NULL, &env};
    double out[MAX_OUT];
    const double t0 = now(), c0 = cpu_now();
    fmi2Component c = fmi->Instantiate("bench", fmi2CoSimulation, F.guid, NULL, &cb, fmi2False, fmi2False);
    if (!c) return snprintf(r.error, sizeof r.error, "fmi2Instantiate failed: %s", env.last), r;
    const unsigned in_vrs[3] = {VR_DRAWBAR, VR_THROTTLE_L, VR_THROTTLE_R};
    const fmi2Real in[3] = {sc->drawbar, sc->throttle, sc->throttle};
    int ok = fmi->SetupExperiment(c, fmi2False, 0, 0.0, fmi2True, sc->duration) == fmi2OK &&
             fmi->EnterInitializationMode(c) == fmi2OK && fmi->SetReal(c, &vr_init_x, 1, &sc->init_x) == fmi2OK &&
             fmi->SetReal(c, in_vrs, 3, in) == fmi2OK;
    if (ok && solver_step > 0) ok = fmi->SetReal(c, &vr_solver_step, 1, &solver_step) == fmi2OK;
    if (ok && solver_tolerance >= 0) ok = fmi->SetReal(c, &vr_solver_tolerance, 1, &solver_tolerance) == fmi2OK;
    if (ok && contact_model >= 0) ok = fmi->SetInteger(c, &vr_contact_model, 1, &contact_model) == fmi2OK;
    if (ok && sc->terrain) {
        const fmi2String file = sc->terrain;
        ok = fmi->SetString(c, &vr_terrain, 1, &file) == fmi2OK;
    }
    ok = ok && fmi->ExitInitializationMode(c) == fmi2OK;
    if (!ok) {
        snprintf(r.error, sizeof r.error, "set-up: %s", env.last);
    } else {
        const int n = (int)lround(sc->duration / comm_step);
        const double t1 = now(), c1 = cpu_now();
        int k = 0;
        for (; k < n; ++k) {
            if (fmi->DoStep(c, k * comm_step, comm_step, fmi2True) != fmi2OK) break;
            if (fmi->GetReal(c, out_vrs, n_out, out) != fmi2OK) break;
        }
        r.stepping = now() - t1;
        r.stepping_cpu = cpu_now() - c1;
        if (k < n) snprintf(r.error, sizeof r.error, "fmi2DoStep at t = %.2f s: %s", k * comm_step, env.last);
        else r.ok = 1;
        const unsigned pos_vrs[3] = {vr_x, vr_y, vr_z};
        double pos[3] = {NAN, NAN, NAN};
        fmi->GetReal(c, pos_vrs, 3, pos);
        r.x = pos[0];
        r.y = pos[1];
        r.z = pos[2];
        fmi->Terminate(c);
    }
    fmi->FreeInstance(c);
    r.total = now() - t0;
    r.cpu = cpu_now() - c0;
    return r;
}

/* ------------------------------------------------------------ terrain */

/* The synthetic mound grid (see the header); returns 0 or -1. */
static int write_mound_grid(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    const double cell = 0.02, x0 = -1.0, y0 = -2.3;
    const int ncols = 501, nrows = 231;
    static const double k[4][3] = {{1.3, 2.1, 0.4}, {2.7, 1.2, 2.2}, {1.9, 2.8, 4.1}, {1.1, 1.6, 5.3}};
    fprintf(f, "ncols %d\nnrows %d\nxllcenter %.17g\nyllcenter %.17g\ncellsize %.17g\nNODATA_value -9999\n", ncols,
            nrows, x0, y0, cell);
    for (int row = nrows - 1; row >= 0; --row) {          /* north to south */
        const double y = y0 + row * cell;
        for (int col = 0; col < ncols; ++col) {
            const double x = x0 + col * cell;
            double z = 0.5 * exp(-((x - 4.0) * (x - 4.0) / (2 * 0.81) + (y - 0.35) * (y - 0.35) / (2 * 0.49)));
            for (int i = 0; i < 4; ++i) z += 0.004 * sin(k[i][0] * x + k[i][1] * y + k[i][2]);
            fprintf(f, col ? " %.6f" : "%.6f", z);
        }
        fputc('\n', f);
    }
    return fclose(f) == 0 ? 0 : -1;
}

/* ------------------------------------------------------------ profile */

/* --profile: CPU time of the parts of one evaluation of the dynamics, at the
 * state the scenario reaches after 5 s at the fixed 1 ms step, each part
 * repeated on that same state (the state does not move, so the figures are
 * of warm caches): the whole input-independent evaluation with the
 * matrices an implicit step needs (kinematics, the bodies' M and Q, four
 * contacts with their damping and stiffness), the same without matrices,
 * and the four contacts alone, with and without matrices.  Kinematics and
 * the bodies' assembly are the difference; the internal step's remainder
 * (the input terms, the 9 x 9 solve, the state update) is the fixed 1 ms
 * step's CPU time per internal step over the next 2 s minus the
 * evaluation with matrices.  Printed, never asserted. */
static double cpu_per_call(Model *m, Eval *ev, int what, int n)
{
    const double c0 = cpu_now();
    for (int i = 0; i < n; ++i) {
        if (what == 0) rover_evaluate_passive(m, ev, 1);
        else if (what == 1) rover_evaluate_passive(m, ev, 0);
        else
            rover_wheel_contacts(m, ev, what == 2);
    }
    return (cpu_now() - c0) / n;
}

static int profile_scenario(const Scenario *sc)
{
    Model *m = scenario_model(sc, 1e-3, 0.0);
    Eval *ev = (Eval *)calloc(1, sizeof *ev);
    if (!m || !ev) {
        if (m) model_free(m), free(m);
        return free(ev), fprintf(stderr, "bench_fmu: out of memory\n"), -1;
    }
    char err[512];
    int rc = model_initialize(m, err, sizeof err);
    for (int k = 0; rc == 0 && k < 500; ++k) rc = model_do_step(m, 0.01, err, sizeof err);
    if (rc == 0) {
        enum { N = 20000 };
        rover_evaluate_passive(m, ev, 1);
        const double full = cpu_per_call(m, ev, 0, N), forces = cpu_per_call(m, ev, 1, N);
        const double contacts = cpu_per_call(m, ev, 2, N), contacts_forces = cpu_per_call(m, ev, 3, N);
        const double c0 = cpu_now();
        for (int k = 0; rc == 0 && k < 200; ++k) rc = model_do_step(m, 0.01, err, sizeof err);
        const double step = (cpu_now() - c0) / 2000;
        printf("  %-8s evaluation with matrices %.2f us (kinematics and bodies %.2f, four contacts %.2f); "
               "without matrices %.2f us (four contacts %.2f); fixed 1 ms internal step %.2f us, of which "
               "the input terms, solve and update %.2f us\n",
               sc->name, full * 1e6, (full - contacts) * 1e6, contacts * 1e6, forces * 1e6, contacts_forces * 1e6,
               step * 1e6, (step - full) * 1e6);
    }
    if (rc != 0) printf("  %-8s profile FAILED: %s\n", sc->name, err);
    model_free(m);
    free(m);
    free(ev);
    return rc;
}

/* ------------------------------------------------------------ main */

typedef struct {
    double total[MAX_REPEATS], stepping[MAX_REPEATS], stepping_cpu[MAX_REPEATS], cpu, wall;
    RunResult last;
    int n;
} Series;

int main(int argc, char **argv)
{
    const char *fmu_dir = NULL, *terrain = NULL, *json = NULL, *only = NULL;
    int repeats = 5, profile = 0;
    for (int i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--fmu-dir") && i + 1 < argc) fmu_dir = argv[++i];
        else if (!strcmp(argv[i], "--terrain") && i + 1 < argc) terrain = argv[++i];
        else if (!strcmp(argv[i], "--repeats") && i + 1 < argc) repeats = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--solver-step") && i + 1 < argc) solver_step = atof(argv[++i]);
        else if (!strcmp(argv[i], "--solver-tolerance") && i + 1 < argc) solver_tolerance = atof(argv[++i]);
        else if (!strcmp(argv[i], "--contact-model") && i + 1 < argc) contact_model = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--only") && i + 1 < argc) only = argv[++i];
        else if (!strcmp(argv[i], "--json") && i + 1 < argc) json = argv[++i];
        else if (!strcmp(argv[i], "--trace") && i + 1 < argc) trace_prefix = argv[++i];
        else if (!strcmp(argv[i], "--comm-step") && i + 1 < argc) comm_step = atof(argv[++i]);
        else if (!strcmp(argv[i], "--compare") && i + 1 < argc) compare_prefix = argv[++i];
        else if (!strcmp(argv[i], "--tolerance") && i + 1 < argc) tolerance = atof(argv[++i]);
        else if (!strcmp(argv[i], "--profile")) profile = 1;
        else {
            fprintf(stderr,
                    "usage: %s [--fmu-dir DIR (default: build/fmu beside this program)] [--terrain FILE.asc] "
                    "[--repeats N (default 5; 0 with --trace: the traces only)] [--solver-step S] [--solver-tolerance T] "
                    "[--contact-model 0|1] [--only direct|fmi] [--json FILE] "
                    "[--trace PREFIX [--compare REF [--tolerance T (default 1e-9)]]] [--comm-step S (default 0.01)] "
                    "[--profile]\n",
                    argv[0]);
            return 2;
        }
    }
    if (repeats < (trace_prefix ? 0 : 1) || repeats > MAX_REPEATS) {
        fprintf(stderr, "bench_fmu: --repeats must be 1..%d (0: with --trace)\n", MAX_REPEATS);
        return 2;
    }
    if (compare_prefix && !trace_prefix) {
        fprintf(stderr, "bench_fmu: --compare needs --trace\n");
        return 2;
    }
    if (!(comm_step > 0) || comm_step > 1) {
        fprintf(stderr, "bench_fmu: --comm-step must be in (0, 1] s\n");
        return 2;
    }
    if (only && strcmp(only, "direct") && strcmp(only, "fmi")) {
        fprintf(stderr, "bench_fmu: --only takes direct or fmi\n");
        return 2;
    }
    const int do_direct = !only || !strcmp(only, "direct"), do_fmi = !only || !strcmp(only, "fmi");

    /* The staged FMU: --fmu-dir, else "fmu" beside this executable (build/fmu). */
    char *dir = NULL;
    if (fmu_dir) {
        dir = (char *)malloc(strlen(fmu_dir) + 1);
        if (dir) strcpy(dir, fmu_dir);
    } else {
        char self[4096];
        ssize_t len = readlink("/proc/self/exe", self, sizeof self - 1);
        if (len <= 0) return fprintf(stderr, "bench_fmu: give --fmu-dir\n"), 2;
        self[len] = '\0';
        char *slash = strrchr(self, '/');
        if (slash) *slash = '\0';
        dir = (char *)malloc(strlen(self) + 5);
        if (dir) sprintf(dir, "%s/fmu", self);
    }
    if (!dir) return fprintf(stderr, "bench_fmu: out of memory\n"), 1;
    if (do_fmi) {
        if (fmu_load(&F, dir) != 0) return 1;
        fmu_loaded = 1;
        for (int i = 0; i < F.nvars && n_out < MAX_OUT; ++i)
            if (F.vars[i].causality == 'o' && F.vars[i].type == 'r') out_vrs[n_out++] = F.vars[i].vr;
        vr_x = fmu_var(&F, "x")->vr;
        vr_y = fmu_var(&F, "y")->vr;
        vr_z = fmu_var(&F, "z")->vr;
        vr_terrain = fmu_var(&F, "terrain.file")->vr;
        vr_init_x = fmu_var(&F, "init.x")->vr;
        vr_solver_step = fmu_var(&F, "solver.step")->vr;
        vr_solver_tolerance = fmu_var(&F, "solver.tolerance")->vr;
        vr_contact_model = fmu_var(&F, "contact.model")->vr;
    }

    char tmp_grid[] = "/tmp/bench_fmu_mound_XXXXXX";
    int own_grid = 0;
    if (!terrain) {
        const int fd = mkstemp(tmp_grid);
        if (fd < 0 || close(fd) != 0 || write_mound_grid(tmp_grid) != 0) {
            fprintf(stderr, "bench_fmu: cannot write a terrain grid to %s\n", tmp_grid);
            return 1;
        }
        terrain = tmp_grid;
        own_grid = 1;
    }

    Model probe;
    memset(&probe, 0, sizeof probe);
    model_set_defaults(&probe);
    const double h_solver = solver_step > 0 ? solver_step : probe.p.solver_step;
    const double tol = solver_tolerance >= 0 ? solver_tolerance : probe.p.solver_tolerance;
    const Scenario scenarios[2] = {
        {"drawbar", 30.0, NULL, probe.p.init_x, probe.in.drawbarForce, probe.in.throttleLeft},
        {"terrain", 60.0, terrain, 0.8, 0.0, 0.45},
    };
    if (profile) {
        printf("CPU time of one internal step's parts (state after 5 s at a fixed 1 ms step)\n");
        int bad = 0;
        for (int s = 0; s < 2; ++s) bad += profile_scenario(&scenarios[s]) != 0;
        if (own_grid) remove(tmp_grid);
        if (fmu_loaded) fmu_unload(&F);
        free(dir);
        return bad ? 1 : 0;
    }
    const char *const paths[2] = {"direct", "fmi"};
    Series series[2][2];
    memset(series, 0, sizeof series);

    printf("real-time factor from C (solver.step %g s, solver.tolerance %g m/s, communication step %g s, median of "
           "%d runs)\n", h_solver, tol, comm_step, repeats);
    printf("  drawbar: 30 s, flat, drive.mode 2, drawbar %g N, throttle %g; terrain: 60 s on %s from x = 0.8 m, "
           "throttle 0.45\n", probe.in.drawbarForce, probe.in.throttleLeft, terrain);
    int failures = 0;
    double steps[2] = {0, 0}, rejected[2] = {0, 0};   /* per scenario, from a direct run (the model counts them) */
    for (int s = 0; s < 2; ++s) {
        if (!(tol > 0)) {                              /* fixed: ceil(comm_step / h) substeps per step */
            int per_comm = (int)ceil(comm_step / h_solver - 1e-9);
            if (per_comm < 1) per_comm = 1;
            steps[s] = lround(scenarios[s].duration / comm_step) * (double)per_comm;
        } else if (repeats > 0) {
            const RunResult probe_run = run_direct(&scenarios[s], NULL);
            steps[s] = probe_run.steps;
            rejected[s] = probe_run.rejected;
        }
    }
    for (int s = 0; s < 2; ++s) {
        for (int p = 0; p < 2; ++p) {
            if ((p == 0 && !do_direct) || (p == 1 && !do_fmi)) continue;
            Series *se = &series[s][p];
            if (p == 0 && trace_prefix) {   /* an extra, untimed run */
                char path[4096];
                snprintf(path, sizeof path, "%s_%s.txt", trace_prefix, scenarios[s].name);
                FILE *f = fopen(path, "w");
                if (!f) return perror(path), 1;
                const RunResult tr = run_direct(&scenarios[s], f);
                fclose(f);
                if (!tr.ok) printf("  %-8s trace   FAILED: %s\n", scenarios[s].name, tr.error);
                if (compare_prefix) {
                    char ref[4096];
                    snprintf(ref, sizeof ref, "%s_%s.txt", compare_prefix, scenarios[s].name);
                    if (compare_traces(ref, path, scenarios[s].name) != 1) failures++;
                }
            }
            if (repeats == 0) continue;                       /* the trace only */
            for (int r = 0; r < repeats; ++r) {
                se->last = p == 0 ? run_direct(&scenarios[s], NULL) : run_fmi(&scenarios[s]);
                if (!se->last.ok) break;
                se->total[se->n] = se->last.total;
                se->stepping[se->n] = se->last.stepping;
                se->stepping_cpu[se->n] = se->last.stepping_cpu;
                se->cpu += se->last.cpu;
                se->wall += se->last.total;
                se->n++;
            }
            const double dur = scenarios[s].duration;
            if (!se->last.ok) {
                printf("  %-8s %-7s FAILED: %s\n", scenarios[s].name, paths[p], se->last.error);
                failures++;
                continue;
            }
            const double tot = median(se->total, se->n), stp = median(se->stepping, se->n);
            const double stp_cpu = median(se->stepping_cpu, se->n);
            const double substeps = steps[s] > 0 ? steps[s] : 1;
            printf("  %-8s %-7s %8.1fx real time whole run (%.3f s), %8.1fx stepping only; %.0f internal steps "
                   "(mean %.2f ms, %.0f rejected), %.2f us per internal step (%.2f us CPU); fastest run %.1fx whole, "
                   "%.1fx stepping; CPU share %.0f %%; final x %.2f y %.2f m\n",
                   scenarios[s].name, paths[p], dur / tot, tot, dur / stp, substeps, dur / substeps * 1e3,
                   rejected[s], stp / substeps * 1e6, stp_cpu / substeps * 1e6, dur / fastest(se->total, se->n),
                   dur / fastest(se->stepping, se->n), 100 * se->cpu / se->wall, se->last.x, se->last.y);
        }
    }

    if (json) {
        FILE *f = fopen(json, "w");
        if (!f) {
            perror(json);
            return 1;
        }
        fprintf(f, "{\n  \"solver_step\": %.17g, \"solver_tolerance\": %.17g, \"comm_step\": %.17g, \"repeats\": %d, \"terrain\": \"%s\",\n  "
                   "\"peak_rss_kb\": %ld,\n  \"runs\": [", h_solver, tol, comm_step, repeats,
                own_grid ? "(generated)" : "(given)", peak_rss_kb());
        int first = 1;
        for (int s = 0; s < 2; ++s)
            for (int p = 0; p < 2; ++p) {
                const Series *se = &series[s][p];
                if ((p == 0 && !do_direct) || (p == 1 && !do_fmi)) continue;
                fprintf(f, "%s\n    {\"scenario\": \"%s\", \"path\": \"%s\", \"duration\": %.17g, \"ok\": %s",
                        first ? "" : ",", scenarios[s].name, paths[p], scenarios[s].duration,
                        se->last.ok ? "true" : "false");
                first = 0;
                if (se->last.ok)
                    fprintf(f, ", \"total_s\": %.17g, \"stepping_s\": %.17g, \"stepping_cpu_s\": %.17g, "
                               "\"total_min_s\": %.17g, \"stepping_min_s\": %.17g, "
                               "\"final_x\": %.17g, \"final_y\": %.17g, \"final_z\": %.17g, \"n\": %d, "
                               "\"cpu_share\": %.17g, \"steps\": %.17g, \"rejected\": %.17g}",
                            median(se->total, se->n), median(se->stepping, se->n),
                            median(se->stepping_cpu, se->n), fastest(se->total, se->n),
                            fastest(se->stepping, se->n), se->last.x, se->last.y, se->last.z, se->n,
                            se->cpu / se->wall, steps[s], rejected[s]);
                else {
                    fputs(", \"error\": \"", f);
                    for (const char *c = se->last.error; *c; ++c) {
                        if (*c == '"' || *c == '\\') fputc('\\', f);
                        fputc((unsigned char)*c < 0x20 ? ' ' : *c, f);
                    }
                    fputs("\"}", f);
                }
            }
        fprintf(f, "\n  ]\n}\n");
        fclose(f);
    }
    if (own_grid) remove(tmp_grid);
    if (fmu_loaded) fmu_unload(&F);
    free(dir);
    return failures ? 1 : 0;
}
