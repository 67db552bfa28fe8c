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
from modelgen.derive.graph import (ONE, ZERO, ZERO3, Graph, GraphBuilder, free_symbols,
                                   operation_count, product)
from modelgen.derive.jacobian import JacobianTerms, differentiate
from modelgen.derive.joint_tree import JointTree
from modelgen.derive.kinematics import quaternion_columns
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, ModelSpec

_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


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


# -- arithmetic that skips constant zeros and ones before sympy sees them --------
# (most entries of S, of the joint rotations and of the first inertias are 0 or 1;
# building 0*x and x + 0 through sympy costs more than the whole rest)

def _zero(x) -> bool:
    if x is ZERO:
        return True
    if isinstance(x, int):
        return x == 0
    return x.is_Number and x.is_zero


def _one(x) -> bool:
    return x is ONE or (isinstance(x, int) and x == 1)


def _times(x, y):
    if _zero(x) or _zero(y):
        return ZERO
    if _one(x):
        return y
    if _one(y):
        return x
    return product(x, y)


def _total(terms):
    terms = [t for t in terms if not _zero(t)]
    if not terms:
        return ZERO
    return terms[0] if len(terms) == 1 else sympy.Add(*terms)


def _neg(x):
    return ZERO if _zero(x) else -x


def dot(a, b):
    return _total(_times(x, y) for x, y in zip(a, b))


def add(a, b):
    return tuple(_total((x, y)) for x, y in zip(a, b))


def sub(a, b):
    return tuple(_total((x, _neg(y))) for x, y in zip(a, b))


def cross(a, b):
    return (_total((_times(a[1], b[2]), _neg(_times(a[2], b[1])))),
            _total((_times(a[2], b[0]), _neg(_times(a[0], b[2])))),
            _total((_times(a[0], b[1]), _neg(_times(a[1], b[0])))))


# -- naming with the sign left outside ------------------------------------------
# The operation count charges a negation (``a - b*c`` is three operations), so a
# quantity is named by its positive form and its sign stays in the expression
# that uses it, where two signs can cancel (``(-x)*(-y)``) before they are ever
# printed.

def _nm(g, e):
    """``g.name(e)``, with a negative numeric factor, or a sum of mostly negative
    terms, kept outside the name."""
    if isinstance(e, sympy.Mul) and e.args[0].is_Number and e.args[0].is_negative:
        return -g.name(-e)
    if isinstance(e, sympy.Add):
        negative = sum(1 for t in e.args if t.could_extract_minus_sign())
        if 2 * negative > len(e.args):
            return -g.name(-e)
    return g.name(e)


def _signed(namer, e):
    """``namer(e)`` with the sign sympy would extract kept outside, so that e
    and -e share one name."""
    return -namer(-e) if e.could_extract_minus_sign() else namer(e)


def _vec(g, xs) -> tuple:
    return tuple(_nm(g, x) for x in xs)


# -- 3x3 helpers: symmetric matrices as full tuples of rows ---------------------

def _sym(entries) -> tuple:
    """Full rows from the 6 entries (xx, yy, zz, xy, xz, yz)."""
    xx, yy, zz, xy, xz, yz = entries
    return ((xx, xy, xz), (xy, yy, yz), (xz, yz, zz))


def _name_sym(g, M) -> tuple:
    return _sym(_vec(g, [M[i][j] for i, j in _PAIRS]))


def _name_full(g, M) -> tuple:
    return tuple(_vec(g, row) for row in M)


def _mul(a, b) -> tuple:
    return tuple(tuple(_total(_times(a[i][l], b[l][j]) for l in range(3)) for j in range(3))
                 for i in range(3))


def _T(a) -> tuple:
    return tuple(tuple(a[j][i] for j in range(3)) for i in range(3))


def _mv(m, v) -> tuple:
    return tuple(dot(row, v) for row in m)


def _skew(r) -> tuple:
    return ((ZERO, -r[2], r[1]), (r[2], ZERO, -r[0]), (-r[1], r[0], ZERO))


def _is_identity(E) -> bool:
    return all(E[i][j] == (1 if i == j else 0) for i in range(3) for j in range(3))


# -- spatial algebra: motion (w, v), force (n, f), inertia (A, B, C) -----------

