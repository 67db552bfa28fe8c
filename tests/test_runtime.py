"""The Python runtime: argument handling, parameters, the fast path, failures."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate
from scipy.special import ellipk

import modelgen
from modelgen.errors import DerivationError, SimulationError
from modelgen.model.api import Model
from modelgen.errors import MassMatrixError

from conftest import MODELS


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


def test_attributes_describe_the_model(dp):
    assert dp.n == 2
    assert dp.coordinates == ("q1", "q2")
    assert dp.parameters == {"m1": 1.0, "m2": 1.0, "l1": 1.0, "l2": 1.0, "g": 9.81}
    assert dp.inputs == ("T1",)
    assert dp.bodies == ("rod1", "rod2")


def test_parameters_as_dict_array_or_defaults_agree(dp):
    q = [0.3, -0.4]
    p = np.array([2.0, 1.0, 1.5, 1.0, 9.81])
    assert np.array_equal(dp.mass_matrix(q, {"m1": 2.0, "l1": 1.5}), dp.mass_matrix(q, p))
    assert not np.array_equal(dp.mass_matrix(q), dp.mass_matrix(q, p))
    # the override changes nothing else: the default vector is untouched
    assert np.array_equal(dp.params(), [1.0, 1.0, 1.0, 1.0, 9.81])


@pytest.mark.parametrize("call, message", [
    (lambda cm: cm.mass_matrix([0.1]), r"q must have shape \(2,\), got \(1,\)"),
    (lambda cm: cm.rhs(0, [0, 0, 0]), r"x must have shape \(4,\)"),
    (lambda cm: cm.mass_matrix([0, 0], {"mass": 1}), "unknown parameter 'mass'"),
    (lambda cm: cm.mass_matrix([0, 0], {"g": float("nan")}), r"parameters must be finite; got \['g'\]"),
    (lambda cm: cm.mass_matrix([0, 0], [1, 2]), r"p must have shape \(5,\)"),
    (lambda cm: cm.generalized_forces(0, [0, 0], [0, 0], u={"T9": 1}), "unknown input 'T9'"),
])
def test_nonsense_arguments_raise_clear_errors(dp, call, message):
    with pytest.raises(SimulationError, match=message):
        call(dp)


def test_input_drives_generalized_force(dp):
    tau0 = dp.generalized_forces(0, [0.2, 0.1], [0, 0])
    tau1 = dp.generalized_forces(0, [0.2, 0.1], [0, 0], u=[2.5])
    assert tau1 - tau0 == pytest.approx([2.5, 0.0], abs=1e-15)
    assert np.array_equal(dp.generalized_forces(0, [0.2, 0.1], [0, 0], u={"T1": 2.5}), tau1)


def test_fast_paths_agree_with_rhs(dp):
    x = np.array([0.3, -0.2, 1.1, 0.4])
    f = dp.rhs_function(p={"m2": 2.0}, u=[0.5])
    expected = dp.rhs(0.0, x, u=[0.5], p={"m2": 2.0})
    first = f(0.0, x)
    assert np.array_equal(first, expected)
    assert f(0.0, x + 1) is not first           # fresh arrays: safe for solve_ivp
    out = np.empty(4)
    assert f(0.0, x, out) is out and np.array_equal(out, expected)
    f.x[:] = x
    f.inplace(0.0)
    assert np.array_equal(f.out, expected)


def test_solve_ivp_gives_the_elliptic_period_of_the_pendulum(compiled):
    """Released from horizontal, L = 1, g = 9.81: T = 4 sqrt(L/g) K(sin^2(pi/4))."""
    cm = compiled("simple_pendulum")
    period = 4 * np.sqrt(1 / 9.81) * ellipk(np.sin(np.pi / 4) ** 2)
    assert period == pytest.approx(2.367841947576237, rel=1e-15)
    q0 = np.pi / 2                       # q is measured from the downward vertical

    def crossing(t, x):
        return x[0]
    crossing.direction = 1
    sol = scipy.integrate.solve_ivp(cm.rhs, (0, 3), [q0, 0.0], method="DOP853",
                                    rtol=1e-12, atol=1e-12, events=crossing)
    # released at rest at +90 deg, it passes the bottom with q increasing after 3/4 period
    assert sol.t_events[0][0] == pytest.approx(0.75 * period, rel=1e-9)


def test_singular_mass_matrix_is_detected_at_generation(tmp_path):
    m = Model("massless_tip")
    m.add_coordinates("q1", "q2")
    m.add_parameter("m", 1.0)
    m.add_base("B1", parent="E", axis=3, angle="q1")
    m.add_base("B2", parent="B1", axis=1, angle="q2")   # spins the rod about its own axis
    m.add_point("G", parent="O", base="B1", coordinates=[1, 0, 0])
    m.add_body("rod", mass="m", G="G", base="B2")          # a particle: no inertia about x
    with pytest.raises(DerivationError, match="coordinate 'q2'"):
        modelgen.load(m, tmp_path)


def test_rhs_reports_the_failing_pivot_as_mass_matrix_error(build_root):
    cm = modelgen.load(MODELS / "double_pendulum.yaml", build_root / "double_pendulum_crba",
                       formulation="crba")
    with pytest.raises(MassMatrixError, match=r"pivot 1 \(coordinate 'q1'\)"):
        cm.rhs(0.0, [0.1, 0.2, 0, 0], p={"m1": 0.0, "m2": 0.0})


@pytest.mark.parametrize("text, key, problem", [
    ("name: empty\nbodies: {}\n", "coordinates", "the model has no generalized coordinates"),
    ("name: nobody\ncoordinates: [q1]\n", "bodies", "the model has no bodies"),
])
def test_model_without_coordinates_or_bodies_is_refused(tmp_path, text, key, problem):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    with pytest.raises(modelgen.ModelError, match=problem) as exc:
        modelgen.load(path, tmp_path / "out")
    assert exc.value.key == key and exc.value.file == str(path)


@pytest.mark.parametrize("call, message", [
    (lambda cm: cm.rhs_function()(0.0, 1.0), r"x must have shape \(4,\), got \(\)"),
    (lambda cm: cm.rhs_function()(0.0, np.zeros((1, 4))), r"x must have shape \(4,\), got \(1, 4\)"),
    (lambda cm: cm.rhs(0.0, np.zeros(4) + 0.5j), "x must be real"),
    (lambda cm: cm.rhs_function()(0.0, np.zeros(4) + 0.5j), "x must be real"),
    (lambda cm: cm.rhs(0.0, np.zeros(4), u={"T1": np.nan}), r"inputs must be finite; got \['T1'\]"),
    (lambda cm: cm.rhs(0.0, np.zeros(4), u=[np.inf]), r"inputs must be finite"),
    (lambda cm: cm.rhs(np.nan, np.zeros(4)), "t must be finite"),
    (lambda cm: cm.generalized_forces(np.inf, [0, 0], [0, 0]), "t must be finite"),
    (lambda cm: cm.rhs(0.0, ["a", "b", "c", "d"]), "x must be numbers"),
])
def test_runtime_refuses_what_it_would_silently_get_wrong(dp, call, message):
    """No broadcasting, no dropped imaginary part, no NaN input or time passed to the C."""
    with pytest.raises(SimulationError, match=message):
        call(dp)


def test_simulate_result_names_states_and_outputs(dp):
    res = dp.simulate([1.0, 0.5, 0.0, 0.0], (0.0, 1.0), t_eval=np.linspace(0, 1, 11),
                      dense_output=True)
    assert res.success and res.y.shape == (4, 11)
    assert np.array_equal(res["q1"], res.y[0]) and np.array_equal(res["q2_dot"], res.y[3])
    assert "q1" in res and "nfev" in res and res["nfev"] == res.nfev
    with pytest.raises(KeyError, match="neither a state"):
        res["elbow"]
    # sol is the method's own dense output: it agrees with t_eval sampling anywhere
    assert np.allclose(res.sol(res.t), res.y, rtol=0, atol=1e-12)
    between = np.linspace(0.0, 1.0, 37)
    sampled = dp.simulate([1.0, 0.5, 0.0, 0.0], (0.0, 1.0), t_eval=between)
    assert np.allclose(res.sol(between), sampled.y, rtol=0, atol=1e-11)
    assert res.sol(0.55).shape == (4,)


def test_result_tables_round_trip(dp, tmp_path):
    import csv
    res = dp.simulate([1.0, 0.5, 0.0, 0.0], (0.0, 0.5), t_eval=np.linspace(0, 0.5, 6))
    res.energy = dp.energies(res)
    with open(res.to_csv(tmp_path / "r.csv")) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "q1", "q2", "q1_dot", "q2_dot", "kinetic", "potential", "total"]
    assert np.array_equal(np.array(rows[1:], dtype=float)[:, 1:5], res.y.T)
    with np.load(res.to_npz(tmp_path / "r.npz")) as npz:
        assert np.array_equal(npz["y"], res.y) and list(npz["state_names"]) == list(dp.state_names)


def test_each_column_of_the_table_is_a_key_by_its_csv_name(tmp_path):
    """What the CSV's header names (an output's column, the energies, a work) indexes
    the result too, as a series (n_times,), equal to that column of the table (a
    one-column output named as its column, ``energy``, is the output: (n_times, 1))."""
    from conftest import SCENES
    import modelgen
    res = modelgen.load_scene(SCENES / "dp_damped.yaml", tmp_path).run()
    table = res.table()
    for k, column in enumerate(res.columns()):
        assert column in res and np.array_equal(np.ravel(res[column]), table[:, k]), column
        assert column in res.keys()
    assert res["elbow.x"].shape == res.t.shape and "elbow.w" not in res
    with pytest.raises(KeyError, match="nor a column of the table"):
        res["elbow.w"]


def test_plot_returns_a_figure_and_leaves_pyplot_alone(dp, tmp_path):
    import matplotlib
    backend = matplotlib.get_backend()
    res = dp.simulate([1.0, 0.5, 0.0, 0.0], (0.0, 0.5), t_eval=np.linspace(0, 0.5, 6))
    res.energy = dp.energies(res)
    fig = res.plot(tmp_path / "r.png", conservative=True)
    from matplotlib.figure import Figure
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
    assert matplotlib.get_backend() == backend


def test_everywhere_singular_model_is_refused_fresh_and_cached(tmp_path, capsys):
    """A double pendulum whose second base turns with q1 too: q2 moves nothing.

    Refused on the first load, on a second load from the same build cache,
    by generate_model, and by `modelgen generate` (exit status 2), in one message."""
    from conftest import MODELS
    from modelgen.cli import main
    text = (MODELS / "double_pendulum.yaml").read_text()
    assert "B2: {parent: B1, axis: 3, angle: q2}" in text
    path = tmp_path / "stuck.yaml"
    path.write_text(text.replace("B2: {parent: B1, axis: 3, angle: q2}",
                                 "B2: {parent: B1, axis: 3, angle: q1}"))
    for _ in range(2):
        with pytest.raises(DerivationError, match="coordinate 'q2'") as loaded:
            modelgen.load(path, tmp_path / "out")
    # generate_model checks through ctypes, not a CompiledModel: the same words
    with pytest.raises(DerivationError, match="coordinate 'q2'") as exc:
        modelgen.generate_model(path, tmp_path / "out")
    assert str(exc.value) == str(loaded.value)
    for force in ([], ["--force"]):
        capsys.readouterr()
        assert main(["generate", str(path), "-o", str(tmp_path / "out"), *force]) == 2
        assert capsys.readouterr().err.strip() == f"modelgen: error: {exc.value}"


def test_compiled_model_pickles_and_runs_in_another_process(dp):
    import concurrent.futures
    import pickle
    clone = pickle.loads(pickle.dumps(dp))
    x = [0.3, -0.2, 1.0, 0.5]
    assert np.array_equal(clone.rhs(0.0, x), dp.rhs(0.0, x))
    with concurrent.futures.ProcessPoolExecutor(1) as pool:
        remote = pool.submit(dp.rhs, 0.0, x).result()
    assert np.array_equal(remote, dp.rhs(0.0, x))


@pytest.mark.parametrize("mass, message", [
    ("1.7e308", "overflows double precision"),
    ("5e-324", "too small for double precision"),
])
def test_defaults_beyond_double_range_are_named_not_called_massless(tmp_path, mass, message,
                                                                   capsys):
    """A mass of 1e308 overflows A, one of 5e-324 underflows it: the error says so and
    names the parameter, instead of "coordinate 'q' moves no mass"."""
    from conftest import MODELS
    text = (MODELS / "double_pendulum.yaml").read_text()
    path = tmp_path / "extreme.yaml"
    path.write_text(text.replace("m1: 1.0, m2: 1.0", f"m1: {mass}, m2: {mass}"))
    assert f"m1: {mass}, m2: {mass}" in path.read_text()
    with pytest.raises(DerivationError, match=message) as exc:
        modelgen.load(path, tmp_path / "out")
    assert "m1 = " in str(exc.value) and "moves no mass" not in str(exc.value)
    # `modelgen generate` checks through ctypes, not a CompiledModel: the same words
    from modelgen.cli import main
    assert main(["generate", str(path), "-o", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip() == f"modelgen: error: {exc.value}"
