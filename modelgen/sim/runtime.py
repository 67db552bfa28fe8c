"""Runtime stage: the compiled model as numpy-in, numpy-out Python callables.

:class:`CompiledModel` wraps one model's compiled library (see
:mod:`modelgen.sim.library`).  Every method checks
its arguments (length, finiteness of parameters) and returns fresh arrays.
For tight loops, :meth:`CompiledModel.rhs_function` returns a low-overhead
callable with cached pointers and preallocated buffers.
"""
from __future__ import annotations

import math
import numbers
import threading
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from modelgen.codegen.build import file_problem
from modelgen.errors import (ArgumentTypeError, ArgumentValueError, BuildError,
                             MassMatrixError, SimulationError)
from modelgen.sim import assemble, integrate
from modelgen.sim.kinematics import FrameKinematics
from modelgen.sim.library import ModelLibrary
from modelgen.sim import linearize as linearization
from modelgen.sim import massmatrix
from modelgen.sim.arguments import FLOAT, real_array
from modelgen.sim.conditioning import failure_kind
from modelgen.sim.result import DenseOutput, Result


class Derivatives(NamedTuple):
    """:meth:`CompiledModel.derivatives`: d qdd / d q (tangent space), d qdd / d v and
    d qdd / d u, shapes (n, n), (n, n), (n, nu)."""
    dqdd_dq: np.ndarray
    dqdd_dv: np.ndarray
    dqdd_du: np.ndarray


class InverseDynamicsDerivatives(NamedTuple):
    """:meth:`CompiledModel.inverse_dynamics_derivatives`: dQ/dq (tangent space),
    dQ/dv and the mass matrix M = dQ/dqdd, each (n, n)."""
    dQ_dq: np.ndarray
    dQ_dv: np.ndarray
    M: np.ndarray


