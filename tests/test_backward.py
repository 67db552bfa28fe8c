"""Backward integration: a decreasing t_span runs the C integrators on the system in
s = -t (mg_reverse_system), with inputs, events, outputs, dense output and
messages mapped back to t.  Checked against forward runs (a run there and back
returns to its start) and against scipy's solve_ivp integrating backwards."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import modelgen

ROOT = Path(__file__).resolve().parent.parent
X0 = np.array([1.5, 0.5, 0.0, 0.0])


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


@pytest.fixture(scope="module")
def cart(compiled):
    return compiled("cart_pole")


@pytest.mark.parametrize("method, options, tol", [
    ("dop853", {"rtol": 1e-12, "atol": 1e-12}, 1e-9),
    ("dopri5", {"rtol": 1e-11, "atol": 1e-11}, 1e-8),
    ("rodas", {"rtol": 1e-10, "atol": 1e-10}, 1e-6),
    ("gauss4", {"step": 1e-3}, 1e-9),       # symmetric: there and back exactly
])
def test_there_and_back_returns_to_the_start(dp, method, options, tol):
    there = dp.simulate(X0, (0.0, 2.0), method=method, **options)
    back = dp.simulate(there.y[:, -1], (2.0, 0.0), method=method, **options)
    assert there.success and back.success, back.message
    assert back.t[0] == 2.0 and back.t[-1] == 0.0 and np.all(np.diff(back.t) < 0)
    assert np.max(np.abs(back.y[:, -1] - X0)) < tol


def test_rk4_backward_converges_with_order_4(dp):
    """rk4 is not symmetric: against a tight backward reference its error falls 16x
    when the step halves."""
    ref = dp.simulate(X0, (2.0, 0.0), rtol=1e-13, atol=1e-13).y[:, -1]
    errors = [np.max(np.abs(dp.simulate(X0, (2.0, 0.0), method="rk4", step=h).y[:, -1] - ref))
              for h in (2e-3, 1e-3)]
    assert 14 < errors[0] / errors[1] < 18, errors


def test_backward_equals_solve_ivp_backward(dp):
    x1 = dp.simulate(X0, (0.0, 2.0), rtol=1e-12, atol=1e-12).y[:, -1]
    t_eval = np.linspace(2.0, 0.5, 16)
    ours = dp.simulate(x1, (2.0, 0.5), t_eval=t_eval, rtol=1e-12, atol=1e-12)
    ref = solve_ivp(dp.rhs, (2.0, 0.5), x1, method="DOP853", t_eval=t_eval, rtol=1e-12,
                    atol=1e-12)
    assert np.array_equal(ours.t, t_eval)
    assert np.max(np.abs(ours.y - ref.y)) < 1e-9


def test_a_decreasing_t_eval_is_required_and_sampled_exactly(dp):
    res = dp.simulate(X0, (1.0, -1.0), t_eval=[1.0, 0.25, -0.5, -1.0])
    assert res.t.tolist() == [1.0, 0.25, -0.5, -1.0] and res.success


@pytest.mark.parametrize("interp", ["linear", "hold"])
def test_sampled_inputs_run_the_same_function_of_t_both_ways(cart, interp):
    times = np.linspace(0.0, 2.0, 9)
    values = np.sin(3 * times)[:, None] * 4.0
    u = (times, values, interp)
    x0 = [0.1, 0.3, 0.0, 0.0]
    opts = {"rtol": 1e-12, "atol": 1e-12, "max_step": 0.05}
    there = cart.simulate(x0, (0.0, 2.0), u=u, **opts)
    back = cart.simulate(there.y[:, -1], (2.0, 0.0), u=u, **opts)
    assert np.max(np.abs(back.y[:, -1] - x0)) < 1e-8


def test_feedback_sees_t_and_events_are_found_going_backwards(cart):
    seen = []

    def u(t, x):
        seen.append(t)
        return [np.cos(t)]

    def crossing(t, x):
        return x[1] - 3.0
    x0 = [0.0, 0.3, 0.0, 0.0]
    opts = {"rtol": 1e-12, "atol": 1e-12}
    res = cart.simulate(x0, (0.0, -3.0), u=u, events=crossing, **opts)
    assert res.success and min(seen) >= -3.0 - 1e-12 and max(seen) <= 1e-12
    ref = solve_ivp(lambda t, x: cart.rhs(t, x, u=[np.cos(t)]), (0.0, -3.0), x0,
                    method="DOP853", rtol=1e-12, atol=1e-12, events=crossing)
    assert len(res.t_events[0]) == len(ref.t_events[0]) > 0
    assert np.all(np.diff(res.t_events[0]) < 0)
    assert np.max(np.abs(res.t_events[0] - ref.t_events[0])) < 1e-8
    assert np.max(np.abs(res.y[:, -1] - ref.y[:, -1])) < 1e-8


def test_dense_output_backward_matches_t_eval_sampling(dp):
    res = dp.simulate(X0, (2.0, 0.0), dense_output=True, rtol=1e-10, atol=1e-10)
    t = np.linspace(2.0, 0.0, 37)
    sampled = dp.simulate(X0, (2.0, 0.0), t_eval=t, rtol=1e-10, atol=1e-10)
    assert res.sol is not None and res.sol.t_min == 0.0 and res.sol.t_max == 2.0
    assert np.max(np.abs(res.sol(t) - sampled.y)) < 1e-11


def test_scene_outputs_are_recorded_at_the_reported_times(tmp_path):
    scene = modelgen.load_scene(ROOT / "models" / "scenes" / "cart_pole_push.yaml", tmp_path)
    cm = scene.model
    u = scene.input_signal()
    res = cm.simulate(scene.initial_state(), (1.0, 0.0), t_eval=np.linspace(1.0, 0.0, 11),
                      u=u, rtol=1e-10, atol=1e-10)
    flat = np.column_stack([res.outputs[name] for name in cm.outputs])
    inputs = scene.inputs_at
    for k, t in enumerate(res.t):
        expected = cm.output_values(t, res.y[:, k], u=[inputs(t)[name] for name in cm.inputs])
        assert np.allclose(flat[k], expected, rtol=1e-12, atol=1e-12), t


def test_batch_backward_equals_single_runs(dp):
    X = np.array([[1.5, 0.5, 0.0, 0.0], [0.3, -0.2, 0.1, 0.0]])
    t_eval = np.linspace(1.0, 0.0, 5)
    batch = dp.simulate_batch(X, (1.0, 0.0), t_eval=t_eval, rtol=1e-10, atol=1e-10)
    assert np.array_equal(batch.t, t_eval)
    for r in range(len(X)):
        single = dp.simulate(X[r], (1.0, 0.0), t_eval=t_eval, rtol=1e-10, atol=1e-10)
        assert np.array_equal(batch.y[r], single.y)


def test_a_failure_backward_names_times_of_t(dp):
    with pytest.warns(RuntimeWarning, match="max_steps"):
        res = dp.simulate(X0, (0.0, -50.0), max_steps=50)
    assert res.status == -1 and res.t[-1] < 0
    assert f"t={float(res.t[-1])!r}" in res.message and "% of t_span (0.0, -50.0)" in res.message
