"""Constrained models (``constraints:``): the rhs against sympy.physics.mechanics
``KanesMethod`` with dependent speeds and velocity constraints, written by hand
in ``constrained_references.py`` (nothing shared with modelgen but the parameter
values), and a four-bar's
position against Freudenstein's closed form.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy
from sympy.physics.mechanics import dynamicsymbols

from constrained_references import WHEEL_DISC, four_bar_kane, rolling_disc_kane

import modelgen
from modelgen.errors import ModelError
from modelgen.model.api import Model, parse_model, spec_to_yaml

ROOT = Path(__file__).resolve().parent.parent
RTOL = 1e-12
t = dynamicsymbols._t


def _kane_accelerations(kane, q, u, u_ind, u_dep, vc, params):
    """A function (q values, u_i values) -> (u values, u' values): the dependent
    speeds from the velocity constraints, every acceleration from KanesMethod's
    ``mass_matrix`` and ``forcing`` (with dependent speeds these are the n
    equations: Kane's projected ones and the velocity constraints' time
    derivatives)."""
    plain_q, plain_u = sympy.symbols(f"Q0:{len(q)}"), sympy.symbols(f"U0:{len(u)}")
    swap = dict(zip(q, plain_q)) | dict(zip(u, plain_u))

    def compile_(e):
        return sympy.lambdify((plain_q, plain_u), sympy.sympify(e).subs(params).xreplace(swap),
                              "numpy")
    f_M, f_F = compile_(kane.mass_matrix), compile_(kane.forcing)
    f_B = compile_(sympy.Matrix(vc).jacobian(u))
    i_ind = [u.index(s) for s in u_ind]
    i_dep = [u.index(s) for s in u_dep]

    def accel(qv, ui_v):
        uv = np.zeros(len(u))
        uv[i_ind] = ui_v
        B = np.array(f_B(qv, uv), dtype=float)
        uv[i_dep] = np.linalg.solve(B[:, i_dep], -B[:, i_ind] @ uv[i_ind])
        M = np.array(f_M(qv, uv), dtype=float)
        assert M.shape == (len(u), len(u))
        return uv, np.linalg.solve(M, np.array(f_F(qv, uv), dtype=float).ravel())
    return accel


def four_bar_reference(values):
    kane, q, u, syms, vc = four_bar_kane()
    return _kane_accelerations(kane, q, u, u[:1], u[1:], vc, dict(zip(syms, values)))


def rolling_disc_reference(values):
    kane, q, u, syms, vc = rolling_disc_kane()
    return _kane_accelerations(kane, q, u, u[:3], u[3:], vc, dict(zip(syms, values)))


@pytest.fixture(scope="module")
def four_bar():
    return modelgen.load(ROOT / "models" / "four_bar.yaml")


@pytest.fixture(scope="module")
def rolling_disc():
    return modelgen.load(ROOT / "models" / "rolling_disc.yaml")


def _compare(cm, reference, rng, n_states, q_scale=np.pi, u_scale=2.0):
    worst = 0.0
    ind = cm.manifest["constraints"]["independent_speeds"]
    for _ in range(n_states):
        q = rng.uniform(-q_scale, q_scale, cm.nq)
        ui = rng.uniform(-u_scale, u_scale, len(ind))
        u_ref, a_ref = reference(q, ui)
        x = np.concatenate([q, rng.normal(size=cm.n)])     # dependent speeds: ignored
        x[cm.nq + np.array(ind)] = ui
        xdot = cm.rhs(0.0, x)
        got = np.concatenate([xdot[:cm.nq], xdot[cm.nq:]])
        want = np.concatenate([u_ref, a_ref])
        err = np.linalg.norm(got - want) / max(np.linalg.norm(want), 1e-3)
        worst = max(worst, err)
    return worst


def test_four_bar_rhs_matches_kanes_method_with_dependent_speeds(four_bar):
    reference = four_bar_reference(list(four_bar.parameters.values()))
    worst = _compare(four_bar, reference, np.random.default_rng(26), 20)
    assert worst <= RTOL, worst


def test_rolling_disc_rhs_matches_kanes_method_with_dependent_speeds(rolling_disc):
    reference = rolling_disc_reference(list(rolling_disc.parameters.values()))
    worst = _compare(rolling_disc, reference, np.random.default_rng(27), 20, q_scale=1.2)
    assert worst <= RTOL, worst


# -- positions, assembly, drift --------------------------------------------------

def freudenstein_rocker(theta2, a, b, c, d):
    """Both rocker angles theta4 of a four-bar (ground d, crank a, coupler b, rocker c)
    from Freudenstein's equation K1 cos t4 - K2 cos t2 + K3 = cos(t2 - t4)."""
    K1, K2, K3 = d / a, d / c, (a**2 - b**2 + c**2 + d**2) / (2 * a * c)
    A, B, C = K1 - np.cos(theta2), -np.sin(theta2), K3 - K2 * np.cos(theta2)
    root = np.sqrt(B**2 - (C - A) * (C + A))
    return [2 * np.arctan((-B + s * root) / (C - A)) for s in (1.0, -1.0)]


def test_four_bar_assembly_matches_freudenstein(four_bar):
    a, b, c, d = (four_bar.parameters[k] for k in "abcd")
    q = np.array([0.3, 1.0, 2.0])
    worst = 0.0
    for theta2 in np.linspace(0.0, 2 * np.pi, 13):
        q = four_bar.assemble([theta2, q[1], q[2]], keep=["q1"])
        assert q[0] == theta2
        assert np.max(np.abs(four_bar.constraint_residuals(q))) <= 1e-13
        expected = min(freudenstein_rocker(theta2, a, b, c, d),
                       key=lambda t4: abs(np.angle(np.exp(1j * (t4 - q[2])))))
        worst = max(worst, abs(np.angle(np.exp(1j * (q[2] - expected)))))
    assert worst <= 1e-12, worst


def test_four_bar_energy_and_constraints_hold_over_100_s(four_bar):
    q0 = four_bar.assemble([0.3, 1.0, 2.0], keep=["q1"])
    qd0 = four_bar.consistent_speeds(q0, [2.0, 0.0, 0.0])
    res = four_bar.simulate(np.concatenate([q0, qd0]), (0.0, 100.0),
                            t_eval=np.linspace(0.0, 100.0, 2001), method="dop853",
                            rtol=1e-12, atol=1e-12)
    assert res.success, res.message
    q, qd = res.y[:3], res.y[3:]
    residual = max(np.max(np.abs(four_bar.constraint_residuals(q[:, k])))
                   for k in range(q.shape[1]))
    velocity = max(np.max(np.abs(four_bar.constraint_jacobian(q[:, k]) @ qd[:, k]))
                   for k in range(q.shape[1]))
    energy = np.array([four_bar.energy(q[:, k], qd[:, k]).sum() for k in range(q.shape[1])])
    drift = np.max(np.abs(energy - energy[0])) / abs(energy[0])
    assert residual <= 1e-12, residual
    assert velocity <= 1e-10, velocity
    assert drift <= 1e-8, drift


def test_the_c_projection_onto_the_constraints_is_exported(four_bar):
    """<name>_constrain, what the integrators call after every step, is public so a C
    user's own stepper can call it too: a state 1e-3 off the loop comes back onto it
    (f(q) and G qd to rounding); one it cannot bring back returns 1, x unchanged."""
    cm = four_bar
    constrain = getattr(cm.lib, f"{cm.name}_constrain")
    q = cm.assemble(np.full(cm.nq, 0.5))
    x = np.concatenate([q, cm.consistent_speeds(q, np.full(cm.n, 0.3))])
    x[:cm.nq] += 1e-3
    x[cm.nq:] += 1e-2
    assert constrain(cm._ptr(cm.params()), cm._ptr(x)) == 0
    q, qd = x[:cm.nq], x[cm.nq:]
    assert np.max(np.abs(cm.constraint_residuals(q))) < 1e-12
    assert np.max(np.abs(cm.constraint_jacobian(q) @ qd)) < 1e-12
    far = np.concatenate([np.full(cm.nq, 0.5), np.full(cm.n, 0.3)])
    before = far.copy()
    assert constrain(cm._ptr(cm.params()), cm._ptr(far)) == 1
    assert np.array_equal(far, before)


def test_simulate_refuses_a_state_off_the_constraints(four_bar):
    with pytest.raises(modelgen.errors.SimulationError, match="assemble it first"):
        four_bar.simulate([0.3, 1.0, 2.0, 0.0, 0.0, 0.0], (0.0, 1.0))
    q0 = four_bar.assemble([0.3, 1.0, 2.0], keep=["q1"])
    with pytest.raises(modelgen.errors.SimulationError, match="consistent_speeds"):
        four_bar.simulate(np.concatenate([q0, [1.0, 1.0, 1.0]]), (0.0, 1.0))


def test_a_singular_dependent_block_is_an_error_naming_the_dead_point(four_bar):
    # every angle zero: coupler and rocker collinear, the dependent columns of G singular
    with pytest.raises(modelgen.errors.SimulationError, match="dead point") as info:
        four_bar.rhs(0.0, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    assert "pivot of q3_dot" in str(info.value)


def test_four_bar_at_its_dead_point_stops_with_a_status(tmp_path):
    # the rocker's speed independent: at the rocker's extreme positions crank and
    # coupler are collinear and the crank's and coupler's speeds are not determined
    text = (ROOT / "models" / "four_bar.yaml").read_text().replace(
        "name: four_bar", "name: four_bar_rocker").replace(
        "dependent: {coordinates: [q2, q3], speeds: [q2_dot, q3_dot]}",
        "dependent: {coordinates: [q1, q2], speeds: [q1_dot, q2_dot]}")
    path = tmp_path / "four_bar_rocker.yaml"
    path.write_text(text)
    cm = modelgen.load(path)
    a, b, c, d = (cm.parameters[k] for k in "abcd")
    # |D + c e(q3)| = a + b: crank and coupler stretched out in line
    q3 = np.arccos(((a + b) ** 2 - d**2 - c**2) / (2 * c * d))
    theta = np.arctan2(c * np.sin(q3), d + c * np.cos(q3))
    x0 = np.array([theta, theta, q3, 0.0, 0.0, 0.0])
    assert np.max(np.abs(cm.constraint_residuals(x0[:3]))) <= 1e-14
    res = cm.simulate(x0, (0.0, 1.0), method="dop853")
    assert res.status == modelgen.codegen.capi.STATUS_BY_NAME["PROJECTION"].code
    assert "dead point" in res.message and "x=[" in res.message, res.message
    assert np.all(np.isfinite(res.y))
    with pytest.raises(modelgen.errors.SimulationError, match="pivot of q"):
        cm.rhs(0.0, x0)


# -- the model format ------------------------------------------------------------------

FOUR_BAR = (ROOT / "models" / "four_bar.yaml").read_text()


def test_constraints_round_trip_through_yaml():
    for name in ("four_bar", "rolling_disc"):
        spec = modelgen.model.api.load_model(ROOT / "models" / f"{name}.yaml")
        assert parse_model(spec_to_yaml(spec)) == spec


def test_constraints_from_the_python_api_equal_the_yaml():
    m = Model("slider").add_coordinates("x", "y").add_parameters({"L": 1.0, "m": 1.0})
    m.add_point("P", coordinates=["x", "y", 0]).add_body("b", mass="m", G="P", base="E")
    m.add_constraint("circle", "position", expression="x**2 + y**2 - L**2")
    m.set_dependent(coordinates=["y"], speeds=["y_dot"])
    spec = m.spec()
    assert parse_model(spec_to_yaml(spec)) == spec
    assert spec.constraints[0].expression == sympy.sympify("x**2 + y**2 - L**2")


@pytest.mark.parametrize("old, new, message, key", [
    ("point_b: P3", "point_b: P9", "unknown point 'P9'", "constraints.loop.point_b"),
    ("base: E, axes", "base: B7, axes", "unknown base 'B7'", "constraints.loop.base"),
    ("axes: [1, 2]", "axes: [1, 4]", "axis must be 1, 2 or 3", "constraints.loop.axes[1]"),
    ("type: coincide", "type: coincident", "unknown constraint type", "constraints.loop.type"),
    ("speeds: [q2_dot, q3_dot]", "speeds: [q2_dot]", "1 dependent speeds for 2 constraint",
     "dependent"),
    ("coordinates: [q2, q3], speeds", "coordinates: [q2, q9], speeds",
     "'q9' is not a declared coordinate", "dependent.coordinates[1]"),
    ("axes: [1, 2]", "axes: [1, 2, 3]",
     "3 constraint equations for 3 coordinates", "constraints.loop"),
])
def test_constraint_errors_name_file_line_key_and_fix(old, new, message, key):
    assert old in FOUR_BAR
    with pytest.raises(ModelError) as info:
        parse_model(FOUR_BAR.replace(old, new), "four_bar.yaml")
    err = info.value
    assert message in str(err), str(err)
    assert err.key == key and err.file == "four_bar.yaml" and err.line is not None
    assert err.fix


def test_a_constraint_not_linear_in_the_speeds_is_refused():
    text = FOUR_BAR.replace(
        "loop: {type: coincide, point_a: P2, point_b: P3, base: E, axes: [1, 2]}",
        "loop: {type: coincide, point_a: P2, point_b: P3, base: E, axes: [1]}\n"
        "  spin: {type: speeds, expression: 'q1_dot*q2_dot - q3_dot'}")
    with pytest.raises(ModelError, match="not linear in the speeds") as info:
        parse_model(text, "four_bar.yaml")
    assert info.value.key == "constraints.spin.expression" and info.value.line is not None
    text = text.replace("q1_dot*q2_dot - q3_dot", "q1_dot - 1")
    with pytest.raises(ModelError, match="term without a speed"):
        parse_model(text, "four_bar.yaml")


def test_redundant_constraints_are_refused_at_generation(tmp_path):
    # a planar loop closed along z as well: the z equation is 0 = 0
    text = FOUR_BAR.replace("name: four_bar", "name: four_bar_z").replace(
        "coordinates: [q1, q2, q3]", "coordinates: [q1, q2, q3, q4]").replace(
        "axes: [1, 2]}", "axes: [1, 2, 3]}").replace(
        "coordinates: [q2, q3], speeds: [q2_dot, q3_dot]",
        "coordinates: [q2, q3, q4], speeds: [q2_dot, q3_dot, q4_dot]")
    path = tmp_path / "four_bar_z.yaml"
    path.write_text(text)
    with pytest.raises(ModelError, match="redundant") as info:
        modelgen.load(path)
    assert info.value.line is not None and "loop" in str(info.value)


def test_slider_crank_piston_follows_the_closed_form():
    cm = modelgen.load(ROOT / "models" / "slider_crank.yaml")
    r, l = cm.parameters["r"], cm.parameters["l"]
    q = np.array([0.0, 0.0, r + l])
    worst = 0.0
    for q1 in np.linspace(0.0, 2 * np.pi, 17):
        q = cm.assemble([q1, q[1], q[2]], keep=["q1"])
        expected = r * np.cos(q1) + np.sqrt(l**2 - (r * np.sin(q1)) ** 2)
        worst = max(worst, abs(q[2] - expected))
    assert worst <= 1e-12, worst


def test_dependent_speeds_chosen_by_pivoting_give_the_same_motion(tmp_path, four_bar):
    text = FOUR_BAR.replace("name: four_bar", "name: four_bar_auto").replace(
        "dependent: {coordinates: [q2, q3], speeds: [q2_dot, q3_dot]}\n", "")
    path = tmp_path / "four_bar_auto.yaml"
    path.write_text(text)
    cm = modelgen.load(path)
    info = cm.manifest["constraints"]
    assert info["chosen"] and len(info["dependent_speeds"]) == 2
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(10):
        q = four_bar.assemble(rng.uniform(-np.pi, np.pi, 3))
        qd = four_bar.consistent_speeds(q, [rng.normal(), 0.0, 0.0])
        x = np.concatenate([q, qd])
        a, b = cm.rhs(0.0, x), four_bar.rhs(0.0, x)
        worst = max(worst, np.linalg.norm(a - b) / np.linalg.norm(b))
    assert worst <= 1e-12, worst




def test_rolling_helper_moves_as_the_written_out_disc(tmp_path, rolling_disc):
    """The ``rolling`` kind (contact geometry, height and no-slip built by modelgen)
    against the disc written out by hand (checked against KanesMethod above)."""
    spec = parse_model(WHEEL_DISC)
    assert parse_model(spec_to_yaml(spec)) == spec
    path = tmp_path / "wheel_disc.yaml"
    path.write_text(WHEEL_DISC)
    wheel = modelgen.load(path)
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(20):
        q = np.concatenate([rng.uniform(-1.2, 1.2, 3), rng.normal(size=2)])
        qd = rolling_disc.consistent_speeds(q, np.concatenate([rng.normal(size=3), [0, 0]]))
        x = np.concatenate([q, qd])
        centre = rolling_disc.body_poses(q).reshape(-1, 4, 4)[0][:3, 3]
        xw = np.concatenate([q[:3], centre, qd[:3], np.zeros(3)])
        assert np.max(np.abs(wheel.constraint_residuals(xw[:6]))) <= 1e-14
        want, got = rolling_disc.rhs(0.0, x), wheel.rhs(0.0, xw)
        # yaw, lean, spin and their accelerations; the centre's velocity
        pairs = [(got[:3], want[:3]), (got[6:9], want[5:8])]
        err = sum(np.linalg.norm(a - b) for a, b in pairs) / sum(np.linalg.norm(b)
                                                                  for _, b in pairs)
        worst = max(worst, err)
    assert worst <= 1e-12, worst


# -- constraints beside ball and free joints ---------------------------------------------
#
# A four-bar whose ground link is a free body (no gravity): the free joint's
# quaternion and position stay independent, the loop closes through the plain
# angles.  Its twin writes the ground link's attitude with ZYX angles and its
# position with three lengths (every coordinate plain, the path checked against
# KanesMethod above), so the two must give the same motion at matching states.

FLOATING_FOUR_BAR = """
name: floating_four_bar
coordinates: [q1, q2, q3]
parameters: {a: 1.0, b: 2.0, c: 2.0, d: 2.5, m0: 3.0, m1: 1.0, m2: 2.0, m3: 2.0}
joints:
  J: {type: free, parent: E, base: B0, point: P0}
bases:
  B1: {parent: B0, axis: 3, angle: q1}
  B2: {parent: B0, axis: 3, angle: q2}
  B3: {parent: B0, axis: 3, angle: q3}
points:
  G0: {from: P0, base: B0, coordinates: [d/2, 0.1, 0.2]}
  D:  {from: P0, base: B0, coordinates: [d, 0, 0]}
  P1: {from: P0, base: B1, coordinates: [a, 0, 0]}
  G1: {from: P0, base: B1, coordinates: [a/2, 0, 0]}
  P2: {from: P1, base: B2, coordinates: [b, 0, 0]}
  G2: {from: P1, base: B2, coordinates: [b/2, 0, 0]}
  P3: {from: D, base: B3, coordinates: [c, 0, 0]}
  G3: {from: D, base: B3, coordinates: [c/2, 0, 0]}
bodies:
  ground:  {mass: m0, G: G0, base: B0, inertia: [0.4, 1.2, 1.5]}
  crank:   {mass: m1, G: G1, base: B1, inertia: [0.01, m1*a**2/12, m1*a**2/12]}
  coupler: {mass: m2, G: G2, base: B2, inertia: [0.02, m2*b**2/12, m2*b**2/12]}
  rocker:  {mass: m3, G: G3, base: B3, inertia: [0.02, m3*c**2/12, m3*c**2/12]}
constraints:
  loop: {type: coincide, point_a: P2, point_b: P3, base: B0, axes: [1, 2]}
dependent: {coordinates: [q2, q3], speeds: [q2_dot, q3_dot]}
"""

EULER_FOUR_BAR = FLOATING_FOUR_BAR.replace("name: floating_four_bar", "name: euler_four_bar") \
    .replace("coordinates: [q1, q2, q3]\n",
             "coordinates: [q1, q2, q3, x, y, z, yaw, pitch, roll]\n") \
    .replace("joints:\n  J: {type: free, parent: E, base: B0, point: P0}\n", "") \
    .replace("bases:\n", "bases:\n  Y1: {parent: E, axis: 3, angle: yaw}\n"
             "  Y2: {parent: Y1, axis: 2, angle: pitch}\n"
             "  B0: {parent: Y2, axis: 1, angle: roll}\n") \
    .replace("points:\n", "points:\n  P0: {coordinates: [x, y, z]}\n")


def _yaml_model(tmp_path_factory, text, name):
    path = tmp_path_factory.mktemp(name) / f"{name}.yaml"
    path.write_text(text)
    return modelgen.load(path)


@pytest.fixture(scope="module")
def floating_pair(tmp_path_factory):
    return (_yaml_model(tmp_path_factory, FLOATING_FOUR_BAR, "floating_four_bar"),
            _yaml_model(tmp_path_factory, EULER_FOUR_BAR, "euler_four_bar"))


def _rot(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _quaternion(R):
    """The unit quaternion (w, x, y, z) of rotation matrix R (Shepperd's method)."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2
    x = np.copysign(np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2, R[2, 1] - R[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2, R[0, 2] - R[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2, R[1, 0] - R[0, 1])
    return np.array([w, x, y, z])


def _euler_state(euler, rng):
    """An assembled state of the Euler twin with random angles and speeds."""
    q = np.concatenate([[rng.uniform(-np.pi, np.pi)], [1.0, 2.0], rng.normal(size=3),
                        rng.uniform(-1.2, 1.2, 3)])
    q = euler.assemble(q, keep=["q1", "x", "y", "z", "yaw", "pitch", "roll"])
    qd = np.concatenate([[rng.normal()], [0.0, 0.0], rng.normal(size=6)])
    return q, euler.consistent_speeds(q, qd)


def _floating_state(q, qd):
    """The free model's state at the twin's (q, qd): the quaternion of
    R = Rz(yaw) Ry(pitch) Rx(roll), and the point's velocity and the angular
    velocity in components of the ground link's base (the free joint's speeds)."""
    yaw, pitch, roll = q[6:9]
    Rz, Ry, Rx = _rot(2, yaw), _rot(1, pitch), _rot(0, roll)
    R = Rz @ Ry @ Rx
    omega = qd[6] * np.array([0, 0, 1.0]) + qd[7] * Rz[:, 1] + qd[8] * (Rz @ Ry)[:, 0]
    xf = np.concatenate([q[:3], q[3:6], _quaternion(R), qd[:3], R.T @ qd[3:6], R.T @ omega])
    return xf, R, omega


def test_floating_four_bar_matches_its_euler_angle_twin(floating_pair):
    """The rhs with a free joint beside the loop (dependent speeds and Kane's
    projection in speed space, dq/dt = N(q) v for the joint) against the same
    system with every coordinate plain: the loop's accelerations, the point's
    acceleration r'' = R (v' + w x v) and the angular acceleration R w', to 1e-12."""
    free, euler = floating_pair
    info = free.manifest["constraints"]
    assert info["dependent"] == ["q2_dot", "q3_dot", "q2", "q3"]
    rng = np.random.default_rng(2026)
    worst = 0.0
    for _ in range(20):
        q, qd = _euler_state(euler, rng)
        xe = np.concatenate([q, qd])
        xf, R, omega = _floating_state(q, qd)
        assert np.max(np.abs(free.constraint_residuals(xf[:free.nq]))) <= 1e-12
        # the free model's dependent speeds come from the independent ones
        xf_noisy = xf.copy()
        xf_noisy[free.nq + np.array(info["dependent_speeds"])] = rng.normal(size=2)
        fe, ff = euler.rhs(0.0, xe), free.rhs(0.0, xf_noisy)
        v, w = xf[free.nq + 3:free.nq + 6], xf[free.nq + 6:]
        vdot, wdot = ff[free.nq + 3:free.nq + 6], ff[free.nq + 6:]
        # Euler twin: omega' = yaw'' e_z + pitch'' Rz e_y + roll'' Rz Ry e_x + the
        # turning of the last two axes (each frame's angular velocity crossed in)
        Rz, Ry = _rot(2, q[6]), _rot(1, q[7])
        ey, ex = Rz[:, 1], (Rz @ Ry)[:, 0]
        w1, w2 = qd[6] * np.array([0, 0, 1.0]), qd[6] * np.array([0, 0, 1.0]) + qd[7] * ey
        alpha = (fe[9 + 6] * np.array([0, 0, 1.0]) + fe[9 + 7] * ey + fe[9 + 8] * ex
                 + qd[7] * np.cross(w1, ey) + qd[8] * np.cross(w2, ex))
        pairs = [(ff[:3], fe[:3]),                       # q1..q3 rates (dependent: solved)
                 (ff[3:6], fe[3:6]),                     # dr/dt = R v
                 (ff[free.nq:free.nq + 3], fe[9:12]),    # loop accelerations
                 (R @ (vdot + np.cross(w, v)), fe[12:15]),
                 (R @ wdot, alpha)]
        scale = sum(np.linalg.norm(b) for _, b in pairs)
        worst = max(worst, sum(np.linalg.norm(a - b) for a, b in pairs) / scale)
        assert np.allclose(R @ w, omega, rtol=0, atol=1e-14)
    assert worst <= 1e-12, worst


def test_floating_four_bar_conserves_energy_and_momentum_on_the_constraints(floating_pair):
    """100 s of free flight (dop853, rtol 1e-12): the projection keeps the loop
    closed to 1e-12 and the quaternion's norm 1; the energy stays constant and the
    centre of mass moves on a straight line at constant speed (no external force)."""
    free, euler = floating_pair
    q, qd = _euler_state(euler, np.random.default_rng(7))
    x0, _, _ = _floating_state(q, qd)
    times = np.linspace(0.0, 100.0, 401)
    res = free.simulate(x0, (0.0, 100.0), t_eval=times, rtol=1e-12, atol=1e-12)
    assert res.success, res.message
    nq = free.nq
    Q, V = res.y[:nq], res.y[nq:]
    residual = max(np.max(np.abs(free.constraint_residuals(Q[:, k]))) for k in range(len(times)))
    velocity = max(np.max(np.abs(free.constraint_jacobian(Q[:, k]) @ V[:, k]))
                   for k in range(len(times)))
    norm = np.max(np.abs(np.linalg.norm(Q[6:10], axis=0) - 1.0))
    energy = np.array([free.energy(Q[:, k], V[:, k]).sum() for k in range(len(times))])
    masses = np.array([3.0, 1.0, 2.0, 2.0])
    centre = np.array([masses @ free.body_poses(Q[:, k])[:, :3, 3] / masses.sum()
                       for k in range(len(times))])
    line = centre[0] + np.outer(times / times[-1], centre[-1] - centre[0])
    assert residual <= 1e-12, residual
    assert velocity <= 1e-10, velocity
    assert norm <= 1e-14, norm
    assert np.ptp(energy) / abs(energy[0]) <= 1e-9, np.ptp(energy) / abs(energy[0])
    assert np.max(np.abs(centre - line)) <= 1e-8 * max(1.0, np.max(np.abs(centre))), \
        np.max(np.abs(centre - line))


def test_the_projection_closes_the_loop_and_normalises_the_quaternion(floating_pair):
    """A start a little off the loop (within simulate's check) and off the unit
    sphere: the integrator's projection hook puts both back; ``assemble`` keeps
    the joint's coordinates (the quaternion scaled to unit length)."""
    free, euler = floating_pair
    q, qd = _euler_state(euler, np.random.default_rng(8))
    x0, _, _ = _floating_state(q, qd)
    x0[2] += 2e-10
    x0[6:10] *= 1.3
    assert np.max(np.abs(free.constraint_residuals(free.project(x0)[:free.nq]))) > 1e-11
    res = free.simulate(x0, (0.0, 1e-2), t_eval=[1e-2], rtol=1e-10)
    assert res.success, res.message
    y = res.y[:, -1]
    assert np.max(np.abs(free.constraint_residuals(y[:free.nq]))) <= 1e-13
    assert np.max(np.abs(free.constraint_jacobian(y[:free.nq]) @ y[free.nq:])) <= 1e-12
    assert abs(np.linalg.norm(y[6:10]) - 1.0) <= 1e-15
    x0[2] += 1e-3
    with pytest.raises(modelgen.errors.SimulationError, match="assemble it first"):
        free.simulate(x0, (0.0, 0.1))
    q = free.assemble(x0[:free.nq], keep=["q1"])
    assert np.max(np.abs(free.constraint_residuals(q))) <= 1e-13
    assert abs(np.linalg.norm(q[6:10]) - 1.0) <= 1e-15
    assert np.array_equal(q[3:6], x0[3:6])          # the joint's coordinates are kept
    assert np.allclose(q[6:10], x0[6:10] / 1.3, rtol=0, atol=1e-15)


def test_a_quaternion_component_cannot_be_a_dependent_coordinate():
    text = FLOATING_FOUR_BAR.replace("coordinates: [q2, q3], speeds",
                                     "coordinates: [q2, J_qz], speeds")
    with pytest.raises(ModelError, match="belongs to a ball or free joint") as info:
        parse_model(text, "floating.yaml")
    err = info.value
    assert err.key == "dependent.coordinates[1]" and err.line is not None and err.fix
    assert "q1, q2, q3" in err.fix
    text = FLOATING_FOUR_BAR.replace("speeds: [q2_dot, q3_dot]", "speeds: [q2_dot, J_wz]")
    with pytest.raises(ModelError, match="belongs to a ball or free joint") as info:
        parse_model(text, "floating.yaml")
    assert info.value.key == "dependent.speeds[1]"


def test_constraints_on_a_joint_alone_cannot_be_solved_for_plain_coordinates(tmp_path):
    # the free body's point held on a line: only the joint's coordinates could move
    text = FLOATING_FOUR_BAR.replace(
        "dependent: {coordinates: [q2, q3], speeds: [q2_dot, q3_dot]}\n", "") + \
        "  rail: {type: coincide, point_a: P0, point_b: O, axes: [3]}\n"
    text = text.replace("name: floating_four_bar", "name: floating_rail")
    path = tmp_path / "floating_rail.yaml"
    path.write_text(text)
    with pytest.raises(ModelError, match="cannot be solved") as info:
        modelgen.load(path)
    assert "plain" in str(info.value) and info.value.fix


def test_jacobian_and_linearization_with_a_free_joint_are_refused(tmp_path):
    path = tmp_path / "floating_four_bar.yaml"
    path.write_text(FLOATING_FOUR_BAR)
    with pytest.raises(ModelError, match="Jacobian of a constrained model with ball or free"):
        modelgen.load(path, jacobian=True)
    with pytest.raises(ModelError, match="linearization of a model with ball or free"):
        modelgen.load(path, linearize=True)


def test_a_dead_point_beside_a_free_joint_is_an_error_naming_the_speed(floating_pair):
    # every angle zero: coupler and rocker along B0's x axis, G_d singular
    free, _ = floating_pair
    x = free.neutral_state()
    x[free.nq] = 1.0
    with pytest.raises(modelgen.errors.SimulationError, match="dead point") as info:
        free.rhs(0.0, x)
    assert "pivot of q3_dot" in str(info.value)
