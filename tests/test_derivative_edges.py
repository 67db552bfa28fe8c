"""Edges of the derivatives, the Jacobian, the linearization and the rest-point search
found by an audit: ball and free joints in equilibrium (tangent space), quaternions
off unit norm, a search that landed turns away, an upper-case .NPZ, messages whose
fix the build refused, the CLI's exit status with --equilibrium, and the checks of
t and of the state."""
from __future__ import annotations

import numpy as np
import pytest

import modelgen
from modelgen.cli import EXIT, main
from modelgen.errors import (ArgumentTypeError, ArgumentValueError, BuildError,
                             SimulationError)
from modelgen.sim.linearize import retract, tangent_map

from conftest import MODELS, ROOT, SCENES

DP = MODELS / "double_pendulum.yaml"
JOINTS = ROOT / "tests" / "data" / "joints"
#: the double pendulum's rest points (q1 from the x axis, q2 relative): hanging,
#: upright, and the two folded ones
DP_RESTS = [(-np.pi / 2, 0.0), (np.pi / 2, 0.0), (-np.pi / 2, np.pi), (np.pi / 2, np.pi)]


@pytest.fixture(scope="module")
def dp_lin(build_root):
    # the build directory and options of test_api_arguments' and the CLI's: one build
    return modelgen.load(DP, build_root / "dp_args_lin", linearize=True)


@pytest.fixture(scope="module")
def dp_der(build_root):
    return modelgen.load(DP, build_root / "dp_edges_derivatives", derivatives=True)


@pytest.fixture(scope="module")
def ball(build_root):
    """The heavy body on a ball joint, built with the Jacobian and with the derivatives."""
    path = JOINTS / "heavy_body_ball.yaml"
    return {"jacobian": modelgen.load(path, build_root / "hbb_edges_jac", jacobian=True),
            "derivatives": modelgen.load(path, build_root / "hbb_edges_der", derivatives=True)}


def _rest_residual(cm, q, u=None) -> float:
    return float(np.max(np.abs(cm.rhs(0.0, np.concatenate([q, np.zeros(cm.n)]), u))))


# -- 1: ball and free joints in equilibrium ------------------------------------------------

@pytest.mark.parametrize("source", ["jacobian", "derivatives"])
def test_equilibrium_of_a_ball_joint_searches_the_tangent_space(ball, source):
    """A 4-number guess (not unit) used to be refused for shape (3,); the rest point
    found hangs the centre of mass straight below the joint, with a unit quaternion,
    from either build's slope."""
    cm = ball[source]
    a = np.array([cm.parameters[k] for k in ("a1", "a2", "a3")])
    w, x, y, z = q = cm.equilibrium(1.7 * np.array([0.2, 1.0, 0.1, 0.0]))
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    assert abs(np.linalg.norm(q) - 1.0) <= 1e-12
    assert _rest_residual(cm, q) <= 1e-10
    np.testing.assert_allclose(R @ a / np.linalg.norm(a), [0.0, 0.0, -1.0], atol=1e-9)
    # both slopes lead the same way
    other = ball["derivatives" if source == "jacobian" else "jacobian"]
    np.testing.assert_allclose(q, other.equilibrium(1.7 * np.array([0.2, 1.0, 0.1, 0.0])),
                               atol=1e-9)


def test_tangent_map_and_retraction_follow_the_models_kinematics(build_root):
    """N(q) is the rhs's own dq/dt per unit speed (simple coordinates, then a free
    joint's position and quaternion), and the exponential-map move agrees with it to
    first order and keeps the quaternion unit."""
    cm = modelgen.load(JOINTS / "free_base_two_links.yaml", build_root / "fb_edges_der",
                       derivatives=True)
    rng = np.random.default_rng(7)
    q = cm.project(rng.uniform(-1, 1, cm.nq))
    N = tangent_map(cm, q)
    rates = np.column_stack([cm.rhs(0.0, np.concatenate([q, e]))[:cm.nq] for e in np.eye(cm.n)])
    assert np.max(np.abs(N - rates)) <= 1e-15
    dv = rng.uniform(-1, 1, cm.n)
    gaps = [np.max(np.abs(retract(cm, q, h * dv) - (q + h * N @ dv))) for h in (1e-2, 1e-3)]
    assert gaps[1] <= gaps[0] / 50          # second order
    quat = list(cm.quaternions[0])
    assert abs(np.linalg.norm(retract(cm, q, 3.0 * dv)[quat]) - 1.0) <= 1e-15
    # no forces: every configuration is at rest, and the guess comes back
    np.testing.assert_array_equal(cm.equilibrium(q), q)


