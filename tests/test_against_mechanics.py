"""modelgen's compiled C against independent references.

Every model in ``models/*.yaml``, the spatial chains of
``modelgen.model.chains.spatial_chain(n)`` (n = 1..6) and a few hand-built specs
(``hand_*``, see tests/mechanics_reference.py; they add ZXZ angles, products of
inertia with gravity, forces at points other than G that depend on speeds,
time and inputs, and every kind of effect) are compared with a
sympy.physics.mechanics KanesMethod derivation at seeded random states and
parameter sets (defaults times factors in [0.5, 1.5]).

The comparison is norm-relative: ``||a - b|| <= RTOL * max(||b||, floor)``
with ``RTOL = 1e-12``.  The floor only matters when a quantity is nearly zero
at some state; it is 1e-3 of the quantity's median size over the sampled
states (or, for a quantity that is identically zero, the size of the terms it
is a sum of at that state, e.g. ||A|| (1 + |qd|^2) for h and tau).  The worst ratio ``||a - b|| / max(||b||, floor)`` per
model and quantity is printed at the end of the module.

The closed-form tests at the end do not use sympy.physics.mechanics at all.
"""
from __future__ import annotations

import dataclasses
import functools
import zlib
from pathlib import Path

import numpy as np
import pytest

import modelgen
from conftest import SUMMARY
from mechanics_reference import (MechanicsReference, actions_spec,
                                 double_pendulum_closed_form, effects_spec, free_body_spec,
                                 rigid_body_closed_form, zxz_body_rate_matrix,
                                 zxz_rotation, zyx_body_rate_matrix, zyx_rotation)

RTOL = 1e-12
N_STATES = 24
ROOT = Path(__file__).resolve().parent.parent
#: the shipped models with simple rotations only: the reference builds its frames
#: from the seed's rotations; models with ball or free joints (a quaternion state)
#: are checked against closed forms, Euler-angle twins and conserved quantities in
#: test_joints.py and against Pinocchio in test_urdf.py
MODEL_FILES = sorted(path for path in (ROOT / "models").glob("*.yaml")
                     if "\njoints:" not in path.read_text()
                     and "\nconstraints:" not in path.read_text())   # test_constraints.py
CHAIN_SIZES = (1, 2, 3, 4, 5, 6)


def _hand(make):
    spec = make()
    return dataclasses.replace(spec, name="hand_" + spec.name)


HAND_SPECS = {
    # ZXZ angles (the file model torque_free_body uses ZYX)
    "hand_free_body": lambda: _hand(free_body_spec),
    # G off the pivot, gravity and products of inertia
    "hand_heavy_body": lambda: _hand(functools.partial(free_body_spec, gravity=True,
                                                       products=True)),
    # forces at points other than G, given in rotated bases, depending on
    # speeds, time and inputs; a particle and a body with a full tensor
    "hand_actions": lambda: _hand(actions_spec),
    # every effect kind: gravity fields, spring, damper, torsion spring, joint
    # damping, friction, drag at a body-fixed point, an action as an effect
    "hand_effects": lambda: _hand(effects_spec),
}

CASES = ([path.stem for path in MODEL_FILES]
         + [f"spatial_chain_{n}" for n in CHAIN_SIZES]
         + list(HAND_SPECS))


@functools.lru_cache(maxsize=None)
def spec_of(case: str):
    if case in HAND_SPECS:
        return HAND_SPECS[case]()
    if case.startswith("spatial_chain_") and not (ROOT / "models" / f"{case}.yaml").exists():
        from modelgen.model.chains import spatial_chain
        return spatial_chain(int(case.rsplit("_", 1)[1])).spec()
    from modelgen.model.api import load_model
    return load_model(ROOT / "models" / f"{case}.yaml")


@functools.lru_cache(maxsize=None)
def reference(case: str) -> MechanicsReference:
    return MechanicsReference(spec_of(case))


@pytest.fixture(scope="session")
def mechanics_out_dir(tmp_path_factory):
    """Session-wide build directory for this module's models."""
    return tmp_path_factory.mktemp("against_mechanics")


