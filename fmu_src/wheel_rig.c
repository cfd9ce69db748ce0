/*
 * The single-wheel test rig (wheel_rig.h): parameter checks, the contact
 * laws' constants, the static equilibrium the wheel starts from, the
 * integrator, and the life cycle and hooks the FMI layer calls
 * (model_hooks.h).
 *
 * Assumptions, named:
 *  - The soil is flat and level and homogeneous (no soil patch, no rut):
 *    the contact frame is the world's, turned by the slip angle about the
 *    vertical.
 *  - The carriage is rigid and its speed rig.vx is imposed; the wheel
 *    turns only about its axle at the imposed spin (a rig's drive motor
 *    holds the spin, whatever the torque), so the only free motion is the
 *    hub's height z, carrying the constant load rig.load with the mass
 *    rig.mass.  The carriage takes the drawbar pull, the lateral force and
 *    the torque; the rig measures them.
 *  - The hub's vertical motion does not change the slip: on level soil
 *    the heading is horizontal, so the vertical velocity has no part
 *    along it; nor the lateral slip velocity, which is the hub's,
 *    -rig.vx sin(slip angle): the rim point's velocity relative to the hub
 *    lies in the wheel's mid-plane, perpendicular to the axle.
 *  - Slip set (rig.driveMode 0): the spin that gives the slip with the
 *    model's slip definition (wheel_soil.h) at the hub's speed along the
 *    heading v = rig.vx cos(slip angle): omega R = v / (1 - slip) when
 *    driving, v (1 + slip) when braking (slip -1: a locked wheel).  Below
 *    contact.slipVelocityEps the law's slip denominator is that floor, so
 *    the slip it sees (rig.slipActual) is smaller than the one set.
 *  - The wheel starts at rest in static equilibrium, pressed straight
 *    into virgin soil (symmetric contact, no rebound yet), and moves with
 *    the inputs from the first step: the soil memory (maximum sinkage,
 *    distance rolled, contact.h) then builds up over about one contact
 *    length of travel, after which the forces are steady.
 * Integration as the rover's (rover_step.c): linearly implicit Euler in
 * the vertical velocity with the normal force linearised in the sinkage,
 *   (m + h^2 kz) dvz = h (Fz - load - h kz vz),  vz += dvz,  z += h vz,
 * then the soil memory advanced explicitly with the step's sinkage.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "wheel_rig.h"

/* The acceleration the default moving mass rig.load / g assumes, m/s^2. */
#define RIG_GRAVITY 9.81

/* ------------------------------------------------------------ set-up */

static int check_params(const Params *p, char *err, size_t n)
{
    if (!(p->rig_load > 0)) return snprintf(err, n, "rig.load = %g must be positive", p->rig_load), -1;
    if (!(p->rig_mass >= 0)) return snprintf(err, n, "rig.mass = %g must not be negative", p->rig_mass), -1;
    if (p->rig_driveMode != RIG_SLIP_SET && p->rig_driveMode != RIG_SPIN_SET)
        return snprintf(err, n, "rig.driveMode = %d must be 0 (slip set) or 1 (spin set)", p->rig_driveMode), -1;
    if (!(p->solver_step > 0)) return snprintf(err, n, "solver.step = %g must be positive", p->solver_step), -1;
    return 0;
}

/* ------------------------------------------------------------- the force */

/* The wheel's spin (rad/s) from the inputs, at hub speed v_long along the
 * heading (m/s). */
static double imposed_spin(const Model *m, double v_long)
{
    if (m->p.rig_driveMode == RIG_SPIN_SET) return m->in.omega;
    const double s = m->in.slip;
    const double omega_r = s >= 0 ? v_long / (1.0 - s) : v_long * (1.0 + s);
    return omega_r / m->p.wheel_radius;
}

