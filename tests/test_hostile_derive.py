"""Hostile but valid models through derivation, printing and the C compiler.

abs() and sign() of coordinates and speeds are differentiated as real functions
(d|u|/dx = sign(u) du/dx, d sign(u)/dx = 0), nothing unprintable reaches the
C, numbers beyond C's integer constants compile, and a description cannot
change the meaning of the C.  The models that once crashed the process are
built in a subprocess, so a crash fails the test instead of killing pytest.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap

import pytest
import sympy

import modelgen
from modelgen.codegen.printer import ModelPrinter
from modelgen.derive.calculus import diff
from modelgen.errors import DerivationError
from modelgen.model import parse_model

from conftest import MODELS, ROOT

x = sympy.Symbol("x")

ABS_DRAG_CART_POLE = (MODELS / "cart_pole.yaml").read_text().replace(
    "force: [F, 0, 0]", "force: [F - 0.5*abs(x_dot)*x_dot, 0, 0]")

# Models that once crashed the process (symengine segfaulted on sympy's
# complex derivative of abs) are built in a child process: it prints one
# number per line, computed by ``code`` from the CompiledModel ``cm``.
_CHILD = """
import sys
import numpy as np
import modelgen
from modelgen.model import parse_model
spec = parse_model(sys.stdin.read(), "hostile.yaml")
cm = modelgen.load(spec, sys.argv[1], jacobian=True)
"""

_JACOBIAN_ERROR = """
rng = np.random.default_rng(3)
worst = 0.0
for _ in range(5):
    x = np.concatenate([rng.uniform(-1, 1, cm.n), rng.normal(size=cm.n)])
    u = rng.normal(size=len(cm.inputs))
    J = cm.jac(0.0, x, u=u)
    F = np.empty_like(J)
    for j in range(2 * cm.n):
        h = 1e-5 * max(1.0, abs(x[j]))
        e = np.zeros_like(x)
        e[j] = h
        F[:, j] = (cm.rhs(0.0, x + e, u=u) - cm.rhs(0.0, x - e, u=u)) / (2 * h)
    worst = max(worst, np.abs(J - F).max() / np.abs(F).max())
print(worst)
"""


def _in_child(model_text: str, code: str, out_dir) -> list:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    result = subprocess.run([sys.executable, "-c", _CHILD + code, str(out_dir)],
                            input=model_text, capture_output=True, text=True,
                            env=env, cwd=ROOT, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    return [float(v) for v in result.stdout.split()]


def _slider(position: str, mass: str = "m", description: str = "a slider") -> str:
    return textwrap.dedent(f"""\
        name: slider
        description: {description!r}
        coordinates: [q]
        parameters: {{m: 2.0, L: 1.0}}
        points: {{P: {{coordinates: [{position}, 0, 0]}}}}
        bodies: {{b: {{mass: {mass}, G: P, base: E}}}}
        """)


def test_abs_drag_cart_pole_jacobian_matches_central_differences(tmp_path):
    (worst,) = _in_child(ABS_DRAG_CART_POLE, _JACOBIAN_ERROR, tmp_path / "cp")
    # central differences with h = 1e-5 are good to ~1e-8 of the scale
    assert worst <= 1e-6


def test_abs_and_sign_differentiate_as_real_functions():
    assert diff(sympy.Abs(x) * x, x) == x * sympy.sign(x) + sympy.Abs(x)
    assert diff(sympy.Abs(sympy.sin(x)), x) == sympy.sign(sympy.sin(x)) * sympy.cos(x)
    assert diff(sympy.sign(x) * x, x) == sympy.sign(x)
    for e in (diff(sympy.Abs(x) ** 3, x), diff(sympy.sign(x ** 2 - 1), x)):
        assert not e.has(sympy.re, sympy.im, sympy.Derivative)


def test_point_at_abs_of_a_coordinate_has_mass_matrix_m_sign_squared(tmp_path):
    code = "for q in (-0.7, 0.4, 0.0): print(cm.mass_matrix([q])[0, 0])\n"
    a_neg, a_pos, a_zero = _in_child(_slider("L + abs(q)"), code, tmp_path / "abs")
    assert (a_neg, a_pos) == pytest.approx((2.0, 2.0), rel=1e-15)
    # the C computes sign(0) = 0: the subgradient choice, not NaN
    assert a_zero == 0.0


def test_sign_of_a_coordinate_in_a_position_has_zero_derivative(tmp_path):
    out = tmp_path / "sign"
    code = "print(cm.mass_matrix([0.3])[0, 0]); print(cm.jac(0, [0.3, 0.2])[1, 0])\n"
    a, dqdd_dq = _in_child(_slider("q + 0.1*sign(q)"), code, out)
    assert (a, dqdd_dq) == (pytest.approx(2.0, rel=1e-15), 0.0)
    c_text = "".join(p.read_text() for p in out.rglob("*.c"))
    # sympy's re() printed as a call (not the "re(" ending "prepare(")
    assert "Derivative" not in c_text and not re.search(r"\bre\(", c_text)


def test_printer_refuses_unprintable_expressions_naming_the_routine():
    printer = ModelPrinter({x: "q[0]"}, "slider_mass_matrix")
    for expr in (sympy.Derivative(sympy.sign(x), x), sympy.re(x) + 1):
        with pytest.raises(DerivationError, match="in routine slider_mass_matrix"):
            printer.doprint(expr)


def test_integers_beyond_c_integer_constants_print_as_doubles():
    printer = ModelPrinter({x: "q[0]"})
    assert printer.doprint(sympy.Integer(10**19) * x) == "1e+19*q[0]"
    assert printer.doprint(sympy.Integer(2**63 + 1)) == "9.223372036854776e+18"
    assert printer.doprint(sympy.Rational(10**30, 3)) == "3.333333333333333e+29"
    assert printer.doprint(sympy.Rational(1, 3) + x) == "1.0/3.0 + q[0]"


def test_mass_of_1e19_m_compiles_and_gives_the_right_mass_matrix(tmp_path):
    cm = modelgen.load(parse_model(_slider("q", mass="1e19*m")), tmp_path / "big")
    assert cm.mass_matrix([0.0])[0, 0] == pytest.approx(2e19, rel=1e-15)


@pytest.mark.parametrize("ending", ["??/", "??/ ", "\\", "*/ int x; /*", "???/"])
def test_description_cannot_change_the_meaning_of_the_c(tmp_path, ending):
    spec = parse_model(_slider("q", description="trailing " + ending))
    cm = modelgen.load(spec, tmp_path / "desc")   # model parts compile with -Werror
    assert cm.mass_matrix([0.0])[0, 0] == pytest.approx(2.0)


def test_constants_whose_products_overflow_are_refused_before_the_compiler(tmp_path):
    # 1e200 is a double, but the mass matrix holds m*(1e200)**2
    spec = parse_model(_slider("1e200*q"))
    with pytest.raises(DerivationError, match="about 1e400 in routine mass_matrix is beyond the "
                                              "range of a double"):
        modelgen.load(spec, tmp_path / "overflow")
