"""Derivatives of inverse dynamics by the recursive method in the ground frame.

Carpentier and Mansard, "Analytical derivatives of rigid body dynamics
algorithms" (RSS 2018), as Pinocchio's ``computeRNEADerivatives``
(``algorithm/rnea-derivatives.hxx``) computes them: with every quantity in
the ground frame E, a joint's motion moves its whole subtree rigidly along
its column ``J_k`` (the motion subspace in E), so the derivative of any
quantity of a descendant along ``q_k`` is a cross product with ``J_k``, and
every entry of ``dQ/dq``, ``dQ/dv`` and ``M = dQ/da`` is one or two dot
products of 6-vectors that each joint computes once:

* outwards, per joint i with parent p: ``J_k`` (each of its dofs),
  ``ov_i = ov_p + J qd``, ``oa_i = oa_p + J qdd + ov_i x J qd`` (``oa`` of the
  ground is ``-g``), the link's inertia ``oY_i`` and force
  ``of_i = oY_i oa_i + ov_i x* oY_i ov_i`` in E, and per dof
  ``dVdq = ov_p x J``, ``dAdq = oa_p x J + ov_p x dVdq``,
  ``dAdv = ov_i x J + dVdq`` (``2 dVdq`` for a joint of one dof, whose
  ``J qd x J`` is 0; ``ov_i x J qd`` in ``oa_i`` is likewise the sum of the
  ``dVdq qd``), with ``doY_i = ov_i x* oY_i - oY_i ov_i x + (. x* oY_i ov_i)``;
* inwards, with the composite ``oYc_i``, ``doYc_i`` and ``of_i`` of the
  subtree: per dof ``dFda = oYc J``, ``dFdq0 = doYc dVdq + oYc dAdq``,
  ``dFdq = dFdq0 + J x* of``, ``dFdv = doYc J + oYc dAdv``, ``dYtJ = doYc^T J``
  (``doY`` has only two non-zero 3x3 blocks, :func:`variation`, so ``dYtJ``
  has no linear part).

Then for a dof k of a joint and a dof l of a strict descendant
``dQ_k/dq_l = J_k . dFdq_l``, ``dQ_l/dq_k = dFda_l . dAdq_k + dYtJ_l . dVdq_k``,
``dQ_k/dv_l = J_k . dFdv_l``, ``dQ_l/dv_k = dFda_l . dAdv_k + dYtJ_l . J_k``,
``M_kl = M_lk = J_k . dFda_l``, and for two dofs of one joint ``J_k . dFdq0_l``,
``J_k . dFdv_l``, ``J_k . dFda_l``.  Entries of joints on different branches
are zero.

The per-joint part (O(n) statements) is a straight-line program here; the
O(n depth) dot products are left to the generated C as a loop over the
pairs of dofs on one branch (:attr:`RneaPartials.pairs`), so what is derived,
eliminated and compiled grows with n, not n^2.  An action whose spatial force
is constant in its link's frame (a joint's motor and its reaction) is a force
on that link, subtracted from ``of``: its derivatives along q are the
transport ``J_k x* of`` already there.  The other effects that are neither
gravity in E (the ground's acceleration) nor inertial forces (springs,
dampers, friction, drag, other actions...) enter as their generalized forces
(``Equations.tau_parts``), differentiated in forward mode
(:func:`modelgen.derive.jacobian.differentiate`): they are small.  An
armature adds to the diagonal of M.

Ball and free joints are differentiated in the tangent space, Pinocchio's
convention (:mod:`modelgen.derive.rnea_derivatives`): a column ``J_k`` is the
motion of the link along its own constant ``S`` column.  A tree whose one
root joint is a ball or free joint is worked in that root link's frame at
the current configuration instead of E (:func:`floating_root`).
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.dynamics import Equations
from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.jacobian import accelerations, differentiate
from modelgen.derive.joint_tree import JointTree
from modelgen.derive.link_kernels import LinkKernels, derive_link_kernels, loopable
from modelgen.derive.kinematics import quaternion_columns
from modelgen.derive.recursion import action_force, ground_acceleration
from modelgen.derive.rnea_derivatives import tangent_rows
from modelgen.derive.ground_frame import (dof_partials, force_to_ground, link_dynamics,
                                          motion_to_ground, sym6)
from modelgen.derive.spatial import (IDENTITY3, ZERO, ZERO3, add, cross_motion,
                                     dot, is_identity, is_zero, matmul, matvec, name_vec, named,
                                     rotation, times, total, transpose)
from modelgen.model.spec import ModelSpec

#: the per-dof 6-vectors of :attr:`RneaPartials.vectors`, in their order
VECTORS = ("J", "dAdq", "dVdq", "dAdv", "dFda", "dYtJ", "dFdq0", "dFdq", "dFdv")
#: Above this many speeds ``-M^-1`` is applied by the articulated-body factor
#: (:func:`articulated_factor`, O(n) a column), up to it by the sparse LDL^T
#: of M (unrolled, O(n^2) a column for a chain but with no extra factor to
#: derive); at the 20-link chain the LDL^T is the cheaper, at 50 the factor.
ARTICULATED_SOLVE_ABOVE = 30
#: operations of the five entries of one pair of dofs (k, l) in the C loop: three
#: dot products of 6-vectors and two sums of one of 6 and one of 3 terms
PAIR_OPERATIONS = 3 * 11 + 2 * 17


@dataclass(frozen=True)
class RneaPartials:
    """Output of :func:`derive_rnea_partials`, over ``graph``.

    ``vectors[k]``: the vectors of :data:`VECTORS` of speed k (51
    expressions, vector after vector: 6 each but ``dYtJ``, whose linear part is
    0); ``same``: the pairs ``(k, l)`` of dofs
    of one joint (``k == l`` included), ``pairs``: ``(k, l)`` with l a dof of a
    strict descendant of k's joint, both in the order the C loop runs.
    ``factor``, ``dof_order``, ``dof_parent``: see the fields.
    ``effects``: ``(dq, dv, du, M)``, n-row matrices (tuples of rows) of what
    adds to the dot products: the effects' ``-d tau/d q`` (tangent space),
    ``-d tau/d v``, ``-d tau/d u`` and the armature on M's diagonal.
    """
    graph: Graph
    a: tuple
    vectors: tuple
    same: tuple
    pairs: tuple
    effects: tuple
    #: the articulated-body factor of M in E, per speed k: ``U_k`` (6) and
    #: ``1 / D_k`` (7 expressions), for ``-M^-1`` applied column by column
    #: (:func:`articulated_factor`); empty up to :data:`ARTICULATED_SOLVE_ABOVE`
    #: speeds
    factor: tuple = ()
    #: the speeds in the order of the factor's inward pass reversed (a parent's
    #: before its children's, a joint's in its own order), and each one's
    #: predecessor in that chain of dofs (-1: the ground)
    dof_order: tuple = ()
    dof_parent: tuple = ()
    #: the pairs of :attr:`same` whose dot products are in :attr:`effects`, not
    #: in the C loop: a floating root's (:func:`floating_root`), whose ``J_k``
    #: are constant in its frame: each dot product is an entry of the other vector
    programmed: tuple = ()
    #: the vectors (and the factor) as kernels per joint signature
    #: (:class:`~modelgen.derive.link_kernels.LinkKernels`), when derived with
    #: ``looped``: then ``vectors`` and ``factor`` are empty
    kernels: LinkKernels | None = None

    def articulated(self) -> bool:
        """Whether ``-M^-1`` is applied by the articulated-body factor."""
        return bool(self.factor) or (self.kernels is not None
                                     and self.kernels.factor is not None)

    def looped_same(self) -> tuple:
        """The pairs of :attr:`same` the C loop computes."""
        programmed = set(self.programmed)
        return tuple(pair for pair in self.same if pair not in programmed)

    def pattern(self) -> tuple:
        """n x n booleans: the entries of M that can be non-zero (one branch)."""
        n = len(self.a)
        out = [[False] * n for _ in range(n)]
        for k, l in self.same + self.pairs:
            out[k][l] = out[l][k] = True
        return tuple(tuple(row) for row in out)

    def effect_entries(self) -> tuple:
        """``((array, index, expr), ...)``: the non-zero entries of :attr:`effects`,
        ``array`` 0 dq, 1 dv, 2 M, 3 du, ``index`` row-major in it."""
        dq, dv, du, M = self.effects
        out = []
        for array, rows in enumerate((dq, dv, M, du)):
            for r, row in enumerate(rows):
                out.extend((array, r * len(row) + c, e) for c, e in enumerate(row) if e != 0)
        return tuple(out)

    def runs(self) -> tuple:
        """:attr:`pairs` as runs ``(k, first, end)``: the dofs ``first <= l < end``
        (consecutive speeds) of strict descendants of k's joint, one run for each
        k when the speeds are numbered depth first (a chain, most trees)."""
        out = []
        for k, l in self.pairs:
            if out and out[-1][0] == k and out[-1][2] == l:
                out[-1][2] = l + 1
            else:
                out.append([k, l, l + 1])
        return tuple(tuple(r) for r in out)

    def operations(self) -> int:
        """Operations of the per-joint program and the effects (before CSE), and
        of the dot products of the C loop (11 per dot product of two 6-vectors)."""
        flat = [e for v in self.vectors for e in v] + \
            [e for m in self.effects for row in m for e in row]
        kernels = self.kernels.operations(Graph.operations) if self.kernels else 0
        return self.graph.operations(flat) + kernels + 11 * (3 * len(self.looped_same())
                                                             + 8 * len(self.pairs))


def floating_root(tree: JointTree) -> bool:
    """True if the tree has one root joint and it is a ball or free joint: then
    :func:`derive_rnea_partials` works in that root link's frame at the current
    configuration (a fixed frame like E), where the root's columns ``J_k`` are its
    constant ``S`` columns and only gravity depends on the root's rotation."""
    roots = [joint for joint in tree.joints if joint.parent < 0]
    return len(roots) == 1 and roots[0].kind in ("ball", "free")


