/*
 * Standalone tests for the terrain reader and grid (fmu_src/terrain_reader.c
 * with the number conversion it includes, fmu_src/grid_decimal.h;
 * fmu_src/terrain_grid.c).
 *
 *   gcc -std=c11 -O2 -Wall -Wextra -Werror -pedantic -D_POSIX_C_SOURCE=200809L \
 *       fmu_src/terrain_reader.c fmu_src/terrain_grid.c tests/c/test_terrain.c -Ifmu_src -lm \
 *       -o /tmp/test_terrain
 *   /tmp/test_terrain [scratch-dir]
 *
 * Fixture grids are written into a fresh directory (mkdtemp under argv[1],
 * or /tmp) which is removed at the end.  Prints every failing check and a
 * final "N passed, M failed" line; exits nonzero if anything failed.
 */
#include "terrain.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int n_pass, n_fail;

#define CHECK(cond, ...)                                                     \
    do {                                                                     \
        if (cond) {                                                          \
            n_pass++;                                                        \
        } else {                                                             \
            n_fail++;                                                        \
            printf("FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond);           \
            printf(__VA_ARGS__);                                             \
            printf("\n");                                                    \
        }                                                                    \
    } while (0)

static const double PI = 3.14159265358979323846;

/* ---------------------------------------------------------------- */
/* fixtures                                                          */
/* ---------------------------------------------------------------- */

#define MAX_FIXTURES 128
static char scratch[4096];
static char fixtures[MAX_FIXTURES][4200];
static int n_fixtures;

/* Path of a fixture in the scratch directory (registered for removal). */
static const char *fixture_path(const char *name)
{
    int i;
    char p[4200];
    snprintf(p, sizeof p, "%s/%s", scratch, name);
    for (i = 0; i < n_fixtures; i++)
        if (strcmp(fixtures[i], p) == 0)
            return fixtures[i];
    if (n_fixtures == MAX_FIXTURES) {
        fprintf(stderr, "too many fixtures\n");
        exit(2);
    }
    strcpy(fixtures[n_fixtures], p);
    return fixtures[n_fixtures++];
}

static FILE *open_fixture(const char *name, const char **path)
{
    FILE *f;
    *path = fixture_path(name);
    f = fopen(*path, "wb");
    if (f == NULL) {
        perror(*path);
        exit(2);
    }
    return f;
}

static const char *write_fixture(const char *name, const char *text)
{
    const char *path;
    FILE *f = open_fixture(name, &path);
    fputs(text, f);
    fclose(f);
    return path;
}

typedef double (*SurfaceFn)(double x, double y, const void *ctx);

/* Writes an ESRI grid sampling fn at the cell centres x = x0 + i*cell,
 * y = y0 + j*cell (rows from north to south), with %.17g precision. */
static const char *write_surface(const char *name, int nc, int nr, double x0, double y0,
                                 double cell, SurfaceFn fn, const void *ctx)
{
    const char *path;
    FILE *f = open_fixture(name, &path);
    int i, j;
    fprintf(f, "ncols %d\nnrows %d\nxllcenter %.17g\nyllcenter %.17g\ncellsize %.17g\n",
            nc, nr, x0, y0, cell);
    for (j = nr - 1; j >= 0; j--) {
        for (i = 0; i < nc; i++)
            fprintf(f, "%s%.17g", i ? " " : "", fn(x0 + i * cell, y0 + j * cell, ctx));
        fputc('\n', f);
    }
    fclose(f);
    return path;
}

static void remove_fixtures(void)
{
    int i;
    for (i = 0; i < n_fixtures; i++)
        remove(fixtures[i]);
    if (rmdir(scratch) != 0)
        perror(scratch);
}

/* Deterministic uniform numbers in [a, b). */
static unsigned long long rng_state = 0x9E3779B97F4A7C15ULL;
static double urand(double a, double b)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return a + (b - a) * (double)(rng_state >> 11) / 9007199254740992.0;
}

static int is_flat(const Terrain *t)
{
    return t->ncols == 0 && t->nrows == 0 && t->z == NULL;
}

static double angle_deg(const double a[3], const double b[3])
{
    double c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    double s[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
    return atan2(sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]), c) * 180.0 / PI;
}

static double vdiff(const double a[3], const double b[3])
{
    return fmax(fabs(a[0] - b[0]), fmax(fabs(a[1] - b[1]), fabs(a[2] - b[2])));
}

/* ---------------------------------------------------------------- */
/* 1. plane                                                          */
/* ---------------------------------------------------------------- */

typedef struct { double a, b, c; } Plane;

static double plane_fn(double x, double y, const void *ctx)
{
    const Plane *p = ctx;
    return p->a + p->b * x + p->c * y;
}

static void plane_normal(const Plane *p, double n[3])
{
    double s = 1.0 / sqrt(p->b * p->b + p->c * p->c + 1.0);
    n[0] = -p->b * s, n[1] = -p->c * s, n[2] = s;
}

static void check_plane_point(const Terrain *t, const Plane *p, double x, double y, const char *what)
{
    double n[3], ne[3], h = terrain_height(t, x, y), he = plane_fn(x, y, p);
    terrain_normal(t, x, y, n);
    plane_normal(p, ne);
    CHECK(fabs(h - he) < 1e-12, "%s (%.9g, %.9g): height %.17g, expected %.17g", what, x, y, h, he);
    CHECK(vdiff(n, ne) < 1e-12, "%s (%.9g, %.9g): normal (%.17g %.17g %.17g), expected (%.17g %.17g %.17g)",
          what, x, y, n[0], n[1], n[2], ne[0], ne[1], ne[2]);
}

static void test_plane(void)
{
    const Plane p = { 1.3, 0.2, -0.15 };
    const int nc = 7, nr = 5;
    const double x0 = -0.75, y0 = 2.25, cell = 0.5;
    const double x1 = x0 + (nc - 1) * cell, y1 = y0 + (nr - 1) * cell;
    const double eps = 1e-9;
    char err[512];
    Terrain t;
    int k, rc;
    const char *path = write_surface("plane.asc", nc, nr, x0, y0, cell, plane_fn, &p);

    rc = terrain_load(&t, path, err, sizeof err);
    CHECK(rc == 0, "plane load failed: %s", err);
    if (rc != 0)
        return;
    CHECK(t.ncols == nc && t.nrows == nr, "size %d x %d", t.ncols, t.nrows);
    CHECK(t.x0 == x0 && t.y0 == y0 && t.cell == cell, "geometry %g %g %g", t.x0, t.y0, t.cell);
    /* row 0 must be the southernmost row (the last one in the file) */
    CHECK(fabs(t.z[0] - plane_fn(x0, y0, &p)) < 1e-15, "z[0] = %.17g is not the SW node", t.z[0]);
    CHECK(fabs(t.z[(nr - 1) * nc + nc - 1] - plane_fn(x1, y1, &p)) < 1e-15, "last z is not the NE node");

    for (k = 0; k < 300; k++)
        check_plane_point(&t, &p, urand(x0, x1), urand(y0, y1), "random interior");
    for (k = 0; k < 20; k++) {
        double s = urand(0.0, 1.0);
        check_plane_point(&t, &p, x0 + eps, y0 + s * (y1 - y0), "inside west edge");
        check_plane_point(&t, &p, x1 - eps, y0 + s * (y1 - y0), "inside east edge");
        check_plane_point(&t, &p, x0 + s * (x1 - x0), y0 + eps, "inside south edge");
        check_plane_point(&t, &p, x0 + s * (x1 - x0), y1 - eps, "inside north edge");
    }
    check_plane_point(&t, &p, x0, y0, "SW corner node");
    check_plane_point(&t, &p, x1, y1, "NE corner node");
    check_plane_point(&t, &p, x0 + 2 * cell, y0 + 3 * cell, "interior node");
    terrain_free(&t);
    CHECK(is_flat(&t), "terrain_free did not reset to flat");
}

/* ---------------------------------------------------------------- */
/* 2. 15-degree slope                                                */
/* ---------------------------------------------------------------- */

static void test_slope15(void)
{
    const double tilt = 15.0 * PI / 180.0, dir = 30.0 * PI / 180.0;
    const Plane p = { 0.0, tan(tilt) * cos(dir), tan(tilt) * sin(dir) };
    char err[512];
    Terrain t;
    int k;
    const char *path = write_surface("slope15.asc", 12, 9, 0.0, 0.0, 0.25, plane_fn, &p);

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "slope load failed: %s", err);
    for (k = 0; k < 50; k++) {
        double n[3], x = urand(-1.0, 4.0), y = urand(-1.0, 3.0); /* also outside */
        double deg;
        terrain_normal(&t, x, y, n);
        if (x < 0.0 || x > 11 * 0.25 || y < 0.0 || y > 8 * 0.25) {
            /* beyond the nodes the ground is level */
            CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "outside (%g, %g): normal (%g %g %g) not up",
                  x, y, n[0], n[1], n[2]);
            continue;
        }
        deg = acos(n[2]) * 180.0 / PI;
        CHECK(fabs(deg - 15.0) < 1e-9, "tilt %.12g deg at (%g, %g)", deg, x, y);
        CHECK(fabs(hypot(n[0], n[1]) - sin(tilt)) < 1e-12, "horizontal part %.17g", hypot(n[0], n[1]));
        /* the normal leans downhill, i.e. against the gradient direction */
        CHECK(fabs(atan2(-n[1], -n[0]) - dir) < 1e-9, "lean azimuth %.12g", atan2(-n[1], -n[0]));
        CHECK(fabs(n[0] * n[0] + n[1] * n[1] + n[2] * n[2] - 1.0) < 1e-14, "not unit");
    }
    terrain_free(&t);
}