class CompiledModel(FrameKinematics):
    """A generated, compiled model.

    >>> cm = modelgen.load("models/double_pendulum.yaml")          # doctest: +SKIP
    >>> cm.mass_matrix([0.1, 0.2]).shape                            # doctest: +SKIP
    (2, 2)
    """

    def __init__(self, manifest: dict, module_path: Path, runtime: tuple | None = None):
        self.path = Path(module_path)
        # first: it checks the manifest the attributes below are read from
        self.lib = ModelLibrary(manifest, self.path, runtime)
        self.manifest = manifest
        self.name = manifest["name"]
        self.coordinates = tuple(manifest["coordinates"])
        self.parameters = {name: float(v) for name, v in manifest["parameters"]}
        self.inputs = tuple(manifest["inputs"])
        self.bodies = tuple(manifest["bodies"])
        #: the speeds: ``q_dot`` of each simple coordinate, then the speeds of the
        #: ball and free joints (angular velocities in the joint's base, and a
        #: free joint's linear velocity first)
        self.speeds = tuple(manifest.get("speeds") or (f"{c}_dot" for c in self.coordinates))
        #: number of speeds (degrees of freedom, the size of A); ``nq`` coordinates
        self.n = len(self.speeds)
        self.nq = len(self.coordinates)
        self.nx = self.nq + self.n
        #: state indices (w, x, y, z) of each joint's unit quaternion
        self.quaternions = tuple(tuple(qi) for qi in manifest.get("quaternions", ()))
        #: names of the state x = [q, qd]: the coordinates, then the speeds
        self.state_names = self.coordinates + self.speeds
        #: the model's ``units:`` (a state's, parameter's or input's name -> unit; a
        #: simple coordinate's speed per second): for people and exports, never used
        self.units = dict(manifest.get("units") or {})
        #: one name per degree of freedom (the rows of A): a simple coordinate's
        #: own name, a joint's speed name
        self.dof_names = massmatrix.dof_names(manifest)
        self.ffi = self.lib.ffi
        fn = lambda suffix: getattr(self.lib, f"{self.name}_{suffix}")   # noqa: E731
        self._mass_matrix = fn("mass_matrix")
        self._velocity_terms = fn("velocity_terms")
        self._generalized_forces = fn("generalized_forces")
        self._rhs = fn("rhs")
        self._inverse_dynamics = fn("inverse_dynamics")
        self._energy = fn("energy")
        self._body_poses = fn("body_poses")
        self.outputs = {o["name"]: tuple(o["columns"]) for o in manifest.get("outputs", [])}
        self.output_columns = tuple(c for cols in self.outputs.values() for c in cols)
        self._outputs = fn("outputs") if self.output_columns else None
        self._p_default = np.array(list(self.parameters.values()), dtype=float)
        self._p_default.flags.writeable = False     # shared by every call; params() copies
        self._param_index = {name: i for i, name in enumerate(self.parameters)}

    def __reduce__(self):
        """Pickle as (manifest, library path, runtime module): the unpickled model loads
        the same compiled library, so it crosses process boundaries (multiprocessing,
        concurrent.futures, joblib, Dask) on machines that share the build; naming the
        runtime module spares a spawned worker the code generator's imports (sympy)."""
        runtime = (self.lib.runtime[0], str(self.lib.runtime[1]))
        return (unpickled, (self.manifest, str(self.path), runtime))

    def __repr__(self):
        sizes = f"n={self.n}" if self.nq == self.n else f"nq={self.nq}, nv={self.n}"
        return (f"<CompiledModel {self.name}: {sizes}, {len(self.parameters)} parameters, "
                f"{len(self.inputs)} inputs, {len(self.bodies)} bodies>")

    # -- argument handling -------------------------------------------------------
    def _ptr(self, a):
        return self.ffi.from_buffer("double[]", a)

    def _real(self, value, what):
        """``value`` as a new float array of its own shape (:func:`~modelgen.sim.arguments.real_array`)."""
        return real_array(value, self.name, what)

    def _vector(self, value, size, what):
        """``value`` as a contiguous float vector of ``size``; never broadcast, never
        silently drop an imaginary part."""
        a = self._real(value, what)
        if a.shape != (size,):
            raise SimulationError(f"{self.name}: {what} must have shape ({size},), got {a.shape}")
        return np.ascontiguousarray(a)

    def _time(self, t) -> float:
        try:
            # a string is not a time, though float() would read "0" as one
            if np.iscomplexobj(t) or np.ndim(t) != 0 or np.asarray(t).dtype.kind in "SU":
                raise TypeError(t)
            t = float(t)
        except (TypeError, ValueError, OverflowError):
            raise ArgumentTypeError(f"{self.name}: t must be a real number, got {t!r}") from None
        if not np.isfinite(t):
            raise ArgumentValueError(f"{self.name}: t must be finite, got {t!r}")
        return t

    def checked_state(self, x, what: str = "x", normalise: bool = True) -> np.ndarray:
        """The state (or configuration) ``x``, a float vector of ``nx`` (or ``nq``)
        values, refused when not finite or when a joint's quaternion is zero, and
        returned with each quaternion normalised (:meth:`project`) unless not
        ``normalise``: what the derivatives and the linearization are taken at (a
        quaternion off unit norm is no rotation; the integrators normalise it after
        every step)."""
        if not np.all(np.isfinite(x)):
            bad = [name for name, v in zip(self.state_names, x) if not np.isfinite(v)]
            raise ArgumentValueError(f"{self.name}: {what} must be finite; got NaN or Inf in "
                                     f"{bad}")
        if not self.quaternions:
            return x
        integrate.check_quaternions(self, x[None, :], what)
        return self.project(x) if normalise else x

    def params(self, p=None) -> np.ndarray:
        """Full parameter vector from None (defaults), a dict of overrides or an array.

        >>> cm.params({"g": 0.0})                                   # doctest: +SKIP
        """
        if p is None:
            return self._p_default.copy()
        if isinstance(p, dict):
            out = self._p_default.copy()
            for key, value in p.items():
                if key not in self._param_index:
                    raise ArgumentValueError(
                        f"{self.name}: unknown parameter {key!r}; parameters are "
                        f"{', '.join(self.parameters)}")
                out[self._param_index[key]] = self._vector([value], 1, f"parameter {key}")[0]
        else:
            out = self._vector(p, len(self.parameters), "p")
        if not np.all(np.isfinite(out)):
            bad = [name for name, v in zip(self.parameters, out) if not np.isfinite(v)]
            raise ArgumentValueError(f"{self.name}: parameters must be finite; got {bad}")
        return out

    def input_vector(self, u=None) -> np.ndarray:
        """Input vector from None (zeros), a dict by name, or an array; a model with
        one input also takes a plain number.

        >>> cm.input_vector(0.5)          # a one-input model, e.g. the cart-pole  # doctest: +SKIP
        array([0.5])
        """
        if u is None:
            return np.zeros(len(self.inputs))
        if len(self.inputs) == 1 and (isinstance(u, numbers.Number)
                                      or (isinstance(u, np.ndarray) and u.ndim == 0)):
            u = [u]
        if isinstance(u, dict):
            out = np.zeros(len(self.inputs))
            for key, value in u.items():
                if key not in self.inputs:
                    raise ArgumentValueError(f"{self.name}: unknown input {key!r}; inputs are "
                                          f"{', '.join(self.inputs) or 'none'}")
                out[self.inputs.index(key)] = self._vector([value], 1, f"input {key}")[0]
        else:
            out = self._vector(u, len(self.inputs), "u")
        if not np.all(np.isfinite(out)):
            bad = [name for name, v in zip(self.inputs, out) if not np.isfinite(v)]
            raise ArgumentValueError(f"{self.name}: inputs must be finite; got {bad}")
        return out

    def state_vector(self, x, what: str = "x0", base=None) -> np.ndarray:
        """The state from an array of ``nx`` values, or from a dict of coordinate and
        speed names -> values over ``base`` (default :meth:`neutral_state`: every
        coordinate and speed zero, every quaternion (1, 0, 0, 0)), as a scene's
        ``x0`` takes its missing entries from the scene's initial state.

        >>> cm.state_vector({"q1": 0.5})                              # doctest: +SKIP
        array([0.5, 0. , 0. , 0. ])
        """
        if not isinstance(x, dict):
            return self._vector(x, self.nx, what)
        out = self.neutral_state() if base is None else self._vector(base, self.nx, "base")
        for name, value in x.items():
            if name not in self.state_names:
                raise SimulationError(f"{self.name}: {what} names unknown state {name!r}; "
                                      f"states are {', '.join(self.state_names)}")
            out[self.state_names.index(name)] = self._vector([value], 1, f"{what}[{name!r}]")[0]
        return out

    # -- model functions ---------------------------------------------------------
    def neutral_state(self) -> np.ndarray:
        """The state with every coordinate and speed zero and every quaternion (1, 0, 0, 0)."""
        x = np.zeros(self.nx)
        for quat in self.quaternions:
            x[quat[0]] = 1.0
        return x

    def project(self, x) -> np.ndarray:
        """A copy of the state (or configuration) ``x`` with each quaternion normalised
        (what the integrators do after every step)."""
        x = self._real(x, "x")
        if x.shape not in ((self.nx,), (self.nq,)):
            raise ArgumentValueError(f"{self.name}: x must be a state, shape ({self.nx},), or a "
                                     f"configuration, shape ({self.nq},); got shape {x.shape}")
        if self.quaternions:       # the C's own, bit for bit (and safe from overflow)
            x = np.ascontiguousarray(x)
            getattr(self.lib, f"{self.name}_project")(self._ptr(x))
        return x

    # -- constraints (modelgen.sim.assemble) ------------------------------------
    def constraint_residuals(self, q, p=None) -> np.ndarray:
        """f(q) of the position constraints (see :func:`modelgen.sim.assemble.residuals`)."""
        return assemble.residuals(self, q, p)

    def constraint_jacobian(self, q, p=None) -> np.ndarray:
        """G(q), shape (m, n), with G qd = 0 (:func:`modelgen.sim.assemble.constraint_jacobian`)."""
        return assemble.constraint_jacobian(self, q, p)

    def assemble(self, q_guess, keep=(), p=None, **options) -> np.ndarray:
        """q on the position constraints near ``q_guess``, holding the coordinates
        named in ``keep`` (:func:`modelgen.sim.assemble.assemble`).

        >>> q = cm.assemble([0.5, 1.0, 2.0], keep=["q1"])          # doctest: +SKIP
        """
        return assemble.assemble(self, q_guess, keep, p, **options)

    def consistent_speeds(self, q, qd, p=None) -> np.ndarray:
        """``qd`` with the dependent speeds solved from the independent ones."""
        return assemble.consistent_speeds(self, q, qd, p)

    def mass_matrix(self, q, p=None) -> np.ndarray:
        """A(q, p), shape (n, n); q has ``nq`` entries."""
        q = self._vector(q, self.nq, "q")
        out = np.empty((self.n, self.n))
        self._mass_matrix(self._ptr(q), self._ptr(self.params(p)), self._ptr(out))
        return out

    def velocity_terms(self, q, qd, p=None) -> np.ndarray:
        """h(q, qd, p) with A qdd = tau - h, shape (n,)."""
        q, qd = self._vector(q, self.nq, "q"), self._vector(qd, self.n, "qd")
        out = np.empty(self.n)
        self._velocity_terms(self._ptr(q), self._ptr(qd), self._ptr(self.params(p)),
                             self._ptr(out))
        return out

    def generalized_forces(self, t, q, qd, u=None, p=None) -> np.ndarray:
        """tau(t, q, qd, u, p), shape (n,)."""
        q, qd = self._vector(q, self.nq, "q"), self._vector(qd, self.n, "qd")
        out = np.empty(self.n)
        self._generalized_forces(self._time(t), self._ptr(q), self._ptr(qd),
                                 self._ptr(self.input_vector(u)), self._ptr(self.params(p)),
                                 self._ptr(out))
        return out

    def inverse_dynamics(self, t, x, qdd, u=None, p=None) -> np.ndarray:
        """The generalized forces Q = A qdd + h - tau, shape (n,), that must act besides
        the model's own (gravity, effects, actions and the inputs ``u``) for the
        accelerations ``qdd`` at state ``x`` = [q, qd]: zero at the qdd of :meth:`rhs`.
        O(n) by recursive Newton-Euler for a joint tree (Pinocchio's ``rnea``,
        MuJoCo's ``mj_inverse``, with the model's forces taken off).

        >>> Q = cm.inverse_dynamics(0.0, x, qdd)                          # doctest: +SKIP
        """
        x, qdd = self._vector(x, self.nx, "x"), self._vector(qdd, self.n, "qdd")
        out = np.empty(self.n)
        self._inverse_dynamics(self._time(t), self._ptr(x), self._ptr(qdd),
                               self._ptr(self.input_vector(u)), self._ptr(self.params(p)),
                               self._ptr(out))
        return out

    def _derivatives_function(self, suffix: str):
        fn = getattr(self.lib, f"{self.name}_{suffix}", None)
        if fn is None and self.manifest.get("constraints"):
            # derivatives=True is refused for this model: name what works instead
            raise BuildError(f"{self.name}: a constrained model has no analytical "
                             f"derivatives (a build with derivatives=True is refused: they "
                             f"would leave out the constraint forces); fix: load it with "
                             f"jacobian=True and use cm.jac(t, x, u), or with "
                             f"linearize=True and use cm.linearize(x, u) (the derivatives "
                             f"of the constrained rhs)")
        if fn is None:
            raise BuildError(f"{self.name}: built without the analytical derivatives; load "
                             f"it with derivatives=True")
        return fn

    def derivatives(self, t, x, u=None, p=None) -> Derivatives:
        """d qdd / d q, d qdd / d v, d qdd / d u of the rhs's accelerations at (t, x, u, p),
        analytical (``<name>_derivatives``: -M^-1 times the derivatives of inverse
        dynamics, Carpentier and Mansard 2018); d/dq of a ball or free joint in the
        tangent space (along the speeds), as Pinocchio's ``computeABADerivatives``.
        Load the model with ``derivatives=True``.  ``x`` must be finite; its
        quaternions are normalised first (a zero one is refused), as the integrators
        do: the derivatives are those at the rotation it stands for.

        >>> d = modelgen.load(path, derivatives=True).derivatives(0.0, x)  # doctest: +SKIP
        >>> d.dqdd_dq.shape                                                 # doctest: +SKIP
        """
        fn = self._derivatives_function("derivatives")
        x = self.checked_state(self._vector(x, self.nx, "x"))
        n, nu = self.n, len(self.inputs)
        out = Derivatives(np.empty((n, n)), np.empty((n, n)), np.empty((n, nu)))
        status = fn(self._time(t), self._ptr(x), self._ptr(self.input_vector(u)),
                    self._ptr(self.params(p)), self._ptr(out.dqdd_dq), self._ptr(out.dqdd_dv),
                    self._ptr(out.dqdd_du) if nu else self.ffi.NULL)
        if status:
            raise self._mass_matrix_error(status, t, x, p)
        return out

    def inverse_dynamics_derivatives(self, t, x, qdd, u=None, p=None) -> InverseDynamicsDerivatives:
        """dQ/dq, dQ/dv and M = dQ/dqdd of :meth:`inverse_dynamics` at (t, x, qdd, u, p)
        (``<name>_inverse_dynamics_derivatives``; Pinocchio's ``computeRNEADerivatives``
        with the model's own forces taken off).  Load the model with ``derivatives=True``.
        ``x`` is checked and its quaternions normalised as by :meth:`derivatives`.

        >>> d = cm.inverse_dynamics_derivatives(0.0, x, qdd)             # doctest: +SKIP
        """
        fn = self._derivatives_function("inverse_dynamics_derivatives")
        x = self.checked_state(self._vector(x, self.nx, "x"))
        qdd = self._vector(qdd, self.n, "qdd")
        n = self.n
        out = InverseDynamicsDerivatives(np.empty((n, n)), np.empty((n, n)), np.empty((n, n)))
        fn(self._time(t), self._ptr(x), self._ptr(qdd), self._ptr(self.input_vector(u)),
           self._ptr(self.params(p)), self._ptr(out.dQ_dq), self._ptr(out.dQ_dv),
           self._ptr(out.M))
        return out

    def rhs(self, t, x, u=None, p=None) -> np.ndarray:
        """xdot = [qd, qdd] for x = [q, qd]; usable directly with solve_ivp.

        Raises :class:`MassMatrixError` if A is not positive definite.
        """
        x = self._vector(x, self.nx, "x")
        out = np.empty(self.nx)
        status = self._rhs(self._time(t), self._ptr(x), self._ptr(self.input_vector(u)),
                           self._ptr(self.params(p)), self._ptr(out))
        if status:
            raise self._mass_matrix_error(status, t, x, p)
        return out

    def _mass_matrix_error(self, pivot: int, t, x, p=None) -> MassMatrixError:
        """The error of a failing pivot at x, worded by the kind of failure (a NaN in q
        is no property of A: it is named, as jac names it)."""
        if pivot > self.n and self.manifest.get("constraints"):
            return SimulationError(assemble.singular_message(self, pivot, t, x, p))
        if not np.all(np.isfinite(x)):
            bad = [name for name, v in zip(self.state_names, x) if not np.isfinite(v)]
            return ArgumentValueError(f"{self.name}: x must be finite; got NaN or Inf in {bad}")
        kind = failure_kind(self.mass_matrix(x[:self.nq], p), pivot - 1)
        return MassMatrixError(pivot, self.dof_names[pivot - 1], t, x, kind)

    def rhs_function(self, u=None, p=None):
        """Low-overhead ``f(t, x) -> xdot`` with parameters and inputs bound.

        Pointers are created once and x is copied into a preallocated buffer.
        ``f(t, x)`` returns a fresh array (safe for solve_ivp, which keeps the
        arrays it is given); ``f(t, x, out)`` writes into ``out`` instead.
        ``out`` must be a writable float64 numpy array of shape (nx,) (a strided
        view is fine: it is written element by element); anything else raises
        :class:`~modelgen.errors.ArgumentTypeError` or
        :class:`~modelgen.errors.ArgumentValueError` instead of rounding into it.
        The fastest path copies nothing: write the state into ``f.x``, call
        ``f.inplace(t)``, and read ``f.out`` (overwritten by the next call).
        ``f(t, x)`` may be shared between threads (its calls take turns on its
        buffers); for threads that run in parallel, give each its own ``f``.
        ``f.x``, ``f.inplace`` and ``f.out`` are one thread's, not to be mixed with
        calls of ``f`` from others.

        >>> f = cm.rhs_function(p={"g": 1.62})                      # doctest: +SKIP
        >>> scipy.integrate.solve_ivp(f, (0, 1), x0)                # doctest: +SKIP
        >>> f.x[:] = x0; f.inplace(0.0); f.out                      # doctest: +SKIP
        """
        ffi = self.ffi
        nx = self.nx
        p_arr = self.params(p).copy()
        u_arr = self.input_vector(u).copy()
        x_buf = np.zeros(nx)
        out_buf = np.zeros(nx)
        p_ptr, u_ptr = ffi.from_buffer("double[]", p_arr), ffi.from_buffer("double[]", u_arr)
        x_ptr, out_ptr = ffi.from_buffer("double[]", x_buf), ffi.from_buffer("double[]", out_buf)
        call, pointer = self.lib.unbound(f"{self.name}_rhs")
        # the C call releases the GIL: without the lock, another thread's x could
        # replace this one's in x_buf mid-call, or its result this one's in out_buf
        lock = threading.Lock()
        isfinite = math.isfinite

        def rhs(*args):          # only off the fast path (errors)
            return call(pointer, *args)

        def fail(status, t):
            raise self._mass_matrix_error(status, t, x_buf.copy(), p_arr)

        def f(t, x, out=None):
            with lock:
                try:
                    # a float64 vector as solve_ivp passes it; anything else (text,
                    # complex, a NaN time...) the checks below refuse or convert
                    if (type(x) is not np.ndarray or x.dtype is not FLOAT
                            or x.shape != (nx,) or not isfinite(t)):
                        raise ValueError(x)
                    x_buf[:] = x
                    status = call(pointer, t, x_ptr, u_ptr, p_ptr, out_ptr)
                except (TypeError, ValueError, OverflowError):   # off the fast path
                    x_buf[:] = self._vector(x, nx, "x")
                    status = rhs(self._time(t), x_ptr, u_ptr, p_ptr, out_ptr)
                if status:
                    fail(status, t)
                if out is None:
                    return out_buf.copy()
                if (type(out) is not np.ndarray or out.dtype != np.float64
                        or out.shape != (nx,) or not out.flags.writeable):
                    self._check_out(out, nx)
                out[:] = out_buf
                return out

        def inplace(t):
            # no lock: the caller's f.x and f.out around the call are one thread's anyway
            try:
                if not isfinite(t):
                    raise ValueError(t)
                status = call(pointer, t, x_ptr, u_ptr, p_ptr, out_ptr)
            except (TypeError, ValueError, OverflowError):
                status = rhs(self._time(t), x_ptr, u_ptr, p_ptr, out_ptr)
            if status:
                fail(status, t)

        f.inplace = inplace
        f.x, f.out, f.p, f.u = x_buf, out_buf, p_arr, u_arr   # buffers live with f
        return f

    def _check_out(self, out, size: int) -> None:
        """Refuse an ``out=`` array that cannot take ``size`` doubles exactly (numpy
        would round floats into an integer array, or broadcast a wrong shape)."""
        if not isinstance(out, np.ndarray):
            raise ArgumentTypeError(f"{self.name}: out must be a numpy float64 array of shape "
                                    f"({size},), got {type(out).__name__}")
        if out.dtype != np.float64:
            raise ArgumentTypeError(f"{self.name}: out must have dtype float64, got {out.dtype} "
                                    f"(values would be converted); use np.empty({size})")
        if out.shape != (size,):
            raise ArgumentValueError(f"{self.name}: out must have shape ({size},), got "
                                     f"{out.shape}")
        if not out.flags.writeable:
            raise ArgumentValueError(f"{self.name}: out is read-only")

    def energy(self, q, qd, p=None) -> np.ndarray:
        """[kinetic, potential] in J; potential of gravity (zero at O) and of springs."""
        q, qd = self._vector(q, self.nq, "q"), self._vector(qd, self.n, "qd")
        out = np.empty(2)
        self._energy(self._ptr(q), self._ptr(qd), self._ptr(self.params(p)), self._ptr(out))
        return out

    def output_values(self, t, x, u=None, p=None) -> np.ndarray:
        """The scene's recorded outputs at one state (flat, ``output_columns`` order)."""
        if self._outputs is None:
            raise SimulationError(f"{self.name}: this model was generated without outputs")
        x = self._vector(x, self.nx, "x")
        out = np.empty(len(self.output_columns))
        self._outputs(self._time(t), self._ptr(x), self._ptr(self.input_vector(u)),
                      self._ptr(self.params(p)), self._ptr(out))
        return out

    def _input_samples(self, u):
        """(times, values (n, nu) C-ordered, hold) for the C integrator: every input
        form but a callable, checked here for every method."""
        nu = len(self.inputs)
        if u is None:
            return np.zeros(0), np.zeros(0), False
        if isinstance(u, tuple) and len(u) == 3 and not isinstance(u[2], (int, float)):
            if not (isinstance(u[2], str) and u[2] in ("linear", "hold")):
                raise SimulationError(f"{self.name}: interpolation must be 'linear' or "
                                      f"'hold', got {u[2]!r}")
            times = self._real(u[0], "u's sample times")
            if times.ndim != 1 or times.size == 0:
                raise ArgumentValueError(
                    f"{self.name}: u's sample times must be a non-empty 1-D array, got shape "
                    f"{times.shape}; fix: u=(times, values, {u[2]!r}) with one row of values "
                    "per time (a constant input is a plain value)")
            if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
                raise ArgumentValueError(f"{self.name}: u's sample times must be finite and "
                                         "increase")
            values = self._real(u[1], "u's sample values")
            if nu == 1 and values.shape == times.shape:
                values = values[:, None]
            if values.shape != (len(times), nu):
                raise ArgumentValueError(
                    f"{self.name}: u's sample values must have shape ({len(times)}, {nu}) (one "
                    f"row per sample time, one column per input: {', '.join(self.inputs)}), "
                    f"got {values.shape}")
            # NaN is refused as a constant NaN is; an infinite sample is a blow-up the
            # run reports with the trajectory before it (a non-finite state)
            if np.any(np.isnan(values)):
                bad = [name for j, name in enumerate(self.inputs)
                       if np.any(np.isnan(values[:, j]))]
                raise ArgumentValueError(f"{self.name}: u's sample values must not be NaN; "
                                         f"got NaN in {bad}")
            return np.ascontiguousarray(times), np.ascontiguousarray(values), u[2] == "hold"
        return np.zeros(1), self.input_vector(u).reshape(1, nu).copy(), False

    # -- integration (modelgen/sim/integrate.py) -------------------------------------
    def simulate(self, x0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10,
                 u=None, p=None, events=None, *, step=None, first_step=None, max_step=None,
                 max_steps=None, dense_output=False, outputs=True, **options) -> Result:
        """Integrate from ``x0`` over ``t_span`` in C; returns a :class:`~modelgen.sim.result.Result`.

        The one way to integrate a model.  ``method``: ``rk4``, ``dopri5``,
        ``dop853`` (default), ``rodas`` (stiff, uses the Jacobian), ``midpoint``,
        ``gauss4`` (see :data:`modelgen.sim.integrate.METHODS`); the fixed-step
        ones need ``step``, which also runs the adaptive ones with fixed steps.
        solve_ivp's names are accepted and mapped to these, modelgen's own
        methods: ``"RK45"`` -> dopri5, ``"DOP853"`` -> dop853, ``"Radau"``,
        ``"BDF"``, ``"LSODA"`` -> rodas.  A decreasing ``t_span`` integrates
        backwards in time (the C integrators run on the system in s = -t; ``t_eval``
        then decreases too), as ``solve_ivp`` does.
        ``t_eval`` samples through each method's dense output (otherwise every
        step is recorded); ``events`` are ``g(t, x)`` callables with
        ``terminal``/``direction`` attributes, as in ``solve_ivp``.  ``x0`` is an
        array or a dict of state names (the others zero, quaternions (1, 0, 0, 0)).
        ``u`` is None (zeros), a vector or dict of constant inputs (a number for a
        one-input model), a tuple ``(times, values, "linear" | "hold")`` of
        samples, or a callable ``u(t, x)`` (feedback) returning a constant form;
        an exception it or an event function raises is re-raised with the run up
        to it as ``exc.partial_result``.
        ``p`` overrides parameters.  ``max_steps`` defaults to 100,000, or for a
        fixed ``step`` to the steps the span needs if that is more (a run that
        hits it stops with status -1, warns and says how to raise it).  ``dense_output=True``
        sets ``res.sol`` (:class:`~modelgen.sim.result.DenseOutput`), the method's
        own continuous extension on every step (it costs a second run).
        With ``outputs=True`` a scene's outputs are recorded at each time.
        Other ``options`` go to :func:`modelgen.sim.integrate.simulate` (``chunk``).

        A failure returns what was computed up to it, with ``status < 0``,
        ``t_fail`` and the reason in ``message``.

        >>> res = cm.simulate([1.0, 0.0], (0, 10), t_eval=np.linspace(0, 10, 101))  # doctest: +SKIP
        >>> res.y.shape, res.success, res["q"][-1]                                  # doctest: +SKIP
        """
        options.update(step=step, first_step=first_step, max_step=max_step)
        if max_steps is not None:
            options["max_steps"] = max_steps
        if self.manifest.get("constraints"):
            assemble.check_initial_state(self, self.state_vector(x0), p)
        def run(times):
            return integrate.simulate(self, x0, t_span, times, method, rtol, atol, u, p,
                                      events, outputs=outputs, **options)
        res = run(t_eval)
        if step is not None:
            warning = self.stability_warning(method, step, t_span[0], x0, u, p)
            if warning:
                res.message = f"{res.message} WARNING: {warning}"
                res.info["stability_warning"] = warning
        if dense_output:
            # the same run again (to sample its steps): what it would warn, res has said
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                steps = res if t_eval is None else run(None)
                res.sol = self._dense(steps, run)
        return res

    def _dense(self, steps, run) -> DenseOutput | None:
        """Sample the method's own dense output inside every accepted step (a second,
        identical run with those times as t_eval) and wrap it as ``sol``."""
        sign = 1.0 if len(steps.t) < 2 or steps.t[-1] >= steps.t[0] else -1.0
        keep = np.concatenate([[True], sign * np.diff(steps.t) > 0])
        ts, ys = steps.t[keep], steps.y[:, keep]
        if len(ts) < 2:
            return None
        inner = DenseOutput.NODES[1:-1]
        times = (ts[:-1, None] + np.diff(ts)[:, None] * inner[None, :]).ravel()
        times = sign * np.minimum(np.maximum.accumulate(sign * times), sign * ts[-1])
        sampled = run(times)
        nx = ys.shape[0]
        values = np.empty((len(ts) - 1, len(DenseOutput.NODES), nx))
        values[:, 0], values[:, -1] = ys[:, :-1].T, ys[:, 1:].T
        got = np.asarray(sampled.y).T.reshape(-1, nx)
        if got.shape[0] != times.size:      # the second run stopped early: no sol
            return None
        values[:, 1:-1] = got.reshape(len(ts) - 1, len(inner), nx)
        if sign < 0:        # steps and nodes ascending in t (the nodes are symmetric)
            ts, values = ts[::-1], values[::-1, ::-1]
        return DenseOutput(np.ascontiguousarray(ts), np.ascontiguousarray(values),
                           self.quaternions)

    def stability_warning(self, method, step, t0, x0, u=None, p=None) -> str | None:
        """Why a fixed ``step`` of an explicit ``method`` is unstable at (t0, x0), or None.

        Explicit Runge-Kutta methods are stable only while ``h |lambda|`` stays inside
        their stability region; with ``h |lambda|max`` beyond it (lambda the eigenvalues
        of d xdot / d x at the start) the run "succeeds" with a wrong answer.
        """
        name = integrate.method_of(method).name
        limit = STABILITY_LIMIT.get(name)
        if limit is None:            # implicit methods: A-stable
            return None
        # the state the run starts from: its quaternions normalised, as simulate's are
        x = self.checked_state(self.state_vector(x0, "x0"), "x0")
        # a bad u is the caller's error, as in simulate; what fails below is the heuristic's
        samples = None if u is None or callable(u) else self._input_samples(u)
        try:
            J = self.jac(t0, x, _input_at(u, samples, t0, x), p)
            lam = float(np.max(np.abs(np.linalg.eigvals(J))))
        except Exception:
            # a heuristic: whatever fails in it (a feedback u raising at t0, an infinite
            # input sample, a singular A...) must not discard the run it annotates
            return None
        if float(step) * lam <= limit:
            return None
        return (f"the step {float(step):g} s is beyond {name}'s stability limit: "
                f"h |lambda|max = {float(step) * lam:.3g} > {limit:g} (|lambda|max = "
                f"{lam:.3g} 1/s at the start), so the result is unreliable; use a step "
                f"below {limit / lam:.3g} s or an implicit method (rodas, gauss4)")

    def energies(self, res, p=None) -> np.ndarray:
        """Kinetic and potential energy at every time of a result, shape (n_times, 2)."""
        nq, nx = self.nq, self.nx
        if not hasattr(res, "y"):
            raise ArgumentTypeError(f"{self.name}: energies takes the Result of simulate (its "
                                    f"y, shape ({nx}, n_times)), got {type(res).__name__}")
        X = np.ascontiguousarray(self._real(res.y, "res.y").T)
        if X.ndim != 2 or X.shape[1] != nx:
            raise ArgumentValueError(f"{self.name}: res.y must have {nx} rows, got shape "
                                     f"{np.shape(res.y)}")
        out = np.empty((len(X), 2))
        # one checked conversion for the whole run, then pointer arithmetic per sample:
        # a long interrupted run's energies must not cost a Python check per sample
        x, e, pp = self._ptr(X), self._ptr(out), self._ptr(self.params(p))
        for k in range(len(X)):
            self._energy(x + k * nx, x + k * nx + nq, pp, e + 2 * k)
        return out

    def simulate_batch(self, X0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10,
                       u=None, P=None, **options):
        """Integrate many initial states / parameter sets in one C call (``threads=`` to split).

        See :func:`modelgen.sim.integrate.simulate_batch`.

        >>> res = cm.simulate_batch(X0, (0, 5), P={"g": [9.81, 1.62]})           # doctest: +SKIP
        >>> res.y.shape                                                           # doctest: +SKIP
        (2, 4, 1)
        """
        return integrate.simulate_batch(self, X0, t_span, t_eval, method, rtol, atol, u, P,
                                        **options)

    def jac(self, t, x, u=None, p=None) -> np.ndarray:
        """d xdot / d x at (t, x), shape (2n, 2n), for ``solve_ivp(..., jac=cm.jac)``.

        The generated symbolic Jacobian when the model has one, else central
        differences of the compiled rhs (see :func:`modelgen.sim.integrate.jacobian_source`).
        ``x`` must be finite and a joint's quaternion nonzero; it is not normalised,
        since this is the derivative of :meth:`rhs` at ``x`` itself (which a stiff
        solver needs where its iterates stray off unit norm).

        >>> scipy.integrate.solve_ivp(cm.rhs, (0, 1), x0, method="Radau", jac=cm.jac)  # doctest: +SKIP
        """
        x = self.checked_state(self._vector(x, self.nx, "x"), normalise=False)
        return integrate.jacobian(self, t, x, u, p)

    # -- linearization (modelgen/sim/linearize.py) -------------------------------------
    def linearize(self, x, u=None, t=0.0, p=None, outputs=None):
        """State space model about (t, x, u, p): a :class:`~modelgen.sim.linearize.Linearization`
        with A, B, C, D from the symbolic ``<name>_linearize`` (load with ``linearize=True``).

        ``x`` is the state, q alone (speeds zero) or a dict of state names;
        ``outputs`` selects output names or columns for C and D (default: all).

        >>> lin = modelgen.load("models/cart_pole.yaml", linearize=True).linearize([0, 0])  # doctest: +SKIP
        >>> lin.A, lin.B, lin.eigenvalues()                                                 # doctest: +SKIP
        """
        return linearization.linearize(self, x, u, t, p, outputs)

    def equilibrium(self, q_guess, u=None, p=None, t=0.0, **options) -> np.ndarray:
        """A rest point q (q_ddot(q, 0, u) = 0) near ``q_guess`` (``nq`` values), by
        trust-region Newton in the tangent space; the model is loaded with
        ``linearize=True``, ``jacobian=True`` or ``derivatives=True``.  See
        :func:`modelgen.sim.linearize.equilibrium` (``tol``, ``max_iter``).

        >>> q = cm.equilibrium([2.9]); cm.linearize(q).eigenvalues()    # doctest: +SKIP
        """
        return linearization.equilibrium(self, q_guess, u, p, t, **options)

    def linearize_call(self, t: float, x, u, p):
        """``(status, A, B, C, D)`` from the compiled ``<name>_linearize`` (checked
        contiguous float arrays in), or None when the build has none."""
        fn = getattr(self.lib, f"{self.name}_linearize", None)
        if fn is None:
            return None
        nx, nu, ny = self.nx, len(self.inputs), len(self.output_columns)
        out = [np.zeros((nx, nx)), np.zeros((nx, nu)), np.zeros((ny, nx)), np.zeros((ny, nu))]
        ptrs = [self._ptr(a) if a.size else self.ffi.NULL for a in out]
        status = fn(t, self._ptr(x), self._ptr(u), self._ptr(p), *ptrs)
        return (status, *out)

    def body_poses(self, q, p=None) -> np.ndarray:
        """4x4 pose of every body, shape (n_bodies, 4, 4)."""
        q = self._vector(q, self.nq, "q")
        out = np.empty((len(self.bodies), 4, 4))
        self._body_poses(self._ptr(q), self._ptr(self.params(p)), self._ptr(out))
        return out


