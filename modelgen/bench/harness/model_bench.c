/* Harness of a generated model's <name>_rhs_prepared (or, with -DMG_INVERSE,
 * <name>_inverse_dynamics at the accelerations 0.3 (i mod 3) - 0.2; with
 * -DMG_DERIVATIVES, <name>_derivatives into dqdd_dq, dqdd_dv, dqdd_du one after
 * the other in the output; with -DMG_JACOBIAN, <name>_jacobian), built by
 * modelgen.bench.harnesses.build_model_harness.
 * No argument: prints the best time per call, the loops, the status and a sink.
 * K: K calls untimed, then the status and the sink (for callgrind).
 *
 * The model and its state come in as macros, so one file serves every model:
 *   MG_HEADER      the model's header, a string ("<name>.h")
 *   MG_MODEL       the model's prefix (<name>)
 *   MG_NPD_ALLOC   the header's <NAME>_NPD_ALLOC
 *   MG_NX, MG_NOUT the lengths of x and of the output
 *   MG_NP, MG_NU   the lengths of p and u (at least 1)
 *   MG_N           the number of coordinates (MG_DERIVATIVES only; the output
 *                  holds dqdd_du when it is longer than 2 MG_N^2)
 *   MG_X0, MG_P    x0 and p as comma-separated numbers
 *   MIN_SECONDS, REPEATS   the timing rule (min over REPEATS runs of >= MIN_SECONDS) */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include MG_HEADER

#define MG_CAT_(a, b) a##_##b
#define MG_CAT(a, b) MG_CAT_(a, b)
#define MG_FN(f) MG_CAT(MG_MODEL, f)

#define NX MG_NX
#define NOUT MG_NOUT

#if defined(MG_INVERSE)
#define CALL() (MG_FN(inverse_dynamics)(0.0, x, a, u, p, out), 0)
#elif defined(MG_JACOBIAN)
#define CALL() MG_FN(jacobian)(0.0, x, u, p, out)
#elif defined(MG_DERIVATIVES)
#if NOUT > 2 * MG_N * MG_N
#define MG_DU (out + 2 * MG_N * MG_N)
#else
#define MG_DU NULL      /* no inputs: the model leaves dqdd_du untouched */
#endif
#define CALL() MG_FN(derivatives)(0.0, x, u, p, out, out + MG_N * MG_N, MG_DU)
#else
#define CALL() MG_FN(rhs_prepared)(0.0, x, u, p, pd, out)
#endif

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static const double x0[NX] = {MG_X0};
static const double p[MG_NP] = {MG_P};
static double pd[MG_NPD_ALLOC];
static double u[MG_NU];
static double x[NX], a[NX], out[NOUT];
static int status;
static double sink;

/* ``loops`` calls; x[j] is reset to x0[j] plus a tiny amount taken from the
 * previous output, so every call depends on the one before. */
static double run(long loops)
{
    long k;
    const double start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % NX);
        x[j] = x0[j] + 1e-9 * out[NOUT - 1 - j % NOUT];
        status |= CALL();
        sink += out[NOUT - 1];
    }
    return now() - start;
}

int main(int argc, char **argv)
{
    long loops = 1;
    int r, i;
    double best = 1e300;
    for (i = 0; i < NX; ++i) {
        x[i] = x0[i];
        a[i] = 0.3 * (double)(i % 3) - 0.2;     /* accelerations, for inverse dynamics */
    }
    MG_FN(prepare)(p, pd);      /* once, as the peers' models hold their inertias */
    status = CALL();
    if (argc == 2) {
        run(atol(argv[1]));
        printf("%d %.17g\n", status, sink);
        return 0;
    }
    while (run(loops) < MIN_SECONDS)
        loops *= 2;
    for (r = 0; r < REPEATS; ++r) {
        const double t = run(loops) / (double)loops;
        if (t < best)
            best = t;
    }
    printf("%.9e %ld %d %.17g\n", best, loops, status, sink);
    return 0;
}
