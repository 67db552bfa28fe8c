"""Work-precision diagrams: error against cost for many integrators on one problem.

Done the way SciML's DiffEqBenchmarks and Hairer's test set do it:

* a **reference solution** that is a closed form where one exists, otherwise
  two different high-order methods at rtol = atol <= 1e-13 (in extended
  precision for chaotic problems) whose disagreement is measured and shown:
  errors less than 100 times that disagreement are not resolved and are drawn
  hollow, over a grey band;
* **errors** on the positions q: the final-time error ``max_i |q_i(T) -
  q_ref,i(T)|`` and a dense L2 error ``sqrt(mean_k mean_i (q_i(t_k) -
  q_ref,i(t_k))^2)`` on the problem's fixed grid ``t_k``;
* adaptive methods swept over tolerances (half or whole decades, atol =
  rtol), fixed-step methods over step sizes that divide the grid spacing, on
  the same axes;
* **cost**: the minimum wall time over repeats, and the number of rhs
  evaluations (hardware-independent);
* **failures** (a status < 0, an exception, a budget exceeded) are kept and
  drawn as ``x`` in a "failed" band, never dropped.

A method is any callable ``method(problem, setting, budget) -> Outcome``
(``setting`` is the tolerance or the step) with a ``label`` and a
``fixed_step`` flag; :func:`scipy_method` drives ``solve_ivp`` with the
compiled rhs, :func:`c_method` the C integrators of ``CompiledModel.simulate``.

>>> problem = pendulum_problem()                                   # doctest: +SKIP
>>> points = run_sweep(problem, default_methods(problem.model),
...                    tolerances=[1e-4, 1e-6, 1e-8])               # doctest: +SKIP
>>> write_tables(points, "out/pendulum")                           # doctest: +SKIP
>>> plot_work_precision(points, problem, "out/pendulum.png")       # doctest: +SKIP
"""
from __future__ import annotations

import csv
import gc
import math
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, NamedTuple

import numpy as np

from modelgen.errors import ModelgenError, SimulationError

#: where the standard set's scenes live (a source checkout)
SCENES = Path(__file__).resolve().parents[2] / "models" / "scenes"
#: grid points of the dense error
GRID_POINTS = 201
#: errors below FLOOR_FACTOR x the reference's own disagreement are not resolved
FLOOR_FACTOR = 100.0


# -- data ------------------------------------------------------------------------------

@dataclass(frozen=True)
class Reference:
    """The reference positions ``q`` (len(t), n) on the grid ``t``.

    ``spread_final`` / ``spread_l2`` bound the reference's own error in the two
    measures: the disagreement of the two methods that made it, or the
    rounding of a closed form.  ``how`` says how it was made.
    """
    t: np.ndarray
    q: np.ndarray
    how: str
    spread_final: float
    spread_l2: float

    def floor(self, measure: str) -> float:
        """The smallest error this reference resolves (FLOOR_FACTOR x its spread)."""
        spread = self.spread_final if measure == "final" else self.spread_l2
        return FLOOR_FACTOR * max(spread, 1e-300)


@dataclass(frozen=True)
class Problem:
    """One initial value problem of a compiled model, with its reference.

    ``steps`` maps a fixed-step method's name (``"rk4"``) or ``"*"`` to the
    step sizes to sweep (each divides the grid spacing).
    """
    name: str
    title: str
    model: Any                        # CompiledModel
    x0: np.ndarray
    t_span: tuple
    t_eval: np.ndarray
    reference: Reference | None = None
    u: Any = None
    p: Any = None
    tolerances: tuple = ()
    steps: dict = field(default_factory=dict)
    notes: tuple = ()

    @property
    def n(self) -> int:
        return self.model.n

    def steps_for(self, method) -> tuple:
        key = getattr(method, "name", None)
        return tuple(self.steps.get(key, self.steps.get("*", ())))


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


@dataclass(frozen=True)
class Point:
    """One (method, setting) of a sweep, with its errors and costs.

    ``seconds`` is the minimum over ``repeats`` runs (the time to the failure
    for a failed run, which is run once).  ``ran`` is False when a looser
    setting of the method already exceeded the budget.
    """
    problem: str
    method: str
    family: str
    fixed_step: bool
    setting: float
    final_error: float
    l2_error: float
    seconds: float
    repeats: int
    nfev: int
    njev: int
    status: int
    message: str
    floor_final: float
    floor_l2: float
    ran: bool = True

    @property
    def ok(self) -> bool:
        return self.ran and self.status >= 0 and np.isfinite(self.final_error)

    @property
    def failed(self) -> bool:
        return self.ran and not self.ok

    def error(self, measure: str) -> float:
        return self.final_error if measure == "final" else self.l2_error

    def resolved(self, measure: str) -> bool:
        """True when the error is above the reference's floor."""
        floor = self.floor_final if measure == "final" else self.floor_l2
        return self.error(measure) >= floor

    @property
    def setting_text(self) -> str:
        return f"h={self.setting:.3g}" if self.fixed_step else f"rtol={self.setting:.3g}"


# -- tolerances and steps ---------------------------------------------------------------

def tolerance_sweep(loosest: float, tightest: float, per_decade: int = 2) -> tuple:
    """Tolerances from ``loosest`` down to ``tightest``, ``per_decade`` per decade.

    >>> [f"{tol:.3g}" for tol in tolerance_sweep(1e-3, 1e-5)]
    ['0.001', '0.000316', '0.0001', '3.16e-05', '1e-05']
    """
    a, b = math.log10(loosest), math.log10(tightest)
    count = int(round((a - b) * per_decade))
    return tuple(float(10 ** (a - k / per_decade)) for k in range(count + 1))


