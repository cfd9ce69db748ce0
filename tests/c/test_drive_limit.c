/*
 * The drive's torque limit in the step (drive.mode 1, the PID on the wheel
 * spin, with a stiff tracker: drive.Kp 2000 N m s/rad, drive.Ki 2e4 N m/rad,
 * drive.torqueMax 2000 N m, as the harness's replays use), at a 2 ms step,
 * fixed and automatic, one internal step per communication step:
 *   - on the ground, a step of the spin reference from rest reaches the
 *     reference without the applied torque changing sign step after step
 *     (at most a few sign changes in 1 s, where a step that applied the
 *     limit over its whole length while the demand fell inside it would
 *     swing between +- drive.torqueMax every step) and overshoots it by
 *     less than a tenth;
 *   - in the air (no contact: the spin rows of the equations of motion
 *     hold only the drive), a large reference step saturates the drive
 *     for several steps, and no step gives the wheels more than the limit:
 *     the torque a step gave, M's spin row times the step's change of the
 *     velocities over its length (the step matrix's M is its start's),
 *     is within drive.torqueMax;
 *   - the tracker settles in the air too (no sign changes of the torque
 *     after it reached the reference).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "model.h"
#include "model_hooks.h"
#include "rover_fixture.h"
#include "rover_internal.h"

#define STEP 0.002            /* s, the internal and the communication step */
#define TORQUE_MAX 2000.0     /* N m */

static Model *stiff_tracker(double tolerance)
{
    Model *m = rover_at_defaults();
    m->p.drive_mode = DRIVE_PID;
    m->p.drive_Kp = 2000.0;
    m->p.drive_Ki = 2e4;
    m->p.drive_torqueMax = TORQUE_MAX;
    m->p.solver_step = STEP;
    m->p.solver_tolerance = tolerance;
    m->in.omegaRefLeft = m->in.omegaRefRight = 0.0;
    return initialised(m, "stiff PID tracker at a 2 ms step");
}

static void one_step(Model *m)
{
    char err[768];
    if (model_do_step(m, STEP, err, sizeof err) != 0) {
        printf("model_do_step: %s\n", err);
        exit(2);
    }
}

/* What a run of a reference step shows: the sign changes of each side's
 * applied torque from one communication step to the next (counted from
 * after_time on), the largest spin beyond the reference, the largest torque
 * any step gave a side's wheels (only where measured) and how many steps
 * ended with the torque at its limit. */
typedef struct {
    int sign_changes;
    double overshoot;            /* rad/s */
    double largest_given;        /* N m */
    int saturated_steps;
} Trace;

/* The torque (N m, motor side) each side's wheels got over a step from the
 * velocities u0 to u1, from M (the step's start's): in the air only the
 * drive acts on the spin rows, (M du)_spin = h (1 - drive.lossFraction) T. */
static void torque_given(const Model *m, const double M[NU][NU], const double u0[NU], const double u1[NU],
                         double given[2])
{
    for (int k = 0; k < 2; ++k) {
        double s = 0;
        for (int j = 0; j < NU; ++j) s += M[U_SPIN_L + k][j] * (u1[j] - u0[j]);
        given[k] = s / (STEP * (1.0 - m->p.drive_lossFraction));
    }
}

static Trace run_reference_step(Model *m, double reference, double duration, double after_time, int measure_given)
{
    Trace t = {0, 0.0, 0.0, 0};
    Eval *ev = (Eval *)malloc(sizeof *ev);
    if (!ev) exit(2);
    const double start = m->s.time;
    m->in.omegaRefLeft = m->in.omegaRefRight = reference;
    double last[2] = {0, 0};
    while (m->s.time < start + duration - 1e-9) {
        double u0[NU];
        memcpy(u0, m->s.u, sizeof u0);
        if (measure_given) rover_evaluate_passive(m, ev, EVAL_MATRICES);
        one_step(m);
        const double torque[2] = {m->out.torqueLeftApplied, m->out.torqueRightApplied};
        const double omega[2] = {m->out.omegaLeft, m->out.omegaRight};
        for (int k = 0; k < 2; ++k) {
            if (m->s.time - start > after_time && torque[k] * last[k] < 0) t.sign_changes++;
            last[k] = torque[k];
            t.overshoot = fmax(t.overshoot, omega[k] - reference);
            if (fabs(torque[k]) >= TORQUE_MAX) t.saturated_steps++;
        }
        if (measure_given) {
            double given[2];
            torque_given(m, (const double (*)[NU])ev->M, u0, m->s.u, given);
            for (int k = 0; k < 2; ++k) t.largest_given = fmax(t.largest_given, fabs(given[k]));
        }
    }
    free(ev);
    return t;
}

static const char *step_name(double tolerance) { return tolerance > 0 ? "automatic" : "fixed"; }

/* On the ground: from rest, the reference steps to 3 rad/s (0.84 m/s at
 * the rim, a fast start): the first steps' demand is beyond the limit. */
static void test_reference_step_on_the_ground(double tolerance)
{
    Model *m = stiff_tracker(tolerance);
    const double reference = 3.0;
    const Trace t = run_reference_step(m, reference, 1.0, 0.0, 0);
    printf("  %s step, on the ground, 0 -> %.1f rad/s: %d sign changes of the torque in 1 s, overshoot %.3g rad/s, "
           "%d side-steps at the limit\n", step_name(tolerance), reference, t.sign_changes, t.overshoot,
           t.saturated_steps);
    CHECK(t.sign_changes <= 4, "%s step: the torque does not change sign step after step (%d sign changes in 1 s)",
          step_name(tolerance), t.sign_changes);
    CHECK(t.overshoot < 0.1 * reference, "%s step: the spin overshoots the reference by less than a tenth (%.3g rad/s)",
          step_name(tolerance), t.overshoot);
    model_free(m), free(m);
}

/* In the air (the rover lifted 20 m above the ground it stood on, falling
 * less than 5 m in the 1 s): the reference steps to 20 rad/s, beyond what
 * the limit gives the wheels in one step. */
static void test_reference_step_in_the_air(double tolerance)
{
    Model *m = stiff_tracker(tolerance);
    m->s.pos[2] += 20.0;
    model_changed(m);
    const double reference = 20.0;
    const Trace t = run_reference_step(m, reference, 1.0, 0.2, 1);
    printf("  %s step, in the air, 0 -> %.0f rad/s: %d side-steps at the limit, largest torque a step gave %.6g N m; "
           "%d sign changes after 0.2 s, overshoot %.3g rad/s\n", step_name(tolerance), reference, t.saturated_steps,
           t.largest_given, t.sign_changes, t.overshoot);
    CHECK(t.saturated_steps >= 4, "%s step: the drive saturates for several steps (%d side-steps)", step_name(tolerance),
          t.saturated_steps);
    CHECK(t.largest_given <= TORQUE_MAX * (1 + 1e-9), "%s step: no step gives the wheels more than the limit (%.9g N m)",
          step_name(tolerance), t.largest_given);
    CHECK(t.sign_changes == 0, "%s step: the tracker settles (%d sign changes of the torque after 0.2 s)",
          step_name(tolerance), t.sign_changes);
    CHECK(t.overshoot < 0.1 * reference, "%s step: the spin overshoots the reference by less than a tenth (%.3g rad/s)",
          step_name(tolerance), t.overshoot);
    model_free(m), free(m);
}

int main(void)
{
    const double tolerances[2] = {0.0, 4e-4};
    for (int i = 0; i < 2; ++i) {
        test_reference_step_on_the_ground(tolerances[i]);
        test_reference_step_in_the_air(tolerances[i]);
    }
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail ? 1 : 0;
}
