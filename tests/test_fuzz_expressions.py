"""Property-based fuzzing of expressions through the model loader.

Expression texts (grammar-shaped, random characters, deep nesting, huge
numbers, Unicode) are put into a small pendulum model and given to
:func:`modelgen.model.parse_model`.  Properties:

* only :class:`ModelgenError` subclasses escape;
* every :class:`ModelError` names the file and the line of the key;
* every case finishes within :data:`BUDGET` seconds;
* a model that validates either compiles or is refused with a ModelError
  before the compiler runs (a small sample: compiling is slow).

The run is bounded and reproducible (``derandomize=True``); ``bench/fuzz.py``
runs the same generators for thousands of cases and prints a table.
"""
from __future__ import annotations

import json
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import modelgen
from modelgen.errors import BuildError, ModelError, ModelgenError
from modelgen.model import parse_model
from modelgen.model.expr import FUNCTIONS

#: Seconds one model may take to load (validation only).
BUDGET = 2.0

SOURCE = "fuzz.yaml"

# the line of each slot's key in MODEL (1-based), for the file:line check
MODEL = """name: fuzz
coordinates: [q]
parameters: {{L: 1.0, m: 1.0, g: 9.81}}
bases: {{B1: {{parent: E, axis: 3, angle: {angle}}}}}
points: {{P: {{from: O, base: B1, coordinates: [0, {y}, 0]}}}}
bodies: {{bob: {{mass: {mass}, G: P, base: B1}}}}
gravity: [0, -g, 0]
"""
SLOTS = {"angle": 4, "y": 5, "mass": 6}
DEFAULTS = {"angle": "q", "y": "-L", "mass": "m"}


def model_text(slot: str, expression) -> str:
    """The pendulum model with ``expression`` (text or number) in ``slot``."""
    values = dict(DEFAULTS)
    values[slot] = json.dumps(expression)   # a YAML double-quoted scalar or a number
    return MODEL.format(**values)


# -- generators (shared with bench/fuzz.py) -------------------------------------------

NAMES = ["q", "q_dot", "L", "m", "g", "t", "pi", "x", "E", "sin"]
DIGIT_STRINGS = st.text("0123456789", min_size=1, max_size=450)


@st.composite
def numbers(draw):
    """Number literals: small, decimal, long, and with exponents around the limits."""
    kind = draw(st.sampled_from(["int", "decimal", "exp", "long"]))
    if kind == "int":
        return str(draw(st.integers(0, 10**6)))
    if kind == "decimal":
        return f"{draw(st.integers(0, 999))}.{draw(st.integers(0, 999))}"
    if kind == "exp":
        mantissa = draw(st.sampled_from(["1", "2.5", "9.99", "1.7976931348623157", "5"]))
        return f"{mantissa}e{draw(st.integers(-500, 500))}"
    return draw(DIGIT_STRINGS)


def _call(name_and_args):
    name, args = name_and_args
    return f"{name}({', '.join(args)})"


def grammar_expressions(max_leaves: int = 12):
    """Texts shaped like the grammar: numbers, names, operators, calls, parentheses."""
    leaves = st.one_of(numbers(), st.sampled_from(NAMES))

    def extend(children):
        return st.one_of(
            st.tuples(children, st.sampled_from(["+", "-", "*", "/", "**"]), children)
            .map(lambda t: f"{t[0]}{t[1]}{t[2]}"),
            children.map(lambda c: f"-{c}"),
            children.map(lambda c: f"({c})"),
            st.tuples(st.sampled_from(sorted(FUNCTIONS)),
                      st.lists(children, min_size=1, max_size=2)).map(_call),
        )
    return st.recursive(leaves, extend, max_leaves=max_leaves)


@st.composite
def deep_nesting(draw):
    """Deep nesting of one construct, around and far beyond MAX_DEPTH."""
    depth = draw(st.integers(1, 400))
    open_, close = draw(st.sampled_from([("sin(", ")"), ("(", ")"), ("-", ""), ("q**", ""),
                                         ("(q+", ")"), ("exp(", ")"), ("abs(", ")")]))
    return open_ * depth + draw(st.sampled_from(["q", "1", "1e300", "2"])) + close * depth


def random_texts():
    """Random characters, ASCII-heavy, with Unicode digits, letters and controls."""
    alphabet = st.one_of(st.sampled_from(list("q0123456789+-*/().,eE ^_Lmg")),
                         st.sampled_from(list("²³١٢߀０×−·√π\u00a0\u200b\t\n\\\"'#:{}[]&|")),
                         st.characters())
    return st.text(alphabet, max_size=60)


@st.composite
def huge_constants(draw):
    """Constant subexpressions whose exact evaluation is expensive or not a double."""
    inner = draw(st.sampled_from(["1e99", "10**300", "1.7976931348623157e308", "710",
                                  "2**1023", "1e-320", "(-1)", "2", "0"]))
    for _ in range(draw(st.integers(1, 4))):
        inner = draw(st.sampled_from([f"{f}({inner})" for f in sorted(FUNCTIONS)
                                      if f != "atan2"] + [f"({inner})**(10**8)",
                                                          f"(2*q*{inner})**(10**9)",
                                                          f"({inner})**(1/3)"]))
    return draw(st.sampled_from([inner, f"q + {inner}", f"{inner}*q"]))


def expressions():
    return st.one_of(grammar_expressions(), deep_nesting(), random_texts(), huge_constants())


def yaml_numbers():
    return st.one_of(st.integers(-10**400, 10**400), st.floats(allow_nan=False),
                     st.sampled_from([10**400, 1e-320, 5e-324, 1e308, -10**19, 2**63]))


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


@settings(FUZZ, max_examples=4)
@given(slot=st.sampled_from(["angle", "y"]), expression=grammar_expressions(max_leaves=5))
def test_a_model_that_validates_compiles_or_is_refused_before_the_compiler(
        tmp_path_factory, slot, expression):
    outcome = check_outcome(model_text(slot, expression))
    if isinstance(outcome, ModelgenError):
        return
    try:
        modelgen.load(outcome, tmp_path_factory.mktemp("fuzz"))
    except BuildError as exc:   # the C compiler must never be the one to refuse
        pytest.fail(f"{expression!r} validated but did not compile: {exc}")
    except ModelgenError:       # e.g. refused before the compiler, or a singular A after it
        pass
