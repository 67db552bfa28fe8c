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

import signal
import threading
import warnings

import numpy as np

from modelgen.codegen.capi import (ALIASES, METHODS, STAT_NAMES, STATUS, STATUS_BY_NAME, STOP_X,
                                   Method, define_values, work_size)
from modelgen.errors import (ArgumentTypeError, ArgumentValueError, MassMatrixError,
                             SimulationError)
from modelgen.sim.arguments import (LONG, MAX_CHUNK, MIN_ATOL, MIN_RTOL, Inputs, c_options,
                                     check_step_count, crossing_direction, event_functions,
                                     method_of, progress_callback, row_chunk, run_options,
                                     sample_times, span, terminal_count, thread_count)
from modelgen.sim.conditioning import condition_number, failure_kind, growth_note
from modelgen.sim.assemble import check_initial_states, crossing_message
from modelgen.sim.assemble import singular_message as constraint_message
from modelgen.sim.result import Result, make_result

__all__ = ["METHODS", "ALIASES", "STATUS", "Method", "method_of", "MIN_RTOL", "MIN_ATOL",
           "status_message", "jacobian", "jacobian_source", "simulate", "simulate_batch",
           "c_constants"]


#: the C status codes are modelgen.codegen.capi's
BUFFER_FULL = STATUS_BY_NAME["BUFFER_FULL"].code
MAX_STEPS = STATUS_BY_NAME["MAX_STEPS"].code
INTERRUPTED = STATUS_BY_NAME["INTERRUPTED"].code
INPUT_ERROR = STATUS_BY_NAME["INPUT_ERROR"].code
EVENT_ERROR = STATUS_BY_NAME["EVENT_ERROR"].code
DEAD_POINT = STATUS_BY_NAME["DEAD_POINT"].code
#: the step budget of a run when max_steps is not given (fixed-step runs get at
#: least the steps they need)
DEFAULT_MAX_STEPS = 100_000


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
    t = cm._time(t)             # as rhs checks it: a real, finite number
    out = np.empty((nx, nx))
    fn = _lib_function(cm, "jacobian") or _lib_function(cm, "jacobian_fd")
    status = fn(t, cm._ptr(x), cm._ptr(cm.input_vector(u)), cm._ptr(cm.params(p)),
                cm._ptr(out))
    if status > cm.n and cm.manifest.get("constraints"):
        # a constrained rhs's status n + k: the dependent columns of G, not A
        raise SimulationError(constraint_message(cm, status, t, x, p))
    if status:
        raise MassMatrixError(status, cm.dof_names[status - 1], t, x,
                              failure_kind(cm.mass_matrix(x[:cm.nq], p), status - 1))
    return out


# -- argument checking ---------------------------------------------------------------

def check_quaternions(cm, X, what: str) -> None:
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


def c_constants(cm) -> dict:
    """The constants of ``mg_integrate.h`` as compiled into ``cm``'s module, by name
    (``MG_METHOD_DOP853``, ``MG_STATUS_MAX_STEPS``...); equal to
    :func:`modelgen.codegen.capi.define_values` unless the module is stale."""
    return {name: getattr(cm.lib, name) for name in define_values()}


