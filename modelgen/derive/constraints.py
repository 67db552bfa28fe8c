"""Constraints: the position residuals f(q), the constraint Jacobian G(q) and the
velocity-product term gamma = dG/dt q_dot of a model's ``constraints:``.

Input: the :class:`~modelgen.derive.kinematics.Kinematics` of a spec with
constraints.  Output: :class:`ConstraintTerms`, named expressions in the
kinematics' graph.  Every constraint is written as the velocity constraint
``G(q) q_dot = 0`` (a position constraint through its time derivative
``df/dt = (df/dq) q_dot``), and its acceleration form
``G q_ddot + gamma = 0`` with ``gamma`` the part of ``d(G q_dot)/dt`` that
remains when every q_ddot is zero.  The rows are the holonomic equations
first (in declaration order; the first ``len(residuals)`` rows of G are
df/dq), then the nonholonomic ones.

Nothing is expanded: the rows are built from the kinematics' named positions,
partial velocities and bias accelerations (for a base D with unit vector
e_j, ``de_j/dq_k = c_k^D x e_j`` and ``de_j/dt = omega_D x e_j``), so a
bicycle's rows cost what its kinematics costs.

How the rhs uses them (the Kane form with dependent speeds, see
``docs/constraints.md``) is in the C template; :func:`check_constraints`
refuses redundant constraints and dependent speeds that cannot be solved
for, at seeded random configurations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy

from modelgen.derive.calculus import diff
from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.kinematics import Kinematics
from modelgen.derive.spatial import ZERO3, add, cross, dot, sub
from modelgen.errors import ModelError
from modelgen.model.spec import symbol

if TYPE_CHECKING:
    # imported by the functions that evaluate G, which only a constrained model
    # calls: an unconstrained model is generated without importing numpy
    import numpy as np

__all__ = [
    "RANK_SAMPLES",
    "ConstraintTerms",
    "check_constraints",
    "choose_dependent",
    "constraint_rows",
    "derive_constraints",
]

#: seeded random configurations at which redundancy and the dependent speeds are checked
RANK_SAMPLES = 3
#: draws tried for each of them until every constraint is real there (a square root,
#: logarithm or inverse sine of a coordinate is real on part of its range only); the
#: coordinates' range is pi times a power of two that changes every
#: :data:`DRAWS_PER_RANGE` draws (:data:`RANGE_EXPONENTS`), so narrow and wide
#: domains are both met
REAL_DRAWS = 100
DRAWS_PER_RANGE = 10
RANGE_EXPONENTS = (0, -1, 1, -2, 2, -3, 3, -4, 4, -5)


@dataclass(frozen=True)
class ConstraintTerms:
    """Output of :func:`derive_constraints`."""
    graph: Graph
    residuals: tuple        # m_h: f(q) of the holonomic equations
    G: tuple                # m rows of n: G(q) q_dot = 0
    gamma: tuple            # m: d(G q_dot)/dt with q_ddot = 0
    rows: tuple             # m: (constraint name, axis or 0) of each row, for messages
    dependent: tuple        # speed indices of the dependent speeds (declared order)
    independent: tuple      # the other speed indices, ascending
    dependent_coordinates: tuple    # coordinate indices (declared order)

    @property
    def m(self) -> int:
        return len(self.G)


def _column(R, j):
    return (R[0][j], R[1][j], R[2][j])


def _material_point(kin: Kinematics, point: str, body: str, n: int):
    """(velocity, partial velocities b_k, bias acceleration) of ``point``; with a
    ``body``, of the body's material point that is at ``point`` now."""
    P = kin.points[point]
    if not body:
        return P.v, [kin.point_partial(point, k) for k in range(n)], P.a_bias
    spec_body = next(b for b in kin.spec.bodies if b.name == body)
    B, G = kin.bases[spec_body.base], kin.points[spec_body.G]
    rho = sub(P.r, G.r)
    v = add(G.v, cross(B.omega, rho))
    partials = [add(kin.point_partial(spec_body.G, k), cross(B.partials.get(k, ZERO3), rho))
                for k in range(n)]
    a = add(add(G.a_bias, cross(B.alpha_bias, rho)), cross(B.omega, sub(P.v, G.v)))
    return v, partials, a