/* ---------------------------------------------------------------- */
/* 3. corner vs centre                                               */
/* ---------------------------------------------------------------- */

static void test_corner_center(void)
{
    const char *data = "1 2 3\n4 5 6\n7 8 10\n";
    char text[512], err[512];
    Terrain a, b;
    const char *pa, *pb;
    int k;

    snprintf(text, sizeof text, "ncols 3\nnrows 3\nxllcorner 10\nyllcorner 20\ncellsize 2\n%s", data);
    pa = write_fixture("corner.asc", text);
    snprintf(text, sizeof text, "ncols 3\nnrows 3\nxllcenter 10\nyllcenter 20\ncellsize 2\n%s", data);
    pb = write_fixture("center.asc", text);

    CHECK(terrain_load(&a, pa, err, sizeof err) == 0, "corner load: %s", err);
    CHECK(terrain_load(&b, pb, err, sizeof err) == 0, "center load: %s", err);
    CHECK(a.x0 == 11.0 && a.y0 == 21.0, "corner: node origin (%g, %g), expected (11, 21)", a.x0, a.y0);
    CHECK(b.x0 == 10.0 && b.y0 == 20.0, "center: node origin (%g, %g), expected (10, 20)", b.x0, b.y0);
    /* SW node value is the first value of the last file row */
    CHECK(terrain_height(&a, 11.0, 21.0) == 7.0, "corner SW node %g", terrain_height(&a, 11.0, 21.0));
    CHECK(terrain_height(&b, 10.0, 20.0) == 7.0, "center SW node %g", terrain_height(&b, 10.0, 20.0));
    CHECK(terrain_height(&a, 15.0, 25.0) == 3.0, "corner NE node %g", terrain_height(&a, 15.0, 25.0));
    for (k = 0; k < 50; k++) {
        double x = urand(9.0, 16.0), y = urand(19.0, 26.0), na[3], nb[3];
        double ha = terrain_height(&a, x + 1.0, y + 1.0), hb = terrain_height(&b, x, y);
        CHECK(fabs(ha - hb) < 1e-12, "shifted heights differ at (%g, %g): %.17g vs %.17g", x, y, ha, hb);
        terrain_normal(&a, x + 1.0, y + 1.0, na);
        terrain_normal(&b, x, y, nb);
        CHECK(vdiff(na, nb) < 1e-12, "shifted normals differ at (%g, %g)", x, y);
    }
    terrain_free(&a);
    terrain_free(&b);
}

/* ---------------------------------------------------------------- */
/* 4. smooth mound                                                   */
/* ---------------------------------------------------------------- */

static double mound_fn(double x, double y, const void *ctx)
{
    (void)ctx;
    return 0.5 * exp(-(x * x + y * y) / 2.0);
}

static void test_mound(void)
{
    const double cell = 0.05;
    char err[512];
    Terrain t;
    int k;
    double worst_h = 0.0, worst_a = 0.0;
    const char *path = write_surface("mound.asc", 81, 81, -2.0, -2.0, cell, mound_fn, NULL);

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "mound load failed: %s", err);
    for (k = 0; k < 2000; k++) {
        double x = urand(-1.95, 1.95), y = urand(-1.95, 1.95), n[3], ne[3];
        double e = mound_fn(x, y, NULL), gx = -x * e, gy = -y * e, s = 1.0 / sqrt(gx * gx + gy * gy + 1.0);
        double dh = fabs(terrain_height(&t, x, y) - e), da;
        ne[0] = -gx * s, ne[1] = -gy * s, ne[2] = s;
        terrain_normal(&t, x, y, n);
        da = angle_deg(n, ne);
        worst_h = fmax(worst_h, dh);
        worst_a = fmax(worst_a, da);
    }
    CHECK(worst_h < 1e-3, "mound height error %.3g m", worst_h);
    CHECK(worst_a < 1.0, "mound normal error %.3g deg", worst_a);
    printf("mound: worst height error %.3g m, worst normal error %.3g deg\n", worst_h, worst_a);
    terrain_free(&t);
}

/* ---------------------------------------------------------------- */
/* 5. outside the grid; flat ground                                  */
/* ---------------------------------------------------------------- */

/* A curved surface, so that extrapolating instead of clamping shows up in
 * the normal as well as in the height. */
static double quad_fn(double x, double y, const void *ctx)
{
    (void)ctx;
    return 0.5 + 0.3 * x * x - 0.2 * y * y + 0.1 * x * y;
}

