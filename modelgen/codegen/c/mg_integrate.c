/* ---------------------------------------------------------------------------
 * mg_integrate: modelgen's integrators, the whole integration loop in C, for
 * any mg_system.  The same for every model: copied unchanged from modelgen's
 * package (modelgen/codegen/c/) next to each model's C; change them there.
 *
 *   rk4       classic Runge-Kutta, fixed step.
 *   dopri5    Dormand-Prince 5(4), FSAL, PI step control (safety 0.9, step
 *             ratio in [0.2, 10], beta = 0.04), Shampine's 4th-order dense
 *             output.  Coefficients: Hairer & Wanner, dopri5.f.
 *   dop853    Dormand-Prince 8(5,3), combined 5th/3rd-order error estimate,
 *             step ratio in [1/3, 6], beta = 0, 7th-order dense output (three
 *             extra stages, computed only when a step is sampled or an event
 *             is located in it).  Coefficients: Hairer & Wanner, dop853.f (as
 *             tabulated in scipy/integrate/_ivp/dop853_coefficients.py).
 *   rodas4    Rosenbrock 4(3), 6 stages, L-stable, stiffly accurate, with the
 *             Jacobian d xdot / d x and a finite difference d xdot / d t;
 *             Gustafsson's predictive step control; 3rd-order dense output.
 *             Coefficients: Hairer & Wanner II, IV.7, rodas.f with METH = 1.
 *   midpoint  implicit midpoint rule (1-stage Gauss-Legendre, order 2), and
 *   gauss4    2-stage Gauss-Legendre (order 4): implicit, symplectic, fixed
 *             step; simplified Newton iteration to round-off.
 *
 * rk4, midpoint and gauss4 sample through the cubic Hermite interpolant of
 * x and xdot at both ends of the step (3rd-order dense output).  dopri5,
 * dop853 and rodas4 can also run with a fixed step (no error control), which
 * the tests use to measure their order.
 *
 * No allocation: the caller's work array holds every vector, sized at run
 * time from the system (MG_WORK_SIZE).  The constants are in mg_integrate.h,
 * rendered from modelgen/codegen/capi.py, which also holds the messages.
 *
 * One translation unit: this file is the driver and includes the method families
 * of mg_integrate/ (numerics, the system, explicit Runge-Kutta, rodas, Gauss,
 * events, step size control), not compiled alone; a C user compiles this file.
 *
 * Each output directory holds a copy of this file, and a program that embeds
 * several models compiles them all: with gcc or clang on ELF and Mach-O the four
 * public functions are weak, so the linker keeps one copy.  Their link names carry
 * the ABI version (mg_integrate.h): only copies of one interface merge, and those
 * of two stay apart, each serving its own models.  PE/COFF: compile one copy.
 * ------------------------------------------------------------------------- */
#if (defined(__GNUC__) || defined(__clang__)) && (defined(__ELF__) || defined(__APPLE__))
#define MG_WEAK __attribute__((weak))
#else
#define MG_WEAK
#endif

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <string.h>
#include "mg_integrate.h"

#include "mg_integrate/numerics.c"
#include "mg_integrate/system.c"
#include "mg_integrate/erk.c"
#include "mg_integrate/rodas.c"
#include "mg_integrate/gauss.c"
#include "mg_integrate/events.c"
#include "mg_integrate/control.c"

/* -- the driver ----------------------------------------------------------------- */

/* One call of mg_integrate: its arguments, the vectors of the work array and the
 * state of the step loop. */
typedef struct {
    mg_ode o;
    const mg_system *sys;
    const mg_options *opt;
    mg_output *out;
    int nx, method, adaptive, n_events;
    double t0, t1;
    /* the work array (mg_layout) */
    double *x, *xn, *f0, *f1, *x_cut, *xw, *dfdt, *K, *cont, *J, *M, *piv;
    double *g_old, *g_new, *g_work, *hit_t;
    /* the step from t to t_new: size h, error norm err, the controller's memory */
    double t, t_new, h, hmax, err, facold, hacc, erracc, t_origin;
    long rows, found, attempts, n_fixed, done_steps;
    int m, reject, last, dense_ready, fresh_jacobian, singular, overflowed;
    /* the sign of the system's chart at the last accepted state (0: not known) */
    int orientation;
    /* the events: found in the step (sorted by time), counted, and where a terminal one cut */
    int hit_i[MG_MAX_EVENTS], counts[MG_MAX_EVENTS], terminated;
    double t_cut;
} mg_run;

