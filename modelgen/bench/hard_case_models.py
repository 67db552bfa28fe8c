"""The models of the hard-case suite, and the closed forms they are checked against.

Each model is a YAML text here (the suite reads nothing from the source
tree's ``models/``), parsed with :func:`modelgen.model.api.parse_model`.  The
references are written out from the mechanics, independently of modelgen's
derivation: closed forms (pendulum period, Lagrange top separatrix, tennis
racket flip period, Coulomb stop time), the double pendulum's A and h by hand
for the 30-digit mpmath solve, a linear model's state matrix for the matrix
exponential (the chain's MJCF for MuJoCo is in :mod:`modelgen.bench.peers`).

>>> round(pendulum_period(math.pi / 2), 12)
2.367841947576
>>> float(separatrix_cos_theta(0.0, 9.0))
0.5
"""
from __future__ import annotations

import math

import mpmath
import numpy as np
from scipy.special import ellipk

#: a point mass on a massless rod (q from the downward vertical)
PENDULUM = """
name: hc_pendulum
coordinates: [q]
parameters: {L: 1.0, m: 1.0, g: 9.81}
bases:
  B1: {parent: E, axis: 3, angle: q}
points:
  P: {from: O, base: B1, coordinates: [0, -L, 0]}
bodies:
  bob: {mass: m, G: P, base: B1}
gravity: [0, -g, 0]
"""

#: the heavy symmetric top, ZXZ Euler angles (theta the nutation angle)
HEAVY_TOP = """
name: hc_heavy_top
coordinates: [phi, theta, psi]
parameters: {m: 1.0, a: 0.1, A0: 0.002, C: 0.003, g: 9.81}
bases:
  B1: {parent: E, axis: 3, angle: phi}
  B2: {parent: B1, axis: 1, angle: theta}
  B3: {parent: B2, axis: 3, angle: psi}
points:
  G: {from: O, base: B3, coordinates: [0, 0, a]}
bodies:
  top: {mass: m, G: G, base: B3, inertia: [A0, A0, C]}
gravity: [0, 0, -g]
"""

#: the planar double pendulum of two rods (no input); J1, J2: moments about G1, G2
#: (m l^2 / 12 for the default uniform rods)
DOUBLE_PENDULUM = """
name: hc_double_pendulum
coordinates: [q1, q2]
parameters: {m1: 1.0, m2: 1.0, l1: 1.0, l2: 1.0, J1: 0.08333333333333333,
             J2: 0.08333333333333333, g: 9.81}
bases:
  B1: {parent: E, axis: 3, angle: q1}
  B2: {parent: B1, axis: 3, angle: q2}
points:
  P1: {from: O, base: B1, coordinates: [l1, 0, 0]}
  G1: {from: O, base: B1, coordinates: [l1/2, 0, 0]}
  G2: {from: P1, base: B2, coordinates: [l2/2, 0, 0]}
bodies:
  rod1: {mass: m1, G: G1, base: B1, inertia: [0, J1, J1]}
  rod2: {mass: m2, G: G2, base: B2, inertia: [0, J2, J2]}
gravity: [0, -g, 0]
"""

#: two masses on a line: a soft spring to the wall, a stiff spring and a damper between
STIFF_PAIR = """
name: hc_stiff_pair
coordinates: [x1, x2]
parameters: {m1: 1.0, m2: 1.0, k1: 1.0, k: 100.0, c: 1.0}
points:
  W: {coordinates: [0, 0, 0]}
  P1: {coordinates: [x1, 0, 0]}
  P2: {coordinates: [x2, 0, 0]}
bodies:
  mass1: {mass: m1, G: P1, base: E}
  mass2: {mass: m2, G: P2, base: E}
effects:
  soft: {type: spring, point_a: W, point_b: P1, stiffness: k1, rest_length: 1.0}
  stiff: {type: spring, point_a: P1, point_b: P2, stiffness: k, rest_length: 1.0}
  damper: {type: damper, point_a: P1, point_b: P2, damping: c}
"""

#: a block on an incline with regularised Coulomb friction on its coordinate
INCLINE_BLOCK = """
name: hc_incline_block
coordinates: [s]
parameters: {m: 1.0, g: 9.81, alpha: 0.3, mu: 0.5, v_s: 0.001}
bases:
  Bs: {parent: E, axis: 3, angle: -alpha}
points:
  P: {from: O, base: Bs, coordinates: [s, 0, 0]}
bodies:
  block: {mass: m, G: P, base: Bs}
gravity: [0, -g, 0]
effects:
  friction: {type: friction, coordinate: s, coulomb: mu*m*g*cos(alpha), smoothing_speed: v_s}
"""

