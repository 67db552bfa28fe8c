"""Emit stage: routines -> C header and source, through jinja2 templates.

The templates get a plain dict of strings, ints and lists (see
:func:`template_context`); every expression is printed here, by
:class:`modelgen.codegen.printer.ModelPrinter`.

Large routines are cut into ``noinline`` parts of about ``CHUNK`` statements
that share a work array ``w`` on the caller's stack.  gcc's time grows faster
than linearly with function size (register allocation), so this keeps builds
of big models fast at no cost at run time.  Values used only inside one part
stay ``const double`` locals.  A compile at -O0 is linear in any case, and
there the work array's accesses double its time: the query routines (part 1,
at -O0 in a model's library) also carry their text as one function of locals,
which the C reads when the compiler does not optimize.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import re
import sys
from dataclasses import dataclass, fields, replace
from pathlib import Path

import jinja2
import sympy

from modelgen.version import __version__
from modelgen.codegen import capi
from modelgen.codegen.build import cache_dir
from modelgen.codegen.cse import Routine
from modelgen.derive.graph import free_symbols
from modelgen.codegen.ldlt import derivative_solve, solve_code
from modelgen.errors import TemplateError
from modelgen.codegen.printer import ModelPrinter

#: Version of the generated C ABI, checked by the Python loader (the C interface table's).
ABI_VERSION = capi.ABI_VERSION
#: The templates of a model's own code (the model hash covers these only).
MODEL_TEMPLATES = ("model.c.j2", "model.h.j2", "macros.j2", "constraints.c.j2")
#: The templates of the frame kinematics, rendered only into builds that ask for them
#: (so they enter the model hash of those builds only).
KINEMATICS_TEMPLATES = ("kinematics.c.j2", "kinematics.h.j2")
#: The integrators' header, rendered from modelgen.codegen.capi alone; their C is
#: plain files in ``c/`` (:func:`integrator_files`).
INTEGRATOR_HEADER = "mg_integrate.h"
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


#: How the templates are read (part of where their compiled form is cached).
ENVIRONMENT_OPTIONS = dict(trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                           undefined=jinja2.StrictUndefined, autoescape=False)


class _TemplateCache(jinja2.FileSystemBytecodeCache):
    """The templates compiled to Python bytecode, in the build cache.

    Compiling the templates is most of the emit stage of a small model; jinja2
    keys each entry by the template's name and checks the checksum of its
    source on load, so an edited template is compiled afresh.  The directory
    is named after jinja2's version, Python's and :data:`ENVIRONMENT_OPTIONS`
    (which change the compiled code but not the key).  Best effort: a cache
    that cannot be read or written only costs the compile.
    """

    def load_bytecode(self, bucket) -> None:
        with contextlib.suppress(OSError):
            super().load_bytecode(bucket)

    def dump_bytecode(self, bucket) -> None:
        with contextlib.suppress(OSError):
            super().dump_bytecode(bucket)


def _template_cache() -> _TemplateCache | None:
    key = hashlib.sha256(repr((jinja2.__version__, sys.version,
                               sorted(map(str, ENVIRONMENT_OPTIONS.items())))).encode())
    directory = cache_dir() / "templates" / key.hexdigest()[:16]
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return _TemplateCache(str(directory))


@functools.lru_cache(maxsize=None)
def environment() -> jinja2.Environment:
    """The one cached jinja2 environment (its compiled templates cached on disk)."""
    return jinja2.Environment(loader=jinja2.FileSystemLoader(str(templates_dir())),
                              bytecode_cache=_template_cache(), **ENVIRONMENT_OPTIONS)


def templates_digest(kinematics: bool = False) -> str:
    """Hash of the model templates (not the integrators'), part of the model hash;
    with ``kinematics``, of the frame kinematics' too."""
    h = hashlib.sha256()
    for name in MODEL_TEMPLATES + (KINEMATICS_TEMPLATES if kinematics else ()):
        h.update(name.encode())
        h.update((templates_dir() / name).read_bytes())
    return h.hexdigest()


def c_dir() -> Path:
    """Where the integrators' C lives (``mg_integrate.c`` and ``mg_integrate/``)."""
    here = Path(__file__).resolve().parent / "c"
    if not (here / "mg_integrate.c").is_file():
        raise TemplateError(f"modelgen's integrator sources not found in {here}")
    return here


def integrator_files() -> tuple:
    """The integrators' C files, as paths relative to :func:`c_dir` and to a model's
    output directory: ``mg_integrate.c`` (the one translation unit) and the
    ``mg_integrate/*.c`` it includes, sorted.

    >>> integrator_files()[0]
    'mg_integrate.c'
    """
    root = c_dir()
    return tuple(sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                        if p.suffix in (".c", ".h")))


