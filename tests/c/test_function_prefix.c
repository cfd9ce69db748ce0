/*
 * The FMU's sources compiled with FMI2_FUNCTION_PREFIX, as an importer that links several source
 * FMUs into one program does: every FMI function carries the prefix, and the prefixed FMU runs.
 */
#ifndef FMI2_FUNCTION_PREFIX
#error "built with FMI2_FUNCTION_PREFIX=JunoRover_ (CMakeLists.txt), as fmi2_cs.c beside it"
#endif
#include <stdarg.h>
#include <stdio.h>

#include "check.h"
#include "fmi2.h"
#include "juno_guid.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    (void)name;
    (void)status;
    (void)category;
    (void)message;
}

int main(void)
{
    const fmi2CallbackFunctions callbacks = {logger, NULL, NULL, NULL, NULL};
    CHECK(JunoRover_fmi2GetVersion()[0] == '2', "JunoRover_fmi2GetVersion answers");
    fmi2Component c = JunoRover_fmi2Instantiate("prefixed", fmi2CoSimulation, JUNO_GUID, NULL, &callbacks,
                                                fmi2False, fmi2False);
    CHECK(c != NULL, "JunoRover_fmi2Instantiate makes an instance");
    if (c == NULL) return 1;
    CHECK(JunoRover_fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK, "set up");
    CHECK(JunoRover_fmi2EnterInitializationMode(c) == fmi2OK, "enter initialisation");
    CHECK(JunoRover_fmi2ExitInitializationMode(c) == fmi2OK, "exit initialisation (static equilibrium)");
    CHECK(JunoRover_fmi2DoStep(c, 0.0, 0.01, fmi2True) == fmi2OK, "one step");
    JunoRover_fmi2FreeInstance(c);
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
