"""Frame kinematics at the edges: constrained models, quaternions that are not unit
ones, the checks of ``kinematics=``, the ``frames=`` keyword beside it, and the
command line and docs that give a C user the same functions.

Values are checked against closed forms (the four-bar's loop, a free body's
quaternion rotation) and against the model's own body poses.
"""
from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import modelgen
from modelgen.cli import main
from modelgen.codegen.emit import kinematics_api
from modelgen.codegen.options import BuildOptions, KinematicsOptions
from modelgen.errors import ArgumentTypeError, ModelError, SimulationError

from conftest import MODELS

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _close(got, want, tol=1e-13):
    want = np.asarray(want, dtype=float)
    np.testing.assert_allclose(got, want, rtol=0, atol=tol * max(1.0, np.abs(want).max()))


def _rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


# -- a constrained model ---------------------------------------------------------

@pytest.fixture(scope="module")
def four_bar(tmp_path_factory):
    """The four-bar with a frame C at the coupler's tip (point P2, base B2)."""
    d = tmp_path_factory.mktemp("four_bar")
    path = d / "four_bar.yaml"
    path.write_text((MODELS / "four_bar.yaml").read_text()
                    + "frames:\n  C: {point: P2, base: B2}\n")
    return modelgen.load(path, d / "build", kinematics={"frames": ["C"], "com": True})


def test_constrained_model_declares_its_kinematics_in_the_header(four_bar):
    cm = four_bar
    header = (cm.path.parent / f"{cm.name}.h").read_text()
    for routine in ("frame_poses", "frame_velocities", "frame_jacobians",
                    "frame_bias_accelerations", "com", "com_jacobian"):
        assert re.search(rf"^void {cm.name}_{routine}\(", header, re.M), routine
    assert "#define FOUR_BAR_NFRAMES 1" in header
    assert "#define FOUR_BAR_FRAME_C 0" in header
    assert "four_bar_constrain" in header        # the constrained API is still there


def test_constrained_model_frame_and_com_match_closed_forms_and_body_poses(four_bar):
    """C = a e(q1) + b e(q2), turned by q2 about z; the centre of mass is the bodies'
    centres weighted by their masses, read from body_poses."""
    cm = four_bar
    par = cm.parameters
    a, b, c = par["a"], par["b"], par["c"]
    masses = np.array([par["m1"], par["m2"], par["m3"]])
    for q in ([0.4, 1.1, 2.3], [2.0, -0.3, 0.9], [-1.2, 0.7, -2.5]):
        q1, q2, q3 = q
        T = cm.frame_pose(q, "C")
        _close(T[:3, 3], [a * np.cos(q1) + b * np.cos(q2), a * np.sin(q1) + b * np.sin(q2), 0])
        _close(T[:3, :3], _rot_z(q2))
        poses = cm.body_poses(q)
        coupler = poses[1]
        _close(T[:3, :3], coupler[:3, :3])
        _close(T[:3, 3], coupler[:3, 3] + coupler[:3, :3] @ [b / 2, 0, 0])
        _close(cm.com(q), masses @ poses[:, :3, 3] / masses.sum())

        J = cm.frame_jacobian(q, "C", "local_world_aligned")
        _close(J[:3], [[-a * np.sin(q1), -b * np.sin(q2), 0],
                       [a * np.cos(q1), b * np.cos(q2), 0], [0, 0, 0]])
        _close(J[3:], [[0, 0, 0], [0, 0, 0], [0, 1, 0]])         # the coupler turns at q2_dot
        # d/dq of m1 a/2 e(q1) + m2 (a e(q1) + b/2 e(q2)) + m3 (D + c/2 e(q3))
        de = [lambda t: -np.sin(t), np.cos]
        Jc = [[(masses[0] * a / 2 + masses[1] * a) * de[i](q1), masses[1] * b / 2 * de[i](q2),
               masses[2] * c / 2 * de[i](q3)] for i in range(2)]
        _close(cm.com_jacobian(q), np.array(Jc + [[0, 0, 0]]) / masses.sum())


# -- quaternions -----------------------------------------------------------------

RACKET = (MODELS / "tennis_racket.yaml").read_text() + """points:
  T: {from: G, base: B, coordinates: [0.3, 0.2, -0.1]}
frames:
  F: {point: T, base: B}
"""


@pytest.fixture(scope="module")
def racket(tmp_path_factory):
    """A free body (free joint J: x, y, z, qw, qx, qy, qz) with a frame off its centre."""
    d = tmp_path_factory.mktemp("racket")
    (d / "racket.yaml").write_text(RACKET)
    return modelgen.load(d / "racket.yaml", d / "build",
                         kinematics={"frames": ["F"], "com": True, "centroidal": True})


def _quaternion_matrix(w, x, y, z):
    """The rotation of the unit quaternion (w, x, y, z), scalar first."""
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _everything(cm, q, v):
    return [cm.frame_pose(q, "F"), cm.frame_jacobian(q, "F"),
            cm.frame_jacobian(q, "F", "local"), cm.frame_jacobian(q, "F", "world"),
            cm.frame_velocity(q, v, "F", "local"),
            cm.frame_bias_acceleration(q, v, "F", "world"),
            cm.com(q), cm.com_jacobian(q), cm.centroidal_map(q)]


