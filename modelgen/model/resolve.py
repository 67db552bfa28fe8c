"""Resolution: a builder's validated declarations -> a frozen ModelSpec.

Input: a :class:`~modelgen.model.builder.ModelBuilder` whose entries are each
valid on their own.  Output: the :class:`~modelgen.model.spec.ModelSpec`, once
every reference (parents, points, bases, frames, bodies, coordinates) names a
declared entity of the right kind, the bases and points form trees (no
cycles), and both are sorted parents-first; or a ModelError naming the
offending reference, with a suggestion.
"""
from __future__ import annotations

import heapq
from typing import Optional

from modelgen.model.messages import API_FILE, article, closest, listing
from modelgen.model.schema import SECTION_OF
from modelgen.model.spec import (CANONICAL_BASE, CANONICAL_POINT, EFFECT_KINDS, ActionSpec,
                                 BaseSpec, BodySpec, ConstraintSpec, FrameSpec, JointSpec,
                                 ModelSpec, PointSpec, speed_name)

__all__ = ["build_spec", "resolve", "resolve_effect"]


def resolve(builder, ref: str, kind: str, key: str, canonical: Optional[str] = None) -> str:
    """Check that ``ref`` names a declared ``kind`` (or the canonical one)."""
    if ref == canonical or builder.kind_of(ref) == kind:
        return ref
    section = SECTION_OF[kind]
    known = ([canonical] if canonical else []) + \
        [name for name, (k, _) in builder.kinds.items() if k == kind]
    other = builder.kind_of(ref)
    if other is not None:
        raise builder.error(f"'{ref}' is {article(other)}, not {article(kind)}", key,
                            f"name {article(kind)} here (known {section}: {listing(known)})")
    close = closest(ref, known)
    if close:
        fix = f"did you mean '{close}'? Otherwise declare '{ref}' under '{section}'"
    else:
        fix = f"declare '{ref}' under '{section}' (known {section}: {listing(known)})"
    raise builder.error(f"unknown {kind} '{ref}'", key, fix)


