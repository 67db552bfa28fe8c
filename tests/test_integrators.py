"""The integrators of mg_integrate.c, driven through a model's mg_system.

References are independent of the code under test: the pendulum's closed form
(Jacobi elliptic functions), its elliptic-integral period, scipy's solve_ivp,
numpy finite differences, and conserved energy.
"""
from __future__ import annotations

import re
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.integrate
from scipy.special import ellipj, ellipk

from modelgen.codegen import capi
from modelgen.codegen.capi import STOP_X
from modelgen.sim import integrate
from modelgen.errors import SimulationError

MODELS = Path(__file__).resolve().parent.parent / "models"
G = 9.81
PERIOD_90 = 2.367841947576237          # L = 1, g = 9.81, released from horizontal
ADAPTIVE = ("dopri5", "dop853", "rodas")
ALL_METHODS = ("rk4", "dopri5", "dop853", "rodas", "midpoint", "gauss4")
#: the published order of each step and of the continuous extension its t_eval and
#: events use, written out here rather than read from the table under test: RK4 4;
#: Dormand-Prince 5(4) 5 with Shampine's dense output 4 and DOP853 8 with its dense
#: output 7 (Hairer, Norsett & Wanner, Solving ODEs I, II.5-II.6); RODAS4 4 with its
#: dense output 3 (Hairer & Wanner, Solving ODEs II, IV.7); the implicit midpoint rule
#: 2 and the 2-stage Gauss-Legendre method 4; rk4, midpoint and gauss4 sample through
#: the cubic Hermite interpolant of x and xdot at the step ends (3)
ORDER = {"rk4": 4, "dopri5": 5, "dop853": 8, "rodas": 4, "midpoint": 2, "gauss4": 4}
DENSE_ORDER = {"rk4": 3, "dopri5": 4, "dop853": 7, "rodas": 3, "midpoint": 3, "gauss4": 3}


@pytest.fixture(scope="module")
def sp(compiled):
    return compiled("simple_pendulum")


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


@pytest.fixture(scope="module")
def dp_crba(build_root):
    """The double pendulum with the crba rhs, whose failures name the Cholesky pivot."""
    import modelgen
    return modelgen.load(MODELS / "double_pendulum.yaml", build_root / "double_pendulum_crba",
                         formulation="crba")


@pytest.fixture(scope="module")
def symbolic(build_root):
    """The two pendulums generated with the symbolic Jacobian <name>_jacobian, which the
    implicit methods then use instead of central differences."""
    import modelgen
    return {name: modelgen.load(MODELS / f"{name}.yaml", build_root / f"{name}_jacobian",
                                jacobian=True)
            for name in ("simple_pendulum", "double_pendulum")}


DRIVEN = """\
name: driven_pendulum
description: Simple pendulum driven by the torque A sin(w t) about its hinge.
coordinates: [q]
parameters: {L: 1.0, m: 1.0, g: 9.81, A: 5.0, w: 3.0}
bases:
  B1: {parent: E, axis: 3, angle: q}
points:
  P: {from: O, base: B1, coordinates: [0, -L, 0]}
bodies:
  bob: {mass: m, G: P, base: B1}
gravity: [0, -g, 0]
actions:
  drive: {body: bob, point: O, base: E, torque: [0, 0, A*sin(w*t)]}
"""


@pytest.fixture(scope="module")
def driven(build_root):
    """A non-autonomous model: xdot depends on t (Rosenbrock needs d xdot / d t)."""
    import modelgen
    path = build_root / "driven_pendulum.yaml"
    path.write_text(DRIVEN)
    return modelgen.load(path, build_root / "driven_pendulum")


def pendulum_exact(q0, t):
    """x(t) of the pendulum (L = 1) released at rest from q0:
    q = 2 asin(k sn(K - w t)), qdot = -2 k w cn(K - w t), k = sin(q0/2)."""
    w, k = np.sqrt(G), np.sin(q0 / 2)
    sn, cn, _, _ = ellipj(ellipk(k * k) - w * np.asarray(t), k * k)
    return np.array([2 * np.arcsin(k * sn), -2 * k * w * cn])


def fixed_step(method):
    return {} if method in ADAPTIVE else {"step": 1e-3}


# -- order -----------------------------------------------------------------------------

#: largest step of each method's sweep (then h/2, h/4, h/8): inside the asymptotic
#: range and above round-off (dop853's smallest error is about 1e-14)
SWEEP = {"rk4": 0.05, "dopri5": 0.05, "dop853": 0.25, "rodas": 0.05, "midpoint": 0.05,
         "gauss4": 0.1}


def _observed_order(sp, method, theta):
    """Least-squares slope of log(RMS error) against log(h) over four fixed steps;
    samples at fraction theta of each step (0: the step points themselves)."""
    q0, T = 1.0, 2.0
    hs = SWEEP[method] / 2.0 ** np.arange(4)
    errors = []
    for h in hs:
        n = int(round(T / h))
        t = (np.arange(n) + theta) * h if theta else np.linspace(0, T, 9)
        res = sp.simulate([q0, 0.0], (0, T), t_eval=t, method=method, step=h)
        assert res.success and res.naccept == n
        errors.append(np.sqrt(np.mean((res.y - pendulum_exact(q0, t)) ** 2)))
    return np.polyfit(np.log(hs), np.log(errors), 1)[0]


def test_the_method_table_states_the_published_orders():
    assert set(integrate.METHODS) == set(ALL_METHODS)
    for name, m in integrate.METHODS.items():
        assert (m.order, m.dense_order) == (ORDER[name], DENSE_ORDER[name]), name


@pytest.mark.parametrize("method", ALL_METHODS)
def test_fixed_step_convergence_order_matches_the_nominal_order(sp, method):
    """Adaptive methods run with fixed steps (step=) for this; error at t = 0, 0.25 .. 2."""
    order = _observed_order(sp, method, 0.0)
    assert abs(order - ORDER[method]) <= 0.3, order


