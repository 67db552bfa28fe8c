"""URDF text -> a checked :class:`Robot` (links, joints, the tree), every item with its line.

The XML is read with :mod:`xml.parsers.expat` directly, recording the line of
every element.  Entity declarations are refused (this stops "billion laughs"
expansion and external entities, as ``defusedxml`` does), so no dependency is
needed.  Tags the importer does not use (``visual``, ``collision`` with their
meshes, ``material``, ``gazebo``...) are skipped: no mesh file is ever
opened.  Of a ``<transmission>``, only Drake's rotor extension is read
(``<actuator>`` with ``<drake:rotor_inertia value=...>`` and
``<drake:gear_ratio value=...>``): the joint's armature is
rotor_inertia * gear_ratio^2, the reflected inertia of its rotor.

Errors are :class:`~modelgen.errors.ModelError` with the URDF file, line and a
key such as ``joint[shoulder].axis``.

>>> robot = parse_robot('<robot name="r"><link name="a"/><link name="b"/>'
...     '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
...     '<axis xyz="0 0 1"/></joint></robot>')
>>> robot.root, [j.name for j in robot.order]
('a', ['j'])
"""
from __future__ import annotations

import math
import xml.parsers.expat as expat
from typing import NamedTuple, Optional

import numpy as np

from modelgen.errors import ModelError

__all__ = ["JOINT_TYPES", "Inertial", "Link", "Limit", "Joint", "Rotor", "Robot",
           "parse_robot",
           "rpy_matrix", "unit_vector"]

#: joint types the importer builds (``floating`` only as a fixed root, on request)
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating")


class Inertial(NamedTuple):
    mass: float
    xyz: tuple          # centre of mass in the link frame
    rpy: tuple          # orientation of the inertia's frame in the link frame
    inertia: np.ndarray  # 3x3 about the centre of mass, in the inertia's frame
    line: int
    inertia_line: int = 0   # the line of <inertia>


class Link(NamedTuple):
    name: str
    inertial: Optional[Inertial]
    line: int


class Limit(NamedTuple):
    lower: Optional[float]
    upper: Optional[float]
    velocity: Optional[float]
    effort: Optional[float]


class Joint(NamedTuple):
    name: str
    type: str
    parent: str
    child: str
    xyz: tuple
    rpy: tuple
    axis: tuple           # unit vector in the joint frame
    limit: Optional[Limit]
    mimic: Optional[tuple]  # (joint, multiplier, offset)
    damping: float
    friction: float
    line: int


class Rotor(NamedTuple):
    """Drake's URDF rotor extension of one joint's transmission."""
    joint: str
    rotor_inertia: float   # kg m^2 (revolute) or kg (prismatic), on the motor side
    gear_ratio: float      # motor speed / joint speed (Drake's default 1)
    armature: float        # rotor_inertia * gear_ratio^2: added to the joint's A_ii
    line: int


class Robot(NamedTuple):
    name: str
    file: str
    links: dict           # name -> Link, file order
    joints: dict          # name -> Joint, file order
    root: str
    order: tuple          # joints in depth-first order from the root, children in file order
    ignored_mimics: tuple = ()   # (joint, the joint its ignored <mimic> named), file order
    rotors: tuple = ()           # Rotor per joint with Drake's rotor extension, file order


class _Node(NamedTuple):
    tag: str
    attrib: dict
    line: int
    children: list


def unit_vector(v) -> Optional[tuple]:
    """``v`` divided by its length, or None for a zero vector.

    Scaled by the largest component first, so that the squares cannot overflow
    (1e308) or underflow (1e-200) and no direction is lost.

    >>> [round(x, 12) for x in unit_vector((1e308, 1e308, 1e308))]
    [0.57735026919, 0.57735026919, 0.57735026919]
    >>> unit_vector((0.0, -0.0, 0.0)) is None
    True
    """
    scale = max(abs(x) for x in v)
    if not scale > 0:
        return None
    w = [x / scale for x in v]
    norm = math.sqrt(sum(x * x for x in w))
    return tuple(x / norm for x in w)


