"""The recursive derivatives' per-dof vectors as kernels per joint signature.

:func:`modelgen.derive.rnea_partials.derive_rnea_partials` writes the vectors
of every dof as one straight line, O(n) statements that gcc compiles in
seconds at 20 links and that stream through the instruction cache at every
call.  Every quantity is in the ground frame E, so what a joint computes
from its parent's state (rotation R, origin p, velocity ov, acceleration oa)
depends on the joint only through its axis and a few constants: the fixed
transform to its frame, its motion subspace, its link's inertia.  Here each
joint is abstracted to a *signature* (its axis and the constants, each a slot
``c[i]`` unless it is 0, 1 or -1), and the forward step is derived once per
signature over symbols for the parent's state (:data:`KIN`), the slots and
the joint's q, qd and qdd; the backward step and the articulated-body factor
do not depend on the joint at all; a root joint's signature has the ground's
state folded in.  The C calls them in loops over the joints
(``templates/model.c.j2``), with the slots' values (expressions of the
parameters) in a table, so what is derived and compiled grows with the number
of signatures, not with n.  The
arithmetic is :func:`~modelgen.derive.rnea_partials.derive_rnea_partials`'s,
step for step (:mod:`modelgen.derive.ground_frame`).

Joints the kernels take (:func:`loopable`): revolute and prismatic joints,
so a fixed base; an armature enters the articulated factor.  Actions fixed to
a link (a joint's motor and its reaction) enter its force ``of`` as constants
of its signature, evaluated with the inputs at every call.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.derive.graph import Graph, GraphBuilder
from modelgen.derive.ground_frame import (dof_partials, link_dynamics, motion_to_ground,
                                          sym6)
from modelgen.derive.joint_tree import JointTree, LinkInertia
from modelgen.model.spec import symbol
from modelgen.derive.spatial import (IDENTITY3, PAIRS, ZERO3, add, cross_motion, dot,
                                     is_identity, matmul, matvec, name_vec, named, rotation,
                                     symmetric, times, total, transpose)

#: a link's state for its children: R (9, by rows), p (3), ov (6), oa (6)
KIN = 24
#: its dynamics: I_O (6, as PAIRS), h_O (3), m, doY's A (9, by rows) and F (3),
#: of (6); the backward loop adds a child's 28 numbers into its parent's
DYN = 28
#: the first of them, the link's own inertia (I_O, h_O, m), which the
#: articulated factor reads
INERTIA = 10
#: the articulated inertia a dof hands its predecessor: a symmetric 6x6 by its
#: upper triangle, row by row
TRIANGLE = 21
#: W's components the forward kernel writes (J, dAdq, dVdq, dAdv), the backward
#: one (dFda, dYtJ, dFdq0, dFdq, dFdv) and the factor (U, 1 / D)
FORWARD_VECTORS, BACKWARD_VECTORS, FACTOR_VECTORS = 24, 27, 7


@dataclass(frozen=True)
class Kernel:
    """A straight-line program over its own ``graph``: ``inputs`` and ``outputs``
    are ``((array name, (symbol or expression, ...)), ...)``."""
    graph: Graph
    inputs: tuple
    outputs: tuple


@dataclass(frozen=True)
class LinkKernels:
    """Output of :func:`derive_link_kernels`.

    ``forward[s]`` is the forward step of signature s: inputs ``P`` (the
    parent's :data:`KIN` state), ``c`` (the slots), ``j`` (q, qd, qdd); outputs
    ``K`` (the link's state), ``D`` (its :data:`DYN` dynamics) and ``V`` (W's
    components 0..23 of its dof).  ``backward``: inputs ``D`` (the subtree's
    composite dynamics) and ``V``; outputs ``V`` (components 24..50).
    ``factor`` (above ``ARTICULATED_SOLVE_ABOVE`` speeds, else None): inputs
    ``Y`` (the link's own inertia, the first :data:`INERTIA` of D), ``A``
    (what its children handed it, :data:`TRIANGLE`) and ``J``; outputs ``V`` (components 51..57) and ``H``
    (what it hands its parent).  Per joint: ``signature``, ``parent`` (-1:
    the ground; a root's kernel reads no parent state, the ground's is folded
    in), ``dof`` (its speed and coordinate) and ``offset`` of its slots in
    ``table``: expressions of the parameters (and of the inputs, for the
    actions fixed to links).
    """
    forward: tuple
    backward: Kernel
    factor: Kernel | None
    signature: tuple
    parent: tuple
    dof: tuple
    offset: tuple
    table: tuple
    #: the actions fixed to links along the inputs: ``(joint, input, offset)``, the
    #: 6 entries of d force / d u (link components) at ``offset`` in ``table``;
    #: the loop adds ``-J_k . d force / d u`` (in E) to dQ_du of every dof k at or
    #: above the joint
    du: tuple = ()
    #: per joint, where its dof's armature is in ``table`` (for the factor's D);
    #: empty without armature
    armature: tuple = ()

    def operations(self, graph_operations) -> int:
        """Operations of one call: each joint's kernels (``graph_operations(graph,
        exprs)`` counts a program)."""
        def ops(kernel):
            exprs = [e for _, items in kernel.outputs for e in items]
            return graph_operations(kernel.graph, exprs)
        per_signature = [ops(k) for k in self.forward]
        per_joint = ops(self.backward) + (ops(self.factor) if self.factor else 0) + DYN
        return sum(per_signature[s] + per_joint for s in self.signature)


def loopable(tree: JointTree, q) -> bool:
    """Whether :func:`derive_link_kernels` takes ``tree``: revolute joints turning
    by ``a q + c`` and prismatic joints moving by ``q d`` (``q`` the joint's own
    coordinate, of ``q``, the coordinates' symbols; ``a``, ``c`` and ``d``
    constants), so no ball or free joint."""
    for joint in tree.joints:
        if joint.kind not in ("revolute", "prismatic") or \
                joint.dofs != ((joint.coordinate, joint.S),):
            return False
        own = q[joint.coordinate]
        if own != symbol(joint.name):
            return False
        if joint.kind == "revolute":
            if own in sympy.sympify(_angle_offset(joint)).free_symbols:
                return False
        elif any(sympy.expand(o - d * own) != 0
                 for o, d in zip(joint.offset, joint.S[3:], strict=True)):
            return False
    return True


def signature(joint, body: LinkInertia, ground=None, load=None) -> tuple:
    """``(key, values)``: the joint and its link with every constant that is not
    0, 1 or -1 a slot (one per distinct value, numbered as they appear), and the
    slots' values.  Joints of one key share a forward kernel.  ``ground``: the
    ground's spatial acceleration, for a root joint, whose kernel then has the
    ground's state folded in (its slots too).  ``load``: the force of the
    actions fixed to the link (link components, at its origin; of the inputs
    and parameters: the table is filled at every call)."""
    values = []

    def slot(x):
        x = sympy.sympify(x)
        if x.is_Number and x in (0, 1, -1):
            return sympy.Integer(x)
        for i, v in enumerate(values):
            if v == x:
                return _Slot(i)
        values.append(x)
        return _Slot(len(values) - 1)

    E, r = joint.fixed
    key = (joint.axis, tuple(tuple(slot(x) for x in row) for row in E),
           tuple(slot(x) for x in r), tuple(slot(x) for x in joint.S),
           tuple(slot(x) for x in body.I), tuple(slot(x) for x in body.h), slot(body.m),
           None if ground is None else tuple(slot(x) for x in ground),
           None if load is None else tuple(slot(x) for x in load),
           slot(_angle_offset(joint)) if joint.kind == "revolute" else None)
    return key, tuple(values)


def _angle_offset(joint):
    """``c`` of a revolute joint's angle ``a q + c`` (``a`` is its S entry)."""
    return sympy.expand(joint.angle - joint.S[joint.axis - 1] * symbol(joint.name))


