/* Part of mg_integrate.c (included there, not compiled alone): the implicit
 * Gauss-Legendre methods midpoint (s = 1) and gauss4 (s = 2), fixed step,
 * solved by simplified Newton, halving a step whose iteration fails. */

/* -- Gauss-Legendre: implicit midpoint (s = 1) and 2-stage Gauss (s = 2) ---------- */

static const double mg_gl1_a[1] = {0.5};
static const double mg_gl1_c[1] = {0.5};
static const double mg_gl1_d[1] = {2.0};
/* 1/4 -+ sqrt(3)/6 off the diagonal; c = 1/2 -+ sqrt(3)/6; d = b^T A^-1 = (-sqrt(3), sqrt(3)) */
/* clang-format off */
static const double mg_gl2_a[4] = {0.25, 0.25 - 0.28867513459481287,
                                   0.25 + 0.28867513459481287, 0.25};
/* clang-format on */
static const double mg_gl2_c[2] = {0.5 - 0.28867513459481287, 0.5 + 0.28867513459481287};
static const double mg_gl2_d[2] = {-1.7320508075688772, 1.7320508075688772};

/* Most simplified Newton iterations per Gauss step. */
#define MG_GAUSS_MAXIT 50
/* How many times a fixed Gauss step whose Newton iteration fails is halved. */
#define MG_GAUSS_HALVINGS 3

/* Solves Z_i = h sum_j a_ij f(t + c_j h, x + Z_j) by simplified Newton with J at
 * (t + h/2, x), to round-off; xn = x + sum_i d_i Z_i.  K holds Z, F, dZ, xs
 * (K[0 .. 7 nx)).  Convergence is judged by the contraction rate, as in
 * Hairer's radau5: theta = |dZ_k| / |dZ_k-1| (from the third iteration on, the
 * geometric mean of the last two ratios); the iteration gives up when
 * theta >= 1 (no contraction) or when theta^(iterations left) / (1 - theta) |dZ|
 * predicts it cannot converge within MG_GAUSS_MAXIT.  The caller halves the
 * step on failure (mg_step_gauss_halving). */
static int mg_step_gauss(mg_ode *o, int s, double t, const double *x, const double *f0, double h,
                         double *xn, double *K, double *J, double *M, double *piv)
{
    const int nx = o->nx;
    const double *a = s == 1 ? mg_gl1_a : mg_gl2_a;
    const double *c = s == 1 ? mg_gl1_c : mg_gl2_c;
    const double *d = s == 1 ? mg_gl1_d : mg_gl2_d;
    const int n = s * nx;
    double *Z = K, *F = K + 2 * nx, *dZ = K + 4 * nx, *xs = K + 6 * nx;
    double dn = 0.0, dn_old = 0.0, thq_old = 1.0;
    int i, j, r, q, it, status, converged = 0;
    if ((status = mg_ode_jacobian(o, t + 0.5 * h, x, J)))
        return status;
    for (i = 0; i < s; ++i)
        for (r = 0; r < nx; ++r)
            for (j = 0; j < s; ++j)
                for (q = 0; q < nx; ++q)
                    M[(i * nx + r) * n + j * nx + q] =
                        (i == j && r == q ? 1.0 : 0.0) - h * a[i * s + j] * J[r * nx + q];
    o->stats->nlu += 1;
    if (mg_lu(M, n, piv))
        return MG_STATUS_IMPLICIT_FAILED;
    for (i = 0; i < s; ++i)
        for (r = 0; r < nx; ++r)
            Z[i * nx + r] = c[i] * h * f0[r];
    for (it = 0; it < MG_GAUSS_MAXIT && !converged; ++it) {
        for (i = 0; i < s; ++i) {
            for (r = 0; r < nx; ++r)
                xs[r] = x[r] + Z[i * nx + r];
            /* an iterate that overflowed is a diverging iteration, halved like one */
            if ((status = mg_ode_f(o, t + c[i] * h, xs, F + i * nx)))
                return status == MG_STATUS_NON_FINITE ? MG_STATUS_IMPLICIT_FAILED : status;
        }
        for (i = 0; i < s; ++i)
            for (r = 0; r < nx; ++r) {
                double v = -Z[i * nx + r];
                for (j = 0; j < s; ++j)
                    v += h * a[i * s + j] * F[j * nx + r];
                dZ[i * nx + r] = v;
            }
        mg_lu_solve(M, n, piv, dZ);
        o->stats->nnewton += 1;
        dn = 0.0;
        for (i = 0; i < s; ++i)
            for (r = 0; r < nx; ++r) {
                const double v = dZ[i * nx + r] / (1.0 + fabs(x[r]));
                Z[i * nx + r] += dZ[i * nx + r];
                dn += v * v;
            }
        dn = sqrt(dn / n);
        if (!(dn - dn == 0.0))
            return MG_STATUS_IMPLICIT_FAILED;
        if (dn <= 4.0 * MG_UROUND)
            converged = 1;
        else if (it > 0) {
            const double thq = dn / dn_old;
            const double theta = it == 1 ? thq : sqrt(thq * thq_old);
            thq_old = thq;
            if (theta >= 1.0) { /* no contraction: round-off, or divergence */
                if (dn <= 1e-12)
                    converged = 1;
                else
                    return MG_STATUS_IMPLICIT_FAILED;
            } else if (theta / (1.0 - theta) * dn <= 4.0 * MG_UROUND) {
                converged = 1; /* the remaining error is below round-off */
            } else if (pow(theta, MG_GAUSS_MAXIT - 1 - it) / (1.0 - theta) * dn > 1e-12) {
                return MG_STATUS_IMPLICIT_FAILED; /* too slow to converge in time */
            }
        }
        dn_old = dn;
    }
    if (!converged)
        return MG_STATUS_IMPLICIT_FAILED;
    for (r = 0; r < nx; ++r) {
        double v = x[r];
        for (i = 0; i < s; ++i)
            v += d[i] * Z[i * nx + r];
        xn[r] = v;
    }
    return 0;
}

/* One Gauss step from t to t + h; when its Newton iteration fails, the two halves
 * instead (recursively, down to h / 2^depth), so a fixed-step run keeps its grid.
 * Each level keeps its midpoint state and its xdot in K[8 nx + 2 nx level ...),
 * beyond what mg_step_gauss uses (3 levels: up to K[14 nx) of 17 nx). */
static int mg_step_gauss_halving(mg_ode *o, int s, double t, const double *x, const double *f0,
                                 double h, double *xn, double *K, double *J, double *M, double *piv,
                                 int depth)
{
    const int nx = o->nx;
    double *xm = K + 8 * nx + 2 * nx * (MG_GAUSS_HALVINGS - depth), *fm = xm + nx;
    int status = mg_step_gauss(o, s, t, x, f0, h, xn, K, J, M, piv);
    if (status != MG_STATUS_IMPLICIT_FAILED || depth == 0)
        return status;
    if ((status = mg_step_gauss_halving(o, s, t, x, f0, 0.5 * h, xm, K, J, M, piv, depth - 1)))
        return status;
    if ((status = mg_ode_f(o, t + 0.5 * h, xm, fm)))
        return status;
    return mg_step_gauss_halving(o, s, t + 0.5 * h, xm, fm, 0.5 * h, xn, K, J, M, piv, depth - 1);
}
