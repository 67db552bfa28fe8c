"""Linearization: the compiled model about an operating point as a state space model.

``cm.linearize(x, u)`` calls the generated ``<name>_linearize`` (symbolic
derivatives, see :mod:`modelgen.derive.linearize`, or for a joint tree the
analytical ``<name>_derivatives``; no finite differences) and
returns a :class:`Linearization`: ``A, B, C, D`` with the operating point and
the names of states, inputs and outputs, its eigenvalues and modes (natural
frequency, damping ratio), and writers for NPZ, MAT and python-control.
``cm.equilibrium(q_guess, u)`` finds a rest point to linearize about (Newton
on q_ddot(q, 0, u) = 0 in the tangent space, with the symbolic Jacobian or the
analytical derivatives and a trust region).
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
from modelgen.sim.result import replacing

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
        arrays ``states``, ``inputs``, ``outputs``, ``parameters``) to ``path``, exactly
        that name (``np.savez`` given a name would add ``.npz`` unless it ends in
        lower-case ``.npz``); ``np.load(path)`` reads it back without pickle.  The file
        appears only once complete: a failed write leaves neither it nor a temporary."""
        names = {k: np.array(v, dtype=str) for k, v in self._names().items()}
        return _written(path, lambda fh: np.savez(fh, model=np.array(self.model),
                                                  **self._arrays(), **names))

    def to_mat(self, path) -> Path:
        """Write the same as :meth:`to_npz` as a MATLAB file (scipy.io.savemat; the
        names are cell arrays of strings), exactly at ``path`` (no ``.mat`` added)."""
        from scipy.io import savemat
        names = {k: np.array(list(v), dtype=object).reshape(-1, 1)
                 for k, v in self._names().items()}
        return _written(path, lambda fh: savemat(fh, {"model": self.model, **self._arrays(),
                                                      **names}))

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


def _written(path, write) -> Path:
    """``write(fh)`` into a file opened at exactly ``path`` (under a temporary name
    beside it, renamed when complete); returns ``path``."""
    path = Path(path)
    with replacing(path) as part, open(part, "wb") as fh:
        write(fh)
    return path


def state_at(cm, x) -> np.ndarray:
    """The state from x[nx], q[nq] (speeds zero), or names -> values (the others
    zero, quaternions (1, 0, 0, 0)); finite, each joint's quaternion nonzero and
    normalised (as the integrators and :meth:`CompiledModel.project` do)."""
    if isinstance(x, dict):
        out = cm.neutral_state()
        for name, value in x.items():
            if name not in cm.state_names:
                raise SimulationError(f"{cm.name}: unknown state {name!r}; states are "
                                      f"{', '.join(cm.state_names)}")
            out[cm.state_names.index(name)] = cm._vector([value], 1, f"state {name}")[0]
    elif np.ndim(x) == 1 and np.shape(x)[0] == cm.nq:
        out = np.concatenate([cm._vector(x, cm.nq, "q"), np.zeros(cm.n)])
    else:
        out = cm._vector(x, cm.nx, "x")
    return cm.checked_state(out, "x")


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
    if getattr(cm.lib, f"{cm.name}_linearize", None) is None:
        # before x is read: a model with quaternions cannot be built with it at all
        raise SimulationError(_no_linearize(cm))
    x = state_at(cm, x)
    t = cm._time(t)
    u_vec, p_vec = cm.input_vector(u), cm.params(p)
    status, A, B, C, D = cm.linearize_call(t, x, u_vec, p_vec)
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


