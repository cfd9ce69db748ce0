/*
 * Specification tests of the single-wheel test rig model (fmu_src/wheel_rig.c),
 * through the hooks the FMI layer calls (model_hooks.h):
 *   - static equilibrium: at initialisation the soil carries rig.load exactly,
 *     and after the wheel has rolled into its steady rut the mean vertical
 *     force is rig.load again (the hub is free vertically under the load);
 *   - a free-rolling wheel (no driving torque) meets rolling resistance: its
 *     drawbar pull is negative; for the volumetric law that is slip 0, for
 *     Wong-Reece the towed slip where the torque crosses 0;
 *   - the drawbar pull rises with slip and saturates (concave: it gains less
 *     per unit of slip at high slip than at low), and the torque has the
 *     sign of the slip (positive driving, negative braking);
 *   - a slip angle brings a lateral force against the lateral sliding, and
 *     none without it;
 *   - the spin-set mode at the spin the slip-set mode computes gives the
 *     same forces;
 *   - the volumetric and the Wong-Reece laws both run, and a soil too soft
 *     for the load is refused at initialisation, naming rig.load;
 *   - an FMU state (ModelState) restored continues exactly as the original.
 * Standalone: one line per check and "N passed, M failed"; nonzero exit on
 * failure.  Every run is a few seconds of simulated time at the default
 * solver step (milliseconds of CPU each).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "wheel_rig.h"

/* Steady outputs of a run: means over the last `average` s of `duration` s. */
typedef struct {
    double drawbar, vertical, torque, lateral, sinkage, slip, omega;
    int ok;
} Steady;

static Model *new_rig(int law)
{
    Model *m = (Model *)calloc(1, sizeof *m);
    if (!m) exit(2);
    model_reset(m);
    m->p.contact_model = law;
    return m;
}

static int initialize(Model *m)
{
    char err[512];
    if (model_initialize(m, err, sizeof err) != 0) {
        printf("      model_initialize: %s\n", err);
        return -1;
    }
    return 0;
}

/* Runs m (initialised) for duration s in steps of 0.05 s and averages the
 * outputs over the last `average` s. */
static Steady run(Model *m, double duration, double average)
{
    Steady st;
    memset(&st, 0, sizeof st);
    const double h = 0.05;
    const int n = (int)lround(duration / h), n_avg = (int)lround(average / h);
    char err[512];
    for (int k = 0; k < n; ++k) {
        if (model_do_step(m, h, err, sizeof err) != 0) {
            printf("      model_do_step: %s\n", err);
            return st;
        }
        if (k >= n - n_avg) {
            st.drawbar += m->out.drawbarPull / n_avg;
            st.vertical += m->out.verticalForce / n_avg;
            st.torque += m->out.torque / n_avg;
            st.lateral += m->out.lateralForce / n_avg;
            st.sinkage += m->out.sinkage / n_avg;
            st.slip += m->out.slipActual / n_avg;
            st.omega += m->out.omegaActual / n_avg;
        }
    }
    st.ok = 1;
    return st;
}

/* Steady state at slip s (slip set) with the law and slip angle given:
 * 8 s at 5 cm/s (0.4 m, several contact lengths), the last 2 s averaged. */
static Steady at_slip(int law, double slip, double slip_angle)
{
    Model *m = new_rig(law);
    m->in.slip = slip;
    m->in.slipAngle = slip_angle;
    Steady st;
    memset(&st, 0, sizeof st);
    if (initialize(m) == 0) st = run(m, 8.0, 2.0);
    free(m);
    return st;
}

static const char *const LAW_NAME[2] = {"volumetric", "Wong-Reece"};

static void test_static_equilibrium(int law)
{
    Model *m = new_rig(law);
    m->in.vx = 0.0;                       /* standing: the initial outputs are those at rest */
    const int ok = initialize(m) == 0;
    CHECK(ok && fabs(m->out.verticalForce - m->p.rig_load) <= 1e-9 * m->p.rig_load && m->out.sinkage > 0,
          "%s: at initialisation the soil carries rig.load = %g N: vertical force %.12g N, sinkage %.2f mm",
          LAW_NAME[law], m->p.rig_load, m->out.verticalForce, 1e3 * m->out.sinkage);
    free(m);

    const Steady st = at_slip(law, 0.2, 0.0);
    CHECK(st.ok && fabs(st.vertical - 779.0) < 0.005 * 779.0,
          "%s: rolling steadily at slip 0.2 the mean vertical force is rig.load: %.3f N (779 N, 0.5 %%)",
          LAW_NAME[law], st.vertical);
}