MG_WEAK long mg_work_size(int nx, int nu, int n_events)
{
    return MG_WORK_SIZE((long)nx, (long)nu, (long)n_events);
}

/* The next n doubles of the work array. */
static double *mg_take(double **w, long n)
{
    double *v = *w;
    *w += n;
    return v;
}

/* The vectors of the work array: MG_WORK_SIZE(nx, nu, n_events) doubles. */
static void mg_layout(mg_run *r, double *work)
{
    const int nx = r->nx, n_events = r->n_events > 0 ? r->n_events : 0;
    double *w = work;
    r->x = mg_take(&w, nx);
    r->xn = mg_take(&w, nx);
    r->f0 = mg_take(&w, nx);
    r->f1 = mg_take(&w, nx);
    r->x_cut = mg_take(&w, nx);
    r->xw = mg_take(&w, nx);
    r->dfdt = mg_take(&w, nx);
    r->K = mg_take(&w, 17 * nx);
    r->cont = mg_take(&w, 8 * nx);
    r->J = mg_take(&w, nx * nx);
    r->M = mg_take(&w, 4 * nx * nx);
    r->piv = mg_take(&w, 2 * nx);
    r->o.fd_work = mg_take(&w, 3 * nx);
    r->o.u = mg_take(&w, r->sys->nu);
    r->g_old = mg_take(&w, n_events);
    r->g_new = mg_take(&w, n_events);
    r->g_work = mg_take(&w, n_events);
    r->hit_t = w;
}

/* The run of these arguments (r->sys, opt, out, t0, t1, o.p, o.in and o.stats are
 * set): its work array laid out, the statistics zero, x = x0 (mg_start puts it
 * on its manifold). */
static void mg_begin(mg_run *r, const double *x0, double *work)
{
    const mg_options *opt = r->opt;
    int i;
    r->nx = r->sys->nx;
    r->method = opt->method;
    r->n_events = opt->n_events;
    r->adaptive = (r->method == MG_METHOD_DOPRI5 || r->method == MG_METHOD_DOP853 ||
                   r->method == MG_METHOD_RODAS) &&
                  !(opt->fixed_step > 0.0);
    mg_layout(r, work);
    r->o.sys = r->sys;
    r->o.nx = r->nx;
    r->o.rtol = opt->rtol;
    r->o.atol = opt->atol;
    r->o.t_fail = r->t0;
    r->o.n_events = r->n_events;
    r->o.events = opt->events;
    r->o.ctx = opt->events_ctx;
    r->t = r->t_new = r->t_cut = r->t_origin = r->t0;
    r->h = r->hmax = r->err = r->hacc = 0.0;
    r->facold = 1e-4;
    r->erracc = 1e-2;
    r->rows = r->found = r->attempts = r->n_fixed = r->done_steps = 0;
    r->m = 4;
    r->reject = r->last = r->dense_ready = r->fresh_jacobian = r->singular = r->overflowed = 0;
    r->orientation = 0;
    r->terminated = 0;
    memset(r->o.stats, 0, sizeof *r->o.stats);
    for (i = 0; i < MG_MAX_EVENTS; ++i)
        r->hit_i[i] = r->counts[i] = 0;
    mg_copy(r->x, x0, r->nx);
    mg_copy(r->x_cut, r->x, r->nx);
    r->out->n = 0;
    r->out->n_events = 0;
}

/* Whether v[0..n) lies in [lo, hi] (so is finite) and never decreases (with
 * `strict`, increases). */
static int mg_sorted(const double *v, long n, double lo, double hi, int strict)
{
    long i;
    for (i = 0; i < n; ++i)
        if (!(v[i] >= lo && v[i] <= hi) ||
            (i > 0 && (strict ? !(v[i] > v[i - 1]) : v[i] < v[i - 1])))
            return 0;
    return 1;
}

/* Whether every tolerance is finite and > 0 (a zero, negative or NaN one has no error
 * norm: the first step would fail as if the state were not finite). */
static int mg_tolerances_ok(const double *tol, int nx)
{
    int i;
    for (i = 0; i < nx; ++i)
        if (!(tol[i] > 0.0 && tol[i] <= DBL_MAX))
            return 0;
    return 1;
}