def constraint_rows(spec) -> tuple:
    """``(constraint name, axis or 0)`` of each row of G, in the order
    :func:`derive_constraints` writes them (what the rows of a constraint are
    before anything is derived: a scene's constraint forces name them).

    >>> from modelgen.model.api import load_model                     # doctest: +SKIP
    >>> constraint_rows(load_model("models/four_bar.yaml"))           # doctest: +SKIP
    (('loop', 1), ('loop', 2))
    """
    rows = [(c.name, c.normal) for c in spec.constraints if c.kind == "rolling"]
    for c in [c for c in spec.constraints if c.holonomic] + \
            [c for c in spec.constraints if not c.holonomic]:
        if c.kind == "rolling":
            rows.extend((c.name, axis) for axis in (1, 2, 3) if axis != c.normal)
        elif c.kind in ("position", "speeds"):
            rows.append((c.name, 0))
        else:
            rows.extend((c.name, axis) for axis in c.axes)
    return tuple(rows)


def derive_constraints(kin: Kinematics, graph: Graph | None = None) -> ConstraintTerms:
    """The residuals, G and gamma of ``kin.spec.constraints``, named in a graph that
    extends ``graph`` (default ``kin.graph``; a later graph that extends it).

    >>> from modelgen.model.api import load_model                     # doctest: +SKIP
    >>> from modelgen.derive.kinematics import derive_kinematics      # doctest: +SKIP
    >>> terms = derive_constraints(derive_kinematics(load_model("models/four_bar.yaml")))  # doctest: +SKIP
    >>> terms.m, terms.independent                                    # doctest: +SKIP
    (2, (0,))
    """
    spec = kin.spec
    builder = GraphBuilder(graph if graph is not None else kin.graph)
    n = spec.n
    # expressions use plain coordinates only (a joint's may not appear in them),
    # whose speeds have the same index
    ns = len(spec.simple_coordinates)
    q, qd = kin.q, kin.qd
    residuals, G, gamma, rows = [], [], [], []
    # the position equations first: each wheel's contact, then the others' (a
    # wheel's two no-slip equations come with the velocity constraints)
    ordered = [c for c in spec.constraints if c.holonomic] + \
        [c for c in spec.constraints if not c.holonomic]
    wheels = {c.name: _Wheel(builder, kin, c) for c in spec.constraints
              if c.kind == "rolling"}
    for w in wheels.values():
        residuals.append(w.height_residual)
        G.append(w.height_row)
        gamma.append(w.height_gamma)
        rows.append((w.c.name, w.c.normal))
    for c in ordered:
        if c.kind == "rolling":
            w = wheels[c.name]
            for axis, row, g in w.no_slip:
                G.append(row)
                gamma.append(g)
                rows.append((c.name, axis))
            continue
        if c.kind == "position":
            f = c.expression
            grad = [diff(f, q[k]) for k in range(ns)] + [sympy.S.Zero] * (n - ns)
            residuals.append(builder.name(f))
            G.append(builder.vec(grad))
            gamma.append(builder.name(sympy.Add(*[
                diff(grad[k], q[l]) * qd[l] * qd[k] for k in range(ns) for l in range(ns)
                if grad[k] != 0])))
            rows.append((c.name, 0))
            continue
        if c.kind == "speeds":
            g = c.expression
            G.append(builder.vec([diff(g, v) for v in qd]))
            gamma.append(builder.name(sympy.Add(*[diff(g, q[k]) * qd[k]
                                                  for k in range(ns)])))
            rows.append((c.name, 0))
            continue
        D = kin.bases[c.base]
        for axis in c.axes:
            e = _column(D.R, axis - 1)
            w_e = builder.vec(cross(D.omega, e))
            if c.kind == "coincide":
                A, B = kin.points[c.point_a], kin.points[c.point_b]
                d = builder.vec(sub(A.r, B.r))
                dv = builder.vec(sub(A.v, B.v))
                residuals.append(builder.name(dot(e, d)))
                G.append(builder.vec(
                    dot(cross(D.partials.get(k, ZERO3), e), d)
                    + dot(e, sub(kin.point_partial(c.point_a, k),
                                 kin.point_partial(c.point_b, k))) for k in range(n)))
                e_dd = add(cross(D.alpha_bias, e), cross(D.omega, w_e))
                gamma.append(builder.name(dot(e_dd, d) + 2 * dot(w_e, dv)
                                          + dot(e, sub(A.a_bias, B.a_bias))))
            else:       # velocity
                v, partials, a = _material_point(kin, c.point, c.body, n)
                v, a = builder.vec(v), builder.vec(a)
                G.append(builder.vec(dot(e, partials[k]) for k in range(n)))
                gamma.append(builder.name(dot(w_e, v) + dot(e, a)))
            rows.append((c.name, axis))
    graph_ = builder.freeze()
    if spec.dependent_speeds:
        dependent = tuple(spec.speeds.index(s) for s in spec.dependent_speeds)
        dep_q = tuple(spec.coordinates.index(c) for c in spec.dependent_coordinates)
    else:
        dependent, dep_q = choose_dependent(graph_, G, len(residuals), spec)
    independent = tuple(k for k in range(n) if k not in dependent)
    return ConstraintTerms(graph_, tuple(residuals), tuple(G), tuple(gamma),
                           tuple(rows), dependent, independent, dep_q)


