/* Part of mg_integrate.c (included there, not compiled alone): step size
 * control of the adaptive methods: the initial step and the next step after an
 * accepted or a rejected one. */

/* -- initial step (Hairer's hinit) ------------------------------------------------- */

static double mg_hinit(mg_ode *o, double t, const double *x, const double *f0, int order,
                       double hmax, double *x1, double *f1)
{
    const int nx = o->nx;
    double dnf = 0.0, dny = 0.0, der2 = 0.0, der12, h, h1;
    int i;
    for (i = 0; i < nx; ++i) {
        const double sk = o->atol[i] + o->rtol[i] * fabs(x[i]);
        dnf += (f0[i] / sk) * (f0[i] / sk);
        dny += (x[i] / sk) * (x[i] / sk);
    }
    h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : sqrt(dny / dnf) * 0.01;
    if (!(h <= hmax))
        h = hmax;
    for (i = 0; i < nx; ++i)
        x1[i] = x[i] + h * f0[i];
    if (mg_ode_f(o, t + h, x1, f1))
        return h; /* the first step reports the failure */
    for (i = 0; i < nx; ++i) {
        const double sk = o->atol[i] + o->rtol[i] * fabs(x[i]);
        der2 += ((f1[i] - f0[i]) / sk) * ((f1[i] - f0[i]) / sk);
    }
    der2 = sqrt(der2) / h;
    der12 = der2 > sqrt(dnf) ? der2 : sqrt(dnf);
    if (der12 > 1e-15)
        h1 = pow(0.01 / der12, 1.0 / order);
    else
        h1 = 1e-6 > h * 1e-3 ? 1e-6 : h * 1e-3;
    if (!(h1 > 0.0))
        h1 = h;
    h = 100.0 * h < h1 ? 100.0 * h : h1;
    return h < hmax ? h : hmax;
}

/* The next step size after an accepted (err <= 1) or a rejected step. */
static double mg_next_step(int method, int accepted, double h, double err, long n_accepted,
                           double *facold, double *hacc, double *erracc)
{
    if (method == MG_METHOD_RODAS) {
        double fac = mg_clamp(pow(err, 0.25) / 0.9, 1.0 / 6.0, 5.0);
        if (!accepted)
            return n_accepted == 0 ? 0.1 * h : h / fac;
        if (n_accepted > 1) { /* Gustafsson's predictive controller */
            const double facgus =
                mg_clamp((*hacc / h) * pow(err * err / *erracc, 0.25) / 0.9, 1.0 / 6.0, 5.0);
            fac = fac > facgus ? fac : facgus;
        }
        *hacc = h;
        *erracc = err > 1e-2 ? err : 1e-2;
        return h / fac;
    } else {
        /* Hairer's dopri5 (beta = 0.04, ratio in [0.2, 10]) and dop853 (beta = 0, [1/3, 6]) */
        const int dp5 = method == MG_METHOD_DOPRI5;
        const double expo = dp5 ? 0.2 - 0.04 * 0.75 : 0.125, beta = dp5 ? 0.04 : 0.0;
        const double facc1 = dp5 ? 5.0 : 1.0 / 0.333, facc2 = dp5 ? 0.1 : 1.0 / 6.0;
        const double fac11 = pow(err, expo);
        if (!accepted)
            return h / (facc1 < fac11 / 0.9 ? facc1 : fac11 / 0.9);
        h /= mg_clamp(fac11 / pow(*facold, beta) / 0.9, facc2, facc1);
        *facold = err > 1e-4 ? err : 1e-4;
        return h;
    }
}
