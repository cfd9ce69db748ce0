/*
 * One wheel's contact with the soil (rover_internal.h): the contact frame
 * on the terrain, the slip, the normal force and its tilt from the contact
 * law (volumetric, Petersen & McPhee 2013, or Wong-Reece/Ishigami), the
 * shear, and their generalised force, damping and stiffness for the
 * linearly implicit integrator.  The model extensions that act at the
 * contact live here too: the soil patch, the multi-pass rut, slip-sinkage,
 * grousers and the terrain registration offsets.
 */
#include <math.h>
#include <string.h>

#include "rover_internal.h"

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
double rover_terrain_at(const Model *m, double x, double y, double n[3])
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

/* ---------------------------------------------------- one wheel's contact */

/* Where wheel w meets the soil.  Assumption: the soil is locally a plane
 * through the terrain point below the hub; the contact is solved in the
 * wheel's mid-plane. */
typedef struct {
    double n[3];                   /* terrain normal under the hub */
    double np[3];                  /* n within the wheel's mid-plane, unit */
    double in_plane;               /* length of n within the mid-plane before normalising */
    double f[3];                   /* heading in the contact plane */
    double l[3];                   /* lateral direction, n x f */
    double kh_factor, strength_factor;   /* soil patch, multi-pass, slip-sinkage */
    double spin, omega_r, den;     /* wheel spin about its axle (rad/s), omega R, slip denominator (m/s) */
    double shear_factor;           /* F_taumax scaling: patch strength and grouser thrust */
} ContactFrame;

/* The contact frame, the sinkage (with a rear wheel's rut) and the forward
 * speed into wc.  Returns 1 if the wheel is in the soil, 0 if not (then
 * the slip, forces and the rest of wc stay 0). */
static int contact_frame(const Model *m, const Eval *ev, int w, double Jh[3][NU], int sp, WheelContact *wc,
                         ContactFrame *cf)
{
    const Params *p = &m->p;
    const double R = m->d.contact.radius;
    const double *H = ev->hub[w];
    const double zt = rover_terrain_at(m, H[0], H[1], cf->n);
    const double hub_height = (H[2] - zt) * cf->n[2];
    v3_copy(cf->np, cf->n);
    v3_axpy(cf->np, -v3_dot(cf->n, ev->e), ev->e);
    cf->in_plane = v3_norm(cf->np);
    if (cf->in_plane < 1e-6) return 0;                 /* wheel lying on its side */
    v3_scale(cf->np, cf->np, 1.0 / cf->in_plane);
    double sinkage = R - hub_height / cf->in_plane;
    soil_factors(p, H[0], H[1], &cf->kh_factor, &cf->strength_factor);
    if (w % 2 == 1 && p->multipass_rutFraction > 0) {
        /* A rear wheel rolls in its front wheel's rut, on compacted soil. */
        const double rut = p->multipass_rutFraction *
                           rut_depth_at(&m->s, side_of(w), m->s.path[side_of(w)] - p->rover_wheelbase);
        sinkage -= rut;
        cf->kh_factor *= 1.0 + (p->multipass_khFactor - 1.0) * rut / (rut + 0.002);
    }
    wc->sinkage = sinkage;
    v3_cross(cf->f, ev->e, cf->np);
    v3_cross(cf->l, cf->n, cf->f);
    v3_normalize(cf->l);
    double vh[3] = {0, 0, 0};
    for (int i = 0; i < 3; ++i) vh[i] = point_row_dot(Jh, i, m->s.u, sp);
    wc->v_long = v3_dot(cf->f, vh);
    return !(sinkage <= 0);               /* a NaN sinkage goes on, to be caught as a diverged state */
}

/* The slip of a wheel in the soil, and the soil factors that depend on it. */
static void contact_slip(const Model *m, const Eval *ev, double Jw[3][NU], int sp, WheelContact *wc,
                         ContactFrame *cf)
{
    const Params *p = &m->p;
    const ContactModel *cm = &m->d.contact;
    double wheel_omega[3];
    for (int i = 0; i < 3; ++i) wheel_omega[i] = angular_row_dot(Jw, i, m->s.u, sp);
    cf->spin = v3_dot(wheel_omega, ev->e);
    cf->omega_r = cm->radius * cf->spin;
    cf->den = fmax(fmax(fabs(cf->omega_r), fabs(wc->v_long)), cm->slip_v_eps);
    wc->slip = (cf->omega_r - wc->v_long) / cf->den;
    if (p->slipSinkage_coefficient > 0)       /* the soil under a slipping wheel yields: it digs in */
        cf->kh_factor /= 1.0 + p->slipSinkage_coefficient * fmin(fabs(wc->slip), 1.0);
    cf->shear_factor = cf->strength_factor * (1.0 + p->grouser_thrustGain);
}

/* The normal force Fn, its tilt alpha (Eqns 6-9), the contact area and
 * the normal stiffness, from the contact law. */
typedef struct {
    int wong_reece;                /* contact.model = 1 */
    WongReeceContact wr;           /* that law's result (wong_reece only) */
    double Fn, sa, ca;             /* N; sin and cos of the tilt as applied */
    double area;                   /* m^2 */
    double support;                /* normal load of the shear law, N */
    double kn;                     /* normal stiffness, N/m */
} NormalForce;

