"""The model builder: validated declarations, one ``add_*`` call per entry.

Input: calls from the YAML section readers (:mod:`modelgen.model.sections`),
the Python API (:class:`~modelgen.model.api.Model`) and the scene loader, one
per declared name, with raw values and the entry's dotted key.
Output: :meth:`ModelBuilder.build` -> a frozen :class:`~modelgen.model.spec.ModelSpec`
(references are resolved by :mod:`modelgen.model.resolve`).  Every ``add_*``
validates its entry completely (names, expressions, physical checks at the
parameter defaults) before it changes anything, so a failed call leaves the
builder as it was.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import re
from typing import Mapping, NamedTuple, Optional

import sympy

from modelgen.errors import ModelError

from modelgen.model import spec as specmod
from modelgen.model.constraints import constraint_decl, constraint_fields, dependent_decl
from modelgen.model.expr import ExpressionParseError, format_expression, parse_expression
from modelgen.model.inertia import check_physical_inertia, read_inertia
from modelgen.model.messages import (API_FILE, article, as_list, closest, describe,
                                     join_and, quote_expression)
from modelgen.model.names import (MAX_NAME_LENGTH, NAME_FIX, NAME_RE, NAMESPACE_NOTE,
                                  NAMESPACE_NOTE_EFFECTS, check_model_name, check_name)
from modelgen.model.resolve import build_spec
from modelgen.model.schema import ENTRY_KEYS, EXPRESSION_RULES, NUMERIC_STRING, REQUIRED_KEYS
from modelgen.model.spec import (CANONICAL_BASE, CANONICAL_POINT, EFFECT_KINDS, TIME,
                                 ModelSpec, effect_fields)

__all__ = ["ModelBuilder", "replay", "BaseDecl", "PointDecl", "JointDecl", "FrameDecl",
           "BodyDecl", "ActionDecl", "EffectDecl"]


# -- declarations: validated entries, before references are resolved ----------

#: The fix of a name that is a coordinate's or a joint speed's acceleration.
ACCELERATION_FIX = ("rename it; accelerations are named q_ddot for a coordinate q and "
                    "J_wx_dot for a ball or free joint's speed J_wx")

#: What a unit may be written as (see ModelBuilder.set_units).
UNIT_TEXT = re.compile(r"[A-Za-z0-9_.*/^() -]{1,40}")

class BaseDecl(NamedTuple):
    name: str
    parent: str
    axis: int
    angle: sympy.Expr
    key: str
    quaternion: tuple = ()  # a joint's base: its quaternion symbols (w, x, y, z)
    rates: tuple = ()       # and its angular-velocity symbols


class PointDecl(NamedTuple):
    name: str
    parent: Optional[str]   # None when given by a frame
    base: Optional[str]
    frame: Optional[str]
    coordinates: tuple
    key: str
    speeds: tuple = ()      # a free joint's point: its velocity symbols
    speed_base: str = ""    # in components of this base


class JointDecl(NamedTuple):
    name: str
    kind: str               # a key of JOINT_KINDS
    parent: str
    base: str
    origin: str
    point: str
    coordinates: tuple      # names
    speeds: tuple           # names
    key: str


class FrameDecl(NamedTuple):
    name: str
    point: str
    base: str
    key: str


class BodyDecl(NamedTuple):
    name: str
    mass: sympy.Expr
    G: str
    base: str
    inertia: tuple
    key: str


class ActionDecl(NamedTuple):
    name: str
    body: str
    point: Optional[str]
    base: Optional[str]
    frame: Optional[str]
    torque: tuple
    force: tuple
    key: str


class EffectDecl(NamedTuple):
    name: str
    kind: str               # a key of EFFECT_KINDS
    fields: dict            # field -> validated value (given fields only)
    frame: Optional[str]    # action effects given a frame
    key: str


class ModelBuilder:
    """Accumulates validated declarations; :meth:`build` resolves them into a spec.

    Every ``add_*`` method validates completely before it changes anything.
    ``lines`` maps dotted keys to 1-based lines (empty for the Python API).
    Keys under a prefix registered with :meth:`add_source` come from another
    file (a scene adding parameters and effects to its model) and their
    errors name that file.
    """

    def __init__(self, file: Optional[str], lines: Optional[dict] = None):
        self.file = file
        self.lines = lines if lines is not None else {}
        self.name: Optional[str] = None
        self.description = ""
        self.units: list = []
        self.physical_inertia = True  # False: inertias as given (see set_physical_inertia)
        self.kinds: dict = {}         # name -> (kind, key) for every declared name
        self.speeds: dict = {}        # speed name -> coordinate
        self.symbols: dict = {}       # name -> Symbol (coordinates, speeds, parameters, inputs)
        self.coordinates: list = []
        self.parameters: list = []    # (name, float)
        self.defaults: dict = {}      # Symbol -> sympy Float, for the physical checks
        self.inputs: list = []
        self.bases: list = []
        self.points: list = []
        self.joints: list = []
        self.frames: list = []
        self.bodies: list = []
        self.actions: list = []
        self.effects: list = []
        self.gravity: Optional[tuple] = None
        self.armature: list = []      # (dof name, expression, key), checked by build()
        self.constraints: list = []   # ConstraintDecl (modelgen.model.constraints)
        self.dependent: tuple = ((), ())
        self.dependent_key = "dependent"
        self.sources: list = []       # (key prefix, file, lines) of keys from other files
        self._allowed: dict = {}

    def clone(self) -> "ModelBuilder":
        other = ModelBuilder(self.file, self.lines)
        for attr, value in vars(self).items():
            if isinstance(value, (dict, list)) and attr != "lines":
                value = type(value)(value)
            setattr(other, attr, value)
        return other

    # -- errors ------------------------------------------------------------
    def add_source(self, prefix: str, file: Optional[str], lines: dict) -> None:
        """Keys ``prefix`` and ``prefix.*`` come from ``file`` with line table ``lines``."""
        self.sources.append((prefix, file, lines))

    def _source(self, key: Optional[str]):
        for prefix, file, lines in self.sources:
            if key and (key == prefix or key.startswith((prefix + ".", prefix + "["))):
                return file, lines
        return self.file, self.lines

    def file_of(self, key: Optional[str]) -> Optional[str]:
        return self._source(key)[0]

    def line_of(self, key: Optional[str]) -> Optional[int]:
        lines = self._source(key)[1]
        while key:
            if key in lines:
                return lines[key]
            cut = max(key.rfind("."), key.rfind("["))
            key = key[:cut] if cut > 0 else ""
        return None

    def place(self, key: str, seen_from: Optional[str]) -> str:
        """``key (line 3)``, or ``key (file:3)`` when ``key`` is in another file."""
        line, file = self.line_of(key), self.file_of(key)
        if file != self.file_of(seen_from) and file is not None:
            return f"{key} ({file}" + (f":{line})" if line is not None else ")")
        return key + (f" (line {line})" if line is not None else "")

    def error(self, problem: str, key: Optional[str], fix: Optional[str]) -> ModelError:
        return ModelError(problem, file=self.file_of(key), line=self.line_of(key), key=key,
                          fix=fix)

    # -- names -------------------------------------------------------------
    def kind_of(self, name: str) -> Optional[str]:
        if name in self.kinds:
            return self.kinds[name][0]
        if name in self.speeds:
            return "speed"
        if name == "t":
            return "time"
        return None

    def check_new_name(self, name, kind: str, key: str) -> str:
        check_name(name, file=self.file_of(key), line=self.line_of(key), key=key,
                   what=f"{kind} name")
        if name in self.kinds:
            other_kind, other_key = self.kinds[name]
            note = NAMESPACE_NOTE_EFFECTS if "effect" in (kind, other_kind) \
                else NAMESPACE_NOTE
            raise self.error(f"duplicate name '{name}': already declared as "
                             f"{article(other_kind)} at {self.place(other_key, key)}", key,
                             f"rename one of them; {note}")
        if name in self.speeds:
            raise self.error(f"'{name}' is the speed of coordinate '{self.speeds[name]}'",
                             key, "rename it; the speed of a coordinate q is named q_dot")
        owner = self.acceleration_owner(name)
        if owner is not None:
            raise self.error(f"'{name}' is the acceleration of {self.kind_of(owner)} "
                             f"'{owner}'", key, ACCELERATION_FIX)
        return name

    def acceleration_owner(self, name: str) -> Optional[str]:
        """The coordinate (q of ``q_ddot``) or ball/free joint speed (J_wx of
        ``J_wx_dot``) whose acceleration symbol is ``name``, or None: the names of
        :class:`~modelgen.derive.queries.Mechanism`'s results, so reserved."""
        for suffix, kind in (("_ddot", "coordinate"), ("_dot", "joint speed")):
            stem = name.removesuffix(suffix)
            if stem != name and self.kind_of(stem) == kind:
                return stem
        return None

    def register(self, name: str, kind: str, key: str) -> None:
        self.kinds[name] = (kind, key)

    def add_symbol(self, name: str) -> None:
        self.symbols[name] = specmod.symbol(name)
        self._allowed = {}

    # -- values --------------------------------------------------------------
    def allowed(self, rule: str) -> dict:
        if rule not in self._allowed:
            kinds = EXPRESSION_RULES[rule].kinds
            table = {name: symbol for name, symbol in self.symbols.items()
                     if self.kind_of(name) in kinds}
            if "time" in kinds:
                table["t"] = TIME
            self._allowed[rule] = table
        return self._allowed[rule]

    def expression(self, value, key: str, rule: str) -> sympy.Expr:
        try:
            return parse_expression(value, self.allowed(rule),
                                    kinds=EXPRESSION_RULES[rule].text)
        except ExpressionParseError as exc:
            raise self._expression_error(exc, value, key, rule) from None

    def _expression_error(self, exc: ExpressionParseError, value, key: str,
                          rule_name: str) -> ModelError:
        rule = EXPRESSION_RULES[rule_name]
        if exc.name is not None:
            name = exc.name
            kind = self.kind_of(name)
            if kind is not None:
                motion = ("; for a prescribed motion, make it a coordinate and drive it "
                          "with an action" if kind == "time" and rule_name == "position" else "")
                return self.error(f"{kind} '{name}' is not allowed in expression "
                                  f"{quote_expression(value)}", key,
                                  f"use only {rule.text} here{rule.why}{motion}")
            close = closest(name, list(self.allowed(rule_name)))
            fix = f"did you mean '{close}'? Otherwise " if close else ""
            fix += (f"declare '{name}' under {rule.declare}; only {rule.text} "
                    f"may be used here")
            return self.error(f"undefined name '{name}' in expression {quote_expression(value)}",
                              key, fix)
        problem = "invalid expression: " + exc.reason
        if exc.column is not None:
            problem += f" at column {exc.column} of {quote_expression(exc.text)}"
        elif exc.text is not None:
            problem += f" in {quote_expression(exc.text)}"
        return self.error(problem, key, exc.hint or "correct the expression")

    def vector(self, value, key: str, rule: str, length: int = 3,
               example: str = "[x, y, z]") -> tuple:
        items = as_list(value)
        if not isinstance(items, list):
            raise self.error(f"expected a list of {length} components but got "
                             f"{describe(value)}", key, f"write {example}")
        if len(items) != length:
            raise self.error(f"expected {length} components but got {len(items)}", key,
                             f"write {example}")
        return tuple(self.expression(item, f"{key}[{i}]", rule)
                     for i, item in enumerate(items))

    def reference(self, value, what: str, key: str) -> str:
        """A reference to a base, point, body or frame: must be a string name."""
        if not isinstance(value, str):
            raise self.error(f"expected {article(what)} name but got {describe(value)}", key,
                             f"write the name of {article(what)}")
        return value

    def number(self, value, key: str, what: str) -> float:
        """A real number (or numeric string) as a double; one that overflows a double,
        or is not 0 but rounds to 0, is refused as the expression grammar refuses it."""
        if isinstance(value, str) and NUMERIC_STRING.match(value):
            exact_zero = not re.search(r"[1-9]", value.lower().partition("e")[0])
            approx = float(value)
            overflow = math.isinf(approx)
        elif isinstance(value, numbers.Real) and not isinstance(value, bool):
            exact_zero = value == 0
            try:
                approx = float(value)
            except OverflowError:       # an int or a fraction beyond the doubles
                approx = math.inf if value > 0 else -math.inf
            overflow = math.isinf(approx) and value != approx
        else:
            raise self.error(f"{what} must be a finite real number but is "
                             f"{describe(value)}", key, "write a number such as 1.0")
        if overflow:
            raise self.error(f"{what} overflows a double (its magnitude is above 1.8e308)",
                             key, "write a number of magnitude at most 1.7e308")
        if not math.isfinite(approx):
            raise self.error(f"{what} must be a finite real number but is "
                             f"{describe(value)}", key, "write a number such as 1.0")
        if approx == 0 and not exact_zero:
            raise self.error(f"{what} is too small for a double (it would be 0)", key,
                             "use a magnitude of at least 5e-324, or 0")
        return approx

    def at_defaults(self, expr: sympy.Expr) -> Optional[float]:
        """Value of a parameters-only expression at the defaults (None if not real)."""
        value = expr.xreplace(self.defaults)
        try:
            result = float(value)
        except (TypeError, OverflowError):
            return None
        return result if math.isfinite(result) else None

    # -- declarations ---------------------------------------------------------
    def set_name(self, name, key: str = "name") -> None:
        if not isinstance(name, str) or not NAME_RE.match(name) or len(name) > MAX_NAME_LENGTH:
            shown = f"'{name}'" if isinstance(name, str) else describe(name)
            raise self.error(f"model name {shown} is not a valid C identifier", key,
                             f"{NAME_FIX} and at most {MAX_NAME_LENGTH} characters "
                             "(it prefixes every generated C function)")
        check_model_name(name, file=self.file, line=self.line_of(key), key=key)
        self.name = name

    def set_description(self, text, key: str = "description") -> None:
        if text is None:
            text = ""
        if not isinstance(text, str):
            raise self.error(f"expected a string but got {describe(text)}", key,
                             "write the description as text (quote it if needed)")
        self.description = text

    def set_physical_inertia(self, value, key: str = "physical_inertia") -> None:
        """``physical_inertia: false`` takes the bodies' inertias as given (a vendor's
        file that no rigid body can have); declared before the bodies it applies to."""
        if value is None:
            value = True
        if not isinstance(value, bool):
            raise self.error(f"expected true or false but got {describe(value)}", key,
                             "write 'physical_inertia: false' to take inertias as given, or "
                             "leave the key out")
        self.physical_inertia = value

    def set_units(self, value, key: str = "units") -> None:
        """``units: {name: unit, ...}`` for declared coordinates, parameters and inputs;
        a unit is short plain text (letters, digits, ``_ . * / ^ ( ) -`` and spaces),
        so it can be written into XML and C comments as it is."""
        self.units = []
        if value is None:
            return
        if not isinstance(value, dict):
            raise self.error(f"expected a mapping of names to units but got {describe(value)}",
                             key, "write e.g. 'units: {L: m, m: kg, q1: rad}'")
        for name, unit in value.items():
            entry = f"{key}.{name}"
            if self.kind_of(name) not in ("coordinate", "parameter", "input"):
                raise self.error(f"'{name}' is not a declared coordinate, parameter or input",
                                 entry, "give units of coordinates, parameters and inputs "
                                 "(a speed's unit is its coordinate's per second)")
            if not isinstance(unit, str) or not UNIT_TEXT.fullmatch(unit):
                raise self.error(f"the unit of '{name}' must be short plain text, got "
                                 f"{describe(unit)}", entry,
                                 "write it like m, kg, rad, N*m, m/s^2 (at most 40 letters, "
                                 "digits, spaces and _ . * / ^ ( ) -)")
            self.units.append((name, unit))

    def add_coordinate(self, name, key: str) -> None:
        self.check_new_name(name, "coordinate", key)
        speed = specmod.speed_name(name)
        if speed in self.kinds:
            other_kind, other_key = self.kinds[speed]
            raise self.error(f"the speed of coordinate '{name}' would be '{speed}', which "
                             f"is already declared as {article(other_kind)} at {other_key}", key,
                             f"rename {other_kind} '{speed}' or coordinate '{name}'")
        if f"{name}_ddot" in self.kinds:
            other_kind, other_key = self.kinds[f"{name}_ddot"]
            raise self.error(f"the acceleration of coordinate '{name}' would be '{name}_ddot', "
                             f"which is already declared as {article(other_kind)} at "
                             f"{other_key}", key, ACCELERATION_FIX)
        self.register(name, "coordinate", key)
        self.coordinates.append(name)
        self.speeds[speed] = name
        self.add_symbol(name)
        self.add_symbol(speed)

    def add_parameter(self, name, default, key: str) -> None:
        self.check_new_name(name, "parameter", key)
        value = self.number(default, key, f"the default of parameter '{name}'")
        self.register(name, "parameter", key)
        self.parameters.append((name, value))
        self.add_symbol(name)
        self.defaults[self.symbols[name]] = sympy.Float(value)

    def add_input(self, name, key: str) -> None:
        self.check_new_name(name, "input", key)
        self.register(name, "input", key)
        self.inputs.append(name)
        self.add_symbol(name)

    def add_base(self, name, parent, axis, angle, key: str) -> None:
        self.check_new_name(name, "base", key)
        parent = self.reference(parent, "base", f"{key}.parent")
        if isinstance(axis, bool) or not isinstance(axis, numbers.Integral) \
                or not 1 <= axis <= 3:
            raise self.error(f"axis must be 1, 2 or 3 but is {describe(axis)}",
                             f"{key}.axis", "use 1, 2 or 3 for the parent's x, y or z axis")
        angle = self.expression(angle, f"{key}.angle", "position")
        self.register(name, "base", key)
        self.bases.append(BaseDecl(name, parent, int(axis), angle, key))

    def spelled(self, field: str, key: str) -> str:
        """A field as its writer spells it: 'from' in a model file, from_= in the
        Python API (whose ``file`` is ``<api>``; ``from`` is a Python keyword)."""
        if self.file_of(key) == API_FILE:
            return ("from_" if field == "from" else field) + "="
        return f"'{field}'"

    def missing(self, field: str, key: str) -> str:
        """'missing required key 'from'', or in the Python API 'missing argument from_='."""
        api = self.file_of(key) == API_FILE
        return f"missing {'argument' if api else 'required key'} {self.spelled(field, key)}"

    def add_point(self, name, parent, base, frame, coordinates, key: str) -> None:
        self.check_new_name(name, "point", key)
        spell = functools.partial(self.spelled, key=key)
        if frame is not None:
            if parent is not None or base is not None:
                raise self.error(f"{spell('frame')} cannot be combined with "
                                 f"{spell('from')} or {spell('base')}", f"{key}.frame",
                                 f"give either {spell('frame')} or {spell('from')} and "
                                 f"{spell('base')}")
            frame = self.reference(frame, "frame", f"{key}.frame")
        elif parent is None and base is None:
            parent, base = CANONICAL_POINT, CANONICAL_BASE
        elif base is None:
            raise self.error(f"{self.missing('base', key)} (needed with {spell('from')})",
                             key, f"add {spell('base')}, or use {spell('frame')} instead of "
                             f"{spell('from')}")
        elif parent is None:
            raise self.error(f"{self.missing('from', key)} (needed with {spell('base')})",
                             key, f"add {spell('from')}, or use {spell('frame')} instead of "
                             f"{spell('base')}")
        if frame is None:
            parent = self.reference(parent, "point", f"{key}.from")
            base = self.reference(base, "base", f"{key}.base")
        where = f"base '{base}'" if frame is None else f"frame '{frame}'"
        coordinates = self.vector(coordinates, f"{key}.coordinates", "position",
                                  example=f"[x, y, z] (components in {where})")
        self.register(name, "point", key)
        self.points.append(PointDecl(name, parent, base, frame, coordinates, key))

    def add_joint(self, name, kind, parent, base, origin, point, key: str) -> None:
        """A ball or free joint: it declares its base (and a free joint its point),
        its coordinates ``<name>_<suffix>`` and speeds (``JOINT_KINDS``)."""
        self.check_new_name(name, "joint", key)
        api = self.file_of(key) == API_FILE
        if not isinstance(kind, str) or kind not in specmod.JOINT_KINDS:
            raise self.error(f"unknown joint {'kind' if api else 'type'} {describe(kind)}",
                             f"{key}.type",
                             "use 'ball' (a quaternion, 3 speeds) or 'free' (a position and "
                             "a quaternion, 6 speeds); a hinge is a base with an axis and "
                             "an angle")
        parent = self.reference(parent, "base", f"{key}.parent")
        base = self.reference(base, "base", f"{key}.base")
        if kind == "free":
            origin = CANONICAL_POINT if origin is None else \
                self.reference(origin, "point", f"{key}.from")
            if point is None:
                raise self.error(self.missing("point", key), key, "a free joint makes a point: "
                                 + ("add point='<new point name>'" if api else
                                    "add 'point: <new point name>'"))
            point = self.reference(point, "point", f"{key}.point")
        else:
            for field, value in (("from", origin), ("point", point)):
                if value is not None:
                    raise self.error(f"a ball joint has no {self.spelled(field, key)}",
                                     f"{key}.{field}", "remove it, or make the joint "
                                     + ("kind='free'" if api else "'type: free'"))
            origin = point = ""
        q_suffixes, v_suffixes = specmod.JOINT_KINDS[kind]
        coordinates = tuple(f"{name}_{s}" for s in q_suffixes)
        speeds = tuple(f"{name}_{s}" for s in v_suffixes)
        made = [(base, "base")] + ([(point, "point")] if point else [])
        names = made + [(c, "joint coordinate") for c in coordinates] + \
            [(v, "joint speed") for v in speeds]
        for new, what in names:
            self.check_new_name(new, what, key)
        for speed in speeds:
            if f"{speed}_dot" in self.kinds:
                raise self.error(f"the acceleration of joint speed '{speed}' would be "
                                 f"'{speed}_dot', which is already declared as "
                                 f"{article(self.kinds[speed + '_dot'][0])}", key,
                                 ACCELERATION_FIX)
        if len({new for new, _ in names} | {name}) != len(names) + 1:
            raise self.error("the joint's base, point and name must differ", key,
                             "give the base and the point their own names")
        self.register(name, "joint", key)
        for new, what in names:
            self.register(new, what, key)
        for new in coordinates + speeds:
            self.add_symbol(new)
        sym = self.symbols
        self.bases.append(BaseDecl(base, parent, 0, sympy.S.Zero, key,
                                   tuple(sym[c] for c in coordinates[-4:]),
                                   tuple(sym[v] for v in speeds[-3:])))
        if kind == "free":
            self.points.append(PointDecl(point, origin, parent, None,
                                         tuple(sym[c] for c in coordinates[:3]), key,
                                         tuple(sym[v] for v in speeds[:3]), base))
        self.joints.append(JointDecl(name, kind, parent, base, origin, point, coordinates,
                                     speeds, key))

    def add_frame(self, name, point, base, key: str) -> None:
        self.check_new_name(name, "frame", key)
        point = self.reference(point, "point", f"{key}.point")
        base = self.reference(base, "base", f"{key}.base")
        self.register(name, "frame", key)
        self.frames.append(FrameDecl(name, point, base, key))

    def add_body(self, name, mass, G, base, inertia, key: str) -> None:
        self.check_new_name(name, "body", key)
        mass = self.expression(mass, f"{key}.mass", "constant")
        G = self.reference(G, "point", f"{key}.G")
        base = self.reference(base, "base", f"{key}.base")
        inertia = read_inertia(self, inertia, f"{key}.inertia", name)
        mass_value = self.at_defaults(mass)
        if mass_value is None:
            raise self.error(f"mass of body '{name}' is not a real number with the default "
                             f"parameters: {format_expression(mass)}", f"{key}.mass",
                             "give a mass >= 0")
        if mass_value < 0:
            raise self.error(f"mass of body '{name}' is negative: {format_expression(mass)} "
                             f"= {mass_value!r} with the default parameters", f"{key}.mass",
                             "give a mass >= 0")
        if self.physical_inertia:
            check_physical_inertia(self, name, inertia, f"{key}.inertia")
        self.register(name, "body", key)
        self.bodies.append(BodyDecl(name, mass, G, base, inertia, key))

    def set_gravity(self, vector, key: str = "gravity") -> None:
        if vector is None:
            self.gravity = None
            return
        self.gravity = self.vector(vector, key, "gravity",
                                   example="[gx, gy, gz] (components in base E)")

    def set_armature(self, value, key: str = "armature") -> None:
        """``armature: {dof: expression, ...}``: reflected rotor inertia on the diagonal
        of A, per simple coordinate or ball/free joint speed (the names are
        checked by :meth:`build`, so they may be declared later)."""
        entries = []
        if value is not None:
            if not isinstance(value, dict):
                raise self.error(f"expected a mapping of coordinate names to armatures but "
                                 f"got {describe(value)}", key,
                                 "write e.g. 'armature: {q1: 0.01, J_wx: Ir}'")
            for name, amount in value.items():
                entry = f"{key}.{name}"
                if not isinstance(name, str):
                    raise self.error(f"expected a coordinate or joint speed name but got "
                                     f"{describe(name)}", entry,
                                     "write e.g. 'armature: {q1: 0.01}'")
                expr = self.expression(amount, entry, "coefficient")
                at = self.at_defaults(expr)
                if at is None or at < 0:
                    shown = format_expression(expr)
                    problem = ("is not a real number with the default parameters"
                               if at is None else f"is negative: {shown} = {at!r} with the "
                               "default parameters")
                    raise self.error(f"armature of '{name}' {problem}", entry,
                                     "give an armature >= 0 (a rotor inertia times the "
                                     "gear ratio squared)")
                entries.append((name, expr, entry))
        self.armature = entries

    def add_action(self, name, body, point, base, frame, torque, force, vector,
                   key: str) -> None:
        self.check_new_name(name, "action", key)
        parts = self.action_parts(body, point, base, frame, torque, force, vector, key)
        self.register(name, "action", key)
        self.actions.append(ActionDecl(name, *parts, key))

    def action_parts(self, body, point, base, frame, torque, force, vector,
                     key: str) -> tuple:
        """Validated (body, point, base, frame, torque, force) of an action."""
        body = self.reference(body, "body", f"{key}.body")
        if frame is not None:
            if point is not None or base is not None:
                raise self.error("'frame' cannot be combined with 'point' or 'base'",
                                 f"{key}.frame", "give either 'frame' or 'point' and 'base'")
            frame = self.reference(frame, "frame", f"{key}.frame")
        else:
            if point is None:
                raise self.error("missing required key 'point' (or 'frame')", key,
                                 "add 'point' and 'base', or 'frame'")
            if base is None:
                raise self.error("missing required key 'base' (needed with 'point')", key,
                                 "add 'base', or give 'frame' instead of 'point' and 'base'")
            point = self.reference(point, "point", f"{key}.point")
            base = self.reference(base, "base", f"{key}.base")
        zero = (sympy.Integer(0),) * 3
        if vector is not None:
            if torque is not None or force is not None:
                raise self.error("'vector' cannot be combined with 'torque' or 'force'",
                                 f"{key}.vector",
                                 "give either 'vector' or 'torque' and 'force'")
            six = self.vector(vector, f"{key}.vector", "action", 6,
                              "[Mx, My, Mz, Fx, Fy, Fz]")
            torque, force = six[:3], six[3:]
        else:
            torque = zero if torque is None else self.vector(
                torque, f"{key}.torque", "action", example="[Mx, My, Mz]")
            force = zero if force is None else self.vector(
                force, f"{key}.force", "action", example="[Fx, Fy, Fz]")
        return body, point, base, frame, torque, force

    def add_effect(self, name, kind, fields: Mapping, key: str) -> None:
        """An effect of type ``kind`` with ``fields`` (None means not given)."""
        self.check_new_name(name, "effect", key)
        types = ", ".join(EFFECT_KINDS)
        if not isinstance(kind, str):
            raise self.error(f"expected an effect type but got {describe(kind)}",
                             f"{key}.type", f"write one of {types}")
        if kind not in EFFECT_KINDS:
            close = closest(kind, EFFECT_KINDS)
            fix = f"did you mean '{close}'? " if close else ""
            raise self.error(f"unknown effect type '{kind}'", f"{key}.type",
                             fix + f"effect types: {types}")
        if kind == "action":
            valid = ENTRY_KEYS["actions"]
            required = REQUIRED_KEYS["actions"]
        else:
            valid = tuple(f.name for f in dataclasses.fields(EFFECT_KINDS[kind])
                          if f.name != "name")
            required = tuple(f.name for f in dataclasses.fields(EFFECT_KINDS[kind])
                             if f.name != "name" and f.default is dataclasses.MISSING)
        for field in fields:
            if field not in valid:
                close = closest(field, valid)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown key '{field}' for {article(kind)} effect",
                                 f"{key}.{field}",
                                 fix + "valid keys: " + ", ".join(("type",) + valid))
        for field in required:
            if field not in fields:
                raise self.error(f"missing required key '{field}'", key,
                                 f"add '{field}'; {article(kind)} effect needs " + join_and(required))
        if kind == "action":
            parts = self.action_parts(*(fields.get(f) for f in valid), key)
            body, point, base, frame, torque, force = parts
            values = {"body": body, "point": point, "base": base, "torque": torque,
                      "force": force}
        else:
            frame = None
            values = {field: self.effect_field(name, kind, field, fields[field],
                                               f"{key}.{field}")
                      for field in valid if fields.get(field) is not None
                      or field in required}
            if "point_a" in values and values["point_a"] == values.get("point_b"):
                raise self.error(f"{kind} '{name}' joins point '{values['point_a']}' to "
                                 "itself", f"{key}.point_b", f"give two different points "
                                 f"({article(kind)} acts along the line between them)")
        self.register(name, "effect", key)
        self.effects.append(EffectDecl(name, kind, values, frame, key))

    def effect_field(self, name: str, kind: str, field: str, value, key: str):
        """One validated field of an effect (its role in the effect class's ``roles``)."""
        role = EFFECT_KINDS[kind].roles[field]
        if role in ("point", "body", "base", "coordinate"):
            return self.reference(value, role, key)
        if role == "coordinates":
            items = as_list(value)
            if not isinstance(items, list) or not items:
                raise self.error(f"expected a list of one or more coordinate names but got "
                                 f"{describe(value)}", key, "write e.g. [q1, q2]")
            for i, item in enumerate(items):
                self.reference(item, "coordinate", f"{key}[{i}]")
                if item in items[:i]:
                    raise self.error(f"coordinate '{item}' is listed twice", f"{key}[{i}]",
                                     "list each coordinate once")
            return tuple(items)
        if role == "vector":
            return self.vector(value, key, "gravity",
                               example="[gx, gy, gz] (components in the effect's base)")
        expr = self.expression(value, key, "coefficient")
        if role == "signed":
            return expr
        shown = format_expression(expr)
        at = self.at_defaults(expr)
        bound = ">= 0" if role == "nonnegative" else "> 0"
        fix = f"give {article(field)} {bound}"
        if field == "smoothing_speed":
            fix += (" (the speed over which friction changes sign: tanh(v/smoothing_speed); "
                    "e.g. 0.001)")
        if at is None:
            raise self.error(f"{field} of {kind} '{name}' is not a real number with the "
                             f"default parameters: {shown}", key, fix)
        if at < 0 or (role == "positive" and at == 0):
            problem = "is negative" if at < 0 else "is not positive"
            raise self.error(f"{field} of {kind} '{name}' {problem}: {shown} = {at!r} "
                             "with the default parameters", key, fix)
        return expr

    def add_constraint(self, name, kind, fields: Mapping, key: str) -> None:
        """A constraint of type ``kind`` with ``fields`` (see modelgen.model.constraints)."""
        self.check_new_name(name, "constraint", key)
        decl = constraint_decl(self, name, kind, dict(fields), key)
        self.register(name, "constraint", key)
        self.constraints.append(decl)

    def set_dependent(self, value, key: str = "dependent") -> None:
        """The dependent coordinates and speeds: ``{coordinates: [...], speeds: [...]}``."""
        self.dependent = dependent_decl(self, value, key)
        self.dependent_key = key

    # -- the spec ------------------------------------------------------------------
    def build(self) -> ModelSpec:
        """Resolve references, check for cycles, sort and freeze into a ModelSpec."""
        return build_spec(self)


