"""Integration in C with error control, dense output and events, shaped like solve_ivp.

The integrators are model-independent C (``mg_integrate.c``, compiled once and
linked into every model's module), driven through the model's ``mg_system``;
this module validates arguments, fills the structs of ``mg_integrate.h``
(options, inputs, output buffers, statistics), calls ``<name>_integrate``
(in chunks when every step is recorded), and builds a result with the fields
of scipy's ``OdeResult``:

>>> res = cm.simulate([1.0, 0.0], (0.0, 10.0), method="dop853", rtol=1e-10)  # doctest: +SKIP
>>> res.t.shape, res.y.shape, res.status, res.nfev                           # doctest: +SKIP

Methods (``METHODS``): ``rk4`` (fixed step), ``dopri5`` and ``dop853``
(Dormand-Prince, Hairer's step control and dense output), ``rodas``
(Rosenbrock RODAS4, stiff, uses the Jacobian), ``midpoint`` and ``gauss4``
(Gauss-Legendre, implicit, symplectic, fixed step).  solve_ivp's names are
aliases of these (``ALIASES``, case-insensitive): "RK45" runs dopri5, "DOP853"
dop853, and "Radau", "BDF" and "LSODA" run rodas -- modelgen's own methods, not
scipy's.  A decreasing ``t_span`` runs backwards in time on the system in s = -t
(the C integrators step forward only).  Fixed-step methods need
``step=``; the adaptive ones run with fixed steps too when given ``step=``.

The method codes, C status codes and their messages, and the statistics are
one table, :mod:`modelgen.codegen.capi` (``STATUS`` and ``METHODS`` here are
its); :func:`c_constants` reads the same constants back from a compiled model.
"""
from __future__ import annotations

import concurrent.futures
import functools
import numbers
import signal
import threading
import warnings

import numpy as np

from modelgen.codegen.capi import (ALIASES, LIMITS, MAX_EVENTS, METHODS, STAT_NAMES, STATUS,
                                   STATUS_BY_NAME, STOP_X, Method, define_values, work_size)
from modelgen.errors import (ArgumentTypeError, ArgumentValueError, MassMatrixError,
                             SimulationError)
from modelgen.sim.conditioning import condition_number, failure_kind, growth_note
from modelgen.sim.assemble import singular_message as constraint_message
from modelgen.sim.result import Result, make_result

__all__ = ["METHODS", "ALIASES", "STATUS", "Method", "method_of",
           "status_message", "jacobian", "jacobian_source", "simulate", "simulate_batch",
           "c_constants"]


#: the C status codes are modelgen.codegen.capi's
BUFFER_FULL = STATUS_BY_NAME["BUFFER_FULL"].code
MAX_STEPS = STATUS_BY_NAME["MAX_STEPS"].code
INTERRUPTED = STATUS_BY_NAME["INTERRUPTED"].code
INPUT_ERROR = STATUS_BY_NAME["INPUT_ERROR"].code
#: the step budget of a run when max_steps is not given (fixed-step runs get at
#: least the steps they need)
DEFAULT_MAX_STEPS = 100_000
#: numpy's C long (the counters of the C API)
_LONG = np.dtype("l")
#: fixed step counts from here on do not fit the C integrator's counter (a C long)
_MAX_FIXED_STEPS = float(np.iinfo(_LONG).max)
#: the smallest rtol of an adaptive run; a smaller one is raised to it with a warning,
#: as solve_ivp does with its 100 eps.  Hairer's DOP853 and RODAS, which these
#: integrators follow, refuse rtol <= 10 uround: below it the error estimate is
#: rounding noise and the step size collapses
MIN_RTOL = 10.0 * np.finfo(float).eps
#: the smallest atol of an adaptive run (0 included), raised to it with a warning: the
#: error norm and the initial step square ratios value / (atol + rtol |x|), which
#: overflow past 1e154 (an infinite error norm, reported as a non-finite state) or
#: are 0 / 0 for a component that stays at zero with atol = 0; from 1e-100 on,
#: states and derivatives up to 1e50 stay representable
MIN_ATOL = 1e-100
#: the largest event count the C takes (an int)
_MAX_COUNT = int(np.iinfo(np.intc).max)


def method_of(name: str) -> Method:
    """The :class:`Method` called ``name`` (or an alias); a clear error otherwise."""
    key = ALIASES.get(str(name).lower(), str(name).lower())
    if key not in METHODS:
        raise SimulationError(f"unknown method {name!r}; methods are "
                              f"{', '.join(METHODS)} (aliases {', '.join(ALIASES)})")
    return METHODS[key]


def status_message(status: int, **context) -> str:
    """The message of a C status code, formatted with what the stop left behind."""
    if status not in STATUS:
        return f"Unknown status {status} from the C integrator."
    template = STATUS[status].message
    try:
        return template.format(**context)
    except (KeyError, ValueError, TypeError):
        return template


def jacobian_source(cm) -> str:
    """``"symbolic"`` when the model was generated with ``<name>_jacobian``, else
    ``"finite differences"`` (what ``rodas``, ``midpoint``, ``gauss4`` and ``cm.jac`` use)."""
    return "symbolic" if _lib_function(cm, "jacobian") is not None else "finite differences"


