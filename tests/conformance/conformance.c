/*
 * FMI 2.0 Co-Simulation call-sequence conformance of the JunoRover FMU.
 *
 *   conformance FMU_DIR [WORK_DIR]
 *
 * FMU_DIR is the unzipped FMU (build/fmu); the binary is opened with
 * dlopen, exactly as an importer does, and the GUID and value references
 * come from its modelDescription.xml.  WORK_DIR (default: the temporary
 * directory) receives a scratch folder with spaces in its name.
 *
 * Checked: every FMI function in every state (Instantiated,
 * InitializationMode, StepComplete, Terminated, Error) against the state
 * table of the standard (section 4.2.4): legal calls succeed, illegal ones
 * return fmi2Error and log why, naming the function, and leave the
 * instance usable; fmi2Reset and fmi2FreeInstance from every state;
 * serialisation with too small, too large and corrupted buffers; log
 * categories; resource URIs with %20, the scheme in capitals and without
 * a resources folder; a terrain.file from the resources read back as set;
 * communication steps of 0, negative, tiny, huge and non-finite size and a
 * wrong communication point; NULL arguments; a wrong GUID and the
 * ModelExchange type; a diverging state.  Nothing may crash.
 *
 * Prints one line per failure and a final line "N passed, M failed";
 * exits nonzero if anything failed.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#if defined(_WIN32)
#include <direct.h>
#include <process.h>
#else
#include <sys/wait.h>
#include <unistd.h>
#endif

#include "fmu_loader.h"

static Fmu F;
static const Fmi *fmi;
static int passed, failed;
static char scratch[2048];        /* "<tmp>/juno conformance XXXXXX" */
static char resources_uri[4096];  /* file URI of scratch/resources, %20-encoded */

/* ------------------------------------------------------------- checks */

static void check(int ok, const char *fmt, ...)
{
    if (ok) {
        ++passed;
        return;
    }
    ++failed;
    va_list ap;
    va_start(ap, fmt);
    fputs("FAIL: ", stdout);
    vprintf(fmt, ap);
    fputc('\n', stdout);
    va_end(ap);
    fflush(stdout);
}

/* ------------------------------------------------------------ logging */

static int log_errors;            /* messages with status fmi2Error or worse */
static int log_total;
static char last_error[2048];
static char all_log[16384];       /* everything since the last log_clear, for searching */

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    char text[2048];
    va_list ap;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message ? message : "(null)", ap);
    va_end(ap);
    ++log_total;
    if (status >= fmi2Error) {
        ++log_errors;
        snprintf(last_error, sizeof last_error, "%s", text);
    }
    size_t used = strlen(all_log);
    snprintf(all_log + used, sizeof all_log - used, "[%s|%d|%s] %s\n", instance ? instance : "?", (int)status,
             category ? category : "?", text);
    if (getenv("JUNO_CONFORMANCE_VERBOSE")) printf("  log [%s] %s: %s\n", category, instance, text);
}

static void log_clear(void)
{
    log_errors = log_total = 0;
    last_error[0] = all_log[0] = '\0';
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

/* ------------------------------------------------------- instances */

enum { S_INSTANTIATED, S_INIT, S_STEP, S_TERMINATED, S_ERROR, NSTATES };
static const char *const state_names[NSTATES] = {"Instantiated", "InitializationMode", "StepComplete",
                                                  "Terminated", "Error"};
#define ALL ((1u << NSTATES) - 1)
#define BIT(s) (1u << (s))

static unsigned vr_kh, vr_inertia, vr_mode, vr_terrain, vr_drawbar, vr_tq_left, vr_tq_right, vr_x, vr_z;
static unsigned out_vrs[256];
static size_t n_out;

static fmi2Component make(const char *name, const char *resource_uri)
{
    return fmi->Instantiate(name, fmi2CoSimulation, F.guid, resource_uri, &callbacks, fmi2False, fmi2False);
}

/* Brings a fresh instance to state s; returns 0 on success. */
static int reach(fmi2Component c, int s)
{
    if (s == S_INSTANTIATED) return 0;
    if (fmi->SetupExperiment(c, fmi2False, 0, 0.0, fmi2False, 0) != fmi2OK) return -1;
    if (fmi->EnterInitializationMode(c) != fmi2OK) return -1;
    if (s == S_INIT) return 0;
    if (s == S_ERROR) {
        /* soil.kh at its declared min: accepted, but too soft to carry the rover, so
         * initialisation finds no static equilibrium and fails */
        const fmi2Real kh = 1e-3;
        if (fmi->SetReal(c, &vr_kh, 1, &kh) != fmi2OK) return -1;
        return fmi->ExitInitializationMode(c) == fmi2Error ? 0 : -1;
    }
    const fmi2Integer mode = 0;
    if (fmi->SetInteger(c, &vr_mode, 1, &mode) != fmi2OK) return -1;
    if (fmi->ExitInitializationMode(c) != fmi2OK) return -1;
    if (fmi->DoStep(c, 0.0, 0.01, fmi2True) != fmi2OK) return -1;
    if (s == S_STEP) return 0;
    return fmi->Terminate(c) == fmi2OK ? 0 : -1;
}

/* Simulates 20 steps of 10 ms from a fresh initialisation (drive.mode 0,
 * constant torques) and returns the outputs at the end in y (n_out). */
static int reference_run(fmi2Component c, double *y)
{
    const fmi2Integer mode = 0;
    const fmi2Real u[3] = {100.0, 40.0, 40.0};
    const unsigned vr_u[3] = {vr_drawbar, vr_tq_left, vr_tq_right};
    if (fmi->SetupExperiment(c, fmi2False, 0, 0.0, fmi2False, 0) != fmi2OK) return -1;
    if (fmi->EnterInitializationMode(c) != fmi2OK) return -1;
    if (fmi->SetInteger(c, &vr_mode, 1, &mode) != fmi2OK) return -1;
    if (fmi->SetReal(c, vr_u, 3, u) != fmi2OK) return -1;
    if (fmi->ExitInitializationMode(c) != fmi2OK) return -1;
    for (int i = 0; i < 20; ++i)
        if (fmi->DoStep(c, i * 0.01, 0.01, fmi2True) != fmi2OK) return -1;
    return fmi->GetReal(c, out_vrs, n_out, y) == fmi2OK ? 0 : -1;
}

/* --------------------------------------------- the state-table probes */

typedef struct {
    const char *fn;       /* the FMI function the probe calls */
    const char *what;
    unsigned legal;       /* states in which the call is legal and, with these arguments, succeeds */
    fmi2Status (*call)(fmi2Component c);
} Probe;

static fmi2Status p_debug_logging(fmi2Component c) { return fmi->SetDebugLogging(c, fmi2True, 0, NULL); }
static fmi2Status p_debug_logging_cat(fmi2Component c)
{
    const fmi2String cats[2] = {"logStatusError", "logStatusWarning"};
    return fmi->SetDebugLogging(c, fmi2True, 2, cats);
}
static fmi2Status p_setup(fmi2Component c) { return fmi->SetupExperiment(c, fmi2True, 1e-6, 0.0, fmi2True, 10.0); }
static fmi2Status p_enter(fmi2Component c) { return fmi->EnterInitializationMode(c); }
static fmi2Status p_exit(fmi2Component c) { return fmi->ExitInitializationMode(c); }
static fmi2Status p_terminate(fmi2Component c) { return fmi->Terminate(c); }
static fmi2Status p_get_real(fmi2Component c)
{
    fmi2Real v[2];
    const unsigned vrs[2] = {vr_x, vr_kh};
    return fmi->GetReal(c, vrs, 2, v);
}
static fmi2Status p_get_integer(fmi2Component c)
{
    fmi2Integer v;
    return fmi->GetInteger(c, &vr_mode, 1, &v);
}
static fmi2Status p_get_boolean(fmi2Component c)
{
    fmi2Boolean v;
    return fmi->GetBoolean(c, NULL, 0, &v);
}
static fmi2Status p_get_string(fmi2Component c)
{
    fmi2String v = NULL;
    fmi2Status st = fmi->GetString(c, &vr_terrain, 1, &v);
    if (st == fmi2OK && v == NULL) return fmi2Fatal;   /* a NULL string is never OK */
    return st;
}
static fmi2Status p_set_param(fmi2Component c)
{
    const fmi2Real v = 1.6e5;
    return fmi->SetReal(c, &vr_kh, 1, &v);
}
static fmi2Status p_set_input(fmi2Component c)
{
    const fmi2Real v = 120.0;
    return fmi->SetReal(c, &vr_drawbar, 1, &v);
}
static fmi2Status p_set_integer(fmi2Component c)
{
    const fmi2Integer v = 0;
    return fmi->SetInteger(c, &vr_mode, 1, &v);
}
static fmi2Status p_set_boolean(fmi2Component c)
{
    const fmi2Boolean v = fmi2True;
    return fmi->SetBoolean(c, NULL, 0, &v);
}
static fmi2Status p_set_string(fmi2Component c)
{
    const fmi2String v = "";
    return fmi->SetString(c, &vr_terrain, 1, &v);
}
static fmi2Status p_get_free_state(fmi2Component c)
{
    fmi2FMUstate s = NULL;
    fmi2Status st = fmi->GetFMUstate(c, &s);
    if (st != fmi2OK) return st;
    st = fmi->GetFMUstate(c, &s);   /* overwrite the same state */
    if (st != fmi2OK) return st;
    st = fmi->FreeFMUstate(c, &s);
    return st == fmi2OK && s != NULL ? fmi2Fatal : st;
}
static fmi2Status p_set_state(fmi2Component c)
{
    fmi2FMUstate s = NULL;
    fmi2Status st = fmi->GetFMUstate(c, &s);
    if (st != fmi2OK) return fmi2Fatal;
    st = fmi->SetFMUstate(c, s);
    fmi->FreeFMUstate(c, &s);
    return st;
}
static fmi2Status p_serialize(fmi2Component c)
{
    fmi2FMUstate s = NULL, back = NULL;
    size_t size = 0;
    if (fmi->GetFMUstate(c, &s) != fmi2OK) return fmi2Fatal;
    fmi2Status st = fmi->SerializedFMUstateSize(c, s, &size);
    char *buf = st == fmi2OK ? (char *)malloc(size) : NULL;
    if (st == fmi2OK) st = buf ? fmi->SerializeFMUstate(c, s, buf, size) : fmi2Fatal;
    if (st == fmi2OK) st = fmi->DeSerializeFMUstate(c, buf, size, &back);
    if (st == fmi2OK) st = fmi->SetFMUstate(c, back);
    if (back) fmi->FreeFMUstate(c, &back);
    fmi->FreeFMUstate(c, &s);
    free(buf);
    return st;
}
static fmi2Status p_dir_derivative(fmi2Component c)
{
    fmi2Real dv = 1.0, out = 0.0;
    return fmi->GetDirectionalDerivative(c, &vr_x, 1, &vr_drawbar, 1, &dv, &out);
}
static fmi2Status p_set_input_der(fmi2Component c)
{
    const fmi2Integer order = 1;
    const fmi2Real v = 1.0;
    return fmi->SetRealInputDerivatives(c, &vr_drawbar, 1, &order, &v);
}
static fmi2Status p_get_output_der(fmi2Component c)
{
    const fmi2Integer order = 1;
    fmi2Real v;
    return fmi->GetRealOutputDerivatives(c, &vr_x, 1, &order, &v);
}
static fmi2Status p_do_step(fmi2Component c)
{
    fmi2Real t = 0.0;
    if (fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &t) != fmi2OK) t = 0.0;
    return fmi->DoStep(c, t, 0.01, fmi2True);
}
static fmi2Status p_cancel(fmi2Component c) { return fmi->CancelStep(c); }
static fmi2Status p_status(fmi2Component c)
{
    fmi2Status v;
    return fmi->GetStatus(c, fmi2DoStepStatus, &v);
}
static fmi2Status p_status_pending(fmi2Component c)
{
    fmi2Status v;
    return fmi->GetStatus(c, fmi2PendingStatus, &v);
}
static fmi2Status p_real_status(fmi2Component c)
{
    fmi2Real v;
    return fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &v);
}
static fmi2Status p_integer_status(fmi2Component c)
{
    fmi2Integer v;
    return fmi->GetIntegerStatus(c, fmi2DoStepStatus, &v);
}
static fmi2Status p_boolean_status(fmi2Component c)
{
    fmi2Boolean v;
    return fmi->GetBooleanStatus(c, fmi2Terminated, &v);
}
static fmi2Status p_string_status(fmi2Component c)
{
    fmi2String v;
    return fmi->GetStringStatus(c, fmi2PendingStatus, &v);
}
static fmi2Status p_reset(fmi2Component c) { return fmi->Reset(c); }

