"""The whole pipeline: spec -> kinematics -> dynamics -> CSE -> C -> module.

:func:`generate` runs every stage (or reuses the cache) and reports the time
of each stage and the operation counts.  It knows nothing of YAML or the CLI.
"""
from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

from modelgen.version import __version__
from modelgen.codegen.build import (BuildResult, build_module, cache_dir, cache_lookup,
                                    compiler, host_flags, integrator_hash, runtime_module)
from modelgen.codegen.capi import signature_of
from modelgen.codegen.cse import hoist_parameters, make_routines
from modelgen.derive.aba import ForwardDynamics, derive_aba, derive_aba_jacobian
from modelgen.derive.dynamics import Equations, derive_equations
from modelgen.derive.graph import GraphBuilder
from modelgen.derive.joint_tree import JointTree, extract_joint_tree
from modelgen.derive.rnea import derive_inverse_dynamics, derive_velocity_terms
from modelgen.errors import ModelError
from modelgen.codegen.emit import (ABI_VERSION, emit_sources, integrator_sources, print_routine,
                                   runtime_sources, template_context, templates_digest)
from modelgen.derive.jacobian import accelerations, derive_jacobian_terms, residual
from modelgen.derive.linearize import derive_linearization_terms
from modelgen.derive.kinematics import derive_kinematics
from modelgen.derive.outputs import derive_outputs
from modelgen.model.spec import TIME, ModelSpec

def default_output(name: str) -> Path:
    """Where a model is built when no output directory is given: the per-user cache
    (``models/<name>`` under :func:`modelgen.codegen.build.cache_dir`), never the
    current directory."""
    return cache_dir() / "models" / name

#: how ``<name>_rhs`` computes q_ddot: ``crba`` builds A and b = tau - h and
#: solves A q_ddot = b (Cholesky in C); ``aba`` runs the articulated-body
#: algorithm (O(n), joint trees only); ``auto`` picks aba for joint trees with
#: at least ABA_CROSSOVER coordinates, else crba.
FORMULATIONS = ("auto", "aba", "crba")

#: smallest n for which ``auto`` chooses aba.  Measured with bench/aba_scaling.py
#: (rhs in C, same run, busy 2-core machine): crba/aba = 1.6 at n = 2, 1.7 at
#: n = 7, 2.3-2.4 at n = 20, 4.2 at n = 50, 21 at n = 100, 1.4-3 on the 7-joint
#: arm; there is no crossover (at n = 1 aba has nothing to solve either), so
#: every joint tree gets aba.
ABA_CROSSOVER = 1


@dataclass(frozen=True)
class Generated:
    """What :func:`generate` did: the build and the figures of each stage."""
    build: BuildResult
    manifest: dict

    @property
    def seconds(self) -> dict:
        return self.manifest["seconds"]

    @property
    def ops(self) -> dict:
        return self.manifest["ops"]


def model_hash(spec: ModelSpec, outputs=(), jacobian: bool = False,
               formulation: str = "crba", linearize: bool = False) -> str:
    """Hash of what determines the model's generated C: the model, modelgen, the
    model templates (not the integrators', which every model shares), the formulation.

    The file the model came from and its line numbers are not part of it, so
    the same model gives the same C wherever it lies.
    """
    h = hashlib.sha256()
    for part in (repr(replace(spec, source=None, lines=(), units=()))
                 + (f" armature={spec.armature!r}" if spec.armature else ""),
                 repr(tuple(outputs)) + (" jacobian" if jacobian else "")
                 + (" linearize" if linearize else ""),
                 formulation, __version__, str(ABI_VERSION), templates_digest()):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


#: The routines on the integration path (compiled as MG_PART 2, see model.c.j2).
INTEGRATION_PATH = ("prepare", "rhs", "outputs", "jacobian_terms", "linearize_terms",
                    "inverse_dynamics")

def part_statements(statements: dict) -> dict:
    """Routine name -> statements, to part -> its largest routine's statements (what
    :func:`modelgen.codegen.build.build_module` chooses optimisation levels by)."""
    return {part: max((count for name, count in statements.items()
                       if (name in INTEGRATION_PATH) == (part == 2)), default=0)
            for part in (1, 2)}


