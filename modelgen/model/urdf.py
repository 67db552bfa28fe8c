"""URDF import: a fixed-base robot description -> a :class:`~modelgen.model.Model`.

:func:`load_urdf` reads a ``.urdf`` file (``modelgen.load("robot.urdf")`` and
``modelgen import robot.urdf -o robot.yaml`` use it) and builds the model
through the public :class:`Model` API, so every check of the model loader
applies.  What becomes what:

* The root link is the ground (base ``E``, point ``O``).  Gravity is
  ``[0, 0, -g]`` in E with parameter ``g = 9.81``.
* A joint's ``origin`` is a point ``J_<joint>`` (``P_<link>`` for a fixed
  joint: the child link's origin; from the parent link's origin, in its base) and constant rotations ``B_<joint>_rz``, ``_ry``,
  ``_rx`` for ``rpy`` (R = Rz(yaw) Ry(pitch) Rx(roll): yaw about z first,
  moving axes); zero offsets and angles are left out.
* ``revolute`` and ``continuous`` joints are one angle coordinate; an axis
  along +-x, +-y or +-z is one simple rotation (the angle negated for a
  negative axis), any other unit axis a: constant rotations ``_az`` (about
  z by atan2(ay, ax)) and ``_ay`` (about y by acos(az)) that bring z onto
  a, the rotation about z, and the same two undone.  ``prismatic`` joints
  move the child's origin by ``q * a`` in the joint frame.  The child link's
  base is ``B_<link>`` (or the joint frame's base when the joint does not
  rotate), its origin point ``P_<link>`` (or the joint point).
* Coordinates are the joint names with every character outside
  ``[A-Za-z0-9_]`` replaced by ``_``, in depth-first order from the root
  (children in file order).  A ``mimic`` joint has no coordinate: its
  position is ``multiplier * q + offset`` of the joint it mimics, and it has
  no input or effects.  A mimic of a joint the file does not have is
  refused unless ``mimic="ignore"``, which drops every ``<mimic>`` tag (each
  joint its own coordinate, as Pinocchio's ``mimic=False``; a warning).
* A ``fixed`` joint welds its child to the parent: the child keeps its
  frames (bases and points, so outputs can use them) and its mass, centre of
  mass and inertia are merged exactly into the parent's body (the body of a
  group of welded links is named after its first link).  Links welded to
  the root do not move and get no body.  A link without ``<inertial>`` is a
  massless frame; a moving group without mass is a body of mass 0 (so the
  joint torques have a body to act on).
* Each joint with a coordinate gets an input ``tau_<joint>``: a torque about
  (revolute) or a force along (prismatic) the axis acting on the child's
  body, with the reaction on the parent's body (actions ``motor_<joint>``
  and ``motor_<joint>_reaction``), so ``tau_<joint>`` is exactly the
  generalized force of the joint's coordinate.
* Drake's rotor extension of a ``<transmission>`` (``<actuator>`` with
  ``<drake:rotor_inertia value=...>`` and ``<drake:gear_ratio value=...>``,
  default ratio 1) is the joint's armature, rotor_inertia * gear_ratio^2
  (the model's ``armature:``), as Drake's MultibodyPlant reflects it.
* ``<dynamics damping=...>`` > 0 is an effect ``damping_<joint>`` (type
  ``joint_damping``) and ``friction`` > 0 an effect ``friction_<joint>``
  (type ``friction``, Coulomb level = the URDF value); ``<limit>`` values are
  kept in :attr:`UrdfImport.joints` and written as comments by
  :func:`urdf_to_yaml`.
* Masses, centres of mass and inertias are numbers (exact decimals of the
  URDF values) unless ``inertial_parameters=True``, which makes each body's
  mass ``m_<body>`` and inertia entries ``I_<body>_xx`` ... parameters.
* A ``floating`` joint is a ``free`` joint (a position and a unit quaternion,
  6 speeds: Pinocchio's free-flyer) named after the joint, from the joint
  origin's point and base to the child's; it has no input (nothing actuates
  it).  ``floating_base=True`` makes the root link itself a free body,
  through a free joint ``root_joint`` from E/O, as Pinocchio's
  ``buildModel(urdf, JointModelFreeFlyer())`` does.  The free joints'
  coordinates and speeds come after the joint angles (modelgen's order: simple
  coordinates first), where Pinocchio puts its free-flyer first.
  ``fix_floating_root=True`` welds a floating joint at the root instead and
  says so in the description.  Meshes are never opened.
* Inertias are checked on each moving body after its welded links are merged,
  with a tolerance of the body's own scale (rounding noise passes; a particle
  stays a particle).  A body no rigid body matches is refused unless
  ``inertia="as_is"`` (the file's values, as Pinocchio; a warning) or
  ``inertia="balance"`` (MuJoCo's ``balanceinertia``: the principal moments
  set to their mean); ``min_mass`` and ``min_inertia`` are MuJoCo's
  ``boundmass`` and ``boundinertia``.  A joint moving only massless links, and a
  fixed robot without joints, are refused with a fix naming the option.
* Every link is a frame (its origin point and base, Pinocchio's BODY frame) named
  after the link, or ``<link>_frame`` when a body (a moving link's) has the name.

>>> imp = import_urdf_text('''<robot name="pend"><link name="world"/>
...   <link name="rod"><inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
...     <inertia ixx="0.1" iyy="0.1" izz="0" ixy="0" ixz="0" iyz="0"/></inertial></link>
...   <joint name="hinge" type="continuous"><parent link="world"/><child link="rod"/>
...     <axis xyz="0 1 0"/></joint></robot>''')
>>> spec = imp.model.spec()
>>> spec.coordinates, spec.inputs, spec.bases[0].axis
(('hinge',), ('tau_hinge',), 2)
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import NamedTuple, Optional

import numpy as np
import sympy

from modelgen.errors import ModelError
from modelgen.model.api import Model, check_name
from modelgen.model.messages import comment_text
from modelgen.model.names import fresh_name, model_name_for, sanitize
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, JOINT_KINDS, symbol
from modelgen.model.urdf_read import Joint, Limit, Robot, parse_robot, rpy_matrix

__all__ = ["UrdfImport", "JointInfo", "ReadingOptions", "INERTIA_OPTIONS", "MIMIC_OPTIONS",
           "reading_options",
           "load_urdf", "import_urdf", "import_urdf_text", "urdf_to_yaml", "sanitize"]

_MOVING = ("revolute", "continuous", "prismatic")


class JointInfo(NamedTuple):
    """What the model keeps of one URDF joint (limits for later use)."""
    name: str                  # URDF name
    type: str
    coordinate: Optional[str]  # None for fixed and mimic joints
    input: Optional[str]
    limit: Optional[Limit]
    damping: float
    friction: float
    mimic: Optional[tuple] = None   # (coordinate, multiplier, offset) of a mimic joint


#: values of the ``inertia`` option: refuse what no rigid body has (default), take the
#: file's values as Pinocchio does, or apply MuJoCo's ``balanceinertia`` rule
INERTIA_OPTIONS = ("physical", "as_is", "balance")

#: values of the ``mimic`` option: a ``<mimic>`` joint follows the joint it names
#: (default; a mimic of a missing joint is refused), or every ``<mimic>`` tag is
#: ignored and each joint has a coordinate of its own (Pinocchio's ``mimic=False``)
MIMIC_OPTIONS = ("strict", "ignore")


class ReadingOptions(NamedTuple):
    """How non-physical or massless bodies are read (MuJoCo's compiler options
    ``balanceinertia``, ``boundmass`` and ``boundinertia``; Pinocchio's as-is)."""
    inertia: str = "physical"   # one of INERTIA_OPTIONS
    min_mass: float = 0.0       # lower bound on each moving body's mass [kg]
    min_inertia: float = 0.0    # lower bound on each principal moment [kg m^2]
    mimic: str = "strict"       # one of MIMIC_OPTIONS

    def text(self) -> str:
        """The options as keyword arguments ('' for the defaults).

        >>> ReadingOptions("balance", 0.0, 1e-6).text()
        'inertia="balance", min_inertia=1e-06'
        >>> ReadingOptions(mimic="ignore").text()
        'mimic="ignore"'
        """
        parts = [f'inertia="{self.inertia}"'] if self.inertia != "physical" else []
        parts += [f"{k}={v!r}" for k, v in (("min_mass", self.min_mass),
                                              ("min_inertia", self.min_inertia)) if v > 0]
        parts += [f'mimic="{self.mimic}"'] if self.mimic != "strict" else []
        return ", ".join(parts)


def reading_options(inertia: str = "physical", min_mass: float = 0.0,
                    min_inertia: float = 0.0, mimic: str = "strict") -> ReadingOptions:
    """Checked :class:`ReadingOptions` ("as-is" is accepted for "as_is")."""
    inertia = "as_is" if inertia == "as-is" else inertia
    if inertia not in INERTIA_OPTIONS:
        raise ValueError(f"inertia={inertia!r}: use one of "
                         + ", ".join(repr(o) for o in INERTIA_OPTIONS))
    if mimic not in MIMIC_OPTIONS:
        raise ValueError(f"mimic={mimic!r}: use one of "
                         + ", ".join(repr(o) for o in MIMIC_OPTIONS))
    for name, value in (("min_mass", min_mass), ("min_inertia", min_inertia)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name}={value!r}: give a finite number >= 0")
    return ReadingOptions(inertia, float(min_mass), float(min_inertia), mimic)


class UrdfImport(NamedTuple):
    """The result of an import: the model, the joints' data and notes for the reader."""
    model: Model
    joints: tuple      # JointInfo in depth-first order
    source: str
    notes: tuple       # sentences (e.g. a floating root imported fixed)
    options: ReadingOptions = ReadingOptions()


def _num(x: float):
    """A float as an exact sympy number of its shortest decimal (ints stay ints)."""
    if x == int(x) and abs(x) < 2 ** 53:
        return sympy.Integer(int(x))
    return sympy.Rational(repr(float(x)))


class _Builder:
    def __init__(self, robot: Robot, inertial_parameters: bool, notes: tuple,
                 floating_base: bool = False, fix_floating_root: bool = False,
                 options: Optional[ReadingOptions] = None):
        self.robot = robot
        self.options = options = options or ReadingOptions()
        self.changes: list = []       # what the reading options changed or let through
        self.fix_floating_root = fix_floating_root
        self.free_links: set = set()
        self.inertial_parameters = inertial_parameters
        self.notes = notes
        self.floating_base = floating_base
        moving = [j for j in robot.order if j.type in _MOVING]
        free = sum(j.type == "floating" and not (fix_floating_root and j.parent == robot.root)
                   for j in robot.order)
        text = (f"Robot '{robot.name}' imported from {Path(robot.file).name}: "
                f"{sum(j.mimic is None for j in moving)} coordinates, "
                f"{len(moving) + free + floating_base} moving links"
                + (f", {free} floating joints" if free else "")
                + (", floating base." if floating_base else ", fixed base.")
                + (f" Read with {options.text()}." if options.text() else ""))
        self.model = Model(self.model_name(), " ".join((text,) + notes),
                           physical_inertia=options.inertia != "as_is")
        self.actuation: dict = {}                     # joint -> (base, point, unit axis)
        self.taken: set = set()
        self.base = {robot.root: CANONICAL_BASE}      # link -> base name
        self.point = {robot.root: CANONICAL_POINT}    # link -> point name
        self.group = {robot.root: robot.root}          # link -> head of its welded group
        self.placement = {robot.root: (np.eye(3), np.zeros(3))}   # link in its group's frame
        self.coordinate: dict = {}                    # joint -> coordinate name
        self.infos: list = []
        if robot.ignored_mimics:
            self.changes.append("the <mimic> tags of " + ", ".join(
                f"joint '{joint}' (of '{target}')" for joint, target in robot.ignored_mimics)
                + " were ignored: each of these joints has a coordinate of its own (mimic)")

    def error(self, problem, joint: Joint, key: str, fix: str) -> ModelError:
        return ModelError(problem, file=self.robot.file, line=joint.line,
                          key=f"joint[{joint.name}].{key}", fix=fix)

    def model_name(self) -> str:
        """The robot's name made a valid model name (a keyword such as 'True' or 'int'
        gets the suffix '_robot': the name is a C prefix and a Python identifier)."""
        return model_name_for(self.robot.name)

    def unique(self, wanted: str) -> str:
        """A fresh valid name close to ``wanted`` (suffix _2, _3... on a clash)."""
        return fresh_name(wanted, self.taken)

    # -- declarations ---------------------------------------------------------
    def coordinates(self) -> None:
        for joint in self.robot.order:
            if joint.type not in _MOVING or joint.mimic is not None:
                continue
            name = sanitize(joint.name)
            key = f"joint[{joint.name}]"
            check_name(name, file=self.robot.file, line=joint.line, key=key,
                       what="coordinate (the sanitized joint name)")
            if name in self.taken or f"{name}_dot" in self.taken or \
                    (name.endswith("_dot") and name[:-4] in self.taken):
                raise ModelError(f"joint '{joint.name}' gives coordinate '{name}', which "
                                 "clashes with another joint's coordinate or speed",
                                 file=self.robot.file, line=joint.line, key=key,
                                 fix="rename one of the joints")
            self.taken.add(name)
            self.coordinate[joint.name] = name
            self.model.add_coordinate(name)

    def position(self, joint: Joint) -> sympy.Expr:
        """The joint's angle or displacement: its coordinate or the mimic expression."""
        if joint.mimic is None:
            return symbol(self.coordinate[joint.name])
        target, multiplier, offset = joint.mimic
        return _num(multiplier) * symbol(self.coordinate[target]) + _num(offset)

    def add_base(self, wanted: str, parent: str, axis: int, angle) -> str:
        name = self.unique(wanted)
        self.model.add_base(name, parent=parent, axis=axis, angle=angle)
        return name

    def add_point(self, wanted: str, parent: str, base: str, coordinates) -> str:
        name = self.unique(wanted)
        self.model.add_point(name, parent=parent, base=base, coordinates=coordinates)
        return name

    # -- kinematics -----------------------------------------------------------
    def free_joint(self, wanted: str, parent_base: str, parent_point: str, link: str,
                   line: int) -> None:
        """A free joint from (parent_point, parent_base) to ``link``'s own base and point."""
        name = sanitize(wanted)
        # as a joint's coordinate: an invalid name is refused at the joint's line
        check_name(name, file=self.robot.file, line=line, key=f"joint[{wanted}]",
                   what="free joint name (the sanitized joint name)")
        taken = [name] + [f"{name}_{s}" for kind in ("free",)
                          for part in JOINT_KINDS[kind] for s in part]
        clash = [t for t in taken if t in self.taken]
        if clash:
            raise ModelError(f"floating joint '{wanted}' gives the name '{clash[0]}', which "
                             "is already taken", file=self.robot.file, line=line,
                             key=f"joint[{wanted}]", fix="rename the joint or the link")
        self.taken.update(taken)
        base, point = self.unique(f"B_{sanitize(link)}"), self.unique(f"P_{sanitize(link)}")
        self.model.add_joint(name, "free", parent=parent_base, base=base, origin=parent_point,
                             point=point)
        self.base[link], self.point[link] = base, point
        self.free_links.add(link)
        self.group[link] = link
        self.placement[link] = (np.eye(3), np.zeros(3))

    def joint(self, joint: Joint) -> None:
        parent_base, parent_point = self.base[joint.parent], self.point[joint.parent]
        jname = sanitize(joint.name)
        point = parent_point
        if any(joint.xyz):      # a welded link's origin is named after the link
            wanted = f"J_{jname}" if joint.type in _MOVING + ("floating",) \
                else f"P_{sanitize(joint.child)}"
            point = self.add_point(wanted, parent_point, parent_base,
                                   [_num(x) for x in joint.xyz])
        base = parent_base
        for axis, angle, tag in ((3, joint.rpy[2], "rz"), (2, joint.rpy[1], "ry"),
                                 (1, joint.rpy[0], "rx")):
            if angle != 0:
                base = self.add_base(f"B_{jname}_{tag}", base, axis, _num(angle))
        child = joint.child
        if joint.type == "floating" and not (self.fix_floating_root
                                              and joint.parent == self.robot.root):
            self.free_joint(joint.name, base, point, child, joint.line)
            return
        moving = joint.type in _MOVING
        if not moving:
            self.weld(joint)
            self.base[child], self.point[child] = base, point
            return
        self.group[child] = child
        self.placement[child] = (np.eye(3), np.zeros(3))
        q = self.position(joint)
        a = joint.axis
        action_base = base
        if joint.type == "prismatic":
            self.base[child] = base
            self.point[child] = self.add_point(f"P_{sanitize(child)}", point, base,
                                               [_num(x) * q for x in a])
        else:
            self.point[child] = point
            aligned = [k for k in range(3) if abs(a[k]) == 1.0]
            if aligned:
                k = aligned[0]
                angle = q if a[k] > 0 else -q
                self.base[child] = self.add_base(f"B_{sanitize(child)}", base, k + 1, angle)
            else:
                phi = math.atan2(a[1], a[0])
                theta = math.acos(max(-1.0, min(1.0, a[2])))
                if phi != 0:
                    base = self.add_base(f"B_{jname}_az", base, 3, _num(phi))
                base = self.add_base(f"B_{jname}_ay", base, 2, _num(theta))
                action_base = base
                base = self.add_base(f"B_{jname}_q", base, 3, q)
                if phi != 0:
                    base = self.add_base(f"B_{jname}_ay_back", base, 2, _num(-theta))
                    base = self.add_base(f"B_{sanitize(child)}", base, 3, _num(-phi))
                else:
                    base = self.add_base(f"B_{sanitize(child)}", base, 2, _num(-theta))
                self.base[child] = base
                a = (0.0, 0.0, 1.0)
        self.actuation[joint.name] = (action_base, point, a)

    def weld(self, joint: Joint) -> None:
        """The child of a fixed joint joins its parent's group (placement in the group)."""
        r, p = self.placement[joint.parent]
        self.group[joint.child] = self.group[joint.parent]
        self.placement[joint.child] = (r @ rpy_matrix(joint.rpy), p + r @ np.array(joint.xyz))

    # -- bodies, inputs, effects -----------------------------------------------
    def bodies(self) -> dict:
        """One body per moving group (merged mass, centre of mass and inertia)."""
        members: dict = {}
        for link in self.robot.links.values():
            members.setdefault(self.group[link.name], []).append(link)
        body_of = {}
        for head, links in members.items():
            if head == self.robot.root and not self.floating_base:
                continue
            with np.errstate(over="ignore", invalid="ignore"):   # inf is refused below
                merged = _merge(links, self.placement)
            mass, com, inertia = self.physical(head, links, *merged)
            name = self.unique(sanitize(head))
            body_of[head] = name
            base, point = self.base[head], self.point[head]
            if mass > 0 and np.any(com != 0):
                point = self.add_point(f"G_{sanitize(head)}", point, base,
                                       [_num(x) for x in com])
            inertia = [[_num(inertia[i][j]) for j in range(3)] for i in range(3)]
            mass = _num(mass)
            if self.inertial_parameters:
                mass = self.parameter(f"m_{name}", mass)
                for i, j, tag in ((0, 0, "xx"), (1, 1, "yy"), (2, 2, "zz"), (0, 1, "xy"),
                                  (0, 2, "xz"), (1, 2, "yz")):
                    inertia[i][j] = inertia[j][i] = self.parameter(f"I_{name}_{tag}",
                                                                   inertia[i][j])
            try:
                self.model.add_body(name, mass=mass, G=point, base=base, inertia=inertia)
            except ModelError as exc:
                # the model's own rigid-body check (relative to the largest entry) may
                # refuse what passed as noise against a huge m |c|^2 here: name the file
                line, key, _ = self.located(head, links)
                raise ModelError(exc.problem, file=self.robot.file, line=line,
                                 key=f"{key}.inertia",
                                 fix=f"{exc.fix}; or load the file's values as Pinocchio "
                                     "does with inertia=\"as_is\" (command line: "
                                     "--inertia as-is)") from None
        return body_of

    def located(self, head: str, links: list) -> tuple:
        """(line, key, description) of the body of group ``head`` for messages: the
        first of its links with an inertial."""
        link = self.robot.links[head]
        where = next((x for x in links if x.inertial is not None), link)
        line = where.inertial.inertia_line if where.inertial is not None else where.line
        merged = [x.name for x in links if x.inertial is not None]
        what = f"link '{head}'" + (f" (merged with the links welded to it: "
                                   f"{', '.join(n for n in merged if n != head)})"
                                   if len(merged) > 1 or merged[:1] not in ([], [head]) else "")
        return line, f"link[{where.name}].inertial", what

    def physical(self, head: str, links: list, mass: float, com: np.ndarray,
                 inertia: np.ndarray) -> tuple:
        """The merged body of group ``head``, checked as a rigid body, with the bounds
        and the ``inertia`` option applied (each change recorded in ``self.changes``)."""
        line, key, what = self.located(head, links)
        if not (math.isfinite(mass) and np.all(np.isfinite(com))
                and np.all(np.isfinite(inertia))):
            raise ModelError(f"the mass, centre of mass or inertia of {what} is too large "
                             "for a double (inf or NaN after merging the welded links)",
                             file=self.robot.file, line=line, key=key,
                             fix="give masses in kg, lengths in m and inertias in kg m^2 of a "
                                 "real robot (mass x length^2 must stay below 1e308)")
        options = self.options
        moments, axes, scale = _principal(inertia)
        if options.min_mass > mass:
            self.changes.append(f"mass of {what} raised from {mass:.6g} to the minimum "
                                f"{options.min_mass:.6g} (min_mass)")
            mass = options.min_mass
        if options.min_inertia > 0 and np.any(moments * scale < options.min_inertia):
            raised = np.maximum(moments * scale, options.min_inertia)
            self.changes.append(f"principal moments of {what} raised from "
                                f"{_shown(moments * scale)} to {_shown(raised)} (min_inertia)")
            inertia = _rotated(axes, np.diag(raised))
            moments, axes, scale = _principal(inertia)
        # rounding noise relative to the body's own scale: its trace and its mass times
        # the squared distance of its centre of mass from the joint
        size = float(np.sum(np.maximum(moments, 0)))
        if mass > 0 and np.any(com != 0):
            # mass |com|^2 / scale in logarithms: neither the square nor the quotient
            # may overflow or underflow on the way
            log = math.log(mass) + 2 * math.log(math.hypot(*com)) - math.log(scale) \
                if scale > 0 else math.inf
            size += math.exp(log) if log < 700 else math.inf
        tol = 64 * np.finfo(float).eps * size
        negative = max(0.0, -moments[0])
        triangle = max(0.0, moments[2] - moments[0] - moments[1])
        if negative <= tol and triangle <= tol:
            return mass, com, inertia
        shown = _shown(moments * scale)
        off = (f"{negative * scale:.3g} kg m^2 below zero" if negative > tol else
               f"{triangle * scale:.3g} kg m^2 past the triangle inequality")
        relative = max(negative, triangle) / max(float(np.sum(np.abs(moments))), 1e-300)
        if options.inertia == "as_is":
            self.changes.append(f"inertia of {what} is not that of a rigid body, kept as "
                                f"the file gives it: principal moments {shown}, {off} "
                                f"({relative:.2g} of its trace)")
            return mass, com, inertia
        if options.inertia == "balance" and negative <= tol:
            # MuJoCo's balanceinertia: all three principal moments set to their mean
            mean = float(np.sum(moments)) / 3 * scale
            self.changes.append(f"inertia of {what} balanced: principal moments {shown} "
                                f"({off}) set to their mean {mean:.6g} (balance)")
            return mass, com, np.eye(3) * mean
        problem = ("has a negative principal moment" if negative > tol else
                   "violates the triangle inequality (each principal moment must be at "
                   "most the sum of the other two)")
        fix = ("give the inertia tensor about the centre of mass of a real body; or load "
               "the file's values as Pinocchio does with inertia=\"as_is\" (command line: "
               "--inertia as-is)")
        if negative <= tol:
            fix += (", or apply MuJoCo's balanceinertia rule (the three principal moments "
                    "set to their mean) with inertia=\"balance\" (--inertia balance)")
        raise ModelError(f"inertia of {what} {problem}: principal moments {shown}, {off}",
                         file=self.robot.file, line=line, key=f"{key}.inertia", fix=fix)

    def link_frames(self) -> None:
        """A frame per link (its origin point and base), named after the link, or
        ``<link>_frame`` when the name is taken (a moving link's body has it)."""
        for link in self.robot.links:
            name = sanitize(link)
            try:
                check_name(name)
                free = name not in self.taken and not name.endswith("_dot")
            except ModelError:
                free = False
            if free:
                self.taken.add(name)
            else:
                name = self.unique(f"{name}_frame")
            self.model.add_frame(name, point=self.point[link], base=self.base[link])

    def parameter(self, wanted: str, value) -> sympy.Symbol:
        name = self.unique(wanted)
        self.model.add_parameter(name, float(value))
        return symbol(name)

    def inputs_and_effects(self, body_of: dict) -> None:
        for joint in self.robot.order:
            coordinate = self.coordinate.get(joint.name)
            if joint.type == "floating" and joint.child in self.free_links:
                self.infos.append(JointInfo(joint.name, joint.type, None, None, joint.limit,
                                            joint.damping, joint.friction))
                continue
            if coordinate is None:
                mimic = None
                if joint.mimic is not None and joint.type in _MOVING:
                    target, multiplier, offset = joint.mimic
                    mimic = (self.coordinate[target], multiplier, offset)
                self.infos.append(JointInfo(joint.name, joint.type, None, None, joint.limit,
                                            joint.damping, joint.friction, mimic))
                continue
            jname = sanitize(joint.name)
            tau = self.unique(f"tau_{jname}")
            self.model.add_input(tau)
            base, point, a = self.actuation[joint.name]
            vector = [_num(x) * symbol(tau) for x in a]
            what = "force" if joint.type == "prismatic" else "torque"
            child = body_of[self.group[joint.child]]
            at = self.point[joint.child] if what == "force" else point
            self.model.add_action(self.unique(f"motor_{jname}"), body=child, point=at,
                                  base=base, **{what: vector})
            parent_group = self.group[joint.parent]
            if parent_group != self.robot.root or self.floating_base:
                self.model.add_action(self.unique(f"motor_{jname}_reaction"),
                                      body=body_of[parent_group], point=point, base=base,
                                      **{what: [-v for v in vector]})
            if joint.damping > 0:
                self.model.add_effect(self.unique(f"damping_{jname}"), "joint_damping",
                                      coordinates=[coordinate], damping=_num(joint.damping))
            if joint.friction > 0:
                self.model.add_effect(self.unique(f"friction_{jname}"), "friction",
                                      coordinate=coordinate, coulomb=_num(joint.friction))
            self.infos.append(JointInfo(joint.name, joint.type, coordinate, tau, joint.limit,
                                        joint.damping, joint.friction))

    def check_motion(self) -> None:
        """Refuse a robot that cannot move (fixed base, no joint) and a joint that moves
        only massless links (A singular for every q); both fixes name the options."""
        free = any(j.type == "floating" and not (self.fix_floating_root
                                                  and j.parent == self.robot.root)
                   for j in self.robot.order)
        if not self.coordinate and not free and not self.floating_base:
            root = self.robot.links[self.robot.root]
            raise ModelError(f"robot '{self.robot.name}' has no moving joint: with a fixed "
                             "base it has no coordinates", file=self.robot.file,
                             line=root.line, key=f"link[{root.name}]",
                             fix="a single body that flies (a quadrotor) needs a free root: "
                                 "load it with floating_base=True (command line: "
                                 "--floating-base)")
        massive = {name: link.inertial is not None and (link.inertial.mass > 0
                                                        or bool(link.inertial.inertia.any()))
                   for name, link in self.robot.links.items()}
        for joint in reversed(self.robot.order):      # children before their parents
            massive[joint.parent] = massive[joint.parent] or massive[joint.child]
        for joint in self.robot.order:
            bounded = self.options.min_mass if joint.type == "prismatic" \
                else self.options.min_inertia
            if joint.type in _MOVING and not massive[joint.child] and not bounded > 0:
                raise ModelError(
                    f"joint '{joint.name}' moves only massless links (link '{joint.child}' "
                    "and the links it carries have no mass and no inertia), so the mass "
                    "matrix is singular for every configuration", file=self.robot.file,
                    line=joint.line, key=f"joint[{joint.name}]",
                    fix="give the links a mass and an inertia, or bound them from below as "
                        "MuJoCo's boundmass and boundinertia do: min_mass=..., "
                        "min_inertia=... (command line: --min-mass, --min-inertia), e.g. "
                        "1e-6 kg and 1e-9 kg m^2")

    def build(self) -> UrdfImport:
        self.taken.update(("g",))
        self.coordinates()
        self.check_motion()
        self.model.add_parameter("g", 9.81)
        if self.floating_base:
            self.free_joint("root_joint", CANONICAL_BASE, CANONICAL_POINT, self.robot.root,
                            1)
        for joint in self.robot.order:
            self.joint(joint)
        body_of = self.bodies()
        self.inputs_and_effects(body_of)
        armature = {self.coordinate[r.joint]: _num(r.armature)
                    for r in self.robot.rotors if r.armature > 0}
        if armature:
            self.model.set_armature(armature)
        self.link_frames()
        self.model.set_gravity([0, 0, -symbol("g")])
        if self.changes:
            # never silent: the changed or non-physical bodies, per link
            warnings.warn(comment_text(f"{Path(self.robot.file).name}: read with "
                                       f"{self.options.text()}: " + "; ".join(self.changes)),
                          stacklevel=4)
        # the notes name links and joints: one line each in the file's comments and
        # in the terminal, whatever characters the names hold
        return UrdfImport(self.model, tuple(self.infos), self.robot.file,
                          tuple(map(comment_text, self.notes + tuple(self.changes))),
                          self.options)


def _shown(moments) -> str:
    return "[" + ", ".join(f"{m:.6g}" for m in moments) + "]"


def _principal(inertia: np.ndarray) -> tuple:
    """(moments / scale, axes, scale): the principal moments in ascending order of the
    inertia divided by a power of two near its largest entry (no overflow), and the
    principal axes (columns)."""
    largest = float(np.max(np.abs(inertia)))
    if not largest > 0:
        return np.zeros(3), np.eye(3), 0.0
    scale = math.ldexp(1.0, math.frexp(largest)[1] - 1)
    moments, axes = np.linalg.eigh(inertia / scale)
    return moments, axes, scale


def _rotated(r: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """R I R^T, symmetric, scaled by a power of two near the largest entry first so
    that no sum overflows (and the rounding is that of the unscaled product)."""
    largest = float(np.max(np.abs(inertia)))
    if not largest > 0:
        return np.zeros((3, 3))
    scale = math.ldexp(1.0, math.frexp(largest)[1] - 1)
    out = r @ (inertia / scale) @ r.T
    return (out / 2 + out.T / 2) * scale


def _parallel_axis(m: float, d: np.ndarray) -> np.ndarray:
    """m (|d|^2 1 - d d^T), with d scaled by its largest component (no overflow of the
    squares unless the result itself is too large for a double)."""
    length = float(np.max(np.abs(d)))
    if not (length > 0 and m > 0):
        return np.zeros((3, 3))
    scale = math.ldexp(1.0, math.frexp(length)[1] - 1)
    e = d / scale
    return m * (e @ e * np.eye(3) - np.outer(e, e)) * scale * scale


def _merge(links, placement) -> tuple:
    """Total mass, centre of mass and inertia about it, in the group's frame (exact).

    Overflow-safe: masses are weighted by the largest one, vectors and tensors
    scaled by their largest component; a sum that is too large for a double comes
    out as inf, which the caller refuses.
    """
    parts = []
    for link in links:
        if link.inertial is None or link.inertial.mass == 0 and not link.inertial.inertia.any():
            continue
        r, p = placement[link.name]
        ri = r @ rpy_matrix(link.inertial.rpy)
        parts.append((link.inertial.mass, p + r @ np.array(link.inertial.xyz),
                      _rotated(ri, link.inertial.inertia)))
    if not parts:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    if len(parts) == 1:
        return parts[0]
    heaviest = max(m for m, _, _ in parts)
    if heaviest > 0:
        scale = math.ldexp(1.0, math.frexp(heaviest)[1] - 1)
        weights = [m / scale for m, _, _ in parts]
        total = sum(weights)
        com = sum(w * c for w, (_, c, _) in zip(weights, parts)) / total
        mass = total * scale
    else:
        mass, com = 0.0, parts[0][1]
    inertia = np.zeros((3, 3))
    for m, c, i in parts:
        inertia = inertia + i + _parallel_axis(m, c - com)
    return mass, com, inertia / 2 + inertia.T / 2


def import_urdf_text(text, source: str = "<string>", *, fix_floating_root: bool = False,
                     inertial_parameters: bool = False, floating_base: bool = False,
                     inertia: str = "physical", min_mass: float = 0.0,
                     min_inertia: float = 0.0, mimic: str = "strict") -> UrdfImport:
    """Import URDF text (str or bytes); see the module docstring.

    ``inertia``, ``min_mass`` and ``min_inertia`` say how bodies that no rigid body
    matches are read (the default refuses them; see "Inertias" in the module
    docstring); every change they make is a warning and a note of the import.
    ``mimic="ignore"`` reads every ``<mimic>`` joint as a joint of its own (as
    Pinocchio's ``mimic=False``), also a warning and a note.
    """
    options = reading_options(inertia, min_mass, min_inertia, mimic)
    robot = parse_robot(text, source, ignore_mimic=options.mimic == "ignore")
    notes = tuple(f"The floating joint '{j.name}' at the root was imported as fixed."
                  for j in robot.order if j.type == "floating" and fix_floating_root
                  and j.parent == robot.root)
    return _Builder(robot, inertial_parameters, notes, floating_base,
                    fix_floating_root, options).build()


def import_urdf(path, **options) -> UrdfImport:
    """Import a URDF file; ``options`` as :func:`import_urdf_text`.

    >>> imp = import_urdf("tests/data/urdf/ur5_robot.urdf")      # doctest: +SKIP
    >>> imp.model.spec().coordinates[0]                          # doctest: +SKIP
    'shoulder_pan_joint'
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"cannot read the URDF file: {exc.strerror}", file=str(path),
                         fix="check the path") from None
    return import_urdf_text(data, str(path), **options)


def load_urdf(path, **options) -> Model:
    """The :class:`Model` of a URDF file (see :func:`import_urdf`)."""
    return import_urdf(path, **options).model


def _fmt(x: Optional[float]) -> str:
    return "-" if x is None else repr(x)


def urdf_to_yaml(imported: UrdfImport) -> str:
    """The model file of an import: a comment header (source, notes, joint limits), then YAML."""
    lines = [f"# Imported by 'modelgen import' from {Path(imported.source).name}.",
             "# Edit freely; re-importing overwrites this file."]
    if imported.options.text():
        lines.append(f"# Read with {imported.options.text()}: the values below are the "
                     "adjusted ones (see the notes).")
    lines += [f"# Note: {note}" for note in imported.notes]
    limited = [j for j in imported.joints if j.limit is not None and j.coordinate]
    if limited:
        lines.append("# Joint limits (URDF <limit>; not enforced by the model):")
        lines.append("#   coordinate: lower upper velocity effort")
        lines += [f"#   {j.coordinate}: {_fmt(j.limit.lower)} {_fmt(j.limit.upper)} "
                  f"{_fmt(j.limit.velocity)} {_fmt(j.limit.effort)}" for j in limited]
    return "\n".join(map(comment_text, lines)) + "\n" + imported.model.to_yaml()
