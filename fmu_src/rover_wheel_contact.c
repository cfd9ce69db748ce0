/*
 * The wheels' contacts with the soil (rover_internal.h): each wheel's
 * contact frame on the terrain, the rover's kinematics at the contact, and
 * the generalised force, damping and stiffness for the linearly implicit
 * integrator, the four wheels computed in phases side by side
 * (rover_wheel_contacts).  The force law itself (slip, normal force and
 * tilt from the volumetric or Wong-Reece law, shear, slip-sinkage,
 * grousers) is wheel_soil.c's, shared with the single-wheel rig.  The model
 * extensions that depend on where the wheel is live here: the soil patch,
 * the multi-pass rut and the terrain registration offsets.
 */
#include <math.h>

#include "rover_internal.h"

/* Wheel Jacobians are mostly zeros and ones, and the hot loop (four
 * contacts per evaluation) works only with their structural non-zeros.
 * For a wheel on side `side` (spin column sp = U_SPIN_L + side):
 *   point rows J (hub: point_jacobian; rim point: + add_wheel_offset):
 *     [1 | -[r]x | c | spin column (0 at the hub) | other spin 0],
 *     the diagonal of the -[r]x block exactly 0;
 *   angular rows Jw: [0 | 1 | sigma e | e in column sp | 0].
 * Each function below adds the non-zero products in the order the dense
 * loop over all NU columns (rows) would, and a product with an exact 0 or
 * 1 changes nothing in IEEE arithmetic (x + 0 * y = x, 1 * y = y for finite
 * y), so the results are the dense loops' bit for bit (up to the sign of
 * an exact zero); bench_fmu --compare checks this against the dense build. */

/* The point Jacobian J of a point on a wheel body (offset r from its hub)
 * from the hub's Jh: Jh plus -[r]x times the wheel's angular Jacobian, in
 * the columns where Jw is not zero (the angular rates, the rocker rate and
 * this wheel's spin), the only columns written: the others are the hub's
 * (the identity of the velocity columns, the other spin's 0), which
 * point_vecs_times_jac takes as known and does not read, so they are not
 * copied.  Jw's angular-rate columns are the identity, so their products
 * are the entries of r (-[r]x's off-diagonal; the diagonal stays the hub's
 * exact 0), and the hub's spin column is 0, so the spin column is the
 * product alone: the same values (up to the sign of an exact zero) without
 * the products with 0 and 1. */
static void offset_point_jacobian(double J[3][NU], double Jh[3][NU], double Jw[3][NU], const double r[3], int sp)
{
    J[0][U_WX + 0] = Jh[0][U_WX + 0];
    J[1][U_WX + 0] = Jh[1][U_WX + 0] - r[2];
    J[2][U_WX + 0] = Jh[2][U_WX + 0] + r[1];
    J[0][U_WX + 1] = Jh[0][U_WX + 1] + r[2];
    J[1][U_WX + 1] = Jh[1][U_WX + 1];
    J[2][U_WX + 1] = Jh[2][U_WX + 1] - r[0];
    J[0][U_WX + 2] = Jh[0][U_WX + 2] - r[1];
    J[1][U_WX + 2] = Jh[1][U_WX + 2] + r[0];
    J[2][U_WX + 2] = Jh[2][U_WX + 2];
    double wb[3] = {Jw[0][U_BETA], Jw[1][U_BETA], Jw[2][U_BETA]}, ws[3] = {Jw[0][sp], Jw[1][sp], Jw[2][sp]};
    double cb[3], cs[3];
    v3_cross(cb, wb, r);
    v3_cross(cs, ws, r);
    for (int i = 0; i < 3; ++i) {
        J[i][U_BETA] = Jh[i][U_BETA] + cb[i];
        J[i][sp] = cs[i];
    }
}

/* Row i of a hub's point Jacobian (structure above, its spin columns
 * exact zeros, so without their terms) times u. */
static inline double hub_row_dot(double J[3][NU], int i, const double u[NU])
{
    double s = u[U_VX + i];
    for (int j = 0; j < 3; ++j)
        if (j != i) s += J[i][U_WX + j] * u[U_WX + j];
    return s + J[i][U_BETA] * u[U_BETA];
}

/* Row i of an angular wheel Jacobian times u. */
static inline double angular_row_dot(double Jw[3][NU], int i, const double u[NU], int sp)
{
    return u[U_WX + i] + Jw[i][U_BETA] * u[U_BETA] + Jw[i][sp] * u[sp];
}

