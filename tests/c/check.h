/* The small test harness shared by the C unit tests: CHECK prints PASS or
 * FAIL with a message, and every test program ends with the line
 * "N passed, M failed" and a non-zero exit status on failure. */
#ifndef JUNO_TEST_CHECK_H
#define JUNO_TEST_CHECK_H

#include <math.h>
#include <stdio.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static int n_pass = 0, n_fail = 0;

#define CHECK(cond, ...)                                        \
    do {                                                        \
        if (cond) {                                             \
            ++n_pass;                                           \
            printf("PASS  ");                                   \
        } else {                                                \
            ++n_fail;                                           \
            printf("FAIL  ");                                   \
        }                                                       \
        printf(__VA_ARGS__);                                    \
        printf("\n");                                           \
    } while (0)

/* The Juno wheel and its static load: a quarter of 317.7 kg * 9.81. */
static const double R_WHEEL = 0.2794, B_WHEEL = 0.254;
static const double LOAD = 779.0; /* N */

#endif
