"""Differentiation of model expressions as functions of real variables.

Model symbols are plain sympy symbols (not declared real), so sympy
differentiates ``Abs(x)`` as a complex function, ``(re(x)*Derivative(re(x), x)
+ ...)/Abs(x)``, and leaves ``Derivative(sign(x), x)`` unevaluated.  Neither
can be printed as C (and symengine crashes converting the first).  Every
quantity in a model is real, so here ``d|u|/dx = sign(u) du/dx`` and
``d sign(u)/dx = 0`` (both hold everywhere except at u = 0, where C evaluates
sign(0) = 0, the usual subgradient choice).

Every derivative the derive stage takes goes through :func:`diff`.
"""
from __future__ import annotations

import sympy

__all__ = ["diff", "norm_of_square"]


class _RealAbs(sympy.Function):
    """|u| of a real u, differentiated as sign(u)."""
    nargs = 1

    def fdiff(self, argindex=1):
        return _RealSign(self.args[0])


class _RealSign(sympy.Function):
    """sign(u) of a real u, differentiated as 0 (almost everywhere)."""
    nargs = 1

    def fdiff(self, argindex=1):
        return sympy.S.Zero


_TO_REAL = {sympy.Abs: _RealAbs, sympy.sign: _RealSign}
_FROM_REAL = {_RealAbs: sympy.Abs, _RealSign: sympy.sign}


def diff(expr, x):
    """d expr / dx for real variables: abs and sign differentiate as real functions.

    >>> x = sympy.Symbol("x")
    >>> diff(sympy.Abs(x) * x, x)
    x*sign(x) + Abs(x)
    >>> diff(sympy.sign(sympy.sin(x)), x)
    0
    """
    expr = sympy.sympify(expr)
    if not expr.has(sympy.Abs, sympy.sign):
        return expr.diff(x)
    real = expr.replace(lambda e: e.func in _TO_REAL, lambda e: _TO_REAL[e.func](*e.args))
    result = real.diff(x)
    return result.replace(lambda e: e.func in _FROM_REAL,
                          lambda e: _FROM_REAL[e.func](*e.args))


def norm_of_square(w):
    """sqrt(w) of a w >= 0 that is a sum of squares (w = v.v, this is |v|), written so
    that its derivative is 0 where w = 0 instead of 0/0.

    d sqrt(w) = dw / (2 sqrt(w)) is 0/0 at w = 0, where dw = 2 v.dv is 0 too; every
    expression the derivatives of |v| enter (drag's |v| v) has the limit 0 there.
    With s = sign(w), ``w s (w + 1 - s)^(-1/2)`` equals sqrt(w) for w > 0 and 0 at
    w = 0, and since d sign = 0 (:func:`diff`) its derivative is dw / (2 sqrt(w))
    for w > 0 and exactly 0 at w = 0, in C with no branch.

    >>> w = sympy.Symbol("w")
    >>> e = norm_of_square(w)
    >>> e.subs(w, 4), e.subs(w, 0), diff(e, w).subs(w, 4), diff(e, w).subs(w, 0)
    (2, 0, 1/4, 0)
    """
    s = sympy.sign(w)
    return w * s * (w + 1 - s) ** sympy.Rational(-1, 2)