static void test_outside_and_flat(void)
{
    const double x0 = 1.0, y0 = -2.0, cell = 0.1, x1 = x0 + 9 * cell, y1 = y0 + 7 * cell;
    const double far[][2] = { { -100, 0 }, { 100, 0 }, { 0, -100 }, { 0, 100 } };
    char err[512];
    Terrain t;
    int k;
    double n[3], ne[3];
    const char *path = write_surface("outside.asc", 10, 8, x0, y0, cell, quad_fn, NULL);

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "load failed: %s", err);
    for (k = 0; k < 30; k++) {
        double x = urand(x0, x1), y = urand(y0, y1), d = urand(0.01, 50.0);
        CHECK(fabs(terrain_height(&t, x1 + d, y) - terrain_height(&t, x1, y)) < 1e-12, "east not clamped");
        CHECK(fabs(terrain_height(&t, x0 - d, y) - terrain_height(&t, x0, y)) < 1e-12, "west not clamped");
        CHECK(fabs(terrain_height(&t, x, y1 + d) - terrain_height(&t, x, y1)) < 1e-12, "north not clamped");
        CHECK(fabs(terrain_height(&t, x, y0 - d) - terrain_height(&t, x, y0)) < 1e-12, "south not clamped");
        /* outside: level ground, the normal exactly up on every side */
        terrain_normal(&t, x1 + d, y, n);
        CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "east normal (%g %g %g) not up", n[0], n[1], n[2]);
        terrain_normal(&t, x0 - d, y, n);
        CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "west normal (%g %g %g) not up", n[0], n[1], n[2]);
        terrain_normal(&t, x, y1 + d, n);
        CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "north normal (%g %g %g) not up", n[0], n[1], n[2]);
        terrain_normal(&t, x, y0 - d, n);
        CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "south normal (%g %g %g) not up", n[0], n[1], n[2]);
        /* on the edge itself (inside, edges included) the normal is still
         * the grid's: the quadratic surface is not level at its east edge */
        terrain_normal(&t, x1, y, ne);
        CHECK(ne[2] < 1.0 - 1e-6, "east edge normal (%g %g %g) should be the grid's slope", ne[0], ne[1], ne[2]);
        /* the transition at the edge: the elevation is continuous (no step:
         * just outside equals on the edge to rounding), the normal has a
         * kink (jumps from the edge's slope to vertical) */
        CHECK(fabs(terrain_height(&t, x1 + 1e-9, y) - terrain_height(&t, x1, y)) < 1e-12, "step at the east edge");
        CHECK(terrain_outside(&t, x1 + 1e-9, y) && !terrain_outside(&t, x1, y), "outside test at the east edge");
    }
    for (k = 0; k < 4; k++) {
        terrain_normal(&t, x0 - 5 + 2 * (k & 1) * (x1 - x0 + 5), y0 - 5 + (k & 2) * (y1 - y0 + 5), n);
        CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "corner %d normal (%g %g %g) not up", k, n[0], n[1], n[2]);
    }
    terrain_normal(&t, 1e300, -1e300, n);
    CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "huge coordinates: normal (%g %g %g) not up", n[0], n[1], n[2]);
    CHECK(fabs(terrain_height(&t, x0 - 5, y0 - 5) - quad_fn(x0, y0, NULL)) < 1e-12, "SW corner extension");
    CHECK(fabs(terrain_height(&t, x1 + 5, y1 + 5) - quad_fn(x1, y1, NULL)) < 1e-12, "NE corner extension");
    CHECK(fabs(terrain_height(&t, 1e300, -1e300) - quad_fn(x1, y0, NULL)) < 1e-12, "huge coordinates");
    CHECK(isnan(terrain_height(&t, NAN, 0.0)), "NaN query should give NaN");
    terrain_free(&t);

    terrain_init_flat(&t);
    CHECK(is_flat(&t), "terrain_init_flat not flat");
    for (k = 0; k < 4; k++) {
        CHECK(terrain_height(&t, far[k][0], far[k][1]) == 0.0, "flat height not 0");
        terrain_normal(&t, far[k][0], far[k][1], n);
        CHECK(n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0, "flat normal (%g %g %g)", n[0], n[1], n[2]);
    }
}

/* ---------------------------------------------------------------- */
/* 6. NODATA filling                                                 */
/* ---------------------------------------------------------------- */

static void test_nodata(void)
{
    /* 6 x 5, north first; holes: isolated interior cell, a 2x2 block,
     * a corner and an edge cell */
    const char *text =
        "ncols 6\nnrows 5\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n"
        "-9999 2 3 4 5 6\n"
        "1 -9999 -9999 5 6 -9999\n"
        "2 -9999 -9999 6 -9999 8\n"
        "3 4 5 6 7 8\n"
        "4.5 5 6.5 7 8 9\n";
    static const int hole[5][6] = { /* file order, north first */
        { 1, 0, 0, 0, 0, 0 }, { 0, 1, 1, 0, 0, 1 }, { 0, 1, 1, 0, 1, 0 },
        { 0, 0, 0, 0, 0, 0 }, { 0, 0, 0, 0, 0, 0 } };
    char err[512];
    Terrain t, t2;
    int i, j, ok_finite = 1, ok_range = 1, ok_valid = 1;
    const char *path = write_fixture("nodata.asc", text);
    double vmin = 1e300, vmax = -1e300;

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "nodata load failed: %s", err);
    if (t.ncols != 6 || t.nrows != 5)
        return;
    for (j = 0; j < 5; j++)
        for (i = 0; i < 6; i++) {
            double v = t.z[j * 6 + i];
            if (!isfinite(v) || v == -9999.0)
                ok_finite = 0;
            if (!hole[4 - j][i])
                vmin = fmin(vmin, v), vmax = fmax(vmax, v);
        }
    CHECK(ok_finite, "NODATA cells left unfilled or non-finite");
    for (j = 0; j < 5; j++)
        for (i = 0; i < 6; i++) {
            double v = t.z[j * 6 + i], lo = 1e300, hi = -1e300;
            if (!hole[4 - j][i])
                continue;
            if (i > 0) lo = fmin(lo, t.z[j * 6 + i - 1]), hi = fmax(hi, t.z[j * 6 + i - 1]);
            if (i < 5) lo = fmin(lo, t.z[j * 6 + i + 1]), hi = fmax(hi, t.z[j * 6 + i + 1]);
            if (j > 0) lo = fmin(lo, t.z[(j - 1) * 6 + i]), hi = fmax(hi, t.z[(j - 1) * 6 + i]);
            if (j < 4) lo = fmin(lo, t.z[(j + 1) * 6 + i]), hi = fmax(hi, t.z[(j + 1) * 6 + i]);
            if (!(v >= lo && v <= hi && v >= vmin && v <= vmax)) {
                ok_range = 0;
                printf("  filled cell (col %d, row %d) = %g outside [%g, %g]\n", i, j, v, lo, hi);
            }
        }
    CHECK(ok_range, "filled values not between their neighbours' min and max");
    /* valid cells keep their values (spot checks; row 0 = south) */
    ok_valid = t.z[0] == 4.5 && t.z[5] == 9.0 && t.z[1 * 6 + 3] == 6.0 && t.z[4 * 6 + 5] == 6.0;
    CHECK(ok_valid, "valid cells changed");
    /* the isolated hole (file row 3, column 5) has four valid neighbours
     * 6 (west), 8 (east), 6 (north), 7 (south): it gets their mean */
    CHECK(fabs(t.z[2 * 6 + 4] - (6.0 + 8.0 + 6.0 + 7.0) / 4.0) < 1e-15,
          "isolated hole %.17g, expected the mean of its 4 neighbours 6.75", t.z[2 * 6 + 4]);
    /* corner (file row 1, col 1) has neighbours 2 (east) and 1 (south) */
    CHECK(fabs(t.z[4 * 6 + 0] - 1.5) < 1e-15, "corner hole %.17g, expected 1.5", t.z[4 * 6 + 0]);
    /* deterministic */
    CHECK(terrain_load(&t2, path, err, sizeof err) == 0, "second load: %s", err);
    CHECK(t2.z != NULL && memcmp(t.z, t2.z, 30 * sizeof(double)) == 0, "fill not deterministic");
    terrain_free(&t);
    terrain_free(&t2);
}

/* A hole between elevations near the double range gets their mean, not
 * the overflow of their sum. */
static void test_nodata_near_double_range(void)
{
    const char *text =
        "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n"
        "1e308 -9999 1.5e308\n"
        "1 2 3\n";
    char err[512];
    Terrain t;
    const char *path = write_fixture("nodata_huge.asc", text);

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "load failed: %s", err);
    if (t.ncols != 3 || t.nrows != 2)
        return;
    /* north row (row 1): the hole's neighbours are 1e308, 1.5e308 (west,
     * east) and 2 (south) */
    const double v = t.z[1 * 3 + 1], expected = 1e308 / 3.0 + 1.5e308 / 3.0 + 2.0 / 3.0;
    CHECK(isfinite(v) && fabs(v - expected) <= 1e-15 * expected,
          "hole between 1e308 and 1.5e308: %.17g, expected %.17g", v, expected);
    terrain_free(&t);
}

