"""Joint-tree extraction: read a model as a tree of one-degree-of-freedom joints.

The model format does not declare joints: coordinates may appear anywhere in
base angles and point coordinates.  The articulated-body algorithm
(:mod:`modelgen.derive.aba`) needs the tree explicitly, so this module decides
whether a :class:`~modelgen.model.spec.ModelSpec` *is* a joint tree and, if so,
returns it as plain data.

A model is a joint tree when

* every coordinate enters exactly one base angle or one point's coordinates,
  and nowhere else among the bases and points;
* in a base angle it enters linearly, alone: ``angle = a*q + c`` with ``a`` and
  ``c`` free of coordinates (a revolute joint about that base axis);
* in a point's coordinates every component is linear in the coordinates, with
  coefficients free of coordinates (one prismatic joint per coordinate, along
  the direction ``d coordinates / dq`` of the point's base);
* every body's pose reads as one sequence of elementary transforms from E/O:
  walking its centre's point chain from O, each point with non-zero
  coordinates is given in a base on the way from E to the body's base, never
  in a base nearer E than the previous one (rotations are then applied
  lazily, just before the first translation that needs them, and the rest up
  to the body's base at the end);
* the bodies' sequences, merged by the names of the bases and points they
  pass through (a trie), contain each coordinate's transform in exactly one
  place, and every coordinate moves at least one body.

Each joint becomes a link; its frame is the frame right after the joint's
transform.  The constant transforms between two joints are composed into one
(``fixed``), and bodies fixed to the same link are merged into one spatial
inertia (exact: parallel-axis theorem).  Bodies fixed to the ground are
dropped: they cannot move.

Transforms are Plücker transforms ``X = rot(E) xlt(r)``: ``r`` is the child
origin in parent components and ``E`` maps parent components to child
components (Featherstone, *Rigid Body Dynamics Algorithms*, 2008, §2.8).
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.spatial import (IDENTITY3, ONE, ZERO, ZERO3, add, matmul, matvec, rotation,
                                     transpose)
from modelgen.errors import ModelError
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, ModelSpec, symbol



@dataclass(frozen=True)
class Joint:
    """One joint of the tree and the link it moves.

    ``fixed`` is the constant transform ``(E, r)`` from the parent link's frame
    (or E/O for a root joint) to the frame just before the joint.  A revolute
    joint then rotates by ``angle`` about ``axis`` (1, 2 or 3) of that frame;
    a prismatic one translates by ``offset`` (components in that frame, linear
    in the coordinate).  ``S`` is the motion subspace in the link's frame,
    (angular, linear), per unit of the coordinate's speed.
    """
    name: str             # the coordinate's name
    coordinate: int       # its index in spec.coordinates
    parent: int           # index of the parent joint in JointTree.joints, -1 for the ground
    fixed: tuple          # (E, r): 3x3 rows, 3-vector
    kind: str             # "revolute" | "prismatic"
    axis: int             # revolute: 1 | 2 | 3; prismatic: 0
    angle: sympy.Expr     # revolute: the whole angle a*q + c; prismatic: 0
    offset: tuple         # prismatic: a*q (3 components); revolute: zeros
    S: tuple              # 6 entries
    source: str           # the dotted key of the expression the joint comes from
    base: str             # the base whose orientation the link frame has
    origin: tuple         # (point, correction): the link origin is r_point + R_base correction
    #: a ball or free joint (``kind`` "ball" | "free"): ((speed index, S column), ...),
    #: its quaternion (w, x, y, z) and a free joint's position (x, y, z) in the
    #: frame before the joint; the joint transform is ``rot(R(quat)^T) xlt(position)``
    columns: tuple = ()
    quaternion: tuple = ()
    position: tuple = ()

    @property
    def dofs(self) -> tuple:
        """((speed index, motion subspace column), ...): one for a revolute or
        prismatic joint, 3 for a ball joint, 6 for a free one."""
        return self.columns or ((self.coordinate, self.S),)


@dataclass(frozen=True)
class LinkInertia:
    """The merged rigid-body inertia of a link, in the link's frame at its origin.

    ``I`` is about the link origin (6 entries xx, yy, zz, xy, xz, yz), ``h`` the
    first moment m*c (c the centre of mass), ``m`` the mass.
    """
    I: tuple
    h: tuple
    m: sympy.Expr
    bodies: tuple         # names of the bodies merged into it


@dataclass(frozen=True)
class JointTree:
    """Output of :func:`extract_joint_tree`: joints parents-first, one inertia each."""
    joints: tuple         # tuple[Joint, ...], a parent before its children
    inertias: tuple       # tuple[LinkInertia, ...], one per joint
    body_links: tuple     # ((body name, joint index or -1 for the ground), ...)
    #: per dof (coordinate order): reflected rotor inertia on the diagonal of A
    #: (``D_i`` of the ABA, ``armature * qdd`` of the RNEA); empty when none is given
    armature: tuple = ()


def _error(spec: ModelSpec, key: str, problem: str) -> ModelError:
    return ModelError(
        f"not a joint tree (needed by formulation 'aba'): {problem}",
        file=spec.source, line=spec.line_of(key), key=key,
        fix="use formulation 'crba' (or 'auto'), or write the coordinate as a base "
            "angle 'q' (+ a constant) or as one linear point offset")


def _linear_in(expr, coordinates: dict):
    """{k: d expr / d q_k} and the rest, or None if expr is not linear in the q."""
    if not getattr(expr, "free_symbols", None):
        return {}, expr
    free = expr.free_symbols
    used = [k for k, qk in coordinates.items() if qk in free]
    slopes = {}
    rest = expr
    for k in used:
        slope = sympy.diff(expr, coordinates[k])
        if slope.free_symbols & set(coordinates.values()):
            return None
        slopes[k] = slope
        rest = rest - slope * coordinates[k]
    rest = sympy.expand(rest) if used else rest
    if rest.free_symbols & set(coordinates.values()):
        return None
    return slopes, rest


class _Compose:
    """A constant transform X = rot(E) xlt(r) built op by op."""

    def __init__(self):
        self.E, self.r = IDENTITY3, ZERO3

    def rotate(self, E_op):
        self.E = matmul(E_op, self.E)

    def translate(self, c):
        self.r = add(self.r, matvec(transpose(self.E), c))

    def value(self) -> tuple:
        return (self.E, self.r)


def _occurrences(spec: ModelSpec, q: dict) -> dict:
    """{k: [(key, element)]}: where each coordinate enters the bases and points."""
    where: dict = {k: [] for k in q}
    items = [(f"bases.{b.name}.angle", b, (b.angle,)) for b in spec.bases]
    items += [(f"points.{p.name}.coordinates", p, p.coordinates) for p in spec.points]
    for key, element, exprs in items:
        free = set().union(*(getattr(e, "free_symbols", set()) for e in exprs))
        for k, qk in q.items():
            if qk in free:
                where[k].append((key, element))
    return where


def _check_coordinates(spec: ModelSpec, q: dict) -> None:
    for k, places in _occurrences(spec, q).items():
        name = spec.coordinates[k]
        if len(places) > 1:
            raise _error(spec, places[1][0],
                         f"coordinate {name!r} enters {places[0][0]} and {places[1][0]}; "
                         "each coordinate must enter exactly one base angle or point")
    for b in spec.bases:
        lin = _linear_in(b.angle, q)
        key = f"bases.{b.name}.angle"
        if lin is None or len(lin[0]) > 1:
            raise _error(spec, key, f"angle '{b.angle}' of base {b.name} is not one "
                                    "coordinate times a constant plus a constant")
    for p in spec.points:
        for c in p.coordinates:
            if _linear_in(c, q) is None:
                raise _error(spec, f"points.{p.name}.coordinates",
                             f"coordinate '{c}' of point {p.name} is not linear in the "
                             "coordinates")


def _body_ops(spec: ModelSpec, body, bases: dict, points: dict, linear: dict) -> list:
    """The body's pose as elementary ops: (key, kind, data), E/O outwards."""
    chain = []
    b = body.base
    while b != CANONICAL_BASE:
        chain.append(b)
        b = bases[b].parent
    chain.reverse()
    depth = {name: i + 1 for i, name in enumerate(chain)}
    depth[CANONICAL_BASE] = 0
    segments = []
    p = body.G
    while p != CANONICAL_POINT:
        segments.append(points[p])
        p = points[p].parent
    segments.reverse()

    ops = []
    level = 0
    joint_of_base = {j.base: j for j in spec.joints}

    def advance(to):
        nonlocal level
        for name in chain[level:to]:
            base = bases[name]
            if base.quaternion:
                joint = joint_of_base[name]
                if joint.kind == "free":
                    raise _error(spec, f"joints.{joint.name}",
                                 f"body {body.name} turns with free joint {joint.name} "
                                 f"but is not placed from its point {joint.point}")
                ops.append((("joint", joint.name), "ball", joint))
            else:
                ops.append((("base", name), "rot", base))
        level = max(level, to)

    for point in segments:
        if point.speeds:                 # a free joint: its position, then its rotation
            joint = joint_of_base[point.speed_base]
            d = depth.get(point.base, -1)
            if d < level or point.speed_base not in depth:
                raise _error(spec, f"joints.{joint.name}",
                             f"body {body.name} is placed from free joint {joint.name}'s "
                             f"point but does not turn with its base {joint.base}")
            advance(d)
            ops.append((("joint", joint.name), "free", joint))
            level = depth[point.speed_base]
            continue
        if all(c == 0 for c in point.coordinates):
            continue
        d = depth.get(point.base)
        if d is None or d < level:
            why = ("is not on the way from E to the body's base" if d is None else
                   f"comes before base {chain[level - 1]}, already used nearer the body")
            raise _error(spec, f"points.{point.name}.base",
                         f"body {body.name}: point {point.name} is given in base "
                         f"{point.base}, which {why}")
        advance(d)
        slopes = linear[point.name]
        const = tuple(rest for _, rest in slopes)
        if any(c != 0 for c in const):
            ops.append((("point", point.name, -1), "trans", const))
        for k in sorted({k for sl, _ in slopes for k in sl}):
            direction = tuple(sl.get(k, ZERO) for sl, _ in slopes)
            ops.append((("point", point.name, k), "prism", (k, direction, point)))
    advance(len(chain))
    return ops


