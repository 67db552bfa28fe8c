"""What a model file may contain: its keys, the keys of each entry, and which
symbols each kind of expression may use.

Input: nothing (tables only).  Output: the tables the builder and the section
readers check against.  The format itself is documented in
``docs/model-format.md``; the effect fields come from the effect dataclasses
of :mod:`modelgen.model.spec`.
"""
from __future__ import annotations

import re
from typing import NamedTuple

__all__ = ["TOP_LEVEL_KEYS", "ENTRY_KEYS", "REQUIRED_KEYS", "ExpressionRule",
           "EXPRESSION_RULES", "SECTION_KIND", "SECTION_OF", "SECTION_EXAMPLES",
           "NUMERIC_STRING"]

#: Top-level keys of a model file, in the order they are processed and written.
#: Any other key is an error; a stage adding a key adds it here and reads it
#: in ``builder_from_data``.
TOP_LEVEL_KEYS = ("name", "description", "coordinates", "parameters", "inputs",
                  "bases", "joints", "points", "frames", "bodies", "gravity", "actions", "effects",
                  "armature", "constraints", "dependent", "units", "physical_inertia")

#: Keys of one entry of each mapping section.
ENTRY_KEYS = {
    "bases": ("parent", "axis", "angle"),
    "joints": ("type", "parent", "base", "from", "point"),
    "points": ("from", "base", "frame", "coordinates"),
    "frames": ("point", "base"),
    "bodies": ("mass", "G", "base", "inertia"),
    "actions": ("body", "point", "base", "frame", "torque", "force", "vector"),
    "constraints": ("type", "point_a", "point_b", "point", "body", "base", "axes",
                    "expression", "axle", "radius", "normal", "height"),
}

#: Keys an entry must have (alternatives such as ``frame`` are checked separately).
REQUIRED_KEYS = {
    "bases": ("parent", "axis", "angle"),
    "joints": ("type", "parent", "base"),
    "points": ("coordinates",),
    "frames": ("point", "base"),
    "bodies": ("mass", "G", "base"),
    "actions": ("body",),
    "constraints": ("type",),
}


class ExpressionRule(NamedTuple):
    """The symbols allowed in one kind of expression, and how to say so in a message."""
    kinds: tuple      # symbol kinds allowed: "coordinate", "speed", "parameter", "input", "time"
    text: str         # the allowed kinds in words
    declare: str      # where an undefined name should be declared
    why: str          # the reason for the restriction ("" if none)


#: Which symbols the expressions at each kind of key may use.
EXPRESSION_RULES = {
    "position": ExpressionRule(
        ("coordinate", "parameter"), "coordinates and parameters",
        "'coordinates' or 'parameters'",
        " (positions and angles cannot depend on speeds, inputs or t)"),
    "constant": ExpressionRule(
        ("parameter",), "parameters", "'parameters'", " (masses and inertias are constant)"),
    "gravity": ExpressionRule(
        ("parameter", "time"), "parameters and t", "'parameters'",
        " (gravity is a uniform field; use an action for forces that depend "
        "on the state or on inputs)"),
    "action": ExpressionRule(
        ("coordinate", "speed", "parameter", "input", "time"),
        "coordinates, speeds, parameters, inputs and t",
        "'coordinates', 'parameters' or 'inputs'", ""),
    "coefficient": ExpressionRule(
        ("parameter",), "parameters", "'parameters'",
        " (effect coefficients, lengths and speeds are constant)"),
    "holonomic": ExpressionRule(
        ("coordinate", "parameter"), "coordinates and parameters", "'coordinates' or 'parameters'",
        " (a position constraint f(q) = 0; a constraint on speeds has type 'speeds')"),
    "nonholonomic": ExpressionRule(
        ("coordinate", "speed", "parameter"), "coordinates, speeds and parameters",
        "'coordinates' or 'parameters'", " (a velocity constraint B(q) q_dot = 0)"),
}

#: The kind of entry of each mapping section, and the section of each kind.
SECTION_KIND = {"bases": "base", "joints": "joint", "points": "point", "frames": "frame",
                "bodies": "body", "actions": "action", "effects": "effect",
                "constraints": "constraint"}
SECTION_OF = {**{kind: section for section, kind in SECTION_KIND.items()},
              "coordinate": "coordinates"}

#: An example entry of each mapping section, for the fixes of messages.
SECTION_EXAMPLES = {
    "bases": "B1: {parent: E, axis: 3, angle: q1}",
    "joints": "J1: {type: free, parent: E, base: B1, from: O, point: P1}",
    "points": "P1: {from: O, base: B1, coordinates: [l1, 0, 0]}",
    "frames": "F1: {point: P1, base: B1}",
    "bodies": "rod1: {mass: m1, G: G1, base: B1, inertia: [I1, I2, I3]}",
    "actions": "motor: {body: rod1, point: O, base: B1, torque: [0, 0, T1]}",
    "constraints": "loop: {type: coincide, point_a: P3, point_b: D, base: E, axes: [1, 2]}",
    "effects": "spring1: {type: spring, point_a: A, point_b: P1, stiffness: k, "
               "rest_length: L0}",
}
#: A number written as a string (YAML 1.1 reads an unquoted ``1e5`` as one).
NUMERIC_STRING = re.compile(r"\s*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\s*\Z")
