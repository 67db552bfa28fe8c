"""The load-time check of a mass matrix singular by construction, in plain Python.

A build is refused when its mass matrix A, evaluated with the default
parameters at a few scattered configurations, fails the generated solve's
pivot test at every one of them: a coordinate whose pivot vanishes
everywhere moves no mass or inertia (e.g. a body with zero inertia about a
terminal joint axis, or an unused coordinate).  Defaults that overflow or
underflow A are named as such instead.

Everything here works on lists of floats and imports no numpy, so that
``modelgen generate`` (:func:`modelgen.sim.load.generate_model`) checks its
library through :mod:`ctypes` without numpy's import while its compilers run;
:func:`modelgen.sim.runtime.check_mass_matrix` runs the same :func:`check` on a
loaded :class:`~modelgen.sim.runtime.CompiledModel`.

The pivot test is that of :mod:`modelgen.sim.conditioning` (``A = L D L^T``
without pivoting; pivot j fails when ``d_j <= PIVOT_TOL * A_jj`` or
``A_jj <= 0``).

>>> failing_pivot([[1.0, 1.0], [1.0, 1.0]])
1
>>> failing_pivot([[1.0, 0.0], [0.0, 1e-15]]) is None     # a mass ratio of 1e15
True
"""
from __future__ import annotations

import math
from operator import mul

from modelgen.errors import DerivationError

#: relative pivot tolerance (the generated C's ``<NAME>_PIVOT_TOL``)
PIVOT_TOL = 1e-13
#: a mass matrix whose largest entry is below this cannot be factorized meaningfully
#: in double precision (its pivots underflow to subnormal numbers)
TINY_MASS_MATRIX = 1e-250


def check(manifest: dict, mass_matrix, samples: int = 3, seed: int = 0) -> None:
    """Raise :class:`DerivationError` if the model of ``manifest`` has a mass matrix
    singular by construction (naming the coordinate), or default parameters
    whose A overflows or underflows double precision (naming them).

    ``mass_matrix(q)`` returns A (n lists of n floats) at the configuration ``q``
    (a list of ``nq`` floats) with the default parameters.
    """
    failing = None
    for k in range(samples):
        A = mass_matrix(configuration(manifest, k + seed))
        check_representable(manifest, A)
        pivot = failing_pivot(A)
        if pivot is None:
            pivot = negligible_diagonal(A)    # zero up to rounding
        if pivot is None:
            return
        failing = pivot
    name = dof_names(manifest)[failing]
    raise DerivationError(
        f"{manifest['name']}: the mass matrix is singular for every configuration tried: "
        f"coordinate {name!r} (row {failing + 1} of A) moves no mass or inertia "
        f"independently of the coordinates before it; give the bodies it moves mass and "
        f"inertia about its axis, or remove the coordinate")


def dof_names(manifest: dict) -> tuple:
    """One name per degree of freedom (the rows of A): a simple coordinate's own
    name, a ball or free joint's speed name."""
    coordinates = tuple(manifest["coordinates"])
    speeds = tuple(manifest.get("speeds") or (f"{c}_dot" for c in coordinates))
    simple = manifest.get("n_simple", len(coordinates))
    return coordinates[:simple] + speeds[simple:]


def configuration(manifest: dict, k: int) -> list:
    """The ``k``-th scattered configuration of the model (:func:`scattered`), with each
    joint's quaternion normalised."""
    q = scattered(len(manifest["coordinates"]), k)
    for quat in manifest.get("quaternions", ()):
        norm = math.sqrt(sum(q[i] * q[i] for i in quat))
        for i in quat:
            q[i] /= norm
    return q


def scattered(n: int, k: int) -> list:
    """The ``k``-th of a sequence of configurations spread over [-pi, pi)^n: a Weyl
    sequence with irrational steps, so no coordinate repeats a value or another
    coordinate's (without a random generator's import).

    >>> [round(v, 3) for v in scattered(3, 0)]
    [-2.939, 2.022, 0.45]
    """
    step = (k + 1) * 0.41421356237309515
    return [math.pi * (2.0 * math.modf(i * 0.6180339887498949 + step * math.sqrt(i))[0] - 1.0)
            for i in range(1, n + 1)]


def check_representable(manifest: dict, A) -> None:
    """Refuse default parameters whose mass matrix overflows or underflows double
    precision, saying so (not "moves no mass")."""
    extremes = ", ".join(f"{name} = {value:g}" for name, value in _parameters(manifest)
                         if value != 0 and not 1e-100 < abs(value) < 1e100) or "none"
    if not all(math.isfinite(v) for row in A for v in row):
        raise DerivationError(
            f"{manifest['name']}: the mass matrix overflows double precision with the "
            f"default parameters (parameters beyond 1e+-100: {extremes}); choose units in "
            f"which masses, lengths and inertias are nearer 1")
    if max(abs(v) for row in A for v in row) < TINY_MASS_MATRIX:
        raise DerivationError(
            f"{manifest['name']}: the mass matrix is below {TINY_MASS_MATRIX:g} with the "
            f"default parameters, too small for double precision (parameters beyond "
            f"1e+-100: {extremes}); choose units in which masses, lengths and inertias "
            f"are nearer 1")


def _parameters(manifest: dict) -> list:
    return [(name, float(value)) for name, value in manifest["parameters"]]


def default_parameters(manifest: dict) -> list:
    """The default parameter values of the manifest, in declaration order."""
    return [value for _, value in _parameters(manifest)]


def pivot_ratios(A) -> list:
    """``d_j / A_jj`` of the LDL^T factorization of A (n lists of n floats), up to
    and including the first pivot that fails the test (NaN after it)."""
    n = len(A)
    L = [[0.0] * n for _ in range(n)]
    d = [0.0] * n
    ratios = [math.nan] * n
    for j in range(n):
        Lj, Ajj = L[j][:j], A[j][j]
        Ld = list(map(mul, Lj, d))                  # L_jk d_k, k < j
        d[j] = Ajj - sum(map(mul, Lj, Ld))
        # a diagonal that is zero, negative or NaN: the coordinate moves no mass (or
        # the parameters are not physical): not positive definite
        ratios[j] = d[j] / Ajj if Ajj > 0 else -math.inf
        if not ratios[j] > PIVOT_TOL:
            break
        for i in range(j + 1, n):
            Li = L[i]
            Li[j] = (A[i][j] - sum(map(mul, Li[:j], Ld))) / d[j]
    return ratios


def failing_pivot(A, tol: float = PIVOT_TOL):
    """0-based index of the first pivot with ``d_j <= tol * A_jj`` (or NaN), or None."""
    for j, r in enumerate(pivot_ratios(A)):
        if not r > tol:
            return j
    return None


def negligible_diagonal(A, tol: float = PIVOT_TOL):
    """0-based index of the first diagonal entry ``A_jj <= tol * max_i A_ii``, or None.

    Not a run-time test (a mass ratio of 1e-15 is well defined): the load-time
    check uses it, because a coordinate that moves no mass leaves a diagonal
    that is zero only up to rounding, which the pivot test alone can let through.
    """
    diag = [float(A[j][j]) for j in range(len(A))]
    largest = math.nan if any(math.isnan(a) for a in diag) else max(max(diag), 0.0)
    for j, a in enumerate(diag):
        if not a > tol * largest:
            return j
    return None