/* Whether a resumed run's stop array is one mg_finish could have written. */
static int mg_resume_ok(const double *resume)
{
    int i;
    for (i = 0; i < MG_STOP_X; ++i)
        if (!(resume[i] >= -DBL_MAX && resume[i] <= DBL_MAX))
            return 0;
    return resume[7] >= 0.0 && resume[7] < (double)LONG_MAX;
}

/* Whether the arguments describe a run mg_integrate can do (else BAD_ARGUMENT). */
static int mg_arguments_ok(const mg_run *r)
{
    const mg_options *opt = r->opt;
    const mg_output *out = r->out;
    const mg_inputs *in = r->o.in;
    const int n_events = r->n_events;
    if (r->method < MG_METHOD_RK4 || r->method > MG_METHOD_GAUSS4 || !(r->t1 >= r->t0) ||
        !(r->t0 >= -DBL_MAX && r->t1 <= DBL_MAX) || r->nx < 1 || r->sys->nu < 0 || !r->sys->rhs ||
        (r->sys->np > 0 && !r->o.p))
        return 0;
    if ((!r->adaptive && !(opt->fixed_step > 0.0)) ||
        (r->adaptive && (!r->o.rtol || !r->o.atol || !mg_tolerances_ok(r->o.rtol, r->nx) ||
                         !mg_tolerances_ok(r->o.atol, r->nx))))
        return 0;
    if (n_events < 0 || n_events > MG_MAX_EVENTS ||
        (n_events > 0 && (!r->o.events || !opt->direction || !opt->terminal || !out->t_events ||
                          !out->x_events || !out->which_events)))
        return 0;
    if (out->capacity < (out->t_eval ? 0 : 1) || opt->max_steps < 0 || (!out->t_eval && !out->t) ||
        !out->x)
        return 0;
    if (opt->resume && !mg_resume_ok(opt->resume))
        return 0;
    /* samples outside the span (of the whole run, when resumed: from its first t0) or
     * out of order would be extrapolated from one step's dense output and returned as
     * if they were the solution */
    if (out->t_eval &&
        !mg_sorted(out->t_eval, out->capacity, opt->resume ? opt->resume[8] : r->t0, r->t1, 0))
        return 0;
    return !(in && !in->callback &&
             (in->n < 0 || (in->n > 0 && (!in->times || !in->values ||
                                          !mg_sorted(in->times, in->n, -DBL_MAX, DBL_MAX, 1)))));
}

/* The outputs y of row `row` (state already in out->x), when asked for. */
static int mg_record_outputs(mg_ode *o, mg_output *out, long row, double t)
{
    const double *x = out->x + row * o->nx;
    if (!out->y || !o->sys->outputs || o->sys->ny <= 0)
        return 0;
    if (mg_inputs_at(o->in, o->sys->nu, t, x, o->u)) {
        o->t_fail = t;
        return MG_STATUS_INPUT_ERROR;
    }
    o->sys->outputs(o->sys->model, t, x, o->u, o->p, out->y + row * o->sys->ny);
    return 0;
}

/* The rows at t0: the t_eval samples up to t0, or t0 itself. */
static int mg_first_rows(mg_run *r)
{
    mg_output *out = r->out;
    const double *t_eval = out->t_eval;
    int status;
    if (!t_eval) {
        out->t[0] = r->t0;
        mg_copy(out->x, r->x, r->nx);
        if ((status = mg_record_outputs(&r->o, out, 0, r->t0)))
            return status;
        r->rows = 1;
        return 0;
    }
    while (r->rows < out->capacity && t_eval[r->rows] <= r->t0) {
        if (out->t)
            out->t[r->rows] = t_eval[r->rows];
        mg_copy(out->x + r->rows * r->nx, r->x, r->nx);
        if ((status = mg_record_outputs(&r->o, out, r->rows, t_eval[r->rows])))
            return status;
        ++r->rows;
    }
    return 0;
}

/* The first step size: the fixed grid's, the resumed run's, options.first_step or
 * Hairer's hinit.  BAD_ARGUMENT when the fixed grid has too many steps to count. */