def _spatial_inertia(body, E, r) -> tuple:
    """(I about the link origin as 6 entries, h, m) of a body at (E, r) from the link."""
    m = body.mass
    Ic = body.inertia if E == IDENTITY3 else matmul(transpose(E), matmul(body.inertia, E))
    c = r
    cc = c[0] ** 2 + c[1] ** 2 + c[2] ** 2
    I = tuple(Ic[i][j] + m * ((cc if i == j else 0) - c[i] * c[j])
              for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))
    return I, tuple(m * x for x in c), m


def extract_joint_tree(spec: ModelSpec) -> JointTree:
    """The model as a tree of revolute and prismatic joints, or a :class:`ModelError`.

    The error names the offending expression (its dotted key, file and line).

    >>> from modelgen.model.chains import spatial_chain
    >>> tree = extract_joint_tree(spatial_chain(2).spec())
    >>> [(j.name, j.parent, j.kind, j.axis) for j in tree.joints]
    [('q1', -1, 'revolute', 3), ('q2', 0, 'revolute', 2)]
    >>> tree.joints[1].fixed[1]
    (l1, 0, 0)
    """
    q = {k: symbol(name) for k, name in enumerate(spec.simple_coordinates)}
    _check_coordinates(spec, q)
    bases = {b.name: b for b in spec.bases}
    points = {p.name: p for p in spec.points}
    linear = {p.name: [_linear_in(c, q) for c in p.coordinates] for p in spec.points
              if not p.speeds}

    # the trie of every body's ops, merged by names
    nodes = [None]                      # node -> (parent node, key, kind, data)
    children: list = [{}]
    ends = []
    for body in spec.bodies:
        node = 0
        for key, kind, data in _body_ops(spec, body, bases, points, linear):
            if key not in children[node]:
                nodes.append((node, key, kind, data))
                children.append({})
                children[node][key] = len(nodes) - 1
            node = children[node][key]
        ends.append(node)

    joints, joint_at = _joints(spec, nodes, q, *_frames(nodes, points, linear, q))
    inertias, body_links = _link_inertias(spec, nodes, ends, joint_at, len(joints))
    return JointTree(tuple(joints), inertias, tuple(body_links),
                     spec.armature_by_dof if spec.armature else ())


