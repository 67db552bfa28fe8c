"""Constrained models (``constraints:``): the rhs against sympy.physics.mechanics
``KanesMethod`` with dependent speeds and velocity constraints, written here by
hand (nothing shared with modelgen but the parameter values), and a four-bar's
position against Freudenstein's closed form.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy
from sympy.physics.mechanics import (KanesMethod, Point, ReferenceFrame, RigidBody,
                                     dynamicsymbols, inertia)

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
    q1, q2, q3 = q = list(dynamicsymbols("q1:4"))
    u1, u2, u3 = u = list(dynamicsymbols("u1:4"))
    a, b, c, d, m1, m2, m3, g = syms = sympy.symbols("a b c d m1 m2 m3 g")
    N = ReferenceFrame("N")
    frames = [N.orientnew(f"B{k}", "Axis", (qk, N.z)) for k, qk in enumerate(q, 1)]
    for f, uk in zip(frames, u):
        f.set_ang_vel(N, uk * N.z)
    O = Point("O")
    O.set_vel(N, 0)
    D = O.locatenew("D", d * N.x)
    P1 = O.locatenew("P1", a * frames[0].x)
    G1 = O.locatenew("G1", a / 2 * frames[0].x)
    P2 = P1.locatenew("P2", b * frames[1].x)
    G2 = P1.locatenew("G2", b / 2 * frames[1].x)
    P3 = D.locatenew("P3", c * frames[2].x)
    G3 = D.locatenew("G3", c / 2 * frames[2].x)
    kd = [qk.diff(t) - uk for qk, uk in zip(q, u)]
    qd_to_u = {qk.diff(t): uk for qk, uk in zip(q, u)}
    for P in (G1, G2, G3):
        P.set_vel(N, P.pos_from(O).dt(N).subs(qd_to_u))
    bodies = []
    for name, G, f, m, L in (("crank", G1, frames[0], m1, a), ("coupler", G2, frames[1], m2, b),
                             ("rocker", G3, frames[2], m3, c)):
        bodies.append(RigidBody(name, G, f, m, (inertia(f, 0, m * L**2 / 12, m * L**2 / 12), G)))
    loads = [(G, -body.mass * g * N.y) for G, body in zip((G1, G2, G3), bodies)]
    loop = P2.pos_from(O) - P3.pos_from(O)
    f = [loop.dot(N.x), loop.dot(N.y)]
    vc = [sympy.diff(fi, t).subs(qd_to_u) for fi in f]
    kane = KanesMethod(N, q_ind=[q1], u_ind=[u1], kd_eqs=kd, q_dependent=[q2, q3],
                       configuration_constraints=f, u_dependent=[u2, u3],
                       velocity_constraints=vc)
    kane.kanes_equations(bodies, loads)
    params = dict(zip(syms, values))
    return _kane_accelerations(kane, q, u, [u1], [u2, u3], vc, params)


def rolling_disc_reference(values):
    q1, q2, q3, x, y = q = list(dynamicsymbols("q1:4 x y"))
    u = list(dynamicsymbols("u1:6"))
    m, r, g = syms = sympy.symbols("m r g")
    N = ReferenceFrame("N")
    Y = N.orientnew("Y", "Axis", (q1, N.z))
    L = Y.orientnew("L", "Axis", (q2, Y.x))
    R = L.orientnew("R", "Axis", (q3, L.y))
    qd_to_u = {qk.diff(t): uk for qk, uk in zip(q, u)}
    for fr in (Y, L, R):
        fr.set_ang_vel(N, fr.ang_vel_in(N).subs(qd_to_u))
    O = Point("O")
    O.set_vel(N, 0)
    C = O.locatenew("C", x * N.x + y * N.y)
    Dm = C.locatenew("Dm", r * L.z)
    Dm.set_vel(N, Dm.pos_from(O).dt(N).subs(qd_to_u))
    contact = Dm.vel(N) + R.ang_vel_in(N).cross(C.pos_from(Dm))
    vc = [contact.dot(N.x), contact.dot(N.y)]
    disc = RigidBody("disc", Dm, R, m, (inertia(R, m * r**2 / 4, m * r**2 / 2, m * r**2 / 4),
                                        Dm))
    kd = [qk.diff(t) - uk for qk, uk in zip(q, u)]
    kane = KanesMethod(N, q_ind=q, u_ind=u[:3], kd_eqs=kd, u_dependent=u[3:],
                       velocity_constraints=vc)
    kane.kanes_equations([disc], [(Dm, -m * g * N.z)])
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