def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll): joint-frame components -> parent-frame components.

    >>> bool(np.allclose(rpy_matrix((0, 0, math.pi / 2)) @ [1, 0, 0], [0, 1, 0]))
    True
    """
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


class _Reader:
    def __init__(self, file: str, ignore_mimic: bool = False):
        self.file = file
        self.ignore_mimic = ignore_mimic
        self.ignored_mimics: list = []

    def error(self, problem: str, line: Optional[int], key: Optional[str], fix: str):
        return ModelError(problem, file=self.file, line=line, key=key, fix=fix)

    # -- XML ------------------------------------------------------------------
    def xml(self, data) -> _Node:
        parser = expat.ParserCreate()
        parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
        stack: list = []
        top: list = []

        def start(tag, attrib):
            node = _Node(tag, attrib, parser.CurrentLineNumber, [])
            (stack[-1].children if stack else top).append(node)
            stack.append(node)

        def end(_tag):
            stack.pop()

        def entity(name, *_args):
            raise self.error(f"entity declaration '{name}' refused", parser.CurrentLineNumber,
                             None, "URDF files need no entities; expand them or use xacro "
                                   "to produce plain URDF")

        def external(*_args):
            raise self.error("external entity refused", parser.CurrentLineNumber, None,
                             "remove the external reference")

        parser.StartElementHandler = start
        parser.EndElementHandler = end
        parser.EntityDeclHandler = entity
        parser.ExternalEntityRefHandler = external
        try:
            parser.Parse(data, True)
        except expat.ExpatError as exc:
            raise self.error(f"malformed XML: {expat.errors.messages[exc.code]}", exc.lineno,
                             None, "correct the XML syntax") from None
        if top[0].tag != "robot":
            raise self.error(f"the root element is <{top[0].tag}>, not <robot>", top[0].line,
                             None, "a URDF file is one <robot> element")
        return top[0]

    # -- values ---------------------------------------------------------------
    def attr(self, node: _Node, name: str, key: str, default=None, required=True) -> str:
        value = node.attrib.get(name)
        if value is None:
            if not required:
                return default
            raise self.error(f"missing attribute '{name}' of <{node.tag}>", node.line, key,
                             f'add {name}="..."')
        return value

    def number(self, text: str, line: int, key: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value):
            raise self.error(f"malformed number '{text}'", line, key,
                             "write a finite decimal number such as 0.25 or 1e-3")
        return value

    def numbers(self, node: Optional[_Node], name: str, key: str, default: tuple) -> tuple:
        if node is None or name not in node.attrib:
            return default
        parts = node.attrib[name].split()
        if len(parts) != 3:
            raise self.error(f"{name}=\"{node.attrib[name]}\" needs 3 numbers but has "
                             f"{len(parts)}", node.line, key, f'write {name}="x y z"')
        return tuple(self.number(p, node.line, key) for p in parts)

    def optional(self, node: Optional[_Node], name: str, key: str) -> Optional[float]:
        if node is None or name not in node.attrib:
            return None
        return self.number(node.attrib[name], node.line, f"{key}.{name}")

    @staticmethod
    def child(node: _Node, tag: str) -> Optional[_Node]:
        return next((c for c in node.children if c.tag == tag), None)

    def name(self, node: _Node) -> str:
        name = node.attrib.get("name")
        if not name:
            raise self.error(f"<{node.tag}> without a name", node.line, node.tag,
                             f'give every <{node.tag}> a unique name="..."')
        return name

    # -- links and joints -----------------------------------------------------
    def link(self, node: _Node) -> Link:
        name = self.name(node)
        key = f"link[{name}].inertial"
        inertial = self.child(node, "inertial")
        if inertial is None:
            return Link(name, None, node.line)
        origin = self.child(inertial, "origin")
        xyz = self.numbers(origin, "xyz", f"{key}.origin.xyz", (0.0, 0.0, 0.0))
        rpy = self.numbers(origin, "rpy", f"{key}.origin.rpy", (0.0, 0.0, 0.0))
        mass_node = self.child(inertial, "mass")
        if mass_node is None:
            raise self.error("<inertial> without <mass>", inertial.line, key,
                             'add <mass value="..."/>')
        mass = self.number(self.attr(mass_node, "value", f"{key}.mass"), mass_node.line,
                           f"{key}.mass")
        if mass < 0:
            raise self.error(f"negative mass {mass!r}", mass_node.line, f"{key}.mass",
                             "give a mass >= 0")
        inode = self.child(inertial, "inertia")
        if inode is None:
            raise self.error("<inertial> without <inertia>", inertial.line, key,
                             'add <inertia ixx="..." ixy="..." ixz="..." iyy="..." iyz="..." '
                             'izz="..."/>')
        v = {a: self.number(self.attr(inode, a, f"{key}.inertia.{a}"), inode.line,
                            f"{key}.inertia.{a}")
             for a in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        matrix = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                           [v["ixz"], v["iyz"], v["izz"]]])
        # whether a rigid body can have this inertia is checked on the body it becomes
        # part of, after the links welded to it are merged (see urdf.py)
        return Link(name, Inertial(mass, xyz, rpy, matrix, inertial.line, inode.line),
                    node.line)

    def joint(self, node: _Node, links: dict) -> Joint:
        name = self.name(node)
        key = f"joint[{name}]"
        kind = self.attr(node, "type", f"{key}.type")
        if kind not in JOINT_TYPES:
            fix = ("model it as two prismatic joints and a revolute joint"
                   if kind == "planar" else f"use one of {', '.join(JOINT_TYPES)}")
            raise self.error(f"unsupported joint type '{kind}'", node.line, f"{key}.type", fix)
        ends = []
        for end in ("parent", "child"):
            sub = self.child(node, end)
            if sub is None:
                raise self.error(f"joint '{name}' has no <{end}>", node.line, f"{key}.{end}",
                                 f'add <{end} link="..."/>')
            link = self.attr(sub, "link", f"{key}.{end}")
            if link not in links:
                raise self.error(f"unknown link '{link}'", sub.line, f"{key}.{end}",
                                 "declare the link with <link name=...> or correct the name")
            ends.append(link)
        origin = self.child(node, "origin")
        xyz = self.numbers(origin, "xyz", f"{key}.origin.xyz", (0.0, 0.0, 0.0))
        rpy = self.numbers(origin, "rpy", f"{key}.origin.rpy", (0.0, 0.0, 0.0))
        axis_node = self.child(node, "axis")
        # read for every joint type: a fixed joint's axis is unused, but a malformed or
        # non-finite number anywhere in the file is refused, not skipped
        axis = self.numbers(axis_node, "xyz", f"{key}.axis", (1.0, 0.0, 0.0))
        if kind in ("revolute", "continuous", "prismatic"):
            axis = unit_vector(axis)
            if axis is None:
                raise self.error("the joint axis is zero", (axis_node or node).line,
                                 f"{key}.axis", 'give a unit vector such as xyz="0 0 1"')
        lim = self.child(node, "limit")
        limit = None if lim is None else Limit(*(self.optional(lim, a, f"{key}.limit") for a in
                                                 ("lower", "upper", "velocity", "effort")))
        mim = self.child(node, "mimic")
        mimic = None
        if mim is not None:
            multiplier = self.optional(mim, "multiplier", f"{key}.mimic")
            offset = self.optional(mim, "offset", f"{key}.mimic")
            mimic = (self.attr(mim, "joint", f"{key}.mimic"),
                     1.0 if multiplier is None else multiplier, offset or 0.0)
            if self.ignore_mimic:       # read (its numbers checked), then dropped
                self.ignored_mimics.append((name, mimic[0]))
                mimic = None
        dyn = self.child(node, "dynamics")
        damping = self.optional(dyn, "damping", f"{key}.dynamics") or 0.0
        friction = self.optional(dyn, "friction", f"{key}.dynamics") or 0.0
        for what, value in (("damping", damping), ("friction", friction)):
            if value < 0:
                raise self.error(f"negative {what} {value!r}", dyn.line,
                                 f"{key}.dynamics.{what}", f"give a {what} >= 0")
        return Joint(name, kind, ends[0], ends[1], xyz, rpy, axis, limit, mimic, damping,
                     friction, node.line)

    def rotor(self, node: _Node, joints: dict) -> Optional[Rotor]:
        """A ``<transmission>``'s Drake rotor (None when it has none): Drake reads
        ``<drake:rotor_inertia>`` and ``<drake:gear_ratio>`` in its ``<actuator>``."""
        actuator = self.child(node, "actuator")
        if actuator is None:
            return None
        inertia = self.child(actuator, "drake:rotor_inertia")
        ratio = self.child(actuator, "drake:gear_ratio")
        if inertia is None and ratio is None:
            return None
        name = node.attrib.get("name", "")
        key = f"transmission[{name}]"
        joint = self.child(node, "joint")
        if joint is None:
            raise self.error("a transmission with a rotor names no <joint>", node.line, key,
                             'add <joint name="..."/>')
        target = self.attr(joint, "name", f"{key}.joint")
        if target not in joints:
            raise self.error(f"transmission of unknown joint '{target}'", joint.line,
                             f"{key}.joint", "name an existing joint")
        values = []
        for sub, tag, default in ((inertia, "rotor_inertia", 0.0), (ratio, "gear_ratio", 1.0)):
            if sub is None:
                values.append(default)
                continue
            values.append(self.number(self.attr(sub, "value", f"{key}.{tag}"), sub.line,
                                      f"{key}.{tag}"))
        rotor_inertia, gear_ratio = values
        if rotor_inertia < 0:
            raise self.error(f"negative rotor inertia {rotor_inertia!r}", inertia.line,
                             f"{key}.rotor_inertia", "give a rotor inertia >= 0")
        # one rounding (the square first) unless the square overflows where the product
        # would not (a huge ratio, a tiny rotor)
        with np.errstate(over="ignore"):
            square = np.float64(gear_ratio) * np.float64(gear_ratio)
            armature = 0.0 if not rotor_inertia else float(
                rotor_inertia * square if math.isfinite(square) else
                np.float64(rotor_inertia) * np.float64(gear_ratio) * np.float64(gear_ratio))
        if not math.isfinite(armature):
            raise self.error(f"the armature rotor_inertia * gear_ratio^2 = {rotor_inertia!r}"
                             f" * {gear_ratio!r}^2 is too large for a double", node.line, key,
                             "give the rotor inertia in kg m^2 and the gear ratio as motor "
                             "turns per joint turn")
        return Rotor(target, rotor_inertia, gear_ratio, armature, node.line)

    # -- the tree -------------------------------------------------------------
    def robot(self, data) -> Robot:
        top = self.xml(data)
        if not any(node.tag in ("link", "joint") for node in top.children):
            raise self.error("the <robot> element is empty: no <link> and no <joint>",
                             top.line, "robot",
                             "a URDF describes at least one link; if the file was made by "
                             "xacro from a file that only defines macros (ur3.urdf of "
                             "example-robot-data), generate it from the file that calls "
                             "them (ur3_robot.urdf.xacro)")
        robot_name = self.name(top)

        links: dict = {}
        for node in top.children:
            if node.tag == "link":
                link = self.link(node)
                if link.name in links:
                    raise self.error(f"link '{link.name}' is declared twice (first on line "
                                     f"{links[link.name].line})", node.line,
                                     f"link[{link.name}]", "give every link a unique name")
                links[link.name] = link
        if not links:
            raise self.error("the robot has no <link>", top.line, "robot",
                             "declare at least one link")
        joints: dict = {}
        parent_joint: dict = {}
        for node in top.children:
            if node.tag != "joint":
                continue
            joint = self.joint(node, links)
            if joint.name in joints:
                raise self.error(f"joint '{joint.name}' is declared twice (first on line "
                                 f"{joints[joint.name].line})", node.line,
                                 f"joint[{joint.name}]", "give every joint a unique name")
            if joint.child in parent_joint:
                other = parent_joint[joint.child]
                raise self.error(f"loop: link '{joint.child}' has two parents, through joint "
                                 f"'{other.name}' (line {other.line}) and joint '{joint.name}'",
                                 node.line, f"joint[{joint.name}].child",
                                 "a URDF is a tree: give every link at most one parent joint")
            joints[joint.name] = joint
            parent_joint[joint.child] = joint
        roots = [name for name in links if name not in parent_joint]
        if len(roots) != 1:
            line = top.line if not roots else links[roots[1]].line
            problem = ("loop: every link has a parent joint" if not roots else
                       f"{len(roots)} root links ({', '.join(roots[:5])}): the links are not "
                       "one tree")
            raise self.error(problem, line, "robot",
                             "connect the links into one tree with a single root link")
        root = roots[0]
        children: dict = {name: [] for name in links}
        for joint in joints.values():
            children[joint.parent].append(joint)
        order = []
        stack = list(reversed(children[root]))
        while stack:
            joint = stack.pop()
            order.append(joint)
            stack.extend(reversed(children[joint.child]))
        if len(order) != len(joints):
            lost = next(j for j in joints.values() if j not in order)
            raise self.error(f"loop: joint '{lost.name}' is on a cycle not connected to the "
                             f"root link '{root}'", lost.line, f"joint[{lost.name}]",
                             "a URDF is a tree: remove the joint that closes the loop")
        for joint in order:
            self.check_joint_use(joint, joints, root)
        rotors: dict = {}
        for node in top.children:
            rotor = self.rotor(node, joints) if node.tag == "transmission" else None
            if rotor is None:
                continue
            joint = joints[rotor.joint]
            key = f"joint[{joint.name}]"
            if rotor.joint in rotors:
                raise self.error(f"joint '{rotor.joint}' has two rotors (the first on line "
                                 f"{rotors[rotor.joint].line})", rotor.line, key,
                                 "give each joint one transmission with a rotor")
            if joint.type not in ("revolute", "continuous", "prismatic") \
                    or joint.mimic is not None:
                raise self.error(f"a rotor on joint '{joint.name}', which has no coordinate "
                                 f"of its own ({joint.type}"
                                 f"{', mimic' if joint.mimic else ''})", rotor.line, key,
                                 "put the rotor on a revolute, continuous or prismatic joint "
                                 "that is not a mimic")
            rotors[rotor.joint] = rotor
        return Robot(robot_name, self.file, links, joints, root, tuple(order),
                     tuple(self.ignored_mimics), tuple(rotors.values()))

    def check_joint_use(self, joint: Joint, joints: dict, root: str):
        key = f"joint[{joint.name}]"
        if joint.type == "floating" and joint.mimic is not None:
            raise self.error("a floating joint cannot mimic another joint", joint.line,
                             f"{key}.mimic", "remove the <mimic> element")
        if joint.mimic is None or joint.type in ("fixed", "floating"):
            return
        target = joints.get(joint.mimic[0])
        if target is None:
            raise self.error(f"mimic of unknown joint '{joint.mimic[0]}'", joint.line,
                             f"{key}.mimic", "name an existing joint; or read every joint "
                             "as a joint of its own, ignoring the file's <mimic> tags as "
                             "Pinocchio's mimic=False does, with mimic=\"ignore\" (command "
                             "line: --mimic ignore)")
        if target.mimic is not None or target.type not in ("revolute", "continuous",
                                                           "prismatic"):
            raise self.error(f"mimic of joint '{target.name}', which has no coordinate of its "
                             f"own ({target.type}{', mimic' if target.mimic else ''})",
                             joint.line, f"{key}.mimic",
                             "mimic a revolute, continuous or prismatic joint that is not "
                             "itself a mimic; or ignore the file's <mimic> tags with "
                             "mimic=\"ignore\" (command line: --mimic ignore)")


def parse_robot(data, source: str = "<string>", *, ignore_mimic: bool = False) -> Robot:
    """Read URDF text (str or bytes) into a checked :class:`Robot` (what becomes of a
    ``floating`` joint is the importer's choice: :mod:`modelgen.model.urdf`).

    ``ignore_mimic`` drops every ``<mimic>`` (each joint then has a coordinate
    of its own) and lists them in :attr:`Robot.ignored_mimics`.
    """
    return _Reader(source, ignore_mimic).robot(data)