#: a torque-free body, ZYX angles; the intermediate moment I2 is about the body's z axis
TORQUE_FREE = """
name: hc_torque_free
coordinates: [yaw, pitch, roll]
parameters: {m: 1.0, I1: 1.0, I2: 2.0, I3: 3.0}
bases:
  B1: {parent: E, axis: 3, angle: yaw}
  B2: {parent: B1, axis: 2, angle: pitch}
  B3: {parent: B2, axis: 1, angle: roll}
bodies:
  brick: {mass: m, G: O, base: B3, inertia: [I1, I3, I2]}
"""

#: a pendulum whose bob (a particle) can also turn about the rod: q2 moves no mass
SINGULAR_EVERYWHERE = """
name: hc_singular_everywhere
coordinates: [q1, q2]
parameters: {L: 1.0, m: 1.0, g: 9.81}
bases:
  B1: {parent: E, axis: 3, angle: q1}
  B2: {parent: B1, axis: 2, angle: q2}
points:
  P: {from: O, base: B1, coordinates: [0, -L, 0]}
bodies:
  bob: {mass: m, G: P, base: B2}
gravity: [0, -g, 0]
"""

#: a crank-rocker four-bar (Grashof: the crank a turns fully) whose rocker's speed
#: is the independent one: at the rocker's extremes crank and coupler are in line,
#: the crank's and coupler's columns of the constraint Jacobian are singular (its
#: dead points, which the motion reaches every half turn of the crank)
FOUR_BAR_ROCKER = """
name: hc_four_bar_rocker
coordinates: [q1, q2, q3]
parameters: {a: 1.0, b: 2.0, c: 2.0, d: 2.5, m1: 1.0, m2: 2.0, m3: 2.0, g: 9.81}
bases:
  B1: {parent: E, axis: 3, angle: q1}
  B2: {parent: E, axis: 3, angle: q2}
  B3: {parent: E, axis: 3, angle: q3}
points:
  D:  {coordinates: [d, 0, 0]}
  P1: {from: O, base: B1, coordinates: [a, 0, 0]}
  G1: {from: O, base: B1, coordinates: [a/2, 0, 0]}
  P2: {from: P1, base: B2, coordinates: [b, 0, 0]}
  G2: {from: P1, base: B2, coordinates: [b/2, 0, 0]}
  P3: {from: D, base: B3, coordinates: [c, 0, 0]}
  G3: {from: D, base: B3, coordinates: [c/2, 0, 0]}
bodies:
  crank:   {mass: m1, G: G1, base: B1, inertia: [0, m1*a**2/12, m1*a**2/12]}
  coupler: {mass: m2, G: G2, base: B2, inertia: [0, m2*b**2/12, m2*b**2/12]}
  rocker:  {mass: m3, G: G3, base: B3, inertia: [0, m3*c**2/12, m3*c**2/12]}
gravity: [0, -g, 0]
constraints:
  loop: {type: coincide, point_a: P2, point_b: P3, base: E, axes: [1, 2]}
dependent: {coordinates: [q1, q2], speeds: [q1_dot, q2_dot]}
"""


def rocker_dead_points(a=1.0, b=2.0, c=2.0, d=2.5) -> tuple:
    """The rocker angles q3 at the four-bar's dead points, where crank and coupler are
    in line and the loop's C is a + b (stretched) or b - a (folded) from A:
    |D + c e(q3)| = a + b or b - a, by the law of cosines."""
    return tuple(float(np.arccos((r**2 - d**2 - c**2) / (2 * c * d))) for r in (a + b, b - a))


def pendulum_period(theta0: float, L: float = 1.0, g: float = 9.81) -> float:
    """T = 4 sqrt(L/g) K(sin^2(theta0/2)) (scipy's ellipk takes m = k^2)."""
    return 4.0 * math.sqrt(L / g) * float(ellipk(math.sin(theta0 / 2.0) ** 2))


def separatrix_cos_theta(t, gamma: float):
    """cos theta(t) = 1 / (1 + sech(gamma t)) of the Lagrange top on its separatrix."""
    return 1.0 / (1.0 + 1.0 / np.cosh(gamma * np.asarray(t, dtype=float)))


