"""Symbolic queries on a model: the seed's System methods, in closed form.

The seed library answers questions such as "the angular velocity of B2
relative to B1 in components of B3" or "the vector from P to Q in base B".
:class:`Mechanism` answers them as sympy expressions in the coordinates
(``q1``), speeds (``q1_dot``), accelerations (``q1_ddot``) and parameters.

Results are closed forms obtained by expanding the named intermediates, so
they are meant for inspection, documentation and tests on small models; the
generated C never expands them.

>>> from modelgen.model.api import load_model                       # doctest: +SKIP
>>> m = Mechanism(load_model("models/double_pendulum.yaml"))     # doctest: +SKIP
>>> m.angular_velocity("E", "B2", "B2")                          # doctest: +SKIP
Matrix([[0], [0], [q1_dot + q2_dot]])
"""
from __future__ import annotations

import functools

import sympy

from modelgen.derive.dynamics import derive_equations
from modelgen.errors import ModelError
from modelgen.derive.spatial import add
from modelgen.derive.kinematics import derive_kinematics
from modelgen.model.api import Model
from modelgen.model.spec import ModelSpec, symbol


def acceleration_name(coordinate: str) -> str:
    """Name of the acceleration symbol of a coordinate: ``q1`` -> ``q1_ddot``."""
    return coordinate + "_ddot"