def _no_linearize(cm) -> str:
    """Why ``cm`` cannot linearize, with a fix its build accepts."""
    if cm.quaternions:
        return (f"{cm.name}: a model with ball or free joints has no <name>_linearize (a "
                f"build with linearize=True is refused: its state holds unit quaternions, "
                f"whose four components cannot move independently); fix: load it with "
                f"derivatives=True and use cm.derivatives(t, x, u) (d q_ddot / dq in the "
                f"tangent space, d q_ddot / dv, d q_ddot / du), or write the rotations as "
                f"simple angles")
    return (f"{cm.name}: this build has no {cm.name}_linearize; fix: load it with "
            f"modelgen.load(..., linearize=True) or modelgen.load_scene(..., linearize=True)")


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

    A trust-region Newton method (Powell's dogleg, as MINPACK's ``hybrj``) on the
    accelerations, in the tangent space: one unknown per speed, a ball or free
    joint's rotation vector turning its quaternion by the exponential map (the
    guess's quaternions are normalised).  The slope is ``<name>_jacobian``'s (a
    build with ``linearize=True`` or ``jacobian=True``) or ``<name>_derivatives``'
    (``derivatives=True``).  Steps are least squares, so neutral directions such
    as a cart's position stay where they are, and no longer than the trust radius,
    which starts at :data:`FIRST_RADIUS` and grows only while the linear model
    predicts the residual well: the search follows the residual down to the rest
    point near the guess instead of jumping turns away.  A guess that is a rest
    point is returned as it is.  ``tol`` > 0; ``max_iter`` >= 1 Newton steps.
    Raises :class:`SimulationError` with the residual when it does not converge.

    >>> cm.equilibrium([-1.2, 0.4], {"T1": 3.0})                 # doctest: +SKIP
    """
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
    guess = _guess(cm, q_guess)
    t = cm._time(t)
    u_vec, p_vec = cm.input_vector(u), cm.params(p)
    rest = _RestProblem(cm, t, u_vec, p_vec)
    q, f = guess, rest.residual(guess)
    if not np.all(np.isfinite(f)):
        # LAPACK would be handed NaN (and print its own noise) on the first step
        raise ArgumentValueError(
            f"{cm.name}: q_ddot is not finite at the start q = {_listed(q)} (a division by "
            f"zero in the model there, e.g. a spring of zero length); fix: start from "
            f"another q or other parameters")
    radius = FIRST_RADIUS
    for _ in range(max_iter):
        if np.max(np.abs(f)) <= tol:
            return q
        J = rest.slope(q)
        if not np.all(np.isfinite(J)):
            raise SimulationError(
                f"{cm.name}: no equilibrium found from q = {_listed(guess)}: the Jacobian of "
                f"q_ddot is not finite at q = {_listed(q)}; fix: start nearer a rest point")
        moved = _trust_region_step(rest, q, f, J, radius)
        if moved is None:
            raise SimulationError(_stationary(cm, guess, q, f))
        q, f, radius = moved
    if np.max(np.abs(f)) <= tol:
        return q
    raise SimulationError(
        f"{cm.name}: no equilibrium found from q = {_listed(guess)}: Newton stopped after "
        f"{max_iter} steps at q = {_listed(q)} with residual |q_ddot| = "
        f"{float(np.max(np.abs(f))):.3g} (tolerance {tol:g}); fix: start nearer a rest "
        f"point, raise max_iter, or check that one exists for these inputs")


#: the trust radius of :func:`equilibrium`'s first step, in the tangent space (radians,
#: metres); it doubles after a step the linear model predicted well, up to
#: :data:`MAX_RADIUS`, and shrinks after one it did not
FIRST_RADIUS = 0.5
#: the longest step :func:`equilibrium` takes: about a sixth of a turn, so a rest
#: point a turn or more away is reached only by walking down the residual to it
MAX_RADIUS = 1.0
#: a step is taken when the residual's square fell by at least this part of what the
#: linear model predicted (Nocedal and Wright, Numerical Optimization, algorithm 4.1)
ACCEPT = 0.1


def _listed(v) -> list:
    return [float(a) for a in v]


def _guess(cm, q_guess) -> np.ndarray:
    """q_guess as a finite configuration of ``nq`` values, its quaternions normalised."""
    return cm.checked_state(cm._vector(q_guess, cm.nq, "q_guess").copy(), "q_guess")


class _RestProblem:
    """The residual q_ddot(q) at rest and its slope in the tangent space, (n, n): from
    the symbolic Jacobian (its q columns times the kinematic map dq = N(q) dv), or
    from the analytical derivatives, which are in the tangent space already."""

    def __init__(self, cm, t, u, p):
        self.cm, self.t, self.u, self.p = cm, t, u, p
        self.zero = np.zeros(cm.n)
        if getattr(cm.lib, f"{cm.name}_jacobian", None) is not None:
            self.source = "jacobian"
        elif getattr(cm.lib, f"{cm.name}_derivatives", None) is not None:
            self.source = "derivatives"
        else:
            builds = "jacobian=True or derivatives=True" if cm.quaternions else \
                "linearize=True (or jacobian=True or derivatives=True)"
            raise SimulationError(f"{cm.name}: equilibrium needs the symbolic Jacobian or "
                                  f"the analytical derivatives; fix: load the model with "
                                  f"{builds}")

    def residual(self, q) -> np.ndarray:
        x = np.concatenate([q, self.zero])
        return self.cm.rhs(self.t, x, self.u, self.p)[self.cm.nq:]

    def slope(self, q) -> np.ndarray:
        cm, x = self.cm, np.concatenate([q, self.zero])
        if self.source == "derivatives":
            return cm.derivatives(self.t, x, self.u, self.p).dqdd_dq
        J = cm.jac(self.t, x, self.u, self.p)[cm.nq:, :cm.nq]
        return J @ tangent_map(cm, q) if cm.quaternions else J


def _trust_region_step(rest, q, f, J, radius):
    """``(q, f, radius)`` after one accepted dogleg step from q, or None when no step
    inside a vanishing radius lowers |f| (the residual is stationary there)."""
    ff = float(f @ f)
    g = J.T @ f                        # half the gradient of |f|^2
    scale = float(np.linalg.norm(J, 2)) * np.sqrt(ff)
    if not np.linalg.norm(g) > 1e-14 * scale:
        return None
    newton = np.linalg.lstsq(J, -f, rcond=None)[0]
    floor = 1e-12 * (1.0 + float(np.linalg.norm(q)))
    while radius > floor:
        step = _dogleg(J, g, newton, radius)
        length = float(np.linalg.norm(step))
        predicted = ff - float(np.sum((f + J @ step) ** 2))
        try:
            trial = retract(rest.cm, q, step)
            f_trial = rest.residual(trial)
        except MassMatrixError:
            f_trial = None
        if f_trial is not None and np.all(np.isfinite(f_trial)) and predicted > 0:
            ratio = (ff - float(f_trial @ f_trial)) / predicted
            if ratio >= ACCEPT:
                if ratio > 0.75 and length >= 0.99 * radius:
                    radius = min(2.0 * radius, MAX_RADIUS)
                elif ratio < 0.25:
                    radius = 0.25 * length
                return trial, f_trial, radius
        radius = 0.25 * length
    return None


def _dogleg(J, g, newton, radius) -> np.ndarray:
    """The dogleg step inside ``radius``: the Newton step if it fits, else along the
    steepest descent of |f|^2 to its minimum (the Cauchy point) and on towards the
    Newton step until the radius."""
    if np.linalg.norm(newton) <= radius:
        return newton
    Jg = J @ g
    cauchy = -(float(g @ g) / float(Jg @ Jg)) * g
    if np.linalg.norm(cauchy) >= radius:
        return -radius * g / np.linalg.norm(g)
    d = newton - cauchy
    a, b, c = float(d @ d), 2.0 * float(cauchy @ d), float(cauchy @ cauchy) - radius ** 2
    return cauchy + ((-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)) * d


def _stationary(cm, guess, q, f) -> str:
    at = "the guess" if np.array_equal(q, guess) else f"q = {_listed(q)}"
    return (f"{cm.name}: no equilibrium found from q = {_listed(guess)}: at {at} the "
            f"residual q_ddot = {_listed(f)} is not zero but stationary (no step in q "
            f"lowers |q_ddot|: its Jacobian in q is singular there, e.g. zero where "
            f"gravity's torque peaks), so Newton has no direction to go; fix: start from "
            f"another guess, nearer a configuration where the forces balance, or check "
            f"that one exists for these parameters and inputs")


def _quaternion_rows(quat) -> np.ndarray:
    """d quat / d w (4 x 3) of ``dquat/dt = quat * (0, w) / 2``, w in the joint's base."""
    w, x, y, z = quat
    return 0.5 * np.array([[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]])


