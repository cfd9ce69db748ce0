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
 *   - what the message blames follows from the ground under the wheels
 *     and the step setting alone, so it is specified directly: a rover
 *     evaluated at rest, its attitude turned upside down (180 deg end over
 *     end, or rolled 120 deg sideways), is not upright, and on level ground
 *     the message says the ground slopes at most 0.0 deg, that it is not the
 *     terrain, and names the step setting (solver.step at a fixed step,
 *     solver.tolerance at the automatic one); on the 0.55 tilt it blames the
 *     terrain as too steep; the line between them lies at tan slope =
 *     tan soil.phi / 2 (0.289 at the default 30 deg), so a 0.25 tilt blames
 *     the step setting and a 0.3 tilt the terrain.  Whether an integration
 *     overturns a rover on level ground is chaotic in its parameters (a few
 *     pairs of soil stiffness and drawbar do, their neighbours do not), so
 *     no run specifies this message: the check of the attitude does;
 *   - on the tilt of 0.3 the registration allows, the same rover stays
 *     upright and runs its whole 30 s at both step settings;
 *   - an upright rover whose weight the soil cannot carry (the gravity
 *     raised to 100 m/s2 after the static equilibrium on level ground)
 *     sinks straight in; there the soil too soft for the load is the
 *     cause, and the message says so;
 *   - a wheel sunk past its radius under an upright rover at rest on level
 *     ground (neither the terrain, an overturn nor a fall) is blamed on
 *     the soil, and the message names the step setting: at a fixed step
 *     (0.1 s) it also names the step too coarse for the soil's stiffness
 *     and the run that tells the two apart (the automatic step or a
 *     smaller solver.step); at the automatic step it names
 *     solver.tolerance and blames no step.  A coarse fixed step sinks a
 *     wheel on a stiff soil only in runs chaotic in their parameters, so
 *     the check of the sinkage specifies this message, not a run;
 *   - a rocker angle beyond 1.2 rad (69 deg; the model has no stop on the
 *     rockers) or a velocity beyond 1e3 in magnitude, checked directly on
 *     a rover at rest on level ground, is a diverged state whose message
 *     keeps the angle or the velocity and says what it is: for the rocker,
 *     how far the left front wheel then stands below the left rear and the
 *     right front (rover.wheelbase sin 1.2, 0.76 m, the geometry an
 *     evaluation at 1.2 rad gives), for a velocity which one it is, with
 *     its unit; both say the ground slopes at most 0.0 deg, not the
 *     terrain, and name the step setting, at a fixed step and at the
 *     automatic one, the whole message within the FMI layer's 768
 *     characters.
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

/* The attitude q0 (world from chassis, w x y z) turned by angle (rad)
 * about the chassis axis (unit, in chassis coordinates): q0 times the
 * turn's quaternion. */
static void turned(double q[4], const double q0[4], const double axis[3], double angle)
{
    const double c = cos(0.5 * angle), sn = sin(0.5 * angle);
    const double t[4] = {c, sn * axis[0], sn * axis[1], sn * axis[2]};
    q[0] = q0[0] * t[0] - q0[1] * t[1] - q0[2] * t[2] - q0[3] * t[3];
    q[1] = q0[0] * t[1] + q0[1] * t[0] + q0[2] * t[3] - q0[3] * t[2];
    q[2] = q0[0] * t[2] - q0[1] * t[3] + q0[2] * t[0] + q0[3] * t[1];
    q[3] = q0[0] * t[3] + q0[1] * t[2] - q0[2] * t[1] + q0[3] * t[0];
}

#define CHECKED_AT 2.5          /* s: the time the upright check is told */

/* The message of the upright check for the rover m, evaluated where it
 * rests (the ground normals under its hubs), at its attitude turned by
 * angle (rad) about the chassis axis; into err, returns what the check
 * returns (1 upright, 0 not). */
