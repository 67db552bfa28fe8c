"""Emit stage: routines -> C header and source, through jinja2 templates.

The templates get a plain dict of strings, ints and lists (see
:func:`template_context`); every expression is printed here, by
:class:`modelgen.codegen.printer.ModelPrinter`.

Large routines are cut into ``noinline`` parts of about ``CHUNK`` statements
that share a work array ``w`` on the caller's stack.  gcc's time grows faster
than linearly with function size (register allocation), so this keeps builds
of big models fast at no cost at run time.  Values used only inside one part
stay ``const double`` locals.
"""
from __future__ import annotations

import functools
import hashlib
from dataclasses import asdict, dataclass
from pathlib import Path

import jinja2
import sympy

from modelgen.version import __version__
from modelgen.codegen.cse import Routine
from modelgen.errors import TemplateError
from modelgen.codegen.printer import ModelPrinter

#: Version of the generated C ABI, checked by the Python loader.
ABI_VERSION = 1
#: Statements per noinline part of a large routine.
CHUNK = 150
#: Routines up to this many statements stay in one function.
SINGLE_LIMIT = 400


def templates_dir() -> Path:
    """Where the jinja2 templates live (inside the wheel, or the source tree)."""
    here = Path(__file__).resolve().parent
    for candidate in (here / "templates", here.parent / "templates"):
        if (candidate / "model.c.j2").is_file():
            return candidate
    raise TemplateError(f"modelgen templates not found next to {here}")


@functools.lru_cache(maxsize=None)
def environment() -> jinja2.Environment:
    """The one cached jinja2 environment."""
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(templates_dir())),
        trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
        undefined=jinja2.StrictUndefined, autoescape=False)


def templates_digest() -> str:
    """Hash of every template file, part of the build cache key."""
    h = hashlib.sha256()
    for path in sorted(templates_dir().glob("*.j2")):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def render(template: str, context: dict) -> str:
    """Render one template; errors become :class:`TemplateError`."""
    try:
        return environment().get_template(template).render(**context)
    except jinja2.TemplateError as exc:
        raise TemplateError(f"template {template} failed: {exc}") from exc


# -- input arrays ----------------------------------------------------------------

#: C parameter declaration of every input array name
_PARAM = {"t": "double t", "q": "const double *q", "qd": "const double *qd",
          "x": "const double *x", "u": "const double *u", "p": "const double *p",
          "a": "const double *a"}


def _input_slots(routine: Routine) -> dict:
    slots = {}
    for array, symbols in routine.inputs:
        if array == "t":
            slots[symbols[0]] = "t"
            continue
        for i, s in enumerate(symbols):
            slots[s] = f"{array}[{i}]"
    return slots


@dataclass(frozen=True)
class CFunction:
    """A routine printed to C: parts (noinline helpers) and the main body."""
    name: str
    params: str             # input parameters, comma separated
    args: str               # the same, as call arguments
    inputs: tuple           # input array names, for (void) casts
    work_size: int
    parts: tuple            # (lines, ...) one per noinline part
    body: tuple             # lines of the main function (after the parts)
    ops_before: int
    ops_after: int
    statements: int


