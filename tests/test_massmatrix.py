"""The numpy-free check of a mass matrix singular by construction (modelgen.sim.massmatrix).

Its pieces are compared with numpy: the scattered configurations bit for bit
with the numpy formula they replace, the pivot test with
an LDL^T in numpy written here (``_numpy_ratios``) on random
positive definite, singular and indefinite matrices; its ctypes evaluation of A
with the loaded model's; and the command line, which checks through it,
imports no numpy and refuses what ``modelgen.load`` refuses, in the same words.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import modelgen
from modelgen.errors import DerivationError
from modelgen.sim import massmatrix
from modelgen.sim.library import mass_matrix_function

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
MODELS = REPO / "models"
SETTINGS = settings(max_examples=200, deadline=None, derandomize=True)


def _scattered_numpy(n: int, k: int) -> np.ndarray:
    """The numpy formula of the scattered configurations (modelgen.sim.runtime's before)."""
    i = np.arange(1, n + 1)
    steps = np.modf(i * 0.6180339887498949 + (k + 1) * 0.41421356237309515 * np.sqrt(i))[0]
    return np.pi * (2.0 * steps - 1.0)


@pytest.mark.parametrize("n", [1, 2, 7, 60, 250])
def test_scattered_is_bitwise_the_numpy_formula(n):
    for k in range(6):
        assert massmatrix.scattered(n, k) == _scattered_numpy(n, k).tolist()


def _matrix(seed: int, n: int, rank: int, negative: int) -> np.ndarray:
    """B diag(s) B^T with B n x rank (columns scaled by up to 10^+-1): positive definite
    at full rank, singular below it; ``negative`` of the signs s are -1 (indefinite)."""
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((n, rank)) * 10.0 ** rng.uniform(-1, 1, rank)
    s = np.ones(rank)
    s[:negative] = -1.0
    return (B * s) @ B.T


def _numpy_ratios(A: np.ndarray) -> np.ndarray:
    """The reference: ``d_j / A_jj`` of A's LDL^T in numpy, row-vector products,
    up to and including the first pivot at or below the tolerance (NaN after it)."""
    n = A.shape[0]
    L, d, ratios = np.eye(n), np.zeros(n), np.full(n, np.nan)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        for j in range(n):
            d[j] = A[j, j] - (L[j, :j] * L[j, :j]) @ d[:j]
            ratios[j] = d[j] / A[j, j] if A[j, j] > 0 else -np.inf
            if not ratios[j] > massmatrix.PIVOT_TOL:
                break
            L[j + 1:, j] = (A[j + 1:, j] - L[j + 1:, :j] @ (L[j, :j] * d[:j])) / d[j]
    return ratios


def _first_failing(ratios):
    return next((j for j, r in enumerate(ratios) if not r > massmatrix.PIVOT_TOL), None)


def _clear_cut(ratios) -> bool:
    """Whether numpy's ratios pass or fail the test by a margin that round-off (the
    order of summation) cannot cross: 1e3 either side of the tolerance."""
    for r in ratios:
        if not r > 1e3 * massmatrix.PIVOT_TOL:
            return not r > 1e-3 * massmatrix.PIVOT_TOL
    return True


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 12), data=st.data())
def test_the_pivot_test_is_that_of_numpy(seed, n, data):
    rank = data.draw(st.integers(1, n), label="rank")
    negative = data.draw(st.integers(0, rank), label="negative")
    A = _matrix(seed, n, rank, negative)
    theirs = _numpy_ratios(A)
    hypothesis.assume(_clear_cut(theirs))
    assert massmatrix.failing_pivot(A.tolist()) == _first_failing(theirs)
    assert np.allclose(massmatrix.pivot_ratios(A.tolist()), theirs, rtol=1e-6, atol=1e-9,
                       equal_nan=True)


def test_the_pivot_test_names_singular_and_indefinite_pivots():
    spd = _matrix(1, 5, 5, 0)
    assert massmatrix.failing_pivot(spd.tolist()) is None
    singular = spd.copy()
    singular[3, :], singular[:, 3] = singular[1, :], singular[:, 1]    # row 4 = row 2
    assert massmatrix.failing_pivot(singular.tolist()) == 3
    indefinite = np.diag([1.0, 2.0, -1.0])
    assert massmatrix.failing_pivot(indefinite.tolist()) == 2
    nan = np.eye(2)
    nan[1, 1] = np.nan
    assert massmatrix.failing_pivot(nan.tolist()) == _first_failing(_numpy_ratios(nan)) == 1


def test_negligible_diagonal_finds_the_diagonal_zero_up_to_rounding():
    assert massmatrix.negligible_diagonal([[1.0, 0.0], [0.0, 1e-12]]) is None
    assert massmatrix.negligible_diagonal([[1.0, 0.0], [0.0, 1e-14]]) == 1
    assert massmatrix.negligible_diagonal([[0.0, 0.0], [0.0, 1.0]]) == 0


@pytest.mark.parametrize("model", ["double_pendulum", "tennis_racket"])
def test_ctypes_mass_matrix_is_the_loaded_models(build_root, model):
    """A through ctypes with the default parameters is bitwise the CompiledModel's, at
    the check's configurations (a free joint's quaternion normalised)."""
    cm = modelgen.load(MODELS / f"{model}.yaml", build_root / model)
    A = mass_matrix_function(cm.manifest, cm.path)
    for k in range(3):
        q = massmatrix.configuration(cm.manifest, k)
        assert A(q) == cm.mass_matrix(q).tolist()
    if cm.quaternions:
        (w, x, y, z), = cm.quaternions
        assert abs(np.linalg.norm(np.array(q)[[w, x, y, z]]) - 1.0) < 1e-15


def _cli(*args, wrapper: str = "") -> subprocess.CompletedProcess:
    """``modelgen`` in a fresh process (this checkout); its last line of output says
    whether numpy, cffi and the runtime module were imported."""
    code = ("import sys\nfrom modelgen.cli import main\nstatus = main(sys.argv[1:])\n"
            "print(sorted(m for m in ('numpy', 'cffi', 'modelgen.sim.runtime') "
            "if m in sys.modules))\nsys.exit(status)")
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True,
                          text=True, cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)),
                          timeout=600)


def test_cli_generate_imports_no_numpy(tmp_path):
    proc = _cli("generate", MODELS / "double_pendulum.yaml", "-o", tmp_path, "--force")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "double_pendulum.c").exists()
    assert proc.stdout.strip().splitlines()[-1] == "[]"


def test_cli_refuses_a_singular_model_in_the_words_of_load(tmp_path):
    """A double pendulum whose second base turns with q1 too (q2 moves nothing): the
    command line (ctypes, no numpy) and ``modelgen.load`` (the CompiledModel) refuse
    it with one message, built fresh and from the cache."""
    text = (MODELS / "double_pendulum.yaml").read_text()
    path = tmp_path / "stuck.yaml"
    path.write_text(text.replace("B2: {parent: B1, axis: 3, angle: q2}",
                                 "B2: {parent: B1, axis: 3, angle: q1}"))
    assert path.read_text() != text
    with pytest.raises(DerivationError, match="coordinate 'q2'") as exc:
        modelgen.load(path, tmp_path / "out")
    for force in (["--force"], []):
        proc = _cli("generate", path, "-o", tmp_path / "out", *force)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert proc.stderr.strip() == f"modelgen: error: {exc.value}"
        assert proc.stdout.strip().splitlines()[-1] == "[]"