static int upright_when_turned(const Model *m, const double axis[3], double angle, char *err, size_t n)
{
    Eval *ev = (Eval *)calloc(1, sizeof *ev);
    if (!ev) exit(2);
    rover_evaluate(m, ev, 0);
    double q[4];
    turned(q, m->s.quat, axis, angle);
    const int upright = rover_attitude_is_upright(m, q, ev, CHECKED_AT, err, n);
    free(ev);
    return upright;
}

/* A rover at its defaults at rest on flat ground tilted by slope_x, at
 * the automatic step (fixed_step 0) or at that fixed step; initialised. */
static Model *new_resting_rover(double slope_x, double fixed_step)
{
    Model *m = rover_at_defaults();
    m->p.terrain_slopeX = slope_x;
    if (fixed_step > 0) m->p.solver_tolerance = 0.0, m->p.solver_step = fixed_step;
    return initialised(m, "the resting rover");
}

static const double LATERAL[3] = {0.0, 1.0, 0.0}, HEADING[3] = {1.0, 0.0, 0.0};

/* The clause naming the step setting, as the message gives it: solver.step
 * with its value at a fixed step, solver.tolerance at the automatic one. */
static const char *step_setting(double fixed_step, char *buf, size_t n)
{
    if (fixed_step > 0) snprintf(buf, n, "the internal step is fixed, solver.step = %g s", fixed_step);
    else snprintf(buf, n, "the internal step is automatic, solver.tolerance = ");
    return buf;
}

/* Whether err names the step setting and blames it: a fixed step too
 * coarse, or (at the automatic step, which has no solver.step to name) a
 * tolerance too loose. */
static int blames_the_step_setting(const char *err, double fixed_step)
{
    char setting[96];
    if (!strstr(err, step_setting(fixed_step, setting, sizeof setting))) return 0;
    if (fixed_step > 0) return strstr(err, "fixed step too coarse for the soil's stiffness") != NULL;
    return strstr(err, "solver.tolerance too loose for the soil's stiffness") != NULL &&
           strstr(err, "solver.step") == NULL;
}

#define CHECKED_FIXED_STEP 0.05 /* s */

static void test_an_upside_down_rover_on_level_ground_blames_the_step_not_the_terrain(double fixed_step)
{
    const char *step = fixed_step > 0 ? "fixed step" : "automatic step";
    Model *m = new_resting_rover(0.0, fixed_step);
    char err[768] = "";
    CHECK(upright_when_turned(m, LATERAL, 0.0, err, sizeof err) == 1 && err[0] == '\0',
          "%s: the resting rover is upright: \"%s\"", step, err);
    const struct {
        const double *axis;
        double deg;
        const char *turn;
    } turns[] = {{LATERAL, 180.0, "turned 180 deg end over end"}, {HEADING, 120.0, "rolled 120 deg sideways"}};
    for (size_t i = 0; i < sizeof turns / sizeof turns[0]; ++i) {
        err[0] = '\0';
        const int upright = upright_when_turned(m, turns[i].axis, turns[i].deg * M_PI / 180.0, err, sizeof err);
        CHECK(!upright && strstr(err, "state diverged at t = 2.5000 s") != NULL && strstr(err, "overturned") != NULL,
              "%s, %s: the rover is not upright, it has overturned: \"%s\"", step, turns[i].turn, err);
        CHECK(fabs(overturn_angle(err) - turns[i].deg) <= 1.0,
              "%s, %s: its up axis is %.0f deg from the ground's normal (%.0f)", step, turns[i].turn, turns[i].deg,
              overturn_angle(err));
        CHECK(strstr(err, "slopes at most 0.0 deg") != NULL && strstr(err, "not the terrain") != NULL &&
                  strstr(err, "too steep") == NULL,
              "%s, %s: the message says the level ground is not the cause: \"%s\"", step, turns[i].turn, err);
        CHECK(blames_the_step_setting(err, fixed_step), "%s, %s: and names the step setting as a cause: \"%s\"", step,
              turns[i].turn, err);
        /* the longest of the messages (the fixed step's advice), whole: no buffer on its way cuts it short */
        CHECK(strstr(err, "beyond what holds the rover down)") != NULL, "%s, %s: the message is whole: \"%s\"", step,
              turns[i].turn, err);
    }
    err[0] = '\0';
    upright_when_turned(m, HEADING, 120.0 * M_PI / 180.0, err, sizeof err);
    CHECK(strstr(err, "about its heading (rolled sideways)") != NULL,
          "%s: a rover rolled 120 deg is said to have rolled sideways: \"%s\"", step, err);
    free_rover(m);
}

