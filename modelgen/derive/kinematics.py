"""Kinematics stage: frames, points, velocities and partial velocities.

Every quantity is built recursively from its parent and named (see
:mod:`modelgen.derive.graph`), so the cost is linear in the size of the tree instead
of exponential.  All vectors are in components of the canonical base E.

For base B obtained from parent P by angle theta about P's axis e:

* ``R_B = R_P @ Rot(axis, theta)``  (columns of R_B: B's unit vectors in E)
* ``omega_B = omega_P + theta_dot * e``
* ``alpha_B = alpha_P + theta_ddot * e + theta_dot * (omega_P x e)``
* partial angular velocity ``c_k^B = c_k^P + d(theta)/d(q_k) * e``

For point P at coordinates c (in base B) from point Q, with d = R_B c:

* ``r_P = r_Q + d``
* ``v_P = v_Q + omega_B x d + R_B c_dot``
* ``a_P = a_Q + alpha_B x d + omega_B x (omega_B x d) + 2 omega_B x R_B c_dot + R_B c_ddot``

Accelerations are kept as *bias* accelerations: the part that remains when
every q_ddot is zero.  The full acceleration is ``sum_k b_k q_ddot_k + bias``.

Partial velocities of points are stored in a screw-like form: for coordinate
k, ``b_k^P = beta_k^P + w_k^P x r_P``.  Along a chain of points fixed in the
same moving base, ``w`` and ``beta`` are *the same named symbols* from body to
body, which lets the dynamics stage recognise bodies that move together and
sum their inertias once (composite rigid body grouping).
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.calculus import diff
from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.spatial import (IDENTITY3, ZERO, ZERO3, add, cross, is_zero_vec, matvec,
                                     rotation, scale, sub, transpose)
from modelgen.errors import ModelError
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, TIME, ModelSpec, symbol

@dataclass(frozen=True)
class BaseKinematics:
    R: tuple            # 3x3 rows; columns are the base's unit vectors in E
    omega: tuple        # angular velocity wrt E, in E
    alpha_bias: tuple   # angular acceleration with all q_ddot = 0, in E
    partials: dict      # k -> c_k (partial angular velocity, in E)


@dataclass(frozen=True)
class PointKinematics:
    r: tuple            # position from O, in E
    v: tuple            # velocity wrt E, in E
    a_bias: tuple       # acceleration with all q_ddot = 0, in E
    partials: dict      # k -> (w_k, beta_k) with b_k = beta_k + w_k x r


@dataclass(frozen=True)
class Kinematics:
    """Output of :func:`derive_kinematics`."""
    spec: ModelSpec
    graph: Graph
    q: tuple            # coordinate symbols
    qd: tuple           # speed symbols
    bases: dict         # name -> BaseKinematics
    points: dict        # name -> PointKinematics

    def point_partial(self, point: str, k: int) -> tuple:
        """Partial velocity b_k of a point (components in E)."""
        pk = self.points[point]
        if k not in pk.partials:
            return ZERO3
        w, beta = pk.partials[k]
        return add(beta, cross(w, pk.r))


def quaternion_columns(quaternion):
    """Child unit vectors in parent components for a unit quaternion (w, x, y, z).

    The matrix with these columns is the usual R(q) (Shuster's passive
    convention transposed): ``v_parent = R v_child``.
    """
    w, x, y, z = quaternion
    return ((1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)),
            (2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)),
            (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)))


def _column(R, j):
    return (R[0][j], R[1][j], R[2][j])


class _Deriver:
    """Time derivatives of user expressions f(q, t) along the motion."""

    def __init__(self, q, qd):
        self.q = q
        self.qd = qd

    def gradient(self, expr):
        """{k: df/dq_k} for the coordinates f depends on."""
        free = expr.free_symbols
        return {k: diff(expr, qk) for k, qk in enumerate(self.q) if qk in free}

    def rate(self, expr, grad=None):
        """df/dt = sum_k df/dq_k * qd_k + df/dt (explicit)."""
        grad = self.gradient(expr) if grad is None else grad
        total = sympy.Add(*[dk * self.qd[k] for k, dk in grad.items()])
        if expr.has(TIME):
            total += diff(expr, TIME)
        return total

    def bias_rate(self, expr_dot):
        """d/dt of an expression in (q, qd, t) with every qdd set to zero."""
        total = sympy.Add(*[diff(expr_dot, qk) * self.qd[k]
                            for k, qk in enumerate(self.q) if qk in expr_dot.free_symbols])
        if expr_dot.has(TIME):
            total += diff(expr_dot, TIME)
        return total


def _reject_explicit_time(spec: ModelSpec) -> None:
    """Prescribed motion (t in an angle or a point) is not supported yet.

    A(q), h(q, qd), the energy and the poses are generated without a time
    argument, so kinematics must be scleronomic.  Drive such a motion with a
    coordinate and an action instead.
    """
    items = [(f"bases.{b.name}.angle", (b.angle,)) for b in spec.bases]
    items += [(f"points.{p.name}.coordinates", p.coordinates) for p in spec.points]
    for key, exprs in items:
        if any(getattr(e, "has", lambda *_: False)(TIME) for e in exprs):
            raise ModelError(
                "time 't' in a base angle or point position (prescribed motion) is not "
                "supported: A(q), h(q, qd), energy and poses take no time argument",
                file=spec.source, line=spec.line_of(key), key=key,
                fix="make the motion a generalized coordinate and drive it with an action")


def derive_kinematics(spec: ModelSpec, graph: Graph | None = None) -> Kinematics:
    """Build the kinematics of every base and point of ``spec``.

    >>> from modelgen.model.spec import ModelSpec, BaseSpec, symbol
    >>> spec = ModelSpec("m", coordinates=("q1",),
    ...                  bases=(BaseSpec("B1", "E", 3, symbol("q1")),))
    >>> kin = derive_kinematics(spec)
    >>> kin.bases["B1"].omega
    (0, 0, q1_dot)
    """
    _reject_explicit_time(spec)
    builder = GraphBuilder(graph)
    q = tuple(symbol(c) for c in spec.coordinates)
    qd = tuple(symbol(s) for s in spec.speeds)
    simple = len(spec.simple_coordinates)
    d = _Deriver(q[:simple], qd[:simple])
    speed_index = {v: k for k, v in enumerate(qd)}

    bases = {CANONICAL_BASE: BaseKinematics(IDENTITY3, ZERO3, ZERO3, {})}
    for b in spec.bases:
        parent = bases[b.parent]
        if b.quaternion:
            bases[b.name] = _quaternion_base(builder, parent, b, speed_index)
            continue
        theta = b.angle
        c, s = builder.name(sympy.cos(theta)), builder.name(sympy.sin(theta))
        local = rotation(b.axis, c, s)        # rows: the base's unit vectors
        cols = [builder.vec(matvec(parent.R, col)) for col in local]
        R = transpose(cols)
        e = _column(parent.R, b.axis - 1)
        grad = d.gradient(theta)
        theta_dot = builder.name(d.rate(theta, grad))
        omega = builder.vec(add(parent.omega, scale(theta_dot, e)))
        theta_ddot = builder.name(d.bias_rate(d.rate(theta, grad)))
        alpha = builder.vec(add(add(parent.alpha_bias, scale(theta_ddot, e)),
                                scale(theta_dot, builder.vec(cross(parent.omega, e)))))
        partials = dict(parent.partials)
        for k, dk in grad.items():
            dk = builder.name(dk)
            partials[k] = builder.vec(add(partials.get(k, ZERO3), scale(dk, e)))
        bases[b.name] = BaseKinematics(R, omega, alpha, partials)

    points = {CANONICAL_POINT: PointKinematics(ZERO3, ZERO3, ZERO3, {})}
    for p in spec.points:
        Q = points[p.parent]
        B = bases[p.base]
        dvec = builder.vec(matvec(B.R, p.coordinates))
        r = builder.vec(add(Q.r, dvec))
        w_x_d = builder.vec(cross(B.omega, dvec))
        v = add(Q.v, w_x_d)
        a = add(add(Q.a_bias, cross(B.alpha_bias, dvec)), cross(B.omega, w_x_d))
        grads = [{}, {}, {}] if p.speeds else [d.gradient(ci) for ci in p.coordinates]
        moving = any(grads) or any(ci.has(TIME) for ci in p.coordinates)
        if p.speeds:   # a free joint: d/dt (R_B c) relative to B = R_J v
            J = bases[p.speed_base]
            rel_v = builder.vec(matvec(J.R, p.speeds))
            v = add(v, rel_v)
            a = add(a, cross(add(B.omega, J.omega), rel_v))
        elif moving:   # coordinates that change in time (prismatic-like)
            cdot = tuple(d.rate(ci, gi) for ci, gi in zip(p.coordinates, grads, strict=True))
            rel_v = builder.vec(matvec(B.R, builder.vec(cdot)))
            cddot = builder.vec(d.bias_rate(x) for x in cdot)
            v = add(v, rel_v)
            a = add(add(a, scale(2, cross(B.omega, rel_v))), matvec(B.R, cddot))
        v = builder.vec(v)
        a = builder.vec(a)

        partials = {}
        if p.speeds:
            J = bases[p.speed_base]
            for j, speed in enumerate(p.speeds):
                partials[speed_index[speed]] = (ZERO3, _column(J.R, j))
        for k in sorted(set(Q.partials) | set(B.partials) | {k for gi in grads for k in gi}):
            wQ, betaQ = Q.partials.get(k, (ZERO3, ZERO3))
            cB = B.partials.get(k, ZERO3)
            beta = betaQ
            if wQ != cB:
                beta = add(beta, cross(sub(wQ, cB), Q.r))
            dc = tuple(gi.get(k, ZERO) for gi in grads)
            if not is_zero_vec(dc):
                beta = add(beta, matvec(B.R, dc))
            beta = builder.vec(beta)
            if is_zero_vec(beta) and is_zero_vec(cB):
                continue
            partials[k] = (cB, beta)
        points[p.name] = PointKinematics(r, v, a, partials)

    return Kinematics(spec, builder.freeze(), q, qd, bases, points)


def _quaternion_base(builder: GraphBuilder, parent: BaseKinematics, b, speed_index: dict):
    """A joint's base: turned by a unit quaternion, turning at ``b.rates`` (in itself).

    ``omega_B = omega_P + R_B w``; with every speed derivative zero,
    ``d/dt (R_B w) = omega_B x R_B w = omega_P x R_B w``.
    """
    local = quaternion_columns(b.quaternion)
    cols = [builder.vec(matvec(parent.R, tuple(builder.name(x) for x in col))) for col in local]
    R = transpose(cols)
    rel = builder.vec(matvec(R, b.rates))
    omega = builder.vec(add(parent.omega, rel))
    alpha = builder.vec(add(parent.alpha_bias, cross(parent.omega, rel)))
    partials = dict(parent.partials)
    for j, rate in enumerate(b.rates):
        partials[speed_index[rate]] = cols[j]
    return BaseKinematics(R, omega, alpha, partials)