#define I_ BIT(S_INSTANTIATED)
#define N_ BIT(S_INIT)
#define C_ BIT(S_STEP)
#define T_ BIT(S_TERMINATED)
#define E_ BIT(S_ERROR)

/* legal: the standard's table (4.2.4) narrowed to calls that succeed with
 * these arguments.  fmi2GetStatus & co. are also answered in the Error
 * state (where a failed fmi2DoStep leaves the instance): the standard
 * lists them for stepFailed, which this FMU reports as Error. */
static const Probe probes[] = {
    {"fmi2SetDebugLogging", "all categories on", ALL, p_debug_logging},
    {"fmi2SetDebugLogging", "two named categories", ALL, p_debug_logging_cat},
    {"fmi2SetupExperiment", "", I_, p_setup},
    {"fmi2EnterInitializationMode", "", I_, p_enter},
    {"fmi2ExitInitializationMode", "", N_, p_exit},
    {"fmi2Terminate", "", C_, p_terminate},
    {"fmi2GetReal", "an output and a parameter", N_ | C_ | T_ | E_, p_get_real},
    {"fmi2GetInteger", "drive.mode", N_ | C_ | T_ | E_, p_get_integer},
    {"fmi2GetBoolean", "no variables", N_ | C_ | T_ | E_, p_get_boolean},
    {"fmi2GetString", "terrain.file", N_ | C_ | T_ | E_, p_get_string},
    {"fmi2SetReal", "a fixed parameter", I_ | N_, p_set_param},
    {"fmi2SetReal", "an input", I_ | N_ | C_, p_set_input},
    {"fmi2SetInteger", "a fixed parameter", I_ | N_, p_set_integer},
    {"fmi2SetBoolean", "no variables", I_ | N_ | C_, p_set_boolean},
    {"fmi2SetString", "terrain.file", I_ | N_, p_set_string},
    {"fmi2GetFMUstate", "get twice and free", ALL, p_get_free_state},
    {"fmi2SetFMUstate", "its own state", ALL, p_set_state},
    {"fmi2SerializeFMUstate", "size, serialize, deserialize, set", ALL, p_serialize},
    {"fmi2GetDirectionalDerivative", "not provided", 0, p_dir_derivative},
    {"fmi2SetRealInputDerivatives", "canInterpolateInputs = false", 0, p_set_input_der},
    {"fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder = 0", 0, p_get_output_der},
    {"fmi2DoStep", "10 ms", C_, p_do_step},
    {"fmi2CancelStep", "no step pending", 0, p_cancel},
    {"fmi2GetStatus", "fmi2DoStepStatus", C_ | T_ | E_, p_status},
    {"fmi2GetStatus", "fmi2PendingStatus", 0, p_status_pending},
    {"fmi2GetRealStatus", "fmi2LastSuccessfulTime", C_ | T_ | E_, p_real_status},
    {"fmi2GetIntegerStatus", "no integer status", 0, p_integer_status},
    {"fmi2GetBooleanStatus", "fmi2Terminated", C_ | T_ | E_, p_boolean_status},
    {"fmi2GetStringStatus", "no string status", 0, p_string_status},
    {"fmi2Reset", "", ALL, p_reset},
};
#define NPROBES (sizeof probes / sizeof probes[0])

