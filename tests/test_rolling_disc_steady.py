"""The shipped rolling disc (models/rolling_disc.yaml) in a steady turn, against the
closed-form relation between lean, turn rate, spin and turn radius.

A thin disc (mass m, radius r, I_axle = m r^2/2, I_diameter = m r^2/4) rolls
without slipping, leaning by phi (the model's q2), its heading turning at the
constant rate Omega (q1_dot), its centre on a horizontal circle of radius
R_G.  The steady-motion condition is the classical one (Routh, *Advanced
Rigid Dynamics*, art. 244; K. T. McDonald, "The rolling motion of a disk on a
horizontal plane", arXiv:physics/0008227, 2000, sec. 2.2), written here in the
model's angles and derived from Newton's and Euler's laws about the centre:

* rolling: the centre moves at v = r w_y along the heading, w_y = Omega sin phi
  + q3_dot the disc's angular velocity along its axle, so R_G = |r w_y / Omega|;
* Newton: the ground's force is m Omega r w_y across the heading and m g up;
* Euler about the centre (the angular momentum I_a w_y along the axle and
  I_d Omega cos phi along the disc's plane turns at Omega):
  Omega cos phi (I_d Omega sin phi - I_a w_y) = r (m Omega r w_y cos phi + m g sin phi),

which for the thin disc and a turn towards the lean (Omega r w_y = -Omega^2 R_G) is

    Omega^2 = 4 g tan(phi) / (6 R_G + r sin(phi)),

and the contact point runs on the circle of radius R = R_G + r sin(phi).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import modelgen

ROOT = Path(__file__).resolve().parent.parent
R_DISC, G = 0.5, 9.81


@pytest.fixture(scope="module")
def disc():
    cm = modelgen.load(ROOT / "models" / "rolling_disc.yaml")
    assert cm.parameters == {"m": 1.0, "r": R_DISC, "g": G}
    return cm


def steady_turn(cm, phi, R, sense):
    """The state of the steady turn with lean ``phi`` whose contact point runs on a
    circle of radius ``R``, rolling backwards (``sense`` +1: Omega > 0) or forwards
    along the heading (-1); and Omega."""
    RG = R - R_DISC * np.sin(phi)
    omega = sense * np.sqrt(4 * G * np.tan(phi) / (6 * RG + R_DISC * np.sin(phi)))
    w_axle = -omega * RG / R_DISC
    q = np.array([0.0, phi, 0.0, 0.0, 0.0])
    qd = cm.consistent_speeds(q, [omega, 0.0, w_axle - omega * np.sin(phi), 0.0, 0.0])
    return np.concatenate([q, qd]), omega


def run(cm, x0, t_end=10.0):
    res = cm.simulate(x0, (0.0, t_end), t_eval=np.linspace(0.0, t_end, 1001),
                      method="dop853", rtol=1e-12, atol=1e-12)
    assert res.success, res.message
    return res


@pytest.mark.parametrize("phi, R, sense", [(0.2, 3.0, 1), (0.5, 1.0, 1), (0.3, 2.0, -1)])
def test_steady_turn_keeps_its_lean_rate_and_circle(disc, phi, R, sense):
    x0, omega = steady_turn(disc, phi, R, sense)
    res = run(disc, x0)
    lean, yaw_rate = res.y[1], res.y[5]
    assert np.abs(lean - phi).max() < 1e-9
    assert np.abs(yaw_rate - omega).max() < 1e-9 * abs(omega)
    # the contact point (x, y) on the circle of radius R about the turn's centre,
    # which lies across the heading (E's y axis at the start), on the side the
    # disc leans to (-y for phi > 0), whichever way it rolls
    x, y = res.y[3], res.y[4]
    assert np.abs(np.hypot(x, y + R) - R).max() < 1e-9 * R


@pytest.mark.parametrize("phi, R, sense", [(0.2, 3.0, 1), (0.5, 1.0, 1)])
def test_a_slightly_wrong_spin_does_not_keep_the_lean(disc, phi, R, sense):
    x0, _ = steady_turn(disc, phi, R, sense)
    x0[7] *= 1.01                       # q3_dot one percent off
    x0 = np.concatenate([x0[:5], disc.consistent_speeds(x0[:5], x0[5:])])
    lean = run(disc, x0).y[1]
    assert np.abs(lean - phi).max() > 1e-4