def _poses(builder, tree: JointTree, root_frame: bool = False) -> tuple:
    """``(poses, R0)``: ``(R, p)`` of every link, its rotation (link -> E components)
    and origin in E, and the root link's rotation R0 when ``root_frame`` (then E is
    the root link's frame: R = I and p = 0 for the root; else R0 is None)."""
    poses, R0 = [], None
    for joint in tree.joints:
        if root_frame and joint.parent < 0:
            R0 = _root_rotation(builder, joint)
            poses.append((IDENTITY3, ZERO3))
            continue
        R, p = poses[joint.parent] if joint.parent >= 0 else (IDENTITY3, ZERO3)
        E, r = joint.fixed
        if any(x != 0 for x in r):
            p = name_vec(builder, add(p, matvec(R, r)))
        if not is_identity(E):
            R = tuple(name_vec(builder, row) for row in matmul(R, transpose(E)))
        if joint.kind in ("ball", "free"):
            if joint.position:
                p = name_vec(builder, add(p, matvec(R, joint.position)))
            # quaternion_columns: the columns of R(quat), rows of E = R(quat)^T
            Rq = transpose(tuple(tuple(builder.name(x) for x in col)
                                 for col in quaternion_columns(joint.quaternion)))
            R = tuple(name_vec(builder, row) for row in matmul(R, Rq))
        elif joint.kind == "revolute":
            c, s = builder.name(sympy.cos(joint.angle)), builder.name(sympy.sin(joint.angle))
            R = tuple(name_vec(builder, row)
                      for row in matmul(R, transpose(rotation(joint.axis, c, s))))
        else:
            p = name_vec(builder, add(p, matvec(R, name_vec(builder, joint.offset))))
        poses.append((R, p))
    return tuple(poses), R0


