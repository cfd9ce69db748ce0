/*
 * The automatic step (solver.tolerance > 0, rover_auto_step.c):
 *   - it is second order: with every step accepted at a fixed length h (a
 *     tolerance no step exceeds), its velocity error through the drawbar
 *     run's pitching falls as h^2 (measured: 2.0) where the fixed step's
 *     falls as h, and is at least thirty times smaller than the fixed
 *     step's at 4 ms and at 2 ms (measured: 65 and 141 times);
 *   - the correction it takes from the last step is that of the current
 *     inputs: with the inputs unchanged, forgetting the last step changes
 *     the next (so the correction is there), and after the inputs change,
 *     the next step is the one a model that never had a last step takes;
 *   - the soil memory follows the sinkage the step ends at, not the one it
 *     starts from: where a wheel sinks deeper, the remembered maximum after
 *     a step is within a twentieth of the step's change of sinkage of the
 *     end's, summed over the steps (the start's lags a step behind);
 *   - its rejected steps leave nothing behind: at a tolerance tight enough
 *     to reject steps it still agrees with a fine fixed step;
 *   - reusing the end-of-step evaluation changes nothing, as for the fixed
 *     step (test_eval_reuse.c): reused and fresh agree bit for bit with the
 *     inputs changing every step, in every drive mode, with ruts on.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "model.h"
#include "rover_fixture.h"

static Model *new_model(int drive_mode, double solver_step, double tolerance, double rut_fraction)
{
    Model *m = rover_at_defaults();
    m->p.drive_mode = drive_mode;
    m->p.solver_step = solver_step;
    m->p.solver_tolerance = tolerance;
    m->p.multipass_rutFraction = rut_fraction;
    return initialised(m, "drive mode, step, tolerance, rut");
}

static void step_to(Model *m, double t_end, double h_comm)
{
    char err[512];
    while (m->s.time < t_end - 1e-9)
        if (model_do_step(m, h_comm, err, sizeof err) != 0) {
            printf("model_do_step: %s\n", err);
            exit(2);
        }
}

/* Largest difference of the velocities (the spins as rim speeds), m/s. */
static double velocity_difference(const Model *a, const Model *b)
{
    double worst = 0;
    for (int i = 0; i < NU; ++i) {
        const double lever = i >= U_SPIN_L ? a->p.wheel_radius : 1.0;
        worst = fmax(worst, fabs(a->s.u[i] - b->s.u[i]) * lever);
    }
    return worst;
}

/* From the drawbar run's state at 2 s (the pitching after the start still
 * ringing), 0.4 s more at steps of h and h/2 against the automatic step's
 * own at 1/16 ms. */
static void test_accuracy_at_a_fixed_length(void)
{
    Model *start = new_model(DRIVE_MOTOR, 2.5e-4, 0.0, 0.0);
    step_to(start, 2.0, 0.02);
    double err_auto[2], err_fixed[2];
    const double h[2] = {0.004, 0.002};
    Model *ref = new_model(DRIVE_MOTOR, 6.25e-5, 1.0, 0.0);
    ref->s = start->s;
    ref->s.step_next = 6.25e-5;
    ref->eval_valid = 0;
    step_to(ref, 2.4, 0.02);
    for (int k = 0; k < 2; ++k) {
        Model *a = new_model(DRIVE_MOTOR, h[k], 1.0, 0.0), *f = new_model(DRIVE_MOTOR, h[k], 0.0, 0.0);
        a->s = start->s, f->s = start->s;
        a->s.step_next = h[k];
        a->eval_valid = f->eval_valid = 0;
        step_to(a, 2.4, 0.02);
        step_to(f, 2.4, 0.02);
        CHECK(a->steps_rejected == 0, "solver.tolerance 1 m/s rejects no step (%lu rejected)", a->steps_rejected);
        err_auto[k] = velocity_difference(a, ref);
        err_fixed[k] = velocity_difference(f, ref);
        model_free(a), model_free(f), free(a), free(f);
    }
    const double order_auto = log2(err_auto[0] / err_auto[1]), order_fixed = log2(err_fixed[0] / err_fixed[1]);
    printf("  velocity error after 0.4 s at 4 ms and 2 ms: automatic %.3g, %.3g m/s (order %.2f); fixed %.3g, "
           "%.3g m/s (order %.2f)\n", err_auto[0], err_auto[1], order_auto, err_fixed[0], err_fixed[1], order_fixed);
    CHECK(order_fixed > 0.8 && order_fixed < 1.2, "the fixed step converges at first order (measured %.2f)",
          order_fixed);
    CHECK(order_auto > 1.7, "the automatic step converges at second order (measured %.2f)", order_auto);
    CHECK(30 * err_auto[0] < err_fixed[0] && 30 * err_auto[1] < err_fixed[1],
          "and is at least thirty times more accurate at both steps (%.0f and %.0f times)",
          err_fixed[0] / err_auto[0], err_fixed[1] / err_auto[1]);
    model_free(start), model_free(ref), free(start), free(ref);
}

