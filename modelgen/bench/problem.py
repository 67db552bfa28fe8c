"""A work-precision problem and its reference solution (plain data), and the settings to sweep.

A :class:`Problem` is one initial value problem of a compiled model: the
initial state, the time span, the fixed grid ``t_eval`` on which every method
returns its solution, the tolerances and step sizes to sweep, and a
:class:`Reference` (the positions on that grid, and how far the reference
itself can be trusted).

>>> [f"{tol:.3g}" for tol in tolerance_sweep(1e-3, 1e-4)]
['0.001', '0.000316', '0.0001']
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: grid points of the dense error
GRID_POINTS = 201
#: errors below FLOOR_FACTOR x the reference's own disagreement are not resolved
FLOOR_FACTOR = 100.0


@dataclass(frozen=True)
class Reference:
    """The reference positions ``q`` (len(t), n) on the grid ``t``.

    ``spread_final`` / ``spread_l2`` bound the reference's own error in the two
    measures: the disagreement of the two methods that made it, or the
    rounding of a closed form.  ``how`` says how it was made.

    >>> ref = Reference(np.zeros(2), np.zeros((2, 1)), "zeros", 1e-16, 1e-16)
    >>> ref.floor("final")
    1e-14
    """
    t: np.ndarray
    q: np.ndarray
    how: str
    spread_final: float
    spread_l2: float

    def floor(self, measure: str) -> float:
        """The smallest error this reference resolves (FLOOR_FACTOR x its spread)."""
        spread = self.spread_final if measure == "final" else self.spread_l2
        return FLOOR_FACTOR * max(spread, 1e-300)


@dataclass(frozen=True)
class Problem:
    """One initial value problem of a compiled model, with its reference.

    ``steps`` maps a fixed-step method's name (``"rk4"``) or ``"*"`` to the
    step sizes to sweep (each divides the grid spacing).
    """
    name: str
    title: str
    model: Any                        # CompiledModel
    x0: np.ndarray
    t_span: tuple
    t_eval: np.ndarray
    reference: Reference | None = None
    u: Any = None
    p: Any = None
    tolerances: tuple = ()
    steps: dict = field(default_factory=dict)
    notes: tuple = ()

    @property
    def n(self) -> int:
        return self.model.n

    def steps_for(self, method) -> tuple:
        """The step sizes of a fixed-step method (by its ``name``, else ``"*"``)."""
        key = getattr(method, "name", None)
        return tuple(self.steps.get(key, self.steps.get("*", ())))


def grid(t0: float, t1: float, points: int = GRID_POINTS) -> np.ndarray:
    """The uniform grid of the dense error.

    >>> grid(0.0, 1.0, 5)
    array([0.  , 0.25, 0.5 , 0.75, 1.  ])
    """
    return np.linspace(t0, t1, points)


def tolerance_sweep(loosest: float, tightest: float, per_decade: int = 2) -> tuple:
    """Tolerances from ``loosest`` down to ``tightest``, ``per_decade`` per decade.

    >>> [f"{tol:.3g}" for tol in tolerance_sweep(1e-3, 1e-5)]
    ['0.001', '0.000316', '0.0001', '3.16e-05', '1e-05']
    """
    a, b = math.log10(loosest), math.log10(tightest)
    count = int(round((a - b) * per_decade))
    return tuple(float(10 ** (a - k / per_decade)) for k in range(count + 1))


def steps_dividing(spacing: float, fewest: float, most: float, per_decade: int = 4) -> tuple:
    """Step sizes ``spacing / m`` for integers m from ``fewest`` to ``most`` steps
    per grid interval, about ``per_decade`` per decade, largest step first.

    >>> steps_dividing(0.1, 1, 10, per_decade=2)
    (0.1, 0.03333333333333333, 0.01)
    """
    lo, hi = math.log10(max(fewest, 1)), math.log10(most)
    count = max(int(round((hi - lo) * per_decade)), 0)
    ms = sorted({max(1, int(round(10 ** (lo + k * (hi - lo) / max(count, 1)))))
                 for k in range(count + 1)})
    return tuple(spacing / m for m in ms)
