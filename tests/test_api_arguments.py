"""The Python API refuses nonsensical arguments with a modelgen error naming the
argument, before any C runs, and never discards a finished run over a heuristic.

Each case is a call that used to end in a raw numpy, cffi or Python exception
(TypeError, OverflowError, AttributeError...), return a wrong value silently, or
report a bad option as a failure to converge; the references are the same call
written the documented way.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from modelgen.errors import (ArgumentTypeError, ArgumentValueError, ModelError, ModelgenError,
                             SimulationError)

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
SCENES = MODELS / "scenes"
X = [0.1, 0.2, 0.0, 0.0]


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


@pytest.fixture(scope="module")
def cp(compiled):
    """The cart-pole: one input, F."""
    return compiled("cart_pole")


@pytest.fixture(scope="module")
def dp_lin(build_root):
    import modelgen
    return modelgen.load(MODELS / "double_pendulum.yaml", build_root / "dp_args_lin",
                         linearize=True)


@pytest.fixture(scope="module")
def dp_frames(build_root):
    import modelgen
    return modelgen.load(MODELS / "double_pendulum.yaml", build_root / "dp_args_frames",
                         frames=["F2"])


@pytest.fixture(scope="module")
def push(build_root):
    """The cart-pole scene, with a sampled (linear) input F."""
    import modelgen
    return modelgen.load_scene(SCENES / "cart_pole_push.yaml", build_root / "cpp_args")


# -- 1, 6: sampled inputs are checked up front, the same for every method --------------------

BAD_SAMPLES = [
    ((0.0, 1.0, "hold"), ArgumentValueError, "u's sample times must be a non-empty 1-D array"),
    ((np.array([]), np.array([]), "linear"), ArgumentValueError,
     "u's sample times must be a non-empty 1-D array"),
    (([0, 1], [1, 2, 3], "linear"), ArgumentValueError,
     r"u's sample values must have shape \(2, 1\)"),
    ((["a", "b"], [1, 2], "hold"), SimulationError, "u's sample times must be numbers"),
    (([0, 1], [1.0, np.nan], "hold"), ArgumentValueError, "u's sample values must not be NaN"),
    (([0, 1], [1j, 2], "linear"), SimulationError, "u's sample values must be real"),
    (([0, np.nan], [1, 2], "linear"), ArgumentValueError, "u's sample times must be finite"),
]


@pytest.mark.parametrize("method", [{"method": "rk4", "step": 0.01}, {"method": "dop853"}],
                         ids=["rk4", "dop853"])
@pytest.mark.parametrize("u, error, message", BAD_SAMPLES)
def test_bad_input_samples_are_refused_before_the_run_by_every_method(cp, method, u, error,
                                                                       message):
    with pytest.raises(error, match=message):
        cp.simulate([0, 0.1, 0, 0], (0, 1), u=u, **method)


def test_a_one_column_sample_list_equals_the_column_array_with_the_stability_warning(cp):
    """Values (n,) for a one-input model are the column (n, 1); the fixed-step run's
    stability heuristic reads the same checked samples."""
    flat = cp.simulate([0, 0.1, 0, 0], (0, 1), method="rk4", step=0.01,
                       u=([0.0, 0.5], [0.0, 1.0], "hold"))
    column = cp.simulate([0, 0.1, 0, 0], (0, 1), method="rk4", step=0.01,
                         u=(np.array([0.0, 0.5]), np.array([[0.0], [1.0]]), "hold"))
    assert flat.success and np.array_equal(flat.y, column.y)


def test_a_failing_stability_heuristic_keeps_the_finished_run(cp):
    """The heuristic calls a feedback u(t0, x0) once more after the run: an exception
    there must not discard the result."""
    calls = []

    def u(t, x):
        calls.append(t)
        return 0.0
    reference = cp.simulate([0, 0.1, 0, 0], (0, 1), method="rk4", step=0.01, u=u)
    in_run = len(calls) - 1         # the heuristic's own call came last

    def flaky(t, x):
        calls.append(t)
        if len(calls) > in_run:
            raise RuntimeError("only the heuristic sees this")
        return 0.0
    calls.clear()
    res = cp.simulate([0, 0.1, 0, 0], (0, 1), method="rk4", step=0.01, u=flaky)
    assert res.success and np.array_equal(res.y, reference.y)
    assert "stability_warning" not in res.info


@pytest.mark.parametrize("chunk, error", [
    (None, ArgumentTypeError), ("a", ArgumentTypeError), (float("nan"), ArgumentValueError),
    (10**30, ArgumentValueError), (0, ArgumentValueError), (2.5, ArgumentValueError)])
def test_chunk_must_be_a_whole_number_of_rows(dp, chunk, error):
    with pytest.raises(error, match="chunk must be"):
        dp.simulate(X, (0, 1), chunk=chunk)


def test_a_whole_chunk_gives_the_same_run(dp):
    assert np.array_equal(dp.simulate(X, (0, 1), chunk=3.0).y, dp.simulate(X, (0, 1)).y)


def test_a_progress_that_is_not_callable_is_refused_before_the_run(dp):
    with pytest.raises(ArgumentTypeError, match=r"progress must be None or a callable"):
        dp.simulate(X, (0, 1), progress="bar")


# -- 2: frame routines that take speeds ------------------------------------------------------

@pytest.mark.parametrize("routine", ["frame_velocity", "frame_bias_acceleration"])
def test_frame_routines_check_their_speeds(dp_frames, routine):
    fn = getattr(dp_frames, routine)
    with pytest.raises(SimulationError, match="v must be numbers"):
        fn([0.0, 0.0], None, "F2")
    with pytest.raises(SimulationError, match=r"v must have shape \(2,\)"):
        fn([0.0, 0.0], [1.0], "F2")
    assert np.all(np.isfinite(fn([0.1, 0.2], [0.3, 0.4], "F2")))


# -- 3, 5: simulate_batch checks X0, P and threads as simulate checks x0 and p ------------------

@pytest.mark.parametrize("P, message", [
    (np.ones((1, 5)) * 1j, "P must be real"), ([[1, 1, 1, 1, 9.81j]], "P must be real"),
    ({"g": 1j}, r"P\['g'\] must be real"), ("abc", "P must be numbers"),
    ({"g": "a"}, r"P\['g'\] must be numbers")])
def test_batch_parameters_must_be_real_numbers(dp, P, message):
    with pytest.raises(SimulationError, match=message):
        dp.simulate_batch(np.zeros((1, 4)), (0, 1), P=P)


def test_a_batch_parameter_column_of_the_wrong_length_is_named(dp):
    with pytest.raises(ArgumentValueError, match=r"P\['g'\] must be one value or one per run "
                                                 r"\(3\), got shape \(2,\)"):
        dp.simulate_batch(np.zeros((3, 4)), (0, 1), P={"g": [1, 2]})


def test_non_finite_batch_parameters_are_named(dp):
    with pytest.raises(ArgumentValueError, match=r"parameters must be finite; got \['g'\]"):
        dp.simulate_batch(np.zeros((2, 4)), (0, 1), P={"g": [1.0, np.inf]})


@pytest.mark.parametrize("X0, message", [
    (np.zeros((1, 4)) + 1j, "X0 must be real"), ([[1, 2, 3, 4], [1, 2]], "X0 must be numbers"),
    ("abc", "X0 must be numbers"), ([[10**400, 0, 0, 0]], "X0 must be numbers")])
def test_batch_initial_states_must_be_real_numbers(dp, X0, message):
    with pytest.raises(SimulationError, match=message):
        dp.simulate_batch(X0, (0, 1))


@pytest.mark.parametrize("threads, error", [
    (None, ArgumentTypeError), ("a", ArgumentTypeError), (float("nan"), ArgumentValueError),
    (2.5, ArgumentValueError), (0, ArgumentValueError)])
def test_threads_must_be_a_whole_number_of_at_least_one(dp, threads, error):
    with pytest.raises(error, match="threads must be"):
        dp.simulate_batch(np.zeros((3, 4)), (0, 1), threads=threads)


def test_batch_parameters_by_row_and_by_name_agree(dp):
    P = np.tile(dp.params(), (2, 1))
    P[:, list(dp.parameters).index("g")] = [9.81, 1.62]
    rows = dp.simulate_batch([X, X], (0, 1), P=P, threads=2.0)
    named = dp.simulate_batch([X, X], (0, 1), P={"g": [9.81, 1.62]})
    assert np.array_equal(rows.y, named.y)


# -- 4, 7: huge integers and the time of jac ----------------------------------------------------

def test_integers_beyond_a_double_are_refused_by_name(dp):
    with pytest.raises(SimulationError, match="x must be numbers"):
        dp.rhs(0, [10**400, 0, 0, 0])
    with pytest.raises(SimulationError, match="t must be a real number"):
        dp.rhs(10**400, X)
    with pytest.raises(ArgumentValueError, match="t_span must be finite"):
        dp.simulate(X, (0, 10**400))


@pytest.mark.parametrize("t, error, message", [
    (None, SimulationError, "t must be a real number"),
    ("a", SimulationError, "t must be a real number"),
    (np.nan, ArgumentValueError, "t must be finite")])
def test_jac_checks_t_as_rhs_does(dp, t, error, message):
    with pytest.raises(error, match=message):
        dp.jac(t, X)
    with pytest.raises(error, match=message):
        dp.rhs(t, X)


# -- 8: equilibrium and linearize options -------------------------------------------------------

@pytest.mark.parametrize("options, error, message", [
    ({"tol": "a"}, ArgumentTypeError, "tol must be a number > 0"),
    ({"tol": -1}, ArgumentValueError, "tol must be finite and > 0"),
    ({"tol": np.nan}, ArgumentValueError, "tol must be finite and > 0"),
    ({"max_iter": 2.5}, ArgumentValueError, "max_iter must be a whole number"),
    ({"max_iter": 0}, ArgumentValueError, "max_iter must be >= 1")])
def test_equilibrium_options_are_refused_not_reported_as_non_convergence(dp_lin, options, error,
                                                                         message):
    with pytest.raises(error, match=message):
        dp_lin.equilibrium([0.1, 0.1], **options)


def test_equilibrium_with_checked_options_finds_the_hanging_rest(dp_lin):
    q = dp_lin.equilibrium([0.1, 0.1], tol=1e-12, max_iter=50.0)
    assert np.max(np.abs(dp_lin.rhs(0.0, np.concatenate([q, [0, 0]]))[2:])) <= 1e-12


@pytest.mark.parametrize("outputs", [3, [3], b"tip"])
def test_linearize_outputs_must_be_names(dp_lin, outputs):
    with pytest.raises(ArgumentTypeError, match="outputs must be None, a name or a sequence"):
        dp_lin.linearize(X, outputs=outputs)


# -- 9: project and energies --------------------------------------------------------------------

@pytest.mark.parametrize("x, error, message", [
    ([1.0], ArgumentValueError, r"x must be a state, shape \(4,\), or a configuration"),
    (None, SimulationError, "x must be numbers"), ("ab", SimulationError, "x must be numbers"),
    ([1j, 0], SimulationError, "x must be real")])
def test_project_checks_its_state(dp, x, error, message):
    with pytest.raises(error, match=message):
        dp.project(x)


def test_project_returns_a_state_or_a_configuration_unchanged_without_quaternions(dp):
    assert np.array_equal(dp.project(X), X) and np.array_equal(dp.project(X[:2]), X[:2])


@pytest.mark.parametrize("quaternion, unit", [
    ([1e200, 0, 0, 0], [1, 0, 0, 0]), ([1e-170, 0, 0, 0], [1, 0, 0, 0]),
    ([0, -3e-160, 4e-160, 0], [0, -0.6, 0.8, 0]), ([1, 2, 3, 4], np.arange(1, 5) / 30 ** 0.5)])
def test_quaternions_far_from_unit_length_are_normalised_without_overflow(compiled, quaternion,
                                                                          unit):
    """The squares of 1e200 overflowed (the quaternion became zero), those of 1e-170
    underflowed (NaN); project is the C's <name>_project, which scales first."""
    cm = compiled("tennis_racket")
    (k, *_), = cm.quaternions
    x = np.zeros(cm.nx)
    x[k:k + 4] = quaternion
    assert np.allclose(cm.project(x)[k:k + 4], unit, rtol=0, atol=1e-15)


