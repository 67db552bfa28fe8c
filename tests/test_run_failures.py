"""What a run does at the edges of what it can compute: a trial step that
overflows is retried smaller, a span of a few ulps is one step, and a run that
stops says when (``t_fail``) and why, in single runs and in batches."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import modelgen
from modelgen.sim.mechanical_work import UNRESOLVED, energy_balance, quadrature_times

# A pendulum without gravity held by a stiffening spring: torque -(exp(a q) - 1).
# Released at q_dot = 3 it coasts at constant deceleration on the q < 0 side,
# where adaptive steps grow long, and a trial step that overshoots to q > 0 meets
# exp(20 q) beyond the doubles though the motion itself stays within |q| < 4.6.
STIFFENING = """name: stiffening
coordinates: [q]
parameters: {L: 1.0, m: 1.0, a: 20.0}
bases: {B1: {parent: E, axis: 3, angle: q}}
points: {P: {from: O, base: B1, coordinates: [0, -L, 0]}}
bodies: {bob: {mass: m, G: P, base: B1}}
actions: {spring: {body: bob, point: O, base: E, torque: [0, 0, -(exp(a*q) - 1)]}}
"""

# q_ddot = q_dot^3: from q_dot = 1 the speed 1 / sqrt(1 - 2 t) is infinite at t = 1/2.
BLOW_UP = STIFFENING.replace("name: stiffening", "name: blow_up").replace(
    "torque: [0, 0, -(exp(a*q) - 1)]", "torque: [0, 0, q_dot**3]")


@pytest.fixture(scope="module")
def stiffening(build_root):
    path = build_root / "stiffening.yaml"
    path.write_text(STIFFENING)
    return modelgen.load(path, build_root / "stiffening")


@pytest.fixture(scope="module")
def blow_up(build_root):
    path = build_root / "blow_up.yaml"
    path.write_text(BLOW_UP)
    return modelgen.load(path, build_root / "blow_up")


@pytest.fixture(scope="module")
def pendulum(compiled):
    return compiled("simple_pendulum")


@pytest.mark.parametrize("method, options", [
    ("dop853", {}), ("dopri5", {}), ("rodas", {}),
    ("dop853", {"first_step": 2.0}), ("dopri5", {"first_step": 2.0})])
def test_an_overflowing_trial_step_is_retried_smaller(stiffening, method, options):
    res = stiffening.simulate([0.0, 3.0], (0.0, 20.0), method=method, **options)
    assert res.status == 0, res.message
    assert res.nreject > 0
    with np.errstate(all="ignore"), warnings.catch_warnings():   # its own overflowed trials
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = solve_ivp(stiffening.rhs, (0.0, 20.0), [0.0, 3.0], method="DOP853", rtol=1e-10,
                        atol=1e-12)
    assert ref.status == 0
    # the same motion: the final state to the tolerances' scale
    assert np.allclose(res.y[:, -1], ref.y[:, -1], rtol=1e-5, atol=1e-5)


def test_an_overflowing_newton_iterate_halves_a_gauss_step(stiffening):
    # step 0.25 needs the halving (its iterates overflow); 0.5 is too long even then
    res = stiffening.simulate([0.0, 3.0], (0.0, 20.0), method="gauss4", step=0.25)
    assert res.status == 0, res.message
    res = stiffening.simulate([0.0, 3.0], (0.0, 20.0), method="gauss4", step=0.5)
    assert res.status == -5 and "smaller step" in res.message


@pytest.mark.parametrize("method", ["dop853", "dopri5", "rodas"])
def test_a_solution_that_blows_up_stops_at_its_singularity(blow_up, method):
    res = blow_up.simulate([0.0, 1.0], (0.0, 1.0), method=method)
    assert res.status in (-2, -4), res.message
    assert abs(res.t[-1] - 0.5) < 1e-6 and res.t_fail == pytest.approx(res.t[-1], abs=1e-6)
    assert np.isfinite(res.y).all() and len(res.t) == res.y.shape[1]


@pytest.mark.parametrize("method, step", [("dop853", None), ("rodas", None), ("rk4", 1e-3)])
def test_a_span_of_a_few_ulps_is_one_step(pendulum, method, step):
    t0 = 9.99999999999998          # 11 ulps below 10: the last of 100 steps of 0.1
    res = pendulum.simulate([1.0, 0.0], (t0, 10.0), method=method, step=step)
    assert res.status == 0, res.message
    assert res.t.tolist() == [t0, 10.0]


def test_t_fail_is_where_a_run_stopped(pendulum):
    with pytest.warns(RuntimeWarning, match="max_steps"):
        res = pendulum.simulate([1.0, 0.0], (0.0, 100.0), method="rk4", step=1e-3,
                                max_steps=5000, chunk=1000)
    assert res.status == -1 and res.t_fail == res.t[-1] == pytest.approx(5.0)

    def nan_late(t, x):
        return np.nan if t > 1.0 else x[0] - 2.0
    res = pendulum.simulate([1.0, 0.0], (0.0, 5.0), events=nan_late)
    assert res.status == -6 and res.t_fail > 1.0 >= res.t[-1]
    assert "_NonFiniteEvent" not in res.message and "raised" not in res.message
    assert "event function 0 (nan_late) returned nan" in res.message


def test_a_batch_that_runs_out_of_steps_warns_once_and_keeps_where_it_stopped(pendulum):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = pendulum.simulate_batch([[1.0, 0.0], [2.0, 0.0], [0.1, 0.0]], (0.0, 100.0),
                                      max_steps=50, P={"g": [9.81, 9.81, 0.0]})
    assert [str(w.message).count("max_steps") > 0 for w in caught] == [True]
    assert "2 of 3 runs" in str(caught[0].message)
    assert res.status.tolist() == [-1, -1, 0]
    assert all("fix: raise max_steps" in m for m in res.message[:2])
    reached = res.info["t_reached"]
    assert 0 < reached[0] < 100 and reached[2] == 100.0
    assert res.t_fail[:2].tolist() == reached[:2].tolist() and np.isnan(res.t_fail[2])
    assert np.isfinite(res.info["x_reached"]).all() and np.isnan(res.y[0]).all()
    with pytest.warns(RuntimeWarning, match="max_steps"):
        single = pendulum.simulate([1.0, 0.0], (0.0, 100.0), max_steps=50, t_eval=[100.0])
    assert single.t_fail == reached[0]


def test_sol_is_nan_outside_the_steps_taken(pendulum):
    res = pendulum.simulate([1.0, 0.0], (0.0, 1.0), dense_output=True)
    inside = res.sol([0.0, 0.5, 1.0])
    assert np.isfinite(inside).all() and np.allclose(inside[:, -1], res.y[:, -1], atol=1e-14)
    assert np.isnan(res.sol([-1e-3, 1.001, 2.0])).all()
    back = pendulum.simulate([1.0, 0.0], (1.0, 0.0), dense_output=True)
    assert np.isfinite(back.sol(0.25)).all() and np.isnan(back.sol(1.5)).all()


def test_dense_output_warns_once_for_its_repeated_run(pendulum):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = pendulum.simulate([1.0, 0.0], (0.0, 100.0), max_steps=50, dense_output=True,
                                t_eval=[1.0, 2.0])
    assert res.status == -1 and len(caught) == 1
    # the repeated run is the same run: its steps give back the samples
    assert res.t.tolist() == [1.0, 2.0] and np.allclose(res.sol(res.t), res.y, rtol=0,
                                                        atol=1e-12)


def test_the_balance_flags_a_power_the_samples_do_not_resolve():
    times = np.linspace(0.0, 1.0, 101)              # h = 0.01
    grid = quadrature_times(times)
    for w, flagged in ((20.0, False), (250.0, False), (1000.0, True), (2000.0, True)):
        power = np.sin(w * grid)                     # work (1 - cos w t) / w
        energy = (1.0 - np.cos(w * times)) / w       # E(t) - E(0) = W(t): a zero balance
        balance = energy_balance(grid, energy, {"f": power})
        assert (balance.unresolved > UNRESOLVED) is flagged, (w, balance.unresolved)
        # resolved, the check overstates the quadrature's error by orders of magnitude;
        # unresolved, the error is of the check's order
        ratio = np.abs(balance.error).max() / balance.quadrature_check
        assert ratio > 0.01 if flagged else ratio < 1e-3, (w, ratio)


def test_a_fixed_step_batch_gets_the_steps_its_span_needs(pendulum):
    """simulate gives a fixed-step run the steps its span needs; simulate_batch kept
    100,000, so rk4 at 1e-5 s over 1.2 s ended every run with MAX_STEPS."""
    X0 = np.array([[0.5, 0.0], [1.0, 0.0]])
    res = pendulum.simulate_batch(X0, (0.0, 1.2), method="rk4", step=1e-5)
    assert np.all(res.status == 0), res.message
    one = pendulum.simulate(X0[1], (0.0, 1.2), t_eval=[1.2], method="rk4", step=1e-5)
    assert np.array_equal(res.y[1], one.y)
    back = pendulum.simulate_batch(X0, (1.2, 0.0), method="rk4", step=1e-5)
    assert np.all(back.status == 0), back.message
    with pytest.warns(RuntimeWarning, match="max_steps"):
        short = pendulum.simulate_batch(X0, (0.0, 1.2), method="rk4", step=1e-5,
                                        max_steps=10)
    assert np.all(short.status == -1)


def test_a_batch_names_the_row_and_state_that_is_not_finite(pendulum):
    X0 = np.array([[0.5, 0.0], [1.0, np.nan]])
    name = pendulum.state_names[1]
    with pytest.raises(modelgen.errors.ArgumentValueError,
                       match=rf"got nan in row 1 \({name}\)"):
        pendulum.simulate_batch(X0, (0.0, 1.0))
