/* Part of mg_integrate.c (included there, not compiled alone): the explicit
 * Runge-Kutta methods rk4, dopri5 and dop853, each a Butcher tableau (as data;
 * dopri5's and dop853's run by one stage function), with its error estimate
 * and dense output. */

/* One explicit Runge-Kutta stage: xs = x + h sum_j a[j] K_j, ks = f(t + c h, xs). */
static int mg_erk_stage(mg_ode *o, double t, const double *x, double h, const double *a, int s,
                        const double *K, double c, double *xs, double *ks)
{
    const int nx = o->nx;
    int i, j;
    mg_copy(xs, x, nx);
    for (j = 0; j < s; ++j) {
        const double w = h * a[j];
        if (w != 0.0)
            for (i = 0; i < nx; ++i)
                xs[i] += w * K[j * nx + i];
    }
    return ks ? mg_ode_f(o, t + c * h, xs, ks) : 0;
}

/* -- rk4 --------------------------------------------------------------------- */

/* The classic tableau is a subdiagonal: stage s takes x + h a[s] K[s - 1] at t + c[s] h
 * (a = c), so it is stored and run as one, not through mg_erk_stage's full rows.  The
 * weights (1, 2, 2, 1) / 6 are applied in the nested form h/6 (k1 + 2 (k2 + k3) + k4). */
static const double mg_rk4_c[4] = {0.0, 0.5, 0.5, 1.0};

