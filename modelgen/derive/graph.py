"""Named intermediate quantities: the straight-line program the stages build.

Closed-form equations of motion grow exponentially with the number of bodies.
modelgen never builds them.  Each stage instead computes every quantity
(rotation entries, velocities, partial velocities, composite inertias...) from
already-named quantities and gives the result a name when it is not trivial.
The outcome is a *straight-line program*: an ordered list of assignments
``symbol = small expression``, which is what the C code will execute.

:class:`GraphBuilder` records such a program; :class:`Graph` is its frozen
result.  Identical right-hand sides get the same name (hash-consing), which is
the first, cheapest level of common-subexpression elimination.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Iterable

import sympy

ZERO = sympy.S.Zero
ONE = sympy.S.One

#: Prefix of intermediate symbols.  User names may not start with ``mg_``.
PREFIX = "mg_"


def _is_trivial(expr: sympy.Expr) -> bool:
    """True if ``expr`` costs nothing to inline (a number, a symbol, c*symbol)."""
    if expr.is_Number or expr.is_Symbol:
        return True
    if expr.is_Mul and len(expr.args) == 2:
        a, b = expr.args
        return a.is_Number and b.is_Symbol
    return False


@dataclass(frozen=True)
class Graph:
    """A frozen straight-line program: ``assignments[i] = (symbol, expr)``.

    Every symbol used by an expression is either an input (coordinate, speed,
    parameter, input, time) or an intermediate assigned earlier in the list.
    """
    assignments: tuple

    def definitions(self) -> dict:
        """Mapping intermediate symbol -> expression."""
        return dict(self._index[0])

    @cached_property
    def _index(self) -> tuple:
        """(definitions, position of each symbol, intermediates each expression uses),
        computed once: a graph is asked for many closures."""
        defs = dict(self.assignments)
        order = {sym: i for i, (sym, _) in enumerate(self.assignments)}
        deps = {sym: tuple(s for s in expr.free_symbols if s in defs)
                for sym, expr in self.assignments}
        return defs, order, deps

    def closure(self, outputs: Iterable[sympy.Expr]) -> tuple:
        """The assignments needed to evaluate ``outputs``, in program order."""
        defs, order, deps = self._index
        needed = set()
        stack = [s for e in outputs for s in sympy.sympify(e).free_symbols if s in defs]
        while stack:
            sym = stack.pop()
            if sym in needed:
                continue
            needed.add(sym)
            stack.extend(s for s in deps[sym] if s not in needed)
        return tuple(self.assignments[i] for i in sorted(order[s] for s in needed))

    def expand(self, expr: sympy.Expr) -> sympy.Expr:
        """Substitute every intermediate in ``expr`` by its definition.

        Use only for small models or queries: the result is the closed form,
        whose size grows quickly with the number of bodies.
        """
        defs = self.definitions()
        memo: dict = {}

        def full(sym):
            if sym not in memo:
                body = defs[sym]
                memo[sym] = body.xreplace({s: full(s) for s in body.free_symbols if s in defs})
            return memo[sym]

        return sympy.sympify(expr).xreplace(
            {s: full(s) for s in sympy.sympify(expr).free_symbols if s in defs})


class GraphBuilder:
    """Records named intermediates while a stage computes.

    >>> g = GraphBuilder()
    >>> x, y = sympy.symbols("x y")
    >>> a = g.name(x*y + 1)
    >>> a, g.name(x*y + 1) is a, g.name(2*x)
    (mg_0, True, 2*x)
    """

    def __init__(self, graph: Graph | None = None):
        self._assignments: list = list(graph.assignments) if graph else []
        self._memo: dict = {expr: sym for sym, expr in self._assignments}

    def name(self, expr) -> sympy.Expr:
        """Return a symbol standing for ``expr`` (or ``expr`` itself if trivial)."""
        expr = sympy.sympify(expr)
        if _is_trivial(expr):
            return expr
        # a negated intermediate stays inline: -mg_3 is free in C
        if expr.is_Mul and len(expr.args) == 2 and expr.args[0] is sympy.S.NegativeOne:
            inner = self.name(expr.args[1])
            return -inner
        sym = self._memo.get(expr)
        if sym is None:
            sym = sympy.Symbol(f"{PREFIX}{len(self._assignments)}")
            self._assignments.append((sym, expr))
            self._memo[expr] = sym
        return sym

    def vec(self, components) -> tuple:
        """Name each component of a vector."""
        return tuple(self.name(c) for c in components)

    def freeze(self) -> Graph:
        return Graph(tuple(self._assignments))


# -- small vector algebra on tuples of sympy expressions ---------------------

def add(a, b):
    return tuple(x + y for x, y in zip(a, b))


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def scale(s, a):
    return tuple(s * x for x in a)


def dot(a, b):
    return sympy.Add(*[x * y for x, y in zip(a, b)])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


def matvec(m, v):
    """``m @ v`` for a 3x3 tuple-of-rows ``m``."""
    return tuple(dot(row, v) for row in m)


def is_zero_vec(v) -> bool:
    return all(x == 0 for x in v)


ZERO3 = (ZERO, ZERO, ZERO)