def steps_dividing(spacing: float, fewest: float, most: float, per_decade: int = 4) -> tuple:
    """Step sizes ``spacing / m`` for integers m from ``fewest`` to ``most`` steps
    per grid interval, about ``per_decade`` per decade, largest step first.

    >>> steps_dividing(0.1, 1, 10, per_decade=2)
    (0.1, 0.03333333333333333, 0.01)
    """
    lo, hi = math.log10(max(fewest, 1)), math.log10(most)
    count = max(int(round((hi - lo) * per_decade)), 0)
    ms = sorted({max(1, int(round(10 ** (lo + k * (hi - lo) / max(count, 1)))))
                 for k in range(count + 1)})
    return tuple(spacing / m for m in ms)


# -- methods ---------------------------------------------------------------------------

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
    """A low-overhead ``jac(t, x)`` of a compiled model for ``solve_ivp``, or None.

    Uses the generated symbolic ``<name>_jacobian`` with bound inputs and
    parameters when the model has it, else ``cm.jac`` (central differences in
    C), else None (scipy then differences the rhs itself).
    """
    fn = getattr(cm.lib, f"{cm.name}_jacobian", None)
    if fn is None:
        if hasattr(cm, "jac"):
            return lambda t, x: cm.jac(t, x, u, p)
        return None
    nx = 2 * cm.n
    ffi = cm.ffi
    p_arr, u_arr = cm.params(p).copy(), cm.input_vector(u).copy()
    x_buf = np.zeros(nx)
    ptrs = [ffi.from_buffer("double[]", a) for a in (x_buf, u_arr, p_arr)]

    def jac(t, x):
        x_buf[:] = x
        out = np.empty((nx, nx))
        status = fn(t, ptrs[0], ptrs[1], ptrs[2], ffi.from_buffer("double[]", out))
        if status:
            from modelgen.sim.runtime import MassMatrixError
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
    from scipy.integrate import solve_ivp

    def run(problem, rtol, budget):
        cm = problem.model
        f, count = _counted(cm.rhs_function(u=problem.u, p=problem.p), budget)
        options = {}
        if jac:
            j = jacobian_function(cm, problem.u, problem.p)
            if j is not None:
                options["jac"] = j
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
    """``CompiledModel.simulate(method=name)``: the integrator generated into the model's C.

    Adaptive methods take the tolerance (atol = rtol); fixed-step ones the step.
    """
    try:
        from modelgen.sim.integrate import method_of
        fixed = not method_of(name).adaptive
    except ImportError:                               # an older runtime
        fixed = name in ("rk4", "midpoint", "gauss4", "gauss2")

    def run(problem, setting, budget):
        cm = problem.model
        options = {"step": setting} if fixed else {"rtol": setting, "atol": setting}
        res = cm.simulate(problem.x0, problem.t_span, problem.t_eval, method=name,
                          u=problem.u, p=problem.p, **options,
                          max_steps=budget.max_fixed_steps if fixed else budget.max_steps)
        status = int(res.status)
        return Outcome(np.asarray(res.t), np.asarray(res.y), int(res.nfev),
                       int(getattr(res, "njev", 0)), status, str(res.message),
                       status == -1)        # MAX_STEPS

    return Method(label or f"C {name}", run, name=name, fixed_step=fixed, family="C")


#: the C integrators a default diagram shows
C_METHODS = ("dopri5", "dop853", "rodas", "rk4", "gauss4")
#: solve_ivp methods on the same compiled rhs (Radau with the model's Jacobian)
SCIPY_METHODS = (("RK45", False), ("DOP853", False), ("Radau", True))


def default_methods(cm, c_names=C_METHODS, scipy_names=SCIPY_METHODS) -> list:
    """The C methods and the scipy ones."""
    return [c_method(name) for name in c_names] + [scipy_method(name, jac=jac) for name, jac in scipy_names]


# -- running a sweep ---------------------------------------------------------------------

def _on_grid(out: Outcome, problem: Problem) -> bool:
    t = np.asarray(out.t)
    span = problem.t_span[1] - problem.t_span[0]
    return (t.shape == problem.t_eval.shape
            and np.allclose(t, problem.t_eval, rtol=0, atol=1e-9 * span))


def error_measures(out: Outcome, problem: Problem) -> tuple:
    """(final-time error, dense L2 error) of the positions against the reference.

    NaN when the run did not reach the end or produced non-finite values.
    """
    ref, n = problem.reference, problem.n
    if out.status < 0 or not _on_grid(out, problem):
        return math.nan, math.nan
    q = np.asarray(out.y)[:n].T
    if not np.all(np.isfinite(q)):
        return math.nan, math.nan
    d = q - ref.q
    return float(np.max(np.abs(d[-1]))), float(np.sqrt(np.mean(d ** 2)))


#: what a method may raise that counts as its failure (recorded, not propagated)
FAILURES = (ModelgenError, ArithmeticError, ValueError, np.linalg.LinAlgError, RuntimeError)


def _run_once(method, problem, setting, budget):
    gc_was = gc.isenabled()
    gc.disable()
    t0 = time.perf_counter()
    try:
        out = method(problem, setting, budget)
    except FAILURES as exc:
        out = Outcome(np.empty(0), np.empty((len(problem.x0), 0)), 0, 0, -100,
                      f"{type(exc).__name__}: {exc}")
    finally:
        seconds = time.perf_counter() - t0
        if gc_was:
            gc.enable()
    return out, seconds


