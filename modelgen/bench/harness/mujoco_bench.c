/* Timing harness for MuJoCo's mj_forward and mj_step, built by
 * modelgen.bench.harnesses.build_mujoco_harness with -DMIN_SECONDS, -DREPEATS
 * and -DSTEP_RESET (mj_step restarts from x0 every STEP_RESET steps).
 * Usage: mjbench model.xml state.txt [K], where state.txt holds qpos then qvel
 * (nq + nv numbers).  With K, it calls mj_forward K times untimed and exits
 * (for callgrind).  mjbench model.xml state.txt inverse [K] does the same with
 * mj_inverse at the accelerations 0.3 (i mod 3) - 0.2 (bench/inverse_dynamics.py),
 * printing its best time.  mjbench model.xml state.txt transition [K] does it with
 * mjd_transitionFD (central differences, eps 1e-6; the model's integrator
 * replaced by Euler, MuJoCo's default, so that each perturbation is one step),
 * the discrete transition Jacobian A = d x_next / d x (bench/derivatives.py). */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <mujoco/mujoco.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static mjModel *m;
static mjData *d;
static double q0[1024], v0[1024];
static double sink;
static double *transition;     /* A of mjd_transitionFD, (2 nv + na)^2 */

static void reset(void)
{
    memcpy(d->qpos, q0, sizeof(double) * (size_t)m->nq);
    memcpy(d->qvel, v0, sizeof(double) * (size_t)m->nv);
    d->time = 0.0;
}

static double run_forward(long loops)
{
    long k;
    const int nv = m->nv;
    const double start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % nv);
        d->qpos[j] = q0[j] + 1e-9 * d->qacc[nv - 1 - j];
        mj_forward(m, d);
        sink += d->qacc[nv - 1];
    }
    return now() - start;
}

static double run_inverse(long loops)
{
    long k;
    int i;
    const int nv = m->nv;
    double start;
    for (i = 0; i < nv; ++i)
        d->qacc[i] = 0.3 * (double)(i % 3) - 0.2;
    start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % nv);
        d->qpos[j] = q0[j] + 1e-9 * d->qfrc_inverse[nv - 1 - j];
        mj_inverse(m, d);
        sink += d->qfrc_inverse[nv - 1];
    }
    return now() - start;
}

static double run_transition(long loops)
{
    long k;
    const int nv = m->nv, nx = 2 * m->nv + m->na;
    const double start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % nv);
        d->qpos[j] = q0[j] + 1e-9 * transition[nx * nx - 1 - j];
        mjd_transitionFD(m, d, 1e-6, 1, transition, NULL, NULL, NULL);
        sink += transition[nx * nx - 1];
    }
    return now() - start;
}

static double run_step(long loops)
{
    long k;
    double start;
    reset();
    start = now();
    for (k = 0; k < loops; ++k) {
        if (k % STEP_RESET == 0)
            reset();
        mj_step(m, d);
        sink += d->qacc[0];
    }
    return now() - start;
}

static double best_of(double (*run)(long))
{
    long loops = 1;
    int r;
    double best = 1e300;
    while (run(loops) < MIN_SECONDS)
        loops *= 2;
    for (r = 0; r < REPEATS; ++r) {
        const double t = run(loops) / (double)loops;
        if (t < best)
            best = t;
    }
    return best;
}

int main(int argc, char **argv)
{
    char error[1000] = "";
    FILE *f;
    int i;
    double forward, step;
    if (argc < 3 || argc > 5) {
        fprintf(stderr, "usage: %s model.xml state.txt [inverse | transition] [K]\n", argv[0]);
        return 2;
    }
    m = mj_loadXML(argv[1], NULL, error, sizeof(error));
    if (!m) {
        fprintf(stderr, "mj_loadXML: %s\n", error);
        return 1;
    }
    if (m->nq > 1024 || m->nv > 1024) {
        fprintf(stderr, "model too large for the harness\n");
        return 1;
    }
    d = mj_makeData(m);
    f = fopen(argv[2], "r");
    if (!f) {
        fprintf(stderr, "cannot open %s\n", argv[2]);
        return 1;
    }
    for (i = 0; i < m->nq; ++i)
        if (fscanf(f, "%lf", &q0[i]) != 1) return 1;
    for (i = 0; i < m->nv; ++i)
        if (fscanf(f, "%lf", &v0[i]) != 1) return 1;
    fclose(f);
    reset();
    mj_forward(m, d);
    if (argc >= 4 && strcmp(argv[3], "transition") == 0) {
        const int nx = 2 * m->nv + m->na;
        m->opt.integrator = mjINT_EULER;
        transition = (double *)calloc((size_t)nx * (size_t)nx, sizeof(double));
        if (!transition)
            return 1;
        if (argc == 5)
            run_transition(atol(argv[4]));
        else
            printf("%.9e ", best_of(run_transition));
        printf("%.17g\n", sink);
        free(transition);
        return 0;
    }
    if (argc >= 4 && strcmp(argv[3], "inverse") == 0) {
        if (argc == 5)
            run_inverse(atol(argv[4]));
        else
            printf("%.9e ", best_of(run_inverse));
        printf("%.17g\n", sink);
        return 0;
    }
    if (argc == 4) {
        run_forward(atol(argv[3]));
        printf("%.17g\n", sink);
        return 0;
    }
    forward = best_of(run_forward);
    step = best_of(run_step);
    printf("%.9e %.9e %d %.17g\n", forward, step,
           d->warning[mjWARN_BADQACC].number, sink);
    mj_deleteData(d);
    mj_deleteModel(m);
    return 0;
}