def step_budget(max_steps, budget: int, fixed: float, t0: float, t1: float) -> int:
    """The step budget of a run: ``budget`` (max_steps, or its default when None), but
    a fixed-step run without a given max_steps gets the steps its span needs."""
    if max_steps is None and fixed > 0:
        budget = max(budget, int(np.ceil(abs(t1 - t0) / fixed)) + 2)
    return budget


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
    are located on the dense output.  A g that is zero at t0 itself does not
    fire there (solve_ivp reports it at t0): an event is a sign change inside a
    step, so a run released on its event surface (a ball at rest on the floor)
    fires when it next crosses it.  ``u`` is None, constant (vector, dict, or a
    number for a one-input model), samples ``(times, values, "linear" | "hold")``,
    or a feedback callable ``u(t, x)`` (called from the C; any method) returning
    one of the constant forms.  ``p`` is None, a dict of
    overrides or a vector.  ``rtol``/``atol`` are scalars or one value per
    state; an adaptive run raises rtol below :data:`MIN_RTOL` and atol below
    :data:`MIN_ATOL` to them, with a warning.  ``step`` selects fixed steps.
    ``max_steps`` (attempted steps, a whole number) defaults
    to :data:`DEFAULT_MAX_STEPS`, or for fixed steps to the steps the span needs if
    that is more.  ``chunk`` is the number of rows of the first C call when every
    step is recorded (a whole number from 1 to :data:`MAX_CHUNK`).  ``interrupt`` is
    None or a writable numpy ``intc`` array of one element that the C polls every
    step: set it nonzero (from another thread, a signal handler or a callback) to stop with
    status INTERRUPTED and the trajectory so far.  ``progress`` is None or a
    callable ``progress(t)`` given the time reached about every 0.05 s while the C
    runs (from the calling thread, when that is the main thread) and after each
    C call: for a progress bar.  With ``outputs`` a scene's
    outputs are recorded by the C at every row (``res.outputs``).  A failure returns what was
    computed up to it, with ``status < 0`` and a message naming the time (and
    the state).  An exception raised by a feedback ``u(t, x)`` (a typo's
    NameError...) is re-raised, as solve_ivp would, with the result up to it
    (status INPUT_ERROR) attached as ``exc.partial_result``; so is an exception
    raised by an event function ``g(t, x)`` (status EVENT_ERROR), while an event
    function returning NaN or Inf ends the run with status EVENT_ERROR.
    Arguments of the wrong type or value raise :class:`~modelgen.errors.ArgumentTypeError`
    or :class:`~modelgen.errors.ArgumentValueError` (a ``TypeError``/``ValueError``
    too) or :class:`~modelgen.errors.SimulationError`.

    >>> res = simulate(cm, [np.pi / 2, 0.0], (0.0, 3.0), rtol=1e-10, events=g)  # doctest: +SKIP
    >>> res.t_events[0], res.y.shape, res.message                             # doctest: +SKIP
    """
    ffi = cm.ffi
    m, rtol, atol, fixed, first, hmax, budget = run_options(
        cm, method, rtol, atol, step, first_step, max_step,
        DEFAULT_MAX_STEPS if max_steps is None else max_steps, stacklevel=4)
    t0, t1, sign = span(t_span)
    times = None if t_eval is None else sample_times(t_eval, t0, t1, sign)
    t0, t1 = sign * t0, sign * t1          # from here on s = sign * t, increasing
    check_step_count(fixed, t0, t1)
    chunk, progress = row_chunk(chunk), progress_callback(progress)
    max_steps = step_budget(max_steps, budget, fixed, t0, t1)
    x = cm.state_vector(x0, "x0").copy()
    if not np.all(np.isfinite(x)):
        raise ArgumentValueError(f"{cm.name}: x0 must be finite")
    check_quaternions(cm, x[None, :], "x0")
    x_start = x.copy()
    inputs = Inputs(cm, u, sign)
    p_vec = cm.params(p).copy()
    events = event_functions(events)
    terminal = np.array([terminal_count(ev, i) for i, ev in enumerate(events)] or [0],
                        dtype=np.intc)
    direction = np.array([crossing_direction(ev, i) for i, ev in enumerate(events)] or [0],
                         dtype=np.intc)

    errors = []
    opt = c_options(cm, m, rtol, atol, fixed, first, hmax, max_steps)
    # the callback must outlive the C calls that use it
    callback = _event_callback(cm, opt, events, sign, terminal, direction, errors)  # noqa: F841
    if interrupt is not None:
        if not (isinstance(interrupt, np.ndarray) and interrupt.dtype == np.intc
                and interrupt.size == 1 and interrupt.flags.writeable):
            raise SimulationError("interrupt must be a writable numpy intc array of one element")
    flag = interrupt if interrupt is not None else np.zeros(1, dtype=np.intc)
    opt.interrupt = ffi.from_buffer("int[]", flag)
    reached = np.array([t0])                  # the C writes the time reached here
    opt.progress = ffi.from_buffer("double[]", reached)
    poll = None if progress is None else (lambda: progress(sign * float(reached[0])))
    ny = len(cm.output_columns) if outputs else 0
    run = _drive(cm, opt, inputs, flag, poll, sign, t0, t1, x, p_vec, times, terminal,
                 max_steps, chunk, ny)
    return _finish(cm, m, run, errors, inputs, sign, p_vec, x_start, max_steps, t_span, ny,
                   len(events))


def _event_callback(cm, opt, events, sign, terminal, direction, errors):
    """Point ``opt`` at the events: a cffi callback that evaluates every ``g(t, x)``
    (returned: it must live as long as the C call); exceptions go to ``errors``."""
    if not events:
        return None
    ffi, nx = cm.ffi, cm.nx

    def call_events(ctx, t, x_ptr, g_ptr):
        xs = np.frombuffer(ffi.buffer(x_ptr, 8 * nx), dtype=float).copy()
        for i, ev in enumerate(events):
            value = ev(sign * t, xs)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ArgumentTypeError(
                    f"event function {i} ({_name(ev)}) returned {value!r} at t={sign * t!r}; "
                    "it must return a number") from None
            if not np.isfinite(value):   # a NaN never changes sign: it would never fire
                errors.append(_NonFiniteEvent(f"event function {i} ({_name(ev)}) "
                                              f"returned {value!r}"))
                return 1
            g_ptr[i] = value
        return 0

    def on_error(exc_type, exc_value, tb):
        errors.append(exc_value)
        return 1
    callback = ffi.callback("int(void *, double, const double *, double *)",
                            call_events, onerror=on_error)
    opt.n_events = len(events)
    opt.events = callback
    opt.direction = ffi.from_buffer("int[]", direction)
    opt.terminal = ffi.from_buffer("int[]", terminal)
    return callback


class _NonFiniteEvent(ValueError):
    """An event function returned NaN or Inf: the run's status, not an exception of
    the user's to re-raise."""