def run_sweep(problem: Problem, methods, *, tolerances=None, steps=None, repeats: int = 5,
              time_budget: float = 1.0, budget: Budget = Budget(), warmup: bool = True,
              progress=None) -> list:
    """Run every method over its settings; returns one :class:`Point` per setting.

    Adaptive methods get ``tolerances`` (default ``problem.tolerances``),
    fixed-step ones ``steps`` (default ``problem.steps_for(method)``), from
    loose to tight.  A successful setting is repeated up to ``repeats`` times
    or until ``time_budget`` seconds are spent, keeping the minimum time; a
    failure is recorded once.  Once a setting exceeds ``budget``, the tighter
    settings of that method are listed as not run.  With ``warmup`` each
    method first runs once, untimed, at its loosest setting.

    >>> points = run_sweep(problem, [scipy_method("RK45")],
    ...                    tolerances=[1e-4, 1e-6])                 # doctest: +SKIP
    """
    if problem.reference is None:
        raise SimulationError(f"problem {problem.name}: no reference solution")
    ref = problem.reference
    floors = ref.floor("final"), ref.floor("l2")
    points = []
    for method in methods:
        label = getattr(method, "label", getattr(method, "__name__", repr(method)))
        fixed = bool(getattr(method, "fixed_step", False))
        family = getattr(method, "family", "")
        if fixed:
            settings = sorted(steps if steps is not None else problem.steps_for(method),
                              reverse=True)
        else:
            settings = sorted(tolerances if tolerances is not None else problem.tolerances,
                              reverse=True)
        if warmup and settings:        # first calls (imports, caches) are not timed
            _run_once(method, problem, settings[0], budget)
        over_budget = None
        for setting in settings:
            if over_budget is not None:
                points.append(Point(problem.name, label, family, fixed, float(setting), math.nan,
                                    math.nan, math.nan, 0, 0, 0, -1,
                                    f"not run: {over_budget}", *floors, ran=False))
                continue
            out, seconds = _run_once(method, problem, setting, budget)
            times = [seconds]
            final, l2 = error_measures(out, problem)
            ok = out.status >= 0 and np.isfinite(final)
            if out.status >= 0 and not ok:
                reason = "non-finite state" if _on_grid(out, problem) else "stopped early"
                out = out._replace(status=-101, message=f"{reason}: {out.message}")
            while ok and len(times) < repeats and sum(times) < time_budget:
                times.append(_run_once(method, problem, setting, budget)[1])
            point = Point(problem.name, label, family, fixed, float(setting), final, l2,
                          min(times), len(times), int(out.nfev), int(out.njev), int(out.status),
                          out.message, *floors)
            points.append(point)
            if out.budget:
                over_budget = f"the budget was exceeded at {point.setting_text}"
            if progress:
                progress(f"{problem.name}: {label} {point.setting_text}: "
                         + (f"final {final:.2e}, L2 {l2:.2e}, {min(times) * 1e3:.3g} ms, "
                            f"nfev {out.nfev}" if ok else f"FAILED ({out.message})"))
    return points


# -- reading a sweep ---------------------------------------------------------------------

def _curve(points, label, measure, cost):
    pts = [p for p in points if p.method == label and p.ok and p.error(measure) > 0
           and p.resolved(measure)]
    pts.sort(key=lambda p: -p.setting)                  # loose -> tight
    return [(p.error(measure), p.seconds if cost == "seconds" else p.nfev) for p in pts]


def cost_at_error(points, label: str, target: float, measure: str = "final",
                  cost: str = "seconds"):
    """Cost (``"seconds"`` or ``"nfev"``) at which ``label`` reaches the error ``target``.

    Interpolated linearly on the log-log curve (resolved points only) between
    the two settings whose errors bracket the target (the first such pair from
    loose to tight); None when the curve never crosses it or the target is
    below the reference's floor.
    """
    mine = [p for p in points if p.method == label]
    if not mine:
        return None
    floor = mine[0].floor_final if measure == "final" else mine[0].floor_l2
    if target < floor:
        return None
    curve = _curve(points, label, measure, cost)
    for (ea, ca), (eb, cb) in zip(curve, curve[1:]):
        if (ea - target) * (eb - target) <= 0 and ea != eb:
            w = (math.log(target) - math.log(ea)) / (math.log(eb) - math.log(ea))
            return math.exp(math.log(ca) + w * (math.log(cb) - math.log(ca)))
    return None


def point_at(points, label: str, setting: float):
    """The point of ``label`` at ``setting`` (relative match 1e-9), or None."""
    for p in points:
        if p.method == label and abs(p.setting - setting) <= 1e-9 * abs(setting):
            return p
    return None


# -- tables ------------------------------------------------------------------------------

CSV_COLUMNS = ("problem", "method", "family", "kind", "setting", "final_error", "l2_error",
               "seconds", "repeats", "nfev", "njev", "status", "resolved", "message")


def _csv_row(p: Point) -> list:
    return [p.problem, p.method, p.family, "step" if p.fixed_step else "rtol",
            repr(p.setting), repr(p.final_error), repr(p.l2_error), repr(p.seconds), p.repeats,
            p.nfev, p.njev, p.status, int(p.ok and p.resolved("final") and p.resolved("l2")),
            p.message]


def _fmt(value, spec=".2e"):
    return "–" if value is None or not np.isfinite(value) else format(value, spec)


