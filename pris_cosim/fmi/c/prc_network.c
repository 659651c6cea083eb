/* Assemble G, Cn, L from element values and reduce the MNA equations to
 * state-space form, the same computation as pris_cosim.mna.MNA.state_space:
 *
 *   Cn v' + G v + AL iL + AV iV = BI u_I,   L iL' = AL^T v,   AV^T v = BV u_V,
 *
 * node voltages v = Q1 a + Q0 b with a capacitive (a) and an algebraic (b)
 * part; b and iV are eliminated through the Schur complement M Z = [-Nx, Nu],
 * then E x' = [F + H Zx] x + [J + H Zu] u with E = diag(Q1^T Cn Q1, L).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "prc_linalg.h"
#include "prc_network.h"

#define IDX(M, i, j, ncols) (M)[(size_t)(i) * (size_t)(ncols) + (size_t)(j)]

typedef struct {
    double *next;
} arena;

static double *take(arena *a, size_t n) {
    double *p = a->next;
    memset(p, 0, n * sizeof(double));
    a->next += n;
    return p;
}

size_t prc_network_scratch(const prc_model *m) {
    size_t N = (size_t)m->n_nodes, nx = (size_t)(m->n_q1 + m->n_l), nu = (size_t)(m->n_ui + m->n_uv);
    size_t k = (size_t)(m->n_q0 + m->n_v), ml = (size_t)m->n_l, q = (size_t)m->n_v;
    size_t s = N + nx + nu + k + ml + q + 1;
    return 24 * s * s + 4 * s;
}

static void stamp(double *M, int n, int a, int b, double g) {
    if (a >= 0) IDX(M, a, a, n) += g;
    if (b >= 0) IDX(M, b, b, n) += g;
    if (a >= 0 && b >= 0) {
        IDX(M, a, b, n) -= g;
        IDX(M, b, a, n) -= g;
    }
}

static int check_positive(const prc_elem *e, const double *r, const char *what, const char *unit, char *msg,
                          size_t len) {
    double v = r[e->slot];
    const char *eq = e->expr ? " = " : "";
    const char *ex = e->expr ? e->expr : "";
    if (!isfinite(v)) {
        snprintf(msg, len, "element '%s'%s%s: value is not finite (got %g)", e->name, eq, ex, v);
        return -1;
    }
    if (!(v > 0.0)) {
        snprintf(msg, len, "element '%s'%s%s: %s must be positive (got %g %s)", e->name, eq, ex, what, v, unit);
        return -1;
    }
    return 0;
}

/* Copy block src (rows x cols, row stride sc) into dst at (r0, c0) with row stride dc, times s. */
static void put(double *dst, int dc, int r0, int c0, const double *src, int rows, int cols, int sc, double s) {
    int i, j;
    for (i = 0; i < rows; i++)
        for (j = 0; j < cols; j++) IDX(dst, r0 + i, c0 + j, dc) = s * IDX(src, i, j, sc);
}

