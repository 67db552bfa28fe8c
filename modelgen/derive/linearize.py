"""Linearization stage: d(xdot)/d[x, u] and d(y)/d[x, u] by forward mode over the program.

With x = [q, qd], inputs u and scene outputs y(t, x, u), the state space
model about an operating point is

    d(dx)/dt = A dx + B du,    dy = C dx + D du,
    A = [[0, I], [dqdd/dq, dqdd/dqd]],  B = [[0], [dqdd/du]],
    C = dy/dx,                          D = dy/du.

The lower halves come from the same program as the Jacobian
(:mod:`modelgen.derive.jacobian`): for the crba formulation the residual
``r = tau - h - A a`` (``a`` the accelerations the rhs has just computed) is
differentiated with respect to ``[q, qd, u]`` and the C code solves with
``A``; for aba, ``qdd`` itself is differentiated and nothing is solved.  The
outputs are differentiated in the same pass, so they share its derivatives
of the kinematics.  No finite differences anywhere.

A joint tree whose ``<name>_derivatives`` (the derivatives of RNEA,
:mod:`modelgen.derive.rnea_partials`) cost fewer operations than this forward
mode takes the dynamics' rows of A and B from them instead, and only the
outputs are differentiated here (:func:`derive_output_linearization`; the
choice is :func:`modelgen.codegen.pipeline.generate`'s ``jacobian_method``).
"""
from __future__ import annotations

from dataclasses import dataclass

from modelgen.derive.dynamics import Equations
from modelgen.derive.graph import Graph
from modelgen.derive.jacobian import JacobianTerms, differentiate, residual


@dataclass(frozen=True)
class LinearizationTerms:
    """Derivatives over ``graph`` with respect to ``[q, qd, u]`` (``nx + nu`` columns).

    ``R[k][j]``: of the residual (crba: solve with A to get d qdd) or of
    ``qdd`` itself (aba, ``a == ()``); ``Y[i][j]``: of output column i.
    ``lam``: the multiplier symbols a constrained model's rows take as a
    further input (:mod:`modelgen.derive.constrained_linearize`; empty otherwise).
    """
    graph: Graph
    a: tuple
    R: tuple
    Y: tuple
    nx: int
    lam: tuple = ()

    def jacobian_terms(self) -> JacobianTerms:
        """The state columns of ``R``: what ``<name>_jacobian`` needs, no second pass."""
        return JacobianTerms(self.graph, self.a, tuple(row[:self.nx] for row in self.R))


def derive_linearization_terms(eqs: Equations, graph: Graph, outputs=(),
                               qdd=None) -> LinearizationTerms:
    """Forward-mode derivatives of the accelerations and of ``outputs`` w.r.t. x and u.

    ``qdd``: the accelerations of the aba program (differentiated directly);
    None for crba (the residual is differentiated).  ``outputs``: the scene's
    output expressions (functions of t, x, u, p; never of qdd).

    >>> terms = derive_linearization_terms(eqs, eqs.graph)          # doctest: +SKIP
    >>> len(terms.R[0]) == 2 * len(eqs.q) + len(eqs.u)              # doctest: +SKIP
    True
    """
    n = len(eqs.q)
    if qdd is None:
        a, f = residual(eqs)
    else:
        a, f = (), tuple(qdd)
    builder, rows = differentiate(graph, list(f) + list(outputs), eqs.q + eqs.qd + eqs.u)
    return LinearizationTerms(builder, a, rows[:n], rows[n:], 2 * n)


def derive_output_linearization(eqs: Equations, graph: Graph, outputs=()) -> LinearizationTerms:
    """Forward-mode derivatives of ``outputs`` alone w.r.t. x and u (``R`` empty): for
    a model whose A and B rows of the dynamics come from ``<name>_derivatives``
    (:mod:`modelgen.derive.rnea_partials`), so only C and D are differentiated here.

    >>> derive_output_linearization(eqs, eqs.graph).R                # doctest: +SKIP
    ()
    """
    if not outputs:
        return LinearizationTerms(graph, (), (), (), 2 * len(eqs.q))
    builder, rows = differentiate(graph, list(outputs), eqs.q + eqs.qd + eqs.u)
    return LinearizationTerms(builder, (), (), rows, 2 * len(eqs.q))