@pytest.fixture(scope="session")
def compiled_case(mechanics_out_dir):
    """``compiled_case(case)``: the case's spec built once per session.

    (Not the conftest's ``compiled``: that one caches by model name, and these
    specs must be exactly the ones the reference was built from.)
    """
    cache = {}

    def get(case):
        if case not in cache:
            cache[case] = modelgen.load(spec_of(case), out_dir=mechanics_out_dir / case)
        return cache[case]
    return get


# -- sampling ----------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Sample:
    t: float
    q: np.ndarray
    qd: np.ndarray
    u: np.ndarray       # in spec.inputs order
    p: np.ndarray       # in spec.parameters order


def samples(case: str, count: int = N_STATES):
    """Seeded random states and parameter sets for one model (stable per case)."""
    spec = spec_of(case)
    rng = np.random.default_rng(zlib.crc32(case.encode()))
    defaults = np.array(spec.parameter_defaults, dtype=float)
    out = []
    for _ in range(count):
        out.append(Sample(
            t=float(rng.uniform(0.0, 5.0)),
            q=rng.uniform(-np.pi, np.pi, spec.n),
            qd=rng.uniform(-3.0, 3.0, spec.n),
            u=rng.uniform(-2.0, 2.0, len(spec.inputs)),
            p=defaults * rng.uniform(0.5, 1.5, defaults.size)))
    return out


@functools.lru_cache(maxsize=None)
def reference_values(case: str):
    ref = reference(case)
    return [ref.evaluate(s.t, s.q, s.qd, s.u, s.p) for s in samples(case)]


def cm_args(cm, case, s: Sample):
    """p and u of a sample in the compiled model's order (matched by name)."""
    spec = spec_of(case)
    assert list(cm.parameters) == list(spec.parameter_names)
    assert list(cm.inputs) == list(spec.inputs)
    p = dict(zip(spec.parameter_names, s.p))
    u = dict(zip(spec.inputs, s.u))
    return (np.array([p[name] for name in cm.parameters]),
            np.array([u[name] for name in cm.inputs]))


# -- comparison and the report ---------------------------------------------------

WORST: dict = {}


def compare(case, quantity, actual, expected, terms=None):
    """Assert ||a - b|| <= RTOL * max(||b||, floor) at every sample; record the worst ratio.

    The floor is 1e-3 of the median ||b||.  ``terms[i]``, the size of the terms
    sample i is a sum of, is the floor instead when b is zero at every sample.
    """
    actual = [np.asarray(a, dtype=float) for a in actual]
    expected = [np.asarray(b, dtype=float) for b in expected]
    sizes = np.array([np.linalg.norm(b) for b in expected])
    floors = np.full(len(sizes), 1e-3 * np.median(sizes))
    if floors[0] == 0.0 and terms is not None:
        floors = np.asarray(terms, dtype=float)
    ratios = []
    for a, b, size, floor in zip(actual, expected, sizes, floors):
        assert a.shape == b.shape, f"{quantity}: shape {a.shape} != {b.shape}"
        err = np.linalg.norm(a - b)
        denominator = max(size, floor)
        ratios.append(err / denominator if denominator > 0 else (0.0 if err == 0 else np.inf))
    ratios = np.array(ratios)
    worst = int(np.argmax(ratios))
    WORST[(case, quantity)] = max(WORST.get((case, quantity), 0.0), float(ratios[worst]))
    assert ratios[worst] <= RTOL, (
        f"{case}: {quantity} differs at sample {worst}: ||a-b||/max(||b||, floor) = "
        f"{ratios[worst]:.3e} > {RTOL:g}\nmodelgen  = {actual[worst]!r}\n"
        f"reference = {expected[worst]!r}")


