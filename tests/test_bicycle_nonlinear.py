"""The nonlinear benchmark of Basu-Mandal, Chatterjee and Papadopoulos (2007,
"Hands-free circular motions of a benchmark bicycle", Proc. R. Soc. A 463,
1983-2003, Table 1): at one general state of the benchmark bicycle (leaning
35 degrees, steered, rolling at about 2.7 m/s) the accelerations of all nine
coordinates, which they give to 13 or 14 significant figures, computed by two
independent formulations (Newton-Euler and Lagrange).

The numbers are the table's as transcribed in J. K. Moore's DynamicistToolKit
(``dtk/bicycle.py``: ``basu_table_one_input``, ``basu_table_one_output``, with
the conversion ``basu_to_moore_input``), the check PyDy's bicycle uses.

Conventions.  Basu-Mandal's axes have z up and x, y opposite to modelgen's E
(from dtk's conversion: their x = -(Moore's N.x), y = N.y, z = -N.z, N with z
down; E here is N turned by pi about x).  Their (x, y, z) is the rear wheel's
centre; theta the yaw; psi the rear frame's angle to the vertical as
pi/2 - roll; phi the rear frame's pitch as pi + (modelgen's pitch); psi_f, beta_r and
beta_f the steer and the wheels' rotations, all three of opposite sense to
modelgen's.  So, in modelgen's coordinates
(x, y, z, yaw, roll, pitch, steer, thR, thF):

    (-x, -y, z, theta, pi/2 - psi, phi - pi, -psi_f, -beta_r, -beta_f),

and the rates likewise (the constants dropped, the signs kept).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import modelgen

ROOT = Path(__file__).resolve().parent.parent

#: Basu-Mandal et al. (2007), Table 1: the state ...
STATE = dict(x=0.0, y=0.0, z=0.2440472102925, theta=0.0, psi=0.9501292851472,
             phi=3.1257073014894, psif=0.2311385135743, betar=0.0, betaf=0.0,
             xd=-2.8069345714545, yd=-0.1480982396001, zd=0.1058778746261,
             thetad=0.7830033527065, psid=0.6068425835418, phid=-0.0119185528069,
             psifd=0.4859824687093, betard=8.9129896614890, betafd=8.0133620584155)
#: ... and its accelerations
ACCELERATIONS = dict(xdd=-0.5041626315047, ydd=-0.3449706619454, zdd=-1.4604528332980,
                     thetadd=0.8353281706379, psidd=-7.8555281128244,
                     phidd=0.1205543897884, psifdd=-4.6198904039403,
                     betardd=1.8472554144217, betafdd=2.4548072904550)


def coordinates(d):
    return np.array([-d["x"], -d["y"], d["z"], d["theta"], np.pi / 2 - d["psi"],
                     d["phi"] - np.pi, -d["psif"], -d["betar"], -d["betaf"]])


def rates(d, s):
    return np.array([-d["x" + s], -d["y" + s], d["z" + s], d["theta" + s], -d["psi" + s],
                     d["phi" + s], -d["psif" + s], -d["betar" + s], -d["betaf" + s]])


@pytest.fixture(scope="module")
def bicycle():
    return modelgen.load(ROOT / "models" / "whipple_bicycle.yaml")


def test_table_one_state_is_on_the_constraints(bicycle):
    q, qd = coordinates(STATE), rates(STATE, "d")
    assert np.abs(bicycle.constraint_residuals(q)).max() < 1e-13
    assert np.abs(bicycle.constraint_jacobian(q) @ qd).max() < 1e-12


def test_accelerations_match_basu_mandal_table_one(bicycle):
    q, qd = coordinates(STATE), rates(STATE, "d")
    xdot = bicycle.rhs(0.0, np.concatenate([q, qd]))
    # the dependent speeds the rhs computes from roll, steer and the rear
    # wheel's rates are the table's
    assert np.abs(xdot[:9] - qd).max() < 1e-12
    want = rates(ACCELERATIONS, "dd")
    assert np.abs(xdot[9:] - want).max() < 1e-10 * np.abs(want).max()
    assert np.abs(xdot[9:] - want).max() < 1e-11
