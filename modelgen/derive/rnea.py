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
``tau``).  The model's inverse dynamics folds gravity into the ground's
acceleration and the actions into the link forces, as the ABA does, which
leaves far fewer operations than subtracting their generalized forces
(``tau``, in E) afterwards.  A dof's armature (reflected rotor inertia) adds ``armature_k qdd_k``
to its own generalized force, as in MuJoCo's ``mj_rne`` plus ``dof_armature``.
"""
from __future__ import annotations

from modelgen.derive.recursion import (joint_motion, joint_velocity, link_force, link_loads,
                                       link_velocities, outward_pass, to_parent_force)
from modelgen.derive.graph import GraphBuilder
from modelgen.derive.spatial import ZERO, add, dot, sub
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


def derive_inverse_dynamics(builder: GraphBuilder, tree: JointTree, qd, qdd, a0=None,
                            external=None) -> tuple:
    """``A qdd + h`` (in coordinate order) by RNEA, built in ``builder``: the generalized
    forces that give the accelerations ``qdd``, less those of gravity and the
    effects (``tau``), which the caller subtracts.  With the ground's
    acceleration ``a0`` (gravity as Featherstone's fictitious ``-g``) and
    ``external`` (joint index -> spatial force on its link, in link components:
    :func:`~modelgen.derive.recursion.link_loads`), the result is already less
    those forces, Pinocchio's ``rnea`` with its ``fext``, and the caller
    subtracts only the other effects'.

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
        parent = a[joint.parent] if joint.parent >= 0 else a0
        a[i] = builder.vec(add(add(joint_motion(builder, joint, parent), c[i]), aJ)
                           if parent is not None else add(c[i], aJ))
        f = link_force(builder, tree.inertias[i], v[i], a[i])
        if external and i in external:
            f = builder.vec(sub(f, external[i]))
        force.append(f)
    out = _inward(builder, tree, force, len(qd))
    # a rotor's reflected inertia acts on its own dof only: armature_k qdd_k
    return tuple(builder.name(f + armature * qdd[k]) if armature != 0 else f
                 for k, (f, armature) in enumerate(zip(out, tree.armature or (0,) * len(out),
                                                       strict=True)))


def derive_model_inverse_dynamics(builder: GraphBuilder, eqs, tree: JointTree, spec,
                                  qdd) -> tuple:
    """The model's inverse dynamics ``Q = A qdd + h - tau`` of ``eqs`` (its
    :class:`~modelgen.derive.dynamics.Equations`), built in ``builder``: RNEA with
    gravity and the actions as :func:`~modelgen.derive.recursion.link_loads`, less
    the generalized forces of the other effects."""
    a0, tau, external = link_loads(builder, eqs, tree, spec)
    inverse = derive_inverse_dynamics(builder, tree, eqs.qd, qdd, a0, external)
    return tuple(e - t for e, t in zip(inverse, tau, strict=True))


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


__all__ = ["derive_velocity_terms", "derive_inverse_dynamics",
           "derive_model_inverse_dynamics"]