static void test_an_upside_down_rover_on_steep_ground_blames_the_terrain(double fixed_step)
{
    const char *step = fixed_step > 0 ? "fixed step" : "automatic step";
    Model *m = new_resting_rover(0.55, fixed_step);
    char err[768] = "";
    const int upright = upright_when_turned(m, LATERAL, M_PI, err, sizeof err);
    CHECK(!upright && strstr(err, "overturned") != NULL,
          "%s, 0.55 tilt, turned 180 deg: the rover has overturned: \"%s\"", step, err);
    CHECK(strstr(err, "slopes up to 28.8 deg, steep against soil.phi = 30.0 deg") != NULL &&
              strstr(err, "terrain too steep or rough for the drive") != NULL && strstr(err, "not the terrain") == NULL,
          "%s, 0.55 tilt: the message blames the terrain, naming its slope: \"%s\"", step, err);
    char setting[96];
    CHECK(strstr(err, step_setting(fixed_step, setting, sizeof setting)) != NULL &&
              strstr(err, "too coarse") == NULL && strstr(err, "too loose") == NULL,
          "%s, 0.55 tilt: it names the step setting without blaming it: \"%s\"", step, err);
    free_rover(m);
}

/* The line between the terrain and the step setting: tan slope = tan
 * soil.phi / 2, 0.289 at the default 30 deg. */
