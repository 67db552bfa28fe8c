"""Derivatives of inverse and forward dynamics (modelgen/derive/rnea_derivatives.py and
``<name>_derivatives``) against Pinocchio's ``computeRNEADerivatives`` and
``computeABADerivatives`` and against central differences of the generated rhs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from modelgen.derive.dynamics import derive_equations
from modelgen.derive.joint_tree import extract_joint_tree
from modelgen.derive.kinematics import derive_kinematics
from modelgen.bench.peers import tree_links
from modelgen.derive.rnea_derivatives import derive_inverse_dynamics_derivatives
from modelgen.model.chains import spatial_chain

#: relative, in the scale of :func:`_relative`; measured worst 6.5e-14 (arm7's q_ddot
#: against Pinocchio's aba), 5.1e-14 (solo12's forward derivatives), 5e-15 elsewhere
TOL = 1e-12
#: the derivatives of q_ddot in :func:`_check_against_pinocchio`: against -M^-1 of
#: Pinocchio's RNEA derivatives (numpy's inverse of its M) and its ABA derivatives, where
#: the rounding grows with the conditioning of M; measured worst 2.8e-13 (arm7), 1.1e-13
#: (kinova and g1 in test_link_kernels.py), 9e-14 (kinova here), 7e-14 (12-link chain)
QDD_DERIVATIVES_TOL = 3e-12


from test_aba import _program  # noqa: E402 (the one evaluator of a program)


def _relative(a, b) -> float:
    """max |a - b| over max(1, max |b|): relative to the reference's largest entry,
    absolute where that is below 1 (entries of a derivative may be near zero)."""
    if np.size(b) == 0:
        return 0.0 if np.size(a) == 0 else math.inf
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


@pytest.mark.parametrize("n", [1, 4, 9])
def test_rnea_derivatives_program_matches_pinocchio_on_spatial_chains(n):
    pin = pytest.importorskip("pinocchio")
    from modelgen.bench.peers import chain_pinocchio
    spec = spatial_chain(n).spec()
    eqs = derive_equations(derive_kinematics(spec))
    d = derive_inverse_dynamics_derivatives(eqs, extract_joint_tree(spec), spec)
    flat = [e for rows in (d.dq, d.dv, d.M) for row in rows for e in row]
    f = _program(d.graph, flat + list(d.Q), (eqs.t,) + eqs.q + eqs.qd + eqs.u + eqs.p + d.a)
    rng = np.random.default_rng(n)
    for _ in range(2):
        p = dict(zip((str(s) for s in eqs.p), rng.uniform(0.5, 1.5, len(eqs.p))))
        p["r"], p["g"] = 0.02 * p["r"], 9.81 * p["g"]
        model = chain_pinocchio(n, p)
        data = model.createData()
        q, v, a = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
        r = np.array(f(0.0, *q, *v, *(p[str(s)] for s in eqs.p), *a))
        dq, dv, M = (r[k * n * n:(k + 1) * n * n].reshape(n, n) for k in range(3))
        dtau_dq, dtau_dv, M_pin = pin.computeRNEADerivatives(model, data, q, v, a)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        assert _relative(r[3 * n * n:], pin.rnea(model, data, q, v, a)) <= TOL
        for got, want in ((dq, dtau_dq), (dv, dtau_dv), (M, M_pin)):
            assert _relative(got, want) <= TOL


@pytest.mark.parametrize("n", [1, 5])
def test_recursive_derivatives_program_matches_pinocchio_on_spatial_chains(n):
    # the per-dof vectors of derive/rnea_partials.py, combined as the C loop does,
    # and its articulated-body factor applied as the C does, in numpy
    pin = pytest.importorskip("pinocchio")
    from modelgen.bench.peers import chain_pinocchio
    from modelgen.derive import rnea_partials
    spec = spatial_chain(n).spec()
    eqs = derive_equations(derive_kinematics(spec))
    old = rnea_partials.ARTICULATED_SOLVE_ABOVE
    try:
        rnea_partials.ARTICULATED_SOLVE_ABOVE = 0
        d = rnea_partials.derive_rnea_partials(eqs, extract_joint_tree(spec), spec)
    finally:
        rnea_partials.ARTICULATED_SOLVE_ABOVE = old
    f = _program(d.graph, [e for v in d.vectors + d.factor for e in v],
                 (eqs.t,) + eqs.q + eqs.qd + eqs.u + eqs.p + d.a)
    rng = np.random.default_rng(n)
    p = dict(zip((str(s) for s in eqs.p), rng.uniform(0.5, 1.5, len(eqs.p))))
    p["r"], p["g"] = 0.02 * p["r"], 9.81 * p["g"]
    model = chain_pinocchio(n, p)
    q, v, a = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    r = np.array(f(0.0, *q, *v, *(p[str(s)] for s in eqs.p), *a), dtype=float)
    W, F = r[:51 * n].reshape(n, 51), r[51 * n:].reshape(n, 7)
    J, dAdq, dVdq, dAdv, dFda = (W[:, c:c + 6] for c in (0, 6, 12, 18, 24))
    dYtJ, dFdq0, dFdq, dFdv = W[:, 30:33], W[:, 33:39], W[:, 39:45], W[:, 45:51]
    dq, dv, M = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for k, l in d.same:
        dq[k, l], dv[k, l], M[k, l] = J[k] @ dFdq0[l], J[k] @ dFdv[l], J[k] @ dFda[l]
    for k, l in d.pairs:
        dq[k, l], dv[k, l] = J[k] @ dFdq[l], J[k] @ dFdv[l]
        dq[l, k] = dFda[l] @ dAdq[k] + dYtJ[l] @ dVdq[k, :3]
        dv[l, k] = dFda[l] @ dAdv[k] + dYtJ[l] @ J[k, :3]
        M[k, l] = M[l, k] = J[k] @ dFda[l]
    data = model.createData()       # the results are views into it
    rq, rv, M_pin = pin.computeRNEADerivatives(model, data, q, v, a)
    for got, want in ((dq, rq), (dv, rv), (M, np.triu(M_pin) + np.triu(M_pin, 1).T)):
        assert _relative(got, want) <= TOL
    # -M^-1 B by the factor: inwards w, P; outwards x, A
    B = rng.uniform(-1, 1, (n, 3))
    P, A, w, x = np.zeros((n, 6, 3)), np.zeros((n, 6, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    for k in reversed(d.dof_order):
        w[k] = (B[k] - J[k] @ P[k]) * F[k, 6]
        if d.dof_parent[k] >= 0:
            P[d.dof_parent[k]] += P[k] + np.outer(F[k, :6], w[k])
    for k in d.dof_order:
        Ap = A[d.dof_parent[k]] if d.dof_parent[k] >= 0 else np.zeros((6, 3))
        x[k] = w[k] - F[k, 6] * (F[k, :6] @ Ap)
        A[k] = Ap + np.outer(J[k], x[k])
    assert _relative(x, np.linalg.solve(M, B)) <= TOL


def test_entries_of_joints_on_different_branches_are_structurally_zero():
    from test_aba import branched_tree
    spec = branched_tree().spec()
    eqs = derive_equations(derive_kinematics(spec))
    d = derive_inverse_dynamics_derivatives(eqs, extract_joint_tree(spec), spec)
    k = {c: i for i, c in enumerate(spec.coordinates)}
    apart = [(k["q3"], k["q2"]), (k["q3"], k["q4"])]
    for i, j in apart + [(j, i) for i, j in apart]:
        assert d.M[i][j] == 0 and d.dv[i][j] == 0
    # the spring between the branches couples their coordinates' forces
    assert d.dq[k["q3"]][k["q4"]] != 0
    assert all(d.M[i][i] != 0 for i in range(spec.n))



def test_joint_motors_enter_the_recursive_derivatives_as_their_own_torques():
    # a motor torque about its joint's axis with its reaction on the parent link
    # has the generalized force tau_k on coordinate k alone: d Q / d u = I and
    # nothing along q or v, whatever the quaternion's or the angles' values
    from modelgen.derive.rnea_partials import derive_rnea_partials
    spec = load_model(REPO / "models" / "arm7.yaml")
    d = derive_rnea_partials(derive_equations(derive_kinematics(spec)),
                             extract_joint_tree(spec), spec)
    nu = len(spec.inputs)
    assert d.effect_entries() == tuple((3, k * nu + k, -1) for k in range(spec.n))

# -- the generated C: <name>_derivatives and <name>_inverse_dynamics_derivatives -----

from pathlib import Path  # noqa: E402

import modelgen  # noqa: E402
from modelgen.model.api import load_model  # noqa: E402
from modelgen.model.urdf import import_urdf  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
URDF = REPO / "tests" / "data" / "urdf"


@pytest.fixture(scope="module")
def pin():
    return pytest.importorskip("pinocchio")


def _pinocchio_tree(pin, links, g):
    """A Pinocchio model of ``tree_links``' revolute joints about frame axes."""
    model = pin.Model()
    ids = [0]
    for parent, axis, R, p, m, c, I in links:
        joint = {"x": pin.JointModelRX, "y": pin.JointModelRY, "z": pin.JointModelRZ}[axis]()
        jid = model.addJoint(ids[parent], joint, pin.SE3(np.array(R), np.array(p)),
                             f"j{len(ids)}")
        xx, yy, zz, xy, xz, yz = I
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        model.appendBodyToJoint(jid, pin.Inertia(m, np.array(c), inertia), pin.SE3.Identity())
        ids.append(jid)
    model.gravity.linear = np.array([0.0, 0.0, -g])
    return model