def markdown_table(points) -> str:
    """One row per point: method, setting, both errors, time, repeats, nfev, njev, status.

    Errors below the reference's floor are marked with an asterisk.
    """
    lines = ["| method | setting | final error | L2 error | time [ms] | repeats | nfev | njev "
             "| status |",
             "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for p in points:
        if not p.ran:
            status = p.message
        elif p.ok:
            status = "ok"
        else:
            status = f"**FAILED** ({p.status}): {p.message}"
        star = {m: "" if not p.ok or p.resolved(m) else "*" for m in ("final", "l2")}
        lines.append(f"| {p.method} | {p.setting_text} | {_fmt(p.final_error)}{star['final']} | "
                     f"{_fmt(p.l2_error)}{star['l2']} | {_fmt(p.seconds * 1e3, '.4g')} | "
                     f"{p.repeats} | {p.nfev if p.ran else '–'} | "
                     f"{p.njev if p.ran else '–'} | {status.replace('|', '/')} |")
    return "\n".join(lines)


def describe(problem: Problem) -> str:
    """A markdown paragraph: the problem, its reference and the resolvable floors."""
    ref = problem.reference
    lines = [f"**{problem.title}** — t = {problem.t_span[0]:g} … {problem.t_span[1]:.10g} s, "
             f"n = {problem.n}, dense grid of {len(problem.t_eval)} points.",
             f"Reference: {ref.how}; its spread is {ref.spread_final:.1e} (final) and "
             f"{ref.spread_l2:.1e} (L2), so errors below {ref.floor('final'):.1e} / "
             f"{ref.floor('l2'):.1e} (marked *) are not resolved."]
    lines += list(problem.notes)
    return "\n\n".join(lines)


def write_tables(points, stem, problem: Problem | None = None) -> tuple:
    """Write ``<stem>.md`` (markdown) and ``<stem>.csv``; returns the two paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    md, csv_path = stem.with_suffix(".md"), stem.with_suffix(".csv")
    head = (f"# Work-precision: {problem.title}\n\n{describe(problem)}\n\n"
            if problem is not None else "")
    md.write_text(head + markdown_table(points) + "\n")
    with csv_path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(CSV_COLUMNS)
        for p in points:
            writer.writerow(_csv_row(p))
    return md, csv_path


# -- plotting ----------------------------------------------------------------------------

MEASURES = (("final", "final-time error of q (max over coordinates)"),
            ("l2", "dense L2 error of q (RMS over the grid)"))
COSTS = (("seconds", "wall time [s] (minimum over repeats)"),
         ("nfev", "rhs evaluations"))


#: a C method and its scipy counterpart share a colour (C solid, scipy dashed)
COLOR_SLOTS = {"dopri5": 0, "rk45": 0, "dop853": 1, "rodas": 2, "radau": 2, "rk4": 3,
               "gauss4": 4, "midpoint": 5, "bdf": 6, "lsoda": 7}


def _colors(labels, palette) -> dict:
    free = iter([i for i in range(len(palette)) if i not in COLOR_SLOTS.values()] * 4)
    out = {}
    for label in labels:
        slot = COLOR_SLOTS.get(label.split()[-1].lower())
        out[label] = palette[(slot if slot is not None else next(free, 9)) % len(palette)]
    return out


def plot_work_precision(points, problem: Problem, path, title: str | None = None) -> Path:
    """Four log-log panels: (final, dense L2 error) x (wall time, rhs evaluations).

    One line per method (C solid and filled, scipy dashed and hollow; squares
    for fixed-step methods; a C method and its scipy counterpart share a
    colour).  Points below the reference's floor (grey band, "unresolved")
    are drawn faint and off their line; failures are ``x`` in the red
    "failed" band at the right, at the time / evaluations they used.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(dict.fromkeys(p.method for p in points))
    colors = _colors(labels, plt.get_cmap("tab10").colors)
    finite = [p.error(m) for p in points if p.ok for m in ("final", "l2") if p.error(m) > 0]
    if finite:
        lo, hi = min(finite), max(finite)
    else:
        lo, hi = 1e-12, 1.0
    ref = problem.reference
    lo = min(lo / 3, ref.floor("l2") / 100, ref.floor("final") / 100)
    fail_x = 10 ** (math.ceil(math.log10(hi)) + 1)
    fig, axes = plt.subplots(2, 2, figsize=(13, 10), sharex="row")
    for r, (measure, xlabel) in enumerate(MEASURES):
        for c, (cost, ylabel) in enumerate(COSTS):
            ax = axes[r, c]
            floor = ref.floor(measure)
            ax.axvspan(lo, floor, color="0.88", zorder=0)
            ax.text(lo * 1.3, 0.985, "unresolved", transform=ax.get_xaxis_transform(),
                    ha="left", va="top", fontsize=7, color="0.3")
            ax.axvspan(fail_x / 4, fail_x * 4, color="#fde0dc", zorder=0)
            ax.text(fail_x, 0.98, "failed", transform=ax.get_xaxis_transform(), ha="center",
                    va="top", fontsize=8, color="#b2182b")
            for i, label in enumerate(labels):
                mine = [p for p in points if p.method == label and p.ran]
                if not mine:
                    continue
                color = colors[label]
                scipy_like = mine[0].family == "scipy"
                marker = "s" if mine[0].fixed_step else "o"
                good = sorted((p for p in mine if p.ok and p.error(measure) > 0),
                              key=lambda p: -p.setting)
                resolved = [p for p in good if p.resolved(measure)]
                value = (lambda p: p.seconds) if cost == "seconds" else (lambda p: p.nfev)
                ax.plot([p.error(measure) for p in resolved], [value(p) for p in resolved],
                        ls="--" if scipy_like else "-", marker=marker, color=color, ms=5,
                        mfc="white" if scipy_like else color, label=label, lw=1.4)
                under = [p for p in good if not p.resolved(measure)]
                ax.plot([p.error(measure) for p in under], [value(p) for p in under],
                        ls="none", marker=marker, color=color, ms=5, mfc="none", alpha=0.6)
                bad = [p for p in mine if p.failed]
                jitter = np.exp(0.25 * (i - len(labels) / 2) / len(labels))
                ax.plot([fail_x * jitter] * len(bad), [max(value(p), 1e-9) for p in bad],
                        ls="none", marker="x", color=color, ms=8, mew=2)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(lo, fail_x * 4)
            ax.grid(True, which="major", alpha=0.4)
            ax.grid(True, which="minor", alpha=0.1)
            ax.set_xlabel(xlabel)
            ax.set_ylabel(ylabel)
    handles, names = axes[0, 0].get_legend_handles_labels()
    from matplotlib.lines import Line2D
    handles.append(Line2D([], [], ls="none", marker="x", color="k", mew=2))
    names.append("failed (time / evaluations used)")
    fig.legend(handles, names, loc="lower center", ncol=5, fontsize=9, frameon=False)
    import textwrap
    heading = title or (f"Work-precision: {problem.title}\n"
                        + textwrap.fill(f"reference: {ref.how}", 150))
    fig.suptitle(heading, fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 0.96 - 0.015 * heading.count("\n")))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# -- references --------------------------------------------------------------------------

