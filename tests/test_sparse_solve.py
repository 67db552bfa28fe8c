"""The crba rhs's solve skips the structural zeros of a tree's mass matrix.

A tree's A couples a coordinate only with its ancestors and descendants
(Featherstone, RBDA §6.5); eliminating a leaf of what is left first gives no
fill-in.  The straight-line C that :func:`modelgen.codegen.ldlt.unrolled_ldlt`
writes from :func:`~modelgen.codegen.ldlt.elimination` is compiled here on
random matrices of random trees (and on structures that are not chordal, which
fill in) and checked against numpy's dense solve; the generated models are
checked against the ABA program, which shares no code with it.
"""
from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

import modelgen
from modelgen.codegen.build import compiler
from modelgen.codegen.ldlt import elimination, solve_code, unrolled_ldlt, UNROLL_SOLVE

MODELS = Path(__file__).resolve().parent.parent / "models"


def _tree_matrix(parents, rng):
    """A random SPD matrix with a tree's structure: sum over bodies of J^T J, where a
    body's J has columns for the body's joint and its ancestors only."""
    n = len(parents)
    A = 1e-3 * np.eye(n)
    for body in range(n):
        chain, j = [], body
        while j >= 0:
            chain.append(j)
            j = parents[j]
        J = np.zeros((6, n))
        J[:, chain] = rng.normal(size=(6, len(chain)))
        A += J.T @ J
    return A


def _random_parents(n, rng):
    """Parents of a random tree (-1 for a root), numbered in a random order."""
    perm = rng.permutation(n)
    tree = [-1] + [int(rng.integers(0, i)) for i in range(1, n)]   # parent before child
    parents = [-1] * n
    for node, parent in enumerate(tree):
        parents[perm[node]] = -1 if parent < 0 else int(perm[parent])
    return parents


_MAIN = r"""
#include <stdio.h>
static int solve(const double *A, double *b)
{
%s
    return 0;
}
int main(void)
{
    static double A[%d], b[%d];
    int i, status;
    for (i = 0; i < %d; ++i) if (scanf("%%lf", &A[i]) != 1) return 90;
    for (i = 0; i < %d; ++i) if (scanf("%%lf", &b[i]) != 1) return 91;
    status = solve(A, b);
    printf("%%d\n", status);
    for (i = 0; i < %d; ++i) printf("%%.17g\n", b[i]);
    return 0;
}
"""


@pytest.fixture(scope="module")
def run_solver(tmp_path_factory):
    """compile the solve of ``lines`` for size n; returns f(A, b) -> (status, y)."""
    root = tmp_path_factory.mktemp("sparse_solve")
    count = iter(range(10 ** 6))

    def build(n, lines):
        k = next(count)
        src, exe = root / f"s{k}.c", root / f"s{k}"
        src.write_text(_MAIN % ("\n".join("    " + line for line in lines), n * n, n,
                                n * n, n, n))
        subprocess.run([*compiler(), "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror",
                        "-DTOL=1e-13", str(src), "-o", str(exe)], check=True)

        def solve(A, b):
            text = "\n".join(repr(float(v)) for v in [*np.ravel(A), *b])
            out = subprocess.run([str(exe)], input=text, capture_output=True, text=True,
                                 check=True).stdout.split()
            return int(out[0]), np.array(out[1:], float)
        return solve
    return build


def _pattern(A):
    return [[bool(v != 0.0) for v in row] for row in A]


@pytest.mark.parametrize("seed", range(12))
def test_tree_structure_factors_without_fill_and_solves_like_numpy(run_solver, seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 16))
    parents = _random_parents(n, rng)
    A = _tree_matrix(parents, rng)
    plan = elimination(_pattern(A))
    assert plan.fill == frozenset()
    assert sorted(plan.order) == list(range(n))
    solve = run_solver(n, unrolled_ldlt(n, "TOL", plan))
    for _ in range(3):
        b = rng.normal(size=n)
        status, y = solve(A, b)
        assert status == 0
        expected = np.linalg.solve(A, b)
        assert np.max(np.abs(y - expected)) <= 1e-12 * np.max(np.abs(expected))


