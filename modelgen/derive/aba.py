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
from modelgen.derive.kinematics import quaternion_columns
from modelgen.derive.spatial import (ONE, PAIRS, ZERO, ZERO3, add, axis_rot_T, cross, cross_motion,
                                     dot, elementary, force_rot_T, force_xlt_T, inertia_rot_T,
                                     inertia_times, inertia_xlt_T, is_identity, is_zero, matvec,
                                     motion_rot, motion_xlt, name_matrix, name_symmetric, name_vec,
                                     named, neg, rotation, signed, skew, sub, symmetric, times,
                                     total, transpose)
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, ModelSpec

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


def _single(S):
    """Index of the one non-zero entry of S, or None."""
    nonzero = [j for j, s in enumerate(S) if s != 0]
    return nonzero[0] if len(nonzero) == 1 else None


def _zero_row_col(M, j):
    return tuple(tuple(ZERO if j in (r, s) else M[r][s] for s in range(3)) for r in range(3))


def _rigid_force(g, I_O, h, m, v, a):
    """I a + v x* (I v) for a rigid body (I_O about the origin, first moment h, mass m).

    ``I v = (I_O w + h x vl, m vl - h x w)``; the term ``vl x (m vl)`` of
    ``v x* (I v)`` vanishes, so ``v x* (I v) = (w x n - vl x k, w x f)`` with
    ``k = h x w``.
    """
    w, vl = v[:3], v[3:]
    n = name_vec(g, add(matvec(I_O, w), cross(h, vl)))
    k = name_vec(g, cross(h, w))
    f = name_vec(g, sub(tuple(times(m, x) for x in vl), k))
    bias = sub(cross(w, n), cross(vl, k)) + cross(w, f)
    I = (I_O, skew(h), ((m, ZERO, ZERO), (ZERO, m, ZERO), (ZERO, ZERO, m)))
    return name_vec(g, add(bias, inertia_times(I, a)))


def _centre(h, m):
    """The centre of mass h / m, if it has no division by a mass (a parameter
    that may be 0 at run time), else None."""
    if is_zero(m):
        return None
    c = tuple(sympy.cancel(x / m) if not is_zero(x) else ZERO for x in h)
    if any(p.exp.is_negative for x in c if not is_zero(x) for p in x.atoms(sympy.Pow)):
        return None
    return c


def _com_force(g, I_O, h, m, c, v, a):
    """I a + v x* (I v) about the centre c: the Newton-Euler equations at c.

    The centre's acceleration (the part not due to q_ddot) is
    ``ac = al + wd x c + w x vc`` with ``vc = vl + w x c``; at the centre the
    force is ``(Ic wd + w x Ic w, m ac)`` with ``Ic = I_O - m (|c|^2 1 - c c^T)``
    (parameters only, and the ``m`` terms of ``I_O`` cancel exactly); moved to
    the origin the moment gains ``c x f`` (``= h x ac``).  Fewer products than
    :func:`_rigid_force`, whose ``I_O`` and ``h`` are both dense when the
    centre is off the axes.
    """
    w, vl = v[:3], v[3:]
    wd, al = a[:3], a[3:]
    cc = total(times(x, x) for x in c)
    entries = tuple(sympy.expand(I_O[a_][b] - m * ((cc if a_ == b else 0) - c[a_] * c[b]))
                    for a_, b in PAIRS)
    # a c such as l/2 named once (hoisted with the parameters): inline, each
    # product by it would be two
    cn = tuple(ZERO if is_zero(x) else g.factor(x) for x in c)
    vc = name_vec(g, add(vl, cross(w, cn)))
    e = name_vec(g, add(add(al, cross(wd, cn)), cross(w, vc)))
    f = name_vec(g, [times(m, x) for x in e])
    # c x f costs one product per term when c is numeric, h x e otherwise
    moment = cross(cn, f) if all(x.is_Number for x in c) else cross(h, e)
    Ic = name_symmetric(g, symmetric(entries))
    spin = add(_gyroscopic(g, entries, w), matvec(Ic, wd))
    return name_vec(g, add(spin, moment)) + f


