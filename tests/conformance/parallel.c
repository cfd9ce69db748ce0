/*
 * Many JunoRover instances in threads give the same results, bit for bit,
 * as the same runs one after another.
 *
 *   parallel FMU_DIR [WORK_DIR] [THREADS] [STEPS]
 *
 * Eight scenarios (drive modes 0, 1, 2, soil parameters, a terrain grid,
 * time-varying inputs, FMU state get/set and serialisation in the middle
 * of the run) are first run serially; then THREADS threads (default 8)
 * each run every scenario, starting at different ones so that the same
 * scenario runs in several threads at once, one of them with two instances
 * interleaved step by step.  Every output after every step must equal the
 * serial run's.  Prints "N passed, M failed".
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmu_loader.h"

#define NSCEN 8
#define MAX_OUT 128

static Fmu F;
static const Fmi *fmi;
static int steps = 150;
static const double H = 0.01;
static char terrain_path[4096];
static unsigned out_vrs[MAX_OUT];
static size_t n_out;
static unsigned vr_mode, vr_kh, vr_gamma, vr_yaw, vr_terrain, vr_drawbar, vr_tql, vr_tqr, vr_wl, vr_wr, vr_thl,
    vr_thr;
static double *serial[NSCEN];    /* steps * n_out outputs per scenario */

/* per-instance environment: the logger counts errors without shared state */
typedef struct {
    int errors;
    char last[512];
} Env;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
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
    e->errors++;
}

typedef struct {
    fmi2Component c;
    Env env;
    fmi2CallbackFunctions cb;
    int scen;
    int k;            /* next step */
    double *out;      /* steps * n_out */
    char error[600];
} Run;

static int run_begin(Run *r, int scen, const char *name)
{
    memset(r, 0, sizeof *r);
    r->scen = scen;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, &r->env};
    memcpy(&r->cb, &cb, sizeof cb);
    r->out = (double *)malloc((size_t)steps * n_out * sizeof(double));
    r->c = fmi->Instantiate(name, fmi2CoSimulation, F.guid, NULL, &r->cb, fmi2False, fmi2False);
    if (!r->c || !r->out) return snprintf(r->error, sizeof r->error, "instantiate failed"), -1;
    fmi2Integer mode = scen % 3;
    fmi2Real kh = 1.3e5 + 1e4 * scen, gamma = 0.05 + 0.03 * scen, yaw = 0.1 * scen;
    if (fmi->SetupExperiment(r->c, fmi2False, 0, 0.0, fmi2True, steps * H) != fmi2OK ||
        fmi->EnterInitializationMode(r->c) != fmi2OK || fmi->SetInteger(r->c, &vr_mode, 1, &mode) != fmi2OK ||
        fmi->SetReal(r->c, &vr_kh, 1, &kh) != fmi2OK || fmi->SetReal(r->c, &vr_gamma, 1, &gamma) != fmi2OK ||
        fmi->SetReal(r->c, &vr_yaw, 1, &yaw) != fmi2OK)
        return snprintf(r->error, sizeof r->error, "set-up failed: %s", r->env.last), -1;
    if (scen >= 4) {
        const fmi2String file = terrain_path;
        if (fmi->SetString(r->c, &vr_terrain, 1, &file) != fmi2OK)
            return snprintf(r->error, sizeof r->error, "terrain.file: %s", r->env.last), -1;
    }
    if (fmi->ExitInitializationMode(r->c) != fmi2OK)
        return snprintf(r->error, sizeof r->error, "initialisation failed: %s", r->env.last), -1;
    return 0;
}

/* One communication step with the scenario's inputs at t; scenarios 3 and 7
 * save the state halfway, run on, and go back to it (through bytes). */
