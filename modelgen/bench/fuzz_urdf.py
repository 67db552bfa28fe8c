"""Mutated URDF files for fuzzing the URDF importer, and an independent check of
what an accepted file became.

Shared by ``tests/test_urdf_fuzz.py`` (a small seeded run) and ``bench/fuzz.py
--urdf`` (tens of thousands of cases).  Plain ``random.Random`` with a seed: no
hypothesis needed.

:func:`mutate` takes a real URDF text and applies one to three mutations:
numeric (huge, tiny, negative, NaN, inf, ``1e999``, denormal values in any
number slot, zero and denormal axes), structural (elements and attributes
deleted or duplicated, unknown joint types, cycles, parents swapped, deep
chains, mimic loops and mimics of missing joints) and textual (malformed XML,
entity attacks, external entities, long names, names that are C or Python
keywords or carry injection text, bytes that are not UTF-8).

:func:`check_accepted` compares the spec of an accepted file with the file as
:mod:`xml.etree` reads it, computed with mpmath (no overflow, 30 digits): the
direction of every joint's axis in the world frame at q = 0, the number of
coordinates, and the total mass, centre of mass and inertia (about it, world
frame) of the moving links.  A mismatch is a file accepted as something it
does not say.

>>> import random
>>> text, what = mutate(TINY, random.Random(1))
>>> isinstance(text, (str, bytes)) and bool(what)
True
>>> check_accepted(__import__("modelgen.model.urdf", fromlist=["x"])
...                .import_urdf_text(TINY).model.spec(), TINY)
[]
"""
from __future__ import annotations

import math
import random
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import mpmath
import sympy

__all__ = ["TINY", "HOSTILE_NUMBERS", "HOSTILE_NAMES", "XML_MUTATIONS", "mutate",
           "check_accepted", "base_texts"]

#: a two-link robot with an unaligned axis, for the doctest and the quick tests
TINY = """<robot name="tiny"><link name="world"/>
<link name="a"><inertial><origin xyz="0.1 0 0.2" rpy="0.3 0.2 0.1"/><mass value="2"/>
<inertia ixx="0.05" ixy="0.004" ixz="-0.003" iyy="0.04" iyz="0.002" izz="0.03"/></inertial></link>
<link name="b"><inertial><mass value="1"/>
<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.008"/></inertial></link>
<joint name="j1" type="revolute"><parent link="world"/><child link="a"/>
<origin xyz="0 0 0.5" rpy="0.1 0.2 0.3"/><axis xyz="0.2 -0.5 0.8"/>
<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
<joint name="j2" type="prismatic"><parent link="a"/><child link="b"/>
<origin xyz="0 0.3 0"/><axis xyz="0 0 1"/><dynamics damping="0.1" friction="0.2"/></joint>
</robot>
"""

HOSTILE_NUMBERS = ["1e308", "-1e308", "1.7976931348623157e308", "1e999", "-1e999", "nan",
                   "NaN", "-nan", "inf", "-inf", "Infinity", "1e-320", "5e-324", "-5e-324",
                   "0", "-0", "-0.0", "-1", "-1e-300", "1e200", "1e-200", "1e-308",
                   "2.2250738585072014e-308", "0x10", "1_000", "", " ", "1,5", "1e", "--1",
                   "+.5", ".5e-3", "1e+308", "٣", "１", "1e309", "123456789" * 40]

HOSTILE_NAMES = ["int", "double", "return", "class", "None", "True", "lambda", "import",
                 "__import__('os').system('true')", "a; rm -rf /", "x\"); system(\"ls",
                 "*/ int x; /*", "#define q 1", "{{ 7*7 }}", "${HOME}", "E", "O", "g", "t",
                 "q", "pi", "sin", "tau_j1", "j1_dot", "", " ", "0start", "a" * 5000,
                 "é", "名前", "a\tb", "a..b", "\u200b", "_", "__", "main", "static",
                 "restrict", "NULL", "link", "-", "1e308"]

