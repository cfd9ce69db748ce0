/*
 * The registration tilt (terrain.slopeX, slopeY: a plane through the world
 * origin added to the terrain's heights, the normals turned with it) is the
 * same ground as that plane given as a grid, at any slope: flat ground so
 * tilted and a grid of the plane's heights place the rover alike, give the
 * same contact forces, and move it alike, to round-off.  A grid holds a
 * plane exactly in its bilinear heights and its central-difference normals,
 * so the two differ only in the rounding of the heights and gradients.
 *
 * Slopes up to 1 (45 deg) along x, along y and askew, the rover heading
 * along, across and obliquely to the fall line; 0.3 s of driving at the
 * fixed 1 ms step after the static equilibrium (on the steeper ones the
 * rover slides down, and the forces change quickly: a tilt that differed
 * from the grid in its heights, its normals or the contact's geometry on
 * them would show within that time).
 *
 * Also: the contacts' lookup of the terrain under the four hubs at once
 * (rover_terrain_under_wheels, the registration's checks and its turn's
 * cosine and sine once for the four) is rover_terrain_at at each hub, bit
 * for bit, with and without a registration.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "model.h"
#include "rover_fixture.h"
#include "rover_internal.h"

/* The grid: nodes every CELL m over [-HALF, HALF] m both ways, wide
 * enough that the rover stays on it for the run. */
#define CELL 0.25
#define HALF 4.0
#define RUN_STEPS 30            /* communication steps of 10 ms */

/* Round-off bounds (the differences measured are below a tenth of them;
 * a tilt whose normals were not turned differs by hundreds of N): forces
 * relative to a wheel's share of the rover's weight, lengths and angles. */
#define FORCE_TOL 2e-12         /* x LOAD, N */
#define LENGTH_TOL 1e-13        /* m, rad */

/* Writes the plane z = sx x + sy y as an ESRI ASCII grid into a new
 * temporary file; its path into path. */
static void write_plane_grid(double sx, double sy, char *path, size_t n)
{
    const char *dir = getenv("TMPDIR");
    snprintf(path, n, "%s/juno_tilt_XXXXXX", dir && dir[0] ? dir : "/tmp");
    const int fd = mkstemp(path);
    FILE *f = fd >= 0 ? fdopen(fd, "w") : NULL;
    if (!f) {
        perror(path);
        exit(2);
    }
    const int nodes = (int)lround(2.0 * HALF / CELL) + 1;
    fprintf(f, "ncols %d\nnrows %d\nxllcenter %.17g\nyllcenter %.17g\ncellsize %.17g\n", nodes, nodes, -HALF,
            -HALF, CELL);
    for (int j = nodes - 1; j >= 0; --j) {
        for (int i = 0; i < nodes; ++i) {
            const double x = -HALF + i * CELL, y = -HALF + j * CELL;
            fprintf(f, "%s%.17g", i ? " " : "", sx * x + sy * y);
        }
        fputc('\n', f);
    }
    fclose(f);
}

/* A rover at its defaults heading yaw, at the fixed 1 ms step, on the
 * tilted flat ground (grid NULL) or on the grid file; initialised. */
static Model *new_rover(double sx, double sy, double yaw, const char *grid)
{
    Model *m = rover_at_defaults();
    m->p.init_yaw = yaw;
    m->p.solver_step = 1e-3;
    m->p.solver_tolerance = 0.0;
    if (grid) {
        m->terrain_file = strdup(grid);
        if (!m->terrain_file) exit(2);
    } else {
        m->p.terrain_slopeX = sx;
        m->p.terrain_slopeY = sy;
    }
    return initialised(m, grid ? "the grid" : "the tilt");
}

/* The largest difference of the wheels' forces (N) and of the sinkages
 * and the pose (m, rad) between two rovers' outputs. */
static void differences(const Outputs *a, const Outputs *b, double *force, double *length)
{
    *force = *length = 0.0;
    for (int w = 0; w < NUM_WHEELS; ++w) {
        const WheelOutputs *p = &a->wheel[w], *q = &b->wheel[w];
        const double f[6] = {p->Fn - q->Fn, p->Ft - q->Ft, p->Fx - q->Fx, p->Fy - q->Fy, p->Fz - q->Fz, 0.0};
        for (int k = 0; k < 5; ++k) *force = fmax(*force, fabs(f[k]));
        *length = fmax(*length, fabs(p->sinkage - q->sinkage));
    }
    const double pose[6] = {a->x - b->x, a->y - b->y, a->z - b->z, a->roll - b->roll, a->pitch - b->pitch,
                            a->yaw - b->yaw};
    for (int k = 0; k < 6; ++k) *length = fmax(*length, fabs(pose[k]));
}

