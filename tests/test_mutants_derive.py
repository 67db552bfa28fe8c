"""Derivation slips that the rest of the suite let through, each pinned against
an independent reference.

A mutation audit of ``modelgen/derive`` and ``modelgen/model`` applied plausible
slips one at a time (a sign, a transpose, a factor 1/2 or 2, a term left out,
an axis order) and ran the tests that ought to catch each.  This file holds a
test for every slip that survived and was neither an equivalent mutant nor dead
code.  Nothing here is compiled: the derive stage's expressions are expanded
and compared with sympy's own calculus.

The constraints' ``gamma`` (``G q_ddot + gamma = 0``) went unchecked where the
shipped models make it trivial: every shipped ``coincide`` and ``velocity``
constraint is taken in E, where ``w x e = 0`` and the Coriolis terms of gamma
vanish; and no test exercised the mixed second derivatives of a position
constraint's gamma (those written in the tests and docs are separable in the
coordinates, and the tests of MuJoCo's welds, whose residuals mix them, passed
with half of them left out).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy

from constrained_references import WHEEL_DISC
from modelgen.derive.constraints import derive_constraints
from modelgen.derive.kinematics import derive_kinematics
from modelgen.model.api import parse_model
from modelgen.model.spec import symbol

RTOL = 1e-12
MODELS = Path(__file__).resolve().parent.parent / "models"

#: a point on a circle-like curve whose equation mixes the coordinates (its Hessian
#: has off-diagonal terms)
CURVE = """\
name: curve
coordinates: [x, y]
parameters: {L: 1.0, m: 1.0, g: 9.81}
points:
  P: {coordinates: [x, y, 0]}
bodies:
  b: {mass: m, G: P, base: E}
gravity: [0, -g, 0]
constraints:
  curve: {type: position, expression: "x**2*y + sin(x*y) + y**3 - L**3"}
dependent: {coordinates: [y], speeds: [y_dot]}
"""

#: one model per constraint kind, with what makes its gamma non-trivial: the
#: shipped four-bar's and rolling disc's constraints taken in a base that turns
#: with q1, a curved position equation and rolling wheels
CONSTRAINED = {
    "coincide_in_a_turning_base": lambda: parse_model(
        (MODELS / "four_bar.yaml").read_text().replace("base: E, axes: [1, 2]",
                                                       "base: B1, axes: [1, 2]")),
    "velocity_in_a_turning_base": lambda: parse_model(
        (MODELS / "rolling_disc.yaml").read_text().replace("base: E, axes: [1, 2]",
                                                           "base: Y, axes: [1, 2]")),
    "position_with_mixed_terms": lambda: parse_model(CURVE),
    "rolling": lambda: parse_model(WHEEL_DISC),
}


@pytest.mark.parametrize("case", sorted(CONSTRAINED))
def test_constraint_rows_are_the_gradients_and_gamma_their_rate(case):
    """Each row of G is ``df/dq`` for a position equation ``f(q) = 0``, and for
    every row ``gamma = d(G qd)/dt`` at zero q_ddot, ``sum_l d(G qd)/dq_l qd_l``:
    the definitions, by sympy's ``diff`` of the expanded G and residuals, not the
    vector formulas of :mod:`modelgen.derive.constraints`."""
    spec = CONSTRAINED[case]()
    terms = derive_constraints(derive_kinematics(spec))
    graph = terms.graph
    q = [symbol(c) for c in spec.coordinates]
    qd = [symbol(s) for s in spec.speeds]
    p = [symbol(name) for name in spec.parameter_names]
    G = [[graph.expand(x) for x in row] for row in terms.G]
    G_qd = [sum(x * v for x, v in zip(row, qd, strict=True)) for row in G]
    rate = [sum(sympy.diff(e, ql) * vl for ql, vl in zip(q, qd, strict=True)) for e in G_qd]
    grads = [[sympy.diff(graph.expand(f), qk) for qk in q] for f in terms.residuals]
    m, m_h, n = len(G), len(grads), len(q)
    assert m > 0 and n == len(qd)
    exprs = [graph.expand(x) for x in terms.gamma] + rate + \
        [x for row in G[:m_h] for x in row] + [x for row in grads for x in row]
    evaluate = sympy.lambdify([*q, *qd, *p], exprs, cse=True)
    rng = np.random.default_rng(11)
    for _ in range(6):
        params = [float(v) * rng.uniform(0.5, 1.5) for _, v in spec.parameters]
        values = np.array(evaluate(*rng.uniform(-1.2, 1.2, n), *rng.uniform(-2, 2, n),
                                   *params), dtype=float)
        gamma, want = values[:m], values[m:2 * m]
        rows, grad = values[2 * m:2 * m + m_h * n], values[2 * m + m_h * n:]
        assert np.max(np.abs(gamma - want)) <= RTOL * (1 + np.max(np.abs(want))), \
            (case, gamma, want)
        assert np.max(np.abs(rows - grad), initial=0.0) <= \
            RTOL * (1 + np.max(np.abs(grad), initial=0.0)), (case, rows, grad)