def _symmetric(M):
    return np.triu(M) + np.triu(M, 1).T


def _check_against_pinocchio(pin, cm, model, states=3, seed=0, P=None, q_pin=None,
                             damping=None):
    """cm's derivatives against computeRNEADerivatives and computeABADerivatives:
    Pinocchio's v = P v_mg (a permutation, or with mimic joints a map of the
    speeds onto more), its q = q_pin(q); ``damping`` the coefficients of the
    model's joint damping (-c qd, which Pinocchio does not have); the inputs,
    if any, are one effort per coordinate.  Without a permutation the forward
    derivatives are checked against -M^-1 of Pinocchio's RNEA derivatives at
    the rhs's qdd (Carpentier and Mansard's identity), M = P^T M_pin P."""
    n, nq = cm.n, cm.nq
    P = np.eye(n) if P is None else P
    q_pin = q_pin or (lambda q: q)
    C = np.diag(damping) if damping is not None else np.zeros((n, n))
    data = model.createData()
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(states):
        q = cm.project(rng.uniform(-1.2, 1.2, nq))
        v = rng.uniform(-1.5, 1.5, n)
        u = rng.uniform(-2, 2, len(cm.inputs))
        x = np.concatenate([q, v])
        qdd = cm.rhs(0.0, x, u)[nq:]
        d = cm.derivatives(0.0, x, u)
        rq, rv, M = pin.computeRNEADerivatives(model, data, q_pin(q), P @ v, P @ qdd)
        Mr = P.T @ _symmetric(M) @ P
        Minv = np.linalg.inv(Mr)
        # the derivatives of q_ddot (to QDD_DERIVATIVES_TOL), then of the inverse dynamics
        pairs = [(d.dqdd_dq, -Minv @ P.T @ rq @ P), (d.dqdd_dv, -Minv @ (P.T @ rv @ P + C))]
        if len(cm.inputs):
            pairs.append((d.dqdd_du, Minv))
        if P.shape[0] == P.shape[1]:
            tau = P @ (u if len(cm.inputs) else np.zeros(n)) - P @ C @ v
            dq, dv, Mi = pin.computeABADerivatives(model, data, q_pin(q), P @ v, tau)
            assert _relative(P @ qdd, data.ddq) <= TOL
            pairs += [(d.dqdd_dq, P.T @ dq @ P),
                      (d.dqdd_dv, P.T @ (dv - _symmetric(Mi) @ P @ C @ P.T) @ P)]
        forward = len(pairs)
        a = rng.uniform(-2, 2, n)
        i = cm.inverse_dynamics_derivatives(0.0, x, a, u)
        rq, rv, M = pin.computeRNEADerivatives(model, data, q_pin(q), P @ v, P @ a)
        pairs += [(i.dQ_dq, P.T @ rq @ P), (i.dQ_dv, P.T @ rv @ P + C),
                  (i.M, P.T @ _symmetric(M) @ P)]
        for k, (got, want) in enumerate(pairs):
            err = _relative(got, want)
            assert err <= (QDD_DERIVATIVES_TOL if k < forward else TOL), (k, err)
            worst = max(worst, err)
    return worst


