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

from modelgen.errors import ArgumentTypeError, ArgumentValueError, SimulationError
from modelgen.sim.arguments import positive, whole_number

__all__ = [
    "ASSEMBLY_TOL",
    "STATE_TOL",
    "STEP_TOL",
    "assemble",
    "check_initial_state",
    "check_initial_states",
    "consistent_speeds",
    "constraint_jacobian",
    "crossing_message",
    "residuals",
    "singular_message",
]

#: assembly stops when max |f(q)| is at most this (m, or rad for an angle expression)
ASSEMBLY_TOL = 1e-13
#: ... or after a Newton step that moved no coordinate by more than this times
#: max(1, |q_k|): what is left of f is then the rounding of its terms, which grows
#: with the lengths (a model in millimetres, or far from the origin) while an
#: absolute tolerance does not.  The C projection (``<NAME>_PROJECT_STEP_TOL`` in
#: the model's C) uses the same test, so both accept the same states.
STEP_TOL = 1e-10
#: the largest residual (position or velocity constraint) an initial state may have
STATE_TOL = 1e-9


def _vector(cm, value, size: int, what: str) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.shape != (size,):
        raise SimulationError(f"{cm.name}: {what} must be {size} finite numbers, got "
                              f"shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SimulationError(f"{cm.name}: {what} must be {size} finite numbers, got "
                              f"{np.array2string(a)}")
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


def _kept(cm, keep) -> list:
    """``keep`` as a list of coordinate names: None (none), one name, or names."""
    if keep is None:
        return []
    if isinstance(keep, str):
        keep = [keep]
    elif isinstance(keep, (bytes, dict)) or not np.iterable(keep):
        raise ArgumentTypeError(f"{cm.name}: keep must be None, a coordinate name or a list "
                                f"of them, got {keep!r:.80}; fix: e.g. keep=['{cm.coordinates[0]}']")
    keep = list(keep)
    for name in keep:
        if not isinstance(name, str):
            raise ArgumentTypeError(f"{cm.name}: keep names {name!r}, not a coordinate name; "
                                    f"coordinates are {', '.join(cm.coordinates)}")
        if name not in cm.coordinates:
            raise ArgumentValueError(f"{cm.name}: keep names {name!r}, not a coordinate; "
                                     f"coordinates are {', '.join(cm.coordinates)}")
    return keep


def _small_step(step: np.ndarray, q: np.ndarray) -> bool:
    """The Newton step moved no coordinate by more than :data:`STEP_TOL` of its size
    (at least 1): what remains of the residual is rounding (see the C's
    ``_constrain``, which makes the same test)."""
    return bool(np.all(np.abs(step) <= STEP_TOL * np.maximum(1.0, np.abs(q))))


def assemble(cm, q_guess, keep=(), p=None, tol: float = ASSEMBLY_TOL,
             max_iterations: int = 50) -> np.ndarray:
    """q near ``q_guess`` with f(q) = 0, by Newton (minimum-norm steps) on the
    coordinates not named in ``keep`` (None, a name or names), which stay as
    given.  A ball or free joint's coordinates are always kept (its quaternion
    scaled to unit length): the constraints are solved for plain coordinates,
    whose columns of G are their speeds'.

    Converged when max |f| <= ``tol`` (> 0), or when a step moved no coordinate
    by more than :data:`STEP_TOL` times max(1, |q_k|) and did not make max |f|
    grow more than twofold: f is then at the rounding level of its terms (the
    test the C projection makes, so a model in millimetres or far from the
    origin assembles as one in metres near it does).

    Raises :class:`SimulationError` naming the residuals when it does not
    converge in ``max_iterations`` (>= 1) steps (the kept coordinates may leave
    no solution: a four-bar's crank beyond its range).
    """
    info = _info(cm)
    q = np.array(_vector(cm, q_guess, cm.nq, "q_guess"), dtype=float)
    keep = _kept(cm, keep)
    tol = positive(tol, f"{cm.name}: tol")
    max_iterations = whole_number(max_iterations, f"{cm.name}: max_iterations")
    if max_iterations < 1:
        raise ArgumentValueError(f"{cm.name}: max_iterations must be >= 1, got "
                                 f"{max_iterations!r}")
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
    big, last, small = float(np.max(np.abs(f))), np.inf, False
    for iteration in range(max_iterations + 1):
        if not np.isfinite(big):
            k = int(np.argmax(~np.isfinite(f)))
            raise SimulationError(
                f"{cm.name}: assembly stopped: the residual of constraint {_rows(info)[k]} "
                f"is {f[k]} at q = {np.array2string(q)}, where the constraints are not "
                "defined; fix: start from another guess")
        if big <= tol or (small and big <= 2.0 * last):
            return q
        if iteration == max_iterations or not free:
            break
        J = constraint_jacobian(cm, q, p)[:mh][:, free]
        step = np.linalg.lstsq(J, -f, rcond=None)[0]
        small, last = _small_step(step, q[free]), big
        q[free] += step
        f = residuals(cm, q, p)
        big = float(np.max(np.abs(f)))
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
    if not np.all(np.isfinite(G)):
        raise SimulationError(_undefined(cm, info, G, q, "the constraints are"))
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