static void normal_force(const Model *m, int w, const WheelContact *wc, const ContactFrame *cf, int matrices,
                         NormalForce *nf)
{
    const ContactModel *cm = &m->d.contact;
    memset(nf, 0, sizeof *nf);
    nf->wong_reece = m->p.contact_model == CONTACT_LAW_WONG_REECE;
    if (nf->wong_reece) {
        wong_reece_contact(m, wc->sinkage, wc->slip, wc->v_long, cf->omega_r, cf->shear_factor, matrices, &nf->wr);
        nf->Fn = nf->wr.Fn;
        nf->sa = nf->wr.sin_alpha;
        nf->ca = nf->wr.cos_alpha;
        nf->area = nf->wr.area;
        nf->support = nf->wr.Fz;        /* the lateral law's normal load */
        nf->kn = nf->wr.kz;
        return;
    }
    double cut_front, cut_rear;
    contact_cuts(cm, &m->s.memory[w], wc->sinkage, &cut_front, &cut_rear);
    ContactPatch patch;
    contact_patch(cm, wc->sinkage, cut_front, cut_rear, &patch);
    nf->Fn = cf->kh_factor * patch.Fn;
    nf->area = patch.area;
    nf->support = nf->Fn;
    /* Normal stiffness dFn/dz at fixed cuts, from contact_patch. */
    nf->kn = cf->kh_factor * patch.dFn_dz;
    /* The tilt alpha times the rolling factor; the usual factors +-1 and 0
     * need no trigonometry. */
    const double roll = contact_rolling_factor(cm, &m->s.memory[w], wc->v_long);
    double sa = patch.sin_alpha, ca = patch.cos_alpha;
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
    nf->sa = sa;
    nf->ca = ca;
}

/* The directions of the contact force and the rim point the shear acts
 * on.  Grouser lugs (grouser.lugHeight h, volumetric law only): the soil
 * between the lugs turns with the wheel, so the shear surface is the lug
 * tips' circle, h beyond the rim the normal law presses on.  The shear's
 * slip velocity is omega (R + h) - v and its moment about the axle (R + h)
 * F_t: more torque per unit of thrust, and thrust already at omega R = v.
 * Assumption: the pressure (Fn, its tilt, the contact area) stays that of
 * the rim of radius R.  With h = 0, shear_radius is R exactly. */
typedef struct {
    double shear_radius;           /* m */
    double nvec[3];                /* Eqn 6: from the centroid towards the hub */
    double t[3];                   /* tangential direction of Eqns 8-9 */
    double Jp[3][NU];              /* velocity Jacobian of the rim (or lug tip) point on the centroid ray */
    double jac[6];                 /* d(F_long, F_lat) / d(v_long, v_lat, omega R) */
} ShearGeometry;

/* The shear forces and the wheel's total force into wc. */
static void contact_forces(const Model *m, double Jh[3][NU], double Jw[3][NU], int sp,
                           const ContactFrame *cf, const NormalForce *nf, int matrices, WheelContact *wc,
                           ShearGeometry *sg)
{
    const ContactModel *cm = &m->d.contact;
    const double R = cm->radius, sa = nf->sa, ca = nf->ca;
    sg->shear_radius = nf->wong_reece ? R : R + m->p.grouser_lugHeight;
    const double omega_shear = sg->shear_radius * cf->spin;
    double r_rim[3];
    for (int i = 0; i < 3; ++i) {
        sg->nvec[i] = -sa * cf->f[i] + ca * cf->np[i];
        sg->t[i] = ca * cf->f[i] + sa * cf->np[i];
        r_rim[i] = -sg->shear_radius * sg->nvec[i];
    }
    /* The shear acts on the rim where the centroid ray meets it, so its
     * moment about the axle is exactly -R F_t (-(R + h) F_t with lugs) and
     * the normal force passes through the hub. */
    memcpy(sg->Jp, Jh, sizeof sg->Jp);
    add_wheel_offset(sg->Jp, Jw, r_rim, sp);
    double v_rim[3];
    for (int i = 0; i < 3; ++i) v_rim[i] = point_row_dot(sg->Jp, i, m->s.u, sp);
    const double v_lat = v3_dot(cf->l, v_rim);
    double F_long, F_lat;
    double *jac = sg->jac;
    contact_shear(cm, nf->support, nf->area, wc->v_long, v_lat, omega_shear, &F_long, &F_lat,
                  matrices ? jac : NULL);
    if (cf->shear_factor != 1.0) {       /* soil patch strength, grouser thrust: F_taumax scales */
        F_long *= cf->shear_factor;
        F_lat *= cf->shear_factor;
        if (matrices)
            for (int i = 0; i < 6; ++i) jac[i] *= cf->shear_factor;
    }
    if (nf->wong_reece) {
        /* Assumption: Wong-Reece has no lateral force; the lateral one is
         * the volumetric slip-vector law's (combined slip, soil.Kvx,
         * soil.KvyRatio) with F_taumax from WR's normal load and contact
         * area.  The traction along the heading is WR's (its damping is
         * added in contact_matrices, so the law's own longitudinal
         * Jacobian row goes). */
        F_long = nf->wr.F_long;
        if (matrices) jac[0] = jac[1] = jac[2] = 0.0;
    }
    wc->Fn = nf->Fn;
    wc->F_long = F_long;
    wc->F_lat = F_lat;
    wc->sin_alpha = sa;
    wc->cos_alpha = ca;
    for (int i = 0; i < 3; ++i) wc->force[i] = nf->Fn * sg->nvec[i] + F_long * sg->t[i] + F_lat * cf->l[i];
}

