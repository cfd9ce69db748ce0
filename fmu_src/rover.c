/*
 * The CSA Juno rover: chassis (6 DOF), two main rockers coupled by the
 * transverse differential (left angle beta, right -beta), one spin DOF per
 * side (1:1 chain), four volumetric wheel/soil contacts, a drawbar hitch.
 *
 * Formulation: Kane's equations in the 9 generalised velocities u of
 * model.h.  Each of the 7 bodies (chassis, 2 rockers, 4 wheels) has a
 * linear and angular velocity Jacobian J(q) (3 x 9) and a bias
 * acceleration (the J'u terms), so M(q) u' = Q(q, u) with
 * M = sum J^T m J and Q = sum J^T (F - m b) + gyroscopic terms.
 *
 * Integrator: linearly implicit Euler in the velocities (the stiff soil
 * shear, normal stiffness and drive damping are linearised), then the
 * positions with the new velocities (symplectic):
 *   (M + h D + h^2 K) du = h (Q - h K u),   u += du,   q += h u.
 * The contact memory (max sinkage, distance rolled) and the PID integral
 * are advanced explicitly once per internal step.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "vec3.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

enum { BODY_CHASSIS = 0, BODY_ROCKER_L = 1, BODY_ROCKER_R = 2, BODY_WHEEL0 = 3 };

static const char *const wheel_names[NUM_WHEELS] = {"FL", "RL", "FR", "RR"};

static inline int side_of(int w) { return w / 2; }
static inline double sigma_of(int side) { return side == SIDE_LEFT ? 1.0 : -1.0; }

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
    if (!(p->rover_wheelbase > 0)) return snprintf(err, n, "rover.wheelbase = %g must be positive", p->rover_wheelbase), -1;
    if (!(p->rover_track > p->wheel_width))
        return snprintf(err, n, "rover.track = %g must exceed wheel.width = %g", p->rover_track, p->wheel_width), -1;
    if (!(p->env_gravity > 0)) return snprintf(err, n, "env.gravity = %g must be positive", p->env_gravity), -1;
    if (!(p->solver_step > 0)) return snprintf(err, n, "solver.step = %g must be positive", p->solver_step), -1;
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
    d->chassis_mass = p->rover_mass - 4 * p->wheel_mass - 2 * p->rover_rockerMass;
    /* Assumption (model-notes 4): chassis inertia of a uniform 1.38 x 1.6 x 0.5 m box. */
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
}

/* ------------------------------------------------------- kinematics */

/* Jacobian rows of a point x (world) moving with the chassis, or with a
 * rocker of the given side (side < 0: chassis). */
static void point_jacobian(const Eval *ev, const double pos[3], const double x[3], int side, double J[3][NU])
{
    double r[3], c[3] = {0, 0, 0};
    v3_sub(r, x, pos);
    if (side >= 0) {
        double s[3];
        v3_sub(s, x, ev->pivot[side]);
        v3_cross(c, ev->e, s);
        v3_scale(c, c, sigma_of(side));
    }
    /* v = v_c + w x r + u_beta c  ->  [1 | -[r]x | c | 0 0], written whole (no memset) */
    for (int i = 0; i < 3; ++i) {
        J[i][U_VX + 0] = i == 0;
        J[i][U_VX + 1] = i == 1;
        J[i][U_VX + 2] = i == 2;
        J[i][U_BETA] = c[i];
        J[i][U_SPIN_L] = 0;
        J[i][U_SPIN_R] = 0;
    }
    J[0][U_WX + 0] = 0;     J[0][U_WX + 1] = r[2];  J[0][U_WX + 2] = -r[1];
    J[1][U_WX + 0] = -r[2]; J[1][U_WX + 1] = 0;     J[1][U_WX + 2] = r[0];
    J[2][U_WX + 0] = r[1];  J[2][U_WX + 1] = -r[0]; J[2][U_WX + 2] = 0;
}

/* Wheel Jacobians are mostly zeros and ones, and the hot loop (four
 * contacts per evaluation) works only with their structural non-zeros.
 * For a wheel on side `side` (spin column sp = U_SPIN_L + side):
 *   point rows J (hub: point_jacobian; rim point: + add_wheel_offset):
 *     [1 | -[r]x | c | spin column (0 at the hub) | other spin 0],
 *     the diagonal of the -[r]x block exactly 0;
 *   angular rows Jw: [0 | 1 | sigma e | e in column sp | 0].
 * Each function below adds the non-zero products in the order the dense
 * loop over all NU columns (rows) would, and a product with an exact 0 or
 * 1 changes nothing in IEEE arithmetic (x + 0 * y = x, 1 * y = y for finite
 * y), so the results are the dense loops' bit for bit (up to the sign of
 * an exact zero); bench_fmu --compare checks this against the dense build. */

/* Adds to the point Jacobian J the motion of a point on a wheel body
 * (offset r from its hub): -[r]x times the wheel's angular Jacobian, for
 * the columns where Jw is not zero (the angular rates, the rocker rate and
 * this wheel's spin). */
static void add_wheel_offset(double J[3][NU], double Jw[3][NU], const double r[3], int sp)
{
    const int cols[5] = {U_WX + 0, U_WX + 1, U_WX + 2, U_BETA, sp};
    for (int n = 0; n < 5; ++n) {
        const int k = cols[n];
        double w[3] = {Jw[0][k], Jw[1][k], Jw[2][k]}, c[3];
        v3_cross(c, w, r);
        for (int i = 0; i < 3; ++i) J[i][k] += c[i];
    }
}

/* Row i of a point Jacobian (structure above) times u. */
static inline double point_row_dot(double J[3][NU], int i, const double u[NU], int sp)
{
    double s = u[U_VX + i];
    for (int j = 0; j < 3; ++j)
        if (j != i) s += J[i][U_WX + j] * u[U_WX + j];
    s += J[i][U_BETA] * u[U_BETA];
    return s + J[i][sp] * u[sp];
}

/* Row i of an angular wheel Jacobian times u. */
static inline double angular_row_dot(double Jw[3][NU], int i, const double u[NU], int sp)
{
    return u[U_WX + i] + Jw[i][U_BETA] * u[U_BETA] + Jw[i][sp] * u[sp];
}

/* a^T J for a point Jacobian J: a row of NU (the other spin column 0). */
static inline void point_vec_times_jac(double out[NU], const double a[3], double J[3][NU], int sp)
{
    out[U_VX + 0] = a[0];
    out[U_VX + 1] = a[1];
    out[U_VX + 2] = a[2];
    out[U_WX + 0] = a[1] * J[1][U_WX + 0] + a[2] * J[2][U_WX + 0];
    out[U_WX + 1] = a[0] * J[0][U_WX + 1] + a[2] * J[2][U_WX + 1];
    out[U_WX + 2] = a[0] * J[0][U_WX + 2] + a[1] * J[1][U_WX + 2];
    out[U_BETA] = a[0] * J[0][U_BETA] + a[1] * J[1][U_BETA] + a[2] * J[2][U_BETA];
    out[U_SPIN_L] = out[U_SPIN_R] = 0.0;
    out[sp] = a[0] * J[0][sp] + a[1] * J[1][sp] + a[2] * J[2][sp];
}

/* a^T Jw for an angular wheel Jacobian: a row of NU. */
static inline void angular_vec_times_jac(double out[NU], const double a[3], double Jw[3][NU], int sp)
{
    out[U_VX + 0] = out[U_VX + 1] = out[U_VX + 2] = 0.0;
    out[U_WX + 0] = a[0];
    out[U_WX + 1] = a[1];
    out[U_WX + 2] = a[2];
    out[U_BETA] = a[0] * Jw[0][U_BETA] + a[1] * Jw[1][U_BETA] + a[2] * Jw[2][U_BETA];
    out[U_SPIN_L] = out[U_SPIN_R] = 0.0;
    out[sp] = a[0] * Jw[0][sp] + a[1] * Jw[1][sp] + a[2] * Jw[2][sp];
}

/* Q += J^T F for a point Jacobian J. */
static inline void point_add_generalised(double Q[NU], double J[3][NU], const double F[3], int sp)
{
    double g[NU];
    point_vec_times_jac(g, F, J, sp);
    for (int k = 0; k < NU; ++k)
        if (k < U_SPIN_L || k == sp) Q[k] += g[k];
}

/* M += a^T s b for rows a, b */
static void add_outer(double Mx[NU][NU], const double a[NU], double s, const double b[NU])
{
    for (int i = 0; i < NU; ++i) {
        if (a[i] == 0) continue;
        for (int j = 0; j < NU; ++j) Mx[i][j] += a[i] * s * b[j];
    }
}