def _undefined(cm, info, G, q, subject: str) -> str:
    """The words for a constraint Jacobian with NaN or Inf entries at a finite q;
    ``subject`` says what is not defined ("the constraints are")."""
    rows = _rows(info)
    bad = [rows[i] for i in range(G.shape[0]) if not np.all(np.isfinite(G[i]))]
    return (f"{cm.name}: {subject} not defined at q = "
            f"{np.array2string(np.asarray(q, dtype=float))}: the constraint Jacobian's rows of "
            f"{', '.join(bad)} are not finite there (e.g. a rolling wheel lying flat, its "
            "axle along the ground's normal, has no contact direction); fix: start from "
            "a configuration where they are defined")


def _independent(cm, info) -> list:
    """The coordinates assembly keeps when it solves for the dependent ones."""
    dep = set(info["dependent_coordinates"])
    return [c for k, c in enumerate(cm.coordinates) if k not in dep]


def _wrapped(cm, q, p, k: int) -> float:
    """q[k] moved by whole turns into [-pi, pi] when it is an angle of the constraints
    (their residuals the same a turn away), else q[k]: Newton from a poor guess can
    land several turns off, which is the same configuration."""
    turned = q.copy()
    turned[k] = np.remainder(q[k] + np.pi, 2 * np.pi) - np.pi
    f, g = residuals(cm, q, p), residuals(cm, turned, p)
    return turned[k] if np.allclose(f, g, rtol=0, atol=1e-9) else q[k]


def _assembly_hint(cm, info, q, p, var: str) -> str:
    """How to put q on the position constraints, with the dependent coordinates'
    values that assembly gives for the others as they are (what a scene file or a
    command line, which cannot call assemble, can give instead)."""
    keep = _independent(cm, info)
    call = f"{var}[:nq] = cm.assemble(q_guess, keep={keep!r})"
    dep = [cm.coordinates[k] for k in info["dependent_coordinates"]]
    try:
        qa = assemble(cm, q, keep, p)
    except SimulationError:
        return (f"fix: assemble it first ({call} in Python); no configuration on the "
                f"constraints was found with {', '.join(keep) or 'nothing'} as given and "
                f"{', '.join(dep)} moved, so change those (in a scene file or on the "
                "command line too) towards one that closes the constraints")
    values = ", ".join(f"{cm.coordinates[k]} = {float(_wrapped(cm, qa, p, k))!r}"
                       for k in info["dependent_coordinates"])
    return (f"fix: assemble it first: {call} in Python, or, in a scene file or on the "
            f"command line, give {values} (what assembly gives with {', '.join(keep)} "
            "as given)")


def _speeds_hint(cm, info, q, qd, p, var: str) -> str:
    dep = info["dependent_speeds"]
    try:
        qd = consistent_speeds(cm, q, qd, p)
    except SimulationError as exc:
        return f"the dependent speeds cannot be computed there either ({exc})"
    values = ", ".join(f"{cm.speeds[k]} = {float(qd[k])!r}" for k in dep)
    return (f"make them consistent: {var}[nq:] = cm.consistent_speeds(q, qd) in Python, "
            f"or, in a scene file or on the command line, give {values} (what the "
            "independent speeds give)")