def _vector_text(v) -> str:
    return "[" + ", ".join(repr(float(a)) for a in v) + "]"


def _lib_function(cm, suffix):
    try:
        return getattr(cm.lib, f"{cm.name}_{suffix}")
    except AttributeError:
        return None


def jacobian(cm, t, x, u=None, p=None) -> np.ndarray:
    """d xdot / d x at (t, x), shape (nx, nx): the generated symbolic Jacobian when
    the model has one, else central differences of the compiled rhs in C."""
    nx = cm.nx
    x = cm._vector(x, nx, "x")
    out = np.empty((nx, nx))
    fn = _lib_function(cm, "jacobian") or _lib_function(cm, "jacobian_fd")
    status = fn(float(t), cm._ptr(x), cm._ptr(cm.input_vector(u)), cm._ptr(cm.params(p)),
                cm._ptr(out))
    if status:
        raise MassMatrixError(status, cm.dof_names[status - 1], t, x,
                              failure_kind(cm.mass_matrix(x[:cm.nq], p), status - 1))
    return out


# -- argument checking ---------------------------------------------------------------

def _check_quaternions(cm, X, what: str) -> None:
    """Every joint quaternion of every row of X is nonzero (the integrators
    normalise it; a zero one has no direction)."""
    for quat in cm.quaternions:
        norms = np.linalg.norm(X[:, list(quat)], axis=1)
        if np.any(norms == 0):
            names = ", ".join(cm.state_names[k] for k in quat)
            row = int(np.argmax(norms == 0))
            where = f" (row {row})" if X.shape[0] > 1 else ""
            raise SimulationError(f"{cm.name}: {what}{where} has a zero quaternion ({names}); "
                                  f"give a unit quaternion, e.g. {cm.state_names[quat[0]]} = 1 "
                                  "and the others 0 for no rotation (it is normalised)")


def _checked(check):
    """Make an argument check raise only SimulationError: the TypeError, ValueError
    or OverflowError of a nonsensical argument (a string, a ragged list, a complex
    number, 1e400 as an integer) becomes one naming the check's arguments."""
    @functools.wraps(check)
    def wrapper(*args, **kwargs):
        try:
            return check(*args, **kwargs)
        except SimulationError:         # already clear (ArgumentTypeError is a TypeError)
            raise
        except (TypeError, ValueError, OverflowError) as exc:
            raise SimulationError(f"invalid argument to simulate ({check.__name__.strip('_')}): "
                                  f"{type(exc).__name__}: {exc}") from None
    return wrapper


@_checked
def _tolerance(value, nx, what):
    a = np.array(np.broadcast_to(np.asarray(value, dtype=float), (nx,)))
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise SimulationError(f"{what} must be finite and >= 0, got {value!r}")
    return a


def _span(t_span):
    """``(t0, t1, sign)``: the span as floats and its direction (``sign`` -1 when
    t1 < t0: the run goes backwards in time, integrated forward in s = -t)."""
    try:
        t0, t1 = (float(v) for v in t_span)
    except (TypeError, ValueError) as exc:
        raise SimulationError(f"t_span must be (t0, t1), got {t_span!r}") from exc
    if not (np.isfinite(t0) and np.isfinite(t1)):
        raise SimulationError(f"t_span must be finite, got {t_span!r}")
    if t1 == t0:
        raise SimulationError(f"t_span must not be empty, got {t_span!r}")
    return t0, t1, (-1.0 if t1 < t0 else 1.0)


@_checked
def _times(t_eval, t0, t1, sign=1.0):
    """``t_eval`` checked against the span (t0, t1) and mapped to s = sign * t, where
    it must increase."""
    t_eval = np.ascontiguousarray(t_eval, dtype=float)
    if t_eval.ndim != 1 or t_eval.size == 0:
        raise SimulationError("t_eval must be a non-empty 1-D array")
    if np.any(sign * np.diff(t_eval) < 0):
        raise SimulationError("t_eval must be sorted in " + (
            "increasing order" if sign > 0 else "decreasing order (t_span runs backwards)"))
    lo, hi = min(t0, t1), max(t0, t1)
    if t_eval.min() < lo or t_eval.max() > hi or not np.all(np.isfinite(t_eval)):
        raise SimulationError(f"t_eval must lie within t_span ({t0!r}, {t1!r})")
    return np.ascontiguousarray(sign * t_eval)