/* The contact's generalised force (Q), damping (D = -dQ/du of the shear)
 * and stiffness (K = -dQ/dq of the normal force). */
static void contact_matrices(const Model *m, Eval *ev, double Jh[3][NU], double Jw[3][NU], int sp,
                             const ContactFrame *cf, const NormalForce *nf, ShearGeometry *sg,
                             const WheelContact *wc)
{
    const ContactModel *cm = &m->d.contact;
    const double *jac = sg->jac;
    point_add_generalised(ev->Q, sg->Jp, wc->force, sp);
    /* Damping: through v_long, v_lat and omega R. */
    double g_long[NU], g_lat[NU], g_spin[NU], a_t[NU], e_row[NU];
    point_vec_times_jac(g_long, cf->f, Jh, sp);
    point_vec_times_jac(g_lat, cf->l, sg->Jp, sp);
    angular_vec_times_jac(e_row, ev->e, Jw, sp);
    for (int k = 0; k < NU; ++k) g_spin[k] = sg->shear_radius * e_row[k];
    point_vec_times_jac(a_t, sg->t, sg->Jp, sp);
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
     * per second along it, so the step's end-of-step force would be short
     * by h kn v sin(alpha), a bias of first order in h even in steady
     * rolling (measured with the symmetric K, PID at 2 rad/s, 300 N
     * drawbar: the front normal loads 6.9 % low at solver.step 20 ms, 0.37 %
     * at 1 ms; with this K the same to 6 digits at every step). */
    double a_s[NU];
    point_vec_times_jac(a_s, cf->n, Jh, sp);
    for (int k = 0; k < NU; ++k) a_s[k] /= cf->in_plane;
    double a_n[NU];
    if (nf->wong_reece) {
        /* Slip damping of WR's in-plane forces: Q = Jh^T (Fx f + Fz np) -
         * T e^T Jw depends on u through the slip s = (omega R - v) / den. */
        double a_z[NU], dQ_ds[NU], ds_du[NU];
        point_vec_times_jac(a_z, cf->np, Jh, sp);
        const double aw = fabs(cf->omega_r), av = fabs(wc->v_long);
        double dden_dv = 0.0, dden_dw = 0.0;
        if (aw >= av && aw >= cm->slip_v_eps) dden_dw = cf->omega_r > 0.0 ? 1.0 : -1.0;
        else if (av >= cm->slip_v_eps) dden_dv = wc->v_long > 0.0 ? 1.0 : -1.0;
        const double ds_dv = (-1.0 - wc->slip * dden_dv) / cf->den, ds_dw = (1.0 - wc->slip * dden_dw) / cf->den;
        for (int k = 0; k < NU; ++k) {
            dQ_ds[k] = g_long[k] * nf->wr.dFx_ds + a_z[k] * nf->wr.dFz_ds - g_spin[k] * nf->wr.dFt_ds;
            ds_du[k] = ds_dv * g_long[k] + ds_dw * g_spin[k];
        }
        add_outer(ev->D, dQ_ds, -1.0, ds_du);
        /* Normal stiffness: dFz along the soil normal per unit of sinkage. */
        add_outer(ev->K, a_z, nf->kn, a_s);
        return;
    }
    point_vec_times_jac(a_n, sg->nvec, Jh, sp);
    add_outer(ev->K, a_n, nf->kn, a_s);
}

void rover_wheel_contact(const Model *m, Eval *ev, int w, int matrices)
{
    double (*Jh)[NU] = ev->Jv[BODY_WHEEL0 + w];   /* the hub's velocity Jacobian (the wheel's CG) */
    double (*Jw)[NU] = ev->Jw[BODY_WHEEL0 + w];   /* the wheel's angular velocity Jacobian */
    const int sp = U_SPIN_L + side_of(w);         /* this wheel's spin column */
    WheelContact *wc = &ev->wheel[w];
    memset(wc, 0, sizeof *wc);
    wc->cos_alpha = 1.0;

    ContactFrame cf;
    if (!contact_frame(m, ev, w, Jh, sp, wc, &cf)) return;
    wc->in_contact = 1;
    contact_slip(m, ev, Jw, sp, wc, &cf);
    NormalForce nf;
    normal_force(m, w, wc, &cf, matrices, &nf);
    ShearGeometry sg;
    contact_forces(m, Jh, Jw, sp, &cf, &nf, matrices, wc, &sg);
    if (matrices) contact_matrices(m, ev, Jh, Jw, sp, &cf, &nf, &sg, wc);
}
