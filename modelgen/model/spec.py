"""The validated model specification: plain, immutable data.

This is what the loaders (:mod:`modelgen.model.api`) produce from YAML or from the
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

from dataclasses import MISSING, dataclass, field, fields
from typing import ClassVar, Optional

import sympy

from modelgen.model.records import InputSignal, OutputSpec  # noqa: F401 (re-exported)

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
    """A base rotated from ``parent`` by ``angle`` about the parent's axis ``axis``.

    A base made by a ball or free joint (:class:`JointSpec`) has ``axis`` 0 and
    ``angle`` 0 instead: it is turned from ``parent`` by the unit quaternion
    ``quaternion`` (symbols w, x, y, z) and turns relative to ``parent`` with the
    angular velocity ``rates`` (symbols, components in this base).
    """
    name: str
    parent: str
    axis: int          # 1, 2 or 3; 0 for a joint's quaternion base
    angle: Expr
    quaternion: tuple = ()
    rates: tuple = ()


@dataclass(frozen=True)
class PointSpec:
    """A point at ``coordinates`` (components in ``base``) from point ``parent``.

    A free joint's point (:class:`JointSpec`) has the joint's position symbols as
    ``coordinates`` and moves relative to ``parent`` and ``base`` with the
    velocity ``speeds`` (symbols) in components of ``speed_base``, the joint's
    own base.
    """
    name: str
    parent: str        # a point name; "O" for absolute points
    base: str          # a base name; "E" for absolute points
    coordinates: Vec3
    speeds: tuple = ()
    speed_base: str = ""


#: Joint kinds with a quaternion: configuration names and speed names after the
#: joint's name (``<joint>_<suffix>``).  A free joint's speeds are Pinocchio's
#: free-flyer's: the linear velocity of its point, then the angular velocity,
#: both in components of the joint's own base.
JOINT_KINDS = {
    "ball": (("qw", "qx", "qy", "qz"), ("wx", "wy", "wz")),
    "free": (("x", "y", "z", "qw", "qx", "qy", "qz"), ("vx", "vy", "vz", "wx", "wy", "wz")),
}


@dataclass(frozen=True)
class JointSpec:
    """A ball or free joint: the one place where coordinates and speeds differ.

    It makes base ``base``, turned from base ``parent`` by a unit quaternion
    (w, x, y, z: scalar first), and for a free joint also point ``point`` at
    position (x, y, z) from point ``origin``, in components of ``parent``.
    ``coordinates`` and ``speeds`` are the names of :data:`JOINT_KINDS`; the
    kinematic relation is ``d(quaternion)/dt = quaternion * (0, w) / 2`` and
    ``d(position)/dt = R v`` (R: the quaternion's rotation matrix).
    """
    name: str
    kind: str             # "ball" | "free"
    parent: str           # the parent base
    base: str             # the base the joint makes
    origin: str           # free: the parent point; ball: ""
    point: str            # free: the point the joint makes; ball: ""
    coordinates: tuple    # names, JOINT_KINDS order
    speeds: tuple         # names, JOINT_KINDS order

    @property
    def quaternion(self) -> tuple:
        """The names of the quaternion's w, x, y, z."""
        return self.coordinates[-4:]


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
    kind = "action"
    roles: ClassVar[dict] = {"body": "body", "point": "point", "base": "base",
                             "torque": "vector", "force": "vector"}
    stiff = False
    conservative = False


# -- effects: the physical effects a scene may switch on ---------------------------
# Each contributes to the generalized forces tau and, where it has one, to the
# potential energy.  Every field below is a key of the YAML entry
# ``effects: {<name>: {type: <kind>, <field>: ...}}``; a field with a default is
# optional.  One class is the whole description of a kind, as class-level data:
#
# * ``kind``: the YAML ``type``;
# * ``roles``: how the loader reads each field (one of :data:`FIELD_ROLES`);
# * ``stiff``: the effect can make a problem stiff or non-smooth (scenes flag it);
# * ``conservative``: its forces derive from a potential (energy is conserved).
#
# Its physics is one function in :data:`modelgen.derive.effects.DERIVATIONS`.
# The registries below (EFFECT_KINDS, EFFECT_FIELD_ROLES, STIFF_KINDS,
# CONSERVATIVE_KINDS) are computed from these classes, never written out.

#: How an effect field is read: a reference to a declared ``point``, ``body``,
#: ``base`` or ``coordinate``; ``coordinates``, a list of coordinates; a
#: ``vector`` of three expressions (parameters and t); or a parameters-only
#: expression that must be ``nonnegative``, ``positive`` or may be ``signed``
#: at the parameter defaults.
FIELD_ROLES = ("point", "body", "base", "coordinate", "coordinates", "vector",
               "nonnegative", "positive", "signed")


@dataclass(frozen=True)
class GravityEffect:
    """Uniform field: force m * vector on every body at its G (vector in ``base``)."""
    name: str
    vector: Vec3
    base: str = CANONICAL_BASE
    kind = "gravity"
    roles: ClassVar[dict] = {"vector": "vector", "base": "base"}
    stiff = False
    conservative = True

    @property
    def in_energy(self) -> bool:
        """Its potential is part of the energy: only a field constant in E has one (a
        field fixed in a moving base, or one that varies in time, does work that no
        potential accounts for)."""
        return self.base == CANONICAL_BASE and time_free(self.vector)


def time_free(exprs) -> bool:
    """No expression of ``exprs`` depends on the time ``t``."""
    return not any(sympy.sympify(e).has(TIME) for e in exprs)


@dataclass(frozen=True)
class SpringEffect:
    """Linear spring between two points: tension k (l - rest_length) + preload.

    Potential: k/2 (l - rest_length)^2 + preload * l.  The force acts along
    the line between the points; its generalized force uses the points'
    partial velocities.
    """
    name: str
    point_a: str
    point_b: str
    stiffness: Expr
    rest_length: Expr
    preload: Expr = sympy.S.Zero
    kind = "spring"
    roles: ClassVar[dict] = {"point_a": "point", "point_b": "point",
                             "stiffness": "nonnegative", "rest_length": "nonnegative",
                             "preload": "signed"}
    stiff = True
    conservative = True


@dataclass(frozen=True)
class TorsionSpringEffect:
    """Torque -k (q - rest_angle) on one coordinate; potential k/2 (q - rest)^2."""
    name: str
    coordinate: str
    stiffness: Expr
    rest_angle: Expr = sympy.S.Zero
    kind = "torsion_spring"
    roles: ClassVar[dict] = {"coordinate": "coordinate", "stiffness": "nonnegative",
                             "rest_angle": "signed"}
    stiff = True
    conservative = True


@dataclass(frozen=True)
class DamperEffect:
    """Linear damper between two points: tension c * dl/dt along the line."""
    name: str
    point_a: str
    point_b: str
    damping: Expr
    kind = "damper"
    roles: ClassVar[dict] = {"point_a": "point", "point_b": "point",
                             "damping": "nonnegative"}
    stiff = False
    conservative = False


@dataclass(frozen=True)
class JointDampingEffect:
    """Viscous damping -c q_dot on each listed coordinate (or -c v on a listed
    ball/free joint speed)."""
    name: str
    coordinates: tuple
    damping: Expr
    kind = "joint_damping"
    roles: ClassVar[dict] = {"coordinates": "coordinates", "damping": "nonnegative"}
    stiff = False
    conservative = False


@dataclass(frozen=True)
class FrictionEffect:
    """Coulomb + viscous + Stribeck friction on one coordinate, regularised.

    ``tau = -(coulomb + (static - coulomb) exp(-(v/stribeck_speed)^2))
    * tanh(v / smoothing_speed) - viscous * v`` with v the coordinate's speed.
    ``smoothing_speed`` sets the width of the smooth transition through v = 0
    (exact stick/slip needs event handling in the integrators).
    """
    name: str
    coordinate: str
    coulomb: Expr
    viscous: Expr = sympy.S.Zero
    static: Expr | None = None           # None: same as coulomb (no Stribeck peak)
    stribeck_speed: Expr = sympy.S.One
    smoothing_speed: Expr = sympy.Rational(1, 1000)
    kind = "friction"
    roles: ClassVar[dict] = {"coordinate": "coordinate", "coulomb": "nonnegative",
                             "viscous": "nonnegative", "static": "nonnegative",
                             "stribeck_speed": "positive", "smoothing_speed": "positive"}
    stiff = True
    conservative = False


@dataclass(frozen=True)
class DragEffect:
    """Quadratic drag on ``body`` at ``point``: F = -1/2 rho Cd A |v| v.

    v is the velocity of the body-fixed point at ``point`` relative to still
    air; the force acts on the body at that point.
    """
    name: str
    body: str
    point: str
    density: Expr
    drag_coefficient: Expr
    area: Expr
    kind = "drag"
    roles: ClassVar[dict] = {"body": "body", "point": "point", "density": "nonnegative",
                             "drag_coefficient": "nonnegative", "area": "nonnegative"}
    stiff = False
    conservative = False


#: The effect classes, in the order their types are listed in messages.
EFFECT_TYPES = (GravityEffect, SpringEffect, TorsionSpringEffect, DamperEffect,
                JointDampingEffect, FrictionEffect, DragEffect)
#: Effect ``type`` -> the spec class it builds (``action`` builds an ActionSpec).
EFFECT_KINDS = {**{cls.kind: cls for cls in EFFECT_TYPES}, "action": ActionSpec}
#: Field -> role over every effect kind (a field has the same role in every kind).
EFFECT_FIELD_ROLES = {name: role for cls in EFFECT_KINDS.values()
                      for name, role in cls.roles.items()}
#: Effect kinds that can make a problem stiff or non-smooth: scenes flag them.
STIFF_KINDS = tuple(kind for kind, cls in EFFECT_KINDS.items() if cls.stiff)
#: Effect kinds whose forces derive from a potential (energy is then conserved).
CONSERVATIVE_KINDS = tuple(kind for kind, cls in EFFECT_KINDS.items() if cls.conservative)


def effect_fields(effect) -> dict:
    """The fields of an effect spec that differ from the dataclass defaults (not ``name``).

    >>> effect_fields(TorsionSpringEffect("s", "q", sympy.Symbol("k")))
    {'coordinate': 'q', 'stiffness': k}
    """
    given = {}
    for f in fields(effect):
        value = getattr(effect, f.name)
        if f.name == "name" or (f.default is not MISSING and value == f.default):
            continue
        given[f.name] = value
    return given


#: Constraint kinds and the equations each gives: ``coincide`` (two points
#: coincide along chosen axes of a base: one position equation per axis),
#: ``position`` (a scalar f(q) = 0), ``velocity`` (the components along chosen
#: axes of a base of a point's velocity are zero; with ``body``, the velocity of
#: the body's material point at the point, as for rolling without slip) and
#: ``speeds`` (a scalar expression linear in the speeds is zero).  The first two
#: are holonomic, the last two nonholonomic.  ``rolling`` is a knife-edge wheel
#: (a body, the axis of its base that is its axle, its radius) on the plane
#: normal to an axis of E at a height: one position equation (the wheel touches
#: the plane) and two velocity ones (its contact point does not slip).
CONSTRAINT_KINDS = ("coincide", "position", "velocity", "speeds", "rolling")
HOLONOMIC_KINDS = ("coincide", "position")


@dataclass(frozen=True)
class ConstraintSpec:
    """One named constraint: ``kind`` (one of :data:`CONSTRAINT_KINDS`) and its fields.

    ``coincide``: points ``point_a``, ``point_b``, base ``base``, ``axes``
    (1, 2, 3); ``position``: ``expression`` of coordinates and parameters;
    ``velocity``: ``point``, optional ``body``, ``base``, ``axes``; ``speeds``:
    ``expression`` linear and homogeneous in the speeds.  Unused fields are
    empty.
    """
    name: str
    kind: str
    point_a: str = ""
    point_b: str = ""
    point: str = ""
    body: str = ""
    base: str = ""
    axes: tuple = ()
    expression: Optional[Expr] = None
    #: ``rolling``: the axle (axis 1-3 of the body's base), the radius, the plane's
    #: normal (axis 1-3 of E, pointing away from the ground) and its height
    axle: int = 0
    radius: Optional[Expr] = None
    normal: int = 0
    height: Optional[Expr] = None

    @property
    def holonomic(self) -> bool:
        """Whether every equation of it is a position constraint."""
        return self.kind in HOLONOMIC_KINDS

    @property
    def size(self) -> int:
        """Number of scalar equations."""
        if self.kind == "rolling":
            return 3
        return len(self.axes) if self.axes else 1

    @property
    def holonomic_size(self) -> int:
        """Number of its position equations."""
        return self.size if self.holonomic else (1 if self.kind == "rolling" else 0)


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
    effects: tuple = ()                # tuple of the effect dataclasses above
    #: ball and free joints (JointSpec); their coordinates and speeds come after
    #: the simple coordinates, in joint order
    joints: tuple = ()
    #: ((name, unit), ...): units of coordinates, parameters and inputs, for people
    #: and for exports (an FMU's variables); they never change the equations
    units: tuple = ()
    #: ((degree of freedom, expression), ...) in dof order, non-zero entries only:
    #: reflected rotor inertia added to that dof's diagonal entry of A (MuJoCo's
    #: ``dof_armature``); a dof is a simple coordinate or a ball/free joint's speed.
    #: Left out of the repr (the C's hash) while empty, so models without it keep
    #: their hash; :func:`modelgen.codegen.pipeline.model_hash` adds it when given
    armature: tuple = field(default=(), repr=False)
    #: False when the bodies' inertias are taken as given, without the rigid-body
    #: checks (a URDF imported with ``inertia="as_is"``, as Pinocchio reads it)
    #: (left out of the repr like ``armature``: the model hash adds it when False)
    physical_inertia: bool = field(default=True, repr=False)
    #: constraints (ConstraintSpec), and the coordinates and speeds they make
    #: dependent (names): as many speeds as constraint equations, as many
    #: coordinates as holonomic ones
    constraints: tuple = ()
    dependent_coordinates: tuple = ()
    dependent_speeds: tuple = ()
    #: where the spec came from (file path or None) -- for error messages only
    source: Optional[str] = field(default=None, compare=False)
    #: (dotted key, line) pairs for error messages from later stages
    lines: tuple = field(default=(), compare=False)

    # -- convenience -------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of degrees of freedom: the speeds (the size of A)."""
        return len(self.speeds)

    @property
    def nq(self) -> int:
        """Number of configuration coordinates (more than ``n`` with a ball or free joint)."""
        return len(self.coordinates)

    @property
    def dof_names(self) -> tuple:
        """One name per degree of freedom (row of A): each simple coordinate's own
        name, then the joints' speed names."""
        return self.simple_coordinates + tuple(s for j in self.joints for s in j.speeds)

    @property
    def simple_coordinates(self) -> tuple:
        """The coordinates whose speed is their time derivative (all but joints')."""
        return self.coordinates[:len(self.coordinates) - sum(len(j.coordinates)
                                                             for j in self.joints)]

    @property
    def n_constraints(self) -> int:
        """Number of scalar constraint equations (rows of the constraint Jacobian)."""
        return sum(c.size for c in self.constraints)

    @property
    def n_holonomic(self) -> int:
        """Number of scalar position constraints (the first rows, in declaration order)."""
        return sum(c.holonomic_size for c in self.constraints)

    @property
    def parameter_names(self) -> tuple:
        return tuple(name for name, _ in self.parameters)

    @property
    def parameter_defaults(self) -> tuple:
        return tuple(float(value) for _, value in self.parameters)

    @property
    def speeds(self) -> tuple:
        """Speed names: ``q_dot`` of each simple coordinate, then the joints' speeds."""
        return (tuple(speed_name(c) for c in self.simple_coordinates)
                + tuple(s for j in self.joints for s in j.speeds))

    @property
    def name_units(self) -> dict:
        """Unit of each coordinate, speed, parameter and input that the model's
        ``units:`` gives one (others are left out): a simple coordinate's speed
        has its coordinate's unit per second (``rad/s``; a joint's speeds have
        none, as its quaternion has none).

        >>> ModelSpec(name="m", coordinates=("x",), units=(("x", "m"),)).name_units
        {'x': 'm', 'x_dot': 'm/s'}
        """
        given = dict(self.units)
        out = {name: unit for name, unit in self.units if name in self.coordinates}
        out.update((speed_name(c), f"{given[c]}/s") for c in self.simple_coordinates
                   if c in given)
        out.update((name, given[name]) for name in (*self.parameter_names, *self.inputs)
                   if name in given)
        return out

    def expressions(self):
        """Every expression of the model: angles, coordinates, masses, inertias,
        gravity, action components and effect fields."""
        for b in self.bases:
            yield b.angle
        for p in self.points:
            yield from p.coordinates
        for b in self.bodies:
            yield b.mass
            for row in b.inertia:
                yield from row
        yield from self.gravity or ()
        for a in self.actions:
            yield from a.torque
            yield from a.force
        for c in self.constraints:
            yield from (e for e in (c.expression, c.radius, c.height) if e is not None)
        for e in self.effects:
            for value in vars(e).values():
                if isinstance(value, tuple):
                    yield from (v for v in value if not isinstance(v, str))
                elif value is not None and not isinstance(value, str):
                    yield value
        for _, value in self.armature:
            yield value

    @property
    def armature_by_dof(self) -> tuple:
        """The armature of each degree of freedom (row of A), 0 where none is given."""
        given = dict(self.armature)
        return tuple(given.get(name, sympy.S.Zero) for name in self.dof_names)

    def free_symbols(self) -> set:
        """The symbols the model's expressions use."""
        out: set = set()
        for expr in self.expressions():
            out |= getattr(expr, "free_symbols", set())
        return out

    def line_of(self, key: str) -> Optional[int]:
        """Line of a dotted key in the source file, if known."""
        for k, line in self.lines:
            if k == key:
                return line
        return None


# -- scenes: which effects and outputs a simulation needs ---------------------------

#: output kinds and the keys each takes (see SceneSpec)
OUTPUT_KINDS = {
    "position": ("point", "from", "base"),        # r(point) - r(from) in base (from: O, base: E)
    "velocity": ("point", "base"),                # velocity of a point wrt E, in base
    "orientation": ("base", "relative_to"),       # 3x3 change-of-basis matrix, row-major
    "angular_velocity": ("base", "relative_to", "components"),
    "energy": ("which",),                         # kinetic | potential | total
    "generalized_force": ("effect",),             # tau of one effect (n values)
    "power": ("effect",),                         # its power tau . q_dot (1 value, W)
    "pose": ("body",),                            # 4x4 pose, row-major
    "constraint_force": ("constraint",),          # its rows' multipliers (docs/constraints.md)
}


@dataclass(frozen=True)
class SceneSpec:
    """A validated scene: a model, the effects switched on, and what to record.

    ``model`` is the scene's reduced model: only the selected effects (the
    top-level gravity is the effect named ``gravity``; actions are effects by
    their names), only the parameters they still use, parameter overrides
    applied as new defaults, and named after the scene so its C never
    collides with the full model's.
    """
    name: str
    model: ModelSpec
    full_model: ModelSpec
    effects: tuple                  # names switched on, in model order
    initial: tuple                  # full state in [q, q_dot] order, floats
    t_start: float
    t_end: float
    sample_dt: float
    method: str = "rk4"
    step: float = 1e-3              # fixed-step methods (rk4, midpoint, gauss4)
    rtol: float = 1e-8              # adaptive methods (dopri5, dop853, rodas)
    atol: float = 1e-10
    inputs: tuple = ()              # tuple[InputSignal, ...] in model input order
    outputs: tuple = ()             # tuple[OutputSpec, ...]
    stiff_effects: tuple = ()       # names of selected effects in STIFF_KINDS
    source: Optional[str] = field(default=None, compare=False)
    lines: tuple = field(default=(), compare=False)
    kinematics: tuple = ()          # ((key, value), ...) of the scene's ``kinematics:``