def test_a_quaternion_model_without_a_slope_names_a_build_it_accepts(compiled):
    cm = compiled("tennis_racket")
    with pytest.raises(SimulationError, match="jacobian=True or derivatives=True") as exc:
        cm.equilibrium(cm.neutral_state()[:cm.nq])
    assert "linearize=True" not in str(exc.value)


# -- 2: quaternions off unit norm in the derivatives -----------------------------------------

def test_derivatives_normalise_the_quaternion_and_refuse_a_zero_one(ball):
    cm = ball["derivatives"]
    rng = np.random.default_rng(3)
    x = np.concatenate([cm.project(rng.uniform(-1, 1, cm.nq)), rng.uniform(-1, 1, cm.n)])
    qdd = rng.uniform(-1, 1, cm.n)
    unit, inverse = cm.derivatives(0.0, x), cm.inverse_dynamics_derivatives(0.0, x, qdd)
    quat = list(cm.quaternions[0])
    for scale in (1.7, 0.3):
        scaled = x.copy()
        scaled[quat] *= scale
        # the quaternion scaled by 1.7 changed dqdd_dq by 3.0 relative
        for got, want in zip(cm.derivatives(0.0, scaled), unit):
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
        for got, want in zip(cm.inverse_dynamics_derivatives(0.0, scaled, qdd), inverse):
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
    zero = x.copy()
    zero[quat] = 0.0
    for call in (lambda: cm.derivatives(0.0, zero), lambda: cm.jac(0.0, zero),
                 lambda: cm.inverse_dynamics_derivatives(0.0, zero, qdd),
                 lambda: ball["jacobian"].equilibrium(zero[:cm.nq])):
        with pytest.raises(SimulationError, match="zero quaternion"):
            call()


# -- 3: the rest point near the guess --------------------------------------------------------

@pytest.mark.parametrize("rest", DP_RESTS)
def test_equilibrium_finds_the_rest_point_near_the_guess(dp_lin, rest):
    rng = np.random.default_rng(11)
    for _ in range(6):
        q = dp_lin.equilibrium(np.array(rest) + rng.uniform(-0.5, 0.5, 2))
        np.testing.assert_allclose(q, rest, atol=1e-9)
        assert _rest_residual(dp_lin, q) <= 1e-10


def test_equilibrium_does_not_jump_turns_away(dp_lin):
    # Newton with a line search went from here to [1.365, 12.77] and to [-2.5 pi, 7 pi]
    guess = np.array([-1.2, 0.4])
    q = dp_lin.equilibrium(guess, {"T1": 3.0})
    assert np.linalg.norm(q - guess) <= 0.63 and _rest_residual(dp_lin, q, {"T1": 3.0}) <= 1e-10
    q = dp_lin.equilibrium([3.0, 3.0])
    np.testing.assert_allclose(q, [np.pi / 2, np.pi], atol=1e-9)


def test_a_rest_point_is_returned_and_a_stationary_residual_is_named(dp_lin):
    hanging = np.array([-np.pi / 2, 0.0])
    assert _rest_residual(dp_lin, hanging) <= 1e-10
    np.testing.assert_array_equal(dp_lin.equilibrium(hanging), hanging)
    # held horizontal the Jacobian is zero: not "no rest point nearby" (one is)
    with pytest.raises(SimulationError, match="not zero but stationary.*another guess"):
        dp_lin.equilibrium([0.0, 0.0])


# -- 4: files under exactly their names --------------------------------------------------------

@pytest.mark.parametrize("name", ["up.NPZ", "plain", "lin.npz", "up.MAT", "bare"])
def test_linearization_files_are_written_under_exactly_their_name(dp_lin, tmp_path, name):
    from scipy.io import loadmat
    lin = dp_lin.linearize([0.3, -0.2])
    mat = name in ("up.MAT", "bare")
    path = (lin.to_mat if mat else lin.to_npz)(tmp_path / name)
    assert path == tmp_path / name and sorted(tmp_path.iterdir()) == [path]
    if mat:
        np.testing.assert_array_equal(loadmat(path, appendmat=False)["A"], lin.A)
    else:
        with np.load(path) as npz:
            np.testing.assert_array_equal(npz["A"], lin.A)