def _gyroscopic(g, entries, w) -> tuple:
    """``w x (Ic w)`` for Ic given by its entries (xx, yy, zz, xy, xz, yz).

    A diagonal Ic (principal axes along the link's, as for most bodies) gives
    component k as ``(I_{k+2} - I_{k+1}) w_{k+1} w_{k+2}``: 3 products and 3
    multiplications by parameter differences, not 3 + 9 operations; a
    difference that is exactly 0 (a body symmetric about axis k, such as a
    rod or a disc) drops the component, where ``w_y (I w_z) - w_z (I w_y)``
    would be computed and come out 0.
    """
    if any(not is_zero(x) for x in entries[3:]):
        Ic = name_symmetric(g, symmetric(entries))
        return cross(w, name_vec(g, matvec(Ic, w)))
    out = []
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        d = sympy.expand(entries[k2] - entries[k1])
        # one name for d and -d
        d = signed(g.name, d)
        out.append(ZERO if is_zero(d) else times(d, times(w[k1], w[k2])))
    return tuple(out)


def quaternion_rotation(g, quaternion) -> tuple:
    """E = R(quat)^T of a ball or free joint's base: parent -> child components
    (the rows of E are the columns of R)."""
    return tuple(tuple(g.name(x) for x in col) for col in quaternion_columns(quaternion))


def joint_motion(g, joint, m):
    """X_i m for the parent->link transform X_i = X_J X_T."""
    E, r = joint.fixed
    if any(x != 0 for x in r):
        m = motion_xlt(g, r, m)
    if not is_identity(E):
        m = motion_rot(g, E, m)
    if joint.kind in ("ball", "free"):
        if joint.position:
            m = motion_xlt(g, joint.position, m)
        m = motion_rot(g, quaternion_rotation(g, joint.quaternion), m)
    elif joint.kind == "revolute":
        c, s = g.name(sympy.cos(joint.angle)), g.name(sympy.sin(joint.angle))
        m = motion_rot(g, rotation(joint.axis, c, s), m)
    else:
        m = motion_xlt(g, name_vec(g, joint.offset), m)
    return m


def to_parent_force(g, joint, f):
    """X_i^T f."""
    E, r = joint.fixed
    if joint.kind in ("ball", "free"):
        f = force_rot_T(g, quaternion_rotation(g, joint.quaternion), f)
        if joint.position:
            f = force_xlt_T(g, joint.position, f)
    elif joint.kind == "revolute":
        c, s = g.name(sympy.cos(joint.angle)), g.name(sympy.sin(joint.angle))
        f = force_rot_T(g, rotation(joint.axis, c, s), f)
    else:
        f = force_xlt_T(g, name_vec(g, joint.offset), f)
    if not is_identity(E):
        f = force_rot_T(g, E, f)
    if any(x != 0 for x in r):
        f = force_xlt_T(g, r, f)
    return f


def to_parent_inertia(g, joint, I):
    """X_i^T I X_i."""
    E, r = joint.fixed
    if joint.kind in ("ball", "free"):
        I = inertia_rot_T(g, quaternion_rotation(g, joint.quaternion), I)
        if joint.position:
            I = inertia_xlt_T(g, joint.position, I)
    elif joint.kind == "revolute":
        c, s = g.name(sympy.cos(joint.angle)), g.name(sympy.sin(joint.angle))
        I = axis_rot_T(g, I, joint.axis, c, s)
    else:
        I = inertia_xlt_T(g, name_vec(g, joint.offset), I)
    if not is_identity(E):
        # a constant rotation about one base axis (a URDF rpy with one angle)
        # turns the inertia like a joint does; any other goes through E^T I E
        simple = elementary(E)
        I = (axis_rot_T(g, I, simple[0], g.name(simple[1]), g.name(simple[2])) if simple
             else inertia_rot_T(g, E, I))
    if any(x != 0 for x in r):
        I = inertia_xlt_T(g, r, I)
    return I


