"""A restricted expression language for model files, and its printer.

Model files are untrusted input, so their expressions are never given to
``eval`` or ``sympy.sympify``.  This module reads them with a small
hand-written tokenizer and a Pratt parser and builds sympy expressions
directly.  The grammar, loosest binding first::

    expression := term (('+' | '-') term)*
    term       := unary (('*' | '/') unary)*
    unary      := ('-' | '+') unary | power
    power      := atom ('**' unary)?            # right-associative
    atom       := number | name | name '(' arguments ')' | '(' expression ')'

so, as in Python, ``-x**2`` is ``-(x**2)``, ``2**-1`` is ``1/2`` and
``a**b**c`` is ``a**(b**c)``.

* Numbers: ``3``, ``0.25``, ``.5``, ``1e-3``, ``2.5E+2``.  They are exact:
  ``0.1`` is ``Rational(1, 10)``, never a float.
* Names: ``[A-Za-z_][A-Za-z0-9_]*``, looked up in the ``allowed`` mapping
  (the caller decides which coordinates, parameters... and whether time
  ``t`` may appear).  ``pi`` is always the constant pi.
* Functions (fixed whitelist): ``sin cos tan asin acos atan sinh cosh tanh
  exp log sqrt abs sign`` take one argument and ``atan2`` two.  ``abs`` is
  ``sympy.Abs``; Euler's number is written ``exp(1)``.

Sums and products are built in one call (``sympy.Add(*terms)``,
``sympy.Mul(*factors)``) rather than pairwise, which keeps long chains
linear in time.  sympy's automatic simplification still applies: ``x + x``
gives ``2*x`` and ``(x + y)/2`` gives ``x/2 + y/2``.  One visible
consequence of building products in one call: ``2*(x + y)*z`` stays
``2*z*(x + y)`` (Python's pairwise ``*`` would give ``z*(2*x + 2*y)``).

Limits (model files are untrusted input; every limit is checked while
parsing, before sympy evaluates anything expensive, and a violation is an
:class:`ExpressionParseError`, which the loader reports with file, line and key):

* text: at most :data:`MAX_LENGTH` characters, ASCII only (``x²``, ``١`` and
  other non-ASCII characters are refused by name);
* nesting depth (parentheses, signs, powers, function calls, operands) at most
  :data:`MAX_DEPTH`;
* number literals: at most :data:`MAX_NUMBER_CHARS` characters, decimal
  exponents from -:data:`MAX_EXPONENT` to :data:`MAX_EXPONENT` (``1e-400`` to
  ``1e400``); the same holds for the numerator and denominator of every
  number in the result, and for YAML numbers;
* values: every number and every constant subexpression (``sqrt(2)``,
  ``sin(1)``, ``2**(1/3)``) must be a finite real double: at most about
  1.8e308 in magnitude, not so small that it becomes 0 (subnormals down to
  5e-324 are fine), not complex (``(-1)**(1/3)``, ``acos(2)``) and not
  undefined (``1/0``, ``log(0)``).  Constants are evaluated in double
  precision before sympy sees them, so ``tanh(tan(sinh(1e99)))`` is refused
  at once (sinh overflows) instead of sending sympy into an unbounded search.
  Intermediate exact values may exceed the double range (``1e400/1e300`` is
  ``1e100``);
* exact powers: sympy computes powers and rational roots of the numbers in a
  base exactly (also in ``(2*x)**(10**9)``, and ``212.124**5e-209`` is a root of
  degree 2e208), so such a power or root may need at most
  :data:`MAX_POWER_BITS` bits;
* a constant argument of sin, cos or tan is at most
  :data:`MAX_PERIODIC_ARGUMENT` in magnitude.

:func:`format_expression` writes a sympy expression back in this grammar, so
that ``parse_expression(format_expression(e), allowed) == e``.  To make that
hold despite sympy's automatic evaluation (which is not always idempotent,
and which can leave the grammar because names are not assumed real, e.g.
``abs(exp(x))`` becomes ``exp(re(x))``), :func:`parse_expression` prints and
re-parses its result until nothing changes, and refuses expressions that
sympy rewrites into something the grammar cannot express.
"""
from __future__ import annotations