/* a[v]^T J for three vectors a[v] and a point Jacobian J, each a row of NU
 * (the other spin column 0) into out[v], reading the entries of J once.
 * at_hub (a constant where it is inlined): J is a hub's, whose spin
 * columns are exact zeros, so the row's spin entry is 0 without its
 * products (up to the sign of an exact zero). */
static inline void point_vecs_times_jac(double out[3][NU], const double *const a[3], double J[3][NU], int sp,
                                        int at_hub)
{
    const double j13 = J[1][U_WX + 0], j23 = J[2][U_WX + 0], j04 = J[0][U_WX + 1], j24 = J[2][U_WX + 1];
    const double j05 = J[0][U_WX + 2], j15 = J[1][U_WX + 2];
    const double j0b = J[0][U_BETA], j1b = J[1][U_BETA], j2b = J[2][U_BETA];
    const double j0s = J[0][sp], j1s = J[1][sp], j2s = J[2][sp];
    for (int v = 0; v < 3; ++v) {
        const double a0 = a[v][0], a1 = a[v][1], a2 = a[v][2];
        double *o = out[v];
        o[U_VX + 0] = a0;
        o[U_VX + 1] = a1;
        o[U_VX + 2] = a2;
        o[U_WX + 0] = a1 * j13 + a2 * j23;
        o[U_WX + 1] = a0 * j04 + a2 * j24;
        o[U_WX + 2] = a0 * j05 + a1 * j15;
        o[U_BETA] = a0 * j0b + a1 * j1b + a2 * j2b;
        o[U_SPIN_L] = o[U_SPIN_R] = 0.0;
        if (!at_hub) o[sp] = a0 * j0s + a1 * j1s + a2 * j2s;
    }
}

/* s a^T Jw for an angular wheel Jacobian and a scale s > 0: a row of NU,
 * its structural zeros written as such (s 0 is 0). */
static inline void angular_vec_times_jac(double out[NU], double s, const double a[3], double Jw[3][NU], int sp)
{
    out[U_VX + 0] = out[U_VX + 1] = out[U_VX + 2] = 0.0;
    out[U_WX + 0] = s * a[0];
    out[U_WX + 1] = s * a[1];
    out[U_WX + 2] = s * a[2];
    out[U_BETA] = s * (a[0] * Jw[0][U_BETA] + a[1] * Jw[1][U_BETA] + a[2] * Jw[2][U_BETA]);
    out[U_SPIN_L] = out[U_SPIN_R] = 0.0;
    out[sp] = s * (a[0] * Jw[0][sp] + a[1] * Jw[1][sp] + a[2] * Jw[2][sp]);
}

/* The rank-one updates of D and K below touch only the structural
 * non-zeros of their rows: columns 0..U_BETA (the chassis's six and the
 * rocker rate) and this wheel's spin column sp; the other spin column of
 * every row above is an exact 0, and adding a product with an exact 0
 * changes nothing.  Each entry gets the same products in the same order as
 * a dense loop.  The hot two (the damping pair, the volumetric stiffness)
 * update columns 0..U_SPIN_L of a row in eight explicit statements from a
 * local copy of the column factors, a form GCC turns into 2-wide vector
 * instructions (the loop form it leaves scalar), and U_SPIN_R separately. */
enum { ACTIVE = U_BETA + 1, SPAN = U_SPIN_L + 1 };

/* M += (a s) b^T over rows and columns 0..U_BETA and sp. */
static inline void add_outer(double (*restrict Mx)[NU], const double *restrict a, double s, const double *restrict b,
                             int sp)
{
    for (int n = 0; n <= ACTIVE; ++n) {
        const int i = n < ACTIVE ? n : sp;
        const double ai = a[i] * s;
        double *row = Mx[i];
        for (int j = 0; j < ACTIVE; ++j) row[j] += ai * b[j];
        row[sp] += ai * b[sp];
    }
}

/* M += (a s) b^T for rows a, b whose spin columns are both 0 (a hub's
 * point Jacobian): rows 0..U_BETA, columns 0..U_SPIN_L (b's an exact 0). */
