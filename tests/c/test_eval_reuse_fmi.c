/*
 * The FMI calls that change what the kept end-of-step evaluation was computed from make the next
 * step evaluate afresh (rover_step.c, "reusing an evaluation"): an instance taken through them
 * ends in the same FMU state, bit for bit, as one that never kept an evaluation across them:
 *   - fmi2SetFMUstate back to an earlier state (the kept evaluation is of a later one);
 *   - the same state through fmi2SerializeFMUstate and fmi2DeSerializeFMUstate;
 *   - fmi2SetFMUstate of another instance's state, whose parameters differ (env.gravity): the
 *     only way an FMU's parameters change after initialisation;
 *   - fmi2Reset and a new initialisation with another parameter.
 * The inputs change before every step (fmi2SetReal), and keep the evaluation: it reads none.
 * Built with the FMI layer and FMI2_FUNCTION_PREFIX=JunoRover_ (CMakeLists.txt).
 */
#ifndef FMI2_FUNCTION_PREFIX
#error "built with FMI2_FUNCTION_PREFIX=JunoRover_ (CMakeLists.txt), as fmi2_cs.c beside it"
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fmi2.h"
#include "juno_guid.h"

enum { VR_GRAVITY = 139, VR_THROTTLE_LEFT = 205, VR_THROTTLE_RIGHT = 206 };
#define H_COMM 0.01

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env, (void)name, (void)category;
    if (status != fmi2OK) printf("  FMU: %s\n", message);
}

static const fmi2CallbackFunctions callbacks = {logger, NULL, NULL, NULL, NULL};

static void must(fmi2Status status, const char *what)
{
    if (status != fmi2OK) {
        printf("%s failed\n", what);
        exit(2);
    }
}

/* An initialised instance; gravity > 0 sets env.gravity (m/s2) before initialisation. */
static fmi2Component new_instance(double gravity)
{
    fmi2Component c = JunoRover_fmi2Instantiate("reuse", fmi2CoSimulation, JUNO_GUID, NULL, &callbacks,
                                                fmi2False, fmi2False);
    if (!c) exit(2);
    must(JunoRover_fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0), "fmi2SetupExperiment");
    must(JunoRover_fmi2EnterInitializationMode(c), "fmi2EnterInitializationMode");
    if (gravity > 0) {
        const fmi2ValueReference vr = VR_GRAVITY;
        must(JunoRover_fmi2SetReal(c, &vr, 1, &gravity), "fmi2SetReal env.gravity");
    }
    must(JunoRover_fmi2ExitInitializationMode(c), "fmi2ExitInitializationMode");
    return c;
}

/* Steps k0 .. k1 - 1 of H_COMM from time k0 H_COMM, the throttles changing before every step. */
static void run(fmi2Component c, int k0, int k1)
{
    const fmi2ValueReference vr[2] = {VR_THROTTLE_LEFT, VR_THROTTLE_RIGHT};
    for (int k = k0; k < k1; ++k) {
        const fmi2Real throttle[2] = {0.2 + 0.1 * (k % 5), 0.7 - 0.1 * (k % 3)};
        must(JunoRover_fmi2SetReal(c, vr, 2, throttle), "fmi2SetReal throttles");
        must(JunoRover_fmi2DoStep(c, k * H_COMM, H_COMM, fmi2True), "fmi2DoStep");
    }
}

/* The instance's FMU state as bytes (malloc'ed; *n its size). */
static fmi2Byte *state_bytes(fmi2Component c, size_t *n)
{
    fmi2FMUstate s = NULL;
    must(JunoRover_fmi2GetFMUstate(c, &s), "fmi2GetFMUstate");
    must(JunoRover_fmi2SerializedFMUstateSize(c, s, n), "fmi2SerializedFMUstateSize");
    fmi2Byte *bytes = (fmi2Byte *)malloc(*n);
    if (!bytes) exit(2);
    must(JunoRover_fmi2SerializeFMUstate(c, s, bytes, *n), "fmi2SerializeFMUstate");
    must(JunoRover_fmi2FreeFMUstate(c, &s), "fmi2FreeFMUstate");
    return bytes;
}