import math
import numbers
import re
import sys
from fractions import Fraction
from typing import Mapping, Optional

import sympy

from modelgen.errors import ExpressionError
from modelgen.model.expr_print import (FUNCTION_NAMES, MAX_TEXT_BITS, Unprintable,
                                       expression_text, integer_text)

__all__ = [
    "FUNCTIONS", "CONSTANTS", "MAX_LENGTH", "MAX_DEPTH", "MAX_NUMBER_CHARS",
    "MAX_EXPONENT", "MAX_POWER_BITS", "MAX_PERIODIC_ARGUMENT", "ExpressionParseError",
    "parse_expression", "format_expression",
]

#: Longest expression text accepted, in characters.
MAX_LENGTH = 10_000
#: Deepest nesting accepted (parentheses, unary signs, powers, calls, operands).
MAX_DEPTH = 32
#: Longest number literal accepted, in characters (also the most digits of the
#: numerator or denominator of a number in a parsed expression).
MAX_NUMBER_CHARS = 400
#: Largest decimal exponent accepted in a number literal (``1e400``).
MAX_EXPONENT = 400
#: Largest exact power of numbers that is computed, in bits.
MAX_POWER_BITS = 10_000
#: Largest magnitude of a constant argument of sin, cos or tan.
MAX_PERIODIC_ARGUMENT = 1e15

#: Function name -> (sympy function, number of arguments).
FUNCTIONS: Mapping[str, tuple] = {
    "sin": (sympy.sin, 1), "cos": (sympy.cos, 1), "tan": (sympy.tan, 1),
    "asin": (sympy.asin, 1), "acos": (sympy.acos, 1), "atan": (sympy.atan, 1),
    "atan2": (sympy.atan2, 2),
    "sinh": (sympy.sinh, 1), "cosh": (sympy.cosh, 1), "tanh": (sympy.tanh, 1),
    "exp": (sympy.exp, 1), "log": (sympy.log, 1), "sqrt": (sympy.sqrt, 1),
    "abs": (sympy.Abs, 1), "sign": (sympy.sign, 1),
}

#: Named constants of the grammar.
CONSTANTS: Mapping[str, sympy.Expr] = {"pi": sympy.pi}

_GRAMMAR_HINT = ("use numbers, names, + - * / **, parentheses and the functions "
                 + " ".join(FUNCTIONS))

_NOT_FINITE_REAL = (sympy.S.ImaginaryUnit, sympy.S.ComplexInfinity,
                    sympy.S.NaN, sympy.S.Infinity, sympy.S.NegativeInfinity)


class ExpressionParseError(ExpressionError):
    """An expression was rejected; the pieces are kept for better messages.

    ``reason`` says what is wrong, ``column`` is the 1-based column in
    ``text`` (None when the error is not tied to a position), ``hint`` says
    how to fix it and ``name`` is the offending name for an undefined name
    (None otherwise).  ``str(error)`` combines them.

    >>> try:
    ...     parse_expression("2*", {})
    ... except ExpressionParseError as e:
    ...     print(e.reason, e.column)
    expected a number, a name, '(' or '-' but found the end of the expression 3
    """

    def __init__(self, reason: str, text: Optional[str], column: Optional[int] = None,
                 hint: Optional[str] = None, name: Optional[str] = None):
        self.reason = reason
        self.text = text
        self.column = column
        self.hint = hint
        self.name = name
        message = reason
        if column is not None:
            message += f" at column {column} of {_quote(text)}"
        elif text is not None:
            message += f" in {_quote(text)}"
        if hint:
            message += f"; {hint}"
        super().__init__(message)


def _quote(text: str) -> str:
    """Quote an expression for a message, shortening very long ones."""
    if len(text) > 80:
        text = text[:60] + "..." + text[-15:]
    return repr(text)


