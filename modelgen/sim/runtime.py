"""Runtime stage: the compiled model as numpy-in, numpy-out Python callables.

:class:`CompiledModel` wraps one generated cffi module.  Every method checks
its arguments (length, finiteness of parameters) and returns fresh arrays.
For tight loops, :meth:`CompiledModel.rhs_function` returns a low-overhead
callable with cached pointers and preallocated buffers.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

from modelgen.codegen.emit import ABI_VERSION
from modelgen.errors import DerivationError, MassMatrixError, ModelgenError, SimulationError
from modelgen.sim import integrate
from modelgen.sim.simulate import SimulationResult, rk4


def _import(module_name: str, path: Path):
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, str(path))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules[module_name] = module
    return module


class CompiledModel:
    """A generated, compiled model.

    >>> cm = modelgen.load("models/double_pendulum.yaml")          # doctest: +SKIP
    >>> cm.mass_matrix([0.1, 0.2]).shape                            # doctest: +SKIP
    (2, 2)
    """

    def __init__(self, manifest: dict, module_path: Path):
        self.manifest = manifest
        self.name = manifest["name"]
        self.coordinates = tuple(manifest["coordinates"])
        self.parameters = {name: float(v) for name, v in manifest["parameters"]}
        self.inputs = tuple(manifest["inputs"])
        self.bodies = tuple(manifest["bodies"])
        self.n = len(self.coordinates)
        self.path = Path(module_path)
        module = _import(manifest["module_name"], self.path)
        self.ffi, self.lib = module.ffi, module.lib
        got = getattr(self.lib, f"{self.name}_abi_version")()
        if got != ABI_VERSION:
            raise ModelgenError(f"{self.path}: generated ABI version {got}, this modelgen "
                                f"expects {ABI_VERSION}; regenerate the model")
        fn = lambda suffix: getattr(self.lib, f"{self.name}_{suffix}")   # noqa: E731
        self._mass_matrix = fn("mass_matrix")
        self._velocity_terms = fn("velocity_terms")
        self._generalized_forces = fn("generalized_forces")
        self._rhs = fn("rhs")
        self._energy = fn("energy")
        self._body_poses = fn("body_poses")
        self._simulate_rk4 = fn("simulate_rk4")
        self.outputs = {o["name"]: tuple(o["columns"]) for o in manifest.get("outputs", [])}
        self.output_columns = tuple(c for cols in self.outputs.values() for c in cols)
        self._outputs = fn("outputs") if self.output_columns else None
        self._p_default = np.array(list(self.parameters.values()), dtype=float)
        self._param_index = {name: i for i, name in enumerate(self.parameters)}

    def __repr__(self):
        return (f"<CompiledModel {self.name}: n={self.n}, {len(self.parameters)} parameters, "
                f"{len(self.inputs)} inputs, {len(self.bodies)} bodies>")

    # -- argument handling -------------------------------------------------------
    def _ptr(self, a):
        return self.ffi.from_buffer("double[]", a)

    def _vector(self, value, size, what):
        a = np.ascontiguousarray(value, dtype=float)
        if a.shape != (size,):
            raise SimulationError(f"{self.name}: {what} must have shape ({size},), got {a.shape}")
        return a

    def params(self, p=None) -> np.ndarray:
        """Full parameter vector from None (defaults), a dict of overrides or an array.

        >>> cm.params({"g": 0.0})                                   # doctest: +SKIP
        """
        if p is None:
            return self._p_default
        if isinstance(p, dict):
            out = self._p_default.copy()
            for key, value in p.items():
                if key not in self._param_index:
                    raise SimulationError(
                        f"{self.name}: unknown parameter {key!r}; parameters are "
                        f"{', '.join(self.parameters)}")
                out[self._param_index[key]] = float(value)
        else:
            out = self._vector(p, len(self.parameters), "p")
        if not np.all(np.isfinite(out)):
            bad = [name for name, v in zip(self.parameters, out) if not np.isfinite(v)]
            raise SimulationError(f"{self.name}: parameters must be finite; got {bad}")
        return out

    def input_vector(self, u=None) -> np.ndarray:
        """Input vector from None (zeros), a dict by name, or an array."""
        if u is None:
            return np.zeros(len(self.inputs))
        if isinstance(u, dict):
            out = np.zeros(len(self.inputs))
            for key, value in u.items():
                if key not in self.inputs:
                    raise SimulationError(f"{self.name}: unknown input {key!r}; inputs are "
                                          f"{', '.join(self.inputs) or 'none'}")
                out[self.inputs.index(key)] = float(value)
            return out
        return self._vector(u, len(self.inputs), "u")

    # -- model functions ---------------------------------------------------------
    def mass_matrix(self, q, p=None) -> np.ndarray:
        """A(q, p), shape (n, n)."""
        q = self._vector(q, self.n, "q")
        out = np.empty((self.n, self.n))
        self._mass_matrix(self._ptr(q), self._ptr(self.params(p)), self._ptr(out))
        return out

    def velocity_terms(self, q, qd, p=None) -> np.ndarray:
        """h(q, qd, p) with A qdd = tau - h, shape (n,)."""
        q, qd = self._vector(q, self.n, "q"), self._vector(qd, self.n, "qd")
        out = np.empty(self.n)
        self._velocity_terms(self._ptr(q), self._ptr(qd), self._ptr(self.params(p)),
                             self._ptr(out))
        return out

    def generalized_forces(self, t, q, qd, u=None, p=None) -> np.ndarray:
        """tau(t, q, qd, u, p), shape (n,)."""
        q, qd = self._vector(q, self.n, "q"), self._vector(qd, self.n, "qd")
        out = np.empty(self.n)
        self._generalized_forces(float(t), self._ptr(q), self._ptr(qd),
                                 self._ptr(self.input_vector(u)), self._ptr(self.params(p)),
                                 self._ptr(out))
        return out

    def rhs(self, t, x, u=None, p=None) -> np.ndarray:
        """xdot = [qd, qdd] for x = [q, qd]; usable directly with solve_ivp.

        Raises :class:`MassMatrixError` if A is not positive definite.
        """
        x = self._vector(x, 2 * self.n, "x")
        out = np.empty(2 * self.n)
        status = self._rhs(float(t), self._ptr(x), self._ptr(self.input_vector(u)),
                           self._ptr(self.params(p)), self._ptr(out))
        if status:
            raise MassMatrixError(status, self.coordinates[status - 1], t, x)
        return out

    def rhs_function(self, u=None, p=None):
        """Low-overhead ``f(t, x) -> xdot`` with parameters and inputs bound.

        Pointers are created once and x is copied into a preallocated buffer.
        ``f(t, x)`` returns a fresh array (safe for solve_ivp, which keeps the
        arrays it is given); ``f(t, x, out)`` writes into ``out`` instead.
        The fastest path copies nothing: write the state into ``f.x``, call
        ``f.inplace(t)``, and read ``f.out`` (overwritten by the next call).

        >>> f = cm.rhs_function(p={"g": 1.62})                      # doctest: +SKIP
        >>> scipy.integrate.solve_ivp(f, (0, 1), x0)                # doctest: +SKIP
        >>> f.x[:] = x0; f.inplace(0.0); f.out                      # doctest: +SKIP
        """
        ffi = self.ffi
        nx = 2 * self.n
        p_arr = self.params(p).copy()
        u_arr = self.input_vector(u).copy()
        x_buf = np.zeros(nx)
        out_buf = np.zeros(nx)
        p_ptr, u_ptr = ffi.from_buffer("double[]", p_arr), ffi.from_buffer("double[]", u_arr)
        x_ptr, out_ptr = ffi.from_buffer("double[]", x_buf), ffi.from_buffer("double[]", out_buf)
        rhs = self._rhs
        coordinates = self.coordinates

        def fail(status, t):
            raise MassMatrixError(status, coordinates[status - 1], t, x_buf.copy())

        def f(t, x, out=None):
            x_buf[:] = x
            status = rhs(t, x_ptr, u_ptr, p_ptr, out_ptr)
            if status:
                fail(status, t)
            if out is None:
                return out_buf.copy()
            out[:] = out_buf
            return out

        def inplace(t):
            status = rhs(t, x_ptr, u_ptr, p_ptr, out_ptr)
            if status:
                fail(status, t)

        f.inplace = inplace
        f.x, f.out, f.p, f.u = x_buf, out_buf, p_arr, u_arr   # buffers live with f
        return f

    def energy(self, q, qd, p=None) -> np.ndarray:
        """[kinetic, potential] in J; potential of gravity (zero at O) and of springs."""
        q, qd = self._vector(q, self.n, "q"), self._vector(qd, self.n, "qd")
        out = np.empty(2)
        self._energy(self._ptr(q), self._ptr(qd), self._ptr(self.params(p)), self._ptr(out))
        return out

    def output_values(self, t, x, u=None, p=None) -> np.ndarray:
        """The scene's recorded outputs at one state (flat, ``output_columns`` order)."""
        if self._outputs is None:
            raise SimulationError(f"{self.name}: this model was generated without outputs")
        x = self._vector(x, 2 * self.n, "x")
        out = np.empty(len(self.output_columns))
        self._outputs(float(t), self._ptr(x), self._ptr(self.input_vector(u)),
                      self._ptr(self.params(p)), self._ptr(out))
        return out

    def simulate_rk4(self, x0, t_span, step, *, every: int = 1, u=None, p=None):
        """Fixed-step RK4 integrated in C; returns a :class:`~modelgen.sim.simulate.SimulationResult`.

        ``u`` is None (zeros), a constant vector or dict, a tuple
        ``(times, values, interpolation)`` with ``values`` of shape
        (len(times), n_inputs) and interpolation ``"linear"`` or ``"hold"``, or
        a callable ``u(t, x)`` (feedback; the loop then runs in Python).  The state is recorded
        every ``every`` steps and after the last one.  A failure (mass matrix
        not positive definite, non-finite state) returns what was computed,
        with the time and the reason.

        >>> res = cm.simulate_rk4([1.0, 0, 0, 0], (0, 10), 1e-3, every=10)   # doctest: +SKIP
        """
        t0, t1 = map(float, t_span)
        step = float(step)
        if not (np.isfinite(step) and step > 0):
            raise SimulationError(f"{self.name}: step must be positive, got {step!r}")
        if not t1 > t0:
            raise SimulationError(f"{self.name}: t_span must be increasing, got {t_span!r}")
        every = int(every)
        if every < 1:
            raise SimulationError(f"{self.name}: every must be >= 1, got {every}")
        x0 = self._vector(x0, 2 * self.n, "x0")
        if not np.all(np.isfinite(x0)):
            raise SimulationError(f"{self.name}: x0 must be finite")
        n_steps = int(np.ceil((t1 - t0) / step - 1e-9))
        step = (t1 - t0) / n_steps
        if callable(u):
            return self._simulate_feedback(x0, t0, t1, step, every, u, p)
        times, values, hold = self._input_samples(u)
        rows = n_steps // every + 2
        nx, ny = 2 * self.n, len(self.output_columns)
        t_out, x_out = np.empty(rows), np.empty((rows, nx))
        y_out = np.empty((rows, max(ny, 1)))
        n_out = self.ffi.new("long *")
        t_stop = self.ffi.new("double *")
        status = self._simulate_rk4(
            t0, step, n_steps, every, self._ptr(x0), self._ptr(self.params(p)),
            len(times), self._ptr(times), self._ptr(values), int(hold),
            self._ptr(t_out), self._ptr(x_out), self._ptr(y_out), n_out, t_stop)
        k = n_out[0]
        if status == 0:
            message = "success"
        elif status > 0:
            message = (f"mass matrix not positive definite after t={t_stop[0]!r}: Cholesky "
                       f"pivot {status} (coordinate {self.coordinates[status - 1]!r}) failed")
        else:
            message = f"non-finite state after t={t_stop[0]!r}"
        outputs = {name: y_out[:k, [self.output_columns.index(c) for c in cols]]
                   for name, cols in self.outputs.items()}
        return SimulationResult(t_out[:k].copy(), x_out[:k].copy(), self.coordinates,
                                status=0 if status == 0 else (1 if status > 0 else 2),
                                message=message, outputs=outputs,
                                output_columns=dict(self.outputs))

    def _simulate_feedback(self, x0, t0, t1, step, every, u, p):
        """RK4 with inputs from a Python callable u(t, x): the loop runs in Python."""
        res = rk4(self, x0, (t0, t1), step, u=u, p=p, record_energy=False)
        keep = np.arange(0, len(res.t), every)
        if keep[-1] != len(res.t) - 1:
            keep = np.append(keep, len(res.t) - 1)
        res.t, res.x = res.t[keep], res.x[keep]
        if self.output_columns:
            y = np.array([self.output_values(t, x, u(t, x), p) for t, x in zip(res.t, res.x)])
            res.outputs = {name: y[:, [self.output_columns.index(c) for c in cols]]
                           for name, cols in self.outputs.items()}
            res.output_columns = dict(self.outputs)
        return res

    def _input_samples(self, u):
        """(times, values (n, nu) C-ordered, hold) for the C integrator."""
        nu = len(self.inputs)
        if u is None:
            return np.zeros(0), np.zeros(0), False
        if isinstance(u, tuple) and len(u) == 3 and not isinstance(u[2], (int, float)):
            times = np.ascontiguousarray(u[0], dtype=float)
            values = np.ascontiguousarray(u[1], dtype=float).reshape(len(times), nu)
            if u[2] not in ("linear", "hold"):
                raise SimulationError(f"{self.name}: interpolation must be 'linear' or "
                                      f"'hold', got {u[2]!r}")
            if len(times) > 1 and not np.all(np.diff(times) > 0):
                raise SimulationError(f"{self.name}: input sample times must increase")
            return times, values, u[2] == "hold"
        return np.zeros(1), self.input_vector(u).reshape(1, nu).copy(), False

    # -- integration in C (modelgen/integrate.py) ------------------------------------
    def simulate(self, x0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10,
                 u=None, p=None, events=None, **options):
        """Integrate in C with error control; returns a solve_ivp-shaped result.

        Methods: ``rk4``, ``dopri5``, ``dop853``, ``rodas`` (stiff), ``midpoint``,
        ``gauss4`` (the fixed-step ones need ``step=``); ``events`` are
        ``g(t, x)`` callables with ``terminal``/``direction`` as in solve_ivp.
        Options: ``step``, ``first_step``, ``max_step``, ``max_steps``, ``chunk``.
        See :func:`modelgen.sim.integrate.simulate`.

        >>> res = cm.simulate([1.0, 0.0], (0, 10), t_eval=np.linspace(0, 10, 101))  # doctest: +SKIP
        >>> res.y.shape, res.success                                                # doctest: +SKIP
        ((2, 101), True)
        """
        return integrate.simulate(self, x0, t_span, t_eval, method, rtol, atol, u, p, events, **options)

    def simulate_batch(self, X0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10,
                       u=None, P=None, **options):
        """Integrate many initial states / parameter sets in one C call (``threads=`` to split).

        See :func:`modelgen.sim.integrate.simulate_batch`.

        >>> res = cm.simulate_batch(X0, (0, 5), P={"g": [9.81, 1.62]})           # doctest: +SKIP
        >>> res.y.shape                                                           # doctest: +SKIP
        (2, 4, 1)
        """
        return integrate.simulate_batch(self, X0, t_span, t_eval, method, rtol, atol, u, P, **options)

    def jac(self, t, x, u=None, p=None) -> np.ndarray:
        """d xdot / d x at (t, x), shape (2n, 2n), for ``solve_ivp(..., jac=cm.jac)``.

        The generated symbolic Jacobian when the model has one, else central
        differences of the compiled rhs (see :func:`modelgen.sim.integrate.jacobian_source`).

        >>> scipy.integrate.solve_ivp(cm.rhs, (0, 1), x0, method="Radau", jac=cm.jac)  # doctest: +SKIP
        """
        return integrate.jacobian(self, t, x, u, p)

    def body_poses(self, q, p=None) -> np.ndarray:
        """4x4 pose of every body, shape (n_bodies, 4, 4)."""
        q = self._vector(q, self.n, "q")
        out = np.empty((len(self.bodies), 4, 4))
        self._body_poses(self._ptr(q), self._ptr(self.params(p)), self._ptr(out))
        return out


