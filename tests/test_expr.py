"""Tests of the restricted expression parser and printer (modelgen.model.expr)."""
from __future__ import annotations

import random
import time
from fractions import Fraction

import pytest
import sympy

from modelgen.errors import ExpressionError
from modelgen.model.expr import (FUNCTIONS, MAX_DEPTH, MAX_LENGTH, MAX_NUMBER_CHARS,
                                 ExpressionParseError, format_expression, parse_expression)
from modelgen.model.spec import TIME, symbol

x, y, z, m, l = (symbol(n) for n in ("x", "y", "z", "m", "l"))
ALLOWED = {"x": x, "y": y, "z": z, "m": m, "l": l, "t": TIME}


def parse(text, allowed=ALLOWED, **kw):
    return parse_expression(text, allowed, **kw)


def message(text, allowed=ALLOWED, **kw) -> str:
    with pytest.raises(ExpressionError) as info:
        parse_expression(text, allowed, **kw)
    return str(info.value)


# -- numbers -----------------------------------------------------------------------

@pytest.mark.parametrize("text, value", [
    ("3", sympy.Integer(3)),
    ("0.1", sympy.Rational(1, 10)),
    (".5", sympy.Rational(1, 2)),
    ("2.", sympy.Integer(2)),
    ("1e-3", sympy.Rational(1, 1000)),
    ("2.5E+2", sympy.Integer(250)),
    ("007", sympy.Integer(7)),
])
def test_number_literals_are_exact_rationals(text, value):
    result = parse(text)
    assert result == value
    assert isinstance(result, sympy.Rational)   # never a Float


def test_decimal_sum_is_exact_not_binary_floating_point():
    assert parse("0.1 + 0.2") == sympy.Rational(3, 10)


@pytest.mark.parametrize("number, value", [
    (9.81, sympy.Rational(981, 100)),
    (0.1, sympy.Rational(1, 10)),
    (1e-05, sympy.Rational(1, 100000)),
    (3, sympy.Integer(3)),
    (-2, sympy.Integer(-2)),
])
def test_yaml_numbers_become_exact_rationals_of_their_repr(number, value):
    assert parse_expression(number, {}) == value


@pytest.mark.parametrize("value", [True, False])
def test_booleans_are_rejected(value):
    assert message(value) == (f"expected an expression but got the boolean {value}; "
                              "write a number or an expression")


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_floats_are_rejected(value):
    assert message(value) == f"{value!r} is not a finite number; write a finite number"


def test_other_python_types_are_rejected():
    assert message([1, 2]) == ("expected an expression but got a list; "
                               "write a number or an expression string")


# -- grammar -----------------------------------------------------------------------

@pytest.mark.parametrize("text, expected", [
    ("-x**2", -(x**2)),
    ("(-x)**2", x**2),
    ("2**-1", sympy.Rational(1, 2)),
    ("2**3**2", sympy.Integer(512)),           # right-associative: 2**9
    ("x**y**z", x**(y**z)),
    ("x - y - z", x - y - z),                   # left-associative
    ("x/y/z", x / (y * z)),
    ("-x*y", -x * y),
    ("- -x", x),
    ("+x", x),
    ("2**-x*y", 2**(-x) * y),                   # as in Python
    ("x + y*z**2", x + y * z**2),
    ("(x + y)/2", x / 2 + y / 2),
    ("m*l**2/12", m * l**2 / 12),
])
def test_precedence_and_associativity_follow_python(text, expected):
    assert parse(text) == expected


def test_products_are_built_in_one_call():
    # documented difference from Python's pairwise '*': 2*(x+y)*z stays factored
    assert parse("2*(x + y)*z") == sympy.Mul(2, z, x + y)
    assert parse("2*(x + y)*z") != 2 * (x + y) * z


@pytest.mark.parametrize("name", sorted(set(FUNCTIONS) - {"atan2"}))
def test_every_whitelisted_function_maps_to_its_sympy_function(name):
    function, arity = FUNCTIONS[name]
    assert arity == 1
    assert parse(f"{name}(x)") == function(x)