def _base_steps(spec, X: str, L: str) -> tuple:
    """Bases from X up to (not including) the common ancestor with L, and from
    below that ancestor down to L."""
    parent = {b.name: b.parent for b in spec.bases}

    def chain(b):
        out = []
        while b != CANONICAL_BASE:
            out.append(b)
            b = parent[b]
        return out

    cx, cl = chain(X), chain(L)
    shared = set(cx) & set(cl)
    return [b for b in cx if b not in shared], [b for b in reversed(cl) if b not in shared]


def _rotate_into(g, spec, v, X: str, L: str) -> tuple:
    """Components in base L of the vector with components ``v`` in base X."""
    if all(x == 0 for x in v):
        return ZERO3
    bases = {b.name: b for b in spec.bases}
    up, down = _base_steps(spec, X, L)
    v = tuple(v)
    for name in up:                  # child -> parent components: E^T v
        v = name_vec(g, matvec(transpose(_base_rotation(g, bases[name])), v))
    for name in down:                # parent -> child components: E v
        v = name_vec(g, matvec(_base_rotation(g, bases[name]), v))
    return v


def _base_rotation(g, b) -> tuple:
    """E of a base: parent -> base components."""
    if b.quaternion:
        return quaternion_rotation(g, b.quaternion)
    return rotation(b.axis, g.name(sympy.cos(b.angle)), g.name(sympy.sin(b.angle)))


def _point_offset(g, spec, P: str, Q: str, L: str) -> tuple:
    """r_P - r_Q in components of base L."""
    points = {p.name: p for p in spec.points}

    def chain(p):
        out = []
        while p != CANONICAL_POINT:
            out.append(p)
            p = points[p].parent
        return out

    cp, cq = chain(P), chain(Q)
    shared = set(cp) & set(cq)
    total = ZERO3
    for name, sign in [(p, 1) for p in cp if p not in shared] + \
                      [(p, -1) for p in cq if p not in shared]:
        seg = _rotate_into(g, spec, points[name].coordinates, points[name].base, L)
        total = add(total, tuple(times(sign, x) for x in seg))
    return name_vec(g, total)


def _action_force(g, spec, joint, act) -> tuple:
    """An action as a spatial force on its link, at the link origin, in link components."""
    L = joint.base
    T = _rotate_into(g, spec, act.torque, act.base, L)
    F = _rotate_into(g, spec, act.force, act.base, L)
    if any(x != 0 for x in F):
        point, correction = joint.origin
        r = name_vec(g, sub(_point_offset(g, spec, act.point, point, L), correction))
        T = name_vec(g, add(T, cross(r, F)))
    return T + F


def _ground_acceleration(eqs_spec) -> tuple:
    """(-g as a spatial acceleration in E, labels of the tau parts it replaces)."""
    total = ZERO3
    labels = []
    if eqs_spec.gravity is not None:
        total = add(total, eqs_spec.gravity)
        labels.append("gravity")
    for eff in eqs_spec.effects:
        if eff.kind == "gravity" and eff.base == CANONICAL_BASE:
            total = add(total, eff.vector)
            labels.append(eff.name)
    return ZERO3 + tuple(-x for x in total), labels


@dataclass(frozen=True)
class Outward:
    """Pass 1 of ABA and RNEA (Featherstone Table 5.1), per joint, in link frames.

    ``v`` the link velocity, ``c = v x S qd`` the velocity-product
    acceleration; for a joint whose ``c`` goes outwards (``plan``), ``a`` the
    link acceleration at zero q_ddot (RNEA's a_vp: ``a_i = X_i a_p + c_i``,
    or ``c_i`` where the parent's goes inwards) and ``f = I a + v x* I v``;
    for the others ``a`` is None and ``f = v x* I v``.
    """
    v: tuple
    c: tuple
    a: tuple
    f: tuple


