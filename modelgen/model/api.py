"""The model stage: YAML text or Python API calls -> a validated :class:`ModelSpec`.

Two front ends build the same immutable :class:`~modelgen.model.spec.ModelSpec`:

* :func:`load_model` / :func:`parse_model` read the YAML format below;
* :class:`Model` is a Python API with one method per YAML entry.

The YAML format (every top-level key except ``name`` is optional)::

    name: double_pendulum                # a C identifier; prefixes the generated C
    description: Planar double pendulum.
    coordinates: [q1, q2]                # their speeds are q1_dot, q2_dot
    parameters: {m1: 1.0, l1: 1.0, g: 9.81}   # name: default (a finite real number)
    inputs: [T1]
    bases:                               # rotation about axis 1|2|3 of the parent base
      B1: {parent: E, axis: 3, angle: q1}
    points:                              # r = r_from + R_base @ coordinates
      P1: {from: O, base: B1, coordinates: [l1, 0, 0]}
      P2: {frame: F1, coordinates: [l1, 0, 0]}    # from/base taken from a frame
      A:  {coordinates: [0, -3, 0]}               # absolute: from O in base E
    frames:
      F1: {point: P1, base: B1}
    bodies:                              # inertia about G in the body's base
      rod1: {mass: m1, G: P1, base: B1, inertia: [0, m1*l1**2/12, m1*l1**2/12]}
    gravity: [0, -g, 0]                  # in base E
    actions:                             # torque and force at a point, in a base
      motor: {body: rod1, point: O, base: B1, torque: [0, 0, T1], force: [0, 0, 0]}
    effects:                             # named physical effects (see below)
      spring1: {type: spring, point_a: A, point_b: P1, stiffness: k, rest_length: L0}
      hinges: {type: joint_damping, coordinates: [q1, q2], damping: c}

Effects (``effects:``): each entry has ``type`` (the ``kind`` of one class of
:data:`modelgen.model.spec.EFFECT_TYPES`, or ``action``) and that class's fields as
keys; a field with a default in the dataclass is optional.

=================== ================================================================
type                keys (optional ones in brackets)
=================== ================================================================
``gravity``         vector, [base] (default E)
``spring``          point_a, point_b, stiffness, rest_length, [preload] (default 0)
``torsion_spring``  coordinate, stiffness, [rest_angle] (default 0)
``damper``          point_a, point_b, damping
``joint_damping``   coordinates (a list of one or more), damping
``friction``        coordinate, coulomb, [viscous] (0), [static] (= coulomb),
                    [stribeck_speed] (1), [smoothing_speed] (0.001)
``drag``            body, point, density, drag_coefficient, area
``action``          the keys of an ``actions:`` entry (body, point/base or frame,
                    torque/force or vector)
=================== ================================================================

* Evaluated at the parameter defaults, ``stiffness``, ``rest_length``,
  ``damping``, ``coulomb``, ``viscous``, ``static``, ``density``,
  ``drag_coefficient`` and ``area`` must be >= 0 and ``stribeck_speed`` and
  ``smoothing_speed`` > 0; ``preload`` and ``rest_angle`` may have any sign.
* A spring or damper needs two different points; ``coordinates`` of a
  joint damping lists each coordinate once.
* Friction is regularised: the Coulomb level is multiplied by
  ``tanh(v / smoothing_speed)`` (v the coordinate's speed), so it reaches
  76% of its value at ``v = smoothing_speed``; see
  :class:`~modelgen.model.spec.FrictionEffect` for the whole law.  Friction acts
  on a coordinate, so a normal force belongs in ``coulomb`` (a block of
  mass m on an incline: ``coulomb: mu*m*g*cos(alpha)``).
* A gravity effect may use any base: the field is uniform and constant in
  that base.  Its potential energy is only counted when ``base`` is E (a
  field fixed in a moving base is not conservative), so give the vector in
  E when energies matter.
* The top-level ``gravity:`` is shorthand for a gravity effect in E named
  ``gravity`` (the spec keeps it in ``ModelSpec.gravity``); with it, no
  action or effect may be named ``gravity``.  Effects of type ``action`` are
  the same as entries of ``actions:`` except that the spec lists them in
  ``ModelSpec.effects``.

Details:

* ``inertia`` is ``[Ixx, Iyy, Izz]`` (principal moments), a full 3x3 nested
  list, or omitted (a particle: all zeros).  It must be symmetric (entries
  are compared structurally, then by ``sympy.expand`` of the difference; the
  spec holds the upper triangle mirrored) and, evaluated at the parameter
  defaults, positive semi-definite with principal moments satisfying the
  triangle inequality (relative tolerance 1e-9).  A mass must not be
  negative at the parameter defaults.
* An action gives ``torque`` and ``force`` (each defaults to zeros) or the
  seed's ``vector: [Mx, My, Mz, Fx, Fy, Fz]``; its point and base are
  ``point``/``base`` or ``frame``.
* A point or action given ``frame: F`` gets ``F``'s point and base in the
  spec.  The spec's bases and points are in topological order: the
  declaration order, except that an entry waits until its parent has been
  placed (the lexicographically smallest topological order by declaration
  index).  Frames, bodies and actions keep declaration order.
* An empty (null) section is the same as an absent one.  YAML aliases (so
  also merge keys), explicit tags, duplicate keys, non-string keys and values
  other than strings, numbers, booleans and null (e.g. dates) are rejected.
  A parameter default may also be a numeric string such as ``"1e5"`` (YAML
  1.1 reads an unquoted ``1e5`` as a string).

Which symbols an expression may use (see :data:`EXPRESSION_RULES`):

========================================== ==========================================
key                                        allowed names
========================================== ==========================================
``bases.*.angle``, ``points.*.coordinates`` coordinates, parameters, ``t``
``bodies.*.mass``, ``bodies.*.inertia``    parameters (masses and inertias are constant)
``gravity``                                parameters, ``t``
``actions.*.torque/force/vector``          coordinates, speeds, parameters, inputs, ``t``
``effects.*`` coefficients, lengths...     parameters (effect coefficients are constant)
``effects.*.vector`` (gravity)             parameters, ``t``
``effects.*`` of type action               as ``actions``
========================================== ==========================================

``pi`` and the functions of :mod:`modelgen.model.expr` may be used everywhere.

Names (see :func:`check_name`): every coordinate, parameter, input, base,
point, frame, body, action and effect name shares one namespace and must be a C
identifier (``[A-Za-z_][A-Za-z0-9_]*``, at most 63 characters) that is not:

* a C (C99, C11, C23) or C++ keyword, or a Python keyword;
* reserved by modelgen: ``t`` (time), ``pi``, ``E`` (canonical base), ``O``
  (canonical point) and the function names of :mod:`modelgen.model.expr`;
* the speed of a coordinate (``<coordinate>_dot``);
* a name starting with ``_`` (C reserves ``__x`` and ``_X``; modelgen
  reserves ``_<digit>``) or with ``mg_`` in any case (generated code).

Errors are :class:`~modelgen.errors.ModelError` with the file, 1-based line,
dotted key (``bases.B2.parent``, ``points.P1.coordinates[0]``), the
offending name and a fix.  Errors of the Python API use ``file="<api>"`` and
no line.  A failed load returns nothing, and a failed :class:`Model` method
leaves the model unchanged.
"""
from __future__ import annotations

