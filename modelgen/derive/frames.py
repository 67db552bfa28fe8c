"""Frame kinematics for control: poses, velocities, Jacobians, bias accelerations,
the centre of mass and the centroidal momentum matrix.

Everything is read off :mod:`modelgen.derive.kinematics`: a frame F is a point P
and a base B, so its rotation is ``R_B``, its origin ``r_P``, its velocity
``(v_P, omega_B)`` and the columns of its Jacobian the partial velocities
``(b_k^P, c_k^B)`` with respect to the speeds (for ball and free joints these
are the tangent-space coordinates: a free joint's linear velocity and angular
velocity in its own base, Pinocchio's free-flyer convention).

Conventions are Pinocchio's (``ReferenceFrame``), rows linear first, then
angular:

* ``local_world_aligned``: ``[v_P; omega]`` in E's axes, at P;
* ``world``: the velocity of the body-fixed point at O, ``[v_P - omega x r_P;
  omega]``, in E's axes;
* ``local``: ``[R^T v_P; R^T omega]``, in F's axes.

The bias acceleration is the classical acceleration of F's origin with every
speed derivative zero (Pinocchio's ``getFrameClassicalAcceleration`` after
``forwardKinematics(q, v, 0)``): ``[a_P; alpha_B]`` with q_ddot = 0 in
``local_world_aligned``, where it is exactly J_dot v; rotated by R^T in
``local``; in ``world``, the classical acceleration of the body-fixed point at
O, ``a_P - alpha x r_P - omega x (omega x r_P)``.

The centre of mass is ``c = sum m_i r_Gi / M``, its Jacobian ``sum m_i b_k^Gi /
M`` (E's axes), and the centroidal momentum matrix ``A_g`` (6 x nv) maps the
speeds to the momentum about c in E's axes, linear rows first (Pinocchio's
``computeCentroidalMap``): ``[sum m_i b_k^Gi; sum m_i (r_Gi - c) x b_k^Gi +
R_i I_i R_i^T c_k^Bi]``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import sympy

from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.kinematics import Kinematics
from modelgen.derive.spatial import (
    ZERO,
    ZERO3,
    add,
    cross,
    matmul,
    matvec,
    scale,
    sub,
    total,
    transpose,
)


@dataclass(frozen=True)
class FrameTerms:
    """Output of :func:`derive_frames`: flat, row-major expressions per routine.

    ``poses``: 16 per frame (the 4x4 ``[[R, r], [0, 0, 0, 1]]``); ``velocities``
    and ``bias``: 6 per frame; ``jacobians``: 6 * nv per frame; ``com``: 3;
    ``com_jacobian``: 3 * nv; ``centroidal``: 6 * nv.  Empty when not asked.
    """
    frames: tuple
    reference: str
    poses: tuple
    velocities: tuple
    jacobians: tuple
    bias: tuple
    com: tuple
    com_jacobian: tuple
    centroidal: tuple
    graph: Graph = field(repr=False)


def _rows(builder, reference, R, r, linear, angular):
    """``(linear, angular)`` at P in E's axes, in ``reference``'s (see the module)."""
    if reference == "local":
        Rt = transpose(R)
        return builder.vec(matvec(Rt, linear)), builder.vec(matvec(Rt, angular))
    if reference == "world":
        return builder.vec(sub(linear, cross(angular, r))), angular
    return linear, angular


def _frame(builder, kin: Kinematics, frame, reference: str, n: int, bias: bool):
    base, point = kin.bases[frame.base], kin.points[frame.point]
    R, r = base.R, point.r
    pose = tuple(x for i in range(3) for x in (*R[i], r[i])) + (ZERO, ZERO, ZERO, sympy.S.One)
    velocity = _rows(builder, reference, R, r, point.v, base.omega)
    columns = [_rows(builder, reference, R, r, kin.point_partial(frame.point, k),
                     base.partials.get(k, ZERO3)) for k in range(n)]
    jacobian = tuple(columns[k][0][i] for i in range(3) for k in range(n)) + \
        tuple(columns[k][1][i] for i in range(3) for k in range(n))
    accel = ()
    if bias:
        a, alpha = point.a_bias, base.alpha_bias
        if reference == "world":
            wr = cross(base.omega, r)
            a = builder.vec(sub(sub(a, cross(alpha, r)), cross(base.omega, wr)))
            alpha = builder.vec(alpha)
        else:
            a, alpha = _rows(builder, reference, R, r, builder.vec(a), builder.vec(alpha))
        accel = (*a, *alpha)
    return pose, (*velocity[0], *velocity[1]), jacobian, accel


class _Composite:
    """Sums of the bodies' (mass, first moment m r_G, inertia about O in E) over
    sets of bodies, memoised: a set is built from the largest known subsets, so
    the nested subtrees of a chain cost one addition each (CRBA's composites)."""

    def __init__(self, builder, items: dict):
        self.builder = builder
        self.items = items          # body index -> (m, h, I_O rows)
        self.memo: dict = {}

    def plus(self, a, b):
        name, vec = self.builder.name, self.builder.vec
        return (name(a[0] + b[0]), vec(add(a[1], b[1])),
                tuple(vec(add(ra, rb)) for ra, rb in zip(a[2], b[2], strict=True)))

    def __call__(self, bodies: frozenset):
        if bodies not in self.memo:
            remaining, out = set(bodies), None
            for known in sorted((s for s in self.memo if s < bodies),
                                key=lambda s: (-len(s), sorted(s))):
                if known <= remaining:
                    out = self.memo[known] if out is None else self.plus(out, self.memo[known])
                    remaining -= known
            for i in sorted(remaining):
                out = self.items[i] if out is None else self.plus(out, self.items[i])
            self.memo[bodies] = out
        return self.memo[bodies]


def _about_O(builder, kin: Kinematics, body):
    """(m, m r_G, I_O): the body's inertia about O in E's axes,
    ``R I R^T + m (|r|^2 1 - r r^T)``."""
    R, r, m = kin.bases[body.base].R, kin.points[body.G].r, body.mass
    I_E = matmul(matmul(R, body.inertia), transpose(R))
    rr = [[r[i] * r[j] for j in range(3)] for i in range(3)]
    r2 = rr[0][0] + rr[1][1] + rr[2][2]
    rows = tuple(builder.vec(I_E[i][j] + m * ((r2 if i == j else 0) - rr[i][j])
                             for j in range(3)) for i in range(3))
    return builder.name(m), builder.vec(scale(m, r)), rows


def _mass_terms(builder, kin: Kinematics, n: int, centroidal: bool):
    """(M, c, columns of sum m_i b_k^Gi, columns of the angular momentum about O).

    Column k groups the bodies that column k moves as one rigid body: those with
    the same twist (c_k, beta_k) at O (angular partial velocity and the partial
    velocity of the body-fixed point at O; the kinematics names them once along a
    chain).  A group with composite (M, h, I_O) has the momentum ``(M beta + c x
    h, h x beta + I_O c)``; a body whose centre's partial has another angular part
    (its G given in another base) is summed alone."""
    spec = kin.spec
    massive = [i for i, b in enumerate(spec.bodies) if b.mass != 0]
    mass = builder.name(total([spec.bodies[i].mass for i in massive]))
    first = builder.vec(total([scale(spec.bodies[i].mass, kin.points[spec.bodies[i].G].r)[j]
                               for i in massive]) for j in range(3))
    c = builder.vec(scale(1 / mass, first))
    items = {}
    composite = _Composite(builder, items)
    groups = []
    for k in range(n):
        by_twist, alone = {}, []
        for i, b in enumerate(spec.bodies):
            if b.mass == 0 and not any(x != 0 for row in b.inertia for x in row):
                continue
            ck = kin.bases[b.base].partials.get(k, ZERO3)
            w, beta = kin.points[b.G].partials.get(k, (ZERO3, ZERO3))
            if w == ck:
                if ck != ZERO3 or beta != ZERO3:
                    by_twist.setdefault((ck, beta), []).append(i)
            else:
                alone.append(i)
        groups.append((sorted(by_twist.items(), key=lambda g: g[1]), alone))
    for i in sorted({i for g, alone in groups for _, members in g for i in members}
                    | {i for _, alone in groups for i in alone}):
        items[i] = _about_O(builder, kin, spec.bodies[i])
    sets = {frozenset(members) for g, _ in groups for _, members in g}
    for s in sorted(sets, key=lambda s: (len(s), sorted(s))):
        composite(s)          # smallest first, so the larger reuse them
    linear, angular = [], []
    for k, (by_twist, alone) in enumerate(groups):
        lin = ang = ZERO3
        for (ck, beta), members in by_twist:
            M, h, I_O = composite(frozenset(members))
            lin = add(lin, add(scale(M, beta), cross(ck, h)))
            if centroidal:
                ang = add(ang, add(cross(h, beta), matvec(I_O, ck)))
        for i in alone:
            b = spec.bodies[i]
            mb = builder.vec(scale(b.mass, kin.point_partial(b.G, k)))
            lin = add(lin, mb)
            if centroidal:
                R = kin.bases[b.base].R
                I_E = matmul(matmul(R, b.inertia), transpose(R))
                ang = add(ang, add(cross(kin.points[b.G].r, mb),
                                   matvec(I_E, kin.bases[b.base].partials.get(k, ZERO3))))
        linear.append(builder.vec(lin))
        angular.append(builder.vec(ang))
    return mass, c, linear, angular


def derive_frames(kin: Kinematics, graph: Graph, frames: tuple, reference: str,
                  bias: bool, com: bool, centroidal: bool) -> FrameTerms:
    """The frame quantities asked for, built on ``graph`` (so they share its names).

    ``frames`` are :class:`~modelgen.model.spec.FrameSpec`; ``reference`` one of
    ``local``, ``world``, ``local_world_aligned`` (see the module).

    >>> from modelgen.model.api import Model
    >>> from modelgen.derive.kinematics import derive_kinematics
    >>> m = Model("m").add_coordinate("q").add_base("B", parent="E", axis=3, angle="q")
    >>> m = m.add_point("P", parent="O", base="B", coordinates=[1, 0, 0])
    >>> m = m.add_frame("F", point="P", base="B").add_body("b", mass=1, G="P", base="B")
    >>> spec = m.spec(); kin = derive_kinematics(spec)
    >>> t = derive_frames(kin, kin.graph, spec.frames, "local", False, True, False)
    >>> [sympy.simplify(t.graph.expand(e)) for e in t.jacobians]     # 6 x 1, LOCAL
    [0, 1, 0, 0, 0, 1]
    """
    builder = GraphBuilder(graph)
    n = len(kin.qd)
    parts = [_frame(builder, kin, f, reference, n, bias) for f in frames]
    poses = tuple(x for p in parts for x in p[0])
    velocities = tuple(x for p in parts for x in p[1])
    jacobians = tuple(x for p in parts for x in p[2])
    accels = tuple(x for p in parts for x in p[3])
    com_terms, com_jac, cmm = (), (), ()
    if com or centroidal:
        mass, c, linear, angular = _mass_terms(builder, kin, n, centroidal)
        if com:
            com_terms = c
            inv = builder.name(1 / mass)
            com_jac = tuple(builder.name(inv * linear[k][i]) for i in range(3)
                            for k in range(n))
        if centroidal:
            # about c: L_G = L_O - c x (M v_c), column by column
            about_c = [builder.vec(sub(angular[k], cross(c, linear[k]))) for k in range(n)]
            cmm = tuple(linear[k][i] for i in range(3) for k in range(n)) + \
                tuple(about_c[k][i] for i in range(3) for k in range(n))
    return FrameTerms(tuple(f.name for f in frames), reference, poses, velocities, jacobians,
                      accels, com_terms, com_jac, cmm, builder.freeze())