def _root_rotation(builder, joint) -> tuple:
    """The rows of the rotation (link -> E components) of a ball or free root joint's
    link: ``E^T R(quat)`` for its fixed rotation E (the position does not rotate)."""
    Rq = transpose(tuple(tuple(builder.name(x) for x in col)
                         for col in quaternion_columns(joint.quaternion)))
    E = joint.fixed[0]
    R = Rq if is_identity(E) else matmul(transpose(E), Rq)
    return tuple(name_vec(builder, row) for row in R)


# -- the algorithm ---------------------------------------------------------------------

def derive_rnea_partials(eqs: Equations, tree: JointTree, spec: ModelSpec,
                         graph: Graph | None = None, looped: bool = False) -> RneaPartials:
    """The per-dof vectors of the recursive derivatives of inverse dynamics of a
    joint tree, and the effects' derivatives, built over ``graph`` (default
    ``eqs.graph``).  With ``looped``, a tree the kernels take
    (:func:`~modelgen.derive.link_kernels.loopable`) gets its vectors as
    kernels per joint signature instead (:attr:`RneaPartials.kernels`).

    >>> from modelgen.model.chains import spatial_chain
    >>> from modelgen.derive.kinematics import derive_kinematics
    >>> from modelgen.derive.dynamics import derive_equations
    >>> from modelgen.derive.joint_tree import extract_joint_tree
    >>> spec = spatial_chain(3).spec()
    >>> d = derive_rnea_partials(derive_equations(derive_kinematics(spec)),
    ...                          extract_joint_tree(spec), spec)
    >>> len(d.vectors), len(d.vectors[0]), d.same, d.pairs
    (3, 51, ((0, 0), (1, 1), (2, 2)), ((0, 1), (0, 2), (1, 2)))
    """
    builder = GraphBuilder(graph or eqs.graph)
    n = len(eqs.qd)
    a = accelerations(n)
    qd = eqs.qd
    a0, gravity_labels = ground_acceleration(spec)
    count = len(tree.joints)
    root_frame = floating_root(tree)
    loads, moved, load_du = _body_fixed_actions(builder, eqs, tree, spec)
    motors, load_du = _motor_columns(tree, load_du, n, len(eqs.u))
    same, pairs = _dof_pairs(tree)
    order, parent = _dof_chain(tree)
    if looped and not root_frame and loopable(tree, eqs.q):
        # the other body-fixed actions' d Q / d u comes from the kernels' loop
        kernels = derive_link_kernels(tree, a0, n > ARTICULATED_SOLVE_ABOVE, loads, load_du)
        graph, effects = _effects(builder.freeze(), eqs, tree, set(gravity_labels) | moved,
                                  motors)
        return RneaPartials(graph, a, (), same, pairs, effects, (), order, parent,
                            kernels=kernels)
    poses, R0 = _poses(builder, tree, root_frame)
    if root_frame and any(x != 0 for x in a0[3:]):
        # gravity (the ground's linear acceleration) in the root link's components
        a0 = ZERO3 + name_vec(builder, matvec(transpose(R0), a0[3:]))
    J, ov, oa, Y, doY, of = {}, [None] * count, [None] * count, [None] * count, \
        [None] * count, [None] * count
    dVdq, dAdq, dAdv = {}, {}, {}
    turned = [False] * count            # a quaternion's matrix in the link's R
    for i, joint in enumerate(tree.joints):
        R, p = poses[i]
        par = joint.parent
        turned[i] = (par >= 0 and turned[par]) or \
            (joint.kind in ("ball", "free") and not (root_frame and par < 0))
        ov_p = ov[par] if par >= 0 else (ZERO,) * 6
        oa_p = oa[par] if par >= 0 else tuple(a0)
        for k, S in joint.dofs:
            J[k] = name_vec(builder, motion_to_ground(R, p, S))
            dVdq[k] = name_vec(builder, cross_motion(ov_p, J[k]))
        vJ = tuple(total(times(J[k][r], qd[k]) for k, _ in joint.dofs) for r in range(6))
        aJ = tuple(total(times(J[k][r], a[k]) for k, _ in joint.dofs) for r in range(6))
        # ov_i x vJ = ov_p x vJ (vJ x vJ = 0), a sum of the dVdq already there
        cJ = tuple(total(times(dVdq[k][r], qd[k]) for k, _ in joint.dofs) for r in range(6))
        vJ = name_vec(builder, vJ)
        ov[i] = name_vec(builder, add(ov_p, vJ))
        oa[i] = name_vec(builder, add(add(oa_p, aJ), cJ))
        Y[i], of[i], doY[i] = link_dynamics(builder, tree.inertias[i], R, p, ov[i], oa[i],
                                            not turned[i], loads.get(i))
        for k, _ in joint.dofs:
            dV = dVdq[k]
            dAdq[k] = name_vec(builder, add(cross_motion(oa_p, J[k]), cross_motion(ov_p, dV)))
            # ov_i x J_k = dV + vJ x J_k, and vJ x J_k = 0 for a joint of one dof
            twice = tuple(builder.factor(times(2, x)) for x in dV)
            dAdv[k] = (twice if len(joint.dofs) == 1 else
                       name_vec(builder, add(cross_motion(vJ, J[k]), twice)))
    # inwards: composite inertias, their variations and forces, leaves first
    Yc, dYc, fc = list(Y), list(doY), list(of)
    vectors = {}
    for i in reversed(range(count)):
        joint = tree.joints[i]
        for k, _ in joint.dofs:
            vectors[k] = (J[k], dAdq[k], dVdq[k], dAdv[k]) + dof_partials(
                builder, Yc[i], dYc[i], fc[i], J[k], dAdq[k], dVdq[k], dAdv[k])
        par = joint.parent
        if par >= 0:
            (Ip, hp, mp), (Ii, hi, mi) = Yc[par], Yc[i]
            Yc[par] = (tuple(name_vec(builder, add(a, b)) for a, b in zip(Ip, Ii, strict=True)),
                       name_vec(builder, add(hp, hi)), builder.name(mp + mi))
            (Ap, Fp), (Ai, Fi) = dYc[par], dYc[i]
            dYc[par] = (tuple(name_vec(builder, add(a, b)) for a, b in zip(Ap, Ai, strict=True)),
                        name_vec(builder, add(Fp, Fi)))
            fc[par] = name_vec(builder, add(fc[par], fc[i]))
    factor = (articulated_factor(builder, order, parent, J, Y, tree)
              if n > ARTICULATED_SOLVE_ABOVE else None)
    du_loads = _plus(_loads_du(builder, load_du, poses, J, tree, len(eqs.u)), motors)
    root_dofs = {k for joint in tree.joints if joint.parent < 0 for k, _ in joint.dofs}
    programmed = tuple((k, l) for k, l in same if root_frame and k in root_dofs)
    constant = _constant_pairs(builder, programmed, vectors, n)
    graph, effects = _effects(builder.freeze(), eqs, tree, set(gravity_labels) | moved,
                              du_loads)
    effects = (_plus(effects[0], constant[0]), _plus(effects[1], constant[1]), effects[2],
               _plus(effects[3], constant[2]))
    return RneaPartials(graph, a, tuple(tuple(e for vec in vectors[k] for e in vec)
                                        for k in range(n)), same, pairs, effects,
                        tuple(factor[k] for k in range(n)) if factor else (), order, parent,
                        programmed)