def _frames(nodes, points, linear, q) -> tuple:
    """``(orient, origin)``: the orientation base and the origin (point,
    correction in that base) after each trie node."""
    orient = {0: CANONICAL_BASE}
    origin = {0: (CANONICAL_POINT, ZERO3)}
    for node in range(1, len(nodes)):
        parent, key, kind, data = nodes[node]
        orient[node], origin[node] = orient[parent], origin[parent]
        if kind == "rot":
            orient[node] = data.name
        elif kind in ("ball", "free"):
            orient[node] = data.base
            if kind == "free":
                origin[node] = (data.point, ZERO3)
        elif kind in ("trans", "prism"):
            point = points[key[1]]
            slopes = [sl for sl, _ in linear[point.name]]
            later = [k for k in sorted({k for sl in slopes for k in sl}) if k > key[2]]
            origin[node] = (point.name, tuple(-sympy.Add(*[sl.get(k, ZERO) * q[k] for k in later])
                                              for sl in slopes))
    return orient, origin


def _composed(nodes, joint_at, node) -> tuple:
    """``(up, (E, r))``: the nearest node at or above ``node`` that is a joint
    (or the root, 0) and the constant transform of the ops in between."""
    ops = []
    while node and node not in joint_at:
        ops.append(nodes[node])
        node = nodes[node][0]
    composed = _Compose()
    for _, _, okind, odata in reversed(ops):
        if okind == "rot":
            composed.rotate(rotation(odata.axis, sympy.cos(odata.angle), sympy.sin(odata.angle)))
        else:
            composed.translate(odata)
    return node, composed.value()


