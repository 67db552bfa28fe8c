"""How close a mass matrix is to singular: the pivot test, its wording, and its growth along a run.

The generated solve factors A = L D L^T without pivoting and refuses pivot j
when ``d_j <= tol * A_jj`` or ``A_jj <= 0`` (``PIVOT_TOL`` = 1e-13, the C's
``<NAME>_PIVOT_TOL``).
The ratio ``A_jj / d_j`` is the factorization's estimate of the condition
number of the diagonally scaled A, the one that bounds the error of q''
(extreme mass ratios inflate cond(A) but not this one; DYNAMICS-NOTES), so
the test refuses A only when q'' is lost to round-off.  The two ways to fail
are worded apart: a pivot with |d_j| <= tol * A_jj on a positive diagonal
is *singular to working precision*; a pivot more negative than that, a
diagonal A_jj <= 0, or NaN is *not positive definite*.

>>> A = np.array([[1.0, 0.0], [0.0, 1e-15]])          # a mass ratio of 1e15: well defined
>>> failing_pivot(A) is None
True
>>> failure_kind(np.array([[1.0, 1.0], [1.0, 1.0 + 1e-15]]), 1)
'singular to working precision'
>>> failure_kind(np.array([[1.0, 2.0], [2.0, 1.0]]), 1)
'not positive definite'
"""
from __future__ import annotations

import numpy as np

from modelgen.sim.massmatrix import PIVOT_TOL
#: a failure note names the configuration when cond(A) grew by this factor
GROWTH = 1e3


def pivot_ratios(A) -> np.ndarray:
    """``d_j / A_jj`` of the LDL^T factorization, up to and including the first
    pivot that fails the test (NaN after it)."""
    A = np.array(A, dtype=float)
    n = A.shape[0]
    L, d = np.eye(n), np.zeros(n)
    ratios = np.full(n, np.nan)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):   # inf or NaN in A
        return _ratios(A, L, d, ratios)


def _ratios(A, L, d, ratios) -> np.ndarray:
    for j in range(A.shape[0]):
        d[j] = A[j, j] - (L[j, :j] * L[j, :j]) @ d[:j]
        # a diagonal that is zero, negative or NaN: the coordinate moves no mass (or
        # the parameters are not physical): not positive definite
        ratios[j] = d[j] / A[j, j] if A[j, j] > 0 else -np.inf
        if not ratios[j] > PIVOT_TOL:
            break
        L[j + 1:, j] = (A[j + 1:, j] - L[j + 1:, :j] @ (L[j, :j] * d[:j])) / d[j]
    return ratios


def failing_pivot(A, tol: float = PIVOT_TOL):
    """0-based index of the first pivot with ``d_j <= tol * A_jj`` (or NaN), or None."""
    ratios = pivot_ratios(A)
    for j, r in enumerate(ratios):
        if not r > tol:
            return j
    return None


def failure_kind(A, pivot: int, tol: float = PIVOT_TOL) -> str:
    """Why pivot ``pivot`` (0-based) of A fails: 'singular to working precision'
    (|d_j| <= tol A_jj) or 'not positive definite' (below that, or NaN)."""
    r = pivot_ratios(A)[pivot]
    return "singular to working precision" if r >= -tol else "not positive definite"


def condition_number(A) -> float:
    """2-norm condition number of A (inf when A is singular or not finite)."""
    A = np.asarray(A, dtype=float)
    if not np.all(np.isfinite(A)):
        return float("inf")
    try:
        return float(np.linalg.cond(A))
    except np.linalg.LinAlgError:
        return float("inf")


def growth_note(cond_start: float, cond_end: float) -> str:
    """A sentence for a failed run's message when A's condition number grew by
    ``GROWTH`` or more between its start and its last good state, else ''."""
    if not cond_end >= GROWTH * cond_start:
        return ""
    return (f" A's condition number grew from {cond_start:.0e} to {cond_end:.0e}: the "
            "coordinates are near a singular configuration (Euler angles at gimbal lock?).")