/* Stages 2..4 (K[0] = f0 on entry); xn = the solution. */
static int mg_step_rk4(mg_ode *o, double t, const double *x, double h, double *xn, double *K)
{
    const int nx = o->nx;
    const double *k2 = K + nx, *k3 = K + 2 * nx, *k4 = K + 3 * nx;
    double *xs = K + 4 * nx;
    int i, s, status;
    for (s = 1; s < 4; ++s) {
        const double *k = K + (s - 1) * nx;
        for (i = 0; i < nx; ++i)
            xs[i] = x[i] + mg_rk4_c[s] * h * k[i];
        if ((status = mg_ode_f(o, t + mg_rk4_c[s] * h, xs, K + s * nx)))
            return status;
    }
    for (i = 0; i < nx; ++i)
        xn[i] = x[i] + h / 6.0 * (K[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    return 0;
}

/* -- dopri5 (Hairer & Wanner, dopri5.f) ---------------------------------------- */

static const double mg_dp5_c[7] = {0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0};
/* clang-format off */
static const double mg_dp5_a[7][6] = {
    {0.0},
    {0.2},
    {3.0 / 40.0, 9.0 / 40.0},
    {44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0},
    {19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0},
    {9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0},
    {35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0}};
/* 5th minus 4th order weights */
static const double mg_dp5_e[7] = {71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0,
                                   -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0};
/* Shampine's (1986) dense output */
static const double mg_dp5_d[7] = {-12715105075.0 / 11282082432.0, 0.0,
                                   87487479700.0 / 32700410799.0, -10690763975.0 / 1880347072.0,
                                   701980252875.0 / 199316789632.0, -1453857185.0 / 822651844.0,
                                   69997945.0 / 29380423.0};
/* clang-format on */

/* Stages 2..7 (K[0] = f0 on entry); xn = the 5th-order solution, K[6] = f(t + h, xn). */
static int mg_step_dopri5(mg_ode *o, double t, const double *x, double h, double *xn, double *K,
                          double *err)
{
    const int nx = o->nx;
    double *e = K + 7 * nx;
    int i, j, s, status;
    for (s = 1; s < 7; ++s)
        if ((status = mg_erk_stage(o, t, x, h, mg_dp5_a[s], s, K, mg_dp5_c[s], xn, K + s * nx)))
            return status;
    for (i = 0; i < nx; ++i) {
        double v = 0.0;
        for (j = 0; j < 7; ++j)
            v += mg_dp5_e[j] * K[j * nx + i];
        e[i] = h * v;
    }
    *err = mg_ode_norm(o, e, x, xn);
    return 0;
}

static void mg_dense_dopri5(int nx, const double *x, const double *xn, double h, const double *K,
                            double *cont)
{
    int i, j;
    mg_hermite(nx, x, xn, K, K + 6 * nx, h, cont);
    for (i = 0; i < nx; ++i) {
        double v = 0.0;
        for (j = 0; j < 7; ++j)
            v += mg_dp5_d[j] * K[j * nx + i];
        cont[4 * nx + i] = h * v;
    }
}

/* -- dop853 (Hairer & Wanner, dop853.f) ---------------------------------------- */

/* clang-format off */
static const double mg_dp8_c[16] = {
    0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726,
    0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6,
    0.8571428571428571, 1.0, 1.0, 0.1, 0.2, 0.7777777777777778};
/* row s: the coefficients of stages 0..s-1; row 12 holds the 8th-order weights */
static const double mg_dp8_a[16][15] = {
    {0.0},
    {0.05260015195876773},
    {0.0197250569845379, 0.0591751709536137},
    {0.02958758547680685, 0.0, 0.08876275643042054},
    {0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792},
    {0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242},
    {0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125},
    {0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328,
     -0.015319437748624402, 0.008273789163814023},
    {0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671,
     20.154067550477894, -43.48988418106996},
    {0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193,
     15.279233632882423, -33.28821096898486, -0.020331201708508627},
    {-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927,
     -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196},
    {2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188,
     27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303,
     0.6433927460157636},
    {0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003,
     -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034,
     0.04471061572777259},
    {0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483, -0.2462390374708025,
     -0.12419142326381637, 0.15329179827876568, 0.00820105229563469, 0.007567897660545699,
     -0.008298},
    {0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776, 0.053541988307438566,
     -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932, 0.0003825710908356584,
     -0.00034046500868740456, 0.1413124436746325},
    {-0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599,
     4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145,
     2.9475147891527724, -9.15095847217987}};
/* 8th minus 5th order, and 8th minus 3rd order weights of stages 0..11 */
static const double mg_dp8_e5[12] = {
    0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502,
    1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571,
    -0.022355307863886294};
static const double mg_dp8_e3[12] = {
    -0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003,
    -5.801203960010585, -0.4226823213237919, -0.1521609496625161, 0.20136540080403034,
    0.02265179219836082};
/* dense output: the 4 highest coefficient vectors from the 16 stages */
static const double mg_dp8_d[4][16] = {
    {-8.428938276109013, 0.0, 0.0, 0.0, 0.0, 0.5667149535193777, -3.0689499459498917,
     2.38466765651207, 2.117034582445028, -0.871391583777973, 2.2404374302607883,
     0.6315787787694688, -0.08899033645133331, 18.148505520854727, -9.194632392478356,
     -4.436036387594894},
    {10.427508642579134, 0.0, 0.0, 0.0, 0.0, 242.28349177525817, 165.20045171727028,
     -374.5467547226902, -22.113666853125306, 7.733432668472264, -30.674084731089398,
     -9.332130526430229, 15.697238121770845, -31.139403219565178, -9.35292435884448,
     35.81684148639408},
    {19.985053242002433, 0.0, 0.0, 0.0, 0.0, -387.0373087493518, -189.17813819516758,
     527.8081592054236, -11.57390253995963, 6.8812326946963, -1.0006050966910838,
     0.7777137798053443, -2.778205752353508, -60.19669523126412, 84.32040550667716,
     11.99229113618279},
    {-25.69393346270375, 0.0, 0.0, 0.0, 0.0, -154.18974869023643, -231.5293791760455,
     357.6391179106141, 93.40532418362432, -37.45832313645163, 104.0996495089623,
     29.8402934266605, -43.53345659001114, 96.32455395918828, -39.17726167561544,
     -149.72683625798564}};
/* clang-format on */

/* Stages 2..12 (K[0] = f0 on entry); xn = the 8th-order solution. */
static int mg_step_dop853(mg_ode *o, double t, const double *x, double h, double *xn, double *K,
                          double *err)
{
    const int nx = o->nx;
    double *xs = K + 13 * nx;
    double e5 = 0.0, e3 = 0.0, denom;
    int i, j, s, status;
    for (s = 1; s < 12; ++s)
        if ((status = mg_erk_stage(o, t, x, h, mg_dp8_a[s], s, K, mg_dp8_c[s], xs, K + s * nx)))
            return status;
    mg_erk_stage(o, t, x, h, mg_dp8_a[12], 12, K, 1.0, xn, 0);
    for (i = 0; i < nx; ++i) {
        const double a = fabs(x[i]), b = fabs(xn[i]);
        const double sk = o->atol[i] + o->rtol[i] * (a > b ? a : b);
        double v5 = 0.0, v3 = 0.0;
        for (j = 0; j < 12; ++j) {
            v5 += mg_dp8_e5[j] * K[j * nx + i];
            v3 += mg_dp8_e3[j] * K[j * nx + i];
        }
        e5 += (v5 / sk) * (v5 / sk);
        e3 += (v3 / sk) * (v3 / sk);
    }
    denom = e5 + 0.01 * e3;
    *err = denom > 0.0 ? fabs(h) * e5 / sqrt(denom * nx) : 0.0;
    if (!(denom - denom == 0.0))
        *err = denom;
    return 0;
}

/* K[12] = f(t + h, xn) on entry; computes the three extra stages 13..15. */
static int mg_dense_dop853(mg_ode *o, double t, const double *x, const double *xn, double h,
                           double *K, double *cont)
{
    const int nx = o->nx;
    double *xs = K + 16 * nx;
    int i, j, k, s, status;
    for (s = 13; s < 16; ++s)
        if ((status = mg_erk_stage(o, t, x, h, mg_dp8_a[s], s, K, mg_dp8_c[s], xs, K + s * nx)))
            return status;
    for (i = 0; i < nx; ++i) {
        const double dx = xn[i] - x[i], b = h * K[i] - dx;
        cont[i] = x[i];
        cont[nx + i] = dx;
        cont[2 * nx + i] = b;
        cont[3 * nx + i] = 2.0 * dx - h * (K[12 * nx + i] + K[i]);
        for (k = 0; k < 4; ++k) {
            double v = 0.0;
            for (j = 0; j < 16; ++j)
                v += mg_dp8_d[k][j] * K[j * nx + i];
            cont[(4 + k) * nx + i] = h * v;
        }
    }
    return 0;
}
