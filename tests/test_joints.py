"""Ball and free joints (unit quaternions, nq != nv) against independent references.

* A free rigid body (joint point off the centre of mass, full inertia, a
  rotated parent base and an offset origin, gravity): A, h, tau, the energies,
  the pose and dq/dt equal Newton-Euler in body components at random states.
* The tennis racket (models/tennis_racket.yaml): energy, angular and linear
  momentum conserved, unit quaternions at every sample, the flip period equal
  to Landau & Lifshitz's closed form, through attitudes where ZYX angles are
  singular.
* A heavy asymmetric body on a ball joint against the same body on ZXZ Euler
  angles: the same A (mapped), the same trajectory of poses.
* A free base with two hinged links: A symmetric positive definite, energy and
  linear momentum conserved, the symbolic Jacobian against central differences.
* The joints: section's errors, the YAML writer's round trip, the CLI's columns.

Quaternions are scalar first (w, x, y, z); R(q) has the child base's unit
vectors as columns in the parent's components.  Rotation matrices here come
from scipy (independent of modelgen's formula).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import ellipk

import modelgen
from modelgen.cli import main
from modelgen.errors import ModelError, SimulationError
from modelgen.model.api import load_model, parse_model, spec_to_yaml
from modelgen.model.scene import parse_scene

from conftest import SUMMARY
from mechanics_reference import zxz_body_rate_matrix, zxz_rotation

DATA = Path(__file__).resolve().parent / "data" / "joints"
MODELS = Path(__file__).resolve().parent.parent / "models"
RACKET = MODELS / "tennis_racket.yaml"


# -- independent helpers -------------------------------------------------------------------

def rotation(quat) -> np.ndarray:
    """R(q) for a scalar-first quaternion, by scipy."""
    w, x, y, z = quat
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def quaternion_of(R) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def hamilton(a, b) -> np.ndarray:
    """The quaternion product a * b (scalar first)."""
    a0, av, b0, bv = a[0], np.asarray(a[1:]), b[0], np.asarray(b[1:])
    return np.concatenate([[a0 * b0 - av @ bv], a0 * bv + b0 * av + np.cross(av, bv)])


def skew(c) -> np.ndarray:
    """[c]x with [c]x w = c x w."""
    return np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])


def rot_x(a) -> np.ndarray:
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def unit_quaternion(rng) -> np.ndarray:
    v = rng.normal(size=4)
    return v / np.linalg.norm(v)


def inertia_tensor(rng, scale=1.0) -> np.ndarray:
    """A full, physical inertia tensor: principal moments in [1, 2] (triangle
    inequality holds) turned by a random rotation."""
    Q = rotation(unit_quaternion(rng))
    return scale * Q @ np.diag(rng.uniform(1.0, 2.0, 3)) @ Q.T


def relative_error(got, expected) -> float:
    got, expected = np.asarray(got, dtype=float), np.asarray(expected, dtype=float)
    return float(np.max(np.abs(got - expected)) / np.max(np.abs(expected)))


@pytest.fixture(scope="module")
def free_body(compiled):
    return compiled(DATA / "free_body_offset.yaml")


@pytest.fixture(scope="module")
def racket(compiled):
    return compiled(RACKET)


@pytest.fixture(scope="module")
def tree(build_root):
    """The free base with two links, with its symbolic Jacobian."""
    return modelgen.load(DATA / "free_base_two_links.yaml", build_root / "joints_tree",
                         jacobian=True)


# -- 1. a free rigid body: Newton-Euler in body components ----------------------------------

def _free_body_parameters(rng) -> dict:
    I = inertia_tensor(rng)
    p = {"m": rng.uniform(0.5, 2.0), "alpha": rng.uniform(-np.pi, np.pi)}
    p.update({f"I{i + 1}{j + 1}": I[i, j] for i in range(3) for j in range(i, 3)})
    p.update(zip(("cx", "cy", "cz"), rng.normal(scale=0.3, size=3)))
    p.update(zip(("qx0", "qy0", "qz0"), rng.normal(size=3)))
    p.update(zip(("gx", "gy", "gz"), rng.normal(scale=5.0, size=3)))
    return p


def newton_euler(q, v, p) -> dict:
    """Closed forms for free_body_offset.yaml in B's components.

    The joint's point P moves with velocity v, the body turns with w (both in
    B); G = P + c.  v_G = v - [c]x w, so T = m |v - [c]x w|^2 / 2 + w'Iw / 2,
    A = [[m 1, -m [c]x], [m [c]x, I + m [c]x'[c]x]]; the velocity part of G's
    acceleration is w x v_G, so h = [m w x v_G, c x (m w x v_G) + w x Iw];
    gravity m g at G gives tau = [m g_B, c x m g_B] with g_B = R_B' g.
    """
    m = p["m"]
    I = np.array([[p["I11"], p["I12"], p["I13"]], [p["I12"], p["I22"], p["I23"]],
                  [p["I13"], p["I23"], p["I33"]]])
    c = np.array([p["cx"], p["cy"], p["cz"]])
    g = np.array([p["gx"], p["gy"], p["gz"]])
    r, quat = q[:3], q[3:]
    vP, w = v[:3], v[3:]
    RC = rot_x(p["alpha"])
    R = RC @ rotation(quat)                      # B in E
    C = skew(c)
    A = np.block([[m * np.eye(3), -m * C], [m * C, I + m * C.T @ C]])
    vG = vP + np.cross(w, c)
    f = m * np.cross(w, vG)
    h = np.concatenate([f, np.cross(c, f) + np.cross(w, I @ w)])
    gB = R.T @ g
    tau = np.concatenate([m * gB, np.cross(c, m * gB)])
    rG = np.array([p["qx0"], p["qy0"], p["qz0"]]) + RC @ r + R @ c
    T = 0.5 * m * vG @ vG + 0.5 * w @ I @ w
    V = -m * g @ rG
    qdot = np.concatenate([rotation(quat) @ vP, hamilton(quat, np.concatenate([[0.0], w])) / 2])
    return dict(A=A, h=h, tau=tau, R=R, rG=rG, T=T, V=V, qdot=qdot,
                vdot=np.linalg.solve(A, tau - h))


def test_free_body_equals_newton_euler_in_body_components(free_body):
    cm = free_body
    assert (cm.nq, cm.n, cm.nx) == (7, 6, 13)
    assert cm.quaternions == ((3, 4, 5, 6),)
    rng = np.random.default_rng(11)
    worst = {}
    for _ in range(20):
        p = _free_body_parameters(rng)
        q = np.concatenate([rng.normal(size=3), unit_quaternion(rng)])
        v = rng.normal(size=6)
        ref = newton_euler(q, v, p)
        pose = cm.body_poses(q, p)[0]
        xdot = cm.rhs(0.0, np.concatenate([q, v]), p=p)
        got = dict(A=cm.mass_matrix(q, p), h=cm.velocity_terms(q, v, p),
                   tau=cm.generalized_forces(0.0, q, v, p=p), R=pose[:3, :3],
                   rG=pose[:3, 3], T=cm.energy(q, v, p)[0], V=cm.energy(q, v, p)[1],
                   qdot=xdot[:7], vdot=xdot[7:])
        for key, value in got.items():
            worst[key] = max(worst.get(key, 0.0), relative_error(value, ref[key]))
    SUMMARY.append("joints: free body vs Newton-Euler, worst relative error "
                   + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert max(worst.values()) < 1e-12, worst


# -- 2. the tennis racket: the intermediate-axis theorem --------------------------------------

RACKET_MOMENTS = np.array([1.0, 2.0, 3.0])
#: body axis 1 along z of E (ZYX pitch = -90 degrees), axis 2 along x, axis 3 along y
RACKET_ATTITUDE = np.array([0.5, -0.5, -0.5, -0.5])


def flip_half_period(w, I=RACKET_MOMENTS) -> float:
    """The time between sign changes of w2: 2 K(k) / lambda (Landau & Lifshitz,
    Mechanics, section 37: w2 is proportional to sn(lambda t, k)); for
    L^2 < 2 E I2 the roles of axes 1 and 3 swap."""
    Iw = I * w
    E, L2 = 0.5 * w @ Iw, Iw @ Iw
    I1, I2, I3 = I if L2 > 2 * E * I[1] else I[::-1]
    lam = np.sqrt((I3 - I2) * (L2 - 2 * E * I1) / (I1 * I2 * I3))
    k2 = (I2 - I1) * (2 * E * I3 - L2) / ((I3 - I2) * (L2 - 2 * E * I1))
    assert 0.9 < k2 < 1
    return 2 * ellipk(k2) / lam


# a perturbation along axis 1 (L^2 < 2 E I2) and one mostly along axis 3 (L^2 > 2 E I2)
@pytest.mark.parametrize("w", [(0.2, 4.0, 0.0), (0.05, 4.0, 0.15)], ids=["axis1", "axis3"])
def test_tennis_racket_flips_with_the_closed_form_period_conserving_everything(racket, w):
    cm = racket
    w = np.array(w)
    x0 = cm.neutral_state()
    x0[3:7] = RACKET_ATTITUDE
    x0[7:10] = [0.3, -0.2, 0.1]                   # G drifts: R v is constant
    x0[10:13] = w
    iw2 = cm.state_names.index("J_wy")
    assert cm.state_names[3:7] == ("J_qw", "J_qx", "J_qy", "J_qz") and iw2 == 11
    t_end = 40.0
    res = cm.simulate(x0, (0.0, t_end), t_eval=np.linspace(0.0, t_end, 4001),
                      method="dop853", rtol=1e-11, atol=1e-12,
                      events=[lambda t, x: x[iw2]])
    assert res.success, res.message
    y = res.y

    # (b) unit quaternion at every output sample
    norm_error = np.abs(np.linalg.norm(y[3:7], axis=0) - 1).max()
    # (a) energy, angular momentum R I w and momentum m R v (m = 1) in E
    R = np.array([rotation(quat) for quat in y[3:7].T])
    L = np.einsum("nij,jn->ni", R, RACKET_MOMENTS[:, None] * y[10:13])
    P = np.einsum("nij,jn->ni", R, y[7:10])
    T = np.array([cm.energy(x[:7], x[7:])[0] for x in y.T])
    energy_error = np.abs(T / T[0] - 1).max()
    L_error = np.abs(L - L[0]).max() / np.linalg.norm(L[0])
    P_error = np.abs(P - P[0]).max() / np.linalg.norm(P[0])
    position_error = np.abs(y[:3] - (x0[:3, None] + np.outer(P[0], res.t))).max()
    # (c) the flip period: successive zeros of w2
    crossings = res.t_events[0]
    half = flip_half_period(w)
    period_error = np.abs(np.diff(crossings) / half - 1).max()
    # (d) through attitudes where ZYX angles are singular: axis 1 along z of E
    # (cos pitch = 0) at the start and again (to 2e-2) after the first flip; axis 2
    # along L, then against it, and back (its L component is I2 w2 / |L|)
    cos_pitch = np.sqrt(np.clip(1 - R[:, 2, 0] ** 2, 0, None))
    axis2_on_L = R[:, :, 1] @ (L[0] / np.linalg.norm(L[0]))

    label = ", ".join(f"{v:g}" for v in w)
    SUMMARY.append(f"joints: tennis racket w=({label}): {len(crossings)} flips, period "
                   f"{half:.6f} s rel err {period_error:.1e}; energy {energy_error:.1e}, "
                   f"L {L_error:.1e}, momentum {P_error:.1e}, |q|-1 {norm_error:.1e}, "
                   f"min cos(pitch) after the first flip "
                   f"{cos_pitch[res.t > crossings[0]].min():.1e}")
    assert norm_error < 1e-10
    assert energy_error < 1e-9 and L_error < 1e-9 and P_error < 1e-9
    assert position_error < 1e-8
    assert len(crossings) >= 8
    assert period_error < 1e-7
    assert cos_pitch[0] < 1e-15 and cos_pitch[res.t > crossings[0]].min() < 2e-2
    # between successive zeros of w2, axis 2 turns to along L, then against it
    extremes = []
    for a, b in zip(crossings[:-1], crossings[1:]):
        between = axis2_on_L[(res.t > a) & (res.t < b)]
        extremes.append(between[np.abs(between).argmax()])
    assert np.all(np.abs(extremes) > 0.99)
    assert np.all(np.sign(extremes[1:]) == -np.sign(extremes[:-1]))


def test_tennis_racket_scene_runs_and_conserves_energy(build_root):
    scene = modelgen.load_scene(MODELS / "scenes" / "tennis_racket_flip.yaml",
                                build_root / "tennis_racket_flip")
    res = scene.run()
    assert res.success, res.message
    cm = scene.model
    energy = np.ravel(res["energy"])
    assert np.abs(energy / energy[0] - 1).max() < 1e-8
    norm_error = np.abs(np.linalg.norm(res.y[3:7], axis=0) - 1).max()
    assert norm_error < 1e-10
    # the outputs of a joint's base: its orientation is R(q), its angular velocity
    # in its own components the speeds w (R(q) of a quaternion of norm 1 + e is
    # off a rotation by 4 e at most, R'R w off w by about 8 e |w|)
    R = np.array([rotation(quat) for quat in res.y[3:7].T])
    assert np.abs(res["attitude"] - R.reshape(-1, 9)).max() < 1e-14 + 4.5 * norm_error
    w = res.y[10:13].T
    assert np.abs(res["omega"] - w).max() < 1e-14 + 9 * norm_error * np.abs(w).max()
    w2 = res.y[cm.state_names.index("J_wy")]
    assert w2.max() > 1.9 and w2.min() < -1.9          # it flipped


def test_quaternions_are_unit_at_dense_output_samples_at_the_default_tolerance(racket):
    cm = racket
    x0 = cm.neutral_state()
    x0[3:7] = RACKET_ATTITUDE
    x0[10:13] = [0.1, 2.0, 0.0]
    for method in ("dop853", "dopri5", "rodas"):
        steps = cm.simulate(x0, (0.0, 40.0), method=method)
        samples = cm.simulate(x0, (0.0, 40.0), t_eval=np.linspace(0.0, 40.0, 4001),
                              method=method)
        assert steps.success and samples.success
        assert np.abs(np.linalg.norm(steps.y[3:7], axis=0) - 1).max() < 1e-15
        assert np.abs(np.linalg.norm(samples.y[3:7], axis=0) - 1).max() < 1e-10, method


# -- 3. a ball joint against Euler angles --------------------------------------------------

def _zxz_to_ball(x):
    """The ball model's state at the ZXZ model's state (same physical state)."""
    q, qd = x[:3], x[3:]
    return np.concatenate([quaternion_of(zxz_rotation(q)), zxz_body_rate_matrix(q) @ qd])


def test_ball_joint_equations_map_to_the_euler_angle_ones(compiled):
    """With w = J(q) qd (J: ZXZ body rates): A_e = J'A_b J, h_e = J'(A_b Jdot qd + h_b),
    tau_e = J' tau_b, and the same energies and poses."""
    ball = compiled(DATA / "heavy_body_ball.yaml")
    zxz = compiled(DATA / "heavy_body_zxz.yaml")
    rng = np.random.default_rng(3)
    worst = {}
    for _ in range(20):
        q = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(0.3, 2.8),
                      rng.uniform(-np.pi, np.pi)])
        qd = rng.normal(size=3)
        xb = _zxz_to_ball(np.concatenate([q, qd]))
        qb, w = xb[:4], xb[4:]
        J = zxz_body_rate_matrix(q)
        Jdot_qd = zxz_body_rate_matrix(q + 1e-30j * qd).imag / 1e-30 @ qd   # complex step
        Ab = ball.mass_matrix(qb)
        pairs = {"A": (J.T @ Ab @ J, zxz.mass_matrix(q)),
                 "h": (J.T @ (Ab @ Jdot_qd + ball.velocity_terms(qb, w)),
                       zxz.velocity_terms(q, qd)),
                 "tau": (J.T @ ball.generalized_forces(0.0, qb, w),
                         zxz.generalized_forces(0.0, q, qd)),
                 "energy": (ball.energy(qb, w), zxz.energy(q, qd)),
                 "poses": (ball.body_poses(qb), zxz.body_poses(q))}
        for key, (got, expected) in pairs.items():
            worst[key] = max(worst.get(key, 0.0), relative_error(got, expected))
    SUMMARY.append("joints: ball joint vs ZXZ angles, worst relative error "
                   + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert max(worst.values()) < 1e-12, worst


def test_ball_joint_follows_the_euler_angle_trajectory(compiled):
    ball = compiled(DATA / "heavy_body_ball.yaml")
    zxz = compiled(DATA / "heavy_body_zxz.yaml")
    x_e = np.array([0.3, 1.0, 0.2, 1.5, -0.8, 25.0])      # a spinning top, nutating
    x_b = _zxz_to_ball(x_e)
    t = np.linspace(0.0, 3.0, 301)
    opts = dict(t_eval=t, method="dop853", rtol=1e-12, atol=1e-13)
    res_e = zxz.simulate(x_e, (0.0, 3.0), **opts)
    res_b = ball.simulate(x_b, (0.0, 3.0), **opts)
    assert res_e.success and res_b.success
    theta = res_e.y[1]
    assert 0.3 < theta.min() and theta.max() < np.pi - 0.3      # away from gimbal lock
    assert np.ptp(theta) > 0.1                                     # and it nutates
    poses_e = np.array([zxz.body_poses(x[:3]) for x in res_e.y.T])
    poses_b = np.array([ball.body_poses(x[:4]) for x in res_b.y.T])
    pose_error = np.abs(poses_b - poses_e).max()
    energy = ball.energies(res_b).sum(axis=1)
    scale = np.abs(ball.energies(res_b)).max()
    energy_error = np.abs(energy - energy[0]).max() / scale
    norm_error = np.abs(np.linalg.norm(res_b.y[:4], axis=0) - 1).max()
    SUMMARY.append(f"joints: heavy body, ball vs ZXZ over 3 s: pose {pose_error:.1e}, "
                   f"energy {energy_error:.1e}, |q|-1 {norm_error:.1e}")
    assert pose_error < 1e-8
    assert energy_error < 1e-10
    assert norm_error < 1e-10


# -- 4. a mixed tree: a free base with two hinged links ------------------------------------

def _tree_state(cm, rng):
    x = np.concatenate([rng.uniform(-np.pi, np.pi, 2), rng.normal(size=3),
                        unit_quaternion(rng), rng.normal(size=cm.n)])
    return x


def test_free_base_tree_mass_matrix_is_symmetric_positive_definite(tree):
    cm = tree
    assert cm.state_names[:2] == ("q1", "q2") and cm.quaternions == ((5, 6, 7, 8),)
    assert cm.speeds == ("q1_dot", "q2_dot", "J_vx", "J_vy", "J_vz", "J_wx", "J_wy", "J_wz")
    rng = np.random.default_rng(5)
    m_total = sum(cm.parameters[k] for k in ("m0", "m1", "m2"))
    for _ in range(20):
        x = _tree_state(cm, rng)
        A = cm.mass_matrix(x[:cm.nq])
        assert np.abs(A - A.T).max() <= 1e-14 * np.abs(A).max()
        assert np.linalg.eigvalsh(A).min() > 0
        # a pure translation of the base moves the whole mass
        assert np.allclose(A[2:5, 2:5], m_total * np.eye(3), rtol=0, atol=1e-13)


def _centre_velocities(cm, x, h=1e-6):
    """Every body's G velocity in E, by central differences of body_poses along dq/dt."""
    qdot = cm.rhs(0.0, x)[:cm.nq]
    q = x[:cm.nq]
    return (cm.body_poses(q + h * qdot)[:, :3, 3] - cm.body_poses(q - h * qdot)[:, :3, 3]) / (2 * h)


def test_free_base_tree_conserves_energy_and_linear_momentum(tree):
    cm = tree
    rng = np.random.default_rng(6)
    x0 = _tree_state(cm, rng)
    t = np.linspace(0.0, 5.0, 101)
    res = cm.simulate(x0, (0.0, 5.0), t_eval=t, method="dop853", rtol=1e-11, atol=1e-12)
    assert res.success, res.message
    masses = np.array([cm.parameters[k] for k in ("m0", "m1", "m2")])
    momentum = np.array([masses @ _centre_velocities(cm, x) for x in res.y.T])
    T = cm.energies(res)[:, 0]
    energy_error = np.abs(T / T[0] - 1).max()
    momentum_error = np.abs(momentum - momentum[0]).max() / np.linalg.norm(momentum[0])
    norm_error = np.abs(np.linalg.norm(res.y[5:9], axis=0) - 1).max()
    SUMMARY.append(f"joints: free base + 2 links, 5 s: energy {energy_error:.1e}, "
                   f"momentum {momentum_error:.1e}, |q|-1 {norm_error:.1e}")
    assert np.ptp(res.y[0]) > 0.5 and np.ptp(res.y[1]) > 0.5    # the links swing
    assert energy_error < 1e-9
    assert momentum_error < 1e-8
    assert norm_error < 1e-10


def test_free_base_tree_symbolic_jacobian_equals_central_differences(tree):
    cm = tree
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(3):
        x = _tree_state(cm, rng)
        J = cm.jac(0.0, x)
        assert J.shape == (cm.nx, cm.nx)
        fd = np.empty_like(J)
        for j in range(cm.nx):
            h = 1e-6 * max(1.0, abs(x[j]))
            e = np.zeros(cm.nx)
            e[j] = h
            fd[:, j] = (cm.rhs(0.0, x + e) - cm.rhs(0.0, x - e)) / (2 * h)
        worst = max(worst, relative_error(J, fd))
    SUMMARY.append(f"joints: free base + 2 links, symbolic Jacobian vs central differences "
                   f"{worst:.1e}")
    assert worst < 1e-7


def test_free_base_tree_aba_equals_crba(tree, build_root):
    aba = modelgen.load(DATA / "free_base_two_links.yaml", build_root / "joints_tree_aba",
                        formulation="aba")
    rng = np.random.default_rng(8)
    for _ in range(5):
        x = _tree_state(tree, rng)
        assert relative_error(aba.rhs(0.0, x), tree.rhs(0.0, x)) < 1e-12


# -- 5. the joints: section's errors and the writer ----------------------------------------

HEADER = """name: m
parameters: {m: 1.0}
"""                 # lines 1-2; the snippets start at line 3


def message(snippet: str) -> str:
    with pytest.raises(ModelError) as info:
        parse_model(HEADER + snippet, source="m.yaml")
    return str(info.value)


def test_unknown_joint_type_is_refused():
    assert message("joints:\n  J: {type: planar, parent: E, base: B}\n") == (
        "m.yaml:4: joints.J.type: unknown joint type the string 'planar'; fix: use 'ball' "
        "(a quaternion, 3 speeds) or 'free' (a position and a quaternion, 6 speeds); a hinge "
        "is a base with an axis and an angle")


def test_a_ball_joint_has_no_point():
    assert message("joints:\n  J: {type: ball, parent: E, base: B, point: P}\n") == (
        "m.yaml:4: joints.J.point: a ball joint has no 'point'; "
        "fix: remove it, or make the joint 'type: free'")


def test_a_free_joint_needs_a_point():
    assert message("joints:\n  J: {type: free, parent: E, base: B}\n") == (
        "m.yaml:4: joints.J: missing required key 'point'; "
        "fix: a free joint makes a point: add 'point: <new point name>'")


def test_a_joint_base_may_not_reuse_a_base_name():
    assert message("coordinates: [q1]\nbases:\n  B: {parent: E, axis: 3, angle: q1}\n"
                   "joints:\n  J: {type: ball, parent: E, base: B}\n") == (
        "m.yaml:5: bases.B: duplicate name 'B': already declared as a base at joints.J "
        "(line 7); fix: rename one of them; coordinates, parameters, inputs, bases, points, "
        "frames, bodies and actions share one namespace")


def test_a_joint_coordinate_in_a_point_is_refused():
    assert message("joints:\n  J: {type: ball, parent: E, base: B}\n"
                   "points:\n  P: {from: O, base: B, coordinates: [J_qx, 0, 0]}\n") == (
        "m.yaml:6: points.P.coordinates[0]: joint coordinate 'J_qx' is not allowed in "
        "expression 'J_qx'; fix: use only coordinates and parameters here (positions and "
        "angles cannot depend on speeds, inputs or t)")


def test_a_joint_coordinate_in_an_angle_is_refused_by_the_api():
    from modelgen.model.api import Model
    with pytest.raises(ModelError) as info:
        Model("m").add_joint("J", "ball", parent="E", base="B").add_base(
            "B2", parent="B", axis=3, angle="2*J_qw")
    assert str(info.value) == (
        "<api>: bases.B2.angle: joint coordinate 'J_qw' is not allowed in expression "
        "'2*J_qw'; fix: use only coordinates and parameters here (positions and angles "
        "cannot depend on speeds, inputs or t)")


def test_a_joint_coordinate_in_an_angle_is_refused_naming_the_joint_coordinate():
    text = message("joints:\n  J: {type: ball, parent: E, base: B}\n"
                   "bases:\n  B2: {parent: B, axis: 3, angle: sin(J_qw)}\n")
    assert text.startswith("m.yaml:6: bases.B2.angle: ")
    assert "joint coordinate 'J_qw' is not allowed" in text


def test_a_joint_coordinate_in_an_angle_is_refused_with_file_line_and_key():
    """Whatever the wording, the message names the file, line, key and name."""
    text = message("joints:\n  J: {type: ball, parent: E, base: B}\n"
                   "bases:\n  B2: {parent: B, axis: 3, angle: sin(J_qw)}\n")
    assert text.startswith("m.yaml:6: bases.B2.angle: ") and "'J_qw'" in text


SCENE = """scene: s
model: heavy_body_ball.yaml
effects: [gravity]
initial: {{J_qw: {w}, J_qx: {x}, J_qy: 0.0, J_qz: 0.0, J_wx: 0.0, J_wy: 0.0, J_wz: 1.0}}
time: {{end: 1.0, sample: 0.01}}
"""


def test_a_zero_initial_quaternion_in_a_scene_is_refused():
    with pytest.raises(ModelError) as info:
        parse_scene(SCENE.format(w=0.0, x=0.0), source="s.yaml", base_dir=DATA)
    assert str(info.value) == (
        "s.yaml:4: initial: the quaternion of joint 'J' is zero; fix: give a unit "
        "quaternion, e.g. J_qw: 1.0 and the others 0 for no rotation (it is normalised)")


def test_a_scene_normalises_its_initial_quaternion(build_root):
    spec = parse_scene(SCENE.format(w=2.0, x=2.0), source="s.yaml", base_dir=DATA)
    from modelgen.sim.scene import Scene
    scene = Scene(spec, build_root / "joints_scene")
    res = scene.run()
    assert res.success, res.message
    assert np.allclose(res.y[:4, 0], [np.sqrt(0.5), np.sqrt(0.5), 0, 0], rtol=0, atol=1e-15)
    assert np.abs(np.linalg.norm(res.y[:4], axis=0) - 1).max() < 1e-10


def test_simulate_refuses_a_zero_quaternion_naming_it(racket):
    x0 = np.zeros(racket.nx)
    x0[racket.state_names.index("J_wy")] = 1.0
    with pytest.raises(SimulationError, match="quaternion"):
        racket.simulate(x0, (0.0, 1.0))


def test_linearizing_a_model_with_joints_is_refused_with_the_reason(tmp_path):
    with pytest.raises(ModelError) as info:
        modelgen.load(DATA / "heavy_body_ball.yaml", tmp_path, linearize=True)
    text = str(info.value)
    assert text.startswith(f"{DATA / 'heavy_body_ball.yaml'}: linearize: ")
    assert "ball or free joints is not supported" in text
    assert "fix: build with derivatives=True and use cm.derivatives" in text


@pytest.mark.parametrize("path", sorted(DATA.glob("*.yaml")), ids=lambda p: p.stem)
def test_writer_round_trip_gives_an_equal_spec(path):
    spec = load_model(path)
    text = spec_to_yaml(spec)
    again = parse_model(text, source="written.yaml")
    assert again == spec
    assert spec_to_yaml(again) == text


# -- 6. the command line --------------------------------------------------------------------

def test_cli_simulate_writes_the_state_names_as_csv_columns(tmp_path, racket):
    out = tmp_path / "out"
    argv = ["simulate", str(RACKET), "--build-dir", str(tmp_path / "b"),
            "-o", str(out), "--init", "J_wy=2", "--init", "J_wx=0.1", "--t-end", "1",
            "--no-plot", "--quiet"]
    assert main(argv) == 0
    with open(out / "tennis_racket.csv") as fh:
        rows = list(csv.reader(fh))
    nx = racket.nx
    assert rows[0][:1 + nx] == ["t", *racket.state_names]
    data = np.array(rows[1:], dtype=float)
    assert data[-1, 0] == 1.0
    quat = data[:, 1 + 3:1 + 7]
    assert np.allclose(quat[0], [1, 0, 0, 0], rtol=0, atol=0)
    assert np.abs(np.linalg.norm(quat, axis=1) - 1).max() < 1e-10
    assert abs(data[-1, 1 + racket.state_names.index("J_wy")]) > 1.0


def test_dense_output_quaternions_are_unit(racket):
    """res.sol interpolates between the steps and normalises the quaternion as the C
    samples do (an FMU of a quaternion model: tests/test_fmu_joints.py)."""
    x0 = racket.neutral_state()
    x0[3:7] = RACKET_ATTITUDE
    x0[10:13] = [0.1, 2.0, 0.0]
    res = racket.simulate(x0, (0.0, 10.0), rtol=1e-6, atol=1e-8, dense_output=True)
    t = np.linspace(0.0, 10.0, 997)
    y = res.sol(t)
    assert np.abs(np.linalg.norm(y[3:7], axis=0) - 1).max() < 1e-14
    sampled = racket.simulate(x0, (0.0, 10.0), t_eval=t, rtol=1e-6, atol=1e-8)
    # the nodes inside each step were normalised by the C, the interpolant between
    # them here: the two differ by the interpolation error (rtol 1e-6), not more
    assert np.abs(y - sampled.y).max() < 1e-6