static int same_state(fmi2Component a, fmi2Component b)
{
    size_t na, nb;
    fmi2Byte *sa = state_bytes(a, &na), *sb = state_bytes(b, &nb);
    const int same = na == nb && memcmp(sa, sb, na) == 0;
    free(sa), free(sb);
    return same;
}

static void test_state_set_back(void)
{
    fmi2Component a = new_instance(0), ref = new_instance(0);
    fmi2FMUstate early = NULL;
    run(a, 0, 20);
    must(JunoRover_fmi2GetFMUstate(a, &early), "fmi2GetFMUstate");
    run(a, 20, 40);
    must(JunoRover_fmi2SetFMUstate(a, early), "fmi2SetFMUstate");
    run(a, 20, 40);
    run(ref, 0, 40);
    CHECK(same_state(a, ref), "set back 20 steps with fmi2SetFMUstate: the same state after 20 more, bit for bit");

    size_t n;
    fmi2FMUstate copy = NULL;
    must(JunoRover_fmi2SerializedFMUstateSize(a, early, &n), "fmi2SerializedFMUstateSize");
    fmi2Byte *bytes = (fmi2Byte *)malloc(n);
    if (!bytes) exit(2);
    must(JunoRover_fmi2SerializeFMUstate(a, early, bytes, n), "fmi2SerializeFMUstate");
    must(JunoRover_fmi2DeSerializeFMUstate(a, bytes, n, &copy), "fmi2DeSerializeFMUstate");
    must(JunoRover_fmi2SetFMUstate(a, copy), "fmi2SetFMUstate (deserialised)");
    run(a, 20, 40);
    CHECK(same_state(a, ref), "and through fmi2SerializeFMUstate and fmi2DeSerializeFMUstate, bit for bit");
    free(bytes);
    must(JunoRover_fmi2FreeFMUstate(a, &copy), "fmi2FreeFMUstate");
    must(JunoRover_fmi2FreeFMUstate(a, &early), "fmi2FreeFMUstate");
    JunoRover_fmi2FreeInstance(a), JunoRover_fmi2FreeInstance(ref);
}

static void test_parameters_changed(void)
{
    fmi2Component a = new_instance(0), other = new_instance(9.0), ref = new_instance(9.0);
    fmi2FMUstate s = NULL;
    run(a, 0, 20);
    run(other, 0, 20);
    run(ref, 0, 40);
    CHECK(!same_state(a, other), "env.gravity 9 m/s2 makes another state than the default's");
    must(JunoRover_fmi2GetFMUstate(other, &s), "fmi2GetFMUstate");
    must(JunoRover_fmi2SetFMUstate(a, s), "fmi2SetFMUstate");
    run(a, 20, 40);
    CHECK(same_state(a, ref), "another instance's state with another env.gravity set: the same state as that "
          "instance's own after 20 steps, bit for bit");
    must(JunoRover_fmi2FreeFMUstate(a, &s), "fmi2FreeFMUstate");

    must(JunoRover_fmi2Reset(a), "fmi2Reset");
    must(JunoRover_fmi2SetupExperiment(a, fmi2False, 0.0, 0.0, fmi2False, 0.0), "fmi2SetupExperiment");
    must(JunoRover_fmi2EnterInitializationMode(a), "fmi2EnterInitializationMode");
    const fmi2ValueReference vr = VR_GRAVITY;
    const fmi2Real g = 9.0;
    must(JunoRover_fmi2SetReal(a, &vr, 1, &g), "fmi2SetReal env.gravity");
    must(JunoRover_fmi2ExitInitializationMode(a), "fmi2ExitInitializationMode");
    run(a, 0, 40);
    CHECK(same_state(a, ref), "fmi2Reset and initialised again with env.gravity 9 m/s2: the same state as an "
          "instance made so, bit for bit");
    JunoRover_fmi2FreeInstance(a), JunoRover_fmi2FreeInstance(other), JunoRover_fmi2FreeInstance(ref);
}

int main(void)
{
    test_state_set_back();
    test_parameters_changed();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