def link_force(g, body, v, a):
    """``I a + v x* I v`` for a link's rigid body at its origin."""
    A = symmetric(name_vec(g, body.I))
    h = name_vec(g, body.h)
    m = g.name(body.m)
    centre = _centre(body.h, body.m)
    if centre is None:
        return _rigid_force(g, A, h, m, v, a)
    return _com_force(g, symmetric(body.I), h, body.m, centre, v, a)


def joint_velocity(g, joint, qd) -> tuple:
    """``S_i qd_i``: the joint's motion subspace times its speeds (or accelerations)."""
    return name_vec(g, [total(times(S[r], qd[k]) for k, S in joint.dofs) for r in range(6)])


def outward_place(i):
    """The place (GraphBuilder.place) of joint i's work in pass 1."""
    return (0, i)


def inward_place(count, i):
    """The place of joint i's work in pass 2 (leaves first)."""
    return (1, count - 1 - i)


def link_velocities(g: GraphBuilder, tree: JointTree, qd) -> tuple:
    """``(v, c)``: every link's velocity ``v_i = X_i v_p + S_i qd_i`` and
    velocity-product acceleration ``c_i = v_i x S_i qd_i``."""
    count = len(tree.joints)
    v, c = [None] * count, [None] * count
    for i, joint in enumerate(tree.joints):
        g.place = outward_place(i)
        vJ = joint_velocity(g, joint, qd)
        p = joint.parent
        if p < 0:
            v[i], c[i] = vJ, (ZERO,) * 6
        else:
            v[i] = name_vec(g, add(joint_motion(g, joint, v[p]), vJ))
            c[i] = name_vec(g, cross_motion(v[i], vJ))
    return tuple(v), tuple(c)


def outward_pass(g: GraphBuilder, tree: JointTree, qd, plan=None, velocities=None) -> Outward:
    """Velocities, velocity-product accelerations and forces of every link.

    ``plan[i]`` says whether joint i's ``c`` goes outwards (default: every
    one, as RNEA needs); ``velocities`` is :func:`link_velocities`' result if
    the caller has it already.  Built in ``g``: a second call with the same
    ``g`` returns the same symbols (the graph hash-conses), so ABA and RNEA
    share what they have in common.
    """
    count = len(tree.joints)
    plan = (True,) * count if plan is None else plan
    v, c = velocities or link_velocities(g, tree, qd)
    a, f = [None] * count, [None] * count
    nothing = (ZERO,) * 6
    for i, joint in enumerate(tree.joints):
        g.place = outward_place(i)
        p = joint.parent
        if plan[i]:
            a[i] = (name_vec(g, add(joint_motion(g, joint, a[p]), c[i])) if p >= 0 and plan[p]
                    else c[i])
        f[i] = link_force(g, tree.inertias[i], v[i], a[i] if plan[i] else nothing)
    return Outward(v, c, tuple(a), tuple(f))


#: where the velocity-product accelerations c_i enter the ABA (:func:`derive_aba`)
VELOCITY_PRODUCTS = ("inward", "outward", "auto")


def _variable_operations(g: GraphBuilder, out, variables) -> int:
    """Operations of ``out``, built in ``g``, without the statements of the
    parameters alone (they are hoisted): what depends on ``variables``."""
    moving = set(variables)
    total = 0
    for sym, e in g.freeze().closure(out):
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
            g = GraphBuilder()
            forces[key] = _variable_operations(g, link_force(g, body, vs, a), set(vs) | set(a))
        return forces[key]

    def below(joint, shape, ap, cs):
        key = (shape, ap, cs)
        if key not in transforms:
            g = GraphBuilder()
            a = add(joint_motion(g, joint, ap), cs)
            transforms[key] = (_variable_operations(g, a, set(ap) | set(cs)), generic("mg_a", a))
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