def _rotation(quat) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z): child axes as columns."""
    w, x, y, z = quat
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _joints(cm):
    """Per ball or free joint: (its position's coordinate indices or None, its
    quaternion's, its linear speeds' or None, its angular speeds'), in the state's
    order (simple coordinates and speeds first, then each joint's: a free joint's
    position and linear velocity before its quaternion and angular velocity)."""
    c = s = cm.manifest.get("n_simple", cm.nq)
    for quat in map(list, cm.quaternions):
        position = linear = None
        if quat[0] - c == 3:
            position, linear, s = list(range(c, c + 3)), list(range(s, s + 3)), s + 3
        yield position, quat, linear, list(range(s, s + 3))
        c, s = quat[3] + 1, s + 3


def tangent_map(cm, q) -> np.ndarray:
    """N(q), (nq, n): dq = N(q) dv, the model's kinematic relation dq/dt = N(q) v (a
    simple coordinate's rate its speed, a quaternion's ``quat * (0, w) / 2``, a free
    joint's position's ``R(quat) v``)."""
    simple = cm.manifest.get("n_simple", cm.nq)
    N = np.zeros((cm.nq, cm.n))
    N[range(simple), range(simple)] = 1.0
    for position, quat, linear, angular in _joints(cm):
        if position is not None:
            N[np.ix_(position, linear)] = _rotation(q[quat])
        N[np.ix_(quat, angular)] = _quaternion_rows(q[quat])
    return N


def retract(cm, q, dv) -> np.ndarray:
    """q moved by dv in the tangent space: simple coordinates and a free joint's
    position (by ``R(quat) dv``) linearly, each quaternion by the exponential map,
    ``quat * exp(dw / 2)`` (unit, as the motion of angular velocity dw for a unit
    time turns it)."""
    simple = cm.manifest.get("n_simple", cm.nq)
    out = np.array(q, dtype=float)
    out[:simple] += dv[:simple]
    for position, quat, linear, angular in _joints(cm):
        if position is not None:
            out[position] += _rotation(q[quat]) @ dv[linear]
        w = np.asarray(dv[angular], dtype=float)
        angle = float(np.linalg.norm(w))
        half = np.concatenate([[np.cos(angle / 2)], np.sinc(angle / (2 * np.pi)) * w / 2])
        out[quat] = _product(q[quat], half)
    return out


def _product(a, b) -> np.ndarray:
    """The quaternion product a * b, (w, x, y, z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])
