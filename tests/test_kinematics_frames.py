"""Frame kinematics, centre of mass and centroidal map (``kinematics=`` builds).

Checked against Pinocchio (``pin``) on URDF robots, fixed base (the ur5, C in
the WORLD convention; the double pendulum, C in LOCAL) and floating (solo12,
C in LOCAL_WORLD_ALIGNED), in all three conventions, to 1e-12 relative; against
central differences of the poses; and J_dot v against the derivative of J v
along a motion with constant speeds.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import modelgen
from modelgen.errors import ModelError, SimulationError
from modelgen.model.urdf import import_urdf

pin = pytest.importorskip("pinocchio")

DATA = Path(__file__).parent / "data" / "urdf"
REFS = ("local", "world", "local_world_aligned")
#: modelgen frame -> Pinocchio frame (a moving link's frame is <link>_frame)
ROBOTS = {
    "ur5": ("ur5_robot.urdf", False, "world",
            {"tool0": "tool0", "wrist_3_link_frame": "wrist_3_link",
             "forearm_link_frame": "forearm_link", "ee_link": "ee_link"}),
    "solo12": ("solo12.urdf", True, "local_world_aligned",
               {"FL_FOOT": "FL_FOOT", "HR_FOOT": "HR_FOOT", "base_link_frame": "base_link",
                "FR_LOWER_LEG_frame": "FR_LOWER_LEG"}),
    "double_pendulum": ("double_pendulum.urdf", False, "local", None),
}


def _close(got, want, rel=1e-12):
    """Equal to ``rel`` relative to the largest entry of ``want``."""
    want = np.asarray(want)
    np.testing.assert_allclose(got, want, rtol=0, atol=rel * max(1.0, np.abs(want).max()))


class Robot:
    """A modelgen build and the Pinocchio model of one URDF, with the maps between
    their coordinates (modelgen puts a free joint after the angles, Pinocchio first,
    and orders the quaternion w, x, y, z where Pinocchio has x, y, z, w)."""

    def __init__(self, key, build_dir):
        file, floating, reference, frames = ROBOTS[key]
        path = DATA / file
        spec = import_urdf(path, floating_base=floating).model.spec()
        if frames is None:          # every link of the small pendulum
            frames = {f.name: f.name.removesuffix("_frame") for f in spec.frames}
        self.frames = frames
        self.cm = modelgen.load(str(path), build_dir / key, floating_base=floating or None,
                                kinematics={"frames": list(frames), "reference": reference,
                                            "com": True, "centroidal": True})
        self.model = (pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if floating
                      else pin.buildModelFromUrdf(str(path)))
        self.data = self.model.createData()
        self.floating = floating
        n, nq = self.cm.n, self.cm.nq
        if floating:    # modelgen: angles, x y z, qw qx qy qz; pin: x y z qx qy qz qw, angles
            k = nq - 7
            self.q_perm = [k, k + 1, k + 2, k + 4, k + 5, k + 6, k + 3] + list(range(k))
            self.v_perm = list(range(n - 6, n)) + list(range(n - 6))
        else:
            self.q_perm, self.v_perm = list(range(nq)), list(range(n))

    def random(self, rng):
        q = rng.uniform(-1.5, 1.5, self.cm.nq)
        if self.floating:
            quat = rng.normal(size=4)
            q[-4:] = quat / np.linalg.norm(quat)
        return q, rng.uniform(-2, 2, self.cm.n)

    def pin_qv(self, q, v):
        return q[self.q_perm], v[self.v_perm]

    def columns(self, J_pin):
        """Pinocchio's columns in modelgen's speed order."""
        out = np.empty_like(J_pin)
        out[:, self.v_perm] = J_pin
        return out

    def fid(self, frame):
        return self.model.getFrameId(self.frames[frame])


@pytest.fixture(scope="module", params=list(ROBOTS))
def robot(request, tmp_path_factory):
    return Robot(request.param, tmp_path_factory.mktemp("kin"))


def _states(robot, count=3, seed=7):
    rng = np.random.default_rng(seed)
    return [robot.random(rng) for _ in range(count)]


def test_frame_poses_match_update_frame_placements(robot):
    for q, v in _states(robot):
        pin.framesForwardKinematics(robot.model, robot.data, robot.pin_qv(q, v)[0])
        for frame in robot.frames:
            _close(robot.cm.frame_pose(q, frame), robot.data.oMf[robot.fid(frame)].homogeneous)


@pytest.mark.parametrize("reference", REFS)
def test_frame_jacobians_and_velocities_match_pinocchio(robot, reference):
    ref = {"local": pin.LOCAL, "world": pin.WORLD,
           "local_world_aligned": pin.LOCAL_WORLD_ALIGNED}[reference]
    for q, v in _states(robot):
        pq, pv = robot.pin_qv(q, v)
        pin.forwardKinematics(robot.model, robot.data, pq, pv)
        pin.computeJointJacobians(robot.model, robot.data, pq)
        pin.updateFramePlacements(robot.model, robot.data)
        for frame in robot.frames:
            J = pin.getFrameJacobian(robot.model, robot.data, robot.fid(frame), ref)
            _close(robot.cm.frame_jacobian(q, frame, reference), robot.columns(J))
            V = pin.getFrameVelocity(robot.model, robot.data, robot.fid(frame), ref)
            _close(robot.cm.frame_velocity(q, v, frame, reference), V.vector)


@pytest.mark.parametrize("reference", REFS)
def test_bias_acceleration_is_pinocchios_classical_acceleration(robot, reference):
    ref = {"local": pin.LOCAL, "world": pin.WORLD,
           "local_world_aligned": pin.LOCAL_WORLD_ALIGNED}[reference]
    for q, v in _states(robot):
        pq, pv = robot.pin_qv(q, v)
        pin.forwardKinematics(robot.model, robot.data, pq, pv, np.zeros(robot.model.nv))
        pin.updateFramePlacements(robot.model, robot.data)
        for frame in robot.frames:
            a = pin.getFrameClassicalAcceleration(robot.model, robot.data, robot.fid(frame), ref)
            _close(robot.cm.frame_bias_acceleration(q, v, frame, reference), a.vector)


def test_com_jacobian_and_centroidal_map_match_pinocchio(robot):
    for q, v in _states(robot):
        pq, _ = robot.pin_qv(q, v)
        _close(robot.cm.com(q), pin.centerOfMass(robot.model, robot.data, pq))
        _close(robot.cm.com_jacobian(q),
               robot.columns(pin.jacobianCenterOfMass(robot.model, robot.data, pq)))
        _close(robot.cm.centroidal_map(q),
               robot.columns(pin.computeCentroidalMap(robot.model, robot.data, pq)))


def _moved(robot, q, v, t):
    """q after moving with the constant speeds v for time t (the exponential map on
    a free joint: Pinocchio's integrate)."""
    pq = pin.integrate(robot.model, robot.pin_qv(q, v)[0], t * robot.pin_qv(q, v)[1])
    out = np.empty_like(q)
    out[robot.q_perm] = pq
    return out


def test_jacobian_is_the_derivative_of_the_pose(robot):
    """Central differences of the pose along q(t) with constant speeds v: dr/dt and
    omega (from dR/dt R^T) are J v in local_world_aligned."""
    h = 1e-6
    for q, v in _states(robot, 2):
        for frame in robot.frames:
            Tp, Tm = (robot.cm.frame_pose(_moved(robot, q, v, s), frame) for s in (h, -h))
            dT = (Tp - Tm) / (2 * h)
            R = robot.cm.frame_pose(q, frame)[:3, :3]
            W = dT[:3, :3] @ R.T
            got = robot.cm.frame_jacobian(q, frame, "local_world_aligned") @ v
            _close(got, np.concatenate((dT[:3, 3], [W[2, 1], W[0, 2], W[1, 0]])), 1e-8)


def test_bias_acceleration_is_the_derivative_of_jv(robot):
    """J_dot v = d/dt (J(q(t)) v) along a motion with constant speeds (local_world_aligned)."""
    h = 1e-5
    for q, v in _states(robot, 2, seed=3):
        for frame in robot.frames:
            Jp, Jm = (robot.cm.frame_jacobian(_moved(robot, q, v, s), frame,
                                              "local_world_aligned") for s in (h, -h))
            _close(robot.cm.frame_bias_acceleration(q, v, frame, "local_world_aligned"),
                   (Jp - Jm) @ v / (2 * h), 1e-7)


def test_unknown_frame_is_refused_with_the_available_ones(tmp_path):
    with pytest.raises(ModelError, match="no frame named 'tool9'.*tool0"):
        modelgen.load(str(DATA / "ur5_robot.urdf"), tmp_path, frames=["tool9"])
    with pytest.raises(ModelError, match="unknown frame reference 'global'"):
        modelgen.load(str(DATA / "ur5_robot.urdf"), tmp_path,
                      kinematics={"frames": ["tool0"], "reference": "global"})


def test_methods_say_how_to_build_what_is_missing(robot, tmp_path):
    q, _ = _states(robot, 1)[0]
    with pytest.raises(SimulationError, match="no frame 'nowhere'"):
        robot.cm.frame_pose(q, "nowhere")
    with pytest.raises(SimulationError, match="reference must be one of"):
        robot.cm.frame_jacobian(q, next(iter(robot.frames)), "global")
    plain = modelgen.load("models/double_pendulum.yaml", tmp_path)
    with pytest.raises(SimulationError, match="no kinematics were generated"):
        plain.com(np.zeros(2))


def test_only_what_is_asked_is_generated(tmp_path):
    cm = modelgen.load(str(DATA / "double_pendulum.urdf"), tmp_path, frames=["link2_frame"])
    names = set(cm.manifest["functions"])
    assert f"{cm.name}_frame_jacobians" in names
    assert f"{cm.name}_frame_bias_accelerations" in names     # the default
    assert f"{cm.name}_com" not in names and f"{cm.name}_centroidal_momentum_matrix" not in names
    header = (cm.path.parent / f"{cm.name}.h").read_text()
    assert f"#define {cm.name.upper()}_NFRAMES 1" in header
    with pytest.raises(SimulationError, match="'com': True"):
        cm.com(np.zeros(cm.nq))



SCENE = """scene: dp_kin
model: ../double_pendulum.yaml
effects: [gravity]
initial: {q1: 1.0, q2: 0.5, q1_dot: 0.0, q2_dot: 0.0}
time: {start: 0.0, end: 1.0, sample: 0.1}
kinematics: {frames: [F2], reference: local, com: true}
"""


def test_scene_kinematics_key_builds_the_frames(tmp_path):
    """F2 (point P1, base B2) of the double pendulum, in closed form: its origin is
    l1 (cos q1, sin q1, 0), its z axis E's, turned by q1 + q2."""
    from modelgen.model.scene import parse_scene
    from modelgen.sim.scene import Scene
    spec = parse_scene(SCENE, "dp_kin.yaml", base_dir=Path("models/scenes"))
    assert dict(spec.kinematics) == {"frames": ("F2",), "reference": "local", "com": True}
    cm = Scene(spec, tmp_path).model
    l1 = cm.parameters["l1"]
    q1, q2, w1, w2 = 0.3, -0.7, 1.1, 0.4
    c, s = np.cos(q1 + q2), np.sin(q1 + q2)
    T = cm.frame_pose([q1, q2], "F2")
    _close(T[:3, 3], [l1 * np.cos(q1), l1 * np.sin(q1), 0])
    _close(T[:3, :2], [[c, -s], [s, c], [0, 0]])
    dP = l1 * np.array([-np.sin(q1), np.cos(q1), 0])
    _close(cm.frame_jacobian([q1, q2], "F2", "local_world_aligned"),
           np.array([[*dP, 0, 0, 1], [0, 0, 0, 0, 0, 1]]).T)
    _close(cm.frame_bias_acceleration([q1, q2], [w1, w2], "F2", "local_world_aligned"),
           [-l1 * w1**2 * np.cos(q1), -l1 * w1**2 * np.sin(q1), 0, 0, 0, 0])
    assert f"{cm.name}_centroidal_momentum_matrix" not in cm.manifest["functions"]


@pytest.mark.parametrize("entry, words", [
    ("{frames: [F3]}", "no frame named 'F3'.*frames: F2"),
    ("{frame: [F2]}", "unknown key 'frame' in kinematics.*did you mean 'frames'"),
    ("{frames: F2}", "expected a list of frame names"),
    ("{frames: [F2], com: 1}", "expected true or false"),
])
def test_scene_kinematics_errors_name_the_key(entry, words):
    from modelgen.model.scene import parse_scene
    text = SCENE.replace("{frames: [F2], reference: local, com: true}", entry)
    with pytest.raises(ModelError, match=words) as info:
        parse_scene(text, "dp_kin.yaml", base_dir=Path("models/scenes"))
    assert info.value.key.startswith("kinematics")


def test_kinematics_options_refuse_unknown_fields_and_mean_nothing_when_empty():
    from modelgen.codegen.options import BuildOptions, KinematicsOptions
    with pytest.raises(TypeError, match="unknown kinematics option 'frame'.*frames"):
        KinematicsOptions.of({"frame": ["tool0"]})
    assert BuildOptions(kinematics={"frames": []}).kinematics is None
    assert BuildOptions(kinematics=[]).key_text() == BuildOptions().key_text()
    assert "kinematics" in BuildOptions(kinematics=["tool0"]).key_text()


def test_frames_keyword_joins_the_kinematics_keyword(tmp_path):
    g = modelgen.generate_model("models/double_pendulum.yaml", tmp_path, frames="F2",
                                kinematics={"com": True, "bias_acceleration": False})
    assert g.manifest["kinematics"] == {"frames": ["F2"], "reference": "local_world_aligned",
                                        "bias_acceleration": False, "com": True,
                                        "centroidal": False}
