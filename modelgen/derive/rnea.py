"""The velocity-product term h and inverse dynamics in O(n): recursive Newton-Euler.

Featherstone, *Rigid Body Dynamics Algorithms* (2008), §5.3, Table 5.1, in
each link's own frame (:mod:`modelgen.derive.joint_tree` gives the links),
without gravity and external forces:

1. outwards: ``v_i = X_i v_p + S_i qd_i``, ``c_i = v_i x S_i qd_i``,
   ``a_i = X_i a_p + c_i`` (``a`` of the ground is 0),
   ``f_i = I_i a_i + v_i x* I_i v_i``;
2. inwards: ``h_i = S_i^T f_i``, ``f_p += X_i^T f_i``.

This is ``h`` of ``A q_ddot + h = tau`` (:mod:`modelgen.derive.dynamics`):
the generalized inertia forces at zero acceleration.  Pass 1 is
:func:`modelgen.derive.recursion.outward_pass`, which the ABA program uses too
(its ``f`` is the ABA's bias force), so over it RNEA costs only step 2:
about 20 operations per revolute joint, against the O(n^2) projections of
the composite-body sums.

With accelerations (:func:`derive_inverse_dynamics`), pass 1 carries
``a_i = X_i a_p + c_i + S_i qdd_i`` instead and the result is ``A qdd + h``,
the generalized inertia forces, in O(n) (Pinocchio's ``rnea`` without
gravity, MuJoCo's ``mj_inverse`` without the passive forces: those are in
``tau``).  A dof's armature (reflected rotor inertia) adds ``armature_k qdd_k``
to its own generalized force, as in MuJoCo's ``mj_rne`` plus ``dof_armature``.
"""
from __future__ import annotations

from modelgen.derive.recursion import (joint_motion, joint_velocity, link_force,
                                       link_velocities, outward_pass, to_parent_force)
from modelgen.derive.graph import GraphBuilder
from modelgen.derive.spatial import ZERO, add, dot
from modelgen.derive.joint_tree import JointTree


def derive_velocity_terms(builder: GraphBuilder, tree: JointTree, qd) -> tuple:
    """h (in coordinate order) by RNEA with q_ddot = 0, built in ``builder``.

    >>> from modelgen.model.chains import spatial_chain
    >>> from modelgen.derive.joint_tree import extract_joint_tree
    >>> from modelgen.model.spec import symbol
    >>> spec = spatial_chain(2).spec()
    >>> h = derive_velocity_terms(GraphBuilder(), extract_joint_tree(spec),
    ...                           [symbol(c + "_dot") for c in spec.coordinates])
    >>> len(h)
    2
    """
    return _inward(builder, tree, outward_pass(builder, tree, qd).f, len(qd))


def derive_inverse_dynamics(builder: GraphBuilder, tree: JointTree, qd, qdd) -> tuple:
    """``A qdd + h`` (in coordinate order) by RNEA, built in ``builder``: the generalized
    forces that give the accelerations ``qdd``, less those of gravity and the
    effects (``tau``), which the caller subtracts.

    >>> from modelgen.model.chains import spatial_chain
    >>> from modelgen.derive.joint_tree import extract_joint_tree
    >>> from modelgen.model.spec import symbol
    >>> spec = spatial_chain(2).spec()
    >>> qdd = derive_inverse_dynamics(GraphBuilder(), extract_joint_tree(spec),
    ...                               [symbol(c + "_dot") for c in spec.coordinates],
    ...                               [symbol(c + "_acc") for c in spec.coordinates])
    >>> len(qdd)
    2
    """
    v, c = link_velocities(builder, tree, qd)
    a, force = [None] * len(tree.joints), []
    for i, joint in enumerate(tree.joints):
        aJ = joint_velocity(builder, joint, qdd)          # S_i qdd_i
        a[i] = builder.vec(add(add(joint_motion(builder, joint, a[joint.parent]), c[i]), aJ)
                           if joint.parent >= 0 else add(c[i], aJ))
        force.append(link_force(builder, tree.inertias[i], v[i], a[i]))
    out = _inward(builder, tree, force, len(qd))
    # a rotor's reflected inertia acts on its own dof only: armature_k qdd_k
    return tuple(builder.name(f + armature * qdd[k]) if armature != 0 else f
                 for k, (f, armature) in enumerate(zip(out, tree.armature or (0,) * len(out),
                                                       strict=True)))


def _inward(builder: GraphBuilder, tree: JointTree, force, n: int) -> tuple:
    """RNEA's pass 2: each joint's generalized force ``S_i^T f_i``, with the link
    forces summed into the parents, leaves first."""
    force = list(force)
    out = [ZERO] * n
    for i in reversed(range(len(tree.joints))):
        joint = tree.joints[i]
        for k, S in joint.dofs:
            out[k] = builder.name(dot(S, force[i]))
        if joint.parent >= 0:
            p = joint.parent
            force[p] = builder.vec(add(force[p], to_parent_force(builder, joint, force[i])))
    return tuple(out)


__all__ = ["derive_velocity_terms", "derive_inverse_dynamics"]