def _motor_columns(tree: JointTree, load_du, n: int, nu: int) -> tuple:
    """``(du, rest)``: the inputs that act as a motor of a revolute joint (a torque
    along its axis on its link, and the opposite torque on its parent's link unless
    the parent is the ground) as their constant columns of d Q / d u (n x nu:
    ``-S . d torque / d u`` at the joint's dof, 0 above it, where the torque and
    its reaction cancel exactly), and ``load_du`` without them."""
    du = [[ZERO] * nu for _ in range(n)]
    by_input = {}
    for i, row in load_du.items():
        for j, d in row.items():
            by_input.setdefault(j, {})[i] = d
    rest = {}
    for j, entries in by_input.items():
        motor = _motor_of(tree, entries)
        if motor is None:
            for i, d in entries.items():
                rest.setdefault(i, {})[j] = d
            continue
        (k, S), = tree.joints[motor].dofs
        du[k][j] = -dot(S[:3], entries[motor][:3])
    return tuple(tuple(row) for row in du), rest


def _motor_of(tree: JointTree, entries) -> int | None:
    """The joint of which ``entries`` ({link: d force / d u}) is a motor, or None."""
    def torque_along(d, axis):
        return all(is_zero(x) for x in d[3:]) and \
            all(is_zero(x) for c, x in enumerate(d[:3]) if c != axis - 1)
    for m, d in entries.items():
        joint = tree.joints[m]
        if joint.kind != "revolute" or not torque_along(d, joint.axis):
            continue
        others = {i: e for i, e in entries.items() if i != m}
        if not others and joint.parent < 0:
            return m
        if set(others) == {joint.parent} and joint.parent >= 0:
            E = joint.fixed[0]
            reaction = others[joint.parent]
            back = tuple(-sum(E[r][c] * d[r] for r in range(3)) for c in range(3))
            if all(is_zero(x) for x in reaction[3:]) and \
                    all(sympy.expand(x - y) == 0 for x, y in zip(reaction[:3], back, strict=True)):
                return m
    return None


