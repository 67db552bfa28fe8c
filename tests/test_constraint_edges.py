"""Constrained models at their edges: batches and sweeps off the constraints,
length scales far from a metre, constraints real on part of their range only,
dependent coordinates the constraints do not involve, dead points and NaN, and
hostile arguments.

Each test is a case that used to be accepted silently, stop a regular run, or
end in a raw Python or numpy exception; the references are the metre-scale
model near the origin, Newton's own result, or the values the error message
prints put back into the model.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

import modelgen
from modelgen.errors import ArgumentTypeError, ArgumentValueError, ModelError, SimulationError
from modelgen.model.api import Model
from modelgen.sim import assemble

from conftest import MODELS, SCENES
from constrained_references import WHEEL_DISC

FOUR_BAR = (MODELS / "four_bar.yaml").read_text()
#: the four-bar in millimetres (every length times 1000, g in mm/s^2): the same motion
MM = {"a": 1e3, "b": 2e3, "c": 2e3, "d": 2.5e3, "g": 9810.0}
#: a circle of radius L: y dependent, the rest is the test's
CIRCLE = """\
name: {name}
coordinates: [x, y]
parameters: {{L: 1.0, m: 1.0, g: 9.81}}
points:
  P: {{coordinates: [x, y, 0]}}
bodies:
  b: {{mass: m, G: P, base: E}}
gravity: [0, -g, 0]
constraints:
  circle: {{type: position, expression: "{expression}"}}