static inline void add_outer_hub(double (*restrict Mx)[NU], const double *restrict a, double s,
                                 const double *restrict b)
{
    double bl[SPAN];
    for (int j = 0; j < SPAN; ++j) bl[j] = b[j];
    for (int i = 0; i < ACTIVE; ++i) {
        const double ai = a[i] * s;
        double *row = Mx[i];
        row[0] += ai * bl[0]; row[1] += ai * bl[1]; row[2] += ai * bl[2]; row[3] += ai * bl[3];
        row[4] += ai * bl[4]; row[5] += ai * bl[5]; row[6] += ai * bl[6]; row[7] += ai * bl[7];
    }
}

/* row -= ai b + ci d over columns 0..U_SPIN_L (each entry gets the two
 * additions in that order), from local copies of b and d. */
static inline void sub_outer_pair_row(double *restrict row, double ai, double ci, const double *bl, const double *dl)
{
    row[0] = (row[0] + ai * bl[0]) + ci * dl[0];
    row[1] = (row[1] + ai * bl[1]) + ci * dl[1];
    row[2] = (row[2] + ai * bl[2]) + ci * dl[2];
    row[3] = (row[3] + ai * bl[3]) + ci * dl[3];
    row[4] = (row[4] + ai * bl[4]) + ci * dl[4];
    row[5] = (row[5] + ai * bl[5]) + ci * dl[5];
    row[6] = (row[6] + ai * bl[6]) + ci * dl[6];
    row[7] = (row[7] + ai * bl[7]) + ci * dl[7];
}

/* M -= a^T b, then M -= c^T d, in one pass over M (each entry gets the
 * two additions in that order), over rows and columns 0..U_BETA and sp
 * (and column U_SPIN_L for a right wheel, where b and d are an exact 0):
 * rows 0..U_BETA by a loop of constant length (unrolled, with b and d in
 * registers), then row sp. */
static inline void sub_outer_pair(double (*restrict Mx)[NU], const double *restrict a, const double *restrict b,
                                  const double *restrict c, const double *restrict d, int sp)
{
    double bl[SPAN], dl[SPAN];
    for (int j = 0; j < SPAN; ++j) {
        bl[j] = b[j];
        dl[j] = d[j];
    }
    for (int i = 0; i < ACTIVE; ++i) sub_outer_pair_row(Mx[i], a[i] * -1.0, c[i] * -1.0, bl, dl);
    sub_outer_pair_row(Mx[sp], a[sp] * -1.0, c[sp] * -1.0, bl, dl);
    if (sp == U_SPIN_R)
        for (int n = 0; n <= ACTIVE; ++n) {
            const int i = n < ACTIVE ? n : sp;
            Mx[i][sp] = (Mx[i][sp] + (a[i] * -1.0) * b[sp]) + (c[i] * -1.0) * d[sp];
        }
}

/* ------------------------------------------------------ terrain, soil */

/* The tilt of the registration: the ground raised by the plane
 * slopeX x + slopeY y (world x, y) on top of height z, with the unit
 * normal n (if not NULL) turned to the tilted surface's: a surface of
 * gradient g has the normal (-g, 1) / |(-g, 1)|, so the grid's gradient is
 * -n[0..1] / n[2], and the plane adds the slopes to it. */
static double tilted(const Params *p, double x, double y, double z, double n[3])
{
    if (n) {
        const double gx = -n[0] / n[2] + p->terrain_slopeX, gy = -n[1] / n[2] + p->terrain_slopeY;
        const double inv = 1.0 / sqrt(gx * gx + gy * gy + 1.0);
        n[0] = -gx * inv;
        n[1] = -gy * inv;
        n[2] = inv;
    }
    return z + (p->terrain_slopeX * x + p->terrain_slopeY * y);
}

/* Terrain at world (x, y), with the registration extension: the grid is
 * moved by (terrain.offsetX, offsetY, offsetZ) and turned by offsetYaw
 * about the world z axis, so a grid feature at grid coordinates q appears
 * at world o + Rz(yaw) q, then tilted (terrain.slopeX, slopeY; tilted()).
 * All zero: the grid as given.  c, sn: the cosine and sine of offsetYaw
 * (used only where an offset is not zero). */
