"""The C integrator interface as data: the one table behind ``mg_integrate.h``.

Method codes, statuses (with their messages), statistics slots, limits and
the fields of the public structs live here and nowhere else.  The template
``mg_integrate.h.j2`` renders them as prefixed ``#define`` s and struct
declarations (the integrators themselves are plain C in ``codegen/c/``, which
uses only those names), the runtime module's cffi ``cdef``
declares the same ``#define`` s so Python reads them back from the compiled C,
``SIGNATURES`` lists the signatures of the model's exported functions (one
trampoline each in the runtime module), and
:mod:`modelgen.sim.integrate` formats results with the messages below.  A
test compares the compiled constants with this table.

To add a status: append a :class:`Status` to ``STATUSES`` (a new negative
code for a failure), return ``MG_STATUS_<NAME>`` from the C, bump
``ABI_VERSION``.  To add a statistic: append to ``STATS`` (it becomes a
``long`` field of ``mg_stats``) and bump ``ABI_VERSION``.

>>> METHODS["dop853"].code, STATUS_BY_NAME["MAX_STEPS"].code
(2, -1)
"""
from __future__ import annotations

import re
from typing import NamedTuple

#: Version of the C interface (model functions and mg_integrate), checked by the loader.
ABI_VERSION = 9
#: Prefix of every constant, type and function of the model-independent C.
PREFIX = "MG"


class Method(NamedTuple):
    """An integration method of ``mg_integrate.c``."""
    name: str
    code: int           # MG_METHOD_<NAME>
    order: int          # order of the step
    dense_order: int    # order of the continuous extension used for t_eval and events
    adaptive: bool      # has error control (else fixed step only)
    implicit: bool      # uses the Jacobian d xdot / d x
    aliases: tuple = ()


#: Aliases are lower case (names are matched case-insensitively).  solve_ivp's
#: names map to modelgen's own methods: "RK45" is the same Dormand-Prince 5(4)
#: pair as dopri5, "DOP853" is dop853, and the stiff "Radau", "BDF" and "LSODA"
#: all run rodas (RODAS4, L-stable, order 4; not Radau IIA's 5 nor BDF's variable
#: order, and LSODA's switching is not reproduced: rodas handles both regimes).
METHOD_LIST = (
    Method("rk4", 0, 4, 3, False, False),
    Method("dopri5", 1, 5, 4, True, False, ("rk45",)),
    Method("dop853", 2, 8, 7, True, False),
    Method("rodas", 3, 4, 3, True, True, ("rodas4", "radau", "bdf", "lsoda")),
    Method("midpoint", 4, 2, 3, False, True, ("implicit_midpoint",)),
    Method("gauss4", 5, 4, 3, False, True, ("gauss_legendre4",)),
)
METHODS = {m.name: m for m in METHOD_LIST}
#: other accepted spellings -> method name
ALIASES = {alias: m.name for m in METHOD_LIST for alias in m.aliases}


class Status(NamedTuple):
    """A return code of ``mg_integrate``: 0 end reached, 1 terminal event, 2 buffer
    full (continue from the stop array), negative a failure.  ``message`` is
    formatted with t (reached), h (step size), t_fail, x, pivot, coordinate,
    kind (of a mass-matrix failure: 'singular to working precision' or 'not
    positive definite') and max_steps."""
    code: int
    name: str           # MG_STATUS_<name>
    message: str