import dataclasses
import difflib
import heapq
import json
import keyword
import math
import numbers
import os
import re
from typing import Mapping, NamedTuple, Optional

import numpy as np
import sympy
import yaml

from modelgen.model import spec as specmod
from modelgen.errors import ModelError
from modelgen.model.expr import FUNCTIONS, ExpressionParseError, format_expression, parse_expression
from modelgen.model.spec import (CANONICAL_BASE, CANONICAL_POINT, TIME, ActionSpec, BaseSpec,
                           BodySpec, FrameSpec, ModelSpec, PointSpec)

__all__ = [
    "TOP_LEVEL_KEYS", "ENTRY_KEYS", "REQUIRED_KEYS", "EXPRESSION_RULES", "API_FILE",
    "EFFECT_KINDS", "EFFECT_FIELD_ROLES",
    "MAX_NAME_LENGTH", "C_KEYWORDS", "CPP_KEYWORDS", "PYTHON_KEYWORDS", "MODELGEN_RESERVED",
    "check_name", "load_model", "parse_model", "spec_to_yaml", "Model",
]

#: Top-level keys of a model file, in the order they are processed and written.
#: Any other key is an error; a stage adding a key adds it here and reads it
#: in ``_load_context``.
TOP_LEVEL_KEYS = ("name", "description", "coordinates", "parameters", "inputs",
                  "bases", "points", "frames", "bodies", "gravity", "actions", "effects")

#: Keys of one entry of each mapping section.
ENTRY_KEYS = {
    "bases": ("parent", "axis", "angle"),
    "points": ("from", "base", "frame", "coordinates"),
    "frames": ("point", "base"),
    "bodies": ("mass", "G", "base", "inertia"),
    "actions": ("body", "point", "base", "frame", "torque", "force", "vector"),
}

#: Keys an entry must have (alternatives such as ``frame`` are checked separately).
REQUIRED_KEYS = {
    "bases": ("parent", "axis", "angle"),
    "points": ("coordinates",),
    "frames": ("point", "base"),
    "bodies": ("mass", "G", "base"),
    "actions": ("body",),
}

#: Effect ``type`` -> the spec class it builds (``action`` builds an ActionSpec).
EFFECT_KINDS = {**{cls.kind: cls for cls in specmod.EFFECT_TYPES}, "action": ActionSpec}

#: How each effect field is read: a reference (``point``, ``body``, ``base``,
#: ``coordinate``, ``coordinates``: a list of coordinates), a gravity vector
#: (``vector``) or a parameters-only expression that must be ``nonnegative``,
#: ``positive`` or may be ``signed`` at the parameter defaults.
EFFECT_FIELD_ROLES = {
    "point_a": "point", "point_b": "point", "point": "point", "body": "body",
    "base": "base", "coordinate": "coordinate", "coordinates": "coordinates",
    "vector": "vector",
    "stiffness": "nonnegative", "rest_length": "nonnegative", "damping": "nonnegative",
    "coulomb": "nonnegative", "viscous": "nonnegative", "static": "nonnegative",
    "density": "nonnegative", "drag_coefficient": "nonnegative", "area": "nonnegative",
    "stribeck_speed": "positive", "smoothing_speed": "positive",
    "preload": "signed", "rest_angle": "signed",
}

#: ``file`` of the errors raised by the Python API.
API_FILE = "<api>"

#: Longest name accepted (C99 guarantees 63 significant initial characters).
MAX_NAME_LENGTH = 63

C_KEYWORDS = frozenset("""
    auto break case char const continue default do double else enum extern float for
    goto if inline int long register restrict return short signed sizeof static struct
    switch typedef union unsigned void volatile while
    _Bool _Complex _Imaginary _Alignas _Alignof _Atomic _Generic _Noreturn
    _Static_assert _Thread_local
    alignas alignof bool constexpr false nullptr static_assert thread_local true
    typeof typeof_unqual
""".split())

CPP_KEYWORDS = frozenset("""
    alignas alignof and and_eq asm auto bitand bitor bool break case catch char char8_t
    char16_t char32_t class compl concept const consteval constexpr constinit const_cast
    continue co_await co_return co_yield decltype default delete do double dynamic_cast
    else enum explicit export extern false float for friend goto if inline int long
    mutable namespace new noexcept not not_eq nullptr operator or or_eq private protected
    public register reinterpret_cast requires return short signed sizeof static
    static_assert static_cast struct switch template this thread_local throw true try
    typedef typeid typename union unsigned using virtual void volatile wchar_t while xor
    xor_eq
""".split())

PYTHON_KEYWORDS = frozenset(keyword.kwlist)

#: Names modelgen reserves, with what they mean.
MODELGEN_RESERVED = {
    "t": "time", "pi": "the constant pi",
    CANONICAL_BASE: "the canonical base", CANONICAL_POINT: "the canonical point",
    **{name: "a function" for name in FUNCTIONS},
}


class _Rule(NamedTuple):
    kinds: tuple      # symbol kinds allowed: "coordinate", "speed", "parameter", "input", "time"
    text: str         # the allowed kinds in words
    declare: str      # where an undefined name should be declared
    why: str          # the reason for the restriction ("" if none)


#: Which symbols the expressions at each kind of key may use.
EXPRESSION_RULES = {
    "position": _Rule(("coordinate", "parameter", "time"), "coordinates, parameters and t",
                      "'coordinates' or 'parameters'",
                      " (positions and angles cannot depend on speeds or inputs)"),
    "constant": _Rule(("parameter",), "parameters", "'parameters'",
                      " (masses and inertias are constant)"),
    "gravity": _Rule(("parameter", "time"), "parameters and t", "'parameters'",
                     " (gravity is a uniform field; use an action for forces that depend "
                     "on the state or on inputs)"),
    "action": _Rule(("coordinate", "speed", "parameter", "input", "time"),
                    "coordinates, speeds, parameters, inputs and t",
                    "'coordinates', 'parameters' or 'inputs'", ""),
    "coefficient": _Rule(("parameter",), "parameters", "'parameters'",
                         " (effect coefficients, lengths and speeds are constant)"),
}

_SECTION_KIND = {"bases": "base", "points": "point", "frames": "frame",
                 "bodies": "body", "actions": "action", "effects": "effect"}
_SECTION_OF = {**{kind: section for section, kind in _SECTION_KIND.items()},
               "coordinate": "coordinates"}
_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_NUMERIC_STRING = re.compile(r"\s*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\s*\Z")
_NAME_FIX = "use ASCII letters, digits and '_', starting with a letter"
_NAMESPACE_NOTE = ("coordinates, parameters, inputs, bases, points, frames, bodies and "
                   "actions share one namespace")
_NAMESPACE_NOTE_EFFECTS = ("coordinates, parameters, inputs, bases, points, frames, bodies, "
                           "actions and effects share one namespace")


# -- small helpers -------------------------------------------------------------

