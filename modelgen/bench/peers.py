"""The peers' models: modelgen's models written for MuJoCo (MJCF) and Pinocchio.

Two sources, the same numbers: ``spatial_chain(n)`` from its written definition
(:func:`chain_links`: rods hinged alternately about z and y), and any model file
that is a tree of revolute joints with gravity only (:func:`tree_links`, read off
modelgen's joint tree).  Each is written as MJCF (:func:`chain_mjcf`,
:func:`tree_mjcf`), as the input file of ``harness/pinocchio_bench.cpp``
(:func:`pinocchio_chain_file`, :func:`pinocchio_tree_file`), or built as a
Pinocchio model in Python (:func:`chain_pinocchio`).  A third source, a Pinocchio
model of revolute joints and free flyers (a URDF robot with a floating base), is
written for both from Pinocchio's own numbers (:func:`write_pinocchio_peer_models`).

>>> p = {"m1": 1.0, "m2": 2.0, "l1": 0.5, "l2": 0.4, "r": 0.02, "g": 9.81}
>>> [(offset, axis, m) for offset, axis, m, _c, _I in chain_links(2, p)]
[(0.0, 'z', 1.0), (0.5, 'y', 2.0)]
>>> chain_mjcf(2, p).count("<joint")
2
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import sympy

from modelgen.derive.joint_tree import extract_joint_tree
from modelgen.errors import ModelError
from modelgen.model.spec import symbol


def have_mujoco() -> bool:
    """Whether the mujoco Python package imports."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


# -- spatial_chain(n), from its written definition ---------------------------------

def chain_links(n: int, params: dict):
    """Per link of ``spatial_chain(n)``: (joint offset from the previous joint along
    x, axis 'z' | 'y', mass, centre of mass along x, (Ixx, Iyy, Izz) about it)."""
    r = params["r"]
    for i in range(1, n + 1):
        m, l = params[f"m{i}"], params[f"l{i}"]
        offset = 0.0 if i == 1 else params[f"l{i - 1}"]
        transverse = m * l ** 2 / 12 + m * r ** 2 / 4
        yield offset, "z" if i % 2 else "y", m, l / 2, (m * r ** 2 / 2, transverse, transverse)


def chain_mjcf(n: int, params: dict) -> str:
    """MJCF of ``spatial_chain(n)`` with the given parameter values: hinges about z / y
    of the body frame, which sits at the joint; inertial at (l/2, 0, 0) with the rods'
    principal moments; gravity (0, 0, -g); contacts disabled; no damping or armature;
    timestep 0.001, RK4."""
    r, g = params["r"], params["g"]
    lines = [f'<mujoco model="spatial_chain_{n}">',
             '  <compiler inertiafromgeom="false"/>',
             f'  <option timestep="0.001" integrator="RK4" gravity="0 0 {-g!r}">',
             '    <flag contact="disable"/>', '  </option>', '  <worldbody>']
    for i in range(1, n + 1):
        m, l = params[f"m{i}"], params[f"l{i}"]
        pos = "0 0 0" if i == 1 else f"{params[f'l{i - 1}']!r} 0 0"
        axis = "0 0 1" if i % 2 else "0 1 0"
        axial, transverse = m * r ** 2 / 2, m * l ** 2 / 12 + m * r ** 2 / 4
        pad = "  " * (i + 1)
        lines += [f'{pad}<body name="rod{i}" pos="{pos}">',
                  f'{pad}  <joint name="q{i}" type="hinge" axis="{axis}" damping="0" '
                  f'armature="0"/>',
                  f'{pad}  <inertial pos="{l / 2!r} 0 0" mass="{m!r}" '
                  f'diaginertia="{axial!r} {transverse!r} {transverse!r}"/>']
    lines += ["  " * (i + 1) + "</body>" for i in range(n, 0, -1)]
    lines += ['  </worldbody>', '</mujoco>', '']
    return "\n".join(lines)


def chain_pinocchio(n: int, params: dict):
    """Pinocchio model of ``spatial_chain(n)`` (needs the ``pin`` package), built
    from the chain's written definition like :func:`chain_mjcf`: revolute
    joints about z / y of the previous link frame, placed ``l(i-1)`` along its
    x axis; each rod's inertia at ``(l/2, 0, 0)``; gravity ``(0, 0, -g)``.

    >>> model = chain_pinocchio(3, {"m1": 1, "m2": 1, "m3": 1, "l1": .5, "l2": .5,
    ...                             "l3": .5, "r": .02, "g": 9.81})   # doctest: +SKIP
    >>> model.nq                                                     # doctest: +SKIP
    3
    """
    import pinocchio as pin
    model = pin.Model()
    parent = 0
    for i, (offset, axis, m, c, diag) in enumerate(chain_links(n, params), start=1):
        joint = pin.JointModelRZ() if axis == "z" else pin.JointModelRY()
        placement = pin.SE3(np.eye(3), np.array([offset, 0.0, 0.0]))
        parent = model.addJoint(parent, joint, placement, f"q{i}")
        inertia = pin.Inertia(m, np.array([c, 0.0, 0.0]), np.diag(diag))
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    model.gravity.linear = np.array([0.0, 0.0, -params["g"]])
    return model


