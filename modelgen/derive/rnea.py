"""The velocity-product term h in O(n): recursive Newton-Euler with q_ddot = 0.

Featherstone, *Rigid Body Dynamics Algorithms* (2008), §5.3, Table 5.1, in
each link's own frame (:mod:`modelgen.derive.joint_tree` gives the links),
without gravity and external forces:

1. outwards: ``v_i = X_i v_p + S_i qd_i``, ``c_i = v_i x S_i qd_i``,
   ``a_i = X_i a_p + c_i`` (``a`` of the ground is 0),
   ``f_i = I_i a_i + v_i x* I_i v_i``;
2. inwards: ``h_i = S_i^T f_i``, ``f_p += X_i^T f_i``.

This is ``h`` of ``A q_ddot + h = tau`` (:mod:`modelgen.derive.dynamics`):
the generalized inertia forces at zero acceleration.  Pass 1 is
:func:`modelgen.derive.aba.outward_pass`, which the ABA program uses too
(its ``f`` is the ABA's bias force), so over it RNEA costs only step 2:
about 20 operations per revolute joint, against the O(n^2) projections of
the composite-body sums.
"""
from __future__ import annotations

from modelgen.derive.aba import add, dot, outward_pass, to_parent_force
from modelgen.derive.graph import ZERO, GraphBuilder
from modelgen.derive.joint_tree import JointTree


def derive_velocity_terms(g: GraphBuilder, tree: JointTree, qd) -> tuple:
    """h (in coordinate order) by RNEA with q_ddot = 0, built in ``g``.

    >>> from modelgen.model.chains import spatial_chain
    >>> from modelgen.derive.joint_tree import extract_joint_tree
    >>> from modelgen.model.spec import symbol
    >>> spec = spatial_chain(2).spec()
    >>> h = derive_velocity_terms(GraphBuilder(), extract_joint_tree(spec),
    ...                           [symbol(c + "_dot") for c in spec.coordinates])
    >>> len(h)
    2
    """
    joints = tree.joints
    force = list(outward_pass(g, tree, qd).f)
    h = [ZERO] * len(qd)
    for i in reversed(range(len(joints))):
        joint = joints[i]
        for k, S in joint.dofs:
            h[k] = g.name(dot(S, force[i]))
        if joint.parent >= 0:
            p = joint.parent
            force[p] = g.vec(add(force[p], to_parent_force(g, joint, force[i])))
    return tuple(h)


__all__ = ["derive_velocity_terms"]