static double registered_terrain_at(const Model *m, double c, double sn, double x, double y, double n[3])
{
    const Params *p = &m->p;
    double z;
    if (p->terrain_offsetX == 0 && p->terrain_offsetY == 0 && p->terrain_offsetYaw == 0) {
        z = (n ? terrain_height_normal(&m->terrain, x, y, n) : terrain_height(&m->terrain, x, y)) + p->terrain_offsetZ;
    } else {
        const double dx = x - p->terrain_offsetX, dy = y - p->terrain_offsetY;
        const double qx = c * dx + sn * dy, qy = -sn * dx + c * dy;
        if (n) {
            double ng[3];
            z = terrain_height_normal(&m->terrain, qx, qy, ng) + p->terrain_offsetZ;
            n[0] = c * ng[0] - sn * ng[1];
            n[1] = sn * ng[0] + c * ng[1];
            n[2] = ng[2];
        } else {
            z = terrain_height(&m->terrain, qx, qy) + p->terrain_offsetZ;
        }
    }
    if (p->terrain_slopeX != 0 || p->terrain_slopeY != 0) return tilted(p, x, y, z, n);
    return z;
}

double rover_terrain_at(const Model *m, double x, double y, double n[3])
{
    const Params *p = &m->p;
    if (p->terrain_offsetX == 0 && p->terrain_offsetY == 0 && p->terrain_offsetYaw == 0)
        return registered_terrain_at(m, 1.0, 0.0, x, y, n);         /* no turn: c, sn unused */
    return registered_terrain_at(m, cos(p->terrain_offsetYaw), sin(p->terrain_offsetYaw), x, y, n);
}

/* rover_terrain_at under the four hubs (or any four points: world x, y of
 * each), the registration's checks made once for the four: on a grid
 * without registration (the common case) each lookup is the grid's own,
 * inlined (flatten: 60 fewer instructions an internal step); with one, the
 * turn's cosine and sine once for the four. */
#if defined(__GNUC__)
__attribute__((flatten))
#endif
void rover_terrain_under_wheels(const Model *m, const double (*xy)[3], double zt[NUM_WHEELS], double n[NUM_WHEELS][3])
{
    const Params *p = &m->p;
    if (p->terrain_offsetX == 0 && p->terrain_offsetY == 0 && p->terrain_offsetYaw == 0 && p->terrain_slopeX == 0 &&
        p->terrain_slopeY == 0) {
        terrain_heights_normals(&m->terrain, NUM_WHEELS, xy, zt, n);
        for (int w = 0; w < NUM_WHEELS; ++w) zt[w] += p->terrain_offsetZ;
        return;
    }
    const double c = cos(p->terrain_offsetYaw), sn = sin(p->terrain_offsetYaw);
    for (int w = 0; w < NUM_WHEELS; ++w) zt[w] = registered_terrain_at(m, c, sn, xy[w][0], xy[w][1], n[w]);
}

/* Soil-patch extension: relative stiffness and strength at (x, y), a
 * Gaussian bump of the factors towards soilPatch.* (1 everywhere when off),
 * times a band across x towards soilStrip.* (|x - soilStrip.x| below its
 * half width; the edges a logistic step of scale 12.5 mm, 10-90 % over
 * 5.5 cm, so that the forces stay smooth for the integrator). */
static void soil_factors(const Params *p, double x, double y, double *kh_factor, double *strength_factor)
{
    *kh_factor = 1.0;
    *strength_factor = 1.0;
    if (p->strip_khFactor != 1.0 || p->strip_strengthFactor != 1.0) {
        const double g = 1.0 / (1.0 + exp((fabs(x - p->strip_x) - p->strip_halfWidth) / 0.0125));
        *kh_factor = 1.0 + (p->strip_khFactor - 1.0) * g;
        *strength_factor = 1.0 + (p->strip_strengthFactor - 1.0) * g;
    }
    if (p->patch_khFactor == 1.0 && p->patch_strengthFactor == 1.0) return;
    const double dx = x - p->patch_x, dy = y - p->patch_y;
    const double g = exp(-(dx * dx + dy * dy) / (2 * p->patch_radius * p->patch_radius));
    *kh_factor *= 1.0 + (p->patch_khFactor - 1.0) * g;
    *strength_factor *= 1.0 + (p->patch_strengthFactor - 1.0) * g;
}

/* Multi-pass extension: residual rut depth that side's front wheel left at
 * forward travel `pos` (m); 0 before the start or beyond the memory.
 * Assumption: the rear wheel follows the front wheel's track one
 * wheelbase behind (straight running; on a turn it strays from the rut). */