static void test_state_table(void)
{
    for (int s = 0; s < NSTATES; ++s) {
        for (size_t k = 0; k < NPROBES; ++k) {
            const Probe *p = &probes[k];
            fmi2Component c = make("table", resources_uri);
            if (!c) {
                check(0, "%s in %s: fmi2Instantiate failed", p->fn, state_names[s]);
                continue;
            }
            if (reach(c, s) != 0) {
                check(0, "%s in %s: could not reach the state: %s", p->fn, state_names[s], last_error);
                fmi->FreeInstance(c);
                continue;
            }
            log_clear();
            fmi2Status st = p->call(c);
            int legal = (p->legal & BIT(s)) != 0;
            if (legal) {
                check(st == fmi2OK, "%s (%s) in %s: status %d, expected fmi2OK; log: %s", p->fn, p->what,
                      state_names[s], (int)st, all_log);
            } else {
                check(st == fmi2Error, "%s (%s) in %s: status %d, expected fmi2Error", p->fn, p->what,
                      state_names[s], (int)st);
                check(log_errors > 0 && strstr(last_error, p->fn) != NULL,
                      "%s (%s) in %s: refused without an error message naming the function (log: %s)", p->fn,
                      p->what, state_names[s], all_log);
                /* a refused call changes nothing: the instance still works */
                check(fmi->Reset(c) == fmi2OK, "%s (%s) in %s: fmi2Reset after the refused call failed", p->fn,
                      p->what, state_names[s]);
            }
            fmi->FreeInstance(c);
        }
    }
}

/* fmi2Reset from every state, then a run equal (bit for bit) to a fresh
 * instance's; and fmi2FreeInstance from every state. */
static void test_reset_and_free(void)
{
    double ref[256], y[256];
    fmi2Component c = make("reference", resources_uri);
    check(c && reference_run(c, ref) == 0, "reference run failed: %s", last_error);
    fmi->FreeInstance(c);
    for (int s = 0; s < NSTATES; ++s) {
        c = make("reset", resources_uri);
        if (!c || reach(c, s) != 0) {
            check(0, "reset from %s: could not reach the state", state_names[s]);
            if (c) fmi->FreeInstance(c);
            continue;
        }
        if (s == S_STEP) {   /* also move on a bit and change an input first */
            const fmi2Real v = 900.0;
            fmi->SetReal(c, &vr_drawbar, 1, &v);
            fmi->DoStep(c, 0.01, 0.05, fmi2True);
        }
        check(fmi->Reset(c) == fmi2OK, "fmi2Reset from %s failed", state_names[s]);
        check(reference_run(c, y) == 0, "run after fmi2Reset from %s failed: %s", state_names[s], last_error);
        check(memcmp(ref, y, n_out * sizeof *y) == 0,
              "run after fmi2Reset from %s differs from a fresh instance's (x %.17g vs %.17g)", state_names[s],
              y[0], ref[0]);
        /* reset twice in a row is fine too */
        check(fmi->Reset(c) == fmi2OK && fmi->Reset(c) == fmi2OK, "fmi2Reset twice after %s failed",
              state_names[s]);
        fmi->FreeInstance(c);
    }
    for (int s = 0; s < NSTATES; ++s) {
        c = make("free", resources_uri);
        check(c != NULL && reach(c, s) == 0, "free from %s: could not reach the state", state_names[s]);
        if (c) {
            fmi2FMUstate st = NULL;
            fmi->GetFMUstate(c, &st);   /* a state left allocated is the FMU's to free */
            fmi->FreeFMUstate(c, &st);
            fmi->FreeInstance(c);
        }
        check(1, "fmi2FreeInstance from %s", state_names[s]);
    }
    fmi->FreeInstance(NULL);
    check(1, "fmi2FreeInstance(NULL) did not crash");
}

/* ------------------------------------------------------ instantiation */

static void test_instantiate(void)
{
    check(fmi->GetTypesPlatform() && !strcmp(fmi->GetTypesPlatform(), "default"), "fmi2GetTypesPlatform");
    check(fmi->GetVersion() && !strcmp(fmi->GetVersion(), "2.0"), "fmi2GetVersion");

    log_clear();
    fmi2Component c = fmi->Instantiate("me", fmi2ModelExchange, F.guid, resources_uri, &callbacks, 0, 0);
    check(c == NULL, "ModelExchange instantiation was accepted");
    check(log_errors > 0 && strstr(last_error, "Co-Simulation"), "ModelExchange refusal not explained: %s",
          all_log);
    if (c) fmi->FreeInstance(c);

    log_clear();
    c = fmi->Instantiate("guid", fmi2CoSimulation, "{00000000-0000-0000-0000-000000000000}", resources_uri,
                         &callbacks, 0, 0);
    check(c == NULL, "a wrong GUID was accepted");
    check(log_errors > 0 && strstr(last_error, "GUID"), "wrong GUID refusal not explained: %s", all_log);
    if (c) fmi->FreeInstance(c);

    char longer[160];
    snprintf(longer, sizeof longer, "%s ", F.guid);
    c = fmi->Instantiate("guid2", fmi2CoSimulation, longer, resources_uri, &callbacks, 0, 0);
    check(c == NULL, "a GUID with a trailing space was accepted");
    if (c) fmi->FreeInstance(c);

    log_clear();
    c = fmi->Instantiate("noguid", fmi2CoSimulation, NULL, resources_uri, &callbacks, 0, 0);
    check(c == NULL && log_errors > 0, "a NULL GUID was accepted or not explained");
    if (c) fmi->FreeInstance(c);

    log_clear();
    c = fmi->Instantiate(NULL, fmi2CoSimulation, F.guid, resources_uri, &callbacks, 0, 0);
    check(c == NULL && log_errors > 0, "a NULL instance name was accepted or not explained");
    if (c) fmi->FreeInstance(c);
    c = fmi->Instantiate("", fmi2CoSimulation, F.guid, resources_uri, &callbacks, 0, 0);
    check(c == NULL, "an empty instance name was accepted");
    if (c) fmi->FreeInstance(c);

    c = fmi->Instantiate("nocb", fmi2CoSimulation, F.guid, resources_uri, NULL, 0, 0);
    check(c == NULL, "NULL callbacks were accepted");
    if (c) fmi->FreeInstance(c);
    const fmi2CallbackFunctions no_logger = {NULL, calloc, free, NULL, NULL};
    c = fmi->Instantiate("nolog", fmi2CoSimulation, F.guid, resources_uri, &no_logger, 0, 0);
    check(c == NULL, "callbacks without a logger were accepted");
    if (c) fmi->FreeInstance(c);

    /* the memory callbacks are not used (canNotUseMemoryManagementFunctions) */
    const fmi2CallbackFunctions no_memory = {logger, NULL, NULL, NULL, NULL};
    c = fmi->Instantiate("nomem", fmi2CoSimulation, F.guid, resources_uri, &no_memory, 0, 0);
    double y[256];
    check(c != NULL && reference_run(c, y) == 0, "instance without memory callbacks failed");
    if (c) fmi->FreeInstance(c);

    /* visible and loggingOn = true; two instances with the same name */
    log_clear();
    fmi2Component a = fmi->Instantiate("twin", fmi2CoSimulation, F.guid, resources_uri, &callbacks, 1, 1);
    fmi2Component b = fmi->Instantiate("twin", fmi2CoSimulation, F.guid, NULL, &callbacks, 1, 1);
    check(a && b && a != b, "two instances with the same name");
    check(log_total > 0 && strstr(all_log, "logCalls"), "loggingOn = true logged no calls: %s", all_log);
    if (a) fmi->FreeInstance(a);
    if (b) fmi->FreeInstance(b);
}

/* --------------------------------------------------- NULL arguments */

