/*
 * The integrator (rover_internal.h): one communication step in internal
 * steps of at most solver.step, linearly implicit Euler in the velocities
 * (the stiff soil shear, normal stiffness and drive damping are
 * linearised), then the positions (and the wheels' spin angles) with the new
 * velocities (symplectic):
 *   (M + h D + h^2 K) du = h (Q - h K u),   u += du,   q += h u.
 * The contact memory (max sinkage, distance rolled), the multi-pass rut
 * and the PID integral are advanced explicitly once per internal step.
 * With solver.tolerance > 0, the automatic step instead (rover_auto_step.c).
 * Also, for both: the reuse of the end-of-step evaluation, the soil
 * memory's update, the checks that name the likely cause of a diverging
 * state, and the check that the rover has not overturned.
 */
#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>

#include "dense_lu.h"
#include "rover_internal.h"

/* ------------------------------------------------- diverging states */

/* The steepest terrain slope (rad) under the points (x, y) of n points,
 * and which point it is under. */
static double steepest_slope(const Model *m, const double (*xy)[3], int n, int *which)
{
    double steepest = 0.0;
    *which = 0;
    for (int k = 0; k < n; ++k) {
        double nrm[3];
        rover_terrain_at(m, xy[k][0], xy[k][1], nrm);
        const double slope = acos(fmax(-1.0, fmin(1.0, nrm[2])));
        if (slope > steepest) steepest = slope, *which = k;
    }
    return steepest;
}

/* Why the rover cannot stand or drive where it is, as far as the model can
 * tell: on terrain sloping more steeply than the soil's friction angle,
 * the Mohr-Coulomb shear strength of a cohesionless soil (F_taumax = C A +
 * Fn tan phi) cannot hold a wheel, and the rover slides and digs in
 * whatever the soil's stiffness.  Writes a clause into buf and returns 1
 * if the steepest slope under the given points exceeds soil.phi, else 0. */
int rover_slope_beyond_friction(const Model *m, const double (*xy)[3], char *buf, size_t n)
{
    int w;
    const double slope = steepest_slope(m, xy, NUM_WHEELS, &w);
    if (!(slope > m->p.soil_phi)) return 0;
    snprintf(buf, n,
             "the terrain under wheel %s slopes %.1f deg, steeper than the soil's friction angle soil.phi = "
             "%.1f deg: the soil cannot hold the rover there (terrain too steep)",
             rover_wheel_names[w], slope * 180.0 / M_PI, m->p.soil_phi * 180.0 / M_PI);
    return 1;
}

/* Speed (m/s) at which wheel w's hub moves into the ground, along the
 * terrain normal under it (negative: away from it). */
static double hub_approach_speed(const Model *m, const Eval *ev, int w)
{
    double n[3], v[3];
    rover_terrain_at(m, ev->hub[w][0], ev->hub[w][1], n);
    for (int i = 0; i < 3; ++i) {
        v[i] = 0.0;
        for (int k = 0; k < NU; ++k) v[i] += ev->Jv[BODY_WHEEL0 + w][i][k] * m->s.u[k];
    }
    return -v3_dot(n, v);
}

/* The sum of the unit terrain normals under the four hubs of ev. */
static void ground_normal_sum(const Eval *ev, double nrm[3])
{
    const double (*g)[3] = (const double (*)[3])ev->ground_normal;
    for (int i = 0; i < 3; ++i) nrm[i] = g[0][i] + g[1][i] + g[2][i] + g[3][i];
}

/* How the internal step is chosen, as a clause into buf: fixed, with
 * solver.step, or automatic, with solver.tolerance.  Returns 1 if fixed. */
static int step_setting(const Model *m, char *buf, size_t n)
{
    const int fixed = !(m->p.solver_tolerance > 0);
    if (fixed)
        snprintf(buf, n, "the internal step is fixed, solver.step = %g s", m->p.solver_step);
    else
        snprintf(buf, n, "the internal step is automatic, solver.tolerance = %g m/s", m->p.solver_tolerance);
    return fixed;
}

