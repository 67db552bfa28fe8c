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