@pytest.fixture(scope="module", autouse=True)
def report_worst_ratios(request):
    yield
    if not WORST:
        return
    cases = sorted({c for c, _ in WORST}, key=CASES.index)
    quantities = ["A", "h", "tau", "rhs_qdd", "rhs_resid", "T", "V", "T_vs_A", "R", "r_G"]
    lines = ["", "worst ||a-b||/max(||b||, floor) against the references (RTOL 1e-12)",
             f"{'model':28s}" + "".join(f"{q:>10s}" for q in quantities)]
    for c in cases:
        cells = [f"{WORST[(c, q)]:10.1e}" if (c, q) in WORST else f"{'-':>10s}"
                 for q in quantities]
        lines.append(f"{c:28s}" + "".join(cells))
    SUMMARY.extend(lines)           # printed after the run (conftest's terminal summary)


# -- modelgen against KanesMethod -------------------------------------------------

def test_models_directory_has_models():
    assert MODEL_FILES, f"no models in {ROOT / 'models'}"


@pytest.mark.parametrize("case", CASES)
def test_mass_matrix_matches_kanes_method(case, compiled_case):
    cm = compiled_case(case)
    got = []
    for s in samples(case):
        p, _ = cm_args(cm, case, s)
        got.append(cm.mass_matrix(s.q, p))
    compare(case, "A", got, [r["A"] for r in reference_values(case)])


def _force_terms(case):
    """Size of the terms h and tau are sums of: ||A|| (1 + |qd|^2)."""
    return [np.linalg.norm(r["A"]) * (1.0 + s.qd @ s.qd)
            for r, s in zip(reference_values(case), samples(case))]


@pytest.mark.parametrize("case", CASES)
def test_velocity_terms_match_kanes_method(case, compiled_case):
    cm = compiled_case(case)
    got = []
    for s in samples(case):
        p, _ = cm_args(cm, case, s)
        got.append(cm.velocity_terms(s.q, s.qd, p))
    compare(case, "h", got, [r["h"] for r in reference_values(case)], _force_terms(case))


@pytest.mark.parametrize("case", CASES)
def test_generalized_forces_match_kanes_method(case, compiled_case):
    cm = compiled_case(case)
    got = []
    for s in samples(case):
        p, u = cm_args(cm, case, s)
        got.append(cm.generalized_forces(s.t, s.q, s.qd, u, p))
    compare(case, "tau", got, [r["tau"] for r in reference_values(case)], _force_terms(case))


@pytest.mark.parametrize("case", CASES)
def test_rhs_matches_kanes_method(case, compiled_case):
    """xdot = [qd, A^-1 (tau - h)]; the qd half must be copied exactly.

    Two checks of qdd: the forward error against the reference's solution
    (sensitive to cond(A), up to ~1.5e4 for arm7), and the residual
    A_ref qdd - forcing_ref relative to ||A_ref|| ||qdd|| + ||forcing_ref||
    (the backward error, independent of the conditioning).
    """
    cm = compiled_case(case)
    n = cm.n
    got = []
    for s in samples(case):
        p, u = cm_args(cm, case, s)
        xdot = cm.rhs(s.t, np.concatenate([s.q, s.qd]), u, p)
        assert xdot.shape == (2 * n,)
        np.testing.assert_array_equal(xdot[:n], s.qd)
        got.append(xdot[n:])
    refs = reference_values(case)
    # if qdd is identically zero: the accelerations the force terms would give
    terms = [np.linalg.norm(np.linalg.inv(r["A"]), 2) * f
             for r, f in zip(refs, _force_terms(case))]
    compare(case, "rhs_qdd", got, [r["qdd"] for r in refs], terms)
    residuals = [r["A"] @ qdd - r["forcing"] for r, qdd in zip(refs, got)]
    forcing = np.array([np.linalg.norm(r["forcing"]) for r in refs])
    forcing_floor = (np.full(len(refs), 1e-3 * np.median(forcing)) if np.median(forcing) > 0
                     else np.array(_force_terms(case)))
    sizes = [np.linalg.norm(r["A"]) * np.linalg.norm(qdd) + max(f, f_floor)
             for r, qdd, f, f_floor in zip(refs, got, forcing, forcing_floor)]
    compare(case, "rhs_resid", residuals, [np.zeros(n)] * len(refs), sizes)