/* What the model knows of why the rover tumbled (overturned, or fell onto
 * a wheel), into buf: the steepest slope of the ground under the wheels
 * of ev and how the internal step is chosen, and the cause they point
 * at.  The line between the terrain and the rest: on a slope s, holding
 * the rover against sliding takes tan s / tan soil.phi of the grip the
 * soil's friction gives (Mohr-Coulomb, F_taumax = Fn tan phi); the terrain
 * is named where that exceeds one half, the slope taking the larger part
 * of the grip from the drive (so the rover slides and pitches over, as on
 * slopes near soil.phi).  On gentler ground the slope is the lesser part
 * of what tipped the rover, and what is left is the integration (a fixed
 * step too coarse for the soil's stiffness, or an automatic step's
 * solver.tolerance too loose for it) or a drive or drawbar load beyond
 * what holds the rover down. */
static void tumble_cause(const Model *m, const Eval *ev, char *buf, size_t n)
{
    int w;
    const double slope = steepest_slope(m, (const double (*)[3])ev->hub, NUM_WHEELS, &w);
    char step[96];
    const int fixed = step_setting(m, step, sizeof step);
    const double deg = slope * 180.0 / M_PI, phi_deg = m->p.soil_phi * 180.0 / M_PI;
    if (tan(slope) > 0.5 * tan(m->p.soil_phi)) {
        snprintf(buf, n,
                 "the ground under the wheels slopes up to %.1f deg, steep against soil.phi = %.1f deg; %s: it "
                 "tumbled, the terrain too steep or rough for the drive, not the soil's stiffness",
                 deg, phi_deg, step);
        return;
    }
    snprintf(buf, n,
             "the ground under the wheels slopes at most %.1f deg, too gentle against soil.phi = %.1f deg to make "
             "the rover slide or tip over; %s: not the terrain but %s or a drive or drawbar load beyond what holds "
             "the rover down",
             deg, phi_deg, step,
             fixed ? "a fixed step too coarse for the soil's stiffness (try the automatic step, solver.tolerance > 0, "
                     "or a smaller solver.step)"
                   : "a solver.tolerance too loose for the soil's stiffness (try a smaller one)");
}

/* Whether the rover, at the attitude R (world from chassis: its columns
 * are the chassis axes), has overturned: its up axis (the chassis z) more
 * than 90 deg from the ground's normal under it, the sum of the unit
 * terrain normals under the four hubs (of the evaluation ev, whose contacts
 * looked them up).  Upright, the rockers hold the wheels below the chassis, and
 * the wheels are the model's only contacts with the ground (the chassis
 * and the rockers have none); past 90 deg the chassis is the side that
 * faces the ground, so the wheels can no longer be the only contacts, and
 * left to the model the rover falls through the ground until its wheels
 * meet the soil from the wrong side.  Writes a clause into buf naming the
 * angle, the axis it turned about and why it tumbled (tumble_cause), and
 * returns 1 if so, else 0 (a dot product, unless it has overturned).  The
 * axis is a line, not a sense: past 180 deg a rover that pitched over
 * backwards reads as one pitching forwards, so only "end over end" (about
 * its lateral axis) or "sideways" (about its heading) is said. */
static int overturned(const Model *m, const double R[9], const Eval *ev, char *buf, size_t n)
{
    double nrm[3];
    ground_normal_sum(ev, nrm);
    const double up[3] = {R[2], R[5], R[8]};
    const double along = v3_dot(up, nrm);
    if (!(along < 0.0)) return 0;
    const double forward[3] = {R[0], R[3], R[6]}, lateral[3] = {R[1], R[4], R[7]};
    const double cos_tilt = along / sqrt(v3_dot(nrm, nrm));
    double axis[3];
    v3_cross(axis, nrm, up);                       /* the turn from the normal to the up axis is about this */
    const int end_over_end = fabs(v3_dot(axis, lateral)) >= fabs(v3_dot(axis, forward));
    char cause[400];
    tumble_cause(m, ev, cause, sizeof cause);
    snprintf(buf, n,
             "the rover has overturned: its up axis is %.0f deg from the ground's normal, turned %s; the wheels "
             "are the model's only contacts with the ground, and the chassis that now faces it has none (%s)",
             acos(fmax(-1.0, cos_tilt)) * 180.0 / M_PI,
             end_over_end ? "about its lateral axis (end over end)" : "about its heading (rolled sideways)", cause);
    return 1;
}