/* ---------------------------------------------------------------- */
/* 7. bad and odd files                                              */
/* ---------------------------------------------------------------- */

static const char *HDR = "ncols 4\nnrows 3\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value -9999\n";

/* Loads a file expected to be refused: checks -1, *t flat (even though it
 * held junk on entry, which must not be freed), and that err names the
 * file and contains each of the given fragments. */
static void expect_fail(const char *name, const char *text, const char *frag1, const char *frag2)
{
    static double not_heap[4];
    char err[1024];
    Terrain t;
    const char *path = text ? write_fixture(name, text) : fixture_path(name);
    int rc;

    t.ncols = 7, t.nrows = 7, t.cell = 1.0, t.x0 = t.y0 = 3.0, t.z = not_heap;
    memset(err, 'X', sizeof err);
    rc = terrain_load(&t, path, err, sizeof err);
    CHECK(memchr(err, '\0', sizeof err) != NULL, "%s: err not NUL-terminated", name);
    err[sizeof err - 1] = '\0';
    CHECK(rc == -1, "%s: accepted (rc %d)", name, rc);
    CHECK(is_flat(&t), "%s: *t not left flat", name);
    CHECK(strstr(err, path) != NULL, "%s: err does not name the file: %s", name, err);
    if (frag1)
        CHECK(strstr(err, frag1) != NULL, "%s: err lacks '%s': %s", name, frag1, err);
    if (frag2)
        CHECK(strstr(err, frag2) != NULL, "%s: err lacks '%s': %s", name, frag2, err);
    if (rc == 0)
        terrain_free(&t);
}

/* Loads a file expected to be accepted and returns the terrain. */
static int expect_ok(const char *path, Terrain *t, int nc, int nr, const char *what)
{
    char err[1024];
    int rc = terrain_load(t, path, err, sizeof err);
    CHECK(rc == 0, "%s refused: %s", what, err);
    if (rc != 0)
        return 0;
    CHECK(t->ncols == nc && t->nrows == nr, "%s: size %d x %d, expected %d x %d", what, t->ncols,
          t->nrows, nc, nr);
    return t->ncols == nc && t->nrows == nr;
}

static void test_bad_files(void)
{
    char text[2048];

    expect_fail("does_not_exist.asc", NULL, "cannot open", "No such file");
    expect_fail("empty.asc", "", "empty", NULL);
    expect_fail("blank.asc", "  \n\r\n\t\n", "empty", NULL);
    expect_fail("no_ncols.asc", "nrows 3\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n5 6\n",
                "ncols", "line 5:");
    expect_fail("no_xll.asc", "ncols 2\nnrows 2\nyllcorner 0\ncellsize 1\n1 2\n3 4\n", "xllcorner", NULL);
    expect_fail("no_cellsize.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2\n3 4\n",
                "cellsize", NULL);
    expect_fail("nrows_neg.asc", "ncols 2\nnrows -3\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n",
                "nrows", "line 2:");
    expect_fail("ncols_frac.asc", "ncols 2.5\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n",
                "ncols", "line 1:");
    expect_fail("ncols_huge.asc", "ncols 30000\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n",
                "too large", "line 1:");
    expect_fail("cells_huge.asc", "ncols 20000\nnrows 20000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1\n",
                "too large", NULL);
    expect_fail("cellsize0.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 0\n1 2\n3 4\n",
                "cellsize", "line 5:");
    expect_fail("cellsize_bad.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize abc\n1 2\n3 4\n",
                "'abc'", "line 5:");
    expect_fail("dup.asc", "ncols 2\nnrows 2\nxllcorner 0\nNROWS 2\nyllcorner 0\ncellsize 1\n1 2\n3 4\n",
                "duplicate", "line 4:");
    expect_fail("both_corner_center.asc",
                "ncols 2\nnrows 2\nxllcorner 0\nxllcenter 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n",
                "xllcenter", "line 4:");
    expect_fail("unknown_key.asc", "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\nfoo 1\ncellsize 1\n1 2\n3 4\n",
                "'foo'", "line 5:");
    expect_fail("no_value.asc", "ncols 2\nnrows\n2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n",
                "no value", "line 2:");
    expect_fail("extra_hdr.asc", "ncols 2 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4\n",
                "'3'", "line 1:");

    snprintf(text, sizeof text, "%s1 2 3 4\n5 6 7 8\n9 abc 11 12\n", HDR);
    expect_fail("abc.asc", text, "line 9,", "'abc'");
    snprintf(text, sizeof text, "%s1 2 3 4\n5 6 7 8\n9 10 11\n", HDR);
    expect_fail("few.asc", text, "expected nrows*ncols = 3*4 = 12 values, found 11", "row 3");
    snprintf(text, sizeof text, "%s1 2 3 4\n5 6 7 8\n", HDR);
    expect_fail("few_rows.asc", text, "found 8", "row 3");
    snprintf(text, sizeof text, "%s", HDR);
    expect_fail("no_data.asc", text, "found 0", NULL);
    snprintf(text, sizeof text, "%s1 2 3 4\n5 6 7 8\n9 10 11 12\n\n13\n", HDR);
    expect_fail("many.asc", text, "extra", "line 11,");
    snprintf(text, sizeof text, "%s1 2 3 4\n5 6 nan 8\n9 10 11 12\n", HDR);
    expect_fail("nan.asc", text, "not finite", "line 8,");
    snprintf(text, sizeof text, "%s1 2 3 4\n5 6 7 8\n9 10 11 -inf\n", HDR);
    expect_fail("inf.asc", text, "not finite", "line 9,");
    snprintf(text, sizeof text, "%s1 2 3 1e999\n5 6 7 8\n9 10 11 12\n", HDR);
    expect_fail("overflow.asc", text, "not finite", "line 7,");
    expect_fail("1x1.asc", "ncols 1\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n5\n", "2 x 2", NULL);
    expect_fail("3x1.asc", "ncols 3\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n5 6 7\n", "2 x 2",
                "line 2:");
    snprintf(text, sizeof text, "%s-9999 -9999 -9999 -9999\n-9999 -9999 -9999 -9999\n"
             "-9999 -9999 -9999 -9999.0\n", HDR);
    expect_fail("all_nodata.asc", text, "NODATA", NULL);

    /* a very long bad token is quoted only in part */
    {
        char tok[600];
        memset(tok, 'q', sizeof tok - 1);
        tok[sizeof tok - 1] = '\0';
        snprintf(text, sizeof text, "%s1 2 3 4\n5 %s 7 8\n9 10 11 12\n", HDR, tok);
        expect_fail("long_token.asc", text, "line 8,", "...");
    }
    /* a value whose digits after the point run into '/' or ':' (the bytes
     * either side of '0'..'9') is not a number, wherever in the reader's
     * words of eight and sixteen digits that byte falls; white space after
     * the grid keeps the value far from the file's end, where the grid's
     * values are read */
    {
        static const int digits_before[] = {0, 3, 7, 8, 9, 15, 16, 17, 23, 24, 31, 32, 33};
        static const char ends[] = {'/', ':'};
        char name[64], bad[64], quoted[96];
        size_t i, j;
        for (i = 0; i < sizeof digits_before / sizeof digits_before[0]; i++) {
            for (j = 0; j < sizeof ends; j++) {
                int n = 3, k;
                memcpy(bad, "-0.", 3);
                for (k = 0; k < digits_before[i]; k++)
                    bad[n++] = (char)('1' + k % 9);
                bad[n++] = ends[j];
                bad[n++] = '5';
                bad[n] = '\0';
                snprintf(name, sizeof name, "runs_on_%d_%d.asc", digits_before[i], (int)j);
                snprintf(quoted, sizeof quoted, "'%s' is not a number", bad);
                snprintf(text, sizeof text, "%s1 2 3 4\n5 6 %s 8\n9 10 11 12\n%64s\n", HDR, bad, "");
                expect_fail(name, text, "line 8, value 3 on the line (grid row 2, column 3)", quoted);
            }
        }
    }
    /* a long number token is not silently cut to a shorter number */
    {
        char num[400];
        memset(num, '1', sizeof num - 1);
        num[0] = '0', num[1] = '.';
        num[sizeof num - 1] = '\0';
        snprintf(text, sizeof text, "%s1 2 3 4\n5 6 7 %s\n9 10 11 12\n", HDR, num);
        expect_fail("long_number.asc", text, "line 8,", NULL);
    }
}