def _joints(spec, nodes, q, orient, origin) -> tuple:
    """``(joints, joint_at)``: the trie nodes whose op moves with a coordinate,
    parents first (node order), and {node: joint index}; a coordinate that
    moves two places or none, or a joint that moves no body, is an error."""
    joint_at: dict = {}
    joints = []
    seen: dict = {}                     # coordinate -> key
    for node in range(1, len(nodes)):
        parent, key, kind, data = nodes[node]
        if kind == "rot":
            lin = _linear_in(data.angle, q)[0]
            if not lin:
                continue
            (k, a), = lin.items()
            source = f"bases.{data.name}.angle"
        elif kind == "prism":
            k, direction, point = data
            source = f"points.{point.name}.coordinates"
        elif kind in ("ball", "free"):
            k, source = data.name, f"joints.{data.name}"
        else:
            continue
        if k in seen:
            raise _error(spec, source,
                         f"coordinate {spec.coordinates[k]!r} ({source}) moves different "
                         "bodies about different places: it is not one joint")
        seen[k] = source
        # walk up to the previous joint, composing the constant ops on the way
        up, fixed = _composed(nodes, joint_at, parent)
        if kind in ("ball", "free"):
            joint = _quaternion_joint(spec, data, joint_at.get(up, -1), fixed,
                                      orient[node], origin[node])
        elif kind == "rot":
            S = (a if data.axis == 1 else ZERO, a if data.axis == 2 else ZERO,
                 a if data.axis == 3 else ZERO, ZERO, ZERO, ZERO)
            joint = Joint(spec.coordinates[k], k, joint_at.get(up, -1), fixed,
                          "revolute", data.axis, data.angle, ZERO3, S, source,
                          orient[node], origin[node])
        else:
            joint = Joint(spec.coordinates[k], k, joint_at.get(up, -1), fixed,
                          "prismatic", 0, ZERO, tuple(d * q[k] for d in direction),
                          ZERO3 + tuple(direction), source, orient[node], origin[node])
        joint_at[node] = len(joints)
        joints.append(joint)
    for j in spec.joints:
        if j.name not in seen:
            raise _error(spec, f"joints.{j.name}", f"joint {j.name!r} moves no body")
    for k, name in enumerate(spec.simple_coordinates):
        if k not in seen:
            place = _occurrences(spec, {k: q[k]})[k]
            key = place[0][0] if place else "coordinates"
            raise _error(spec, key, f"coordinate {name!r} moves no body")
    return joints, joint_at