/* ------------------------------------------------------ terrain, soil */

/* Terrain at world (x, y), with the registration extension: the grid is
 * moved by (terrain.offsetX, offsetY, offsetZ) and turned by offsetYaw
 * about the world z axis, so a grid feature at grid coordinates q appears
 * at world o + Rz(yaw) q.  All zero: the grid as given. */
static double terrain_query(const Model *m, double x, double y, double n[3])
{
    const Params *p = &m->p;
    if (p->terrain_offsetX == 0 && p->terrain_offsetY == 0 && p->terrain_offsetYaw == 0) {
        if (n) terrain_normal(&m->terrain, x, y, n);
        return terrain_height(&m->terrain, x, y) + p->terrain_offsetZ;
    }
    const double c = cos(p->terrain_offsetYaw), sn = sin(p->terrain_offsetYaw);
    const double dx = x - p->terrain_offsetX, dy = y - p->terrain_offsetY;
    const double qx = c * dx + sn * dy, qy = -sn * dx + c * dy;
    if (n) {
        double ng[3];
        terrain_normal(&m->terrain, qx, qy, ng);
        n[0] = c * ng[0] - sn * ng[1];
        n[1] = sn * ng[0] + c * ng[1];
        n[2] = ng[2];
    }
    return terrain_height(&m->terrain, qx, qy) + p->terrain_offsetZ;
}

/* Soil-patch extension: relative stiffness and strength at (x, y), a
 * Gaussian bump of the factors towards soilPatch.* (1 everywhere when off). */
static void soil_factors(const Params *p, double x, double y, double *kh_factor, double *strength_factor)
{
    *kh_factor = 1.0;
    *strength_factor = 1.0;
    if (p->patch_khFactor == 1.0 && p->patch_strengthFactor == 1.0) return;
    const double dx = x - p->patch_x, dy = y - p->patch_y;
    const double g = exp(-(dx * dx + dy * dy) / (2 * p->patch_radius * p->patch_radius));
    *kh_factor = 1.0 + (p->patch_khFactor - 1.0) * g;
    *strength_factor = 1.0 + (p->patch_strengthFactor - 1.0) * g;
}

/* Multi-pass extension: residual rut depth that side's front wheel left at
 * forward travel `pos` (m); 0 before the start or beyond the memory.
 * Assumption: the rear wheel follows the front wheel's track one
 * wheelbase behind (straight running; on a turn it strays from the rut). */
static double rut_point(const State *s, int side, double pos)
{
    if (pos < 0 || pos < s->path[side] - (RUT_SAMPLES - 2) * RUT_SPACING || pos > s->path[side]) return 0.0;
    const double u = pos / RUT_SPACING;
    const long i = (long)floor(u);
    const double f = u - (double)i;
    return (1 - f) * s->rut[side][i % RUT_SAMPLES] + f * s->rut[side][(i + 1) % RUT_SAMPLES];  /* i >= 0 here */
}

/* Rut depth under a rear wheel at path position pos, averaged over 2 RUT_WINDOW_HALF + 1 samples.
 * Assumption: the rim bridges rut features shorter than its contact length, so
 * the wheel follows the rut's mean over about that length.  Unaveraged, the
 * step where the rut begins (the pit the front wheel sat in) and steps where
 * the front wheel's sinkage jumped kick the rear wheel like a kerb. */
static double rut_depth_at(const State *s, int side, double pos)
{
    double sum = 0;
    for (int k = -RUT_WINDOW_HALF; k <= RUT_WINDOW_HALF; ++k) sum += rut_point(s, side, pos + k * RUT_SPACING);
    return sum / (2 * RUT_WINDOW_HALF + 1);
}

/* ---------------------------------------------------------- drive */

static void drive_torques(const Model *m, double torque[2], double dtorque_domega[2])
{
    const Params *p = &m->p;
    const double omega[2] = {m->s.u[U_SPIN_L], m->s.u[U_SPIN_R]};
    for (int k = 0; k < 2; ++k) {
        double t = 0, slope = 0;
        if (p->drive_mode == DRIVE_TORQUE) {
            t = k == SIDE_LEFT ? m->in.torqueLeft : m->in.torqueRight;
        } else if (p->drive_mode == DRIVE_PID) {
            double ref = k == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
            t = p->drive_Kp * (ref - omega[k]) + p->drive_Ki * m->s.pid_integral[k];
            slope = -p->drive_Kp;
        } else {
            /* DC motor at throttle u: T = eff * n * kt * (u V - ke n w) / Ra, ke = kt (SI). */
            double u = k == SIDE_LEFT ? m->in.throttleLeft : m->in.throttleRight;
            double n = p->motor_gearRatio, kt = p->motor_kt;
            t = p->motor_efficiency * n * kt * (u * p->motor_voltage - kt * n * omega[k]) / p->motor_resistance;
            slope = -p->motor_efficiency * n * n * kt * kt / p->motor_resistance;
        }
        if (p->drive_mode != DRIVE_TORQUE && fabs(t) > p->drive_torqueMax) {
            t = copysign(p->drive_torqueMax, t);
            slope = 0;
        }
        torque[k] = t;
        dtorque_domega[k] = slope;
    }
}

/* ------------------------------------------------- Wong-Reece contact */

/* The Wong-Reece/Ishigami law (contact.model = 1) at one wheel, mapped onto
 * the representation the volumetric law uses (Eqns 8-9): a force Fn
 * through the hub tilted by alpha, and a traction F_long along the tilted
 * tangent at the rim point on the tilted ray, whose moment about the axle
 * is -R F_long.  With F_long = T / R (T the resisting torque) and (Fn,
 * alpha) solved from (Fx, Fz) = Rot(alpha) (F_long, Fn), the wheel gets
 * exactly WR's drawbar pull Fx along the heading, vertical load Fz along
 * the soil normal and torque -T about its axle.
 *
 * Assumptions, named (README "Contact laws"):
 *  - Direction: wong_reece_forces describes a wheel moving forwards; a
 *    wheel is described in the frame of the faster of its rim speed omega R
 *    and hub speed v (dir = the sign of that one), mirrored when dir < 0:
 *    WR slip = dir * slip, Fx and T flip sign, Fz not.
 *  - Standstill: WR is a steady rolling solution (the shear displacement j
 *    and the front-heavy stress profile both come from rolling), and at
 *    slip 0 it has T > 0 and a rolling resistance, which would make a
 *    parked rover creep.  As for the volumetric tilt (contact.h,
 *    contact_rolling_factor), below slipVelocityEps they fade: the rolling
 *    resistance Fx - T/R is scaled by clamp(v / eps, -1, 1) (it always
 *    opposes the motion) and the traction loses (1 - b) of its zero-slip
 *    part, F_long = (T(s) - (1 - b) T(0)) / R with b = min(1, max(|omega R|,
 *    |v|) / eps); at rest only the slip-proportional (viscous) shear is
 *    left.  At speed >= eps, WR exactly.
 *  - soilPatch.strengthFactor and grouser.thrustGain scale the traction
 *    T / R (WR's shear stress scales with c and tan phi); their smaller
 *    share in Fz and in the rolling resistance is not scaled.  The k_h
 *    factors (soilPatch.khFactor, multipass.khFactor, slipSinkage) are
 *    volumetric-only; the multi-pass rut depth (geometry) applies.
 *  - When T / R exceeds the in-plane resultant (only at sub-millimetre
 *    sinkage, where WR's cohesion can pull the wheel down), the moment is
 *    limited to R times the resultant (Fn = 0).
 * For the linearly implicit integrator it also returns slip derivatives of
 * the applied forces (a one-sided difference of 1e-3 in slip, 0 where the
 * WR slip is clamped at +-1) and dFz/d(sinkage) (a difference of 1e-3 of
 * the sinkage, 1 um at least), checked against a 20000-point reference in
 * tests/c/test_wong_reece.c.  The speed dependence of the fading factors
 * b and c is left out of the damping, as that of the volumetric rolling
 * factor is. */
typedef struct {
    double Fn, sin_alpha, cos_alpha, F_long;   /* the Eqn 8-9 representation */
    double Fx, Fz;                             /* applied along the heading and the soil normal, N */
    double area;                               /* b r (sin theta_f - sin theta_r), m^2 */
    double dFx_ds, dFz_ds, dFt_ds;             /* derivatives in the rover's slip, N */
    double kz;                                 /* dFz / d(sinkage), N/m */
} WongReeceContact;

