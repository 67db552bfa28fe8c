"""The model stage's front doors: a model file or Python calls -> a validated ModelSpec.

Input: model YAML (a path for :func:`load_model`, text for
:func:`parse_model`) or calls on :class:`Model`, one method per YAML entry.
Output: the same immutable :class:`~modelgen.model.spec.ModelSpec` either way,
or a :class:`~modelgen.errors.ModelError` with the file, 1-based line, dotted
key (``bases.B2.parent``), the offending name and a fix (the Python API uses
``file="<api>"`` and no line).  A failed load returns nothing, and a failed
:class:`Model` method leaves the model unchanged.

The format (every section, effect type and rule, with examples) is documented
in ``docs/model-format.md``; how the work is split across the modules of this
package is in ``modelgen/model/README.md``.
"""
from __future__ import annotations

from typing import Mapping, Optional

from modelgen.errors import ModelError
from modelgen.model.builder import ModelBuilder, replay
from modelgen.model.messages import API_FILE, describe
from modelgen.model.names import check_name
from modelgen.model.reader import read_text
from modelgen.model.sections import builder_from_text
from modelgen.model.spec import ModelSpec
from modelgen.model.writer import spec_to_yaml

__all__ = ["Model", "load_model", "parse_model", "spec_to_yaml", "check_name", "API_FILE"]


def parse_model(text: str, source: str = "<string>") -> ModelSpec:
    """Parse and validate model YAML text; ``source`` names it in errors.

    >>> spec = parse_model('''
    ... name: pendulum
    ... coordinates: [q]
    ... parameters: {L: 1.0, m: 1.0, g: 9.81}
    ... bases: {B1: {parent: E, axis: 3, angle: q}}
    ... points: {P: {from: O, base: B1, coordinates: [0, -L, 0]}}
    ... bodies: {bob: {mass: m, G: P, base: B1}}
    ... gravity: [0, -g, 0]
    ... ''')
    >>> spec.points[0].coordinates
    (0, -L, 0)
    """
    return builder_from_text(text, source).build()


def load_model(path) -> ModelSpec:
    """Load and validate a model file.

    >>> spec = load_model("models/double_pendulum.yaml")   # doctest: +SKIP
    >>> spec.coordinates                                      # doctest: +SKIP
    ('q1', 'q2')
    """
    file, text = read_text(path)
    return parse_model(text, source=file)



def _listed(names: tuple, method: str) -> tuple:
    """``add_coordinates("q1", "q2")`` or ``add_coordinates(["q1", "q2"])``, as the YAML's
    list: the names either way."""
    if len(names) == 1 and isinstance(names[0], (list, tuple)):
        return tuple(names[0])
    if len(names) == 1 and isinstance(names[0], Mapping):
        # a dict's keys would be taken as the names and its values dropped unread
        raise ModelError(f"expected names but got {describe(names[0])}", file=API_FILE,
                         key=method.split("_", 1)[1],
                         fix=f"pass names, e.g. {method}('a', 'b') or {method}(['a', 'b'])")
    return names


def _as_dict(value, method: str, example: str) -> dict:
    """A mapping argument of ``method`` as a dict, or a ModelError naming the method."""
    if not isinstance(value, Mapping):
        raise ModelError(f"{method}() takes a mapping (a dict) but got {describe(value)}",
                         file=API_FILE, key=method.split("_", 1)[1],
                         fix=f"pass a dict, e.g. {method}({example})")
    return dict(value)


def _mapping(defaults, keywords: dict, what: str) -> dict:
    """``add_parameters({"m": 1.0})`` or ``add_parameters(m=1.0)`` (or both), as the
    YAML's mapping: one dict of name -> default."""
    out = {} if defaults is None else _as_dict(defaults, f"add_{what}", "{'m': 1.0}")
    twice = sorted(set(out) & set(keywords))
    if twice:
        raise ModelError(f"{what} {', '.join(twice)} given both in the mapping and as "
                         f"keywords", file=API_FILE, key=what,
                         fix="give each name once")
    out.update(keywords)
    return out


def _origin(name: str, from_, parent, key: str, what: str):
    """The YAML's ``from:`` given as ``from_=`` (a Python keyword cannot be ``from``) or
    by its older name ``parent=``/``origin=``: the point it names, or None."""
    if from_ is not None and parent is not None and from_ != parent:
        raise ModelError(f"both from_={from_!r} and {what}={parent!r} given", file=API_FILE,
                         key=key, fix=f"give from_= only ({what}= is its older name)")
    return from_ if from_ is not None else parent