def _constant_pairs(builder, programmed, vectors, n) -> tuple:
    """``(dq, dv, M)`` (n x n) of the pairs ``programmed`` of one joint's dofs with
    constant ``J_k``: ``J_k . dFdq0_l``, ``J_k . dFdv_l``, ``J_k . dFda_l``."""
    out = [[[ZERO] * n for _ in range(n)] for _ in range(3)]
    for k, l in programmed:
        J, (dFda, dFdq0, dFdv) = vectors[k][0], (vectors[l][4], vectors[l][6], vectors[l][8])
        for m, x in zip(out, (dFdq0, dFdv, dFda), strict=True):
            m[k][l] = builder.name(dot(J, x))
    return tuple(tuple(tuple(row) for row in m) for m in out)


def _plus(a, b) -> tuple:
    return tuple(tuple(x + y for x, y in zip(ra, rb, strict=True))
                 for ra, rb in zip(a, b, strict=True))


def _dof_chain(tree: JointTree) -> tuple:
    """``(order, parent)``: the speeds, a joint's in its own order after its parent's,
    and each speed's predecessor (the previous dof of its joint, else the last of
    the parent joint's, else -1): a ball or free joint is a chain of one-dof joints
    between massless links."""
    order, parent, last = [], {}, {}
    for i, joint in enumerate(tree.joints):
        prev = last[joint.parent] if joint.parent >= 0 else -1
        for k, _ in joint.dofs:
            order.append(k)
            parent[k] = prev
            prev = k
        last[i] = prev
    return tuple(order), tuple(parent[k] for k in range(len(order)))


