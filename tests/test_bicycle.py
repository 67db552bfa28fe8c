"""The Whipple bicycle (models/whipple_bicycle.yaml) against the benchmark of
Meijaard, Papadopoulos, Ruina and Schwab (2007, Proc. R. Soc. A 463,
1955-1982): the lean and steer eigenvalues of ``cm.linearize`` about upright
straight running against the paper's Table 2 and against its closed-form
linear model (Appendix A, written out below from the paper's formulas) at
other parameter sets, and the weave and capsize speeds of its section 5.
"""
from __future__ import annotations

from math import cos, pi, sin
from pathlib import Path

import numpy as np
import pytest

import modelgen
from modelgen.bench.bicycle import (CAPSIZE_SPEED, TABLE_2, WEAVE_SPEED, lean_steer_block,
                                    lean_steer_eigenvalues, stability_speeds, upright_state)

ROOT = Path(__file__).resolve().parent.parent

#: Table 1 of the paper
BENCHMARK = dict(w=1.02, c=0.08, lam=pi / 10, g=9.81, rR=0.3, mR=2.0, IRxx=0.0603, IRyy=0.12,
                 xB=0.3, zB=-0.9, mB=85.0, IBxx=9.2, IByy=11.0, IBzz=2.8, IBxz=2.4, xH=0.9,
                 zH=-0.7, mH=4.0, IHxx=0.05892, IHyy=0.06, IHzz=0.00708, IHxz=-0.00756,
                 rF=0.35, mF=3.0, IFxx=0.1405, IFyy=0.28)



def closed_form(P):
    """M, C1, K0, K2 of the paper's Appendix A: M q'' + v C1 q' + (g K0 + v^2 K2) q = 0
    in q = (lean phi, steer delta)."""
    lam, w, c = P["lam"], P["w"], P["c"]
    mR, mB, mH, mF = P["mR"], P["mB"], P["mH"], P["mF"]
    rR, rF, xB, zB, xH, zH = P["rR"], P["rF"], P["xB"], P["zB"], P["xH"], P["zH"]
    IRxx, IRzz, IFxx, IFzz = P["IRxx"], P["IRxx"], P["IFxx"], P["IFxx"]
    mT = mR + mB + mH + mF
    xT = (xB * mB + xH * mH + w * mF) / mT
    zT = (-rR * mR + zB * mB + zH * mH - rF * mF) / mT
    ITxx = IRxx + P["IBxx"] + P["IHxx"] + IFxx + mR * rR**2 + mB * zB**2 + mH * zH**2 \
        + mF * rF**2
    ITxz = P["IBxz"] + P["IHxz"] - mB * xB * zB - mH * xH * zH + mF * w * rF
    ITzz = IRzz + P["IBzz"] + P["IHzz"] + IFzz + mB * xB**2 + mH * xH**2 + mF * w**2
    mA = mH + mF
    xA = (xH * mH + w * mF) / mA
    zA = (zH * mH - rF * mF) / mA
    IAxx = P["IHxx"] + IFxx + mH * (zH - zA) ** 2 + mF * (rF + zA) ** 2
    IAxz = P["IHxz"] - mH * (xH - xA) * (zH - zA) + mF * (w - xA) * (rF + zA)
    IAzz = P["IHzz"] + IFzz + mH * (xH - xA) ** 2 + mF * (w - xA) ** 2
    uA = (xA - w - c) * cos(lam) - zA * sin(lam)
    IAll = mA * uA**2 + IAxx * sin(lam) ** 2 + 2 * IAxz * sin(lam) * cos(lam) \
        + IAzz * cos(lam) ** 2
    IAlx = -mA * uA * zA + IAxx * sin(lam) + IAxz * cos(lam)
    IAlz = mA * uA * xA + IAxz * sin(lam) + IAzz * cos(lam)
    mu = c / w * cos(lam)
    SR, SF = P["IRyy"] / rR, P["IFyy"] / rF
    ST = SR + SF
    SA = mA * uA + mu * mT * xT
    M = np.array([[ITxx, IAlx + mu * ITxz],
                  [IAlx + mu * ITxz, IAll + 2 * mu * IAlz + mu**2 * ITzz]])
    C1 = np.array([[0.0, mu * ST + SF * cos(lam) + ITxz / w * cos(lam) - mu * mT * zT],
                   [-(mu * ST + SF * cos(lam)), IAlz / w * cos(lam)
                    + mu * (SA + ITzz / w * cos(lam))]])
    K0 = np.array([[mT * zT, -SA], [-SA, -SA * sin(lam)]])
    K2 = np.array([[0.0, (ST - mT * zT) / w * cos(lam)],
                   [0.0, (SA + SF * sin(lam)) / w * cos(lam)]])
    return M, C1, K0, K2


def closed_form_eigenvalues(P, v):
    M, C1, K0, K2 = closed_form(P)
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((2, 2)), np.eye(2)],
                  [-Mi @ (P["g"] * K0 + v**2 * K2), -Mi @ (v * C1)]])
    return np.sort_complex(np.linalg.eigvals(A).astype(complex))


#: two other bicycles: every Table 1 value moved by a seeded factor in [0.7, 1.3]
#: (a longer, a shorter, a heavier and a lighter one; the products of inertia too)
OTHER_SETS = [{k: v * f for (k, v), f in zip(BENCHMARK.items(),
                                             np.random.default_rng(seed).uniform(0.7, 1.3,
                                                                                 len(BENCHMARK)))}
              for seed in (1, 2)]


