"""Parametric benchmark models built with the Python API."""
from __future__ import annotations

import numbers

from modelgen.errors import ModelError
from modelgen.model.api import Model
from modelgen.model.messages import API_FILE

__all__ = ["spatial_chain"]


def spatial_chain(n: int) -> Model:
    """An n-link spatial chain of uniform rods (cylinders), hanging from O.

    The definition, exactly (a MuJoCo benchmark rebuilds it in MJCF):

    * model name ``spatial_chain_<n>``;
    * coordinates ``q1 .. qn`` (all angles zero: the chain is straight along
      the x axis of E);
    * parameters, in this order: ``m1 .. mn`` (default 1.0 kg), ``l1 .. ln``
      (default 0.5 m), ``r`` (rod radius, 0.02 m), ``g`` (9.81 m/s^2);
    * bases ``B1 .. Bn``: ``Bi`` is ``B(i-1)`` rotated by ``qi`` about its
      axis 3 (z) if i is odd and axis 2 (y) if i is even, with ``B0 = E``;
    * points: ``P0 = O`` and the joints ``Pi = P(i-1) + R_Bi [li, 0, 0]``
      (``Pn`` is the free tip); centres of mass
      ``Gi = P(i-1) + R_Bi [li/2, 0, 0]``;
    * bodies ``rod1 .. rodn``: mass ``mi``, centre ``Gi``, base ``Bi``, inertia
      about ``Gi`` in ``Bi`` = diag(``mi*r**2/2``, ``mi*li**2/12 + mi*r**2/4``,
      ``mi*li**2/12 + mi*r**2/4``) (a solid cylinder of radius r along x);
    * gravity ``[0, 0, -g]`` in E; no inputs, no actions.

    Joint i (angle ``qi``) is thus located at ``P(i-1)``, with its axis the
    z (odd i) or y (even i) axis of ``B(i-1)``, which is also that axis of
    ``Bi``.

    >>> spec = spatial_chain(3).spec()
    >>> [(b.name, b.parent, b.axis) for b in spec.bases]
    [('B1', 'E', 3), ('B2', 'B1', 2), ('B3', 'B2', 3)]
    >>> p = spec.points[1]; p.name, p.parent, p.base, p.coordinates
    ('G1', 'O', 'B1', (l1/2, 0, 0))
    """
    if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
        raise ModelError(f"the number of links must be a positive integer but is {n!r}",
                         file=API_FILE, key="n", fix="pass n >= 1")
    n = int(n)
    m = Model(f"spatial_chain_{n}",
              description=f"Spatial chain of {n} uniform rods; joint axes alternate z, y.")
    m.add_coordinates(*(f"q{i}" for i in range(1, n + 1)))
    m.add_parameters({f"m{i}": 1.0 for i in range(1, n + 1)})
    m.add_parameters({f"l{i}": 0.5 for i in range(1, n + 1)})
    m.add_parameters({"r": 0.02, "g": 9.81})
    previous_base, previous_point = "E", "O"
    for i in range(1, n + 1):
        base = f"B{i}"
        m.add_base(base, parent=previous_base, axis=3 if i % 2 else 2, angle=f"q{i}")
        m.add_point(f"P{i}", parent=previous_point, base=base, coordinates=[f"l{i}", 0, 0])
        m.add_point(f"G{i}", parent=previous_point, base=base,
                    coordinates=[f"l{i}/2", 0, 0])
        transverse = f"m{i}*l{i}**2/12 + m{i}*r**2/4"
        m.add_body(f"rod{i}", mass=f"m{i}", G=f"G{i}", base=base,
                   inertia=[f"m{i}*r**2/2", transverse, transverse])
        previous_base, previous_point = base, f"P{i}"
    m.set_gravity([0, 0, "-g"])
    return m