def _link_inertias(spec, nodes, ends, joint_at, count) -> tuple:
    """``(inertias, body_links)``: the bodies merged per link (one
    :class:`LinkInertia` per joint) and each body's link (-1: the ground)."""
    merged: dict = {}
    body_links = []
    for body, end in zip(spec.bodies, ends, strict=True):
        node, (E, r) = _composed(nodes, joint_at, end)
        body_links.append((body.name, joint_at.get(node, -1)))
        if not node:
            continue                    # fixed to the ground
        I, h, m = _spatial_inertia(body, E, r)
        i = joint_at[node]
        if i in merged:
            I0, h0, m0, names = merged[i]
            I, h, m = add(I0, I), add(h0, h), m0 + m
            names = names + (body.name,)
        else:
            names = (body.name,)
        merged[i] = (I, h, m, names)
    inertias = tuple(LinkInertia(*merged[i]) if i in merged else
                     LinkInertia((ZERO,) * 6, ZERO3, ZERO, ()) for i in range(count))
    return inertias, body_links


def _quaternion_joint(spec: ModelSpec, joint, parent: int, fixed: tuple, base: str,
                      origin: tuple) -> Joint:
    """A ball or free joint of the spec as a multi-degree-of-freedom Joint.

    Its motion subspace, in the link frame, is the identity on its speeds: the
    angular velocity (and a free joint's linear velocity of its point) in the
    joint's own base, which is the link frame.
    """
    speed_index = {v: k for k, v in enumerate(spec.speeds)}
    unit = lambda j: tuple(ONE if i == j else ZERO for i in range(6))   # noqa: E731
    rates = [speed_index[v] for v in joint.speeds[-3:]]
    columns = [(k, unit(j)) for j, k in enumerate(rates)]
    position = ()
    if joint.kind == "free":
        columns = [(speed_index[v], unit(3 + j)) for j, v in enumerate(joint.speeds[:3])] \
            + columns
        position = tuple(symbol(c) for c in joint.coordinates[:3])
    first = columns[0][0]
    return Joint(joint.name, first, parent, fixed, joint.kind, 0, ZERO, ZERO3, columns[0][1],
                 f"joints.{joint.name}", base, origin, tuple(columns),
                 tuple(symbol(c) for c in joint.quaternion), position)


def is_joint_tree(spec: ModelSpec) -> bool:
    """True if :func:`extract_joint_tree` accepts ``spec``."""
    try:
        extract_joint_tree(spec)
    except ModelError:
        return False
    return True


__all__ = ["Joint", "LinkInertia", "JointTree", "extract_joint_tree", "is_joint_tree"]