def _name(fn) -> str:
    return str(getattr(fn, "__name__", fn))


class _Run:
    """What the C calls of one run produced: the rows and events of every call, the
    summed statistics, the last status and the stop array."""

    def __init__(self):
        self.t, self.x, self.y, self.ev_t, self.ev_x, self.ev_i = [], [], [], [], [], []
        self.stats = dict.fromkeys(STAT_NAMES, 0)
        self.status = 0
        self.stop = None


def _drive(cm, opt, inputs, flag, poll, sign, t0, t1, x, p_vec, times, terminal,
           max_steps, chunk, ny) -> _Run:
    """Call the C integrator until it stops for another reason than full arrays.

    It returns BUFFER_FULL when the rows (every step recorded) or the events found
    fill their arrays, and is then continued from ``stop`` exactly where it stopped
    (step size, controller memory, grid)."""
    ffi, nx, ptr = cm.ffi, cm.nx, cm._ptr
    n_ev = int(opt.n_events)
    fn = cm.lib.integrate_function(cm.name, backward=sign < 0)
    work = np.empty(work_size(nx, len(cm.inputs), n_ev))
    stats = ffi.new("mg_stats *")
    run = _Run()
    run.stop = np.zeros(STOP_X + nx)
    out = ffi.new("mg_output *")
    out.stop = ptr(run.stop)
    resume = None
    capacity, ev_capacity = max(chunk, 2), 64 * max(n_ev, 1)
    remaining = times
    steps_left = max_steps
    while True:
        if times is None:
            rows_max, t_eval_arg = capacity, None
        else:
            rows_max, t_eval_arg = len(remaining), (remaining if len(remaining) else np.array([t1]))
        t_out, x_out, y_out = _result_arrays(
            cm, [(max(rows_max, 1),), (max(rows_max, 1), nx), (max(rows_max, 1), max(ny, 1))],
            f"{rows_max} samples")
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
        run.status = _interruptible(fn, (t0, t1, ptr(x), ptr(p_vec), inputs.struct, opt, out,
                                         stats, ptr(work)), flag, poll)
        if poll is not None:
            poll()
        rows, k = out.n, out.n_events
        skip = 1 if (times is None and run.t) else 0   # a continuation repeats its start
        run.t.append(t_out[skip:rows].copy())
        run.x.append(x_out[skip:rows].copy())
        run.y.append(y_out[skip:rows, :ny].copy())
        run.ev_t.append(t_found[:k].copy())
        run.ev_x.append(x_found[:k].copy())
        run.ev_i.append(which[:k].copy())
        for name in STAT_NAMES:
            if name != "pivot":
                run.stats[name] += getattr(stats, name)
        run.stats["pivot"] = stats.pivot or run.stats["pivot"]
        if run.status != BUFFER_FULL:
            return run
        resume = run.stop.copy()
        t0, x = float(run.stop[0]), run.stop[STOP_X:].copy()
        steps_left = max(max_steps - int(run.stats["naccept"] + run.stats["nreject"]), 0)
        if times is not None:
            remaining = remaining[rows:]
        else:
            capacity = min(capacity * 2, MAX_CHUNK)
        for i in range(n_ev):
            if terminal[i]:
                terminal[i] -= int(np.count_nonzero(run.ev_i[-1] == i))
        ev_capacity = min(ev_capacity * 2, 1 << 16)