def print_routine(routine: Routine, outputs_c: dict) -> CFunction:
    """Print a routine; ``outputs_c`` maps output array name -> C array name."""
    statements = list(routine.statements)
    inputs = tuple(a for a, _ in routine.inputs)
    params = ", ".join(_PARAM[a] for a in inputs)
    args = ", ".join(inputs)
    n_parts = 1 if len(statements) <= SINGLE_LIMIT else -(-len(statements) // CHUNK)
    size = CHUNK if n_parts > 1 else max(len(statements), 1)
    part_of = {sym: i // size for i, (sym, _) in enumerate(statements)}

    # symbols used outside the part that defines them live in the work array
    shared = set()
    for i, (_, expr) in enumerate(statements):
        here = i // size
        for s in expr.free_symbols:
            if s in part_of and part_of[s] != here:
                shared.add(s)
    if n_parts > 1:
        for _, items in routine.outputs:
            for e in items:
                shared.update(s for s in e.free_symbols if s in part_of)

    slots = _input_slots(routine)
    work = 0
    for i, (sym, _) in enumerate(statements):
        if sym in shared:
            slots[sym] = f"w[{work}]"
            work += 1
        else:
            slots[sym] = f"v{i}"
    printer = ModelPrinter(slots)

    parts = [[] for _ in range(n_parts)]
    for i, (sym, expr) in enumerate(statements):
        code = printer.doprint(expr)
        if sym in shared and expr.func in (sympy.sin, sympy.cos):
            # through a local, so gcc still pairs sin and cos into one sincos call
            parts[i // size].append(f"const double v{i} = {code};")
            parts[i // size].append(f"{slots[sym]} = v{i};")
        elif sym in shared:
            parts[i // size].append(f"{slots[sym]} = {code};")
        else:
            parts[i // size].append(f"const double {slots[sym]} = {code};")
    out_lines = []
    for array, items in routine.outputs:
        target = outputs_c[array]
        for j, e in enumerate(items):
            out_lines.append(f"{target}[{j}] = {printer.doprint(e)};")
    if n_parts == 1:
        return CFunction(routine.name, params, args, inputs, work, (),
                         tuple(parts[0] + out_lines), routine.ops_before,
                         routine.ops_after, len(statements))
    return CFunction(routine.name, params, args, inputs, work,
                     tuple(tuple(p) for p in parts), tuple(out_lines),
                     routine.ops_before, routine.ops_after, len(statements))


#: Up to this many coordinates the solve is emitted as straight-line LDL^T
#: (no sqrt, independent chains the compiler can interleave); above it, a
#: right-looking Cholesky loop.
UNROLL_SOLVE = 12


def unrolled_ldlt(n: int, tol: str) -> list:
    """Straight-line C that solves ``A y = b`` by LDL^T for a fixed ``n``.

    No square roots: each pivot costs one division, which shortens the
    dependency chain from pivot to pivot.  Reads the lower triangle of the
    row-major ``A``; overwrites ``b`` with y.  Returns the 1-based failing
    pivot (d_j <= tol * A_jj, or A_jj <= 0) like the loop version: A_jj / d_j
    estimates the condition number of the diagonally scaled A, so extreme but
    well-defined mass ratios pass (see ``modelgen.sim.conditioning``).
    """
    lines = []
    for j in range(n):
        # u{j}_{k} = L{j}_{k} * d{k}: reused by every row below j
        for k in range(j):
            lines.append(f"const double u{j}_{k} = L{j}_{k} * d{k};")
        terms = "".join(f" - u{j}_{k} * L{j}_{k}" for k in range(j))
        lines.append(f"const double d{j} = A[{j * n + j}]{terms};")
        lines.append(f"if (!(d{j} > {tol} * A[{j * n + j}]) || "
                     f"!(A[{j * n + j}] > 0.0)) return {j + 1};")
        lines.append(f"const double inv{j} = 1.0 / d{j};")
        for i in range(j + 1, n):
            terms = "".join(f" - L{i}_{k} * u{j}_{k}" for k in range(j))
            lines.append(f"const double L{i}_{j} = (A[{i * n + j}]{terms}) * inv{j};")
    for i in range(n):
        terms = "".join(f" - L{i}_{k} * y{k}" for k in range(i))
        lines.append(f"const double y{i} = b[{i}]{terms};")
    for i in reversed(range(n)):
        terms = "".join(f" - L{k}_{i} * b[{k}]" for k in range(i + 1, n))
        lines.append(f"b[{i}] = y{i} * inv{i}{terms};")
    return lines


def _comment_safe(text: str) -> str:
    """Text that cannot close or nest a C comment, nor smuggle a line break."""
    return "".join(ch if ch.isprintable() else " " for ch in text).replace("*/", "* /").replace("/*", "/ *")


def template_context(*, name: str, description: str, model_hash: str, n: int,
                     coordinates, parameters, inputs, bodies,
                     functions: dict, output_columns=(), has_jacobian=False) -> dict:
    """The plain dict every C template receives."""
    return {
        "name": name,
        "NAME": name.upper(),
        "version": __version__,
        "abi_version": ABI_VERSION,
        "model_hash": model_hash,
        "description": _comment_safe(description),
        "n": n,
        "nx": 2 * n,
        "np": len(parameters),
        "nu": len(inputs),
        "nbodies": len(bodies),
        "coordinates": list(coordinates),
        "parameters": [{"name": p, "default": repr(float(v))} for p, v in parameters],
        "inputs": list(inputs),
        "bodies": list(bodies),
        "functions": {k: asdict(f) for k, f in functions.items()},
        "ny": len(output_columns),
        "has_jacobian": bool(has_jacobian),
        "output_columns": list(output_columns),
        "api": public_api(name, n, len(parameters), len(inputs), len(bodies),
                          len(output_columns), has_jacobian),
        "solve_lines": unrolled_ldlt(n, f"{name.upper()}_PIVOT_TOL") if n <= UNROLL_SOLVE else [],
    }


def public_api(name: str, n: int, n_p: int, n_u: int, n_b: int, n_y: int = 0,
               has_jacobian: bool = False) -> list:
    """Prototypes and documentation of every exported function.

    The header and the cffi ``cdef`` are both rendered from this one list.
    """
    P = f"p: {n_p} parameters (see {name}_default_parameters)"
    extra = []
    if n_y:
        extra.append(
            {"ret": "void", "name": f"{name}_outputs",
             "params": "double t, const double *x, const double *u, const double *p, double *y",
             "doc": [f"The scene's recorded outputs y[{n_y}] at state x[{2 * n}] (columns in",
                     "the order listed at the top of this file)."]})
    if has_jacobian:
        extra.append(
            {"ret": "int", "name": f"{name}_jacobian",
             "params": "double t, const double *x, const double *u, const double *p, double *J",
             "doc": [f"Jacobian J[{2 * n}*{2 * n}] = d xdot / d x, row-major, derived symbolically",
                     "(forward mode over the generated program). Returns the rhs status."]})
    extra.append(
        {"ret": "int", "name": f"{name}_simulate_rk4",
         "params": "double t0, double step, long n_steps, long every, const double *x0, "
                   "const double *p, long n_u, const double *u_times, const double *u_values, "
                   "int u_hold, double *t_out, double *x_out, double *y_out, long *n_out, "
                   "double *t_stop",
         "doc": ["Classic RK4 from x0 at t0 for n_steps steps of size step, recording t, x",
                 f"(and the {n_y} outputs) every `every` steps and after the last step:",
                 "t_out[], x_out[][NX], y_out[][NY] need n_steps/every + 2 rows.",
                 f"Inputs: n_u samples u_times[n_u] (increasing), u_values[n_u][{n_u}],",
                 "interpolated linearly (u_hold = 0) or held (u_hold = 1), ends held;",
                 "n_u = 0 means all inputs are zero.  Returns 0; or k > 0 when pivot k",
                 "of A failed, -1 when the state became non-finite.  *n_out rows were",
                 "written either way, *t_stop is the time of the last good state."]})
    return extra + [
        {"ret": "int", "name": f"{name}_abi_version", "params": "void",
         "doc": [f"Returns the ABI version ({ABI_VERSION}) this file was generated for."]},
        {"ret": "void", "name": f"{name}_default_parameters", "params": "double *p",
         "doc": [f"Writes the {n_p} default parameter values into p, in declaration order."]},
        {"ret": "void", "name": f"{name}_mass_matrix",
         "params": "const double *q, const double *p, double *A",
         "doc": [f"Mass matrix A(q, p): q[{n}] coordinates; {P};",
                 f"A[{n}*{n}] row-major, symmetric (SI units: kg, kg m, kg m^2)."]},
        {"ret": "void", "name": f"{name}_velocity_terms",
         "params": "const double *q, const double *qd, const double *p, double *h",
         "doc": [f"Velocity-product term h(q, qd, p) (Coriolis, centrifugal, gyroscopic),",
                 f"so that A qdd = tau - h: q[{n}], qd[{n}]; {P}; h[{n}]."]},
        {"ret": "void", "name": f"{name}_generalized_forces",
         "params": "double t, const double *q, const double *qd, const double *u, const double *p, double *tau",
         "doc": [f"Generalized forces tau of gravity and actions: t [s]; q[{n}]; qd[{n}];",
                 f"u[{n_u}] inputs; {P}; tau[{n}] (N or N m per coordinate)."]},
        {"ret": "int", "name": f"{name}_rhs",
         "params": "double t, const double *x, const double *u, const double *p, double *xdot",
         "doc": [f"State derivative for x = [q, qd] (x[{2 * n}]): xdot = [qd, qdd] with",
                 "A qdd = tau - h solved by Cholesky in place. u, p as above.",
                 "Returns 0, or k > 0 when pivot k (1-based) of A is not positive",
                 "(A not positive definite); xdot[n..2n) is then NaN."]},
        {"ret": "void", "name": f"{name}_energy",
         "params": "const double *q, const double *qd, const double *p, double *out",
         "doc": ["out[0] kinetic energy, out[1] potential energy of gravity (zero at O)",
                 "and of springs [J]."]},
        {"ret": "void", "name": f"{name}_body_poses",
         "params": "const double *q, const double *p, double *T",
         "doc": [f"Pose of every body: T[{n_b}*16], one row-major 4x4 matrix per body",
                 "[[R, r_G], [0, 0, 0, 1]]: R's columns are the body base's unit vectors",
                 "in E, r_G the centre of mass from O in E [m]."]},
    ] + _integrator_api(name, n, n_p, n_u)


# -- integrators (templates/integrators.c.j2) ----------------------------------------

def _integrator_api(name: str, n: int, n_p: int, n_u: int) -> list:
    """Prototypes and documentation of the integrators' exported functions.

    The status codes, method numbers and statistics slots named here are
    defined in templates/integrators.c.j2 and mirrored, with the messages, by
    :mod:`modelgen.sim.integrate`.
    """
    nx = 2 * n
    return [
        {"ret": "int", "name": f"{name}_jacobian_fd",
         "params": "double t, const double *x, const double *u, const double *p, double *J",
         "doc": [f"d xdot / d x by central differences of {name}_rhs (step cbrt(eps) max(1, |x_j|),",
                 f"error about 1e-10 relative): J[{nx}*{nx}] row-major, J[i*{nx} + j] = d xdot_i / d x_j.",
                 f"x[{nx}], u[{n_u}], p[{n_p}] as for {name}_rhs; returns its status."]},
        {"ret": "int", "name": f"{name}_integrate",
         "params": "int method, double t0, double t1, const double *x0, const double *p, "
                   "long n_u, const double *u_times, const double *u_values, int u_hold, "
                   "const double *rtol, const double *atol, double first_step, double max_step, "
                   "double fixed_step, long max_steps, const double *resume, long n_out_max, "
                   "const double *t_eval, "
                   "double *t_out, double *x_out, long *n_out, int n_events, "
                   "int (*events)(void *, double, const double *, double *), void *ctx, "
                   "const int *direction, const int *terminal, long n_found_max, "
                   "double *t_found, double *x_found, int *which_found, long *n_found, "
                   "long *stats, double *stop",
         "doc": [f"Integrates x' = xdot(t, x) from x0[{nx}] at t0 to t1 >= t0; nothing is allocated.",
                 "method: 0 rk4, 1 dopri5, 2 dop853, 3 rodas4 (Rosenbrock, uses the Jacobian),",
                 "4 implicit midpoint, 5 gauss4 (2-stage Gauss-Legendre).  fixed_step > 0 gives",
                 "fixed steps of about that size (required by 0, 4 and 5; no error control);",
                 f"else rtol[{nx}], atol[{nx}] set the error control, first_step (0: Hairer's",
                 "hinit) and max_step (0: t1 - t0) its steps.  max_steps counts attempts.",
                 "resume: NULL, or the stop array of a call that returned 2, to continue it",
                 "exactly (from t0 = stop[0], x0 = stop + 9).",
                 f"p, n_u, u_times, u_values, u_hold: as for {name}_simulate_rk4.",
                 "Output: t_eval NULL records t0 and every accepted step into t_out[n_out_max],",
                 f"x_out[n_out_max][{nx}]; else x_out[i] is x(t_eval[i]) for the n_out_max increasing",
                 "times t_eval (from the dense output; t_out may be NULL).  *n_out rows written.",
                 "Events (n_events <= 32, 0: no calls): events(ctx, t, x, g) writes g[n_events],",
                 "returns nonzero to abort; a sign change of g[i] (direction[i] > 0 rising only,",
                 "< 0 falling only) is located on the dense output and recorded in t_found,",
                 f"x_found[][{nx}], which_found (capacity n_found_max, *n_found written); the",
                 "integration stops at occurrence terminal[i] > 0 of event i.",
                 "stats[8]: accepted, rejected steps, rhs, Jacobian evaluations, LU",
                 "factorizations, Newton iterations, event function calls, failing pivot.",
                 f"stop[9 + {nx}]: t reached, next step size, time of the failure, the step",
                 "controller's memory (4), steps since the first t0, that t0; x at t from 9.",
                 "Returns 0 (t1 reached), 1 (terminal event), 2 (an output buffer is full:",
                 "continue from stop), -1 max_steps reached, -2 step size underflow, -3 mass",
                 "matrix not positive definite, -4 NaN/Inf in the state, -5 implicit stage",
                 "equations not solved, -6 event function aborted, -7 bad argument.",
                 "Everything up to the stop is written."]},
        {"ret": "int", "name": f"{name}_integrate_batch",
         "params": "long n_runs, int method, double t0, double t1, const double *x0, "
                   "const double *p, long p_stride, long n_u, const double *u_times, "
                   "const double *u_values, int u_hold, const double *rtol, const double *atol, "
                   "double first_step, double max_step, double fixed_step, long max_steps, "
                   "long n_eval, const double *t_eval, double *x_out, long *n_out, int *status, "
                   "long *stats, double *stop",
         "doc": [f"{name}_integrate for n_runs initial states x0[n_runs][{nx}] with parameters",
                 f"p + r * p_stride (p_stride 0: one parameter set, {n_p}: one per run), sampled",
                 f"at t_eval[n_eval] (required) into x_out[n_runs][n_eval][{nx}]; no events.",
                 f"n_out[n_runs], status[n_runs], stats[n_runs][8], stop[n_runs][9 + {nx}].",
                 "Returns the number of runs that failed (status < 0)."]},
    ]


def emit_sources(context: dict) -> dict:
    """Render ``<name>.h``, ``<name>.c`` and the cffi cdef text."""
    name = context["name"]
    return {
        f"{name}.h": render("model.h.j2", dict(context, template="model.h.j2")),
        f"{name}.c": render("model.c.j2", dict(context, template="model.c.j2")),
        "cdef": render("cdef.h.j2", dict(context, template="cdef.h.j2")),
    }