@pytest.mark.parametrize("case", CASES)
def test_energy_matches_reference(case, compiled_case):
    cm = compiled_case(case)
    T, V = [], []
    for s in samples(case):
        p, _ = cm_args(cm, case, s)
        e = cm.energy(s.q, s.qd, p)
        assert e.shape == (2,)
        T.append(e[0])
        V.append(e[1])
    refs = reference_values(case)
    compare(case, "T", T, [r["T"] for r in refs])
    compare(case, "V", V, [r["V"] for r in refs], [np.linalg.norm(r["A"]) for r in refs])


@pytest.mark.parametrize("case", CASES)
def test_kinetic_energy_is_half_qd_A_qd(case, compiled_case):
    cm = compiled_case(case)
    T, quadratic = [], []
    for s in samples(case):
        p, _ = cm_args(cm, case, s)
        T.append(cm.energy(s.q, s.qd, p)[0])
        quadratic.append(0.5 * s.qd @ cm.mass_matrix(s.q, p) @ s.qd)
    compare(case, "T_vs_A", T, quadratic)


@pytest.mark.parametrize("case", CASES)
def test_body_poses_match_reference(case, compiled_case):
    """R_B = N.dcm(B) (columns: B's unit vectors in E) and r_G = G.pos_from(O) in E."""
    cm = compiled_case(case)
    spec = spec_of(case)
    assert list(cm.bodies) == [b.name for b in spec.bodies]
    poses = []
    for s in samples(case):
        p, _ = cm_args(cm, case, s)
        poses.append(cm.body_poses(s.q, p))
    refs = reference_values(case)
    for pose in poses:
        np.testing.assert_array_equal(pose[:, 3, :], np.tile([0.0, 0.0, 0.0, 1.0],
                                                              (len(spec.bodies), 1)))
    compare(case, "R", [pose[:, :3, :3] for pose in poses], [r["R"] for r in refs])
    compare(case, "r_G", [pose[:, :3, 3] for pose in poses], [r["r_G"] for r in refs],
            [1.0] * len(refs))


def test_parameter_forms_agree(compiled_case):
    """p as None, a dict of overrides and a full array give the same numbers."""
    case = "hand_actions"
    cm = compiled_case(case)
    s = samples(case)[0]
    defaults = np.array(list(cm.parameters.values()))
    np.testing.assert_array_equal(cm.mass_matrix(s.q), cm.mass_matrix(s.q, defaults))
    override = {"m": 1.7, "J": 0.2}
    full = defaults.copy()
    for name, value in override.items():
        full[list(cm.parameters).index(name)] = value
    np.testing.assert_array_equal(cm.generalized_forces(s.t, s.q, s.qd, s.u, override),
                                  cm.generalized_forces(s.t, s.q, s.qd, s.u, full))
    ref = reference(case).evaluate(s.t, s.q, s.qd, s.u, override)
    assert np.linalg.norm(cm.mass_matrix(s.q, override) - ref["A"]) <= RTOL * np.linalg.norm(ref["A"])


# -- closed forms (no sympy.physics.mechanics) ----------------------------------------

def _perturbed(cm, rng):
    """Defaults times factors in [0.5, 1.5], as a dict by name."""
    return {name: value * rng.uniform(0.5, 1.5) for name, value in cm.parameters.items()}


def test_simple_pendulum_matches_closed_form(compiled_case):
    """Particle at L (sin q, -cos q): A = m L^2, tau = -m g L sin q, h = 0."""
    cm = compiled_case("simple_pendulum")
    rng = np.random.default_rng(11)
    for _ in range(20):
        q, qd = rng.uniform(-np.pi, np.pi, 1), rng.uniform(-3, 3, 1)
        p = _perturbed(cm, rng)
        m, L, g = p["m"], p["L"], p["g"]
        np.testing.assert_allclose(cm.mass_matrix(q, p), [[m * L**2]], rtol=RTOL)
        np.testing.assert_allclose(cm.generalized_forces(0.0, q, qd, None, p),
                                   [-m * g * L * np.sin(q[0])], rtol=RTOL)
        assert abs(cm.velocity_terms(q, qd, p)[0]) <= RTOL * m * L**2 * qd[0] ** 2
        np.testing.assert_allclose(cm.rhs(0.0, np.r_[q, qd], None, p),
                                   [qd[0], -g / L * np.sin(q[0])], rtol=RTOL)
        np.testing.assert_allclose(
            cm.energy(q, qd, p), [0.5 * m * L**2 * qd[0] ** 2, -m * g * L * np.cos(q[0])],
            rtol=RTOL)


