/*
 * The automatic step (rover_internal.h; solver.tolerance > 0, the
 * default): a two-stage linearly implicit step of second order on one
 * evaluation, with an embedded first-order solution whose difference
 * chooses the step size.  The fixed step, the reuse of the end-of-step
 * evaluation and the checks of a diverging state are rover_step.c's.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "dense_lu.h"
#include "rover_internal.h"

/* solver.tolerance > 0: a two-stage linearly implicit (Rosenbrock-type)
 * step of second order with an embedded first-order solution, the step
 * size chosen by their difference.  In the first-order form y' = f(y), y
 * the displacements (positions, attitude as a rotation vector, rocker and
 * spin angles), the PID integrals and the velocities, with J the Jacobian
 * of the step's start's evaluation (its damping D, stiffness K and the
 * drive's slopes: those the fixed step linearises), one step of h from y is
 *   (I - g h J) k1 = h f(y),   (I - g h J) k2 = k1 + h^2/(2 (1 - g)) d,
 *   y + g k1 + (1 - g) k2       (the solution the state moves on with),
 *   y + k1                      (the embedded solution),
 * with g = 1 - 1/sqrt(2) and d the correction below.  Without it the step
 * is y + h phi(hJ) f(y), phi(z) = (1 - g^2 z) / (1 - g z)^2 = 1 + z/2 +
 * O(z^2), second order if J were exact: y + h f + h^2/2 J f against the
 * exact y + h f + h^2/2 f' f.  Its stability function, (1 + (1 - 2 g) z) /
 * (1 - g z)^2, vanishes as z -> -inf (L-stable, as the fixed step's
 * linearly implicit Euler): a stiff soil mode a long step cannot resolve
 * is damped, not left ringing, and the embedded solution (1 / (1 - g z),
 * L-stable too) damps it alike, so it does not count as error.
 *
 * J is not exact: D and K leave out the shear's dependence on the
 * sinkage, the soil memory's on the motion, the mass matrix's change and
 * the gyroscopic terms, and what they leave out makes an O(h^2) local
 * error, (f' - J) f h^2/2.  The correction d estimates (f' - J) f from the
 * last accepted step (of h_last, with the same inputs): the change of the
 * generalised forces over it that the linearisation does not explain,
 *   R = Q(now) - Q(then) + K dq + D du - c (dq_spin + dI)  ~  M (f' - J) f h_last
 * (c: the PID integral's share of K, two_stage), so d = M^-1 R / h_last:
 * in the second stage, solved with M + g h D + ... ((I - g h J)^-1 = I +
 * O(h)) and weighted 1 - g, it adds h^2/2 d + O(h^3).  It treats what J
 * leaves out explicitly, over two steps (as Adams-Bashforth does), which
 * holds as long as that part is slow beside the step: where it is not, the
 * extrapolation feeds the motion it extrapolates, so its change from one
 * step to the next counts in the error estimate (error_ratio) and the step
 * shortens until it is slow again.  So at a tolerance loose enough for
 * 20 ms steps the step runs over every declared parameter range, the
 * stiffest soil too (tests/python/test_fmu_accuracy.py).  The first step after
 * initialisation, after the inputs change (their forces are not in the last
 * step's) or after a state with none is restored goes without it, at first
 * order.
 *
 * Both stages share one matrix, M + g h D + (g h)^2 K, factorised once,
 * and one evaluation of f and J, the step's start's, which is the
 * end-of-step evaluation of the step before: an accepted step costs one
 * evaluation with Jacobians (of its end), one factorisation and two solves.
 *
 * The contact memory and the rut are advanced explicitly (a running
 * maximum and clamps are not smooth in time), as in the fixed step, but
 * with the sinkage over the step rather than its start's: the end's where
 * the wheel sinks deeper than its memory (the memory is then the end's
 * sinkage), the mean of the start's and the end's where the memory relaxes
 * towards a shallower sinkage.  With the start's the memory would lag one
 * step behind, an O(h) error.  The end's sinkage is the end state's own:
 * the end-of-step evaluation computes its geometry (the kinematics and the
 * terrain under the hubs, which do not depend on the memory) first, the
 * memory moves on with the sinkage on it (sinkages_at_end), and the
 * evaluation's forces follow, so the terrain is looked up once a step.
 *
 * The step is accepted when the largest component of the difference of
 * the two solutions' velocities, plus the correction's change from the
 * last step (error_ratio), (angular rates as the speed they give at a
 * lever of wheel.radius for the spins, half rover.wheelbase for the
 * chassis and rocker rates) is within solver.tolerance (m/s); that is the
 * embedded solution's local error, which grows as h^2, so the next step is
 * 0.9 h sqrt(tol / est), within 0.2..2 times this one and at most
 * solver.step.  A rejected step, or one whose state fails the checks of a
 * diverging state, is taken again from the step's start (whose evaluation
 * it has not changed), shorter, down to STEP_MIN, below which that failure
 * is reported. */
