"""The link-frame recursions that the articulated-body algorithm and RNEA share.

Featherstone, *Rigid Body Dynamics Algorithms* (2008): each link's quantities
are in its own frame (:mod:`modelgen.derive.joint_tree` gives the links and
their joints), and a pass goes over the joints outwards (parents first) or
inwards (leaves first).  Here:

* the joint transforms ``X_i = X_J X_T`` (parent -> link): a motion outwards
  (:func:`joint_motion`), a force (:func:`to_parent_force`) and an inertia
  (:func:`to_parent_inertia`) inwards;
* a link's rigid-body force ``I a + v x* I v`` (:func:`link_force`), at the
  centre of mass when that needs no division by a mass;
* pass 1 of both algorithms (Table 5.1): the link velocities and
  velocity-product accelerations (:func:`link_velocities`), and the
  accelerations at zero q_ddot and link forces (:func:`outward_pass`);
* the actions of a model as spatial forces on their links
  (:func:`action_force`).

:mod:`modelgen.derive.aba` and :mod:`modelgen.derive.rnea` both build on one
:class:`~modelgen.derive.graph.GraphBuilder`, which hash-conses: what the two
compute alike (the outward pass) is one set of statements.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.graph import GraphBuilder
from modelgen.derive.joint_tree import JointTree
from modelgen.derive.kinematics import quaternion_columns
from modelgen.derive.spatial import (PAIRS, ZERO, ZERO3, add, axis_rot_T, cross, cross_motion,
                                     elementary, force_rot_T, force_xlt_T, inertia_rot_T,
                                     inertia_times, inertia_xlt_T, is_identity, is_zero, matvec,
                                     motion_rot, motion_xlt, name_symmetric, name_vec, named,
                                     rotation,
                                     signed, skew, sub, symmetric, times, total, transpose)
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT


# -- joint transforms: X_i = X_J X_T, parent -> link -----------------------------

def quaternion_rotation(builder, quaternion) -> tuple:
    """E = R(quat)^T of a ball or free joint's base: parent -> child components
    (the rows of E are the columns of R)."""
    return tuple(tuple(builder.name(x) for x in col) for col in quaternion_columns(quaternion))


def joint_motion(builder, joint, m):
    """X_i m for the parent->link transform X_i = X_J X_T."""
    E, r = joint.fixed
    if any(x != 0 for x in r):
        m = motion_xlt(builder, r, m)
    if not is_identity(E):
        m = motion_rot(builder, E, m)
    if joint.kind in ("ball", "free"):
        if joint.position:
            m = motion_xlt(builder, joint.position, m)
        m = motion_rot(builder, quaternion_rotation(builder, joint.quaternion), m)
    elif joint.kind == "revolute":
        c, s = builder.name(sympy.cos(joint.angle)), builder.name(sympy.sin(joint.angle))
        m = motion_rot(builder, rotation(joint.axis, c, s), m)
    else:
        m = motion_xlt(builder, name_vec(builder, joint.offset), m)
    return m


def to_parent_force(builder, joint, f):
    """X_i^T f."""
    E, r = joint.fixed
    if joint.kind in ("ball", "free"):
        f = force_rot_T(builder, quaternion_rotation(builder, joint.quaternion), f)
        if joint.position:
            f = force_xlt_T(builder, joint.position, f)
    elif joint.kind == "revolute":
        c, s = builder.name(sympy.cos(joint.angle)), builder.name(sympy.sin(joint.angle))
        f = force_rot_T(builder, rotation(joint.axis, c, s), f)
    else:
        f = force_xlt_T(builder, name_vec(builder, joint.offset), f)
    if not is_identity(E):
        f = force_rot_T(builder, E, f)
    if any(x != 0 for x in r):
        f = force_xlt_T(builder, r, f)
    return f


def to_parent_inertia(builder, joint, I):
    """X_i^T I X_i."""
    E, r = joint.fixed
    if joint.kind in ("ball", "free"):
        I = inertia_rot_T(builder, quaternion_rotation(builder, joint.quaternion), I)
        if joint.position:
            I = inertia_xlt_T(builder, joint.position, I)
    elif joint.kind == "revolute":
        c, s = builder.name(sympy.cos(joint.angle)), builder.name(sympy.sin(joint.angle))
        I = axis_rot_T(builder, I, joint.axis, c, s)
    else:
        I = inertia_xlt_T(builder, name_vec(builder, joint.offset), I)
    if not is_identity(E):
        # a constant rotation about one base axis (a URDF rpy with one angle)
        # turns the inertia like a joint does; any other goes through E^T I E
        simple = elementary(E)
        I = (axis_rot_T(builder, I, simple[0], builder.name(simple[1]), builder.name(simple[2]))
             if simple
             else inertia_rot_T(builder, E, I))
    if any(x != 0 for x in r):
        I = inertia_xlt_T(builder, r, I)
    return I


# -- a link's rigid-body force -----------------------------------------------------

def link_force(builder, body, v, a):
    """``I a + v x* I v`` for a link's rigid body at its origin."""
    A = symmetric(name_vec(builder, body.I))
    h = name_vec(builder, body.h)
    m = builder.name(body.m)
    centre = _centre(body.h, body.m)
    if centre is None:
        return _rigid_force(builder, A, h, m, v, a)
    return _com_force(builder, symmetric(body.I), h, body.m, centre, v, a)