@pytest.mark.parametrize("scale", [2.0, 0.5, 1e-3, 37.0])
def test_kinematics_normalise_a_quaternion_as_simulate_does(racket, scale):
    """s (0.5, 0.5, 0.5, 0.5) is the rotation of (0.5, 0.5, 0.5, 0.5) in every method
    (s = 2 gave a 'rotation' of determinant 64), and the caller's q is left as it was."""
    cm = racket
    unit = np.array([0.5, 0.5, 0.5, 0.5])
    position = np.array([0.7, -0.4, 1.3])
    v = np.array([0.3, -0.2, 0.5, 1.1, -0.7, 0.4])
    q_unit = np.concatenate([position, unit])
    q = np.concatenate([position, scale * unit])
    given = q.copy()
    R = _quaternion_matrix(*unit)
    T = cm.frame_pose(q, "F")
    _close(T[:3, :3], R)
    _close(T[:3, 3], position + R @ [0.3, 0.2, -0.1])
    assert abs(np.linalg.det(T[:3, :3]) - 1) < 1e-14
    _close(cm.com(q), position)
    for got, want in zip(_everything(cm, q, v), _everything(cm, q_unit, v)):
        _close(got, want, 1e-14)
    np.testing.assert_array_equal(q, given)


def test_kinematics_refuse_a_zero_quaternion_naming_it(racket):
    q = np.array([0.7, -0.4, 1.3, 0.0, 0.0, 0.0, 0.0])
    v = np.zeros(6)
    calls = [lambda: racket.frame_pose(q, "F"), lambda: racket.frame_jacobian(q, "F", "local"),
             lambda: racket.frame_velocity(q, v, "F"),
             lambda: racket.frame_bias_acceleration(q, v, "F"),
             lambda: racket.com(q), lambda: racket.com_jacobian(q),
             lambda: racket.centroidal_map(q)]
    for call in calls:
        with pytest.raises(SimulationError, match=r"zero quaternion \(J_qw, J_qx, J_qy, J_qz\)"
                                                  r".*give a unit quaternion"):
            call()


# -- kinematics= checked ---------------------------------------------------------

@pytest.mark.parametrize("value, error, words", [
    ({"frames": ["tool0"], "com": "false"}, ArgumentTypeError,
     "'com' must be True or False, got 'false'; fix: com=True or com=False"),
    ({"frames": ["tool0"], "bias_acceleration": "no"}, ArgumentTypeError,
     "'bias_acceleration' must be True or False, got 'no'"),
    ({"frames": ["tool0"], "centroidal": 1}, ArgumentTypeError,
     "'centroidal' must be True or False, got 1"),
    ({"frames": [["tool0"]]}, ArgumentTypeError,
     r"'frames' must be a frame name or a list of frame names, got \[\['tool0'\]\]"),
    ({"frames": [3]}, ArgumentTypeError, "'frames' must be a frame name or a list"),
    ({"frames": {"tool0"}}, ArgumentTypeError, "'frames' must be a frame name or a list"),
    ({"frames": ["tool0"], "reference": "LOCAL"}, ModelError,
     "unknown frame reference 'LOCAL'; fix: use one of local, world, local_world_aligned"),
    ({"frames": ["tool0"], "reference": None}, ModelError, "unknown frame reference None"),
    ({"frame": ["tool0"]}, ArgumentTypeError,
     "unknown kinematics option 'frame'; fix: use the options frames, reference, "
     "bias_acceleration, com, centroidal"),
    (42, ArgumentTypeError, "kinematics must be a KinematicsOptions, a dict or a list"),
])
def test_kinematics_values_are_checked_naming_the_field_and_the_fix(value, error, words):
    with pytest.raises(error, match=words):
        KinematicsOptions.of(value)
    with pytest.raises(error, match=words):
        BuildOptions(kinematics=value)


def test_kinematics_are_checked_before_anything_is_built(tmp_path):
    with pytest.raises(ArgumentTypeError, match="'com' must be True or False"):
        modelgen.load(MODELS / "double_pendulum.yaml", tmp_path,
                      kinematics={"frames": ["F2"], "com": "false"})
    assert not any(tmp_path.iterdir())


def test_one_frame_name_is_one_frame_not_its_letters():
    assert KinematicsOptions.of({"frames": "tool0"}).frames == ("tool0",)
    assert KinematicsOptions.of("tool0").frames == ("tool0",)
    assert KinematicsOptions(frames="tool0", com=True).frames == ("tool0",)
    assert KinematicsOptions.of({"frames": ("a", "b"), "com": False,
                                 "bias_acceleration": False}).frames == ("a", "b")


# -- frames= beside kinematics= ---------------------------------------------------

