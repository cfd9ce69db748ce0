/*
 * The dense NU x NU solver (dense_lu.h): LU factorisation with partial
 * pivoting, forward and backward substitution.
 *
 * Shaped for a small matrix of fixed size on the integrators' hot path:
 * the columns and rows are helpers inlined with constant indices, so
 * that their loops have fixed lengths, which GCC unrolls (the
 * elimination's row updates two entries at a time, row_minus);
 * and the factorisation and the substitutions are chains of dependent
 * operations whose latency, more than their number, sets their time.
 * Hence the factorisation divides once a column (by the pivot's
 * reciprocal) and keeps U's rows over their diagonal, and each
 * substitution row takes the entry solved last last, so that a row adds
 * one multiplication and one subtraction to the chain, with the rows in
 * registers (a local array with constant indices; the pivoting's
 * reordering is a gather).
 */
#include <math.h>
#include <string.h>

#include "dense_lu.h"
#include "rover_internal.h"

/* rr[k] -= f pr[k] for k = from..NU-1, two entries at a time where GCC's
 * vector types give SSE2 (the same multiplication and subtraction for
 * every entry: the scalar loop's results; left to itself, GCC keeps the
 * fully unrolled elimination scalar). */
static inline void row_minus(double *restrict rr, const double *restrict pr, double f, const int from)
{
    int k = from;
#if defined(__GNUC__) && defined(__SSE2__)
    typedef double pair __attribute__((vector_size(16)));
    const pair fv = {f, f};
    for (; k + 1 < NU; k += 2) {
        pair a, b;
        memcpy(&a, rr + k, sizeof a);
        memcpy(&b, pr + k, sizeof b);
        a -= fv * b;
        memcpy(rr + k, &a, sizeof a);
    }
#endif
    for (; k < NU; ++k) rr[k] -= f * pr[k];
}

/* One column c of dense_lu_factor's elimination: partial pivoting among
 * rows c..NU-1, then the rows below get their multiplier in column c (by
 * the pivot's reciprocal: one division a column) and lose that column's
 * share right of it; and row c of U over its diagonal. */
static inline int lu_column(DenseLU *lu, const int c)
{
    double (*A)[NU] = lu->a;
    int piv = c;
    double best = fabs(A[c][c]);
    for (int r = c + 1; r < NU; ++r) {
        const double v = fabs(A[r][c]);
        if (v > best) best = v, piv = r;
    }
    if (!(best > 1e-300)) return -1;
    if (piv != c) {
        for (int k = 0; k < NU; ++k) {
            const double t = A[c][k];
            A[c][k] = A[piv][k], A[piv][k] = t;
        }
        const int t = lu->order[c];
        lu->order[c] = lu->order[piv], lu->order[piv] = t;
    }
    const double *pr = A[c], inv = 1.0 / pr[c];
    lu->inv_diag[c] = inv;
    for (int r = c + 1; r < NU; ++r) {
        double *rr = A[r];
        const double f = rr[c] * inv;
        rr[c] = f;
        row_minus(rr, pr, f, c + 1);
    }
    for (int k = c + 1; k < NU; ++k) lu->u_scaled[c][k] = pr[k] * inv;
    return 0;
}

/* Out of line also under link-time optimisation: inlined into the
 * automatic step's two_stage, that grew too large for GCC to keep its
 * values in registers (330 more instructions an accepted step, 4 % more
 * CPU time). */
NOINLINE int dense_lu_factor(DenseLU *lu)
{
    _Static_assert(NU == 9, "dense_lu_factor() unrolls its columns for NU = 9");
    for (int i = 0; i < NU; ++i) lu->order[i] = i;
    return lu_column(lu, 0) || lu_column(lu, 1) || lu_column(lu, 2) || lu_column(lu, 3) || lu_column(lu, 4) ||
                   lu_column(lu, 5) || lu_column(lu, 6) || lu_column(lu, 7) || lu_column(lu, 8)
               ? -1
               : 0;
}

/* Row r of the forward substitution (L y = b, unit diagonal) and row c of
 * the backward one (U x = y, as x_c = y_c / U_cc - sum (U_ck / U_cc) x_k),
 * each inlined with a constant row; each sum takes the entry solved last
 * (y[r - 1], x[c + 1]) last. */
static inline void lu_forward_row(const DenseLU *lu, double x[NU], const int r)
{
    double y = x[r];
    for (int c = 0; c < r; ++c) y -= lu->a[r][c] * x[c];
    x[r] = y;
}

static inline void lu_backward_row(const DenseLU *lu, double x[NU], const int c)
{
    double v = x[c] * lu->inv_diag[c];
    for (int k = NU - 1; k > c; --k) v -= lu->u_scaled[c][k] * x[k];
    x[c] = v;
}

/* The rows are solved in a local array indexed by constants only, which
 * the compiler keeps in registers: through memory, each row would add a
 * store and a load to the chain. */
void dense_lu_solve(const DenseLU *restrict lu, double *restrict b)
{
    double x[NU];
    for (int i = 0; i < NU; ++i) x[i] = b[lu->order[i]];
    lu_forward_row(lu, x, 1), lu_forward_row(lu, x, 2), lu_forward_row(lu, x, 3), lu_forward_row(lu, x, 4);
    lu_forward_row(lu, x, 5), lu_forward_row(lu, x, 6), lu_forward_row(lu, x, 7), lu_forward_row(lu, x, 8);
    lu_backward_row(lu, x, 8), lu_backward_row(lu, x, 7), lu_backward_row(lu, x, 6), lu_backward_row(lu, x, 5);
    lu_backward_row(lu, x, 4), lu_backward_row(lu, x, 3), lu_backward_row(lu, x, 2), lu_backward_row(lu, x, 1);
    lu_backward_row(lu, x, 0);
    for (int i = 0; i < NU; ++i) b[i] = x[i];
}