static int mg_first_step(mg_run *r)
{
    const mg_options *opt = r->opt;
    const double *resume = opt->resume;
    if (resume) { /* continue a previous call exactly: its controller memory and grid */
        r->facold = resume[3];
        r->hacc = resume[4];
        r->erracc = resume[5];
        r->reject = resume[6] != 0.0;
        r->done_steps = (long)resume[7];
        r->t_origin = resume[8];
    }
    r->hmax = opt->max_step > 0.0 ? opt->max_step : r->t1 - r->t_origin;
    if (!r->adaptive) {
        const double count = ceil((r->t1 - r->t_origin) / opt->fixed_step - 1e-9);
        if (!(count < (double)LONG_MAX)) /* (long)count would overflow: refused */
            return MG_STATUS_BAD_ARGUMENT;
        r->n_fixed = (long)count;
        if (r->n_fixed < 1)
            r->n_fixed = 1;
        r->h = (r->t1 - r->t_origin) / (double)r->n_fixed;
    } else if (resume) {
        r->h = resume[1] < r->hmax ? resume[1] : r->hmax;
    } else if (opt->first_step > 0.0) {
        r->h = opt->first_step < r->hmax ? opt->first_step : r->hmax;
    } else {
        const int order =
            r->method == MG_METHOD_DOP853 ? 8 : (r->method == MG_METHOD_DOPRI5 ? 5 : 4);
        r->h = mg_hinit(&r->o, r->t, r->x, r->f0, order, r->hmax, r->K, r->K + r->nx);
    }
    return 0;
}

/* Everything before the first step: the rows at t0, xdot and g at t0, the step size. */
static int mg_start(mg_run *r)
{
    int i, status;
    for (i = 0; i < r->n_events; ++i)
        r->g_old[i] = r->g_new[i] = r->g_work[i] = r->hit_t[i] = 0.0;
    if (r->sys->project && r->sys->project(r->sys->model, r->o.p, r->x)) {
        r->o.t_fail = r->t;
        return MG_STATUS_PROJECTION;
    }
    /* recorded afresh by every call (a continued run too): no state outlives it */
    if (r->sys->orientation)
        r->orientation = r->sys->orientation(r->sys->model, r->o.p, r->x);
    mg_copy(r->x_cut, r->x, r->nx);
    if ((status = mg_first_rows(r)))
        return status;
    if ((status = mg_ode_f(&r->o, r->t, r->x, r->f0)))
        return status;
    if (r->n_events > 0 && (status = mg_ode_events(&r->o, r->t, r->x, r->g_old)))
        return status;
    return mg_first_step(r);
}

/* Whether another step may be tried (else the status saying why not), and where it
 * ends: t_new, and whether it is the last. */
static int mg_next_attempt(mg_run *r)
{
    const mg_options *opt = r->opt;
    const mg_output *out = r->out;
    int stop = 0;
    if (opt->interrupt && *opt->interrupt)
        stop = MG_STATUS_INTERRUPTED;
    else if (r->attempts >= opt->max_steps)
        stop = MG_STATUS_MAX_STEPS;
    else if ((!out->t_eval && r->rows >= out->capacity) ||
             (r->n_events > 0 && r->found + r->n_events > out->events_capacity))
        return MG_STATUS_BUFFER_FULL;
    r->last = r->adaptive ? r->t + 1.01 * r->h >= r->t1 : r->done_steps + 1 >= r->n_fixed;
    /* t + h would not differ from t (a step that ends at t1 always does: the last one
     * of a span of a few ulps); after overflowed trial steps, the overflow's time is kept */
    if (!stop && !r->last && !(0.1 * r->h > fabs(r->t) * MG_UROUND)) {
        if (r->overflowed)
            return MG_STATUS_NON_FINITE;
        stop = MG_STATUS_STEP_UNDERFLOW;
    }
    if (stop) {
        r->o.t_fail = r->t;
        return stop;
    }
    if (r->adaptive) {
        if (r->last)
            r->h = r->t1 - r->t;
        r->t_new = r->last ? r->t1 : r->t + r->h;
    } else {
        r->t_new = r->last ? r->t1 : r->t_origin + (double)(r->done_steps + 1) * r->h;
    }
    ++r->attempts;
    return 0;
}

