"""The ``constraints:`` and ``dependent:`` sections: one validated entry each.

Input: a builder (:class:`~modelgen.model.builder.ModelBuilder`, for its
expressions, references and errors) and the raw values of one entry.
Output: a :class:`ConstraintDecl` (references still unresolved; see
:func:`modelgen.model.resolve.build_spec`) or the declared dependent
coordinates and speeds.  The kinds are :data:`~modelgen.model.spec.CONSTRAINT_KINDS`;
the format is documented in ``docs/constraints.md``.
"""
from __future__ import annotations

import numbers
from typing import NamedTuple

import sympy

from modelgen.model.expr import format_expression
from modelgen.model.messages import as_list, closest, describe, join_and
from modelgen.model.spec import CANONICAL_BASE, CONSTRAINT_KINDS, speed_name

__all__ = [
    "KIND_FIELDS",
    "ConstraintDecl",
    "constraint_decl",
    "constraint_fields",
    "dependent_decl",
]

#: The keys each kind takes (besides ``type``), and those it needs.
KIND_FIELDS = {
    "coincide": (("point_a", "point_b", "base", "axes"), ("point_a", "point_b")),
    "position": (("expression",), ("expression",)),
    "velocity": (("point", "body", "base", "axes"), ("point",)),
    "speeds": (("expression",), ("expression",)),
    "rolling": (("body", "axle", "radius", "normal", "height"), ("body", "axle", "radius")),
}


class ConstraintDecl(NamedTuple):
    name: str
    kind: str
    point_a: str
    point_b: str
    point: str
    body: str
    base: str
    axes: tuple
    expression: sympy.Expr | None
    key: str
    axle: int = 0
    radius: sympy.Expr | None = None
    normal: int = 0
    height: sympy.Expr | None = None


def _axes(ctx, value, key: str) -> tuple:
    if value is None:
        return (1, 2, 3)
    items = as_list(value)
    fix = "write a list of distinct base axes 1, 2, 3, e.g. axes: [1, 2]"
    if not isinstance(items, list) or not items:
        raise ctx.error(f"expected a list of axes but got {describe(value)}", key, fix)
    for i, item in enumerate(items):
        if isinstance(item, bool) or not isinstance(item, numbers.Integral) \
                or not 1 <= item <= 3:
            raise ctx.error(f"axis must be 1, 2 or 3 but is {describe(item)}", f"{key}[{i}]",
                            fix)
        if item in items[:i]:
            raise ctx.error(f"axis {item} is listed twice", f"{key}[{i}]", fix)
    return tuple(int(a) for a in items)


def _linear_in_speeds(ctx, expr: sympy.Expr, key: str) -> None:
    """``expr`` is linear and homogeneous in the speeds: B(q) q_dot = 0."""
    speeds = [s for name, s in ctx.symbols.items() if ctx.kind_of(name) == "speed"]
    used = [s for s in speeds if s in expr.free_symbols]
    shown = format_expression(expr)
    fix = ("write it as a sum of speeds times expressions of coordinates and parameters, "
           "e.g. 'r*phi_dot - x_dot' (a constraint on positions has type 'position')")
    if not used:
        raise ctx.error(f"constraint expression {shown!r} has no speed", key, fix)
    for s in used:
        if sympy.diff(expr, s).free_symbols & set(speeds):
            raise ctx.error(f"constraint expression {shown!r} is not linear in the speeds "
                            f"(its derivative by '{s}' still has a speed)", key, fix)
    rest = sympy.expand(expr.xreplace({s: sympy.S.Zero for s in used}))
    if rest != 0:
        raise ctx.error(f"constraint expression {shown!r} has a term without a speed: "
                        f"{format_expression(rest)}", key, fix)