void wheel_rig_force(const Model *m, double z, int at_rest, RigForce *f)
{
    const double psi = m->in.slipAngle, cpsi = cos(psi), spsi = sin(psi);
    const double vx = at_rest ? 0.0 : m->in.vx;
    memset(f, 0, sizeof *f);
    f->sinkage = m->p.wheel_radius - z;
    f->v_long = vx * cpsi;
    f->spin = at_rest ? 0.0 : imposed_spin(m, f->v_long);
    if (f->sinkage <= 0) return;          /* in the air; a NaN goes on, to be caught as a diverged state */
    const WheelSoil ws = {.contact = &m->d.contact, .wong_reece = &m->d.wong_reece, .law = m->p.contact_model,
                          .slip_sinkage = m->p.slipSinkage_coefficient, .thrust_gain = m->p.grouser_thrustGain,
                          .lug_height = m->p.grouser_lugHeight, .slip_sinkage_power = m->p.slipSinkage_exponent,
                          .thrust_slip = m->p.grouser_thrustSlip};
    const WheelSoilInput in = {f->sinkage, f->v_long, f->spin, 1.0, 1.0, 0.0, 0.0};   /* no lug ripple */
    WheelSoilContact sc;
    wheel_soil_slip(&ws, &in, &sc);
    wheel_soil_normal(&ws, &m->s.memory, &in, 1, &sc);
    const double v_lat = -vx * spsi;
    wheel_soil_shear(&ws, &sc, &in, v_lat, &f->F_long, &f->F_lat, NULL);
    const double sa = sc.sin_alpha, ca = sc.cos_alpha;
    f->slip = sc.slip;
    f->Fn = sc.Fn;
    /* force = Fn nvec + F_long t + F_lat l (wheel_soil.h) with the heading
     * f = (cpsi, spsi, 0), the soil normal (0, 0, 1), l = (-spsi, cpsi, 0) */
    const double along = -sc.Fn * sa + f->F_long * ca;
    f->Fx = along * cpsi - f->F_lat * spsi;
    f->Fy = along * spsi + f->F_lat * cpsi;
    f->Fz = sc.Fn * ca + f->F_long * sa;
    f->torque = sc.shear_radius * f->F_long;
    /* The linearised normal force, as the rover's stiffness: the normal
     * force's growth with the sinkage along its own direction
     * (volumetric), the law's dFz/d(sinkage) (Wong-Reece). */
    f->kz = sc.wong_reece ? sc.kn : sc.kn * ca;
}

/* --------------------------------------------------- static equilibrium */

/* The soil memory of a wheel pressed straight down to the sinkage z_s. */
static void press(Model *m, double z_s)
{
    m->s.memory.zmax = z_s > 0 ? z_s : 0.0;
    m->s.memory.travel = 0.0;
}

/* The vertical force at rest with the hub at height z, pressed there. */
static double rest_force(Model *m, double z)
{
    press(m, m->p.wheel_radius - z);
    RigForce f;
    wheel_rig_force(m, z, 1, &f);
    return f.Fz;
}

/* The hub height at which the soil carries rig.load at rest, by bisection
 * of the sinkage between 0 (nothing carried) and the wheel's radius.
 * Returns 0, or -1 with why in err. */
static int find_equilibrium(Model *m, char *err, size_t errlen)
{
    const double R = m->p.wheel_radius, load = m->p.rig_load;
    double z_air = R, z_deep = 1e-9 * R;     /* the hub at the surface is beyond any law's reach */
    const double deepest = rest_force(m, z_deep);
    if (!(deepest >= load))
        return snprintf(err, errlen,
                        "no static equilibrium: sunk to its hub the wheel carries %.4g N, less than rig.load = %g N "
                        "(the soil is too soft for this load: soil.kh, soil.eta or the Wong-Reece moduli, "
                        "wheel.radius, wheel.width)", deepest, load), -1;
    for (int it = 0; it < 200 && z_air - z_deep > 1e-15 * R; ++it) {
        const double z = 0.5 * (z_air + z_deep);
        if (rest_force(m, z) < load) z_air = z;
        else z_deep = z;
    }
    /* the side where the soil carries the load at least */
    m->s.z = z_deep;
    press(m, R - z_deep);
    return 0;
}

/* ------------------------------------------------------------- stepping */

static void outputs_from(Model *m, const RigForce *f)
{
    Outputs *o = &m->out;
    o->drawbarPull = f->Fx;
    o->verticalForce = f->Fz;
    o->torque = f->torque;
    o->lateralForce = f->F_lat;
    o->sinkage = f->sinkage;
    o->slipActual = f->slip;
    o->omegaActual = f->spin;
    o->normalForce = f->Fn;
    o->tractionForce = f->F_long;
    o->travel = m->s.x;
    o->hubHeight = m->s.z;
}

static void evaluate_outputs(Model *m)
{
    RigForce f;
    wheel_rig_force(m, m->s.z, 0, &f);
    outputs_from(m, &f);
}

