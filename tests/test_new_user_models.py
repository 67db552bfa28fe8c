"""Two mechanisms a new user writes from the docs alone, against independent references.

The Furuta (rotary inverted) pendulum is ``models/furuta_pendulum.yaml`` with its
scene ``models/scenes/furuta_swing.yaml``; the planar gantry crane (a cart on a
rail, a point load on a cable of fixed length) is built here with the Python API
(``modelgen.model.Model``), as docs/python-api.md shows.  Each is checked against

* a sympy.physics.mechanics ``KanesMethod`` derivation written by hand below
  (frames, points, bodies and loads, nothing of modelgen's), at seeded random
  states, inputs and parameter sets (defaults times factors in [0.5, 1.5]):
  mass matrix, rhs and energies to 1e-12, norm-relative;
* closed forms: the Furuta pendulum's linearization about upright (Cazzolato and
  Prime, "On the dynamics of the Furuta pendulum", J. Control Sci. Eng. 2011,
  eq. 33-36, in this model's angles: the pendulum angle measured from hanging,
  so upright is al = pi) and the crane's small-oscillation frequency
  sqrt(g (M + m) / (M L)) with the cart free;
* conserved quantities of the undamped, unforced motion: the energy of both, the
  crane's horizontal momentum.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sm
import sympy.physics.mechanics as me

import modelgen
from modelgen.model import Model

ROOT = Path(__file__).resolve().parent.parent
FURUTA = ROOT / "models" / "furuta_pendulum.yaml"
FURUTA_SCENE = ROOT / "models" / "scenes" / "furuta_swing.yaml"
RTOL = 1e-12
N_STATES = 12


def _close(a, b, rtol=RTOL):
    """Norm-relative agreement; the floor keeps a near-zero reference meaningful."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.linalg.norm(a - b) <= rtol * max(np.linalg.norm(b), 1e-9)


# ---------------------------------------------------------------- the models

def crane_model() -> Model:
    """The gantry crane, built in Python: x the cart, th the cable from hanging."""
    m = Model("gantry_crane", description="cart on a rail, point load on a cable of fixed length")
    m.add_coordinates("x", "th").add_parameters(M=5.0, m=1.0, L=1.5, g=9.81, c=0.5, d=0.02)
    m.add_input("F")
    m.add_base("B", parent="E", axis=3, angle="th")
    m.add_point("C", coordinates=["x", 0, 0])
    m.add_point("G", from_="C", base="B", coordinates=[0, "-L", 0])
    m.add_body("cart", mass="M", G="C", base="E")
    m.add_body("load", mass="m", G="G", base="B")
    m.set_gravity([0, "-g", 0])
    m.add_action("drive", body="cart", point="C", base="E", force=["F", 0, 0])
    m.add_effect("rail", "joint_damping", coordinates=["x"], damping="c")
    m.add_effect("sway", "joint_damping", coordinates=["th"], damping="d")
    return m.set_units({"x": "m", "th": "rad", "M": "kg", "m": "kg", "L": "m", "F": "N"})


CRANE_SCENE = """\
scene: crane_sway
model: gantry_crane.yaml
effects: [gravity, drive, sway]
initial: {x: 0.0, th: 0.2, x_dot: 0.0, th_dot: 0.0}
time: {end: 4.0, sample: 0.01}
integrator: {method: dop853, rtol: 1.0e-11, atol: 1.0e-12}
inputs: {F: {times: [0, 1, 1.5], values: [0, 5, 0]}}
outputs:
  load: {position: G}
  energy: {energy: total}
"""


@pytest.fixture(scope="module")
def furuta(tmp_path_factory):
    return modelgen.load(FURUTA, tmp_path_factory.mktemp("furuta"), linearize=True)


@pytest.fixture(scope="module")
def crane(tmp_path_factory):
    return modelgen.load(crane_model(), tmp_path_factory.mktemp("crane"), linearize=True)