@pytest.mark.parametrize("method", ALL_METHODS)
def test_fixed_step_order_holds_for_a_time_dependent_right_hand_side(driven, method):
    """Stages at t + c_i h see the inputs of their own time, and rodas its
    d xdot / d t term.  Reference: scipy's DOP853 at 1e-13 (its own error, about
    8e-14 RMS, is the floor).  dop853 is still superconvergent on this problem
    (measured slopes 8.8 over h = 0.4, 0.2, 0.1, errors 1.6e-5, 3.5e-8, 7.6e-11; at
    h = 0.05, 1.5e-13, the reference's error shows), so it runs those three steps
    and its slope is bounded below only: a wrong stage time c_i gives order 1."""
    T, x0, t = 2.0, [1.0, 0.0], np.linspace(0, 2.0, 9)
    ref = scipy.integrate.solve_ivp(driven.rhs, (0, T), x0, method="DOP853", rtol=1e-13,
                                    atol=1e-13, t_eval=t)
    hs = 0.4 / 2.0 ** np.arange(3) if method == "dop853" else SWEEP[method] / 2.0 ** np.arange(4)
    errors = [np.sqrt(np.mean((driven.simulate(x0, (0, T), t_eval=t, method=method,
                                               step=h).y - ref.y) ** 2)) for h in hs]
    order = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    if method == "dop853":
        assert order >= 7.7 and errors[-1] < 1e-9, (order, errors)
    else:
        assert abs(order - ORDER[method]) <= 0.3, order


@pytest.mark.parametrize("method", ALL_METHODS)
def test_dense_output_converges_at_the_order_of_step_or_interpolant(sp, method):
    """Samples at 37% of every step: the error is O(h^min(p, q + 1)) for a method of
    order p with a continuous extension of order q (dopri5 4, dop853 7, the others 3)."""
    order = _observed_order(sp, method, 0.37)
    assert abs(order - min(ORDER[method], DENSE_ORDER[method] + 1)) <= 0.3, order


@pytest.mark.parametrize("method", ADAPTIVE)
def test_adaptive_error_is_proportional_to_the_tolerance(sp, method):
    """Tolerance sweep 1e-5 .. 1e-11: the global error follows tol^(1 +- 0.15) and stays
    within [0.3, 100] x tol; the work grows as the tolerance tightens."""
    q0, t = 1.0, np.linspace(0, 5, 51)
    tols = 10.0 ** -np.arange(5, 11.5, 1.0)
    errors, work = [], []
    for tol in tols:
        res = sp.simulate([q0, 0.0], (0, 5), t_eval=t, method=method, rtol=tol, atol=tol)
        assert res.success
        errors.append(np.max(np.abs(res.y - pendulum_exact(q0, t))))
        work.append(res.nfev)
    errors = np.array(errors)
    slope = np.polyfit(np.log(tols), np.log(errors), 1)[0]
    assert abs(slope - 1) <= 0.15, slope
    assert np.all(errors < 100 * tols) and np.all(errors > 0.3 * tols), errors / tols
    assert np.all(np.diff(work) > 0), work


# -- events ------------------------------------------------------------------------------

def _upward_zero(t, x):
    return x[0]


_upward_zero.direction = 1


@pytest.mark.parametrize("method", ADAPTIVE + ("rodas, symbolic Jacobian",))
def test_pendulum_period_by_event_detection_matches_the_elliptic_integral(sp, symbolic,
                                                                          method):
    """Released from horizontal, q passes 0 upwards at 3T/4 and 7T/4: rtol = 1e-10
    gives T to 1e-9 relative (measured: 1e-10 dopri5, 5e-12 dop853, 6e-13 rodas)."""
    assert 4 * np.sqrt(1 / G) * ellipk(0.5) == pytest.approx(PERIOD_90, rel=1e-15)
    if method.endswith("symbolic Jacobian"):
        sp, method = symbolic["simple_pendulum"], "rodas"
        assert integrate.jacobian_source(sp) == "symbolic"
    res = sp.simulate([np.pi / 2, 0.0], (0, 4.5), method=method, rtol=1e-10, atol=1e-10,
                      events=_upward_zero)
    assert res.status == 0 and res.success
    t_up = res.t_events[0]
    assert len(t_up) == 2
    assert t_up[1] - t_up[0] == pytest.approx(PERIOD_90, rel=1e-9)
    assert t_up[0] == pytest.approx(0.75 * PERIOD_90, rel=1e-9)
    # the event state lies on the solution: q = 0 there, moving up at the energy's speed
    q, qd = res.y_events[0][0]
    assert abs(q) < 1e-9 and qd == pytest.approx(np.sqrt(2 * G), rel=1e-8)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_terminal_event_stops_there_and_ends_the_result_with_the_event(sp, method):
    def falling_through_zero(t, x):
        return x[0]
    falling_through_zero.terminal = True
    falling_through_zero.direction = -1
    res = sp.simulate([np.pi / 2, 0.0], (0, 10), method=method, events=falling_through_zero,
                      rtol=1e-10, atol=1e-10, **fixed_step(method))
    assert res.status == 1 and res.success
    assert res.message == integrate.STATUS[1].message
    t_event = res.t_events[0][0]
    # second order at h = 1e-3: the implicit midpoint rule is good to ~3e-7 here
    assert t_event == pytest.approx(0.25 * PERIOD_90, rel=1e-6 if method == "midpoint" else 1e-8)
    assert res.t[-1] == t_event and np.array_equal(res.y[:, -1], res.y_events[0][0])
    # with t_eval: the samples stop at the event
    t_eval = np.linspace(0, 10, 101)
    res2 = sp.simulate([np.pi / 2, 0.0], (0, 10), t_eval=t_eval, method=method,
                       events=falling_through_zero, rtol=1e-10, atol=1e-10,
                       **fixed_step(method))
    assert np.array_equal(res2.t, t_eval[t_eval <= res2.t_events[0][0]])