def _motion_rot(g, E, m):
    return _vec(g, _mv(E, m[:3])) + _vec(g, _mv(E, m[3:]))


def _motion_xlt(g, r, m):
    return m[:3] + _vec(g, sub(m[3:], cross(r, m[:3])))


def _force_rot_T(g, E, f):
    Et = _T(E)
    return _vec(g, _mv(Et, f[:3])) + _vec(g, _mv(Et, f[3:]))


def _force_xlt_T(g, r, f):
    return _vec(g, add(f[:3], cross(r, f[3:]))) + f[3:]


def _inertia_rot_T(g, E, I):
    """X^T I X for X = rot(E): each block B -> E^T B E."""
    Et = _T(E)
    A, B, C = I
    return (_name_sym(g, _mul(Et, _name_full(g, _mul(A, E)))),
            _name_full(g, _mul(Et, _name_full(g, _mul(B, E)))),
            _name_sym(g, _mul(Et, _name_full(g, _mul(C, E)))))


def _inertia_xlt_T(g, r, I):
    """X^T I X for X = xlt(r): A + rx B^T - B rx - rx C rx, B + rx C, C."""
    A, B, C = I
    rx = _skew(r)
    M = _name_full(g, _mul(rx, C))                # rx C
    N = _name_full(g, _mul(B, rx))                # B rx
    P = _mul(M, rx)                               # rx C rx (symmetric)
    # on the diagonal N_ii + N_ii = B (2 rx) _ii: one product by the parameter 2 r
    # (computed once per parameter set), where 2 * (B rx)_ii would be two
    rx2 = _skew(tuple(ZERO if _zero(x) else _signed(g.factor, 2 * x) for x in r))
    A2 = tuple(tuple(_total((A[i][j], _neg(dot(B[i], (rx2[0][i], rx2[1][i], rx2[2][i]))),
                             _neg(P[i][j]))) if i == j else
                     _total((A[i][j], _neg(N[i][j]), _neg(N[j][i]), _neg(P[i][j])))
                     for j in range(3)) for i in range(3))
    B2 = tuple(tuple(_total((B[i][j], M[i][j])) for j in range(3)) for i in range(3))
    return (_name_sym(g, A2), _name_full(g, B2), C)


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


def inertia_times(I, m):
    A, B, C = I
    w, v = m[:3], m[3:]
    return add(_mv(A, w), _mv(B, v)) + add(_mv(_T(B), w), _mv(C, v))


def _rigid_force(g, I_O, h, m, v, a):
    """I a + v x* (I v) for a rigid body (I_O about the origin, first moment h, mass m).

    ``I v = (I_O w + h x vl, m vl - h x w)``; the term ``vl x (m vl)`` of
    ``v x* (I v)`` vanishes, so ``v x* (I v) = (w x n - vl x k, w x f)`` with
    ``k = h x w``.
    """
    w, vl = v[:3], v[3:]
    n = _vec(g, add(_mv(I_O, w), cross(h, vl)))
    k = _vec(g, cross(h, w))
    f = _vec(g, sub(tuple(_times(m, x) for x in vl), k))
    bias = sub(cross(w, n), cross(vl, k)) + cross(w, f)
    I = (I_O, _skew(h), ((m, ZERO, ZERO), (ZERO, m, ZERO), (ZERO, ZERO, m)))
    return _vec(g, add(bias, inertia_times(I, a)))


def _centre(h, m):
    """The centre of mass h / m, if it has no division by a mass (a parameter
    that may be 0 at run time), else None."""
    if _zero(m):
        return None
    c = tuple(sympy.cancel(x / m) if not _zero(x) else ZERO for x in h)
    if any(p.exp.is_negative for x in c if not _zero(x) for p in x.atoms(sympy.Pow)):
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
    cc = _total(_times(x, x) for x in c)
    entries = tuple(sympy.expand(I_O[a_][b] - m * ((cc if a_ == b else 0) - c[a_] * c[b]))
                    for a_, b in _PAIRS)
    # a c such as l/2 named once (hoisted with the parameters): inline, each
    # product by it would be two
    cn = tuple(ZERO if _zero(x) else g.factor(x) for x in c)
    vc = _vec(g, add(vl, cross(w, cn)))
    e = _vec(g, add(add(al, cross(wd, cn)), cross(w, vc)))
    f = _vec(g, [_times(m, x) for x in e])
    # c x f costs one product per term when c is numeric, h x e otherwise
    moment = cross(cn, f) if all(x.is_Number for x in c) else cross(h, e)
    Ic = _name_sym(g, _sym(entries))
    spin = add(_gyroscopic(g, entries, w), _mv(Ic, wd))
    return _vec(g, add(spin, moment)) + f