static int run_step(Run *r)
{
    const int k = r->k;
    const double t = k * H, s = (double)r->scen;
    const unsigned vrs[7] = {vr_drawbar, vr_tql, vr_tqr, vr_wl, vr_wr, vr_thl, vr_thr};
    const fmi2Real u[7] = {200.0 + 50.0 * sin(0.7 * t + s), 60.0 + 10 * s, 55.0 + 5 * cos(t),
                           1.0 + 0.2 * sin(t + s), 1.1 - 0.1 * s * cos(t), 0.4 + 0.02 * s, 0.45 - 0.1 * sin(t)};
    if (fmi->SetReal(r->c, vrs, 7, u) != fmi2OK) return snprintf(r->error, sizeof r->error, "inputs: %s", r->env.last), -1;
    if ((r->scen == 3 || r->scen == 7) && k == steps / 2) {
        fmi2FMUstate st = NULL, back = NULL;
        size_t size = 0;
        if (fmi->GetFMUstate(r->c, &st) != fmi2OK || fmi->SerializedFMUstateSize(r->c, st, &size) != fmi2OK)
            return snprintf(r->error, sizeof r->error, "get state: %s", r->env.last), -1;
        char *bytes = (char *)malloc(size);
        int ok = bytes && fmi->SerializeFMUstate(r->c, st, bytes, size) == fmi2OK;
        for (int j = 0; ok && j < 5; ++j) ok = fmi->DoStep(r->c, t + j * H, H, fmi2False) == fmi2OK;
        ok = ok && fmi->DeSerializeFMUstate(r->c, bytes, size, &back) == fmi2OK &&
             fmi->SetFMUstate(r->c, back) == fmi2OK;
        fmi->FreeFMUstate(r->c, &st);
        fmi->FreeFMUstate(r->c, &back);
        free(bytes);
        if (!ok) return snprintf(r->error, sizeof r->error, "state round trip: %s", r->env.last), -1;
    }
    if (fmi->DoStep(r->c, t, H, fmi2True) != fmi2OK)
        return snprintf(r->error, sizeof r->error, "doStep at %g: %s", t, r->env.last), -1;
    if (fmi->GetReal(r->c, out_vrs, n_out, r->out + (size_t)k * n_out) != fmi2OK)
        return snprintf(r->error, sizeof r->error, "getReal: %s", r->env.last), -1;
    r->k++;
    return 0;
}

static void run_end(Run *r)
{
    if (r->c) {
        fmi->Terminate(r->c);
        fmi->FreeInstance(r->c);
    }
    r->c = NULL;
}

typedef struct {
    int id;
    int runs, mismatches, errors;
    char message[800];
} Worker;

static void note(Worker *w, const char *fmt, ...)
{
    if (w->message[0]) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(w->message, sizeof w->message, fmt, ap);
    va_end(ap);
}

static void compare(Worker *w, const Run *r)
{
    w->runs++;
    if (memcmp(r->out, serial[r->scen], (size_t)steps * n_out * sizeof(double)) != 0) {
        w->mismatches++;
        note(w, "thread %d: scenario %d differs from the serial run", w->id, r->scen);
    }
}

static void *worker_main(void *arg)
{
    Worker *w = (Worker *)arg;
    char name[64];
    for (int j = 0; j < NSCEN; ++j) {
        int scen = (w->id + j) % NSCEN;
        Run r;
        snprintf(name, sizeof name, "t%d-s%d", w->id, scen);
        int ok = run_begin(&r, scen, name) == 0;
        while (ok && r.k < steps) ok = run_step(&r) == 0;
        if (!ok) {
            w->errors++;
            note(w, "thread %d, scenario %d: %s", w->id, scen, r.error);
        } else {
            compare(w, &r);
        }
        run_end(&r);
        free(r.out);
    }
    /* two instances in this thread, interleaved step by step */
    Run a, b;
    int sa = w->id % NSCEN, sb = (w->id + 3) % NSCEN;
    int ok = run_begin(&a, sa, "interleaved-a") == 0 && run_begin(&b, sb, "interleaved-b") == 0;
    while (ok && a.k < steps) ok = run_step(&a) == 0 && run_step(&b) == 0;
    if (!ok) {
        w->errors++;
        note(w, "thread %d, interleaved: %s %s", w->id, a.error, b.error);
    } else {
        compare(w, &a);
        compare(w, &b);
    }
    run_end(&a);
    run_end(&b);
    free(a.out);
    free(b.out);
    return NULL;
}

