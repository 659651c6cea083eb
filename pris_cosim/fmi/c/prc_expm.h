/* Matrix exponential by scaling and squaring with Pade approximants
 * (degree 3, 5, 7, 9 or 13 chosen from the 1-norm, Higham 2005). */
#ifndef PRC_EXPM_H
#define PRC_EXPM_H

/* Doubles of workspace prc_expm needs for an n x n matrix. */
#define PRC_EXPM_WORK(n) (9 * (size_t)(n) * (size_t)(n))

/* E = expm(A) for the n x n matrix A; work holds PRC_EXPM_WORK(n) doubles,
 * ipiv n ints. Returns 0, or -1 when A is not finite or the Pade denominator
 * is singular. */
int prc_expm(int n, const double *A, double *E, double *work, int *ipiv);

#endif