def replay(ctx: ModelBuilder, spec: ModelSpec, parameters=None) -> ModelBuilder:
    """Declare everything of ``spec`` in ``ctx`` again (every check runs again).

    ``parameters`` replaces the spec's ``(name, default)`` pairs if given.
    Points are declared with their resolved from/base.
    """
    for c in spec.simple_coordinates:
        ctx.add_coordinate(c, f"coordinates[{len(ctx.coordinates)}]")
    for p, value in (spec.parameters if parameters is None else parameters):
        ctx.add_parameter(p, value, f"parameters.{p}")
    for i in spec.inputs:
        ctx.add_input(i, f"inputs[{len(ctx.inputs)}]")
    made = {j.base for j in spec.joints} | {j.point for j in spec.joints}
    for j in spec.joints:
        ctx.add_joint(j.name, j.kind, j.parent, j.base, j.origin or None, j.point or None,
                      f"joints.{j.name}")
    for b in spec.bases:
        if b.name not in made:
            ctx.add_base(b.name, b.parent, b.axis, b.angle, f"bases.{b.name}")
    for p in spec.points:
        if p.name not in made:
            ctx.add_point(p.name, p.parent, p.base, None, p.coordinates, f"points.{p.name}")
    for f in spec.frames:
        ctx.add_frame(f.name, f.point, f.base, f"frames.{f.name}")
    for b in spec.bodies:
        ctx.add_body(b.name, b.mass, b.G, b.base, b.inertia, f"bodies.{b.name}")
    ctx.set_gravity(spec.gravity)
    for a in spec.actions:
        ctx.add_action(a.name, a.body, a.point, a.base, None, a.torque, a.force, None,
                       f"actions.{a.name}")
    for e in spec.effects:
        ctx.add_effect(e.name, e.kind, effect_fields(e), f"effects.{e.name}")
    ctx.set_armature(dict(spec.armature) or None)
    for c in spec.constraints:
        ctx.add_constraint(c.name, c.kind, constraint_fields(c), f"constraints.{c.name}")
    if spec.dependent_speeds:
        ctx.set_dependent({"coordinates": list(spec.dependent_coordinates),
                           "speeds": list(spec.dependent_speeds)})
    # a reduced model (a scene's) may have dropped some names: their units go too
    ctx.set_units({name: unit for name, unit in spec.units
                   if ctx.kind_of(name) in ("coordinate", "parameter", "input")} or None)
    return ctx