@functools.lru_cache(maxsize=None)
def _integrator_header(digest: str) -> str:
    context = dict(capi.context(), capi=capi.context(), version=__version__)
    template = f"{INTEGRATOR_HEADER}.j2"
    return render(template, dict(context, template=template))


def integrator_sources() -> dict:
    """The integrators, the same for every model: relative path -> text of
    ``mg_integrate.h`` (rendered from :mod:`modelgen.codegen.capi` and its template,
    cached while they are unchanged) and of the C files of :func:`integrator_files`
    (read from the package as they are).
    """
    h = hashlib.sha256(repr(capi.context()).encode())
    for name in (f"{INTEGRATOR_HEADER}.j2", "macros.j2"):
        h.update((templates_dir() / name).read_bytes())
    sources = {INTEGRATOR_HEADER: _integrator_header(h.hexdigest())}
    for name in integrator_files():
        sources[name] = (c_dir() / name).read_text()
    return sources


def runtime_sources() -> dict:
    """The runtime module's cffi ``cdef`` and C source (``mg_runtime.c``): the
    trampolines of :data:`modelgen.codegen.capi.SIGNATURES` and the interface of
    ``mg_integrate.h``; the same for every model."""
    context = dict(capi=capi.context(), version=__version__, template="mg_runtime.c.j2")
    return {"cdef": render("mg_runtime.c.j2", dict(context, cdef=True)),
            "mg_runtime.c": render("mg_runtime.c.j2", dict(context, cdef=False))}


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
          "a": "const double *a", "pd": "const double *pd", "qdd": "const double *qdd",
          "lam": "const double *lam"}


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
    #: the output lines of a large routine in noinline pieces of CHUNK lines (then
    #: ``body`` is empty), which take ``out_params`` (``out_args`` in a call)
    outs: tuple = ()
    out_params: str = ""
    out_args: str = ""
    #: with ``parts``, the same routine as one function of locals (or None)
    flat: "CFunction | None" = None


def _fields(f: CFunction) -> dict:
    """``asdict(f)`` without its deep copy of every printed line (a CFunction holds
    only strings, ints and tuples of them, which are never changed)."""
    return {field.name: getattr(f, field.name) for field in fields(f)}


def print_routine(routine: Routine, flat: bool = False) -> CFunction:
    """Print a routine; each output array keeps its name in C.  With ``flat``, a
    routine cut into parts also carries its text as one function of locals
    (``flat``), for compilers that do not optimize (see ``macros.j2``)."""
    statements = list(routine.statements)
    slots = _input_slots(routine)
    slots.update((sym, f"v{i}") for i, (sym, _) in enumerate(statements))
    printer = ModelPrinter(slots, routine.name)
    codes = [printer.doprint(expr) for _, expr in statements]
    outs = [(array, [printer.doprint(e) for e in items]) for array, items in routine.outputs]
    if len(statements) <= SINGLE_LIMIT:
        return _whole(routine, codes, outs)
    parts = _parts(routine, codes, outs)
    return replace(parts, flat=_whole(routine, codes, outs)) if flat else parts


def _signature(routine: Routine) -> tuple:
    inputs = tuple(a for a, _ in routine.inputs)
    return ", ".join(_PARAM[a] for a in inputs), ", ".join(inputs), inputs


def _out_lines(outs, rename=None) -> list:
    sub = (lambda code: _LOCAL.sub(rename, code)) if rename else (lambda code: code)
    return [f"{array}[{j}] = {sub(code)};" for array, codes in outs
            for j, code in enumerate(codes)]


def _whole(routine: Routine, codes: list, outs: list) -> CFunction:
    """The routine as one function whose intermediates are all locals ``v<i>``."""
    lines = [f"const double v{i} = {code};" for i, code in enumerate(codes)]
    return CFunction(routine.name, *_signature(routine), 0, (),
                     tuple(lines + _out_lines(outs)), routine.ops_before,
                     routine.ops_after, len(codes))


