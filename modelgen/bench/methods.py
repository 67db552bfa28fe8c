"""Method adapters: every integrator the sweep runs, behind one call.

A method is any callable ``method(problem, setting, budget) -> Outcome``
(``setting`` is the tolerance or the step) with a ``label``, a ``name``, a
``fixed_step`` flag and a ``family``.  :func:`c_method` drives the C
integrators through ``CompiledModel.simulate`` (the methods and whether they
are adaptive come from the simulation stage's table,
:data:`modelgen.sim.integrate.METHODS`); :func:`scipy_method` drives
``scipy.integrate.solve_ivp`` on the same compiled rhs.

>>> labels = [m.label for m in default_methods()]
>>> "C dop853" in labels and "solve_ivp DOP853" in labels
True
>>> c_method("gauss4").fixed_step, c_method("dop853").fixed_step
(True, False)
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
from scipy.integrate import solve_ivp

from modelgen.bench.problem import Problem
from modelgen.errors import MassMatrixError
from modelgen.sim.integrate import METHODS, method_of

#: the C integrators a default diagram shows: every method of the C method table
C_METHODS = tuple(METHODS)
#: solve_ivp methods on the same compiled rhs (Radau with the model's Jacobian)
SCIPY_METHODS = (("RK45", False), ("DOP853", False), ("Radau", True))
#: the C status of a run stopped by its step budget (``MAX_STEPS``)
C_MAX_STEPS = -1


class Outcome(NamedTuple):
    """What one integration returned: ``y`` is (nx, len(t)); ``status`` < 0 is a failure.

    ``budget`` is True when the run stopped because it hit the evaluation,
    step or time budget (tighter settings of that method are then not run).
    """
    t: np.ndarray
    y: np.ndarray
    nfev: int
    njev: int = 0
    status: int = 0
    message: str = ""
    budget: bool = False


@dataclass(frozen=True)
class Budget:
    """Limits of one run: Python-driven methods stop after ``max_nfev`` rhs
    evaluations or ``max_seconds``; the adaptive C methods after ``max_steps``
    steps, the fixed-step ones after ``max_fixed_steps`` (their count is
    chosen, not discovered)."""
    max_nfev: int = 1_000_000
    max_seconds: float = 30.0
    max_steps: int = 10_000_000
    max_fixed_steps: int = 30_000_000


@dataclass(frozen=True)
class Method:
    """An integrator the sweep can run: ``run(problem, setting, budget) -> Outcome``.

    ``name`` is the method's own name (``"rk4"``, ``"DOP853"``); ``label``
    what the diagram and table call it; ``family`` ``"C"`` or ``"scipy"``.
    """
    label: str
    run: Callable
    name: str = ""
    fixed_step: bool = False
    family: str = "C"

    def __call__(self, problem, setting, budget=Budget()) -> Outcome:
        return self.run(problem, setting, budget)


def on_grid(out: Outcome, problem: Problem) -> bool:
    """True when the outcome reached the end: its times are the problem's grid."""
    t = np.asarray(out.t)
    span = problem.t_span[1] - problem.t_span[0]
    return (t.shape == problem.t_eval.shape
            and np.allclose(t, problem.t_eval, rtol=0, atol=1e-9 * span))


class _BudgetExceeded(Exception):
    """Raised inside a Python-driven integration when its budget runs out."""


def _counted(f, budget: Budget):
    """``f`` with a call counter that stops the integration when the budget runs out."""
    state = {"n": 0}
    deadline = time.perf_counter() + budget.max_seconds
    limit = budget.max_nfev

    def g(t, x):
        if state["n"] >= limit:
            raise _BudgetExceeded(f"stopped after {limit} rhs evaluations (budget)")
        state["n"] += 1
        if not state["n"] & 255 and time.perf_counter() > deadline:
            raise _BudgetExceeded(f"stopped after {budget.max_seconds:g} s (budget)")
        return f(t, x)
    return g, state


def jacobian_function(cm, u=None, p=None):
    """A low-overhead ``jac(t, x)`` of a compiled model for ``solve_ivp``.

    Uses the generated symbolic ``<name>_jacobian`` with bound inputs and
    parameters when the model has it, else ``cm.jac`` (central differences in
    C).
    """
    fn = getattr(cm.lib, f"{cm.name}_jacobian", None)
    if fn is None:
        return lambda t, x: cm.jac(t, x, u, p)
    nx = cm.nx
    ffi = cm.ffi
    p_arr, u_arr = cm.params(p).copy(), cm.input_vector(u).copy()
    x_buf = np.zeros(nx)
    ptrs = [ffi.from_buffer("double[]", a) for a in (x_buf, u_arr, p_arr)]

    def jac(t, x):
        x_buf[:] = x
        out = np.empty((nx, nx))
        status = fn(t, ptrs[0], ptrs[1], ptrs[2], ffi.from_buffer("double[]", out))
        if status:
            raise MassMatrixError(status, cm.coordinates[status - 1], t, x_buf.copy())
        return out
    jac.buffers = (x_buf, u_arr, p_arr)
    return jac


def scipy_method(name: str, *, jac: bool = False, label: str | None = None) -> Method:
    """``scipy.integrate.solve_ivp(method=name)`` on the compiled rhs
    (``cm.rhs_function``), with the model's Jacobian when ``jac``.

    >>> scipy_method("DOP853").label
    'solve_ivp DOP853'
    """
    def run(problem, rtol, budget):
        cm = problem.model
        f, count = _counted(cm.rhs_function(u=problem.u, p=problem.p), budget)
        options = {"jac": jacobian_function(cm, problem.u, problem.p)} if jac else {}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = solve_ivp(f, problem.t_span, problem.x0, method=name,
                                t_eval=problem.t_eval, rtol=rtol, atol=rtol, **options)
        except _BudgetExceeded as exc:
            return Outcome(np.empty(0), np.empty((len(problem.x0), 0)), count["n"], 0, -1,
                           str(exc), True)
        return Outcome(res.t, res.y, int(res.nfev), int(res.njev), int(res.status),
                       str(res.message))

    return Method(label or f"solve_ivp {name}", run, name=name, family="scipy")


def c_method(name: str, *, label: str | None = None) -> Method:
    """``CompiledModel.simulate(method=name)``: a C integrator of the model's module.

    Adaptive methods take the tolerance (atol = rtol); fixed-step ones the
    step.  An unknown name raises :class:`~modelgen.errors.SimulationError`.

    >>> c_method("rodas").label
    'C rodas'
    """
    fixed = not method_of(name).adaptive

    def run(problem, setting, budget):
        cm = problem.model
        options = {"step": setting} if fixed else {"rtol": setting, "atol": setting}
        with warnings.catch_warnings():     # the budget is a point's outcome, not news
            warnings.filterwarnings("ignore", message=".*max_steps", category=RuntimeWarning)
            res = cm.simulate(problem.x0, problem.t_span, problem.t_eval, method=name,
                              u=problem.u, p=problem.p, **options,
                              max_steps=budget.max_fixed_steps if fixed else budget.max_steps)
        status = int(res.status)
        return Outcome(np.asarray(res.t), np.asarray(res.y), int(res.nfev), int(res.njev),
                       status, str(res.message), status == C_MAX_STEPS)

    return Method(label or f"C {name}", run, name=name, fixed_step=fixed, family="C")


def default_methods(c_names=C_METHODS, scipy_names=SCIPY_METHODS) -> list:
    """The C methods (by default every one in the C method table) and the scipy ones."""
    return ([c_method(name) for name in c_names]
            + [scipy_method(name, jac=jac) for name, jac in scipy_names])
