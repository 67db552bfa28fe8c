"""``cm.linearize`` of constrained models: the minimal linearization in the
independent coordinates and speeds against sympy.physics.mechanics'
``KanesMethod.linearize`` (the same systems written by hand in
``constrained_references.py``, nothing shared with modelgen but the parameter
values), and the symbolic Jacobian of
the constrained rhs against central differences.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sympy.physics.mechanics import dynamicsymbols

from constrained_references import four_bar_kane, rolling_disc_kane

import modelgen
from modelgen.errors import SimulationError

ROOT = Path(__file__).resolve().parent.parent
t = dynamicsymbols._t


def kane_linearization(kane, q, u, syms, cm, x):
    """KanesMethod.linearize's A at the state x (speeds and accelerations from the
    compiled rhs, which the test of the rhs checks against KanesMethod)."""
    xdot = cm.rhs(0.0, x)
    n = len(q)
    op = (dict(zip(q, x[:n])) | dict(zip(u, x[n:]))
          | {qk.diff(t): v for qk, v in zip(q, xdot[:n])}
          | {uk.diff(t): v for uk, v in zip(u, xdot[n:])}
          | dict(zip(syms, cm.params())))
    A, _, _ = kane.linearize(op_point=op, A_and_B=True, simplify=False)
    return np.array(A.evalf(30), dtype=float)


@pytest.fixture(scope="module")
def disc():
    return modelgen.load(ROOT / "models" / "rolling_disc.yaml", linearize=True)


@pytest.fixture(scope="module")
def four_bar():
    return modelgen.load(ROOT / "models" / "four_bar.yaml", linearize=True)


def test_rolling_disc_linearization_matches_kanes_method(disc):
    kane = rolling_disc_kane()[:4]         # kane, q, u, syms
    rng = np.random.default_rng(260)
    worst = 0.0
    for _ in range(4):
        q = np.concatenate([rng.uniform(-1.2, 1.2, 3), rng.normal(size=2)])
        x = np.concatenate([q, disc.consistent_speeds(q, np.concatenate(
            [rng.uniform(-3, 3, 3), [0.0, 0.0]]))])
        lin = disc.linearize(x)
        assert lin.states == ("q1", "q2", "q3", "x", "y", "q1_dot", "q2_dot", "q3_dot")
        want = kane_linearization(*kane, disc, x)
        worst = max(worst, np.max(np.abs(lin.A - want)) / np.max(np.abs(want)))
    assert worst <= 1e-12, worst


def test_four_bar_linearization_in_the_crank_matches_kanes_method(four_bar):
    """Dependent coordinates: the minimal state is (q1, q1_dot)."""
    kane = four_bar_kane()[:4]
    rng = np.random.default_rng(261)
    worst = 0.0
    for _ in range(4):
        q = four_bar.assemble([rng.uniform(-np.pi, np.pi), 1.0, 2.0], keep=["q1"])
        x = np.concatenate([q, four_bar.consistent_speeds(q, [rng.uniform(-3, 3), 0, 0])])
        lin = four_bar.linearize(x)
        assert lin.states == ("q1", "q1_dot") and lin.A.shape == (2, 2)
        want = kane_linearization(*kane, four_bar, x)
        worst = max(worst, np.max(np.abs(lin.A - want)) / np.max(np.abs(want)))
    assert worst <= 1e-12, worst


def test_constrained_jacobian_matches_central_differences(disc, four_bar):
    """``cm.jac`` (the full d xdot / d x of the rhs, whose dependent-speed columns are
    zero) against central differences, to their truncation error."""
    rng = np.random.default_rng(262)
    for cm in (disc, four_bar):
        q = cm.assemble(rng.uniform(-1, 1, cm.n)) if cm is four_bar else rng.uniform(-1, 1, 5)
        x = np.concatenate([q, cm.consistent_speeds(q, rng.uniform(-2, 2, cm.n))])
        J = cm.jac(0.0, x)
        h, fd = 1e-6, np.empty_like(J)
        for j in range(cm.nx):
            e = np.zeros(cm.nx)
            e[j] = h
            fd[:, j] = (cm.rhs(0.0, x + e) - cm.rhs(0.0, x - e)) / (2 * h)
        assert np.max(np.abs(J - fd)) <= 1e-7 * max(1.0, np.max(np.abs(J))), cm.name
        dep = cm.manifest["constraints"]["dependent_speeds"]
        assert not np.any(J[:, [cm.n + k for k in dep]])


def test_linearize_refuses_a_state_off_the_constraints(four_bar):
    with pytest.raises(SimulationError, match="off the position constraints"):
        four_bar.linearize(np.array([0.3, 1.0, 2.0, 0.0, 0.0, 0.0]))


def test_outputs_of_a_constrained_scene_are_linearized_in_the_minimal_states():
    """C = dy / d(minimal states) of the rolling disc's scene (contact position,
    energy) against central differences of the outputs along the independent
    coordinates and speeds, the dependent speeds recomputed from them."""
    scene = modelgen.load_scene(ROOT / "models" / "scenes" / "rolling_disc_coast.yaml",
                                linearize=True)
    cm = scene.model
    rng = np.random.default_rng(263)
    q = np.concatenate([rng.uniform(-1, 1, 3), rng.normal(size=2)])
    qd = cm.consistent_speeds(q, np.concatenate([rng.uniform(-3, 3, 3), [0.0, 0.0]]))
    lin = cm.linearize(np.concatenate([q, qd]))
    assert lin.C.shape == (len(cm.output_columns), 8)
    ind = cm.manifest["constraints"]["independent_speeds"]

    def outputs(z):
        speeds = np.zeros(cm.n)
        speeds[ind] = z[5:]
        return cm.output_values(0.0, np.concatenate([z[:5], cm.consistent_speeds(z[:5],
                                                                                  speeds)]))
    z0, h = np.concatenate([q, qd[ind]]), 1e-6
    fd = np.column_stack([(outputs(z0 + h * e) - outputs(z0 - h * e)) / (2 * h)
                          for e in np.eye(8)])
    assert np.max(np.abs(lin.C - fd)) <= 1e-7 * max(1.0, np.max(np.abs(fd)))


def test_equilibrium_refuses_a_constrained_model(four_bar):
    with pytest.raises(SimulationError, match="cm.assemble"):
        four_bar.equilibrium([0.3, 1.0, 2.0])


def test_inputs_of_a_constrained_model_give_b(tmp_path):
    """B of the rolling disc driven by an axle torque and a lean torque against central
    differences of the rhs in the inputs, on the rows of the minimal states."""
    text = (ROOT / "models" / "rolling_disc.yaml").read_text()
    text = text.replace("name: rolling_disc", "name: driven_disc").replace(
        "parameters:", "inputs: [T_spin, T_lean]\nparameters:").replace(
        "constraints:", "actions:\n  drive: {body: disc, point: Gd, base: L, force: [0, 0, 0], "
        "torque: [T_lean, T_spin, 0]}\nconstraints:")
    path = tmp_path / "driven_disc.yaml"
    path.write_text(text)
    cm = modelgen.load(path, linearize=True)
    rng = np.random.default_rng(264)
    q = np.concatenate([rng.uniform(-1, 1, 3), rng.normal(size=2)])
    x = np.concatenate([q, cm.consistent_speeds(q, np.concatenate([rng.uniform(-3, 3, 3),
                                                                    [0.0, 0.0]]))])
    u = np.array([0.3, -0.2])
    lin = cm.linearize(x, u)
    rows = [cm.state_names.index(s) for s in lin.states]
    h = 1e-6
    fd = np.column_stack([(cm.rhs(0.0, x, u + h * e) - cm.rhs(0.0, x, u - h * e))[rows] / (2 * h)
                          for e in np.eye(2)])
    assert lin.B.shape == (8, 2) and np.any(lin.B)
    assert np.max(np.abs(lin.B - fd)) <= 1e-7 * np.max(np.abs(fd))