static void test_null_arguments(void)
{
    /* every function with a NULL instance: fmi2Error, no crash */
    fmi2Real r = 0;
    fmi2Integer i = 0;
    fmi2Boolean b = 0;
    fmi2String s = NULL;
    fmi2Status stv;
    fmi2FMUstate fs = NULL;
    size_t size = 0;
    char buf[16] = {0};
    const fmi2Status e = fmi2Error;
    int k = 0;
#define NULLC(call) check((call) == e, "NULL instance: %s did not return fmi2Error", #call), ++k
    NULLC(fmi->SetDebugLogging(NULL, 1, 0, NULL));
    NULLC(fmi->SetupExperiment(NULL, 0, 0, 0, 0, 0));
    NULLC(fmi->EnterInitializationMode(NULL));
    NULLC(fmi->ExitInitializationMode(NULL));
    NULLC(fmi->Terminate(NULL));
    NULLC(fmi->Reset(NULL));
    NULLC(fmi->GetReal(NULL, &vr_x, 1, &r));
    NULLC(fmi->GetInteger(NULL, &vr_mode, 1, &i));
    NULLC(fmi->GetBoolean(NULL, &vr_mode, 1, &b));
    NULLC(fmi->GetString(NULL, &vr_terrain, 1, &s));
    NULLC(fmi->SetReal(NULL, &vr_x, 1, &r));
    NULLC(fmi->SetInteger(NULL, &vr_mode, 1, &i));
    NULLC(fmi->SetBoolean(NULL, &vr_mode, 1, &b));
    NULLC(fmi->SetString(NULL, &vr_terrain, 1, &s));
    NULLC(fmi->GetFMUstate(NULL, &fs));
    NULLC(fmi->SetFMUstate(NULL, fs));
    NULLC(fmi->FreeFMUstate(NULL, &fs));
    NULLC(fmi->SerializedFMUstateSize(NULL, fs, &size));
    NULLC(fmi->SerializeFMUstate(NULL, fs, buf, sizeof buf));
    NULLC(fmi->DeSerializeFMUstate(NULL, buf, sizeof buf, &fs));
    NULLC(fmi->GetDirectionalDerivative(NULL, &vr_x, 1, &vr_x, 1, &r, &r));
    NULLC(fmi->SetRealInputDerivatives(NULL, &vr_x, 1, &i, &r));
    NULLC(fmi->GetRealOutputDerivatives(NULL, &vr_x, 1, &i, &r));
    NULLC(fmi->DoStep(NULL, 0, 0.01, 1));
    NULLC(fmi->CancelStep(NULL));
    NULLC(fmi->GetStatus(NULL, fmi2DoStepStatus, &stv));
    NULLC(fmi->GetRealStatus(NULL, fmi2LastSuccessfulTime, &r));
    NULLC(fmi->GetIntegerStatus(NULL, fmi2DoStepStatus, &i));
    NULLC(fmi->GetBooleanStatus(NULL, fmi2Terminated, &b));
    NULLC(fmi->GetStringStatus(NULL, fmi2PendingStatus, &s));
#undef NULLC
    check(k == (int)FMI_NUM_FUNCTIONS - 4, "NULL-instance cases cover every function with a component");

    /* NULL arrays and pointers on a live instance */
    fmi2Component c = make("nullargs", resources_uri);
    reach(c, S_STEP);
#define NULLA(call, why)                                                                               \
    do {                                                                                               \
        log_clear();                                                                                   \
        fmi2Status st_ = (call);                                                                       \
        check(st_ == e && log_errors > 0, "%s: %s returned %d (expected a logged fmi2Error)", why, #call, \
              (int)st_);                                                                               \
    } while (0)
    NULLA(fmi->GetReal(c, NULL, 1, &r), "NULL value references");
    NULLA(fmi->GetReal(c, &vr_x, 1, NULL), "NULL values");
    NULLA(fmi->GetInteger(c, NULL, 1, &i), "NULL value references");
    NULLA(fmi->GetInteger(c, &vr_mode, 1, NULL), "NULL values");
    NULLA(fmi->GetString(c, &vr_terrain, 1, NULL), "NULL values");
    NULLA(fmi->GetBoolean(c, NULL, 1, &b), "NULL value references");
    NULLA(fmi->SetReal(c, NULL, 1, &r), "NULL value references");
    NULLA(fmi->SetReal(c, &vr_drawbar, 1, NULL), "NULL values");
    NULLA(fmi->SetInteger(c, &vr_mode, 1, NULL), "NULL values");
    NULLA(fmi->SetBoolean(c, NULL, 1, &b), "NULL value references");
    NULLA(fmi->GetFMUstate(c, NULL), "NULL state pointer");
    NULLA(fmi->SetFMUstate(c, NULL), "NULL state");
    NULLA(fmi->FreeFMUstate(c, NULL), "NULL state pointer");
    NULLA(fmi->SerializedFMUstateSize(c, NULL, &size), "NULL state");
    NULLA(fmi->SerializeFMUstate(c, NULL, buf, sizeof buf), "NULL state");
    NULLA(fmi->DeSerializeFMUstate(c, NULL, 100, &fs), "NULL buffer");
    NULLA(fmi->DeSerializeFMUstate(c, buf, sizeof buf, NULL), "NULL state pointer");
    NULLA(fmi->GetStatus(c, fmi2DoStepStatus, NULL), "NULL value");
    NULLA(fmi->GetRealStatus(c, fmi2LastSuccessfulTime, NULL), "NULL value");
    NULLA(fmi->GetBooleanStatus(c, fmi2Terminated, NULL), "NULL value");
    NULLA(fmi->SetDebugLogging(c, 1, 1, NULL), "NULL categories");
    /* zero-length requests with NULL arrays are fine */
    check(fmi->GetReal(c, NULL, 0, NULL) == fmi2OK, "GetReal of no variables with NULL arrays");
    check(fmi->SetReal(c, NULL, 0, NULL) == fmi2OK, "SetReal of no variables with NULL arrays");
    fmi2FMUstate none = NULL;
    check(fmi->FreeFMUstate(c, &none) == fmi2OK, "FreeFMUstate of a NULL state is a no-op");
    /* unknown value references and wrong types */
    const unsigned bad = 99999;
    NULLA(fmi->GetReal(c, &bad, 1, &r), "unknown value reference");
    NULLA(fmi->GetInteger(c, &vr_x, 1, &i), "Real value reference read as Integer");
    NULLA(fmi->GetString(c, &vr_x, 1, &s), "Real value reference read as String");
    NULLA(fmi->SetReal(c, &vr_mode, 1, &r), "Integer value reference set as Real");
    NULLA(fmi->SetReal(c, &vr_x, 1, &r), "setting an output");
    fmi->Terminate(c);
    fmi->FreeInstance(c);

    c = make("nullstring", resources_uri);
    const fmi2String nul = NULL;
    NULLA(fmi->SetString(c, &vr_terrain, 1, &nul), "NULL string");
    fmi->FreeInstance(c);
#undef NULLA
}

/* ---------------------------------------------------- log categories */

static void test_log_categories(void)
{
    fmi2Component c = make("log", resources_uri);
    const fmi2String unknown[1] = {"logNoSuchCategory"};
    log_clear();
    check(fmi->SetDebugLogging(c, 1, 1, unknown) == fmi2Error, "an unknown log category was accepted");
    check(strstr(last_error, "logNoSuchCategory") != NULL, "unknown category refusal not explained: %s", all_log);
    const fmi2String mixed[2] = {"logCalls", "LOGCALLS"};
    check(fmi->SetDebugLogging(c, 1, 2, mixed) == fmi2Error, "a wrongly capitalised category was accepted");
    const fmi2String nullcat[1] = {NULL};
    check(fmi->SetDebugLogging(c, 1, 1, nullcat) == fmi2Error, "a NULL category was accepted");
    /* a refused call changed nothing: logCalls is still off */
    log_clear();
    fmi->SetupExperiment(c, 0, 0, 0, 0, 0);
    check(strstr(all_log, "logCalls") == NULL, "a refused fmi2SetDebugLogging turned logCalls on");

    const fmi2String calls[1] = {"logCalls"};
    check(fmi->SetDebugLogging(c, 1, 1, calls) == fmi2OK, "logCalls on");
    log_clear();
    fmi->EnterInitializationMode(c);
    check(strstr(all_log, "fmi2EnterInitializationMode") != NULL, "logCalls on but the call was not logged");
    check(fmi->SetDebugLogging(c, 0, 1, calls) == fmi2OK, "logCalls off");
    log_clear();
    fmi->ExitInitializationMode(c);
    check(strstr(all_log, "logCalls") == NULL, "logCalls off but calls were logged: %s", all_log);
    const fmi2String errors[1] = {"logStatusError"};
    check(fmi->SetDebugLogging(c, 0, 1, errors) == fmi2OK, "logStatusError off");
    log_clear();
    check(fmi->EnterInitializationMode(c) == fmi2Error && log_total == 0,
          "with logStatusError off a refused call was still logged");
    check(fmi->SetDebugLogging(c, 1, 0, NULL) == fmi2OK, "all categories on");
    log_clear();
    fmi->EnterInitializationMode(c);
    check(log_errors == 1, "all categories on: the refusal was not logged");
    fmi->FreeInstance(c);

    /* '%' in a message (the logger formats it): the terrain file name is quoted */
    c = make("percent", resources_uri);
    reach(c, S_INIT);
    const fmi2String pct = "/nonexistent/100%done%s%n.asc";
    fmi->SetString(c, &vr_terrain, 1, &pct);
    log_clear();
    check(fmi->ExitInitializationMode(c) == fmi2Error, "a missing terrain file was accepted");
    check(strstr(last_error, "100%done%s%n.asc") != NULL, "a file name with %% was not logged verbatim: %s",
          last_error);
    fmi->FreeInstance(c);
}

