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

from dataclasses import dataclass, field
from functools import cached_property
from typing import Iterable

import sympy

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


def free_symbols(expr) -> set:
    """``expr.free_symbols``, by a walk over the node types a program holds (sums,
    products, powers, functions, atoms), two to three times faster than sympy's
    set unions at every node; any other node answers for itself.

    >>> x, y = sympy.symbols("x y")
    >>> sorted(free_symbols(sympy.sin(x) * y + 2), key=str)
    [x, y]
    """
    out = set()
    stack = [expr]
    while stack:
        e = stack.pop()
        if e.is_Symbol:
            out.add(e)
        elif e.is_Atom:
            continue
        elif e.is_Add or e.is_Mul or e.is_Pow or e.is_Function:
            stack.extend(e.args)
        else:
            out |= e.free_symbols
    return out


def operation_count(expr) -> int:
    """Operations to evaluate ``expr`` as written: one per binary operator,
    power or function call; a numeric factor other than -1 is one product, a
    sign is free.  A quick measure for comparing two programs built here (the
    codegen stage counts the C it prints exactly).

    >>> x, y = sympy.symbols("x y")
    >>> operation_count(2*x*y - sympy.sin(x)), operation_count(-x*y)
    (4, 1)
    """
    count = 0
    stack = [expr]
    while stack:
        e = stack.pop()
        if e.is_Atom:
            continue
        args = e.args
        if e.is_Mul:
            numbers = [a for a in args if a.is_Number]
            count += len(args) - 1 - (1 if numbers and numbers[0] == -1 else 0)
        elif e.is_Add:
            count += len(args) - 1
        else:
            count += 1
        stack.extend(args)
    return count