static double rut_point(const State *s, int side, double pos)
{
    if (pos < 0 || pos < s->path[side] - (RUT_SAMPLES - 2) * RUT_SPACING || pos > s->path[side]) return 0.0;
    const double u = pos / RUT_SPACING;
    const long i = (long)floor(u);
    const double f = u - (double)i;
    return (1 - f) * s->rut[side][i % RUT_SAMPLES] + f * s->rut[side][(i + 1) % RUT_SAMPLES];  /* i >= 0 here */
}

/* Rut depth under a rear wheel at path position pos, averaged over 2 RUT_WINDOW_HALF + 1 samples.
 * Assumption: the rim bridges rut features shorter than its contact length, so
 * the wheel follows the rut's mean over about that length.  Unaveraged, the
 * step where the rut begins (the pit the front wheel sat in) and steps where
 * the front wheel's sinkage jumped kick the rear wheel like a kerb. */
static double rut_depth_at(const State *s, int side, double pos)
{
    double sum = 0;
    for (int k = -RUT_WINDOW_HALF; k <= RUT_WINDOW_HALF; ++k) sum += rut_point(s, side, pos + k * RUT_SPACING);
    return sum / (2 * RUT_WINDOW_HALF + 1);
}

/* ---------------------------------------------------- one wheel's contact */

/* Where wheel w meets the soil.  Assumption: the soil is locally a plane
 * through the terrain point below the hub; the contact is solved in the
 * wheel's mid-plane. */
typedef struct {
    double n[3];                   /* terrain normal under the hub */
    double np[3];                  /* n within the wheel's mid-plane, unit */
    double in_plane;               /* length of n within the mid-plane before normalising */
    double f[3];                   /* heading in the contact plane */
    double l[3];                   /* lateral direction, n x f */
    double v_hub[3];               /* the hub's velocity, m/s */
    double omega[3];               /* the wheel's angular velocity, rad/s (set by wheel_spin) */
} ContactFrame;

/* The contact frame, the sinkage (with a rear wheel's rut), the local soil
 * factors (1 where uniform_soil) and the forward speed into cf and in
 * (v_long also into wc), from the terrain's elevation zt and normal n under
 * the hub.
 * Returns 1 if the wheel is in the soil, 0 if not (then the slip, forces
 * and the rest of wc stay 0). */
static int contact_frame(const Model *m, const Eval *ev, int w, double Jh[3][NU], double zt,
                         const double n[3], int uniform_soil, WheelContact *wc, ContactFrame *cf, WheelSoilInput *in)
{
    const Params *p = &m->p;
    const double R = m->d.contact.radius;
    const double *H = ev->hub[w];
    v3_copy(cf->n, n);
    const double hub_height = (H[2] - zt) * cf->n[2];
    v3_copy(cf->np, cf->n);
    v3_axpy(cf->np, -v3_dot(cf->n, ev->e), ev->e);
    cf->in_plane = v3_norm(cf->np);
    if (cf->in_plane < 1e-6) return 0;                 /* wheel lying on its side */
    v3_scale(cf->np, cf->np, 1.0 / cf->in_plane);
    double sinkage = R - hub_height / cf->in_plane;
    if (uniform_soil) in->kh_factor = in->strength_factor = 1.0;
    else soil_factors(p, H[0], H[1], &in->kh_factor, &in->strength_factor);
    if (w % 2 == 1 && p->multipass_rutFraction > 0) {
        /* A rear wheel rolls in its front wheel's rut, on compacted soil. */
        const double rut = p->multipass_rutFraction *
                           rut_depth_at(&m->s, side_of(w), m->s.path[side_of(w)] - p->rover_wheelbase);
        sinkage -= rut;
        wc->rut = rut;
        in->kh_factor *= 1.0 + (p->multipass_khFactor - 1.0) * rut / (rut + p->multipass_compactionDepth);
    }
    wc->sinkage = sinkage;
    in->sinkage = sinkage;
    /* Both unit to rounding, without normalising: np is unit and normal
     * to the axle e, and n = in_plane np + (n . e) e is normal to f. */
    v3_cross(cf->f, ev->e, cf->np);
    v3_cross(cf->l, cf->n, cf->f);
    for (int i = 0; i < 3; ++i) cf->v_hub[i] = hub_row_dot(Jh, i, m->s.u);
    wc->v_long = v3_dot(cf->f, cf->v_hub);
    in->v_long = wc->v_long;
    return !(sinkage <= 0);               /* a NaN sinkage goes on, to be caught as a diverged state */
}

/* The wheel's spin about its axle (rad/s), from the rover's velocities;
 * its angular velocity into cf->omega. */
