"""Derivatives of inverse dynamics: dQ/dq, dQ/dv, dQ/du and M = dQ/da, unrolled.

Carpentier and Mansard, "Analytical derivatives of rigid body dynamics
algorithms" (RSS 2018): the derivatives of forward dynamics follow from
those of inverse dynamics, ``dqdd/dq = -M^-1 dID/dq`` and
``dqdd/dv = -M^-1 dID/dv`` evaluated at ``a = qdd``, and the derivatives of
RNEA carry, per link, the derivatives of its velocity, acceleration and
force with respect to the coordinates and speeds of the joints they depend
on: entry ``(i, j)`` is non-zero only when joints i and j are on one branch.

Here the RNEA of a joint tree (Featherstone §5.3, in link frames, over
:mod:`modelgen.derive.recursion`'s passes) with gravity as the ground's
acceleration ``-g`` and the actions as link forces is built as a
straight-line program, and that program is differentiated in forward mode
(:func:`modelgen.derive.jacobian.differentiate`) along each ``q_j``, ``v_j``,
``u_j`` and ``a_j``: every intermediate carries derivatives only for the
variables it depends on, which is the tree's structure (a link's velocity
and acceleration depend on its ancestors', its force on those and on its
descendants'), with the constant zeros of the link-frame transforms folded
as the expressions are formed.  The effects that are neither gravity in E
nor actions (springs, dampers, friction, drag...) enter as their
generalized forces (``Equations.tau_parts``) and are differentiated along
with the rest.

``Q(q, v, a, u) = ID(q, v, a) - tau_effects(q, v, u)`` is the function of
``<name>_inverse_dynamics``.  The generated C uses this forward mode for
models that are not joint trees; a joint tree's derivatives come from
:mod:`modelgen.derive.rnea_partials` (the recursive method, fewer operations
per entry and O(n) statements).  Ball and free joints are differentiated in the
tangent space, Pinocchio's convention: ``dQ/dq`` column j is the derivative
along ``q (+) delta e_j`` (``quat * exp(delta w / 2)``, ``r + R delta v``),
which to first order is ``dQ/dq_full N(q)`` with ``N = d(dq/dt)/dv``.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.calculus import diff
from modelgen.derive.dynamics import Equations
from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.jacobian import accelerations, differentiate
from modelgen.derive.joint_tree import JointTree
from modelgen.derive.recursion import (
    joint_motion,
    joint_velocity,
    link_force,
    link_loads,
    link_velocities,
    to_parent_force,
)
from modelgen.derive.spatial import (
    ZERO,
    ZERO3,
    add,
    dot,
    is_zero_vec,
    name_vec,
    named,
    sub,
)
from modelgen.model.spec import ModelSpec


@dataclass(frozen=True)
class InverseDynamicsDerivatives:
    """Output of :func:`derive_inverse_dynamics_derivatives`, over ``graph``.

    ``a`` the acceleration symbols, ``Q`` the inverse dynamics (n), and n-row
    matrices (tuples of rows): ``dq`` (n x n, tangent space), ``dv``
    (n x n), ``du`` (n x nu), ``M`` (n x n, the mass matrix dQ/da).
    """
    graph: Graph
    a: tuple
    Q: tuple
    dq: tuple
    dv: tuple
    du: tuple
    M: tuple

    def operations(self) -> int:
        """Operations of the derivatives and of what they need (before CSE)."""
        flat = [e for rows in (self.dq, self.dv, self.du, self.M) for row in rows for e in row]
        return self.graph.operations(flat)


def rnea_with_loads(builder: GraphBuilder, eqs: Equations, tree: JointTree, spec: ModelSpec,
                    qdd) -> tuple:
    """``Q = ID(q, v, qdd) - tau_effects`` (coordinate order) by RNEA with gravity
    as the ground's acceleration and the actions as link forces; the other
    effects' generalized forces are subtracted."""
    n = len(eqs.qd)
    a0, tau, external = link_loads(builder, eqs, tree, spec)
    v, c = link_velocities(builder, tree, eqs.qd)
    count = len(tree.joints)
    acc, force = [None] * count, [None] * count
    for i, joint in enumerate(tree.joints):
        aJ = joint_velocity(builder, joint, qdd)          # S_i qdd_i
        parent = acc[joint.parent] if joint.parent >= 0 else a0
        moved = ZERO3 * 2 if is_zero_vec(parent) else joint_motion(builder, joint, parent)
        acc[i] = name_vec(builder, add(add(moved, c[i]), aJ))
        f = link_force(builder, tree.inertias[i], v[i], acc[i])
        force[i] = name_vec(builder, sub(f, external[i])) if i in external else f
    out = [ZERO] * n
    for i in reversed(range(count)):
        joint = tree.joints[i]
        for k, S in joint.dofs:
            out[k] = builder.name(dot(S, force[i]))
        if joint.parent >= 0:
            p = joint.parent
            force[p] = name_vec(builder, add(force[p], to_parent_force(builder, joint, force[i])))
    # a rotor's reflected inertia acts on its own dof only: armature_k qdd_k
    armature = tree.armature or (0,) * n
    return tuple(named(builder, out[k] + armature[k] * qdd[k] - tau[k]) for k in range(n))