/* Volumetric: slip 0 is free rolling (the shear vanishes with the slip). */
static void test_rolling_resistance_volumetric(void)
{
    const Steady st = at_slip(CONTACT_LAW_VOLUMETRIC, 0.0, 0.0);
    CHECK(st.ok && fabs(st.torque) < 1e-9 && st.drawbar < -0.05 * 779.0,
          "volumetric: a free-rolling wheel (slip 0, torque %.3g N m) meets rolling resistance: drawbar %.1f N < -5 %% "
          "of the load", st.torque, st.drawbar);
}

/* Wong-Reece: the towed wheel (torque 0) runs at a braking slip. */
static void test_rolling_resistance_wong_reece(void)
{
    const double s0 = -0.2, s1 = 0.0;
    const Steady a = at_slip(CONTACT_LAW_WONG_REECE, s0, 0.0), b = at_slip(CONTACT_LAW_WONG_REECE, s1, 0.0);
    const int bracket = a.ok && b.ok && a.torque < 0 && b.torque > 0;
    const double f = bracket ? a.torque / (a.torque - b.torque) : NAN;
    const double towed = a.drawbar + f * (b.drawbar - a.drawbar);
    CHECK(bracket && towed < 0,
          "Wong-Reece: the towed wheel (torque 0 between slip %g and %g, at about %.3f) meets rolling resistance: "
          "drawbar %.1f N < 0", s0, s1, s0 + f * (s1 - s0), towed);
}

static void test_drawbar_curve(int law)
{
    const double slips[] = {-0.2, 0.0, 0.1, 0.2, 0.4, 0.6, 0.8};
    enum { N = sizeof slips / sizeof slips[0] };
    Steady st[N];
    int ok = 1;
    for (int i = 0; i < N; ++i) {
        st[i] = at_slip(law, slips[i], 0.0);
        ok = ok && st[i].ok;
    }
    int rising = ok;
    for (int i = 1; i < 5 && ok; ++i) rising = rising && st[i].drawbar > st[i - 1].drawbar;
    CHECK(rising, "%s: the drawbar pull rises with slip up to 0.4: %.1f %.1f %.1f %.1f %.1f N at slip -0.2 0 0.1 0.2 0.4",
          LAW_NAME[law], st[0].drawbar, st[1].drawbar, st[2].drawbar, st[3].drawbar, st[4].drawbar);
    const double low = (st[3].drawbar - st[1].drawbar) / 0.2, high = (st[6].drawbar - st[5].drawbar) / 0.2;
    CHECK(ok && high < 0.6 * low,
          "%s: and saturates: %.0f N per unit slip over 0.6-0.8 against %.0f over 0-0.2", LAW_NAME[law], high, low);
    int torque_sign = ok && st[0].torque < 0;
    for (int i = 2; i < N && ok; ++i) torque_sign = torque_sign && st[i].torque > 0;
    CHECK(torque_sign, "%s: the torque is positive when driving (slip 0.1: %.1f N m, 0.8: %.1f N m), negative braking "
          "(slip -0.2: %.1f N m)", LAW_NAME[law], st[2].torque, st[6].torque, st[0].torque);
    int slip_held = ok;
    for (int i = 0; i < N && ok; ++i) slip_held = slip_held && fabs(st[i].slip - slips[i]) < 1e-12;
    CHECK(slip_held, "%s: the slip the law sees is the slip set (rig.vx = contact.slipVelocityEps)", LAW_NAME[law]);
}

