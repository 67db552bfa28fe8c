"""Symbolic linearization (<name>_linearize, cm.linearize, cm.equilibrium, the CLI).

Checked against central differences of the compiled rhs and outputs, and
against closed forms: a physical pendulum hanging and inverted, the
cart-pole's A and B, the sleeping top's stability threshold; an LQR designed
on the linearization must stabilise the non-linear cart-pole.
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import modelgen
from modelgen.errors import SimulationError

from conftest import MODELS, ROOT, SCENES, SUMMARY

#: a physical pendulum: G at d below the hinge, radius of gyration k about G,
#: torque T at the hinge; I_O = m (k^2 + d^2), l_eff = I_O / (m d)
PENDULUM = """\
name: physical_pendulum
coordinates: [q]
parameters: {m: 2.0, d: 0.45, k: 0.3, g: 9.81}
inputs: [T]
bases:
  B: {parent: E, axis: 3, angle: q}
points:
  G: {from: O, base: B, coordinates: [0, -d, 0]}
bodies:
  link: {mass: m, G: G, base: B, inertia: [m*k**2, m*k**2, m*k**2]}
gravity: [0, -g, 0]
actions:
  motor: {body: link, point: O, base: B, torque: [0, 0, T], force: [0, 0, 0]}
"""

#: a symmetric top on a fixed pivot in Bryant angles (x, y, then spin about z):
#: regular at the upright, where ZXZ Euler angles are singular
TOP = """\
name: sleeping_top
coordinates: [alpha, beta, psi]
parameters: {m: 1.0, a: 0.1, A0: 0.002, C: 0.003, g: 9.81}
bases:
  B1: {parent: E, axis: 1, angle: alpha}
  B2: {parent: B1, axis: 2, angle: beta}
  B3: {parent: B2, axis: 3, angle: psi}
points:
  G: {from: O, base: B3, coordinates: [0, 0, a]}
bodies:
  top: {mass: m, G: G, base: B3, inertia: [A0, A0, C]}
