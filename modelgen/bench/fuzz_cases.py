"""Generated inputs for fuzzing the model loader: expression texts and YAML numbers
(hypothesis strategies), each put into one slot of a small pendulum model.

Shared by ``tests/test_fuzz_expressions.py`` (a bounded, derandomized run) and
``bench/fuzz.py`` (thousands of cases, :func:`draw_cases`).  Needs hypothesis
(the ``test`` extra); ``modelgen.bench`` does not import this module.

>>> print(model_text("mass", "2*m").splitlines()[SLOTS["mass"] - 1])
bodies: {bob: {mass: "2*m", G: P, base: B1}}
"""
from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

from modelgen.model.expr import FUNCTIONS

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


# -- generators ------------------------------------------------------------------------

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


def draw_cases(n: int, seed: int) -> list:
    """``n`` model texts, each an expression or a YAML number in one slot, reproducibly."""
    cases = []
    any_case = st.one_of(
        st.tuples(st.sampled_from(sorted(SLOTS)), expressions()),
        st.tuples(st.sampled_from(sorted(SLOTS)), yaml_numbers()))

    @hypothesis_seed(seed)
    @settings(max_examples=n, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(any_case)
    def collect(case):
        cases.append(model_text(*case))

    collect()
    return cases
