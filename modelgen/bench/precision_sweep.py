"""The sweep runner: every method over its settings, with errors, costs and failures.

* **errors** on the positions q: the final-time error ``max_i |q_i(T) -
  q_ref,i(T)|`` and a dense L2 error ``sqrt(mean_k mean_i (q_i(t_k) -
  q_ref,i(t_k))^2)`` on the problem's fixed grid ``t_k``;
* adaptive methods are swept over tolerances (atol = rtol), fixed-step
  methods over step sizes that divide the grid spacing, on the same axes;
* **cost**: the minimum wall time over repeats, and the number of rhs
  evaluations (hardware-independent);
* **failures** (a status < 0, an exception, a budget exceeded) are kept as
  points, never dropped.

>>> points = run_sweep(problem, default_methods(),
...                    tolerances=[1e-4, 1e-6, 1e-8])               # doctest: +SKIP
>>> cost_at_error(points, "C dop853", 1e-8)                         # doctest: +SKIP
"""
from __future__ import annotations

import gc
import math
import time
from dataclasses import dataclass

import numpy as np

from modelgen.bench.methods import Budget, Outcome, on_grid
from modelgen.bench.problem import Problem
from modelgen.errors import ModelgenError, SimulationError


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


def error_measures(out: Outcome, problem: Problem) -> tuple:
    """(final-time error, dense L2 error) of the positions against the reference.

    NaN when the run did not reach the end or produced non-finite values.
    """
    ref, n = problem.reference, problem.n
    if out.status < 0 or not on_grid(out, problem):
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
                reason = "non-finite state" if on_grid(out, problem) else "stopped early"
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


