"""The energy balance of a non-conservative run: the work of each effect.

A scene records the power ``P_k = tau_k . q_dot`` of every effect k whose
energy the total energy E leaves out (damping, friction, drag, actions), as a
``power`` output the C evaluates on the integrator's dense output.  The work
``W_k(t) = integral of P_k from t0 to t`` is summed here, and the balance

    E(t) - E(0) - sum_k W_k(t)

is zero for the exact motion: what is left is the integration error plus the
quadrature error.

Quadrature: 5-point Gauss-Lobatto on every sample interval (the two samples and
three nodes inside, which the scene adds to its ``t_eval``), exact for
polynomials of degree 7; its error on an interval of length h is
``7.0e-10 h^9 |P^(8)|`` (Abramowitz & Stegun 25.4.32), about 1e-16 relative for
h = 0.01 s and motions of 10 rad/s.  ``quadrature_check`` is the largest
difference to Simpson's rule on the same interval (the samples and the middle
node, error ``h^5 |P^(4)| / 2880``): an estimate that exceeds the Lobatto error
by orders of magnitude, so a small check means a resolved power.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["NODES", "UNRESOLVED", "quadrature_times", "EnergyBalance", "energy_balance"]

#: 5-point Gauss-Lobatto nodes and weights on [0, 1] (the ends are the samples)
NODES = (1.0 + np.array([-1.0, -np.sqrt(3.0 / 7.0), 0.0, np.sqrt(3.0 / 7.0), 1.0])) / 2.0
WEIGHTS = np.array([1.0 / 10.0, 49.0 / 90.0, 32.0 / 45.0, 49.0 / 90.0, 1.0 / 10.0]) / 2.0
#: rows per sample interval (a sample and the inner nodes)
PER = len(NODES) - 1
#: ``EnergyBalance.unresolved`` above which an interval spans half a period or more
#: of a power's fastest change (h w > pi): its quadrature error is then about as
#: large as ``quadrature_check``
UNRESOLVED = np.pi ** 4 / 2880


def quadrature_times(times) -> np.ndarray:
    """The sample ``times`` with the 3 inner Lobatto nodes of each interval between
    them: sample j is row ``PER * j``.

    >>> quadrature_times([0.0, 1.0]).round(4).tolist()
    [0.0, 0.1727, 0.5, 0.8273, 1.0]
    """
    times = np.asarray(times, dtype=float)
    inner = times[:-1, None] + np.diff(times)[:, None] * NODES[None, :-1]
    return np.concatenate([inner.ravel(), times[-1:]])


class EnergyBalance(NamedTuple):
    """The energy balance of a run at its samples."""
    work: dict               # effect -> W_k at each sample [J]
    error: np.ndarray        # E - E(0) - sum_k W_k at each sample [J]
    quadrature_check: float  # largest |Lobatto - Simpson| of the summed work over an interval [J]
    #: the largest |Lobatto - Simpson| of an interval against h max|P| there: about
    #: (h w)^4 / 2880 for a power of frequency w that the samples resolve (h w < 1),
    #: of order 0.1 where they do not (a stiff damper between 0.01 s samples), and
    #: then the quadrature's error is of the check's size, not far below it
    unresolved: float = 0.0


def energy_balance(grid, total_energy, powers: dict) -> EnergyBalance:
    """The work of each effect and the balance error at the samples.

    ``grid``: the times of :func:`quadrature_times` a run reached (it may stop
    early); ``powers``: effect -> P_k on ``grid``; ``total_energy``: E at the
    samples (rows ``0, PER, 2 PER...`` of ``grid``).

    >>> b = energy_balance(grid, E, {"damping": P})          # doctest: +SKIP
    >>> abs(b.error).max()                                   # doctest: +SKIP
    """
    grid = np.asarray(grid, dtype=float)
    m = (len(grid) - 1) // PER                      # complete intervals
    h = grid[PER:PER * m + 1:PER] - grid[:PER * (m - 1) + 1:PER] if m else np.zeros(0)
    work, check, size = {}, np.zeros(m), np.zeros(m)
    for name, P in powers.items():
        P = np.asarray(P, dtype=float)
        nodes = np.stack([P[k:PER * m + k:PER] for k in range(PER)] + [P[PER:PER * m + 1:PER]],
                         axis=1) if m else np.zeros((0, len(NODES)))
        pieces = h * (nodes @ WEIGHTS)
        simpson = h * (nodes[:, 0] + 4.0 * nodes[:, 2] + nodes[:, -1]) / 6.0
        check += pieces - simpson
        size += h * np.max(np.abs(nodes), axis=1, initial=0.0)
        work[name] = np.concatenate([[0.0], np.cumsum(pieces)])
    E = np.asarray(total_energy, dtype=float)[:m + 1]
    error = E - E[0] - sum(work.values(), np.zeros(m + 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(size > 0, np.abs(check) / size, 0.0)
    return EnergyBalance(work, error, float(np.max(np.abs(check), initial=0.0)),
                         float(np.max(ratio, initial=0.0)))