dependent: {{coordinates: [y], speeds: [{speed}]}}
"""


def write(tmp_path, text: str, name: str):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def four_bar(compiled):
    return compiled("four_bar")


@pytest.fixture(scope="module")
def far(build_root):
    """The four-bar with its ground pivots at X0 and X0 + d on the x axis."""
    text = FOUR_BAR.replace("name: four_bar", "name: four_bar_far").replace(
        "g: 9.81}", "g: 9.81, X0: 0.0}").replace(
        "  D:  {coordinates: [d, 0, 0]}",
        "  A0: {coordinates: [X0, 0, 0]}\n  D:  {coordinates: [X0 + d, 0, 0]}").replace(
        "P1: {from: O,", "P1: {from: A0,").replace("G1: {from: O,", "G1: {from: A0,")
    path = build_root / "four_bar_far.yaml"
    path.write_text(text)
    return modelgen.load(path, build_root / "four_bar_far")


def state(cm, q1=0.3, q1_dot=2.0, p=None):
    q = cm.assemble([q1, 1.0, 2.0], keep=["q1"], p=p)
    return np.concatenate([q, cm.consistent_speeds(q, [q1_dot, 0.0, 0.0], p)])


def bound(scale: float) -> float:
    """What a projected residual may be: the absolute floor, or a few rounding errors
    of positions of size ``scale``."""
    return max(assemble.ASSEMBLY_TOL, 16 * np.finfo(float).eps * scale)


def printed(message: str, names) -> dict:
    """The values ``name = value`` an error message prints for ``names``."""
    return {name: float(re.search(rf"\b{name} = ([-+0-9.e]+)", message).group(1))
            for name in names}


# -- 1: a batch or a sweep never starts a run off the constraints ----------------------

def test_simulate_batch_refuses_a_row_off_the_constraints_as_simulate_does(four_bar):
    good = state(four_bar)
    bad = np.array([0.3, 1.0, 2.0, 2.0, 0.0, 0.0])
    with pytest.raises(SimulationError, match=r"run 1's initial state is off the position "
                                              r"constraints.*X0\[1\]\[:nq\] = cm.assemble"):
        four_bar.simulate_batch(np.array([good, bad]), (0.0, 1.0))
    # on the loop with the default coupler, off it with run 1's
    with pytest.raises(SimulationError, match="run 1's initial state is off"):
        four_bar.simulate_batch(np.array([good, good]), (0.0, 1.0), P={"b": [2.0, 2.3]})
    res = four_bar.simulate_batch(np.array([good, good]), (0.0, 0.5))
    assert list(res.status) == [0, 0]


def test_a_sweep_over_the_crank_assembles_the_dependent_coordinates_for_each_value(build_root):
    """The audit's `modelgen sweep four_bar_swing.yaml --init q1=0.3:1.3:3`: every run
    starts at its swept q1 (not a projection that moves it), on the loop, with the
    dependent speeds from q1_dot; q2, q3 are Newton's from the scene's values."""
    pytest.importorskip("xarray")
    scene = modelgen.load_scene(SCENES / "four_bar_swing.yaml", build_root / "edges_swing")
    cm = scene.model
    q1 = np.array([0.3, 0.8, 1.3])
    ds = modelgen.sweep(scene, initial={"q1": q1}, t_span=(0.0, 0.5),
                        t_eval=np.array([0.0, 0.5]))
    assert list(ds.status.values) == [0, 0, 0]
    x0 = np.array([[float(ds[name].isel(run=r, time=0)) for name in cm.state_names]
                   for r in range(3)])
    assert np.array_equal(x0[:, 0], q1)
    assert np.array_equal(x0[:, 3], np.full(3, 2.0))
    base = scene.initial_state()
    for r in range(3):
        expected = cm.assemble(np.r_[q1[r], base[1:3]], keep=["q1"])
        assert np.allclose(x0[r, :3], expected, rtol=0, atol=1e-12)
        assert np.max(np.abs(cm.constraint_residuals(x0[r, :3]))) <= 1e-12
        assert np.max(np.abs(cm.constraint_jacobian(x0[r, :3]) @ x0[r, 3:])) <= 1e-12
    # a swept coupler length: each run is assembled with its own
    ds = modelgen.sweep(scene, parameters={"b": [1.9, 2.0, 2.1]}, t_span=(0.0, 0.1),
                        t_eval=np.array([0.0]))
    for r, b in enumerate([1.9, 2.0, 2.1]):
        q = np.array([float(ds[name].isel(run=r, time=0)) for name in ("q1", "q2", "q3")])
        assert q[0] == 0.3
        assert np.max(np.abs(cm.constraint_residuals(q, p={"b": b}))) <= 1e-12
    with pytest.raises(ArgumentValueError, match="initial q2 is swept, but it is a dependent"):
        modelgen.sweep(scene, initial={"q2": [0.9, 1.0]}, t_span=(0.0, 0.1))
    # with a coupler of 0.1 the loop cannot close at the scene's crank angle
    with pytest.raises(SimulationError, match=r"run 1 \(b = 0.1\) cannot start on the "
                                              r"constraints"):
        modelgen.sweep(scene, parameters={"b": [2.0, 0.1]}, t_span=(0.0, 0.1))


# -- 2: the projection's and assembly's tolerance follow the length scale --------------

def test_the_four_bar_in_millimetres_runs_and_assembles_as_in_metres(four_bar):
    t = np.linspace(0.0, 10.0, 101)
    runs = {}
    for name, p in (("m", None), ("mm", MM)):
        x0 = state(four_bar, p=p)
        res = four_bar.simulate(x0, (0.0, 10.0), t_eval=t, method="dop853", rtol=1e-10,
                                atol=1e-12, p=p)
        assert res.status == 0, (name, res.message)
        f = np.array([four_bar.constraint_residuals(q, p) for q in res.y[:3].T])
        # the absolute floor in metres, the rounding of positions of 2500 mm in mm
        assert np.max(np.abs(f)) <= bound(1.0 if p is None else 2500.0)
        runs[name] = res.y[:3]
    assert np.max(np.abs(runs["mm"] - runs["m"])) <= 1e-7
    for theta in np.linspace(0.0, 2 * np.pi, 25):
        q = four_bar.assemble([theta, 1.0, 2.0], keep=["q1"], p=MM)
        assert np.max(np.abs(four_bar.constraint_residuals(q, MM))) <= 1e-11
        assert np.allclose(q, four_bar.assemble([theta, 1.0, 2.0], keep=["q1"]), rtol=0,
                           atol=1e-12)


def test_the_four_bar_two_kilometres_from_the_origin_runs_as_at_the_origin(far):
    t = np.linspace(0.0, 10.0, 101)
    y = []
    for x0_pivot in (0.0, 2000.0):
        p = {"X0": x0_pivot}
        res = far.simulate(state(far, p=p), (0.0, 10.0), t_eval=t, method="dop853",
                           rtol=1e-10, atol=1e-12, p=p)
        assert res.status == 0, res.message
        f = np.array([far.constraint_residuals(q, p) for q in res.y[:3].T])
        assert np.max(np.abs(f)) <= bound(max(1.0, x0_pivot))
        y.append(res.y[:3])
    assert np.max(np.abs(y[1] - y[0])) <= 1e-6


def test_the_c_projection_and_python_assembly_accept_the_same_states(far, four_bar):
    """Both stop at the absolute floor or after a step below STEP_TOL (one constant,
    written into the C), and both reach the rounding level of the millimetre and the
    far-off four-bar from a state 1e-6 (relative) off it."""
    source = (four_bar.path.parent / "four_bar.c").read_text()
    step = re.search(r"#define FOUR_BAR_PROJECT_STEP_TOL (\S+)", source).group(1)
    floor = re.search(r"#define FOUR_BAR_PROJECT_TOL (\S+)", source).group(1)
    assert float(step) == assemble.STEP_TOL and float(floor) == assemble.ASSEMBLY_TOL
    rng = np.random.default_rng(3)
    for cm, p, scale in ((four_bar, MM, 2500.0), (far, {"X0": 2000.0}, 2000.0),
                         (four_bar, None, 1.0)):
        constrain = getattr(cm.lib, f"{cm.name}_constrain")
        for _ in range(5):
            x = state(cm, q1=rng.uniform(-np.pi, np.pi), p=p)
            x[:3] += 1e-6 * rng.standard_normal(3)
            q_python = cm.assemble(x[:3], p=p)
            assert constrain(cm._ptr(cm.params(p)), cm._ptr(x)) == 0
            for q in (x[:3], q_python):
                assert np.max(np.abs(cm.constraint_residuals(q, p))) <= bound(scale)
            # the same minimum-norm Gauss-Newton: the same configuration
            assert np.allclose(x[:3], q_python, rtol=0, atol=1e-12)


# -- 3: a constraint real on part of the coordinates' range ----------------------------

def test_a_square_root_constraint_is_checked_where_it_is_real(tmp_path):
    path = write(tmp_path, CIRCLE.format(name="circle_sqrt", expression="sqrt(L**2 - x**2) - y",
                                         speed="y_dot"), "circle_sqrt")
    cm = modelgen.load(path, tmp_path / "build")
    q = cm.assemble([0.3, 0.5], keep=["x"])
    assert abs(q[1] - np.sqrt(1 - 0.3**2)) <= 1e-15
    res = cm.simulate(np.concatenate([q, cm.consistent_speeds(q, [0.5, 0.0])]), (0.0, 0.2))
    assert res.status == 0, res.message


def test_a_constraint_real_nowhere_is_a_model_error_naming_its_expression(tmp_path):
    text = CIRCLE.format(name="circle_never", expression="sqrt(-L**2 - x**2) - y",
                         speed="y_dot")
    with pytest.raises(ModelError, match="complex or not finite") as info:
        modelgen.load(write(tmp_path, text, "circle_never"), tmp_path / "build")
    err = info.value
    assert err.key == "constraints.circle.expression" and err.line == 10 and err.fix


# -- 4: dependent coordinates the position constraints do not involve -----------------

def test_a_dependent_coordinate_the_constraints_do_not_involve_is_refused(tmp_path):
    text = """\
