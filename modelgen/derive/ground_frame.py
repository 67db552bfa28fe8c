"""Spatial algebra in the ground frame E for the recursive derivatives
(:mod:`modelgen.derive.rnea_partials`) and their per-joint kernels
(:mod:`modelgen.derive.link_kernels`): motions and forces of a link moved to
E, a link's spatial inertia ``(I_O, h, m)`` about E's origin and its variation
``doY`` (Pinocchio's ``Inertia::variation``), as tuples of sympy expressions
built over a :class:`~modelgen.derive.graph.GraphBuilder`.
"""
from __future__ import annotations

from modelgen.derive.spatial import (PAIRS, ZERO, add, cross, dot, matmul, matvec, name_vec,
                                     named, skew, sub, symmetric, times, total, transpose)


def motion_to_ground(R, p, m):
    """A link's motion vector ``m`` (link components) in E: ``(R w, R v + p x R w)``."""
    w = matvec(R, m[:3])
    return tuple(w) + add(matvec(R, m[3:]), cross(p, w))


def force_cross(v, f):
    """``v x* f`` (Featherstone's crf)."""
    return add(cross(v[:3], f[:3]), cross(v[3:], f[3:])) + cross(v[:3], f[3:])


def inertia_times(Y, x) -> tuple:
    """``Y x`` for a spatial inertia ``Y = (I_O, h, m)``: ``(I_O w + h x v, m v - h x w)``."""
    I, h, m = Y
    w, v = x[:3], x[3:]
    return add(matvec(I, w), cross(h, v)) + sub(tuple(times(m, c) for c in v), cross(h, w))


def variation(builder, Y, v, oh) -> tuple:
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


def variation_times(dY, x) -> tuple:
    """``doY x`` for ``doY = (A, F)`` of :func:`variation`."""
    A, F = dY
    w = x[:3]
    return matvec(A, w) + tuple(times(-2, c) for c in cross(F, w))


def variation_T_times(dY, x) -> tuple:
    """The angular part of ``doY^T x`` (its linear part is 0): ``A^T w + 2 F x v``."""
    A, F = dY
    return add(matvec(transpose(A), x[:3]), tuple(times(2, c) for c in cross(F, x[3:])))


def rotated_inertia(builder, I, R, orthogonal: bool) -> tuple:
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


def ground_inertia(builder, body, R, p, orthogonal: bool) -> tuple:
    """The link's spatial inertia ``(I_O, h, m)`` about E's origin in E components.

    ``I_O = R I R^T - m p^ p^ - p^ hr^ - hr^ p^`` (``x^`` the cross-product matrix,
    ``hr = R h``), its translation part arranged around ``h_O = hr + m p``, the
    first moment about E's origin, which the link needs anyway: an off-diagonal
    entry ``(a, b)`` is ``(R I R^T)_ab - p_a h_O,b - hr_a p_b``, a diagonal one
    ``(R I R^T)_aa + t_b + t_c`` over the two other axes, ``t_b = p_b (h_O,b +
    hr_b)`` (that is ``m p_b^2 + 2 p_b hr_b``).  ``orthogonal``: see
    :func:`rotated_inertia`.
    """
    Ir = rotated_inertia(builder, name_vec(builder, body.I), R, orthogonal)
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


def sym6(Y) -> list:
    """The 6x6 rows of a rigid-body inertia ``(I_O, h, m)``."""
    I, h, m = Y
    hx = skew(h)
    return [list(I[r]) + list(hx[r]) for r in range(3)] + \
        [[-hx[r][c] if hx[r][c] != 0 else ZERO for c in range(3)]
         + [m if r == c else ZERO for c in range(3)] for r in range(3)]


def force_to_ground(R, p, f):
    """A link's force ``f`` (link components, at its origin) in E at E's origin:
    ``(R n + p x R f, R f)``."""
    F = matvec(R, f[3:])
    return add(matvec(R, f[:3]), cross(p, F)) + tuple(F)


# -- the steps the straight line and the kernels share ---------------------------------

def link_dynamics(builder, body, R, p, ov, oa, orthogonal: bool, load=None) -> tuple:
    """A link's ``(Y, of, doY)`` in E: its spatial inertia about E's origin
    (:func:`ground_inertia`), its RNEA force ``Y oa + ov x* Y ov`` less the
    force ``load`` of the actions fixed to it (link components, at its origin;
    None: no such actions), and the variation of Y (:func:`variation`)."""
    Y = ground_inertia(builder, body, R, p, orthogonal)
    oh = name_vec(builder, inertia_times(Y, ov))
    of = name_vec(builder, add(inertia_times(Y, oa), force_cross(ov, oh)))
    if load is not None:                # Q = RNEA's forces less the actions'
        of = name_vec(builder, sub(of, force_to_ground(R, p, load)))
    return Y, of, variation(builder, Y, ov, oh)


def dof_partials(builder, Y, dY, f, J, dAdq, dVdq, dAdv) -> tuple:
    """The inward vectors of one dof, ``(dFda, dYtJ, dFdq0, dFdq, dFdv)``, from the
    composite inertia ``Y``, variation ``dY`` and force ``f`` of the subtree at
    its joint and the dof's outward ones (``J``, ``dAdq``, ``dVdq``, ``dAdv``)."""
    dFda = name_vec(builder, inertia_times(Y, J))
    dFdq0 = name_vec(builder, add(variation_times(dY, dVdq), inertia_times(Y, dAdq)))
    dFdq = name_vec(builder, add(dFdq0, force_cross(J, f)))
    dFdv = name_vec(builder, add(variation_times(dY, J), inertia_times(Y, dAdv)))
    dYtJ = name_vec(builder, variation_T_times(dY, J))
    return dFda, dYtJ, dFdq0, dFdq, dFdv


__all__ = ["dof_partials", "force_cross", "force_to_ground", "ground_inertia", "inertia_times",
           "link_dynamics", "motion_to_ground", "rotated_inertia", "sym6", "variation",
           "variation_T_times", "variation_times"]
