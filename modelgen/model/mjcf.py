"""MJCF import: a MuJoCo model -> a :class:`~modelgen.model.Model`.

:func:`import_mjcf` compiles an MJCF file with the official ``mujoco`` package
(``mujoco.MjModel.from_xml_path``: includes, defaults, ``<compiler>`` options,
inertias from geoms are MuJoCo's own) and reads the *compiled* model, so what
modelgen sees is exactly what MuJoCo simulates.  ``modelgen.load("robot.xml")``
and ``modelgen import robot.xml -o robot.yaml`` use it; the model is built
through the public :class:`Model` API, so every check of the model loader
applies.  What becomes what (``docs/mjcf.md`` has the table and the checks):

* The world body is the ground (base ``E``, point ``O``); ``opt.gravity`` is
  the gravity vector (``[0, 0, -g]`` with parameter ``g`` when it points down
  the z axis).
* A body's frame is its parent's moved by ``body_pos`` (point ``P_<body>``)
  and turned by ``body_quat`` (constant rotations ``B_<body>_rz``, ``_ry``,
  ``_rx``: R = Rz Ry Rx, zero angles left out), then by each of its joints in
  order, as ``mj_kinematics`` does.  A ``hinge`` turns about its axis through
  the anchor ``jnt_pos`` by ``q - ref`` (MuJoCo's ``qpos - qpos0``: the
  coordinate is MuJoCo's ``qpos``); an axis along +-x, +-y or +-z is one simple
  rotation, any other the URDF importer's five (``_az``, ``_ay``, the joint,
  both undone).  A ``slide`` moves the origin by ``(q - ref) axis``.  A
  ``ball`` is a ball joint about its anchor, a ``free`` joint a free joint from
  ``E``/``O`` (MuJoCo ignores a free body's ``pos``, ``quat`` and joint
  ``pos``: ``qpos`` is the body's pose).
* Coordinates are the joint names with every character outside
  ``[A-Za-z0-9_]`` replaced by ``_`` (``joint<id>`` for an unnamed joint), in
  MuJoCo's order, the ball and free joints' after them (modelgen's order).
* A body on a moving chain with mass or inertia is a body of the model
  (``body_mass``; centre of mass ``G_<body>`` at ``body_ipos``; the principal
  inertia ``body_inertia`` turned by ``body_iquat`` into the body's frame).
  Bodies welded to the world do not move and are left out.
* ``dof_armature`` is the model's ``armature:``; ``dof_damping`` of a hinge
  or slide an effect ``damping_<joint>`` (``joint_damping``),
  (a ball or free joint's on its speeds), ``jnt_stiffness`` a ``torsion_spring`` ``spring_<joint>`` about
  ``qpos_spring`` (MuJoCo's ``springref``), ``dof_frictionloss`` a smoothed
  Coulomb ``friction_<joint>`` (MuJoCo's is a constraint; see
  ``frictionloss=``).  MuJoCo's ``disableflag`` for gravity, springs and
  dampers is honoured.
* Active equality constraints become exact position constraints, one
  equation per row of MuJoCo's ``efc_pos`` and the same function of the
  configuration (``mj_instantiateEquality``): a joint or fixed-tendon
  coupling an expression with MuJoCo's ``polycoef`` about ``qpos0`` /
  ``tendon_length0``; ``connect`` a ``coincide`` of the two anchors; ``weld``
  that and the orientation error ``torquescale * vec(conj(q1) q0 relpose)``
  as three expressions in the half-angle cosines and sines of the hinges
  between the bodies (a mocap body stays at its model pose).  Inactive ones
  are skipped with a note, ``solref``/``solimp`` ignored; spatial tendons and
  models with ball or free joints are refused.
* Contacts, geoms, tendons, actuators, sensors, joint limits, fluid forces
  and everything else that is not rigid-body dynamics are ignored and listed
  in :attr:`MjcfImport.notes`.

Conventions against MuJoCo's: ``qpos`` maps one to one (quaternions are
``(w, x, y, z)`` in both), only the order differs (modelgen lists the hinge
and slide coordinates first); a free joint's linear velocity is in the
*world* frame in MuJoCo's ``qvel`` and in the *body* frame in modelgen's
speeds (Pinocchio's free-flyer).  :func:`qpos_from_mujoco`,
:func:`qvel_from_mujoco`, :func:`qpos_to_mujoco`, :func:`qvel_to_mujoco`,
:func:`qacc_to_mujoco` and :func:`velocity_map` convert.

>>> imp = import_mjcf_text('''<mujoco><worldbody><body name="rod">
...   <joint name="hinge" type="hinge" axis="0 1 0" armature="0.1"/>
...   <geom type="capsule" fromto="0 0 0 0 0 -1" size="0.05" mass="1"/>
... </body></worldbody></mujoco>''')                                # doctest: +SKIP
>>> imp.model.spec().coordinates, imp.model.spec().armature         # doctest: +SKIP
(('hinge',), (('hinge', 1/10),))
"""
from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple, Optional

import numpy as np
import sympy

from modelgen.errors import ModelError
from modelgen.model.api import API_FILE, Model, check_name
from modelgen.model.expr import MAX_LENGTH
from modelgen.model.halfangle import POLY_NOISE, quat_conj, quat_const, quat_mul
from modelgen.model.mjcf_state import (qacc_to_mujoco, qpos_from_mujoco, qpos_to_mujoco,
                                      quat_matrix, qvel_from_mujoco, qvel_to_mujoco,
                                      velocity_map)
