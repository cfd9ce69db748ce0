/*
 * The rover model's set-up (rover_internal.h): parameter checks, derived
 * masses and geometry, the contact laws' constants, the terrain, the
 * static equilibrium the rover starts from, and the life cycle and hooks
 * the FMI layer calls (model.h).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rover_internal.h"

const char *const rover_wheel_names[NUM_WHEELS] = {"FL", "RL", "FR", "RR"};

/* ------------------------------------------------------------ set-up */

static int check_params(const Params *p, char *err, size_t n)
{
    const double wheels = 4 * p->wheel_mass, rockers = 2 * p->rover_rockerMass;
    if (!(p->wheel_mass > 0)) return snprintf(err, n, "wheel.mass = %g must be positive", p->wheel_mass), -1;
    if (!(p->wheel_inertia > 0)) return snprintf(err, n, "wheel.inertia = %g must be positive", p->wheel_inertia), -1;
    if (!(p->rover_rockerMass > 0)) return snprintf(err, n, "rover.rockerMass = %g must be positive", p->rover_rockerMass), -1;
    if (!(p->rover_mass > wheels + rockers))
        return snprintf(err, n, "rover.mass = %g must exceed the wheels' and rockers' mass, 4 wheel.mass + "
                        "2 rover.rockerMass = %g kg", p->rover_mass, wheels + rockers), -1;
    if (!(p->rover_mass + p->rover_payload > wheels + rockers))
        return snprintf(err, n, "rover.mass + rover.payload = %g + %g must exceed the wheels' and rockers' mass, "
                        "4 wheel.mass + 2 rover.rockerMass = %g kg", p->rover_mass, p->rover_payload, wheels + rockers), -1;
    if (!(p->rover_wheelbase > 0)) return snprintf(err, n, "rover.wheelbase = %g must be positive", p->rover_wheelbase), -1;
    if (!(p->rover_track > p->wheel_width))
        return snprintf(err, n, "rover.track = %g must exceed wheel.width = %g", p->rover_track, p->wheel_width), -1;
    if (!(p->env_gravity > 0)) return snprintf(err, n, "env.gravity = %g must be positive", p->env_gravity), -1;
    if (!(p->solver_step > 0)) return snprintf(err, n, "solver.step = %g must be positive", p->solver_step), -1;
    if (!(p->solver_tolerance >= 0)) return snprintf(err, n, "solver.tolerance = %g must not be negative", p->solver_tolerance), -1;
    if (p->drive_mode == DRIVE_MOTOR) {
        if (!(p->motor_resistance > 0)) return snprintf(err, n, "motor.resistance = %g must be positive", p->motor_resistance), -1;
        if (!(p->motor_gearRatio > 0)) return snprintf(err, n, "motor.gearRatio = %g must be positive", p->motor_gearRatio), -1;
    }
    return 0;
}

static void derive(Model *m)
{
    const Params *p = &m->p;
    Derived *d = &m->d;
    const double L = p->rover_wheelbase, W = p->rover_track, hp = p->rover_pivotHeight;
    /* Assumption: a payload sits at the chassis's centre of gravity and is spread like the chassis's own mass. */
    d->chassis_mass = p->rover_mass + p->rover_payload - 4 * p->wheel_mass - 2 * p->rover_rockerMass;
    /* Assumption (the paper gives no inertias): chassis inertia of a uniform 1.38 x 1.6 x 0.5 m box. */
    const double bx = 1.38, by = 1.6, bz = 0.5;
    d->chassis_inertia[0] = d->chassis_mass * (by * by + bz * bz) / 12;
    d->chassis_inertia[1] = d->chassis_mass * (bx * bx + bz * bz) / 12;
    d->chassis_inertia[2] = d->chassis_mass * (bx * bx + by * by) / 12;
    /* Assumption: a rocker is a slender beam between its two axles. */
    d->rocker_inertia[0] = 0.02 * p->rover_rockerMass;
    d->rocker_inertia[1] = p->rover_rockerMass * L * L / 12;
    d->rocker_inertia[2] = d->rocker_inertia[1];
    /* Assumption: a wheel is a disc for the transverse axes. */
    d->wheel_inertia_transverse = 0.5 * p->wheel_inertia + p->wheel_mass * p->wheel_width * p->wheel_width / 12;
    /* Chassis frame: origin midway between the rocker pivots, x forward, y left, z up. */
    v3_set(d->chassis_cg, 0, 0, p->rover_cgHeight - hp);
    v3_set(d->pivot[SIDE_LEFT], 0, W / 2, 0);
    v3_set(d->pivot[SIDE_RIGHT], 0, -W / 2, 0);
    v3_set(d->rocker_cg, 0, 0, -hp);
    v3_set(d->hub[0], L / 2, 0, -hp);
    v3_set(d->hub[1], -L / 2, 0, -hp);
    rover_side_body(p, d, &d->side_mass, d->side_cg, d->side_I);
}

