"""Behaviour of code generation and the runtime that a mutation audit found unpinned.

Each test here was written against a hand-made mutant of ``modelgen/codegen`` or
``modelgen/sim`` (a plausible slip: a sign, an index, a stride, a precision, a
copy turned into a view) that the rest of the suite let through; each fails on
its mutant and passes on the code as it is (two pin more than one mutant).  The mutants and their outcomes are
listed in the audit's report; each test's docstring names the slip it
catches.  Every test compares against something independent
of the code it checks: Python's own correctly rounded doubles, numpy, a closed
form or two paths that must agree bit for bit.
"""
from __future__ import annotations

import math
import re
import shutil

import jinja2.meta
import numpy as np
import pytest
import sympy

import modelgen
from modelgen.codegen import emit, ldlt, parts
from modelgen.codegen.printer import ModelPrinter
from modelgen.errors import DerivationError
from modelgen.sim import massmatrix
from modelgen.sim import scene as scene_module

from conftest import MODELS, SCENES
from test_aba import branched_tree
from test_integrators import DRIVEN


# -- printer: constants keep every bit of their double -------------------------

def test_pi_and_e_print_as_their_correctly_rounded_doubles():
    """Both printer paths write pi and e with 17 significant digits, which C reads
    back as ``math.pi`` and ``math.e`` exactly; a literal cut to 15 digits (3e-15
    off) passes every comparison at 1e-12 and moves every pendulum with a pi in it."""
    printer = ModelPrinter({})
    for constant, value in ((sympy.pi, math.pi), (sympy.E, math.e)):
        assert float(printer.doprint(constant)) == value
        assert float(printer._slow(constant)) == value
        x = sympy.Symbol("x")
        text = ModelPrinter({x: "q[0]"}).doprint(constant * x + 1)
        literal = text.split("*")[0].split()[-1]
        assert float(literal) == value, text


def test_float_constants_round_trip_bit_for_bit():
    """A float constant of a model (a URDF's inertia, 0.1 m) is printed with the
    shortest text that reads back as the same double; ``%.15g`` loses the last bits
    of one in ten, below any tolerance a comparison with a peer uses."""
    rng = np.random.default_rng(23)
    values = np.concatenate([rng.uniform(-1, 1, 200), 10.0 ** rng.uniform(-30, 30, 200),
                             [0.1, 1 / 3, 2 / 3, 1e-300, 1.7976931348623157e308]])
    printer = ModelPrinter({})
    for v in values:
        text = printer.doprint(sympy.Float(float(v), 17))
        assert float(text) == float(v), (v, text)


# -- the build cache's key covers every template a model's C is rendered from ----

def _reachable_templates(env, roots) -> set:
    """The templates ``roots`` include or import, transitively (jinja2's own parse)."""
    seen, todo = set(), list(roots)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        source = env.loader.get_source(env, name)[0]
        todo.extend(jinja2.meta.find_referenced_templates(env.parse(source)))
    return seen


def test_every_template_of_a_models_c_changes_the_model_hash(tmp_path, monkeypatch):
    """A model's C is rendered from model.c.j2 and model.h.j2 and what they include
    (constraints.c.j2) or import (macros.j2): a byte changed in any of them must
    change :func:`templates_digest`, the model hash's share of the templates, or a
    cached library built from the old text is loaded as if it were current."""
    env = emit.environment()
    reachable = _reachable_templates(env, ("model.c.j2", "model.h.j2"))
    assert "constraints.c.j2" in reachable and "macros.j2" in reachable
    copy = tmp_path / "templates"
    shutil.copytree(emit.templates_dir(), copy)
    monkeypatch.setattr(emit, "templates_dir", lambda: copy)
    digest = emit.templates_digest()
    for name in sorted(reachable):
        path = copy / name
        text = path.read_text()
        path.write_text(text + "\n")
        assert emit.templates_digest() != digest, f"{name} is not in the model hash"
        path.write_text(text)
    assert emit.templates_digest() == digest



C_NAMESPACE = {"sqrt": math.sqrt, "pow": math.pow, "mg_sin": math.sin, "mg_cos": math.cos,
               "fabs": abs, "exp": math.exp, "log": math.log}