# -- tokenizer ---------------------------------------------------------------

_NUMBER = re.compile(r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_WORD_TAIL = re.compile(r"[A-Za-z0-9_.]*")
_OPERATORS = ("**", "+", "-", "*", "/", "(", ")", ",")
_DIGITS = "0123456789"


class _Token:
    __slots__ = ("kind", "text", "column", "value")

    def __init__(self, kind: str, text: str, column: int, value=None):
        self.kind = kind        # "number", "name", "op" or "end"
        self.text = text
        self.column = column    # 1-based
        self.value = value

    def describe(self) -> str:
        if self.kind == "end":
            return "the end of the expression"
        return repr(self.text)


def _tokenize(text: str) -> list:
    tokens = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in " \t\r\n":
            i += 1
            continue
        column = i + 1
        if not c.isascii() and (c.isdigit() or c.isnumeric()):
            raise ExpressionParseError(
                f"unexpected character {c!r}", text, column,
                "write numbers with the ASCII digits 0-9 and powers as x**2")
        if c in _DIGITS or (c == "." and i + 1 < n and text[i + 1] in _DIGITS):
            match = _NUMBER.match(text, i)
            end = match.end()
            tail = _WORD_TAIL.match(text, end).group()
            if tail:
                literal = text[i:end]
                if tail[0] in "eE.":
                    raise ExpressionParseError(
                        f"malformed number {literal + tail!r}", text, column,
                        "write numbers like 3, 0.25 or 1.5e-3")
                raise ExpressionParseError(
                    f"missing operator between {literal!r} and {tail!r}", text,
                    end + 1, f"write {literal}*{tail} for a product")
            tokens.append(_Token("number", text[i:end], column,
                                 _number(text[i:end], text, column)))
            i = end
            continue
        if c.isalpha() or c == "_":
            match = _NAME.match(text, i)
            if match is None:  # a non-ASCII letter
                raise ExpressionParseError(
                    f"unexpected character {c!r}", text, column,
                    "names use ASCII letters, digits and '_'")
            tokens.append(_Token("name", match.group(), column))
            i = match.end()
            continue
        for op in _OPERATORS:
            if text.startswith(op, i):
                tokens.append(_Token("op", op, column))
                i += len(op)
                break
        else:
            hint = _GRAMMAR_HINT
            if c == "^":
                hint = "write powers as x**2"
            raise ExpressionParseError(f"unexpected character {c!r}", text,
                                       column, hint)
    tokens.append(_Token("end", "", n + 1))
    return tokens


def _number(literal: str, text: str, column: int) -> sympy.Rational:
    """Exact value of a number literal (already matched by ``_NUMBER``)."""
    if len(literal) > MAX_NUMBER_CHARS:
        raise ExpressionParseError(
            f"number literal is {len(literal)} characters long", text, column,
            f"use at most {MAX_NUMBER_CHARS} characters (e.g. exponent notation)")
    mantissa, _, exponent = literal.lower().partition("e")
    if exponent and abs(int(exponent)) > MAX_EXPONENT:
        raise ExpressionParseError(
            f"exponent of {literal!r} is out of range", text, column,
            f"use exponents between -{MAX_EXPONENT} and {MAX_EXPONENT}")
    if not exponent and "." not in mantissa:
        return sympy.Integer(int(mantissa))
    value = Fraction(literal)
    return sympy.Rational(value.numerator, value.denominator)


# -- parser ------------------------------------------------------------------

# binding powers: + - 10, * / 20, unary sign 25, ** 30 (right-associative)
_BINARY = {"+": 10, "-": 10, "*": 20, "/": 20, "**": 30}
_UNARY_BP = 25


class _Parser:
    def __init__(self, text: str, allowed: Mapping[str, sympy.Symbol],
                 kinds: Optional[str]):
        self.text = text
        self.allowed = allowed
        self.kinds = kinds
        self.tokens = _tokenize(text)
        self.pos = 0
        self.values: dict = {}

    def error(self, reason: str, column: Optional[int], hint: Optional[str] = None,
              name: Optional[str] = None) -> ExpressionParseError:
        return ExpressionParseError(reason, self.text, column, hint, name)

    def peek(self) -> _Token:
        return self.tokens[self.pos]

    def take(self) -> _Token:
        token = self.tokens[self.pos]
        self.pos += 1
        return token

    def expect(self, op: str, opened: Optional[_Token] = None) -> None:
        token = self.take()
        if token.kind == "op" and token.text == op:
            return
        hint = None
        if opened is not None:
            hint = f"close the '{opened.text}' opened at column {opened.column}"
        raise self.error(f"expected '{op}' but found {token.describe()}",
                         token.column, hint)

    def parse(self) -> sympy.Expr:
        result = self.expression(0, 1)
        token = self.peek()
        if token.kind != "end":
            if token.kind == "op" and token.text == ")":
                raise self.error("unmatched ')'", token.column,
                                 "remove it or add the missing '('")
            raise self.error(
                f"expected an operator or the end of the expression but found "
                f"{token.describe()}", token.column,
                "join terms with + - * / or **")
        return result

    def expression(self, min_bp: int, depth: int) -> sympy.Expr:
        """Pratt loop: a prefix, then binary operators binding tighter than min_bp."""
        if depth > MAX_DEPTH:
            raise self.error(f"expression is nested more than {MAX_DEPTH} levels deep",
                             self.peek().column, "simplify the expression")
        left = self.prefix(depth)
        while True:
            token = self.peek()
            if token.kind != "op" or token.text not in _BINARY:
                return left
            bp = _BINARY[token.text]
            if bp <= min_bp:
                return left
            if token.text in "+-":
                left = self.chain(left, depth, additive=True)
            elif token.text in "*/":
                left = self.chain(left, depth, additive=False)
            else:  # '**', right-associative: the exponent may contain '**'
                self.take()
                exponent = self.expression(bp - 1, depth + 1)
                left = self.power(left, exponent, token)

    def chain(self, first: sympy.Expr, depth: int, additive: bool) -> sympy.Expr:
        """A run of + - (or * /) operators, built with one Add (or Mul)."""
        ops = "+-" if additive else "*/"
        bp = 10 if additive else 20
        items = [first]
        while True:
            token = self.peek()
            if token.kind != "op" or token.text not in ops:
                break
            self.take()
            operand = self.expression(bp, depth + 1)
            if token.text == "-":
                operand = -operand
            elif token.text == "/":
                if operand == 0:
                    raise self.error("division by zero", token.column,
                                     "check the divisor")
                operand = sympy.Pow(operand, -1)
            items.append(operand)
        return sympy.Add(*items) if additive else sympy.Mul(*items)

    def prefix(self, depth: int) -> sympy.Expr:
        token = self.take()
        if token.kind == "number":
            return token.value
        if token.kind == "name":
            return self.name(token, depth)
        if token.kind == "op" and token.text == "(":
            inner = self.expression(0, depth + 1)
            self.expect(")", token)
            return inner
        if token.kind == "op" and token.text in "+-":
            operand = self.expression(_UNARY_BP, depth + 1)
            return -operand if token.text == "-" else operand
        raise self.error(
            f"expected a number, a name, '(' or '-' but found {token.describe()}",
            token.column)

    def name(self, token: _Token, depth: int) -> sympy.Expr:
        name = token.text
        follower = self.peek()
        called = follower.kind == "op" and follower.text == "("
        if name in FUNCTIONS:
            if not called:
                raise self.error(f"function '{name}' must be called", token.column,
                                 f"write {name}(...)")
            return self.call(token, depth)
        if called:
            raise self.error(f"'{name}' is not a function", token.column,
                             "the functions are " + " ".join(FUNCTIONS))
        if name in CONSTANTS:
            return CONSTANTS[name]
        symbol = self.allowed.get(name)
        if symbol is None:
            if self.kinds:
                hint = f"allowed here: {self.kinds}"
            elif self.allowed:
                names = sorted(self.allowed)
                shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
                hint = f"allowed names: {shown}"
            else:
                hint = "no names are allowed here"
            raise self.error(f"undefined name '{name}'", token.column, hint, name)
        return symbol

    def call(self, token: _Token, depth: int) -> sympy.Expr:
        name = token.text
        function, arity = FUNCTIONS[name]
        opened = self.take()  # '('
        args = []
        if not (self.peek().kind == "op" and self.peek().text == ")"):
            while True:
                args.append(self.expression(0, depth + 1))
                follower = self.peek()
                if follower.kind == "op" and follower.text == ",":
                    self.take()
                    continue
                break
        self.expect(")", opened)
        if len(args) != arity:
            plural = "argument" if arity == 1 else "arguments"
            raise self.error(
                f"function '{name}' takes {arity} {plural} but was given {len(args)}",
                token.column,
                "write atan2(y, x)" if name == "atan2" else f"write {name}(x)")
        if all(a.is_number for a in args):
            values = [self.value(a, token) for a in args]
            if name in ("sin", "cos", "tan") and abs(values[0]) > MAX_PERIODIC_ARGUMENT:
                raise self.error(f"the argument of {name}(...) is too large",
                                 token.column,
                                 f"use constant arguments of at most {MAX_PERIODIC_ARGUMENT:g} "
                                 "in magnitude")
            if _float_call(name, values) is None:
                raise self.error(f"{name}(...) is not a finite real number here",
                                 token.column, "check the argument")
        result = function(*args)
        if result.has(*_NOT_FINITE_REAL):
            raise self.error(f"{name}(...) is not a finite real number here",
                             token.column, "check the argument")
        return result

    def value(self, expr: sympy.Expr, token: _Token) -> float:
        """The double value of a constant, or an error naming the constant."""
        try:
            return _float_value(expr, self.values)
        except _NotADouble as exc:
            raise self.error(exc.reason, token.column, exc.hint) from None

    def power(self, base: sympy.Expr, exponent: sympy.Expr, token: _Token) -> sympy.Expr:
        if exponent.is_Rational and base.is_number:
            if base == 0 and exponent < 0:
                raise self.error("division by zero (0 to a negative power)",
                                 token.column, "check the base and the exponent")
        if exponent.is_Rational:
            # sympy computes powers of the numbers in the base exactly, even in
            # (2*x)**(10**9): bound the size of every such power first
            for factor in sympy.Mul.make_args(base):
                # a rational root (a/b)**(1/q) is computed as (a b**(q-1))**(1/q) / b:
                # its size grows with q as a power's grows with p
                if (factor.is_number and max(abs(exponent.p), exponent.q) * _exact_bits(factor)
                        > MAX_POWER_BITS):
                    raise self.error("the power is too large to compute exactly",
                                     token.column, "use a smaller exponent")
        if base.is_number and exponent.is_number and not (base.is_Rational
                                                          and exponent.is_Integer):
            values = (self.value(base, token), self.value(exponent, token))
            if _float_call("**", values) is None:
                raise self.error("the power is not a finite real number", token.column,
                                 "check the base and the exponent")
        result = sympy.Pow(base, exponent)
        if result.has(*_NOT_FINITE_REAL):
            raise self.error("the power is not a finite real number", token.column,
                             "check the base and the exponent")
        return result


# -- bounded arithmetic on constants -------------------------------------------
#
# sympy evaluates constants exactly, and some questions it asks of them (is
# tan(sinh(10**99)) zero?) cost without bound.  Every constant the parser is
# about to hand to a function or a power is first evaluated here, in double
# precision, and refused unless it is a finite real double.

_DOUBLE_MAX = sys.float_info.max

_MATH = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin,
    "acos": math.acos, "atan": math.atan, "atan2": math.atan2, "sinh": math.sinh,
    "cosh": math.cosh, "tanh": math.tanh, "exp": math.exp, "sqrt": math.sqrt,
    "log": math.log, "abs": abs, "sign": lambda v: float((v > 0) - (v < 0)),
    "**": math.pow,
}


