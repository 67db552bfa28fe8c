"""Linearization: the compiled model about an operating point as a state space model.

``cm.linearize(x, u)`` calls the generated ``<name>_linearize`` (symbolic
derivatives, see :mod:`modelgen.derive.linearize`, or for a joint tree the
analytical ``<name>_derivatives``; no finite differences) and
returns a :class:`Linearization`: ``A, B, C, D`` with the operating point and
the names of states, inputs and outputs, its eigenvalues and modes (natural
frequency, damping ratio), and writers for NPZ, MAT and python-control.
``cm.equilibrium(q_guess, u)`` finds a rest point to linearize about (Newton
on q_ddot(q, 0, u) = 0 with the symbolic Jacobian and a line search).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modelgen.errors import (ArgumentTypeError, ArgumentValueError, MassMatrixError,
                             SimulationError)
from modelgen.sim.arguments import positive, whole_number
from modelgen.sim.assemble import (check_initial_state, consistent_speeds, constraint_jacobian,
                                   singular_message)
from modelgen.sim.conditioning import failure_kind
from modelgen.sim.integrate import jacobian_source

#: an eigenvalue below this times the largest |eigenvalue| (or 1) counts as zero, and a
#: real part below it times |lambda| as none
ZERO_EIGENVALUE = 1e-10
#: ... and so does one below this times sqrt(eps ||A||_1): a neutral coordinate (no
#: stiffness: a double zero eigenvalue, a Jordan block) splits by that much in rounding
JORDAN_ZERO = 10.0


@dataclass(frozen=True)
class Mode:
    """One eigenvalue of A: ``frequency`` = ``|lambda|`` (natural frequency, rad/s),
    ``damping`` = ``-Re(lambda) / |lambda|`` (NaN for a zero eigenvalue)."""
    eigenvalue: complex
    frequency: float
    damping: float

    @property
    def stable(self) -> bool | None:
        """True when Re(lambda) < 0, False when > 0, None when zero or purely imaginary
        (``|Re|`` up to ``ZERO_EIGENVALUE |lambda|``: rounding)."""
        if np.isnan(self.damping) or abs(self.damping) <= ZERO_EIGENVALUE:
            return None
        return bool(self.damping > 0)


@dataclass(frozen=True, eq=False)
class Linearization:
    """``d(dx)/dt = A dx + B du``, ``dy = C dx + D du`` about (t, x, u, p).

    Shapes: A (nx, nx), B (nx, nu), C (ny, nx), D (ny, nu); ``states``,
    ``inputs``, ``outputs`` name the rows and columns (outputs: the scene's
    output columns, e.g. ``tip.x``; none for a bare model).  For a constrained model
    the states (and ``x``) are the minimal ones: the independent coordinates and
    speeds (see :func:`linearize`).

    >>> lin = cm.linearize({"q": np.pi})                  # doctest: +SKIP
    >>> lin.eigenvalues()                                 # doctest: +SKIP
    array([-3.13209195+0.j,  3.13209195+0.j])
    >>> print(lin.table())                                # doctest: +SKIP
    """
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    t: float
    x: np.ndarray
    u: np.ndarray
    p: np.ndarray
    states: tuple
    inputs: tuple
    outputs: tuple
    parameters: tuple
    model: str

    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of A, sorted by real then imaginary part."""
        return np.sort_complex(np.linalg.eigvals(self.A).astype(complex))

    def modes(self) -> list:
        """One :class:`Mode` per eigenvalue (same order as :meth:`eigenvalues`); an
        eigenvalue at the level of rounding (see :data:`JORDAN_ZERO`) is zero, its
        damping ratio NaN."""
        lam = self.eigenvalues()
        scale = max(1.0, float(np.max(np.abs(lam)))) if lam.size else 1.0
        norm = float(np.linalg.norm(self.A, 1)) if self.A.size else 0.0
        zero = max(ZERO_EIGENVALUE * scale, JORDAN_ZERO * np.sqrt(np.finfo(float).eps * norm))
        out = []
        for e in lam:
            w = float(abs(e))
            zeta = float("nan") if w <= zero else float(-e.real / w)
            out.append(Mode(complex(e), w, zeta))
        return out

    def table(self) -> str:
        """The eigenvalues with natural frequency [rad/s and Hz] and damping ratio."""
        lines = [f"{'eigenvalue':>34} {'omega_n [rad/s]':>16} {'f [Hz]':>11} "
                 f"{'damping':>10}  note"]
        for m in self.modes():
            e = m.eigenvalue
            text = f"{e.real + 0.0:+.9g} {'+' if e.imag >= 0 else '-'} {abs(e.imag):.9g}j"
            if np.isnan(m.damping):
                zeta, note = "-", "zero (neutral)"
            else:
                zeta = "0" if m.stable is None else f"{m.damping:.6g}"
                note = {None: "undamped", True: "", False: "unstable"}[m.stable]
            lines.append(f"{text:>34} {m.frequency:>16.9g} {m.frequency / (2 * np.pi):>11.6g} "
                         f"{zeta:>10}  {note}".rstrip())
        return "\n".join(lines)

    def _arrays(self) -> dict:
        return {"A": self.A, "B": self.B, "C": self.C, "D": self.D, "t": np.array(self.t),
                "x": self.x, "u": self.u, "p": self.p}

    def _names(self) -> dict:
        return {"states": self.states, "inputs": self.inputs, "outputs": self.outputs,
                "parameters": self.parameters}

    def to_npz(self, path) -> Path:
        """Write A, B, C, D, the operating point (t, x, u, p) and the names (string
        arrays ``states``, ``inputs``, ``outputs``, ``parameters``) to ``path``;
        ``np.load(path)`` reads it back without pickle."""
        path = Path(path)
        names = {k: np.array(v, dtype=str) for k, v in self._names().items()}
        np.savez(path, model=np.array(self.model), **self._arrays(), **names)
        return path

    def to_mat(self, path) -> Path:
        """Write the same as :meth:`to_npz` as a MATLAB file (scipy.io.savemat; the
        names are cell arrays of strings)."""
        from scipy.io import savemat
        path = Path(path)
        names = {k: np.array(list(v), dtype=object).reshape(-1, 1)
                 for k, v in self._names().items()}
        savemat(str(path), {"model": self.model, **self._arrays(), **names})
        return path

    def to_control(self):
        """A ``control.StateSpace`` with the names of states, inputs and outputs (python-control
        allows no ``.`` in a name: ``tip.x`` becomes ``tip_x``); without outputs,
        y = x (C = I, D = 0).  Needs python-control (extra ``control``)."""
        try:
            import control
        except ImportError as exc:
            raise ImportError("Linearization.to_control needs python-control; fix: "
                              "pip install 'modelgen[control]'") from exc
        C, D, outputs = self.C, self.D, self.outputs
        if not outputs:
            C, D, outputs = np.eye(len(self.states)), np.zeros((len(self.states),
                                                                 len(self.inputs))), self.states
        return control.ss(self.A, self.B, C, D, states=list(self.states),
                          inputs=list(self.inputs),
                          outputs=[name.replace(".", "_") for name in outputs], name=self.model)

    def __str__(self):
        with np.printoptions(precision=6, suppress=False, linewidth=120):
            parts = [f"linearization of {self.model} at t = {self.t:g}",
                     "x = " + ", ".join(f"{n}={v:.9g}" for n, v in zip(self.states, self.x))]
            if self.inputs:
                parts.append("u = " + ", ".join(f"{n}={v:.9g}"
                                                for n, v in zip(self.inputs, self.u)))
            # + 0.0 prints a negative zero (a product with a zero entry) as 0
            parts += [f"A ({', '.join(self.states)}):", str(self.A + 0.0)]
            if self.inputs:
                parts += [f"B ({', '.join(self.inputs)}):", str(self.B + 0.0)]
            if self.outputs:
                parts += [f"C ({', '.join(self.outputs)}):", str(self.C + 0.0)]
                if self.inputs:
                    parts += [f"D (rows: the outputs of C; columns: {', '.join(self.inputs)}):",
                              str(self.D + 0.0)]
            parts += ["eigenvalues:", self.table()]
        return "\n".join(parts)