def _describe(value) -> str:
    """A value's type (and value, when short) for messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, numbers.Number):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)} item" + ("" if len(value) == 1 else "s")
    return f"a {type(value).__name__}"


def _listing(names, limit: int = 10) -> str:
    names = list(names)
    if not names:
        return "none"
    if len(names) > limit:
        return ", ".join(names[:limit]) + f" and {len(names) - limit} more"
    return ", ".join(names)


def _a(noun: str) -> str:
    """The noun with its indefinite article: 'a base name', 'an input name'."""
    return ("an " if noun[:1] in "aeiou" else "a ") + noun


def _and(words) -> str:
    """'a', 'a and b', 'a, b and c'."""
    words = list(words)
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def _closest(word: str, candidates) -> Optional[str]:
    matches = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.6)
    return matches[0] if matches else None


def _as_list(value):
    """A list/tuple (or numpy array, sympy Matrix) as a list; anything else unchanged."""
    if isinstance(value, (list, tuple)):
        return list(value)
    if isinstance(value, sympy.MatrixBase) or (
            hasattr(value, "tolist") and not isinstance(value, (str, sympy.Basic))):
        return value.tolist()
    return value


def _quote_expr(value) -> str:
    text = value if isinstance(value, str) else repr(value)
    if len(text) > 80:
        text = text[:60] + "..." + text[-15:]
    return repr(text)


def check_name(name, *, file: Optional[str] = API_FILE, line: Optional[int] = None,
               key: Optional[str] = None, what: str = "name",
               modelgen_reserved: bool = True) -> str:
    """Check that ``name`` may name a model entity; return it or raise ModelError.

    Applies the syntax and reserved-word rules of the module docstring (not
    the namespace rules, which need the whole model).  ``what`` names the
    kind of name in messages; ``modelgen_reserved=False`` skips the
    :data:`MODELGEN_RESERVED` names (used for the model's own name, which is
    a C prefix, not a symbol).

    >>> check_name("q1")
    'q1'
    >>> check_name("int")
    Traceback (most recent call last):
    ...
    modelgen.errors.ModelError: <api>: 'int' is a C keyword; fix: rename it, e.g. 'int1'
    """
    def fail(problem, fix):
        raise ModelError(problem, file=file, line=line, key=key, fix=fix)

    if not isinstance(name, str):
        fix = f"write {_a(what)} such as q1 ({_NAME_FIX})"
        if isinstance(name, bool):
            fix += "; YAML reads unquoted yes/no/on/off/true/false as booleans, so quote it"
        fail(f"expected {_a(what)} but got {_describe(name)}", fix)
    if not _NAME_RE.match(name):
        fail(f"'{name}' is not a valid {what}", _NAME_FIX)
    if len(name) > MAX_NAME_LENGTH:
        fail(f"{what} '{name[:20]}...' is {len(name)} characters long",
             f"use at most {MAX_NAME_LENGTH} characters")
    if name.startswith("_"):
        fail(f"'{name}' starts with '_', which is reserved for generated code",
             "start the name with a letter")
    if name.lower().startswith("mg_"):
        fail(f"'{name}' starts with '{name[:3]}', which is reserved for generated code",
             "choose a name that does not start with 'mg_'")
    if modelgen_reserved and name in MODELGEN_RESERVED:
        fail(f"'{name}' is reserved by modelgen ({MODELGEN_RESERVED[name]})",
             f"rename it, e.g. '{name}1'")
    for words, language in ((C_KEYWORDS, "C"), (CPP_KEYWORDS, "C++"),
                            (PYTHON_KEYWORDS, "Python")):
        if name in words:
            fail(f"'{name}' is a {language} keyword", f"rename it, e.g. '{name}1'")
    return name


# -- declarations: validated entries, before references are resolved ----------

class _Base(NamedTuple):
    name: str
    parent: str
    axis: int
    angle: sympy.Expr
    key: str


class _Point(NamedTuple):
    name: str
    parent: Optional[str]   # None when given by a frame
    base: Optional[str]
    frame: Optional[str]
    coordinates: tuple
    key: str


class _Frame(NamedTuple):
    name: str
    point: str
    base: str
    key: str


class _Body(NamedTuple):
    name: str
    mass: sympy.Expr
    G: str
    base: str
    inertia: tuple
    key: str


class _Action(NamedTuple):
    name: str
    body: str
    point: Optional[str]
    base: Optional[str]
    frame: Optional[str]
    torque: tuple
    force: tuple
    key: str


class _Effect(NamedTuple):
    name: str
    kind: str               # a key of EFFECT_KINDS
    fields: dict            # field -> validated value (given fields only)
    frame: Optional[str]    # action effects given a frame
    key: str


class _Context:
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
        self.kinds: dict = {}         # name -> (kind, key) for every declared name
        self.speeds: dict = {}        # speed name -> coordinate
        self.symbols: dict = {}       # name -> Symbol (coordinates, speeds, parameters, inputs)
        self.coordinates: list = []
        self.parameters: list = []    # (name, float)
        self.defaults: dict = {}      # Symbol -> sympy Float, for the physical checks
        self.inputs: list = []
        self.bases: list = []
        self.points: list = []
        self.frames: list = []
        self.bodies: list = []
        self.actions: list = []
        self.effects: list = []
        self.gravity: Optional[tuple] = None
        self.sources: list = []       # (key prefix, file, lines) of keys from other files
        self._allowed: dict = {}

    def clone(self) -> "_Context":
        other = _Context(self.file, self.lines)
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
            note = _NAMESPACE_NOTE_EFFECTS if "effect" in (kind, other_kind) \
                else _NAMESPACE_NOTE
            raise self.error(f"duplicate name '{name}': already declared as "
                             f"{_a(other_kind)} at {self.place(other_key, key)}", key,
                             f"rename one of them; {note}")
        if name in self.speeds:
            raise self.error(f"'{name}' is the speed of coordinate '{self.speeds[name]}'",
                             key, "rename it; the speed of a coordinate q is named q_dot")
        return name

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
                return self.error(f"{kind} '{name}' is not allowed in expression "
                                  f"{_quote_expr(value)}", key,
                                  f"use only {rule.text} here{rule.why}")
            close = _closest(name, list(self.allowed(rule_name)))
            fix = f"did you mean '{close}'? Otherwise " if close else ""
            fix += (f"declare '{name}' under {rule.declare}; only {rule.text} "
                    f"may be used here")
            return self.error(f"undefined name '{name}' in expression {_quote_expr(value)}",
                              key, fix)
        problem = "invalid expression: " + exc.reason
        if exc.column is not None:
            problem += f" at column {exc.column} of {_quote_expr(exc.text)}"
        elif exc.text is not None:
            problem += f" in {_quote_expr(exc.text)}"
        return self.error(problem, key, exc.hint or "correct the expression")

    def vector(self, value, key: str, rule: str, length: int = 3,
               example: str = "[x, y, z]") -> tuple:
        items = _as_list(value)
        if not isinstance(items, list):
            raise self.error(f"expected a list of {length} components but got "
                             f"{_describe(value)}", key, f"write {example}")
        if len(items) != length:
            raise self.error(f"expected {length} components but got {len(items)}", key,
                             f"write {example}")
        return tuple(self.expression(item, f"{key}[{i}]", rule)
                     for i, item in enumerate(items))

    def reference(self, value, what: str, key: str) -> str:
        """A reference to a base, point, body or frame: must be a string name."""
        if not isinstance(value, str):
            raise self.error(f"expected {_a(what)} name but got {_describe(value)}", key,
                             f"write the name of {_a(what)}")
        return value

    def number(self, value, key: str, what: str) -> float:
        if isinstance(value, str) and _NUMERIC_STRING.match(value):
            value = float(value)
        if (isinstance(value, bool) or not isinstance(value, numbers.Real)
                or not math.isfinite(float(value))):
            raise self.error(f"{what} must be a finite real number but is "
                             f"{_describe(value)}", key, "write a number such as 1.0")
        return float(value)

    def at_defaults(self, expr: sympy.Expr) -> Optional[float]:
        """Value of a parameters-only expression at the defaults (None if not real)."""
        value = expr.xreplace(self.defaults)
        try:
            result = float(value)
        except TypeError:
            return None
        return result if math.isfinite(result) else None

    # -- declarations ---------------------------------------------------------
    def set_name(self, name, key: str = "name") -> None:
        if not isinstance(name, str) or not _NAME_RE.match(name) or len(name) > MAX_NAME_LENGTH:
            shown = f"'{name}'" if isinstance(name, str) else _describe(name)
            raise self.error(f"model name {shown} is not a valid C identifier", key,
                             f"{_NAME_FIX} and at most {MAX_NAME_LENGTH} characters "
                             "(it prefixes every generated C function)")
        check_name(name, file=self.file, line=self.line_of(key), key=key, what="model name",
                   modelgen_reserved=False)
        self.name = name

    def set_description(self, text, key: str = "description") -> None:
        if text is None:
            text = ""
        if not isinstance(text, str):
            raise self.error(f"expected a string but got {_describe(text)}", key,
                             "write the description as text (quote it if needed)")
        self.description = text

    def add_coordinate(self, name, key: str) -> None:
        self.check_new_name(name, "coordinate", key)
        speed = specmod.speed_name(name)
        if speed in self.kinds:
            other_kind, other_key = self.kinds[speed]
            raise self.error(f"the speed of coordinate '{name}' would be '{speed}', which "
                             f"is already declared as {_a(other_kind)} at {other_key}", key,
                             f"rename {other_kind} '{speed}' or coordinate '{name}'")
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
            raise self.error(f"axis must be 1, 2 or 3 but is {_describe(axis)}",
                             f"{key}.axis", "use 1, 2 or 3 for the parent's x, y or z axis")
        angle = self.expression(angle, f"{key}.angle", "position")
        self.register(name, "base", key)
        self.bases.append(_Base(name, parent, int(axis), angle, key))

    def add_point(self, name, parent, base, frame, coordinates, key: str) -> None:
        self.check_new_name(name, "point", key)
        if frame is not None:
            if parent is not None or base is not None:
                raise self.error("'frame' cannot be combined with 'from' or 'base'",
                                 f"{key}.frame", "give either 'frame' or 'from' and 'base'")
            frame = self.reference(frame, "frame", f"{key}.frame")
        elif parent is None and base is None:
            parent, base = CANONICAL_POINT, CANONICAL_BASE
        elif base is None:
            raise self.error("missing required key 'base' (needed with 'from')", key,
                             "add 'base', or use 'frame' instead of 'from'")
        elif parent is None:
            raise self.error("missing required key 'from' (needed with 'base')", key,
                             "add 'from', or use 'frame' instead of 'base'")
        if frame is None:
            parent = self.reference(parent, "point", f"{key}.from")
            base = self.reference(base, "base", f"{key}.base")
        where = f"base '{base}'" if frame is None else f"frame '{frame}'"
        coordinates = self.vector(coordinates, f"{key}.coordinates", "position",
                                  example=f"[x, y, z] (components in {where})")
        self.register(name, "point", key)
        self.points.append(_Point(name, parent, base, frame, coordinates, key))

    def add_frame(self, name, point, base, key: str) -> None:
        self.check_new_name(name, "frame", key)
        point = self.reference(point, "point", f"{key}.point")
        base = self.reference(base, "base", f"{key}.base")
        self.register(name, "frame", key)
        self.frames.append(_Frame(name, point, base, key))

    def add_body(self, name, mass, G, base, inertia, key: str) -> None:
        self.check_new_name(name, "body", key)
        mass = self.expression(mass, f"{key}.mass", "constant")
        G = self.reference(G, "point", f"{key}.G")
        base = self.reference(base, "base", f"{key}.base")
        inertia = self.inertia(inertia, f"{key}.inertia", name)
        mass_value = self.at_defaults(mass)
        if mass_value is None:
            raise self.error(f"mass of body '{name}' is not a real number with the default "
                             f"parameters: {format_expression(mass)}", f"{key}.mass",
                             "give a mass >= 0")
        if mass_value < 0:
            raise self.error(f"mass of body '{name}' is negative: {format_expression(mass)} "
                             f"= {mass_value!r} with the default parameters", f"{key}.mass",
                             "give a mass >= 0")
        self.check_physical_inertia(name, inertia, f"{key}.inertia")
        self.register(name, "body", key)
        self.bodies.append(_Body(name, mass, G, base, inertia, key))

    def inertia(self, value, key: str, body: str) -> tuple:
        zero = sympy.Integer(0)
        if value is None:
            return ((zero,) * 3,) * 3
        shape = "write [Ixx, Iyy, Izz] (principal moments) or a 3x3 matrix [[Ixx, Ixy, Ixz], " \
                "[Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]"
        rows = _as_list(value)
        if not isinstance(rows, list) or len(rows) != 3:
            raise self.error("expected 3 principal moments or a 3x3 matrix but got "
                             f"{_describe(value)}", key, shape)
        rows = [_as_list(row) for row in rows]
        if not any(isinstance(row, list) for row in rows):
            diagonal = [self.expression(item, f"{key}[{i}]", "constant")
                        for i, item in enumerate(rows)]
            return tuple(tuple(diagonal[i] if i == j else zero for j in range(3))
                         for i in range(3))
        for i, row in enumerate(rows):
            if not isinstance(row, list) or len(row) != 3:
                raise self.error(f"row {i + 1} of the 3x3 inertia matrix is "
                                 f"{_describe(row)}, not a list of 3 items", key, shape)
        matrix = [[self.expression(item, f"{key}[{i}][{j}]", "constant")
                   for j, item in enumerate(row)] for i, row in enumerate(rows)]
        for i in range(3):
            for j in range(i + 1, 3):
                upper, lower = matrix[i][j], matrix[j][i]
                if upper != lower and sympy.expand(upper - lower) != 0:
                    raise self.error(
                        f"inertia of body '{body}' is not symmetric: entry [{i}][{j}] is "
                        f"{format_expression(upper)} but entry [{j}][{i}] is "
                        f"{format_expression(lower)}", key,
                        f"make entries [{i}][{j}] and [{j}][{i}] equal")
                matrix[j][i] = upper
        return tuple(tuple(row) for row in matrix)

    def check_physical_inertia(self, body: str, inertia: tuple, key: str) -> None:
        values = [[self.at_defaults(item) for item in row] for row in inertia]
        if any(v is None for row in values for v in row):
            raise self.error(f"inertia of body '{body}' is not real with the default "
                             "parameters", key, "check the inertia expressions")
        moments = np.linalg.eigvalsh(np.array(values, dtype=float))
        tol = 1e-9 * max(1.0, float(np.max(np.abs(moments))))
        shown = "[" + ", ".join(f"{m:.6g}" for m in moments) + "]"
        if moments[0] < -tol:
            raise self.error(f"inertia of body '{body}' has a negative principal moment "
                             f"with the default parameters: {shown}", key,
                             "give a positive semi-definite inertia tensor about G")
        if moments[0] + moments[1] < moments[2] - tol:
            raise self.error(f"inertia of body '{body}' violates the triangle inequality "
                             f"with the default parameters: principal moments {shown}, "
                             f"{moments[0]:.6g} + {moments[1]:.6g} < {moments[2]:.6g}", key,
                             "no rigid body has these moments; each principal moment must "
                             "be at most the sum of the other two")

    def set_gravity(self, vector, key: str = "gravity") -> None:
        if vector is None:
            self.gravity = None
            return
        self.gravity = self.vector(vector, key, "gravity",
                                   example="[gx, gy, gz] (components in base E)")

    def add_action(self, name, body, point, base, frame, torque, force, vector,
                   key: str) -> None:
        self.check_new_name(name, "action", key)
        parts = self.action_parts(body, point, base, frame, torque, force, vector, key)
        self.register(name, "action", key)
        self.actions.append(_Action(name, *parts, key))

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
            raise self.error(f"expected an effect type but got {_describe(kind)}",
                             f"{key}.type", f"write one of {types}")
        if kind not in EFFECT_KINDS:
            close = _closest(kind, EFFECT_KINDS)
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
                close = _closest(field, valid)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown key '{field}' for {_a(kind)} effect",
                                 f"{key}.{field}",
                                 fix + "valid keys: " + ", ".join(("type",) + valid))
        for field in required:
            if field not in fields:
                raise self.error(f"missing required key '{field}'", key,
                                 f"add '{field}'; {_a(kind)} effect needs " + _and(required))
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
                                 f"({_a(kind)} acts along the line between them)")
        self.register(name, "effect", key)
        self.effects.append(_Effect(name, kind, values, frame, key))

    def effect_field(self, name: str, kind: str, field: str, value, key: str):
        """One validated field of an effect (see :data:`EFFECT_FIELD_ROLES`)."""
        role = EFFECT_FIELD_ROLES[field]
        if role in ("point", "body", "base", "coordinate"):
            return self.reference(value, role, key)
        if role == "coordinates":
            items = _as_list(value)
            if not isinstance(items, list) or not items:
                raise self.error(f"expected a list of one or more coordinate names but got "
                                 f"{_describe(value)}", key, "write e.g. [q1, q2]")
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
        fix = f"give {_a(field)} {bound}"
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

    # -- resolution --------------------------------------------------------------
    def resolve(self, ref: str, kind: str, key: str, canonical: Optional[str] = None) -> str:
        """Check that ``ref`` names a declared ``kind`` (or the canonical one)."""
        if ref == canonical or self.kind_of(ref) == kind:
            return ref
        section = _SECTION_OF[kind]
        known = ([canonical] if canonical else []) + \
            [name for name, (k, _) in self.kinds.items() if k == kind]
        other = self.kind_of(ref)
        if other is not None:
            raise self.error(f"'{ref}' is {_a(other)}, not {_a(kind)}", key,
                             f"name {_a(kind)} here (known {section}: {_listing(known)})")
        close = _closest(ref, known)
        if close:
            fix = f"did you mean '{close}'? Otherwise declare '{ref}' under '{section}'"
        else:
            fix = f"declare '{ref}' under '{section}' (known {section}: {_listing(known)})"
        raise self.error(f"unknown {kind} '{ref}'", key, fix)

    def build(self) -> ModelSpec:
        """Resolve references, check for cycles, sort and freeze into a ModelSpec."""
        if self.name is None:
            raise self.error("missing required key 'name'", None,
                             "add 'name: <model name>' (a C identifier) at the top level")
        for b in self.bases:
            self.resolve(b.parent, "base", f"{b.key}.parent", CANONICAL_BASE)
        bases = _topological(self.bases, lambda b: b.parent)
        if isinstance(bases, tuple):
            first = self._decl(self.bases, bases[0])
            raise self.error("the bases form a cycle: " + " -> ".join(bases) +
                             " (each base is rotated from the next)", f"{first.key}.parent",
                             "make one of these bases a child of 'E' or of a base outside "
                             "the cycle")
        frames = {}
        for f in self.frames:
            self.resolve(f.point, "point", f"{f.key}.point", CANONICAL_POINT)
            self.resolve(f.base, "base", f"{f.key}.base", CANONICAL_BASE)
            frames[f.name] = f
        points = []
        for p in self.points:
            if p.frame is not None:
                self.resolve(p.frame, "frame", f"{p.key}.frame")
                frame = frames[p.frame]
                p = p._replace(parent=frame.point, base=frame.base)
            else:
                self.resolve(p.parent, "point", f"{p.key}.from", CANONICAL_POINT)
                self.resolve(p.base, "base", f"{p.key}.base", CANONICAL_BASE)
            points.append(p)
        ordered_points = _topological(points, lambda p: p.parent)
        if isinstance(ordered_points, tuple):
            first = self._decl(points, ordered_points[0])
            via = "frame" if first.frame is not None else "from"
            raise self.error("the points form a cycle: " + " -> ".join(ordered_points) +
                             " (each point is measured from the next)",
                             f"{first.key}.{via}",
                             "measure one of these points from 'O' or from a point outside "
                             "the cycle")
        for body in self.bodies:
            self.resolve(body.G, "point", f"{body.key}.G", CANONICAL_POINT)
            self.resolve(body.base, "base", f"{body.key}.base", CANONICAL_BASE)
        actions = []
        for a in self.actions:
            self.resolve(a.body, "body", f"{a.key}.body")
            if a.frame is not None:
                self.resolve(a.frame, "frame", f"{a.key}.frame")
                frame = frames[a.frame]
                a = a._replace(point=frame.point, base=frame.base)
            else:
                self.resolve(a.point, "point", f"{a.key}.point", CANONICAL_POINT)
                self.resolve(a.base, "base", f"{a.key}.base", CANONICAL_BASE)
            actions.append(a)
        effects = [self.resolve_effect(e, frames) for e in self.effects]
        if self.gravity is not None and self.kind_of("gravity") in ("action", "effect"):
            kind, key = self.kinds["gravity"]
            raise self.error(f"{_a(kind)} is named 'gravity', the name of the top-level "
                             "gravity", key, f"rename the {kind}, or remove the top-level "
                             "'gravity:' and declare it as an effect of type gravity")
        return ModelSpec(
            name=self.name,
            description=self.description,
            coordinates=tuple(self.coordinates),
            parameters=tuple(self.parameters),
            inputs=tuple(self.inputs),
            bases=tuple(BaseSpec(b.name, b.parent, b.axis, b.angle) for b in bases),
            points=tuple(PointSpec(p.name, p.parent, p.base, p.coordinates)
                         for p in ordered_points),
            frames=tuple(FrameSpec(f.name, f.point, f.base) for f in self.frames),
            bodies=tuple(BodySpec(b.name, b.mass, b.G, b.base, b.inertia)
                         for b in self.bodies),
            gravity=self.gravity,
            actions=tuple(ActionSpec(a.name, a.body, a.point, a.base, a.torque, a.force)
                          for a in actions),
            effects=tuple(effects),
            source=None if self.file == API_FILE else self.file,
            lines=tuple(self.lines.items()),
        )

    def resolve_effect(self, e: _Effect, frames: dict):
        """Check an effect's references and build its spec dataclass."""
        values = dict(e.fields)
        if e.frame is not None:
            self.resolve(e.frame, "frame", f"{e.key}.frame")
            values["point"], values["base"] = frames[e.frame].point, frames[e.frame].base
        for field, value in values.items():
            role = EFFECT_FIELD_ROLES.get(field)
            where = f"{e.key}.{field}"
            if e.frame is not None and field in ("point", "base"):
                continue
            if role in ("point", "base"):
                self.resolve(value, role, where,
                             CANONICAL_POINT if role == "point" else CANONICAL_BASE)
            elif role in ("body", "coordinate"):
                self.resolve(value, role, where)
            elif role == "coordinates":
                for i, item in enumerate(value):
                    self.resolve(item, "coordinate", f"{where}[{i}]")
        return EFFECT_KINDS[e.kind](name=e.name, **values)

    @staticmethod
    def _decl(items, name):
        return next(item for item in items if item.name == name)