static void test_the_terrain_is_blamed_from_half_the_frictional_grip(void)
{
    const struct {
        double tilt;
        int terrain;
    } sides[] = {{0.25, 0}, {0.3, 1}};
    for (size_t i = 0; i < sizeof sides / sizeof sides[0]; ++i) {
        Model *m = new_resting_rover(sides[i].tilt, 0.0);
        char err[768] = "";
        const int upright = upright_when_turned(m, LATERAL, M_PI, err, sizeof err);
        const int blames_terrain = strstr(err, "terrain too steep or rough") != NULL,
                  blames_step = strstr(err, "not the terrain") != NULL && blames_the_step_setting(err, 0.0);
        CHECK(!upright && (sides[i].terrain ? blames_terrain && !blames_step : blames_step && !blames_terrain),
              "a %.2f tilt (tan slope %s 0.289) blames %s: \"%s\"", sides[i].tilt, sides[i].terrain ? ">" : "<",
              sides[i].terrain ? "the terrain" : "the step setting", err);
        free_rover(m);
    }
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

#define COARSE_FIXED_STEP 0.1   /* s */

/* The message of the state check for the rover m at rest where it
 * stands, its wheel FL sunk to its radius, at time 1e4 s (the widest time
 * the message gives in full); into err, returns what the check returns
 * (1 sane, 0 not). */
static int sanity_with_front_left_sunk(const Model *m, char *err, size_t n)
{
    Eval *ev = (Eval *)calloc(1, sizeof *ev);
    if (!ev) exit(2);
    rover_evaluate(m, ev, 0);
    ev->wheel[0].sinkage = m->p.wheel_radius;
    const int sane = rover_motion_is_sane(m, ev, 1e4, m->s.pos, m->s.u, m->s.beta, err, n);
    free(ev);
    return sane;
}

static void test_a_wheel_sunk_under_a_resting_rover_blames_the_soil_and_names_the_step(double fixed_step)
{
    const char *step = fixed_step > 0 ? "fixed 0.1 s step" : "automatic step";
    Model *m = new_resting_rover(0.0, fixed_step);
    char err[768] = "";
    CHECK(sanity_with_front_left_sunk(m, err, sizeof err) == 0 &&
              strstr(err, "state diverged at t = 10000.0000 s: wheel FL sank") != NULL &&
              strstr(err, "deeper than its radius") != NULL,
          "%s: a wheel sunk to its radius is a diverged state: \"%s\"", step, err);
    CHECK(strstr(err, "the soil is too soft for the load on these wheels (check soil.kh, soil.eta, wheel.radius, "
                      "wheel.width)") != NULL &&
              strstr(err, "overturned") == NULL && strstr(err, "struck the ground") == NULL &&
              strstr(err, "friction angle") == NULL,
          "%s: on level ground, upright and at rest, the soil is blamed: \"%s\"", step, err);
    char setting[96];
    CHECK(strstr(err, step_setting(fixed_step, setting, sizeof setting)) != NULL,
          "%s: the message names the step setting: \"%s\"", step, err);
    if (fixed_step > 0) {
        CHECK(strstr(err, "or the internal step is fixed, solver.step = 0.1 s, too coarse for the soil's "
                          "stiffness") != NULL,
              "%s: it names the step too coarse for the soil's stiffness as the other cause: \"%s\"", step, err);
        /* the longest of the messages, whole: no buffer on its way cuts it short */
        CHECK(strstr(err, "(run it again at the automatic step, solver.tolerance > 0, or a smaller solver.step: "
                          "if that run holds the wheel, the step was the cause)") != NULL,
              "%s: and the run that tells the two apart, the message whole: \"%s\"", step, err);
    } else {
        CHECK(strstr(err, "too coarse") == NULL && strstr(err, "too loose") == NULL &&
                  strstr(err, "solver.step") == NULL,
              "%s: it blames no step setting: \"%s\"", step, err);
    }
    free_rover(m);
}

/* The FMI layer's error buffer (fmi2_cs.c): a message longer than this is cut short. */
#define FMI_ERROR_BUFFER 768

/* The message of the motion check for the rover m at rest where it
 * stands, with its rocker angle beta and velocity component i set to
 * value (i < 0: none), at time 1e4 s (the widest time the message gives
 * in full); into err, returns what the check returns (1 sane, 0 not). */
static int sanity_of_motion(const Model *m, double beta, int i, double value, char *err, size_t n)
{
    Eval *ev = (Eval *)calloc(1, sizeof *ev);
    if (!ev) exit(2);
    rover_evaluate(m, ev, 0);
    double u[NU];
    memcpy(u, m->s.u, sizeof u);
    if (i >= 0) u[i] = value;
    const int sane = rover_motion_is_sane(m, ev, 1e4, m->s.pos, u, beta, err, n);
    free(ev);
    return sane;
}

/* Whether err says the level ground is not the cause, names the step
 * setting as one and is whole: its last clause, the drive or drawbar
 * load, is there, and the message fits the FMI layer's error buffer. */
static int blames_the_step_not_level_ground(const char *err, double fixed_step)
{
    return strstr(err, "slopes at most 0.0 deg") != NULL && strstr(err, "not the terrain") != NULL &&
           strstr(err, "too steep") == NULL && blames_the_step_setting(err, fixed_step) &&
           strstr(err, "beyond what holds the rover down") != NULL && strlen(err) + 1 < FMI_ERROR_BUFFER;
}

/* How far (m) the left front hub stands below the left rear and the right
 * front hubs (chassis z) for the rover m at rest with rocker angle beta:
 * below[0] the left rear, below[1] the right front. */
static void left_front_below(const Model *m, double beta, double below[2])
{
    Model *turned_rockers = (Model *)malloc(sizeof *turned_rockers);
    Eval *ev = (Eval *)calloc(1, sizeof *ev);
    if (!turned_rockers || !ev) exit(2);
    *turned_rockers = *m;
    turned_rockers->s.beta = beta;
    rover_evaluate(turned_rockers, ev, 0);
    double z[NUM_WHEELS];           /* the hubs' heights along the chassis's up axis */
    for (int w = 0; w < NUM_WHEELS; ++w)
        z[w] = ev->R[2] * ev->hub[w][0] + ev->R[5] * ev->hub[w][1] + ev->R[8] * ev->hub[w][2];
    below[0] = z[WHEEL_RL] - z[WHEEL_FL];
    below[1] = z[WHEEL_FR] - z[WHEEL_FL];
    free(ev);
    free(turned_rockers);
}

static void test_a_rocker_turned_past_its_limit_says_where_the_wheels_stand(double fixed_step)
{
    const char *step = fixed_step > 0 ? "fixed step" : "automatic step";
    Model *m = new_resting_rover(0.0, fixed_step);
    char err[FMI_ERROR_BUFFER] = "";
    CHECK(sanity_of_motion(m, 1.2, -1, 0.0, err, sizeof err) == 1 && err[0] == '\0',
          "%s: a rocker angle of 1.2 rad is sane: \"%s\"", step, err);
    CHECK(sanity_of_motion(m, 1.3, -1, 0.0, err, sizeof err) == 0 &&
              strstr(err, "state diverged at t = 10000.0000 s: rocker angle 1.3 rad, beyond the 1.2 rad (69 deg) "
                          "the model accepts") != NULL,
          "%s: a rocker angle of 1.3 rad is a diverged state, the angle and the limit named: \"%s\"", step, err);
    double below[2];
    left_front_below(m, 1.2, below);
    char stands[160];
    snprintf(stands, sizeof stands,
             "the left front wheel stands %.2f m below the left rear and the right front (rover.wheelbase = 0.82 m)",
             0.82 * sin(1.2));
    CHECK(strstr(err, stands) != NULL && strstr(err, "0.76 m below") != NULL,
          "%s: it says where the wheels stand at the limit: \"%s\"", step, err);
    CHECK(fabs(below[0] - 0.82 * sin(1.2)) < 5e-3 && fabs(below[1] - 0.82 * sin(1.2)) < 5e-3,
          "%s: as the rover's geometry at 1.2 rad has them (left front %.3f m below the left rear, %.3f m below "
          "the right front)", step, below[0], below[1]);
    CHECK(blames_the_step_not_level_ground(err, fixed_step),
          "%s: on level ground it is not the terrain, the step setting is named, the message whole (%zu chars): "
          "\"%s\"", step, strlen(err), err);
    err[0] = '\0';
    CHECK(sanity_of_motion(m, -1.3, -1, 0.0, err, sizeof err) == 0 && strstr(err, "rocker angle -1.3 rad") != NULL &&
              strstr(err, "the left front wheel stands 0.76 m above the left rear and the right front") != NULL,
          "%s: turned the other way, the left front wheel stands above them: \"%s\"", step, err);
    err[0] = '\0';
    CHECK(sanity_of_motion(m, 1.2 + 1e-9, -1, 0.0, err, sizeof err) == 0 &&
              strstr(err, "rocker angle 1.200000001 rad, beyond the 1.2 rad") != NULL,
          "%s: an angle just past the limit is given with the digits that show it past: \"%s\"", step, err);
    err[0] = '\0';
    CHECK(sanity_of_motion(m, NAN, -1, 0.0, err, sizeof err) == 0 && strstr(err, "rocker angle ") != NULL &&
              strstr(err, " rad, not finite; ") != NULL && blames_the_step_not_level_ground(err, fixed_step),
          "%s: a rocker angle that is not a number is a diverged state too: \"%s\"", step, err);
    free_rover(m);
}

static void test_a_velocity_past_its_limit_names_which_velocity_it_is(double fixed_step)
{
    const char *step = fixed_step > 0 ? "fixed step" : "automatic step";
    Model *m = new_resting_rover(0.0, fixed_step);
    const struct {
        int component;
        double value;
        const char *says, *limit;
    } cases[] = {
        {U_VX + 2, -1500.0, "velocity component 2 = -1500 m/s, the chassis's velocity along world z",
         "beyond the magnitude of 1000 the model accepts"},
        {U_WX + 1, 2000.0, "velocity component 4 = 2000 rad/s, the chassis's angular velocity about world y",
         "beyond the magnitude of 1000 the model accepts"},
        {U_BETA, 1001.0, "velocity component 6 = 1001 rad/s, the rocker rate", "beyond the magnitude of 1000"},
        {U_SPIN_R, NAN, "velocity component 8 = nan rad/s, the right wheels' spin relative to their rocker",
         "rocker, not finite (the model accepts magnitudes up to 1000); "},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        char err[FMI_ERROR_BUFFER] = "";
        const int sane = sanity_of_motion(m, m->s.beta, cases[k].component, cases[k].value, err, sizeof err);
        CHECK(!sane && strstr(err, "state diverged at t = 10000.0000 s: ") != NULL &&
                  strstr(err, cases[k].says) != NULL && strstr(err, cases[k].limit) != NULL,
              "%s: component %d = %g is a diverged state, named with its unit: \"%s\"", step, cases[k].component,
              cases[k].value, err);
        CHECK(blames_the_step_not_level_ground(err, fixed_step),
              "%s, component %d: on level ground it is not the terrain, the step setting is named, the message "
              "whole (%zu chars)", step, cases[k].component, strlen(err));
    }
    char err[FMI_ERROR_BUFFER] = "";
    CHECK(sanity_of_motion(m, m->s.beta, U_SPIN_L, 1000.0, err, sizeof err) == 1 && err[0] == '\0',
          "%s: a wheel spin of 1e3 rad/s is sane: \"%s\"", step, err);
    free_rover(m);
}

int main(void)
{
    test_a_rover_flipping_over_is_stopped_as_overturned(0.0);
    test_a_rover_flipping_over_is_stopped_as_overturned(FIXED_STEP);
    test_an_upside_down_rover_on_level_ground_blames_the_step_not_the_terrain(0.0);
    test_an_upside_down_rover_on_level_ground_blames_the_step_not_the_terrain(CHECKED_FIXED_STEP);
    test_an_upside_down_rover_on_steep_ground_blames_the_terrain(0.0);
    test_an_upside_down_rover_on_steep_ground_blames_the_terrain(CHECKED_FIXED_STEP);
    test_the_terrain_is_blamed_from_half_the_frictional_grip();
    test_an_upright_rover_on_the_steepest_allowed_tilt_runs_its_whole_time(0.0);
    test_an_upright_rover_on_the_steepest_allowed_tilt_runs_its_whole_time(FIXED_STEP);
    test_an_upright_rover_sinking_under_its_load_blames_the_soil(0.0);
    test_an_upright_rover_sinking_under_its_load_blames_the_soil(FIXED_STEP);
    test_a_wheel_sunk_under_a_resting_rover_blames_the_soil_and_names_the_step(0.0);
    test_a_wheel_sunk_under_a_resting_rover_blames_the_soil_and_names_the_step(COARSE_FIXED_STEP);
    test_a_rocker_turned_past_its_limit_says_where_the_wheels_stand(0.0);
    test_a_rocker_turned_past_its_limit_says_where_the_wheels_stand(CHECKED_FIXED_STEP);
    test_a_velocity_past_its_limit_names_which_velocity_it_is(0.0);
    test_a_velocity_past_its_limit_names_which_velocity_it_is(CHECKED_FIXED_STEP);
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