@pytest.mark.parametrize("n", [2, 12])
def test_generated_derivatives_match_pinocchio_on_spatial_chains(n, pin, tmp_path, solve):
    from modelgen.bench.peers import chain_pinocchio
    cm = modelgen.load(spatial_chain(n), tmp_path / "build", derivatives=True)
    assert _uses(cm, solve)
    _check_against_pinocchio(pin, cm, chain_pinocchio(n, cm.parameters), seed=n)


def test_generated_derivatives_match_pinocchio_on_arm7(pin, tmp_path):
    spec = load_model(REPO / "models" / "arm7.yaml")
    cm = modelgen.load(REPO / "models" / "arm7.yaml", tmp_path / "build", derivatives=True)
    links = tree_links(spec, cm.parameters)
    assert links is not None
    _check_against_pinocchio(pin, cm, _pinocchio_tree(pin, links, cm.parameters["g"]))


@pytest.mark.parametrize("robot", ["double_pendulum", "ur5_robot", "panda", "kinova"])
def test_generated_derivatives_match_pinocchio_on_urdf_robots(robot, pin, tmp_path):
    from test_urdf import _pinocchio_maps
    imp = import_urdf(URDF / f"{robot}.urdf")
    cm = modelgen.load(imp.model, tmp_path / "build", derivatives=True)
    model = pin.buildModelFromUrdf(str(URDF / f"{robot}.urdf"))
    q_of, jmap = _pinocchio_maps(model, imp)
    damping = np.array([j.damping for j in imp.joints if j.coordinate is not None])
    _check_against_pinocchio(pin, cm, model, P=jmap, q_pin=q_of, damping=damping)


