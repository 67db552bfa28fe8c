/* Integrate a modelgen-generated double pendulum in plain C (no Python).
 *
 * Classic fourth-order Runge-Kutta with a fixed step, default parameters and
 * the motor torque T1 = 0, from a given initial state.  Prints the final state
 * and the drift of the total energy (kinetic + potential), which a conservative
 * system keeps constant: the drift measures the integration error.
 *
 * Usage: double_pendulum_rk4 [t_end [h [q1 q2 q1_dot q2_dot]]]
 *        (defaults: 10 s, 1e-3 s, state -0.5 0.5 0 0).  q1 is the angle of rod 1
 *        from the x axis of E, q2 that of rod 2 from rod 1, in rad; gravity is
 *        along -y, so the pendulum hangs straight down at q1 = -pi/2, q2 = 0.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "double_pendulum.h"

#define NX DOUBLE_PENDULUM_NX

/* One RK4 step of size h from (t, x) into x_next.  Returns the first nonzero
 * status of double_pendulum_rhs (mass matrix not positive definite), else 0. */
static int rk4_step(double t, double h, const double *x, const double *u,
                    const double *p, double *x_next)
{
    double k1[NX], k2[NX], k3[NX], k4[NX], xs[NX];
    int i, status;

    if ((status = double_pendulum_rhs(t, x, u, p, k1)) != 0) return status;
    for (i = 0; i < NX; ++i) xs[i] = x[i] + 0.5 * h * k1[i];
    if ((status = double_pendulum_rhs(t + 0.5 * h, xs, u, p, k2)) != 0) return status;
    for (i = 0; i < NX; ++i) xs[i] = x[i] + 0.5 * h * k2[i];
    if ((status = double_pendulum_rhs(t + 0.5 * h, xs, u, p, k3)) != 0) return status;
    for (i = 0; i < NX; ++i) xs[i] = x[i] + h * k3[i];
    if ((status = double_pendulum_rhs(t + h, xs, u, p, k4)) != 0) return status;
    for (i = 0; i < NX; ++i)
        x_next[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    return 0;
}

/* Total energy: out[0] kinetic + out[1] potential, x = [q, qd]. */
static double total_energy(const double *x, const double *p)
{
    double e[2];
    double_pendulum_energy(x, x + DOUBLE_PENDULUM_NQ, p, e);
    return e[0] + e[1];
}

int main(int argc, char **argv)
{
    double p[DOUBLE_PENDULUM_NP];
    double u[DOUBLE_PENDULUM_NU] = {0.0};          /* T1 = 0: no motor torque */
    double x[NX] = {-0.5, 0.5, 0.0, 0.0};           /* q1, q2 [rad], q1_dot, q2_dot [rad/s] */
    double t_end = 10.0, h = 1e-3, t = 0.0, e0, e1;
    long k, steps;
    int i;

    if (argc > 1) t_end = atof(argv[1]);
    if (argc > 2) h = atof(argv[2]);
    if (argc > 3 && argc != 3 + NX) {
        fprintf(stderr, "usage: %s [t_end [h [q1 q2 q1_dot q2_dot]]]\n", argv[0]);
        return EXIT_FAILURE;
    }
    for (i = 0; argc > 3 && i < NX; ++i) x[i] = atof(argv[3 + i]);
    if (!(t_end >= 0.0) || !(h > 0.0)) {
        fprintf(stderr, "need t_end >= 0 and h > 0\n");
        return EXIT_FAILURE;
    }
    if (double_pendulum_abi_version() != DOUBLE_PENDULUM_ABI_VERSION) {
        fprintf(stderr, "double_pendulum.c and .h were generated for different ABIs\n");
        return EXIT_FAILURE;
    }

    double_pendulum_default_parameters(p);
    e0 = total_energy(x, p);
    steps = (long)floor(t_end / h + 0.5);
    for (k = 0; k < steps; ++k) {
        int status = rk4_step(t, h, x, u, p, x);
        if (status != 0) {
            fprintf(stderr, "double_pendulum_rhs failed at t = %.6g s: mass matrix not "
                    "positive definite (Cholesky pivot %d)\n", t, status);
            return EXIT_FAILURE;
        }
        t = (double)(k + 1) * h;
    }
    e1 = total_energy(x, p);

    printf("steps: %ld of h = %.17g s, t = %.17g s\n", steps, h, t);
    printf("final state:");
    for (i = 0; i < NX; ++i) printf(" %.17g", x[i]);
    printf("\n");
    printf("energy: initial %.17g J, final %.17g J\n", e0, e1);
    printf("energy drift: %.17g J (relative %.3g)\n", e1 - e0,
           (e1 - e0) / (fabs(e0) > 0.0 ? fabs(e0) : 1.0));
    return EXIT_SUCCESS;
}