def test_event_direction_selects_crossings_and_terminal_counts_occurrences(sp):
    def zero(t, x):
        return x[0]
    both = sp.simulate([np.pi / 2, 0.0], (0, 5), events=zero, rtol=1e-10, atol=1e-10)
    expected = np.array([0.25, 0.75, 1.25, 1.75]) * PERIOD_90
    assert np.allclose(both.t_events[0], expected, rtol=1e-8)
    zero.direction = 1
    up = sp.simulate([np.pi / 2, 0.0], (0, 5), events=zero, rtol=1e-10, atol=1e-10)
    assert np.allclose(up.t_events[0], expected[1::2], rtol=1e-8)
    zero.direction, zero.terminal = 0, 3           # stop at the third crossing
    third = sp.simulate([np.pi / 2, 0.0], (0, 5), events=zero, rtol=1e-10, atol=1e-10)
    assert third.status == 1 and np.allclose(third.t_events[0], expected[:3], rtol=1e-8)
    assert third.t[-1] == third.t_events[0][-1]


@pytest.mark.parametrize("method", ALL_METHODS)
def test_hundreds_of_events_are_all_found_across_output_buffers(dp, method):
    """200 zeros of sin(40 pi t) in 5 s: more than the first event buffer holds, so
    the C call is continued; each zero is found to round-off (at most one per step:
    max_step keeps the steps shorter than the spacing of the zeros)."""
    def ticks(t, x):
        return np.sin(40 * np.pi * t)
    res = dp.simulate([1.0, -0.5, 0, 0], (0, 5), events=ticks, max_step=0.01,
                      **fixed_step(method))
    assert res.success
    assert np.allclose(res.t_events[0], np.arange(1, 201) / 40, rtol=0, atol=1e-13)
    assert res.y_events[0].shape == (200, 4)


def test_an_event_function_returning_nan_is_an_error_not_silence(sp):
    res = sp.simulate([1.0, 0.0], (0, 2), events=lambda t, x: float("nan"))
    assert res.status == capi.STATUS_BY_NAME["EVENT_ERROR"].code
    assert "returned nan" in res.message


# -- output --------------------------------------------------------------------------------

@pytest.mark.parametrize("method", ADAPTIVE)
def test_dense_output_at_t_eval_agrees_with_stepping_exactly_to_those_times(dp, method):
    """Sampling through the dense output (steps unchanged) against integrations whose
    last step lands exactly on each time: both are within the tolerance of the truth."""
    x0, tol = [1.0, -0.5, 0.0, 0.0], 1e-9
    t_eval = np.array([0.0, 0.137, 0.5, 1.01, 1.5, 1.999])
    dense = dp.simulate(x0, (0, 2), t_eval=t_eval, method=method, rtol=tol, atol=tol)
    assert dense.success and np.array_equal(dense.t, t_eval)
    for j, t in enumerate(t_eval[1:], start=1):
        stepped = dp.simulate(x0, (0, t), method=method, rtol=tol, atol=tol)
        assert stepped.t[-1] == t
        assert np.max(np.abs(dense.y[:, j] - stepped.y[:, -1])) < 100 * tol, (method, t)
    # and t_eval does not change the steps: the step points are reproduced bitwise
    steps = dp.simulate(x0, (0, 2), method=method, rtol=tol, atol=tol)
    again = dp.simulate(x0, (0, 2), t_eval=steps.t, method=method, rtol=tol, atol=tol)
    assert np.array_equal(again.y, steps.y)


@pytest.mark.parametrize("method", ["dop853", "rodas", "gauss4"])
def test_recording_every_step_in_small_chunks_changes_nothing(dp, method):
    """chunk=7 forces dozens of C calls, each continued from the last exactly."""
    x0 = [1.0, -0.5, 0.0, 0.0]
    whole = dp.simulate(x0, (0, 3), method=method, step=0.01 if method == "gauss4" else None)
    chunked = dp.simulate(x0, (0, 3), method=method, chunk=7,
                          step=0.01 if method == "gauss4" else None)
    assert len(whole.t) > 30
    assert np.array_equal(whole.t, chunked.t) and np.array_equal(whole.y, chunked.y)
    assert whole.naccept == chunked.naccept and whole.nreject == chunked.nreject
    assert np.all(np.diff(chunked.t) > 0)


def test_result_is_shaped_like_solve_ivps(dp):
    res = dp.simulate([1.0, -0.5, 0.0, 0.0], (0, 1))
    ref = scipy.integrate.solve_ivp(dp.rhs, (0, 1), [1.0, -0.5, 0.0, 0.0], method="DOP853",
                                    rtol=1e-12, atol=1e-12)
    for key in ("t", "y", "sol", "t_events", "y_events", "nfev", "njev", "nlu", "status",
                "message", "success"):
        assert key in res and key in ref
    assert res.y.shape == (4, len(res.t)) and res.t[0] == 0 and res.t[-1] == 1
    assert res.sol is None and res.t_events is None
    assert res.naccept + 1 == len(res.t) and res.nfev > 0 and res.njev == 0
    assert np.max(np.abs(res.y[:, -1] - ref.y[:, -1])) < 1e-7
    assert "naccept" in repr(res)


@pytest.mark.parametrize("method", ["rodas", "midpoint", "gauss4"])
def test_implicit_methods_count_jacobians_factorizations_and_newton_iterations(sp, method):
    step = None if method == "rodas" else 0.01
    res = sp.simulate([1.0, 0.0], (0, 1), method=method, step=step)
    assert res.njev >= res.naccept > 0 and res.nlu >= res.naccept
    if method != "rodas":
        assert res.nnewton >= 2 * res.naccept
    assert integrate.jacobian_source(sp) in ("symbolic", "finite differences")


def test_symplectic_methods_keep_the_energy_bounded_where_rk4_drifts(sp):
    """5000 steps of 0.2 s over 160 periods of a large swing: the Gauss methods'
    energy error does not grow, RK4's does (tenfold)."""
    def energy_error(method):
        res = sp.simulate([2.5, 0.0], (0, 1000), t_eval=np.linspace(0, 1000, 2001),
                          method=method, step=0.2)
        assert res.success
        e = np.array([sp.energy(y[:1], y[1:]).sum() for y in res.y.T])
        err = np.abs(e - e[0]) / abs(e[0])
        return err[:200].max(), err[-200:].max()
    for method in ("midpoint", "gauss4"):
        early, late = energy_error(method)
        assert late < 1.5 * early, (method, early, late)
    early, late = energy_error("rk4")
    assert late > 5 * early