@pytest.mark.parametrize("exponent", [sympy.Rational(k, d) for k, d in (
    (1, 2), (-1, 2), (3, 2), (-3, 2), (5, 2), (1, 3), (-2, 3), (2, 1), (-3, 1), (5, 1), (-7, 1))])
def test_rational_powers_print_as_the_power_they_are(exponent):
    """Half powers are ``sqrt`` only for +-1/2: ``r**(-3/2)`` (an inverse-square law's
    1/r^3 written with a root) is not ``1/sqrt(r)``.  Both printer paths, evaluated
    as Python, against Python's own power; no shipped model has such an exponent."""
    x, y = sympy.symbols("x y", positive=True)
    printer = ModelPrinter({x: "x", y: "y"})
    rng = np.random.default_rng(11)
    for expr in (x ** exponent, y * (x + y) ** exponent, 1 / (y * x ** exponent)):
        fast, slow = printer.doprint(expr), printer._slow(expr)
        for xv, yv in rng.uniform(0.3, 3.0, (4, 2)):
            want = float(expr.subs({x: xv, y: yv}))
            for text in (fast, slow):
                got = eval(text, dict(C_NAMESPACE, x=xv, y=yv))  # noqa: S307 - our own C text
                assert got == pytest.approx(want, rel=1e-14), (expr, text)


def test_sign_prints_as_minus_one_zero_or_one():
    """``sign`` (a model's expressions allow it: Coulomb friction's direction) is
    printed by sympy's path as two comparisons; evaluated as Python (C's ``(double)``
    of a comparison is Python's ``float`` of a bool) against ``sympy.sign``, on both
    sides of zero and at zero."""
    x, y = sympy.symbols("x y")
    printer = ModelPrinter({x: "x", y: "y"})
    for expr in (sympy.sign(x), y * sympy.sign(x - y), sympy.sign(x) ** 2 + sympy.sign(y)):
        text = printer.doprint(expr).replace("(double)", "float")
        for xv, yv in ((1.5, 0.5), (-2.0, 0.5), (0.0, 0.0), (0.25, -3.0), (-1e-300, 1e-300)):
            want = float(expr.subs({x: xv, y: yv}))
            assert eval(text, {"x": xv, "y": yv, "float": float}) == want, (expr, text)  # noqa: S307


# -- backward integration: the reversed system is the mirrored one, bit for bit ----

@pytest.fixture(scope="module")
def dp_jacobian(tmp_path_factory):
    return modelgen.load(MODELS / "double_pendulum.yaml",
                         tmp_path_factory.mktemp("dp_jacobian"), jacobian=True)


@pytest.mark.parametrize("method, options", [
    ("dop853", {"rtol": 1e-9, "atol": 1e-9}), ("rodas", {"rtol": 1e-8, "atol": 1e-8}),
    ("gauss4", {"step": 5e-3}), ("midpoint", {"step": 5e-3})])
def test_backward_run_is_the_forward_run_with_speeds_reversed(dp_jacobian, method, options):
    """The undamped double pendulum (motor off) is reversible: its accelerations are
    even in the speeds, so running it from x0 backwards in time (the C's system in
    s = -t: xdot and the Jacobian negated) is running it forwards from x0 with the
    speeds negated, the speeds of one the negated speeds of the other.  Negation is
    exact, so the two agree bit for bit, statistics too; the implicit methods read
    the reversed Jacobian, every entry of which must be negated."""
    cm = dp_jacobian
    mirror = np.array([1.0, 1.0, -1.0, -1.0])
    x0 = np.array([1.1, -0.4, 0.8, -1.3])
    t_eval = np.linspace(0.0, 1.5, 7)
    back = cm.simulate(x0, (0.0, -1.5), t_eval=-t_eval, method=method, **options)
    ahead = cm.simulate(mirror * x0, (0.0, 1.5), t_eval=t_eval, method=method, **options)
    assert back.success and ahead.success, (back.message, ahead.message)
    assert np.array_equal(back.t, -ahead.t)
    assert np.array_equal(back.y, mirror[:, None] * ahead.y)
    assert (back.nfev, back.njev, back.nlu) == (ahead.nfev, ahead.njev, ahead.nlu)
    if method in ("rodas", "gauss4", "midpoint"):
        assert ahead.njev > 0


