"""The whole pipeline: spec -> kinematics -> dynamics -> CSE -> C -> module.

:func:`generate` runs every stage (or reuses the cache) and reports the time
of each stage and the operation counts.  It knows nothing of YAML or the CLI.
"""
from __future__ import annotations

import gc
import hashlib
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

from modelgen.version import __version__
from modelgen.codegen import budget
from modelgen.codegen import parts
from modelgen.codegen.build import (Generated, build_module, cache_lookup,
                                    compiler, default_output, host_flags, integrator_hash,
                                    part_command, runtime_module, unoptimized)
from modelgen.codegen.capi import signature_of
from modelgen.codegen.compilers import core_count, probe_compiler
from modelgen.codegen.cse import Routine, hoist_parameters, make_routines
from modelgen.derive.frames import FrameTerms, derive_frames
from modelgen.derive.aba import ForwardDynamics, derive_aba, derive_aba_jacobian
from modelgen.derive.dynamics import Equations, derive_equations
from modelgen.derive.graph import GraphBuilder
from modelgen.derive.joint_tree import JointTree, extract_joint_tree
from modelgen.derive.rnea import derive_model_inverse_dynamics, derive_velocity_terms
from modelgen.derive.rnea_derivatives import differentiate_inverse_dynamics
from modelgen.derive.rnea_partials import RneaPartials
from modelgen.codegen import tree_derivatives as plan
from modelgen.codegen.tree_derivatives import (derivative_loop, derivative_manifest,
                                               derivative_routine, derivatives_pattern,
                                               time_free)
from modelgen.errors import ModelError, ModelgenError
from modelgen.codegen.emit import (ABI_VERSION, constraint_context, emit_sources,
                                   integrator_sources, print_routine, runtime_sources,
                                   template_context, templates_digest)
from modelgen.derive.constraints import check_constraints, constraint_rows, derive_constraints
from modelgen.codegen.options import FORMULATIONS, REFERENCES, BuildOptions
from modelgen.derive.jacobian import accelerations, derive_jacobian_terms, residual
from modelgen.derive.constrained_linearize import (derive_constrained_linearization_terms,
                                                   multipliers)
from modelgen.derive.linearize import (derive_linearization_terms,
                                      derive_output_linearization)
from modelgen.derive.kinematics import derive_kinematics
from modelgen.derive.outputs import derive_outputs
from modelgen.model.spec import ModelSpec


#: smallest n for which ``auto`` chooses aba.  Measured with bench/aba_scaling.py
#: (rhs in C, same run, busy 2-core machine): crba/aba = 1.6 at n = 2, 1.7 at
#: n = 7, 2.3-2.4 at n = 20, 4.2 at n = 50, 21 at n = 100, 1.4-3 on the 7-joint
#: arm; there is no crossover (at n = 1 aba has nothing to solve either), so
#: every joint tree gets aba.
ABA_CROSSOVER = 1


def model_hash(spec: ModelSpec, options: BuildOptions | None = None) -> str:
    """Hash of what determines a build: the model, modelgen, the model templates
    (not the integrators', which every model shares) and the build options
    (:meth:`BuildOptions.key_text`; default: the defaults; ``auto`` resolved as
    :func:`generate` resolves it).

    The file the model came from and its line numbers are not part of it, so
    the same model gives the same build wherever it lies.  Its ``units:`` are:
    they change no line of C, but the manifest carries them, and a cached
    build must not answer with another model's units.
    """
    options = options if options is not None else BuildOptions()
    if options.formulation == "auto":
        options = replace(options, formulation=choose_formulation(spec)[0])
    h = hashlib.sha256()
    for part in (repr(replace(spec, source=None, lines=(), units=tuple(sorted(spec.units))))
                 + (f" armature={spec.armature!r}" if spec.armature else "")
                 + ("" if spec.physical_inertia else " physical_inertia=False"),
                 options.key_text(read=False), __version__, str(ABI_VERSION),
                 templates_digest(kinematics=options.kinematics is not None)):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


#: The routines on the integration path (compiled as MG_PART 2, see model.c.j2).
INTEGRATION_PATH = ("prepare", "rhs", "outputs", "jacobian_terms", "linearize_terms",
                    "constraint_residuals", "constraint_jacobian")
#: What a controller calls at every step (MG_PART 3; kinematics.c.j2's are there too,
#: and the derivatives' solve and API).
CONTROL_PATH = ("inverse_dynamics", "frame_poses", "frame_velocities",
                "frame_jacobians", "frame_bias_accelerations", "com", "com_jacobian",
                "centroidal_momentum_matrix")
#: The derivatives' straight line (MG_PART 4): the largest routine of a model built
#: with derivatives, so a part of its own, compiled beside the others.
DERIVATIVE_PATH = ("derivative_terms",)