#define STEP_FIRST 1e-3     /* s, the first step after initialisation */
#define STEP_MIN 1e-6       /* s */
#define ROS_GAMMA 0.29289321881345247560   /* 1 - 1/sqrt(2): the root of g^2 - 2 g + 1/2 = 0 below 1/2 */

/* What one automatic step of h changes: the second-order solution's
 * increments, and the embedded first-order solution's of the velocities. */
typedef struct {
    double du[NU];                 /* velocities */
    double dq[NU];                 /* displacements along the velocities: position (m), rotation vector
                                    * (rad, world), rocker angle, spin angles (rad) */
    double dI[2];                  /* PID integrals, rad */
    double du_first[NU];           /* the first-order solution's velocities */
    double drive_torque[2];        /* N m, the drive torque the step gives each side's wheels (motor side) */
    double correction[NU];         /* the correction's share of du over h^2 (m/s^3, rad/s^3) */
    int has_correction;            /* 0: the step went without it (correction[] unset) */
} StepIncrement;

/* The two stages from the state m->s and its evaluation ev (with its input
 * terms and matrices): writes inc; returns -1 if the matrix is singular.
 *
 * With r = (r_q, r_I, r_u) a stage's right-hand side, (I - g h J) k = r
 * reads, for the velocities (the displacements and integrals following),
 *   (M + g h D + (g h)^2 K) k_u = M r_u - g h K r_q + g h c (r_q,spin + r_I),
 *   k_q = r_q + g h k_u,   k_I = r_I - g h a k_u,spin,
 * where c = (1 - drive.lossFraction) drive.Ki is the PID integral's share
 * of K's spin entries (where ev's torque is not saturated, as K has it) and
 * a = 1 where the integral integrates (anti-windup, decided at the step's
 * start), the integral's rate being a (ref - omega).  The first stage's
 * r = h f(y) = (h u, h a (ref - omega), h M^-1 Q), the second's r = k1 plus
 * the correction in r_u.  Out of line: inlined, its caller grew too large
 * for GCC to keep its values in registers (it and dense_lu_factor out of
 * line: 330 fewer instructions an accepted step, 4 % less CPU time). */