/* Small error buffers are filled safely and NUL-terminated. */
/* A path that is not a regular file is refused at once, before it is
 * opened, with a message naming it and saying what it is: a directory,
 * a device that never ends (/dev/zero), a FIFO no writer opens (opening
 * it for reading would block forever; the alarm ends the test if so). */
static void expect_not_regular(const char *path, const char *kind)
{
    char err[512];
    Terrain t;
    int r;
    alarm(10);
    r = terrain_load(&t, path, err, sizeof err);
    alarm(0);
    CHECK(r == -1, "%s (%s) was accepted", path, kind);
    CHECK(is_flat(&t), "%s: not flat after failure", path);
    CHECK(strstr(err, path) != NULL && strstr(err, "not a regular file") != NULL && strstr(err, kind) != NULL,
          "%s: message '%s' should name the path, 'not a regular file' and '%s'", path, err, kind);
}

static void test_not_regular_files(void)
{
    char dir[4200], fifo[4200];
    snprintf(dir, sizeof dir, "%s/a directory.asc", scratch);
    snprintf(fifo, sizeof fifo, "%s/fifo.asc", scratch);
    CHECK(mkdir(dir, 0700) == 0, "mkdir %s", dir);
    expect_not_regular(dir, "directory");
    if (access("/dev/zero", R_OK) == 0)
        expect_not_regular("/dev/zero", "device");
    CHECK(mkfifo(fifo, 0600) == 0, "mkfifo %s", fifo);
    expect_not_regular(fifo, "FIFO");
    rmdir(dir);
    unlink(fifo);
}

static void test_err_buffer(void)
{
    char buf[24];
    Terrain t;
    const char *path = fixture_path("does_not_exist_either.asc");
    int rc;

    memset(buf, 'X', sizeof buf);
    rc = terrain_load(&t, path, buf, 10);
    CHECK(rc == -1 && is_flat(&t), "missing file accepted");
    CHECK(buf[9] == '\0' && strlen(buf) == 9, "small err buffer not truncated: len %zu", strlen(buf));
    CHECK(buf[10] == 'X' && buf[23] == 'X', "err buffer overrun");
    rc = terrain_load(&t, path, NULL, 0);
    CHECK(rc == -1 && is_flat(&t), "NULL err buffer");
    buf[0] = 'X';
    rc = terrain_load(&t, path, buf, 0);
    CHECK(rc == -1 && buf[0] == 'X', "errlen 0 must not write");
}

static void test_odd_but_valid(void)
{
    Terrain t;
    const char *path;
    FILE *f;
    int i, j;

    /* CRLF, mixed-case keys, NODATA key spelled differently, no final newline */
    path = write_fixture("crlf.asc", "NCOLS 3\r\nNRows 2\r\nXLLCorner 1\r\nyllCORNER 2\r\n"
                                     "CellSize 0.5\r\nnodata_VALUE -1\r\n1 2 3\r\n4 5 6");
    if (expect_ok(path, &t, 3, 2, "CRLF file")) {
        CHECK(t.x0 == 1.25 && t.y0 == 2.25 && t.cell == 0.5, "CRLF geometry");
        CHECK(t.z[0] == 4 && t.z[2] == 6 && t.z[3] == 1 && t.z[5] == 3, "CRLF values");
        terrain_free(&t);
    }
    /* CRLF line numbers still right in error messages */
    expect_fail("crlf_bad.asc", "ncols 2\r\nnrows 2\r\nxllcorner 0\r\nyllcorner 0\r\ncellsize 1\r\n"
                                "1 2\r\n3 x\r\n", "line 7,", "'x'");
    /* old Mac line ends (lone CR) count as lines too */
    expect_fail("cr_bad.asc", "ncols 2\rnrows 2\rxllcorner 0\ryllcorner 0\rcellsize 1\r1 2\r3 x\r",
                "line 7,", "'x'");

    /* UTF-8 BOM, tabs, blank lines, values split arbitrarily across lines */
    path = write_fixture("split.asc", "\xEF\xBB\xBFncols\t3\n\nnrows 3\nxllcenter 0\nyllcenter 0\n"
                                      "cellsize 1\n1\n2 3 4\n5 6 7 8\n\n   9   \n");
    if (expect_ok(path, &t, 3, 3, "split file")) {
        CHECK(t.z[6] == 1 && t.z[8] == 3 && t.z[0] == 7 && t.z[2] == 9, "split values");
        terrain_free(&t);
    }

    /* 5000 columns: each row on one huge line */
    f = open_fixture("wide.asc", &path);
    fprintf(f, "ncols 5000\nnrows 3\nxllcenter 0\nyllcenter 0\ncellsize 0.01\n");
    for (j = 2; j >= 0; j--) {
        for (i = 0; i < 5000; i++)
            fprintf(f, "%s%.17g", i ? " " : "", 1000.0 * j + i + 0.123456789012345);
        fputc('\n', f);
    }
    fclose(f);
    if (expect_ok(path, &t, 5000, 3, "5000-column file")) {
        CHECK(t.z[4999] == 1000.0 * 0 + 4999 + 0.123456789012345 &&
              t.z[2 * 5000 + 17] == 1000.0 * 2 + 17 + 0.123456789012345, "wide values");
        /* midway between columns 4998/4999 and rows 1/2 */
        CHECK(fabs(terrain_height(&t, 49.985, 0.015) - (1500.0 + 4998.5 + 0.123456789012345)) < 1e-8,
              "wide interpolation %.17g", terrain_height(&t, 49.985, 0.015));
        terrain_free(&t);
    }

    /* the whole grid on one line, ending without a newline; a bad token at
     * the end of that line is reported on line 6 */
    f = open_fixture("oneline.asc", &path);
    fprintf(f, "ncols 4000\nnrows 4\nxllcenter 0\nyllcenter 0\ncellsize 1\n");
    for (i = 0; i < 16000; i++)
        fprintf(f, "%s%d", i ? " " : "", i % 97);
    fclose(f);
    if (expect_ok(path, &t, 4000, 4, "single-line file")) {
        CHECK(t.z[3 * 4000] == 0 && t.z[1] == (12001 % 97), "single-line values");
        terrain_free(&t);
    }
    f = open_fixture("oneline_bad.asc", &path);
    fprintf(f, "ncols 4000\nnrows 4\nxllcenter 0\nyllcenter 0\ncellsize 1\n");
    for (i = 0; i < 15999; i++)
        fprintf(f, "%s%d", i ? " " : "", i % 97);
    fprintf(f, " 1.5.3");
    fclose(f);
    expect_fail("oneline_bad.asc", NULL, "line 6, value 16000", "'1.5.3'");
}