static double wheel_spin(const Model *m, const Eval *ev, double Jw[3][NU], int sp, ContactFrame *cf)
{
    for (int i = 0; i < 3; ++i) cf->omega[i] = angular_row_dot(Jw, i, m->s.u, sp);
    return v3_dot(cf->omega, ev->e);
}

/* The rim (or lug tip) point the shear acts on and the directions of the
 * contact force (wheel_soil.h), in world coordinates. */
typedef struct {
    double nvec[3];                /* Eqn 6: from the centroid towards the hub */
    double t[3];                   /* tangential direction of Eqns 8-9 */
    double Jp[3][NU];              /* velocity Jacobian of the rim (or lug tip) point on the centroid ray,
                                    * its angular, rocker and own spin columns (offset_point_jacobian) */
} ShearGeometry;

/* The rim point's geometry into sg; returns its velocity along l, the
 * lateral slip velocity of the shear law (m/s). */
static double shear_geometry(double Jh[3][NU], double Jw[3][NU], int sp, const ContactFrame *cf,
                             const WheelSoilContact *sc, ShearGeometry *sg)
{
    const double sa = sc->sin_alpha, ca = sc->cos_alpha;
    double r_rim[3];
    for (int i = 0; i < 3; ++i) {
        sg->nvec[i] = -sa * cf->f[i] + ca * cf->np[i];
        sg->t[i] = ca * cf->f[i] + sa * cf->np[i];
        r_rim[i] = -sc->shear_radius * sg->nvec[i];
    }
    /* The shear acts on the rim where the centroid ray meets it, so its
     * moment about the axle is exactly -R F_t (-(R + h) F_t with lugs) and
     * the normal force passes through the hub. */
    offset_point_jacobian(sg->Jp, Jh, Jw, r_rim, sp);
    double v_rim[3];                                 /* Jp u: the hub's velocity + omega x r_rim */
    v3_cross(v_rim, cf->omega, r_rim);
    v3_add(v_rim, cf->v_hub, v_rim);
    return v3_dot(cf->l, v_rim);
}

/* The wheel's forces and its total force into wc. */
static void contact_forces(const ContactFrame *cf, const WheelSoilContact *sc, const ShearForce *sh,
                           const ShearGeometry *sg, WheelContact *wc)
{
    wc->Fn = sc->Fn;
    wc->F_long = sh->F_long;
    wc->F_lat = sh->F_lat;
    wc->sin_alpha = sc->sin_alpha;
    wc->cos_alpha = sc->cos_alpha;
    for (int i = 0; i < 3; ++i)
        wc->force[i] = sc->Fn * sg->nvec[i] + sh->F_long * sg->t[i] + sh->F_lat * cf->l[i];
}

/* The contact's generalised force (Q), damping (D = -dQ/du of the shear)
 * and stiffness (K = -dQ/dq of the normal force).  Out of line: inlined,
 * rover_wheel_contacts grew too large for GCC to keep its values in
 * registers (280 more instructions an accepted step, 4 % more CPU time). */