def _whole(value, what: str) -> int:
    """``value`` as an int: an integer, or a float with an integral value (``1e6``);
    never truncated (``2.5`` is an error, not 2)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ArgumentTypeError(f"{what} must be an integer, got {value!r}")
    if not isinstance(value, numbers.Integral) and not float(value).is_integer():
        raise ArgumentValueError(f"{what} must be a whole number, got {value!r}")
    return int(value)


def _floor(tol, least: float, name: str, stacklevel: int):
    """``tol`` with every value below ``least`` raised to it, with a warning (as
    solve_ivp raises rtol below 100 eps)."""
    if np.all(tol >= least):
        return tol
    warnings.warn(f"{name} below {least:.3g} is raised to {least:.3g} "
                  f"(the integrators cannot control errors below it)", RuntimeWarning,
                  stacklevel=stacklevel + 1)
    return np.maximum(tol, least)


@_checked
def _options(cm, method, rtol, atol, step, first_step, max_step, max_steps, stacklevel=2):
    m = method_of(method)
    nx = cm.nx
    if step is None:
        if not m.adaptive:
            raise SimulationError(f"method {m.name!r} has a fixed step: give step=")
        fixed = 0.0
    else:
        fixed = float(step)
        if not (np.isfinite(fixed) and fixed > 0):
            raise SimulationError(f"step must be positive, got {step!r}")
    rtol, atol = _tolerance(rtol, nx, "rtol"), _tolerance(atol, nx, "atol")
    if step is None and np.any(rtol + atol == 0):
        raise SimulationError("rtol and atol must not both be zero")
    if step is None:
        # ``stacklevel`` is the caller's (its frame 1); this check and its _checked
        # wrapper come between
        rtol = _floor(rtol, MIN_RTOL, "rtol", stacklevel + 2)
        atol = _floor(atol, MIN_ATOL, "atol", stacklevel + 2)
    first = 0.0 if first_step is None else float(first_step)
    hmax = 0.0 if max_step is None or max_step == np.inf else float(max_step)
    if not (np.isfinite(first) and first >= 0 and np.isfinite(hmax) and hmax >= 0):
        raise SimulationError("first_step and max_step must be positive")
    max_steps = min(_whole(max_steps, "max_steps"), int(np.iinfo(_LONG).max))
    if max_steps < 1:
        raise SimulationError(f"max_steps must be >= 1, got {max_steps}")
    return m, rtol, atol, fixed, first, hmax, max_steps


class _Inputs:
    """The ``mg_inputs`` struct of one call, and what its pointers point to.

    ``u`` is None (zeros), a constant vector, dict or (one input) number,
    samples ``(times, values, "linear" | "hold")``, or a callable ``u(t, x)``
    called from the C through a cffi callback (feedback; works with every
    method) that returns any constant form but None.  An exception in the
    callable stops the integration with status INPUT_ERROR and is kept in
    ``errors``; :func:`simulate` re-raises it.
    """

    def __init__(self, cm, u, sign=1.0):
        ffi = cm.ffi
        self.struct = ffi.new("mg_inputs *")
        self.errors = []
        self._keep = []
        if callable(u):
            nu, nx = len(cm.inputs), cm.nx

            def call(ctx, t, x_ptr, u_ptr):
                x = np.frombuffer(ffi.buffer(x_ptr, 8 * nx), dtype=float).copy()
                got = u(sign * t, x)
                if got is None:         # input_vector's "zeros": here a forgotten return
                    raise ArgumentTypeError(
                        f"{cm.name}: the feedback u(t, x) returned None at t={sign * t!r}; "
                        f"it must return the inputs ({', '.join(cm.inputs) or 'none'}) as a "
                        "sequence or a dict by name" + (", or a number" if nu == 1 else ""))
                value = cm.input_vector(got)
                for k in range(nu):
                    u_ptr[k] = value[k]
                return 0

            def on_error(exc_type, exc_value, tb):
                self.errors.append(exc_value)
                return 1
            callback = ffi.callback("int(void *, double, const double *, double *)", call,
                                    onerror=on_error)
            self._keep.append(callback)
            self.struct.callback = callback
            return
        times, values, hold = cm._input_samples(u)
        if sign < 0 and len(times):
            # the samples in s = -t: reversed; a held value covers the interval to the
            # *left* of its sample in s, so each takes its successor's value
            times = np.ascontiguousarray(-times[::-1])
            rows = values.reshape(len(times), -1)[::-1]
            if hold:
                rows = np.concatenate([rows[1:], rows[-1:]])
            values = np.ascontiguousarray(rows).reshape(values.shape)
        self._keep += [times, values]
        self.struct.n = len(times)
        self.struct.times = ffi.from_buffer("double[]", times)
        self.struct.values = ffi.from_buffer("double[]", values)
        self.struct.hold = LIMITS["INPUT_HOLD" if hold else "INPUT_LINEAR"][0]

    def error(self):
        """The first exception the callable raised, or None."""
        return self.errors[0] if self.errors else None


def _events(events):
    """The event functions as a list: ``events`` is None, a callable ``g(t, x)`` or
    a sequence of them."""
    if events is None:
        return []
    if callable(events):
        events = [events]
    what = "events must be a callable g(t, x) or a sequence of callables"
    if isinstance(events, (str, bytes, dict)):
        raise ArgumentTypeError(f"{what}, got {events!r}")
    try:
        events = list(events)
    except TypeError:
        raise ArgumentTypeError(f"{what}, got {events!r}") from None
    if len(events) > MAX_EVENTS:
        raise SimulationError(f"at most {MAX_EVENTS} event functions, got {len(events)}")
    for i, ev in enumerate(events):
        if not callable(ev):
            raise ArgumentTypeError(f"{what}; events[{i}] is {ev!r}")
    return events


def _event_name(ev, i: int) -> str:
    return f"event {i} ({getattr(ev, '__name__', type(ev).__name__)})"


def _terminal(ev, i: int) -> int:
    """The event's ``terminal`` as solve_ivp reads it: False, None or 0 never stop;
    True stops at the first occurrence, a whole number k >= 1 at the k-th."""
    value = getattr(ev, "terminal", False)
    if value is None or isinstance(value, (bool, np.bool_)):
        return int(bool(value))
    what = (f"{_event_name(ev, i)}: terminal must be a bool or a positive int count of "
            f"occurrences, got {value!r}")
    if not isinstance(value, numbers.Real):
        raise ArgumentTypeError(what)
    if not (float(value).is_integer() and 0 <= value <= _MAX_COUNT):
        raise ArgumentValueError(what)
    return int(value)


def _direction(ev, i: int) -> int:
    """The sign of the event's ``direction``, as solve_ivp uses it: > 0 rising zeros
    only, < 0 falling ones, 0 (or None, or no attribute) both."""
    value = getattr(ev, "direction", 0)
    if value is None:
        return 0
    what = (f"{_event_name(ev, i)}: direction must be a real number (its sign selects the "
            f"crossings: > 0 rising, < 0 falling, 0 both), got {value!r}")
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ArgumentTypeError(what)
    if np.isnan(value):
        raise ArgumentValueError(what)
    return 1 if value > 0 else (-1 if value < 0 else 0)


# -- simulate ------------------------------------------------------------------------

def _check_step_count(fixed, t0, t1):
    """Refuse a fixed step so small that its step count overflows the C counter."""
    if fixed > 0 and not (t1 - t0) / fixed < _MAX_FIXED_STEPS:
        raise SimulationError(
            f"step={fixed!r} over t_span ({t0!r}, {t1!r}) needs {(t1 - t0) / fixed:.3g} steps, "
            f"more than the C integrator can count; give a larger step")


def _c_options(cm, m, rtol, atol, fixed, first, hmax, max_steps):
    """The ``mg_options`` struct (events and resume are set by the caller)."""
    opt = cm.ffi.new("mg_options *")
    opt.method = m.code
    opt.rtol = cm._ptr(rtol)
    opt.atol = cm._ptr(atol)
    opt.first_step = first
    opt.max_step = hmax
    opt.fixed_step = fixed
    opt.max_steps = max_steps
    return opt


def c_constants(cm) -> dict:
    """The constants of ``mg_integrate.h`` as compiled into ``cm``'s module, by name
    (``MG_METHOD_DOP853``, ``MG_STATUS_MAX_STEPS``...); equal to
    :func:`modelgen.codegen.capi.define_values` unless the module is stale."""
    return {name: getattr(cm.lib, name) for name in define_values()}


def simulate(cm, x0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10, u=None,
             p=None, events=None, *, step=None, first_step=None, max_step=None,
             max_steps=None, chunk=2048, interrupt=None, outputs=True,
             progress=None) -> Result:
    """Integrate the compiled model ``cm`` in C from ``x0`` over ``t_span``.

    ``t_eval`` samples the solution through each method's dense output (the
    steps are not shortened to hit them); without it every accepted step is
    recorded.  ``x0`` is an array of ``nx`` values or a dict of coordinate and
    speed names -> values (the others from :meth:`CompiledModel.neutral_state`:
    zero, quaternions (1, 0, 0, 0)).  ``events`` is a callable ``g(t, x)`` or a
    sequence of them, with optional attributes ``terminal`` (bool, or the
    occurrence count at which to stop) and ``direction`` (a real number whose
    sign selects rising or falling zeros, 0 both), as in ``solve_ivp``; their zeros
    are located on the dense output.  ``u`` is None, constant (vector, dict, or a
    number for a one-input model), samples ``(times, values, "linear" | "hold")``,
    or a feedback callable ``u(t, x)`` (called from the C; any method) returning
    one of the constant forms.  ``p`` is None, a dict of
    overrides or a vector.  ``rtol``/``atol`` are scalars or one value per
    state; an adaptive run raises rtol below :data:`MIN_RTOL` and atol below
    :data:`MIN_ATOL` to them, with a warning.  ``step`` selects fixed steps.
    ``max_steps`` (attempted steps, a whole number) defaults
    to :data:`DEFAULT_MAX_STEPS`, or for fixed steps to the steps the span needs if
    that is more.  ``chunk`` is the number of rows per C
    call when every step is recorded.  ``interrupt`` is None or a writable
    numpy ``intc`` array of one element that the C polls every step: set it
    nonzero (from another thread, a signal handler or a callback) to stop with
    status INTERRUPTED and the trajectory so far.  ``progress`` is None or a
    callable ``progress(t)`` given the time reached about every 0.05 s while the C
    runs (from the calling thread, when that is the main thread) and after each
    C call: for a progress bar.  With ``outputs`` a scene's
    outputs are recorded by the C at every row (``res.outputs``).  A failure returns what was
    computed up to it, with ``status < 0`` and a message naming the time (and
    the state).  An exception raised by a feedback ``u(t, x)`` (a typo's
    NameError...) is re-raised, as solve_ivp would, with the result up to it
    (status INPUT_ERROR) attached as ``exc.partial_result``; an exception in an
    event function ends the run with status EVENT_ERROR (``res.info["exception"]``).
    Arguments of the wrong type or value raise :class:`~modelgen.errors.ArgumentTypeError`
    or :class:`~modelgen.errors.ArgumentValueError` (a ``TypeError``/``ValueError``
    too) or :class:`~modelgen.errors.SimulationError`.

    >>> res = simulate(cm, [np.pi / 2, 0.0], (0.0, 3.0), rtol=1e-10, events=g)  # doctest: +SKIP
    >>> res.t_events[0], res.y.shape, res.message                             # doctest: +SKIP
    """
    ffi, nx = cm.ffi, cm.nx
    m, rtol, atol, fixed, first, hmax, budget = _options(
        cm, method, rtol, atol, step, first_step, max_step,
        DEFAULT_MAX_STEPS if max_steps is None else max_steps, stacklevel=4)
    t0, t1, sign = _span(t_span)
    times = None if t_eval is None else _times(t_eval, t0, t1, sign)
    t0, t1 = sign * t0, sign * t1          # from here on s = sign * t, increasing
    _check_step_count(fixed, t0, t1)
    if max_steps is None and fixed > 0:      # a fixed-step run's step count is known
        budget = max(budget, int(np.ceil((t1 - t0) / fixed)) + 2)
    max_steps = budget
    x = cm.state_vector(x0, "x0").copy()
    if not np.all(np.isfinite(x)):
        raise SimulationError(f"{cm.name}: x0 must be finite")
    _check_quaternions(cm, x[None, :], "x0")
    x_start = x.copy()
    inputs = _Inputs(cm, u, sign)
    p_vec = cm.params(p).copy()
    events = _events(events)
    n_ev = len(events)
    terminal = np.array([_terminal(ev, i) for i, ev in enumerate(events)] or [0],
                        dtype=np.intc)
    direction = np.array([_direction(ev, i) for i, ev in enumerate(events)] or [0],
                         dtype=np.intc)

    errors = []
    opt = _c_options(cm, m, rtol, atol, fixed, first, hmax, max_steps)
    if n_ev:
        def call_events(ctx, t, x_ptr, g_ptr):
            xs = np.frombuffer(ffi.buffer(x_ptr, 8 * nx), dtype=float).copy()
            for i, ev in enumerate(events):
                value = float(ev(sign * t, xs))
                if not np.isfinite(value):   # a NaN never changes sign: it would never fire
                    raise ValueError(f"event function {i} ({getattr(ev, '__name__', ev)!s}) "
                                     f"returned {value!r}")
                g_ptr[i] = value
            return 0

        def on_error(exc_type, exc_value, tb):
            errors.append(exc_value)
            return 1
        callback = ffi.callback("int(void *, double, const double *, double *)",
                                call_events, onerror=on_error)
        opt.n_events = n_ev
        opt.events = callback
        opt.direction = ffi.from_buffer("int[]", direction)
        opt.terminal = ffi.from_buffer("int[]", terminal)
    if interrupt is not None:
        if not (isinstance(interrupt, np.ndarray) and interrupt.dtype == np.intc
                and interrupt.size == 1 and interrupt.flags.writeable):
            raise SimulationError("interrupt must be a writable numpy intc array of one element")
    flag = interrupt if interrupt is not None else np.zeros(1, dtype=np.intc)
    opt.interrupt = ffi.from_buffer("int[]", flag)
    reached = np.array([t0])                  # the C writes the time reached here
    opt.progress = ffi.from_buffer("double[]", reached)
    poll = None if progress is None else (lambda: progress(sign * float(reached[0])))

    fn = cm.lib.integrate_function(cm.name, backward=sign < 0)
    ptr = cm._ptr
    work = np.empty(work_size(nx, len(cm.inputs), n_ev))
    stats = ffi.new("mg_stats *")
    stats_total = dict.fromkeys(STAT_NAMES, 0)
    stop = np.zeros(STOP_X + nx)
    out = ffi.new("mg_output *")
    out.stop = ptr(stop)
    resume = None
    t_parts, x_parts, y_parts, ev_t, ev_x, ev_i = [], [], [], [], [], []
    ny = len(cm.output_columns) if outputs else 0
    capacity, ev_capacity = int(max(chunk, 2)), 64 * max(n_ev, 1)
    remaining = times
    steps_left = max_steps
    while True:
        # one C call; it returns BUFFER_FULL when the rows (every step recorded) or
        # the events found fill their arrays, and is then continued from `stop`
        if times is None:
            rows_max, t_eval_arg = capacity, None
        else:
            rows_max, t_eval_arg = len(remaining), (remaining if len(remaining) else np.array([t1]))
        t_out, x_out = np.empty(max(rows_max, 1)), np.empty((max(rows_max, 1), nx))
        y_out = np.empty((max(rows_max, 1), max(ny, 1)))
        t_found, x_found = np.empty(ev_capacity), np.empty((ev_capacity, nx))
        which = np.empty(ev_capacity, dtype=np.intc)
        out.capacity = rows_max
        out.t_eval = ffi.NULL if t_eval_arg is None else ptr(t_eval_arg)
        out.t, out.x = ptr(t_out), ptr(x_out)
        out.y = ptr(y_out) if ny else ffi.NULL      # the scene's outputs, from the C
        out.events_capacity = ev_capacity
        out.t_events, out.x_events = ptr(t_found), ptr(x_found)
        out.which_events = ffi.from_buffer("int[]", which)
        opt.max_steps = steps_left
        opt.resume = ffi.NULL if resume is None else ptr(resume)
        status = _interruptible(fn, (t0, t1, ptr(x), ptr(p_vec), inputs.struct, opt, out, stats,
                                     ptr(work)), flag, poll)
        if poll is not None:
            poll()
        rows, k = out.n, out.n_events
        skip = 1 if (times is None and t_parts) else 0   # a continuation repeats its start
        t_parts.append(t_out[skip:rows].copy())
        x_parts.append(x_out[skip:rows].copy())
        y_parts.append(y_out[skip:rows, :ny].copy())
        ev_t.append(t_found[:k].copy())
        ev_x.append(x_found[:k].copy())
        ev_i.append(which[:k].copy())
        for name in STAT_NAMES:
            if name != "pivot":
                stats_total[name] += getattr(stats, name)
        stats_total["pivot"] = stats.pivot or stats_total["pivot"]
        if status != BUFFER_FULL:
            break
        # continue exactly where the C stopped (step size, controller memory, grid)
        resume = stop.copy()
        t0, x = float(stop[0]), stop[STOP_X:].copy()
        steps_left = max(max_steps - int(stats_total["naccept"] + stats_total["nreject"]), 0)
        if times is not None:
            remaining = remaining[rows:]
        else:
            capacity = min(capacity * 2, 1 << 16)
        for i in range(n_ev):
            if terminal[i]:
                terminal[i] -= int(np.count_nonzero(ev_i[-1] == i))
        ev_capacity = min(ev_capacity * 2, 1 << 16)

    pivot = int(stats_total["pivot"])
    failure = errors[0] if errors else inputs.error()
    if isinstance(failure, KeyboardInterrupt) and status == INPUT_ERROR:
        # Ctrl-C raised inside u(t, x) (a plain call: no worker thread took the
        # signal): an interrupt like any other, the trajectory so far kept
        status, failure = INTERRUPTED, None
    t_reached, t_fail = sign * float(stop[0]), sign * float(stop[2])
    message = status_message(
        int(status), t=t_reached, h=sign * float(stop[1]), t_fail=t_fail,
        x=_vector_text(stop[STOP_X:]), pivot=pivot,
        coordinate=cm.dof_names[pivot - 1] if 0 < pivot <= cm.n else "?", max_steps=max_steps,
        kind=_mass_matrix_kind(cm, status, pivot, p_vec, x_start,
                               stats_total["naccept"] == 0))
    if pivot > cm.n and cm.manifest.get("constraints"):
        message = constraint_message(cm, pivot, t_fail, stop[STOP_X:])
    if failure is not None:
        message = f"{message.rstrip('.')}: {type(failure).__name__}: {failure}."
    if status < 0:
        message += _conditioning_note(cm, p_vec, x_start, stop[STOP_X:])
    if status == MAX_STEPS:
        message += _max_steps_note(max_steps, t_span, t_reached)
        warnings.warn(f"{cm.name}: {message}", RuntimeWarning, stacklevel=4)
    et, ex, ei = (np.concatenate(ev_t), np.concatenate(ev_x).reshape(-1, nx),
                  np.concatenate(ev_i))
    res = make_result(
        t=sign * np.concatenate(t_parts), y=np.ascontiguousarray(np.concatenate(x_parts)
                                                          .reshape(-1, nx).T),
        state_names=cm.state_names, n_coordinates=cm.nq, status=int(status), message=message,
        method=m.name,
        t_events=[sign * et[ei == i] for i in range(n_ev)] if n_ev else None,
        y_events=[ex[ei == i] for i in range(n_ev)] if n_ev else None,
        t_fail=t_fail if status < 0 else None,
        **{name: int(stats_total[name]) for name in STAT_NAMES if name != "pivot"})
    if ny:
        y = np.concatenate(y_parts).reshape(-1, ny)
        res.outputs = {name: y[:, [cm.output_columns.index(c) for c in cols]]
                       for name, cols in cm.outputs.items()}
        res.output_columns = dict(cm.outputs)
    if failure is not None:
        res.info["exception"] = failure
        if status == INPUT_ERROR and isinstance(failure, Exception):
            _reraise(failure, res, f"near t={t_reached!r}")
    return res


def _reraise(exc: Exception, res: Result, where: str):
    """Re-raise the exception of a feedback ``u(t, x)``, as solve_ivp would, with the
    result up to it attached as ``exc.partial_result``."""
    try:
        exc.partial_result = res
    except AttributeError:          # an exception type with __slots__: not attachable
        pass
    else:
        if hasattr(exc, "add_note"):        # Python 3.11+
            exc.add_note(f"modelgen: raised by the feedback u(t, x) {where}; the run "
                         "up to there is this exception's .partial_result")
    raise exc


def _max_steps_note(max_steps, t_span, t_reached) -> str:
    """What a run truncated by ``max_steps`` missed and how to raise it."""
    t0, t1 = (float(v) for v in t_span)
    done = (t_reached - t0) / (t1 - t0)
    need = None
    if done > 0:        # 1.2 times the steps at the pace so far, rounded up to 2 digits
        estimate = 1.2 * max_steps / done
        unit = 10.0 ** max(np.floor(np.log10(estimate)) - 1, 0)
        need = f"{int(np.ceil(estimate / unit) * unit):d}"
    return (f" The run stopped at {100 * done:.3g}% of t_span ({t0!r}, {t1!r}); fix: raise "
            f"max_steps (simulate(..., max_steps={need or 'N'}), or --max-steps "
            f"{need or 'N'} on the command line), or loosen rtol/atol.")


def _interruptible(fn, args, flag, poll=None):
    """``fn(*args)``, a C integration loop that polls ``flag``, stopped by Ctrl-C
    (and ``poll()`` called between the short joins, for progress).

    In the main thread, with Python's default SIGINT handler in place, the C
    call runs in a worker thread while the main thread waits in short joins;
    Ctrl-C then sets ``flag`` (the C returns INTERRUPTED within a step and the
    trajectory so far is kept) instead of raising KeyboardInterrupt after the
    whole run.  Elsewhere (another thread, a custom handler) it is a plain call.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        return fn(*args)
    box = []

    def on_sigint(signum, frame):
        flag[0] = 1

    worker = threading.Thread(target=lambda: box.append(fn(*args)), daemon=True)
    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        worker.start()
        while worker.is_alive():
            worker.join(0.05)
            if poll is not None:
                poll()
    finally:
        signal.signal(signal.SIGINT, previous)
    return box[0]


