/* Integrate a modelgen-generated double pendulum in plain C (no Python).
 *
 * double_pendulum_integrate (the model-independent integrators of
 * mg_integrate.c driven through the model's mg_system) with classic
 * fourth-order Runge-Kutta at a fixed step, or dop853 with error control,
 * default parameters and the motor torque T1 = 0, from a given initial state.
 * Prints the final state and the drift of the total energy (kinetic +
 * potential), which a conservative system keeps constant: the drift measures
 * the integration error.  Nothing is allocated: the work array is on the stack.
 *
 * Usage: double_pendulum_sim [t_end [h [q1 q2 q1_dot q2_dot]]]
 *        (defaults: 10 s, 1e-3 s, state -0.5 0.5 0 0).  h > 0 is the RK4 step;
 *        h = 0 selects dop853 at rtol = atol = 1e-12 instead.  q1 is the angle
 *        of rod 1 from the x axis of E, q2 that of rod 2 from rod 1, in rad;
 *        gravity is along -y, so the pendulum hangs straight down at
 *        q1 = -pi/2, q2 = 0.  Arguments that are not numbers, t_end <= 0,
 *        h < 0, more than 1e8 steps or a wrong count are refused with the usage
 *        line and EXIT_FAILURE.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "double_pendulum.h"

#define NX DOUBLE_PENDULUM_NX

/* Total energy: out[0] kinetic + out[1] potential, x = [q, qd]. */
static double total_energy(const double *x, const double *p)
{
    double e[2];
    double_pendulum_energy(x, x + DOUBLE_PENDULUM_NQ, p, e);
    return e[0] + e[1];
}

#define USAGE "usage: %s [t_end [h [q1 q2 q1_dot q2_dot]]]\n" \
              "  t_end > 0 [s], h >= 0 [s] (0 selects dop853), at most 1e8 steps of h\n"

/* Parse the whole of text as a double into *value; 0 if it is not a number
 * (empty, trailing characters, out of range) or not finite. */
static int parse_number(const char *text, double *value)
{
    char *end;
    errno = 0;
    *value = strtod(text, &end);
    return end != text && *end == '\0' && errno != ERANGE && isfinite(*value);
}

int main(int argc, char **argv)
{
    double p[DOUBLE_PENDULUM_NP];
    double x0[NX] = {-0.5, 0.5, 0.0, 0.0};          /* q1, q2 [rad], q1_dot, q2_dot [rad/s] */
    double x[NX], tol[NX], stop[MG_STOP_X + NX], work[DOUBLE_PENDULUM_WORK_SIZE];
    double t_end = 10.0, h = 1e-3, t_reached, e0, e1;
    mg_options options;
    mg_output output;
    mg_stats stats;
    int i, status;

    if (argc > 3 && argc != 3 + NX) {
        fprintf(stderr, "%s: expected 0, 1, 2 or %d arguments, got %d\n" USAGE,
                argv[0], 2 + NX, argc - 1, argv[0]);
        return EXIT_FAILURE;
    }
    for (i = 1; i < argc && i <= 2; ++i) {
        if (!parse_number(argv[i], i == 1 ? &t_end : &h)) {
            fprintf(stderr, "%s: %s '%s' is not a finite number\n" USAGE, argv[0],
                    i == 1 ? "t_end" : "h", argv[i], argv[0]);
            return EXIT_FAILURE;
        }
    }
    /* the state may be NaN on purpose (the integrator reports it), not text */
    for (i = 0; argc > 3 && i < NX; ++i) {
        char *end;
        x0[i] = strtod(argv[3 + i], &end);
        if (end == argv[3 + i] || *end != '\0') {
            fprintf(stderr, "%s: state '%s' is not a number\n" USAGE, argv[0], argv[3 + i], argv[0]);
            return EXIT_FAILURE;
        }
    }
    if (!(t_end > 0.0) || !(h >= 0.0) || (h > 0.0 && t_end / h > 1e8)) {
        fprintf(stderr, "%s: need t_end > 0, h >= 0 and t_end / h <= 1e8 steps, got t_end = %g, h = %g\n"
                USAGE, argv[0], t_end, h, argv[0]);
        return EXIT_FAILURE;
    }
    if (double_pendulum_abi_version() != DOUBLE_PENDULUM_ABI_VERSION ||
        DOUBLE_PENDULUM_ABI_VERSION != MG_ABI_VERSION) {
        fprintf(stderr, "double_pendulum.c/.h and mg_integrate.h were generated for different ABIs\n");
        return EXIT_FAILURE;
    }

    double_pendulum_default_parameters(p);
    for (i = 0; i < NX; ++i) tol[i] = 1e-12;
    memset(&options, 0, sizeof options);          /* no events, no resume, inputs u = 0 */
    options.method = h > 0.0 ? MG_METHOD_RK4 : MG_METHOD_DOP853;
    options.fixed_step = h;
    options.rtol = tol;
    options.atol = tol;
    options.max_steps = 100000000;
    memset(&output, 0, sizeof output);            /* only the final state: t_eval = {t_end} */
    output.capacity = 1;
    output.t_eval = &t_end;
    output.x = x;
    output.stop = stop;

    e0 = total_energy(x0, p);
    status = double_pendulum_integrate(0.0, t_end, x0, p, NULL, &options, &output, &stats, work);
    t_reached = stop[0];
    if (status != MG_STATUS_SUCCESS) {
        fprintf(stderr, "double_pendulum_integrate failed at t = %.6g s (status %d): %s\n",
                stop[2], status,
                status == MG_STATUS_MASS_MATRIX ? "mass matrix not positive definite" :
                status == MG_STATUS_NON_FINITE ? "NaN or Inf in the state" : "see mg_integrate.h");
        return EXIT_FAILURE;
    }
    e1 = total_energy(x, p);

    if (h > 0.0)
        printf("steps: %ld of h = %.17g s, t = %.17g s\n", stats.naccept, h, t_reached);
    else
        printf("steps: %ld of dop853 (%ld rejected, %ld rhs calls), t = %.17g s\n",
               stats.naccept, stats.nreject, stats.nfev, t_reached);
    printf("final state:");
    for (i = 0; i < NX; ++i) printf(" %.17g", x[i]);
    printf("\n");
    printf("energy: initial %.17g J, final %.17g J\n", e0, e1);
    printf("energy drift: %.17g J (relative %.3g)\n", e1 - e0,
           (e1 - e0) / (fabs(e0) > 0.0 ? fabs(e0) : 1.0));
    return EXIT_SUCCESS;
}