@pytest.fixture(scope="module")
def bicycle():
    return modelgen.load(ROOT / "models" / "whipple_bicycle.yaml", linearize=True)


def test_the_model_carries_table_1_as_its_parameters(bicycle):
    assert list(bicycle.parameters) == list(BENCHMARK)
    assert np.allclose(list(bicycle.parameters.values()), list(BENCHMARK.values()),
                       rtol=1e-15, atol=0)


def test_closed_form_reproduces_the_papers_matrices():
    """Appendix A as written above gives the paper's printed M, C1, K0, K2 (A.14-A.17)."""
    M, C1, K0, K2 = closed_form(BENCHMARK)
    assert np.allclose(M, [[80.81722, 2.31941332208709], [2.31941332208709, 0.29784188199686]],
                       rtol=0, atol=1e-13)
    assert np.allclose(C1, [[0, 33.86641391492494], [-0.85035641456978, 1.68540397397560]],
                       rtol=0, atol=1e-13)
    assert np.allclose(K0, [[-80.95, -2.59951685249872], [-2.59951685249872,
                                                           -0.80329488458618]],
                       rtol=0, atol=1e-13)
    assert np.allclose(K2, [[0, 76.59734589573222], [0, 2.65431523794604]], rtol=0, atol=1e-13)


def test_lean_steer_eigenvalues_match_table_2(bicycle):
    worst = 0.0
    for v, want in TABLE_2.items():
        got = lean_steer_eigenvalues(bicycle, float(v))
        worst = max(worst, np.max(np.abs(got - np.sort_complex(np.array(want, complex)))))
    assert worst <= 1e-10, worst


def test_lean_steer_block_is_the_closed_form_one(bicycle):
    """At 0.4 m/s steps: the block's eigenvalues against the closed form, and the
    block decoupled from the other minimal states (cyclic coordinates, the speed)."""
    worst, coupling = 0.0, 0.0
    for v in np.linspace(0.0, 10.0, 26):
        got = lean_steer_eigenvalues(bicycle, v)
        worst = max(worst, np.max(np.abs(got - closed_form_eigenvalues(BENCHMARK, v))))
        lin = bicycle.linearize(upright_state(bicycle, v))
        i = [lin.states.index(s) for s in ("roll", "steer", "roll_dot", "steer_dot")]
        j = [k for k in range(len(lin.states)) if k not in i]
        coupling = max(coupling, np.max(np.abs(lin.A[np.ix_(i, j)])))
    assert worst <= 1e-10, worst
    assert coupling <= 1e-10, coupling


def test_weave_and_capsize_speeds_match_the_paper(bicycle):
    weave, capsize = stability_speeds(bicycle)
    assert abs(weave - WEAVE_SPEED) <= 1e-8, weave
    assert abs(capsize - CAPSIZE_SPEED) <= 1e-8, capsize


@pytest.mark.parametrize("k", range(len(OTHER_SETS)))
def test_other_bicycles_match_the_closed_form(bicycle, k):
    """Run-time parameters: the same library at another parameter set."""
    P = OTHER_SETS[k]
    worst = 0.0
    for v in (0.0, 1.5, 3.0, 4.5, 6.0, 8.0):
        got = lean_steer_eigenvalues(bicycle, v, p=P)
        worst = max(worst, np.max(np.abs(got - closed_form_eigenvalues(P, v))))
    assert worst <= 1e-10, worst


def test_lean_steer_block_of_a_state_space_model(bicycle):
    """The block is the paper's [[0, I], [-M^-1 (g K0 + v^2 K2), -M^-1 v C1]] itself
    (the model's roll and steer are the paper's phi and delta)."""
    v = 4.6
    M, C1, K0, K2 = closed_form(BENCHMARK)
    Mi = np.linalg.inv(M)
    want = np.block([[np.zeros((2, 2)), np.eye(2)],
                     [-Mi @ (BENCHMARK["g"] * K0 + v**2 * K2), -Mi @ (v * C1)]])
    got = lean_steer_block(bicycle, v)
    assert np.max(np.abs(got - want)) <= 1e-10 * np.max(np.abs(want))


def test_the_coasting_scene_weaves_down_and_conserves_energy():
    """models/scenes/whipple_bicycle_coast.yaml: at 4.6 m/s (inside the stable range)
    a push's lean oscillation dies out, rolling without slip does no work, and the
    projection keeps the contacts on the ground."""
    scene = modelgen.load_scene(ROOT / "models" / "scenes" / "whipple_bicycle_coast.yaml")
    res = scene.run()
    assert res.success, res.message
    cm = scene.model
    roll = res.y[cm.state_names.index("roll")]
    first, last = np.abs(roll[res.t <= 1.0]).max(), np.abs(roll[res.t >= 9.0]).max()
    assert first > 0.05 and last < 0.05 * first, (first, last)
    energy = res.outputs["energy"].ravel()
    assert np.max(np.abs(energy - energy[0])) <= 1e-9 * abs(energy[0])
    assert max(np.max(np.abs(cm.constraint_residuals(x[:cm.n]))) for x in res.y.T) <= 1e-12