class _Slot(int):
    """A slot's index in a signature's key: never equal to the number it is (an
    entry 1 of one joint and slot 1 of another make different keys)."""

    def __eq__(self, other):
        return type(other) is _Slot and int(self) == int(other)

    def __ne__(self, other):
        return not self == other

    def __hash__(self):
        return hash(("slot", int(self)))


def _fill(key, slots) -> tuple:
    """``key`` with each slot index replaced by its symbol."""
    def one(x):
        return slots[x] if type(x) is _Slot else x
    axis, E, r, S, I, h, m, ground, load, offset = key
    return (axis, tuple(tuple(one(x) for x in row) for row in E), tuple(one(x) for x in r),
            tuple(one(x) for x in S), tuple(one(x) for x in I), tuple(one(x) for x in h),
            one(m), None if ground is None else tuple(one(x) for x in ground),
            None if load is None else tuple(one(x) for x in load), one(offset))


def _inputs(prefix: str, count: int) -> tuple:
    return tuple(sympy.Symbol(f"mg_{prefix}{i}") for i in range(count))


def forward_kernel(key, count: int) -> Kernel:
    """The forward step of a joint of signature ``key`` with ``count`` slots
    (:func:`signature`: the number of its values), as the outward loop of
    ``derive_rnea_partials`` takes it: the link's pose, its column J, velocity
    and acceleration, its inertia, force and their variation in E, and
    ``dVdq``, ``dAdq``, ``dAdv``."""
    slots = _inputs("slot", count)
    axis, E, r, S, I, h, m, ground, load, offset = _fill(key, slots)
    P = _inputs("par", KIN)
    q, qd, qdd = sympy.symbols("mg_q mg_qd mg_qdd")
    builder = GraphBuilder()
    if ground is None:
        R, p = (P[0:3], P[3:6], P[6:9]), P[9:12]
        ov_p, oa_p = P[12:18], P[18:24]
    else:
        R, p, ov_p, oa_p = IDENTITY3, ZERO3, ZERO3 + ZERO3, ground
    if any(x != 0 for x in r):
        p = name_vec(builder, add(p, matvec(R, r)))
    if not is_identity(E):
        R = tuple(name_vec(builder, row) for row in matmul(R, transpose(E)))
    if axis:                            # revolute: turned by a q + c
        angle = total((times(S[axis - 1], q), offset))
        c, s = builder.name(sympy.cos(angle)), builder.name(sympy.sin(angle))
        R = tuple(name_vec(builder, row) for row in matmul(R, transpose(rotation(axis, c, s))))
    else:                               # prismatic: moved by q along S's linear part
        p = name_vec(builder, add(p, matvec(R, name_vec(builder, tuple(times(d, q)
                                                                     for d in S[3:])))))
    J = name_vec(builder, motion_to_ground(R, p, S))
    dV = name_vec(builder, cross_motion(ov_p, J))
    vJ = name_vec(builder, tuple(times(x, qd) for x in J))
    ov = name_vec(builder, add(ov_p, vJ))
    oa = name_vec(builder, add(add(oa_p, tuple(times(x, qdd) for x in J)),
                               tuple(times(x, qd) for x in dV)))
    Y, of, (A, F) = link_dynamics(builder, LinkInertia(I, h, m, ()), R, p, ov, oa, True, load)
    dAdq = name_vec(builder, add(cross_motion(oa_p, J), cross_motion(ov_p, dV)))
    dAdv = tuple(builder.factor(times(2, x)) for x in dV)
    I_O, h_O, mass = Y
    K = tuple(x for row in R for x in row) + tuple(p) + ov + oa
    D = tuple(I_O[a][b] for a, b in PAIRS) + tuple(h_O) + (mass,) + \
        tuple(x for row in A for x in row) + tuple(F) + of
    return Kernel(builder.freeze(), (("P", P), ("c", slots), ("j", (q, qd, qdd))),
                  (("K", K), ("D", D), ("V", J + dAdq + dV + dAdv)))