@pytest.mark.parametrize("release_deg", [90.0, 179.0])
def test_simple_pendulum_period_matches_elliptic_integral(compiled_case, release_deg):
    """Released at rest from q0, q first reaches 0 after T/4, T = 4 sqrt(L/g) K(sin^2(q0/2))."""
    from scipy.integrate import solve_ivp
    from scipy.special import ellipk
    cm = compiled_case("simple_pendulum")
    L, g = cm.parameters["L"], cm.parameters["g"]
    theta0 = np.radians(release_deg)
    period = 4.0 * np.sqrt(L / g) * ellipk(np.sin(theta0 / 2) ** 2)
    crossing = lambda t, x: x[0]           # noqa: E731
    crossing.terminal, crossing.direction = True, -1
    sol = solve_ivp(cm.rhs, (0.0, period), [theta0, 0.0], method="DOP853",
                    rtol=1e-12, atol=1e-12, events=crossing)
    assert sol.status == 1
    assert abs(sol.t_events[0][0] - period / 4) <= 1e-9 * period


def test_double_pendulum_matches_closed_form(compiled_case):
    """Rods, q1 from E.x, q2 relative, gravity -y; the motor T1 acts on q1 only."""
    cm = compiled_case("double_pendulum")
    rng = np.random.default_rng(12)
    for _ in range(20):
        q, qd = rng.uniform(-np.pi, np.pi, 2), rng.uniform(-3, 3, 2)
        p = _perturbed(cm, rng)
        T1 = rng.uniform(-2, 2)
        m1, m2, l1, l2, g = (p[k] for k in ("m1", "m2", "l1", "l2", "g"))
        want = double_pendulum_closed_form(q, qd, (m1, m2, l1, l2, g))
        want["tau"] = want["tau"] + [T1, 0.0]
        force_scale = m2 * l1 * l2 * (qd @ qd) + g * (m1 + m2) * (l1 + l2)
        for got, key, scale in ((cm.mass_matrix(q, p), "A", 0.0),
                                (cm.velocity_terms(q, qd, p), "h", 1e-3 * force_scale),
                                (cm.generalized_forces(0.0, q, qd, [T1], p), "tau",
                                 1e-3 * force_scale),
                                (cm.energy(q, qd, p), "energy", 1e-3 * force_scale)):
            expected = [want["T"], want["V"]] if key == "energy" else want[key]
            err = np.linalg.norm(got - expected)
            assert err <= RTOL * max(np.linalg.norm(expected), scale), (key, got, expected)


@pytest.mark.parametrize("case, rate_matrix, rotation", [
    ("torque_free_body", zyx_body_rate_matrix, zyx_rotation),
    ("hand_free_body", zxz_body_rate_matrix, zxz_rotation),
], ids=["torque_free_body", "hand_free_body"])
def test_torque_free_body_matches_euler_equations(compiled_case, case, rate_matrix, rotation):
    """A = J'IJ and h = J'(I Jdot qd + w x Iw) with w_B = J(q) qd; tau = 0."""
    cm = compiled_case(case)
    rng = np.random.default_rng(13)
    for _ in range(20):
        q, qd = rng.uniform(-np.pi, np.pi, 3), rng.uniform(-3, 3, 3)
        p = _perturbed(cm, rng)
        inertia = [p[k] for k in ("I1", "I2", "I3")]
        A, h, w = rigid_body_closed_form(rate_matrix, q, qd, inertia)
        assert np.linalg.norm(cm.mass_matrix(q, p) - A) <= RTOL * np.linalg.norm(A)
        assert (np.linalg.norm(cm.velocity_terms(q, qd, p) - h)
                <= RTOL * max(np.linalg.norm(h), 1e-3 * np.linalg.norm(A) * (qd @ qd)))
        assert np.linalg.norm(cm.generalized_forces(0.0, q, qd, None, p)) == 0.0
        pose = cm.body_poses(q, p)[0]
        assert np.linalg.norm(pose[:3, :3] - rotation(q)) <= RTOL
        assert np.linalg.norm(pose[:3, 3]) == 0.0
        T = cm.energy(q, qd, p)[0]
        assert abs(T - 0.5 * w @ (np.array(inertia) * w)) <= RTOL * T