class Mechanism:
    """Closed-form kinematic and dynamic queries on a :class:`ModelSpec` (or on a
    :class:`~modelgen.model.api.Model`, whose spec it takes)."""

    def __init__(self, spec: ModelSpec | Model, simplify: bool = True):
        if isinstance(spec, Model):
            spec = spec.spec()
        if not isinstance(spec, ModelSpec):
            raise TypeError(f"Mechanism takes a ModelSpec or a Model, not "
                            f"{type(spec).__name__}: e.g. Mechanism(load_model('arm.yaml')) "
                            "or Mechanism(Model(...))")
        self.spec = spec
        self.kin = derive_kinematics(spec)
        self._simplify = simplify
        #: one acceleration per degree of freedom: ``q_ddot`` of a simple coordinate,
        #: ``<speed>_dot`` of a joint's speed
        self.qdd = tuple(symbol(acceleration_name(c)) for c in spec.simple_coordinates) + \
            tuple(symbol(s + "_dot") for j in spec.joints for s in j.speeds)

    # -- helpers ----------------------------------------------------------------
    def _final(self, expr):
        expr = self._eqs.graph.expand(expr)   # the equations' graph extends the kinematics'
        return sympy.trigsimp(sympy.expand(expr)) if self._simplify else expr

    def _matrix(self, rows):
        return sympy.Matrix([[self._final(e) for e in row] for row in rows])

    def _column(self, vec):
        return sympy.Matrix([self._final(e) for e in vec])

    def _base(self, name):
        try:
            return self.kin.bases[name]
        except KeyError:
            raise ModelError(f"unknown base {name!r}", key="base",
                             fix=f"use one of {', '.join(sorted(self.kin.bases))}") from None

    def _point(self, name):
        try:
            return self.kin.points[name]
        except KeyError:
            raise ModelError(f"unknown point {name!r}", key="point",
                             fix=f"use one of {', '.join(sorted(self.kin.points))}") from None

    def _body(self, name):
        for i, b in enumerate(self.spec.bodies):
            if b.name == name:
                return i, b
        raise ModelError(f"unknown body {name!r}", key="body",
                         fix=f"use one of {', '.join(b.name for b in self.spec.bodies)}")

    def _in_base(self, vec_E, base):
        R = sympy.Matrix(self._base(base).R)
        return R.T * sympy.Matrix(vec_E)

    @functools.cached_property
    def _eqs(self):
        return derive_equations(self.kin)

    # -- the seed's queries -------------------------------------------------------
    def change_of_basis(self, base_from: str, base_to: str) -> sympy.Matrix:
        """Matrix M with ``v_to = M v_from`` (components of one vector in two bases).

        Column j of M is ``base_from``'s j-th unit vector in components of
        ``base_to``: the seed's ``Change_Basis_Matrix(Base_1, Base_2)``, and the
        scene output ``{orientation: base_from, relative_to: base_to}``.
        """
        R1 = sympy.Matrix(self._base(base_from).R)
        R2 = sympy.Matrix(self._base(base_to).R)
        return self._matrix((R2.T * R1).tolist())

    def angular_velocity(self, base_fixed: str, base_moving: str, components: str = "E"):
        """Angular velocity of ``base_moving`` relative to ``base_fixed``, in ``components``.

        The fixed base comes first, as in the seed's ``Angular_Velocity(Base_1,
        Base_2, Base_Components)``; the scene output names the moving one first:
        ``{angular_velocity: base_moving, relative_to: base_fixed}``.  Swapping
        the two bases negates the vector.
        """
        w = [a - b for a, b in zip(self._base(base_moving).omega, self._base(base_fixed).omega,
                                   strict=True)]
        return self._column(self._in_base(w, components))

    def position(self, start: str, end: str, components: str = "E") -> sympy.Matrix:
        """Vector from point ``start`` to point ``end`` (``r_end - r_start``), in ``components``.

        The scene output names the end first: ``{position: end, from: start}``.
        """
        d = [b - a for a, b in zip(self._point(start).r, self._point(end).r, strict=True)]
        return self._column(self._in_base(d, components))

    def velocity(self, point: str, components: str = "E") -> sympy.Matrix:
        """Velocity of ``point`` relative to E, in ``components``."""
        return self._column(self._in_base(self._point(point).v, components))

    def acceleration(self, point: str, components: str = "E") -> sympy.Matrix:
        """Acceleration of ``point`` relative to E, in ``components``.

        Linear in the accelerations :attr:`qdd`: ``<q>_ddot`` of a coordinate,
        ``<speed>_dot`` of a ball or free joint's speed.
        """
        pk = self._point(point)
        a = pk.a_bias
        for k in range(self.spec.n):
            a = add(a, tuple(self.qdd[k] * x for x in self.kin.point_partial(point, k)))
        return self._column(self._in_base(a, components))

    def partial_velocities(self, body: str) -> dict:
        """The seed's virtual velocities of a body: ``{coordinate: (c_k, b_k)}`` in E.

        ``omega = sum_k c_k q_dot_k`` and ``v_G = sum_k b_k q_dot_k``; for the
        speeds of a ball or free joint the key is the speed's name.
        """
        _, b = self._body(body)
        out = {}
        for k, name in enumerate(self.spec.dof_names):
            c = self._base(b.base).partials.get(k, (0, 0, 0))
            out[name] = (self._column(c), self._column(self.kin.point_partial(b.G, k)))
        return out

    def pose(self, body: str) -> sympy.Matrix:
        """4x4 transformation matrix [[R, r_G], [0, 0, 0, 1]] of a body.

        R's columns are the body base's unit vectors in E (``v_E = R v_body``,
        ``change_of_basis(body base, "E")``); r_G is the centre of mass from O in E.
        """
        i, _ = self._body(body)
        return self._matrix([self._eqs.poses[i][4 * r:4 * r + 4] for r in range(4)])

    def kinetic_energy(self):
        """Kinetic energy of the bodies relative to E."""
        return self._final(self._eqs.kinetic)

    def potential_energy(self):
        """Potential energy: gravity's (zero at O) plus the conservative effects'
        (springs between points and on coordinates, gravity fields constant in E),
        as ``CompiledModel.energy`` returns it."""
        return self._final(self._eqs.potential)

    def mass_matrix(self) -> sympy.Matrix:
        return self._matrix(self._eqs.A)

    def velocity_terms(self) -> sympy.Matrix:
        """h with A q_ddot = tau - h (the seed's "dA/dt q_dot" term, done right)."""
        return self._column(self._eqs.h)

    def generalized_forces(self) -> sympy.Matrix:
        return self._column(self._eqs.tau)