def _spreads(qa, qb) -> tuple:
    d = np.asarray(qa, dtype=float) - np.asarray(qb, dtype=float)
    return float(np.max(np.abs(d[-1]))), float(np.sqrt(np.mean(d ** 2)))


def reference_from_methods(problem: Problem, methods=None, tolerance: float = 1e-14,
                           budget: Budget = Budget(max_nfev=5_000_000, max_seconds=300,
                                                   max_steps=50_000_000)) -> Reference:
    """The first method's solution at rtol = atol = ``tolerance``, and its spread:
    the disagreement with the second method at the same tolerance.

    Default: C dop853 and C rodas (explicit order 8 against linearly implicit
    order 4).
    """
    if methods is None:
        methods = [c_method("dop853"), c_method("rodas")]
    sols = []
    for method in methods:
        out = method(problem, tolerance, budget)
        if out.status < 0 or not _on_grid(out, problem):
            raise SimulationError(f"problem {problem.name}: reference by {method.label} at "
                                  f"{tolerance:g} failed: {out.message}")
        sols.append(np.asarray(out.y)[:problem.n].T)
    spread = _spreads(sols[0], sols[1])
    how = (f"{methods[0].label} at rtol = atol = {tolerance:g}, checked against "
           f"{methods[1].label} at the same tolerance")
    return Reference(problem.t_eval.copy(), sols[0], how, *spread)


def linear_reference(cm, x0, t, u=None, p=None, digits: int = 40) -> Reference:
    """Closed form of a linear (affine) model: x(t) = x0 + [expm(M t)]_top [0..0, 1],
    M = [[J, f(x0)], [0, 0]], with J the model's symbolic Jacobian, computed with
    mpmath to ``digits`` digits on the uniform grid ``t``.

    Raises :class:`SimulationError` when the compiled rhs is not affine near x0
    (checked at seeded random states).
    """
    import mpmath
    x0 = np.asarray(x0, dtype=float)
    nx = len(x0)
    jac = jacobian_function(cm, u, p) if hasattr(cm.lib, f"{cm.name}_jacobian") else None
    if jac is None:
        raise SimulationError(f"{cm.name}: linear_reference needs the symbolic Jacobian "
                              f"(differences are good to ~1e-10 only); load the model with "
                              f"jacobian=True")
    J = jac(t[0], x0)
    f0 = cm.rhs(t[0], x0, u, p)
    rng = np.random.default_rng(1)
    for _ in range(5):
        dx = rng.normal(size=nx) * 1e-2 * (1 + np.abs(x0))
        want = f0 + J @ dx
        got = cm.rhs(t[0], x0 + dx, u, p)
        scale = np.abs(f0) + np.abs(J) @ np.abs(dx)
        if np.any(np.abs(got - want) > 1e-11 * scale + 1e-300):
            raise SimulationError(f"{cm.name}: the rhs is not affine near x0, so it has no "
                                  f"matrix-exponential closed form")
    spacing = np.diff(t)
    if not np.allclose(spacing, spacing[0], rtol=1e-9, atol=0):
        raise SimulationError("linear_reference needs a uniform grid")
    with mpmath.workdps(digits):
        M = mpmath.zeros(nx + 1, nx + 1)
        for i in range(nx):
            for j in range(nx):
                M[i, j] = mpmath.mpf(J[i, j])
            M[i, nx] = mpmath.mpf(f0[i])
        h = (mpmath.mpf(t[-1]) - mpmath.mpf(t[0])) / (len(t) - 1)
        E = mpmath.expm(M * h)
        z = mpmath.zeros(nx + 1, 1)
        z[nx] = 1
        rows = [np.zeros(nx)]
        for _ in range(len(t) - 1):
            z = E * z
            rows.append(np.array([float(z[i]) for i in range(nx)]))
    x = x0 + np.array(rows)
    n = nx // 2
    rounding = 4 * np.finfo(float).eps * float(np.max(np.abs(x[:, :n])))
    # how far the compiled rhs (rounding included) is from the linear map it is solved for
    residual = max(float(np.max(np.abs(cm.rhs(ti, xi, u, p) - f0 - J @ (xi - x0))))
                   for ti, xi in zip(t, x))
    return Reference(np.asarray(t, dtype=float).copy(), x[:, :n],
                     f"closed form of the linear system, expm([[J, f(x0)], [0, 0]] t) with "
                     f"mpmath ({digits} digits); along it the compiled rhs differs from the "
                     f"linear map by up to {residual:.1e} (its rounding)", rounding, rounding)


# -- extended precision (chaotic problems) -----------------------------------------------

