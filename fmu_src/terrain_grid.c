/*
 * Terrain grid: the queries on a loaded grid or flat ground (see
 * terrain.h).  Pure, allocation-free and thread-safe on a const Terrain.
 *
 * Grid convention: node (col i, row j) sits at the centre of its cell,
 * x = x0 + i*cell, y = y0 + j*cell, with row 0 the southernmost row.
 */
#include "terrain.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void terrain_init_flat(Terrain *t)
{
    t->ncols = t->nrows = 0;
    t->x0 = t->y0 = 0.0;
    t->cell = 0.0;
    t->z = NULL;
}

void terrain_free(Terrain *t)
{
    if (t == NULL)
        return;
    free(t->z);
    terrain_init_flat(t);
}

#define FNV_PRIME 1099511628211ull

static uint64_t fnv1a_more(uint64_t h, const void *data, size_t n)
{
    const unsigned char *bytes = (const unsigned char *)data;
    for (size_t i = 0; i < n; ++i) {
        h ^= bytes[i];
        h *= FNV_PRIME;
    }
    return h;
}

/* The elevations' share of the fingerprint: FNV-1a's step (xor, multiply by its prime) on whole
 * 64-bit words, each word then folded down (h ^= h >> 29) so that its high bits reach the low
 * bits of the next product, in four lanes side by side.  A byte at a time, one multiplication
 * waits for the one before: about 1.9 ms of CPU for a 901 x 231 grid, against 0.15 ms. */
static uint64_t words_fingerprint(uint64_t h, const double *z, size_t n)
{
    enum { LANES = 4 };
    uint64_t lane[LANES];
    for (int l = 0; l < LANES; ++l) lane[l] = h ^ (uint64_t)(l + 1);
    size_t k = 0;
    for (; k + LANES <= n; k += LANES)
        for (int l = 0; l < LANES; ++l) {
            uint64_t w;
            memcpy(&w, &z[k + (size_t)l], sizeof w);
            lane[l] = (lane[l] ^ w) * FNV_PRIME;
            lane[l] ^= lane[l] >> 29;
        }
    for (; k < n; ++k) {
        uint64_t w;
        memcpy(&w, &z[k], sizeof w);
        lane[0] = (lane[0] ^ w) * FNV_PRIME;
        lane[0] ^= lane[0] >> 29;
    }
    return fnv1a_more(h, lane, sizeof lane);
}

uint64_t terrain_fingerprint(const Terrain *t)
{
    uint64_t h = 1469598103934665603ull;
    h = fnv1a_more(h, &t->ncols, sizeof t->ncols);
    h = fnv1a_more(h, &t->nrows, sizeof t->nrows);
    h = fnv1a_more(h, &t->x0, sizeof t->x0);
    h = fnv1a_more(h, &t->y0, sizeof t->y0);
    h = fnv1a_more(h, &t->cell, sizeof t->cell);
    if (t->z) h = words_fingerprint(h, t->z, (size_t)t->ncols * (size_t)t->nrows);
    return h;
}

/* Maps a coordinate to the grid interval [k, k+1] holding it and the
 * fraction f in [0, 1] within it, after clamping to the grid extent (so
 * edge values extend flat outside).  NaN is mapped to the first node only
 * to keep the integer conversion defined; callers handle NaN themselves. */
static void locate(double q, double q0, double cell, int n, int *k, double *f)
{
    double u = (q - q0) / cell;
    int i;
    if (!(u > 0.0))
        u = 0.0;
    else if (u > (double)(n - 1))
        u = (double)(n - 1);
    i = (int)u;
    if (i > n - 2)
        i = n - 2;
    *k = i;
    *f = u - (double)i;
}

/* The bilinear elevation in cell (i, j) at fractions (fx, fy). */
static double height_in_cell(const Terrain *t, int i, int j, double fx, double fy)
{
    const double *z = t->z;
    const size_t nc = (size_t)t->ncols;
    const size_t r0 = (size_t)j * nc + (size_t)i, r1 = r0 + nc;
    return (1.0 - fy) * ((1.0 - fx) * z[r0] + fx * z[r0 + 1])
         + fy * ((1.0 - fx) * z[r1] + fx * z[r1 + 1]);
}

double terrain_height(const Terrain *t, double x, double y)
{
    int i, j;
    double fx, fy;

    if (t->ncols == 0)
        return 0.0;
    if (isnan(x) || isnan(y))
        return NAN; /* a NaN position is an upstream bug: propagate, don't hide */
    locate(x, t->x0, t->cell, t->ncols, &i, &fx);
    locate(y, t->y0, t->cell, t->nrows, &j, &fy);
    return height_in_cell(t, i, j, fx, fy);
}

/* Elevation gradient at node (i, j): central differences inside, one-sided
 * at the edges (the grid has at least 2 nodes each way). */
static void node_gradient(const Terrain *t, int i, int j, double *gx, double *gy)
{
    const size_t nc = (size_t)t->ncols;
    const double *row = t->z + (size_t)j * nc;
    const int il = i > 0 ? i - 1 : i, ir = i < t->ncols - 1 ? i + 1 : i;
    const int jl = j > 0 ? j - 1 : j, jr = j < t->nrows - 1 ? j + 1 : j;
    *gx = (row[ir] - row[il]) / ((double)(ir - il) * t->cell);
    *gy = (t->z[(size_t)jr * nc + (size_t)i] - t->z[(size_t)jl * nc + (size_t)i])
        / ((double)(jr - jl) * t->cell);
}