def _mass_matrix_kind(cm, status, pivot, p_vec, x_start, at_start) -> str:
    """How the mass matrix failed: classified exactly at the start; later in a run A
    was positive definite at the last accepted state and is continuous in q, so a
    failing pivot is A becoming singular to working precision."""
    if status != -3 or not 0 < pivot <= cm.n:
        return "not positive definite"
    if at_start:
        return failure_kind(cm.mass_matrix(x_start[:cm.nq], p_vec), pivot - 1)
    return "singular to working precision"


def _conditioning_note(cm, p_vec, x_start, x_last) -> str:
    """Why a run failed when A's condition number grew by orders of magnitude between
    its start and its last good state (a singular configuration ahead), else ''."""
    if not (np.all(np.isfinite(x_start)) and np.all(np.isfinite(x_last))):
        return ""
    return growth_note(condition_number(cm.mass_matrix(x_start[:cm.nq], p_vec)),
                       condition_number(cm.mass_matrix(x_last[:cm.nq], p_vec)))


# -- batches ---------------------------------------------------------------------------

def _parameter_rows(cm, P, n_runs):
    """(array, stride): one parameter set for all runs (stride 0) or one per run."""
    n_p = len(cm.parameters)
    if P is None:
        return cm.params(None).copy(), 0
    if isinstance(P, dict):
        rows = np.tile(cm.params(None), (n_runs, 1))
        for key, value in P.items():
            if key not in cm._param_index:
                raise SimulationError(f"{cm.name}: unknown parameter {key!r}; parameters are "
                                      f"{', '.join(cm.parameters)}")
            rows[:, cm._param_index[key]] = np.broadcast_to(np.asarray(value, dtype=float),
                                                            (n_runs,))
    else:
        rows = np.asarray(P, dtype=float)
        if rows.shape == (n_p,):
            return cm.params(rows).copy(), 0
        if rows.shape != (n_runs, n_p):
            raise SimulationError(f"{cm.name}: P must have shape ({n_p},) or ({n_runs}, {n_p}), "
                                  f"got {rows.shape}")
    rows = np.ascontiguousarray(rows)
    if not np.all(np.isfinite(rows)):
        raise SimulationError(f"{cm.name}: parameters must be finite")
    return rows, n_p