def pinocchio_chain_file(n: int, params: dict, x0, path: Path) -> Path:
    """The input of the Pinocchio harness: ``spatial_chain(n)`` from its written
    definition (:func:`chain_links`) and the state x0."""
    links = [(i, axis, ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), (offset, 0.0, 0.0),
              m, (c, 0.0, 0.0), tuple(diag) + (0.0, 0.0, 0.0))
             for i, (offset, axis, m, c, diag) in enumerate(chain_links(n, params))]
    return pinocchio_tree_file(links, float(params["g"]), x0, path)


# -- a tree of revolute joints, read off modelgen's joint tree ----------------------

def tree_links(spec, params: dict):
    """A model of revolute joints about base axes, numerically, for Pinocchio and MuJoCo:
    per joint (parent's 1-based index or 0, axis 'x' | 'y' | 'z', R = the joint frame's
    axes in the parent's (rows), p its origin, mass, centre of mass, inertia about it
    as (xx, yy, zz, xy, xz, yz)).  Read from modelgen's joint tree of ``spec``, so it
    is the same model; None if the model is not such a tree (or has actions or
    effects other than gravity, which the peers would not see)."""
    try:
        tree = extract_joint_tree(spec)
    except ModelError:
        return None
    values = {symbol(name): float(v) for name, v in params.items()}
    values.update({symbol(name): 0.0 for name in spec.inputs})
    g = symbol("g")
    if spec.effects or "g" not in params or tuple(spec.gravity or ()) != (0, 0, -g):
        return None
    for act in spec.actions:          # the harnesses run with zero inputs
        if any(sympy.sympify(x).xreplace(values) != 0 for x in (*act.torque, *act.force)):
            return None

    def num(e):
        return float(sympy.sympify(e).xreplace(values))
    links = []
    for joint, body in zip(tree.joints, tree.inertias, strict=True):
        if joint.kind != "revolute" or sympy.sympify(joint.angle) != symbol(joint.name):
            return None
        E, r = joint.fixed
        R = np.array([[num(x) for x in row] for row in E]).T     # E maps parent -> child
        m = num(body.m)
        c = np.array([num(x) for x in body.h]) / m
        I = np.array([num(x) for x in body.I])                     # about the link origin
        shift = m * (np.dot(c, c) * np.array([1, 1, 1, 0, 0, 0])
                     - np.array([c[0] * c[0], c[1] * c[1], c[2] * c[2],
                                 c[0] * c[1], c[0] * c[2], c[1] * c[2]]))
        links.append((joint.parent + 1, "xyz"[joint.axis - 1], tuple(map(tuple, R)),
                      tuple(num(x) for x in r), m, tuple(c), tuple(I - shift)))
    return links


#: the joint codes of ``harness/pinocchio_bench.cpp``'s input: revolute about z, y, x
#: of the joint frame, or a free flyer
HARNESS_JOINTS = ("z", "y", "x", "free")


def pinocchio_links(model):
    """A Pinocchio model of revolute joints about the joint frame's axes and free flyers
    as links in :func:`tree_links`'s layout (axis ``free`` for a free flyer), read off
    Pinocchio's own joint placements and inertias (a URDF's fixed links already merged
    into their moving parents'), or None for any other joint.  Pinocchio numbers its
    joints parents first and depth first, so :func:`tree_mjcf` writes them in its
    order, and MuJoCo's qpos and qvel follow Pinocchio's q and v
    (:func:`mujoco_state`)."""
    kinds = {"JointModelRX": "x", "JointModelRY": "y", "JointModelRZ": "z",
             "JointModelFreeFlyer": "free"}
    links = []
    for jid in range(1, model.njoints):
        kind = kinds.get(model.joints[jid].shortname())
        if kind is None:
            return None
        placement, body = model.jointPlacements[jid], model.inertias[jid]
        I = np.array(body.inertia)
        links.append((int(model.parents[jid]), kind,
                      tuple(tuple(float(x) for x in row) for row in placement.rotation),
                      tuple(float(x) for x in placement.translation), float(body.mass),
                      tuple(float(x) for x in body.lever),
                      (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])))
    return links


