/* Part of mg_integrate.c (included there, not compiled alone): events, the sign
 * changes of g = options.events(t, x), located by Brent's method on the dense
 * output of a step. */

/* -- events ---------------------------------------------------------------------- */

static int mg_ode_events(mg_ode *o, double t, const double *x, double *g)
{
    o->stats->ngev += 1;
    if (!o->events(o->ctx, t, x, g))
        return 0;
    o->t_fail = t;
    return MG_STATUS_EVENT_ERROR;
}

/* Event function `which` on the dense output at time tt. */
static int mg_event_at(mg_ode *o, int which, const double *cont, int m, double t_old, double h,
                       double tt, double *xw, double *gw, double *value)
{
    int status;
    mg_dense(o->nx, cont, m, (tt - t_old) / h, xw);
    if ((status = mg_ode_events(o, tt, xw, gw)))
        return status;
    *value = gw[which];
    return 0;
}

/* Brent's zeroin (Brent 1973) on the dense output: the root of event `which`
 * in [a, b], where its values fa, fb have opposite signs. */
static int mg_event_root(mg_ode *o, int which, const double *cont, int m, double t_old, double h,
                         double a, double fa, double b, double fb, double *root, double *xw,
                         double *gw)
{
    const double tol = 4.0 * MG_UROUND * (fabs(t_old) + fabs(h));
    double c = a, fc = fa, d = b - a, e = d;
    int it, status;
    for (it = 0; it < 200; ++it) {
        double tol1, xm;
        if (fabs(fc) < fabs(fb)) {
            a = b;
            b = c;
            c = a;
            fa = fb;
            fb = fc;
            fc = fa;
        }
        tol1 = 2.0 * MG_UROUND * fabs(b) + 0.5 * tol;
        xm = 0.5 * (c - b);
        if (fabs(xm) <= tol1 || fb == 0.0)
            break;
        if (fabs(e) >= tol1 && fabs(fa) > fabs(fb)) {
            double p, q, r, sr = fb / fa;
            if (a == c) {
                p = 2.0 * xm * sr;
                q = 1.0 - sr;
            } else {
                q = fa / fc;
                r = fb / fc;
                p = sr * (2.0 * xm * q * (q - r) - (b - a) * (r - 1.0));
                q = (q - 1.0) * (r - 1.0) * (sr - 1.0);
            }
            if (p > 0.0)
                q = -q;
            else
                p = -p;
            if (2.0 * p < 3.0 * xm * q - fabs(tol1 * q) && p < fabs(0.5 * e * q)) {
                e = d;
                d = p / q;
            } else {
                d = xm;
                e = d;
            }
        } else {
            d = xm;
            e = d;
        }
        a = b;
        fa = fb;
        b += fabs(d) > tol1 ? d : (xm > 0.0 ? tol1 : -tol1);
        if ((status = mg_event_at(o, which, cont, m, t_old, h, b, xw, gw, &fb)))
            return status;
        if ((fb > 0.0) == (fc > 0.0) && fb != 0.0 && fc != 0.0) {
            c = a;
            fc = fa;
            d = b - a;
            e = d;
        }
    }
    *root = b;
    return 0;
}
