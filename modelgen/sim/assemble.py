"""Constrained models from Python: residuals, the constraint Jacobian, assembly
and consistent speeds (SD/FAST's ``sdassemble``), and the check of an initial
state.

Input: a :class:`~modelgen.sim.runtime.CompiledModel` whose manifest has
``constraints`` (see :mod:`modelgen.derive.constraints`).  Output: numpy
arrays, or a :class:`~modelgen.errors.SimulationError` naming the constraint
rows and what to do.

>>> q = assemble(cm, [0.3, 1.0, 2.0], keep=["q1"])          # doctest: +SKIP
>>> residuals(cm, q)                                           # doctest: +SKIP
array([0., 0.])
"""
from __future__ import annotations

import numpy as np

from modelgen.errors import SimulationError

__all__ = [
    "ASSEMBLY_TOL",
    "STATE_TOL",
    "assemble",
    "check_initial_state",
    "consistent_speeds",
    "constraint_jacobian",
    "crossing_message",
    "residuals",
    "singular_message",
]

#: assembly stops when max |f(q)| is at most this (m, or rad for an angle expression)
ASSEMBLY_TOL = 1e-13
#: the largest residual (position or velocity constraint) an initial state may have
STATE_TOL = 1e-9


def _vector(cm, value, size: int, what: str) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.shape != (size,) or not np.all(np.isfinite(a)):
        raise SimulationError(f"{cm.name}: {what} must be {size} finite numbers, got "
                              f"shape {a.shape}")
    return np.ascontiguousarray(a)


def _call(cm, suffix: str, q, p, out) -> np.ndarray:
    ptr = lambda a: cm.ffi.from_buffer("double[]", a)
    getattr(cm.lib, f"{cm.name}_{suffix}")(ptr(q), ptr(cm.params(p)), ptr(out))
    return out


def _info(cm) -> dict:
    info = cm.manifest.get("constraints")
    if not info:
        raise SimulationError(f"{cm.name}: the model has no constraints")
    return info


def _rows(info) -> list:
    return [name + (f" (axis {axis})" if axis else "") for name, axis in info["rows"]]


def residuals(cm, q, p=None) -> np.ndarray:
    """f(q) of the position constraints (``holonomic`` entries; empty if none)."""
    info = _info(cm)
    out = np.empty(info["holonomic"])
    if info["holonomic"]:
        _call(cm, "constraint_residuals", _vector(cm, q, cm.nq, "q"), p, out)
    return out


def constraint_jacobian(cm, q, p=None) -> np.ndarray:
    """G(q), shape (m, n): the constraints are G qd = 0 (position rows first)."""
    info = _info(cm)
    return _call(cm, "constraint_jacobian", _vector(cm, q, cm.nq, "q"), p,
                 np.empty((info["m"], cm.n)))


def assemble(cm, q_guess, keep=(), p=None, tol: float = ASSEMBLY_TOL,
             max_iterations: int = 50) -> np.ndarray:
    """q near ``q_guess`` with f(q) = 0, by Newton (minimum-norm steps) on the
    coordinates not named in ``keep``, which stay as given.  A ball or free
    joint's coordinates are always kept (its quaternion scaled to unit length):
    the constraints are solved for plain coordinates, whose columns of G are
    their speeds'.

    Raises :class:`SimulationError` naming the residuals when it does not
    converge (the kept coordinates may leave no solution: a four-bar's crank
    beyond its range).
    """
    info = _info(cm)
    q = np.array(_vector(cm, q_guess, cm.nq, "q_guess"), dtype=float)
    keep = [keep] if isinstance(keep, str) else list(keep)
    for name in keep:
        if name not in cm.coordinates:
            raise SimulationError(f"{cm.name}: keep names {name!r}, not a coordinate; "
                                  f"coordinates are {', '.join(cm.coordinates)}")
    n_plain = cm.manifest.get("n_simple", cm.nq)
    free = [k for k, c in enumerate(cm.coordinates[:n_plain]) if c not in keep]
    for quat in map(list, cm.quaternions):
        norm = np.linalg.norm(q[quat])
        if not norm > 0:
            names = ", ".join(cm.coordinates[k] for k in quat)
            raise SimulationError(f"{cm.name}: the quaternion ({names}) of q_guess is zero; "
                                  "give a rotation, e.g. (1, 0, 0, 0)")
        q[quat] /= norm
    mh = info["holonomic"]
    if mh == 0:
        return q
    f = residuals(cm, q, p)
    for _ in range(max_iterations):
        if np.max(np.abs(f)) <= tol:
            return q
        J = constraint_jacobian(cm, q, p)[:mh][:, free]
        step, *_ = np.linalg.lstsq(J, -f, rcond=None)
        q[free] += step
        f = residuals(cm, q, p)
    if np.max(np.abs(f)) <= tol:
        return q
    worst = int(np.argmax(np.abs(f)))
    raise SimulationError(
        f"{cm.name}: assembly did not converge in {max_iterations} Newton steps: residual "
        f"{f[worst]:.3g} of constraint {_rows(info)[worst]} at q = {np.array2string(q)}; "
        + (f"kept {', '.join(keep)}: " if keep else "")
        + "start from a guess closer to an assembled configuration, or keep fewer "
          "coordinates")