JOINT_TYPES = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "ball",
               "spherical", "REVOLUTE", "", "screw", "universal", "revolute "]

_NUMERIC = {  # tag -> attributes holding numbers (space-separated for the vectors)
    "origin": ("xyz", "rpy"), "axis": ("xyz",), "mass": ("value",),
    "inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
    "limit": ("lower", "upper", "effort", "velocity"), "dynamics": ("damping", "friction"),
    "mimic": ("multiplier", "offset")}

_AXES = ["0 0 0", "0 -0 0.0", "1e-320 0 0", "5e-324 5e-324 0", "1e308 1e308 1e308",
         "0 0 -1e308", "1e200 0 1e200", "-1.7e308 1.7e308 0", "1e-300 1e-300 1e-300",
         "nan 0 1", "inf 0 0", "1 0", "1 0 0 0", "1e999 0 0", "0 0 1e-400", "1 1 1",
         "-1 0 0", "0 0 -1", "3 4 0", "2.2250738585072014e-308 0 -1e-310"]


def base_texts(paths) -> list:
    """(name, text) of each readable URDF file among ``paths``."""
    out = []
    for path in paths:
        try:
            out.append((Path(path).name, Path(path).read_text()))
        except (OSError, UnicodeDecodeError):
            continue
    return out


# -- mutations ---------------------------------------------------------------------

def _elements(root, tag=None):
    return [e for e in root.iter() if tag is None or e.tag == tag]


def _top(root, tag):
    return [e for e in root if e.tag == tag]


def _number_slot(root, rng):
    slots = [(e, a) for e in root.iter() if e.tag in _NUMERIC for a in _NUMERIC[e.tag]
             if a in e.attrib]
    return rng.choice(slots) if slots else (None, None)


def _m_number(root, rng):
    e, a = _number_slot(root, rng)
    if e is None:
        return "no number slot"
    parts = e.attrib[a].split()
    value = rng.choice(HOSTILE_NUMBERS)
    if len(parts) > 1 and rng.random() < 0.7:
        parts[rng.randrange(len(parts))] = value or "0"
        e.attrib[a] = " ".join(parts)
    else:
        e.attrib[a] = value
    return f"number {e.tag}.{a}={e.attrib[a][:30]!r}"


def _m_scale(root, rng):
    """Every number of one slot kind multiplied by a huge or tiny factor (still finite)."""
    factor = rng.choice([1e300, 1e-300, 1e150, 1e-150, -1.0, 1e308, 5e-324, 0.0])
    tag = rng.choice(["mass", "inertia", "origin", "axis"])
    for e in _elements(root, tag):
        for a in _NUMERIC[tag]:
            if a in e.attrib:
                try:
                    values = [float(x) * factor for x in e.attrib[a].split()]
                except ValueError:
                    continue
                e.attrib[a] = " ".join(repr(v) for v in values)
    return f"scale {tag} by {factor!r}"


def _m_axis(root, rng):
    joints = _top(root, "joint")
    if not joints:
        return "no joint"
    j = rng.choice(joints)
    axis = j.find("axis")
    if axis is None:
        axis = ET.SubElement(j, "axis")
    axis.attrib["xyz"] = rng.choice(_AXES)
    return f"axis {j.get('name')}={axis.attrib['xyz']}"


def _m_delete_element(root, rng):
    candidates = [(p, c) for p in root.iter() for c in p]
    if not candidates:
        return "nothing to delete"
    parent, child = rng.choice(candidates)
    parent.remove(child)
    return f"delete <{child.tag}>"