def _rigid_force(builder, I_O, h, m, v, a):
    """I a + v x* (I v) for a rigid body (I_O about the origin, first moment h, mass m).

    ``I v = (I_O w + h x vl, m vl - h x w)``; the term ``vl x (m vl)`` of
    ``v x* (I v)`` vanishes, so ``v x* (I v) = (w x n - vl x k, w x f)`` with
    ``k = h x w``.
    """
    w, vl = v[:3], v[3:]
    n = name_vec(builder, add(matvec(I_O, w), cross(h, vl)))
    k = name_vec(builder, cross(h, w))
    f = name_vec(builder, sub(tuple(times(m, x) for x in vl), k))
    bias = sub(cross(w, n), cross(vl, k)) + cross(w, f)
    I = (I_O, skew(h), ((m, ZERO, ZERO), (ZERO, m, ZERO), (ZERO, ZERO, m)))
    return name_vec(builder, add(bias, inertia_times(I, a)))


def _centre(h, m):
    """The centre of mass h / m, if it has no division by a mass (a parameter
    that may be 0 at run time), else None."""
    if is_zero(m):
        return None
    c = tuple(_quotient(x, m) if not is_zero(x) else ZERO for x in h)
    if any(p.exp.is_negative for x in c if not is_zero(x) for p in x.atoms(sympy.Pow)):
        return None
    return c


def _quotient(x, m):
    """``cancel(x / m)``; when the division already cancelled to a sum of
    monomials with rational coefficients (``h = m c`` as the spec writes it),
    that sum, which is what ``cancel`` returns for it, without converting it
    to a polynomial in every parameter it names."""
    q = x / m
    return q if _expanded_polynomial(q) else sympy.cancel(q)


def _expanded_polynomial(x) -> bool:
    """Whether ``x`` is a sum of products of rationals, symbols and their
    positive integer powers."""
    for term in sympy.Add.make_args(x):
        for factor in sympy.Mul.make_args(term):
            if factor.is_Pow:
                if not (factor.base.is_Symbol and factor.exp.is_Integer
                        and factor.exp > 0):
                    return False
            elif not (factor.is_Symbol or factor.is_Rational):
                return False
    return True


def _com_force(builder, I_O, h, m, c, v, a):
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
    cn = tuple(ZERO if is_zero(x) else builder.factor(x) for x in c)
    vc = name_vec(builder, add(vl, cross(w, cn)))
    e = name_vec(builder, add(add(al, cross(wd, cn)), cross(w, vc)))
    f = name_vec(builder, [times(m, x) for x in e])
    # c x f costs one product per term when c is numeric, h x e otherwise
    moment = cross(cn, f) if all(x.is_Number for x in c) else cross(h, e)
    Ic = name_symmetric(builder, symmetric(entries))
    spin = add(_gyroscopic(builder, entries, w), matvec(Ic, wd))
    return name_vec(builder, add(spin, moment)) + f


def _gyroscopic(builder, entries, w) -> tuple:
    """``w x (Ic w)`` for Ic given by its entries (xx, yy, zz, xy, xz, yz).

    A diagonal Ic (principal axes along the link's, as for most bodies) gives
    component k as ``(I_{k+2} - I_{k+1}) w_{k+1} w_{k+2}``: 3 products and 3
    multiplications by parameter differences, not 3 + 9 operations; a
    difference that is exactly 0 (a body symmetric about axis k, such as a
    rod or a disc) drops the component, where ``w_y (I w_z) - w_z (I w_y)``
    would be computed and come out 0.
    """
    if any(not is_zero(x) for x in entries[3:]):
        Ic = name_symmetric(builder, symmetric(entries))
        return cross(w, name_vec(builder, matvec(Ic, w)))
    out = []
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        d = sympy.expand(entries[k2] - entries[k1])
        # one name for d and -d
        d = signed(builder.name, d)
        out.append(ZERO if is_zero(d) else times(d, times(w[k1], w[k2])))
    return tuple(out)


# -- pass 1: velocities, velocity-product accelerations, forces -------------------

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


def joint_velocity(builder, joint, qd) -> tuple:
    """``S_i qd_i``: the joint's motion subspace times its speeds (or accelerations)."""
    return name_vec(builder, [total(times(S[r], qd[k]) for k, S in joint.dofs) for r in range(6)])


def outward_place(i):
    """The place (GraphBuilder.place) of joint i's work in pass 1."""
    return (0, i)