#: How a model is built and loaded (part of the cache key): a plain shared library
#: called through the runtime module's trampolines.
LIBRARY_FORMAT = "shared-library+runtime-trampolines"


def runtime() -> tuple:
    """(module name, path) of the compiled runtime module, built on first use."""
    return runtime_module(integrator_sources(), runtime_sources())


def build_hash(spec: ModelSpec, outputs=(), jacobian: bool = False,
               formulation: str = "crba", linearize: bool = False) -> str:
    """Cache key of the compiled module: the model hash, the compiler and its flags,
    and the integrators it links (so a changed mg_integrate rebuilds every module)."""
    return _build_key(model_hash(spec, outputs, jacobian, formulation, linearize))


def _build_key(model: str) -> str:
    """:func:`build_hash` of the model whose :func:`model_hash` is ``model``."""
    h = hashlib.sha256()
    for part in (LIBRARY_FORMAT, model,
                 " ".join(compiler()), " ".join(host_flags()),
                 os.environ.get("MODELGEN_CFLAGS", ""), integrator_hash(integrator_sources())):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def choose_formulation(spec: ModelSpec, formulation: str = "auto"):
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
    if formulation == "crba":
        return "crba", None
    if formulation == "aba":
        return "aba", extract_joint_tree(spec)
    if spec.n < ABA_CROSSOVER:
        return "crba", None
    try:
        return "aba", extract_joint_tree(spec)
    except ModelError:
        return "crba", None