static NOINLINE int two_stage(const Model *m, const Eval *ev, double h, StepIncrement *inc)
{
    const State *s = &m->s;
    const double g = ROS_GAMMA * h;
    const double (*K)[NU] = (const double (*)[NU])ev->K;
    DenseLU lu;
    double (*A)[NU] = lu.a, k1u[NU], k1q[NU], k1I[2], k2u[NU];
    step_matrix(ev, g, A);
    double diag[NU];               /* the matrix's diagonal, for the correction's share of the error */
    for (int i = 0; i < NU; ++i) diag[i] = A[i][i];
    if (dense_lu_factor(&lu) != 0) return -1;

    double c[2] = {0, 0}, rate[2] = {0, 0}, active[2] = {0, 0};
    if (m->p.drive_mode == DRIVE_PID)
        for (int k = 0; k < 2; ++k) {
            const double ref = k == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
            const double e = ref - s->u[U_SPIN_L + k], limit = ev->drive_limit[k];
            if (limit == 0) c[k] = (1.0 - m->p.drive_lossFraction) * m->p.drive_Ki;
            if (limit == 0 || e * limit < 0) active[k] = 1, rate[k] = e;
        }

    /* first stage: r = h f(y) */
    double Ku[NU];
    k_times(K, s->u, Ku);
    for (int i = 0; i < NU; ++i) k1u[i] = h * ev->Q[i] - g * h * Ku[i];
    for (int k = 0; k < 2; ++k) k1u[U_SPIN_L + k] += g * c[k] * h * (s->u[U_SPIN_L + k] + rate[k]);
    dense_lu_solve(&lu, k1u);
    for (int j = 0; j < NU; ++j) k1q[j] = h * s->u[j] + g * k1u[j];
    for (int k = 0; k < 2; ++k) k1I[k] = h * rate[k] - g * active[k] * k1u[U_SPIN_L + k];

    /* second stage: r = k1 */
    double Kq[NU], Mk[NU];
    k_times(K, k1q, Kq);
    /* M k1u by M's rows scaled and added (M is symmetric, its lower triangle the upper's copy:
     * each entry gets the products of its dot product in the same order, in a loop GCC
     * vectorises) */
    for (int i = 0; i < NU; ++i) Mk[i] = 0;
    for (int j = 0; j < NU; ++j)
        for (int i = 0; i < NU; ++i) Mk[i] += ev->M[j][i] * k1u[j];
    for (int i = 0; i < NU; ++i) k2u[i] = Mk[i] - g * Kq[i];
    for (int k = 0; k < 2; ++k) k2u[U_SPIN_L + k] += g * c[k] * (k1q[U_SPIN_L + k] + k1I[k]);
    /* the last step's forces are those of this step's drive terms only where it took the same */
    inc->has_correction = s->last_step > 0 && s->last_drive_limit[0] == ev->drive_limit[0] &&
                          s->last_drive_limit[1] == ev->drive_limit[1];
    if (inc->has_correction) {
        /* the correction (above): R from the last step, h^2 / (2 (1 - g)) M^-1 R / h_last added to
         * r_u, so that k2's weight 1 - g makes it h^2/2 M^-1 R / h_last in the solution; its share
         * of the velocities, for the error estimate (error_ratio), by the matrix's diagonal alone
         * (an estimate of a size needs no second solve) */
        double R[NU];
        for (int i = 0; i < NU; ++i) {
            /* K dq + D du, K's structural zeros (k_times) left out (0 dq + D du is D du) */
            double r = ev->Q[i] - s->last_Q[i];
            if (i < K_BLOCK) {
                for (int j = 0; j < K_BLOCK; ++j) r += K[i][j] * s->last_dq[j] + ev->D[i][j] * s->last_du[j];
                for (int j = K_BLOCK; j < NU; ++j) r += ev->D[i][j] * s->last_du[j];
            } else {
                for (int j = 0; j < NU; ++j)
                    r += j == i ? K[i][j] * s->last_dq[j] + ev->D[i][j] * s->last_du[j] : ev->D[i][j] * s->last_du[j];
            }
            R[i] = r;
        }
        for (int k = 0; k < 2; ++k) R[U_SPIN_L + k] -= c[k] * (s->last_dq[U_SPIN_L + k] + s->last_dI[k]);
        const double f = h * h / (2.0 * (1.0 - ROS_GAMMA) * s->last_step);
        const double share = (1.0 - ROS_GAMMA) * f / (h * h);
        for (int i = 0; i < NU; ++i) {
            k2u[i] += f * R[i];
            inc->correction[i] = share * R[i] / diag[i];
        }
    }
    dense_lu_solve(&lu, k2u);

    /* y + g k1 + (1 - g) k2, k2's displacements and integrals from its velocities */
    const double b1 = ROS_GAMMA, b2 = 1.0 - ROS_GAMMA;
    for (int j = 0; j < NU; ++j) {
        const double k2q = k1q[j] + g * k2u[j];
        inc->du[j] = b1 * k1u[j] + b2 * k2u[j];
        inc->dq[j] = b1 * k1q[j] + b2 * k2q;
        inc->du_first[j] = k1u[j];
    }
    for (int k = 0; k < 2; ++k) {
        const double k2I = k1I[k] - g * active[k] * k2u[U_SPIN_L + k];
        inc->dI[k] = b1 * k1I[k] + b2 * k2I;
    }
    /* The drive torque the step gives each side's wheels: the drive's share of the spin row of
     * M du over h (consistent_two_stage).  Stage one's share of M k1u is h (1 - loss) T0 +
     * g c rate h - g (d + g c) k1u (d = -(1 - loss) slope, D's drive entry; the PID integral's
     * g h c u of K u and of the right-hand side cancel), stage two adds g c k1I - g (d + g c) k2u
     * to it (the correction's drive share is zero: the law is linear, and a step with the last
     * step's drive terms is the only one that takes it). */
    const double transmitted = 1.0 - m->p.drive_lossFraction;
    for (int k = 0; k < 2; ++k) {
        const int sp = U_SPIN_L + k;
        if (ev->drive_limit[k] != 0) {
            inc->drive_torque[k] = ev->drive_limit[k] * m->p.drive_torqueMax;
            continue;
        }
        const double d = -transmitted * ev->torque_slope[k], stiff = d + g * c[k];
        const double stage1 = h * transmitted * ev->torque_demand[k] + g * c[k] * rate[k] * h - g * stiff * k1u[sp];
        const double stage2 = stage1 + g * c[k] * k1I[k] - g * stiff * k2u[sp];
        inc->drive_torque[k] = (b1 * stage1 + b2 * stage2) / (h * transmitted);
    }
    return 0;
}