def routine_part(name: str) -> int:
    """The MG_PART a routine is compiled in: 2, 3, 4, else 1 (the model functions)."""
    return (2 if name in INTEGRATION_PATH else 3 if name in CONTROL_PATH
            else 4 if name in DERIVATIVE_PATH else 1)


def part_statements(statements: dict) -> dict:
    """Routine name -> statements, to part -> its largest routine's statements (what
    :func:`modelgen.codegen.build.build_module` chooses optimisation levels and
    the order it starts the parts in by): parts 1 to 3 always, 4 only with the
    derivatives (without, it would compile nothing).

    >>> part_statements({"rhs": 900, "prepare": 40, "mass_matrix": 500})
    {1: 500, 2: 900, 3: 0}
    """
    parts = {1, 2, 3} | {routine_part(name) for name in statements}
    return {part: max((count for name, count in statements.items()
                       if routine_part(name) == part), default=0)
            for part in sorted(parts)}


#: How a model is built and loaded (part of the cache key): a plain shared library
#: called through the runtime module's trampolines.
LIBRARY_FORMAT = "shared-library+runtime-trampolines"


def runtime(rebuild: bool = False) -> tuple:
    """(module name, path) of the compiled runtime module, built on first use (and
    again with ``rebuild``, when its import failed)."""
    return runtime_module(integrator_sources(), runtime_sources(), rebuild=rebuild)


def build_hash(spec: ModelSpec, options: BuildOptions | None = None) -> str:
    """Cache key of the compiled module: the model hash, the compiler and its flags,
    and the integrators it links (so a changed mg_integrate rebuilds every module)."""
    return _build_key(model_hash(spec, options))


def _build_key(model: str) -> str:
    """:func:`build_hash` of the model whose :func:`model_hash` is ``model``."""
    h = hashlib.sha256()
    for part in (LIBRARY_FORMAT, model,
                 " ".join(compiler()), " ".join(host_flags()),
                 os.environ.get("MODELGEN_CFLAGS", ""), integrator_hash(integrator_sources())):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def choose_formulation(spec: ModelSpec, formulation: str = BuildOptions.formulation):
    """``(formulation, joint tree or None)``: resolve ``auto`` and check ``aba``.

    ``aba`` on a model that is not a joint tree raises the
    :class:`~modelgen.errors.ModelError` of
    :func:`~modelgen.derive.joint_tree.extract_joint_tree`, which names the
    offending expression; ``auto`` then falls back to ``crba``.

    >>> from modelgen.model.chains import spatial_chain
    >>> choose_formulation(spatial_chain(7).spec())[0]
    'aba'
    """
    if formulation not in FORMULATIONS:
        raise ModelError(f"unknown formulation {formulation!r}", file=spec.source,
                         key="formulation", fix="use one of " + ", ".join(FORMULATIONS))
    if formulation == "crba" or (spec.constraints and formulation == "auto"):
        return "crba", None
    if formulation == "aba" and spec.constraints:
        raise ModelError("formulation 'aba' needs a joint tree, and a model with "
                         "constraints is not one", file=spec.source, key="formulation",
                         fix="use formulation 'crba' (or 'auto') for a constrained model")
    if formulation == "aba":
        return "aba", extract_joint_tree(spec)
    if spec.n < ABA_CROSSOVER:
        return "crba", None
    try:
        return "aba", extract_joint_tree(spec)
    except ModelError:
        return "crba", None