@dataclass(frozen=True)
class Graph:
    """A frozen straight-line program: ``assignments[i] = (symbol, expr)``.

    Every symbol used by an expression is either an input (coordinate, speed,
    parameter, input, time) or an intermediate assigned earlier in the list.
    """
    assignments: tuple
    #: expression -> its free symbols (a tuple): shared by the graphs built on
    #: this one (:class:`GraphBuilder`), which each index the same statements
    free: dict = field(default_factory=dict, compare=False, repr=False)

    def definitions(self) -> dict:
        """Mapping intermediate symbol -> expression."""
        return dict(self._index[0])

    @cached_property
    def _index(self) -> tuple:
        """(definitions, position of each symbol, positions of the intermediates each
        statement uses), computed once: a graph is asked for many closures.  The
        last is filled as closures reach each statement (most graphs of a
        derivation are asked for the closure of a few outputs only); it holds
        positions, not symbols, because a closure's walk then hashes ints, not
        sympy objects (whose hash is a Python-level call)."""
        defs = dict(self.assignments)
        order = {sym: i for i, (sym, _) in enumerate(self.assignments)}
        return defs, order, {}

    def symbols_of(self, expr) -> tuple:
        """The free symbols of ``expr`` (:func:`free_symbols`), remembered."""
        symbols = self.free.get(expr)
        if symbols is None:
            symbols = self.free[expr] = tuple(free_symbols(expr))
        return symbols

    def closure(self, outputs: Iterable[sympy.Expr]) -> tuple:
        """The assignments needed to evaluate ``outputs``, in program order."""
        _, order, deps = self._index
        assignments = self.assignments
        needed = set()
        stack = [order[s] for e in outputs for s in self.symbols_of(sympy.sympify(e))
                 if s in order]
        while stack:
            i = stack.pop()
            if i in needed:
                continue
            needed.add(i)
            uses = deps.get(i)
            if uses is None:
                uses = deps[i] = tuple(order[s] for s in self.symbols_of(assignments[i][1])
                                       if s in order)
            stack.extend(uses)
        return tuple(assignments[i] for i in sorted(needed))

    def operations(self, outputs) -> int:
        """Arithmetic operations of ``outputs`` and the assignments they need
        (:func:`operation_count`), before any CSE: the size of the program."""
        outputs = list(outputs)
        return sum(operation_count(e) for _, e in self.closure(outputs)) + \
            sum(operation_count(sympy.sympify(e)) for e in outputs)

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

    >>> builder = GraphBuilder()
    >>> x, y = sympy.symbols("x y")
    >>> a = builder.name(x*y + 1)
    >>> a, builder.name(x*y + 1) is a, builder.name(2*x)
    (mg_0, True, 2*x)
    """

    def __init__(self, graph: Graph | None = None):
        self._assignments: list = list(graph.assignments) if graph else []
        self._free: dict = graph.free if graph else {}
        self._memo: dict = {expr: sym for sym, expr in self._assignments}
        #: where statements recorded from now on belong in the program (a tuple,
        #: compared as tuples; None for nowhere in particular): see :meth:`arrange`
        self.place = None
        self._places: dict = {}

    def __len__(self) -> int:
        return len(self._assignments)

    def arrange(self, start: int) -> None:
        """Put the statements recorded from index ``start`` on in the order of
        their :attr:`place`, each after what it uses.

        A stage can then build its program in whatever order it needs to know
        things (a whole pass first) and still hand the compiler the order that
        keeps few values alive at once (each joint's work together): the C
        compiler allocates registers along the program as written.  A
        statement's place is raised to the latest place among what it uses;
        statements of equal place keep the order they were recorded in.

        >>> x, y = sympy.symbols("x y")
        >>> builder = GraphBuilder(); builder.place = (2,); a = builder.name(x * y + 1)
        >>> builder.place = (1,); b = builder.name(x + y + 1); c = builder.name(a * b + 2)
        >>> builder.arrange(0); [str(e) for _, e in builder.freeze().assignments]
        ['x + y + 1', 'x*y + 1', 'mg_0*mg_1 + 2']
        """
        head, tail = self._assignments[:start], self._assignments[start:]
        effective: dict = {}
        keyed = []
        for index, (sym, expr) in enumerate(tail):
            key = self._places.get(sym) or ()
            for s in free_symbols(expr):
                k = effective.get(s)
                if k is not None and k > key:
                    key = k
            effective[sym] = key
            keyed.append((key, index))
        keyed.sort()
        self._assignments = head + [tail[index] for _, index in keyed]

    def name(self, expr) -> sympy.Expr:
        """Return a symbol standing for ``expr`` (or ``expr`` itself if trivial)."""
        if not isinstance(expr, sympy.Basic):
            expr = sympy.sympify(expr)
        if _is_trivial(expr):
            return expr
        # a negated intermediate stays inline: -mg_3 is free in C
        if expr.is_Mul and len(expr.args) == 2 and expr.args[0] is sympy.S.NegativeOne:
            inner = self.name(expr.args[1])
            return -inner
        return self._symbol(expr)

    def factor(self, expr) -> sympy.Expr:
        """A symbol for ``expr`` even when it is a number times a symbol (``2*l``),
        which :meth:`name` leaves inline: for a factor that multiplies several
        things, or that the caller wants computed once (a parameter's multiple,
        hoisted with the parameters)."""
        if not isinstance(expr, sympy.Basic):
            expr = sympy.sympify(expr)
        if expr.is_Number or expr.is_Symbol:
            return expr
        return self._symbol(expr)

    def _symbol(self, expr) -> sympy.Symbol:
        """The statement's symbol for ``expr``, recording the statement once."""
        sym = self._memo.get(expr)
        if sym is None:
            sym = sympy.Symbol(f"{PREFIX}{len(self._assignments)}")
            self._assignments.append((sym, expr))
            self._memo[expr] = sym
            if self.place is not None:
                self._places[sym] = self.place
        return sym

    def vec(self, components) -> tuple:
        """Name each component of a vector."""
        return tuple(self.name(c) for c in components)

    def freeze(self) -> Graph:
        return Graph(tuple(self._assignments), self._free)