def _parts(routine: Routine, codes: list, outs: list) -> CFunction:
    """The routine in noinline parts of :data:`CHUNK` statements: the locals used
    outside the part that defines them become entries of the work array."""
    statements = routine.statements
    part_of = {sym: i // CHUNK for i, (sym, _) in enumerate(statements)}
    shared = set()
    for i, (_, expr) in enumerate(statements):
        here = i // CHUNK
        for s in free_symbols(expr):
            part = part_of.get(s)
            if part is not None and part != here:
                shared.add(s)
    for _, items in routine.outputs:
        for e in items:
            shared.update(s for s in free_symbols(e) if s in part_of)
    work = {}
    for i, (sym, _) in enumerate(statements):
        if sym in shared:
            work[f"v{i}"] = f"w[{len(work)}]"

    def rename(match):
        return work.get(match.group(0), match.group(0))

    parts = [[] for _ in range(-(-len(statements) // CHUNK))]
    for i, ((_, expr), code) in enumerate(zip(statements, codes, strict=True)):
        code = _LOCAL.sub(rename, code) if "v" in code else code
        slot = work.get(f"v{i}")
        if slot is not None and expr.func in (sympy.sin, sympy.cos):
            # through a local, so gcc still pairs sin and cos into one sincos call
            parts[i // CHUNK].append(f"const double v{i} = {code};")
            parts[i // CHUNK].append(f"{slot} = v{i};")
        elif slot is not None:
            parts[i // CHUNK].append(f"{slot} = {code};")
        else:
            parts[i // CHUNK].append(f"const double v{i} = {code};")
    out_lines = _out_lines(outs, rename)
    params, args, inputs = _signature(routine)
    common = (routine.name, params, args, inputs, len(work), tuple(tuple(p) for p in parts))
    if len(out_lines) <= CHUNK:
        return CFunction(*common, tuple(out_lines), routine.ops_before, routine.ops_after,
                         len(statements))
    # thousands of output lines in one function (the derivatives' W) cost gcc
    # more than the statements that compute them: each load of w is checked
    # against every store to an output before it
    arrays = [array for array, _ in routine.outputs]
    return CFunction(*common, (), routine.ops_before, routine.ops_after, len(statements),
                     tuple(tuple([f"(void){a};" for a in ("w", *arrays)] + out_lines[k:k + CHUNK])
                           for k in range(0, len(out_lines), CHUNK)),
                     ", ".join(f"double *{a}" for a in arrays),
                     ", ".join(arrays))


#: A routine's local ``v<i>`` in printed C (no other name the printer writes
#: starts a word with ``v`` and digits).
_LOCAL = re.compile(r"\bv\d+\b")


def _comment_safe(text: str) -> str:
    r"""Text that cannot close or nest a C comment, nor smuggle a line break.

    Non-printable characters become spaces; ``*/`` and ``/*`` are split; ``??``
    is split so that no trigraph (``??/`` is a backslash in C99) survives; a
    trailing backslash, which would splice the comment with the next line, is
    followed by a full stop.

    >>> _comment_safe("ends in ??/")
    'ends in ? ?/'
    >>> _comment_safe("a */ b\\")
    'a * / b\\.'
    """
    text = "".join(ch if ch.isprintable() else " " for ch in text)
    text = text.replace("*/", "* /").replace("/*", "/ *")
    while "??" in text:
        text = text.replace("??", "? ?")
    if text.rstrip().endswith("\\"):
        text = text.rstrip() + "."
    return text


def template_context(*, name: str, description: str, model_hash: str, n: int,
                     coordinates, parameters, inputs, bodies,
                     functions: dict, output_columns=(), has_jacobian=False,
                     has_linearize=False, nq: int | None = None, speeds=None,
                     quaternions=(), npd: int = 0, mass_pattern=None,
                     formulation: str = "crba", aba_inward=(), frames=None,
                     constraints=None, derivatives_pattern=None,
                     derivative_loop=None, jacobian_method=None) -> dict:
    """The plain dict every C template receives.

    ``mass_pattern`` (n x n booleans, default dense) marks the entries of the
    mass matrix that can be non-zero: the rhs's solve skips the others
    (:func:`solve_code`).  ``formulation`` is the resolved one (``aba`` or
    ``crba``); ``aba_inward`` the coordinates of the ABA's D in inward order.
    ``constraints``: None, or the dict of :func:`constraint_context`.
    ``derivatives_pattern`` (n x n booleans, the structure of the mass matrix of
    ``derivative_terms``) asks for ``<name>_derivatives`` and
    ``<name>_inverse_dynamics_derivatives``; their solve skips its zeros.
    ``derivative_loop`` (None: ``derivative_terms`` writes the matrices itself)
    has the tables of the loop over the pairs of dofs of the recursive
    derivatives (:func:`modelgen.codegen.tree_derivatives.derivative_loop`).
    ``jacobian_method``: ``derivatives`` builds ``<name>_jacobian`` and the
    dynamics' rows of ``<name>_linearize`` on ``<name>_derivatives``; else
    (``forward``, None) forward mode over the rhs program.

    ``n`` is the number of speeds (the size of A), ``nq`` that of the
    coordinates (default ``n``; more with ball or free joints, whose
    ``quaternions`` are lists of the four state indices of each quaternion).

    ``frames`` (:class:`~modelgen.derive.frames.FrameTerms`, or None) adds the
    frame kinematics' functions (``kinematics``, ``frames``, ``reference``).
    """
    nq = n if nq is None else nq
    kinematics = kinematics_api(name, frames, n, nq, len(parameters))
    solve = solve_code(n, f"{name.upper()}_PIVOT_TOL", mass_pattern)
    return {
        "name": name,
        "NAME": name.upper(),
        "version": __version__,
        "abi_version": ABI_VERSION,
        "model_hash": model_hash,
        "description": _comment_safe(description),
        "n": n,
        "nq": nq,
        "nx": nq + n,
        "has_joints": nq != n,
        "quaternions": [list(qi) for qi in quaternions],
        "speeds": list(speeds) if speeds is not None else [],
        "np": len(parameters),
        "nu": len(inputs),
        "nbodies": len(bodies),
        "npd": npd,
        "coordinates": list(coordinates),
        "parameters": [{"name": p, "default": repr(float(v))} for p, v in parameters],
        "inputs": list(inputs),
        "bodies": list(bodies),
        "functions": {k: _fields(f) for k, f in functions.items()},
        "ny": len(output_columns),
        "has_jacobian": bool(has_jacobian),
        "has_linearize": bool(has_linearize),
        "jacobian_method": jacobian_method or "forward",
        "nc": nq + n + len(inputs),
        "output_columns": list(output_columns),
        "api": _before_integration(
            public_api(name, n, len(parameters), len(inputs), len(bodies),
                       len(output_columns), has_jacobian, has_linearize, nq,
                       rhs_solve=_solve_words(formulation, solve),
                       has_derivatives=derivatives_pattern is not None,
                       jacobian_method=jacobian_method), kinematics, name),
        "kinematics": kinematics,
        "frames": list(frames.frames) if frames else [],
        "nframes": len(frames.frames) if frames else 0,
        "reference": frames.reference if frames else "",
        "REFERENCE": frames.reference.upper() if frames else "",
        **solve,
        "formulation": formulation,
        "aba_inward": list(aba_inward),
        "has_derivatives": derivatives_pattern is not None,
        "derivative_loop": derivative_loop,
        "derivative_aba": bool(derivative_loop and derivative_loop["aba"]),
        "derivative_solve": (derivative_solve(n, f"{name.upper()}_PIVOT_TOL",
                                              derivatives_pattern, len(inputs), name)
                             if derivatives_pattern is not None else None),
        "capi": capi.context(),
        "constraints": constraints,
    } | ({"api": _before_integration(
        constraint_api(name, n, nq, len(parameters), constraints)
        + public_api(name, n, len(parameters), len(inputs), len(bodies),
                     len(output_columns), has_jacobian, has_linearize, nq,
                     rhs_solve="with dependent speeds (see below)", constrained=True),
        kinematics, name)} if constraints else {})


def constraint_context(m: int, mh: int, dependent, independent, n: int,
                       ns: int | None = None, output_lam=()) -> dict:
    """What ``constraints.c.j2`` needs: ``m`` equations (``mh`` holonomic, first),
    the speed indices of the dependent and independent speeds, ``ns`` the number
    of plain coordinates (default ``n``: no ball or free joints); ``output_lam``,
    when the outputs record constraint forces: per output column, the index of
    the multiplier it is (-1: another output)."""
    return {"m": m, "mh": mh, "ni": n - m, "dep": list(dependent), "ind": list(independent),
            "ns": n if ns is None else ns,
            "forces": bool(output_lam), "out_lam": list(output_lam)}


def constraint_api(name: str, n: int, nq: int, n_p: int, c: dict) -> list:
    """The prototypes of a constrained model's own functions."""
    out = [{"ret": "void", "name": f"{name}_constraint_jacobian",
            "params": "const double *q, const double *p, double *out",
            "doc": [f"Constraint Jacobian G(q)[{c['m']}*{n}], row-major: the constraints are",
                    f"G qd = 0; its first {c['mh']} rows are d f / d q of the position",
                    f"constraints f(q) = 0.  q[{nq}], p[{n_p}]."]}]
    if c["mh"]:
        out.insert(0, {"ret": "void", "name": f"{name}_constraint_residuals",
                       "params": "const double *q, const double *p, double *out",
                       "doc": [f"Position constraint residuals f(q)[{c['mh']}] (zero on the",
                               f"constraints; m).  q[{nq}], p[{n_p}]."]})
    out.append({"ret": "int", "name": f"{name}_constrain", "params": "const double *p, double *x",
                "doc": ["Brings x[NX] back onto the constraints in place, as the integrators do",
                        "after every step (call it after yours): quaternions normalised, q by",
                        "Gauss-Newton, then the dependent speeds.  Returns 0, or 1 (x unchanged)",
                        "when it does not converge."]})
    return out


def public_api(name: str, n: int, n_p: int, n_u: int, n_b: int, n_y: int = 0,
               has_jacobian: bool = False, has_linearize: bool = False,
               nq: int | None = None, rhs_solve: str = "",
               has_derivatives: bool = False, jacobian_method: str | None = None,
               constrained: bool = False) -> list:
    """Prototypes and documentation of every exported function.

    The header is rendered from this one list, and the manifest records each
    function's :class:`~modelgen.codegen.capi.Signature` (how Python calls it).
    ``rhs_solve`` (:func:`_solve_words`) says how the rhs gets qdd; empty: the
    articulated-body algorithm.
    """
    P = f"p: {n_p} parameters (see {name}_default_parameters)"
    nq = n if nq is None else nq
    nx = nq + n
    how = (f"the dynamics' rows from {name}_derivatives" if jacobian_method == "derivatives"
           else "forward mode over the generated program")
    extra = []
    if n_y:
        extra.append(
            {"ret": "void", "name": f"{name}_outputs",
             "params": "double t, const double *x, const double *u, const double *p, double *y",
             "doc": [f"The scene's recorded outputs y[{n_y}] at state x[{nx}] (columns in",
                     "the order listed at the top of this file)."]})
    if has_jacobian:
        extra.append(
            {"ret": "int", "name": f"{name}_jacobian",
             "params": "double t, const double *x, const double *u, const double *p, double *J",
             "doc": [f"Jacobian J[{nx}*{nx}] = d xdot / d x, row-major, derived symbolically",
                     f"({how}). Returns the rhs status."]})
    if has_derivatives:
        extra.extend(_derivatives_api(name, n, nq, n_u))
    if has_linearize:
        extra.append(
            {"ret": "int", "name": f"{name}_linearize",
             "params": "double t, const double *x, const double *u, const double *p, "
                       "double *A, double *B, double *C, double *D",
             "doc": [f"State space model about (t, x[{nx}], u[{n_u}], p[{n_p}]), derived",
                     f"symbolically ({how}), row-major:",
                     f"A[{nx}*{nx}] = d xdot / d x, B[{nx}*{n_u}] = d xdot / d u,",
                     f"C[{n_y}*{nx}] = d y / d x, D[{n_y}*{n_u}] = d y / d u (y: the outputs).",
                     "B and D are untouched (may be NULL) when there are no inputs, C and D",
                     "when there are no outputs.  Returns the rhs status (0, or the failing",
                     "pivot; the arrays are then not written)."]})
    return extra + [
        {"ret": "int", "name": f"{name}_abi_version", "params": "void",
         "doc": [f"Returns the ABI version ({ABI_VERSION}) this file was generated for."]},
        {"ret": "void", "name": f"{name}_dimensions", "params": "int *d",
         "doc": [f"Writes the sizes d[7] = {{{name.upper()}_NQ, _NX, _NP, _NU, _NBODIES, _NY, "
                 "_NV}",
                 "(what the loader checks a library against its manifest with)."]},
        {"ret": "void", "name": f"{name}_default_parameters", "params": "double *p",
         "doc": [f"Writes the {n_p} default parameter values into p, in declaration order."]},
        {"ret": "void", "name": f"{name}_mass_matrix",
         "params": "const double *q, const double *p, double *A",
         "doc": [f"Mass matrix A(q, p): q[{nq}] coordinates; {P};",
                 f"A[{n}*{n}] row-major, symmetric (SI units: kg, kg m, kg m^2)."]},
        {"ret": "void", "name": f"{name}_velocity_terms",
         "params": "const double *q, const double *qd, const double *p, double *h",
         "doc": ["Velocity-product term h(q, qd, p) (Coriolis, centrifugal, gyroscopic),",
                 f"so that A qdd = tau - h: q[{nq}], qd[{n}]; {P}; h[{n}]."]},
        {"ret": "void", "name": f"{name}_generalized_forces",
         "params": "double t, const double *q, const double *qd, const double *u, const double *p, double *tau",
         "doc": [f"Generalized forces tau of gravity and actions: t [s]; q[{nq}]; qd[{n}];",
                 f"u[{n_u}] inputs; {P}; tau[{n}] (N or N m per coordinate)."]},
        {"ret": "void", "name": f"{name}_prepare", "params": "const double *p, double *pd",
         "doc": [f"Derived parameters pd[{name.upper()}_NPD] of p[{n_p}]: what the rhs",
                 "computes from the parameters alone (inertias about the joints, products",
                 "of masses and lengths...).  Call it once per parameter set, then",
                 f"{name}_rhs_prepared at every step."]},
        {"ret": "int", "name": f"{name}_rhs_prepared",
         "params": "double t, const double *x, const double *u, const double *p, "
                   "const double *pd, double *xdot",
         "doc": [f"{name}_rhs with pd from {name}_prepare(p, pd): the same xdot, bit for",
                 "bit, and the same status, without the parameter-only work."]},
        {"ret": "int", "name": f"{name}_rhs",
         "params": "double t, const double *x, const double *u, const double *p, double *xdot",
         "doc": _rhs_doc(n, nq, rhs_solve)},
        {"ret": "void", "name": f"{name}_inverse_dynamics",
         "params": "double t, const double *x, const double *qdd, const double *u, "
                   "const double *p, double *Q",
         "doc": [f"Inverse dynamics: the generalized forces Q[{n}] = A qdd + h - tau that must",
                 "act besides the model's own (gravity, effects, actions and the inputs u)",
                 f"for the accelerations qdd[{n}] at state x[{nx}], time t; zero at the",
                 f"qdd that {name}_rhs gives.  O(n) by recursive Newton-Euler for a joint",
                 "tree (N or N m per degree of freedom)."]},
        {"ret": "void", "name": f"{name}_project", "params": "double *x",
         "doc": ["Normalises the quaternions of the ball and free joints in x[NX] in place"
                 if nq != n else "Nothing to do: this model has no ball or free joints",
                 "(the integrators call it after every step; call it after yours)"
                 + (f"; onto the constraints: {name}_constrain." if constrained else ".")]},
        {"ret": "void", "name": f"{name}_energy",
         "params": "const double *q, const double *qd, const double *p, double *out",
         "doc": ["out[0] kinetic energy, out[1] potential energy of gravity (zero at O)",
                 "and of springs [J]."]},
        {"ret": "void", "name": f"{name}_body_poses",
         "params": "const double *q, const double *p, double *T",
         "doc": [f"Pose of every body: T[{n_b}*16], one row-major 4x4 matrix per body",
                 "[[R, r_G], [0, 0, 0, 1]]: R's columns are the body base's unit vectors",
                 "in E, r_G the centre of mass from O in E [m]."]},
    ] + _integrator_api(name, nx, n_p, n_u, n_y, has_jacobian)


def _before_integration(api: list, extra: list, name: str) -> list:
    """``api`` with ``extra`` put after the model functions, before the integrators'."""
    if not extra:
        return api
    at = next(i for i, f in enumerate(api) if f["name"] == f"{name}_system")
    return api[:at] + extra + api[at:]


def kinematics_api(name: str, frames, n: int, nq: int, n_p: int) -> list:
    """Prototypes and documentation of the frame kinematics asked for (``frames``:
    :class:`~modelgen.derive.frames.FrameTerms`, or None: none); each entry also
    names its ``routine`` and output array ``out`` for the C template."""
    if frames is None:
        return []
    nf = len(frames.frames)
    NAME = name.upper()
    where = {"local": "in the frame's own axes, at its origin",
             "world": "in E's axes, of the body-fixed point at O",
             "local_world_aligned": "in E's axes, at the frame's origin"}[frames.reference]
    ref = f"{frames.reference.upper()} ({where})"
    qp = f"q[{nq}] coordinates; p: {n_p} parameters"
    table = [
        ("frame_poses", frames.poses, "T", False,
         [f"Pose of every frame: T[{NAME}_NFRAMES*16], one row-major 4x4 matrix per",
          "frame [[R, r], [0, 0, 0, 1]]: R's columns are the frame's unit vectors in E,",
          f"r its origin from O in E [m]; {qp}."]),
        ("frame_velocities", frames.velocities, "V", True,
         [f"Spatial velocity of every frame: V[{NAME}_NFRAMES*6], linear [m/s] then",
          f"angular [rad/s], {ref}; q[{nq}], qd[{n}] speeds."]),
        ("frame_jacobians", frames.jacobians, "J", False,
         [f"Jacobian of every frame: J[{NAME}_NFRAMES*6*{n}], one row-major 6 x {n} matrix",
          f"per frame with V = J qd: rows linear then angular, {ref};",
          "columns: the speeds (ball and free joints in the tangent space)."]),
        ("frame_bias_accelerations", frames.bias, "a", True,
         ["Classical acceleration of every frame's origin with zero speed derivatives",
          f"(Pinocchio's getFrameClassicalAcceleration, a = 0): a[{NAME}_NFRAMES*6],",
          f"linear [m/s^2] then angular [rad/s^2], {ref};",
          "J_dot qd exactly for LOCAL_WORLD_ALIGNED."]),
        ("com", frames.com, "c", False,
         [f"Centre of mass c[3] from O in E [m]; {qp}."]),
        ("com_jacobian", frames.com_jacobian, "Jc", False,
         [f"Jacobian of the centre of mass Jc[3*{n}], row-major, in E: dc/dt = Jc qd."]),
        ("centroidal_momentum_matrix", frames.centroidal, "Ag", False,
         [f"Centroidal momentum matrix Ag[6*{n}], row-major (Pinocchio's computeCentroidalMap):",
          "the momentum about the centre of mass in E's axes is Ag qd, linear rows",
          "[kg m/s] first, then angular [kg m^2/s]."]),
    ]
    out = []
    for routine, exprs, array, with_qd, doc in table:
        if not exprs or (routine.startswith("frame") and not nf):
            continue
        params = "const double *q, " + ("const double *qd, " if with_qd else "") + \
            f"const double *p, double *{array}"
        out.append({"ret": "void", "name": f"{name}_{routine}", "params": params, "doc": doc,
                    "routine": routine, "out": array})
    return out


def _derivatives_api(name: str, n: int, nq: int, n_u: int) -> list:
    """Prototypes and documentation of the analytical derivatives."""
    nx = nq + n
    tangent = ([] if nq == n else
               ["d/dq in the tangent space: column j along speed j (a quaternion turned by",
                "quat * (0, w) / 2, a free joint's position moved by R v), as Pinocchio's."])
    return [
        {"ret": "int", "name": f"{name}_derivatives",
         "params": "double t, const double *x, const double *u, const double *p, "
                   "double *dqdd_dq, double *dqdd_dv, double *dqdd_du",
         "doc": [f"Derivatives of qdd = {name}_rhs's accelerations at (t, x[{nx}], u[{n_u}], p),",
                 f"row-major: dqdd_dq[{n}*{n}], dqdd_dv[{n}*{n}], dqdd_du[{n}*{n_u}] (untouched,",
                 "may be NULL, without inputs).", *tangent,
                 "-M^-1 times the derivatives of inverse dynamics at a = qdd (Carpentier",
                 "and Mansard 2018), M factorized once over its structural non-zeros.",
                 "Returns the rhs status (0, or the failing pivot: the arrays are then undefined)."]},
        {"ret": "void", "name": f"{name}_inverse_dynamics_derivatives",
         "params": "double t, const double *x, const double *qdd, const double *u, "
                   "const double *p, double *dQ_dq, double *dQ_dv, double *M",
         "doc": [f"Derivatives of Q = {name}_inverse_dynamics(t, x, qdd, u, p), row-major:",
                 f"dQ_dq[{n}*{n}] (tangent space as for {name}_derivatives), dQ_dv[{n}*{n}]",
                 f"and the mass matrix M[{n}*{n}] = dQ/dqdd."]},
    ]


def _solve_words(formulation: str, solve: dict) -> str:
    """How the crba rhs solves A qdd = tau - h (from :func:`solve_code`'s choice), or
    "" for the articulated-body algorithm, which has nothing to solve."""
    if formulation == "aba":
        return ""
    if solve["solve_loop"]:
        return "by LDL^T over the non-zeros of A"
    if solve["solve_lines"]:
        sparse = solve["solve_lines"][0].startswith("/*")
        return "by an unrolled LDL^T that skips the zeros of A" if sparse \
            else "by an unrolled LDL^T"
    return "by Cholesky (A = L L^T) in place"


def _rhs_doc(n: int, nq: int, solve: str) -> list:
    """The header's comment on ``<name>_rhs``: how this model's rhs computes qdd
    (``solve``: :func:`_solve_words`) and what its status means."""
    nx = nq + n
    if solve:
        how = [f"A qdd = tau - h solved {solve}.", "u, p as above."]
        status = ["Returns 0, or k > 0 when the pivot of coordinate k (1-based) is not",
                  f"positive (A not positive definite); xdot[{nq}..{nx}) is then NaN."]
    else:
        how = ["qdd by the articulated-body algorithm (O(n), without the mass matrix).",
               "u, p as above."]
        status = ["Returns 0, or k > 0 when the articulated inertia D of coordinate k",
                  "(1-based) is not positive (the mass matrix is not positive definite);",
                  f"xdot[{nq}..{nx}) is then NaN."]
    if nq == n:
        return [f"State derivative for x = [q, qd] (x[{nx}]): xdot = [qd, qdd];"] + how + status
    return [f"State derivative for x = [q, qd] (x[{nx}]: {nq} coordinates, {n} speeds):",
            "xdot = [N(q) qd, qdd], N(q) the kinematic relation of the ball and free",
            "joints (dquat/dt = quat * (0, w) / 2, dr/dt = R v);"] + how + status


# -- integration (mg_integrate.h, rendered from modelgen/codegen/capi.py) ----------------

def _integrator_api(name: str, nx: int, n_p: int, n_u: int, n_y: int,
                    has_jacobian: bool) -> list:
    """Prototypes and documentation of the model's entry points into mg_integrate."""
    return [
        {"ret": "void", "name": f"{name}_system", "params": "mg_system *system",
         "doc": [f"Fills system with this model for mg_integrate: nx = {nx}, nu = {n_u},",
                 f"np = {n_p}, ny = {n_y}, rhs = {name}_rhs, jacobian = "
                 + (f"{name}_jacobian," if has_jacobian else "NULL (central differences),"),
                 "outputs = " + (f"{name}_outputs." if n_y else "NULL.")]},
        {"ret": "int", "name": f"{name}_jacobian_fd",
         "params": "double t, const double *x, const double *u, const double *p, double *J",
         "doc": [f"d xdot / d x by central differences of {name}_rhs (mg_jacobian_fd):",
                 f"J[{nx}*{nx}] row-major, J[i*{nx} + j] = d xdot_i / d x_j; x[{nx}], u[{n_u}],",
                 f"p[{n_p}] as for {name}_rhs; returns its status."]},
        {"ret": "int", "name": f"{name}_integrate",
         "params": "double t0, double t1, const double *x0, const double *p, "
                   "const mg_inputs *inputs, const mg_options *options, mg_output *output, "
                   "mg_stats *stats, double *work",
         "doc": [f"mg_integrate on this model: x0[{nx}], p[{n_p}], inputs (NULL: u = 0),",
                 f"output->x[capacity][{nx}]" + (f", output->y[capacity][{n_y}]" if n_y else "")
                 + f", work[{name.upper()}_WORK_SIZE].",
                 "Returns an MG_STATUS_* (see mg_integrate.h)."]},
        {"ret": "int", "name": f"{name}_integrate_batch",
         "params": "long n_runs, double t0, double t1, const double *x0, const double *p, "
                   "long p_stride, const mg_inputs *inputs, const mg_options *options, "
                   "long n_eval, const double *t_eval, double *x_out, double *y_out, long *n_out, "
                   "int *status, mg_stats *stats, double *stop, double *work",
         "doc": [f"mg_integrate_batch on this model: x0[n_runs][{nx}], parameters",
                 f"p + r * p_stride (0: one set, {n_p}: one per run), x_out[n_runs][n_eval][{nx}],",
                 f"y_out[n_runs][n_eval][{n_y}] the outputs (NULL: none)," if n_y
                 else "y_out NULL (this model records no outputs),",
                 f"stop[n_runs][MG_STOP_X + {nx}].  Returns the number of failed runs."]},
    ]


def emit_sources(context: dict) -> dict:
    """Render ``<name>.h`` and ``<name>.c``; the frame kinematics, when asked, go at the
    end of the C and before the header's closing ``extern "C"`` (so a build that
    asks for none is byte for byte what it was)."""
    name = context["name"]
    header = render("model.h.j2", dict(context, template="model.h.j2"))
    source = render("model.c.j2", dict(context, template="model.c.j2"))
    if context["kinematics"]:
        source += render("kinematics.c.j2", context)
        head, mark, tail = header.rpartition(_HEADER_END)
        header = head + render("kinematics.h.j2", context) + mark + tail
    return {f"{name}.h": header, f"{name}.c": source}


#: where the header's declarations end (the kinematics' defines go before it)
_HEADER_END = "#ifdef __cplusplus\n}\n#endif"