static void wong_reece_contact(const Model *m, double sinkage, double slip, double v_long, double omega_r,
                               double shear_factor, int derivatives, WongReeceContact *out)
{
    const WongReeceModel *wm = &m->d.wong_reece;
    const double R = wm->radius, eps = m->p.contact_slipVelocityEps;
    const double dir = (fabs(omega_r) >= fabs(v_long) ? omega_r : v_long) < 0 ? -1.0 : 1.0;
    const double speed = fmax(fabs(omega_r), fabs(v_long));
    const double b = speed < eps ? speed / eps : 1.0;
    const double c = v_long >= eps ? 1.0 : v_long <= -eps ? -1.0 : v_long / eps;
    const double s = dir * slip;

    WRForces f;
    wong_reece_forces(wm, sinkage, s, &f);
    double T0 = 0.0;
    if (b < 1.0) {
        WRForces f0;
        wong_reece_forces(wm, sinkage, 0.0, &f0);
        T0 = f0.T;
    }
    /* applied forces along the heading and the soil normal, and the traction */
    const double Ft = shear_factor * dir * (f.T - (1.0 - b) * T0) / R;
    const double Hx = c * (f.Fx - f.T / R);            /* rolling resistance, regularised */
    out->Fx = Ft + Hx;
    out->Fz = f.Fz;
    out->area = wm->width * R * (sin(f.theta_f) - sin(f.theta_r));

    /* (Fx + i Fz) = e^{i alpha} (F_long + i Fn) */
    const double F2 = out->Fx * out->Fx + out->Fz * out->Fz;
    double Fl = Ft, Fn2 = F2 - Ft * Ft;
    if (!(Fn2 > 0.0)) {
        Fn2 = 0.0;
        Fl = copysign(sqrt(F2), Ft);
    }
    out->F_long = Fl;
    out->Fn = sqrt(Fn2);
    if (F2 > 0.0) {
        out->cos_alpha = (out->Fx * Fl + out->Fz * out->Fn) / F2;
        out->sin_alpha = (out->Fz * Fl - out->Fx * out->Fn) / F2;
    } else {
        out->cos_alpha = 1.0;
        out->sin_alpha = 0.0;
    }

    out->dFx_ds = out->dFz_ds = out->dFt_ds = out->kz = 0.0;
    if (!derivatives) return;
    if (f.slip > -1.0 && f.slip < 1.0) {
        const double ds = f.slip + 1e-3 <= 1.0 ? 1e-3 : -1e-3;
        WRForces g;
        wong_reece_forces(wm, sinkage, f.slip + ds, &g);
        const double dT = (g.T - f.T) / ds, dFx = (g.Fx - f.Fx) / ds, dFz = (g.Fz - f.Fz) / ds;
        /* d/d(slip) = dir d/ds (s = dir slip), and dir^2 = 1 */
        out->dFt_ds = shear_factor * dT / R;
        out->dFx_ds = out->dFt_ds + c * dir * (dFx - dT / R);
        out->dFz_ds = dir * dFz;
    }
    if (f.sinkage > 0.0 && f.sinkage < R) {
        const double dh = fmax(1e-3 * f.sinkage, 1e-6);
        WRForces g;
        wong_reece_forces(wm, f.sinkage + dh, f.slip, &g);
        out->kz = (g.Fz - f.Fz) / dh;
    }
}

/* ---------------------------------------------------- the dynamics */

/* Contact of wheel w: fills ev->wheel[w]; if J is given (matrices wanted),
 * adds its generalised force, damping and stiffness.  The wheel's angular
 * Jacobian is Jw; hub velocity Jacobian Jh. */