def _pivots(M: np.ndarray, count: int) -> tuple:
    """The first ``count`` columns chosen by Gaussian elimination with complete
    pivoting (largest remaining entry first)."""
    import numpy as np
    M = np.array(M, dtype=float)
    chosen = []
    for _ in range(count):
        i, j = np.unravel_index(np.argmax(np.abs(M)), M.shape)
        chosen.append(int(j))
        if M[i, j] != 0:
            M = M - np.outer(M[:, j] / M[i, j], M[i, :])
        M[:, j] = 0.0
        M[i, :] = 0.0
    return tuple(sorted(chosen))


def choose_dependent(graph: Graph, G, m_h: int, spec, seed: int = 0) -> tuple:
    """(dependent speed indices, dependent coordinate indices) for a model that
    declares none: the columns of G (and of its position rows) picked by
    complete pivoting at the parameter defaults and a seeded random
    configuration (the coordinates' zero is often a singular one: a four-bar
    with every angle zero).  Only plain coordinates and their speeds are
    candidates (the first columns; a ball or free joint's are not, see
    :func:`modelgen.model.resolve.build_spec`)."""
    import numpy as np
    rng = np.random.default_rng(seed)
    params = {symbol(p): v for p, v in zip(spec.parameter_names, spec.parameter_defaults)}
    m, n, ns = len(G), spec.n, len(spec.simple_coordinates)
    rows = constraint_rows(spec)
    Gv = _real_sample(graph, [list(row) for row in G], spec, rng, params, rows)
    Gv = Gv.reshape(m, n)[:, :ns]
    return _pivots(Gv, m), _pivots(Gv[:m_h], m_h) if m_h else ()


def _configuration(spec, rng, span: float = math.pi) -> dict:
    """Seeded random coordinates in [-span, span], each joint's quaternion then scaled
    to unit length (a rotation; the draws are those of a model without joints)."""
    import numpy as np
    values = {symbol(c): rng.uniform(-span, span) for c in spec.coordinates}
    for j in spec.joints:
        quat = [symbol(c) for c in j.quaternion]
        norm = float(np.sqrt(sum(values[c] ** 2 for c in quat)))
        values.update({c: values[c] / norm for c in quat})
    return values