def check_initial_state(cm, x0, p=None, tol: float = STATE_TOL,
                        what: str = "the initial state", var: str = "x0") -> None:
    """Refuse an initial state off the constraints (position or velocity), naming
    the worst row and the fix (with the values that would put it on them), or
    one where they are not defined (NaN or Inf residuals or Jacobian).  ``what``
    names the state in the message (``run 3's initial state``), ``var`` the
    Python variable of the fix (``x0``, ``X0[3]``)."""
    info = _info(cm)
    # the integrators normalise the quaternions first, so the check does too
    x0 = cm.project(x0) if cm.quaternions else np.asarray(x0, dtype=float)
    q, qd = x0[:cm.nq], x0[cm.nq:]
    f = residuals(cm, q, p)
    G = constraint_jacobian(cm, q, p)
    rows = _rows(info)
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(G))):
        bad = [rows[k] for k in range(f.size) if not np.isfinite(f[k])]
        if bad:
            raise SimulationError(
                f"{cm.name}: {what} is where the position constraints are not defined: the "
                f"residual of {', '.join(bad)} is {f[~np.isfinite(f)][0]} at q = "
                f"{np.array2string(q)}; fix: start from a configuration where they are")
        raise SimulationError(_undefined(cm, info, G, q,
                                         f"{what} is where the constraints are"))
    g = G @ qd
    if f.size and not np.max(np.abs(f)) <= tol:
        k = int(np.argmax(np.abs(f)))
        raise SimulationError(
            f"{cm.name}: {what} is off the position constraints: residual "
            f"{f[k]:.3g} of {rows[k]}; " + _assembly_hint(cm, info, q, p, var))
    if g.size and not np.max(np.abs(g)) <= tol * max(1.0, float(np.max(np.abs(qd)))):
        k = int(np.argmax(np.abs(g)))
        raise SimulationError(
            f"{cm.name}: the speeds of {what} violate the constraints: G qd = {g[k]:.3g} for "
            f"{rows[k]}; " + _speeds_hint(cm, info, q, qd, p, var))


def check_initial_states(cm, X0, P_rows) -> None:
    """:func:`check_initial_state` of every row of ``X0`` (a batch's runs) with its
    parameters: row r of ``P_rows``, or ``P_rows`` itself for every run when it is one
    vector.  The integrators' first projection would otherwise move a row onto the
    constraints, its independent coordinates too, and the run would succeed from a
    state nobody gave."""
    P_rows = np.asarray(P_rows, dtype=float)
    for r in range(X0.shape[0]):
        check_initial_state(cm, X0[r], P_rows[r] if P_rows.ndim == 2 else P_rows,
                            what=f"run {r}'s initial state", var=f"X0[{r}]")


def singular_message(cm, status: int, t, x, p=None) -> str:
    """The words for rhs status ``n + k`` of a constrained model: column k (1-based) of
    the dependent speeds' part of G is singular at x (a dead point), or x has NaN or
    Inf, or the constraints are not defined there (``p``: the run's parameters)."""
    info = _info(cm)
    x = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(x)):
        names = [cm.state_names[k] for k in range(min(x.size, cm.nx)) if not np.isfinite(x[k])]
        return (f"{cm.name}: the dependent speeds cannot be computed at t = {float(t):.6g}: "
                f"the state has NaN or Inf in {', '.join(names)} (x = {np.array2string(x)}); "
                "fix: give finite values")
    G = constraint_jacobian(cm, x[:cm.nq], p)
    if not np.all(np.isfinite(G)):
        return _undefined(cm, info, G, x[:cm.nq],
                          f"at t = {float(t):.6g} the constraints are")
    dep = info["dependent_speeds"]
    k = status - cm.n - 1
    speed = cm.speeds[dep[k]] if 0 <= k < len(dep) else "?"
    return (f"{cm.name}: the constraints cannot be solved for the dependent speeds at t = "
            f"{float(t):.6g}: the constraint Jacobian's dependent columns are singular "
            f"(pivot of {speed}) at q = {np.array2string(x[:cm.nq])}, a dead "
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
