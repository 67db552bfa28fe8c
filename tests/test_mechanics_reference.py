"""Tests of the sympy.physics.mechanics reference itself (tests/mechanics_reference.py).

The reference is only useful if it is right, so it is checked here against
things that do not use sympy.physics.mechanics at all:

* closed forms derived by hand (pendulum, double pendulum of rods, a rigid body
  in ZXZ Euler angles through Euler's equations);
* an independent Lagrangian derivation for every hand-built spec, done with
  plain sympy matrices (rotation matrices, position Jacobians, T = 1/2 qd' A qd,
  h = dA/dt qd - dT/dq, tau = -dV/dq + J' F; springs enter only through their
  potential), compared at seeded random states.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
import sympy

from mechanics_reference import (MechanicsReference, actions_spec,
                                 double_pendulum_closed_form, effects_spec,
                                 euler_closed_form,
                                 free_body_spec, particle_pendulum_spec,
                                 rod_double_pendulum_spec, spatial_chain_spec,
                                 zxz_rotation)
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, TIME, speed_name

RTOL = 1e-12


@functools.lru_cache(maxsize=None)
def reference(name: str) -> MechanicsReference:
    return MechanicsReference(HAND_SPECS[name]())


HAND_SPECS = {
    "particle_pendulum": particle_pendulum_spec,
    "rod_double_pendulum": rod_double_pendulum_spec,
    "free_body": free_body_spec,
    "heavy_body": lambda: free_body_spec(gravity=True, products=True),
    "actions": actions_spec,
    "effects": effects_spec,
    **{f"spatial_chain_{n}": functools.partial(spatial_chain_spec, n) for n in (1, 2, 3)},
}


def random_state(rng, spec):
    n = spec.n
    t = rng.uniform(0.0, 5.0)
    q = rng.uniform(-np.pi, np.pi, n)
    qd = rng.uniform(-3.0, 3.0, n)
    u = rng.uniform(-2.0, 2.0, len(spec.inputs))
    p = np.array(spec.parameter_defaults) * rng.uniform(0.5, 1.5, len(spec.parameters))
    return t, q, qd, u, p


def assert_rel(actual, expected, what, scale=0.0, rtol=RTOL):
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    err = np.linalg.norm(actual - expected)
    bound = rtol * max(np.linalg.norm(expected), scale)
    assert err <= bound, (f"{what}: |a-b| = {err:.3e} > {bound:.3e}\n"
                          f"actual   = {actual!r}\nexpected = {expected!r}")


# -- closed forms -------------------------------------------------------------

def test_particle_pendulum_matches_closed_form():
    ref = reference("particle_pendulum")
    rng = np.random.default_rng(1)
    for _ in range(20):
        t, q, qd, u, p = random_state(rng, ref.spec)
        m, L, g = p
        out = ref.evaluate(t, q, qd, u, p)
        assert_rel(out["A"], [[m * L**2]], "A")
        assert_rel(out["tau"], [-m * g * L * np.sin(q[0])], "tau")
        assert_rel(out["h"], [0.0], "h", scale=m * L**2 * qd[0] ** 2)
        assert_rel(out["forcing"], [-m * g * L * np.sin(q[0])], "forcing")
        assert_rel(out["T"], 0.5 * m * L**2 * qd[0] ** 2, "T")
        assert_rel(out["V"], -m * g * L * np.cos(q[0]), "V", scale=m * g * L)
        assert_rel(out["r_G"][0], [L * np.sin(q[0]), -L * np.cos(q[0]), 0.0], "r_G", scale=L)


def test_rod_double_pendulum_matches_closed_form():
    ref = reference("rod_double_pendulum")
    rng = np.random.default_rng(2)
    for _ in range(20):
        t, q, qd, u, p = random_state(rng, ref.spec)
        out = ref.evaluate(t, q, qd, u, p)
        want = double_pendulum_closed_form(q, qd, p)
        m1, m2, l1, l2, g = p
        scale_h = m2 * l1 * l2 * qd @ qd
        assert_rel(out["A"], want["A"], "A")
        assert_rel(out["h"], want["h"], "h", scale=scale_h)
        assert_rel(out["tau"], want["tau"], "tau", scale=g * (m1 + m2) * (l1 + l2))
        assert_rel(out["T"], want["T"], "T")
        assert_rel(out["V"], want["V"], "V", scale=g * (m1 + m2) * (l1 + l2))


def test_free_body_matches_euler_equations():
    ref = reference("free_body")
    rng = np.random.default_rng(3)
    for _ in range(20):
        t, q, qd, u, p = random_state(rng, ref.spec)
        out = ref.evaluate(t, q, qd, u, p)
        m, a, I1, I2, I3, g = p
        A, h, w = euler_closed_form(q, qd, (I1, I2, I3))
        assert_rel(out["A"], A, "A")
        assert_rel(out["h"], h, "h", scale=np.linalg.norm(A) * (qd @ qd))
        assert_rel(out["T"], 0.5 * w @ np.diag([I1, I2, I3]) @ w, "T")
        assert_rel(out["R"][0], zxz_rotation(q), "R", scale=1.0)
        assert_rel(out["tau"], np.zeros(3), "tau", scale=1.0)


# -- an independent Lagrangian derivation -------------------------------------

def _axis_rotation(axis, angle):
    c, s = sympy.cos(angle), sympy.sin(angle)
    if axis == 1:
        return sympy.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 2:
        return sympy.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return sympy.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _vee(S):
    return sympy.Matrix([S[2, 1], S[0, 2], S[1, 0]])


class LagrangeReference:
    """Equations of motion from rotation matrices and Jacobians (no mechanics module)."""

    def __init__(self, spec):
        q = [sympy.Symbol(c) for c in spec.coordinates]
        qd = [sympy.Symbol(speed_name(c)) for c in spec.coordinates]
        inputs = [sympy.Symbol(s) for s in spec.inputs]
        params = [sympy.Symbol(s) for s in spec.parameter_names]
        qv, qdv = sympy.Matrix(q), sympy.Matrix(qd)
        R = {CANONICAL_BASE: sympy.eye(3)}
        for b in spec.bases:
            R[b.name] = R[b.parent] * _axis_rotation(b.axis, b.angle)
        r = {CANONICAL_POINT: sympy.zeros(3, 1)}
        for pt in spec.points:
            r[pt.name] = r[pt.parent] + R[pt.base] * sympy.Matrix(pt.coordinates)
        for expr in list(R.values()) + list(r.values()):
            assert TIME not in expr.free_symbols, "kinematics must not depend on t here"

        def omega_jacobian(Rb):
            cols = [_vee(Rb.diff(qk) * Rb.T) for qk in q]
            return sympy.Matrix.hstack(*cols) if cols else sympy.zeros(3, 0)

        g = sympy.Matrix(spec.gravity) if spec.gravity is not None else sympy.zeros(3, 1)
        T = sympy.Integer(0)
        V = sympy.Integer(0)
        tau = sympy.zeros(len(q), 1)
        bodies = {}
        for b in spec.bodies:
            Rb, rG = R[b.base], r[b.G]
            Jv = rG.jacobian(qv)
            Jw = omega_jacobian(Rb)
            I_E = Rb * sympy.Matrix(b.inertia) * Rb.T
            v, w = Jv * qdv, Jw * qdv
            T += b.mass * (v.T * v)[0] / 2 + (w.T * I_E * w)[0] / 2
            V -= b.mass * (g.T * rG)[0]
            bodies[b.name] = (Rb, rG, Jv, Jw)
        def on_body(body, point, F, torque=None):
            """Generalized force of F at the body-fixed point at ``point`` (+ a torque)."""
            Rb, rG, Jv, Jw = bodies[body]
            M = (r[point] - rG).cross(F)
            if torque is not None:
                M += torque
            return Jv.T * F + Jw.T * M

        def body_point_velocity(body, point):
            Rb, rG, Jv, Jw = bodies[body]
            return Jv * qdv + (Jw * qdv).cross(r[point] - rG)

        for a in list(spec.actions) + [e for e in spec.effects if e.kind == "action"]:
            F = R[a.base] * sympy.Matrix(a.force)
            tau += on_body(a.body, a.point, F, R[a.base] * sympy.Matrix(a.torque))
        for e in spec.effects:
            if e.kind == "gravity":
                field = R[e.base] * sympy.Matrix(e.vector)
                for b in spec.bodies:
                    if e.base == CANONICAL_BASE:   # conservative: through V
                        V -= b.mass * (field.T * r[b.G])[0]
                    else:                          # a field turning with its base
                        tau += on_body(b.name, b.G, b.mass * field)
            elif e.kind in ("spring", "damper"):
                d = r[e.point_b] - r[e.point_a]
                length = sympy.sqrt((d.T * d)[0])
                if e.kind == "spring":
                    stretch = length - e.rest_length
                    V += e.stiffness * stretch**2 / 2 + e.preload * length
                else:   # tension c dl/dt along the line
                    rate = (sympy.Matrix([length]).jacobian(qv) * qdv)[0]
                    F_b = -e.damping * rate * d / length
                    tau += (r[e.point_b].jacobian(qv).T - r[e.point_a].jacobian(qv).T) * F_b
            elif e.kind == "torsion_spring":
                qk = q[list(spec.coordinates).index(e.coordinate)]
                V += e.stiffness * (qk - e.rest_angle) ** 2 / 2
            elif e.kind == "joint_damping":
                for c in e.coordinates:
                    k = list(spec.coordinates).index(c)
                    tau[k] += -e.damping * qd[k]
            elif e.kind == "friction":
                k = list(spec.coordinates).index(e.coordinate)
                static = e.coulomb if e.static is None else e.static
                level = e.coulomb + (static - e.coulomb) * sympy.exp(
                    -(qd[k] / e.stribeck_speed) ** 2)
                tau[k] += -level * sympy.tanh(qd[k] / e.smoothing_speed) - e.viscous * qd[k]
            elif e.kind == "drag":
                v = body_point_velocity(e.body, e.point)
                speed = sympy.sqrt((v.T * v)[0])
                tau += on_body(e.body, e.point,
                               -e.density * e.drag_coefficient * e.area * speed * v / 2)
            elif e.kind != "action":
                raise NotImplementedError(e.kind)
        # conservative loads (gravity fixed in E, springs): tau = -dV/dq
        tau += -sympy.Matrix([V]).jacobian(qv).T
        dT_dqd = sympy.Matrix([T]).jacobian(qdv).T
        A = dT_dqd.jacobian(qdv)
        h = dT_dqd.jacobian(qv) * qdv - sympy.Matrix([T]).jacobian(qv).T
        poses = [R[b.base] for b in spec.bodies] + [r[b.G] for b in spec.bodies]
        self.nb = len(spec.bodies)
        self.function = sympy.lambdify([TIME, q, qd, inputs, params],
                                       [A, h, tau, T, V] + poses, cse=True)

    def evaluate(self, t, q, qd, u, p):
        out = self.function(t, list(q), list(qd), list(u), list(p))
        n, nb = len(q), self.nb
        return dict(A=np.array(out[0], dtype=float).reshape(n, n),
                    h=np.array(out[1], dtype=float).reshape(n),
                    tau=np.array(out[2], dtype=float).reshape(n),
                    T=float(out[3]), V=float(out[4]),
                    R=np.array([np.array(m, dtype=float) for m in out[5:5 + nb]]),
                    r_G=np.array([np.array(m, dtype=float).reshape(3) for m in out[5 + nb:]]))


@pytest.mark.parametrize("name", sorted(HAND_SPECS))
def test_reference_matches_independent_lagrangian(name):
    ref = reference(name)
    lag = LagrangeReference(ref.spec)
    rng = np.random.default_rng(sum(map(ord, name)))
    for _ in range(20):
        t, q, qd, u, p = random_state(rng, ref.spec)
        got = ref.evaluate(t, q, qd, u, p)
        want = lag.evaluate(t, q, qd, u, p)
        norm_A = np.linalg.norm(want["A"])
        # force-like scale: the size of the terms h and tau are sums of
        scale_f = norm_A * (1.0 + qd @ qd) + np.linalg.norm(want["tau"])
        assert_rel(got["A"], want["A"], "A")
        assert_rel(got["h"], want["h"], "h", scale=1e-3 * scale_f)
        assert_rel(got["tau"], want["tau"], "tau", scale=1e-3 * scale_f)
        assert_rel(got["T"], want["T"], "T")
        assert_rel(got["V"], want["V"], "V", scale=1e-3 * (abs(want["V"]) + norm_A))
        assert_rel(got["R"], want["R"], "R", scale=1.0)
        assert_rel(got["r_G"], want["r_G"], "r_G", scale=1e-3)


def test_offset_action_point_velocity_matters():
    """Applying the wind force with Q's own velocity would give a different tau.

    In ``actions_spec`` the wind point Q is fixed in the cart (it has no
    ``th'`` in its velocity) while its force acts on the pendulum, so the
    generalized force must come from the pendulum's body-fixed point at Q.  The
    Lagrangian test above checks the right answer; this checks the wrong one is
    really different, so that test can fail.
    """
    ref = reference("actions")
    N, u = ref.N, ref.u
    Q, G = ref.points["Q"], ref.points["G"]
    frame = ref.frames["C"]
    F = next(a for a in ref.spec.actions if a.name == "wind").force
    to_dyn = {sympy.Symbol(c): qk for c, qk in zip(ref.spec.coordinates, ref.q)}
    to_dyn.update({sympy.Symbol(speed_name(c)): uk for c, uk in zip(ref.spec.coordinates, ref.u)})
    F_vec = sum((sympy.sympify(c).xreplace(to_dyn) * e for c, e in zip(F, (N.x, N.y, N.z))),
                start=0 * N.x)
    body_point = G.vel(N) + frame.ang_vel_in(N).cross(Q.pos_from(G))
    own = Q.vel(N)

    def gen_force(v):
        v = v.subs(ref._qdot_to_u)
        return sympy.Matrix([ref._plain(v.diff(uk, N).dot(F_vec)) for uk in u])

    right, wrong = gen_force(body_point), gen_force(own)
    values = {sympy.Symbol(name): value for name, value in ref.spec.parameters}
    values.update({sympy.Symbol("x"): 0.4, sympy.Symbol("th"): 0.7,
                   sympy.Symbol("x_dot"): 1.1, sympy.Symbol("th_dot"): -0.8})
    diff = (right - wrong).xreplace(values)
    assert abs(float(diff[1])) > 0.1, diff
