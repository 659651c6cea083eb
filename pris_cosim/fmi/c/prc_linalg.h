/* Small dense linear algebra for the generated network FMUs.
 *
 * All matrices are row-major arrays of double. Sizes are those of lumped
 * circuit models (tens of states), so plain loops are fast enough and keep
 * the FMU free of external libraries.
 */
#ifndef PRC_LINALG_H
#define PRC_LINALG_H

/* C (m x n) = A (m x k) * B (k x n); C must not alias A or B. */
void prc_matmul(int m, int k, int n, const double *A, const double *B, double *C);

/* C (m x n) = A^T * B with A (k x m), B (k x n). */
void prc_matmul_tn(int m, int k, int n, const double *A, const double *B, double *C);

/* y (m) = A (m x n) * x (n). */
void prc_matvec(int m, int n, const double *A, const double *x, double *y);

/* In-place LU factorisation with partial pivoting of the n x n matrix A.
 * Returns 0, or i + 1 when the pivot of column i is zero or below
 * rel_tol * max|A| (numerically singular). */
int prc_lu_factor(int n, double *A, int *piv, double rel_tol);

/* Solve A X = B in place of B (n x nrhs) with the factors from prc_lu_factor. */
void prc_lu_solve(int n, const double *LU, const int *piv, int nrhs, double *B);

/* Cholesky factor L (lower, n x n) of the symmetric matrix A.
 * Returns 0, or i + 1 when the leading minor of order i + 1 is not positive. */
int prc_cholesky(int n, const double *A, double *L);

/* Maximum absolute column sum (matrix 1-norm). */
double prc_norm1(int n, const double *A);

#endif