def _gyroscopic(g, entries, w) -> tuple:
    """``w x (Ic w)`` for Ic given by its entries (xx, yy, zz, xy, xz, yz).

    A diagonal Ic (principal axes along the link's, as for most bodies) gives
    component k as ``(I_{k+2} - I_{k+1}) w_{k+1} w_{k+2}``: 3 products and 3
    multiplications by parameter differences, not 3 + 9 operations; a
    difference that is exactly 0 (a body symmetric about axis k, such as a
    rod or a disc) drops the component, where ``w_y (I w_z) - w_z (I w_y)``
    would be computed and come out 0.
    """
    if any(not _zero(x) for x in entries[3:]):
        Ic = _name_sym(g, _sym(entries))
        return cross(w, _vec(g, _mv(Ic, w)))
    out = []
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        d = sympy.expand(entries[k2] - entries[k1])
        # one name for d and -d
        d = _signed(g.name, d)
        out.append(ZERO if _zero(d) else _times(d, _times(w[k1], w[k2])))
    return tuple(out)


def _cross_motion(a, b):
    """a x b for motion vectors (Featherstone's crm)."""
    return cross(a[:3], b[:3]) + add(cross(a[:3], b[3:]), cross(a[3:], b[:3]))


def _cross_force(a, f):
    """a x* f for a motion a and a force f (Featherstone's crf)."""
    return add(cross(a[:3], f[:3]), cross(a[3:], f[3:])) + cross(a[:3], f[3:])


def _quaternion_rotation(g, quaternion) -> tuple:
    """E = R(quat)^T of a ball or free joint's base: parent -> child components
    (the rows of E are the columns of R)."""
    return tuple(tuple(g.name(x) for x in col) for col in quaternion_columns(quaternion))


def joint_motion(g, joint, m):
    """X_i m for the parent->link transform X_i = X_J X_T."""
    E, r = joint.fixed
    if any(x != 0 for x in r):
        m = _motion_xlt(g, r, m)
    if not _is_identity(E):
        m = _motion_rot(g, E, m)
    if joint.kind in ("ball", "free"):
        if joint.position:
            m = _motion_xlt(g, joint.position, m)
        m = _motion_rot(g, _quaternion_rotation(g, joint.quaternion), m)
    elif joint.kind == "revolute":
        c, s = g.name(sympy.cos(joint.angle)), g.name(sympy.sin(joint.angle))
        m = _motion_rot(g, _rotation(joint.axis, c, s), m)
    else:
        m = _motion_xlt(g, _vec(g, joint.offset), m)
    return m


def _rotation(axis, c, s):
    if axis == 1:
        return ((1, ZERO, ZERO), (ZERO, c, s), (ZERO, -s, c))
    if axis == 2:
        return ((c, ZERO, -s), (ZERO, 1, ZERO), (s, ZERO, c))
    return ((c, s, ZERO), (-s, c, ZERO), (ZERO, ZERO, 1))


def to_parent_force(g, joint, f):
    """X_i^T f."""
    E, r = joint.fixed
    if joint.kind in ("ball", "free"):
        f = _force_rot_T(g, _quaternion_rotation(g, joint.quaternion), f)
        if joint.position:
            f = _force_xlt_T(g, joint.position, f)
    elif joint.kind == "revolute":
        c, s = g.name(sympy.cos(joint.angle)), g.name(sympy.sin(joint.angle))
        f = _force_rot_T(g, _rotation(joint.axis, c, s), f)
    else:
        f = _force_xlt_T(g, _vec(g, joint.offset), f)
    if not _is_identity(E):
        f = _force_rot_T(g, E, f)
    if any(x != 0 for x in r):
        f = _force_xlt_T(g, r, f)
    return f


#: the plane (k1, k2) of a rotation about axis 1, 2, 3 in which E = [[c, s], [-s, c]]
_PLANE = {1: (1, 2), 2: (2, 0), 3: (0, 1)}