def _m_duplicate_element(root, rng):
    candidates = [(p, c) for p in root.iter() for c in p]
    if not candidates:
        return "nothing to duplicate"
    parent, child = rng.choice(candidates)
    copy = ET.fromstring(ET.tostring(child))
    if rng.random() < 0.5 and child.tag in ("link", "joint") and "name" in copy.attrib:
        copy.attrib["name"] += "_copy"      # same content, a new name: a second root or parent
    parent.insert(rng.randrange(len(parent) + 1), copy)
    return f"duplicate <{child.tag}>"


def _m_delete_attribute(root, rng):
    candidates = [(e, a) for e in root.iter() for a in e.attrib]
    if not candidates:
        return "no attribute"
    e, a = rng.choice(candidates)
    del e.attrib[a]
    return f"delete {e.tag}@{a}"


def _m_joint_type(root, rng):
    joints = _top(root, "joint")
    if not joints:
        return "no joint"
    j = rng.choice(joints)
    j.attrib["type"] = rng.choice(JOINT_TYPES)
    return f"type {j.get('name')}={j.attrib['type']!r}"


def _m_cycle(root, rng):
    joints = _top(root, "joint")
    links = [l.get("name") for l in _top(root, "link")]
    if not joints or not links:
        return "no joint"
    j = rng.choice(joints)
    kind = rng.randrange(3)
    parent, child = j.find("parent"), j.find("child")
    if parent is None or child is None:
        return "joint without ends"
    if kind == 0:
        parent.attrib["link"], child.attrib["link"] = child.get("link"), parent.get("link")
    elif kind == 1:
        child.attrib["link"] = links[0]          # the root gets a parent
    else:
        parent.attrib["link"] = child.get("link")   # a self-loop
    return f"cycle {kind} at {j.get('name')}"


def _m_rename(root, rng):
    items = _top(root, "link") + _top(root, "joint") + [root]
    e = rng.choice(items)
    old, new = e.get("name"), rng.choice(HOSTILE_NAMES)
    e.attrib["name"] = new
    if e.tag == "link" and rng.random() < 0.8:     # keep references consistent mostly
        for ref in list(_elements(root, "parent")) + list(_elements(root, "child")):
            if ref.get("link") == old:
                ref.attrib["link"] = new
    if e.tag == "joint" and rng.random() < 0.8:
        for ref in _elements(root, "mimic"):
            if ref.get("joint") == old:
                ref.attrib["joint"] = new
    return f"rename <{e.tag}> {new[:20]!r}"


def _m_mimic(root, rng):
    joints = _top(root, "joint")
    if not joints:
        return "no joint"
    a, b = rng.choice(joints), rng.choice(joints)
    kind = rng.randrange(4)
    for e in a.findall("mimic"):
        a.remove(e)
    target = {0: a.get("name"), 1: b.get("name"), 2: "no_such_joint", 3: b.get("name")}[kind]
    ET.SubElement(a, "mimic", {"joint": target or "",
                               "multiplier": rng.choice(["1", "-0.5", "1e308", "0", "nan"]),
                               "offset": rng.choice(["0", "0.2", "-1e308"])})
    if kind == 3:                       # a loop of two
        for e in b.findall("mimic"):
            b.remove(e)
        ET.SubElement(b, "mimic", {"joint": a.get("name") or ""})
    return f"mimic {kind} {a.get('name')}->{target}"


def _m_deep(root, rng):
    """A long chain (or a wide fan) of links hung below one link."""
    links = _top(root, "link")
    if not links:
        return "no link"
    parent = rng.choice(links).get("name")
    n = rng.choice([10, 20, 20, 40, 40, 100, 300])
    fan = rng.random() < 0.3
    kind = rng.choice(["revolute", "fixed", "prismatic", "continuous"])
    for k in range(n):
        name = f"deep_{k}"
        link = ET.SubElement(root, "link", {"name": name})
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "mass", {"value": "0.1"})
        ET.SubElement(inertial, "inertia", {"ixx": "1e-3", "iyy": "1e-3", "izz": "1e-3",
                                            "ixy": "0", "ixz": "0", "iyz": "0"})
        joint = ET.SubElement(root, "joint", {"name": f"deep_j{k}", "type": kind})
        ET.SubElement(joint, "parent", {"link": parent})
        ET.SubElement(joint, "child", {"link": name})
        ET.SubElement(joint, "origin", {"xyz": "0 0 0.01", "rpy": "0.01 0 0"})
        ET.SubElement(joint, "axis", {"xyz": "0 1 0"})
        if not fan:
            parent = name
    return f"{'fan' if fan else 'chain'} of {n} {kind}"