class _NotADouble(Exception):
    """Internal: a constant that is not a finite real double (reason, hint)."""

    def __init__(self, reason: str, hint: str):
        super().__init__(reason)
        self.reason = reason
        self.hint = hint


def _float_call(name: str, values) -> Optional[float]:
    """``name(*values)`` in double precision; None if not a finite real number."""
    try:
        result = _MATH[name](*values)
    except (ValueError, OverflowError, ZeroDivisionError):
        return None
    if isinstance(result, complex) or not math.isfinite(result):
        return None
    return float(result)


def _rational_float(e) -> float:
    """The double nearest to a sympy Rational, or _NotADouble."""
    try:
        value = e.p / e.q
    except OverflowError:
        value = math.inf
    if abs(value) > _DOUBLE_MAX:
        raise _NotADouble(f"the number {_shorten(_fmt(e)[0])} is beyond the range of a double",
                          "use numbers of magnitude at most 1.7e308")
    if value == 0 and e.p != 0:
        raise _NotADouble(f"the number {_shorten(_fmt(e)[0])} is too small for a double (it "
                          "would be 0)", "use numbers of magnitude at least 5e-324, or 0")
    return value


def _shorten(text: str) -> str:
    return text if len(text) <= 40 else text[:25] + "..." + text[-10:]


