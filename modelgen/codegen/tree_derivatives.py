"""Which derivatives of inverse dynamics a model gets, and what their C reads.

:func:`tree_derivatives` chooses, for a joint tree, between the recursive method
(:mod:`modelgen.derive.rnea_partials`, with its dot products in a C loop or, for
a few speeds, written out: :class:`UnrolledPartials`) and forward mode over RNEA
(:mod:`modelgen.derive.rnea_derivatives`), by their operation counts;
:func:`jacobian_operations` and :func:`derivatives_operations` are the estimates
by which ``<name>_jacobian`` is built on ``<name>_derivatives`` or by forward
mode over the rhs (:func:`modelgen.codegen.pipeline.generate` decides);
:func:`derivative_routine` and :func:`derivative_loop` are what the routine
computes and the tables of the template's loops.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.dynamics import Equations
from modelgen.codegen.kernels import kernel_context
from modelgen.derive.graph import Graph
from modelgen.derive.joint_tree import JointTree
from modelgen.derive.link_kernels import BACKWARD_VECTORS, FACTOR_VECTORS, FORWARD_VECTORS
from modelgen.derive.rnea_derivatives import (InverseDynamicsDerivatives,
                                              derive_inverse_dynamics_derivatives)
from modelgen.derive.rnea_partials import VECTORS, RneaPartials, derive_rnea_partials
from modelgen.model.spec import TIME, ModelSpec


def derivative_routine(inputs, d) -> tuple:
    """The ``derivative_terms`` routine: ``(name, inputs, outputs)`` of dQ/dq, dQ/dv,
    dQ/du (when there are inputs) and M, row-major, at the accelerations ``a``; for
    the recursive derivatives (:class:`RneaPartials`) the per-dof vectors ``W`` and
    the effects' non-zero entries ``E``, which the C's loop over the pairs of
    dofs turns into those matrices."""
    def flat(rows):
        return tuple(e for row in rows for e in row)
    if isinstance(d, RneaPartials):
        effects = tuple(e for _, _, e in d.effect_entries())
        if d.kernels is not None:
            # the vectors come from the kernels' loops (derivative_loop); the
            # routine computes their table of constants and the effects
            first = ("C", d.kernels.table)
        else:
            # component-major, W[c * n + k]: a component of every dof is one row,
            # which the C's loops over consecutive dofs read as a vector
            rows = [v + f for v, f in zip(d.vectors, d.factor or ((),) * len(d.vectors),
                                          strict=True)]
            first = ("W", tuple(v[c] for c in range(len(rows[0])) for v in rows))
        return ("derivative_terms", inputs + (("a", d.a),),
                (first,) + ((("E", effects),) if effects else ()))
    du = (("dQ_du", flat(d.du)),) if d.du and d.du[0] else ()
    return ("derivative_terms", inputs + (("a", d.a),),
            (("dQ_dq", flat(d.dq)), ("dQ_dv", flat(d.dv))) + du + (("M", flat(d.M)),))


def time_free(tree: JointTree) -> bool:
    """True if no joint of ``tree`` moves with time t by itself (then h has no t)."""
    for joint in tree.joints:
        exprs = (joint.angle,) + tuple(joint.offset) + tuple(joint.fixed[1]) + \
            tuple(x for row in joint.fixed[0] for x in row)
        if any(TIME in getattr(e, "free_symbols", ()) for e in exprs):
            return False
    return True


#: Up to this many speeds a joint tree's derivatives are derived both ways, and
#: forward mode over RNEA (derive/rnea_derivatives.py) is kept when it has fewer
#: operations than the recursive method with its loop: on the 7-link chain it
#: does, on the 7-joint arm it does not; else the recursive method's dot
#: products are written into the program (:class:`UnrolledPartials`).  Above,
#: forward mode costs more per entry and its derivation grows with n^2, and the
#: dot products are a vectorized C loop.
FORWARD_DERIVATIVES_MAX = 10
#: Above :data:`FORWARD_DERIVATIVES_MAX` speeds, a tree the kernels take has its
#: per-dof vectors computed by loops over the joints calling one kernel per joint
#: signature (:mod:`modelgen.derive.link_kernels`) instead of a straight line:
#: about as many instructions, a fraction of the code and of its compile time
#: (``bench/looped_derivatives.py``).
LOOPED = True


@dataclass(frozen=True)
class UnrolledPartials(InverseDynamicsDerivatives):
    """The recursive derivatives (:class:`RneaPartials`) with the dot products of
    every pair of dofs written out as the entries of dQ/dq, dQ/dv, dQ/du and M:
    for a few dofs straight-line code runs fewer instructions than the loop
    over the pairs (its set-up, short runs, the transposed copies)."""


def unrolled_partials(d: RneaPartials) -> UnrolledPartials:
    """``d``'s matrices as expressions (the dot products of the C loop of
    ``derivative_terms``, :data:`~modelgen.derive.rnea_partials.VECTORS`), the
    effects' entries added."""
    n = len(d.vectors)
    start, at = {}, 0
    for name in VECTORS:
        start[name] = at
        at += 3 if name == "dYtJ" else 6

    def vec(k, name, size=6):
        return d.vectors[k][start[name]:start[name] + size]

    def dot(x, y):
        return sympy.Add(*[a * b for a, b in zip(x, y, strict=True)])
    dq, dv, M = ([[sympy.S.Zero] * n for _ in range(n)] for _ in range(3))
    for k, l in d.looped_same():
        J = vec(k, "J")
        dq[k][l], dv[k][l], M[k][l] = (dot(J, vec(l, "dFdq0")), dot(J, vec(l, "dFdv")),
                                       dot(J, vec(l, "dFda")))
    for k, l in d.pairs:
        J, Fa = vec(k, "J"), vec(l, "dFda")
        dq[k][l], dv[k][l] = dot(J, vec(l, "dFdq")), dot(J, vec(l, "dFdv"))
        M[k][l] = M[l][k] = dot(J, Fa)
        dq[l][k] = dot(Fa, vec(k, "dAdq")) + dot(vec(l, "dYtJ", 3), vec(k, "dVdq", 3))
        dv[l][k] = dot(Fa, vec(k, "dAdv")) + dot(vec(l, "dYtJ", 3), J[:3])
    edq, edv, edu, eM = d.effects

    def plus(a, b):
        return tuple(tuple(x + y for x, y in zip(ra, rb, strict=True))
                     for ra, rb in zip(a, b, strict=True))
    return UnrolledPartials(d.graph, d.a, (), plus(dq, edq), plus(dv, edv), edu, plus(M, eM))


