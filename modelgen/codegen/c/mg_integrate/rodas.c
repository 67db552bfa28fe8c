/* Part of mg_integrate.c (included there, not compiled alone): RODAS4, the
 * Rosenbrock method for stiff systems, with its Jacobian, one step and its
 * dense output (the step size control is in control.c). */

/* -- rodas4 (Hairer & Wanner, rodas.f, METH = 1) -------------------------------- */

#define MG_RO_GAMMA 0.25
static const double mg_ro_c[4] = {0.0, 0.386, 0.21, 0.63};
/* gamma_i = sum_j gamma_ij: the coefficients of h * d xdot / d t */
static const double mg_ro_g[4] = {0.25, -0.1043, 0.1035, -0.3620000000000023e-01};
/* clang-format off */
static const double mg_ro_a[5][4] = {
    {0.0},
    {0.1544000000000000e+01},
    {0.9466785280815826e+00, 0.2557011698983284e+00},
    {0.3314825187068521e+01, 0.2896124015972201e+01, 0.9986419139977817e+00},
    {0.1221224509226641e+01, 0.6019134481288629e+01, 0.1253708332932087e+02,
     -0.6878860361058950e+00}};
static const double mg_ro_cc[6][5] = {
    {0.0},
    {-0.5668800000000000e+01},
    {-0.2430093356833875e+01, -0.2063599157091915e+00},
    {-0.1073529058151375e+00, -0.9594562251023355e+01, -0.2047028614809616e+02},
    {0.7496443313967647e+01, -0.1024680431464352e+02, -0.3399990352819905e+02,
     0.1170890893206160e+02},
    {0.8083246795921522e+01, -0.7981132988064893e+01, -0.3152159432874371e+02,
     0.1631930543123136e+02, -0.6058818238834054e+01}};
/* dense output */
static const double mg_ro_d[2][5] = {
    {0.1012623508344586e+02, -0.7487995877610167e+01, -0.3480091861555747e+02,
     -0.7992771707568823e+01, 0.1025137723295662e+01},
    {-0.6762803392801253e+00, 0.6087714651680015e+01, 0.1643084320892478e+02,
     0.2476722511418386e+02, -0.6594389125716872e+01}};
/* clang-format on */

/* The Jacobian J (and d xdot / d t by a forward difference) at (t, x), once per step. */
static int mg_rodas_jacobian(mg_ode *o, double t, const double *x, const double *f0, double *J,
                             double *dfdt, double *work)
{
    const int nx = o->nx;
    const double at = fabs(t) > 1e-5 ? fabs(t) : 1e-5;
    const double delta = sqrt(MG_UROUND * at);
    int i, status;
    if ((status = mg_ode_jacobian(o, t, x, J)))
        return status;
    if ((status = mg_ode_f(o, t + delta, x, work)))
        return status;
    for (i = 0; i < nx; ++i)
        dfdt[i] = (work[i] - f0[i]) / delta;
    return 0;
}

/* One step; K[0..4] = k1..k5 (for the dense output), xn = the solution.
 * Returns IMPLICIT_FAILED when the matrix 1/(gamma h) - J is singular. */
static int mg_step_rodas(mg_ode *o, double t, const double *x, const double *f0, double h,
                         double *xn, double *K, const double *J, const double *dfdt, double *M,
                         double *piv, double *err)
{
    const int nx = o->nx;
    double *ys = K + 6 * nx, *fy = K + 7 * nx, *k6 = K + 5 * nx;
    int i, j, s, status;
    for (i = 0; i < nx * nx; ++i)
        M[i] = -J[i];
    for (i = 0; i < nx; ++i)
        M[i * nx + i] += 1.0 / (MG_RO_GAMMA * h);
    o->stats->nlu += 1;
    if (mg_lu(M, nx, piv))
        return MG_STATUS_IMPLICIT_FAILED;
    for (s = 0; s < 6; ++s) {
        double *k = K + s * nx;
        if (s == 0) {
            mg_copy(fy, f0, nx);
        } else {
            if (s < 5) {
                mg_copy(ys, x, nx);
                for (j = 0; j < s; ++j)
                    for (i = 0; i < nx; ++i)
                        ys[i] += mg_ro_a[s][j] * K[j * nx + i];
            } else {
                for (i = 0; i < nx; ++i) /* stage 6: y5 + k5 */
                    ys[i] += K[4 * nx + i];
            }
            if ((status = mg_ode_f(o, t + (s < 4 ? mg_ro_c[s] : 1.0) * h, ys, fy)))
                return status;
        }
        for (i = 0; i < nx; ++i) {
            double v = fy[i];
            for (j = 0; j < s; ++j)
                v += mg_ro_cc[s][j] * K[j * nx + i] / h;
            if (s < 4)
                v += h * mg_ro_g[s] * dfdt[i];
            k[i] = v;
        }
        mg_lu_solve(M, nx, piv, k);
    }
    for (i = 0; i < nx; ++i)
        xn[i] = ys[i] + k6[i];
    *err = mg_ode_norm(o, k6, x, xn);
    return 0;
}

static void mg_dense_rodas(int nx, const double *x, const double *xn, const double *K, double *cont)
{
    int i, j, k;
    for (i = 0; i < nx; ++i) {
        cont[i] = x[i];
        cont[nx + i] = xn[i] - x[i];
        for (k = 0; k < 2; ++k) {
            double v = 0.0;
            for (j = 0; j < 5; ++j)
                v += mg_ro_d[k][j] * K[j * nx + i];
            cont[(2 + k) * nx + i] = v;
        }
    }
}