def _derive_aba(eqs, tree, spec, graph, velocity_products) -> ForwardDynamics:
    g = GraphBuilder(graph or eqs.graph)
    start = len(g)
    n = len(eqs.qd)
    a0, gravity_labels = _ground_acceleration(spec)
    actions = list(spec.actions) + [e for e in spec.effects if e.kind == "action"]
    local = set(gravity_labels) | {a.name for a in actions}
    others = [part for label, part in eqs.tau_parts if label not in local]
    tau = [named(g, sympy.Add(*[part[k] for part in others])) for k in range(n)]
    link_of = dict(tree.body_links)
    external: dict = {}                 # joint index -> spatial force on its link
    for act in actions:
        i = link_of[act.body]
        if i >= 0:
            f = _action_force(g, spec, tree.joints[i], act)
            external[i] = name_vec(g, add(external[i], f)) if i in external else f

    joints = tree.joints
    count = len(joints)
    velocities = link_velocities(g, tree, eqs.qd)
    # pass 2, inertias (they do not depend on where c goes): U, D, Ia of every joint
    IA = [_rigid_inertia(g, body) for body in tree.inertias]
    U, D, nUd, Ia = [None] * count, [None] * count, [None] * count, [None] * count
    multi: dict = {}                    # joint index -> _MultiDofInertia of a ball or free joint
    for i in reversed(range(count)):
        joint = joints[i]
        g.place = inward_place(count, i)
        if len(joint.dofs) > 1:
            multi[i] = _multi_dof_inertia(g, joint, IA[i])
            Ia[i] = multi[i].Ia
        else:
            S = joint.S
            j = _single(S)
            U[i] = name_vec(g, inertia_times(IA[i], S))
            D[i] = g.name(dot(S, U[i]))
            invD = g.name(1 / D[i])
            # -U/D is named with its sign, so that Ia, pa and qdd are sums of
            # products; for a one-entry S its entry j is exactly -1/S_j (U_j = D / S_j)
            nUd[i] = tuple(-1 / S[r] if r == j else named(g, -x * invD) if not is_zero(x) else ZERO
                           for r, x in enumerate(U[i]))
            if joint.parent >= 0:
                A, B, C = IA[i]

                def update(M, r0, s0):
                    return tuple(tuple(total((M[r][s], times(U[i][r0 + r], nUd[i][s0 + s])))
                                       for s in range(3)) for r in range(3))

                A, B, C = _drop_subspace((update(A, 0, 0), update(B, 0, 3), update(C, 3, 3)), S)
                Ia[i] = (name_symmetric(g, A), name_matrix(g, B), name_symmetric(g, C))
        if joint.parent >= 0:
            p = joint.parent
            Ip = to_parent_inertia(g, joint, Ia[i])
            IA[p] = tuple(name_matrix(g, tuple(tuple(total((X[r][s], Y[r][s])) for s in range(3))
                                              for r in range(3)))
                          for X, Y in zip(IA[p], Ip))

    g.place = None
    if velocity_products == "auto":
        inward = [0 if joint.parent < 0 else _inward_cost(Ia[i], velocities[1][i])
                  for i, joint in enumerate(joints)]
        plan = velocity_product_plan(tree, velocities, inward)
    else:
        plan = tuple(velocity_products == "outward" and j.parent >= 0 for j in joints)
    # pass 1, accelerations and forces: where c goes outwards the bias force
    # carries I a_vp and c is 0 in passes 2 and 3; gravity is the ground's
    # acceleration in pass 3 either way
    outward = outward_pass(g, tree, eqs.qd, plan, velocities)
    pA = list(outward.f)
    c = tuple((ZERO,) * 6 if plan[i] else outward.c[i] for i in range(count))
    for i, f in external.items():
        g.place = outward_place(i)
        pA[i] = name_vec(g, sub(pA[i], f))

    uD = [None] * count
    for i in reversed(range(count)):                        # pass 2, forces
        joint = joints[i]
        g.place = inward_place(count, i)
        if i in multi:
            pa = multi[i].forces(g, joint, pA[i], c[i], tau)
        else:
            S = joint.S
            j = _single(S)
            tau_i = tau[joint.coordinate]
            uD[i] = named(g, (tau_i - dot(S, pA[i])) * g.name(1 / D[i]))
            if joint.parent < 0:
                continue
            # pa = pA + Ia c + U u/D; with a one-entry S, S^T pa = tau exactly
            # (Ia S = 0 and S^T U = D), so entry j is tau / S_j
            pa = add(add(pA[i], inertia_times(Ia[i], c[i])), tuple(times(x, uD[i]) for x in U[i]))
            pa = name_vec(g, [tau_i / S[r] if r == j else x for r, x in enumerate(pa)])
        if joint.parent >= 0:
            p = joint.parent
            pA[p] = name_vec(g, add(pA[p], to_parent_force(g, joint, pa)))

    qdd = [None] * n
    acc = [None] * count
    for i, joint in enumerate(joints):                      # pass 3: outwards
        g.place = (2, i)
        ap = a0 if joint.parent < 0 else acc[joint.parent]
        a_prime = name_vec(g, add(joint_motion(g, joint, ap), c[i]))
        if i in multi:
            acc[i] = multi[i].outward(g, joint, a_prime, qdd)
            continue
        k = joint.coordinate
        # (u - U^T a') / D
        j = _single(joint.S)
        if j is not None and joint.S[j] == 1:
            # entry j of -U/D is -1: a_j = a'_j + qdd = u/D + the other terms, named
            # once, and qdd = a_j - a'_j
            # named as it stands (not by named): qdd = rest - a'_j is then one
            # subtraction, where a negated name would make it -(name) - a'_j
            rest = g.name(total([uD[i]] + [times(x, y) for r, (x, y) in
                                            enumerate(zip(nUd[i], a_prime)) if r != j]))
            qdd[k] = g.name(total((rest, neg(a_prime[j]))))
            acc[i] = tuple(rest if r == j else x for r, x in enumerate(a_prime))
        else:
            qdd[k] = g.name(total((uD[i], dot(nUd[i], a_prime))))
            acc[i] = name_vec(g, add(a_prime, tuple(times(s, qdd[k]) for s in joint.S)))
    D_out = [None] * n
    for i, joint in enumerate(joints):
        if i in multi:
            for (k, _), d in zip(joint.dofs, multi[i].pivots):
                D_out[k] = d
        else:
            D_out[joint.coordinate] = D[i]
    inward = tuple(k for i in reversed(range(count)) for k, _ in joints[i].dofs)
    # built pass by pass (the plan needs every joint's inertia), written joint by
    # joint: each joint's inertia and force work together, as Table 7.1 has them
    g.place = None
    g.arrange(start)
    return ForwardDynamics(g.freeze(), tuple(qdd), tuple(D_out), inward, tuple(plan))