/* --------------------------------------------------- static equilibrium */

/* Places the chassis at height z with roll, pitch (yaw from init) and
 * rocker angle beta, at rest, with the soil memory of a wheel pressed
 * straight down (or rolling, when init.vx != 0). */
static void place(Model *m, const double x[4])
{
    State *s = &m->s;
    s->pos[0] = m->p.init_x;
    s->pos[1] = m->p.init_y;
    s->pos[2] = x[0];
    quat_from_euler(s->quat, x[1], x[2], m->p.init_yaw);
    s->beta = x[3];
    Eval ev;
    rover_evaluate(m, &ev, 0);
    for (int w = 0; w < NUM_WHEELS; ++w) {
        double z = ev.wheel[w].sinkage;
        s->memory[w].zmax = z > 0 ? z : 0;
        double L = z > 0 ? m->p.wheel_radius * sin(acos(1 - fmin(z, m->p.wheel_radius) / m->p.wheel_radius)) : 0;
        s->memory[w].travel = m->p.init_vx > 0 ? L : m->p.init_vx < 0 ? -L : 0;
    }
}

/* Fills each side's rut memory with the residual rut its front wheel leaves at its
 * present sinkage, (1 - gamma) zmax as the step records it, over the whole memory,
 * so the rear wheel (one wheelbase behind) stands in it. */
static void prefill_rut(Model *m)
{
    State *s = &m->s;
    for (int side = 0; side < 2; ++side) {
        const double zmax = s->memory[2 * side].zmax;
        const double depth = zmax > 0 ? (1 - m->p.soil_gamma) * zmax : 0.0;
        s->path[side] = (RUT_SAMPLES - 2) * RUT_SPACING;
        for (int i = 0; i < RUT_SAMPLES; ++i) s->rut[side][i] = depth;
    }
}

/* Residual: the generalised forces along z, roll, pitch and beta at rest. */
static void equilibrium_residual(Model *m, const double x[4], double r[4])
{
    place(m, x);
    Eval ev;
    double saved[NU];
    memcpy(saved, m->s.u, sizeof saved);
    memset(m->s.u, 0, sizeof m->s.u);
    rover_evaluate(m, &ev, 1);
    memcpy(m->s.u, saved, sizeof saved);
    r[0] = ev.Q[U_VX + 2];
    r[1] = ev.Q[U_WX + 0];
    r[2] = ev.Q[U_WX + 1];
    r[3] = ev.Q[U_BETA];
}

static int solve4(double A[4][4], double b[4])
{
    for (int c = 0; c < 4; ++c) {
        int piv = c;
        for (int r = c + 1; r < 4; ++r)
            if (fabs(A[r][c]) > fabs(A[piv][c])) piv = r;
        if (!(fabs(A[piv][c]) > 1e-300)) return -1;
        for (int k = 0; k < 4; ++k) { double t = A[c][k]; A[c][k] = A[piv][k]; A[piv][k] = t; }
        double t = b[c]; b[c] = b[piv]; b[piv] = t;
        for (int r = c + 1; r < 4; ++r) {
            double f = A[r][c] / A[c][c];
            for (int k = c; k < 4; ++k) A[r][k] -= f * A[c][k];
            b[r] -= f * b[c];
        }
    }
    for (int c = 3; c >= 0; --c) {
        double s = b[c];
        for (int k = c + 1; k < 4; ++k) s -= A[c][k] * b[k];
        b[c] = s / A[c][c];
    }
    return 0;
}