def check_mass_matrix(cm: CompiledModel, samples: int = 3, seed: int = 0) -> None:
    """Detect a mass matrix that is singular by construction, and name the coordinate.

    A is evaluated at a few random configurations with the default
    parameters; a coordinate whose Cholesky pivot vanishes at all of them
    moves no mass or inertia (e.g. a body with zero inertia about a terminal
    joint axis, or an unused coordinate).
    """
    rng = np.random.default_rng(seed)
    failing = None
    for _ in range(samples):
        A = cm.mass_matrix(rng.uniform(-np.pi, np.pi, cm.n))
        pivot = _cholesky_pivot(A)
        if pivot is None:
            return
        failing = pivot
    name = cm.coordinates[failing]
    raise DerivationError(
        f"{cm.name}: the mass matrix is singular for every configuration tried: coordinate "
        f"{name!r} (row {failing + 1} of A) moves no mass or inertia independently of "
        f"the coordinates before it; give the bodies it moves mass and inertia about its "
        f"axis, or remove the coordinate")


def _cholesky_pivot(A, tol=1e-13):
    """Index of the first failing pivot of a Cholesky factorisation, or None."""
    A = np.array(A, dtype=float)
    n = A.shape[0]
    L = np.zeros_like(A)
    largest = max(np.max(np.diag(A)), 0.0)
    for j in range(n):
        d = A[j, j] - L[j, :j] @ L[j, :j]
        if not (d > tol * A[j, j] and A[j, j] > tol * largest):
            return j
        L[j, j] = np.sqrt(d)
        L[j + 1:, j] = (A[j + 1:, j] - L[j + 1:, :j] @ L[j, :j]) / L[j, j]
    return None