def test_a_failed_write_leaves_no_file(dp_lin, tmp_path, monkeypatch):
    lin = dp_lin.linearize([0.3, -0.2])

    def cut(fh, **arrays):
        fh.write(b"PK")
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(np, "savez", cut)
    with pytest.raises(OSError):
        lin.to_npz(tmp_path / "lin.npz")
    assert list(tmp_path.iterdir()) == []


def test_cli_writes_an_upper_case_npz(build_root, tmp_path, capsys):
    out = tmp_path / "up.NPZ"
    argv = ["linearize", str(DP), "--equilibrium", "--at", "q1=-1.2", "--at", "q2=0.3",
            "--build-dir", str(build_root / "dp_args_lin"), "-o", str(out)]
    assert main(argv) == EXIT["ok"], capsys.readouterr().err
    assert sorted(tmp_path.iterdir()) == [out]
    with np.load(out) as npz:
        np.testing.assert_allclose(npz["x"][:2], [-np.pi / 2, 0.0], atol=1e-9)


# -- 5: messages whose fix works -----------------------------------------------------------------

def test_a_constrained_model_is_sent_to_the_jacobian_not_to_a_refused_build(compiled, tmp_path):
    cm = compiled("four_bar")
    with pytest.raises(BuildError, match=r"jacobian=True and use cm\.jac") as exc:
        cm.derivatives(0.0, np.zeros(cm.nx))
    assert "load it with derivatives=True" not in str(exc.value)


def test_linearizing_a_quaternion_model_names_derivatives_not_a_refused_build(compiled):
    cm = compiled("tennis_racket")
    # its state has 13 values: it used to say "x must have shape (12,)", then linearize=True
    for x in (cm.neutral_state(), cm.neutral_state()[:cm.nq]):
        with pytest.raises(SimulationError, match="fix: load it with derivatives=True") as exc:
            cm.linearize(x)
        assert "must have shape" not in str(exc.value)


def test_cli_equilibrium_of_a_constrained_scene_gives_a_command_line_fix(tmp_path, capsys):
    argv = ["linearize", str(SCENES / "four_bar_swing.yaml"), "--equilibrium",
            "--build-dir", str(tmp_path / "never")]
    assert main(argv) == EXIT["input"]
    err = capsys.readouterr().err
    assert "--at NAME=VALUE" in err and "cm.assemble" not in err
    assert not (tmp_path / "never").exists()          # refused before the build


# -- 6: the CLI's exit status with and without --equilibrium ----------------------------------

@pytest.mark.parametrize("extra", [[], ["--equilibrium"]])
def test_a_singular_mass_matrix_exits_4_with_or_without_equilibrium(build_root, capsys, extra):
    argv = ["linearize", str(DP), "--set", "m1=0", "--set", "m2=0", *extra,
            "--build-dir", str(build_root / "dp_args_lin")]
    assert main(argv) == EXIT["simulation"]
    assert "mass matrix" in capsys.readouterr().err


# -- 7: t and the state are checked alike ---------------------------------------------------------

def test_t_as_a_string_is_refused(dp_lin, dp_der):
    x = np.array([0.3, -0.2, 0.1, 0.0])
    for call in (lambda: dp_der.derivatives("0", x), lambda: dp_lin.linearize(x, t="0"),
                 lambda: dp_lin.jac("0", x), lambda: dp_lin.rhs("0", x),
                 lambda: dp_der.inverse_dynamics_derivatives(np.str_("0"), x, [0.0, 0.0]),
                 lambda: dp_lin.equilibrium([0.1, 0.1], t=b"0")):
        with pytest.raises(ArgumentTypeError, match="t must be a real number"):
            call()


def test_a_nan_state_is_refused_by_every_derivative(dp_lin, dp_der):
    x = np.array([0.3, np.nan, 0.1, 0.0])
    for call in (lambda: dp_der.derivatives(0.0, x), lambda: dp_lin.jac(0.0, x),
                 lambda: dp_der.inverse_dynamics_derivatives(0.0, x, [0.0, 0.0]),
                 lambda: dp_lin.linearize(x)):
        with pytest.raises(ArgumentValueError, match=r"x must be finite; got NaN or Inf in "
                                                     r"\['q2'\]"):
            call()