/* ---------------------------------------------------- FMU state bytes */

/* The serialized layout ends with a 64-bit FNV-1a checksum of the bytes
 * before it (fmu_src/fmi2_cs.c); a crafted state recomputes it. */
static void fix_checksum(char *buf, size_t n)
{
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i + 8 < n; ++i) {
        h ^= (unsigned char)buf[i];
        h *= 1099511628211ull;
    }
    memcpy(buf + n - 8, &h, 8);
}

/* Replaces the first 8-byte occurrence of the double `from` by `to`. */
static int patch_double(char *buf, size_t n, double from, double to)
{
    for (size_t i = 0; i + 16 <= n; ++i)
        if (!memcmp(buf + i, &from, 8)) {
            memcpy(buf + i, &to, 8);
            return 1;
        }
    return 0;
}

/* States with a valid checksum but impossible contents are refused too:
 * a parameter outside its range, a non-finite integrator state. */
static void test_crafted_states(void)
{
    const double kh = 123456.789012, start = 12.3456789;
    fmi2Component c = make("crafted", resources_uri);
    fmi->SetupExperiment(c, 0, 0, start, 0, 0);
    fmi->EnterInitializationMode(c);
    fmi->SetReal(c, &vr_kh, 1, &kh);
    fmi->ExitInitializationMode(c);
    fmi->DoStep(c, start, 0.01, 1);
    fmi2FMUstate s = NULL, t = NULL;
    size_t size = 0;
    fmi->GetFMUstate(c, &s);
    fmi->SerializedFMUstateSize(c, s, &size);
    char *buf = (char *)malloc(size), *bad = (char *)malloc(size);
    fmi->SerializeFMUstate(c, s, buf, size);
    const struct {
        double from, to;
        const char *what, *expect;
    } cases[] = {{kh, -1.0, "soil.kh = -1", "soil.kh"},
                 {kh, NAN, "soil.kh = NaN", "soil.kh"},
                 {start + 0.01, NAN, "time = NaN", "integrator state"},
                 {start + 0.01, 1e300, "time = 1e300", "integrator state"}};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        memcpy(bad, buf, size);
        int found = patch_double(bad, size, cases[k].from, cases[k].to);
        check(found, "crafted state %s: value not found in the serialized bytes", cases[k].what);
        fix_checksum(bad, size);
        log_clear();
        check(fmi->DeSerializeFMUstate(c, bad, size, &t) == fmi2Error && t == NULL,
              "a crafted state with %s was accepted", cases[k].what);
        check(strstr(last_error, cases[k].expect) != NULL, "crafted state with %s: message '%s' does not name %s",
              cases[k].what, last_error, cases[k].expect);
    }
    memcpy(bad, buf, size);
    fix_checksum(bad, size);
    check(fmi->DeSerializeFMUstate(c, bad, size, &t) == fmi2OK, "recomputing the checksum alone breaks nothing");
    fmi->FreeFMUstate(c, &t);
    fmi->FreeFMUstate(c, &s);
    free(buf);
    free(bad);
    fmi->FreeInstance(c);
}

static void test_serialization(void)
{
    fmi2Component c = make("serial", resources_uri);
    fmi2Component d = make("serial2", resources_uri);
    reach(c, S_STEP);
    reach(d, S_STEP);
    fmi2FMUstate s = NULL, back = NULL;
    size_t size = 0;
    check(fmi->GetFMUstate(c, &s) == fmi2OK, "GetFMUstate");
    check(fmi->SerializedFMUstateSize(c, s, &size) == fmi2OK && size > 16, "SerializedFMUstateSize = %zu", size);
    const size_t pad = 64;
    char *buf = (char *)malloc(size + pad), *copy = (char *)malloc(size + pad);
    memset(buf, 0xA5, size + pad);

    log_clear();
    check(fmi->SerializeFMUstate(c, s, buf, size - 1) == fmi2Error && log_errors > 0,
          "serialize into a buffer one byte too small was accepted");
    check(fmi->SerializeFMUstate(c, s, buf, 0) == fmi2Error, "serialize into a 0-byte buffer was accepted");
    int untouched = 1;
    for (size_t k = 0; k < size + pad; ++k) untouched &= (unsigned char)buf[k] == 0xA5;
    check(untouched, "a refused serialize wrote into the buffer");
    check(fmi->SerializeFMUstate(c, s, buf, size + pad) == fmi2OK, "serialize into a larger buffer");
    int canary = 1;
    for (size_t k = size; k < size + pad; ++k) canary &= (unsigned char)buf[k] == 0xA5;
    check(canary, "serialize wrote past the serialized size");
    memcpy(copy, buf, size + pad);

    log_clear();
    check(fmi->DeSerializeFMUstate(c, buf, size - 1, &back) == fmi2Error && back == NULL,
          "deserialize of a truncated buffer was accepted");
    check(strstr(last_error, "fmi2DeSerializeFMUstate") != NULL, "truncated buffer refusal not explained");
    check(fmi->DeSerializeFMUstate(c, buf, size + 1, &back) == fmi2Error && back == NULL,
          "deserialize of a too-large buffer was accepted");
    check(fmi->DeSerializeFMUstate(c, buf, 0, &back) == fmi2Error && back == NULL,
          "deserialize of an empty buffer was accepted");
    check(fmi->DeSerializeFMUstate(c, buf, 1, &back) == fmi2Error && back == NULL,
          "deserialize of a 1-byte buffer was accepted");

    /* every single-byte corruption, at every offset, is refused */
    size_t accepted = 0, first_accepted = (size_t)-1;
    for (size_t k = 0; k < size; ++k) {
        buf[k] ^= (char)0x5A;
        fmi2FMUstate t = NULL;
        if (fmi->DeSerializeFMUstate(c, buf, size, &t) != fmi2Error || t != NULL) {
            if (!accepted) first_accepted = k;
            ++accepted;
            if (t) fmi->FreeFMUstate(c, &t);
        }
        buf[k] ^= (char)0x5A;
    }
    check(accepted == 0, "%zu of %zu single-byte corruptions were accepted (first at offset %zu)", accepted, size,
          first_accepted);
    /* zeroed and all-ones buffers, a zeroed checksum */
    char *junk = (char *)calloc(1, size);
    fmi2FMUstate t = NULL;
    check(fmi->DeSerializeFMUstate(c, junk, size, &t) == fmi2Error && !t, "an all-zero buffer was accepted");
    memset(junk, 0xFF, size);
    check(fmi->DeSerializeFMUstate(c, junk, size, &t) == fmi2Error && !t, "an all-ones buffer was accepted");
    memcpy(junk, buf, size);
    memset(junk + size - 8, 0, 8);
    check(fmi->DeSerializeFMUstate(c, junk, size, &t) == fmi2Error && !t, "a zeroed checksum was accepted");
    free(junk);
    check(memcmp(buf, copy, size + pad) == 0, "the corruption loop did not restore the buffer");

    /* a state that is not this FMU's */
    unsigned char foreign[4096] = {0};
    fmi2FMUstate fp = foreign;
    log_clear();
    check(fmi->SetFMUstate(c, fp) == fmi2Error && log_errors > 0, "a foreign FMUstate was set");
    check(fmi->GetFMUstate(c, &fp) == fmi2Error, "GetFMUstate overwrote a foreign FMUstate");
    check(fmi->SerializedFMUstateSize(c, s, NULL) == fmi2Error, "SerializedFMUstateSize with a NULL size");

    /* valid round trip, into the same instance and into a second one, replays bit for bit */
    double y1[256], y2[256], y3[256];
    fmi2Real t0 = 0;
    fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &t0);
    for (int k = 0; k < 10; ++k) fmi->DoStep(c, t0 + k * 0.01, 0.01, fmi2False);
    fmi->GetReal(c, out_vrs, n_out, y1);
    check(fmi->DeSerializeFMUstate(c, buf, size, &back) == fmi2OK && back, "deserialize a valid buffer");
    check(fmi->SetFMUstate(c, back) == fmi2OK, "set the deserialized state");
    for (int k = 0; k < 10; ++k) fmi->DoStep(c, t0 + k * 0.01, 0.01, fmi2False);
    fmi->GetReal(c, out_vrs, n_out, y2);
    check(memcmp(y1, y2, n_out * sizeof *y1) == 0, "replay after deserialize differs");
    fmi2FMUstate other = NULL;
    check(fmi->DeSerializeFMUstate(d, buf, size, &other) == fmi2OK && fmi->SetFMUstate(d, other) == fmi2OK,
          "deserialize into a second instance");
    for (int k = 0; k < 10; ++k) fmi->DoStep(d, t0 + k * 0.01, 0.01, fmi2False);
    fmi->GetReal(d, out_vrs, n_out, y3);
    check(memcmp(y1, y3, n_out * sizeof *y1) == 0, "replay in a second instance differs");
    /* deserialize into an existing state object reuses it */
    fmi2FMUstate reuse = back;
    check(fmi->DeSerializeFMUstate(c, buf, size, &reuse) == fmi2OK && reuse == back,
          "deserialize into an existing FMUstate");
    fmi->FreeFMUstate(d, &other);

    /* a state taken after initialisation cannot be set into an uninitialised instance */
    fmi2Component fresh = make("serial3", resources_uri);
    fmi2FMUstate into_fresh = NULL;
    log_clear();
    check(fmi->DeSerializeFMUstate(fresh, buf, size, &into_fresh) == fmi2OK, "deserialize in a fresh instance");
    check(fmi->SetFMUstate(fresh, into_fresh) == fmi2Error && log_errors > 0,
          "a StepComplete state was set into an uninitialised instance");
    fmi->FreeFMUstate(fresh, &into_fresh);
    fmi->FreeInstance(fresh);

    fmi->FreeFMUstate(c, &back);
    fmi->FreeFMUstate(c, &s);
    free(buf);
    free(copy);
    fmi->FreeInstance(c);
    fmi->FreeInstance(d);
    test_crafted_states();
}