def consistent_speeds(cm, q, qd, p=None) -> np.ndarray:
    """``qd`` with its dependent speeds computed from the independent ones
    (G(q) qd = 0); raises when the dependent columns of G are singular at q."""
    info = _info(cm)
    qd = np.array(_vector(cm, qd, cm.n, "qd"), dtype=float)
    G = constraint_jacobian(cm, q, p)
    dep, ind = info["dependent_speeds"], info["independent_speeds"]
    Gd = G[:, dep]
    if np.linalg.matrix_rank(Gd) < len(dep):
        raise SimulationError(
            f"{cm.name}: the dependent speeds "
            f"{', '.join(cm.speeds[k] for k in dep)} are not determined at q = "
            f"{np.array2string(np.asarray(q))}: the constraint Jacobian's columns are "
            "singular there (a dead point); move the configuration")
    qd[dep] = np.linalg.solve(Gd, -G[:, ind] @ qd[ind])
    return qd


def check_initial_state(cm, x0, p=None, tol: float = STATE_TOL) -> None:
    """Refuse an initial state off the constraints (position or velocity), naming
    the worst row and the fix."""
    info = _info(cm)
    # the integrators normalise the quaternions first, so the check does too
    x0 = cm.project(x0) if cm.quaternions else np.asarray(x0, dtype=float)
    q, qd = x0[:cm.nq], x0[cm.nq:]
    f = residuals(cm, q, p)
    g = constraint_jacobian(cm, q, p) @ qd
    rows = _rows(info)
    if f.size and np.max(np.abs(f)) > tol:
        k = int(np.argmax(np.abs(f)))
        raise SimulationError(
            f"{cm.name}: the initial state is off the position constraints: residual "
            f"{f[k]:.3g} of {rows[k]}; assemble it first: "
            "x0[:nq] = cm.assemble(q_guess, keep=[...])")
    if g.size and np.max(np.abs(g)) > tol * max(1.0, float(np.max(np.abs(qd)))):
        k = int(np.argmax(np.abs(g)))
        raise SimulationError(
            f"{cm.name}: the initial speeds violate the constraints: G qd = {g[k]:.3g} for "
            f"{rows[k]}; make them consistent: x0[nq:] = cm.consistent_speeds(q, qd)")


def singular_message(cm, status: int, t, x) -> str:
    """The words for rhs status ``n + k`` of a constrained model: column k (1-based) of
    the dependent speeds' part of G is singular at x (a dead point)."""
    info = _info(cm)
    dep = info["dependent_speeds"]
    k = status - cm.n - 1
    speed = cm.speeds[dep[k]] if 0 <= k < len(dep) else "?"
    return (f"{cm.name}: the constraints cannot be solved for the dependent speeds at t = "
            f"{float(t):.6g}: the constraint Jacobian's dependent columns are singular "
            f"(pivot of {speed}) at q = {np.array2string(np.asarray(x)[:cm.nq])}, a dead "
            "point or a lock-up of the mechanism; choose other dependent speeds "
            "('dependent:' in the model) or keep the motion away from it")


def crossing_message(cm, t, t_fail, x) -> str:
    """The words for status DEAD_POINT of a constrained model: det G_d (the constraint
    Jacobian's dependent columns) changed sign in the step from t to t_fail, so the
    motion went through a configuration where they are singular; x is the last
    state before it."""
    info = _info(cm)
    names = ", ".join(cm.speeds[k] for k in info["dependent_speeds"])
    return (f"{cm.name}: the motion went through a dead point between t = {float(t):.6g} and "
            f"t = {float(t_fail):.6g}: the determinant of the constraint Jacobian's "
            f"dependent columns ({names}) changed sign, so they were singular in between "
            "and the dependent coordinates cannot follow the motion through it; last good "
            "state at t = "
            f"{float(t):.6g}: q = {np.array2string(np.asarray(x)[:cm.nq])}; choose other "
            "dependent speeds ('dependent:' in the model) or keep the motion away from it")