def test_a_structure_that_is_not_chordal_fills_in_and_still_solves(run_solver):
    rng = np.random.default_rng(7)
    n = 6                                           # a ring: no elimination avoids fill-in
    A = 4.0 * np.eye(n)
    for i in range(n):
        A[i, (i + 1) % n] = A[(i + 1) % n, i] = rng.uniform(0.5, 1.5)
    plan = elimination(_pattern(A))
    assert plan.fill
    status, y = run_solver(n, unrolled_ldlt(n, "TOL", plan))(A, np.arange(1.0, n + 1))
    assert status == 0
    assert np.allclose(y, np.linalg.solve(A, np.arange(1.0, n + 1)), rtol=1e-13, atol=0)


def test_a_singular_tree_matrix_returns_its_failing_pivot(run_solver):
    parents = [-1, 0, 0, 1]
    A = _tree_matrix(parents, np.random.default_rng(3))
    A[3, :] = A[:, 3] = 0.0                         # the leaf 4 has nothing to move
    plan = elimination(_pattern(_tree_matrix(parents, np.random.default_rng(3))))
    status, _ = run_solver(4, unrolled_ldlt(4, "TOL", plan))(A, np.ones(4))
    assert status == 4


def test_a_dense_matrix_keeps_the_plain_ldlt_in_index_order():
    dense = [[True] * 5] * 5
    assert elimination(dense).order == (0, 1, 2, 3, 4)
    assert unrolled_ldlt(2, "TOL") == [               # the LDL^T the build always wrote
        "const double d0 = A[0];",
        "if (!(d0 > TOL * A[0]) || !(A[0] > 0.0)) return 1;",
        "const double inv0 = 1.0 / d0;",
        "const double L1_0 = (A[2]) * inv0;",
        "const double u1_0 = L1_0 * d0;",
        "const double d1 = A[3] - u1_0 * L1_0;",
        "if (!(d1 > TOL * A[3]) || !(A[3] > 0.0)) return 2;",
        "const double inv1 = 1.0 / d1;",
        "const double y0 = b[0];",
        "const double y1 = b[1] - L1_0 * y0;",
        "b[1] = y1 * inv1;",
        "b[0] = y0 * inv0 - L1_0 * b[1];"]
    assert solve_code(5, "TOL", dense) == {"solve_lines": unrolled_ldlt(5, "TOL"),
                                           "solve_loop": None}
    assert solve_code(UNROLL_SOLVE + 1, "TOL", None) == {"solve_lines": [],  # the dense loop
                                                         "solve_loop": None}


def test_a_sparse_tree_beyond_the_dense_limit_is_still_unrolled():
    parents = _random_parents(30, np.random.default_rng(11))
    code = solve_code(30, "TOL", _pattern(_tree_matrix(parents, np.random.default_rng(0))))
    # a random tree of 30 is shallow: its factorization is cheaper than a dense one of 30
    assert code["solve_lines"][0].startswith("/* eliminated in the order")
    assert code["solve_loop"] is None


@pytest.mark.parametrize("unrolled", [True, False], ids=["unrolled", "loop"])
def test_solo12_crba_rhs_agrees_with_aba_through_the_sparse_solve(tmp_path, monkeypatch,
                                                                  unrolled):
    """The floating quadruped (18 speeds: four legs, then the free joint's six): the
    crba rhs, whose solve skips the legs' zero blocks, against the ABA program; once
    straight-line (its default) and once through the loop that larger trees get."""
    from modelgen.codegen import ldlt
    if not unrolled:
        monkeypatch.setattr(ldlt, "SPARSE_UNROLL_SIZE", 1)
    path = MODELS / "robots" / "solo12.yaml"
    crba = modelgen.load(path, tmp_path / "crba", formulation="crba", force=True)
    aba = modelgen.load(path, tmp_path / "aba", formulation="aba")
    c_source = (tmp_path / "crba" / f"{crba.name}.c").read_text()
    assert ("the structural zeros of A skipped" in c_source) == unrolled
    assert ("LDL^T over the structurally non-zero entries" in c_source) != unrolled
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = crba.project(np.concatenate([rng.uniform(-1, 1, crba.nq),
                                         rng.uniform(-2, 2, crba.n)]))
        a, b = aba.rhs(0.0, x), crba.rhs(0.0, x)
        assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))
