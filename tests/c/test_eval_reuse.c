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
 */
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "model.h"

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
    char err[512];
    Model *m = (Model *)calloc(1, sizeof *m);
    if (!m) exit(2);
    model_set_defaults(m);
    terrain_init_flat(&m->terrain);
    m->p.drive_mode = drive_mode;
    m->p.solver_step = solver_step;
    m->p.multipass_rutFraction = rut_fraction;
    if (model_initialize(m, err, sizeof err) != 0) {
        printf("model_initialize: %s\n", err);
        exit(2);
    }
    return m;
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

/* An earlier state put back (fmi2SetFMUstate), and a parameter changed
 * between steps: the next step must evaluate afresh. */
static void test_state_restored_and_parameter_changed(void)
{
    Model *a = new_model(DRIVE_MOTOR, 0.01, 0.0), *b = new_model(DRIVE_MOTOR, 0.01, 0.0);
    int k = lockstep(a, b, 0, 50, 0.01);
    const State early = a->s;
    const Outputs early_out = a->out;
    if (k < 0) k = lockstep(a, b, 50, 50, 0.01);
    a->s = early, a->out = early_out;           /* a keeps its evaluation of the later state */
    b->s = early, b->out = early_out;
    if (k < 0) k = lockstep(a, b, 100, 50, 0.01);
    CHECK(k < 0, "state set back 50 steps: bit for bit afterwards (first difference at step %d)", k);
    a->p.wheel_mass *= 1.5;                     /* read by the body assembly */
    b->p.wheel_mass *= 1.5;
    if (k < 0) k = lockstep(a, b, 150, 50, 0.01);
    CHECK(k < 0, "wheel.mass changed between steps: bit for bit afterwards (first difference at step %d)", k);
    model_free(a), model_free(b), free(a), free(b);
}

int main(void)
{
    test_changing_inputs();
    test_multipass();
    test_state_restored_and_parameter_changed();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