def _plane_rot_T(c, s, k1, k2, x1, x2):
    """(E^T x)[k1], (E^T x)[k2] for the plane rotation."""
    return (_total((_times(c, x1), _neg(_times(s, x2)))),
            _total((_times(s, x1), _times(c, x2))))


def _sym_axis_rot_T(g, M, k1, k2, c, s, trig):
    """E^T M E for a symmetric M and a rotation about one axis.

    With a, b, d the in-plane entries and ``t = s^2 (a - d) + 2cs b``:
    ``a' = a - t``, ``d' = d + t``, ``b' = cs (a - d) + (c^2 - s^2) b``
    (expand ``E^T M E`` and use ``c^2 + s^2 = 1``); the out-of-plane column
    turns like a vector.
    """
    ss, cs, C2, S2 = trig
    j = 3 - k1 - k2
    a, b, d = M[k1][k1], M[k1][k2], M[k2][k2]
    out = [[None] * 3 for _ in range(3)]
    diff = _nm(g, a - d)
    t = _nm(g, ss * diff + S2 * b)
    out[k1][k1], out[k2][k2] = a - t, d + t
    out[k1][k2] = cs * diff + C2 * b
    out[j][k1], out[j][k2] = _plane_rot_T(c, s, k1, k2, M[j][k1], M[j][k2])
    out[j][j] = M[j][j]
    return _name_sym(g, _sym_rows(out))


def _sym_rows(out):
    return tuple(tuple(out[i][j] if out[i][j] is not None else out[j][i] for j in range(3))
                 for i in range(3))


def _full_axis_rot_T(g, M, k1, k2, c, s, trig):
    """E^T M E for a general M and a rotation about one axis.

    The in-plane 2x2 block changes by its symmetric, trace-free part only:
    with ``d = m11 - m22``, ``e = m12 + m21``, ``t = s^2 d + cs e`` and
    ``w = cs d - s^2 e``: ``m11' = m11 - t``, ``m22' = m22 + t``,
    ``m12' = m12 + w``, ``m21' = m21 + w`` (8 operations, not 24); the
    out-of-plane row and column turn like vectors.
    """
    ss, cs = trig[0], trig[1]
    j = 3 - k1 - k2
    out = [[None] * 3 for _ in range(3)]
    d = _nm(g, M[k1][k1] - M[k2][k2])
    e = _nm(g, M[k1][k2] + M[k2][k1])
    t = _nm(g, _total((_times(ss, d), _times(cs, e))))
    w = _nm(g, _total((_times(cs, d), _neg(_times(ss, e)))))
    out[k1][k1], out[k2][k2] = _total((M[k1][k1], _neg(t))), _total((M[k2][k2], t))
    out[k1][k2], out[k2][k1] = _total((M[k1][k2], w)), _total((M[k2][k1], w))
    out[j][k1], out[j][k2] = _plane_rot_T(c, s, k1, k2, M[j][k1], M[j][k2])
    out[k1][j], out[k2][j] = _plane_rot_T(c, s, k1, k2, M[k1][j], M[k2][j])
    out[j][j] = M[j][j]
    return _name_full(g, out)


def _axis_rot_T(g, I, axis, c, s):
    """X^T I X for X = rot(E), E a rotation by (c, s) about one base axis."""
    ss, cs = g.name(s * s), g.name(c * s)
    trig = (ss, cs, g.name(1 - 2 * ss), g.name(2 * cs))
    k1, k2 = _PLANE[axis]
    A, B, C = I
    return (_sym_axis_rot_T(g, A, k1, k2, c, s, trig),
            _full_axis_rot_T(g, B, k1, k2, c, s, trig),
            _sym_axis_rot_T(g, C, k1, k2, c, s, trig))


def _elementary(E):
    """(axis, c, s) if the constant E is a rotation about one base axis (as
    :func:`_rotation` writes it), else None."""
    for axis, (k1, k2) in _PLANE.items():
        j = axis - 1
        if E[j][j] == 1 and all(E[j][k] == 0 and E[k][j] == 0 for k in (k1, k2)) \
                and E[k2][k2] == E[k1][k1] and E[k2][k1] == -E[k1][k2]:
            return axis, E[k1][k1], E[k1][k2]
    return None


