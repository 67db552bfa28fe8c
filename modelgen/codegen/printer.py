"""Printer stage: sympy expressions to C99 source text.

One printer, a subclass of sympy's C99 printer, that maps every symbol to the
C expression holding it (``q[0]``, ``p[3]``, a local ``w12`` or a work-array
slot ``w[7]``).  Templates never format numbers or expressions themselves.
"""
from __future__ import annotations

import sympy
from sympy.printing.c import C99CodePrinter
from sympy.printing.precedence import precedence

from modelgen.errors import DerivationError


class ModelPrinter(C99CodePrinter):
    """C99 printer with symbol -> slot mapping and cheap integer powers.

    >>> x, y = sympy.symbols("x y")
    >>> ModelPrinter({x: "q[0]", y: "p[1]"}).doprint(x**2 * y + sympy.pi)
    '3.1415926535897931 + p[1]*(q[0]*q[0])'
    """

    def __init__(self, slots: dict):
        super().__init__({"order": "none", "strict": False})
        self.slots = slots

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


def print_expression(expr, slots: dict) -> str:
    """Print one expression with the given symbol mapping."""
    return ModelPrinter(slots).doprint(expr)