gravity: [0, 0, -g]
"""


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    root = tmp_path_factory.mktemp("linearize")
    cache = {}

    def get(key, source, **options):
        if key not in cache:
            if isinstance(source, str) and "\n" in source:
                path = root / f"{key}.yaml"
                path.write_text(source)
                source = path
            cache[key] = modelgen.load(source, root / key, linearize=True, **options)
        return cache[key]
    return get


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return modelgen.load_scene(SCENES / "cart_pole_push.yaml",
                               tmp_path_factory.mktemp("scene"), linearize=True)


def central(f, z, h=1e-6):
    """Central differences of f at z, one column per entry of z."""
    cols = []
    for j in range(len(z)):
        step = h * max(1.0, abs(z[j]))
        zp, zm = z.copy(), z.copy()
        zp[j] += step
        zm[j] -= step
        cols.append((f(zp) - f(zm)) / (2 * step))
    return np.array(cols).T


def relative(a, b) -> float:
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def test_A_and_B_match_central_differences_of_the_rhs(build):
    """crba: the residual's derivatives solved with A in C (aba: the scene's test below)."""
    formulation = "crba"
    cm = build(f"dp_{formulation}", MODELS / "double_pendulum.yaml", formulation=formulation)
    assert cm.manifest["formulation"] == formulation
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(3):
        x, u = rng.uniform(-1.5, 1.5, 4), rng.uniform(-2, 2, 1)
        lin = cm.linearize(x, u)
        assert lin.A.shape == (4, 4) and lin.B.shape == (4, 1)
        assert lin.C.shape == (0, 4) and lin.states == cm.state_names and lin.inputs == ("T1",)
        fd_A = central(lambda z, u=u: cm.rhs(0.0, z, u), x)
        fd_B = central(lambda v, x=x: cm.rhs(0.0, x, v), u)
        worst = max(worst, relative(lin.A, fd_A), relative(lin.B, fd_B))
        # the same A as the generated Jacobian the integrators use
        np.testing.assert_allclose(lin.A, cm.jac(0.0, x, u), rtol=0, atol=1e-13)
    SUMMARY.append(f"linearize {formulation}: A, B against central differences {worst:.1e}")
    assert worst < 1e-7


def test_A_B_C_D_of_a_scene_match_central_differences(scene):
    cm = scene.model
    assert cm.manifest["formulation"] == "aba"
    x, u = np.array([0.3, 0.4, -0.7, 1.1]), np.array([2.5])
    lin = cm.linearize(x, u, t=0.25)
    ny = len(cm.output_columns)
    assert lin.C.shape == (ny, 4) and lin.D.shape == (ny, 1) and lin.outputs == cm.output_columns
    fd_A = central(lambda z: cm.rhs(0.25, z, u), x)
    fd_B = central(lambda v: cm.rhs(0.25, x, v), u)
    fd_C = central(lambda z: cm.output_values(0.25, z, u), x)
    fd_D = central(lambda v: cm.output_values(0.25, x, v), u)
    worst_AB = max(relative(lin.A, fd_A), relative(lin.B, fd_B))
    worst = max(relative(lin.C, fd_C), relative(lin.D, fd_D))
    SUMMARY.append(f"linearize aba: A, B against central differences {worst_AB:.1e}; "
                   f"outputs: C, D {worst:.1e}")
    assert worst < 1e-7 and worst_AB < 1e-7
    # the push's generalized force is F along x: D has exactly that column
    push = lin.outputs.index("push.x")
    assert lin.D[push, 0] == 1.0 and np.all(lin.C[push] == 0)
    # a selection of outputs keeps their rows, by output or column name
    sub = cm.linearize(x, u, t=0.25, outputs=["energy", "tip_v.y"])
    assert sub.outputs == ("energy", "tip_v.y")
    np.testing.assert_array_equal(sub.C, lin.C[[lin.outputs.index("energy"),
                                                lin.outputs.index("tip_v.y")]])
    with pytest.raises(SimulationError, match="unknown output 'nope'"):
        cm.linearize(x, u, outputs=["nope"])


def test_physical_pendulum_hanging_and_inverted_eigenvalues(build):
    cm = build("pendulum", PENDULUM)
    m, d, k, g = (cm.parameters[n] for n in ("m", "d", "k", "g"))
    I_O = m * (k ** 2 + d ** 2)
    w = np.sqrt(g / (I_O / (m * d)))
    hanging = cm.linearize([0.0])
    inverted = cm.linearize({"q": np.pi})
    err_h = np.max(np.abs(hanging.eigenvalues() - np.array([-1j * w, 1j * w]))) / w
    err_i = np.max(np.abs(inverted.eigenvalues() - np.array([-w, w]))) / w
    SUMMARY.append(f"linearize pendulum: eigenvalues vs +-i, +-sqrt(g/l_eff): hanging "
                   f"{err_h:.1e}, inverted {err_i:.1e} (relative)")
    assert err_h < 1e-14 and err_i < 1e-14
    np.testing.assert_allclose(hanging.B, [[0.0], [1.0 / I_O]], rtol=1e-15)
    modes = hanging.modes()
    assert all(abs(md.damping) < 1e-15 and abs(md.frequency - w) < 1e-14 * w for md in modes)
    assert [md.stable for md in inverted.modes()] == [True, False]
    assert "unstable" in inverted.table()


def test_cart_pole_A_and_B_equal_their_closed_form(build):
    cm = build("cart_pole", MODELS / "cart_pole.yaml")
    M, m, L, g = (cm.parameters[n] for n in ("M", "m", "L", "g"))
    lin = cm.linearize([0.0, 0.0, 0.0, 0.0])
    # (M+m) x'' - m l theta'' = F,  -m l x'' + J theta'' = m g l theta; l = L/2, J = m L^2/3
    l, J = L / 2, m * L ** 2 / 3
    det = (M + m) * J - (m * l) ** 2
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2, 1] = m * l * m * g * l / det
    A[3, 1] = (M + m) * m * g * l / det
    B = np.array([[0.0], [0.0], [J / det], [m * l / det]])
    err = max(relative(lin.A, A), relative(lin.B, B))
    SUMMARY.append(f"linearize cart-pole: A, B against the closed form {err:.1e}")
    assert err < 1e-14


def test_sleeping_top_is_stable_exactly_above_the_closed_form_threshold(build):
    cm = build("top", TOP)
    m, a, A0, C, g = (cm.parameters[n] for n in ("m", "a", "A0", "C", "g"))
    A = A0 + m * a ** 2                        # transverse moment about the pivot
    critical = 2 * np.sqrt(A * m * g * a) / C  # C^2 w^2 = 4 A m g a

    def growth(w):
        lam = cm.linearize([0, 0, 0, 0, 0, w]).eigenvalues()
        return float(np.max(lam.real) / np.max(np.abs(lam)))

    # closed form of the transverse eigenvalues on both sides
    for w in (0.8 * critical, 1.25 * critical):
        lam = cm.linearize([0, 0, 0, 0, 0, w]).eigenvalues()
        root = np.sqrt(complex(4 * A * m * g * a - (C * w) ** 2))
        expected = [(s * 1j * C * w + r * root) / (2 * A) for s in (1, -1) for r in (1, -1)]
        nonzero = lam[np.abs(lam) > 1e-9 * np.max(np.abs(lam))]
        assert len(nonzero) == 4
        err = max(np.min(np.abs(nonzero - e)) for e in expected) / np.max(np.abs(nonzero))
        assert err < 1e-12, (w, lam, expected)
    assert growth(critical * (1 - 1e-6)) > 1e-3     # sqrt(2e-6) of the frequency
    assert growth(critical * (1 + 1e-6)) < 1e-9
    # the threshold found by bisection on the eigenvalues alone
    lo, hi = 0.5 * critical, 2.0 * critical
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if growth(mid) > 1e-7 else (lo, mid)
    found = 0.5 * (lo + hi)
    SUMMARY.append(f"linearize sleeping top: threshold from eigenvalues {found:.12g} rad/s, "
                   f"closed form {critical:.12g} (relative {abs(found / critical - 1):.1e})")
    assert abs(found / critical - 1) < 1e-9


def test_lqr_on_the_linearization_stabilises_the_nonlinear_cart_pole(build):
    from scipy.linalg import solve_continuous_are
    cm = build("cart_pole", MODELS / "cart_pole.yaml")
    lin = cm.linearize(np.zeros(4))
    Q, R = np.diag([1.0, 10.0, 1.0, 1.0]), np.array([[1.0]])
    P = solve_continuous_are(lin.A, lin.B, Q, R)
    K = np.linalg.solve(R, lin.B.T @ P)
    assert np.all(np.linalg.eigvals(lin.A - lin.B @ K).real < 0)
    from scipy.linalg import expm

    def run(degrees):
        x0 = np.array([0.0, np.radians(degrees), 0.0, 0.0])
        res = cm.simulate(x0, (0.0, 10.0), t_eval=np.linspace(0, 10, 101),
                          u=lambda t, x: -K @ x)
        assert res.success, res.message
        linear = np.array([expm((lin.A - lin.B @ K) * t) @ x0 for t in res.t]).T
        return res, x0, np.max(np.abs(res.y - linear)) / np.max(np.abs(x0))

    res, x0, gap = run(10.0)
    assert np.max(np.abs(res["theta"])) <= np.radians(10.0) + 1e-12
    assert np.linalg.norm(res.y[:, -1]) < 1e-2 * np.linalg.norm(x0)
    # it follows the linear closed loop up to the non-linearity, whose relative
    # share falls with the square of the tilt: the linearization is the tangent
    _, _, small = run(1.0)
    SUMMARY.append(f"linearize LQR cart-pole from 10 deg: |x(10 s)| = "
                   f"{np.linalg.norm(res.y[:, -1]):.1e}; gap to the linear closed loop "
                   f"{gap:.1e} (from 1 deg: {small:.1e})")
    assert gap < 0.1 and small < gap / 50
    # without the controller the pole falls
    free = cm.simulate(x0, (0.0, 2.0), t_eval=[2.0])
    assert abs(free["theta"][-1]) > 1.0


def test_equilibrium_finds_the_hanging_rest_point(build):
    cm = build("pendulum", PENDULUM)
    q = cm.equilibrium([0.8])
    assert abs(q[0]) < 1e-12
    # with a constant torque the rest point is off the vertical: m g d sin q = T
    T = 2.0
    q = cm.equilibrium([0.1], u={"T": T})
    m, d, g = (cm.parameters[n] for n in ("m", "d", "g"))
    assert abs(q[0] - np.arcsin(T / (m * g * d))) < 1e-12
    # the cart-pole's rest point keeps the cart where it was (a neutral direction)
    cp = build("cart_pole", MODELS / "cart_pole.yaml")
    q = cp.equilibrium([0.7, 2.9])
    assert abs(q[0] - 0.7) < 1e-12 and abs(q[1] - np.pi) < 1e-12
    # no rest point: a torque beyond m g d
    with pytest.raises(SimulationError, match="no equilibrium found.*residual"):
        cm.equilibrium([0.1], u={"T": 1.5 * m * g * d})


def test_linearization_writes_npz_mat_and_a_control_state_space(scene, tmp_path):
    lin = scene.model.linearize([0.0, 0.1, 0.0, 0.0])
    with np.load(lin.to_npz(tmp_path / "lin.npz")) as npz:
        np.testing.assert_array_equal(npz["A"], lin.A)
        np.testing.assert_array_equal(npz["D"], lin.D)
        assert tuple(npz["states"]) == lin.states and tuple(npz["outputs"]) == lin.outputs
        assert npz["x"][1] == 0.1
    from scipy.io import loadmat
    mat = loadmat(lin.to_mat(tmp_path / "lin.mat"))
    np.testing.assert_array_equal(mat["B"], lin.B)
    assert [str(s[0][0]) for s in mat["inputs"]] == ["F"]
    control = pytest.importorskip("control")
    sys_ = lin.to_control()
    assert isinstance(sys_, control.StateSpace)
    np.testing.assert_array_equal(sys_.C, lin.C)
    np.testing.assert_allclose(np.sort_complex(sys_.poles()), lin.eigenvalues(), atol=1e-12)


def test_a_build_without_linearize_says_how_to_get_it(compiled):
    cm = compiled("simple_pendulum")
    with pytest.raises(SimulationError, match="linearize=True"):
        cm.linearize([0.0])


def test_a_state_where_the_model_is_not_differentiable_is_an_error(build):
    cm = build("springs", MODELS / "spring_chain.yaml")   # zero-length springs at x = 0
    with pytest.raises(SimulationError, match="A is not finite .* rows of x1_dot"):
        cm.linearize(np.zeros(6))
    lin = cm.linearize([1.0, 2.0, 3.0])                   # at rest at their rest lengths
    k, m = cm.parameters["k"], cm.parameters["m"]
    # the fixed-free chain of three equal springs: omega^2 = 2 (k/m) (1 - cos((2j-1) pi/7))
    w = np.sqrt(2 * k / m * (1 - np.cos((2 * np.arange(1, 4) - 1) * np.pi / 7)))
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(lin.A[3:, :3]).real),
                               -w[::-1] ** 2, rtol=1e-13)


def test_cli_linearize_prints_eigenvalues_and_writes_npz(tmp_path):
    out = tmp_path / "lin.npz"
    proc = subprocess.run([sys.executable, "-m", "modelgen", "linearize",
                           str(MODELS / "simple_pendulum.yaml"), "--at", "q=pi",
                           "--set", "L=2", "--build-dir", str(tmp_path / "b"), "-o", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "eigenvalue" in proc.stdout and "unstable" in proc.stdout and "A (q, q_dot)" in proc.stdout
    with np.load(out) as npz:
        lam = np.sort(np.linalg.eigvals(npz["A"]).real)
    np.testing.assert_allclose(lam, [-np.sqrt(9.81 / 2), np.sqrt(9.81 / 2)], rtol=1e-12)
    bad = subprocess.run([sys.executable, "-m", "modelgen", "linearize",
                          str(MODELS / "simple_pendulum.yaml"), "--at", "z=1",
                          "--build-dir", str(tmp_path / "b")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--at z: unknown state" in bad.stderr


def test_a_scenes_linearization_has_its_own_outputs_not_its_power_records(tmp_path,
                                                                           capsys):
    """A damped scene records each damper's power for its energy balance, as outputs
    of its build; its linearization's y are the outputs the scene asks for, from
    Python (Scene.linearize) and from the command line, as its FMU's are."""
    from modelgen.cli import main
    scene = modelgen.load_scene(SCENES / "dp_damped.yaml", tmp_path / "b", linearize=True)
    assert any(name.startswith("power_") for name in scene.model.outputs)
    lin = scene.linearize()
    assert list(lin.outputs) == [c for name in ("elbow", "energy", "damping")
                                 for c in scene.model.outputs[name]]
    full = scene.model.linearize(scene.initial_state(), t=0.0)
    rows = [list(full.outputs).index(c) for c in lin.outputs]
    np.testing.assert_array_equal(lin.C, full.C[rows])
    np.testing.assert_array_equal(lin.A, full.A)
    assert main(["linearize", str(SCENES / "dp_damped.yaml"), "--build-dir",
                 str(tmp_path / "b")]) == 0
    printed = capsys.readouterr().out
    assert "C (elbow.x" in printed and "power_" not in printed