def routines_for(eqs: Equations, output_exprs=(), jacobian=None,
                 forward: ForwardDynamics | None = None, linearization=None, inverse=None):
    """The C routines of a model: (name, inputs, outputs) for make_routines.

    With ``forward`` (the ABA program) the ``rhs`` routine writes q_ddot and
    the articulated inertias D (in the order of ``forward.inward``), and
    ``jacobian_terms`` is d(q_ddot)/dx.  With ``linearization``
    (:class:`~modelgen.derive.linearize.LinearizationTerms`) ``linearize_terms``
    writes its R and Y (derivatives with respect to [x, u]).  ``inverse``:
    ``(qdd symbols, Q)`` of ``inverse_dynamics``, Q = A qdd + h - tau.
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
        rhs = ("rhs", t + (x, u, p), (("A", A_flat), ("b", b)) + qdot)
        jac_inputs = t + (x, u, p, ("a", jacobian.a)) if jacobian else ()
    lin = []
    if linearization is not None:
        lin_inputs = t + (x, u, p) + ((("a", linearization.a),) if linearization.a else ())
        lin = [("linearize_terms", lin_inputs,
                (("R", tuple(e for row in linearization.R for e in row)),)
                + ((("Y", tuple(e for row in linearization.Y for e in row)),)
                   if linearization.Y else ()))]
    return [
        ("mass_matrix", (q, p), (("A", A_flat),)),
        ("velocity_terms", (q, qd, p), (("h", eqs.h),)),
        ("generalized_forces", t + (q, qd, u, p), (("tau", eqs.tau),)),
        rhs,
        ("energy", (q, qd, p), (("out", (eqs.kinetic, eqs.potential)),)),
        ("body_poses", (q, p), (("T", tuple(e for pose in eqs.poses for e in pose)),)),
    ] + ([("inverse_dynamics", t + (x, ("qdd", inverse[0]), u, p), (("Q", inverse[1]),))]
         if inverse else []) \
      + ([("outputs", t + (x, u, p), (("y", tuple(output_exprs)),))] if output_exprs else []) \
      + ([("jacobian_terms", jac_inputs,
           (("D", tuple(e for row in jacobian.D for e in row)),)
           + ((("K", tuple(e for row in jacobian.K for e in row)),) if jacobian.K else ()))]
         if jacobian else []) \
      + lin


def _hoisted(routines) -> tuple:
    """``routines`` with ``rhs`` split into ``prepare`` (its parameter-only
    statements, written into ``pd``) and the ``rhs`` that reads ``pd``
    (:func:`modelgen.codegen.cse.hoist_parameters`)."""
    out = []
    for r in routines:
        out.extend(hoist_parameters(r) if r.name == "rhs" else (r,))
    return tuple(out)


def _time_free(tree: JointTree) -> bool:
    """True if no joint of ``tree`` moves with time t by itself (then h has no t)."""
    for joint in tree.joints:
        exprs = (joint.angle,) + tuple(joint.offset) + tuple(joint.fixed[1]) + \
            tuple(x for row in joint.fixed[0] for x in row)
        if any(TIME in getattr(e, "free_symbols", ()) for e in exprs):
            return False
    return True


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


#: the stages of a build, in order (the keys of ``Generated.seconds``)
STAGES = ("derive", "cse", "emit", "compile")


def generate(spec: ModelSpec, out_dir=None, *, force: bool = False, outputs=(),
             jacobian: bool = False, formulation: str = "auto", progress=None,
             linearize: bool = False) -> Generated:
    """Generate, compile and cache the model; reuse an unchanged build.

    ``out_dir`` defaults to :func:`default_output` (the per-user cache).  ``outputs`` (a tuple of
    :class:`~modelgen.model.spec.OutputSpec`, from a scene) adds a
    ``<name>_outputs`` routine computing exactly those quantities.
    ``jacobian=True`` adds ``<name>_jacobian``, the symbolic d(xdot)/dx.
    ``formulation`` (one of :data:`FORMULATIONS`) chooses how ``<name>_rhs``
    computes q_ddot; the Jacobian is derived from the same program.
    ``progress`` is None or a callable ``progress(stage)`` called as each of
    :data:`STAGES` starts (not at all when the build is reused).
    ``linearize=True`` adds ``<name>_linearize`` (A, B and, for the scene's
    outputs, C and D, symbolic; see :mod:`modelgen.derive.linearize`) and
    implies ``jacobian``.

    >>> g = generate(load_model("models/double_pendulum.yaml"))   # doctest: +SKIP
    >>> g.manifest["n"]                                             # doctest: +SKIP
    2
    """
    _check_generable(spec)
    if linearize and spec.joints:
        raise ModelError("linearization of a model with ball or free joints is not supported: "
                         "its state holds unit quaternions, whose four components cannot "
                         "move independently", file=spec.source, key="linearize",
                         fix="linearize a model whose rotations are simple ones (angles)")
    formulation, tree = choose_formulation(spec, formulation)
    jacobian = bool(jacobian or linearize)
    directory = Path(out_dir) if out_dir is not None else default_output(spec.name)
    # computed once: the emit stage prints it into the preamble (repr of the
    # spec and a read of the templates, about 5 ms on the 6-link chain)
    model_key = model_hash(spec, outputs, jacobian, formulation, linearize)
    key = _build_key(model_key)
    damage = ""
    if not force:
        hit, damage = cache_lookup(directory, key)
        if hit is not None:
            return Generated(hit, hit.manifest)

    def stage(name):
        if progress is not None:
            progress(name)
    seconds = {}
    stage("derive")
    t0 = time.perf_counter()
    kin = derive_kinematics(spec)
    eqs = derive_equations(kin)
    columns = derive_outputs(kin, eqs, outputs) if outputs else None
    graph = columns.graph if columns else eqs.graph
    forward = derive_aba(eqs, tree, spec, graph) if tree is not None else None
    graph = forward.graph if forward else graph
    if tree is not None and _time_free(tree):
        # h by RNEA in link frames (O(n), sharing ABA's outward pass); after the
        # ABA, whose program keeps the order it was written in (each joint's
        # velocity next to its forces)
        builder = GraphBuilder(graph)
        eqs = replace(eqs, h=derive_velocity_terms(builder, tree, eqs.qd))
        # inverse dynamics A qdd + h - tau, A qdd + h by RNEA too, sharing the velocities
        qdd = accelerations(len(eqs.qd))
        inverse = (qdd, tuple(e - tau for e, tau in
                              zip(derive_inverse_dynamics(builder, tree, eqs.qd, qdd), eqs.tau)))
        graph = builder.freeze()
        forward = replace(forward, graph=graph)
    else:       # minus the residual tau - h - A qdd of the composite-body equations
        qdd, r = residual(eqs)
        inverse = (qdd, tuple(-e for e in r))
    linearization = None
    if linearize:       # one pass for A, B, C, D; the Jacobian is its state columns
        linearization = derive_linearization_terms(
            eqs, graph, columns.exprs if columns else (), forward.qdd if forward else None)
        terms = linearization.jacobian_terms()
    elif jacobian:
        terms = (derive_aba_jacobian(forward, eqs) if forward else
                 derive_jacobian_terms(eqs, graph))
    else:
        terms = None
    graph = terms.graph if terms else graph
    t1 = time.perf_counter()
    seconds["derive"] = t1 - t0
    stage("cse")
    # the rhs (what an integration runs) is eliminated on its own
    routines = make_routines(graph, routines_for(eqs, columns.exprs if columns else (), terms,
                                                 forward, linearization, inverse),
                             alone=("rhs", "inverse_dynamics"))
    routines = _hoisted(routines)
    t2 = time.perf_counter()
    seconds["cse"] = t2 - t1
    stage("emit")
    outputs_c = {"A": "A", "h": "h", "tau": "tau", "b": "b", "out": "out", "T": "T", "y": "y",
                 "D": "D", "qdd": "qdd", "R": "R", "Y": "Y", "qdot": "qdot", "K": "K",
                 "pd": "pd", "Q": "Q"}
    functions = {r.name: print_routine(r, outputs_c) for r in routines}
    context = template_context(
        name=spec.name, description=spec.description,
        model_hash=model_key[:16],
        n=spec.n, nq=spec.nq,
        coordinates=spec.coordinates, speeds=spec.speeds,
        quaternions=[[spec.coordinates.index(c) for c in j.quaternion] for j in spec.joints], parameters=spec.parameters, inputs=spec.inputs,
        bodies=eqs.bodies, functions=functions,
        output_columns=[c for cols in columns.columns for c in cols] if columns else (),
        has_jacobian=bool(jacobian), has_linearize=bool(linearize),
        npd=next(len(r.outputs[0][1]) for r in routines if r.name == "prepare"),
        # the crba rhs's solve skips the entries of A that are structurally zero
        mass_pattern=None if forward else [[e != 0 for e in row] for row in eqs.A])
    sources = emit_sources(dict(context, formulation=formulation,
                                aba_inward=list(forward.inward) if forward else []))
    t3 = time.perf_counter()
    seconds["emit"] = t3 - t2
    stage("compile")
    statements = part_statements({f.name: f.statements for f in functions.values()})
    manifest = {
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
        "quaternions": [[spec.coordinates.index(c) for c in j.quaternion]
                        for j in spec.joints],
        "parameters": [[name, float(value)] for name, value in spec.parameters],
        "inputs": list(spec.inputs),
        "jacobian": bool(jacobian),
        "linearize": bool(linearize),
        "formulation": formulation,
        "bodies": list(eqs.bodies),
        "outputs": [{"name": name, "columns": list(cols)}
                    for name, cols in zip(columns.names, columns.columns)] if columns else [],
        "sources_sha256": {fname: hashlib.sha256(text.encode()).hexdigest()
                           for fname, text in sources.items()},
        "functions": {f["name"]: signature_of(f["ret"], f["params"]).name
                      for f in context["api"]},
        "ops": {f.name: {"before_cse": f.ops_before, "after_cse": f.ops_after,
                         "statements": f.statements} for f in functions.values()},
    }
    build = build_module(directory, spec.name, sources, dict(manifest, seconds=seconds),
                         statements, integrator_sources())
    seconds["compile"] = build.seconds
    build = replace(build, rebuilt_because=damage)
    manifest = dict(build.manifest, seconds=seconds)
    return Generated(build, manifest)