def test_a_quaternion_that_cannot_be_normalised_stops_the_run_as_projection(compiled):
    cm = compiled("tennis_racket")
    (k, *_), = cm.quaternions
    x = np.zeros(cm.nx)
    x[k:k + 4] = [np.inf, 0, 0, 0]
    assert np.all(np.isnan(cm.project(x)[k:k + 4]))
    system = cm.ffi.new("mg_system *")
    getattr(cm.lib, f"{cm.name}_system")(system)
    assert system.project(system.model, cm._ptr(cm.params()), cm._ptr(x)) != 0
    x[k:k + 4] = [2, 0, 0, 0]
    assert system.project(system.model, cm._ptr(cm.params()), cm._ptr(x)) == 0
    assert list(x[k:k + 4]) == [1, 0, 0, 0]


@pytest.mark.parametrize("res", [np.zeros((4, 3)), None])
def test_energies_takes_a_result(dp, res):
    with pytest.raises(ArgumentTypeError, match="energies takes the Result of simulate"):
        dp.energies(res)


# -- 10: load's options --------------------------------------------------------------------------

def test_load_refuses_options_that_are_not_build_options(build_root):
    import modelgen
    with pytest.raises(ArgumentTypeError, match="options must be a BuildOptions or None, got "
                                                "dict; fix: options=BuildOptions"):
        modelgen.load(MODELS / "double_pendulum.yaml", build_root / "dp_args_opt",
                      options={"jacobian": True})