def state_at(cm, x) -> np.ndarray:
    """The state from x[2n], q[n] (speeds zero), or names -> values (missing ones zero)."""
    n = cm.n
    if isinstance(x, dict):
        out = np.zeros(2 * n)
        for name, value in x.items():
            if name not in cm.state_names:
                raise SimulationError(f"{cm.name}: unknown state {name!r}; states are "
                                      f"{', '.join(cm.state_names)}")
            out[cm.state_names.index(name)] = cm._vector([value], 1, f"state {name}")[0]
    elif np.ndim(x) == 1 and np.shape(x)[0] == n:
        out = np.concatenate([cm._vector(x, n, "q"), np.zeros(n)])
    else:
        out = cm._vector(x, 2 * n, "x")
    if not np.all(np.isfinite(out)):
        raise SimulationError(f"{cm.name}: the state must be finite, got {out}")
    return out


def _rows(cm, outputs) -> list:
    """Row indices of the output columns selected by ``outputs`` (names of outputs or
    of columns; None: all)."""
    if outputs is None:
        return list(range(len(cm.output_columns)))
    if isinstance(outputs, str):
        outputs = [outputs]
    what = "outputs must be None, a name or a sequence of names of outputs or output columns"
    if isinstance(outputs, (bytes, dict)) or not np.iterable(outputs):
        raise ArgumentTypeError(f"{cm.name}: {what}, got {outputs!r}")
    rows = []
    for name in outputs:
        if not isinstance(name, str):
            raise ArgumentTypeError(f"{cm.name}: {what}; got {name!r} in outputs")
        if name in cm.outputs:
            rows += [cm.output_columns.index(c) for c in cm.outputs[name]]
        elif name in cm.output_columns:
            rows.append(cm.output_columns.index(name))
        else:
            have = ", ".join(cm.outputs) or "none (outputs come from a scene)"
            raise SimulationError(f"{cm.name}: unknown output {name!r}; outputs are {have}")
    return rows


