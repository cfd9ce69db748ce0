/*
 * The WheelRig FMU's FMI layer (fmu_src/fmi2_cs.c compiled with the rig's model and
 * FMI2_FUNCTION_PREFIX=WheelRig_, as an importer linking several source FMUs does), called as a
 * host calls it:
 *   - every FMI function carries the prefix, and a wrong GUID is refused;
 *   - the state machine: a step before initialisation and a parameter set after it are refused,
 *     an input may change between steps, a value outside its range is refused and not stored;
 *   - a state taken mid-run, serialised and deserialised into a second instance, continues bit
 *     for bit as the original; corrupted or truncated bytes are refused;
 *   - fmi2Reset returns to the start values.
 * Run under the sanitizers and valgrind by scripts/checks.sh with the other ctest programs.
 */
#ifndef FMI2_FUNCTION_PREFIX
#error "built with FMI2_FUNCTION_PREFIX=WheelRig_ (CMakeLists.txt), as fmi2_cs.c beside it"
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmi2.h"
#include "juno_guid.h"

/* The rig's value references (modelDescription/wheel_rig_variables.h). */
enum { VR_LOAD = 700, VR_SLIP = 710, VR_SLIP_ANGLE = 713, VR_DRAWBAR = 800, VR_VERTICAL = 801, VR_TORQUE = 802,
       VR_LATERAL = 803, VR_SINKAGE = 804 };

typedef struct {
    int errors;
    char last[512];
} Log;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)name;
    (void)category;
    Log *log = (Log *)env;
    if (!log || status < fmi2Error) return;
    va_list ap;
    va_start(ap, message);
    vsnprintf(log->last, sizeof log->last, message, ap);
    va_end(ap);
    log->errors++;
}

static fmi2Component instantiate(const char *name, const char *guid, Log *log, fmi2CallbackFunctions *cb)
{
    const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, log};
    memcpy(cb, &callbacks, sizeof callbacks);
    return WheelRig_fmi2Instantiate(name, fmi2CoSimulation, guid, NULL, cb, fmi2False, fmi2False);
}

static int initialise(fmi2Component c, double load)
{
    const fmi2ValueReference vr = VR_LOAD;
    return WheelRig_fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK &&
           WheelRig_fmi2EnterInitializationMode(c) == fmi2OK && WheelRig_fmi2SetReal(c, &vr, 1, &load) == fmi2OK &&
           WheelRig_fmi2ExitInitializationMode(c) == fmi2OK;
}

/* n steps of h from t0 with a slip and slip angle that change every step; the outputs after
 * each step into out (n x 5), if out. */
static int run(fmi2Component c, double t0, int n, double h, double *out)
{
    const fmi2ValueReference in[2] = {VR_SLIP, VR_SLIP_ANGLE};
    const fmi2ValueReference outs[5] = {VR_DRAWBAR, VR_VERTICAL, VR_TORQUE, VR_LATERAL, VR_SINKAGE};
    for (int k = 0; k < n; ++k) {
        const double t = t0 + k * h;
        const fmi2Real u[2] = {0.1 + 0.05 * (double)(k % 5), 0.02 * (double)(k % 3) - 0.02};
        if (WheelRig_fmi2SetReal(c, in, 2, u) != fmi2OK || WheelRig_fmi2DoStep(c, t, h, fmi2False) != fmi2OK)
            return 0;
        if (out && WheelRig_fmi2GetReal(c, outs, 5, out + 5 * k) != fmi2OK) return 0;
    }
    return 1;
}

