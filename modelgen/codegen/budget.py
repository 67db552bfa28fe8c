"""The build budget: what a model may cost before the C compiler runs.

A model within the input limits (``modelgen.model.expr``) can still make C
that takes gcc minutes: a 300-link chain, or one long expression whose every
``sin`` is compiled inline.  The budget bounds it in *operations after CSE*
(what the manifest's ``ops`` records, :func:`modelgen.codegen.printer.c_operations`),
with each ``sin`` and ``cos`` counted as :data:`TRIG_OPERATIONS`, the inline
code gcc compiles for it (``mg_sin`` in ``model.c.j2``).  It is checked twice:

* before deriving, against :func:`estimated_operations`, a lower estimate from
  the model's size alone (so a chain far past the budget is refused in
  milliseconds, not after minutes of derivation);
* after CSE, against the exact figure (:func:`build_cost`), before emitting.

The budget is not part of what is built (a larger one builds the same C):
``max_operations=`` of ``generate``/``load``, else ``$MODELGEN_MAX_OPERATIONS``,
else :data:`MAX_OPERATIONS`; the CLI's ``--max-operations``.  A cached build
is reused whatever the budget.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from modelgen.codegen.options import ENV, MAX_OPERATIONS, max_operations  # noqa: F401
from modelgen.errors import ModelError

#: Operations a ``sin`` or ``cos`` counts for: the inline ``mg_sin``'s kernels
#: and reduction are about 40 operations that gcc compiles at every call.
TRIG_OPERATIONS = 40
#: Lower estimate per entry of the mass matrix that a joint tree leaves nonzero
#: (fitted on the chains n = 100 and 150, sin and cos weighted: 11.2 per entry).
PER_MASS_ENTRY = 10
#: Lower estimate per coordinate (a chain's routines cost about 1,400 a coordinate
#: with sin and cos weighted; a one-link chain 301 in all).
PER_COORDINATE = 250


@dataclass(frozen=True)
class Cost:
    """The figure the budget is checked against, and its parts."""
    operations: int         # after CSE, each sin and cos counted once
    trig: int               # calls of sin and cos
    largest: str            # the costliest routine

    @property
    def weighted(self) -> int:
        return self.operations + (TRIG_OPERATIONS - 1) * self.trig


def estimated_operations(n: int, tree=None) -> int:
    """A lower estimate of a model's cost from its size alone, before deriving: the
    nonzero entries of the mass matrix (a joint ``tree``'s: each coordinate with
    its ancestors'; without a tree, the diagonal) and the coordinates.

    >>> estimated_operations(300) < estimated_operations(300, _chain(300))
    True
    """
    entries = n
    if tree is not None:
        depth = []                  # coordinates on the path from the ground, per joint
        entries = 0
        for joint in tree.joints:
            dofs = len(joint.dofs)
            depth.append(dofs + (depth[joint.parent] if joint.parent >= 0 else 0))
            entries += dofs * depth[-1]
    return PER_MASS_ENTRY * entries + PER_COORDINATE * n


def _chain(n: int):
    """A stand-in joint tree of an n-link chain (for the doctest)."""
    class Joint:
        dofs = ((0, ()),)

        def __init__(self, parent):
            self.parent = parent

    class Tree:
        joints = tuple(Joint(i - 1) for i in range(n))
    return Tree()


def build_cost(routines, memo: dict | None = None) -> Cost:
    """The exact cost of CSE'd ``routines`` (:class:`modelgen.codegen.cse.Routine`).
    ``memo`` (a dict kept by the caller) remembers each routine's calls of sin
    and cos, for a build that asks again as its routines come in."""
    operations, trig, largest, most = 0, 0, "", -1
    for r in routines:
        known = memo.get(id(r)) if memo is not None else None
        if known is not None and known[0] is r:
            calls = known[1]
        else:
            calls = sum(_trig_calls(expr) for expr in
                        [e for _, e in r.statements] + [e for _, es in r.outputs for e in es]
                        if isinstance(expr, sympy.Basic))
            if memo is not None:
                memo[id(r)] = (r, calls)     # the routine kept, so its id is not reused
        operations += r.ops_after
        trig += calls
        if r.ops_after + (TRIG_OPERATIONS - 1) * calls > most:
            largest, most = r.name, r.ops_after + (TRIG_OPERATIONS - 1) * calls
    return Cost(operations, trig, largest)


def _trig_calls(expr) -> int:
    """The ``sin`` and ``cos`` nodes of ``expr``'s tree, a repeated subtree counted
    each time it appears (as ``sympy.preorder_traversal`` visits them), by one
    walk that skips the atoms (``has`` then ``preorder_traversal`` walked every
    statement twice, through generators)."""
    calls = 0
    stack = [expr]
    while stack:
        e = stack.pop()
        if e.is_Atom:
            continue
        if isinstance(e, (sympy.sin, sympy.cos)):
            calls += 1
        stack.extend(e.args)
    return calls


def _fix(budget: int) -> str:
    return (f"simplify the model, or raise the budget (now {budget:,}) if the build time "
            f"is acceptable: max_operations=... (generate, load), ${ENV}=..., "
            f"or --max-operations ... on the command line")


def check_estimate(spec, tree, budget: int) -> None:
    """Refuse a model whose :func:`estimated_operations` exceed ``budget``, before
    any derivation."""
    estimate = estimated_operations(spec.n, tree)
    if estimate > budget:
        raise ModelError(
            f"the model is too large to build within the budget: {spec.n} coordinates "
            f"make at least {estimate:,} operations after CSE (estimated from its size "
            f"before deriving), over the budget of {budget:,}", file=spec.source,
            fix=_fix(budget))


def check_cost(spec, cost: Cost, budget: int) -> None:
    """Refuse CSE'd routines whose :class:`Cost` exceeds ``budget``, before any C."""
    if cost.weighted > budget:
        raise ModelError(
            f"the model's C would cost {cost.weighted:,} operations after CSE "
            f"({cost.operations:,} operations and {cost.trig:,} calls of sin or cos, "
            f"each compiled inline as {TRIG_OPERATIONS}; most in {cost.largest}), over the "
            f"budget of {budget:,}", file=spec.source, fix=_fix(budget))