static double norm4(const double r[4], double weight, double moment_scale)
{
    return sqrt(r[0] * r[0] / (weight * weight) +
                (r[1] * r[1] + r[2] * r[2] + r[3] * r[3]) / (moment_scale * moment_scale));
}

/* World (x, y) of wheel w's nominal position at the start pose (init.x,
 * init.y, init.yaw), in xy[0..1]; xy[2] = 0. */
static void nominal_wheel_position(const Params *p, int w, double xy[3])
{
    const double cy = cos(p->init_yaw), sy = sin(p->init_yaw);
    const double lx = (w % 2 == 0 ? 0.5 : -0.5) * p->rover_wheelbase;
    const double ly = (side_of(w) == SIDE_LEFT ? 0.5 : -0.5) * p->rover_track;
    xy[0] = p->init_x + cy * lx - sy * ly;
    xy[1] = p->init_y + sy * lx + cy * ly;
    xy[2] = 0.0;
}

/* The first guess of (z, roll, pitch, beta): from the ground under the
 * four nominal wheel positions, each rocker pitched along its own side's
 * ground (their difference is the differential's twist), the chassis
 * rolled across, a centimetre of sinkage.  Starting level on uneven ground
 * lets Newton settle on the uphill wheels alone. */
static void initial_pose(const Model *m, double x[4])
{
    const Params *p = &m->p;
    double ground[NUM_WHEELS];
    for (int w = 0; w < NUM_WHEELS; ++w) {
        double at[3];
        nominal_wheel_position(p, w, at);
        ground[w] = rover_terrain_at(m, at[0], at[1], NULL);
    }
    const double pitch_left = -atan((ground[WHEEL_FL] - ground[WHEEL_RL]) / p->rover_wheelbase);
    const double pitch_right = -atan((ground[WHEEL_FR] - ground[WHEEL_RR]) / p->rover_wheelbase);
    const double roll = atan(0.5 * (ground[WHEEL_FL] + ground[WHEEL_RL] - ground[WHEEL_FR] - ground[WHEEL_RR]) /
                             p->rover_track);
    const double mean_ground = 0.25 * (ground[0] + ground[1] + ground[2] + ground[3]);
    const double pitch = 0.5 * (pitch_left + pitch_right);
    x[0] = mean_ground + (p->rover_pivotHeight + p->wheel_radius - 0.01) * cos(pitch) * cos(roll);
    x[1] = roll;
    x[2] = pitch;
    x[3] = 0.5 * (pitch_left - pitch_right);
}

/* The height x[0] at which the soil carries the weight, by bisection
 * between a pose with every wheel in the air (the soil carries nothing)
 * and one sunk 0.8 R deeper (it carries more than the weight): robust from
 * the softest to a near-rigid soil, where the first guess may already be
 * far too deep.  Leaves the residual of the result in r. */
static void settle_height(Model *m, double x[4], double r[4])
{
    double z_air = x[0] + 0.05, z_deep = x[0] - 0.8 * m->p.wheel_radius, r_deep[4];
    int air_known = 0, deep_known = 0;     /* whether the residual's sign there has been evaluated */
    for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (z_air + z_deep);
        /* Once the ends are adjacent doubles the midpoint rounds to one of
         * them; once that one has been evaluated, every further halving
         * evaluates it again (the residual is a function of x alone: place
         * sets the whole pose and the soil memory from it) and moves neither
         * end.  About 53 halvings reach that from these 0.27 m at R = 0.28 m. */
        if ((mid == z_air && air_known) || (mid == z_deep && deep_known)) break;
        x[0] = mid;
        equilibrium_residual(m, x, r);
        if (r[0] < 0) {
            z_air = mid, air_known = 1;
        } else {
            z_deep = mid, deep_known = 1;
            memcpy(r_deep, r, sizeof r_deep);
        }
    }
    x[0] = z_deep;
    if (deep_known) memcpy(r, r_deep, sizeof r_deep);   /* the residual at z_deep, as evaluated there */
    else equilibrium_residual(m, x, r);
}