/* One communication step of a copy of a's state, with or without its last
 * step (a is left as it was); 1 if it ends where a's own does, bit for bit. */
static int same_without_last_step(Model *a, Model *b, double h_comm)
{
    char err[512];
    b->s = a->s, b->in = a->in;
    b->s.last_step = 0;
    b->eval_valid = 0;
    Model *c = new_model(a->p.drive_mode, a->p.solver_step, a->p.solver_tolerance, a->p.multipass_rutFraction);
    c->s = a->s, c->in = a->in;
    c->eval_valid = 0;
    if (model_do_step(b, h_comm, err, sizeof err) != 0 || model_do_step(c, h_comm, err, sizeof err) != 0) {
        printf("model_do_step: %s\n", err);
        exit(2);
    }
    const int same = memcmp(b->s.u, c->s.u, sizeof b->s.u) == 0 && memcmp(b->s.pos, c->s.pos, sizeof b->s.pos) == 0;
    model_free(c), free(c);
    return same;
}

/* PID drive, 1 s into the run: the next communication step with the
 * reference unchanged, and with it stepped from 2 to 3 rad/s. */
static void test_the_correction_is_that_of_the_current_inputs(void)
{
    Model *a = new_model(DRIVE_PID, 0.02, 1e-4, 0.0), *b = new_model(DRIVE_PID, 0.02, 1e-4, 0.0);
    a->in.omegaRefLeft = a->in.omegaRefRight = 2.0;
    step_to(a, 1.0, 0.01);
    CHECK(a->s.last_step > 0, "1 s into the run the model has a last step (%g s)", a->s.last_step);
    CHECK(!same_without_last_step(a, b, 0.01), "with the inputs unchanged, forgetting the last step changes the next");
    a->in.omegaRefLeft = a->in.omegaRefRight = 3.0;
    CHECK(same_without_last_step(a, b, 0.01),
          "after the reference steps, the next step is the one without a last step, bit for bit");
    model_free(a), model_free(b), free(a), free(b);
}

/* Through the start and the pitching after it at the automatic step's own
 * lengths: after every communication step (10 ms, one or two internal
 * steps), each wheel that sank deeper than ever over it remembers the
 * sinkage it ended at.  The remembered maxima after the step's last
 * internal step are compared with the end's evaluation (the outputs): the
 * sum of their differences against the sum of the changes of sinkage over
 * those steps (a memory of the start's sinkage lags a step behind: 0.3 of
 * the change, measured; near a turning point, where the change is small,
 * the end's sinkage predicted to O(h^2) can be off by more than it). */
