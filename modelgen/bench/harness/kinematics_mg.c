/* modelgen's side of bench/kinematics.py: one generated kinematics function,
 * timed the way bench/kinematics_pin.cpp times Pinocchio's.  The script writes
 * kin_case.h beside it: the model's header, NQ, NV, NOUT, the call CALL(q, p,
 * out), the configuration q0 and the parameters p.  Usage:
 *   kinematics_mg          prints the best time per call [s] and the loops
 *   kinematics_mg K        K calls untimed, then a sink (for callgrind) */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "kin_case.h"

static double q[NQ], out[NOUT];
static double sink;

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* each call's q depends on the previous result (the last row's entries), as in
 * Pinocchio's harness */
static double run(long loops)
{
    long k;
    const double start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % NQ);
        q[j] = q0[j] + 1e-12 * out[NOUT - 1 - j % NV];
        CALL(q, p, out);
        sink += out[NOUT - 1];
    }
    return now() - start;
}

int main(int argc, char **argv)
{
    long loops = 1;
    double best = 1e300;
    int i, r;
    for (i = 0; i < NQ; ++i)
        q[i] = q0[i];
    if (argc == 2) {
        run(atol(argv[1]));
        printf("%.17g\n", sink);
        return 0;
    }
    while (run(loops) < 0.05)
        loops *= 2;
    for (r = 0; r < 5; ++r) {
        const double t = run(loops) / (double)loops;
        best = t < best ? t : best;
    }
    printf("%.6e %ld %.17g\n", best, loops, sink);
    return 0;
}