def extended_rhs(spec, p, u):
    """``f(t, x)`` in numpy long double (80-bit on x86: eps 1.1e-19) from the model's
    closed-form equations (:class:`modelgen.derive.queries.Mechanism`): A(q) qdd = tau - h.

    For small models (the closed forms grow quickly with n); ``p`` and ``u`` are
    the parameter and input vectors of the compiled model.
    """
    import sympy

    from modelgen.derive.queries import Mechanism
    from modelgen.model.spec import TIME
    LD = np.longdouble
    mech = Mechanism(spec, simplify=False)
    A = mech.mass_matrix()
    b = mech.generalized_forces() - mech.velocity_terms()
    n = len(spec.coordinates)
    exprs = [A[i, j] for i in range(n) for j in range(i + 1)] + list(b)
    # rationals would be printed as Python float divisions: pass them as long doubles
    rationals = sorted({r for e in exprs for r in e.atoms(sympy.Rational) if not r.is_Integer},
                       key=lambda r: (r.p, r.q))
    r_syms = sympy.symbols(f"_r0:{len(rationals)}")
    exprs = [e.xreplace(dict(zip(rationals, r_syms))) for e in exprs]
    args = ([sympy.Symbol(c) for c in spec.coordinates]
            + [sympy.Symbol(c + "_dot") for c in spec.coordinates]
            + [sympy.Symbol(name) for name, _ in spec.parameters]
            + [sympy.Symbol(name) for name in spec.inputs] + list(r_syms) + [TIME])
    known = set(args)
    unknown = {s for e in exprs for s in e.free_symbols} - known
    if unknown:
        raise SimulationError(f"{spec.name}: extended_rhs cannot bind {sorted(map(str, unknown))}")
    fn = sympy.lambdify(args, exprs, modules="numpy", cse=True)
    consts = ([LD(v) for v in np.asarray(p, dtype=float)]
              + [LD(v) for v in np.asarray(u, dtype=float)]
              + [LD(r.p) / LD(r.q) for r in rationals])
    m = n * (n + 1) // 2

    def f(t, x):
        vals = fn(*x, *consts, LD(t))
        L = [[LD(0)] * n for _ in range(n)]
        k = 0
        for i in range(n):                       # Cholesky of A, row by row
            for j in range(i + 1):
                s = vals[k] - sum((L[i][c] * L[j][c] for c in range(j)), LD(0))
                L[i][j] = np.sqrt(s) if i == j else s / L[j][j]
                k += 1
        y = [LD(0)] * n
        for i in range(n):
            y[i] = (vals[m + i] - sum((L[i][c] * y[c] for c in range(i)), LD(0))) / L[i][i]
        z = [LD(0)] * n
        for i in reversed(range(n)):
            z[i] = (y[i] - sum((L[c][i] * z[c] for c in range(i + 1, n)), LD(0))) / L[i][i]
        return np.array([*x[n:], *z], dtype=LD)
    return f


def _error_scale(x, xn, tol):
    return tol + tol * np.maximum(np.abs(x), np.abs(xn))


def dop853_extended(f, x0, grid, tol: float = 1e-17, max_steps: int = 1_000_000):
    """Dormand-Prince 8(5,3) with Hairer's error estimate, in long double, stepping
    exactly onto every grid point; returns (states (len(grid), nx), nfev).

    The tableau is scipy's (``dop853_coefficients``, given there to 30 digits
    and stored as doubles, i.e. good to ~1e-17).
    """
    from scipy.integrate._ivp import dop853_coefficients as D
    LD = np.longdouble
    A, B, C = D.A[:12, :12].astype(LD), D.B.astype(LD), D.C[:12].astype(LD)
    E3, E5 = D.E3.astype(LD), D.E5.astype(LD)
    tol = LD(tol)
    x = np.array(x0, dtype=LD)
    K = np.empty((13, x.size), dtype=LD)
    out, nfev, steps = [x.copy()], 0, 0
    t, h = LD(grid[0]), LD(grid[1] - grid[0]) / 10
    for t_next in grid[1:]:
        t_next = LD(t_next)
        while t < t_next:
            steps += 1
            if steps > max_steps:
                raise SimulationError(f"dop853_extended: more than {max_steps} steps "
                                      f"at t={float(t)}")
            last = t + h >= t_next
            hs = t_next - t if last else h
            K[0] = f(t, x)
            for s in range(1, 12):
                K[s] = f(t + C[s] * hs, x + hs * (A[s, :s] @ K[:s]))
            xn = x + hs * (B @ K[:12])
            K[12] = f(t + hs, xn)
            nfev += 13
            sc = _error_scale(x, xn, tol)
            e5, e3 = (K.T @ E5) / sc, (K.T @ E3) / sc
            e5n, e3n = np.sum(e5 ** 2), np.sum(e3 ** 2)
            den = e5n + LD(0.01) * e3n
            err = abs(hs) * e5n / np.sqrt(den * x.size) if den > 0 else LD(0)
            fac = LD(6) if err == 0 else min(LD(6), max(LD(1) / 3, LD(0.9) * err ** LD(-1 / 8)))
            if err <= 1:
                t, x = (t_next if last else t + hs), xn
                if not last:
                    h = hs * fac
            else:
                h = hs * min(fac, LD(1))
        out.append(x.copy())
    return np.array(out), nfev


def gbs_extended(f, x0, grid, tol: float = 1e-17, k: int = 8, max_steps: int = 200_000):
    """Gragg-Bulirsch-Stoer extrapolation (modified midpoint, n = 2, 4, ..., 2k, order
    2k) in long double, stepping exactly onto every grid point; returns
    (states (len(grid), nx), nfev).  Exact rational coefficients throughout."""
    LD = np.longdouble
    seq = [2 * (j + 1) for j in range(k)]
    tol = LD(tol)
    x = np.array(x0, dtype=LD)
    out, nfev, steps = [x.copy()], 0, 0
    t, H = LD(grid[0]), LD(grid[1] - grid[0])
    expo = LD(-1) / (2 * k - 1)
    for t_next in grid[1:]:
        t_next = LD(t_next)
        while t < t_next:
            steps += 1
            if steps > max_steps:
                raise SimulationError(f"gbs_extended: more than {max_steps} steps at t={float(t)}")
            last = t + H >= t_next
            Hs = t_next - t if last else H
            f0 = f(t, x)
            nfev += 1
            table = []
            for j, nj in enumerate(seq):
                hh = Hs / nj
                z0, z1 = x, x + hh * f0
                for i in range(1, nj):
                    z0, z1 = z1, z0 + 2 * hh * f(t + i * hh, z1)
                row = [(z0 + z1 + hh * f(t + Hs, z1)) / 2]
                nfev += nj
                for col in range(1, j + 1):
                    ratio = LD(nj * nj) / LD(seq[j - col] ** 2)
                    row.append(row[col - 1] + (row[col - 1] - table[j - 1][col - 1]) / (ratio - 1))
                table.append(row)
            xn = table[-1][-1]
            err = np.sqrt(np.mean(((xn - table[-1][-2]) / _error_scale(x, xn, tol)) ** 2))
            fac = LD(4) if err == 0 else min(LD(4), max(LD(0.25), LD(0.8) * err ** expo))
            if err <= 1:
                t, x = (t_next if last else t + Hs), xn
                if not last:
                    H = Hs * fac
            else:
                H = Hs * min(fac, LD(0.5))
        out.append(x.copy())
    return np.array(out), nfev