static NOINLINE void contact_matrices(const Model *m, Eval *ev, double Jh[3][NU], double Jw[3][NU], int sp,
                             const ContactFrame *cf, const WheelSoilContact *sc, const ShearForce *sh,
                             ShearGeometry *sg, const WheelContact *wc)
{
    const ContactModel *cm = &m->d.contact;
    const double *jac = sh->jac;
    /* The rows through the rim point (the force, the lateral and the
     * tangential direction) and through the hub (the heading, the soil
     * normal, and the normal force's direction or, with Wong-Reece, the
     * in-plane normal), each three in one pass over their Jacobian. */
    double rim[3][NU], hub[3][NU];
    const double *const rim_dirs[3] = {wc->force, cf->l, sg->t};
    const double *const hub_dirs[3] = {cf->f, cf->n, sc->wong_reece ? cf->np : sg->nvec};
    point_vecs_times_jac(rim, rim_dirs, sg->Jp, sp, 0);
    point_vecs_times_jac(hub, hub_dirs, Jh, sp, 1);
    for (int k = 0; k < NU; ++k)                    /* Q += Jp^T force */
        if (k < U_SPIN_L || k == sp) ev->Q[k] += rim[0][k];
    /* Damping: through v_long, v_lat and omega R. */
    const double *g_long = hub[0], *g_lat = rim[1], *a_t = rim[2];
    double g_spin[NU];
    angular_vec_times_jac(g_spin, sc->shear_radius, ev->e, Jw, sp);
    double dFl[NU], dFy[NU];
    for (int k = 0; k < NU; ++k) {
        dFl[k] = jac[0] * g_long[k] + jac[1] * g_lat[k] + jac[2] * g_spin[k];
        dFy[k] = jac[3] * g_long[k] + jac[4] * g_lat[k] + jac[5] * g_spin[k];
    }
    sub_outer_pair(ev->D, a_t, dFl, g_lat, dFy, sp);
    /* The stiffness K = -dQ/dq: the force's direction times the sinkage's
     * gradient.  Sinkage = R - (H_z - z_t) n_z / in_plane grows by
     * -(n . dH) / in_plane when the hub moves by dH, whatever the force's
     * tilt, so the row is a_s = -d(sinkage)/dq = Jh^T n / in_plane.  Why not
     * the force's own direction (a symmetric K): the force tilts back by
     * alpha, and a wheel rolling forward at v then "climbs" v sin(alpha)
     * per second along it, so the step's end-of-step force would be short
     * by h kn v sin(alpha), a bias of first order in h even in steady
     * rolling (measured with the symmetric K, PID at 2 rad/s, 300 N
     * drawbar: the front normal loads 6.9 % low at solver.step 20 ms, 0.37 %
     * at 1 ms; with this K the same to 6 digits at every step). */
    double *a_s = hub[1];
    if (cf->in_plane != 1.0)                /* 1 exactly wherever the axle is level across the slope */
        for (int k = 0; k < NU; ++k) a_s[k] /= cf->in_plane;
    if (sc->wong_reece) {
        /* Slip damping of WR's in-plane forces: Q = Jh^T (Fx f + Fz np) -
         * T e^T Jw depends on u through the slip s = (omega R - v) / den. */
        const double *a_z = hub[2];
        double dQ_ds[NU], ds_du[NU];
        const double aw = fabs(sc->omega_r), av = fabs(wc->v_long);
        double dden_dv = 0.0, dden_dw = 0.0;
        if (aw >= av && aw >= cm->slip_v_eps) dden_dw = sc->omega_r > 0.0 ? 1.0 : -1.0;
        else if (av >= cm->slip_v_eps) dden_dv = wc->v_long > 0.0 ? 1.0 : -1.0;
        const double ds_dv = (-1.0 - sc->slip * dden_dv) / sc->den, ds_dw = (1.0 - sc->slip * dden_dw) / sc->den;
        for (int k = 0; k < NU; ++k) {
            dQ_ds[k] = g_long[k] * sc->wr.dFx_ds + a_z[k] * sc->wr.dFz_ds - g_spin[k] * sc->wr.dFt_ds;
            ds_du[k] = ds_dv * g_long[k] + ds_dw * g_spin[k];
        }
        add_outer(ev->D, dQ_ds, -1.0, ds_du, sp);
        /* Normal stiffness: dFz along the soil normal per unit of sinkage. */
        add_outer_hub(ev->K, a_z, sc->kn, a_s);
        return;
    }
    add_outer_hub(ev->K, hub[2], sc->kn, a_s);
}

void rover_wheel_contacts(const Model *m, Eval *ev, int matrices)
{
    rover_terrain_under_wheels(m, (const double (*)[3])ev->hub, ev->ground_z, ev->ground_normal);
    rover_wheel_contacts_on_ground(m, ev, matrices);
}

/* The four contacts in phases, each a loop over the wheels, so that the
 * wheels' independent chains of dependent library calls (the terrain
 * lookup before, the patch's log and exp, the shear's exp, the divisions
 * and square roots between them) sit side by side and the processor
 * overlaps them; one wheel after another, each chain would wait for the
 * one before.  The wheels in the soil go through phases 2 to 5 as n
 * compact entries (k: wheel[k]). */