def routines_for(eqs: Equations, output_exprs=(), jacobian=None,
                 forward: ForwardDynamics | None = None, linearization=None, inverse=None,
                 constraints=None, derivatives=None, output_lam=()):
    """The C routines of a model: (name, inputs, outputs) for make_routines.

    With ``forward`` (the ABA program) the ``rhs`` routine writes q_ddot and
    the articulated inertias D (in the order of ``forward.inward``), and
    ``jacobian_terms`` is d(q_ddot)/dx.  With ``linearization``
    (:class:`~modelgen.derive.linearize.LinearizationTerms`) ``linearize_terms``
    writes its R and Y (derivatives with respect to [x, u]).  ``inverse``:
    ``(qdd symbols, Q)`` of ``inverse_dynamics``, Q = A qdd + h - tau.
    ``derivatives`` (:class:`~modelgen.derive.rnea_derivatives.InverseDynamicsDerivatives`):
    ``derivative_terms`` writes dQ/dq, dQ/dv, dQ/du (with inputs) and M at ``a``.
    ``output_lam``: the multiplier symbols, when an output records a constraint
    force (the C computes them from the rhs and passes them to ``outputs``).
    """
    n = len(eqs.qd)
    t = (("t", (eqs.t,)),)
    q, qd, u, p = ("q", eqs.q), ("qd", eqs.qd), ("u", eqs.u), ("p", eqs.p)
    x = ("x", eqs.q + eqs.qd)
    A_flat = tuple(eqs.A[i][j] for i in range(n) for j in range(n))
    b = tuple(eqs.tau[k] - eqs.h[k] for k in range(n))
    qdot = (("qdot", eqs.qdot),) if eqs.has_joints else ()
    if forward is not None:
        rhs = ("rhs", t + (x, u, p),
               (("qdd", forward.qdd), ("D", tuple(forward.D[k] for k in forward.inward)))
               + qdot)
        jac_inputs = t + (x, u, p)
    else:
        rhs = ("rhs", t + (x, u, p), (("A", A_flat), ("b", b)) + qdot
               + ((("gamma", constraints.gamma),) if constraints else ()))
        jac_inputs = t + (x, u, p, ("a", jacobian.a)) if jacobian else ()
    lin = []
    if linearization is not None and (linearization.R or linearization.Y):
        # no R: the dynamics' rows come from <name>_derivatives, only the outputs' here
        lin_inputs = t + (x, u, p) + ((("a", linearization.a),) if linearization.a else ()) \
            + ((("lam", linearization.lam),) if linearization.lam else ())
        lin = [("linearize_terms", lin_inputs,
                ((("R", tuple(e for row in linearization.R for e in row)),)
                 if linearization.R else ())
                + ((("Y", tuple(e for row in linearization.Y for e in row)),)
                   if linearization.Y else ()))]
    cons = []
    if constraints is not None:
        if constraints.residuals:
            cons.append(("constraint_residuals", (q, p), (("f", constraints.residuals),)))
        cons.append(("constraint_jacobian", (q, p),
                     (("G", tuple(e for row in constraints.G for e in row)),)))
    return cons + [
        ("mass_matrix", (q, p), (("A", A_flat),)),
        ("velocity_terms", (q, qd, p), (("h", eqs.h),)),
        ("generalized_forces", t + (q, qd, u, p), (("tau", eqs.tau),)),
        rhs,
        ("energy", (q, qd, p), (("out", (eqs.kinetic, eqs.potential)),)),
        ("body_poses", (q, p), (("T", tuple(e for pose in eqs.poses for e in pose)),)),
    ] + ([("inverse_dynamics", t + (x, ("qdd", inverse[0]), u, p), (("Q", inverse[1]),))]
         if inverse else []) \
      + ([("outputs", t + (x, u, p) + ((("lam", output_lam),) if output_lam else ()),
            (("y", tuple(output_exprs)),))] if output_exprs else []) \
      + ([("jacobian_terms", jac_inputs,
           (("D", tuple(e for row in jacobian.D for e in row)),)
           + ((("K", tuple(e for row in jacobian.K for e in row)),) if jacobian.K else ()))]
         if jacobian else []) \
      + lin \
      + ([derivative_routine(t + (x, u, p), derivatives)] if derivatives else [])


def frame_routines(terms: FrameTerms | None, eqs: Equations) -> list:
    """The routines of the frame kinematics asked for (:mod:`modelgen.derive.frames`)."""
    if terms is None:
        return []
    q, qd, p = ("q", eqs.q), ("qd", eqs.qd), ("p", eqs.p)
    table = (("frame_poses", (q, p), "T", terms.poses),
             ("frame_velocities", (q, qd, p), "V", terms.velocities),
             ("frame_jacobians", (q, p), "J", terms.jacobians),
             ("frame_bias_accelerations", (q, qd, p), "a", terms.bias),
             ("com", (q, p), "c", terms.com),
             ("com_jacobian", (q, p), "Jc", terms.com_jacobian),
             ("centroidal_momentum_matrix", (q, p), "Ag", terms.centroidal))
    return [(name, inputs, ((out, exprs),)) for name, inputs, out, exprs in table if exprs]


def _hoisted(routines, split=hoist_parameters) -> tuple:
    """``routines`` with ``rhs`` split into ``prepare`` (its parameter-only
    statements, written into ``pd``) and the ``rhs`` that reads ``pd``
    (:func:`modelgen.codegen.cse.hoist_parameters`, or ``split``)."""
    out = []
    for r in routines:
        out.extend(split(r) if r.name == "rhs" else (r,))
    return tuple(out)


def _check_generable(spec: ModelSpec) -> None:
    """A model needs a coordinate and a body, or its mass matrix is empty or zero."""
    if not spec.coordinates:
        raise ModelError("the model has no generalized coordinates", file=spec.source,
                         line=spec.line_of("coordinates"), key="coordinates",
                         fix="declare at least one coordinate, e.g. coordinates: [q1]")
    if not spec.bodies:
        raise ModelError("the model has no bodies, so its mass matrix is zero",
                         file=spec.source, line=spec.line_of("bodies"), key="bodies",
                         fix="declare at least one body with a mass under 'bodies'")


