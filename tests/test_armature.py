"""Armature (reflected rotor inertia on a dof's diagonal of A): the model key, its
errors and round trip, and its dynamics in both formulations and the inverse
dynamics, against a closed form and against the model without it."""
from __future__ import annotations

import numpy as np
import pytest

import modelgen
from modelgen.errors import ModelError
from modelgen.model import Model, parse_model, spec_to_yaml
from modelgen.model.chains import spatial_chain

PENDULUM = """
name: geared_rod
coordinates: [q]
parameters: {m: 2.0, l: 1.5, g: 9.81, Ir: 0.3}
bases: {B: {parent: E, axis: 3, angle: q}}
points: {G: {from: O, base: B, coordinates: [l/2, 0, 0]}}
bodies: {rod: {mass: m, G: G, base: B, inertia: [0, m*l**2/12, m*l**2/12]}}
gravity: [0, -g, 0]
armature: {q: Ir}
"""

#: a free body carrying a hinged rod: armature on the hinge and on two free speeds
TUMBLER = """
name: tumbler
coordinates: [a]
parameters: {g: 9.81}
joints: {J: {type: free, parent: E, base: B, point: P}}
bases: {C: {parent: B, axis: 1, angle: a}}
points: {H: {from: P, base: B, coordinates: [0.1, 0.2, -0.1]},
         G2: {from: H, base: C, coordinates: [0, 0.3, 0.05]}}
bodies: {hub: {mass: 3, G: P, base: B, inertia: [0.1, 0.2, 0.25]},
         rod: {mass: 0.5, G: G2, base: C, inertia: [0.02, 0.003, 0.02]}}
gravity: [0, 0, -g]
armature: {a: 0.05, J_wz: 0.2, J_vx: 0.7}
"""


@pytest.mark.parametrize("formulation", ["crba", "aba"])
def test_pendulum_mass_is_m_l2_over_3_plus_armature(build_root, formulation):
    cm = modelgen.load(parse_model(PENDULUM), build_root, formulation=formulation)
    m, l, g, Ir = 2.0, 1.5, 9.81, 0.3
    assert cm.mass_matrix([0.4])[0, 0] == pytest.approx(m * l * l / 3 + Ir, rel=1e-15)
    qdd = cm.rhs(0.0, [0.4, 0.7])[1]
    assert qdd == pytest.approx(-m * g * l / 2 * np.cos(0.4) / (m * l * l / 3 + Ir), rel=1e-14)


@pytest.mark.parametrize("formulation", ["crba", "aba"])
def test_armature_adds_to_the_diagonal_only(build_root, formulation):
    spec = parse_model(TUMBLER)
    plain = Model.from_spec(spec).set_armature(None).spec()
    with_it = modelgen.load(spec, build_root, formulation=formulation)
    without = modelgen.load(plain, build_root, formulation=formulation)
    rng = np.random.default_rng(5)
    extra = np.zeros(spec.n)
    for name, value in spec.armature:
        extra[spec.dof_names.index(name)] = float(value)
    for _ in range(3):
        q = rng.uniform(-1, 1, spec.nq)
        k = spec.coordinates.index("J_qw")
        q[k:k + 4] /= np.linalg.norm(q[k:k + 4])
        v = rng.normal(size=spec.n)
        A = with_it.mass_matrix(q)
        assert np.allclose(A - without.mass_matrix(q), np.diag(extra), rtol=0, atol=1e-14)
        # q_ddot solves A qdd = tau - h with the armature in A
        x = np.concatenate([q, v])
        qdd = with_it.rhs(0.0, x)[spec.nq:]
        rhs = with_it.generalized_forces(0.0, q, v) - with_it.velocity_terms(q, v)
        assert np.allclose(A @ qdd, rhs, rtol=1e-12, atol=1e-12)
        # the inverse dynamics carry armature * qdd: A qdd + h - tau for any qdd
        probe = rng.normal(size=spec.n)
        assert np.allclose(with_it.inverse_dynamics(0.0, x, probe), A @ probe - rhs,
                           rtol=1e-12, atol=1e-12)


def test_armature_round_trips_and_zero_is_no_armature():
    spec = parse_model(TUMBLER)
    # in dof order, whatever the order in the file
    assert [(name, float(v)) for name, v in spec.armature] == [("a", 0.05), ("J_vx", 0.7),
                                                                ("J_wz", 0.2)]
    assert parse_model(spec_to_yaml(spec)) == spec
    assert Model.from_spec(spec).spec() == spec
    chain = spatial_chain(2)
    zero = Model.from_spec(chain.spec()).set_armature({"q1": 0}).spec()
    assert zero == chain.spec() and zero.armature == ()
    assert "armature" not in spec_to_yaml(zero)


@pytest.mark.parametrize("text, key, problem", [
    ("armature: {x: 1}", "armature.x", "unknown degree of freedom 'x'"),
    ("armature: {P: 1}", "armature.P", "'P' is a point, not a degree of freedom"),
    ("armature: {J_x: 1}", "armature.J_x", "'J_x' is a joint coordinate, not a degree of "
                                           "freedom"),
    ("armature: {a: -1}", "armature.a", "armature of 'a' is negative"),
    ("armature: {a: a_dot}", "armature.a", "a_dot"),
    ("armature: [1]", "armature", "expected a mapping of coordinate names to armatures"),
])
def test_armature_errors_name_the_key_and_a_fix(text, key, problem):
    source = TUMBLER.replace("armature: {a: 0.05, J_wz: 0.2, J_vx: 0.7}", text)
    with pytest.raises(ModelError) as info:
        parse_model(source, "tumbler.yaml")
    err = info.value
    assert err.key == key and problem in str(err) and err.fix
    assert err.file == "tumbler.yaml" and err.line == 12