def _float_value(e, memo: dict) -> float:
    """Double value of a constant sympy expression, or :class:`_NotADouble`.

    Evaluated node by node with Python floats (so in bounded time), with the
    results memoised in ``memo``.
    """
    if e in memo:
        return memo[e]
    if e.is_Rational:
        value = _rational_float(e)
    elif e is sympy.pi:
        value = math.pi
    elif e is sympy.E:
        value = math.e
    elif isinstance(e, sympy.Float):
        value = float(e)
    else:
        if e.is_Add:
            name = "+"
        elif e.is_Mul:
            name = "*"
        elif e.is_Pow:
            name = "**"
        else:
            name = FUNCTION_NAMES.get(e.func)
            if name is None:
                raise _NotADouble(f"{_shorten(str(e))} is not a real number",
                                  "check divisors, logarithms, roots and powers")
        values = [_float_value(a, memo) for a in e.args]
        if name == "+":
            value = math.fsum(values)
        elif name == "*":
            value = math.prod(values)
        else:
            value = _float_call(name, values)
        if value is None or not math.isfinite(value):
            raise _NotADouble(f"{_shorten(_fmt(e)[0])} is not a finite real number",
                              "check divisors, logarithms, roots and powers, and keep "
                              "constants within the range of a double")
    if len(memo) < 10_000:
        memo[e] = value
    return value


