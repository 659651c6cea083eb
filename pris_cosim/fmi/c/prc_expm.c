/* Matrix exponential: scaling and squaring with a diagonal Pade approximant.
 *
 * The degree m in {3, 5, 7, 9, 13} is the smallest whose theta_m bound holds
 * for the 1-norm of A (Higham, SIAM J. Matrix Anal. Appl. 26 (2005) 1179);
 * above theta_13 the matrix is scaled by 2^-s, the degree-13 approximant
 * formed, and the result squared s times.
 */
#include <math.h>
#include <string.h>

#include "prc_expm.h"
#include "prc_linalg.h"

static const double THETA[5] = {1.495585217958292e-2, 2.539398330063230e-1, 9.504178996162932e-1,
                                2.097847961257068e0, 5.371920351148152e0};
static const int DEGREE[5] = {3, 5, 7, 9, 13};

static const double B3[4] = {120.0, 60.0, 12.0, 1.0};
static const double B5[6] = {30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0};
static const double B7[8] = {17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0};
static const double B9[10] = {17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0,
                              2162160.0, 110880.0, 3960.0, 90.0, 1.0};
static const double B13[14] = {64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
                               1187353796428800.0, 129060195264000.0, 10559470521600.0,
                               670442572800.0, 33522128640.0, 1323241920.0, 40840800.0,
                               960960.0, 16380.0, 182.0, 1.0};

/* out = sum_j c[j] * P[j] + c0 * I over `count` matrices P[j] (n x n). */
static void combine(int n, double *out, double c0, int count, const double *c, double *const *P) {
    size_t nn = (size_t)n * n;
    size_t i;
    int j;
    for (i = 0; i < nn; i++) {
        double s = 0.0;
        for (j = 0; j < count; j++) s += c[j] * P[j][i];
        out[i] = s;
    }
    for (i = 0; i < (size_t)n; i++) out[i * n + i] += c0;
}

int prc_expm(int n, const double *A, double *E, double *work, int *ipiv) {
    size_t nn = (size_t)n * n, i;
    double *As = work, *A2 = work + nn, *A4 = work + 2 * nn, *A6 = work + 3 * nn;
    double *U = work + 4 * nn, *V = work + 5 * nn, *T = work + 6 * nn, *T2 = work + 7 * nn;
    double *P = work + 8 * nn;
    double norm, scale = 1.0;
    int s = 0, m = 13, k, idx;

    if (n == 0) return 0;
    for (i = 0; i < nn; i++)
        if (!isfinite(A[i])) return -1;
    norm = prc_norm1(n, A);
    for (idx = 0; idx < 5; idx++) {
        if (norm <= THETA[idx]) { m = DEGREE[idx]; break; }
    }
    if (idx == 5) {
        s = (int)ceil(log2(norm / THETA[4]));
        if (s < 0) s = 0;
        scale = ldexp(1.0, -s);
    }
    for (i = 0; i < nn; i++) As[i] = A[i] * scale;
    prc_matmul(n, n, n, As, As, A2);
    if (m == 13) {
        double *pw[3];
        double c[3];
        prc_matmul(n, n, n, A2, A2, A4);
        prc_matmul(n, n, n, A4, A2, A6);
        /* U = A [A6 (b13 A6 + b11 A4 + b9 A2) + b7 A6 + b5 A4 + b3 A2 + b1 I] */
        pw[0] = A6; pw[1] = A4; pw[2] = A2;
        c[0] = B13[13]; c[1] = B13[11]; c[2] = B13[9];
        combine(n, T, 0.0, 3, c, pw);
        prc_matmul(n, n, n, A6, T, T2);
        c[0] = B13[7]; c[1] = B13[5]; c[2] = B13[3];
        combine(n, T, B13[1], 3, c, pw);
        for (i = 0; i < nn; i++) T[i] += T2[i];
        prc_matmul(n, n, n, As, T, U);
        /* V = A6 (b12 A6 + b10 A4 + b8 A2) + b6 A6 + b4 A4 + b2 A2 + b0 I */
        c[0] = B13[12]; c[1] = B13[10]; c[2] = B13[8];
        combine(n, T, 0.0, 3, c, pw);
        prc_matmul(n, n, n, A6, T, T2);
        c[0] = B13[6]; c[1] = B13[4]; c[2] = B13[2];
        combine(n, V, B13[0], 3, c, pw);
        for (i = 0; i < nn; i++) V[i] += T2[i];
    } else {
        const double *b = m == 3 ? B3 : m == 5 ? B5 : m == 7 ? B7 : B9;
        double *pw[4];
        double codd[4], ceven[4];
        int half = (m - 1) / 2;   /* number of even powers A^2 .. A^(m-1) */
        pw[0] = A2;
        if (half > 1) { prc_matmul(n, n, n, A2, A2, A4); pw[1] = A4; }
        if (half > 2) { prc_matmul(n, n, n, A4, A2, A6); pw[2] = A6; }
        if (half > 3) { prc_matmul(n, n, n, A6, A2, P); pw[3] = P; }
        for (k = 0; k < half; k++) {
            codd[k] = b[2 * k + 3];
            ceven[k] = b[2 * k + 2];
        }
        combine(n, T, b[1], half, codd, pw);
        prc_matmul(n, n, n, As, T, U);
        combine(n, V, b[0], half, ceven, pw);
    }
    /* E = (V - U)^-1 (V + U) */
    for (i = 0; i < nn; i++) {
        T[i] = V[i] - U[i];
        E[i] = V[i] + U[i];
    }
    if (prc_lu_factor(n, T, ipiv, 0.0) != 0) return -1;
    prc_lu_solve(n, T, ipiv, n, E);
    for (k = 0; k < s; k++) {
        prc_matmul(n, n, n, E, E, T);
        memcpy(E, T, nn * sizeof(double));
    }
    return 0;
}
