"""CSE stage: one common-subexpression pass per generated C function.

Input: the program of named intermediates (:class:`modelgen.derive.graph.Graph`) and
the outputs a function must write.  Output: a :class:`Routine`, the ordered
statements that compute exactly those outputs (dead intermediates dropped),
after one ``sympy.cse`` pass over all of them, with operation counts before
and after.

``sympy.cse`` returns its replacements ahead of the reduced expressions, but
here a replacement may use intermediates defined by earlier statements.  The
statements are therefore merged in dependency order: every replacement is
emitted just before the first statement that needs it.  That keeps the
original, deterministic program order (``order='none'`` is used for speed;
determinism comes from the program order and the numbered symbols).
"""
from __future__ import annotations

import importlib
import sys
import types
from dataclasses import dataclass

import sympy

from modelgen.derive.graph import Graph, free_symbols
from modelgen.derive.spatial import canonical_product, canonical_sum
from modelgen.codegen.printer import c_operations


@dataclass(frozen=True)
class Routine:
    """A straight-line routine ready to print.

    ``statements``: ((symbol, expr), ...) in execution order;
    ``outputs``: ((array name, (expr, ...)), ...), written after the statements;
    ``inputs``: ((array name, (symbol, ...)), ...) -- element i of the array is
    the i-th symbol; scalar inputs (``t``) have a 1-tuple and ``scalar=True``
    in ``scalars``.
    """
    name: str
    inputs: tuple
    outputs: tuple
    statements: tuple
    ops_before: int
    ops_after: int


def count_ops(exprs) -> int:
    """Floating-point operations of a list of expressions, each counted as
    printed in C (:func:`modelgen.codegen.printer.c_operations`).

    >>> x, y = sympy.symbols("x y")
    >>> count_ops([x*y + 1, x**2, sympy.sin(x) / y, x - x*y])
    7
    """
    return sum(c_operations(e) for e in exprs)


#: sympy functions with a symengine function of the same name and arity
#: (anything else is converted by ``symengine.sympify``).
_SYMENGINE_FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh",
                        "exp", "log")


def _converters(symengine, shared=None):
    """``(to_symengine, to_sympy)``: sympy <-> symengine converters sharing one memo.

    The statements of a program share their leaves (every intermediate symbol
    is used by several statements), so remembering the converted nodes makes
    the way in about 1.6x faster than ``symengine.sympify`` of each statement
    (chain 6: 11.5 against 18.6 ms), for the same symengine expression.  The
    way back maps every symengine symbol to the sympy symbol it came from (or
    to the name given by ``to_sympy.rename``), so cse's temporaries get their
    final names as the sympy expression is built, instead of by an
    ``xreplace`` that builds it a second time.

    ``shared`` (a dict, empty at first) keeps the way in and the symbols for
    the next converters given it: the CSE passes of one program convert the
    same statements (the way back is each pass's own, for its renames).
    """
    functions = {getattr(sympy, name): getattr(symengine, name) for name in _SYMENGINE_FUNCTIONS}
    if shared is None:
        shared = {}
    forward = shared.setdefault("forward", {})
    origin = shared.setdefault("symbols", {})
    back = dict(origin)

    def to_symengine(e):
        r = forward.get(e)
        if r is not None:
            return r
        if e.is_Symbol:
            r = symengine.Symbol(e.name)
            back[r] = origin[r] = e
        elif e.is_Add:
            r = symengine.Add(*[to_symengine(a) for a in e.args])
        elif e.is_Mul:
            r = symengine.Mul(*[to_symengine(a) for a in e.args])
        elif e.is_Pow:
            r = symengine.Pow(to_symengine(e.args[0]), to_symengine(e.args[1]))
        elif e.is_Integer:
            r = symengine.Integer(e.p)
        elif e.is_Rational:
            r = symengine.Rational(e.p, e.q)
        elif e.func in functions:
            r = functions[e.func](*[to_symengine(a) for a in e.args])
        else:
            r = symengine.sympify(e)
        forward[e] = r
        return r

    add, mul, power = symengine.Add, symengine.Mul, symengine.Pow
    renamed = {}

    def to_sympy(e):
        r = back.get(e)
        if r is not None:
            return r
        kind = type(e)
        if kind is add:
            args = [to_sympy(a) for a in e.args]
            r = canonical_sum(args)
            if r is None:
                r = sympy.Add(*args)
        elif kind is mul:
            args = [to_sympy(a) for a in e.args]
            r = canonical_product(args)
            if r is None:
                r = sympy.Mul(*args)
        elif kind is power:
            r = sympy.Pow(to_sympy(e.args[0]), to_sympy(e.args[1]))
        else:       # numbers, functions, anything else: symengine's own conversion
            r = sympy.sympify(e)
            if renamed and r.free_symbols:
                r = r.xreplace(renamed)
        back[e] = r
        return r

    def rename(symbol, new):
        """From now on, ``to_sympy`` turns the symengine ``symbol`` into ``new``."""
        back[symbol] = new
        renamed[sympy.Symbol(str(symbol))] = new

    to_sympy.rename = rename
    return to_symengine, to_sympy