STATUSES = (
    Status(0, "SUCCESS", "The solver successfully reached the end of the integration interval."),
    Status(1, "EVENT", "A termination event occurred."),
    Status(2, "BUFFER_FULL", "An output buffer is full (internal: the integration is continued)."),
    Status(-1, "MAX_STEPS", "Maximum number of steps ({max_steps}) reached at t={t!r}."),
    Status(-2, "STEP_UNDERFLOW", "Step size underflow at t={t!r}: the step {h:.3g} s is too small "
                                 "to advance t in double precision."),
    Status(-3, "MASS_MATRIX", "Mass matrix {kind} at t={t_fail!r}: pivot "
                              "{pivot} (coordinate {coordinate!r}) failed; last good state at "
                              "t={t!r}: x={x}."),
    Status(-4, "NON_FINITE", "NaN or Inf in the state at t={t_fail!r}; last finite state at "
                             "t={t!r}: x={x}."),
    Status(-5, "IMPLICIT_FAILED", "The implicit stage equations could not be solved in the step "
                                  "from t={t!r} (h={h:.3g}): the Newton iteration diverged or its "
                                  "matrix is singular; use a smaller step."),
    Status(-6, "EVENT_ERROR", "An event function failed at t={t_fail!r}; the trajectory up to "
                              "t={t!r} is kept."),
    Status(-7, "BAD_ARGUMENT", "Invalid argument to the C integrator."),
    Status(-8, "INTERRUPTED", "Interrupted at t={t!r}; the trajectory up to there is kept."),
    Status(-9, "INPUT_ERROR", "The input function u(t, x) failed at t={t!r}."),
    Status(-10, "PROJECTION", "The state could not be put back on the constraints at "
                              "t={t_fail!r} (Gauss-Newton did not converge, or the dependent "
                              "speeds are not determined there: a dead point); last good state "
                              "at t={t!r}: x={x}."),
    Status(-11, "DEAD_POINT", "The configuration passed through a singularity of its "
                              "coordinates between t={t!r} and t={t_fail!r}: the orientation of "
                              "the system's chart changed sign (a dead point); last good state "
                              "at t={t!r}: x={x}."),
)
STATUS = {s.code: s for s in STATUSES}
STATUS_BY_NAME = {s.name: s for s in STATUSES}

#: The slots of ``mg_stats`` (each a ``long``), in order.
STATS = (
    ("naccept", "accepted steps"),
    ("nreject", "rejected steps (error too large, or a singular Rosenbrock matrix)"),
    ("nfev", "right-hand side evaluations"),
    ("njev", "Jacobian evaluations"),
    ("nlu", "LU factorizations"),
    ("nnewton", "Newton iterations of the implicit Gauss methods"),
    ("ngev", "calls of the event function"),
    ("pivot", "the failing pivot (1-based) of a MASS_MATRIX failure (of the LDL^T/Cholesky "
              "factorization of A, or the articulated inertia D of the ABA), else 0"),
)
STAT_NAMES = tuple(name for name, _ in STATS)

#: Limits and layout constants: name -> (value, meaning).
LIMITS = {
    "MAX_EVENTS": (32, "most event functions per call"),
    "STOP_X": (9, "where the state starts in the stop array"),
    "INPUT_LINEAR": (0, "sampled inputs interpolated linearly"),
    "INPUT_HOLD": (1, "sampled inputs held (zero-order hold)"),
}
MAX_EVENTS = LIMITS["MAX_EVENTS"][0]
STOP_X = LIMITS["STOP_X"][0]

#: The slots of the stop array before the state (its length is STOP_X + nx).
STOP_SLOTS = ("t reached", "next step size", "time of the failure", "controller memory facold",
              "controller memory hacc", "controller memory erracc", "last step rejected",
              "steps since t_origin", "t_origin (the first t0 of a continued run)")
assert len(STOP_SLOTS) == STOP_X

# -- the public structs of mg_integrate.h: (C declaration, name, comment) ---------------

RHS_FN = "int (*{})(void *model, double t, const double *x, const double *u, const double *p, double *out)"
OUTPUTS_FN = "void (*{})(void *model, double t, const double *x, const double *u, const double *p, double *y)"