def _inward_cost(Ia, c) -> int:
    """Operations ``c`` costs where it goes inwards: ``Ia c`` added into ``pa``,
    and ``+ c`` in pass 3."""
    rows = inertia_times(Ia, c)
    return sum(operation_count(x) + 1 for x in rows if not is_zero(x)) + \
        sum(1 for x in c if not is_zero(x))


def _rigid_inertia(g, body) -> tuple:
    """A link's rigid inertia as blocks (A, B, C) at its origin."""
    m = g.name(body.m)
    h = name_vec(g, body.h)
    return (symmetric(name_vec(g, body.I)), skew(h), ((m, ZERO, ZERO), (ZERO, m, ZERO), (ZERO, ZERO, m)))


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

    def forces(self, g, joint, pA, c, tau) -> tuple:
        """``pa = pA + Ia c + U D^-1 u`` (and ``u``, kept for the outward pass)."""
        k = len(joint.dofs)
        self.u = tuple(g.name(tau[idx] - dot(col, pA)) for idx, col in joint.dofs)
        Du = [g.name(total(times(self.Dinv[a][b], self.u[b]) for b in range(k)))
              for a in range(k)]
        return g.vec(add(add(pA, inertia_times(self.Ia, c)),
                         tuple(total(times(self.U[a][r], Du[a]) for a in range(k))
                               for r in range(6))))

    def outward(self, g, joint, a_prime, qdd) -> tuple:
        """qdd of the joint's speeds (written into ``qdd``) and the link acceleration."""
        k = len(joint.dofs)
        rhs = [g.name(self.u[a] - dot(self.U[a], a_prime)) for a in range(k)]
        acc = a_prime
        for a, (idx, col) in enumerate(joint.dofs):
            qdd[idx] = g.name(total(times(self.Dinv[a][b], rhs[b]) for b in range(k)))
            acc = add(acc, tuple(times(s, qdd[idx]) for s in col))
        return g.vec(acc)