def derive_inverse_dynamics_derivatives(eqs: Equations, tree: JointTree, spec: ModelSpec,
                                        graph: Graph | None = None) -> InverseDynamicsDerivatives:
    """dQ/dq (tangent space), dQ/dv, dQ/du and M = dQ/da of the inverse dynamics of
    a joint tree, built over ``graph`` (default ``eqs.graph``).

    >>> from modelgen.model.chains import spatial_chain
    >>> from modelgen.derive.kinematics import derive_kinematics
    >>> from modelgen.derive.dynamics import derive_equations
    >>> from modelgen.derive.joint_tree import extract_joint_tree
    >>> spec = spatial_chain(3).spec()
    >>> d = derive_inverse_dynamics_derivatives(derive_equations(derive_kinematics(spec)),
    ...                                         extract_joint_tree(spec), spec)
    >>> len(d.dq), len(d.dq[0]), d.dq[2][0]    # the first joint turns about gravity's axis
    (3, 3, 0)
    """
    builder = GraphBuilder(graph or eqs.graph)
    a = accelerations(len(eqs.qd))
    Q = rnea_with_loads(builder, eqs, tree, spec, a)
    return differentiate_inverse_dynamics(builder.freeze(), eqs, a, Q)


def differentiate_inverse_dynamics(graph: Graph, eqs: Equations, a, Q) -> InverseDynamicsDerivatives:
    """The derivatives of any inverse-dynamics program ``Q(q, v, a, u)`` over
    ``graph`` (the accelerations ``a`` are symbols of it), by forward mode along
    q, v, u and a: RNEA's (:func:`rnea_with_loads`) for a joint tree, or the
    composite-body ``A a + h - tau`` of any other model."""
    n, nq, nu = len(eqs.qd), len(eqs.q), len(eqs.u)
    wrt = tuple(eqs.q) + tuple(eqs.qd) + tuple(eqs.u) + tuple(a)
    graph, rows = differentiate(graph, Q, wrt)
    dv = tuple(tuple(row[nq:nq + n]) for row in rows)
    du = tuple(tuple(row[nq + n:nq + n + nu]) for row in rows)
    M = tuple(tuple(row[nq + n + nu:]) for row in rows)
    dq_full = [row[:nq] for row in rows]
    if nq == n:
        dq = tuple(tuple(row) for row in dq_full)
    else:
        graph, dq = tangent_rows(graph, eqs, dq_full)
    return InverseDynamicsDerivatives(graph, tuple(a), tuple(Q), dq, dv, du, M)


def tangent_rows(graph: Graph, eqs: Equations, dq_full) -> tuple:
    """``dQ/dq_full N`` with ``N = d(dq/dt)/dv`` (nq x n, sparse): the derivatives
    along the joints' tangent directions."""
    builder = GraphBuilder(graph)
    # dq/dt is named in the graph (quat * (0, w) / 2, R v): its few statements
    # expanded, it is linear in the speeds
    qdot = [graph.expand(e) for e in eqs.qdot]
    N = [{j: d for j, s in enumerate(eqs.qd) if (d := diff(e, s)) != 0} for e in qdot]
    rows = []
    for row in dq_full:
        out = [sympy.S.Zero] * len(eqs.qd)
        for i, d in enumerate(row):
            if d == 0:
                continue
            for j, nij in N[i].items():
                out[j] += d * nij
        rows.append(tuple(named(builder, e) for e in out))
    return builder.freeze(), tuple(rows)


__all__ = ["InverseDynamicsDerivatives", "derive_inverse_dynamics_derivatives",
           "differentiate_inverse_dynamics", "tangent_rows", "rnea_with_loads"]
