"""numpy in, numpy out, as users of scipy, Pinocchio and MuJoCo's bindings expect.

Hostile but legitimate arrays (strided views, Fortran columns, read-only, other
dtypes, lists) give the numbers of a plain float64 vector; what is not a vector of
numbers (text, times, wrong shapes) is refused by name; results are fresh writable
float64 arrays that alias nothing; the fast path is safe to share between threads;
the C calls release the GIL; a pickled model loads without the symbolic pipeline;
and a quaternion off unit norm is treated as each entry point documents.
"""
from __future__ import annotations

import pickle
import re
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import modelgen
from modelgen.errors import SimulationError

from conftest import ROOT

BALL = ROOT / "tests" / "data" / "joints" / "heavy_body_ball.yaml"
X = np.array([0.1, 0.2, 0.3, 0.4])


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


@pytest.fixture(scope="module")
def ball(build_root):
    """The heavy body on a ball joint (a quaternion in q), finite-difference Jacobian."""
    return modelgen.load(BALL, build_root / "hbb_numpy_edges")


#: every vector argument of the double pendulum's functions: (name, call, reference)
CALLS = {
    "mass_matrix": (lambda cm, a: cm.mass_matrix(a), X[:2]),
    "velocity_terms": (lambda cm, a: cm.velocity_terms(X[:2], a), X[2:]),
    "generalized_forces": (lambda cm, a: cm.generalized_forces(0.0, a, X[2:], u=[0.2]), X[:2]),
    "inverse_dynamics": (lambda cm, a: cm.inverse_dynamics(0.0, a, [0.5, -0.5]), X),
    "energy": (lambda cm, a: cm.energy(a, X[2:]), X[:2]),
    "body_poses": (lambda cm, a: cm.body_poses(a), X[:2]),
    "rhs": (lambda cm, a: cm.rhs(0.0, a), X),
    "rhs u": (lambda cm, a: cm.rhs(0.0, X, u=a), np.array([0.7])),
    "rhs p": (lambda cm, a: cm.rhs(0.0, X, p=a), np.array([1.0, 2.0, 1.0, 3.0, 9.0])),
    "jac": (lambda cm, a: cm.jac(0.0, a), X),
    "project": (lambda cm, a: cm.project(a), X),
    "state_vector": (lambda cm, a: cm.state_vector(a), X),
    "rhs_function": (lambda cm, a: cm.rhs_function()(0.0, a), X),
    "simulate": (lambda cm, a: cm.simulate(a, (0.0, 0.2)).y, X),
}


def _layouts(a):
    """The same numbers as ``a`` in layouts and dtypes numpy converts exactly."""
    strided = np.zeros(2 * len(a))
    strided[::2] = a
    fortran = np.zeros((len(a), 3), order="F")
    fortran[:, 1] = a
    readonly = a.copy()
    readonly.flags.writeable = False

    class Sub(np.ndarray):
        pass
    return {"strided": strided[::2], "fortran column": fortran[:, 1], "read-only": readonly,
            "list": list(a), "tuple": tuple(a), "object": a.astype(object),
            "big-endian": a.astype(">f8"), "longdouble": a.astype(np.longdouble),
            "subclass": a.view(Sub), "list of numpy scalars": [np.float64(v) for v in a]}


@pytest.mark.parametrize("name", CALLS)
def test_layouts_and_exact_dtypes_give_the_numbers_of_a_plain_vector(dp, name):
    call, a = CALLS[name]
    want = call(dp, a)
    for layout, value in _layouts(a).items():
        assert np.array_equal(call(dp, value), want), layout
    # dtypes numpy converts to float64 by value: the numbers of the converted vector
    for value in (a.astype(np.float32), np.round(a).astype(np.int32), np.round(a) != 0):
        assert np.array_equal(call(dp, value), call(dp, value.astype(float)))


@pytest.mark.parametrize("name", CALLS)
@pytest.mark.parametrize("bad", ["text", "timedelta", "datetime", "object text"])
def test_text_and_dates_are_not_numbers(dp, name, bad):
    """numpy's astype(float) reads "0.1" and a timedelta's count as numbers; a vector
    of them is refused as a string t always was."""
    call, a = CALLS[name]
    value = {"text": a.astype(str), "timedelta": np.round(a).astype("m8[s]"),
             "datetime": np.round(a).astype("M8[D]"),
             "object text": np.array([str(v) for v in a], dtype=object)}[bad]
    with pytest.raises(SimulationError, match="must be numbers"):
        call(dp, value)


@pytest.mark.parametrize("name", CALLS)
def test_wrong_shapes_are_refused_naming_the_expected_and_given_shape(dp, name):
    call, a = CALLS[name]
    n = len(a)
    for value in (a[None, :], a[:, None], a[:0], a[:-1], np.append(a, 0.0),
                  np.tile(a, (3, 1))):
        message = re.escape(f"({n},)") + ".*" + re.escape(str(value.shape))
        with pytest.raises(SimulationError, match=message):
            call(dp, value)


