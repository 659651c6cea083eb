/* Small dense linear algebra: products, LU with partial pivoting, Cholesky. */
#include <math.h>
#include <string.h>

#include "prc_linalg.h"

void prc_matmul(int m, int k, int n, const double *A, const double *B, double *C) {
    int i, j, p;
    for (i = 0; i < m; i++) {
        double *c = C + (size_t)i * n;
        for (j = 0; j < n; j++) c[j] = 0.0;
        for (p = 0; p < k; p++) {
            const double a = A[(size_t)i * k + p];
            const double *b = B + (size_t)p * n;
            if (a == 0.0) continue;
            for (j = 0; j < n; j++) c[j] += a * b[j];
        }
    }
}

void prc_matmul_tn(int m, int k, int n, const double *A, const double *B, double *C) {
    int i, j, p;
    memset(C, 0, sizeof(double) * (size_t)m * (size_t)n);
    for (p = 0; p < k; p++) {
        const double *a = A + (size_t)p * m;
        const double *b = B + (size_t)p * n;
        for (i = 0; i < m; i++) {
            double *c = C + (size_t)i * n;
            if (a[i] == 0.0) continue;
            for (j = 0; j < n; j++) c[j] += a[i] * b[j];
        }
    }
}

void prc_matvec(int m, int n, const double *A, const double *x, double *y) {
    int i, j;
    for (i = 0; i < m; i++) {
        double s = 0.0;
        const double *a = A + (size_t)i * n;
        for (j = 0; j < n; j++) s += a[j] * x[j];
        y[i] = s;
    }
}

int prc_lu_factor(int n, double *A, int *piv, double rel_tol) {
    int i, j, k;
    double amax = 0.0;
    for (i = 0; i < n * n; i++) amax = fmax(amax, fabs(A[i]));
    for (k = 0; k < n; k++) {
        int p = k;
        double best = fabs(A[(size_t)k * n + k]);
        for (i = k + 1; i < n; i++) {
            double v = fabs(A[(size_t)i * n + k]);
            if (v > best) { best = v; p = i; }
        }
        piv[k] = p;
        if (!(best > rel_tol * amax) || best == 0.0) return k + 1;
        if (p != k) {
            for (j = 0; j < n; j++) {
                double t = A[(size_t)k * n + j];
                A[(size_t)k * n + j] = A[(size_t)p * n + j];
                A[(size_t)p * n + j] = t;
            }
        }
        for (i = k + 1; i < n; i++) {
            double f = A[(size_t)i * n + k] / A[(size_t)k * n + k];
            A[(size_t)i * n + k] = f;
            if (f == 0.0) continue;
            for (j = k + 1; j < n; j++) A[(size_t)i * n + j] -= f * A[(size_t)k * n + j];
        }
    }
    return 0;
}

void prc_lu_solve(int n, const double *LU, const int *piv, int nrhs, double *B) {
    int i, j, k;
    for (k = 0; k < n; k++) {
        if (piv[k] != k) {
            double *a = B + (size_t)k * nrhs, *b = B + (size_t)piv[k] * nrhs;
            for (j = 0; j < nrhs; j++) { double t = a[j]; a[j] = b[j]; b[j] = t; }
        }
    }
    for (i = 1; i < n; i++) {          /* forward: unit lower triangle */
        for (k = 0; k < i; k++) {
            double f = LU[(size_t)i * n + k];
            if (f == 0.0) continue;
            for (j = 0; j < nrhs; j++) B[(size_t)i * nrhs + j] -= f * B[(size_t)k * nrhs + j];
        }
    }
    for (i = n - 1; i >= 0; i--) {     /* backward: upper triangle */
        double d = LU[(size_t)i * n + i];
        for (k = i + 1; k < n; k++) {
            double f = LU[(size_t)i * n + k];
            if (f == 0.0) continue;
            for (j = 0; j < nrhs; j++) B[(size_t)i * nrhs + j] -= f * B[(size_t)k * nrhs + j];
        }
        for (j = 0; j < nrhs; j++) B[(size_t)i * nrhs + j] /= d;
    }
}

int prc_cholesky(int n, const double *A, double *L) {
    int i, j, k;
    memset(L, 0, sizeof(double) * (size_t)n * (size_t)n);
    for (j = 0; j < n; j++) {
        double d = A[(size_t)j * n + j];
        for (k = 0; k < j; k++) d -= L[(size_t)j * n + k] * L[(size_t)j * n + k];
        if (!(d > 0.0)) return j + 1;
        d = sqrt(d);
        L[(size_t)j * n + j] = d;
        for (i = j + 1; i < n; i++) {
            double s = A[(size_t)i * n + j];
            for (k = 0; k < j; k++) s -= L[(size_t)i * n + k] * L[(size_t)j * n + k];
            L[(size_t)i * n + j] = s / d;
        }
    }
    return 0;
}

double prc_norm1(int n, const double *A) {
    int i, j;
    double best = 0.0;
    for (j = 0; j < n; j++) {
        double s = 0.0;
        for (i = 0; i < n; i++) s += fabs(A[(size_t)i * n + j]);
        if (s > best) best = s;
    }
    return best;
}