/* The two stages with each side's drive at the linear law or at its
 * limit, consistently (rover_internal.h): first with ev's drive terms (the
 * linear law), then, for a side whose law gives its wheels a torque beyond
 * the limit over the step, again with that side at the limit of that
 * torque's sign, until each side's choice is consistent (the set at the
 * limit only grows: at most three passes).  The torque the step gives the
 * wheels is the law's along the step as the stages weigh it
 * (StepIncrement.drive_torque), not the law's at the step's end as in the
 * fixed step: on a stiff tracker (drive.Kp h over the wheels' inertia
 * beyond 2) the second-order solution's stability function is negative,
 * so the step's end lies beyond the reference, and the end's demand may
 * lie beyond the opposite limit while the step pushed the wheels towards
 * the reference; at the limit of the end demand's sign the step would push
 * them away from it.  ev's drive terms are left as the step took them;
 * saved, the linear law's are restored by restore_drive_terms. */
typedef struct {
    double Q[2], D[2], K[2];
} DriveTerms;

static void save_drive_terms(const Eval *ev, DriveTerms *t)
{
    for (int k = 0; k < 2; ++k) {
        const int sp = U_SPIN_L + k;
        t->Q[k] = ev->Q[sp], t->D[k] = ev->D[sp][sp], t->K[k] = ev->K[sp][sp];
    }
}

static void restore_drive_terms(Eval *ev, const DriveTerms *t)
{
    for (int k = 0; k < 2; ++k) {
        const int sp = U_SPIN_L + k;
        ev->Q[sp] = t->Q[k], ev->D[sp][sp] = t->D[k], ev->K[sp][sp] = t->K[k];
        ev->drive_limit[k] = 0;
    }
}

static int consistent_two_stage(const Model *m, Eval *ev, double h, StepIncrement *inc)
{
    for (int pass = 0;; ++pass) {
        if (two_stage(m, ev, h, inc) != 0) return -1;
        if (m->p.drive_mode == DRIVE_TORQUE || pass == 2) return 0;
        int changed = 0;
        for (int k = 0; k < 2; ++k) {
            const double torque = inc->drive_torque[k];
            if (ev->drive_limit[k] != 0 || !(fabs(torque) > m->p.drive_torqueMax)) continue;
            rover_drive_at_limit(m, ev, k, torque > 0 ? 1 : -1);
            changed = 1;
        }
        if (!changed) return 0;
    }
}

/* The step's local error in its velocities (levers above), relative to
 * solver.tolerance: the step of h is accepted at <= 1.
 *
 * Per velocity, the difference of the two solutions plus the error of the
 * correction.  The correction holds (f' - J) f constant from the last step
 * to this one, an explicit extrapolation; its error is its change from the
 * last step's to this one's, h^2 times that of correction[] (its share of
 * the velocities over h^2).  The embedded solution does not see it: both
 * solutions share J, and the correction is what stands for J's error.  Where
 * what J leaves out varies as fast as the step (on the stiffest soils at a
 * loose tolerance, the chassis pitching on its wheels in a few steps a
 * period), the extrapolation is outside its stability region and feeds the
 * motion it extrapolates, which then grows step by step; its change is then
 * as large as itself, and so counted the step shortens until what it
 * extrapolates is slow beside the step again.  Where it barely changes, as
 * over a run's smooth stretches, it adds little. */