def test_results_are_fresh_writable_float64_arrays_that_alias_nothing(dp):
    """Every result is a new array: writing into it, or a second call, changes nothing
    else (``params()`` returned the model's own default vector: writing into it
    changed every later call's parameters)."""
    calls = {name: (lambda a, call=call: call(dp, a)) for name, (call, _) in CALLS.items()
             if name not in ("rhs u", "rhs p")}
    calls.update(params=lambda a: dp.params(), input_vector=lambda a: dp.input_vector(),
                 neutral_state=lambda a: dp.neutral_state())
    for name, call in calls.items():
        a = CALLS.get(name, (None, X))[1]
        first = call(a)
        kept = first.copy()
        assert first.dtype == np.float64 and first.flags.writeable, name
        assert not np.shares_memory(first, a), name
        second = call(a * 1.5)
        assert first is not second and not np.shares_memory(first, second), name
        assert np.array_equal(first, kept), name
    before = dp.rhs(0.0, X)
    dp.params()[:] = 1.0
    dp.input_vector()[:] = 5.0
    assert np.array_equal(dp.rhs(0.0, X), before)
    assert dp.params()[4] == 9.81


def test_nan_in_the_state_propagates_through_rhs_and_is_refused_where_documented(dp):
    """rhs, like a solve_ivp fun, does not check x: NaN in a speed comes back as NaN
    (a solver sees it), NaN in q fails the factorisation and is named as NaN (it was
    reported as "mass matrix not positive definite"); jac, simulate, the inputs and
    the parameters refuse NaN by name."""
    speed, angle = X.copy(), X.copy()
    speed[3], angle[1] = np.nan, np.nan
    assert np.isnan(dp.rhs(0.0, speed)).any()
    assert np.isnan(dp.rhs_function()(0.0, speed)).any()
    for call, message in ((lambda: dp.rhs(0.0, angle), r"x must be finite.*\['q2'\]"),
                          (lambda: dp.rhs_function()(0.0, angle), r"x must be finite.*'q2'"),
                          (lambda: dp.jac(0.0, angle), r"x must be finite.*'q2'"),
                          (lambda: dp.simulate(angle, (0, 1)), "x0"),
                          (lambda: dp.rhs(0.0, X, u=[np.inf]), r"inputs must be finite"),
                          (lambda: dp.rhs(0.0, X, p={"g": np.nan}), r"parameters must be "
                                                                     r"finite; got \['g'\]")):
        with pytest.raises(SimulationError, match=message):
            call()


@pytest.mark.parametrize("t", [np.nan, np.inf, -np.inf, np.float64(np.nan)])
def test_the_fast_path_refuses_a_non_finite_time_as_rhs_does(dp, t):
    """``f(nan, x)`` passed the NaN to the C while ``rhs(nan, x)`` refused it."""
    f = dp.rhs_function()
    for call in (lambda: dp.rhs(t, X), lambda: f(t, X), lambda: f.inplace(t)):
        with pytest.raises(SimulationError, match="t must be finite"):
            call()


def test_times_of_every_numeric_kind_are_read_alike(dp):
    class F64(np.float64):
        pass
    f = dp.rhs_function()
    want = dp.rhs(0.25, X)
    for t in (np.float32(0.25), F64(0.25), np.array(0.25), np.longdouble(0.25)):
        assert np.array_equal(dp.rhs(t, X), want) and np.array_equal(f(t, X), want)
    for t in (np.array([0.25]), "0.25", None, 0.25j):
        for call in (dp.rhs, f):
            with pytest.raises(SimulationError, match="t must be a real number"):
                call(t, X)


def test_one_fast_path_shared_by_threads_gives_the_sequential_results(dp):
    """``f(t, x)`` wrote x into its one buffer and released the GIL in the C call, so
    another thread's x could replace it mid-call: results of the wrong state."""
    f = dp.rhs_function()
    states = np.random.default_rng(0).uniform(-2, 2, (3000, 4))
    want = [f(0.1, x) for x in states]
    for _ in range(4):
        with ThreadPoolExecutor(8) as pool:
            got = list(pool.map(lambda x: f(0.1, x), states))
        assert all(np.array_equal(a, b) for a, b in zip(got, want))


def test_threads_give_the_sequential_results(dp):
    states = np.random.default_rng(1).uniform(-1, 1, (8, 4))
    K = np.array([0.1, 0.2, 0.3, 0.4])

    def run(x):
        res = dp.simulate(x, (0.0, 2.0), u=lambda t, y: [-K @ y], events=lambda t, y: y[0],
                          dense_output=True)
        return res.y, res.t_events[0], res.sol(1.0), dp.rhs(0.3, x), dp.jac(0.3, x)
    want = [run(x) for x in states]
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(run, states))
    for a, b in zip(got, want):
        assert all(np.array_equal(u, v) for u, v in zip(a, b))