static void wheel_contact(const Model *m, Eval *ev, int w, double Jh[3][NU], double Jw[3][NU],
                          int matrices, double K[NU][NU])
{
    const ContactModel *cm = &m->d.contact;
    const double R = cm->radius;
    const double *u = m->s.u;
    const double *H = ev->hub[w];
    const int sp = U_SPIN_L + side_of(w);       /* this wheel's spin column */
    WheelContact *wc = &ev->wheel[w];
    memset(wc, 0, sizeof *wc);
    wc->cos_alpha = 1.0;

    double n[3];
    const double zt = terrain_query(m, H[0], H[1], n);
    /* Assumption: the soil is locally a plane through the terrain point
     * below the hub; the contact is solved in the wheel's mid-plane. */
    const double hub_height = (H[2] - zt) * n[2];
    double np[3];
    v3_copy(np, n);
    v3_axpy(np, -v3_dot(n, ev->e), ev->e);
    const double in_plane = v3_norm(np);
    if (in_plane < 1e-6) return;                        /* wheel lying on its side */
    v3_scale(np, np, 1.0 / in_plane);
    double sinkage = R - hub_height / in_plane;
    const Params *p = &m->p;
    double kh_factor, strength_factor;
    soil_factors(p, H[0], H[1], &kh_factor, &strength_factor);
    if (w % 2 == 1 && p->multipass_rutFraction > 0) {
        /* A rear wheel rolls in its front wheel's rut, on compacted soil. */
        const double rut = p->multipass_rutFraction *
                           rut_depth_at(&m->s, side_of(w), m->s.path[side_of(w)] - p->rover_wheelbase);
        sinkage -= rut;
        kh_factor *= 1.0 + (p->multipass_khFactor - 1.0) * rut / (rut + 0.002);
    }
    wc->sinkage = sinkage;
    double f[3], l[3];
    v3_cross(f, ev->e, np);                            /* heading in the contact plane */
    v3_cross(l, n, f);
    v3_normalize(l);
    double vh[3] = {0, 0, 0};
    for (int i = 0; i < 3; ++i) vh[i] = point_row_dot(Jh, i, u, sp);
    wc->v_long = v3_dot(f, vh);
    if (sinkage <= 0) return;
    wc->in_contact = 1;

    double wheel_omega[3];
    for (int i = 0; i < 3; ++i) wheel_omega[i] = angular_row_dot(Jw, i, u, sp);
    const double spin = v3_dot(wheel_omega, ev->e);   /* rad/s about the axle */
    const double omega_r = R * spin;
    const double den = fmax(fmax(fabs(omega_r), fabs(wc->v_long)), cm->slip_v_eps);
    wc->slip = (omega_r - wc->v_long) / den;
    if (p->slipSinkage_coefficient > 0)       /* the soil under a slipping wheel yields: it digs in */
        kh_factor /= 1.0 + p->slipSinkage_coefficient * fmin(fabs(wc->slip), 1.0);
    const double shear_factor = strength_factor * (1.0 + p->grouser_thrustGain);

    /* The normal force Fn, its tilt alpha (Eqns 6-9), the contact area and
     * the normal stiffness, from the contact law. */
    const int wong_reece = p->contact_model == CONTACT_LAW_WONG_REECE;
    WongReeceContact wr = {0};
    double Fn, sa, ca, area, support, kn;
    if (wong_reece) {
        wong_reece_contact(m, sinkage, wc->slip, wc->v_long, omega_r, shear_factor, matrices, &wr);
        Fn = wr.Fn;
        sa = wr.sin_alpha;
        ca = wr.cos_alpha;
        area = wr.area;
        support = wr.Fz;            /* the lateral law's normal load */
        kn = wr.kz;
    } else {
        double cut_front, cut_rear;
        contact_cuts(cm, &m->s.memory[w], sinkage, &cut_front, &cut_rear);
        ContactPatch patch;
        contact_patch(cm, sinkage, cut_front, cut_rear, &patch);
        Fn = kh_factor * patch.Fn;
        area = patch.area;
        support = Fn;
        /* Normal stiffness dFn/dz at fixed cuts, from contact_patch. */
        kn = kh_factor * patch.dFn_dz;
        /* The tilt alpha times the rolling factor; the usual factors +-1
         * and 0 need no trigonometry. */
        const double roll = contact_rolling_factor(cm, &m->s.memory[w], wc->v_long);
        sa = patch.sin_alpha;
        ca = patch.cos_alpha;
        if (roll == 0.0) {
            sa = 0.0;
            ca = 1.0;
        } else if (roll == -1.0) {
            sa = -sa;
        } else if (roll != 1.0) {
            const double alpha = roll * atan2(sa, ca);
            sa = sin(alpha);
            ca = cos(alpha);
        }
    }
    /* Grouser lugs (grouser.lugHeight h, volumetric law only): the soil
     * between the lugs turns with the wheel, so the shear surface is the
     * lug tips' circle, h beyond the rim the normal law presses on.  The
     * shear's slip velocity is omega (R + h) - v and its moment about the
     * axle (R + h) F_t: more torque per unit of thrust, and thrust already
     * at omega R = v.  Assumption: the pressure (Fn, its tilt, the
     * contact area) stays that of the rim of radius R.  With h = 0,
     * shear_radius is R exactly and nothing changes. */
    const double shear_radius = wong_reece ? R : R + p->grouser_lugHeight;
    const double omega_shear = shear_radius * spin;
    double nvec[3], t[3], r_rim[3];
    for (int i = 0; i < 3; ++i) {
        nvec[i] = -sa * f[i] + ca * np[i];             /* Eqn 6: from the centroid towards the hub */
        t[i] = ca * f[i] + sa * np[i];                 /* tangential direction of Eqns 8-9 */
        r_rim[i] = -shear_radius * nvec[i];            /* rim (or lug tip) point on the centroid ray */
    }
    /* The shear acts on the rim where the centroid ray meets it, so its
     * moment about the axle is exactly -R F_t (-(R + h) F_t with lugs) and
     * the normal force passes through the hub. */
    double Jp[3][NU];
    memcpy(Jp, Jh, sizeof Jp);
    add_wheel_offset(Jp, Jw, r_rim, sp);
    double v_rim[3];
    for (int i = 0; i < 3; ++i) v_rim[i] = point_row_dot(Jp, i, u, sp);
    const double v_lat = v3_dot(l, v_rim);
    double F_long, F_lat, jac[6];
    contact_shear(cm, support, area, wc->v_long, v_lat, omega_shear, &F_long, &F_lat, matrices ? jac : NULL);
    if (shear_factor != 1.0) {           /* soil patch strength, grouser thrust: F_taumax scales */
        F_long *= shear_factor;
        F_lat *= shear_factor;
        if (matrices)
            for (int i = 0; i < 6; ++i) jac[i] *= shear_factor;
    }
    if (wong_reece) {
        /* Assumption: Wong-Reece has no lateral force; the lateral one is
         * the volumetric slip-vector law's (combined slip, soil.Kvx,
         * soil.KvyRatio) with F_taumax from WR's normal load and contact
         * area.  The traction along the heading is WR's (its damping is
         * added below, so the law's own longitudinal Jacobian row goes). */
        F_long = wr.F_long;
        if (matrices) jac[0] = jac[1] = jac[2] = 0.0;
    }
    wc->Fn = Fn;
    wc->F_long = F_long;
    wc->F_lat = F_lat;
    wc->sin_alpha = sa;
    wc->cos_alpha = ca;
    for (int i = 0; i < 3; ++i) wc->force[i] = Fn * nvec[i] + F_long * t[i] + F_lat * l[i];
    if (!matrices) return;

    point_add_generalised(ev->Q, Jp, wc->force, sp);
    /* Damping: -dQ/du of the shear, through v_long, v_lat and omega R. */
    double g_long[NU], g_lat[NU], g_spin[NU], a_t[NU], e_row[NU];
    point_vec_times_jac(g_long, f, Jh, sp);
    point_vec_times_jac(g_lat, l, Jp, sp);
    angular_vec_times_jac(e_row, ev->e, Jw, sp);
    for (int k = 0; k < NU; ++k) g_spin[k] = shear_radius * e_row[k];
    point_vec_times_jac(a_t, t, Jp, sp);
    double dFl[NU], dFy[NU];
    for (int k = 0; k < NU; ++k) {
        dFl[k] = jac[0] * g_long[k] + jac[1] * g_lat[k] + jac[2] * g_spin[k];
        dFy[k] = jac[3] * g_long[k] + jac[4] * g_lat[k] + jac[5] * g_spin[k];
    }
    add_outer(ev->D, a_t, -1.0, dFl);
    add_outer(ev->D, g_lat, -1.0, dFy);
    /* The stiffness K = -dQ/dq: the force's direction times the sinkage's
     * gradient.  Sinkage = R - (H_z - z_t) n_z / in_plane grows by
     * -(n . dH) / in_plane when the hub moves by dH, whatever the force's
     * tilt, so the row is a_s = -d(sinkage)/dq = Jh^T n / in_plane.  Why not
     * the force's own direction (a symmetric K): the force tilts back by
     * alpha, and a wheel rolling forward at v then "climbs" v sin(alpha)
     * per second along it.  The step's end-of-step force was then short by
     * h kn v sin(alpha), a bias of first order in h even in steady rolling:
     * measured (PID at 2 rad/s, 300 N drawbar), the front normal loads
     * 6.9 % low at solver.step 20 ms and 0.37 % low at 1 ms; now the same
     * to 6 digits at every step. */
    double a_s[NU];
    point_vec_times_jac(a_s, n, Jh, sp);
    for (int k = 0; k < NU; ++k) a_s[k] /= in_plane;
    double a_n[NU];
    if (wong_reece) {
        /* Slip damping of WR's in-plane forces: Q = Jh^T (Fx f + Fz np) -
         * T e^T Jw depends on u through the slip s = (omega R - v) / den. */
        double a_z[NU], dQ_ds[NU], ds_du[NU];
        point_vec_times_jac(a_z, np, Jh, sp);
        const double aw = fabs(omega_r), av = fabs(wc->v_long);
        double dden_dv = 0.0, dden_dw = 0.0;
        if (aw >= av && aw >= cm->slip_v_eps) dden_dw = omega_r > 0.0 ? 1.0 : -1.0;
        else if (av >= cm->slip_v_eps) dden_dv = wc->v_long > 0.0 ? 1.0 : -1.0;
        const double ds_dv = (-1.0 - wc->slip * dden_dv) / den, ds_dw = (1.0 - wc->slip * dden_dw) / den;
        for (int k = 0; k < NU; ++k) {
            dQ_ds[k] = g_long[k] * wr.dFx_ds + a_z[k] * wr.dFz_ds - g_spin[k] * wr.dFt_ds;
            ds_du[k] = ds_dv * g_long[k] + ds_dw * g_spin[k];
        }
        add_outer(ev->D, dQ_ds, -1.0, ds_du);
        /* Normal stiffness: dFz along the soil normal per unit of sinkage. */
        add_outer(K, a_z, kn, a_s);
        return;
    }
    point_vec_times_jac(a_n, nvec, Jh, sp);
    add_outer(K, a_n, kn, a_s);
}

/* One rigid body's kinematics for the assembly.  With r = CG - chassis
 * reference point (world), the CG velocity is
 *   v = u_v + w x r + u_beta cb,
 * and the angular velocity w + u_beta sb e + u_spin e (the spin term on
 * a wheel only); that is, Jv = [I, -[r]x, cb, 0] and Jw = [0, I, sb e, e].
 * The assembly below multiplies these blocks out instead of forming the
 * 3 x 9 matrices (most of their 54 entries are 0 or 1). */
typedef struct {
    double mass, r[3], I[9];       /* kg; m; world inertia about the CG, kg m^2 */
    double cb[3];                  /* CG velocity per unit rocker rate, m/rad (0: chassis) */
    double sb;                     /* rocker-rate factor of the angular velocity: sigma, or 0 */
    double spin_rate;              /* about e, relative to the chassis, rad/s */
    int side;                      /* SIDE_LEFT or SIDE_RIGHT for a rocker or wheel, -1: chassis */
    int spin;                      /* U_SPIN_L or U_SPIN_R for a wheel, -1 otherwise */
    double Ie[3], eIe;             /* I e and e.I e (rocker or wheel) */
} Body;

/* What the bodies share within one evaluation. */
typedef struct {
    const double *w;               /* chassis angular velocity, rad/s */
    double g;                      /* gravity, m/s^2 */
    double wxe[3];                 /* w x e */
    double pivot_acc[2][3];        /* w x (w x (pivot - reference point)), per side */
} BodyCommon;

/* Adds body b's mass matrix (upper triangle) and generalised forces
 * (gravity, bias and gyroscopic terms) to M and Q. */