def _topological(items: list, parent_of):
    """Parents-first order of ``items``; ties keep declaration order.

    Returns the sorted list, or, if some items form a cycle, the cycle as a
    tuple of names starting at its earliest-declared member and ending with
    it again (``("B1", "B2", "B1")``).
    """
    index = {item.name: i for i, item in enumerate(items)}
    children: dict = {}
    heap = []
    for i, item in enumerate(items):
        parent = parent_of(item)
        if parent in index:
            children.setdefault(parent, []).append(i)
        else:
            heap.append(i)
    heapq.heapify(heap)
    order = []
    while heap:
        i = heapq.heappop(heap)
        order.append(items[i])
        for child in children.get(items[i].name, ()):
            heapq.heappush(heap, child)
    if len(order) == len(items):
        return order
    placed = {item.name for item in order}
    remaining = [item for item in items if item.name not in placed]
    # follow parents from the first unplaced item until a name repeats
    seen: list = []
    name = remaining[0].name
    while name not in seen:
        seen.append(name)
        name = parent_of(items[index[name]])
    cycle = seen[seen.index(name):]
    start = min(cycle, key=index.__getitem__)
    k = cycle.index(start)
    cycle = cycle[k:] + cycle[:k]
    return tuple(cycle + [start])


# -- YAML front end ---------------------------------------------------------------