def _finish(cm, m, run: _Run, errors, inputs, sign, p_vec, x_start, max_steps, t_span,
            ny, n_ev) -> Result:
    """The :class:`Result` of a run: its rows, events, statistics and the message of
    its status; a feedback's exception is re-raised with the result attached."""
    nx, stop, status = cm.nx, run.stop, run.status
    pivot = int(run.stats["pivot"])
    failure = errors[0] if errors else inputs.error()
    if isinstance(failure, KeyboardInterrupt) and status in (INPUT_ERROR, EVENT_ERROR):
        # Ctrl-C raised inside u(t, x) or g(t, x) (a plain call: no worker thread
        # took the signal): an interrupt like any other, the trajectory so far kept
        status, failure = INTERRUPTED, None
    t_reached, t_fail = sign * float(stop[0]), sign * float(stop[2])
    message = status_message(
        int(status), t=t_reached, h=sign * float(stop[1]), t_fail=t_fail,
        x=_vector_text(stop[STOP_X:]), pivot=pivot,
        coordinate=cm.dof_names[pivot - 1] if 0 < pivot <= cm.n else "?", max_steps=max_steps,
        kind=_mass_matrix_kind(cm, status, pivot, p_vec, x_start,
                               run.stats["naccept"] == 0))
    if pivot > cm.n and cm.manifest.get("constraints"):
        message = constraint_message(cm, pivot, t_fail, stop[STOP_X:])
    elif status == DEAD_POINT and cm.manifest.get("constraints"):
        message = crossing_message(cm, t_reached, t_fail, stop[STOP_X:])
    if isinstance(failure, _NonFiniteEvent):
        message = f"{message.rstrip('.')}: {failure}."
    elif failure is not None:
        message = f"{message.rstrip('.')}: {type(failure).__name__}: {failure}."
    if status < 0:
        message += _conditioning_note(cm, p_vec, x_start, stop[STOP_X:])
    if status == MAX_STEPS:
        message += _max_steps_note(max_steps, t_span, t_reached)
        warnings.warn(f"{cm.name}: {message}", RuntimeWarning, stacklevel=5)
    et, ex, ei = (np.concatenate(run.ev_t), np.concatenate(run.ev_x).reshape(-1, nx),
                  np.concatenate(run.ev_i))
    res = make_result(
        t=sign * np.concatenate(run.t), y=np.ascontiguousarray(np.concatenate(run.x)
                                                        .reshape(-1, nx).T),
        state_names=cm.state_names, n_coordinates=cm.nq, status=int(status), message=message,
        method=m.name,
        t_events=[sign * et[ei == i] for i in range(n_ev)] if n_ev else None,
        y_events=[ex[ei == i] for i in range(n_ev)] if n_ev else None,
        t_fail=t_fail if status < 0 else None,
        **{name: int(run.stats[name]) for name in STAT_NAMES if name != "pivot"})
    if ny:
        y = np.concatenate(run.y).reshape(-1, ny)
        res.outputs = {name: y[:, [cm.output_columns.index(c) for c in cols]]
                       for name, cols in cm.outputs.items()}
        res.output_columns = dict(cm.outputs)
    if failure is not None:
        res.info["exception"] = failure
        if (status in (INPUT_ERROR, EVENT_ERROR) and isinstance(failure, Exception)
                and not isinstance(failure, _NonFiniteEvent)):
            source = "the feedback u(t, x)" if status == INPUT_ERROR else "an event function"
            _reraise(failure, res, f"by {source} near t={t_reached!r}")
    return res


