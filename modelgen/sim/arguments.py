"""The arguments of a run, checked at the boundary as solve_ivp checks them, and
turned into the structs of ``mg_integrate.h`` (options, inputs).

Every check raises :class:`~modelgen.errors.SimulationError` or one of its
``TypeError``/``ValueError`` subclasses naming the argument; a nonsensical value
(a string, a ragged list, 1e400 as an integer) never escapes as numpy's own
exception.
"""
from __future__ import annotations

import functools
import numbers
import warnings

import numpy as np

from modelgen.codegen.capi import ALIASES, LIMITS, MAX_EVENTS, METHODS, Method
from modelgen.errors import ArgumentTypeError, ArgumentValueError, SimulationError

#: the dtype of every array the C reads or writes
FLOAT = np.dtype(np.float64)
#: numpy's C long (the counters of the C API)
LONG = np.dtype("l")
#: fixed step counts from here on do not fit the C integrator's counter (a C long)
MAX_FIXED_STEPS = float(np.iinfo(LONG).max)
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
MAX_COUNT = int(np.iinfo(np.intc).max)
#: the most rows one C call of a run records when every step is recorded
MAX_CHUNK = 1 << 16


#: dtype kinds numpy's astype(float) converts that hold no numbers: text ("0.1" would
#: be read as 0.1), timedeltas and dates (their counts of some unit), records
NOT_NUMBERS = {"S": "text", "U": "text", "m": "timedeltas", "M": "dates", "V": "records"}


def real_array(value, model: str, what: str) -> np.ndarray:
    """``value`` as a new float64 array of its own shape (never a view of the caller's
    array: the C and the caller may both write later); never silently drop an
    imaginary part, read None as NaN (numpy's cast of an object array), or read text
    and times as numbers."""
    try:
        raw = np.asarray(value)
        if np.iscomplexobj(raw):
            raise SimulationError(f"{model}: {what} must be real, got a complex value")
        if raw.dtype.kind in NOT_NUMBERS:
            raise ArgumentTypeError(f"{model}: {what} must be numbers, got "
                                    f"{NOT_NUMBERS[raw.dtype.kind]} (dtype {raw.dtype})")
        if raw.dtype == object:     # None, ints beyond a double, mixed: float() each
            items = raw.ravel()
            for v in items:
                if isinstance(v, (str, bytes)) or (isinstance(v, np.generic)
                                                   and v.dtype.kind in NOT_NUMBERS):
                    raise ArgumentTypeError(f"{model}: {what} must be numbers, got {v!r}")
            return np.array([float(v) for v in items]).reshape(raw.shape)
        return raw.astype(float)
    except (TypeError, ValueError, OverflowError) as exc:
        if isinstance(exc, SimulationError):
            raise
        raise SimulationError(f"{model}: {what} must be numbers: {exc}") from None


def method_of(name: str) -> Method:
    """The :class:`Method` called ``name`` (or an alias); a clear error otherwise."""
    key = ALIASES.get(str(name).lower(), str(name).lower())
    if key not in METHODS:
        raise SimulationError(f"unknown method {name!r}; methods are "
                              f"{', '.join(METHODS)} (aliases {', '.join(ALIASES)})")
    return METHODS[key]


def checked(check):
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


@checked
def tolerance(value, nx, what):
    a = np.array(np.broadcast_to(np.asarray(value, dtype=float), (nx,)))
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise SimulationError(f"{what} must be finite and >= 0, got {value!r}")
    return a


def span(t_span):
    """``(t0, t1, sign)``: the span as floats and its direction (``sign`` -1 when
    t1 < t0: the run goes backwards in time, integrated forward in s = -t)."""
    try:
        t0, t1 = (float(v) for v in t_span)
    except OverflowError:           # an int beyond a double
        raise ArgumentValueError(f"t_span must be finite, got {t_span!r}") from None
    except (TypeError, ValueError) as exc:
        raise SimulationError(f"t_span must be (t0, t1), got {t_span!r}") from exc
    if not (np.isfinite(t0) and np.isfinite(t1)):
        raise ArgumentValueError(f"t_span must be finite, got {t_span!r}")
    if t1 == t0:
        raise SimulationError(f"t_span must not be empty, got {t_span!r}")
    return t0, t1, (-1.0 if t1 < t0 else 1.0)


@checked
def sample_times(t_eval, t0, t1, sign=1.0):
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


