"""Mutated MJCF files for fuzzing the MJCF importer, and a check of what an accepted
file became against MuJoCo's own compiled model.

Shared by ``tests/test_mjcf_fuzz.py`` (a small seeded run) and ``bench/fuzz.py
--mjcf`` (tens of thousands of cases).  MuJoCo compiles each file (its parser
and compiler refuse what they refuse, and the import says so as a ModelError at
MuJoCo's line); the mutations aim at what it compiles with a warning at most:

* numbers: NaN, infinities, overflowing, tiny and negative values in any number
  slot (positions, quaternions, axes, masses, inertias, damping, stiffness,
  springref, armature, frictionloss, gravity, sizes, gear, polycoef...);
* structure: joint types (hinge, slide, ball, free, unknown), elements and
  attributes deleted or duplicated, deep chains of hinged bodies, equality
  constraints (joint couplings, connect, weld) between any two named joints or
  bodies;
* text: hostile names (C and Python keywords, injection text, Unicode), truncated
  or malformed XML, deep nesting, raw bytes that are not UTF-8.

:func:`check_accepted` compares an accepted model with the compiled MjModel: as
many coordinates as MuJoCo has ``qpos``, as many speeds as dofs, and the total
mass of the bodies that move (a body dropped, duplicated or given another
mass).

>>> import random
>>> text, what = mutate(TINY, random.Random(3))
>>> isinstance(text, (str, bytes)) and bool(what)
True
"""
from __future__ import annotations

import random
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from modelgen.bench.fuzz_urdf import HOSTILE_NAMES, HOSTILE_NUMBERS, XML_MUTATIONS

__all__ = ["TINY", "base_texts", "mutate", "check_accepted"]

#: a small model with every joint kind the import reads, for the tests
TINY = """<mujoco model="tiny">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="upper" pos="0 0 1" quat="0.9 0.1 0.2 0.3">
      <joint name="shoulder" type="hinge" axis="0.2 1 0.1" damping="0.1" armature="0.01"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" mass="1"/>
      <body name="lower" pos="0 0 -0.5">
        <joint name="elbow" type="hinge" axis="0 1 0" stiffness="2" springref="0.3"/>
        <joint name="slider" type="slide" axis="0 0 1" frictionloss="0.05"/>
        <inertial pos="0 0 -0.2" mass="0.7" diaginertia="0.01 0.02 0.03" quat="1 0 0 0"/>
        <site name="tip" pos="0 0 -0.4"/>
      </body>
    </body>
    <body name="ball" pos="1 0 1">
      <joint name="pivot" type="ball"/>
      <geom type="sphere" size="0.1" mass="0.5"/>
    </body>
    <body name="box" pos="2 0 1">
      <freejoint name="box_free"/>
      <geom type="box" size="0.1 0.2 0.3" mass="2"/>
    </body>
  </worldbody>
</mujoco>
"""

#: attributes that hold numbers (space-separated for the vectors)
NUMERIC = ("pos", "quat", "axis", "euler", "axisangle", "xyaxes", "zaxis", "mass",
           "diaginertia", "fullinertia", "damping", "stiffness", "springref", "ref",
           "armature", "frictionloss", "gravity", "size", "fromto", "density", "range",
           "gear", "polycoef", "anchor", "relpose", "torquescale", "timestep")

JOINT_TYPES = ["hinge", "slide", "ball", "free", "", "HINGE", "revolute", "hinge "]

_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")

#: MuJoCo's tinyxml2 rejects these before its compiler sees them; they stay in the
#: mix so that the refusal is a ModelError at a line too
_JUNK = ["<", ">", "&", "&amp", "]]>", "<!--", "\x00", "\x01", "<a>", "</mujoco>", "<?x?>",
         '"', "'", "<body/>", "<include file='/etc/passwd'/>", "<include file='x.xml'/>"]


def base_texts() -> list:
    """(name, text) of the MJCF files to mutate: :data:`TINY` and, when gymnasium is
    installed, its MuJoCo assets (files that include no others)."""
    out = [("tiny.xml", TINY)]
    try:
        import gymnasium
    except ImportError:
        return out
    folder = Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets"
    for path in sorted(folder.glob("*.xml")):
        text = path.read_text()
        if "<include" not in text:
            out.append((path.name, text))
    return out


# -- mutations ---------------------------------------------------------------------

def _named(root, tag):
    return [e.get("name") for e in root.iter(tag) if e.get("name")]


def _m_number(root, rng):
    slots = [(e, a) for e in root.iter() for a in NUMERIC if a in e.attrib]
    if not slots:
        return "no number slot"
    e, a = rng.choice(slots)
    parts = e.attrib[a].split() or ["0"]
    k = rng.randrange(len(parts))
    value = rng.choice(HOSTILE_NUMBERS) or "0"
    if rng.random() < 0.3 and _FLOAT.fullmatch(parts[k]):    # scaled, still finite
        value = repr(float(parts[k]) * rng.choice([1e300, 1e-300, 1e150, -1.0, 0.0]))
    parts[k] = value
    e.attrib[a] = " ".join(parts)
    return f"number {e.tag}.{a}={e.attrib[a][:30]!r}"


def _m_joint_type(root, rng):
    joints = list(root.iter("joint"))
    if not joints:
        return "no joint"
    joint = rng.choice(joints)
    joint.set("type", rng.choice(JOINT_TYPES))
    return f"joint type {joint.get('type')!r}"


