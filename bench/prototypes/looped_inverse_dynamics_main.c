#include <stdio.h>
#include <stdlib.h>
#include <math.h>
void id_loop(const double *x, const double *qdd, const double *p, double *Q);
void spatial_chain_20_inverse_dynamics(double t, const double *x, const double *qdd, const double *u, const double *p, double *Q);
void spatial_chain_20_default_parameters(double *p);
int main(int argc, char **argv) {
    double x[40], qdd[20], p[42], Q1[20], Q2[20], u[1] = {0}, acc = 0;
    int which = atoi(argv[1]), K = atoi(argv[2]), i, k;
    spatial_chain_20_default_parameters(p);
    srand(3);
    for (i = 0; i < 40; ++i) x[i] = 4 * (rand() / (double)RAND_MAX - 0.5);
    for (i = 0; i < 20; ++i) qdd[i] = 0.3 * (i % 3) - 0.2;
    for (k = 0; k < K; ++k) {
        x[k % 40] += 1e-9 * acc;
        if (which) id_loop(x, qdd, p, Q1); else spatial_chain_20_inverse_dynamics(0, x, qdd, u, p, Q1);
        acc += Q1[k % 20] * 1e-12;
    }
    if (K == 1) {
        double e = 0, mx = 0;
        id_loop(x, qdd, p, Q1); spatial_chain_20_inverse_dynamics(0, x, qdd, u, p, Q2);
        for (i = 0; i < 20; ++i) { e = fmax(e, fabs(Q1[i] - Q2[i])); mx = fmax(mx, fabs(Q2[i])); }
        printf("max diff %.3g (max |Q| %.3g)\n", e, mx);
    }
    return acc > 1e300;
}