def whole_number(value, what: str) -> int:
    """``value`` as an int: an integer, or a float with an integral value (``1e6``);
    never truncated (``2.5`` is an error, not 2)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ArgumentTypeError(f"{what} must be an integer, got {value!r}")
    if not isinstance(value, numbers.Integral) and not float(value).is_integer():
        raise ArgumentValueError(f"{what} must be a whole number, got {value!r}")
    return int(value)


def positive(value, what: str) -> float:
    """``value`` as a float: a real number, finite and > 0 (a tolerance, a step)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ArgumentTypeError(f"{what} must be a number > 0, got {value!r}")
    try:
        number = float(value)
    except OverflowError:           # an int beyond a double
        number = np.inf
    if not (np.isfinite(number) and number > 0):
        raise ArgumentValueError(f"{what} must be finite and > 0, got {value!r}")
    return number


def floored(tol, least: float, name: str, stacklevel: int):
    """``tol`` with every value below ``least`` raised to it, with a warning (as
    solve_ivp raises rtol below 100 eps)."""
    if np.all(tol >= least):
        return tol
    warnings.warn(f"{name} below {least:.3g} is raised to {least:.3g} "
                  f"(the integrators cannot control errors below it)", RuntimeWarning,
                  stacklevel=stacklevel + 1)
    return np.maximum(tol, least)


@checked
def run_options(cm, method, rtol, atol, step, first_step, max_step, max_steps, stacklevel=2):
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
    rtol, atol = tolerance(rtol, nx, "rtol"), tolerance(atol, nx, "atol")
    if step is None and np.any(rtol + atol == 0):
        raise SimulationError("rtol and atol must not both be zero")
    if step is None:
        # ``stacklevel`` is the caller's (its frame 1); this check and its checked
        # wrapper come between
        rtol = floored(rtol, MIN_RTOL, "rtol", stacklevel + 2)
        atol = floored(atol, MIN_ATOL, "atol", stacklevel + 2)
    first = 0.0 if first_step is None else float(first_step)
    hmax = 0.0 if max_step is None or max_step == np.inf else float(max_step)
    if not (np.isfinite(first) and first >= 0 and np.isfinite(hmax) and hmax >= 0):
        raise SimulationError("first_step and max_step must be positive")
    max_steps = min(whole_number(max_steps, "max_steps"), int(np.iinfo(LONG).max))
    if max_steps < 1:
        raise SimulationError(f"max_steps must be >= 1, got {max_steps}")
    return m, rtol, atol, fixed, first, hmax, max_steps


class Inputs:
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


def event_functions(events):
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


def terminal_count(ev, i: int) -> int:
    """The event's ``terminal`` as solve_ivp reads it: False, None or 0 never stop;
    True stops at the first occurrence, a whole number k >= 1 at the k-th."""
    value = getattr(ev, "terminal", False)
    if value is None or isinstance(value, (bool, np.bool_)):
        return int(bool(value))
    what = (f"{_event_name(ev, i)}: terminal must be a bool or a positive int count of "
            f"occurrences, got {value!r}")
    if not isinstance(value, numbers.Real):
        raise ArgumentTypeError(what)
    if not (float(value).is_integer() and 0 <= value <= MAX_COUNT):
        raise ArgumentValueError(what)
    return int(value)


def crossing_direction(ev, i: int) -> int:
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

def check_step_count(fixed, t0, t1):
    """Refuse a fixed step so small that its step count overflows the C counter."""
    if fixed > 0 and not (t1 - t0) / fixed < MAX_FIXED_STEPS:
        raise ArgumentValueError(
            f"step={fixed!r} over t_span ({t0!r}, {t1!r}) needs {(t1 - t0) / fixed:.3g} steps, "
            f"more than the C integrator can count; give a larger step")


def row_chunk(chunk) -> int:
    """``chunk``, the rows of the first C call when every step is recorded (later ones
    double up to :data:`MAX_CHUNK`), as an int from 1 to :data:`MAX_CHUNK`."""
    rows = whole_number(chunk, "chunk")
    if not 1 <= rows <= MAX_CHUNK:
        raise ArgumentValueError(f"chunk must be from 1 to {MAX_CHUNK} rows per C call, got "
                                 f"{chunk!r}")
    return rows


def progress_callback(progress):
    """``progress``: None or a callable ``progress(t)``, refused before the C starts
    (it is first called while the C runs)."""
    if progress is not None and not callable(progress):
        raise ArgumentTypeError(f"progress must be None or a callable progress(t), got "
                                f"{progress!r}")
    return progress


def thread_count(threads, n_runs: int) -> int:
    """``threads``, a whole number >= 1, as the threads a batch of ``n_runs`` uses."""
    count = whole_number(threads, "threads")
    if count < 1:
        raise ArgumentValueError(f"threads must be >= 1, got {threads!r}")
    return max(1, min(count, n_runs))


def c_options(cm, m, rtol, atol, fixed, first, hmax, max_steps):
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


