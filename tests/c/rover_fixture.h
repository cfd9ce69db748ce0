/* What the rover's C unit tests share to make a model: a rover at the
 * FMU's defaults on flat ground, for the test to set its parameters on,
 * then initialised (a test whose set-up fails stops with exit status 2, not
 * a FAIL: nothing it checks has run). */
#ifndef JUNO_TEST_ROVER_FIXTURE_H
#define JUNO_TEST_ROVER_FIXTURE_H

#include <stdio.h>
#include <stdlib.h>

#include "model.h"

/* A rover at its defaults on flat ground, not yet initialised. */
static Model *rover_at_defaults(void)
{
    Model *m = (Model *)calloc(1, sizeof *m);
    if (!m) exit(2);
    model_set_defaults(m);
    terrain_init_flat(&m->terrain);
    return m;
}

/* Initialises m; on failure prints what (the test's set-up) with the
 * model's message and exits with status 2. */
static Model *initialised(Model *m, const char *what)
{
    char err[768];
    if (model_initialize(m, err, sizeof err) != 0) {
        printf("model_initialize (%s): %s\n", what, err);
        exit(2);
    }
    return m;
}

#endif