def tree_derivatives(eqs: Equations, tree: JointTree, spec: ModelSpec, graph):
    """The derivatives of inverse dynamics of a joint tree: the recursive ones
    (:func:`derive_rnea_partials`), for a few speeds with their dot products
    unrolled, or forward mode where that has fewer operations."""
    if spec.n > FORWARD_DERIVATIVES_MAX:
        return derive_rnea_partials(eqs, tree, spec, graph, looped=LOOPED)
    recursive = derive_rnea_partials(eqs, tree, spec, graph)
    forward = derive_inverse_dynamics_derivatives(eqs, tree, spec, graph)
    return forward if forward.operations() < recursive.operations() else \
        unrolled_partials(recursive)


#: Up to this many speeds the Jacobian of a joint tree is derived both ways, and
#: forward mode over the rhs is kept when its estimate (:func:`jacobian_operations`)
#: is lower than that of ``<name>_derivatives`` (:func:`derivatives_operations`);
#: above, forward mode is not even derived: its derivation grows with n^2 and its
#: code per Jacobian entry does not shrink, while the derivatives' does.  The
#: estimates follow callgrind's instructions of ``<name>_jacobian`` both ways
#: (the commit that added this records them): forward mode wins on one- and
#: two-dof models, the derivatives from three dofs on.


FORWARD_JACOBIAN_MAX = 6
#: operations ``<name>_jacobian`` spends calling ``<name>_derivatives`` (their
#: calls and loops), besides copying its 2 n^2 entries into J
DERIVATIVES_CALL = 32


def jacobian_candidate(spec: ModelSpec, tree: JointTree | None) -> bool:
    """Whether ``<name>_jacobian`` can be built on ``<name>_derivatives``: a joint
    tree (RNEA's derivatives) with no ball or free joints (whose derivatives are
    in the tangent space, not in the quaternion's four coordinates)."""
    return tree is not None and spec.nq == spec.n and time_free(tree)


def jacobian_operations(terms) -> int:
    """Estimated operations of ``<name>_jacobian`` by forward mode past its rhs call:
    the derivatives' program, and for crba the solve of its 2n columns."""
    ops = terms.graph.operations([e for row in terms.D for e in row])
    n = len(terms.D)
    return ops + (2 * n * 2 * n * n if terms.a else 0)