def articulated_factor(builder, order, parent, J, Y, tree: JointTree) -> dict:
    """{speed k: (U_k (6), 1 / D_k)}: the articulated-body inertias in E
    (Featherstone §7.3, every quantity in one frame, so no transforms) with the
    dofs as a chain of one-dof joints: inwards ``U_k = IA_k J_k``,
    ``D_k = J_k . U_k + armature_k`` and ``IA_p += IA_k - U_k U_k^T / D_k``
    for the predecessor p, ``IA_k`` starting as the inertia of k's link when k
    is its joint's last dof.  ``-M^-1 b`` is then, inwards,
    ``w_k = (b_k - J_k . P_k) / D_k``, ``P_p += P_k + U_k w_k``, and outwards
    ``x_k = w_k - U_k . A_p / D_k``, ``A_k = A_p + J_k x_k`` (the C loop)."""
    link = {}
    for i, joint in enumerate(tree.joints):
        link[joint.dofs[-1][0]] = i
    IA = {k: sym6(Y[link[k]]) for k in link}
    out = {}
    for k in reversed(order):
        A = IA.pop(k)
        U = name_vec(builder, [dot(row, J[k]) for row in A])
        arm = tree.armature[k] if tree.armature else ZERO
        d = builder.name(total((dot(J[k], U), arm)))
        inv = builder.name(1 / d)
        out[k] = U + (inv,)
        p = parent[k]
        if p < 0:
            continue
        Uw = name_vec(builder, [times(inv, x) for x in U])
        # IA - U U^T / D: symmetric, each entry named once
        child = [[None] * 6 for _ in range(6)]
        for r in range(6):
            for c in range(r, 6):
                child[r][c] = child[c][r] = total((A[r][c], -times(U[r], Uw[c])))
        if p in IA:
            child = [[total((x, y)) for x, y in zip(ra, rb, strict=True)]
                     for ra, rb in zip(IA[p], child, strict=True)]
        elif p in link:
            child = [[total((x, y)) for x, y in zip(ra, rb, strict=True)]
                     for ra, rb in zip(sym6(Y[link[p]]), child, strict=True)]
        named6 = [[None] * 6 for _ in range(6)]
        for r in range(6):
            for c in range(r, 6):
                named6[r][c] = named6[c][r] = named(builder, child[r][c])
        IA[p] = named6
    return out