def generate(spec: ModelSpec, out_dir=None, *, force: bool = False,
             options: BuildOptions | None = None, progress=None, outputs=None,
             jacobian: bool | None = None, formulation: str | None = None,
             linearize: bool | None = None, max_operations: int | None = None,
             while_compiling=None) -> Generated:
    """Generate, compile and cache the model; reuse an unchanged build.

    ``out_dir`` defaults to :func:`default_output` (the per-user cache).
    ``options`` (:class:`~modelgen.codegen.options.BuildOptions`) says what to
    build; the keywords ``outputs``, ``jacobian``, ``formulation`` and
    ``linearize`` are shorthand that override its fields.  ``outputs`` (a tuple of
    :class:`~modelgen.model.spec.OutputSpec`, from a scene) adds a
    ``<name>_outputs`` routine computing exactly those quantities.
    ``jacobian=True`` adds ``<name>_jacobian``, the symbolic d(xdot)/dx.
    ``formulation`` (one of :data:`FORMULATIONS`) chooses how ``<name>_rhs``
    computes q_ddot; the Jacobian is derived from the same program.
    ``linearize=True`` adds ``<name>_linearize`` (A, B and, for the scene's
    outputs, C and D, symbolic; see :mod:`modelgen.derive.linearize`) and
    implies ``jacobian``.
    ``progress`` is None or a callable ``progress(stage)`` called as each of
    :data:`~modelgen.codegen.build.STAGES` starts (not at all when the build is reused).
    ``max_operations`` is the build budget (:mod:`modelgen.codegen.budget`:
    default ``$MODELGEN_MAX_OPERATIONS``, else 320,000 operations after CSE): a
    model over it is refused with a ModelError before deriving (by an estimate
    from its size) or after CSE, never after minutes of compiling.  The seconds
    of the result (``check``, then each stage) add up to the whole call.
    ``while_compiling()`` (if given) is called once the compilers have started,
    while they run (not at all when the build is reused).

    >>> g = generate(load_model("models/double_pendulum.yaml"))   # doctest: +SKIP
    >>> g.manifest["n"]                                             # doctest: +SKIP
    2
    """
    start = time.perf_counter()
    limit = budget.max_operations(max_operations)
    options = BuildOptions.of(options, outputs=outputs, jacobian=jacobian,
                              formulation=formulation, linearize=linearize)
    _check_options(spec, options)
    resolved, tree = choose_formulation(spec, options.formulation)
    options = replace(options, formulation=resolved)
    directory = Path(out_dir) if out_dir is not None else default_output(spec.name)
    # computed once: the emit stage prints it into the preamble
    model_key = model_hash(spec, options)
    key = _build_key(model_key)
    damage = ""
    if not force:
        hit, damage = cache_lookup(directory, key)
        if hit is not None:
            return Generated(hit, hit.manifest)
    budget.check_estimate(spec, tree, limit)
    # the compiler's --version (is it gcc?) runs while the model is derived
    probe_compiler(tuple(compiler()))
    clock = _Clock(progress)
    clock.seconds["check"] = time.perf_counter() - start    # hashes, formulation, cache
    early = None
    try:
        with _collector_paused():
            with clock("derive"):
                derived = _derive(spec, options, tree)
            with clock("cse"):
                listed = _routine_list(derived)
                early = _EarlyStart(spec, options, derived, listed, model_key, directory,
                                    limit)
                routines = _eliminate(derived, early, listed)
                budget.check_cost(spec, budget.build_cost(routines, early.trig), limit)
            with clock("emit"):
                emitted = _emit(spec, options, derived, routines, model_key, early.printed)
        with clock("compile"):
            return _compile(directory, spec, options, derived, emitted, key, clock.seconds,
                            damage, while_compiling, early.started)
    finally:
        if early is not None:
            early.stop()


# -- the stages ------------------------------------------------------------------------

class _Clock:
    """The seconds of each stage, and ``progress(stage)`` as each starts."""

    def __init__(self, progress):
        self.progress = progress
        self.seconds = {}

    def start(self, name: str) -> None:
        if self.progress is not None:
            self.progress(name)

    @contextmanager
    def __call__(self, name: str):
        self.start(name)
        t0 = time.perf_counter()
        try:
            yield
        finally:        # set before a return inside the block reaches the caller
            self.seconds[name] = time.perf_counter() - t0