def test_a_long_c_run_releases_the_gil(dp):
    """While one thread integrates (out-of-line cffi calls release the GIL), Python in
    another keeps running: no pause as long as the C run."""
    x0 = np.array([1.5, 0.5, 0.0, 0.0])
    started = time.perf_counter()
    dp.simulate(x0, (0.0, 100.0), t_eval=[100.0], rtol=1e-13, atol=1e-13, max_steps=10**7)
    alone = time.perf_counter() - started
    worker = threading.Thread(target=dp.simulate, args=(x0, (0.0, 100.0)),
                              kwargs=dict(t_eval=[100.0], rtol=1e-13, atol=1e-13,
                                          max_steps=10**7))
    gaps, last = [], time.perf_counter()
    worker.start()
    while worker.is_alive():
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    assert len(gaps) > 100 and max(gaps) < max(0.5 * alone, 0.02)


def test_a_pickled_model_loads_without_the_symbolic_pipeline(dp):
    """The pickle names the runtime module it was loaded with: a spawned worker (joblib,
    Dask, multiprocessing with 'spawn') unpickled it by rendering the runtime's sources,
    importing sympy and the code generator (seconds per worker)."""
    code = ("import pickle, sys\n"
            "cm = pickle.loads(sys.stdin.buffer.read())\n"
            "print(cm.rhs(0.0, [0.1, 0.2, 0.3, 0.4]).tolist())\n"
            "print(sorted(m for m in ('sympy', 'symengine', 'modelgen.codegen.pipeline')"
            " if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], input=pickle.dumps(dp),
                         capture_output=True, check=True, cwd=ROOT).stdout.decode().splitlines()
    assert eval(out[0]) == dp.rhs(0.0, X).tolist()
    assert out[1] == "[]"


def test_a_model_whose_runtime_moved_still_unpickles(dp):
    """A pickle made where the runtime module lives elsewhere (another machine's cache)
    falls back to this machine's runtime module."""
    func, args = dp.__reduce__()
    manifest, path, runtime = args
    clone = func(manifest, path, ("_mg_runtime_elsewhere", "/nonexistent/_mg_runtime.so"))
    assert np.array_equal(clone.rhs(0.0, X), dp.rhs(0.0, X))


def test_jac_is_the_derivative_of_rhs_at_x_itself_off_unit_norm(ball):
    """cm.rhs evaluates the C at x as given (as the C rhs and Pinocchio's aba do), so
    cm.jac, solve_ivp's jac for it, is its derivative there, not at the normalised x;
    the quaternion columns are the derivatives along the raw components."""
    x = ball.neutral_state()
    x[:4] = 1.7 * np.array([0.8, 0.4, 0.2, 0.4])
    x[4:] = [0.5, -0.3, 0.2]
    e = 1e-6
    fd = np.column_stack([(ball.rhs(0.0, x + e * d) - ball.rhs(0.0, x - e * d)) / (2 * e)
                          for d in np.eye(ball.nx)])
    J = ball.jac(0.0, x)
    assert np.max(np.abs(J - fd)) <= 1e-6 * np.max(np.abs(J))
    assert np.max(np.abs(J - ball.jac(0.0, ball.project(x)))) > 1.0


@pytest.mark.parametrize("scale", [10.0, 0.1])
def test_the_stability_warning_is_taken_where_the_run_starts(ball, scale):
    """simulate normalises x0's quaternion; the stability heuristic took the Jacobian at
    the raw x0, so one run got |lambda|max 59.6 (x0's quaternion times 10) or no
    warning at all (times 0.1) instead of the 6.1 of the state it started from."""
    x = ball.neutral_state()
    x[:4] = [0.8, 0.4, 0.2, 0.4]
    x[4:] = [0.5, -0.3, 0.2]
    scaled = x.copy()
    scaled[:4] *= scale
    want = ball.stability_warning("rk4", 0.5, 0.0, ball.project(x))
    assert want is not None
    assert ball.stability_warning("rk4", 0.5, 0.0, scaled) == want
    runs = [ball.simulate(v, (0.0, 1.0), method="rk4", step=0.5) for v in (x, scaled)]
    assert np.allclose(runs[0].y, runs[1].y, rtol=1e-8, atol=1e-12)    # one run (unstable)
    assert runs[0].info["stability_warning"] == runs[1].info["stability_warning"] == want


def test_batch_shapes_are_the_documented_ones(dp):
    X0 = np.random.default_rng(2).uniform(-1, 1, (3, 4))
    res = dp.simulate_batch(np.asfortranarray(X0), (0.0, 1.0), t_eval=[0.5, 1.0],
                            P={"g": [9.81, 1.62, 3.7]})
    assert res.y.shape == (3, 4, 2) and res.t.shape == (2,) and res.status.shape == (3,)
    assert res.y.dtype == np.float64 and res.y.flags.writeable
    one = dp.simulate(X0[1], (0.0, 1.0), t_eval=[0.5, 1.0], p={"g": 1.62})
    assert np.array_equal(res.y[1], one.y)
    assert dp.simulate_batch(X0[:1], (0.0, 1.0)).y.shape == (1, 4, 1)
    with pytest.raises(SimulationError, match=r"X0 must have shape \(n_runs, 4\), got \(4,\)"):
        dp.simulate_batch(X0[0], (0.0, 1.0))