def _dof_pairs(tree: JointTree) -> tuple:
    """``(same, pairs)`` of :class:`RneaPartials`."""
    same, pairs = [], []
    below = [[] for _ in tree.joints]         # the strict descendants of each joint
    for i in reversed(range(len(tree.joints))):
        par = tree.joints[i].parent
        if par >= 0:
            below[par] = [i] + below[i] + below[par]
    for i, joint in enumerate(tree.joints):
        dofs = [k for k, _ in joint.dofs]
        same.extend((k, l) for k in dofs for l in dofs)
        pairs.extend((k, l) for k in dofs
                     for l in sorted(m for j in below[i] for m, _ in tree.joints[j].dofs))
    return tuple(same), tuple(pairs)


def _body_fixed_actions(builder, eqs: Equations, tree: JointTree, spec: ModelSpec) -> tuple:
    """``(loads, labels, du)``: the actions whose spatial force is constant in their
    link's frame (no coordinate or speed in it, a joint's motor and its reaction
    among them), as forces on their links ({joint index: 6-vector in link
    components}), their labels, and {joint index: {input index: d force / d u}}.
    Their derivatives along q are then the transport of the links' forces
    (``J_k x* of``), exact, where forward mode over their generalized forces
    differentiates expressions that are constant only for a unit quaternion."""
    moving = set(eqs.q) | set(eqs.qd)
    link_of = dict(tree.body_links)
    loads, labels, du = {}, set(), {}
    # each force in a scratch graph first: the ones kept are expanded (small)
    probe = GraphBuilder(eqs.graph)
    forces = [(act, link_of.get(act.body, -1))
              for act in list(spec.actions) + [e for e in spec.effects if e.kind == "action"]]
    forces = [(act, i, action_force(probe, spec, tree.joints[i], act))
              for act, i in forces if i >= 0]
    graph = probe.freeze()
    for act, i, f in forces:
        if set().union(*(_symbols_through(graph, e) for e in f)) & moving:
            continue
        f = tuple(graph.expand(e) for e in f)
        labels.add(act.name)
        loads[i] = name_vec(builder, add(loads[i], f)) if i in loads else name_vec(builder, f)
        for j, uj in enumerate(eqs.u):
            d = tuple(sympy.diff(e, uj) for e in f)
            if any(x != 0 for x in d):
                row = du.setdefault(i, {})
                row[j] = add(row[j], d) if j in row else d
    return loads, labels, du