from modelgen.model.messages import comment_text
from modelgen.model.names import fresh_name, model_name_for, sanitize
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT, JOINT_KINDS, symbol

__all__ = ["MjcfImport", "MjcfJoint", "import_mjcf", "import_mjcf_text", "import_mjmodel",
           "load_mjcf", "mjcf_to_yaml", "qpos_from_mujoco", "qpos_to_mujoco",
           "qvel_from_mujoco", "qvel_to_mujoco", "qacc_to_mujoco", "velocity_map",
           "FRICTIONLOSS"]

#: MuJoCo's joint types (``mjtJoint``), by their numbers in ``jnt_type``.
_FREE, _BALL, _SLIDE, _HINGE = 0, 1, 2, 3
_TYPE_NAMES = {_FREE: "free", _BALL: "ball", _SLIDE: "slide", _HINGE: "hinge"}

#: What ``frictionloss=`` may ask for: a smoothed Coulomb ``friction`` effect, or nothing.
FRICTIONLOSS = ("smooth", "ignore")


class MjcfJoint(NamedTuple):
    """One MuJoCo joint and where its values go in modelgen's state."""
    name: str            # the MuJoCo name ("" if unnamed)
    id: int              # the MuJoCo joint id
    type: str            # hinge | slide | ball | free
    coordinates: tuple   # modelgen coordinate names, MuJoCo's qpos order
    speeds: tuple        # modelgen speed (dof) names, MuJoCo's qvel order
    qposadr: int
    dofadr: int


class MjcfImport(NamedTuple):
    """The result of an import: the model, the joints (MuJoCo order) and notes."""
    model: Model
    joints: tuple        # MjcfJoint, MuJoCo's joint order
    source: str
    notes: tuple         # sentences: what was ignored
    #: modelgen coordinate k -> MuJoCo qpos index; modelgen dof k -> MuJoCo dof index
    qpos_index: tuple
    dof_index: tuple
    #: per free joint: (modelgen index of its qw, modelgen dof index of its vx)
    free: tuple
    #: per position-constraint equation of the model, in order: (MuJoCo equality id,
    #: row of that equality's ``efc_pos`` block), so ``cm.constraint_residuals(q)[i]``
    #: is the violation MuJoCo computes in that row
    equality_rows: tuple = ()


def _mujoco():
    try:
        import mujoco  # optional: only MJCF import needs it
    except ImportError:
        raise ModelError("MJCF import needs the 'mujoco' package, which is not installed",
                         fix="pip install mujoco (or modelgen's 'mjcf' extra)") from None
    return mujoco


def _num(x: float):
    """A float as an exact sympy number of its shortest decimal (ints stay ints)."""
    x = float(x)
    if x == int(x) and abs(x) < 2 ** 53:
        return sympy.Integer(int(x))
    return sympy.Rational(repr(x))