def backward_kernel() -> Kernel:
    """The backward step of any joint: from its subtree's composite inertia,
    variation and force and its dof's forward vectors, ``dFda``, ``dYtJ``,
    ``dFdq0``, ``dFdq`` and ``dFdv``."""
    D, V = _inputs("dyn", DYN), _inputs("vec", FORWARD_VECTORS)
    builder = GraphBuilder()
    Y = (symmetric(D[0:6]), D[6:9], D[9])
    dY = ((D[10:13], D[13:16], D[16:19]), D[19:22])
    f = D[22:28]
    J, dAdq, dV, dAdv = V[0:6], V[6:12], V[12:18], V[18:24]
    partials = dof_partials(builder, Y, dY, f, J, dAdq, dV, dAdv)
    return Kernel(builder.freeze(), (("D", D), ("V", V)),
                  (("V", tuple(x for vec in partials for x in vec)),))


def factor_kernel(armature: bool = False) -> Kernel:
    """One dof of ``articulated_factor``: its articulated inertia (its link's own
    plus what its children handed it), ``U = IA J``, ``1 / D`` and what it hands
    its predecessor, ``IA - U U^T / D``; with ``armature``, ``D = J . U`` plus
    the dof's armature (input ``arm``)."""
    Yin, Ain, J = _inputs("own", INERTIA), _inputs("acc", TRIANGLE), _inputs("col", 6)
    arm = sympy.Symbol("mg_arm")
    builder = GraphBuilder()
    own = sym6((symmetric(Yin[0:6]), Yin[6:9], Yin[9]))
    upper = {}
    for r in range(6):
        for c in range(r, 6):
            upper[r, c] = Ain[len(upper)]
    A = [[named(builder, total((own[r][c], upper[min(r, c), max(r, c)]))) for c in range(6)]
         for r in range(6)]
    U = name_vec(builder, [dot(row, J) for row in A])
    d = builder.name(total((dot(J, U), arm)) if armature else dot(J, U))
    inv = builder.name(1 / d)
    Uw = name_vec(builder, [times(inv, x) for x in U])
    child = tuple(total((A[r][c], -times(U[r], Uw[c]))) for r in range(6) for c in range(r, 6))
    return Kernel(builder.freeze(), (("Y", Yin), ("A", Ain), ("J", J))
                  + ((("arm", (arm,)),) if armature else ()),
                  (("V", U + (inv,)), ("H", child)))


