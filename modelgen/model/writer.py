"""The YAML writer: a ModelSpec -> model file text.

Input: a :class:`~modelgen.model.spec.ModelSpec`.  Output: YAML text in the
format of ``docs/model-format.md`` that reads back to an equal spec
(``parse_model(spec_to_yaml(spec)) == spec``): one line per entry, flow
style, expressions printed by :func:`modelgen.model.expr.format_expression`,
strings quoted only where YAML would read them as something else.
"""
from __future__ import annotations

import json
import re

import yaml

from modelgen.model.constraints import constraint_fields
from modelgen.model.expr import format_expression
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, ModelSpec, effect_fields

__all__ = ["spec_to_yaml", "yaml_float"]


_RESOLVER = yaml.resolver.Resolver()
_PLAIN_SAFE = re.compile(r"-?[A-Za-z0-9_(][A-Za-z0-9_ .+\-*/()]*\Z")


#: what :func:`_yaml_scalar` escapes after JSON has: DEL and everything beyond ASCII
_ESCAPED = re.compile(r"[^\x00-\x7e]")


def _escape(match) -> str:
    """YAML's escape of one character: ``\\u00e9``, or ``\\U0001f600`` beyond the
    Basic Multilingual Plane (where JSON's surrogate pair would read back as two
    lone surrogates)."""
    code = ord(match.group())
    return f"\\u{code:04x}" if code <= 0xFFFF else f"\\U{code:08x}"


def _yaml_scalar(text: str, numbers_ok: bool = False) -> str:
    """``text`` as a YAML scalar that reads back as the same string (or number).

    >>> print(_yaml_scalar("a: b\u00e9\U0001F600"))
    "a: b\\u00e9\\U0001f600"
    """
    if _PLAIN_SAFE.match(text) and not text.endswith(" "):
        tag = _RESOLVER.resolve(yaml.ScalarNode, text, (True, False)).rsplit(":", 1)[-1]
        if tag == "str" or (numbers_ok and tag == "int"):
            return text
    return _ESCAPED.sub(_escape, json.dumps(text, ensure_ascii=False))


def _yaml_expr(expr) -> str:
    return _yaml_scalar(format_expression(expr), numbers_ok=True)


def _yaml_vector(items) -> str:
    return "[" + ", ".join(_yaml_expr(item) for item in items) + "]"


def yaml_float(value: float) -> str:
    """A float as YAML text that reads back as the same float (``1.0e-05``, not ``1e-05``).

    >>> yaml_float(1e-5), yaml_float(2)
    ('1.0e-05', '2.0')
    """
    text = repr(float(value))
    if "e" in text and "." not in text.split("e")[0]:
        mantissa, exponent = text.split("e")
        text = f"{mantissa}.0e{exponent}"
    return text


def spec_to_yaml(spec: ModelSpec) -> str:
    """Write a ModelSpec in the YAML format of :func:`parse_model`.

    ``parse_model(spec_to_yaml(spec)) == spec``.  Points given by a frame are
    written with their resolved ``from``/``base``.

    >>> from modelgen.model import parse_model
    >>> spec = parse_model("{name: m, coordinates: [q], bases: {B: {parent: E, axis: 3, "
    ...                    "angle: q}}}")
    >>> print(spec_to_yaml(spec), end="")
    name: m
    coordinates: [q]
    bases:
      B: {parent: E, axis: 3, angle: q}
    """
    return "\n".join(_header(spec) + _geometry(spec) + _physics(spec)) + "\n"


def _header(spec: ModelSpec) -> list:
    """The lines of the name, description, coordinates, parameters and inputs."""
    name = _yaml_scalar
    out = [f"name: {name(spec.name)}"]
    if spec.description:
        out.append(f"description: {name(spec.description)}")
    if not spec.physical_inertia:
        out.append("physical_inertia: false")
    if spec.simple_coordinates:
        out.append("coordinates: [" + ", ".join(name(c) for c in spec.simple_coordinates) + "]")
    if spec.parameters:
        out.append("parameters:")
        out += [f"  {name(p)}: {yaml_float(v)}" for p, v in spec.parameters]
    if spec.inputs:
        out.append("inputs: [" + ", ".join(name(i) for i in spec.inputs) + "]")
    return out


def _geometry(spec: ModelSpec) -> list:
    """The lines of the bases, joints, points and frames."""
    name = _yaml_scalar
    out = []
    made = {j.base for j in spec.joints} | {j.point for j in spec.joints}
    bases = [b for b in spec.bases if b.name not in made]
    if bases:
        out.append("bases:")
        out += [f"  {name(b.name)}: {{parent: {name(b.parent)}, axis: {b.axis}, "
                f"angle: {_yaml_expr(b.angle)}}}" for b in bases]
    if spec.joints:
        out.append("joints:")
        for j in spec.joints:
            text = f"  {name(j.name)}: {{type: {j.kind}, parent: {name(j.parent)}, " \
                   f"base: {name(j.base)}"
            if j.kind == "free":
                text += f", from: {name(j.origin)}, point: {name(j.point)}"
            out.append(text + "}")
    points = [p for p in spec.points if p.name not in made]
    if points:
        out.append("points:")
        for p in points:
            where = "" if (p.parent, p.base) == (CANONICAL_POINT, CANONICAL_BASE) else \
                f"from: {name(p.parent)}, base: {name(p.base)}, "
            out.append(f"  {name(p.name)}: {{{where}coordinates: "
                       f"{_yaml_vector(p.coordinates)}}}")
    if spec.frames:
        out.append("frames:")
        out += [f"  {name(f.name)}: {{point: {name(f.point)}, base: {name(f.base)}}}"
                for f in spec.frames]
    return out


def _physics(spec: ModelSpec) -> list:
    """The lines of the bodies, gravity, actions, effects, armature and units."""
    name = _yaml_scalar
    out = []
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
    if spec.armature:
        out.append("armature: {" + ", ".join(f"{name(n)}: {_yaml_expr(v)}"
                                             for n, v in spec.armature) + "}")
    if spec.constraints:
        out.append("constraints:")
        for c in spec.constraints:
            parts = [f"type: {c.kind}"]
            for field, value in constraint_fields(c).items():
                text = ("[" + ", ".join(str(a) for a in value) + "]" if field == "axes" else
                        str(value) if field in ("axle", "normal") else
                        _yaml_expr(value) if field in ("expression", "radius", "height")
                        else name(value))
                parts.append(f"{field}: {text}")
            out.append(f"  {name(c.name)}: {{{', '.join(parts)}}}")
        if spec.dependent_speeds:
            out.append("dependent: {coordinates: ["
                       + ", ".join(map(name, spec.dependent_coordinates))
                       + "], speeds: [" + ", ".join(map(name, spec.dependent_speeds)) + "]}")
    if spec.units:
        out.append("units: {" + ", ".join(f"{name(n)}: {name(u)}" for n, u in spec.units) + "}")
    return out


def _yaml_effect(effect) -> str:
    """The inside of one ``effects:`` entry: ``type: spring, point_a: A, ...``."""
    parts = [f"type: {effect.kind}"]
    for field, value in effect_fields(effect).items():
        role = type(effect).roles[field]
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