def test_torque_free_body_conserves_energy_and_angular_momentum(compiled_case):
    """Integrate with rtol 1e-12: T and H_E = R I w_B stay constant (tennis racket)."""
    from scipy.integrate import solve_ivp
    cm = compiled_case("torque_free_body")
    inertia = np.array([cm.parameters[k] for k in ("I1", "I2", "I3")])

    def invariants(x):
        q, qd = x[:3], x[3:]
        w = zyx_body_rate_matrix(q) @ qd
        R = cm.body_poses(q)[0, :3, :3]
        return 0.5 * w @ (inertia * w), R @ (inertia * w)

    # spin mostly about the intermediate axis (unstable): the body flips
    q0 = np.array([0.3, 0.2, -0.4])
    w0 = np.array([0.02, 1.0, 0.03])
    qd0 = np.linalg.solve(zyx_body_rate_matrix(q0), w0)
    x0 = np.r_[q0, qd0]
    T0, H0 = invariants(x0)
    sol = solve_ivp(cm.rhs, (0.0, 3.0), x0, method="DOP853", rtol=1e-12, atol=1e-12,
                    dense_output=True)
    assert sol.success
    for t in np.linspace(0.0, 3.0, 61):
        x = sol.sol(t)
        assert abs(np.cos(x[1])) > 0.05, "too close to the angles' singularity"
        T, H = invariants(x)
        assert abs(T - T0) <= 1e-9 * T0
        assert np.linalg.norm(H - H0) <= 1e-9 * np.linalg.norm(H0)


def test_heavy_top_follows_separatrix_solution(compiled_case):
    """Lagrange top with m g a = A gamma^2 (A = A0 + m a^2 about the pivot).

    From theta = pi/3, theta' = 0, phi' = 2 gamma/sqrt 3 and
    psi' = (3A - C) gamma / (C sqrt 3): cos theta(t) = 1 / (1 + sech(gamma t)).
    The separatrix is unstable (errors grow like e^(gamma t)), so stop at gamma t = 4.
    """
    from scipy.integrate import solve_ivp
    cm = compiled_case("heavy_top")
    m, a, A0, C, g = (cm.parameters[k] for k in ("m", "a", "A0", "C", "g"))
    A = A0 + m * a**2
    gamma = np.sqrt(m * g * a / A)
    x0 = [0.0, np.pi / 3, 0.0,
          2 * gamma / np.sqrt(3), 0.0, (3 * A - C) * gamma / (C * np.sqrt(3))]
    t_end = 4.0 / gamma
    sol = solve_ivp(cm.rhs, (0.0, t_end), x0, method="DOP853", rtol=1e-12, atol=1e-12,
                    dense_output=True)
    assert sol.success
    T0, V0 = cm.energy(x0[:3], x0[3:])
    for t in np.linspace(0.0, t_end, 21):
        x = sol.sol(t)
        assert abs(np.cos(x[1]) - 1.0 / (1.0 + 1.0 / np.cosh(gamma * t))) <= 1e-9
        T, V = cm.energy(x[:3], x[3:])
        assert abs(T + V - T0 - V0) <= 1e-9 * (abs(T0) + abs(V0))