def linearize(cm, x, u=None, t=0.0, p=None, outputs=None) -> Linearization:
    """The :class:`Linearization` of ``cm`` at (t, x, u, p) from ``<name>_linearize``.

    ``x``: the state x[2n], or q[n] (speeds zero), or a dict of state names;
    ``u``: None (zeros), a vector or a dict; ``outputs``: names of outputs or
    output columns to keep as rows of C and D (default: all of the scene's).
    A constrained model's linearization is the minimal one, in its independent
    coordinates and speeds, about an ``x`` on the position constraints (its
    dependent speeds are recomputed from the independent ones; docs/constraints.md).
    """
    x = state_at(cm, x)
    t = cm._time(t)
    u_vec, p_vec = cm.input_vector(u), cm.params(p)
    got = cm.linearize_call(t, x, u_vec, p_vec)
    if got is None:
        raise SimulationError(
            f"{cm.name}: this build has no {cm.name}_linearize; fix: load it with "
            f"modelgen.load(..., linearize=True) or modelgen.load_scene(..., linearize=True)")
    status, A, B, C, D = got
    info = cm.manifest.get("constraints")
    if info:
        # off the constraints the dependent columns may be singular too: that the
        # point is off them is what to say, not a dead point
        check_initial_state(cm, np.concatenate([x[:cm.nq], np.zeros(cm.n)]), p_vec,
                            what="the operating point", var="x")
    if info and status > cm.n:
        raise SimulationError(singular_message(cm, status, t, x, p_vec))
    if status:
        raise MassMatrixError(status, cm.dof_names[status - 1], t, x,
                              failure_kind(cm.mass_matrix(x[:cm.nq], p_vec), status - 1))
    for label, M, names in (("A", A, cm.state_names), ("B", B, cm.state_names),
                            ("C", C, cm.output_columns), ("D", D, cm.output_columns)):
        bad = [names[i] for i in range(M.shape[0]) if not np.all(np.isfinite(M[i]))]
        if bad:
            raise SimulationError(
                f"{cm.name}: {label} is not finite at x = {list(map(float, x))} in the rows "
                f"of {', '.join(bad)} (the model is not differentiable there, e.g. a spring "
                f"or damper of zero length); fix: linearize at another state")
    rows = _rows(cm, outputs)
    states = cm.state_names
    if info:
        A, B, C, x_min, states = _minimal(cm, info, A, B, C, x, p_vec)
    else:
        x_min = x
    return Linearization(A, B, C[rows], D[rows], t, x_min, u_vec.copy(), p_vec.copy(),
                         states, cm.inputs,
                         tuple(cm.output_columns[i] for i in rows),
                         tuple(cm.parameters), cm.name)


