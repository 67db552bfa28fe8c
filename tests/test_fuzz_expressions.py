"""Property-based fuzzing of expressions through the model loader.

Expression texts (grammar-shaped, random characters, deep nesting, huge
numbers, Unicode) are put into a small pendulum model and given to
:func:`modelgen.model.parse_model`.  Properties:

* only :class:`ModelgenError` subclasses escape;
* every :class:`ModelError` names the file and the line of the key;
* every case finishes within :data:`BUDGET` seconds;
* a model that validates either compiles or is refused by the derivation
  before the compiler runs (a small sample: compiling is slow);
* valid, non-trivial expressions compile, and the compiled rhs agrees with the
  point mass's Lagrangian derived by sympy.

The generators are :mod:`modelgen.bench.fuzz_cases`.  The run is bounded and
reproducible (``derandomize=True``); ``bench/fuzz.py`` runs the same generators
for thousands of cases and prints a table.
"""
from __future__ import annotations

import re
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import modelgen
from modelgen.bench.fuzz_cases import (SLOTS, expressions, grammar_expressions, model_text,
                                       yaml_numbers)
from modelgen.errors import BuildError, DerivationError, ModelError, ModelgenError
from modelgen.model import parse_model

#: Seconds one model may take to load (validation only).
BUDGET = 2.0

SOURCE = "fuzz.yaml"


def check_outcome(text: str):
    """Load one model text; return the spec or the ModelError, after the properties."""
    start = time.perf_counter()
    try:
        spec = parse_model(text, SOURCE)
    except ModelError as exc:
        result = exc
        assert exc.file == SOURCE, str(exc)
        assert exc.line is not None, str(exc)
    except ModelgenError as exc:
        result = exc
    elapsed = time.perf_counter() - start
    assert elapsed < BUDGET, f"{elapsed:.2f} s"
    return result if "result" in locals() else spec


# -- properties ----------------------------------------------------------------------

FUZZ = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))


@FUZZ
@given(slot=st.sampled_from(sorted(SLOTS)), expression=expressions())
def test_any_expression_text_gives_a_spec_or_a_located_model_error(slot, expression):
    check_outcome(model_text(slot, expression))


@settings(FUZZ, max_examples=100)
@given(slot=st.sampled_from(sorted(SLOTS)), value=yaml_numbers())
def test_any_yaml_number_gives_a_spec_or_a_located_model_error(slot, value):
    check_outcome(model_text(slot, value))


@pytest.mark.parametrize("slot, text", [
    ("angle", "(q/100)**(10**8)"), ("angle", "tanh(tan(sinh(1e99)))"),
    ("angle", "acos(cos(cosh(1.7976931348623157e308)))"), ("angle", "(2*q)**(10**9)"),
    ("angle", "sin(" * 199 + "q" + ")" * 199), ("angle", "sin(" * 120 + "q" + ")" * 120),
    ("angle", "q*\u00b2"), ("angle", "q + \u0661"), ("angle", "acos(cos(10**300))"),
    ("y", "(-1)**(1/3)"), ("y", "acos(2) + L"), ("y", "asin(2)*L"), ("mass", "log(0)*m"),
])
def test_pathological_texts_are_refused_within_the_budget(slot, text):
    outcome = check_outcome(model_text(slot, text))
    assert isinstance(outcome, ModelError)
    assert outcome.line == SLOTS[slot]


@pytest.mark.parametrize("slot, text", [("mass", "1e100*m"), ("mass", "1e-100*m"),
                                        ("mass", "2**333*m"), ("mass", 10**300),
                                        ("y", 1e-320)])
def test_numbers_within_the_documented_range_load(slot, text):
    assert not isinstance(check_outcome(model_text(slot, text)), ModelgenError)


#: Valid, non-trivial expressions in the angle of B1 or the y of P (the bob): each
#: must compile, and its rhs must agree with the Lagrangian of the point mass below.
VALID = [
    ("angle", "atan2(sin(q), 2 + cos(q)) + q**3/3"),
    ("angle", "q + L*sin(q)**2/4 - g*q**2/40 + asin(sin(q)/2)"),
    ("angle", "q + log(1 + q**2)/4 + cosh(q/2)/5 - acos(cos(q)/3)"),
    ("y", "-L*sqrt(1 + q**2)*exp(-q/4)"),
    ("y", "-L*(2 + cos(q)**2)**1.5/(1 + tanh(q)**2) - (L + m*q**2)**(1/3)*atan(q)/g"),
]
#: states (q, q_dot) at which the rhs is compared
STATES = [(0.7, 0.4), (-1.1, -0.3), (0.2, 2.5)]


