"""Forward dynamics in O(n): the articulated-body algorithm, unrolled.

Featherstone, *Rigid Body Dynamics Algorithms* (2008), ch. 7, Table 7.1, in
each link's own frame (:mod:`modelgen.derive.joint_tree` gives the links):

1. outwards: ``v_i = X_i v_p + S_i qd_i``, ``c_i = v_i x S_i qd_i``,
   ``IA_i = I_i``, ``pA_i = v_i x* I_i v_i``;
2. inwards: ``U_i = IA_i S_i``, ``D_i = S_i^T U_i``, ``u_i = tau_i - S_i^T pA_i``;
   then ``Ia = IA_i - U_i U_i^T / D_i`` and ``pa = pA_i + Ia c_i + U_i u_i / D_i``
   are added to the parent as ``X_i^T Ia X_i`` and ``X_i^T pa``;
3. outwards: ``a'_i = X_i a_p + c_i``, ``qdd_i = (u_i - U_i^T a'_i) / D_i``,
   ``a_i = a'_i + S_i qdd_i``.

Or the ``c_i`` go into pass 1 (``velocity_products="outward"``): RNEA's
``a_vp,i = X_i a_vp,p + c_i`` and ``pA_i = I_i a_vp,i + v_i x* I_i v_i``, and
passes 2 and 3 run with ``c = 0``.  :func:`derive_aba` builds both and keeps
the shorter program.

What is known exactly is not computed: ``-U_i / D_i`` is named once (so ``Ia``
and ``qdd`` are sums of products, ``qdd_i = u_i / D_i + (-U_i / D_i)^T a'_i``);
for a one-entry ``S`` (entry j) row and column j of ``Ia`` vanish, entry j of
``-U_i / D_i`` is ``-1 / S_j`` and entry j of ``pa`` is ``tau_i / S_j``
(``Ia S = 0``, ``S^T U = D``).  A rotation about a base axis turns the in-plane
2x2 blocks of ``Ia`` by their trace-free symmetric part only.  The rigid bias
force is formed at the centre of mass when that needs no division by a mass.

Gravity (the top-level ``gravity`` and gravity effects in base E) is the
acceleration ``-g`` of the ground, so it costs nothing per body.  Actions are
external spatial forces ``f_i`` on their links (``pA_i = v_i x* I_i v_i - f_i``),
turned into link components along the base and point trees.  Every other
effect enters through its generalized force ``tau_k``, taken
from the CRBA derivation (:attr:`modelgen.derive.dynamics.Equations.tau_parts`):
``tau_k`` is exactly the power of those forces per unit ``qd_k``, so adding it
to ``u_i`` gives the same ``qdd`` as ``A qdd = tau - h``.  (Actions could go
that way too, but their projection needs every base's rotation in E.)

The program is built with :class:`~modelgen.derive.graph.GraphBuilder`, so the
constant zeros and ones of the motion subspaces (unit vectors along a base
axis) and of the joint transforms (one elementary rotation, one translation)
fold away as the expressions are formed: a projection ``S^T f`` is a single
entry, ``U`` a column of ``IA``.  Articulated inertias are symmetric 6x6
matrices ``[[A, B], [B^T, C]]`` carried as 21 entries.

A dof's armature (reflected rotor inertia, MuJoCo's ``dof_armature``) adds to
its joint's ``D_i = S_i^T U_i + armature_i`` (the diagonal of D for a ball or
free joint) and nothing else: the rotor's inertia turns with the joint's
coordinate only, so ``U_i``, ``u_i`` and the formulas above stand, but the
shortcuts that rest on ``S^T U = D`` are skipped for that joint.

``D_i`` is returned with ``qdd``: it must be checked > 0 at run time (a
non-positive ``D_i`` is a singular configuration at joint i).
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.dynamics import Equations
from modelgen.derive.graph import Graph, GraphBuilder, free_symbols, operation_count
from modelgen.derive.jacobian import JacobianTerms, differentiate
from modelgen.derive.joint_tree import JointTree
from modelgen.derive.recursion import (inward_place, joint_motion, link_force, link_loads,
                                       link_velocities, outward_pass, outward_place,
                                       to_parent_force, to_parent_inertia)
from modelgen.derive.spatial import (ONE, ZERO, add, dot, inertia_times, is_zero,
                                     name_matrix, name_symmetric, name_vec, named, neg, skew, sub,
                                     symmetric, times, total)
from modelgen.model.spec import ModelSpec

@dataclass(frozen=True)
class ForwardDynamics:
    """Output of :func:`derive_aba`: ``qdd`` and ``D`` in coordinate order, over ``graph``.

    ``inward`` lists the coordinate indices in the order the inward pass
    computes their D: a D that is not positive spoils the D of every joint
    nearer the root, so the first failing one in this order names the joint.
    """
    graph: Graph
    qdd: tuple
    D: tuple
    inward: tuple
    #: per joint (tree order): does its velocity-product acceleration go outwards?
    outward: tuple = ()


def _drop_subspace(I, S):
    """Ia with the row and column of a one-entry S set to zero exactly.

    ``Ia S = U - U (S^T U) / D = 0``, so when S has a single non-zero entry j,
    row and column j of Ia vanish; symbolically they would be
    ``x - x * x * (1/x)``, which no folding sees.
    """
    nonzero = [j for j, s in enumerate(S) if s != 0]
    if len(nonzero) != 1:
        return I
    (j,) = nonzero
    A, B, C = I
    if j < 3:
        A = _zero_row_col(A, j)
        B = tuple(tuple(ZERO if r == j else B[r][s] for s in range(3)) for r in range(3))
    else:
        C = _zero_row_col(C, j - 3)
        B = tuple(tuple(ZERO if s == j - 3 else B[r][s] for s in range(3)) for r in range(3))
    return (A, B, C)


def _armature(tree, k: int):
    """The armature of dof ``k`` (0 when the model gives none)."""
    return tree.armature[k] if tree.armature else ZERO


def _single(S):
    """Index of the one non-zero entry of S, or None."""
    nonzero = [j for j, s in enumerate(S) if s != 0]
    return nonzero[0] if len(nonzero) == 1 else None


def _zero_row_col(M, j):
    return tuple(tuple(ZERO if j in (r, s) else M[r][s] for s in range(3)) for r in range(3))


#: where the velocity-product accelerations c_i enter the ABA (:func:`derive_aba`)
VELOCITY_PRODUCTS = ("inward", "outward", "auto")


def _variable_operations(builder: GraphBuilder, out, variables) -> int:
    """Operations of ``out``, built in ``builder``, without the statements of the
    parameters alone (they are hoisted): what depends on ``variables``."""
    moving = set(variables)
    total = 0
    for sym, e in builder.freeze().closure(out):
        if free_symbols(e) & moving:
            moving.add(sym)
            total += operation_count(e)
    for e in map(sympy.sympify, out):
        if free_symbols(e) & moving:
            total += operation_count(e)
    return total


def _renamed(data) -> tuple:
    """``data`` (nested tuples of expressions) flat, with its symbols renamed in
    order of appearance: what the costs of :func:`velocity_product_plan`
    depend on (the links of a uniform chain have one shape)."""
    flat = _flat(data)
    names: dict = {}
    for node in sympy.preorder_traversal(sympy.Tuple(*[x for x in flat
                                                       if isinstance(x, sympy.Basic)])):
        if isinstance(node, sympy.Symbol) and node not in names:
            names[node] = sympy.Symbol(f"s{len(names)}")
    return tuple(x.xreplace(names) if isinstance(x, sympy.Basic) else x for x in flat)


def _flat(data) -> list:
    out = []
    for x in data:
        if isinstance(x, (tuple, list)):
            out.extend(_flat(x))
        else:
            out.append(sympy.sympify(x) if isinstance(x, (int, float)) else x)
    return out


#: operations a subtree must save, by the estimate, to send its c outwards: the
#: estimate misses what CSE and shared names do (a few operations a joint:
#: the heavy top's last joint counts 10 inwards against 8 outwards and costs 4
#: more outwards), and inwards is the textbook's program
_PLAN_MARGIN = 4


def velocity_product_plan(tree: JointTree, velocities, cost_in) -> tuple:
    """Per joint: does its ``c_i`` go outwards (True) or inwards?

    ``velocities`` is :func:`link_velocities`' ``(v, c)``: where they are
    exactly zero (near the root, at massless links) the choice costs less.
    A joint's choice costs, in operations of its own:

    * inwards: ``cost_in[i]``, counted on the joint's articulated inertia
      (``Ia c`` added into ``pa``, and ``+ c`` in pass 3);

    and, counted on generic values with the zeros of ``v`` and ``c``,
    parameters aside:

    * outwards, below a joint whose ``c`` goes inwards: ``a = c`` and
      ``I c`` in the force (no transform);
    * outwards below an outward joint: the transform of the parent's ``a``,
      ``+ c``, and ``I a`` (``a`` with the zeros of the parent's ``c`` below
      a start, taken as dense further down).

    An outward joint's children go outwards too (going back would cost the
    transform and a dense ``c``); the cheapest such choice is found by dynamic
    programming over the tree, and a subtree goes outwards only if that saves
    at least ``_PLAN_MARGIN`` operations.  Roots (``c = 0``) go inwards.
    """
    joints = tree.joints
    count = len(joints)
    dense = sympy.symbols("mg_a0:6")
    nothing = (ZERO,) * 6

    def generic(prefix, values):
        return tuple(ZERO if is_zero(x) else sympy.Symbol(f"{prefix}{r}")
                     for r, x in enumerate(values))

    # per joint: a = c (start), a = X a_p + c below a start (a_p = c_p, sparse)
    # and below an outward joint (a_p taken as dense); the costs of links and
    # joints alike but for their symbols are counted once
    forces: dict = {}
    transforms: dict = {}

    def force(body, shape, vs, a):
        key = (shape, vs, a)
        if key not in forces:
            builder = GraphBuilder()
            forces[key] = _variable_operations(builder, link_force(builder, body, vs, a),
                                               set(vs) | set(a))
        return forces[key]

    def below(joint, shape, ap, cs):
        key = (shape, ap, cs)
        if key not in transforms:
            builder = GraphBuilder()
            a = add(joint_motion(builder, joint, ap), cs)
            transforms[key] = (_variable_operations(builder, a, set(ap) | set(cs)),
                               generic("mg_a", a))
        return transforms[key]

    cost_start, after_start, after_more = [0] * count, [0] * count, [0] * count
    for i, joint in enumerate(joints):
        if joint.parent < 0:
            continue
        body = tree.inertias[i]
        link = _renamed((body.I, body.h, body.m))
        motion = _renamed((joint.kind, joint.axis, joint.fixed, joint.offset, joint.angle,
                           joint.quaternion, joint.position))
        vs, cs = generic("mg_v", velocities[0][i]), generic("mg_c", velocities[1][i])
        bias = force(body, link, vs, nothing)
        cost_start[i] = force(body, link, vs, cs) - bias
        for out, ap in ((after_start, generic("mg_a", velocities[1][joint.parent])),
                        (after_more, dense)):
            ops, a = below(joint, motion, ap, cs)
            out[i] = ops + force(body, link, vs, a) - bias
    children: list = [[] for _ in range(count)]
    for i, joint in enumerate(joints):
        if joint.parent >= 0:
            children[joint.parent].append(i)
    inward, start, more_s, more = [0] * count, [0] * count, [0] * count, [0] * count
    for i in reversed(range(count)):
        inward[i] = cost_in[i] + sum(min(inward[k], start[k]) for k in children[i])
        start[i] = cost_start[i] + sum(more_s[k] for k in children[i])
        more_s[i] = after_start[i] + sum(more[k] for k in children[i])
        more[i] = after_more[i] + sum(more[k] for k in children[i])
    plan = [False] * count
    for i, joint in enumerate(joints):
        p = joint.parent
        plan[i] = p >= 0 and (plan[p] or start[i] + _PLAN_MARGIN <= inward[i])
    return tuple(plan)


def derive_aba(eqs: Equations, tree: JointTree, spec: ModelSpec, graph: Graph | None = None,
               velocity_products: str = "auto") -> ForwardDynamics:
    """qdd by the articulated-body algorithm over ``graph`` (default ``eqs.graph``).

    ``spec`` is the model the equations came from; ``tree`` its joint tree.
    Gravity in E and actions are handled here; the generalized forces of every
    other effect are read from ``eqs.tau_parts``.

    ``velocity_products`` says where the velocity-product accelerations
    ``c_i`` enter (every choice gives the same qdd, up to rounding):

    * ``"inward"``: as in Table 7.1, ``pa_i = pA_i + Ia_i c_i + U_i u_i / D_i``
      and ``a'_i = X_i a_p + c_i``;
    * ``"outward"``: pass 1 propagates ``a_vp,i = X_i a_vp,p + c_i`` (RNEA's
      accelerations at zero q_ddot) and the bias force becomes
      ``pA_i = I_i a_vp,i + v_i x* I_i v_i``; passes 2 and 3 run with
      ``c = 0`` (write ``a_i = a_vp,i + a^_i``: then ``a^_i = X_i a^_p +
      S_i qdd_i`` and ``f_i = I_i a^_i + pA_i``).  No ``Ia c`` (about 40
      operations a revolute joint) and no ``+ c`` in pass 3, for one more
      transform and ``I a_vp`` in pass 1: cheaper for links whose centre lies
      on an axis and whose inertia is diagonal (the spatial chain's rods: 11
      operations a joint fewer), dearer for full inertias off the axes (the
      arm: 11 more);
    * ``"auto"``: per joint, as :func:`velocity_product_plan` finds cheapest
      (a subtree can go outwards from a joint whose parent's ``c`` goes
      inwards: there ``a_vp = c``, no transform).

    >>> from modelgen.model.chains import spatial_chain
    >>> from modelgen.derive.kinematics import derive_kinematics
    >>> from modelgen.derive.dynamics import derive_equations
    >>> from modelgen.derive.joint_tree import extract_joint_tree
    >>> spec = spatial_chain(2).spec()
    >>> fd = derive_aba(derive_equations(derive_kinematics(spec)), extract_joint_tree(spec), spec)
    >>> len(fd.qdd), fd.inward
    (2, (1, 0))
    """
    if velocity_products not in VELOCITY_PRODUCTS:
        raise ValueError(f"velocity_products must be one of {VELOCITY_PRODUCTS}")
    return _derive_aba(eqs, tree, spec, graph, velocity_products)


@dataclass(frozen=True)
class _Inertias:
    """Pass 2's inertia half, per joint (tree order): what the force half and
    pass 3 read.  ``multi`` holds the ball and free joints, the others have
    ``U``, ``D``, ``nUd`` (-U/D)."""
    U: list
    D: list
    nUd: list
    Ia: list          # articulated inertia passed to the parent (blocks)
    multi: dict       # joint index -> _MultiDofInertia


def _derive_aba(eqs, tree, spec, graph, velocity_products) -> ForwardDynamics:
    """The three passes of Table 7.1 (:func:`derive_aba`), built pass by pass."""
    builder = GraphBuilder(graph or eqs.graph)
    start = len(builder)
    a0, tau, external = link_loads(builder, eqs, tree, spec)
    velocities = link_velocities(builder, tree, eqs.qd)
    inertias = _backward_inertias(builder, tree)
    builder.place = None
    if velocity_products == "auto":
        inward = [0 if joint.parent < 0 else _inward_cost(inertias.Ia[i], velocities[1][i])
                  for i, joint in enumerate(tree.joints)]
        plan = velocity_product_plan(tree, velocities, inward)
    else:
        plan = tuple(velocity_products == "outward" and j.parent >= 0 for j in tree.joints)
    pA, c = _forward_bias(builder, tree, eqs.qd, plan, velocities, external)
    uD = _backward_forces(builder, tree, inertias, pA, c, tau)
    qdd = _forward_accelerations(builder, tree, inertias, uD, c, a0, len(eqs.qd))
    D = [None] * len(eqs.qd)
    for i, joint in enumerate(tree.joints):
        if i in inertias.multi:
            for (k, _), d in zip(joint.dofs, inertias.multi[i].pivots, strict=True):
                D[k] = d
        else:
            D[joint.coordinate] = inertias.D[i]
    inward = tuple(k for joint in reversed(tree.joints) for k, _ in joint.dofs)
    # built pass by pass (the plan needs every joint's inertia), written joint by
    # joint: each joint's inertia and force work together, as Table 7.1 has them
    builder.place = None
    builder.arrange(start)
    return ForwardDynamics(builder.freeze(), tuple(qdd), tuple(D), inward, tuple(plan))


def _backward_inertias(builder, tree) -> _Inertias:
    """Pass 2, inertias (Pinocchio's AbaBackwardStep without the forces): U, D
    and Ia of every joint, leaves first, each Ia added into the parent's IA.
    They do not depend on where the c go."""
    joints = tree.joints
    count = len(joints)
    IA = [_rigid_inertia(builder, body) for body in tree.inertias]
    U, D, nUd, Ia = [None] * count, [None] * count, [None] * count, [None] * count
    multi: dict = {}
    for i in reversed(range(count)):
        joint = joints[i]
        builder.place = inward_place(count, i)
        if len(joint.dofs) > 1:
            multi[i] = _multi_dof_inertia(builder, joint, IA[i],
                                          [_armature(tree, k) for k, _ in joint.dofs])
            Ia[i] = multi[i].Ia
        else:
            S = joint.S
            # with an armature (rotor inertia) D = S^T U + armature, and the exact
            # shortcuts below (S^T U = D, so Ia S = 0) no longer hold
            armature = _armature(tree, joint.coordinate)
            j = _single(S) if armature == 0 else None
            U[i] = name_vec(builder, inertia_times(IA[i], S))
            D[i] = builder.name(dot(S, U[i]) + armature)
            invD = builder.name(1 / D[i])
            # -U/D is named with its sign, so that Ia, pa and qdd are sums of
            # products; for a one-entry S its entry j is exactly -1/S_j (U_j = D / S_j)
            nUd[i] = tuple(-1 / S[r] if r == j else
                           named(builder, -x * invD) if not is_zero(x) else ZERO
                           for r, x in enumerate(U[i]))
            if joint.parent >= 0:
                A, B, C = IA[i]
                blocks = (_rank_one(A, U[i], nUd[i], 0, 0), _rank_one(B, U[i], nUd[i], 0, 3),
                          _rank_one(C, U[i], nUd[i], 3, 3))
                A, B, C = _drop_subspace(blocks, S) if armature == 0 else blocks
                Ia[i] = (name_symmetric(builder, A), name_matrix(builder, B),
                         name_symmetric(builder, C))
        if joint.parent >= 0:
            p = joint.parent
            Ip = to_parent_inertia(builder, joint, Ia[i])
            IA[p] = tuple(name_matrix(builder, tuple(tuple(total((X[r][s], Y[r][s]))
                                                           for s in range(3)) for r in range(3)))
                          for X, Y in zip(IA[p], Ip, strict=True))
    return _Inertias(U, D, nUd, Ia, multi)


def _rank_one(M, U, nUd, r0, s0) -> tuple:
    """The 3x3 block at (r0, s0) of ``IA - U U^T / D``, ``M`` that block of IA."""
    return tuple(tuple(total((M[r][s], times(U[r0 + r], nUd[s0 + s]))) for s in range(3))
                 for r in range(3))


def _forward_bias(builder, tree, qd, plan, velocities, external) -> tuple:
    """Pass 1, accelerations and forces (Pinocchio's AbaForwardStep1): ``(pA, c)``,
    the bias forces less the actions, and the c that passes 2 and 3 use.

    Where c goes outwards the bias force carries ``I a_vp`` and c is 0 in
    passes 2 and 3; gravity is the ground's acceleration in pass 3 either way.
    """
    outward = outward_pass(builder, tree, qd, plan, velocities)
    pA = list(outward.f)
    c = tuple((ZERO,) * 6 if plan[i] else outward.c[i] for i in range(len(tree.joints)))
    for i, f in external.items():
        builder.place = outward_place(i)
        pA[i] = name_vec(builder, sub(pA[i], f))
    return pA, c


def _backward_forces(builder, tree, inertias, pA, c, tau) -> list:
    """Pass 2, forces (the rest of Pinocchio's AbaBackwardStep): ``u_i / D_i``
    of every one-dof joint, leaves first, each ``pa`` added into the parent's
    ``pA`` (which this updates)."""
    joints = tree.joints
    count = len(joints)
    uD = [None] * count
    for i in reversed(range(count)):
        joint = joints[i]
        builder.place = inward_place(count, i)
        if i in inertias.multi:
            pa = inertias.multi[i].forces(builder, joint, pA[i], c[i], tau)
        else:
            S = joint.S
            j = _single(S) if _armature(tree, joint.coordinate) == 0 else None
            tau_i = tau[joint.coordinate]
            uD[i] = named(builder, (tau_i - dot(S, pA[i])) * builder.name(1 / inertias.D[i]))
            if joint.parent < 0:
                continue
            # pa = pA + Ia c + U u/D; with a one-entry S, S^T pa = tau exactly
            # (Ia S = 0 and S^T U = D), so entry j is tau / S_j
            pa = add(add(pA[i], inertia_times(inertias.Ia[i], c[i])),
                     tuple(times(x, uD[i]) for x in inertias.U[i]))
            pa = name_vec(builder, [tau_i / S[r] if r == j else x for r, x in enumerate(pa)])
        if joint.parent >= 0:
            p = joint.parent
            pA[p] = name_vec(builder, add(pA[p], to_parent_force(builder, joint, pa)))
    return uD


def _forward_accelerations(builder, tree, inertias, uD, c, a0, n) -> list:
    """Pass 3 (Pinocchio's AbaForwardStep2): ``qdd`` in coordinate order, from
    ``a'_i = X_i a_p + c_i``, ``qdd_i = (u_i - U_i^T a'_i) / D_i``."""
    qdd = [None] * n
    acc = [None] * len(tree.joints)
    for i, joint in enumerate(tree.joints):
        builder.place = (2, i)
        ap = a0 if joint.parent < 0 else acc[joint.parent]
        a_prime = name_vec(builder, add(joint_motion(builder, joint, ap), c[i]))
        if i in inertias.multi:
            acc[i] = inertias.multi[i].outward(builder, joint, a_prime, qdd)
            continue
        k = joint.coordinate
        nUd = inertias.nUd[i]
        j = _single(joint.S) if _armature(tree, k) == 0 else None
        if j is not None and joint.S[j] == 1:
            # entry j of -U/D is -1: a_j = a'_j + qdd = u/D + the other terms, named
            # once, and qdd = a_j - a'_j
            # named as it stands (not by named): qdd = rest - a'_j is then one
            # subtraction, where a negated name would make it -(name) - a'_j
            rest = builder.name(total([uD[i]] + [times(x, y) for r, (x, y) in
                                                 enumerate(zip(nUd, a_prime, strict=True))
                                                 if r != j]))
            qdd[k] = builder.name(total((rest, neg(a_prime[j]))))
            acc[i] = tuple(rest if r == j else x for r, x in enumerate(a_prime))
        else:
            qdd[k] = builder.name(total((uD[i], dot(nUd, a_prime))))
            acc[i] = name_vec(builder, add(a_prime, tuple(times(s, qdd[k]) for s in joint.S)))
    return qdd


def _inward_cost(Ia, c) -> int:
    """Operations ``c`` costs where it goes inwards: ``Ia c`` added into ``pa``,
    and ``+ c`` in pass 3."""
    rows = inertia_times(Ia, c)
    return sum(operation_count(x) + 1 for x in rows if not is_zero(x)) + \
        sum(1 for x in c if not is_zero(x))


def _rigid_inertia(builder, body) -> tuple:
    """A link's rigid inertia as blocks (A, B, C) at its origin."""
    m = builder.name(body.m)
    h = name_vec(builder, body.h)
    return (symmetric(name_vec(builder, body.I)), skew(h),
            ((m, ZERO, ZERO), (ZERO, m, ZERO), (ZERO, ZERO, m)))


# -- ball and free joints: several degrees of freedom (Featherstone Table 7.1 with
# S a 6 x k matrix; here the columns of the identity, so U = IA S picks columns) ---

@dataclass
class _MultiDofInertia:
    """A ball or free joint's pass-2 inertias, and (after :meth:`forces`) its ``u``."""
    U: tuple          # k columns, 6 entries each
    Dinv: tuple       # k x k, (S^T U)^-1, symmetric
    pivots: tuple     # the k pivots of the LDL^T of D: all > 0 iff D is positive definite
    UD: tuple         # U D^-1, k columns
    Ia: tuple         # articulated inertia passed to the parent (blocks)
    u: tuple = ()     # tau - S^T pA (k)

    def forces(self, builder, joint, pA, c, tau) -> tuple:
        """``pa = pA + Ia c + U D^-1 u`` (and ``u``, kept for the outward pass)."""
        k = len(joint.dofs)
        self.u = tuple(builder.name(tau[idx] - dot(col, pA)) for idx, col in joint.dofs)
        Du = [builder.name(total(times(self.Dinv[a][b], self.u[b]) for b in range(k)))
              for a in range(k)]
        return builder.vec(add(add(pA, inertia_times(self.Ia, c)),
                               tuple(total(times(self.U[a][r], Du[a]) for a in range(k))
                                     for r in range(6))))

    def outward(self, builder, joint, a_prime, qdd) -> tuple:
        """qdd of the joint's speeds (written into ``qdd``) and the link acceleration."""
        k = len(joint.dofs)
        rhs = [builder.name(self.u[a] - dot(self.U[a], a_prime)) for a in range(k)]
        acc = a_prime
        for a, (idx, col) in enumerate(joint.dofs):
            qdd[idx] = builder.name(total(times(self.Dinv[a][b], rhs[b]) for b in range(k)))
            acc = add(acc, tuple(times(s, qdd[idx]) for s in col))
        return builder.vec(acc)


def _ldlt_inverse(builder, D) -> tuple:
    """(D^-1, pivots) of a symmetric k x k D by an unrolled LDL^T."""
    k = len(D)
    L = [[ZERO] * k for _ in range(k)]
    d = [None] * k
    for j in range(k):
        d[j] = builder.name(D[j][j] - total(times(times(L[j][m], L[j][m]), d[m]) for m in range(j)))
        inv = builder.name(1 / d[j])
        for i in range(j + 1, k):
            L[i][j] = builder.name((D[i][j] - total(times(times(L[i][m], L[j][m]), d[m])
                                                for m in range(j))) * inv)
    # columns of the inverse: solve L d L^T x = e_c
    cols = []
    for col in range(k):
        y = [None] * k
        for i in range(k):
            y[i] = builder.name((ONE if i == col else ZERO) - total(times(L[i][m], y[m])
                                                               for m in range(i)))
        x = [None] * k
        for i in reversed(range(k)):
            x[i] = builder.name(y[i] / d[i] - total(times(L[m][i], x[m]) for m in range(i + 1, k)))
        cols.append(x)
    inverse = tuple(tuple(cols[c][r] for c in range(k)) for r in range(k))
    return inverse, tuple(d)


def _multi_dof_inertia(builder, joint, IA, armature) -> _MultiDofInertia:
    """U, D^-1 and the inertia the parent receives, for a joint with k columns
    (``armature``: one per column, added to D's diagonal)."""
    S = [col for _, col in joint.dofs]
    k = len(S)
    U = [builder.vec(inertia_times(IA, col)) for col in S]
    D = [[builder.name(dot(S[a], U[b]) + (armature[a] if a == b else ZERO))
          for b in range(k)] for a in range(k)]
    Dinv, pivots = _ldlt_inverse(builder, D)
    # U D^-1 (6 x k)
    UD = [builder.vec(total(times(U[b][r], Dinv[b][a]) for b in range(k)) for r in range(6))
          for a in range(k)]
    A, B, C = IA

    def update(M, r0, s0):
        return tuple(tuple(total((M[r][s], neg(total(times(UD[a][r0 + r], U[a][s0 + s])
                                                         for a in range(k)))))
                           for s in range(3)) for r in range(3))
    Ia = (name_symmetric(builder, update(A, 0, 0)), name_matrix(builder, update(B, 0, 3)),
          name_symmetric(builder, update(C, 3, 3)))
    return _MultiDofInertia(tuple(U), Dinv, pivots, tuple(UD), Ia)


def derive_aba_jacobian(fd: ForwardDynamics, eqs: Equations) -> JacobianTerms:
    """d(qdd)/dx, x = [q, qd], by forward-mode differentiation of the ABA program.

    Unlike the CRBA Jacobian there is nothing to solve: ``D`` is the lower half
    of the state Jacobian itself (``a`` is empty).
    """
    extra = eqs.qdot if eqs.has_joints else ()
    graph, rows = differentiate(fd.graph, tuple(fd.qdd) + tuple(extra), eqs.q + eqs.qd)
    return JacobianTerms(graph, (), rows[:len(fd.qdd)], rows[len(fd.qdd):])
