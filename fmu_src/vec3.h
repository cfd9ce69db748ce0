/* Small 3-vector and 3x3 helpers (row-major), all inline and allocation-free. */
#ifndef JUNO_VEC3_H
#define JUNO_VEC3_H

#include <math.h>

static inline void v3_set(double r[3], double x, double y, double z) { r[0] = x; r[1] = y; r[2] = z; }
static inline void v3_copy(double r[3], const double a[3]) { r[0] = a[0]; r[1] = a[1]; r[2] = a[2]; }
static inline void v3_add(double r[3], const double a[3], const double b[3]) { r[0] = a[0] + b[0]; r[1] = a[1] + b[1]; r[2] = a[2] + b[2]; }
static inline void v3_sub(double r[3], const double a[3], const double b[3]) { r[0] = a[0] - b[0]; r[1] = a[1] - b[1]; r[2] = a[2] - b[2]; }
static inline void v3_scale(double r[3], const double a[3], double s) { r[0] = a[0] * s; r[1] = a[1] * s; r[2] = a[2] * s; }
static inline void v3_axpy(double r[3], double s, const double a[3]) { r[0] += s * a[0]; r[1] += s * a[1]; r[2] += s * a[2]; }
static inline double v3_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static inline double v3_norm(const double a[3]) { return sqrt(v3_dot(a, a)); }
static inline void v3_cross(double r[3], const double a[3], const double b[3])
{
    double x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
    r[0] = x; r[1] = y; r[2] = z;
}
static inline void v3_normalize(double a[3])
{
    double n = v3_norm(a);
    if (n > 0) v3_scale(a, a, 1.0 / n);
}
/* r = A a */
static inline void m3_mul_v(double r[3], const double A[9], const double a[3])
{
    double x = A[0] * a[0] + A[1] * a[1] + A[2] * a[2];
    double y = A[3] * a[0] + A[4] * a[1] + A[5] * a[2];
    double z = A[6] * a[0] + A[7] * a[1] + A[8] * a[2];
    r[0] = x; r[1] = y; r[2] = z;
}
/* C = A B */
static inline void m3_mul(double C[9], const double A[9], const double B[9])
{
    double T[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) T[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
    for (int k = 0; k < 9; ++k) C[k] = T[k];
}
/* World inertia R diag(I) R^T */
static inline void m3_rotate_diag(double C[9], const double R[9], const double I[3])
{
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            C[3 * i + j] = R[3 * i] * I[0] * R[3 * j] + R[3 * i + 1] * I[1] * R[3 * j + 1] + R[3 * i + 2] * I[2] * R[3 * j + 2];
}
/* World inertia R I R^T of a body inertia I (symmetric). */
static inline void m3_rotate(double C[9], const double R[9], const double I[9])
{
    double RI[9];
    m3_mul(RI, R, I);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) C[3 * i + j] = RI[3 * i] * R[3 * j] + RI[3 * i + 1] * R[3 * j + 1] + RI[3 * i + 2] * R[3 * j + 2];
}
/* Rotation matrix of a unit quaternion (w, x, y, z). */
static inline void quat_to_m3(double R[9], const double q[4])
{
    double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - w * z);     R[2] = 2 * (x * z + w * y);
    R[3] = 2 * (x * y + w * z);     R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - w * x);
    R[6] = 2 * (x * z - w * y);     R[7] = 2 * (y * z + w * x);     R[8] = 1 - 2 * (x * x + y * y);
}
/* sin x and cos x, for |x| <= 1/2 from their Taylor series to x^15 and x^16
 * (the first terms left out, x^17/17! and x^18/18!, are below 5e-20 of the
 * values there), in Estrin's scheme (a shorter chain than Horner's), within
 * an ulp: the leading x and 1 are added last to corrections of at most a
 * twentieth and a seventh of the values.  The library's beyond. */
static inline void sin_cos(double x, double *s, double *c)
{
    if (fabs(x) <= 0.5) {
        const double x2 = x * x, x4 = x2 * x2, x8 = x4 * x4;
        const double p = (-1.0 / 6 + (1.0 / 120) * x2) + (-1.0 / 5040 + (1.0 / 362880) * x2) * x4 +
                         ((-1.0 / 39916800 + (1.0 / 6227020800.0) * x2) + (-1.0 / 1307674368000.0) * x4) * x8;
        const double q = (-1.0 / 2 + (1.0 / 24) * x2) + (-1.0 / 720 + (1.0 / 40320) * x2) * x4 +
                         ((-1.0 / 3628800 + (1.0 / 479001600) * x2) +
                          (-1.0 / 87178291200.0 + (1.0 / 20922789888000.0) * x2) * x4) * x8;
        *s = x + (x * x2) * p;
        *c = 1.0 + x2 * q;
    } else {
        *s = sin(x);
        *c = cos(x);
    }
}

/* Quaternion of Z-Y-X Euler angles (yaw, pitch, roll). */
static inline void quat_from_euler(double q[4], double roll, double pitch, double yaw)
{
    double cr = cos(roll / 2), sr = sin(roll / 2), cp = cos(pitch / 2), sp = sin(pitch / 2);
    double cy = cos(yaw / 2), sy = sin(yaw / 2);
    q[0] = cr * cp * cy + sr * sp * sy;
    q[1] = sr * cp * cy - cr * sp * sy;
    q[2] = cr * sp * cy + sr * cp * sy;
    q[3] = cr * cp * sy - sr * sp * cy;
}
/* q <- exp(w h / 2) * q for a world-frame angular velocity w (exact rotation).
 * The rotation of a step is small: up to a half angle t = |w| h / 2 of 1/16
 * (a step turning the rover by 7 degrees) sin(t) / |w| = (h/2) sin(t)/t
 * and cos t come from their series in t^2, to t^8: the first terms left
 * out, t^10/11! and t^10/10!, are below 3e-19 there, so both are within
 * the rounding of their evaluation (an ulp or two) without sin, cos, the
 * square root of |w|^2 and the division (a library call of about 100
 * instructions an internal step). */
static inline void quat_integrate_world(double q[4], const double w[3], double h)
{
    const double w2 = v3_dot(w, w);
    if (w2 == 0 || h == 0) return;
    const double t2 = 0.25 * w2 * (h * h);
    double s, c;
    if (t2 <= 0x1p-8) {
        s = (0.5 * h) * (1.0 - t2 * (1.0 / 6 - t2 * (1.0 / 120 - t2 * (1.0 / 5040 - t2 * (1.0 / 362880)))));
        c = 1.0 - t2 * (1.0 / 2 - t2 * (1.0 / 24 - t2 * (1.0 / 720 - t2 * (1.0 / 40320))));
    } else {
        const double angle = sqrt(w2) * h;
        s = sin(angle / 2) / (angle / h);
        c = cos(angle / 2);
    }
    double d[4] = {c, w[0] * s, w[1] * s, w[2] * s};
    double r[4] = {d[0] * q[0] - d[1] * q[1] - d[2] * q[2] - d[3] * q[3],
                   d[0] * q[1] + d[1] * q[0] + d[2] * q[3] - d[3] * q[2],
                   d[0] * q[2] - d[1] * q[3] + d[2] * q[0] + d[3] * q[1],
                   d[0] * q[3] + d[1] * q[2] - d[2] * q[1] + d[3] * q[0]};
    double n = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]);
    for (int i = 0; i < 4; ++i) q[i] = r[i] / n;
}

#endif
