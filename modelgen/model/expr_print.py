"""The printer of modelgen's expression grammar: sympy expressions back to text.

:func:`expression_text` writes what :func:`modelgen.model.expr.parse_expression`
reads (``Abs`` as ``abs``, Euler's number as ``exp(1)``, rationals ``a/b``,
long round integers as ``<digits>e<k>``); the parser uses it to bring its
results to a fixed point of printing and parsing, and
:func:`modelgen.model.expr.format_expression` is its public face.
"""
from __future__ import annotations

import math

import sympy

#: sympy function class -> name in the grammar (for the printer).
FUNCTION_NAMES = {
    sympy.sin: "sin", sympy.cos: "cos", sympy.tan: "tan",
    sympy.asin: "asin", sympy.acos: "acos", sympy.atan: "atan",
    sympy.atan2: "atan2",
    sympy.sinh: "sinh", sympy.cosh: "cosh", sympy.tanh: "tanh",
    sympy.exp: "exp", sympy.log: "log",
    sympy.Abs: "abs", sympy.sign: "sign",
}

_PREC_ADD, _PREC_MUL, _PREC_NEG, _PREC_POW, _PREC_ATOM = 10, 20, 25, 30, 40


def _wrap(item: tuple, minimum: int) -> str:
    text, prec = item
    return f"({text})" if prec < minimum else text


def expression_text(e) -> tuple:
    """(text, precedence) of ``e``; the precedence tells the caller when to wrap."""
    if e.is_Integer:
        text = integer_text(abs(e.p))
        return ("-" + text, _PREC_NEG) if e < 0 else (text, _PREC_ATOM)
    if e.is_Rational:
        denominator = integer_text(e.q)
        if denominator.startswith("1e"):  # a small decimal fraction: 3e-20
            text = f"{digits_text(abs(e.p))}e-{denominator[2:]}"
            return ("-" + text, _PREC_NEG) if e.p < 0 else (text, _PREC_ATOM)
        text = f"{integer_text(abs(e.p))}/{denominator}"
        return ("-" + text, _PREC_NEG) if e.p < 0 else (text, _PREC_MUL)
    if isinstance(e, sympy.Float):
        value = float(e)
        if not math.isfinite(value):
            raise Unprintable(e, f"{value!r} is not a finite number")
        return (repr(value), _PREC_NEG if value < 0 else _PREC_ATOM)
    if e is sympy.pi:
        return ("pi", _PREC_ATOM)
    if e is sympy.E:
        return ("exp(1)", _PREC_ATOM)
    if e.is_Symbol:
        return (e.name, _PREC_ATOM)
    if e.is_Add:
        return _add(e)
    if e.is_Mul:
        return _mul(e)
    if e.is_Pow:
        return _pow(e.base, e.exp)
    name = FUNCTION_NAMES.get(e.func)
    if name is not None and e.args:
        return (f"{name}({', '.join(expression_text(a)[0] for a in e.args)})", _PREC_ATOM)
    raise Unprintable(e)


#: Most bits of an integer printed (about 3900 digits): Python refuses to convert an
#: int of more than 4300 digits to text, and the grammar takes at most 400 anyway.
MAX_TEXT_BITS = 13_000


def digits_text(n: int) -> str:
    """``str(n)``, or :class:`Unprintable` for an integer of more than
    :data:`MAX_TEXT_BITS` bits (which ``str`` would refuse with a ValueError)."""
    if abs(n).bit_length() > MAX_TEXT_BITS:
        raise Unprintable(None, f"a number in the expression has more than "
                          f"{int(MAX_TEXT_BITS * math.log10(2))} digits",
                          "use fewer significant digits")
    return str(n)


def integer_text(n: int) -> str:
    """A non-negative integer as a literal: digits, or ``<digits>e<k>`` when shorter.

    >>> integer_text(10**19), integer_text(1000), integer_text(12 * 10**40)
    ('1e19', '1000', '12e40')
    """
    digits = digits_text(n)
    if len(digits) <= 15:
        return digits
    mantissa = digits.rstrip("0")
    zeros = len(digits) - len(mantissa)
    if zeros < 3:
        return digits
    return f"{mantissa}e{zeros}"


class Unprintable(Exception):
    """A node outside the grammar; ``reason`` (and ``hint``) are set when the node is
    a number that is not finite or too long to print.  :mod:`modelgen.model.expr`
    turns it into its ExpressionParseError."""

    def __init__(self, node, reason: str = "", hint: str = ""):
        super().__init__(reason or str(node))
        self.node = node
        self.reason = reason
        self.hint = hint


def _negative_coefficient(term) -> bool:
    coefficient = term.as_coeff_Mul()[0]
    return coefficient.is_Number and coefficient < 0


def _add(e) -> tuple:
    parts = []
    for i, term in enumerate(e.as_ordered_terms()):
        if i and _negative_coefficient(term):
            parts.append(" - " + _wrap(expression_text(-term), _PREC_MUL))
        elif i:
            parts.append(" + " + _wrap(expression_text(term), _PREC_MUL))
        else:
            parts.append(_wrap(expression_text(term), _PREC_MUL))
    return ("".join(parts), _PREC_ADD)


def _mul(e) -> tuple:
    coefficient, factors = e.as_coeff_mul()
    sign = ""
    if coefficient.is_Number and coefficient < 0:
        sign, coefficient = "-", -coefficient
    numerator, denominator = [], []
    if coefficient.is_Rational:
        if coefficient.p != 1:
            numerator.append((integer_text(coefficient.p), _PREC_ATOM))
        if coefficient.q != 1:
            denominator.append((integer_text(coefficient.q), _PREC_ATOM))
    elif coefficient != 1:  # a Float coefficient
        numerator.append(expression_text(coefficient))
    for factor in factors:
        if factor.is_Pow and factor.exp.is_Number and factor.exp < 0:
            if factor.exp == -1:
                denominator.append(expression_text(factor.base))
            else:
                denominator.append(_pow(factor.base, -factor.exp))
        else:
            numerator.append(expression_text(factor))
    if sign and numerator and numerator[0][1] <= _PREC_MUL:
        # "-(a + b)*c" would negate the sum before multiplying; "-1*(a + b)*c"
        # keeps the -1 as a separate factor, as in the expression printed
        numerator.insert(0, ("1", _PREC_ATOM))
    text = "*".join(_wrap(item, _PREC_MUL + 1) for item in numerator) or "1"
    for item in denominator:
        text += "/" + _wrap(item, _PREC_POW)
    return (sign + text, _PREC_NEG if sign else _PREC_MUL)


def _pow(base, exponent) -> tuple:
    if exponent == sympy.S.Half:
        return (f"sqrt({expression_text(base)[0]})", _PREC_ATOM)
    if exponent.is_Number and exponent < 0:
        if exponent == -1:
            inner = expression_text(base)
        else:
            inner = _pow(base, -exponent)
        return ("1/" + _wrap(inner, _PREC_POW), _PREC_MUL)
    return (_wrap(expression_text(base), _PREC_ATOM) + "**" + _wrap(expression_text(exponent), _PREC_ATOM),
            _PREC_POW)
