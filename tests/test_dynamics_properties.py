"""Physical properties every model must have, checked on the compiled C.

These need no reference implementation: A is symmetric positive definite,
T = 1/2 qd^T A qd, and a conservative system conserves energy along RK4 with
an error that shrinks like h^4.
"""
from __future__ import annotations

import numpy as np
import pytest

from modelgen.model.chains import spatial_chain

from conftest import MODELS

#: constrained models (their rhs is Kane's with dependent speeds) are in test_constraints.py
MODEL_NAMES = sorted(p.stem for p in MODELS.glob("*.yaml")
                     if "\nconstraints:" not in p.read_text())


def _random_state(cm, rng):
    """q (unit quaternions for ball and free joints) and the speeds."""
    return cm.project(rng.uniform(-np.pi, np.pi, cm.nq)), rng.normal(size=cm.n)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_mass_matrix_is_symmetric_positive_definite(compiled, name):
    cm = compiled(name)
    rng = np.random.default_rng(1)
    for _ in range(20):
        q, _ = _random_state(cm, rng)
        A = cm.mass_matrix(q)
        assert np.allclose(A, A.T, rtol=0, atol=1e-14 * np.abs(A).max())
        assert np.linalg.eigvalsh(A).min() > 0


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_kinetic_energy_equals_half_qd_A_qd(compiled, name):
    cm = compiled(name)
    rng = np.random.default_rng(2)
    for _ in range(20):
        q, qd = _random_state(cm, rng)
        T = cm.energy(q, qd)[0]
        assert T == pytest.approx(0.5 * qd @ cm.mass_matrix(q) @ qd, rel=1e-13)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_rhs_solves_the_equations_of_motion(compiled, name):
    cm = compiled(name)
    rng = np.random.default_rng(3)
    u = rng.normal(size=len(cm.inputs))
    for _ in range(10):
        q, qd = _random_state(cm, rng)
        xdot = cm.rhs(0.3, np.concatenate([q, qd]), u=u)
        A = cm.mass_matrix(q)
        residual = A @ xdot[cm.nq:] - (cm.generalized_forces(0.3, q, qd, u=u)
                                       - cm.velocity_terms(q, qd))
        if cm.nq == cm.n:
            assert np.array_equal(xdot[:cm.n], qd)
        for quat in cm.quaternions:       # dq/dt = N(q) qd keeps |quat| = 1: q . dq/dt = 0
            assert abs(q[list(quat)] @ xdot[list(quat)]) < 1e-15 * np.abs(qd).max()
        assert np.linalg.norm(residual) <= 1e-12 * max(1.0, np.linalg.norm(A @ xdot[cm.nq:]))


def _energy_drift(cm, x0, dt, p):
    res = cm.simulate(x0, (0.0, 1.0), method="rk4", step=dt, p=p)
    assert res.success, res.message
    total = cm.energies(res, p).sum(axis=1)
    return abs(total[-1] - total[0])


@pytest.mark.parametrize("name, dt", [("double_pendulum", 0.02), ("spherical_pendulum", 0.02),
                                      ("heavy_top", 0.02), ("torque_free_body", 0.02),
                                      ("arm7", 0.0025)])   # the wrist's small inertia is fast
def test_energy_is_conserved_to_fourth_order_without_forces(compiled, name, dt):
    """No gravity, no inputs: RK4's energy error must fall ~16x when h halves."""
    cm = compiled(name)
    p = {k: 0.0 for k in cm.parameters if k == "g"}
    rng = np.random.default_rng(4)
    x0 = np.concatenate([rng.uniform(-1, 1, cm.n), rng.uniform(-2, 2, cm.n)])
    e1 = _energy_drift(cm, x0, dt, p)
    e2 = _energy_drift(cm, x0, dt / 2, p)
    assert e2 < 1e-5 * cm.energy(x0[:cm.n], x0[cm.n:], p)[0]
    assert 2**3.5 < e1 / e2 < 2**4.7, (e1, e2)


def test_gravity_energy_is_conserved_for_chain(compiled):
    cm = compiled(spatial_chain(4).spec())
    x0 = np.concatenate([np.full(4, 0.4), np.zeros(4)])
    drift = _energy_drift(cm, x0, 1e-3, None)
    assert drift < 1e-8


TIME_VARYING_GRAVITY = """
name: {name}
coordinates: [q]
parameters: {{l: 0.8, m: 1.5, g: 9.81}}
bases: {{B: {{parent: E, axis: 3, angle: q}}}}
points: {{P: {{from: O, base: B, coordinates: [l, 0, 0]}}}}
bodies: {{bob: {{mass: m, G: P, base: B}}}}
{field}
"""


@pytest.mark.parametrize("field", [
    "gravity: [0, -g*(1 + sin(3*t)/10), 0]",
    "effects: {pull: {type: gravity, vector: [0, -g*(1 + sin(3*t)/10), 0]}}"])
def test_a_gravity_that_varies_in_time_acts_and_has_no_potential(tmp_path, field):
    """A pendulum in the field g(t) = g (1 + sin(3t)/10) along -y: m l² q̈ = -m g(t) l
    cos q.  Its potential is not counted (the field does work no potential accounts
    for): the build used to fail on the energy's t, which has no storage."""
    import modelgen
    from modelgen.model.api import parse_model
    spec = parse_model(TIME_VARYING_GRAVITY.format(name="gt", field=field))
    cm = modelgen.load(spec, tmp_path / "gt")
    l, g = 0.8, 9.81
    for t, q, qd in [(0.0, 0.3, 0.4), (0.7, -1.1, 2.0), (2.0, 2.5, -0.3)]:
        expected = -g * (1 + np.sin(3 * t) / 10) * np.cos(q) / l
        assert cm.rhs(t, [q, qd])[1] == pytest.approx(expected, rel=1e-14)
        assert cm.energy([q], [qd]) == pytest.approx([1.5 * (l * qd) ** 2 / 2, 0.0], rel=1e-14)


@pytest.mark.parametrize("name, moved", [("whipple_bicycle", ("x", "y")), ("cart_pole", ("x",)),
                                         ("slider_crank", ())])
def test_the_mass_matrix_keeps_its_digits_far_from_O(compiled, name, moved):
    """A does not depend on where a vehicle or a cart is.  Taken about O, its terms
    grew as m |r|^2 and cancelled: the bicycle's A changed by 4.3e-10 relative 1 km
    away (1.7e-8 at 10 km); about the first body's G, 5.6e-14.  A slider crank,
    whose slider stays near O, checks that the reference point changes nothing there."""
    cm = compiled(name)
    q = np.full(cm.nq, 0.1)
    A0 = cm.mass_matrix(q)
    far = q.copy()
    for c in moved:
        far[cm.coordinates.index(c)] += 1e3
    assert np.max(np.abs(cm.mass_matrix(far) - A0)) <= 1e-12 * np.max(np.abs(A0))
