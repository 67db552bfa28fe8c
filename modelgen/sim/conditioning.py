"""How close a mass matrix is to singular: the pivot test's wording, and its growth along a run.

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

The test itself is :func:`modelgen.sim.massmatrix.failing_pivot` (plain Python,
which a build's check runs without numpy):

>>> from modelgen.sim.massmatrix import failing_pivot
>>> failing_pivot([[1.0, 0.0], [0.0, 1e-15]]) is None   # a mass ratio of 1e15: well defined
True
>>> failure_kind(np.array([[1.0, 1.0], [1.0, 1.0 + 1e-15]]), 1)
'singular to working precision'
>>> failure_kind(np.array([[1.0, 2.0], [2.0, 1.0]]), 1)
'not positive definite'
"""
from __future__ import annotations

import numpy as np

from modelgen.sim.massmatrix import PIVOT_TOL, pivot_ratios
#: a failure note names the configuration when cond(A) grew by this factor
GROWTH = 1e3


def failure_kind(A, pivot: int, tol: float = PIVOT_TOL) -> str:
    """Why pivot ``pivot`` (0-based) of A fails: 'singular to working precision'
    (|d_j| <= tol A_jj) or 'not positive definite' (below that, or NaN)."""
    r = pivot_ratios(np.asarray(A, dtype=float).tolist())[pivot]
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