class Model:
    """Build a model in Python; :meth:`spec` returns the same ModelSpec as the YAML.

    Method and keyword names follow the YAML: ``from_=`` is the key ``from`` (``from``
    is a Python keyword; the older ``parent=`` of :meth:`add_point` and ``origin=`` of
    :meth:`add_joint` still work), and the methods adding several names take them as
    the YAML lists or maps them, or as arguments: ``add_coordinates(["q1", "q2"])`` or
    ``add_coordinates("q1", "q2")``, ``add_parameters({"m": 1.0})`` or
    ``add_parameters(m=1.0)``.

    Expressions may be strings (parsed by :mod:`modelgen.model.expr`), ints, floats
    or sympy expressions built from :func:`modelgen.model.spec.symbol`.  Declare
    coordinates, parameters and inputs before using them in expressions;
    bases, points, frames and bodies may be referenced before they are added
    (references are checked by :meth:`spec`).  Every method validates its
    arguments before changing the model, raises :class:`ModelError` with
    ``file="<api>"`` and returns the model, so calls can be chained.

    >>> m = Model("pendulum", description="a point mass on a massless rod")
    >>> _ = m.add_coordinate("q").add_parameter("L", 1.0).add_parameter("m", 1.0)
    >>> _ = m.add_parameter("g", 9.81)
    >>> _ = m.add_base("B1", parent="E", axis=3, angle="q")
    >>> _ = m.add_point("P", from_="O", base="B1", coordinates=[0, "-L", 0])
    >>> _ = m.add_body("bob", mass="m", G="P", base="B1")
    >>> _ = m.set_gravity([0, "-g", 0])
    >>> m.spec().bodies[0].mass
    m
    """

    def __init__(self, name: str, description: str = "", *, physical_inertia: bool = True):
        ctx = ModelBuilder(API_FILE)
        ctx.set_name(name)
        ctx.set_description(description)
        ctx.set_physical_inertia(physical_inertia)
        self._ctx = ctx

    def __repr__(self) -> str:
        c = self._ctx
        return (f"Model({c.name!r}: {len(c.coordinates)} coordinates, {len(c.bases)} bases, "
                f"{len(c.points)} points, {len(c.bodies)} bodies)")

    @property
    def name(self) -> str:
        return self._ctx.name

    @property
    def description(self) -> str:
        return self._ctx.description

    def _apply(self, change) -> "Model":
        """Run ``change`` on a copy and keep it only if it succeeds."""
        trial = self._ctx.clone()
        change(trial)
        self._ctx = trial
        return self

    def add_coordinate(self, name: str) -> "Model":
        """Add a generalized coordinate; its speed is ``<name>_dot``.

        >>> Model("m").add_coordinate("q1").spec().speeds
        ('q1_dot',)
        """
        return self._apply(lambda c: c.add_coordinate(name, f"coordinates[{len(c.coordinates)}]"))

    def add_coordinates(self, *names) -> "Model":
        """Add several coordinates (all or none), as arguments or one list.

        >>> Model("m").add_coordinates("q1", "q2").spec().coordinates
        ('q1', 'q2')
        >>> Model("m").add_coordinates(["q1", "q2"]).spec().coordinates
        ('q1', 'q2')
        """
        names = _listed(names, "add_coordinates")

        def change(c):
            for name in names:
                c.add_coordinate(name, f"coordinates[{len(c.coordinates)}]")
        return self._apply(change)

    def add_parameter(self, name: str, default: float) -> "Model":
        """Add a parameter with its default value (a finite real number).

        >>> Model("m").add_parameter("g", 9.81).spec().parameters
        (('g', 9.81),)
        """
        return self._apply(lambda c: c.add_parameter(name, default, f"parameters.{name}"))

    def add_parameters(self, defaults: Optional[Mapping[str, float]] = None, /,
                       **more: float) -> "Model":
        """Add several parameters from a ``{name: default}`` mapping and/or keywords
        (all or none).

        >>> Model("m").add_parameters({"m": 1.0, "g": 9.81}).spec().parameter_names
        ('m', 'g')
        >>> Model("m").add_parameters(m=1.0, g=9.81).spec().parameter_names
        ('m', 'g')
        """
        defaults = _mapping(defaults, more, "parameters")

        def change(c):
            for name, default in defaults.items():
                c.add_parameter(name, default, f"parameters.{name}")
        return self._apply(change)

    def add_input(self, name: str) -> "Model":
        """Add an input (a signal given at run time).

        >>> Model("m").add_input("T1").spec().inputs
        ('T1',)
        """
        return self._apply(lambda c: c.add_input(name, f"inputs[{len(c.inputs)}]"))

    def add_inputs(self, *names) -> "Model":
        """Add several inputs (all or none), as arguments or one list.

        >>> Model("m").add_inputs("T1", "T2").spec().inputs
        ('T1', 'T2')
        >>> Model("m").add_inputs(["T1", "T2"]).spec().inputs
        ('T1', 'T2')
        """
        names = _listed(names, "add_inputs")

        def change(c):
            for name in names:
                c.add_input(name, f"inputs[{len(c.inputs)}]")
        return self._apply(change)

    def add_base(self, name: str, *, parent: str, axis: int, angle) -> "Model":
        """Add a base rotated from ``parent`` by ``angle`` about its axis 1, 2 or 3.

        >>> m = Model("m").add_coordinate("q1")
        >>> m.add_base("B1", parent="E", axis=3, angle="q1").spec().bases[0].axis
        3
        """
        return self._apply(lambda c: c.add_base(name, parent, axis, angle, f"bases.{name}"))

    def add_joint(self, name: str, kind: str, *, parent: str, base: str,
                  from_: Optional[str] = None, point: Optional[str] = None,
                  origin: Optional[str] = None) -> "Model":
        """Add a ``ball`` or ``free`` joint: base ``base`` turned from ``parent`` by
        a unit quaternion; a free joint also makes ``point`` at a position from
        ``from_`` (default O; the YAML key ``from``; ``origin=`` is its older name)
        in ``parent``'s components.

        >>> spec = Model("m").add_joint("J", "free", parent="E", base="B", point="P").spec()
        >>> spec.coordinates, spec.speeds
        (('J_x', 'J_y', 'J_z', 'J_qw', 'J_qx', 'J_qy', 'J_qz'), ('J_vx', 'J_vy', 'J_vz', 'J_wx', 'J_wy', 'J_wz'))
        """
        origin = _origin(name, from_, origin, f"joints.{name}", "origin")
        return self._apply(lambda c: c.add_joint(name, kind, parent, base, origin, point,
                                                 f"joints.{name}"))

    def add_point(self, name: str, *, coordinates, from_: Optional[str] = None,
                  base: Optional[str] = None, frame: Optional[str] = None,
                  parent: Optional[str] = None) -> "Model":
        """Add a point at ``coordinates`` (in ``base``) from point ``from_`` (the YAML
        key ``from``; ``parent=`` is its older name and still works).

        Give ``frame=`` instead of ``from_``/``base`` to use a frame's point
        and base, or neither for an absolute point (from O in base E).

        >>> m = Model("m").add_parameter("l", 1.0)
        >>> m.add_point("P", coordinates=["l", 0, 0]).spec().points[0].parent
        'O'
        >>> m.add_point("Q", from_="P", base="E", coordinates=["l", 0, 0]).spec().points[1].parent
        'P'
        """
        parent = _origin(name, from_, parent, f"points.{name}", "parent")
        return self._apply(lambda c: c.add_point(name, parent, base, frame, coordinates,
                                                 f"points.{name}"))

    def add_frame(self, name: str, *, point: str, base: str) -> "Model":
        """Add a named coordinate system (a point and a base).

        >>> Model("m").add_frame("F", point="O", base="E").spec().frames[0].point
        'O'
        """
        return self._apply(lambda c: c.add_frame(name, point, base, f"frames.{name}"))

    def add_body(self, name: str, *, mass, G: str, base: str, inertia=None) -> "Model":
        """Add a rigid body: mass, centre of mass ``G``, base and inertia about G.

        ``inertia`` is ``[Ixx, Iyy, Izz]``, a 3x3 nested list, or None (a particle).

        >>> m = Model("m").add_parameters({"m": 2.0, "I": 0.5})
        >>> m.add_body("b", mass="m", G="O", base="E", inertia=["I", "I", "I"]).spec(
        ...     ).bodies[0].inertia[1]
        (0, I, 0)
        """
        return self._apply(lambda c: c.add_body(name, mass, G, base, inertia,
                                                f"bodies.{name}"))

    def set_gravity(self, vector) -> "Model":
        """Set the gravity vector (components in E), or remove it with None.

        >>> Model("m").add_parameter("g", 9.81).set_gravity([0, 0, "-g"]).spec().gravity
        (0, 0, -g)
        """
        return self._apply(lambda c: c.set_gravity(vector))

    def add_action(self, name: str, *, body: str, point: Optional[str] = None,
                   base: Optional[str] = None, frame: Optional[str] = None,
                   torque=None, force=None, vector=None) -> "Model":
        """Add a torque and a force acting on ``body`` at ``point``, components in ``base``.

        ``torque`` and ``force`` default to zeros; ``vector=[Mx, My, Mz, Fx,
        Fy, Fz]`` is the seed's alternative.  ``frame=`` may replace
        ``point``/``base``.

        >>> m = Model("m").add_input("F").add_body("b", mass=1, G="O", base="E")
        >>> m.add_action("push", body="b", point="O", base="E", force=["F", 0, 0]).spec(
        ...     ).actions[0].force
        (F, 0, 0)
        """
        return self._apply(lambda c: c.add_action(name, body, point, base, frame, torque,
                                                  force, vector, f"actions.{name}"))

    def add_effect(self, name: str, type: str, **fields) -> "Model":
        """Add a named effect of kind ``type``; ``fields`` as in the YAML ``effects:``.

        ``type`` is ``gravity``, ``spring``, ``torsion_spring``, ``damper``,
        ``joint_damping``, ``friction``, ``drag`` or ``action``; the keyword
        arguments are that effect's fields (omit the optional ones, or pass
        None).  References to points, bases, bodies and coordinates are
        checked by :meth:`spec`.

        >>> m = Model("m").add_coordinate("x").add_parameters({"k": 10.0, "L": 1.0})
        >>> _ = m.add_point("P", coordinates=["x", 0, 0])
        >>> m.add_effect("s", "spring", point_a="O", point_b="P", stiffness="k",
        ...              rest_length="L").spec().effects[0].stiffness
        k
        """
        return self._apply(lambda c: c.add_effect(name, type, fields, f"effects.{name}"))

    def set_armature(self, armature: Optional[Mapping[str, object]]) -> "Model":
        """Set the armature (reflected rotor inertia, added to the dof's diagonal entry
        of A) of simple coordinates or ball/free joint speeds, replacing any set
        before; None removes it.  Values are parameters-only expressions >= 0.

        >>> m = Model("m").add_coordinate("q").add_parameter("Ir", 0.01)
        >>> m.set_armature({"q": "Ir"}).spec().armature
        (('q', Ir),)
        """
        armature = None if armature is None else \
            _as_dict(armature, "set_armature", "{'q1': 0.01}")
        return self._apply(lambda c: c.set_armature(armature))

    def add_constraint(self, name: str, type: str, **fields) -> "Model":
        """Add a named constraint of kind ``type`` (``coincide``, ``position``,
        ``velocity`` or ``speeds``); ``fields`` as in the YAML ``constraints:``.

        >>> m = Model("m").add_coordinates("x", "y").add_parameter("L", 1.0)
        >>> _ = m.add_constraint("line", "position", expression="x - y")
        >>> m.set_dependent(coordinates=["y"], speeds=["y_dot"]).spec().constraints[0].kind
        'position'
        """
        return self._apply(lambda c: c.add_constraint(name, type, fields,
                                                      f"constraints.{name}"))

    def set_dependent(self, *, coordinates=(), speeds=()) -> "Model":
        """Declare the dependent coordinates (one per position equation) and speeds
        (one per constraint equation); the others stay independent.  Each is a list
        of names, one name, or None (none).

        >>> m = Model("m").add_coordinates("x", "y").add_parameter("L", 1.0)
        >>> m = m.add_constraint("line", "position", expression="x - y")
        >>> m.set_dependent(coordinates="y", speeds="y_dot").spec().dependent_speeds
        ('y_dot',)
        """
        def names(value):
            # one name is a list of one, not its characters; anything else that is not
            # a list (a number) goes to the YAML's check, which names the key
            return [] if value is None else [value] if isinstance(value, str) else value
        return self._apply(lambda c: c.set_dependent({"coordinates": names(coordinates),
                                                       "speeds": names(speeds)}))

    def set_units(self, units: Optional[Mapping[str, str]]) -> "Model":
        """Set the units of declared coordinates, parameters and inputs (replacing any
        set before); for people and exports, never in the equations.  None removes
        them (as ``units: null`` in the YAML).

        >>> Model("m").add_parameter("L", 1.0).set_units({"L": "m"}).spec().units
        (('L', 'm'),)
        """
        units = None if units is None else _as_dict(units, "set_units", "{'L': 'm'}")
        return self._apply(lambda c: c.set_units(units))

    def spec(self) -> ModelSpec:
        """Validate the whole model and return the frozen :class:`ModelSpec`.

        >>> Model("empty").spec().name
        'empty'
        """
        return self._ctx.build()

    def to_yaml(self) -> str:
        """The model in the YAML format; ``parse_model(m.to_yaml()) == m.spec()``.

        >>> print(Model("m", description="demo").to_yaml(), end="")
        name: m
        description: demo
        """
        return spec_to_yaml(self.spec())

    @classmethod
    def from_spec(cls, spec: ModelSpec) -> "Model":
        """A Model that builds ``spec`` again (frames are kept; points use from/base).

        >>> Model.from_spec(Model("m").spec()).spec() == Model("m").spec()
        True
        """
        m = cls(spec.name, spec.description, physical_inertia=spec.physical_inertia)
        return m._apply(lambda c: replay(c, spec))

    @classmethod
    def from_yaml(cls, path) -> "Model":
        """A Model built from a model file (see :func:`load_model`).

        >>> Model.from_yaml("models/double_pendulum.yaml").name   # doctest: +SKIP
        'double_pendulum'
        """
        return cls.from_spec(load_model(path))