STRUCTS = (
    ("mg_system", "A model as the integrators see it: sizes, functions, context.", (
        ("int", "nx", "states x = [q, qd]"),
        ("int", "nu", "inputs u"),
        ("int", "np", "parameters p"),
        ("int", "ny", "outputs y (0: none)"),
        (RHS_FN.format("rhs"), "rhs", "xdot[nx] at (t, x[nx], u[nu], p[np]); returns 0 or the failing pivot"),
        (RHS_FN.format("jacobian"), "jacobian", "J[nx*nx] = d xdot / d x, row-major; NULL: central differences"),
        (OUTPUTS_FN.format("outputs"), "outputs", "y[ny] at (t, x, u, p); NULL when ny = 0"),
        ("int (*project)(void *model, const double *p, double *x)", "project",
         "NULL, or puts x back on its manifold (unit quaternions of ball and free joints, "
         "the constraints) after each accepted step and at the start; returns 0, or "
         "nonzero when it cannot (status PROJECTION)"),
        ("int (*orientation)(void *model, const double *p, const double *x)", "orientation",
         "NULL, or the sign (1 or -1, 0 if singular) of the determinant of the chart x is "
         "written in (a constrained model: the constraint Jacobian's dependent columns); "
         "recorded at the start, a change after an accepted step stops the run (status "
         "DEAD_POINT): the configuration passed through a singularity of that chart"),
        ("void *", "model", "passed as the first argument of the functions above"),
    )),
    ("mg_inputs", "The inputs u(t): none, samples, or a callback.", (
        ("long", "n", "number of samples (0 and no callback: u = 0)"),
        ("const double *", "times", "times[n], finite and increasing (else BAD_ARGUMENT)"),
        ("const double *", "values", "values[n][nu], row-major"),
        ("int", "hold", "MG_INPUT_LINEAR or MG_INPUT_HOLD; ends are held"),
        ("int (*callback)(void *ctx, double t, const double *x, double *u)", "callback",
         "if not NULL: u[nu] = u(t, x), returns nonzero on failure (INPUT_ERROR)"),
        ("void *", "ctx", "first argument of callback"),
    )),
    ("mg_options", "How to integrate (zero-initialise, then set what you need).", (
        ("int", "method", "MG_METHOD_*"),
        ("const double *", "rtol", "rtol[nx] (adaptive methods)"),
        ("const double *", "atol", "atol[nx] (adaptive methods)"),
        ("double", "first_step", "0: Hairer's hinit"),
        ("double", "max_step", "0: t1 - t0"),
        ("double", "fixed_step", "> 0: fixed steps of about that size (required by rk4, midpoint, gauss4)"),
        ("long", "max_steps", "attempted steps per call (0 stops at once: set it)"),
        ("int", "n_events", "event functions (<= MG_MAX_EVENTS; 0: none)"),
        ("int (*events)(void *ctx, double t, const double *x, double *g)", "events",
         "writes g[n_events]; returns nonzero to abort (EVENT_ERROR)"),
        ("void *", "events_ctx", "first argument of events"),
        ("const int *", "direction", "direction[n_events]: > 0 rising only, < 0 falling only, 0 both"),
        ("const int *", "terminal", "terminal[n_events]: stop at this occurrence (0: never)"),
        ("const double *", "resume", "NULL, or the stop array of a call that returned BUFFER_FULL "
         "(with t_eval, continue with the samples not yet written: t_eval + n)"),
        ("const volatile int *", "interrupt", "NULL, or polled every step: nonzero stops (INTERRUPTED)"),
        ("volatile double *", "progress", "NULL, or set to t after every accepted step (read from another thread to show progress)"),
    )),
    ("mg_output", "Where the trajectory goes (arrays of the caller).", (
        ("long", "capacity", "rows of t, x, y; with t_eval: its length"),
        ("const double *", "t_eval", "NULL: record t0 and every step; else sample x(t_eval[i]), "
         "finite, non-decreasing, in [t0, t1] (t0 of the first call when resumed)"),
        ("double *", "t", "t[capacity] (may be NULL with t_eval)"),
        ("double *", "x", "x[capacity][nx]"),
        ("double *", "y", "NULL, or y[capacity][ny] through system.outputs"),
        ("long", "n", "rows written"),
        ("long", "events_capacity", "rows of t_events, x_events, which_events"),
        ("double *", "t_events", "times of the events found"),
        ("double *", "x_events", "x_events[events_capacity][nx]"),
        ("int *", "which_events", "the event function of each"),
        ("long", "n_events", "events written"),
        ("double *", "stop", "stop[MG_STOP_X + nx]: where the integration stopped (layout above)"),
    )),
    ("mg_stats", "What the integration cost.", tuple(("long", name, text) for name, text in STATS)),
)