void rover_wheel_contacts_on_ground(const Model *m, Eval *ev, int matrices)
{
    const WheelSoil ws = {&m->d.contact, &m->d.wong_reece, m->p.contact_model, m->p.slipSinkage_coefficient,
                          m->p.grouser_thrustGain, m->p.grouser_lugHeight, m->p.slipSinkage_exponent,
                          m->p.grouser_thrustSlip, m->p.grouser_lugCount, m->p.grouser_rippleAmplitude};
    const int jacobians = matrices == EVAL_MATRICES;
    int wheel[NUM_WHEELS], n = 0;
    ContactFrame cf[NUM_WHEELS];
    WheelSoilInput in[NUM_WHEELS];
    WheelSoilContact sc[NUM_WHEELS];
    ContactMemory mem[NUM_WHEELS];

    /* 1. From the terrain under each hub, wheel by wheel the contact frame,
     * the sinkage, the spin and the slip. */
    const double *zt = ev->ground_z;
    double (*normal)[3] = ev->ground_normal;
    /* Whether the soil is the same everywhere (no strip, no patch: the
     * defaults), once for the four wheels rather than in each one's frame. */
    const Params *p = &m->p;
    const int uniform_soil = p->strip_khFactor == 1.0 && p->strip_strengthFactor == 1.0 && p->patch_khFactor == 1.0 &&
                             p->patch_strengthFactor == 1.0;
    for (int w = 0; w < NUM_WHEELS; ++w) {
        double (*Jh)[NU] = ev->Jv[BODY_WHEEL0 + w];   /* the hub's velocity Jacobian (the wheel's CG) */
        WheelContact *wc = &ev->wheel[w];
        /* out of the soil: no slip, no force (field by field: GCC makes a
         * memset or a cleared struct of this size a rep stos, slow to start) */
        wc->in_contact = 0;
        wc->sinkage = wc->slip = wc->Fn = wc->F_long = wc->F_lat = wc->v_long = wc->sin_alpha = wc->rut = 0.0;
        wc->cos_alpha = 1.0;
        wc->force[0] = wc->force[1] = wc->force[2] = 0.0;
        if (!contact_frame(m, ev, w, Jh, zt[w], normal[w], uniform_soil, wc, &cf[n], &in[n])) continue;
        wc->in_contact = 1;
        mem[n] = m->s.memory[w];
        wheel[n++] = w;
    }
    for (int k = 0; k < n; ++k) {
        const int w = wheel[k];
        in[k].spin = wheel_spin(m, ev, ev->Jw[BODY_WHEEL0 + w], U_SPIN_L + side_of(w), &cf[k]);
        /* Lug ripple: the lugs' angle is the side's encoder angle (the rocker's
         * and chassis' pitch, a few degrees, shift the phase a little), which
         * counts from 0 where the run starts, wherever the lugs then are: the
         * side's lug phase says where; the rear wheel's lugs sit half a lug
         * pitch behind the front's (pi more).  The ripple's dependence on the
         * angle is explicit in the step (not in K): N omega h is small at the
         * steps that resolve the ripple. */
        in[k].spin_angle = m->s.spin_angle[side_of(w)];
        in[k].lug_phase = (side_of(w) == SIDE_LEFT ? p->grouser_lugPhaseLeft : p->grouser_lugPhaseRight) +
                          (w % 2 == 1 ? M_PI : 0.0);
        wheel_soil_slip(&ws, &in[k], &sc[k]);
        ev->wheel[w].slip = sc[k].slip;
    }

    /* 2. The normal forces, side by side. */
    wheel_soil_normals(&ws, n, mem, in, jacobians, sc);

    /* 3. The rim points the shear acts on, and their lateral slip velocities. */
    ShearGeometry sg[NUM_WHEELS];
    double v_lat[NUM_WHEELS];
    for (int k = 0; k < n; ++k) {
        const int w = wheel[k];
        v_lat[k] = shear_geometry(ev->Jv[BODY_WHEEL0 + w], ev->Jw[BODY_WHEEL0 + w], U_SPIN_L + side_of(w), &cf[k],
                                  &sc[k], &sg[k]);
    }

    /* 4. The shear forces, side by side. */
    ShearForce sh[NUM_WHEELS];
    wheel_soil_shears(&ws, n, sc, in, v_lat, jacobians, sh);

    /* 5. Wheel by wheel, in order (so that Q, D and K sum the wheels in the
     * same order whichever are in the soil): the forces and the matrices. */
    for (int k = 0; k < n; ++k) {
        const int w = wheel[k];
        WheelContact *wc = &ev->wheel[w];
        contact_forces(&cf[k], &sc[k], &sh[k], &sg[k], wc);
        if (jacobians)
            contact_matrices(m, ev, ev->Jv[BODY_WHEEL0 + w], ev->Jw[BODY_WHEEL0 + w], U_SPIN_L + side_of(w), &cf[k],
                             &sc[k], &sh[k], &sg[k], wc);
    }
}