@contextmanager
def _collector_paused():
    """Python's cyclic garbage collector off for the block, as it was after.

    The derivation, CSE and printing build hundreds of thousands of sympy
    objects that live until the stages end and make few reference cycles, so
    the collector's passes, each over every object alive (more and longer ones
    as the model grows), find next to nothing to free; the few cycles are
    freed by the first collection after the block.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def _check_options(spec: ModelSpec, options: BuildOptions) -> None:
    """Refuse what cannot be generated before any work."""
    _check_generable(spec)
    k = options.kinematics
    if k is not None:
        _check_kinematics(spec, k)
    if options.linearize and spec.joints:
        raise ModelError("linearization of a model with ball or free joints is not supported: "
                         "its state holds unit quaternions, whose four components cannot "
                         "move independently", file=spec.source, key="linearize",
                         fix="build with derivatives=True and use cm.derivatives (in the "
                             "tangent space), or write the rotations as simple angles")
    if options.derivatives and spec.constraints:
        raise ModelError("the analytical derivatives of a constrained model are not "
                         "supported: they are those of the joint tree's dynamics, while "
                         "a constrained model's accelerations also carry the constraint "
                         "forces, which depend on the state", file=spec.source,
                         key="derivatives",
                         fix="build with jacobian=True (<name>_jacobian) or linearize=True "
                             "(<name>_linearize) instead: they differentiate the "
                             "constrained rhs, constraint forces included")
    if options.jacobian and spec.joints and spec.constraints:
        raise ModelError("the Jacobian of a constrained model with ball or free joints is "
                         "not supported: its derivatives are taken in the coordinates, "
                         "and a quaternion's four components cannot move independently",
                         file=spec.source, key="jacobian",
                         fix="build without jacobian=True (the implicit integrators then "
                             "difference the rhs), or write the rotations as simple angles")


def _check_kinematics(spec: ModelSpec, k) -> None:
    """Every frame asked for is the model's, the reference is known."""
    if k.reference not in REFERENCES:
        raise ModelError(f"unknown frame reference {k.reference!r}", file=spec.source,
                         key="kinematics.reference", fix="use one of " + ", ".join(REFERENCES))
    names = [f.name for f in spec.frames]
    for frame in k.frames:
        if frame not in names:
            raise ModelError(f"no frame named {frame!r} in the model", file=spec.source,
                             key="kinematics.frames",
                             fix=("declare it under 'frames:' or use one of: "
                                  + ", ".join(names)) if names
                             else "declare it under 'frames:' (a point and a base)")
    if len(set(k.frames)) != len(k.frames):
        raise ModelError("a frame is listed twice", file=spec.source, key="kinematics.frames",
                         fix="list each frame once")


@dataclass(frozen=True)
class Derived:
    """What the derive stage gives the later ones: the equations and every program
    derived from them, all in one expression ``graph``."""
    eqs: Equations
    columns: object             # the scene's outputs (derive_outputs), or None
    forward: ForwardDynamics | None     # the ABA program (formulation aba), or None
    inverse: tuple              # (qdd symbols, Q) of inverse_dynamics
    linearization: object       # LinearizationTerms, or None
    terms: object               # the Jacobian's terms, or None
    graph: object = field(repr=False)
    frames: FrameTerms | None = None    # the frame kinematics asked for, or None
    constraints: object = None  # ConstraintTerms of a constrained model, or None
    #: InverseDynamicsDerivatives or RneaPartials (options.derivatives, or what the
    #: Jacobian is built on), or None
    derivatives: object = None
    #: how ``<name>_jacobian`` and ``<name>_linearize`` get the accelerations'
    #: derivatives (``forward`` or ``derivatives``: :func:`_state_derivatives`), or None
    jacobian_method: str | None = None

    @property
    def output_exprs(self) -> tuple:
        return self.columns.exprs if self.columns else ()


def _derive(spec: ModelSpec, options: BuildOptions, tree: JointTree | None) -> Derived:
    """Kinematics, equations of motion, outputs, the ABA (with a joint ``tree``), the
    inverse dynamics and the Jacobian or linearization the options ask for."""
    kin = derive_kinematics(spec)
    eqs = derive_equations(kin)
    columns = derive_outputs(kin, eqs, options.outputs) if options.outputs else None
    graph = columns.graph if columns else eqs.graph
    forward = derive_aba(eqs, tree, spec, graph) if tree is not None else None
    graph = forward.graph if forward else graph
    if tree is not None and time_free(tree):
        # h by RNEA in link frames (O(n), sharing ABA's outward pass); after the
        # ABA, whose program keeps the order it was written in (each joint's
        # velocity next to its forces)
        builder = GraphBuilder(graph)
        eqs = replace(eqs, h=derive_velocity_terms(builder, tree, eqs.qd))
        # inverse dynamics A qdd + h - tau by RNEA too, sharing the velocities
        qdd = accelerations(len(eqs.qd))
        inverse = (qdd, derive_model_inverse_dynamics(builder, eqs, tree, spec, qdd))
        graph = builder.freeze()
        forward = replace(forward, graph=graph)
    else:       # minus the residual tau - h - A qdd of the composite-body equations
        qdd, r = residual(eqs)
        inverse = (qdd, tuple(-e for e in r))
    derivatives = None
    if options.derivatives:
        # a joint tree: the recursive derivatives, O(n) statements and a C loop
        # over the pairs of dofs on one branch; any other model: forward mode
        # over its composite-body inverse dynamics
        derivatives = (plan.tree_derivatives(eqs, tree, spec, graph)
                       if tree is not None and time_free(tree)
                       else differentiate_inverse_dynamics(graph, eqs, *inverse))
        graph = derivatives.graph
    constraints = None
    if spec.constraints:
        constraints = derive_constraints(kin, graph)
        check_constraints(constraints, spec)
        if constraints.rows != constraint_rows(spec):   # pragma: no cover - kept in step
            raise AssertionError("the constraint forces' rows differ from G's rows")
        graph = constraints.graph
    linearization, terms, method = None, None, None
    if constraints is not None and options.jacobian:
        # the rhs's three sets of equations, differentiated for the C code to solve
        # for the total derivatives (the Jacobian is the state columns of its A)
        linearization = derive_constrained_linearization_terms(
            eqs, constraints, columns.exprs if columns and options.linearize else ())
        method = "forward"
    elif options.jacobian or options.linearize:
        method, derivatives, linearization, terms = _state_derivatives(
            spec, options, eqs, tree, graph, columns, forward, derivatives)
    # the last extension of the program: the derivatives' graph stops before the
    # constraints' (derived after them), so it is the last only when
    # _state_derivatives chose (and perhaps derived) them
    graph = (linearization.graph if linearization else terms.graph if terms else
             derivatives.graph if method == "derivatives" else graph)
    frames = _derive_frames(spec, options, kin, graph)
    graph = frames.graph if frames else graph
    return Derived(eqs, columns, forward, inverse, linearization, terms, graph, frames,
                   constraints, derivatives, method)