/* One step of the method from (t, x): xn, and the error norm err of the adaptive ones. */
static int mg_step(mg_run *r)
{
    mg_ode *o = &r->o;
    int status;
    mg_copy(r->K, r->f0, r->nx);
    switch (r->method) {
    case MG_METHOD_RK4:
        return mg_step_rk4(o, r->t, r->x, r->h, r->xn, r->K);
    case MG_METHOD_DOPRI5:
        return mg_step_dopri5(o, r->t, r->x, r->h, r->xn, r->K, &r->err);
    case MG_METHOD_DOP853:
        return mg_step_dop853(o, r->t, r->x, r->h, r->xn, r->K, &r->err);
    case MG_METHOD_RODAS:
        if (!r->fresh_jacobian) { /* kept through rejected steps */
            status = mg_rodas_jacobian(o, r->t, r->x, r->f0, r->J, r->dfdt, r->K + 8 * r->nx);
            if (status)
                return status;
            r->fresh_jacobian = 1;
        }
        return mg_step_rodas(o, r->t, r->x, r->f0, r->h, r->xn, r->K, r->J, r->dfdt, r->M, r->piv,
                             &r->err);
    default:
        return mg_step_gauss_halving(o, r->method == MG_METHOD_MIDPOINT ? 1 : 2, r->t, r->x, r->f0,
                                     r->h, r->xn, r->K, r->J, r->M, r->piv, MG_GAUSS_HALVINGS);
    }
}

/* Why a Gauss step failed even halved: an overflowing iterate or a singular matrix,
 * which a smaller step may cure, unless the rhs is not finite at the start state at a
 * time the step needs (t_seen, where it met one; the stages; the end): NON_FINITE. */
static int mg_gauss_failure(mg_run *r, double t_seen)
{
    const double *c = r->method == MG_METHOD_MIDPOINT ? mg_gl1_c : mg_gl2_c;
    const double c2 = c[r->method == MG_METHOD_GAUSS4], t = r->t, h = r->h;
    const double times[4] = {t_seen, t + c[0] * h, t + c2 * h, r->t_new};
    int i, status;
    for (i = 0; i < 4; ++i)
        if (times[i] == times[i] && (status = mg_ode_f(&r->o, times[i], r->x, r->xw)))
            return status;
    r->o.t_fail = r->t;
    return MG_STATUS_IMPLICIT_FAILED;
}

/* One attempted step: *accepted = 1, or 0 when it is to be tried again with the new
 * h (a singular Rosenbrock matrix, a stage that overflowed, or an error above the
 * tolerances); or a failure.  An adaptive step whose stages or result left the
 * finite numbers is rejected, its step cut by 5 (solve_ivp's smallest factor): a
 * trial step can overshoot where the solution never goes (a stiffening spring's
 * exponential force after long growing steps).  After MG_OVERFLOW_CUTS such cuts
 * in a row, or when the step no longer moves t, the run stops as NON_FINITE at the
 * last accepted state; at once when rodas's Jacobian fails at that state itself. */
#define MG_OVERFLOW_CUTS 30
static int mg_attempt(mg_run *r, int *accepted)
{
    const int gauss = r->method == MG_METHOD_MIDPOINT || r->method == MG_METHOD_GAUSS4;
    const double t_fail = r->o.t_fail;
    int status;
    r->o.t_fail = NAN; /* set by the rhs only when it fails */
    status = mg_step(r);
    if (gauss && status == MG_STATUS_IMPLICIT_FAILED)
        status = mg_gauss_failure(r, r->o.t_fail);
    else if (r->o.t_fail != r->o.t_fail) /* no NaN left in the stop array */
        r->o.t_fail = t_fail;
    *accepted = 0;
    if (status == MG_STATUS_IMPLICIT_FAILED && r->adaptive && r->singular < 5) {
        ++r->singular; /* rodas4: singular matrix; retry with half the step (as rodas.f) */
        r->o.stats->nreject += 1;
        r->h *= 0.5;
        r->reject = 1;
        return 0;
    }
    if (!status && (!mg_finite(r->xn, r->nx) || !(r->err - r->err == 0.0))) {
        r->o.t_fail = r->t_new;
        status = MG_STATUS_NON_FINITE;
    }
    if (status == MG_STATUS_NON_FINITE && r->adaptive && r->overflowed < MG_OVERFLOW_CUTS &&
        !(r->method == MG_METHOD_RODAS && !r->fresh_jacobian)) {
        ++r->overflowed;
        r->o.stats->nreject += 1;
        r->h *= 0.2;
        r->reject = 1;
        return 0;
    }
    if (status) {
        if (status == MG_STATUS_IMPLICIT_FAILED)
            r->o.t_fail = r->t;
        return status;
    }
    r->singular = 0;
    if (r->adaptive && r->err > 1.0) {
        r->o.stats->nreject += 1;
        r->reject = 1;
        r->h = mg_next_step(r->method, 0, r->h, r->err, r->done_steps, &r->facold, &r->hacc,
                            &r->erracc);
        return 0;
    }
    *accepted = 1;
    return 0;
}