def _to_parent_inertia(g, joint, I):
    """X_i^T I X_i."""
    E, r = joint.fixed
    if joint.kind in ("ball", "free"):
        I = _inertia_rot_T(g, _quaternion_rotation(g, joint.quaternion), I)
        if joint.position:
            I = _inertia_xlt_T(g, joint.position, I)
    elif joint.kind == "revolute":
        c, s = g.name(sympy.cos(joint.angle)), g.name(sympy.sin(joint.angle))
        I = _axis_rot_T(g, I, joint.axis, c, s)
    else:
        I = _inertia_xlt_T(g, _vec(g, joint.offset), I)
    if not _is_identity(E):
        # a constant rotation about one base axis (a URDF rpy with one angle)
        # turns the inertia like a joint does; any other goes through E^T I E
        simple = _elementary(E)
        I = (_axis_rot_T(g, I, simple[0], g.name(simple[1]), g.name(simple[2])) if simple
             else _inertia_rot_T(g, E, I))
    if any(x != 0 for x in r):
        I = _inertia_xlt_T(g, r, I)
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
        v = _vec(g, _mv(_T(_base_rotation(g, bases[name])), v))
    for name in down:                # parent -> child components: E v
        v = _vec(g, _mv(_base_rotation(g, bases[name]), v))
    return v


def _base_rotation(g, b) -> tuple:
    """E of a base: parent -> base components."""
    if b.quaternion:
        return _quaternion_rotation(g, b.quaternion)
    return _rotation(b.axis, g.name(sympy.cos(b.angle)), g.name(sympy.sin(b.angle)))


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
        total = add(total, tuple(_times(sign, x) for x in seg))
    return _vec(g, total)


def _action_force(g, spec, joint, act) -> tuple:
    """An action as a spatial force on its link, at the link origin, in link components."""
    L = joint.base
    T = _rotate_into(g, spec, act.torque, act.base, L)
    F = _rotate_into(g, spec, act.force, act.base, L)
    if any(x != 0 for x in F):
        point, correction = joint.origin
        r = _vec(g, sub(_point_offset(g, spec, act.point, point, L), correction))
        T = _vec(g, add(T, cross(r, F)))
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
    A = _sym(_vec(g, body.I))
    h = _vec(g, body.h)
    m = g.name(body.m)
    centre = _centre(body.h, body.m)
    if centre is None:
        return _rigid_force(g, A, h, m, v, a)
    return _com_force(g, _sym(body.I), h, body.m, centre, v, a)


def joint_velocity(g, joint, qd) -> tuple:
    """``S_i qd_i``: the joint's motion subspace times its speeds (or accelerations)."""
    return _vec(g, [_total(_times(S[r], qd[k]) for k, S in joint.dofs) for r in range(6)])


def _outwards(i):
    """The place (GraphBuilder.place) of joint i's work in pass 1."""
    return (0, i)


def _inwards(count, i):
    """The place of joint i's work in pass 2 (leaves first)."""
    return (1, count - 1 - i)


