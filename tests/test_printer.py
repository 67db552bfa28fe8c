"""The printer's direct walk (ModelPrinter._fast) against sympy's own C99 printer
(ModelPrinter._slow), statement by statement, on the routines of real models:
the two C texts, evaluated as Python with random inputs, agree to rounding."""
from __future__ import annotations

import math
import random
import re

import pytest
import sympy

import modelgen
from modelgen.codegen.printer import ModelPrinter, c_operations
from modelgen.errors import DerivationError

from conftest import MODELS, SCENES

C_FUNCTIONS = {name: getattr(math, name) for name in (
    "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp",
    "log", "sqrt", "fabs", "pow")}
C_FUNCTIONS.update(mg_sin=math.sin, mg_cos=math.cos)


def _namespace(texts, rng):
    ns = dict(C_FUNCTIONS)
    for text in texts:
        for name in re.findall(r"\b([A-Za-z_]\w*)\[", text):
            ns.setdefault(name, [rng.uniform(0.3, 1.7) for _ in range(4096)])
        for name in re.findall(r"\b(v\d+|t)\b", text):
            ns.setdefault(name, rng.uniform(0.3, 1.7))
    return ns


def _value(text, ns):
    try:
        return eval(text.replace("(double)", "float"), ns)     # noqa: S307 - our own C text
    except (ValueError, ZeroDivisionError, OverflowError):
        return None


def _printed(source, options, tmp_path, monkeypatch) -> list:
    """(printer, expression, C text) of every expression printed while
    building the model or scene ``source`` (fresh, into ``tmp_path``)."""
    seen = []
    fast = ModelPrinter.doprint

    def record(self, expr, assign_to=None):
        text = fast(self, expr)
        seen.append((self, expr, text))
        return text
    monkeypatch.setattr(ModelPrinter, "doprint", record)
    if source.parent == SCENES:
        modelgen.load_scene(source, tmp_path)
    else:
        modelgen.load(source, tmp_path, **options)
    return seen


@pytest.mark.parametrize("source, options", [
    (MODELS / "double_pendulum.yaml", {"formulation": "crba", "jacobian": True}),
    (MODELS / "arm7.yaml", {}),
    (MODELS / "heavy_top.yaml", {"jacobian": True}),
    (MODELS / "spring_chain.yaml", {"formulation": "crba"}),
    (SCENES / "dp_damped.yaml", {}),
    (SCENES / "block_friction.yaml", {}),
])
def test_the_direct_walk_prints_what_sympys_printer_prints(source, options, tmp_path,
                                                             monkeypatch):
    pairs = [(text, printer._slow(expr))
             for printer, expr, text in _printed(source, options, tmp_path, monkeypatch)]
    assert len(pairs) > 50
    rng = random.Random(1)
    compared = 0
    for mine, theirs in pairs:
        ns = _namespace([mine, theirs], rng)
        a, b = _value(mine, ns), _value(theirs, ns)
        if a is None and b is None:
            continue
        assert a is not None and b is not None, (mine, theirs)
        assert math.isclose(a, b, rel_tol=1e-13, abs_tol=1e-13 * (1 + abs(b))), (mine, theirs)
        compared += 1
    assert compared > 0.9 * len(pairs)


def test_what_the_walk_does_not_know_goes_to_sympys_printer_strictly():
    x = sympy.Symbol("x")
    printer = ModelPrinter({x: "q[0]"}, "rhs")
    assert printer.doprint(sympy.floor(x) + 1) == "1.0 + (floor(q[0]))"
    with pytest.raises(DerivationError, match="cannot print .* in routine rhs"):
        printer.doprint(sympy.Derivative(sympy.Function("f")(x), x))
    assert printer.doprint(-x / 3 + x**-2) == "1.0/(q[0]*q[0]) - 1.0/3.0*q[0]"
    assert printer.doprint(sympy.sqrt(x) / (x + 1) / x) == "1.0/(sqrt(q[0])*(1.0 + q[0]))"
    assert printer.doprint(2 * x * (x - 1)**3 / sympy.sin(x)) == \
        "2.0*q[0]*((q[0] - 1.0)*(q[0] - 1.0)*(q[0] - 1.0))/mg_sin(q[0])"


_TOKEN = re.compile(r"\s*(?:(?P<num>\d+\.\d*(?:e[+-]?\d+)?)|(?P<name>[A-Za-z_]\w*(?:\[\d+\])?)"
                    r"|(?P<op>[-+*/(),]))")


def _operators_in(text: str) -> int:
    """Floating-point operations in a printed C expression, read off the text:
    binary + - * /, a unary minus, a function call; a literal's own minus and
    a quotient of two literals (constant folding) cost nothing."""
    tokens = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        assert m and m.end() > pos, text[pos:]
        kind = m.lastgroup
        tokens.append((kind, m.group(kind)))
        pos = m.end()
    count = 0
    for i, (kind, tok) in enumerate(tokens):
        before = tokens[i - 1] if i else ("op", "(")
        after = tokens[i + 1] if i + 1 < len(tokens) else ("op", ")")
        if kind == "name" and after == ("op", "("):
            count += 1                                   # a call
        elif tok == "-" and before[0] == "op" and before[1] != ")":
            count += after[0] != "num"                   # unary minus
        elif tok in "+-*" and kind == "op":
            count += 1
        elif tok == "/":
            count += not (before[0] == "num" and after[0] == "num")
    return count


@pytest.mark.parametrize("source, options", [
    (MODELS / "arm7.yaml", {"jacobian": True}),
    (MODELS / "heavy_top.yaml", {"formulation": "crba", "jacobian": True}),
    (SCENES / "block_friction.yaml", {}),
])
def test_the_operation_count_is_the_operators_of_the_printed_c(source, options, tmp_path,
                                                               monkeypatch):
    """c_operations (the counts in manifests and benchmarks) against the
    operators in the C text the printer writes, statement by statement."""
    seen = [(expr, text) for _, expr, text in _printed(source, options, tmp_path, monkeypatch)]
    assert len(seen) > 50
    wrong = [(text, c_operations(e), _operators_in(text)) for e, text in seen
             if c_operations(e) != _operators_in(text)]
    assert not wrong, wrong[:5]