class _Wheel:
    """A knife-edge wheel on the plane ``n . r = height`` (n: axis ``normal`` of E).

    With j the axle and s = |n x j| = sqrt(1 - (n.j)^2), the contact point is
    the centre plus rho = r d, d = -(n - (n.j) j) / s the unit vector of the
    wheel's plane that points most down.  The height equation is
    ``n . r_G - r s - height = 0``; the no-slip equations say the wheel's
    material point at the contact has no velocity along the other two axes of E:
    ``e_a . (v_G + omega x rho) = 0``.
    """

    def __init__(self, builder: GraphBuilder, kin: Kinematics, c):
        spec = kin.spec
        self.c = c
        n_q = spec.n
        body = next(b for b in spec.bodies if b.name == c.body)
        W, Gk = kin.bases[body.base], kin.points[body.G]
        nvec = tuple(sympy.S.One if i == c.normal - 1 else sympy.S.Zero for i in range(3))
        j = _column(W.R, c.axle - 1)
        r = c.radius
        jn = builder.name(dot(nvec, j))
        s = builder.name(sympy.sqrt(1 - jn**2))
        jdot = builder.vec(cross(W.omega, j))
        jn_dot = builder.name(dot(nvec, jdot))
        jn_ddot = builder.name(dot(nvec, add(cross(W.alpha_bias, j), cross(W.omega, jdot))))
        ratio = builder.name(jn / s)
        # height: f = n.r_G - r s - h; df/dq_k = n.b_k^G + r (jn/s) n.(c_k x j)
        self.height_residual = builder.name(dot(nvec, Gk.r) - r * s - c.height)
        self.height_row = builder.vec(
            dot(nvec, kin.point_partial(body.G, k))
            + r * ratio * dot(nvec, cross(W.partials.get(k, ZERO3), j)) for k in range(n_q))
        self.height_gamma = builder.name(dot(nvec, Gk.a_bias)
                                         + r * (jn_dot**2 / s**3 + ratio * jn_ddot))
        # no slip: the material point at rho = r d, d = -(n - jn j)/s
        u = builder.vec(sub(nvec, tuple(jn * x for x in j)))
        rho = builder.vec(tuple(-r * x / s for x in u))
        u_dot = builder.vec(tuple(-jn_dot * a - jn * b for a, b in zip(j, jdot)))
        rho_dot = builder.vec(tuple(r * (-a / s - b * jn * jn_dot / s**3)
                                    for a, b in zip(u_dot, u)))
        a = builder.vec(add(add(Gk.a_bias, cross(W.alpha_bias, rho)), cross(W.omega, rho_dot)))
        self.no_slip = []
        for axis in (1, 2, 3):
            if axis == c.normal:
                continue
            e = tuple(sympy.S.One if i == axis - 1 else sympy.S.Zero for i in range(3))
            row = builder.vec(dot(e, add(kin.point_partial(body.G, k),
                                         cross(W.partials.get(k, ZERO3), rho)))
                              for k in range(n_q))
            self.no_slip.append((axis, row, builder.name(dot(e, a))))


class _NotReal(Exception):
    """A value of :func:`_evaluate` is complex, infinite or NaN."""


def _real(value) -> float:
    """``value`` (a number sympy evaluated) as a finite float, else :class:`_NotReal`."""
    if getattr(value, "free_symbols", None):
        raise TypeError(f"{value} is not a number")      # a symbol left: a defect here
    try:
        out = float(value)
    except TypeError:               # complex: sqrt or log of a negative number, zoo
        raise _NotReal from None
    if not math.isfinite(out):
        raise _NotReal
    return out


def _evaluate(graph: Graph, exprs, values: dict) -> np.ndarray:
    """``exprs`` at ``values`` (symbol -> float), through the graph's statements;
    :class:`_NotReal` when a value on the way is complex or not finite."""
    import numpy as np
    values = dict(values)
    for sym, expr in graph.closure(exprs):
        values[sym] = _real(expr.xreplace(values))
    return np.array([_real(sympy.sympify(e).xreplace(values)) for e in exprs])