def quaternion_matrix(w, x, y, z) -> np.ndarray:
    """The rotation matrix of the unit quaternion (w, x, y, z).

    >>> quaternion_matrix(0.0, 0.0, 0.0, 1.0).round(12).tolist()
    [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
    """
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def mujoco_state(links, q, v):
    """MuJoCo's (qpos, qvel) of :func:`tree_mjcf`'s model of ``links`` at Pinocchio's
    (q, v): a free joint's quaternion first-scalar (Pinocchio's is (x, y, z, w)) and
    its linear velocity in the world frame (Pinocchio's is in the body frame; both
    have the angular velocity in the body frame).

    >>> links = [(0, "free", None, None, 1.0, None, None), (1, "x", None, None, 1.0,
    ...          None, None)]
    >>> qpos, qvel = mujoco_state(links, [1, 2, 3, 0, 0, 1, 0, 0.5], [1, 0, 0, 0, 0, 7, 8])
    >>> qpos.tolist(), qvel.round(12).tolist()
    ([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0, 0.5], [-1.0, 0.0, 0.0, 0.0, 0.0, 7.0, 8.0])
    """
    q, v = np.asarray(q, float), np.asarray(v, float)
    qpos, qvel, iq, iv = [], [], 0, 0
    for link in links:
        if link[1] == "free":
            x, y, z, w = q[iq + 3:iq + 7]
            qpos += [*q[iq:iq + 3], w, x, y, z]
            qvel += [*(quaternion_matrix(w, x, y, z) @ v[iv:iv + 3]), *v[iv + 3:iv + 6]]
            iq, iv = iq + 7, iv + 6
        else:
            qpos.append(q[iq])
            qvel.append(v[iv])
            iq, iv = iq + 1, iv + 1
    return np.array(qpos), np.array(qvel)


def mujoco_acceleration(links, q, v, a):
    """MuJoCo's qacc of :func:`tree_mjcf`'s model at Pinocchio's (q, v) and
    acceleration ``a``: a free joint's linear rows are the derivative of its
    world-frame velocity R v, R (a + w x v) (:func:`mujoco_state`)."""
    q, v, a = (np.asarray(z, float) for z in (q, v, a))
    out, iq, iv = [], 0, 0
    for link in links:
        if link[1] == "free":
            x, y, z, w = q[iq + 3:iq + 7]
            linear = a[iv:iv + 3] + np.cross(v[iv + 3:iv + 6], v[iv:iv + 3])
            out += [*(quaternion_matrix(w, x, y, z) @ linear), *a[iv + 3:iv + 6]]
            iq, iv = iq + 7, iv + 6
        else:
            out.append(a[iv])
            iq, iv = iq + 1, iv + 1
    return np.array(out)


def tree_mjcf(name: str, links, g: float) -> str:
    """MJCF of ``links`` (:func:`tree_links` or :func:`pinocchio_links`), with the
    chain's options; a link of axis ``free`` is a ``freejoint``."""
    children: dict = {}
    for i, link in enumerate(links, start=1):
        children.setdefault(link[0], []).append(i)
    lines = [f'<mujoco model="{name}">', '  <compiler inertiafromgeom="false"/>',
             f'  <option timestep="0.001" integrator="RK4" gravity="0 0 {-g!r}">',
             '    <flag contact="disable"/>', '  </option>', '  <worldbody>']

    def quat(R):
        R = np.asarray(R)
        w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2
        if w > 1e-6:
            return (w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                    (R[1, 0] - R[0, 1]) / (4 * w))
        x = np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
        return ((R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x),
                (R[0, 2] + R[2, 0]) / (4 * x))

    def body(i, depth):
        _, axis, R, p, m, c, inertia = links[i - 1]
        pad = "  " * depth
        lines.append(f'{pad}<body name="link{i}" pos="{" ".join(repr(float(x)) for x in p)}" '
                     f'quat="{" ".join(repr(float(x)) for x in quat(R))}">')
        if axis == "free":
            lines.append(f'{pad}  <freejoint name="q{i}"/>')
        else:
            lines.append(f'{pad}  <joint name="q{i}" type="hinge" axis="'
                         + {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}[axis]
                         + '" damping="0" armature="0"/>')
        lines.append(f'{pad}  <inertial pos="{" ".join(repr(float(x)) for x in c)}" mass="{m!r}" '
                     f'fullinertia="{" ".join(repr(float(x)) for x in inertia)}"/>')
        for k in children.get(i, []):
            body(k, depth + 1)
        lines.append(f"{pad}</body>")
    for i in children.get(0, []):
        body(i, 2)
    lines += ['  </worldbody>', '</mujoco>', '']
    return "\n".join(lines)