name: bad_depq
coordinates: [x, y, z]
parameters: {m: 1.0, g: 9.81}
points:
  P: {coordinates: [x, y, z]}
bodies:
  b: {mass: m, G: P, base: E}
gravity: [0, 0, -g]
constraints:
  diag: {type: position, expression: x - y}
dependent: {coordinates: [z], speeds: [y_dot]}
"""
    with pytest.raises(ModelError, match="cannot be solved for the dependent coordinates z") \
            as info:
        modelgen.load(write(tmp_path, text, "bad_depq"), tmp_path / "build")
    assert info.value.key == "dependent.coordinates" and info.value.line == 11
    assert "ball or free" not in str(info.value)


def test_linearize_where_the_dependent_coordinates_are_singular_says_so(tmp_path):
    """y dependent, x_dot the dependent speed: at y = 0 the circle cannot be solved
    for y (df/dy = 2y = 0) though the speeds can (df/dx = 2x)."""
    path = write(tmp_path, CIRCLE.format(name="circle_lin", expression="x**2 + y**2 - L**2",
                                         speed="x_dot"), "circle_lin")
    cm = modelgen.load(path, tmp_path / "build", linearize=True)
    with pytest.raises(SimulationError, match=r"no minimal linearization .* dependent "
                                              r"coordinates \(y\) are singular"):
        cm.linearize([1.0, 0.0, 0.0, 0.7])
    lin = cm.linearize([0.6, 0.8, 0.0, 0.0])
    assert lin.states == ("x", "y_dot")
    # off the constraints at a point where G_d (df/dx = 2x) is singular too: the
    # message says off, and the value of y that closes them
    with pytest.raises(SimulationError, match="operating point is off the position") as info:
        cm.linearize([0.0, 0.5, 0.0, 0.0])
    assert "dead point" not in str(info.value)
    assert abs(printed(str(info.value), ["y"])["y"] - 1.0) <= 1e-15


# -- 5, 6, 7: the messages of a dead point, NaN, and a state off the constraints ------

def test_jac_at_a_dead_point_names_it(four_bar):
    with pytest.raises(SimulationError, match="dead point") as info:
        four_bar.jac(0.0, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    assert "pivot of q3_dot" in str(info.value)


def test_rhs_with_nan_says_nan_not_dead_point(four_bar):
    with pytest.raises(SimulationError, match=r"NaN or Inf in q1") as info:
        four_bar.rhs(0.0, [np.nan, 1.0, 2.0, 1.0, 0.0, 0.0])
    assert "dead point" not in str(info.value)


def test_a_wheel_started_flat_is_refused_naming_the_undefined_constraint(tmp_path):
    cm = modelgen.load(write(tmp_path, WHEEL_DISC, "wheel_disc"), tmp_path / "build")
    flat = np.array([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0] + [0.0] * 6)
    with pytest.raises(SimulationError, match=r"constraints are not defined .* wheel "
                                              r"\(axis 3\)"):
        cm.simulate(flat, (0.0, 1.0))


def test_the_fix_for_a_state_off_the_constraints_prints_values_that_close_them(four_bar):
    with pytest.raises(SimulationError, match="assemble it first") as info:
        four_bar.simulate([0.3, 1.0, 2.0, 2.0, 0.0, 0.0], (0.0, 1.0))
    values = printed(str(info.value), ["q2", "q3"])
    q = np.array([0.3, values["q2"], values["q3"]])
    assert np.max(np.abs(four_bar.constraint_residuals(q))) <= 1e-14
    assert "scene file or on the command line" in str(info.value)
    with pytest.raises(SimulationError, match="consistent_speeds") as info:
        four_bar.simulate(np.concatenate([q, [2.0, 0.0, 0.0]]), (0.0, 1.0))
    speeds = printed(str(info.value), ["q2_dot", "q3_dot"])
    qd = np.array([2.0, speeds["q2_dot"], speeds["q3_dot"]])
    res = four_bar.simulate(np.concatenate([q, qd]), (0.0, 0.1))
    assert res.status == 0, res.message


# -- 8: hostile arguments -------------------------------------------------------------

def circle_model() -> Model:
    m = Model("slider").add_coordinates("x", "y", "z").add_parameters({"L": 1.0, "m": 1.0})
    m.add_point("P", coordinates=["x", "y", 0]).add_body("b", mass="m", G="P", base="E")
    return m.add_constraint("c", "position", expression="x**2 + y**2 - L**2")


def test_set_dependent_takes_one_name_or_none_and_refuses_a_number():
    spec = circle_model().set_dependent(coordinates="y", speeds="y_dot").spec()
    assert spec.dependent_coordinates == ("y",) and spec.dependent_speeds == ("y_dot",)
    with pytest.raises(ModelError, match="0 dependent coordinates for 1 position"):
        circle_model().set_dependent(coordinates=None, speeds=["y_dot"]).spec()
    with pytest.raises(ModelError, match="expected a list of coordinate names but got the "
                                         "number 5") as info:
        circle_model().set_dependent(coordinates=5, speeds=["y_dot"])
    assert info.value.key == "dependent.coordinates"


@pytest.mark.parametrize("options, error, message", [
    ({"keep": 5}, ArgumentTypeError, "keep must be None, a coordinate name or a list"),
    ({"keep": [0]}, ArgumentTypeError, "keep names 0, not a coordinate name"),
    ({"keep": ["q1_dot"]}, ArgumentValueError, "keep names 'q1_dot', not a coordinate"),
    ({"max_iterations": "5"}, ArgumentTypeError, "max_iterations must be an integer"),
    ({"max_iterations": 0}, ArgumentValueError, "max_iterations must be >= 1"),
    ({"max_iterations": 2.5}, ArgumentValueError, "max_iterations must be a whole number"),
    ({"tol": -1}, ArgumentValueError, "tol must be finite and > 0"),
    ({"tol": float("nan")}, ArgumentValueError, "tol must be finite and > 0"),
    ({"tol": "1e-9"}, ArgumentTypeError, "tol must be a number"),
])
def test_assemble_refuses_bad_options_before_newton(four_bar, options, error, message):
    with pytest.raises(error, match=message):
        four_bar.assemble([0.3, 1.0, 2.0], **options)


def test_assemble_keeps_nothing_with_keep_none(four_bar):
    q = four_bar.assemble([0.3, 1.0, 2.0], keep=None)
    assert np.array_equal(q, four_bar.assemble([0.3, 1.0, 2.0]))
    assert np.max(np.abs(four_bar.constraint_residuals(q))) <= 1e-13