#: The functions of mg_integrate.c: (return type, name, parameters, documentation lines).
FUNCTIONS = (
    ("long", "mg_work_size", "int nx, int nu, int n_events",
     ["MG_WORK_SIZE(nx, nu, n_events): the doubles of work array mg_integrate needs."]),
    ("int", "mg_integrate",
     "const mg_system *system, double t0, double t1, const double *x0, const double *p, "
     "const mg_inputs *inputs, const mg_options *options, mg_output *output, mg_stats *stats, "
     "double *work",
     ["Integrates x' = system.rhs(t, x, u(t), p) from x0[nx] at t0 to t1 >= t0.",
      "rk4, midpoint and gauss4 need options.fixed_step; dopri5, dop853 and rodas4 use",
      "rtol[nx], atol[nx], finite and > 0 (or fixed steps when fixed_step > 0).  inputs",
      "may be NULL (u = 0); p may be NULL only when np = 0.",
      "Output: without t_eval, t0 and every accepted step into t, x (and y); with",
      "t_eval, x(t_eval[i]) from the dense output.  Events: sign changes of",
      "g = options.events(t, x), located on the dense output, into t_events...",
      "work: MG_WORK_SIZE(nx, nu, n_events) doubles.  Returns an MG_STATUS_*: 0 t1",
      "reached, 1 terminal event, 2 an output buffer is full (continue with",
      "options.resume = the stop array), < 0 a failure; everything up to it is written.",
      "Arguments it cannot run (NULL arrays, a bad tolerance, step, t_eval or resume",
      "array, t1 < t0): BAD_ARGUMENT, nothing computed."]),
    ("int", "mg_integrate_batch",
     "const mg_system *system, long n_runs, double t0, double t1, const double *x0, "
     "const double *p, long p_stride, const mg_inputs *inputs, const mg_options *options, "
     "long n_eval, const double *t_eval, double *x_out, double *y_out, long *n_out, "
     "int *status, mg_stats *stats, double *stop, double *work",
     ["mg_integrate for n_runs states x0[n_runs][nx] with parameters p + r * p_stride,",
      "sampled at t_eval[n_eval] (required) into x_out[n_runs][n_eval][nx]; no events.",
      "y_out[n_runs][n_eval][ny]: the outputs at those times (NULL: none recorded).",
      "n_out[n_runs], status[n_runs], stats[n_runs], stop[n_runs][MG_STOP_X + nx].",
      "Returns the number of runs that failed (status < 0), or MG_STATUS_BAD_ARGUMENT,",
      "nothing written, when an array is NULL, n_runs < 0, or p_stride is neither 0",
      "nor >= np."]),
    ("int", "mg_jacobian_fd",
     "const mg_system *system, double t, const double *x, const double *u, const double *p, "
     "double *J, double *work",
     ["d xdot / d x by central differences of system.rhs (step cbrt(eps) max(1, |x_j|),",
      "error about 1e-10 relative): J[nx*nx] row-major, J[i*nx + j] = d xdot_i / d x_j;",
      "work[3 * nx].  Returns the rhs status."]),
)


# -- the signatures of the model's exported functions ----------------------------------

class Signature(NamedTuple):
    """One C signature shared by exported model functions.  Python calls a model's
    plain shared library through the model-independent runtime module's trampoline
    ``mg_call_<name>(mg_fn_<name> fn, ...)``, one per signature, so no model needs
    a compiled Python extension of its own."""
    name: str
    ret: str
    params: tuple       # C parameter declarations, with names

    @property
    def types(self) -> tuple:
        return tuple(_parameter_type(p) for p in self.params)


_RHS_ARGS = ("double t", "const double *x", "const double *u", "const double *p")
SIGNATURES = (
    Signature("version", "int", ()),
    Signature("p", "void", ("double *p",)),
    Signature("dimensions", "void", ("int *d",)),
    Signature("q_p", "void", ("const double *q", "const double *p", "double *out")),
    Signature("q_qd_p", "void", ("const double *q", "const double *qd", "const double *p",
                                 "double *out")),
    Signature("t_q_qd_u_p", "void", ("double t", "const double *q", "const double *qd",
                                     "const double *u", "const double *p", "double *out")),
    Signature("t_x_u_p", "int", (*_RHS_ARGS, "double *out")),
    Signature("t_x_u_p_pd", "int", (*_RHS_ARGS, "const double *pd", "double *out")),
    Signature("prepare", "void", ("const double *p", "double *out")),
    Signature("t_x_u_p_void", "void", (*_RHS_ARGS, "double *out")),
    Signature("linearize", "int", (*_RHS_ARGS, "double *A", "double *B", "double *C",
                                   "double *D")),
    Signature("derivatives", "int", (*_RHS_ARGS, "double *dqdd_dq", "double *dqdd_dv",
                                     "double *dqdd_du")),
    Signature("inverse_dynamics_derivatives", "void", (
        "double t", "const double *x", "const double *qdd", "const double *u",
        "const double *p", "double *dQ_dq", "double *dQ_dv", "double *M")),
    Signature("system", "void", ("mg_system *system",)),
    Signature("x_inplace", "void", ("double *x",)),
    Signature("p_x_inplace", "int", ("const double *p", "double *x")),
    Signature("integrate", "int", (
        "double t0", "double t1", "const double *x0", "const double *p",
        "const mg_inputs *inputs", "const mg_options *options", "mg_output *output",
        "mg_stats *stats", "double *work")),
    Signature("integrate_batch", "int", (
        "long n_runs", "double t0", "double t1", "const double *x0", "const double *p",
        "long p_stride", "const mg_inputs *inputs", "const mg_options *options",
        "long n_eval", "const double *t_eval", "double *x_out", "double *y_out", "long *n_out",
        "int *status", "mg_stats *stats", "double *stop", "double *work")),
)


