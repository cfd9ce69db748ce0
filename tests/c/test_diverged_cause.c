/*
 * A wheel sunk deeper than its radius stops the step with the likely
 * cause, and the cause named is the one that holds:
 *   - on flat ground tilted at 0.55 along x (28.8 deg, just under the soil's
 *     friction angle soil.phi = 30 deg), driven at the defaults (45 %
 *     throttle, 400 N drawbar), the rover slides down, pitches up and
 *     flips over backwards; a front wheel then lands from above and ends
 *     deeper than its radius.  The message says the rover overturned, end
 *     over end, and does not blame the soil (whose stiffness has nothing
 *     to do with it) nor the slope (which the soil can hold);
 *   - an upright rover whose weight the soil cannot carry (the gravity
 *     raised to 100 m/s2 after the static equilibrium on level ground)
 *     sinks straight in; there the soil too soft for the load is the
 *     cause, and the message says so.
 * The tumble at the automatic step (the default; at the fixed 1 ms step the
 * same rover lands on its upturned wheels without sinking past their radius,
 * and no check stops it), the sinking at both.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "model.h"
#include "rover_internal.h"

#define COMM_STEP 0.01          /* s */
#define MAX_STEPS 3000          /* 30 s: the tilted run fails within 10 s */

/* A rover at its defaults, the inputs of the drawbar benchmark, on flat
 * ground tilted by slope_x, at the automatic step (fixed_step 0) or at
 * that fixed step; initialised. */
static Model *new_rover(double slope_x, double fixed_step)
{
    char err[768];
    Model *m = (Model *)calloc(1, sizeof *m);
    if (!m) exit(2);
    model_set_defaults(m);
    terrain_init_flat(&m->terrain);
    m->p.terrain_slopeX = slope_x;
    if (fixed_step > 0) m->p.solver_tolerance = 0.0, m->p.solver_step = fixed_step;
    m->in.drawbarForce = 400.0;
    m->in.throttleLeft = m->in.throttleRight = 0.45;
    if (model_initialize(m, err, sizeof err) != 0) {
        printf("model_initialize (slope %g): %s\n", slope_x, err);
        exit(2);
    }
    return m;
}

/* Steps m until a step fails (its message into err, returns 1) or
 * MAX_STEPS have passed (returns 0). */
static int run_until_failure(Model *m, char *err, size_t n)
{
    for (int k = 0; k < MAX_STEPS; ++k)
        if (model_do_step(m, COMM_STEP, err, n) != 0) return 1;
    return 0;
}

static void free_rover(Model *m)
{
    model_free(m);
    free(m);
}

static void test_a_rover_flipping_over_is_said_to_have_overturned(void)
{
    char err[768] = "";
    Model *m = new_rover(0.55, 0.0);
    const int failed = run_until_failure(m, err, sizeof err);
    const char *step = "automatic step";
    CHECK(failed && strstr(err, "deeper than its radius") != NULL,
          "%s: on a 0.55 tilt the rover ends with a wheel deeper than its radius: \"%s\"", step, err);
    CHECK(strstr(err, "overturned") != NULL && strstr(err, "end over end") != NULL,
          "%s: the message says the rover overturned end over end: \"%s\"", step, err);
    CHECK(strstr(err, "too soft") == NULL && strstr(err, "soil.kh") == NULL && strstr(err, "friction angle") == NULL,
          "%s: and blames neither the soil's stiffness nor a slope steeper than soil.phi", step);
    free_rover(m);
}

static void test_an_upright_rover_sinking_under_its_load_blames_the_soil(double fixed_step)
{
    char err[768] = "";
    Model *m = new_rover(0.0, fixed_step);
    m->p.env_gravity = 100.0;           /* about 10 times the load the static equilibrium carried */
    model_changed(m);
    const int failed = run_until_failure(m, err, sizeof err);
    const char *step = fixed_step > 0 ? "fixed 1 ms step" : "automatic step";
    CHECK(failed && strstr(err, "deeper than its radius") != NULL && strstr(err, "too soft") != NULL,
          "%s: under ten times its load the upright rover sinks in, the soil too soft for it: \"%s\"", step, err);
    CHECK(strstr(err, "overturned") == NULL, "%s: and it is not said to have overturned", step);
    free_rover(m);
}

int main(void)
{
    test_a_rover_flipping_over_is_said_to_have_overturned();
    test_an_upright_rover_sinking_under_its_load_blames_the_soil(0.0);
    test_an_upright_rover_sinking_under_its_load_blames_the_soil(1e-3);
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
