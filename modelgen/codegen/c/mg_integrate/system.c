/* Part of mg_integrate.c (included there, not compiled alone): the problem as the
 * methods see it (mg_ode): the system, its parameters, inputs and tolerances;
 * every evaluation of the rhs and its Jacobian goes through here and is counted
 * in the statistics; and the error norm of the adaptive methods. */

/* cube root of the unit round-off: the central difference step */
#define MG_FD_STEP 6.0554544523933395e-06

typedef struct {
    const mg_system *sys;
    int nx;
    const double *p;
    const mg_inputs *in;
    const double *rtol;
    const double *atol;
    mg_stats *stats;
    double t_fail;
    int n_events;
    int (*events)(void *, double, const double *, double *);
    void *ctx;
    double *u;       /* u[nu] at the last evaluation */
    double *fd_work; /* 3 nx for central differences */
} mg_ode;

/* Inputs at (t, x): the callback, or n samples (times ts[n], values vs[n][nu])
 * interpolated linearly or held, end values held outside the samples.
 * Returns nonzero when the callback failed. */
static int mg_inputs_at(const mg_inputs *in, int nu, double t, const double *x, double *u)
{
    long lo, hi, mid, n;
    const double *ts, *vs;
    int i;
    if (in && in->callback)
        return in->callback(in->ctx, t, x, u);
    n = in ? in->n : 0;
    if (n <= 0) {
        for (i = 0; i < nu; ++i)
            u[i] = 0.0;
        return 0;
    }
    ts = in->times;
    vs = in->values;
    if (n == 1 || t <= ts[0]) {
        for (i = 0; i < nu; ++i)
            u[i] = vs[i];
        return 0;
    }
    if (t >= ts[n - 1]) {
        for (i = 0; i < nu; ++i)
            u[i] = vs[(n - 1) * nu + i];
        return 0;
    }
    lo = 0;
    hi = n - 1;
    while (hi - lo > 1) { /* ts[lo] <= t < ts[hi] */
        mid = lo + (hi - lo) / 2;
        if (ts[mid] <= t)
            lo = mid;
        else
            hi = mid;
    }
    for (i = 0; i < nu; ++i) {
        const double a = vs[lo * nu + i], b = vs[hi * nu + i];
        u[i] = in->hold ? a : a + (b - a) * (t - ts[lo]) / (ts[hi] - ts[lo]);
    }
    return 0;
}

/* xdot at (t, x) with the inputs at (t, x); counts the evaluation.
 * A failing Cholesky pivot at a finite state is a mass matrix failure; a
 * non-finite state or xdot (an infinite input, an overflow) is NON_FINITE. */
static int mg_ode_f(mg_ode *o, double t, const double *x, double *f)
{
    const int nx = o->nx;
    int status;
    if (mg_inputs_at(o->in, o->sys->nu, t, x, o->u)) {
        o->t_fail = t;
        return MG_STATUS_INPUT_ERROR;
    }
    status = o->sys->rhs(o->sys->model, t, x, o->u, o->p, f);
    o->stats->nfev += 1;
    if (!mg_finite(x, nx) || (!status && !mg_finite(f, nx))) {
        o->t_fail = t;
        return MG_STATUS_NON_FINITE;
    }
    if (status) {
        o->stats->pivot = status;
        o->t_fail = t;
        return MG_STATUS_MASS_MATRIX;
    }
    return 0;
}

/* Central differences of the rhs, column by column: J[i*nx + j] = d xdot_i / d x_j.
 * Step cbrt(eps) * max(1, |x_j|); error about eps^(2/3) relative.  work: 3 nx.
 * With feedback inputs (a callback u(t, x) in `in`), the closed loop
 * xdot(t, x, u(t, x)) is differentiated: u is recomputed into u at each point. */
static int mg_fd_jacobian(const mg_system *sys, const mg_inputs *in, double t, const double *x,
                          double *u, const double *p, double *J, long *nfev, double *work)
{
    const int nx = sys->nx, feedback = in && in->callback;
    double *xp = work, *fp = work + nx, *fm = work + 2 * nx;
    int i, j, status;
    mg_copy(xp, x, nx);
    for (j = 0; j < nx; ++j) {
        const double scale = fabs(x[j]) > 1.0 ? fabs(x[j]) : 1.0;
        double hi, lo;
        xp[j] = x[j] + MG_FD_STEP * scale;
        hi = xp[j];
        if (feedback && in->callback(in->ctx, t, xp, u))
            return -1;
        status = sys->rhs(sys->model, t, xp, u, p, fp);
        *nfev += 1;
        if (status)
            return status;
        xp[j] = x[j] - MG_FD_STEP * scale;
        lo = xp[j];
        if (feedback && in->callback(in->ctx, t, xp, u))
            return -1;
        status = sys->rhs(sys->model, t, xp, u, p, fm);
        *nfev += 1;
        if (status)
            return status;
        for (i = 0; i < nx; ++i)
            J[i * nx + j] = (fp[i] - fm[i]) / (hi - lo);
        xp[j] = x[j];
    }
    return 0;
}

MG_WEAK int mg_jacobian_fd(const mg_system *system, double t, const double *x, const double *u,
                           const double *p, double *J, double *work)
{
    long nfev = 0;
    return mg_fd_jacobian(system, NULL, t, x, (double *)u, p, J, &nfev, work);
}

/* The Jacobian the implicit methods use: the system's own, else (and always with
 * feedback inputs, whose d u / d x the system's does not know) central differences. */
static int mg_ode_jacobian(mg_ode *o, double t, const double *x, double *J)
{
    const int feedback = o->in && o->in->callback;
    int status;
    if (mg_inputs_at(o->in, o->sys->nu, t, x, o->u)) {
        o->t_fail = t;
        return MG_STATUS_INPUT_ERROR;
    }
    o->stats->njev += 1;
    if (o->sys->jacobian && !feedback)
        status = o->sys->jacobian(o->sys->model, t, x, o->u, o->p, J);
    else
        status = mg_fd_jacobian(o->sys, o->in, t, x, o->u, o->p, J, &o->stats->nfev, o->fd_work);
    if (status < 0) {
        o->t_fail = t;
        return MG_STATUS_INPUT_ERROR;
    }
    if (status) {
        o->stats->pivot = status;
        o->t_fail = t;
        return MG_STATUS_MASS_MATRIX;
    }
    return 0;
}

/* Error norm sqrt(mean((e_i / (atol_i + rtol_i * max(|xa_i|, |xb_i|)))^2)). */
static double mg_ode_norm(const mg_ode *o, const double *e, const double *xa, const double *xb)
{
    const int nx = o->nx;
    double s = 0.0;
    int i;
    for (i = 0; i < nx; ++i) {
        const double a = fabs(xa[i]), b = fabs(xb[i]);
        const double r = e[i] / (o->atol[i] + o->rtol[i] * (a > b ? a : b));
        s += r * r;
    }
    return sqrt(s / nx);
}