/* Newton's method on all four of x from the residual r there, with a
 * finite-difference Jacobian and backtracking that keeps every step an
 * improvement.  Returns the scaled residual norm reached. */
static double newton(Model *m, double x[4], double r[4], double weight, double moment_scale)
{
    double res = norm4(r, weight, moment_scale);
    for (int it = 0; it < 100 && res > 1e-10; ++it) {
        double J[4][4], step[4];
        const double dx[4] = {1e-6, 1e-6, 1e-6, 1e-6};
        for (int j = 0; j < 4; ++j) {
            double xp[4], rp[4];
            memcpy(xp, x, sizeof xp);
            xp[j] += dx[j];
            equilibrium_residual(m, xp, rp);
            for (int i = 0; i < 4; ++i) J[i][j] = (rp[i] - r[i]) / dx[j];
        }
        for (int i = 0; i < 4; ++i) step[i] = -r[i];
        if (solve4(J, step) != 0) break;
        double lambda = 1.0, xn[4], rn[4], resn = res;
        for (int ls = 0; ls < 30; ++ls, lambda *= 0.5) {
            double len = 0;
            for (int i = 0; i < 4; ++i) len = fmax(len, fabs(lambda * step[i]));
            double clip = len > 0.05 ? 0.05 / len : 1.0;    /* at most 5 cm / 0.05 rad per step */
            for (int i = 0; i < 4; ++i) xn[i] = x[i] + clip * lambda * step[i];
            equilibrium_residual(m, xn, rn);
            resn = norm4(rn, weight, moment_scale);
            if (resn < res) break;
        }
        if (!(resn < res)) break;
        memcpy(x, xn, sizeof xn);
        memcpy(r, rn, sizeof rn);
        res = resn;
    }
    return res;
}

/* Places the rover in static equilibrium at its start pose: the height
 * first (settle_height), then Newton on all four.  Returns 0, or -1 with
 * the likely cause in err. */
static int find_equilibrium(Model *m, char *err, size_t errlen)
{
    const Params *p = &m->p;
    const double weight = (p->rover_mass + p->rover_payload) * p->env_gravity, moment_scale = weight * p->rover_wheelbase;
    double x[4], r[4];
    initial_pose(m, x);
    settle_height(m, x, r);
    const double res = newton(m, x, r, weight, moment_scale);
    if (!(res < 1e-8)) {
        double at[NUM_WHEELS][3];
        char cause[256];
        for (int w = 0; w < NUM_WHEELS; ++w) nominal_wheel_position(p, w, at[w]);
        if (!rover_slope_beyond_friction(m, (const double (*)[3])at, cause, sizeof cause))
            /* the extensions that soften the soil where the rover stands are named too */
            snprintf(cause, sizeof cause,
                     "is the soil too soft for the load on these wheels (soil.kh, soil.eta, wheel.radius, "
                     "wheel.width%s%s%s)?", p->patch_khFactor < 1.0 ? ", soilPatch.khFactor" : "",
                     p->strip_khFactor < 1.0 ? ", soilStrip.khFactor" : "",
                     p->multipass_khFactor < 1.0 ? ", multipass.khFactor" : "");
        snprintf(err, errlen,
                 "no static equilibrium found for the rover at init.x = %g, init.y = %g (residual %.3g of the "
                 "weight): %s", p->init_x, p->init_y, res, cause);
        return -1;
    }
    place(m, x);
    Eval ev;
    rover_evaluate(m, &ev, 0);
    for (int w = 0; w < NUM_WHEELS; ++w)
        if (!(ev.wheel[w].sinkage > 0)) {
            snprintf(err, errlen,
                     "the static equilibrium at init.x = %g, init.y = %g leaves wheel %s off the ground "
                     "(the rocker differential cannot reach it): choose another start pose",
                     p->init_x, p->init_y, rover_wheel_names[w]);
            return -1;
        }
    return 0;
}