class _Loader(yaml.SafeLoader):
    """SafeLoader that refuses aliases (no billion-laughs expansion)."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise _YamlProblem(f"YAML alias '*{event.anchor}' is not supported (aliases are "
                               "refused)", event.start_mark.line + 1,
                               "write the value out in full")
        return super().compose_node(parent, index)


class _YamlProblem(Exception):
    def __init__(self, problem: str, line: Optional[int], fix: str, key: Optional[str] = None):
        super().__init__(problem)
        self.problem, self.line, self.fix, self.key = problem, line, fix, key


_SCALAR_TAGS = {"tag:yaml.org,2002:" + t for t in ("str", "int", "float", "bool", "null")}
_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"


def _plain(node, path: str, lines: dict, loader: _Loader):
    """Convert a composed YAML node to plain Python data, recording lines by key."""
    line = node.start_mark.line + 1
    if path not in lines:
        lines[path] = line
    if isinstance(node, yaml.MappingNode):
        if node.tag != _MAP_TAG:
            raise _YamlProblem(f"unsupported YAML tag '{node.tag}'", line,
                               "remove the tag", path or None)
        result: dict = {}
        first_line: dict = {}
        for key_node, value_node in node.value:
            key_line = key_node.start_mark.line + 1
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag != "tag:yaml.org,2002:str":
                if key_node.tag == "tag:yaml.org,2002:merge":
                    raise _YamlProblem("YAML merge keys '<<' are not supported", key_line,
                                       "write the keys out in full", path or None)
                shown = getattr(key_node, "value", "?")
                shown = shown if isinstance(shown, str) else "a collection"
                raise _YamlProblem(f"key {shown!r} is not a name (YAML reads it as "
                                   f"{key_node.tag.rsplit(':', 1)[-1]})", key_line,
                                   f"quote the key: \"{shown}\"" if isinstance(shown, str)
                                   else "use a name as the key", path or None)
            key = key_node.value
            child = f"{path}.{key}" if path else key
            if key in result:
                raise _YamlProblem(f"duplicate key '{key}' (first at line {first_line[key]})",
                                   key_line, "remove or rename one of them", child)
            first_line[key] = key_line
            lines[child] = key_line
            result[key] = _plain(value_node, child, lines, loader)
        return result
    if isinstance(node, yaml.SequenceNode):
        if node.tag != _SEQ_TAG:
            raise _YamlProblem(f"unsupported YAML tag '{node.tag}'", line, "remove the tag",
                               path or None)
        return [_plain(item, f"{path}[{i}]", lines, loader)
                for i, item in enumerate(node.value)]
    if node.tag not in _SCALAR_TAGS:
        implicit = loader.resolve(yaml.ScalarNode, node.value, (True, False))
        if node.tag == implicit:
            raise _YamlProblem(f"unsupported YAML value {node.value!r} (read as "
                               f"{node.tag.rsplit(':', 1)[-1]})", line, "quote the value",
                               path or None)
        raise _YamlProblem(f"unsupported YAML tag '{node.tag}'", line, "remove the tag",
                           path or None)
    return loader.construct_object(node, deep=True)


def _compose(text: str, file: str):
    """Parse YAML text into plain data and a {dotted key: line} table."""
    loader = _Loader(text)
    try:
        try:
            node = loader.get_single_node()
            if node is None:
                return None, {}
            lines: dict = {}
            data = _plain(node, "", lines, loader)
            lines.pop("", None)
            return data, lines
        finally:
            loader.dispose()
    except _YamlProblem as exc:
        raise ModelError(exc.problem, file=file, line=exc.line, key=exc.key,
                         fix=exc.fix) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = f"invalid YAML: {exc.problem}"
        if exc.context:
            problem += f" ({exc.context})"
        raise ModelError(problem, file=file, line=mark.line + 1 if mark else None,
                         fix="correct the YAML syntax near this line") from None
    except yaml.YAMLError as exc:
        raise ModelError(f"invalid YAML: {exc}", file=file,
                         fix="correct the YAML syntax") from None


def _check_keys(ctx: _Context, entry: dict, section: str, key: str) -> None:
    valid = ENTRY_KEYS[section]
    for field in entry:
        if field not in valid:
            close = _closest(field, valid)
            fix = f"did you mean '{close}'? " if close else ""
            fix += "valid keys: " + ", ".join(valid)
            raise ctx.error(f"unknown key '{field}'", f"{key}.{field}", fix)
    for field in REQUIRED_KEYS[section]:
        if field not in entry:
            kind = _SECTION_KIND[section]
            raise ctx.error(f"missing required key '{field}'", key,
                            f"add '{field}'; a {kind} needs " + _and(REQUIRED_KEYS[section]))


_SECTION_EXAMPLES = {
    "bases": "B1: {parent: E, axis: 3, angle: q1}",
    "points": "P1: {from: O, base: B1, coordinates: [l1, 0, 0]}",
    "frames": "F1: {point: P1, base: B1}",
    "bodies": "rod1: {mass: m1, G: G1, base: B1, inertia: [I1, I2, I3]}",
    "actions": "motor: {body: rod1, point: O, base: B1, torque: [0, 0, T1]}",
    "effects": "spring1: {type: spring, point_a: A, point_b: P1, stiffness: k, "
               "rest_length: L0}",
}


def _mapping_entries(ctx: _Context, value, section: str, key: str, kind: str):
    """``(name, entry, key)`` of a mapping section whose entries are mappings."""
    if value is None:
        return
    example = _SECTION_EXAMPLES[section]
    if not isinstance(value, dict):
        raise ctx.error(f"expected a mapping of {kind} names to definitions but got "
                        f"{_describe(value)}", key,
                        f"write one entry per line, e.g. '{example}'")
    for name, entry in value.items():
        entry_key = f"{key}.{name}"
        if not isinstance(entry, dict):
            raise ctx.error(f"expected a mapping but got {_describe(entry)}", entry_key,
                            f"write it like '{example}'")
        yield name, entry, entry_key


def _load_effects(ctx: _Context, value, key: str = "effects") -> None:
    """Add the entries of an ``effects:`` mapping (``key``: its dotted key)."""
    for name, entry, entry_key in _mapping_entries(ctx, value, "effects", key, "effect"):
        if "type" not in entry:
            raise ctx.error("missing required key 'type'", entry_key,
                            "add 'type: <effect type>', one of " + ", ".join(EFFECT_KINDS))
        fields = {k: v for k, v in entry.items() if k != "type"}
        ctx.add_effect(name, entry["type"], fields, entry_key)


def _load_parameters(ctx: _Context, value, key: str = "parameters") -> None:
    """Add the entries of a ``parameters:`` mapping (``key``: its dotted key)."""
    if value is None:
        return
    if not isinstance(value, dict):
        raise ctx.error(f"expected a mapping of parameter names to defaults but got "
                        f"{_describe(value)}", key, f"write {key}: {{m: 1.0, g: 9.81}}")
    for name, default in value.items():
        ctx.add_parameter(name, default, f"{key}.{name}")


def _check_top_level(data, ctx: "_Context", what: str, keys, start: str) -> None:
    """A parsed file is a non-empty mapping whose keys are all in ``keys``.

    Shared by model and scene files; ``start`` says how such a file begins.
    """
    if data is None:
        raise ModelError(f"the {what} file is empty", file=ctx.file, line=1, fix=start)
    if not isinstance(data, dict):
        raise ModelError(f"expected a mapping of {what} keys but got {_describe(data)}",
                         file=ctx.file, line=1, fix=f"{start} and use the keys " + ", ".join(keys))
    for key in data:
        if key not in keys:
            close = _closest(key, keys)
            fix = f"did you mean '{close}'? " if close else ""
            raise ctx.error(f"unknown key '{key}'", key, fix + "valid keys: " + ", ".join(keys))


def _load_tree(data, lines: dict, file: str) -> ModelSpec:
    return _load_context(data, lines, file).build()


def _load_context(data, lines: dict, file: str) -> _Context:
    """The validated declarations of a parsed model file, not yet resolved."""
    ctx = _Context(file, lines)
    _check_top_level(data, ctx, "model", TOP_LEVEL_KEYS, "start with 'name: <model name>'")
    if "name" not in data:
        raise ModelError("missing required key 'name'", file=file, line=1,
                         fix="add 'name: <model name>' (a C identifier) at the top level")
    ctx.set_name(data["name"])
    ctx.set_description(data.get("description"))

    def names_list(section: str):
        value = data.get(section)
        if value is None:
            return []
        if not isinstance(value, list):
            example = "q1, q2" if section == "coordinates" else "T1, T2"
            raise ctx.error(f"expected a list of names but got {_describe(value)}", section,
                            f"write {section}: [{example}]")
        return value

    for i, name in enumerate(names_list("coordinates")):
        ctx.add_coordinate(name, f"coordinates[{i}]")
    _load_parameters(ctx, data.get("parameters"))
    for i, name in enumerate(names_list("inputs")):
        ctx.add_input(name, f"inputs[{i}]")

    def entries(section: str):
        for name, entry, key in _mapping_entries(ctx, data.get(section), section, section,
                                                 _SECTION_KIND[section]):
            _check_keys(ctx, entry, section, key)
            yield name, entry, key

    for name, e, key in entries("bases"):
        ctx.add_base(name, e["parent"], e["axis"], e["angle"], key)
    for name, e, key in entries("points"):
        ctx.add_point(name, e.get("from"), e.get("base"), e.get("frame"),
                      e["coordinates"], key)
    for name, e, key in entries("frames"):
        ctx.add_frame(name, e["point"], e["base"], key)
    for name, e, key in entries("bodies"):
        ctx.add_body(name, e["mass"], e["G"], e["base"], e.get("inertia"), key)
    if "gravity" in data:
        ctx.set_gravity(data["gravity"])
    for name, e, key in entries("actions"):
        ctx.add_action(name, e["body"], e.get("point"), e.get("base"), e.get("frame"),
                       e.get("torque"), e.get("force"), e.get("vector"), key)
    _load_effects(ctx, data.get("effects"))
    return ctx


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
    return _parse_context(text, source).build()


def _parse_context(text: str, source: str) -> _Context:
    if not isinstance(text, str):
        raise ModelError(f"expected YAML text but got {_describe(text)}", file=source,
                         fix="pass the file's text, or use load_model(path)")
    data, lines = _compose(text, source)
    return _load_context(data, lines, source)


def _read_text(path, what: str = "model") -> tuple:
    """``(file name, text)`` of a UTF-8 file, or a ModelError naming the file."""
    file = os.fspath(path)
    try:
        with open(file, encoding="utf-8") as handle:
            return file, handle.read()
    except OSError as exc:
        raise ModelError(f"cannot read the {what} file: {exc.strerror or exc}", file=file,
                         fix="check the path") from None
    except UnicodeDecodeError as exc:
        raise ModelError(f"the {what} file is not UTF-8 text ({exc.reason})", file=file,
                         fix="save the file as UTF-8") from None


def load_model(path) -> ModelSpec:
    """Load and validate a model file.

    >>> spec = load_model("models/double_pendulum.yaml")   # doctest: +SKIP
    >>> spec.coordinates                                      # doctest: +SKIP
    ('q1', 'q2')
    """
    file, text = _read_text(path)
    return parse_model(text, source=file)


# -- YAML writer ---------------------------------------------------------------------

_RESOLVER = yaml.resolver.Resolver()
_PLAIN_SAFE = re.compile(r"-?[A-Za-z0-9_(][A-Za-z0-9_ .+\-*/()]*\Z")


def _yaml_scalar(text: str, numbers_ok: bool = False) -> str:
    """``text`` as a YAML scalar that reads back as the same string (or number)."""
    if _PLAIN_SAFE.match(text) and not text.endswith(" "):
        tag = _RESOLVER.resolve(yaml.ScalarNode, text, (True, False)).rsplit(":", 1)[-1]
        if tag == "str" or (numbers_ok and tag == "int"):
            return text
    return json.dumps(text)


def _yaml_expr(expr) -> str:
    return _yaml_scalar(format_expression(expr), numbers_ok=True)


def _yaml_vector(items) -> str:
    return "[" + ", ".join(_yaml_expr(item) for item in items) + "]"


def _yaml_float(value: float) -> str:
    text = repr(float(value))
    if "e" in text and "." not in text.split("e")[0]:
        mantissa, exponent = text.split("e")
        text = f"{mantissa}.0e{exponent}"
    return text


def spec_to_yaml(spec: ModelSpec) -> str:
    """Write a ModelSpec in the YAML format of :func:`parse_model`.

    ``parse_model(spec_to_yaml(spec)) == spec``.  Points given by a frame are
    written with their resolved ``from``/``base``.

    >>> spec = Model("m").add_coordinate("q").add_base("B", parent="E", axis=3,
    ...                                                angle="q").spec()
    >>> print(spec_to_yaml(spec), end="")
    name: m
    coordinates: [q]
    bases:
      B: {parent: E, axis: 3, angle: q}
    """
    name = _yaml_scalar
    out = [f"name: {name(spec.name)}"]
    if spec.description:
        out.append(f"description: {name(spec.description)}")
    if spec.coordinates:
        out.append("coordinates: [" + ", ".join(name(c) for c in spec.coordinates) + "]")
    if spec.parameters:
        out.append("parameters:")
        out += [f"  {name(p)}: {_yaml_float(v)}" for p, v in spec.parameters]
    if spec.inputs:
        out.append("inputs: [" + ", ".join(name(i) for i in spec.inputs) + "]")
    if spec.bases:
        out.append("bases:")
        out += [f"  {name(b.name)}: {{parent: {name(b.parent)}, axis: {b.axis}, "
                f"angle: {_yaml_expr(b.angle)}}}" for b in spec.bases]
    if spec.points:
        out.append("points:")
        for p in spec.points:
            where = "" if (p.parent, p.base) == (CANONICAL_POINT, CANONICAL_BASE) else \
                f"from: {name(p.parent)}, base: {name(p.base)}, "
            out.append(f"  {name(p.name)}: {{{where}coordinates: "
                       f"{_yaml_vector(p.coordinates)}}}")
    if spec.frames:
        out.append("frames:")
        out += [f"  {name(f.name)}: {{point: {name(f.point)}, base: {name(f.base)}}}"
                for f in spec.frames]
    if spec.bodies:
        out.append("bodies:")
        for b in spec.bodies:
            text = f"  {name(b.name)}: {{mass: {_yaml_expr(b.mass)}, G: {name(b.G)}, " \
                   f"base: {name(b.base)}"
            off_diagonal = [b.inertia[i][j] for i in range(3) for j in range(3) if i != j]
            if any(item != 0 for item in off_diagonal):
                text += ", inertia: [" + ", ".join(_yaml_vector(row) for row in b.inertia) + "]"
            elif any(b.inertia[i][i] != 0 for i in range(3)):
                text += ", inertia: " + _yaml_vector(b.inertia[i][i] for i in range(3))
            out.append(text + "}")
    if spec.gravity is not None:
        out.append(f"gravity: {_yaml_vector(spec.gravity)}")
    if spec.actions:
        out.append("actions:")
        out += [f"  {name(a.name)}: {{body: {name(a.body)}, point: {name(a.point)}, "
                f"base: {name(a.base)}, torque: {_yaml_vector(a.torque)}, "
                f"force: {_yaml_vector(a.force)}}}" for a in spec.actions]
    if spec.effects:
        out.append("effects:")
        out += [f"  {name(e.name)}: {{{_yaml_effect(e)}}}" for e in spec.effects]
    return "\n".join(out) + "\n"


def _effect_fields(effect) -> dict:
    """The fields of an effect spec that differ from the dataclass defaults."""
    given = {}
    for f in dataclasses.fields(effect):
        value = getattr(effect, f.name)
        if f.name == "name" or (f.default is not dataclasses.MISSING and value == f.default):
            continue
        given[f.name] = value
    return given


def _yaml_effect(effect) -> str:
    """The inside of one ``effects:`` entry: ``type: spring, point_a: A, ...``."""
    parts = [f"type: {effect.kind}"]
    for field, value in _effect_fields(effect).items():
        role = EFFECT_FIELD_ROLES.get(field, "vector")     # action torque/force: vectors
        if role in ("point", "body", "base", "coordinate"):
            text = _yaml_scalar(value)
        elif role == "coordinates":
            text = "[" + ", ".join(_yaml_scalar(c) for c in value) + "]"
        elif role == "vector":
            text = _yaml_vector(value)
        else:
            text = _yaml_expr(value)
        parts.append(f"{field}: {text}")
    return ", ".join(parts)


def _replay(ctx: _Context, spec: ModelSpec, parameters=None) -> _Context:
    """Declare everything of ``spec`` in ``ctx`` again (every check runs again).

    ``parameters`` replaces the spec's ``(name, default)`` pairs if given.
    Points are declared with their resolved from/base.
    """
    for c in spec.coordinates:
        ctx.add_coordinate(c, f"coordinates[{len(ctx.coordinates)}]")
    for p, value in (spec.parameters if parameters is None else parameters):
        ctx.add_parameter(p, value, f"parameters.{p}")
    for i in spec.inputs:
        ctx.add_input(i, f"inputs[{len(ctx.inputs)}]")
    for b in spec.bases:
        ctx.add_base(b.name, b.parent, b.axis, b.angle, f"bases.{b.name}")
    for p in spec.points:
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
        ctx.add_effect(e.name, e.kind, _effect_fields(e), f"effects.{e.name}")
    return ctx


# -- Python API -----------------------------------------------------------------------

class Model:
    """Build a model in Python; :meth:`spec` returns the same ModelSpec as the YAML.

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
    >>> _ = m.add_point("P", parent="O", base="B1", coordinates=[0, "-L", 0])
    >>> _ = m.add_body("bob", mass="m", G="P", base="B1")
    >>> _ = m.set_gravity([0, "-g", 0])
    >>> m.spec().bodies[0].mass
    m
    """

    def __init__(self, name: str, description: str = ""):
        ctx = _Context(API_FILE)
        ctx.set_name(name)
        ctx.set_description(description)
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

    def add_coordinates(self, *names: str) -> "Model":
        """Add several coordinates (all or none).

        >>> Model("m").add_coordinates("q1", "q2").spec().coordinates
        ('q1', 'q2')
        """
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

    def add_parameters(self, defaults: Mapping[str, float]) -> "Model":
        """Add several parameters from a ``{name: default}`` mapping (all or none).

        >>> Model("m").add_parameters({"m": 1.0, "g": 9.81}).spec().parameter_names
        ('m', 'g')
        """
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

    def add_inputs(self, *names: str) -> "Model":
        """Add several inputs (all or none).

        >>> Model("m").add_inputs("T1", "T2").spec().inputs
        ('T1', 'T2')
        """
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

    def add_point(self, name: str, *, coordinates, parent: Optional[str] = None,
                  base: Optional[str] = None, frame: Optional[str] = None) -> "Model":
        """Add a point at ``coordinates`` (in ``base``) from point ``parent``.

        Give ``frame=`` instead of ``parent``/``base`` to use a frame's point
        and base, or neither for an absolute point (from O in base E).  The
        YAML key for ``parent`` is ``from``.

        >>> m = Model("m").add_parameter("l", 1.0)
        >>> m.add_point("P", coordinates=["l", 0, 0]).spec().points[0].parent
        'O'
        """
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
        m = cls(spec.name, spec.description)
        return m._apply(lambda c: _replay(c, spec))

    @classmethod
    def from_yaml(cls, path) -> "Model":
        """A Model built from a model file (see :func:`load_model`).

        >>> Model.from_yaml("models/double_pendulum.yaml").name   # doctest: +SKIP
        'double_pendulum'
        """
        return cls.from_spec(load_model(path))