static void write_terrain(const char *dir)
{
    snprintf(terrain_path, sizeof terrain_path, "%s/parallel-terrain-%ld.asc", dir, (long)getpid());
    FILE *f = fopen(terrain_path, "w");
    if (!f) {
        perror(terrain_path);
        exit(2);
    }
    const int n = 60;
    fprintf(f, "ncols %d\nnrows %d\nxllcenter -3\nyllcenter -3\ncellsize 0.1\n", n, n);
    for (int j = n - 1; j >= 0; --j) {
        for (int i = 0; i < n; ++i) {
            double x = -3 + 0.1 * i, y = -3 + 0.1 * j;
            fprintf(f, "%.6f%c", 0.03 * sin(1.7 * x) * cos(1.3 * y) + 0.01 * x, i + 1 < n ? ' ' : '\n');
        }
    }
    fclose(f);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s FMU_DIR [WORK_DIR] [THREADS] [STEPS]\n", argv[0]);
        return 2;
    }
    const char *dir = argc > 2 ? argv[2] : "/tmp";
    int nthreads = argc > 3 ? atoi(argv[3]) : 8;
    if (argc > 4) steps = atoi(argv[4]);
    if (nthreads < 1 || nthreads > 256 || steps < 10) {
        fprintf(stderr, "bad THREADS or STEPS\n");
        return 2;
    }
    if (fmu_load(&F, argv[1]) != 0) return 2;
    fmi = &F.fmi;
    vr_mode = fmu_var(&F, "drive.mode")->vr;
    vr_kh = fmu_var(&F, "soil.kh")->vr;
    vr_gamma = fmu_var(&F, "soil.gamma")->vr;
    vr_yaw = fmu_var(&F, "init.yaw")->vr;
    vr_terrain = fmu_var(&F, "terrain.file")->vr;
    vr_drawbar = fmu_var(&F, "drawbarForce")->vr;
    vr_tql = fmu_var(&F, "torqueLeft")->vr;
    vr_tqr = fmu_var(&F, "torqueRight")->vr;
    vr_wl = fmu_var(&F, "omegaRefLeft")->vr;
    vr_wr = fmu_var(&F, "omegaRefRight")->vr;
    vr_thl = fmu_var(&F, "throttleLeft")->vr;
    vr_thr = fmu_var(&F, "throttleRight")->vr;
    for (int i = 0; i < F.nvars && n_out < MAX_OUT; ++i)
        if (F.vars[i].causality == 'o' && F.vars[i].type == 'r') out_vrs[n_out++] = F.vars[i].vr;
    write_terrain(dir);

    int passed = 0, failed = 0;
    /* serial reference runs; every scenario must move the rover */
    for (int s = 0; s < NSCEN; ++s) {
        Run r;
        int ok = run_begin(&r, s, "serial") == 0;
        while (ok && r.k < steps) ok = run_step(&r) == 0;
        int finite = ok;
        for (size_t k = 0; ok && k < (size_t)steps * n_out; ++k) finite &= isfinite(r.out[k]) != 0;
        if (ok && finite) {
            ++passed;
        } else {
            ++failed;
            printf("FAIL: serial scenario %d: %s\n", s, ok ? "non-finite outputs" : r.error);
        }
        run_end(&r);
        serial[s] = r.out;
    }
    /* the scenarios differ from each other (so a mix-up would be seen) */
    int distinct = 1;
    for (int s = 1; s < NSCEN; ++s)
        distinct &= memcmp(serial[s], serial[0], (size_t)steps * n_out * sizeof(double)) != 0;
    if (distinct) ++passed;
    else ++failed, printf("FAIL: two scenarios gave identical results\n");

    pthread_t *threads = (pthread_t *)calloc((size_t)nthreads, sizeof *threads);
    Worker *workers = (Worker *)calloc((size_t)nthreads, sizeof *workers);
    for (int i = 0; i < nthreads; ++i) {
        workers[i].id = i;
        if (pthread_create(&threads[i], NULL, worker_main, &workers[i]) != 0) {
            fprintf(stderr, "pthread_create failed\n");
            return 2;
        }
    }
    int runs = 0;
    for (int i = 0; i < nthreads; ++i) {
        pthread_join(threads[i], NULL);
        Worker *w = &workers[i];
        runs += w->runs;
        passed += w->runs - w->mismatches;
        failed += w->mismatches + w->errors;
        if (w->message[0]) printf("FAIL: %s\n", w->message);
    }
    printf("%d threads ran %d instances (%d steps each, %zu outputs compared per step) against %d serial runs\n",
           nthreads, runs, steps, n_out, NSCEN);
    free(threads);
    free(workers);
    for (int s = 0; s < NSCEN; ++s) free(serial[s]);
    remove(terrain_path);
    fmu_unload(&F);
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
