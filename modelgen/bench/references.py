"""Reference solutions of work-precision problems, and how far each can be trusted.

Done the way SciML's DiffEqBenchmarks and Hairer's test set do it: a closed
form where one exists (:func:`linear_reference` for linear models, a
problem's own formula such as the pendulum's Jacobi sn), otherwise two
different high-order methods at rtol = atol <= 1e-13 whose disagreement is
measured (:func:`reference_from_methods`), in extended precision for chaotic
problems (:func:`extended_reference`: DOP853 and Gragg-Bulirsch-Stoer
extrapolation in numpy long double on the model's closed-form equations).
Every :class:`~modelgen.bench.problem.Reference` carries that spread; errors
less than 100 times it are not resolved.

>>> problem = replace(problem, reference=reference_from_methods(problem))   # doctest: +SKIP
"""
from __future__ import annotations

import mpmath
import numpy as np
import sympy
from scipy.integrate._ivp import dop853_coefficients

from modelgen.bench.methods import Budget, c_method, jacobian_function, on_grid
from modelgen.bench.problem import Problem, Reference
from modelgen.derive.queries import Mechanism
from modelgen.errors import SimulationError
from modelgen.model.spec import TIME


def _spreads(qa, qb) -> tuple:
    d = np.asarray(qa, dtype=float) - np.asarray(qb, dtype=float)
    return float(np.max(np.abs(d[-1]))), float(np.sqrt(np.mean(d ** 2)))


def reference_from_methods(problem: Problem, methods=None, tolerance: float = 1e-14,
                           budget: Budget = Budget(max_nfev=5_000_000, max_seconds=300,
                                                   max_steps=50_000_000)) -> Reference:
    """The first method's solution at rtol = atol = ``tolerance``, and its spread:
    the disagreement with the second method at the same tolerance.

    Default: C dop853 and C rodas (explicit order 8 against linearly implicit
    order 4).
    """
    if methods is None:
        methods = [c_method("dop853"), c_method("rodas")]
    sols = []
    for method in methods:
        out = method(problem, tolerance, budget)
        if out.status < 0 or not on_grid(out, problem):
            raise SimulationError(f"problem {problem.name}: reference by {method.label} at "
                                  f"{tolerance:g} failed: {out.message}")
        sols.append(np.asarray(out.y)[:problem.n].T)
    spread = _spreads(sols[0], sols[1])
    how = (f"{methods[0].label} at rtol = atol = {tolerance:g}, checked against "
           f"{methods[1].label} at the same tolerance")
    return Reference(problem.t_eval.copy(), sols[0], how, *spread)


def linear_reference(cm, x0, t, u=None, p=None, digits: int = 40) -> Reference:
    """Closed form of a linear (affine) model: x(t) = x0 + [expm(M t)]_top [0..0, 1],
    M = [[J, f(x0)], [0, 0]], with J the model's symbolic Jacobian, computed with
    mpmath to ``digits`` digits on the uniform grid ``t``.

    Raises :class:`SimulationError` when the compiled rhs is not affine near x0
    (checked at seeded random states).
    """
    x0 = np.asarray(x0, dtype=float)
    nx = len(x0)
    jac = jacobian_function(cm, u, p) if hasattr(cm.lib, f"{cm.name}_jacobian") else None
    if jac is None:
        raise SimulationError(f"{cm.name}: linear_reference needs the symbolic Jacobian "
                              f"(differences are good to ~1e-10 only); load the model with "
                              f"jacobian=True")
    J = jac(t[0], x0)
    f0 = cm.rhs(t[0], x0, u, p)
    rng = np.random.default_rng(1)
    for _ in range(5):
        dx = rng.normal(size=nx) * 1e-2 * (1 + np.abs(x0))
        want = f0 + J @ dx
        got = cm.rhs(t[0], x0 + dx, u, p)
        scale = np.abs(f0) + np.abs(J) @ np.abs(dx)
        if np.any(np.abs(got - want) > 1e-11 * scale + 1e-300):
            raise SimulationError(f"{cm.name}: the rhs is not affine near x0, so it has no "
                                  f"matrix-exponential closed form")
    spacing = np.diff(t)
    if not np.allclose(spacing, spacing[0], rtol=1e-9, atol=0):
        raise SimulationError("linear_reference needs a uniform grid")
    with mpmath.workdps(digits):
        M = mpmath.zeros(nx + 1, nx + 1)
        for i in range(nx):
            for j in range(nx):
                M[i, j] = mpmath.mpf(J[i, j])
            M[i, nx] = mpmath.mpf(f0[i])
        h = (mpmath.mpf(t[-1]) - mpmath.mpf(t[0])) / (len(t) - 1)
        E = mpmath.expm(M * h)
        z = mpmath.zeros(nx + 1, 1)
        z[nx] = 1
        rows = [np.zeros(nx)]
        for _ in range(len(t) - 1):
            z = E * z
            rows.append(np.array([float(z[i]) for i in range(nx)]))
    x = x0 + np.array(rows)
    n = nx // 2
    rounding = 4 * np.finfo(float).eps * float(np.max(np.abs(x[:, :n])))
    # how far the compiled rhs (rounding included) is from the linear map it is solved for
    residual = max(float(np.max(np.abs(cm.rhs(ti, xi, u, p) - f0 - J @ (xi - x0))))
                   for ti, xi in zip(t, x))
    return Reference(np.asarray(t, dtype=float).copy(), x[:, :n],
                     f"closed form of the linear system, expm([[J, f(x0)], [0, 0]] t) with "
                     f"mpmath ({digits} digits); along it the compiled rhs differs from the "
                     f"linear map by up to {residual:.1e} (its rounding)", rounding, rounding)