/* The accepted step's end: back onto the state's manifold (unit quaternions: a
 * projection, first order in the step's error, which the next step's error
 * estimate sees), then xdot at the new state (already known to dopri5 when
 * nothing was projected: FSAL).  A chart whose orientation changed sign over
 * the step was singular somewhere inside it (the determinant is continuous along
 * the motion): an adaptive step can jump over a four-bar's dead point without
 * a stage near enough to see the singular matrix, and the projection would
 * carry the run on from the other branch, so the run stops at the step's start. */
static int mg_accept(mg_run *r)
{
    const mg_system *sys = r->sys;
    int status;
    if (sys->project && sys->project(sys->model, r->o.p, r->xn)) {
        r->o.t_fail = r->t_new;
        return MG_STATUS_PROJECTION;
    }
    if (sys->orientation) {
        const int orientation = sys->orientation(sys->model, r->o.p, r->xn);
        if (r->orientation && orientation != r->orientation) {
            r->o.t_fail = r->t_new;
            return MG_STATUS_DEAD_POINT;
        }
        r->orientation = orientation;
    }
    if (r->method == MG_METHOD_DOPRI5 && !sys->project)
        mg_copy(r->f1, r->K + 6 * r->nx, r->nx);
    else if ((status = mg_ode_f(&r->o, r->t_new, r->xn, r->f1)))
        return status;
    if (!mg_finite(r->f1, r->nx)) {
        r->o.t_fail = r->t_new;
        return MG_STATUS_NON_FINITE;
    }
    r->o.stats->naccept += 1;
    r->dense_ready = 0;
    return 0;
}

/* The dense output of the accepted step t -> t + h into cont (m vectors). */
static int mg_prepare_dense(mg_ode *o, int method, double t, const double *x, const double *xn,
                            const double *f0, const double *f1, double h, double *K, double *cont,
                            int *m)
{
    const int nx = o->nx;
    switch (method) {
    case MG_METHOD_DOPRI5:
        mg_dense_dopri5(nx, x, xn, h, K, cont);
        *m = 5;
        return 0;
    case MG_METHOD_DOP853:
        mg_copy(K + 12 * nx, f1, nx);
        *m = 8;
        return mg_dense_dop853(o, t, x, xn, h, K, cont);
    case MG_METHOD_RODAS:
        mg_dense_rodas(nx, x, xn, K, cont);
        *m = 4;
        return 0;
    default:
        mg_hermite(nx, x, xn, f0, f1, h, cont);
        *m = 4;
        return 0;
    }
}

/* The dense output of the accepted step, computed on its first use. */
static int mg_need_dense(mg_run *r)
{
    int status;
    if (r->dense_ready)
        return 0;
    status = mg_prepare_dense(&r->o, r->method, r->t, r->x, r->xn, r->f0, r->f1, r->h, r->K,
                              r->cont, &r->m);
    r->dense_ready = !status;
    return status;
}

/* The events of the accepted step: sign changes of g between its ends in the
 * directions asked for, located on the dense output, into hit_t and hit_i[*n_hit]
 * sorted by time. */
static int mg_find_events(mg_run *r, int *n_hit)
{
    const int *direction = r->opt->direction;
    int i, k, status;
    *n_hit = 0;
    if ((status = mg_ode_events(&r->o, r->t_new, r->xn, r->g_new)))
        return status;
    for (i = 0; i < r->n_events; ++i) {
        const double ga = r->g_old[i], gb = r->g_new[i];
        const int up = ga < 0.0 && gb >= 0.0, down = ga > 0.0 && gb <= 0.0;
        double root = r->t_new;
        if (!((up && direction[i] >= 0) || (down && direction[i] <= 0)))
            continue;
        if (gb != 0.0 && ((status = mg_need_dense(r)) ||
                          (status = mg_event_root(&r->o, i, r->cont, r->m, r->t, r->h, r->t, ga,
                                                  r->t_new, gb, &root, r->xw, r->g_work))))
            return status;
        for (k = *n_hit; k > 0 && r->hit_t[k - 1] > root; --k) {
            r->hit_t[k] = r->hit_t[k - 1];
            r->hit_i[k] = r->hit_i[k - 1];
        }
        r->hit_t[k] = root;
        r->hit_i[k] = i;
        ++*n_hit;
    }
    return 0;
}

