"""Constraint (reaction) forces as a scene output (``constraint_force``): the
multipliers of a constraint's rows, from the rhs's own solve.

Checked against a closed form (a point mass pinned to the tip of a uniform rod:
the pin's force from Newton's law on the mass), against sympy.physics.mechanics
``KanesMethod`` with auxiliary speeds (the same pin force, written by hand), and
against Kane's full equations ``A qdd = tau - h + G^T lam`` (every row, not only
the dependent ones the C solves) on the shipped four-bar and rolling disc.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy
from sympy.physics.mechanics import (
    KanesMethod,
    Particle,
    Point,
    ReferenceFrame,
    RigidBody,
    dynamicsymbols,
    inertia,
)

from constrained_references import WHEEL_DISC

import modelgen
from modelgen.errors import ModelError
from modelgen.model.scene import parse_scene
from modelgen.sim.scene import Scene

ROOT = Path(__file__).resolve().parent.parent
VALUES = {"m": 1.3, "M": 0.4, "L": 0.7, "g": 9.81}

ROD_MODEL = """\
name: rod_pendulum
description: a point mass pinned to the tip of a uniform rod hinged at O
coordinates: [th, x, y]
parameters: {m: 1.3, M: 0.4, L: 0.7, g: 9.81}
bases:
  B: {parent: E, axis: 3, angle: th}
points:
  Q:  {from: O, base: B, coordinates: [0, -L, 0]}
  Gr: {from: O, base: B, coordinates: [0, -L/2, 0]}
  P:  {coordinates: [x, y, 0]}
bodies:
  rod:  {mass: M, G: Gr, base: B, inertia: [M*L**2/12, 0, M*L**2/12]}
  ball: {mass: m, G: P, base: E, inertia: [0, 0, 0]}
gravity: [0, -g, 0]
constraints:
  pin: {type: coincide, point_a: P, point_b: Q, base: E, axes: [1, 2]}
dependent: {coordinates: [x, y], speeds: [x_dot, y_dot]}
"""

ROD_SCENE = """\
scene: rod_swing
model: rod_pendulum.yaml
effects: [gravity]
initial: {th: 0.0, x: 0.0, y: -0.7, th_dot: 0.0, x_dot: 0.0, y_dot: 0.0}
time: {end: 2.0, sample: 0.05}
integrator: {method: dop853, rtol: 1.0e-12, atol: 1.0e-12}
outputs:
  f_pin: {constraint_force: pin}