def _real_sample(graph: Graph, row_exprs: list, spec, rng, params: dict, rows) -> np.ndarray:
    """The values of ``row_exprs`` (one list of expressions per constraint row, the
    rows named by ``rows``) at the first seeded random configuration where all are
    real and finite (:data:`REAL_DRAWS` draws at most; the first is
    :func:`_configuration`'s over [-pi, pi], so a model real everywhere draws as it
    always did), flattened row by row.  A :class:`ModelError` naming the first row
    that is never real when none is found."""
    flat = [e for row in row_exprs for e in row]
    for draw in range(REAL_DRAWS):
        span = math.pi * 2.0 ** RANGE_EXPONENTS[draw // DRAWS_PER_RANGE % len(RANGE_EXPONENTS)]
        values = dict(params)
        values.update(_configuration(spec, rng, span))
        try:
            return _evaluate(graph, flat, values)
        except _NotReal:
            continue
    bad = 0
    for i, row in enumerate(row_exprs):
        try:
            _evaluate(graph, row, values)
        except _NotReal:
            bad = i
            break
    raise _not_real_error(spec, rows[bad][0])


def _not_real_error(spec, name: str) -> ModelError:
    """The error of constraint ``name``, complex or not finite at every draw."""
    c = next(c for c in spec.constraints if c.name == name)
    key = f"constraints.{name}" + (".expression" if c.kind in ("position", "speeds") else "")
    lo, hi = (math.pi * 2.0 ** e for e in (min(RANGE_EXPONENTS), max(RANGE_EXPONENTS)))
    return ModelError(
        f"constraint {name} is complex or not finite at every one of the {REAL_DRAWS} "
        f"random configurations tried (coordinates within +-{lo:.3g} to +-{hi:.3g}, parameters "
        "at their defaults), so the constraint Jacobian cannot be checked: a square root, "
        "logarithm, inverse sine or cosine whose argument is outside its domain there",
        file=spec.source, line=spec.line_of(key) or spec.line_of(f"constraints.{name}"),
        key=key,
        fix="write the constraint so that it is real where the mechanism moves, or "
            "without those functions (x**2 + y**2 - L**2 for a point on a circle, not "
            "sqrt(L**2 - x**2) - y)")


def check_constraints(terms: ConstraintTerms, spec, samples: int = RANK_SAMPLES,
                      seed: int = 0) -> None:
    """Refuse redundant constraints (G rank-deficient at every one of ``samples``
    seeded random configurations) and dependent speeds whose columns of G are
    singular there (the rhs could never solve for them)."""
    import numpy as np
    m, n = terms.m, spec.n
    # each row's entries of G, and a position row's residual: all must be real
    row_exprs = [list(row) + ([terms.residuals[i]] if i < len(terms.residuals) else [])
                 for i, row in enumerate(terms.G)]
    at = np.cumsum([0] + [len(row) for row in row_exprs])
    rng = np.random.default_rng(seed)
    params = {symbol(p): v for p, v in zip(spec.parameter_names, spec.parameter_defaults)}
    ranks, dep_ranks, coord_ranks = [], [], []
    m_h, dep_q = len(terms.residuals), list(terms.dependent_coordinates)
    for _ in range(samples):
        flat = _real_sample(terms.graph, row_exprs, spec, rng, params, terms.rows)
        Gv = np.array([flat[at[i]:at[i] + n] for i in range(m)]).reshape(m, n)
        scale_ = max(1.0, float(np.abs(Gv).max()))
        tol = 1e-9 * scale_
        ranks.append(np.linalg.matrix_rank(Gv, tol))
        dep_ranks.append(np.linalg.matrix_rank(Gv[:, list(terms.dependent)], tol))
        # plain dependent coordinates: their columns of the position rows (speed
        # index = coordinate index) are what the projection's Newton steps solve
        coord_ranks.append(np.linalg.matrix_rank(Gv[:m_h, dep_q], tol) if m_h else 0)
    where = spec.line_of(f"constraints.{terms.rows[0][0]}")
    if max(ranks) < m:
        raise ModelError(
            f"the constraints are redundant: their {m} equations have rank {max(ranks)} at "
            f"{samples} random configurations (rows: "
            + ", ".join(f"{name}" + (f" axis {axis}" if axis else "") for name, axis in
                        terms.rows) + ")",
            file=spec.source, line=where, key="constraints",
            fix="remove the equations that follow from the others (e.g. a coincide axis "
                "that a planar model satisfies anyway)")
    if max(dep_ranks) < m:
        raise ModelError(
            "the dependent speeds " + ", ".join(spec.speeds[k] for k in terms.dependent)
            + " cannot be solved "
            "for: their columns of the constraint Jacobian are singular at "
            f"{samples} random configurations", file=spec.source,
            line=spec.line_of("dependent"), key="dependent.speeds",
            fix="choose speeds the constraints actually involve, one per equation"
                + (" (with ball or free joints, plain coordinates' speeds: a constraint "
                   "that only a joint's speeds could satisfy cannot be imported)"
                   if spec.joints else ""))
    # checked on every model: coordinates the position rows do not involve (z for
    # x - y = 0) would leave the projection's and the linearization's solves singular
    if m_h and max(coord_ranks) < m_h:
        raise ModelError(
            "the position constraints cannot be solved for the dependent coordinates "
            + ", ".join(spec.coordinates[k] for k in dep_q) + ": their columns of the "
            f"constraint Jacobian are singular at {samples} random configurations"
            + (", and on a model with ball or free joints only plain coordinates (angles "
               "or lengths) can be dependent" if spec.joints else ""), file=spec.source,
            line=spec.line_of("dependent") or where,
            key="dependent.coordinates" if spec.dependent_coordinates else "constraints",
            fix=("choose plain coordinates the position constraints involve, one per "
                 "equation, or write the joint's motion with simple bases and points")
            if spec.joints else "choose coordinates the position constraints involve, "
                                "one per position equation, whose columns are independent")