/* Records the n_hit events found, in time order, up to the first terminal one,
 * which cuts the step: t_cut, x_cut. */
static void mg_record_events(mg_run *r, int n_hit)
{
    mg_output *out = r->out;
    const int nx = r->nx, *terminal = r->opt->terminal;
    int k;
    for (k = 0; k < n_hit; ++k) {
        const int which = r->hit_i[k];
        double *xe = out->x_events + r->found * nx;
        if (r->hit_t[k] == r->t_new) {
            mg_copy(xe, r->xn, nx);
        } else {
            mg_dense(nx, r->cont, r->m, (r->hit_t[k] - r->t) / r->h, xe);
            /* the interpolant leaves the manifold; a sample that cannot be put
             * back stays interpolated (the step's own end was projected) */
            if (r->sys->project)
                (void)r->sys->project(r->sys->model, r->o.p, xe);
        }
        out->t_events[r->found] = r->hit_t[k];
        out->which_events[r->found] = which;
        ++r->found;
        r->counts[which] += 1;
        if (terminal[which] > 0 && r->counts[which] >= terminal[which]) {
            r->terminated = 1;
            r->t_cut = r->hit_t[k];
            mg_copy(r->x_cut, xe, nx);
            return;
        }
    }
}

/* The events of the accepted step; the step ends at t_cut (t_new unless a terminal
 * event cut it). */
static int mg_events(mg_run *r)
{
    int n_hit, status;
    r->terminated = 0;
    r->t_cut = r->t_new;
    if (r->n_events <= 0)
        return 0;
    if ((status = mg_find_events(r, &n_hit)))
        return status;
    mg_record_events(r, n_hit);
    return 0;
}

/* The output of the accepted step: the t_eval samples in (t, t_cut] through the
 * dense output, or the step's end. */
static int mg_sample(mg_run *r)
{
    mg_output *out = r->out;
    const int nx = r->nx;
    int status;
    if (!out->t_eval) {
        out->t[r->rows] = r->t_cut;
        mg_copy(out->x + r->rows * nx, r->terminated ? r->x_cut : r->xn, nx);
        if ((status = mg_record_outputs(&r->o, out, r->rows, r->t_cut)))
            return status;
        ++r->rows;
        return 0;
    }
    while (r->rows < out->capacity && out->t_eval[r->rows] <= r->t_cut) {
        const double te = out->t_eval[r->rows];
        double *xr = out->x + r->rows * nx;
        if (r->terminated && te == r->t_cut) {
            mg_copy(xr, r->x_cut, nx);
        } else if (te == r->t_new) {
            mg_copy(xr, r->xn, nx);
        } else {
            if ((status = mg_need_dense(r)))
                return status;
            mg_dense(nx, r->cont, r->m, (te - r->t) / r->h, xr);
            /* the interpolant leaves the manifold; a sample that cannot be put
             * back stays interpolated (the step's own end was projected) */
            if (r->sys->project)
                (void)r->sys->project(r->sys->model, r->o.p, xr);
        }
        if (out->t)
            out->t[r->rows] = te;
        if ((status = mg_record_outputs(&r->o, out, r->rows, te)))
            return status;
        ++r->rows;
    }
    return 0;
}

/* Moves to the end of the accepted step and chooses the next step size; returns
 * whether that was the last step. */
static int mg_advance(mg_run *r)
{
    int i;
    r->t = r->t_new;
    if (r->opt->progress)
        *r->opt->progress = r->t;
    mg_copy(r->x, r->xn, r->nx);
    mg_copy(r->f0, r->f1, r->nx);
    for (i = 0; i < r->n_events; ++i)
        r->g_old[i] = r->g_new[i];
    ++r->done_steps;
    r->fresh_jacobian = r->overflowed = 0;
    if (r->adaptive) {
        double hnew = mg_next_step(r->method, 1, r->h, r->err, r->done_steps, &r->facold, &r->hacc,
                                   &r->erracc);
        if (r->reject && hnew > r->h)
            hnew = r->h;
        r->reject = 0;
        r->h = hnew < r->hmax ? hnew : r->hmax;
    }
    return r->last;
}