"""


@pytest.fixture(scope="module")
def rod(tmp_path_factory):
    d = tmp_path_factory.mktemp("rod")
    (d / "rod_pendulum.yaml").write_text(ROD_MODEL)
    (d / "rod_swing.yaml").write_text(ROD_SCENE)
    return modelgen.load_scene(d / "rod_swing.yaml", linearize=True)


def rod_state(cm, th, w):
    L = VALUES["L"]
    q = np.array([th, L * np.sin(th), -L * np.cos(th)])
    return np.concatenate([q, cm.consistent_speeds(q, [w, 0.0, 0.0])])


def pin_force_closed_form(th, w):
    """The force on the mass: along the rod the tension m (g cos th + L w^2)
    (towards O), across it m (L th'' + g sin th), th'' of the compound pendulum."""
    m, M, L, g = (VALUES[k] for k in "mMLg")
    tension = m * (g * np.cos(th) + L * w * w)
    thdd = -(m * L + M * L / 2) * g * np.sin(th) / (m * L**2 + M * L**2 / 3)
    across = m * (L * thdd + g * np.sin(th))
    return tension * np.array([-np.sin(th), np.cos(th)]) \
        + across * np.array([np.cos(th), np.sin(th)])


def test_pin_force_matches_the_closed_form(rod):
    cm = rod.model
    assert cm.output_columns == ("f_pin.x", "f_pin.y")
    rng = np.random.default_rng(7)
    worst = 0.0
    for th, w in rng.uniform([-np.pi, -4.0], [np.pi, 4.0], (20, 2)):
        ref = pin_force_closed_form(th, w)
        y = cm.output_values(0.0, rod_state(cm, th, w))
        worst = max(worst, np.abs(y - ref).max() / np.abs(ref).max())
    assert worst < 1e-12, worst


def test_pin_force_along_a_run(rod):
    res = rod.run(x0=rod_state(rod.model, 2.0, 1.5))
    assert res.success
    th, w = res["th"], res["th_dot"]
    ref = np.array([pin_force_closed_form(a, b) for a, b in zip(th, w)])
    got = res["f_pin"]
    assert got.shape == ref.shape
    assert np.abs(got - ref).max() / np.abs(ref).max() < 1e-12


def kane_pin_force():
    """The pin force on the mass by KanesMethod with two auxiliary speeds (the
    mass's velocity relative to the rod's tip): a function (th, w) -> (Fx, Fy)."""
    th, w = dynamicsymbols("th w")
    ua = dynamicsymbols("ua1:3")
    Fx, Fy = sympy.symbols("Fx Fy")
    m, M, L, g = sympy.symbols("m M L g")
    N = ReferenceFrame("N")
    B = N.orientnew("B", "Axis", [th, N.z])
    B.set_ang_vel(N, w * N.z)
    O = Point("O")
    O.set_vel(N, 0)
    Q = O.locatenew("Q", -L * B.y)
    Q.v2pt_theory(O, N, B)
    Gr = O.locatenew("Gr", -L / 2 * B.y)
    Gr.v2pt_theory(O, N, B)
    P = Q.locatenew("P", 0)
    P.set_vel(N, Q.vel(N) + ua[0] * N.x + ua[1] * N.y)
    rod_ = RigidBody("rod", Gr, B, M, (inertia(B, M * L**2 / 12, 0, M * L**2 / 12), Gr))
    ball = Particle("ball", P, m)
    F = Fx * N.x + Fy * N.y
    loads = [(Gr, -M * g * N.y), (P, -m * g * N.y + F), (Q, -F)]
    kane = KanesMethod(N, q_ind=[th], u_ind=[w], kd_eqs=[th.diff() - w], u_auxiliary=ua)
    fr, frstar = kane.kanes_equations([rod_, ball], loads)
    wdot = sympy.solve((fr + frstar)[0], w.diff())[0]
    aux = [e.subs(w.diff(), wdot) for e in kane.auxiliary_eqs]
    sol = sympy.solve(aux, [Fx, Fy], dict=True)[0]
    a, b = sympy.symbols("a b")
    exprs = [sol[Fx], sol[Fy]]
    exprs = [sympy.sympify(e).subs({sympy.Symbol(k): v for k, v in VALUES.items()})
             .subs({th: a, w: b}) for e in exprs]
    return sympy.lambdify((a, b), exprs, "numpy")


def test_pin_force_matches_kanes_method_with_auxiliary_speeds(rod):
    cm = rod.model
    f = kane_pin_force()
    rng = np.random.default_rng(11)
    for th, w in rng.uniform([-np.pi, -4.0], [np.pi, 4.0], (10, 2)):
        ref = np.array(f(th, w), dtype=float)
        y = cm.output_values(0.0, rod_state(cm, th, w))
        assert np.abs(y - ref).max() <= 1e-12 * np.abs(ref).max()


def test_pin_force_linearization_against_differences(rod):
    """The outputs' rows of the minimal linearization (the multipliers' total
    derivatives, solved in C) against central differences along the constraints."""
    cm = rod.model
    th, w = 0.8, -1.1
    lin = cm.linearize(rod_state(cm, th, w))
    assert lin.states == ("th", "th_dot")
    h = 1e-6
    fd = np.column_stack([
        (pin_force_closed_form(th + h, w) - pin_force_closed_form(th - h, w)) / (2 * h),
        (pin_force_closed_form(th, w + h) - pin_force_closed_form(th, w - h)) / (2 * h)])
    assert np.abs(lin.C - fd).max() < 1e-7 * np.abs(fd).max()


def full_kane_residual(cm, x, lam_rows):
    """A qdd - (tau - h) - G^T lam at x (every row: the C solves the dependent ones)."""
    n = cm.n
    q, qd = x[:n], x[n:]
    qdd = cm.rhs(0.0, x)[n:]
    A = cm.mass_matrix(q)
    rhs = cm.generalized_forces(0.0, q, qd) - cm.velocity_terms(q, qd)
    G = cm.constraint_jacobian(q)
    return A @ qdd - rhs - G.T @ lam_rows, np.abs(A @ qdd).max() + np.abs(rhs).max()


def _scene(text, tmp_path):
    return parse_scene(text, str(tmp_path / "s.yaml"), base_dir=str(ROOT / "models" / "scenes"))


def test_four_bar_forces_satisfy_every_row_of_kanes_equations(tmp_path):
    spec = _scene("""\