def _state_derivatives(spec, options, eqs, tree, graph, columns, forward, derivatives):
    """``(method, derivatives, linearization, terms)`` for ``<name>_jacobian`` and
    ``<name>_linearize``: ``forward``, by forward mode over the rhs program
    (``terms``, or the state columns of ``linearization``), or ``derivatives``, the
    dynamics' rows from ``<name>_derivatives`` (``derivatives``, derived here when
    the options did not ask for them) and only the outputs' rows differentiated."""
    outputs = columns.exprs if columns and options.linearize else ()

    def forward_mode():
        if options.linearize:   # one pass for A, B, C, D; the Jacobian is its state columns
            lin = derive_linearization_terms(eqs, graph, outputs,
                                             forward.qdd if forward else None)
            return lin, lin.jacobian_terms()
        # over ``graph``, which holds the derivatives' program too when the options
        # ask for both (forward's own graph stops before it)
        return None, (derive_aba_jacobian(replace(forward, graph=graph), eqs) if forward
                      else derive_jacobian_terms(eqs, graph))

    if not plan.jacobian_candidate(spec, tree):
        return ("forward", derivatives) + forward_mode()
    d = derivatives if derivatives is not None else plan.tree_derivatives(eqs, tree, spec, graph)
    if spec.n <= plan.FORWARD_JACOBIAN_MAX:
        lin, terms = forward_mode()
        if plan.jacobian_operations(terms) <= plan.derivatives_operations(d, len(eqs.u)) \
                + plan.DERIVATIVES_CALL + 2 * spec.n * spec.n:
            return "forward", derivatives, lin, terms
    lin = derive_output_linearization(eqs, d.graph, outputs) if options.linearize else None
    return "derivatives", d, lin, None


def _derive_frames(spec: ModelSpec, options: BuildOptions, kin, graph) -> FrameTerms | None:
    """The frame kinematics of ``options.kinematics`` (None: none asked)."""
    k = options.kinematics
    if k is None:
        return None
    by_name = {f.name: f for f in spec.frames}
    return derive_frames(kin, graph, tuple(by_name[f] for f in k.frames), k.reference,
                         k.bias_acceleration and bool(k.frames), k.com, k.centroidal)


def _routine_list(derived: Derived) -> list:
    """``(name, inputs, outputs)`` of every routine of the model, for make_routines."""
    d = derived
    output_lam = multipliers(d.constraints.m) \
        if d.columns is not None and d.columns.reads_multipliers else ()
    return routines_for(d.eqs, d.output_exprs, d.terms, d.forward, d.linearization, d.inverse,
                        d.constraints, d.derivatives, output_lam) \
        + frame_routines(d.frames, d.eqs)


def _eliminate(derived: Derived, ready=None, listed=None) -> tuple:
    """CSE of every routine (``listed``: :func:`_routine_list`'s, if known); the rhs
    (what an integration runs), the derivatives' straight line and the inverse
    dynamics are eliminated on their own (first, in that order: the largest
    compiles first, see :class:`_EarlyStart`), and the rhs's parameter-only
    part hoisted.  ``ready(known)`` (if given) is called after each of those
    passes with the routines known so far, hoisted (name -> Routine)."""
    splits = {}             # id(rhs) -> (rhs, its split), by identity: no hash of it

    def split(rhs):         # once, for the early starts and the result alike
        if id(rhs) not in splits:
            splits[id(rhs)] = (rhs, hoist_parameters(rhs))
        return splits[id(rhs)][1]

    def hoisted_ready(built: dict) -> None:
        ready({r.name: r for r in _hoisted(built.values(), split)})
    # the recursive derivatives' program names every per-dof vector as it is
    # built: a CSE pass over it is costly and finds nothing gcc does not
    plain = ("derivative_terms",) if isinstance(derived.derivatives, RneaPartials) else ()
    return _hoisted(make_routines(derived.graph, listed or _routine_list(derived),
                                  ready=hoisted_ready if ready is not None else None,
                                  alone=("rhs", "derivative_terms", "inverse_dynamics"),
                                  plain=plain),
                    split)