int prc_network_build(const prc_model *m, const double *r, prc_net *net, double *scratch, char *msg,
                      size_t msglen) {
    const int N = m->n_nodes, r1 = m->n_q1, n0 = m->n_q0, ml = m->n_l, q = m->n_v;
    const int nI = m->n_ui, nV = m->n_uv, nu = nI + nV, nx = r1 + ml, kk = n0 + q, w = nx + nu;
    arena ar = {scratch};
    double *G = take(&ar, (size_t)N * N), *Cn = take(&ar, (size_t)N * N);
    double *Lm = take(&ar, (size_t)ml * ml), *Lc = take(&ar, (size_t)ml * ml);
    double *AL = take(&ar, (size_t)N * ml), *AV = take(&ar, (size_t)N * q);
    double *T = take(&ar, (size_t)N * N);
    double *G11 = take(&ar, (size_t)r1 * r1), *G10 = take(&ar, (size_t)r1 * n0);
    double *G00 = take(&ar, (size_t)n0 * n0), *G01 = take(&ar, (size_t)n0 * r1);
    double *C11 = take(&ar, (size_t)r1 * r1);
    double *Q0AV = take(&ar, (size_t)n0 * q), *Q0AL = take(&ar, (size_t)n0 * ml);
    double *Q1AL = take(&ar, (size_t)r1 * ml), *Q1AV = take(&ar, (size_t)r1 * q);
    double *Q0BI = take(&ar, (size_t)n0 * nI), *Q1BI = take(&ar, (size_t)r1 * nI);
    double *M = take(&ar, (size_t)kk * kk), *Z = take(&ar, (size_t)kk * w);
    double *H = take(&ar, (size_t)nx * kk), *rhs = take(&ar, (size_t)nx * w), *HZ = take(&ar, (size_t)nx * w);
    double *Cblk = take(&ar, (size_t)r1 * r1);
    int *piv = (int *)take(&ar, (size_t)(N + nx + kk + 2));
    int i, j, e;

    /* element checks and stamps */
    for (e = 0; e < m->n_r; e++) {
        const prc_elem *el = &m->resistors[e];
        if (check_positive(el, r, "resistance", "Ohm", msg, msglen)) return -1;
        stamp(G, N, el->a, el->b, 1.0 / r[el->slot]);
    }
    for (e = 0; e < m->n_c; e++) {
        const prc_elem *el = &m->capacitors[e];
        if (check_positive(el, r, "capacitance", "F", msg, msglen)) return -1;
        stamp(Cn, N, el->a, el->b, r[el->slot]);
    }
    for (e = 0; e < ml; e++) {
        const prc_elem *el = &m->inductors[e];
        if (check_positive(el, r, "inductance", "H", msg, msglen)) return -1;
        IDX(Lm, e, e, ml) = r[el->slot];
        if (el->a >= 0) IDX(AL, el->a, e, ml) += 1.0;
        if (el->b >= 0) IDX(AL, el->b, e, ml) -= 1.0;
    }
    for (e = 0; e < m->n_k; e++) {
        const prc_elem *el = &m->couplings[e];
        double k = r[el->slot], mut;
        if (!isfinite(k) || !(fabs(k) < 1.0)) {
            snprintf(msg, msglen, "element '%s'%s%s: coupling |k| must be below 1 (got %g)", el->name,
                     el->expr ? " = " : "", el->expr ? el->expr : "", k);
            return -1;
        }
        mut = k * sqrt(r[m->inductors[el->a].slot] * r[m->inductors[el->b].slot]);
        IDX(Lm, el->a, el->b, ml) += mut;
        IDX(Lm, el->b, el->a, ml) += mut;
    }
    if (ml > 0) {
        int bad = prc_cholesky(ml, Lm, Lc);
        if (bad) {
            snprintf(msg, msglen,
                     "inductance matrix is not positive definite (not passive): Cholesky fails at inductor "
                     "'%s'; check the couplings K and the inductances",
                     m->inductors[bad - 1].name);
            return -1;
        }
    }
    for (e = 0; e < q; e++) {
        int a = m->v_nodes[2 * e], b = m->v_nodes[2 * e + 1];
        if (a >= 0) IDX(AV, a, e, q) += 1.0;
        if (b >= 0) IDX(AV, b, e, q) -= 1.0;
    }

    /* projections on the capacitive (Q1) and algebraic (Q0) node subspaces */
    prc_matmul(N, N, r1, G, m->Q1, T);
    prc_matmul_tn(r1, N, r1, m->Q1, T, G11);
    prc_matmul_tn(n0, N, r1, m->Q0, T, G01);
    prc_matmul(N, N, n0, G, m->Q0, T);
    prc_matmul_tn(r1, N, n0, m->Q1, T, G10);
    prc_matmul_tn(n0, N, n0, m->Q0, T, G00);
    prc_matmul(N, N, r1, Cn, m->Q1, T);
    prc_matmul_tn(r1, N, r1, m->Q1, T, C11);
    prc_matmul_tn(n0, N, q, m->Q0, AV, Q0AV);
    prc_matmul_tn(n0, N, ml, m->Q0, AL, Q0AL);
    prc_matmul_tn(r1, N, ml, m->Q1, AL, Q1AL);
    prc_matmul_tn(r1, N, q, m->Q1, AV, Q1AV);
    prc_matmul_tn(n0, N, nI, m->Q0, m->BI, Q0BI);
    prc_matmul_tn(r1, N, nI, m->Q1, m->BI, Q1BI);

    /* algebraic part: M Z = [-Nx, Nu] */
    if (kk > 0) {
        put(M, kk, 0, 0, G00, n0, n0, n0, 1.0);
        put(M, kk, 0, n0, Q0AV, n0, q, q, 1.0);
        for (i = 0; i < n0; i++)
            for (j = 0; j < q; j++) IDX(M, n0 + j, i, kk) = IDX(Q0AV, i, j, q);
        put(Z, w, 0, 0, G01, n0, r1, r1, -1.0);
        put(Z, w, 0, r1, Q0AL, n0, ml, ml, -1.0);
        put(Z, w, 0, nx, Q0BI, n0, nI, nI, 1.0);
        put(Z, w, n0, nx + nI, m->BV, q, nV, nV, 1.0);
        if (prc_lu_factor(kk, M, piv, 1e-13)) {
            snprintf(msg, msglen,
                     "the network has a node with no capacitive or resistive connection "
                     "(only inductors or sources): its response is improper");
            return -1;
        }
        prc_lu_solve(kk, M, piv, w, Z);
    }

    /* dynamic part: rhs = [F, J] + H Z */
    put(rhs, w, 0, 0, G11, r1, r1, r1, -1.0);
    put(rhs, w, 0, r1, Q1AL, r1, ml, ml, -1.0);
    for (i = 0; i < ml; i++)
        for (j = 0; j < r1; j++) IDX(rhs, r1 + i, j, w) = IDX(Q1AL, j, i, ml);
    put(rhs, w, 0, nx, Q1BI, r1, nI, nI, 1.0);
    if (kk > 0) {
        put(H, kk, 0, 0, G10, r1, n0, n0, -1.0);
        put(H, kk, 0, n0, Q1AV, r1, q, q, -1.0);
        for (i = 0; i < ml; i++)
            for (j = 0; j < n0; j++) IDX(H, r1 + i, j, kk) = IDX(Q0AL, j, i, ml);
        prc_matmul(nx, kk, w, H, Z, HZ);
        for (i = 0; i < nx * w; i++) rhs[i] += HZ[i];
    }

    /* E = diag(C11, L): solve both blocks */
    if (r1 > 0) {
        memcpy(Cblk, C11, sizeof(double) * (size_t)r1 * r1);
        if (prc_lu_factor(r1, Cblk, piv, 1e-14)) {
            snprintf(msg, msglen, "the capacitance matrix of the network is singular");
            return -1;
        }
        prc_lu_solve(r1, Cblk, piv, w, rhs);
    }
    if (ml > 0) {   /* L = Lc Lc^T */
        double *blk = rhs + (size_t)r1 * w;
        int c;
        for (c = 0; c < w; c++) {
            for (i = 0; i < ml; i++) {
                double s = IDX(blk, i, c, w);
                for (j = 0; j < i; j++) s -= IDX(Lc, i, j, ml) * IDX(blk, j, c, w);
                IDX(blk, i, c, w) = s / IDX(Lc, i, i, ml);
            }
            for (i = ml - 1; i >= 0; i--) {
                double s = IDX(blk, i, c, w);
                for (j = i + 1; j < ml; j++) s -= IDX(Lc, j, i, ml) * IDX(blk, j, c, w);
                IDX(blk, i, c, w) = s / IDX(Lc, i, i, ml);
            }
        }
    }
    for (i = 0; i < nx; i++) {
        for (j = 0; j < nx; j++) IDX(net->A, i, j, nx) = IDX(rhs, i, j, w);
        for (j = 0; j < nu; j++) IDX(net->B, i, j, nu) = IDX(rhs, i, nx + j, w);
    }

    /* node voltages v = Q1 a + Q0 b = Cv x + Dv u */
    for (i = 0; i < N; i++) {
        for (j = 0; j < nx; j++) {
            double s = j < r1 ? IDX(m->Q1, i, j, r1) : 0.0;
            int p;
            for (p = 0; p < n0; p++) s += IDX(m->Q0, i, p, n0) * IDX(Z, p, j, w);
            IDX(net->Cv, i, j, nx) = s;
        }
        for (j = 0; j < nu; j++) {
            double s = 0.0;
            int p;
            for (p = 0; p < n0; p++) s += IDX(m->Q0, i, p, n0) * IDX(Z, p, nx + j, w);
            IDX(net->Dv, i, j, nu) = s;
        }
    }
    return 0;
}
