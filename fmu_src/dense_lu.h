/*
 * The dense NU x NU linear solver both integrators use: LU factorisation
 * with partial pivoting, then forward and backward substitution.  The
 * fixed step (rover_step.c) solves one system with each matrix, the
 * automatic step (rover_auto_step.c) two with one factorisation, so the
 * factorisation and the solve are separate calls on a plain struct the
 * caller keeps on its stack: no allocation, no state between calls.
 */
#ifndef JUNO_DENSE_LU_H
#define JUNO_DENSE_LU_H

#include "model.h"

/* The matrix to factorise (the caller writes a), then its LU factors in
 * place: L's multipliers below the diagonal of a (unit diagonal implied),
 * U on and above it, row c of both from the matrix's row order[c]
 * (partial pivoting).  For the backward substitution, the reciprocals of
 * U's diagonal and U's rows right of it over their diagonal, so that a
 * substitution row needs no division (dense_lu.c says why). */
typedef struct {
    double a[NU][NU];
    double inv_diag[NU];
    double u_scaled[NU][NU];       /* right of the diagonal: U[c][k] / U[c][c] */
    int order[NU];
} DenseLU;

/* Factorises lu->a in place (and fills the rest of lu).  Returns -1 if the
 * matrix is singular (a pivot's magnitude not above 1e-300, or NaN), else 0. */
int dense_lu_factor(DenseLU *lu);

/* Solves A x = b with dense_lu_factor's factors of A; b is overwritten
 * with x. */
void dense_lu_solve(const DenseLU *restrict lu, double *restrict b);

#endif