/* overturned at the attitude of the evaluation ev itself. */
static int rover_overturned(const Model *m, const Eval *ev, char *buf, size_t n)
{
    return overturned(m, ev->R, ev, buf, n);
}

int rover_attitude_is_upright(const Model *m, const double quat[4], const Eval *ev, double time, char *err, size_t n)
{
    const double w = quat[0], x = quat[1], y = quat[2], z = quat[3];
    double nrm[3];
    ground_normal_sum(ev, nrm);
    /* the chassis up axis, the third column of quat_to_m3's rotation */
    const double along = 2 * (x * z + w * y) * nrm[0] + 2 * (y * z - w * x) * nrm[1] + (1 - 2 * (x * x + y * y)) * nrm[2];
    if (!(along < 0.0)) return 1;
    double R[9];
    char why[640];
    quat_to_m3(R, quat);
    if (!overturned(m, R, ev, why, sizeof why)) return 1;
    return snprintf(err, n, "state diverged at t = %.4f s: %s", time, why), 0;
}

/* The likely cause of a wheel sinking deeper than its radius, from what
 * the model knows at that moment, the first that holds of:
 *  - the terrain under a wheel slopes more steeply than soil.phi (above);
 *  - the rover has overturned (above): whatever the soil, the wheels then
 *    meet it from above, and the speed at this moment says little, being
 *    what is left after the soil has braked the fall;
 *  - the wheel struck the ground faster than a fall from its own radius
 *    height, sqrt(2 g R): the rover fell or tumbled (why, tumble_cause),
 *    and no soil stops a wheel within its radius from such a speed at
 *    these stiffnesses;
 *  - otherwise the soil yields that far under the load: too soft, or, at
 *    a fixed step, the step too coarse for the soil's stiffness.  The
 *    clause names the step setting, and at a fixed step both causes and
 *    the run that tells them apart (the automatic step or a smaller
 *    solver.step: if it holds the wheel, the step was the cause).  No
 *    threshold picks one of the two: the step is linearly implicit in the
 *    contact's stiffness, stable for the linearised contact at any step,
 *    so the explicit limit (a step beyond 1/pi of the contact's natural
 *    period) does not bound it.  What a coarse step misses is the change
 *    of the stiffness within the step (the volumetric force stiffens as
 *    the wheel sinks, and a wheel entering the soil has none at the
 *    step's start), which the evaluation at one moment does not measure. */
static void sinkage_cause(const Model *m, const Eval *ev, int w, char *buf, size_t n)
{
    if (rover_slope_beyond_friction(m, (const double (*)[3])ev->hub, buf, n)) return;
    if (rover_overturned(m, ev, buf, n)) return;
    const double speed = hub_approach_speed(m, ev, w), fall = sqrt(2.0 * m->p.env_gravity * m->p.wheel_radius);
    if (speed > fall) {
        char cause[400];
        tumble_cause(m, ev, cause, sizeof cause);
        snprintf(buf, n,
                 "it struck the ground at %.2f m/s, faster than a fall from its radius height (%.2f m/s): the "
                 "rover fell or tumbled (%s)", speed, fall, cause);
        return;
    }
    char step[96];
    const char *const soft = "the soil is too soft for the load on these wheels (check soil.kh, soil.eta, "
                             "wheel.radius, wheel.width)";
    if (step_setting(m, step, sizeof step))
        snprintf(buf, n,
                 "%s, or %s, too coarse for the soil's stiffness (run it again at the automatic step, "
                 "solver.tolerance > 0, or a smaller solver.step: if that run holds the wheel, the step was the "
                 "cause)", soft, step);
    else
        snprintf(buf, n, "%s; %s", soft, step);
}

/* The largest magnitude of a generalised velocity (m/s or rad/s) a sane
 * state has: far beyond any speed the rover drives at or any spin its
 * motors give. */
#define VELOCITY_LIMIT 1e3