# -- failures -------------------------------------------------------------------------------

@pytest.mark.parametrize("method", ALL_METHODS)
def test_singular_mass_matrix_stops_with_the_pivot_and_keeps_the_start(dp_crba, method):
    res = dp_crba.simulate([0.5, -0.3, 0, 0], (0, 2), method=method, p={"m1": 0.0, "m2": 0.0},
                      **fixed_step(method))
    assert res.status == -3 and not res.success
    assert res.message.startswith("Mass matrix not positive definite at t=0.0: pivot "
                                  "1 (coordinate 'q1') failed; last good state at t=0.0: "
                                  "x=[0.5, -0.3, 0.0, 0.0]")
    assert np.array_equal(res.t, [0.0]) and np.array_equal(res.y[:, 0], [0.5, -0.3, 0, 0])


@pytest.mark.parametrize("method", ALL_METHODS)
def test_infinite_input_gives_non_finite_status_and_the_trajectory_before_it(dp, method):
    """The input (held) jumps to +inf at t = 1: the state would become Inf/NaN."""
    u = (np.array([0.0, 1.0]), np.array([[0.0], [np.inf]]), "hold")
    x0 = [0.5, -0.3, 0.0, 0.0]
    res = dp.simulate(x0, (0, 2), method=method, u=u, **fixed_step(method))
    assert res.status == -4 and not res.success
    assert re.match(r"NaN or Inf in the state at t=1\.0\d*; last finite state at t=0\.99\d*",
                    res.message), res.message
    assert 1.0 <= res.t_fail < 1.01
    assert 0.99 <= res.t[-1] < 1.0 and len(res.t) > 10 and np.all(np.isfinite(res.y))
    clean = dp.simulate(x0, (0, res.t[-1]), method=method, **fixed_step(method))
    assert np.allclose(res.y[:, -1], clean.y[:, -1], atol=1e-6)


@pytest.mark.parametrize("method", ALL_METHODS)
def test_max_steps_returns_the_steps_taken(sp, method):
    res = sp.simulate([1.0, 0.0], (0, 10), method=method, max_steps=10, **fixed_step(method))
    assert res.status == -1 and not res.success
    assert res.message.startswith("Maximum number of steps (10) reached at t=")
    assert res.naccept + res.nreject == 10 and len(res.t) == res.naccept + 1
    assert 0 < res.t[-1] < 10


@pytest.mark.parametrize("method", ["dop853", "rk4"])
def test_progress_hears_the_time_the_c_reached(dp, method):
    """The C writes the time reached to options.progress after every step; simulate
    passes it to progress(t) while it waits and after each C call (the buffer starts
    at t0, so ending at t1 proves the C wrote it)."""
    seen = []
    res = dp.simulate([1.5, 0.5, 0.0, 0.0], (0.5, 3.0), method=method, progress=seen.append,
                      **fixed_step(method), chunk=64)
    assert res.success and seen[-1] == res.t[-1] == 3.0
    assert len(seen) >= 2 and np.all(np.diff(seen) >= 0) and seen[0] > 0.5  # chunked: >1 call


def test_an_exception_from_progress_stops_the_c_before_its_arrays_are_freed(dp):
    """progress raises while the C run is under way in its worker thread: simulate
    must stop and join that thread before the exception frees the arrays it writes
    into (it used to keep running: a segfault on large t_eval).  The caller's own
    interrupt flag is left as it was."""
    flag = np.zeros(1, dtype=np.intc)
    before = threading.active_count()

    def progress(t):
        raise RuntimeError("progress bar closed")
    with pytest.raises(RuntimeError, match="progress bar closed"):
        dp.simulate([1.0, 1.0, 0.0, 0.0], (0, 1e4), t_eval=np.linspace(0, 1e4, 200_000),
                    max_step=1e-3, max_steps=10**9, progress=progress, interrupt=flag)
    assert threading.active_count() == before and flag[0] == 0


