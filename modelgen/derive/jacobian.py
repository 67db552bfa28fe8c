"""Jacobian stage: d(xdot)/dx by forward-mode differentiation of the program.

With x = [q, qd] and A(q) qdd = tau - h, the Jacobian is
``[[0, I], [dqdd/dq, dqdd/dqd]]``.  Differentiating ``A qdd = tau - h`` at
fixed ``qdd = a`` gives ``A dqdd/dx = d(tau - h - A a)/dx``, so it suffices to
differentiate the residual ``r(x, a) = tau - h - A a`` with ``a`` an input
(the accelerations the C code has just computed) and to solve with the same
A.  No symbolic inverse is ever formed.

The residual is differentiated statement by statement along the straight-line
program (forward mode): every intermediate s gets named derivatives
``ds/dx_j`` only for the state variables it depends on, so the cost follows
the sparsity of the program instead of the size of the closed form.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.calculus import diff
from modelgen.derive.dynamics import Equations
from modelgen.derive.graph import Graph, GraphBuilder


@dataclass(frozen=True)
class JacobianTerms:
    """``D[k][j] = d r_k / d x_j`` (nv x nx) over ``graph``; ``a`` the qdd symbols.

    ``K[i][j] = d (dq_i/dt) / d x_j`` (nq x nx) for a model with ball or free
    joints, where dq/dt = N(q) qd is not the speeds themselves; empty otherwise.
    """
    graph: Graph
    a: tuple
    D: tuple
    K: tuple = ()


def accelerations(n: int) -> tuple:
    """The symbols standing for qdd inside the Jacobian routine."""
    return tuple(sympy.Symbol(f"mg_qdd{k}") for k in range(n))


def differentiate(graph: Graph, outputs, wrt) -> tuple:
    """Forward-mode derivatives of ``outputs`` with respect to the symbols ``wrt``.

    Returns ``(graph', rows)`` with ``rows[i][j] = d outputs[i] / d wrt[j]``
    as expressions over ``graph'`` (which extends ``graph``).

    >>> from modelgen.derive.graph import GraphBuilder
    >>> x, y = sympy.symbols("x y")
    >>> builder = GraphBuilder(); s = builder.name(sympy.sin(x) * y)
    >>> graph, rows = differentiate(builder.freeze(), [s + x], [x, y])
    >>> [graph.expand(e) for e in rows[0]]
    [y*cos(x) + 1, sin(x)]
    """
    index = {s: j for j, s in enumerate(wrt)}
    builder = GraphBuilder(graph)
    grads: dict = {}

    def grad_of(expr):
        """{j: d expr / d wrt_j} for an expression over already-differentiated symbols."""
        total: dict = {}
        for f in expr.free_symbols:
            if f in index:
                inner = {index[f]: sympy.S.One}
            else:
                inner = grads.get(f)
                if not inner:
                    continue
            partial = diff(expr, f)
            if partial == 0:
                continue
            for j, dj in inner.items():
                total[j] = total.get(j, sympy.S.Zero) + partial * dj
        # named in column order, not in the order of the free-symbol set (which
        # follows the hash seed), so the generated C is the same on every run
        return {j: builder.name(v) for j, v in sorted(total.items()) if v != 0}

    for sym, expr in graph.closure(outputs):
        g = grad_of(expr)
        if g:
            grads[sym] = g
    rows = []
    for out in outputs:
        g = grad_of(sympy.sympify(out))
        rows.append(tuple(g.get(j, sympy.S.Zero) for j in range(len(wrt))))
    return builder.freeze(), tuple(rows)


def residual(eqs: Equations) -> tuple:
    """``(a, r)``: the qdd symbols and ``r = tau - h - A a``, zero at the solution."""
    n = len(eqs.qd)
    a = accelerations(n)
    return a, tuple(eqs.tau[k] - eqs.h[k] - sympy.Add(*[eqs.A[k][l] * a[l] for l in range(n)])
                    for k in range(n))


def derive_jacobian_terms(eqs: Equations, graph: Graph | None = None) -> JacobianTerms:
    """d(tau - h - A a)/dx for the equations ``eqs`` (graph defaults to eqs.graph)."""
    a, r = residual(eqs)
    extra = eqs.qdot if eqs.has_joints else ()
    graph, rows = differentiate(graph or eqs.graph, tuple(r) + tuple(extra), eqs.q + eqs.qd)
    return JacobianTerms(graph, a, rows[:len(r)], rows[len(r):])