def extended_reference(spec, problem: Problem, tol: float = 1e-17) -> Reference:
    """Reference from two different high-order methods in long double (DOP853 and
    GBS extrapolation of order 16) on the model's closed-form equations, for
    chaotic problems whose double-precision references disagree too early.
    """
    f = extended_rhs(spec, problem.model.params(problem.p), problem.model.input_vector(problem.u))
    n = problem.n
    check = np.random.default_rng(3).normal(size=(3, 2 * n))
    for x in check:                  # the closed form must be the compiled model
        a = f(0.0, x.astype(np.longdouble)).astype(float)
        b = problem.model.rhs(0.0, x, problem.u, problem.p)
        if np.max(np.abs(a - b)) > 1e-11 * max(np.max(np.abs(b)), 1.0):
            raise SimulationError(f"{spec.name}: the closed-form rhs differs from the "
                                  f"compiled one by {np.max(np.abs(a - b)):.2e}")
    xa, _ = dop853_extended(f, problem.x0, problem.t_eval, tol)
    xb, _ = gbs_extended(f, problem.x0, problem.t_eval, tol)
    qa, qb = xa[:, :n].astype(float), xb[:, :n].astype(float)
    spread = _spreads(qa, qb)
    return Reference(problem.t_eval.copy(), qa,
                     f"DOP853 in long double at rtol = atol = {tol:g}, checked against GBS "
                     f"extrapolation (order 16) in long double, on the closed-form equations",
                     *spread)


# -- problems ----------------------------------------------------------------------------

def _scene_model(scene_path, build_root):
    """(SceneSpec, CompiledModel built with the symbolic Jacobian)."""
    from modelgen.sim.load import load
    from modelgen.model.scene import load_scene
    scene_path = Path(scene_path)
    if not scene_path.is_file():
        raise SimulationError(f"scene file {scene_path} not found (the standard set needs "
                              f"a source checkout with models/scenes)")
    spec = load_scene(scene_path)
    if build_root is None:
        from modelgen.codegen.pipeline import DEFAULT_OUTPUT
        build_root = DEFAULT_OUTPUT / "workprecision"
    cm = load(spec.model, Path(build_root) / spec.name, jacobian=spec.model.n <= 12)
    return spec, cm


def _constant_inputs(spec):
    if not spec.inputs:
        return None
    sampled = [sig.name for sig in spec.inputs if sig.constant is None]
    if sampled:
        raise SimulationError(f"scene {spec.name}: work-precision diagrams need constant "
                              f"inputs; {', '.join(sampled)} are sampled in time")
    return {sig.name: sig.constant for sig in spec.inputs}


def _grid(t0, t1, points=GRID_POINTS):
    return np.linspace(t0, t1, points)


def pendulum_problem(build_root=None, periods: int = 4, quick: bool = False) -> Problem:
    """Simple pendulum released from rest at 90 degrees (L = 1, g = 9.81), over
    ``periods`` periods T = 4 sqrt(L/g) K(sin^2(45 deg)) = 2.367841947576237 s.

    Closed-form reference: theta(t) = 2 asin(k sn(K - w t | k^2)) with mpmath
    (30 digits) on the grid; after whole periods it is exactly the release
    angle.  scipy's ``ellipj`` gives the same to ~1e-14 (checked).
    """
    import mpmath
    from scipy.special import ellipj, ellipk
    spec, cm = _scene_model(SCENES / "simple_pendulum_swing.yaml", build_root)
    theta0, omega0 = spec.initial
    if omega0 != 0:
        raise SimulationError("pendulum_problem: the scene must release from rest")
    L, g = cm.parameters["L"], cm.parameters["g"]
    k = math.sin(theta0 / 2)
    period = 4 * math.sqrt(L / g) * float(ellipk(k * k))
    t = _grid(0.0, periods * period)
    with mpmath.workdps(30):
        mk = mpmath.sin(mpmath.mpf(theta0) / 2)
        mK, w = mpmath.ellipk(mk ** 2), mpmath.sqrt(mpmath.mpf(g) / mpmath.mpf(L))
        q = np.array([float(2 * mpmath.asin(mk * mpmath.ellipfun("sn", mK - w * mpmath.mpf(ti),
                                                                   m=mk ** 2))) for ti in t])
    q[-1] = theta0                          # whole periods: back at the release angle
    sn = ellipj(float(ellipk(k * k)) - math.sqrt(g / L) * t, k * k)[0]
    check = float(np.max(np.abs(2 * np.arcsin(k * sn) - q)))
    rounding = 4 * np.finfo(float).eps * float(np.max(np.abs(q)))
    ref = Reference(t, q[:, None], f"closed form θ(t) = 2 asin(k sn(K − ωt | k²)) in mpmath "
                    f"(scipy ellipj agrees to {check:.0e}); θ(T) = θ0 after whole periods",
                    rounding, rounding)
    tols = tolerance_sweep(1e-3, 1e-12, 1 if quick else 2)
    spacing = t[1] - t[0]
    steps = {"*": steps_dividing(spacing, 1, 1000, 2 if quick else 4)}
    return Problem("pendulum", f"simple pendulum released from horizontal, {periods} periods",
                   cm, np.array(spec.initial), (0.0, float(t[-1])), t, ref, tolerances=tols,
                   steps=steps,
                   notes=(f"Period T = {period!r} s (L = {L:g} m, g = {g:g} m/s²). The final "
                          f"time is a turning point (θ' = 0), so a phase error δt shows in "
                          f"θ(T) only as θ''δt²/2; the dense L2 error sees it at first "
                          f"order.",))


