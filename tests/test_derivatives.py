"""Derivatives of inverse and forward dynamics (modelgen/derive/rnea_derivatives.py and
``<name>_derivatives``) against Pinocchio's ``computeRNEADerivatives`` and
``computeABADerivatives`` and against central differences of the generated rhs."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy
from sympy.printing.pycode import pycode

from modelgen.derive.dynamics import derive_equations
from modelgen.derive.joint_tree import extract_joint_tree
from modelgen.derive.kinematics import derive_kinematics
from modelgen.derive.rnea_derivatives import derive_inverse_dynamics_derivatives
from modelgen.model.chains import spatial_chain

TOL = 1e-9


def _program(graph, outputs, inputs):
    """A Python function evaluating ``outputs`` of a straight-line program."""
    lines = ["def f(" + ", ".join(str(s) for s in inputs) + "):"]
    for sym, expr in graph.closure(outputs):
        lines.append(f"    {sym} = {pycode(expr)}")
    lines.append("    return [" + ", ".join(pycode(sympy.sympify(e)) for e in outputs) + "]")
    namespace = {"math": math}
    exec("\n".join(lines), namespace)     # noqa: S102 - our own generated program
    return namespace["f"]


def _relative(a, b) -> float:
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


@pytest.mark.parametrize("n", [1, 4, 9])
def test_rnea_derivatives_program_matches_pinocchio_on_spatial_chains(n):
    pin = pytest.importorskip("pinocchio")
    from modelgen.bench.hardcase_models import chain_pinocchio
    spec = spatial_chain(n).spec()
    eqs = derive_equations(derive_kinematics(spec))
    d = derive_inverse_dynamics_derivatives(eqs, extract_joint_tree(spec), spec)
    flat = [e for rows in (d.dq, d.dv, d.M) for row in rows for e in row]
    f = _program(d.graph, flat + list(d.Q), (eqs.t,) + eqs.q + eqs.qd + eqs.u + eqs.p + d.a)
    rng = np.random.default_rng(n)
    for _ in range(2):
        p = dict(zip((str(s) for s in eqs.p), rng.uniform(0.5, 1.5, len(eqs.p))))
        p["r"], p["g"] = 0.02 * p["r"], 9.81 * p["g"]
        model = chain_pinocchio(n, p)
        data = model.createData()
        q, v, a = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
        r = np.array(f(0.0, *q, *v, *(p[str(s)] for s in eqs.p), *a))
        dq, dv, M = (r[k * n * n:(k + 1) * n * n].reshape(n, n) for k in range(3))
        dtau_dq, dtau_dv, M_pin = pin.computeRNEADerivatives(model, data, q, v, a)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        assert _relative(r[3 * n * n:], pin.rnea(model, data, q, v, a)) <= TOL
        for got, want in ((dq, dtau_dq), (dv, dtau_dv), (M, M_pin)):
            assert _relative(got, want) <= TOL


def test_entries_of_joints_on_different_branches_are_structurally_zero():
    from test_aba import branched_tree
    spec = branched_tree().spec()
    eqs = derive_equations(derive_kinematics(spec))
    d = derive_inverse_dynamics_derivatives(eqs, extract_joint_tree(spec), spec)
    k = {c: i for i, c in enumerate(spec.coordinates)}
    apart = [(k["q3"], k["q2"]), (k["q3"], k["q4"])]
    for i, j in apart + [(j, i) for i, j in apart]:
        assert d.M[i][j] == 0 and d.dv[i][j] == 0
    # the spring between the branches couples their coordinates' forces
    assert d.dq[k["q3"]][k["q4"]] != 0
    assert all(d.M[i][i] != 0 for i in range(spec.n))