static void add_body(const Eval *ev, const BodyCommon *c, const Body *b, double M[NU][NU], double Q[NU])
{
    const double m = b->mass, *r = b->r, *I = b->I, *e = ev->e, *w = c->w, g = c->g;
    /* Bias accelerations (u' = 0) of the CG and of the angular velocity. */
    double bv[3], bw[3], tmp[3];
    if (b->side >= 0) {
        /* CG = pivot + sv, the body turning at w + sb u_beta e about the pivot */
        double sv[3], wr[3], tmp2[3];
        const double *rd = ev->pivot_r[b->side], *wxe = c->wxe;
        const double sb_rate = b->sb * ev->u_beta;
        v3_sub(sv, r, rd);
        v3_copy(bv, c->pivot_acc[b->side]);
        v3_cross(tmp, wxe, sv);
        v3_axpy(bv, sb_rate, tmp);
        v3_copy(wr, w);
        v3_axpy(wr, sb_rate, e);
        v3_cross(tmp, wr, sv);
        v3_cross(tmp2, wr, tmp);
        v3_add(bv, bv, tmp2);
        v3_scale(bw, wxe, b->spin_rate);
    } else {
        v3_cross(tmp, w, r);
        v3_cross(bv, w, tmp);
        v3_set(bw, 0, 0, 0);
    }
    /* body angular velocity and gyroscopic torque */
    double wb[3], Iw[3], gyro[3], Ibw[3];
    v3_copy(wb, w);
    v3_axpy(wb, b->spin_rate, e);
    m3_mul_v(Iw, I, wb);
    v3_cross(gyro, wb, Iw);
    m3_mul_v(Ibw, I, bw);
    const double F[3] = {-m * bv[0], -m * bv[1], -m * (bv[2] + g)};
    const double T[3] = {-Ibw[0] - gyro[0], -Ibw[1] - gyro[1], -Ibw[2] - gyro[2]};

    /* Q += Jv^T F + Jw^T T */
    double rF[3];
    v3_cross(rF, r, F);
    for (int i = 0; i < 3; ++i) {
        Q[U_VX + i] += F[i];
        Q[U_WX + i] += rF[i] + T[i];
    }
    /* M += m Jv^T Jv + Jw^T I Jw, upper triangle:
     *   vv: m 1, vw: -m [r]x, ww: m (|r|^2 1 - r r^T) + I. */
    const double rr = v3_dot(r, r);
    for (int i = 0; i < 3; ++i) M[U_VX + i][U_VX + i] += m;
    M[U_WX + 0][U_WX + 0] += m * (rr - r[0] * r[0]) + I[0];
    M[U_WX + 0][U_WX + 1] += m * (0 - r[0] * r[1]) + I[1];
    M[U_WX + 0][U_WX + 2] += m * (0 - r[0] * r[2]) + I[2];
    M[U_WX + 1][U_WX + 1] += m * (rr - r[1] * r[1]) + I[4];
    M[U_WX + 1][U_WX + 2] += m * (0 - r[1] * r[2]) + I[5];
    M[U_WX + 2][U_WX + 2] += m * (rr - r[2] * r[2]) + I[8];
    M[U_VX + 0][U_WX + 1] += m * r[2];
    M[U_VX + 0][U_WX + 2] -= m * r[1];
    M[U_VX + 1][U_WX + 0] -= m * r[2];
    M[U_VX + 1][U_WX + 2] += m * r[0];
    M[U_VX + 2][U_WX + 0] += m * r[1];
    M[U_VX + 2][U_WX + 1] -= m * r[0];
    if (b->side < 0) return;
    /* rocker rate column: vb: m cb, wb: m r x cb + sb I e, bb: m cb.cb + sb^2 e.I e */
    const double *Ie = b->Ie, eIe = b->eIe;
    double rc[3];
    v3_cross(rc, r, b->cb);
    for (int i = 0; i < 3; ++i) {
        M[U_VX + i][U_BETA] += m * b->cb[i];
        M[U_WX + i][U_BETA] += m * rc[i] + b->sb * Ie[i];
    }
    M[U_BETA][U_BETA] += m * v3_dot(b->cb, b->cb) + b->sb * b->sb * eIe;
    Q[U_BETA] += v3_dot(b->cb, F) + b->sb * v3_dot(e, T);
    if (b->spin < 0) return;
    /* wheel spin column: ws: I e, bs: sb e.I e, ss: e.I e */
    for (int i = 0; i < 3; ++i) M[U_WX + i][b->spin] += Ie[i];
    M[U_BETA][b->spin] += b->sb * eIe;
    M[b->spin][b->spin] += eIe;
    Q[b->spin] += v3_dot(e, T);
}

/* The part of an evaluation that does not depend on the inputs:
 * kinematics, the bodies' M and Q (if matrices), the contacts (and their
 * Q, D, K).  From s.pos, quat, beta, u, memory, path, rut, the parameters,
 * derived data and terrain only (what EvalKey records). */
static void evaluate_passive(const Model *m, Eval *ev, int matrices)
{
    double (*K)[NU] = ev->K;
    const Params *p = &m->p;
    const Derived *d = &m->d;
    const State *s = &m->s;
    const double *u = s->u;

    quat_to_m3(ev->R, s->quat);
    v3_set(ev->e, ev->R[1], ev->R[4], ev->R[7]);
    v3_set(ev->heading, ev->R[0], ev->R[3], 0);
    v3_normalize(ev->heading);
    ev->u_beta = u[U_BETA];

    /* Rocker frames R Ry(sigma beta): the y column is the chassis's, one
     * sine and cosine serve both sides (sin is odd). */
    double Rr[2][9];
    const double cb = cos(s->beta), sbeta = sin(s->beta);
    for (int k = 0; k < 2; ++k) {
        const double sb = sigma_of(k) * sbeta;
        const double *R = ev->R;
        double *A = Rr[k];
        for (int i = 0; i < 3; ++i) {
            A[3 * i + 0] = R[3 * i] * cb - R[3 * i + 2] * sb;
            A[3 * i + 1] = R[3 * i + 1];
            A[3 * i + 2] = R[3 * i] * sb + R[3 * i + 2] * cb;
        }
        m3_mul_v(ev->pivot_r[k], ev->R, d->pivot[k]);
        v3_add(ev->pivot[k], s->pos, ev->pivot_r[k]);
    }
    double hub_r[NUM_WHEELS][3];   /* hub - chassis reference point */
    for (int wh = 0; wh < NUM_WHEELS; ++wh) {
        const int side = side_of(wh);
        double tmp[3];
        m3_mul_v(tmp, Rr[side], d->hub[wh % 2]);
        v3_add(ev->hub[wh], ev->pivot[side], tmp);
        v3_add(hub_r[wh], ev->pivot_r[side], tmp);
        /* The hub Jacobians wheel_contact works with (dense rows). */
        double (*Jv)[NU] = ev->Jv[BODY_WHEEL0 + wh];
        double (*Jw)[NU] = ev->Jw[BODY_WHEEL0 + wh];
        point_jacobian(ev, s->pos, ev->hub[wh], side, Jv);
        const double sg = sigma_of(side);
        for (int i = 0; i < 3; ++i) {
            Jw[i][U_VX + 0] = 0; Jw[i][U_VX + 1] = 0; Jw[i][U_VX + 2] = 0;
            Jw[i][U_WX + 0] = i == 0; Jw[i][U_WX + 1] = i == 1; Jw[i][U_WX + 2] = i == 2;
            Jw[i][U_BETA] = sg * ev->e[i];
            Jw[i][U_SPIN_L] = side == SIDE_LEFT ? ev->e[i] : 0;
            Jw[i][U_SPIN_R] = side == SIDE_RIGHT ? ev->e[i] : 0;
        }
    }

    if (matrices) {
        memset(ev->M, 0, sizeof ev->M);
        memset(ev->Q, 0, sizeof ev->Q);
        memset(ev->D, 0, sizeof ev->D);
        memset(K, 0, sizeof(double) * NU * NU);
        BodyCommon common;
        common.w = &u[U_WX];
        common.g = p->env_gravity;
        v3_cross(common.wxe, common.w, ev->e);
        for (int side = 0; side < 2; ++side) {
            double tmp[3];
            v3_cross(tmp, common.w, ev->pivot_r[side]);
            v3_cross(common.pivot_acc[side], common.w, tmp);
        }
        Body b;
        /* chassis */
        b.mass = d->chassis_mass;
        m3_mul_v(b.r, ev->R, d->chassis_cg);
        m3_rotate_diag(b.I, ev->R, d->chassis_inertia);
        v3_set(b.cb, 0, 0, 0);
        b.sb = 0;
        b.side = -1;
        b.spin_rate = 0;
        b.spin = -1;
        add_body(ev, &common, &b, ev->M, ev->Q);
        /* rockers */
        for (int side = 0; side < 2; ++side) {
            double tmp[3], sv[3];
            b.mass = p->rover_rockerMass;
            m3_mul_v(tmp, Rr[side], d->rocker_cg);
            v3_add(b.r, ev->pivot_r[side], tmp);
            m3_rotate_diag(b.I, Rr[side], d->rocker_inertia);
            b.sb = sigma_of(side);
            b.side = side;
            v3_cross(sv, ev->e, tmp);                 /* e x (CG - pivot) */
            v3_scale(b.cb, sv, b.sb);
            b.spin_rate = b.sb * u[U_BETA];
            b.spin = -1;
            m3_mul_v(b.Ie, b.I, ev->e);
            b.eIe = v3_dot(ev->e, b.Ie);
            add_body(ev, &common, &b, ev->M, ev->Q);
        }
        /* wheels: discs about the axle e */
        const double It = d->wheel_inertia_transverse, Is = p->wheel_inertia;
        b.mass = p->wheel_mass;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) b.I[3 * i + j] = (i == j ? It : 0) + (Is - It) * ev->e[i] * ev->e[j];
        m3_mul_v(b.Ie, b.I, ev->e);
        b.eIe = v3_dot(ev->e, b.Ie);
        for (int wh = 0; wh < NUM_WHEELS; ++wh) {
            const int side = side_of(wh);
            v3_copy(b.r, hub_r[wh]);
            b.sb = sigma_of(side);
            b.side = side;
            for (int i = 0; i < 3; ++i) b.cb[i] = ev->Jv[BODY_WHEEL0 + wh][i][U_BETA];
            b.spin_rate = b.sb * u[U_BETA] + u[U_SPIN_L + side];
            b.spin = U_SPIN_L + side;
            add_body(ev, &common, &b, ev->M, ev->Q);
        }
        for (int i = 0; i < NU; ++i)
            for (int j = 0; j < i; ++j) ev->M[i][j] = ev->M[j][i];
    }

    /* Contacts: the hub Jacobian is the wheel body's CG Jacobian. */
    for (int wh = 0; wh < NUM_WHEELS; ++wh)
        wheel_contact(m, ev, wh, ev->Jv[BODY_WHEEL0 + wh], ev->Jw[BODY_WHEEL0 + wh], matrices, K);
}