/* The largest rocker angle (rad, 69 deg) a sane state has.  The model puts
 * no stop on the rockers, so this stands for one: at it, each rocker has
 * turned so far against the chassis that the wheels at its two ends are
 * rover.wheelbase sin(1.2) apart in height (0.76 m at the defaults, more
 * than a wheel's diameter), and, the differential turning the other side's
 * rocker the other way, a front wheel stands as far from the other side's
 * front wheel. */
#define ROCKER_ANGLE_LIMIT 1.2

/* What each generalised velocity (see U_*) is, with its unit. */
static const char *const velocity_names[NU] = {
    "m/s, the chassis's velocity along world x",        "m/s, the chassis's velocity along world y",
    "m/s, the chassis's velocity along world z",        "rad/s, the chassis's angular velocity about world x",
    "rad/s, the chassis's angular velocity about world y", "rad/s, the chassis's angular velocity about world z",
    "rad/s, the rocker rate (the left rocker against the chassis, the right turning opposite)",
    "rad/s, the left wheels' spin relative to their rocker", "rad/s, the right wheels' spin relative to their rocker"};

/* x into buf with the fewest significant digits (at least %g's six) that
 * print its magnitude beyond limit, as it is: an angle just past the limit
 * would otherwise read as the limit itself. */
static void print_beyond(double x, double limit, char *buf, size_t n)
{
    for (int digits = 6; digits <= 17; ++digits) {
        snprintf(buf, n, "%.*g", digits, x);
        if (fabs(strtod(buf, NULL)) > limit) return;
    }
}

/* rover_motion_is_sane's message for a state that fails its checks. */
static NOINLINE int motion_failure(const Model *m, const Eval *ev, double time, const double pos[3],
                                   const double u[NU], double beta, char *err, size_t n)
{
    char cause[640];
    for (int i = 0; i < 3; ++i)
        if (!isfinite(pos[i])) return snprintf(err, n, "state diverged at t = %.4f s: position is not finite", time), 0;
    for (int i = 0; i < NU; ++i)
        if (!isfinite(u[i]) || fabs(u[i]) > VELOCITY_LIMIT) {
            char limit[64];
            if (isfinite(u[i]))
                snprintf(limit, sizeof limit, "beyond the magnitude of %g the model accepts", VELOCITY_LIMIT);
            else
                snprintf(limit, sizeof limit, "not finite (the model accepts magnitudes up to %g)", VELOCITY_LIMIT);
            tumble_cause(m, ev, cause, sizeof cause);
            return snprintf(err, n, "state diverged at t = %.4f s: velocity component %d = %g %s, %s; %s", time, i,
                            u[i], velocity_names[i], limit, cause), 0;
        }
    if (!isfinite(beta)) {
        tumble_cause(m, ev, cause, sizeof cause);
        return snprintf(err, n, "state diverged at t = %.4f s: rocker angle %g rad, not finite; %s", time, beta,
                        cause), 0;
    }
    if (fabs(beta) > ROCKER_ANGLE_LIMIT) {
        /* a positive angle turns the left rocker's front hub down (rover_evaluate's Ry(beta)) */
        char angle[32];
        print_beyond(beta, ROCKER_ANGLE_LIMIT, angle, sizeof angle);
        tumble_cause(m, ev, cause, sizeof cause);
        return snprintf(err, n,
                        "state diverged at t = %.4f s: rocker angle %s rad, beyond the %g rad (%.0f deg) the model "
                        "accepts: there the rockers have turned so far that the left front wheel stands %.2f m %s "
                        "the left rear and the right front (rover.wheelbase = %g m); %s",
                        time, angle, ROCKER_ANGLE_LIMIT, ROCKER_ANGLE_LIMIT * 180.0 / M_PI,
                        m->p.rover_wheelbase * sin(ROCKER_ANGLE_LIMIT), beta > 0 ? "below" : "above",
                        m->p.rover_wheelbase, cause), 0;
    }
    for (int w = 0; w < NUM_WHEELS; ++w)
        if (ev->wheel[w].sinkage >= m->p.wheel_radius) {
            sinkage_cause(m, ev, w, cause, sizeof cause);
            return snprintf(err, n,
                            "state diverged at t = %.4f s: wheel %s sank %.3f m, deeper than its radius "
                            "(wheel.radius = %.3f m); %s",
                            time, rover_wheel_names[w], ev->wheel[w].sinkage, m->p.wheel_radius, cause), 0;
        }
    return snprintf(err, n, "state diverged at t = %.4f s", time), 0;   /* not reached: the checks agree */
}