# -- extended precision (chaotic problems) --------------------------------------------

def extended_rhs(spec, p, u):
    """``f(t, x)`` in numpy long double (80-bit on x86: eps 1.1e-19) from the model's
    closed-form equations (:class:`modelgen.derive.queries.Mechanism`): A(q) qdd = tau - h.

    For small models (the closed forms grow quickly with n); ``p`` and ``u`` are
    the parameter and input vectors of the compiled model.
    """
    LD = np.longdouble
    mech = Mechanism(spec, simplify=False)
    A = mech.mass_matrix()
    b = mech.generalized_forces() - mech.velocity_terms()
    n = len(spec.coordinates)
    exprs = [A[i, j] for i in range(n) for j in range(i + 1)] + list(b)
    # rationals would be printed as Python float divisions: pass them as long doubles
    rationals = sorted({r for e in exprs for r in e.atoms(sympy.Rational) if not r.is_Integer},
                       key=lambda r: (r.p, r.q))
    r_syms = sympy.symbols(f"_r0:{len(rationals)}")
    exprs = [e.xreplace(dict(zip(rationals, r_syms))) for e in exprs]
    args = ([sympy.Symbol(c) for c in spec.coordinates]
            + [sympy.Symbol(c + "_dot") for c in spec.coordinates]
            + [sympy.Symbol(name) for name, _ in spec.parameters]
            + [sympy.Symbol(name) for name in spec.inputs] + list(r_syms) + [TIME])
    known = set(args)
    unknown = {s for e in exprs for s in e.free_symbols} - known
    if unknown:
        raise SimulationError(f"{spec.name}: extended_rhs cannot bind {sorted(map(str, unknown))}")
    fn = sympy.lambdify(args, exprs, modules="numpy", cse=True)
    consts = ([LD(v) for v in np.asarray(p, dtype=float)]
              + [LD(v) for v in np.asarray(u, dtype=float)]
              + [LD(r.p) / LD(r.q) for r in rationals])
    m = n * (n + 1) // 2

    def f(t, x):
        vals = fn(*x, *consts, LD(t))
        L = [[LD(0)] * n for _ in range(n)]
        k = 0
        for i in range(n):                       # Cholesky of A, row by row
            for j in range(i + 1):
                s = vals[k] - sum((L[i][c] * L[j][c] for c in range(j)), LD(0))
                L[i][j] = np.sqrt(s) if i == j else s / L[j][j]
                k += 1
        y = [LD(0)] * n
        for i in range(n):
            y[i] = (vals[m + i] - sum((L[i][c] * y[c] for c in range(i)), LD(0))) / L[i][i]
        z = [LD(0)] * n
        for i in reversed(range(n)):
            z[i] = (y[i] - sum((L[c][i] * z[c] for c in range(i + 1, n)), LD(0))) / L[i][i]
        return np.array([*x[n:], *z], dtype=LD)
    return f


def _error_scale(x, xn, tol):
    return tol + tol * np.maximum(np.abs(x), np.abs(xn))


