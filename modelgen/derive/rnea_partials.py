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
  (``doY`` has only two non-zero 3x3 blocks, :func:`_variation`, so ``dYtJ``
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
from modelgen.derive.kinematics import quaternion_columns
from modelgen.derive.recursion import action_force, ground_acceleration
from modelgen.derive.rnea_derivatives import tangent_rows
from modelgen.derive.spatial import (IDENTITY3, PAIRS, ZERO, ZERO3, add, cross, cross_motion,
                                     dot, is_identity, matmul, matvec, name_vec, named,
                                     rotation, skew, sub, symmetric, times, total, transpose)
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

    def looped_same(self) -> tuple:
        """The pairs of :attr:`same` the C loop computes."""
        programmed = set(self.programmed)
        return tuple(pair for pair in self.same if pair not in programmed)

    def pattern(self) -> tuple:
        """n x n booleans: the entries of M that can be non-zero (one branch)."""
        n = len(self.vectors)
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
        return self.graph.operations(flat) + 11 * (3 * len(self.looped_same())
                                                   + 8 * len(self.pairs))


# -- the ground-frame algebra --------------------------------------------------------

def _motion_to_ground(R, p, m):
    """A link's motion vector ``m`` (link components) in E: ``(R w, R v + p x R w)``."""
    w = matvec(R, m[:3])
    return tuple(w) + add(matvec(R, m[3:]), cross(p, w))


def _force_cross(v, f):
    """``v x* f`` (Featherstone's crf)."""
    return add(cross(v[:3], f[:3]), cross(v[3:], f[3:])) + cross(v[:3], f[3:])


def _inertia_times(Y, x) -> tuple:
    """``Y x`` for a spatial inertia ``Y = (I_O, h, m)``: ``(I_O w + h x v, m v - h x w)``."""
    I, h, m = Y
    w, v = x[:3], x[3:]
    return add(matvec(I, w), cross(h, v)) + sub(tuple(times(m, c) for c in v), cross(h, w))


def _variation(builder, Y, v, oh) -> tuple:
    """``doY = v x* Y - Y v x + B(oh)`` with ``B(oh) x = x x* oh`` and ``oh = Y v``
    (Pinocchio's ``Inertia::variation`` plus ``addForceCrossMatrix``), as ``(A, F)``:
    its blocks are ``[[A, 0], [-2 F x, 0]]``.

    With ``W = w x``, ``U = u x``, ``H = h x`` for ``v = (w, u)``: the top left block
    is ``W I - I W - (U H + H U) - (n x)`` (``n`` the angular part of ``oh``),
    the top right ``W H - H W + m U - (f x) = 0`` since ``f = m u + w x h``, and
    the bottom left ``-(W H - H W + m U) - (f x) = -2 (f x)``.
    """
    I, h, m = Y
    w, u = v[:3], v[3:]
    n, f = oh[:3], oh[3:]
    P = tuple(tuple(builder.name(x) for x in cross(w, tuple(I[r][c] for r in range(3))))
              for c in range(3))              # P[c] = column c of W I
    nx = skew(n)
    # the symmetric part once per pair of entries, the skew part -(n x) on each
    A = [[None] * 3 for _ in range(3)]
    for r in range(3):
        # W I - I W - (U H + H U) on the diagonal: 2 ((W I)_rr + u . h - u_r h_r)
        others = tuple(times(u[c], h[c]) for c in range(3) if c != r)
        A[r][r] = builder.factor(times(2, named(builder, total((P[r][r],) + others))))
        for c in range(r + 1, 3):
            sym = named(builder, total((P[c][r], P[r][c], -times(h[r], u[c]),
                                        -times(u[r], h[c]))))
            A[r][c] = named(builder, total((sym, -nx[r][c])))
            A[c][r] = named(builder, total((sym, -nx[c][r])))
    return tuple(tuple(row) for row in A), f


def _variation_times(dY, x) -> tuple:
    """``doY x`` for ``doY = (A, F)`` of :func:`_variation`."""
    A, F = dY
    w = x[:3]
    return matvec(A, w) + tuple(times(-2, c) for c in cross(F, w))


def _variation_T_times(dY, x) -> tuple:
    """The angular part of ``doY^T x`` (its linear part is 0): ``A^T w + 2 F x v``."""
    A, F = dY
    return add(matvec(transpose(A), x[:3]), tuple(times(2, c) for c in cross(F, x[3:])))


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


def _rotated_inertia(builder, I, R, orthogonal: bool) -> tuple:
    """The 6 entries (as :data:`PAIRS`) of ``R I R^T`` for the 6 entries ``I``.

    With R ``orthogonal`` (a product of the joints' cos/sin rotations, exactly
    orthogonal, where a quaternion's matrix is only when its norm is 1) a
    diagonal ``I`` (principal axes along the link's: rods, boxes, cylinders) is
    ``d 1 + sum_k (I_k - d) r_k r_k^T`` over the columns ``r_k`` of R, with ``d``
    the moment most axes share: one term less per axis of symmetry."""
    if not orthogonal or any(x != 0 for x in I[3:]):
        RI = tuple(name_vec(builder, row) for row in matmul(R, symmetric(I)))
        return tuple(dot(RI[a], R[b]) for a, b in PAIRS)
    # the moment most axes share, a zero on a tie (no d 1 to add, no I_k - 0)
    d = max(I[:3], key=lambda x: (sum(1 for y in I[:3] if y == x), x == 0))
    out = [d, d, d, ZERO, ZERO, ZERO]
    for k in range(3):
        if I[k] == d:
            continue
        s = builder.name(total((I[k], -d)))
        r = tuple(R[a][k] for a in range(3))
        sr = name_vec(builder, tuple(times(s, x) for x in r))
        out = [total((e, times(sr[a], r[b]))) for e, (a, b) in zip(out, PAIRS, strict=True)]
    return tuple(out)


def _ground_inertia(builder, body, R, p, orthogonal: bool) -> tuple:
    """The link's spatial inertia ``(I_O, h, m)`` about E's origin in E components.

    ``I_O = R I R^T - m p^ p^ - p^ hr^ - hr^ p^`` (``x^`` the cross-product matrix,
    ``hr = R h``), its translation part arranged around ``h_O = hr + m p``, the
    first moment about E's origin, which the link needs anyway: an off-diagonal
    entry ``(a, b)`` is ``(R I R^T)_ab - p_a h_O,b - hr_a p_b``, a diagonal one
    ``(R I R^T)_aa + t_b + t_c`` over the two other axes, ``t_b = p_b (h_O,b +
    hr_b)`` (that is ``m p_b^2 + 2 p_b hr_b``).  ``orthogonal``: see
    :func:`_rotated_inertia`.
    """
    Ir = _rotated_inertia(builder, name_vec(builder, body.I), R, orthogonal)
    h = name_vec(builder, body.h)
    m = builder.name(body.m)
    hr = name_vec(builder, matvec(R, h))
    h_O = name_vec(builder, add(hr, tuple(times(m, x) for x in p)))
    t = name_vec(builder, tuple(times(x, total((y, z))) for x, y, z in zip(p, h_O, hr,
                                                                           strict=True)))
    entries = []
    for (a, b), Iab in zip(PAIRS, Ir, strict=True):
        if a == b:
            e = total((Iab,) + tuple(t[c] for c in range(3) if c != a))
        else:
            e = total((Iab, -times(p[a], h_O[b]), -times(hr[a], p[b])))
        entries.append(e)
    I_O = symmetric(name_vec(builder, entries))
    return I_O, h_O, m


# -- the algorithm ---------------------------------------------------------------------

def derive_rnea_partials(eqs: Equations, tree: JointTree, spec: ModelSpec,
                         graph: Graph | None = None) -> RneaPartials:
    """The per-dof vectors of the recursive derivatives of inverse dynamics of a
    joint tree, and the effects' derivatives, built over ``graph`` (default
    ``eqs.graph``).

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
    poses, R0 = _poses(builder, tree, root_frame)
    loads, moved, load_du = _body_fixed_actions(builder, eqs, tree, spec)
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
            J[k] = name_vec(builder, _motion_to_ground(R, p, S))
            dVdq[k] = name_vec(builder, cross_motion(ov_p, J[k]))
        vJ = tuple(total(times(J[k][r], qd[k]) for k, _ in joint.dofs) for r in range(6))
        aJ = tuple(total(times(J[k][r], a[k]) for k, _ in joint.dofs) for r in range(6))
        # ov_i x vJ = ov_p x vJ (vJ x vJ = 0), a sum of the dVdq already there
        cJ = tuple(total(times(dVdq[k][r], qd[k]) for k, _ in joint.dofs) for r in range(6))
        vJ = name_vec(builder, vJ)
        ov[i] = name_vec(builder, add(ov_p, vJ))
        oa[i] = name_vec(builder, add(add(oa_p, aJ), cJ))
        Y[i] = _ground_inertia(builder, tree.inertias[i], R, p, not turned[i])
        oh = name_vec(builder, _inertia_times(Y[i], ov[i]))
        of[i] = name_vec(builder, add(_inertia_times(Y[i], oa[i]), _force_cross(ov[i], oh)))
        if i in loads:                  # Q = RNEA's forces less the actions'
            of[i] = name_vec(builder, sub(of[i], _force_to_ground(R, p, loads[i])))
        doY[i] = _variation(builder, Y[i], ov[i], oh)
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
            dFda = name_vec(builder, _inertia_times(Yc[i], J[k]))
            dFdq0 = name_vec(builder, add(_variation_times(dYc[i], dVdq[k]),
                                          _inertia_times(Yc[i], dAdq[k])))
            dFdq = name_vec(builder, add(dFdq0, _force_cross(J[k], fc[i])))
            dFdv = name_vec(builder, add(_variation_times(dYc[i], J[k]),
                                         _inertia_times(Yc[i], dAdv[k])))
            dYtJ = name_vec(builder, _variation_T_times(dYc[i], J[k]))
            vectors[k] = (J[k], dAdq[k], dVdq[k], dAdv[k], dFda, dYtJ, dFdq0, dFdq, dFdv)
        par = joint.parent
        if par >= 0:
            (Ip, hp, mp), (Ii, hi, mi) = Yc[par], Yc[i]
            Yc[par] = (tuple(name_vec(builder, add(a, b)) for a, b in zip(Ip, Ii, strict=True)),
                       name_vec(builder, add(hp, hi)), builder.name(mp + mi))
            (Ap, Fp), (Ai, Fi) = dYc[par], dYc[i]
            dYc[par] = (tuple(name_vec(builder, add(a, b)) for a, b in zip(Ap, Ai, strict=True)),
                        name_vec(builder, add(Fp, Fi)))
            fc[par] = name_vec(builder, add(fc[par], fc[i]))
    same, pairs = _dof_pairs(tree)
    order, parent = _dof_chain(tree)
    factor = (articulated_factor(builder, order, parent, J, Y, tree)
              if n > ARTICULATED_SOLVE_ABOVE else None)
    du_loads = _loads_du(builder, load_du, poses, J, tree, len(eqs.u))
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


def _sym6(Y) -> list:
    """The 6x6 rows of a rigid-body inertia ``(I_O, h, m)``."""
    I, h, m = Y
    hx = skew(h)
    return [list(I[r]) + list(hx[r]) for r in range(3)] + \
        [[-hx[r][c] if hx[r][c] != 0 else ZERO for c in range(3)]
         + [m if r == c else ZERO for c in range(3)] for r in range(3)]


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
    IA = {k: _sym6(Y[link[k]]) for k in link}
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
                     for ra, rb in zip(_sym6(Y[link[p]]), child, strict=True)]
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


def _force_to_ground(R, p, f):
    """A link's force ``f`` (link components, at its origin) in E at E's origin:
    ``(R n + p x R f, R f)``."""
    F = matvec(R, f[3:])
    return add(matvec(R, f[:3]), cross(p, F)) + tuple(F)


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
            f = _force_to_ground(R, p, d)
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