/* The checks as one expression without branches or calls, each a
 * comparison that a NaN fails (|x| <= DBL_MAX: x finite), so that a sane
 * state, every internal step's, costs no more; a state that fails them
 * goes to motion_failure for its message. */
int rover_motion_is_sane(const Model *m, const Eval *ev, double time, const double pos[3], const double u[NU],
                         double beta, char *err, size_t n)
{
    int sane = fabs(beta) <= ROCKER_ANGLE_LIMIT;
    for (int i = 0; i < 3; ++i) sane &= fabs(pos[i]) <= DBL_MAX;
    for (int i = 0; i < NU; ++i) sane &= fabs(u[i]) <= VELOCITY_LIMIT;
    for (int w = 0; w < NUM_WHEELS; ++w) sane &= !(ev->wheel[w].sinkage >= m->p.wheel_radius);
    return sane ? 1 : motion_failure(m, ev, time, pos, u, beta, err, n);
}

int rover_state_is_sane(const Model *m, const Eval *ev, char *err, size_t n)
{
    const State *s = &m->s;
    return rover_motion_is_sane(m, ev, s->time, s->pos, s->u, s->beta, err, n);
}

/* ------------------------------------------- reusing an evaluation */

/* The evaluation at the end of a communication step (for the outputs) is
 * that of the state the next step starts from.  Only its drive and drawbar
 * terms depend on the inputs, which the importer may change in between;
 * so the input-independent part (rover_evaluate_passive, with matrices) is
 * kept in m->eval and the next step's first substep adds the input terms
 * to it (rover_evaluate_inputs), the same operations in the same order as
 * evaluating afresh.  It is used only while m->eval_valid, which says that
 * nothing it was computed from has changed since: set where it is computed
 * (the end of model_do_step, model_initialize), cleared when a step starts
 * (the state moves on; a failed step leaves it cleared) and by every other
 * write of what rover_evaluate_passive reads: the parameters, the derived
 * data, the terrain, and the state's pos, quat, beta, u, spin_angle,
 * memory, path and rut.  Between steps only the life cycle
 * (model_initialize, model_reset, model_free) and the accessors write
 * them, and the accessors call model_changed after writing anything but an
 * input or the time (which the passive part does not read): a parameter or
 * String variable (fmi2SetReal, fmi2SetInteger, fmi2SetString) or a whole
 * state (fmi2SetFMUstate, also of a deserialised state).  A flag set by the
 * writers, not a comparison of the bytes, so that a step does not compare
 * and copy some 1.4 kB of parameters and state; code that writes the model's
 * fields directly (tests) calls model_changed as the accessors do. */

/* The end-of-step evaluation: the outputs, and m->eval kept for reuse. */
void rover_evaluate_end_of_step(Model *m)
{
    rover_evaluate_passive(m, &m->eval, 1);
    m->eval_valid = 1;
    rover_evaluate_inputs(m, &m->eval, 0);          /* the torques only: Q, D, K stay input-free */
    rover_outputs_from(m, &m->eval);
}

/* The contact memory (max sinkage, distance rolled) and the multi-pass
 * rut over a step of length h, explicitly, from the evaluation ev of the
 * step's start. */