static void test_lateral_force(int law)
{
    const Steady straight = at_slip(law, 0.2, 0.0), left = at_slip(law, 0.2, 0.1), right = at_slip(law, 0.2, -0.1);
    CHECK(straight.ok && straight.lateral == 0.0, "%s: no lateral force without a slip angle (%.3g N)", LAW_NAME[law],
          straight.lateral);
    CHECK(left.ok && right.ok && left.lateral > 0.02 * 779.0 && fabs(left.lateral + right.lateral) < 1e-6 * left.lateral,
          "%s: a slip angle of +-0.1 rad brings a lateral force to the wheel's left and right, against its sliding: "
          "%.2f N, %.2f N", LAW_NAME[law], left.lateral, right.lateral);
}

/* The spin the slip-set mode computes, set in the spin-set mode, gives the same forces. */
static void test_spin_set_mode(void)
{
    Model *a = new_rig(CONTACT_LAW_VOLUMETRIC), *b = new_rig(CONTACT_LAW_VOLUMETRIC);
    a->in.slip = 0.3;
    b->p.rig_driveMode = RIG_SPIN_SET;
    b->in.omega = a->in.vx / ((1.0 - 0.3) * a->p.wheel_radius);
    const int ok = initialize(a) == 0 && initialize(b) == 0;
    const Steady sa = ok ? run(a, 4.0, 1.0) : (Steady){0}, sb = ok ? run(b, 4.0, 1.0) : (Steady){0};
    CHECK(sa.ok && sb.ok && fabs(sa.drawbar - sb.drawbar) < 1e-6 * fabs(sa.drawbar) &&
              fabs(sa.torque - sb.torque) < 1e-6 * fabs(sa.torque) && fabs(sb.slip - 0.3) < 1e-9,
          "spin set at omega = v / ((1 - 0.3) R) = slip set at 0.3: drawbar %.6f / %.6f N, torque %.6f / %.6f N m, "
          "slip %.9f", sa.drawbar, sb.drawbar, sa.torque, sb.torque, sb.slip);
    free(a);
    free(b);
}

static void test_soil_too_soft(void)
{
    Model *m = new_rig(CONTACT_LAW_VOLUMETRIC);
    m->p.soil_kh = 1e-3;
    char err[512] = "";
    const int rc = model_initialize(m, err, sizeof err);
    CHECK(rc != 0 && strstr(err, "rig.load") != NULL && strstr(err, "too soft") != NULL,
          "a soil too soft for the load is refused at initialisation, naming rig.load: \"%s\"", err);
    free(m);
}

static void test_bad_parameters(void)
{
    Model *m = new_rig(CONTACT_LAW_VOLUMETRIC);
    m->p.rig_driveMode = 2;
    char err[512] = "";
    const int rc = model_initialize(m, err, sizeof err);
    CHECK(rc != 0 && strstr(err, "rig.driveMode") != NULL, "rig.driveMode = 2 is refused, named: \"%s\"", err);
    free(m);
}

/* A state taken mid-run and restored into a second model continues exactly. */
static void test_state_round_trip(void)
{
    Model *a = new_rig(CONTACT_LAW_VOLUMETRIC), *b = new_rig(CONTACT_LAW_VOLUMETRIC);
    char err[512];
    int ok = initialize(a) == 0 && initialize(b) == 0;
    for (int k = 0; k < 20 && ok; ++k) ok = model_do_step(a, 0.05, err, sizeof err) == 0;
    ModelState st;
    model_get_state(a, &st);
    model_set_state(b, &st);
    for (int k = 0; k < 20 && ok; ++k)
        ok = model_do_step(a, 0.05, err, sizeof err) == 0 && model_do_step(b, 0.05, err, sizeof err) == 0;
    CHECK(ok && memcmp(&a->s, &b->s, sizeof a->s) == 0 && memcmp(&a->out, &b->out, sizeof a->out) == 0,
          "a restored state continues bit for bit as the original (1 s on)");
    free(a);
    free(b);
}

int main(void)
{
    for (int law = 0; law < 2; ++law) {
        test_static_equilibrium(law);
        test_drawbar_curve(law);
        test_lateral_force(law);
    }
    test_rolling_resistance_volumetric();
    test_rolling_resistance_wong_reece();
    test_spin_set_mode();
    test_soil_too_soft();
    test_bad_parameters();
    test_state_round_trip();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail ? 1 : 0;
}
