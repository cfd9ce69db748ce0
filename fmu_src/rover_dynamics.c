/*
 * The rover's dynamics (rover_internal.h): the kinematics of its seven
 * parts (chassis, two rockers, four wheels), their mass matrix, gravity, bias and gyroscopic forces (each
 * side's rocker and wheels assembled as one body, rover_side_body), the drive,
 * the rocker differential's friction and the drawbar, and the outputs.
 * The contacts are rover_wheel_contact.c's.
 */
#include <math.h>
#include <string.h>

#include "rover_internal.h"

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

/* One rigid body's kinematics for the assembly.  With r = CG - chassis
 * reference point (world), the CG velocity is
 *   v = u_v + w x r + u_beta cb,
 * and the angular velocity w + u_beta sb e; that is, Jv = [I, -[r]x, cb, 0]
 * and Jw = [0, I, sb e, 0].  The assembly below multiplies these blocks out
 * instead of forming the 3 x 9 matrices (most of their 54 entries are 0 or
 * 1).  The bodies are the chassis and each side's rocker with its two
 * wheels (rover_side_body); the wheels' spin adds its own terms (assemble_bodies). */
typedef struct {
    double mass, r[3], I[9];       /* kg; m; world inertia about the CG, kg m^2 */
    double cb[3];                  /* CG velocity per unit rocker rate, m/rad (0: chassis) */
    double sb;                     /* rocker-rate factor of the angular velocity: sigma, or 0 */
    double spin_rate;              /* about e, relative to the chassis, rad/s */
    int side;                      /* SIDE_LEFT or SIDE_RIGHT for a side's body, -1: chassis */
    double Ie[3], eIe;             /* I e and e.I e (a side's body) */
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
}

/* A side's rocker and its two wheels as one body turning with the rocker:
 * a wheel is a disc about the axle (the rocker frame's y axis), so its
 * mass distribution does not change as it spins, and the three bodies'
 * mass matrix, gravity and bias forces at the rocker's motion are those of
 * one body with their total mass, at their CG, with their inertia about it.
 * Mass (kg), CG (rocker frame, from the pivot, m) and that inertia (rocker
 * frame, kg m^2); the same for both sides.  (rover_internal.h: derived from
 * the parameters once, not each evaluation.) */
void rover_side_body(const Params *p, const Derived *d, double *mass, double cg[3], double I[9])
{
    const double mr = p->rover_rockerMass, mw = p->wheel_mass;
    const double It = d->wheel_inertia_transverse, Is = p->wheel_inertia;
    const double part_mass[3] = {mr, mw, mw};
    const double *part_cg[3] = {d->rocker_cg, d->hub[0], d->hub[1]};
    *mass = mr + 2 * mw;
    for (int i = 0; i < 3; ++i) cg[i] = (mr * part_cg[0][i] + mw * part_cg[1][i] + mw * part_cg[2][i]) / *mass;
    /* the parts' own inertias about their CGs: the rocker's principal axes are the rocker frame's,
     * a wheel's I = It 1 + (Is - It) y y^T; then each part's mass about the common CG */
    for (int k = 0; k < 9; ++k) I[k] = 0;
    for (int i = 0; i < 3; ++i) I[4 * i] = d->rocker_inertia[i] + 2 * (i == 1 ? Is : It);
    for (int n = 0; n < 3; ++n) {
        double r[3];
        v3_sub(r, part_cg[n], cg);
        const double rr = v3_dot(r, r);
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) I[3 * i + j] += part_mass[n] * ((i == j ? rr : 0) - r[i] * r[j]);
    }
}

/* Kinematics: the chassis frame, the rocker frames, pivots, hubs and the
 * wheels' velocity Jacobians. */