def _closure_ops(statements, memo: dict) -> int:
    """Operations of ``statements``, each expression counted once (``memo``:
    expression -> operations, shared by the routines of one program)."""
    total = 0
    for _, expr in statements:
        n = memo.get(expr)
        if n is None:
            n = memo[expr] = c_operations(expr)
        total += n
    return total


def _cse(exprs, shared=None):
    """(replacements, reduced) from symengine's cse when available, else sympy's;
    an expression the cse leaves unchanged is returned as the same object.

    symengine's cse is about 17x faster on a 30-link chain (0.08 s against
    1.4 s for sympy's ``order='none'``) for the same number of temporaries.
    Replacement symbols are renamed ``mg_c<i>`` in order of appearance.
    ``shared``: the conversions' memo of :func:`_converters`.
    """
    try:
        symengine = import_symengine()
    except ImportError:   # pragma: no cover - symengine is a declared dependency
        return sympy.cse(exprs, symbols=_numbered("mg_c"), order="none")
    to_symengine, to_sympy = _converters(symengine, shared)
    originals = [to_symengine(e) for e in exprs]
    reps, reduced = symengine.cse(originals)
    replacements = []
    for i, (sym, value) in enumerate(reps):
        new = sympy.Symbol(f"mg_c{i}")
        replacements.append((new, to_sympy(value)))
        to_sympy.rename(sym, new)
    # most statements of a straight-line program come back unchanged: keep the
    # sympy original (converting back costs ten times the cse itself)
    reduced = [e if r == o else to_sympy(r) for e, o, r in zip(exprs, originals, reduced)]
    return replacements, reduced


class _NumpyOnFirstUse(types.ModuleType):
    """What symengine's import binds as ``numpy`` when numpy is not imported yet: a
    stand-in that imports numpy (the one module of that name) on first use."""

    def __getattr__(self, name: str):
        if sys.modules.get("numpy") is self:
            del sys.modules["numpy"]
        return getattr(importlib.import_module("numpy"), name)


def import_symengine():
    """symengine, imported without importing numpy with it.

    symengine's import only binds numpy, for its ``lambdify`` and numpy's scalars,
    which nothing here uses; a model read from YAML needs no numpy before its
    compile, and the loader imports it while the compilers run
    (:mod:`modelgen.sim.load`).  So while symengine is imported, ``numpy`` in
    ``sys.modules`` is a stand-in (:class:`_NumpyOnFirstUse`), which symengine
    keeps and which imports numpy, the real module, when anything of it is used.
    """
    if "symengine" not in sys.modules and "numpy" not in sys.modules:
        sys.modules["numpy"] = _NumpyOnFirstUse("numpy")
        try:
            import symengine
        finally:
            if isinstance(sys.modules.get("numpy"), _NumpyOnFirstUse):
                del sys.modules["numpy"]
    import symengine
    return symengine


def _numbered(prefix):
    i = 0
    while True:
        yield sympy.Symbol(f"{prefix}{i}")
        i += 1


