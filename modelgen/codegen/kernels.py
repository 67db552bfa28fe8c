"""The recursive derivatives' kernels (:mod:`modelgen.derive.link_kernels`) as C:
each kernel's statements after CSE, printed for ``templates/model.c.j2``,
which wraps them in inline functions and the loops over the joints.

A kernel reads its inputs from arrays (``P[i]``, ``c[i]``, ``D[i]``...) or
scalars, keeps its statements in locals ``t<i>`` and writes its outputs to
arrays; W's components of the joint's dof are ``Wk[c * N]`` (``Wk = W + k``:
component c of dof k is ``W[c * N + k]``).
"""
from __future__ import annotations

from modelgen.codegen.cse import make_routines
from modelgen.codegen.printer import ModelPrinter
from modelgen.derive.graph import free_symbols
from modelgen.derive.link_kernels import (BACKWARD_VECTORS, DYN, FORWARD_VECTORS, INERTIA, KIN,
                                          TRIANGLE, Kernel, LinkKernels)

#: W's first component each kernel writes
BACKWARD_FIRST = FORWARD_VECTORS
FACTOR_FIRST = FORWARD_VECTORS + BACKWARD_VECTORS
#: the last kernels printed and their context: the early renders of a build's
#: parts and its final one print them once (id(kernels) -> (kernels, context))
_PRINTED: dict = {}


def _slot(array: str, first: int = 0):
    if array == "Wk":
        return lambda i: f"Wk[{first + i} * N]"
    return lambda i: f"{array}[{first + i}]"


def kernel_lines(kernel: Kernel, name: str, inputs: dict, outputs: dict) -> tuple:
    """The C statements of ``kernel``: ``inputs`` maps each input array to a
    function of the index giving its C (or to a tuple of names), ``outputs``
    each output array likewise."""
    (routine,) = make_routines(kernel.graph, [(name, kernel.inputs, kernel.outputs)])
    slots = {}
    for array, symbols in kernel.inputs:
        where = inputs[array]
        for i, s in enumerate(symbols):
            slots[s] = where[i] if isinstance(where, tuple) else where(i)
    for i, (sym, _) in enumerate(routine.statements):
        slots[sym] = f"t{i}"
    printer = ModelPrinter(slots, name)
    index = {sym: i for i, (sym, _) in enumerate(routine.statements)}
    # each output stored right after the last statement it needs: a value kept
    # for a store at the end would hold a register, or be spilled, until then
    stores = [[] for _ in range(len(routine.statements) + 1)]
    for array, items in routine.outputs:
        where = outputs[array]
        for j, e in enumerate(items):
            last = max((index[s] for s in free_symbols(e) if s in index), default=-1)
            stores[last + 1].append(f"{where(j)} = {printer.doprint(e)};")
    lines = list(stores[0])
    for i, (_, e) in enumerate(routine.statements):
        lines.append(f"const double t{i} = {printer.doprint(e)};")
        lines.extend(stores[i + 1])
    return tuple(lines)


def kernel_context(kernels: LinkKernels) -> dict:
    """The template's ``derivative_loop.kernels``: each kernel's lines and the
    per-joint tables as C initialiser lists."""
    hit = _PRINTED.get(id(kernels))
    if hit is not None and hit[0] is kernels:
        return hit[1]
    context = _context(kernels)
    _PRINTED.clear()
    _PRINTED[id(kernels)] = (kernels, context)
    return context


def _context(kernels: LinkKernels) -> dict:
    def c_list(values):
        return ", ".join(str(v) for v in values)
    forward = tuple(
        kernel_lines(k, f"derivative_forward{s}",
                     {"P": _slot("P"), "c": _slot("c"), "j": ("q", "qd", "qdd")},
                     {"K": _slot("K"), "D": _slot("D"), "V": _slot("Wk")})
        for s, k in enumerate(kernels.forward))
    backward = kernel_lines(kernels.backward, "derivative_backward",
                            {"D": _slot("D"), "V": _slot("Wk")},
                            {"V": _slot("Wk", BACKWARD_FIRST)})
    factor = None if kernels.factor is None else kernel_lines(
        kernels.factor, "derivative_factor",
        {"Y": _slot("Y"), "A": _slot("A"), "J": _slot("Wk"), "arm": ("arm",)},
        {"V": _slot("Wk", FACTOR_FIRST), "H": _slot("H")})
    return {"forward": forward, "backward": backward, "factor": factor,
            "joints": len(kernels.signature), "signature": c_list(kernels.signature),
            "parent": c_list(kernels.parent), "dof": c_list(kernels.dof),
            "offset": c_list(kernels.offset), "table": len(kernels.table),
            "du": c_list(x for row in kernels.du for x in row) or "0", "ndu": len(kernels.du),
            "armature": c_list(kernels.armature),
            "kin": KIN, "dyn": DYN, "inertia": INERTIA, "triangle": TRIANGLE}


__all__ = ["kernel_context", "kernel_lines"]
