"""An independent reference for modelgen's equations of motion.

:class:`MechanicsReference` translates a validated :class:`~modelgen.model.spec.ModelSpec`
into :mod:`sympy.physics.mechanics` objects and derives the equations of motion
with :class:`~sympy.physics.mechanics.KanesMethod`.  It shares nothing with
modelgen's own kinematics/dynamics stages except the spec dataclasses, so the
two can be compared number for number.

Translation rules (the conventions of :mod:`modelgen.model.spec`):

* one :class:`ReferenceFrame` per base, ``orient_axis`` about the parent's
  x/y/z (axis 1/2/3) by the angle expression; ``E`` is the Newtonian frame;
* one :class:`Point` per spec point, located from its parent by its coordinates
  in the components of its base; ``O`` is fixed in ``E``; every point's velocity
  is the time derivative of its position from ``O`` in ``E``;
* one :class:`RigidBody` per body (inertia dyadic about G from the 3x3 tensor in
  the body's base), or a :class:`Particle` when the tensor is all zeros;
* loads: gravity ``m g`` at every G (``g`` in components of ``E``); for each
  action a torque on the body's frame and a force applied at the *body-fixed*
  point that coincides with the action point (``v2pt_theory`` from G);
* effects (``spec.effects``, as documented in :mod:`modelgen.model.spec`): gravity
  fields in any base; springs and dampers between two points, acting at the
  points themselves (their own velocities); drag at a body-fixed point;
  torsion springs, joint damping and friction as generalized forces added to
  Kane's Fr; spring potentials are part of V;
* coordinates ``q_k`` become dynamicsymbols and the speeds are ``u_k = q_k'``,
  so ``mass_matrix`` is modelgen's ``A`` and ``forcing`` is ``tau - h``.

The symbolic results are lambdified once (with ``cse=True``); no ``simplify``.

Example (a particle pendulum of length L, q measured from the downward vertical):

>>> import sympy
>>> from modelgen.model.spec import ModelSpec, BaseSpec, PointSpec, BodySpec
>>> q, m, L, g = sympy.symbols("q m L g")
>>> zero = sympy.Integer(0)
>>> spec = ModelSpec(
...     name="pendulum", coordinates=("q",),
...     parameters=(("m", 2.0), ("L", 0.5), ("g", 9.81)),
...     bases=(BaseSpec("B", "E", 3, q),),
...     points=(PointSpec("G", "O", "B", (L, zero, zero)),),
...     bodies=(BodySpec("bob", m, "G", "B", ((zero,) * 3,) * 3),),
...     gravity=(g, zero, zero))
>>> ref = MechanicsReference(spec)
>>> out = ref.evaluate(0.0, [0.3], [0.0], None, None)
>>> float(out["A"][0, 0])                       # m L^2
0.5
>>> bool(abs(out["forcing"][0] + 2.0 * 9.81 * 0.5 * sympy.sin(0.3)) < 1e-12)
True
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import sympy
from sympy.physics.mechanics import (KanesMethod, Particle, Point,
                                     ReferenceFrame, RigidBody, dynamicsymbols,
                                     msubs)
from sympy.physics.vector import Vector

from modelgen.model.spec import (CANONICAL_BASE, CANONICAL_POINT, TIME, ModelSpec,
                           speed_name)

__all__ = ["MechanicsReference", "ReferenceTimings"]


@dataclass(frozen=True)
class ReferenceTimings:
    """Wall times (seconds) of the two expensive steps of building a reference."""
    derive: float       # frames, points, bodies, loads and KanesMethod
    lambdify: float     # lambdify(..., cse=True) of every output


class MechanicsReference:
    """Equations of motion of ``spec`` derived with sympy.physics.mechanics.

    Attributes of interest (all symbolic results are in the spec's plain
    symbols: ``q1``, ``q1_dot``, parameters, inputs and ``t``):

    ``mass_matrix`` (A), ``forcing`` (tau - h), ``fr`` (tau), ``velocity_terms``
    (h), ``kinetic_energy``, ``potential_energy``, ``rotations`` (list of R_B per body, columns are the
    body base's unit vectors in E) and ``mass_centres`` (r_G in E per body);
    ``frames``, ``points``, ``bodies`` and ``kane`` are the mechanics objects.
    """

    def __init__(self, spec: ModelSpec):
        self.spec = spec
        t0 = time.perf_counter()
        self._derive()
        t1 = time.perf_counter()
        self._lambdify()
        t2 = time.perf_counter()
        self.timings = ReferenceTimings(derive=t1 - t0, lambdify=t2 - t1)

    # -- derivation --------------------------------------------------------
    def _derive(self) -> None:
        spec = self.spec
        t = dynamicsymbols._t
        assert t == TIME, "sympy's time symbol must be modelgen's 't'"

        # plain spec symbols <-> dynamicsymbols
        self.q_syms = [sympy.Symbol(c) for c in spec.coordinates]
        self.qd_syms = [sympy.Symbol(speed_name(c)) for c in spec.coordinates]
        self.input_syms = [sympy.Symbol(name) for name in spec.inputs]
        self.param_syms = [sympy.Symbol(name) for name in spec.parameter_names]
        self.q = [dynamicsymbols(c) for c in spec.coordinates]
        self.u = [dynamicsymbols(speed_name(c) + "_u") for c in spec.coordinates]
        to_dynamic = {}
        for plain, q in zip(self.q_syms, self.q):
            to_dynamic[plain] = q
        for plain, u in zip(self.qd_syms, self.u):
            to_dynamic[plain] = u
        self._to_plain = {q: s for q, s in zip(self.q, self.q_syms)}
        self._to_plain.update({u: s for u, s in zip(self.u, self.qd_syms)})
        self._qdot_to_u = {q.diff(t): u for q, u in zip(self.q, self.u)}
        self._replacements = {q.diff(t): s for q, s in zip(self.q, self.qd_syms)}
        self._replacements.update(self._to_plain)

        def dyn(expr):
            return sympy.sympify(expr).xreplace(to_dynamic)

        # frames (bases)
        N = ReferenceFrame(CANONICAL_BASE)
        frames = {CANONICAL_BASE: N}
        for base in spec.bases:
            parent = frames[base.parent]
            frame = ReferenceFrame(base.name)
            axis = (parent.x, parent.y, parent.z)[base.axis - 1]
            frame.orient_axis(parent, axis, dyn(base.angle))
            frames[base.name] = frame
        self.N = N
        self.frames = frames

        def vector(base, components):
            frame = frames[base]
            c = [dyn(x) for x in components]
            return c[0] * frame.x + c[1] * frame.y + c[2] * frame.z

        # points: position from the parent in the base's components
        O = Point(CANONICAL_POINT)
        O.set_vel(N, 0)
        points = {CANONICAL_POINT: O}
        for p in spec.points:
            point = points[p.parent].locatenew(p.name, vector(p.base, p.coordinates))
            point.set_vel(N, point.pos_from(O).dt(N))
            points[p.name] = point
        self.O = O
        self.points = points

        # bodies
        bodies = []
        by_name = {}
        for b in spec.bodies:
            G = points[b.G]
            frame = frames[b.base]
            mass = dyn(b.mass)
            I = [[dyn(x) for x in row] for row in b.inertia]
            if all(x == 0 for row in I for x in row):
                body = Particle(b.name, G, mass)
            else:
                e = (frame.x, frame.y, frame.z)
                dyadic = sum((I[i][j] * (e[i] | e[j])
                              for i in range(3) for j in range(3) if I[i][j] != 0),
                             start=0 * (e[0] | e[0]))
                body = RigidBody(b.name, masscenter=G, frame=frame, mass=mass,
                                 inertia=(dyadic, G))
            bodies.append(body)
            by_name[b.name] = (body, G, frame, mass)
        self.bodies = bodies

        # loads (forces on points, torques on frames), generalized forces put
        # directly on coordinates, and potential energy
        loads = []
        direct = [sympy.Integer(0)] * spec.n
        V = sympy.Integer(0)
        coordinate_index = {c: k for k, c in enumerate(spec.coordinates)}

        def body_point(name, body, P):
            """The point of ``body``'s frame that coincides with P (velocity from G)."""
            _, G, frame, _ = by_name[body]
            if P is G:
                return G
            P_body = G.locatenew(name, P.pos_from(G))
            P_body.v2pt_theory(G, N, frame)
            return P_body

        def add_gravity(g_vec, potential):
            nonlocal V
            if g_vec == Vector(0):
                return
            for _, G, _, mass in by_name.values():
                loads.append((G, mass * g_vec))
                if potential:
                    V -= mass * g_vec.dot(G.pos_from(O))

        def add_action(a):
            _, G, frame, _ = by_name[a.body]
            torque = vector(a.base, a.torque)
            force = vector(a.base, a.force)
            if torque != Vector(0):
                loads.append((frame, torque))
            if force != Vector(0):
                # the body-fixed point coinciding with P, not P's own velocity
                loads.append((body_point(f"{a.name}_on_{a.body}", a.body, points[a.point]),
                              force))

        if spec.gravity is not None:
            add_gravity(vector(CANONICAL_BASE, spec.gravity), potential=True)
        for a in spec.actions:
            add_action(a)
        for eff in getattr(spec, "effects", ()):
            kind = eff.kind
            if kind == "action":
                add_action(eff)
            elif kind == "gravity":
                # a potential only for a field fixed in E
                add_gravity(vector(eff.base, eff.vector),
                            potential=eff.base == CANONICAL_BASE)
            elif kind in ("spring", "damper"):
                A, B = points[eff.point_a], points[eff.point_b]
                d = B.pos_from(A)
                length = sympy.sqrt(d.dot(d))
                unit = d / length
                if kind == "spring":
                    stretch = length - dyn(eff.rest_length)
                    tension = dyn(eff.stiffness) * stretch + dyn(eff.preload)
                    V += dyn(eff.stiffness) * stretch**2 / 2 + dyn(eff.preload) * length
                else:
                    rate = unit.dot(B.vel(N) - A.vel(N))
                    tension = dyn(eff.damping) * rate
                # the points' own velocities (points are not attached to bodies)
                loads.append((B, -tension * unit))
                loads.append((A, tension * unit))
            elif kind == "torsion_spring":
                k = coordinate_index[eff.coordinate]
                stretch = self.q[k] - dyn(eff.rest_angle)
                direct[k] += -dyn(eff.stiffness) * stretch
                V += dyn(eff.stiffness) * stretch**2 / 2
            elif kind == "joint_damping":
                for c in eff.coordinates:
                    k = coordinate_index[c]
                    direct[k] += -dyn(eff.damping) * self.u[k]
            elif kind == "friction":
                k = coordinate_index[eff.coordinate]
                v = self.u[k]
                coulomb = dyn(eff.coulomb)
                static = coulomb if eff.static is None else dyn(eff.static)
                level = coulomb + (static - coulomb) * sympy.exp(
                    -(v / dyn(eff.stribeck_speed)) ** 2)
                direct[k] += (-level * sympy.tanh(v / dyn(eff.smoothing_speed))
                              - dyn(eff.viscous) * v)
            elif kind == "drag":
                P_body = body_point(f"{eff.name}_on_{eff.body}", eff.body, points[eff.point])
                v = P_body.vel(N)
                speed = sympy.sqrt(v.dot(v))
                coefficient = -dyn(eff.density) * dyn(eff.drag_coefficient) * dyn(eff.area) / 2
                loads.append((P_body, coefficient * speed * v))
            else:
                raise NotImplementedError(
                    f"the mechanics reference does not model effects of kind {kind!r}")
        self.loads = loads

        # Kane's equations with u_k = q_k'
        kd = [q.diff(t) - u for q, u in zip(self.q, self.u)]
        kane = KanesMethod(N, q_ind=self.q, u_ind=self.u, kd_eqs=kd)
        fr, frstar = kane.kanes_equations(bodies, loads)
        self.kane = kane

        plain = self._plain
        direct = plain(sympy.Matrix(direct).xreplace(self._qdot_to_u))
        self.mass_matrix = plain(kane.mass_matrix)
        self.forcing = plain(kane.forcing) + direct
        self.fr = plain(fr) + direct
        # Fr* = -(M u' + h): h is -Fr* at u' = 0.  (Taken from Fr* rather than as
        # tau - forcing so that the loads do not cancel in floating point.)
        udot_zero = {u.diff(t): 0 for u in self.u}
        self.velocity_terms = plain(-msubs(frstar, udot_zero))

        # energies, poses
        T = sum((body.kinetic_energy(N) for body in bodies), start=sympy.Integer(0))
        self.kinetic_energy = plain(T)
        self.potential_energy = plain(V)
        self.rotations = [plain(N.dcm(frame)) for _, _, frame, _ in by_name.values()]
        self.mass_centres = [plain(G.pos_from(O).to_matrix(N))
                             for _, G, _, _ in by_name.values()]

    def _plain(self, expr):
        """Replace q_k', u_k, q_k (functions of t) by the spec's plain symbols."""
        # one pass: xreplace matches q_k' before descending into it
        expr = sympy.sympify(expr).xreplace(self._replacements)
        if expr.has(sympy.Derivative, *self.q, *self.u):
            raise AssertionError(f"dynamicsymbols left in reference expression: {expr}")
        return expr

    def _lambdify(self) -> None:
        args = [TIME, self.q_syms, self.qd_syms, self.input_syms, self.param_syms]
        n_bodies = len(self.spec.bodies)
        outputs = [self.mass_matrix, self.forcing, self.fr,
                   self.kinetic_energy, self.potential_energy, self.velocity_terms]
        outputs += list(self.rotations) + list(self.mass_centres)
        self._n_bodies = n_bodies
        self._function = sympy.lambdify(args, outputs, modules="numpy", cse=True)

    # -- numbers -----------------------------------------------------------
    def parameter_vector(self, p=None) -> np.ndarray:
        """Parameters in spec order from None (defaults), a dict of overrides or an array."""
        values = np.array(self.spec.parameter_defaults, dtype=float)
        if p is None:
            return values
        if isinstance(p, dict):
            names = list(self.spec.parameter_names)
            for name, value in p.items():
                values[names.index(name)] = float(value)
            return values
        p = np.asarray(p, dtype=float).reshape(-1)
        if p.shape != values.shape:
            raise ValueError(f"expected {values.size} parameters, got {p.size}")
        return p

    def evaluate(self, t, q, qd, u=None, p=None) -> dict:
        """Numeric values at one state.

        Returns a dict of numpy arrays: ``A`` (n, n), ``forcing`` (n,) = tau - h,
        ``tau`` (n,), ``h`` (n,), ``qdd`` (n,), ``T``, ``V`` (floats; V is the
        potential of gravity fixed in E and of the springs),
        ``R`` (n_bodies, 3, 3), ``r_G`` (n_bodies, 3) and ``poses``
        (n_bodies, 4, 4) laid out like modelgen's ``body_poses``.
        """
        n = self.spec.n
        q = np.asarray(q, dtype=float).reshape(n)
        qd = np.asarray(qd, dtype=float).reshape(n)
        if u is None:
            u = np.zeros(len(self.spec.inputs))
        u = np.asarray(u, dtype=float).reshape(len(self.spec.inputs))
        p = self.parameter_vector(p)
        out = self._function(float(t), list(q), list(qd), list(u), list(p))
        nb = self._n_bodies
        A = np.array(out[0], dtype=float).reshape(n, n)
        forcing = np.array(out[1], dtype=float).reshape(n)
        tau = np.array(out[2], dtype=float).reshape(n)
        h = np.array(out[5], dtype=float).reshape(n)
        R = np.array([np.array(m, dtype=float).reshape(3, 3) for m in out[6:6 + nb]]).reshape(nb, 3, 3)
        r_G = np.array([np.array(m, dtype=float).reshape(3) for m in out[6 + nb:6 + 2 * nb]]).reshape(nb, 3)
        poses = np.zeros((nb, 4, 4))
        poses[:, :3, :3] = R
        poses[:, :3, 3] = r_G
        poses[:, 3, 3] = 1.0
        return dict(A=A, forcing=forcing, tau=tau, h=h,
                    qdd=np.linalg.solve(A, forcing) if n else forcing,
                    T=float(out[3]), V=float(out[4]), R=R, r_G=r_G, poses=poses)


# -- hand-built specs ----------------------------------------------------------
# Built with the spec dataclasses directly (no loader), for validating the
# reference by hand and for closed-form tests of modelgen.

def _zero3x3():
    z = sympy.Integer(0)
    return ((z, z, z), (z, z, z), (z, z, z))


def _diag(a, b, c):
    z = sympy.Integer(0)
    return ((a, z, z), (z, b, z), (z, z, c))


def particle_pendulum_spec():
    """A point mass ``m`` on a massless rod of length ``L`` about E.z.

    ``q`` is measured from the downward vertical (-E.y): the bob is at
    ``L (sin q, -cos q, 0)`` and ``A = m L^2``, ``tau = -m g L sin q``, ``h = 0``.
    """
    from modelgen.model.spec import BaseSpec, BodySpec, PointSpec
    q, m, L, g = sympy.symbols("q m L g")
    z = sympy.Integer(0)
    return ModelSpec(
        name="particle_pendulum", coordinates=("q",),
        parameters=(("m", 1.3), ("L", 0.7), ("g", 9.81)),
        bases=(BaseSpec("B", "E", 3, q),),
        points=(PointSpec("G", "O", "B", (z, -L, z)),),
        bodies=(BodySpec("bob", m, "G", "B", _zero3x3()),),
        gravity=(z, -g, z))


def rod_double_pendulum_spec():
    """Two uniform rods in the E.x-E.y plane; q1 absolute, q2 relative.

    Rod i has mass ``mi``, length ``li``, lies along its base's x axis and has
    its centre at ``li/2``; gravity is ``-g E.y``.
    """
    from modelgen.model.spec import BaseSpec, BodySpec, PointSpec
    q1, q2, m1, m2, l1, l2, g = sympy.symbols("q1 q2 m1 m2 l1 l2 g")
    z = sympy.Integer(0)
    rod = lambda m, l: _diag(z, m * l**2 / 12, m * l**2 / 12)
    return ModelSpec(
        name="rod_double_pendulum", coordinates=("q1", "q2"),
        parameters=(("m1", 1.0), ("m2", 0.8), ("l1", 1.2), ("l2", 0.9), ("g", 9.81)),
        bases=(BaseSpec("B1", "E", 3, q1), BaseSpec("B2", "B1", 3, q2)),
        points=(PointSpec("G1", "O", "B1", (l1 / 2, z, z)),
                PointSpec("P1", "O", "B1", (l1, z, z)),
                PointSpec("G2", "P1", "B2", (l2 / 2, z, z))),
        bodies=(BodySpec("rod1", m1, "G1", "B1", rod(m1, l1)),
                BodySpec("rod2", m2, "G2", "B2", rod(m2, l2))),
        gravity=(z, -g, z))


def spatial_chain_spec(n: int):
    """The n-link spatial chain described for ``modelgen.model.chains.spatial_chain``.

    Base ``Bi`` is rotated from ``B(i-1)`` (``B0 = E``) by ``qi`` about axis 3
    for odd i and axis 2 for even i; rod i of length ``li`` and mass ``mi`` lies
    along ``Bi.x`` from joint ``P(i-1)`` (``P0 = O``), G at ``li/2``; gravity -z.
    """
    from modelgen.model.spec import BaseSpec, BodySpec, PointSpec
    z = sympy.Integer(0)
    g = sympy.Symbol("g")
    params, bases, points, bodies = [], [], [], []
    parent_base, parent_point = CANONICAL_BASE, CANONICAL_POINT
    for i in range(1, n + 1):
        q, m, l = sympy.symbols(f"q{i} m{i} l{i}")
        params += [(f"m{i}", 1.0 + 0.1 * i), (f"l{i}", 1.0 - 0.05 * i)]
        bases.append(BaseSpec(f"B{i}", parent_base, 3 if i % 2 else 2, q))
        points.append(PointSpec(f"G{i}", parent_point, f"B{i}", (l / 2, z, z)))
        points.append(PointSpec(f"P{i}", parent_point, f"B{i}", (l, z, z)))
        bodies.append(BodySpec(f"rod{i}", m, f"G{i}", f"B{i}",
                               _diag(z, m * l**2 / 12, m * l**2 / 12)))
        parent_base, parent_point = f"B{i}", f"P{i}"
    params.append(("g", 9.81))
    return ModelSpec(
        name=f"spatial_chain_{n}", coordinates=tuple(f"q{i}" for i in range(1, n + 1)),
        parameters=tuple(params), bases=tuple(bases), points=tuple(points),
        bodies=tuple(bodies), gravity=(z, z, -g))


def free_body_spec(gravity: bool = False, products: bool = False):
    """A rigid body about a fixed point O, ZXZ Euler angles (phi, theta, psi).

    ``R = Rz(phi) Rx(theta) Rz(psi)``; inertia ``diag(I1, I2, I3)`` about G in the
    body base (plus products of inertia ``I1/10, -I2/9, I3/8`` if ``products``);
    G is at ``a`` along the body's z axis (``a = 0``: torque-free).
    """
    from modelgen.model.spec import BaseSpec, BodySpec, PointSpec
    phi, theta, psi, m, a, I1, I2, I3, g = sympy.symbols("phi theta psi m a I1 I2 I3 g")
    z = sympy.Integer(0)
    inertia = _diag(I1, I2, I3)
    if products:
        ixy, ixz, iyz = I1 / 10, -I2 / 9, I3 / 8
        inertia = ((I1, ixy, ixz), (ixy, I2, iyz), (ixz, iyz, I3))
    return ModelSpec(
        name="free_body", coordinates=("phi", "theta", "psi"),
        parameters=(("m", 2.0), ("a", 0.3 if gravity else 0.0),
                    ("I1", 0.5), ("I2", 0.8), ("I3", 1.1), ("g", 9.81)),
        bases=(BaseSpec("B1", "E", 3, phi), BaseSpec("B2", "B1", 1, theta),
               BaseSpec("B", "B2", 3, psi)),
        points=(PointSpec("G", "O", "B", (z, z, a)),),
        bodies=(BodySpec("body", m, "G", "B", inertia),),
        gravity=(z, z, -g) if gravity else None)


def actions_spec():
    """A two-body model exercising every kind of load.

    A cart (particle, sliding along E.x by ``x``) carries a pendulum (rigid body,
    angle ``th`` about E.z, full inertia tensor given in base ``C``, which is
    tilted from the pendulum's base ``B`` so that the products of inertia matter).  Actions: an input force on the
    cart; a torque and a force on the pendulum given in the pendulum's base and
    applied at its tip (not at G), depending on the speeds, ``t`` and inputs;
    a force on the pendulum given in E at a point fixed in the cart frame.
    """
    from modelgen.model.spec import ActionSpec, BaseSpec, BodySpec, PointSpec
    x, th, x_dot, th_dot = sympy.symbols("x th x_dot th_dot")
    M, m, L, c, k, g, J, F, Tq = sympy.symbols("M m L c k g J F Tq")
    t = TIME
    z = sympy.Integer(0)
    inertia = ((J, J / 10, -J / 7), (J / 10, 2 * J, J / 5), (-J / 7, J / 5, 3 * J))
    return ModelSpec(
        name="actions", coordinates=("x", "th"),
        parameters=(("M", 2.0), ("m", 0.7), ("L", 0.8), ("c", 0.3), ("k", 1.7),
                    ("g", 9.81), ("J", 0.05)),
        inputs=("F", "Tq"),
        bases=(BaseSpec("B", "E", 3, th), BaseSpec("C", "B", 1, sympy.Rational(1, 3))),
        points=(PointSpec("C0", "O", "E", (x, z, z)),
                PointSpec("G", "C0", "B", (z, -L / 2, L / 5)),
                PointSpec("TIP", "C0", "B", (L / 3, -L, z)),
                PointSpec("Q", "C0", "E", (L / 2, z, -L / 4))),
        bodies=(BodySpec("cart", M, "C0", "E", _zero3x3()),
                BodySpec("pend", m, "G", "C", inertia)),
        gravity=(z, -g, z),
        actions=(ActionSpec("push", "cart", "C0", "E", (z, z, z), (F, z, z)),
                 ActionSpec("tip", "pend", "TIP", "C",
                            (Tq, -c * th_dot, sympy.sin(t)),
                            (-c * x_dot, k * sympy.cos(th) * t, F / 3)),
                 ActionSpec("wind", "pend", "Q", "E",
                            (z, z, z), (k * x, c, -x_dot * th_dot))))


def effects_spec():
    """A cart, a pendulum and a bob with every kind of effect switched on.

    The cart (particle, ``x`` along E.x) carries a pendulum (angle ``th`` about
    E.z, base B) whose tip carries a bob turning about B.x by ``ph`` (base C,
    full inertia tensor).  Effects: gravity in E and a "buoyancy" field fixed
    in the rotating base B; a spring from a point fixed in E to the tip, a
    damper from O to the bob's centre; a torsion spring on ``th``; joint
    damping on ``x`` and ``ph``; friction with a Stribeck peak on ``x``; drag
    on the bob at a point off its centre that is defined in the pendulum's
    base (so the body-fixed point matters); an action given as an effect.
    Requires the effect dataclasses of :mod:`modelgen.model.spec`.
    """
    from modelgen.model.spec import (ActionSpec, BaseSpec, BodySpec, DamperEffect, DragEffect,
                               FrictionEffect, GravityEffect, JointDampingEffect,
                               PointSpec, SpringEffect, TorsionSpringEffect)
    x, th, ph = sympy.symbols("x th ph")
    (M, m1, m2, L, a, g, b, k, l0, F0, c, kt, th0, cj, mu, mus, vs, eps, cv, rho, cd,
     area, J, Tq) = sympy.symbols(
        "M m1 m2 L a g b k l0 F0 c kt th0 cj mu mus vs eps cv rho cd area J Tq")
    z = sympy.Integer(0)
    bob_inertia = ((J, J / 10, -J / 7), (J / 10, 2 * J, J / 5), (-J / 7, J / 5, 3 * J))
    return ModelSpec(
        name="effects", coordinates=("x", "th", "ph"),
        parameters=(("M", 2.0), ("m1", 0.7), ("m2", 0.4), ("L", 0.8), ("a", 0.15),
                    ("g", 9.81), ("b", 1.3), ("k", 40.0), ("l0", 0.6), ("F0", 2.0),
                    ("c", 0.8), ("kt", 3.0), ("th0", 0.3), ("cj", 0.25), ("mu", 1.5),
                    ("mus", 2.5), ("vs", 0.4), ("eps", 0.05), ("cv", 0.2), ("rho", 1.2),
                    ("cd", 1.1), ("area", 0.3), ("J", 0.02)),
        inputs=("Tq",),
        bases=(BaseSpec("B", "E", 3, th), BaseSpec("C", "B", 1, ph)),
        points=(PointSpec("C0", "O", "E", (x, z, z)),
                PointSpec("G1", "C0", "B", (z, -L / 2, z)),
                PointSpec("TIP", "C0", "B", (z, -L, z)),
                PointSpec("G2", "TIP", "C", (z, z, -a)),
                # fixed in the pendulum's base but dragged on the bob: its own
                # velocity differs from the bob's body-fixed point's
                PointSpec("FIN", "TIP", "B", (a, a / 2, -a)),
                PointSpec("W", "O", "E", (sympy.Rational(1, 2), sympy.Rational(1, 4),
                                          sympy.Rational(1, 5)))),
        bodies=(BodySpec("cart", M, "C0", "E", _zero3x3()),
                BodySpec("pend", m1, "G1", "B", _diag(m1 * L**2 / 12, J, m1 * L**2 / 12)),
                BodySpec("bob", m2, "G2", "C", bob_inertia)),
        effects=(GravityEffect("gravity", (z, -g, z)),
                 GravityEffect("buoyancy", (z, b, z), base="B"),
                 SpringEffect("spring", "W", "TIP", k, l0, F0),
                 DamperEffect("damper", "O", "G2", c),
                 TorsionSpringEffect("hinge", "th", kt, th0),
                 JointDampingEffect("bearings", ("x", "ph"), cj),
                 FrictionEffect("rail", "x", mu, cv, mus, vs, eps),
                 DragEffect("drag", "bob", "FIN", rho, cd, area),
                 ActionSpec("motor", "bob", "G2", "C", (Tq, z, z), (z, z, z))))


# -- closed forms (numpy only) --------------------------------------------------

def double_pendulum_closed_form(q, qd, p):
    """Rods in a vertical plane, q1 absolute from E.x, q2 relative; gravity -y.

    T = 1/2 m1 l1^2/3 q1'^2
      + 1/2 m2 (l1^2 q1'^2 + l2^2/4 w2^2 + l1 l2 cos q2 q1' w2) + 1/2 m2 l2^2/12 w2^2,
    with w2 = q1' + q2'.  V = g (m1 l1/2 sin q1 + m2 (l1 sin q1 + l2/2 sin(q1+q2))).
    """
    m1, m2, l1, l2, g = p
    c2, s2 = np.cos(q[1]), np.sin(q[1])
    A = np.array([
        [m1 * l1**2 / 3 + m2 * (l1**2 + l2**2 / 3 + l1 * l2 * c2),
         m2 * (l2**2 / 3 + l1 * l2 * c2 / 2)],
        [m2 * (l2**2 / 3 + l1 * l2 * c2 / 2), m2 * l2**2 / 3]])
    # h = dA/dt qd - dT/dq; only q2 enters A: dA/dq2 = -m2 l1 l2 s2 [[1, 1/2], [1/2, 0]]
    k = m2 * l1 * l2 * s2 / 2
    h = np.array([-k * (2 * qd[0] * qd[1] + qd[1] ** 2), k * qd[0] ** 2])
    tau = -g * np.array([
        m1 * l1 / 2 * np.cos(q[0]) + m2 * (l1 * np.cos(q[0]) + l2 / 2 * np.cos(q[0] + q[1])),
        m2 * l2 / 2 * np.cos(q[0] + q[1])])
    T = 0.5 * qd @ A @ qd
    V = g * (m1 * l1 / 2 * np.sin(q[0]) + m2 * (l1 * np.sin(q[0]) + l2 / 2 * np.sin(q[0] + q[1])))
    return dict(A=A, h=h, tau=tau, T=T, V=V)


def zxz_rotation(q):
    """R = Rz(phi) Rx(theta) Rz(psi): columns are the body's unit vectors in E."""
    phi, theta, psi = q
    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return rz(phi) @ rx(theta) @ rz(psi)


def zxz_body_rate_matrix(q):
    """J with omega_B = J(q) qd for ZXZ Euler angles (phi, theta, psi). Works for complex q."""
    phi, theta, psi = q
    s, c = np.sin, np.cos
    return np.array([
        [s(theta) * s(psi), c(psi), 0 * psi],
        [s(theta) * c(psi), -s(psi), 0 * psi],
        [c(theta), 0 * psi, 1 + 0 * psi]])


def euler_closed_form(q, qd, inertia):
    """:func:`rigid_body_closed_form` for ZXZ Euler angles."""
    return rigid_body_closed_form(zxz_body_rate_matrix, q, qd, inertia)


def zyx_rotation(q):
    """R = Rz(yaw) Ry(pitch) Rx(roll): columns are the body's unit vectors in E."""
    yaw, pitch, roll = q
    cy, sy, cp, sp, cr, sr = (np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch),
                              np.cos(roll), np.sin(roll))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def zyx_body_rate_matrix(q):
    """J with omega_B = J(q) qd for ZYX angles (yaw, pitch, roll). Works for complex q."""
    yaw, pitch, roll = q
    s, c = np.sin, np.cos
    zero = 0 * yaw
    return np.array([
        [-s(pitch), zero, 1 + zero],
        [c(pitch) * s(roll), c(roll), zero],
        [c(pitch) * c(roll), -s(roll), zero]])


def rigid_body_closed_form(rate_matrix, q, qd, inertia):
    """Euler's equations mapped to the angles: A = J'IJ, h = J'(I Jdot qd + w x Iw).

    ``rate_matrix(q)`` gives J with omega_B = J qd; Jdot qd is taken by complex
    step, exact to rounding.  Returns (A, h, omega_B).
    """
    J = rate_matrix(q)
    w = J @ qd
    step = 1e-30
    Jdot = rate_matrix(q + 1j * step * qd).imag / step
    I = np.diag(inertia)
    A = J.T @ I @ J
    h = J.T @ (I @ Jdot @ qd + np.cross(w, I @ w))
    return A, h, w