def _minimal(cm, info, A, B, C, x, p) -> tuple:
    """The minimal linearization of a constrained model from the derivatives of its rhs
    in the full state: ``(A, B, C, x, names)`` in the independent coordinates (every
    coordinate but the dependent ones of the position constraints) and the
    independent speeds.

    On the constraints, the dependent coordinates follow the independent ones:
    ``G_h,d dq_d = -G_h,i dq_i`` (G_h: the position rows of G), so a change of the
    independent states maps to one of x by ``P = [[Q, 0], [0, E]]``, ``Q = [I; -G_h,d^-1
    G_h,i]`` (rows in the coordinates' order) and ``E`` the independent speeds'
    columns; the reduced model is ``S A P``, ``S B``, ``C P`` with ``S`` the rows of the
    independent states (sympy's ``KanesMethod.linearize`` does the same with its
    constraint matrices).  ``x`` must be on the constraints (:func:`check_initial_state`).
    """
    n = cm.n
    check_initial_state(cm, np.concatenate([x[:n], consistent_speeds(cm, x[:n], x[n:], p)]), p,
                        what="the operating point", var="x")
    dep_q = list(info["dependent_coordinates"])
    ind_q = [k for k in range(n) if k not in dep_q]
    ind_u = list(info["independent_speeds"])
    Q = np.zeros((n, len(ind_q)))
    Q[ind_q, range(len(ind_q))] = 1.0
    if dep_q:
        Gh = constraint_jacobian(cm, x[:n], p)[:info["holonomic"]]
        if np.linalg.matrix_rank(Gh[:, dep_q]) < len(dep_q):
            names = ", ".join(cm.coordinates[k] for k in dep_q)
            raise SimulationError(
                f"{cm.name}: no minimal linearization at q = {np.array2string(x[:n])}: the "
                f"position constraints' columns of the dependent coordinates ({names}) are "
                "singular there, so those cannot follow a change of the independent ones "
                "(a singular configuration for them); fix: linearize at another "
                "configuration, or choose other dependent coordinates ('dependent:' in "
                "the model)")
        Q[dep_q] = np.linalg.solve(Gh[:, dep_q], -Gh[:, ind_q])
    P = np.zeros((2 * n, len(ind_q) + len(ind_u)))
    P[:n, :len(ind_q)] = Q
    P[[n + k for k in ind_u], range(len(ind_q), len(ind_q) + len(ind_u))] = 1.0
    S = ind_q + [n + k for k in ind_u]
    return (A[S] @ P, B[S], C @ P, x[S], tuple(cm.state_names[k] for k in S))