def constraint_decl(ctx, name, kind, fields: dict, key: str) -> ConstraintDecl:
    """One validated constraint entry (``fields``: its keys but ``type``)."""
    kinds = ", ".join(CONSTRAINT_KINDS)
    if not isinstance(kind, str) or kind not in CONSTRAINT_KINDS:
        close = closest(kind, CONSTRAINT_KINDS) if isinstance(kind, str) else None
        fix = f"did you mean '{close}'? " if close else ""
        raise ctx.error(f"unknown constraint type {describe(kind)}", f"{key}.type",
                        fix + f"constraint types: {kinds}")
    valid, required = KIND_FIELDS[kind]
    for field in fields:
        if field not in valid:
            close = closest(field, valid)
            fix = f"did you mean '{close}'? " if close else ""
            raise ctx.error(f"unknown key '{field}' for a {kind} constraint", f"{key}.{field}",
                            fix + "valid keys: " + ", ".join(("type",) + valid))
    for field in required:
        if fields.get(field) is None:
            raise ctx.error(f"missing required key '{field}'", key,
                            f"add '{field}'; a {kind} constraint needs " + join_and(required))
    ref = lambda field, what: (ctx.reference(fields[field], what, f"{key}.{field}")
                               if fields.get(field) is not None else "")
    expression = None
    if kind in ("position", "speeds"):
        rule = "holonomic" if kind == "position" else "nonholonomic"
        expression = ctx.expression(fields["expression"], f"{key}.expression", rule)
        if kind == "speeds":
            _linear_in_speeds(ctx, expression, f"{key}.expression")
        elif not any(ctx.kind_of(str(s)) == "coordinate" for s in expression.free_symbols):
            raise ctx.error(f"constraint expression {format_expression(expression)!r} has no "
                            "coordinate", f"{key}.expression",
                            "write f(q) with f = 0 on the constraint, using coordinates")
    axes = _axes(ctx, fields.get("axes"), f"{key}.axes") if "axes" in valid else ()
    base = (ref("base", "base") or CANONICAL_BASE) if "base" in valid else ""
    if kind == "coincide" and fields["point_a"] == fields["point_b"]:
        raise ctx.error(f"constraint '{name}' makes point '{fields['point_a']}' coincide with "
                        "itself", f"{key}.point_b", "give two different points")
    rolling = {}
    if kind == "rolling":
        rolling["axle"] = _axis(ctx, fields["axle"], f"{key}.axle", "the axle: the axis of "
                                "the wheel body's base about which it spins")
        rolling["normal"] = _axis(ctx, fields.get("normal", 3), f"{key}.normal",
                                  "the ground's normal: the axis of E pointing up from it")
        rolling["radius"] = ctx.expression(fields["radius"], f"{key}.radius", "constant")
        radius = ctx.at_defaults(rolling["radius"])
        if radius is None or radius <= 0:
            raise ctx.error(f"the radius of wheel '{name}' is not positive with the default "
                            f"parameters: {format_expression(rolling['radius'])}",
                            f"{key}.radius", "give a radius > 0")
        rolling["height"] = ctx.expression(fields.get("height", 0), f"{key}.height",
                                           "constant")
    return ConstraintDecl(name, kind, ref("point_a", "point"), ref("point_b", "point"),
                          ref("point", "point"), ref("body", "body"), base, axes,
                          expression, key, **rolling)


def _axis(ctx, value, key: str, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 1 <= value <= 3:
        raise ctx.error(f"axis must be 1, 2 or 3 but is {describe(value)}", key,
                        f"give {what} as 1, 2 or 3")
    return int(value)


def dependent_decl(ctx, value, key: str = "dependent") -> tuple:
    """``dependent: {coordinates: [...], speeds: [...]}`` -> (coordinates, speeds)."""
    example = "write dependent: {coordinates: [q2, q3], speeds: [q2_dot, q3_dot]}"
    if value is None:
        return (), ()
    if not isinstance(value, dict):
        raise ctx.error(f"expected a mapping but got {describe(value)}", key, example)
    for field in value:
        if field not in ("coordinates", "speeds"):
            raise ctx.error(f"unknown key '{field}'", f"{key}.{field}",
                            "valid keys: coordinates, speeds")
    out = []
    for field, kind in (("coordinates", "coordinate"), ("speeds", "speed")):
        items = as_list(value.get(field, []))
        if not isinstance(items, list):
            raise ctx.error(f"expected a list of {kind} names but got {describe(items)}",
                            f"{key}.{field}", example)
        for i, item in enumerate(items):
            where = f"{key}.{field}[{i}]"
            if isinstance(item, str) and ctx.kind_of(item) == f"joint {kind}":
                raise ctx.error(f"{kind} '{item}' belongs to a ball or free joint: a "
                                f"constraint can only make a plain {kind} dependent (an angle "
                                "or a length, whose speed is its time derivative; a "
                                "quaternion or a free joint's position moves with the joint's "
                                "speeds)", where,
                                f"name plain {field} instead (here: "
                                + (", ".join(ctx.coordinates if kind == "coordinate" else
                                             [speed_name(c) for c in ctx.coordinates])
                                   or "none") + "), or write the joint's rotation as simple "
                                "bases (angles)")
            if not isinstance(item, str) or ctx.kind_of(item) != kind:
                known = [c for c in ctx.coordinates] if kind == "coordinate" else \
                    [speed_name(c) for c in ctx.coordinates]
                close = closest(item, known) if isinstance(item, str) else None
                fix = f"did you mean '{close}'? " if close else ""
                raise ctx.error(f"{describe(item) if not isinstance(item, str) else repr(item)}"
                                f" is not a declared {kind}", where,
                                fix + f"name one of the {field}: " + ", ".join(known))
            if item in items[:i]:
                raise ctx.error(f"{kind} '{item}' is listed twice", where, "list it once")
        out.append(tuple(items))
    return tuple(out)


def constraint_fields(c) -> dict:
    """The YAML keys of a :class:`~modelgen.model.spec.ConstraintSpec` (not ``type``),
    defaults left out (``base: E``, ``axes: [1, 2, 3]``, no ``body``)."""
    out = {}
    for field in KIND_FIELDS[c.kind][0]:
        value = getattr(c, field)
        if (field == "base" and value == CANONICAL_BASE) or (field == "axes" and value ==
                                                               (1, 2, 3)) or value == "" \
                or (field == "normal" and value == 3) or (field == "height" and value == 0):
            continue
        out[field] = list(value) if field == "axes" else value
    return out