/* The part that depends on the inputs (and s.pid_integral): the drive
 * torques and, if matrices, the drive, rocker damping and drawbar terms
 * added to the Q, D, K of evaluate_passive (once per passive evaluation). */
static void evaluate_inputs(const Model *m, Eval *ev, int matrices)
{
    const Params *p = &m->p;
    const double *u = m->s.u;
    double (*K)[NU] = ev->K;
    double *slope = ev->torque_slope;
    drive_torques(m, ev->torque, slope);
    if (!matrices) return;

    /* Drive: the motor on each rocker turns its side's wheels relative to it. */
    /* The drive torque is on the motor side (what the current measures);
     * the wheels get (1 - drive.lossFraction) of it. */
    const double transmitted = 1.0 - p->drive_lossFraction;
    for (int k = 0; k < 2; ++k) {
        ev->Q[U_SPIN_L + k] += transmitted * ev->torque[k];
        ev->D[U_SPIN_L + k][U_SPIN_L + k] -= transmitted * slope[k];
        /* The PID's integral acts like a torsion spring on the spin angle (I' = ref - omega):
         * treated implicitly as a stiffness, so a stiff PID stays stable at large steps
         * (explicitly, K_i = 2e4 N m/rad went unstable at 5 ms in soft soil).  Off when the
         * torque is saturated (slope 0), where the anti-windup holds the integral. */
        if (p->drive_mode == DRIVE_PID && slope[k] != 0)
            K[U_SPIN_L + k][U_SPIN_L + k] += transmitted * p->drive_Ki;
    }
    /* Rocker differential friction. */
    ev->Q[U_BETA] -= p->rover_rockerDamping * u[U_BETA];
    ev->D[U_BETA][U_BETA] += p->rover_rockerDamping;
    /* Drawbar: horizontal, backwards along the heading, at the hitch (a
     * chassis point r from the reference point: Q_v += F, Q_w += r x F). */
    const double hitch_local[3] = {p->rover_hitchX, 0, p->rover_hitchZ};
    double r_hitch[3], Fd[3], rF[3];
    m3_mul_v(r_hitch, ev->R, hitch_local);
    v3_scale(Fd, ev->heading, -m->in.drawbarForce);
    v3_cross(rF, r_hitch, Fd);
    for (int i = 0; i < 3; ++i) {
        ev->Q[U_VX + i] += Fd[i];
        ev->Q[U_WX + i] += rF[i];
    }
}

/* Evaluates kinematics, forces and (if matrices) M, Q, D, K. */
static void evaluate(const Model *m, Eval *ev, int matrices)
{
    evaluate_passive(m, ev, matrices);
    evaluate_inputs(m, ev, matrices);
}

/* One column of the elimination in solve(): partial pivoting among rows
 * c..NU-1 (by row pointer), then the rows below lose their column-c entry.
 * The entries left of the diagonal are never read again, so they are not
 * updated.  Inlined with a constant c, the loops have fixed lengths. */
static inline int eliminate_column(double *row[NU], int idx[NU], double b[NU], const int c)
{
    int piv = c;
    double best = fabs(row[c][c]);
    for (int r = c + 1; r < NU; ++r) {
        const double v = fabs(row[r][c]);
        if (v > best) best = v, piv = r;
    }
    if (!(best > 1e-300)) return -1;
    if (piv != c) {
        double *t = row[c]; row[c] = row[piv]; row[piv] = t;
        const int ti = idx[c]; idx[c] = idx[piv]; idx[piv] = ti;
    }
    const double *pr = row[c], pivot = pr[c], bc = b[idx[c]];
    for (int r = c + 1; r < NU; ++r) {
        double *rr = row[r];
        const double f = rr[c] / pivot;
        if (f == 0) continue;
        for (int k = c + 1; k < NU; ++k) rr[k] -= f * pr[k];
        b[idx[r]] -= f * bc;
    }
    return 0;
}

/* Solves A x = b (n = NU) by Gaussian elimination with partial pivoting.
 * A and b are overwritten.  Returns -1 if singular.  The rows are swapped
 * through pointers: the arithmetic is that of the textbook loop,
 * operation for operation. */
static int solve(double A[NU][NU], double b[NU])
{
    _Static_assert(NU == 9, "solve() unrolls its columns for NU = 9");
    double *row[NU], x[NU];
    int idx[NU];
    for (int i = 0; i < NU; ++i) row[i] = A[i], idx[i] = i;
    if (eliminate_column(row, idx, b, 0) || eliminate_column(row, idx, b, 1) || eliminate_column(row, idx, b, 2) ||
        eliminate_column(row, idx, b, 3) || eliminate_column(row, idx, b, 4) || eliminate_column(row, idx, b, 5) ||
        eliminate_column(row, idx, b, 6) || eliminate_column(row, idx, b, 7) || eliminate_column(row, idx, b, 8))
        return -1;
    for (int c = NU - 1; c >= 0; --c) {
        const double *pr = row[c];
        double s = b[idx[c]];
        for (int k = c + 1; k < NU; ++k) s -= pr[k] * x[k];
        x[c] = s / pr[c];
    }
    memcpy(b, x, sizeof x);
    return 0;
}

/* The steepest terrain slope (rad) under the points (x, y) of n points,
 * and which point it is under. */
