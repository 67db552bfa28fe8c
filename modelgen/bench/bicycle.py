"""The Whipple bicycle benchmark (Meijaard, Papadopoulos, Ruina and Schwab 2007,
Proc. R. Soc. A 463) on ``models/whipple_bicycle.yaml``: the lean and steer
eigenvalues about upright straight running from ``cm.linearize``, and the
weave and capsize speeds that bound the self-stable range.

Input: a compiled bicycle built with ``linearize=True`` and optional parameter
values (a dict, as ``cm.params`` takes).  Output: numpy arrays and floats.

>>> cm = modelgen.load("models/whipple_bicycle.yaml", linearize=True)   # doctest: +SKIP
>>> lean_steer_eigenvalues(cm, 5.0)                                     # doctest: +SKIP
array([-14.07838969+0.j, -0.77534188-4.46486771j, -0.77534188+4.46486771j, -0.32286643+0.j])
>>> stability_speeds(cm)                                                # doctest: +SKIP
(4.292382536341..., 6.024262015388...)
"""
from __future__ import annotations

import numpy as np

__all__ = ["CAPSIZE_SPEED", "LEAN_STEER", "TABLE_2", "WEAVE_SPEED", "lean_steer_block", "lean_steer_eigenvalues", "stability_speeds",
           "upright_state"]

#: Table 2 of the paper (published values, not computed here): the lean and steer
#: eigenvalues at v = 0, 1, ..., 10 m/s to 15 significant digits: the weave pair
#: (two real ones at low speed), capsize and castering
TABLE_2 = {
    0: [5.53094371765393, 3.13164324790656, -3.13164324790656, -5.53094371765393],
    1: [3.52696170990070 + 0.80774027519930j, 3.52696170990070 - 0.80774027519930j,
        -3.13423125066578, -7.11008014637442],
    2: [2.68234517512745 + 1.68066296590675j, 2.68234517512745 - 1.68066296590675j,
        -3.07158645641514, -8.67387984831735],
    3: [1.70675605663975 + 2.31582447384325j, 1.70675605663975 - 2.31582447384325j,
        -2.63366137253667, -10.3510146724592],
    4: [0.41325331521125 + 3.07910818603206j, 0.41325331521125 - 3.07910818603206j,
        -1.42944427361326, -12.1586142657645],
    5: [-0.77534188219585 + 4.46486771378823j, -0.77534188219585 - 4.46486771378823j,
        -0.32286642900409, -14.0783896927982],
    6: [-1.52644486584142 + 5.87673060598709j, -1.52644486584142 - 5.87673060598709j,
        -0.00406690076970, -16.0853712309803],
    7: [-2.13875644258362 + 7.19525913329805j, -2.13875644258362 - 7.19525913329805j,
        0.10268170574766, -18.1578846612526],
    8: [-2.69348683581097 + 8.46037971396931j, -2.69348683581097 - 8.46037971396931j,
        0.14327879765713, -20.2794089439457],
    9: [-3.21675402252485 + 9.69377351531791j, -3.21675402252485 - 9.69377351531791j,
        0.15790184030917, -22.4378855904086],
    10: [-3.72016840437287 + 10.9068113947629j, -3.72016840437287 - 10.9068113947629j,
         0.16105338653172, -24.6245963501740],
}
#: the weave and capsize speeds of the paper's section 5 [m/s]
WEAVE_SPEED, CAPSIZE_SPEED = 4.29238253634111, 6.02426201538837

#: the states of the lean and steer block of the minimal linearization
LEAN_STEER = ("roll", "steer", "roll_dot", "steer_dot")


def upright_state(cm, v: float, p=None) -> np.ndarray:
    """Upright straight running at forward speed ``v`` [m/s]: every angle zero, the
    rear wheel's centre at its radius (assembled), the rear wheel turning at -v/rR
    (forward, in the model's axes) and the dependent speeds consistent."""
    p_vec = cm.params(p)
    rR = p_vec[list(cm.parameters).index("rR")]
    q = np.zeros(cm.n)
    q[cm.coordinates.index("z")] = rR
    q = cm.assemble(q, keep=[c for c in cm.coordinates if c not in ("z", "pitch")], p=p)
    qd = np.zeros(cm.n)
    qd[cm.speeds.index("thR_dot")] = -v / rR
    return np.concatenate([q, cm.consistent_speeds(q, qd, p)])


def lean_steer_block(cm, v: float, p=None) -> np.ndarray:
    """The 4 x 4 block of ``cm.linearize``'s minimal A in (roll, steer, roll_dot,
    steer_dot); about upright straight running it is decoupled from the other states
    (the yaw, the position and the wheels' angles are cyclic, the speed constant)."""
    lin = cm.linearize(upright_state(cm, v, p), p=p)
    i = [lin.states.index(s) for s in LEAN_STEER]
    return lin.A[np.ix_(i, i)]


def lean_steer_eigenvalues(cm, v: float, p=None) -> np.ndarray:
    """The four lean and steer eigenvalues at speed ``v``, sorted by real then
    imaginary part."""
    return np.sort_complex(np.linalg.eigvals(lean_steer_block(cm, v, p)).astype(complex))


def _largest_real_part(cm, v, p) -> float:
    return float(np.max(lean_steer_eigenvalues(cm, v, p).real))


def stability_speeds(cm, p=None, v_max: float = 10.0, grid: int = 101,
                     tol: float = 1e-12) -> tuple:
    """(weave speed, capsize speed): where the largest real part of the lean and steer
    eigenvalues changes sign on [0, ``v_max``], from positive to negative (the weave
    pair becoming stable) and back (the capsize mode becoming unstable), each found by
    bisection to ``tol`` [m/s] from a bracket of a ``grid``-point scan.  None for a
    crossing that does not happen."""
    speeds = np.linspace(0.0, v_max, grid)
    signs = [_largest_real_part(cm, v, p) > 0 for v in speeds]
    weave = capsize = None
    for k in range(grid - 1):
        if signs[k] == signs[k + 1]:
            continue
        lo, hi = speeds[k], speeds[k + 1]
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            if (_largest_real_part(cm, mid, p) > 0) == signs[k]:
                lo = mid
            else:
                hi = mid
        root = 0.5 * (lo + hi)
        if signs[k] and weave is None:
            weave = root
        elif not signs[k] and capsize is None:
            capsize = root
    return weave, capsize