def test_generated_linearize_compiles_strictly_as_c99_and_cxx(build, scene, tmp_path):
    """Every branch of the template (aba/crba, with and without inputs and outputs)
    compiles with -Werror -pedantic as C99 and as C++ (the build itself uses -Werror)."""
    from modelgen.codegen.pipeline import generate
    from modelgen.model.scene import load_scene
    spec = load_scene(SCENES / "cart_pole_push.yaml")
    crba_outputs = generate(spec.model, tmp_path / "crba", outputs=spec.outputs,
                            formulation="crba", linearize=True)
    dirs = {"crba, nu = 1, ny > 0": crba_outputs.build.directory,
            "aba, nu = 1, ny > 0": scene.generated.build.directory,
            "crba, nu = 1, ny = 0": build("dp_crba", MODELS / "double_pendulum.yaml",
                                          formulation="crba").path.parent,
            "aba, nu = 0, ny = 0": build("top", TOP).path.parent}
    failures = []
    for label, directory in dirs.items():
        source = next(p for p in directory.glob("*.c") if p.name != "mg_integrate.c")
        assert f"{source.stem}_linearize(" in source.read_text(), label
        for cmd in (["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"],
                    ["c++", "-x", "c++", "-std=c++11", "-Wall", "-Wextra", "-Werror"]):
            r = subprocess.run(cmd + ["-c", str(source), "-I", str(directory), "-o",
                                      str(tmp_path / "out.o")], capture_output=True, text=True)
            if r.returncode:
                failures.append(f"{label}: {' '.join(cmd)}\n{r.stderr}")
    assert not failures, "\n".join(failures)
    # and the crba build with outputs agrees with the aba one
    from modelgen.sim.runtime import CompiledModel
    other = CompiledModel(crba_outputs.manifest, crba_outputs.build.module_path)
    x, u = np.array([0.2, -0.3, 0.5, 0.7]), np.array([1.5])
    # the scene records its effects' powers too (energy balance): compare the columns both have
    a, b = other.linearize(x, u), scene.model.linearize(x, u, outputs=list(other.output_columns))
    for m in "ABCD":
        np.testing.assert_allclose(getattr(a, m), getattr(b, m), rtol=1e-12, atol=1e-12)