/* Every value read is strtod's for the same text, bit for bit (the reader
 * parses common decimals itself and hands the rest to strtod): fixed
 * corner cases around its limits (2^53 digits, 10^+-22 and 10^+-27, 17
 * to 20 significant digits, ties above 2^53, signs, zeros, the grids'
 * usual "%.6f" values and the limits of their shortcut, Python's shortest
 * round-trip values, exact ties between two doubles) and 9000 random
 * tokens: of up to 20 digits with random point, sign and exponent, and
 * shaped like Python's shortest round-trip values. */
static void test_numbers_match_strtod(void)
{
    static const char *const fixed[] = {
        "0", "-0", "+0", "0.0", "-0.000", "0e999", "-0e-999", "1", "-1", "+7", "1.", ".5", "-.5", "1.5",
        "0.1", "0.2", "0.3", "123.456", "-9999", "1e22", "1e23", "1e-22", "1e-23", "1E5", "2.5e-3",
        "2.5E+3", "9007199254740992", "9007199254740993", "9007199254740991", "900719925474099.3",
        "18014398509481985", "12345678901234567", "123456789012345678", "0.12345678901234567",
        "0.0038795912416837394", "00000001.50000000000000000000", "0.000000000000000000000001",
        "4.9406564584124654e-324", "1.7976931348623157e308", "3.14159265358979323846", "1e0", "1e-0",
        "5e-1", "0.000001", "100000000000000000000000", "4503599627370497.5", "2.2250738585072014e-308",
        /* ties and near-ties above 2^53 (round half to even) */
        "9007199254740995", "18014398509481986", "18014398509481990", "18014398509481986.000000001",
        "1801439850948198.6e1", "18014398509481985.9999", "0.0038795912416837394", "-0.00011357538857554618",
        "1234567890123456789", "12345678901234567890", "0.1234567890123456789e-8", "9999999999999999999e-27",
        "9999999999999999999e27", "1e-27", "1e27", "1e28", "1e-28",
        /* the grids' usual "%.6f" shapes, and either side of seven digits each side of the point */
        "0.004940", "-0.000114", "-0.000000", "0.000000", "0.500000", "9.999999", "1234567.1234567",
        "-1234567.7654321", "12345678.5", "0.12345678", "12345678.12345678", "7.", "-7.0000001e2", "5.25e-3",
        /* shortest round-trip values as Python writes them (17 significant digits after up to three
         * zeros), the limits of 19 digits and of three runs of eight after the point, and exact
         * ties between two doubles m / 10^k (k = 1..4: the reciprocal cannot tell, the division
         * decides) with their neighbours */
        "0.00024398663911276647", "-0.0009433532997486452", "0.0038795912416837394", "-0.047928081333166754",
        "1234567.123456789012", "1234567.1234567890123", "0.1234567890123456789", "0.12345678901234567890",
        "0.00000000000000012345678", "0.000000000000000000000001", "-0.000000000000000000000000",
        "2251799813685248.25", "2251799813685248.2500000001", "2251799813685248.2499999999",
        "1125899906842624.125", "1125899906842624.375", "562949953421312.0625", "562949953421312.0625000001",
        "4503599627370498.5",
        /* the digits after the point read sixteen at a time: runs of 31 to 40 (declined: strtod
         * reads them), and exponents right after 7, 8, 15, 16, 17 and 23 of them */
        "0.1234567890123456789012345678901", "-0.12345678901234567890123456789012",
        "0.000000000000000000000000000000001", "7.0000000000000000000000000000000000000",
        "0.1234567e3", "0.12345678e-3", "0.123456789012345e2", "-0.1234567890123456e1",
        "0.12345678901234567E-2", "0.00000000000000000000012e22"};
    /* the reader takes the digits after the point in words of eight:
     * NSHAPE tokens with every count of them from 0 to 25 (each side of
     * one, two and three whole words), after integer parts of one to
     * eight digits with and without a sign, some with leading zeros after
     * the point, and NRAND random tokens: a third of 1 to 20 digits, a
     * third of 16 to 19 significant digits (beyond 2^53: the exact integer
     * path), a third shaped like Python's shortest round-trip values
     * ([-]d.ddd or [-]0.000ddd with 15 to 19 significant digits) */
    static const char *const int_parts[] = {"0", "-0", "7", "-3", "+0", "12", "-1234567", "12345678"};
    enum { NFIX = sizeof fixed / sizeof fixed[0], NINT = sizeof int_parts / sizeof int_parts[0],
           NFRAC = 26, NSHAPE = 2 * NINT * NFRAC, NRAND = 9000 + (NFIX + NSHAPE) % 2,
           N = NFIX + NSHAPE + NRAND };   /* N even: two rows */
    static char tok[N][48];
    const char *path;
    FILE *f;
    Terrain t;
    int i, k, bad = 0;

    for (i = 0; i < N; i++) {
        char *q = tok[i];
        int nd, point, e;
        if (i < NFIX) {
            snprintf(tok[i], sizeof tok[i], "%s", fixed[i]);
            continue;
        }
        if (i < NFIX + NSHAPE) {
            const int s = i - NFIX, nf = s % NFRAC, zeros = (s / NFRAC) % 2 ? nf / 3 : 0;
            q += sprintf(q, "%s.", int_parts[s / (2 * NFRAC)]);
            for (k = 0; k < nf; k++)
                *q++ = (char)('0' + (k < zeros ? 0 : (int)urand(0, 10)));
            *q = '\0';
            continue;
        }
        if (i >= NFIX + NSHAPE + 2 * (NRAND / 3)) {
            const int zeros = (int)urand(0, 4);
            nd = 15 + (int)urand(0, 5);
            if (urand(0, 1) < 0.4) *q++ = '-';
            if (zeros > 0 || urand(0, 1) < 0.5) {
                q += sprintf(q, "0.%.*s", zeros, "000");
                *q++ = (char)('1' + (int)urand(0, 9));
            } else {
                *q++ = (char)('1' + (int)urand(0, 9));
                *q++ = '.';
            }
            for (k = 1; k < nd; k++)
                *q++ = (char)('0' + (int)urand(0, 10));
            *q = '\0';
            continue;
        }
        if (urand(0, 1) < 0.3) *q++ = urand(0, 1) < 0.8 ? '-' : '+';
        nd = i < NFIX + NSHAPE + NRAND / 3 ? 1 + (int)urand(0, 20) : 16 + (int)urand(0, 4);
        point = (int)urand(-1, nd + 1);            /* -1: no point */
        for (k = 0; k < nd; k++) {
            if (k == point) *q++ = '.';
            *q++ = (char)('0' + (k == 0 && urand(0, 1) < 0.7 ? 1 + (int)urand(0, 9) : (int)urand(0, 10)));
        }
        if (point == nd) *q++ = '.';
        if (urand(0, 1) < 0.3) {
            e = (int)urand(-30, 31);
            q += sprintf(q, "%c%d", urand(0, 1) < 0.5 ? 'e' : 'E', e);
        }
        *q = '\0';
    }
    f = open_fixture("numbers.asc", &path);
    fprintf(f, "ncols %d\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n", N / 2);
    for (i = 0; i < N; i++)
        fprintf(f, "%s%s", tok[i], (i + 1) % (N / 2) == 0 ? "\n" : " ");
    fclose(f);
    if (!expect_ok(path, &t, N / 2, 2, "numbers file"))
        return;
    for (i = 0; i < N; i++) {
        /* file row 0 (north) is grid row 1 */
        const int row = i < N / 2 ? 1 : 0, col = i % (N / 2);
        const double got = t.z[row * (N / 2) + col], want = strtod(tok[i], NULL);
        if (memcmp(&got, &want, sizeof got) != 0 && bad++ < 5)
            CHECK(0, "'%s' read as %.17g, strtod gives %.17g", tok[i], got, want);
    }
    CHECK(bad == 0, "%d of %d values differ from strtod's", bad, N);
    terrain_free(&t);
}