def _exact_bits(number) -> int:
    """Bits sympy needs to hold ``number`` exactly (0 for symbolic constants like pi).

    A power of a rational costs the bits of the rational times the exponent.
    """
    if number.is_Rational:
        size = max(abs(number.p), abs(number.q)).bit_length()
        return size if size > 1 else 0
    if number.is_Pow and number.base.is_Rational and number.exp.is_Rational:
        return _exact_bits(number.base) * abs(number.exp.p)
    return 0


def _check_numbers(result: sympy.Expr, text: Optional[str]) -> None:
    """Every number in ``result`` is a finite double with at most MAX_NUMBER_CHARS digits."""
    memo: dict = {}
    stack = [result]
    while stack:
        e = stack.pop()
        if e.is_Rational:
            for part in (e.p, e.q):
                if abs(part).bit_length() > MAX_TEXT_BITS or \
                        len(integer_text(abs(part))) > MAX_NUMBER_CHARS:
                    raise ExpressionParseError(
                        f"a number in the expression has more than {MAX_NUMBER_CHARS} digits",
                        text, None, "use fewer significant digits")
        if e.is_number:
            try:
                _float_value(e, memo)
            except _NotADouble as exc:
                raise ExpressionParseError(exc.reason, text, None, exc.hint) from None
        else:
            stack.extend(e.args)