def pinocchio_tree_file(links, g: float, x0, path: Path) -> Path:
    """The input of the Pinocchio harness for ``links`` as :func:`tree_links` or
    :func:`pinocchio_links` gives them, and the state ``x0`` in Pinocchio's
    coordinates (q, then v)."""
    lines = [str(len(links))]
    for parent, axis, R, p, m, c, inertia in links:
        lines.append(" ".join([str(parent), str(HARNESS_JOINTS.index(axis)),
                               *(repr(float(x)) for row in R for x in row),
                               *(repr(float(x)) for x in (*p, m, *c, *inertia))]))
    lines += [repr(g), " ".join(repr(float(v)) for v in x0)]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_pinocchio_peer_models(name: str, model, q, v, work: Path):
    """Write a Pinocchio model (of the joints :func:`pinocchio_links` reads: a URDF
    robot with a free-flyer base) for the peers at Pinocchio's state (q, v):
    ``work/<name>.xml`` (MJCF), ``work/<name>.pin.txt`` (the Pinocchio harness's
    input).  Returns the two paths and MuJoCo's state (qpos then qvel, one array;
    :func:`mujoco_state`), or None when a joint is of another kind."""
    links = pinocchio_links(model)
    if links is None:
        return None
    gravity = np.array(model.gravity.linear)
    if gravity[0] or gravity[1]:
        return None
    g = -float(gravity[2])
    xml, pin = work / f"{name}.xml", work / f"{name}.pin.txt"
    work.mkdir(parents=True, exist_ok=True)
    xml.write_text(tree_mjcf(name, links, g))
    pinocchio_tree_file(links, g, np.concatenate([q, v]), pin)
    return xml, pin, np.concatenate(mujoco_state(links, q, v))


def write_peer_models(spec, cm, x0, work: Path, chain: bool):
    """Write ``cm``'s model for the peers: ``work/<name>.xml`` (MJCF) and
    ``work/<name>.pin.txt`` (the Pinocchio harness's input, with the state ``x0``).
    ``chain``: ``spatial_chain(n)`` from its written definition; else the tree of
    revolute joints read off ``spec`` (:func:`tree_links`).  Returns the two paths,
    or None when the model is not a tree the peers can see."""
    params, g = cm.parameters, float(cm.parameters["g"])
    xml, pin = work / f"{cm.name}.xml", work / f"{cm.name}.pin.txt"
    work.mkdir(parents=True, exist_ok=True)
    if chain:
        xml.write_text(chain_mjcf(cm.n, params))
        return xml, pinocchio_chain_file(cm.n, params, x0, pin)
    links = tree_links(spec, params)
    if links is None:
        return None
    xml.write_text(tree_mjcf(cm.name, links, g))
    return xml, pinocchio_tree_file(links, g, x0, pin)


# -- agreement ----------------------------------------------------------------------

def mujoco_agreement(cm, states, xml_path: Path):
    """MuJoCo's ``qacc`` after ``mj_forward`` on the model ``xml_path`` against ``cm``'s
    q_ddot at ``states``: (max over states of ||qacc - qdd||_inf / ||qdd||_inf, qacc at
    the first state, the MjModel, the MjData at the first state)."""
    import mujoco
    n = cm.n
    model = mujoco.MjModel.from_xml_path(str(xml_path))
    data = mujoco.MjData(model)
    worst = 0.0
    for x in states:
        data.qpos[:], data.qvel[:] = x[:n], x[n:]
        mujoco.mj_forward(model, data)
        qdd = cm.rhs(0.0, x)[n:]
        worst = max(worst, float(np.max(np.abs(data.qacc - qdd)) / np.max(np.abs(qdd))))
    data.qpos[:], data.qvel[:] = states[0][:n], states[0][n:]
    mujoco.mj_forward(model, data)
    return worst, [float(v) for v in data.qacc], model, data


def agreement(values: dict) -> float:
    """The largest pairwise max-norm difference of ``values`` (name -> vector) over
    the largest magnitude among them.

    >>> agreement({"a": np.array([1.0, 2.0]), "b": np.array([1.0, 2.5])})
    0.2
    """
    scale = max(float(np.max(np.abs(v))) for v in values.values())
    names = sorted(values)
    return max(float(np.max(np.abs(values[a] - values[b]))) / scale
               for i, a in enumerate(names) for b in names[i + 1:])