def test_abs_is_sympy_abs_and_atan2_takes_two_arguments():
    assert parse("abs(x)") == sympy.Abs(x)
    assert parse("atan2(y, x)") == sympy.atan2(y, x)


def test_pi_is_the_constant_and_exp_of_one_is_euler():
    assert parse("pi/2") == sympy.pi / 2
    assert parse("exp(1)") is sympy.E


def test_time_is_only_available_when_allowed():
    assert parse("sin(t)") == sympy.sin(TIME)
    assert message("t", {"x": x}, kinds="x only") == (
        "undefined name 't' at column 1 of 't'; allowed here: x only")


def test_returned_symbols_are_the_allowed_ones():
    q = sympy.Symbol("q")
    assert parse("q", {"q": q}).free_symbols == {q}


def test_sympy_input_is_validated_and_normalised():
    real_x = sympy.Symbol("x", real=True)
    assert parse(3 * real_x) == 3 * x
    assert parse(sympy.Float(0.25) * x) == x / 4
    with pytest.raises(ExpressionParseError, match="undefined name 'w'"):
        parse(sympy.Symbol("w") + 1)
    with pytest.raises(ExpressionParseError, match="not part of modelgen's expression"):
        parse(sympy.Function("f")(x))


def test_whitespace_including_newlines_is_ignored():
    assert parse(" x\n+\ty ") == x + y


# -- error messages ----------------------------------------------------------------

@pytest.mark.parametrize("text, expected", [
    ("x*", "expected a number, a name, '(' or '-' but found the end of the expression "
           "at column 3 of 'x*'"),
    ("(x", "expected ')' but found the end of the expression at column 3 of '(x'; "
           "close the '(' opened at column 1"),
    ("x)", "unmatched ')' at column 2 of 'x)'; remove it or add the missing '('"),
    ("x y", "expected an operator or the end of the expression but found 'y' at column 3 "
            "of 'x y'; join terms with + - * / or **"),
    ("x^2", "unexpected character '^' at column 2 of 'x^2'; write powers as x**2"),
    ("2x", "missing operator between '2' and 'x' at column 2 of '2x'; write 2*x for a product"),
    ("1e", "malformed number '1e' at column 1 of '1e'; write numbers like 3, 0.25 or 1.5e-3"),
    ("1.2.3", "malformed number '1.2.3' at column 1 of '1.2.3'; "
              "write numbers like 3, 0.25 or 1.5e-3"),
    ("sin", "function 'sin' must be called at column 1 of 'sin'; write sin(...)"),
    ("foo(x)", "'foo' is not a function at column 1 of 'foo(x)'; the functions are "
               "sin cos tan asin acos atan atan2 sinh cosh tanh exp log sqrt abs sign"),
    ("sin(x, y)", "function 'sin' takes 1 argument but was given 2 at column 1 of "
                  "'sin(x, y)'; write sin(x)"),
    ("atan2(y)", "function 'atan2' takes 2 arguments but was given 1 at column 1 of "
                 "'atan2(y)'; write atan2(y, x)"),
    ("sqrt()", "function 'sqrt' takes 1 argument but was given 0 at column 1 of 'sqrt()'; "
               "write sqrt(x)"),
    ("", "empty expression; write a number or an expression"),
    ("x $ y", "unexpected character '$' at column 3 of 'x $ y'; use numbers, names, "
              "+ - * / **, parentheses and the functions sin cos tan asin acos atan atan2 "
              "sinh cosh tanh exp log sqrt abs sign"),
    ("é", "unexpected character 'é' at column 1 of 'é'; names use ASCII letters, digits "
          "and '_'"),
])
def test_syntax_errors_give_column_and_fix(text, expected):
    assert message(text) == expected