def simulate_batch(cm, X0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10,
                   u=None, P=None, *, step=None, first_step=None, max_step=None,
                   max_steps=100_000, threads=1, outputs=True) -> Result:
    """Integrate many initial states (rows of ``X0``), each with its own parameters.

    One C call loops over the runs (``threads`` > 1 splits them between Python
    threads; the C call releases the GIL, so they run in parallel).  ``P`` is
    None (defaults), one parameter vector, an array (n_runs, n_p) or a dict of
    parameter -> value or per-run values.  A row of ``X0`` may be a dict of state
    names (see :func:`simulate`'s ``x0``).  ``t_eval`` defaults to ``[t1]``
    (final states).  Returns ``t`` (n_t,), ``y`` (n_runs, nx, n_t) (NaN after a
    failure), and per run ``status``, ``success``, ``message``, ``nfev``...; with
    ``outputs`` a scene's outputs, recorded by the C at every time, in
    ``res.outputs[name]`` of shape (n_runs, n_t, columns).

    >>> res = simulate_batch(cm, X0, (0, 5), P={"m2": np.linspace(0.5, 2, len(X0))})  # doctest: +SKIP
    """
    nx = cm.nx
    m, rtol, atol, fixed, first, hmax, max_steps = _options(
        cm, method, rtol, atol, step, first_step, max_step, max_steps, stacklevel=3)
    t0, t1, sign = _span(t_span)
    if isinstance(X0, (list, tuple)) and any(isinstance(row, dict) for row in X0):
        X0 = [cm.state_vector(row, f"X0[{r}]") for r, row in enumerate(X0)]
    X0 = np.ascontiguousarray(X0, dtype=float)
    if X0.ndim != 2 or X0.shape[1] != nx:
        raise SimulationError(f"{cm.name}: X0 must have shape (n_runs, {nx}), got {X0.shape}")
    if not np.all(np.isfinite(X0)):
        raise SimulationError(f"{cm.name}: X0 must be finite")
    _check_quaternions(cm, X0, "X0")
    n_runs = X0.shape[0]
    times = _times([t1] if t_eval is None else t_eval, t0, t1, sign)
    t0, t1 = sign * t0, sign * t1          # from here on s = sign * t, increasing
    inputs = _Inputs(cm, u, sign)
    P_rows, p_stride = _parameter_rows(cm, P, n_runs)
    threads = max(1, min(int(threads), max(n_runs, 1)))

    _check_step_count(fixed, t0, t1)
    n_t = len(times)
    x_out = np.full((n_runs, n_t, nx), np.nan)
    ny = len(cm.output_columns) if outputs else 0
    y_out = np.full((n_runs, n_t, max(ny, 1)), np.nan)
    n_out = np.zeros(n_runs, dtype=_LONG)
    status = np.zeros(n_runs, dtype=np.intc)
    stats = cm.ffi.new("mg_stats[]", max(n_runs, 1))
    stop = np.zeros((n_runs, STOP_X + nx))
    fn = cm.lib.integrate_function(cm.name, batch=True, backward=sign < 0)
    ffi, ptr = cm.ffi, cm._ptr
    opt = _c_options(cm, m, rtol, atol, fixed, first, hmax, max_steps)

    def run(lo, hi):
        if hi <= lo:
            return
        work = np.empty(work_size(nx, len(cm.inputs), 0))     # one per thread
        p_block = P_rows[lo:hi] if p_stride else P_rows
        fn(hi - lo, t0, t1, ptr(X0[lo:hi]), ptr(p_block), p_stride, inputs.struct, opt, n_t,
           ptr(times), ptr(x_out[lo:hi]), ptr(y_out[lo:hi]) if ny else ffi.NULL,
           ffi.from_buffer("long[]", n_out[lo:hi]),
           ffi.from_buffer("int[]", status[lo:hi]), stats + lo, ptr(stop[lo:hi]), ptr(work))

    bounds = np.linspace(0, n_runs, threads + 1).astype(int)
    if threads == 1:
        run(0, n_runs)
    else:
        with concurrent.futures.ThreadPoolExecutor(threads) as pool:
            list(pool.map(run, bounds[:-1], bounds[1:]))
    for r in range(n_runs):    # rows after a failure stay NaN
        x_out[r, n_out[r]:] = np.nan
        y_out[r, n_out[r]:] = np.nan
    messages = []
    for r in range(n_runs):
        pivot = int(stats[r].pivot)
        messages.append(status_message(
            int(status[r]), t=sign * float(stop[r, 0]), h=sign * float(stop[r, 1]),
            t_fail=sign * float(stop[r, 2]),
            x=_vector_text(stop[r, STOP_X:]), pivot=pivot,
            coordinate=cm.dof_names[pivot - 1] if 0 < pivot <= cm.n else "?",
            max_steps=max_steps,
            kind=_mass_matrix_kind(cm, int(status[r]), pivot,
                                   P_rows[r] if p_stride else P_rows, X0[r],
                                   stats[r].naccept == 0)))
        if status[r] < 0:
            messages[-1] += _conditioning_note(cm, P_rows[r] if p_stride else P_rows, X0[r],
                                               stop[r, STOP_X:])
    res = make_result(
        t=sign * times, y=np.ascontiguousarray(x_out.transpose(0, 2, 1)), state_names=cm.state_names,
        n_coordinates=cm.nq,
        status=status.astype(int), message=messages, method=m.name,
        **{name: np.array([getattr(stats[r], name) for r in range(n_runs)], dtype=_LONG)
           for name in STAT_NAMES if name != "pivot"})
    if ny:
        res.outputs = {name: y_out[:, :, [cm.output_columns.index(c) for c in cols]]
                       for name, cols in cm.outputs.items()}
        res.output_columns = dict(cm.outputs)
    failure = inputs.error()
    if failure is not None:
        res.info["exception"] = failure
        if isinstance(failure, Exception):
            r = int(np.argmax(status == INPUT_ERROR))
            _reraise(failure, res, f"in run {r} near t={sign * float(stop[r, 0])!r}")
    return res