def equilibrium(cm, q_guess, u=None, p=None, t=0.0, *, tol=1e-10, max_iter=50) -> np.ndarray:
    """A rest point q near ``q_guess``: q_ddot(t, q, 0, u) = 0 to ``tol`` (max norm).

    Newton with the symbolic Jacobian's columns for q of the lower half of A
    (least squares, so neutral directions such as a cart's position stay
    where they are) and a backtracking line search on |q_ddot|^2 (``tol`` > 0,
    ``max_iter`` >= 1 Newton steps).  Raises :class:`SimulationError` with the
    residual when it does not converge.
    """
    n = cm.n
    # checked first: a bad option is the caller's error, not a failure to converge
    tol = positive(tol, f"{cm.name}: tol")
    max_iter = whole_number(max_iter, f"{cm.name}: max_iter")
    if max_iter < 1:
        raise ArgumentValueError(f"{cm.name}: max_iter must be >= 1, got {max_iter!r}")
    if cm.manifest.get("constraints"):
        # Newton on all of q would leave the constraints; a rest point on them needs
        # the reduced equations, which this search does not form
        raise SimulationError(f"{cm.name}: equilibrium does not search a constrained "
                              f"model's rest points; fix: put the configuration on the "
                              f"constraints with cm.assemble(q_guess, keep=[...]) and "
                              f"linearize there")
    if jacobian_source(cm) != "symbolic":
        raise SimulationError(f"{cm.name}: equilibrium needs the symbolic Jacobian; fix: "
                              f"load the model with linearize=True (or jacobian=True)")
    q = cm._vector(q_guess, n, "q_guess").copy()
    if not np.all(np.isfinite(q)):
        raise ArgumentValueError(f"{cm.name}: q_guess must be finite, got {list(map(float, q))}")
    t = cm._time(t)
    u_vec, p_vec = cm.input_vector(u), cm.params(p)
    zero = np.zeros(n)

    def residual(q):
        return cm.rhs(t, np.concatenate([q, zero]), u_vec, p_vec)[n:]

    f = residual(q)
    if not np.all(np.isfinite(f)):
        # LAPACK would be handed NaN (and print its own noise) on the first step
        raise ArgumentValueError(
            f"{cm.name}: q_ddot is not finite at the start q = {list(map(float, q))} (a "
            f"division by zero in the model there, e.g. a spring of zero length); fix: start "
            f"from another q or other parameters")
    for _ in range(max_iter):
        if np.max(np.abs(f)) <= tol:
            return q
        J = cm.jac(t, np.concatenate([q, zero]), u_vec, p_vec)[n:, :n]
        if not np.all(np.isfinite(J)):
            raise SimulationError(
                f"{cm.name}: no equilibrium found from q = {list(map(float, q_guess))}: the "
                f"Jacobian of q_ddot is not finite at q = {list(map(float, q))}; fix: start "
                f"nearer a rest point")
        if not np.any(J):
            raise SimulationError(
                f"{cm.name}: no equilibrium found from q = {list(map(float, q_guess))}: q_ddot "
                f"= {list(map(float, f))} does not depend on q at q = {list(map(float, q))} "
                f"(a zero Jacobian: no rest point nearby for these parameters and inputs)")
        step = np.linalg.lstsq(J, -f, rcond=None)[0]
        norm, alpha = float(f @ f), 1.0
        while alpha > 1e-10:
            try:
                trial = residual(q + alpha * step)
            except MassMatrixError:
                trial = None
            if trial is not None and float(trial @ trial) <= (1 - 1e-4 * alpha) * norm:
                break
            alpha *= 0.5
        else:
            break
        q, f = q + alpha * step, trial
    if np.max(np.abs(f)) <= tol:
        return q
    raise SimulationError(
        f"{cm.name}: no equilibrium found from q = {list(map(float, q_guess))}: Newton stopped "
        f"at q = {list(map(float, q))} with residual |q_ddot| = {float(np.max(np.abs(f))):.3g} "
        f"(tolerance {tol:g}); fix: start nearer a rest point, or check that one exists "
        f"for these inputs")