def _ldlt_inverse(g, D) -> tuple:
    """(D^-1, pivots) of a symmetric k x k D by an unrolled LDL^T."""
    k = len(D)
    L = [[ZERO] * k for _ in range(k)]
    d = [None] * k
    for j in range(k):
        d[j] = g.name(D[j][j] - total(times(times(L[j][m], L[j][m]), d[m]) for m in range(j)))
        inv = g.name(1 / d[j])
        for i in range(j + 1, k):
            L[i][j] = g.name((D[i][j] - total(times(times(L[i][m], L[j][m]), d[m])
                                                for m in range(j))) * inv)
    # columns of the inverse: solve L d L^T x = e_c
    cols = []
    for col in range(k):
        y = [None] * k
        for i in range(k):
            y[i] = g.name((ONE if i == col else ZERO) - total(times(L[i][m], y[m])
                                                               for m in range(i)))
        x = [None] * k
        for i in reversed(range(k)):
            x[i] = g.name(y[i] / d[i] - total(times(L[m][i], x[m]) for m in range(i + 1, k)))
        cols.append(x)
    inverse = tuple(tuple(cols[c][r] for c in range(k)) for r in range(k))
    return inverse, tuple(d)


def _multi_dof_inertia(g, joint, IA) -> _MultiDofInertia:
    """U, D^-1 and the inertia the parent receives, for a joint with k columns."""
    S = [col for _, col in joint.dofs]
    k = len(S)
    U = [g.vec(inertia_times(IA, col)) for col in S]
    D = [[g.name(dot(S[a], U[b])) for b in range(k)] for a in range(k)]
    Dinv, pivots = _ldlt_inverse(g, D)
    # U D^-1 (6 x k)
    UD = [g.vec(total(times(U[b][r], Dinv[b][a]) for b in range(k)) for r in range(6))
          for a in range(k)]
    A, B, C = IA

    def update(M, r0, s0):
        return tuple(tuple(total((M[r][s], neg(total(times(UD[a][r0 + r], U[a][s0 + s])
                                                         for a in range(k)))))
                           for s in range(3)) for r in range(3))
    Ia = (name_symmetric(g, update(A, 0, 0)), name_matrix(g, update(B, 0, 3)),
          name_symmetric(g, update(C, 3, 3)))
    return _MultiDofInertia(tuple(U), Dinv, pivots, tuple(UD), Ia)


def derive_aba_jacobian(fd: ForwardDynamics, eqs: Equations) -> JacobianTerms:
    """d(qdd)/dx, x = [q, qd], by forward-mode differentiation of the ABA program.

    Unlike the CRBA Jacobian there is nothing to solve: ``D`` is the lower half
    of the state Jacobian itself (``a`` is empty).
    """
    extra = eqs.qdot if eqs.has_joints else ()
    graph, rows = differentiate(fd.graph, tuple(fd.qdd) + tuple(extra), eqs.q + eqs.qd)
    return JacobianTerms(graph, (), rows[:len(fd.qdd)], rows[len(fd.qdd):])
