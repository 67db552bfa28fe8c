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

__all__ = ["LEAN_STEER", "lean_steer_block", "lean_steer_eigenvalues", "stability_speeds",
           "upright_state"]

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