# ------------------------------------------------- sympy.physics.mechanics by hand

class Reference:
    """M(q, p), the rhs f(x, u, p) and (T, V) of a KanesMethod derivation, as numpy."""

    def __init__(self, q, u, params, inputs, kane, kinetic, potential):
        x = list(q) + list(u)
        M = kane.mass_matrix
        rhs = sm.Matrix(list(u)).col_join(M.LUsolve(kane.forcing))
        args = (x, list(inputs), list(params))
        self.mass = sm.lambdify(args, M, "numpy")
        self.rhs = sm.lambdify(args, rhs, "numpy")
        self.energy = sm.lambdify(args, [kinetic, potential], "numpy")


def furuta_reference() -> Reference:
    th, al, w1, w2 = me.dynamicsymbols("th al w1 w2")
    m1, L1, m2, L2, J2z, g, b1, b2, tau = sm.symbols("m1 L1 m2 L2 J2z g b1 b2 tau")
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Axis", [th, N.z])
    P = A.orientnew("P", "Axis", [al, A.x])
    A.set_ang_vel(N, w1 * N.z)
    P.set_ang_vel(A, w2 * A.x)
    O = me.Point("O")
    O.set_vel(N, 0)
    G1 = O.locatenew("G1", L1 / 2 * A.x)
    H = O.locatenew("H", L1 * A.x)
    G2 = H.locatenew("G2", -L2 / 2 * P.z)
    G1.v2pt_theory(O, N, A)
    H.v2pt_theory(O, N, A)
    G2.v2pt_theory(H, N, P)
    arm = me.RigidBody("arm", G1, A, m1, (me.inertia(A, 0, m1 * L1**2 / 12, m1 * L1**2 / 12), G1))
    pend = me.RigidBody("pend", G2, P, m2,
                        (me.inertia(P, m2 * L2**2 / 12, m2 * L2**2 / 12, J2z), G2))
    # the motor and the arm bearing act between ground and arm; the hinge's
    # damping between arm and pendulum, so the arm takes its reaction
    loads = [(G1, -m1 * g * N.z), (G2, -m2 * g * N.z),
             (A, (tau - b1 * w1) * N.z + b2 * w2 * A.x), (P, -b2 * w2 * A.x)]
    kane = me.KanesMethod(N, q_ind=[th, al], u_ind=[w1, w2],
                          kd_eqs=[th.diff() - w1, al.diff() - w2])
    kane.kanes_equations([arm, pend], loads)
    kinetic = arm.kinetic_energy(N) + pend.kinetic_energy(N)
    potential = g * (m1 * G1.pos_from(O).dot(N.z) + m2 * G2.pos_from(O).dot(N.z))
    return Reference([th, al], [w1, w2], [m1, L1, m2, L2, J2z, g, b1, b2], [tau],
                     kane, kinetic, potential)


def crane_reference() -> Reference:
    x, th, v, w = me.dynamicsymbols("x th v w")
    M, m, L, g, c, d, F = sm.symbols("M m L g c d F")
    N = me.ReferenceFrame("N")
    B = N.orientnew("B", "Axis", [th, N.z])
    B.set_ang_vel(N, w * N.z)
    O = me.Point("O")
    O.set_vel(N, 0)
    C = O.locatenew("C", x * N.x)
    C.set_vel(N, v * N.x)
    G = C.locatenew("G", -L * B.y)
    G.v2pt_theory(C, N, B)
    cart, load = me.Particle("cart", C, M), me.Particle("load", G, m)
    loads = [(C, (F - c * v) * N.x - M * g * N.y), (G, -m * g * N.y), (B, -d * w * N.z)]
    kane = me.KanesMethod(N, q_ind=[x, th], u_ind=[v, w], kd_eqs=[x.diff() - v, th.diff() - w])
    kane.kanes_equations([cart, load], loads)
    kinetic = cart.kinetic_energy(N) + load.kinetic_energy(N)
    potential = g * (M * C.pos_from(O).dot(N.y) + m * G.pos_from(O).dot(N.y))
    return Reference([x, th], [v, w], [M, m, L, g, c, d], [F], kane, kinetic, potential)