def parse_expression(text_or_number, allowed: Mapping[str, sympy.Symbol], *,
                     kinds: Optional[str] = None) -> sympy.Expr:
    """Parse an expression of the restricted grammar into a sympy expression.

    ``text_or_number`` is a string in the grammar of this module, an int or
    float (as YAML gives them; a float becomes the exact rational of its
    shortest repr, so ``9.81`` is ``981/100``), or a sympy expression (it is
    printed with :func:`format_expression` and parsed back, which checks that
    it only uses the grammar and ``allowed``).  Booleans are rejected.

    ``allowed`` maps each name that may appear to its symbol; include
    ``"t": modelgen.model.spec.TIME`` to allow time.  ``kinds`` describes the
    allowed names for the "undefined name" message (e.g. ``"coordinates,
    parameters and t"``); without it the allowed names are listed.

    Raises :class:`ExpressionParseError` (an ``ExpressionError``).

    >>> from modelgen.model.spec import symbol
    >>> parse_expression("m1*l1**2/12", {"m1": symbol("m1"), "l1": symbol("l1")})
    l1**2*m1/12
    >>> parse_expression(0.1, {})
    1/10
    >>> parse_expression("-x**2", {"x": symbol("x")})
    -x**2
    """
    if isinstance(text_or_number, bool):
        raise ExpressionParseError(
            f"expected an expression but got the boolean {text_or_number}",
            None, None, "write a number or an expression")
    if isinstance(text_or_number, sympy.Basic):
        text_or_number = format_expression(text_or_number)
    elif isinstance(text_or_number, numbers.Integral):
        return _checked(sympy.Integer(int(text_or_number)), None)
    elif isinstance(text_or_number, numbers.Rational):
        return _checked(sympy.Rational(text_or_number.numerator,
                                       text_or_number.denominator), None)
    elif isinstance(text_or_number, numbers.Real):
        value = float(text_or_number)
        if not math.isfinite(value):
            raise ExpressionParseError(f"{value!r} is not a finite number", None,
                                       None, "write a finite number")
        exact = Fraction(repr(value))
        return _checked(sympy.Rational(exact.numerator, exact.denominator), None)
    if not isinstance(text_or_number, str):
        kind = type(text_or_number).__name__
        raise ExpressionParseError(f"expected an expression but got a {kind}",
                                   None, None, "write a number or an expression string")
    text = text_or_number
    if len(text) > MAX_LENGTH:
        raise ExpressionParseError(f"expression is {len(text)} characters long",
                                   None, None, f"use at most {MAX_LENGTH} characters")
    if not text.strip():
        raise ExpressionParseError("empty expression", None, None,
                                   "write a number or an expression")
    try:
        result = _Parser(text, allowed, kinds).parse()
        if result.has(*_NOT_FINITE_REAL):
            raise ExpressionParseError("the expression is not a finite real number", text,
                                       None, "check divisors, logarithms and square roots")
        _check_numbers(result, text)
        return _stable(result, text, allowed)
    except _SYMPY_FAILURES as exc:
        # a backstop: sympy's own evaluation failed on a corner the checks above miss
        raise ExpressionParseError(
            f"sympy cannot evaluate the expression ({type(exc).__name__})", text, None,
            "simplify the expression, and keep constants within the range of a double"
        ) from None


#: Exceptions sympy's automatic evaluation raises on extreme input.
_SYMPY_FAILURES = (ArithmeticError, AttributeError, TypeError, ValueError, RecursionError,
                   NotImplementedError)


