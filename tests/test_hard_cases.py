"""The hard-case suite (modelgen/bench/hard_cases.py): a fast subset in CI, and the defects it found.

The full suite is the benchmark script ``bench/hard_cases.py``; here every
case runs in its quick form except the slow ones (the 1e6-step singular run,
the 100-link chain), and each defect the suite found has a test of its own.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.bench import hard_case_models as hm
from modelgen.codegen import capi
from modelgen.bench.hard_cases import CASES, Context, markdown, run_cases
from modelgen.errors import MassMatrixError


@pytest.fixture(scope="module")
def ctx(tmp_path_factory):
    return Context(tmp_path_factory.mktemp("hard_cases"), quick=True)


@pytest.mark.parametrize("name", ["pendulum_near_top", "lagrange_top_separatrix",
                                  "sleeping_top", "stiff_springs", "mass_ratios",
                                  "singular_at_start", "singular_everywhere",
                                  "energy_long_run", "friction_stop", "tennis_racket",
                                  "fixed_step_implicit", "rk4_beyond_stability",
                                  "bicycle_capsize"])
def test_quick_hard_case_passes(ctx, name):
    result = CASES[name](ctx)
    assert result.passed, f"{name}: {result.figure} ({result.note})"


def test_closed_forms_match_the_notes():
    # DYNAMICS-NOTES: T(90 deg) = 2.367841947576237 s, T(179 deg) = 7.825796837537810 s
    assert hm.pendulum_period(math.pi / 2) == pytest.approx(2.367841947576237, rel=1e-14)
    assert hm.pendulum_period(math.radians(179)) == pytest.approx(7.825796837537810, rel=1e-13)
    gamma, _ = hm.separatrix_start()
    assert hm.separatrix_cos_theta(hm.separatrix_time_to(0.3, gamma), gamma) == \
        pytest.approx(math.cos(0.3), rel=1e-14)


def test_flip_period_against_eulers_equations():
    from scipy.integrate import solve_ivp
    I = np.array([1.0, 2.0, 3.0])

    def euler(t, w):
        return [(I[1] - I[2]) * w[1] * w[2] / I[0], (I[2] - I[0]) * w[2] * w[0] / I[1],
                (I[0] - I[1]) * w[0] * w[1] / I[2]]
    for w0 in ([0.05, 1.0, 0.0], [0.0, 1.0, 0.05]):      # M^2 < 2EI2 and M^2 > 2EI2
        T = hm.flip_period(*I, w0)
        ev = lambda t, w: w[1]                            # noqa: E731
        sol = solve_ivp(euler, (0, 4.5 * T), w0, rtol=1e-12, atol=1e-12, events=ev)
        assert np.diff(sol.t_events[0]) == pytest.approx(T, rel=1e-7)


def test_table_names_every_case_with_its_verdict(ctx):
    results = run_cases(["singular_at_start"], quick=True, build_root=ctx.build_root)
    table = markdown(results)
    assert "`singular_at_start`" in table and "**pass**" in table


def test_gauss4_keeps_a_newton_iteration_that_converges(ctx):
    """Defect 2: the second correction slightly larger than the first (then a rate
    about 0.05) made gauss4 give up: status -5 at t = 2.45 with h = 0.05."""
    cm = ctx.model(hm.DOUBLE_PENDULUM)
    for method, step in (("gauss4", 0.05), ("gauss4", 0.03), ("midpoint", 0.01)):
        res = cm.simulate([2.0, 1.0, 0.0, 0.0], (0.0, 30.0), method=method, step=step)
        assert res.status == 0, (method, step, res.message)
        assert np.all(np.isfinite(res.y))


def test_tiny_mass_ratio_is_solved_not_refused(ctx):
    """Defect 3: A_jj <= 1e-13 max A_ii refused m2/m1 = 1e-15, whose q'' is well defined."""
    cm = ctx.model(hm.DOUBLE_PENDULUM)
    x = np.array([0.3, -0.7, 0.5, 1.1])
    p = {"m2": 1e-15, "J2": 1e-15 / 12}
    ref = hm.double_pendulum_qdd(x[:2], x[2:], 1.0, p["m2"], 1.0, 1.0, 1 / 12, p["J2"])
    assert cm.rhs(0.0, x, p=p)[2:] == pytest.approx(ref, rel=1e-12)
    res = cm.simulate(x, (0.0, 1.0), p=p)
    assert res.status == 0, res.message


def test_singular_and_indefinite_mass_matrices_are_worded_apart(ctx):
    """Defect 3: the top below theta ~ 3e-7 is singular to working precision, not
    'not positive definite'; a negative inertia is not positive definite."""
    top = ctx.model(hm.HEAVY_TOP, formulation="crba")     # the Cholesky pivot test
    x = [0.0, 1e-7, 0.0, 0.0, 0.0, 50.0]
    with pytest.raises(MassMatrixError, match="mass matrix singular to working precision"):
        top.rhs(0.0, x)
    assert top.simulate(x, (0.0, 1.0)).message.startswith(
        "Mass matrix singular to working precision at t=0.0: pivot 3 (coordinate 'psi')")
    dp = ctx.model(hm.DOUBLE_PENDULUM, formulation="crba")
    with pytest.raises(MassMatrixError, match="mass matrix not positive definite"):
        dp.rhs(0.0, [0.3, -0.7, 0.0, 0.0], p={"J1": -1.0})


def test_a_run_failing_near_a_singular_configuration_says_so(ctx):
    """Defect 4: the separatrix top creeping toward theta = 0 stopped with 'Maximum
    number of steps (100000) reached' and nothing about why."""
    top = ctx.model(hm.HEAVY_TOP, formulation="crba")     # A's condition number
    _, x0 = hm.separatrix_start()
    res = top.simulate(x0, (0.0, 6.0), rtol=1e-12, atol=1e-12, t_eval=[6.0])
    assert res.status == -1
    assert "A's condition number grew from 4e+00 to" in res.message
    assert "near a singular configuration (Euler angles at gimbal lock?)" in res.message
    # a failure far from any singular configuration carries no such note
    dp = ctx.model(hm.DOUBLE_PENDULUM, formulation="crba")
    res = dp.simulate([0.5, 0.3, 0.0, 0.0], (0.0, 10.0), max_steps=10)
    assert res.status == -1 and "condition number" not in res.message


