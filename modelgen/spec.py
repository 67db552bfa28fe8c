"""The validated model specification: plain, immutable data.

This is what the loader (:mod:`modelgen.model`) produces from YAML or from the
Python API, and what every later stage consumes.  Nothing here parses or
validates; by the time a :class:`ModelSpec` exists it is known to be valid:

* names are unique C identifiers that are not reserved words;
* every base, point and body reference resolves, and the tuples below are in
  topological order (a parent always comes before its children);
* every expression is a sympy expression whose free symbols are declared
  coordinates, speeds, parameters, inputs or ``t`` (see :func:`symbol`).

Conventions, fixed for every stage:

* ``E`` is the canonical (inertial) base and ``O`` the canonical point.
* A base is obtained from its parent by a right-handed rotation of ``angle``
  about the parent's axis ``axis`` (1, 2 or 3).  ``R_B`` denotes the matrix
  whose columns are the unit vectors of B in components of E, so that
  ``v_E = R_B @ v_B``.
* A point is ``r_P = r_parent + R_base @ coordinates``.
* Inertia tensors are about the body's centre of mass G, in components of the
  body's base.
* The speed of coordinate ``q`` is the symbol ``q_dot`` (:func:`speed_name`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import sympy

#: Name of the canonical base and the canonical point.
CANONICAL_BASE = "E"
CANONICAL_POINT = "O"

#: The time symbol.
TIME = sympy.Symbol("t")

Expr = sympy.Expr
Vec3 = tuple  # tuple[Expr, Expr, Expr]


def symbol(name: str) -> sympy.Symbol:
    """The sympy symbol modelgen uses for a coordinate, speed, parameter or input.

    >>> symbol("q1")
    q1
    """
    return sympy.Symbol(name)


def speed_name(coordinate: str) -> str:
    """Name of the speed of a generalized coordinate.

    >>> speed_name("q1")
    'q1_dot'
    """
    return coordinate + "_dot"


@dataclass(frozen=True)
class BaseSpec:
    """A base rotated from ``parent`` by ``angle`` about the parent's axis ``axis``."""
    name: str
    parent: str
    axis: int          # 1, 2 or 3
    angle: Expr


@dataclass(frozen=True)
class PointSpec:
    """A point at ``coordinates`` (components in ``base``) from point ``parent``."""
    name: str
    parent: str        # a point name; "O" for absolute points
    base: str          # a base name; "E" for absolute points
    coordinates: Vec3


@dataclass(frozen=True)
class FrameSpec:
    """A named coordinate system: a point and a base."""
    name: str
    point: str
    base: str


@dataclass(frozen=True)
class BodySpec:
    """A rigid body: mass, centre of mass point ``G``, attached base and inertia.

    ``inertia`` is the full symmetric 3x3 tensor about G in components of
    ``base`` (a tuple of three row tuples).  All zeros means a particle.
    """
    name: str
    mass: Expr
    G: str
    base: str
    inertia: tuple     # ((Ixx, Ixy, Ixz), (Ixy, Iyy, Iyz), (Ixz, Iyz, Izz))


@dataclass(frozen=True)
class ActionSpec:
    """The seed's Action: a torque and a force acting on ``body``.

    The force acts at ``point``; both have components in ``base``.  The
    action is transported to the body (moment about G = torque + GP x force)
    so its virtual power uses the body's velocity field, which is what the
    seed's ``Get_Action_in_G`` does.
    """
    name: str
    body: str
    point: str
    base: str
    torque: Vec3
    force: Vec3


@dataclass(frozen=True)
class ModelSpec:
    """A complete, validated model."""
    name: str
    description: str = ""
    coordinates: tuple = ()            # tuple[str, ...]
    parameters: tuple = ()             # tuple[tuple[str, float], ...], declaration order
    inputs: tuple = ()                 # tuple[str, ...]
    bases: tuple = ()                  # tuple[BaseSpec, ...], parents first
    points: tuple = ()                 # tuple[PointSpec, ...], parents first
    frames: tuple = ()                 # tuple[FrameSpec, ...]
    bodies: tuple = ()                 # tuple[BodySpec, ...]
    gravity: Optional[Vec3] = None     # components in E, acting at every G
    actions: tuple = ()                # tuple[ActionSpec, ...]
    #: where the spec came from (file path or None) -- for error messages only
    source: Optional[str] = field(default=None, compare=False)
    #: (dotted key, line) pairs for error messages from later stages
    lines: tuple = field(default=(), compare=False)

    # -- convenience -------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of generalized coordinates."""
        return len(self.coordinates)

    @property
    def parameter_names(self) -> tuple:
        return tuple(name for name, _ in self.parameters)

    @property
    def parameter_defaults(self) -> tuple:
        return tuple(float(value) for _, value in self.parameters)

    @property
    def speeds(self) -> tuple:
        return tuple(speed_name(c) for c in self.coordinates)

    def line_of(self, key: str) -> Optional[int]:
        """Line of a dotted key in the source file, if known."""
        for k, line in self.lines:
            if k == key:
                return line
        return None