def derive_link_kernels(tree: JointTree, a0, articulated: bool, loads=None,
                        load_du=None) -> LinkKernels:
    """The kernels of ``tree`` (:func:`loopable`) and their tables; ``a0`` is the
    ground's spatial acceleration (minus gravity) in E; ``articulated`` adds the
    factor's kernel.  ``loads`` ({joint index: 6-vector}) and ``load_du`` ({joint
    index: {input index: 6-vector}}) are the actions fixed to links and their
    derivatives along the inputs, in link components."""
    loads, load_du = loads or {}, load_du or {}
    keys, forward, signature_of, offset, table = {}, [], [], [], []
    for i, (joint, body) in enumerate(zip(tree.joints, tree.inertias, strict=True)):
        key, values = signature(joint, body, a0 if joint.parent < 0 else None, loads.get(i))
        if key not in keys:
            keys[key] = len(forward)
            forward.append(forward_kernel(key, len(values)))
        signature_of.append(keys[key])
        offset.append(len(table))
        table.extend(values)
    armature = bool(tree.armature) and any(x != 0 for x in tree.armature)
    arm = []
    for joint in tree.joints if armature else ():
        arm.append(len(table))
        table.append(sympy.sympify(tree.armature[joint.coordinate]))
    du = []
    for i in sorted(load_du):
        for j in sorted(load_du[i]):
            du.append((i, j, len(table)))
            table.extend(sympy.sympify(x) for x in load_du[i][j])
    return LinkKernels(tuple(forward), backward_kernel(),
                       factor_kernel(armature) if articulated else None, tuple(signature_of),
                       tuple(j.parent for j in tree.joints),
                       tuple(j.coordinate for j in tree.joints), tuple(offset), tuple(table),
                       tuple(du), tuple(arm))


__all__ = ["BACKWARD_VECTORS", "DYN", "FACTOR_VECTORS", "FORWARD_VECTORS", "INERTIA", "KIN",
           "Kernel", "LinkKernels", "TRIANGLE", "backward_kernel",
           "derive_link_kernels", "factor_kernel", "forward_kernel", "loopable", "signature"]
