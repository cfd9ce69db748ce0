/*
 * Specification tests for the side-by-side entry points of the contact law:
 * contact_patches and contact_shears (contact.c), wheel_soil_normals and
 * wheel_soil_shears (wheel_soil.c).  The rover computes its four wheels
 * through them so that the wheels' chains of library calls overlap in the
 * processor; each must give every wheel exactly what the one-wheel function
 * gives it, bit for bit, whatever the mix of wheels (out of the soil, cut
 * halves, clamped sinkage, standstill, more wheels than one batch).
 *
 * Standalone: prints one line per check and a final "N passed, M failed";
 * exits nonzero if any check failed.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "contact.h"
#include "wheel_soil.h"

/* The same double, bit for bit (NaN and the sign of zero included). */
static int same_bits(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

/* The soil of the rover's defaults, with cohesion so that the shear limit
 * has both terms. */
static SoilLaws soil(int method, int law)
{
    SoilLaws s;
    memset(&s, 0, sizeof s);
    s.kh = 1.58e5;
    s.eta = 0.501;
    s.gamma = 0.0813;
    s.Kvx = 0.819;
    s.Kvy_ratio = 0.7;
    s.cohesion = 800.0;
    s.phi = 0.55;
    s.radius = R_WHEEL;
    s.width = B_WHEEL;
    s.slip_v_eps = 0.01;
    s.method = method;
    s.law = law;
    s.wr_n = 1.1;                      /* Wong-Reece: the FMU's dry sand */
    s.wr_kc = 990.0;
    s.wr_kphi = 1.528e6;
    s.wr_K = 0.010;
    s.wr_a0 = 0.40;
    s.wr_a1 = 0.15;
    s.wr_points = 100;
    return s;
}

/* The laws of soil(method, law) prepared into cm and wm; 0 (a failed check) if they do not. */
static int prepared(int method, int law, ContactModel *cm, WongReeceModel *wm)
{
    const SoilLaws s = soil(method, law);
    char err[256];
    if (wheel_soil_prepare_laws(&s, cm, wm, err, sizeof err) != 0) {
        CHECK(0, "the test's soil prepares: %s", err);
        return 0;
    }
    return 1;
}

/* Eight patches, more than one batch: in the soil, out of it (0, below,
 * NaN), beyond the radius, a half cut to nothing, both halves cut, a
 * sinkage of a nanometre. */
enum { NP = 8 };
static const double SINK[NP] = {0.02, 0.0, -0.01, 0.35, 0.03, 0.04, 1e-9, NAN};
static const double CUT_F[NP] = {0.0, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0};
static const double CUT_R[NP] = {0.0018, 0.0, 0.0, 0.1, 0.0, 0.05, 0.0, 0.0};

static int same_patch(const ContactPatch *a, const ContactPatch *b)
{
    const double x[] = {a->sinkage, a->V, a->Vh, a->area, a->length_front, a->length_rear, a->xc, a->zc,
                        a->Fn, a->dFn_dz, a->sin_alpha, a->cos_alpha};
    const double y[] = {b->sinkage, b->V, b->Vh, b->area, b->length_front, b->length_rear, b->xc, b->zc,
                        b->Fn, b->dFn_dz, b->sin_alpha, b->cos_alpha};
    for (size_t i = 0; i < sizeof x / sizeof x[0]; ++i)
        if (!same_bits(x[i], y[i])) return 0;
    return 1;
}

static void test_patches(void)
{
    for (int method = CONTACT_CLOSED_FORM; method <= CONTACT_QUADRATURE; ++method) {
        ContactModel cm;
        WongReeceModel wm;
        if (!prepared(method, CONTACT_LAW_VOLUMETRIC, &cm, &wm)) return;
        ContactPatch one[NP];
        for (int i = 0; i < NP; ++i) contact_patch(&cm, SINK[i], CUT_F[i], CUT_R[i], &one[i]);
        /* all eight at once, then every count from 1 to 5 from every start */
        ContactPatch many[NP];
        contact_patches(&cm, NP, SINK, CUT_F, CUT_R, many);
        int same = 1;
        for (int i = 0; i < NP; ++i) same &= same_patch(&one[i], &many[i]);
        for (int n = 1; n <= 5; ++n)
            for (int at = 0; at + n <= NP; ++at) {
                contact_patches(&cm, n, SINK + at, CUT_F + at, CUT_R + at, many);
                for (int i = 0; i < n; ++i) same &= same_patch(&one[at + i], &many[i]);
            }
        CHECK(same, "method %d: contact_patches gives each patch contact_patch's values bit for bit (8 patches "
              "in and out of the soil, cut, clamped, NaN; in batches of 1 to 8)", method);
        CHECK(one[0].Fn > 0.0 && one[1].Fn == 0.0 && one[5].length_rear == 0.0,
              "method %d: the cases are what they say (in the soil, out of it, the rear half cut away)", method);
    }
}

/* Six shears: rolling with slip, with lateral slip, at standstill, in
 * reverse, near zero slip (the series branch of tanh), a negative load. */
enum { NS = 6 };
static const ShearInput SHEAR[NS] = {
    {700.0, 0.02, 0.3, 0.0, 0.35}, {650.0, 0.018, 0.25, 0.04, 0.3},   {0.0, 0.0, 0.0, 0.0, 0.0},
    {720.0, 0.021, -0.2, 0.01, -0.1}, {700.0, 0.02, 0.3, 0.0, 0.3001}, {-10.0, 0.0, 0.1, 0.0, 0.2},
};

static void test_shears(void)
{
    ContactModel cm;
    WongReeceModel wm;
    if (!prepared(CONTACT_CLOSED_FORM, CONTACT_LAW_VOLUMETRIC, &cm, &wm)) return;
    int same = 1, same_forces = 1;
    ShearForce many[NS], forces[NS];
    contact_shears(&cm, NS, SHEAR, many, 1);
    contact_shears(&cm, NS, SHEAR, forces, 0);
    for (int i = 0; i < NS; ++i) {
        const ShearInput *in = &SHEAR[i];
        double Fl, Ft, jac[6], Fl0, Ft0;
        contact_shear(&cm, in->Fn, in->area, in->v_long, in->v_lat, in->omega_r, &Fl, &Ft, jac);
        contact_shear(&cm, in->Fn, in->area, in->v_long, in->v_lat, in->omega_r, &Fl0, &Ft0, NULL);
        same &= same_bits(Fl, many[i].F_long) && same_bits(Ft, many[i].F_lat);
        for (int k = 0; k < 6; ++k) same &= same_bits(jac[k], many[i].jac[k]);
        same_forces &= same_bits(Fl0, forces[i].F_long) && same_bits(Ft0, forces[i].F_lat);
    }
    CHECK(same, "contact_shears gives each wheel contact_shear's forces and Jacobian bit for bit (6 wheels: "
          "slip, lateral slip, standstill, reverse, near zero slip, negative load)");
    CHECK(same_forces, "contact_shears without Jacobians: the same forces");
    CHECK(many[0].F_long > 0.0 && many[1].F_lat != 0.0 && many[2].F_long == 0.0 && many[5].F_long == 0.0,
          "the cases are what they say (traction, a lateral force, none at rest, none without a load)");
}

/* Five wheels of a rover (more than one batch) through the three stages of
 * wheel_soil.h, with the extensions that scale the shear on. */
enum { NW = 5 };

static void test_wheel_soil(void)
{
    static const WheelSoilInput IN[NW] = {
        {0.021, 0.30, 1.25, 1.0, 1.0, 0.3, 0.0},  {0.018, 0.28, 1.10, 0.8, 1.2, 1.7, M_PI},
        {0.025, 0.00, 0.00, 1.0, 1.0, 0.0, 0.0},  {0.015, -0.2, -0.9, 1.1, 0.9, 2.2, M_PI},
        {0.030, 0.31, 1.12, 1.0, 1.0, 4.0, 0.0},
    };
    static const ContactMemory MEM[NW] = {{0.022, 0.05}, {0.018, 0.0}, {0.025, 0.0}, {0.02, -0.03}, {0.03, 0.004}};
    static const double V_LAT[NW] = {0.0, 0.03, 0.0, -0.01, 0.002};
    for (int law = CONTACT_LAW_VOLUMETRIC; law <= CONTACT_LAW_WONG_REECE; ++law) {
        ContactModel cm;
        WongReeceModel wm;
        if (!prepared(CONTACT_CLOSED_FORM, law, &cm, &wm)) return;
        const WheelSoil ws = {&cm, &wm, law, 0.3, 0.2, 0.01, 0.7, 0.1, 12.0, 0.05};
        WheelSoilContact one[NW], many[NW];
        double Fl[NW], Ft[NW], jac[NW][6];
        for (int i = 0; i < NW; ++i) {
            wheel_soil_slip(&ws, &IN[i], &one[i]);
            wheel_soil_normal(&ws, &MEM[i], &IN[i], 1, &one[i]);
            wheel_soil_shear(&ws, &one[i], &IN[i], V_LAT[i], &Fl[i], &Ft[i], jac[i]);
            wheel_soil_slip(&ws, &IN[i], &many[i]);
        }
        ShearForce sh[NW];
        wheel_soil_normals(&ws, NW, MEM, IN, 1, many);
        wheel_soil_shears(&ws, NW, many, IN, V_LAT, 1, sh);
        int same = 1;
        for (int i = 0; i < NW; ++i) {
            const WheelSoilContact *a = &one[i], *b = &many[i];
            same &= a->wong_reece == b->wong_reece && same_bits(a->Fn, b->Fn) && same_bits(a->sin_alpha, b->sin_alpha) &&
                    same_bits(a->cos_alpha, b->cos_alpha) && same_bits(a->area, b->area) &&
                    same_bits(a->support, b->support) && same_bits(a->kn, b->kn);
            if (law == CONTACT_LAW_WONG_REECE)
                same &= same_bits(a->wr.Fx, b->wr.Fx) && same_bits(a->wr.Fz, b->wr.Fz) &&
                        same_bits(a->wr.dFx_ds, b->wr.dFx_ds) && same_bits(a->wr.dFz_ds, b->wr.dFz_ds) &&
                        same_bits(a->wr.dFt_ds, b->wr.dFt_ds) && same_bits(a->wr.kz, b->wr.kz);
            same &= same_bits(Fl[i], sh[i].F_long) && same_bits(Ft[i], sh[i].F_lat);
            for (int k = 0; k < 6; ++k) same &= same_bits(jac[i][k], sh[i].jac[k]);
        }
        CHECK(same, "%s law: wheel_soil_normals and wheel_soil_shears give each of 5 wheels what "
              "wheel_soil_normal and wheel_soil_shear give it, bit for bit (shear scaled, lugs, ripple)",
              law == CONTACT_LAW_VOLUMETRIC ? "volumetric" : "Wong-Reece");
        CHECK(one[0].Fn > 0.0 && Fl[0] != 0.0 && Ft[1] != 0.0,
              "%s law: the wheels carry load and traction, and lateral slip gives a lateral force",
              law == CONTACT_LAW_VOLUMETRIC ? "volumetric" : "Wong-Reece");
    }
}

int main(void)
{
    test_patches();
    test_shears();
    test_wheel_soil();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