def eliminate(graph: Graph, outputs, shared=None) -> tuple:
    """One ``sympy.cse`` pass over everything needed for ``outputs``.

    Returns ``(new_graph, new_outputs)``: a program whose statements compute
    the same values with common subexpressions named ``mg_c<i>``, and the
    outputs rewritten in terms of it (dead statements are dropped).
    ``shared`` (a dict) carries the conversions to symengine to the next pass
    over the same program.
    """
    outputs = list(outputs)
    program = graph.closure(outputs)
    if not program:
        return Graph(()), outputs
    exprs = [e for _, e in program] + outputs
    replacements, reduced = _cse(exprs, shared)
    rep = dict(replacements)
    emitted = set()
    statements = []

    def emit_deps(expr):
        stack = [(expr, False)]
        while stack:
            e, ready = stack.pop()
            if ready:
                if e not in emitted:
                    emitted.add(e)
                    statements.append((e, rep[e]))
                continue
            # remembered in the program's memo, which _propagate_copies reads again
            deps = (e,) if e.is_Symbol else graph.symbols_of(e)
            for s in sorted((s for s in deps if s in rep and s not in emitted),
                            key=str, reverse=True):
                stack.append((s, True))
                stack.append((rep[s], False))

    for (sym, original), expr in zip(program, reduced):
        if expr is not original:    # an unchanged statement uses no replacement
            emit_deps(expr)
        statements.append((sym, expr))
    new_outputs = reduced[len(program):]
    for e in new_outputs:
        emit_deps(e)
    return _propagate_copies(statements, list(new_outputs), graph)


def _propagate_copies(statements, outputs, graph: Graph):
    """Drop statements ``a = b`` (b a symbol or number) and use b in place of a.
    The free symbols come from ``graph``'s memo (:meth:`Graph.symbols_of`), which
    the new graph keeps."""
    alias = {}
    kept = []
    for sym, expr in statements:
        if alias and not expr.is_Atom:
            renamed = {s: alias[s] for s in graph.symbols_of(expr) if s in alias}
            if renamed:
                expr = expr.xreplace(renamed)
        elif expr in alias:
            expr = alias[expr]
        if expr.is_Symbol or expr.is_Number:
            alias[sym] = expr
        else:
            kept.append((sym, expr))
    if alias:
        outputs = [alias.get(e, e) if e.is_Symbol else
                   e.xreplace({s: alias[s] for s in free_symbols(e) if s in alias})
                   for e in outputs]
    return Graph(tuple(kept), graph.free), outputs


def make_routines(graph: Graph, routines, *, cse: bool = True, alone=(), plain=(),
                  ready=None) -> tuple:
    """Build several routines from one program with a single CSE pass.

    ``routines`` is a sequence of ``(name, inputs, outputs)`` where ``outputs``
    is ``((array name, (expr, ...)), ...)``.  A routine named in ``alone`` gets
    a CSE pass of its own: a joint pass names subexpressions that several
    routines share, and can split one routine's sums and products where that
    routine alone would not (the ABA rhs of the 20-link chain: 229.1
    operations a coordinate after a joint pass, 226.8 after its own).  Those
    passes come first, in the order of ``alone``, and ``ready(built)`` (if
    given) is called after each with the routines built so far (name ->
    Routine), before the joint pass.  A routine named in ``alone`` and in
    ``plain`` keeps its program as derived, with no CSE pass: one whose
    derivation already names every quantity it shares, where what a pass
    would find the compiler's value numbering finds too.

    >>> import sympy
    >>> from modelgen.derive.graph import GraphBuilder
    >>> x, y = sympy.symbols("x y")
    >>> g = GraphBuilder(); a = g.name(x*y + x); b = g.name((x*y + 1)**2)
    >>> (r,) = make_routines(g.freeze(), [("f", (("in", (x, y)),), (("out", (a, b)),))])
    >>> [str(e) for _, e in r.statements], r.ops_before, r.ops_after
    (['x*y', 'mg_c0 + x', '(mg_c0 + 1)**2'], 5, 4)
    """
    # expression -> operations, for every routine: the groups share statements
    return _make_routines(graph, routines, cse, alone, {}, {}, ready, plain)