def build_spec(builder) -> ModelSpec:
    """Resolve references, check for cycles, sort and freeze into a ModelSpec."""
    if builder.name is None:
        raise builder.error("missing required key 'name'", None,
                            "add 'name: <model name>' (a C identifier) at the top level")
    declared_bases = _joints_first(builder.bases, {j.base for j in builder.joints})
    for b in declared_bases:
        resolve(builder, b.parent, "base", f"{b.key}.parent", CANONICAL_BASE)
    bases = _topological(declared_bases, lambda b: b.parent)
    if isinstance(bases, tuple):
        first = _declared(declared_bases, bases[0])
        raise builder.error("the bases form a cycle: " + " -> ".join(bases) +
                            " (each base is rotated from the next)", f"{first.key}.parent",
                            "make one of these bases a child of 'E' or of a base outside "
                            "the cycle")
    for j in builder.joints:
        resolve(builder, j.parent, "base", f"{j.key}.parent", CANONICAL_BASE)
        if j.kind == "free":
            resolve(builder, j.origin, "point", f"{j.key}.from", CANONICAL_POINT)
    frames = {}
    for f in builder.frames:
        resolve(builder, f.point, "point", f"{f.key}.point", CANONICAL_POINT)
        resolve(builder, f.base, "base", f"{f.key}.base", CANONICAL_BASE)
        frames[f.name] = f
    points = []
    for p in _joints_first(builder.points, {j.point for j in builder.joints}):
        if p.frame is not None:
            resolve(builder, p.frame, "frame", f"{p.key}.frame")
            frame = frames[p.frame]
            p = p._replace(parent=frame.point, base=frame.base)
        else:
            resolve(builder, p.parent, "point", f"{p.key}.from", CANONICAL_POINT)
            resolve(builder, p.base, "base", f"{p.key}.base", CANONICAL_BASE)
        points.append(p)
    ordered_points = _topological(points, lambda p: p.parent)
    if isinstance(ordered_points, tuple):
        first = _declared(points, ordered_points[0])
        via = "frame" if first.frame is not None else "from"
        raise builder.error("the points form a cycle: " + " -> ".join(ordered_points) +
                            " (each point is measured from the next)",
                            f"{first.key}.{via}",
                            "measure one of these points from 'O' or from a point outside "
                            "the cycle")
    for body in builder.bodies:
        resolve(builder, body.G, "point", f"{body.key}.G", CANONICAL_POINT)
        resolve(builder, body.base, "base", f"{body.key}.base", CANONICAL_BASE)
    actions = []
    for a in builder.actions:
        resolve(builder, a.body, "body", f"{a.key}.body")
        if a.frame is not None:
            resolve(builder, a.frame, "frame", f"{a.key}.frame")
            frame = frames[a.frame]
            a = a._replace(point=frame.point, base=frame.base)
        else:
            resolve(builder, a.point, "point", f"{a.key}.point", CANONICAL_POINT)
            resolve(builder, a.base, "base", f"{a.key}.base", CANONICAL_BASE)
        actions.append(a)
    effects = [resolve_effect(builder, e, frames) for e in builder.effects]
    if builder.gravity is not None and builder.kind_of("gravity") in ("action", "effect"):
        kind, key = builder.kinds["gravity"]
        raise builder.error(f"{article(kind)} is named 'gravity', the name of the top-level "
                            "gravity", key, f"rename the {kind}, or remove the top-level "
                            "'gravity:' and declare it as an effect of type gravity")
    armature = _armature(builder)
    constraints = _resolve_constraints(builder)
    return ModelSpec(
        name=builder.name,
        description=builder.description,
        coordinates=tuple(builder.coordinates) + tuple(c for j in builder.joints
                                                       for c in j.coordinates),
        parameters=tuple(builder.parameters),
        inputs=tuple(builder.inputs),
        bases=tuple(BaseSpec(b.name, b.parent, b.axis, b.angle, b.quaternion, b.rates)
                    for b in bases),
        points=tuple(PointSpec(p.name, p.parent, p.base, p.coordinates, p.speeds, p.speed_base)
                     for p in ordered_points),
        joints=tuple(JointSpec(j.name, j.kind, j.parent, j.base, j.origin, j.point,
                               j.coordinates, j.speeds) for j in builder.joints),
        frames=tuple(FrameSpec(f.name, f.point, f.base) for f in builder.frames),
        bodies=tuple(BodySpec(b.name, b.mass, b.G, b.base, b.inertia)
                     for b in builder.bodies),
        gravity=builder.gravity,
        actions=tuple(ActionSpec(a.name, a.body, a.point, a.base, a.torque, a.force)
                      for a in actions),
        effects=tuple(effects),
        units=tuple(builder.units),
        physical_inertia=builder.physical_inertia,
        armature=armature,
        constraints=constraints,
        dependent_coordinates=builder.dependent[0] if constraints else (),
        dependent_speeds=builder.dependent[1] if constraints else (),
        source=None if builder.file == API_FILE else builder.file,
        lines=tuple(builder.lines.items()),
    )


def _armature(builder) -> tuple:
    """``((dof, expression), ...)`` in dof order, zeros dropped: each name must be a
    simple coordinate or a ball/free joint's speed, given once."""
    dofs = list(builder.coordinates) + [v for j in builder.joints for v in j.speeds]
    given = {}
    for name, expr, key in builder.armature:
        if name not in dofs:
            kind = builder.kind_of(name)
            problem = (f"'{name}' is {article(kind)}, not a degree of freedom" if kind
                       else f"unknown degree of freedom '{name}'")
            close = closest(name, dofs)
            fix = f"did you mean '{close}'? " if close else ""
            raise builder.error(problem, key, fix + "name a coordinate or a ball/free "
                                f"joint's speed (known: {listing(dofs)})")
        given[name] = expr
    return tuple((name, given[name]) for name in dofs if name in given and given[name] != 0)