def separatrix_start(m=1.0, a=0.1, A0=0.002, C=0.003, g=9.81):
    """(gamma, x0) of the separatrix: theta = pi/3, phi' = 2 gamma/sqrt 3,
    psi' = (3A - C) gamma / (C sqrt 3), with A = A0 + m a^2 and m g a = A gamma^2."""
    A = A0 + m * a * a
    gamma = math.sqrt(m * g * a / A)
    s3 = math.sqrt(3.0)
    return gamma, np.array([0.0, math.pi / 3, 0.0, 2 * gamma / s3, 0.0,
                            (3 * A - C) * gamma / (C * s3)])


def separatrix_time_to(theta: float, gamma: float) -> float:
    """When the separatrix solution's nutation angle falls to ``theta``."""
    c = math.cos(theta)
    return math.acosh(c / (1.0 - c)) / gamma     # sech(gamma t) = 1/c - 1


def sleeping_top_threshold(m=1.0, a=0.1, A0=0.002, C=0.003, g=9.81) -> float:
    """The spin above which the sleeping top is stable: C^2 w^2 > 4 A m g a."""
    return math.sqrt(4.0 * (A0 + m * a * a) * m * g * a) / C


def flip_period(I1: float, I2: float, I3: float, omega) -> float:
    """Time between two flips of a torque-free body spinning near its intermediate
    axis (Landau-Lifshitz section 37): 2 K(k) / lambda, for M^2 > 2 E I2
    (``omega`` in principal axes with I1 < I2 < I3)."""
    w = np.asarray(omega, dtype=float)
    I = np.array([I1, I2, I3])
    E2 = float(np.sum(I * w * w))            # 2E
    M2 = float(np.sum((I * w) ** 2))
    lam = math.sqrt((I3 - I2) * (M2 - E2 * I1) / (I1 * I2 * I3))
    k2 = (I2 - I1) * (E2 * I3 - M2) / ((I3 - I2) * (M2 - E2 * I1))
    if M2 > E2 * I2:
        return 2.0 * float(ellipk(k2)) / lam
    # M^2 < 2EI2: the roles of I1 and I3 swap (same formula with 1 <-> 3)
    lam = math.sqrt((I2 - I1) * (E2 * I3 - M2) / (I1 * I2 * I3))
    k2 = (I3 - I2) * (M2 - E2 * I1) / ((I2 - I1) * (E2 * I3 - M2))
    return 2.0 * float(ellipk(k2)) / lam


def double_pendulum_qdd(q, qd, m1, m2, l1, l2, J1, J2, g=9.81, digits=30):
    """q'' of the double pendulum, solved in ``digits`` digits.

    T = 1/2 (J1 + m1 l1^2/4) q1'^2 + 1/2 m2 |v_G2|^2 + 1/2 J2 (q1' + q2')^2,
    V = g (m1 l1/2 sin q1 + m2 (l1 sin q1 + l2/2 sin(q1 + q2))) (gravity along -y,
    rods along the x axes of their bases).
    """
    with mpmath.workdps(digits):
        m1, m2, l1, l2, J1, J2, g = (mpmath.mpf(v) for v in (m1, m2, l1, l2, J1, J2, g))
        q1, q2 = (mpmath.mpf(v) for v in q)
        u1, u2 = (mpmath.mpf(v) for v in qd)
        c = m2 * l1 * l2 / 2
        a22 = m2 * l2 ** 2 / 4 + J2
        A = mpmath.matrix([[J1 + m1 * l1 ** 2 / 4 + m2 * l1 ** 2 + a22 + 2 * c * mpmath.cos(q2),
                            a22 + c * mpmath.cos(q2)],
                           [a22 + c * mpmath.cos(q2), a22]])
        h = mpmath.matrix([-c * mpmath.sin(q2) * (2 * u1 * u2 + u2 ** 2),
                           c * mpmath.sin(q2) * u1 ** 2])
        tau = mpmath.matrix([-g * (m1 * l1 / 2 * mpmath.cos(q1) + m2 * l1 * mpmath.cos(q1)
                                   + m2 * l2 / 2 * mpmath.cos(q1 + q2)),
                             -g * m2 * l2 / 2 * mpmath.cos(q1 + q2)])
        qdd = mpmath.lu_solve(A, tau - h)
        return np.array([float(qdd[0]), float(qdd[1])])


def stiff_pair_matrix(m1, m2, k1, k, c) -> np.ndarray:
    """State matrix of the stiff pair about its equilibrium (x1, x2) = (1, 2)."""
    M_inv = np.diag([1.0 / m1, 1.0 / m2])
    K = np.array([[k1 + k, -k], [-k, k]])
    D = np.array([[c, -c], [-c, c]])
    return np.block([[np.zeros((2, 2)), np.eye(2)], [-M_inv @ K, -M_inv @ D]])