int main(void)
{
    Log log_a = {0, ""}, log_b = {0, ""}, log_x = {0, ""};
    fmi2CallbackFunctions cb_a, cb_b, cb_x;
    const double h = 0.05;

    fmi2Component wrong = instantiate("wrong", "{00000000-0000-0000-0000-000000000000}", &log_x, &cb_x);
    CHECK(wrong == NULL && log_x.errors == 1, "a wrong GUID is refused: \"%s\"", log_x.last);

    fmi2Component a = instantiate("A", JUNO_GUID, &log_a, &cb_a);
    fmi2Component b = instantiate("B", JUNO_GUID, &log_b, &cb_b);
    CHECK(a != NULL && b != NULL, "WheelRig_fmi2Instantiate makes two instances");
    if (!a || !b) return 1;

    CHECK(WheelRig_fmi2DoStep(a, 0.0, h, fmi2False) == fmi2Error && strstr(log_a.last, "Instantiated"),
          "a step before initialisation is refused: \"%s\"", log_a.last);
    const fmi2ValueReference vr_load = VR_LOAD;
    const fmi2Real too_light = 0.5;
    CHECK(WheelRig_fmi2SetReal(a, &vr_load, 1, &too_light) == fmi2Error && strstr(log_a.last, "rig.load") &&
              strstr(log_a.last, "range"),
          "rig.load below its range is refused, naming it: \"%s\"", log_a.last);
    CHECK(initialise(a, 600.0) && initialise(b, 600.0), "both initialise at rig.load = 600 N");
    fmi2Real load = 0, vertical = 0;
    const fmi2ValueReference vr_vertical = VR_VERTICAL;
    WheelRig_fmi2GetReal(a, &vr_load, 1, &load);
    WheelRig_fmi2GetReal(a, &vr_vertical, 1, &vertical);
    CHECK(load == 600.0 && fabs(vertical - 600.0) < 1e-6, "the out-of-range value was not stored; the wheel carries "
          "rig.load = %g N at the start: %.9g N", load, vertical);
    const fmi2Real heavier = 700.0;
    CHECK(WheelRig_fmi2SetReal(a, &vr_load, 1, &heavier) == fmi2Error && strstr(log_a.last, "cannot be set"),
          "a parameter cannot change after initialisation: \"%s\"", log_a.last);

    /* the state round trip, through bytes, into the second instance */
    double first[5 * 40], again[5 * 40];
    int ok = run(a, 0.0, 40, h, NULL);
    fmi2FMUstate state = NULL, restored = NULL;
    size_t size = 0;
    ok = ok && WheelRig_fmi2GetFMUstate(a, &state) == fmi2OK && WheelRig_fmi2SerializedFMUstateSize(a, state, &size) == fmi2OK;
    char *bytes = ok ? (char *)malloc(size) : NULL;
    ok = ok && bytes && WheelRig_fmi2SerializeFMUstate(a, state, bytes, size) == fmi2OK;
    ok = ok && run(a, 40 * h, 40, h, first);
    ok = ok && run(b, 0.0, 7, h, NULL);   /* b elsewhere first */
    ok = ok && WheelRig_fmi2DeSerializeFMUstate(b, bytes, size, &restored) == fmi2OK &&
         WheelRig_fmi2SetFMUstate(b, restored) == fmi2OK && run(b, 40 * h, 40, h, again);
    CHECK(ok && memcmp(first, again, sizeof first) == 0,
          "a serialised state continues bit for bit in a second instance (%zu bytes)", size);
    if (bytes) {
        fmi2FMUstate bad = NULL;
        bytes[size / 2] ^= 0x55;
        CHECK(WheelRig_fmi2DeSerializeFMUstate(b, bytes, size, &bad) == fmi2Error && strstr(log_b.last, "checksum"),
              "corrupted bytes are refused: \"%s\"", log_b.last);
        CHECK(WheelRig_fmi2DeSerializeFMUstate(b, bytes, size - 8, &bad) == fmi2Error && bad == NULL,
              "truncated bytes are refused: \"%s\"", log_b.last);
    }
    free(bytes);
    WheelRig_fmi2FreeFMUstate(a, &state);
    WheelRig_fmi2FreeFMUstate(b, &restored);

    CHECK(WheelRig_fmi2Reset(a) == fmi2OK && WheelRig_fmi2GetReal(a, &vr_load, 1, &load) == fmi2Error,
          "fmi2Reset returns to Instantiated, where outputs cannot be read yet");
    CHECK(initialise(a, 779.0) && WheelRig_fmi2GetReal(a, &vr_vertical, 1, &vertical) == fmi2OK &&
              fabs(vertical - 779.0) < 1e-6,
          "and the instance initialises again at another load: %.9g N", vertical);
    CHECK(WheelRig_fmi2Terminate(a) == fmi2OK && WheelRig_fmi2DoStep(a, 0.0, h, fmi2False) == fmi2Error,
          "after fmi2Terminate a step is refused");
    WheelRig_fmi2FreeInstance(a);
    WheelRig_fmi2FreeInstance(b);
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