def derivatives_operations(d, nu: int) -> int:
    """Estimated operations of ``<name>_derivatives`` past its rhs call: the
    derivatives of inverse dynamics (:meth:`RneaPartials.operations`) and -M^-1
    applied to their 2n + nu columns through the tree's sparse factor."""
    pattern = derivatives_pattern(d)
    n = len(pattern)
    below = (sum(sum(map(bool, row)) for row in pattern) - n) // 2
    return d.operations() + (2 * n + nu) * (4 * below + n)


def derivative_method(d) -> str | None:
    """How the derivatives were derived (the manifest's ``derivative_method``)."""
    if d is None:
        return None
    return "recursive" if isinstance(d, (RneaPartials, UnrolledPartials)) else "forward"


def derivative_manifest(d) -> dict:
    """The manifest's ``derivative_method`` and, when the per-dof vectors are loops
    over the joints, ``derivative_kernels``: the joint signatures, the joints and
    the kernels' operations in one call (before CSE)."""
    out = {"derivative_method": derivative_method(d)}
    if isinstance(d, RneaPartials) and d.kernels is not None:
        k = d.kernels
        out["derivative_kernels"] = {"signatures": len(k.forward), "joints": len(k.signature),
                                     "operations": k.operations(Graph.operations)}
    return out


def derivatives_pattern(d):
    """The structure of the mass matrix of the derivatives (n x n booleans), or None."""
    if d is None:
        return None
    if isinstance(d, RneaPartials):
        return [list(row) for row in d.pattern()]
    return [[e != 0 for e in row] for row in d.M]


def derivative_loop(d: RneaPartials) -> dict:
    """The tables of the C loop over the pairs of dofs (the template's
    ``derivative_loop``): C initialiser lists and their lengths."""
    def c_list(pairs):
        return ", ".join(str(x) for pair in pairs for x in pair) or "0"
    effects = [(array, index) for array, index, _ in d.effect_entries()]
    runs = d.runs()
    same = d.looped_same()
    return {"same": c_list(same), "nsame": len(same), "same_size": max(2 * len(same), 2),
            "runs": c_list(runs), "nruns": len(runs), "runs_size": max(3 * len(runs), 1),
            "npairs": len(d.pairs),
            "effects": c_list(effects), "neffects": len(effects),
            "nw": (len(d.a) * (FORWARD_VECTORS + BACKWARD_VECTORS
                                       + (FACTOR_VECTORS if d.articulated() else 0))
                   if d.kernels else
                   sum(len(v) for v in d.vectors) + sum(len(f) for f in d.factor)),
            "aba": d.articulated(),
            "kernels": kernel_context(d.kernels) if d.kernels else None,
            # every entry written by the loops: no zeros to set first
            "dense": all(all(row) for row in d.pattern()) and not d.programmed,
            "flags": ", ".join(map(str, solve_flags(d.dof_order, d.dof_parent))),
            "order": ", ".join(map(str, d.dof_order)),
            "parent": ", ".join(map(str, d.dof_parent))}


def solve_flags(order, parent) -> list:
    """Per speed, the bits of the template's ``dflags`` for the articulated solve,
    which runs inwards over ``order`` reversed and outwards over ``order``: 1, it
    receives the P carried from the dof processed just before it inwards (its
    child); 2, other children's P in memory; 4, its own P goes to memory (its
    parent is not the next processed), 8, first there; 16, outwards the carried A
    is its parent's; 32, its A is stored for a child not processed just after it.

    >>> solve_flags((0, 1, 2), (-1, 0, 1)), solve_flags((0, 1, 2), (-1, 0, 0))
    ([1, 17, 16], [35, 16, 12])
    """
    flags = [0] * len(order)
    seen = set()
    for i in reversed(range(len(order))):
        k, p = order[i], parent[order[i]]
        if p < 0:
            continue
        if i > 0 and order[i - 1] == p:
            flags[p] |= 1                      # carried inwards to p
            flags[k] |= 16                     # and outwards from p
        else:
            flags[p] |= 2 | 32
            flags[k] |= 4 | (8 if p not in seen else 0)
            seen.add(p)
    return flags


__all__ = ["FORWARD_DERIVATIVES_MAX", "FORWARD_JACOBIAN_MAX", "DERIVATIVES_CALL", "UnrolledPartials", "derivative_loop", "derivative_manifest", "derivative_method", "derivative_routine", "derivatives_operations", "derivatives_pattern", "jacobian_candidate", "jacobian_operations", "solve_flags", "time_free", "tree_derivatives", "unrolled_partials"]
