/*
 * Terrain: flat ground (z = 0) or an ESRI ASCII elevation grid.
 * The grid is read once (allocation happens only in terrain_load);
 * queries are pure, allocation-free and thread-safe on a const Terrain.
 */
#ifndef JUNO_TERRAIN_H
#define JUNO_TERRAIN_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

typedef struct {
    int ncols, nrows;       /* 0 for flat ground */
    double x0, y0;          /* world position of the centre of cell (col 0, row 0 = southernmost) */
    double cell;            /* m */
    double *z;              /* nrows*ncols, row-major from south (row 0) to north */
} Terrain;

/* Flat ground. */
void terrain_init_flat(Terrain *t);

/* Reads an ESRI ASCII grid (.asc): header keys ncols, nrows,
 * xllcorner|xllcenter, yllcorner|yllcenter, cellsize, optional
 * NODATA_value (case-insensitive), then nrows lines of ncols numbers from
 * north to south.  NODATA cells are filled from valid neighbours.
 * Returns 0, or -1 with a message naming the file and line written to err
 * (missing/unreadable file, a path that is not a regular file (a
 * directory, a device, a FIFO: refused before it is opened), bad header,
 * non-numeric value, too few/many values, non-finite value, grid smaller
 * than 2x2, all NODATA).
 * *t is overwritten, not freed (it may be uninitialised): call
 * terrain_free first if it holds a grid.  On error *t is flat ground. */
int terrain_load(Terrain *t, const char *path, char *err, size_t errlen);

/* The same from a stream open for reading (in binary mode), read from its
 * current position to its end and not closed; name stands for the file in
 * messages (NULL: "(stream)").  For grids held in memory (fmemopen) and
 * the fuzz target. */
int terrain_read(Terrain *t, FILE *f, const char *name, char *err, size_t errlen);

void terrain_free(Terrain *t);

/* A 64-bit hash (FNV-1a; the elevations a 64-bit word at a time) of the grid's size, placement
 * and elevations: equal for the same ground read from any path, different (but for a hash
 * collision) for other ground; flat ground has its own. */
uint64_t terrain_fingerprint(const Terrain *t);

/* Elevation (m) and unit upward surface normal at (x, y).  Inside the
 * grid (the rectangle of its nodes, edges included) the elevation is
 * bilinear and the normal comes from the bilinear interpolation of
 * central-difference gradients at the nodes, so both are continuous there.
 * Outside it nothing is known of the ground, and it is taken as level:
 * the normal is exactly (0, 0, 1) and the elevation that of the nearest
 * point of the grid's edge (clamped coordinates).  Crossing the edge, the
 * elevation is continuous (no step) but the normal jumps from the edge's
 * slope to vertical (a kink).  Beside a side of the grid the clamped
 * elevation still follows the edge's profile along that side while the
 * normal is vertical: the level ground outside is level across the edge,
 * the profile along it only keeps the surface free of steps.  A reader
 * (or a rover) beyond a tilted grid stands on flat ground. */
double terrain_height(const Terrain *t, double x, double y);
void terrain_normal(const Terrain *t, double x, double y, double n[3]);
/* Both at once (one lookup of the cell): the elevation, and the normal into n. */
double terrain_height_normal(const Terrain *t, double x, double y, double n[3]);
/* terrain_height_normal at count points (x, y: the first two of each xy[k]) into z[k] and n[k]. */
void terrain_heights_normals(const Terrain *t, int count, const double (*xy)[3], double *z, double (*n)[3]);

/* 1 if (x, y) lies outside the grid's nodes (0 for flat ground and NaN). */
int terrain_outside(const Terrain *t, double x, double y);

#endif
