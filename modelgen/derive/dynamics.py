"""Dynamics stage: mass matrix A, velocity-product term h and generalized forces tau.

The equations of motion are ``A(q) q_ddot = tau(t, q, q_dot, u) - h(q, q_dot, t)``,
derived by virtual power (Kane's method):

* ``A_kl = sum_i m_i b_k^i . b_l^i + c_k^i . (I_i c_l^i)``
* ``h_k  = sum_i b_k^i . m_i a_i^bias + c_k^i . (I_i alpha_i^bias + omega_i x I_i omega_i)``
* ``tau_k = sum_i b_k^i . F_i + c_k^i . M_i``  (forces F_i at G_i, moments M_i about G_i)

where b_k^i, c_k^i are the partial (the seed's *virtual*) velocities of body
i's centre of mass and base.  The seed calls h "dA/dt q_dot"; that name is
only right for one coordinate.  In general ``h = dA/dt q_dot - dT/dq``, which
is what virtual power gives and what is computed here (see the README).

The sums are organised the way the composite-rigid-body algorithm does: each
body's partial velocities are written as a spatial vector at O,
``S_k^i = (c_k^i, b_k^i - c_k^i x r_Gi)``.  Bodies downstream of the place
where q_k enters share the *same symbols* for S_k, so
``A_kl = S_k . (sum_{i in X} M_i) S_l`` with the sum over the shared set X
computed once and reused (a composite inertia).  For a chain this is O(n^2)
instead of O(n^3); for any tree it reduces to CRBA and the backward
recursion of RNEA.  Nothing here assumes a chain: bodies that do not share
symbols simply fall into separate groups.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.effects import action_forces, derive_effect
from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.spatial import (ZERO, ZERO3, add, cross, dot, matvec, scale, sub, times,
                                     total)
from modelgen.derive.kinematics import Kinematics, quaternion_columns
from modelgen.model.spec import TIME, symbol, time_free


@dataclass(frozen=True)
class Equations:
    """Output of :func:`derive_equations`: everything the C functions compute."""
    name: str
    graph: Graph
    t: sympy.Symbol
    q: tuple
    qd: tuple
    u: tuple                # input symbols
    p: tuple                # parameter symbols
    bodies: tuple           # body names, in spec order
    A: tuple                # n x n rows (symmetric)
    h: tuple                # n
    tau: tuple              # n, the sum of tau_parts
    tau_parts: tuple        # ((label, n-tuple), ...): gravity and each action
    kinetic: sympy.Expr
    potential: sympy.Expr   # gravity's (zero at O) plus the conservative effects'
    poses: tuple            # per body: 16 entries of the 4x4 pose, row-major
    #: dq/dt = N(q) qd (len(q) entries): the speeds themselves, except for the
    #: coordinates of ball and free joints (:func:`kinematic_relation`)
    qdot: tuple = ()

    @property
    def has_joints(self) -> bool:
        """True if some dq/dt is not its speed (a ball or free joint)."""
        return len(self.q) != len(self.qd)


def _transform_inertia(builder: GraphBuilder, R, inertia):
    """I_E = R I R^T as a named symmetric 3x3 (tuple of rows)."""
    # X = I R^T  (X[i][j] = sum_l I[i][l] R[j][l])
    X = [[total([times(inertia[i][l], R[j][l]) for l in range(3)]) for j in range(3)]
         for i in range(3)]
    X = [[builder.name(x) for x in row] for row in X]
    out = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            out[i][j] = out[j][i] = builder.name(total([times(R[i][l], X[l][j])
                                                        for l in range(3)]))
    return tuple(tuple(row) for row in out)


@dataclass(frozen=True)
class _Spatial:
    """Spatial inertia about a point P in E: (I_P, h = m (r_G - r_P), m); I_P as 6
    unique entries."""
    I: tuple     # (xx, yy, zz, xy, xz, yz)
    h: tuple
    m: sympy.Expr

    def plus(self, other, builder):
        return _Spatial(builder.vec(add(self.I, other.I)), builder.vec(add(self.h, other.h)),
                        builder.name(self.m + other.m))

    def times(self, S, builder):
        """M S for a spatial motion S = (c, beta): (I_O c + h x beta, m beta + c x h)."""
        c, beta = S[:3], S[3:]
        xx, yy, zz, xy, xz, yz = self.I
        Ic = (dot((xx, xy, xz), c), dot((xy, yy, yz), c), dot((xz, yz, zz), c))
        ang = add(Ic, cross(self.h, beta))
        lin = add(scale(self.m, beta), cross(c, self.h))
        return builder.vec(ang + lin)


def _sum_vectors(a, b, builder):
    return builder.vec(add(a, b))


class _SetSums:
    """Memoised sums of per-body quantities over sets of bodies.

    A set is built from the largest already-known subsets (greedy cover), so
    nested sets along a chain cost one addition each, as in CRBA.
    """

    def __init__(self, items: dict, plus, builder):
        self.items = items          # body index -> quantity
        self.plus = plus
        self.builder = builder
        self.memo: dict = {}

    def __call__(self, bodies: frozenset):
        if bodies in self.memo:
            return self.memo[bodies]
        remaining = set(bodies)
        total = None
        for known in sorted((s for s in self.memo if s < bodies),
                            key=lambda s: (-len(s), sorted(s))):
            if known <= remaining:
                total = (self.memo[known] if total is None else
                         self.plus(total, self.memo[known], self.builder))
                remaining -= known
        for i in sorted(remaining):
            total = (self.items[i] if total is None else
                     self.plus(total, self.items[i], self.builder))
        self.memo[bodies] = total
        return total


def _warm(sums: _SetSums, sets):
    """Compute sets smallest-first so larger ones reuse them."""
    for s in sorted(set(sets), key=lambda s: (len(s), sorted(s))):
        sums(s)


def kinematic_relation(builder: GraphBuilder, spec) -> tuple:
    """dq/dt = N(q) qd: a simple coordinate's rate is its speed; a joint's
    quaternion turns as ``dquat/dt = quat * (0, w) / 2`` (w in the joint's own
    base), and a free joint's position as ``dr/dt = R(quat) v``.

    >>> from modelgen.model.api import Model
    >>> spec = Model("m").add_joint("J", "ball", parent="E", base="B").spec()
    >>> builder = GraphBuilder()
    >>> qdot = kinematic_relation(builder, spec)
    >>> builder.freeze().expand(qdot[0])
    -J_qx*J_wx/2 - J_qy*J_wy/2 - J_qz*J_wz/2
    """
    out = [symbol(v) for v in spec.speeds[:len(spec.simple_coordinates)]]
    for joint in spec.joints:
        qs = [symbol(c) for c in joint.coordinates]
        vs = [symbol(v) for v in joint.speeds]
        w, x, y, z = qs[-4:]
        wx, wy, wz = vs[-3:]
        half = sympy.Rational(1, 2)
        quat_dot = [-half * (x * wx + y * wy + z * wz), half * (w * wx + y * wz - z * wy),
                    half * (w * wy + z * wx - x * wz), half * (w * wz + x * wy - y * wx)]
        if joint.kind == "free":
            cols = quaternion_columns((w, x, y, z))
            out += [builder.name(sympy.Add(*[cols[j][i] * vs[j] for j in range(3)]))
                    for i in range(3)]
        out += [builder.name(e) for e in quat_dot]
    return tuple(out)


def derive_equations(kin: Kinematics) -> Equations:
    """Derive A, h and tau (and energies, poses) from the kinematics.

    >>> from modelgen.model.api import load_model       # doctest: +SKIP
    >>> eqs = derive_equations(derive_kinematics(load_model("models/simple_pendulum.yaml")))  # doctest: +SKIP
    """
    spec = kin.spec
    builder = GraphBuilder(kin.graph)
    n = spec.n
    ref = _reference_point(kin)
    per_body = _body_terms(builder, kin, ref)
    potential = per_body.potential
    ext_parts = []    # [(label, {body index: 6-tuple})]
    if spec.gravity is not None:
        ext_parts.append(("gravity", per_body.gravity))
    for act in spec.actions:
        ext_parts.append((act.name, action_forces(builder, kin, act)))

    # effects (modelgen.derive.effects): forces on bodies, projected with the
    # groups below, or generalized forces computed directly (springs and
    # dampers between points; effects on coordinates)
    direct_parts = []
    for eff in spec.effects:
        terms = derive_effect(builder, kin, eff)
        if terms.body_forces is not None:
            ext_parts.append((eff.name, terms.body_forces))
        else:
            direct_parts.append((eff.name, terms.generalized))
        potential += terms.potential

    # -- group bodies by identical spatial partials ----------------------------
    groups = []       # per k: [(S, frozenset of bodies)]
    for k in range(n):
        by_motion: dict = {}
        for i in range(len(spec.bodies)):
            if k in per_body.S[i]:
                by_motion.setdefault(per_body.S[i][k], []).append(i)
        groups.append([(motion, frozenset(members)) for motion, members in by_motion.items()])

    # A about the reference point: the partials shifted there (h and tau keep O: their
    # terms grow only as |r|, A's as |r|^2)
    A = _mass_matrix(builder, per_body.M, groups if ref is None else [
        [(_shifted(builder, S, ref), X) for S, X in g] for g in groups], n)
    # armature: a rotor's reflected inertia, on its own dof's diagonal only
    for k, armature in enumerate(spec.armature_by_dof):
        if armature != 0:
            A[k][k] = builder.name(A[k][k] + armature)
    h = _project(builder, per_body.bias, groups, n)
    # tau projects the sum of all external forces once; the per-effect parts
    # stay in the graph and cost nothing unless a routine outputs them.
    total_ext: dict = {}
    for _, forces in ext_parts:
        for i, f in forces.items():
            total_ext[i] = builder.vec(add(total_ext[i], f)) if i in total_ext else f
    tau = _project(builder, total_ext, groups, n)
    if direct_parts:
        tau = tuple(builder.name(tau[k] + sympy.Add(*[part[k] for _, part in direct_parts]))
                    for k in range(n))
    tau_parts = tuple((label, _project(builder, forces, groups, n))
                      for label, forces in ext_parts) + tuple(direct_parts)

    kinetic, potential = builder.name(per_body.kinetic), builder.name(potential)
    qdot = kinematic_relation(builder, spec)
    return Equations(
        name=spec.name, graph=builder.freeze(), t=TIME, q=kin.q, qd=kin.qd,
        u=tuple(symbol(x) for x in spec.inputs),
        p=tuple(symbol(x) for x in spec.parameter_names),
        bodies=tuple(b.name for b in spec.bodies),
        A=tuple(tuple(row) for row in A), h=h, tau=tau, tau_parts=tau_parts,
        kinetic=kinetic, potential=potential, poses=tuple(per_body.poses), qdot=qdot)


@dataclass(frozen=True)
class _BodyTerms:
    """Per body (spec order): what :func:`derive_equations` sums and projects."""
    S: list           # {k: 6-tuple spatial partial}
    M: dict           # body index -> _Spatial
    bias: dict        # body index -> 6-tuple spatial force at O (N_O, F)
    gravity: dict     # body index -> spatial force of the top-level gravity
    kinetic: sympy.Expr
    potential: sympy.Expr
    poses: list


def _reference_point(kin: Kinematics):
    """The position of the point the spatial inertias of A are taken about: None (O),
    unless a coordinate moves bodies without turning them (a slider, a vehicle's or a
    free body's position: a coordinate in a point's position that is no base's angle),
    then the first body's G, which goes along.  About O, A's terms grow as m |r|^2
    and cancel to O(1): a bicycle's A lost 9.6 digits 1 km from O."""
    spec = kin.spec
    if not spec.bodies:
        return None
    coordinates = {symbol(c) for c in spec.coordinates}
    angles = set()
    for b in spec.bases:
        angles |= sympy.sympify(b.angle).free_symbols
    translating = any(j.kind == "free" for j in spec.joints) or any(
        (sympy.sympify(c).free_symbols & coordinates) - angles
        for p in spec.points for c in p.coordinates)
    return kin.points[spec.bodies[0].G].r if translating else None


def _shifted(builder: GraphBuilder, S, ref) -> tuple:
    """A spatial motion (c, beta) at O as one at ``ref``: (c, beta + c x ref)."""
    c, beta = S[:3], S[3:]
    return c + tuple(builder.vec(add(beta, cross(c, ref))))


def _body_terms(builder: GraphBuilder, kin: Kinematics, ref=None) -> _BodyTerms:
    """Spatial partials, inertias (about ``ref``, else O), bias and gravity forces,
    energies and poses of every body."""
    spec = kin.spec
    S, M, bias, grav_forces, poses = [], {}, {}, {}, []
    # summed once at the end: adding to a growing sum re-sorts all of it each time
    kinetic, potential = [], []
    gravity = spec.gravity
    # a field that varies in time does work that no potential accounts for
    gravity_potential = gravity is not None and time_free(gravity)
    for i, body in enumerate(spec.bodies):
        B = kin.bases[body.base]
        G = kin.points[body.G]
        r = G.r
        Si = {}
        for k in sorted(set(B.partials) | set(G.partials)):
            c = B.partials.get(k, ZERO3)
            w, beta = G.partials.get(k, (ZERO3, ZERO3))
            if w != c:
                beta = builder.vec(add(beta, cross(sub(w, c), r)))
            if any(x != 0 for x in c + beta):
                Si[k] = c + tuple(beta)
        S.append(Si)

        m = body.mass
        IE = _transform_inertia(builder, B.R, body.inertia)
        M[i] = _spatial_inertia(builder, IE, m, r if ref is None else builder.vec(sub(r, ref)))

        omega, alpha = B.omega, B.alpha_bias
        I_omega = builder.vec(matvec(IE, omega))
        F = builder.vec(scale(m, G.a_bias))
        N_G = add(matvec(IE, alpha), cross(omega, I_omega))
        bias[i] = builder.vec(add(N_G, cross(r, F))) + F

        kinetic.append((m * (G.v[0] ** 2 + G.v[1] ** 2 + G.v[2] ** 2)
                        + dot(omega, I_omega)) / 2)
        if gravity is not None:
            Fg = builder.vec(scale(m, gravity))
            grav_forces[i] = builder.vec(cross(r, Fg)) + Fg
            if gravity_potential:
                potential.append(-dot(Fg, r))
        R = B.R
        poses.append(tuple(R[0]) + (r[0],) + tuple(R[1]) + (r[1],) + tuple(R[2]) + (r[2],)
                     + (ZERO, ZERO, ZERO, sympy.S.One))
    return _BodyTerms(S, M, bias, grav_forces, sympy.Add(*kinetic), sympy.Add(*potential),
                      poses)


def _spatial_inertia(builder: GraphBuilder, IE, m, r) -> _Spatial:
    """The spatial inertia of a body of mass ``m`` and inertia ``IE`` (in E) at G,
    about the point G - ``r``."""
    h_vec = builder.vec(scale(m, r))
    rr = builder.name(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    return _Spatial((builder.name(IE[0][0] + m * (rr - r[0] ** 2)),
                     builder.name(IE[1][1] + m * (rr - r[1] ** 2)),
                     builder.name(IE[2][2] + m * (rr - r[2] ** 2)),
                     builder.name(IE[0][1] - r[0] * h_vec[1]),
                     builder.name(IE[0][2] - r[0] * h_vec[2]),
                     builder.name(IE[1][2] - r[1] * h_vec[2])), h_vec, m)


def _mass_matrix(builder: GraphBuilder, M: dict, groups, n: int) -> list:
    """A by composite inertias: ``A_kl`` sums ``S_k . (I_XY S_l)`` over the groups
    X of k and Y of l, with ``I_XY`` the summed inertia of the bodies in both."""
    inertia_sums = _SetSums(M, lambda a, b, gb: a.plus(b, gb), builder)
    _warm(inertia_sums, [X & Y for k in range(n) for l in range(k, n)
                         for _, X in groups[k] for _, Y in groups[l] if X & Y])
    forces_memo: dict = {}
    A = [[ZERO] * n for _ in range(n)]
    for l in range(n):
        for k in range(l + 1):
            total = ZERO
            for Sk, X in groups[k]:
                for Sl, Y in groups[l]:
                    XY = X & Y
                    if not XY:
                        continue
                    key = (XY, Sl)
                    if key not in forces_memo:
                        forces_memo[key] = inertia_sums(XY).times(Sl, builder)
                    total += dot(Sk, forces_memo[key])
            A[k][l] = A[l][k] = builder.name(total)
    return A


def _project(builder: GraphBuilder, per_body: dict, groups, n: int) -> tuple:
    """Generalized forces of the spatial forces ``per_body`` (body index ->
    force at O): grouped force sums dotted with each group's partial."""
    sums = _SetSums(per_body, _sum_vectors, builder)
    _warm(sums, [frozenset(i for i in X if i in per_body)
                 for k in range(n) for _, X in groups[k]] and
          [s for s in (frozenset(i for i in X if i in per_body)
                       for k in range(n) for _, X in groups[k]) if s])
    out = []
    for k in range(n):
        total = ZERO
        for Sk, X in groups[k]:
            X = frozenset(i for i in X if i in per_body)
            if X:
                total += dot(Sk, sums(X))
        out.append(builder.name(total))
    return tuple(out)