/* ---------------------------------------------------------- stepping */

static void test_steps(void)
{
    fmi2Component c = make("steps", resources_uri);
    reach(c, S_STEP);   /* at t = 0.01 */
    fmi2Real t = 0.0;
    fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &t);
    check(t == 0.01, "time after the first step is %.17g", t);
    const struct {
        double h;
        const char *what;
    } bad_h[] = {{0.0, "0"}, {-0.01, "negative"}, {-1e-12, "tiny negative"}, {1e6, "1e6 s"},
                 {NAN, "NaN"}, {INFINITY, "Inf"}, {-INFINITY, "-Inf"}};
    for (size_t k = 0; k < sizeof bad_h / sizeof bad_h[0]; ++k) {
        log_clear();
        check(fmi->DoStep(c, t, bad_h[k].h, fmi2True) == fmi2Error, "a %s communication step was accepted",
              bad_h[k].what);
        check(log_errors > 0 && strstr(last_error, "communicationStepSize"),
              "a %s communication step: refusal not explained (%s)", bad_h[k].what, last_error);
    }
    const struct {
        double t;
        const char *what;
    } bad_t[] = {{0.5, "0.5 s ahead"}, {0.0, "one step back"}, {-1.0, "negative"}, {NAN, "NaN"},
                 {INFINITY, "Inf"}, {0.0100001, "0.1 us ahead"}};
    for (size_t k = 0; k < sizeof bad_t / sizeof bad_t[0]; ++k) {
        log_clear();
        check(fmi->DoStep(c, bad_t[k].t, 0.01, fmi2True) == fmi2Error,
              "doStep at a wrong communication point (%s) was accepted", bad_t[k].what);
        check(log_errors > 0 && strstr(last_error, "currentCommunicationPoint"),
              "wrong communication point (%s): refusal not explained (%s)", bad_t[k].what, last_error);
    }
    /* the refusals changed nothing: the FMU is still at t = 0.01 in StepComplete */
    fmi2Real t2 = -1;
    fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &t2);
    check(t2 == t, "refused steps moved the time to %.17g", t2);
    check(fmi->DoStep(c, t + 1e-13, 0.01, fmi2True) == fmi2OK,
          "a communication point off by rounding (1e-13 s) was refused");
    check(fmi->DoStep(c, 0.02, 1e-12, fmi2True) == fmi2OK, "a tiny (1e-12 s) communication step was refused: %s",
          last_error);
    fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &t2);
    check(t2 == 0.02 + 1e-12, "time after a 1e-12 s step is %.17g", t2);
    double x = NAN;
    fmi->GetReal(c, &vr_x, 1, &x);
    check(isfinite(x), "x after a tiny step is %g", x);
    check(fmi->DoStep(c, t2, 1.0, fmi2True) == fmi2OK, "a 1 s communication step was refused: %s", last_error);
    fmi->GetRealStatus(c, fmi2LastSuccessfulTime, &t2);
    check(fabs(t2 - 1.02) < 1e-9, "time after a 1 s step is %.17g", t2);
    fmi2Status status = fmi2Fatal;
    check(fmi->GetStatus(c, fmi2DoStepStatus, &status) == fmi2OK && status == fmi2OK, "fmi2DoStepStatus = %d",
          (int)status);
    fmi2Boolean terminated = 1;
    check(fmi->GetBooleanStatus(c, fmi2Terminated, &terminated) == fmi2OK && terminated == 0, "fmi2Terminated");
    fmi->Terminate(c);
    fmi->FreeInstance(c);

    /* solver.step below its declared minimum (1e-6 s) is refused by name; at the
     * minimum, a communication step needing more internal steps than the FMU
     * allows (1e7) is refused naming solver.step, not undefined behaviour */
    c = make("solverstep", resources_uri);
    reach(c, S_INIT);
    const unsigned vr_solver = fmu_var(&F, "solver.step")->vr;
    const fmi2Real tiny = 1e-300, smallest = 1e-6;
    log_clear();
    check(fmi->SetReal(c, &vr_solver, 1, &tiny) == fmi2Error && strstr(last_error, "solver.step"),
          "solver.step = 1e-300 is below its declared minimum: '%s'", last_error);
    check(fmi->SetReal(c, &vr_solver, 1, &smallest) == fmi2OK, "solver.step = 1e-6 is its declared minimum");
    fmi->ExitInitializationMode(c);
    log_clear();
    check(fmi->DoStep(c, 0.0, 1e3, 1) == fmi2Error && strstr(last_error, "solver.step"),
          "a step needing 1e9 internal steps: '%s'", last_error);
    check(fmi->DoStep(c, 0.0, 1e-3, 1) == fmi2OK, "a step of 1000 internal steps of 1e-6 s: %s", last_error);
    fmi->FreeInstance(c);

    /* a start time other than 0 */
    c = make("start", resources_uri);
    fmi->SetupExperiment(c, 0, 0, 100.0, 1, 200.0);
    fmi->EnterInitializationMode(c);
    fmi->ExitInitializationMode(c);
    check(fmi->DoStep(c, 0.0, 0.01, 1) == fmi2Error, "doStep at 0 after a start time of 100 s was accepted");
    check(fmi->DoStep(c, 100.0, 0.01, 1) == fmi2OK, "doStep at the start time 100 s");
    fmi->FreeInstance(c);
    c = make("badstart", resources_uri);
    check(fmi->SetupExperiment(c, 0, 0, NAN, 0, 0) == fmi2Error, "a NaN start time was accepted");
    check(fmi->SetupExperiment(c, 0, 0, 5.0, 1, 1.0) == fmi2Error, "a stop time before the start was accepted");
    fmi->FreeInstance(c);
}