def _m_rename(root, rng):
    named = [e for e in root.iter() if "name" in e.attrib]
    if not named:
        return "nothing named"
    e = rng.choice(named)
    e.set("name", rng.choice(HOSTILE_NAMES))
    return f"renamed <{e.tag}> {e.get('name')[:30]!r}"


def _m_deep(root, rng):
    """A chain of hinged bodies under the world body."""
    world = root.find("worldbody")
    if world is None:
        return "no worldbody"
    depth = rng.choice([10, 40, 120])
    parent = world
    for k in range(depth):
        parent = ET.SubElement(parent, "body", name=f"deep{k}", pos="0 0 -0.1")
        ET.SubElement(parent, "joint", name=f"deep_j{k}", type="hinge",
                      axis=rng.choice(["0 1 0", "1 0 0", "0.3 0.4 0.5"]))
        ET.SubElement(parent, "geom", type="sphere", size="0.02", mass="0.1")
    return f"chain of {depth}"


def _m_equality(root, rng):
    """A joint coupling, connect or weld between two named joints or bodies."""
    eq = root.find("equality")
    if eq is None:
        eq = ET.SubElement(root, "equality")
    kind = rng.choice(["joint", "connect", "weld"])
    names = _named(root, "joint") if kind == "joint" else _named(root, "body")
    if not names:
        return "nothing to couple"
    first, second = rng.choice(names), rng.choice(names)
    if kind == "joint":
        ET.SubElement(eq, "joint", joint1=first, joint2=second,
                      polycoef=rng.choice(["0 1 0 0 0", "0.1 -2 0.5 0 0", "nan 1 0 0 0",
                                           "0 1e308 0 0 0"]))
    else:
        ET.SubElement(eq, kind, body1=first, body2=second,
                      **({"anchor": rng.choice(["0 0 0", "0.1 0 -0.2", "inf 0 0"])}
                         if kind == "connect" else {}))
    return f"equality {kind} {first!r} {second!r}"


TREE_MUTATIONS = [_m_number] * 6 + [_m_joint_type, *XML_MUTATIONS, _m_rename, _m_deep] \
    + [_m_equality] * 2


def _text_mutation(text: str, rng: random.Random):
    kind = rng.randrange(6)
    if kind == 0:
        cut = rng.randrange(len(text) + 1)
        return text[:cut], f"truncated at {cut}"
    if kind == 1:
        at = rng.randrange(len(text) + 1)
        junk = rng.choice(_JUNK)
        return text[:at] + junk + text[at:], f"inserted {junk!r} at {at}"
    if kind == 2:
        at = rng.randrange(len(text) + 1)
        junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        return text[:at].encode() + junk + text[at:].encode(), "raw bytes"
    if kind == 3:
        return rng.choice(["", "<mujoco/>", "not xml at all", "<mujoco>" * 3000,
                           "<mujoco><worldbody><body/></worldbody></mujoco>"]), "tiny"
    if kind == 4:
        depth = rng.choice([100, 1000, 20000])
        at = text.find("<worldbody>")
        at = at + len("<worldbody>") if at >= 0 else len(text)
        return text[:at] + "<body>" * depth + "</body>" * depth + text[at:], f"nested {depth}"
    return "\ufeff" + text.replace("\n", "\r\n"), "BOM and CRLF"


def mutate(text: str, rng: random.Random):
    """(mutated text or bytes, description) of one to three mutations of ``text``."""
    if rng.random() < 0.15:
        return _text_mutation(text, rng)
    root = ET.fromstring(text)
    done = [rng.choice(TREE_MUTATIONS)(root, rng) for _ in range(rng.choice([1, 1, 2, 3]))]
    return ET.tostring(root, encoding="unicode"), "; ".join(done)


# -- the check of an accepted file ---------------------------------------------------

def check_accepted(imported, mjmodel) -> list:
    """What an accepted import (:class:`~modelgen.model.mjcf.MjcfImport`) says
    differently from MuJoCo's compiled ``mjmodel``: the number of coordinates and
    speeds, and the total mass of the moving bodies.  Empty when they agree."""
    spec = imported.model.spec()
    problems = []
    if len(spec.coordinates) != mjmodel.nq:
        problems.append(f"{len(spec.coordinates)} coordinates, MuJoCo's nq is {mjmodel.nq}")
    if len(spec.dof_names) != mjmodel.nv:
        problems.append(f"{len(spec.dof_names)} speeds, MuJoCo's nv is {mjmodel.nv}")
    moving = [b for b in range(1, mjmodel.nbody) if _moves(mjmodel, b)]
    theirs = sum(float(mjmodel.body_mass[b]) for b in moving)
    ours = sum(float(body.mass) for body in spec.bodies)
    if abs(ours - theirs) > 1e-12 * max(1.0, abs(theirs)):
        problems.append(f"total moving mass {ours!r}, MuJoCo's {theirs!r}")
    return problems


def _moves(mjmodel, b: int) -> bool:
    """True if a joint moves body ``b`` (one of its own or of an ancestor's)."""
    while b > 0:
        if mjmodel.body_jntnum[b] > 0:
            return True
        b = int(mjmodel.body_parentid[b])
    return False
