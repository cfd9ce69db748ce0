/*
 * The soil's force on one rigid wheel (wheel_soil.h): the slip, the
 * normal force and its tilt from the contact law (volumetric, Petersen &
 * McPhee 2013, or Wong-Reece/Ishigami), the slip-vector shear, and the
 * extensions that act at the contact (slip-sinkage, grousers, lug ripple).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "wheel_soil.h"

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
 * For a linearly implicit integrator it also returns slip derivatives of
 * the applied forces (a one-sided difference of 1e-3 in slip, 0 where the
 * WR slip is clamped at +-1) and dFz/d(sinkage) (a difference of 1e-3 of
 * the sinkage, 1 um at least), checked against a 20000-point reference in
 * tests/c/test_wong_reece.c.  The speed dependence of the fading factors
 * b and c is left out of the damping, as that of the volumetric rolling
 * factor is. */
static void wong_reece_contact(const WheelSoil *ws, double sinkage, double slip, double v_long, double omega_r,
                               double shear_factor, int derivatives, WongReeceContact *out)
{
    const WongReeceModel *wm = ws->wong_reece;
    const double R = wm->radius, eps = ws->contact->slip_v_eps;
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

/* ------------------------------------------------------------ the stages */

void wheel_soil_slip(const WheelSoil *ws, const WheelSoilInput *in, WheelSoilContact *c)
{
    const ContactModel *cm = ws->contact;
    c->omega_r = cm->radius * in->spin;
    /* max(|omega R|, |v|, eps), without fmax's library calls (a NaN speed
     * gives a NaN slip either way) */
    const double aw = fabs(c->omega_r), av = fabs(in->v_long), fast = aw >= av ? aw : av;
    c->den = fast >= cm->slip_v_eps ? fast : cm->slip_v_eps;
    c->slip = (c->omega_r - in->v_long) / c->den;
    c->kh_factor = in->kh_factor;
    if (ws->slip_sinkage > 0) {     /* the soil under a slipping wheel yields: it digs in */
        const double s = fmin(fabs(c->slip), 1.0), p = ws->slip_sinkage_power;
        c->kh_factor /= 1.0 + ws->slip_sinkage * (p > 0 && p != 1.0 ? pow(s, p) : s);
    }
    /* Lug thrust that builds up with slip (grouser.thrustSlip > 0): the soil
     * between the lugs shears before their faces bear. */
    const double gain = ws->thrust_slip > 0 ? ws->thrust_gain * (1.0 - exp(-fabs(c->slip) / ws->thrust_slip))
                                            : ws->thrust_gain;
    c->shear_factor = in->strength_factor * (1.0 + gain);
    /* Lug ripple (grouser.lugCount N, grouser.rippleAmplitude a): each lug
     * entering the soil bears on it before the soil between the lugs is
     * sheared, so the traction limit pulses N times per revolution,
     * F_taumax (1 + a cos(N theta + phi)) at the wheel's angle theta.  The
     * lateral limit pulses with it (the same shear surface).  Skipped when
     * off, so that the forces stay bit for bit those without it. */
    if (ws->ripple_amplitude > 0 && ws->lug_count > 0)
        c->shear_factor *= 1.0 + ws->ripple_amplitude * cos(ws->lug_count * in->spin_angle + in->lug_phase);
    /* Grouser lugs (grouser.lugHeight h, volumetric law only): the soil
     * between the lugs turns with the wheel, so the shear surface is the lug
     * tips' circle, h beyond the rim the normal law presses on.  The shear's
     * slip velocity is omega (R + h) - v and its moment about the axle (R + h)
     * F_t: more torque per unit of thrust, and thrust already at omega R = v.
     * Assumption: the pressure (Fn, its tilt, the contact area) stays that of
     * the rim of radius R.  With h = 0, shear_radius is R exactly. */
    c->shear_radius = ws->law == CONTACT_LAW_WONG_REECE ? cm->radius : cm->radius + ws->lug_height;
}

/* Wong-Reece: the normal force and the rest of stage 2 from that law. */
static void normal_wong_reece(const WheelSoil *ws, const WheelSoilInput *in, int derivatives, WheelSoilContact *c)
{
    wong_reece_contact(ws, in->sinkage, c->slip, in->v_long, c->omega_r, c->shear_factor, derivatives, &c->wr);
    c->Fn = c->wr.Fn;
    c->sin_alpha = c->wr.sin_alpha;
    c->cos_alpha = c->wr.cos_alpha;
    c->area = c->wr.area;
    c->support = c->wr.Fz;        /* the lateral law's normal load */
    c->kn = c->wr.kz;
}

/* Volumetric: stage 2 from the contact patch at the wheel's sinkage. */
static void normal_from_patch(const WheelSoil *ws, const ContactMemory *mem, const WheelSoilInput *in,
                              const ContactPatch *patch, WheelSoilContact *c)
{
    c->Fn = c->kh_factor * patch->Fn;
    c->area = patch->area;
    c->support = c->Fn;
    /* Normal stiffness dFn/dz at fixed cuts, from contact_patch. */
    c->kn = c->kh_factor * patch->dFn_dz;
    /* The tilt alpha times the rolling factor; the usual factors +-1 and 0
     * need no trigonometry. */
    const double roll = contact_rolling_factor(ws->contact, mem, in->v_long);
    double sa = patch->sin_alpha, ca = patch->cos_alpha;
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
    c->sin_alpha = sa;
    c->cos_alpha = ca;
}

void wheel_soil_normal(const WheelSoil *ws, const ContactMemory *mem, const WheelSoilInput *in,
                       int derivatives, WheelSoilContact *c)
{
    c->wong_reece = ws->law == CONTACT_LAW_WONG_REECE;
    if (c->wong_reece) {
        normal_wong_reece(ws, in, derivatives, c);
        return;
    }
    double cut_front, cut_rear;
    contact_cuts(ws->contact, mem, in->sinkage, &cut_front, &cut_rear);
    ContactPatch patch;
    contact_patch(ws->contact, in->sinkage, cut_front, cut_rear, &patch);
    normal_from_patch(ws, mem, in, &patch, c);
}

void wheel_soil_normals(const WheelSoil *ws, int n, const ContactMemory *mem, const WheelSoilInput *in,
                        int derivatives, WheelSoilContact *c)
{
    if (ws->law == CONTACT_LAW_WONG_REECE) {      /* its integrations are most of its time: one by one */
        for (int k = 0; k < n; ++k) {
            c[k].wong_reece = 1;
            normal_wong_reece(ws, &in[k], derivatives, &c[k]);
        }
        return;
    }
    for (int i = 0; i < n; i += CONTACT_BATCH) {
        const int nb = n - i < CONTACT_BATCH ? n - i : CONTACT_BATCH;
        double sinkage[CONTACT_BATCH], cut_front[CONTACT_BATCH], cut_rear[CONTACT_BATCH];
        for (int k = 0; k < nb; ++k) {
            sinkage[k] = in[i + k].sinkage;
            contact_cuts(ws->contact, &mem[i + k], sinkage[k], &cut_front[k], &cut_rear[k]);
        }
        ContactPatch patch[CONTACT_BATCH];
        contact_patches(ws->contact, nb, sinkage, cut_front, cut_rear, patch);
        for (int k = 0; k < nb; ++k) {
            c[i + k].wong_reece = 0;
            normal_from_patch(ws, &mem[i + k], &in[i + k], &patch[k], &c[i + k]);
        }
    }
}

/* The shear law's forces as the contact law applies them: scaled by the
 * shear factor, and with Wong-Reece its own traction. */
static void shear_as_applied(const WheelSoilContact *c, double *F_long, double *F_lat, double *jac)
{
    if (c->shear_factor != 1.0) {       /* soil patch strength, grouser thrust: F_taumax scales */
        *F_long *= c->shear_factor;
        *F_lat *= c->shear_factor;
        if (jac)
            for (int i = 0; i < 6; ++i) jac[i] *= c->shear_factor;
    }
    if (c->wong_reece) {
        /* Assumption: Wong-Reece has no lateral force; the lateral one is
         * the volumetric slip-vector law's (combined slip, soil.Kvx,
         * soil.KvyRatio) with F_taumax from WR's normal load and contact
         * area.  The traction along the heading is WR's (its slip
         * derivatives are c->wr.dF*_ds, so the law's own longitudinal
         * Jacobian row goes). */
        *F_long = c->wr.F_long;
        if (jac) jac[0] = jac[1] = jac[2] = 0.0;
    }
}

void wheel_soil_shear(const WheelSoil *ws, const WheelSoilContact *c, const WheelSoilInput *in, double v_lat,
                      double *F_long, double *F_lat, double *jac)
{
    const double omega_shear = c->shear_radius * in->spin;
    contact_shear(ws->contact, c->support, c->area, in->v_long, v_lat, omega_shear, F_long, F_lat, jac);
    shear_as_applied(c, F_long, F_lat, jac);
}

void wheel_soil_shears(const WheelSoil *ws, int n, const WheelSoilContact *c, const WheelSoilInput *in,
                       const double *v_lat, int jacobians, ShearForce *out)
{
    for (int i = 0; i < n; i += CONTACT_BATCH) {
        const int nb = n - i < CONTACT_BATCH ? n - i : CONTACT_BATCH;
        ShearInput sh[CONTACT_BATCH];
        for (int k = 0; k < nb; ++k) {
            const WheelSoilContact *ck = &c[i + k];
            sh[k] = (ShearInput){ck->support, ck->area, in[i + k].v_long, v_lat[i + k],
                                 ck->shear_radius * in[i + k].spin};
        }
        contact_shears(ws->contact, nb, sh, out + i, jacobians);
        for (int k = 0; k < nb; ++k)
            shear_as_applied(&c[i + k], &out[i + k].F_long, &out[i + k].F_lat, jacobians ? out[i + k].jac : NULL);
    }
}

/* ------------------------------------------------- preparing the laws */

int wheel_soil_prepare_laws(const SoilLaws *s, ContactModel *cm, WongReeceModel *wm, char *err, size_t errlen)
{
    memset(cm, 0, sizeof *cm);
    cm->kh = s->kh;
    cm->eta = s->eta;
    cm->gamma = s->gamma;
    cm->Kvx = s->Kvx;
    cm->Kvy_ratio = s->Kvy_ratio;
    cm->cohesion = s->cohesion;
    cm->phi = s->phi;
    cm->radius = s->radius;
    cm->width = s->width;
    cm->slip_v_eps = s->slip_v_eps;
    cm->method = s->method;
    if (contact_model_prepare(cm, err, errlen) != 0) return -1;
    if (s->law != CONTACT_LAW_VOLUMETRIC && s->law != CONTACT_LAW_WONG_REECE)
        return snprintf(err, errlen, "contact.model = %d must be 0 (volumetric) or 1 (Wong-Reece)", s->law), -1;
    /* the rebound lambda is soil.gamma; cohesion, phi and the wheel are the volumetric law's,
     * checked above */
    memset(wm, 0, sizeof *wm);
    wm->n = s->wr_n;
    wm->kc = s->wr_kc;
    wm->kphi = s->wr_kphi;
    wm->cohesion = s->cohesion;
    wm->phi = s->phi;
    wm->K = s->wr_K;
    wm->a0 = s->wr_a0;
    wm->a1 = s->wr_a1;
    wm->lambda = s->gamma;
    wm->radius = s->radius;
    wm->width = s->width;
    wm->points = s->wr_points;
    return wong_reece_prepare(wm, err, errlen);
}