# -- linearize on the analytical derivatives with more than one input ------------

TWO_MOTORS = """\
name: chain_two_motors
coordinates: [q1, q2, q3]
parameters: {m: 1.1, l: 0.8, g: 9.81}
inputs: [T1, T3]
bases:
  B1: {parent: E, axis: 3, angle: q1}
  B2: {parent: B1, axis: 3, angle: q2}
  B3: {parent: B2, axis: 3, angle: q3}
points:
  P1: {from: O, base: B1, coordinates: [l, 0, 0]}
  G1: {from: O, base: B1, coordinates: [l/2, 0, 0]}
  P2: {from: P1, base: B2, coordinates: [l, 0, 0]}
  G2: {from: P1, base: B2, coordinates: [l/2, 0, 0]}
  G3: {from: P2, base: B3, coordinates: [0.6*l, 0, 0]}
bodies:
  rod1: {mass: m, G: G1, base: B1, inertia: [0, m*l**2/12, m*l**2/12]}
  rod2: {mass: m, G: G2, base: B2, inertia: [0, m*l**2/12, m*l**2/12]}
  rod3: {mass: 2*m, G: G3, base: B3, inertia: [0, m*l**2/6, m*l**2/6]}
gravity: [0, -g, 0]
actions:
  motor1: {body: rod1, point: O, base: B1, torque: [0, 0, T1], force: [0, 0, 0]}
  motor3: {body: rod3, point: P2, base: B3, torque: [0, 0, 0.5*T3], force: [0, T3, 0]}
"""


def test_linearize_on_the_derivatives_keeps_the_columns_of_each_input(tmp_path):
    """With three dofs ``<name>_linearize`` copies B out of ``<name>_derivatives``'
    dQ/du (N x NU, row-major); with one input any layout of it gives the same
    B, so two inputs on three dofs: A and B against central differences of the
    rhs (the shipped models with linearize have one input each)."""
    path = tmp_path / "two_motors.yaml"
    path.write_text(TWO_MOTORS)
    cm = modelgen.load(path, tmp_path / "build", linearize=True)
    assert cm.manifest["jacobian_method"] == "derivatives"
    rng = np.random.default_rng(3)
    x, u, h = rng.uniform(-1.5, 1.5, 6), rng.uniform(-2.0, 2.0, 2), 1e-6
    lin = cm.linearize(x, u)
    A = np.column_stack([(cm.rhs(0.0, x + h * e, u) - cm.rhs(0.0, x - h * e, u)) / (2 * h)
                         for e in np.eye(6)])
    B = np.column_stack([(cm.rhs(0.0, x, u + h * e) - cm.rhs(0.0, x, u - h * e)) / (2 * h)
                         for e in np.eye(2)])
    np.testing.assert_allclose(lin.A, A, rtol=0, atol=1e-7 * np.abs(A).max())
    np.testing.assert_allclose(lin.B, B, rtol=0, atol=1e-7 * np.abs(B).max())
    assert np.abs(B[3:, 0] - B[3:, 1]).max() > 0.1     # the two columns differ


# -- an early part is kept only for the same text, headers and command -----------

def test_an_early_part_is_discarded_when_its_header_or_command_changed(tmp_path):
    """:meth:`EarlyPart.matches` keeps an object compiled while Python still
    eliminated the rest only if the final file gives it the same part text, the
    same headers (a ``#define`` of a size it reads) and the same command (an
    optimisation flag); the existing test changes the text only."""
    source = ('#include "m.h"\n#if !defined(MG_PART) || MG_PART == 2\n'
              "int m_f(void) { return M_SIZE; }\n#endif /* MG_PART 2 */\n")
    sources = {"m.c": source, "m.h": "#define M_SIZE 3\n"}
    command = ["true", "-O2", "m.o"]
    cases = {"same": (sources, command, True),
             "header": ({**sources, "m.h": "#define M_SIZE 4\n"}, command, False),
             "command": (sources, ["true", "-O1", "m.o"], False),
             "other part": ({**sources, "m.c": source + "#if !defined(MG_PART) || MG_PART == 1"
                             "\nint m_g;\n#endif /* MG_PART 1 */\n"}, command, True)}
    for case, (final, final_command, kept) in cases.items():
        early = parts.start(tmp_path, "m", sources, 2, command)
        assert early is not None
        try:
            assert early.matches(final, "m", final_command) is kept, case
        finally:
            early.stop()