def _m_unknown_element(root, rng):
    e = rng.choice(list(root.iter()))
    sub = ET.SubElement(e, rng.choice(["gazebo", "transmission", "xacro_include", "sensor",
                                       "inertial", "origin", "mass", "link", "joint"]))
    sub.attrib["name"] = rng.choice(HOSTILE_NAMES[:10])
    return f"extra <{sub.tag}> in <{e.tag}>"


DRAKE = "http://drake.mit.edu"
ET.register_namespace("drake", DRAKE)     # written as drake:rotor_inertia, as Drake reads it


def _m_rotor(root, rng):
    """A transmission with Drake's rotor extension on a random joint, hostile numbers."""
    joints = _top(root, "joint")
    if not joints:
        return "no joint"
    joint = rng.choice(joints).get("name") if rng.random() < 0.9 else "no_such_joint"
    t = ET.SubElement(root, "transmission", {"name": f"t{rng.randrange(1000)}"})
    ET.SubElement(t, "joint", {"name": joint or ""})
    actuator = ET.SubElement(t, "actuator", {"name": "m"})
    inertia = rng.choice(["0.001", "0", "1e-6", "-1", "1e308", "nan", "5e-324", "2"])
    ratio = rng.choice(["50", "1", "-100", "1e200", "0", "inf", "3.5"])
    if rng.random() < 0.9:
        ET.SubElement(actuator, f"{{{DRAKE}}}rotor_inertia", {"value": inertia})
    if rng.random() < 0.7:
        ET.SubElement(actuator, f"{{{DRAKE}}}gear_ratio", {"value": ratio})
    return f"rotor on {joint}: {inertia} x {ratio}^2"


#: the mutations that know nothing of URDF (an element or attribute deleted, an element
#: duplicated, a joint or link copy renamed), shared with the MJCF fuzz
XML_MUTATIONS = (_m_delete_element, _m_duplicate_element, _m_delete_attribute)

TREE_MUTATIONS = [_m_rotor, _m_number, _m_number, _m_number, _m_scale, _m_axis, _m_axis,
                  *XML_MUTATIONS, _m_joint_type, _m_cycle, _m_rename, _m_mimic, _m_deep,
                  _m_unknown_element]

_ATTACKS = [
    '<!DOCTYPE robot [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
    '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;">]>',
    '<!DOCTYPE robot [<!ENTITY x SYSTEM "file:///etc/passwd">]>',
    '<!DOCTYPE robot [<!ENTITY % p SYSTEM "http://127.0.0.1:1/x.dtd"> %p;]>',
    '<!DOCTYPE robot SYSTEM "http://127.0.0.1:1/robot.dtd">',
    '<?xml-stylesheet href="x.xsl"?>',
    '<?xml version="1.0" encoding="latin-1"?>',
]