/* A state that diverges: a huge drive torque on wheels of tiny inertia. */
static void test_divergence(void)
{
    fmi2Component c = make("diverge", resources_uri);
    reach(c, S_INIT);
    const fmi2Integer mode = 0;
    const fmi2Real inertia = 1e-6, torque = 1e6, zero = 0.0;
    fmi->SetInteger(c, &vr_mode, 1, &mode);
    check(fmi->SetReal(c, &vr_inertia, 1, &inertia) == fmi2OK, "wheel.inertia = 1e-6");
    fmi->SetReal(c, &vr_drawbar, 1, &zero);
    check(fmi->ExitInitializationMode(c) == fmi2OK, "initialisation with a tiny wheel inertia: %s", last_error);
    fmi->SetReal(c, &vr_tq_left, 1, &torque);
    fmi->SetReal(c, &vr_tq_right, 1, &torque);
    fmi2Status st = fmi2OK;
    double t = 0;
    int k;
    log_clear();
    for (k = 0; k < 100 && st == fmi2OK; ++k, t += 0.01) st = fmi->DoStep(c, t, 0.01, 1);
    check(st == fmi2Error, "a huge torque on a tiny wheel inertia did not fail within 1 s");
    check(strstr(last_error, "diverged") != NULL, "divergence not explained: %s", last_error);
    /* now in the Error state: values can be read, stepping is refused, reset recovers */
    double z = 0;
    check(fmi->GetReal(c, &vr_z, 1, &z) == fmi2OK, "GetReal after a failed step");
    fmi2Status status = fmi2OK;
    check(fmi->GetStatus(c, fmi2DoStepStatus, &status) == fmi2OK && status == fmi2Error,
          "fmi2DoStepStatus after a failed step is %d", (int)status);
    check(fmi->DoStep(c, t, 0.01, 1) == fmi2Error, "doStep after a failed step was accepted");
    check(fmi->Terminate(c) == fmi2Error, "fmi2Terminate in the Error state was accepted");
    check(fmi->Reset(c) == fmi2OK, "fmi2Reset after divergence");
    double y[256];
    check(reference_run(c, y) == 0, "a run after reset from divergence failed: %s", last_error);
    fmi->FreeInstance(c);
}

/* ------------------------------------------------------- resources */

static int write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    fputs(text, f);
    return fclose(f);
}

static const char *const raised_grid =
    "ncols 4\nnrows 4\nxllcenter -10\nyllcenter -10\ncellsize 10\n"
    "0.5 0.5 0.5 0.5\n0.5 0.5 0.5 0.5\n0.5 0.5 0.5 0.5\n0.5 0.5 0.5 0.5\n";

/* z after initialisation with terrain.file = file, or NAN if it failed */
static double initial_z(const char *uri, const char *file, char *err, size_t errlen)
{
    fmi2Component c = make("res", uri);
    if (!c) return NAN;
    reach(c, S_INIT);
    fmi->SetString(c, &vr_terrain, 1, &file);
    log_clear();
    double z = NAN;
    if (fmi->ExitInitializationMode(c) == fmi2OK) fmi->GetReal(c, &vr_z, 1, &z);
    snprintf(err, errlen, "%s", last_error);
    fmi->FreeInstance(c);
    return z;
}

/* A terrain file without read permission.  Root reads it anyway, so as
 * root the check runs in a child process that drops to uid/gid 65534. */
static void test_unreadable_terrain(void)
{
#if defined(_WIN32)
    check(1, "unreadable terrain file: not checked on Windows");
#else
    char path[4096], err[2048];
    snprintf(path, sizeof path, "%s/resources/locked.asc", scratch);
    if (write_text(path, raised_grid) != 0 || chmod(path, 0) != 0) {
        check(0, "cannot make %s", path);
        return;
    }
    if (geteuid() != 0) {
        double z = initial_z(NULL, path, err, sizeof err);
        check(isnan(z) && strstr(err, path) && strstr(err, "Permission denied"),
              "unreadable terrain file: z %g, message '%s'", z, err);
    } else {
        chmod(scratch, 0755);   /* let the unprivileged child reach the file */
        char res[4096];
        snprintf(res, sizeof res, "%s/resources", scratch);
        chmod(res, 0755);
        fflush(stdout);
        pid_t pid = fork();
        if (pid == 0) {
            if (setgid(65534) != 0 || setuid(65534) != 0) _exit(3);
            double z = initial_z(NULL, path, err, sizeof err);
            int ok = isnan(z) && strstr(err, path) && strstr(err, "Permission denied");
            if (!ok) printf("  child (uid 65534): z %g, message '%s'\n", z, err);
            fflush(stdout);
            _exit(ok ? 0 : 1);
        }
        int status = -1;
        if (pid > 0) waitpid(pid, &status, 0);
        check(pid > 0 && WIFEXITED(status) && WEXITSTATUS(status) != 3,
              "unreadable terrain file: could not drop privileges to check it as root");
        check(pid > 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0,
              "unreadable terrain file (checked as uid 65534) was not refused with 'Permission denied'");
    }
    chmod(path, 0600);
    remove(path);
#endif
}

/* terrain.file of instance c as fmi2GetString reads it: "(failed)" if the call fails */
static const char *terrain_file_read(fmi2Component c)
{
    fmi2String v = NULL;
    if (fmi->GetString(c, &vr_terrain, 1, &v) != fmi2OK || !v) return "(failed)";
    return v;
}

/* A relative terrain.file found in the resources folder reads back as the user set it, in
 * Initialization Mode once the initial values have been read, after initialisation, and after a
 * state was set and deserialised: what a host saves is the parameter, not this machine's
 * resources path.  The state still restores only on the same ground. */
static void test_terrain_file_reads_as_set(void)
{
    fmi2Component c = make("asset", resources_uri), d = make("asset2", resources_uri);
    const fmi2String file = "raised.asc";
    double z = NAN;
    if (!c || !d || reach(c, S_INIT) != 0 || reach(d, S_INIT) != 0) {
        check(0, "cannot bring two instances to Initialization Mode: %s", last_error);
        fmi->FreeInstance(c);
        fmi->FreeInstance(d);
        return;
    }
    fmi->SetString(c, &vr_terrain, 1, &file);
    fmi->SetString(d, &vr_terrain, 1, &file);
    check(fmi->GetReal(c, &vr_z, 1, &z) == fmi2OK && isfinite(z), "z in Initialization Mode: %s", last_error);
    check(strcmp(terrain_file_read(c), file) == 0,
          "terrain.file read in Initialization Mode after the initial values: '%s', set '%s'", terrain_file_read(c),
          file);
    check(fmi->ExitInitializationMode(c) == fmi2OK && fmi->ExitInitializationMode(d) == fmi2OK,
          "initialisation on the resources' grid: %s", last_error);
    check(strcmp(terrain_file_read(c), file) == 0, "terrain.file read after initialisation: '%s', set '%s'",
          terrain_file_read(c), file);
    fmi2FMUstate s = NULL;
    check(fmi->DoStep(c, 0.0, 0.01, fmi2True) == fmi2OK && fmi->GetFMUstate(c, &s) == fmi2OK,
          "a step and a state on the resources' grid: %s", last_error);
    check(fmi->SetFMUstate(d, s) == fmi2OK, "a state taken on the same grid is refused: %s", last_error);
    check(strcmp(terrain_file_read(d), file) == 0, "terrain.file read after fmi2SetFMUstate: '%s', set '%s'",
          terrain_file_read(d), file);
    size_t size = 0;
    unsigned char *buf = NULL;
    fmi2FMUstate back = NULL;
    if (fmi->SerializedFMUstateSize(c, s, &size) == fmi2OK) buf = (unsigned char *)malloc(size);
    check(buf && fmi->SerializeFMUstate(c, s, (fmi2Byte *)buf, size) == fmi2OK &&
              fmi->DeSerializeFMUstate(d, (const fmi2Byte *)buf, size, &back) == fmi2OK &&
              fmi->SetFMUstate(d, back) == fmi2OK,
          "a serialised state taken on the same grid is refused: %s", last_error);
    check(strcmp(terrain_file_read(d), file) == 0,
          "terrain.file read after a deserialised state: '%s', set '%s'", terrain_file_read(d), file);
    free(buf);
    fmi->FreeFMUstate(d, &back);
    fmi->FreeFMUstate(c, &s);
    fmi->FreeInstance(c);
    fmi->FreeInstance(d);
}

