"""Linearization of a constrained model: forward-mode derivatives of its three
sets of equations, for the C code to combine by the implicit function theorem.

A constrained model's rhs (``templates/constraints.c.j2``) computes, from q
and the independent speeds u_i, the dependent speeds and the accelerations
``a`` that satisfy

    G(q) qd = 0                                  (m equations: qd from u_i)
    G(q) a + gamma(q, qd) = 0                    (m: the accelerations' constraints)
    tau - h - A(q) a + G(q)^T lam = 0            (n: Kane's equations, lam the
                                                  constraint forces)

Differentiating them at the solution (q, qd, a, lam) with respect to
[q, qd, u] gives linear equations for the derivatives of the dependent
speeds, of ``a`` and of ``lam``, whose matrices are the rhs's own (G_d and
``T^T A T``).  So only the partial derivatives of the three left-hand sides,
with ``a`` and ``lam`` held as inputs, are derived here (no symbolic inverse,
no finite differences); the C code solves for the total ones.  The rows of
:attr:`LinearizationTerms.R` are those of the n Kane rows, then the m
velocity rows ``G qd``, then the m acceleration rows ``G a + gamma``.
"""
from __future__ import annotations

import sympy

from modelgen.derive.constraints import ConstraintTerms
from modelgen.derive.dynamics import Equations
from modelgen.derive.jacobian import differentiate, residual
from modelgen.derive.linearize import LinearizationTerms

__all__ = ["derive_constrained_linearization_terms", "multipliers"]


def multipliers(m: int) -> tuple:
    """The symbols standing for the constraint forces lam inside the routine."""
    return tuple(sympy.Symbol(f"mg_lam{k}") for k in range(m))


def derive_constrained_linearization_terms(eqs: Equations, constraints: ConstraintTerms,
                                           outputs=()) -> LinearizationTerms:
    """d/d[q, qd, u] of Kane's rows ``tau - h - A a + G^T lam``, of ``G qd`` and of
    ``G a + gamma``, and of the scene's ``outputs``, over ``constraints.graph``.

    >>> terms = derive_constrained_linearization_terms(eqs, constraints)   # doctest: +SKIP
    >>> len(terms.R) == len(eqs.q) + 2 * constraints.m                     # doctest: +SKIP
    True
    """
    n, m = len(eqs.q), constraints.m
    a, r = residual(eqs)
    lam = multipliers(m)
    G = constraints.G
    kane = [r[k] + sympy.Add(*[G[i][k] * lam[i] for i in range(m)]) for k in range(n)]
    velocity = [sympy.Add(*[G[i][k] * eqs.qd[k] for k in range(n)]) for i in range(m)]
    acceleration = [sympy.Add(*[G[i][k] * a[k] for k in range(n)]) + constraints.gamma[i]
                    for i in range(m)]
    rows_in = kane + velocity + acceleration
    graph, rows = differentiate(constraints.graph, rows_in + list(outputs),
                                eqs.q + eqs.qd + eqs.u)
    return LinearizationTerms(graph, a, rows[:len(rows_in)], rows[len(rows_in):], 2 * n,
                              lam=lam)
