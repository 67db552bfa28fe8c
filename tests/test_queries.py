"""The seed's symbolic queries, checked against sympy.physics.mechanics.

The reference frames and points are built here by hand with
sympy.physics.mechanics, independently of modelgen's kinematics.
"""
from __future__ import annotations

import pytest
import sympy
from sympy.physics.mechanics import Point, ReferenceFrame, dynamicsymbols

from modelgen.errors import ModelError
from modelgen.model.api import load_model
from modelgen.derive.queries import Mechanism

from conftest import MODELS


@pytest.fixture(scope="module")
def dp():
    return Mechanism(load_model(MODELS / "double_pendulum.yaml"))


@pytest.fixture(scope="module")
def ref():
    """The double pendulum, built by hand with sympy.physics.mechanics."""
    q1, q2 = dynamicsymbols("q1 q2")
    l1, l2 = sympy.symbols("l1 l2")
    N = ReferenceFrame("N")
    B1 = N.orientnew("B1", "Axis", (q1, N.z))
    B2 = B1.orientnew("B2", "Axis", (q2, B1.z))
    O = Point("O")
    O.set_vel(N, 0)
    P1 = O.locatenew("P1", l1 * B1.x)
    G2 = P1.locatenew("G2", l2 / 2 * B2.x)
    return dict(q=(q1, q2), N=N, B1=B1, B2=B2, O=O, P1=P1, G2=G2)


def _plain(expr):
    """mechanics' q(t), q'(t), q''(t) -> modelgen's q, q_dot, q_ddot symbols."""
    t = dynamicsymbols._t
    subs = {}
    for name in ("q1", "q2"):
        f = dynamicsymbols(name)
        subs[f.diff(t, 2)] = sympy.Symbol(name + "_ddot")
        subs[f.diff(t)] = sympy.Symbol(name + "_dot")
        subs[f] = sympy.Symbol(name)
    return sympy.Matrix(expr).subs(subs)


def _same(a, b):
    return sympy.simplify(sympy.Matrix(a) - sympy.Matrix(b)) == sympy.zeros(*sympy.Matrix(a).shape)


def test_change_of_basis_matches_direction_cosines(dp, ref):
    # v_B2 = M v_B1  <=>  M = B2.dcm(B1)
    assert _same(dp.change_of_basis("B1", "B2"), _plain(ref["B2"].dcm(ref["B1"])))
    assert _same(dp.change_of_basis("E", "B2"), _plain(ref["B2"].dcm(ref["N"])))


def test_relative_angular_velocity_in_any_base(dp, ref):
    w = ref["B2"].ang_vel_in(ref["B1"])
    assert _same(dp.angular_velocity("B1", "B2", "B1"), _plain(w.to_matrix(ref["B1"])))
    w = ref["B2"].ang_vel_in(ref["N"])
    assert _same(dp.angular_velocity("E", "B2", "B1"), _plain(w.to_matrix(ref["B1"])))


def test_vector_between_points_in_any_base(dp, ref):
    r = ref["G2"].pos_from(ref["P1"])
    assert _same(dp.position("P1", "G2", "E"), _plain(r.to_matrix(ref["N"])))
    r = ref["G2"].pos_from(ref["O"])
    assert _same(dp.position("O", "G2", "B1"), _plain(r.to_matrix(ref["B1"])))


def test_point_velocity_and_acceleration(dp, ref):
    G2, N, B1, B2 = ref["G2"], ref["N"], ref["B1"], ref["B2"]
    ref["P1"].v2pt_theory(ref["O"], N, B1)
    G2.v2pt_theory(ref["P1"], N, B2)
    assert _same(dp.velocity("G2", "B2"), _plain(G2.vel(N).to_matrix(B2)))
    ref["P1"].a2pt_theory(ref["O"], N, B1)
    a = G2.a2pt_theory(ref["P1"], N, B2)
    assert _same(dp.acceleration("G2", "E"), _plain(a.to_matrix(N)))


def test_partial_velocities_are_derivatives_of_velocity(dp, ref):
    omega_c, b = dp.partial_velocities("rod2")["q2"]
    G2, N, B2 = ref["G2"], ref["N"], ref["B2"]
    G2.v2pt_theory(ref["P1"], N, B2)
    q2d = dynamicsymbols("q2", 1)
    assert _same(b, _plain(G2.vel(N).diff(q2d, N).to_matrix(N)))
    assert _same(omega_c, _plain(B2.ang_vel_in(N).diff(q2d, N).to_matrix(N)))


def test_pose_holds_rotation_and_centre_of_mass(dp, ref):
    T = dp.pose("rod2")
    assert _same(T[:3, :3], _plain(ref["N"].dcm(ref["B2"])))
    assert _same(T[:3, 3], _plain(ref["G2"].pos_from(ref["O"]).to_matrix(ref["N"])))
    assert list(T[3, :]) == [0, 0, 0, 1]


def test_energies_in_closed_form(dp):
    q1, q2, q1d, q2d, m1, m2, l1, l2, g = sympy.symbols("q1 q2 q1_dot q2_dot m1 m2 l1 l2 g")
    T = (m1 * l1**2 / 6 * q1d**2
         + m2 / 2 * (l1**2 * q1d**2 + l2**2 / 4 * (q1d + q2d)**2
                     + l1 * l2 * q1d * (q1d + q2d) * sympy.cos(q2))
         + m2 * l2**2 / 24 * (q1d + q2d)**2)
    V = g * (m1 * l1 / 2 * sympy.sin(q1) + m2 * (l1 * sympy.sin(q1) + l2 / 2 * sympy.sin(q1 + q2)))
    assert sympy.simplify(dp.kinetic_energy() - T) == 0
    assert sympy.simplify(dp.potential_energy() - V) == 0


def test_unknown_names_in_queries_raise_model_error(dp):
    with pytest.raises(ModelError, match="unknown base 'B9'"):
        dp.change_of_basis("B1", "B9")
    with pytest.raises(ModelError, match="unknown point 'Q'"):
        dp.position("O", "Q")
    with pytest.raises(ModelError, match="unknown body 'rod3'"):
        dp.pose("rod3")