static void kinematics(const Model *m, Eval *ev)
{
    const Derived *d = &m->d;
    const State *s = &m->s;
    const double *u = s->u;

    quat_to_m3(ev->R, s->quat);
    v3_set(ev->e, ev->R[1], ev->R[4], ev->R[7]);
    v3_set(ev->heading, ev->R[0], ev->R[3], 0);
    v3_normalize(ev->heading);
    ev->u_beta = u[U_BETA];

    /* Rocker frames R Ry(sigma beta): the y column is the chassis's, one
     * sine and cosine serve both sides (sin is odd); from their series at
     * the rocker angles of practice (|beta| <= 1/2, sin_cos), without the
     * library call of about 100 instructions an evaluation. */
    double cb, sbeta;
    sin_cos(s->beta, &sbeta, &cb);
    for (int k = 0; k < 2; ++k) {
        const double sb = sigma_of(k) * sbeta;
        const double *R = ev->R;
        double *A = ev->rocker_R[k];
        for (int i = 0; i < 3; ++i) {
            A[3 * i + 0] = R[3 * i] * cb - R[3 * i + 2] * sb;
            A[3 * i + 1] = R[3 * i + 1];
            A[3 * i + 2] = R[3 * i] * sb + R[3 * i + 2] * cb;
        }
        m3_mul_v(ev->pivot_r[k], ev->R, d->pivot[k]);
        v3_add(ev->pivot[k], s->pos, ev->pivot_r[k]);
    }
    for (int wh = 0; wh < NUM_WHEELS; ++wh) {
        const int side = side_of(wh);
        double tmp[3];
        m3_mul_v(tmp, ev->rocker_R[side], d->hub[wh % 2]);
        v3_add(ev->hub[wh], ev->pivot[side], tmp);
        /* The hub Jacobians the contacts work with (dense rows). */
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
}

/* A = 0 by a loop of stores (GCC makes memset of this size a rep stos,
 * whose start-up costs more than the stores). */
static void zero_matrix(double A[NU][NU])
{
    for (int i = 0; i < NU; ++i)
        for (int j = 0; j < NU; ++j) A[i][j] = 0.0;
}

/* M and Q of the bodies (ev->M, ev->Q cleared first; ev->D and ev->K
 * cleared for the contacts and inputs to add to). */
static void assemble_bodies(const Model *m, Eval *ev)
{
    const Params *p = &m->p;
    const Derived *d = &m->d;
    const double *u = m->s.u;
    zero_matrix(ev->M);
    memset(ev->Q, 0, sizeof ev->Q);
    zero_matrix(ev->D);
    zero_matrix(ev->K);
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
    add_body(ev, &common, &b, ev->M, ev->Q);
    /* each side's rocker with its wheels (rover_side_body), turning with the rocker */
    const double side_mass = d->side_mass, *side_cg = d->side_cg, *side_I = d->side_I;
    /* principal axes along the rocker frame's (the model's geometry, its parts in the x-z
     * plane, symmetric fore and aft): R diag R^T, the same values with fewer products */
    const int side_diagonal = side_I[1] == 0 && side_I[2] == 0 && side_I[3] == 0 && side_I[5] == 0 &&
                              side_I[6] == 0 && side_I[7] == 0;
    const double side_I_diag[3] = {side_I[0], side_I[4], side_I[8]};
    for (int side = 0; side < 2; ++side) {
        double tmp[3], sv[3];
        b.mass = side_mass;
        m3_mul_v(tmp, ev->rocker_R[side], side_cg);
        v3_add(b.r, ev->pivot_r[side], tmp);
        if (side_diagonal)
            m3_rotate_diag(b.I, ev->rocker_R[side], side_I_diag);
        else
            m3_rotate(b.I, ev->rocker_R[side], side_I);
        b.sb = sigma_of(side);
        b.side = side;
        v3_cross(sv, ev->e, tmp);                 /* e x (CG - pivot) */
        v3_scale(b.cb, sv, b.sb);
        b.spin_rate = b.sb * u[U_BETA];
        m3_mul_v(b.Ie, b.I, ev->e);
        b.eIe = v3_dot(ev->e, b.Ie);
        add_body(ev, &common, &b, ev->M, ev->Q);
    }
    /* The wheels' spin u_s relative to the rocker, about e: the spin columns
     * of M (a disc's I e = Is e) and the gyroscopic torque of the spin,
     * -Is u_s (w x e) per wheel (normal to e: nothing on the rocker and spin
     * rows). */
    const double Is = p->wheel_inertia;
    for (int side = 0; side < 2; ++side) {
        const int sp = U_SPIN_L + side;
        const double wheels = NUM_WHEELS / 2, spin_torque = -wheels * Is * u[sp];
        for (int i = 0; i < 3; ++i) {
            ev->M[U_WX + i][sp] += wheels * Is * ev->e[i];
            ev->Q[U_WX + i] += spin_torque * common.wxe[i];
        }
        ev->M[U_BETA][sp] += wheels * sigma_of(side) * Is;
        ev->M[sp][sp] += wheels * Is;
    }
    for (int i = 0; i < NU; ++i)
        for (int j = 0; j < i; ++j) ev->M[i][j] = ev->M[j][i];
}

void rover_evaluate_geometry(const Model *m, Eval *ev)
{
    kinematics(m, ev);
    rover_terrain_under_wheels(m, (const double (*)[3])ev->hub, ev->ground_z, ev->ground_normal);
}

void rover_evaluate_forces(const Model *m, Eval *ev, int matrices)
{
    if (matrices) assemble_bodies(m, ev);
    rover_wheel_contacts_on_ground(m, ev, matrices);
}

/* From s.pos, quat, beta, u, spin_angle, memory, path, rut, the parameters,
 * derived data and terrain only (what a write outside model_do_step must
 * call model_changed for, rover_step.c). */
void rover_evaluate_passive(const Model *m, Eval *ev, int matrices)
{
    rover_evaluate_geometry(m, ev);
    rover_evaluate_forces(m, ev, matrices);
}

/* ---------------------------------------------------------- drive, drawbar */

double rover_drive_law(const Model *m, int side, double omega, double integral, double *slope)
{
    const Params *p = &m->p;
    if (p->drive_mode == DRIVE_TORQUE) {
        *slope = 0;
        return side == SIDE_LEFT ? m->in.torqueLeft : m->in.torqueRight;
    }
    if (p->drive_mode == DRIVE_PID) {
        const double ref = side == SIDE_LEFT ? m->in.omegaRefLeft : m->in.omegaRefRight;
        *slope = -p->drive_Kp;
        return p->drive_Kp * (ref - omega) + p->drive_Ki * integral;
    }
    /* DC motor at throttle u: T = eff * n * kt * (u V - ke n w) / Ra, ke = kt (SI). */
    const double u = side == SIDE_LEFT ? m->in.throttleLeft : m->in.throttleRight;
    const double n = p->motor_gearRatio, kt = p->motor_kt;
    *slope = -p->motor_efficiency * n * n * kt * kt / p->motor_resistance;
    return p->motor_efficiency * n * kt * (u * p->motor_voltage - kt * n * omega) / p->motor_resistance;
}

double rover_drive_limited(const Model *m, double demand)
{
    if (m->p.drive_mode != DRIVE_TORQUE && fabs(demand) > m->p.drive_torqueMax)
        return copysign(m->p.drive_torqueMax, demand);
    return demand;
}

void rover_drive_torques(const Model *m, double torque[2])
{
    for (int k = 0; k < 2; ++k) {
        double slope;
        torque[k] = rover_drive_limited(m, rover_drive_law(m, k, m->s.u[U_SPIN_L + k], m->s.pid_integral[k], &slope));
    }
}

void rover_drive_at_limit(const Model *m, Eval *ev, int side, double sign)
{
    const Params *p = &m->p;
    const int sp = U_SPIN_L + side;
    const double transmitted = 1.0 - p->drive_lossFraction;
    ev->drive_limit[side] = sign;
    ev->Q[sp] += transmitted * (sign * p->drive_torqueMax - ev->torque_demand[side]);
    ev->D[sp][sp] += transmitted * ev->torque_slope[side];
    if (p->drive_mode == DRIVE_PID) ev->K[sp][sp] -= transmitted * p->drive_Ki;
}

/* The part that depends on the inputs (and s.pid_integral): the drive
 * torques and, if matrices, the drive, rocker damping and drawbar terms
 * added to the Q, D, K of rover_evaluate_passive (once per passive
 * evaluation). */
void rover_evaluate_inputs(const Model *m, Eval *ev, int matrices)
{
    const Params *p = &m->p;
    const double *u = m->s.u;
    double (*D)[NU] = ev->D, (*K)[NU] = ev->K;
    const double *slope = ev->torque_slope;
    for (int k = 0; k < 2; ++k) {
        ev->torque_demand[k] = rover_drive_law(m, k, u[U_SPIN_L + k], m->s.pid_integral[k], &ev->torque_slope[k]);
        ev->torque[k] = rover_drive_limited(m, ev->torque_demand[k]);
        ev->drive_limit[k] = 0;
    }
    if (!matrices) return;

    /* Drive: the motor on each rocker turns its side's wheels relative to it. */
    /* The drive torque is on the motor side (what the current measures);
     * the wheels get (1 - drive.lossFraction) of it.  Its linear law, the
     * unlimited demand and its slope, whatever the limit: the step decides
     * whether it takes the law or the limit (rover_drive_at_limit). */
    const double transmitted = 1.0 - p->drive_lossFraction;
    for (int k = 0; k < 2; ++k) {
        ev->Q[U_SPIN_L + k] += transmitted * ev->torque_demand[k];
        D[U_SPIN_L + k][U_SPIN_L + k] -= transmitted * slope[k];
        /* The PID's integral acts like a torsion spring on the spin angle (I' = ref - omega):
         * treated implicitly as a stiffness, so a stiff PID stays stable at large steps
         * (explicitly, K_i = 2e4 N m/rad went unstable at 5 ms in soft soil). */
        if (p->drive_mode == DRIVE_PID) K[U_SPIN_L + k][U_SPIN_L + k] += transmitted * p->drive_Ki;
        /* Drivetrain friction on the wheel side (drive.frictionLeft/Right: Coulomb,
         * drive.viscousFriction: viscous), opposing the spin relative to the rocker; the
         * measured (motor) torque does not include it.  The Coulomb part is smoothed over
         * 0.05 rad/s (tanh) so that the implicit step sees a finite slope at rest. */
        const double coulomb = k == SIDE_LEFT ? p->drive_frictionLeft : p->drive_frictionRight;
        if (coulomb > 0 || p->drive_viscousFriction > 0) {
            const double w = u[U_SPIN_L + k], th = tanh(w / 0.05);
            ev->Q[U_SPIN_L + k] -= coulomb * th + p->drive_viscousFriction * w;
            D[U_SPIN_L + k][U_SPIN_L + k] += coulomb * (1.0 - th * th) / 0.05 + p->drive_viscousFriction;
        }
    }
    /* Rocker differential friction. */
    ev->Q[U_BETA] -= p->rover_rockerDamping * u[U_BETA];
    D[U_BETA][U_BETA] += p->rover_rockerDamping;
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
void rover_evaluate(const Model *m, Eval *ev, int matrices)
{
    rover_evaluate_passive(m, ev, matrices);
    rover_evaluate_inputs(m, ev, matrices);
}

/* ------------------------------------------------------------ outputs */

/* Outputs from an evaluation of the current state (with its torques). */
void rover_outputs_from(Model *m, const Eval *ev)
{
    Outputs *o = &m->out;
    const double *R = ev->R;
    o->x = m->s.pos[0];
    o->y = m->s.pos[1];
    o->z = m->s.pos[2];
    o->yaw = atan2(R[3], R[0]);
    o->pitch = asin(fmax_of(-1.0, fmin_of(1.0, -R[6])));
    o->roll = atan2(R[7], R[8]);
    o->vx = v3_dot(&m->s.u[U_VX], ev->heading);
    o->omegaLeft = m->s.u[U_SPIN_L];
    o->omegaRight = m->s.u[U_SPIN_R];
    o->torqueLeftApplied = ev->torque[SIDE_LEFT];
    o->torqueRightApplied = ev->torque[SIDE_RIGHT];
    o->rocker = m->s.beta;
    o->spinAngleLeft = m->s.spin_angle[SIDE_LEFT];
    o->spinAngleRight = m->s.spin_angle[SIDE_RIGHT];
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