static void test_resources(void)
{
    char err[2048], path[4096], uri[4400];
    double z_flat = initial_z(resources_uri, "", err, sizeof err);
    check(isfinite(z_flat), "flat ground initialisation failed: %s", err);
    /* relative terrain file found in the resources folder whose URI has %20 */
    check(strstr(resources_uri, "%20") != NULL, "the resource URI has no %%20: %s", resources_uri);
    double z = initial_z(resources_uri, "raised.asc", err, sizeof err);
    check(isfinite(z) && fabs(z - z_flat - 0.5) < 1e-6, "terrain from resources (URI %s): z %g vs flat %g (%s)",
          resources_uri, z, z_flat, err);
    /* the same folder as file:/path and file://localhost/path */
    snprintf(path, sizeof path, "%s/resources", scratch);
    char enc[4096];
    path_to_uri(path, enc, sizeof enc);                  /* file:///... */
    snprintf(uri, sizeof uri, "file:%s", enc + 7);      /* file:/... */
    z = initial_z(uri, "raised.asc", err, sizeof err);
    check(fabs(z - z_flat - 0.5) < 1e-6, "resource URI of the form file:/path (%s): %s", uri, err);
    snprintf(uri, sizeof uri, "file://localhost%s", enc + 7);
    z = initial_z(uri, "raised.asc", err, sizeof err);
    check(fabs(z - z_flat - 0.5) < 1e-6, "resource URI of the form file://localhost/path (%s): %s", uri, err);
    /* the scheme is case-insensitive (RFC 3986, 3.1) */
    snprintf(uri, sizeof uri, "FILE:///%s", enc + 8);
    z = initial_z(uri, "raised.asc", err, sizeof err);
    check(fabs(z - z_flat - 0.5) < 1e-6, "resource URI with the scheme in capitals (%s): %s", uri, err);
    snprintf(uri, sizeof uri, "File:%s", enc + 7);
    z = initial_z(uri, "raised.asc", err, sizeof err);
    check(fabs(z - z_flat - 0.5) < 1e-6, "resource URI of the form File:/path (%s): %s", uri, err);
    /* an absolute path with spaces needs no resources */
    snprintf(path, sizeof path, "%s/resources/raised.asc", scratch);
    z = initial_z(NULL, path, err, sizeof err);
    check(fabs(z - z_flat - 0.5) < 1e-6, "absolute terrain path with spaces: %s", err);
    /* no resources folder: flat ground works, a relative terrain file is reported missing */
    snprintf(path, sizeof path, "%s/no resources here", scratch);
    path_to_uri(path, uri, sizeof uri);
    z = initial_z(uri, "", err, sizeof err);
    check(z == z_flat, "URI of a folder that does not exist, flat ground: %s", err);
    z = initial_z(uri, "raised.asc", err, sizeof err);
    check(isnan(z) && strstr(err, "raised.asc") != NULL,
          "relative terrain file without a resources folder: z %g, message '%s'", z, err);
    z = initial_z(NULL, "raised.asc", err, sizeof err);
    check(isnan(z) && strstr(err, "raised.asc") != NULL, "NULL resource location: message '%s'", err);
    z = initial_z("http://example.invalid/resources", "", err, sizeof err);
    check(z == z_flat, "a non-file resource URI with flat ground: %s", err);
    z = initial_z("", "", err, sizeof err);
    check(z == z_flat, "an empty resource URI: %s", err);
    z = initial_z("file:///%zz%2", "raised.asc", err, sizeof err);
    check(isnan(z), "a malformed percent escape in the resource URI");
    test_terrain_file_reads_as_set();
    test_unreadable_terrain();
}

/* ------------------------------------------------------------------ */

static void make_scratch(const char *base)
{
#if defined(_WIN32)
    /* Windows (also under wine): an absolute path with a drive letter */
    char full[1024];
    if (!_fullpath(full, base, sizeof full)) snprintf(full, sizeof full, "%s", base);
    snprintf(scratch, sizeof scratch, "%s\\juno conformance %d", full, (int)_getpid());
    if (_mkdir(scratch) != 0) {
        perror(scratch);
        exit(2);
    }
#else
    char cwd[1024] = "";
    if (base[0] != '/' && !getcwd(cwd, sizeof cwd)) cwd[0] = '\0';
    snprintf(scratch, sizeof scratch, "%s%s%s/juno conformance XXXXXX", cwd, cwd[0] ? "/" : "", base);
    if (!mkdtemp(scratch)) {
        perror("mkdtemp");
        exit(2);
    }
#endif
    char path[4096];
    snprintf(path, sizeof path, "%s/resources", scratch);
#if defined(_WIN32)
    _mkdir(path);
#else
    mkdir(path, 0755);
#endif
    path_to_uri(path, resources_uri, sizeof resources_uri);
    snprintf(path, sizeof path, "%s/resources/raised.asc", scratch);
    if (write_text(path, raised_grid) != 0) {
        perror(path);
        exit(2);
    }
}

static void remove_scratch(void)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/resources/raised.asc", scratch);
    remove(path);
    snprintf(path, sizeof path, "%s/resources", scratch);
#if defined(_WIN32)
    _rmdir(path);
    _rmdir(scratch);
#else
    rmdir(path);
    rmdir(scratch);
#endif
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s FMU_DIR [WORK_DIR]\n", argv[0]);
        return 2;
    }
    if (fmu_load(&F, argv[1]) != 0) return 2;
    fmi = &F.fmi;
    const char *base = argc > 2 ? argv[2] : getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp";
    make_scratch(base);

    vr_kh = fmu_var(&F, "soil.kh")->vr;
    vr_inertia = fmu_var(&F, "wheel.inertia")->vr;
    vr_mode = fmu_var(&F, "drive.mode")->vr;
    vr_terrain = fmu_var(&F, "terrain.file")->vr;
    vr_drawbar = fmu_var(&F, "drawbarForce")->vr;
    vr_tq_left = fmu_var(&F, "torqueLeft")->vr;
    vr_tq_right = fmu_var(&F, "torqueRight")->vr;
    vr_x = fmu_var(&F, "x")->vr;
    vr_z = fmu_var(&F, "z")->vr;
    for (int i = 0; i < F.nvars && n_out < 256; ++i)
        if (F.vars[i].causality == 'o' && F.vars[i].type == 'r') out_vrs[n_out++] = F.vars[i].vr;
    check(n_out >= 10, "the model description lists %zu Real outputs", n_out);

    struct {
        const char *name;
        void (*run)(void);
    } groups[] = {{"instantiation", test_instantiate},
                  {"state table", test_state_table},
                  {"reset and free from every state", test_reset_and_free},
                  {"NULL arguments", test_null_arguments},
                  {"log categories", test_log_categories},
                  {"serialization", test_serialization},
                  {"communication steps", test_steps},
                  {"divergence", test_divergence},
                  {"resources", test_resources}};
    for (size_t g = 0; g < sizeof groups / sizeof groups[0]; ++g) {
        int p0 = passed, f0 = failed;
        groups[g].run();
        printf("%-34s %4d passed, %d failed\n", groups[g].name, passed - p0, failed - f0);
    }
    remove_scratch();
    fmu_unload(&F);
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
