"""Inverse dynamics: ``<name>_inverse_dynamics`` gives Q = A qdd + h - tau.

Checked against the model's own A, h and tau (themselves checked against
sympy.physics.mechanics and Pinocchio elsewhere), which for a joint tree come
from another program (composite-body sums, not RNEA), and against forward
dynamics: at the qdd that the rhs returns, no extra force is needed.  Its cost
grows linearly with the size of a chain, as RNEA's does.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import modelgen
from modelgen.model.chains import spatial_chain

MODELS = Path(__file__).resolve().parent.parent / "models"
SHIPPED = ["simple_pendulum", "double_pendulum", "cart_pole", "spherical_pendulum",
           "heavy_top", "arm7", "spring_chain", "incline_block", "torque_free_body",
           "tennis_racket", "robots/solo12", "robots/ur5"]


def _states(cm, rng, count=4):
    for _ in range(count):
        x = cm.project(np.concatenate([rng.uniform(-1.5, 1.5, cm.nq),
                                       rng.uniform(-2.0, 2.0, cm.n)]))
        u = rng.uniform(-1.0, 1.0, len(cm.inputs))
        yield x, u


@pytest.mark.parametrize("formulation", ["auto", "crba"])
@pytest.mark.parametrize("name", SHIPPED)
def test_inverse_dynamics_is_a_qdd_plus_h_minus_tau_and_zero_at_the_rhs(build_root, name,
                                                                        formulation):
    cm = modelgen.load(MODELS / f"{name}.yaml", build_root / f"id_{name}_{formulation}"
                       .replace("/", "_"), formulation=formulation)
    rng = np.random.default_rng(len(name))
    for x, u in _states(cm, rng):
        q, v = x[:cm.nq], x[cm.nq:]
        tau, h = cm.generalized_forces(0.3, q, v, u), cm.velocity_terms(q, v)
        scale = max(np.max(np.abs(tau)), np.max(np.abs(h)), 1e-300)
        # at the accelerations of forward dynamics nothing else has to act
        qdd = cm.rhs(0.3, x, u)[cm.nq:]
        assert np.max(np.abs(cm.inverse_dynamics(0.3, x, qdd, u))) <= 1e-12 * scale
        # at any others, A a + h - tau
        a = rng.normal(size=cm.n)
        expected = cm.mass_matrix(q) @ a + h - tau
        got = cm.inverse_dynamics(0.3, x, a, u)
        assert np.max(np.abs(got - expected)) <= 1e-12 * max(np.max(np.abs(expected)), scale)


def test_inverse_dynamics_of_a_chain_costs_linear_operations(build_root):
    """RNEA: the operations of the routine double, or a little less, from n = 25 to 50
    (the composite-body A qdd would quadruple)."""
    ops = {}
    for n in (25, 50):
        cm = modelgen.load(spatial_chain(n).spec(), build_root / f"id_chain_{n}")
        ops[n] = cm.manifest["ops"]["inverse_dynamics"]["after_cse"]
    assert ops[50] <= 2.1 * ops[25], ops
    assert ops[50] / 50 <= 300, ops                  # per coordinate, about RNEA's


def test_inverse_dynamics_is_in_the_header_with_its_documentation(build_root):
    cm = modelgen.load(MODELS / "double_pendulum.yaml", build_root / "id_header")
    header = (Path(cm.path).parent / "double_pendulum.h").read_text()
    assert "void double_pendulum_inverse_dynamics(" in header
    assert "Q[2] = A qdd + h - tau" in header