def reference_qdd(slot, text, q, qd, L=1.0, m=1.0, g=9.81):
    """q_ddot of the bob by Lagrange's equations, with sympy (independent of modelgen):
    r(q) = y (-sin a, cos a) in E, T = m |r'|^2 qd^2 / 2, V = m g r_y, so
    q_ddot = -((r' . r'') qd^2 + g r_y') / |r'|^2 (m cancels).  None where that is
    not finite or |r'|^2 is tiny (the compiled rhs may then fail or differ)."""
    import sympy
    sq, sL, sm, sg = sympy.symbols("q L m g")
    names = {"q": sq, "L": sL, "m": sm, "g": sg, "atan2": sympy.atan2, "abs": sympy.Abs,
             "sign": sympy.sign, "pi": sympy.pi}
    values = {"angle": sq, "y": -sL}
    values[slot] = sympy.sympify(text, locals=names)
    a, y = values["angle"], values["y"]
    r = sympy.Matrix([-y * sympy.sin(a), y * sympy.cos(a)])
    r1, r2 = r.diff(sq), r.diff(sq, 2)
    num = -(r1.dot(r2) * qd ** 2 + sg * r1[1])
    den = r1.dot(r1)
    at = {sq: q, sL: L, sm: m, sg: g}
    den_v = complex(den.subs(at).evalf(30))
    num_v = complex(num.subs(at).evalf(30))
    if not (np.isfinite(den_v) and np.isfinite(num_v)) or den_v.imag or num_v.imag \
            or abs(den_v) < 1e-6:
        return None
    return num_v.real / den_v.real


def check_rhs(cm, slot, text):
    """The compiled rhs at STATES against :func:`reference_qdd`; the number compared."""
    compared = 0
    for q, qd in STATES:
        ref = reference_qdd(slot, text, q, qd)
        if ref is None:
            continue
        xdot = cm.rhs(0.0, [q, qd])
        assert xdot[0] == qd, (text, xdot)
        # relative to max(1, |ref|) (the derivatives' tests' scale); measured <= 5e-16
        assert abs(xdot[1] - ref) <= 1e-13 * max(1.0, abs(ref)), (text, q, qd, xdot[1], ref)
        compared += 1
    return compared


@pytest.mark.parametrize("slot, text", VALID)
def test_valid_expressions_compile_and_their_rhs_agrees_with_lagrange(tmp_path, slot,
                                                                      text):
    spec = check_outcome(model_text(slot, text))
    assert not isinstance(spec, ModelgenError), spec
    cm = modelgen.load(spec, tmp_path)
    assert check_rhs(cm, slot, text) == len(STATES)


def test_a_model_that_validates_compiles_or_is_refused_before_the_compiler(tmp_path):
    """Grammar-shaped expressions in the angle or y slot (a reproducible draw of 150):
    those that validate and use q are built.  Each compiles, or is refused by the
    derivation (a DerivationError, e.g. a mass matrix that vanishes); never by the C
    compiler nor by any other error.  At least three compile, and their rhs agrees
    with the Lagrangian wherever that is finite and well conditioned."""
    drawn = []

    @settings(FUZZ, max_examples=150)
    @given(slot=st.sampled_from(["angle", "y"]), expression=grammar_expressions(max_leaves=5))
    def collect(slot, expression):
        drawn.append((slot, expression))
    collect()
    uses_q = re.compile(r"\bq\b")         # the coordinate, not the q of sqrt
    candidates = [(slot, text) for slot, text in dict.fromkeys(drawn)
                  if uses_q.search(text) and not isinstance(
                      check_outcome(model_text(slot, text)), ModelgenError)]
    assert len(candidates) >= 3, candidates
    built = compared = 0
    for k, (slot, text) in enumerate(candidates[:5]):
        try:
            cm = modelgen.load(parse_model(model_text(slot, text), SOURCE), tmp_path / str(k))
        except BuildError as exc:   # the C compiler must never be the one to refuse
            pytest.fail(f"{text!r} validated but did not compile: {exc}")
        except DerivationError:     # refused before the compiler (e.g. a singular A)
            continue
        built += 1
        compared += check_rhs(cm, slot, text)
    assert built >= 3 and compared >= 3, (candidates, built, compared)