scene: four_bar_forces
model: ../four_bar.yaml
effects: [gravity]
initial: {q1: 0.3, q2: 0.0, q3: 0.0, q1_dot: 0.0, q2_dot: 0.0, q3_dot: 0.0}
time: {end: 1.0, sample: 0.1}
outputs:
  f_loop: {constraint_force: loop}
""", tmp_path)
    scene = Scene(spec)
    cm = scene.model
    assert cm.output_columns == ("f_loop.x", "f_loop.y")
    rng = np.random.default_rng(3)
    for _ in range(10):
        q = cm.assemble([rng.uniform(0, 2 * np.pi), 1.0, 2.0], keep=["q1"])
        x = np.concatenate([q, cm.consistent_speeds(q, [rng.uniform(-3, 3), 0, 0])])
        lam = cm.output_values(0.0, x)
        r, scale = full_kane_residual(cm, x, lam)
        assert np.abs(r).max() < 1e-12 * scale




def test_rolling_contact_force_is_newtons_law_on_the_disc(tmp_path):
    """A disc built with the ``rolling`` kind: the ground's force on it (columns
    x, y, z of E: the two no-slip rows and the height row) is, by Newton's law
    on the whole disc, m a_G - m g, with a_G the centre's (x, y, z) accelerations
    from the rhs; at rest upright it is (0, 0, m g)."""
    (tmp_path / "wheel_disc.yaml").write_text(WHEEL_DISC)
    (tmp_path / "disc_forces.yaml").write_text("""\
scene: disc_forces
model: wheel_disc.yaml
effects: [gravity]
initial: {q1: 0, q2: 0, q3: 0, x: 0, y: 0, z: 0.5, q1_dot: 0, q2_dot: 0, q3_dot: 0,
          x_dot: 0, y_dot: 0, z_dot: 0}
time: {end: 1.0, sample: 0.1}
outputs:
  f_c: {constraint_force: wheel}
""")
    cm = modelgen.load_scene(tmp_path / "disc_forces.yaml").model
    assert cm.output_columns == ("f_c.x", "f_c.y", "f_c.z")
    m, g, r = 1.0, 9.81, 0.5
    x = np.zeros(12)
    x[5] = r
    assert np.abs(cm.output_values(0.0, x) - [0, 0, m * g]).max() < 1e-14
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = cm.assemble(np.concatenate([rng.uniform(-1.2, 1.2, 3), rng.normal(size=2), [r]]),
                        keep=["q1", "q2", "q3", "x", "y"])
        qd = cm.consistent_speeds(q, np.concatenate([rng.normal(size=3), np.zeros(3)]))
        x = np.concatenate([q, qd])
        want = m * cm.rhs(0.0, x)[9:12] + [0, 0, m * g]
        got = cm.output_values(0.0, x)
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
        r_, scale = full_kane_residual(cm, x, _rows_of(cm, got))
        assert np.abs(r_).max() < 1e-12 * scale


def _rows_of(cm, columns):
    """The wheel's multipliers in G's row order (height first) from its x, y, z columns."""
    return np.array([columns[2], columns[0], columns[1]])


@pytest.mark.parametrize("model, initial, name, problem", [
    ("../four_bar.yaml", "q1: 0, q2: 0, q3: 0, q1_dot: 0, q2_dot: 0, q3_dot: 0", "lop",
     "unknown constraint 'lop'"),
    ("../double_pendulum.yaml", "q1: 0, q2: 0, q1_dot: 0, q2_dot: 0", "loop",
     "has no constraints"),
])
def test_constraint_force_of_an_unknown_constraint_is_refused(tmp_path, model, initial, name,
                                                              problem):
    text = f"""\
scene: bad
model: {model}
effects: [gravity]
initial: {{{initial}}}
time: {{end: 1.0, sample: 0.1}}
outputs:
  f: {{constraint_force: {name}}}
"""
    with pytest.raises(ModelError) as info:
        _scene(text, tmp_path)
    assert problem in str(info.value)
    assert "outputs.f.constraint_force" in str(info.value)