/* One internal step of length h (s). */
static int substep(Model *m, double h, char *err, size_t errlen)
{
    State *s = &m->s;
    RigForce f;
    wheel_rig_force(m, s->z, 0, &f);
    const double mass = m->d.mass;
    const double dvz = h * (f.Fz - m->p.rig_load - h * f.kz * s->vz) / (mass + h * h * f.kz);
    s->vz += dvz;
    s->z += h * s->vz;
    s->x += h * m->in.vx;
    contact_memory_update(&m->d.contact, &s->memory, f.sinkage, f.v_long, h);
    s->time += h;
    if (!isfinite(s->z) || !isfinite(s->vz) || fabs(s->vz) > 1e3)
        return snprintf(err, errlen, "state diverged at t = %.4f s: hub height %g m, vertical velocity %g m/s",
                        s->time, s->z, s->vz), -1;
    if (m->p.wheel_radius - s->z >= m->p.wheel_radius)
        return snprintf(err, errlen,
                        "state diverged at t = %.4f s: the wheel sank %.3f m, deeper than its radius; the soil is "
                        "too soft for rig.load = %g N at this slip (check soil.kh, soil.eta, slipSinkage.coefficient)",
                        s->time, m->p.wheel_radius - s->z, m->p.rig_load), -1;
    return 0;
}

static int inputs_are_finite(const Inputs *in, char *err, size_t n)
{
    const double v[4] = {in->slip, in->vx, in->omega, in->slipAngle};
    static const char *const names[4] = {"rig.slip", "rig.vx", "rig.omega", "rig.slipAngle"};
    for (int i = 0; i < 4; ++i)
        if (!isfinite(v[i])) return snprintf(err, n, "input %s = %g is not finite", names[i], v[i]), 0;
    return 1;
}

int model_do_step(Model *m, double h_comm, char *err, size_t errlen)
{
    if (!inputs_are_finite(&m->in, err, errlen)) return -1;
    if (m->p.rig_driveMode == RIG_SLIP_SET && !(m->in.slip < 1.0))
        return snprintf(err, errlen, "input rig.slip = %g: a wheel cannot drive at slip 1 or more while the carriage "
                        "moves", m->in.slip), -1;
    const double t_end = m->s.time + h_comm;
    int n = (int)ceil(h_comm / m->p.solver_step - 1e-9);
    if (n < 1) n = 1;
    const double h = h_comm / n;
    for (int i = 0; i < n; ++i)
        if (substep(m, h, err, errlen) != 0) return -1;
    m->s.time = t_end;
    evaluate_outputs(m);
    return 0;
}

/* ------------------------------------------------------------- life cycle */

int model_initialize(Model *m, char *err, size_t errlen)
{
    const Params *p = &m->p;
    if (check_params(p, err, errlen) != 0) return -1;
    const SoilLaws laws = SOIL_LAWS_OF(p);
    if (wheel_soil_prepare_laws(&laws, &m->d.contact, &m->d.wong_reece, err, errlen) != 0) return -1;
    m->d.mass = p->rig_mass > 0 ? p->rig_mass : p->rig_load / RIG_GRAVITY;
    const double t0 = m->s.time;
    memset(&m->s, 0, sizeof m->s);
    m->s.time = t0;
    if (find_equilibrium(m, err, errlen) != 0) return -1;
    evaluate_outputs(m);
    return 0;
}

void model_free(Model *m)
{
    (void)m;   /* the rig owns nothing outside its plain data */
}

void model_reset(Model *m)
{
    model_free(m);
    memset(m, 0, sizeof *m);
    model_set_defaults(m);
}

/* The rig keeps nothing from one step for the next. */
void model_changed(Model *m) { (void)m; }

/* The rig loads nothing at initialisation: every state is its own. */
const char *model_state_foreign(const Model *m, const ModelState *st, char *why, size_t n)
{
    (void)m;
    (void)st;
    (void)why;
    (void)n;
    return NULL;
}

void model_describe(const Model *m, char *buf, size_t n)
{
    snprintf(buf, n, "%s law, static sinkage %.4f m under rig.load = %g N, moving mass %g kg, A1 = %.4f",
             m->p.contact_model == CONTACT_LAW_WONG_REECE ? "Wong-Reece" : "volumetric", m->out.sinkage,
             m->p.rig_load, m->d.mass, m->d.contact.A1);
}