int terrain_outside(const Terrain *t, double x, double y)
{
    if (t->ncols == 0)
        return 0;
    return x < t->x0 || x > t->x0 + (double)(t->ncols - 1) * t->cell ||
           y < t->y0 || y > t->y0 + (double)(t->nrows - 1) * t->cell;
}

/* The normal in cell (i, j) at fractions (fx, fy) of a point inside the
 * grid: the bilinear interpolation of the central-difference gradients at
 * the cell's four nodes.  Away from the grid's edge every node has both
 * neighbours, and the gradients are the same differences without the
 * clamping of node_gradient. */
static void normal_in_cell(const Terrain *t, int i, int j, double fx, double fy, double n[3])
{
    double gx00, gy00, gx10, gy10, gx01, gy01, gx11, gy11, gx, gy, s;

    if (i > 0 && i + 2 < t->ncols && j > 0 && j + 2 < t->nrows) {
        const size_t nc = (size_t)t->ncols;
        const double *z0 = t->z + (size_t)j * nc + (size_t)i, *z1 = z0 + nc;   /* nodes (i, j), (i, j + 1) */
        const double d = 2.0 * t->cell;                  /* (ir - il) cell, (jr - jl) cell */
        gx00 = (z0[1] - z0[-1]) / d;
        gy00 = (z1[0] - z0[-(ptrdiff_t)nc]) / d;
        gx10 = (z0[2] - z0[0]) / d;
        gy10 = (z1[1] - z0[1 - (ptrdiff_t)nc]) / d;
        gx01 = (z1[1] - z1[-1]) / d;
        gy01 = (z1[nc] - z0[0]) / d;
        gx11 = (z1[2] - z1[0]) / d;
        gy11 = (z1[nc + 1] - z0[1]) / d;
    } else {
        node_gradient(t, i, j, &gx00, &gy00);
        node_gradient(t, i + 1, j, &gx10, &gy10);
        node_gradient(t, i, j + 1, &gx01, &gy01);
        node_gradient(t, i + 1, j + 1, &gx11, &gy11);
    }
    gx = (1.0 - fy) * ((1.0 - fx) * gx00 + fx * gx10) + fy * ((1.0 - fx) * gx01 + fx * gx11);
    gy = (1.0 - fy) * ((1.0 - fx) * gy00 + fx * gy10) + fy * ((1.0 - fx) * gy01 + fx * gy11);
    if (fabs(gx) <= 1e150 && fabs(gy) <= 1e150) {
        s = 1.0 / sqrt(gx * gx + gy * gy + 1.0);
        n[0] = -gx * s;
        n[1] = -gy * s;
        n[2] = s;
    } else {
        /* slopes whose squares overflow (elevations near the limits of a
         * double, found by fuzzing): normalise (-gx, -gy, 1) scaled by its
         * largest component, so the normal stays a unit vector pointing up.
         * An infinite gradient (the difference of two elevations overflowed)
         * leaves NaN, which the model reports as a diverged state. */
        const double m = fmax(fabs(gx), fabs(gy));
        const double a = gx / m, b = gy / m, c = 1.0 / m;
        s = 1.0 / sqrt(a * a + b * b + c * c);
        n[0] = -a * s;
        n[1] = -b * s;
        n[2] = c * s;
    }
}

void terrain_normal(const Terrain *t, double x, double y, double n[3])
{
    int i, j;
    double fx, fy;

    if (t->ncols == 0) {
        n[0] = 0.0, n[1] = 0.0, n[2] = 1.0;
        return;
    }
    if (isnan(x) || isnan(y)) {
        n[0] = n[1] = n[2] = NAN;
        return;
    }
    if (terrain_outside(t, x, y)) {
        n[0] = 0.0, n[1] = 0.0, n[2] = 1.0;
        return;
    }
    locate(x, t->x0, t->cell, t->ncols, &i, &fx);
    locate(y, t->y0, t->cell, t->nrows, &j, &fy);
    normal_in_cell(t, i, j, fx, fy, n);
}

double terrain_height_normal(const Terrain *t, double x, double y, double n[3])
{
    int i, j;
    double fx, fy;

    if (t->ncols == 0) {
        n[0] = 0.0, n[1] = 0.0, n[2] = 1.0;
        return 0.0;
    }
    if (isnan(x) || isnan(y)) {
        n[0] = n[1] = n[2] = NAN;
        return NAN;
    }
    locate(x, t->x0, t->cell, t->ncols, &i, &fx);
    locate(y, t->y0, t->cell, t->nrows, &j, &fy);
    if (terrain_outside(t, x, y)) {
        n[0] = 0.0, n[1] = 0.0, n[2] = 1.0;
    } else {
        normal_in_cell(t, i, j, fx, fy, n);
    }
    return height_in_cell(t, i, j, fx, fy);
}

void terrain_heights_normals(const Terrain *t, int count, const double (*xy)[3], double *z, double (*n)[3])
{
    /* On a grid, from a copy of its description: the normals' stores cannot
     * change it, so its fields and the grid's extent stay in registers from
     * one point to the next instead of being read and computed again.  Flat
     * ground needs no fields, and its lookups cost less than the copy. */
    if (t->ncols == 0) {
        for (int k = 0; k < count; ++k) z[k] = terrain_height_normal(t, xy[k][0], xy[k][1], n[k]);
        return;
    }
    const Terrain g = *t;
    for (int k = 0; k < count; ++k) z[k] = terrain_height_normal(&g, xy[k][0], xy[k][1], n[k]);
}