def _random_cases(cm, seed):
    """Seeded states in [-pi, pi], speeds and inputs in [-2, 2], parameters scaled."""
    rng = np.random.default_rng(seed)
    defaults = np.array(list(cm.parameters.values()))
    for _ in range(N_STATES):
        x = rng.uniform(-np.pi, np.pi, 2 * cm.n)
        x[cm.n:] = rng.uniform(-2.0, 2.0, cm.n)
        yield x, rng.uniform(-2.0, 2.0, len(cm.inputs)), defaults * rng.uniform(0.5, 1.5, defaults.size)


@pytest.mark.parametrize("name", ["furuta", "crane"])
def test_mass_matrix_rhs_and_energy_match_kanes_method(name, request):
    cm = request.getfixturevalue(name)
    ref = {"furuta": furuta_reference, "crane": crane_reference}[name]()
    assert tuple(cm.parameters) == {"furuta": ("m1", "L1", "m2", "L2", "J2z", "g", "b1", "b2"),
                                    "crane": ("M", "m", "L", "g", "c", "d")}[name]
    for x, u, p in _random_cases(cm, seed=7 if name == "furuta" else 8):
        q, qd = x[:cm.n], x[cm.n:]
        assert _close(cm.mass_matrix(q, p=p), ref.mass(x, u, p))
        assert _close(cm.rhs(0.0, x, u=u, p=p), np.ravel(ref.rhs(x, u, p)))
        assert _close(cm.energy(q, qd, p=p), ref.energy(x, u, p))


# ------------------------------------------------------------ closed forms

def test_furuta_linearization_about_upright_matches_cazzolato_prime(furuta):
    p = furuta.parameters
    m1, L1, m2, L2, g, b1, b2 = (p[k] for k in ("m1", "L1", "m2", "L2", "g", "b1", "b2"))
    l2 = L2 / 2
    # the arm's inertia about the motor axis with the pendulum's mass at its tip,
    # the pendulum's about its hinge, and the coupling; J2z turns with the arm upright
    J0 = m1 * L1**2 / 12 + m1 * (L1 / 2) ** 2 + m2 * L1**2 + p["J2z"]
    J2 = m2 * L2**2 / 12 + m2 * l2**2
    k = m2 * L1 * l2
    den = J0 * J2 - k**2
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2] = [0, g * m2 * l2 * k / den, -b1 * J2 / den, -b2 * k / den]
    A[3] = [0, g * m2 * l2 * J0 / den, -b1 * k / den, -b2 * J0 / den]
    B = np.array([[0], [0], [J2 / den], [k / den]])
    lin = furuta.linearize([0.0, np.pi, 0.0, 0.0], u={"tau": 0.0})
    assert lin.states == ("th", "al", "th_dot", "al_dot") and lin.inputs == ("tau",)
    assert _close(lin.A, A, 1e-13) and _close(lin.B, B, 1e-13)
    # the unstable mode without damping: +sqrt(g m2 l2 J0 / den)
    undamped = furuta.linearize([0.0, np.pi, 0.0, 0.0], p={"b1": 0.0, "b2": 0.0})
    assert np.isclose(np.max(np.linalg.eigvals(undamped.A).real),
                      np.sqrt(g * m2 * l2 * J0 / den), rtol=1e-13, atol=0)