def _checked(number: sympy.Rational, text: Optional[str]) -> sympy.Rational:
    """A number given as YAML int or float, under the same limits as text."""
    _check_numbers(number, text)
    return number


def _stable(result: sympy.Expr, text: str, allowed: Mapping[str, sympy.Symbol]) -> sympy.Expr:
    """Make ``result`` a fixed point of format-then-parse.

    sympy's automatic evaluation is not always idempotent (``Abs(3*Abs(x))``
    can come out as ``3*Abs(Abs(x))``, which parses back as ``3*Abs(x)``) and
    can leave the grammar (``abs(exp(x))`` becomes ``exp(re(x))`` because
    names are not assumed real).  Printing and re-parsing until nothing
    changes gives an expression that survives a round trip through YAML, and
    refuses the ones that cannot be written at all.
    """
    hint = ("simplify the expression by hand (names are not assumed real, so e.g. "
            "abs(exp(x)) becomes exp(re(x)))")
    for _ in range(4):
        try:
            printed = _fmt(result)[0]
        except Unprintable as exc:
            raise ExpressionParseError(
                f"sympy rewrites the expression as {_quote(str(result))}, and "
                f"{type(exc.node).__name__} is not part of modelgen's expression grammar",
                text, None, hint) from None
        try:
            again = _Parser(printed, allowed, None).parse()
        except ExpressionParseError:
            break
        if again == result:
            if len(printed) > MAX_LENGTH:
                # what is accepted must read back from the model file it is written to
                raise ExpressionParseError(
                    f"the expression is {len(printed)} characters long as sympy writes it",
                    text, None, f"use at most {MAX_LENGTH} characters once sympy has "
                    "evaluated it (a number times a sum is multiplied out: 7*(a + b) is "
                    "7*a + 7*b)")
            return result
        result = again
    raise ExpressionParseError("the expression has no stable form under sympy's automatic "
                               "simplification", text, None, hint)


# -- printer -----------------------------------------------------------------

def format_expression(expr) -> str:
    """Write a sympy expression in the grammar of :func:`parse_expression`.

    ``Abs`` is written ``abs``, Euler's number ``exp(1)``, rationals ``a/b``
    and sympy floats as their shortest decimal (which parses back to the
    exact rational of that decimal).  Python ints and floats are accepted
    too.  Anything outside the grammar (e.g. an undefined function, ``I``,
    ``oo``) raises :class:`ExpressionParseError`.

    For an expression ``e`` returned by :func:`parse_expression`,
    ``parse_expression(format_expression(e), allowed) == e`` structurally.

    >>> from modelgen.model.spec import symbol
    >>> m, l = symbol("m"), symbol("l")
    >>> format_expression(-m*l**2/12 + sympy.sqrt(2)*sympy.Abs(l))
    '-m*l**2/12 + sqrt(2)*abs(l)'
    """
    if isinstance(expr, bool):
        raise ExpressionParseError("cannot write a boolean as an expression", None)
    if isinstance(expr, sympy.Basic):
        pass
    elif isinstance(expr, numbers.Integral):
        expr = sympy.Integer(int(expr))
    elif isinstance(expr, numbers.Real):
        expr = sympy.Float(float(expr))
    if not isinstance(expr, sympy.Basic):
        raise ExpressionParseError(f"cannot write a {type(expr).__name__} as an expression",
                                   None)
    try:
        return _fmt(expr)[0]
    except Unprintable as exc:
        raise ExpressionParseError(
            f"cannot write {_quote(str(exc.node))}: {type(exc.node).__name__} is not part of "
            "modelgen's expression grammar", None, None, _GRAMMAR_HINT) from None


def _fmt(e) -> tuple:
    """:func:`~modelgen.model.expr_print.expression_text`, with a non-finite float
    reported as the :class:`ExpressionParseError` it is."""
    try:
        return expression_text(e)
    except Unprintable as exc:
        if exc.reason:
            raise ExpressionParseError(exc.reason, None, None, exc.hint or None) from None
        raise