static double steepest_slope(const Model *m, const double (*xy)[3], int n, int *which)
{
    double steepest = 0.0;
    *which = 0;
    for (int k = 0; k < n; ++k) {
        double nrm[3];
        terrain_query(m, xy[k][0], xy[k][1], nrm);
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
static int slope_beyond_friction(const Model *m, const double (*xy)[3], char *buf, size_t n)
{
    int w;
    const double slope = steepest_slope(m, xy, NUM_WHEELS, &w);
    if (!(slope > m->p.soil_phi)) return 0;
    snprintf(buf, n,
             "the terrain under wheel %s slopes %.1f deg, steeper than the soil's friction angle soil.phi = "
             "%.1f deg: the soil cannot hold the rover there (terrain too steep)",
             wheel_names[w], slope * 180.0 / M_PI, m->p.soil_phi * 180.0 / M_PI);
    return 1;
}

/* Speed (m/s) at which wheel w's hub moves into the ground, along the
 * terrain normal under it (negative: away from it). */
static double hub_approach_speed(const Model *m, const Eval *ev, int w)
{
    double n[3], v[3];
    terrain_query(m, ev->hub[w][0], ev->hub[w][1], n);
    for (int i = 0; i < 3; ++i) {
        v[i] = 0.0;
        for (int k = 0; k < NU; ++k) v[i] += ev->Jv[BODY_WHEEL0 + w][i][k] * m->s.u[k];
    }
    return -v3_dot(n, v);
}

/* The likely cause of a wheel sinking deeper than its radius, from what
 * the model knows at that moment, the first that holds of:
 *  - the terrain under a wheel slopes more steeply than soil.phi (above);
 *  - the wheel struck the ground faster than a fall from its own radius
 *    height, sqrt(2 g R): the rover fell or tumbled, and no soil stops a
 *    wheel within its radius from such a speed at these stiffnesses;
 *  - otherwise the soil yields that far under the load: too soft. */
static void sinkage_cause(const Model *m, const Eval *ev, int w, char *buf, size_t n)
{
    if (slope_beyond_friction(m, (const double (*)[3])ev->hub, buf, n)) return;
    const double speed = hub_approach_speed(m, ev, w), fall = sqrt(2.0 * m->p.env_gravity * m->p.wheel_radius);
    if (speed > fall) {
        snprintf(buf, n,
                 "it struck the ground at %.2f m/s, faster than a fall from its radius height (%.2f m/s): the "
                 "rover fell or tumbled (terrain too steep or rough?)", speed, fall);
        return;
    }
    snprintf(buf, n, "the soil is too soft for the load on these wheels (check soil.kh, soil.eta, wheel.radius, "
             "wheel.width)");
}

static int state_is_sane(const Model *m, const Eval *ev, char *err, size_t n)
{
    const State *s = &m->s;
    char cause[256];
    for (int i = 0; i < 3; ++i)
        if (!isfinite(s->pos[i])) return snprintf(err, n, "state diverged at t = %.4f s: position is not finite", s->time), 0;
    for (int i = 0; i < NU; ++i)
        if (!isfinite(s->u[i]) || fabs(s->u[i]) > 1e3)
            return snprintf(err, n, "state diverged at t = %.4f s: velocity component %d = %g", s->time, i, s->u[i]), 0;
    if (fabs(s->beta) > 1.2)
        return snprintf(err, n, "state diverged at t = %.4f s: rocker angle %g rad", s->time, s->beta), 0;
    for (int w = 0; w < NUM_WHEELS; ++w)
        if (ev->wheel[w].sinkage >= m->p.wheel_radius) {
            sinkage_cause(m, ev, w, cause, sizeof cause);
            return snprintf(err, n, "state diverged at t = %.4f s: wheel %s sank %.3f m, deeper than its radius; %s",
                            s->time, wheel_names[w], ev->wheel[w].sinkage, cause), 0;
        }
    return 1;
}

/* ------------------------------------------- reusing an evaluation */

/* The evaluation at the end of a communication step (for the outputs) is
 * that of the state the next step starts from.  Only its drive and drawbar
 * terms depend on the inputs, which the importer may change in between;
 * so the input-independent part (evaluate_passive, with matrices) is kept
 * in m->eval and the next step's first substep adds the input terms to it
 * (evaluate_inputs), the same operations in the same order as evaluating
 * afresh.  It is used only if nothing it was computed from has changed
 * since, byte for byte (EvalKey: parameters, derived data, terrain, the
 * state it reads); fmi2SetFMUstate, a new parameter or terrain, or a
 * failed step make the next step evaluate afresh. */
static void eval_key_store(Model *m)
{
    EvalKey *k = &m->eval_key;
    const State *s = &m->s;
    memcpy(&k->p, &m->p, sizeof k->p);
    memcpy(&k->d, &m->d, sizeof k->d);
    memcpy(&k->terrain, &m->terrain, sizeof k->terrain);
    memcpy(k->pos, s->pos, sizeof k->pos);
    memcpy(k->quat, s->quat, sizeof k->quat);
    k->beta = s->beta;
    memcpy(k->u, s->u, sizeof k->u);
    memcpy(k->memory, s->memory, sizeof k->memory);
    memcpy(k->path, s->path, sizeof k->path);
    if (m->p.multipass_rutFraction > 0) memcpy(k->rut, s->rut, sizeof k->rut);
}

static int eval_key_matches(const Model *m)
{
    const EvalKey *k = &m->eval_key;
    const State *s = &m->s;
    return memcmp(&k->p, &m->p, sizeof k->p) == 0 && memcmp(&k->d, &m->d, sizeof k->d) == 0 &&
           memcmp(&k->terrain, &m->terrain, sizeof k->terrain) == 0 &&
           memcmp(k->pos, s->pos, sizeof k->pos) == 0 && memcmp(k->quat, s->quat, sizeof k->quat) == 0 &&
           memcmp(&k->beta, &s->beta, sizeof k->beta) == 0 && memcmp(k->u, s->u, sizeof k->u) == 0 &&
           memcmp(k->memory, s->memory, sizeof k->memory) == 0 &&
           memcmp(k->path, s->path, sizeof k->path) == 0 &&
           (!(m->p.multipass_rutFraction > 0) || memcmp(k->rut, s->rut, sizeof k->rut) == 0);
}

static void outputs_from(Model *m, const Eval *ev);

/* The end-of-step evaluation: the outputs, and m->eval kept for reuse. */
static void evaluate_end_of_step(Model *m)
{
    evaluate_passive(m, &m->eval, 1);
    eval_key_store(m);
    m->eval_valid = 1;
    evaluate_inputs(m, &m->eval, 0);          /* the torques only: Q, D, K stay input-free */
    outputs_from(m, &m->eval);
}

/* One internal step of length h.  reuse: m->eval holds the passive
 * evaluation of the current state (model_do_step checked it). */
static int substep(Model *m, double h, int reuse, char *err, size_t errlen)
{
    State *s = &m->s;
    Eval *ev = &m->eval;
    double (*K)[NU] = ev->K;
    double A[NU][NU], b[NU];
    if (!reuse) evaluate_passive(m, ev, 1);
    m->eval_valid = 0;                        /* it gets the input terms, and the state moves on */
    evaluate_inputs(m, ev, 1);
    for (int i = 0; i < NU; ++i) {
        double Ku = 0;
        for (int j = 0; j < NU; ++j) {
            A[i][j] = ev->M[i][j] + h * ev->D[i][j] + h * h * K[i][j];
            Ku += K[i][j] * s->u[j];
        }
        b[i] = h * (ev->Q[i] - h * Ku);
    }
    if (m->p.drive_mode == DRIVE_PID)   /* the reference's share of the implicit PID integral */
        for (int k = 0; k < 2; ++k)
            if (ev->torque_slope[k] != 0) {
                const double ref = k == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
                b[U_SPIN_L + k] += h * h * (1.0 - m->p.drive_lossFraction) * m->p.drive_Ki * ref;
            }
    if (solve(A, b) != 0)
        return snprintf(err, errlen, "singular mass matrix at t = %.4f s", s->time), -1;

    for (int k = 0; k < 2; ++k) s->torque_applied[k] = ev->torque[k];
    for (int i = 0; i < NU; ++i) s->u[i] += b[i];
    /* PID integral with anti-windup: integrate only while not saturated,
     * or while the error would bring the torque back inside the limit.  The
     * error is the end-of-step one, as the implicit stiffness above assumes. */
    if (m->p.drive_mode == DRIVE_PID) {
        for (int k = 0; k < 2; ++k) {
            double ref = k == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
            double e = ref - s->u[U_SPIN_L + k];
            int saturated = fabs(ev->torque[k]) >= m->p.drive_torqueMax;
            if (!saturated || e * ev->torque[k] < 0) s->pid_integral[k] += e * h;
        }
        /* What the wheels got over the step is the end-of-step PID torque. */
        double slope[2];
        drive_torques(m, s->torque_applied, slope);
    }
    for (int i = 0; i < 3; ++i) s->pos[i] += h * s->u[U_VX + i];
    quat_integrate_world(s->quat, &s->u[U_WX], h);
    s->beta += h * s->u[U_BETA];
    for (int w = 0; w < NUM_WHEELS; ++w)
        contact_memory_update(&m->d.contact, &s->memory[w], ev->wheel[w].sinkage, ev->wheel[w].v_long, h);
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
    s->time += h;
    if (!state_is_sane(m, ev, err, errlen)) return -1;
    return 0;
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

int model_do_step(Model *m, double h_comm, char *err, size_t errlen)
{
    if (!inputs_are_finite(&m->in, err, errlen)) return -1;
    const double t_end = m->s.time + h_comm;
    int n = (int)ceil(h_comm / m->p.solver_step - 1e-9);
    if (n < 1) n = 1;
    const double h = h_comm / n;
    const int reuse = m->eval_valid && eval_key_matches(m);
    for (int i = 0; i < n; ++i)
        if (substep(m, h, reuse && i == 0, err, errlen) != 0) return -1;
    m->s.time = t_end;
    evaluate_end_of_step(m);
    return 0;
}

/* ------------------------------------------------------------ outputs */

void model_compute_outputs(Model *m)
{
    Eval ev;
    evaluate(m, &ev, 0);
    outputs_from(m, &ev);
}

/* Outputs from an evaluation of the current state (with its torques). */
static void outputs_from(Model *m, const Eval *ev)
{
    Outputs *o = &m->out;
    const double *R = ev->R;
    o->x = m->s.pos[0];
    o->y = m->s.pos[1];
    o->z = m->s.pos[2];
    o->yaw = atan2(R[3], R[0]);
    o->pitch = asin(fmax(-1.0, fmin(1.0, -R[6])));
    o->roll = atan2(R[7], R[8]);
    o->vx = v3_dot(&m->s.u[U_VX], ev->heading);
    o->omegaLeft = m->s.u[U_SPIN_L];
    o->omegaRight = m->s.u[U_SPIN_R];
    o->torqueLeftApplied = ev->torque[SIDE_LEFT];
    o->torqueRightApplied = ev->torque[SIDE_RIGHT];
    o->rocker = m->s.beta;
    for (int w = 0; w < NUM_WHEELS; ++w) {
        const WheelContact *wc = &ev->wheel[w];
        WheelOutputs *wo = &o->wheel[w];
        const double sa = wc->sin_alpha, ca = wc->cos_alpha;
        wo->sinkage = wc->sinkage;
        wo->slip = wc->slip;
        wo->Fn = wc->Fn;
        wo->Ft = wc->F_long;
        wo->Fx = wc->F_long * ca - wc->Fn * sa;
        wo->Fy = wc->F_lat;
        wo->Fz = wc->Fn * ca + wc->F_long * sa;
    }
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
    evaluate(m, &ev, 0);
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
    evaluate(m, &ev, 1);
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

static int find_equilibrium(Model *m, char *err, size_t errlen)
{
    const Params *p = &m->p;
    const double weight = p->rover_mass * p->env_gravity, moment_scale = weight * p->rover_wheelbase;
    /* Start from the ground under the four nominal wheel positions: each
     * rocker pitched along its own side's ground (their difference is the
     * differential's twist), the chassis rolled across, a centimetre of
     * sinkage.  Starting level on uneven ground lets Newton settle on the
     * uphill wheels alone. */
    const double cy = cos(p->init_yaw), sy = sin(p->init_yaw);
    double ground[NUM_WHEELS];
    for (int w = 0; w < NUM_WHEELS; ++w) {
        double lx = (w % 2 == 0 ? 0.5 : -0.5) * p->rover_wheelbase;
        double ly = (side_of(w) == SIDE_LEFT ? 0.5 : -0.5) * p->rover_track;
        ground[w] = terrain_query(m, p->init_x + cy * lx - sy * ly, p->init_y + sy * lx + cy * ly, NULL);
    }
    const double pitch_left = -atan((ground[WHEEL_FL] - ground[WHEEL_RL]) / p->rover_wheelbase);
    const double pitch_right = -atan((ground[WHEEL_FR] - ground[WHEEL_RR]) / p->rover_wheelbase);
    const double roll = atan(0.5 * (ground[WHEEL_FL] + ground[WHEEL_RL] - ground[WHEEL_FR] - ground[WHEEL_RR]) /
                             p->rover_track);
    const double mean_ground = 0.25 * (ground[0] + ground[1] + ground[2] + ground[3]);
    const double pitch = 0.5 * (pitch_left + pitch_right);
    double x[4] = {mean_ground + (p->rover_pivotHeight + p->wheel_radius - 0.01) * cos(pitch) * cos(roll), roll,
                   pitch, 0.5 * (pitch_left - pitch_right)};
    double r[4];
    /* Height first, by bisection between a pose with every wheel in the air (the soil
     * carries nothing) and one sunk 0.8 R deeper (it carries more than the weight): robust
     * from the softest to a near-rigid soil, where the first guess may already be far too
     * deep.  Then Newton on all four. */
    double z_air = x[0] + 0.05, z_deep = x[0] - 0.8 * p->wheel_radius;
    for (int it = 0; it < 60; ++it) {
        x[0] = 0.5 * (z_air + z_deep);
        equilibrium_residual(m, x, r);
        if (r[0] < 0) z_air = x[0];
        else z_deep = x[0];
    }
    x[0] = z_deep;
    equilibrium_residual(m, x, r);
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
        /* Backtracking keeps every Newton step an improvement. */
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
        memcpy(x, xn, sizeof x);
        memcpy(r, rn, sizeof r);
        res = resn;
    }
    if (!(res < 1e-8)) {
        double at[NUM_WHEELS][3];
        char steep[256];
        for (int w = 0; w < NUM_WHEELS; ++w) {
            const double lx = (w % 2 == 0 ? 0.5 : -0.5) * p->rover_wheelbase;
            const double ly = (side_of(w) == SIDE_LEFT ? 0.5 : -0.5) * p->rover_track;
            at[w][0] = p->init_x + cy * lx - sy * ly;
            at[w][1] = p->init_y + sy * lx + cy * ly;
            at[w][2] = 0.0;
        }
        if (!slope_beyond_friction(m, (const double (*)[3])at, steep, sizeof steep))
            snprintf(steep, sizeof steep,
                     "is the soil too soft for the load on these wheels (soil.kh, soil.eta, wheel.radius, "
                     "wheel.width)?");
        snprintf(err, errlen,
                 "no static equilibrium found for the rover at init.x = %g, init.y = %g (residual %.3g of the "
                 "weight): %s", p->init_x, p->init_y, res, steep);
        return -1;
    }
    place(m, x);
    Eval ev;
    evaluate(m, &ev, 0);
    for (int w = 0; w < NUM_WHEELS; ++w)
        if (!(ev.wheel[w].sinkage > 0)) {
            snprintf(err, errlen,
                     "the static equilibrium at init.x = %g, init.y = %g leaves wheel %s off the ground "
                     "(the rocker differential cannot reach it): choose another start pose",
                     p->init_x, p->init_y, wheel_names[w]);
            return -1;
        }
    return 0;
}

/* ------------------------------------------------------------- life cycle */

/* The Wong-Reece law's constants (model-notes section 6), from wongReece.*,
 * the shared soil.cohesion, soil.phi, the rebound lambda = soil.gamma and
 * the wheel.  Checked whatever contact.model is, so a bad value is
 * reported when it is set, not when the law is switched on later; the
 * messages name the FMU variables (wong_reece_prepare uses the same names;
 * gamma, cohesion, phi and the wheel were checked by contact_model_prepare). */
static int prepare_wong_reece(Model *m, char *err, size_t errlen)
{
    const Params *p = &m->p;
    if (p->contact_model != CONTACT_LAW_VOLUMETRIC && p->contact_model != CONTACT_LAW_WONG_REECE)
        return snprintf(err, errlen, "contact.model = %d must be 0 (volumetric) or 1 (Wong-Reece)",
                        p->contact_model), -1;
    WongReeceModel *wm = &m->d.wong_reece;
    memset(wm, 0, sizeof *wm);
    wm->n = p->wr_n;
    wm->kc = p->wr_kc;
    wm->kphi = p->wr_kphi;
    wm->cohesion = p->soil_cohesion;
    wm->phi = p->soil_phi;
    wm->K = p->wr_K;
    wm->a0 = p->wr_a0;
    wm->a1 = p->wr_a1;
    wm->lambda = p->soil_gamma;
    wm->radius = p->wheel_radius;
    wm->width = p->wheel_width;
    wm->points = p->wr_points;
    return wong_reece_prepare(wm, err, errlen);
}

int model_initialize(Model *m, char *err, size_t errlen)
{
    const Params *p = &m->p;
    m->eval_valid = 0;
    if (check_params(p, err, errlen) != 0) return -1;
    ContactModel *cm = &m->d.contact;
    memset(cm, 0, sizeof *cm);
    cm->kh = p->soil_kh;
    cm->eta = p->soil_eta;
    cm->gamma = p->soil_gamma;
    cm->Kvx = p->soil_Kvx;
    cm->Kvy_ratio = p->soil_KvyRatio;
    cm->cohesion = p->soil_cohesion;
    cm->phi = p->soil_phi;
    cm->radius = p->wheel_radius;
    cm->width = p->wheel_width;
    cm->slip_v_eps = p->contact_slipVelocityEps;
    cm->method = p->contact_method;
    if (contact_model_prepare(cm, err, errlen) != 0) return -1;
    if (prepare_wong_reece(m, err, errlen) != 0) return -1;
    derive(m);

    terrain_free(&m->terrain);
    if (m->terrain_file && m->terrain_file[0]) {
        if (terrain_load(&m->terrain, m->terrain_file, err, errlen) != 0) return -1;
    } else {
        terrain_init_flat(&m->terrain);
    }

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
    evaluate_end_of_step(m);
    return 0;
}

void model_free(Model *m)
{
    terrain_free(&m->terrain);
}
