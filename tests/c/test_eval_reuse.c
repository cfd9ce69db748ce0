/*
 * Reusing the end-of-step evaluation (rover_step.c, model_do_step) changes
 * nothing: a model that reuses it and one made to evaluate afresh at every
 * step (its eval_valid cleared before each model_do_step) end every
 * communication step in bit-identical states and outputs, while
 *   - the inputs change between every two steps (drawbar, torques, speed
 *     references, throttles), in each drive mode;
 *   - the internal step equals the communication step or divides it;
 *   - multi-pass ruts are on (the rut history is part of what is reused);
 *   - the model is set back to an earlier state (as fmi2SetFMUstate does)
 *     or a parameter changes between steps: the kept evaluation belongs to
 *     another state and must not be used.
 * The accessors (model_set_state, model_set_real) are what clears it; the
 * FMI functions that reach them are checked in test_eval_reuse_fmi.c.
 */
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "model.h"
#include "rover_fixture.h"

/* Inputs that change every step: a few different values per channel. */
static void set_inputs(Model *m, int k)
{
    const double a = (double)(k % 7) / 6.0, b = (double)((3 * k) % 5) / 4.0;
    m->in.drawbarForce = 600.0 * a;
    m->in.torqueLeft = 40.0 + 30.0 * b;
    m->in.torqueRight = 70.0 - 30.0 * a;
    m->in.omegaRefLeft = 0.5 + 1.5 * a;
    m->in.omegaRefRight = 2.0 - 1.5 * b;
    m->in.throttleLeft = 0.2 + 0.6 * b;
    m->in.throttleRight = 0.8 - 0.6 * a;
}

static Model *new_model(int drive_mode, double solver_step, double rut_fraction)
{
    Model *m = rover_at_defaults();
    m->p.drive_mode = drive_mode;
    m->p.solver_step = solver_step;
    m->p.multipass_rutFraction = rut_fraction;
    return initialised(m, "drive mode, step, rut");
}

static int same_state(const Model *a, const Model *b)
{
    return memcmp(&a->s, &b->s, sizeof a->s) == 0 && memcmp(&a->out, &b->out, sizeof a->out) == 0;
}

/* Steps a (reusing) and b (fresh) n times from step k0 with changing
 * inputs; returns the first step where they differ, or -1. */
static int lockstep(Model *a, Model *b, int k0, int n, double h_comm)
{
    char err[512];
    for (int k = k0; k < k0 + n; ++k) {
        set_inputs(a, k);
        set_inputs(b, k);
        b->eval_valid = 0;
        if (model_do_step(a, h_comm, err, sizeof err) != 0 || model_do_step(b, h_comm, err, sizeof err) != 0) {
            printf("model_do_step: %s\n", err);
            return k;
        }
        if (!same_state(a, b)) return k;
    }
    return -1;
}

static void test_changing_inputs(void)
{
    static const char *const modes[3] = {"torque", "PID", "motor"};
    static const double steps[2] = {0.01, 0.0025};
    for (int mode = 0; mode < 3; ++mode)
        for (int i = 0; i < 2; ++i) {
            Model *a = new_model(mode, steps[i], 0.0), *b = new_model(mode, steps[i], 0.0);
            const int k = lockstep(a, b, 0, 300, 0.01);
            CHECK(k < 0, "drive %s, solver.step %g s: reused and fresh evaluations agree bit for bit over 300 "
                  "steps with inputs changing every step (first difference at step %d)", modes[mode], steps[i], k);
            model_free(a), model_free(b), free(a), free(b);
        }
}

static void test_multipass(void)
{
    Model *a = new_model(DRIVE_MOTOR, 0.01, 0.5), *b = new_model(DRIVE_MOTOR, 0.01, 0.5);
    const int k = lockstep(a, b, 0, 300, 0.01);
    CHECK(k < 0, "multipass on: bit for bit over 300 steps (first difference at step %d)", k);
    model_free(a), model_free(b), free(a), free(b);
}

/* An earlier state put back (model_set_state, as fmi2SetFMUstate does),
 * and a parameter changed between steps (model_set_real): the next step
 * must evaluate afresh.  Both go through the accessors, which are what
 * tells the model that its kept evaluation no longer holds. */
static void test_state_restored_and_parameter_changed(void)
{
    enum { VR_GRAVITY = 139, VR_THROTTLE_LEFT = 205 };
    Model *a = new_model(DRIVE_MOTOR, 0.01, 0.0), *b = new_model(DRIVE_MOTOR, 0.01, 0.0);
    ModelState *early = (ModelState *)malloc(sizeof *early);
    if (!early) exit(2);
    int k = lockstep(a, b, 0, 50, 0.01);
    model_get_state(a, early);
    if (k < 0) k = lockstep(a, b, 50, 50, 0.01);
    model_set_state(a, early);                  /* a kept its evaluation of the later state */
    model_set_state(b, early);
    CHECK(!a->eval_valid, "setting a state makes the next step evaluate afresh");
    if (k < 0) k = lockstep(a, b, 100, 50, 0.01);
    CHECK(k < 0, "state set back 50 steps: bit for bit afterwards (first difference at step %d)", k);
    double g = 0;
    model_get_real(a, VR_GRAVITY, &g);
    model_set_real(a, VR_GRAVITY, 1.1 * g);     /* read by the body assembly (the bodies' weights) */
    model_set_real(b, VR_GRAVITY, 1.1 * g);
    CHECK(!a->eval_valid && a->p.env_gravity == 1.1 * g, "setting env.gravity makes the next step evaluate afresh");
    if (k < 0) k = lockstep(a, b, 150, 50, 0.01);
    CHECK(k < 0, "env.gravity changed between steps: bit for bit afterwards (first difference at step %d)", k);
    /* and the change is seen: a step from the same state with the old gravity ends elsewhere */
    Model *c = new_model(DRIVE_MOTOR, 0.01, 0.0);
    model_get_state(a, early);
    model_set_state(c, early);
    model_set_real(c, VR_GRAVITY, g);
    char err[512];
    set_inputs(a, 200), set_inputs(c, 200);
    if (model_do_step(a, 0.01, err, sizeof err) != 0 || model_do_step(c, 0.01, err, sizeof err) != 0) {
        printf("model_do_step: %s\n", err);
        exit(2);
    }
    CHECK(memcmp(a->s.u, c->s.u, sizeof a->s.u) != 0, "a step with env.gravity %g m/s2 ends elsewhere than with %g",
          1.1 * g, g);
    /* an input set between steps keeps the kept evaluation: it reads no input */
    model_set_real(a, VR_THROTTLE_LEFT, 0.3);
    CHECK(a->eval_valid, "setting an input keeps the kept evaluation");
    model_free(a), model_free(b), model_free(c), free(a), free(b), free(c), free(early);
}

int main(void)
{
    test_changing_inputs();
    test_multipass();
    test_state_restored_and_parameter_changed();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
