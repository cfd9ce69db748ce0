/*
 * A rover that has overturned, or a wheel sunk deeper than its radius,
 * stops the step with the likely cause, and the cause named is the one
 * that holds:
 *   - on flat ground tilted at 0.55 along x (28.8 deg, just under the soil's
 *     friction angle soil.phi = 30 deg), driven at the defaults (45 %
 *     throttle, 400 N drawbar), the rover slides down, pitches up and
 *     flips over backwards.  As its up axis passes 90 deg from the ground's
 *     normal (the automatic step: the internal step that crosses it, taken
 *     again shorter down to its smallest; the fixed step: the next
 *     communication point) the step fails, at both step settings alike:
 *     the message says the rover overturned, end over end, on terrain too
 *     steep for the drive, names the step setting, and does not blame the
 *     soil's stiffness (which has nothing to do with it) nor a slope
 *     steeper than soil.phi (the soil can hold this one);
 *   - on level ground, a soil about six times stiffer than the default
 *     (soil.kh = 1e6), a full throttle and a 2000 N drawbar, at a fixed
 *     internal step of 0.1 s (communication steps of 0.1 s) the rover
 *     pitches up and overturns within 5 s, while at the automatic step (of at most the
 *     same 0.1 s) it runs its whole 30 s: the step is the cause, and the
 *     message names it (solver.step = 0.1 s) and does not call the level
 *     ground too steep;
 *   - on the tilt of 0.3 the registration allows, the same rover stays
 *     upright and runs its whole 30 s at both step settings;
 *   - an upright rover whose weight the soil cannot carry (the gravity
 *     raised to 100 m/s2 after the static equilibrium on level ground)
 *     sinks straight in; there the soil too soft for the load is the
 *     cause, and the message says so.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "model.h"
#include "rover_fixture.h"
#include "rover_internal.h"

#define COMM_STEP 0.01          /* s */
#define MAX_STEPS 3000          /* 30 s: the tilted run fails within 10 s */
#define FIXED_STEP 1e-3         /* s */

/* A rover at its defaults, the inputs of the drawbar benchmark, on flat
 * ground tilted by slope_x, at the automatic step (fixed_step 0) or at
 * that fixed step; initialised. */
static Model *new_rover(double slope_x, double fixed_step)
{
    Model *m = rover_at_defaults();
    m->p.terrain_slopeX = slope_x;
    if (fixed_step > 0) m->p.solver_tolerance = 0.0, m->p.solver_step = fixed_step;
    m->in.drawbarForce = 400.0;
    m->in.throttleLeft = m->in.throttleRight = 0.45;
    return initialised(m, "the tilted rover");
}

/* Steps m in communication steps of comm_step until a step fails (its
 * message into err, returns 1) or MAX_STEPS * COMM_STEP (30 s) have passed
 * (returns 0). */
static int run_until_failure_at(Model *m, double comm_step, char *err, size_t n)
{
    const int steps = (int)lround(MAX_STEPS * COMM_STEP / comm_step);
    for (int k = 0; k < steps; ++k)
        if (model_do_step(m, comm_step, err, n) != 0) return 1;
    return 0;
}

static int run_until_failure(Model *m, char *err, size_t n)
{
    return run_until_failure_at(m, COMM_STEP, err, n);
}

static void free_rover(Model *m)
{
    model_free(m);
    free(m);
}

static const char *step_name(double fixed_step)
{
    return fixed_step > 0 ? "fixed 1 ms step" : "automatic step";
}

/* The angle (deg) a message gives between the up axis and the ground's
 * normal, or -1 if it gives none. */
static double overturn_angle(const char *err)
{
    const char *at = strstr(err, "its up axis is ");
    double deg;
    if (!at || sscanf(at, "its up axis is %lf deg", &deg) != 1) return -1.0;
    return deg;
}

static void test_a_rover_flipping_over_is_stopped_as_overturned(double fixed_step)
{
    char err[768] = "";
    Model *m = new_rover(0.55, fixed_step);
    const int failed = run_until_failure(m, err, sizeof err);
    const char *step = step_name(fixed_step);
    const double deg = overturn_angle(err);
    CHECK(failed && strstr(err, "state diverged at t = ") != NULL && strstr(err, "overturned") != NULL,
          "%s: on a 0.55 tilt the rover's run stops, the rover overturned: \"%s\"", step, err);
    CHECK(strstr(err, "end over end") != NULL, "%s: the message says it turned end over end: \"%s\"", step, err);
    /* caught as it passes 90 deg (the automatic step at the internal step that crosses it, the fixed
     * step at the next communication point, 10 ms of a flip's few rad/s later), not once it has come
     * to rest upside down (180 deg) */
    CHECK(deg >= 90.0 && deg < 135.0, "%s: it is stopped just past 90 deg (%.0f deg)", step, deg);
    CHECK(strstr(err, "too soft") == NULL && strstr(err, "soil.kh") == NULL && strstr(err, "friction angle") == NULL,
          "%s: and blames neither the soil's stiffness nor a slope steeper than soil.phi", step);
    CHECK(strstr(err, "slopes up to 28.8 deg") != NULL &&
              strstr(err, "terrain too steep or rough for the drive") != NULL,
          "%s: it blames the terrain, naming its slope: \"%s\"", step, err);
    CHECK(strstr(err, fixed_step > 0 ? "internal step is fixed, solver.step = 0.001 s" : "internal step is automatic")
              != NULL, "%s: and names the step setting: \"%s\"", step, err);
    free_rover(m);
}