/* Writes the header and, on line 6, "0 0 ... 0 " (a first "00" if needed)
 * up to byte offset `to` of the file; returns the number of values written.
 * The header says ncols = nc, nrows = 2. */
static long pad_to(FILE *f, long nc, long to)
{
    long k = 0, at = fprintf(f, "ncols %ld\r\nnrows 2\r\nxllcorner 0\r\nyllcorner 0\r\ncellsize 1\r\n", nc);
    if ((to - at) % 2 != 0) at += fprintf(f, "00 "), k++;
    while (at < to) at += fprintf(f, "0 "), k++;
    return k;
}

/* The reader takes the file in blocks of 16384 bytes: a CR LF split
 * between two blocks is one line end, and a token split between them is
 * one token (here one with a NUL byte in it, which is never a number). */
static void test_block_boundaries(void)
{
    const long block = 16384, nc = 9000;
    const char *path;
    char frag[128];
    FILE *f;
    Terrain t;
    long i, k;
    int bad;

    /* line 6 ends "... 0 1\r\n" with its CR the last byte of the first
     * block; then one value per line, the last one "x" in the second file */
    for (bad = 0; bad < 2; bad++) {
        f = open_fixture(bad ? "crlf_block_bad.asc" : "crlf_block.asc", &path);
        k = pad_to(f, nc, block - 2) + 1;
        fputs("1\r\n", f);
        for (i = k; i < 2 * nc; i++) fputs(bad && i == 2 * nc - 1 ? "x\r\n" : "3\r\n", f);
        fclose(f);
        if (bad) {
            snprintf(frag, sizeof frag, "line %ld, value 1", 6 + 2 * nc - k);
            expect_fail("crlf_block_bad.asc", NULL, frag, "'x'");
        } else if (expect_ok(path, &t, (int)nc, 2, "CR LF across blocks")) {
            CHECK(t.z[nc + k - 2] == 0 && t.z[nc + k - 1] == 1 && t.z[nc + k] == 3, "CR LF across blocks: values");
            terrain_free(&t);
        }
    }

    /* a 200-byte token "1...1<NUL>1...1" on line 6 whose NUL is the first
     * byte of the second block */
    f = open_fixture("nul_block.asc", &path);
    k = pad_to(f, nc, block - 100);
    for (i = 0; i < 100; i++) fputc('1', f);
    fputc('\0', f);
    for (i = 0; i < 99; i++) fputc('1', f);
    fputs(" 9\r\n", f);
    fclose(f);
    snprintf(frag, sizeof frag, "line 6, value %ld on the line (grid row 1, column %ld)", k + 1, k + 1);
    expect_fail("nul_block.asc", NULL, frag, "is not a number");
}

/* A grid of 37 x 40 tokens for test_token_ends into text: token i is
 * 1 + (7 i + i / 37) % 36 bytes long (so that the reader's windows of 32
 * bytes end at every place in them, and some tokens fill one), a digit,
 * a signed digit or [-]d.ddd, with random digits; between tokens mostly a
 * space, else two spaces, a tab or a space and a tab; lines end in LF or
 * CR LF in turn.  Token `bad` (unless -1) is `bad_tok` instead.  Copies
 * the tokens into tok; returns the text's length. */
enum { ENDS_NC = 37, ENDS_NR = 40, ENDS_N = ENDS_NC * ENDS_NR, ENDS_TOK = 40 };
static size_t token_ends_grid(char *text, char tok[][ENDS_TOK], int bad, const char *bad_tok)
{
    static const char *const seps[] = {"  ", "\t", " \t"};
    char *q = text + sprintf(text, "ncols %d\nnrows %d\nxllcorner 0\nyllcorner 0\ncellsize 1\n", ENDS_NC, ENDS_NR);
    int i, k;

    rng_state = 0x2545F4914F6CDD1DULL;
    for (i = 0; i < ENDS_N; i++) {
        const int len = 1 + (7 * i + i / ENDS_NC) % 36;
        char *t = tok[i];
        if (len == 1) {
            t[0] = (char)('0' + (int)urand(0, 10)), t[1] = '\0';
        } else if (len == 2) {
            t[0] = '-', t[1] = (char)('0' + (int)urand(0, 10)), t[2] = '\0';
        } else {
            const int neg = len > 3 && urand(0, 1) < 0.4;
            k = 0;
            if (neg) t[k++] = '-';
            t[k++] = urand(0, 1) < 0.7 ? '0' : (char)('1' + (int)urand(0, 9));
            t[k++] = '.';
            while (k < len) t[k++] = (char)('0' + (int)urand(0, 10));
            t[k] = '\0';
        }
        q += sprintf(q, "%s", i == bad ? bad_tok : t);
        if ((i + 1) % ENDS_NC == 0) {
            q += sprintf(q, "%s", (i / ENDS_NC) % 2 ? "\r\n" : "\n");
        } else {
            const double r = urand(0, 1);
            q += sprintf(q, "%s", r < 0.8 ? " " : seps[(int)((r - 0.8) / 0.2 * 3)]);
        }
    }
    return (size_t)(q - text);
}

/* Where the values end: the reader's quick path finds the ends of the
 * tokens before it reads their values (in windows of 32 bytes, with SSE2)
 * and takes a value only where both agree.  Tokens of 1 to 36 bytes
 * between spaces, tabs and line ends are read as strtod reads them; a
 * token that runs on after a number, at each of 40 places in turn, is
 * reported at its line and place on the line. */
static void test_token_ends(void)
{
    static const char *const bad_toks[] = {"0.25x", "-0.5.5", "7:", "0.125-", "1.0000000000000000000000000000000!"};
    static char text[ENDS_N * (ENDS_TOK + 2) + 256];
    static char tok[ENDS_N][ENDS_TOK];
    const char *path;
    char frag1[128], frag2[64];
    Terrain t;
    int i, bad = 0;

    token_ends_grid(text, tok, -1, NULL);
    path = write_fixture("token_ends.asc", text);
    if (expect_ok(path, &t, ENDS_NC, ENDS_NR, "token ends")) {
        for (i = 0; i < ENDS_N; i++) {
            /* file row 0 (north) is the grid's last row */
            const int row = ENDS_NR - 1 - i / ENDS_NC, col = i % ENDS_NC;
            const double got = t.z[row * ENDS_NC + col], want = strtod(tok[i], NULL);
            if (memcmp(&got, &want, sizeof got) != 0 && bad++ < 5)
                CHECK(0, "token ends: '%s' read as %.17g, strtod gives %.17g", tok[i], got, want);
        }
        CHECK(bad == 0, "token ends: %d of %d values differ from strtod's", bad, ENDS_N);
        terrain_free(&t);
    }
    for (i = 0; i < 40; i++) {
        const int b = ENDS_NC + i;
        const char *bt = bad_toks[i % 5];
        token_ends_grid(text, tok, b, bt);
        snprintf(frag1, sizeof frag1, "line %d, value %d on the line (grid row %d, column %d)",
                 6 + b / ENDS_NC, b % ENDS_NC + 1, b / ENDS_NC + 1, b % ENDS_NC + 1);
        snprintf(frag2, sizeof frag2, "'%s' is not a number", bt);
        expect_fail("token_ends_bad.asc", text, frag1, frag2);
    }
}

/* ---------------------------------------------------------------- */
/* 8. terrain_free                                                   */
/* ---------------------------------------------------------------- */

static void test_free(void)
{
    Terrain t;
    terrain_init_flat(&t);
    terrain_free(&t);
    CHECK(is_flat(&t), "free of flat terrain");
    terrain_free(&t);
    CHECK(is_flat(&t), "second free");
    terrain_free(NULL);
    CHECK(terrain_height(&t, 1.0, 2.0) == 0.0, "freed terrain not flat");
}