def test_frames_keyword_adds_to_the_kinematics_frames(tmp_path):
    """Both lists are built, each frame once, those of kinematics first; the other
    fields of kinematics stay."""
    path = tmp_path / "double_pendulum.yaml"
    path.write_text((MODELS / "double_pendulum.yaml").read_text().replace(
        "  F2: {point: P1, base: B2}", "  F2: {point: P1, base: B2}\n  F1: {point: O, base: B1}"))
    g = modelgen.generate_model(path, tmp_path / "a", frames=["F2", "F1"],
                                kinematics={"frames": ["F1"], "bias_acceleration": False})
    assert g.manifest["kinematics"]["frames"] == ["F1", "F2"]
    assert g.manifest["kinematics"]["bias_acceleration"] is False
    g = modelgen.generate_model(path, tmp_path / "b", frames="F1",
                                kinematics={"bias_acceleration": False})
    assert g.manifest["kinematics"]["frames"] == ["F1"]
    assert g.manifest["kinematics"]["bias_acceleration"] is False


# -- the command line and the docs ------------------------------------------------

def test_generate_kinematics_options_put_the_prototypes_in_the_header(tmp_path, capsys):
    out = tmp_path / "dp"
    assert main(["generate", str(MODELS / "double_pendulum.yaml"), "-o", str(out),
                 "--frame", "F2", "--com", "--centroidal", "--reference", "local",
                 "--no-bias-acceleration"]) == 0
    printed = capsys.readouterr().out
    assert "kinematics frames F2 (local); centre of mass; centroidal momentum matrix" \
        in printed
    # the routine table's columns stay aligned past 20-character names
    table = ("routine" + printed.split("\nroutine")[1]).split("\n\n")[0].splitlines()
    assert any(len(line.split()[0]) > 20 for line in table[1:])
    assert len({len(line) for line in table}) == 1, table
    header = (out / "double_pendulum.h").read_text()
    for prototype in (
            "void double_pendulum_frame_poses(const double *q, const double *p, double *T);",
            "void double_pendulum_frame_velocities(const double *q, const double *qd, "
            "const double *p, double *V);",
            "void double_pendulum_frame_jacobians(const double *q, const double *p, double *J);",
            "void double_pendulum_com(const double *q, const double *p, double *c);",
            "void double_pendulum_com_jacobian(const double *q, const double *p, double *Jc);",
            "void double_pendulum_centroidal_momentum_matrix(const double *q, const double *p, "
            "double *Ag);"):
        assert prototype in header, prototype
    assert "frame_bias_accelerations" not in header
    assert "#define DOUBLE_PENDULUM_NFRAMES 1\n#define DOUBLE_PENDULUM_FRAME_F2 0" in header
    assert "(Pinocchio's LOCAL)" in header


@pytest.mark.parametrize("flags, words", [
    (["--reference", "world"], "--reference applies to the frames' functions.*add --frame"),
    (["--com", "--no-bias-acceleration"], "--no-bias-acceleration applies to the frames'"),
    (["--frame", "F9"], "no frame named 'F9'.*F2"),
])
def test_generate_kinematics_mistakes_are_input_errors(flags, words, tmp_path, capsys):
    assert main(["generate", str(MODELS / "double_pendulum.yaml"), "-o", str(tmp_path),
                 *flags]) == 2
    assert re.search(words, capsys.readouterr().err)


def test_generate_refuses_an_unknown_reference_listing_the_three(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:       # argparse's usage error
        main(["generate", str(MODELS / "double_pendulum.yaml"), "-o", str(tmp_path),
              "--frame", "F2", "--reference", "global"])
    assert info.value.code == 2
    assert "invalid choice: 'global' (choose from 'local', 'world', 'local_world_aligned')" \
        in capsys.readouterr().err


def test_generated_c_page_lists_every_kinematics_prototype_and_macro():
    """The table of docs/generated-c.md against what the generator declares."""
    everything = SimpleNamespace(frames=("F",), reference="local", poses=[1], velocities=[1],
                                 jacobians=[1], bias=[1], com=[1], com_jacobian=[1],
                                 centroidal=[1])
    page = (DOCS / "generated-c.md").read_text()
    for entry in kinematics_api("MODEL", everything, 2, 2, 1):
        prototype = f"{entry['ret']} {entry['name']}({entry['params']})".replace(
            "MODEL_", "<name>_")
        assert f"`{prototype}`" in page, prototype
    for macro in ("<NAME>_NFRAMES", "#define DOUBLE_PENDULUM_FRAME_F2 0", "--frame NAME",
                  "--com", "--centroidal", "--reference", "--no-bias-acceleration"):
        assert macro in page, macro


def test_api_reference_shows_the_kinematics_methods_of_compiled_model():
    """They are FrameKinematics', CompiledModel's base: autodoc shows them only with
    inherited-members."""
    page = (DOCS / "api.md").read_text()
    block = page.split(".. autoclass:: modelgen.sim.runtime.CompiledModel", 1)[1]
    block = block.split("```", 1)[0]
    assert ":inherited-members:" in block
    assert "[kinematics.md](kinematics.md)" in (DOCS / "python-api.md").read_text()