def test_cli_runs_named_cases_and_writes_the_table_and_figure(tmp_path, capsys):
    from modelgen.cli import main
    assert main(["hard-cases", "--quick", "--cases", "singular_at_start", "-o",
                 str(tmp_path / "out"), "--build-dir", str(tmp_path / "build")]) == 0
    assert "`singular_at_start`" in (tmp_path / "out" / "hard_cases.md").read_text()
    assert (tmp_path / "out" / "hard_cases.png").stat().st_size > 0
    assert main(["hard-cases", "--cases", "no_such_case", "-o", str(tmp_path)]) == 2
    assert "unknown hard case(s) no_such_case" in capsys.readouterr().err


def test_four_bar_run_into_its_dead_point_stops_with_a_named_status(ctx):
    """At rtol 1e-12 the rocker-driven four-bar stops where crank and coupler come
    in line (the law of cosines' rocker angle), with the constraint Jacobian named;
    no run of the case holds a NaN."""
    cm = ctx.model(hm.FOUR_BAR_ROCKER)
    q0 = cm.assemble([0.0, 1.2, 2.0], keep=["q1"])
    x0 = np.concatenate([q0, cm.consistent_speeds(q0, [0.0, 0.0, 3.0])])
    res = cm.simulate(x0, (0.0, 5.0), method="dop853", rtol=1e-12, atol=1e-14)
    assert res.status == -3 and 0.2 < res.t[-1] < 0.4
    assert "constraint Jacobian" in res.message and "dead point" in res.message
    assert np.all(np.isfinite(res.y))
    q = res.y[:3, -1]
    assert min(abs(q[2] - r) for r in hm.rocker_dead_points()) < 1e-3
    assert abs(math.sin(q[0] - q[1])) < 1e-3


def test_four_bar_dead_point_is_never_stepped_over(ctx):
    result = CASES["four_bar_dead_point"](ctx)
    assert "nan" not in result.figure.lower()
    assert result.passed, result.figure


def _rocker_start(cm, q1_guess=0.0):
    q0 = cm.assemble([q1_guess, 1.2, 2.0], keep=["q3"])
    return np.concatenate([q0, cm.consistent_speeds(q0, [0.0, 0.0, 3.0])])


@pytest.mark.parametrize("method, options", [
    ("dop853", {"rtol": 1e-6, "atol": 1e-8}), ("dopri5", {"rtol": 1e-5, "atol": 1e-7}),
    ("rodas", {"rtol": 1e-6, "atol": 1e-8}), ("rk4", {"step": 2e-3})])
@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_a_step_across_the_dead_point_stops_before_it(ctx, method, options, direction):
    """Every integrator, forward and backward in time, either stops with the dead point
    named or reports the singular Jacobian: its last state is on the branch it started
    on (the sign of det G_d = a b sin(q2 - q1), crank and coupler's angle, written out)
    and next to the law of cosines' rocker angle; the run never goes on."""
    cm = ctx.model(hm.FOUR_BAR_ROCKER)
    x0 = _rocker_start(cm)
    res = cm.simulate(x0, (0.0, 5.0 * direction), method=method, **options)
    codes = {capi.STATUS_BY_NAME[k].code for k in ("DEAD_POINT", "MASS_MATRIX")}
    assert res.status in codes, (res.status, res.message)
    assert "dead point" in res.message and "constraint Jacobian" in res.message
    assert np.all(np.isfinite(res.y))
    q = res.y[:3, -1]
    assert np.sign(math.sin(q[1] - q[0])) == np.sign(math.sin(x0[1] - x0[0]))
    assert min(abs(q[2] - r) for r in hm.rocker_dead_points()) < 5e-3
    if res.status == capi.STATUS_BY_NAME["DEAD_POINT"].code:
        assert abs(res.t_fail) > abs(res.t[-1]) and "between t =" in res.message


def test_each_run_of_a_batch_records_its_own_branch(ctx):
    """Two starts on the two branches of the loop (det G_d of opposite signs), in one
    batch and each after the other: neither is taken for a crossing, and a batch
    whose runs cross stops each one at the time the single run stops."""
    cm = ctx.model(hm.FOUR_BAR_ROCKER)
    a, b = _rocker_start(cm, 0.0), _rocker_start(cm, 2.0)
    assert math.sin(a[1] - a[0]) * math.sin(b[1] - b[0]) < 0     # opposite branches
    t = np.linspace(0.0, 0.05, 6)
    for X0 in ([a, b], [b, a]):
        res = cm.simulate_batch(np.array(X0), (0.0, 0.05), t_eval=t, method="dop853",
                                rtol=1e-8)
        assert list(res.status) == [0, 0], res.message
    alone = cm.simulate(a, (0.0, 5.0), method="dop853", rtol=1e-8)
    both = cm.simulate_batch(np.array([b, a]), (0.0, 5.0), t_eval=np.linspace(0, 5, 51),
                             method="dop853", rtol=1e-8)
    dead = capi.STATUS_BY_NAME["DEAD_POINT"].code
    assert alone.status == both.status[1] == dead
    assert "dead point" in both.message[1]