def double_pendulum_problem(build_root=None, t_end: float = 10.0, quick: bool = False,
                            reference: bool = True) -> Problem:
    """The free double pendulum (scene dp_free: q1 = 1, q2 = 0.5 from rest) over 10 s.

    It is chaotic here (the outer rod turns over; errors grow about e^t), so two
    double-precision methods at 1e-13 disagree by ~1e-10 at 10 s; the reference
    is made in long double instead (:func:`extended_reference`).
    """
    spec, cm = _scene_model(SCENES / "dp_free.yaml", build_root)
    t = _grid(0.0, t_end)
    tols = tolerance_sweep(1e-4, 1e-13, 1 if quick else 2)
    steps = {"*": steps_dividing(t[1] - t[0], 2, 2000, 2 if quick else 4)}
    problem = Problem("double_pendulum", f"double pendulum (dp_free), {t_end:g} s", cm,
                      np.array(spec.initial), (0.0, t_end), t, None,
                      u=_constant_inputs(spec), tolerances=tols, steps=steps)
    if reference:
        problem = replace(problem, reference=extended_reference(spec.model, problem))
    return problem


def arm_problem(build_root=None, t_end: float = 5.0, quick: bool = False) -> Problem:
    """The 7-joint arm falling under gravity with joint damping (scene arm7_damped), 5 s.

    Reference: two high-order methods at 1e-14 (:func:`reference_from_methods`).
    """
    spec, cm = _scene_model(SCENES / "arm7_damped.yaml", build_root)
    t = _grid(0.0, t_end)
    tols = tolerance_sweep(1e-3, 1e-10, 1 if quick else 2)
    steps = {"*": steps_dividing(t[1] - t[0], 1, 1000, 2 if quick else 4)}
    problem = Problem("arm7", f"7-joint arm with joint damping (arm7_damped), {t_end:g} s", cm,
                      np.array(spec.initial), (0.0, t_end), t, None, u=_constant_inputs(spec),
                      tolerances=tols, steps=steps)
    return replace(problem, reference=reference_from_methods(problem))


def stiff_chain_problem(build_root=None, quick: bool = False) -> Problem:
    """The stiff spring chain (scene spring_chain_stiff, 2 s): masses 1 and 2 joined
    by a spring 1e6 times stiffer than the others with a stiff damper beside it,
    so the Jacobian's eigenvalues run from -2e7 to -0.03 1/s.

    The system is linear, so the reference is its matrix exponential
    (:func:`linear_reference`).  RK4 is swept around its stability limit
    (h ~ 1.4e-7 s); the implicit fixed-step methods from the grid spacing.
    """
    spec, cm = _scene_model(SCENES / "spring_chain_stiff.yaml", build_root)
    t = _grid(spec.t_start, spec.t_end)
    x0 = np.array(spec.initial)
    ref = linear_reference(cm, x0, t)
    eig = np.linalg.eigvals(cm.jac(0.0, x0))
    lo, hi = np.min(np.abs(eig)), np.max(np.abs(eig))
    tols = tolerance_sweep(1e-3, 1e-10, 1 if quick else 2)
    spacing = t[1] - t[0]
    per = 2 if quick else 4
    steps = {"rk4": steps_dividing(spacing, 10 ** 4.5, 10 ** 5, per),
             "*": steps_dividing(spacing, 1, 1000, per)}
    return Problem("stiff_chain", f"stiff spring chain (spring_chain_stiff), {spec.t_end:g} s",
                   cm, x0, (spec.t_start, spec.t_end), t, ref, tolerances=tols, steps=steps,
                   notes=(f"Eigenvalues of the Jacobian: |λ| from {lo:.3g} to {hi:.3g} 1/s "
                          f"(ratio {hi / lo:.1e}); real parts from "
                          f"{-np.max(np.abs(eig.real)):.3g} to "
                          f"{-np.min(np.abs(eig.real)):.3g} 1/s.",))


#: the standard set, by name
STANDARD = {"pendulum": pendulum_problem, "double_pendulum": double_pendulum_problem,
            "arm7": arm_problem, "stiff_chain": stiff_chain_problem}


def scene_problem(scene_path, build_dir=None, *, quick: bool = False,
                  tolerance: float = 1e-14) -> Problem:
    """A work-precision problem from any scene: its initial state and time span,
    constant inputs, a 201-point grid, and a reference by two high-order methods
    (:func:`reference_from_methods`).  Fixed steps go from 10x to 1/10 of the
    scene's integrator step.
    """
    from modelgen.sim.load import load
    from modelgen.model.scene import load_scene
    spec = load_scene(scene_path)
    if build_dir is None:
        from modelgen.codegen.pipeline import DEFAULT_OUTPUT
        build_dir = DEFAULT_OUTPUT / "workprecision" / spec.name
    cm = load(spec.model, build_dir, jacobian=spec.model.n <= 12)
    t = _grid(spec.t_start, spec.t_end)
    spacing = t[1] - t[0]
    per_interval = spacing / spec.step
    steps = {"*": steps_dividing(spacing, max(per_interval / 10, 1), max(per_interval * 10, 10),
                                 2 if quick else 4)}
    tols = tolerance_sweep(1e-3, 1e-10, 1 if quick else 2)
    problem = Problem(spec.name, f"scene {spec.name}", cm, np.array(spec.initial),
                      (spec.t_start, spec.t_end), t, None, u=_constant_inputs(spec),
                      tolerances=tols, steps=steps)
    return replace(problem, reference=reference_from_methods(problem, tolerance=tolerance))