def _result_arrays(cm, shapes, what: str, fill=None) -> list:
    """The arrays a run's results are written into, or, when memory cannot hold them,
    an :class:`ArgumentValueError` naming their size (a raw MemoryError named nothing)."""
    try:
        return [np.empty(shape) if fill is None else np.full(shape, fill) for shape in shapes]
    except MemoryError:
        size = sum(float(np.prod(shape, dtype=float)) for shape in shapes) * 8
        raise ArgumentValueError(
            f"{cm.name}: the results of {what} need {size / 1e9:.3g} GB, more than this "
            f"machine's memory gives; fix: fewer samples in t_eval (or fewer runs)") from None


def _reraise(exc: Exception, res: Result, where: str):
    """Re-raise the exception of a feedback ``u(t, x)`` or an event function, as
    solve_ivp would, with the result up to it attached as ``exc.partial_result``."""
    try:
        exc.partial_result = res
    except AttributeError:          # an exception type with __slots__: not attachable
        pass
    else:
        if hasattr(exc, "add_note"):        # Python 3.11+
            exc.add_note(f"modelgen: raised {where}; the run "
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
        if worker.is_alive():
            _stop(worker, flag)
        signal.signal(signal.SIGINT, previous)
    return box[0]


def _stop(worker, flag) -> None:
    """Stop the C run of ``worker`` and wait for it: an exception raised in the main
    thread (by ``poll`` or a signal handler) is about to free the arrays it writes
    into.  The caller's own ``interrupt`` array is left as it was."""
    before = int(flag[0])
    flag[0] = 1
    while worker.is_alive():
        try:
            worker.join(0.05)
        except BaseException:       # noqa: B036 - a second signal: the arrays still must live
            continue
    flag[0] = before


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
    """(array, stride): one parameter set for all runs (stride 0) or one per run; the
    values checked as ``cm.params`` checks one set (real, finite numbers)."""
    n_p = len(cm.parameters)
    if P is None:
        return cm.params(None).copy(), 0
    if isinstance(P, dict):
        rows = np.tile(cm.params(None), (n_runs, 1))
        for key, value in P.items():
            if key not in cm._param_index:
                raise ArgumentValueError(f"{cm.name}: unknown parameter {key!r}; parameters are "
                                      f"{', '.join(cm.parameters)}")
            column = cm._real(value, f"P[{key!r}]")
            if column.shape not in ((), (n_runs,)):
                raise ArgumentValueError(f"{cm.name}: P[{key!r}] must be one value or one per "
                                         f"run ({n_runs}), got shape {column.shape}")
            rows[:, cm._param_index[key]] = column
    else:
        rows = cm._real(P, "P")
        if rows.shape == (n_p,):
            return cm.params(rows).copy(), 0
        if rows.shape != (n_runs, n_p):
            raise SimulationError(f"{cm.name}: P must have shape ({n_p},) or ({n_runs}, {n_p}), "
                                  f"got {rows.shape}")
    rows = np.ascontiguousarray(rows)
    if not np.all(np.isfinite(rows)):
        bad = [name for j, name in enumerate(cm.parameters)
               if not np.all(np.isfinite(rows[:, j]))]
        raise ArgumentValueError(f"{cm.name}: parameters must be finite; got {bad}")
    return rows, n_p


def _batch_messages(cm, status, stats, stop, sign, rows, p_vec, X0, max_steps,
                    t_span) -> list:
    """Each run's message, as :func:`simulate`'s (``rows``: per-run parameters, or None
    when all share ``p_vec``)."""
    messages = []
    for r in range(len(status)):
        p = rows[r] if rows is not None else p_vec
        pivot = int(stats[r].pivot)
        messages.append(status_message(
            int(status[r]), t=sign * float(stop[r, 0]), h=sign * float(stop[r, 1]),
            t_fail=sign * float(stop[r, 2]),
            x=_vector_text(stop[r, STOP_X:]), pivot=pivot,
            coordinate=cm.dof_names[pivot - 1] if 0 < pivot <= cm.n else "?",
            max_steps=max_steps,
            kind=_mass_matrix_kind(cm, int(status[r]), pivot, p, X0[r],
                                   stats[r].naccept == 0)))
        if status[r] == DEAD_POINT and cm.manifest.get("constraints"):
            messages[-1] = crossing_message(cm, sign * float(stop[r, 0]),
                                            sign * float(stop[r, 2]), stop[r, STOP_X:])
        if status[r] < 0:
            messages[-1] += _conditioning_note(cm, p, X0[r], stop[r, STOP_X:])
        if status[r] == MAX_STEPS:
            messages[-1] += _max_steps_note(max_steps, t_span, sign * float(stop[r, 0]))
    return messages


def _batch_states(cm, X0) -> np.ndarray:
    """The rows of ``X0`` as a C-ordered float array (n_runs, nx), checked."""
    if isinstance(X0, (list, tuple)) and any(isinstance(row, dict) for row in X0):
        X0 = [cm.state_vector(row, f"X0[{r}]") for r, row in enumerate(X0)]
    X0 = np.ascontiguousarray(cm._real(X0, "X0"))
    if X0.ndim != 2 or X0.shape[1] != cm.nx:
        raise SimulationError(f"{cm.name}: X0 must have shape (n_runs, {cm.nx}), got "
                              f"{X0.shape}")
    if not np.all(np.isfinite(X0)):
        r, j = np.argwhere(~np.isfinite(X0))[0]
        raise ArgumentValueError(f"{cm.name}: X0 must be finite; got {X0[r, j]} in row {r} "
                                 f"({cm.state_names[j]})")
    check_quaternions(cm, X0, "X0")
    return X0


def simulate_batch(cm, X0, t_span, t_eval=None, method="dop853", rtol=1e-8, atol=1e-10,
                   u=None, P=None, *, step=None, first_step=None, max_step=None,
                   max_steps=None, threads=1, outputs=True) -> Result:
    """Integrate many initial states (rows of ``X0``), each with its own parameters.

    One C call loops over the runs (``threads`` > 1, a whole number, splits them
    between Python threads; the C call releases the GIL, so they run in parallel).  ``P`` is
    None (defaults), one parameter vector, an array (n_runs, n_p) or a dict of
    parameter -> value or per-run values.  A row of ``X0`` may be a dict of state
    names (see :func:`simulate`'s ``x0``).  ``t_eval`` defaults to ``[t1]``
    (final states).  Returns ``t`` (n_t,), ``y`` (n_runs, nx, n_t) (NaN after a
    failure), and per run ``status``, ``success``, ``message``, ``nfev``...; with
    ``outputs`` a scene's outputs, recorded by the C at every time, in
    ``res.outputs[name]`` of shape (n_runs, n_t, columns).  A constrained model's
    rows must be on its constraints with their runs' parameters, as ``x0`` of :func:`simulate`.

    >>> res = simulate_batch(cm, X0, (0, 5), P={"m2": np.linspace(0.5, 2, len(X0))})  # doctest: +SKIP
    """
    nx = cm.nx
    m, rtol, atol, fixed, first, hmax, budget = run_options(
        cm, method, rtol, atol, step, first_step, max_step,
        DEFAULT_MAX_STEPS if max_steps is None else max_steps, stacklevel=3)
    t0, t1, sign = span(t_span)
    max_steps = step_budget(max_steps, budget, fixed, t0, t1)
    X0 = _batch_states(cm, X0)
    n_runs = X0.shape[0]
    times = sample_times([t1] if t_eval is None else t_eval, t0, t1, sign)
    t0, t1 = sign * t0, sign * t1          # from here on s = sign * t, increasing
    inputs = Inputs(cm, u, sign)
    P_rows, p_stride = _parameter_rows(cm, P, n_runs)
    if cm.manifest.get("constraints"):     # as simulate: projected, a row would move
        check_initial_states(cm, X0, P_rows)
    threads = thread_count(threads, n_runs)

    check_step_count(fixed, t0, t1)
    n_t = len(times)
    ny = len(cm.output_columns) if outputs else 0
    x_out, y_out = _result_arrays(cm, [(n_runs, n_t, nx), (n_runs, n_t, max(ny, 1))],
                                  f"{n_runs} runs x {n_t} samples", np.nan)
    n_out = np.zeros(n_runs, dtype=LONG)
    status = np.zeros(n_runs, dtype=np.intc)
    stats = cm.ffi.new("mg_stats[]", max(n_runs, 1))
    stop = np.zeros((n_runs, STOP_X + nx))
    fn = cm.lib.integrate_function(cm.name, batch=True, backward=sign < 0)
    ffi, ptr = cm.ffi, cm._ptr
    opt = c_options(cm, m, rtol, atol, fixed, first, hmax, max_steps)
    flag = np.zeros(1, dtype=np.intc)       # Ctrl-C: every run left stops, INTERRUPTED
    opt.interrupt = ffi.from_buffer("int[]", flag)

    def run(lo, hi):
        if hi <= lo:
            return
        work = np.empty(work_size(nx, len(cm.inputs), 0))     # one per thread
        p_block = P_rows[lo:hi] if p_stride else P_rows
        fn(hi - lo, t0, t1, ptr(X0[lo:hi]), ptr(p_block), p_stride, inputs.struct, opt, n_t,
           ptr(times), ptr(x_out[lo:hi]), ptr(y_out[lo:hi]) if ny else ffi.NULL,
           ffi.from_buffer("long[]", n_out[lo:hi]),
           ffi.from_buffer("int[]", status[lo:hi]), stats + lo, ptr(stop[lo:hi]), ptr(work))

    def runs():
        bounds = np.linspace(0, n_runs, threads + 1).astype(int)
        if threads == 1:
            return run(0, n_runs)
        import concurrent.futures      # only batches use it; a cached load does not
        with concurrent.futures.ThreadPoolExecutor(threads) as pool:
            list(pool.map(run, bounds[:-1], bounds[1:]))

    _interruptible(runs, (), flag)
    for r in range(n_runs):    # rows after a failure stay NaN
        x_out[r, n_out[r]:] = np.nan
        y_out[r, n_out[r]:] = np.nan
    messages = _batch_messages(cm, status, stats, stop, sign, P_rows if p_stride else None,
                               P_rows, X0, max_steps, (sign * t0, sign * t1))
    if flag[0]:
        warnings.warn(f"{cm.name}: interrupted (Ctrl-C): {np.count_nonzero(status == INTERRUPTED)}"
                      f" of {n_runs} runs stopped early, with the samples they reached",
                      RuntimeWarning, stacklevel=3)
    short = np.flatnonzero(status == MAX_STEPS)
    if short.size:
        warnings.warn(f"{cm.name}: {short.size} of {n_runs} runs reached max_steps; run "
                      f"{short[0]}: {messages[short[0]]}", RuntimeWarning, stacklevel=3)
    res = make_result(
        t=sign * times, y=np.ascontiguousarray(x_out.transpose(0, 2, 1)), state_names=cm.state_names,
        n_coordinates=cm.nq,
        status=status.astype(int), message=messages, method=m.name,
        t_fail=np.where(status < 0, sign * stop[:, 2], np.nan),
        **{name: np.array([getattr(stats[r], name) for r in range(n_runs)], dtype=LONG)
           for name in STAT_NAMES if name != "pivot"})
    # where each run stopped: a failed run's rows are NaN after the failure, and with
    # the default t_eval=[t1] they would hold nothing of it
    res.info["t_reached"] = sign * stop[:, 0]
    res.info["x_reached"] = stop[:, STOP_X:].copy()
    if ny:
        res.outputs = {name: y_out[:, :, [cm.output_columns.index(c) for c in cols]]
                       for name, cols in cm.outputs.items()}
        res.output_columns = dict(cm.outputs)
    failure = inputs.error()
    if failure is not None:
        res.info["exception"] = failure
        if isinstance(failure, Exception):
            r = int(np.argmax(status == INPUT_ERROR))
            _reraise(failure, res, f"by the feedback u(t, x) in run {r} near "
                     f"t={sign * float(stop[r, 0])!r}")
    return res