def _symbols_through(graph: Graph, expr) -> set:
    """The symbols ``expr`` depends on through ``graph``'s intermediates."""
    defs = graph.definitions()
    out = set(sympy.sympify(expr).free_symbols)
    for _, e in graph.closure([expr]):
        out |= e.free_symbols
    return out - set(defs)


def _loads_du(builder, load_du, poses, J, tree: JointTree, nu: int) -> tuple:
    """n x nu: minus the derivatives of the body-fixed actions' generalized forces
    along the inputs, ``-J_k . sum of d f / d u_j`` over the links of the subtree
    of k's joint, in E; where only k's own link has such a force, ``-S_k . d f /
    d u_j`` in that link's frame (a motor on its own coordinate: a constant)."""
    n = len(J)
    out = [[ZERO] * nu for _ in range(n)]
    below = [{} for _ in tree.joints]       # the strict descendants' d f / d u in E
    for i in reversed(range(len(tree.joints))):
        joint, own = tree.joints[i], load_du.get(i, {})
        R, p = poses[i]
        here = dict(below[i])
        for j, d in own.items():
            f = force_to_ground(R, p, d)
            here[j] = name_vec(builder, add(here[j], f)) if j in here else name_vec(builder, f)
        for k, S in joint.dofs:
            for j in here:
                e = dot(S, own[j]) if j not in below[i] else dot(J[k], here[j])
                out[k][j] = builder.name(-e)
        if joint.parent >= 0:
            up = below[joint.parent]
            for j, g in here.items():
                up[j] = name_vec(builder, add(up[j], g)) if j in up else g
    return tuple(tuple(row) for row in out)


def _effects(graph: Graph, eqs: Equations, tree: JointTree, local, du_loads) -> tuple:
    """``(graph, (dq, dv, du, M))``: minus the derivatives of the generalized forces of
    every effect but those in ``local`` (gravity in E, the body-fixed actions, whose
    ``du`` is ``du_loads``), and the armature on M's diagonal."""
    n, nq = len(eqs.qd), len(eqs.q)
    others = [part for label, part in eqs.tau_parts if label not in local]
    zero = tuple(tuple(ZERO for _ in range(n)) for _ in range(n))
    M = tuple(tuple((tree.armature[k] if tree.armature and k == l else ZERO)
                    for l in range(n)) for k in range(n))
    if not others:
        return graph, (zero, zero, du_loads, M)
    builder = GraphBuilder(graph)
    tau = [named(builder, -sympy.Add(*[part[k] for part in others])) for k in range(n)]
    graph, rows = differentiate(builder.freeze(), tau, tuple(eqs.q) + tuple(eqs.qd)
                                + tuple(eqs.u))
    dv = tuple(tuple(row[nq:nq + n]) for row in rows)
    du = tuple(tuple(x + y for x, y in zip(row[nq + n:], extra, strict=True))
               for row, extra in zip(rows, du_loads, strict=True))
    dq_full = [row[:nq] for row in rows]
    if nq == n:
        dq = tuple(tuple(row) for row in dq_full)
    else:
        graph, dq = tangent_rows(graph, eqs, dq_full)
    return graph, (dq, dv, du, M)


__all__ = ["ARTICULATED_SOLVE_ABOVE", "PAIR_OPERATIONS", "RneaPartials", "VECTORS", "articulated_factor",
           "derive_rnea_partials", "floating_root"]