def _text_mutation(text: str, rng: random.Random):
    kind = rng.randrange(9)
    if kind == 0:
        cut = rng.randrange(len(text) + 1)
        return text[:cut], f"truncated at {cut}"
    if kind == 1:
        at = rng.randrange(len(text) + 1)
        junk = rng.choice(["<", ">", "&", "&amp", "]]>", "<!--", "\x00", "\x01", "<a>", "</robot>",
                           "<?x?>", "\ufffe", '"', "'", "<link name='z'/>"])
        return text[:at] + junk + text[at:], f"inserted {junk!r} at {at}"
    if kind == 2:
        attack = rng.choice(_ATTACKS)
        body = text.split("?>", 1)[1] if text.lstrip().startswith("<?xml") else text
        ref = "&d;" if "ENTITY d" in attack else "&x;" if "ENTITY x" in attack else ""
        body = body.replace('name="', f'name="{ref}', 1) if ref else body
        return attack + body, f"attack {attack[:40]!r}"
    if kind == 3:
        at = rng.randrange(len(text) + 1)
        junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        return text[:at].encode() + junk + text[at:].encode(), "raw bytes"
    if kind == 4:
        return "", "empty file"
    if kind == 5:
        return rng.choice(['<robot name="r"/>', "<robot/>", '<robot name="r"><link/></robot>',
                           "<urdf/>", "not xml at all", '<robot name="r">' * 5000,
                           '<robot name="r"><link name="a"/></robot>',
                           '<?xml version="1.0"?>\n<robot xmlns:xacro="x">\n</robot>']), "tiny"
    if kind == 6:
        depth = rng.choice([100, 1000, 50000])
        at = text.find("<link")
        at = at if at >= 0 else len(text)
        return text[:at] + "<a>" * depth + "</a>" * depth + text[at:], f"nested {depth}"
    if kind == 7:
        return "\ufeff" + text, "BOM"
    return text.replace("\n", "\r\n"), "CRLF"


def mutate(text: str, rng: random.Random):
    """(mutated text or bytes, description) of one to three mutations of ``text``."""
    if rng.random() < 0.15:
        return _text_mutation(text, rng)
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return _text_mutation(text, rng)
    done = [rng.choice(TREE_MUTATIONS)(root, rng) for _ in range(rng.choice([1, 1, 2, 3]))]
    for e in root.iter():       # an attribute copied from one a mutation deleted
        for name in [n for n, v in e.attrib.items() if v is None]:
            del e.attrib[name]
    return ET.tostring(root, encoding="unicode"), "; ".join(done)


# -- the independent check -----------------------------------------------------------

mpmath.mp.prec = 80
_ZERO = mpmath.mpf(0)


class _Mat:
    """A small dense matrix of mpmath numbers (3x3 or 3x1): mpmath's own matrix class
    costs more in bookkeeping than these sizes need."""
    __slots__ = ("rows",)

    def __init__(self, rows):
        self.rows = [[x if isinstance(x, mpmath.mpf) else mpmath.mpf(x) for x in row]
                     if isinstance(row, (list, tuple)) else
                     [row if isinstance(row, mpmath.mpf) else mpmath.mpf(row)]
                     for row in rows]

    @property
    def T(self):
        return _Mat([list(col) for col in zip(*self.rows)])

    def __getitem__(self, ik):
        if isinstance(ik, tuple):
            return self.rows[ik[0]][ik[1]]
        return self.rows[ik][0]

    def __iter__(self):
        return (x for row in self.rows for x in row)

    def __mul__(self, other):
        if isinstance(other, _Mat):
            cols = list(zip(*other.rows))
            return _Mat([[mpmath.fsum(a * b for a, b in zip(row, col)) for col in cols]
                         for row in self.rows])
        return _Mat([[x * other for x in row] for row in self.rows])

    __rmul__ = __mul__

    def __truediv__(self, k):
        return _Mat([[x / k for x in row] for row in self.rows])

    def __add__(self, other):
        return _Mat([[a + b for a, b in zip(r1, r2)] for r1, r2 in zip(self.rows, other.rows)])

    def __sub__(self, other):
        return _Mat([[a - b for a, b in zip(r1, r2)] for r1, r2 in zip(self.rows, other.rows)])


def _eye():
    return _Mat([[1, 0, 0], [0, 1, 0], [0, 0, 1]])


def _vec(v):
    return _Mat([[x] for x in v])


class NotFinite(ValueError):
    """A number the file gives is NaN or infinite (an accepted file must have none)."""


