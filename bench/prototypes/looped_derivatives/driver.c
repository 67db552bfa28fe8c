#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
void gen_eval(const double *x, const double *p, const double *a, double *W);
void proto_prepare(const double *p);
void proto_eval(const double *x, const double *a, double *W);
#define NC (N > 30 ? 58 : 51)
static double urand(double lo, double hi) { return lo + (hi - lo) * (rand() / (double)RAND_MAX); }
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
int main(int argc, char **argv)
{
    const char *mode = argc > 1 ? argv[1] : "check";
    int K = argc > 2 ? atoi(argv[2]) : 200;
    static double p[2 * N + 2], x[2 * N], a[N], W1[58 * N], W2[58 * N];
    int i, s, c;
    for (i = 0; i < N; ++i) { p[i] = 1.0; p[N + i] = 0.5; }
    p[2 * N] = 0.02; p[2 * N + 1] = 9.81;
    if (!strcmp(mode, "check")) {
        double worst = 0;
        /* also unequal masses and lengths: the tables must follow p */
        for (s = 0; s < 10; ++s) {
            if (s >= 5) for (i = 0; i < N; ++i) { p[i] = urand(0.5, 2); p[N + i] = urand(0.2, 1); }
            proto_prepare(p);
            for (i = 0; i < N; ++i) { x[i] = urand(-M_PI, M_PI); x[N + i] = urand(-2, 2); a[i] = urand(-2, 2); }
            memset(W1, 0, sizeof W1); memset(W2, 0, sizeof W2);
            gen_eval(x, p, a, W1);
            proto_eval(x, a, W2);
            double md = 0, mw = 0; int at = -1;
            for (c = 0; c < NC * N; ++c) {
                double d = fabs(W1[c] - W2[c]);
                if (d > md) { md = d; at = c; }
                if (fabs(W1[c]) > mw) mw = fabs(W1[c]);
            }
            double pc = 0; int pcc = -1;
            for (int cc = 0; cc < NC; ++cc) {
                double dm = 0, wm = 0;
                for (int k = 0; k < N; ++k) {
                    double d = fabs(W1[cc * N + k] - W2[cc * N + k]);
                    if (d > dm) dm = d;
                    if (fabs(W1[cc * N + k]) > wm) wm = fabs(W1[cc * N + k]);
                }
                if (wm > 0 && dm / wm > pc) { pc = dm / wm; pcc = cc; }
                if (wm == 0 && dm > pc) pc = dm;
            }
            printf("  per-component worst %.3g (comp %d)\n", pc, pcc);
            printf("state %d: max|diff| %.3g, max|W| %.3g, ratio %.3g (worst at comp %d dof %d)\n", s, md, mw, md / mw, at / N, at % N);
            if (md / mw > worst) worst = md / mw;
        }
        printf("worst ratio %.3g %s\n", worst, worst <= 1e-12 ? "OK" : "FAIL");
        return worst <= 1e-12 ? 0 : 1;
    }
    proto_prepare(p);
    srand(7);
    for (i = 0; i < N; ++i) { x[i] = urand(-M_PI, M_PI); x[N + i] = urand(-2, 2); a[i] = urand(-2, 2); }
    int gen = !strcmp(mode, "gen");
    if (!strcmp(mode, "gen") || !strcmp(mode, "proto")) {
        for (s = 0; s < K; ++s) { if (gen) gen_eval(x, p, a, W1); else proto_eval(x, a, W1); x[0] += 1e-9 * W1[N]; }
        printf("%g\n", W1[3 * N]);
        return 0;
    }
    /* time: min over repeats of the mean of K calls */
    for (gen = 1; gen >= 0; --gen) {
        double best = 1e9;
        for (s = 0; s < 15; ++s) {
            double t0 = now();
            for (i = 0; i < K; ++i) { if (gen) gen_eval(x, p, a, W1); else proto_eval(x, a, W1); }
            double t = (now() - t0) / K;
            if (t < best) best = t;
        }
        printf("%s: %.3f us/call\n", gen ? "unrolled" : "looped", best * 1e6);
    }
    return 0;
}
