"""The generated Jacobian d(xdot)/dx against central finite differences."""
from __future__ import annotations

import numpy as np
import pytest

import modelgen
from modelgen.derive.jacobian import differentiate

from conftest import MODELS


def _jacobian(cm, t, x, u):
    J = np.empty((2 * cm.n, 2 * cm.n))
    ptr = lambda a: cm.ffi.from_buffer("double[]", a)   # noqa: E731
    status = getattr(cm.lib, f"{cm.name}_jacobian")(t, ptr(x), ptr(u), ptr(cm.params()), ptr(J))
    assert status == 0
    return J


def _central_differences(cm, t, x, u):
    J = np.empty((2 * cm.n, 2 * cm.n))
    for j in range(2 * cm.n):
        h = 1e-5 * max(1.0, abs(x[j]))
        e = np.zeros_like(x)
        e[j] = h
        J[:, j] = (cm.rhs(t, x + e, u=u) - cm.rhs(t, x - e, u=u)) / (2 * h)
    return J


@pytest.mark.parametrize("name", ["double_pendulum", "cart_pole", "spherical_pendulum",
                                  "heavy_top", "spring_chain", "arm7"])
def test_generated_jacobian_matches_central_differences(build_root, name):
    cm = modelgen.load(MODELS / f"{name}.yaml", build_root / f"jac_{name}", jacobian=True)
    rng = np.random.default_rng(7)
    for _ in range(5):
        x = np.concatenate([rng.uniform(-1, 1, cm.n), rng.normal(size=cm.n)])
        u = rng.normal(size=len(cm.inputs))
        J, F = _jacobian(cm, 0.2, x, u), _central_differences(cm, 0.2, x, u)
        # central differences with h = 1e-5 are good to ~1e-8 of the scale
        assert np.abs(J - F).max() <= 1e-6 * np.abs(F).max()
        assert np.array_equal(J[:cm.n, cm.n:], np.eye(cm.n))
        assert not np.any(J[:cm.n, :cm.n])


def test_forward_mode_differentiates_through_named_intermediates():
    import sympy
    from modelgen.derive.graph import GraphBuilder
    x, y = sympy.symbols("x y")
    g = GraphBuilder()
    s = g.name(sympy.cos(x) * y)
    t = g.name(s * s + x)
    graph, rows = differentiate(g.freeze(), [t], [x, y])
    value = {x: 0.7, y: -1.3}
    exact = [sympy.diff((sympy.cos(x) * y) ** 2 + x, v).subs(value) for v in (x, y)]
    got = [float(graph.expand(e).subs(value)) for e in rows[0]]
    assert got == pytest.approx([float(e) for e in exact], rel=1e-14)


def test_jacobian_c_is_the_same_whatever_the_hash_seed(tmp_path):
    """The derivatives are named in column order, not in the order of a set of
    symbols (which follows PYTHONHASHSEED): two processes write the same C."""
    import os
    import subprocess
    import sys
    script = ("import sys; from modelgen.codegen.pipeline import generate; "
              "from modelgen.model import as_spec; "
              f"generate(as_spec({str(MODELS / 'cart_pole.yaml')!r}), sys.argv[1], "
              "linearize=True, formulation='crba')")
    texts = []
    for seed in ("1", "2"):
        out = tmp_path / seed
        env = dict(os.environ, PYTHONHASHSEED=seed, MODELGEN_CACHE_DIR=str(tmp_path / "cache"))
        subprocess.run([sys.executable, "-c", script, str(out)], check=True, env=env)
        texts.append((out / "cart_pole.c").read_text())
    assert "cart_pole_linearize" in texts[0] and texts[0] == texts[1]


# The parachute of docs/model-format.md: drag -1/2 rho Cd S |v| v on a falling body.
PARACHUTE = """name: parachute
coordinates: [y]
parameters: {m: 80.0, g: 9.81, rho: 1.2, cd: 1.5, S: 30.0}
points: {P: {coordinates: [0, y, 0]}}
bodies: {jumper: {mass: m, G: P, base: E}}
gravity: [0, -g, 0]
effects:
  air: {type: drag, body: jumper, point: P, density: rho, drag_coefficient: cd, area: S}
"""


def test_drag_is_differentiable_at_rest(build_root):
    """d|v|/dv is 0/0 at v = 0 written as sqrt; the Jacobian, the derivatives and a
    rodas run released from rest were NaN (rodas stopped at t = 0)."""
    path = build_root / "parachute.yaml"
    path.write_text(PARACHUTE)
    cm = modelgen.load(path, build_root / "parachute", jacobian=True, derivatives=True)
    k = 0.5 * 1.2 * 1.5 * 30.0 / 80.0        # q_ddot = -g + k v^2 for v < 0
    for v in (0.0, -3.0, 2.0):
        x = np.array([1.0, v])
        J = cm.jac(0.0, x)
        assert np.isfinite(J).all()
        assert J[1, 1] == pytest.approx(-2 * k * abs(v), rel=1e-14, abs=1e-300)
        assert cm.derivatives(0.0, x).dqdd_dv[0, 0] == pytest.approx(J[1, 1], rel=1e-14,
                                                                      abs=1e-300)
    res = cm.simulate([1000.0, 0.0], (0.0, 5.0), method="rodas", rtol=1e-10, atol=1e-10)
    # v(t) = -c tanh(g t / c), c = sqrt(g / k): y(t) = y0 - c^2 / g log cosh(g t / c)
    c = np.sqrt(9.81 / k)
    y = 1000.0 - c ** 2 / 9.81 * np.log(np.cosh(9.81 * 5.0 / c))
    assert res.status == 0 and res.y[0, -1] == pytest.approx(y, rel=1e-8)
    assert res.y[1, -1] == pytest.approx(-c * np.tanh(9.81 * 5.0 / c), rel=1e-8)