def link_velocities(g: GraphBuilder, tree: JointTree, qd) -> tuple:
    """``(v, c)``: every link's velocity ``v_i = X_i v_p + S_i qd_i`` and
    velocity-product acceleration ``c_i = v_i x S_i qd_i``."""
    count = len(tree.joints)
    v, c = [None] * count, [None] * count
    for i, joint in enumerate(tree.joints):
        g.place = _outwards(i)
        vJ = joint_velocity(g, joint, qd)
        p = joint.parent
        if p < 0:
            v[i], c[i] = vJ, (ZERO,) * 6
        else:
            v[i] = _vec(g, add(joint_motion(g, joint, v[p]), vJ))
            c[i] = _vec(g, _cross_motion(v[i], vJ))
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
        g.place = _outwards(i)
        p = joint.parent
        if plan[i]:
            a[i] = (_vec(g, add(joint_motion(g, joint, a[p]), c[i])) if p >= 0 and plan[p]
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
        return tuple(ZERO if _zero(x) else sympy.Symbol(f"{prefix}{r}")
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
    tau = [_nm(g, sympy.Add(*[part[k] for part in others])) for k in range(n)]
    link_of = dict(tree.body_links)
    external: dict = {}                 # joint index -> spatial force on its link
    for act in actions:
        i = link_of[act.body]
        if i >= 0:
            f = _action_force(g, spec, tree.joints[i], act)
            external[i] = _vec(g, add(external[i], f)) if i in external else f

    joints = tree.joints
    count = len(joints)
    velocities = link_velocities(g, tree, eqs.qd)
    # pass 2, inertias (they do not depend on where c goes): U, D, Ia of every joint
    IA = [_rigid_inertia(g, body) for body in tree.inertias]
    U, D, nUd, Ia = [None] * count, [None] * count, [None] * count, [None] * count
    multi: dict = {}                    # joint index -> _MultiDofInertia of a ball or free joint
    for i in reversed(range(count)):
        joint = joints[i]
        g.place = _inwards(count, i)
        if len(joint.dofs) > 1:
            multi[i] = _multi_dof_inertia(g, joint, IA[i])
            Ia[i] = multi[i].Ia
        else:
            S = joint.S
            j = _single(S)
            U[i] = _vec(g, inertia_times(IA[i], S))
            D[i] = g.name(dot(S, U[i]))
            invD = g.name(1 / D[i])
            # -U/D is named with its sign, so that Ia, pa and qdd are sums of
            # products; for a one-entry S its entry j is exactly -1/S_j (U_j = D / S_j)
            nUd[i] = tuple(-1 / S[r] if r == j else _nm(g, -x * invD) if not _zero(x) else ZERO
                           for r, x in enumerate(U[i]))
            if joint.parent >= 0:
                A, B, C = IA[i]

                def update(M, r0, s0):
                    return tuple(tuple(_total((M[r][s], _times(U[i][r0 + r], nUd[i][s0 + s])))
                                       for s in range(3)) for r in range(3))

                A, B, C = _drop_subspace((update(A, 0, 0), update(B, 0, 3), update(C, 3, 3)), S)
                Ia[i] = (_name_sym(g, A), _name_full(g, B), _name_sym(g, C))
        if joint.parent >= 0:
            p = joint.parent
            Ip = _to_parent_inertia(g, joint, Ia[i])
            IA[p] = tuple(_name_full(g, tuple(tuple(_total((X[r][s], Y[r][s])) for s in range(3))
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
        g.place = _outwards(i)
        pA[i] = _vec(g, sub(pA[i], f))

    uD = [None] * count
    for i in reversed(range(count)):                        # pass 2, forces
        joint = joints[i]
        g.place = _inwards(count, i)
        if i in multi:
            pa = multi[i].forces(g, joint, pA[i], c[i], tau)
        else:
            S = joint.S
            j = _single(S)
            tau_i = tau[joint.coordinate]
            uD[i] = _nm(g, (tau_i - dot(S, pA[i])) * g.name(1 / D[i]))
            if joint.parent < 0:
                continue
            # pa = pA + Ia c + U u/D; with a one-entry S, S^T pa = tau exactly
            # (Ia S = 0 and S^T U = D), so entry j is tau / S_j
            pa = add(add(pA[i], inertia_times(Ia[i], c[i])), tuple(_times(x, uD[i]) for x in U[i]))
            pa = _vec(g, [tau_i / S[r] if r == j else x for r, x in enumerate(pa)])
        if joint.parent >= 0:
            p = joint.parent
            pA[p] = _vec(g, add(pA[p], to_parent_force(g, joint, pa)))

    qdd = [None] * n
    acc = [None] * count
    for i, joint in enumerate(joints):                      # pass 3: outwards
        g.place = (2, i)
        ap = a0 if joint.parent < 0 else acc[joint.parent]
        a_prime = _vec(g, add(joint_motion(g, joint, ap), c[i]))
        if i in multi:
            acc[i] = multi[i].outward(g, joint, a_prime, qdd)
            continue
        k = joint.coordinate
        # (u - U^T a') / D
        j = _single(joint.S)
        if j is not None and joint.S[j] == 1:
            # entry j of -U/D is -1: a_j = a'_j + qdd = u/D + the other terms, named
            # once, and qdd = a_j - a'_j
            # named as it stands (not by _nm): qdd = rest - a'_j is then one
            # subtraction, where a negated name would make it -(name) - a'_j
            rest = g.name(_total([uD[i]] + [_times(x, y) for r, (x, y) in
                                            enumerate(zip(nUd[i], a_prime)) if r != j]))
            qdd[k] = g.name(_total((rest, _neg(a_prime[j]))))
            acc[i] = tuple(rest if r == j else x for r, x in enumerate(a_prime))
        else:
            qdd[k] = g.name(_total((uD[i], dot(nUd[i], a_prime))))
            acc[i] = _vec(g, add(a_prime, tuple(_times(s, qdd[k]) for s in joint.S)))
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
    return sum(operation_count(x) + 1 for x in rows if not _zero(x)) + \
        sum(1 for x in c if not _zero(x))


def _rigid_inertia(g, body) -> tuple:
    """A link's rigid inertia as blocks (A, B, C) at its origin."""
    m = g.name(body.m)
    h = _vec(g, body.h)
    return (_sym(_vec(g, body.I)), _skew(h), ((m, ZERO, ZERO), (ZERO, m, ZERO), (ZERO, ZERO, m)))


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
        Du = [g.name(_total(_times(self.Dinv[a][b], self.u[b]) for b in range(k)))
              for a in range(k)]
        return g.vec(add(add(pA, inertia_times(self.Ia, c)),
                         tuple(_total(_times(self.U[a][r], Du[a]) for a in range(k))
                               for r in range(6))))

    def outward(self, g, joint, a_prime, qdd) -> tuple:
        """qdd of the joint's speeds (written into ``qdd``) and the link acceleration."""
        k = len(joint.dofs)
        rhs = [g.name(self.u[a] - dot(self.U[a], a_prime)) for a in range(k)]
        acc = a_prime
        for a, (idx, col) in enumerate(joint.dofs):
            qdd[idx] = g.name(_total(_times(self.Dinv[a][b], rhs[b]) for b in range(k)))
            acc = add(acc, tuple(_times(s, qdd[idx]) for s in col))
        return g.vec(acc)


def _ldlt_inverse(g, D) -> tuple:
    """(D^-1, pivots) of a symmetric k x k D by an unrolled LDL^T."""
    k = len(D)
    L = [[ZERO] * k for _ in range(k)]
    d = [None] * k
    for j in range(k):
        d[j] = g.name(D[j][j] - _total(_times(_times(L[j][m], L[j][m]), d[m]) for m in range(j)))
        inv = g.name(1 / d[j])
        for i in range(j + 1, k):
            L[i][j] = g.name((D[i][j] - _total(_times(_times(L[i][m], L[j][m]), d[m])
                                                for m in range(j))) * inv)
    # columns of the inverse: solve L d L^T x = e_c
    cols = []
    for col in range(k):
        y = [None] * k
        for i in range(k):
            y[i] = g.name((ONE if i == col else ZERO) - _total(_times(L[i][m], y[m])
                                                               for m in range(i)))
        x = [None] * k
        for i in reversed(range(k)):
            x[i] = g.name(y[i] / d[i] - _total(_times(L[m][i], x[m]) for m in range(i + 1, k)))
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
    UD = [g.vec(_total(_times(U[b][r], Dinv[b][a]) for b in range(k)) for r in range(6))
          for a in range(k)]
    A, B, C = IA

    def update(M, r0, s0):
        return tuple(tuple(_total((M[r][s], _neg(_total(_times(UD[a][r0 + r], U[a][s0 + s])
                                                         for a in range(k)))))
                           for s in range(3)) for r in range(3))
    Ia = (_name_sym(g, update(A, 0, 0)), _name_full(g, update(B, 0, 3)),
          _name_sym(g, update(C, 3, 3)))
    return _MultiDofInertia(tuple(U), Dinv, pivots, tuple(UD), Ia)


def derive_aba_jacobian(fd: ForwardDynamics, eqs: Equations) -> JacobianTerms:
    """d(qdd)/dx, x = [q, qd], by forward-mode differentiation of the ABA program.

    Unlike the CRBA Jacobian there is nothing to solve: ``D`` is the lower half
    of the state Jacobian itself (``a`` is empty).
    """
    extra = eqs.qdot if eqs.has_joints else ()
    graph, rows = differentiate(fd.graph, tuple(fd.qdd) + tuple(extra), eqs.q + eqs.qd)
    return JacobianTerms(graph, (), rows[:len(fd.qdd)], rows[len(fd.qdd):])