@pytest.mark.parametrize("method", ["rk4", "gauss4", "dop853"])
def test_fixed_steps_get_the_budget_they_need_by_default(sp, method):
    """200 s at h = 1e-3 are 200,000 steps, beyond the default budget of 100,000: a
    fixed-step run is given the steps its span needs (an explicit max_steps still
    counts)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = sp.simulate([1.0, 0.0], (0, 200), t_eval=[200.0], method=method, step=1e-3)
    assert res.success and res.t[-1] == 200.0 and res.naccept == 200_000
    with pytest.warns(RuntimeWarning, match="max_steps"):
        capped = sp.simulate([1.0, 0.0], (0, 200), method=method, step=1e-3,
                             max_steps=100_000)
    assert capped.status == -1


def test_max_steps_truncation_warns_and_says_how_to_raise_it(dp):
    """A run cut short by max_steps is not silent: a RuntimeWarning naming max_steps
    (raised at the caller's line), and the message says how far it got and the fix;
    the suggested budget then reaches t1."""
    x0 = [1.5, 0.5, 0.0, 0.0]
    with pytest.warns(RuntimeWarning, match=r"max_steps") as caught:
        res = dp.simulate(x0, (0, 20), rtol=1e-12, atol=1e-12, max_steps=1000)
    assert caught[0].filename == __file__
    assert res.status == -1 and res.t[-1] < 20
    assert "The run stopped at " in res.message and "% of t_span (0.0, 20.0)" in res.message
    need = int(re.search(r"max_steps=([\d_]+)", res.message)[1])
    assert need > 1000 and "--max-steps" in res.message
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        full = dp.simulate(x0, (0, 20), rtol=1e-12, atol=1e-12, max_steps=need)
    assert full.success and full.t[-1] == 20.0


@pytest.mark.parametrize("method", ALL_METHODS)
def test_step_size_underflow_when_t_is_too_large_to_resolve_the_step(sp, method):
    """At t = 1e15 consecutive doubles are 0.125 apart: no step the pendulum needs
    can advance t."""
    res = sp.simulate([1.0, 0.0], (1e15, 1e15 + 10), method=method, **fixed_step(method))
    assert res.status == -2
    assert res.message.startswith("Step size underflow at t=1000000000000000.0")
    assert np.array_equal(res.t, [1e15])


@pytest.mark.parametrize("method", ["midpoint", "gauss4"])
def test_newton_failure_of_a_too_large_implicit_step_is_reported(sp, method):
    # a failing step is halved up to 3 times first: 20 s is beyond even its eighth
    res = sp.simulate([1.0, 0.0], (0, 40), method=method, step=20.0)
    assert res.status == -5
    assert "implicit stage equations could not be solved in the step from t=0.0" in res.message
    assert np.array_equal(res.t, [0.0])


def test_singular_rosenbrock_matrix_halves_the_step_or_stops_a_fixed_step_run(symbolic):
    """Inverted pendulum at rest: J = [[0, 1], [g, 0]] exactly (symbolic), so
    1/(gamma h) - J is singular for h = 1/(gamma sqrt(g)), gamma = 1/4."""
    sp = symbolic["simple_pendulum"]
    h = 1 / (0.25 * np.sqrt(G))
    fixed = sp.simulate([np.pi, 0.0], (0, 2 * h), method="rodas", step=h)
    assert fixed.status == -5 and fixed.nlu == 1 and np.array_equal(fixed.t, [0.0])
    assert "matrix is singular" in fixed.message
    adaptive = sp.simulate([np.pi, 0.0], (0, 5), method="rodas", first_step=h)
    assert adaptive.success and adaptive.nreject >= 1
    assert adaptive.t[1] == pytest.approx(h / 2, rel=1e-15)     # the halved first step


def _c_call(cm, method, fixed, t1=1.0, interrupt=None, events=None, setup=None):
    """One direct call of <name>_integrate through the structs of mg_integrate.h
    (``setup(ffi, opt, out, keep)`` changes them and may return the inputs struct;
    ``keep`` holds what the C reads until it returns)."""
    ffi, ptr = cm.ffi, cm._ptr
    nx = 2 * cm.n
    keep = [np.array([1.0, 0.0]), cm.params(), np.full(nx, 1e-8), np.empty(64),
            np.empty((64, nx)), np.zeros(STOP_X + nx), np.empty(capi.work_size(nx, 0, 1))]
    x0, p, tol, t_out, x_out, stop, work = keep
    opt, out, stats = ffi.new("mg_options *"), ffi.new("mg_output *"), ffi.new("mg_stats *")
    opt.method, opt.fixed_step, opt.max_steps = method, fixed, 100
    opt.rtol = opt.atol = ptr(tol)
    if interrupt is not None:
        opt.interrupt = ffi.from_buffer("int[]", interrupt)
    if events is not None:
        opt.n_events, opt.events = 1, events
        direction, terminal = np.zeros(1, np.intc), np.zeros(1, np.intc)
        t_ev, x_ev, which = np.empty(8), np.empty((8, nx)), np.empty(8, np.intc)
        keep += [direction, terminal, t_ev, x_ev, which]
        opt.direction, opt.terminal = ffi.from_buffer("int[]", direction), ffi.from_buffer("int[]", terminal)
        out.events_capacity, out.t_events, out.x_events = 8, ptr(t_ev), ptr(x_ev)
        out.which_events = ffi.from_buffer("int[]", which)
    out.capacity, out.t, out.x, out.stop = 64, ptr(t_out), ptr(x_out), ptr(stop)
    inputs = ffi.NULL
    if setup is not None:
        inputs = setup(ffi, opt, out, keep) or ffi.NULL
    status = getattr(cm.lib, f"{cm.name}_integrate")(0.0, t1, ptr(x0), ptr(p), inputs, opt,
                                                       out, stats, ptr(work))
    return status, out.n, stats, t_out[:out.n].copy(), stop.copy()


def test_c_rejects_bad_arguments_with_its_own_status(sp):
    for method, fixed in ((99, 0.0), (0, 0.0)):       # unknown method; rk4 without a step
        status, *_ = _c_call(sp, method, fixed)
        assert status == -7 and integrate.STATUS[status].name == "BAD_ARGUMENT"


def _tolerance(value):
    def setup(ffi, opt, out, keep):
        keep.append(np.full(2, value))
        opt.rtol = ffi.from_buffer("double[]", keep[-1])
    return setup


def _t_eval(values):
    def setup(ffi, opt, out, keep):
        keep.append(np.array(values, dtype=float))
        out.t_eval, out.capacity = ffi.from_buffer("double[]", keep[-1]), len(values)
    return setup


def _samples(times):
    def setup(ffi, opt, out, keep):
        keep.append(np.array(times, dtype=float))
        inputs = ffi.new("mg_inputs *")
        inputs.n = len(times)
        inputs.times = inputs.values = ffi.from_buffer("double[]", keep[-1])
        keep.append(inputs)
        return inputs
    return setup


def _resume(slot, value):
    def setup(ffi, opt, out, keep):
        stop = np.zeros(STOP_X + 2)
        stop[0] = stop[1] = 0.1
        stop[slot] = value
        keep.append(stop)
        opt.resume = ffi.from_buffer("double[]", stop)
    return setup


@pytest.mark.parametrize("why, setup", [
    ("rtol 0", _tolerance(0.0)), ("rtol < 0", _tolerance(-1e-8)), ("rtol NaN", _tolerance(np.nan)),
    ("rtol inf", _tolerance(np.inf)),
    ("t_eval decreasing", _t_eval([0.5, 0.2, 1.0])), ("t_eval past t1", _t_eval([0.5, 2.0])),
    ("t_eval before t0", _t_eval([-1.0, 0.5])), ("t_eval NaN", _t_eval([0.2, np.nan, 0.9])),
    ("input times not increasing", _samples([0.0, 0.5, 0.5])),
    ("input times NaN", _samples([0.0, np.nan])),
    ("resume steps NaN", _resume(7, np.nan)), ("resume steps 1e30", _resume(7, 1e30)),
    ("resume t_origin inf", _resume(8, np.inf))])
def test_c_refuses_arguments_it_would_compute_garbage_from(sp, why, setup):
    """The embedded C has no Python in front of it: tolerances that are not finite and
    > 0, t_eval out of order or outside the span (returned as extrapolations of one
    step's polynomial, with status 0), unsorted input samples and a stop array no run
    wrote are BAD_ARGUMENT, nothing integrated."""
    status, rows, stats, t, stop = _c_call(sp, capi.METHODS["dop853"].code, 0.0, setup=setup)
    assert status == capi.STATUS_BY_NAME["BAD_ARGUMENT"].code, why
    assert stats.naccept == 0 and rows == 0, why
    good = _c_call(sp, capi.METHODS["dop853"].code, 0.0, setup=_t_eval([0.0, 0.5, 1.0]))
    assert good[0] == 0 and good[1] == 3


def test_c_batch_refuses_null_arrays_and_a_bad_parameter_stride(sp):
    """mg_integrate_batch used to check only system and options, then index NULL or
    short arrays by run (a segfault, or a read before P with a negative stride)."""
    ffi, lib, nx = sp.ffi, sp.lib, 2
    n_runs, n_eval = 2, 3
    arrays = dict(x0=np.zeros((n_runs, nx)), t_eval=np.linspace(0, 1, n_eval),
                  x_out=np.empty((n_runs, n_eval, nx)), stop=np.zeros((n_runs, STOP_X + nx)),
                  work=np.empty(capi.work_size(nx, 0, 0)))
    P, tol = sp.params(), np.full(nx, 1e-8)
    n_out, status = np.zeros(n_runs, dtype=np.int_), np.zeros(n_runs, dtype=np.intc)
    stats = ffi.new("mg_stats[]", n_runs)
    opt = ffi.new("mg_options *")
    opt.method, opt.max_steps = capi.METHODS["dop853"].code, 1000
    opt.rtol = opt.atol = sp._ptr(tol)
    fn = getattr(lib, f"{sp.name}_integrate_batch")

    def call(n=n_runs, stride=0, drop=None):
        a = {k: (ffi.NULL if k == drop else sp._ptr(v)) for k, v in arrays.items()}
        return fn(n, 0.0, 1.0, a["x0"], sp._ptr(P), stride, ffi.NULL, opt, n_eval, a["t_eval"],
                  a["x_out"], ffi.NULL, ffi.from_buffer("long[]", n_out),
                  ffi.from_buffer("int[]", status), stats, a["stop"], a["work"])
    bad = capi.STATUS_BY_NAME["BAD_ARGUMENT"].code
    for drop in arrays:
        assert call(drop=drop) == bad, drop
    assert call(stride=-1) == bad and call(stride=1) == bad and call(n=-1) == bad
    assert call() == 0 and list(status) == [0, 0] and list(n_out) == [n_eval] * n_runs


@pytest.mark.parametrize("t1, step", [(1.0, 1e-19), (1e10, 1e-9)])
def test_a_fixed_step_count_that_overflows_is_refused_not_reported_as_success(sp, t1, step):
    """(long)ceil(span/step) overflowed: one step and 'success' once; now the C refuses
    (BAD_ARGUMENT, nothing integrated) and simulate says why before calling it."""
    status, rows, stats, t, stop = _c_call(sp, capi.METHODS["rk4"].code, step, t1=t1)
    assert status == capi.STATUS_BY_NAME["BAD_ARGUMENT"].code
    assert stats.naccept == 0 and stop[0] == 0.0 and list(t) == [0.0]
    with pytest.raises(SimulationError, match=r"needs 1e\+19 steps, more than the C integrator"):
        sp.simulate([1.0, 0.0], (0, t1), method="rk4", step=step)
    # a merely long fixed-step run still stops at max_steps with what it computed
    res = sp.simulate([1.0, 0.0], (0, 1), method="rk4", step=1e-12, max_steps=5)
    assert res.status == -1 and res.naccept == 5 and res.t[-1] == pytest.approx(5e-12)


def test_the_interrupt_flag_stops_every_method_with_the_trajectory_so_far(sp):
    """An input callback raises the flag at t >= 0.5: the C stops at the next step."""
    for method in ALL_METHODS:
        flag = np.zeros(1, dtype=np.intc)

        def u(t, x, flag=flag):
            if t >= 0.5:
                flag[0] = 1
            return []
        res = sp.simulate([1.0, 0.0], (0, 2), method=method, u=u, interrupt=flag,
                          **fixed_step(method))
        assert res.status == capi.STATUS_BY_NAME["INTERRUPTED"].code and not res.success
        # stopped before the step after the callback's first t >= 0.5 (a rejected or a
        # long step may have called it beyond the step it then took)
        assert res.message.startswith(f"Interrupted at t={float(res.t[-1])!r}")
        assert 0.4 < res.t[-1] < 0.6 and res.t[0] == 0.0 and np.all(np.isfinite(res.y))
        clean = sp.simulate([1.0, 0.0], (0, res.t[-1]), method=method, **fixed_step(method))
        assert np.allclose(res.y[:, -1], clean.y[:, -1], atol=1e-6)
    flag = np.ones(1, dtype=np.intc)                   # raised before the first step
    status, rows, stats, t, stop = _c_call(sp, capi.METHODS["dop853"].code, 0.0, interrupt=flag)
    assert status == capi.STATUS_BY_NAME["INTERRUPTED"].code and rows == 1 and stats.naccept == 0


@pytest.mark.parametrize("method", ALL_METHODS)
def test_feedback_input_from_a_python_callable_works_with_every_method(dp, method):
    """u(t, x) = -k qd1 (a damper on the motor, called from the C) against the same
    feedback in solve_ivp on cm.rhs.  The implicit methods differentiate the closed
    loop (d u / d x included), or rodas' steps would collapse."""
    k = 2.0

    def u(t, x):
        return [-k * x[2]]
    x0 = [1.0, -0.5, 0.0, 0.0]
    step = {"midpoint": 2.5e-4, "rk4": 1e-3, "gauss4": 1e-3}.get(method)
    res = dp.simulate(x0, (0, 2), t_eval=[0, 1, 2], method=method, u=u, rtol=1e-10,
                      atol=1e-10, step=step)
    ref = scipy.integrate.solve_ivp(lambda t, x: dp.rhs(t, x, u=u(t, x)), (0, 2), x0,
                                    method="DOP853", rtol=1e-12, atol=1e-12, t_eval=[0, 1, 2])
    assert res.success, res.message
    tol = 1e-5 if method == "midpoint" else 1e-7          # second order at h = 2.5e-4
    assert np.max(np.abs(res.y - ref.y)) < tol, (method, np.max(np.abs(res.y - ref.y)))


def test_an_exception_in_the_input_callable_is_raised_with_the_trajectory_so_far(sp):
    def broken(t, x):
        if t > 0.5:
            raise ValueError("input function broke")
        return []
    with pytest.raises(ValueError, match="input function broke") as info:
        sp.simulate([1.0, 0.0], (0, 2), u=broken)
    res = info.value.partial_result
    assert res.status == capi.STATUS_BY_NAME["INPUT_ERROR"].code and not res.success
    assert "ValueError: input function broke" in res.message
    assert res.t[0] == 0.0 and 0.3 < res.t[-1] <= 0.6


CTRL_C = """\
import signal, sys, time, numpy as np, modelgen
# Python's own handler, as in a terminal, even when the test runs where SIGINT is
# ignored (a background job of a non-interactive shell inherits SIG_IGN)
signal.signal(signal.SIGINT, signal.default_int_handler)
cm = modelgen.load(sys.argv[1], sys.argv[2])
print("ready", flush=True)
start = time.perf_counter()
res = cm.simulate([1.0, 0.5, 0.0, 0.0], (0.0, 1e9), method="rk4", step=1e-4,
                  t_eval=np.linspace(0.0, 1e9, 11), max_steps=10**15)
print(res.status, res.t[-1], time.perf_counter() - start, flush=True)
print(res.message, flush=True)
"""


def _interrupted(tmp_path, script_text, *args) -> tuple:
    """(stdout after "ready", stderr, seconds from SIGINT to exit) of ``script_text``
    run with ``args``, sent SIGINT 1 s after it says it is ready."""
    import signal
    import subprocess
    import sys
    import time
    script = tmp_path / "run.py"
    script.write_text(script_text)
    proc = subprocess.Popen([sys.executable, str(script), *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    sent = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"SIGINT did not stop the run within 60 s: {out} {err}")
    return out, err, time.perf_counter() - sent


def test_ctrl_c_stops_a_long_c_run_and_keeps_what_it_computed(tmp_path, dp):
    """SIGINT during a C loop that would run for days: it stops within 0.2 s with
    status INTERRUPTED, and the result (not a KeyboardInterrupt) comes back."""
    out, err, waited = _interrupted(tmp_path, CTRL_C, MODELS / "double_pendulum.yaml",
                                    dp.path.parent)
    # waited: about 0.1 s; bounded loosely (shared machine)
    first, out = out.split("\n", 1)
    status, t_last, _ = first.split()
    assert int(status) == capi.STATUS_BY_NAME["INTERRUPTED"].code, err
    assert "Interrupted at t=" in out and waited < 2.0, (first, out, err)
    assert float(t_last) == 0.0          # no t_eval sample reached yet: the start is kept


CTRL_C_BATCH = """\
import signal, sys, time, warnings, numpy as np, modelgen
signal.signal(signal.SIGINT, signal.default_int_handler)
cm = modelgen.load(sys.argv[1], sys.argv[2])
print("ready", flush=True)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    res = cm.simulate_batch(np.tile([1.0, 0.5, 0.0, 0.0], (4, 1)), (0.0, 1e9), method="rk4",
                            step=1e-4, max_steps=10**15, threads=int(sys.argv[3]))
print(*res.status, flush=True)
print(*[str(w.message) for w in caught], flush=True)
"""


@pytest.mark.parametrize("threads", [1, 2])
def test_ctrl_c_stops_a_long_batch_and_returns_its_runs(tmp_path, dp, threads):
    """A batch was one C call that Ctrl-C could not stop before every run ended
    (here: days); now every run left stops within a step, INTERRUPTED, and the
    result comes back with a warning."""
    out, err, _ = _interrupted(tmp_path, CTRL_C_BATCH, MODELS / "double_pendulum.yaml",
                               dp.path.parent, threads)
    statuses, warned = out.split("\n", 1)
    code = capi.STATUS_BY_NAME["INTERRUPTED"].code
    assert statuses.split() == [str(code)] * 4, (out, err)
    assert "interrupted (Ctrl-C): 4 of 4 runs stopped early" in warned, (out, err)


@pytest.mark.parametrize("name, method", [
    ("RK45", "dopri5"), ("DOP853", "dop853"), ("Radau", "rodas"), ("BDF", "rodas"),
    ("LSODA", "rodas"), ("rk45", "dopri5")])
def test_solve_ivp_method_names_run_modelgens_methods(dp, name, method):
    """solve_ivp's method names are accepted and run the mapped method, bit for bit."""
    x0, span, t_eval = [1.5, 0.5, 0.0, 0.0], (0.0, 2.0), np.linspace(0.0, 2.0, 11)
    alias = dp.simulate(x0, span, t_eval=t_eval, method=name, rtol=1e-9, atol=1e-9)
    own = dp.simulate(x0, span, t_eval=t_eval, method=method, rtol=1e-9, atol=1e-9)
    assert alias.success and alias.method == method
    assert np.array_equal(alias.y, own.y) and alias.nfev == own.nfev


@pytest.mark.parametrize("call, message", [
    (lambda cm: cm.simulate([1, 0], (0, 1), method="rk44"), "unknown method 'rk44'"),
    (lambda cm: cm.simulate([1, 0], (0, 1), method="gauss4"), "has a fixed step: give step="),
    (lambda cm: cm.simulate([1, 0], (1, 1)), "t_span must not be empty"),
    (lambda cm: cm.simulate([1, 0], (1, 0), t_eval=[0.2, 0.5]),
     r"sorted in decreasing order \(t_span runs backwards\)"),
    (lambda cm: cm.simulate([1, 0], (0, np.inf)), "t_span must be finite"),
    (lambda cm: cm.simulate([1, 0], (0, 1), t_eval=[0.5, 2]), "t_eval must lie within"),
    (lambda cm: cm.simulate([1, 0], (0, 1), t_eval=[0.5, 0.2]), "t_eval must be sorted"),
    (lambda cm: cm.simulate([1, 0], (0, 1), rtol=-1), "rtol must be finite and >= 0"),
    (lambda cm: cm.simulate([np.nan, 0], (0, 1)), "x0 must be finite"),
])
def test_nonsense_arguments_raise_clear_errors(sp, call, message):
    with pytest.raises(SimulationError, match=message):
        call(sp)


# -- batches -----------------------------------------------------------------------------------

@pytest.mark.parametrize("threads", [1, 3])
def test_batch_equals_one_run_per_state_and_parameter_set(dp, threads):
    rng = np.random.default_rng(7)
    X0 = np.column_stack([rng.uniform(-1, 1, (5, 2)), np.zeros((5, 2))])
    g = rng.uniform(1.0, 10.0, 5)
    t_eval = np.linspace(0, 2, 5)
    batch = dp.simulate_batch(X0, (0, 2), t_eval, P={"g": g}, threads=threads, rtol=1e-9)
    assert batch.y.shape == (5, 4, 5) and np.all(batch.success)
    for r in range(5):
        one = dp.simulate(X0[r], (0, 2), t_eval, p={"g": g[r]}, rtol=1e-9)
        assert np.array_equal(batch.y[r], one.y)
        assert batch.nfev[r] == one.nfev and batch.naccept[r] == one.naccept


def test_batch_failure_of_one_run_leaves_the_others_alone(dp_crba):
    X0 = np.array([[0.5, -0.3, 0, 0], [0.1, 0.2, 0, 0], [1.0, 0.0, 0, 0]])
    P = np.tile(dp_crba.params(), (3, 1))
    P[1, :2] = 0.0                                   # m1 = m2 = 0 in run 1
    res = dp_crba.simulate_batch(X0, (0, 1), method="rk4", step=1e-2, P=P)
    assert list(res.status) == [0, -3, 0]
    assert "coordinate 'q1'" in res.message[1] and res.message[0].startswith("The solver")
    assert np.all(np.isnan(res.y[1])) and np.all(np.isfinite(res.y[[0, 2]]))
    assert res.y.shape == (3, 4, 1)


# -- the Jacobian ---------------------------------------------------------------------------------

def test_jacobian_of_the_pendulum_matches_the_hand_derived_one(sp):
    for q in (0.0, 0.7, 2.5):
        J = sp.jac(0.0, [q, 0.3])
        assert np.allclose(J, [[0.0, 1.0], [-G * np.cos(q), 0.0]], rtol=1e-9, atol=1e-9)


def test_jacobian_of_the_double_pendulum_matches_numpy_differences_of_rhs(dp):
    rng = np.random.default_rng(3)
    x = rng.uniform(-1, 1, 4)
    J = dp.jac(0.1, x, u=[0.3])
    eps = 1e-6
    ref = np.column_stack([(dp.rhs(0.1, x + eps * e, u=[0.3]) - dp.rhs(0.1, x - eps * e, u=[0.3]))
                           / (2 * eps) for e in np.eye(4)])
    assert J.shape == (4, 4)
    assert np.allclose(J, ref, rtol=1e-7, atol=1e-7)


def test_jac_is_the_symbolic_jacobian_when_generated_and_agrees_with_differences(dp, symbolic):
    dps = symbolic["double_pendulum"]
    assert integrate.jacobian_source(dps) == "symbolic"
    assert integrate.jacobian_source(dp) == "finite differences"
    x, u = np.array([0.3, -0.8, 1.2, 0.4]), np.array([0.7])
    exact = np.empty((4, 4))
    assert dps.lib.double_pendulum_jacobian(0.0, dps._ptr(x), dps._ptr(u), dps._ptr(dps.params()),
                                            dps._ptr(exact)) == 0
    assert np.array_equal(dps.jac(0.0, x, u=u), exact)
    assert np.allclose(dp.jac(0.0, x, u=u), exact, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("method", ["rodas", "gauss4"])
def test_implicit_methods_give_the_same_answer_with_either_jacobian(dp, symbolic, method):
    """Central differences (error ~1e-9 here) or the symbolic Jacobian: the same
    steps to within the tolerance, and the symbolic one saves 2 nx rhs calls each."""
    step = None if method == "rodas" else 0.01
    x0 = [1.0, -0.5, 0.0, 0.0]
    fd = dp.simulate(x0, (0, 3), method=method, step=step, rtol=1e-9, atol=1e-9)
    sym = symbolic["double_pendulum"].simulate(x0, (0, 3), method=method, step=step,
                                               rtol=1e-9, atol=1e-9)
    assert fd.success and sym.success
    assert np.max(np.abs(fd.y[:, -1] - sym.y[:, -1])) < 1e-7
    assert sym.nfev + 8 * sym.njev == pytest.approx(fd.nfev, rel=0.02)


def test_rhs_and_jac_plug_into_solve_ivp_radau(sp):
    res = scipy.integrate.solve_ivp(sp.rhs, (0, 2), [np.pi / 2, 0.0], method="Radau",
                                    jac=sp.jac, rtol=1e-10, atol=1e-10, events=_upward_zero)
    assert res.success and res.njev > 0
    assert res.t_events[0][0] == pytest.approx(0.75 * PERIOD_90, rel=1e-8)
