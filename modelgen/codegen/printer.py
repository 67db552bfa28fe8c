"""Printer stage: sympy expressions to C99 source text.

One printer, a subclass of sympy's C99 printer, that maps every symbol to the
C expression holding it (``q[0]``, ``p[3]``, a local ``w12`` or a work-array
slot ``w[7]``).  Templates never format numbers or expressions themselves.
"""
from __future__ import annotations

import math

import sympy
from sympy.printing.c import C99CodePrinter
from sympy.printing.codeprinter import PrintMethodNotImplementedError
from sympy.printing.precedence import precedence

from modelgen.errors import DerivationError


#: Integers at least this large are printed as double literals (a C integer
#: constant of 2**63 or more does not compile; beyond 2**53 a double is inexact anyway).
EXACT_INTEGER_LIMIT = 2**53


class ModelPrinter(C99CodePrinter):
    """C99 printer with symbol -> slot mapping and cheap integer powers.

    The printer is strict: an expression it cannot print as C (an unevaluated
    ``Derivative``, ``re``...) raises :class:`DerivationError` naming
    ``routine``, never leaves text in the C.

    >>> x, y = sympy.symbols("x y")
    >>> ModelPrinter({x: "q[0]", y: "p[1]"}).doprint(x**2 * y + sympy.pi)
    '3.1415926535897931 + p[1]*(q[0]*q[0])'
    >>> ModelPrinter({x: "q[0]"}).doprint(10**19 * x + sympy.Rational(1, 3))
    '1.0/3.0 + 1e+19*q[0]'
    """

    def __init__(self, slots: dict, routine: str = ""):
        super().__init__({"order": "none", "strict": True})
        self.slots = slots
        self.routine = routine

    def doprint(self, expr, assign_to=None):
        try:
            return super().doprint(expr, assign_to)
        except PrintMethodNotImplementedError as exc:
            where = f" in routine {self.routine}" if self.routine else ""
            first = str(exc).splitlines()[0]
            raise DerivationError(f"cannot print {_shorten(str(expr))} as C{where} "
                                  f"({first})") from None

    def _handle_UnevaluatedExpr(self, expr):
        """No rewrite pass: modelgen never builds ``UnevaluatedExpr`` (sympy's pass
        walks every expression with ``replace``, a sixth of the printing time),
        and an ``re`` left in would still be refused by the strict printer."""
        return expr

    def _print_Integer(self, expr):
        if abs(expr.p) >= EXACT_INTEGER_LIMIT:
            return self._double(expr)
        return super()._print_Integer(expr)

    def _print_Rational(self, expr):
        if max(abs(expr.p), expr.q) >= EXACT_INTEGER_LIMIT:
            return self._double(expr)
        return super()._print_Rational(expr)

    def _double(self, expr) -> str:
        """A number as the nearest double literal (validation keeps it in range)."""
        try:
            value = expr.p / expr.q
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            magnitude = round(math.log10(abs(expr.p)) - math.log10(expr.q))
            where = f" in routine {self.routine}" if self.routine else ""
            raise DerivationError(
                f"a constant of about 1e{magnitude}{where} is beyond the range of a double: "
                "the model's constants are in range but their products (e.g. a mass times "
                "a length squared) are not; use units that keep constants near 1")
        return repr(value)

    def _print_Symbol(self, expr):
        try:
            return self.slots[expr]
        except KeyError:
            raise DerivationError(f"symbol {expr} has no storage in the generated C") from None

    def _print_Pi(self, expr):
        return "3.1415926535897931"

    def _print_Exp1(self, expr):
        return "2.7182818284590451"

    def _print_Pow(self, expr):
        base, exp = expr.args
        if exp.is_Integer and 1 < abs(int(exp)) <= 4:
            b = self.parenthesize(base, precedence(sympy.Mul(base, base, evaluate=False)))
            prod = "(" + "*".join([b] * abs(int(exp))) + ")"
            return prod if exp > 0 else f"1.0/{prod}"
        if exp == -1:
            return f"1.0/{self.parenthesize(base, precedence(expr))}"
        if exp == sympy.S.Half:
            return f"sqrt({self._print(base)})"
        if exp == -sympy.S.Half:
            return f"1.0/sqrt({self._print(base)})"
        return f"pow({self._print(base)}, {self._print(exp)})"

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_sign(self, expr):
        a = self._print(expr.args[0])
        return f"((double)(({a}) > 0) - (double)(({a}) < 0))"


def _shorten(text: str) -> str:
    return text if len(text) <= 80 else text[:60] + "..." + text[-15:]


def print_expression(expr, slots: dict, routine: str = "") -> str:
    """Print one expression with the given symbol mapping."""
    return ModelPrinter(slots, routine).doprint(expr)