def _parameter_type(declaration: str) -> str:
    """``'const double *x'`` -> ``'const double *'``: the declaration without its name."""
    match = re.fullmatch(r"\s*(.*?[\s*])(\w+)\s*", declaration)
    if not match:
        raise ValueError(f"not a C parameter declaration: {declaration!r}")
    return " ".join(match.group(1).replace("*", " * ").split()).replace(" *", "*")


def signature_of(ret: str, params: str) -> Signature:
    """The :class:`Signature` of a prototype given as its return type and parameter text.

    >>> signature_of("int", "double t, const double *x, const double *u, const double *p, double *J").name
    't_x_u_p'
    """
    decls = () if params.strip() in ("", "void") else tuple(params.split(","))
    types = tuple(_parameter_type(d) for d in decls)
    for sig in SIGNATURES:
        if sig.ret == ret and sig.types == types:
            return sig
    raise KeyError(f"no Signature in capi.SIGNATURES for {ret} ({params}); add one and bump "
                   f"ABI_VERSION")


def defines() -> list:
    """Every ``#define`` of the interface as (name, value, comment), in header order."""
    rows = [(f"{PREFIX}_ABI_VERSION", ABI_VERSION, "version of this interface")]
    rows += [(f"{PREFIX}_METHOD_{m.name.upper()}", m.code, f"order {m.order}"
              + (", adaptive" if m.adaptive else ", fixed step")
              + (", implicit" if m.implicit else "")) for m in METHOD_LIST]
    rows += [(f"{PREFIX}_STATUS_{s.name}", s.code, "") for s in STATUSES]
    rows += [(f"{PREFIX}_{name}", value, text) for name, (value, text) in LIMITS.items()]
    rows += [(f"{PREFIX}_NSTATS", len(STATS), "slots of mg_stats")]
    return rows


def define_values() -> dict:
    """``defines()`` as a dict name -> value (what the compiled module must report)."""
    return {name: value for name, value, _ in defines()}


def work_size(nx: int, nu: int, n_events: int) -> int:
    """Doubles of work array ``mg_integrate`` needs (the C ``MG_WORK_SIZE``)."""
    return 5 * nx * nx + 37 * nx + nu + 4 * n_events + 1


#: The C text of the work size, rendered into the header (same formula as work_size).
WORK_SIZE_C = "(5 * (nx) * (nx) + 37 * (nx) + (nu) + 4 * (n_events) + 1)"


def _declaration(decl: str, field: str) -> str:
    if "(" in decl:                  # a function pointer names its field inside
        return decl
    return f"{decl}{'' if decl.endswith('*') else ' '}{field}"


def context() -> dict:
    """The plain dict the mg_integrate templates (and the cdef) receive."""
    return {
        "abi_version": ABI_VERSION,
        "defines": [{"name": n, "value": v, "comment": c} for n, v, c in defines()],
        "methods": [m._asdict() for m in METHOD_LIST],
        "statuses": [s._asdict() for s in STATUSES],
        "structs": [{"name": n, "doc": d,
                     "fields": [{"decl": _declaration(decl, field),
                                 "name": field, "comment": c} for decl, field, c in fields]}
                    for n, d, fields in STRUCTS],
        "stats": [{"name": n, "upper": n.upper(), "index": i} for i, (n, _) in enumerate(STATS)],
        "stop_slots": list(STOP_SLOTS),
        "work_size": WORK_SIZE_C,
        "functions": [{"ret": r, "name": n, "params": a, "doc": d} for r, n, a, d in FUNCTIONS],
        "signatures": [{"name": s.name, "ret": s.ret, "params": ", ".join(s.params) or "void",
                        "types": ", ".join(s.types) or "void",
                        "args": ", ".join(p.split()[-1].lstrip("*") for p in s.params)}
                       for s in SIGNATURES],
    }
