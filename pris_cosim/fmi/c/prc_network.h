/* Run-time assembly of the state-space model of a network from element values. */
#ifndef PRC_NETWORK_H
#define PRC_NETWORK_H

#include <stddef.h>

#include "prc_model.h"

/* Continuous-time model x' = A x + B u; node voltages v = Cv x + Dv u. */
typedef struct {
    int N, nx, nu;
    double *A, *B, *Cv, *Dv;   /* nx x nx, nx x nu, N x nx, N x nu */
} prc_net;

/* Doubles of scratch space prc_network_build needs for model m. */
size_t prc_network_scratch(const prc_model *m);

/* Check the element values in r (R, L, C > 0, |k| < 1, inductance matrix
 * positive definite), assemble G, Cn, L and reduce to (A, B, Cv, Dv).
 * Returns 0, or -1 with a one-line reason in msg. */
int prc_network_build(const prc_model *m, const double *r, prc_net *net, double *scratch, char *msg,
                      size_t msglen);

#endif