class _EarlyStart:
    """The ``ready`` of :func:`_eliminate` that starts the compile of a part as
    soon as the routines it needs are eliminated (:mod:`modelgen.codegen.parts`),
    on a machine with two cores or more: its own, the rhs (which gives the
    header its ``NPD``) and, for part 3, the derivatives' straight line (whose
    work array its API declares).  The routines eliminated on their own are
    all some parts hold (part 2: the rhs and prepare; 3: the inverse dynamics;
    4: the derivatives' straight line), so those parts compile while the joint
    elimination of the others runs; part 1 and any part with a routine of the
    joint elimination are compiled with the rest.  Nothing starts once the
    routines known are alone over the build budget ``limit`` (the model is then
    refused after its elimination).  ``printed``: the routines it printed, for
    :func:`_emit`; ``started``: part -> :class:`~modelgen.codegen.parts.EarlyPart`;
    ``trig``: the memo of :func:`~modelgen.codegen.budget.build_cost`."""

    def __init__(self, spec: ModelSpec, options: BuildOptions, derived: Derived,
                 listed: list, model_key: str, directory: Path, limit: int):
        self.spec, self.options, self.derived = spec, options, derived
        self.model_key, self.directory, self.limit = model_key, directory, limit
        self.routines = listed          # _routine_list(derived)
        names = {name for name, _, _ in self.routines}
        self.needs = {} if core_count() < 2 else {
            part: {name for name in names if routine_part(name) == part} | {"rhs"}
            | ({"derivative_terms"} & names if part == 3 else set())
            for part in (2, 3, 4) if any(routine_part(name) == part for name in names)}
        self.printed, self.started, self.trig = {}, {}, {}

    def __call__(self, known: dict) -> None:
        ready = [part for part, need in self.needs.items() if need <= known.keys()]
        if not ready:
            return
        for part in ready:
            del self.needs[part]
        if budget.build_cost(tuple(known.values()), self.trig).weighted > self.limit:
            self.needs = {}
            return
        order = [r for name, inputs, _ in self.routines
                 for r in ((known["prepare"], known["rhs"]) if name == "rhs" else
                           (known.get(name) or Routine(name, inputs, (), (), 0, 0),))]
        try:
            emitted = _emit(self.spec, self.options, self.derived, tuple(order),
                            self.model_key, self.printed)
        except ModelgenError:
            # a routine that cannot be printed: the final emit refuses the model, in
            # the order of every build (and on one core), not this one's
            self.needs = {}
            return
        self.printed = {name: emitted.functions[name] for name in known}
        statements = part_statements({f.name: f.statements for f in self.printed.values()})
        name = self.spec.name
        sources = {**emitted.sources, "mg_integrate.h": integrator_sources()["mg_integrate.h"]}
        for part in ready:
            started = parts.start(self.directory, name, sources, part,
                                  part_command(name, part, statements[part]))
            if started is not None:
                self.started[part] = started

    def stop(self) -> None:
        for started in self.started.values():
            started.stop()


@dataclass(frozen=True)
class Emitted:
    """The emit stage's result: the printed routines, the template context and the
    rendered sources (file name -> text)."""
    functions: dict
    context: dict
    sources: dict


def _emit(spec: ModelSpec, options: BuildOptions, derived: Derived, routines: tuple,
          model_key: str, printed=None) -> Emitted:
    """Print every routine to C (``printed``: name -> those already printed) and
    render ``<name>.h`` and ``<name>.c``."""
    eqs, columns, forward = derived.eqs, derived.columns, derived.forward
    printed = printed or {}
    functions = {r.name: printed.get(r.name) or print_routine(
        r, unoptimized(routine_part(r.name), len(r.statements))) for r in routines}
    context = template_context(
        name=spec.name, description=spec.description,
        model_hash=model_key[:16],
        n=spec.n, nq=spec.nq,
        coordinates=spec.coordinates, speeds=spec.speeds,
        quaternions=_quaternions(spec), parameters=spec.parameters, inputs=spec.inputs,
        bodies=eqs.bodies, functions=functions,
        output_columns=[c for cols in columns.columns for c in cols] if columns else (),
        has_jacobian=options.jacobian, has_linearize=options.linearize,
        jacobian_method=derived.jacobian_method,
        npd=next(len(r.outputs[0][1]) for r in routines if r.name == "prepare"),
        # the crba rhs's solve skips the entries of A that are structurally zero
        mass_pattern=None if forward else [[e != 0 for e in row] for row in eqs.A],
        formulation=options.formulation, aba_inward=forward.inward if forward else (),
        frames=derived.frames,
        constraints=_constraint_context(spec, derived.constraints, columns),
        derivatives_pattern=derivatives_pattern(derived.derivatives),
        derivative_loop=(derivative_loop(derived.derivatives)
                         if isinstance(derived.derivatives, RneaPartials) else None))
    return Emitted(functions, context, emit_sources(context))