# -- floating base: a free joint in the tangent space ---------------------------------

def _quaternion_matrix(w, x, y, z):
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _quaternion_product(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _free_joints(cm):
    """Per free or ball joint: (its quaternion's 4 state indices, its position's 3 or
    None, the speed indices of its linear velocity or None, of its angular velocity)."""
    out = []
    for quat in cm.quaternions:
        name = cm.coordinates[quat[0]][:-len("_qw")]
        position = [cm.coordinates.index(f"{name}_{s}") for s in "xyz"] \
            if f"{name}_x" in cm.coordinates else None
        linear = [cm.speeds.index(f"{name}_v{s}") for s in "xyz"] if position else None
        angular = [cm.speeds.index(f"{name}_w{s}") for s in "xyz"]
        out.append((list(quat), position, linear, angular))
    return out


def _step(cm, q, j, h):
    """q moved by h along speed j (the exponential map for a joint's quaternion, R h e
    for its position; + h for a simple coordinate)."""
    q = np.array(q, dtype=float)
    for quat, position, linear, angular in _free_joints(cm):
        if j in angular:
            axis = np.zeros(3)
            axis[angular.index(j)] = 1.0
            turn = np.concatenate([[math.cos(h / 2)], math.sin(h / 2) * axis])
            q[quat] = _quaternion_product(q[quat], turn)
            return q
        if linear and j in linear:
            q[position] += _quaternion_matrix(*q[quat])[:, linear.index(j)] * h
            return q
    q[cm.coordinates.index(cm.dof_names[j])] += h
    return q


def _central_differences(cm, x, u, h=1e-6):
    """(dqdd/dq, dqdd/dv, dqdd/du) of the compiled rhs by central differences."""
    nq, n = cm.nq, cm.n
    q, v = x[:nq], x[nq:]

    def qdd(q_, v_, u_):
        return cm.rhs(0.0, np.concatenate([q_, v_]), u_)[nq:]
    dq = np.column_stack([(qdd(_step(cm, q, j, h), v, u) - qdd(_step(cm, q, j, -h), v, u))
                          / (2 * h) for j in range(n)])
    dv = np.column_stack([(qdd(q, v + h * e, u) - qdd(q, v - h * e, u)) / (2 * h)
                          for e in np.eye(n)])
    du = np.column_stack([(qdd(q, v, u + h * e) - qdd(q, v, u - h * e)) / (2 * h)
                          for e in np.eye(len(u))]) if len(u) else np.zeros((n, 0))
    return dq, dv, du


def _check_against_differences(cm, states=2, seed=0, tol=1e-6):
    rng = np.random.default_rng(seed)
    for _ in range(states):
        x = np.concatenate([cm.project(rng.uniform(-1, 1, cm.nq)), rng.uniform(-1, 1, cm.n)])
        u = rng.uniform(-1, 1, len(cm.inputs))
        d = cm.derivatives(0.0, x, u)
        for got, want in zip(d, _central_differences(cm, x, u), strict=True):
            assert got.shape == want.shape
            assert _relative(got, want) <= tol, _relative(got, want)


@pytest.fixture(params=["ldlt", "articulated"])
def solve(request, monkeypatch):
    """Both ways of applying -M^-1 of the recursive derivatives: the sparse LDL^T
    (small models) and the articulated-body factor (large ones, here forced); the
    recursive derivatives forced too (a small tree may get forward mode)."""
    from modelgen.codegen import tree_derivatives
    from modelgen.derive import rnea_partials
    monkeypatch.setattr(tree_derivatives, "FORWARD_DERIVATIVES_MAX", 0)
    if request.param == "articulated":
        monkeypatch.setattr(rnea_partials, "ARTICULATED_SOLVE_ABOVE", 0)
    return request.param


def _uses(cm, solve) -> bool:
    """True if cm's C has the recursive derivatives and applies -M^-1 the way
    ``solve`` says."""
    source = (Path(cm.path).parent / f"{cm.name}.c").read_text()
    return cm.manifest["derivative_method"] == "recursive" and \
        (f"{cm.name}_aba_columns" in source) == (solve == "articulated")


def test_floating_solo12_matches_pinocchio_free_flyer_in_the_tangent_space(pin, tmp_path, solve):
    path = URDF / "solo12.urdf"
    imp = import_urdf(path, floating_base=True)
    cm = modelgen.load(imp.model, tmp_path / "build", derivatives=True)
    assert _uses(cm, solve)
    model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    ((quat, position, linear, angular),) = _free_joints(cm)
    P = np.zeros((model.nv, cm.n))        # Pinocchio's v = P v_mg
    order = []                            # Pinocchio's q from modelgen's
    for jid in range(1, model.njoints):
        jm, name = model.joints[jid], model.names[jid]
        if name == "root_joint":
            for k, s in enumerate(linear + angular):
                P[jm.idx_v + k, s] = 1.0
            order += position + quat[1:] + quat[:1]      # (x, y, z, qx, qy, qz, qw)
        else:
            coordinate = next(j.coordinate for j in imp.joints if j.name == name)
            P[jm.idx_v, cm.speeds.index(coordinate + "_dot")] = 1.0
            order.append(cm.coordinates.index(coordinate))
    damping = np.array([next((j.damping for j in imp.joints
                              if j.coordinate and j.coordinate + "_dot" == s), 0.0)
                        for s in cm.speeds])
    assert not damping.any() or len(cm.inputs) == 12
    # the inputs are the 12 joint efforts: Pinocchio's tau has them on the joints
    # and zeros on the free flyer; the forward check goes through M^-1 of the
    # reduced map (P is square here, so computeABADerivatives is compared too)
    B = np.zeros((cm.n, len(cm.inputs)))
    for k, name in enumerate(cm.inputs):
        coordinate = next(j.coordinate for j in imp.joints if j.input == name)
        B[cm.speeds.index(coordinate + "_dot"), k] = 1.0
    rng = np.random.default_rng(5)
    data = model.createData()
    C = np.diag(damping)
    for _ in range(3):
        q = cm.project(rng.uniform(-1, 1, cm.nq))
        v, u = rng.uniform(-1.5, 1.5, cm.n), rng.uniform(-2, 2, len(cm.inputs))
        x, qp = np.concatenate([q, v]), q[order]
        d = cm.derivatives(0.0, x, u)
        tau = P @ (B @ u - C @ v)
        dq, dv, Minv = pin.computeABADerivatives(model, data, qp, P @ v, tau)
        Minv = P.T @ _symmetric(Minv) @ P
        assert _relative(cm.rhs(0.0, x, u)[cm.nq:], P.T @ data.ddq) <= TOL
        assert _relative(d.dqdd_dq, P.T @ dq @ P) <= TOL
        assert _relative(d.dqdd_dv, P.T @ dv @ P - Minv @ C) <= TOL
        assert _relative(d.dqdd_du, Minv @ B) <= TOL
        a = rng.uniform(-2, 2, cm.n)
        i = cm.inverse_dynamics_derivatives(0.0, x, a, u)
        rq, rv, M = pin.computeRNEADerivatives(model, data, qp, P @ v, P @ a)
        assert _relative(i.dQ_dq, P.T @ rq @ P) <= TOL
        assert _relative(i.dQ_dv, P.T @ rv @ P + C) <= TOL
        assert _relative(i.M, P.T @ _symmetric(M) @ P) <= TOL
    _check_against_differences(cm, states=1)


# -- central differences of the generated rhs: effects, inputs, any formulation -------

@pytest.mark.parametrize("method", ["forward", "recursive"])
def test_derivatives_with_armature_and_a_free_joint_match_central_differences(
        method, tmp_path, monkeypatch):
    # a small tree is derived both ways and the one with fewer operations kept:
    # each forced here, on a free body with a hinged rod and armature on both
    from test_armature import TUMBLER
    from modelgen.codegen import tree_derivatives
    from modelgen.derive.rnea_partials import RneaPartials
    from modelgen.model import parse_model
    if method == "recursive":
        monkeypatch.setattr(tree_derivatives, "FORWARD_DERIVATIVES_MAX", 0)
    else:
        monkeypatch.setattr(RneaPartials, "operations", lambda self: 10 ** 9)
    cm = modelgen.load(parse_model(TUMBLER), tmp_path / "build", derivatives=True)
    assert cm.manifest["derivative_method"] == method
    _check_against_differences(cm, seed=4)
    q = cm.project(np.random.default_rng(4).uniform(-1, 1, cm.nq))
    i = cm.inverse_dynamics_derivatives(0.0, np.concatenate([q, np.ones(cm.n)]),
                                        np.zeros(cm.n))
    assert _relative(i.M, cm.mass_matrix(q)) <= TOL     # the armature on M's diagonal


@pytest.mark.parametrize("solve", ["articulated"], indirect=True)
def test_derivatives_with_armature_through_the_articulated_solve_match_differences(
        tmp_path, solve):
    # the armature enters the articulated-body factor's D_k (the LDL^T case is the
    # test above, whose small tree takes the sparse solve)
    from test_armature import TUMBLER
    from modelgen.model import parse_model
    spec = parse_model(TUMBLER)
    assert len(spec.armature) == 3
    cm = modelgen.load(spec, tmp_path / "build", derivatives=True)
    assert _uses(cm, solve)
    _check_against_differences(cm, seed=4)


def test_derivatives_of_a_branched_tree_with_effects_match_central_differences(tmp_path,
                                                                              solve):
    from test_aba import branched_tree
    cm = modelgen.load(branched_tree(), tmp_path / "build", derivatives=True)
    assert cm.manifest["formulation"] == "aba" and cm.inputs == ("F",) and _uses(cm, solve)
    _check_against_differences(cm, seed=1)


def _has_avx512f() -> bool:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            return any(line.startswith("flags") and "avx512f" in line.split() for line in f)
    except OSError:
        return False


@pytest.mark.skipif(not _has_avx512f(), reason="the wide solve runs only with AVX-512")
def test_articulated_solve_gives_the_same_bits_at_both_vector_widths(tmp_path, monkeypatch):
    # the wide solve (8 columns a vector, taken at run time on this CPU) against the
    # library built without it (4 columns): the same operations on every column
    from modelgen.derive import rnea_partials
    monkeypatch.setattr(rnea_partials, "ARTICULATED_SOLVE_ABOVE", 0)
    spec = spatial_chain(11).spec()
    wide = modelgen.load(spec, tmp_path / "wide", derivatives=True)
    monkeypatch.setenv("MODELGEN_CFLAGS", "-DMG_NO_WIDE")
    narrow = modelgen.load(spec, tmp_path / "narrow", derivatives=True)
    source = (Path(wide.path).parent / f"{wide.name}.c").read_text()
    assert f"{wide.name}_aba_solve_wide" in source
    rng = np.random.default_rng(7)
    for _ in range(3):
        x = np.concatenate([wide.project(rng.uniform(-3, 3, wide.nq)), rng.uniform(-2, 2, wide.n)])
        for a, b in zip(wide.derivatives(0.0, x), narrow.derivatives(0.0, x), strict=True):
            assert a.tobytes() == b.tobytes()
    _check_against_differences(wide, seed=8)


@pytest.mark.parametrize("model, formulation", [("cart_pole", "crba"), ("heavy_top", "auto"),
                                                ("spring_chain", "auto")])
def test_derivatives_match_central_differences_on_shipped_models(model, formulation, tmp_path):
    cm = modelgen.load(REPO / "models" / f"{model}.yaml", tmp_path / "build",
                       derivatives=True, formulation=formulation)
    _check_against_differences(cm, seed=2)


@pytest.mark.parametrize("model", ["simple_pendulum", "double_pendulum"])
def test_derivatives_and_a_forward_mode_jacobian_build_together(model, tmp_path):
    # both options: the Jacobian (forward mode on these small models) is derived
    # over the program that already holds the derivatives'
    cm = modelgen.load(REPO / "models" / f"{model}.yaml", tmp_path / "build",
                       derivatives=True, jacobian=True)
    assert cm.manifest["jacobian_method"] == "forward"
    _check_against_differences(cm, seed=6)
    x = np.concatenate([cm.project(np.full(cm.nq, 0.4)), np.full(cm.n, -0.3)])
    d, J = cm.derivatives(0.0, x), cm.jac(0.0, x)
    assert _relative(np.hstack([d.dqdd_dq, d.dqdd_dv]), J[cm.nq:]) <= 1e-12


def test_a_constrained_model_is_refused_the_derivatives_with_the_fix(tmp_path):
    from modelgen.errors import ModelError
    with pytest.raises(ModelError, match="constrained model.*jacobian=True"):
        modelgen.load(REPO / "models" / "four_bar.yaml", tmp_path / "build", derivatives=True)


def test_without_the_option_there_are_no_derivatives(tmp_path):
    from modelgen.errors import BuildError
    cm = modelgen.load(spatial_chain(2), tmp_path / "build")
    assert not any("derivatives" in f for f in cm.manifest["functions"])
    with pytest.raises(BuildError, match="derivatives=True"):
        cm.derivatives(0.0, np.zeros(4))


@pytest.mark.parametrize("model", ["heavy_body_ball", "free_base_two_links"])
def test_ball_and_free_joint_derivatives_match_differences_along_the_exponential_map(
        model, tmp_path):
    cm = modelgen.load(REPO / "tests" / "data" / "joints" / f"{model}.yaml", tmp_path / "build",
                       derivatives=True)
    assert cm.quaternions
    _check_against_differences(cm, seed=3)


def test_the_looped_solve_of_large_models_gives_the_same_derivatives(tmp_path, monkeypatch):
    # models past the unrolling limit solve with a loop over the non-zeros of L:
    # the limit lowered, a small model takes that path
    from test_aba import branched_tree
    from modelgen.codegen import ldlt
    unrolled = modelgen.load(branched_tree(), tmp_path / "unrolled", derivatives=True)
    monkeypatch.setattr(ldlt, "UNROLL_SOLVE", 0)
    monkeypatch.setattr(ldlt, "SPARSE_UNROLL_SIZE", 1)
    looped = modelgen.load(branched_tree(), tmp_path / "looped", derivatives=True, force=True)
    source = (Path(looped.path).parent / "branched.c").read_text()
    assert "branched_derivatives_columns" in source
    assert "branched_derivatives_columns" not in \
        (Path(unrolled.path).parent / "branched.c").read_text()
    rng = np.random.default_rng(9)
    x = np.concatenate([rng.uniform(-1, 1, 5), rng.uniform(-1, 1, 5)])
    for got, want in zip(looped.derivatives(0.0, x, [0.7]), unrolled.derivatives(0.0, x, [0.7]),
                         strict=True):
        assert _relative(got, want) <= 1e-12