def _euler_zyx(R) -> tuple:
    """(yaw, pitch, roll) with R = Rz(yaw) Ry(pitch) Rx(roll); pitch by atan2, so a
    quarter turn about y is exact to rounding."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.hypot(R[0, 0], R[1, 0]) < 1e-12:       # gimbal lock: roll folded into yaw
        return math.atan2(-R[0, 1], R[1, 1]), pitch, 0.0
    return math.atan2(R[1, 0], R[0, 0]), pitch, math.atan2(R[2, 1], R[2, 2])


#: The compiled numbers the import reads: (element, count, mjtObj, fields), a dof's or
#: qpos's row named after its joint.  MuJoCo compiles NaN and infinities with a warning
#: at most; the model would get nonsense, or drop them (a NaN damping is not > 0).
_READ_FIELDS = (
    ("body", "nbody", "mjOBJ_BODY", ("body_pos", "body_quat", "body_mass", "body_ipos",
                                     "body_iquat", "body_inertia")),
    ("joint", "njnt", "mjOBJ_JOINT", ("jnt_pos", "jnt_axis", "jnt_stiffness")),
    ("dof", "nv", "mjOBJ_JOINT", ("dof_damping", "dof_armature", "dof_frictionloss")),
    ("qpos", "nq", "mjOBJ_JOINT", ("qpos0", "qpos_spring")),
    ("site", "nsite", "mjOBJ_SITE", ("site_pos", "site_quat")),
    ("equality", "neq", "mjOBJ_EQUALITY", ("eq_data",)), ("wrap", "nwrap", None, ("wrap_prm",)),
    ("tendon", "ntendon", "mjOBJ_TENDON", ("tendon_length0",)))

#: hinges between two welded bodies (from their common ancestor) beyond which the
#: orientation residual (up to 2^k terms per equation) is refused as too large
WELD_MAX_HINGES = 12


class _Builder:
    def __init__(self, m, name: str, source: str, frictionloss: str):
        self.m = m
        self.source = source
        self.frictionloss = frictionloss
        self.model = Model(name)
        self.taken: set = {"g"}
        self.notes: list = []
        self.joints: list = []
        self.coordinates: list = []       # simple coordinates, MuJoCo order
        self.quaternion_joints: list = [] # (MjcfJoint) ball and free, MuJoCo order
        self.equality_rows: list = []     # (equality id, row) per constraint equation

    def error(self, problem: str, key: str, fix: str) -> ModelError:
        return ModelError(problem, file=self.source, key=key, fix=fix)

    def name_of(self, kind, index: int) -> str:
        try:
            return _mujoco().mj_id2name(self.m, kind, index) or ""
        except UnicodeDecodeError:      # MuJoCo keeps the file's bytes
            what = kind.name[len("mjOBJ_"):].lower()
            raise self.error(f"the name of {what} {index} is not UTF-8 text",
                             f"{what}[{index}]", "write the names in UTF-8") from None

    def unique(self, wanted: str) -> str:
        """A fresh valid name close to ``wanted`` (suffix _2, _3... on a clash)."""
        return fresh_name(wanted, self.taken)

    # -- frames ----------------------------------------------------------------
    def rotate(self, base: str, R, tag: str) -> str:
        """Constant rotations Rz Ry Rx from ``base`` (none for the identity)."""
        yaw, pitch, roll = _euler_zyx(R)
        for axis, angle, suffix in ((3, yaw, "rz"), (2, pitch, "ry"), (1, roll, "rx")):
            if angle != 0.0:
                name = self.unique(f"{tag}_{suffix}")
                self.model.add_base(name, parent=base, axis=axis, angle=_num(angle))
                base = name
        return base

    def offset(self, point: str, base: str, xyz, wanted: str) -> str:
        if not np.any(xyz):
            return point
        name = self.unique(wanted)
        self.model.add_point(name, parent=point, base=base, coordinates=[_num(x) for x in xyz])
        return name

    def turn(self, base: str, axis, angle, tag: str) -> str:
        """A base turned from ``base`` by ``angle`` about the unit ``axis``."""
        aligned = [k for k in range(3) if abs(axis[k]) == 1.0]
        if aligned:
            k = aligned[0]
            name = self.unique(tag)
            self.model.add_base(name, parent=base, axis=k + 1,
                                angle=angle if axis[k] > 0 else -angle)
            return name
        phi = math.atan2(axis[1], axis[0])
        theta = math.acos(max(-1.0, min(1.0, axis[2])))
        steps = ([(3, _num(phi), "az")] if phi != 0 else []) + [(2, _num(theta), "ay"),
                                                                 (3, angle, "q"),
                                                                 (2, _num(-theta), "ay_back")]
        steps += [(3, _num(-phi), "az_back")] if phi != 0 else []
        for i, (k, value, suffix) in enumerate(steps):
            name = self.unique(tag if i == len(steps) - 1 else f"{tag}_{suffix}")
            self.model.add_base(name, parent=base, axis=k, angle=value)
            base = name
        return base

    # -- joints ----------------------------------------------------------------
    def joint_name(self, j: int) -> str:
        return sanitize(self.name_of(_mujoco().mjtObj.mjOBJ_JOINT, j)) or f"joint{j}"

    def simple_coordinate(self, j: int) -> str:
        name = self.joint_name(j)
        key = f"joint[{j}]"
        check_name(name, file=self.source, key=key, what="coordinate (the sanitized joint name)")
        if name in self.taken or f"{name}_dot" in self.taken or \
                (name.endswith("_dot") and name[:-4] in self.taken):
            raise self.error(f"joint {j} gives coordinate '{name}', which clashes with "
                             "another name of the model", key, "rename one of the joints")
        self.taken.add(name)
        self.model.add_coordinate(name)
        return name

    def quaternion_joint(self, j: int, kind: str, parent_base: str, point: str,
                         body: str) -> tuple:
        """A ball or free joint named after the MuJoCo joint; returns (base, point)."""
        name = self.joint_name(j)
        check_name(name, file=self.source, key=f"joint[{j}]",
                   what=f"{kind} joint name (the sanitized joint name)")
        made = [name] + [f"{name}_{s}" for part in JOINT_KINDS[kind] for s in part]
        clash = [t for t in made if t in self.taken]
        if clash:
            raise self.error(f"{kind} joint {j} gives the name '{clash[0]}', which is "
                             "already taken", f"joint[{j}]", "rename the joint or the body")
        self.taken.update(made)
        base = self.unique(f"B_{body}")
        if kind == "free":
            new_point = self.unique(f"P_{body}")
            self.model.add_joint(name, "free", parent=CANONICAL_BASE, base=base,
                                 origin=CANONICAL_POINT, point=new_point)
            point = new_point
        else:
            self.model.add_joint(name, "ball", parent=parent_base, base=base)
        q, v = JOINT_KINDS[kind]
        self.quaternion_joints.append(MjcfJoint(self.name_of(_mujoco().mjtObj.mjOBJ_JOINT, j),
                                                j, kind, tuple(f"{name}_{s}" for s in q),
                                                tuple(f"{name}_{s}" for s in v),
                                                int(self.m.jnt_qposadr[j]),
                                                int(self.m.jnt_dofadr[j])))
        return base, point

    def body_frames(self) -> tuple:
        """(base, point, moving) of every MuJoCo body, joints applied."""
        m = self.m
        frames = [(CANONICAL_BASE, CANONICAL_POINT, False)]
        for b in range(1, m.nbody):
            parent_base, parent_point, moving = frames[m.body_parentid[b]]
            body = sanitize(self.name_of(_mujoco().mjtObj.mjOBJ_BODY, b)) or f"body{b}"
            joints = range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b])
            if any(m.jnt_type[j] == _FREE for j in joints):
                base, point = self.quaternion_joint(joints[0], "free", CANONICAL_BASE,
                                                    CANONICAL_POINT, body)
                frames.append((base, point, True))
                continue
            point = self.offset(parent_point, parent_base, m.body_pos[b], f"P_{body}")
            base = self.rotate(parent_base, quat_matrix(m.body_quat[b]), f"B_{body}")
            for j in joints:
                base, point = self.apply_joint(j, base, point, body)
                moving = True
            frames.append((base, point, moving))
        return tuple(frames)

    def apply_joint(self, j: int, base: str, point: str, body: str) -> tuple:
        """The frame after joint ``j`` (``mj_kinematics``: about the anchor ``jnt_pos``)."""
        m = self.m
        kind = int(m.jnt_type[j])
        axis, anchor = [float(a) for a in m.jnt_axis[j]], m.jnt_pos[j]
        if kind == _SLIDE:
            q = self.simple_coordinate(j)
            self.record(j, "slide", (q,), (q,))
            shift = symbol(q) - _num(m.qpos0[m.jnt_qposadr[j]])
            name = self.unique(f"P_{body}_{q}")
            self.model.add_point(name, parent=point, base=base,
                                 coordinates=[_num(a) * shift for a in axis])
            return base, name
        at = self.offset(point, base, anchor, f"A_{body}_{self.joint_name(j)}")
        if kind == _HINGE:
            q = self.simple_coordinate(j)
            self.record(j, "hinge", (q,), (q,))
            base = self.turn(base, axis, symbol(q) - _num(m.qpos0[m.jnt_qposadr[j]]),
                             f"B_{body}_{q}")
        else:
            base, _ = self.quaternion_joint(j, "ball", base, point, body)
        return base, self.offset(at, base, -anchor, f"P_{body}_{self.joint_name(j)}")

    def record(self, j: int, kind: str, coordinates: tuple, speeds: tuple) -> None:
        self.coordinates.append(MjcfJoint(self.name_of(_mujoco().mjtObj.mjOBJ_JOINT, j), j, kind,
                                          coordinates, speeds, int(self.m.jnt_qposadr[j]),
                                          int(self.m.jnt_dofadr[j])))

    # -- bodies and effects ----------------------------------------------------
    def bodies(self, frames) -> None:
        m = self.m
        for b in range(1, m.nbody):
            base, point, moving = frames[b]
            mass, principal = float(m.body_mass[b]), m.body_inertia[b]
            if not moving or (mass == 0 and not np.any(principal)):
                continue
            body = self.unique(sanitize(self.name_of(_mujoco().mjtObj.mjOBJ_BODY, b))
                               or f"body{b}")
            G = self.offset(point, base, m.body_ipos[b], f"G_{body}")
            R = quat_matrix(m.body_iquat[b])
            inertia = R @ np.diag(principal) @ R.T
            inertia = (inertia + inertia.T) / 2
            # rounding of the turn, not data: off-diagonals at 1e-14 of the largest moment
            inertia[np.abs(inertia) <= 1e-14 * max(principal)] = 0.0
            self.model.add_body(body, mass=_num(mass), G=G, base=base,
                                inertia=[[_num(inertia[r][c]) for c in range(3)]
                                         for r in range(3)])

    def frames(self, frames) -> None:
        """A frame per body (its origin and axes after its joints: MuJoCo's ``xpos``,
        ``xmat``) and per site (``site_xpos``, ``site_xmat``), named after it, or
        ``<name>_frame`` when a body or another name has it."""
        m, mujoco = self.m, _mujoco()

        def name(label: str) -> str:
            wanted = sanitize(label)
            return self.unique(wanted if wanted not in self.taken else f"{wanted}_frame")
        for b in range(1, m.nbody):
            base, point, _ = frames[b]
            self.model.add_frame(name(self.name_of(mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"),
                                 point=point, base=base)
        for s in range(m.nsite):
            base, point, _ = frames[m.site_bodyid[s]]
            label = self.name_of(mujoco.mjtObj.mjOBJ_SITE, s) or f"site{s}"
            point = self.offset(point, base, m.site_pos[s], f"S_{sanitize(label)}")
            base = self.rotate(base, quat_matrix(m.site_quat[s]), f"S_{sanitize(label)}")
            self.model.add_frame(name(label), point=point, base=base)

    def effects(self) -> None:
        mujoco, m = _mujoco(), self.m
        flags = m.opt.disableflags
        springs = not flags & mujoco.mjtDisableBit.mjDSBL_SPRING
        dampers = not flags & mujoco.mjtDisableBit.mjDSBL_DAMPER
        armature, skipped = {}, {}
        for joint in self.coordinates + self.quaternion_joints:
            j = joint.id
            for k, speed in enumerate(joint.speeds):
                dof = joint.dofadr + k
                if m.dof_armature[dof] > 0:
                    armature[speed] = _num(m.dof_armature[dof])
            simple = joint.type in ("hinge", "slide")
            q = joint.coordinates[0]
            dof = joint.dofadr
            damping = m.dof_damping[dof:dof + len(joint.speeds)]
            if dampers and np.any(damping > 0):
                # MuJoCo damps the world-frame linear velocity of a free joint: the
                # same generalized force on the body-frame speeds when the three
                # linear dampings are equal (R is orthogonal), as a joint's damping makes
                if np.all(damping == damping[0]):
                    self.model.add_effect(self.unique(f"damping_{self.joint_name(j)}"),
                                          "joint_damping", coordinates=list(joint.speeds),
                                          damping=_num(damping[0]))
                else:
                    skipped.setdefault("unequal damping of", []).append(joint.name)
            if springs and m.jnt_stiffness[j] > 0:
                if simple:
                    self.model.add_effect(self.unique(f"spring_{q}"), "torsion_spring",
                                          coordinate=q, stiffness=_num(m.jnt_stiffness[j]),
                                          rest_angle=_num(m.qpos_spring[joint.qposadr]))
                else:
                    skipped.setdefault(f"stiffness of {joint.type} joint", []).append(joint.name)
            if np.any(m.dof_frictionloss[dof:dof + len(joint.speeds)] > 0):
                if simple and self.frictionloss == "smooth":
                    self.model.add_effect(self.unique(f"friction_{q}"), "friction",
                                          coordinate=q,
                                          coulomb=_num(m.dof_frictionloss[dof]))
                else:
                    what = "frictionloss (left out as asked) of" if simple else \
                        f"frictionloss of {joint.type} joint"
                    skipped.setdefault(what, []).append(joint.name)
        if armature:
            self.model.set_armature(armature)
        if skipped:
            self.notes.append("Ignored: " + "; ".join(
                f"{what} {', '.join(names)}" for what, names in skipped.items()) + ".")

    # -- equality constraints -----------------------------------------------------
    def equalities(self, frames) -> None:
        """MuJoCo's active equality constraints as the model's exact position
        constraints, one equation per row of MuJoCo's ``efc_pos``, the same
        function of the configuration (``mj_instantiateEquality``)."""
        mujoco, m = _mujoco(), self.m
        label = lambda e: self.name_of(mujoco.mjtObj.mjOBJ_EQUALITY, e) or f"equality {e}"
        inactive = [label(e) for e in range(m.neq) if not m.eq_active0[e]]
        if inactive:
            self.notes.append(f"Skipped: {len(inactive)} inactive equality constraints "
                              f"(active=\"false\"): {', '.join(inactive)}.")
        active = [e for e in range(m.neq) if m.eq_active0[e]]
        if not active:
            return
        coordinate = {jt.id: jt.coordinates[0] for jt in self.coordinates}
        for e in active:
            kind = mujoco.mjtEq(int(m.eq_type[e])).name.removeprefix("mjEQ_").lower()
            name = self.unique(sanitize(self.name_of(mujoco.mjtObj.mjOBJ_EQUALITY, e))
                               or f"equality{e}")
            key = f"equality[{e}]"
            data = m.eq_data[e]
            if kind in ("joint", "tendon"):
                value = self.joint_value if kind == "joint" else self.tendon_length
                first = value(int(m.eq_obj1id[e]), coordinate, key)
                residual = first[0] - first[1] - _num(data[0])
                if m.eq_obj2id[e] >= 0:
                    second = value(int(m.eq_obj2id[e]), coordinate, key)
                    d = second[0] - second[1]
                    residual -= sum(_num(data[k]) * d ** k for k in range(1, 5) if data[k])
                self.constrain(name, e, [(0, {"expression": residual})], key)
            elif kind in ("connect", "weld"):
                self.body_equality(e, kind, name, frames, key)
            else:
                raise self.error(f"equality constraint '{label(e)}' is of kind '{kind}', "
                                 "which modelgen cannot import", key,
                                 "remove it; joint, fixed-tendon, connect and weld "
                                 "equalities import")
        self.notes.append(f"Equality constraints ({self.eq_kinds(active)}) are exact "
                          "position constraints (MuJoCo's solref and solimp softness is "
                          "ignored).")

    def eq_kinds(self, ids) -> str:
        kinds = [_mujoco().mjtEq(int(self.m.eq_type[e])).name.removeprefix("mjEQ_").lower()
                 for e in ids]
        return ", ".join(f"{kinds.count(k)} {k}" for k in sorted(set(kinds)))

    def constrain(self, name: str, e: int, rows: list, key: str) -> None:
        """Add one equality's equations: ``rows`` of (efc row, fields) in order; a
        ``position`` expression that is identically zero is left out (MuJoCo keeps
        the row: its violation is then zero at every configuration)."""
        kept = [(r, f) for r, f in rows if "point_a" in f or f["expression"] != 0]
        for i, (row, fields) in enumerate(kept):
            # a weld's orientation rows 3-5 are about x, y, z
            label = name if i == 0 else self.unique(f"{name}_r{'xyz'[row - 3]}")
            if "point_a" in fields:
                self.model.add_constraint(label, "coincide", **fields)
                self.equality_rows += [(e, row + k) for k in range(3)]
            else:
                self.model.add_constraint(label, "position", **fields)
                self.equality_rows.append((e, row))

    def joint_value(self, j: int, coordinate: dict, key: str) -> tuple:
        """(qpos, qpos0) of a hinge or slide joint."""
        if j not in coordinate:
            raise self.error(f"an equality constraint couples joint '{self.joint_name(j)}', "
                             "which is not a hinge or slide", key, "couple hinges or slides")
        return symbol(coordinate[j]), _num(self.m.qpos0[self.m.jnt_qposadr[j]])

    def tendon_length(self, t: int, coordinate: dict, key: str) -> tuple:
        """(length, length at qpos0) of a fixed tendon: sum of coef * qpos."""
        mujoco, m = _mujoco(), self.m
        name = self.name_of(mujoco.mjtObj.mjOBJ_TENDON, t) or f"tendon {t}"
        length = sympy.S.Zero
        for w in range(m.tendon_adr[t], m.tendon_adr[t] + m.tendon_num[t]):
            if m.wrap_type[w] != mujoco.mjtWrap.mjWRAP_JOINT:
                raise self.error(f"an equality constraint couples the spatial tendon "
                                 f"'{name}', whose length follows sites and wrapping geoms "
                                 "(not an expression of the coordinates modelgen can write)",
                                 key, "remove the equality, or couple the joints with a "
                                 "fixed tendon or a joint equality")
            q, _ = self.joint_value(int(m.wrap_objid[w]), coordinate, key)
            length += _num(m.wrap_prm[w]) * q
        return length, _num(m.tendon_length0[t])

    def body_equality(self, e: int, kind: str, name: str, frames, key: str) -> None:
        """connect: the two anchors coincide (3 rows); weld: the anchors coincide and
        the orientation error ``torquescale * vec(conj(q1) q0 relpose)`` is zero (3
        more rows), as ``mj_instantiateEquality``, with body or site semantics."""
        mujoco, m = _mujoco(), self.m
        data = m.eq_data[e]
        ids = (int(m.eq_obj1id[e]), int(m.eq_obj2id[e]))
        sites = m.eq_objtype[e] == mujoco.mjtObj.mjOBJ_SITE
        bodies = tuple(int(m.site_bodyid[i]) for i in ids) if sites else ids
        points = []
        for j, (obj, body) in enumerate(zip(ids, bodies)):
            base, point, _ = frames[body]
            # connect: anchor j is data[3j:3j+3]; weld: body 1 takes relpose's position
            offset = m.site_pos[obj] if sites else \
                data[3 * j:3 * j + 3] if kind == "connect" else data[3 * (1 - j):6 - 3 * j]
            points.append(self.offset(point, base, offset, f"{name}_anchor{j + 1}"))
        if points[0] == points[1]:
            raise self.error(f"equality constraint '{name}' ties a point to itself", key,
                             "remove it")
        rows = [(0, {"point_a": points[0], "point_b": points[1]})]
        if kind == "weld" and data[10] != 0:
            top = self.common_ancestor(*bodies)
            self.weld_hinges(bodies, top, key)
            q0, q1 = (self.body_quaternion(b, top, key) for b in bodies)
            if sites:
                q0 = quat_mul(q0, quat_const(m.site_quat[ids[0]]))
                q1 = quat_mul(q1, quat_const(m.site_quat[ids[1]]))
            else:
                q0 = quat_mul(q0, quat_const(data[6:10]))
            error = quat_mul(quat_conj(q1), q0)
            rows += [(3 + k, {"expression": self.polynomial(error[1 + k], data[10], key)})
                     for k in range(3)]
        self.constrain(name, e, rows, key)

    def common_ancestor(self, a: int, b: int) -> int:
        m = self.m
        above = set()
        while True:
            above.add(a)
            if a == 0:
                break
            a = int(m.body_parentid[a])
        while b not in above:
            b = int(m.body_parentid[b])
        return b

    def body_quaternion(self, b: int, top: int, key: str) -> tuple:
        """The orientation of body ``b`` relative to its ancestor ``top`` (MuJoCo's
        ``conj(xquat[top]) xquat[b]``) as polynomials in half-angle cosines and sines."""
        m, chain = self.m, []
        while b != top:
            chain.append(b)
            b = int(m.body_parentid[b])
        quat = quat_const((1.0, 0.0, 0.0, 0.0))
        for b in reversed(chain):
            quat = quat_mul(quat, quat_const(m.body_quat[b]))
            for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
                if m.jnt_type[j] in (_BALL, _FREE):
                    raise self.error(
                        f"a weld's orientation error passes through the "
                        f"{_TYPE_NAMES[int(m.jnt_type[j])]} joint '{self.joint_name(j)}', "
                        "whose quaternion a position constraint's expression cannot use",
                        key, "weld bodies joined by hinges and slides only, or use a "
                        "connect (the anchors coincide; it takes any joints)")
                if m.jnt_type[j] != _HINGE:
                    continue
                axis = m.jnt_axis[j]
                turn = ({((j, "c"),): 1.0},) + tuple(
                    {((j, "s"),): float(a)} if a else {} for a in axis)
                quat = quat_mul(quat, turn)
        return quat

    def weld_hinges(self, bodies, top: int, key: str) -> None:
        """Refuse a weld whose bodies are more than WELD_MAX_HINGES hinges apart (both
        sides of ``top``), before any of its 2^k terms is built."""
        m, hinges = self.m, 0
        for b in bodies:
            while b != top:
                joints = range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b])
                hinges += sum(m.jnt_type[j] == _HINGE for j in joints)
                b = int(m.body_parentid[b])
        if hinges > WELD_MAX_HINGES:
            raise self.error(f"a weld's orientation error through {hinges} hinges would be "
                             f"a sum of up to 2^{hinges} terms per equation", key,
                             f"weld bodies at most {WELD_MAX_HINGES} hinges apart")

    def polynomial(self, poly: dict, scale: float, key: str) -> sympy.Expr:
        """A polynomial in half-angle cosines and sines, times ``scale``, as an
        expression of the coordinates (terms at rounding level left out)."""
        m = self.m
        big = max((abs(c) for c in poly.values()), default=0.0)
        kept = [mono for mono in sorted(poly) if abs(poly[mono]) > POLY_NOISE * big]
        # at least ' + ' between terms and '*cos(q/2)' a factor: refused before it is built
        shortest = sum(3 + 9 * len(mono) for mono in kept)
        if shortest > MAX_LENGTH:
            raise self.error(f"a weld's orientation error would be over {shortest} characters "
                             f"long, over the {MAX_LENGTH} of a model's expression", key,
                             "weld bodies fewer hinges apart, or use a connect")
        names = {jt.id: jt.coordinates[0] for jt in self.coordinates}
        terms = []          # summed once: a growing sum re-sorts all of it each time
        for mono in kept:
            halves = [(symbol(names[j]) - _num(m.qpos0[m.jnt_qposadr[j]])) / 2 for j, _ in mono]
            terms.append(sympy.Mul(_num(poly[mono] * scale), *(
                sympy.cos(h) if f == "c" else sympy.sin(h) for h, (_, f) in zip(halves, mono))))
        return sympy.Add(*terms)

    def gravity(self) -> None:
        mujoco, m = _mujoco(), self.m
        if m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_GRAVITY or not np.any(m.opt.gravity):
            return
        gx, gy, gz = (float(x) for x in m.opt.gravity)
        if gx == 0 and gy == 0 and gz < 0:
            self.model.add_parameter("g", -gz)
            self.model.set_gravity([0, 0, -symbol("g")])
        else:
            self.model.set_gravity([_num(x) for x in (gx, gy, gz)])

    def ignored(self) -> None:
        """Notes for what MuJoCo simulates and the model leaves out."""
        m = self.m
        counts = (("geoms (contacts)", m.ngeom), ("tendons", m.ntendon),
                  ("actuators", m.nu), ("sensors", m.nsensor), ("flexes", m.nflex))
        listed = [f"{n} {what}" for what, n in counts if n]
        if listed:
            self.notes.append("Ignored: " + ", ".join(listed) + " (the model is the rigid "
                              "bodies, joints and joint effects only; no inputs).")
        if np.any(m.jnt_limited):
            self.notes.append(f"Joint limits of {int(np.sum(m.jnt_limited))} joints are not "
                              "enforced.")
        if m.opt.density > 0 or m.opt.viscosity > 0 or np.any(m.opt.wind):
            self.notes.append("Fluid forces (density, viscosity, wind) are ignored.")
        if np.any(m.body_gravcomp):
            self.notes.append("Gravity compensation (gravcomp) is ignored.")
        if m.ntendon and (np.any(m.tendon_stiffness) or np.any(m.tendon_damping)
                          or np.any(m.tendon_armature)):
            self.notes.append("Tendon stiffness, damping and armature are ignored.")

    def build(self) -> MjcfImport:
        self.check_numbers()
        self.gravity()
        frames = self.body_frames()
        self.bodies(frames)
        self.frames(frames)
        self.equalities(frames)
        self.ignored()
        self.effects()
        # the notes are known only now; the description goes first in the file
        spec = replace(self.model.spec(),
                       description=" ".join(self.description() + tuple(self.notes)))
        model = Model.from_spec(spec)
        joints = sorted(self.coordinates + self.quaternion_joints, key=lambda j: j.id)
        qpos_index, dof_index = [], []
        by_coordinate = {c: jt.qposadr + i for jt in joints for i, c in enumerate(jt.coordinates)}
        by_speed = {v: jt.dofadr + i for jt in joints for i, v in enumerate(jt.speeds)}
        qpos_index = tuple(by_coordinate[c] for c in spec.coordinates)
        dof_index = tuple(by_speed[v] for v in spec.dof_names)
        free = tuple((spec.coordinates.index(jt.coordinates[3]), spec.dof_names.index(jt.speeds[0]))
                     for jt in self.quaternion_joints if jt.type == "free")
        return MjcfImport(model, tuple(joints), self.source, tuple(map(comment_text, self.notes)),
                          qpos_index, dof_index, free, tuple(self.equality_rows))

    def check_numbers(self) -> None:
        """Refuse NaN, infinities (:data:`_READ_FIELDS`, gravity), non-unit quaternions."""
        m, mujoco = self.m, _mujoco()
        fix = ("write finite numbers in the MJCF (no nan or inf, none whose compiled value "
               "overflows) and quaternions MuJoCo can normalize (none zero or near it)")
        if not np.all(np.isfinite(m.opt.gravity)):
            raise self.error(f"the gravity {m.opt.gravity.tolist()} is not finite",
                             "option.gravity", fix)
        for kind, count, obj, fields in _READ_FIELDS:
            for field in fields:
                values = np.asarray(getattr(m, field), dtype=float).reshape(getattr(m, count), -1) \
                    if getattr(m, count) else np.zeros((0, 1))
                bad = ~np.isfinite(values).all(axis=1)
                quat = field.endswith("quat")
                if quat:    # MuJoCo normalizes one but keeps one too small to: zero, 1e-300
                    with np.errstate(all="ignore"):
                        bad |= ~(np.abs(np.einsum("ij,ij->i", values, values) - 1) < 1e-9)
                bad = np.flatnonzero(bad)
                if bad.size:
                    i = int(bad[0])
                    owner, index = ("joint", int(m.dof_jntid[i])) if kind == "dof" else \
                        ("joint", int(np.flatnonzero(m.jnt_qposadr <= i)[-1])) \
                        if kind == "qpos" else (kind, i)
                    label = self.name_of(getattr(mujoco.mjtObj, obj), index) if obj else ""
                    what = "no unit quaternion" if quat else "not finite"
                    raise self.error(
                        f"{owner} {repr(label) if label else index} has {field} = "
                        f"{values[i].tolist()}, {what} (MuJoCo compiles it with a warning at "
                        "most)", f"{owner}[{index}].{field}", fix)

    def description(self) -> tuple:
        m = self.m
        return (f"Imported from {Path(self.source).name} (MJCF, compiled by MuJoCo "
                f"{_mujoco().__version__}): {m.nq} qpos, {m.nv} dofs, {m.nbody - 1} bodies.",)


def import_mjmodel(mjmodel, source: str = "<mjmodel>", *, name: Optional[str] = None,
                   frictionloss: str = "smooth") -> MjcfImport:
    """Import a compiled ``mujoco.MjModel`` (see the module docstring).

    ``name`` defaults to the model's ``<mujoco model="...">`` (sanitized);
    ``frictionloss="ignore"`` leaves MuJoCo's ``frictionloss`` out instead of
    importing it as a smoothed Coulomb ``friction`` effect.
    """
    if frictionloss not in FRICTIONLOSS:
        raise ValueError(f"frictionloss must be one of {FRICTIONLOSS}, not {frictionloss!r}")
    if name is None:
        name = model_name_for(_mujoco().mj_id2name(mjmodel, _mujoco().mjtObj.mjOBJ_MODEL, 0)
                              or Path(source).stem)
    if not re.match(r"[A-Za-z]", name):
        name = "robot_" + name
    try:
        return _Builder(mjmodel, name[:63], source, frictionloss).build()
    except ModelError as exc:
        if exc.file != API_FILE:
            raise
        # the model's own checks (a name, too many constraint equations...): in the
        # generated model's terms, at the file they came from
        raise ModelError(exc.problem, file=source, key=exc.key, fix=exc.fix) from None


def import_mjcf(path, *, name: Optional[str] = None, frictionloss: str = "smooth") -> MjcfImport:
    """Compile an MJCF file with MuJoCo and import it; options as :func:`import_mjmodel`.

    >>> imp = import_mjcf("acrobot.xml")                        # doctest: +SKIP
    >>> imp.model.spec().coordinates                            # doctest: +SKIP
    ('shoulder', 'elbow')
    """
    mujoco = _mujoco()
    path = Path(path)
    if not path.is_file():
        raise ModelError("cannot read the MJCF file: no such file", file=str(path),
                         fix="check the path")
    mjmodel = _compiled(lambda: mujoco.MjModel.from_xml_path(str(path)), str(path), "file",
                        path)
    return import_mjmodel(mjmodel, str(path), name=name, frictionloss=frictionloss)


def import_mjcf_text(text: str, source: str = "<string>", **options) -> MjcfImport:
    """Import MJCF text (no file includes or assets); options as :func:`import_mjmodel`."""
    mujoco = _mujoco()
    mjmodel = _compiled(lambda: mujoco.MjModel.from_xml_string(text), source, "text")
    return import_mjmodel(mjmodel, source, **options)


def _compiled(compile_mjcf, source: str, what: str, path: Path | None = None):
    """``compile_mjcf()``'s MjModel; MuJoCo's compile errors (ValueError) as a
    ModelError at the line MuJoCo names; when it names none, in the file ``path``,
    at the first byte that is not UTF-8 (which fails MuJoCo's message itself) or
    at the element it names (its message, cut at about 500 characters, loses the
    line after a long name)."""
    try:
        return compile_mjcf()
    except ValueError as exc:
        message = " ".join(str(exc).split())
        found = re.search(r"\bline(?: number=| )(\d+)", message, re.IGNORECASE)
        line = int(found[1]) if found else None
        if line is None and isinstance(exc, UnicodeDecodeError) and path is not None:
            data = path.read_bytes()
            try:
                data.decode("utf-8")
            except UnicodeDecodeError as bad:
                line = data[:bad.start].count(b"\n") + 1
                message = f"byte {data[bad.start]:#04x} is not UTF-8 text"
        named = re.search(r"\belement '([^']+)", message) if line is None and path else None
        if named:
            text = path.read_bytes().decode("utf-8", "replace")
            at = text.find(named[1][:100])
            line = text.count("\n", 0, at) + 1 if at >= 0 else None
        # without a line, MuJoCo's engine names the element by its id: "body 4 is..."
        element = re.search(r"\b(body|joint|geom|site|equality|tendon|actuator) (\d+)\b",
                            message) if line is None else None
        raise ModelError(f"MuJoCo cannot compile the {what}: {message}", file=source,
                         line=line, key=f"{element[1]}[{element[2]}]" if element else None,
                         fix="fix the MJCF as MuJoCo's message says") from None


def load_mjcf(path, **options) -> Model:
    """The :class:`Model` of an MJCF file (see :func:`import_mjcf`)."""
    return import_mjcf(path, **options).model


def mjcf_to_yaml(imported: MjcfImport) -> str:
    """The model file of an import: a comment header (source, notes), then YAML."""
    lines = [f"# Imported by 'modelgen import' from {Path(imported.source).name} (MJCF).",
             "# Edit freely; re-importing overwrites this file."]
    lines += [f"# Note: {note}" for note in imported.notes]
    return "\n".join(map(comment_text, lines)) + "\n" + imported.model.to_yaml()
