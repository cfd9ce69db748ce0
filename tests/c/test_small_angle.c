/* The series the step takes for small angles (fmu_src/vec3.h) are as accurate as the library's
 * functions: sin_cos within an ulp of sin x and cos x for |x| <= 1/2 and the library's own
 * values beyond; quat_integrate_world's rotation within a few ulp of the exact one (long
 * double) for half angles on both sides of the series' limit of 1/16. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "check.h"
#include "vec3.h"

static double ulp_error(double got, long double want)
{
    const double w = fabs((double)want);
    const double ulp = w > 0 ? nextafter(w, INFINITY) - w : 0x1p-1074;
    return (double)(fabsl((long double)got - want) / ulp);
}

/* xorshift64*: the same sequence on every machine */
static double random_unit(uint64_t *state)
{
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    return (double)((*state * 0x2545F4914F6CDD1DULL) >> 11) * 0x1p-53;
}

/* exp(w h / 2) q in long double, normalised as the step does */
static void reference_rotation(const double q[4], const double w[3], double h, long double out[4])
{
    const long double n = sqrtl((long double)w[0] * w[0] + (long double)w[1] * w[1] + (long double)w[2] * w[2]);
    const long double t = n * h / 2, s = sinl(t) / n, c = cosl(t);
    const long double d[4] = {c, w[0] * s, w[1] * s, w[2] * s};
    long double r[4] = {d[0] * q[0] - d[1] * q[1] - d[2] * q[2] - d[3] * q[3],
                        d[0] * q[1] + d[1] * q[0] + d[2] * q[3] - d[3] * q[2],
                        d[0] * q[2] - d[1] * q[3] + d[2] * q[0] + d[3] * q[1],
                        d[0] * q[3] + d[1] * q[2] - d[2] * q[1] + d[3] * q[0]};
    const long double norm = sqrtl(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]);
    for (int i = 0; i < 4; ++i) out[i] = r[i] / norm;
}

int main(void)
{
    uint64_t state = 0x2545F4914F6CDD1DULL;
    printf("-- sin_cos against sinl and cosl\n");
    double worst_s = 0, worst_c = 0, at_s = 0, at_c = 0;
    for (int k = 0; k <= 1000000; ++k) {
        const double x = k == 0 ? 0.5 : k == 1 ? -0.5 : k < 100 ? ldexp(1.0, -k) : (2.0 * random_unit(&state) - 1.0) * 0.5;
        double s, c;
        sin_cos(x, &s, &c);
        const double es = ulp_error(s, sinl((long double)x)), ec = ulp_error(c, cosl((long double)x));
        if (es > worst_s) worst_s = es, at_s = x;
        if (ec > worst_c) worst_c = ec, at_c = x;
    }
    CHECK(worst_s <= 1.0, "sin_cos's sine within an ulp for |x| <= 1/2: worst %.3f ulp at %.17g", worst_s, at_s);
    CHECK(worst_c <= 1.0, "sin_cos's cosine within an ulp for |x| <= 1/2: worst %.3f ulp at %.17g", worst_c, at_c);
    int same = 1;
    const double beyond[] = {nextafter(0.5, 1.0), -0.7, 1.2, -3.0, 10.0};
    for (int k = 0; k < 5; ++k) {
        double s, c;
        sin_cos(beyond[k], &s, &c);
        same &= s == sin(beyond[k]) && c == cos(beyond[k]);
    }
    CHECK(same, "sin_cos beyond |x| = 1/2 is the library's sin and cos");
    double s0, c0;
    sin_cos(0.0, &s0, &c0);
    CHECK(s0 == 0.0 && c0 == 1.0, "sin_cos(0) = (0, 1) exactly");

    printf("-- quat_integrate_world against the exact rotation\n");
    double worst_q = 0, at_t = 0;
    for (int k = 0; k < 200000; ++k) {
        double q[4] = {2 * random_unit(&state) - 1, 2 * random_unit(&state) - 1, 2 * random_unit(&state) - 1,
                       2 * random_unit(&state) - 1};
        const double qn = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        for (int i = 0; i < 4; ++i) q[i] /= qn;
        const double w[3] = {2 * random_unit(&state) - 1, 2 * random_unit(&state) - 1, 2 * random_unit(&state) - 1};
        const double wn = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
        /* half angles from 1e-9 to 0.25 (the series to 1/16, the library beyond) */
        const double t = 1e-9 * pow(0.25e9, random_unit(&state)), h = 2 * t / wn;
        long double want[4];
        reference_rotation(q, w, h, want);
        quat_integrate_world(q, w, h);
        for (int i = 0; i < 4; ++i) {
            const double e = (double)(fabsl((long double)q[i] - want[i]) / 0x1p-53L);   /* in ulp of 1 */
            if (e > worst_q) worst_q = e, at_t = t;
        }
    }
    CHECK(worst_q <= 4.0, "quat_integrate_world within 4 ulp of 1 of the exact rotation: worst %.3f at half angle %.3g",
          worst_q, at_t);

    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