def test_undefined_name_lists_allowed_kinds_when_given():
    assert message("x + q9", kinds="coordinates, parameters and t") == (
        "undefined name 'q9' at column 5 of 'x + q9'; "
        "allowed here: coordinates, parameters and t")


def test_undefined_name_lists_allowed_names_otherwise():
    assert message("w") == ("undefined name 'w' at column 1 of 'w'; "
                            "allowed names: l, m, t, x, y, z")
    assert message("w", {}) == "undefined name 'w' at column 1 of 'w'; no names are allowed here"


def test_undefined_name_error_carries_the_name_and_column():
    with pytest.raises(ExpressionParseError) as info:
        parse("x*foo_bar")
    assert (info.value.name, info.value.column, info.value.text) == ("foo_bar", 3, "x*foo_bar")


@pytest.mark.parametrize("text, expected", [
    ("1/0", "division by zero at column 2 of '1/0'; check the divisor"),
    ("x/(y - y)", "division by zero at column 2 of 'x/(y - y)'; check the divisor"),
    ("0**-1", "division by zero (0 to a negative power) at column 2 of '0**-1'; "
              "check the base and the exponent"),
    ("log(0)", "log(...) is not a finite real number here at column 1 of 'log(0)'; "
               "check the argument"),
    ("sqrt(-1)", "sqrt(...) is not a finite real number here at column 1 of 'sqrt(-1)'; "
                 "check the argument"),
    ("tan(pi/2)", "tan(...) is not a finite real number here at column 1 of 'tan(pi/2)'; "
                  "check the argument"),
    ("(-8)**(1/2)", "the power is not a finite real number at column 5 of '(-8)**(1/2)'; "
                    "check the base and the exponent"),
])
def test_non_finite_or_complex_results_are_refused(text, expected):
    assert message(text) == expected


def test_code_injection_attempts_are_refused():
    assert message("__import__(x)") == (
        "'__import__' is not a function at column 1 of '__import__(x)'; the functions are "
        "sin cos tan asin acos atan atan2 sinh cosh tanh exp log sqrt abs sign")
    for text in ("__import__('os')", "x.__class__", "[x for x in y]", "lambda: 1"):
        with pytest.raises(ExpressionParseError, match="unexpected character"):
            parse(text)


# -- limits on hostile input ---------------------------------------------------------

def test_nesting_up_to_the_limit_is_accepted():
    assert parse("(" * (MAX_DEPTH - 1) + "x" + ")" * (MAX_DEPTH - 1)) == x
    assert parse("-" * (MAX_DEPTH - 2) + "x") == x
    nested = "sin(" * (MAX_DEPTH - 1) + "x" + ")" * (MAX_DEPTH - 1)
    result = parse(nested)
    assert result.count(sympy.sin) == MAX_DEPTH - 1


def test_nesting_beyond_the_limit_is_refused_without_recursion_error():
    for text in ("(" * 3000 + "x" + ")" * 3000, "-" * 5000 + "x", "x" + "**x" * 3000):
        with pytest.raises(ExpressionParseError,
                           match=f"nested more than {MAX_DEPTH} levels deep"):
            parse(text)