def _mp_number(text):
    """A URDF number is a double (urdfdom reads it so): parsed as one, then exact."""
    value = float(text)
    if not math.isfinite(value):
        raise NotFinite(text)
    return mpmath.mpf(value)


def _mp_vector(text, default=(0, 0, 0)):
    return [_mp_number(x) for x in text.split()] if text is not None else \
        [mpmath.mpf(x) for x in default]


def _rpy(r, p, y):
    """Rz(y) Ry(p) Rx(r), written out (not rpy_matrix): the URDF convention."""
    cr, sr, cp, sp, cy, sy = (mpmath.cos(r), mpmath.sin(r), mpmath.cos(p), mpmath.sin(p),
                              mpmath.cos(y), mpmath.sin(y))
    return _Mat([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                          [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                          [-sp, cp * sr, cp * cr]])


def _rodrigues(unit, angle):
    """The rotation by ``angle`` about the unit vector ``unit``."""
    k = _Mat([[0, -unit[2], unit[1]], [unit[2], 0, -unit[0]],
                       [-unit[1], unit[0], 0]])
    return _eye() + mpmath.sin(angle) * k + (1 - mpmath.cos(angle)) * (k * k)


def _about(axis: int, angle):
    c, s = mpmath.cos(angle), mpmath.sin(angle)
    if axis == 1:
        return _Mat([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 2:
        return _Mat([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return _Mat([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _file_model(text, floating_base: bool):
    """From the file read by xml.etree: {joint: (type, world rotation of the joint
    frame at q=0, unit axis, mimic target)} and the moving links' (mass, world
    position of the centre of mass, world inertia about it)."""
    root = ET.fromstring(text)
    links = {l.get("name"): l for l in _top(root, "link")}
    joints = _top(root, "joint")
    by_child = {j.find("child").get("link"): j for j in joints}
    head = next(n for n in links if n not in by_child)
    frames = {head: (_eye(), _vec([0, 0, 0]), False)}
    axes = {}
    pending = list(joints)
    while pending:
        rest = []
        for j in pending:
            parent = j.find("parent").get("link")
            if parent not in frames:
                rest.append(j)
                continue
            r0, p0, moving = frames[parent]
            origin = j.find("origin")
            xyz = _mp_vector(origin.get("xyz") if origin is not None else None)
            rpy = _mp_vector(origin.get("rpy") if origin is not None else None)
            r = r0 * _rpy(*rpy)
            p = p0 + r0 * _vec(xyz)
            kind = j.get("type")
            axis_node = j.find("axis")
            axis = _mp_vector(axis_node.get("xyz") if axis_node is not None else None,
                              (1, 0, 0))
            length = mpmath.sqrt(sum(x * x for x in axis))
            unit = [x / length for x in axis] if length else None
            mimic = j.find("mimic")
            axes[j.get("name")] = (kind, r, unit,
                                   mimic.get("joint") if mimic is not None else None)
            child_r, child_p = r, p
            offset = _mp_number(mimic.get("offset") or "0") if mimic is not None else _ZERO
            if offset and unit is not None and kind == "prismatic":
                child_p = p + r * _vec(unit) * offset     # a mimic at q = 0
            elif offset and unit is not None and kind in ("revolute", "continuous"):
                child_r = r * _rodrigues(unit, offset)
            frames[j.find("child").get("link")] = (child_r, child_p, moving or kind != "fixed")
        if len(rest) == len(pending):
            break
        pending = rest
    parts = []
    for name, link in links.items():
        r, p, moving = frames[name]
        inertial = link.find("inertial")
        if inertial is None or not (moving or floating_base):
            continue
        origin = inertial.find("origin")
        xyz = _mp_vector(origin.get("xyz") if origin is not None else None)
        rpy = _mp_vector(origin.get("rpy") if origin is not None else None)
        i = {a: _mp_number(inertial.find("inertia").get(a))
             for a in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        tensor = _Mat([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]],
                                [i["ixz"], i["iyz"], i["izz"]]])
        ri = r * _rpy(*rpy)
        parts.append((_mp_number(inertial.find("mass").get("value")),
                      p + r * _vec(xyz), ri * tensor * ri.T))
    return axes, parts


def _file_rotors(text) -> dict:
    """{joint: rotor_inertia * gear_ratio^2} of the transmissions with Drake's rotor."""
    out = {}
    for t in _top(ET.fromstring(text), "transmission"):
        actuator, joint = t.find("actuator"), t.find("joint")
        if actuator is None or joint is None:
            continue
        inertia = actuator.find(f"{{{DRAKE}}}rotor_inertia")
        ratio = actuator.find(f"{{{DRAKE}}}gear_ratio")
        if inertia is None and ratio is None:
            continue
        i = _mp_number(inertia.get("value")) if inertia is not None else _ZERO
        n = _mp_number(ratio.get("value")) if ratio is not None else mpmath.mpf(1)
        out[joint.get("name")] = float(i * n * n)
    return out


def _spec_frames(spec):
    """World rotation of each base and world position of each point at q = 0 (unit
    quaternions at identity), from the spec alone."""
    zero = {sympy.Symbol(c): sympy.S.Zero for c in spec.coordinates}
    for j in spec.joints:
        zero.update({sympy.Symbol(c): (sympy.S.One if c.endswith("_qw") else sympy.S.Zero)
                     for c in j.coordinates})
    rot = {"E": _eye()}
    for b in spec.bases:
        parent = rot[b.parent]
        # an angle as the double the generated C computes with (an angle of 1e308 as
        # an exact decimal and as a double have unrelated cosines)
        rot[b.name] = parent if b.axis == 0 else \
            parent * _about(b.axis, _mp(b.angle, zero))
    pos = {"O": _vec([0, 0, 0])}
    for p in spec.points:
        local = _vec([_mp(c, zero) for c in p.coordinates])
        pos[p.name] = pos[p.parent] + rot[p.base] * local
    return rot, pos, zero


def _mp(x, zero):
    """An expression at q = 0 as the double the generated C computes with, exactly
    as an mpmath number (the spec's 5e-324 is the double 4.94e-324, as the file's)."""
    value = sympy.sympify(x).xreplace(zero)
    return mpmath.mpf(float(value))


def _totals(parts):
    mass = sum((m for m, _, _ in parts), _ZERO)
    if mass > 0:
        com = sum((m * c for m, c, _ in parts), _vec([0, 0, 0])) / mass
    else:
        com = _vec([0, 0, 0])
    inertia = _Mat([[0] * 3] * 3)
    for m, c, i in parts:
        d = c - com
        dd = sum(x * x for x in d)
        inertia = inertia + i + m * (dd * _eye() - d * d.T)
    # what rounding is relative to: the moments and parallel-axis terms, and the
    # lever of the centre of mass's own rounding (relative to the positions' size)
    reach = max((_norm(c) for _, c, _ in parts), default=_ZERO)
    spread = max((_norm(c - com) for _, c, _ in parts), default=_ZERO)
    scale = sum((abs(m) * sum(x * x for x in (c - com)) + sum(abs(i[k, k]) for k in range(3))
                 for m, c, i in parts), _ZERO) + abs(mass) * reach * spread
    return mass, com, inertia, scale


def _norm(v):
    return max((abs(x) for x in v), default=_ZERO)


def check_accepted(spec, text, floating_base: bool = False, rtol: float = 1e-9) -> list:
    """Mismatches between an accepted file's spec and the file read independently:
    joint axes (world frame, q = 0), the count of coordinates, and the moving links'
    total mass, centre of mass and inertia.  [] when the spec says what the file says."""
    problems = []
    try:
        axes, file_parts = _file_model(text, floating_base)
        rotors = _file_rotors(text)
    except NotFinite as exc:
        return [f"accepted the non-finite number {str(exc)[:30]!r}"]
    rot, pos, zero = _spec_frames(spec)
    moving = [n for n, (kind, _, _, mimic) in axes.items()
              if kind in ("revolute", "continuous", "prismatic") and mimic is None]
    free = {c for j in spec.joints for c in j.coordinates}
    simple = [c for c in spec.coordinates if c not in free]
    if len(simple) != len(moving):
        problems.append(f"{len(simple)} joint coordinates for {len(moving)} moving "
                        "joints")
        return problems
    mimicked = {mimic for (_, _, _, mimic) in axes.values() if mimic}
    named = {re.sub(r"[^A-Za-z0-9_]", "_", j): j for j in moving}
    if set(named) != set(simple):
        return [f"coordinates {sorted(set(simple) ^ set(named))[:3]} are not the moving "
                "joints' names"]
    by_name = {c: named[c] for c in simple}
    places: dict = {c: [] for c in simple}
    for b in spec.bases:
        for c in b.angle.free_symbols if b.axis else ():
            places.setdefault(c.name, []).append(b)
    for p in spec.points:
        for c in set().union(*(x.free_symbols for x in p.coordinates)):
            places.setdefault(c.name, []).append(p)
    for coordinate, joint in by_name.items():
        kind, r, axis, _ = axes[joint]
        if joint in mimicked or axis is None:
            continue
        expected = r * _vec(axis)
        c = sympy.Symbol(coordinate)
        if kind == "prismatic":
            found = [rot[p.base] * _vec([_mp(sympy.diff(x, c), zero)
                                                  for x in p.coordinates])
                     for p in places[coordinate] if hasattr(p, "coordinates")]
        else:
            found = []
            for b in places[coordinate]:
                if hasattr(b, "angle"):
                    e = _vec([1 if k == b.axis else 0 for k in (1, 2, 3)])
                    found.append(rot[b.parent] * e * _mp(sympy.diff(b.angle, c), zero))
        if len(found) != 1:
            problems.append(f"joint {joint}: {len(found)} places move with {coordinate}")
        elif _norm(found[0] - expected) > rtol:
            problems.append(f"joint {joint}: axis {[float(x) for x in found[0]]} in the spec, "
                            f"{[float(x) for x in expected]} in the file")
    armature = {name: float(_mp(value, zero)) for name, value in spec.armature}
    expected = {c: rotors[j] for c, j in by_name.items() if rotors.get(j)}
    if set(armature) != set(expected) or any(
            abs(armature[c] - expected[c]) > rtol * expected[c] + 1e-322 for c in expected):
        problems.append(f"armature {armature} in the spec, {expected} in the file")
    spec_parts = []
    for b in spec.bodies:
        r = rot[b.base]
        tensor = _Mat([[_mp(b.inertia[i][k], zero) for k in range(3)]
                                for i in range(3)])
        spec_parts.append((_mp(b.mass, zero), pos[b.G], r * tensor * r.T))
    m1, c1, i1, s1 = _totals(file_parts)
    m2, c2, i2, _ = _totals(spec_parts)
    if abs(m1 - m2) > rtol * abs(m1):
        problems.append(f"total mass {float(m2)!r} in the spec, {float(m1)!r} in the file")
    reach = max((_norm(c) for _, c, _ in file_parts), default=_ZERO)
    if m1 > 0 and _norm(c1 - c2) > rtol * reach:
        problems.append(f"centre of mass {[float(x) for x in c2]} in the spec, "
                        f"{[float(x) for x in c1]} in the file")
    if max(abs(x) for x in (i1 - i2)) > rtol * s1:
        problems.append(f"inertia differs by {float(max(abs(x) for x in (i1 - i2)))!r} "
                        f"(scale {float(s1)!r})")
    return problems