DRIVEN_SCENE = """\
scene: driven_swing
model: driven.yaml
effects: [gravity, drive]
initial: {q: 0.4, q_dot: 0.0}
time: {start: 0.0, end: 1.0, sample: 0.1}
outputs:
  torque: {generalized_force: drive}
"""


def test_outputs_recorded_backwards_are_those_at_the_reported_times(tmp_path):
    """An output that depends on t itself (a torque ``A sin(w t)``) recorded while
    integrating backwards is evaluated at t, not at the reversed system's s = -t:
    against ``output_values`` at each reported time and the closed form."""
    (tmp_path / "driven.yaml").write_text(DRIVEN)     # A = 5, w = 3
    (tmp_path / "scene.yaml").write_text(DRIVEN_SCENE)
    cm = modelgen.load_scene(tmp_path / "scene.yaml", tmp_path / "build").model
    t_eval = np.linspace(1.0, 0.2, 5)
    res = cm.simulate([0.4, 0.0], (1.0, 0.2), t_eval=t_eval, rtol=1e-10, atol=1e-10)
    assert res.success and np.array_equal(res.t, t_eval)
    got = np.asarray(res.outputs["torque"]).ravel()
    np.testing.assert_allclose(got, 5.0 * np.sin(3.0 * t_eval), rtol=1e-12, atol=1e-14)
    for k, t in enumerate(res.t):
        assert got[k] == pytest.approx(cm.output_values(t, res.y[:, k])[0], rel=1e-12)


@pytest.mark.parametrize("method, options", [("dop853", {}), ("rk4", {"step": 0.01})])
def test_a_mass_matrix_failure_backwards_is_reported_as_forwards(dp_jacobian, method, options):
    """The reversed system passes on the rhs's status: a singular mass matrix (both
    masses zero) stops a backward run with MASS_MATRIX and the same failing pivot
    as it stops the forward run, not with NaN in the state."""
    p = {"m1": 0.0, "m2": 0.0}
    x0 = [0.3, 0.2, 0.0, 0.0]
    ahead = dp_jacobian.simulate(x0, (0.0, 0.5), method=method, p=p, **options)
    back = dp_jacobian.simulate(x0, (0.0, -0.5), method=method, p=p, **options)
    assert ahead.status == back.status == -3, (ahead.message, back.message)
    pivot = re.search(r"pivot \d+ \(coordinate '\w+'\)", ahead.message)
    assert pivot and pivot[0] in back.message, back.message


# -- the crba rhs's loop over the non-zeros of a sparse mass matrix ---------------

def test_the_sparse_loop_solve_of_a_branched_tree_agrees_with_the_aba(tmp_path, monkeypatch):
    """Trees beyond the unrolling limit solve A qdd = b by a loop over the non-zeros
    of L in the elimination order (``solve_loop`` in model.c.j2); of the shipped
    models none is that large, and the only other test of the loop builds solo12
    (slow).  The limits lowered, the 5-dof branched tree takes the loop: its crba
    rhs against the ABA program, which shares no code with it."""
    aba = modelgen.load(branched_tree(), tmp_path / "aba", formulation="aba")
    monkeypatch.setattr(ldlt, "UNROLL_SOLVE", 0)
    monkeypatch.setattr(ldlt, "SPARSE_UNROLL_SIZE", 1)
    crba = modelgen.load(branched_tree(), tmp_path / "crba", formulation="crba", force=True)
    source = (tmp_path / "crba" / "branched.c").read_text()
    assert "LDL^T over the structurally non-zero entries" in source
    rng = np.random.default_rng(17)
    for _ in range(8):
        x, u = rng.uniform(-1.5, 1.5, 10), rng.uniform(-1.0, 1.0, 1)
        want, got = aba.rhs(0.0, x, u), crba.rhs(0.0, x, u)
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))