void rover_advance_soil_memory(Model *m, const Eval *ev, const double sinkage[NUM_WHEELS], double h)
{
    State *s = &m->s;
    for (int w = 0; w < NUM_WHEELS; ++w)
        contact_memory_update(&m->d.contact, &s->memory[w], sinkage[w], ev->wheel[w].v_long, h);
    if (m->p.multipass_rutFraction > 0) {
        /* Record the residual rut each front wheel leaves along its forward travel. */
        for (int side = 0; side < 2; ++side) {
            const int front = 2 * side;
            const double v = ev->wheel[front].v_long;
            if (!(v > 0)) continue;
            const double depth = ev->wheel[front].sinkage > 0
                                     ? (1 - m->p.soil_gamma) * s->memory[front].zmax : 0.0;
            const long from = (long)floor(s->path[side] / RUT_SPACING) + 1;
            s->path[side] += v * h;
            const long to = (long)floor(s->path[side] / RUT_SPACING);
            for (long i = from; i <= to && i - from < RUT_SAMPLES; ++i)
                s->rut[side][((i % RUT_SAMPLES) + RUT_SAMPLES) % RUT_SAMPLES] = depth;
        }
    }
}

/* The linearly implicit Euler step's matrix and right-hand side from ev
 * (with its input terms, the drive's as ev->drive_limit says) over h. */
static void euler_system(const Model *m, const Eval *ev, double h, double A[NU][NU], double b[NU])
{
    const double (*K)[NU] = (const double (*)[NU])ev->K;
    double Ku[NU];
    step_matrix(ev, h, A);
    k_times(K, m->s.u, Ku);
    for (int i = 0; i < NU; ++i) b[i] = h * (ev->Q[i] - h * Ku[i]);
    if (m->p.drive_mode == DRIVE_PID)   /* the reference's share of the implicit PID integral */
        for (int k = 0; k < 2; ++k)
            if (ev->drive_limit[k] == 0) {
                const double ref = k == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
                b[U_SPIN_L + k] += h * h * (1.0 - m->p.drive_lossFraction) * m->p.drive_Ki * ref;
            }
}

/* The PID integral's increment over a step of h ending at the spin
 * omega, with anti-windup: it integrates the end-of-step error (as the
 * implicit stiffness of rover_evaluate_inputs assumes) while the step
 * takes the linear law, and while at the limit only where the error would
 * bring the torque back inside it. */
static double integral_increment(const Model *m, int side, double limit, double omega, double h)
{
    const double ref = side == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
    const double e = ref - omega;
    return limit == 0 || e * limit < 0 ? e * h : 0.0;
}

/* One internal step of length h from m->eval, the evaluation of the
 * current state with its input terms (rover_evaluate_passive and
 * rover_evaluate_inputs, with matrices); m->eval's drive terms are set to
 * the limit where the step takes it (rover_drive_at_limit), the rest is
 * only read.  The drive's limit is decided per side (rover_internal.h):
 * the step with the linear law, then, for a side whose end demand lies
 * beyond the limit, again with that side at the limit, until each side's
 * choice is consistent (the set at the limit only grows: at most three
 * solves). */
static int advance(Model *m, double h, char *err, size_t errlen)
{
    State *s = &m->s;
    Eval *ev = &m->eval;
    DenseLU lu;
    double (*A)[NU] = lu.a, b[NU];
    for (int pass = 0;; ++pass) {
        euler_system(m, ev, h, A, b);
        if (dense_lu_factor(&lu) != 0)
            return snprintf(err, errlen, "singular mass matrix at t = %.4f s", s->time), -1;
        dense_lu_solve(&lu, b);
        if (m->p.drive_mode == DRIVE_TORQUE || pass == 2) break;
        int changed = 0;
        for (int k = 0; k < 2; ++k) {
            if (ev->drive_limit[k] != 0) continue;
            const double omega = s->u[U_SPIN_L + k] + b[U_SPIN_L + k];
            const double integral = s->pid_integral[k] + integral_increment(m, k, 0, omega, h);
            double slope;
            const double demand = rover_drive_law(m, k, omega, integral, &slope);
            if (fabs(demand) > m->p.drive_torqueMax) rover_drive_at_limit(m, ev, k, demand > 0 ? 1 : -1), changed = 1;
        }
        if (!changed) break;
    }

    for (int i = 0; i < NU; ++i) s->u[i] += b[i];
    if (m->p.drive_mode == DRIVE_PID)
        for (int k = 0; k < 2; ++k) s->pid_integral[k] += integral_increment(m, k, ev->drive_limit[k], s->u[U_SPIN_L + k], h);
    /* What the wheels got over the step: the limit where the step took it, else the law's end torque. */
    rover_drive_torques(m, s->torque_applied);
    for (int k = 0; k < 2; ++k)
        if (ev->drive_limit[k] != 0) s->torque_applied[k] = ev->drive_limit[k] * m->p.drive_torqueMax;
    for (int i = 0; i < 3; ++i) s->pos[i] += h * s->u[U_VX + i];
    quat_integrate_world(s->quat, &s->u[U_WX], h);
    s->beta += h * s->u[U_BETA];
    for (int k = 0; k < 2; ++k) s->spin_angle[k] += h * s->u[U_SPIN_L + k];
    const double sinkage[NUM_WHEELS] = {ev->wheel[0].sinkage, ev->wheel[1].sinkage, ev->wheel[2].sinkage,
                                        ev->wheel[3].sinkage};
    rover_advance_soil_memory(m, ev, sinkage, h);
    s->time += h;
    if (!rover_state_is_sane(m, ev, err, errlen)) return -1;
    return 0;
}

