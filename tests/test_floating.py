"""A floating-base robot in flight: the shipped Solo-12 scene against the laws of motion.

``models/scenes/solo12_falling.yaml`` throws the quadruped (a free joint at its
base link, 12 damped joints, gravity, no contact) tumbling into the air.  With
only gravity and internal forces, whatever the legs do:

* the total linear momentum grows as ``L(t) = L(0) + M g t`` and the centre of
  mass follows the parabola ``r_c(t) = r_c(0) + L(0) t / M + g t^2 / 2``;
* the angular momentum about the centre of mass is constant;
* the energy changes by exactly the work of the joint damping.

The momenta come from the generalized momentum ``A v``: for the free joint's
speeds (the base point's velocity and the base's angular velocity, both in the
base's components) its rows are the linear momentum and the angular momentum
about the base point, in the base's components.  The centre of mass comes from
the bodies' poses and masses.  None of this uses the equations of motion the
integrator solved.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from modelgen.sim.load import load_scene

SCENE = Path(__file__).resolve().parent.parent / "models" / "scenes" / "solo12_falling.yaml"
G = np.array([0.0, 0.0, -9.81])


def _rotation(quat):
    """R of a scalar-first unit quaternion, from scipy (not modelgen's formula)."""
    w, x, y, z = quat
    return Rotation.from_quat([x, y, z, w]).as_matrix()


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    scene = load_scene(SCENE, tmp_path_factory.mktemp("solo12"))
    res = scene.run()
    assert res.success, res.message
    return scene, res


def test_the_state_is_19_coordinates_and_18_speeds_with_a_unit_quaternion(flight):
    scene, res = flight
    cm = scene.model
    assert (cm.nq, cm.n, cm.nx) == (19, 18, 37) and res.y.shape[0] == 37
    quat = res.y[list(cm.quaternions[0])]
    assert np.max(np.abs(np.linalg.norm(quat, axis=0) - 1)) < 1e-10
    # the base turned through more than a right angle: Euler angles would have met
    # their singularity somewhere on the way for some choice of axes
    R0, R1 = _rotation(quat[:, 0]), _rotation(quat[:, -1])
    assert np.degrees(np.arccos((np.trace(R0.T @ R1) - 1) / 2)) > 90


def _momenta(cm, spec, x):
    """(centre of mass, linear momentum, angular momentum about the centre of mass) in E."""
    q, v = x[:cm.nq], x[cm.nq:]
    names = cm.state_names
    R = _rotation(q[list(cm.quaternions[0])])
    r_base = q[[names.index(f"root_joint_{c}") for c in "xyz"]]
    p = cm.mass_matrix(q) @ v
    speeds = list(cm.speeds)
    lin = R @ p[[speeds.index(f"root_joint_v{c}") for c in "xyz"]]
    ang_base = R @ p[[speeds.index(f"root_joint_w{c}") for c in "xyz"]]
    masses = np.array([float(b.mass) for b in spec.bodies])
    poses = cm.body_poses(q)
    r_c = masses @ poses[:, :3, 3] / masses.sum()
    return r_c, lin, ang_base - np.cross(r_c - r_base, lin), masses.sum()


def test_centre_of_mass_parabola_and_angular_momentum_about_it(flight):
    scene, res = flight
    cm, spec = scene.model, scene.spec.model
    c0, L0, H0, M = _momenta(cm, spec, res.y[:, 0])
    assert np.linalg.norm(H0) > 0.01 and L0[2] > 1.0          # it tumbles and rises
    worst = {"L": 0.0, "r": 0.0, "H": 0.0}
    for k, t in enumerate(res.t):
        c, L, H, _ = _momenta(cm, spec, res.y[:, k])
        worst["L"] = max(worst["L"], np.max(np.abs(L - (L0 + M * G * t))) / np.linalg.norm(L0))
        worst["r"] = max(worst["r"], np.max(np.abs(c - (c0 + L0 * t / M + G * t * t / 2))))
        worst["H"] = max(worst["H"], np.max(np.abs(H - H0)) / np.linalg.norm(H0))
    print("worst deviations", worst)
    assert worst["L"] < 1e-9 and worst["r"] < 1e-9 and worst["H"] < 1e-8, worst


def test_energy_changes_by_the_work_of_the_joint_damping(flight):
    _, res = flight
    total = res.energy.sum(axis=1)
    balance = total - total[0] - sum(res.work.values())
    assert abs(res.work["joint_damping"][-1]) > 1e-3           # damping did work
    assert np.max(np.abs(balance)) < 1e-9 * np.max(np.abs(res.energy))