static double error_ratio(const Model *m, const StepIncrement *inc, double h)
{
    const double half_base = 0.5 * m->p.rover_wheelbase, R = m->p.wheel_radius;
    const double lever[NU] = {1, 1, 1, half_base, half_base, half_base, half_base, R, R};
    const int changed = inc->has_correction && m->s.last_correction_valid;
    const double h2 = h * h;
    double worst = 0;
    for (int i = 0; i < NU; ++i) {
        double v = fabs(inc->du[i] - inc->du_first[i]);
        if (changed) v += h2 * fabs(inc->correction[i] - m->s.last_correction[i]);
        v *= lever[i];
        if (!(v <= worst)) worst = v;                  /* NaN counts as the worst */
    }
    return worst / m->p.solver_tolerance;
}

/* The wheels' sinkages at the end of the step, for the soil memory, from
 * the end's geometry in ev (rover_evaluate_geometry; ev->wheel still the
 * start's contacts): each the sinkage the end's evaluation computes
 * (rover_wheel_contact.c: R less the hub's height above the terrain's
 * tangent plane under it, along the plane's normal, over the length of
 * that normal within the wheel's mid-plane, less a rear wheel's rut), with
 * the start's rut, which the memory's update moves on, and the start's
 * sinkage for a wheel lying on its side. */
static void sinkages_at_end(const Model *m, const Eval *ev, double sinkage[NUM_WHEELS])
{
    const double R = m->d.contact.radius;
    for (int w = 0; w < NUM_WHEELS; ++w) {
        const double *n = ev->ground_normal[w];
        const double hub_height = (ev->hub[w][2] - ev->ground_z[w]) * n[2];
        double np[3];
        v3_copy(np, n);
        v3_axpy(np, -v3_dot(n, ev->e), ev->e);
        const double in_plane = v3_norm(np);
        sinkage[w] = in_plane < 1e-6 ? ev->wheel[w].sinkage : R - hub_height / in_plane - ev->wheel[w].rut;
    }
}

/* Moves the state on by inc over h (ev: the step's start's evaluation, for
 * the soil memory and the checks); -1 with a message, the state and ev
 * left as they were, if the new state would fail the checks of a diverging
 * state (they read its time, position, velocities, rocker angle and
 * attitude, the last over the ground under the start's wheels, checked
 * before anything is written: so a rejected step needs no copy of the
 * state).  On success ev holds the end's geometry (rover_evaluate_geometry)
 * beside the start's contacts, for rover_evaluate_forces to complete. */
static int apply_increment(Model *m, Eval *ev, const StepIncrement *inc, double h, char *err, size_t errlen)
{
    State *s = &m->s;
    double u[NU], pos[3];
    for (int i = 0; i < NU; ++i) u[i] = s->u[i] + inc->du[i];
    for (int i = 0; i < 3; ++i) pos[i] = s->pos[i] + inc->dq[U_VX + i];
    const double beta = s->beta + inc->dq[U_BETA];
    double quat[4] = {s->quat[0], s->quat[1], s->quat[2], s->quat[3]};
    quat_integrate_world(quat, &inc->dq[U_WX], 1.0);
    if (!rover_motion_is_sane(m, ev, s->time + h, pos, u, beta, err, errlen) ||
        !rover_attitude_is_upright(m, quat, ev, s->time + h, err, errlen))
        return -1;
    memcpy(s->u, u, sizeof s->u);
    memcpy(s->pos, pos, sizeof s->pos);
    memcpy(s->quat, quat, sizeof s->quat);
    s->beta = beta;
    for (int k = 0; k < 2; ++k) s->spin_angle[k] += inc->dq[U_SPIN_L + k];
    if (m->p.drive_mode == DRIVE_PID)
        for (int k = 0; k < 2; ++k) s->pid_integral[k] += inc->dI[k];
    /* What the wheels got over the step: the limit where the step took it, else the law's end torque. */
    rover_drive_torques(m, s->torque_applied);
    for (int k = 0; k < 2; ++k)
        if (ev->drive_limit[k] != 0) s->torque_applied[k] = ev->drive_limit[k] * m->p.drive_torqueMax;
    /* The soil memory over the step: where the wheel ends deeper than its memory, the memory is
     * the end's sinkage; where it stays shallower, the memory relaxes towards the sinkage, and
     * the mean of the start's and the end's is its mean over the step (trapezoidal rule). */
    double sinkage[NUM_WHEELS], end[NUM_WHEELS];
    rover_evaluate_geometry(m, ev);
    sinkages_at_end(m, ev, end);
    for (int w = 0; w < NUM_WHEELS; ++w) {
        const double z0 = ev->wheel[w].sinkage, z1 = end[w], zmax = s->memory[w].zmax;
        const double mean = 0.5 * (z0 + z1);
        /* fmin(mean, zmax) without its library call (a NaN zmax gives the mean, as fmin does) */
        sinkage[w] = z1 >= zmax || !(z0 > 0) || !(z1 > 0) ? z1 : !(mean >= zmax) ? mean : zmax;
    }
    rover_advance_soil_memory(m, ev, sinkage, h);
    s->time += h;
    return 0;
}