def _constraint_context(spec: ModelSpec, terms, columns=None) -> dict | None:
    return None if terms is None else constraint_context(
        terms.m, len(terms.residuals), terms.dependent, terms.independent, spec.n,
        len(spec.simple_coordinates),
        columns.multipliers if columns is not None and columns.reads_multipliers else ())


def _quaternions(spec: ModelSpec) -> list:
    """The four state indices of each ball or free joint's quaternion."""
    return [[spec.coordinates.index(c) for c in j.quaternion] for j in spec.joints]


def _manifest(spec: ModelSpec, options: BuildOptions, derived: Derived, emitted: Emitted,
              key: str) -> dict:
    """What the cache records of a build and the loader reads (see
    :data:`modelgen.codegen.build.MANIFEST_KEYS`)."""
    columns = derived.columns
    return {
        "name": spec.name,
        "description": spec.description,
        "version": __version__,
        "abi_version": ABI_VERSION,
        "build_hash": key,
        "n": spec.n,
        "nq": spec.nq,
        "coordinates": list(spec.coordinates),
        "speeds": list(spec.speeds),
        "n_simple": len(spec.simple_coordinates),
        "quaternions": _quaternions(spec),
        "parameters": [[name, float(value)] for name, value in spec.parameters],
        "inputs": list(spec.inputs),
        "units": spec.name_units,
        "jacobian": options.jacobian,
        "linearize": options.linearize,
        "derivatives": options.derivatives,
        **derivative_manifest(derived.derivatives),
        "jacobian_method": derived.jacobian_method,
        "formulation": options.formulation,
        **({"constraints": _constraint_manifest(spec, derived.constraints)}
           if derived.constraints else {}),
        "bodies": list(derived.eqs.bodies),
        **_kinematics_manifest(derived.frames),
        "outputs": [{"name": name, "columns": list(cols)}
                    for name, cols in zip(columns.names, columns.columns)] if columns else [],
        "sources_sha256": {fname: hashlib.sha256(text.encode()).hexdigest()
                           for fname, text in emitted.sources.items()},
        "functions": {f["name"]: signature_of(f["ret"], f["params"]).name
                      for f in emitted.context["api"]},
        "ops": {f.name: {"before_cse": f.ops_before, "after_cse": f.ops_after,
                         "statements": f.statements} for f in emitted.functions.values()},
    }


def _kinematics_manifest(frames: FrameTerms | None) -> dict:
    """The manifest's record of the frame kinematics (nothing when none was asked, so
    the manifests of other builds stay as they were)."""
    if frames is None:
        return {}
    return {"kinematics": {"frames": list(frames.frames), "reference": frames.reference,
                           "bias_acceleration": bool(frames.bias), "com": bool(frames.com),
                           "centroidal": bool(frames.centroidal)}}


def _constraint_manifest(spec: ModelSpec, terms) -> dict:
    """What the loader needs of a constrained model."""
    return {"m": terms.m, "holonomic": len(terms.residuals),
            "rows": [[name, axis] for name, axis in terms.rows],
            "dependent_speeds": list(terms.dependent), "independent_speeds":
            list(terms.independent), "dependent_coordinates": list(terms.dependent_coordinates),
            # by name, and whether modelgen chose them (no 'dependent:' in the model)
            "dependent": [spec.speeds[k] for k in terms.dependent]
            + [spec.coordinates[k] for k in terms.dependent_coordinates],
            "chosen": not spec.dependent_speeds}


def _compile(directory: Path, spec: ModelSpec, options: BuildOptions, derived: Derived,
             emitted: Emitted, key: str, seconds: dict, damage: str,
             while_compiling=None, early=None) -> Generated:
    """Compile and cache the sources (the caller times it into ``seconds``).
    ``damage`` says why a cached build was not reused (recorded in the result);
    ``early``: part -> the parts already compiling (:class:`_EarlyStart`)."""
    manifest = _manifest(spec, options, derived, emitted, key)
    statements = part_statements({f.name: f.statements for f in emitted.functions.values()})
    build = build_module(directory, spec.name, emitted.sources, dict(manifest, seconds=seconds),
                         statements, integrator_sources(), while_compiling, early)
    build = replace(build, rebuilt_because=damage)
    return Generated(build, dict(build.manifest, seconds=seconds))