def test_crane_sway_frequency_matches_closed_form(crane):
    p = crane.parameters
    omega = np.sqrt(p["g"] * (p["M"] + p["m"]) / (p["M"] * p["L"]))
    lin = crane.linearize([0.0, 0.0, 0.0, 0.0], p={"c": 0.0, "d": 0.0})
    eig = np.linalg.eigvals(lin.A)
    assert np.isclose(np.max(eig.imag), omega, rtol=1e-13, atol=0)
    assert np.max(np.abs(eig.real)) < 1e-12
    # the non-linear motion at a small amplitude: the period from the upward
    # zero crossings of th (its amplitude correction, th0^2/16, is ~1e-10 here)
    def crossing(t, x):
        return x[1]
    crossing.direction = 1
    res = crane.simulate([0.0, 4e-5, 0.0, 0.0], (0.0, 12.0), method="dop853", rtol=1e-12,
                         atol=1e-16, p={"c": 0.0, "d": 0.0}, events=crossing)
    periods = np.diff(res.t_events[0])
    assert res.status == 0 and len(periods) >= 3
    assert np.allclose(periods, 2 * np.pi / omega, rtol=1e-8, atol=0)


def test_undamped_unforced_motion_conserves_energy_and_momentum(furuta, crane):
    off = {"furuta": {"b1": 0.0, "b2": 0.0}, "crane": {"c": 0.0, "d": 0.0}}
    starts = {"furuta": [0.0, 3.0, 1.0, 0.0], "crane": [0.0, 1.2, 0.5, 0.0]}
    for name, cm in (("furuta", furuta), ("crane", crane)):
        res = cm.simulate(starts[name], (0.0, 10.0), t_eval=np.linspace(0.0, 10.0, 201),
                          method="dop853", rtol=1e-12, atol=1e-14, p=off[name])
        q, qd = res.y[:2], res.y[2:]
        E = np.array([np.sum(cm.energy(q[:, i], qd[:, i], p=off[name])) for i in range(q.shape[1])])
        scale = np.max(np.abs(cm.energy(q[:, 0], qd[:, 0], p=off[name])))
        assert res.status == 0 and np.max(np.abs(E - E[0])) < 1e-9 * scale, name
    # the crane's cart is free along the rail: (M + m) x_dot + m L cos(th) th_dot is constant
    p = crane.parameters
    momentum = (p["M"] + p["m"]) * res.y[2] + p["m"] * p["L"] * np.cos(res.y[1]) * res.y[3]
    assert np.max(np.abs(momentum - momentum[0])) < 1e-9 * (p["M"] + p["m"])


# ----------------------------------------------------------------- scenes

def test_furuta_scene_outputs_match_the_geometry_and_the_energy_balance_closes():
    scene = modelgen.load_scene(FURUTA_SCENE)
    res = scene.run()
    p = scene.model.parameters
    th, al = res["th"], res["al"]
    L1, L2 = p["L1"], p["L2"]
    tip = np.column_stack([L1 * np.cos(th) - L2 * np.sin(al) * np.sin(th),
                           L1 * np.sin(th) + L2 * np.sin(al) * np.cos(th),
                           -L2 * np.cos(al)])
    assert res.status == 0 and _close(res["tip"], tip, 1e-13)
    assert np.max(np.abs(res.info["energy_balance"])) < 1e-8 * np.max(np.abs(res["energy"]))
    # the bearings took energy out: the total at the end is below the start
    assert res["energy"][-1, 0] < res["energy"][0, 0]


def test_crane_scene_from_a_python_model_records_the_load_position(tmp_path):
    (tmp_path / "gantry_crane.yaml").write_text(crane_model().to_yaml())
    (tmp_path / "crane_sway.yaml").write_text(CRANE_SCENE)
    scene = modelgen.load_scene(tmp_path / "crane_sway.yaml", tmp_path / "build")
    res = scene.run()
    L = scene.model.parameters["L"]
    load = np.column_stack([res["x"] + L * np.sin(res["th"]), -L * np.cos(res["th"]),
                            np.zeros_like(res["x"])])
    assert res.status == 0 and _close(res["load"], load, 1e-13)
    # the pulse's work is the energy gained, less the sway damping's
    assert np.max(np.abs(res.info["energy_balance"])) < 1e-6 * np.max(np.abs(res["energy"]))