int rover_do_step_automatic(Model *m, double h_comm, char *err, size_t errlen)
{
    State *s = &m->s;
    Eval *ev = &m->eval;
    const double t_end = s->time + h_comm;
    if (!(h_comm > 0)) return snprintf(err, errlen, "communication step %g s must be positive", h_comm), -1;
    double h = fmin_of(m->p.solver_step, s->step_next > 0 ? s->step_next : STEP_FIRST);
    if (!m->eval_valid) rover_evaluate_passive(m, ev, 1);
    m->eval_valid = 0;
    rover_evaluate_inputs(m, ev, 1);
    if (memcmp(&s->last_inputs, &m->in, sizeof m->in) != 0) s->last_step = 0;   /* its forces had other inputs */
    double remaining = h_comm;
    while (remaining > 0) {
        const double n = ceil(remaining / h - 1e-9);     /* steps of at most h to the communication point */
        const int last = n <= 1;
        const double hs = last ? remaining : remaining / n;
        /* at the smallest step by intent (h), not by hs, which round-off can leave just above it:
         * compared by hs, a step that must be accepted there would be rejected for ever */
        const int smallest = h <= STEP_MIN;
        char why[768];
        StepIncrement inc;
        double ratio = HUGE_VAL;
        DriveTerms linear_law;
        save_drive_terms(ev, &linear_law);
        int ok = consistent_two_stage(m, ev, hs, &inc) == 0;
        if (!ok) snprintf(why, sizeof why, "singular mass matrix at t = %.4f s", s->time);
        if (ok) {
            ratio = error_ratio(m, &inc, hs);
            if (ratio <= 1.0 || smallest) {
                ok = apply_increment(m, ev, &inc, hs, why, sizeof why) == 0;
                if (ok) {
                    s->last_step = hs;
                    memcpy(s->last_Q, ev->Q, sizeof s->last_Q);
                    memcpy(s->last_dq, inc.dq, sizeof s->last_dq);
                    memcpy(s->last_du, inc.du, sizeof s->last_du);
                    memcpy(s->last_dI, inc.dI, sizeof s->last_dI);
                    if (inc.has_correction) memcpy(s->last_correction, inc.correction, sizeof s->last_correction);
                    s->last_correction_valid = inc.has_correction;
                    s->last_inputs = m->in;
                    for (int k = 0; k < 2; ++k) s->last_drive_limit[k] = ev->drive_limit[k];
                    const double grow = ratio > 0 ? 0.9 / sqrt(ratio) : 2.0;
                    /* never below STEP_MIN: a step accepted there with a large error would otherwise
                     * shrink the next towards 0, and the step would never reach its end */
                    h = fmax_of(STEP_MIN, fmin_of(m->p.solver_step, hs * fmin_of(2.0, fmax_of(0.2, grow))));
                    s->step_next = h;
                    m->steps_taken++;
                    remaining = last ? 0.0 : remaining - hs;
                    rover_evaluate_forces(m, ev, 1);        /* the next step's start, on its geometry */
                    if (!last) rover_evaluate_inputs(m, ev, 1);
                    continue;
                }
                /* the state is the step's start's still (apply_increment wrote nothing), as is ev */
            }
        }
        /* rejected: again from the step's start (with the drive's linear law), shorter */
        restore_drive_terms(ev, &linear_law);
        if (smallest) return snprintf(err, errlen, "%s", why), -1;   /* a state diverging at any step */
        m->steps_rejected++;
        h = fmax_of(STEP_MIN, hs * (ok && isfinite(ratio) ? fmax_of(0.2, 0.9 / sqrt(ratio)) : 0.25));
    }
    s->time = t_end;
    m->eval_valid = 1;                               /* the end's passive evaluation, for the next step */
    rover_evaluate_inputs(m, ev, 0);                 /* the torques only: Q, D, K stay input-free */
    rover_outputs_from(m, ev);
    return 0;
}