/* Steps until t1, a terminal event or a failure; returns the status. */
static int mg_steps(mg_run *r)
{
    int status, accepted, finished = !(r->t1 > r->t0);
    while (!finished) {
        if ((status = mg_next_attempt(r)) || (status = mg_attempt(r, &accepted)))
            return status;
        if (!accepted)
            continue;
        if ((status = mg_accept(r)) || (status = mg_events(r)) || (status = mg_sample(r)))
            return status;
        if (r->terminated) {
            r->t = r->t_cut;
            mg_copy(r->x, r->x_cut, r->nx);
            return MG_STATUS_EVENT;
        }
        finished = mg_advance(r);
    }
    return 0;
}

/* Where the run stopped, into the stop array (layout in mg_integrate.h), and the
 * row counts. */
static void mg_finish(const mg_run *r)
{
    double *stop = r->out->stop;
    stop[0] = r->t;
    stop[1] = r->h;
    stop[2] = r->o.t_fail;
    stop[3] = r->facold;
    stop[4] = r->hacc;
    stop[5] = r->erracc;
    stop[6] = r->reject;
    stop[7] = (double)r->done_steps;
    stop[8] = r->t_origin;
    mg_copy(stop + MG_STOP_X, r->x, r->nx);
    r->out->n = r->rows;
    r->out->n_events = r->found;
}

MG_WEAK int mg_integrate(const mg_system *system, double t0, double t1, const double *x0,
                         const double *p, const mg_inputs *inputs, const mg_options *options,
                         mg_output *output, mg_stats *stats, double *work)
{
    mg_run r;
    int status;
    if (!system || !options || !output || !stats || !work || !x0 || !output->stop)
        return MG_STATUS_BAD_ARGUMENT;
    r.sys = system;
    r.opt = options;
    r.out = output;
    r.t0 = t0;
    r.t1 = t1;
    r.o.p = p;
    r.o.in = inputs;
    r.o.stats = stats;
    mg_begin(&r, x0, work);
    status = mg_arguments_ok(&r) ? mg_start(&r) : MG_STATUS_BAD_ARGUMENT;
    if (!status)
        status = mg_steps(&r);
    mg_finish(&r);
    return status;
}

MG_WEAK int mg_integrate_batch(const mg_system *system, long n_runs, double t0, double t1,
                               const double *x0, const double *p, long p_stride,
                               const mg_inputs *inputs, const mg_options *options, long n_eval,
                               const double *t_eval, double *x_out, double *y_out, long *n_out,
                               int *status, mg_stats *stats, double *stop, double *work)
{
    mg_options one;
    mg_output out;
    long r, failed = 0;
    if (!system || !options || n_runs < 0 || p_stride < 0 ||
        (p_stride > 0 && p_stride < system->np) ||
        (n_runs > 0 && (!x0 || (system->np > 0 && !p) || !t_eval || !x_out || !n_out || !status ||
                        !stats || !stop || !work)))
        return MG_STATUS_BAD_ARGUMENT; /* nothing written: no run's arrays can be trusted */
    one = *options;                    /* a batch has no events and does not resume */
    one.n_events = 0;
    one.events = NULL;
    one.events_ctx = NULL;
    one.direction = NULL;
    one.terminal = NULL;
    one.resume = NULL;
    for (r = 0; r < n_runs; ++r) {
        out.capacity = n_eval;
        out.t_eval = t_eval;
        out.t = NULL;
        out.x = x_out + r * n_eval * system->nx;
        out.y =
            (y_out && system->outputs && system->ny > 0) ? y_out + r * n_eval * system->ny : NULL;
        out.n = 0;
        out.events_capacity = 0;
        out.t_events = NULL;
        out.x_events = NULL;
        out.which_events = NULL;
        out.n_events = 0;
        out.stop = stop + r * (MG_STOP_X + system->nx);
        status[r] = mg_integrate(system, t0, t1, x0 + r * system->nx, p ? p + r * p_stride : NULL,
                                 inputs, &one, &out, stats + r, work);
        n_out[r] = out.n;
        if (status[r] < 0)
            ++failed;
    }
    return (int)failed;
}

#undef MG_WEAK
#undef MG_UROUND
#undef MG_FD_STEP
#undef MG_RO_GAMMA
#undef MG_GAUSS_MAXIT
#undef MG_GAUSS_HALVINGS