static void test_tilt_is_the_grid(double sx, double sy, double yaw)
{
    char path[4096], err[512];
    write_plane_grid(sx, sy, path, sizeof path);
    Model *tilt = new_rover(sx, sy, yaw, NULL), *grid = new_rover(sx, sy, yaw, path);
    double force, length, worst_force, worst_length;
    differences(&tilt->out, &grid->out, &worst_force, &worst_length);
    const double z0 = tilt->out.z;
    int ok = 1;
    for (int k = 0; k < RUN_STEPS && ok; ++k) {
        if (model_do_step(tilt, 0.01, err, sizeof err) != 0 || model_do_step(grid, 0.01, err, sizeof err) != 0) {
            printf("model_do_step: %s\n", err);
            ok = 0;
            break;
        }
        differences(&tilt->out, &grid->out, &force, &length);
        worst_force = fmax(worst_force, force);
        worst_length = fmax(worst_length, length);
    }
    CHECK(ok, "slope (%g, %g), heading %.2f rad: both ran %g s", sx, sy, yaw, RUN_STEPS * 0.01);
    CHECK(worst_force <= FORCE_TOL * LOAD && worst_length <= LENGTH_TOL,
          "slope (%g, %g), heading %.2f rad: tilt and grid differ by at most %.3g N and %.3g m "
          "(the rover moved %.3f m down)", sx, sy, yaw, worst_force, worst_length, z0 - tilt->out.z);
    model_free(tilt);
    model_free(grid);
    free(tilt);
    free(grid);
    remove(path);
}

/* rover_terrain_under_wheels against rover_terrain_at at 400 points on
 * the plane grid, for each registration in turn (none, a raise only, a
 * shift, a turn, a tilt, all of them). */
static void test_terrain_under_wheels_is_terrain_at(void)
{
    static const double reg[6][6] = {   /* offsetX, offsetY, offsetZ, offsetYaw, slopeX, slopeY */
        {0, 0, 0, 0, 0, 0}, {0, 0, 0.3, 0, 0, 0}, {0.2, -0.1, 0, 0, 0, 0},
        {0, 0, 0, 0.4, 0, 0}, {0, 0, 0, 0, 0.2, -0.1}, {0.2, -0.1, 0.3, 0.4, 0.2, -0.1}};
    char path[4096];
    write_plane_grid(0.3, -0.2, path, sizeof path);
    Model *m = new_rover(0.3, -0.2, 0.0, path);
    int differ = 0;
    for (int r = 0; r < 6; ++r) {
        m->p.terrain_offsetX = reg[r][0], m->p.terrain_offsetY = reg[r][1], m->p.terrain_offsetZ = reg[r][2];
        m->p.terrain_offsetYaw = reg[r][3], m->p.terrain_slopeX = reg[r][4], m->p.terrain_slopeY = reg[r][5];
        for (int k = 0; k < 100; ++k) {
            double xy[NUM_WHEELS][3], zt[NUM_WHEELS], n[NUM_WHEELS][3];
            for (int w = 0; w < NUM_WHEELS; ++w) {   /* inside and beyond the grid's edge */
                xy[w][0] = -5.0 + 10.0 * (double)((37 * k + 11 * w) % 101) / 100.0;
                xy[w][1] = -5.0 + 10.0 * (double)((53 * k + 29 * w) % 103) / 102.0;
                xy[w][2] = 0.0;
            }
            rover_terrain_under_wheels(m, (const double (*)[3])xy, zt, n);
            for (int w = 0; w < NUM_WHEELS; ++w) {
                double n1[3];
                const double z1 = rover_terrain_at(m, xy[w][0], xy[w][1], n1);
                differ += memcmp(&z1, &zt[w], sizeof z1) != 0 || memcmp(n1, n[w], sizeof n1) != 0;
            }
        }
    }
    CHECK(differ == 0, "the terrain under four points at once is rover_terrain_at's at each, bit for bit, "
          "for 6 registrations (%d of 2400 differ)", differ);
    model_free(m);
    free(m);
    remove(path);
}

int main(void)
{
    test_terrain_under_wheels_is_terrain_at();
    static const double cases[][3] = {
        {0.3, 0.0, 0.0},     {0.0, -0.3, 0.0}, {0.6, 0.4, 0.5}, {1.0, 0.0, 0.0},
        {-1.0, 0.0, 0.0},    {0.0, 1.0, 0.0},  {0.0, 1.0, M_PI / 2}, {0.7, -0.7, 2.5},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) test_tilt_is_the_grid(cases[k][0], cases[k][1], cases[k][2]);
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