def _make_routines(graph: Graph, routines, cse: bool, alone, ops: dict, shared: dict,
                   ready=None, plain=()) -> tuple:
    routines = [(name, tuple(inputs), tuple(outputs)) for name, inputs, outputs in routines]
    if alone:
        built = {}
        for group in sorted(([r] for r in routines if r[0] in alone),
                            key=lambda group: list(alone).index(group[0][0])):
            built.update((r.name, r) for r in _make_routines(
                graph, group, cse and group[0][0] not in plain, (), ops, shared))
            if ready is not None:
                ready(dict(built))
        rest = [r for r in routines if r[0] not in alone]
        if rest:
            built.update((r.name, r) for r in _make_routines(graph, rest, cse, (), ops, shared))
        return tuple(built[name] for name, _, _ in routines)
    all_outputs = [e for _, _, outs in routines for _, items in outs for e in items]
    before = {}
    for name, _, outs in routines:
        flat = [e for _, items in outs for e in items]
        before[name] = _closure_ops(graph.closure(flat), ops) + count_ops(flat)
    if cse:
        graph, all_outputs = eliminate(graph, all_outputs, shared)
    result = []
    pos = 0
    for name, inputs, outs in routines:
        new_outs = []
        for array, items in outs:
            new_outs.append((array, tuple(all_outputs[pos:pos + len(items)])))
            pos += len(items)
        flat = [e for _, items in new_outs for e in items]
        statements = graph.closure(flat)
        after = _closure_ops(statements, ops) + count_ops(flat)
        result.append(Routine(name, inputs, tuple(new_outs), statements, before[name], after))
    return tuple(result)


def hoist_parameters(routine: Routine, name: str = "prepare") -> tuple:
    """``(prepare, rest)``: ``routine`` split where its statements stop depending
    on the parameters alone.

    ``prepare`` (inputs ``p``) computes every statement whose value depends on
    the parameters only (a body's inertia about its joint, ``m l / 2``, the
    difference of two principal moments...) and writes the ones ``rest``
    needs into ``pd``; ``rest`` is ``routine`` with those statements removed
    and ``pd`` as one more input.  A caller that integrates with fixed
    parameters runs ``prepare`` once and ``rest`` at every step, as Pinocchio
    and MuJoCo keep a model's inertias precomputed.  The values are those of
    ``routine``, bit for bit: the same statements, evaluated once.

    >>> import sympy
    >>> from modelgen.derive.graph import GraphBuilder
    >>> x, m, l = sympy.symbols("x m l")
    >>> g = GraphBuilder(); a = g.name(m * l / 2); b = g.name(a * x + m)
    >>> (r,) = make_routines(g.freeze(), [("f", (("x", (x,)), ("p", (m, l))), (("out", (b,)),))])
    >>> pre, rest = hoist_parameters(r)
    >>> [str(e) for _, e in pre.statements], pre.outputs, [str(e) for _, e in rest.statements]
    (['l*m/2'], (('pd', (mg_0,)),), ['m + mg_0*x'])
    >>> rest.inputs[-1], pre.ops_after + rest.ops_after == r.ops_after
    (('pd', (mg_0,)), True)
    """
    parameters = tuple(s for array, symbols in routine.inputs if array == "p" for s in symbols)
    params = set(parameters)
    fixed, before, after = set(), [], []
    for sym, expr in routine.statements:
        # not ``<= params | fixed``: that union costs the size of ``fixed`` each time
        if all(s in params or s in fixed for s in free_symbols(expr)):
            fixed.add(sym)
            before.append((sym, expr))
        else:
            after.append((sym, expr))
    used = set()
    for _, expr in after:
        used |= free_symbols(expr) & fixed
    for _, items in routine.outputs:
        for e in items:
            used |= free_symbols(e) & fixed
    pd = tuple(sym for sym, _ in before if sym in used)
    ops = sum(c_operations(e) for _, e in before)
    prepare = Routine(name, (("p", parameters),), (("pd", pd),), tuple(before), ops, ops)
    # ops_before stays the whole program's, before CSE and hoisting
    rest = Routine(routine.name, routine.inputs + (("pd", pd),), routine.outputs, tuple(after),
                   routine.ops_before, routine.ops_after - ops)
    return prepare, rest