/* One internal step of length h at a fixed step.  reuse: m->eval holds
 * the passive evaluation of the current state (model_do_step checked it). */
static int substep(Model *m, double h, int reuse, char *err, size_t errlen)
{
    if (!reuse) rover_evaluate_passive(m, &m->eval, 1);
    m->eval_valid = 0;                        /* it gets the input terms, and the state moves on */
    rover_evaluate_inputs(m, &m->eval, 1);
    return advance(m, h, err, errlen);
}

static int inputs_are_finite(const Inputs *in, char *err, size_t n)
{
    const double v[7] = {in->drawbarForce, in->torqueLeft, in->torqueRight, in->omegaRefLeft,
                         in->omegaRefRight, in->throttleLeft, in->throttleRight};
    static const char *const names[7] = {"drawbarForce", "torqueLeft", "torqueRight", "omegaRefLeft",
                                         "omegaRefRight", "throttleLeft", "throttleRight"};
    for (int i = 0; i < 7; ++i)
        if (!isfinite(v[i])) return snprintf(err, n, "input %s = %g is not finite", names[i], v[i]), 0;
    return 1;
}

/* One communication step at a fixed internal step, ending with the check
 * that the rover has not overturned (rover_overturned): past 90 deg the
 * state is one the model does not describe, so it is an error, not a
 * result.  Checked at the communication point, on the end-of-step
 * evaluation the step computes anyway (its attitude and the normals under
 * the wheels): a dot product a communication step rather than one an
 * internal step, and no result past an overturn reaches the importer (a
 * wheel that lands from above within the step meets the sinkage check
 * first, which names the overturn too).  A fixed step cannot take a step
 * again, shorter, so checking each internal step would only stop it up to
 * a communication step earlier.  The automatic step checks each internal
 * step's end instead, among the checks of a diverging state
 * (rover_attitude_is_upright), as a step whose end fails them is taken
 * again, shorter. */
static int do_step_fixed(Model *m, double h_comm, char *err, size_t errlen)
{
    const double t_end = m->s.time + h_comm;
    int n = (int)ceil(h_comm / m->p.solver_step - 1e-9);
    if (n < 1) n = 1;
    const double h = h_comm / n;
    const int reuse = m->eval_valid;
    for (int i = 0; i < n; ++i) {
        if (substep(m, h, reuse && i == 0, err, errlen) != 0) return -1;
        m->steps_taken++;
    }
    m->s.time = t_end;
    rover_evaluate_end_of_step(m);
    char why[640];
    if (rover_overturned(m, &m->eval, why, sizeof why)) {
        m->eval_valid = 0;                         /* a failed step leaves it cleared */
        return snprintf(err, errlen, "state diverged at t = %.4f s: %s", m->s.time, why), -1;
    }
    return 0;
}

int model_do_step(Model *m, double h_comm, char *err, size_t errlen)
{
    if (!inputs_are_finite(&m->in, err, errlen)) return -1;
    if (m->p.solver_tolerance > 0) return rover_do_step_automatic(m, h_comm, err, errlen);
    return do_step_fixed(m, h_comm, err, errlen);
}