/* terrain_height_normal is terrain_height and terrain_normal at once: the
 * same numbers bit for bit everywhere (inside, in the cells along every
 * edge, on nodes, outside, NaN), so the model may use either. */
static int same_double(double a, double b) { return (isnan(a) && isnan(b)) || a == b; }

static void test_height_normal_at_once(void)
{
    const double x0 = 1.0, y0 = -2.0, cell = 0.1, x1 = x0 + 9 * cell, y1 = y0 + 7 * cell;
    const char *path = write_surface("at_once.asc", 10, 8, x0, y0, cell, quad_fn, NULL);
    char err[512];
    Terrain t;
    int k, mismatches = 0;

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "at-once load failed: %s", err);
    for (k = 0; k < 3000; k++) {
        double x, y, n[3], na[3], h, ha;
        if (k < 1000) {                          /* anywhere, a margin outside included */
            x = urand(x0 - 0.3, x1 + 0.3);
            y = urand(y0 - 0.3, y1 + 0.3);
        } else if (k < 2000) {                   /* in the two rows of cells along each edge */
            x = k % 4 == 0 ? urand(x0, x0 + 2 * cell) : k % 4 == 1 ? urand(x1 - 2 * cell, x1) : urand(x0, x1);
            y = k % 4 == 2 ? urand(y0, y0 + 2 * cell) : k % 4 == 3 ? urand(y1 - 2 * cell, y1) : urand(y0, y1);
        } else if (k < 2980) {                   /* on nodes */
            x = x0 + (k % 10) * cell;
            y = y0 + ((k / 10) % 8) * cell;
        } else {                                 /* NaN */
            x = k % 2 ? NAN : 1.2;
            y = k % 2 ? -1.5 : NAN;
        }
        h = terrain_height(&t, x, y);
        terrain_normal(&t, x, y, n);
        ha = terrain_height_normal(&t, x, y, na);
        if (!same_double(h, ha) || !same_double(n[0], na[0]) || !same_double(n[1], na[1]) ||
            !same_double(n[2], na[2]))
            mismatches++;
    }
    CHECK(mismatches == 0, "terrain_height_normal differs from terrain_height/terrain_normal at %d of 3000 points",
          mismatches);
    terrain_free(&t);
    {
        double n[3];
        terrain_init_flat(&t);
        CHECK(terrain_height_normal(&t, 3.0, 4.0, n) == 0.0 && n[0] == 0.0 && n[1] == 0.0 && n[2] == 1.0,
              "flat ground: height and normal (%g %g %g)", n[0], n[1], n[2]);
    }
}

/* terrain_heights_normals gives each point terrain_height_normal's values
 * bit for bit, on a grid (inside, along its edges, outside, NaN) and on
 * flat ground. */
static void test_several_points_at_once(void)
{
    enum { POINTS = 2000 };
    const double x0 = 1.0, y0 = -2.0, cell = 0.1, x1 = x0 + 9 * cell, y1 = y0 + 7 * cell;
    const char *path = write_surface("several.asc", 10, 8, x0, y0, cell, quad_fn, NULL);
    static double xy[POINTS][3], z[POINTS], n[POINTS][3];
    char err[512];
    Terrain t;
    int k;

    CHECK(terrain_load(&t, path, err, sizeof err) == 0, "several-points load failed: %s", err);
    for (k = 0; k < POINTS; k++) {
        xy[k][0] = k < 1990 ? urand(x0 - 0.3, x1 + 0.3) : k % 2 ? NAN : 1.2;
        xy[k][1] = k < 1990 ? urand(y0 - 0.3, y1 + 0.3) : k % 2 ? -1.5 : NAN;
        xy[k][2] = 0.0;
    }
    for (int flat = 0; flat < 2; flat++) {
        int mismatches = 0;
        if (flat) {
            terrain_free(&t);
            terrain_init_flat(&t);
        }
        for (k = 0; k < POINTS; k += 4)                 /* in fours, as the rover's hubs */
            terrain_heights_normals(&t, 4, (const double (*)[3])&xy[k], &z[k], &n[k]);
        for (k = 0; k < POINTS; k++) {
            double one[3];
            const double h = terrain_height_normal(&t, xy[k][0], xy[k][1], one);
            if (!same_double(h, z[k]) || !same_double(one[0], n[k][0]) || !same_double(one[1], n[k][1]) ||
                !same_double(one[2], n[k][2]))
                mismatches++;
        }
        CHECK(mismatches == 0, "%s: terrain_heights_normals differs from terrain_height_normal at %d of %d points",
              flat ? "flat ground" : "grid", mismatches, POINTS);
    }
}

/* The fingerprint tells grids apart by any one elevation: a change of any single bit of any
 * elevation, whichever of the hash's lanes the node falls in and in the tail of a grid whose node
 * count is not a multiple of them, changes it; the same elevations and placement give the same
 * fingerprint, and so does a copy of the grid in other memory. */
static void test_fingerprint_sees_every_elevation(void)
{
    enum { NC = 7, NR = 3 };                          /* 21 nodes: five rows of four lanes and a tail */
    double z[NC * NR], copy[NC * NR];
    for (int k = 0; k < NC * NR; ++k) z[k] = copy[k] = urand(-0.5, 0.5);
    Terrain t = {NC, NR, 1.0, 2.0, 0.05, z}, u = {NC, NR, 1.0, 2.0, 0.05, copy};
    const uint64_t h = terrain_fingerprint(&t);
    CHECK(terrain_fingerprint(&u) == h, "the same elevations in other memory: another fingerprint");
    int unchanged = 0;
    for (int k = 0; k < NC * NR; ++k)
        for (int bit = 0; bit < 64; ++bit) {
            uint64_t w;
            memcpy(&w, &z[k], sizeof w);
            w ^= 1ull << bit;
            memcpy(&z[k], &w, sizeof w);
            if (terrain_fingerprint(&t) == h) {
                if (unchanged++ < 5) CHECK(0, "node %d, bit %d flipped: the same fingerprint", k, bit);
            }
            w ^= 1ull << bit;
            memcpy(&z[k], &w, sizeof w);
        }
    CHECK(unchanged == 0, "%d single-bit changes of an elevation left the fingerprint as it was", unchanged);
    CHECK(terrain_fingerprint(&t) == h, "the elevations restored: another fingerprint");
    Terrain moved = t;
    moved.x0 += 0.05;
    CHECK(terrain_fingerprint(&moved) != h, "the grid moved by a cell: the same fingerprint");
    Terrain flat;
    terrain_init_flat(&flat);
    CHECK(terrain_fingerprint(&flat) != h, "flat ground has the grid's fingerprint");
}

int main(int argc, char **argv)
{
    const char *base = argc > 1 ? argv[1] : "/tmp";
    snprintf(scratch, sizeof scratch, "%s/test_terrain_XXXXXX", base);
    if (mkdtemp(scratch) == NULL) {
        perror(scratch);
        return 2;
    }

    test_plane();
    test_slope15();
    test_corner_center();
    test_mound();
    test_outside_and_flat();
    test_height_normal_at_once();
    test_several_points_at_once();
    test_nodata();
    test_nodata_near_double_range();
    test_bad_files();
    test_not_regular_files();
    test_err_buffer();
    test_odd_but_valid();
    test_numbers_match_strtod();
    test_block_boundaries();
    test_token_ends();
    test_free();
    test_fingerprint_sees_every_elevation();

    remove_fixtures();
    printf("%d passed, %d failed\n", n_pass, n_fail);
    return n_fail != 0;
}