static void test_soil_memory_follows_the_end_of_the_step(void)
{
    char err[512];
    Model *a = new_model(DRIVE_MOTOR, 0.02, 1e-4, 0.0);
    double before[NUM_WHEELS], zmax_before[NUM_WHEELS], missed = 0, sank = 0;
    int loading = 0;
    for (int w = 0; w < NUM_WHEELS; ++w) before[w] = a->out.wheel[w].sinkage, zmax_before[w] = a->s.memory[w].zmax;
    while (a->s.time < 3.0 - 1e-9) {
        if (model_do_step(a, 0.01, err, sizeof err) != 0) {
            printf("model_do_step: %s\n", err);
            exit(2);
        }
        for (int w = 0; w < NUM_WHEELS; ++w) {
            const double z = a->out.wheel[w].sinkage, change = z - before[w];
            if (change > 0 && z > zmax_before[w]) {      /* deeper than ever: the memory is the sinkage */
                ++loading;
                missed += fabs(a->s.memory[w].zmax - z);
                sank += change;
            }
            before[w] = z, zmax_before[w] = a->s.memory[w].zmax;
        }
    }
    printf("  %d wheel-steps sinking deeper than ever in 3 s, %.3g mm in all: the memories %.3g mm from the end's "
           "sinkage in all\n", loading, 1e3 * sank, 1e3 * missed);
    CHECK(loading > 100, "wheels sank deeper than ever over many steps (%d)", loading);
    CHECK(missed < 0.05 * sank, "the memory follows the sinkage the step ends at (%.3g of the change)", missed / sank);
    model_free(a), free(a);
}

/* Through the start (a jolt of the motors from rest, the wheels bouncing)
 * at a tight tolerance: steps are rejected and taken again, and the result
 * stays within 2e-4 m/s of the automatic step's own at 0.05 ms, none
 * rejected (measured: as close as a fixed 0.025 ms step comes, 1.2e-4 m/s;
 * a rejected step that left a trace would stand out). */
static void test_rejected_steps_leave_nothing_behind(void)
{
    Model *a = new_model(DRIVE_MOTOR, 0.02, 1e-6, 0.5), *ref = new_model(DRIVE_MOTOR, 5e-5, 1.0, 0.5);
    ref->s.step_next = 5e-5;                    /* every step 0.05 ms */
    step_to(a, 1.0, 0.01);
    step_to(ref, 1.0, 0.01);
    const double d = velocity_difference(a, ref);
    printf("  tolerance 1e-6 m/s through the start: %lu steps, %lu rejected; velocities within %.3g m/s of a "
           "0.05 ms step\n", a->steps_taken, a->steps_rejected, d);
    CHECK(a->steps_rejected > 0, "steps were rejected (%lu)", a->steps_rejected);
    CHECK(ref->steps_rejected == 0 && d < 2e-4, "and the run agrees with the 0.05 ms one to 2e-4 m/s (%.3g)", d);
    model_free(a), model_free(ref), free(a), free(ref);
}

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

static void test_reuse_changes_nothing(void)
{
    static const char *const modes[3] = {"torque", "PID", "motor"};
    char err[512];
    for (int mode = 0; mode < 3; ++mode)
        for (int rut = 0; rut < 2; ++rut) {
            Model *a = new_model(mode, 0.02, 1e-4, 0.5 * rut), *b = new_model(mode, 0.02, 1e-4, 0.5 * rut);
            int first = -1;
            for (int k = 0; k < 200 && first < 0; ++k) {
                set_inputs(a, k);
                set_inputs(b, k);
                b->eval_valid = 0;
                if (model_do_step(a, 0.01, err, sizeof err) != 0 || model_do_step(b, 0.01, err, sizeof err) != 0) {
                    printf("model_do_step: %s\n", err);
                    first = k;
                    break;
                }
                if (memcmp(&a->s, &b->s, sizeof a->s) != 0 || memcmp(&a->out, &b->out, sizeof a->out) != 0) first = k;
            }
            CHECK(first < 0, "drive %s, ruts %s: reused and fresh evaluations agree bit for bit over 200 steps "
                  "(first difference at step %d)", modes[mode], rut ? "on" : "off", first);
            model_free(a), model_free(b), free(a), free(b);
        }
}

int main(void)
{
    test_accuracy_at_a_fixed_length();
    test_the_correction_is_that_of_the_current_inputs();
    test_soil_memory_follows_the_end_of_the_step();
    test_rejected_steps_leave_nothing_behind();
    test_reuse_changes_nothing();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