def inward_place(count, i):
    """The place of joint i's work in pass 2 (leaves first)."""
    return (1, count - 1 - i)


def link_velocities(builder: GraphBuilder, tree: JointTree, qd) -> tuple:
    """``(v, c)``: every link's velocity ``v_i = X_i v_p + S_i qd_i`` and
    velocity-product acceleration ``c_i = v_i x S_i qd_i``."""
    count = len(tree.joints)
    v, c = [None] * count, [None] * count
    for i, joint in enumerate(tree.joints):
        builder.place = outward_place(i)
        vJ = joint_velocity(builder, joint, qd)
        p = joint.parent
        if p < 0:
            v[i], c[i] = vJ, (ZERO,) * 6
        else:
            v[i] = name_vec(builder, add(joint_motion(builder, joint, v[p]), vJ))
            c[i] = name_vec(builder, cross_motion(v[i], vJ))
    return tuple(v), tuple(c)


def outward_pass(builder: GraphBuilder, tree: JointTree, qd, plan=None, velocities=None) -> Outward:
    """Velocities, velocity-product accelerations and forces of every link.

    ``plan[i]`` says whether joint i's ``c`` goes outwards (default: every
    one, as RNEA needs); ``velocities`` is :func:`link_velocities`' result if
    the caller has it already.  Built in ``builder``: a second call with the
    same ``builder`` returns the same symbols (the graph hash-conses), so ABA and RNEA
    share what they have in common.
    """
    count = len(tree.joints)
    plan = (True,) * count if plan is None else plan
    v, c = velocities or link_velocities(builder, tree, qd)
    a, f = [None] * count, [None] * count
    nothing = (ZERO,) * 6
    for i, joint in enumerate(tree.joints):
        builder.place = outward_place(i)
        p = joint.parent
        if plan[i]:
            a[i] = (name_vec(builder, add(joint_motion(builder, joint, a[p]), c[i]))
                    if p >= 0 and plan[p]
                    else c[i])
        f[i] = link_force(builder, tree.inertias[i], v[i], a[i] if plan[i] else nothing)
    return Outward(v, c, tuple(a), tuple(f))


# -- actions: external forces in link frames --------------------------------------

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


def _rotate_into(builder, spec, v, X: str, L: str) -> tuple:
    """Components in base L of the vector with components ``v`` in base X."""
    if all(x == 0 for x in v):
        return ZERO3
    bases = {b.name: b for b in spec.bases}
    up, down = _base_steps(spec, X, L)
    v = tuple(v)
    for name in up:                  # child -> parent components: E^T v
        v = name_vec(builder, matvec(transpose(_base_rotation(builder, bases[name])), v))
    for name in down:                # parent -> child components: E v
        v = name_vec(builder, matvec(_base_rotation(builder, bases[name]), v))
    return v


def _base_rotation(builder, b) -> tuple:
    """E of a base: parent -> base components."""
    if b.quaternion:
        return quaternion_rotation(builder, b.quaternion)
    return rotation(b.axis, builder.name(sympy.cos(b.angle)), builder.name(sympy.sin(b.angle)))


def _point_offset(builder, spec, P: str, Q: str, L: str) -> tuple:
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
        seg = _rotate_into(builder, spec, points[name].coordinates, points[name].base, L)
        total = add(total, tuple(times(sign, x) for x in seg))
    return name_vec(builder, total)


def action_force(builder, spec, joint, act) -> tuple:
    """An action as a spatial force on its link, at the link origin, in link components."""
    L = joint.base
    T = _rotate_into(builder, spec, act.torque, act.base, L)
    F = _rotate_into(builder, spec, act.force, act.base, L)
    if any(x != 0 for x in F):
        point, correction = joint.origin
        r = name_vec(builder, sub(_point_offset(builder, spec, act.point, point, L), correction))
        T = name_vec(builder, add(T, cross(r, F)))
    return T + F


def ground_acceleration(eqs_spec) -> tuple:
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


def link_loads(builder, eqs, tree, spec) -> tuple:
    """``(a0, tau, external)``: the ground's acceleration (gravity in E), the
    generalized forces of the other effects, and the actions as spatial forces
    on their links ({joint index: force})."""
    n = len(eqs.qd)
    a0, gravity_labels = ground_acceleration(spec)
    actions = list(spec.actions) + [e for e in spec.effects if e.kind == "action"]
    local = set(gravity_labels) | {a.name for a in actions}
    others = [part for label, part in eqs.tau_parts if label not in local]
    tau = [named(builder, sympy.Add(*[part[k] for part in others])) for k in range(n)]
    link_of = dict(tree.body_links)
    external: dict = {}
    for act in actions:
        i = link_of[act.body]
        if i >= 0:
            f = action_force(builder, spec, tree.joints[i], act)
            external[i] = name_vec(builder, add(external[i], f)) if i in external else f
    return a0, tau, external
