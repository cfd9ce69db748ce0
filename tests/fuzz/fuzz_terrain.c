/*
 * libFuzzer target: the ESRI ASCII terrain grid reader (terrain_read on a
 * memory stream, the code path of terrain_load).  Every input must either
 * load into a grid that answers height and normal queries with finite
 * values, or be refused with a message while leaving flat ground.
 *
 *   fuzz_terrain tests/fuzz/corpus_terrain -max_total_time=20
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "terrain.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    /* fmemopen needs a non-empty buffer it may treat as writable */
    unsigned char *copy = (unsigned char *)malloc(size + 1);
    if (!copy) return 0;
    if (size) memcpy(copy, data, size);
    copy[size] = 0;
    FILE *f = size ? fmemopen(copy, size, "rb") : fmemopen(copy, 1, "rb");
    if (!f) {
        free(copy);
        return 0;
    }
    if (!size) fgetc(f);   /* an empty stream */
    Terrain t;
    char err[512];
    memset(err, 'x', sizeof err);
    int r = terrain_read(&t, f, "fuzz.asc", err, sizeof err);
    fclose(f);
    if (memchr(err, '\0', sizeof err) == NULL) abort();   /* the message is always terminated */
    if (r != 0) {
        if (err[0] == '\0' || t.ncols != 0 || t.z != NULL) abort();   /* refused: explained, flat */
    } else {
        if (t.ncols < 2 || t.nrows < 2 || !(t.cell > 0) || !t.z) abort();
        for (size_t k = 0; k < (size_t)t.ncols * (size_t)t.nrows; ++k)
            if (!isfinite(t.z[k])) abort();
        /* queries inside, on the edges and far outside the grid */
        const double w = t.cell * (t.ncols - 1), h = t.cell * (t.nrows - 1);
        const double xs[] = {t.x0, t.x0 + 0.37 * w, t.x0 + w, t.x0 - 1e9, t.x0 + w + 1e9};
        const double ys[] = {t.y0, t.y0 + 0.61 * h, t.y0 + h, t.y0 - 1e300, t.y0 + 1e300};
        for (size_t i = 0; i < sizeof xs / sizeof xs[0]; ++i)
            for (size_t j = 0; j < sizeof ys / sizeof ys[0]; ++j) {
                double n[3], z = terrain_height(&t, xs[i], ys[j]);
                terrain_normal(&t, xs[i], ys[j], n);
                /* elevations are finite; the normal is a unit vector pointing up,
                 * or NaN when a gradient overflowed to infinity (elevation
                 * differences beyond the double range) */
                if (!isfinite(z)) abort();
                if (!isnan(n[0]) || !isnan(n[1]) || !isnan(n[2])) {
                    const double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
                    if (!(n[2] > 0) || !(fabs(len - 1.0) < 1e-12)) abort();
                }
            }
        terrain_free(&t);
        if (t.ncols != 0 || t.z != NULL) abort();
    }
    free(copy);
    return 0;
}