def dop853_extended(f, x0, grid, tol: float = 1e-17, max_steps: int = 1_000_000):
    """Dormand-Prince 8(5,3) with Hairer's error estimate, in long double, stepping
    exactly onto every grid point; returns (states (len(grid), nx), nfev).

    The tableau is scipy's (``dop853_coefficients``, given there to 30 digits
    and stored as doubles, i.e. good to ~1e-17).
    """
    D = dop853_coefficients
    LD = np.longdouble
    A, B, C = D.A[:12, :12].astype(LD), D.B.astype(LD), D.C[:12].astype(LD)
    E3, E5 = D.E3.astype(LD), D.E5.astype(LD)
    tol = LD(tol)
    x = np.array(x0, dtype=LD)
    K = np.empty((13, x.size), dtype=LD)
    out, nfev, steps = [x.copy()], 0, 0
    t, h = LD(grid[0]), LD(grid[1] - grid[0]) / 10
    for t_next in grid[1:]:
        t_next = LD(t_next)
        while t < t_next:
            steps += 1
            if steps > max_steps:
                raise SimulationError(f"dop853_extended: more than {max_steps} steps "
                                      f"at t={float(t)}")
            last = t + h >= t_next
            hs = t_next - t if last else h
            K[0] = f(t, x)
            for s in range(1, 12):
                K[s] = f(t + C[s] * hs, x + hs * (A[s, :s] @ K[:s]))
            xn = x + hs * (B @ K[:12])
            K[12] = f(t + hs, xn)
            nfev += 13
            sc = _error_scale(x, xn, tol)
            e5, e3 = (K.T @ E5) / sc, (K.T @ E3) / sc
            e5n, e3n = np.sum(e5 ** 2), np.sum(e3 ** 2)
            den = e5n + LD(0.01) * e3n
            err = abs(hs) * e5n / np.sqrt(den * x.size) if den > 0 else LD(0)
            fac = LD(6) if err == 0 else min(LD(6), max(LD(1) / 3, LD(0.9) * err ** LD(-1 / 8)))
            if err <= 1:
                t, x = (t_next if last else t + hs), xn
                if not last:
                    h = hs * fac
            else:
                h = hs * min(fac, LD(1))
        out.append(x.copy())
    return np.array(out), nfev


def gbs_extended(f, x0, grid, tol: float = 1e-17, k: int = 8, max_steps: int = 200_000):
    """Gragg-Bulirsch-Stoer extrapolation (modified midpoint, n = 2, 4, ..., 2k, order
    2k) in long double, stepping exactly onto every grid point; returns
    (states (len(grid), nx), nfev).  Exact rational coefficients throughout."""
    LD = np.longdouble
    seq = [2 * (j + 1) for j in range(k)]
    tol = LD(tol)
    x = np.array(x0, dtype=LD)
    out, nfev, steps = [x.copy()], 0, 0
    t, H = LD(grid[0]), LD(grid[1] - grid[0])
    expo = LD(-1) / (2 * k - 1)
    for t_next in grid[1:]:
        t_next = LD(t_next)
        while t < t_next:
            steps += 1
            if steps > max_steps:
                raise SimulationError(f"gbs_extended: more than {max_steps} steps at t={float(t)}")
            last = t + H >= t_next
            Hs = t_next - t if last else H
            f0 = f(t, x)
            nfev += 1
            table = []
            for j, nj in enumerate(seq):
                hh = Hs / nj
                z0, z1 = x, x + hh * f0
                for i in range(1, nj):
                    z0, z1 = z1, z0 + 2 * hh * f(t + i * hh, z1)
                row = [(z0 + z1 + hh * f(t + Hs, z1)) / 2]
                nfev += nj
                for col in range(1, j + 1):
                    ratio = LD(nj * nj) / LD(seq[j - col] ** 2)
                    row.append(row[col - 1] + (row[col - 1] - table[j - 1][col - 1]) / (ratio - 1))
                table.append(row)
            xn = table[-1][-1]
            err = np.sqrt(np.mean(((xn - table[-1][-2]) / _error_scale(x, xn, tol)) ** 2))
            fac = LD(4) if err == 0 else min(LD(4), max(LD(0.25), LD(0.8) * err ** expo))
            if err <= 1:
                t, x = (t_next if last else t + Hs), xn
                if not last:
                    H = Hs * fac
            else:
                H = Hs * min(fac, LD(0.5))
        out.append(x.copy())
    return np.array(out), nfev


def extended_reference(spec, problem: Problem, tol: float = 1e-17) -> Reference:
    """Reference from two different high-order methods in long double (DOP853 and
    GBS extrapolation of order 16) on the model's closed-form equations, for
    chaotic problems whose double-precision references disagree too early.
    """
    f = extended_rhs(spec, problem.model.params(problem.p), problem.model.input_vector(problem.u))
    n = problem.n
    check = np.random.default_rng(3).normal(size=(3, 2 * n))
    for x in check:                  # the closed form must be the compiled model
        a = f(0.0, x.astype(np.longdouble)).astype(float)
        b = problem.model.rhs(0.0, x, problem.u, problem.p)
        if np.max(np.abs(a - b)) > 1e-11 * max(np.max(np.abs(b)), 1.0):
            raise SimulationError(f"{spec.name}: the closed-form rhs differs from the "
                                  f"compiled one by {np.max(np.abs(a - b)):.2e}")
    xa, _ = dop853_extended(f, problem.x0, problem.t_eval, tol)
    xb, _ = gbs_extended(f, problem.x0, problem.t_eval, tol)
    qa, qb = xa[:, :n].astype(float), xb[:, :n].astype(float)
    spread = _spreads(qa, qb)
    return Reference(problem.t_eval.copy(), qa,
                     f"DOP853 in long double at rtol = atol = {tol:g}, checked against GBS "
                     f"extrapolation (order 16) in long double, on the closed-form equations",
                     *spread)


