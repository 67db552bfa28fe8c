"""Derivatives of inverse and forward dynamics (modelgen/derive/rnea_derivatives.py and
``<name>_derivatives``) against Pinocchio's ``computeRNEADerivatives`` and
``computeABADerivatives`` and against central differences of the generated rhs."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy
from sympy.printing.pycode import pycode

from modelgen.derive.dynamics import derive_equations
from modelgen.derive.joint_tree import extract_joint_tree
from modelgen.derive.kinematics import derive_kinematics
from modelgen.derive.rnea_derivatives import derive_inverse_dynamics_derivatives
from modelgen.model.chains import spatial_chain

TOL = 1e-9


def _program(graph, outputs, inputs):
    """A Python function evaluating ``outputs`` of a straight-line program."""
    lines = ["def f(" + ", ".join(str(s) for s in inputs) + "):"]
    for sym, expr in graph.closure(outputs):
        lines.append(f"    {sym} = {pycode(expr)}")
    lines.append("    return [" + ", ".join(pycode(sympy.sympify(e)) for e in outputs) + "]")
    namespace = {"math": math}
    exec("\n".join(lines), namespace)     # noqa: S102 - our own generated program
    return namespace["f"]


def _relative(a, b) -> float:
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


@pytest.mark.parametrize("n", [1, 4, 9])
def test_rnea_derivatives_program_matches_pinocchio_on_spatial_chains(n):
    pin = pytest.importorskip("pinocchio")
    from modelgen.bench.hardcase_models import chain_pinocchio
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


# -- the generated C: <name>_derivatives and <name>_inverse_dynamics_derivatives -----

import importlib.util  # noqa: E402
from pathlib import Path  # noqa: E402

import modelgen  # noqa: E402
from modelgen.model.api import load_model  # noqa: E402
from modelgen.model.urdf import import_urdf  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
URDF = REPO / "tests" / "data" / "urdf"


@pytest.fixture(scope="module")
def pin():
    return pytest.importorskip("pinocchio")


def _bench_models():
    """bench/codegen_scaling.py, whose ``tree_links`` reads a joint tree numerically
    (the model writer the Pinocchio and MuJoCo harnesses use)."""
    spec = importlib.util.spec_from_file_location("codegen_scaling",
                                                  REPO / "bench" / "codegen_scaling.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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
        pairs = [(d.dqdd_dq, -Minv @ P.T @ rq @ P), (d.dqdd_dv, -Minv @ (P.T @ rv @ P + C))]
        if len(cm.inputs):
            pairs.append((d.dqdd_du, Minv))
        if P.shape[0] == P.shape[1]:
            tau = P @ (u if len(cm.inputs) else np.zeros(n)) - P @ C @ v
            dq, dv, Mi = pin.computeABADerivatives(model, data, q_pin(q), P @ v, tau)
            assert _relative(P @ qdd, data.ddq) <= TOL
            pairs += [(d.dqdd_dq, P.T @ dq @ P),
                      (d.dqdd_dv, P.T @ (dv - _symmetric(Mi) @ P @ C @ P.T) @ P)]
        a = rng.uniform(-2, 2, n)
        i = cm.inverse_dynamics_derivatives(0.0, x, a, u)
        rq, rv, M = pin.computeRNEADerivatives(model, data, q_pin(q), P @ v, P @ a)
        pairs += [(i.dQ_dq, P.T @ rq @ P), (i.dQ_dv, P.T @ rv @ P + C),
                  (i.M, P.T @ _symmetric(M) @ P)]
        for got, want in pairs:
            err = _relative(got, want)
            assert err <= TOL, err
            worst = max(worst, err)
    return worst


@pytest.mark.parametrize("n", [2, 12])
def test_generated_derivatives_match_pinocchio_on_spatial_chains(n, pin, tmp_path):
    from modelgen.bench.hardcase_models import chain_pinocchio
    cm = modelgen.load(spatial_chain(n), tmp_path / "build", derivatives=True)
    _check_against_pinocchio(pin, cm, chain_pinocchio(n, cm.parameters), seed=n)


def test_generated_derivatives_match_pinocchio_on_arm7(pin, tmp_path):
    spec = load_model(REPO / "models" / "arm7.yaml")
    cm = modelgen.load(REPO / "models" / "arm7.yaml", tmp_path / "build", derivatives=True)
    links = _bench_models().tree_links(spec, cm.parameters)
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