def test_overlong_text_is_refused():
    assert message("x+" * (MAX_LENGTH // 2) + "x") == (
        f"expression is {MAX_LENGTH + 1} characters long; use at most {MAX_LENGTH} characters")


def test_power_towers_are_refused_before_computing_them():
    assert message("2**2**2**2**2") == (
        "the power is too large to compute exactly at column 2 of '2**2**2**2**2'; "
        "use a smaller exponent")
    assert message("10**1e300") .startswith("the power is too large")


def test_huge_number_literals_are_refused():
    too_long = MAX_NUMBER_CHARS + 1
    assert message("9" * too_long).startswith(
        f"number literal is {too_long} characters long at column 1")
    assert message("1e401") == ("exponent of '1e401' is out of range at column 1 of '1e401'; "
                                "use exponents between -400 and 400")


def test_long_sum_of_allowed_terms_is_parsed():
    text = "+".join(f"sin({i}*x)" for i in range(1, 700))
    assert len(text) < MAX_LENGTH
    assert len(parse(text).args) == 699



# -- budgets: refused before sympy evaluates anything expensive -----------------------

@pytest.mark.parametrize("text", [
    "(x/100)**(10**8)", "(2*x)**(10**9)", "(sqrt(2)*x)**20001", "tanh(tan(sinh(1e99)))",
    "acos(cos(cosh(1.7976931348623157e308)))", "acos(cos(10**300))", "exp(exp(exp(10)))",
])
def test_pathological_constants_and_powers_are_refused_at_once(text):
    start = time.perf_counter()
    with pytest.raises(ExpressionParseError):
        parse(text)
    assert time.perf_counter() - start < 1.0


def test_overflowing_constants_are_refused_naming_the_function():
    assert message("tanh(tan(sinh(1e99)))") == (
        "sinh(...) is not a finite real number here at column 10 of "
        "'tanh(tan(sinh(1e99)))'; check the argument")
    assert message("sin(10**300)*x") == (
        "the argument of sin(...) is too large at column 1 of 'sin(10**300)*x'; use "
        "constant arguments of at most 1e+15 in magnitude")


@pytest.mark.parametrize("text, where", [
    ("(-1)**(1/3)", "the power is not a finite real number"),
    ("x + (-8)**(2/3)", "the power is not a finite real number"),
    ("acos(2)*x", "acos(...) is not a finite real number here"),
    ("x - asin(2)", "asin(...) is not a finite real number here"),
    ("x*log(0)", "log(...) is not a finite real number here"),
    ("x*log(-1)", "log(...) is not a finite real number here"),
])
def test_complex_or_undefined_constants_are_refused(text, where):
    assert message(text).startswith(where)


@pytest.mark.parametrize("text", ["x*\u00b2", "x + \u0661", "\u0662*x", "x\u00b2"])
def test_unicode_digits_are_refused_by_name(text):
    text = text.encode().decode("unicode-escape")
    assert "unexpected character" in message(text)


@pytest.mark.parametrize("text, value", [
    ("1e100*x", sympy.Integer(10)**100 * x), ("1e-100*x", x / sympy.Integer(10)**100),
    ("2**333*x", sympy.Integer(2)**333 * x), ("1e400/1e300*x", sympy.Integer(10)**100 * x),
    ("5e-324*x", sympy.Rational(5, 10**324) * x),
])
def test_numbers_within_double_range_are_accepted_and_round_trip(text, value):
    result = parse(text)
    assert result == value
    assert parse(format_expression(result)) == result


@pytest.mark.parametrize("text, problem", [
    ("1e400*x", "the number 1e400 is beyond the range of a double"),
    ("x/3e-320", "the number 1e320/3 is beyond the range of a double"),
    ("1e-400*x", "the number 1e-400 is too small for a double (it would be 0)"),
    ("(1e-200)**2*x + 1", "the number 1e-400 is too small for a double (it would be 0)"),
    ("x**(10**400)", "the number 1e400 is beyond the range of a double"),
])
def test_numbers_beyond_double_range_are_refused(text, problem):
    assert message(text).startswith(f"{problem} in ")


@pytest.mark.parametrize("value", [10**400, -10**309, Fraction(1, 10**400)])
def test_yaml_numbers_go_through_the_same_limits(value):
    assert "range of a double" in message(value) or "too small" in message(value)


@pytest.mark.parametrize("value", [10**308, 1e-320, 5e-324, 1.7976931348623157e308, -10**19])
def test_yaml_numbers_in_range_round_trip(value):
    result = parse(value)
    assert parse(format_expression(result)) == result


def test_large_integers_are_written_compactly():
    assert format_expression(sympy.Integer(10)**19 * x) == "1e19*x"
    assert format_expression(sympy.Rational(3, 10**20)) == "3e-20"
    assert format_expression(sympy.Integer(1000) * x) == "1000*x"


# -- printer -----------------------------------------------------------------------

@pytest.mark.parametrize("expr, text", [
    (sympy.Abs(x), "abs(x)"),
    (sympy.E, "exp(1)"),
    (sympy.exp(x), "exp(x)"),
    (sympy.Rational(3, 4), "3/4"),
    (sympy.Rational(-3, 4), "-3/4"),
    (sympy.pi / 2, "pi/2"),
    (-x**2, "-x**2"),
    ((-x)**3, "-x**3"),
    (x**-1, "1/x"),
    (sympy.sqrt(x), "sqrt(x)"),
    (1 / sympy.sqrt(x), "1/sqrt(x)"),
    (x**sympy.Rational(1, 3), "x**(1/3)"),
    (x**(-y), "x**(-y)"),
    ((x + y)**2, "(x + y)**2"),
    (x - y, "x - y"),
    (x / (y * z), "x/y/z"),
    (sympy.atan2(y, x), "atan2(y, x)"),
    (sympy.sign(x) * m, "m*sign(x)"),
    (sympy.Float(9.81), "9.81"),
    (sympy.Mul(-1, x + y, 1 / z), "-1*(x + y)/z"),
])
def test_format_writes_the_grammar(expr, text):
    assert format_expression(expr) == text


def test_format_accepts_python_numbers():
    assert format_expression(3) == "3"
    assert format_expression(0.5) == "0.5"


@pytest.mark.parametrize("expr", [sympy.I * x, sympy.oo, sympy.Function("f")(x),
                                  sympy.Float("inf"), sympy.Derivative(x * y, x)])
def test_format_refuses_anything_outside_the_grammar(expr):
    with pytest.raises(ExpressionParseError):
        format_expression(expr)


def _random_expression(rng: random.Random, depth: int) -> str:
    """A random string of the grammar (may be invalid, e.g. log(0))."""
    if depth == 0 or rng.random() < 0.25:
        choice = rng.random()
        if choice < 0.5:
            return rng.choice(["x", "y", "z", "m", "l", "t", "pi"])
        if choice < 0.75:
            return str(rng.randint(0, 12))
        return rng.choice(["0.5", "1.25", "2e-3", ".75", "3.0"])
    kind = rng.random()
    a = _random_expression(rng, depth - 1)
    if kind < 0.45:
        b = _random_expression(rng, depth - 1)
        op = rng.choice(["+", "-", "*", "/", "**"])
        if op == "**":
            b = rng.choice(["2", "3", "-1", "(1/2)", "(-3/2)", "y", "(x + 1)"])
        return f"({a} {op} {b})"
    if kind < 0.55:
        return f"-{a}"
    name = rng.choice(sorted(FUNCTIONS))
    if name == "atan2":
        return f"atan2({a}, {_random_expression(rng, depth - 1)})"
    return f"{name}({a})"


def test_format_then_parse_round_trips_structurally():
    rng = random.Random(20240517)
    checked = 0
    for _ in range(600):
        text = _random_expression(rng, 4)
        try:
            expr = parse(text)
        except ExpressionParseError:
            continue   # e.g. a random division by zero
        printed = format_expression(expr)
        again = parse(printed)
        assert again == expr, (text, printed)
        assert format_expression(again) == printed   # the printer is deterministic
        checked += 1
    assert checked > 400


def test_round_trip_of_expressions_sympy_built_by_hand():
    for expr in (m * l**2 / 12 + m * sympy.Rational(1, 50)**2 / 4,
                 -sympy.cos(x) * sympy.sin(y) / (1 + x**2),
                 sympy.exp(-TIME / 2) * sympy.atan2(y, -x),
                 2 * z * (x + y), sympy.sqrt(2) * x / 3, (x + 1)**-2,
                 sympy.Mul(-1, x + y, sympy.asin(z)**-1), -(x + 1)**2 / y):
        assert parse(format_expression(expr)) == expr