#define COARSE_STEP 0.1         /* s: the largest solver.step, and the communication step with it */

/* A rover on level ground, on a soil about six times stiffer than the default,
 * at full throttle against a 2000 N drawbar, at the automatic step (of at
 * most COARSE_STEP) or the fixed COARSE_STEP; initialised. */
static Model *new_rover_on_stiff_level_soil(int fixed)
{
    Model *m = rover_at_defaults();
    m->p.soil_kh = 1e6;
    m->p.solver_step = COARSE_STEP;
    if (fixed) m->p.solver_tolerance = 0.0;
    m->in.drawbarForce = 2000.0;
    m->in.throttleLeft = m->in.throttleRight = 1.0;
    return initialised(m, "the rover on stiff level soil");
}

static void test_a_rover_overturned_by_a_coarse_fixed_step_on_level_ground_blames_the_step(void)
{
    char err[768] = "";
    Model *m = new_rover_on_stiff_level_soil(0);
    const int failed_automatic = run_until_failure_at(m, COARSE_STEP, err, sizeof err);
    CHECK(!failed_automatic,
          "automatic step: on stiff level soil the rover runs its whole 30 s (stopped at t = %.2f s: \"%s\")",
          m->s.time, err);
    free_rover(m);

    err[0] = '\0';
    m = new_rover_on_stiff_level_soil(1);
    const int failed = run_until_failure_at(m, COARSE_STEP, err, sizeof err);
    CHECK(failed && strstr(err, "overturned") != NULL && m->s.time < 5.0 + 1e-9,
          "fixed 0.1 s step: the same rover overturns within 5 s (t = %.2f s): \"%s\"", m->s.time, err);
    CHECK(strstr(err, "slopes at most 0.0 deg") != NULL && strstr(err, "not the terrain") != NULL &&
              strstr(err, "too steep") == NULL,
          "fixed 0.1 s step: the message says the level ground is not the cause: \"%s\"", err);
    CHECK(strstr(err, "internal step is fixed, solver.step = 0.1 s") != NULL &&
              strstr(err, "fixed step too coarse for the soil's stiffness") != NULL,
          "fixed 0.1 s step: and names the step setting as a cause: \"%s\"", err);
    free_rover(m);
}

static void test_an_upright_rover_on_the_steepest_allowed_tilt_runs_its_whole_time(double fixed_step)
{
    char err[768] = "";
    Model *m = new_rover(0.3, fixed_step);
    const int failed = run_until_failure(m, err, sizeof err);
    const char *step = step_name(fixed_step);
    CHECK(!failed && fabs(m->s.time - MAX_STEPS * COMM_STEP) < 1e-9,
          "%s: on a 0.3 tilt the rover runs its whole %.0f s (stopped at t = %.2f s: \"%s\")", step,
          MAX_STEPS * COMM_STEP, m->s.time, err);
    free_rover(m);
}

static void test_an_upright_rover_sinking_under_its_load_blames_the_soil(double fixed_step)
{
    char err[768] = "";
    Model *m = new_rover(0.0, fixed_step);
    m->p.env_gravity = 100.0;           /* about 10 times the load the static equilibrium carried */
    model_changed(m);
    const int failed = run_until_failure(m, err, sizeof err);
    const char *step = step_name(fixed_step);
    CHECK(failed && strstr(err, "deeper than its radius") != NULL && strstr(err, "too soft") != NULL,
          "%s: under ten times its load the upright rover sinks in, the soil too soft for it: \"%s\"", step, err);
    CHECK(strstr(err, "overturned") == NULL, "%s: and it is not said to have overturned", step);
    free_rover(m);
}

int main(void)
{
    test_a_rover_flipping_over_is_stopped_as_overturned(0.0);
    test_a_rover_flipping_over_is_stopped_as_overturned(FIXED_STEP);
    test_a_rover_overturned_by_a_coarse_fixed_step_on_level_ground_blames_the_step();
    test_an_upright_rover_on_the_steepest_allowed_tilt_runs_its_whole_time(0.0);
    test_an_upright_rover_on_the_steepest_allowed_tilt_runs_its_whole_time(FIXED_STEP);
    test_an_upright_rover_sinking_under_its_load_blames_the_soil(0.0);
    test_an_upright_rover_sinking_under_its_load_blames_the_soil(FIXED_STEP);
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