def _resolve_constraints(builder) -> tuple:
    """The constraints' references, and the counts of equations, coordinates and
    dependent coordinates and speeds."""
    out = []
    for c in builder.constraints:
        for field, kind, canonical in (("point_a", "point", CANONICAL_POINT),
                                       ("point_b", "point", CANONICAL_POINT),
                                       ("point", "point", CANONICAL_POINT),
                                       ("body", "body", None),
                                       ("base", "base", CANONICAL_BASE)):
            if getattr(c, field):
                resolve(builder, getattr(c, field), kind, f"{c.key}.{field}", canonical)
        out.append(ConstraintSpec(c.name, c.kind, c.point_a, c.point_b, c.point, c.body,
                                  c.base, c.axes, c.expression, c.axle, c.radius, c.normal,
                                  c.height))
    coords, speeds = builder.dependent
    key = builder.dependent_key
    if not out:
        if coords or speeds:
            raise builder.error("dependent coordinates or speeds but no constraints", key,
                                "declare the constraints under 'constraints', or remove "
                                "'dependent'")
        return ()
    m = sum(c.size for c in out)
    m_h = sum(c.holonomic_size for c in out)
    first = builder.constraints[0].key
    n = len(builder.coordinates) + sum(len(j.speeds) for j in builder.joints)
    if m >= n:
        dofs = "degrees of freedom" if builder.joints else "coordinates"
        raise builder.error(f"{m} constraint equations for {n} {dofs}: nothing could "
                            "move", first, "remove constraints (each coincide axis is one "
                            "equation), or add coordinates; there must be fewer equations "
                            "than coordinates")
    if builder.joints:
        _plain_dependent(builder, m, m_h, first)
    if not coords and not speeds:
        return tuple(out)      # chosen when the model is generated (largest pivots)
    if len(speeds) != m:
        raise builder.error(f"{len(speeds)} dependent speeds for {m} constraint equations",
                            key, f"name {m} dependent speeds (one per equation), e.g. "
                            f"speeds: [{', '.join(speed_name(c) for c in builder.coordinates[-m:])}]")
    if len(coords) != m_h:
        raise builder.error(f"{len(coords)} dependent coordinates for {m_h} position "
                            "constraint equations", key,
                            f"name {m_h} dependent coordinates (one per position equation; "
                            "velocity constraints make no coordinate dependent)")
    return tuple(out)


def _plain_dependent(builder, m: int, m_h: int, first: str) -> None:
    """With ball or free joints, the constraints are solved for plain coordinates
    and their speeds (angles or lengths whose speed is their time derivative; a
    joint's coordinate or speed declared dependent is refused by
    ``dependent_decl``): a quaternion's component or a free joint's position moves
    with the joint's speeds through N(q), which neither the projection's Newton
    steps nor the dependent speeds' solve could invert.  There must be a plain
    coordinate for every equation."""
    plain = len(builder.coordinates)
    if m > plain:
        what = "position " if m_h > plain else ""
        count = m_h if m_h > plain else m
        raise builder.error(f"{count} {what}constraint equations but {plain} plain "
                            "coordinates: on a model with ball or free joints, constraints "
                            "are solved for plain coordinates (angles or lengths) and their "
                            "speeds, one per equation", first,
                            "add plain coordinates for the constraints to move (e.g. hinges "
                            "instead of a ball joint), or remove constraints")


def resolve_effect(builder, e, frames: dict):
    """Check an effect's references and build its spec dataclass."""
    values = dict(e.fields)
    if e.frame is not None:
        resolve(builder, e.frame, "frame", f"{e.key}.frame")
        values["point"], values["base"] = frames[e.frame].point, frames[e.frame].base
    for field, value in values.items():
        role = EFFECT_KINDS[e.kind].roles.get(field)
        where = f"{e.key}.{field}"
        if e.frame is not None and field in ("point", "base"):
            continue
        if role in ("point", "base"):
            resolve(builder, value, role, where,
                    CANONICAL_POINT if role == "point" else CANONICAL_BASE)
        elif role in ("body", "coordinate"):
            resolve(builder, value, role, where)
        elif role == "coordinates":
            for i, item in enumerate(value):
                if builder.kind_of(item) != "joint speed":   # a ball/free joint's dof
                    resolve(builder, item, "coordinate", f"{where}[{i}]")
    return EFFECT_KINDS[e.kind](name=e.name, **values)

def _joints_first(items: list, made: set) -> list:
    """The bases (or points) the joints make, then the others, each in declaration
    order: the order a model file declares them in (its joints are read first), so
    that a model built in any order has the spec of its YAML."""
    return [i for i in items if i.name in made] + [i for i in items if i.name not in made]


def _declared(items, name):
    """The declaration named ``name``."""
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