def test_load_refuses_frames_that_are_not_names(build_root):
    import modelgen
    with pytest.raises(ArgumentTypeError, match="frames must be a frame name or a list"):
        modelgen.load(MODELS / "double_pendulum.yaml", build_root / "dp_args_opt", frames=3)


@pytest.mark.parametrize("flag, value", [("jacobian", "no"), ("derivatives", 1),
                                         ("linearize", "yes")])
def test_load_refuses_yes_no_options_that_are_not_booleans(build_root, flag, value):
    # "no" is truthy: it used to build the Jacobian
    import modelgen
    with pytest.raises(ArgumentTypeError, match=f"{flag} must be True or False"):
        modelgen.load(MODELS / "double_pendulum.yaml", build_root / "dp_args_opt",
                      **{flag: value})
    from modelgen.codegen.options import BuildOptions
    assert BuildOptions(jacobian=np.bool_(True)).jacobian is True


def test_a_bad_build_budget_is_refused_on_a_cache_hit_too(dp, build_root):
    """``dp`` is built: the load below is an index hit, which never reached the build's
    own check of max_operations."""
    import modelgen
    with pytest.raises(ModelError, match="max_operations must be a positive integer"):
        modelgen.load(MODELS / "double_pendulum.yaml", build_root / "double_pendulum",
                      max_operations="a")
    assert modelgen.load(MODELS / "double_pendulum.yaml", build_root / "double_pendulum",
                         max_operations=10**6).n == 2


# -- 11: scenes ----------------------------------------------------------------------------------

def test_scene_inputs_at_checks_t(push):
    with pytest.raises(SimulationError, match="t must be a real number"):
        push.inputs_at("a")
    with pytest.raises(ArgumentValueError, match="t must be finite"):
        push.inputs_at(np.nan)
    assert push.inputs_at(0.6) == {"F": 10.0}


def test_scene_animate_names_a_directory_under_a_file_and_a_missing_result(push, tmp_path):
    res = push.run()
    (tmp_path / "file").write_text("")
    with pytest.raises(ModelgenError, match=r"its directory .*file.* is under a file, not a "
                                            r"directory; fix: choose a path"):
        push.animate(res, tmp_path / "file" / "sub" / "a.html", max_frames=5)
    with pytest.raises(ArgumentTypeError, match="the result must be the Result of a run"):
        push.animate(None, tmp_path / "a.html")