def unpickled(manifest: dict, path: str, runtime: tuple | None = None) -> CompiledModel:
    """The model a pickle names (:meth:`CompiledModel.__reduce__`), with the runtime module
    it names when that is intact here (size and SHA-256 as recorded, as the fast index
    checks it), else this machine's own."""
    if runtime is not None and file_problem(Path(runtime[1])) is not None:
        runtime = None
    return CompiledModel(manifest, path, None if runtime is None else (runtime[0],
                                                                       Path(runtime[1])))


def check_mass_matrix(cm: CompiledModel, samples: int = 3, seed: int = 0) -> None:
    """Detect a mass matrix that is singular by construction, and name the coordinate
    (:func:`modelgen.sim.massmatrix.check`: A at a few scattered configurations with
    the default parameters)."""
    massmatrix.check(cm.manifest, lambda q: cm.mass_matrix(q).tolist(), samples, seed)


#: |h lambda| where each explicit method's stability region ends on the negative real
#: axis (Hairer & Wanner, Solving ODEs I, IV.2: RK4 2.785, DOPRI5 3.31, DOP853 6.0);
#: on the imaginary axis RK4's is 2.83
STABILITY_LIMIT = {"rk4": 2.785, "dopri5": 3.31, "dop853": 6.0}


def _input_at(u, samples, t, x):
    """The input vector at (t, x) for any input form ``simulate`` accepts: a callable
    ``u``, else its checked ``samples`` (:meth:`CompiledModel._input_samples`)."""
    if callable(u):
        return u(t, x)
    if samples is None:
        return None
    times, values, hold = samples
    if hold:
        k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
        return values[k]
    return np.array([np.interp(t, times, values[:, j]) for j in range(values.shape[1])])