/* ------------------------------------------------------------- life cycle */

int model_initialize(Model *m, char *err, size_t errlen)
{
    const Params *p = &m->p;
    m->eval_valid = 0;
    m->steps_taken = m->steps_rejected = 0;
    if (check_params(p, err, errlen) != 0) return -1;
    const SoilLaws laws = SOIL_LAWS_OF(p);
    if (wheel_soil_prepare_laws(&laws, &m->d.contact, &m->d.wong_reece, err, errlen) != 0) return -1;
    derive(m);

    terrain_free(&m->terrain);
    const char *terrain_path = m->resolved.terrain_file ? m->resolved.terrain_file : m->terrain_file;
    if (terrain_path && terrain_path[0]) {
        if (terrain_load(&m->terrain, terrain_path, err, errlen) != 0) return -1;
    } else {
        terrain_init_flat(&m->terrain);
    }
    m->terrain_fingerprint = m->d.terrain_fingerprint = terrain_fingerprint(&m->terrain);

    const double t0 = m->s.time;
    memset(&m->s, 0, sizeof m->s);
    m->s.time = t0;
    if (find_equilibrium(m, err, errlen) != 0) return -1;
    if (p->init_vx > 0 && p->multipass_rutFraction > 0) {
        /* A rover started moving forward has been driving: its rear wheels already roll
         * in the front wheels' rut.  Started without one, on a slow climb the front wheels
         * need many seconds to cover a wheelbase, and the rear wheels dig in meanwhile
         * (measured: 3.4-4.1 cm against 1.5-1.6 cm, README "terrain run replayed in
         * segments").  Assumption: straight running over the last metres, on the soil
         * under the front wheels now, whose rut is their resting sinkage's residual. */
        prefill_rut(m);
        if (find_equilibrium(m, err, errlen) != 0) return -1;
    }
    /* Initial forward speed: chassis moving along the heading, wheels rolling without slip. */
    m->s.u[U_VX + 0] = p->init_vx * cos(p->init_yaw);
    m->s.u[U_VX + 1] = p->init_vx * sin(p->init_yaw);
    m->s.u[U_SPIN_L] = m->s.u[U_SPIN_R] = p->init_vx / p->wheel_radius;
    rover_evaluate_end_of_step(m);
    return 0;
}

void model_free(Model *m)
{
    terrain_free(&m->terrain);
    free(m->terrain_file);
    m->terrain_file = NULL;
    free(m->resolved.terrain_file);
    m->resolved.terrain_file = NULL;
    m->eval_valid = 0;
}

/* The kept end-of-step evaluation (Model.eval) belongs to the parameters, derived data, terrain
 * and state it was computed from; any of them written outside model_do_step makes the next step
 * evaluate afresh. */
void model_changed(Model *m) { m->eval_valid = 0; }

void model_reset(Model *m)
{
    model_free(m);
    memset(m, 0, sizeof *m);
    model_set_defaults(m);
    terrain_init_flat(&m->terrain);
}

const char *model_state_foreign(const Model *m, const ModelState *st, char *why, size_t n)
{
    if (st->d.terrain_fingerprint == m->terrain_fingerprint) return NULL;
    const char *file = m->terrain_file && m->terrain_file[0] ? m->terrain_file : NULL;
    snprintf(why, n, "the state was taken on other ground than this instance's terrain.file%s%s%s",
             file ? " '" : " (flat ground)", file ? file : "", file ? "'" : "");
    return why;
}

void model_describe(const Model *m, char *buf, size_t n)
{
    snprintf(buf, n, "A1 = %.4f, Vint = %.4g m3, static sinkage FL %.4f m, chassis z %.4f m", m->d.contact.A1,
             m->d.contact.Vint, m->out.wheel[0].sinkage, m->out.z);
}