# -- the minimal linearization of a closed loop maps its outputs too --------------

def test_the_minimal_outputs_matrix_follows_the_dependent_coordinates(tmp_path):
    """A closed loop's linearization is in its independent states: C of the outputs
    is C P, a change of the crank angle moving the coupler and rocker with it (the
    constraints' tangent), not C's columns of the independent states alone.  The
    four-bar's coupler tip and energy against central differences along the
    loop: the crank's angle or speed moved, the loop assembled again and the dependent
    speeds solved from the crank's."""
    scene = modelgen.load_scene(SCENES / "four_bar_swing.yaml", tmp_path, linearize=True)
    cm = scene.model
    x = scene.initial_state()
    lin = cm.linearize(x)
    assert lin.states == ("q1", "q1_dot")
    h, n = 1e-6, cm.n

    def outputs_at(dq1=0.0, dq1_dot=0.0):
        q = x[:n].copy()
        q[0] += dq1
        q = cm.assemble(q, keep=["q1"])
        qd = x[n:].copy()
        qd[0] += dq1_dot
        return cm.output_values(0.0, np.concatenate([q, cm.consistent_speeds(q, qd)]))
    C = np.column_stack([(outputs_at(h) - outputs_at(-h)) / (2 * h),
                         (outputs_at(0.0, h) - outputs_at(0.0, -h)) / (2 * h)])
    assert np.abs(C[:, 0]).max() > 0.1
    np.testing.assert_allclose(lin.C, C, rtol=0, atol=1e-7 * np.abs(C).max())


# -- the load-time check: a diagonal that is zero up to rounding -----------------

def test_a_coordinate_with_a_rounding_level_diagonal_is_refused_at_load():
    """A coordinate that moves no mass leaves a diagonal of A that is zero only up to
    rounding (1e-17 of the others): the pivot test alone passes it (d_j / A_jj is
    1), so the load-time check also refuses a diagonal below ``PIVOT_TOL`` times
    the largest, at every configuration tried, naming the coordinate; a real mass
    ratio of 1e-12 passes."""
    manifest = {"name": "m", "coordinates": ["a", "b", "c"], "parameters": [["k", 1.0]]}

    def mass_matrix(scale):
        return lambda q: [[2.0 + math.cos(q[1]), 0.3, 0.0], [0.3, 1.0, 0.0],
                          [0.0, 0.0, scale * (1.5 + math.sin(q[0]))]]
    assert massmatrix.failing_pivot(mass_matrix(1e-17)([0.1, 0.2, 0.3])) is None
    with pytest.raises(DerivationError, match=r"coordinate 'c' \(row 3 of A\) moves no mass"):
        massmatrix.check(manifest, mass_matrix(1e-17))
    massmatrix.check(manifest, mass_matrix(1e-12))


# -- a scene's cached card follows the scene file's text --------------------------

def test_an_edited_scene_file_is_read_again_not_its_cached_card(tmp_path):
    """The scene card kept in the cache (what ``load_scene`` runs without importing
    sympy) is keyed by the scene file's bytes: only the model file's digest is
    stored beside it, so a key without the scene's bytes would run an edited
    scene with its old span.  Read, edited, read again."""
    path = tmp_path / "dp_card.yaml"

    def write(t_end):
        path.write_text(f"scene: dp_card\nmodel: {MODELS / 'double_pendulum.yaml'}\n"
                        f"effects: [gravity]\ninitial: {{q1: 0.5, q2: 0.0, q1_dot: 0.0, q2_dot: 0.0}}\n"
                        f"time: {{start: 0.0, end: {t_end}, sample: 0.1}}\n")
    write(1.0)
    card, spec = scene_module.read_card(path)
    assert card.t_end == 1.0 and spec is not None
    card, spec = scene_module.read_card(path)
    assert card.t_end == 1.0 and spec is None            # the cached card
    write(2.0)
    card, _ = scene_module.read_card(path)
    assert card.t_end == 2.0
